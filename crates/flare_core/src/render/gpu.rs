//! The wgpu renderer: draws a [`FlareScene`] into a texture view it is given.
//!
//! # How it works
//! [`FlareRenderer`] is the frame's sequence of passes, each a primitive that owns its pipelines and its
//! resources: the compute ghosts (`gpu_ghosts`), the raster ghosts (`gpu_ghosts_raster`, with the aperture
//! mask's levels as textures; [`FlareRenderer::set_aperture`] gives them to both), the LUT ghosts (`gpu_lut`, `gpu_lut_raster`), the
//! starburst and the dirt's glow (`gpu_sprites`) and the tonemap (`gpu_view`). The renderer keeps what they
//! share: the frame's uniforms ([`Globals`]), the HDR accumulation (Rgba16Float, resized on demand), the
//! background plate (Rgba16Float), the LUT atlas, the sampler, the bind groups and the profiler. Called by the
//! app's viewport or by [`crate::frame`]'s headless drawer, it records its passes into the caller's encoder:
//! 1. the accumulation into the HDR target. Where the device runs compute shaders (`ComputeGhosts::supported`:
//!    every Vulkan, Metal and DX12 adapter), the LUT ghosts (`lut_compute.wgsl`, `render::gpu_lut`: per pixel
//!    the instances binned to its tile, into a LUT layer) and then the ghost sprites (`ghosts_compute.wgsl`,
//!    `render::gpu_ghosts`: per sprite and row the open span and the edges into 64-bit fixed-point row
//!    differences, summed once per row while the LUT layer is applied) are compute passes that write every
//!    pixel once, deterministically; elsewhere (a WebGL2-class device), and when
//!    [`FlareRenderer::rasterise_ghosts`] asks, `ghosts.wgsl` (clearing the target; one instanced quad per
//!    ghost sprite, additive) and `lut_ghosts.wgsl` (LUT images from the atlas, a 2D array of [`ATLAS_PAGE`]-texel
//!    Rgba16Float pages, added or composited over through alpha) rasterise them. Then `starburst.wgsl` (the
//!    diffraction texture at the light's image, additive) and, for a dirty front element, `dirt.wgsl` (its glow
//!    over the whole frame from the map of [`FlareRenderer::set_dirt`], additive; never drawn for a clean lens);
//! 2. `tonemap.wgsl`: the composite `hdr x 2^flare_ev + plate x 2^plate_ev`, the tonemap and (for non-sRGB
//!    targets) the sRGB encoding into the caller's view: as compute (`cs_main`) where the target is an
//!    `Rgba8Unorm` texture with a storage binding ([`FlareRenderer::target_usage`]) on a device that runs
//!    compute, else as a screen-covering triangle (`fs_main`), the same arithmetic. The OCIO view is OCIO's
//!    own shader, or, for the frames [`FlareRenderer::sample_view_from_cube`] asks it for (the app's drafts on
//!    a software adapter), the view baked into a cube (`ocio_lut.wgsl`, [`crate::view_lut`]).
//!
//! **GPU time, measured by the GPU**: every pass is a scope of a `wgpu_profiler::GpuProfiler`, which writes
//! timestamp queries at its start and end when the device has `TIMESTAMP_QUERY` (devices made here and the
//! app's ask for it where the adapter offers it; lavapipe does). Results come back asynchronously, a frame or
//! more later, without stalling: [`FlareRenderer::pass_times`] is the latest frame's ([`PassTimes`], per pass in
//! ms, named with the adapter), read by the app's status bar; the app's viewport, which draws only when its
//! frame changes, takes them on the UI frames between with [`FlareRenderer::collect_pass_times`] while
//! [`FlareRenderer::pass_times_pending`]; a headless caller that wants this frame's waits for it with
//! [`FlareRenderer::wait_pass_times`]. Without timestamp support there are simply no times.
//!
//! It never owns a window: the app hands it egui's device and a view, tests and the command line hand it a
//! headless device ([`GpuContext::headless`]) and read the result back ([`render_display_with_lut`],
//! [`read_hdr`]).
//! Rows copied to buffers are padded to 256 bytes as wgpu requires.

use wgpu_profiler::{GpuProfiler, GpuProfilerSettings, GpuTimerQueryResult};

pub(crate) use super::buffers::HDR_FORMAT;
pub use super::buffers::texture_2d;
use super::buffers::{
    frame_group, half_floats, sampled_texture, sampler_entry, texture_entry, uniform_entry, upload, upload_part,
};
use super::cpu::ghosts::GhostMasks;
use super::gpu_ghosts::{ComputeGhosts, mask_level_textures};
use super::gpu_ghosts_raster::RasterGhosts;
use super::gpu_lut::{ComputeLut, TILE};
use super::gpu_lut_raster::RasterLut;
use super::gpu_sprites::{SpritePass, sprite_layout};
use super::gpu_view::{PassKey, ViewPass};
use super::shaders::{DIRT_WGSL, STARBURST_WGSL};
use super::{FlareScene, Globals};
use crate::dirt::PreparedDirt;
use crate::image::{DisplayImage, HdrImage};
use crate::lut::blend::{ATLAS_PAGE, LiveLut, LutScene};
use crate::lut::blend::{Footprint, LutBins, bin_instances};
use crate::starburst::Starburst;

/// Why the GPU path is not available or failed.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (no Vulkan, Metal, DX12 or GL driver); install one (lavapipe: Debian's mesa-vulkan-drivers) or render on the CPU"
    )]
    NoAdapter,
    #[error("the GPU adapter {adapter} refused a device: {message}")]
    Device { adapter: String, message: String },
    #[error("reading the image back from the GPU failed: {0}")]
    Readback(String),
    #[error("the GPU device was lost ({0})")]
    Lost(String),
    #[error(
        "a {width}x{height} frame is beyond this adapter's limit of {max} pixels a side (max_texture_dimension_2d); use a smaller size or --device cpu"
    )]
    TooLarge { width: u32, height: u32, max: u32 },
    #[error("{what}, beyond this adapter's limit of {limit} ({name}); use a smaller size or --device cpu")]
    Limit { what: String, limit: u64, name: &'static str },
}

/// A device and queue made without any window.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    /// Why the device was lost, or the first error wgpu reported outside any call that returns one (the
    /// device is not trusted after either); `None` while it is healthy.
    failure: std::sync::Arc<std::sync::Mutex<Option<String>>>,
}

impl GpuContext {
    /// Picks an adapter with no surface. `prefer_software` ranks CPU adapters (lavapipe, llvmpipe) first,
    /// which keeps test images identical from machine to machine; otherwise real GPUs come first.
    pub fn headless(prefer_software: bool) -> Result<Self, GpuError> {
        Self::headless_on(wgpu::Backends::all(), prefer_software)
    }

