//! Holding a frame time while the user drags: the viewport draws drafts ([`flare_core::frame::Draft`]) while
//! the light is dragged or a value scrubbed, and the full-quality frame once input stops.
//!
//! # How it works
//! Each UI frame [`DraftControl::step`] is told whether the user is interacting (a drag in progress with the
//! pointer moved in the last [`STILL_S`] seconds, an arrow key held, or the drag bench sweeping). While
//! interacting, the frame is a draft at a coarser accumulation (1/4 on a software adapter, 1/2 on a GPU) with a
//! budget of accumulation fragments for the paraxial sprites, the faintest skipped first. The budget follows the
//! measured interval between UI frames, of which the flare is only a part: the rest of the window (egui's
//! panels, the ray diagram, presenting) costs what it costs. The flare's part is the GPU's own time of its
//! passes (timestamp queries, [`flare_core::render::gpu::PassTimes`]) where the adapter has them; otherwise
//! the interval above its floor, the shortest recent interval (rising 2% a frame, so that it follows a window
//! that got dearer). The flare may have what is left of [`TARGET_MS`] after the rest, and never less than a
//! fifth of the rest (on a software adapter a 1280x720 window alone can cost more than the target, and
//! starving the flare would only empty it); the budget is multiplied by that allowance over the flare's
//! measured part, at most halved or grown by half a step each frame. When input
//! stops the next frame is the full one (the app asks for a repaint so that it comes even if nothing else
//! happens). The status bar says which it shows.

use std::time::Instant;

use flare_core::frame::Draft;

/// The frame interval the drafts aim at (ms).
pub const TARGET_MS: f64 = 35.0;
/// A drag whose pointer has not moved for this long counts as stopped (s).
pub const STILL_S: f32 = 0.25;
/// The first draft's budget on a software adapter (accumulation fragments): low, since the budget grows by half
/// a frame while the flare costs little. The first drag of issue 60's replay (the zoom at +25 EV on lavapipe)
/// drew its first draft in 124 ms from 1.5 M fragments, an input waiting behind it; the budget it settled at
/// drew in 2-10 ms.
pub const SOFTWARE_START_BUDGET: u64 = 100_000;
/// The budget's bounds (accumulation fragments).
const MIN_BUDGET: u64 = 20_000;
const MAX_BUDGET: u64 = 2_000_000_000;

/// The draft controller (see the module documentation).
#[derive(Clone, Debug)]
pub struct DraftControl {
    divisor: u32,
    budget: u64,
    last_step: Option<Instant>,
    drafting: bool,
    /// The shortest recent interval while drafting (ms): the window's cost without the flare, roughly.
    floor_ms: Option<f64>,
}

impl DraftControl {
    /// Drafts at 1/4 resolution on a software adapter (starting from a budget of [`SOFTWARE_START_BUDGET`]
    /// fragments), at 1/2 on a GPU (starting with room for everything).
    pub fn new(software: bool) -> Self {
        let Draft { divisor, fragment_budget: budget } = Self::first_draft(software);
        Self { divisor, budget, last_step: None, drafting: false, floor_ms: None }
    }

    /// The first draft of a drag (what the viewport warms its draft passes with on a software adapter).
    pub fn first_draft(software: bool) -> Draft {
        let (divisor, fragment_budget) = if software { (4, SOFTWARE_START_BUDGET) } else { (2, MAX_BUDGET) };
        Draft { divisor, fragment_budget }
    }

    /// One UI frame at `now`: the draft to draw when `interacting`, `None` for the full frame. `flare_gpu_ms`
    /// is the GPU time of the flare's passes in a recent frame, when the adapter measures it.
    pub fn step(&mut self, interacting: bool, flare_gpu_ms: Option<f64>, now: Instant) -> Option<Draft> {
        let interval_ms = self.last_step.map(|t| now.duration_since(t).as_secs_f64() * 1e3);
        self.last_step = Some(now);
        if !interacting {
            self.drafting = false;
            return None;
        }
        if self.drafting
            && let Some(ms) = interval_ms.filter(|ms| *ms > 0.0)
        {
            let floor = self.floor_ms.map_or(ms, |f| (f * 1.02).min(ms));
            self.floor_ms = Some(floor);
            // The flare's part of the interval, and the rest of the window's.
            let (flare, rest) = match flare_gpu_ms.filter(|t| t.is_finite() && *t >= 0.0) {
                Some(gpu) => (gpu.min(ms), (ms - gpu).max(0.0)),
                None => (ms - floor, floor),
            };
            let allowed = (TARGET_MS - rest).max(0.2 * rest);
            let flare = flare.max(0.05 * allowed);
            let factor = (allowed / flare).clamp(0.5, 1.5);
            self.budget = ((self.budget as f64 * factor) as u64).clamp(MIN_BUDGET, MAX_BUDGET);
        }
        self.drafting = true;
        Some(Draft { divisor: self.divisor, fragment_budget: self.budget })
    }

