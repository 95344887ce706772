//! The ghost sprites as a compute pass (`shaders/ghosts_compute.wgsl`): the CPU twin's algorithm
//! ([`super::cpu::ghost_pass`]) on the GPU, instead of rasterising frame-sized quads.
//!
//! # How it works
//! A wide-open lens's sprites are often larger than the frame; rasterised, each one shades every pixel it
//! covers (about 1.4 G fragments for a 28-surface zoom at 1920x1080), and a data-centre GPU rasterises on a few
//! units only. Here each (sprite, accumulation row) is an item of `spans`: the row's open span (every mask
//! exactly 1, from the aperture's per-row table, [`super::cpu::ghosts`]'s `MaskRows`) is added in O(1), only
//! the pixels outside it are shaded as the fragment shader does, and the row's values go in as differences
//! `F(x) - F(x - 1)` to a per-row buffer; `resolve` then sums each row once into the HDR texture. The cost
//! follows rows x sprites plus edge pixels, not covered area. The edge pixels are those where a mask is between
//! 0 and 1, a mask texel or two wide: each stop crossing reads the level of the mask ([`GhostMasks`], 256 to
//! 1024 texels a side, one storage buffer of their tables and footprints, one texture each) that its sprite's
//! size calls for, so that a frame-filling sprite's edge is a few pixels wide, not 32 (at 4K). On a hardware
//! GPU ([`ComputeForm`]) an item's walk is split between several invocations (`default_pieces`: at 4K one invocation walking a long edge held
//! its warp up), each item is worked out once into a buffer those invocations read (`walks_setup`), and each
//! mask lookup gathers its four texels from a texture in one fetch. A software rasteriser (lavapipe) loads a
//! storage word lane by lane, so there the form keeps such loads few: each sprite is one workgroup whose
//! invocations take its rows (`spans_sprites`: the sprite is read once from a workgroup-uniform index; the
//! workgroups take the sprites in a spread order, `buffers::spread_stride`, so that lavapipe's threads share the large
//! ones), a mask lookup reads one word holding its footprint's four texels (`ApertureMask::quad_words`) from a
//! texture of words (lavapipe gathers a texel fetch for all its lanes at once), and one invocation sums a row,
//! each column read once (`resolve_rows`).
//!
//! **Deterministic**: the differences are integers, so the order in which sprites land does not matter: the
//! same frame gives the same bytes on every run and in every [`ComputeForm`]. Each step is at most `2^30`
//! units (the unit is chosen per frame from the brightest sprite's brightest channel, and so that the sum over
//! sprites of their brightest channel, which no pixel can exceed, stays within `2^62`); it is added as two
//! 32-bit parts, `hi = round(d / 2^k)` and `lo = d - hi 2^k`, to a column's two words by atomics whose results
//! are not read, so no invocation waits on an atomic's round trip. `split_units` picks k so that neither
//! word's sum can wrap (at most one step per sprite and column in a strip), and `resolve` rebuilds the exact
//! 64-bit sum `high 2^k + low`.
//!
//! **Limits**: the difference buffer holds `(width + 1) x rows x 24` bytes. A frame whose buffer would pass the
//! adapter's `max_storage_buffer_binding_size` (or `max_buffer_size`) is drawn in strips of rows, one after
//! another into the same buffer (`resolve` leaves it zeroed); a strip's items beyond
//! `max_compute_workgroups_per_dimension` workgroups go in a second dimension. `ComputeGhosts::supported`
//! says whether a device can run the pass at all (compute shaders, four storage buffers, a storage texture);
//! where it cannot (a WebGL-class adapter), `FlareRenderer` keeps the raster pass
//! (`ghosts.wgsl`).

use std::sync::OnceLock;

use bytemuck::{Pod, Zeroable};

use super::buffers::{
    HDR_FORMAT, compute_pipeline, compute_pipeline_with, grow_storage, software_device, spread_stride, storage,
    texture_2d, upload, word_texels,
};
use super::cpu::ghosts::{GhostMasks, MASK_LEVELS, level_index, without_open_stops};
use super::cpu::quads::{accumulation_scale, covered};
use super::shaders::GHOSTS_COMPUTE_WGSL;
use super::{FlareScene, GhostInstance};
use crate::aperture::ApertureMask;

