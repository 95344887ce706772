//! The lens model: an ordered list of optical interfaces, and its validation.
//!
//! # How it works
//! A [`Lens`] is what lens designers write in a prescription table: one [`Surface`] per interface, listed
//! from the object side. Each surface carries its signed radius, the axial thickness to the next surface,
//! the [`Medium`] *behind* it, its clear semi-aperture, whether it is the aperture stop, and the
//! anti-reflection [`Coating`] that later sets its ghost reflectance. [`Lens::validate`] refuses anything
//! that is not a physical lens, naming the surface and the field, so that every later module (tracer,
//! paraxial matrices, ghosts) can assume a well-formed lens and never meets NaN from the input.
//!
//! # The sign convention (the one and only place it is written down)
//! - The optical axis is z; light from the object travels towards +z; the first surface's vertex is at
//!   z = 0 and each later vertex sits `thickness_mm` behind the previous one.
//! - `radius_mm > 0`: the centre of curvature lies on the image side (+z) of the vertex; `radius_mm < 0`:
//!   on the object side; `radius_mm == 0`: the surface is flat (infinite radius).
//! - Curvature `c = 1 / radius_mm` (0 for flat). The sag of a sphere at height h is
//!   `z - z_vertex = c h^2 / (1 + sqrt(1 - c^2 h^2))`.
//! - The medium of a surface is the one *after* it (on its +z side); the object space before surface 0 is
//!   air, and so is the image space after the last surface (the sensor sits in air).
//! - Heights x, y are measured from the axis, y in the meridional (y-z) plane; angles in radians unless a
//!   name ends in `_deg`; lengths in millimetres (`_mm`); wavelengths in nanometres (`_nm`).
//! - Surfaces are numbered from 0 in file order, in the API, the command line and every report.

use serde::{Deserialize, Serialize};

use super::glass::{D_LINE_NM, Dispersion};

/// Largest number of surfaces a lens may have (a 60-surface zoom is large; 1000 is absurd).
pub const MAX_SURFACES: usize = 1000;
/// Thicknesses beyond this are refused as absurd (one kilometre).
pub const MAX_THICKNESS_MM: f64 = 1.0e6;
/// Semi-apertures beyond this are refused as absurd (ten metres).
pub const MAX_SEMI_APERTURE_MM: f64 = 1.0e4;
/// Refractive indices above this are refused as absurd for visible light.
pub const MAX_INDEX: f64 = 4.0;
/// Abbe numbers outside (0, this] are refused (real glasses lie between about 17 and 100).
pub const MAX_ABBE: f64 = 200.0;
/// Surfaces may touch but not cross: an edge gap below minus this is refused.
pub const EDGE_OVERLAP_TOLERANCE_MM: f64 = 1.0e-6;

/// The optical material behind a surface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    /// Refractive index at the helium d-line (587.5618 nm).
    #[serde(rename = "nd")]
    pub n_d: f64,
    /// Abbe number V_d = (n_d - 1) / (n_F - n_C); `None` for air or where the source gives none.
    #[serde(rename = "vd", default)]
    pub v_d: Option<f64>,
    /// Catalogue name where the source gives one (`"air"` for air).
    #[serde(default)]
    pub glass: Option<String>,
}

impl Medium {
    /// Air at the d-line, the medium of object and image space (index 1 by the usual lens-design
    /// convention: all indices are relative to air).
    pub fn air() -> Self {
        Self { n_d: 1.0, v_d: None, glass: Some("air".to_owned()) }
    }

    /// True when this medium is air (index exactly 1): it does not disperse.
    pub fn is_air(&self) -> bool {
        self.n_d == 1.0
    }

    /// Whether light crossing from `self` into `other` meets an optical interface (and so reflects).
    pub fn differs_from(&self, other: &Medium) -> bool {
        self.n_d != other.n_d || (self.v_d != other.v_d && !(self.is_air() && other.is_air()))
    }

    /// The dispersion model for this medium (see [`crate::optics::glass`]).
    pub fn dispersion(&self) -> Dispersion {
        Dispersion::for_medium(self.n_d, self.v_d, self.glass.as_deref())
    }

    /// Refractive index at `wavelength_nm`; exactly `n_d` at the d-line.
    pub fn index_at(&self, wavelength_nm: f64) -> f64 {
        self.dispersion().index_at(wavelength_nm)
    }
}

/// One layer of a thin-film stack, from the surface outwards.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoatingLayer {
    /// Refractive index of the layer material (taken as non-dispersive).
    pub index: f64,
    /// Physical thickness of the layer.
    pub thickness_nm: f64,
}

