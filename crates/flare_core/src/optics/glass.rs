//! Dispersion: the refractive index of each medium as a function of wavelength.
//!
//! # How it works
//! Lens files give each medium's index at the d-line (`n_d`, 587.5618 nm), usually its Abbe number `V_d`,
//! and sometimes a catalogue glass name. From that, [`Dispersion::for_medium`] picks one model:
//! 1. **Air** (`n_d == 1`): constant 1. All indices are relative to air, the lens-design convention.
//! 2. **Catalogue glass** (the name is in [`CATALOGUE`], case-insensitive): the glass's Sellmeier formula
//!    `n^2 - 1 = sum B_i L^2 / (L^2 - C_i)` (L in micrometres, SCHOTT's published coefficients), shifted by
//!    a constant so that it gives the file's `n_d` exactly at the d-line:
//!    `n(L) = n_d + n_sellmeier(L) - n_sellmeier(L_d)`. The shift keeps the file authoritative at the
//!    design wavelength (where the reference figures are computed) and takes only the *shape* of the curve
//!    from the catalogue.
//! 3. **n_d and V_d only**: the two-term Cauchy fit `n(L) = n_d + B (1/L^2 - 1/L_d^2)` whose
//!    `n_F - n_C = (n_d - 1) / V_d` (F = 486.1327 nm, C = 656.2725 nm), the fit of `crates/flare_core/METHOD.md`.
//!    Measured against the catalogue's Sellmeier curves (test `cauchy_model_error_against_sellmeier`):
//!    crowns (V_d > 50) within 4.5e-4 in index over 400-700 nm and 1.2e-4 over 450-650 nm; flints within
//!    7.4e-3 over 400-700 nm (the worst is a dense flint at 400 nm, whose index rises faster in the blue
//!    than 1/L^2) and 1.9e-3 over 450-650 nm. Fringes keep their order and roughly their size; where the
//!    glass is named and catalogued, model 2 is used instead.
//! 4. **n_d alone** (no V_d, unknown glass, as in the pbrt files): the Cauchy fit with an assumed
//!    V_d = [`ASSUMED_ABBE`], a middle-of-the-road glass; reported by [`Dispersion::is_assumed`] so the UI
//!    and `lens info` can say so.
//!
//! At exactly the d-line every model returns `n_d` bit for bit, so d-line results never depend on the model.

/// Helium d-line, the wavelength at which `n_d` is given.
pub const D_LINE_NM: f64 = 587.5618;
/// Hydrogen F-line.
pub const F_LINE_NM: f64 = 486.1327;
/// Hydrogen C-line.
pub const C_LINE_NM: f64 = 656.2725;
/// Abbe number assumed for a glass whose dispersion the file does not give.
pub const ASSUMED_ABBE: f64 = 50.0;

/// One catalogue glass: name, catalogue n_d and V_d, Sellmeier B1..B3 and C1..C3 (C in um^2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CatalogueGlass {
    pub name: &'static str,
    pub n_d: f64,
    pub v_d: f64,
    pub b: [f64; 3],
    pub c_um2: [f64; 3],
}

impl CatalogueGlass {
    /// The catalogue's own Sellmeier index at `wavelength_nm` (unshifted).
    pub fn sellmeier_index(&self, wavelength_nm: f64) -> f64 {
        let l2 = (wavelength_nm * 1e-3).powi(2);
        let mut n2 = 1.0;
        for i in 0..3 {
            n2 += self.b[i] * l2 / (l2 - self.c_um2[i]);
        }
        n2.max(1.0).sqrt()
    }
}

const fn g(name: &'static str, n_d: f64, v_d: f64, b: [f64; 3], c_um2: [f64; 3]) -> CatalogueGlass {
    CatalogueGlass { name, n_d, v_d, b, c_um2 }
}