    /// [`Self::headless`] among the adapters of `backends` alone (a test of the OpenGL ES backend, say).
    pub fn headless_on(backends: wgpu::Backends, prefer_software: bool) -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(backends));
        let rank = |info: &wgpu::AdapterInfo| {
            let software = info.device_type == wgpu::DeviceType::Cpu;
            let kind = match info.device_type {
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu => 2,
                wgpu::DeviceType::Cpu => 3,
                wgpu::DeviceType::Other => 4,
            };
            let vulkan_first = usize::from(info.backend != wgpu::Backend::Vulkan);
            if prefer_software { (usize::from(!software), vulkan_first, kind) } else { (kind, vulkan_first, 0) }
        };
        let adapter = adapters.into_iter().min_by_key(|a| rank(&a.get_info())).ok_or(GpuError::NoAdapter)?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("flarelab"),
            required_features: wanted_features(&adapter),
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device { adapter: info.name.clone(), message: e.to_string() })?;
        // A lost device or an uncaptured error is recorded, never a panic: the drawer then reports
        // `GpuError::Lost` and the frame pipeline falls back to the CPU twin.
        let failure = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
        // On one line: wgpu's messages run over several.
        let record = |failure: &std::sync::Arc<std::sync::Mutex<Option<String>>>, text: String| {
            if let Ok(mut f) = failure.lock() {
                f.get_or_insert(text.split_whitespace().collect::<Vec<_>>().join(" "));
            }
        };
        let lost = failure.clone();
        device.set_device_lost_callback(move |reason, message| record(&lost, format!("{reason:?}: {message}")));
        let errors = failure.clone();
        device.on_uncaptured_error(std::sync::Arc::new(move |e: wgpu::Error| record(&errors, e.to_string())));
        Ok(Self { device, queue, adapter: info, failure })
    }

    /// A headless device on a hardware GPU, for work that a software rasteriser does slower than the CPU (the
    /// LUT bake's columns, the app's ray-grid view): `Err` saying why when there is none (no adapter, or only a
    /// software one such as lavapipe).
    pub fn hardware() -> Result<Self, String> {
        let ctx = Self::headless(false).map_err(|e| e.to_string())?;
        if ctx.adapter.device_type == wgpu::DeviceType::Cpu {
            return Err(format!(
                "the only GPU adapter is {}, a software rasteriser slower than the CPU tracer",
                ctx.adapter.name
            ));
        }
        Ok(ctx)
    }

    /// Why the device can no longer be trusted (lost, or an error wgpu reported on its own), if it cannot.
    pub fn failure(&self) -> Option<String> {
        self.failure.lock().ok().and_then(|f| f.clone())
    }
}

/// The timestamp-query features `adapter` offers (none on adapters without them): what a device asks for so
/// that [`FlareRenderer`] can time its passes.
pub(crate) fn timer_features(adapter: &wgpu::Adapter) -> wgpu::Features {
    adapter.features() & GpuProfiler::ALL_WGPU_TIMER_FEATURES
}

/// The features a device for the renderer asks of `adapter`, where it has them: the timestamp queries
/// (`timer_features`) and blending into 32-bit float targets (the ray grids' splats and the rasterised LUT
/// layer's run sums add in f32 there, in f16 without it).
pub fn wanted_features(adapter: &wgpu::Adapter) -> wgpu::Features {
    timer_features(adapter) | (adapter.features() & wgpu::Features::FLOAT32_BLENDABLE)
}

/// GPU time of each pass of one frame, measured by timestamp queries on the GPU (ms), in drawing order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PassTimes {
    pub passes: Vec<(String, f64)>,
}

/// A scope's time that its nested scopes leave out is listed as its own entry (`"<label> (untimed part)"`)
/// when it is more than this share of the scope's time and more than [`REST_MIN_MS`].
const REST_SHARE: f64 = 0.1;
const REST_MIN_MS: f64 = 0.05;

impl PassTimes {
    /// From the profiler's results: every innermost scope that has a time, the scopes of one label (a pass
    /// repeated per strip of rows) summed into one entry, in the order each label first came. A scope with
    /// nested scopes (a compute pass timed by parts: the ghosts' spans and resolve) is trusted over its parts:
    /// where they add up to less than it (by more than a tenth and 0.05 ms), the difference is an entry of its
    /// own, so that the total is the pass's. lavapipe's timestamps inside a compute pass miss its dispatches:
    /// the zoom at 960x640 drew a "ghosts" pass of 102-108 ms whose spans and resolve scopes said 0.05-0.09 and
    /// 6.3-6.4 ms.
    pub(crate) fn from_results(results: &[GpuTimerQueryResult]) -> Self {
        fn add(out: &mut Vec<(String, f64)>, label: &str, ms: f64) {
            match out.iter_mut().find(|(l, _)| l == label) {
                Some((_, sum)) => *sum += ms,
                None => out.push((label.to_owned(), ms)),
            }
        }
        // Adds the scopes of `results` to `out`; returns the time it added.
        fn walk(results: &[GpuTimerQueryResult], out: &mut Vec<(String, f64)>) -> f64 {
            let mut added = 0.0;
            for r in results {
                let ms = r.time.as_ref().map(|t| (t.end - t.start) * 1e3).filter(|ms| ms.is_finite() && *ms >= 0.0);
                if r.nested_queries.is_empty() {
                    if let Some(ms) = ms {
                        add(out, &r.label, ms);
                        added += ms;
                    }
                } else {
                    let parts = walk(&r.nested_queries, out);
                    added += parts;
                    if let Some(ms) = ms {
                        let rest = ms - parts;
                        if rest > REST_MIN_MS && rest > REST_SHARE * ms {
                            add(out, &format!("{} (untimed part)", r.label), rest);
                            added += rest;
                        }
                    }
                }
            }
            added
        }
        let mut passes = Vec::new();
        walk(results, &mut passes);
        Self { passes }
    }

    /// The sum over the passes (ms).
    pub fn total_ms(&self) -> f64 {
        self.passes.iter().map(|p| p.1).sum()
    }

    /// The time of the pass `name` (ms), if it ran.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.passes.iter().find(|p| p.0 == name).map(|p| p.1)
    }

    /// "ghosts 1.20 + starburst 0.10 + tonemap 0.80 = 2.10 ms".
    pub fn summary(&self) -> String {
        let parts: Vec<String> = self.passes.iter().map(|(n, ms)| format!("{n} {ms:.2}")).collect();
        format!("{} = {:.2} ms", parts.join(" + "), self.total_ms())
    }
}

