//! The light found in the plate: where it is on each frame, and how much of it is visible.
//!
//! # How it works
//! [`detect`] reads one linear plate: every pixel whose luminance (Rec. 709: `0.2126 R + 0.7152 G + 0.0722 B`;
//! a value that is not finite counts as 0) exceeds the threshold is lit; lit pixels are grouped into
//! 8-connected regions. The light is the region of most power (the sum of its luminance), together with any
//! other lit region whose bounding box comes within `2 r + 2` pixels of its centroid, `r` being the radius of
//! a disc of the region's area: an occluder as thin as a branch that splits the sun in two leaves one light,
//! not two. Its position is the luminance-weighted centroid (pixel centres at `i + 0.5`), its power the sum.
//!
//! `solve` turns the detections of a whole range into one light per frame:
//! - **visibility** = power / unoccluded power, the unoccluded power being the user's
//!   ([`AutoLight::reference_power`]) or the largest detected in the range; it is clamped to 0..1 and is 0 on
//!   a frame with no light found where the light is on the plate (covered). A light off the plate (its region
//!   touches the border, or its track puts it within its radius of the border or beyond, and nothing is found
//!   there) is not covered, it is out of view: its visibility cannot be measured and is held from the nearest
//!   frame where it could, so its ghosts keep coming from off-screen (a light that leaves the frame behind a
//!   cloud stays dim);
//! - the visibility is **per frame**: the plate already integrates its shutter, so a frame's measured power is
//!   what the camera saw of the light while it was open, and the flare follows it frame by frame (a frame on
//!   which the sun is fully visible again has the whole flare). An optional denoise, a centred triangular
//!   window of [`AutoLight::smooth_frames`] frames (default 1: none; 5 gives weights 1 2 3 2 1, renormalised
//!   at the ends of the range), is for noisy plates whose measured power flickers; it spreads an occluder's
//!   edge over the window (a light covered for at least half the window on both sides of a frame is still
//!   exactly 0 there);
//! - **position**: a frame whose raw visibility is at least `TRUSTED_VISIBILITY` and whose region does not
//!   touch the plate's border is trusted, and its centroid is the light's position (turned into an angle by
//!   the lens's mapping). On the others (partly or fully covered, or leaving the frame: a partial centroid
//!   is biased towards the visible part) the position continues from the track: the timeline's light keys
//!   when the document has them, else the trusted positions interpolated linearly in angle, or extrapolated
//!   at constant angular velocity from the last two before (or first two after); one trusted frame alone is
//!   held. With no trusted frame at all the detected centroids are used as they are.

use serde::{Deserialize, Serialize};

use crate::image::HdrImage;

/// Raw visibility from which a frame's detected position is trusted.
pub(crate) const TRUSTED_VISIBILITY: f64 = 0.95;

/// How the light is found in the plate (the document's `auto_light`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AutoLight {
    /// Luminance (linear plate units) above which a pixel belongs to the light. HDR plates hold a sun at tens
    /// to thousands; an 8-bit plate clips at 1, so 0.99 is the most it can use.
    pub threshold: f64,
    /// The light's unoccluded power (sum of luminance over its pixels); `None`: the largest found in the range.
    pub reference_power: Option<f64>,
    /// Length of the visibility denoise in frames (odd; 1, the default: none, the flare follows each frame's
    /// measured visibility).
    pub smooth_frames: usize,
}

impl Default for AutoLight {
    fn default() -> Self {
        Self { threshold: 4.0, reference_power: None, smooth_frames: 1 }
    }
}

impl AutoLight {
    /// Why these settings cannot be used: (field, reason).
    pub fn check(&self) -> Result<(), (String, String)> {
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err(("threshold".into(), format!("{} must be a positive luminance", self.threshold)));
        }
        if let Some(p) = self.reference_power
            && !(p.is_finite() && p > 0.0)
        {
            return Err(("reference_power".into(), format!("{p} must be positive")));
        }
        if self.smooth_frames == 0 || self.smooth_frames.is_multiple_of(2) || self.smooth_frames > 101 {
            return Err(("smooth_frames".into(), format!("{} must be odd, 1 to 101", self.smooth_frames)));
        }
        Ok(())
    }
}

