//! GPU buffers, textures and compute pipelines made the one way every pass makes them.
//!
//! # How it works
//! [`storage`] creates a buffer and writes its contents through the queue rather than mapping it at creation:
//! on a lost device that is an error the device records (and the frame pipeline reports), never a panic. The
//! renderer's passes, the ray grids and the depth of field all upload through it. [`compute_pipeline`] makes
//! a compute pipeline with the layout its entry point implies (its bind groups are made from that layout), and
//! [`render_pipeline`] a full render pipeline of a shader's `vs_main` and `fs_main` into one target, and
//! [`upload`] writes a texture's texels (the renderer's textures and the compute ghosts' mask).

/// A render pipeline of `module`'s `vs_main` and `fs_main` drawing into one target of `format` (every pass
/// of the renderer: ghosts, starburst, LUT ghosts and the tonemap of `gpu_view`).
pub(crate) fn render_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    buffers: &[Option<wgpu::VertexBufferLayout>],
    format: wgpu::TextureFormat,
    blend: Option<wgpu::BlendState>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers,
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState { format, blend, write_mask: wgpu::ColorWrites::ALL })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A buffer of `usage` holding `contents`, written through the queue (on a lost device this is an error the
/// device records, not a panic as a buffer mapped at creation would be).
pub(crate) fn storage(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let size = (contents.len() as u64).max(16).next_multiple_of(4);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: usage | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, contents);
    buffer
}

/// Makes `slot` hold a storage buffer of at least `bytes` (at least 16): the one there, or a new one (zeroed
/// by wgpu) where there is none or it is smaller. Buffers a pass reuses from frame to frame grow this way.
pub(crate) fn grow_storage(device: &wgpu::Device, slot: &mut Option<(wgpu::Buffer, u64)>, label: &str, bytes: u64) {
    let bytes = bytes.max(16);
    if !matches!(slot, Some((_, size)) if *size >= bytes) {
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        *slot = Some((buffer, bytes));
    }
}

/// The compute pipeline of `module`'s `entry` point, its layout the one the entry point implies.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    entry: &str,
) -> wgpu::ComputePipeline {
    compute_pipeline_with(device, module, entry, &[])
}

/// [`compute_pipeline`] with the shader's pipeline constants (`override` declarations) set to `constants`.
pub(crate) fn compute_pipeline_with(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: None,
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
        cache: None,
    })
}

/// Whether `device` is a software rasteriser's (lavapipe): there a workgroup barrier costs more than a
/// scattered read and a workgroup's invocations run one SIMD batch after another, so the compute passes keep
/// one invocation per row (and per triangle) where a GPU splits the work finer.
pub(crate) fn software_device(device: &wgpu::Device) -> bool {
    device.adapter_info().device_type == wgpu::DeviceType::Cpu
}

/// The HDR accumulation format.
pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// A plain 2D texture (one mip level, one sample).
pub fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    width: u32,
    height: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// Writes `bytes` (rows of `bytes_per_pixel` bytes a texel, no padding) into the whole of `texture`'s first level.
pub(crate) fn upload(queue: &wgpu::Queue, texture: &wgpu::Texture, bytes: &[u8], bytes_per_pixel: u32) {
    let size = texture.size();
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(size.width * bytes_per_pixel),
            rows_per_image: Some(size.height),
        },
        size,
    );
}
