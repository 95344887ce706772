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
//! - Curvature `c = 1 / radius_mm` (0 for flat). The sag of a surface at height h is the even asphere
//!   `z - z_vertex = c h^2 / (1 + sqrt(1 - (1 + k) c^2 h^2)) + A2 h^2 + A4 h^4 + A6 h^6 + ...` with conic
//!   constant `k` (`conic`, 0 for a sphere, -1 a paraboloid), the r^2 term `A2` (`aspheric_r2`, Zemax's
//!   `PARM 1`) and the even terms `A4, A6, ...` (`aspheric`, from r^4 up). The sag is defined where the
//!   square root is real; [`Surface::sag_limit_mm`] says how far, and validation refuses a clear aperture
//!   beyond it. Paraxial optics sees the vertex curvature `c + 2 A2` ([`Surface::vertex_curvature_per_mm`]).
//! - An anamorphic (toroidal) surface, Zemax's `TOROIDAL`, is the curve above drawn in the y-z section
//!   (`radius_mm`, `conic`, the aspheric terms: its sag `z_y(y)`) and swept about an axis parallel to y that
//!   crosses the optical axis at `radius_x_mm` from the vertex (the radius of the x-z section):
//!   `z(x, y) = z_y + c_x x^2 / (w + sqrt(w^2 - c_x^2 x^2))`, `w = 1 - c_x z_y`, `c_x = 1 / radius_x_mm`.
//!   `radius_x_mm = 0` is flat in x (a cylinder with power in y, its axis along x); `radius_mm = 0` with a
//!   `radius_x_mm` is a cylinder with power in x (axis along y). A surface without `radius_x_mm` is a surface
//!   of revolution, as everywhere above. The sag is defined where `w > 0` and `w^2 >= c_x^2 x^2`
//!   (the vertex side of the torus); validation refuses a clear aperture beyond that.
//! - The medium of a surface is the one *after* it (on its +z side); the object space before surface 0 is
//!   air, and so is the image space after the last surface (the sensor sits in air).
//! - Heights x, y are measured from the axis, y in the meridional (y-z) plane; angles in radians unless a
//!   name ends in `_deg`; lengths in millimetres (`_mm`); wavelengths in nanometres (`_nm`).
//! - Surfaces are numbered from 0 in file order, in the API, the command line and every report.

use serde::{Deserialize, Serialize};

use super::glass::{D_LINE_NM, Dispersion};

