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
//! reach its tile. With the ghosts rasterised (a device without compute) the raster LUT pass (`lut_ghosts.wgsl`)
//! stays.

use bytemuck::{Pod, Zeroable};

use super::buffers::{HDR_FORMAT, compute_pipeline, storage, texture_2d};
use super::shaders::LUT_COMPUTE_WGSL;
use crate::lut::blend::{LutBins, LutInstance, LutScene};

/// Accumulation pixels a side of a tile.
pub(crate) const TILE: u32 = 32;
/// Invocations a side of a workgroup (a tile is four workgroups a side).
const WORKGROUP: u32 = 8;

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
    unused: u32,
}
const _: () = assert!(std::mem::size_of::<LutTiles>() == 32);

/// The pass's pipeline and the LUT layer it writes.
pub(crate) struct ComputeLut {
    pipeline: wgpu::ComputePipeline,
    /// The layer `(A, K)` and its size.
    layer: Option<(wgpu::Texture, u32, u32)>,
}

impl ComputeLut {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("lut_compute.wgsl"),
            source: wgpu::ShaderSource::Wgsl(LUT_COMPUTE_WGSL.into()),
        });
        Self { pipeline: compute_pipeline(device, &module, "lut_tiles"), layer: None }
    }

    /// Records the pass into `pass` for the accumulation of `acc_size` pixels of a `frame_size` frame, and
    /// returns the layer's view for the ghost pass to apply.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pass: &mut wgpu::ComputePass,
        frame_size: (u32, u32),
        acc_size: (u32, u32),
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
        let params = LutTiles {
            width: w,
            height: h,
            tile: bins.tile,
            tiles_x: bins.tiles_x,
            scale_x: frame_size.0 as f32 / w as f32,
            scale_y: frame_size.1 as f32 / h as f32,
            alpha_over: u32::from(lut.alpha_over),
            unused: 0,
        };
        let uniform = storage(device, queue, "lut tiles", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        // Each instance's sampling level ([`crate::lut::blend::instance_levels`]) in its unused last word.
        let with_levels: Vec<LutInstance> = lut
            .instances
            .iter()
            .zip(bins.levels.iter().chain(std::iter::repeat(&0)))
            .map(|(inst, &level)| {
                let mut inst = *inst;
                inst.axis_y_page[3] = f32::from(level);
                inst
            })
            .collect();
        let instances =
            storage(device, queue, "lut sprites", bytemuck::cast_slice(&with_levels), wgpu::BufferUsages::STORAGE);
        let words: Vec<u32> = bins.starts.iter().chain(&bins.list).copied().collect();
        let bin_buffer = storage(device, queue, "lut bins", bytemuck::cast_slice(&words), wgpu::BufferUsages::STORAGE);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lut tiles"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: instances.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: bin_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(atlas) },
                wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::Sampler(sampler) },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&view) },
            ],
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(w.div_ceil(WORKGROUP), h.div_ceil(WORKGROUP), 1);
        view
    }
}
