//! The starburst: far-field (Fraunhofer) diffraction of the aperture, drawn at the light's image.
//!
//! # How it works
//! The far-field pattern of an aperture is the squared magnitude of its Fourier transform. The mask (see
//! [`crate::aperture`]) is drawn into a [`FFT_SIZE`]^2 grid at a quarter of its width (zero padding, so the
//! pattern is sampled finely), transformed with rustfft (rows, then columns), squared and centred. That
//! pattern belongs to one reference wavelength; the diffraction angle grows with the wavelength
//! (theta ~ lambda / D), so the pattern for lambda is the reference pattern scaled by lambda / lambda_ref.
//! [`Starburst::compute`] sums those scaled copies over the spectrum with each wavelength's RGB weight,
//! which spreads red spikes further than blue ones: the coloured fringes of real starbursts. The result is
//! normalised to 1 at the centre and faded to 0 at the texture edge, and is drawn as a texture centred on
//! the light source's image.

use rustfft::FftPlanner;
use rustfft::num_complex::Complex32;

use crate::aperture::ApertureMask;
use crate::spectrum::Spectrum;

/// FFT grid size.
pub const FFT_SIZE: usize = 512;
/// Output texture size.
pub const STARBURST_SIZE: usize = 256;
/// The wavelength the base pattern belongs to.
pub const REFERENCE_WAVELENGTH_NM: f64 = 550.0;

/// A starburst texture: `size` x `size` RGBA (linear, peak 1), row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Starburst {
    pub size: usize,
    pub rgba: Vec<[f32; 4]>,
}

impl Starburst {
    /// The diffraction pattern of `mask` summed over `spectrum`.
    pub fn compute(mask: &ApertureMask, spectrum: &Spectrum) -> Self {
        let n = FFT_SIZE;
        let aperture_px = n / 4;
        let mut grid = vec![Complex32::new(0.0, 0.0); n * n];
        let offset = (n - aperture_px) / 2;
        for j in 0..aperture_px {
            for i in 0..aperture_px {
                let u = -1.0 + 2.0 * (i as f32 + 0.5) / aperture_px as f32;
                let v = 1.0 - 2.0 * (j as f32 + 0.5) / aperture_px as f32;
                grid[(offset + j) * n + offset + i] = Complex32::new(mask.sample(u, v), 0.0);
            }
        }
        let fft = FftPlanner::<f32>::new().plan_fft_forward(n);
        for row in grid.chunks_mut(n) {
            fft.process(row);
        }
        let mut column = vec![Complex32::new(0.0, 0.0); n];
        for i in 0..n {
            for j in 0..n {
                column[j] = grid[j * n + i];
            }
            fft.process(&mut column);
            for j in 0..n {
                grid[j * n + i] = column[j];
            }
        }
        // Power, centred (fftshift).
        let half = n / 2;
        let mut power = vec![0.0f32; n * n];
        for j in 0..n {
            for i in 0..n {
                power[((j + half) % n) * n + (i + half) % n] = grid[j * n + i].norm_sqr();
            }
        }
        let peak = power[half * n + half].max(f32::MIN_POSITIVE);
        let sample = |x: f32, y: f32| -> f32 {
            // Bilinear in the centred power grid; (x, y) in grid texels from the centre.
            let gx = x + half as f32;
            let gy = y + half as f32;
            if gx < 0.0 || gy < 0.0 || gx >= (n - 1) as f32 || gy >= (n - 1) as f32 {
                return 0.0;
            }
            let (x0, y0) = (gx.floor() as usize, gy.floor() as usize);
            let (fx, fy) = (gx - x0 as f32, gy - y0 as f32);
            let p = |i: usize, j: usize| power[j * n + i];
            (p(x0, y0) * (1.0 - fx) + p(x0 + 1, y0) * fx) * (1.0 - fy)
                + (p(x0, y0 + 1) * (1.0 - fx) + p(x0 + 1, y0 + 1) * fx) * fy
        };
        let size = STARBURST_SIZE;
        let mut rgba = vec![[0.0f32; 4]; size * size];
        let centre = size as f32 / 2.0;
        for (k, &w_nm) in spectrum.wavelengths_nm.iter().enumerate() {
            let weight = spectrum.weights_rgb[k];
            let shrink = (REFERENCE_WAVELENGTH_NM / w_nm) as f32;
            for j in 0..size {
                for i in 0..size {
                    let x = (i as f32 + 0.5 - centre) * shrink;
                    let y = (j as f32 + 0.5 - centre) * shrink;
                    let value = sample(x, y) / peak;
                    let texel = &mut rgba[j * size + i];
                    for c in 0..3 {
                        texel[c] += weight[c] as f32 * value;
                    }
                }
            }
        }
        for j in 0..size {
            for i in 0..size {
                let r = ((i as f32 + 0.5 - centre).hypot(j as f32 + 0.5 - centre) / centre).min(1.0);
                let fade = (1.0 - r * r).powi(2);
                let texel = &mut rgba[j * size + i];
                for c in texel.iter_mut().take(3) {
                    *c = (*c * fade).max(0.0);
                }
                texel[3] = 1.0;
            }
        }
        Self { size, rgba }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aperture::{Aperture, ApertureShape};

    #[test]
    fn a_hexagon_makes_six_spikes_and_the_centre_is_brightest() {
        let mask =
            Aperture { shape: ApertureShape::Blades { count: 6, rotation_deg: 0.0, roundness: 0.0 }, f_number: None }
                .rasterise(128);
        let s = Starburst::compute(&mask, &Spectrum::single(550.0).unwrap());
        let n = s.size;
        let at = |x: f32, y: f32| s.rgba[((n as f32 / 2.0 + y) as usize) * n + (n as f32 / 2.0 + x) as usize][1];
        // The four texels around the centre sit half a texel from the peak of the narrow Airy-like core.
        let centre = at(0.0, 0.0).max(at(-1.0, 0.0)).max(at(0.0, -1.0)).max(at(-1.0, -1.0));
        assert!((0.8..=1.0).contains(&centre), "{centre}");
        assert!(s.rgba.iter().all(|t| t[1] <= centre + 1e-6), "the centre is the brightest");
        assert!(s.rgba.iter().all(|t| t.iter().all(|v| v.is_finite() && *v >= 0.0)));
        // Spikes run perpendicular to the hexagon's edges: edges face 30, 90, 150 degrees for a vertex on +x,
        // so there is more light at radius 40 along 90 degrees than along 60 degrees (between spikes).
        let r = 40.0f32;
        let along = |deg: f32| {
            (0..5)
                .map(|d| {
                    at(r * (deg + d as f32 - 2.0).to_radians().cos(), -r * (deg + d as f32 - 2.0).to_radians().sin())
                })
                .sum::<f32>()
        };
        assert!(along(90.0) > 3.0 * along(60.0), "spike {} vs gap {}", along(90.0), along(60.0));
    }

    #[test]
    fn longer_wavelengths_spread_further() {
        let mask = Aperture { shape: ApertureShape::Circle, f_number: None }.rasterise(128);
        let blue = Starburst::compute(&mask, &Spectrum::single(450.0).unwrap());
        let red = Starburst::compute(&mask, &Spectrum::single(650.0).unwrap());
        let energy_outside = |s: &Starburst| {
            let c = s.size as f32 / 2.0;
            s.rgba
                .iter()
                .enumerate()
                .filter(|(k, _)| ((k % s.size) as f32 - c).hypot((k / s.size) as f32 - c) > 6.0)
                .map(|(_, t)| t[0])
                .sum::<f32>()
        };
        assert!(energy_outside(&red) > 1.3 * energy_outside(&blue));
    }
}
