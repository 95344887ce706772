//! Paraxial ghosts (KR 10-1465658; Lee & Eisemann 2013): every two-reflection ghost as a sprite per
//! wavelength, rebuilt when the lens changes and moved per frame by the light direction alone.
//!
//! # How it works
//! Near the axis a rotationally symmetric lens acts on x and y separately with the same 2x2 matrix, so a ray
//! entering the entrance plane (the first vertex, z = 0) at the point `x0` (2-vector) with the light's slope
//! vector `u` reaches the sensor at `A_f x0 + B_f u` and the stop, at its k-th crossing, at `A_k x0 + B_k u`
//! (`M_f = [[A_f, B_f], ..]` and `M_a = [[A_k, B_k], ..]` from [`crate::optics::paraxial::PathMatrices`]).
//! - **Effective entrance region**: the rays that pass crossing k form the disc of centre `-B_k u / A_k` and
//!   radius `r_a / |A_k|` (the patent's `r_e = (r_a - M_a12 theta_e) / M_a11`); the front lens's clear aperture
//!   adds the disc `|x0| <= h_0`. The region is their intersection: empty (culled) when two discs miss each
//!   other. A ghost whose reflections straddle the stop crosses it three times and gets all three discs:
//!   none is dropped.
//! - **Sprite**: the smallest of those discs, centre E and radius rho, bounds the region; mapped to the
//!   sensor it gives the sprite's centre `C = A_f E + B_f u` and signed half-size `S = A_f rho` (the flare
//!   quad: the four corner rays `E + rho (+-1, +-1)` land on `C + S (+-1, +-1)`; centre and rim rays give the
//!   circle). Inside the sprite, at quad coordinate q in [-1, 1]^2, the entrance point is `E + rho q`, so each
//!   crossing's aperture coordinate is the affine `uv_k = (A_k rho / r_a) q + (A_k E + B_k u) / r_a`: the
//!   renderer multiplies the aperture mask at every crossing and the front-disc mask.
//! - **Brightness**: energy is conserved, so the irradiance relative to the incoming light is
//!   `cos(theta) R_i R_j (entrance area / sensor area) = cos(theta) R_i R_j / A_f^2`. A ghost focused onto the
//!   sensor (A_f -> 0) gets the half-size `max(|S|, r_min)` and the irradiance `R_i R_j (rho / S)^2` with that
//!   size: bounded, with the same total energy, never infinite. When `A_k -> 0` (the stop's image at
//!   infinity) the front disc bounds the region and nothing divides by zero.
//! - **Reflectance**: each reflection's angle of incidence is paraxial, `i = u + s c y` for the ray through the
//!   region's centre E, linear in E and the light's slope; the reflectance of each (surface, side, wavelength) is
//!   tabulated at rebuild over sin(i) in [0, 1] ([`REFLECTANCE_SAMPLES`] samples, linear interpolation) from
//!   [`crate::coating`], so a frame costs a few multiplications per sprite.
//! - **Skipping**: sprites whose peak colour is below the threshold, that fall entirely off the sensor or
//!   whose entrance region is empty are culled, with the reason counted in [`FrameStats`].
//!
//! What changes per frame is only `u`: [`GhostSystem::frame`] is all the per-frame CPU work.

use crate::coating::reflection;
use crate::optics::{Coating, FirstOrder, Lens, LightPath, Mat2, ParaxialError, PathMatrices, D_LINE_NM};
use crate::spectrum::Spectrum;

/// Samples of each reflectance table over sin(i) in [0, 1].
pub const REFLECTANCE_SAMPLES: usize = 33;

/// The physical sensor the flare is drawn on, centred on the axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    pub width_mm: f64,
    pub height_mm: f64,
}

impl Sensor {
    /// A full-frame-wide sensor (36 mm) with the aspect of a `width` x `height` image.
    pub fn full_frame_for(width_px: u32, height_px: u32) -> Self {
        let width_mm = 36.0;
        Self { width_mm, height_mm: width_mm * height_px.max(1) as f64 / width_px.max(1) as f64 }
    }
}

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
    /// Sprites whose brightest channel is below this (relative irradiance) are culled.
    pub intensity_threshold: f64,
    /// Smallest sprite half-size on the sensor (a focused ghost is drawn this big, with its energy).
    pub min_half_size_mm: f64,
}

