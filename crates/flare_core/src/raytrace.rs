//! Ray-traced ghosts: the ground-truth reference renderer and Hullin et al. 2011's ray grids.
//!
//! # How it works
//! Nothing here is paraxial. Per ghost and wavelength (one job; jobs run in parallel with rayon, each into a
//! per-thread f64 image that is summed at the end) a regular grid of (N+1) x (N+1) rays leaves the entrance
//! plane (z = 0, the first vertex) in the light's direction and is traced exactly, in f64, along the ghost's
//! path ([`crate::optics::Tracer::trace_visit`]). Each ray records:
//! - where it lands on the sensor (the same plane and pixel mapping as the paraxial renderer);
//! - its **weight**: the reflectance R at both reflections times the transmittance 1 - R at every refraction,
//!   each at the ray's own angle of incidence and wavelength, with the surface's coating (dense tables of
//!   [`DENSE_TABLE_SAMPLES`] samples over sin^2 i from [`crate::coating`]);
//! - its coordinates at every stop crossing (1 or 3), in units of the stop radius at the chosen f-number;
//! - its largest relative height `h / semi-aperture` over every other surface it meets (Hullin's "relative
//!   radius").
//!
//! A ray that misses a surface, is totally internally reflected, or turns back for good is invalid; every
//! triangle touching it is dropped (its light really is lost). Each grid cell is split into two triangles and
//! **splatted with energy conserved**: a triangle carries `cos(theta) x (entrance area) x (mean weight)` of
//! the light (the irradiance on the entrance plane of a unit light is cos theta), spread over its footprint on
//! the sensor, so irradiance = that energy / sensor area: where rays bunch into a caustic, the image
//! brightens exactly as much as the footprint shrinks. The footprint is **box filtered**, as a sensor pixel
//! integrates: the triangle is clipped to each pixel it covers (`Polygon`) and the pixel gets the
//! irradiance times that area. The stop coordinates, relative radius and weight are interpolated
//! barycentrically at the centroid of each covered part; the aperture mask is looked up at every stop crossing
//! and multiplied (the stop's blade shape, anti-aliased; skipped when the triangle's corners all lie in the
//! disc where the mask is fully open), and a part whose interpolated relative radius exceeds 1 is vignetted.
//! Sampling at pixel centres instead aliases the grid into moire wherever triangles are a pixel or two across
//! (the folds of a caustic most), differently at every grid; the box filter does not. A triangle inside one
//! pixel, or collapsed to a line or a point (a ghost focused there), puts all of its light in that pixel: it
//! keeps its energy and stays finite.
//!
//! Where the grid lies: a pre-pass of a coarse grid over the whole front lens (a square of half-side the front
//! clear aperture plus the obliquity of its sag) finds the cells where some ray passes everything and lands in
//! the frame; the dense grid covers their bounding box grown by one coarse cell (light that lands off the frame
//! is not traced twice). When no coarse ray passes at all, it covers 1.25 x the paraxial entrance region instead
//! (only a hint of where to look, never a result), so a ghost smaller than a coarse cell is not missed. Inside
//! that box a dense ray is traced only in the lit cells of the pre-pass grown by one cell ([`LitCells`]): a
//! ghost's light is often a disc, a crescent or a ring, and the rays far from it carry none. A LUT bake first
//! **scouts** a ghost ([`RayGridRenderer::scout`]: a 32-cell pre-pass over the front lens, then 48 cells over
//! where light passed) to size its windows, and that scout grid, much finer than one over the whole front
//! lens, is then the render's pre-pass ([`RayGridRenderer::render_scouted`]).
//!
//! The two methods are this one algorithm at two densities ([`Grid`]):
//! - **reference** (adaptive, up to [`REFERENCE_GRID`] cells across, about two per pixel of the ghost's extent
//!   in the frame): the ground truth, converged (a test and `flarelab bench` show the image change falling as
//!   the grid doubles);
//! - **raygrid-N** (N = 16..128): Hullin et al. 2011's interactive method: a coarse grid of traced rays
//!   rasterised as triangles with the aperture looked up per pixel.

use glam::DVec3;
use rayon::prelude::*;

use crate::aperture::ApertureMask;
use crate::coating::InterfaceTables;
use crate::ghost::light_slopes_for_frame_position;
use crate::ghost::{GhostSystem, Sensor};
use crate::image::GhostMoments;
use crate::image::HdrImage;
use crate::optics::{LightPath, Ray, Tracer};

/// Most grid cells across a ghost's entrance region in the reference renderer (see the convergence table in the
/// README).
pub const REFERENCE_GRID: usize = 256;
/// Fewest grid cells across a ghost's entrance region in the reference renderer.
pub const REFERENCE_MIN_GRID: usize = 64;

/// How many rays a render traces per ghost and wavelength.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grid {
    /// N x N cells over every ghost's entrance region: Hullin 2011's ray grids.
    Fixed(usize),
    /// Up to N x N cells: about two cells per pixel of the ghost's extent in the frame (measured by the
    /// pre-pass), at least [`REFERENCE_MIN_GRID`], rounded up to a power of two: the reference, whose triangles
    /// are then at most about half a pixel on the sensor wherever they are not compressed into a caustic.
    Adaptive(usize),
}

impl Grid {
    /// The largest number of cells across.
    pub fn cells(self) -> usize {
        match self {
            Self::Fixed(n) | Self::Adaptive(n) => n,
        }
    }

    /// Cells across for a ghost extending `extent_px` pixels in the frame.
    fn for_extent(self, extent_px: f64) -> usize {
        match self {
            Self::Fixed(n) => n,
            Self::Adaptive(n) => {
                let wanted = (2.0 * extent_px).ceil().clamp(1.0, n as f64) as usize;
                wanted.next_power_of_two().clamp(REFERENCE_MIN_GRID.min(n), n)
            }
        }
    }
}
/// Samples of the ray-traced renderers' reflectance tables over sin^2(i).
pub const DENSE_TABLE_SAMPLES: usize = 1025;
/// The smallest and largest grid a ray-grid render accepts.
pub const GRID_RANGE: std::ops::RangeInclusive<usize> = 2..=4096;

/// The part of the sensor plane an image covers: a rectangle of centre `centre_mm` and width `width_mm`, drawn
/// `width` x `height` square pixels in the display orientation (the sensor rotated by 180 degrees, as
/// [`crate::ghost::sensor_to_pixel`] does for the whole frame). The whole frame is the window centred on the
/// axis with the sensor's width ([`Window::frame`]); a LUT bake uses a window around one ghost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub centre_mm: [f64; 2],
    pub width_mm: f64,
    pub width: u32,
    pub height: u32,
}

impl Window {
    /// The whole frame of a `width` x `height` image ([`Sensor::full_frame_for`]).
    pub fn frame(width: u32, height: u32) -> Self {
        Self { centre_mm: [0.0, 0.0], width_mm: Sensor::full_frame_for(width, height).width_mm, width, height }
    }

    /// Pixels per millimetre.
    pub fn px_per_mm(&self) -> f64 {
        f64::from(self.width) / self.width_mm
    }

