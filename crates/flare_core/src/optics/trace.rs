//! Exact sequential ray tracing in 3D, in f64, through spherical, flat, conic and even-aspheric interfaces.
//!
//! # How it works
//! A [`Tracer`] is made once per (lens, light path, wavelength): it resolves each [`Step`] of the
//! [`LightPath`] into the vertex position, curvature, clear aperture and the two refractive indices, so that
//! tracing a ray is a tight loop. For each step the ray is intersected with the surface's sphere (or plane)
//! by Welford's form, which is exact for flat surfaces and stable for huge radii:
//! with p the ray point relative to the vertex and d its unit direction,
//! `s = (c |p|^2 - 2 p_z) / (s_dir sqrt(disc) - b)`, `b = c d.p - d_z`, `disc = b^2 - c (c |p|^2 - 2 p_z)`,
//! where `s_dir` is the travel direction (+1 / -1) that picks the root on the vertex side. A conic or aspheric
//! surface (see the sag in [`crate::optics::lens`]) starts from the same stable root for its quadric
//! `c (x^2 + y^2 + (1 + k) z^2) - 2 z = 0` (or from the vertex plane where the line misses the quadric) and
//! then solves `z(s) - sag(r(s)) = 0` by Newton's method, at most [`MAX_NEWTON_STEPS`] steps, until a step is
//! below 1e-13 of the distance; a line that leaves the region where the sag is defined, or does not
//! converge, missed the surface. So a sphere is met as a whole sphere (the reference figures' convention, even
//! off the hemisphere the sag describes), while a conic or asphere is met only on the branch its sag describes. Its normal is `(-m x, -m y, 1) / sqrt(1 + m^2 r^2)` with `m = (dz/dr) / r`.
//! Then it refracts by
//! the vector form of Snell's law, `n2 d' = n1 d + (n2 cos t - n1 cos i) N`, or reflects,
//! `d' = d - 2 (d.N) N`, and finally meets the sensor plane.
//!
//! Every way a ray can fail is an outcome, never a NaN ([`TraceStatus`]):
//! - **missed surface k**: the line does not meet the sphere (negative discriminant) or runs parallel to a
//!   plane (the sensor counts as surface N, the number of surfaces);
//! - **backward**: the ray leaves the last surface travelling away from the sensor;
//! - **total internal reflection at k**: `n2^2 - n1^2 sin^2 i < 0`;
//! - **vignetted at k**: the ray passes outside surface k's clear semi-aperture. Clear apertures are always
//!   *reported* (`clipped_at`, in path order) but only *applied* when [`TraceOptions::apply_apertures`] is set,
//!   the convention of the reference figures.
//!
//! Ray set-up ([`pupil_ray`]), the convention of `tests/data/reference`: light from the field angle theta in
//! the y-z plane has direction (0, sin theta, cos theta) and passes through the point (px r_ep, py r_ep, z_ep)
//! of the paraxial entrance pupil (no real-ray aiming); the sensor is the paraxial back focal plane at the
//! d-line, whatever the wavelength traced (a sensor does not move with colour).

use glam::DVec3;
use serde::Serialize;

use super::lens::{Lens, SurfaceShape};
use super::paraxial::EntrancePupil;
use super::path::{Interaction, LightPath, Step};

/// A ray: a point and a unit direction, in lens coordinates (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin_mm: DVec3,
    pub direction: DVec3,
}

/// The ray of the reference convention: field angle `theta` (radians) in the y-z plane, through the point
/// (`px`, `py`) of the entrance pupil in units of its radius.
pub fn pupil_ray(pupil: &EntrancePupil, theta: f64, px: f64, py: f64) -> Ray {
    let r = pupil.radius_mm;
    Ray { origin_mm: DVec3::new(px * r, py * r, pupil.z_mm), direction: DVec3::new(0.0, theta.sin(), theta.cos()) }
}

