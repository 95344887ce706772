//! Planning and tracing: the jobs (one per ghost and wavelength) of a [`RayGridRenderer`], the pre-pass that
//! finds where light passes, the scout of a LUT bake, and the one entry point every ray-traced image goes
//! through ([`RayGridRenderer::render_request`]). A request may leave out the jobs too dim to see ([`Dim`]):
//! each traced job's peak is bounded from its triangles (`PeakTiles`) and the faintest go while their peaks
//! sum to at most the frame's threshold, the paraxial sprites' rule.

use glam::DVec3;
use rayon::prelude::*;

use crate::aperture::ApertureMask;
use crate::coating::InterfaceTables;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::optics::sensor::light_slopes_for_frame_position;
use crate::optics::{Coating, Lens, LightPath, Ray, Tracer, VertexRecipe};
use crate::spectrum::Spectrum;

use super::grid::*;
use super::splat::*;

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
pub(super) struct TracedGrid {
    region: [f64; 4],
    cells: usize,
    vertices: Vec<Vertex>,
}
/// Which ghosts a ray-grid render draws.
#[derive(Clone, Copy, Debug)]
pub enum Ghosts<'a> {
    /// Every ghost of the lens.
    All,
    /// One ghost (its index in the lens's ghost list).
    Only(usize),
    /// The ghost a [`Scout`] looked at, for the scout's light, with its grid as the pre-pass.
    Scouted(&'a Scout),
    /// Every ghost `g` at the gain `gains[g]` (as a frame's sprites: a preset's per-ghost gains, `enabled` and
    /// `solo`; missing entries are 1; a ghost at gain 0, or one that is not finite and positive, is not traced).
    Weighted(&'a [f32]),
}

/// Which of a request's jobs (ghost x wavelength) are left out as too dim to see.
#[derive(Clone, Copy, Debug, Default)]
pub enum Dim<'a> {
    /// Every job with light is drawn (a LUT bake, the reference, a test).
    #[default]
    Drawn,
    /// The faintest jobs are left out, as many as can go while their peaks sum to at most this (relative
    /// irradiance, the image's unit, gains included): the paraxial sprites' rule
    /// ([`crate::ghost::FrameSettings::intensity_threshold`]), so what is left out adds at most this to any
    /// pixel, however many overlap. A job's peak is a bound worked out from its traced triangles (see
    /// [`RayGridRenderer::render_request`]), never an estimate.
    Below(f64),
    /// The jobs whose entry (by the renderer's job order, [`RayGridRenderer::dim_jobs`]) is `true` are left out:
    /// a ghost's own layer left out as its whole frame decided. A job past the slice's end is drawn (an empty
    /// slice draws every job).
    Skip(&'a [bool]),
}

/// One ray-grid render (see [`RayGridRenderer::render_request`]): a light, the views it is seen in, the grid
/// and the ghosts.
#[derive(Clone, Debug)]
pub struct RayGridRequest<'a> {
    /// Where the light appears in the frame (X right, Y up, degrees); a scouted request uses the scout's.
    pub light_deg: [f64; 2],
    /// Windows of the sensor plane, each with the light turned about the axis by its `turn_deg`.
    pub views: Vec<View>,
    pub grid: Grid,
    pub ghosts: Ghosts<'a>,
    /// When set, the render stops at its next ghost and wavelength and answers [`RayGridError::Cancelled`]
    /// (a job the user cancelled stops within one ghost's trace, its threads free for the next).
    pub cancel: Option<&'a AtomicBool>,
    /// Which jobs are left out as too dim to see ([`Dim::Drawn`]: none).
    pub dim: Dim<'a>,
}

impl<'a> RayGridRequest<'a> {
    /// Every ghost in a `width` x `height` frame on the full-frame sensor.
    pub fn frame(light_deg: [f64; 2], width: u32, height: u32, grid: Grid) -> Self {
        Self::frame_on(light_deg, crate::optics::sensor::FULL_FRAME_WIDTH_MM, width, height, grid)
    }

    /// Every ghost in a `width` x `height` frame on a sensor `sensor_width_mm` wide (a look's own sensor).
    pub fn frame_on(light_deg: [f64; 2], sensor_width_mm: f64, width: u32, height: u32, grid: Grid) -> Self {
        let window = Window::for_sensor(sensor_width_mm, width, height);
        Self::views(light_deg, vec![View { window, turn_deg: 0.0 }], grid)
    }

    /// Every ghost in `views`.
    pub fn views(light_deg: [f64; 2], views: Vec<View>, grid: Grid) -> Self {
        Self { light_deg, views, grid, ghosts: Ghosts::All, cancel: None, dim: Dim::Drawn }
    }

    /// The scouted ghost, for the scout's light, in `views`.
    pub fn scouted(scout: &'a Scout, views: Vec<View>, grid: Grid) -> Self {
        Self { light_deg: scout.light_deg, views, grid, ghosts: Ghosts::Scouted(scout), cancel: None, dim: Dim::Drawn }
    }

    /// This request for ghost `ghost` only.
    pub fn only(self, ghost: usize) -> Self {
        Self { ghosts: Ghosts::Only(ghost), ..self }
    }

    /// This request with every ghost `g` at the gain `gains[g]` ([`Ghosts::Weighted`]).
    pub fn weighted(self, gains: &'a [f32]) -> Self {
        Self { ghosts: Ghosts::Weighted(gains), ..self }
    }

    /// This request with the jobs `dim` says left out.
    pub fn dim(self, dim: Dim<'a>) -> Self {
        Self { dim, ..self }
    }