    /// The pixel position of the sensor point `p_mm`.
    pub fn to_pixel(&self, p_mm: [f64; 2]) -> [f64; 2] {
        let k = self.px_per_mm();
        [
            0.5 * f64::from(self.width) - (p_mm[0] - self.centre_mm[0]) * k,
            0.5 * f64::from(self.height) + (p_mm[1] - self.centre_mm[1]) * k,
        ]
    }

    /// The sensor point at the pixel position `p` (the inverse of [`Self::to_pixel`]).
    pub fn to_mm(&self, p: [f64; 2]) -> [f64; 2] {
        let k = self.px_per_mm();
        [
            self.centre_mm[0] - (p[0] - 0.5 * f64::from(self.width)) / k,
            self.centre_mm[1] + (p[1] - 0.5 * f64::from(self.height)) / k,
        ]
    }
}

/// A window of the sensor plane seen with the light turned by `turn_deg` about the optical axis
/// (counter-clockwise, x right, y up) from the light a render is asked for ([`RayGridRenderer::render_turned`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub window: Window,
    pub turn_deg: f64,
}

impl View {
    /// What this view makes of a traced vertex: its landing point (sensor mm, in `v.pixel` when traced) and
    /// stop coordinates turned, the landing point then in the window's pixels. The turn's sine and cosine are
    /// taken once, here, not per vertex.
    fn seer(&self) -> impl Fn(&Vertex) -> Vertex + '_ {
        let (s, c) = self.turn_deg.to_radians().sin_cos();
        let turned = self.turn_deg != 0.0;
        move |v: &Vertex| {
            let turn = |p: [f64; 2]| if turned { [c * p[0] - s * p[1], s * p[0] + c * p[1]] } else { p };
            let mut seen = *v;
            seen.stops = v.stops.map(turn);
            seen.pixel = self.window.to_pixel(turn(v.pixel));
            seen.valid = v.valid && seen.pixel.iter().all(|c| c.is_finite());
            seen
        }
    }
}

/// What [`RayGridRenderer::scout`] found of one ghost for one light.
#[derive(Clone, Debug)]
pub struct Scout {
    pub ghost: usize,
    pub light_deg: [f64; 2],
    /// Per turn: where the ghost lands, `[x_min, y_min, x_max, y_max]` in sensor mm; `None` when nothing does.
    pub footprints_mm: Vec<Option<[f64; 4]>>,
    /// Per wavelength: the grid traced over the region of the entrance plane where its light passes; `None`
    /// where none does.
    grids: Vec<Option<TracedGrid>>,
}

/// A grid of `cells` x `cells` cells traced over `region` of the entrance plane: (cells + 1)^2 vertices, row
/// by row, in sensor mm (not yet seen by a view).
#[derive(Clone, Debug)]
struct TracedGrid {
    region: [f64; 4],
    cells: usize,
    vertices: Vec<Vertex>,
}

/// An empty bounding box `[x_min, y_min, x_max, y_max]`, for [`grow`].
const NO_BOUNDS: [f64; 4] = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];

/// The bounding box `b` grown to hold `p`.
fn grow(b: [f64; 4], p: [f64; 2]) -> [f64; 4] {
    [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])]
}

/// One ghost at one wavelength, ready to trace.
#[derive(Clone, Debug)]
struct Job {
    ghost: usize,
    wavelength: usize,
    tracer: Tracer,
    /// Per step of the path: the reflectance table of the surface side the light meets (a zero table where it
    /// reflects nothing, so that 1 - R = 1).
    step_tables: Vec<usize>,
    /// Per step: 1 / semi-aperture^2 (0 at the stop, whose aperture is the mask).
    inverse_semi_aperture2: Vec<f64>,
}

/// Everything a ray-traced render of one lens and configuration needs; made once, used for any light.
#[derive(Clone, Debug)]
pub struct RayGridRenderer {
    system: GhostSystem,
    mask: ApertureMask,
    /// The square of the radius (stop radii) within which the mask is fully open ([`ApertureMask::open_radius`]).
    open_radius2: f64,
    jobs: Vec<Job>,
    tables: InterfaceTables,
    stop: usize,
    /// Half-side of the square the pre-pass covers, before the light's obliquity: the front clear aperture.
    front_radius_mm: f64,
    /// |sag| of the front surface at its clear aperture.
    front_sag_mm: f64,
}

/// Counts of one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayGridStats {
    pub jobs: usize,
    pub rays: u64,
    pub triangles: u64,
    /// Jobs (ghost x wavelength) where no ray passed everything.
    pub empty_jobs: usize,
}

/// A ray-traced ghost image and what it is made of.
#[derive(Clone, Debug)]
pub struct RayGridImage {
    /// Linear irradiance relative to the light, ghosts only, `width` x `height`.
    pub hdr: HdrImage,
    /// Per ghost: luminance-weighted energy and its first moments, over the pixels in the frame.
    pub moments: Vec<GhostMoments>,
    pub stats: RayGridStats,
}

/// Why a ray-grid render is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RayGridError {
    #[error("grid {0}: use {min} to {max} cells across", min = GRID_RANGE.start(), max = GRID_RANGE.end())]
    Grid(usize),
    #[error("image size {0}x{1}: both sides must be at least 1 pixel")]
    Size(u32, u32),
    #[error("window width {0} mm: must be finite and positive, with a finite centre")]
    Window(f64),
    #[error("light angle {0:?} deg: each angle must be finite and within +-89 degrees")]
    Angle([f64; 2]),
}

/// One traced grid vertex.
#[derive(Clone, Copy, Debug, Default)]
struct Vertex {
    valid: bool,
    /// Landing point in image pixels.
    pixel: [f64; 2],
    /// Coordinates at each stop crossing, in stop radii.
    stops: [[f64; 2]; 3],
    /// Largest h / semi-aperture over the other surfaces.
    ratio: f64,
    weight: f64,
}

impl Vertex {
    /// Passes every aperture (the stop's unit square holds any mask).
    fn passes(&self, stop_count: usize) -> bool {
        self.valid
            && self.ratio <= 1.0
            && self.stops[..stop_count].iter().all(|s| s[0].abs() <= 1.0 && s[1].abs() <= 1.0)
    }
}

/// Per-thread accumulation: energy per pixel (relative irradiance x mm^2) and per-ghost moments.
struct Accumulator {
    width: usize,
    height: usize,
    energy: Vec<[f64; 3]>,
    moments: Vec<GhostMoments>,
    stats: RayGridStats,
}

impl Accumulator {
    fn new(width: usize, height: usize, ghosts: usize) -> Self {
        Self {
            width,
            height,
            energy: vec![[0.0; 3]; width * height],
            moments: vec![GhostMoments::default(); ghosts],
            stats: RayGridStats::default(),
        }
    }

    fn merge(mut self, other: Self) -> Self {
        for (a, b) in self.energy.iter_mut().zip(&other.energy) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
        for (a, b) in self.moments.iter_mut().zip(&other.moments) {
            a.add(b);
        }
        self.stats.jobs += other.stats.jobs;
        self.stats.rays += other.stats.rays;
        self.stats.triangles += other.stats.triangles;
        self.stats.empty_jobs += other.stats.empty_jobs;
        self
    }

