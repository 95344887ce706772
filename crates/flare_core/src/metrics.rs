//! Image metrics: how far a flare method's image is from the reference renderer's.
//!
//! # How it works
//! What is compared (the same for every method, and written in the README):
//! - **ghosts only**: no starburst, no background; every image is linear relative irradiance at the same size;
//! - **exposure fixed from the reference** ([`exposure_for`]): the 99.9th percentile of the reference's pixel
//!   luminance maps to 1.0 before tonemapping (the maximum when that percentile is 0; 1 for a black
//!   reference), and the same exposure is applied to the image under test;
//! - **display values**: exposure, ACES tonemap and sRGB encoding exactly as the renderer's tonemap pass
//!   (`crate::color::display_value`, which the tonemap shader's CPU twin calls), kept as floats in [0, 1] (no 8-bit rounding);
//! - **PSNR** over the three display channels of every pixel, `10 log10(1 / MSE)`, capped at
//!   `PSNR_CAP_DB` (identical images);
//! - **SSIM** (Wang et al. 2004) on the display luma `0.2126 R' + 0.7152 G' + 0.0722 B'`, an 11 x 11 Gaussian
//!   window of sigma 1.5, K1 = 0.01, K2 = 0.03, dynamic range 1, averaged over every window that fits inside
//!   the image;
//! - **relative L1** of linear energy: `sum |test - ref| / sum |ref|` over every channel and pixel, before any
//!   exposure;
//! - **centroid error**: per ghost, the distance in pixels between the luminance-weighted centroids of its light
//!   in the frame in the two images ([`GhostMoments`], gathered while rendering), over the ghosts holding at
//!   least `CENTROID_MIN_FRACTION` of the brightest ghost's in-frame energy in the reference; the median is
//!   reported.

pub use crate::color::luminance;
use crate::color::{Tonemap, display_value};
pub use crate::image::GhostMoments;
use crate::image::HdrImage;

/// PSNR of identical images.
pub(crate) const PSNR_CAP_DB: f64 = 100.0;
/// Ghosts dimmer than this fraction of the brightest (in-frame energy, reference) are left out of the
/// centroid error.
pub(crate) const CENTROID_MIN_FRACTION: f64 = 0.01;

/// The exposure that maps the reference's 99.9th-percentile pixel luminance to 1.0 (see the module docs).
pub fn exposure_for(reference: &HdrImage) -> f32 {
    let mut l: Vec<f64> = reference
        .pixels
        .iter()
        .map(|p| luminance([p[0], p[1], p[2]].map(f64::from)))
        .filter(|v| v.is_finite())
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    l.sort_by(f64::total_cmp);
    let p999 = l[((l.len() - 1) as f64 * 0.999).round() as usize];
    let level = if p999 > 0.0 { p999 } else { l[l.len() - 1] };
    if level > 0.0 { (1.0 / level) as f32 } else { 1.0 }
}

/// Display values (sRGB-encoded, [0, 1]) of `image` at `exposure` through ACES, as the tonemap pass makes them.
pub fn display_values(image: &HdrImage, exposure: f32) -> Vec<[f32; 3]> {
    image.pixels.iter().map(|p| [p[0], p[1], p[2]].map(|v| display_value(v * exposure, Tonemap::Aces, true))).collect()
}

/// PSNR in dB between two display images of the same size (capped at `PSNR_CAP_DB`).
pub fn psnr(test: &[[f32; 3]], reference: &[[f32; 3]]) -> f64 {
    assert_eq!(test.len(), reference.len(), "PSNR needs images of one size");
    let n = (test.len() * 3).max(1) as f64;
    let mse: f64 = test
        .iter()
        .zip(reference)
        .flat_map(|(a, b)| (0..3).map(move |c| (f64::from(a[c]) - f64::from(b[c])).powi(2)))
        .sum::<f64>()
        / n;
    if mse <= 0.0 { PSNR_CAP_DB } else { (10.0 * (1.0 / mse).log10()).min(PSNR_CAP_DB) }
}