/// The mask texture's format (the texels as they are).
const R8: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
/// Invocations per workgroup of both entry points.
const WORKGROUP: u32 = 64;
/// Invocations per workgroup of the scanning `resolve`, and columns a chunk (`CHUNK` in the shader).
const CHUNK: u32 = 256;
/// Bytes of one accumulation column's difference: three channels of 64 bits.
const BYTES_PER_COLUMN: u64 = 24;
/// Bytes of one item's walk (`struct Walk` in the shader).
const BYTES_PER_WALK: u64 = 44;
/// The most fixed-point units for the brightest sprite's brightest channel: 2^-30 of it is far below what a
/// display or a half float resolves ([`split_units`] takes fewer only for more than about 32 000 sprites).
const MAX_SPRITE_BITS: u32 = 30;
/// The most units the sum over sprites of their brightest channel may take (no 64-bit sum can overflow).
const SUM_UNITS: f64 = 4_611_686_018_427_387_904.0; // 2^62
/// Uniform offsets between strips (the largest alignment an adapter may ask for).
const STRIP_STRIDE: u64 = 256;

/// The shader's entries that walk items: items spread over invocations (each searching for its sprite), the
/// same reading each item's walk from `walks`, and a workgroup a sprite (`ComputeForm::sprite_groups`).
const SPANS_ENTRIES: [&str; 3] = ["spans", "spans_walks", "spans_sprites"];
const SPANS_SPRITES: usize = 2;

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
    /// k: each step goes in as a high part (units of 2^k) and a low part, each to its own word.
    pub split_bits: u32,
    /// Invocations that share one (sprite, row) item's walk, each a piece of it.
    pub pieces: u32,
    /// `spans_sprites`: workgroup x draws sprite x * spread mod sprites (a `buffers::spread_stride`).
    pub spread: u32,
    /// Levels of the mask (`GhostMasks`), each twice the texels a side of the one before (`mask_size` the first).
    pub mask_levels: u32,
    /// The word of the mask buffer where each level starts (`mask_words`; 0 for a level it lacks).
    pub level_starts: [u32; MASK_LEVELS],
}
const _: () = assert!(std::mem::size_of::<ComputeStrip>() == 80);

/// How the shader's steps are split between a column's two words (see `atomic_add_split` in the shader).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SplitUnits {
    /// k: a step d goes in as `hi = round(d / 2^k)` to the high word and `lo = d - hi 2^k` to the low word.
    pub bits: u32,
    /// Units for the brightest sprite's brightest channel (a power of two): no step exceeds it.
    pub sprite_units: f64,
}

/// The split and the sprite unit for `sprites` sprites, each adding at most one step to a word in a strip,
/// such that neither word's 32-bit sum can wrap: the low word gains at most `2^(k-1)` a step, the high word at
/// most `round(units / 2^k)`. The largest k the low word allows, then the most units the high word allows (2^30
/// up to about 32 000 sprites; fewer beyond, down to 2 units for a billion).
pub(crate) fn split_units(sprites: usize) -> SplitUnits {
    const MAX: u64 = i32::MAX as u64;
    let n = sprites.max(1) as u64;
    let mut bits = 1;
    while bits < 30 && n << bits <= MAX {
        bits += 1;
    }
    // A sprite's rounded value may pass its unit by a few f32 steps: allow 2^-10 of it.
    let high_step = |units: u64| (units + (units >> 10) + (1 << (bits - 1))) >> bits;
    let mut sprite_bits = MAX_SPRITE_BITS;
    while sprite_bits > 1 && n.saturating_mul(high_step(1 << sprite_bits)) > MAX {
        sprite_bits -= 1;
    }
    SplitUnits { bits, sprite_units: (1u64 << sprite_bits) as f64 }
}