    /// The image of `window`: energy per pixel / pixel area = irradiance; moments likewise in irradiance x
    /// pixel^2, as the paraxial renderer's.
    fn into_image(self, window: &Window) -> RayGridImage {
        let pixel_area_mm2 = window.px_per_mm().powi(-2);
        let moments = self
            .moments
            .iter()
            .map(|m| GhostMoments {
                energy: m.energy / pixel_area_mm2,
                sum_x: m.sum_x / pixel_area_mm2,
                sum_y: m.sum_y / pixel_area_mm2,
            })
            .collect();
        let pixels = self
            .energy
            .iter()
            .map(|e| {
                let v = e.map(|c| (c / pixel_area_mm2) as f32);
                let v = v.map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 });
                [v[0], v[1], v[2], 1.0]
            })
            .collect();
        RayGridImage {
            hdr: HdrImage { width: self.width as u32, height: self.height as u32, pixels },
            moments,
            stats: self.stats,
        }
    }

    /// Adds `energy` (scalar, before the spectral weight) at pixel (x, y) when it lies in the frame.
    fn add(&mut self, x: i64, y: i64, energy: f64, job: &JobFrame) {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 || energy.is_nan() || energy <= 0.0 {
            return;
        }
        let p = &mut self.energy[y as usize * self.width + x as usize];
        for (value, weight) in p.iter_mut().zip(job.rgb) {
            *value += energy * weight;
        }
        let luma = energy * job.luma;
        self.moments[job.ghost].add_sample(luma, [x as f64 + 0.5, y as f64 + 0.5]);
    }
}

/// What a job's triangles need besides their vertices.
struct JobFrame<'a> {
    ghost: usize,
    rgb: [f64; 3],
    luma: f64,
    stop_count: usize,
    mask: &'a ApertureMask,
    /// [`RayGridRenderer::open_radius2`].
    open_radius2: f64,
    /// cos(theta) x the entrance area of one triangle (mm^2).
    triangle_flux: f64,
}

impl RayGridRenderer {
    /// Prepares every ghost of `system` (its lens, spectrum, f-number and coatings) with the stop shape `mask`.
    pub fn new(system: &GhostSystem, mask: &ApertureMask) -> Self {
        let system = system.clone();
        let lens = &system.lens;
        let spectrum = &system.settings.spectrum;
        let sensor_z_mm = system.first_order.sensor_z_mm();
        let tables = InterfaceTables::new(
            lens,
            system.settings.coating_override.as_ref(),
            &spectrum.wavelengths_nm,
            DENSE_TABLE_SAMPLES,
        );
        let mut jobs = Vec::with_capacity(system.ghosts.len() * spectrum.len());
        for (g, ghost) in system.ghosts.iter().enumerate() {
            let path = LightPath::ghost(lens, ghost.i, ghost.j).expect("the ghost system lists valid ghosts");
            for (w, &wavelength_nm) in spectrum.wavelengths_nm.iter().enumerate() {
                let step_tables =
                    path.steps.iter().map(|s| tables.index(s.surface, s.arriving_direction < 0.0, w)).collect();
                let inverse_semi_aperture2 = path
                    .steps
                    .iter()
                    .map(|s| {
                        if lens.surfaces[s.surface].stop {
                            0.0
                        } else {
                            lens.surfaces[s.surface].semi_aperture_mm.powi(-2)
                        }
                    })
                    .collect();
                jobs.push(Job {
                    ghost: g,
                    wavelength: w,
                    tracer: Tracer::new(lens, &path, wavelength_nm, sensor_z_mm),
                    step_tables,
                    inverse_semi_aperture2,
                });
            }
        }
        let front = &lens.surfaces[0];
        let front_radius_mm = front.semi_aperture_mm;
        let front_sag_mm = front.sag_mm(front_radius_mm).unwrap_or(front_radius_mm).abs();
        let open_radius2 = f64::from(mask.open_radius()).powi(2);
        Self {
            stop: lens.stop_index(),
            mask: mask.clone(),
            open_radius2,
            system,
            jobs,
            tables,
            front_radius_mm,
            front_sag_mm,
        }
    }

    /// Number of ghosts (the length of [`RayGridImage::moments`]).
    pub fn ghost_count(&self) -> usize {
        self.system.ghosts.len()
    }

    /// Renders the ghosts for a light seen at the frame position `light_deg` (X right, Y up, degrees) into a
    /// `width` x `height` image with `grid` cells across each ghost's entrance region.
    pub fn render(
        &self,
        light_deg: [f64; 2],
        width: u32,
        height: u32,
        grid: Grid,
    ) -> Result<RayGridImage, RayGridError> {
        self.render_selected(light_deg, width, height, grid, |_| true)
    }

    /// [`Self::render`] of the ghosts for which `selected(ghost index)` is true only.
    pub fn render_selected(
        &self,
        light_deg: [f64; 2],
        width: u32,
        height: u32,
        grid: Grid,
        selected: impl Fn(usize) -> bool + Sync,
    ) -> Result<RayGridImage, RayGridError> {
        self.render_window(light_deg, &Window::frame(width, height), grid, selected)
    }

    /// [`Self::render_selected`] into any window of the sensor plane.
    pub fn render_window(
        &self,
        light_deg: [f64; 2],
        window: &Window,
        grid: Grid,
        selected: impl Fn(usize) -> bool + Sync,
    ) -> Result<RayGridImage, RayGridError> {
        let mut images = self.render_turned(light_deg, &[View { window: *window, turn_deg: 0.0 }], grid, selected)?;
        Ok(images.remove(0))
    }

    /// Renders several [`View`]s from one set of traced rays: view k is the image for the light turned by
    /// `turn_deg` about the optical axis, in its own window. A rotationally symmetric lens turns its image
    /// with the light, all but the stop: so each traced ray is turned (its landing point and its stop
    /// coordinates, where the mask is looked up) instead of traced again. This is how a LUT bake makes the
    /// azimuths of one theta for the price of one trace.
    pub fn render_turned(
        &self,
        light_deg: [f64; 2],
        views: &[View],
        grid: Grid,
        selected: impl Fn(usize) -> bool + Sync,
    ) -> Result<Vec<RayGridImage>, RayGridError> {
        self.render_views(light_deg, views, grid, |job: &Job| selected(job.ghost).then_some(None))
    }

    /// [`Self::render_turned`] of the ghost a [`Scout`] looked at, for its light: the scout's grid over the
    /// region where each wavelength's light passes is the pre-pass (finer than one over the whole front lens,
    /// and not traced again), and a wavelength where none passed is not traced at all.
    pub fn render_scouted(&self, scout: &Scout, views: &[View], grid: Grid) -> Result<Vec<RayGridImage>, RayGridError> {
        self.render_views(scout.light_deg, views, grid, |job: &Job| {
            if job.ghost != scout.ghost {
                return None;
            }
            scout.grids.get(job.wavelength).and_then(Option::as_ref).map(Some)
        })
    }

