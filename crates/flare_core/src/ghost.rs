//! Paraxial ghosts (KR 10-1465658; Lee & Eisemann 2013): every two-reflection ghost as a sprite per
//! wavelength, rebuilt when the lens changes and moved per frame by the light direction alone.
//!
//! # How it works
//! Near the axis a rotationally symmetric lens acts on x and y separately with the same 2x2 matrix, so a ray
//! entering the entrance plane (the first vertex, z = 0) at the point `x0` (2-vector) with the light's slope
//! vector `u` reaches the sensor at `A_f x0 + B_f u` and the stop, at its k-th crossing, at `A_k x0 + B_k u`
//! (`M_f = [[A_f, B_f], ..]` and `M_a = [[A_k, B_k], ..]` from [`crate::optics::paraxial::PathMatrices`]).
//! - **Effective entrance region**: the rays that pass crossing k of the stop form the disc of centre
//!   `-B_k u / A_k` and radius `r_a / |A_k|` (the patent's `r_e = (r_a - M_a12 theta_e) / M_a11`), and so does
//!   every crossing of every other surface's clear aperture `a` (the front lens's first, then the middle
//!   groups', the reflecting surfaces' too), with radius `a / |A|` from its own entrance-to-arrival matrix
//!   (`Disc`). The region is their intersection: empty (culled) when two discs miss each other. A ghost
//!   whose reflections straddle the stop crosses it three times and gets all three stop discs. Off axis the
//!   discs slide apart by `|c_k - c_m| |u|`, so the region is cut into the cat's eyes and lemons of real
//!   lenses. A clear aperture cuts only where it does not hold another disc: at rebuild each disc gets the
//!   slope below which it holds one (`Disc::redundant_below_slope`), and per frame
//!   [`GhostSystem::sprite_masks`] keeps the discs that cut the sprite's quad at this light, at most
//!   `MAX_DISCS` (when more cut, those that cut the most of a 16 x 16 grid of the quad; the rest are counted).
//!   A crossing with `A = 0` passes a ray only while `|B u| <= a`: it empties the region past that slope.
//! - **Sprite**: the smallest of those discs, centre E and radius rho, bounds the region; mapped to the
//!   sensor it gives the sprite's centre `C = A_f E + B_f u` and signed half-size `S = A_f rho` (the flare
//!   quad: the four corner rays `E + rho (+-1, +-1)` land on `C + S (+-1, +-1)`; centre and rim rays give the
//!   circle). Inside the sprite, at quad coordinate q in [-1, 1]^2, the entrance point is `E + rho q`, so each
//!   crossing's aperture coordinate is the affine `uv_k = (A_k rho / r_a) q + (A_k E + B_k u) / r_a`: the
//!   renderer multiplies the aperture mask at every stop crossing and each cutting disc's
//!   `(E + rho q - c u) / r` (a unit circle). What the discs cut off is gone: the irradiance inside is
//!   unchanged, so energy stays conserved.
//! - **Brightness**: energy is conserved, so the irradiance relative to the incoming light is
//!   `cos(theta) R_i R_j T (entrance area / sensor area) = cos(theta) R_i R_j T / A_f^2`, where T is the
//!   product of the transmittances `1 - R` of every refraction along the path, taken at normal incidence
//!   (a constant per ghost and wavelength: a ghost that crosses 40 uncoated surfaces keeps only ~13%). A ghost focused onto the
//!   sensor (A_f -> 0) gets the half-size `max(|S|, r_min)` and the irradiance `R_i R_j (rho / S)^2` with that
//!   size: bounded, with the same total energy, never infinite. When `A_k -> 0` (the stop's image at
//!   infinity) another disc bounds the region (the front lens's at least) and nothing divides by zero.
//! - **Reflectance**: each reflection's angle of incidence is paraxial, `i = u + s c y` for the ray through the
//!   region's centre E, linear in E and the light's slope; the reflectance of each (surface, side, wavelength) is
//!   tabulated at rebuild over sin^2(i) in [0, 1] (`REFLECTANCE_SAMPLES` samples, linear interpolation) from
//!   [`crate::coating`], so a frame costs a few multiplications per sprite.
//! - **Skipping**: sprites that fall entirely off the sensor or whose entrance region is empty are culled, and
//!   so are the faintest ones, as many as can go while their peak colours sum to at most the threshold (so
//!   that what is culled adds at most the threshold to any pixel, however many faint ghosts overlap), with
//!   the reason counted in [`FrameStats`].
//!
//! - **Anamorphic lenses** (toroids aligned with x and y): near the axis the lens acts on x by its x-z
//!   section's matrices and on y by its y-z section's ([`Lens::section`]), so the method holds axis by axis.
//!   [`GhostSystem::build`] builds a system per section, both ending on the lens's own sensor plane (half way
//!   between the sections' foci), and keeps the x-z one in [`GhostSystem::x_section`]: every x quantity of a
//!   sprite (centre, half-size, mask scales and offsets, the x part of each reflection's angle of incidence)
//!   comes from it, every y quantity from the y-z system. The entrance region is then the box of the two
//!   sections' bounding intervals, mapped to the half-sizes `(S_x, S_y)`; the irradiance is
//!   `cos(theta) R_i R_j T rho_x rho_y / (S_x S_y)` (energy conserved), the angles of incidence add their
//!   squares, and the region is empty when either section's discs part (a box test: never a lit ghost culled).
//!   Each clear aperture's disc is then an ellipse, its x semi-axis and centre from the x-z section, its y ones
//!   from the y-z section (a circle on the surface seen through two different matrices).
//!   A lens of revolution takes the first branch of every such choice, unchanged.
//!
//! What changes per frame is only `u`: [`GhostSystem::frame`] is all the per-frame CPU work.

use crate::coating::InterfaceTables;
use crate::optics::mapping::ImageMapping;
use crate::optics::path::PathError;
pub use crate::optics::sensor::{Sensor, light_slopes_for_frame_position, sensor_to_pixel};
use crate::optics::{Coating, FirstOrder, Lens, LightPath, Mat2, ParaxialError, PathMatrices, Section};
use crate::spectrum::Spectrum;

/// Samples of each reflectance table over sin^2(i) in [0, 1].
pub(crate) const REFLECTANCE_SAMPLES: usize = 33;

/// Settings that change the ghosts without changing the lens geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostSettings {
    pub spectrum: Spectrum,
    /// Stop radius relative to wide open (from the chosen f-number; see [`crate::aperture::Aperture::stop_scale`]).
    pub stop_scale: f64,
    /// When set, every reflecting surface wears this coating instead of its own.
    pub coating_override: Option<Coating>,
}

impl Default for GhostSettings {
    fn default() -> Self {
        Self { spectrum: Spectrum::rgb(), stop_scale: 1.0, coating_override: None }
    }
}

/// Per-frame choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSettings {
    pub sensor: Sensor,
    /// The faintest sprites are culled while the sum of their brightest channels (relative irradiance) stays
    /// at most this: the most light culling may take from any pixel.
    pub intensity_threshold: f64,
    /// Smallest sprite half-size on the sensor (a focused ghost is drawn this big, with its energy).
    pub min_half_size_mm: f64,
}

impl Default for FrameSettings {
    fn default() -> Self {
        Self { sensor: Sensor { width_mm: 36.0, height_mm: 24.0 }, intensity_threshold: 1e-7, min_half_size_mm: 0.02 }
    }
}

impl FrameCoefficients {
    /// Everything linear in the light slope u, from the ghost's matrices (see the module documentation).
    /// `discs` are the ghost's clear-aperture discs (every crossing of a surface other than the stop, the front
    /// lens's first), which it indexes from `first_disc` in [`GhostSystem`]'s list.
    fn new(ghost: usize, wavelength: usize, optics: &GhostOptics, r_a: f64, discs: &[Disc], first_disc: usize) -> Self {
        let m = &optics.matrices;
        let f = m.sensor_from_entrance;
        // Entrance discs as (centre per slope, radius): every clear aperture, then each stop crossing with A != 0.
        // A crossing with A = 0 does not depend on the entry point: every ray misses it once |B u| > r_a (the
        // clear apertures' such crossings are folded into `Disc::empty_from_slope`).
        let mut all: Vec<(f64, f64)> = discs.iter().map(|d| (d.centre_per_slope, d.radius_mm)).collect();
        let mut empty_from_slope = discs.iter().map(|d| d.empty_from_slope).fold(f64::INFINITY, f64::min);
        for a in &m.stop_from_entrance {
            let (centre, radius, empty) = entrance_disc(a, r_a);
            if radius.is_finite() {
                all.push((centre, radius));
            }
            empty_from_slope = empty_from_slope.min(empty);
        }
        // Two discs of centres c_p u and c_q u stop overlapping when |c_p - c_q| |u| >= r_p + r_q.
        for p in 0..all.len() {
            for q in p + 1..all.len() {
                let dc = (all[p].0 - all[q].0).abs();
                if dc > 0.0 {
                    empty_from_slope = empty_from_slope.min((all[p].1 + all[q].1) / dc);
                }
            }
        }
        // The region's bounding disc: the smallest of them (a lens always has its front disc).
        let (e_per_slope, rho) =
            all.iter().copied().fold((0.0, f64::INFINITY), |best, d| if d.1 < best.1 { d } else { best });
        let mut stop_scale = [0.0; 3];
        let mut stop_offset_per_slope = [0.0; 3];
        for (k, a) in m.stop_from_entrance.iter().take(3).enumerate() {
            stop_scale[k] = a.a * rho / r_a;
            stop_offset_per_slope[k] = (a.a * e_per_slope + a.b) / r_a;
        }
        let incidence2 = |inc: &Incidence| (inc.per_entry * e_per_slope + inc.per_slope).powi(2);
        let half_size_mm = f.a * rho;
        Self {
            ghost: ghost as u32,
            wavelength: wavelength as u32,
            centre_per_slope: f.a * e_per_slope + f.b,
            half_size_mm,
            rho_squared: rho * rho,
            empty_from_slope,
            incidence2_j: incidence2(&optics.incidence_j),
            incidence2_i: incidence2(&optics.incidence_i),
            area_ratio: if half_size_mm != 0.0 { (rho / half_size_mm).powi(2) } else { 0.0 },
            transmission: optics.transmission,
            reflectance_j: optics.reflectance_j as u32,
            reflectance_i: optics.reflectance_i as u32,
            stop_scale,
            stop_offset_per_slope,
            stop_count: m.stop_from_entrance.len().min(3) as u8,
            rho_mm: rho,
            e_per_slope,
            discs: first_disc as u32..(first_disc + discs.len()) as u32,
        }
    }
}

