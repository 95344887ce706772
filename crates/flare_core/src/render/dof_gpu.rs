//! The live depth of field on the GPU: `shaders/dof.wgsl`, whose CPU twin is
//! [`crate::dof::live::LivePlan::render_cpu`] (the CPU plans; both run the same steps in f32).
//!
//! # How it works
//! The plate, the per-pixel defocus, the taps and the normalisation tables go up once as storage buffers; each
//! layer's parameters ([`LiveLayer`]) sit in one uniform buffer at 256-byte strides. One compute pass then runs,
//! per layer far to near, `split` (over the layer's texels), `gather` (same) and `composite` (over the frame's
//! pixels), and `resolve` at the end; wgpu orders the dispatches' storage accesses. The pass is one timestamp
//! scope ("dof") where the adapter has timestamp queries. A frame whose buffers exceed the adapter's storage
//! binding is refused with the limit named ([`GpuError::Limit`]) before anything is dispatched; a device lost
//! on the way is [`GpuError::Lost`].

use wgpu_profiler::{GpuProfiler, GpuProfilerSettings};

use super::buffers::{compute_pipeline, storage};
use super::gpu::{GpuContext, GpuError, PassTimes, map_read};
use super::shaders::DOF_WGSL;
use crate::dof::live::{LiveLayer, LivePlan};
use crate::image::HdrImage;

/// The uniform stride of one layer's parameters (the largest offset alignment wgpu allows an adapter).
const LAYER_STRIDE: u64 = 256;
const WORKGROUP: u32 = 8;

/// The four pipelines of the live depth of field.
pub struct GpuDof {
    split: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    composite: wgpu::ComputePipeline,
    resolve: wgpu::ComputePipeline,
    profiler: GpuProfiler,
}

/// A depth of field drawn on the GPU, and how long its pass took there.
pub struct GpuDofImage {
    pub image: HdrImage,
    /// GPU time of the pass (ms), where the adapter has timestamp queries.
    pub gpu_ms: Option<f64>,
}