/// What happened to a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum TraceStatus {
    /// Reached the sensor.
    Landed,
    /// Stopped by surface `surface`'s clear aperture (only when apertures are applied).
    Vignetted { surface: usize },
    /// Totally internally reflected at `surface`.
    Tir { surface: usize },
    /// Did not meet `surface` (the sensor is surface N).
    Missed { surface: usize },
    /// Left the last surface travelling away from the sensor (a ghost turned back for good).
    Backward,
}

impl TraceStatus {
    /// The word used by the command line and the reference figures: ok, vignetted, tir, missed.
    pub fn word(&self) -> &'static str {
        match self {
            Self::Landed => "ok",
            Self::Vignetted { .. } => "vignetted",
            Self::Tir { .. } => "tir",
            Self::Missed { .. } => "missed",
            Self::Backward => "backward",
        }
    }

    /// The surface where the ray stopped, if it did.
    pub fn surface(&self) -> Option<usize> {
        match *self {
            Self::Landed | Self::Backward => None,
            Self::Vignetted { surface } | Self::Tir { surface } | Self::Missed { surface } => Some(surface),
        }
    }
}

/// Options of one trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceOptions {
    /// Stop the ray at the first clear aperture it passes outside.
    pub apply_apertures: bool,
    /// Keep every intersection point (for drawing ray diagrams).
    pub record_points: bool,
}

/// The outcome of one trace.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceResult {
    pub status: TraceStatus,
    /// Where the ray met the sensor plane (only when it landed).
    pub sensor_point_mm: Option<DVec3>,
    /// Direction when it met the sensor (only when it landed).
    pub sensor_direction: Option<DVec3>,
    /// Surfaces, in path order, whose clear aperture the ray passed outside (reported, applied only on request).
    pub clipped_at: Vec<usize>,
    /// The start point and every intersection, when asked for.
    pub points_mm: Vec<DVec3>,
}

/// One step of a path with everything the inner loop needs (the GPU tracer reads the same, see
/// [`Tracer::steps`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResolvedStep {
    pub surface: usize,
    pub vertex_z_mm: f64,
    pub shape: SurfaceShape,
    pub semi_aperture_mm: f64,
    /// n_in / n_out (1 between equal media).
    pub eta: f64,
    pub reflect: bool,
    /// +1 when the light arrives travelling to +z, -1 when travelling back.
    pub arriving_direction: f64,
}

/// Traces rays along one light path of one lens at one wavelength.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracer {
    steps: Vec<ResolvedStep>,
    sensor_z_mm: f64,
    sensor_index: usize,
}

impl Tracer {
    /// Prepares `path` at `wavelength_nm`, ending on the plane `sensor_z_mm`.
    pub fn new(lens: &Lens, path: &LightPath, wavelength_nm: f64, sensor_z_mm: f64) -> Self {
        let n = lens.media_indices_at(wavelength_nm);
        let z = lens.vertex_z_mm();
        let steps = path
            .steps
            .iter()
            .map(|s: &Step| {
                let surf = &lens.surfaces[s.surface];
                ResolvedStep {
                    surface: s.surface,
                    vertex_z_mm: z[s.surface],
                    shape: surf.shape(),
                    semi_aperture_mm: surf.semi_aperture_mm,
                    eta: n[s.medium_in] / n[s.medium_out],
                    reflect: s.interaction == Interaction::Reflect,
                    arriving_direction: s.arriving_direction,
                }
            })
            .collect();
        Self { steps, sensor_z_mm, sensor_index: lens.surfaces.len() }
    }

    /// The resolved steps, in path order (what a GPU twin of the tracer uploads).
    pub fn steps(&self) -> &[ResolvedStep] {
        &self.steps
    }

    /// The sensor plane (mm behind the first vertex).
    pub fn sensor_z_mm(&self) -> f64 {
        self.sensor_z_mm
    }