    /// This request stopped when `cancel` is set (see [`Self::cancel`]).
    pub fn cancellable(self, cancel: &'a AtomicBool) -> Self {
        Self { cancel: Some(cancel), ..self }
    }
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
    /// Per step: that table's samples (what the tracer reads, [`VertexRecipe`]).
    reflectance: Vec<Arc<[f64]>>,
    /// Per step: 1 / semi-aperture^2 (0 at the stop, whose aperture is the mask).
    inverse_semi_aperture2: Vec<f64>,
}
/// One ghost as the ray tracer needs it: its two reflecting surfaces and, per wavelength, how many times its
/// path crosses the stop (1, or 3 when the reflections lie on both sides of it).
#[derive(Clone, Debug, PartialEq)]
pub struct TracedGhost {
    pub i: usize,
    pub j: usize,
    pub stop_crossings: Vec<usize>,
}

/// Where to look when no coarse ray of ghost `g` at wavelength `w` passes, for light slopes `u`: the centre
/// (mm) and radius (mm) of a disc on the entrance plane (a hint of where a ghost smaller than a coarse cell may
/// be, never a result). The paraxial entrance region serves ([`crate::flare::ray_grid_setup`]).
pub(crate) type EntranceHint = Arc<dyn Fn(usize, usize, [f64; 2]) -> Option<([f64; 2], f64)> + Send + Sync>;

/// What the ray tracer needs of a lens and its settings: nothing but optics, coatings and the stop (the
/// aperture mask comes with [`RayGridRenderer::new`]), and a hint of where to look.
#[derive(Clone)]
pub struct RayGridSetup {
    pub lens: Lens,
    pub spectrum: Spectrum,
    /// When set, every reflecting surface wears this coating instead of its own.
    pub coating_override: Option<Coating>,
    /// The sensor plane (mm behind the first vertex).
    pub sensor_z_mm: f64,
    /// The stop's radius at the chosen f-number (the unit of the mask's coordinates).
    pub stop_radius_mm: f64,
    pub ghosts: Vec<TracedGhost>,
    pub entrance_hint: EntranceHint,
}

/// The entrance hint, named in debug output.
#[derive(Clone)]
struct Hint(EntranceHint);

impl std::fmt::Debug for Hint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("EntranceHint")
    }
}

/// Everything a ray-traced render of one lens and configuration needs; made once, used for any light.
#[derive(Clone, Debug)]
pub struct RayGridRenderer {
    spectrum: Spectrum,
    ghosts: Vec<TracedGhost>,
    stop_radius_mm: f64,
    hint: Hint,
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
    #[error("cancelled")]
    Cancelled,
}
/// What draws a column's entries once the scout has placed their windows: the CPU reference renderer
/// (`CpuTracing`) or its GPU twin (`render::raygrid::GpuBake`, which falls back to the CPU if its device is
/// lost). Everything else of the bake (scouts, windows, refinement) is the same for both.
pub trait ColumnTracer: Sync {
    /// The scouted ghost, for the scout's light, seen in each of `views` (linear irradiance); `None` when it
    /// cannot be drawn (the column's entries then stay empty).
    fn trace_column(
        &self,
        renderer: &RayGridRenderer,
        scout: &Scout,
        views: Vec<View>,
        grid: Grid,
    ) -> Option<Vec<crate::image::HdrImage>>;
}

/// The bake's columns traced on the CPU, in f64: [`RayGridRenderer::render_request`] of a scouted request.
pub(crate) struct CpuTracing;

impl ColumnTracer for CpuTracing {
    fn trace_column(
        &self,
        renderer: &RayGridRenderer,
        scout: &Scout,
        views: Vec<View>,
        grid: Grid,
    ) -> Option<Vec<crate::image::HdrImage>> {
        let images = renderer.render_request(&RayGridRequest::scouted(scout, views, grid)).ok()?;
        Some(images.into_iter().map(|i| i.hdr).collect())
    }
}

