//! `FLARELAB_DRAG_BENCH=N`: the app measuring itself. The light (or, with `FLARELAB_DRAG_BENCH_WHAT=exposure`,
//! the flare's exposure from 6 to 14 EV; with `FLARELAB_DRAG_BENCH_WHAT=scrub`, the playhead, one frame of the
//! timeline a UI frame, plates read and all; with `FLARELAB_DRAG_BENCH_WHAT=blades`, the blades' rotation from
//! 0 to 60 degrees, a stop shape not seen before every frame, its optics rebuilt and its mask levels and
//! starburst made and uploaded) moves one step a frame for N frames, as a drag would (the viewport
//! draws drafts, see [`super::draft`]); then it lets go, waits for the full-quality frame, and prints the
//! median frame interval, the median scene build, what the drafts drew, how long after letting go the full
//! frame was on screen and what was rebuilt during the sweep; the window closes.

use std::time::Instant;

use flare_core::frame::DraftOutcome;
use flare_core::preset::Document;

use super::derived::RebuildCounts;

/// What the bench sweeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sweep {
    Light,
    Exposure,
    Scrub,
    Blades,
}

/// The drag bench's state.
pub struct DragBench {
    what: Sweep,
    /// What had been rebuilt when the sweep began (after the first frame).
    rebuilds_at_start: Option<RebuildCounts>,
    frames: usize,
    done: usize,
    last: Option<Instant>,
    intervals_ms: Vec<f64>,
    scene_ms: Vec<f64>,
    /// Sprites drawn by each draft frame, and their divisor.
    drawn: Vec<f64>,
    sprites: Vec<f64>,
    /// The GPU's own time of the flare's passes (timestamp queries), per frame where known.
    gpu_ms: Vec<f64>,
    divisor: u32,
    /// The adapter that measured `gpu_ms`, and the last draft's time by pass.
    adapter: String,
    last_passes: String,
    /// When the sweep let go, and the line waiting for the full frame.
    released: Option<(Instant, String)>,
}

impl DragBench {
    /// The bench of `frames` frames sweeping `what` (`FLARELAB_DRAG_BENCH`, read by [`super::options`]).
    pub fn new(frames: usize, what: Sweep) -> Self {
        Self {
            what,
            rebuilds_at_start: None,
            frames,
            done: 0,
            last: None,
            intervals_ms: Vec::new(),
            scene_ms: Vec::new(),
            drawn: Vec::new(),
            sprites: Vec::new(),
            gpu_ms: Vec::new(),
            divisor: 1,
            adapter: String::new(),
            last_passes: String::new(),
            released: None,
        }
    }

    /// Still moving (the app draws drafts).
    pub fn sweeping(&self) -> bool {
        self.done <= self.frames
    }

    /// One frame: records its interval, moves the light or the exposure of `doc`; after the sweep, the frame
    /// after letting go (the full one, `draft` none, was drawn in the UI frame before) returns the report line.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        doc: &mut Document,
        playhead: &mut i64,
        scene_ms: f64,
        rebuilds: RebuildCounts,
        view_px: (u32, u32),
        draft: Option<DraftOutcome>,
        flare_gpu: Option<(String, f64, String)>,
    ) -> Option<String> {
        let now = Instant::now();
        if let Some((at, line)) = &self.released {
            if draft.is_some() {
                return None;
            }
            let ms = now.duration_since(*at).as_secs_f64() * 1e3;
            return Some(format!("{line}; full quality {ms:.0} ms after letting go"));
        }
        if let Some(last) = self.last {
            self.intervals_ms.push(now.duration_since(last).as_secs_f64() * 1e3);
            self.scene_ms.push(scene_ms);
            if let Some((adapter, ms, passes)) = flare_gpu {
                self.gpu_ms.push(ms);
                self.adapter = adapter;
                self.last_passes = passes;
            }
            if let Some(d) = draft {
                self.drawn.push(d.drawn as f64);
                self.sprites.push((d.drawn + d.skipped) as f64);
                self.divisor = d.divisor;
            }
        }
        // The first frame builds the optics and uploads the textures; rebuilds are counted after it.
        if self.done == 1 {
            self.rebuilds_at_start = Some(rebuilds);
        }
        self.last = Some(now);
        let t = self.done as f64 / self.frames.max(1) as f64;
        match self.what {
            Sweep::Exposure => {
                // As the slider does: a moved exposure is the user's, locked.
                doc.exposure_auto = false;
                doc.flare_ev = 6.0 + 8.0 * t;
            }
            Sweep::Light => doc.light_deg = [-20.0 + 40.0 * t, -10.0 + 20.0 * t],
            // The aperture panel's rotation slider, dragged (an image stop has no blades to turn).
            Sweep::Blades => {
                doc.aperture.image = None;
                doc.aperture.rotation_deg = 60.0 * t;
            }
            Sweep::Scrub => {
                let (first, last) = (doc.timeline.first_frame, doc.timeline.last_frame);
                *playhead = first + (self.done as i64).rem_euclid(last - first + 1);
            }
        }
        self.done += 1;
        if self.done <= self.frames {
            return None;
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        };
        let (interval, scene) = (median(&mut self.intervals_ms), median(&mut self.scene_ms));
        let (drawn, sprites) = (median(&mut self.drawn), median(&mut self.sprites));
        let gpu = if self.gpu_ms.is_empty() {
            "no GPU timestamps".to_owned()
        } else {
            format!(
                "the flare's passes took a median {:.1} ms of GPU time ({}; the last draft: {})",
                median(&mut self.gpu_ms),
                self.adapter,
                self.last_passes
            )
        };
        let start = self.rebuilds_at_start.unwrap_or(rebuilds);
        let line = format!(
            "drag bench: {}: {} frames at {}x{}: median frame interval {interval:.1} ms, median scene build {scene:.2} ms; drafts at 1/{} resolution drew a median {drawn:.0} of {sprites:.0} sprites; {gpu}; {} optics rebuilds, {} texture uploads, {} frames built during the sweep",
            match self.what {
                Sweep::Exposure => "exposure",
                Sweep::Light => "light",
                Sweep::Scrub => "scrub",
                Sweep::Blades => "blades",
            },
            self.frames,
            view_px.0,
            view_px.1,
            self.divisor,
            rebuilds.optics - start.optics,
            rebuilds.textures - start.textures,
            rebuilds.frames - start.frames,
        );
        self.released = Some((now, line));
        None
    }
}
