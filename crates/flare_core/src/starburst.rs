//! The starburst: the light's own image, spread by far-field (Fraunhofer) diffraction at the stop, drawn at
//! its true physical scale and brightness.
//!
//! # How it works
//! The point-spread function of an aperture is the squared magnitude of its Fourier transform. On the
//! sensor it scales with `lambda N` (N the working f-number): a point `r` mm from the light's image sits at
//! `u = r / (lambda N)` in the pattern's own units. Everything but a core a few microns wide is far field,
//! and there the pattern is self-similar: along every direction `phi` the energy density falls as `u^-3`
//! (straight blade edges throw their light into rays, a round stop into rings, both `u^-3` on average), so
//!
//! `I(r, phi) = E c(phi) lambda N / r^3`  (relative irradiance),
//!
//! with `E` the light's power through the entrance pupil (its area in mm^2 times the incoming irradiance)
//! and `c(phi)` the pattern's angular profile. The share of the energy beyond any radius `R` well outside
//! the core is then `C lambda N / R` with `C` the integral of `c` over the circle (2 / pi^2 for a circle):
//! it grows in proportion to `lambda N` as the stop closes and is the same for every wavelength up to that
//! factor, which spreads red rays further than blue ones.
//!
//! [`Starburst::compute`] measures `c(phi)` once per aperture: its `STARBURST_MASK_SIZE`^2 raster is drawn
//! texel for texel into a grid twice as wide (one frequency bin is `lambda N / 2`), transformed with rustfft (rows, then columns),
//! squared and normalised to a total energy of 1; then, on the ring `BAND_START_U` to `BAND_END_U`
//! (well outside the core, well below the raster's one-texel edge ramp, which would dim the rays), `u^3` times the energy density is averaged
//! into `PROFILE_SIZE` angular bins. The renderer ([`crate::render::FlareScene::build`] and the starburst
//! pass of both twins) evaluates `I(r, phi)` at every pixel out to the radius where it falls below a
//! quarter of an 8-bit step at the frame's exposure (or the whole frame), so a bright sun's rays reach as
//! far as they would in a photograph and never fade at a texture's edge. Inside one pixel of the light's
//! image the rest of the energy (`E` minus the far field's share) is spread evenly: the blown-out light.

use rayon::prelude::*;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex32;

use crate::aperture::ApertureMask;

/// The aperture raster the starburst is computed from ([`crate::aperture::Aperture::rasterise`]); it is
/// drawn texel for texel into an FFT grid twice as wide (one frequency bin is `lambda N / 2` on the sensor).
pub(crate) const STARBURST_MASK_SIZE: usize = 512;
/// Angular bins of the far-field profile, over the full circle (0.7 degrees each: on the measuring ring,
/// FFT bins near a lattice direction lie up to 0.45 degrees apart).
pub(crate) const PROFILE_SIZE: usize = 512;
/// The ring the profile is measured on, in units of `lambda N` from the centre.
pub(crate) const BAND_START_U: f64 = 16.0;
pub(crate) const BAND_END_U: f64 = 64.0;

/// The aperture's far-field diffraction (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Starburst {
    /// `c(phi)` over `PROFILE_SIZE` bins, bin `k` centred on `phi = (k + 0.5) 2 pi / PROFILE_SIZE`
    /// (pixel axes: x right, y down), divided by its peak (so the largest is 1).
    pub profile: Vec<f32>,
    /// The peak of `c(phi)` (per radian, for a total energy of 1).
    pub profile_peak: f64,
    /// `C`, the integral of `c(phi)` over the circle: the share of the energy beyond `R` is `C lambda N / R`.
    pub far_total: f64,
}

