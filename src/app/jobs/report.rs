//! The ghost report's state in the app: the report of the frame shown, computed on a worker thread whenever
//! the optics or the light change while the Report tab is open, and the table's sort order.
//!
//! # How it works
//! The key is the prepared flare's identity and the light's slopes: a new key starts a [`Job`] running
//! [`flare_core::report::ghost_report`] on the flare's own ghost system and aperture mask (the numbers the
//! frame is drawn from). While it runs the previous report stays on screen, marked as being recomputed;
//! a key that changes meanwhile is picked up when the job ends, so dragging the light never queues work.

use std::sync::Arc;

use flare_core::flare::PreparedFlare;
use flare_core::optics::Lens;
use flare_core::report::{GhostReport, ghost_report_until};

use super::job::{Job, Slot};

/// Which numbers the report was made for: the prepared flare and the light's slopes (as bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReportKey {
    pub flare: u64,
    pub slope_bits: [u64; 2],
}

impl ReportKey {
    pub fn new(flare: &PreparedFlare, u: [f64; 2]) -> Self {
        Self { flare: flare.id, slope_bits: u.map(f64::to_bits) }
    }
}

/// The columns the table sorts by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReportColumn {
    Rank,
    Pair,
    Focus,
    Size,
    FNumber,
    Peak,
    Mean,
    Share,
    Stop,
    Vignetted,
}

/// The Report tab's state.
pub struct ReportState {
    /// The report being computed (or waiting for a cancelled one to end) and what it is for.
    slot: Slot<ReportKey, Result<GhostReport, String>>,
    /// What a cancelled report was for: not computed again until the optics or the light change.
    cancelled: Option<ReportKey>,
    /// The latest report and the key it was made for.
    pub shown: Option<(ReportKey, Result<GhostReport, String>)>,
    /// Column and descending.
    pub sort: (ReportColumn, bool),
}

impl Default for ReportState {
    fn default() -> Self {
        Self { slot: Slot::default(), cancelled: None, shown: None, sort: (ReportColumn::Rank, false) }
    }
}

impl ReportState {
    /// Takes a finished report and starts one for `key` when the shown one is for another (one at a time: a
    /// key that changes while one runs cancels it, and the last key is computed once it has ended); true while
    /// a job runs (the caller repaints).
    pub fn step(&mut self, key: ReportKey, lens: &Lens, flare: &Arc<PreparedFlare>, u: [f64; 2]) -> bool {
        if let Some(done) = self.slot.poll()
            && !done.cancelled
        {
            self.shown = Some((done.key, done.outcome));
        }
        let current = self.shown.as_ref().is_some_and(|(k, _)| *k == key);
        if !current && self.cancelled != Some(key) {
            let (lens, flare) = (lens.clone(), flare.clone());
            self.slot.request(key, move || {
                Job::spawn("ghost report", move |cancel, _| {
                    ghost_report_until(&lens, &flare.system, flare.mask(), u, cancel)
                        .map_err(|e| e.to_string())?
                        .ok_or_else(|| "cancelled".to_string())
                })
            });
        }
        self.slot.busy()
    }

    /// The running report's progress (`None` when none runs).
    pub fn progress(&self) -> Option<(f32, String)> {
        self.slot.progress()
    }

    /// True while a report is computed or waits.
    pub fn busy(&self) -> bool {
        self.slot.busy()
    }

    /// Stops the running report; it is not computed again until the optics or the light change.
    pub fn cancel(&mut self) {
        self.cancelled = self.slot.cancel();
    }

    /// True when the report shown is not the one for `key` (it is being recomputed).
    pub fn stale(&self, key: ReportKey) -> bool {
        self.shown.as_ref().is_none_or(|(k, _)| *k != key)
    }
}
