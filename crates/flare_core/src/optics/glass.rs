//! Dispersion: the refractive index of each medium as a function of wavelength.
//!
//! # How it works
//! Lens files give each medium's index at the d-line (`n_d`, 587.5618 nm), usually its Abbe number `V_d`,
//! and sometimes a catalogue glass name. From that, [`Dispersion::for_medium`] picks one model:
//! 1. **Air** (`n_d == 1`): constant 1. All indices are relative to air, the lens-design convention.
//! 2. **Catalogue glass** (the name is a known glass, case-insensitive, see [`find_glass`]): the glass's
//!    dispersion formula from its AGF catalogue ([`super::agf`]: the 154 built-in SCHOTT glasses of
//!    [`BUILTIN_CATALOGUES`], plus any catalogue added with [`add_catalogue`], e.g. `--catalog`), shifted
//!    by a constant so that it gives the file's `n_d` exactly at the d-line:
//!    `n(L) = n_d + n_formula(L) - n_formula(L_d)`. The shift keeps the file authoritative at the
//!    design wavelength (where the reference figures are computed) and takes only the *shape* of the curve
//!    from the catalogue.
//! 3. **n_d and V_d only**: the two-term Cauchy fit `n(L) = n_d + B (1/L^2 - 1/L_d^2)` whose
//!    `n_F - n_C = (n_d - 1) / V_d` (F = 486.1327 nm, C = 656.2725 nm), the fit of `crates/flare_core/METHOD.md`.
//!    Measured against the 154 built-in SCHOTT Sellmeier curves (test `cauchy_model_error_against_sellmeier`):
//!    crowns (V_d > 50) within 6.9e-4 in index over 400-700 nm and 1.3e-4 over 450-650 nm; flints within
//!    1.5e-2 over 400-700 nm (the worst is a dense flint, n_d near 2, at 400 nm, whose index rises faster in
//!    the blue than 1/L^2) and 3.7e-3 over 450-650 nm. Fringes keep their order and roughly their size; where the
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

pub use super::agf::CatalogueGlass;

/// The formula's n_d and V_d = (n_d - 1) / (n_F - n_C) of a catalogue glass, to check against its published
/// ones; `None` where the formula gives no index at those lines.
pub fn computed_nd_vd(glass: &CatalogueGlass) -> Option<(f64, f64)> {
    let (d, f, c) = (glass.formula_index(D_LINE_NM)?, glass.formula_index(F_LINE_NM)?, glass.formula_index(C_LINE_NM)?);
    Some((d, (d - 1.0) / (f - c)))
}

/// The catalogues embedded in the binary, as AGF files: (catalogue name, text).
pub const BUILTIN_CATALOGUES: &[(&str, &str)] =
    &[("SCHOTT", include_str!("../../../../assets/glass/flarelab-schott.agf"))];

/// Every glass FlareLab knows: the built-in catalogues, then those added with [`add_catalogue`]. Glasses live
/// for the whole process (a dispersion model refers to its glass), so added ones are leaked once each.
fn registry() -> &'static std::sync::RwLock<Vec<&'static CatalogueGlass>> {
    static REGISTRY: std::sync::OnceLock<std::sync::RwLock<Vec<&'static CatalogueGlass>>> = std::sync::OnceLock::new();
    REGISTRY.get_or_init(|| {
        let mut glasses = Vec::new();
        for (name, text) in BUILTIN_CATALOGUES {
            // The embedded files are checked by a test; a broken one would leave its glasses out, not crash.
            if let Ok(list) = super::agf::parse_agf(text, name) {
                glasses.extend(list.into_iter().map(|g| &*Box::leak(Box::new(g))));
            }
        }
        std::sync::RwLock::new(glasses)
    })
}

/// Every known glass (built-in first, then added catalogues in the order they were added).
pub fn catalogue_glasses() -> Vec<&'static CatalogueGlass> {
    registry().read().map(|r| r.clone()).unwrap_or_default()
}

/// Adds the glasses of an AGF text (catalogue `name`) to the ones found by name; a glass whose name is already
/// known from another catalogue is kept too, and found by `CATALOGUE:NAME`. Returns how many were added.
pub fn add_catalogue(text: &str, name: &str) -> Result<usize, super::agf::AgfError> {
    let list = super::agf::parse_agf(text, name)?;
    let count = list.len();
    if let Ok(mut r) = registry().write() {
        let known: std::collections::HashSet<(String, String)> =
            r.iter().map(|g| (g.catalogue.clone(), normalise(&g.name))).collect();
        for g in list {
            if !known.contains(&(g.catalogue.clone(), normalise(&g.name))) {
                r.push(Box::leak(Box::new(g)));
            }
        }
    }
    Ok(count)
}

