//! Frames whose ghosts are ray-traced instead of drawn as paraxial sprites (`render --method raygrid` and
//! `--method reference`): stills, sequences (`--frames`) and per-ghost layers (`--layers ghosts`) alike.
//!
//! # How it works
//! A frame is built as any other ([`Frame::build`]: its light, ghost gains, exposure and starburst); then
//! [`TracedGhosts::trace`] traces its ghosts at its ghost gains (a preset's per-ghost gains, `enabled` and
//! `solo`; [`RayGridRequest::weighted`]) into an accumulation at the frame's size: on the GPU
//! ([`GpuRayGrid::render`]) when the device is a GPU and the grid fixed, else on the CPU's f64 tracer (the
//! reference's adaptive grid is always there). A device lost on the way falls back to the CPU, said in the
//! line [`Traced::how`] returns. [`frame::drawn_with_traced_ghosts`] adds the starburst and tonemaps as every
//! frame is, and the one writer ([`TracedGhosts::write`] through `frame::write_drawn_with`) writes it; a
//! ghost's own layer is that ghost traced alone (every other gain 0), so the layers sum to the flare.
//! On the CPU a ray grid (not the reference) leaves out the ghost x wavelength jobs too dim to see at the
//! frame's exposure, as the paraxial sprites and the LUT images are ([`crate::raytrace::Dim::Below`], the
//! flare's threshold over the light's gain); a ghost's layer leaves out what its whole frame did. The GPU's ray
//! grid draws every job, for a frame and for its ghosts' layers alike (no choice is traced for them): its frame
//! holds at most the threshold more light at any pixel.
//! [`crate::shot::sequence::render_sequence`] traces each frame of a sequence this way when asked.

use crate::flare::PreparedFlare;
use crate::frame::{self, Device, Drawn, Frame, FrameError, LayerChoice, Made, Sources};
use crate::image::HdrImage;
use crate::raytrace::{Dim, Grid, RayGridRenderer, RayGridRequest, Window};
use crate::render::raygrid::{GpuRayGrid, GpuRayGridError};

/// How a frame's ghosts are traced, with what tracing needs made once (the CPU tracer's tables, the GPU's
/// pipelines) for every frame and layer of a render.
pub struct TracedGhosts {
    pub grid: Grid,
    /// The GPU's samples a pixel across: 0, the box filter (default), or 1 to 8 (the raster path, to compare).
    pub gpu_samples: u32,
    renderer: RayGridRenderer,
    gpu: Option<GpuRayGrid>,
    /// The flare's settings, for the dim threshold at a frame's exposure.
    config: crate::flare::FlareConfig,
}

impl std::fmt::Debug for TracedGhosts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TracedGhosts")
            .field("grid", &self.grid)
            .field("gpu_samples", &self.gpu_samples)
            .field("on_gpu", &self.gpu.is_some())
            .finish()
    }
}

/// One frame's ghosts traced: the accumulation (frame size, linear, before the light's gain) and a line saying
/// where and how.
pub struct Traced {
    pub hdr: HdrImage,
    pub how: String,
}

/// Which jobs a CPU ray grid of `frame` on `grid` leaves out as too dim to see: on a fixed grid, the faintest
/// below the flare's threshold at the frame's exposure over the light's gain (what the accumulation is
/// multiplied by; no light: all of them); the reference's adaptive grid draws every job.
pub fn dim_for(config: &crate::flare::FlareConfig, frame: &Frame, grid: Grid) -> Dim<'static> {
    match grid {
        Grid::Fixed(_) => {
            let light_gain = frame::traced_light_gain(frame);
            let threshold = config.threshold(frame.request.display.flare_gain());
            Dim::Below(if light_gain > 0.0 { threshold / f64::from(light_gain) } else { f64::INFINITY })
        }
        Grid::Adaptive(_) => Dim::Drawn,
    }
}

impl TracedGhosts {
    /// For frames of `flare` drawn on `device` (its pipelines are made here when it is a GPU and the grid fixed).
    pub fn new(flare: &PreparedFlare, grid: Grid, gpu_samples: u32, device: &Device) -> Self {
        let gpu = match (device, grid) {
            (Device::Gpu(drawer), Grid::Fixed(_)) => Some(GpuRayGrid::new(&drawer.ctx.device)),
            _ => None,
        };
        Self { grid, gpu_samples, renderer: flare.ray_grid_renderer(), gpu, config: flare.config.clone() }
    }

    /// `frame`'s ghosts at its ghost gains (see the module documentation). A grid beyond the GPU's limits is an
    /// error naming the limit; a lost device falls back to the CPU.
    pub fn trace(&self, device: &Device, frame: &Frame) -> Result<Traced, FrameError> {
        match &frame.request.cull_gains {
            // A frame culled as another (a ghost's own): its jobs left out as that frame's are.
            Some(_) => {
                self.trace_gains(device, frame, &frame.request.ghost_gains, Some(&self.dim_jobs(device, frame)?))
            }
            None => self.trace_gains(device, frame, &frame.request.ghost_gains, None),
        }
    }