/// True when `FLARELAB_REQUIRE_GPU=1`: tests that need a GPU adapter (or a display) must then fail instead of
/// skipping (CI sets it: lavapipe and Xvfb are installed there).
pub(crate) fn gpu_required() -> bool {
    std::env::var("FLARELAB_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// A test that needs a GPU adapter or a display skips for want of one: it says so, or, when
/// `gpu_required`, fails with `reason`.
pub fn skip_without_gpu(reason: &str) {
    assert!(!gpu_required(), "FLARELAB_REQUIRE_GPU=1 but {reason}");
    println!("SKIPPED: {reason}");
}

/// The adapter tests use: a software one first (reproducible images); `None` when there is none (see
/// [`skip_without_gpu`]).
pub fn test_context() -> Option<GpuContext> {
    test_context_on(wgpu::Backends::all())
}

/// [`test_context`] on wgpu's OpenGL ES backend (llvmpipe's OpenGL in CI): what a machine without Vulkan draws
/// on, and what it lacks (1D textures, a one-layer texture viewed as an array) is tested there.
pub fn gl_test_context() -> Option<GpuContext> {
    let ctx = test_context_on(wgpu::Backends::GL)?;
    assert_eq!(ctx.adapter.backend, wgpu::Backend::Gl);
    Some(ctx)
}

fn test_context_on(backends: wgpu::Backends) -> Option<GpuContext> {
    match GpuContext::headless_on(backends, true) {
        Ok(ctx) => {
            println!("GPU adapter: {} ({:?}, {:?})", ctx.adapter.name, ctx.adapter.device_type, ctx.adapter.backend);
            Some(ctx)
        }
        Err(e) => {
            skip_without_gpu(&format!("{e} ({backends:?})"));
            None
        }
    }
}

/// An Rgba16Float 2D array texture of `pages` square pages of `side` texels holding `bytes` when given (half
/// floats, the pages in order; else filled later, [`LutAtlas::new`]). wgpu's OpenGL ES backend makes a texture of one layer a plain 2D texture, which the
/// shaders' array view then cannot read (wgpu issues 1574 and 1614: a one-page LUT drew 60% of its light
/// wrong): there the texture gets a second layer, left black and never sampled.
fn atlas_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    side: u32,
    pages: u32,
    bytes: Option<&[u8]>,
) -> wgpu::Texture {
    let pages = pages.max(1);
    let gl = device.adapter_info().backend == wgpu::Backend::Gl;
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("lut atlas"),
        size: wgpu::Extent3d { width: side, height: side, depth_or_array_layers: pages.max(if gl { 2 } else { 1 }) },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: HDR_FORMAT,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    if let Some(bytes) = bytes {
        let size = wgpu::Extent3d { width: side, height: side, depth_or_array_layers: pages };
        upload_part(queue, &texture, bytes, 8, size);
    }
    texture
}

/// A LUT's atlas texture, made and filled by [`LutAtlas::new`] on any thread (wgpu's device and queue are shared
/// between threads): a large LUT's atlas (13 pages, 436 MB of half floats) took 0.27 s to pack and 0.21 s to
/// write on lavapipe, which the app's UI thread no longer pays. [`FlareRenderer::set_lut_atlas`] takes it.
pub struct LutAtlas {
    texture: wgpu::Texture,
    lut_id: u64,
}

impl LutAtlas {
    /// Packs `live`'s entries and mip levels into atlas pages and writes them into a new texture, a page at a
    /// time (each write handed to the queue before the next page is packed: the memory it takes is a page's,
    /// not the atlas's twice over).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, live: &LiveLut) -> Self {
        if live.layout.pages == 0 {
            return Self { texture: empty_atlas(device, queue), lut_id: live.id };
        }
        let texture = atlas_texture(device, queue, ATLAS_PAGE, live.layout.pages, None);
        for page in 0..live.layout.pages {
            let texels = live.atlas_page(page);
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: 0, z: page },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(&texels),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(ATLAS_PAGE * 8),
                    rows_per_image: Some(ATLAS_PAGE),
                },
                wgpu::Extent3d { width: ATLAS_PAGE, height: ATLAS_PAGE, depth_or_array_layers: 1 },
            );
            queue.submit(std::iter::empty());
        }
        Self { texture, lut_id: live.id }
    }
}

/// The atlas when no LUT is set: one black texel.
fn empty_atlas(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::Texture {
    atlas_texture(device, queue, 1, 1, Some(&half_floats(&[[0.0; 4]])))
}

/// The GPU flare renderer: the frame's sequence of passes (the ghosts, the LUT ghosts, the starburst, the
/// dirt's glow, the tonemap), each of which owns its pipelines, and what they share (the frame's uniforms, the
/// accumulation, the sampler, the profiler).
pub struct FlareRenderer {
    /// The ghosts rasterised, where the compute pass does not draw them (it owns the aperture's levels).
    raster_ghosts: RasterGhosts,
    starburst: SpritePass,
    /// The front dirt's glow: its map D (Rgba16Float, D in red; 1 x 1 black for a clean lens).
    dirt: SpritePass,
    /// The tonemap pass of the last frame's OCIO view, or of FlareLab's curves when the frame's tonemap is one of
    /// them (made again when a frame's view, or its choice of the view, differs).
    view_pass: ViewPass,
    /// The tonemap pass of a view baked into a cube, for the frames [`Self::sample_view_from_cube`] asks it for
    /// (made when such a frame's view differs from its own; kept while frames go through `view_pass`).
    cube_pass: Option<ViewPass>,
    /// Tonemap the next frames whose tonemap is the view through the view's cube ([`Self::sample_view_from_cube`]).
    view_from_cube: bool,
    /// The starburst's and the dirt's resources (uniforms, a texture, a sampler).
    sprite_layout: wgpu::BindGroupLayout,
    tonemap_layout: wgpu::BindGroupLayout,
    globals: wgpu::Buffer,
    sampler: wgpu::Sampler,
    background: wgpu::Texture,
    has_background: bool,
    hdr: Option<(wgpu::Texture, u32, u32)>,
    target_format: wgpu::TextureFormat,
    /// The LUT layer rasterised (no compute, or bins past the storage binding).
    raster_lut: RasterLut,
    /// The LUT atlas (a 1 x 1 x 1 black array when no LUT is set).
    lut_atlas: wgpu::Texture,
    /// The bind groups of the last frame, made again only when a texture they bind was replaced.
    groups: Option<BindGroups>,
    /// Timestamp scopes around every pass (see the module documentation).
    profiler: GpuProfiler,
    /// A frame was recorded whose profiler frame is not yet ended (it is, once submitted: at the next render,
    /// [`Self::collect_pass_times`] or [`Self::wait_pass_times`]).
    profiled_open: bool,
    /// Profiler frames ended whose results have not come back yet (each comes back once, with or without
    /// timestamps).
    unread_frames: usize,
    /// The device writes timestamps (`TIMESTAMP_QUERY`): without, no frame ever has times to wait for.
    timed: bool,
    /// The latest frame's GPU pass times that came back.
    pass_times: Option<PassTimes>,
    /// The ghost sprites as compute ([`super::gpu_ghosts`]); `None` on a device that cannot run it, which
    /// rasterises them (`ghosts.wgsl`).
    compute: Option<ComputeGhosts>,
    /// The LUT ghosts as compute ([`super::gpu_lut`]), with the ghosts'.
    compute_lut: Option<ComputeLut>,
    /// The uploaded LUT's entry sizes and lit texels, to bin its instances ([`bin_instances`]).
    lut_footprints: Vec<Vec<Vec<Footprint>>>,
    /// Draw the next frames by the raster passes even where the compute passes could ([`Self::rasterise_ghosts`]).
    rasterise: bool,
    /// The most bytes a frame's LUT bins may take ([`Self::limit_lut_bin_bytes`]; the adapter's limits).
    lut_bin_bytes: u64,
}

/// Every bind group a frame uses (see [`FlareRenderer::bind_groups`]).
struct BindGroups {
    ghosts: wgpu::BindGroup,
    starburst: wgpu::BindGroup,
    dirt: wgpu::BindGroup,
    lut: wgpu::BindGroup,
    tonemap: wgpu::BindGroup,
}

/// The tonemap's bind group layout: the frame's uniforms, the accumulation, the plate and a sampler, read by
/// its fragment and its compute form alike.
fn tonemap_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let texture = |binding, filterable| texture_entry(binding, filterable, wgpu::TextureViewDimension::D2);
    let stages = wgpu::ShaderStages::VERTEX_FRAGMENT | wgpu::ShaderStages::COMPUTE;
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("tonemap"),
        entries: &[uniform_entry(0), texture(1, true), texture(2, false), sampler_entry(3)]
            .map(|e| wgpu::BindGroupLayoutEntry { visibility: stages, ..e }),
    })
}

