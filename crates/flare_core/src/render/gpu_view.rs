//! The tonemap pass's pipeline for one OCIO display transform: the shader [`super::shaders::tonemap_wgsl`] of
//! the view's WGSL, and bind group [`WGSL_GROUP`] with the view's LUT textures (and its uniforms, when it has
//! any), uploaded once. The renderer makes a new one when a frame's view differs from the one it has (by
//! [`ViewTransform::key`]). A frame whose tonemap is one of FlareLab's curves gets the pass of no view
//! ([`ViewPass::curves`]: the shader's `ocio_display` the identity, never called): a software rasteriser runs
//! every side of a branch, masked, so a shader that holds the view's code costs it at every pixel whatever
//! tonemap the frame picks. For the same reason a software adapter's drafts get the pass of the view baked
//! into a cube ([`ViewPass::cube`], [`crate::view_lut`]), kept beside the exact view's so that neither is
//! made again when the drafts stop. Where the device runs compute shaders it also gets the pass as compute
//! (`cs_main`, writing an `rgba8unorm` storage texture: what the renderer uses when the target allows it),
//! beside the fragment pipeline (`fs_main`) every other target gets.

use super::buffers::sampler_entry;
use crate::view_lut::ViewLut;
use crate::view_transform::{ViewTransform, WGSL_GROUP, WgslShader, WgslTexture};

/// What a tonemap pass draws through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PassKey {
    /// FlareLab's curves: no view's code.
    Curves,
    /// The exact view of this key ([`ViewTransform::key`]).
    View(u64),
    /// The cube baked from the view of this key.
    Cube(u64),
}

/// The tonemap pipeline of one view and the resources its shader reads.
pub(super) struct ViewPass {
    /// What it draws through.
    pub key: PassKey,
    pub pipeline: wgpu::RenderPipeline,
    pub group: wgpu::BindGroup,
    /// The compute form and the layout of its group 2 (the target as a storage texture), where the device
    /// runs compute.
    pub compute: Option<(wgpu::ComputePipeline, wgpu::BindGroupLayout)>,
}

impl ViewPass {
    /// Records the tonemap of the accumulation into `target` within `frame`, `frame_group` being the frame's
    /// resources (group 0): as compute where the target is an rgba8unorm storage texture (see
    /// `FlareRenderer::target_usage`), else as a full-screen triangle.
    pub fn record(
        &self,
        device: &wgpu::Device,
        frame: &mut wgpu_profiler::Scope<'_, wgpu::CommandEncoder>,
        frame_group: &wgpu::BindGroup,
        target: &wgpu::TextureView,
    ) {
        let storage_target = (target.texture().format() == wgpu::TextureFormat::Rgba8Unorm
            && target.texture().usage().contains(wgpu::TextureUsages::STORAGE_BINDING))
        .then_some(self.compute.as_ref())
        .flatten();
        if let Some((pipeline, output_layout)) = storage_target {
            let output = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("tonemap target"),
                layout: output_layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(target) }],
            });
            let size = target.texture().size();
            let mut pass = frame.scoped_compute_pass("tonemap");
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, frame_group, &[]);
            pass.set_bind_group(1, &self.group, &[]);
            pass.set_bind_group(2, &output, &[]);
            pass.dispatch_workgroups(size.width.div_ceil(8), size.height.div_ceil(8), 1);
            return;
        }
        let mut pass = frame.scoped_render_pass(
            "tonemap",
            wgpu::RenderPassDescriptor {
                label: Some("flare tonemap"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            },
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, frame_group, &[]);
        pass.set_bind_group(1, &self.group, &[]);
        pass.draw(0..3, 0..1);
    }

    /// The pass of `view`, drawing into `target_format` (and, with `compute`, into `rgba8unorm` storage
    /// textures); group 0 is `tonemap_layout` (the frame's resources).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tonemap_layout: &wgpu::BindGroupLayout,
        target_format: wgpu::TextureFormat,
        view: &ViewTransform,
        compute: bool,
    ) -> Self {
        Self::with_shader(device, queue, tonemap_layout, target_format, &view.shader, PassKey::View(view.key), compute)
    }

    /// The pass of the view baked into `cube` (a software adapter's drafts).
    pub fn cube(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tonemap_layout: &wgpu::BindGroupLayout,
        target_format: wgpu::TextureFormat,
        cube: &ViewLut,
        compute: bool,
    ) -> Self {
        let shader = cube.shader();
        Self::with_shader(device, queue, tonemap_layout, target_format, &shader, PassKey::Cube(cube.key), compute)
    }

    /// The pass for frames drawn through one of FlareLab's curves: no view's code in the shader.
    pub fn curves(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tonemap_layout: &wgpu::BindGroupLayout,
        target_format: wgpu::TextureFormat,
        compute: bool,
    ) -> Self {
        let identity = WgslShader {
            text: super::shaders::OCIO_IDENTITY_WGSL.to_owned(),
            textures: Vec::new(),
            uniforms: None,
            sampler: None,
        };
        Self::with_shader(device, queue, tonemap_layout, target_format, &identity, PassKey::Curves, compute)
    }

    /// The pass of `shader` (a view's, its cube's or the identity), its key `key`.
    fn with_shader(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tonemap_layout: &wgpu::BindGroupLayout,
        target_format: wgpu::TextureFormat,
        shader: &WgslShader,
        key: PassKey,
        compute: bool,
    ) -> Self {
        debug_assert_eq!(WGSL_GROUP, 1, "the tonemap pipeline's layout puts the view at group 1");
        let layout = view_layout(device, shader);
        let group = view_group(device, queue, shader, &layout);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tonemap"),
            bind_group_layouts: &[Some(tonemap_layout), Some(&layout)],
            immediate_size: 0,
        });
        let source = super::shaders::tonemap_wgsl(&shader.text);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tonemap.wgsl with the OCIO view"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline =
            super::buffers::render_pipeline(device, "tonemap", &pipeline_layout, &module, &[], target_format, None);
        let compute = compute.then(|| compute_tonemap(device, [tonemap_layout, &layout], &module));
        Self { key, pipeline, group, compute }
    }
}

