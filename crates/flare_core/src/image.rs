//! Images in memory: linear HDR images, 8-bit display images, and the per-ghost moments gathered while
//! drawing.
//!
//! # How it works
//! [`HdrImage`] is linear RGBA f32, row-major from the top-left. It samples as the GPU does (nearest, as
//! `textureLoad` at a scaled pixel; bilinear with the edge clamped, as a linear sampler), which is how an
//! accumulation drawn at a fraction of the frame is brought to the frame's size ([`HdrImage::resampled`]) and
//! how a background plate of any size is laid under the frame. [`DisplayImage`] is what a PNG holds: 8-bit
//! sRGB. [`GhostMoments`] is one ghost's luminance-weighted energy and first moments, gathered by the
//! renderers and compared by [`crate::metrics`]. `finite_half` is how every value bound for a 16-bit GPU
//! texture is made one.

use rayon::prelude::*;

/// `v` as a 16-bit float a GPU texture may hold: what is not finite becomes 0, and what lies beyond f16's range
/// its largest value of that sign (never an infinity).
pub(crate) fn finite_half(v: f32) -> half::f16 {
    if v.is_finite() { half::f16::from_f32(v.clamp(-65504.0, 65504.0)) } else { half::f16::ZERO }
}

/// A linear HDR image: `width` x `height` RGBA f32, row-major from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct HdrImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

/// How [`HdrImage::resampled`] reads the source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// The texel under each pixel centre (how the tonemap shader reads a plate).
    Nearest,
    /// Bilinear with the edge clamped (how the tonemap shader reads the accumulation).
    Bilinear,
}

impl HdrImage {
    /// The mean of every `factor` x `factor` block (a box filter down to 1 / `factor` of the size; the size
    /// must be a multiple of it, else the last partial blocks are left out).
    pub fn box_reduced(&self, factor: u32) -> HdrImage {
        if factor <= 1 {
            return self.clone();
        }
        let (w, h) = (self.width / factor, self.height / factor);
        let f = factor as usize;
        let mut pixels = vec![[0.0f32; 4]; (w * h) as usize];
        for (k, out) in pixels.iter_mut().enumerate() {
            let (x, y) = (k % w as usize, k / w as usize);
            let mut sum = [0.0f64; 4];
            for dy in 0..f {
                for dx in 0..f {
                    let p = self.pixels[(y * f + dy) * self.width as usize + x * f + dx];
                    for c in 0..4 {
                        sum[c] += f64::from(p[c]);
                    }
                }
            }
            *out = sum.map(|v| (v / (f * f) as f64) as f32);
        }
        HdrImage { width: w, height: h, pixels }
    }

    /// A black image (alpha 0).
    pub fn black(width: u32, height: u32) -> Self {
        Self { width, height, pixels: vec![[0.0; 4]; width as usize * height as usize] }
    }

    /// Nearest sample at texture coordinates (s, t) in [0, 1]^2: what `textureLoad` at the scaled pixel reads.
    pub fn sample_nearest(&self, s: f32, t: f32) -> [f32; 4] {
        let x = ((s * self.width as f32) as usize).min(self.width as usize - 1);
        let y = ((t * self.height as f32) as usize).min(self.height as usize - 1);
        self.pixels[y * self.width as usize + x]
    }

    /// Bilinear sample at texture coordinates (s, t) in [0, 1]^2, clamped to the edge: what a GPU's linear
    /// sampler returns.
    pub fn sample_bilinear(&self, s: f32, t: f32) -> [f32; 4] {
        let (w, h) = (self.width as usize, self.height as usize);
        let (x, y) = (s * w as f32 - 0.5, t * h as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: f32, j: f32| {
            let i = (i.max(0.0) as usize).min(w - 1);
            let j = (j.max(0.0) as usize).min(h - 1);
            self.pixels[j * w + i]
        };
        let mut out = [0.0; 4];
        for (c, o) in out.iter_mut().enumerate() {
            let top = at(x0, y0)[c] * (1.0 - fx) + at(x0 + 1.0, y0)[c] * fx;
            let bottom = at(x0, y0 + 1.0)[c] * (1.0 - fx) + at(x0 + 1.0, y0 + 1.0)[c] * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
    }

    /// This image at `width` x `height` (sampled at each pixel centre), its RGB times `gain`; alpha is kept.
    /// At its own size every pixel is its own sample, exactly, as a GPU's sampler reads a texture of the
    /// target's size at its pixel centres (its sub-texel fraction snaps the f32 rounding of the centre's
    /// coordinates away; sampling here would give a column or row a neighbour's weight of about 1e-7 at
    /// sizes such as 1920 or 1080).
    pub fn resampled(&self, width: u32, height: u32, sampling: Sampling, gain: f32) -> Self {
        let (w, h) = (width as usize, height as usize);
        if (width, height) == (self.width, self.height) {
            let mut pixels = vec![[0.0; 4]; w * h];
            pixels.par_chunks_mut(w.max(1)).zip(self.pixels.par_chunks(w.max(1))).for_each(|(row, from)| {
                for (out, p) in row.iter_mut().zip(from) {
                    *out = [p[0] * gain, p[1] * gain, p[2] * gain, p[3]];
                }
            });
            return Self { width, height, pixels };
        }
        let mut pixels = vec![[0.0; 4]; w * h];
        // Rows in parallel (each pixel is its own sample).
        pixels.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let (s, t) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                let p = match sampling {
                    Sampling::Nearest => self.sample_nearest(s, t),
                    Sampling::Bilinear => self.sample_bilinear(s, t),
                };
                *out = [p[0] * gain, p[1] * gain, p[2] * gain, p[3]];
            }
        });
        Self { width, height, pixels }
    }

    /// The pixel-wise sum of RGB (`other` of the same size); alpha is the larger of the two.
    pub fn plus(&self, other: &Self) -> Self {
        assert_eq!((self.width, self.height), (other.width, other.height), "images of one size");
        let pixels = self
            .pixels
            .iter()
            .zip(&other.pixels)
            // A sum past the largest float stays the largest (an overflow is the brightest value, not infinity).
            .map(|(a, b)| [sum(a[0], b[0]), sum(a[1], b[1]), sum(a[2], b[2]), a[3].max(b[3])])
            .collect();
        Self { width: self.width, height: self.height, pixels }
    }
}