impl FlareRenderer {
    /// Pipelines for drawing into views of `target_format`.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, target_format: wgpu::TextureFormat) -> Self {
        let (sprite_layout, tonemap_layout) = (sprite_layout(device), tonemap_layout(device));
        let starburst = SpritePass::new(device, queue, &sprite_layout, ("starburst", STARBURST_WGSL), 6);
        let dirt = SpritePass::new(device, queue, &sprite_layout, ("dirt", DIRT_WGSL), 3);
        let view_pass = ViewPass::new(
            device,
            queue,
            &tonemap_layout,
            target_format,
            &crate::view_transform::ViewTransform::builtin(),
            Self::supports_compute(device),
        );
        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("linear clamp"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let sampled = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let aperture = std::array::from_fn(|_| {
            let level = texture_2d(device, "aperture", 1, 1, wgpu::TextureFormat::R8Unorm, sampled);
            upload(queue, &level, &[255], 1);
            level
        });
        // Black, one texel, until a frame brings its plate.
        let background = sampled_texture(device, queue, "background", (1, 1), &[[0.0; 4]]);
        let lut_atlas = empty_atlas(device, queue);
        let compute = ComputeGhosts::supported(device).then(|| ComputeGhosts::new(device, queue));
        let compute_lut = compute.is_some().then(|| ComputeLut::new(device));
        Self {
            compute,
            compute_lut,
            lut_footprints: Vec::new(),
            rasterise: false,
            lut_bin_bytes: device.limits().max_storage_buffer_binding_size.min(device.limits().max_buffer_size),
            raster_lut: RasterLut::new(device),
            lut_atlas,
            groups: None,
            profiler: GpuProfiler::new(device, GpuProfilerSettings::default())
                .expect("the default profiler settings are valid"),
            profiled_open: false,
            unread_frames: 0,
            timed: device.features().contains(wgpu::Features::TIMESTAMP_QUERY),
            pass_times: None,
            raster_ghosts: RasterGhosts::new(device, aperture),
            view_pass,
            cube_pass: None,
            view_from_cube: false,
            sprite_layout,
            tonemap_layout,
            globals,
            sampler,
            starburst,
            dirt,
            background,
            has_background: false,
            hdr: None,
            target_format,
        }
    }

    /// Whether `device` runs the compute passes (the ghosts, the LUT images and the tonemap as compute).
    pub fn supports_compute(device: &wgpu::Device) -> bool {
        ComputeGhosts::supported(device)
    }

    /// The usages a target texture needs: a render attachment, and where the tonemap can run as compute (an
    /// `Rgba8Unorm` target on a device that runs compute) a storage binding, which makes it do so. A
    /// data-centre GPU shades fragments on a few units only: there the fragment tonemap of a 4K frame took
    /// 8.0 ms of GPU time (NVIDIA H200), the compute one a fraction of that.
    pub fn target_usage(&self) -> wgpu::TextureUsages {
        let storage = self.view_pass.compute.is_some() && self.target_format == wgpu::TextureFormat::Rgba8Unorm;
        wgpu::TextureUsages::RENDER_ATTACHMENT
            | if storage { wgpu::TextureUsages::STORAGE_BINDING } else { wgpu::TextureUsages::empty() }
    }

    /// The format of the views this renderer draws into.
    pub fn target_format(&self) -> wgpu::TextureFormat {
        self.target_format
    }

    /// Replaces the aperture mask's levels (when the aperture settings change).
    pub fn set_aperture(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, masks: &GhostMasks) {
        self.groups = None;
        let textures = mask_level_textures(device, queue, masks);
        if let Some(compute) = &mut self.compute {
            compute.set_aperture(device, queue, masks, &textures);
        }
        self.raster_ghosts.aperture = textures;
    }

    /// Whether the ghost sprites are drawn by the compute pass (`ghosts_compute.wgsl`) rather than rasterised
    /// (`ghosts.wgsl`, on devices without what the compute pass needs).
    pub fn ghosts_as_compute(&self) -> bool {
        self.compute.is_some()
    }

    /// How the compute ghost pass draws on this device (`None` where the ghosts are rasterised).
    pub fn ghost_compute_form(&self) -> Option<super::gpu_ghosts::ComputeForm> {
        self.compute.as_ref().map(|c| c.form)
    }

    /// Picks how the compute ghost pass draws (each device gets its own by default, [`super::gpu_ghosts::ComputeForm`]):
    /// the same image, to the byte, in every form (tests draw each on lavapipe).
    pub fn set_ghost_compute_form(&mut self, form: super::gpu_ghosts::ComputeForm) {
        if let Some(compute) = &mut self.compute {
            compute.form = form;
        }
    }

    /// Draws the ghost sprites by rasterising them (`ghosts.wgsl`) even where the compute pass could: the
    /// raster path, kept for devices without compute, tested and benchmarked against it.
    pub fn force_raster_ghosts(&mut self) {
        self.compute = None;
        self.compute_lut = None;
        self.hdr = None;
    }

