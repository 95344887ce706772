//! How much light an interface reflects: Fresnel reflection of bare glass and thin-film AR coatings.
//!
//! # How it works
//! A ghost's brightness is the product of the reflectances of its two surfaces, so these numbers set both
//! how bright each ghost is and, through their wavelength dependence, its tint.
//! - Every case goes through the thin-film characteristic-matrix method (Macleod, *Thin-Film Optical
//!   Filters*, ch. 2): each layer j of index n_j and thickness d_j is the matrix
//!   `[[cos d, i sin d / eta], [i eta sin d, cos d]]` with phase `d = 2 pi n_j d_j cos t_j / lambda` and tilted
//!   admittance `eta = n cos t` (s) or `n / cos t` (p). `r = (eta0 B - C) / (eta0 B + C)` with
//!   `[B, C] = M [1, eta_substrate]`, `R = |r|^2`, `T = 4 eta0 Re(eta_s) / |eta0 B + C|^2`, averaged over s and p
//!   (unpolarised light). With no layer this is exactly the Fresnel equations.
//! - Angles enter as the sine of the angle of incidence in the incident medium; `cos t` in every layer is
//!   complex past the critical angle, which gives total internal reflection (R = 1) with no special case.
//! - [`Coating::QuarterWave`] is Hullin et al. 2011's single layer: index `max(sqrt(n0 n2), 1.38)` (MgF2 is
//!   the lowest practical) and thickness `lambda0 / (4 n1)`, so reflection vanishes (or is least) at the
//!   design wavelength at normal incidence and rises towards the ends of the spectrum: purple or
//!   amber ghosts.
//! - Where the layers sit: on the side of the interface with the lower index (the air side of a glass-air
//!   surface); [`CoatingLayer`]s are listed from the surface outwards into that medium. Light arriving from
//!   the other side meets them in reverse order.

use rustfft::num_complex::Complex64;
use std::sync::Arc;

use crate::optics::{Coating, CoatingLayer, Lens};

/// Unpolarised reflectance and transmittance of one interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reflection {
    pub reflectance: f64,
    pub transmittance: f64,
}

/// The lowest index a practical single-layer coating has (MgF2).
pub(crate) const MGF2_INDEX: f64 = 1.38;

/// The layers a coating puts on an interface between indices `n_a` and `n_b`, listed from the surface
/// outwards into the lower-index medium.
pub(crate) fn coating_layers(coating: &Coating, n_a: f64, n_b: f64) -> Vec<CoatingLayer> {
    match coating {
        Coating::Uncoated => Vec::new(),
        Coating::QuarterWave { design_wavelength_nm, layer_index } => {
            let n1 = layer_index.unwrap_or_else(|| (n_a * n_b).sqrt().max(MGF2_INDEX));
            vec![CoatingLayer { index: n1, thickness_nm: design_wavelength_nm / (4.0 * n1) }]
        }
        Coating::Multilayer { layers } => layers.clone(),
    }
}

/// Reflectance of the interface from medium `n_incident` into `n_exit` with `coating`, for light of
/// `wavelength_nm` arriving at `sin_incidence` (sine of the angle to the normal, 0..=1).
pub fn reflection(
    coating: &Coating,
    n_incident: f64,
    n_exit: f64,
    wavelength_nm: f64,
    sin_incidence: f64,
) -> Reflection {
    let mut layers = coating_layers(coating, n_incident, n_exit);
    // Layers are listed from the surface into the lower-index side; light from that side meets the
    // outermost first.
    if n_incident <= n_exit {
        layers.reverse();
    }
    stack_reflection(&layers, n_incident, n_exit, wavelength_nm, sin_incidence)
}

/// Reflectance of one interface side at one wavelength, tabulated over sin^2(i) in [0, 1] with `samples`
/// samples (uniform in sin^2, so denser towards grazing incidence, where R changes fastest) and read by
/// linear interpolation. The paraxial ghosts use a coarse table, the ray-traced renderers a dense one.
#[derive(Clone, Debug, PartialEq)]
pub struct ReflectanceTable {
    /// Shared: the ray tracer's jobs hold the tables of their steps ([`Self::samples`]).
    samples: Arc<[f64]>,
}

impl ReflectanceTable {
    /// Tabulates [`reflection`] of `coating` from `n_incident` into `n_exit` at `wavelength_nm`.
    pub fn new(coating: &Coating, n_incident: f64, n_exit: f64, wavelength_nm: f64, samples: usize) -> Self {
        let samples = samples.max(2);
        let samples = (0..samples)
            .map(|k| {
                let sin2_i = k as f64 / (samples - 1) as f64;
                reflection(coating, n_incident, n_exit, wavelength_nm, sin2_i.sqrt()).reflectance
            })
            .collect();
        Self { samples }
    }

    /// The samples, evenly spaced over sin^2 i from 0 to 1 (at least 2).
    pub fn samples(&self) -> &Arc<[f64]> {
        &self.samples
    }

    /// A surface that reflects nothing (the stop, or the same medium on both sides).
    pub fn zero() -> Self {
        Self { samples: Arc::from([0.0, 0.0]) }
    }