/// Largest number of surfaces a lens may have (a 60-surface zoom is large; 1000 is absurd).
pub(crate) const MAX_SURFACES: usize = 1000;
/// Thicknesses beyond this are refused as absurd (one kilometre).
pub(crate) const MAX_THICKNESS_MM: f64 = 1.0e6;
/// Semi-apertures beyond this are refused as absurd (ten metres).
pub(crate) const MAX_SEMI_APERTURE_MM: f64 = 1.0e4;
/// Refractive indices above this are refused as absurd for visible light.
pub(crate) const MAX_INDEX: f64 = 4.0;
/// Most even aspheric terms above r^2 a surface may carry: A4 to A16, what Zemax's even asphere holds.
pub(crate) const MAX_ASPHERIC_TERMS: usize = 7;
/// Abbe numbers outside (0, this] are refused (real glasses lie between about 17 and 100).
pub(crate) const MAX_ABBE: f64 = 200.0;
/// Surfaces may touch but not cross: an edge gap below minus this is refused.
pub(crate) const EDGE_OVERLAP_TOLERANCE_MM: f64 = 1.0e-6;

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
    /// Conic constant k of the sag (0: sphere; -1: paraboloid; below -1: hyperboloid).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub conic: f64,
    /// The r^2 term of the even asphere, mm^-1 (Zemax `PARM 1`; it adds 2 A2 to the vertex curvature).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub aspheric_r2: f64,
    /// The even aspheric terms A4, A6, A8, ... (from r^4 up; A_2i in mm^(1-2i)).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aspheric: Vec<f64>,
    /// Radius of the x-z section of a toroidal surface (Zemax `TOROIDAL`'s radius of rotation; 0 = flat in
    /// x): `None` for a surface of revolution. See the sign convention above.
    #[serde(rename = "radius_x", default, skip_serializing_if = "Option::is_none")]
    pub radius_x_mm: Option<f64>,
    /// Clear semi-aperture (half the clear diameter).
    #[serde(rename = "semi_aperture")]
    pub semi_aperture_mm: f64,
    /// True on the aperture stop: a flat surface in one medium (an iris), or a lens surface whose clear
    /// aperture is the stop.
    #[serde(default)]
    pub stop: bool,
    /// Anti-reflection coating of this interface.
    #[serde(default, skip_serializing_if = "is_uncoated")]
    pub coating: Coating,
    /// Any other keys the file gave for this surface, kept verbatim and written back.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
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
            conic: 0.0,
            aspheric_r2: 0.0,
            aspheric: Vec::new(),
            radius_x_mm: None,
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

    /// True for a sphere or plane: no conic constant, no aspheric term, not toroidal.
    pub fn is_spherical(&self) -> bool {
        self.conic == 0.0
            && self.aspheric_r2 == 0.0
            && self.aspheric.iter().all(|&a| a == 0.0)
            && self.radius_x_mm.is_none()
    }

    /// What makes this surface other than a sphere or a plane, in words for a message (`None` for a sphere or a
    /// plane): "cylindrical" (a toroid flat in one section), "toroidal", "conic", "aspheric".
    pub fn non_spherical_kind(&self) -> Option<&'static str> {
        if let Some(rx) = self.radius_x_mm {
            let flat_in_one = rx.is_infinite() || rx == 0.0 || self.radius_mm.is_infinite() || self.radius_mm == 0.0;
            return Some(if flat_in_one { "cylindrical" } else { "toroidal" });
        }
        if self.aspheric_r2 != 0.0 || self.aspheric.iter().any(|&a| a != 0.0) {
            return Some("aspheric");
        }
        (self.conic != 0.0).then_some("conic")
    }

    /// True for a toroidal (anamorphic) surface: one with a radius of its own in the x-z section.
    pub fn is_toroidal(&self) -> bool {
        self.radius_x_mm.is_some()
    }

    /// Curvature of the x-z section at the vertex, 1/mm: `1 / radius_x_mm` for a toroid (0 when flat in
    /// x), the vertex curvature of the surface of revolution otherwise.
    pub fn vertex_curvature_x_per_mm(&self) -> f64 {
        match self.radius_x_mm {
            Some(0.0) => 0.0,
            Some(r) => 1.0 / r,
            None => self.vertex_curvature_per_mm(),
        }
    }

    /// The vertex curvature paraxial optics sees in `section` (the y-z section: [`Self::vertex_curvature_per_mm`]).
    pub fn section_curvature_per_mm(&self, section: Section) -> f64 {
        match section {
            Section::Y => self.vertex_curvature_per_mm(),
            Section::X => self.vertex_curvature_x_per_mm(),
        }
    }

    /// The curvature paraxial optics sees at the vertex: `c + 2 A2` (the conic and the terms from r^4 up
    /// do not change it).
    pub fn vertex_curvature_per_mm(&self) -> f64 {
        self.curvature_per_mm() + 2.0 * self.aspheric_r2
    }

    /// The shape of this surface as the tracer uses it.
    pub fn shape(&self) -> SurfaceShape {
        SurfaceShape::of(self)
    }

    /// Sag (z offset from the vertex) at height `h_mm` in the y-z section, or `None` where it is not defined
    /// (beyond [`Self::sag_limit_mm`], or not finite). For a surface of revolution, the sag at any point at
    /// that distance from the axis.
    pub fn sag_mm(&self, h_mm: f64) -> Option<f64> {
        self.shape().sag_mm(h_mm * h_mm)
    }

    /// Sag at the point (`x_mm`, `y_mm`) of the surface, toroidal or not; `None` where it is not defined.
    pub fn sag_xy_mm(&self, x_mm: f64, y_mm: f64) -> Option<f64> {
        self.shape().sag_xy_mm(x_mm, y_mm)
    }

    /// The largest height at which the sag is defined: `1 / (|c| sqrt(1 + k))` when `(1 + k) c^2 > 0`
    /// (the rim of the sphere or ellipsoid), infinite otherwise (planes, paraboloids, hyperboloids).
    pub fn sag_limit_mm(&self) -> f64 {
        let q = (1.0 + self.conic) * self.curvature_per_mm().powi(2);
        if q > 0.0 { 1.0 / q.sqrt() } else { f64::INFINITY }
    }
}

