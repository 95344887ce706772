//! The view's ray-grid mode: the frame shown, its ghosts ray-traced exactly (Hullin et al. 2011's ray grids,
//! `flare_core::raytrace` and its GPU twin) instead of drawn as paraxial sprites, for a lens designer who
//! wants to see the optics without the paraxial approximation, live.
//!
//! # How it works
//! [`RayGridView::step`] runs once per UI frame after the frame is built. While the user drags or scrubs, the
//! viewport draws its paraxial drafts as always (tracing every ghost is too slow to follow a drag on most
//! machines). When a full-quality frame is up and has not been traced yet, a [`Job`] traces it on a thread:
//! on a hardware GPU when there is one ([`GpuRayGrid`], its triangles box-filtered by a compute pass as the CPU
//! does; made once, on the first trace), else with the f64 CPU renderer (a software adapter such as lavapipe is
//! slower than the CPU here); a GPU lost on the way hands this trace and every later one to the CPU, said in
//! the status. The traced ghosts go through the frame pipeline's
//! [`flare_core::frame::drawn_with_traced_ghosts`] (light gain, starburst, tonemap, plate), the same function
//! `flarelab render --method raygrid` writes with, and the display image replaces the frame in the viewport
//! ([`ViewportResources::show_image`]). A trace is for the optics, the frame's request, the plate and the grid
//! (`TraceKey`): one that finishes after any of them changed is dropped, and a new frame that differs only in
//! its LUT (a bake that finished) shows the same trace again. Cancel stops the trace of this frame (the next
//! frame is traced again): the CPU trace stops at its next ghost and wavelength
//! ([`RayGridRequest::cancellable`]), and a trace cancelled or replaced (a new frame while one runs) is watched
//! until its thread ends; the next trace starts only then ([`super::job::Slot`]: one trace at a time, the
//! latest request waiting), so traces never pile up behind the view. Exports and
//! commands draw the document's look, not this view.

use std::sync::atomic::Ordering;
use std::sync::{Arc, OnceLock};

use eframe::egui_wgpu::RenderState;
use flare_core::frame::{Frame, Sources};
use flare_core::image::{DisplayImage, HdrImage};
use flare_core::raytrace::{Grid, RayGridRequest, View, Window};
use flare_core::render::gpu::GpuContext;
use flare_core::render::raygrid::{GpuRayGrid, GpuRayGridError, SUPERSAMPLE};

use super::job::{Job, Slot};
use crate::app::derived::Derived;
use crate::viewport::ViewportResources;

/// The grids the view offers (cells across each ghost's entrance region).
pub const GRIDS: [usize; 4] = [16, 32, 64, 128];

/// A hardware GPU and its ray-grid pipelines, made once.
struct TraceDevice {
    ctx: GpuContext,
    raygrid: GpuRayGrid,
}

/// The hardware GPU the traces use, decided on the first trace: `Err` says why there is none.
type DeviceCell = Arc<OnceLock<Result<TraceDevice, String>>>;

/// A traced frame: its display image and what it took.
pub struct Traced {
    pub display: Arc<DisplayImage>,
    pub summary: String,
}

/// What a traced image depends on: the optics, the frame's request (light, size, exposures, sensor...), the
/// plate and the grid; not the LUT, which a ray-traced frame does not use (a LUT that arrives makes a new frame
/// of the same key: the trace is shown again, not redone).
#[derive(Clone, Debug, PartialEq)]
struct TraceKey {
    optics: u64,
    request: flare_core::frame::FrameRequest,
    plate_generation: u64,
    grid: usize,
}

/// The ray-grid view's state (see the module documentation).
#[derive(Default)]
pub struct RayGridView {
    /// Cells across each ghost's grid; `None`: the view draws the document's look.
    pub grid: Option<usize>,
    /// The trace running (or waiting for a cancelled one to stop) and what it is for.
    slot: Slot<TraceKey, Result<Traced, String>>,
    /// The latest traced frame: what it was traced for, the generation of the frame it is shown as, and what
    /// it made.
    shown: Option<(TraceKey, u64, Traced)>,
    /// What a cancelled trace was for: not traced again.
    cancelled: Option<TraceKey>,
    /// What the status bar says.
    pub status: String,
    device: DeviceCell,
}

impl RayGridView {
    /// True while a trace runs, waits, or a cancelled one is still stopping.
    pub fn busy(&self) -> bool {
        self.slot.busy()
    }

    /// The display image shown as the frame of `generation`, when it was traced at the grid chosen.
    pub fn traced(&self, generation: u64) -> Option<&Traced> {
        self.shown.as_ref().filter(|(key, g, _)| *g == generation && Some(key.grid) == self.grid).map(|s| &s.2)
    }

    /// Cancelled traces whose threads have not ended yet.
    pub fn stopping(&self) -> usize {
        self.slot.stopping()
    }

    /// The running trace's progress.
    pub fn progress(&self) -> Option<(f32, String)> {
        self.slot.progress()
    }

    /// Stops the running trace; what it was for is not traced again.
    pub fn cancel(&mut self) {
        if let Some(key) = self.slot.cancel() {
            self.cancelled = Some(key);
            self.status = "ray grid: cancelled (the paraxial frame is shown; the next frame is traced)".into();
        }
    }

