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

use crate::view_lut::ViewLut;
use crate::view_transform::{ViewTransform, WGSL_GROUP, WgslShader};

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

    fn with_shader(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tonemap_layout: &wgpu::BindGroupLayout,
        target_format: wgpu::TextureFormat,
        shader: &WgslShader,
        key: PassKey,
        compute: bool,
    ) -> Self {
        let stages = wgpu::ShaderStages::FRAGMENT | wgpu::ShaderStages::COMPUTE;
        debug_assert_eq!(WGSL_GROUP, 1, "the tonemap pipeline's layout puts the view at group 1");
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
        let dimension = |d: u32| match d {
            1 => (wgpu::TextureDimension::D1, wgpu::TextureViewDimension::D1),
            2 => (wgpu::TextureDimension::D2, wgpu::TextureViewDimension::D2),
            _ => (wgpu::TextureDimension::D3, wgpu::TextureViewDimension::D3),
        };
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
            entries.push(wgpu::BindGroupLayoutEntry {
                binding,
                visibility: stages,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            });
        }
        let layout = device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("ocio view"), entries: &entries });
        let textures: Vec<(u32, wgpu::Texture, wgpu::TextureViewDimension)> = shader
            .textures
            .iter()
            .map(|t| {
                let (dim, view_dim) = dimension(t.dimensions);
                // A filtered texture's f32 texels go up as 16-bit floats (filterable without a feature).
                let (format, bytes_per_texel, bytes) = match (t.filtered, t.rgba) {
                    (false, true) => (wgpu::TextureFormat::Rgba32Float, 16, t.bytes.clone()),
                    (false, false) => (wgpu::TextureFormat::R32Float, 4, t.bytes.clone()),
                    (true, rgba) => {
                        let values: Vec<f32> = bytemuck::pod_collect_to_vec(&t.bytes);
                        let halves: Vec<half::f16> = values.into_iter().map(crate::image::finite_half).collect();
                        let format =
                            if rgba { wgpu::TextureFormat::Rgba16Float } else { wgpu::TextureFormat::R16Float };
                        (format, if rgba { 8 } else { 2 }, bytemuck::cast_slice(&halves).to_vec())
                    }
                };
                let size = wgpu::Extent3d {
                    width: t.size[0].max(1),
                    height: t.size[1].max(1),
                    depth_or_array_layers: t.size[2].max(1),
                };
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
                (t.binding, texture, view_dim)
            })
            .collect();
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
        let views: Vec<(u32, wgpu::TextureView)> = textures
            .iter()
            .map(|(binding, texture, dim)| {
                (
                    *binding,
                    texture.create_view(&wgpu::TextureViewDescriptor { dimension: Some(*dim), ..Default::default() }),
                )
            })
            .collect();
        let mut group_entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .map(|(binding, v)| wgpu::BindGroupEntry {
                binding: *binding,
                resource: wgpu::BindingResource::TextureView(v),
            })
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
            group_entries
                .push(wgpu::BindGroupEntry { binding: *binding, resource: wgpu::BindingResource::Sampler(sampler) });
        }
        if let Some(buffer) = &uniform {
            group_entries.push(wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() });
        }
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ocio view"),
            layout: &layout,
            entries: &group_entries,
        });
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
        let compute = compute.then(|| {
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
                bind_group_layouts: &[Some(tonemap_layout), Some(&layout), Some(&output)],
                immediate_size: 0,
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("tonemap compute"),
                layout: Some(&layout),
                module: &module,
                entry_point: Some("cs_main"),
                compilation_options: Default::default(),
                cache: None,
            });
            (pipeline, output)
        });
        Self { key, pipeline, group, compute }
    }
}