/// A surface's shape in the form the inner loops want, `Copy` and allocation-free: curvature, conic, the
/// r^2 term and up to `MAX_ASPHERIC_TERMS` even terms (unused ones 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceShape {
    pub curvature_per_mm: f64,
    pub conic: f64,
    pub a2: f64,
    /// A4, A6, ... A16.
    pub terms: [f64; MAX_ASPHERIC_TERMS],
    /// True when the conic and every term are 0 and the surface is not toroidal (the tracer then uses the
    /// exact sphere formulas alone).
    pub spherical: bool,
    /// True for a toroid: the y-z profile above swept with the x-z curvature `curvature_x_per_mm`.
    pub toroidal: bool,
    /// Curvature of a toroid's x-z section at the vertex (1 / radius of rotation; 0: flat in x). Unused (0)
    /// on a surface of revolution.
    pub curvature_x_per_mm: f64,
}

impl SurfaceShape {
    fn of(s: &Surface) -> Self {
        let mut terms = [0.0; MAX_ASPHERIC_TERMS];
        for (t, a) in terms.iter_mut().zip(&s.aspheric) {
            *t = *a;
        }
        Self {
            curvature_per_mm: s.curvature_per_mm(),
            conic: s.conic,
            a2: s.aspheric_r2,
            terms,
            spherical: s.is_spherical(),
            toroidal: s.is_toroidal(),
            curvature_x_per_mm: if s.is_toroidal() { s.vertex_curvature_x_per_mm() } else { 0.0 },
        }
    }

    /// Sag at the point (x, y), on the vertex side of a toroid (see the module's notes); `None` where it is not
    /// defined. A surface of revolution gives [`Self::sag_mm`] at `x^2 + y^2`.
    pub fn sag_xy_mm(&self, x: f64, y: f64) -> Option<f64> {
        if !self.toroidal {
            return self.sag_mm(x * x + y * y);
        }
        let z_y = self.sag_mm(y * y)?;
        let c_x = self.curvature_x_per_mm;
        let w = 1.0 - c_x * z_y;
        let root = w * w - c_x * c_x * x * x;
        if w <= 0.0 || root < 0.0 {
            return None;
        }
        let z = z_y + c_x * x * x / (w + root.sqrt());
        z.is_finite().then_some(z)
    }

    /// The slopes (dz/dx, dz/dy) at (x, y); `None` where the sag is not defined or the slope is infinite. On a
    /// toroid, from the torus `(1 - c_x z)^2 + c_x^2 x^2 = (1 - c_x z_y)^2`: `dz/dx = c_x x / (1 - c_x z)` and
    /// `dz/dy = (1 - c_x z_y) z_y' / (1 - c_x z)`.
    pub fn sag_gradient(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        if !self.toroidal {
            let m = self.slope_over_r(x * x + y * y)?;
            return Some([m * x, m * y]);
        }
        self.toroid_sag_and_gradient(x, y).map(|(_, g)| g)
    }

    /// A toroid's sag ([`Self::sag_xy_mm`]) and slopes ([`Self::sag_gradient`]) at (x, y) from one evaluation of
    /// its profile: what each Newton step of the tracer needs.
    pub fn toroid_sag_and_gradient(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        let z_y = self.sag_mm(y * y)?;
        let dz_y = y * self.slope_over_r(y * y)?;
        let c_x = self.curvature_x_per_mm;
        let w = 1.0 - c_x * z_y;
        let root = w * w - c_x * c_x * x * x;
        if w <= 0.0 || root < 0.0 {
            return None;
        }
        let z = z_y + c_x * x * x / (w + root.sqrt());
        let w_z = 1.0 - c_x * z;
        if !z.is_finite() || w_z <= 0.0 {
            return None;
        }
        let g = [c_x * x / w_z, w * dz_y / w_z];
        (g[0].is_finite() && g[1].is_finite()).then_some((z, g))
    }

    /// The conic part's square-root argument `1 - (1 + k) c^2 r^2` at `r2 = r^2`.
    fn root_arg(&self, r2: f64) -> f64 {
        1.0 - (1.0 + self.conic) * self.curvature_per_mm * self.curvature_per_mm * r2
    }

    /// Sag at `r2 = x^2 + y^2`, `None` where the conic's root is imaginary or the value is not finite.
    pub fn sag_mm(&self, r2: f64) -> Option<f64> {
        let root = self.root_arg(r2);
        if root < 0.0 {
            return None;
        }
        let c = self.curvature_per_mm;
        let mut z = c * r2 / (1.0 + root.sqrt()) + self.a2 * r2;
        let mut power = r2 * r2;
        for a in self.terms {
            z += a * power;
            power *= r2;
        }
        z.is_finite().then_some(z)
    }

