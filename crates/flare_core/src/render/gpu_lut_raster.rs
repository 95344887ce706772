//! The LUT ghosts rasterised (`shaders/lut_ghosts.wgsl`): one instanced quad per LUT instance drawn into the HDR
//! accumulation after the ghosts, where the device has no compute or a frame's bins would pass its largest
//! storage binding (the compute pass, `gpu_lut`, is the default).
//!
//! # How it works
//! Added, every instance is one quad of one draw call (blend One, One). Composited through alpha, each run of
//! consecutive instances of one LUT ghost (its interpolated entries, and under motion blur its time samples:
//! [`crate::lut::blend::LutScene::group_by_ghost`]) is laid over what lies beneath once, with its summed
//! coverage, as the CPU twin's `composite_runs` does: a run of one instance is drawn straight over the
//! accumulation (blend One, OneMinusSrcAlpha), consecutive such runs in one draw call; a longer run is first
//! drawn into a scratch image of the accumulation's size, cleared to colour 0 and alpha 1: colour added, and each
//! instance's coverage subtracted from the alpha (blend ReverseSubtract), which leaves `1 - a`, what the run lets
//! through; then `lut_runs.wgsl` lays that image over the accumulation (`p = S + clamp(1 - a, 0, 1) p`). A longer
//! run thus costs two passes and the scratch image (made once per accumulation size).
//!
//! Precision: where a run covers the flare almost wholly, what it lets through is small beside the flare it hides,
//! so it must be precise near 0. The scratch image is Rgba32Float where the device blends into it
//! (`FLOAT32_BLENDABLE`, [`super::gpu::wanted_features`]), else Rgba16Float. In half floats, summing the coverage
//! and taking it from 1 afterwards lost that: on the Tessar's small LUT the raster pass drew 2.9 % more light than
//! the CPU twin (display values up to 6/255 apart) and 56 % more under motion blur; subtracting from 1 as it goes
//! (each step rounded at the size of what is left) keeps it within 0.5 % (0.4/255).

use super::buffers::{
    HDR_FORMAT, pipeline_layout, render_pipeline, sampler_entry, shader_module, texture_2d, texture_entry,
    uniform_entry, vertex_buffer,
};
use super::shaders::{LUT_GHOSTS_WGSL, LUT_RUNS_WGSL};
use crate::lut::blend::{LutInstance, LutScene};

/// What a pass of the LUT layer draws: a range of instances, straight onto the accumulation (added or over) or
/// a run summed in the scratch image and then laid over.
#[derive(Clone, Debug, PartialEq)]
enum Draw {
    Straight(std::ops::Range<u32>),
    Run(std::ops::Range<u32>),
}

/// The passes of `lut`'s instances: one straight draw when added; composited through alpha, the runs of one LUT
/// ghost's instances, the runs of one instance next to each other drawn together.
fn draws(lut: &LutScene) -> Vec<Draw> {
    let n = lut.instances.len() as u32;
    if !lut.alpha_over {
        return vec![Draw::Straight(0..n)];
    }
    let mut out: Vec<Draw> = Vec::new();
    let mut start = 0u32;
    for run in lut.sources.chunk_by(|a, b| a.0 == b.0) {
        let range = start..start + run.len() as u32;
        start = range.end;
        match (out.last_mut(), run.len()) {
            (Some(Draw::Straight(r)), 1) if r.end == range.start => r.end = range.end,
            (_, 1) => out.push(Draw::Straight(range)),
            _ => out.push(Draw::Run(range)),
        }
    }
    out
}

