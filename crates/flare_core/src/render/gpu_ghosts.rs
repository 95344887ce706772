//! The ghost sprites as a compute pass (`shaders/ghosts_compute.wgsl`): the CPU twin's algorithm
//! ([`super::cpu::ghost_pass`]) on the GPU, instead of rasterising frame-sized quads.
//!
//! # How it works
//! A wide-open lens's sprites are often larger than the frame; rasterised, each one shades every pixel it
//! covers (about 1.4 G fragments for a 28-surface zoom at 1920x1080), and a data-centre GPU rasterises on a few
//! units only. Here one invocation of `spans` handles one (sprite, accumulation row) item: it finds the row's
//! open span (every mask exactly 1, from the aperture's per-row table, [`super::cpu::ghosts`]'s `MaskRows`),
//! shades only the pixels outside it as the fragment shader does, and adds the row's values as differences
//! `F(x) - F(x - 1)` to a per-row buffer; `resolve` then sums each row once into the HDR texture. The cost
//! follows rows x sprites plus edge pixels, not covered area.
//!
//! **Deterministic**: the differences are 64-bit fixed-point integers (two u32 words added with carry by
//! atomics), so the order in which sprites land does not matter: the same frame gives the same bytes on every
//! run. The unit is chosen per frame as `2^-30` of the brightest sprite's brightest channel (and at most `2^-62`
//! of the sum over sprites of their brightest channel, which no pixel can exceed, so no sum can overflow):
//! each sprite is rounded far below what a half float keeps, and most steps from one pixel to the next fit the
//! low word, whose carry alone then decides whether the high word needs an atomic of its own.
//!
//! **Limits**: the difference buffer holds `(width + 1) x rows x 24` bytes. A frame whose buffer would pass the
//! adapter's `max_storage_buffer_binding_size` (or `max_buffer_size`) is drawn in strips of rows, one after
//! another into the same buffer (`resolve` leaves it zeroed); a strip's items beyond
//! `max_compute_workgroups_per_dimension` workgroups go in a second dimension. [`ComputeGhosts::supported`]
//! says whether a device can run the pass at all (compute shaders, four storage buffers, a storage texture);
//! where it cannot (a WebGL-class adapter), `FlareRenderer` keeps the raster pass
//! (`ghosts.wgsl`).

use bytemuck::{Pod, Zeroable};

use super::buffers::{HDR_FORMAT, compute_pipeline, software_device, storage, texture_2d};
use super::cpu::ghosts::{MaskRows, without_open_stops};
use super::cpu::quads::{accumulation_scale, covered};
use super::shaders::GHOSTS_COMPUTE_WGSL;
use super::{FlareScene, GhostInstance};
use crate::aperture::ApertureMask;

/// Invocations per workgroup of both entry points.
const WORKGROUP: u32 = 64;
/// Bytes of one accumulation column's difference: three channels of 64 bits.
const BYTES_PER_COLUMN: u64 = 24;
/// Fixed-point units for the brightest sprite's brightest channel: 2^-30 of it is far below what a display
/// or a half float resolves, and a pixel's step from its neighbour then mostly fits the low word, so that the
/// high word's atomic is mostly skipped (see `atomic_add64` in the shader).
const SPRITE_UNITS: f64 = 1_073_741_824.0; // 2^30
/// The most units the sum over sprites of their brightest channel may take (no 64-bit sum can overflow).
const SUM_UNITS: f64 = 4_611_686_018_427_387_904.0; // 2^62
/// Uniform offsets between strips (the largest alignment an adapter may ask for).
const STRIP_STRIDE: u64 = 256;

/// One strip's parameters. Must be kept in sync with `struct ComputeStrip` in `shaders/ghosts_compute.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct ComputeStrip {
    pub width: u32,
    pub height: u32,
    pub first_row: u32,
    pub rows: u32,
    pub instances: u32,
    pub items: u32,
    pub groups_x: u32,
    pub mask_size: u32,
    pub scale_x: f32,
    pub scale_y: f32,
    pub fixed_per_unit: f32,
    pub unit_per_fixed: f32,
    /// 1: `resolve` applies the LUT layer as it writes each pixel.
    pub lut: u32,
    pub unused: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<ComputeStrip>() == 64);