/// How a device draws the pass: the same image, to the byte, in every form (tests draw each on lavapipe).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ComputeForm {
    /// The per-row sum as a workgroup scan of 256 columns at a time (a hardware GPU), or one invocation a row
    /// summing it column by column (`resolve_rows`: a software rasteriser, where a workgroup barrier costs more
    /// than a scattered read and a row's columns read once cost least: 7 ms against 28 ms for a run of columns
    /// an invocation at 480x320 on lavapipe).
    pub scan: bool,
    /// The stop masks' four texels a lookup by one `textureGather` (a hardware GPU: the spans pass took 1.76
    /// against 1.98 ms at 4K on an H200; the mask's row table from the storage buffer) rather than one word
    /// holding all four (`ApertureMask::quad_words`) from a texture of words (`mask_texels`: a software
    /// rasteriser, whose gather and sampler are slower, and which loads a storage buffer's words lane by lane;
    /// lavapipe drew the Nikon zoom at 480x320 in 150 ms so against 159 ms from the buffer, and 168 ms
    /// gathered). Fixed when the pass's pipeline is built (`override GATHER_MASKS`).
    pub gather_masks: bool,
    /// Invocations that share each (sprite, row) item's walk; `None`: `default_pieces` of the frame's width.
    pub pieces: Option<u32>,
    /// Each item worked out once, by one invocation, into a buffer its pieces read (`walks_setup`, then
    /// `spans_walks`: a hardware GPU; at 4K on an H200 1.35 ms for both against 1.47 ms for `spans`), rather than
    /// by each of its pieces (`spans`: a software rasteriser, whose one piece an item gains nothing). A frame
    /// whose buffer (44 bytes an item) would pass the adapter's storage binding limit is drawn without it.
    pub setup_once: bool,
    /// One workgroup a sprite, whose invocations take its items in turn, each in one piece (`spans_sprites`: a
    /// software rasteriser, which then loads the sprite once for a SIMD batch rather than lane by lane, and
    /// needs no search for it), rather than items spread evenly over invocations. Where set, `pieces` and
    /// `setup_once` are not used.
    pub sprite_groups: bool,
}

impl ComputeForm {
    /// The form for `device`: on a software rasteriser a row an invocation in the per-row sum, the masks'
    /// footprint words from the buffer and a workgroup a sprite.
    pub(crate) fn for_device(device: &wgpu::Device) -> Self {
        let hardware = !software_device(device);
        Self {
            scan: hardware,
            gather_masks: hardware,
            pieces: if hardware { None } else { Some(1) },
            setup_once: hardware,
            sprite_groups: !hardware,
        }
    }
}

/// The spans entry (`SPANS_ENTRIES`) that draws in `form`, `walks`: where the items' walks are worked out once.
fn spans_entry(form: ComputeForm, walks: bool) -> usize {
    if form.sprite_groups { SPANS_SPRITES } else { usize::from(walks) }
}

/// Invocations that share an item's walk on a hardware GPU, for an accumulation `width` pixels wide: one per
/// 240 columns, at most 8. An edge's pixels grow with the width; an item walked by one invocation held its warp
/// up (the spans pass at 4K on an H200, masks gathered: 1.52 ms in 8 pieces, 1.75 ms in 16, 2.50 ms in 32; the
/// buffer's masks: 4.13 ms in one piece, 2.77 ms in 8; at 1920x1080 0.51 ms in 8, 0.67 ms in 16).
pub(crate) fn default_pieces(width: u32) -> u32 {
    width.div_ceil(240).clamp(1, 8)
}

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
    mask: &MaskLayout,
    strip_rows: u32,
    max_groups: u32,
    pieces: u32,
) -> Vec<StripPlan> {
    let (w, h) = (scene.hdr_width.max(1), scene.hdr_height.max(1));
    let (sx, sy) = accumulation_scale(scene);
    // No pixel exceeds the sum of every sprite's brightest channel (each mask is at most 1), taken by
    // magnitude so that the bounds on a step hold whatever its sign (colours are not negative in practice).
    let brightest = |i: &GhostInstance| f64::from(i.colour[..3].iter().fold(0.0f32, |m, c| m.max(c.abs())));
    let bound: f64 = instances.iter().map(brightest).sum();
    let peak = instances.iter().map(brightest).fold(0.0, f64::max);
    let split = split_units(instances.len());
    let fixed_per_unit = (split.sprite_units / peak).min(SUM_UNITS / bound);
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
            // The shader counts invocations in a u32.
            let pieces = pieces.clamp(1, (u32::MAX / total.max(1)).max(1));
            let workgroups = (total * pieces).div_ceil(WORKGROUP);
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
                mask_size: mask.size,
                mask_levels: mask.levels,
                level_starts: mask.starts,
                scale_x: sx,
                scale_y: sy,
                fixed_per_unit,
                unit_per_fixed,
                lut: 0,
                split_bits: split.bits,
                pieces,
                spread: spread_stride(instances.len().try_into().unwrap_or(u32::MAX)),
            };
            StripPlan { params, items, groups }
        })
        .collect()
}