    /// dz/dr divided by r at `r2 = r^2` (finite at the axis): `c / sqrt(1 - (1 + k) c^2 r^2) + 2 A2 + 4 A4
    /// r^2 + 6 A6 r^4 + ...`; `None` where the sag is not defined or the slope is infinite (the rim).
    pub fn slope_over_r(&self, r2: f64) -> Option<f64> {
        let root = self.root_arg(r2);
        if root <= 0.0 {
            return None;
        }
        let v = self.curvature_per_mm / root.sqrt() + self.polynomial_slope_over_r(r2);
        v.is_finite().then_some(v)
    }

    fn polynomial_slope_over_r(&self, r2: f64) -> f64 {
        let mut v = 2.0 * self.a2;
        let mut power = r2;
        for (i, a) in self.terms.iter().enumerate() {
            v += (2 * i + 4) as f64 * a * power;
            power *= r2;
        }
        v
    }
}

/// One of the two principal sections of a lens whose toroidal surfaces are aligned with x and y: near the
/// axis such a lens acts on x and on y separately, each by the 2x2 matrices of the surfaces of revolution
/// with that section's vertex curvatures ([`Lens::section`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Section {
    /// The x-z section (horizontal on the sensor).
    X,
    /// The y-z section (vertical; the meridional plane of the reference figures).
    Y,
}

impl Section {
    pub const BOTH: [Section; 2] = [Section::X, Section::Y];