    /// Per job of the renderer, whether `frame` leaves it out as too dim to see, at its cull gains (its ghost
    /// gains when it has none). None (an empty choice: every job drawn) where `device` draws the ray grids: the
    /// GPU draws every job, and so does the CPU should the GPU fail and the frame fall back to it, so no trace
    /// is spent on a choice nothing would use.
    fn dim_jobs(&self, device: &Device, frame: &Frame) -> Result<Vec<bool>, FrameError> {
        if matches!((&self.gpu, device, self.grid), (Some(_), Device::Gpu(_), Grid::Fixed(_))) {
            return Ok(Vec::new());
        }
        let cull_gains = frame.request.cull_gains.as_deref().unwrap_or(&frame.request.ghost_gains);
        self.renderer
            .dim_jobs(&self.cpu_request(frame, cull_gains, None))
            .map_err(|e| FrameError::Request(e.to_string()))
    }

    /// The CPU request of `frame`'s ghosts at `gains`, whose jobs too dim to see are left out ([`dim_for`]: a ray
    /// grid's, not the reference's, as the paraxial sprites and the LUT images are); `skip`, when given, is that
    /// choice made already for the frame's cull gains ([`RayGridRenderer::dim_jobs`]).
    fn cpu_request<'a>(&self, frame: &'a Frame, gains: &'a [f32], skip: Option<&'a [bool]>) -> RayGridRequest<'a> {
        let (light, (width, height)) = (frame.request.light_deg, (frame.scene.width, frame.scene.height));
        let request = RayGridRequest::frame_on(light, frame.request.sensor_width(), width, height, self.grid);
        let dim = match skip {
            Some(skip) => Dim::Skip(skip),
            None => dim_for(&self.config, frame, self.grid),
        };
        request.weighted(gains).dim(dim)
    }

    fn trace_gains(
        &self,
        device: &Device,
        frame: &Frame,
        gains: &[f32],
        skip: Option<&[bool]>,
    ) -> Result<Traced, FrameError> {
        let started = std::time::Instant::now();
        // On the frame's own sensor, as the paraxial sprites are drawn: a desqueezed frame's rows are the sensor's,
        // averaged down when it is written.
        let (light, (width, height)) = (frame.request.light_deg, (frame.scene.width, frame.scene.height));
        let sensor_width_mm = frame.request.sensor_width();
        let mut fallback = String::new();
        if let (Some(gpu), Device::Gpu(drawer), Grid::Fixed(cells)) = (&self.gpu, device, self.grid) {
            let window = Window::for_sensor(sensor_width_mm, width, height);
            match gpu.render(&drawer.ctx, &self.renderer, light, window, cells, self.gpu_samples, gains) {
                Ok(traced) => {
                    let how = format!(
                        "ray grids on the GPU ({}): {} ghost x wavelength jobs with light, {cells}-cell grid, {}, {} batches, {:.2} s{}",
                        drawer.ctx.adapter.name,
                        traced.jobs,
                        match self.gpu_samples {
                            0 => "box-filtered".to_string(),
                            s => format!("{s}x{s} samples a pixel"),
                        },
                        traced.batches,
                        started.elapsed().as_secs_f64(),
                        traced
                            .gpu_times
                            .map_or(String::new(), |t| format!(" (GPU time by timestamps: {})", t.summary()))
                    );
                    return Ok(Traced { hdr: traced.hdr, how });
                }
                Err(GpuRayGridError::Gpu(e)) => {
                    fallback = format!("ray grids on the GPU failed ({e}): traced on the CPU instead; ");
                }
                Err(e @ GpuRayGridError::Path { .. }) => {
                    fallback = format!("{e}: traced on the CPU instead; ");
                }
                Err(e) => return Err(FrameError::Request(e.to_string())),
            }
        }
        let request = self.cpu_request(frame, gains, skip);
        let traced = self
            .renderer
            .render_request(&request)
            .map_err(|e| FrameError::Request(e.to_string()))?
            .into_iter()
            .next()
            .ok_or_else(|| FrameError::Request("the ray-grid render drew no view".into()))?;
        let st = traced.stats;
        let how = format!(
            "{fallback}ray-traced on the CPU {} ghost x wavelength jobs, {:?} grid: {} rays, {} triangles, {} jobs with no light, {} too dim to see, {:.2} s",
            st.jobs,
            self.grid,
            st.rays,
            st.triangles,
            st.empty_jobs,
            st.dim_jobs,
            started.elapsed().as_secs_f64()
        );
        Ok(Traced { hdr: traced.hdr, how })
    }

    /// `frame` drawn with its ghosts traced (starburst and tonemap as every frame), and the tracing's line.
    pub fn draw(&self, device: &Device, frame: &Frame, sources: &Sources) -> Result<(Drawn, String), FrameError> {
        let traced = self.trace(device, frame)?;
        Ok((frame::drawn_with_traced_ghosts(frame, sources, traced.hdr), traced.how))
    }

    /// One layer per ghost the frame traces with light (`ghost_I_J`), each traced alone at its gain, times the
    /// flare's gain: they sum to the `flare` layer less the starburst.
    pub fn ghost_layers(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
    ) -> Result<Vec<(String, HdrImage)>, FrameError> {
        let mut layers = Vec::new();
        let pixel = crate::output::ExrPixel::Auto;
        self.ghost_layers_into(device, frame, sources, pixel, &mut |name, image| layers.push((name, image)))?;
        Ok(layers)
    }

    /// [`Self::ghost_layers`] handed to `sink` one at a time, refused once they would pass
    /// `frame::MAX_GHOST_LAYER_BYTES`.
    pub fn ghost_layers_into(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        pixel: crate::output::ExrPixel,
        sink: &mut frame::LayerSink,
    ) -> Result<(), FrameError> {
        let gains = &frame.request.ghost_gains;
        // The jobs the whole frame leaves out as too dim, left out of each ghost's layer too (the layers sum to
        // the flare).
        let dim = self.dim_jobs(device, frame)?;
        let mut made = 0;
        for (g, model) in sources.flare.system.ghosts.iter().enumerate() {
            let gain = gains.get(g).copied().unwrap_or(1.0);
            if !(gain > 0.0 && gain.is_finite()) {
                continue;
            }
            let alone: Vec<f32> =
                (0..sources.flare.system.ghosts.len()).map(|h| if h == g { gain } else { 0.0 }).collect();
            let traced = self.trace_gains(device, frame, &alone, Some(&dim))?;
            if traced.hdr.pixels.iter().all(|p| p[0] == 0.0 && p[1] == 0.0 && p[2] == 0.0) {
                continue;
            }
            made += 1;
            frame::check_ghost_layers(made, frame.request.width, frame.request.height, pixel)?;
            let hdr = frame::traced_accumulation(frame, &traced.hdr);
            sink(frame::ghost_layer_name(model.i, model.j), crate::render::cpu::flare_layer(&frame.scene, &hdr));
        }
        Ok(())
    }

    /// `frame` with its ghosts traced, written to `path` through the one writer ([`Self::draw_for_file`], then
    /// [`Self::write_made`]), and the tracing's line.
    pub fn render_to_file(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        choice: LayerChoice,
        path: &std::path::Path,
    ) -> Result<String, FrameError> {
        let (made, how) = self.draw_for_file(device, frame, sources, choice, path)?;
        self.write_made(device, frame, sources, &made, choice, path)?;
        Ok(how)
    }

    /// `frame` with its ghosts traced, as the file at `path` needs it ([`frame::draw_for_file`]'s rule: for an
    /// EXR the accumulation alone, `frame::linear_with_traced_ghosts`), and the tracing's line.
    pub fn draw_for_file(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        choice: LayerChoice,
        path: &std::path::Path,
    ) -> Result<(Made, String), FrameError> {
        Ok(match frame::check_output(path, choice)? {
            crate::output::ImageKind::Png => {
                let (drawn, how) = self.draw(device, frame, sources)?;
                (Made::Drawn(drawn), how)
            }
            crate::output::ImageKind::Exr => {
                let traced = self.trace(device, frame)?;
                (Made::Linear(frame::linear_with_traced_ghosts(frame, sources, traced.hdr)), traced.how)
            }
        })
    }

    /// Writes a frame made by [`Self::draw_for_file`] to `path` through the one writer; its ghost layers, when
    /// asked, traced.
    pub fn write_made(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        made: &Made,
        choice: LayerChoice,
        path: &std::path::Path,
    ) -> Result<(), FrameError> {
        frame::write_made_with(frame, sources, made, path, choice.exr, |sink| {
            self.ghost_sink(device, frame, sources, choice, sink)
        })
    }

    /// The ghost layers `choice` asks for, into `sink` (none unless it asks).
    fn ghost_sink(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        choice: LayerChoice,
        sink: &mut frame::LayerSink,
    ) -> Result<(), FrameError> {
        if choice.ghosts { self.ghost_layers_into(device, frame, sources, choice.exr.pixel_type, sink) } else { Ok(()) }
    }

    /// Writes a frame drawn by [`Self::draw`] to `path` through the one writer; its ghost layers, when asked,
    /// traced ([`Self::ghost_layers`]).
    pub fn write(
        &self,
        device: &Device,
        frame: &Frame,
        sources: &Sources,
        drawn: &Drawn,
        choice: LayerChoice,
        path: &std::path::Path,
    ) -> Result<(), FrameError> {
        frame::write_drawn_with(frame, sources, drawn, path, choice.exr, |sink| {
            self.ghost_sink(device, frame, sources, choice, sink)
        })
    }
}