/// The raster LUT pass: its pipelines, instance buffer and scratch image.
pub(crate) struct RasterLut {
    /// Globals, the atlas and its sampler (the bind group is the renderer's, made with its other groups).
    pub(crate) layout: wgpu::BindGroupLayout,
    add: wgpu::RenderPipeline,
    over: wgpu::RenderPipeline,
    /// Into the scratch image (of `scratch_format`): colour added, coverage subtracted from its alpha.
    sum: wgpu::RenderPipeline,
    scratch_format: wgpu::TextureFormat,
    runs_layout: wgpu::BindGroupLayout,
    lay_over: wgpu::RenderPipeline,
    instances: wgpu::Buffer,
    capacity: usize,
    /// The scratch image a run is summed in, its view and bind group, at the accumulation's size.
    scratch: Option<(wgpu::TextureView, wgpu::BindGroup, u32, u32)>,
}

impl RasterLut {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lut ghosts"),
            entries: &[uniform_entry(0), texture_entry(1, true, wgpu::TextureViewDimension::D2Array), sampler_entry(2)],
        });
        let runs_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lut runs"),
            entries: &[texture_entry(0, false, wgpu::TextureViewDimension::D2)],
        });
        let blend = |dst_factor| {
            let component = wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::One,
                dst_factor,
                operation: wgpu::BlendOperation::Add,
            };
            wgpu::BlendState { color: component, alpha: component }
        };
        let (added, over) = (blend(wgpu::BlendFactor::One), blend(wgpu::BlendFactor::OneMinusSrcAlpha));
        // Into the scratch image: colour added, coverage taken from the alpha (what the run lets through).
        let through = wgpu::BlendState {
            alpha: wgpu::BlendComponent { operation: wgpu::BlendOperation::ReverseSubtract, ..added.alpha },
            ..added
        };
        // Each attribute where `LutInstance` has its field (`layouts` checks the order against the shader's).
        let attribute =
            |shader_location, format, offset| wgpu::VertexAttribute { format, offset: offset as u64, shader_location };
        let attributes = [
            attribute(0, wgpu::VertexFormat::Float32x4, std::mem::offset_of!(LutInstance, centre_axis_x)),
            attribute(1, wgpu::VertexFormat::Float32x2, std::mem::offset_of!(LutInstance, axis_y)),
            attribute(4, wgpu::VertexFormat::Uint32, std::mem::offset_of!(LutInstance, page)),
            attribute(5, wgpu::VertexFormat::Uint32, std::mem::offset_of!(LutInstance, _pad0)),
            attribute(2, wgpu::VertexFormat::Float32x4, std::mem::offset_of!(LutInstance, rect)),
            attribute(3, wgpu::VertexFormat::Float32x4, std::mem::offset_of!(LutInstance, colour)),
        ];
        let buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<LutInstance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &attributes,
        })];
        let (quads, runs) = (pipeline_layout(device, &layout), pipeline_layout(device, &runs_layout));
        let lut_module = shader_module(device, "lut_ghosts.wgsl", LUT_GHOSTS_WGSL);
        let runs_module = shader_module(device, "lut_runs.wgsl", LUT_RUNS_WGSL);
        let capacity = 64;
        let scratch_format = if device.features().contains(wgpu::Features::FLOAT32_BLENDABLE) {
            wgpu::TextureFormat::Rgba32Float
        } else {
            HDR_FORMAT
        };
        Self {
            sum: render_pipeline(device, "lut run sum", &quads, &lut_module, &buffers, scratch_format, Some(through)),
            scratch_format,
            add: render_pipeline(device, "lut ghosts", &quads, &lut_module, &buffers, HDR_FORMAT, Some(added)),
            over: render_pipeline(device, "lut ghosts over", &quads, &lut_module, &buffers, HDR_FORMAT, Some(over)),
            lay_over: render_pipeline(device, "lut runs over", &runs, &runs_module, &[], HDR_FORMAT, Some(over)),
            layout,
            runs_layout,
            instances: vertex_buffer::<LutInstance>(device, "lut instances", capacity),
            capacity,
            scratch: None,
        }
    }

    /// Uploads `lut`'s instances and, where a run needs it, makes the scratch image for an accumulation of
    /// `acc_size` pixels.
    pub(crate) fn upload(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, lut: &LutScene, acc_size: (u32, u32)) {
        if lut.instances.len() > self.capacity {
            self.capacity = lut.instances.len().next_power_of_two();
            self.instances = vertex_buffer::<LutInstance>(device, "lut instances", self.capacity);
        }
        queue.write_buffer(&self.instances, 0, bytemuck::cast_slice(&lut.instances));
        let runs = draws(lut).iter().any(|d| matches!(d, Draw::Run(_)));
        let (w, h) = acc_size;
        if runs && !matches!(&self.scratch, Some((_, _, sw, sh)) if (*sw, *sh) == (w, h)) {
            let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
            let view = texture_2d(device, "lut run sum", w, h, self.scratch_format, usage)
                .create_view(&wgpu::TextureViewDescriptor::default());
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lut runs"),
                layout: &self.runs_layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) }],
            });
            self.scratch = Some((view, group, w, h));
        }
    }

    /// Draws `lut` (uploaded by [`Self::upload`]) onto the accumulation `hdr`, its quads bound by `quads` (the
    /// layout [`Self::layout`]), each pass a scope of `frame`.
    pub(crate) fn draw(
        &self,
        frame: &mut wgpu_profiler::Scope<'_, wgpu::CommandEncoder>,
        hdr: &wgpu::TextureView,
        quads: &wgpu::BindGroup,
        lut: &LutScene,
    ) {
        let attachment = |view, load| {
            [Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
            })]
        };
        let onto_hdr = attachment(hdr, wgpu::LoadOp::Load);
        let scratch = self.scratch.as_ref().map(|(view, group, _, _)| {
            // Nothing summed, everything let through.
            (attachment(view, wgpu::LoadOp::Clear(wgpu::Color { r: 0.0, g: 0.0, b: 0.0, a: 1.0 })), group)
        });
        let target = |attachments| wgpu::RenderPassDescriptor {
            label: Some("lut ghosts"),
            color_attachments: attachments,
            ..Default::default()
        };
        for draw in draws(lut) {
            match (draw, &scratch) {
                (Draw::Run(range), Some((onto_scratch, runs))) => {
                    {
                        let mut pass = frame.scoped_render_pass("lut run", target(onto_scratch));
                        pass.set_pipeline(&self.sum);
                        pass.set_bind_group(0, quads, &[]);
                        pass.set_vertex_buffer(0, self.instances.slice(..));
                        pass.draw(0..6, range);
                    }
                    let mut pass = frame.scoped_render_pass("lut run over", target(&onto_hdr));
                    pass.set_pipeline(&self.lay_over);
                    pass.set_bind_group(0, *runs, &[]);
                    pass.draw(0..3, 0..1);
                }
                // (A run without the scratch image cannot happen: `upload` makes it for a frame with runs.)
                (Draw::Straight(range) | Draw::Run(range), _) => {
                    let mut pass = frame.scoped_render_pass("lut", target(&onto_hdr));
                    pass.set_pipeline(if lut.alpha_over { &self.over } else { &self.add });
                    pass.set_bind_group(0, quads, &[]);
                    pass.set_vertex_buffer(0, self.instances.slice(..));
                    pass.draw(0..6, range);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_of_one_instance_share_a_draw_and_longer_runs_are_summed_first() {
        let scene = |sources: &[u32], alpha_over| LutScene {
            instances: vec![LutInstance::zeroed(); sources.len()],
            sources: sources.iter().map(|&g| (g, 0, 0)).collect(),
            alpha_over,
            ..LutScene::default()
        };
        use bytemuck::Zeroable;
        assert_eq!(draws(&scene(&[0, 0, 1, 2, 3, 3, 3, 4], false)), vec![Draw::Straight(0..8)]);
        assert_eq!(
            draws(&scene(&[0, 0, 1, 2, 3, 3, 3, 4], true)),
            vec![Draw::Run(0..2), Draw::Straight(2..4), Draw::Run(4..7), Draw::Straight(7..8)]
        );
        assert_eq!(draws(&scene(&[], true)), vec![]);
    }
}
