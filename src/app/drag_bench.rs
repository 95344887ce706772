//! `FLARELAB_DRAG_BENCH=N`: the app measuring itself. The light (or, with `FLARELAB_DRAG_BENCH_WHAT=exposure`,
//! the flare's exposure from 6 to 14 EV) moves one step a frame for N frames; then the median frame interval,
//! the median scene build and what was rebuilt during the sweep are printed and the window closes.

use std::time::Instant;

use flare_core::preset::Document;

use super::derived::RebuildCounts;

/// The drag bench's state.
pub struct DragBench {
    /// Sweep the exposure instead of the light.
    exposure: bool,
    /// What had been rebuilt when the sweep began (after the first frame).
    rebuilds_at_start: Option<RebuildCounts>,
    frames: usize,
    done: usize,
    last: Option<Instant>,
    intervals_ms: Vec<f64>,
    scene_ms: Vec<f64>,
}

impl DragBench {
    /// The bench `FLARELAB_DRAG_BENCH` asks for, if any.
    pub fn from_env() -> Option<Self> {
        let frames = std::env::var("FLARELAB_DRAG_BENCH").ok()?.parse().ok()?;
        Some(Self {
            exposure: std::env::var("FLARELAB_DRAG_BENCH_WHAT").is_ok_and(|w| w == "exposure"),
            rebuilds_at_start: None,
            frames,
            done: 0,
            last: None,
            intervals_ms: Vec::new(),
            scene_ms: Vec::new(),
        })
    }

    /// One frame: records its interval, moves the light or the exposure of `doc`, and when the sweep is done
    /// returns the report line.
    pub fn step(
        &mut self,
        doc: &mut Document,
        scene_ms: f64,
        rebuilds: RebuildCounts,
        view_px: (u32, u32),
    ) -> Option<String> {
        let now = Instant::now();
        if let Some(last) = self.last {
            self.intervals_ms.push(now.duration_since(last).as_secs_f64() * 1e3);
            self.scene_ms.push(scene_ms);
        }
        // The first frame builds the optics and uploads the textures; rebuilds are counted after it.
        if self.done == 1 {
            self.rebuilds_at_start = Some(rebuilds);
        }
        self.last = Some(now);
        let t = self.done as f64 / self.frames.max(1) as f64;
        if self.exposure {
            doc.flare_ev = 6.0 + 8.0 * t;
        } else {
            doc.light_deg = [-20.0 + 40.0 * t, -10.0 + 20.0 * t];
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
        let start = self.rebuilds_at_start.unwrap_or(rebuilds);
        Some(format!(
            "drag bench: {}: {} frames at {}x{}: median frame interval {interval:.1} ms, median scene build {scene:.2} ms; {} optics rebuilds, {} texture uploads, {} frames built during the sweep",
            if self.exposure { "exposure" } else { "light" },
            self.frames,
            view_px.0,
            view_px.1,
            rebuilds.optics - start.optics,
            rebuilds.textures - start.textures,
            rebuilds.frames - start.frames,
        ))
    }
}
