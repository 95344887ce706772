//! The blur kernel: the stop's shape seen through the entrance pupil, scaled to the blur diameter, cut off-axis
//! by the lens's clear apertures (the cat's eye), normalised to 1.
//!
//! # How it works
//! A frame offset `o` (pixels, X right, Y up) from a source of signed defocus `sigma` (pixels, see
//! [`super::DofModel::defocus_px`]) is the pupil point `q = sign(sigma) o / (|sigma| / 2)` in pupil radii:
//! upright behind the focus plane, point-reflected in front of it. Its weight is the aperture mask at
//! `mask_sign q` (the stop imaged into the pupil) times, with the cat's eye, the coverage of each cutting clear
//! aperture's region in pupil units ([`super::DofModel::cat_eyes_at`], a [`Cat`]) with a soft edge `edge` wide (the
//! sampling step, so that the cut is antialiased like the mask). [`raster`] integrates it over each target pixel (s x s samples)
//! for the reference; [`super::live`] samples it per tap. An anamorphic lens's kernel has a defocus per axis
//! (`pupil_point_xy`, [`raster_xy`]): the pupil point is `2 o_x / sigma_x` along x and `2 o_y / sigma_y` along y.

use crate::aperture::ApertureMask;

/// The pupil points (pupil radii) one clear aperture lets through: those `q` with
/// `hypot(x_scale q_x - centre_x, q_y - centre_y) <= radius`. A lens of revolution's is a circle (`x_scale` 1). An
/// anamorphic lens's is an ellipse: its pupil's x semi-axis over its y one times the aperture's own stretch
/// (the x section's ray height over the y section's per unit of pupil), with the centre's x stretched alike
/// ([`super::DofModel::cat_circles_at`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cat {
    pub centre: [f64; 2],
    pub radius: f64,
    pub x_scale: f64,
}

impl Cat {
    /// A circle (`x_scale` 1).
    pub fn circle(centre: [f64; 2], radius: f64) -> Self {
        Self { centre, radius, x_scale: 1.0 }
    }

    /// How far (pupil radii) its edge can reach into the unit pupil: `|centre| + max(|x_scale|, 1) - radius`
    /// (positive: it may cut; a radius that is not a number cuts everything).
    pub fn cut_depth(&self) -> f64 {
        if self.radius.is_nan() {
            return f64::INFINITY;
        }
        self.centre[0].hypot(self.centre[1]) + self.x_scale.abs().max(1.0) - self.radius
    }

    /// Whether it may leave part of the unit pupil outside ([`Self::cut_depth`] positive).
    pub fn cuts(&self) -> bool {
        self.cut_depth() > 0.0
    }
}

/// The pupil point (pupil radii) of the frame offset `o` (pixels, X right, Y up) for the signed defocus `sigma`
/// along x and along y (an anamorphic lens's oval; equal for a lens of revolution): `2 o / sigma` on each axis.
#[inline]
pub(crate) fn pupil_point_xy(o: [f64; 2], sigma: [f64; 2]) -> [f64; 2] {
    [o[0] * (2.0 / sigma[0]), o[1] * (2.0 / sigma[1])]
}

/// The coverage of the clear apertures `cats` (the ones that cut the pupil) at `q`, the product of each one's,
/// with a soft edge `edge` wide. No apertures: 1.
#[inline]
pub(crate) fn cat_eye_coverage(q: [f64; 2], cats: &[Cat], edge: f64) -> f64 {
    let mut m = 1.0;
    for cat in cats {
        let d = (q[0] * cat.x_scale - cat.centre[0]).hypot(q[1] - cat.centre[1]);
        m *= (0.5 + (cat.radius - d) / edge.max(1e-9)).clamp(0.0, 1.0);
        if m == 0.0 {
            break;
        }
    }
    m
}

/// The kernel's weight at the pupil point `q` (before normalisation).
#[inline]
pub fn weight(mask: &ApertureMask, mask_sign: f64, q: [f64; 2], cats: &[Cat], edge: f64) -> f64 {
    let open = f64::from(mask.sample((mask_sign * q[0]) as f32, (mask_sign * q[1]) as f32));
    if open == 0.0 { 0.0 } else { open * cat_eye_coverage(q, cats, edge) }
}

/// A kernel rasterised on the pixel grid around its source: `(2 radius + 1)^2` weights, row by row from the top
/// (pixel rows, Y down), summing to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterKernel {
    pub radius: i32,
    pub weights: Vec<f32>,
}

impl RasterKernel {
    /// All of the light stays in its pixel (a blur under a sample's spacing).
    pub fn identity() -> Self {
        Self { radius: 0, weights: vec![1.0] }
    }
}

/// Samples per pixel side for a blur of `diameter_px`: fine for small kernels, whose shape a few samples decide.
pub(crate) fn samples_per_pixel(diameter_px: f64) -> usize {
    if diameter_px < 24.0 { 4 } else { 2 }
}