    /// Traces one ray to the sensor.
    pub fn trace(&self, ray: &Ray, options: TraceOptions) -> TraceResult {
        let mut clipped_at = Vec::new();
        let mut points_mm = Vec::new();
        if options.record_points {
            points_mm.push(ray.origin_mm);
        }
        let outcome = self.trace_visit(ray, |hit| {
            if options.record_points {
                points_mm.push(hit.point_mm);
            }
            let outside = hit.point_mm.x.hypot(hit.point_mm.y) > hit.semi_aperture_mm;
            if outside {
                clipped_at.push(hit.surface);
            }
            !(outside && options.apply_apertures)
        });
        match outcome {
            Ok(landing) => {
                if options.record_points {
                    points_mm.push(landing.point_mm);
                }
                TraceResult {
                    status: TraceStatus::Landed,
                    sensor_point_mm: Some(landing.point_mm),
                    sensor_direction: Some(landing.direction),
                    clipped_at,
                    points_mm,
                }
            }
            Err(status) => TraceResult { status, sensor_point_mm: None, sensor_direction: None, clipped_at, points_mm },
        }
    }

    /// The tracing loop itself, allocation-free: `visit` sees every intersection (before the interaction) and
    /// returns `false` to stop the ray there as vignetted. The ray-grid renderers read incidence angles and
    /// stop crossings through it; [`Self::trace`] is built on it. One lane of [`Self::trace_visit_lanes`].
    pub fn trace_visit(&self, ray: &Ray, mut visit: impl FnMut(&StepHit) -> bool) -> Result<Landing, TraceStatus> {
        let [outcome] = self.trace_visit_lanes([*ray], |_, hit| visit(hit));
        outcome
    }

    /// [`Self::trace_visit`] for `L` independent rays at once, step by step in lockstep: `visit(lane, hit)`.
    /// Each lane does exactly the arithmetic of a lone ray (the results are identical, bit for bit); the
    /// lanes only interleave, so that the processor overlaps one ray's square roots and divisions with the
    /// next one's instead of waiting on each in turn (a ray is one long chain of dependent operations). The
    /// ray-grid renderers trace 4 at a time.
    pub fn trace_visit_lanes<const L: usize>(
        &self,
        rays: [Ray; L],
        mut visit: impl FnMut(usize, &StepHit) -> bool,
    ) -> [Result<Landing, TraceStatus>; L] {
        let mut p = rays.map(|r| r.origin_mm);
        let mut d = rays.map(|r| r.direction.normalize_or_zero());
        let mut outcome: [Option<TraceStatus>; L] = [None; L];
        for lane in 0..L {
            if d[lane] == DVec3::ZERO || !p[lane].is_finite() {
                outcome[lane] = Some(TraceStatus::Missed { surface: 0 });
            }
        }
        for (index, step) in self.steps.iter().enumerate() {
            let vertex = DVec3::new(0.0, 0.0, step.vertex_z_mm);
            for lane in 0..L {
                if outcome[lane].is_some() {
                    continue;
                }
                match self.step_ray(index, step, vertex, &mut p[lane], &mut d[lane], |hit| visit(lane, hit)) {
                    Ok(()) => {}
                    Err(status) => outcome[lane] = Some(status),
                }
            }
        }
        std::array::from_fn(|lane| match outcome[lane] {
            Some(status) => Err(status),
            None => self.to_sensor(p[lane], d[lane]),
        })
    }

    /// One step of one ray: meet the surface, show the hit to `visit`, refract or reflect.
    #[inline(always)]
    fn step_ray(
        &self,
        index: usize,
        step: &ResolvedStep,
        vertex: DVec3,
        p: &mut DVec3,
        d: &mut DVec3,
        mut visit: impl FnMut(&StepHit) -> bool,
    ) -> Result<(), TraceStatus> {
        let missed = TraceStatus::Missed { surface: step.surface };
        // The ray is a line and each surface a whole sphere: an intersection may lie behind the current
        // point (the entrance pupil is often inside the lens, and a ray far outside the clear apertures
        // can meet the next sphere before the last one). This is the convention of the reference
        // figures; inside the clear apertures surfaces never cross (validation refuses that), so rays
        // traced with apertures applied always move forward along the path.
        let s = intersect_shape(*p - vertex, *d, &step.shape, step.arriving_direction).ok_or(missed)?;
        *p += s * *d;
        let normal = shape_normal(*p - vertex, &step.shape).ok_or(missed)?;
        let cos_i = d.dot(normal);
        let hit = StepHit {
            index,
            surface: step.surface,
            point_mm: *p,
            cos_incidence: cos_i.abs().min(1.0),
            reflect: step.reflect,
            semi_aperture_mm: step.semi_aperture_mm,
        };
        if !visit(&hit) {
            return Err(TraceStatus::Vignetted { surface: step.surface });
        }
        *d = if step.reflect {
            reflect(*d, normal)
        } else if step.eta == 1.0 {
            *d
        } else {
            refract(*d, normal, step.eta).ok_or(TraceStatus::Tir { surface: step.surface })?
        };
        if !d.is_finite() || !p.is_finite() {
            return Err(missed);
        }
        Ok(())
    }