impl RayGridRenderer {
    /// Prepares every ghost of `setup` with the stop shape `mask`.
    pub fn new(setup: RayGridSetup, mask: &ApertureMask) -> Self {
        let RayGridSetup { lens, spectrum, coating_override, sensor_z_mm, stop_radius_mm, ghosts, entrance_hint } =
            setup;
        let tables =
            InterfaceTables::new(&lens, coating_override.as_ref(), &spectrum.wavelengths_nm, DENSE_TABLE_SAMPLES);
        let mut jobs = Vec::with_capacity(ghosts.len() * spectrum.len());
        for (g, ghost) in ghosts.iter().enumerate() {
            let Ok(path) = LightPath::ghost(&lens, ghost.i, ghost.j) else { continue };
            for (w, &wavelength_nm) in spectrum.wavelengths_nm.iter().enumerate() {
                let step_tables: Vec<usize> =
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
                let reflectance = step_tables.iter().map(|&t| tables.table(t).samples().clone()).collect();
                jobs.push(Job {
                    reflectance,
                    ghost: g,
                    wavelength: w,
                    tracer: Tracer::new(&lens, &path, wavelength_nm, sensor_z_mm),
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
            spectrum,
            ghosts,
            stop_radius_mm,
            hint: Hint(entrance_hint),
            jobs,
            tables,
            front_radius_mm,
            front_sag_mm,
        }
    }

    /// Number of ghosts (the length of [`RayGridImage::moments`]).
    pub fn ghost_count(&self) -> usize {
        self.ghosts.len()
    }

    /// The ghosts of a light seen at the frame position `light_deg` (X right, Y up, degrees) in a `width` x
    /// `height` frame with `grid` cells across each ghost's entrance region: [`Self::render_request`] of
    /// [`RayGridRequest::frame`].
    pub fn render(
        &self,
        light_deg: [f64; 2],
        width: u32,
        height: u32,
        grid: Grid,
    ) -> Result<RayGridImage, RayGridError> {
        let mut images = self.render_request(&RayGridRequest::frame(light_deg, width, height, grid))?;
        Ok(images.remove(0))
    }

    /// The one entry point of every ray-traced image: the request's ghosts, traced once, seen in each of its
    /// views. A view turns the light about the optical axis: a rotationally symmetric lens turns its image with
    /// the light, all but the stop, so each traced ray is turned (its landing point and its stop coordinates,
    /// where the mask is looked up) instead of traced again; this is how a LUT bake makes the azimuths of one
    /// theta for the price of one trace. A scouted request uses the scout's grid over the region where each
    /// wavelength's light passes as the pre-pass (finer than one over the whole front lens, and not traced
    /// again), and does not trace a wavelength where none passed.
    ///
    /// Jobs too dim to see are left out as the request's [`Dim`] says. For [`Dim::Below`], each job's peak in a
    /// view is bounded from its traced triangles: a triangle adds to a pixel at most its irradiance (flux over
    /// its area, or its whole flux when under a pixel) times its largest vertex weight (the light is linear
    /// between the vertices and the masks pass at most all of it) times the wavelength's largest RGB weight;
    /// those bounds are summed over tiles of 8 x 8 pixels that each triangle's box touches, and the job's peak
    /// is its largest tile. The faintest jobs go while their peaks sum to at most the threshold. When the jobs
    /// do not fit one batch they are traced once more to find the peaks first, so the choice never depends on
    /// the batches.
    pub fn render_request(&self, request: &RayGridRequest) -> Result<Vec<RayGridImage>, RayGridError> {
        let (views, grid, cancel) = (request.views.as_slice(), request.grid, request.cancel);
        self.render_views(light_of(request), views, grid, cancel, request.dim, plan_of(request.ghosts))
    }

    /// Per job of this renderer (in its order), whether `request` leaves it out as too dim to see (the choice
    /// [`Self::render_request`] makes, by the first view): what a ghost's own layer passes as [`Dim::Skip`] so
    /// that the layers leave out what their whole frame does. Nothing is splatted.
    pub fn dim_jobs(&self, request: &RayGridRequest) -> Result<Vec<bool>, RayGridError> {
        let (light, views) = (light_of(request), request.views.as_slice());
        validate(light, views, request.grid)?;
        let mut out = vec![false; self.jobs.len()];
        match request.dim {
            Dim::Drawn => {}
            Dim::Skip(skip) => {
                for (o, s) in out.iter_mut().zip(skip) {
                    *o = *s;
                }
            }
            Dim::Below(threshold) => {
                let drawn = self.drawn(&plan_of(request.ghosts));
                let first = &views[..views.len().min(1)];
                let peaks = self.peaks(light, first, request.grid, request.cancel, &drawn)?;
                if let Some(peaks) = peaks.first() {
                    for (&(index, ..), dim) in drawn.iter().zip(faintest(peaks, threshold)) {
                        out[index] = dim;
                    }
                }
            }
        }
        Ok(out)
    }

    /// Validates a request and renders it: `plan(job)` is `None` for a job not drawn, `Some((None, gain))` for
    /// one whose pre-pass is traced over the whole front lens and `Some((Some(grid), gain))` for one whose
    /// pre-pass is the scouted `grid`; its light is multiplied by `gain`. A set `cancel` skips every job not yet
    /// begun and answers [`RayGridError::Cancelled`].
    ///
    /// The jobs are traced in parallel a batch at a time (at most [`BATCH_VERTICES`] vertices held, whatever
    /// the grid), then splatted band by band ([`FrameAcc`]): each band of rows draws every job of the batch in
    /// the jobs' order, so the image is the same to the bit whatever the threads.
    fn render_views<'s>(
        &self,
        light_deg: [f64; 2],
        views: &[View],
        grid: Grid,
        cancel: Option<&AtomicBool>,
        dim: Dim,
        plan: impl Fn(&Job) -> Option<(Option<&'s TracedGrid>, f64)> + Sync,
    ) -> Result<Vec<RayGridImage>, RayGridError> {
        validate(light_deg, views, grid)?;
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        let ghosts = self.ghost_count();
        // The jobs drawn, gathered first: a scouted request draws 3 of the lens's (up to thousands of) jobs.
        let drawn = self.drawn(&plan);
        let mut frames: Vec<FrameAcc> =
            views.iter().map(|v| FrameAcc::new(v.window.width as usize, v.window.height as usize, ghosts)).collect();
        let mut stats = vec![RayGridStats::default(); views.len()];
        let per_batch = self.batch_jobs(grid, views, dim);
        // Per view, per drawn job: left out as too dim. With more than one batch the peaks are found first (a
        // trace of their own); with one they come from the batch itself.
        let mut left_out: Vec<Vec<bool>> = match dim {
            Dim::Drawn => vec![vec![false; drawn.len()]; views.len()],
            Dim::Skip(skip) => {
                let one: Vec<bool> =
                    drawn.iter().map(|&(index, ..)| skip.get(index).copied().unwrap_or(false)).collect();
                vec![one; views.len()]
            }
            Dim::Below(threshold) if drawn.len() > per_batch => {
                let peaks = self.peaks(light_deg, views, grid, cancel, &drawn)?;
                peaks.iter().map(|p| faintest(p, threshold)).collect()
            }
            Dim::Below(_) => Vec::new(),
        };
        // The peaks are bounded in the batch only where they were not found first.
        let bound = matches!(dim, Dim::Below(_)) && left_out.is_empty();
        for (b, batch) in drawn.chunks(per_batch).enumerate() {
            let first = b * per_batch;
            let mut traced = crate::timing::span("trace the rays", || self.trace_batch(batch, u, views, grid, cancel))?;
            stats[0].rays += traced.iter().map(|job| job.rays).sum::<u64>();
            let last = views.len().saturating_sub(1);
            for (k, (view, frame)) in views.iter().zip(&mut frames).enumerate() {
                let bands = frame.bands();
                let seen: Vec<Seen> = crate::timing::span("see the triangles", || {
                    traced.par_iter_mut().map(|job| job.see(view, k == last, bands, bound)).collect()
                });
                if let Dim::Below(threshold) = dim
                    && left_out.len() == k
                {
                    left_out.push(faintest(&seen.iter().map(|s| s.peak).collect::<Vec<_>>(), threshold));
                }
                let skip = &left_out[k][first..first + seen.len()];
                for (s, &skip) in seen.iter().zip(skip) {
                    stats[k].jobs += 1;
                    stats[k].triangles += if skip { 0 } else { s.lit as u64 };
                    stats[k].empty_jobs += usize::from(s.lit == 0);
                    stats[k].dim_jobs += usize::from(skip && s.lit > 0);
                }
                crate::timing::span("splat", || {
                    frame.splat(|band| {
                        for ((job, s), &skip) in traced.iter().zip(&seen).zip(skip) {
                            if !skip {
                                job.splat(s, band);
                            }
                        }
                    })
                });
            }
        }
        Ok(views.iter().zip(frames).zip(stats).map(|((view, frame), s)| frame.into_image(&view.window, s)).collect())
    }

    /// The jobs of `batch` traced in parallel for light slopes `u`; a set `cancel` skips every job not yet begun
    /// and answers [`RayGridError::Cancelled`].
    #[allow(clippy::type_complexity)]
    fn trace_batch(
        &self,
        batch: &[(usize, &Job, (Option<&TracedGrid>, f64))],
        u: [f64; 2],
        views: &[View],
        grid: Grid,
        cancel: Option<&AtomicBool>,
    ) -> Result<Vec<TracedJob<'_>>, RayGridError> {
        let cancelled = || cancel.is_some_and(|c| c.load(Ordering::Relaxed));
        let traced: Vec<Option<TracedJob>> = batch
            .par_iter()
            .map(|(_, job, (scouted, gain))| {
                (!cancelled()).then(|| self.trace_job(job, u, views, grid, *scouted, *gain))
            })
            .collect();
        if cancelled() {
            return Err(RayGridError::Cancelled);
        }
        Ok(traced.into_iter().flatten().collect())
    }

    /// The jobs `plan` draws, in the renderer's order: each with its index there and its plan.
    #[allow(clippy::type_complexity)]
    fn drawn<'j, 's>(
        &'j self,
        plan: &(impl Fn(&Job) -> Option<(Option<&'s TracedGrid>, f64)> + Sync),
    ) -> Vec<(usize, &'j Job, (Option<&'s TracedGrid>, f64))> {
        self.jobs.iter().enumerate().filter_map(|(index, job)| plan(job).map(|planned| (index, job, planned))).collect()
    }

    /// How many jobs a batch traces at once: at most [`BATCH_VERTICES`] vertices held (a job holds its traced
    /// vertices, and while one view is splatted a copy seen in that view; the last view sees them in place), or
    /// [`DIM_BATCH_VERTICES`] for a request that leaves dim jobs out.
    fn batch_jobs(&self, grid: Grid, views: &[View], dim: Dim) -> usize {
        let per_job = (grid.cells() + 1).pow(2) * views.len().min(2);
        let held = if matches!(dim, Dim::Drawn) { BATCH_VERTICES } else { DIM_BATCH_VERTICES };
        (held / per_job.max(1)).max(1)
    }

    /// Per view, per job of `drawn`: the bound of its peak ([`Dim::Below`]), from the jobs traced a batch at a
    /// time and nothing splatted.
    #[allow(clippy::type_complexity)]
    fn peaks(
        &self,
        light_deg: [f64; 2],
        views: &[View],
        grid: Grid,
        cancel: Option<&AtomicBool>,
        drawn: &[(usize, &Job, (Option<&TracedGrid>, f64))],
    ) -> Result<Vec<Vec<f64>>, RayGridError> {
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        crate::timing::span("find the dim jobs' peaks", || {
            let mut peaks = vec![Vec::with_capacity(drawn.len()); views.len()];
            for batch in drawn.chunks(self.batch_jobs(grid, views, Dim::Below(0.0))) {
                let mut traced = self.trace_batch(batch, u, views, grid, cancel)?;
                for (k, view) in views.iter().enumerate() {
                    let bands = band_count(view.window.height as usize);
                    let last = k + 1 == views.len();
                    peaks[k].par_extend(traced.par_iter_mut().map(|job| job.see(view, last, bands, true).peak));
                }
            }
            Ok(peaks)
        })
    }

    /// The jobs of a fixed-grid frame render as [`Self::render`] lays them out, for a twin that traces them
    /// elsewhere (the GPU ray grids, `render::raygrid`): per job with light, its tracer and tables, and where its
    /// `cells` x `cells` grid lies on the entrance plane (the same CPU pre-pass: a coarse grid over the front
    /// lens). Jobs where no light passes are left out.
    pub fn plan_fixed(
        &self,
        light_deg: [f64; 2],
        window: Window,
        cells: usize,
        gains: &[f32],
    ) -> Result<Vec<PlannedJob<'_>>, RayGridError> {
        let views = [View { window, turn_deg: 0.0 }];
        let grid = Grid::Fixed(cells);
        validate(light_deg, &views, grid)?;
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        Ok(self
            .jobs
            .par_iter()
            .enumerate()
            .filter_map(|(index, job)| {
                let gain = ghost_gain(gains, job.ghost);
                if gain <= 0.0 {
                    return None;
                }
                let pre = self.front_pre_pass(job, u, d, grid, &views).0?;
                let mut planned = self.planned(index, pre.bounds, cells, d);
                planned.rgb = planned.rgb.map(|w| w * gain);
                planned.lit = pre.lit;
                Some(planned)
            })
            .collect())
    }

    /// The jobs of a scouted render ([`Ghosts::Scouted`] seen in `views`) as [`Self::render_request`] lays
    /// them out, for a twin that traces them elsewhere (the GPU bake): per wavelength of the scouted ghost with
    /// light, where its grid lies (the scout's grid as the pre-pass) and how many cells it has (`grid` for the
    /// ghost's extent in the views) and which of the scout's cells it traces (the lit ones).
    pub fn plan_scouted(&self, scout: &Scout, views: &[View], grid: Grid) -> Result<Vec<PlannedJob<'_>>, RayGridError> {
        validate(scout.light_deg, views, grid)?;
        let u = light_slopes_for_frame_position(scout.light_deg[0], scout.light_deg[1]);
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        Ok(self
            .jobs
            .iter()
            .enumerate()
            .filter(|(_, job)| job.ghost == scout.ghost)
            .filter_map(|(index, job)| {
                let traced = scout.grids.get(job.wavelength)?.as_ref()?;
                let pre = self.pre_pass(job, u, traced, views)?;
                let mut planned = self.planned(index, pre.bounds, grid.for_extent(pre.extent_px), d);
                planned.lit = pre.lit;
                Some(planned)
            })
            .collect())
    }

    /// Job `index` planned on a `cells` x `cells` grid over `bounds` of the entrance plane, light direction `d`.
    fn planned(&self, index: usize, bounds: [f64; 4], cells: usize, d: DVec3) -> PlannedJob<'_> {
        let job = &self.jobs[index];
        PlannedJob {
            index,
            ghost: job.ghost,
            tracer: &job.tracer,
            step_tables: &job.step_tables,
            inverse_semi_aperture2: &job.inverse_semi_aperture2,
            bounds,
            cells,
            direction: d,
            triangle_flux: triangle_flux(d, bounds, cells),
            stop_count: self.stop_count(job),
            rgb: self.spectrum.weights_rgb[job.wavelength],
            lit: None,
        }
    }