    /// Draws the frames that follow by the raster passes (`ghosts.wgsl`, `lut_ghosts.wgsl`) while `yes`, even
    /// where the compute passes could. The app does this for its drafts on a software adapter: lavapipe's
    /// timestamps of compute passes come back far below the time they take, and the drafts' budget steers by
    /// the GPU's time, which its raster passes report truly.
    pub fn rasterise_ghosts(&mut self, yes: bool) {
        self.rasterise = yes;
    }

    /// Tonemaps the frames that follow, while `yes`, through their view baked into a cube
    /// ([`crate::view_lut`]) instead of the view's own code (frames through one of FlareLab's curves are not
    /// changed; until the view's cube is baked, on a thread of its own started by the first such frame, they
    /// go through the exact view). The app does this for its drafts on a software adapter, which would spend about a third of a
    /// draft's time in an ACES 2.0 view's shader; its full frames, and every frame on a hardware GPU, go
    /// through the exact view.
    pub fn sample_view_from_cube(&mut self, yes: bool) {
        self.view_from_cube = yes;
    }

    /// Caps the bytes of a frame's LUT bins (a test's way to reach the fallback of a frame whose bins pass the
    /// adapter's storage binding limit: its LUT images rasterised over the computed ghosts).
    pub fn limit_lut_bin_bytes(&mut self, bytes: u64) {
        self.lut_bin_bytes = bytes.min(self.lut_bin_bytes);
    }

    /// Whether the compute LUT pass draws its coarse instances into images of their level's size and upsamples
    /// them (each device has its own default: a hardware GPU yes, a software rasteriser no), or samples them at
    /// every pixel: the same values up to the order of the sums.
    pub fn set_lut_coarse_images(&mut self, yes: bool) {
        if let Some(lut) = &mut self.compute_lut {
            lut.coarse_images = yes;
        }
    }

    /// Caps the bytes of the LUT pass's coarse images (a test's way to reach the form of a frame whose coarse
    /// images pass the adapter's storage binding limit: each pixel samples the coarse instances itself).
    pub fn limit_lut_coarse_bytes(&mut self, bytes: u64) {
        if let Some(lut) = &mut self.compute_lut {
            lut.coarse_limit = bytes.min(lut.coarse_limit);
        }
    }

    /// Caps the bytes of the compute pass's difference buffer (a test's way to draw a frame in many strips, as
    /// one beyond the adapter's storage binding limit is drawn).
    pub fn limit_ghost_strip_bytes(&mut self, bytes: u64) {
        if let Some(compute) = &mut self.compute {
            compute.strip_bytes = bytes.min(compute.strip_bytes);
        }
    }

    /// Replaces the starburst texture.
    pub fn set_starburst(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, starburst: &Starburst) {
        self.groups = None;
        let texels: Vec<[f32; 4]> = starburst.profile.iter().map(|&p| [p, p, p, 1.0]).collect();
        self.starburst.set_texture(device, queue, (texels.len() as u32, 1), &texels);
    }

    /// Replaces the front dirt's map (`None`: a clean lens, a 1 x 1 black texture; the pass is drawn only for a
    /// frame that places a glow).
    pub fn set_dirt(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, dirt: Option<&PreparedDirt>) {
        self.groups = None;
        let (side, texels): (u32, Vec<[f32; 4]>) = match dirt {
            Some(d) => (d.size as u32, d.map.iter().map(|&v| [v, v, v, 1.0]).collect()),
            None => (1, vec![[0.0; 4]]),
        };
        self.dirt.set_texture(device, queue, (side, side), &texels);
    }

    /// Sets or clears the background plate (linear).
    pub fn set_background(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, plate: Option<&HdrImage>) {
        self.groups = None;
        self.has_background = plate.is_some();
        self.background = match plate {
            Some(p) => sampled_texture(device, queue, "background", (p.width, p.height), &p.pixels),
            None => sampled_texture(device, queue, "background", (1, 1), &[[0.0; 4]]),
        };
    }

    /// The HDR accumulation texture of the last render (for EXR output).
    pub fn hdr_texture(&self) -> Option<&wgpu::Texture> {
        self.hdr.as_ref().map(|(t, _, _)| t)
    }

    /// Uploads a LUT's atlas (`None` removes it).
    pub fn set_lut(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, lut: Option<&LiveLut>) {
        match lut {
            Some(live) => self.set_lut_atlas(live, LutAtlas::new(device, queue, live)),
            None => {
                self.groups = None;
                self.lut_footprints = Vec::new();
                self.lut_atlas = empty_atlas(device, queue);
            }
        }
    }

    /// [`Self::set_lut`] with its atlas already made ([`LutAtlas::new`], on any thread): what is left is cheap.
    pub fn set_lut_atlas(&mut self, live: &LiveLut, atlas: LutAtlas) {
        debug_assert_eq!(atlas.lut_id, live.id, "the atlas of another LUT");
        self.groups = None;
        self.lut_footprints = live.footprints.clone();
        self.lut_atlas = atlas.texture;
    }

    /// The bind groups of every pass for the current textures (made when one of them was replaced or the
    /// accumulation resized, not every frame).
    fn bind_groups(&self, device: &wgpu::Device, hdr_view: &wgpu::TextureView) -> BindGroups {
        let background_view = self.background.create_view(&wgpu::TextureViewDescriptor::default());
        let atlas_view = self.lut_atlas.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let (globals, sampler) = (&self.globals, &self.sampler);
        let sampled = || wgpu::BindingResource::Sampler(sampler);
        BindGroups {
            ghosts: self.raster_ghosts.bind_group(device, globals, sampler),
            starburst: self.starburst.bind_group(device, &self.sprite_layout, globals, sampler),
            dirt: self.dirt.bind_group(device, &self.sprite_layout, globals, sampler),
            lut: frame_group(device, "lut ghosts", &self.raster_lut.layout, globals, &atlas_view, vec![sampled()]),
            tonemap: frame_group(
                device,
                "tonemap",
                &self.tonemap_layout,
                globals,
                hdr_view,
                vec![wgpu::BindingResource::TextureView(&background_view), sampled()],
            ),
        }
    }

