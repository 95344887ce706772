//! Ray grids on the GPU: Hullin et al. 2011's method traced and splatted in WGSL, the f64 CPU renderer
//! ([`crate::raytrace`], which knows nothing of the GPU) its twin.
//!
//! # How it works
//! The CPU plans the frame exactly as a fixed-grid CPU render does ([`RayGridRenderer::plan_fixed`]: per ghost
//! and wavelength, a coarse pre-pass over the front lens says where the dense grid of `cells` x `cells` cells
//! lies), then uploads per job its path (`GpuStep`: vertex, curvature, conic and aspheric terms, n_in / n_out,
//! reflect or refract, the clear aperture, which reflectance table) and the grid (`GpuJob`), and every dense
//! reflectance table (1025 samples over sin^2 i, the CPU renderer's own), and the pre-pass's lit cells (a ray
//! outside them is not traced, on the CPU as here). Two passes follow:
//! 1. `raygrid_trace.wgsl` (compute, one invocation per grid vertex, workgroup row = job): each ray traced
//!    exactly in f32 through every surface kind the CPU tracer has (spheres by the stable root, conics and even
//!    aspheres by the quadric's root then bounded Newton steps), its weight the reflectance at both reflections
//!    times `1 - R` at every refraction at its own angle and wavelength, its stop coordinates at every
//!    crossing and its largest height over the other clear apertures, into a [`GpuVertex`] buffer;
//! 2. `raygrid_splat.wgsl` (one instanced draw: instance = job, six vertices per cell): each cell's two
//!    triangles (the CPU's split), a triangle carrying its flux `cos(theta) x entrance area x weight` over its
//!    footprint, the mask looked up per pixel at each stop crossing, vignetted where the interpolated height
//!    passes a clear aperture, added into an Rgba32Float target (Rgba16Float where the adapter cannot blend
//!    32-bit floats).
//!
//! Jobs go in batches of one grid size; each batch's two passes write timestamps (the GPU's own time, summed
//! per pass into [`GpuRayGridImage::gpu_times`]) for a frame render. **The LUT bake** draws each column the
//! same way ([`GpuRayGrid::render_scouted`], [`GpuBake`]): the CPU plans it from the scout
//! ([`RayGridRenderer::plan_scouted`]), and the trace turns every landing and stop coordinate by the view's
//! turn (`rgb.w` of `GpuJob`), as the CPU's [`View`] does, once per azimuth.
//!
//! The CPU twin box-filters its triangles (`splat_triangle`). The default GPU path does the same in a compute
//! pass (`raygrid_box.wgsl`): each pixel a triangle touches gets the area and centroid of the triangle's part
//! in it, in closed form from the three edges (Green's theorem; no polygon is cut, on either side), and a
//! triangle collapsed to a line or a point puts its light in one pixel as on the CPU. Per row the pass also
//! finds, in closed form, where the shading can be non-zero and where it is the weight alone (no mask to look
//! up): nothing is done outside the first, and a run of whole pixels in the second is added as second
//! differences (O(1) a run), which the resolve sums along the row. On a hardware GPU each triangle is
//! splatted by `row_split` invocations, each taking every n-th of its rows, and each row is resolved by a
//! workgroup's scan (`resolve_box_scan`); a software adapter keeps one invocation per triangle and one per row
//! (`resolve_box`), the same sums. The tracer is compiled once per kind of
//! surface a lens has (`TraceShapes`). On a GPU it reads each job's path once per workgroup into workgroup
//! memory, all jobs in one dispatch; on a software adapter from uniform chunks of paths, a dispatch a chunk
//! ([`GpuRayGrid::set_chunked_paths`]). A path longer than either holds (255 steps: every ghost of a lens of up
//! to 85 surfaces) is [`GpuRayGridError::Path`], and the callers trace on the CPU. The jobs, the reflectance
//! tables, the mask and (copied after the trace) the vertices are read as rows of Rgba32Uint texels of four
//! words (`texel_at` in `word_texels.wgsl`): lavapipe, which loads a storage buffer's words lane by lane
//! wherever the lanes' indices may differ, fetches texels with gathers (on this 2-core machine the GPU ray grid
//! of the Nikon zoom at grid 64 went from 20 s to 10 s). The raster path (`--gpu-samples 1..8`) samples pixel
//! centres and drops collapsed triangles. Tests compare landings (the f32 drift, per lens) and images.
//! **Limits**: a grid whose dispatch, vertex buffer or supersampled target exceeds the adapter's limits is
//! refused with the limit named, before anything is dispatched; a frame's jobs are traced and drawn in batches
//! that fit the largest storage buffer the adapter binds and its largest 2D texture (`batches_of`). A device
//! lost on the way is [`GpuError::Lost`] (the command line then traces on the CPU).

use super::buffers::{
    TEXEL_ROW_BYTES, TEXELS_PER_ROW, compute_pipeline, compute_pipeline_with, software_device, spread_stride, storage,
    texel_texture, word_texels,
};
use super::gpu::{GpuContext, GpuError, PassTimes, map_read, read_texture, texture_2d};
use super::shaders::{RAYGRID_BOX_WGSL, RAYGRID_SPLAT_WGSL, RAYGRID_TRACE_WGSL};
use crate::image::HdrImage;
use crate::raytrace::{DENSE_TABLE_SAMPLES, Grid, PlannedJob, RayGridError, RayGridRenderer, Scout, View, Window};
use bytemuck::{Pod, Zeroable};
use wgpu_profiler::{GpuProfiler, GpuProfilerSettings};

/// One step of a ghost's path. Must be kept in sync with `struct Step` in `shaders/raygrid_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuStep {
    /// vertex z (mm), curvature (1/mm), conic, 1 / semi-aperture^2 (0 at the stop).
    pub surface: [f32; 4],
    /// n_in / n_out (f32 bits), offset of the reflectance table in the tables, flags ([`STEP_REFLECT`] ...), a
    /// toroid's x-z curvature (f32 bits).
    pub optics: [u32; 4],
    /// r^2 term, A4, A6, A8.
    pub terms_lo: [f32; 4],
    /// A10, A12, A14, A16.
    pub terms_hi: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuStep>() == 64);

/// [`GpuStep::optics`]'s flags (`STEP_*` in `shaders/raygrid_common.wgsl`): a reflection, the stop, the sphere
/// formulas alone, a toroid, arriving towards -z.
pub(crate) const STEP_REFLECT: u32 = 1;
pub(crate) const STEP_STOP: u32 = 2;
pub(crate) const STEP_SPHERE: u32 = 4;
pub(crate) const STEP_TOROID: u32 = 8;
pub(crate) const STEP_BACKWARD: u32 = 16;

/// One ghost at one wavelength. Must be kept in sync with `struct Job` in `shaders/raygrid_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuJob {
    /// First step, step count, first vertex, cells across.
    pub steps: [u32; 4],
    /// x0, y0 of the grid (mm), cell size x, y (mm).
    pub region: [f32; 4],
    /// The light's unit direction, the sensor plane's z (mm).
    pub direction: [f32; 4],
    /// Window centre x, y (sensor mm), pixels per mm, stop radius (mm).
    pub view: [f32; 4],
    /// Width, height (pixels), stop crossings looked at, a triangle's flux over a pixel's area.
    pub frame: [f32; 4],
    /// The wavelength's RGB weight, the view's turn about the axis (radians, counter-clockwise).
    pub rgb: [f32; 4],
    /// The pre-pass grid whose lit cells are traced: corner x, y (mm), cell size x, y (mm).
    pub lit: [f32; 4],
    /// Its first entry of lit bits in the tables buffer (16 bits an entry), cells across (0: no pre-pass, every
    /// ray traced), unused, unused.
    pub lit_cells: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuJob>() == 128);

