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
use flare_core::report::{GhostReport, ghost_report};

use super::job::{Job, JobPoll};

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
    job: Option<(ReportKey, Job<Result<GhostReport, String>>)>,
    /// The latest report and the key it was made for.
    pub shown: Option<(ReportKey, Result<GhostReport, String>)>,
    /// Column and descending.
    pub sort: (ReportColumn, bool),
}

impl Default for ReportState {
    fn default() -> Self {
        Self { job: None, shown: None, sort: (ReportColumn::Rank, false) }
    }
}

impl ReportState {
    /// Takes a finished report and starts one for `key` when the shown one is for another; true while a
    /// job runs (the caller repaints).
    pub fn step(&mut self, key: ReportKey, lens: &Lens, flare: &Arc<PreparedFlare>, u: [f64; 2]) -> bool {
        if let Some((done_key, job)) = &self.job
            && let JobPoll::Finished(outcome) = job.poll()
        {
            self.shown = Some((*done_key, outcome));
            self.job = None;
        }
        let current = self.shown.as_ref().is_some_and(|(k, _)| *k == key);
        if self.job.is_none() && !current {
            let (lens, flare) = (lens.clone(), flare.clone());
            let job = Job::spawn("ghost report", move |_, _| {
                ghost_report(&lens, &flare.system, flare.mask(), u).map_err(|e| e.to_string())
            });
            self.job = Some((key, job));
        }
        self.job.is_some()
    }

    /// True when the report shown is not the one for `key` (it is being recomputed).
    pub fn stale(&self, key: ReportKey) -> bool {
        self.shown.as_ref().is_none_or(|(k, _)| *k != key)
    }
}