/// What one strip draws: its parameters, per sprite its first item and first row (then the item count), and
/// its `spans` dispatch.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StripPlan {
    pub params: ComputeStrip,
    pub items: Vec<[u32; 2]>,
    pub groups: (u32, u32),
}

/// The strips of a frame: rows at most `strip_rows` each, items spread over at most `max_groups` workgroups
/// a dimension. `instances` are the sprites as uploaded (open stops disabled).
pub(crate) fn plan_strips(
    scene: &FlareScene,
    instances: &[GhostInstance],
    mask_size: u32,
    strip_rows: u32,
    max_groups: u32,
) -> Vec<StripPlan> {
    let (w, h) = (scene.hdr_width.max(1), scene.hdr_height.max(1));
    let (sx, sy) = accumulation_scale(scene);
    // No pixel exceeds the sum of every sprite's brightest channel (each mask is at most 1).
    let brightest = |i: &GhostInstance| f64::from(i.colour[0].max(i.colour[1]).max(i.colour[2]).max(0.0));
    let bound: f64 = instances.iter().map(brightest).sum();
    let peak = instances.iter().map(brightest).fold(0.0, f64::max);
    let fixed_per_unit = (SPRITE_UNITS / peak).min(SUM_UNITS / bound);
    let (fixed_per_unit, unit_per_fixed) = if bound > 0.0 && fixed_per_unit.is_finite() && fixed_per_unit > 0.0 {
        (fixed_per_unit as f32, (1.0 / fixed_per_unit) as f32)
    } else {
        (0.0, 0.0)
    };
    let rows_of: Vec<std::ops::Range<usize>> =
        instances.iter().map(|i| covered(i.centre_half[1], i.centre_half[3], sy, h as usize)).collect();
    let strip_rows = strip_rows.clamp(1, h);
    (0..h)
        .step_by(strip_rows as usize)
        .map(|first_row| {
            let rows = strip_rows.min(h - first_row);
            let strip = first_row as usize..(first_row + rows) as usize;
            let mut items = Vec::with_capacity(instances.len() + 1);
            let mut total = 0u32;
            for r in &rows_of {
                let (lo, hi) = (r.start.max(strip.start), r.end.min(strip.end));
                items.push([total, lo as u32]);
                total += hi.saturating_sub(lo) as u32;
            }
            items.push([total, 0]);
            let workgroups = total.div_ceil(WORKGROUP);
            let groups_x = workgroups.clamp(1, max_groups.max(1));
            let groups = (groups_x, workgroups.div_ceil(groups_x));
            let params = ComputeStrip {
                width: w,
                height: h,
                first_row,
                rows,
                instances: instances.len() as u32,
                items: total,
                groups_x,
                mask_size,
                scale_x: sx,
                scale_y: sy,
                fixed_per_unit,
                unit_per_fixed,
                lut: 0,
                unused: [0; 3],
            };
            StripPlan { params, items, groups }
        })
        .collect()
}

/// The mask as `ghosts_compute.wgsl` reads it: the per-band table (f32 bits), then the texels four to a word.
fn mask_words(mask: &ApertureMask) -> Vec<u32> {
    let rows = MaskRows::new(mask);
    let mut words: Vec<u32> = rows.table().iter().flat_map(|b| b.map(f32::to_bits)).collect();
    words.extend(mask.texels.chunks(4).map(|c| {
        let mut word = [0u8; 4];
        word[..c.len()].copy_from_slice(c);
        u32::from_le_bytes(word)
    }));
    words
}

