//! LUT ghosts (KR 10-1658883): the non-linear ghosts, ray-traced ahead of time per light angle, then rotated,
//! fitted to the live paraxial sprite and blended with the linear flare at run time.
//!
//! # How it works
//! The light direction is (theta, alpha): theta its tilt from the axis, alpha the azimuth of its slope vector
//! `u = tan(theta) (cos alpha, sin alpha)` in the lens frame (x right, y up on the sensor, the frame of the stop
//! coordinates and of the aperture mask). A rotationally symmetric lens with an N-bladed stop is symmetric
//! under the dihedral group D_N, so every azimuth reduces ([`Symmetry::reduce`]) to the wedge
//! `[0, 180 / N]` degrees from the blades' symmetry axis: the image at alpha is a rotation (and for half of
//! the azimuths a mirror) of the image at the reduced azimuth. A circular stop needs one azimuth; a user's
//! image stop has no known symmetry and is treated like a circle (rotation only, the patent's approximation).
//!
//! - [`crate::bake::classify`]: per ghost, how far the paraxial sprite is from the ray-traced footprint over theta;
//!   ghosts above a threshold (and visible) are non-linear, and the user can force any ghost either way.
//! - [`crate::bake`]: each non-linear ghost ray-traced ([`crate::raytrace`], exact, energy conserving) at thetas
//!   from 0 to the lens's useful field, refined where the pattern changes fastest, and at the wedge's azimuths.
//!   Each [`LutEntry`] stores its image (RGBA half floats, A = coverage) in a window of the sensor around
//!   the ghost, with the ghost's paraxial frame (centre, half-size, energy) at that light.
//! - [`format`](mod@format): the `.flut` file (versioned header, per-entry metadata, deflate-compressed half floats).
//! - [`photo`]: a photographed flare swept over theta as a 1D LUT.
//! - [`blend`]: at run time, per LUT ghost, the (up to) two thetas and two azimuth samples around the light,
//!   each mapped from its baked paraxial frame into the live one (the same normalised position, rotated by
//!   the symmetry's transform), weighted, and added to (or composited over) the paraxial flare; the GPU
//!   shader `lut_ghosts.wgsl` and its CPU twin [`blend::lut_pass`] draw them.
//!
//! Entry images are in the display orientation of [`crate::raytrace::Window`]: texel (0, 0) is the top-left,
//! x grows to the left on the sensor and y downwards (the sensor rotated by 180 degrees, as the frame is).

pub mod blend;
pub mod format;
pub mod photo;

use half::f16;

use crate::aperture::{Aperture, ApertureShape};
use crate::ghost::ParaxialFrame;
use crate::raytrace::Window;

/// Half-diagonal of the 36 x 24 mm sensor: the light angle whose image reaches a corner sets the useful field.
pub(crate) const SENSOR_HALF_DIAGONAL_MM: f64 = 21.633_307_652_783_937;
/// Finest LUT texel (mm on the sensor): 1/4 of a pixel at 960 pixels across 36 mm.
pub(crate) const MIN_TEXEL_MM: f64 = 0.01;
/// The ghost index a photo LUT's single entry list carries.
pub(crate) const PHOTO_GHOST: u32 = u32::MAX;

/// Where a LUT's images come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LutKind {
    /// Ray-traced per non-linear ghost ([`crate::bake`]).
    RayTraced,
    /// Photographs of a real flare swept over theta, all ghosts together ([`photo`]).
    Photo,
}

/// The azimuthal symmetry of the lens with its stop: dihedral of `order` about the axis at `axis_deg`
/// (a mirror line through a blade vertex), or full rotational symmetry when `order` is 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Symmetry {
    pub order: u32,
    pub axis_deg: f64,
}

/// A 2x2 matrix acting on sensor coordinates (mm), rows first.
pub type Mat2 = [[f64; 2]; 2];

/// The rotation by `deg` degrees (counter-clockwise, x right, y up).
pub fn rotation(deg: f64) -> Mat2 {
    let (s, c) = deg.to_radians().sin_cos();
    [[c, -s], [s, c]]
}

