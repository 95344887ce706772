//! The flare viewport: `flare_core`'s wgpu renderer inside an egui paint callback (the app's one bridge
//! between egui and the renderer).
//!
//! # How it works
//! [`ViewportResources`] lives in egui-wgpu's callback resources: the [`FlareRenderer`] (its HDR accumulation
//! and tonemap pass), an offscreen sRGB texture it draws the tonemapped flare into, and a small pipeline
//! (`shaders/viewport.wgsl`) that draws that texture into egui's render pass. Each frame the app adds a
//! [`FlareCallback`] for the viewport's rect with its latest scene and that scene's generation (bumped when
//! the light, lens, gains, exposure... changed: the frame comes from `flare_core::frame`, the pipeline
//! every command draws through). `prepare` records the flare passes into egui's encoder
//! before egui's own pass only when the generation differs from the one last drawn; otherwise `paint` only
//! re-draws the texture (an egui repaint for a tooltip does not re-render the flare). A frame that is never
//! rendered (skipped by the windowing system, or by a test harness) loses nothing: the next one carries the
//! same scene. Uploads that follow edits (aperture mask, starburst, background plate, LUT atlas)
//! go through [`ViewportResources::with`] from the app. A missing resource is logged once, never a panic.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState, ScreenDescriptor};
use eframe::{egui, wgpu};
use flare_core::frame::Frame;
use flare_core::render::gpu::FlareRenderer;
use flare_core::render::shaders::VIEWPORT_WGSL;

/// The viewport pass's uniforms: `struct Params` in `shaders/viewport.wgsl` (a test checks the layout with naga).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct ViewportParams {
    /// 1 when egui's target is not an sRGB format (the pass encodes), else 0.
    encode_srgb: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

/// The offscreen texture's format as sampled: sRGB, so that sampling it gives linear values. The flare draws
/// into it as `Rgba8Unorm` (the sRGB-encoded bytes the tonemap writes) where the device runs compute and can view
/// a texture in its sRGB form: its tonemap is then a compute pass ([`FlareRenderer::target_usage`]).
const VIEW_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

static MISSING_LOGGED: AtomicBool = AtomicBool::new(false);

/// The GPU side of the viewport (see the module documentation).
pub struct ViewportResources {
    pub renderer: FlareRenderer,
    target: wgpu::Texture,
    size: (u32, u32),
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// The scene generation the texture shows (0: none yet).
    drawn: u64,
    /// The texture holds an image handed over by [`Self::show_image`] (the ray-grid view), not a drawn frame.
    shows_image: bool,
    /// The adapter is a software rasteriser (lavapipe): drafts are drawn by the raster passes there
    /// ([`FlareRenderer::rasterise_ghosts`]) and tonemapped through the view's cube
    /// ([`FlareRenderer::sample_view_from_cube`]).
    software: bool,
}

