//! The shutter: a frame is the image averaged over the time the shutter is open, so a light that moves within
//! a frame streaks its ghosts (motion blur) instead of strobing.
//!
//! # How it works
//! A shutter of `shutter_deg` degrees is open for `shutter_deg / 360` of a frame, centred on the frame's time
//! (`open_interval`: frame 10 at 180 degrees is open from 9.75 to 10.25), so the blurred frame's streaks are
//! centred where the sharp frame's ghosts are; 0 degrees is the sharp frame exactly (no path, nothing added).
//! While it is open the light follows a [`LightPath`]: [`PATH_POINTS`] points evenly spaced from the opening
//! to the closing, each with the light's position and its intensity relative to the frame's own (from the
//! timeline's keys as they interpolate, or from a track of positions found in the plate), read between points
//! linearly ([`LightPath::at`]).
//!
//! `plan_samples` chooses how many time samples each ghost needs: every paraxial sprite of the frame is laid
//! out at each path point (the same culling as the frame) and followed by its ghost and wavelength; the
//! distance its quad's farthest corner travels (the centre's motion plus the half-size's growth, in pixels,
//! summed along the path over every step where the sprite is drawn at either end, the longest of the ghost's
//! wavelengths) gives the ghost the smallest `2^j + 1` samples at least `ceil(length) + 1`, evenly spaced from
//! opening to closing inclusive: no two consecutive images of its centre or its edges are more than a pixel
//! apart. A ghost that moves less than half a pixel is drawn once, at the frame's time
//! (unless the light's intensity changes while the shutter is open: then every ghost gets at least
//! [`PATH_POINTS`] samples). The frame is built at the most any ghost needs (at most `MAX_SAMPLES`; a
//! longer path leaves gaps, and [`ShutterSamples::max_gap_px`] says how large), and since the sample counts
//! are all `2^j + 1`, each ghost's samples are every `2^(m - j)`th of the frame's: a slow ghost costs a few
//! sprites, not as many as the fastest. [`crate::frame::Frame::build`] builds the frame at each sample with
//! the light's gain times the path's intensity there, keeps of each ghost the sprites and LUT instances of its
//! own samples weighted by 1 / its samples, and draws them all in one frame: the accumulation is additive, so
//! the drawn frame is the time average (the same on the GPU and its CPU twin, in the app, `render`, sequences
//! and per-ghost layers). A streak therefore holds the energy of the
//! sharp frame (up to the change of the ghosts' brightness along the path). The starburst (the light's own
//! image) stays at the frame's time: it is not streaked (its reach is the frame's largest quad: streaking it
//! would draw that once per sample, up to `MAX_SAMPLES` times; at 11.7 ms a pass on lavapipe for a 1280x720
//! frame, about 3 s a frame). LUT ghosts composited over the flare through alpha (`blend.mode` alpha) keep
//! colour and coverage each times the sample's weight, and each ghost's samples are put next to each other
//! ([`crate::lut::blend::LutScene::group_by_ghost`]) so that the passes lay them over the flare at once with their
//! summed coverage: where all n samples cover a pixel with coverage a, what lies beneath keeps `1 - a`, the time
//! average over a still flare (one after another it kept `(1 - a / n)^n`).

use crate::flare::PreparedFlare;
use crate::ghost::{Sensor, light_slopes_for_frame_position};

/// The widest shutter (degrees): open the whole frame.
pub const MAX_SHUTTER_DEG: f64 = 360.0;
/// Points of a [`LightPath`] from the shutter's opening to its closing.
pub const PATH_POINTS: usize = 9;
/// The most time samples one frame is built at (`2^8 + 1`).
pub(crate) const MAX_SAMPLES: usize = 257;