/// One traced grid vertex. Must be kept in sync with `struct Vertex` in `shaders/raygrid_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuVertex {
    /// Landing point (image pixels).
    pub pixel: [f32; 2],
    pub ratio: f32,
    pub weight: f32,
    pub stops: [[f32; 2]; 3],
    /// 1 when the ray reached the sensor, else 0.
    pub valid: u32,
    pub pad: f32,
}
const _: () = assert!(std::mem::size_of::<GpuVertex>() == 48);

/// What [`GpuRayGrid::render`] is asked for by default: `BOX_FILTER`, each triangle box-filtered exactly
/// in a compute pass (`raygrid_box.wgsl`), as the CPU twin does.
pub const SUPERSAMPLE: u32 = BOX_FILTER;
/// The `supersample` that box-filters (compute); 1 to 8 rasterise the triangles (`raygrid_splat.wgsl`) at that
/// many samples a pixel across and average them, the earlier path, kept to compare.
pub(crate) const BOX_FILTER: u32 = 0;

/// The box-filter pass's parameters. Must be kept in sync with `struct BoxParams` in `shaders/raygrid_box.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
struct BoxParams {
    width: u32,
    height: u32,
    jobs: u32,
    first_row: u32,
    rows: u32,
    groups_x: u32,
    mask_size: u32,
    job_stride: u32,
    fixed_per_unit: f32,
    unit_per_fixed: f32,
    open_radius2: f32,
    support_radius2: f32,
}
const _: () = assert!(std::mem::size_of::<BoxParams>() == 48);
/// Bytes of one pixel's sums: R, G, B of 64 bits added directly, and R, G, B of 64 bits as second differences
/// along the row (the runs of whole pixels the shader adds in O(1)).
pub const BOX_BYTES_PER_PIXEL: u64 = 48;
/// Uniform offsets between dispatches (the largest alignment an adapter may ask for).
const BOX_STRIDE: u64 = 256;
/// Samples per dense reflectance table (the CPU renderer's).
const TABLE_SAMPLES: usize = DENSE_TABLE_SAMPLES;
/// Texels of one traced vertex (`vertex_at` in `raygrid_common.wgsl`).
const VERTEX_TEXELS: u64 = (std::mem::size_of::<GpuVertex>() / 16) as u64;

/// What [`GpuRayGrid::trace`] leaves: the jobs as a buffer (the raster splat's) and as texels (the tracer's and
/// the box filter's), and the traced vertices, `vertex_count` of them.
struct Traced {
    jobs: wgpu::Buffer,
    job_texels: wgpu::TextureView,
    vertices: wgpu::Buffer,
    vertex_count: u64,
}

/// The traced `vertices` (`count` of them, their buffer whole rows of texels) copied by `encoder` into rows of
/// Rgba32Uint texels for the box filter (`vertex_at` in `raygrid_common.wgsl`).
fn vertex_texels(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    vertices: &wgpu::Buffer,
    count: u64,
) -> wgpu::TextureView {
    let rows = (count * VERTEX_TEXELS).div_ceil(TEXELS_PER_ROW).max(1) as u32;
    let texture = texel_texture(device, "raygrid vertex texels", rows);
    encoder.copy_buffer_to_texture(
        wgpu::TexelCopyBufferInfo {
            buffer: vertices,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(TEXEL_ROW_BYTES as u32),
                rows_per_image: Some(rows),
            },
        },
        texture.as_image_copy(),
        wgpu::Extent3d { width: TEXELS_PER_ROW as u32, height: rows, depth_or_array_layers: 1 },
    );
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}
/// Invocations per workgroup of the tracer (`@workgroup_size` in `raygrid_trace.wgsl`).
const WORKGROUP: u32 = 64;