    /// The pre-pass of a render with no scout: a coarse grid (half the render's, 16 to 64 cells) over the whole
    /// front lens, and how many rays it traced.
    fn front_pre_pass(&self, job: &Job, u: [f64; 2], d: DVec3, grid: Grid, views: &[View]) -> (Option<PrePass>, u64) {
        let cells = (grid.cells() / 2).clamp(16, 64);
        let traced = self.trace_grid(job, self.front_region(u), cells, d, None);
        (self.pre_pass(job, u, &traced, views), traced.vertices.len() as u64)
    }

    /// The reflectance tables the jobs' `step_tables` index.
    pub fn tables(&self) -> &InterfaceTables {
        &self.tables
    }

    /// The stop's surface index and its radius at the chosen f-number (mm).
    pub fn stop(&self) -> (usize, f64) {
        (self.stop, self.stop_radius_mm)
    }

    /// The stop's shape.
    pub fn mask(&self) -> &ApertureMask {
        &self.mask
    }

    /// The f64 twin of one GPU grid vertex: the ray of `job` from the entrance point `x0` (mm), its landing
    /// point in sensor mm in `pixel` (see [`Self::plan_fixed`]).
    pub fn trace_planned(&self, job: &PlannedJob, x0: [f64; 2]) -> ([f64; 2], bool) {
        let [v] = self.trace_lanes(&self.jobs[job.index], [x0], job.direction);
        (v.pixel, v.valid)
    }