    /// Reflectance at `sin2_i` (clamped to [0, 1]).
    pub fn at(&self, sin2_i: f64) -> f64 {
        crate::optics::table_at(&self.samples, sin2_i)
    }
}

/// The reflectance tables of every interface of a lens, per side the light arrives from and per wavelength:
/// what the paraxial ghosts (coarse tables) and the ray-traced renderers (dense tables) both read. A surface
/// that reflects nothing (the stop, or the same medium on both sides) has a zero table, so its transmittance
/// `1 - R` is exactly 1.
#[derive(Clone, Debug, PartialEq)]
pub struct InterfaceTables {
    tables: Vec<ReflectanceTable>,
    wavelengths: usize,
}

impl InterfaceTables {
    /// Tables of `samples` samples for every surface of `lens` at `wavelengths_nm`, each surface wearing
    /// `coating_override` when given, else its own coating.
    pub fn new(lens: &Lens, coating_override: Option<&Coating>, wavelengths_nm: &[f64], samples: usize) -> Self {
        let reflecting = lens.reflecting_surfaces();
        let indices: Vec<Vec<f64>> = wavelengths_nm.iter().map(|&w| lens.media_indices_at(w)).collect();
        let mut tables = Vec::with_capacity(lens.surfaces.len() * 2 * wavelengths_nm.len());
        for (k, surface) in lens.surfaces.iter().enumerate() {
            let coating = coating_override.unwrap_or(&surface.coating);
            for backward in [false, true] {
                for (n, &wavelength_nm) in indices.iter().zip(wavelengths_nm) {
                    let (n_in, n_out) = if backward { (n[k + 1], n[k]) } else { (n[k], n[k + 1]) };
                    tables.push(if reflecting.contains(&k) {
                        ReflectanceTable::new(coating, n_in, n_out, wavelength_nm, samples)
                    } else {
                        ReflectanceTable::zero()
                    });
                }
            }
        }
        Self { tables, wavelengths: wavelengths_nm.len() }
    }

    /// Where the table of `surface`, met travelling backward (towards -z) or not, at wavelength number
    /// `wavelength` is: for [`Self::table`].
    pub fn index(&self, surface: usize, backward: bool, wavelength: usize) -> usize {
        (surface * 2 + usize::from(backward)) * self.wavelengths + wavelength
    }

    pub fn table(&self, index: usize) -> &ReflectanceTable {
        &self.tables[index]
    }
}

