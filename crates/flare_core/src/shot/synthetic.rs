//! A synthetic shot to try and test shots with: a sun disc moving over a sky gradient, with a dark bar (a
//! pole, a trunk) crossing it, as linear HDR plates, together with the sun's true track and visible fraction.
//!
//! # How it works
//! The sun moves linearly from `start_px` to `end_px` over the frames; the occluder is a vertical bar
//! `occluder_width_px` wide whose left edge moves linearly from `occluder_start_px` to `occluder_end_px`. Each
//! pixel is the sky (a blue gradient, brighter at the horizon, about 0.3 to 0.9), covered by the sun disc
//! (luminance `sun_luminance`) and then by the bar, each with its coverage of the pixel measured on an 8 x 8
//! grid of sub-samples (anti-aliased edges, as a camera records). [`SyntheticShot::visible_fraction`] measures
//! the disc's uncovered area on the same sub-samples, so it is the visibility a perfect detector finds.
//! [`SyntheticShot::write`] writes the plates as RGB EXR and the true track as CSV (`frame,x_px,y_px`).

use std::io::Cursor;
use std::ops::RangeInclusive;
use std::path::Path;

use crate::footage::pattern::FramePattern;
use crate::image::HdrImage;

/// Sub-samples per pixel side.
const SUB: usize = 8;

/// The synthetic shot (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticShot {
    pub width: u32,
    pub height: u32,
    pub frames: RangeInclusive<i64>,
    pub sun_radius_px: f64,
    pub sun_luminance: f32,
    pub start_px: [f64; 2],
    pub end_px: [f64; 2],
    pub occluder_width_px: f64,
    /// The occluder's left edge at the first and last frame (`None`: no occluder).
    pub occluder_px: Option<(f64, f64)>,
}

impl SyntheticShot {
    /// A sun crossing a 160 x 90 frame left to right over frames 1-24, a bar crossing it the other way.
    pub fn small() -> Self {
        Self {
            width: 160,
            height: 90,
            frames: 1..=24,
            sun_radius_px: 5.0,
            sun_luminance: 2000.0,
            start_px: [50.0, 30.0],
            end_px: [110.0, 40.0],
            occluder_width_px: 14.0,
            occluder_px: Some((130.0, 30.0)),
        }
    }

    /// [`Self::small`] scaled to a `width` x `height` frame over `frames`.
    pub fn scaled(width: u32, height: u32, frames: RangeInclusive<i64>) -> Self {
        let s = Self::small();
        let k = f64::from(width) / f64::from(s.width);
        let ky = f64::from(height) / f64::from(s.height);
        Self {
            width,
            height,
            frames,
            sun_radius_px: s.sun_radius_px * k,
            start_px: [s.start_px[0] * k, s.start_px[1] * ky],
            end_px: [s.end_px[0] * k, s.end_px[1] * ky],
            occluder_width_px: s.occluder_width_px * k,
            occluder_px: s.occluder_px.map(|(a, b)| (a * k, b * k)),
            ..s
        }
    }

    fn at(&self, frame: i64) -> f64 {
        let (a, b) = (*self.frames.start(), *self.frames.end());
        if b == a { 0.0 } else { (frame - a) as f64 / (b - a) as f64 }
    }

    /// The sun's centre at `frame` (pixels from the top-left corner, y down).
    pub fn sun_px(&self, frame: i64) -> [f64; 2] {
        let t = self.at(frame);
        [
            self.start_px[0] + (self.end_px[0] - self.start_px[0]) * t,
            self.start_px[1] + (self.end_px[1] - self.start_px[1]) * t,
        ]
    }

    /// The occluder's span in x at `frame`.
    fn occluder(&self, frame: i64) -> Option<(f64, f64)> {
        let (a, b) = self.occluder_px?;
        let left = a + (b - a) * self.at(frame);
        Some((left, left + self.occluder_width_px))
    }