/// Mean SSIM on display luma (see the module docs). Images smaller than the window are compared as one
/// window.
pub fn ssim(test: &[[f32; 3]], reference: &[[f32; 3]], width: usize, height: usize) -> f64 {
    assert_eq!(test.len(), width * height);
    assert_eq!(reference.len(), width * height);
    let luma = |img: &[[f32; 3]]| -> Vec<f64> { img.iter().map(|p| luminance(p.map(f64::from))).collect() };
    let (x, y) = (luma(test), luma(reference));
    const RADIUS: usize = 5;
    let sigma = 1.5f64;
    let kernel: Vec<f64> = {
        let k: Vec<f64> =
            (0..=2 * RADIUS).map(|i| (-((i as f64 - RADIUS as f64).powi(2)) / (2.0 * sigma * sigma)).exp()).collect();
        let s: f64 = k.iter().sum();
        k.into_iter().map(|v| v / s).collect()
    };
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let ssim_of = |mx: f64, my: f64, sxx: f64, syy: f64, sxy: f64| {
        ((2.0 * mx * my + c1) * (2.0 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
    };
    if width < 2 * RADIUS + 1 || height < 2 * RADIUS + 1 {
        let n = x.len().max(1) as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let var = |v: &[f64], m: f64| v.iter().map(|a| (a - m).powi(2)).sum::<f64>() / n;
        let cov = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum::<f64>() / n;
        return ssim_of(mx, my, var(&x, mx), var(&y, my), cov);
    }
    // Separable Gaussian sums of x, y, x^2, y^2, xy: horizontal pass then vertical, valid windows only.
    let fields: [Vec<f64>; 5] = [
        x.clone(),
        y.clone(),
        x.iter().map(|a| a * a).collect(),
        y.iter().map(|b| b * b).collect(),
        x.iter().zip(&y).map(|(a, b)| a * b).collect(),
    ];
    let (ow, oh) = (width - 2 * RADIUS, height - 2 * RADIUS);
    let blurred: Vec<Vec<f64>> = fields
        .iter()
        .map(|f| {
            let mut horizontal = vec![0.0; ow * height];
            for row in 0..height {
                for col in 0..ow {
                    horizontal[row * ow + col] =
                        kernel.iter().enumerate().map(|(k, w)| w * f[row * width + col + k]).sum();
                }
            }
            let mut out = vec![0.0; ow * oh];
            for row in 0..oh {
                for col in 0..ow {
                    out[row * ow + col] =
                        kernel.iter().enumerate().map(|(k, w)| w * horizontal[(row + k) * ow + col]).sum();
                }
            }
            out
        })
        .collect();
    let total: f64 = (0..ow * oh)
        .map(|i| {
            let (mx, my) = (blurred[0][i], blurred[1][i]);
            ssim_of(mx, my, blurred[2][i] - mx * mx, blurred[3][i] - my * my, blurred[4][i] - mx * my)
        })
        .sum();
    total / (ow * oh) as f64
}

/// `sum |test - ref| / sum |ref|` over linear RGB; 0 when both are black, 1 when only the reference is.
pub fn relative_l1(test: &HdrImage, reference: &HdrImage) -> f64 {
    let (mut diff, mut norm, mut test_sum) = (0.0f64, 0.0f64, 0.0f64);
    for (a, b) in test.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            diff += (f64::from(a[c]) - f64::from(b[c])).abs();
            norm += f64::from(b[c]).abs();
            test_sum += f64::from(a[c]).abs();
        }
    }
    if norm > 0.0 {
        diff / norm
    } else if test_sum > 0.0 {
        1.0
    } else {
        0.0
    }
}

/// Per-ghost centroid distances (pixels) over the ghosts that matter in the reference (see the module docs);
/// a ghost with no light in the frame in the test image is counted at the frame's diagonal.
pub(crate) fn centroid_errors(test: &[GhostMoments], reference: &[GhostMoments], diagonal_px: f64) -> Vec<f64> {
    let brightest = reference.iter().map(|m| m.energy).fold(0.0, f64::max);
    if brightest <= 0.0 {
        return Vec::new();
    }
    reference
        .iter()
        .zip(test)
        .filter(|(r, _)| r.energy >= CENTROID_MIN_FRACTION * brightest)
        .map(|(r, t)| match (r.centroid(), t.centroid()) {
            (Some(a), Some(b)) => (a[0] - b[0]).hypot(a[1] - b[1]),
            _ => diagonal_px,
        })
        .collect()
}

/// The median of `values` (0 for none).
pub fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// Every metric of one image against the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Comparison {
    pub psnr_db: f64,
    pub ssim: f64,
    pub relative_l1: f64,
    /// Median per-ghost centroid error (pixels) and how many ghosts it is over.
    pub centroid_px: f64,
    pub centroid_ghosts: usize,
}