    /// Validates a request and renders it: `plan(job)` is `None` for a job not drawn, `Some(None)` for one
    /// whose pre-pass is traced over the whole front lens and `Some(Some(grid))` for one whose pre-pass is the
    /// scouted `grid`.
    fn render_views<'s>(
        &self,
        light_deg: [f64; 2],
        views: &[View],
        grid: Grid,
        plan: impl Fn(&Job) -> Option<Option<&'s TracedGrid>> + Sync,
    ) -> Result<Vec<RayGridImage>, RayGridError> {
        if !GRID_RANGE.contains(&grid.cells()) {
            return Err(RayGridError::Grid(grid.cells()));
        }
        for view in views {
            let window = &view.window;
            if window.width == 0 || window.height == 0 {
                return Err(RayGridError::Size(window.width, window.height));
            }
            if !(window.width_mm.is_finite()
                && window.width_mm > 0.0
                && window.centre_mm.iter().all(|c| c.is_finite())
                && view.turn_deg.is_finite())
            {
                return Err(RayGridError::Window(window.width_mm));
            }
        }
        if !light_deg.iter().all(|a| a.is_finite() && a.abs() <= 89.0) {
            return Err(RayGridError::Angle(light_deg));
        }
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        let ghosts = self.ghost_count();
        let fresh = || -> Vec<Accumulator> {
            views.iter().map(|v| Accumulator::new(v.window.width as usize, v.window.height as usize, ghosts)).collect()
        };
        let merge = |a: Vec<Accumulator>, b: Vec<Accumulator>| a.into_iter().zip(b).map(|(a, b)| a.merge(b)).collect();
        let accs = self
            .jobs
            .par_iter()
            .filter_map(|job| plan(job).map(|scouted| (job, scouted)))
            .fold(fresh, |mut accs, (job, scouted)| {
                self.render_job(job, u, views, grid, scouted, &mut accs);
                accs
            })
            .reduce(fresh, merge);
        Ok(views.iter().zip(accs).map(|(view, acc)| acc.into_image(&view.window)).collect())
    }

    /// Where ghost `ghost` lands on the sensor plane for a light at the frame position `light_deg`:
    /// `[x_min, y_min, x_max, y_max]` in sensor mm over every wavelength, from a `cells` x `cells` grid over the
    /// region where the pre-pass found light (each passing ray and its traced neighbours, so the partly lit
    /// cells at the rim are inside). `None` when no ray of the ghost passes.
    pub fn footprint_mm(&self, ghost: usize, light_deg: [f64; 2], cells: usize) -> Option<[f64; 4]> {
        self.footprints_turned_mm(ghost, light_deg, cells, &[0.0]).remove(0)
    }

    /// [`Self::footprint_mm`] for the light turned by each of `turns_deg` about the axis (see
    /// [`Self::render_turned`]), from one set of traced rays.
    pub fn footprints_turned_mm(
        &self,
        ghost: usize,
        light_deg: [f64; 2],
        cells: usize,
        turns_deg: &[f64],
    ) -> Vec<Option<[f64; 4]>> {
        self.scout(ghost, light_deg, cells, turns_deg).footprints_mm
    }

    /// A quick look at ghost `ghost` for the light at `light_deg`: its footprints as
    /// [`Self::footprints_turned_mm`] gives them, and per wavelength the region of the entrance plane where its
    /// light passes, which [`Self::render_scouted`] then covers instead of the whole front lens.
    pub fn scout(&self, ghost: usize, light_deg: [f64; 2], cells: usize, turns_deg: &[f64]) -> Scout {
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        // 1 px per mm over a metre: nothing the lens can image is off this window.
        let views: Vec<View> = turns_deg
            .iter()
            .map(|&turn_deg| View {
                window: Window { centre_mm: [0.0, 0.0], width_mm: 1000.0, width: 1000, height: 1000 },
                turn_deg,
            })
            .collect();
        let n = cells.clamp(4, 512);
        let mut bounds = vec![NO_BOUNDS; views.len()];
        let mut grids = vec![None; self.system.settings.spectrum.len()];
        let front = self.front_region(u);
        for job in self.jobs.iter().filter(|j| j.ghost == ghost) {
            let coarse = self.trace_grid(job, front, SCOUT_PRE_PASS_CELLS, d, None);
            let Some(pre) = self.pre_pass(job, u, &coarse, &views) else {
                continue;
            };
            // Only in the lit cells of the coarse pass, as a render's dense grid.
            let traced = self.trace_grid(job, pre.bounds, n, d, pre.lit.as_ref());
            let stop_count = self.stop_count(job);
            for (view, bounds) in views.iter().zip(&mut bounds) {
                let vertices: Vec<Vertex> = traced.vertices.iter().map(view.seer()).collect();
                for iy in 0..=n {
                    for ix in 0..=n {
                        if !vertices[iy * (n + 1) + ix].passes(stop_count) {
                            continue;
                        }
                        for (jx, jy) in (iy.saturating_sub(1)..=(iy + 1).min(n))
                            .flat_map(|jy| (ix.saturating_sub(1)..=(ix + 1).min(n)).map(move |jx| (jx, jy)))
                        {
                            let v = &vertices[jy * (n + 1) + jx];
                            if v.valid {
                                *bounds = grow(*bounds, view.window.to_mm(v.pixel));
                            }
                        }
                    }
                }
            }
            grids[job.wavelength] = Some(traced);
        }
        Scout {
            ghost,
            light_deg,
            footprints_mm: bounds.into_iter().map(|b| (b[0] <= b[2] && b[1] <= b[3]).then_some(b)).collect(),
            grids,
        }
    }

    /// How many stop crossings of `job` the masks look at (at most 3).
    fn stop_count(&self, job: &Job) -> usize {
        self.system.ghosts[job.ghost].per_wavelength[job.wavelength].matrices.stop_from_entrance.len().min(3)
    }

    /// Traces one ray of `job` from the entrance point `x0` (mm) in direction `d`; its `pixel` is the landing
    /// point in sensor mm until a [`View`] sees it.
    fn trace(&self, job: &Job, x0: [f64; 2], d: DVec3) -> Vertex {
        let ray = Ray { origin_mm: DVec3::new(x0[0], x0[1], 0.0), direction: d };
        let stop_radius = self.system.stop_radius_mm;
        let mut v = Vertex { weight: 1.0, ..Vertex::default() };
        let mut crossings = 0;
        let mut ratio2 = 0.0f64;
        let landing = job.tracer.trace_visit(&ray, |hit| {
            let sin2 = 1.0 - hit.cos_incidence * hit.cos_incidence;
            let r = self.tables.table(job.step_tables[hit.index]).at(sin2);
            v.weight *= if hit.reflect { r } else { 1.0 - r };
            let p = hit.point_mm;
            if hit.surface == self.stop {
                if crossings < 3 {
                    v.stops[crossings] = [p.x / stop_radius, p.y / stop_radius];
                    crossings += 1;
                }
            } else {
                ratio2 = ratio2.max((p.x * p.x + p.y * p.y) * job.inverse_semi_aperture2[hit.index]);
            }
            true
        });
        v.ratio = ratio2.sqrt();
        if let Ok(landing) = landing {
            let p = [landing.point_mm.x, landing.point_mm.y];
            v.valid = p.iter().all(|c| c.is_finite()) && v.weight.is_finite() && v.ratio.is_finite();
            v.pixel = p;
        }
        v
    }

    /// The square of the entrance plane, `[x_min, y_min, x_max, y_max]`, that a pre-pass over the whole front
    /// lens covers for the light slope `u`: half-side the front clear aperture plus the obliquity of its sag.
    fn front_region(&self, u: [f64; 2]) -> [f64; 4] {
        let half = self.front_radius_mm * 1.01 + u[0].hypot(u[1]) * self.front_sag_mm;
        [-half, -half, half, half]
    }

    /// Traces `job` on a `cells` x `cells` grid over `region` of the entrance plane, direction `d`; a ray outside
    /// `lit` (where given) is not traced and stays invalid.
    fn trace_grid(&self, job: &Job, region: [f64; 4], cells: usize, d: DVec3, lit: Option<&LitCells>) -> TracedGrid {
        let step = [(region[2] - region[0]) / cells as f64, (region[3] - region[1]) / cells as f64];
        let vertices = (0..=cells)
            .flat_map(|iy| (0..=cells).map(move |ix| (ix, iy)))
            .map(|(ix, iy)| {
                let x0 = [region[0] + ix as f64 * step[0], region[1] + iy as f64 * step[1]];
                if lit.is_some_and(|lit| !lit.contains(x0)) { Vertex::default() } else { self.trace(job, x0, d) }
            })
            .collect();
        TracedGrid { region, cells, vertices }
    }

    /// Where to lay the dense grid, from the pre-pass `traced`: see [`PrePass`]. `None` when no ray passes
    /// (the pre-pass found none and the paraxial region is empty too).
    fn pre_pass(&self, job: &Job, u: [f64; 2], traced: &TracedGrid, views: &[View]) -> Option<PrePass> {
        let half = self.front_region(u)[2];
        let (region, coarse) = (traced.region, traced.cells);
        let stop_count = self.stop_count(job);
        let step = [(region[2] - region[0]) / coarse as f64, (region[3] - region[1]) / coarse as f64];
        let n = coarse + 1;
        // The cells where light passes and lands in some view's frame (a cell's landings bound where its rays
        // land); the extent is the largest over the views.
        let (mut found, mut any_passes, mut extent_px) = (NO_BOUNDS, false, 0.0f64);
        let mut lit = vec![false; coarse * coarse];
        for view in views {
            let see = view.seer();
            let vertices: Vec<([f64; 2], Vertex)> = traced
                .vertices
                .iter()
                .enumerate()
                .map(|(k, v)| {
                    let x0 = [region[0] + (k % n) as f64 * step[0], region[1] + (k / n) as f64 * step[1]];
                    (x0, see(v))
                })
                .collect();
            let (w, h) = (f64::from(view.window.width), f64::from(view.window.height));
            let mut landed = NO_BOUNDS;
            for iy in 0..coarse {
                for ix in 0..coarse {
                    let corners =
                        [iy * n + ix, iy * n + ix + 1, (iy + 1) * n + ix, (iy + 1) * n + ix + 1].map(|k| &vertices[k]);
                    if !corners.iter().any(|(_, v)| v.passes(stop_count)) {
                        continue;
                    }
                    any_passes = true;
                    let footprint =
                        corners.iter().filter(|(_, v)| v.valid).fold(NO_BOUNDS, |b, (_, v)| grow(b, v.pixel));
                    if footprint[0] > w + 1.0 || footprint[1] > h + 1.0 || footprint[2] < -1.0 || footprint[3] < -1.0 {
                        continue;
                    }
                    lit[iy * coarse + ix] = true;
                    for (x0, v) in corners {
                        found = grow(found, *x0);
                        if v.passes(stop_count) {
                            landed = grow(landed, v.pixel);
                        }
                    }
                }
            }
            if landed[0].is_finite() {
                extent_px = extent_px
                    .max((landed[2].min(w) - landed[0].max(0.0)).max(landed[3].min(h) - landed[1].max(0.0)).max(0.0));
            }
        }
        let mut bounds = if found[0].is_finite() {
            [found[0] - step[0], found[1] - step[1], found[2] + step[0], found[3] + step[1]]
        } else {
            NO_BOUNDS
        };
        let mut lit = found[0].is_finite().then(|| LitCells::grown(region, step, coarse, &lit));
        if !any_passes {
            // No coarse ray passed: look where the paraxial entrance region is, in case the ghost is smaller
            // than a coarse cell (a hint of where to look, never a result), and trace all of it.
            let sprite = job.ghost * self.system.settings.spectrum.len() + job.wavelength;
            let front = self.system.sprite_masks(sprite, u).front_map;
            let rho = front.scale.abs() * self.system.front_radius_mm;
            let e = front.offset.map(|o| o * self.system.front_radius_mm);
            if rho > 0.0 && rho.is_finite() && e.iter().all(|c| c.is_finite()) {
                let r = 1.25 * rho;
                bounds = [e[0] - r, e[1] - r, e[0] + r, e[1] + r];
            }
            lit = None;
        }
        let bounds = [bounds[0].max(-half), bounds[1].max(-half), bounds[2].min(half), bounds[3].min(half)];
        (bounds[0] < bounds[2] && bounds[1] < bounds[3]).then_some(PrePass { bounds, extent_px, lit })
    }

    /// Traces `job` once and splats it into every view's accumulator (`accs[k]` for `views[k]`); the pre-pass
    /// is `scouted`, or traced over the whole front lens.
    fn render_job(
        &self,
        job: &Job,
        u: [f64; 2],
        views: &[View],
        grid: Grid,
        scouted: Option<&TracedGrid>,
        accs: &mut [Accumulator],
    ) {
        for acc in accs.iter_mut() {
            acc.stats.jobs += 1;
        }
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        let pre = match scouted {
            Some(traced) => self.pre_pass(job, u, traced, views),
            None => {
                let cells = (grid.cells() / 2).clamp(16, 64);
                let traced = self.trace_grid(job, self.front_region(u), cells, d, None);
                accs[0].stats.rays += traced.vertices.len() as u64;
                self.pre_pass(job, u, &traced, views)
            }
        };
        let Some(PrePass { bounds: b, extent_px, lit }) = pre else {
            for acc in accs.iter_mut() {
                acc.stats.empty_jobs += 1;
            }
            return;
        };
        let grid = grid.for_extent(extent_px);
        let weights = self.system.settings.spectrum.weights_rgb[job.wavelength];
        let frame = JobFrame {
            ghost: job.ghost,
            rgb: weights,
            luma: crate::metrics::luminance(weights),
            stop_count: self.stop_count(job),
            mask: &self.mask,
            open_radius2: self.open_radius2,
            triangle_flux: d.z * 0.5 * (b[2] - b[0]) * (b[3] - b[1]) / (grid * grid) as f64,
        };
        let (dx, dy) = ((b[2] - b[0]) / grid as f64, (b[3] - b[1]) / grid as f64);
        let mut traced: Vec<Vertex> = Vec::with_capacity(grid + 1);
        // Per view: the previous and the current row as it sees them.
        let mut previous: Vec<Vec<Vertex>> = vec![Vec::with_capacity(grid + 1); views.len()];
        let mut current: Vec<Vec<Vertex>> = vec![Vec::with_capacity(grid + 1); views.len()];
        let mut any = vec![false; views.len()];
        let seers: Vec<_> = views.iter().map(View::seer).collect();
        for iy in 0..=grid {
            traced.clear();
            let mut rays = 0;
            for ix in 0..=grid {
                let x0 = [b[0] + ix as f64 * dx, b[1] + iy as f64 * dy];
                // Far from every lit cell of the pre-pass: no triangle of this ray carries light.
                if lit.as_ref().is_some_and(|lit| !lit.contains(x0)) {
                    traced.push(Vertex::default());
                    continue;
                }
                traced.push(self.trace(job, x0, d));
                rays += 1;
            }
            accs[0].stats.rays += rays;
            for k in 0..views.len() {
                current[k].clear();
                current[k].extend(traced.iter().map(&seers[k]));
                if iy > 0 {
                    let (previous, current, acc) = (&previous[k], &current[k], &mut accs[k]);
                    for ix in 0..grid {
                        let (v00, v10, v01, v11) = (&previous[ix], &previous[ix + 1], &current[ix], &current[ix + 1]);
                        for tri in [[v00, v10, v11], [v00, v11, v01]] {
                            if splat_triangle(tri, &frame, acc) {
                                acc.stats.triangles += 1;
                                any[k] = true;
                            }
                        }
                    }
                }
            }
            std::mem::swap(&mut previous, &mut current);
        }
        for (acc, any) in accs.iter_mut().zip(any) {
            if !any {
                acc.stats.empty_jobs += 1;
            }
        }
    }
}