    /// One UI frame's step (see the module documentation); `gpu` is the viewport's device, `None` in tests.
    pub fn step(&mut self, derived: &Derived, gpu: Option<&RenderState>) {
        let finished = self.slot.poll();
        let Some(grid) = self.grid else {
            self.slot.cancel();
            if self.shown.take().is_some()
                && let Some(rs) = gpu
            {
                // The viewport draws the look again.
                ViewportResources::with(rs, |_, _, _| ());
            }
            self.status.clear();
            return;
        };
        let (Some((generation, frame)), Some(flare), Some(frame_key)) =
            (derived.view_frame().clone(), derived.flare().clone(), derived.frame_key().as_ref())
        else {
            return;
        };
        let key = TraceKey {
            optics: frame_key.optics,
            request: frame_key.request.clone(),
            plate_generation: frame_key.plate_generation,
            grid,
        };
        // A finished trace: kept if it is still what the view shows, dropped otherwise.
        if let Some(done) = finished {
            match done.outcome {
                Ok(traced) if done.key == key => {
                    self.status = traced.summary.clone();
                    self.shown = Some((key.clone(), 0, traced));
                }
                Ok(_) => {}
                Err(e) => self.status = format!("ray grid {grid}: {e}"),
            }
        }
        // Drafts while the user drags; the trace waits for the full frame.
        if derived.draft().is_some() {
            self.slot.cancel();
            self.status = format!("ray grid {grid}: paraxial drafts while dragging; traced when input stops");
            return;
        }
        if let Some((traced_for, shown_as, traced)) = &mut self.shown
            && *traced_for == key
        {
            // Shown as this frame; again if the frame is new (a LUT arrived) or an upload since made the
            // viewport draw the paraxial frame over it.
            *shown_as = generation;
            if let Some(rs) = gpu
                && !ViewportResources::shows_image(rs, generation)
            {
                ViewportResources::show_image(rs, generation, &traced.display);
            }
            return;
        }
        if self.cancelled.as_ref() == Some(&key) {
            return;
        }
        if self.slot.running_for() == Some(&key) {
            return;
        }
        let plate = derived.plate().clone();
        let device = self.device.clone();
        self.slot.request(key, move || {
            Job::spawn(&format!("ray grid {grid}: tracing every ghost…"), move |cancel, report| {
                trace_frame(&flare, &frame, plate.as_deref(), grid, &device, cancel, report)
            })
        });
        self.status = format!("ray grid {grid}: tracing every ghost (the paraxial frame until then)…");
    }
}

/// Traces `frame`'s ghosts on `grid` (GPU or CPU, see the module documentation) and draws the frame with them.
fn trace_frame(
    flare: &flare_core::flare::PreparedFlare,
    frame: &Frame,
    plate: Option<&HdrImage>,
    grid: usize,
    device: &DeviceCell,
    cancel: &std::sync::atomic::AtomicBool,
    report: &(dyn Fn(f32, String) + Sync),
) -> Result<Traced, String> {
    let started = std::time::Instant::now();
    let scene = &frame.scene;
    let window = Window::for_sensor(frame.request.sensor_width(), scene.hdr_width.max(1), scene.hdr_height.max(1));
    let light = frame.request.light_deg;
    let renderer = flare.ray_grid_renderer();
    let device = device
        .get_or_init(|| GpuContext::hardware().map(|ctx| TraceDevice { raygrid: GpuRayGrid::new(&ctx.device), ctx }));
    let mut note = String::new();
    let mut ghosts = None;
    // A device lost on an earlier trace sends this one and every later one to the CPU.
    let lost = device.as_ref().ok().and_then(|d| d.ctx.failure());
    if let Some(why) = &lost {
        note = format!("CPU: the GPU failed ({why})");
    }
    if let (Ok(d), None) = (device, &lost) {
        report(0.1, format!("ray grid {grid}: tracing on the GPU ({})…", d.ctx.adapter.name));
        match d.raygrid.render(&d.ctx, &renderer, light, window, grid, SUPERSAMPLE, &frame.request.ghost_gains) {
            Ok(image) => {
                let times = image.gpu_times.map_or(String::new(), |t| format!(", GPU time {}", t.summary()));
                note = format!("GPU {}, box-filtered{times}", d.ctx.adapter.name);
                ghosts = Some(image.hdr);
            }
            Err(GpuRayGridError::Gpu(e)) => note = format!("CPU: the GPU failed ({e})"),
            Err(e @ GpuRayGridError::Path { .. }) => note = format!("CPU: {e}"),
            Err(e) => return Err(e.to_string()),
        }
    }
    let ghosts = match ghosts {
        Some(hdr) => hdr,
        None => {
            if note.is_empty() {
                note = match device {
                    Err(why) => format!("CPU, f64 ({why})"),
                    Ok(_) => "CPU, f64".into(),
                };
            }
            report(0.1, format!("ray grid {grid}: tracing on the CPU…"));
            let request = RayGridRequest::views(light, vec![View { window, turn_deg: 0.0 }], Grid::Fixed(grid))
                .weighted(&frame.request.ghost_gains)
                .dim(flare_core::traced::dim_for(&flare.config, frame, Grid::Fixed(grid)))
                .cancellable(cancel);
            let image = renderer.render_request(&request).map_err(|e| e.to_string())?.remove(0);
            if image.stats.dim_jobs > 0 {
                note += &format!(", {} ghost x wavelength jobs too dim to see left out", image.stats.dim_jobs);
            }
            image.hdr
        }
    };
    if cancel.load(Ordering::Relaxed) {
        return Err("cancelled".into());
    }
    report(0.9, format!("ray grid {grid}: tonemapping…"));
    let sources = Sources { flare, lut: None, plate };
    let drawn = flare_core::frame::drawn_with_traced_ghosts(frame, &sources, ghosts);
    let summary = format!(
        "ray grid {grid} ({note}): every ghost traced exactly in {:.2} s, at the look's ghost gains",
        started.elapsed().as_secs_f64()
    );
    Ok(Traced { display: Arc::new(drawn.display), summary })
}