/// `a + b`, at most the largest finite float.
fn sum(a: f32, b: f32) -> f32 {
    (a + b).min(f32::MAX)
}

/// A display image: 8-bit sRGB RGBA.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[u8; 4]>,
}

impl DisplayImage {
    /// The largest difference of any R, G or B value from `other`'s, in 8-bit steps (how a GPU image is
    /// compared with its CPU twin); images of different sizes differ by 255.
    pub fn worst_difference(&self, other: &Self) -> u8 {
        if (self.width, self.height) != (other.width, other.height) {
            return u8::MAX;
        }
        let channels =
            self.pixels.iter().zip(&other.pixels).flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])));
        channels.max().unwrap_or(0)
    }
}

/// Luminance-weighted energy of one ghost in the frame and its first moments (pixel coordinates).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GhostMoments {
    pub energy: f64,
    pub sum_x: f64,
    pub sum_y: f64,
}

impl GhostMoments {
    pub fn add(&mut self, other: &Self) {
        self.energy += other.energy;
        self.sum_x += other.sum_x;
        self.sum_y += other.sum_y;
    }

    /// Adds `energy` at the pixel position `p`.
    pub fn add_sample(&mut self, energy: f64, p: [f64; 2]) {
        self.energy += energy;
        self.sum_x += energy * p[0];
        self.sum_y += energy * p[1];
    }

    /// The centroid, when there is any energy.
    pub fn centroid(&self) -> Option<[f64; 2]> {
        (self.energy > 0.0).then(|| [self.sum_x / self.energy, self.sum_y / self.energy])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_half_for_the_gpu_is_always_finite() {
        assert_eq!(finite_half(1.5).to_f32(), 1.5);
        assert_eq!(finite_half(1e9).to_f32(), 65504.0);
        assert_eq!(finite_half(-1e9).to_f32(), -65504.0);
        assert_eq!(finite_half(f32::INFINITY).to_f32(), 0.0);
        assert_eq!(finite_half(f32::NAN).to_f32(), 0.0);
    }

    #[test]
    fn resampling_at_the_same_size_is_exact_and_scales_rgb_only() {
        let mut image = HdrImage::black(3, 2);
        for (k, p) in image.pixels.iter_mut().enumerate() {
            *p = [k as f32, 2.0 * k as f32, 0.5, 1.0];
        }
        for sampling in [Sampling::Nearest, Sampling::Bilinear] {
            let same = image.resampled(3, 2, sampling, 2.0);
            for (a, b) in same.pixels.iter().zip(&image.pixels) {
                assert_eq!(*a, [b[0] * 2.0, b[1] * 2.0, b[2] * 2.0, b[3]]);
            }
        }
        // At sizes where the f32 centres `(x + 0.5) / w * w - 0.5` miss x (1920: 51 columns), too.
        let mut wide = HdrImage::black(1920, 2);
        for (k, p) in wide.pixels.iter_mut().enumerate() {
            *p = [(k % 7) as f32 + 0.1, (k % 13) as f32, 1.0 / (k + 1) as f32, 0.5];
        }
        let same = wide.resampled(1920, 2, Sampling::Bilinear, 3.0);
        for (a, b) in same.pixels.iter().zip(&wide.pixels) {
            assert_eq!(*a, [b[0] * 3.0, b[1] * 3.0, b[2] * 3.0, b[3]]);
        }
        let doubled = image.resampled(6, 4, Sampling::Nearest, 1.0);
        assert_eq!(doubled.pixels[0], image.pixels[0]);
        assert_eq!(doubled.pixels[6 * 4 - 1], image.pixels[5]);
        let sum = image.plus(&image);
        assert_eq!(sum.pixels[5], [10.0, 20.0, 1.0, 1.0]);
    }
}