/// Characteristic-matrix reflectance of `layers` (in the order the light meets them) between two media.
pub fn stack_reflection(
    layers: &[CoatingLayer],
    n0: f64,
    n_s: f64,
    wavelength_nm: f64,
    sin_incidence: f64,
) -> Reflection {
    let sin0 = sin_incidence.clamp(0.0, 1.0);
    // n sin t is conserved through the stack (Snell).
    let invariant = n0 * sin0;
    let cos_in = |n: f64| -> Complex64 {
        let s = invariant / n;
        (Complex64::new(1.0 - s * s, 0.0)).sqrt()
    };
    let mut total_r = 0.0;
    let mut total_t = 0.0;
    for p_polarised in [false, true] {
        let admittance = |n: f64| -> Complex64 {
            let c = cos_in(n);
            if p_polarised {
                // n / cos t; at grazing incidence cos t -> 0 and the admittance grows without bound:
                // the limit R -> 1 is reached through a tiny cos, never a division by zero.
                Complex64::new(n, 0.0) / if c.norm() < 1e-300 { Complex64::new(1e-300, 0.0) } else { c }
            } else {
                n * c
            }
        };
        let eta0 = admittance(n0);
        let eta_s = admittance(n_s);
        // M = product of the layer matrices; [B, C] = M [1, eta_s].
        let mut m = [
            [Complex64::new(1.0, 0.0), Complex64::new(0.0, 0.0)],
            [Complex64::new(0.0, 0.0), Complex64::new(1.0, 0.0)],
        ];
        for layer in layers {
            let delta =
                2.0 * std::f64::consts::PI * layer.index * layer.thickness_nm * cos_in(layer.index) / wavelength_nm;
            let eta = admittance(layer.index);
            let (c, s) = (delta.cos(), delta.sin());
            let i = Complex64::new(0.0, 1.0);
            let l = [[c, i * s / eta], [i * eta * s, c]];
            m = [
                [m[0][0] * l[0][0] + m[0][1] * l[1][0], m[0][0] * l[0][1] + m[0][1] * l[1][1]],
                [m[1][0] * l[0][0] + m[1][1] * l[1][0], m[1][0] * l[0][1] + m[1][1] * l[1][1]],
            ];
        }
        let b = m[0][0] + m[0][1] * eta_s;
        let c = m[1][0] + m[1][1] * eta_s;
        let denominator = eta0 * b + c;
        let r = (eta0 * b - c) / denominator;
        let reflectance = r.norm_sqr().clamp(0.0, 1.0);
        let transmittance = (4.0 * eta0.re * eta_s.re / denominator.norm_sqr()).clamp(0.0, 1.0);
        total_r += 0.5 * if reflectance.is_finite() { reflectance } else { 1.0 };
        total_t += 0.5 * if transmittance.is_finite() { transmittance } else { 0.0 };
    }
    Reflection { reflectance: total_r, transmittance: total_t }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bare(n0: f64, n1: f64, sin_i: f64) -> f64 {
        reflection(&Coating::Uncoated, n0, n1, 550.0, sin_i).reflectance
    }

    #[test]
    fn bare_glass_matches_the_fresnel_equations() {
        // Normal incidence: ((n1 - n2) / (n1 + n2))^2 = 0.04 for 1.5.
        assert!((bare(1.0, 1.5, 0.0) - 0.04).abs() < 1e-15);
        // Brewster's angle: p reflection vanishes, R = Rs / 2.
        let brewster = 1.5f64.atan();
        let cos_t = (1.0 - (brewster.sin() / 1.5).powi(2)).sqrt();
        let rs = ((brewster.cos() - 1.5 * cos_t) / (brewster.cos() + 1.5 * cos_t)).powi(2);
        assert!((bare(1.0, 1.5, brewster.sin()) - rs / 2.0).abs() < 1e-12);
        // Total internal reflection past the critical angle, and grazing incidence reflects everything.
        assert_eq!(bare(1.5, 1.0, 0.8), 1.0);
        assert!(bare(1.0, 1.5, 1.0) > 0.999_999);
    }

    #[test]
    fn reflectance_plus_transmittance_is_one() {
        let coatings = [
            Coating::Uncoated,
            Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None },
            Coating::Multilayer {
                layers: vec![
                    CoatingLayer { index: 1.38, thickness_nm: 99.6 },
                    CoatingLayer { index: 2.1, thickness_nm: 130.0 },
                    CoatingLayer { index: 1.65, thickness_nm: 83.0 },
                ],
            },
        ];
        for coating in &coatings {
            for (n0, n1) in [(1.0, 1.52), (1.52, 1.0), (1.6, 1.75)] {
                for w in [400.0, 475.0, 550.0, 650.0, 700.0] {
                    for sin_i in [0.0, 0.3, 0.6, 0.65] {
                        let r = reflection(coating, n0, n1, w, sin_i);
                        assert!(
                            (r.reflectance + r.transmittance - 1.0).abs() < 1e-12,
                            "{coating:?} {n0}->{n1} {w} {sin_i}: {r:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn quarter_wave_is_least_reflective_at_its_design_wavelength() {
        let qw = Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None };
        let r = |w: f64| reflection(&qw, 1.0, 1.52, w, 0.0).reflectance;
        // MgF2 on 1.52 glass: ((n0 n2 - n1^2) / (n0 n2 + n1^2))^2 at the design wavelength.
        let expected = ((1.52 - 1.38f64.powi(2)) / (1.52 + 1.38f64.powi(2))).powi(2);
        assert!((r(550.0) - expected).abs() < 1e-12, "{} vs {expected}", r(550.0));
        for w in [420.0, 480.0, 520.0, 580.0, 620.0, 700.0] {
            assert!(r(w) > r(550.0), "{w} nm");
        }
        assert!(r(550.0) < 0.4 * bare(1.0, 1.52, 0.0), "the coating cuts reflection");
        // The ideal index sqrt(n0 n2) cancels reflection exactly.
        let ideal = Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: Some(1.9f64.sqrt()) };
        assert!(reflection(&ideal, 1.0, 1.9, 550.0, 0.0).reflectance < 1e-15);
        // Seen from inside the glass the same layer gives the same normal-incidence reflectance.
        assert!((reflection(&qw, 1.52, 1.0, 550.0, 0.0).reflectance - r(550.0)).abs() < 1e-12);
    }

    #[test]
    fn the_broadband_coating_reflects_under_half_a_percent_across_the_visible() {
        let coating = Coating::broadband();
        for glass in [1.52, 1.62, 1.70] {
            let samples: Vec<f64> =
                (430..=670).map(|w| reflection(&coating, 1.0, glass, f64::from(w), 0.0).reflectance).collect();
            let average = samples.iter().sum::<f64>() / samples.len() as f64;
            assert!(average < 0.005, "n = {glass}: average {:.3}%", average * 100.0);
            let violet = reflection(&coating, 1.0, glass, 400.0, 0.0).reflectance;
            assert!(violet < bare(1.0, glass, 0.0), "n = {glass}: {violet} at 400 nm, more than bare glass");
        }
    }

    #[test]
    fn coatings_tint_differently() {
        let colour = |c: &Coating| [650.0, 510.0, 475.0].map(|w| reflection(c, 1.0, 1.6, w, 0.1).reflectance);
        let bare = colour(&Coating::Uncoated);
        let qw = colour(&Coating::QuarterWave { design_wavelength_nm: 510.0, layer_index: None });
        // Bare glass is nearly grey; the MgF2 quarter wave at 510 nm leaves red and blue above green (purple).
        assert!((bare[0] - bare[2]).abs() < 0.1 * bare[0]);
        assert!(qw[0] > 1.5 * qw[1] && qw[2] > qw[1], "{qw:?}");
    }
}