/// The light found in one plate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// Luminance-weighted centroid, pixels (x right, y down, from the top-left corner).
    pub centroid_px: [f64; 2],
    /// Sum of the luminance of its pixels.
    pub power: f64,
    pub pixels: usize,
    /// The region touches the plate's border (the light may be partly out of the frame).
    pub touches_border: bool,
}

/// What [`detect`] saw in one plate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scan {
    pub detection: Option<Detection>,
    /// The brightest luminance in the plate (to say why nothing was found).
    pub peak_luminance: f64,
}

/// Rec. 709 luminance of a linear pixel (0 for a value that is not finite).
pub fn luminance(p: [f32; 4]) -> f64 {
    let l = 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]);
    if l.is_finite() { l } else { 0.0 }
}

/// A lit region while grouping.
#[derive(Clone, Copy, Debug)]
struct Region {
    power: f64,
    sx: f64,
    sy: f64,
    pixels: usize,
    bbox: [usize; 4],
    touches_border: bool,
}

/// Finds the light in `plate` (see the module documentation).
pub fn detect(plate: &HdrImage, threshold: f64) -> Scan {
    let (w, h) = (plate.width as usize, plate.height as usize);
    let lum: Vec<f64> = plate.pixels.iter().map(|&p| luminance(p)).collect();
    let peak_luminance = lum.iter().copied().fold(0.0, f64::max);
    let mut label = vec![u32::MAX; w * h];
    let mut regions: Vec<Region> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if label[start] != u32::MAX || lum[start] <= threshold {
            continue;
        }
        let id = regions.len() as u32;
        let mut r = Region {
            power: 0.0,
            sx: 0.0,
            sy: 0.0,
            pixels: 0,
            bbox: [usize::MAX, usize::MAX, 0, 0],
            touches_border: false,
        };
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let l = lum[i];
            r.power += l;
            r.sx += l * (x as f64 + 0.5);
            r.sy += l * (y as f64 + 0.5);
            r.pixels += 1;
            r.bbox = [r.bbox[0].min(x), r.bbox[1].min(y), r.bbox[2].max(x), r.bbox[3].max(y)];
            r.touches_border |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let j = ny as usize * w + nx as usize;
                    if label[j] == u32::MAX && lum[j] > threshold {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        regions.push(r);
    }
    let Some(seed) = regions.iter().copied().max_by(|a, b| a.power.total_cmp(&b.power)) else {
        return Scan { detection: None, peak_luminance };
    };
    let (cx, cy) = (seed.sx / seed.power, seed.sy / seed.power);
    let reach = 2.0 * (seed.pixels as f64 / std::f64::consts::PI).sqrt() + 2.0;
    let mut light = Region { power: 0.0, sx: 0.0, sy: 0.0, pixels: 0, bbox: seed.bbox, touches_border: false };
    for r in &regions {
        // Distance from the seed's centroid to the region's bounding box (pixel centres).
        let dx = (r.bbox[0] as f64 + 0.5 - cx).max(cx - (r.bbox[2] as f64 + 0.5)).max(0.0);
        let dy = (r.bbox[1] as f64 + 0.5 - cy).max(cy - (r.bbox[3] as f64 + 0.5)).max(0.0);
        if dx.hypot(dy) <= reach {
            light.power += r.power;
            light.sx += r.sx;
            light.sy += r.sy;
            light.pixels += r.pixels;
            light.touches_border |= r.touches_border;
        }
    }
    let detection = (light.power > 0.0).then(|| Detection {
        centroid_px: [light.sx / light.power, light.sy / light.power],
        power: light.power,
        pixels: light.pixels,
        touches_border: light.touches_border,
    });
    Scan { detection, peak_luminance }
}

/// The light of one frame, solved over the range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SolvedLight {
    /// Frame position of the light (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    /// Visibility after the temporal filter (what the flare follows), 0 to 1.
    pub visibility: f64,
    /// Visibility of this frame alone.
    pub raw_visibility: f64,
    /// The position is this frame's own detection (not continued from the track).
    pub detected: bool,
    /// The light is (partly) off the plate: its visibility is held from the nearest frame where it was on it.
    pub off_plate: bool,
}

/// Why the light cannot be found.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    #[error(
        "no light found in any frame: no pixel is brighter than the threshold {threshold} (the brightest is \
         {peak:.3}); lower the threshold (an 8-bit plate clips at 1) or give the light's track"
    )]
    NothingFound { threshold: f64, peak: f64 },
}