impl Default for FrameSettings {
    fn default() -> Self {
        Self { sensor: Sensor { width_mm: 36.0, height_mm: 24.0 }, intensity_threshold: 1e-7, min_half_size_mm: 0.02 }
    }
}

/// A reflectance table over sin(i).
#[derive(Clone, Debug, PartialEq)]
struct ReflectanceTable([f64; REFLECTANCE_SAMPLES]);

impl ReflectanceTable {
    fn at(&self, sin_i: f64) -> f64 {
        let x = sin_i.clamp(0.0, 1.0) * (REFLECTANCE_SAMPLES - 1) as f64;
        let k = (x as usize).min(REFLECTANCE_SAMPLES - 2);
        let f = x - k as f64;
        self.0[k] * (1.0 - f) + self.0[k + 1] * f
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

    /// sin of the angle of incidence for the ray entering at `x0` with slope `u` (the paraxial angle is
    /// taken as a tangent, so the sine stays below 1 however steep the ray).
    fn sin_at(&self, x0: [f64; 2], u: [f64; 2]) -> f64 {
        let t = (self.per_entry * x0[0] + self.per_slope * u[0]).hypot(self.per_entry * x0[1] + self.per_slope * u[1]);
        t / (1.0 + t * t).sqrt()
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
    reflectance_j: ReflectanceTable,
    reflectance_i: ReflectanceTable,
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

/// An affine map from sprite quad coordinates q to a mask's coordinates: `uv = scale q + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskMap {
    pub scale: f64,
    pub offset: [f64; 2],
}

/// One ghost at one wavelength in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Sprite {
    pub ghost: usize,
    pub wavelength: usize,
    /// Sprite centre on the sensor (sensor coordinates, the image is not yet flipped for display).
    pub centre_mm: [f64; 2],
    /// Signed half-size: negative when the ghost is an inverted image of the aperture.
    pub half_size_mm: f64,
    /// Irradiance relative to the incoming light (cos theta R_i R_j / A_f^2, bounded).
    pub irradiance: f64,
    /// irradiance x the wavelength's weight, clamped at 0.
    pub rgb: [f64; 3],
    /// Aperture-mask maps, one per stop crossing (1 or 3).
    pub stop_maps: Vec<MaskMap>,
    /// The front lens's clear-aperture disc (a circle of radius 1 in its coordinates).
    pub front_map: MaskMap,
    pub culled: Option<CullReason>,
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
    #[error("stop scale {0} must be in (0, 1]")]
    StopScale(f64),
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
}

impl GhostSystem {
    /// Builds every ghost of `lens` (which must be valid) for `settings`.
    pub fn build(lens: &Lens, settings: &GhostSettings) -> Result<Self, GhostError> {
        if !(settings.stop_scale > 0.0 && settings.stop_scale <= 1.0) {
            return Err(GhostError::StopScale(settings.stop_scale));
        }
        let first_order = FirstOrder::d_line(lens)?;
        let sensor_z = first_order.sensor_z_mm();
        let z = lens.vertex_z_mm();
        let stop = lens.stop_index();
        let stop_radius_mm = lens.surfaces[stop].semi_aperture_mm * settings.stop_scale;
        let n_surfaces = lens.surfaces.len();
        let spectrum = &settings.spectrum;
        let indices: Vec<Vec<f64>> = spectrum.wavelengths_nm.iter().map(|&w| lens.media_indices_at(w)).collect();

        // Reflectance tables per (surface, arriving direction, wavelength), made once and shared by ghosts.
        let mut tables: Vec<Option<[ReflectanceTable; 2]>> = vec![None; n_surfaces * spectrum.len()];
        let mut table = |k: usize, forward: bool, w: usize| -> ReflectanceTable {
            let slot = k * spectrum.len() + w;
            let pair = tables[slot].get_or_insert_with(|| {
                let coating = settings.coating_override.as_ref().unwrap_or(&lens.surfaces[k].coating);
                let (before, after) = (indices[w][k], indices[w][k + 1]);
                let make = |n_in: f64, n_out: f64| {
                    ReflectanceTable(std::array::from_fn(|s| {
                        let sin_i = s as f64 / (REFLECTANCE_SAMPLES - 1) as f64;
                        reflection(coating, n_in, n_out, spectrum.wavelengths_nm[w], sin_i).reflectance
                    }))
                };
                [make(before, after), make(after, before)]
            });
            pair[usize::from(!forward)].clone()
        };

        let mut ghosts = Vec::new();
        for (i, j) in lens.ghost_pairs() {
            let path = LightPath::ghost(lens, i, j).expect("ghost pairs are reflecting surfaces");
            let straddles_stop = path.straddles_stop(lens);
            let reflect_j = path.steps.iter().position(|s| s.surface == j && s.interaction == crate::optics::Interaction::Reflect);
            let reflect_i = path.steps.iter().rposition(|s| s.surface == i && s.interaction == crate::optics::Interaction::Reflect);
            let (Some(step_j), Some(step_i)) = (reflect_j, reflect_i) else { continue };
            let mut per_wavelength = Vec::with_capacity(spectrum.len());
            for (w, &wavelength_nm) in spectrum.wavelengths_nm.iter().enumerate() {
                let (mut at_j, mut at_i) = (Mat2::IDENTITY, Mat2::IDENTITY);
                let matrices = PathMatrices::walk(lens, &z, &indices[w], &path, sensor_z, |k, m| {
                    if k == step_j {
                        at_j = *m;
                    } else if k == step_i {
                        at_i = *m;
                    }
                });
                let (s_j, s_i) = (path.steps[step_j].arriving_direction, path.steps[step_i].arriving_direction);
                per_wavelength.push(GhostOptics {
                    wavelength_nm,
                    incidence_j: Incidence::new(&at_j, lens.surfaces[j].curvature_per_mm(), s_j),
                    incidence_i: Incidence::new(&at_i, lens.surfaces[i].curvature_per_mm(), s_i),
                    reflectance_j: table(j, path.steps[step_j].arriving_direction > 0.0, w),
                    reflectance_i: table(i, path.steps[step_i].arriving_direction > 0.0, w),
                    matrices,
                });
            }
            ghosts.push(GhostModel { i, j, straddles_stop, per_wavelength });
        }
        let image = LightPath::image(lens);
        let image_centre_per_slope = indices
            .iter()
            .map(|n| {
                let m = PathMatrices::walk(lens, &z, n, &image, sensor_z, |_, _| {});
                let (f, a) = (m.sensor_from_entrance, m.stop_from_entrance[0]);
                f.b - f.a * a.b / a.a
            })
            .collect();
        Ok(Self {
            lens: lens.clone(),
            first_order,
            settings: settings.clone(),
            stop_radius_mm,
            front_radius_mm: lens.surfaces[0].semi_aperture_mm,
            ghosts,
            image_centre_per_slope,
        })
    }

