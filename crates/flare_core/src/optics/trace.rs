//! Exact sequential ray tracing in 3D, in f64, through spherical, flat, conic, even-aspheric and toroidal
//! (anamorphic) interfaces.
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
//! then solves `z(s) - sag(r(s)) = 0` by Newton's method, at most `MAX_NEWTON_STEPS` steps, until a step is
//! below 1e-13 of the distance; a line that leaves the region where the sag is defined, or does not
//! converge, missed the surface. A toroid (no rotational symmetry) starts Newton's method on
//! `z(s) - sag(x(s), y(s))` from the vertex plane, its normal from the two slopes of its sag. So a sphere is met
//! as a whole sphere (the reference figures' convention, even off the hemisphere the sag describes), while a
//! conic, asphere or toroid is met only on the branch its sag describes. Its normal is
//! `(-m x, -m y, 1) / sqrt(1 + m^2 r^2)` with `m = (dz/dr) / r` (a toroid's, `(-dz/dx, -dz/dy, 1)` normalised).
//! Then it refracts by
//! the vector form of Snell's law, `n2 d' = n1 d + (n2 cos t - n1 cos i) N`, or reflects,
//! `d' = d - 2 (d.N) N`, and finally meets the sensor plane.
//!
//! Many rays at once ([`Tracer::trace_visit_lanes`], [`Tracer::trace_vertices`]) are held as columns (x of
//! every ray, then y, ...); at a spherical or flat surface every ray's intersection, normal and refraction is
//! one branch-free loop, compiled for AVX2 and for AVX-512 and chosen at run time (`FLARELAB_SIMD=0|1|2` caps
//! it). Each lane does exactly the operations of a lone ray, in the same order, and IEEE arithmetic rounds
//! them the same in any register width (Rust never fuses a multiply and an add by itself): the results are
//! those of one ray traced alone, bit for bit, on any processor. A conic or aspheric surface steps each ray
//! alone (Newton's method).
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
    /// returns `false` to stop the ray there as vignetted. The mapping and tolerance analyses read hits through
    /// it; [`Self::trace`] is built on it. One lane of [`Self::trace_visit_lanes`].
    pub fn trace_visit(&self, ray: &Ray, mut visit: impl FnMut(&StepHit) -> bool) -> Result<Landing, TraceStatus> {
        let [outcome] = self.trace_visit_lanes([*ray], |_, hit| visit(hit));
        outcome
    }

    /// [`Self::trace_visit`] for `L` independent rays at once, step by step in lockstep: `visit(lane, hit)`.
    /// Each lane does exactly the arithmetic of a lone ray (the results are identical, bit for bit). The rays
    /// are held as columns (x of every lane, then y, ...): at a spherical or flat surface the intersection,
    /// normal and refraction of all lanes are one branch-free loop (`sphere_step`) that the compiler turns
    /// into vector instructions (AVX2 or AVX-512 where the processor has them, chosen at run time), and only the
    /// visit and the failures are looked at lane by lane; a conic or aspheric surface steps each lane alone
    /// (Newton's method).
    pub fn trace_visit_lanes<const L: usize>(
        &self,
        rays: [Ray; L],
        visit: impl FnMut(usize, &StepHit) -> bool,
    ) -> [Result<Landing, TraceStatus>; L] {
        self.trace_dispatch(rays, &mut ClosureVisitor(visit))
    }

    /// `L` rays traced as [`Self::trace_visit_lanes`] does, each recording what a ray-grid vertex needs
    /// ([`VertexRecipe`]): its weight, its stop crossings and its largest relative height. At a spherical step
    /// the recording is vectorised too (what it needs kept in the step's loop, the reflectance tables then read
    /// by gathers in a loop of their own), with the arithmetic of a one-ray visit (the same results, bit for
    /// bit). The ray-grid renderers and the LUT bake trace through it, 16 rays at a time.
    pub fn trace_vertices<const L: usize>(
        &self,
        rays: [Ray; L],
        recipe: &VertexRecipe,
    ) -> ([Result<Landing, TraceStatus>; L], VertexRecord<L>) {
        let mut visitor = RecipeVisitor { recipe, record: VertexRecord::new() };
        let outcome = self.trace_dispatch(rays, &mut visitor);
        (outcome, visitor.record)
    }

    /// [`Self::trace_columns`] with the widest vector instructions this processor has.
    fn trace_dispatch<const L: usize, V: LaneVisitor<L>>(
        &self,
        rays: [Ray; L],
        visitor: &mut V,
    ) -> [Result<Landing, TraceStatus>; L] {
        #[cfg(target_arch = "x86_64")]
        let level = simd_level();
        #[cfg(not(target_arch = "x86_64"))]
        let level = 0;
        self.trace_at_level(level, rays, visitor)
    }

    /// [`Self::trace_columns`] compiled for the vector instructions of `level` ([`simd_level`]; at most what
    /// this processor has).
    fn trace_at_level<const L: usize, V: LaneVisitor<L>>(
        &self,
        level: u8,
        rays: [Ray; L],
        visitor: &mut V,
    ) -> [Result<Landing, TraceStatus>; L] {
        #[cfg(target_arch = "x86_64")]
        {
            let level = level.min(simd_level());
            if L >= 8 && level >= 2 {
                // SAFETY: the processor has AVX-512F (checked once by `simd_level`).
                return unsafe { self.trace_columns_avx512(rays, visitor) };
            }
            if L >= 4 && level >= 1 {
                // SAFETY: the processor has AVX2 (checked once by `simd_level`).
                return unsafe { self.trace_columns_avx2(rays, visitor) };
            }
        }
        self.trace_columns(rays, visitor)
    }

    /// [`Self::trace_columns`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn trace_columns_avx2<const L: usize, V: LaneVisitor<L>>(
        &self,
        rays: [Ray; L],
        visitor: &mut V,
    ) -> [Result<Landing, TraceStatus>; L] {
        self.trace_columns(rays, visitor)
    }

    /// [`Self::trace_columns`] compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
    unsafe fn trace_columns_avx512<const L: usize, V: LaneVisitor<L>>(
        &self,
        rays: [Ray; L],
        visitor: &mut V,
    ) -> [Result<Landing, TraceStatus>; L] {
        self.trace_columns(rays, visitor)
    }

    /// The body of [`Self::trace_visit_lanes`], inlined into each instruction-set variant.
    #[inline(always)]
    fn trace_columns<const L: usize, V: LaneVisitor<L>>(
        &self,
        rays: [Ray; L],
        visitor: &mut V,
    ) -> [Result<Landing, TraceStatus>; L] {
        let mut ray = Columns::<L>::default();
        // Per lane, how it stopped (`Fail`, 0 while it travels on) and at which surface: small integers, so
        // that keeping them is vectorised with the step.
        let (mut fail, mut fail_at) = ([Fail::None as u8; L], [0usize; L]);
        for (lane, r) in rays.iter().enumerate() {
            let d = r.direction.normalize_or_zero();
            ray.set(lane, r.origin_mm, d);
            if d == DVec3::ZERO || !r.origin_mm.is_finite() {
                fail[lane] = Fail::Missed as u8;
            }
        }
        for (index, step) in self.steps.iter().enumerate() {
            if fail.iter().all(|&f| f != Fail::None as u8) {
                break;
            }
            if !step.shape.spherical {
                let vertex = DVec3::new(0.0, 0.0, step.vertex_z_mm);
                for lane in 0..L {
                    if fail[lane] != Fail::None as u8 {
                        continue;
                    }
                    let (mut p, mut d) = ray.get(lane);
                    match self.step_ray(index, step, vertex, &mut p, &mut d, |hit| visitor.lane(lane, hit)) {
                        Ok(()) => ray.set(lane, p, d),
                        Err(status) => (fail[lane], fail_at[lane]) = (Fail::of(status), step.surface),
                    }
                }
                continue;
            }
            let alive: [bool; L] = std::array::from_fn(|l| fail[l] == Fail::None as u8);
            let (next, stopped) = visitor.sphere(index, step, &mut ray, alive);
            for l in 0..L {
                // The first failure of the step, in the order one ray meets them.
                let code = if !next.hit[l] {
                    Fail::Missed
                } else if stopped[l] {
                    Fail::Vignetted
                } else if next.tir[l] {
                    Fail::Tir
                } else if !next.finite[l] {
                    Fail::Missed
                } else {
                    Fail::None
                } as u8;
                let newly = alive[l] & (code != Fail::None as u8);
                fail[l] = if newly { code } else { fail[l] };
                fail_at[l] = if newly { step.surface } else { fail_at[l] };
            }
        }
        let outcome: [Option<TraceStatus>; L] = std::array::from_fn(|l| Fail::status(fail[l], fail_at[l]));
        std::array::from_fn(|lane| match outcome[lane] {
            Some(status) => Err(status),
            None => {
                let (p, d) = ray.get(lane);
                self.to_sensor(p, d)
            }
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

/// How a lane of [`Tracer::trace_columns`] stopped, as a small integer (see [`TraceStatus`]).
#[derive(Clone, Copy)]
#[repr(u8)]
enum Fail {
    None = 0,
    Missed = 1,
    Vignetted = 2,
    Tir = 3,
    Backward = 4,
}

impl Fail {
    fn of(status: TraceStatus) -> u8 {
        (match status {
            TraceStatus::Landed => Self::None,
            TraceStatus::Missed { .. } => Self::Missed,
            TraceStatus::Vignetted { .. } => Self::Vignetted,
            TraceStatus::Tir { .. } => Self::Tir,
            TraceStatus::Backward => Self::Backward,
        }) as u8
    }

    /// The status of a lane that stopped with `code` at `surface` (`None` while it travels on).
    fn status(code: u8, surface: usize) -> Option<TraceStatus> {
        match code {
            1 => Some(TraceStatus::Missed { surface }),
            2 => Some(TraceStatus::Vignetted { surface }),
            3 => Some(TraceStatus::Tir { surface }),
            4 => Some(TraceStatus::Backward),
            _ => None,
        }
    }
}

/// `L` rays as columns: the point and the unit direction of each lane.
#[derive(Clone, Copy)]
struct Columns<const L: usize> {
    px: [f64; L],
    py: [f64; L],
    pz: [f64; L],
    dx: [f64; L],
    dy: [f64; L],
    dz: [f64; L],
}

impl<const L: usize> Default for Columns<L> {
    fn default() -> Self {
        Self { px: [0.0; L], py: [0.0; L], pz: [0.0; L], dx: [0.0; L], dy: [0.0; L], dz: [0.0; L] }
    }
}

impl<const L: usize> Columns<L> {
    fn set(&mut self, lane: usize, p: DVec3, d: DVec3) {
        (self.px[lane], self.py[lane], self.pz[lane]) = (p.x, p.y, p.z);
        (self.dx[lane], self.dy[lane], self.dz[lane]) = (d.x, d.y, d.z);
    }

    fn get(&self, lane: usize) -> (DVec3, DVec3) {
        (
            DVec3::new(self.px[lane], self.py[lane], self.pz[lane]),
            DVec3::new(self.dx[lane], self.dy[lane], self.dz[lane]),
        )
    }
}

/// What one spherical or flat step made of every lane ([`sphere_step`]), besides the rays it moved.
struct SphereStep<const L: usize> {
    /// d.N at the intersection (before the interaction).
    cos_i: [f64; L],
    /// The line met the surface ([`intersect`] is `Some`).
    hit: [bool; L],
    /// Total internal reflection (refraction only).
    tir: [bool; L],
    /// The point and the new direction are finite.
    finite: [bool; L],
}

/// One spherical or flat step of every lane, in place, branch-free so that it vectorises: the same operations, in the
/// same order, as [`intersect`], [`surface_normal`], [`refract`] and [`reflect`] on one ray (so the same
/// results, bit for bit). A lane that fails is computed anyway and flagged; its values are not used.
///
/// `record(lane, met, x, y, cos_i)` sees every lane in the loop (`met`: alive and met the surface; x and y the
/// intersection, cos_i = d.N): a visitor that records what it needs there keeps the loop vectorised.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // One index over every column: the loop the compiler vectorises.
fn sphere_step<const L: usize>(
    ray: &mut Columns<L>,
    step: &ResolvedStep,
    alive: [bool; L],
    mut record: impl FnMut(usize, bool, f64, f64, f64),
) -> SphereStep<L> {
    let c = step.shape.curvature_per_mm;
    let (z_dir, vertex_z, eta) = (step.arriving_direction, step.vertex_z_mm, step.eta);
    let mut out = SphereStep { cos_i: [0.0; L], hit: [false; L], tir: [false; L], finite: [false; L] };
    for l in 0..L {
        let (x, y, z) = (ray.px[l], ray.py[l], ray.pz[l] - vertex_z);
        let (dx, dy, dz) = (ray.dx[l], ray.dy[l], ray.dz[l]);
        // intersect(p - vertex, d, c, z_dir)
        let cx2 = c * (x * x + y * y + z * z) - 2.0 * z;
        let b = c * (dx * x + dy * y + dz * z) - dz;
        let disc = b * b - c * cx2;
        let denominator = z_dir * disc.sqrt() - b;
        let s = cx2 / denominator;
        // (A NaN discriminant gives a NaN s: no hit, as in `intersect`.)
        out.hit[l] = (disc >= 0.0) & (denominator != 0.0) & s.is_finite();
        // p += s d
        let (px, py, pz) = (ray.px[l] + s * dx, ray.py[l] + s * dy, ray.pz[l] + s * dz);
        // surface_normal(p - vertex, c)
        let (nx, ny, nz) = (-c * px, -c * py, 1.0 - c * (pz - vertex_z));
        let cos_i = dx * nx + dy * ny + dz * nz;
        out.cos_i[l] = cos_i;
        record(l, alive[l] & out.hit[l], px, py, cos_i);
        let (ex, ey, ez) = if step.reflect {
            let k = 2.0 * cos_i;
            (dx - k * nx, dy - k * ny, dz - k * nz)
        } else if eta == 1.0 {
            (dx, dy, dz)
        } else {
            let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
            let root = 1.0 - eta * eta * sin2_i;
            out.tir[l] = root < 0.0;
            let k = root.sqrt().copysign(cos_i) - eta * cos_i;
            (eta * dx + k * nx, eta * dy + k * ny, eta * dz + k * nz)
        };
        out.finite[l] =
            (px.is_finite() & py.is_finite() & pz.is_finite()) & (ex.is_finite() & ey.is_finite() & ez.is_finite());
        (ray.px[l], ray.py[l], ray.pz[l]) = (px, py, pz);
        (ray.dx[l], ray.dy[l], ray.dz[l]) = (ex, ey, ez);
    }
    out
}

/// What [`Tracer::trace_columns`] shows each intersection to: one lane's hit (a conic or aspheric step), or
/// every lane of a spherical step at once (the visitor runs the step, [`sphere_step`], so that it can record in
/// its loop). Returns whether a lane stops there as vignetted.
trait LaneVisitor<const L: usize> {
    fn lane(&mut self, lane: usize, hit: &StepHit) -> bool;

    /// A spherical step of every lane ([`sphere_step`]), shown the lanes met (alive, and met the surface);
    /// `true` where one stops.
    fn sphere(
        &mut self,
        index: usize,
        step: &ResolvedStep,
        ray: &mut Columns<L>,
        alive: [bool; L],
    ) -> (SphereStep<L>, [bool; L]);
}

/// A `visit(lane, hit)` closure, shown one hit at a time ([`Tracer::trace_visit_lanes`]).
struct ClosureVisitor<F>(F);

impl<const L: usize, F: FnMut(usize, &StepHit) -> bool> LaneVisitor<L> for ClosureVisitor<F> {
    #[inline(always)]
    fn lane(&mut self, lane: usize, hit: &StepHit) -> bool {
        (self.0)(lane, hit)
    }

    #[inline(always)]
    fn sphere(
        &mut self,
        index: usize,
        step: &ResolvedStep,
        ray: &mut Columns<L>,
        alive: [bool; L],
    ) -> (SphereStep<L>, [bool; L]) {
        let next = sphere_step(ray, step, alive, |_, _, _, _, _| {});
        let stopped = std::array::from_fn(|lane| {
            alive[lane] && next.hit[lane] && {
                let hit = StepHit {
                    index,
                    surface: step.surface,
                    point_mm: DVec3::new(ray.px[lane], ray.py[lane], ray.pz[lane]),
                    cos_incidence: next.cos_i[lane].abs().min(1.0),
                    reflect: step.reflect,
                    semi_aperture_mm: step.semi_aperture_mm,
                };
                !(self.0)(lane, &hit)
            }
        });
        (next, stopped)
    }
}

/// What a ray-grid vertex records along its path ([`Tracer::trace_vertices`]).
pub struct VertexRecipe<'a> {
    /// Per step of the path: the reflectance of the surface side the light meets, sampled evenly over
    /// sin^2 i from 0 to 1 (at least 2 samples; all zero where it reflects nothing), read by linear
    /// interpolation.
    pub reflectance: &'a [std::sync::Arc<[f64]>],
    /// Per step: 1 / semi-aperture^2 (0 at the stop).
    pub inverse_semi_aperture2: &'a [f64],
    /// The stop's surface index.
    pub stop_surface: usize,
    /// The unit of the stop coordinates (mm).
    pub stop_radius_mm: f64,
}

/// What `L` rays recorded ([`VertexRecipe`]); meaningful for the lanes that landed.
#[derive(Clone, Copy, Debug)]
pub struct VertexRecord<const L: usize> {
    /// R at both reflections times 1 - R at every refraction, each at the ray's own angle of incidence.
    pub weight: [f64; L],
    /// The point of each of the first 3 stop crossings, in stop radii.
    pub stops: [[[f64; 2]; 3]; L],
    /// How many of `stops` were crossed.
    pub crossings: [usize; L],
    /// The largest (h / semi-aperture)^2 over the surfaces other than the stop.
    pub ratio2: [f64; L],
}

impl<const L: usize> VertexRecord<L> {
    fn new() -> Self {
        Self { weight: [1.0; L], stops: [[[0.0; 2]; 3]; L], crossings: [0; L], ratio2: [0.0; L] }
    }
}

/// A reflectance table `samples` (at least 2, evenly spaced over sin^2 i from 0 to 1) at sin^2 i = `sin2_i`
/// (clamped to [0, 1]), linearly interpolated: what `coating::ReflectanceTable::at` reads, and the one-lane
/// form of the tracer's vectorised read.
#[inline(always)]
pub(crate) fn table_at(samples: &[f64], sin2_i: f64) -> f64 {
    let n = samples.len();
    let x = sin2_i.clamp(0.0, 1.0) * (n - 1) as f64;
    let k = (x as usize).min(n - 2);
    let f = x - k as f64;
    samples[k] * (1.0 - f) + samples[k + 1] * f
}

/// Records a [`VertexRecipe`] for every lane ([`Tracer::trace_vertices`]).
struct RecipeVisitor<'a, 'r, const L: usize> {
    recipe: &'r VertexRecipe<'a>,
    record: VertexRecord<L>,
}

impl<const L: usize> RecipeVisitor<'_, '_, L> {
    #[inline(always)]
    fn record(
        &mut self,
        lane: usize,
        index: usize,
        surface: usize,
        point: [f64; 2],
        cos_incidence: f64,
        reflect: bool,
    ) {
        let r = table_at(&self.recipe.reflectance[index], 1.0 - cos_incidence * cos_incidence);
        self.record.weight[lane] *= if reflect { r } else { 1.0 - r };
        if surface == self.recipe.stop_surface {
            let k = self.record.crossings[lane];
            if k < 3 {
                let radius = self.recipe.stop_radius_mm;
                self.record.stops[lane][k] = [point[0] / radius, point[1] / radius];
                self.record.crossings[lane] = k + 1;
            }
        } else {
            let h2 = (point[0] * point[0] + point[1] * point[1]) * self.recipe.inverse_semi_aperture2[index];
            self.record.ratio2[lane] = self.record.ratio2[lane].max(h2);
        }
    }
}

impl<const L: usize> LaneVisitor<L> for RecipeVisitor<'_, '_, L> {
    #[inline(always)]
    fn lane(&mut self, lane: usize, hit: &StepHit) -> bool {
        self.record(lane, hit.index, hit.surface, [hit.point_mm.x, hit.point_mm.y], hit.cos_incidence, hit.reflect);
        true
    }

    #[inline(always)]
    fn sphere(
        &mut self,
        index: usize,
        step: &ResolvedStep,
        ray: &mut Columns<L>,
        alive: [bool; L],
    ) -> (SphereStep<L>, [bool; L]) {
        let samples: &[f64] = &self.recipe.reflectance[index];
        if step.surface == self.recipe.stop_surface || samples.len() < 2 {
            let next = sphere_step(ray, step, alive, |_, _, _, _, _| {});
            for lane in (0..L).filter(|&lane| alive[lane] && next.hit[lane]) {
                let point = [ray.px[lane], ray.py[lane]];
                self.record(lane, index, step.surface, point, next.cos_i[lane].abs().min(1.0), step.reflect);
            }
            return (next, [false; L]);
        }
        // Every lane at once, branch-free (a lane not met keeps what it had): the step's own loop keeps what
        // the record needs, then a second loop reads the table (gathers: on AVX2 the compiler leaves a loop
        // with gathers scalar, so they stay out of the step's loop). The arithmetic is `table_at`'s, with the
        // truncation of x >= 0 written as a floor (the same integer).
        let inverse = self.recipe.inverse_semi_aperture2[index];
        let last = samples.len() - 1;
        let (top, scale, reflect) = ((last - 1) as f64, last as f64, step.reflect);
        let (mut sin2, mut h2, mut met) = ([0.0; L], [0.0; L], [false; L]);
        let next = sphere_step(ray, step, alive, |l, lane_met, px, py, cos_i| {
            let cos_incidence = cos_i.abs().min(1.0);
            sin2[l] = if lane_met { 1.0 - cos_incidence * cos_incidence } else { 0.0 };
            h2[l] = (px * px + py * py) * inverse;
            met[l] = lane_met;
        });
        let (mut weight, mut ratio2) = (self.record.weight, self.record.ratio2);
        for l in 0..L {
            let x = sin2[l].clamp(0.0, 1.0) * scale;
            let k = x.floor().min(top);
            let f = x - k;
            // SAFETY: k is an integer in [0, last - 1] (x is in [0, last]: sin2 is 0 for a lane not met, and
            // within [0, 1] for one met, since min(1) makes a NaN cosine 1), so k and k + 1 index the table.
            let (lo, hi) = unsafe {
                // Through i32 (tables are far shorter): AVX2 converts f64 to i32 in vectors, not to i64.
                let k = k.to_int_unchecked::<i32>() as usize;
                (*samples.get_unchecked(k), *samples.get_unchecked(k + 1))
            };
            let r = lo * (1.0 - f) + hi * f;
            let factor = if reflect { r } else { 1.0 - r };
            let (w, q) = (weight[l] * factor, ratio2[l].max(h2[l]));
            weight[l] = if met[l] { w } else { weight[l] };
            ratio2[l] = if met[l] { q } else { ratio2[l] };
        }
        (self.record.weight, self.record.ratio2) = (weight, ratio2);
        (next, [false; L])
    }
}

/// The widest vector instructions [`Tracer::trace_visit_lanes`] may use here: 0 none beyond the baseline,
/// 1 AVX2, 2 AVX-512 (F, DQ and VL); detected once. `FLARELAB_SIMD=0|1|2` caps it (to compare the paths).
#[cfg(target_arch = "x86_64")]
pub(crate) fn simd_level() -> u8 {
    static LEVEL: std::sync::OnceLock<u8> = std::sync::OnceLock::new();
    *LEVEL.get_or_init(|| {
        let found = if is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512dq")
            && is_x86_feature_detected!("avx512vl")
        {
            2
        } else if is_x86_feature_detected!("avx2") {
            1
        } else {
            0
        };
        let cap = std::env::var("FLARELAB_SIMD").ok().and_then(|v| v.trim().parse::<u8>().ok()).unwrap_or(2);
        found.min(cap)
    })
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
pub(crate) const MAX_NEWTON_STEPS: usize = 40;

/// Distance along unit direction `d` from `p` (relative to the vertex) to the surface `shape`, on the branch
/// the sag describes; `None` when the line misses it (see the module's notes).
pub fn intersect_shape(p: DVec3, d: DVec3, shape: &SurfaceShape, z_dir: f64) -> Option<f64> {
    if shape.spherical {
        return intersect(p, d, shape.curvature_per_mm, z_dir);
    }
    if shape.toroidal {
        return intersect_toroid(p, d, shape);
    }
    let c = shape.curvature_per_mm;
    let q = 1.0 + shape.conic;
    // The quadric alone, by the same stable root as the sphere: a s^2 + 2 b s + g0 = 0.
    let g0 = c * (p.x * p.x + p.y * p.y + q * p.z * p.z) - 2.0 * p.z;
    let a = c * (d.x * d.x + d.y * d.y + q * d.z * d.z);
    let b = c * (p.x * d.x + p.y * d.y + q * p.z * d.z) - d.z;
    let disc = b * b - a * g0;
    let quadric = (disc >= 0.0).then(|| g0 / (z_dir * disc.sqrt() - b)).filter(|s| s.is_finite());
    let s = match quadric {
        Some(s) => s,
        None if d.z != 0.0 => -p.z / d.z,
        None => return None,
    };
    newton(p, d, s, |at| {
        let r2 = at.x * at.x + at.y * at.y;
        let f = at.z - shape.sag_mm(r2)?;
        Some((f, d.z - shape.slope_over_r(r2)? * (at.x * d.x + at.y * d.y)))
    })
}

/// Newton's method along the line `p + s d` from `s`: `residual(point)` gives `z - sag` there and its derivative
/// along the line, `None` where the sag is not defined. At most [`MAX_NEWTON_STEPS`] steps, until a step is
/// below 1e-13 of the distance; `None` on a zero derivative, a non-finite distance or no convergence.
fn newton(p: DVec3, d: DVec3, mut s: f64, residual: impl Fn(DVec3) -> Option<(f64, f64)>) -> Option<f64> {
    for _ in 0..MAX_NEWTON_STEPS {
        let (f, derivative) = residual(p + s * d)?;
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

/// A toroid (see [`crate::optics::lens`]): Newton's method on `z(s) - sag(x(s), y(s)) = 0` from where the line
/// meets the vertex plane, with the same stopping rule as the aspheres; `None` when the line runs parallel to
/// the vertex plane, leaves the region where the sag is defined, or does not converge.
fn intersect_toroid(p: DVec3, d: DVec3, shape: &SurfaceShape) -> Option<f64> {
    if d.z == 0.0 {
        return None;
    }
    newton(p, d, -p.z / d.z, |at| {
        let (z, [gx, gy]) = shape.toroid_sag_and_gradient(at.x, at.y)?;
        Some((at.z - z, d.z - gx * d.x - gy * d.y))
    })
}

/// Unit normal of `shape` at the point `p` (relative to the vertex, on the surface), pointing to +z at the
/// vertex; `None` where the slope is infinite (the rim of a sphere or ellipsoid met edge-on).
pub fn shape_normal(p: DVec3, shape: &SurfaceShape) -> Option<DVec3> {
    if shape.spherical {
        return Some(surface_normal(p, shape.curvature_per_mm));
    }
    if shape.toroidal {
        let [gx, gy] = shape.sag_gradient(p.x, p.y)?;
        let n = DVec3::new(-gx, -gy, 1.0);
        return Some(n / n.length());
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
    /// Every instruction-set variant of the tracer, 1 to 16 lanes, gives what one ray traced alone by the
    /// one-ray formulas gives, bit for bit: spherical, flat and aspheric surfaces, rays that land, miss, are
    /// totally reflected or turn back.
    /// A ray traced alone: its outcome, weight, ratio^2, stop crossings and their count.
    type Alone = (Result<Landing, TraceStatus>, f64, f64, [[f64; 2]; 3], usize);

    #[test]
    fn every_vector_variant_traces_exactly_as_one_ray() {
        use crate::optics::library::builtin_lens;
        use crate::optics::path::LightPath;
        for id in ["dgauss", "nikon_zoom", "aspheric_zoom", "heliar"] {
            let lens = builtin_lens(id).unwrap();
            let sensor_z = lens.vertex_z_mm().last().copied().unwrap() + 40.0;
            let ghosts = lens.ghost_pairs();
            let front = lens.surfaces[0].semi_aperture_mm;
            let (mut landed_total, mut failed_total) = (0, 0);
            for &(i, j) in ghosts.iter().step_by(ghosts.len() / 6 + 1) {
                let path = LightPath::ghost(&lens, i, j).unwrap();
                let tracer = Tracer::new(&lens, &path, 550.0, sensor_z);
                let tables: Vec<std::sync::Arc<[f64]>> = (0..path.steps.len())
                    .map(|k| (0..33).map(|n| ((n * 7 + k) % 11) as f64 / 40.0).collect())
                    .collect();
                let inverse: Vec<f64> =
                    path.steps.iter().map(|s| lens.surfaces[s.surface].semi_aperture_mm.powi(-2)).collect();
                let stop = lens.surfaces.iter().position(|s| s.stop).unwrap_or(usize::MAX);
                let recipe = VertexRecipe {
                    reflectance: &tables,
                    inverse_semi_aperture2: &inverse,
                    stop_surface: stop,
                    stop_radius_mm: 7.0,
                };
                // Rays over 1.6 x the front lens, from two directions (some miss, some reflect back).
                let rays: Vec<Ray> = (0..16 * 20)
                    .map(|k| {
                        let (x, y) = ((k % 20) as f64 / 19.0 - 0.5, (k / 20) as f64 / 15.0 - 0.5);
                        let tilt = if k % 3 == 0 { 0.4 } else { 0.05 };
                        Ray {
                            origin_mm: DVec3::new(1.6 * front * x, 1.6 * front * y, 0.0),
                            direction: DVec3::new(tilt * y, 0.1 * x, 1.0).normalize(),
                        }
                    })
                    .collect();
                // One ray alone, by the one-ray formulas (`step_ray`) and the visit the renderers used.
                let alone: Vec<_> = rays
                    .iter()
                    .map(|ray| {
                        let mut record = VertexRecord::<1>::new();
                        let mut visitor = RecipeVisitor { recipe: &recipe, record };
                        let mut d = ray.direction.normalize_or_zero();
                        let mut p = ray.origin_mm;
                        let mut outcome = Ok(());
                        for (index, step) in tracer.steps.iter().enumerate() {
                            let vertex = DVec3::new(0.0, 0.0, step.vertex_z_mm);
                            outcome = tracer.step_ray(index, step, vertex, &mut p, &mut d, |hit| visitor.lane(0, hit));
                            if outcome.is_err() {
                                break;
                            }
                        }
                        record = visitor.record;
                        let landing = outcome.and_then(|()| tracer.to_sensor(p, d));
                        (landing, record.weight[0], record.ratio2[0], record.stops[0], record.crossings[0])
                    })
                    .collect();
                let landed = alone.iter().filter(|a| a.0.is_ok()).count();
                (landed_total, failed_total) = (landed_total + landed, failed_total + rays.len() - landed);
                fn check<const L: usize>(
                    tracer: &Tracer,
                    recipe: &VertexRecipe,
                    rays: &[Ray],
                    alone: &[Alone],
                    what: &str,
                ) {
                    for level in 0..=2 {
                        for (group, expected) in rays.chunks(L).zip(alone.chunks(L)) {
                            let rays: [Ray; L] = std::array::from_fn(|l| group[l]);
                            let mut visitor = RecipeVisitor { recipe, record: VertexRecord::<L>::new() };
                            let outcome = tracer.trace_at_level(level, rays, &mut visitor);
                            let r = visitor.record;
                            for l in 0..L {
                                let e = &expected[l];
                                assert_eq!(outcome[l], e.0, "{what} level {level} lane {l}");
                                if e.0.is_ok() {
                                    assert_eq!(r.weight[l].to_bits(), e.1.to_bits(), "{what} weight");
                                    assert_eq!(r.ratio2[l].to_bits(), e.2.to_bits(), "{what} ratio");
                                    assert_eq!((r.stops[l], r.crossings[l]), (e.3, e.4), "{what} stops");
                                }
                            }
                            // The closure form of the same trace lands the same.
                            let landings = tracer.trace_visit_lanes(rays, |_, _| true);
                            assert_eq!(landings.to_vec(), expected.iter().map(|e| e.0).collect::<Vec<_>>(), "{what}");
                        }
                    }
                }
                let what = format!("{id} {i}-{j}");
                check::<1>(&tracer, &recipe, &rays, &alone, &what);
                check::<4>(&tracer, &recipe, &rays, &alone, &what);
                check::<8>(&tracer, &recipe, &rays, &alone, &what);
                check::<16>(&tracer, &recipe, &rays, &alone, &what);
            }
            assert!(landed_total >= 50 && failed_total >= 50, "{id}: {landed_total} landed, {failed_total} did not");
        }
    }

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
