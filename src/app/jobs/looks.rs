//! The Looks panel's state: the presets shipped in the binary as rendered thumbnails (the panel and applying a
//! look: [`crate::app::looks_panel`]).
//!
//! # How it works
//! The first time the panel is shown, a worker ([`super::job::Job`]) renders every shipped preset's thumbnail
//! through the one frame pipeline on the CPU twin ([`flare_core::preset::Document::thumbnail`]); the panel shows
//! the ones done so far and the worker's progress, and keeps the textures for the session (the thumbnails are made
//! once). Clicking a look replaces the document's optics and display with the look's
//! ([`flare_core::preset::Document::with_look`]: the look's camera comes with it, the plate and the timeline stay,
//! so the view frames what `flarelab render --preset NAME` draws) as one undo step; the
//! automatic bake then fetches or bakes its LUT ghosts.

use std::sync::{Arc, Mutex};

use eframe::egui;
use flare_core::image::DisplayImage;
use flare_core::preset::shipped;

use super::job::{Job, JobPoll, Priority};

/// Thumbnail size in pixels.
pub const THUMB: (u32, u32) = (192, 108);

/// One look's thumbnail as the worker made it (or why it could not).
type Rendered = (usize, Result<DisplayImage, String>);

/// The panel's state.
#[derive(Default)]
pub struct Looks {
    job: Option<Job<()>>,
    /// Rendered by the worker, not yet uploaded.
    done: Arc<Mutex<Vec<Rendered>>>,
    /// Per shipped preset: its texture, or why there is none.
    pub thumbnails: Vec<Option<Result<egui::TextureHandle, String>>>,
    /// The user cancelled the thumbnails: not started again until they ask ([`Self::resume`]).
    pub cancelled: bool,
}

impl Looks {
    /// Starts the worker for the thumbnails not made yet, unless one runs, all are made or the user cancelled.
    pub(crate) fn start(&mut self) {
        if self.job.is_some() || self.cancelled || self.ready() {
            return;
        }
        if self.thumbnails.is_empty() {
            self.thumbnails = vec![None; shipped().len()];
        }
        let missing: Vec<usize> = (0..self.thumbnails.len()).filter(|&k| self.thumbnails[k].is_none()).collect();
        let done = self.done.clone();
        self.job = Some(Job::spawn_with(Priority::Background, "rendering the looks…", move |cancel, progress| {
            // A pool of its own: a background bake keeps rayon's global pool busy for half a minute, and the
            // thumbnails should not wait for it.
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().ok();
            let total = missing.len();
            for (n, &k) in missing.iter().enumerate() {
                if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                    return;
                }
                progress(n as f32 / total as f32, format!("rendering the looks: {n}/{total}"));
                let preset = &shipped()[k];
                let render =
                    || preset.document().and_then(|d| d.thumbnail(THUMB.0, THUMB.1)).map_err(|e| e.to_string());
                let image = match &pool {
                    Some(pool) => pool.install(render),
                    None => render(),
                };
                if let Ok(mut d) = done.lock() {
                    d.push((k, image));
                }
            }
        }));
    }

    /// The worker's progress (`None` when it does not run).
    pub fn progress(&self) -> Option<(f32, String)> {
        self.job.as_ref().map(Job::progress)
    }

    /// True while the worker runs (or a cancelled one has not stopped yet).
    pub fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// Stops the worker after the thumbnail it is drawing (the ones made stay); the panel offers to go on.
    pub fn cancel(&mut self) {
        if let Some(job) = &self.job {
            job.cancel();
            self.cancelled = true;
        }
    }

    /// Goes on with the thumbnails not made (after Cancel).
    pub fn resume(&mut self) {
        self.cancelled = false;
        self.start();
    }

    /// Uploads what the worker finished; true while it still runs.
    pub(crate) fn poll(&mut self, ctx: &egui::Context) -> bool {
        let finished: Vec<Rendered> = self.done.try_lock().map(|mut d| std::mem::take(&mut *d)).unwrap_or_default();
        for (k, image) in finished {
            self.thumbnails[k] = Some(image.map(|img| {
                let pixels: Vec<egui::Color32> =
                    img.pixels.iter().map(|p| egui::Color32::from_rgb(p[0], p[1], p[2])).collect();
                let color = egui::ColorImage::new([img.width as usize, img.height as usize], pixels);
                ctx.load_texture(format!("look {k}"), color, egui::TextureOptions::LINEAR)
            }));
        }
        if let Some(job) = &self.job
            && let JobPoll::Finished(()) = job.poll()
        {
            self.job = None;
        }
        self.job.is_some()
    }

    /// True once every thumbnail is made (for the tests).
    pub fn ready(&self) -> bool {
        !self.thumbnails.is_empty() && self.thumbnails.iter().all(Option::is_some)
    }
}
