//! GPU buffers, textures and compute pipelines made the one way every pass makes them.
//!
//! # How it works
//! [`storage`] creates a buffer and writes its contents through the queue rather than mapping it at creation:
//! on a lost device that is an error the device records (and the frame pipeline reports), never a panic. The
//! renderer's passes, the ray grids and the depth of field all upload through it. [`compute_pipeline`] makes
//! a compute pipeline with the layout its entry point implies (its bind groups are made from that layout), and
//! [`render_pipeline`] a full render pipeline of a shader's `vs_main` and `fs_main` into one target, and
//! [`upload`] writes a texture's texels (the renderer's textures and the compute ghosts' mask), 16-bit floats
//! from [`half_floats`] ([`sampled_texture`] makes and fills one). [`frame_group`] binds what the renderer's raster passes share: the frame's uniforms at
//! binding 0, the pass's texture at 1, then its own resources.

/// Every source added to what the target holds (the accumulation's passes).
pub(crate) const ADDITIVE: wgpu::BlendState = wgpu::BlendState {
    color: wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::One,
        dst_factor: wgpu::BlendFactor::One,
        operation: wgpu::BlendOperation::Add,
    },
    alpha: wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::One,
        dst_factor: wgpu::BlendFactor::One,
        operation: wgpu::BlendOperation::Add,
    },
};

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
pub(crate) const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

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
    upload_part(queue, texture, bytes, bytes_per_pixel, texture.size());
}

/// [`upload`] into the first `size` texels of `texture` (its first layers, say).
pub(crate) fn upload_part(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    bytes: &[u8],
    bytes_per_pixel: u32,
    size: wgpu::Extent3d,
) {
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

/// Texels a row of the textures that hold words (`TEXELS_PER_ROW` in `word_texels.wgsl`; the 2D size every
/// adapter offers), four 32-bit words a texel, and a row's bytes.
pub(crate) const TEXELS_PER_ROW: u64 = 2048;
pub(crate) const TEXEL_ROW_BYTES: u64 = TEXELS_PER_ROW * 16;

/// A texture of `rows` rows of Rgba32Uint texels, [`TEXELS_PER_ROW`] a row (`texel_at` in `word_texels.wgsl`).
pub(crate) fn texel_texture(device: &wgpu::Device, label: &str, rows: u32) -> wgpu::Texture {
    texture_2d(
        device,
        label,
        TEXELS_PER_ROW as u32,
        rows,
        wgpu::TextureFormat::Rgba32Uint,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    )
}

/// `words` as rows of Rgba32Uint texels, the last row padded with zeros.
pub(crate) fn word_texels(device: &wgpu::Device, queue: &wgpu::Queue, label: &str, words: &[u8]) -> wgpu::TextureView {
    let rows = (words.len() as u64).div_ceil(TEXEL_ROW_BYTES).max(1);
    let mut padded = words.to_vec();
    padded.resize((rows * TEXEL_ROW_BYTES) as usize, 0);
    let texture = texel_texture(device, label, rows as u32);
    upload(queue, &texture, &padded, 16);
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

/// A stride with which `n` workgroups visit `n` pieces of work (workgroup x takes piece x * stride mod n):
/// coprime with `n`, so every piece is taken once, and near `n` / golden ratio, so that neighbouring workgroups
/// take pieces from all over. lavapipe hands each of its threads a contiguous run of a dispatch's workgroups;
/// in the pieces' own order one thread can get all the heavy ones (the ray grids' `splat_box`, the ghosts'
/// `spans_sprites`). `x * stride` stays within a u32: past 65 536 pieces the stride is 1 (their own order).
pub(crate) fn spread_stride(n: u32) -> u32 {
    if n > 1 << 16 {
        return 1;
    }
    let gcd = |mut a: u32, mut b: u32| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let start = (f64::from(n) * 0.618_033_988_75).round() as u32;
    (start.max(1)..n.max(2)).find(|&s| gcd(s, n) == 1).unwrap_or(1)
}

/// A vertex buffer of `capacity` items of `T`, written through the queue.
pub(crate) fn vertex_buffer<T>(device: &wgpu::Device, label: &str, capacity: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (capacity * std::mem::size_of::<T>()) as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A bind group layout entry: a filtering sampler at `binding`, read by the fragment stage.
pub(crate) fn sampler_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        count: None,
    }
}

/// A bind group layout entry: the uniform buffer at `binding`, read by the vertex and fragment stages.
pub(crate) fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A bind group layout entry: a float texture of `dimension` at `binding`, read by the fragment stage
/// (`filterable`: through a filtering sampler).
pub(crate) fn texture_entry(
    binding: u32,
    filterable: bool,
    dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: dimension,
            multisampled: false,
        },
        count: None,
    }
}