/// Why a GPU ray-grid render is refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum GpuRayGridError {
    #[error(transparent)]
    Plan(#[from] RayGridError),
    #[error("grid {cells}: {what} would need {needed}, beyond this adapter's limit {limit} ({name})")]
    Limit { cells: usize, what: &'static str, needed: u64, limit: u64, name: &'static str },
    /// A lens whose ghost paths are longer than the GPU tracer holds: traced on the CPU instead.
    #[error("a ghost's path has {steps} steps, beyond the {limit} the GPU tracer holds")]
    Path { steps: usize, limit: usize },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// What one GPU ray-grid render made.
#[derive(Clone, Debug)]
pub struct GpuRayGridImage {
    /// Linear irradiance relative to the light, ghosts only (as [`crate::raytrace::RayGridImage::hdr`]).
    pub hdr: HdrImage,
    /// Jobs drawn (ghost x wavelength with light) and batches they took.
    pub jobs: usize,
    pub batches: usize,
    /// GPU time of the passes, measured by timestamp queries ("trace" and "splat", every batch summed), where
    /// the adapter has them; nothing of the CPU's planning or of the read-back.
    pub gpu_times: Option<PassTimes>,
}

impl GpuRayGridImage {
    /// The image of a frame no job lights: black, nothing traced.
    fn black(window: Window) -> Self {
        Self { hdr: HdrImage::black(window.width, window.height), jobs: 0, batches: 0, gpu_times: None }
    }
}

/// The uploaded form of a planned frame.
struct Upload {
    steps: Vec<GpuStep>,
    jobs: Vec<GpuJob>,
    /// The reflectance tables (f32 bits), then the jobs' lit cells, 16 bits an entry ([`GpuJob::lit_cells`]).
    tables: Vec<u32>,
}

/// The GPU ray-grid renderer: its two pipelines, made once per device.
pub struct GpuRayGrid {
    trace_module: wgpu::ShaderModule,
    /// The tracer compiled for each [`TraceShapes`], made when first asked for.
    trace_pipelines: [std::sync::OnceLock<wgpu::ComputePipeline>; 3],
    splat_pipeline: wgpu::RenderPipeline,
    box_module: wgpu::ShaderModule,
    box_pipeline: wgpu::ComputePipeline,
    /// Invocations per triangle of `box_pipeline` ([`row_split`]); above 1 (a GPU), the resolve is
    /// `resolve_box_scan` (a workgroup per row), else `resolve_box` (an invocation per row).
    row_split: u32,
    resolve_pipeline: wgpu::ComputePipeline,
    /// Whether the tracer reads each job's path from uniform chunks, a dispatch a chunk (a software adapter),
    /// or from workgroup memory, one dispatch for all jobs (a GPU); see [`Self::set_chunked_paths`].
    chunked_paths: bool,
    /// The most bytes the box filter's sums may take (the adapter's limits; tests lower it to draw in strips).
    pub box_strip_bytes: u64,
    sampler: wgpu::Sampler,
    target_format: wgpu::TextureFormat,
    /// Times a frame's passes ([`Self::render`]; the bake's columns, drawn from many threads, are not timed).
    profiler: std::sync::Mutex<GpuProfiler>,
}

impl GpuRayGrid {
    pub fn new(device: &wgpu::Device) -> Self {
        let trace_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raygrid_trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(RAYGRID_TRACE_WGSL.into()),
        });
        let splat_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raygrid_splat.wgsl"),
            source: wgpu::ShaderSource::Wgsl(RAYGRID_SPLAT_WGSL.into()),
        });
        let target_format = if device.features().contains(wgpu::Features::FLOAT32_BLENDABLE) {
            wgpu::TextureFormat::Rgba32Float
        } else {
            wgpu::TextureFormat::Rgba16Float
        };
        let additive = super::buffers::ADDITIVE.color;
        let splat_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("raygrid splat"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &splat_module,
                entry_point: Some("vs_splat"),
                buffers: &[],
                compilation_options: Default::default(),
            },
            fragment: Some(wgpu::FragmentState {
                module: &splat_module,
                entry_point: Some("fs_splat"),
                targets: &[Some(wgpu::ColorTargetState {
                    format: target_format,
                    blend: Some(wgpu::BlendState { color: additive, alpha: additive }),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
                compilation_options: Default::default(),
            }),
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            multiview_mask: None,
            cache: None,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("raygrid aperture"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let profiler =
            GpuProfiler::new(device, GpuProfilerSettings::default()).expect("the default settings are valid");
        let box_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raygrid_box.wgsl"),
            source: wgpu::ShaderSource::Wgsl(RAYGRID_BOX_WGSL.into()),
        });
        let limits = device.limits();
        let row_split = row_split(device);
        let (box_pipeline, resolve_pipeline) = box_pipelines(device, &box_module, row_split);
        Self {
            trace_module,
            trace_pipelines: Default::default(),
            splat_pipeline,
            box_pipeline,
            box_module,
            row_split,
            resolve_pipeline,
            chunked_paths: software_device(device),
            box_strip_bytes: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            sampler,
            target_format,
            profiler: std::sync::Mutex::new(profiler),
        }
    }

    /// Invocations per triangle of the box splat (see [`Self::set_row_split`]).
    pub fn row_split(&self) -> u32 {
        self.row_split
    }

    /// Splats each triangle with `n` invocations (1 to 64), each drawing every n-th of its rows, and resolves
    /// the rows by a workgroup's scan where `n` is above 1, instead of the device's own choice
    /// (`row_split`): the same image (tests draw both on lavapipe).
    pub fn set_row_split(&mut self, device: &wgpu::Device, n: u32) {
        self.row_split = n.clamp(1, 64);
        (self.box_pipeline, self.resolve_pipeline) = box_pipelines(device, &self.box_module, self.row_split);
    }

    /// Whether the tracer reads paths from uniform chunks (see [`Self::set_chunked_paths`]).
    pub fn chunked_paths(&self) -> bool {
        self.chunked_paths
    }

    /// Traces with each job's path read from uniform chunks, one dispatch per chunk of jobs (`true`: what a
    /// software adapter does, whose loads from storage or workgroup memory at an index it cannot prove uniform
    /// go lane by lane), or from workgroup memory in one dispatch (`false`: a GPU's), instead of the device's
    /// own choice: the same vertices (tests trace both on lavapipe).
    pub fn set_chunked_paths(&mut self, chunked: bool) {
        self.chunked_paths = chunked;
        self.trace_pipelines = Default::default();
    }

    /// Workgroups of the resolve for a strip of `rows`: one invocation per row, or with the rows split (a GPU)
    /// one workgroup per row (`resolve_box_scan`).
    fn resolve_groups(&self, rows: u32) -> u32 {
        if self.row_split > 1 { rows } else { rows.div_ceil(WORKGROUP) }
    }

    /// The ghosts of `renderer` for a light at the frame position `light_deg`, seen in `window`, a `cells` x
    /// `cells` grid per ghost and wavelength, traced and drawn on `ctx`'s GPU: with `supersample` `BOX_FILTER`
    /// (the default) each triangle box-filtered exactly by a compute pass as the CPU twin does; else each pixel
    /// the mean of `supersample` x `supersample` samples (the triangles rasterised at that many times the
    /// resolution, then averaged), the earlier path, kept to compare.
    /// Ghost `g` is drawn at the gain `gains[g]` (missing entries are 1, gain 0 leaves it out), as the CPU's
    /// [`crate::raytrace::Ghosts::Weighted`].
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        &self,
        ctx: &GpuContext,
        renderer: &RayGridRenderer,
        light_deg: [f64; 2],
        window: Window,
        cells: usize,
        supersample: u32,
        gains: &[f32],
    ) -> Result<GpuRayGridImage, GpuRayGridError> {
        let planned = renderer.plan_fixed(light_deg, window, cells, gains)?;
        let jobs: Vec<&PlannedJob> = planned.iter().collect();
        let mut profiler = self.profiler.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        self.draw(ctx, renderer, &jobs, View { window, turn_deg: 0.0 }, supersample, Some(&mut profiler))
    }

    /// The GPU twin of a scouted CPU render ([`RayGridRenderer::render_request`] of
    /// [`crate::raytrace::RayGridRequest::scouted`]), what the GPU bake draws each LUT column with: the scout's
    /// ghost for the scout's light, its grid per wavelength placed by the CPU from the scout
    /// ([`RayGridRenderer::plan_scouted`]), traced and drawn once per view (each view turns the landings and the
    /// stop coordinates, as the CPU's does).
    pub fn render_scouted(
        &self,
        ctx: &GpuContext,
        renderer: &RayGridRenderer,
        scout: &Scout,
        views: &[View],
        grid: Grid,
        supersample: u32,
    ) -> Result<Vec<HdrImage>, GpuRayGridError> {
        let planned = renderer.plan_scouted(scout, views, grid)?;
        let jobs: Vec<&PlannedJob> = planned.iter().collect();
        views.iter().map(|view| Ok(self.draw(ctx, renderer, &jobs, *view, supersample, None)?.hdr)).collect()
    }

    /// Traces and draws `planned` seen in `view`: jobs of one grid size go in batches that fit the adapter's
    /// largest storage binding, every batch added into one target, read back once. With `profiler`, each
    /// batch's two passes write timestamps.
    fn draw(
        &self,
        ctx: &GpuContext,
        renderer: &RayGridRenderer,
        planned: &[&PlannedJob],
        view: View,
        supersample: u32,
        mut profiler: Option<&mut GpuProfiler>,
    ) -> Result<GpuRayGridImage, GpuRayGridError> {
        if let Some(reason) = ctx.failure() {
            return Err(GpuError::Lost(reason).into());
        }
        if let Some(e) = path_limit(planned) {
            return Err(e);
        }
        if supersample == BOX_FILTER {
            return self.draw_box(ctx, renderer, planned, view, profiler);
        }
        let window = view.window;
        let s = supersample.clamp(1, 8);
        let fine = Window { width: window.width * s, height: window.height * s, ..window };
        let (device, queue) = (&ctx.device, &ctx.queue);
        let limits = device.limits();
        let cells = planned.iter().map(|j| j.cells).max().unwrap_or(1);
        if let Some(e) = raster_refusal(&limits, cells, fine) {
            return Err(e);
        }
        if planned.is_empty() {
            return Ok(GpuRayGridImage::black(window));
        }
        let target = texture_2d(
            device,
            "raygrid hdr",
            fine.width,
            fine.height,
            self.target_format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let target_view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let mask = renderer.mask();
        let aperture_view = aperture_view(device, queue, mask);
        // Jobs of one grid size together, in batches whose vertices fit one storage binding (at most 256 MB,
        // and at most 65535 jobs, the dispatch's y).
        let mut batches = 0;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("raygrid") });
        {
            for batch in batches_of(planned, &limits) {
                let cells = batch[0].cells;
                let batch = batch.as_slice();
                let query = profiler.as_deref().map(|p| p.begin_pass_query("trace", &mut encoder));
                let writes = query.as_ref().and_then(|q| q.compute_pass_timestamp_writes());
                let Traced { jobs, vertices, .. } =
                    self.trace(device, queue, &mut encoder, renderer, batch, fine, view.turn_deg, writes);
                if let (Some(p), Some(q)) = (profiler.as_deref(), query) {
                    p.end_query(&mut encoder, q);
                }
                let query = profiler.as_deref().map(|p| p.begin_pass_query("splat", &mut encoder));
                let splat_group = self.splat_group(device, &vertices, &jobs, &aperture_view);
                let load =
                    if batches == 0 { wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT) } else { wgpu::LoadOp::Load };
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("raygrid splat"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &target_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
                    })],
                    timestamp_writes: query.as_ref().and_then(|q| q.render_pass_timestamp_writes()),
                    ..Default::default()
                });
                pass.set_pipeline(&self.splat_pipeline);
                pass.set_bind_group(0, &splat_group, &[]);
                pass.draw(0..(cells * cells * 6) as u32, 0..batch.len() as u32);
                drop(pass);
                if let Some(p) = profiler.as_deref_mut() {
                    if let Some(q) = query {
                        p.end_query(&mut encoder, q);
                    }
                    p.resolve_queries(&mut encoder);
                }
                batches += 1;
                submit_batch(device, queue, &mut encoder);
            }
        }
        let (hdr, gpu_times) = finish_frame(ctx, &target, self.target_format, profiler)?;
        Ok(GpuRayGridImage { hdr: hdr.box_reduced(s), jobs: planned.len(), batches, gpu_times })
    }

    /// The raster splat's bind group: a batch's traced `vertices` and `jobs`, and the aperture mask.
    fn splat_group(
        &self,
        device: &wgpu::Device,
        vertices: &wgpu::Buffer,
        jobs: &wgpu::Buffer,
        aperture: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raygrid splat"),
            layout: &self.splat_pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: vertices.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: jobs.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(aperture) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&self.sampler) },
            ],
        })
    }

    /// [`Self::draw`] box-filtered: each batch traced, then its triangles splatted by `splat_box` into 64-bit
    /// fixed-point sums (the unit is 2^-52 of the sum of every triangle's flux, a bound no pixel can pass), which
    /// `resolve_box` turns into the image. A frame whose sums do not fit one storage binding is drawn in strips
    /// of rows, each strip tracing the batches again.
    fn draw_box(
        &self,
        ctx: &GpuContext,
        renderer: &RayGridRenderer,
        planned: &[&PlannedJob],
        view: View,
        mut profiler: Option<&mut GpuProfiler>,
    ) -> Result<GpuRayGridImage, GpuRayGridError> {
        let window = view.window;
        let (device, queue) = (&ctx.device, &ctx.queue);
        let limits = device.limits();
        let cells = planned.iter().map(|j| j.cells).max().unwrap_or(1);
        if let Some(e) = self.box_refusal(&limits, cells, window) {
            return Err(e);
        }
        if planned.is_empty() {
            return Ok(GpuRayGridImage::black(window));
        }
        let target = texture_2d(
            device,
            "raygrid hdr",
            window.width,
            window.height,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        // Jobs of one grid size together, in batches whose vertices fit one storage binding (at most 256 MB,
        // and at most 65535 jobs, the dispatch's y).
        let batches = batches_of(planned, &limits);
        let frame = self.box_frame(ctx, renderer, planned, &batches, window, &target);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("raygrid") });
        let mut dispatched = 0;
        for (s, &first_row) in frame.strips.iter().enumerate() {
            for (b, batch) in batches.iter().enumerate() {
                let traced = {
                    let query = profiler.as_deref().map(|p| p.begin_pass_query("trace", &mut encoder));
                    let writes = query.as_ref().and_then(|q| q.compute_pass_timestamp_writes());
                    let traced =
                        self.trace(device, queue, &mut encoder, renderer, batch, window, view.turn_deg, writes);
                    if let (Some(p), Some(q)) = (profiler.as_deref(), query) {
                        p.end_query(&mut encoder, q);
                    }
                    traced
                };
                let grid = vertex_texels(device, &mut encoder, &traced.vertices, traced.vertex_count);
                let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("raygrid box"),
                    layout: &self.box_pipeline.get_bind_group_layout(0),
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&grid) },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&traced.job_texels),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&frame.mask_texels),
                        },
                        wgpu::BindGroupEntry { binding: 4, resource: frame.sums.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 3, resource: frame.params(s, b) },
                    ],
                });
                let cells = batch[0].cells;
                let groups_y = (2 * cells * cells * self.row_split as usize).div_ceil(WORKGROUP as usize) as u32;
                let pass = ("splat", "raygrid box", &self.box_pipeline);
                timed_dispatch(&mut encoder, profiler.as_deref(), pass, &group, (batch.len() as u32, groups_y));
                dispatched += 1;
                submit_batch(device, queue, &mut encoder);
            }
            let rows = frame.strip_rows.min(window.height - first_row);
            let groups = self.resolve_groups(rows);
            let groups_x = groups.min(limits.max_compute_workgroups_per_dimension).max(1);
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("raygrid resolve"),
                layout: &self.resolve_pipeline.get_bind_group_layout(0),
                entries: &[
                    // `resolve_box` reads the sums by atomics (binding 4), `resolve_box_scan` by plain loads.
                    wgpu::BindGroupEntry {
                        binding: if self.row_split > 1 { 6 } else { 4 },
                        resource: frame.sums.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry { binding: 3, resource: frame.params(s, batches.len()) },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::TextureView(&frame.target_view),
                    },
                ],
            });
            let pass = ("resolve", "raygrid resolve", &self.resolve_pipeline);
            timed_dispatch(&mut encoder, profiler.as_deref(), pass, &group, (groups_x, groups.div_ceil(groups_x)));
            if let Some(p) = profiler.as_deref_mut() {
                p.resolve_queries(&mut encoder);
            }
        }
        queue.submit(Some(encoder.finish()));
        let (hdr, gpu_times) = finish_frame(ctx, &target, wgpu::TextureFormat::Rgba32Float, profiler)?;
        Ok(GpuRayGridImage { hdr, jobs: planned.len(), batches: dispatched, gpu_times })
    }

    /// Why the box filter cannot draw jobs of `cells` cells into `window` on an adapter of `limits`, if it
    /// cannot.
    fn box_refusal(&self, limits: &wgpu::Limits, cells: usize, window: Window) -> Option<GpuRayGridError> {
        let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let max_groups = u64::from(limits.max_compute_workgroups_per_dimension);
        let limit = |what, needed: u64, limit: u64, name| {
            (needed > limit).then_some(GpuRayGridError::Limit { cells, what, needed, limit, name })
        };
        let row_bytes = u64::from(window.width) * BOX_BYTES_PER_PIXEL;
        let side = u64::from(window.width.max(window.height));
        shared_limits(limits, cells, side, "pixels across the frame")
            .or_else(|| {
                let groups = (2 * cells * cells) as u64 * u64::from(self.row_split) / u64::from(WORKGROUP);
                limit("workgroups per dispatch", groups, max_groups, "max_compute_workgroups_per_dimension")
            })
            .or_else(|| limit("bytes of sums for one row", row_bytes, binding, "max_storage_buffer_binding_size"))
            .or_else(|| {
                let rows = vertex_bytes(cells).div_ceil(TEXEL_ROW_BYTES);
                let max = u64::from(limits.max_texture_dimension_2d);
                limit("texel rows of vertices for one ghost", rows, max, "max_texture_dimension_2d")
            })
    }

    /// What every strip and batch of one box-filtered frame shares: the sums of one strip of rows, the mask,
    /// the target and every dispatch's parameters.
    fn box_frame(
        &self,
        ctx: &GpuContext,
        renderer: &RayGridRenderer,
        planned: &[&PlannedJob],
        batches: &[Vec<&PlannedJob>],
        window: Window,
        target: &wgpu::Texture,
    ) -> BoxFrame {
        let (device, queue) = (&ctx.device, &ctx.queue);
        let limits = device.limits();
        let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let row_bytes = u64::from(window.width) * BOX_BYTES_PER_PIXEL;
        let mask = renderer.mask();
        // The mask's bilinear footprints, one word each, fetched as texels and filtered in the shader as
        // `ApertureMask::sample` does (no sampler: a software rasteriser samples a texture several times slower).
        let quads = mask.quad_words();
        let mask_texels = word_texels(device, queue, "raygrid mask", bytemuck::cast_slice(&quads));
        let (fixed_per_unit, unit_per_fixed) = box_scale(planned, window);
        let strip_rows = (self.box_strip_bytes.min(binding) / row_bytes).clamp(1, u64::from(window.height)) as u32;
        let sums = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raygrid sums"),
            size: row_bytes * u64::from(strip_rows),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let strips: Vec<u32> = (0..window.height).step_by(strip_rows as usize).collect();
        // One parameter block per (strip, batch) dispatch and one per strip's resolve, at 256-byte strides.
        let per_strip = batches.len() + 1;
        let mut uniforms = vec![0u8; BOX_STRIDE as usize * strips.len() * per_strip];
        let mut block = |k: usize, params: BoxParams| {
            let at = k * BOX_STRIDE as usize;
            uniforms[at..at + std::mem::size_of::<BoxParams>()].copy_from_slice(bytemuck::bytes_of(&params));
        };
        for (s, &first_row) in strips.iter().enumerate() {
            let rows = strip_rows.min(window.height - first_row);
            let groups_x = self.resolve_groups(rows).min(limits.max_compute_workgroups_per_dimension).max(1);
            let base = BoxParams {
                width: window.width,
                height: window.height,
                first_row,
                rows,
                groups_x,
                fixed_per_unit,
                unit_per_fixed,
                open_radius2: mask.open_radius().powi(2),
                support_radius2: mask.support_radius().powi(2),
                mask_size: mask.size as u32,
                ..BoxParams::default()
            };
            for (b, batch) in batches.iter().enumerate() {
                let jobs = batch.len() as u32;
                block(s * per_strip + b, BoxParams { jobs, job_stride: spread_stride(jobs), ..base });
            }
            block(s * per_strip + batches.len(), base);
        }
        BoxFrame {
            uniforms: storage(device, queue, "raygrid box", &uniforms, wgpu::BufferUsages::UNIFORM),
            per_strip,
            sums,
            mask_texels,
            target_view: target.create_view(&wgpu::TextureViewDescriptor::default()),
            strips,
            strip_rows,
        }
    }

    /// The traced vertices of the first `jobs` planned jobs (for the landing comparison with the f64 tracer),
    /// with the plan they came from.
    pub fn trace_vertices<'r>(
        &self,
        ctx: &GpuContext,
        renderer: &'r RayGridRenderer,
        light_deg: [f64; 2],
        window: Window,
        cells: usize,
        jobs: usize,
    ) -> Result<(Vec<PlannedJob<'r>>, Vec<GpuVertex>), GpuRayGridError> {
        let mut planned = renderer.plan_fixed(light_deg, window, cells, &[])?;
        planned.truncate(jobs);
        // Every ray of each grid, lit cells or not: all of them are compared.
        for job in &mut planned {
            job.lit = None;
        }
        let (device, queue) = (&ctx.device, &ctx.queue);
        let size = ((cells + 1) * (cells + 1) * planned.len() * std::mem::size_of::<GpuVertex>()) as u64;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vertices readback"),
            size: size.max(16),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("trace") });
        let jobs: Vec<&PlannedJob> = planned.iter().collect();
        if let Some(e) = path_limit(&jobs) {
            return Err(e);
        }
        let Traced { vertices, .. } = self.trace(device, queue, &mut encoder, renderer, &jobs, window, 0.0, None);
        encoder.copy_buffer_to_buffer(&vertices, 0, &readback, 0, size);
        queue.submit(Some(encoder.finish()));
        let view = map_read(device, &readback, size)?;
        let out: Vec<GpuVertex> = bytemuck::pod_collect_to_vec(&view);
        Ok((planned, out))
    }
}