/// The most clear-aperture discs a sprite's masks carry ([`SpriteMasks::discs`]): those that cut the sprite's
/// region most at the frame's light. The rest are counted in [`SpriteMasks::discs_left_out`].
pub(crate) const MAX_DISCS: usize = 4;

/// One crossing of a clear aperture (a surface other than the stop) by a ghost path at one wavelength: the rays
/// that pass it form, in the entrance plane, the disc of centre `centre_per_slope * u` and radius `radius_mm`
/// (`-B u / A` and `a / |A|` from the entrance-to-arrival matrix `[[A, B], ..]` and the semi-aperture `a`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Disc {
    /// The surface crossed.
    pub surface: usize,
    pub centre_per_slope: f64,
    pub radius_mm: f64,
    /// The disc holds another of the ghost's discs (clear or the stop's circle) while `|u|` is below this, so
    /// it cannot cut the region there (0 when never; see `GhostSystem::set_redundancy`, at rebuild).
    pub redundant_below_slope: f64,
    /// No ray passes once `|u|` reaches this: a crossing with `A = 0`, where the height `B u` does not depend
    /// on the entry point (infinity otherwise).
    pub empty_from_slope: f64,
}

impl Disc {
    /// The disc of a crossing of `surface` (semi-aperture `a_mm`) whose entrance-to-arrival matrix is `m`
    /// ([`entrance_disc`]); an unbounded one never cuts, so it is redundant at every light.
    fn new(surface: usize, m: &Mat2, a_mm: f64) -> Self {
        let (centre_per_slope, radius_mm, empty_from_slope) = entrance_disc(m, a_mm);
        let redundant_below_slope = if radius_mm.is_finite() { 0.0 } else { f64::INFINITY };
        Self { surface, centre_per_slope, radius_mm, redundant_below_slope, empty_from_slope }
    }
}

/// The entrance-plane disc of the rays that pass an aperture of radius `a_mm` reached through the
/// entrance-to-arrival matrix `m`: (centre per unit slope `-B / A`, radius `a / |A|`, the slope from which it is
/// empty). A crossing with `A = 0` does not depend on the entry point: an unbounded disc that every ray misses
/// once `|B u| > a` (infinity when B is 0 too).
fn entrance_disc(m: &Mat2, a_mm: f64) -> (f64, f64, f64) {
    if m.a.abs() > 1e-12 {
        (-m.b / m.a, a_mm / m.a.abs(), f64::INFINITY)
    } else {
        (0.0, f64::INFINITY, if m.b != 0.0 { a_mm / m.b.abs() } else { f64::INFINITY })
    }
}

/// Paraxial angle of incidence at one reflection, linear in the entry point x0 and the light slope u.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Incidence {
    per_entry: f64,
    per_slope: f64,
}

impl Incidence {
    /// The coefficients from the entrance-to-arrival matrix `m` at a surface of curvature `c`, arriving in
    /// direction `s`: the angle to the normal is `u + s c y`.
    fn new(m: &Mat2, c: f64, s: f64) -> Self {
        let angle = |(y, u): (f64, f64)| u + s * c * y;
        Self { per_entry: angle(m.apply(1.0, 0.0)), per_slope: angle(m.apply(0.0, 1.0)) }
    }
}

/// One ghost at one wavelength: everything a frame needs, from the lens alone.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostOptics {
    pub wavelength_nm: f64,
    /// The path's matrices (entrance -> sensor, entrance -> each stop crossing, last crossing -> sensor).
    pub matrices: PathMatrices,
    /// Paraxial angle of incidence at the two reflections (second surface j, then i) as a linear function of
    /// the entry point and the light slope: `angle = per_entry * x0 + per_slope * u`.
    incidence_j: Incidence,
    incidence_i: Incidence,
    /// Product of the transmittances (1 - R at normal incidence) of every refraction along the path.
    pub transmission: f64,
    /// Indices into [`GhostSystem`]'s reflectance tables.
    reflectance_j: usize,
    reflectance_i: usize,
}

/// What a frame needs of one ghost at one wavelength, precomputed so that the frame is a handful of
/// multiplications: the entrance region's centre E is (a constant) x u, so everything is linear in u.
#[derive(Clone, Debug, PartialEq)]
struct FrameCoefficients {
    ghost: u32,
    wavelength: u32,
    /// Sprite centre = this * u (sensor mm per unit slope).
    centre_per_slope: f64,
    /// Signed half-size A_f rho (mm), before the focused-ghost minimum.
    half_size_mm: f64,
    /// rho^2: the entrance region's bounding radius squared (mm^2), for the energy.
    rho_squared: f64,
    /// The entrance region is empty once |u| reaches this (infinity when never).
    empty_from_slope: f64,
    /// Squared paraxial incidence angle (as a tangent) per unit |u|^2 at the two reflections.
    incidence2_j: f64,
    incidence2_i: f64,
    /// rho^2 / S^2: the irradiance factor when the sprite is not enlarged.
    area_ratio: f64,
    /// The path's transmission (see [`GhostOptics::transmission`]).
    transmission: f64,
    reflectance_j: u32,
    reflectance_i: u32,
    /// Aperture maps: scale, and offset per unit slope, per crossing.
    stop_scale: [f64; 3],
    stop_offset_per_slope: [f64; 3],
    stop_count: u8,
    /// The entrance region's bounding disc: radius (mm) and centre per unit slope (`E = e_per_slope u`).
    rho_mm: f64,
    e_per_slope: f64,
    /// This sprite's clear-aperture discs in [`GhostSystem`]'s list.
    discs: std::ops::Range<u32>,
}

/// One two-reflection ghost.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostModel {
    /// The light reflects at `j`, then at `i` (i < j).
    pub i: usize,
    pub j: usize,
    /// The reflections lie on both sides of the stop: it crosses the stop three times and all three apply.
    pub straddles_stop: bool,
    pub per_wavelength: Vec<GhostOptics>,
}

/// Why a sprite is not drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CullReason {
    BelowThreshold,
    OffSensor,
    EmptyEntranceRegion,
}

impl CullReason {
    pub fn word(self) -> &'static str {
        match self {
            Self::BelowThreshold => "below_threshold",
            Self::OffSensor => "off_sensor",
            Self::EmptyEntranceRegion => "empty_entrance_region",
        }
    }
}

/// An affine map from sprite quad coordinates q to a mask's coordinates, axis by axis:
/// `uv = scale * q + offset` (the two scales are equal for a lens of revolution).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskMap {
    pub scale: [f64; 2],
    pub offset: [f64; 2],
}

impl MaskMap {
    /// The mask coordinates of quad coordinate `q`.
    pub fn at(&self, q: [f64; 2]) -> [f64; 2] {
        [self.scale[0] * q[0] + self.offset[0], self.scale[1] * q[1] + self.offset[1]]
    }
}

/// One ghost at one wavelength in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Sprite {
    pub ghost: usize,
    pub wavelength: usize,
    /// Sprite centre on the sensor (sensor coordinates, the image is not yet flipped for display).
    pub centre_mm: [f64; 2],
    /// Signed half-size along x and y: negative when the ghost is an inverted image of the aperture along that
    /// axis. Equal for a lens of revolution; an anamorphic lens's ghosts are ellipses.
    pub half_size_mm: [f64; 2],
    /// Irradiance relative to the incoming light (cos theta R_i R_j T / A_f^2, bounded).
    pub irradiance: f64,
    /// irradiance x the wavelength's weight, clamped at 0.
    pub rgb: [f64; 3],
    pub culled: Option<CullReason>,
}

/// The masks of one sprite at one light: the aperture at each stop crossing (the first `stop_count`) and the
/// clear-aperture discs that cut its region there (the first `disc_count`, each a circle of radius 1 in its
/// coordinates: the front lens's, and any other surface's that vignettes the ghost).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpriteMasks {
    pub stop_maps: [MaskMap; 3],
    pub stop_count: usize,
    /// The cutting discs; a disc that holds the whole quad is left out (it is 1 there).
    pub disc_maps: [MaskMap; MAX_DISCS],
    /// The surface of each disc.
    pub disc_surfaces: [usize; MAX_DISCS],
    pub disc_count: usize,
    /// Cutting discs beyond `MAX_DISCS`, left out (the region drawn is then a little larger than the lens's).
    pub discs_left_out: usize,
    /// Quad coordinate q -> entrance-plane point (mm): the region's bounding disc's centre E and radius rho per
    /// axis (`x0 = E + rho q`).
    pub region: MaskMap,
}

