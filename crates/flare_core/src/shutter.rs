//! The shutter: a frame is the image averaged over the time the shutter is open, so a light that moves within
//! a frame streaks its ghosts (motion blur) instead of strobing.
//!
//! # How it works
//! A shutter of `shutter_deg` degrees is open for `shutter_deg / 360` of a frame, centred on the frame's time
//! ([`open_interval`]: frame 10 at 180 degrees is open from 9.75 to 10.25), so the blurred frame's streaks are
//! centred where the sharp frame's ghosts are; 0 degrees is the sharp frame exactly (no path, nothing added).
//! While it is open the light follows a [`LightPath`]: [`PATH_POINTS`] points evenly spaced from the opening
//! to the closing, each with the light's position and its intensity relative to the frame's own (from the
//! timeline's keys as they interpolate, or from a track of positions found in the plate), read between points
//! linearly ([`LightPath::at`]).
//!
//! [`plan_samples`] chooses how many time samples the frame needs: every paraxial sprite of the frame is laid
//! out at each path point (the same culling as the frame), and the longest distance any sprite travels (in
//! pixels, summed along the path) decides: `ceil(longest) + 1` samples, evenly spaced from opening to closing
//! inclusive, put no two consecutive images of the fastest ghost more than a pixel apart. The samples are at
//! most [`MAX_SAMPLES`]; a path longer than that leaves gaps, and [`ShutterSamples::max_gap_px`] says how
//! large. [`crate::frame::Frame::build`] then builds the frame at each sample with the light's gain times the
//! path's intensity there, weights every sprite and LUT instance by 1 / samples and draws them all in one
//! frame: the accumulation is additive, so the drawn frame is the time average (the same on the GPU and its CPU
//! twin, in the app, `render`, sequences and per-ghost layers). A streak therefore holds the energy of the
//! sharp frame (up to the change of the ghosts' brightness along the path). The starburst (the light's own
//! image) stays at the frame's time: it is not streaked. LUT ghosts composited over the flare through alpha
//! (`blend.mode` alpha) are averaged as if added, which is exact only where the samples do not overlap.

use crate::flare::PreparedFlare;
use crate::ghost::{Sensor, light_slopes_for_frame_position, sensor_to_pixel};

/// The widest shutter (degrees): open the whole frame.
pub const MAX_SHUTTER_DEG: f64 = 360.0;
/// Points of a [`LightPath`] from the shutter's opening to its closing.
pub const PATH_POINTS: usize = 9;
/// The most time samples one frame is drawn with.
pub const MAX_SAMPLES: usize = 256;

/// Frames (as fractional frame numbers) during which a shutter of `shutter_deg` is open at `frame`: centred
/// on it (see the module documentation). A shutter that is not finite or not positive is closed (0 degrees).
pub fn open_interval(frame: f64, shutter_deg: f64) -> (f64, f64) {
    let deg = if shutter_deg.is_finite() { shutter_deg.clamp(0.0, MAX_SHUTTER_DEG) } else { 0.0 };
    let half = deg / 720.0;
    (frame - half, frame + half)
}

/// Refuses a shutter angle outside 0 to 360 degrees.
pub fn check_shutter(shutter_deg: f64) -> Result<(), String> {
    if shutter_deg.is_finite() && (0.0..=MAX_SHUTTER_DEG).contains(&shutter_deg) {
        Ok(())
    } else {
        Err(format!("{shutter_deg}: a shutter opens 0 to {MAX_SHUTTER_DEG} degrees (0: no motion blur)"))
    }
}

/// Where the light is at one instant of the open shutter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint {
    /// Frame position of the light (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    /// The light's intensity relative to the frame's own (1 at the frame's time when it does not change).
    pub gain: f64,
}

/// The light over the open shutter: points evenly spaced in time, the first at the opening, the last at the
/// closing (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct LightPath {
    pub points: Vec<PathPoint>,
}

impl LightPath {
    /// The path over the open interval `(open, close)` from `at(time) -> (light_deg, relative gain)`; `None`
    /// when the shutter is closed (`open == close`) or no position along it is finite. A position that is not
    /// finite is the first finite one of the path, a gain that is not finite is 1 and a negative one 0.
    pub fn over(open: f64, close: f64, at: impl Fn(f64) -> ([f64; 2], f64)) -> Option<Self> {
        if !(close > open) {
            return None;
        }
        let raw: Vec<([f64; 2], f64)> =
            (0..PATH_POINTS).map(|k| at(open + (close - open) * k as f64 / (PATH_POINTS - 1) as f64)).collect();
        let finite = |deg: &[f64; 2]| deg.iter().all(|v| v.is_finite());
        let fallback = raw.iter().map(|r| r.0).find(finite)?;
        let points = raw
            .into_iter()
            .map(|(deg, gain)| PathPoint {
                light_deg: if finite(&deg) { deg } else { fallback },
                gain: if gain.is_finite() { gain.max(0.0) } else { 1.0 },
            })
            .collect();
        Some(Self { points })
    }

    /// True when the light moves or changes intensity while the shutter is open (else the frame is sharp).
    pub fn moves(&self) -> bool {
        let Some(first) = self.points.first() else { return false };
        self.points.iter().any(|p| p != first)
    }

