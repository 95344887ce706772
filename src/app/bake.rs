//! The app's background bake: classification and LUT bake on a thread, with progress and Cancel, polled by
//! the UI each frame (the window never blocks).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use flare_core::flare::PreparedFlare;
use flare_core::lut::GhostLut;
use flare_core::lut::bake::{BakeProgress, BakeSettings, bake, useful_field_deg};
use flare_core::lut::classify::{ClassifySettings, GhostClass, classify};

/// What a bake thread hands back: the LUT and the classification, or why it stopped.
pub type BakeOutcome = Result<(GhostLut, Vec<GhostClass>), String>;

/// Where a bake stands.
pub enum BakePoll {
    /// Still running: the fraction done and what it is doing.
    Running(f32, String),
    /// Finished (or stopped).
    Finished(BakeOutcome),
}

/// A bake running on its thread.
pub struct BakeJob {
    cancel: Arc<AtomicBool>,
    progress: Arc<Mutex<(f32, String)>>,
    result: Arc<Mutex<Option<BakeOutcome>>>,
}

/// What a new bake says it is doing.
pub const CLASSIFYING: &str = "classifying the ghosts…";

impl BakeJob {
    /// Classifies `flare`'s ghosts and bakes the non-linear ones at the default settings on a new thread;
    /// `previous` lends the ghosts whose key is unchanged.
    pub fn start(flare: Arc<PreparedFlare>, previous: Option<GhostLut>) -> Self {
        let job = Self {
            cancel: Arc::new(AtomicBool::new(false)),
            progress: Arc::new(Mutex::new((0.0, CLASSIFYING.into()))),
            result: Arc::new(Mutex::new(None)),
        };
        let (cancel, progress, result) = (job.cancel.clone(), job.progress.clone(), job.result.clone());
        std::thread::spawn(move || {
            let renderer = flare.ray_grid_renderer();
            let settings = ClassifySettings::for_flare(&flare, useful_field_deg(&flare));
            let classes = classify(&flare, &renderer, &settings, &[]);
            let chosen: Vec<usize> = classes.iter().filter(|c| c.nonlinear()).map(|c| c.ghost).collect();
            let report = |p: BakeProgress| {
                if let Ok(mut g) = progress.lock() {
                    *g = (
                        p.ghosts_done as f32 / p.ghosts_total.max(1) as f32,
                        format!("{}/{} ghosts, {} entries", p.ghosts_done, p.ghosts_total, p.entries),
                    );
                }
            };
            let baked = bake(&flare, &renderer, &chosen, &BakeSettings::default(), previous.as_ref(), &report, &cancel)
                .map(|lut| (lut, classes))
                .map_err(|e| e.to_string());
            if let Ok(mut r) = result.lock() {
                *r = Some(baked);
            }
        });
        job
    }

    /// Asks the thread to stop (it finishes with an error saying so).
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Where the bake stands; a finished bake's outcome is handed over once.
    pub fn poll(&self) -> BakePoll {
        match self.result.lock().ok().and_then(|mut r| r.take()) {
            Some(outcome) => BakePoll::Finished(outcome),
            None => {
                let (fraction, text) = self.progress.lock().map(|p| p.clone()).unwrap_or_default();
                BakePoll::Running(fraction, text)
            }
        }
    }
}