impl SpriteMasks {
    /// The aperture maps of the stop crossings this sprite has.
    pub fn stops(&self) -> &[MaskMap] {
        &self.stop_maps[..self.stop_count]
    }

    /// The clear-aperture discs that cut this sprite.
    pub fn discs(&self) -> &[MaskMap] {
        &self.disc_maps[..self.disc_count]
    }

    /// The surfaces whose clear apertures cut this sprite (as [`Self::discs`]).
    pub fn cutting_surfaces(&self) -> &[usize] {
        &self.disc_surfaces[..self.disc_count]
    }
}

/// The surfaces whose clear apertures cut any of the sprites `masks` belong to ([`SpriteMasks::cutting_surfaces`]),
/// in increasing order, each once.
pub(crate) fn surfaces_cutting(masks: impl IntoIterator<Item = SpriteMasks>) -> Vec<usize> {
    let mut surfaces: Vec<usize> = masks.into_iter().flat_map(|m| m.cutting_surfaces().to_vec()).collect();
    surfaces.sort_unstable();
    surfaces.dedup();
    surfaces
}

/// The map from quad coordinates into a clear-aperture disc's own (a unit circle), x from `discs[0]` (the x-z
/// section's), y from `discs[1]`, for the region `region` (`x0 = E + rho q`) at light slope `u`:
/// `(E + rho q - c u) / r` per axis.
fn disc_map(discs: [&Disc; 2], region: &MaskMap, u: [f64; 2]) -> MaskMap {
    let axis = |k: usize| {
        let d = discs[k];
        (region.scale[k] / d.radius_mm, (region.offset[k] - d.centre_per_slope * u[k]) / d.radius_mm)
    };
    let (x, y) = (axis(0), axis(1));
    MaskMap { scale: [x.0, y.0], offset: [x.1, y.1] }
}

/// How far from its centre a mask map reaches over the quad [-1, 1]^2: a disc map reaching at most 1 holds the
/// whole quad.
pub(crate) fn map_reach(map: &MaskMap) -> f64 {
    (map.offset[0].abs() + map.scale[0].abs()).hypot(map.offset[1].abs() + map.scale[1].abs())
}

/// Counts of what a frame drew and skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    pub sprites: usize,
    pub drawn: usize,
    pub below_threshold: usize,
    pub off_sensor: usize,
    pub empty_entrance_region: usize,
}

/// A frame's sprites and counts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GhostFrame {
    pub sprites: Vec<Sprite>,
    pub stats: FrameStats,
}

/// Why the ghost system cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GhostError {
    #[error(transparent)]
    Paraxial(#[from] ParaxialError),
    #[error(transparent)]
    Path(#[from] PathError),
    #[error("stop scale {0} must be in (0, 1]")]
    StopScale(f64),
    #[error(
        "the lens is anamorphic (toroidal surfaces {surfaces:?}): {what} assumes a lens of revolution and does not \
         handle it yet; the paraxial flare, the ray-traced reference and ray grids, `flarelab trace` and \
         `flarelab lens info` do"
    )]
    Anamorphic { surfaces: Vec<usize>, what: &'static str },
}

impl GhostError {
    /// The refusal of an anamorphic lens by `what` (a method or a part), naming the lens's toroidal surfaces.
    pub fn anamorphic(lens: &Lens, what: &'static str) -> Self {
        Self::Anamorphic {
            surfaces: (0..lens.surfaces.len()).filter(|&k| lens.surfaces[k].is_toroidal()).collect(),
            what,
        }
    }
}

/// One ghost's paraxial sprites reduced to a frame: centre and half-size on the sensor (mm) and energy
/// (luminance of relative irradiance x mm^2). See [`GhostSystem::paraxial_frame`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ParaxialFrame {
    pub centre_mm: [f64; 2],
    pub half_mm: f64,
    pub energy: f64,
}

/// Every ghost of a lens with its matrices and reflectance tables: rebuilt on lens or settings edits.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostSystem {
    pub lens: Lens,
    pub first_order: FirstOrder,
    pub settings: GhostSettings,
    /// Stop radius at the chosen f-number.
    pub stop_radius_mm: f64,
    /// Clear semi-aperture of the first surface.
    pub front_radius_mm: f64,
    pub ghosts: Vec<GhostModel>,
    /// Image path per wavelength: landing of the ray through the stop centre per unit light slope.
    image_centre_per_slope: Vec<f64>,
    /// Image path per wavelength: the product of the transmittances (1 - R at normal incidence) of every
    /// refraction, what reaches the sensor of the light that enters (the front dirt's glow is dimmed by it).
    pub image_transmission: Vec<f64>,
    /// Image path at the spectrum's middle wavelength: `A` of the entrance-to-stop matrix, the stop's height
    /// per entrance height (its sign says whether the entrance pupil is the stop upright or turned over).
    pub image_stop_a: f64,
    /// Where the light itself images, by exact chief rays at the spectrum's middle wavelength.
    pub mapping: ImageMapping,
    /// Reflectance tables per (surface, arriving side, wavelength), shared by the ghosts.
    tables: InterfaceTables,
    /// Per (ghost, wavelength), ghost-major: the frame's coefficients.
    coefficients: Vec<FrameCoefficients>,
    /// Every sprite's clear-aperture discs, in the sprites' order ([`FrameCoefficients::discs`] indexes them).
    discs: Vec<Disc>,
    /// For an anamorphic lens, the ghosts of its x-z section ([`Lens::section`]) on the lens's sensor plane:
    /// every x quantity of a sprite comes from it, every y quantity from this system (whose matrices are then
    /// the y-z section's). `None` for a lens of revolution.
    pub x_section: Option<Box<GhostSystem>>,
}

impl GhostSystem {
    /// Builds every ghost of `lens` (which must be valid) for `settings`.
    ///
    /// Rather than multiplying each ghost's whole path, the products are shared: per wavelength, the
    /// forward products from the entrance to every surface, the products from every surface to the sensor
    /// and to the stop, and for each second reflection j one backward sweep that passes every first
    /// reflection i < j. Each ghost then costs a few 2x2 products (a test checks the result against
    /// [`PathMatrices::walk`] of the full path).
    pub fn build(lens: &Lens, settings: &GhostSettings) -> Result<Self, GhostError> {
        let first_order = FirstOrder::d_line(lens)?;
        if !lens.is_anamorphic() {
            let mut system = Self::build_with(lens, settings, first_order)?;
            system.set_redundancy();
            return Ok(system);
        }
        // Axis by axis: each section is a lens of revolution, its ghosts ending on this lens's sensor plane.
        let section = |s: Section| {
            let own = first_order.section(s);
            let z_last = own.total_track_mm - own.bfd_mm;
            let at_sensor = FirstOrder {
                total_track_mm: first_order.total_track_mm,
                bfd_mm: first_order.total_track_mm - z_last,
                sections: None,
                ..own.clone()
            };
            Self::build_with(&lens.section(s), settings, at_sensor)
        };
        let x = section(Section::X)?;
        let mut y = section(Section::Y)?;
        debug_assert!(x.ghosts.iter().zip(&y.ghosts).all(|(a, b)| (a.i, a.j) == (b.i, b.j)));
        y.lens = lens.clone();
        y.first_order = first_order;
        y.x_section = Some(Box::new(x));
        y.set_redundancy();
        Ok(y)
    }

    /// True for the ghosts of an anamorphic lens (elliptical sprites, a system per section).
    pub fn is_anamorphic(&self) -> bool {
        self.x_section.is_some()
    }

    /// The system that gives the x quantities of the sprites: the x-z section's for an anamorphic lens, this
    /// one otherwise.
    pub fn x_system(&self) -> &GhostSystem {
        self.x_section.as_deref().unwrap_or(self)
    }

    /// Ghost `g`'s image of the stop at wavelength `w` for light slope `u`: its centre and its semi-axes along x
    /// and y (mm on the sensor; equal for a lens of revolution). `None` when the stop's image is at infinity.
    pub fn stop_image_ellipse(&self, g: usize, w: usize, u: [f64; 2]) -> Option<([f64; 2], [f64; 2])> {
        let (cx, rx) = self.x_system().stop_image_sprite(g, w, u)?;
        let (cy, ry) = self.stop_image_sprite(g, w, u)?;
        Some(([cx[0], cy[1]], [rx, ry]))
    }