/// The pass's pipelines and buffers (see the module documentation).
pub(crate) struct ComputeGhosts {
    spans: wgpu::ComputePipeline,
    /// The two forms of the per-row sum (`resolve`, a scan of 64 columns at a time; `resolve_runs`, a run of
    /// columns an invocation) and which one draws: the runs on a software rasteriser (lavapipe, where a
    /// workgroup barrier costs more than a scattered read: 16 ms against 4 ms at 480x270), the scan elsewhere.
    resolve_scan: wgpu::ComputePipeline,
    resolve_runs: wgpu::ComputePipeline,
    pub(crate) scan: bool,
    mask: wgpu::Buffer,
    mask_size: u32,
    open_radius: f32,
    /// The difference buffer and its size in bytes (all zero between strips).
    diff: Option<(wgpu::Buffer, u64)>,
    /// The most bytes a strip's difference buffer may take (the adapter's limits; tests lower it).
    pub(crate) strip_bytes: u64,
    /// What `resolve` binds as the LUT layer when the frame has none (1 x 1, never read).
    no_layer: wgpu::TextureView,
}

impl ComputeGhosts {
    /// Whether `device` can run the pass: compute shaders (workgroups of 64), four storage buffers and one
    /// storage texture a stage, and room for one row of differences.
    pub(crate) fn supported(device: &wgpu::Device) -> bool {
        let l = device.limits();
        l.max_compute_invocations_per_workgroup >= WORKGROUP
            && l.max_compute_workgroup_size_x >= WORKGROUP
            && l.max_storage_buffers_per_shader_stage >= 4
            && l.max_storage_textures_per_shader_stage >= 1
            && l.max_compute_workgroup_storage_size >= 192 * 8
            && l.max_storage_buffer_binding_size >= 16385 * BYTES_PER_COLUMN
    }

