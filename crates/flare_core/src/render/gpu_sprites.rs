//! The starburst and the front dirt's glow on the GPU: two passes of one shape, each its pipeline, its texture
//! and its bind group, added into the accumulation.
//!
//! # How it works
//! [`SpritePass`] is one such pass: `starburst.wgsl` draws a quad round the light's image (six vertices),
//! `dirt.wgsl` a full-screen triangle (three), each reading the frame's uniforms at binding 0, its texture at 1
//! and the renderer's linear sampler at 2 (the layout [`sprite_layout`] makes). A texture starts as one black
//! texel and is replaced when the look changes ([`SpritePass::set_texture`]); the renderer then makes the bind
//! groups again. Their CPU twins are `render::cpu::starburst` and `render::cpu::dirt`.

use super::buffers::{
    ADDITIVE, HDR_FORMAT, frame_group, pipeline_layout, render_pipeline, sampled_texture, sampler_entry, shader_module,
    texture_entry, uniform_entry,
};

/// The sprite passes' bind group layout: the frame's uniforms, the pass's texture, a filtering sampler.
pub(super) fn sprite_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("starburst and dirt"),
        entries: &[uniform_entry(0), texture_entry(1, true, wgpu::TextureViewDimension::D2), sampler_entry(2)],
    })
}

/// One sprite pass: its pipeline, its texture and the vertices it draws.
pub(super) struct SpritePass {
    label: &'static str,
    pipeline: wgpu::RenderPipeline,
    texture: wgpu::Texture,
    vertices: u32,
}

impl SpritePass {
    /// The pass of `source` (a shader of `vs_main` and `fs_main`) in `layout`, drawing `vertices` vertices,
    /// with one black texel for its texture.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        layout: &wgpu::BindGroupLayout,
        (label, source): (&'static str, &str),
        vertices: u32,
    ) -> Self {
        let module = shader_module(device, label, source);
        let layout = pipeline_layout(device, layout);
        let pipeline = render_pipeline(device, label, &layout, &module, &[], HDR_FORMAT, Some(ADDITIVE));
        let texture = sampled_texture(device, queue, label, (1, 1), &[[0.0; 4]]);
        Self { label, pipeline, texture, vertices }
    }

    /// Replaces the pass's texture with `texels` (linear RGBA, `size` texels, rows first), as 16-bit floats.
    pub fn set_texture(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, size: (u32, u32), texels: &[[f32; 4]]) {
        self.texture = sampled_texture(device, queue, self.label, size, texels);
    }

    /// The pass's bind group in `layout` ([`sprite_layout`]), the frame's uniforms `globals`.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        globals: &wgpu::Buffer,
        sampler: &wgpu::Sampler,
    ) -> wgpu::BindGroup {
        let view = self.texture.create_view(&wgpu::TextureViewDescriptor::default());
        frame_group(device, self.label, layout, globals, &view, vec![wgpu::BindingResource::Sampler(sampler)])
    }

    /// Adds the pass into the accumulation `hdr` within `frame`, timed under its label.
    pub fn draw(
        &self,
        frame: &mut wgpu_profiler::Scope<'_, wgpu::CommandEncoder>,
        hdr: &wgpu::TextureView,
        group: &wgpu::BindGroup,
    ) {
        let attachments = [Some(wgpu::RenderPassColorAttachment {
            view: hdr,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
        })];
        let descriptor = wgpu::RenderPassDescriptor {
            label: Some("flare hdr"),
            color_attachments: &attachments,
            ..Default::default()
        };
        let mut pass = frame.scoped_render_pass(self.label, descriptor);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.draw(0..self.vertices, 0..1);
    }
}