/// `a b`.
pub(crate) fn mat_mul(a: Mat2, b: Mat2) -> Mat2 {
    [
        [a[0][0] * b[0][0] + a[0][1] * b[1][0], a[0][0] * b[0][1] + a[0][1] * b[1][1]],
        [a[1][0] * b[0][0] + a[1][1] * b[1][0], a[1][0] * b[0][1] + a[1][1] * b[1][1]],
    ]
}

/// `m v`.
pub fn mat_apply(m: Mat2, v: [f64; 2]) -> [f64; 2] {
    [m[0][0] * v[0] + m[0][1] * v[1], m[1][0] * v[0] + m[1][1] * v[1]]
}

impl Symmetry {
    /// The symmetry a LUT of `lens` with this stop may use: the aperture's ([`Self::of_aperture`]) for a lens of
    /// revolution; for an anamorphic lens (toroids aligned with x and y: mirror-symmetric about both axes, the
    /// dihedral group of order 2) what the two have in common, when this type can say it: order 2 about the x
    /// axis (a round stop, or an even number of blades with a mirror line on an axis), order 1 about the x or y
    /// axis (an odd number of blades with a mirror line there). Otherwise (blades turned off the axes) the
    /// reason, for the bake to refuse.
    pub fn of(lens: &crate::optics::Lens, aperture: &Aperture) -> Result<Self, String> {
        let own = Self::of_aperture(aperture);
        if !lens.is_anamorphic() {
            return Ok(own);
        }
        if own.order == 0 {
            return Ok(Self { order: 2, axis_deg: 0.0 });
        }
        // The aperture's mirror lines lie every 180 / order degrees from its axis.
        let spacing = 180.0 / f64::from(own.order);
        let on = |angle: f64| {
            let r = (own.axis_deg - angle).rem_euclid(spacing);
            r.min(spacing - r) < 1e-9
        };
        match (own.order.is_multiple_of(2), on(0.0), on(90.0)) {
            (true, true, _) => Ok(Self { order: 2, axis_deg: 0.0 }),
            (false, true, _) => Ok(Self { order: 1, axis_deg: 0.0 }),
            (false, false, true) => Ok(Self { order: 1, axis_deg: 90.0 }),
            _ => Err(format!(
                "the {} blades turned {} degrees break the anamorphic lens's mirror symmetry about its axes, which a \
                 LUT needs: turn them by a multiple of {} degrees",
                own.order,
                own.axis_deg,
                crate::optics::lens::round(spacing)
            )),
        }
    }

    /// The symmetry of a lens with this stop: N-fold dihedral for N straight or bowed blades, full for a circle
    /// (or fully rounded blades), and full, as an approximation, for an image stop.
    pub fn of_aperture(aperture: &Aperture) -> Self {
        match aperture.shape {
            ApertureShape::Blades { count, rotation_deg, roundness } if roundness < 1.0 => {
                Self { order: count, axis_deg: rotation_deg }
            }
            _ => Self { order: 0, axis_deg: 0.0 },
        }
    }

    /// The azimuths a LUT needs: `[0, 180 / order]` degrees from the axis.
    pub fn wedge_deg(&self) -> f64 {
        if self.order == 0 { 0.0 } else { 180.0 / f64::from(self.order) }
    }

    /// `steps + 1` azimuths evenly over the wedge (one for full symmetry), degrees from the axis.
    pub fn phi_samples(&self, steps: u32) -> Vec<f64> {
        let wedge = self.wedge_deg();
        if wedge == 0.0 || steps == 0 {
            return vec![0.0];
        }
        (0..=steps).map(|k| wedge * f64::from(k) / f64::from(steps)).collect()
    }

