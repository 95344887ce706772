//! The LUT ghosts as a compute pass (`shaders/lut_compute.wgsl`): per pixel, the LUT instances binned to its
//! tile, instead of one rasterised quad per instance.
//!
//! # How it works
//! The CPU bins the frame's instances into square tiles of [`TILE`] accumulation pixels
//! ([`crate::lut::blend::bin_instances`]: each instance goes to the tiles its lit texels can reach). One
//! invocation per pixel walks its tile's list in the frame's order and samples the atlas as the raster pass did;
//! it writes the LUT layer as `(A, K)`, what the layer does to whatever lies beneath it (`A + K x under`), into
//! a texture of the accumulation's size. The ghost pass's `resolve` (`render::gpu_ghosts`) applies it while
//! it writes each pixel, so the accumulation is written once and every pixel pays only for the instances that
//! reach its tile. Instances sampled coarsely ([`crate::lut::blend::instance_levels`]) are drawn first by
//! `lut_coarse` into images of that level's size, one sample a coarse pixel, and `lut_tiles` adds their
//! bilinear upsample, as the CPU twin does; where those images would pass the adapter's largest storage binding,
//! each pixel samples each such instance at the four coarse pixel centres around it instead (the same values
//! up to the order of the sums). With the ghosts rasterised (a device without compute) the raster LUT pass
//! (`lut_ghosts.wgsl`) stays.

use bytemuck::{Pod, Zeroable};

use super::buffers::{HDR_FORMAT, compute_pipeline, grow_storage, software_device, storage, texture_2d};
use super::shaders::LUT_COMPUTE_WGSL;
use crate::lut::blend::{LutBins, LutInstance, LutScene};

/// Accumulation pixels a side of a tile.
pub(crate) const TILE: u32 = 32;
/// Invocations a side of a workgroup (a tile is four workgroups a side).
const WORKGROUP: u32 = 8;

/// One LUT instance as the pass reads it. Must be kept in sync with `struct TiledInstance` in
/// `shaders/lut_compute.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct TiledInstance {
    instance: LutInstance,
    /// Sampled every 2^level pixels ([`crate::lut::blend::instance_levels`]).
    level: u32,
    /// The LUT ghost it draws: composited through alpha, a run of one ghost's instances is laid over at once.
    ghost: u32,
    unused: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<TiledInstance>() == 80);

/// The pass's parameters. Must be kept in sync with `struct LutTiles` in `shaders/lut_compute.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
struct LutTiles {
    width: u32,
    height: u32,
    tile: u32,
    tiles_x: u32,
    scale_x: f32,
    scale_y: f32,
    alpha_over: u32,
    /// Bit L (1, 2): coarse level L's instances drawn into the coarse images and upsampled from them.
    coarse_images: u32,
}
const _: () = assert!(std::mem::size_of::<LutTiles>() == 32);

/// Bytes of one coarse pixel (RGB as f32 and one unused float).
const COARSE_PIXEL_BYTES: u64 = 16;

/// Bytes of the coarse images of an accumulation `w` x `h` pixels: levels 1 and 2, as `lut_compute.wgsl` lays
/// them out.
fn coarse_bytes(w: u32, h: u32) -> u64 {
    let pixels = |step: u32| u64::from(w.div_ceil(step)) * u64::from(h.div_ceil(step));
    (pixels(2) + pixels(4)) * COARSE_PIXEL_BYTES
}

/// The pass's pipelines, the coarse levels' images and the LUT layer it writes.
pub(crate) struct ComputeLut {
    pipeline: wgpu::ComputePipeline,
    coarse_pipeline: wgpu::ComputePipeline,
    /// The coarse levels' images and their size in bytes (a 16-byte stand-in while no frame needs them).
    coarse: Option<(wgpu::Buffer, u64)>,
    /// Whether coarse instances are drawn into the coarse images (a hardware GPU) or sampled at every pixel (a
    /// software rasteriser: lavapipe drew the zoom's blended 1920x1080 frame in 9.6 s with the images against
    /// 7.9 s without, for reasons not found; at 4K the images took an H200's LUT pass from 1.38 to 0.20 ms).
    pub(crate) coarse_images: bool,
    /// The most bytes the coarse images may take (the adapter's limits; tests lower it).
    pub(crate) coarse_limit: u64,
    /// The layer `(A, K)` and its size.
    layer: Option<(wgpu::Texture, u32, u32)>,
}