    /// Where ghost `ghost` lands on the sensor plane for a light at the frame position `light_deg`:
    /// `[x_min, y_min, x_max, y_max]` in sensor mm over every wavelength, from a `cells` x `cells` grid over the
    /// region where the pre-pass found light (each passing ray and its traced neighbours, so the partly lit
    /// cells at the rim are inside). `None` when no ray of the ghost passes.
    pub fn footprint_mm(&self, ghost: usize, light_deg: [f64; 2], cells: usize) -> Option<[f64; 4]> {
        self.footprints_turned_mm(ghost, light_deg, cells, &[0.0]).remove(0)
    }

    /// [`Self::footprint_mm`] for the light turned by each of `turns_deg` about the axis (see
    /// [`Self::render_request`]), from one set of traced rays.
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
    /// light passes, which a scouted request ([`Ghosts::Scouted`]) then covers instead of the whole front lens.
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
        let mut grids = vec![None; self.spectrum.len()];
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
        self.ghosts[job.ghost].stop_crossings.get(job.wavelength).copied().unwrap_or(1).min(3)
    }

    /// Traces `L` rays of `job` from the entrance points `x0` (mm) in direction `d`, together
    /// ([`Tracer::trace_vertices`]); each one's `pixel` is its landing point in sensor mm until a [`View`]
    /// sees it.
    fn trace_lanes<const L: usize>(&self, job: &Job, x0: [[f64; 2]; L], d: DVec3) -> [Vertex; L] {
        let rays = x0.map(|x| Ray { origin_mm: DVec3::new(x[0], x[1], 0.0), direction: d });
        let recipe = VertexRecipe {
            reflectance: &job.reflectance,
            inverse_semi_aperture2: &job.inverse_semi_aperture2,
            stop_surface: self.stop,
            stop_radius_mm: self.stop_radius_mm,
        };
        let (landings, record) = job.tracer.trace_vertices(rays, &recipe);
        std::array::from_fn(|lane| {
            let mut v = Vertex {
                weight: record.weight[lane],
                stops: record.stops[lane],
                ratio: record.ratio2[lane].sqrt(),
                ..Vertex::default()
            };
            if let Ok(landing) = &landings[lane] {
                let p = [landing.point_mm.x, landing.point_mm.y];
                v.valid = p.iter().all(|c| c.is_finite()) && v.weight.is_finite() && v.ratio.is_finite();
                v.pixel = p;
            }
            v
        })
    }

    /// `count` vertices of `job` in direction `d`: vertex k traced from the entrance point `at(k)`, or left
    /// invalid where that is `None`. The traced ones go [`LANES`] at a time; returns how many were traced.
    fn trace_selected(
        &self,
        job: &Job,
        d: DVec3,
        count: usize,
        at: impl Fn(usize) -> Option<[f64; 2]>,
        out: &mut Vec<Vertex>,
    ) -> u64 {
        let start = out.len();
        out.resize(start + count, Vertex::default());
        let wanted: Vec<(usize, [f64; 2])> = (0..count).filter_map(|k| at(k).map(|x0| (k, x0))).collect();
        for group in wanted.chunks(LANES) {
            // A short last group repeats its last ray (traced, then dropped).
            let x0: [[f64; 2]; LANES] = std::array::from_fn(|lane| group[lane.min(group.len() - 1)].1);
            for ((k, _), vertex) in group.iter().zip(self.trace_lanes(job, x0, d)) {
                out[start + k] = vertex;
            }
        }
        wanted.len() as u64
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
        let n = cells + 1;
        let mut vertices = Vec::with_capacity(n * n);
        self.trace_selected(
            job,
            d,
            n * n,
            |k| {
                let x0 = [region[0] + (k % n) as f64 * step[0], region[1] + (k / n) as f64 * step[1]];
                lit.is_none_or(|lit| lit.contains(x0)).then_some(x0)
            },
            &mut vertices,
        );
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
            if let Some((e, rho)) = (self.hint.0)(job.ghost, job.wavelength, u)
                && rho > 0.0
                && rho.is_finite()
                && e.iter().all(|c| c.is_finite())
            {
                let r = 1.25 * rho;
                bounds = [e[0] - r, e[1] - r, e[0] + r, e[1] + r];
            }
            lit = None;
        }
        let bounds = [bounds[0].max(-half), bounds[1].max(-half), bounds[2].min(half), bounds[3].min(half)];
        (bounds[0] < bounds[2] && bounds[1] < bounds[3]).then_some(PrePass { bounds, extent_px, lit })
    }

    /// Traces `job` once (its pre-pass `scouted`, or traced over the whole front lens), ready to be seen in each
    /// view ([`TracedJob::see`]) and splatted.
    fn trace_job<'m>(
        &'m self,
        job: &Job,
        u: [f64; 2],
        views: &[View],
        grid: Grid,
        scouted: Option<&TracedGrid>,
        gain: f64,
    ) -> TracedJob<'m> {
        let mut rays = 0;
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        let pre = match scouted {
            Some(traced) => self.pre_pass(job, u, traced, views),
            None => {
                let (pre, pre_rays) = self.front_pre_pass(job, u, d, grid, views);
                rays += pre_rays;
                pre
            }
        };
        let weights = self.spectrum.weights_rgb[job.wavelength].map(|w| w * gain);
        let mut frame = JobFrame {
            ghost: job.ghost,
            rgb: weights,
            luma: crate::color::luminance(weights),
            stop_count: self.stop_count(job),
            mask: &self.mask,
            open_radius2: self.open_radius2,
            triangle_flux: 0.0,
        };
        let Some(PrePass { bounds: b, extent_px, lit }) = pre else {
            return TracedJob { frame, cells: 0, vertices: Vec::new(), rays };
        };
        let grid = grid.for_extent(extent_px);
        frame.triangle_flux = triangle_flux(d, b, grid);
        let (dx, dy) = ((b[2] - b[0]) / grid as f64, (b[3] - b[1]) / grid as f64);
        // Every ray of the grid (traced LANES at a time across rows: a row alone leaves lanes idle), a ray far
        // from every lit cell of the pre-pass not at all (no triangle of it carries light).
        let n = grid + 1;
        let mut vertices: Vec<Vertex> = Vec::with_capacity(n * n);
        let at = |k: usize| {
            let x0 = [b[0] + (k % n) as f64 * dx, b[1] + (k / n) as f64 * dy];
            lit.as_ref().is_none_or(|lit| lit.contains(x0)).then_some(x0)
        };
        rays += self.trace_selected(job, d, n * n, at, &mut vertices);
        TracedJob { frame, cells: grid, vertices, rays }
    }
}
/// The most traced vertices a render holds at once (the jobs of a batch with the largest grid, and the copies
/// seen in one view): about 23 MB. (A LUT bake draws a column per ghost on every core at once.)
const BATCH_VERTICES: usize = 1 << 18;
/// The most a render that leaves dim jobs out holds (a frame's still, one render at a time): about 185 MB, so
/// that a lens's jobs on grids up to 128 cells fit one batch (the Heliar's 84 at 128: 1.4 million vertices) and
/// are traced once; more than one batch are traced once more to find their peaks first.
const DIM_BATCH_VERTICES: usize = 1 << 21;
/// Triangle `t` of a grid of `n` x `n` vertices: cell `t / 2` (row by row), its first or second half (the split
/// the GPU makes too).
#[inline(always)]
fn triangle(vertices: &[Vertex], n: usize, t: usize) -> [&Vertex; 3] {
    let (iy, ix) = ((t / 2) / (n - 1), (t / 2) % (n - 1));
    let (v00, v10) = (&vertices[iy * n + ix], &vertices[iy * n + ix + 1]);
    let (v01, v11) = (&vertices[(iy + 1) * n + ix], &vertices[(iy + 1) * n + ix + 1]);
    if t.is_multiple_of(2) { [v00, v10, v11] } else { [v00, v11, v01] }
}
/// One job traced, waiting to be seen in each view and splatted.
struct TracedJob<'m> {
    frame: JobFrame<'m>,
    cells: usize,
    /// `(cells + 1)^2` vertices row by row, landing in sensor mm (none when no light passes); seen in place by
    /// the last view.
    vertices: Vec<Vertex>,
    rays: u64,
}
/// A traced job as one view sees it: its triangles that carry light sorted by the bands of rows they reach.
struct Seen {
    /// How many of its triangles carry light into the view.
    lit: usize,
    /// A bound of the most it adds to any pixel ([`Dim::Below`]'s peak); 0 when not asked for.
    peak: f64,
    /// The vertices in the view's pixels; empty when the view sees the job's own (the last view).
    vertices: Vec<Vertex>,
    /// The triangles ([`triangle`]'s numbers) that reach band `b`, in the triangles' order:
    /// `tris[starts[b]..starts[b + 1]]`. A triangle that reaches several bands is listed in each.
    starts: Vec<u32>,
    tris: Vec<u32>,
}
impl TracedJob<'_> {
    /// This job seen in `view` (`last`: the last view of the render, which sees the vertices in place), its
    /// triangles that carry light sorted into the `bands` of rows of [`BAND_ROWS`] each: a band draws only the
    /// triangles that reach it.
    /// With `bound`, the job's peak in the view is bounded too ([`Seen::peak`]; see
    /// [`RayGridRenderer::render_request`]).
    fn see(&mut self, view: &View, last: bool, bands: usize, bound: bool) -> Seen {
        let see = view.seer();
        let vertices = if last {
            for v in &mut self.vertices {
                *v = see(v);
            }
            Vec::new()
        } else {
            self.vertices.iter().map(&see).collect()
        };
        let all = if last { &self.vertices } else { &vertices };
        let (n, cells) = (self.cells + 1, self.cells);
        let (width, height) = (view.window.width as f64, view.window.height as f64);
        // The bands each triangle that carries light reaches (the frame's rows only: a part above, below or
        // beside the frame lands on no pixel; `splat_triangle` passes over the same).
        let mut reach: Vec<(u32, u32, u32)> = Vec::new();
        let mut starts = vec![0u32; bands + 1];
        let mut peaks = bound.then(|| PeakTiles::new(&view.window, &self.frame));
        for t in 0..2 * cells * cells {
            let tri = triangle(all, n, t);
            if !carries_light(tri, &self.frame) {
                continue;
            }
            let y_lo = tri.iter().map(|v| v.pixel[1]).fold(f64::INFINITY, f64::min);
            let y_hi = tri.iter().map(|v| v.pixel[1]).fold(f64::NEG_INFINITY, f64::max);
            let x_lo = tri.iter().map(|v| v.pixel[0]).fold(f64::INFINITY, f64::min);
            let x_hi = tri.iter().map(|v| v.pixel[0]).fold(f64::NEG_INFINITY, f64::max);
            if y_hi < 0.0 || y_lo >= height || x_hi < -1.0 || x_lo > width + 1.0 {
                continue;
            }
            if let Some(peaks) = &mut peaks {
                peaks.add(tri, [x_lo, y_lo, x_hi, y_hi]);
            }
            let first = (y_lo.max(0.0) as usize / BAND_ROWS).min(bands - 1);
            let last = (y_hi.min(height - 1.0) as usize / BAND_ROWS).min(bands - 1);
            for count in &mut starts[first + 1..=last + 1] {
                *count += 1;
            }
            reach.push((t as u32, first as u32, last as u32));
        }
        for b in 0..bands {
            starts[b + 1] += starts[b];
        }
        let lit = reach.len();
        let mut tris = vec![0u32; starts[bands] as usize];
        let mut next = starts.clone();
        for (t, first, last) in reach {
            for b in first as usize..=last as usize {
                tris[next[b] as usize] = t;
                next[b] += 1;
            }
        }
        Seen { vertices, starts, tris, lit, peak: peaks.map_or(0.0, |p| p.peak()) }
    }

    /// Splats this job's triangles, `seen` in a view, that reach `band`. Compiled for AVX2 too, used where the
    /// processor has it (the splatting's floors and conversions are then single instructions; the same
    /// results).
    fn splat(&self, seen: &Seen, band: &mut BandAcc) {
        #[cfg(target_arch = "x86_64")]
        if crate::optics::simd_level() >= 1 {
            // SAFETY: the processor has AVX2 (checked once by `simd_level`).
            return unsafe { self.splat_avx2(seen, band) };
        }
        self.splat_body(seen, band)
    }

    /// [`Self::splat_body`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn splat_avx2(&self, seen: &Seen, band: &mut BandAcc) {
        self.splat_body(seen, band)
    }

    /// The body of [`Self::splat`].
    #[inline(always)]
    fn splat_body(&self, seen: &Seen, band: &mut BandAcc) {
        let b = band.y0 / BAND_ROWS;
        let Some(range) = seen.starts.get(b..b + 2) else { return };
        let vertices = if seen.vertices.is_empty() { &self.vertices } else { &seen.vertices };
        for &t in &seen.tris[range[0] as usize..range[1] as usize] {
            splat_triangle(triangle(vertices, self.cells + 1, t as usize), &self.frame, band);
        }
    }
}
/// One job of a fixed-grid render, planned on the CPU for a twin that traces it elsewhere
/// ([`RayGridRenderer::plan_fixed`]).
pub struct PlannedJob<'a> {
    /// The job's place among the renderer's jobs (for [`RayGridRenderer::trace_planned`]).
    pub index: usize,
    pub ghost: usize,
    pub tracer: &'a Tracer,
    /// Per step of the path: the index of its reflectance table in [`RayGridRenderer::tables`].
    pub step_tables: &'a [usize],
    /// Per step: 1 / semi-aperture^2 (0 at the stop).
    pub inverse_semi_aperture2: &'a [f64],
    /// The grid's square on the entrance plane, `[x_min, y_min, x_max, y_max]` (mm).
    pub bounds: [f64; 4],
    pub cells: usize,
    /// The light's unit direction.
    pub direction: DVec3,
    /// cos(theta) x the entrance area of one triangle (mm^2).
    pub triangle_flux: f64,
    /// Stop crossings the mask is looked up at (1 or 3).
    pub stop_count: usize,
    /// The wavelength's RGB weight.
    pub rgb: [f64; 3],
    /// The cells of the pre-pass whose rays the dense grid traces (the CPU leaves the others untraced, and so
    /// does a twin); `None`: all of `bounds`.
    pub lit: Option<LitCells>,
}