    /// From the last surface to the sensor plane, facing the light travelling to +z.
    fn to_sensor(&self, p: DVec3, d: DVec3) -> Result<Landing, TraceStatus> {
        if d.z <= 0.0 {
            return Err(TraceStatus::Backward);
        }
        let to_sensor = (self.sensor_z_mm - p.z) / d.z;
        let landing = p + to_sensor * d;
        if !to_sensor.is_finite() || !landing.is_finite() {
            return Err(TraceStatus::Missed { surface: self.sensor_index });
        }
        Ok(Landing { point_mm: landing, direction: d })
    }
}

/// One intersection seen by [`Tracer::trace_visit`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepHit {
    /// Position of the step along the path.
    pub index: usize,
    pub surface: usize,
    pub point_mm: DVec3,
    /// |cos| of the angle between the arriving ray and the surface normal.
    pub cos_incidence: f64,
    pub reflect: bool,
    pub semi_aperture_mm: f64,
}

/// Where and how a ray met the sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landing {
    pub point_mm: DVec3,
    pub direction: DVec3,
}

/// Distance along unit direction `d` from `p` (relative to the vertex) to the surface of curvature `c`,
/// on the root nearer the vertex for travel direction `z_dir`; `None` when the line misses it.
fn intersect(p: DVec3, d: DVec3, c: f64, z_dir: f64) -> Option<f64> {
    let cx2 = c * p.length_squared() - 2.0 * p.z;
    let b = c * d.dot(p) - d.z;
    let disc = b * b - c * cx2;
    if disc < 0.0 {
        return None;
    }
    let denominator = z_dir * disc.sqrt() - b;
    let s = cx2 / denominator;
    (denominator != 0.0 && s.is_finite()).then_some(s)
}

/// Most Newton steps an aspheric intersection may take before the ray counts as missing the surface.
pub const MAX_NEWTON_STEPS: usize = 40;

/// Distance along unit direction `d` from `p` (relative to the vertex) to the surface `shape`, on the branch
/// the sag describes; `None` when the line misses it (see the module's notes).
pub fn intersect_shape(p: DVec3, d: DVec3, shape: &SurfaceShape, z_dir: f64) -> Option<f64> {
    if shape.spherical {
        return intersect(p, d, shape.curvature_per_mm, z_dir);
    }
    let c = shape.curvature_per_mm;
    let q = 1.0 + shape.conic;
    // The quadric alone, by the same stable root as the sphere: a s^2 + 2 b s + g0 = 0.
    let g0 = c * (p.x * p.x + p.y * p.y + q * p.z * p.z) - 2.0 * p.z;
    let a = c * (d.x * d.x + d.y * d.y + q * d.z * d.z);
    let b = c * (p.x * d.x + p.y * d.y + q * p.z * d.z) - d.z;
    let disc = b * b - a * g0;
    let quadric = (disc >= 0.0).then(|| g0 / (z_dir * disc.sqrt() - b)).filter(|s| s.is_finite());
    let mut s = match quadric {
        Some(s) => s,
        None if d.z != 0.0 => -p.z / d.z,
        None => return None,
    };
    for _ in 0..MAX_NEWTON_STEPS {
        let at = p + s * d;
        let r2 = at.x * at.x + at.y * at.y;
        let f = at.z - shape.sag_mm(r2)?;
        let derivative = d.z - shape.slope_over_r(r2)? * (at.x * d.x + at.y * d.y);
        if derivative == 0.0 {
            return None;
        }
        let step = f / derivative;
        s -= step;
        if !s.is_finite() {
            return None;
        }
        if step.abs() <= 1e-13 * (1.0 + s.abs()) {
            return Some(s);
        }
    }
    None
}