/// One R8 texture a level of `masks` (a level they lack repeats the last, and no stop map names it): what the
/// raster ghosts sample and the compute pass gathers from, uploaded once for both.
pub(crate) fn mask_level_textures(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    masks: &GhostMasks,
) -> [wgpu::Texture; MASK_LEVELS] {
    let levels = masks.levels();
    let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
    std::array::from_fn(|l| {
        let mask = &levels[l.min(levels.len() - 1)].mask;
        let size = mask.size as u32;
        let texture = texture_2d(device, "aperture", size, size, R8, usage);
        upload(queue, &texture, &mask.texels, 1);
        texture
    })
}

/// Where the mask's levels lie in the buffer `mask_words` makes (what `ComputeStrip` tells the shader).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MaskLayout {
    /// Texels a side of the base level, and the number of levels.
    pub size: u32,
    pub levels: u32,
    /// The word where each level starts (a multiple of four; 0 for a level the mask lacks).
    pub starts: [u32; MASK_LEVELS],
}

/// The mask's levels as `ghosts_compute.wgsl` reads them: each level's per-band table (f32 bits), then each of
/// its bilinear footprints' four texels in one word (`ApertureMask::quad_words`), then zeros up to a multiple of
/// four words (a row of the table is then one texel of the texture of words); and where each level starts.
fn mask_words(masks: &GhostMasks) -> (Vec<u32>, MaskLayout) {
    let mut words = Vec::new();
    let mut starts = [0; MASK_LEVELS];
    for (level, start) in masks.levels().iter().zip(&mut starts) {
        *start = words.len() as u32;
        words.extend(level.rows.table().iter().flat_map(|b| b.map(f32::to_bits)));
        words.extend(level.mask.quad_words());
        words.resize(words.len().next_multiple_of(4), 0);
    }
    let layout = MaskLayout { size: masks.levels()[0].mask.size as u32, levels: masks.levels().len() as u32, starts };
    (words, layout)
}