/// The light of `request` (a scouted request's is its scout's).
fn light_of(request: &RayGridRequest) -> [f64; 2] {
    match request.ghosts {
        Ghosts::Scouted(scout) => scout.light_deg,
        _ => request.light_deg,
    }
}

/// What a request for `ghosts` draws of each job: `None` for a job not drawn, `Some((None, gain))` for one whose
/// pre-pass is traced over the whole front lens and `Some((Some(grid), gain))` for one whose pre-pass is the
/// scouted `grid`.
fn plan_of<'s>(ghosts: Ghosts<'s>) -> impl Fn(&Job) -> Option<(Option<&'s TracedGrid>, f64)> + Sync + 's {
    move |job: &Job| match ghosts {
        Ghosts::All => Some((None, 1.0)),
        Ghosts::Only(g) => (job.ghost == g).then_some((None, 1.0)),
        Ghosts::Weighted(gains) => {
            let gain = ghost_gain(gains, job.ghost);
            (gain > 0.0).then_some((None, gain))
        }
        Ghosts::Scouted(scout) => {
            if job.ghost != scout.ghost {
                return None;
            }
            scout.grids.get(job.wavelength).and_then(Option::as_ref).map(|g| (Some(g), 1.0))
        }
    }
}

/// Which of `peaks` are left out as too dim to see, the rule of [`Dim::Below`] and of the LUT ghosts
/// ([`crate::lut::blend::LutScene::cull_faint`]): the faintest, as many as can go while their peaks sum to at
/// most `threshold` (ties in the given order). A peak that is negative or not finite ends the choice, and nothing
/// goes when `threshold` is not positive.
pub fn faintest(peaks: &[f64], threshold: f64) -> Vec<bool> {
    let mut out = vec![false; peaks.len()];
    if threshold.is_nan() || threshold <= 0.0 {
        return out;
    }
    let mut order: Vec<usize> = (0..peaks.len()).collect();
    order.sort_by(|&a, &b| peaks[a].total_cmp(&peaks[b]).then(a.cmp(&b)));
    let mut sum = 0.0;
    for k in order {
        let peak = peaks[k];
        if !(peak.is_finite() && peak >= 0.0 && sum + peak <= threshold) {
            break;
        }
        sum += peak;
        out[k] = true;
    }
    out
}

/// Ghost `g`'s gain in `gains` (missing: 1; not finite or negative: 0).
fn ghost_gain(gains: &[f32], g: usize) -> f64 {
    let gain = f64::from(gains.get(g).copied().unwrap_or(1.0));
    if gain.is_finite() && gain > 0.0 { gain } else { 0.0 }
}

/// Refuses a render of `grid` cells, seen in `views`, for a light at `light_deg` that cannot be made.
fn validate(light_deg: [f64; 2], views: &[View], grid: Grid) -> Result<(), RayGridError> {
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
    Ok(())
}

/// cos(theta) x the entrance area of one triangle (mm^2) of a `cells` x `cells` grid over `bounds`, for light
/// in the unit direction `d`.
fn triangle_flux(d: DVec3, bounds: [f64; 4], cells: usize) -> f64 {
    d.z * 0.5 * (bounds[2] - bounds[0]) * (bounds[3] - bounds[1]) / (cells * cells) as f64
}

/// Rays traced together ([`Tracer::trace_vertices`]): two AVX-512 registers of f64 (four AVX2 ones), so that
/// the processor overlaps two chains of square roots and divisions.
const LANES: usize = 16;
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
#[derive(Clone, Debug)]
pub struct LitCells {
    /// The pre-pass grid's corner on the entrance plane (mm), its cell size (mm) and cells across.
    pub origin: [f64; 2],
    pub step: [f64; 2],
    pub cells: usize,
    /// Per cell, row by row: lit (or next to a lit cell).
    pub lit: Vec<bool>,
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