/// Unit normal of `shape` at the point `p` (relative to the vertex, on the surface), pointing to +z at the
/// vertex; `None` where the slope is infinite (the rim of a sphere or ellipsoid met edge-on).
pub fn shape_normal(p: DVec3, shape: &SurfaceShape) -> Option<DVec3> {
    if shape.spherical {
        return Some(surface_normal(p, shape.curvature_per_mm));
    }
    let m = shape.slope_over_r(p.x * p.x + p.y * p.y)?;
    let n = DVec3::new(-m * p.x, -m * p.y, 1.0);
    Some(n / n.length())
}

/// Unit normal of the surface of curvature `c` at the point `p` (relative to the vertex), pointing to +z
/// at the vertex. On the sphere `c |p|^2 = 2 p_z`, so `|(-c x, -c y, 1 - c z)|^2 = 1 + c (c |p|^2 - 2 z) = 1`:
/// the vector is already unit (to rounding) and needs no square root.
fn surface_normal(p: DVec3, c: f64) -> DVec3 {
    DVec3::new(-c * p.x, -c * p.y, 1.0 - c * p.z)
}

/// Vector Snell's law with `eta = n_in / n_out`: `d' = eta d + (sign(cos i) cos t - eta cos i) N`; `None` on
/// total internal reflection.
fn refract(d: DVec3, normal: DVec3, eta: f64) -> Option<DVec3> {
    let cos_i = d.dot(normal);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let root = 1.0 - eta * eta * sin2_i;
    if root < 0.0 {
        return None;
    }
    let cos_t = root.sqrt().copysign(cos_i);
    Some(eta * d + (cos_t - eta * cos_i) * normal)
}

fn reflect(d: DVec3, normal: DVec3) -> DVec3 {
    d - 2.0 * d.dot(normal) * normal
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_surface_intersection_is_exact() {
        let s = intersect(DVec3::new(0.0, 1.0, -5.0), DVec3::Z, 0.0, 1.0).unwrap();
        assert_eq!(s, 5.0);
        assert!(intersect(DVec3::new(0.0, 0.0, -5.0), DVec3::Y, 0.0, 1.0).is_none(), "parallel to a plane");
    }

    #[test]
    fn sphere_intersection_picks_the_vertex_side() {
        // Sphere of radius 10 with vertex at the origin, centre at z = 10; ray along the axis from z = -5.
        let s = intersect(DVec3::new(0.0, 0.0, -5.0), DVec3::Z, 0.1, 1.0).unwrap();
        assert!((s - 5.0).abs() < 1e-12);
        // Travelling back from z = 5 it meets the same vertex.
        let s = intersect(DVec3::new(0.0, 0.0, 5.0), -DVec3::Z, 0.1, -1.0).unwrap();
        assert!((s - 5.0).abs() < 1e-12);
        // A ray at height 11 misses a sphere of radius 10.
        assert!(intersect(DVec3::new(0.0, 11.0, -5.0), DVec3::Z, 0.1, 1.0).is_none());
    }

    #[test]
    fn snell_and_tir() {
        let d = DVec3::new(0.6, 0.0, 0.8);
        let out = refract(d, DVec3::Z, 1.0 / 1.5).unwrap();
        assert!((out.length() - 1.0).abs() < 1e-15);
        assert!((1.5 * out.x - 0.6).abs() < 1e-15, "tangential n sin is conserved");
        assert!(refract(d, DVec3::Z, 1.5).is_some(), "1.5 * 0.6 = 0.9 < 1: no TIR");
        assert!(refract(DVec3::new(0.8, 0.0, 0.6), DVec3::Z, 1.5).is_none(), "1.5 * 0.8 > 1: TIR");
        let r = reflect(d, DVec3::Z);
        assert_eq!(r, DVec3::new(0.6, 0.0, -0.8));
    }
}
