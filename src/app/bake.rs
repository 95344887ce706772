//! The app's background bake: classification and LUT bake on a thread, with progress and Cancel, polled by
//! the UI each frame (the window never blocks).

use std::sync::Arc;

use super::job::{Job, JobPoll};

use flare_core::flare::PreparedFlare;
use flare_core::lut::GhostLut;
use flare_core::lut::bake::{BakeProgress, BakeSettings, bake, useful_field_deg};
use flare_core::lut::classify::{ClassifySettings, GhostClass, classify};

/// What a bake thread hands back: the LUT and the classification, or why it stopped.
pub type BakeOutcome = Result<(GhostLut, Vec<GhostClass>), String>;

/// Where a bake stands.
pub type BakePoll = JobPoll<BakeOutcome>;

/// A bake running on its thread.
pub type BakeJob = Job<BakeOutcome>;

/// What a new bake says it is doing.
pub const CLASSIFYING: &str = "classifying the ghosts…";

/// Classifies `flare`'s ghosts and bakes the non-linear ones at the default settings on a new thread;
/// `previous` lends the ghosts whose key is unchanged.
pub fn start_bake(flare: Arc<PreparedFlare>, previous: Option<GhostLut>) -> BakeJob {
    Job::spawn(CLASSIFYING, move |cancel, progress| {
        let renderer = flare.ray_grid_renderer();
        let settings = ClassifySettings::for_flare(&flare, useful_field_deg(&flare));
        let classes = classify(&flare, &renderer, &settings, &[]);
        let chosen: Vec<usize> = classes.iter().filter(|c| c.nonlinear()).map(|c| c.ghost).collect();
        let report = |p: BakeProgress| {
            progress(
                p.ghosts_done as f32 / p.ghosts_total.max(1) as f32,
                format!("{}/{} ghosts, {} entries", p.ghosts_done, p.ghosts_total, p.entries),
            );
        };
        bake(&flare, &renderer, &chosen, &BakeSettings::default(), previous.as_ref(), &report, cancel)
            .map(|lut| (lut, classes))
            .map_err(|e| e.to_string())
    })
}