/// Cells of the scout's pre-pass over the front lens.
const SCOUT_PRE_PASS_CELLS: usize = 32;

/// What a pre-pass found for one job.
struct PrePass {
    /// Where the dense grid lies on the entrance plane, `[x_min, y_min, x_max, y_max]`: the bounding box of the
    /// lit cells grown by one cell, within the front lens.
    bounds: [f64; 4],
    /// The extent in pixels (the larger side of the bounding box, clipped to the frame) of where the passing
    /// rays land, largest over the views.
    extent_px: f64,
    /// The lit cells, grown by one; `None` when the pre-pass saw no ray pass (the dense grid then traces all
    /// of its bounds).
    lit: Option<LitCells>,
}

/// The cells of a pre-pass where some corner ray passes everything and lands in some view's frame, grown by
/// one cell each way (so that the dense triangles at the rim, half lit, are traced too). A dense ray outside
/// them is not traced: inside the bounding box, a ghost's light is often a disc, a crescent or a ring.
struct LitCells {
    origin: [f64; 2],
    step: [f64; 2],
    cells: usize,
    lit: Vec<bool>,
}

impl LitCells {
    fn grown(region: [f64; 4], step: [f64; 2], cells: usize, lit: &[bool]) -> Self {
        let mut grown = vec![false; cells * cells];
        for iy in 0..cells {
            for ix in 0..cells {
                if lit[iy * cells + ix] {
                    for jy in iy.saturating_sub(1)..=(iy + 1).min(cells - 1) {
                        for jx in ix.saturating_sub(1)..=(ix + 1).min(cells - 1) {
                            grown[jy * cells + jx] = true;
                        }
                    }
                }
            }
        }
        Self { origin: [region[0], region[1]], step, cells, lit: grown }
    }