impl GpuRayGrid {
    /// The tracer compiled for `shapes`.
    fn trace_pipeline(&self, device: &wgpu::Device, shapes: TraceShapes) -> &wgpu::ComputePipeline {
        self.trace_pipelines[shapes as usize].get_or_init(|| {
            let constants =
                [("SHAPES", f64::from(shapes as u8)), ("CHUNKED_PATHS", f64::from(u8::from(self.chunked_paths)))];
            compute_pipeline_with(device, &self.trace_module, "trace_main", &constants)
        })
    }

    /// Uploads `jobs` (of one grid size, seen in `window` with the light turned by `turn_deg`) and records the
    /// tracer's dispatch into `encoder`: every grid vertex of every job, `(cells + 1)^2` a job in job order.
    /// Returns the jobs (as a buffer and as texels) and the vertex buffer.
    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        renderer: &RayGridRenderer,
        jobs: &[&PlannedJob],
        window: Window,
        turn_deg: f64,
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Traced {
        let upload = upload(renderer, jobs, window, turn_deg);
        let pipeline = self.trace_pipeline(device, TraceShapes::of(&upload.steps));
        let per_job = jobs.first().map_or(1, |j| (j.cells + 1) * (j.cells + 1)) as u64;
        let buffer = |label, contents: &[u8]| storage(device, queue, label, contents, wgpu::BufferUsages::STORAGE);
        let steps = buffer("raygrid steps", bytemuck::cast_slice(&upload.steps));
        let jobs_buffer = buffer("raygrid jobs", bytemuck::cast_slice(&upload.jobs));
        let tables = word_texels(device, queue, "raygrid tables", bytemuck::cast_slice(&upload.tables));
        let job_texels = word_texels(device, queue, "raygrid job texels", bytemuck::cast_slice(&upload.jobs));
        let vertex_count = per_job * jobs.len() as u64;
        let vertices = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raygrid vertices"),
            // Whole rows of texels, which `vertex_texels` copies.
            size: (vertex_count * VERTEX_TEXELS).div_ceil(TEXELS_PER_ROW).max(1) * TEXEL_ROW_BYTES,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        // The chunks of paths (`PathChunk` in the shader), each at an offset the adapter can bind; without
        // chunked paths one chunk of zeros, which that form never reads.
        let chunks = if self.chunked_paths { path_chunks(&upload.jobs) } else { vec![(0, 0)] };
        let align = u64::from(device.limits().min_uniform_buffer_offset_alignment).max(16);
        let mut chunk_bytes = Vec::new();
        let mut offsets = Vec::with_capacity(chunks.len());
        for &(first_job, end_job) in &chunks {
            let at = chunk_bytes.len().next_multiple_of(align as usize);
            offsets.push(at as u64);
            // The steps of jobs first_job .. end_job (none for the empty chunk).
            let (from, to) = match &upload.jobs[first_job..end_job] {
                [first, .., last] | [first @ last] => {
                    (first.steps[0] as usize, (last.steps[0] + last.steps[1]) as usize)
                }
                [] => (0, 0),
            };
            chunk_bytes.resize(at, 0);
            chunk_bytes.extend(bytemuck::cast_slice::<u32, u8>(&[first_job as u32, from as u32, 0, 0]));
            chunk_bytes.extend(bytemuck::cast_slice::<GpuStep, u8>(&upload.steps[from..to]));
        }
        // The last chunk's binding reaches CHUNK_BYTES past its offset (the others overlap the next: read only).
        chunk_bytes.resize(offsets.last().map_or(0, |&o| o as usize) + CHUNK_BYTES as usize, 0);
        let chunk_buffer = storage(device, queue, "raygrid path chunks", &chunk_bytes, wgpu::BufferUsages::UNIFORM);
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("raygrid trace"), timestamp_writes });
        pass.set_pipeline(pipeline);
        for (&(first_job, end_job), &offset) in chunks.iter().zip(&offsets) {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("raygrid trace"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: steps.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&job_texels) },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&tables) },
                    wgpu::BindGroupEntry { binding: 3, resource: vertices.as_entire_binding() },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &chunk_buffer,
                            offset,
                            size: wgpu::BufferSize::new(CHUNK_BYTES),
                        }),
                    },
                ],
            });
            pass.set_bind_group(0, &group, &[]);
            let count = if self.chunked_paths { end_job - first_job } else { jobs.len().max(1) };
            pass.dispatch_workgroups((per_job as u32).div_ceil(WORKGROUP), count as u32, 1);
        }
        drop(pass);
        Traced { jobs: jobs_buffer, job_texels, vertices, vertex_count }
    }
}

