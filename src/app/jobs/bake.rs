//! The app's background bake: classification and LUT bake on a thread, with progress and Cancel, polled by
//! the UI each frame (the window never blocks); the thread also writes the finished LUT into the on-disk
//! cache, so a large LUT never stalls a frame.

use std::sync::Arc;

use super::job::{Job, JobPoll, Priority};

use flare_core::bake::cache::LutCache;
use flare_core::bake::classify::{ClassifySettings, GhostClass, classify_until};
use flare_core::bake::{BakeProgress, BakeSettings, bake_with, useful_field_deg};
use flare_core::flare::PreparedFlare;
use flare_core::lut::blend::LiveLut;
use flare_core::render::gpu::GpuContext;
use flare_core::render::raygrid::{GpuBake, SUPERSAMPLE};

/// A finished bake: the LUT, the classification that chose its ghosts, and whether it went into the cache
/// (the error when it could not).
pub struct Baked {
    /// The LUT, prepared for the frame on the bake's thread (its mip levels and atlas layout: a large LUT took
    /// 0.4 s of the UI thread there, and its clone 0.2 s more).
    pub lut: LiveLut,
    pub classes: Vec<GhostClass>,
    pub cached: Result<(), String>,
    /// Where its columns were traced: "on the CPU", "on the GPU (adapter)", or the GPU then the CPU and why.
    pub device: String,
}

/// What a bake thread hands back, or why it stopped.
pub type BakeOutcome = Result<Baked, String>;

/// Where a bake stands.
pub type BakePoll = JobPoll<BakeOutcome>;

/// A bake running on its thread.
pub type BakeJob = Job<BakeOutcome>;

/// What a new bake says it is doing.
pub const CLASSIFYING: &str = "classifying the ghosts…";

/// Classifies `flare`'s ghosts and bakes the non-linear ones with `settings` on a new thread (each column on
/// a hardware GPU when there is one, else on the CPU), then stores the LUT in `cache`; `previous` lends the
/// ghosts whose key is unchanged.
pub fn start_bake(
    flare: Arc<PreparedFlare>,
    previous: Option<Arc<LiveLut>>,
    settings: BakeSettings,
    cache: Option<LutCache>,
) -> BakeJob {
    Job::spawn_with(Priority::Background, CLASSIFYING, move |cancel, progress| {
        let renderer = flare.ray_grid_renderer();
        let classify_settings = ClassifySettings::for_flare(&flare, useful_field_deg(&flare));
        // Cancel stops the classification too (a large lens takes a minute there before its first entry).
        let classes = classify_until(&flare, &renderer, &classify_settings, &[], cancel)
            .ok_or_else(|| flare_core::bake::BakeError::Cancelled.to_string())?;
        let chosen: Vec<usize> = classes.iter().filter(|c| c.nonlinear()).map(|c| c.ghost).collect();
        let report = |p: BakeProgress| {
            progress(
                p.ghosts_done as f32 / p.ghosts_total.max(1) as f32,
                format!("{}/{} ghosts, {} entries", p.ghosts_done, p.ghosts_total, p.entries),
            );
        };
        // A hardware GPU traces the columns when there is one (a software adapter is slower than the CPU).
        let gpu = GpuContext::hardware().ok();
        let on_gpu = gpu.as_ref().map(|ctx| GpuBake::new(ctx, SUPERSAMPLE));
        let lut = bake_with(
            &flare,
            &renderer,
            GpuBake::or_cpu(on_gpu.as_ref()),
            &chosen,
            &settings,
            previous.as_deref().map(|live| &live.lut),
            &report,
            cancel,
        )
        .map_err(|e| e.to_string())?;
        let device = match (&gpu, on_gpu.as_ref().and_then(GpuBake::fell_back)) {
            (None, _) => "on the CPU".to_owned(),
            (Some(ctx), None) => format!("on the GPU ({})", ctx.adapter.name),
            (Some(ctx), Some(why)) => format!("on the GPU ({}), then on the CPU: {why}", ctx.adapter.name),
        };
        let cached = match &cache {
            Some(cache) => cache
                .store(&flare.system.lens, &flare.config, &settings, &lut)
                .map(|_| ())
                .map_err(|e| format!("the LUT could not be cached in {}: {e}", cache.dir.display())),
            None => Ok(()),
        };
        let lut = LiveLut::new(lut);
        Ok(Baked { lut, classes, cached, device })
    })
}