/// The kernel of a source of defocus `sigma` (pixels) integrated over each target pixel with s x s samples
/// (`samples_per_pixel`), normalised to 1; the identity when no sample falls inside (a blur below the sample
/// spacing, or a cat's eye that closes the pupil: then the pixel keeps its own light).
pub fn raster(mask: &ApertureMask, mask_sign: f64, sigma: f64, cats: &[Cat]) -> RasterKernel {
    raster_xy(mask, mask_sign, [sigma; 2], cats)
}

/// [`raster`] of an oval: the defocus `sigma` along x and along y (an anamorphic lens's).
pub fn raster_xy(mask: &ApertureMask, mask_sign: f64, sigma: [f64; 2], cats: &[Cat]) -> RasterKernel {
    let widest = sigma[0].abs().max(sigma[1].abs());
    let half = 0.5 * widest;
    if !(half.is_finite() && half > 1e-6 && sigma.iter().all(|s| s.abs() > 1e-9)) {
        return RasterKernel::identity();
    }
    let radius = (half + 1.0).ceil() as i32;
    let s = samples_per_pixel(widest);
    let step = 1.0 / s as f64;
    let edge = step / half;
    let side = (2 * radius + 1) as usize;
    let mut weights = vec![0.0f64; side * side];
    for (k, w) in weights.iter_mut().enumerate() {
        let (i, j) = ((k % side) as i32 - radius, (k / side) as i32 - radius);
        let mut sum = 0.0;
        for sy in 0..s {
            for sx in 0..s {
                // The sample's frame offset (X right, Y up) from the source's centre.
                let ox = f64::from(i) - 0.5 + (sx as f64 + 0.5) * step;
                let oy = -(f64::from(j) - 0.5 + (sy as f64 + 0.5) * step);
                sum += weight(mask, mask_sign, pupil_point_xy([ox, oy], sigma), cats, edge);
            }
        }
        *w = sum;
    }
    let total: f64 = weights.iter().sum();
    if total <= 0.0 {
        return RasterKernel::identity();
    }
    RasterKernel { radius, weights: weights.into_iter().map(|w| (w / total) as f32).collect() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aperture::{Aperture, ApertureShape};

    fn mask(shape: ApertureShape) -> ApertureMask {
        Aperture { shape, f_number: None }.rasterise(256)
    }

    #[test]
    fn a_kernel_sums_to_one_and_spans_its_diameter() {
        let m = mask(ApertureShape::Circle);
        for sigma in [0.3, 3.0, 17.5, -40.0] {
            let k = raster(&m, 1.0, sigma, &[]);
            let total: f64 = k.weights.iter().map(|&w| f64::from(w)).sum();
            assert!((total - 1.0).abs() < 1e-5, "{sigma}: {total}");
            // The widest row holds about the diameter's worth of lit pixels.
            let side = (2 * k.radius + 1) as usize;
            let middle = &k.weights[k.radius as usize * side..(k.radius as usize + 1) * side];
            let peak = middle.iter().cloned().fold(0.0f32, f32::max);
            let across: f32 = middle.iter().map(|w| w / peak).sum();
            assert!((f64::from(across) - sigma.abs().max(1.0)).abs() < 1.0, "{sigma}: {across}");
        }
        assert_eq!(raster(&m, 1.0, 0.0, &[]), RasterKernel::identity());
    }

    #[test]
    fn in_front_of_the_focus_plane_the_pupil_is_point_reflected() {
        // Five blades are not point-symmetric: the kernel in front is the one behind turned by 180 degrees.
        let m = mask(ApertureShape::Blades { count: 5, rotation_deg: 0.0, roundness: 0.0 });
        let (behind, front) = (raster(&m, 1.0, 21.0, &[]), raster(&m, 1.0, -21.0, &[]));
        let flipped: Vec<f32> = front.weights.iter().rev().cloned().collect();
        let diff = behind.weights.iter().zip(&flipped).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(diff < 1e-6, "{diff}");
        let asymmetry = behind.weights.iter().zip(&front.weights).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(asymmetry > 1e-4, "five blades differ turned");
    }

    #[test]
    fn the_cat_eye_cuts_the_side_towards_its_offset() {
        let m = mask(ApertureShape::Circle);
        let full = raster(&m, 1.0, 30.0, &[]);
        let cut = raster(&m, 1.0, 30.0, &[Cat::circle([1.2, 0.0], 1.0)]);
        // Lit pixels: fewer, and all on the right half (X > 0) where the circle centred at +1.2 overlaps.
        let lit = |k: &RasterKernel| k.weights.iter().filter(|&&w| w > 0.0).count();
        assert!(lit(&cut) < lit(&full) / 2, "{} of {}", lit(&cut), lit(&full));
        let side = (2 * cut.radius + 1) as usize;
        for (k, &w) in cut.weights.iter().enumerate() {
            if w > 0.0 {
                assert!((k % side) as i32 - cut.radius >= 0, "lit at column {}", k % side);
            }
        }
    }
}