    /// [`Self::build`] of the lens of revolution `lens` with the first-order data `first_order` (whose sensor
    /// plane every path ends on).
    fn build_with(lens: &Lens, settings: &GhostSettings, first_order: FirstOrder) -> Result<Self, GhostError> {
        if !(settings.stop_scale > 0.0 && settings.stop_scale <= 1.0) {
            return Err(GhostError::StopScale(settings.stop_scale));
        }
        let sensor_z = first_order.sensor_z_mm();
        let z = lens.vertex_z_mm();
        let stop = lens.stop_index();
        let stop_radius_mm = lens.surfaces[stop].semi_aperture_mm * settings.stop_scale;
        let n_surfaces = lens.surfaces.len();
        let spectrum = &settings.spectrum;
        let n_w = spectrum.len();
        let pairs = lens.ghost_pairs();
        let curvature: Vec<f64> = lens.surfaces.iter().map(|s| s.vertex_curvature_per_mm()).collect();
        let tables = InterfaceTables::new(
            lens,
            settings.coating_override.as_ref(),
            &spectrum.wavelengths_nm,
            REFLECTANCE_SAMPLES,
        );
        let indices: Vec<Vec<f64>> = spectrum.wavelengths_nm.iter().map(|&w| lens.media_indices_at(w)).collect();
        let reflecting_surfaces = lens.reflecting_surfaces();
        let reflecting: Vec<bool> = (0..n_surfaces).map(|k| reflecting_surfaces.contains(&k)).collect();
        let mut ghosts: Vec<GhostModel> = pairs
            .iter()
            .map(|&(i, j)| GhostModel {
                i,
                j,
                straddles_stop: i < stop && stop < j,
                per_wavelength: Vec::with_capacity(n_w),
            })
            .collect();
        let ghost_index = |i: usize, j: usize| pairs.binary_search(&(i, j)).ok();
        let mut image_centre_per_slope = Vec::with_capacity(n_w);
        let mut image_transmission = Vec::with_capacity(n_w);
        let mut image_stop_a = Vec::with_capacity(n_w);
        for (w, &wavelength_nm) in spectrum.wavelengths_nm.iter().enumerate() {
            let transmittance = |k: usize, backward: bool| 1.0 - tables.table(tables.index(k, backward, w)).at(0.0);
            let system = Paraxial { z: &z, curvature: &curvature, n: &indices[w] };
            let sweeps = system.sweeps(stop, sensor_z);
            let Sweeps { arrive, to_sensor, .. } = &sweeps;
            let last = n_surfaces - 1;
            let image_f = to_sensor[last].mul(&system.forward(last)).mul(&arrive[last]);
            let image_a = arrive[stop];
            image_centre_per_slope.push(image_f.b - image_f.a * image_a.b / image_a.a);
            image_transmission.push((0..n_surfaces).map(|m| transmittance(m, false)).product::<f64>());
            image_stop_a.push(image_a.a);

            for j in 0..n_surfaces {
                if !reflecting[j] {
                    continue;
                }
                let at_j = arrive[j];
                // Reflect at j, then sweep back towards the entrance.
                let mut back = Mat2::reflection(curvature[j], 1.0).mul(&at_j);
                let mut backward_stop_crossing = None;
                for k in (0..j).rev() {
                    let at_k = system.gap(k + 1, k).mul(&back);
                    if k == stop {
                        // Just after the stop's interaction, as `PathMatrices::walk` records it (the heights
                        // are those on arrival: refraction and reflection keep them).
                        backward_stop_crossing = Some(system.backward(k).mul(&at_k));
                    }
                    if reflecting[k]
                        && let Some(g) = ghost_index(k, j)
                    {
                        let after_i = Mat2::reflection(curvature[k], -1.0).mul(&at_k);
                        let sensor_from_entrance = to_sensor[k].mul(&after_i);
                        let stop_from_entrance =
                            system.stop_crossings(&sweeps, stop, (k, j), after_i, backward_stop_crossing);
                        let last_crossing = *stop_from_entrance.last().expect("every path crosses the stop");
                        let sensor_from_stop = sensor_from_entrance.mul(&last_crossing.inverse());
                        // Refractions: forward 0..j, back j-1..=i+1, forward i+1..N.
                        let transmission = (0..j).map(|m| transmittance(m, false)).product::<f64>()
                            * (k + 1..j).map(|m| transmittance(m, true)).product::<f64>()
                            * (k + 1..n_surfaces).map(|m| transmittance(m, false)).product::<f64>();
                        ghosts[g].per_wavelength.push(GhostOptics {
                            wavelength_nm,
                            transmission,
                            matrices: PathMatrices { sensor_from_entrance, stop_from_entrance, sensor_from_stop },
                            incidence_j: Incidence::new(&at_j, curvature[j], 1.0),
                            incidence_i: Incidence::new(&at_k, curvature[k], -1.0),
                            reflectance_j: tables.index(j, false, w),
                            reflectance_i: tables.index(k, true, w),
                        });
                    }
                    back = system.backward(k).mul(&at_k);
                }
            }
        }
        let front_radius_mm = lens.surfaces[0].semi_aperture_mm;
        let middle = spectrum.wavelengths_nm.len() / 2;
        let mapping = ImageMapping::new(
            lens,
            first_order.entrance_pupil(),
            sensor_z,
            spectrum.wavelengths_nm[middle],
            image_centre_per_slope[middle],
        );
        let (discs, coefficients) = clear_apertures(lens, &ghosts, &indices, sensor_z, stop_radius_mm)?;
        Ok(Self {
            lens: lens.clone(),
            first_order,
            settings: settings.clone(),
            stop_radius_mm,
            front_radius_mm,
            ghosts,
            image_centre_per_slope,
            image_transmission,
            image_stop_a: image_stop_a[middle],
            mapping,
            tables,
            coefficients,
            discs,
            x_section: None,
        })
    }

    /// Where the light source itself images on the sensor (its starburst), for light slope `u`, at the
    /// spectrum's middle wavelength: the lens's own mapping by exact chief rays ([`ImageMapping`]), which near
    /// the axis is the paraxial `k u`.
    pub fn light_image_mm(&self, u: [f64; 2]) -> [f64; 2] {
        match &self.x_section {
            None => self.mapping.image_mm(u),
            // Each section's mapping along its own axis (exact on the axes; the sections' lenses of revolution
            // off them).
            Some(x) => [x.mapping.image_mm(u)[0], self.mapping.image_mm(u)[1]],
        }
    }

    /// Where the light's own beam crosses the entrance plane (the first vertex) for light slope `u`: its chief
    /// ray's crossing ([`ImageMapping::entrance_mm`]), each section's along its own axis for an anamorphic lens.
    pub fn light_entrance_mm(&self, u: [f64; 2]) -> [f64; 2] {
        match &self.x_section {
            None => self.mapping.entrance_mm(u),
            Some(x) => [x.mapping.entrance_mm(u)[0], self.mapping.entrance_mm(u)[1]],
        }
    }

    /// Lee & Eisemann's sprite of ghost `g` at wavelength `w`: the stop's opening imaged through the ghost
    /// path, centre = landing of the ray through the stop centre, radius = |rim landing - centre|. `None`
    /// when the stop's image through the front part is at infinity (A_a = 0).
    pub fn stop_image_sprite(&self, g: usize, w: usize, u: [f64; 2]) -> Option<([f64; 2], f64)> {
        let m = &self.ghosts[g].per_wavelength[w].matrices;
        let (f, a) = (m.sensor_from_entrance, m.stop_from_entrance[0]);
        if a.a == 0.0 {
            return None;
        }
        let k = f.b - f.a * a.b / a.a;
        Some(([k * u[0], k * u[1]], (f.a / a.a).abs() * self.stop_radius_mm))
    }

    /// The flare quad of the `k`-th sprite by four rays: the corners `E + rho (+-1, +-1)` of its entrance region's
    /// bounding square traced through M_f to the sensor, in the corner order (-,-), (+,-), (+,+), (-,+).
    /// Equal to `C + S (+-1, +-1)` unless the sprite was enlarged because it is focused.
    pub fn flare_quad_mm(&self, k: usize, u: [f64; 2]) -> [[f64; 2]; 4] {
        let sprite_ghost = self.coefficients[k].ghost as usize;
        let sprite_wavelength = self.coefficients[k].wavelength as usize;
        let f_of =
            |s: &GhostSystem| s.ghosts[sprite_ghost].per_wavelength[sprite_wavelength].matrices.sensor_from_entrance;
        let (fx, fy) = (f_of(self.x_system()), f_of(self));
        let region = self.sprite_masks(k, u).region;
        let (rho, e) = (region.scale, region.offset);
        [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|q| {
            let x0 = [e[0] + rho[0] * q[0], e[1] + rho[1] * q[1]];
            [fx.a * x0[0] + fx.b * u[0], fy.a * x0[1] + fy.b * u[1]]
        })
    }

    /// All sprites for the light slope vector `u` (tan of the field angles): the per-frame work.
    pub fn frame(&self, u: [f64; 2], settings: &FrameSettings) -> GhostFrame {
        let mut frame = GhostFrame {
            sprites: Vec::with_capacity(self.ghosts.len() * self.settings.spectrum.len()),
            ..Default::default()
        };
        self.frame_into(u, settings, &mut frame);
        frame
    }

    /// [`Self::frame`] with per-ghost gains (`gains[g]` multiplies ghost `g`; a ghost past the list has gain
    /// 1): the dim threshold is applied to the sprites as they will be drawn, gains included, so that what is
    /// culled stays below the threshold on screen. Issue 61: with every gain at 1000 the same 39 sprites were
    /// culled as dim as at gain 1, and at 0 EV with gain 1e6 every sprite was culled and the flare was black.
    pub fn frame_weighted(&self, u: [f64; 2], settings: &FrameSettings, gains: &[f32]) -> GhostFrame {
        let mut frame = GhostFrame {
            sprites: Vec::with_capacity(self.ghosts.len() * self.settings.spectrum.len()),
            ..Default::default()
        };
        self.frame_into_weighted(u, settings, gains, &mut frame);
        frame
    }

    /// [`Self::frame`] into an existing buffer (no allocation once warmed up).
    pub fn frame_into(&self, u: [f64; 2], settings: &FrameSettings, frame: &mut GhostFrame) {
        self.frame_into_weighted(u, settings, &[], frame);
    }