/// Solves the light of every frame of a range (see the module documentation). `scans[i]` is frame
/// `frames[i]`'s scan (`None`: its plate could not be read, treated as no light); `to_deg` turns a pixel into
/// a light angle (`None` past the lens's field); `keyed` is the timeline's light position at a frame, if it
/// has light keys; `on_plate(light_deg, margin_px)` says whether that light's image lands at least
/// `margin_px` inside the frame.
pub(crate) fn solve(
    frames: &[i64],
    scans: &[Option<Scan>],
    settings: &AutoLight,
    to_deg: impl Fn([f64; 2]) -> Option<[f64; 2]>,
    keyed: impl Fn(i64) -> Option<[f64; 2]>,
    on_plate: impl Fn([f64; 2], f64) -> bool,
) -> Result<Vec<SolvedLight>, DetectError> {
    let detections: Vec<Option<Detection>> = scans.iter().map(|s| s.and_then(|s| s.detection)).collect();
    let largest = detections.iter().flatten().map(|d| d.power).fold(0.0, f64::max);
    if largest <= 0.0 {
        let peak = scans.iter().flatten().map(|s| s.peak_luminance).fold(0.0, f64::max);
        return Err(DetectError::NothingFound { threshold: settings.threshold, peak });
    }
    let reference = settings.reference_power.unwrap_or(largest);
    let measured: Vec<f64> =
        detections.iter().map(|d| d.map_or(0.0, |d| (d.power / reference).clamp(0.0, 1.0))).collect();
    // Positions of trusted frames, in degrees.
    let trusted: Vec<Option<[f64; 2]>> = detections
        .iter()
        .zip(&measured)
        .map(|(d, &v)| d.filter(|d| v >= TRUSTED_VISIBILITY && !d.touches_border).and_then(|d| to_deg(d.centroid_px)))
        .collect();
    let any_trusted = trusted.iter().any(Option::is_some);
    let fallback: Vec<Option<[f64; 2]>> = if any_trusted {
        trusted.clone()
    } else {
        detections.iter().map(|d| d.and_then(|d| to_deg(d.centroid_px))).collect()
    };
    let continued = continue_track(frames, &fallback);
    let light: Vec<[f64; 2]> = (0..frames.len())
        .map(|i| fallback[i].or_else(|| keyed(frames[i])).or(continued[i]).unwrap_or([0.0, 0.0]))
        .collect();
    // Off the plate: the region touches the border, or nothing was found where the track puts the light within
    // a radius of the border or beyond. Its visibility cannot be measured there: it is held from the nearest
    // frame where it was.
    let radius =
        detections.iter().flatten().map(|d| (d.pixels as f64 / std::f64::consts::PI).sqrt()).fold(0.0, f64::max);
    let off: Vec<bool> = (0..frames.len())
        .map(|i| match detections[i] {
            Some(d) => d.touches_border,
            None => !on_plate(light[i], radius),
        })
        .collect();
    let measurable: Vec<usize> = (0..frames.len()).filter(|&i| !off[i]).collect();
    let raw: Vec<f64> = (0..frames.len())
        .map(|i| {
            if !off[i] {
                return measured[i];
            }
            measurable.iter().min_by_key(|&&j| (j as i64 - i as i64).abs()).map_or(1.0, |&j| measured[j])
        })
        .collect();
    let visibility = triangular_filter(&raw, settings.smooth_frames);
    Ok((0..frames.len())
        .map(|i| SolvedLight {
            light_deg: light[i],
            visibility: visibility[i],
            raw_visibility: raw[i],
            detected: fallback[i].is_some(),
            off_plate: off[i],
        })
        .collect())
}

/// A centred triangular filter of odd length `n` (weights 1, 2, .., (n+1)/2, .., 2, 1), renormalised where
/// the window runs past either end.
pub fn triangular_filter(values: &[f64], n: usize) -> Vec<f64> {
    let half = (n.max(1) / 2) as i64;
    (0..values.len() as i64)
        .map(|i| {
            let (mut sum, mut weight) = (0.0, 0.0);
            for k in -half..=half {
                let j = i + k;
                if j < 0 || j >= values.len() as i64 {
                    continue;
                }
                let w = (half + 1 - k.abs()) as f64;
                sum += w * values[j as usize];
                weight += w;
            }
            sum / weight
        })
        .collect()
}