impl ComputeLut {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("lut_compute.wgsl"),
            source: wgpu::ShaderSource::Wgsl(LUT_COMPUTE_WGSL.into()),
        });
        let limits = device.limits();
        Self {
            pipeline: compute_pipeline(device, &module, "lut_tiles"),
            coarse_pipeline: compute_pipeline(device, &module, "lut_coarse"),
            coarse: None,
            coarse_images: !software_device(device),
            coarse_limit: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            layer: None,
        }
    }

    /// Records the pass into `pass` for the accumulation of `acc_size` pixels of a `frame_size` frame, and
    /// returns the layer's view for the ghost pass to apply.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pass: &mut wgpu::ComputePass,
        (frame_size, acc_size): ((u32, u32), (u32, u32)),
        lut: &LutScene,
        bins: &LutBins,
        atlas: &wgpu::TextureView,
        sampler: &wgpu::Sampler,
    ) -> wgpu::TextureView {
        let (w, h) = (acc_size.0.max(1), acc_size.1.max(1));
        if !matches!(&self.layer, Some((_, lw, lh)) if *lw == w && *lh == h) {
            let usage = wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING;
            self.layer = Some((texture_2d(device, "lut layer", w, h, HDR_FORMAT, usage), w, h));
        }
        let Some((layer, _, _)) = &self.layer else { unreachable!("made above") };
        let view = layer.create_view(&wgpu::TextureViewDescriptor::default());
        // The coarse levels this frame samples at, drawn into images where they can be bound.
        let mut coarse_images = bins.levels.iter().filter(|&&l| l > 0).fold(0u32, |bits, &l| bits | 1 << l);
        let needed = coarse_bytes(w, h);
        if !self.coarse_images || needed > self.coarse_limit {
            coarse_images = 0;
        }
        let bytes = if coarse_images != 0 { needed } else { COARSE_PIXEL_BYTES };
        grow_storage(device, &mut self.coarse, "lut coarse images", bytes);
        let Some((coarse, _)) = &self.coarse else { unreachable!("made above") };
        let params = LutTiles {
            width: w,
            height: h,
            tile: bins.tile,
            tiles_x: bins.tiles_x,
            scale_x: frame_size.0 as f32 / w as f32,
            scale_y: frame_size.1 as f32 / h as f32,
            alpha_over: u32::from(lut.alpha_over),
            coarse_images,
        };
        let uniform = storage(device, queue, "lut tiles", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        // Each instance with its sampling level ([`crate::lut::blend::instance_levels`]) and LUT ghost.
        let tiled: Vec<TiledInstance> = lut
            .instances
            .iter()
            .zip(&lut.sources)
            .zip(bins.levels.iter().chain(std::iter::repeat(&0)))
            .map(|((&instance, source), &level)| TiledInstance {
                instance,
                level: u32::from(level),
                ghost: source.0,
                unused: [0; 2],
            })
            .collect();
        let instances =
            storage(device, queue, "lut sprites", bytemuck::cast_slice(&tiled), wgpu::BufferUsages::STORAGE);
        let splits = bins.splits.iter().flatten();
        let words: Vec<u32> = bins.starts.iter().chain(&bins.list).chain(splits).copied().collect();
        let bin_buffer = storage(device, queue, "lut bins", bytemuck::cast_slice(&words), wgpu::BufferUsages::STORAGE);
        let common = [
            wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: instances.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: bin_buffer.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(atlas) },
            wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::Sampler(sampler) },
            wgpu::BindGroupEntry { binding: 6, resource: coarse.as_entire_binding() },
        ];
        if coarse_images != 0 {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lut coarse"),
                layout: &self.coarse_pipeline.get_bind_group_layout(0),
                entries: &common,
            });
            pass.set_pipeline(&self.coarse_pipeline);
            pass.set_bind_group(0, &group, &[]);
            // Level 1's size in x and y, both levels along z (level 2's invocations past its size return).
            pass.dispatch_workgroups(w.div_ceil(2 * WORKGROUP), h.div_ceil(2 * WORKGROUP), 2);
        }
        let mut entries = common.to_vec();
        entries.push(wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&view) });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lut tiles"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(w.div_ceil(WORKGROUP), h.div_ceil(WORKGROUP), 1);
        view
    }
}

/// The pass's structs against `lut_compute.wgsl`'s (a [`TiledInstance`]'s [`LutInstance`] spelled out there).
#[cfg(test)]
pub(crate) fn assert_layouts() {
    use super::shaders::{LUT_COMPUTE_WGSL, layout::*};
    assert_same_layout(
        LUT_COMPUTE_WGSL,
        "LutTiles",
        fields!(LutTiles: width, height, tile, tiles_x, scale_x, scale_y, alpha_over, coarse_images),
    );
    let (size, tiled) = fields!(TiledInstance: instance, level, ghost, unused);
    let (_, instance) = fields!(LutInstance: centre_axis_x, axis_y, page, _pad0, rect, colour);
    assert_same_layout(LUT_COMPUTE_WGSL, "TiledInstance", (size, [instance, tiled[1..].to_vec()].concat()));
}