impl ViewportResources {
    /// Creates the resources in egui's device and registers them with egui-wgpu.
    pub fn install(render_state: &RenderState) {
        let device = &render_state.device;
        let srgb_views =
            render_state.adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::VIEW_FORMATS);
        let draw_format = if srgb_views && FlareRenderer::supports_compute(device) {
            wgpu::TextureFormat::Rgba8Unorm
        } else {
            VIEW_FORMAT
        };
        let renderer = FlareRenderer::new(device, &render_state.queue, draw_format);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("viewport"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("viewport"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("viewport.wgsl"),
            source: wgpu::ShaderSource::Wgsl(VIEWPORT_WGSL.into()),
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("viewport"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: render_state.target_format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("viewport"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let encode =
            ViewportParams { encode_srgb: u32::from(!render_state.target_format.is_srgb()), ..Default::default() };
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("viewport params"),
            size: std::mem::size_of::<ViewportParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        render_state.queue.write_buffer(&params, 0, bytemuck::bytes_of(&encode));
        let (target, bind_group) = Self::target(device, &renderer, &layout, &sampler, &params, (16, 16));
        let resources = Self {
            renderer,
            target,
            size: (16, 16),
            pipeline,
            layout,
            sampler,
            params,
            bind_group,
            drawn: 0,
            shows_image: false,
            software: render_state.adapter.get_info().device_type == wgpu::DeviceType::Cpu,
        };
        render_state.renderer.write().callback_resources.insert(resources);
    }

    /// The offscreen texture `renderer` draws into (its format and usages), sampled through its sRGB view.
    fn target(
        device: &wgpu::Device,
        renderer: &FlareRenderer,
        layout: &wgpu::BindGroupLayout,
        sampler: &wgpu::Sampler,
        params: &wgpu::Buffer,
        size: (u32, u32),
    ) -> (wgpu::Texture, wgpu::BindGroup) {
        let format = renderer.target_format();
        let usage = renderer.target_usage() | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("viewport flare"),
            size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: if format == VIEW_FORMAT { &[] } else { &[VIEW_FORMAT] },
        });
        // Sampled only: its sRGB form cannot be a storage binding, which the texture's own form is.
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            format: Some(VIEW_FORMAT),
            usage: Some(wgpu::TextureUsages::TEXTURE_BINDING),
            ..Default::default()
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("viewport"),
            layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Sampler(sampler) },
                wgpu::BindGroupEntry { binding: 2, resource: params.as_entire_binding() },
            ],
        });
        (texture, bind_group)
    }

    /// Runs `f` on the installed resources (for uploads after an edit, which also make the next frame draw
    /// again); `None` when they are missing.
    pub fn with<R>(
        render_state: &RenderState,
        f: impl FnOnce(&mut Self, &wgpu::Device, &wgpu::Queue) -> R,
    ) -> Option<R> {
        let mut renderer = render_state.renderer.write();
        let resources = renderer.callback_resources.get_mut::<Self>()?;
        resources.drawn = 0;
        resources.shows_image = false;
        Some(f(resources, &render_state.device, &render_state.queue))
    }
}

impl ViewportResources {
    /// Shows `image` (display pixels, sRGB) as the frame of `generation` instead of drawing that frame: the
    /// app's ray-grid view. A frame of another generation is drawn as usual; `false` when the resources are
    /// missing.
    pub fn show_image(render_state: &RenderState, generation: u64, image: &flare_core::image::DisplayImage) -> bool {
        let mut renderer = render_state.renderer.write();
        let Some(res) = renderer.callback_resources.get_mut::<Self>() else { return false };
        let size = (image.width.max(1), image.height.max(1));
        if size != res.size {
            (res.target, res.bind_group) =
                Self::target(&render_state.device, &res.renderer, &res.layout, &res.sampler, &res.params, size);
            res.size = size;
        }
        if image.pixels.len() == (image.width * image.height) as usize && image.width > 0 && image.height > 0 {
            render_state.queue.write_texture(
                res.target.as_image_copy(),
                bytemuck::cast_slice(&image.pixels),
                wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * image.width), rows_per_image: None },
                wgpu::Extent3d { width: image.width, height: image.height, depth_or_array_layers: 1 },
            );
        }
        res.drawn = generation;
        res.shows_image = true;
        true
    }

    /// Whether the texture shows an image handed over by [`Self::show_image`] for the frame of `generation`.
    pub fn shows_image(render_state: &RenderState, generation: u64) -> bool {
        Self::read(render_state, |res| res.shows_image && res.drawn == generation).unwrap_or(false)
    }

    /// Draws `draft` (a draft frame of the scene on screen) once into a texture of its own, the way a draft
    /// is drawn on a software adapter, and changes nothing shown. llvmpipe compiles a pipeline's code for each
    /// state at its first draw, and the view's cube is baked on a thread at the first draft that asks for it:
    /// without this, the first draft of the user's first drag waited about 100 ms behind both (issue 60's
    /// replay). Returns whether the draft went through the view's cube (or needs none): until it does, the
    /// app warms again once the cube is baked. `None` when the resources are missing.
    pub fn warm_up_drafts(render_state: &RenderState, draft: &Frame) -> Option<bool> {
        let mut renderer = render_state.renderer.write();
        let res = renderer.callback_resources.get_mut::<Self>()?;
        let (device, queue) = (&render_state.device, &render_state.queue);
        let scene = &draft.scene;
        let through_cube = Self::draft_through_cube(scene);
        let size = (scene.output_size.0.max(1), scene.output_size.1.max(1));
        let (target, _) = Self::target(device, &res.renderer, &res.layout, &res.sampler, &res.params, size);
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("warm-up") });
        res.renderer.rasterise_ghosts(true);
        res.renderer.sample_view_from_cube(true);
        res.renderer.render_with_lut(device, queue, &mut encoder, &view, scene, draft.lut.as_ref());
        queue.submit([encoder.finish()]);
        Some(through_cube)
    }

    /// Whether a draft of `scene` goes through the view's cube as it would be drawn now: its tonemap needs no
    /// cube, or the cube is baked (asked for on a thread when it is not).
    pub fn draft_through_cube(scene: &flare_core::render::FlareScene) -> bool {
        scene.globals.operator() != flare_core::color::Tonemap::View
            || flare_core::view_lut::ViewLut::ready_or_bake(&scene.view_transform()).is_some()
    }

    /// Reads the resources without touching them (nothing is drawn again); `None` before they exist.
    pub fn read<R>(render_state: &RenderState, f: impl FnOnce(&Self) -> R) -> Option<R> {
        let renderer = render_state.renderer.read();
        renderer.callback_resources.get::<Self>().map(f)
    }
}