/// Fills the frames without a position from the others: linear in between, constant velocity from the last
/// (first) two outside, held when only one is known; all `None` when none is.
fn continue_track(frames: &[i64], known: &[Option<[f64; 2]>]) -> Vec<Option<[f64; 2]>> {
    let points: Vec<(f64, [f64; 2])> =
        frames.iter().zip(known).filter_map(|(&f, p)| p.map(|p| (f as f64, p))).collect();
    let line = |a: (f64, [f64; 2]), b: (f64, [f64; 2]), f: f64| {
        let t = if b.0 == a.0 { 0.0 } else { (f - a.0) / (b.0 - a.0) };
        [a.1[0] + (b.1[0] - a.1[0]) * t, a.1[1] + (b.1[1] - a.1[1]) * t]
    };
    frames
        .iter()
        .map(|&frame| {
            let f = frame as f64;
            let after = points.partition_point(|p| p.0 < f);
            match (points.len(), after) {
                (0, _) => None,
                (1, _) => Some(points[0].1),
                (_, 0) => Some(line(points[0], points[1], f)),
                (n2, a) if a == n2 => Some(line(points[n2 - 2], points[n2 - 1], f)),
                (_, a) => Some(line(points[a - 1], points[a], f)),
            }
            .map(|p: [f64; 2]| p.map(|v| v.clamp(-89.0, 89.0)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plate_with_disc(w: u32, h: u32, centre: [f64; 2], radius: f64, sun: f32) -> HdrImage {
        let mut img = HdrImage::black(w, h);
        for y in 0..h {
            for x in 0..w {
                let d = (f64::from(x) + 0.5 - centre[0]).hypot(f64::from(y) + 0.5 - centre[1]);
                let v = if d <= radius { sun } else { 0.5 };
                img.pixels[(y * w + x) as usize] = [v, v, v, 1.0];
            }
        }
        img
    }

    #[test]
    fn a_split_disc_is_one_light_and_a_dark_plate_none() {
        let mut plate = plate_with_disc(64, 48, [30.0, 20.0], 8.0, 100.0);
        // A two-pixel branch across the middle.
        for y in 0..48 {
            for x in 29..31 {
                plate.pixels[y * 64 + x] = [0.1, 0.1, 0.1, 1.0];
            }
        }
        let scan = detect(&plate, 4.0);
        let d = scan.detection.unwrap();
        assert!((d.centroid_px[0] - 30.0).abs() < 0.5 && (d.centroid_px[1] - 20.0).abs() < 0.5, "{d:?}");
        let whole = detect(&plate_with_disc(64, 48, [30.0, 20.0], 8.0, 100.0), 4.0).detection.unwrap();
        let fraction = d.power / whole.power;
        assert!(fraction > 0.7 && fraction < 0.95, "both halves count: {fraction}");
        let dark = detect(&plate_with_disc(64, 48, [30.0, 20.0], 8.0, 1.0), 4.0);
        assert!(dark.detection.is_none());
        assert_eq!(dark.peak_luminance, 1.0);
    }

    #[test]
    fn the_filter_keeps_a_constant_and_zeroes_a_long_cover() {
        let v = triangular_filter(&[1.0; 9], 5);
        assert!(v.iter().all(|&x| (x - 1.0).abs() < 1e-12));
        let mut cover = vec![1.0; 20];
        for x in &mut cover[5..15] {
            *x = 0.0;
        }
        let f = triangular_filter(&cover, 5);
        assert!(f[7..13].iter().all(|&x| x == 0.0), "{f:?}");
        let steps: f64 = f.windows(2).map(|p| (p[1] - p[0]).abs()).fold(0.0, f64::max);
        assert!(steps < 0.4, "a cut becomes a fade: largest step {steps}");
    }

    #[test]
    fn a_missing_position_continues_from_the_track() {
        let frames: Vec<i64> = (0..6).collect();
        let known = [Some([0.0, 0.0]), Some([1.0, 0.5]), None, None, Some([4.0, 2.0]), None];
        let c = continue_track(&frames, &known);
        assert_eq!(c[2], Some([2.0, 1.0]));
        assert_eq!(c[3], Some([3.0, 1.5]));
        assert_eq!(c[5], Some([5.0, 2.5]), "constant velocity of the last two after the last one");
        assert!(continue_track(&frames, &[None; 6]).iter().all(Option::is_none));
    }
}