    /// The light at `s` from 0 (opening) to 1 (closing), read linearly between the path's points.
    pub fn at(&self, s: f64) -> PathPoint {
        let n = self.points.len();
        if n == 0 {
            return PathPoint { light_deg: [0.0, 0.0], gain: 1.0 };
        }
        let x = if s.is_finite() { s.clamp(0.0, 1.0) } else { 0.5 } * (n - 1) as f64;
        let i = (x.floor() as usize).min(n.saturating_sub(2));
        let (a, b) = (self.points[i], self.points[(i + 1).min(n - 1)]);
        let t = (x - i as f64).clamp(0.0, 1.0);
        let lerp = |p: f64, q: f64| p + (q - p) * t;
        PathPoint {
            light_deg: [lerp(a.light_deg[0], b.light_deg[0]), lerp(a.light_deg[1], b.light_deg[1])],
            gain: lerp(a.gain, b.gain),
        }
    }

    /// `count` samples evenly spaced from the opening to the closing, both included (one: the middle).
    pub fn samples(&self, count: usize) -> Vec<PathPoint> {
        match count {
            0 => Vec::new(),
            1 => vec![self.at(0.5)],
            n => (0..n).map(|k| self.at(k as f64 / (n - 1) as f64)).collect(),
        }
    }
}

/// How a frame's shutter is sampled (see [`plan_samples`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShutterSamples {
    /// Time samples drawn (1: the light did not move far enough to streak).
    pub count: usize,
    /// The longest path of any sprite while the shutter is open (pixels of the frame).
    pub longest_px: f64,
    /// The largest step between two consecutive images of that sprite (at most 1 pixel unless the samples
    /// were capped at [`MAX_SAMPLES`]).
    pub max_gap_px: f64,
}

/// How many samples `path` needs in a `width` x `height` frame on `sensor` at the flare's gain `flare_gain`
/// (see the module documentation).
pub fn plan_samples(
    flare: &PreparedFlare,
    path: &LightPath,
    sensor: Sensor,
    width: u32,
    height: u32,
    flare_gain: f32,
) -> ShutterSamples {
    let settings = flare.frame_settings_on(sensor, width, flare_gain);
    let centres: Vec<Vec<Option<[f64; 2]>>> = path
        .points
        .iter()
        .map(|p| {
            let u = light_slopes_for_frame_position(p.light_deg[0], p.light_deg[1]);
            let frame = flare.system.frame(u, &settings);
            frame
                .sprites
                .iter()
                .map(|s| s.culled.is_none().then(|| sensor_to_pixel(s.centre_mm, &sensor, width, height)))
                .collect()
        })
        .collect();
    let sprites = centres.iter().map(Vec::len).min().unwrap_or(0);
    let mut longest_px = 0.0f64;
    for i in 0..sprites {
        let mut length = 0.0;
        for pair in centres.windows(2) {
            // A sprite culled at either end of a step (too faint there) still moves: its step counts when it is
            // drawn at one end.
            let (a, b) = (pair[0][i], pair[1][i]);
            if let (Some(a), Some(b)) = (a, b) {
                let step = (b[0] - a[0]).hypot(b[1] - a[1]);
                if step.is_finite() {
                    length += step;
                }
            }
        }
        longest_px = longest_px.max(length);
    }
    let count = if path.moves() { ((longest_px.ceil() as usize) + 1).clamp(2, MAX_SAMPLES) } else { 1 };
    let max_gap_px = if count > 1 { longest_px / (count - 1) as f64 } else { 0.0 };
    ShutterSamples { count, longest_px, max_gap_px }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_open_interval_is_centred_and_a_closed_shutter_has_no_path() {
        assert_eq!(open_interval(10.0, 180.0), (9.75, 10.25));
        assert_eq!(open_interval(10.0, 0.0), (10.0, 10.0));
        assert_eq!(open_interval(10.0, f64::NAN), (10.0, 10.0));
        assert_eq!(open_interval(10.0, 720.0), (9.5, 10.5));
        assert!(LightPath::over(10.0, 10.0, |_| ([0.0, 0.0], 1.0)).is_none());
        assert!(check_shutter(360.0).is_ok() && check_shutter(-1.0).is_err() && check_shutter(f64::NAN).is_err());
    }

    #[test]
    fn a_path_reads_linearly_and_samples_include_both_ends() {
        let path = LightPath::over(0.0, 1.0, |t| ([4.0 * t, -2.0 * t], 1.0 + t)).unwrap();
        assert_eq!(path.points.len(), PATH_POINTS);
        assert!(path.moves());
        let s = path.samples(5);
        assert_eq!(s.first().unwrap().light_deg, [0.0, 0.0]);
        assert_eq!(s.last().unwrap().light_deg, [4.0, -2.0]);
        assert!((s[2].light_deg[0] - 2.0).abs() < 1e-12 && (s[2].gain - 1.5).abs() < 1e-12);
        assert_eq!(path.samples(1)[0], path.at(0.5));
        let still = LightPath::over(0.0, 1.0, |_| ([1.0, 1.0], 1.0)).unwrap();
        assert!(!still.moves());
        let bad =
            LightPath::over(0.0, 1.0, |t| if t > 0.4 { ([f64::NAN, 0.0], f64::INFINITY) } else { ([1.0, 2.0], 0.5) });
        let bad = bad.unwrap();
        assert!(bad.points.iter().all(|p| p.light_deg == [1.0, 2.0]));
        assert_eq!(bad.points.last().unwrap().gain, 1.0);
        assert!(LightPath::over(0.0, 1.0, |_| ([f64::NAN, 0.0], 1.0)).is_none());
    }
}