/// The anti-reflection coating of a surface, which sets how bright (and how tinted) its ghosts are.
/// The reflectance physics lives with the ghost renderer; the lens only stores the settings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Coating {
    /// Bare glass: Fresnel reflection only.
    #[default]
    Uncoated,
    /// One quarter-wave layer (Hullin 2011): index `max(sqrt(n0 n2), 1.38)` unless given, thickness
    /// `design_wavelength_nm / (4 n1)`.
    QuarterWave {
        design_wavelength_nm: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        layer_index: Option<f64>,
    },
    /// A general stack of layers, listed from the surface outwards.
    Multilayer { layers: Vec<CoatingLayer> },
}

impl Coating {
    /// A broadband anti-reflection coating: the quarter-half-quarter design (Lockhart and King 1947; H. A.
    /// Macleod, *Thin-Film Optical Filters*, 4th ed., section 4.3) at a design wavelength of 520 nm, from the
    /// glass outwards: a quarter wave of index 1.70 (Al2O3 class, 76.5 nm), a half wave of index 2.15 (ZrO2,
    /// 120.9 nm), a quarter wave of MgF2 (1.38, 94.2 nm). At normal incidence from air its reflectance
    /// averages 0.12% from 430 to 670 nm on n = 1.52 glass and 0.21% on n = 1.70 (a test checks under 0.5%),
    /// with at most 1.5% at 400 nm against bare crown's 4.3%.
    pub fn broadband() -> Self {
        let design_nm = 520.0;
        let layer =
            |index: f64, quarters: f64| CoatingLayer { index, thickness_nm: quarters * design_nm / (4.0 * index) };
        Coating::Multilayer { layers: vec![layer(1.70, 1.0), layer(2.15, 2.0), layer(1.38, 1.0)] }
    }
}

/// One optical interface of a lens.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Surface {
    /// Signed radius of curvature; 0 (or `null` in files) means flat. See the sign convention above.
    #[serde(rename = "radius", deserialize_with = "radius_or_flat")]
    pub radius_mm: f64,
    /// Axial distance to the next vertex. On the last surface, the source's distance to the image plane,
    /// which may be absent: FlareLab puts the sensor at the paraxial focus whatever it says.
    #[serde(rename = "thickness")]
    pub thickness_mm: Option<f64>,
    /// The medium after this surface.
    #[serde(flatten)]
    pub medium: Medium,
    /// Clear semi-aperture (half the clear diameter).
    #[serde(rename = "semi_aperture")]
    pub semi_aperture_mm: f64,
    /// True on the aperture stop (a flat surface with the same medium on both sides).
    #[serde(default)]
    pub stop: bool,
    /// Anti-reflection coating of this interface.
    #[serde(default, skip_serializing_if = "is_uncoated")]
    pub coating: Coating,
    /// Any other keys the file gave for this surface, kept verbatim and written back.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

fn is_uncoated(c: &Coating) -> bool {
    *c == Coating::Uncoated
}

fn radius_or_flat<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(0.0))
}

impl Surface {
    /// An uncoated surface that is not the stop.
    pub fn new(radius_mm: f64, thickness_mm: Option<f64>, medium: Medium, semi_aperture_mm: f64) -> Self {
        Self {
            radius_mm,
            thickness_mm,
            medium,
            semi_aperture_mm,
            stop: false,
            coating: Coating::Uncoated,
            extra: Default::default(),
        }
    }

    /// Curvature 1/R in 1/mm; 0 for a flat surface.
    pub fn curvature_per_mm(&self) -> f64 {
        if self.radius_mm == 0.0 { 0.0 } else { 1.0 / self.radius_mm }
    }

    pub fn is_flat(&self) -> bool {
        self.radius_mm == 0.0
    }

    /// Sag (z offset from the vertex) of this surface at height `h_mm`, or `None` beyond the sphere.
    pub fn sag_mm(&self, h_mm: f64) -> Option<f64> {
        let c = self.curvature_per_mm();
        let root = 1.0 - c * c * h_mm * h_mm;
        (root >= 0.0).then(|| c * h_mm * h_mm / (1.0 + root.sqrt()))
    }
}