    /// Reduces a light azimuth `alpha_deg` to `(beta, base)`: beta in the wedge `[0, 180 / order]` and the
    /// transform of the sensor plane with `image(alpha) = base (image(axis + beta))` (a rotation by a multiple of
    /// 360 / order, after a mirror about the axis line when the azimuth is on the wedge's mirror side). For full
    /// symmetry beta is 0 and base the rotation from the axis to alpha.
    pub fn reduce(&self, alpha_deg: f64) -> (f64, Mat2) {
        let relative = alpha_deg - self.axis_deg;
        if self.order == 0 {
            return (0.0, rotation(relative));
        }
        let sector = 360.0 / f64::from(self.order);
        let k = (relative / sector).round();
        let beta = relative - k * sector;
        let turn = rotation(k * sector);
        if beta >= 0.0 {
            (beta, turn)
        } else {
            // Mirror about the line at the axis angle: [[cos 2a, sin 2a], [sin 2a, -cos 2a]].
            let (s, c) = (2.0 * self.axis_deg).to_radians().sin_cos();
            (-beta, mat_mul(turn, [[c, s], [s, -c]]))
        }
    }
}

/// The frame position (X right, Y up, degrees; what [`crate::flare::PreparedFlare::scene`] takes) of a light
/// `theta_deg` from the axis whose slope vector has the azimuth `alpha_deg` in the lens frame.
pub fn light_position_deg(theta_deg: f64, alpha_deg: f64) -> [f64; 2] {
    let t = theta_deg.to_radians().tan();
    let (s, c) = alpha_deg.to_radians().sin_cos();
    [(-t * c).atan().to_degrees(), (-t * s).atan().to_degrees()]
}

/// `(theta, alpha)` in degrees of light slopes `u` (alpha 0 on the axis).
pub fn light_direction_deg(u: [f64; 2]) -> (f64, f64) {
    let t = u[0].hypot(u[1]);
    let alpha = if t > 0.0 { u[1].atan2(u[0]).to_degrees() } else { 0.0 };
    (t.atan().to_degrees(), alpha)
}

/// One ghost's (or a photo's) image at one light direction.
#[derive(Clone, Debug, PartialEq)]
pub struct LutEntry {
    pub theta_deg: f64,
    /// Azimuth from the symmetry axis (inside the wedge), degrees.
    pub phi_deg: f64,
    /// The ghost's paraxial frame at this light (a photo's: centre 0, half-size 1, energy 0).
    pub paraxial: ParaxialFrame,
    /// Centre of the image on the sensor.
    pub centre_mm: [f64; 2],
    /// Size of a texel on the sensor.
    pub texel_mm: f64,
    pub width: u32,
    pub height: u32,
    /// Linear relative irradiance RGB and coverage A, row-major from the top, display orientation.
    pub texels: Vec<[f16; 4]>,
}

impl LutEntry {
    /// An entry with no light (the ghost passes nothing at this light).
    pub fn empty(theta_deg: f64, phi_deg: f64, paraxial: ParaxialFrame) -> Self {
        Self { theta_deg, phi_deg, paraxial, centre_mm: [0.0; 2], texel_mm: 1.0, width: 0, height: 0, texels: vec![] }
    }

    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// The sensor window the image covers.
    pub fn window(&self) -> Window {
        Window {
            centre_mm: self.centre_mm,
            width_mm: self.texel_mm * f64::from(self.width),
            width: self.width,
            height: self.height,
        }
    }

    /// Bilinear sample at texture coordinates (s, t) in [0, 1]^2 (0 outside the image, as the zero border
    /// around each entry in the GPU atlas gives).
    pub fn sample(&self, s: f32, t: f32) -> [f32; 4] {
        self.bilinear(s, t, |k| self.texels[k].map(f16::to_f32))
    }

    /// The texels as f32 (exact), for many [`Self::sample_decoded`] calls.
    pub fn decoded(&self) -> Vec<[f32; 4]> {
        self.texels.iter().map(|t| t.map(f16::to_f32)).collect()
    }

    /// [`Self::sample`] from this entry's [`Self::decoded`] texels (the same values, without converting four
    /// half floats per sample).
    pub fn sample_decoded(&self, decoded: &[[f32; 4]], s: f32, t: f32) -> [f32; 4] {
        self.bilinear(s, t, |k| decoded[k])
    }