    /// Where the light source itself images on the sensor (its starburst), for light slope `u`, at the
    /// spectrum's middle wavelength.
    pub fn light_image_mm(&self, u: [f64; 2]) -> [f64; 2] {
        let k = self.image_centre_per_slope[self.image_centre_per_slope.len() / 2];
        [k * u[0], k * u[1]]
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

    /// The flare quad of a sprite by four rays: the corners `E + rho (+-1, +-1)` of its entrance region's
    /// bounding square traced through M_f to the sensor, in the corner order (-,-), (+,-), (+,+), (-,+).
    /// Equal to `C + S (+-1, +-1)` unless the sprite was enlarged because it is focused.
    pub fn flare_quad_mm(&self, sprite: &Sprite, u: [f64; 2]) -> [[f64; 2]; 4] {
        let f = self.ghosts[sprite.ghost].per_wavelength[sprite.wavelength].matrices.sensor_from_entrance;
        let rho = sprite.front_map.scale * self.front_radius_mm;
        let e = sprite.front_map.offset.map(|o| o * self.front_radius_mm);
        [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|q| {
            let x0 = [e[0] + rho * q[0], e[1] + rho * q[1]];
            [f.a * x0[0] + f.b * u[0], f.a * x0[1] + f.b * u[1]]
        })
    }

    /// All sprites for the light slope vector `u` (tan of the field angles): the per-frame work.
    pub fn frame(&self, u: [f64; 2], settings: &FrameSettings) -> GhostFrame {
        let mut frame = GhostFrame { sprites: Vec::with_capacity(self.ghosts.len() * self.settings.spectrum.len()), ..Default::default() };
        self.frame_into(u, settings, &mut frame);
        frame
    }

    /// [`Self::frame`] into an existing buffer (no allocation once warmed up).
    pub fn frame_into(&self, u: [f64; 2], settings: &FrameSettings, frame: &mut GhostFrame) {
        frame.sprites.clear();
        frame.stats = FrameStats::default();
        let u_len = u[0].hypot(u[1]);
        let cos_theta = 1.0 / (1.0 + u_len * u_len).sqrt();
        let (half_w, half_h) = (0.5 * settings.sensor.width_mm, 0.5 * settings.sensor.height_mm);
        let r_a = self.stop_radius_mm;
        let r_front = self.front_radius_mm;
        for (g, ghost) in self.ghosts.iter().enumerate() {
            for (w, optics) in ghost.per_wavelength.iter().enumerate() {
                let m = &optics.matrices;
                let f = m.sensor_from_entrance;
                // Entrance discs: the front aperture, then one per stop crossing.
                let mut discs: [([f64; 2], f64); 4] = [([0.0, 0.0], r_front); 4];
                let mut count = 1;
                let mut empty = false;
                for a in &m.stop_from_entrance {
                    if a.a.abs() > 1e-12 {
                        discs[count] = ([-a.b / a.a * u[0], -a.b / a.a * u[1]], r_a / a.a.abs());
                        count += 1;
                    } else if a.b.abs() * u_len > r_a {
                        // The stop crossing does not depend on the entry point: all rays miss it.
                        empty = true;
                    }
                }
                let discs = &discs[..count];
                for p in 0..count {
                    for q in p + 1..count {
                        let d = (discs[p].0[0] - discs[q].0[0]).hypot(discs[p].0[1] - discs[q].0[1]);
                        if d >= discs[p].1 + discs[q].1 {
                            empty = true;
                        }
                    }
                }
                let (e, rho) = discs.iter().copied().fold(discs[0], |best, d| if d.1 < best.1 { d } else { best });
                let centre = [f.a * e[0] + f.b * u[0], f.a * e[1] + f.b * u[1]];
                let size = f.a * rho;
                let half_size = if size.abs() < settings.min_half_size_mm {
                    settings.min_half_size_mm.copysign(if size == 0.0 { 1.0 } else { size })
                } else {
                    size
                };
                // Reflectances at the angles of the ray through the centre of the entrance region.
                let r_j = optics.reflectance_j.at(optics.incidence_j.sin_at(e, u));
                let r_i = optics.reflectance_i.at(optics.incidence_i.sin_at(e, u));
                let irradiance = cos_theta * r_i * r_j * (rho / half_size).powi(2);
                let weight = self.settings.spectrum.weights_rgb[w];
                let rgb = weight.map(|c| (c * irradiance).max(0.0));
                let extent = half_size.abs() * std::f64::consts::SQRT_2;
                let culled = if empty {
                    Some(CullReason::EmptyEntranceRegion)
                } else if centre[0].abs() - extent > half_w || centre[1].abs() - extent > half_h {
                    Some(CullReason::OffSensor)
                } else if rgb.iter().cloned().fold(0.0, f64::max) < settings.intensity_threshold {
                    Some(CullReason::BelowThreshold)
                } else {
                    None
                };
                let stats = &mut frame.stats;
                stats.sprites += 1;
                match culled {
                    None => stats.drawn += 1,
                    Some(CullReason::BelowThreshold) => stats.below_threshold += 1,
                    Some(CullReason::OffSensor) => stats.off_sensor += 1,
                    Some(CullReason::EmptyEntranceRegion) => stats.empty_entrance_region += 1,
                }
                let stop_maps = m
                    .stop_from_entrance
                    .iter()
                    .map(|a| MaskMap {
                        scale: a.a * rho / r_a,
                        offset: [(a.a * e[0] + a.b * u[0]) / r_a, (a.a * e[1] + a.b * u[1]) / r_a],
                    })
                    .collect();
                frame.sprites.push(Sprite {
                    ghost: g,
                    wavelength: w,
                    centre_mm: centre,
                    half_size_mm: half_size,
                    irradiance,
                    rgb,
                    stop_maps,
                    front_map: MaskMap { scale: rho / r_front, offset: [e[0] / r_front, e[1] / r_front] },
                    culled,
                });
            }
        }
    }

    /// The d-line index of the spectrum, or the middle one.
    pub fn reference_wavelength(&self) -> usize {
        let w = &self.settings.spectrum.wavelengths_nm;
        w.iter().position(|&x| x == D_LINE_NM).unwrap_or(w.len() / 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::library::builtin_lens;

    fn system(id: &str) -> GhostSystem {
        GhostSystem::build(&builtin_lens(id).unwrap(), &GhostSettings::default()).unwrap()
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
        for sprite in &frame.sprites {
            let ghost = &s.ghosts[sprite.ghost];
            assert_eq!(sprite.stop_maps.len(), if ghost.straddles_stop { 3 } else { 1 });
            assert!(sprite.irradiance.is_finite() && sprite.irradiance >= 0.0);
            assert!(sprite.half_size_mm.is_finite() && sprite.half_size_mm != 0.0);
        }
    }

    #[test]
    fn the_flare_quad_is_where_four_corner_rays_land() {
        let s = system("dgauss");
        let u = [0.05, -0.12];
        let settings = FrameSettings::default();
        let frame = s.frame(u, &settings);
        let mut checked = 0;
        for sprite in frame.sprites.iter().filter(|s| s.half_size_mm.abs() > settings.min_half_size_mm) {
            let quad = s.flare_quad_mm(sprite, u);
            for (k, q) in [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].iter().enumerate() {
                let expected = [sprite.centre_mm[0] + sprite.half_size_mm * q[0], sprite.centre_mm[1] + sprite.half_size_mm * q[1]];
                assert!((quad[k][0] - expected[0]).abs() < 1e-9 && (quad[k][1] - expected[1]).abs() < 1e-9);
            }
            // Centre and rim: two rays give the same circle.
            let rim = [(quad[1][0] + quad[2][0]) / 2.0, (quad[1][1] + quad[2][1]) / 2.0];
            assert!(((rim[0] - sprite.centre_mm[0]).abs() - sprite.half_size_mm.abs()).abs() < 1e-9);
            checked += 1;
        }
        assert!(checked > 100, "{checked}");
    }

    #[test]
    fn focused_ghosts_keep_finite_bounded_energy() {
        let s = system("tessar");
        let settings = FrameSettings::default();
        for u in [[0.0, 0.0], [0.3, 0.0], [0.0, -0.6], [2.0, 2.0]] {
            for sprite in s.frame(u, &settings).sprites {
                assert!(sprite.half_size_mm.abs() >= settings.min_half_size_mm);
                let rho = sprite.front_map.scale * s.front_radius_mm;
                let energy = sprite.irradiance * sprite.half_size_mm.powi(2);
                assert!(energy <= rho * rho * 1.0001, "energy never exceeds what enters: {energy} vs {}", rho * rho);
                assert!(sprite.rgb.iter().all(|c| c.is_finite() && *c >= 0.0));
            }
        }
    }

    #[test]
    fn culling_reports_reasons() {
        let s = system("wide");
        let tiny_sensor = FrameSettings { sensor: Sensor { width_mm: 0.5, height_mm: 0.5 }, ..FrameSettings::default() };
        let frame = s.frame([0.0, 0.4], &tiny_sensor);
        assert!(frame.stats.off_sensor > 0, "{:?}", frame.stats);
        let strict = FrameSettings { intensity_threshold: 1.0, ..FrameSettings::default() };
        let frame = s.frame([0.0, 0.0], &strict);
        assert_eq!(frame.stats.drawn, 0);
        assert_eq!(frame.stats.below_threshold + frame.stats.empty_entrance_region + frame.stats.off_sensor, frame.stats.sprites);
        // At a steep angle some ghosts' entrance discs no longer meet the front lens.
        let frame = s.frame([0.0, 1.2], &FrameSettings::default());
        assert!(frame.stats.empty_entrance_region > 0, "{:?}", frame.stats);
    }
}