    /// [`Self::frame_weighted`] into an existing buffer.
    pub fn frame_into_weighted(&self, u: [f64; 2], settings: &FrameSettings, gains: &[f32], frame: &mut GhostFrame) {
        frame.sprites.clear();
        frame.stats = FrameStats::default();
        let u2 = u[0] * u[0] + u[1] * u[1];
        let u_len = u2.sqrt();
        let cos_theta = 1.0 / (1.0 + u2).sqrt();
        let (half_w, half_h) = (0.5 * settings.sensor.width_mm, 0.5 * settings.sensor.height_mm);
        let mut stats = FrameStats { sprites: self.coefficients.len(), ..FrameStats::default() };
        let weights = &self.settings.spectrum.weights_rgb;
        let clamp = |h: f64| {
            if h.abs() < settings.min_half_size_mm {
                settings.min_half_size_mm.copysign(if h == 0.0 { 1.0 } else { h })
            } else {
                h
            }
        };
        for (k, co) in self.coefficients.iter().enumerate() {
            let (centre, half_size, empty, irradiance) = match &self.x_section {
                None => {
                    let centre = [co.centre_per_slope * u[0], co.centre_per_slope * u[1]];
                    let (half_size, area_ratio) = if co.half_size_mm.abs() < settings.min_half_size_mm {
                        let clamped = clamp(co.half_size_mm);
                        (clamped, co.rho_squared / (clamped * clamped))
                    } else {
                        (co.half_size_mm, co.area_ratio)
                    };
                    let empty = u_len >= co.empty_from_slope;
                    let irradiance = if empty { 0.0 } else { self.irradiance(co, u2, cos_theta) * area_ratio };
                    (centre, [half_size; 2], empty, irradiance)
                }
                Some(x) => {
                    // Axis by axis: x from the x-z section, y from the y-z section. The entrance region is the
                    // box of the two sections' bounding intervals (rho_x, rho_y), mapped to the half-sizes
                    // (S_x, S_y): irradiance cos(theta) R_i R_j T rho_x rho_y / (S_x S_y), energy conserved. It is
                    // empty when either section's discs part (a box test: it never culls a lit ghost).
                    let cx = &x.coefficients[k];
                    let centre = [cx.centre_per_slope * u[0], co.centre_per_slope * u[1]];
                    let half_size = [clamp(cx.half_size_mm), clamp(co.half_size_mm)];
                    let empty = u[0].abs() >= cx.empty_from_slope || u[1].abs() >= co.empty_from_slope;
                    let area_ratio = (cx.rho_squared * co.rho_squared).sqrt() / (half_size[0] * half_size[1]).abs();
                    let irradiance =
                        if empty { 0.0 } else { self.irradiance_per_axis([cx, co], u, cos_theta) * area_ratio };
                    (centre, half_size, empty, irradiance)
                }
            };
            let weight = weights[co.wavelength as usize];
            let rgb = [
                (weight[0] * irradiance).max(0.0),
                (weight[1] * irradiance).max(0.0),
                (weight[2] * irradiance).max(0.0),
            ];
            let extent = half_size.map(|h| h.abs() * std::f64::consts::SQRT_2);
            let culled = if empty {
                stats.empty_entrance_region += 1;
                Some(CullReason::EmptyEntranceRegion)
            } else if centre[0].abs() - extent[0] > half_w || centre[1].abs() - extent[1] > half_h {
                stats.off_sensor += 1;
                Some(CullReason::OffSensor)
            } else {
                None
            };
            frame.sprites.push(Sprite {
                ghost: co.ghost as usize,
                wavelength: co.wavelength as usize,
                centre_mm: centre,
                half_size_mm: half_size,
                irradiance,
                rgb,
                culled,
            });
        }
        // The dimmest sprites are culled together: all those below the level at which their peaks sum to the
        // threshold, so that everything culled adds at most the threshold to any pixel. (Culling each sprite
        // below the threshold on its own lost a visible haze on a 28-surface lens, whose hundreds of faint
        // ghosts overlap.) The level is found by bisection, without sorting or allocating.
        let gain = |s: &Sprite| gains.get(s.ghost).map_or(1.0, |&g| f64::from(g).max(0.0));
        let peak = |s: &Sprite| s.rgb[0].max(s.rgb[1]).max(s.rgb[2]) * gain(s);
        let threshold = settings.intensity_threshold;
        let culled_sum = |level: f64| -> f64 {
            frame.sprites.iter().filter(|s| s.culled.is_none() && peak(s) < level).map(peak).sum()
        };
        let level = if threshold.is_nan() || threshold <= 0.0 {
            0.0
        } else if culled_sum(threshold) <= threshold {
            threshold
        } else {
            let (mut lo, mut hi) = (0.0, threshold);
            for _ in 0..48 {
                let mid = 0.5 * (lo + hi);
                if culled_sum(mid) <= threshold {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        for sprite in frame.sprites.iter_mut().filter(|s| s.culled.is_none()) {
            if peak(sprite) < level {
                sprite.culled = Some(CullReason::BelowThreshold);
                stats.below_threshold += 1;
            } else {
                stats.drawn += 1;
            }
        }
        frame.stats = stats;
    }

    /// [`Self::irradiance`] of an anamorphic lens's sprite: each reflection's paraxial angle of incidence has an
    /// x part from the x-z section (`co[0]`) and a y part from the y-z section (`co[1]`), their squares added.
    fn irradiance_per_axis(&self, co: [&FrameCoefficients; 2], u: [f64; 2], cos_theta: f64) -> f64 {
        let sin2_of = |per_axis: [f64; 2]| {
            let t2 = per_axis[0] * u[0] * u[0] + per_axis[1] * u[1] * u[1];
            t2 / (1.0 + t2)
        };
        let r_j = self.tables.table(co[1].reflectance_j as usize).at(sin2_of([co[0].incidence2_j, co[1].incidence2_j]));
        let r_i = self.tables.table(co[1].reflectance_i as usize).at(sin2_of([co[0].incidence2_i, co[1].incidence2_i]));
        cos_theta * r_i * r_j * co[1].transmission
    }

    /// A sprite's irradiance before its area ratio: cos(theta) x R_i x R_j x T at the paraxial angles of
    /// incidence for `u2` = |u|^2.
    fn irradiance(&self, co: &FrameCoefficients, u2: f64, cos_theta: f64) -> f64 {
        // The paraxial angle is taken as a tangent t, so sin^2 = t^2 / (1 + t^2) stays below 1.
        let sin2_of = |angle2_per_slope2: f64| {
            let t2 = angle2_per_slope2 * u2;
            t2 / (1.0 + t2)
        };
        let r_j = self.tables.table(co.reflectance_j as usize).at(sin2_of(co.incidence2_j));
        let r_i = self.tables.table(co.reflectance_i as usize).at(sin2_of(co.incidence2_i));
        cos_theta * r_i * r_j * co.transmission
    }

    /// Ghost `g`'s paraxial sprites summed over the spectrum for light slope `u`, with no culling: the frame a
    /// LUT ghost is fitted to ([`crate::lut`]). The centre and half-size are averaged over the wavelengths with
    /// their luminance weights (the half-size at least `min_half_mm`); the energy is the luminance of
    /// irradiance x sprite area, before any vignetting by a clear aperture or the stop (0 when the entrance region
    /// is empty).
    pub fn paraxial_frame(&self, g: usize, u: [f64; 2], min_half_mm: f64) -> ParaxialFrame {
        let u2 = u[0] * u[0] + u[1] * u[1];
        let cos_theta = 1.0 / (1.0 + u2).sqrt();
        let nw = self.settings.spectrum.len();
        let (mut weight_sum, mut centre, mut half, mut energy) = (0.0, [0.0; 2], 0.0, 0.0);
        for (w, co) in self.coefficients[g * nw..(g + 1) * nw].iter().enumerate() {
            let luma = crate::metrics::luminance(self.settings.spectrum.weights_rgb[w]);
            weight_sum += luma;
            match &self.x_section {
                None => {
                    centre =
                        [centre[0] + luma * co.centre_per_slope * u[0], centre[1] + luma * co.centre_per_slope * u[1]];
                    half += luma * co.half_size_mm.abs();
                    if u2.sqrt() < co.empty_from_slope {
                        // irradiance x (2 half)^2 = irradiance per unit area ratio x 4 rho^2.
                        energy += luma * self.irradiance(co, u2, cos_theta) * 4.0 * co.rho_squared;
                    }
                }
                Some(x) => {
                    // An anamorphic ghost: its centre per axis, the larger semi-axis (the square a LUT entry
                    // is fitted in holds the ellipse), the energy through the box of the two sections.
                    let cx = &x.coefficients[g * nw + w];
                    centre =
                        [centre[0] + luma * cx.centre_per_slope * u[0], centre[1] + luma * co.centre_per_slope * u[1]];
                    half += luma * cx.half_size_mm.abs().max(co.half_size_mm.abs());
                    if u[0].abs() < cx.empty_from_slope && u[1].abs() < co.empty_from_slope {
                        let rho_area = (cx.rho_squared * co.rho_squared).sqrt();
                        energy += luma * self.irradiance_per_axis([cx, co], u, cos_theta) * 4.0 * rho_area;
                    }
                }
            }
        }
        let weight_sum = weight_sum.max(1e-300);
        let frame = ParaxialFrame {
            centre_mm: centre.map(|c| c / weight_sum),
            half_mm: (half / weight_sum).max(min_half_mm),
            energy,
        };
        if frame.centre_mm.iter().all(|c| c.is_finite()) && frame.half_mm.is_finite() && frame.energy.is_finite() {
            frame
        } else {
            ParaxialFrame { centre_mm: [0.0; 2], half_mm: min_half_mm, energy: 0.0 }
        }
    }

    /// The surfaces whose clear apertures cut lens ghost `g`'s sprites (every wavelength's) at light slope `u`
    /// (`surfaces_cutting` of their [`Self::sprite_masks`]).
    pub fn cutting_surfaces(&self, g: usize, u: [f64; 2]) -> Vec<usize> {
        let wavelengths = self.settings.spectrum.len();
        surfaces_cutting((g * wavelengths..(g + 1) * wavelengths).map(|k| self.sprite_masks(k, u)))
    }

    /// The masks of the `k`-th sprite of a frame (sprites come ghost by ghost, wavelength by wavelength) for
    /// light slope `u`: computed only for the sprites that are drawn. Of the sprite's clear-aperture discs, those
    /// that hold another of its discs at this light (`Disc::redundant_below_slope`) or the whole quad cannot
    /// cut and are left out; when more than `MAX_DISCS` remain, those that cut the most points of a 16 x 16 grid
    /// over the quad are kept, one by one.
    pub fn sprite_masks(&self, k: usize, u: [f64; 2]) -> SpriteMasks {
        // x from the x-z section's coefficients (the same ones for a lens of revolution), y from these.
        let (xs, cx, co) = (self.x_system(), &self.x_system().coefficients[k], &self.coefficients[k]);
        let map = |scale: [f64; 2], per_slope: [f64; 2]| MaskMap {
            scale,
            offset: [per_slope[0] * u[0], per_slope[1] * u[1]],
        };
        let stop = |i: usize| {
            map([cx.stop_scale[i], co.stop_scale[i]], [cx.stop_offset_per_slope[i], co.stop_offset_per_slope[i]])
        };
        let rho = [cx.rho_mm, co.rho_mm];
        let e = [cx.e_per_slope * u[0], co.e_per_slope * u[1]];
        let mut masks = SpriteMasks {
            stop_maps: [stop(0), stop(1), stop(2)],
            stop_count: co.stop_count as usize,
            disc_maps: [MaskMap { scale: [0.0; 2], offset: [0.0; 2] }; MAX_DISCS],
            disc_surfaces: [0; MAX_DISCS],
            disc_count: 0,
            discs_left_out: 0,
            region: MaskMap { scale: rho, offset: e },
        };
        let slope = u[0].hypot(u[1]);
        let range = co.discs.start as usize..co.discs.end as usize;
        let mut cutting: Vec<(MaskMap, usize)> = Vec::new();
        for (a, b) in xs.discs[range.clone()].iter().zip(&self.discs[range]) {
            // (A NaN threshold never drops a disc.)
            let redundant = slope < b.redundant_below_slope;
            if redundant || !(a.radius_mm.is_finite() && b.radius_mm.is_finite()) {
                continue;
            }
            let disc = disc_map([a, b], &masks.region, u);
            if map_reach(&disc) > 1.0 {
                cutting.push((disc, b.surface));
            }
        }
        if cutting.len() > MAX_DISCS {
            // More discs may cut than a sprite carries: keep those that cut the most, greedily, judged on a grid
            // of 16 x 16 points of the quad (cell centres) inside every stop crossing's circle. A disc that cuts
            // none of the points the kept ones leave is dropped as not cutting, unless a slot is free; any other is left out.
            const SIDE: usize = 16;
            type Points = [u64; SIDE * SIDE / 64];
            let inside = |m: &MaskMap, q: [f64; 2]| {
                let p = m.at(q);
                p[0] * p[0] + p[1] * p[1] <= 1.0
            };
            let point = |i: usize| {
                let at = |k: usize| (k as f64 + 0.5) * 2.0 / SIDE as f64 - 1.0;
                [at(i % SIDE), at(i / SIDE)]
            };
            let set = |test: &dyn Fn([f64; 2]) -> bool| -> Points {
                let mut bits = [0u64; SIDE * SIDE / 64];
                for i in 0..SIDE * SIDE {
                    if test(point(i)) {
                        bits[i / 64] |= 1 << (i % 64);
                    }
                }
                bits
            };
            let and_count = |a: &Points, b: &Points| a.iter().zip(b).map(|(x, y)| (x & y).count_ones()).sum::<u32>();
            let mut alive = set(&|q| masks.stops().iter().all(|m| inside(m, q)));
            let outside: Vec<Points> = cutting.iter().map(|(m, _)| set(&|q| !inside(m, q))).collect();
            let mut kept = Vec::with_capacity(MAX_DISCS);
            while kept.len() < MAX_DISCS {
                let best = (0..cutting.len())
                    .filter(|k| !kept.contains(k))
                    .max_by_key(|&k| (and_count(&outside[k], &alive), std::cmp::Reverse(k)));
                match best {
                    Some(k) if and_count(&outside[k], &alive) > 0 => {
                        for (a, o) in alive.iter_mut().zip(&outside[k]) {
                            *a &= !o;
                        }
                        kept.push(k);
                    }
                    _ => break,
                }
            }
            masks.discs_left_out =
                (0..cutting.len()).filter(|k| !kept.contains(k) && and_count(&outside[*k], &alive) > 0).count();
            // Free slots take the discs that cut between the points (slivers at the region's edge), those whose
            // edges come closest to the region's centre, relative to its size, first.
            let gap = |m: &MaskMap| (1.0 - m.offset[0].hypot(m.offset[1])) / m.scale[0].abs().max(m.scale[1].abs());
            let mut rest: Vec<usize> = (0..cutting.len()).filter(|k| !kept.contains(k)).collect();
            rest.sort_by(|&a, &b| gap(&cutting[a].0).total_cmp(&gap(&cutting[b].0)));
            kept.extend(rest.into_iter().take(MAX_DISCS - kept.len()));
            cutting = kept.into_iter().map(|k| cutting[k]).collect();
        }
        masks.disc_count = cutting.len();
        for (slot, (map, surface)) in cutting.into_iter().enumerate() {
            masks.disc_maps[slot] = map;
            masks.disc_surfaces[slot] = surface;
        }
        masks
    }

    /// Sets each clear-aperture disc's [`Disc::redundant_below_slope`] from the discs of the same sprite (x
    /// quantities from `self.x_system()`, y from `self`): disc k holds disc m while `|u| < (1 - max(a, b)) /
    /// max(|alpha|, |beta|)`, where in k's own units m's centre lies at `(alpha u_x, beta u_y)` and its
    /// semi-axes are `(a, b)` (a sufficient condition; exact for a lens of revolution, where it reads `|u| <
    /// (r_k - r_m) / |c_k - c_m|`). The stop's circles at its crossings are discs m too. Of two equal discs the
    /// later one is redundant, never both.
    fn set_redundancy(&mut self) {
        let nw = self.settings.spectrum.len();
        let mut thresholds = vec![0.0f64; self.discs.len()];
        {
            let xs = self.x_system();
            for (k, cy) in self.coefficients.iter().enumerate() {
                let (g, w) = (k / nw.max(1), k % nw.max(1));
                // Every disc of this sprite as (centre x, centre y, radius x, radius y, is a clear aperture).
                let mut all: Vec<([f64; 2], [f64; 2], Option<usize>)> = Vec::new();
                let range = cy.discs.start as usize..cy.discs.end as usize;
                for (i, (a, b)) in xs.discs[range.clone()].iter().zip(&self.discs[range.clone()]).enumerate() {
                    all.push((
                        [a.centre_per_slope, b.centre_per_slope],
                        [a.radius_mm, b.radius_mm],
                        Some(range.start + i),
                    ));
                }
                let stops = |s: &GhostSystem| -> Vec<(f64, f64)> {
                    let r_a = s.stop_radius_mm;
                    s.ghosts[g].per_wavelength[w]
                        .matrices
                        .stop_from_entrance
                        .iter()
                        .map(|m| {
                            let (centre, radius, _) = entrance_disc(m, r_a);
                            (centre, radius)
                        })
                        .collect()
                };
                for (a, b) in stops(xs).into_iter().zip(stops(self)) {
                    all.push(([a.0, b.0], [a.1, b.1], None));
                }
                for (ki, (ck, rk, index)) in all.iter().enumerate() {
                    let Some(index) = *index else { continue };
                    if !(rk[0].is_finite() && rk[1].is_finite()) {
                        thresholds[index] = f64::INFINITY;
                        continue;
                    }
                    let mut best = 0.0f64;
                    for (mi, (cm, rm, _)) in all.iter().enumerate() {
                        if mi == ki || !(rm[0].is_finite() && rm[1].is_finite()) {
                            continue;
                        }
                        let (a, b) = (rm[0] / rk[0], rm[1] / rk[1]);
                        let (alpha, beta) = ((cm[0] - ck[0]) / rk[0], (cm[1] - ck[1]) / rk[1]);
                        let size = a.max(b);
                        let spread = alpha.abs().max(beta.abs());
                        let s = if spread == 0.0 {
                            // Concentric: held at every light, or never; of two equal discs the later goes.
                            if size < 1.0 || (size == 1.0 && a == b && mi < ki) { f64::INFINITY } else { 0.0 }
                        } else {
                            (1.0 - size) / spread
                        };
                        best = best.max(s);
                    }
                    thresholds[index] = best;
                }
            }
        }
        for (disc, t) in self.discs.iter_mut().zip(thresholds) {
            disc.redundant_below_slope = t;
        }
    }
}

/// One wavelength's paraxial system ([`GhostSystem::build_with`]): the vertices' z, the vertex curvatures and
/// the media's indices (medium k before surface k).
struct Paraxial<'a> {
    z: &'a [f64],
    curvature: &'a [f64],
    n: &'a [f64],
}

/// The sweeps every ghost path of one wavelength is made of ([`Paraxial::sweeps`]).
struct Sweeps {
    /// `arrive[k]`: entrance -> arriving at surface k travelling forward.
    arrive: Vec<Mat2>,
    /// `to_sensor[k]`: leaving surface k forward (after its interaction) -> sensor.
    to_sensor: Vec<Mat2>,
    /// `to_stop[k]`: leaving surface k forward -> arriving at the stop (k < stop).
    to_stop: Vec<Mat2>,
}

impl Paraxial<'_> {
    /// The gap between surfaces `a` and `b`.
    fn gap(&self, a: usize, b: usize) -> Mat2 {
        Mat2::translation((self.z[a] - self.z[b]).abs())
    }

    /// Refraction at surface `k` travelling forward.
    fn forward(&self, k: usize) -> Mat2 {
        Mat2::refraction(self.curvature[k], self.n[k], self.n[k + 1], 1.0)
    }

    /// Refraction at surface `k` travelling backward.
    fn backward(&self, k: usize) -> Mat2 {
        Mat2::refraction(self.curvature[k], self.n[k + 1], self.n[k], -1.0)
    }

    /// The forward sweeps from the entrance to each surface, from each surface to the sensor at `sensor_z`
    /// and from each surface before the stop to the stop.
    fn sweeps(&self, stop: usize, sensor_z: f64) -> Sweeps {
        let n_surfaces = self.curvature.len();
        let mut arrive = Vec::with_capacity(n_surfaces);
        let mut m = Mat2::IDENTITY;
        for k in 0..n_surfaces {
            if k > 0 {
                m = self.gap(k, k - 1).mul(&self.forward(k - 1).mul(&m));
            }
            arrive.push(m);
        }
        let last = n_surfaces - 1;
        let mut to_sensor = vec![Mat2::IDENTITY; n_surfaces];
        to_sensor[last] = Mat2::translation((sensor_z - self.z[last]).abs());
        for k in (0..last).rev() {
            to_sensor[k] = to_sensor[k + 1].mul(&self.forward(k + 1)).mul(&self.gap(k + 1, k));
        }
        let mut to_stop = vec![Mat2::IDENTITY; n_surfaces];
        for k in (0..stop).rev() {
            to_stop[k] = if k + 1 == stop {
                self.gap(stop, k)
            } else {
                to_stop[k + 1].mul(&self.forward(k + 1)).mul(&self.gap(k + 1, k))
            };
        }
        Sweeps { arrive, to_sensor, to_stop }
    }

    /// The stop's crossings along ghost `(i, j)` in path order, each just after its interaction there: going
    /// forward to j (a reflection when the stop is surface j itself), coming back (`back_crossing`, or
    /// `after_i`, the reflection, when the stop is surface i), and going forward again after i.
    fn stop_crossings(
        &self,
        sweeps: &Sweeps,
        stop: usize,
        (i, j): (usize, usize),
        after_i: Mat2,
        back_crossing: Option<Mat2>,
    ) -> Vec<Mat2> {
        let mut crossings = Vec::with_capacity(3);
        if stop < j {
            crossings.push(self.forward(stop).mul(&sweeps.arrive[stop]));
        } else if stop == j {
            crossings.push(Mat2::reflection(self.curvature[j], 1.0).mul(&sweeps.arrive[stop]));
        }
        if let Some(crossing) = back_crossing {
            crossings.push(if i == stop { after_i } else { crossing });
        }
        if i < stop {
            crossings.push(self.forward(stop).mul(&sweeps.to_stop[i].mul(&after_i)));
        }
        crossings
    }
}

/// Every crossing of a clear aperture (a surface other than the stop) along each ghost path, per wavelength:
/// its disc in the entrance plane, from the entrance-to-arrival matrix (heights on arrival); and each
/// (ghost, wavelength)'s frame coefficients, which index those discs.
fn clear_apertures(
    lens: &Lens,
    ghosts: &[GhostModel],
    indices: &[Vec<f64>],
    sensor_z: f64,
    stop_radius_mm: f64,
) -> Result<(Vec<Disc>, Vec<FrameCoefficients>), GhostError> {
    let (z, stop) = (lens.vertex_z_mm(), lens.stop_index());
    let mut discs = Vec::new();
    let mut coefficients = Vec::with_capacity(ghosts.len() * indices.len());
    for (g, ghost) in ghosts.iter().enumerate() {
        let path = LightPath::ghost(lens, ghost.i, ghost.j)?;
        for (w, optics) in ghost.per_wavelength.iter().enumerate() {
            let first = discs.len();
            PathMatrices::walk(lens, &z, &indices[w], &path, sensor_z, |step, m| {
                let surface = path.steps[step].surface;
                if surface != stop {
                    discs.push(Disc::new(surface, m, lens.surfaces[surface].semi_aperture_mm));
                }
            });
            coefficients.push(FrameCoefficients::new(g, w, optics, stop_radius_mm, &discs[first..], first));
        }
    }
    Ok((discs, coefficients))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::LightPath;
    use crate::optics::library::{builtin_lens, ids, synthetic_lens, with_stop_on_front_surface};

    #[test]
    fn shared_products_equal_each_ghost_path_multiplied_out() {
        let mut lenses: Vec<Lens> = ids().into_iter().map(|id| builtin_lens(id).unwrap()).collect();
        lenses.push(synthetic_lens(26));
        // Stops on lens surfaces: ghosts that reflect at the stop cross it twice.
        for id in ["tessar", "heliar", "dgauss"] {
            lenses.push(with_stop_on_front_surface(&builtin_lens(id).unwrap()).unwrap());
        }
        // Rounding, relative to the matrix's largest entry: an entry that is a small difference of large products
        // (d of the 57-surface anamorphic's ghost 0-26, 0.90 from terms of |b c| ~ 0.8 with b = 85 mm, 81 mm of
        // air in the path) carries the products' rounding, 2.5e-11 there.
        let close = |a: &Mat2, b: &Mat2| {
            let (a, b) = (a.as_rows(), b.as_rows());
            let scale = 1.0 + b.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            (0..2).all(|r| (0..2).all(|c| (a[r][c] - b[r][c]).abs() <= 1e-11 * scale))
        };
        for lens in &lenses {
            let s = GhostSystem::build(lens, &GhostSettings::default()).unwrap();
            let z = lens.vertex_z_mm();
            for ghost in &s.ghosts {
                let path = LightPath::ghost(lens, ghost.i, ghost.j).unwrap();
                assert_eq!(ghost.straddles_stop, path.straddles_stop(lens));
                for optics in &ghost.per_wavelength {
                    let n = lens.media_indices_at(optics.wavelength_nm);
                    let walked = PathMatrices::walk(lens, &z, &n, &path, s.first_order.sensor_z_mm(), |_, _| {});
                    let ours = &optics.matrices;
                    let what = format!("{} ghost ({}, {}) at {} nm", lens.id, ghost.i, ghost.j, optics.wavelength_nm);
                    assert!(
                        close(&ours.sensor_from_entrance, &walked.sensor_from_entrance),
                        "{what}: {:?} vs {:?}",
                        ours.sensor_from_entrance,
                        walked.sensor_from_entrance
                    );
                    assert_eq!(ours.stop_from_entrance.len(), walked.stop_from_entrance.len(), "{what}");
                    for (a, b) in ours.stop_from_entrance.iter().zip(&walked.stop_from_entrance) {
                        assert!(close(a, b), "{what}: {a:?} vs {b:?}");
                    }
                    assert!(
                        close(&ours.sensor_from_stop, &walked.sensor_from_stop),
                        "{what}: {:?} vs {:?}",
                        ours.sensor_from_stop,
                        walked.sensor_from_stop
                    );
                }
            }
        }
    }

    fn system(id: &str) -> GhostSystem {
        GhostSystem::build(&builtin_lens(id).unwrap(), &GhostSettings::default()).unwrap()
    }

    /// The discs a sprite carries cut what all of its clear apertures cut: on a 64 x 64 grid of each drawn
    /// sprite's quad (inside its stop circles), the points inside every one of the ghost's discs are those inside
    /// the kept ones, for all but a sliver; the light the sprites carry (irradiance x lit share) within 2 % over a
    /// frame. Every disc kept cuts the quad, and none holds another disc at that light.
    #[test]
    fn the_discs_kept_cut_what_every_clear_aperture_cuts() {
        let inside = |m: &MaskMap, q: [f64; 2]| {
            let p = m.at(q);
            p[0] * p[0] + p[1] * p[1] <= 1.0
        };
        for id in ["nikon_zoom_28_75mm", "pbrt_dgauss_50mm", "heliar"] {
            let s = system(id);
            for light in [[0.02, 0.01], [0.15, 0.08], [0.28, 0.16]] {
                let frame = s.frame(light, &FrameSettings { intensity_threshold: 0.0, ..FrameSettings::default() });
                let (mut all_light, mut kept_light, mut cut_sprites) = (0.0, 0.0, 0);
                for (k, sprite) in frame.sprites.iter().enumerate().filter(|(_, sp)| sp.culled.is_none()) {
                    let masks = s.sprite_masks(k, light);
                    let co = &s.coefficients[k];
                    let every: Vec<MaskMap> = s.discs[co.discs.start as usize..co.discs.end as usize]
                        .iter()
                        .filter(|d| d.radius_mm.is_finite())
                        .map(|d| disc_map([d, d], &masks.region, light))
                        .collect();
                    for disc in masks.discs() {
                        assert!(map_reach(disc) > 1.0, "{id}: a kept disc cuts the quad");
                    }
                    let (mut n_all, mut n_kept, mut n) = (0usize, 0usize, 0usize);
                    for i in 0..64 * 64 {
                        let q = [((i % 64) as f64 + 0.5) / 32.0 - 1.0, ((i / 64) as f64 + 0.5) / 32.0 - 1.0];
                        if !masks.stops().iter().all(|m| inside(m, q)) {
                            continue;
                        }
                        n += 1;
                        n_all += usize::from(every.iter().all(|m| inside(m, q)));
                        n_kept += usize::from(masks.discs().iter().all(|m| inside(m, q)));
                    }
                    assert!(n_kept >= n_all, "{id}: the kept discs cut no more than all of them");
                    let peak = sprite.rgb[0].max(sprite.rgb[1]).max(sprite.rgb[2]);
                    all_light += peak * n_all as f64 / n.max(1) as f64;
                    kept_light += peak * n_kept as f64 / n.max(1) as f64;
                    cut_sprites += usize::from(masks.disc_count > 0 && n_all < n);
                    assert!(
                        (n_kept - n_all) as f64 <= 0.03 * n as f64 + 2.0,
                        "{id} at {light:?}, sprite {k}: {n_kept} points kept against {n_all} inside every disc of {n}"
                    );
                }
                assert!(kept_light <= all_light * 1.02 && kept_light >= all_light, "{id}: {kept_light} vs {all_light}");
                if light[0] > 0.1 {
                    assert!(cut_sprites > 5, "{id} at {light:?}: only {cut_sprites} sprites are cut");
                }
            }
        }
    }

    #[test]
    fn every_ghost_is_enumerated_and_straddling_ones_are_kept() {
        let s = system("heliar");
        assert_eq!(s.ghosts.len(), 28);
        assert_eq!(s.ghosts.iter().filter(|g| g.straddles_stop).count(), 15);
        let frame = s.frame([0.0, 0.1], &FrameSettings::default());
        assert_eq!(frame.sprites.len(), 28 * 3);
        let st = frame.stats;
        assert_eq!(st.drawn + st.below_threshold + st.off_sensor + st.empty_entrance_region, st.sprites);
        for (k, sprite) in frame.sprites.iter().enumerate() {
            let ghost = &s.ghosts[sprite.ghost];
            assert_eq!(s.sprite_masks(k, [0.0, 0.1]).stops().len(), if ghost.straddles_stop { 3 } else { 1 });
            assert!(sprite.irradiance.is_finite() && sprite.irradiance >= 0.0);
            assert!(sprite.half_size_mm[0].is_finite() && sprite.half_size_mm[0] != 0.0);
        }
    }

    #[test]
    fn the_flare_quad_is_where_four_corner_rays_land() {
        let s = system("dgauss");
        let u = [0.05, -0.12];
        let settings = FrameSettings::default();
        let frame = s.frame(u, &settings);
        let mut checked = 0;
        for (k, sprite) in
            frame.sprites.iter().enumerate().filter(|(_, s)| s.half_size_mm[0].abs() > settings.min_half_size_mm)
        {
            let quad = s.flare_quad_mm(k, u);
            for (k, q) in [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].iter().enumerate() {
                let expected = [
                    sprite.centre_mm[0] + sprite.half_size_mm[0] * q[0],
                    sprite.centre_mm[1] + sprite.half_size_mm[0] * q[1],
                ];
                assert!((quad[k][0] - expected[0]).abs() < 1e-9 && (quad[k][1] - expected[1]).abs() < 1e-9);
            }
            // Centre and rim: two rays give the same circle.
            let rim = [(quad[1][0] + quad[2][0]) / 2.0, (quad[1][1] + quad[2][1]) / 2.0];
            assert!(((rim[0] - sprite.centre_mm[0]).abs() - sprite.half_size_mm[0].abs()).abs() < 1e-9);
            checked += 1;
        }
        assert!(checked > 100, "{checked}");
    }

    #[test]
    fn focused_ghosts_keep_finite_bounded_energy() {
        let s = system("tessar");
        let settings = FrameSettings::default();
        for u in [[0.0, 0.0], [0.3, 0.0], [0.0, -0.6], [2.0, 2.0]] {
            for (k, sprite) in s.frame(u, &settings).sprites.into_iter().enumerate() {
                assert!(sprite.half_size_mm[0].abs() >= settings.min_half_size_mm);
                let rho = s.sprite_masks(k, u).region.scale[0];
                let energy = sprite.irradiance * sprite.half_size_mm[0].powi(2);
                assert!(energy <= rho * rho * 1.0001, "energy never exceeds what enters: {energy} vs {}", rho * rho);
                assert!(sprite.rgb.iter().all(|c| c.is_finite() && *c >= 0.0));
            }
        }
    }

    /// Issue 61: the dim threshold ignored the ghosts' gains. Now a gain of 1000 draws ghosts that were dim at
    /// gain 1, a gain of 0 culls them, and what is culled stays under the threshold as drawn (gains applied).
    #[test]
    fn the_dim_threshold_sees_the_ghosts_gains() {
        let s = system("nikon_zoom_28_75mm");
        let settings = FrameSettings { intensity_threshold: 1e-5, ..FrameSettings::default() };
        let u = [0.0, 0.1];
        let plain = s.frame(u, &settings);
        assert!(plain.stats.below_threshold > 0, "{:?}", plain.stats);
        let loud = s.frame_weighted(u, &settings, &vec![1000.0; s.ghosts.len()]);
        assert!(loud.stats.below_threshold < plain.stats.below_threshold, "{:?} vs {:?}", loud.stats, plain.stats);
        let as_drawn = |sp: &Sprite| sp.rgb[0].max(sp.rgb[1]).max(sp.rgb[2]) * 1000.0;
        let culled: f64 =
            loud.sprites.iter().filter(|sp| sp.culled == Some(CullReason::BelowThreshold)).map(as_drawn).sum();
        assert!(culled <= settings.intensity_threshold, "culled as drawn: {culled}");
        let silent = s.frame_weighted(u, &settings, &vec![0.0; s.ghosts.len()]);
        assert_eq!(silent.stats.drawn, 0, "{:?}", silent.stats);
        // A ghost past the list keeps gain 1: the empty list is the plain frame.
        assert_eq!(s.frame_weighted(u, &settings, &[]).stats, plain.stats);
    }

    #[test]
    fn culled_sprites_together_stay_under_the_threshold() {
        // The 28-surface Nikon zoom: hundreds of faint ghosts overlap, so culling each one under the threshold
        // on its own would take many thresholds' worth of light from the middle of the frame.
        let s = system("nikon_zoom_28_75mm");
        let peak = |sp: &Sprite| sp.rgb[0].max(sp.rgb[1]).max(sp.rgb[2]);
        for threshold in [1e-6, 1e-5, 1e-4] {
            let settings = FrameSettings { intensity_threshold: threshold, ..FrameSettings::default() };
            let frame = s.frame([0.0, 0.1], &settings);
            let culled: Vec<f64> =
                frame.sprites.iter().filter(|sp| sp.culled == Some(CullReason::BelowThreshold)).map(peak).collect();
            let drawn: Vec<f64> = frame.sprites.iter().filter(|sp| sp.culled.is_none()).map(peak).collect();
            assert_eq!(culled.len(), frame.stats.below_threshold);
            assert!(!culled.is_empty() && !drawn.is_empty(), "{threshold}: {:?}", frame.stats);
            let sum: f64 = culled.iter().sum();
            assert!(sum <= threshold, "{threshold}: culled sprites add up to {sum}");
            // The faintest go first, and as many as fit: the dimmest drawn sprite would break the bound.
            let brightest_culled = culled.iter().copied().fold(0.0, f64::max);
            let dimmest_drawn = drawn.iter().copied().fold(f64::INFINITY, f64::min);
            assert!(brightest_culled <= dimmest_drawn);
            assert!(dimmest_drawn >= threshold || sum + dimmest_drawn > threshold * (1.0 - 1e-9));
            // Culling each sprite on its own would have taken far more.
            let alone: f64 = frame
                .sprites
                .iter()
                .filter(|sp| sp.culled != Some(CullReason::EmptyEntranceRegion))
                .map(peak)
                .filter(|&p| p < threshold)
                .sum();
            assert!(alone > sum, "{threshold}: {alone} vs {sum}");
        }
    }

    #[test]
    fn culling_reports_reasons() {
        let s = system("wide");
        let tiny_sensor =
            FrameSettings { sensor: Sensor { width_mm: 0.5, height_mm: 0.5 }, ..FrameSettings::default() };
        let frame = s.frame([0.0, 0.4], &tiny_sensor);
        assert!(frame.stats.off_sensor > 0, "{:?}", frame.stats);
        let strict = FrameSettings { intensity_threshold: 1.0, ..FrameSettings::default() };
        let frame = s.frame([0.0, 0.0], &strict);
        assert_eq!(frame.stats.drawn, 0);
        assert_eq!(
            frame.stats.below_threshold + frame.stats.empty_entrance_region + frame.stats.off_sensor,
            frame.stats.sprites
        );
        // At a steep angle some ghosts' entrance discs no longer meet the front lens.
        let frame = s.frame([0.0, 1.2], &FrameSettings::default());
        assert!(frame.stats.empty_entrance_region > 0, "{:?}", frame.stats);
    }
}