    /// Records the frame into `encoder`, drawing into `target` (of the renderer's target format, the scene's
    /// size): the paraxial ghosts, the LUT instances of `lut` (the atlas from [`Self::set_lut`]), the
    /// starburst, then the tonemap pass. A target whose texture has a storage binding
    /// ([`Self::target_usage`]) must be viewed whole, in the texture's own format: the tonemap then writes it
    /// as a storage texture.
    pub fn render_with_lut(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        scene: &FlareScene,
        lut: Option<&LutScene>,
    ) {
        // The previous frame was submitted by now: end its profiler frame and collect what came back.
        self.end_profiled_frame(queue, None);
        let (w, h) = (scene.hdr_width.max(1), scene.hdr_height.max(1));
        self.size_hdr(device, w, h);
        let through_cube = self.choose_view_pass(device, queue, scene);
        let mut globals = scene.globals;
        globals.encode_srgb = u32::from(!self.target_format.is_srgb());
        globals.plate_present = u32::from(self.has_background);
        queue.write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
        let use_compute = self.compute.is_some() && !self.rasterise;
        if !use_compute {
            self.raster_ghosts.upload(device, queue, &scene.instances);
        }
        let lut = lut.filter(|l| !l.instances.is_empty());
        let bins = lut.filter(|_| use_compute && self.compute_lut.is_some()).and_then(|lut| self.bins(scene, lut));
        let raster_lut = bins.is_none();
        if let Some(lut) = lut.filter(|_| raster_lut) {
            self.raster_lut.upload(device, queue, lut, (w, h));
        }
        let Some((hdr, _, _)) = &self.hdr else { return };
        let hdr_view = hdr.create_view(&wgpu::TextureViewDescriptor::default());
        if self.groups.is_none() {
            self.groups = Some(self.bind_groups(device, &hdr_view));
        }
        let Some(groups) = &self.groups else { return };
        {
            let mut frame = self.profiler.scope("flare", encoder);
            if let (true, Some(compute)) = (use_compute, &mut self.compute) {
                // The LUT layer first (the ghosts' resolve applies it), then the ghosts: every pixel of the
                // accumulation is written once, so nothing clears it.
                let layer = match (lut, &mut self.compute_lut, &bins) {
                    (Some(lut), Some(compute_lut), Some(bins)) => {
                        let atlas = self.lut_atlas.create_view(&wgpu::TextureViewDescriptor {
                            dimension: Some(wgpu::TextureViewDimension::D2Array),
                            ..Default::default()
                        });
                        let mut pass = frame.scoped_compute_pass("lut");
                        let sizes = ((scene.width, scene.height), (w, h));
                        Some(compute_lut.encode(device, queue, &mut pass, sizes, lut, bins, &atlas, &self.sampler))
                    }
                    _ => None,
                };
                let mut pass = frame.scoped_compute_pass("ghosts");
                compute.encode(device, queue, &mut pass, scene, &hdr_view, layer.as_ref());
            } else {
                self.raster_ghosts.draw(&mut frame, &hdr_view, &groups.ghosts, scene.instances.len());
            }
            if let Some(lut) = lut.filter(|_| raster_lut) {
                self.raster_lut.draw(&mut frame, &hdr_view, &groups.lut, lut);
            }
            if globals.starburst_reach_px > 0.0 {
                self.starburst.draw(&mut frame, &hdr_view, &groups.starburst);
            }
            if scene.has_dirt_glow() {
                self.dirt.draw(&mut frame, &hdr_view, &groups.dirt);
            }
            let tonemap = match &self.cube_pass {
                Some(cube) if through_cube => cube,
                _ => &self.view_pass,
            };
            tonemap.record(device, &mut frame, &groups.tonemap, target);
        }
        self.profiler.resolve_queries(encoder);
        self.profiled_open = true;
    }

    /// The LUT instances binned for the compute pass, or `None` where the bins would pass the adapter's largest
    /// storage binding (a frame of many thousand pixels a side with hundreds of instances): this frame's LUT
    /// images are then rasterised over the computed ghosts instead.
    fn bins(&self, scene: &FlareScene, lut: &LutScene) -> Option<LutBins> {
        let acc = (scene.hdr_width.max(1), scene.hdr_height.max(1));
        let bins = bin_instances((scene.width, scene.height), acc, lut, &self.lut_footprints, TILE);
        let bytes = 4 * (bins.starts.len() + bins.list.len() + 2 * bins.splits.len()) as u64;
        (bytes <= self.lut_bin_bytes).then_some(bins)
    }

    /// Makes the accumulation `w` x `h`, new bind groups with it where its size changed.
    fn size_hdr(&mut self, device: &wgpu::Device, w: u32, h: u32) {
        if matches!(&self.hdr, Some((_, hw, hh)) if *hw == w && *hh == h) {
            return;
        }
        let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC;
        if self.compute.is_some() {
            usage |= wgpu::TextureUsages::STORAGE_BINDING;
        }
        self.hdr = Some((texture_2d(device, "hdr", w, h, HDR_FORMAT, usage), w, h));
        self.groups = None;
    }

    /// Makes the tonemap pass `scene` asks for: the view's where its tonemap is the view (or its cube's, where
    /// asked), else the pass without the view's code (see `gpu_view`). True where the frame goes through the
    /// cube pass.
    fn choose_view_pass(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, scene: &FlareScene) -> bool {
        let view = (scene.globals.operator() == crate::color::Tonemap::View).then(|| scene.view_transform());
        let compute = self.view_pass.compute.is_some();
        let (layout, format) = (&self.tonemap_layout, self.target_format);
        // The cube is baked on a thread of its own the first time a frame asks for it: until it is, frames go
        // through the exact view.
        let cube = view.as_ref().filter(|_| self.view_from_cube).and_then(crate::view_lut::ViewLut::ready_or_bake);
        let Some(cube) = cube else {
            let key = view.as_ref().map_or(PassKey::Curves, |v| PassKey::View(v.key));
            if key != self.view_pass.key {
                self.view_pass = match &view {
                    Some(view) => ViewPass::new(device, queue, layout, format, view, compute),
                    None => ViewPass::curves(device, queue, layout, format, compute),
                };
            }
            return false;
        };
        if self.cube_pass.as_ref().map(|p| p.key) != Some(PassKey::Cube(cube.key)) {
            self.cube_pass = Some(ViewPass::cube(device, queue, layout, format, &cube, compute));
        }
        true
    }

    /// The GPU time of each pass of the latest frame whose timestamps have come back (`None` before any, or
    /// when the device has no timestamp queries). Never waits.
    pub fn pass_times(&self) -> Option<&PassTimes> {
        self.pass_times.as_ref()
    }

    /// Whether the last frame's pass times may still change what [`Self::pass_times`] says: its profiler frame
    /// is not ended, or its results have not come back. A caller that draws only when its scene changes (the
    /// app's viewport) calls [`Self::collect_pass_times`] until this is false, or the times it shows stay those
    /// of the frame before (a draft's, after the full frame that followed it).
    /// Never on a device without timestamp queries.
    pub fn pass_times_pending(&self) -> bool {
        self.timed && (self.profiled_open || self.unread_frames > 0)
    }

    /// Takes the pass times that came back since the last render, without drawing or waiting: ends the last
    /// render's profiler frame (its commands must have been submitted, as they are by the next UI frame).
    pub fn collect_pass_times(&mut self, queue: &wgpu::Queue) {
        self.end_profiled_frame(queue, None);
    }