/// A 2D FFT in place of an `m` x `m` grid (row by row): rows, then columns. The starburst's far field and the
/// front dirt's footprint convolution ([`crate::dirt`]) both use it. Rows go to rayon's threads; the columns
/// are made rows by a transpose (blocks of [`TRANSPOSE_BLOCK`] squared), transformed as rows and put back.
/// Each 1D transform is the one rustfft computes alone, so the result is the same, bit for bit, on any number
/// of threads (a test holds it to the serial rows-then-columns form).
pub(crate) fn fft_2d(grid: &mut [Complex32], m: usize, fft: &dyn rustfft::Fft<f32>) {
    if m == 0 {
        return;
    }
    grid.par_chunks_mut(m).for_each(|row| fft.process(row));
    let mut columns = vec![Complex32::new(0.0, 0.0); m * m];
    transpose(grid, &mut columns, m);
    columns.par_chunks_mut(m).for_each(|column| fft.process(column));
    transpose(&columns, grid, m);
}

/// The side of the square blocks [`transpose`] copies (8 KiB of `Complex32` each: two fit a core's L1).
const TRANSPOSE_BLOCK: usize = 32;

/// `to[i m + j] = from[j m + i]` for an `m` x `m` grid, bands of [`TRANSPOSE_BLOCK`] rows of `to` in parallel.
fn transpose(from: &[Complex32], to: &mut [Complex32], m: usize) {
    to.par_chunks_mut(TRANSPOSE_BLOCK * m).enumerate().for_each(|(band, out)| {
        let i0 = band * TRANSPOSE_BLOCK;
        let rows = out.len() / m;
        for j0 in (0..m).step_by(TRANSPOSE_BLOCK) {
            for j in j0..(j0 + TRANSPOSE_BLOCK).min(m) {
                for di in 0..rows {
                    out[di * m + j] = from[j * m + i0 + di];
                }
            }
        }
    });
}

impl Starburst {
    /// The far-field profile of `mask` (its texels across the aperture's diameter; see
    /// `STARBURST_MASK_SIZE`).
    pub fn compute(mask: &ApertureMask) -> Self {
        let a = mask.size.max(2);
        let n = (2 * a).next_power_of_two();
        let mut grid = vec![Complex32::new(0.0, 0.0); n * n];
        let offset = (n - a) / 2;
        for j in 0..a {
            for i in 0..a {
                let texel = f32::from(mask.texels.get(j * a + i).copied().unwrap_or(0)) / 255.0;
                grid[(offset + j) * n + offset + i] = Complex32::new(texel, 0.0);
            }
        }
        let fft = FftPlanner::<f32>::new().plan_fft_forward(n);
        fft_2d(&mut grid, n, fft.as_ref());
        let total: f64 = grid.iter().map(|c| f64::from(c.norm_sqr())).sum();
        if !(total.is_finite() && total > 0.0) {
            // A closed stop lets no light through: no starburst.
            return Self { profile: vec![0.0; PROFILE_SIZE], profile_peak: 0.0, far_total: 0.0 };
        }
        // One bin is `bin_u` = a / n in units of lambda N; energy density per unit u^2 is energy / bin_u^2.
        let bin_u = a as f64 / n as f64;
        let mut sum = vec![0.0f64; PROFILE_SIZE];
        let mut weight = vec![0.0f64; PROFILE_SIZE];
        let half = (n / 2) as i64;
        let reach = (BAND_END_U / bin_u).ceil() as i64;
        for dj in -reach..=reach {
            for di in -reach..=reach {
                let u = (di as f64).hypot(dj as f64) * bin_u;
                if !(BAND_START_U..BAND_END_U).contains(&u) {
                    continue;
                }
                // Frequency (di, dj) is stored at ((di + n) % n, (dj + n) % n).
                let (i, j) = ((di + half * 2) as usize % n, (dj + half * 2) as usize % n);
                let density = f64::from(grid[j * n + i].norm_sqr()) / total / (bin_u * bin_u);
                // Shared between the two nearest angular bins, as the renderer interpolates them.
                let (k0, f) = angle_bins(dj as f64, di as f64);
                for (k, w) in [(k0, 1.0 - f), ((k0 + 1) % PROFILE_SIZE, f)] {
                    sum[k] += w * density * u.powi(3);
                    weight[k] += w;
                }
            }
        }
        let c = fill_gaps(&sum, &weight);
        let dphi = std::f64::consts::TAU / PROFILE_SIZE as f64;
        let far_total = c.iter().sum::<f64>() * dphi;
        let profile_peak = c.iter().copied().fold(0.0, f64::max);
        let profile = c.iter().map(|v| if profile_peak > 0.0 { (v / profile_peak) as f32 } else { 0.0 }).collect();
        Self { profile, profile_peak, far_total }
    }