/// A small built-in catalogue: the SCHOTT glasses lens prescriptions name most often (SCHOTT optical glass
/// data sheets, Sellmeier coefficients as published by SCHOTT).
pub const CATALOGUE: &[CatalogueGlass] = &[
    g("N-BK7", 1.5168, 64.17, [1.03961212, 0.231792344, 1.01046945], [0.00600069867, 0.0200179144, 103.560653]),
    g("N-K5", 1.52249, 59.48, [1.08511833, 0.199562005, 0.930511663], [0.00661099503, 0.024110866, 111.982777]),
    g("N-FK5", 1.48749, 70.41, [0.844309338, 0.344147824, 0.910790213], [0.00475111955, 0.0149814849, 97.8600293]),
    g("N-BAK1", 1.5725, 57.55, [1.12365662, 0.309276848, 0.881511957], [0.00644742752, 0.0222284402, 107.297751]),
    g("N-BAK4", 1.56883, 55.98, [1.28834642, 0.132817724, 0.945395373], [0.00779980626, 0.0315631177, 105.965875]),
    g("N-BAF10", 1.67003, 47.11, [1.5851495, 0.143559385, 1.08521269], [0.00926681282, 0.0424489805, 105.613573]),
    g("N-SK4", 1.61272, 58.63, [1.32993741, 0.228542996, 0.988465211], [0.00716874107, 0.0246455892, 100.886364]),
    g("N-SK16", 1.62041, 60.32, [1.34317774, 0.241144399, 0.994317969], [0.00704687339, 0.0229005, 92.7508526]),
    g("N-SSK2", 1.62229, 53.27, [1.4306027, 0.153150554, 1.01390904], [0.00823982975, 0.0333736841, 106.870822]),
    g("N-LAK7", 1.6516, 58.52, [1.23679889, 0.445051837, 1.01745888], [0.00610105538, 0.0201388334, 90.638038]),
    g("N-LAK9", 1.691, 54.71, [1.46231905, 0.344399589, 1.15508372], [0.00724270156, 0.0243353131, 85.4686868]),
    g("N-LAK14", 1.6968, 55.41, [1.50781212, 0.318866829, 1.14287213], [0.00746098727, 0.0242024834, 80.9565165]),
    g("N-LAF2", 1.74397, 44.85, [1.80984227, 0.15729555, 1.0930037], [0.0101711622, 0.0442431765, 100.687748]),
    g("N-LASF9", 1.85025, 32.17, [2.00029547, 0.298926886, 1.80691843], [0.0121426017, 0.0538736236, 156.530829]),
    g("LLF1", 1.54814, 45.75, [1.21640125, 0.13366454, 0.883399468], [0.00857807248, 0.0420143003, 107.59306]),
    g("LF5", 1.58144, 40.85, [1.28035628, 0.163505973, 0.893930112], [0.00929854416, 0.0449135769, 110.493685]),
    g("F2", 1.62004, 36.37, [1.34533359, 0.209073176, 0.937357162], [0.00997743871, 0.0470450767, 111.886764]),
    g("F5", 1.60342, 38.03, [1.3104463, 0.19603426, 0.96612977], [0.00958633048, 0.0457627627, 115.011883]),
    g("N-F2", 1.62005, 36.43, [1.39757037, 0.159201403, 1.2686543], [0.00995906143, 0.0546931752, 119.248346]),
    g("SF2", 1.64769, 33.85, [1.40301821, 0.231767504, 0.939056586], [0.0105795466, 0.0493226978, 112.405955]),
    g("SF5", 1.6727, 32.21, [1.46141885, 0.247713019, 0.949995832], [0.0111826126, 0.0508594669, 112.041888]),
    g("SF6", 1.80518, 25.43, [1.72448482, 0.390104889, 1.04572858], [0.0134871947, 0.0569318095, 118.557185]),
    g("SF10", 1.72825, 28.41, [1.61625977, 0.259229334, 1.07762317], [0.0127534559, 0.0581983954, 116.60768]),
    g("SF11", 1.78472, 25.76, [1.73848403, 0.311168974, 1.17490871], [0.0136068604, 0.0615960463, 121.922711]),
    g("N-SF2", 1.64769, 33.82, [1.47343127, 0.163681849, 1.36920899], [0.0109019098, 0.0585683687, 127.404933]),
    g("N-SF5", 1.67271, 32.25, [1.52481889, 0.187085527, 1.42729015], [0.011254756, 0.0588995392, 129.141675]),
    g("N-SF6", 1.80518, 25.36, [1.77931763, 0.338149866, 2.08734474], [0.0133714182, 0.0617533621, 174.01759]),
    g("N-SF11", 1.78472, 25.68, [1.73759695, 0.313747346, 1.89878101], [0.013188707, 0.0623068142, 155.23629]),
];