    /// Ends the profiler frame of the last render (its commands must have been submitted), waits for the GPU
    /// when given the device, and takes whatever results have come back.
    fn end_profiled_frame(&mut self, queue: &wgpu::Queue, wait: Option<&wgpu::Device>) {
        // An error here means a scope was left open: a bug, but never worth a frame (nothing then comes back).
        if std::mem::take(&mut self.profiled_open) && self.profiler.end_frame().is_ok() {
            self.unread_frames += 1;
        }
        if let Some(device) = wait {
            let _ = device.poll(wgpu::PollType::wait_indefinitely());
        }
        // Older frames first: keep reading until the newest.
        while let Some(results) = self.profiler.process_finished_frame(queue.get_timestamp_period()) {
            self.unread_frames = self.unread_frames.saturating_sub(1);
            let times = PassTimes::from_results(&results);
            if !times.passes.is_empty() {
                self.pass_times = Some(times);
            }
        }
    }

    /// After the last render was submitted: waits for its timestamps and returns its pass times (`None`
    /// without timestamp queries). For headless callers (the benchmark); the app reads [`Self::pass_times`].
    pub fn wait_pass_times(&mut self, device: &wgpu::Device, queue: &wgpu::Queue) -> Option<PassTimes> {
        if !self.profiled_open {
            return None;
        }
        self.pass_times = None;
        self.end_profiled_frame(queue, Some(device));
        self.pass_times.clone()
    }
}

/// Copies `texture` (of `bytes_per_pixel`) into CPU memory, unpadding the 256-byte rows. A texture larger than
/// one buffer may be (the adapter's `max_buffer_size`; 64 MB at most here) comes back in strips of rows.
pub(crate) fn read_texture(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    bytes_per_pixel: u32,
) -> Result<Vec<u8>, GpuError> {
    read_texture_in_strips(ctx, texture, bytes_per_pixel, ctx.device.limits().max_buffer_size.min(64 << 20))
}

/// [`read_texture`] through read-back buffers of at most `largest` bytes (at least one row each).
fn read_texture_in_strips(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    bytes_per_pixel: u32,
    largest: u64,
) -> Result<Vec<u8>, GpuError> {
    let size = texture.size();
    let row = size.width * bytes_per_pixel;
    let padded = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let strip_rows = (largest / u64::from(padded)).clamp(1, u64::from(size.height.max(1))) as u32;
    let mut out = Vec::with_capacity((row * size.height) as usize);
    let mut y0 = 0;
    while y0 < size.height {
        let rows = strip_rows.min(size.height - y0);
        let bytes = u64::from(padded) * u64::from(rows);
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: y0, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(rows),
                },
            },
            wgpu::Extent3d { width: size.width, height: rows, depth_or_array_layers: 1 },
        );
        ctx.queue.submit(Some(encoder.finish()));
        let view = map_read(&ctx.device, &buffer, bytes)?;
        for y in 0..rows as usize {
            let start = y * padded as usize;
            out.extend_from_slice(&view[start..start + row as usize]);
        }
        y0 += rows;
    }
    Ok(out)
}

/// The first `bytes` of a `MAP_READ` buffer whose copy has been submitted: maps it and waits for the GPU.
pub(crate) fn map_read(device: &wgpu::Device, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
        let _ = sender.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
    receiver.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
    let view = buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
    Ok(view[..bytes as usize].to_vec())
}

/// Renders `scene` (with the LUT instances `lut`) headless into a texture of the renderer's format through
/// [`FlareRenderer::render_with_lut`] and reads the display image back.
pub fn render_display_with_lut(
    ctx: &GpuContext,
    renderer: &mut FlareRenderer,
    scene: &FlareScene,
    lut: Option<&LutScene>,
) -> Result<DisplayImage, GpuError> {
    let (width, height) = scene.output_size;
    let target = texture_2d(
        &ctx.device,
        "display",
        width,
        height,
        renderer.target_format(),
        renderer.target_usage() | wgpu::TextureUsages::COPY_SRC,
    );
    let view = target.create_view(&wgpu::TextureViewDescriptor::default());
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("flare") });
    renderer.render_with_lut(&ctx.device, &ctx.queue, &mut encoder, &view, scene, lut);
    ctx.queue.submit(Some(encoder.finish()));
    let bytes = read_texture(ctx, &target, 4)?;
    let pixels = bytes.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    Ok(DisplayImage { width, height, pixels })
}