    /// `c(phi) / peak` at the pixel offset (dx right, dy down), interpolated between the two nearest bins
    /// (wrapping around the circle): what the starburst shader computes.
    pub fn profile_at(profile: &[f32], dx: f32, dy: f32) -> f32 {
        let n = profile.len();
        if n == 0 {
            return 0.0;
        }
        let turn = dy.atan2(dx) / std::f32::consts::TAU;
        let t = (turn - turn.floor()) * n as f32 - 0.5;
        let t = if t < 0.0 { t + n as f32 } else { t };
        let i0 = (t as usize).min(n - 1);
        let f = t - i0 as f32;
        profile[i0] * (1.0 - f) + profile[(i0 + 1) % n] * f
    }

    /// A `size`^2 picture of the pattern from 1 to `size / 2` pixels out, log-scaled to 0..1 over six decades
    /// (for the aperture panel).
    pub fn preview(&self, size: usize) -> Vec<f32> {
        let c = size as f32 / 2.0;
        let mut out = vec![0.0f32; size * size];
        for j in 0..size {
            for i in 0..size {
                let (dx, dy) = (i as f32 + 0.5 - c, j as f32 + 0.5 - c);
                let r = dx.hypot(dy).max(1.0);
                let value = Self::profile_at(&self.profile, dx, dy) / (r * r * r);
                out[j * size + i] = ((value.max(1e-6).log10() + 6.0) / 6.0).clamp(0.0, 1.0);
            }
        }
        out
    }
}

/// The lower of the two profile bins around the direction (dy, dx) (pixel axes: x right, y down) and the
/// weight of the upper one (bin `k` is centred on `(k + 0.5) / PROFILE_SIZE` turns).
fn angle_bins(dy: f64, dx: f64) -> (usize, f64) {
    let n = PROFILE_SIZE as f64;
    let turn = dy.atan2(dx) / std::f64::consts::TAU;
    let t = (turn - turn.floor()) * n - 0.5;
    let t = if t < 0.0 { t + n } else { t };
    let k = (t as usize).min(PROFILE_SIZE - 1);
    (k, t - k as f64)
}