/// Normalises a glass name for look-up: upper case, `_` and spaces read as `-`.
fn normalise(name: &str) -> String {
    name.trim().to_ascii_uppercase().replace(['_', ' '], "-")
}

/// Finds a catalogue glass by name (case-insensitive; `N_BK7` and `n-bk7` both find N-BK7), or by
/// `CATALOGUE:NAME` (`OHARA:S-BSL7`) when two catalogues share a name; the first catalogue wins otherwise.
pub fn find_glass(name: &str) -> Option<&'static CatalogueGlass> {
    let (catalogue, glass) = match name.split_once(':') {
        Some((c, g)) => (Some(c.trim().to_ascii_uppercase()), g),
        None => (None, name),
    };
    let key = normalise(glass);
    let r = registry().read().ok()?;
    r.iter().copied().find(|g| normalise(&g.name) == key && catalogue.as_ref().is_none_or(|c| *c == g.catalogue))
}

/// How a medium's index varies with wavelength. Every variant returns exactly `n_d` at the d-line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dispersion {
    /// Air: index 1 at every wavelength.
    Air,
    /// A catalogue glass's dispersion formula, shifted to pass through the file's `n_d`.
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
                match (glass.formula_index(wavelength_nm), glass.formula_index(D_LINE_NM)) {
                    (Some(n), Some(at_d)) => n_d + n - at_d,
                    // Outside where the formula gives an index: the glass's own n_d and V_d (Cauchy).
                    _ => Self::Cauchy { n_d, v_d: glass.v_d, assumed: false }.index_at(wavelength_nm),
                }
            }
            Self::Cauchy { n_d, v_d, .. } => {
                let b = cauchy_b_nm2(n_d, v_d);
                n_d + b * (1.0 / (wavelength_nm * wavelength_nm) - 1.0 / (D_LINE_NM * D_LINE_NM))
            }
        }
    }

    /// Short words for reports: "air", "SCHOTT F5 (AGF formula 2)", "Cauchy (V_d 58.5)", "Cauchy (V_d assumed 50)".
    pub fn describe(&self) -> String {
        match self {
            Self::Air => "air".to_owned(),
            Self::Sellmeier { glass, .. } => {
                format!("{} {} (AGF formula {})", glass.catalogue, glass.name, glass.formula)
            }
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

    /// Every catalogue glass gives its published n_d to 1e-5 and V_d to its published precision (two
    /// decimals: 0.005) plus 1e-5.
    #[test]
    fn every_catalogue_glass_gives_its_published_nd_and_vd() {
        let glasses = catalogue_glasses();
        assert!(glasses.len() >= 28);
        for g in glasses {
            let (nd, vd) = computed_nd_vd(g).unwrap();
            assert!((nd - g.n_d).abs() < 1e-5, "{} {}: n_d {nd} vs published {}", g.catalogue, g.name, g.n_d);
            assert!((vd - g.v_d).abs() < 0.005 + 1e-5, "{} {}: V_d {vd} vs published {}", g.catalogue, g.name, g.v_d);
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
            for g in catalogue_glasses().into_iter().filter(|g| g.catalogue == "SCHOTT" && (g.v_d > 50.0) == crowns) {
                let cauchy = Dispersion::Cauchy { n_d: g.n_d, v_d: g.v_d, assumed: false };
                let shift = g.n_d - g.formula_index(D_LINE_NM).unwrap();
                for w in range.clone().step_by(10) {
                    let w = w as f64;
                    worst = worst.max((cauchy.index_at(w) - (g.formula_index(w).unwrap() + shift)).abs());
                }
            }
            worst
        };
        let (crown_wide, crown_narrow) = (worst(400..=700, true), worst(450..=650, true));
        let (flint_wide, flint_narrow) = (worst(400..=700, false), worst(450..=650, false));
        assert!(crown_wide < 6.9e-4 && crown_narrow < 1.3e-4, "crowns {crown_wide} {crown_narrow}");
        assert!(flint_wide < 1.5e-2 && flint_narrow < 3.7e-3, "flints {flint_wide} {flint_narrow}");
        assert!(crown_narrow > 1e-5, "the test compares two different models");
    }

    #[test]
    fn glass_lookup_is_forgiving_about_case_and_separators() {
        assert_eq!(find_glass("n_bk7").map(|g| g.name.as_str()), Some("N-BK7"));
        assert_eq!(find_glass(" f5 ").map(|g| g.name.as_str()), Some("F5"));
        assert_eq!(find_glass("schott:f5").map(|g| g.name.as_str()), Some("F5"));
        assert!(find_glass("OHARA:F5").is_none());
        assert!(find_glass("UNOBTAINIUM").is_none());
        assert!(medium(1.6, None, None).dispersion().is_assumed());
        assert!(!medium(1.6, None, Some("F5")).dispersion().is_assumed());
    }
}