    /// Whether the last step asked for a draft.
    pub fn drafting(&self) -> bool {
        self.drafting
    }
}

/// Warming the draft passes on a software adapter before the first drag (see
/// [`crate::viewport::ViewportResources::warm_up_drafts`]): once the first frame has been shown, a draft of
/// the view is drawn aside; if the view's cube was not baked yet, again once it is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DraftWarmth {
    /// Nothing shown yet.
    #[default]
    Cold,
    /// The first frame was handed to the viewport: warm in a later UI frame, after it was presented.
    Shown,
    /// Warmed once, before the view's cube was baked: warm again when it is.
    AwaitingCube,
    /// Done (or nothing to do: a hardware GPU, or no viewport).
    Warm,
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    /// A flare that costs more than the window's floor allows shrinks the budget, one that costs little grows
    /// it, each step by at most half; input stopping gives the full frame at once.
    #[test]
    fn the_budget_follows_the_flares_share_of_the_frame() {
        let mut control = DraftControl::new(true);
        let mut t = Instant::now();
        let first = control.step(true, None, t).unwrap();
        assert_eq!(first.divisor, 4);
        let mut step = |control: &mut DraftControl, ms: u64| {
            t += Duration::from_millis(ms);
            control.step(true, None, t).unwrap().fragment_budget
        };
        // The first interval sets the floor (10 ms): the flare's share is nil, the budget grows.
        let grown = step(&mut control, 10);
        assert_eq!(grown, first.fragment_budget * 3 / 2);
        // 130 ms against a floor of 10.2 and a target of 35: the flare takes far too much, halve.
        let halved = step(&mut control, 130);
        assert_eq!(halved, grown / 2);
        // 35 ms: on target, the budget stays (within rounding).
        let kept = step(&mut control, TARGET_MS as u64);
        assert!((kept as f64 / halved as f64 - 1.0).abs() < 0.03, "{kept} vs {halved}");
        assert!(control.step(false, None, t + Duration::from_millis(50)).is_none());
        assert!(!control.drafting());
        // After a pause the first draft does not count the pause as a slow frame.
        let again = control.step(true, None, t + Duration::from_secs(5)).unwrap();
        assert_eq!(again.fragment_budget, kept);
        // A window dearer than the target (a floor of 60 ms): the flare still gets a fifth of it.
        let mut slow = DraftControl::new(true);
        let mut t = Instant::now();
        let start = slow.step(true, None, t).unwrap().fragment_budget;
        for ms in [60, 60, 66] {
            t += Duration::from_millis(ms);
            slow.step(true, None, t);
        }
        t += Duration::from_millis(72);
        let budget = slow.step(true, None, t).unwrap().fragment_budget;
        assert!(budget >= start, "{budget} < {start}: 12 ms of flare on a 60 ms floor is within its fifth");
        assert_eq!(DraftControl::new(false).step(true, None, t).unwrap().divisor, 2);
        // With the GPU's own times: 45 ms frames of which the flare took 30: 15 ms of window leaves it 20 of
        // the 35 ms target, so the budget goes to two thirds.
        let mut timed = DraftControl::new(true);
        let mut t = Instant::now();
        let start = timed.step(true, Some(30.0), t).unwrap().fragment_budget;
        t += Duration::from_millis(45);
        let next = timed.step(true, Some(30.0), t).unwrap().fragment_budget;
        assert!((next as f64 / start as f64 - 2.0 / 3.0).abs() < 1e-3, "{next} vs {start}");
    }
}