/// The surface kinds a batch's steps hold, which picks the tracer compiled for them (`override SHAPES` in
/// `raygrid_trace.wgsl`): a software rasteriser runs both sides of every branch, so what a lens lacks is left
/// out of its tracer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TraceShapes {
    /// Spheres and planes only.
    Spheres = 0,
    /// Also conics and aspheres.
    Aspheres = 1,
    /// Also toroids.
    Toroids = 2,
}

impl TraceShapes {
    fn of(steps: &[GpuStep]) -> Self {
        if steps.iter().any(|s| s.optics[2] & STEP_TOROID != 0) {
            Self::Toroids
        } else if steps.iter().any(|s| s.optics[2] & STEP_SPHERE == 0) {
            Self::Aspheres
        } else {
            Self::Spheres
        }
    }
}

/// The steps, jobs and tables of `jobs` seen in `window` with the light turned by `turn_deg`, every float
/// finite (a value that is not becomes 0: nothing that is not finite reaches a GPU buffer).
fn upload(renderer: &RayGridRenderer, jobs: &[&PlannedJob], window: Window, turn_deg: f64) -> Upload {
    let tables = renderer.tables();
    let (stop, stop_radius_mm) = renderer.stop();
    let mut out = Upload { steps: Vec::new(), jobs: Vec::new(), tables: Vec::new() };
    let mut lit_bits = Vec::new();
    // Each table the jobs use, once, at its offset.
    let mut offsets = std::collections::HashMap::new();
    let px_per_mm = window.px_per_mm();
    let pixel_area_mm2 = px_per_mm.powi(-2);
    let mut vertex = 0u32;
    for job in jobs {
        let first = out.steps.len() as u32;
        for (k, step) in job.tracer.steps().iter().enumerate() {
            let table = job.step_tables[k];
            let offset = *offsets.entry(table).or_insert_with(|| {
                let at = out.tables.len() as u32;
                // Tables are resampled to the shader's fixed size (they already have it; a zero table has 2).
                out.tables.extend(
                    (0..TABLE_SAMPLES)
                        .map(|i| finite(tables.table(table).at(i as f64 / (TABLE_SAMPLES - 1) as f64)).to_bits()),
                );
                at
            });
            let shape = &step.shape;
            let t = shape.terms;
            let flags = [
                (step.reflect, STEP_REFLECT),
                (step.surface == stop, STEP_STOP),
                (shape.spherical, STEP_SPHERE),
                (shape.toroidal, STEP_TOROID),
                (step.arriving_direction < 0.0, STEP_BACKWARD),
            ]
            .iter()
            .filter(|(on, _)| *on)
            .fold(0, |all, (_, flag)| all | flag);
            out.steps.push(GpuStep {
                surface: [step.vertex_z_mm, shape.curvature_per_mm, shape.conic, job.inverse_semi_aperture2[k]]
                    .map(finite),
                // A toroid's x-z curvature as f32 bits (0 for a surface of revolution).
                optics: [finite(step.eta).to_bits(), offset, flags, finite(shape.curvature_x_per_mm).to_bits()],
                terms_lo: [shape.a2, t[0], t[1], t[2]].map(finite),
                terms_hi: [t[3], t[4], t[5], t[6]].map(finite),
            });
        }
        let b = job.bounds;
        let n = job.cells as f64;
        let d = job.direction;
        // The lit cells as bits; a pre-pass whose numbers are not finite traces every ray.
        let (lit, lit_cells) = match &job.lit {
            Some(l) if l.cells > 0 && l.origin.iter().chain(&l.step).all(|v| v.is_finite() && v.abs() < 1e30) => {
                // Offsets into `lit_bits` for now: the tables go before them once all are known.
                let first = lit_bits.len() as u32;
                let mut words = vec![0u16; l.lit.len().div_ceil(16)];
                for (k, _) in l.lit.iter().enumerate().filter(|(_, lit)| **lit) {
                    words[k / 16] |= 1 << (k % 16);
                }
                lit_bits.extend(words);
                let region = [l.origin[0], l.origin[1], l.step[0], l.step[1]].map(|v| v as f32);
                (region, [first, l.cells as u32, 0, 0])
            }
            _ => ([0.0; 4], [0; 4]),
        };
        out.jobs.push(GpuJob {
            steps: [first, out.steps.len() as u32 - first, vertex, job.cells as u32],
            region: [b[0], b[1], (b[2] - b[0]) / n, (b[3] - b[1]) / n].map(finite),
            direction: [d.x, d.y, d.z, job.tracer.sensor_z_mm()].map(finite),
            view: [window.centre_mm[0], window.centre_mm[1], px_per_mm, stop_radius_mm].map(finite),
            frame: [
                f64::from(window.width),
                f64::from(window.height),
                job.stop_count as f64,
                job.triangle_flux / pixel_area_mm2,
            ]
            .map(finite),
            rgb: [job.rgb[0], job.rgb[1], job.rgb[2], turn_deg.to_radians()].map(finite),
            lit,
            lit_cells,
        });
        vertex += ((job.cells + 1) * (job.cells + 1)) as u32;
    }
    let tables_len = out.tables.len() as u32;
    for job in out.jobs.iter_mut().filter(|j| j.lit_cells[1] > 0) {
        job.lit_cells[0] += tables_len;
    }
    out.tables.extend(lit_bits.into_iter().map(u32::from));
    out
}