    /// Coverage of pixel (x, y) by the sun disc and by the occluder, on the sub-sample grid: (sun only, any).
    fn coverage(&self, frame: i64, x: u32, y: u32) -> (f64, f64) {
        let c = self.sun_px(frame);
        let bar = self.occluder(frame);
        let (mut sun, mut covered) = (0usize, 0usize);
        for j in 0..SUB {
            for i in 0..SUB {
                let sx = f64::from(x) + (i as f64 + 0.5) / SUB as f64;
                let sy = f64::from(y) + (j as f64 + 0.5) / SUB as f64;
                let in_bar = bar.is_some_and(|(l, r)| sx >= l && sx < r);
                if in_bar {
                    covered += 1;
                } else if (sx - c[0]).hypot(sy - c[1]) <= self.sun_radius_px {
                    sun += 1;
                }
            }
        }
        let n = (SUB * SUB) as f64;
        (sun as f64 / n, covered as f64 / n)
    }

    /// The plate of `frame` (linear).
    pub fn plate(&self, frame: i64) -> HdrImage {
        let mut img = HdrImage::black(self.width, self.height);
        for y in 0..self.height {
            let horizon = y as f32 / self.height.max(1) as f32;
            let sky = [0.25 + 0.35 * horizon, 0.45 + 0.3 * horizon, 0.9, 1.0];
            for x in 0..self.width {
                let (sun, bar) = self.coverage(frame, x, y);
                let (sun, bar, open) = (sun as f32, bar as f32, (1.0 - sun - bar) as f32);
                let s = self.sun_luminance;
                img.pixels[(y * self.width + x) as usize] = [
                    open * sky[0] + sun * s + bar * 0.04,
                    open * sky[1] + sun * s * 0.96 + bar * 0.035,
                    open * sky[2] + sun * s * 0.9 + bar * 0.03,
                    1.0,
                ];
            }
        }
        img
    }

    /// The fraction of the sun disc not covered by the occluder (or the frame's edges) at `frame`.
    pub fn visible_fraction(&self, frame: i64) -> f64 {
        let c = self.sun_px(frame);
        let r = self.sun_radius_px;
        let bar = self.occluder(frame);
        let n = 400;
        let (mut inside, mut seen) = (0usize, 0usize);
        for j in 0..n {
            for i in 0..n {
                let sx = c[0] - r + 2.0 * r * (i as f64 + 0.5) / n as f64;
                let sy = c[1] - r + 2.0 * r * (j as f64 + 0.5) / n as f64;
                if (sx - c[0]).hypot(sy - c[1]) > r {
                    continue;
                }
                inside += 1;
                let in_frame = sx >= 0.0 && sy >= 0.0 && sx < f64::from(self.width) && sy < f64::from(self.height);
                if in_frame && !bar.is_some_and(|(l, rr)| sx >= l && sx < rr) {
                    seen += 1;
                }
            }
        }
        seen as f64 / inside.max(1) as f64
    }

    /// Writes every plate to `plates` (a pattern such as `dir/sun.####.exr`) and, when given, the true track
    /// as CSV with a header.
    pub fn write(&self, plates: &FramePattern, track: Option<&Path>) -> std::io::Result<()> {
        for frame in self.frames.clone() {
            let plate = self.plate(frame);
            let raw: Vec<f32> = plate.pixels.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
            let buffer = ::image::Rgb32FImage::from_raw(plate.width, plate.height, raw)
                .ok_or_else(|| std::io::Error::other("plate size mismatch"))?;
            let mut bytes = Vec::new();
            buffer
                .write_to(&mut Cursor::new(&mut bytes), ::image::ImageFormat::OpenExr)
                .map_err(std::io::Error::other)?;
            let path = plates.path(frame);
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)?;
            }
            crate::files::write_atomic(&path, &bytes)?;
        }
        if let Some(track) = track {
            let mut text = String::from("frame,x_px,y_px\n");
            for frame in self.frames.clone() {
                let p = self.sun_px(frame);
                text.push_str(&format!("{frame},{},{}\n", p[0], p[1]));
            }
            crate::files::write_atomic(track, text.as_bytes())?;
        }
        Ok(())
    }
}