/// The pipeline layout of one bind group, `bind_group`.
pub(crate) fn pipeline_layout(device: &wgpu::Device, bind_group: &wgpu::BindGroupLayout) -> wgpu::PipelineLayout {
    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(bind_group)],
        immediate_size: 0,
    })
}

/// The shader module of the WGSL `source` (named `label` in the device's messages).
pub(crate) fn shader_module(device: &wgpu::Device, label: &str, source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}

/// An Rgba16Float texture of `size` texels holding `rgba` (rows first) for the passes to sample.
pub(crate) fn sampled_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    size: (u32, u32),
    rgba: &[[f32; 4]],
) -> wgpu::Texture {
    let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
    let texture = texture_2d(device, label, size.0, size.1, HDR_FORMAT, usage);
    upload(queue, &texture, &half_floats(rgba), 8);
    texture
}

/// `rgba` as the bytes of 16-bit float texels (a value that is not finite is 0).
pub(crate) fn half_floats(rgba: &[[f32; 4]]) -> Vec<u8> {
    let halves: Vec<half::f16> = rgba.iter().flat_map(|t| t.map(crate::image::finite_half)).collect();
    bytemuck::cast_slice(&halves).to_vec()
}

/// A bind group of the renderer's passes: the frame's uniforms `globals` at binding 0, `view` at 1, then
/// `rest` at 2, 3, ... in order.
pub(crate) fn frame_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    globals: &wgpu::Buffer,
    view: &wgpu::TextureView,
    rest: Vec<wgpu::BindingResource>,
) -> wgpu::BindGroup {
    let mut entries = vec![
        wgpu::BindGroupEntry { binding: 0, resource: globals.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(view) },
    ];
    entries.extend(rest.into_iter().zip(2..).map(|(resource, binding)| wgpu::BindGroupEntry { binding, resource }));
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

#[cfg(test)]
mod tests {
    use super::spread_stride;

    /// Workgroup x taking piece x * stride mod n visits every piece once, with no u32 product passing 2^32,
    /// and from 30 pieces on neighbouring workgroups take pieces at least 30% of them apart.
    #[test]
    fn the_spread_visits_every_piece_once() {
        for n in (0..=300).chain([686, 1031, 4096, 65_535, 65_536, 65_537, 1 << 20]) {
            let stride = spread_stride(n);
            assert!(stride >= 1 && (n <= 1 || stride < n), "n {n}: stride {stride}");
            let n64 = u64::from(n);
            assert!(n64.saturating_sub(1) * u64::from(stride) <= u64::from(u32::MAX), "n {n}: stride {stride}");
            if n > 1 << 16 {
                assert_eq!(stride, 1, "n {n}");
                continue;
            }
            let mut seen = vec![false; n as usize];
            for x in 0..n {
                let piece = (x * stride % n) as usize;
                assert!(!seen[piece], "n {n}: piece {piece} twice");
                seen[piece] = true;
            }
            if n >= 30 {
                let gap = (stride.min(n - stride)) as f64 / f64::from(n);
                assert!(gap > 0.3, "n {n}: stride {stride} keeps neighbours {gap} of the pieces apart");
            }
        }
    }
}