/// Bytes of one job's traced vertices on a `cells` grid.
fn vertex_bytes(cells: usize) -> u64 {
    ((cells + 1) * (cells + 1)) as u64 * std::mem::size_of::<GpuVertex>() as u64
}

/// `splat_box` with `row_split` invocations per triangle, and the resolve that goes with it: a workgroup's
/// scan per row where the rows are split (a GPU), else an invocation per row.
fn box_pipelines(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    row_split: u32,
) -> (wgpu::ComputePipeline, wgpu::ComputePipeline) {
    let splat = compute_pipeline_with(device, module, "splat_box", &[("ROW_SPLIT", f64::from(row_split))]);
    let resolve = compute_pipeline(device, module, if row_split > 1 { "resolve_box_scan" } else { "resolve_box" });
    (splat, resolve)
}

/// Invocations of `splat_box` per triangle (its `ROW_SPLIT`, each taking every n-th row): 1 on a software
/// rasteriser, which runs a workgroup's invocations one SIMD batch after another anyway, 8 on a GPU, where an
/// invocation walking a large triangle's rows alone keeps its warp waiting (NVIDIA H200, the Nikon at
/// 1920x1080: the splat took 59 ms at grid 64 and 114 ms at grid 32, whose triangles are four times larger).
/// Above 1 the resolve is `resolve_box_scan`: a device without room for its workgroup (256 invocations, 8 KiB
/// of workgroup memory) keeps 1.
fn row_split(device: &wgpu::Device) -> u32 {
    // `resolve_box_scan` takes 256 invocations a workgroup and 32 bytes of workgroup memory each.
    let l = device.limits();
    let scan_fits = l.max_compute_invocations_per_workgroup >= 256
        && l.max_compute_workgroup_size_x >= 256
        && l.max_compute_workgroup_storage_size >= 32 * 256;
    if software_device(device) || !scan_fits { 1 } else { 8 }
}

/// Why the raster splat cannot draw jobs of `cells` cells into the supersampled target `fine` on an adapter
/// of `limits`, if it cannot.
fn raster_refusal(limits: &wgpu::Limits, cells: usize, fine: Window) -> Option<GpuRayGridError> {
    let side = u64::from(fine.width.max(fine.height));
    shared_limits(limits, cells, side, "texels across the supersampled target").or_else(|| {
        let needed = (cells * cells * 6) as u64;
        (needed > u64::from(u32::MAX)).then_some(GpuRayGridError::Limit {
            cells,
            what: "vertices per draw",
            needed,
            limit: u64::from(u32::MAX),
            name: "u32 vertex index",
        })
    })
}