/// A reference image prepared once for many comparisons: its exposure and display values.
pub struct Reference<'a> {
    pub image: &'a HdrImage,
    pub moments: &'a [GhostMoments],
    pub exposure: f32,
    display: Vec<[f32; 3]>,
}

impl<'a> Reference<'a> {
    pub fn new(image: &'a HdrImage, moments: &'a [GhostMoments]) -> Self {
        let exposure = exposure_for(image);
        Self { image, moments, exposure, display: display_values(image, exposure) }
    }

    /// Every metric of `test` (with its per-ghost moments) against this reference, at its exposure.
    pub fn compare(&self, test: &HdrImage, test_moments: &[GhostMoments]) -> Comparison {
        let reference = self.image;
        assert_eq!((test.width, test.height), (reference.width, reference.height), "compare images of one size");
        let a = display_values(test, self.exposure);
        let diagonal = f64::from(test.width).hypot(f64::from(test.height));
        let centroids = centroid_errors(test_moments, self.moments, diagonal);
        Comparison {
            psnr_db: psnr(&a, &self.display),
            ssim: ssim(&a, &self.display, test.width as usize, test.height as usize),
            relative_l1: relative_l1(test, reference),
            centroid_px: median(&centroids),
            centroid_ghosts: centroids.len(),
        }
    }
}

/// Compares `test` with `reference` at the reference's exposure (see [`Reference`] for many comparisons).
pub fn compare(
    test: &HdrImage,
    test_moments: &[GhostMoments],
    reference: &HdrImage,
    reference_moments: &[GhostMoments],
) -> Comparison {
    Reference::new(reference, reference_moments).compare(test, test_moments)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> HdrImage {
        let pixels = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let v = f(x, y);
                [v, v, v, 1.0]
            })
            .collect();
        HdrImage { width: w, height: h, pixels }
    }

    #[test]
    fn identical_images_score_perfectly() {
        let a = image(40, 30, |x, y| ((x * 7 + y * 3) % 11) as f32 * 0.01);
        let c = compare(&a, &[], &a, &[]);
        assert_eq!(c.psnr_db, PSNR_CAP_DB);
        assert!((c.ssim - 1.0).abs() < 1e-12, "{}", c.ssim);
        assert_eq!(c.relative_l1, 0.0);
    }

    #[test]
    fn psnr_of_a_known_error() {
        // Every value off by 0.1: MSE 0.01, 20 dB.
        let a = vec![[0.5f32; 3]; 100];
        let b = vec![[0.6f32; 3]; 100];
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
    }

    #[test]
    fn ssim_falls_with_noise_and_structure_loss() {
        let reference = image(64, 48, |x, y| if (x / 8 + y / 8) % 2 == 0 { 0.02 } else { 0.0 });
        let shifted = image(64, 48, |x, y| if ((x + 3) / 8 + y / 8) % 2 == 0 { 0.02 } else { 0.0 });
        let exposure = exposure_for(&reference);
        let r = display_values(&reference, exposure);
        let s = display_values(&shifted, exposure);
        let value = ssim(&s, &r, 64, 48);
        assert!(value < 0.8 && value > -1.0, "{value}");
        assert!(relative_l1(&shifted, &reference) > 0.3);
    }

    #[test]
    fn exposure_maps_the_bright_end_to_one() {
        let reference = image(100, 100, |x, _| if x < 50 { 0.0 } else { 0.004 });
        assert!((exposure_for(&reference) - 250.0).abs() < 1e-3);
        let black = image(10, 10, |_, _| 0.0);
        assert_eq!(exposure_for(&black), 1.0);
        assert_eq!(relative_l1(&black, &black), 0.0);
        assert_eq!(relative_l1(&reference, &black), 1.0);
    }

    #[test]
    fn centroid_errors_skip_dim_ghosts_and_count_missing_ones() {
        let at = |e: f64, x: f64, y: f64| GhostMoments { energy: e, sum_x: e * x, sum_y: e * y };
        let reference = [at(1.0, 10.0, 10.0), at(1e-4, 0.0, 0.0), at(0.5, 20.0, 20.0)];
        let test = [at(2.0, 13.0, 14.0), at(1.0, 50.0, 50.0), GhostMoments::default()];
        let e = centroid_errors(&test, &reference, 100.0);
        assert_eq!(e, vec![5.0, 100.0]);
        assert_eq!(median(&e), 52.5);
    }
}