/// A frame to draw and its generation.
pub type ViewFrame = (u64, Arc<Frame>);

/// One frame's viewport: the latest scene (drawn again only when its generation is new).
pub struct FlareCallback {
    pub frame: Option<ViewFrame>,
}

impl FlareCallback {
    /// Adds the viewport to `painter` over `rect`.
    pub fn paint(painter: &egui::Painter, rect: egui::Rect, frame: Option<ViewFrame>) {
        painter.add(egui_wgpu::Callback::new_paint_callback(rect, Self { frame }));
    }
}

fn missing() {
    if !MISSING_LOGGED.swap(true, Ordering::Relaxed) {
        eprintln!("flarelab: the viewport's GPU resources are missing; the flare is not drawn");
    }
}

impl CallbackTrait for FlareCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some((generation, frame)) = &self.frame else { return Vec::new() };
        let Some(res) = resources.get_mut::<ViewportResources>() else {
            missing();
            return Vec::new();
        };
        if res.drawn == *generation {
            // Nothing to draw: take the last frame's GPU times if they came back (the status bar shows them).
            res.renderer.collect_pass_times(queue);
            return Vec::new();
        }
        res.drawn = *generation;
        res.shows_image = false;
        let (scene, lut) = (&frame.scene, &frame.lut);
        let size = (scene.output_size.0.max(1), scene.output_size.1.max(1));
        if size != res.size {
            (res.target, res.bind_group) =
                ViewportResources::target(device, &res.renderer, &res.layout, &res.sampler, &res.params, size);
            res.size = size;
        }
        let view = res.target.create_view(&wgpu::TextureViewDescriptor::default());
        res.renderer.rasterise_ghosts(res.software && frame.draft.is_some());
        res.renderer.sample_view_from_cube(res.software && frame.draft.is_some());
        res.renderer.render_with_lut(device, queue, encoder, &view, scene, lut.as_ref());
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        render_pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(res) = resources.get::<ViewportResources>() else {
            missing();
            return;
        };
        render_pass.set_pipeline(&res.pipeline);
        render_pass.set_bind_group(0, &res.bind_group, &[]);
        render_pass.draw(0..3, 0..1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ViewportParams` has the layout of the shader's `Params`, member for member.
    #[test]
    fn the_params_have_the_shader_s_layout() {
        let module = naga::front::wgsl::parse_str(VIEWPORT_WGSL).unwrap();
        let (_, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("Params")).expect("Params");
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("Params is a struct") };
        assert_eq!(*span as usize, std::mem::size_of::<ViewportParams>());
        let rust = [
            ("encode_srgb", std::mem::offset_of!(ViewportParams, encode_srgb)),
            ("_pad0", std::mem::offset_of!(ViewportParams, _pad0)),
            ("_pad1", std::mem::offset_of!(ViewportParams, _pad1)),
            ("_pad2", std::mem::offset_of!(ViewportParams, _pad2)),
        ];
        let wgsl: Vec<(&str, usize)> =
            members.iter().map(|m| (m.name.as_deref().unwrap_or(""), m.offset as usize)).collect();
        assert_eq!(wgsl, rust);
    }
}