/// The limits every GPU ray-grid render checks before anything is dispatched: the tracer's workgroups, one
/// job's vertices in a storage binding, and the frame's `side` (named `what_side`) in a texture.
fn shared_limits(limits: &wgpu::Limits, cells: usize, side: u64, what_side: &'static str) -> Option<GpuRayGridError> {
    let limit = |what, needed: u64, limit: u64, name| {
        (needed > limit).then_some(GpuRayGridError::Limit { cells, what, needed, limit, name })
    };
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let vertices = ((cells + 1) * (cells + 1)) as u64;
    let max_groups = u64::from(limits.max_compute_workgroups_per_dimension);
    limit(
        "workgroups per dispatch",
        vertices.div_ceil(u64::from(WORKGROUP)),
        max_groups,
        "max_compute_workgroups_per_dimension",
    )
    .or_else(|| {
        limit("bytes of vertices for one ghost", vertex_bytes(cells), binding, "max_storage_buffer_binding_size")
    })
    .or_else(|| limit(what_side, side, u64::from(limits.max_texture_dimension_2d), "max_texture_dimension_2d"))
}

/// Steps of one ghost's path the tracer holds in workgroup memory (`MAX_PATH_STEPS` in `raygrid_trace.wgsl`;
/// 64 bytes each, within the 16352 bytes every adapter offers): every ghost of a lens of up to 85 surfaces.
const MAX_PATH_STEPS: usize = 255;

/// Steps one uniform chunk of paths holds (`CHUNK_STEPS` in `raygrid_trace.wgsl`), and the chunk's bytes: a
/// header of 16 bytes, then the steps; 16336 bytes, within the 16 KiB uniform binding of every adapter.
const CHUNK_STEPS: usize = 255;
const CHUNK_BYTES: u64 = 16 + CHUNK_STEPS as u64 * std::mem::size_of::<GpuStep>() as u64;
const _: () = assert!(CHUNK_BYTES <= 16 << 10 && MAX_PATH_STEPS <= CHUNK_STEPS);

/// Consecutive runs of `jobs` (first, end) whose paths together fit one chunk of [`CHUNK_STEPS`] (every path
/// does alone: [`path_limit`] refuses longer ones first).
fn path_chunks(jobs: &[GpuJob]) -> Vec<(usize, usize)> {
    let mut chunks = Vec::new();
    let (mut first, mut held) = (0, 0);
    for (j, job) in jobs.iter().enumerate() {
        let steps = job.steps[1] as usize;
        if held + steps > CHUNK_STEPS && j > first {
            chunks.push((first, j));
            (first, held) = (j, 0);
        }
        held += steps;
    }
    if first < jobs.len() {
        chunks.push((first, jobs.len()));
    }
    chunks
}

/// A path longer than the tracer holds (the command line and the app then trace on the CPU).
fn path_limit(planned: &[&PlannedJob]) -> Option<GpuRayGridError> {
    let steps = planned.iter().map(|j| j.tracer.steps().len()).max()?;
    (steps > MAX_PATH_STEPS).then_some(GpuRayGridError::Path { steps, limit: MAX_PATH_STEPS })
}

/// `planned` in batches of one grid size whose vertices fit one storage binding (at most 256 MB) and one texture
/// of texels, at most the dispatch's y of jobs, and whose tables and lit bits fit one texture of words.
fn batches_of<'a, 'p>(planned: &[&'a PlannedJob<'p>], limits: &wgpu::Limits) -> Vec<Vec<&'a PlannedJob<'p>>> {
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let table_words = table_capacity(limits);
    let mut order = planned.to_vec();
    order.sort_by_key(|j| j.cells);
    let mut batches: Vec<Vec<&PlannedJob>> = Vec::new();
    for same in order.chunk_by(|a, b| a.cells == b.cells) {
        // Vertices in one storage binding (at most 256 MB) and, as texels, in one texture.
        let bytes = binding.min(256 << 20).min(TEXEL_ROW_BYTES * u64::from(limits.max_texture_dimension_2d));
        let per_batch = (bytes / vertex_bytes(same[0].cells).max(1))
            .min(u64::from(limits.max_compute_workgroups_per_dimension))
            .max(1) as usize;
        // The tables' words of a batch: each reflectance table its jobs use, once, and each job's lit bits.
        let (mut tables, mut lit_words) = (std::collections::HashSet::new(), 0u64);
        let mut batch = Vec::new();
        for &job in same {
            let job_lit = job.lit.as_ref().map_or(0, |l| l.lit.len().div_ceil(16)) as u64;
            let new_tables = job.step_tables.iter().filter(|t| !tables.contains(*t)).count() as u64;
            let words = (tables.len() as u64 + new_tables) * TABLE_SAMPLES as u64 + lit_words + job_lit;
            if !batch.is_empty() && (batch.len() == per_batch || words > table_words) {
                batches.push(std::mem::take(&mut batch));
                (tables, lit_words) = (std::collections::HashSet::new(), 0);
            }
            tables.extend(job.step_tables.iter().copied());
            lit_words += job_lit;
            batch.push(job);
        }
        batches.push(batch);
    }
    batches
}

/// Words a texture of words holds (the tables, `tables` in `raygrid_trace.wgsl`): [`TEXELS_PER_ROW`] texels of
/// four a row, as many rows as the adapter's 2D textures hold.
fn table_capacity(limits: &wgpu::Limits) -> u64 {
    4 * TEXELS_PER_ROW * u64::from(limits.max_texture_dimension_2d)
}

/// The aperture mask as an R8 texture's view, for the splat passes' `aperture_at`.
fn aperture_view(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    mask: &crate::aperture::ApertureMask,
) -> wgpu::TextureView {
    let aperture = texture_2d(
        device,
        "raygrid aperture",
        mask.size as u32,
        mask.size as u32,
        wgpu::TextureFormat::R8Unorm,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    queue.write_texture(
        aperture.as_image_copy(),
        &mask.texels,
        wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(mask.size as u32), rows_per_image: None },
        aperture.size(),
    );
    aperture.create_view(&wgpu::TextureViewDescriptor::default())
}

/// What every strip and batch of one box-filtered frame shares ([`GpuRayGrid::box_frame`]).
struct BoxFrame {
    /// Every dispatch's [`BoxParams`], one block per (strip, batch) and one per strip's resolve, at
    /// [`BOX_STRIDE`] bytes.
    uniforms: wgpu::Buffer,
    /// Blocks per strip: the batches' and the resolve's.
    per_strip: usize,
    /// The 64-bit sums of one strip of rows.
    sums: wgpu::Buffer,
    mask_texels: wgpu::TextureView,
    target_view: wgpu::TextureView,
    /// Each strip's first row.
    strips: Vec<u32>,
    strip_rows: u32,
}

impl BoxFrame {
    /// The parameters of strip `strip`'s dispatch `k`: a batch's splat, or the resolve at `k` = batches.
    fn params(&self, strip: usize, k: usize) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: &self.uniforms,
            offset: (strip * self.per_strip + k) as u64 * BOX_STRIDE,
            size: wgpu::BufferSize::new(std::mem::size_of::<BoxParams>() as u64),
        })
    }
}

/// The box filter's fixed-point scale as (units per unit of radiance, radiance per unit): 2^52 units are the
/// most any pixel can gather, every triangle's flux (weights and masks are at most 1); (0, 0) without light.
fn box_scale(planned: &[&PlannedJob], window: Window) -> (f32, f32) {
    let pixel_area_mm2 = window.px_per_mm().powi(-2);
    let bound: f64 = planned
        .iter()
        .map(|j| {
            let rgb = j.rgb[0].max(j.rgb[1]).max(j.rgb[2]).max(0.0);
            2.0 * (j.cells * j.cells) as f64 * j.triangle_flux / pixel_area_mm2 * rgb
        })
        .filter(|v| v.is_finite())
        .sum();
    let units = 4_503_599_627_370_496.0; // 2^52
    if bound > 0.0 && bound.is_finite() { ((units / bound) as f32, (bound / units) as f32) } else { (0.0, 0.0) }
}