/// A lens prescription. Unknown top-level keys of a JSON file are kept in `extra` and written back.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lens {
    #[serde(default)]
    pub id: String,
    #[serde(default)]
    pub name: String,
    pub surfaces: Vec<Surface>,
    /// Everything else the file said (sources, notes, published data), kept verbatim.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// Why a lens is not a physical lens. Every variant names the surface (numbered from 0) and the field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LensError {
    #[error("the lens has no surfaces")]
    NoSurfaces,
    #[error("the lens has {count} surfaces; at most {MAX_SURFACES} are supported")]
    TooManySurfaces { count: usize },
    #[error("the lens has no aperture stop (mark one flat air surface with \"stop\": true)")]
    NoStop,
    #[error("the lens has {count} aperture stops (surfaces {surfaces:?}); exactly one is needed")]
    SeveralStops { count: usize, surfaces: Vec<usize> },
    #[error("surface {surface}, field `{field}`: {reason}")]
    Field { surface: usize, field: &'static str, reason: String },
    #[error("lens field `{field}`: {reason}")]
    LensField { field: &'static str, reason: String },
}

impl LensError {
    fn field(surface: usize, field: &'static str, reason: impl Into<String>) -> Self {
        Self::Field { surface, field, reason: reason.into() }
    }
}

impl Lens {
    /// Number of interfaces, the stop included.
    pub fn number_of_surfaces(&self) -> usize {
        self.surfaces.len()
    }

    /// Index of the aperture stop. Valid lenses have exactly one.
    pub fn stop_index(&self) -> usize {
        self.surfaces.iter().position(|s| s.stop).unwrap_or(0)
    }

    /// z of each surface vertex, the first at 0.
    pub fn vertex_z_mm(&self) -> Vec<f64> {
        let mut z = 0.0;
        self.surfaces
            .iter()
            .map(|s| {
                let here = z;
                z += s.thickness_mm.unwrap_or(0.0);
                here
            })
            .collect()
    }

    /// The medium in front of surface `k` (object-space air for k = 0).
    pub fn medium_before(&self, k: usize) -> Medium {
        if k == 0 { Medium::air() } else { self.surfaces[k - 1].medium.clone() }
    }

    /// Refractive index of every medium slot at `wavelength_nm`: slot 0 is object-space air, slot k + 1 the
    /// medium after surface k (the numbering [`crate::optics::path::Step`] uses).
    pub fn media_indices_at(&self, wavelength_nm: f64) -> Vec<f64> {
        std::iter::once(1.0).chain(self.surfaces.iter().map(|s| s.medium.index_at(wavelength_nm))).collect()
    }

    /// Surfaces that reflect: the media on their two sides differ. The stop never counts.
    pub fn reflecting_surfaces(&self) -> Vec<usize> {
        (0..self.surfaces.len())
            .filter(|&k| !self.surfaces[k].stop && self.medium_before(k).differs_from(&self.surfaces[k].medium))
            .collect()
    }

    /// Every two-reflection ghost (i, j), i < j: the light reflects at j, then at i.
    pub fn ghost_pairs(&self) -> Vec<(usize, usize)> {
        let r = self.reflecting_surfaces();
        let mut pairs = Vec::with_capacity(r.len() * r.len().saturating_sub(1) / 2);
        for (a, &i) in r.iter().enumerate() {
            for &j in &r[a + 1..] {
                pairs.push((i, j));
            }
        }
        pairs
    }

    /// Checks that this is a lens light can go through; the first problem found is returned.
    pub fn validate(&self) -> Result<(), LensError> {
        let n = self.surfaces.len();
        if n == 0 {
            return Err(LensError::NoSurfaces);
        }
        if n > MAX_SURFACES {
            return Err(LensError::TooManySurfaces { count: n });
        }
        self.validate_extras()?;
        for (k, s) in self.surfaces.iter().enumerate() {
            validate_surface(k, s, k + 1 == n)?;
        }
        let stops: Vec<usize> = (0..n).filter(|&k| self.surfaces[k].stop).collect();
        match stops.len() {
            0 => return Err(LensError::NoStop),
            1 => {}
            count => return Err(LensError::SeveralStops { count, surfaces: stops }),
        }
        let s = stops[0];
        if !self.surfaces[s].is_flat() {
            return Err(LensError::field(s, "radius", "the aperture stop must be flat (radius 0)"));
        }
        if self.medium_before(s).differs_from(&self.surfaces[s].medium) {
            return Err(LensError::field(
                s,
                "nd",
                "the aperture stop must have the same medium on both sides (it is not a refracting surface)",
            ));
        }
        let last = &self.surfaces[n - 1].medium;
        if !last.is_air() {
            return Err(LensError::field(n - 1, "nd", "the image space after the last surface must be air (nd = 1)"));
        }
        self.validate_edges()
    }

    fn validate_extras(&self) -> Result<(), LensError> {
        if let Some(v) = self.extra.get("units")
            && v.as_str() != Some("mm")
        {
            return Err(LensError::LensField { field: "units", reason: format!("{v} is not supported; use \"mm\"") });
        }
        if let Some(v) = self.extra.get("object_index")
            && v.as_f64() != Some(1.0)
        {
            return Err(LensError::LensField {
                field: "object_index",
                reason: format!("{v}: the object space must be air (1.0)"),
            });
        }
        if let Some(v) = self.extra.get("wavelength_nm") {
            match v.as_f64() {
                Some(w) if (w - D_LINE_NM).abs() < 1e-6 => {}
                _ => {
                    return Err(LensError::LensField {
                        field: "wavelength_nm",
                        reason: format!("{v}: indices must be given at the d-line, {D_LINE_NM} nm"),
                    });
                }
            }
        }
        Ok(())
    }

    /// Consecutive surfaces must not cross inside their common clear aperture.
    fn validate_edges(&self) -> Result<(), LensError> {
        for k in 0..self.surfaces.len().saturating_sub(1) {
            let (a, b) = (&self.surfaces[k], &self.surfaces[k + 1]);
            let h = a.semi_aperture_mm.min(b.semi_aperture_mm);
            let t = a.thickness_mm.unwrap_or(0.0);
            let (Some(sag_a), Some(sag_b)) = (a.sag_mm(h), b.sag_mm(h)) else { continue };
            let edge_gap = t + sag_b - sag_a;
            if edge_gap < -EDGE_OVERLAP_TOLERANCE_MM {
                return Err(LensError::field(
                    k,
                    "thickness",
                    format!(
                        "surfaces {k} and {} cross each other inside the clear aperture \
                         (gap {edge_gap:.4} mm at height {h} mm)",
                        k + 1
                    ),
                ));
            }
        }
        Ok(())
    }
}

fn finite(k: usize, field: &'static str, v: f64) -> Result<f64, LensError> {
    if v.is_finite() { Ok(v) } else { Err(LensError::field(k, field, format!("{v} is not a finite number"))) }
}

fn validate_surface(k: usize, s: &Surface, is_last: bool) -> Result<(), LensError> {
    let r = finite(k, "radius", s.radius_mm)?;
    match s.thickness_mm {
        Some(t) => {
            let t = finite(k, "thickness", t)?;
            if t < 0.0 {
                return Err(LensError::field(k, "thickness", format!("{t} is negative")));
            }
            if t > MAX_THICKNESS_MM {
                return Err(LensError::field(k, "thickness", format!("{t} mm is absurdly large")));
            }
        }
        None if !is_last => {
            return Err(LensError::field(k, "thickness", "missing (only the last surface may leave it out)"));
        }
        None => {}
    }
    let n = finite(k, "nd", s.medium.n_d)?;
    if n < 1.0 {
        return Err(LensError::field(k, "nd", format!("{n} is below 1 (no optical glass is less dense than vacuum)")));
    }
    if n > MAX_INDEX {
        return Err(LensError::field(k, "nd", format!("{n} is absurdly large for visible light")));
    }
    if let Some(v) = s.medium.v_d {
        let v = finite(k, "vd", v)?;
        if !(v > 0.0 && v <= MAX_ABBE) {
            return Err(LensError::field(k, "vd", format!("{v} is outside (0, {MAX_ABBE}]")));
        }
    }
    let h = finite(k, "semi_aperture", s.semi_aperture_mm)?;
    if h <= 0.0 {
        return Err(LensError::field(k, "semi_aperture", format!("{h} must be positive")));
    }
    if h > MAX_SEMI_APERTURE_MM {
        return Err(LensError::field(k, "semi_aperture", format!("{h} mm is absurdly large")));
    }
    if r != 0.0 && r.abs() < h {
        return Err(LensError::field(
            k,
            "radius",
            format!("|{r}| mm is smaller than the semi-aperture {h} mm: no sphere is that wide"),
        ));
    }
    validate_coating(k, &s.coating)
}

fn validate_coating(k: usize, c: &Coating) -> Result<(), LensError> {
    match c {
        Coating::Uncoated => Ok(()),
        Coating::QuarterWave { design_wavelength_nm, layer_index } => {
            let w = finite(k, "coating.design_wavelength_nm", *design_wavelength_nm)?;
            if !(100.0..=3000.0).contains(&w) {
                return Err(LensError::field(
                    k,
                    "coating.design_wavelength_nm",
                    format!("{w} nm is not an optical wavelength"),
                ));
            }
            if let Some(n) = layer_index {
                let n = finite(k, "coating.layer_index", *n)?;
                if !(1.0..=MAX_INDEX).contains(&n) {
                    return Err(LensError::field(k, "coating.layer_index", format!("{n} is outside [1, {MAX_INDEX}]")));
                }
            }
            Ok(())
        }
        Coating::Multilayer { layers } => {
            if layers.len() > 200 {
                return Err(LensError::field(k, "coating.layers", format!("{} layers is absurd", layers.len())));
            }
            for l in layers {
                let n = finite(k, "coating.layers.index", l.index)?;
                let t = finite(k, "coating.layers.thickness_nm", l.thickness_nm)?;
                if !(1.0..=MAX_INDEX).contains(&n) {
                    return Err(LensError::field(
                        k,
                        "coating.layers.index",
                        format!("{n} is outside [1, {MAX_INDEX}]"),
                    ));
                }
                if !(0.0..=1.0e5).contains(&t) {
                    return Err(LensError::field(
                        k,
                        "coating.layers.thickness_nm",
                        format!("{t} nm is outside [0, 100000]"),
                    ));
                }
            }
            Ok(())
        }
    }
}