    /// Bilinear interpolation of the texels `texel(index)` at (s, t), 0 outside.
    #[inline(always)]
    fn bilinear(&self, s: f32, t: f32, texel: impl Fn(usize) -> [f32; 4]) -> [f32; 4] {
        let (x, y) = (s * self.width as f32 - 0.5, t * self.height as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        self.bilinear_at([x0 as i64, y0 as i64], [x - x0, y - y0], texel)
    }

    /// [`Self::bilinear`] from the sample's texel (the floor of its texel coordinates) and its fraction.
    #[inline(always)]
    pub(crate) fn bilinear_at(
        &self,
        [x0, y0]: [i64; 2],
        [fx, fy]: [f32; 2],
        texel: impl Fn(usize) -> [f32; 4],
    ) -> [f32; 4] {
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        let at = |i: i64, j: i64| -> [f32; 4] {
            if i < 0 || j < 0 || i >= w || j >= h { [0.0; 4] } else { texel((j * w + i) as usize) }
        };
        let (a, b, c, d) = (at(x0, y0), at(x0 + 1, y0), at(x0, y0 + 1), at(x0 + 1, y0 + 1));
        std::array::from_fn(|k| (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy)
    }

    /// Luminance-weighted energy of the image (relative irradiance x mm^2).
    pub fn energy(&self) -> f64 {
        let area = self.texel_mm * self.texel_mm;
        self.texels
            .iter()
            .map(|t| crate::metrics::luminance([t[0].to_f64(), t[1].to_f64(), t[2].to_f64()]) * area)
            .sum()
    }
}

impl LutEntry {
    /// The entry at half its resolution: each texel the mean of a 2 x 2 block (all four channels; a block past
    /// an odd edge is padded with zeros, so the image grows by at most one fine texel at its high-index sides),
    /// texels twice as large on the sensor. The same energy; what a mip level and the bake's
    /// [`crate::bake::BakeSettings::detail_tolerance`] test are made of. An empty entry stays empty.
    pub fn halved(&self) -> Self {
        if self.is_empty() {
            return self.clone();
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let mut texels = Vec::with_capacity(cw * ch);
        for y in 0..ch {
            for x in 0..cw {
                let mut sum = [0.0f32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (i, j) = (2 * x + dx, 2 * y + dy);
                    if i < w && j < h {
                        let t = self.texels[j * w + i];
                        for c in 0..4 {
                            sum[c] += t[c].to_f32();
                        }
                    }
                }
                texels.push(sum.map(|v| f16::from_f32(0.25 * v)));
            }
        }
        // The padded image's centre, in the fine image's texel coordinates, is (cw, ch).
        let centre_mm = self.window().to_mm([cw as f64, ch as f64]);
        Self {
            theta_deg: self.theta_deg,
            phi_deg: self.phi_deg,
            paraxial: self.paraxial,
            centre_mm,
            texel_mm: 2.0 * self.texel_mm,
            width: cw as u32,
            height: ch as u32,
            texels,
        }
    }

    /// How far [`Self::halved`] loses this entry's detail: `coarse`'s bilinear sample at each of this entry's
    /// texel centres against the texel, as the relative L1 distance of luminance (the sum of differences over
    /// the sum of the texels; 0 for an unlit entry). `coarse` must be this entry halved (its texel coordinates
    /// are half of this entry's).
    pub fn detail_lost(&self, coarse: &Self) -> f64 {
        let luma = |t: [f32; 4]| crate::metrics::luminance([t[0], t[1], t[2]].map(f64::from));
        let decoded = coarse.decoded();
        let (mut total, mut lost) = (0.0, 0.0);
        for y in 0..self.height {
            for x in 0..self.width {
                let fine = luma(self.texels[(y * self.width + x) as usize].map(f16::to_f32));
                // The fine texel centre x + 0.5 is at coarse coordinate (x + 0.5) / 2, its texel coordinate
                // (less half a texel) at x / 2 - 0.25.
                let (u, v) = (0.5 * x as f32 - 0.25, 0.5 * y as f32 - 0.25);
                let (u0, v0) = (u.floor(), v.floor());
                let s = coarse.bilinear_at([u0 as i64, v0 as i64], [u - u0, v - v0], |k| decoded[k]);
                total += fine;
                lost += (fine - luma(s)).abs();
            }
        }
        if total > 0.0 { lost / total } else { 0.0 }
    }
}

/// Where an entry's light lies in its own normalised paraxial frame (`n = (p - centre) / half`): the
/// luminance-weighted mean and covariance of its texels (each texel's own spread, 1/12 of a texel squared,
/// included, so a single-texel image still has a positive covariance).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EntryShape {
    pub mean: [f64; 2],
    pub cov: Mat2,
}

impl LutEntry {
    /// The entry's [`EntryShape`]; `None` for an empty or unlit entry.
    pub fn shape(&self) -> Option<EntryShape> {
        if self.is_empty() {
            return None;
        }
        let window = self.window();
        let (c, h) = (self.paraxial.centre_mm, self.paraxial.half_mm);
        let (mut sum, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for y in 0..self.height {
            for x in 0..self.width {
                let t = self.texels[(y * self.width + x) as usize];
                let l = crate::metrics::luminance([t[0].to_f64(), t[1].to_f64(), t[2].to_f64()]);
                if l <= 0.0 {
                    continue;
                }
                let p = window.to_mm([f64::from(x) + 0.5, f64::from(y) + 0.5]);
                let n = [(p[0] - c[0]) / h, (p[1] - c[1]) / h];
                sum += l;
                sx += l * n[0];
                sy += l * n[1];
                sxx += l * n[0] * n[0];
                syy += l * n[1] * n[1];
                sxy += l * n[0] * n[1];
            }
        }
        if !(sum > 0.0 && sum.is_finite()) {
            return None;
        }
        let mean = [sx / sum, sy / sum];
        let texel = (self.texel_mm / h).powi(2) / 12.0;
        let cov = [
            [sxx / sum - mean[0] * mean[0] + texel, sxy / sum - mean[0] * mean[1]],
            [sxy / sum - mean[0] * mean[1], syy / sum - mean[1] * mean[1] + texel],
        ];
        let shape = EntryShape { mean, cov };
        (mean.iter().chain(cov.iter().flatten()).all(|v| v.is_finite()) && mat_det(cov) > 0.0).then_some(shape)
    }
}

/// How a picked entry is laid onto the live frame, in normalised paraxial coordinates:
/// `n_live = offset + linear n_entry`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    pub linear: Mat2,
    pub offset: [f64; 2],
}

/// The largest stretch (either way) a fit may apply to an entry; beyond it the picks are too unlike each other
/// to be fitted onto one shape, and they are only turned and cross-faded.
pub const MAX_FIT_STRETCH: f64 = 2.0;

/// The determinant of `m`.
pub(crate) fn mat_det(m: Mat2) -> f64 {
    m[0][0] * m[1][1] - m[0][1] * m[1][0]
}

fn transpose(m: Mat2) -> Mat2 {
    [[m[0][0], m[1][0]], [m[0][1], m[1][1]]]
}

/// The inverse of `m` (not finite when `m` is singular).
pub(crate) fn mat_inverse(m: Mat2) -> Mat2 {
    let d = mat_det(m);
    [[m[1][1] / d, -m[0][1] / d], [-m[1][0] / d, m[0][0] / d]]
}

/// The square root of a symmetric positive definite 2x2 matrix: `(M + sqrt(det M) I) / sqrt(tr M + 2 sqrt(det M))`.
fn sqrt_spd(m: Mat2) -> Mat2 {
    let s = mat_det(m).max(0.0).sqrt();
    let t = (m[0][0] + m[1][1] + 2.0 * s).sqrt();
    [[(m[0][0] + s) / t, m[0][1] / t], [m[1][0] / t, (m[1][1] + s) / t]]
}

/// The eigenvalues of a symmetric 2x2 matrix, smaller first.
fn eigenvalues_sym(m: Mat2) -> [f64; 2] {
    let half_trace = 0.5 * (m[0][0] + m[1][1]);
    let r = (half_trace * half_trace - mat_det(m)).max(0.0).sqrt();
    [half_trace - r, half_trace + r]
}

/// Fits the entries picked for one light onto a common shape before they are cross-faded, so that two images
/// of a ghost that moved or stretched between the baked angles (more than its paraxial frame says) add up to
/// one image in between rather than two faded copies. Each pick is `(shape, transform, weight)`: its shape
/// in its own frame, the rotation (or mirror) the symmetry turns it by, and its interpolation weight.
///
/// The target is the weighted mean of the turned means and of the square roots of the turned covariances
/// (squared back); each entry is carried onto it by the linear map of optimal transport between Gaussians,
/// `A = C^-1/2 (C^1/2 C* C^1/2)^1/2 C^-1/2`, a symmetric stretch. A single pick, a pick without a shape (an
/// empty entry) or a stretch beyond [`MAX_FIT_STRETCH`] gives every pick its plain transform (no fit).
pub fn fit_picks(picks: &[(Option<EntryShape>, Mat2, f64)]) -> Vec<Fit> {
    let plain: Vec<Fit> = picks.iter().map(|&(_, t, _)| Fit { linear: t, offset: [0.0; 2] }).collect();
    let total: f64 = picks.iter().map(|p| p.2).sum();
    if picks.len() < 2 || total.is_nan() || total <= 0.0 {
        return plain;
    }
    let Some(turned): Option<Vec<(EntryShape, Mat2, f64)>> = picks
        .iter()
        .map(|&(shape, t, w)| {
            shape.map(|s| {
                let mean = mat_apply(t, s.mean);
                let cov = mat_mul(mat_mul(t, s.cov), transpose(t));
                (EntryShape { mean, cov }, t, w / total)
            })
        })
        .collect()
    else {
        return plain;
    };
    let mut mean = [0.0; 2];
    let mut root = [[0.0; 2]; 2];
    for (s, _, w) in &turned {
        let r = sqrt_spd(s.cov);
        for i in 0..2 {
            mean[i] += w * s.mean[i];
            for j in 0..2 {
                root[i][j] += w * r[i][j];
            }
        }
    }
    let target = mat_mul(root, root);
    let mut fits = Vec::with_capacity(turned.len());
    for (s, t, _) in &turned {
        let r = sqrt_spd(s.cov);
        let r_inv = mat_inverse(r);
        let a = mat_mul(mat_mul(r_inv, sqrt_spd(mat_mul(mat_mul(r, target), r))), r_inv);
        let a = [[a[0][0], 0.5 * (a[0][1] + a[1][0])], [0.5 * (a[0][1] + a[1][0]), a[1][1]]];
        let [lo, hi] = eigenvalues_sym(a);
        if !(lo >= 1.0 / MAX_FIT_STRETCH && hi <= MAX_FIT_STRETCH) {
            return plain;
        }
        let moved = mat_apply(a, s.mean);
        fits.push(Fit { linear: mat_mul(a, *t), offset: [mean[0] - moved[0], mean[1] - moved[1]] });
    }
    if fits.iter().all(|f| f.offset.iter().chain(f.linear.iter().flatten()).all(|v| v.is_finite())) {
        fits
    } else {
        plain
    }
}

/// Mantissa bits a LUT texel keeps of a half float's 10: a relative error of at most 2^-8 (0.4%, under the
/// display's own quantisation), and the low bits that hold only the ray grid's noise, which deflate cannot
/// compress, are zero (a third smaller files).
pub(crate) const TEXEL_MANTISSA_BITS: u32 = 7;
/// Coverage (alpha) is 1 from this fraction of an image's brightest texel (luminance) up, and falls linearly
/// to 0 below it.
pub(crate) const COVERAGE_FRACTION: f64 = 0.05;

/// `v` as a stored texel value: finite, non-negative (else 0), rounded to [`TEXEL_MANTISSA_BITS`].
pub(crate) fn texel_value(v: f32) -> f16 {
    let v = if v.is_finite() { v.max(0.0) } else { 0.0 };
    let drop = 10 - TEXEL_MANTISSA_BITS;
    let bits = f16::from_f32(v).to_bits();
    let rounded = (bits + (1 << (drop - 1))) & !((1u16 << drop) - 1);
    // Rounding up from the largest finite half would give infinity: keep the largest finite stored value.
    f16::from_bits(if f16::from_bits(rounded).is_finite() { rounded } else { 0x7bff & !((1u16 << drop) - 1) })
}

/// Linear RGB texels of one image as stored: `texel_value`s with their coverage as alpha (luminance over
/// `COVERAGE_FRACTION` of the image's brightest, at most 1; computed from the stored values, so that a
/// file, which does not store alpha, loads to exactly these texels).
pub fn texels_with_coverage(rgb: impl Iterator<Item = [f32; 3]>) -> Vec<[f16; 4]> {
    let mut texels: Vec<[f16; 4]> =
        rgb.map(|p| [texel_value(p[0]), texel_value(p[1]), texel_value(p[2]), f16::ZERO]).collect();
    set_coverage(&mut texels);
    texels
}

/// Sets every texel's alpha to its coverage (see [`texels_with_coverage`]).
pub(crate) fn set_coverage(texels: &mut [[f16; 4]]) {
    let luma = |t: &[f16; 4]| crate::metrics::luminance([t[0].to_f64(), t[1].to_f64(), t[2].to_f64()]);
    let peak = texels.iter().map(luma).fold(0.0, f64::max);
    for t in texels.iter_mut() {
        let alpha = if peak > 0.0 { (luma(t) / (COVERAGE_FRACTION * peak)).min(1.0) } else { 0.0 };
        t[3] = f16::from_f64(alpha);
    }
}

/// One LUT ghost: its images over thetas x azimuths.
#[derive(Clone, Debug, PartialEq)]
pub struct LutGhost {
    /// Index in the lens's ghost list (`PHOTO_GHOST` for a photo LUT).
    pub ghost: u32,
    /// The two reflecting surfaces (i, j).
    pub surfaces: [u32; 2],
    /// Hash of everything the images depend on (lens, spectrum, stop, bake settings, the ghost): a re-bake keeps
    /// a ghost whose key is unchanged.
    pub key: u64,
    /// Increasing, degrees.
    pub thetas_deg: Vec<f64>,
    /// Per theta interval (`thetas_deg.len() - 1` of them, or none: all false): whether the run time fits
    /// the entries on either side onto one shape ([`fit_picks`]) before cross-fading them, because at the bake
    /// that predicted the interval's middle better than the plain cross-fade.
    pub fitted: Vec<bool>,
    /// Increasing, degrees from the symmetry axis, inside the wedge.
    pub phis_deg: Vec<f64>,
    /// `thetas x phis`, theta-major.
    pub entries: Vec<LutEntry>,
}

impl LutGhost {
    pub fn entry(&self, theta: usize, phi: usize) -> &LutEntry {
        &self.entries[theta * self.phis_deg.len() + phi]
    }
}

/// A whole LUT: its ghosts (or photo) and what it was made for.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostLut {
    pub kind: LutKind,
    pub lens_id: String,
    /// [`crate::bake::lut_fingerprint`] of the lens and settings it was baked for (0 for a photo LUT: any lens).
    pub lens_fingerprint: u64,
    /// The rule `lens_fingerprint` was made by (`crate::fingerprint::SCHEME`; 0: a file from before schemes,
    /// whose fingerprint cannot be compared).
    pub fingerprint_scheme: u32,
    pub wavelengths_nm: Vec<f64>,
    /// The f-number it was baked at (0 for a photo).
    pub f_number: f64,
    pub symmetry: Symmetry,
    /// The largest theta baked, degrees.
    pub theta_max_deg: f64,
    pub ghosts: Vec<LutGhost>,
}

impl GhostLut {
    pub fn entry_count(&self) -> usize {
        self.ghosts.iter().map(|g| g.entries.len()).sum()
    }

    /// Texels over every entry.
    pub fn texel_count(&self) -> usize {
        self.ghosts.iter().flat_map(|g| &g.entries).map(|e| e.texels.len()).sum()
    }

    /// The LUT ghost of lens ghost `g`, if any.
    pub fn ghost(&self, g: usize) -> Option<&LutGhost> {
        self.ghosts.iter().find(|l| l.ghost as usize == g)
    }
}