/// Records one compute pass, `(scope, label, pipeline)`, with `group` over `groups` workgroups, timed as
/// `scope` when `profiler` writes timestamps.
fn timed_dispatch(
    encoder: &mut wgpu::CommandEncoder,
    profiler: Option<&GpuProfiler>,
    (scope, label, pipeline): (&str, &str, &wgpu::ComputePipeline),
    group: &wgpu::BindGroup,
    groups: (u32, u32),
) {
    let query = profiler.map(|p| p.begin_pass_query(scope, encoder));
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: query.as_ref().and_then(|q| q.compute_pass_timestamp_writes()),
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups(groups.0, groups.1, 1);
    drop(pass);
    if let (Some(p), Some(q)) = (profiler, query) {
        p.end_query(encoder, q);
    }
}

/// Submits what `encoder` recorded and leaves a fresh encoder in its place: each batch's buffers are freed
/// once it has run.
fn submit_batch(device: &wgpu::Device, queue: &wgpu::Queue, encoder: &mut wgpu::CommandEncoder) {
    let fresh = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("raygrid") });
    queue.submit(Some(std::mem::replace(encoder, fresh).finish()));
}

/// Ends a render's profiler frame, reads `target` back and sums its passes' times. A device lost on the way
/// (or an error it reported on its own) spoils the image, whatever came back.
fn finish_frame(
    ctx: &GpuContext,
    target: &wgpu::Texture,
    format: wgpu::TextureFormat,
    mut profiler: Option<&mut GpuProfiler>,
) -> Result<(HdrImage, Option<PassTimes>), GpuRayGridError> {
    if let Some(p) = profiler.as_deref_mut() {
        // An error here means a query was left open: a bug, but never worth an image.
        let _ = p.end_frame();
    }
    let hdr = read_hdr(ctx, target, format);
    if let Some(reason) = ctx.failure() {
        return Err(GpuError::Lost(reason).into());
    }
    let gpu_times = profiler.and_then(|p| summed_times(&ctx.device, &ctx.queue, p));
    Ok((hdr?, gpu_times))
}

/// Waits for the GPU and returns the time of each pass of a render's batches (one profiler frame a render;
/// `PassTimes::from_results` sums every batch's scopes of one pass name), `None` without timestamps.
fn summed_times(device: &wgpu::Device, queue: &wgpu::Queue, profiler: &mut GpuProfiler) -> Option<PassTimes> {
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    let mut last = None;
    while let Some(results) = profiler.process_finished_frame(queue.get_timestamp_period()) {
        last = Some(PassTimes::from_results(&results));
    }
    last.filter(|t| !t.passes.is_empty())
}

/// `v` as f32, 0 where it is not finite.
fn finite(v: f64) -> f32 {
    let f = v as f32;
    if f.is_finite() { f } else { 0.0 }
}

/// Reads the accumulation back as linear RGB.
fn read_hdr(ctx: &GpuContext, target: &wgpu::Texture, format: wgpu::TextureFormat) -> Result<HdrImage, GpuError> {
    let size = target.size();
    let pixels: Vec<[f32; 4]> = if format == wgpu::TextureFormat::Rgba32Float {
        let bytes = read_texture(ctx, target, 16)?;
        bytemuck::cast_slice::<u8, f32>(&bytes).chunks_exact(4).map(|c| [c[0], c[1], c[2], 1.0]).collect()
    } else {
        let bytes = read_texture(ctx, target, 8)?;
        bytemuck::cast_slice::<u8, half::f16>(&bytes)
            .chunks_exact(4)
            .map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), 1.0])
            .collect()
    };
    let pixels = pixels.into_iter().map(|p| p.map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 })).collect();
    Ok(HdrImage { width: size.width, height: size.height, pixels })
}

/// The LUT bake's columns drawn on the GPU ([`GpuRayGrid::render_scouted`]; the scouts, windows and
/// refinement stay on the CPU). A column the GPU refuses (a limit) is traced on the CPU; a device lost on the
/// way sends that column and every later one to the CPU, and [`Self::fell_back`] says why, so the caller can
/// say so once.
pub struct GpuBake<'a> {
    ctx: &'a GpuContext,
    raygrid: GpuRayGrid,
    supersample: u32,
    lost: std::sync::Mutex<Option<String>>,
    on_gpu: std::sync::atomic::AtomicUsize,
    on_cpu: std::sync::atomic::AtomicUsize,
}

impl<'a> GpuBake<'a> {
    /// Columns drawn on `ctx`'s GPU at `supersample` x `supersample` samples a texel.
    pub fn new(ctx: &'a GpuContext, supersample: u32) -> Self {
        Self {
            ctx,
            raygrid: GpuRayGrid::new(&ctx.device),
            supersample,
            lost: std::sync::Mutex::new(None),
            on_gpu: Default::default(),
            on_cpu: Default::default(),
        }
    }

    /// The columns' tracer of a bake: `gpu` where there is one, else the CPU's (`crate::raytrace::CpuTracing`).
    pub fn or_cpu<'g>(gpu: Option<&'g GpuBake<'a>>) -> &'g dyn crate::raytrace::ColumnTracer {
        match gpu {
            Some(g) => g,
            None => &crate::raytrace::CpuTracing,
        }
    }

    /// Why the GPU stopped drawing columns (its device was lost), if it did.
    pub fn fell_back(&self) -> Option<String> {
        self.lost.lock().ok().and_then(|l| l.clone())
    }

    /// Columns drawn on the GPU and on the CPU so far.
    pub fn columns(&self) -> (usize, usize) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.on_gpu.load(Relaxed), self.on_cpu.load(Relaxed))
    }
}

impl crate::raytrace::ColumnTracer for GpuBake<'_> {
    fn trace_column(
        &self,
        renderer: &RayGridRenderer,
        scout: &Scout,
        views: Vec<View>,
        grid: Grid,
    ) -> Option<Vec<HdrImage>> {
        use std::sync::atomic::Ordering::Relaxed;
        if self.fell_back().is_none() {
            match self.raygrid.render_scouted(self.ctx, renderer, scout, &views, grid, self.supersample) {
                Ok(images) => {
                    self.on_gpu.fetch_add(1, Relaxed);
                    return Some(images);
                }
                Err(GpuRayGridError::Gpu(e)) => {
                    if let Ok(mut lost) = self.lost.lock() {
                        lost.get_or_insert(e.to_string());
                    }
                }
                // A refused grid or window: this column on the CPU.
                Err(_) => {}
            }
        }
        self.on_cpu.fetch_add(1, Relaxed);
        crate::raytrace::CpuTracing.trace_column(renderer, scout, views, grid)
    }
}

/// The ray grid's structs against `raygrid_common.wgsl`'s and `raygrid_box.wgsl`'s.
#[cfg(test)]
pub(crate) fn assert_layouts() {
    use super::shaders::{RAYGRID_BOX_WGSL, layout::*};
    assert_same_layout(RAYGRID_BOX_WGSL, "Step", fields!(GpuStep: surface, optics, terms_lo, terms_hi));
    assert_same_layout(
        RAYGRID_BOX_WGSL,
        "Job",
        fields!(GpuJob: steps, region, direction, view, frame, rgb, lit, lit_cells),
    );
    assert_same_layout(RAYGRID_BOX_WGSL, "Vertex", fields!(GpuVertex: pixel, ratio, weight, stops, valid, pad));
    assert_same_layout(
        RAYGRID_BOX_WGSL,
        "BoxParams",
        fields!(BoxParams: width, height, jobs, first_row, rows, groups_x, mask_size, job_stride, fixed_per_unit,
            unit_per_fixed, open_radius2, support_radius2),
    );
}