/// The pass's pipelines and buffers (see the module documentation).
pub(crate) struct ComputeGhosts {
    module: wgpu::ShaderModule,
    /// The entries that walk items (`SPANS_ENTRIES`), each with the stop masks read from the buffer, then
    /// gathered from the texture (built on first use, see `spans_pipeline`).
    spans: [[OnceLock<wgpu::ComputePipeline>; 2]; 3],
    /// `ComputeForm::setup_once`: each item's walk worked out once (then `spans_walks` walks it).
    walks_setup: wgpu::ComputePipeline,
    /// The items' walks and the buffer's size in bytes.
    walks: Option<(wgpu::Buffer, u64)>,
    /// The two forms of the per-row sum (`resolve`, a scan of 256 columns at a time; `resolve_rows`, a row an
    /// invocation).
    resolve_scan: wgpu::ComputePipeline,
    resolve_rows: wgpu::ComputePipeline,
    /// How this device draws the pass (see [`ComputeForm`]).
    pub(crate) form: ComputeForm,
    /// The mask's per-band table and its footprints' words (one storage buffer).
    mask: wgpu::Buffer,
    /// The same words as rows of texels (a software rasteriser's lookups, `mask_texels` in the shader).
    mask_texels: wgpu::TextureView,
    /// The mask's levels as textures (a level the mask lacks repeats the last), and the sampler `textureGather`
    /// reads them with.
    mask_texture: [wgpu::TextureView; MASK_LEVELS],
    mask_sampler: wgpu::Sampler,
    /// Where the levels lie in `mask`.
    mask_layout: MaskLayout,
    /// Each level's fully open radius (`without_open_stops`).
    open_radii: Vec<f32>,
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
        l.max_compute_invocations_per_workgroup >= CHUNK
            && l.max_compute_workgroup_size_x >= CHUNK
            && l.max_storage_buffers_per_shader_stage >= 4
            && l.max_storage_textures_per_shader_stage >= 1
            && l.max_compute_workgroup_storage_size >= 32 * CHUNK
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
        let form = ComputeForm::for_device(device);
        // The walks' setup reads only the mask's row table, from where the device's own form reads it.
        let gather = [("GATHER_MASKS", f64::from(u8::from(form.gather_masks)))];
        let mut this = Self {
            spans: Default::default(),
            walks_setup: compute_pipeline_with(device, &module, "walks_setup", &gather),
            walks: None,
            resolve_scan: pipeline("resolve"),
            resolve_rows: pipeline("resolve_rows"),
            form,
            mask: storage(device, queue, "ghost mask", &[0; 16], wgpu::BufferUsages::STORAGE),
            mask_texels: word_texels(device, queue, "ghost mask texels", &[0; 16]),
            mask_texture: std::array::from_fn(|_| {
                texture_2d(device, "ghost mask", 1, 1, R8, wgpu::TextureUsages::TEXTURE_BINDING)
                    .create_view(&wgpu::TextureViewDescriptor::default())
            }),
            mask_sampler: device
                .create_sampler(&wgpu::SamplerDescriptor { label: Some("ghost mask"), ..Default::default() }),
            mask_layout: MaskLayout { size: 1, levels: 1, starts: [0; MASK_LEVELS] },
            open_radii: vec![0.0],
            diff: None,
            strip_bytes: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            no_layer: texture_2d(device, "no lut layer", 1, 1, HDR_FORMAT, wgpu::TextureUsages::TEXTURE_BINDING)
                .create_view(&wgpu::TextureViewDescriptor::default()),
            module,
        };
        let open = GhostMasks::from_masks(vec![open]);
        this.set_aperture(device, queue, &open, &mask_level_textures(device, queue, &open));
        // The device's own form's entry now, so that its first frame does not wait for the compiler.
        this.spans_pipeline(device, spans_entry(form, form.setup_once));
        this
    }

    /// Entry `SPANS_ENTRIES[entry]` compiled for the form's mask lookups (`override GATHER_MASKS`): fixed when
    /// the pipeline is built rather than read from a uniform, because a software rasteriser runs both sides of a
    /// branch: lavapipe ran the texture gather, masked off, beside every buffer lookup. Built on first use.
    fn spans_pipeline(&self, device: &wgpu::Device, entry: usize) -> &wgpu::ComputePipeline {
        let gather = self.form.gather_masks;
        self.spans[entry][usize::from(gather)].get_or_init(|| {
            let constants = [("GATHER_MASKS", f64::from(u8::from(gather)))];
            compute_pipeline_with(device, &self.module, SPANS_ENTRIES[entry], &constants)
        })
    }

    /// Uploads the aperture mask's levels' per-row tables and footprints, and gathers from `textures`, the
    /// levels as [`mask_level_textures`] made them (the renderer's raster pass samples the same ones).
    pub(crate) fn set_aperture(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        masks: &GhostMasks,
        textures: &[wgpu::Texture; MASK_LEVELS],
    ) {
        let (words, layout) = mask_words(masks);
        self.mask = storage(device, queue, "ghost mask", bytemuck::cast_slice(&words), wgpu::BufferUsages::STORAGE);
        self.mask_texels = word_texels(device, queue, "ghost mask texels", bytemuck::cast_slice(&words));
        let levels = masks.levels();
        self.mask_layout = layout;
        self.open_radii = levels.iter().map(|l| l.open_radius).collect();
        self.mask_texture = textures.each_ref().map(|t| t.create_view(&wgpu::TextureViewDescriptor::default()));
    }

    /// Records strip `s`'s spans: where the walks are set up once, their setup first, then the spans pass
    /// (one workgroup a sprite with `sprite_groups`), timed apart as "ghost spans" where the device has
    /// timestamps inside passes ("ghosts" otherwise).
    fn record_spans(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu_profiler::OwningScope<'_, wgpu::ComputePass<'_>>,
        spans: &wgpu::ComputePipeline,
        s: &StripPlan,
        inputs: &StripInputs,
    ) {
        let mut pass = pass.scope("ghost spans");
        let mask_view = |k: usize| wgpu::BindingResource::TextureView(&self.mask_texture[k]);
        let texels = wgpu::BindingResource::TextureView(&self.mask_texels);
        if let Some(walks) = inputs.walks {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("ghost walks"),
                layout: &self.walks_setup.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: inputs.params.clone() },
                    wgpu::BindGroupEntry { binding: 1, resource: inputs.instances.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: inputs.items.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: self.mask.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 10, resource: texels.clone() },
                    wgpu::BindGroupEntry { binding: 11, resource: walks.as_entire_binding() },
                ],
            });
            // One invocation an item, counted as `spans` counts its invocations (rows of `groups_x`).
            let groups = s.params.items.div_ceil(WORKGROUP);
            let rows = groups.div_ceil(s.params.groups_x);
            pass.set_pipeline(&self.walks_setup);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(if rows > 1 { s.params.groups_x } else { groups }, rows, 1);
        }
        let entries = [
            wgpu::BindGroupEntry { binding: 0, resource: inputs.params.clone() },
            wgpu::BindGroupEntry { binding: 1, resource: inputs.instances.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 3, resource: self.mask.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 4, resource: inputs.diff.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 8, resource: mask_view(0) },
            wgpu::BindGroupEntry { binding: 12, resource: mask_view(1) },
            wgpu::BindGroupEntry { binding: 13, resource: mask_view(2) },
            wgpu::BindGroupEntry { binding: 9, resource: wgpu::BindingResource::Sampler(&self.mask_sampler) },
            wgpu::BindGroupEntry { binding: 10, resource: texels },
            match inputs.walks {
                Some(walks) => wgpu::BindGroupEntry { binding: 11, resource: walks.as_entire_binding() },
                None => wgpu::BindGroupEntry { binding: 2, resource: inputs.items.as_entire_binding() },
            },
        ];
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ghost spans"),
            layout: &spans.get_bind_group_layout(0),
            entries: &entries,
        });
        pass.set_pipeline(spans);
        pass.set_bind_group(0, &group, &[]);
        if self.form.sprite_groups {
            // One workgroup a sprite (rows of `max_groups`; the shader counts them by `num_workgroups`).
            let max_groups = device.limits().max_compute_workgroups_per_dimension;
            let n = s.params.instances;
            pass.dispatch_workgroups(n.min(max_groups), n.div_ceil(max_groups), 1);
        } else {
            pass.dispatch_workgroups(s.groups.0, s.groups.1, 1);
        }
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
        let instances: Vec<GhostInstance> = scene
            .instances
            .iter()
            .map(|i| without_open_stops(i, |code| self.open_radii[level_index(code, self.open_radii.len())]))
            .collect();
        let width = u64::from(scene.hdr_width.max(1));
        let row_bytes = (width + 1) * BYTES_PER_COLUMN;
        let strip_rows = (self.strip_bytes / row_bytes).clamp(1, u64::from(scene.hdr_height.max(1))) as u32;
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        let sprite_groups = self.form.sprite_groups;
        let pieces =
            if sprite_groups { 1 } else { self.form.pieces.unwrap_or_else(|| default_pieces(scene.hdr_width)) };
        let mut strips = plan_strips(scene, &instances, &self.mask_layout, strip_rows, max_groups, pieces);
        for s in &mut strips {
            s.params.lut = u32::from(lut_layer.is_some());
        }
        // The difference buffer is zeroed when new (wgpu) and left zeroed by `resolve`.
        grow_storage(device, &mut self.diff, "ghost differences", row_bytes * u64::from(strip_rows));
        // The walks' buffer, where the form asks for it and the largest strip's walks fit one binding.
        let walk_bytes = strips.iter().map(|s| u64::from(s.params.items) * BYTES_PER_WALK).max().unwrap_or(0);
        let setup_once = self.form.setup_once && !sprite_groups && walk_bytes > 0 && walk_bytes <= self.strip_bytes;
        if setup_once {
            grow_storage(device, &mut self.walks, "ghost walks", walk_bytes);
        }
        let walks = self.walks.as_ref().map(|(b, _)| b).filter(|_| setup_once);
        let spans = self.spans_pipeline(device, spans_entry(self.form, walks.is_some()));
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
        let resolve = if self.form.scan { &self.resolve_scan } else { &self.resolve_rows };
        for (k, s) in strips.iter().enumerate() {
            let items =
                storage(device, queue, "ghost items", bytemuck::cast_slice(&s.items), wgpu::BufferUsages::STORAGE);
            let params = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &uniform_buffer,
                offset: k as u64 * STRIP_STRIDE,
                size: wgpu::BufferSize::new(std::mem::size_of::<ComputeStrip>() as u64),
            });
            if s.params.items > 0 {
                let inputs =
                    StripInputs { params: params.clone(), instances: &instance_buffer, items: &items, diff, walks };
                self.record_spans(device, pass, spans, s, &inputs);
            }
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("ghost resolve"),
                layout: &resolve.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: params },
                    wgpu::BindGroupEntry { binding: 7, resource: diff.as_entire_binding() },
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
            // `resolve`: a workgroup a row; `resolve_rows`: an invocation a row, eight to a workgroup.
            pass.dispatch_workgroups(if self.form.scan { s.params.rows } else { s.params.rows.div_ceil(8) }, 1, 1);
        }
    }
}