impl GpuDof {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("dof.wgsl"),
            source: wgpu::ShaderSource::Wgsl(DOF_WGSL.into()),
        });
        let pipeline = |entry: &str| compute_pipeline(device, &module, entry);
        Self {
            split: pipeline("split"),
            gather: pipeline("gather"),
            composite: pipeline("composite"),
            resolve: pipeline("resolve"),
            profiler: GpuProfiler::new(device, GpuProfilerSettings::default())
                .expect("the default profiler settings are valid"),
        }
    }

    /// Draws `plan` over `plate` on `ctx`'s device (see the module documentation).
    pub fn render(&mut self, ctx: &GpuContext, plan: &LivePlan, plate: &HdrImage) -> Result<GpuDofImage, GpuError> {
        let out = self.render_on(&ctx.device, &ctx.queue, plan, plate)?;
        if let Some(reason) = ctx.failure() {
            return Err(GpuError::Lost(reason));
        }
        Ok(out)
    }

    /// [`Self::render`] on any device and queue (the app's).
    pub fn render_on(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        plan: &LivePlan,
        plate: &HdrImage,
    ) -> Result<GpuDofImage, GpuError> {
        let (w, h) = (plan.width, plan.height);
        let frame_bytes = frame_bytes(device, plan, plate)?;
        let buffer = |label: &str, contents: &[u8], usage| storage(device, queue, label, contents, usage);
        let empty = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let storage = wgpu::BufferUsages::STORAGE;
        // Only finite values go up: the plate's non-finite samples are black, the plan's are finite by make.
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        let plate_values: Vec<[f32; 4]> = plate.pixels.iter().map(|p| p.map(finite)).collect();
        let plate_buffer = buffer("dof plate", bytemuck::cast_slice(&plate_values), storage);
        let sigma: Vec<f32> = plan.sigma.iter().map(|&s| finite(s)).collect();
        let sigma_buffer = buffer("dof defocus", bytemuck::cast_slice(&sigma), storage);
        let taps_buffer = buffer("dof taps", bytemuck::cast_slice(&plan.taps), storage);
        let norm_buffer = buffer("dof norm", bytemuck::cast_slice(&plan.norm), storage);
        let low = empty("dof low", frame_bytes, storage);
        let gathered = empty("dof gathered", frame_bytes, storage);
        let out = empty("dof out", frame_bytes, storage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST);
        let uniform_buffer = buffer("dof layers", &layer_uniforms(plan), wgpu::BufferUsages::UNIFORM);
        let layer_binding = |k: usize| {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &uniform_buffer,
                offset: k as u64 * LAYER_STRIDE,
                size: wgpu::BufferSize::new(std::mem::size_of::<LiveLayer>() as u64),
            })
        };
        let group = |pipeline: &wgpu::ComputePipeline, k: usize, entries: &[(u32, &wgpu::Buffer)]| {
            let mut list = vec![wgpu::BindGroupEntry { binding: 0, resource: layer_binding(k) }];
            list.extend(
                entries.iter().map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }),
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("dof"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &list,
            })
        };
        let groups: Vec<[wgpu::BindGroup; 3]> = (0..plan.layers.len())
            .map(|k| {
                [
                    group(&self.split, k, &[(1, &plate_buffer), (2, &sigma_buffer), (3, &low)]),
                    group(&self.gather, k, &[(3, &low), (4, &gathered), (6, &taps_buffer), (7, &norm_buffer)]),
                    group(&self.composite, k, &[(4, &gathered), (5, &out)]),
                ]
            })
            .collect();
        let resolve_group = group(&self.resolve, plan.layers.len(), &[(5, &out)]);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("dof") });
        encoder.clear_buffer(&out, 0, None);
        {
            let mut scope = self.profiler.scope("dof", &mut encoder);
            let mut pass = scope.scoped_compute_pass("dof");
            let groups_of = |n: u32| n.div_ceil(WORKGROUP);
            // Each step over its region only (see `crate::dof::live`).
            let extent = |b: [u32; 4]| (groups_of(b[2].saturating_sub(b[0])), groups_of(b[3].saturating_sub(b[1])));
            for (layer, [split, gather, composite]) in plan.layers.iter().zip(&groups) {
                for (pipeline, group, region) in [
                    (&self.split, split, layer.low),
                    (&self.gather, gather, layer.out),
                    (&self.composite, composite, layer.pixels),
                ] {
                    let (x, y) = extent(region);
                    if x > 0 && y > 0 {
                        pass.set_pipeline(pipeline);
                        pass.set_bind_group(0, group, &[]);
                        pass.dispatch_workgroups(x, y, 1);
                    }
                }
            }
            pass.set_pipeline(&self.resolve);
            pass.set_bind_group(0, &resolve_group, &[]);
            pass.dispatch_workgroups(groups_of(w), groups_of(h), 1);
        }
        self.profiler.resolve_queries(&mut encoder);
        let (pixels, gpu_ms) = self.read_back(device, queue, encoder, &out, frame_bytes)?;
        Ok(GpuDofImage { image: HdrImage { width: w, height: h, pixels }, gpu_ms })
    }

    /// Submits `encoder` with a copy of `out` (`frame_bytes` of RGBA f32) to a buffer it then reads: the
    /// pixels, and the pass's GPU time where the device has timestamps.
    fn read_back(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mut encoder: wgpu::CommandEncoder,
        out: &wgpu::Buffer,
        frame_bytes: u64,
    ) -> Result<(Vec<[f32; 4]>, Option<f64>), GpuError> {
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dof readback"),
            size: frame_bytes.max(16),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(out, 0, &readback, 0, frame_bytes);
        queue.submit(Some(encoder.finish()));
        let _ = self.profiler.end_frame();
        let view = map_read(device, &readback, frame_bytes)?;
        let pixels: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&view);
        let mut gpu_ms = None;
        while let Some(results) = self.profiler.process_finished_frame(queue.get_timestamp_period()) {
            if let Some(ms) = PassTimes::from_results(&results).get("dof") {
                gpu_ms = Some(ms);
            }
        }
        Ok((pixels, gpu_ms))
    }
}

/// The bytes of one of `plan`'s frames (RGBA f32), which every buffer of the pass holds; refused where they
/// pass the adapter's largest storage binding, or where `plate` is not the plan's size.
fn frame_bytes(device: &wgpu::Device, plan: &LivePlan, plate: &HdrImage) -> Result<u64, GpuError> {
    let (w, h) = (plan.width, plan.height);
    let frame_bytes = u64::from(w) * u64::from(h) * 16;
    let limits = device.limits();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    if frame_bytes > binding {
        return Err(GpuError::Limit {
            what: format!("a {w}x{h} depth of field needs {frame_bytes} bytes a buffer"),
            limit: binding,
            name: "max_storage_buffer_binding_size",
        });
    }
    if plate.width != w || plate.height != h {
        return Err(GpuError::Readback(format!("plate {}x{} for a {w}x{h} plan", plate.width, plate.height)));
    }
    Ok(frame_bytes)
}

/// Every layer's parameters at [`LAYER_STRIDE`]-byte strides, and one more (the frame's size) for `resolve`.
fn layer_uniforms(plan: &LivePlan) -> Vec<u8> {
    let (w, h) = (plan.width, plan.height);
    let mut uniforms = vec![0u8; LAYER_STRIDE as usize * (plan.layers.len() + 1)];
    let frame = LiveLayer { size: [w, h, w, h], taps: [0, 0, 1, 0], ..LiveLayer::default() };
    for (k, layer) in plan.layers.iter().chain(std::iter::once(&frame)).enumerate() {
        let at = k * LAYER_STRIDE as usize;
        uniforms[at..at + std::mem::size_of::<LiveLayer>()].copy_from_slice(bytemuck::bytes_of(layer));
    }
    uniforms
}