/// Reads the HDR accumulation of the last render (linear, before exposure).
pub fn read_hdr(ctx: &GpuContext, renderer: &FlareRenderer) -> Result<HdrImage, GpuError> {
    let texture = renderer.hdr_texture().ok_or_else(|| GpuError::Readback("nothing rendered yet".into()))?;
    let size = texture.size();
    let bytes = read_texture(ctx, texture, 8)?;
    let halves: &[half::f16] = bytemuck::cast_slice(&bytes);
    let pixels = halves.chunks_exact(4).map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), c[3].to_f32()]).collect();
    Ok(HdrImage { width: size.width, height: size.height, pixels })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tonemap as compute (a target with a storage binding) writes the bytes the fragment pass writes
    /// (a target without one), on a frame of the zoom with its starburst, through the default OCIO view, and
    /// with a desqueeze (the delivered image smaller than the accumulation).
    #[test]
    fn the_tonemap_as_compute_writes_the_fragment_passes_bytes() {
        use crate::flare::{FlareConfig, PreparedFlare};
        use crate::frame::{Frame, FrameRequest, GpuDrawer, Sources};
        let Some(ctx) = test_context() else { return };
        let mut drawer = GpuDrawer::on(ctx);
        assert!(drawer.renderer.target_usage().contains(wgpu::TextureUsages::STORAGE_BINDING), "lavapipe runs compute");
        let lens = crate::optics::library::builtin_lens("nikon_zoom_28_75mm").unwrap();
        let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
        for desqueeze in [1.0, 1.5] {
            let request =
                FrameRequest { light_deg: [7.0, 4.0], width: 203, height: 117, desqueeze, ..FrameRequest::default() };
            let frame = Frame::build(&flare, None, &request);
            let sources = Sources { flare: &flare, lut: None, plate: None };
            let computed = drawer.draw(&frame, &sources).unwrap().display;
            let (w, h) = frame.scene.output_size;
            let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
            let target = texture_2d(&drawer.ctx.device, "fragment", w, h, wgpu::TextureFormat::Rgba8Unorm, usage);
            let view = target.create_view(&wgpu::TextureViewDescriptor::default());
            let mut encoder = drawer.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            drawer.renderer.render_with_lut(
                &drawer.ctx.device,
                &drawer.ctx.queue,
                &mut encoder,
                &view,
                &frame.scene,
                frame.lut.as_ref(),
            );
            drawer.ctx.queue.submit(Some(encoder.finish()));
            let fragment = read_texture(&drawer.ctx, &target, 4).unwrap();
            let computed: Vec<u8> = computed.pixels.iter().flatten().copied().collect();
            assert_eq!(computed.len(), fragment.len());
            let lit = computed.chunks(4).filter(|p| p[..3].iter().any(|&v| v > 0)).count();
            let worst = computed.iter().zip(&fragment).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(0);
            let differ = computed.iter().zip(&fragment).filter(|(a, b)| a != b).count();
            eprintln!("desqueeze {desqueeze}: {w}x{h}, {lit} lit pixels, {differ} bytes differ, worst {worst}/255");
            assert!(lit > (w * h / 20) as usize, "only {lit} lit pixels");
            assert!(worst <= 1 && differ * 1000 <= computed.len(), "{differ} bytes differ, worst {worst}/255");
        }
    }

    /// Pass times trust a pass over its timed parts: parts that add up to the pass keep it as they are; parts
    /// that miss most of it (lavapipe's timestamps inside a compute pass) leave the rest as an entry of its own,
    /// and the total is the pass's; a scope repeated (strips) is summed.
    #[test]
    fn pass_times_keep_what_a_pass_s_parts_leave_out() {
        let scope = |label: &str, ms: Option<(f64, f64)>, nested: Vec<GpuTimerQueryResult>| GpuTimerQueryResult {
            label: label.to_owned(),
            pid: 0,
            tid: std::thread::current().id(),
            time: ms.map(|(a, b)| a * 1e-3..b * 1e-3),
            nested_queries: nested,
        };
        let frame = |spans_end_ms: f64| {
            vec![scope(
                "flare",
                Some((0.0, 20.0)),
                vec![
                    scope(
                        "ghosts",
                        Some((0.0, 12.0)),
                        vec![
                            scope("ghost spans", Some((0.0, spans_end_ms)), vec![]),
                            scope("ghost resolve", Some((10.0, 11.0)), vec![]),
                            scope("ghost resolve", Some((11.0, 11.9)), vec![]),
                        ],
                    ),
                    scope("tonemap", Some((12.0, 20.0)), vec![]),
                    scope("untimed", None, vec![]),
                ],
            )]
        };
        let close = |t: &PassTimes, want: &[(&str, f64)]| {
            assert_eq!(t.passes.len(), want.len(), "{t:?}");
            for ((label, ms), (w_label, w_ms)) in t.passes.iter().zip(want) {
                assert_eq!(label, w_label, "{t:?}");
                assert!((ms - w_ms).abs() < 1e-9, "{t:?}");
            }
        };
        // The parts cover the pass but for 0.1 of 12 ms (under a tenth): as they are.
        let whole = PassTimes::from_results(&frame(10.0));
        close(&whole, &[("ghost spans", 10.0), ("ghost resolve", 1.9), ("tonemap", 8.0)]);
        // The spans' scope missed its dispatch: the untimed part of the pass is listed, the total is the frame's.
        let missed = PassTimes::from_results(&frame(0.1));
        close(
            &missed,
            &[("ghost spans", 0.1), ("ghost resolve", 1.9), ("ghosts (untimed part)", 10.0), ("tonemap", 8.0)],
        );
        assert!((missed.total_ms() - 20.0).abs() < 1e-9);
    }

    /// The last frame's GPU times come back without another frame being drawn (the app's viewport draws only
    /// when its frame changes, and collects them on the UI frames between): after a frame with the starburst
    /// and one without, the times shown are the second's, and nothing is left pending.
    #[test]
    fn the_last_frames_gpu_times_come_back_without_another_frame() {
        use crate::flare::{FlareConfig, PreparedFlare};
        use crate::frame::{Frame, FrameRequest, GpuDrawer};
        use crate::render::DisplaySettings;
        let Some(ctx) = test_context() else { return };
        let timestamps = ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut drawer = GpuDrawer::on(ctx);
        let lens = crate::optics::library::builtin_lens("heliar").unwrap();
        let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
        let frame = |starburst: bool| {
            let request = FrameRequest { light_deg: [7.0, 4.0], width: 96, height: 64, ..FrameRequest::default() };
            let display = DisplaySettings { starburst, ..request.display };
            Frame::build(&flare, None, &FrameRequest { display, ..request })
        };
        let (with, without) = (frame(true), frame(false));
        let (w, h) = with.scene.output_size;
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let target = texture_2d(&drawer.ctx.device, "times", w, h, wgpu::TextureFormat::Rgba8Unorm, usage);
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let labels = |drawer: &mut GpuDrawer, frame: &Frame| {
            let (device, queue) = (&drawer.ctx.device, &drawer.ctx.queue);
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            drawer.renderer.render_with_lut(device, queue, &mut encoder, &view, &frame.scene, None);
            queue.submit(Some(encoder.finish()));
            assert_eq!(drawer.renderer.pass_times_pending(), timestamps);
            // The UI frames that follow: nothing drawn, the times collected, the queue polled.
            for _ in 0..500 {
                drawer.renderer.collect_pass_times(queue);
                if !drawer.renderer.pass_times_pending() {
                    break;
                }
                let _ = device.poll(wgpu::PollType::Poll);
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            assert!(!drawer.renderer.pass_times_pending(), "the frame's times never came back");
            let times = drawer.renderer.pass_times().cloned();
            times.map(|t| t.passes.into_iter().map(|(label, _)| label).collect::<Vec<_>>())
        };
        for (frame, starburst) in [(&with, true), (&without, false), (&with, true)] {
            let labels = labels(&mut drawer, frame);
            eprintln!("starburst {starburst}: {labels:?}");
            match labels {
                Some(labels) => {
                    assert!(labels.iter().any(|l| l == "tonemap"), "{labels:?}");
                    assert_eq!(labels.iter().any(|l| l == "starburst"), starburst, "{labels:?}");
                }
                None => assert!(!timestamps, "timestamp queries, but no times"),
            }
        }
    }

    /// A texture read back in strips of rows (as one larger than the adapter's largest buffer is) gives the
    /// same bytes as in one piece, whatever the strip's height.
    #[test]
    fn a_texture_reads_back_the_same_in_strips() {
        let Some(ctx) = test_context() else { return };
        let (width, height) = (70u32, 37u32);
        let usage = wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST;
        let texture = texture_2d(&ctx.device, "strips", width, height, wgpu::TextureFormat::Rgba8Unorm, usage);
        let texels: Vec<u8> = (0..width * height * 4).map(|k| (k * 7 % 251) as u8).collect();
        ctx.queue.write_texture(
            texture.as_image_copy(),
            &texels,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * width), rows_per_image: None },
            texture.size(),
        );
        assert_eq!(read_texture(&ctx, &texture, 4).unwrap(), texels);
        // A padded row is 512 bytes here: strips of 1, 3 and 8 rows, and a limit under one row (still one).
        for largest in [512, 1536, 4096, 100] {
            assert_eq!(
                read_texture_in_strips(&ctx, &texture, 4, largest).unwrap(),
                texels,
                "strips of {largest} bytes"
            );
        }
    }
}