/// Normalises a glass name for look-up: upper case, `_` and spaces read as `-`.
fn normalise(name: &str) -> String {
    name.trim().to_ascii_uppercase().replace(['_', ' '], "-")
}

/// Finds a catalogue glass by name (case-insensitive; `N_BK7` and `n-bk7` both find N-BK7).
pub fn find_glass(name: &str) -> Option<&'static CatalogueGlass> {
    let key = normalise(name);
    CATALOGUE.iter().find(|g| normalise(g.name) == key)
}

/// How a medium's index varies with wavelength. Every variant returns exactly `n_d` at the d-line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dispersion {
    /// Air: index 1 at every wavelength.
    Air,
    /// A catalogue glass's Sellmeier curve, shifted to pass through the file's `n_d`.
    Sellmeier { n_d: f64, glass: &'static CatalogueGlass },
    /// Two-term Cauchy fit through `n_d` and `V_d`; `assumed` when `V_d` was not given.
    Cauchy { n_d: f64, v_d: f64, assumed: bool },
}

impl Dispersion {
    /// The model for a medium of index `n_d` (exactly 1: air), Abbe number `v_d` and catalogue name `glass`
    /// as a file gives them ([`super::lens::Medium::dispersion`] calls this).
    pub fn for_medium(n_d: f64, v_d: Option<f64>, glass: Option<&str>) -> Self {
        if n_d == 1.0 {
            return Self::Air;
        }
        if let Some(glass) = glass.and_then(find_glass) {
            return Self::Sellmeier { n_d, glass };
        }
        match v_d {
            Some(v_d) => Self::Cauchy { n_d, v_d, assumed: false },
            None => Self::Cauchy { n_d, v_d: ASSUMED_ABBE, assumed: true },
        }
    }

    /// True when the dispersion had to be guessed (no V_d and no known glass).
    pub fn is_assumed(&self) -> bool {
        matches!(self, Self::Cauchy { assumed: true, .. })
    }

    /// Refractive index at `wavelength_nm` (meaningful over about 350-1000 nm).
    pub fn index_at(&self, wavelength_nm: f64) -> f64 {
        match *self {
            Self::Air => 1.0,
            Self::Sellmeier { n_d, glass } => {
                if wavelength_nm == D_LINE_NM {
                    return n_d;
                }
                n_d + glass.sellmeier_index(wavelength_nm) - glass.sellmeier_index(D_LINE_NM)
            }
            Self::Cauchy { n_d, v_d, .. } => {
                let b = cauchy_b_nm2(n_d, v_d);
                n_d + b * (1.0 / (wavelength_nm * wavelength_nm) - 1.0 / (D_LINE_NM * D_LINE_NM))
            }
        }
    }

    /// Short words for reports: "air", "Sellmeier F5", "Cauchy (V_d 58.5)", "Cauchy (V_d assumed 50)".
    pub fn describe(&self) -> String {
        match self {
            Self::Air => "air".to_owned(),
            Self::Sellmeier { glass, .. } => format!("Sellmeier {}", glass.name),
            Self::Cauchy { v_d, assumed: false, .. } => format!("Cauchy (V_d {v_d})"),
            Self::Cauchy { v_d, assumed: true, .. } => format!("Cauchy (V_d assumed {v_d})"),
        }
    }
}