    pub(crate) fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ghosts_compute.wgsl"),
            source: wgpu::ShaderSource::Wgsl(GHOSTS_COMPUTE_WGSL.into()),
        });
        let pipeline = |entry: &str| compute_pipeline(device, &module, entry);
        let open = ApertureMask { size: 1, texels: vec![255] };
        let limits = device.limits();
        let mut this = Self {
            spans: pipeline("spans"),
            resolve_scan: pipeline("resolve"),
            resolve_runs: pipeline("resolve_runs"),
            scan: !software_device(device),
            mask: storage(device, queue, "ghost mask", &[0; 16], wgpu::BufferUsages::STORAGE),
            mask_size: 1,
            open_radius: 0.0,
            diff: None,
            strip_bytes: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            no_layer: texture_2d(device, "no lut layer", 1, 1, HDR_FORMAT, wgpu::TextureUsages::TEXTURE_BINDING)
                .create_view(&wgpu::TextureViewDescriptor::default()),
        };
        this.set_aperture(device, queue, &open);
        this
    }

    /// Uploads the aperture mask and its per-row table.
    pub(crate) fn set_aperture(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, mask: &ApertureMask) {
        let words = mask_words(mask);
        self.mask = storage(device, queue, "ghost mask", bytemuck::cast_slice(&words), wgpu::BufferUsages::STORAGE);
        self.mask_size = mask.size as u32;
        self.open_radius = mask.open_radius();
    }

    /// Records the pass into `pass`: every sprite of `scene` into `hdr` (the accumulation, a storage texture of
    /// the scene's accumulation size), every pixel written (the pass also clears it), with the LUT layer
    /// `lut_layer` (`render::gpu_lut`) applied as it is written.
    pub(crate) fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pass: &mut wgpu_profiler::OwningScope<'_, wgpu::ComputePass<'_>>,
        scene: &FlareScene,
        hdr: &wgpu::TextureView,
        lut_layer: Option<&wgpu::TextureView>,
    ) {
        let instances: Vec<GhostInstance> =
            scene.instances.iter().map(|i| without_open_stops(i, self.open_radius)).collect();
        let width = u64::from(scene.hdr_width.max(1));
        let row_bytes = (width + 1) * BYTES_PER_COLUMN;
        let strip_rows = (self.strip_bytes / row_bytes).clamp(1, u64::from(scene.hdr_height.max(1))) as u32;
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        let mut strips = plan_strips(scene, &instances, self.mask_size, strip_rows, max_groups);
        for s in &mut strips {
            s.params.lut = u32::from(lut_layer.is_some());
        }
        let needed = row_bytes * u64::from(strip_rows);
        if !matches!(&self.diff, Some((_, size)) if *size >= needed) {
            // New buffers are zeroed by wgpu.
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("ghost differences"),
                size: needed,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            self.diff = Some((buffer, needed));
        }
        let Some((diff, _)) = &self.diff else { return };
        let instance_bytes: &[u8] =
            if instances.is_empty() { bytemuck::bytes_of(&[0.0f32; 24]) } else { bytemuck::cast_slice(&instances) };
        let instance_buffer = storage(device, queue, "ghost sprites", instance_bytes, wgpu::BufferUsages::STORAGE);
        let mut uniforms = vec![0u8; STRIP_STRIDE as usize * strips.len()];
        for (k, s) in strips.iter().enumerate() {
            let at = k * STRIP_STRIDE as usize;
            uniforms[at..at + std::mem::size_of::<ComputeStrip>()].copy_from_slice(bytemuck::bytes_of(&s.params));
        }
        let uniform_buffer = storage(device, queue, "ghost strips", &uniforms, wgpu::BufferUsages::UNIFORM);
        let resolve = if self.scan { &self.resolve_scan } else { &self.resolve_runs };
        for (k, s) in strips.iter().enumerate() {
            let items =
                storage(device, queue, "ghost items", bytemuck::cast_slice(&s.items), wgpu::BufferUsages::STORAGE);
            let params = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &uniform_buffer,
                offset: k as u64 * STRIP_STRIDE,
                size: wgpu::BufferSize::new(std::mem::size_of::<ComputeStrip>() as u64),
            });
            if s.params.items > 0 {
                let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("ghost spans"),
                    layout: &self.spans.get_bind_group_layout(0),
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: params.clone() },
                        wgpu::BindGroupEntry { binding: 1, resource: instance_buffer.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 2, resource: items.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 3, resource: self.mask.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 4, resource: diff.as_entire_binding() },
                    ],
                });
                // Timed apart where the device has timestamps inside passes ("ghosts" otherwise).
                let mut pass = pass.scope("ghost spans");
                pass.set_pipeline(&self.spans);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(s.groups.0, s.groups.1, 1);
            }
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("ghost resolve"),
                layout: &resolve.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: params },
                    wgpu::BindGroupEntry { binding: 4, resource: diff.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(hdr) },
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: wgpu::BindingResource::TextureView(lut_layer.unwrap_or(&self.no_layer)),
                    },
                ],
            });
            let mut pass = pass.scope("ghost resolve");
            pass.set_pipeline(resolve);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(s.params.rows, 1, 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flare::{FlareConfig, PreparedFlare};
    use crate::optics::library::builtin_lens;

    /// Strips cover every row once, each sprite's items are its covered rows within the strip, and a strip of
    /// more workgroups than a dimension allows spills into the second.
    #[test]
    fn strips_cover_every_row_and_item_once() {
        let flare = PreparedFlare::new(&builtin_lens("heliar").unwrap(), &FlareConfig::default()).unwrap();
        let (scene, _) = flare.scene([6.0, 3.0], 200, 120);
        let one = plan_strips(&scene, &scene.instances, 64, 1000, 65535);
        assert_eq!(one.len(), 1);
        let total = one[0].params.items;
        assert!(total > 100, "{total} items");
        for rows in [1, 7, 50] {
            let strips = plan_strips(&scene, &scene.instances, 64, rows, 3);
            assert_eq!(strips.iter().map(|s| s.params.rows).sum::<u32>(), 120);
            assert_eq!(strips.iter().map(|s| s.params.items).sum::<u32>(), total);
            for s in &strips {
                assert!(s.groups.0 <= 3 && s.groups.0 * s.groups.1 * WORKGROUP >= s.params.items, "{s:?}");
                for pair in s.items.windows(2) {
                    let count = pair[1][0] - pair[0][0];
                    assert!(count == 0 || pair[0][1] >= s.params.first_row);
                    assert!(pair[0][1] + count <= s.params.first_row + s.params.rows);
                }
            }
        }
    }
}