/// The texture and view dimensions of a texture of `dimensions` (1, 2 or 3).
fn dimension(dimensions: u32) -> (wgpu::TextureDimension, wgpu::TextureViewDimension) {
    match dimensions {
        1 => (wgpu::TextureDimension::D1, wgpu::TextureViewDimension::D1),
        2 => (wgpu::TextureDimension::D2, wgpu::TextureViewDimension::D2),
        _ => (wgpu::TextureDimension::D3, wgpu::TextureViewDimension::D3),
    }
}

/// The layout of the view's group ([`WGSL_GROUP`]): its uniforms at binding 0, its textures and its sampler.
fn view_layout(device: &wgpu::Device, shader: &WgslShader) -> wgpu::BindGroupLayout {
    let stages = wgpu::ShaderStages::FRAGMENT | wgpu::ShaderStages::COMPUTE;
    let mut entries = Vec::new();
    if shader.uniforms.is_some() {
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: stages,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        });
    }
    for t in &shader.textures {
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: t.binding,
            visibility: stages,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: t.filtered },
                view_dimension: dimension(t.dimensions).1,
                multisampled: false,
            },
            count: None,
        });
    }
    if let Some(binding) = shader.sampler {
        entries.push(wgpu::BindGroupLayoutEntry { visibility: stages, ..sampler_entry(binding) });
    }
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("ocio view"), entries: &entries })
}

/// The view's group: its textures uploaded, its uniforms and its sampler.
fn view_group(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    shader: &WgslShader,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::BindGroup {
    let views: Vec<(u32, wgpu::TextureView)> = shader.textures.iter().map(|t| upload(device, queue, t)).collect();
    let uniform = shader.uniforms.as_ref().map(|bytes| {
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ocio uniforms"),
            size: (bytes.len() as u64).max(16).next_multiple_of(16),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&buffer, 0, bytes);
        buffer
    });
    let mut entries: Vec<wgpu::BindGroupEntry> = views
        .iter()
        .map(|(binding, v)| wgpu::BindGroupEntry { binding: *binding, resource: wgpu::BindingResource::TextureView(v) })
        .collect();
    let sampler = shader.sampler.map(|binding| {
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("ocio view"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        (binding, sampler)
    });
    if let Some((binding, sampler)) = &sampler {
        entries.push(wgpu::BindGroupEntry { binding: *binding, resource: wgpu::BindingResource::Sampler(sampler) });
    }
    if let Some(buffer) = &uniform {
        entries.push(wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() });
    }
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("ocio view"), layout, entries: &entries })
}

/// `t` uploaded, with its binding and a view of it. A filtered texture's f32 texels go up as 16-bit floats
/// (filterable without a feature).
fn upload(device: &wgpu::Device, queue: &wgpu::Queue, t: &WgslTexture) -> (u32, wgpu::TextureView) {
    let (dim, view_dim) = dimension(t.dimensions);
    let (format, bytes_per_texel, bytes) = match (t.filtered, t.rgba) {
        (false, true) => (wgpu::TextureFormat::Rgba32Float, 16, t.bytes.clone()),
        (false, false) => (wgpu::TextureFormat::R32Float, 4, t.bytes.clone()),
        (true, rgba) => {
            let values: Vec<f32> = bytemuck::pod_collect_to_vec(&t.bytes);
            let halves: Vec<half::f16> = values.into_iter().map(crate::image::finite_half).collect();
            let format = if rgba { wgpu::TextureFormat::Rgba16Float } else { wgpu::TextureFormat::R16Float };
            (format, if rgba { 8 } else { 2 }, bytemuck::cast_slice(&halves).to_vec())
        }
    };
    let size =
        wgpu::Extent3d { width: t.size[0].max(1), height: t.size[1].max(1), depth_or_array_layers: t.size[2].max(1) };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("ocio lut"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: dim,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(size.width * bytes_per_texel),
            rows_per_image: Some(size.height),
        },
        size,
    );
    (t.binding, texture.create_view(&wgpu::TextureViewDescriptor { dimension: Some(view_dim), ..Default::default() }))
}

/// The tonemap's compute form over groups `[frame, view]`, and the layout of its group 2 (the target, an
/// rgba8unorm storage texture).
fn compute_tonemap(
    device: &wgpu::Device,
    [frame, view]: [&wgpu::BindGroupLayout; 2],
    module: &wgpu::ShaderModule,
) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let output = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("tonemap target"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::Rgba8Unorm,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        }],
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("tonemap compute"),
        bind_group_layouts: &[Some(frame), Some(view), Some(&output)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("tonemap compute"),
        layout: Some(&layout),
        module,
        entry_point: Some("cs_main"),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, output)
}