/// The Cauchy coefficient B (nm^2) for which n_F - n_C = (n_d - 1) / V_d.
fn cauchy_b_nm2(n_d: f64, v_d: f64) -> f64 {
    let dn = (n_d - 1.0) / v_d;
    dn / (1.0 / (F_LINE_NM * F_LINE_NM) - 1.0 / (C_LINE_NM * C_LINE_NM))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::optics::lens::Medium;

    fn medium(n_d: f64, v_d: Option<f64>, glass: Option<&str>) -> Medium {
        Medium { n_d, v_d, glass: glass.map(str::to_owned) }
    }

    #[test]
    fn catalogue_transcription_reproduces_catalogue_nd_and_vd() {
        for g in CATALOGUE {
            let nd = g.sellmeier_index(D_LINE_NM);
            let vd = (nd - 1.0) / (g.sellmeier_index(F_LINE_NM) - g.sellmeier_index(C_LINE_NM));
            assert!((nd - g.n_d).abs() < 2e-5, "{}: n_d {nd} vs catalogue {}", g.name, g.n_d);
            assert!((vd - g.v_d).abs() < 0.05, "{}: V_d {vd} vs catalogue {}", g.name, g.v_d);
        }
    }

    #[test]
    fn every_model_gives_nd_exactly_at_the_d_line() {
        for m in [
            medium(1.0, None, Some("air")),
            medium(1.603, Some(38.0), Some("F5")),
            medium(1.652, Some(58.5), Some("LAKN7")),
            medium(1.67, None, None),
        ] {
            assert_eq!(m.index_at(D_LINE_NM), m.n_d, "{m:?}");
        }
    }

    #[test]
    fn cauchy_model_reproduces_the_abbe_number() {
        let d = medium(1.652, Some(58.5), None).dispersion();
        let vd = (d.index_at(D_LINE_NM) - 1.0) / (d.index_at(F_LINE_NM) - d.index_at(C_LINE_NM));
        assert!((vd - 58.5).abs() < 1e-9, "{vd}");
        assert!(d.index_at(450.0) > d.index_at(650.0), "normal dispersion: blue bends more");
    }

    /// The error bounds quoted in the module documentation.
    #[test]
    fn cauchy_model_error_against_sellmeier() {
        let worst = |range: std::ops::RangeInclusive<u32>, crowns: bool| {
            let mut worst = 0.0_f64;
            for g in CATALOGUE.iter().filter(|g| (g.v_d > 50.0) == crowns) {
                let cauchy = Dispersion::Cauchy { n_d: g.n_d, v_d: g.v_d, assumed: false };
                let shift = g.n_d - g.sellmeier_index(D_LINE_NM);
                for w in range.clone().step_by(10) {
                    let w = w as f64;
                    worst = worst.max((cauchy.index_at(w) - (g.sellmeier_index(w) + shift)).abs());
                }
            }
            worst
        };
        let (crown_wide, crown_narrow) = (worst(400..=700, true), worst(450..=650, true));
        let (flint_wide, flint_narrow) = (worst(400..=700, false), worst(450..=650, false));
        assert!(crown_wide < 4.5e-4 && crown_narrow < 1.2e-4, "crowns {crown_wide} {crown_narrow}");
        assert!(flint_wide < 7.4e-3 && flint_narrow < 1.9e-3, "flints {flint_wide} {flint_narrow}");
        assert!(crown_narrow > 1e-5, "the test compares two different models");
    }

    #[test]
    fn glass_lookup_is_forgiving_about_case_and_separators() {
        assert_eq!(find_glass("n_bk7").map(|g| g.name), Some("N-BK7"));
        assert_eq!(find_glass(" f5 ").map(|g| g.name), Some("F5"));
        assert!(find_glass("UNOBTAINIUM").is_none());
        assert!(medium(1.6, None, None).dispersion().is_assumed());
        assert!(!medium(1.6, None, Some("F5")).dispersion().is_assumed());
    }
}