    pub fn word(self) -> &'static str {
        match self {
            Section::X => "x",
            Section::Y => "y",
        }
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
    #[error("the lens has no aperture stop (mark one surface with \"stop\": true)")]
    NoStop,
    #[error("the lens has {count} aperture stops (surfaces {surfaces:?}); exactly one is needed")]
    SeveralStops { count: usize, surfaces: Vec<usize> },
    #[error("surface {surface}, field `{field}`: {reason}")]
    Field { surface: usize, field: &'static str, reason: String },
    #[error("lens field `{field}`: {reason}")]
    LensField { field: &'static str, reason: String },
}

impl LensError {
    pub(crate) fn field(surface: usize, field: &'static str, reason: impl Into<String>) -> Self {
        // A value echoed whole could be hundreds of digits long (a 302-digit semi-aperture): written short.
        Self::Field { surface, field, reason: crate::files::shorten_numbers(&reason.into()) }
    }
}

/// Points along both sections' axes out to `semi_mm`, 257 on each: where [`Lens::insert_dummy_after`] and
/// [`Lens::is_inert`] sample sags (a toroid's sag differs between its sections, and a difference of two toroids'
/// sags, a quadratic form near the axis, is extreme on one of them).
fn section_points(semi_mm: f64) -> impl Iterator<Item = (f64, f64)> {
    const SAMPLES: u32 = 256;
    (0..=SAMPLES).flat_map(move |i| {
        let h = semi_mm * f64::from(i) / f64::from(SAMPLES);
        [(0.0, h), (h, 0.0)]
    })
}

impl Lens {
    /// Number of interfaces, the stop included.
    pub fn number_of_surfaces(&self) -> usize {
        self.surfaces.len()
    }

    /// True when any surface is toroidal: the lens is not rotationally symmetric, and acts on x and y apart.
    pub fn is_anamorphic(&self) -> bool {
        self.surfaces.iter().any(Surface::is_toroidal)
    }

    /// The lens of revolution that `section` of this lens sees paraxially: each toroid becomes the sphere of
    /// that section's vertex curvature (in the y-z section, the profile itself with its conic and aspheric
    /// terms, which paraxial optics reads only through the vertex curvature). A lens of revolution is its own
    /// section, unchanged.
    pub fn section(&self, section: Section) -> Lens {
        let mut lens = self.clone();
        for s in lens.surfaces.iter_mut().filter(|s| s.is_toroidal()) {
            if section == Section::X {
                let c = s.vertex_curvature_x_per_mm();
                s.radius_mm = if c == 0.0 { 0.0 } else { 1.0 / c };
                (s.conic, s.aspheric_r2) = (0.0, 0.0);
                s.aspheric.clear();
            }
            s.radius_x_mm = None;
        }
        lens
    }

    /// Index of the aperture stop. Valid lenses have exactly one.
    pub fn stop_index(&self) -> usize {
        self.surfaces.iter().position(|s| s.stop).unwrap_or(0)
    }

    /// Splits the gap after surface `k` with a dummy surface (the same medium on both sides): no refraction
    /// and no reflection (not a ghost surface), its clear aperture the larger of its neighbours' (it clips no
    /// ray they pass), so the lens is optically what it was. It is flat, half way between the deepest sag of
    /// surface `k` and the shallowest of surface `k + 1` over their clear apertures, where a plane fits there;
    /// else (a meniscus gap: surface `k`'s rim lies beyond the next vertex) it takes the shape of the neighbour
    /// with the larger clear aperture, moved towards the other by half the narrowest gap between the two, so that
    /// it crosses neither and every ray meets the surfaces in their order. After the last surface it is flat, 1 mm behind that surface's deepest sag
    /// (at most half of its distance to the image, if it has one). Returns the new surface's index, or why there
    /// is no room. Sags and gaps are sampled along both sections' axes (a toroid's differ).
    /// [`Self::remove_surface`] on it gives back the lens.
    pub fn insert_dummy_after(&mut self, k: usize) -> Result<usize, String> {
        let Some(here) = self.surfaces.get(k) else {
            return Err(format!("there is no surface {k} (the lens has {})", self.surfaces.len()));
        };
        // The extreme sag of a surface over its clear aperture: the largest (`deepest`) or the smallest.
        let extreme = |s: &Surface, deepest: bool| -> f64 {
            section_points(s.semi_aperture_mm)
                .filter_map(|(x, y)| s.sag_xy_mm(x, y))
                .fold(0.0, |m: f64, z| if deepest { m.max(z) } else { m.min(z) })
        };
        let lo = extreme(here, true);
        let next = self.surfaces.get(k + 1);
        let semi = here.semi_aperture_mm.max(next.map_or(0.0, |s| s.semi_aperture_mm));
        let mut dummy = Surface::new(0.0, None, here.medium.clone(), semi);
        let (before, after) = match (here.thickness_mm, next) {
            (Some(t), Some(next)) if t + extreme(next, false) > lo => {
                let d = 0.5 * (lo + t + extreme(next, false));
                (Some(d), Some(t - d))
            }
            (Some(t), Some(next)) => {
                // The shape of the neighbour with the larger clear aperture (defined over all of the dummy's),
                // moved towards the other by half the narrowest gap between the two.
                let gap = section_points(here.semi_aperture_mm.min(next.semi_aperture_mm))
                    .map(|(x, y)| match (here.sag_xy_mm(x, y), next.sag_xy_mm(x, y)) {
                        (Some(a), Some(b)) => t + b - a,
                        _ => f64::NEG_INFINITY,
                    })
                    .fold(f64::INFINITY, f64::min);
                if gap.is_nan() || gap <= 0.0 {
                    return Err(format!(
                        "no room for a surface after surface {k}: it touches the next surface within their clear \
                         apertures"
                    ));
                }
                let (shape, d) = if here.semi_aperture_mm >= next.semi_aperture_mm {
                    (here, 0.5 * gap)
                } else {
                    (next, t - 0.5 * gap)
                };
                (dummy.radius_mm, dummy.conic, dummy.aspheric_r2, dummy.aspheric, dummy.radius_x_mm) =
                    (shape.radius_mm, shape.conic, shape.aspheric_r2, shape.aspheric.clone(), shape.radius_x_mm);
                (Some(d), Some(t - d))
            }
            (Some(t), None) => {
                let d = (lo + 1.0).min(0.5 * (lo.max(0.0) + t));
                (Some(d), Some(t - d))
            }
            (None, _) => (Some(lo.max(0.0) + 1.0), None),
        };
        // The two parts of the split gap add up to it exactly, so removing the dummy gives back the very same
        // number: `after` rounded, then `before` as `t - after`. By Sterbenz's lemma either `t - after` is exact
        // (`after` at least half of `t`) or `after` itself was (`d` at least half of `t`, so `t - after` is `d`);
        // either way `before + after` is `t` exactly.
        let (before, after) = match (before, after, here.thickness_mm) {
            (Some(_), Some(a), Some(t)) => (Some(t - a), Some(a)),
            other => (other.0, other.1),
        };
        dummy.thickness_mm = after;
        self.surfaces[k].thickness_mm = before;
        self.surfaces.insert(k + 1, dummy);
        Ok(k + 1)
    }

    /// Whether surface `k` is inert: it changes nothing that light does, so the lens without it
    /// ([`Self::without_inert`]) is the same optics (what [`Self::insert_dummy_after`] adds is inert). That is:
    /// not the first surface, not the stop, uncoated and with no extra fields, the very same medium on both
    /// sides (so no refraction and no reflection at any wavelength), and a clear aperture that cuts no ray that
    /// passes its neighbours: at least as wide as either, and lying behind the surface before it over that
    /// one's clear aperture and ahead of the surface after it over that one's (a straight ray between points
    /// inside both neighbours' apertures then crosses it inside its own). Checked along both sections' axes at
    /// 257 points, as the insertion places it.
    pub fn is_inert(&self, k: usize) -> bool {
        let Some(s) = self.surfaces.get(k) else { return false };
        if k == 0
            || s.stop
            || s.coating != Coating::Uncoated
            || !s.extra.is_empty()
            || self.medium_before(k) != s.medium
        {
            return false;
        }
        let (prev, next) = (&self.surfaces[k - 1], self.surfaces.get(k + 1));
        let Some(gap_before) = prev.thickness_mm else { return false };
        if s.semi_aperture_mm < prev.semi_aperture_mm.max(next.map_or(0.0, |n| n.semi_aperture_mm)) {
            return false;
        }
        // z of each surface at (x, y), from the vertex of the surface before.
        let behind_prev =
            section_points(prev.semi_aperture_mm).all(|(x, y)| match (prev.sag_xy_mm(x, y), s.sag_xy_mm(x, y)) {
                (Some(a), Some(b)) => a <= gap_before + b,
                _ => false,
            });
        let ahead_of_next = match (next, s.thickness_mm) {
            (None, _) => true,
            (Some(_), None) => false,
            (Some(next), Some(gap_after)) => {
                section_points(next.semi_aperture_mm).all(|(x, y)| match (s.sag_xy_mm(x, y), next.sag_xy_mm(x, y)) {
                    (Some(b), Some(c)) => b <= gap_after + c,
                    _ => false,
                })
            }
        };
        behind_prev && ahead_of_next
    }

    /// The lens without its inert surfaces ([`Self::is_inert`]), each one's gap joined to the one before it
    /// ([`Self::remove_surface`]), and for each surface left its index in `self`: the same optics, numbered as
    /// the lens was before a dummy surface was added. Borrowed as it is when no surface is inert.
    pub fn without_inert(&self) -> (std::borrow::Cow<'_, Lens>, Vec<usize>) {
        let inert: Vec<usize> = (0..self.surfaces.len()).filter(|&k| self.is_inert(k)).collect();
        if inert.is_empty() {
            return (std::borrow::Cow::Borrowed(self), (0..self.surfaces.len()).collect());
        }
        let mut lens = self.clone();
        // From the last, so the indices still to remove stay valid (and each gap joins its live neighbour's).
        for &k in inert.iter().rev() {
            let _ = lens.remove_surface(k);
        }
        let kept = (0..self.surfaces.len()).filter(|k| !inert.contains(k)).collect();
        (std::borrow::Cow::Owned(lens), kept)
    }

    /// Removes surface `k`, every other surface staying where it was: its gap joins the one before it (so
    /// removing what [`Self::insert_dummy_after`] added gives back the lens). The last surface left is kept.
    pub fn remove_surface(&mut self, k: usize) -> Result<(), String> {
        if k >= self.surfaces.len() {
            return Err(format!("there is no surface {k} (the lens has {})", self.surfaces.len()));
        }
        if self.surfaces.len() == 1 {
            return Err("a lens needs at least one surface".into());
        }
        let removed = self.surfaces.remove(k);
        if k > 0 {
            let now_last = k == self.surfaces.len();
            let previous = &mut self.surfaces[k - 1];
            previous.thickness_mm = match (previous.thickness_mm, removed.thickness_mm) {
                (Some(a), Some(b)) => Some(a + b),
                // The removed surface was the last, with no distance to the image: neither has the new last.
                (_, None) if now_last => None,
                (a, _) => a,
            };
        }
        Ok(())
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

    /// Surfaces that reflect: the media on their two sides differ. A stop on a lens surface reflects like
    /// any lens surface; an iris (a stop with one medium on both sides) never does.
    pub fn reflecting_surfaces(&self) -> Vec<usize> {
        (0..self.surfaces.len()).filter(|&k| self.medium_before(k).differs_from(&self.surfaces[k].medium)).collect()
    }

    /// True when the stop is a lens surface (curved, or between different media) rather than an iris in one
    /// medium.
    pub fn stop_on_lens_surface(&self) -> bool {
        let k = self.stop_index();
        self.surfaces.get(k).is_some_and(|s| !s.is_flat() || self.medium_before(k).differs_from(&s.medium))
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
        self.validate_except_edges()?;
        self.validate_edges()
    }

    /// Every check of [`Self::validate`] but whether neighbouring surfaces cross (which
    /// `crate::optics::tolerance::repair` may mend).
    pub fn validate_except_edges(&self) -> Result<(), LensError> {
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
        let last = &self.surfaces[n - 1].medium;
        if !last.is_air() {
            return Err(LensError::field(n - 1, "nd", "the image space after the last surface must be air (nd = 1)"));
        }
        Ok(())
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
        match self.edge_crossings().first() {
            None => Ok(()),
            Some(c) => Err(LensError::field(c.surface, "thickness", c.describe())),
        }
    }

    /// Every pair of neighbouring surfaces that cross inside their common clear aperture, with the height
    /// at which they meet (the first height, from the axis out, where the edge gap drops below
    /// `-EDGE_OVERLAP_TOLERANCE_MM`, found by bisection to 1e-9 mm).
    pub fn edge_crossings(&self) -> Vec<EdgeCrossing> {
        let mut out = Vec::new();
        for k in 0..self.surfaces.len().saturating_sub(1) {
            let (a, b) = (&self.surfaces[k], &self.surfaces[k + 1]);
            let h_max = a.semi_aperture_mm.min(b.semi_aperture_mm);
            let t = a.thickness_mm.unwrap_or(0.0);
            // The y-z section; the x-z section too where a toroid makes it differ.
            let sections: &[Section] =
                if a.is_toroidal() || b.is_toroidal() { &[Section::Y, Section::X] } else { &[Section::Y] };
            for &section in sections {
                let sag = |s: &Surface, h: f64| match section {
                    Section::Y => s.sag_mm(h),
                    Section::X => s.sag_xy_mm(h, 0.0),
                };
                let gap = |h: f64| match (sag(a, h), sag(b, h)) {
                    (Some(sag_a), Some(sag_b)) => t + sag_b - sag_a,
                    _ => f64::INFINITY,
                };
                if let Some(crossing) = first_crossing(k, gap, h_max, [a.semi_aperture_mm, b.semi_aperture_mm]) {
                    out.push(crossing);
                    break;
                }
            }
        }
        out
    }
}

/// Where the edge gap `gap(h)` first drops below `-EDGE_OVERLAP_TOLERANCE_MM` over `0..=h_max` (sampled,
/// then bisected to 1e-9 mm), as the crossing of surfaces `k` and `k + 1`.
fn first_crossing(k: usize, gap: impl Fn(f64) -> f64, h_max: f64, semi_apertures_mm: [f64; 2]) -> Option<EdgeCrossing> {
    let crosses = |h: f64| gap(h) < -EDGE_OVERLAP_TOLERANCE_MM;
    let samples = 512;
    let i = (1..=samples).find(|&i| crosses(h_max * i as f64 / samples as f64))?;
    // The meeting point lies between the last height that does not cross and the first that does.
    let (mut lo, mut hi) = (h_max * (i - 1) as f64 / samples as f64, h_max * i as f64 / samples as f64);
    while hi - lo > 1e-9 {
        let mid = 0.5 * (lo + hi);
        if gap(mid) < 0.0 { hi = mid } else { lo = mid }
    }
    Some(EdgeCrossing { surface: k, meet_height_mm: lo, semi_apertures_mm, gap_at_edge_mm: gap(h_max) })
}

/// Two neighbouring surfaces, `surface` and `surface + 1`, that cross inside their clear apertures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeCrossing {
    pub surface: usize,
    /// Height from the axis at which the two surfaces meet (the gap between them is 0 there).
    pub meet_height_mm: f64,
    /// The clear semi-apertures the lens gives the two surfaces.
    pub semi_apertures_mm: [f64; 2],
    /// The (negative) axial gap between them at the smaller clear semi-aperture.
    pub gap_at_edge_mm: f64,
}

impl EdgeCrossing {
    /// One sentence, numbers rounded for people.
    pub fn describe(&self) -> String {
        let [a, b] = self.semi_apertures_mm;
        format!(
            "surfaces {} and {} meet at a height of {} mm, inside their clear semi-apertures ({} and {} mm)",
            self.surface,
            self.surface + 1,
            round(self.meet_height_mm),
            round(a),
            round(b)
        )
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
    validate_shape(k, s, r, h)?;
    validate_coating(k, &s.coating)
}

/// Heights at which validation samples an aspheric sag across the clear aperture.
const SAG_SAMPLES: usize = 256;

/// The sag must be defined, finite and of finite slope over the whole clear aperture `0..=h`.
fn validate_shape(k: usize, s: &Surface, r: f64, h: f64) -> Result<(), LensError> {
    let conic = finite(k, "conic", s.conic)?;
    finite(k, "aspheric_r2", s.aspheric_r2)?;
    if s.aspheric.len() > MAX_ASPHERIC_TERMS {
        return Err(LensError::field(
            k,
            "aspheric",
            format!("{} terms; at most {MAX_ASPHERIC_TERMS} (A4 to A16) are supported", s.aspheric.len()),
        ));
    }
    for a in &s.aspheric {
        finite(k, "aspheric", *a)?;
    }
    let limit = s.sag_limit_mm();
    if limit <= h {
        let reason = if conic == 0.0 {
            format!("|{}| mm is smaller than the semi-aperture {} mm: no sphere is that wide", round(r), round(h))
        } else {
            format!(
                "with conic {} the surface is defined up to a height of {} mm, inside the clear semi-aperture \
                 {} mm",
                round(conic),
                round(limit),
                round(h)
            )
        };
        return Err(LensError::field(k, if conic == 0.0 { "radius" } else { "conic" }, reason));
    }
    if let Some(r_x) = s.radius_x_mm {
        finite(k, "radius_x", r_x)?;
        if s.stop {
            return Err(LensError::field(
                k,
                "radius_x",
                "the aperture stop must be a surface of revolution (the iris is round); put the stop on a flat \
                 surface of its own",
            ));
        }
        return validate_toroid(k, s, h);
    }
    if !s.is_spherical() {
        let shape = s.shape();
        for i in 0..=SAG_SAMPLES {
            let height = h * i as f64 / SAG_SAMPLES as f64;
            let r2 = height * height;
            if shape.sag_mm(r2).is_none() || shape.slope_over_r(r2).is_none() {
                return Err(LensError::field(
                    k,
                    "aspheric",
                    format!(
                        "the sag is not finite at a height of {} mm, inside the clear semi-aperture {} mm",
                        round(height),
                        round(h)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// A toroid's sag and slopes must be defined over the whole clear disc `x^2 + y^2 <= h^2`: sampled on
/// [`SAG_SAMPLES`] rings of 64 azimuths (the torus's own limit `w^2 >= c_x^2 x^2` is widest at the rim).
fn validate_toroid(k: usize, s: &Surface, h: f64) -> Result<(), LensError> {
    let shape = s.shape();
    let azimuths = 64;
    for i in 0..=SAG_SAMPLES {
        let r = h * i as f64 / SAG_SAMPLES as f64;
        for a in 0..azimuths {
            let phi = std::f64::consts::TAU * f64::from(a) / f64::from(azimuths);
            let (x, y) = (r * phi.cos(), r * phi.sin());
            if shape.sag_xy_mm(x, y).is_none() || shape.sag_gradient(x, y).is_none() {
                let field = if shape.sag_mm(y * y).is_none() { "radius" } else { "radius_x" };
                return Err(LensError::field(
                    k,
                    field,
                    format!(
                        "the toroid is not defined at (x, y) = ({}, {}) mm, inside the clear semi-aperture {} mm",
                        round(x),
                        round(y),
                        round(h)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// A number as people read it in a message: two decimals at most (four below 1), no trailing zeros
/// (18.8, not 18.799999999999997).
pub fn round(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v != 0.0 && (v.abs() >= 1e7 || v.abs() < 1e-4) {
        return format!("{v:.2e}");
    }
    let s = if v.abs() >= 1.0 { format!("{v:.2}") } else { format!("{v:.4}") };
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".to_owned() } else { s.to_owned() }
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