    /// Whether the entrance point `p` lies in a lit cell (a point on a cell boundary belongs to both).
    fn contains(&self, p: [f64; 2]) -> bool {
        let cell = |axis: usize| -> (usize, usize) {
            let f = (p[axis] - self.origin[axis]) / self.step[axis];
            let lo = (f.floor().max(0.0) as usize).min(self.cells - 1);
            let hi = ((f.ceil() - 1.0).max(0.0) as usize).min(self.cells - 1);
            (lo.min(hi), lo.max(hi))
        };
        let ((x0, x1), (y0, y1)) = (cell(0), cell(1));
        (y0..=y1).any(|y| (x0..=x1).any(|x| self.lit[y * self.cells + x]))
    }
}

/// A quantity linear over a triangle: `a0 + ax x + ay y` at the pixel position (x, y).
#[derive(Clone, Copy, Debug)]
struct Plane {
    a0: f64,
    ax: f64,
    ay: f64,
}

impl Plane {
    fn at(&self, p: [f64; 2]) -> f64 {
        self.a0 + self.ax * p[0] + self.ay * p[1]
    }
}

/// Barycentric interpolation over one triangle in pixel space: the three barycentric coordinates as planes.
struct Interpolator {
    bary: [Plane; 3],
}

impl Interpolator {
    /// `None` for a triangle of zero area.
    fn new(v: [[f64; 2]; 3]) -> Option<Self> {
        let area2 = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
        if area2 == 0.0 || !area2.is_finite() {
            return None;
        }
        // l_i is the edge function of the opposite edge (q, r) over twice the area.
        let plane = |q: [f64; 2], r: [f64; 2]| Plane {
            a0: (q[0] * r[1] - q[1] * r[0]) / area2,
            ax: (q[1] - r[1]) / area2,
            ay: (r[0] - q[0]) / area2,
        };
        Some(Self { bary: [plane(v[1], v[2]), plane(v[2], v[0]), plane(v[0], v[1])] })
    }

    /// The plane of a quantity with values `f` at the three vertices.
    fn attribute(&self, f: [f64; 3]) -> Plane {
        let [l0, l1, l2] = self.bary;
        Plane {
            a0: l0.a0 * f[0] + l1.a0 * f[1] + l2.a0 * f[2],
            ax: l0.ax * f[0] + l1.ax * f[1] + l2.ax * f[2],
            ay: l0.ay * f[0] + l1.ay * f[1] + l2.ay * f[2],
        }
    }
}

/// The attributes of one triangle as planes: the light passing at a pixel is `shade`.
struct TriangleShader<'a> {
    ratio: Plane,
    weight: Plane,
    stops: [[Plane; 2]; 3],
    /// Every stop crossing of the triangle lies in the disc where the mask is fully open (the stop coordinates
    /// are linear over it, so it does if its corners do): no mask lookup needed.
    open: bool,
    frame: &'a JobFrame<'a>,
}

impl<'a> TriangleShader<'a> {
    fn new(tri: [&Vertex; 3], interp: &Interpolator, frame: &'a JobFrame<'a>) -> Self {
        let attr = |f: &dyn Fn(&Vertex) -> f64| interp.attribute([f(tri[0]), f(tri[1]), f(tri[2])]);
        Self {
            ratio: attr(&|v| v.ratio),
            weight: attr(&|v| v.weight),
            stops: std::array::from_fn(|k| {
                if k < frame.stop_count {
                    [attr(&|v| v.stops[k][0]), attr(&|v| v.stops[k][1])]
                } else {
                    [Plane { a0: 0.0, ax: 0.0, ay: 0.0 }; 2]
                }
            }),
            open: Self::open(tri, frame),
            frame,
        }
    }