/// The buffers one strip's spans read ([`ComputeGhosts::record_spans`]).
struct StripInputs<'a> {
    params: wgpu::BindingResource<'a>,
    instances: &'a wgpu::Buffer,
    items: &'a wgpu::Buffer,
    diff: &'a wgpu::Buffer,
    walks: Option<&'a wgpu::Buffer>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flare::{FlareConfig, PreparedFlare};
    use crate::optics::library::builtin_lens;

    /// Neither word of a column can wrap: for any number of sprites, the low word's worst sum (every sprite's
    /// step at `2^(k-1)`) and the high word's (every sprite's step at its unit and a little over, rounded to
    /// units of `2^k`) stay within an i32, and the split is as fine as that allows.
    #[test]
    fn split_words_never_wrap() {
        let limit = i64::from(i32::MAX);
        for n in [1usize, 2, 3, 68, 876, 1023, 1024, 1025, 32_767, 32_768, 100_000, 1 << 20, 1 << 30, 2_000_000_000] {
            let SplitUnits { bits, sprite_units } = split_units(n);
            let n = n as i64;
            assert!((1..=30).contains(&bits), "{n}: k = {bits}");
            assert!(n * (1i64 << (bits - 1)) <= limit, "{n}: low word sum with k = {bits}");
            assert!(bits == 30 || n * (1i64 << bits) > limit, "{n}: k = {bits} could be larger");
            let step = sprite_units as i64 + (sprite_units as i64 >> 10);
            // The shader's hi = (d + 2^(k-1)) >> k, d + 2^(k-1) itself within an i32.
            assert!(step + (1i64 << (bits - 1)) <= limit, "{n}: d + 2^(k-1) with k = {bits}");
            let high = (step + (1i64 << (bits - 1))) >> bits;
            assert!(n * high <= limit, "{n}: high word sum {} with units {sprite_units}", n * high);
            assert!((2.0..=1073741824.0).contains(&sprite_units), "{n}: units {sprite_units}");
        }
        assert_eq!(split_units(876), SplitUnits { bits: 22, sprite_units: 1073741824.0 });
        assert_eq!(split_units(32_768).sprite_units, 1073741824.0);
    }

    /// Strips cover every row once, each sprite's items are its covered rows within the strip, and a strip of
    /// more workgroups than a dimension allows spills into the second.
    #[test]
    fn strips_cover_every_row_and_item_once() {
        const ONE_LEVEL: MaskLayout = MaskLayout { size: 64, levels: 1, starts: [0; MASK_LEVELS] };
        let flare = PreparedFlare::new(&builtin_lens("heliar").unwrap(), &FlareConfig::default()).unwrap();
        let (scene, _) = flare.scene([6.0, 3.0], 200, 120);
        let one = plan_strips(&scene, &scene.instances, &ONE_LEVEL, 1000, 65535, 1);
        assert_eq!(one.len(), 1);
        let total = one[0].params.items;
        assert!(total > 100, "{total} items");
        for rows in [1, 7, 50] {
            let strips = plan_strips(&scene, &scene.instances, &ONE_LEVEL, rows, 3, 1);
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
