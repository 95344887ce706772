//! The paraxial ghosts rasterised on the GPU (`ghosts.wgsl`), for devices without what the compute pass needs
//! and for the app's drafts on a software adapter.
//!
//! # How it works
//! One quad per [`GhostInstance`], its eleven `vec4`s read as instance attributes, each covered pixel shaded
//! with the aperture mask at every stop crossing (the mask's three levels, `GhostMasks`, at bindings 1, 3 and 4
//! beside the frame's uniforms at 0 and the sampler at 2) and the clear-aperture discs, added into a cleared
//! accumulation. The instances' buffer grows to the next power of two when a frame has more. The CPU twin is
//! `render::cpu::ghosts::ghost_pass`.

use super::GhostInstance;
use super::buffers::{
    ADDITIVE, HDR_FORMAT, frame_group, pipeline_layout, render_pipeline, sampler_entry, shader_module, texture_entry,
    uniform_entry, vertex_buffer,
};
use super::cpu::ghosts::MASK_LEVELS;
use super::shaders::GHOSTS_WGSL;

/// The raster ghost pass: its pipeline, its layout, its instances and the aperture mask's levels.
pub(super) struct RasterGhosts {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    instances: wgpu::Buffer,
    capacity: usize,
    /// The mask's levels (base, finer, finest), replaced with the aperture.
    pub aperture: [wgpu::Texture; MASK_LEVELS],
}

impl RasterGhosts {
    /// The pass, with `aperture` for the mask's levels until they are replaced.
    pub fn new(device: &wgpu::Device, aperture: [wgpu::Texture; MASK_LEVELS]) -> Self {
        let texture = |binding| texture_entry(binding, true, wgpu::TextureViewDimension::D2);
        // The mask's levels: the base at 1, the finer ones at 3 and 4.
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ghosts"),
            entries: &[uniform_entry(0), texture(1), sampler_entry(2), texture(3), texture(4)],
        });
        let module = shader_module(device, "ghosts.wgsl", GHOSTS_WGSL);
        let instance_attributes = wgpu::vertex_attr_array![0 => Float32x4, 1 => Float32x4, 2 => Float32x4, 3 => Float32x4, 4 => Float32x4, 5 => Float32x4, 6 => Float32x4, 7 => Float32x4, 8 => Float32x4, 9 => Float32x4, 10 => Float32x4];
        let instances = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<GhostInstance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &instance_attributes,
        };
        let pipeline_layout = pipeline_layout(device, &layout);
        let pipeline = render_pipeline(
            device,
            "ghosts",
            &pipeline_layout,
            &module,
            &[Some(instances)],
            HDR_FORMAT,
            Some(ADDITIVE),
        );
        let capacity = 256;
        let instances = vertex_buffer::<GhostInstance>(device, "ghost instances", capacity);
        Self { pipeline, layout, instances, capacity, aperture }
    }

    /// Writes a frame's instances, growing their buffer to the next power of two where they do not fit.
    pub fn upload(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, instances: &[GhostInstance]) {
        if instances.len() > self.capacity {
            self.capacity = instances.len().next_power_of_two();
            self.instances = vertex_buffer::<GhostInstance>(device, "ghost instances", self.capacity);
        }
        if !instances.is_empty() {
            queue.write_buffer(&self.instances, 0, bytemuck::cast_slice(instances));
        }
    }

    /// The pass's bind group: the frame's uniforms `globals`, the mask's levels and `sampler`.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        globals: &wgpu::Buffer,
        sampler: &wgpu::Sampler,
    ) -> wgpu::BindGroup {
        let [base, finer, finest] =
            self.aperture.each_ref().map(|t| t.create_view(&wgpu::TextureViewDescriptor::default()));
        let rest = vec![
            wgpu::BindingResource::Sampler(sampler),
            wgpu::BindingResource::TextureView(&finer),
            wgpu::BindingResource::TextureView(&finest),
        ];
        frame_group(device, "ghosts", &self.layout, globals, &base, rest)
    }

    /// Clears the accumulation `hdr` within `frame` and adds the first `count` uploaded instances into it.
    pub fn draw(
        &self,
        frame: &mut wgpu_profiler::Scope<'_, wgpu::CommandEncoder>,
        hdr: &wgpu::TextureView,
        group: &wgpu::BindGroup,
        count: usize,
    ) {
        let attachments = [Some(wgpu::RenderPassColorAttachment {
            view: hdr,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
        })];
        let descriptor = wgpu::RenderPassDescriptor {
            label: Some("flare hdr"),
            color_attachments: &attachments,
            ..Default::default()
        };
        let mut pass = frame.scoped_render_pass("ghosts", descriptor);
        if count > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.set_vertex_buffer(0, self.instances.slice(..));
            pass.draw(0..6, 0..count as u32);
        }
    }
}