    /// The attributes averaged over the vertices, constant: for a triangle collapsed to a line or a point.
    fn mean(tri: [&Vertex; 3], frame: &'a JobFrame<'a>) -> Self {
        let mean = |f: &dyn Fn(&Vertex) -> f64| {
            let value = (f(tri[0]) + f(tri[1]) + f(tri[2])) / 3.0;
            Plane { a0: value, ax: 0.0, ay: 0.0 }
        };
        Self {
            ratio: mean(&|v| v.ratio),
            weight: mean(&|v| v.weight),
            stops: std::array::from_fn(|k| [mean(&|v| v.stops[k][0]), mean(&|v| v.stops[k][1])]),
            open: Self::open(tri, frame),
            frame,
        }
    }

    fn open(tri: [&Vertex; 3], frame: &JobFrame) -> bool {
        let inside = |s: [f64; 2]| s[0] * s[0] + s[1] * s[1] < frame.open_radius2;
        tri.iter().all(|v| v.stops[..frame.stop_count].iter().all(|&s| inside(s)))
    }

    /// Weight x aperture masks at the pixel position `p`; 0 where vignetted.
    fn shade(&self, p: [f64; 2]) -> f64 {
        if self.ratio.at(p) > 1.0 {
            return 0.0;
        }
        let mut m = self.weight.at(p).max(0.0);
        if self.open {
            return m;
        }
        for [su, sv] in &self.stops[..self.frame.stop_count] {
            if m == 0.0 {
                break;
            }
            m *= f64::from(self.frame.mask.sample(su.at(p) as f32, sv.at(p) as f32));
        }
        m
    }
}

/// Splats one triangle with its energy conserved; `false` when it carries no light.
fn splat_triangle(tri: [&Vertex; 3], frame: &JobFrame, acc: &mut Accumulator) -> bool {
    if !tri.iter().all(|v| v.valid) || tri.iter().all(|v| v.ratio > 1.0) {
        return false;
    }
    // Entirely outside the mask's square on one side at some crossing: nothing passes.
    for k in 0..frame.stop_count {
        for axis in 0..2 {
            if tri.iter().all(|v| v.stops[k][axis] > 1.0) || tri.iter().all(|v| v.stops[k][axis] < -1.0) {
                return false;
            }
        }
    }
    let pixels = [tri[0].pixel, tri[1].pixel, tri[2].pixel];
    let x_lo = pixels.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let x_hi = pixels.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
    let y_lo = pixels.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let y_hi = pixels.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let (w, h) = (acc.width as f64, acc.height as f64);
    if x_lo > w + 1.0 || y_lo > h + 1.0 || x_hi < -1.0 || y_hi < -1.0 {
        return true; // Its light is real but lands off the frame.
    }
    let at = |l: [f64; 3]| [0, 1].map(|c| l[0] * pixels[0][c] + l[1] * pixels[1][c] + l[2] * pixels[2][c]);
    let Some(interp) = Interpolator::new(pixels) else {
        // Collapsed to a line or a point (a ghost focused there): all of its energy in the pixel of its centroid.
        let c = at([1.0 / 3.0; 3]);
        let energy = frame.triangle_flux * TriangleShader::mean(tri, frame).shade(c);
        acc.add(c[0].floor() as i64, c[1].floor() as i64, energy, frame);
        return true;
    };
    let shader = TriangleShader::new(tri, &interp, frame);
    let b = &interp.bary;
    let area_px = 0.5 / (b[0].ax * b[1].ay - b[0].ay * b[1].ax).abs();
    let (col, row) = (x_lo.floor(), y_lo.floor());
    if x_hi < col + 1.0 && y_hi < row + 1.0 {
        // Inside one pixel: all of it there.
        acc.add(col as i64, row as i64, frame.triangle_flux * shader.shade(at([1.0 / 3.0; 3])), frame);
        return true;
    }
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies.
    let irradiance = frame.triangle_flux / area_px;
    // The part in the frame, cut into rows, each row into pixels.
    let mut rows = Polygon::triangle(pixels);
    if x_lo < 0.0 || y_lo < 0.0 || x_hi > w || y_hi > h {
        rows = rows.clip(0, 0.0, false).clip(0, w, true).clip(1, 0.0, false).clip(1, h, true);
    }
    let Some([_, y_first, ..]) = rows.bounds() else { return true };
    let mut y = y_first.floor();
    while rows.count >= 3 {
        let mut columns = rows.cut_below(1, y + 1.0);
        if let Some([x_first, ..]) = columns.bounds() {
            let mut x = x_first.floor();
            while columns.count >= 3 {
                let piece = columns.cut_below(0, x + 1.0);
                if let Some((area, centroid)) = piece.area_centroid() {
                    acc.add(x as i64, y as i64, irradiance * area * shader.shade(centroid), frame);
                }
                x += 1.0;
            }
        }
        y += 1.0;
    }
    true
}

/// A convex polygon in pixel space: a triangle clipped to an axis-aligned box (the frame, a row of it, a pixel),
/// so at most seven vertices (each side of the box adds at most one).
#[derive(Clone, Copy)]
struct Polygon {
    vertices: [[f64; 2]; 8],
    count: usize,
}

impl Polygon {
    const EMPTY: Self = Self { vertices: [[0.0; 2]; 8], count: 0 };

    fn triangle(v: [[f64; 2]; 3]) -> Self {
        let mut vertices = [[0.0; 2]; 8];
        vertices[..3].copy_from_slice(&v);
        Self { vertices, count: 3 }
    }

    /// Cuts off and returns the part with `p[axis] <= at`, keeping the rest.
    fn cut_below(&mut self, axis: usize, at: f64) -> Self {
        let (lower, upper) = self.split(axis, at);
        *self = upper;
        lower
    }

    /// The part with `p[axis] <= at` (`below`) or `p[axis] >= at`.
    fn clip(&self, axis: usize, at: f64, below: bool) -> Self {
        let (lower, upper) = self.split(axis, at);
        if below { lower } else { upper }
    }

    /// The parts with `p[axis] <= at` and with `p[axis] >= at` (Sutherland-Hodgman against one line, both sides
    /// in one pass).
    fn split(&self, axis: usize, at: f64) -> (Self, Self) {
        let vertices = &self.vertices[..self.count];
        let empty = Self::EMPTY;
        if vertices.iter().all(|p| p[axis] <= at) {
            return (*self, empty);
        }
        if vertices.iter().all(|p| p[axis] >= at) {
            return (empty, *self);
        }
        let (mut lower, mut upper) = (empty, empty);
        let push = |poly: &mut Self, p: [f64; 2]| {
            if poly.count < poly.vertices.len() {
                poly.vertices[poly.count] = p;
                poly.count += 1;
            }
        };
        let mut a = vertices[vertices.len() - 1];
        for &b in vertices {
            if a[axis] <= at {
                push(&mut lower, a);
            }
            if a[axis] >= at {
                push(&mut upper, a);
            }
            if (a[axis] < at && b[axis] > at) || (a[axis] > at && b[axis] < at) {
                // The edge crosses the line (so its ends differ along `axis`): the crossing belongs to both.
                let t = (at - a[axis]) / (b[axis] - a[axis]);
                let mut p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                p[axis] = at;
                push(&mut lower, p);
                push(&mut upper, p);
            }
            a = b;
        }
        (lower, upper)
    }