/// Frames (as fractional frame numbers) during which a shutter of `shutter_deg` is open at `frame`: centred
/// on it (see the module documentation). A shutter that is not finite or not positive is closed (0 degrees).
pub(crate) fn open_interval(frame: f64, shutter_deg: f64) -> (f64, f64) {
    let deg = if shutter_deg.is_finite() { shutter_deg.clamp(0.0, MAX_SHUTTER_DEG) } else { 0.0 };
    let half = deg / 720.0;
    (frame - half, frame + half)
}

/// Refuses a shutter angle outside 0 to 360 degrees.
pub(crate) fn check_shutter(shutter_deg: f64) -> Result<(), String> {
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
        if close.partial_cmp(&open) != Some(std::cmp::Ordering::Greater) {
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

/// How a frame's shutter is sampled (see `plan_samples`).
#[derive(Clone, Debug, PartialEq)]
pub struct ShutterSamples {
    /// Time samples the frame is built at (`2^m + 1`, evenly spaced from opening to closing; 1: the light did
    /// not move far enough to streak).
    pub count: usize,
    /// Per lens ghost, how many of those samples it is drawn at (`2^j + 1`, every `(count - 1) / (n - 1)`th;
    /// 1: the middle one alone, for a ghost that does not move).
    pub per_ghost: Vec<usize>,
    /// The longest path of any sprite while the shutter is open (pixels of the frame).
    pub longest_px: f64,
    /// The largest step between two consecutive images of any ghost (at most 1 pixel unless the samples were
    /// capped at `MAX_SAMPLES`).
    pub max_gap_px: f64,
}

impl ShutterSamples {
    /// Whether lens ghost `ghost` is drawn at sample `k` of [`Self::count`], and with what weight (1 / its
    /// samples). A ghost the plan does not know (a photographed LUT's whole flare) is drawn at every sample.
    pub fn weight(&self, ghost: usize, k: usize) -> Option<f32> {
        let n = self.per_ghost.get(ghost).copied().unwrap_or(self.count).clamp(1, self.count.max(1));
        if n == 1 {
            return (k == (self.count - 1) / 2).then_some(1.0);
        }
        let stride = (self.count - 1) / (n - 1);
        k.is_multiple_of(stride).then_some(1.0 / n as f32)
    }

    /// The instances a frame draws for each one of a still frame: the mean of the ghosts' samples.
    pub fn mean_per_ghost(&self) -> f64 {
        if self.per_ghost.is_empty() {
            return 1.0;
        }
        self.per_ghost.iter().sum::<usize>() as f64 / self.per_ghost.len() as f64
    }
}

/// One path point's sprites by (ghost, wavelength): whether each is drawn there, and its centre and half-size
/// (mm, the half-size's magnitude per axis).
type SpritesAt = std::collections::HashMap<(usize, usize), (bool, [f64; 4])>;

/// The smallest `2^j + 1` samples that put no more than a pixel between consecutive images along a path of
/// `length_px`, capped at [`MAX_SAMPLES`]; at least `least`.
fn samples_for(length_px: f64, least: usize) -> usize {
    let need = if length_px.is_finite() { length_px.ceil().max(0.0) as usize + 1 } else { MAX_SAMPLES };
    let mut n = 2;
    while n < need.max(least) && n < MAX_SAMPLES {
        n = 2 * n - 1;
    }
    n
}

/// How many samples `path` needs in a frame `width` pixels wide on `sensor` at the flare's gain `flare_gain`
/// (see the module documentation): per lens ghost, from the longest path of its sprites, and for the frame the
/// most any ghost needs.
pub(crate) fn plan_samples(
    flare: &PreparedFlare,
    path: &LightPath,
    sensor: Sensor,
    width: u32,
    flare_gain: f32,
) -> ShutterSamples {
    let settings = flare.frame_settings_on(sensor, width, flare_gain);
    let px_per_mm = f64::from(width) / sensor.width_mm;
    // Per path point, each sprite by its ghost and wavelength (never by its place in the list, which changes
    // as sprites are culled): whether it is drawn there, and its centre and half-size (mm).
    let frames: Vec<SpritesAt> = path
        .points
        .iter()
        .map(|p| {
            let u = light_slopes_for_frame_position(p.light_deg[0], p.light_deg[1]);
            let frame = flare.system.frame(u, &settings);
            frame
                .sprites
                .iter()
                .map(|s| {
                    let [cx, cy] = s.centre_mm;
                    let [hx, hy] = s.half_size_mm;
                    ((s.ghost, s.wavelength), (s.culled.is_none(), [cx, cy, hx.abs(), hy.abs()]))
                })
                .collect()
        })
        .collect();
    let ghosts = flare.system.ghosts.len();
    let mut ghost_length = vec![0.0f64; ghosts];
    let keys: std::collections::BTreeSet<(usize, usize)> = frames.iter().flat_map(|f| f.keys().copied()).collect();
    for key in keys {
        let mut length = 0.0;
        for pair in frames.windows(2) {
            // A step is seen when the sprite is drawn at either end of it (it appears or fades within it), and
            // its length is the farthest any corner of the sprite's quad moves: the centre's motion plus the
            // growth of its half-size, per axis.
            let (Some(&(drawn_a, a)), Some(&(drawn_b, b))) = (pair[0].get(&key), pair[1].get(&key)) else { continue };
            if !(drawn_a || drawn_b) {
                continue;
            }
            let along = |i: usize| ((b[i] - a[i]).abs() + (b[i + 2] - a[i + 2]).abs()) * px_per_mm;
            let step = along(0).hypot(along(1));
            if step.is_finite() {
                length += step;
            }
        }
        if let Some(g) = ghost_length.get_mut(key.0) {
            *g = g.max(length);
        }
    }
    // A light whose intensity changes while the shutter is open needs every ghost sampled along the path.
    let first_gain = path.points.first().map_or(1.0, |p| p.gain);
    let least = if path.points.iter().any(|p| p.gain != first_gain) { PATH_POINTS } else { 1 };
    let per_ghost: Vec<usize> =
        ghost_length.iter().map(|&l| if l < 0.5 && least == 1 { 1 } else { samples_for(l, least) }).collect();
    let longest_px = ghost_length.iter().copied().fold(0.0, f64::max);
    let count = if path.moves() { per_ghost.iter().copied().max().unwrap_or(1) } else { 1 };
    let max_gap_px = ghost_length
        .iter()
        .zip(&per_ghost)
        .map(|(&l, &n)| if n > 1 { l / (n - 1) as f64 } else { l })
        .fold(0.0, f64::max);
    ShutterSamples { count, per_ghost, longest_px, max_gap_px }
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
    fn sample_counts_nest_and_weights_sum_to_one() {
        assert_eq!(samples_for(0.0, 1), 2);
        assert_eq!(samples_for(1.0, 1), 2);
        assert_eq!(samples_for(1.5, 1), 3);
        assert_eq!(samples_for(7.9, 1), 9);
        assert_eq!(samples_for(8.1, 1), 17);
        assert_eq!(samples_for(1e9, 1), MAX_SAMPLES);
        assert_eq!(samples_for(f64::NAN, 1), MAX_SAMPLES);
        assert_eq!(samples_for(0.0, PATH_POINTS), PATH_POINTS);
        let s = ShutterSamples { count: 17, per_ghost: vec![1, 2, 3, 5, 9, 17], longest_px: 16.0, max_gap_px: 1.0 };
        for g in 0..7 {
            let weights: Vec<f32> = (0..17).filter_map(|k| s.weight(g, k)).collect();
            let n = s.per_ghost.get(g).copied().unwrap_or(17);
            assert_eq!(weights.len(), n, "ghost {g}");
            assert!((weights.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        assert_eq!(s.weight(0, 8), Some(1.0), "a still ghost is drawn at the middle sample");
        assert_eq!(s.weight(1, 0).and(s.weight(1, 16)), Some(0.5), "two samples: the opening and the closing");
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