/// Weighted means per bin; a bin no sample reached takes the value interpolated between its nearest
/// reached neighbours around the circle (all zero when none was reached).
fn fill_gaps(sum: &[f64], weight: &[f64]) -> Vec<f64> {
    let n = sum.len();
    let reached: Vec<usize> = (0..n).filter(|&k| weight[k] > 1e-9).collect();
    let mean = |k: usize| sum[k] / weight[k];
    (0..n)
        .map(|k| {
            if weight[k] > 1e-9 {
                return mean(k);
            }
            let after = reached.iter().copied().find(|&r| r > k).or(reached.first().copied());
            let before = reached.iter().copied().rev().find(|&r| r < k).or(reached.last().copied());
            match (before, after) {
                (Some(b), Some(a)) => {
                    let (gap_b, gap_a) = ((k + n - b) % n, (a + n - k) % n);
                    let t = gap_b as f64 / (gap_a + gap_b).max(1) as f64;
                    mean(b) * (1.0 - t) + mean(a) * t
                }
                _ => 0.0,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aperture::{Aperture, ApertureShape};

    /// The parallel 2D FFT gives the serial rows-then-columns transform's bits, forward and inverse, on a grid
    /// whose side is not a multiple of the transpose's block.
    #[test]
    fn the_parallel_fft_is_the_serial_one_bit_for_bit() {
        let serial = |grid: &mut [Complex32], m: usize, fft: &dyn rustfft::Fft<f32>| {
            for row in grid.chunks_mut(m) {
                fft.process(row);
            }
            let mut column = vec![Complex32::new(0.0, 0.0); m];
            for i in 0..m {
                for j in 0..m {
                    column[j] = grid[j * m + i];
                }
                fft.process(&mut column);
                for j in 0..m {
                    grid[j * m + i] = column[j];
                }
            }
        };
        let mut planner = FftPlanner::<f32>::new();
        for m in [1usize, 40, 128] {
            let grid: Vec<Complex32> = (0..m * m)
                .map(|k| Complex32::new(((k * 7919) % 257) as f32 / 257.0, ((k * 104_729) % 61) as f32 / 61.0 - 0.5))
                .collect();
            for fft in [planner.plan_fft_forward(m), planner.plan_fft_inverse(m)] {
                let (mut a, mut b) = (grid.clone(), grid.clone());
                fft_2d(&mut a, m, fft.as_ref());
                serial(&mut b, m, fft.as_ref());
                let bits =
                    |g: &[Complex32]| g.iter().flat_map(|c| [c.re.to_bits(), c.im.to_bits()]).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "side {m}");
            }
        }
    }

    #[test]
    fn a_round_stop_sends_two_over_pi_squared_of_its_light_past_u() {
        // The Airy pattern's energy outside radius u (in lambda N) is 2 / (pi^2 u) far from the core.
        let s = Starburst::compute(
            &Aperture { shape: ApertureShape::Circle, f_number: None }.rasterise(STARBURST_MASK_SIZE),
        );
        let airy = 2.0 / std::f64::consts::PI.powi(2);
        assert!((s.far_total / airy - 1.0).abs() < 0.1, "C = {} vs {airy}", s.far_total);
        // And evenly in every direction.
        let (lo, hi) = s.profile.iter().fold((f32::MAX, 0.0f32), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        assert!(lo > 0.7 * hi, "{lo} {hi}");
    }

    #[test]
    fn a_hexagon_makes_six_rays_across_its_edges() {
        let mask =
            Aperture { shape: ApertureShape::Blades { count: 6, rotation_deg: 0.0, roundness: 0.0 }, f_number: None }
                .rasterise(STARBURST_MASK_SIZE);
        let s = Starburst::compute(&mask);
        assert!(s.profile.iter().all(|p| p.is_finite() && (0.0..=1.0).contains(p)));
        // Rays run perpendicular to the edges: a vertex on +x puts edges facing 30, 90, 150 ... degrees, so
        // there is far more light along 90 degrees than along 60 (between rays).
        let along = |deg: f32| {
            let (dx, dy) = (deg.to_radians().cos(), -deg.to_radians().sin());
            Starburst::profile_at(&s.profile, dx, dy)
        };
        assert!(along(90.0) > 10.0 * along(60.0), "ray {} vs gap {}", along(90.0), along(60.0));
        assert!((along(30.0) / along(90.0) - 1.0).abs() < 0.3, "six equal rays");
        // Straight edges put more light in the far field than a circle of the same width.
        assert!(s.far_total > 0.15 && s.far_total < 0.6, "{}", s.far_total);
    }

    #[test]
    fn a_closed_stop_has_no_starburst() {
        let mask = ApertureMask { size: 8, texels: vec![0; 64] };
        let s = Starburst::compute(&mask);
        assert_eq!((s.far_total, s.profile_peak), (0.0, 0.0));
        assert!(s.profile.iter().all(|p| *p == 0.0));
    }
}