    /// `[x_min, y_min, x_max, y_max]`, `None` when the polygon is empty.
    fn bounds(&self) -> Option<[f64; 4]> {
        (self.count >= 3).then(|| {
            self.vertices[..self.count]
                .iter()
                .fold([f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |b, p| {
                    [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])]
                })
        })
    }

    /// Area (px^2) and centroid; `None` when empty or of no area.
    fn area_centroid(&self) -> Option<(f64, [f64; 2])> {
        if self.count < 3 {
            return None;
        }
        let o = self.vertices[0];
        let (mut area2, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for i in 1..self.count - 1 {
            let (a, b) = (self.vertices[i], self.vertices[i + 1]);
            let (ax, ay, bx, by) = (a[0] - o[0], a[1] - o[1], b[0] - o[0], b[1] - o[1]);
            let cross = ax * by - ay * bx;
            area2 += cross;
            cx += cross * (ax + bx);
            cy += cross * (ay + by);
        }
        (area2 != 0.0 && area2.is_finite())
            .then(|| (0.5 * area2.abs(), [o[0] + cx / (3.0 * area2), o[1] + cy / (3.0 * area2)]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flare::FlareConfig;
    use crate::optics::library::builtin_lens;

    fn renderer(id: &str) -> RayGridRenderer {
        let flare = crate::flare::PreparedFlare::new(&builtin_lens(id).unwrap(), &FlareConfig::default()).unwrap();
        RayGridRenderer::new(&flare.system, &flare.mask)
    }

    #[test]
    fn refuses_bad_requests() {
        let r = renderer("tessar");
        assert_eq!(r.render([0.0, 0.0], 32, 32, Grid::Fixed(1)).unwrap_err(), RayGridError::Grid(1));
        assert_eq!(r.render([0.0, 0.0], 0, 32, Grid::Adaptive(16)).unwrap_err(), RayGridError::Size(0, 32));
        assert!(matches!(r.render([f64::NAN, 0.0], 32, 32, Grid::Fixed(16)), Err(RayGridError::Angle(_))));
    }

    #[test]
    fn images_are_finite_and_non_negative_at_0_and_89_degrees() {
        let r = renderer("dgauss");
        for light in [[0.0, 0.0], [0.0, 89.0], [89.0, -89.0], [3.0, 12.0]] {
            let image = r.render(light, 48, 32, Grid::Fixed(16)).unwrap();
            assert!(image.hdr.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "{light:?}");
            assert!(image.moments.iter().all(|m| m.energy.is_finite() && m.energy >= 0.0));
            assert_eq!(image.stats.jobs, r.ghost_count() * 3);
        }
    }

    #[test]
    fn a_point_focused_triangle_keeps_its_energy() {
        let mask = crate::aperture::Aperture::default().rasterise(64);
        let frame = JobFrame {
            ghost: 0,
            rgb: [1.0, 1.0, 1.0],
            luma: 1.0,
            stop_count: 1,
            mask: &mask,
            open_radius2: 0.0,
            triangle_flux: 2.0,
        };
        let v = Vertex { valid: true, pixel: [10.3, 7.6], stops: [[0.0; 2]; 3], ratio: 0.5, weight: 0.25 };
        let mut acc = Accumulator::new(20, 20, 1);
        assert!(splat_triangle([&v, &v, &v], &frame, &mut acc));
        let total: f64 = acc.energy.iter().map(|p| p[0]).sum();
        assert!((total - 0.5).abs() < 1e-12, "{total}");
        // A large triangle: irradiance = flux / area, times the area it covers of each pixel.
        let tri = [[2.0, 2.0], [18.0, 2.0], [2.0, 18.0]].map(|pixel| Vertex { pixel, ..v });
        let mut acc = Accumulator::new(20, 20, 1);
        splat_triangle([&tri[0], &tri[1], &tri[2]], &frame, &mut acc);
        let total: f64 = acc.energy.iter().map(|p| p[0]).sum();
        assert!((total / 0.5 - 1.0).abs() < 1e-9, "box-filtered energy {total} vs 0.5");
        // Partly off the frame: what lands in it is its share by area (x >= 0: a quarter of this one).
        let tri = [[-8.0, 2.0], [8.0, 2.0], [-8.0, 18.0]].map(|pixel| Vertex { pixel, ..v });
        let mut acc = Accumulator::new(20, 20, 1);
        splat_triangle([&tri[0], &tri[1], &tri[2]], &frame, &mut acc);
        let total: f64 = acc.energy.iter().map(|p| p[0]).sum();
        assert!((total / 0.125 - 1.0).abs() < 1e-9, "{total} vs 1/4 of 0.5");
    }

    /// A mesh of triangles a pixel or so across, of one irradiance, tiles a region: every pixel inside it gets
    /// exactly that irradiance (no moire from the grid), whatever the mesh's scale, skew and offset.
    #[test]
    fn a_uniform_mesh_splats_a_uniform_image() {
        let mask = crate::aperture::Aperture::default().rasterise(64);
        let v = Vertex { valid: true, pixel: [0.0; 2], stops: [[0.0; 2]; 3], ratio: 0.5, weight: 1.0 };
        for (step, skew, offset) in [(1.37, 0.21, [3.3, 2.9]), (0.71, -0.4, [4.05, 3.5]), (2.3, 0.0, [2.5, 2.5])] {
            // Cells are parallelograms of area step^2, each two triangles of half that.
            let frame = JobFrame {
                ghost: 0,
                rgb: [1.0; 3],
                luma: 1.0,
                stop_count: 1,
                mask: &mask,
                open_radius2: f64::from(mask.open_radius()).powi(2),
                triangle_flux: 0.5 * step * step,
            };
            let n = (24.0 / step) as usize;
            let at = |i: usize, j: usize| {
                let (x, y) = (i as f64 * step, j as f64 * step);
                Vertex { pixel: [offset[0] + x + skew * y, offset[1] + y], ..v }
            };
            let mut acc = Accumulator::new(32, 32, 1);
            for j in 0..n {
                for i in 0..n {
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                    assert!(splat_triangle([&a, &b, &d], &frame, &mut acc));
                    assert!(splat_triangle([&a, &d, &c], &frame, &mut acc));
                }
            }
            // Pixels well inside the mesh: irradiance 1 (energy per unit area; a pixel is 1 x 1).
            let inside = (0..32 * 32).filter(|k| {
                let (x, y) = ((k % 32) as f64, (k / 32) as f64);
                let (y0, y1) = (offset[1] + 1.0, offset[1] + n as f64 * step - 2.0);
                let x_at = |y: f64| offset[0] + skew * (y - offset[1]);
                y > y0
                    && y + 1.0 < y1
                    && x > x_at(y).max(x_at(y + 1.0)) + 1.0
                    && x + 2.0 < x_at(y).min(x_at(y + 1.0)) + n as f64 * step
            });
            let mut count = 0;
            for k in inside {
                assert!((acc.energy[k][0] - 1.0).abs() < 1e-9, "step {step}: pixel {k} got {}", acc.energy[k][0]);
                count += 1;
            }
            assert!(count > 100, "step {step}: only {count} pixels inside");
        }
    }
}
