//! Wavelength sampling and colour: which wavelengths a flare is rendered at, and what colour each adds.
//!
//! # How it works
//! A [`Spectrum`] is a list of wavelengths with a linear-sRGB weight each; a ghost rendered at every
//! wavelength and summed with these weights gives its colour, fringes included.
//! - [`Spectrum::rgb`]: the three wavelengths of `crates/flare_core/METHOD.md` (650, 510, 475 nm), each feeding one
//!   channel: cheap, and the usual real-time choice.
//! - [`Spectrum::cie`]: N wavelengths (2 to 32) spread evenly over 400-700 nm, weighted by the CIE 1931 2-degree
//!   colour-matching functions and converted XYZ -> linear sRGB (D65 primaries). The matching functions are
//!   the multi-lobe Gaussian fit of Wyman, Sloan and Shirley (JCGT 2013), within a few percent of the
//!   tabulated CIE data across the visible range. The weights are normalised so that a flat spectrum sums to
//!   white (1, 1, 1), i.e. equal-energy white is neutral; negative sRGB components (the spectral locus lies
//!   outside the sRGB gamut) are kept in the sum, where they cancel, and each sprite's colour is clamped at 0.

/// The most wavelengths a spectrum may have.
pub(crate) const MAX_WAVELENGTHS: usize = 32;
/// The RGB wavelengths of the paraxial-flare method.
pub(crate) const RGB_WAVELENGTHS_NM: [f64; 3] = [650.0, 510.0, 475.0];

/// Wavelengths and their linear-sRGB weights.
#[derive(Clone, Debug, PartialEq)]
pub struct Spectrum {
    pub wavelengths_nm: Vec<f64>,
    pub weights_rgb: Vec<[f64; 3]>,
}

/// Why a spectrum cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpectrumError {
    #[error("{0} wavelengths: a spectrum has 1 to {MAX_WAVELENGTHS} (1 for one wavelength, 3 for RGB)")]
    Count(usize),
    #[error("wavelength {0} nm is outside {MIN_WAVELENGTH_NM}-{MAX_WAVELENGTH_NM} nm")]
    Range(f64),
}

/// The wavelengths FlareLab traces and draws (nm), for every command and file alike: near UV to near IR, where
/// the glass models hold.
pub const MIN_WAVELENGTH_NM: f64 = 300.0;
pub const MAX_WAVELENGTH_NM: f64 = 1000.0;

impl Spectrum {
    /// 650 / 510 / 475 nm into R / G / B.
    pub fn rgb() -> Self {
        Self {
            wavelengths_nm: RGB_WAVELENGTHS_NM.to_vec(),
            weights_rgb: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// One wavelength drawn white (for inspecting a single wavelength).
    pub fn single(wavelength_nm: f64) -> Result<Self, SpectrumError> {
        if !(MIN_WAVELENGTH_NM..=MAX_WAVELENGTH_NM).contains(&wavelength_nm) {
            return Err(SpectrumError::Range(wavelength_nm));
        }
        Ok(Self { wavelengths_nm: vec![wavelength_nm], weights_rgb: vec![[1.0, 1.0, 1.0]] })
    }

    /// `count` wavelengths over 400-700 nm weighted by the CIE 1931 matching functions.
    pub fn cie(count: usize) -> Result<Self, SpectrumError> {
        if !(2..=MAX_WAVELENGTHS).contains(&count) {
            return Err(SpectrumError::Count(count));
        }
        let step = 300.0 / count as f64;
        let wavelengths_nm: Vec<f64> = (0..count).map(|k| 400.0 + step * (k as f64 + 0.5)).collect();
        let raw: Vec<[f64; 3]> = wavelengths_nm.iter().map(|&w| xyz_to_linear_srgb(cie_1931_xyz(w))).collect();
        let mut sum = [0.0; 3];
        for w in &raw {
            for c in 0..3 {
                sum[c] += w[c];
            }
        }
        let weights_rgb = raw.iter().map(|w| [w[0] / sum[0], w[1] / sum[1], w[2] / sum[2]]).collect();
        Ok(Self { wavelengths_nm, weights_rgb })
    }

    /// The spectrum a user asks for by count: 1 is the d-line alone, 3 is RGB, others are CIE-weighted.
    pub fn with_count(count: usize) -> Result<Self, SpectrumError> {
        match count {
            1 => Self::single(crate::optics::D_LINE_NM),
            3 => Ok(Self::rgb()),
            n => Self::cie(n),
        }
    }

    pub fn len(&self) -> usize {
        self.wavelengths_nm.len()
    }

    pub fn is_empty(&self) -> bool {
        self.wavelengths_nm.is_empty()
    }
}

fn lobe(x: f64, mu: f64, sigma_low: f64, sigma_high: f64) -> f64 {
    let t = (x - mu) / if x < mu { sigma_low } else { sigma_high };
    (-0.5 * t * t).exp()
}

/// CIE 1931 2-degree colour-matching functions (x-bar, y-bar, z-bar), Wyman-Sloan-Shirley 2013 fit.
pub(crate) fn cie_1931_xyz(wavelength_nm: f64) -> [f64; 3] {
    let w = wavelength_nm;
    let x =
        1.056 * lobe(w, 599.8, 37.9, 31.0) + 0.362 * lobe(w, 442.0, 16.0, 26.7) - 0.065 * lobe(w, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(w, 568.8, 46.9, 40.5) + 0.286 * lobe(w, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(w, 437.0, 11.8, 36.0) + 0.681 * lobe(w, 459.0, 26.0, 13.8);
    [x, y, z]
}

/// XYZ to linear sRGB (IEC 61966-2-1, D65).
pub(crate) fn xyz_to_linear_srgb([x, y, z]: [f64; 3]) -> [f64; 3] {
    [3.2406 * x - 1.5372 * y - 0.4986 * z, -0.9689 * x + 1.8758 * y + 0.0415 * z, 0.0557 * x - 0.2040 * y + 1.0570 * z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_functions_have_their_known_peaks() {
        // Tabulated CIE 1931: y-bar(555) = 1.000, x-bar(600) = 1.062, z-bar(445) = 1.782 (approximately).
        assert!((cie_1931_xyz(555.0)[1] - 1.0).abs() < 0.03);
        assert!((cie_1931_xyz(600.0)[0] - 1.062).abs() < 0.03);
        assert!((cie_1931_xyz(445.0)[2] - 1.782).abs() < 0.1);
        assert!(cie_1931_xyz(780.0).iter().all(|v| v.abs() < 0.01));
    }

    #[test]
    fn cie_spectrum_sums_to_white_and_orders_hues() {
        for n in [2, 8, 16, 32] {
            let s = Spectrum::cie(n).unwrap();
            for c in 0..3 {
                let total: f64 = s.weights_rgb.iter().map(|w| w[c]).sum();
                assert!((total - 1.0).abs() < 1e-12);
            }
        }
        let s = Spectrum::cie(16).unwrap();
        let first = s.weights_rgb[0];
        let last = s.weights_rgb[15];
        assert!(first[2] > first[0], "the short end is blue: {first:?}");
        assert!(last[0] > last[2] && last[0] > last[1], "the long end is red: {last:?}");
        assert_eq!(Spectrum::with_count(3).unwrap(), Spectrum::rgb());
        assert!(Spectrum::cie(33).is_err() && Spectrum::cie(1).is_err());
    }
}
