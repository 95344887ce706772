// Ghost sprites as compute: the CPU twin's algorithm on the GPU, no rasteriser.
// CPU twin: crates/flare_core/src/render/cpu/ghosts.rs, `ghost_pass` (`spans` is its `sweep_instance`, `resolve`
// its per-row sum; same names, same steps); the fixed-point helpers come from fixed64.wgsl, the bilinear mask
// lookup from mask_texels.wgsl. Must be kept in sync with `GhostInstance` in crates/flare_core/src/render/mod.rs
// and `ComputeStrip` in crates/flare_core/src/render/gpu_ghosts.rs.
//
// How it works. Each (sprite, accumulation row) the sprite covers is an item: `spans` finds the row's open
// span (where every clear-aperture disc and every stop crossing's mask are exactly 1, from the mask's per-row table) and
// shades only the pixels outside it, as the fragment shader would, each evaluating only the masks that are not
// open over the row's whole walk (`live`: a factor of 1 changes no bit; every mask worked out with constant
// indices, since a software rasteriser keeps a dynamically indexed array in memory). The row's values F(x) (0 outside the
// sprite, the colour in the open span, colour x mask at an edge pixel) go into a per-row difference buffer as
// F(x) - F(x - 1), wherever that is not 0: a frame-filling sprite costs its edges, not its area. An item's walk
// (its edge pixels, the open span's first pixel, the end) is split between `pieces` invocations, each taking
// one run of it and shading the pixel before its run once more: a long edge does not hold up its warp. Each
// of them works the item out (`spans`), or one invocation an item does so into `walks` first (`walks_setup`,
// then `spans_walks`: hardware GPUs, where the repeats cost 0.26 ms of a 4K frame). Each stop map names the level
// of the mask it reads (its .w: 1 the base of `mask_size` texels a side, 2 and 3 twice and four times that;
// `GhostMasks` in the CPU twin), chosen per sprite so that a texel spans a few pixels: the edges, a texel or
// two of the mask wide, stay a few pixels wide on a frame-filling sprite. A stop mask lookup reads
// its four texels as one word (`ApertureMask::quad_words`) of a texture of words, as does a row of the mask's
// table (`mask_texels`: a software rasteriser gathers a texel fetch for its lanes, where it loads a storage
// word lane by lane), or, where GATHER_MASKS (hardware GPUs), by one `textureGather`, every mask of the pixel
// fetched before any is tested, the table from the storage buffer: the same texels and arithmetic either way.
// On a software rasteriser each sprite is instead one workgroup whose invocations take its rows
// (`spans_sprites`, the sprites in a spread order). `resolve` sums each row once (a prefix sum, one
// workgroup a row scanning 256 columns at a time; `resolve_rows`, one invocation a row, on a software
// rasteriser) into the HDR texture, applying the LUT layer where the frame has one. The differences are
// integers: each step d (at most 2^30 units) is added as two 32-bit parts, hi = round(d / 2^k) and
// lo = d - hi 2^k, to two words by atomics whose results are not read (no invocation waits on one), and
// `resolve` rebuilds the 64-bit sum high 2^k + low. Integer addition does not depend on the
// order in which sprites arrive, so the image is the same bytes on every run, whatever `pieces` is. The
// unit and k are chosen per frame (gpu_ghosts.rs, `split_units`): 2^30 units for the brightest sprite's
// brightest channel (fewer past about 32 000 sprites), at most 2^62 for the sum of every sprite's, and k such
// that neither word's sum can wrap with one step per sprite and column.

struct GhostInstance {
    centre_half: vec4<f32>, // centre x, y (image pixels); half-size x, y (signed: q -> pixel)
    colour: vec4<f32>,      // linear RGB irradiance
    stop0: vec4<f32>,       // aperture map of stop crossing 0: scale, offset x, offset y, mask level (0: off)
    stop1: vec4<f32>,
    stop2: vec4<f32>,
    scale_y: vec4<f32>,     // the y scales of stop0..2 (.x above is the x scale; equal when round); .w unused
    discs: array<vec4<f32>, 4>, // clear-aperture disc maps: scale, offset x, offset y, anti-alias width (0: none)
    disc_scale_y: vec4<f32>,    // the y scales of the four discs
};

struct ComputeStrip {
    width: u32,          // the accumulation's width and height (pixels)
    height: u32,
    first_row: u32,      // the strip: its first accumulation row and its number of rows
    rows: u32,
    instances: u32,      // sprites, (sprite, row) items of this strip, workgroups along x of `spans`
    items: u32,
    groups_x: u32,
    mask_size: u32,      // texels a side of the aperture mask's base level (level l: mask_size << l)
    scale_x: f32,        // image pixels per accumulation pixel
    scale_y: f32,
    fixed_per_unit: f32, // fixed-point units per unit of irradiance, and its inverse
    unit_per_fixed: f32,
    lut: u32,            // 1: apply the LUT layer (lut_compute.wgsl's (A, K)) as each pixel is written
    split_bits: u32,     // k: a step d is added as hi = round(d / 2^k) and lo = d - hi 2^k, each to its own word
    pieces: u32,         // invocations a (sprite, row) item's walk is split between
    spread: u32,         // `spans_sprites`: workgroup x draws sprite x * spread mod sprites
    mask_levels: u32,    // levels of the mask in `mask` (GhostMasks: 1 to 3)
    level_start0: u32,   // the words of `mask` where levels 0, 1 and 2 start (`mask_words` in gpu_ghosts.rs)
    level_start1: u32,
    level_start2: u32,
};

// True (hardware GPUs): the stop masks' texels gathered from `mask_texture` (one fetch a lookup), every mask of a
// pixel looked up before any is tested. A pipeline constant, not a uniform: a software rasteriser runs the code
// of both sides of a branch, masked, so the gather would run beside every buffer lookup.
override GATHER_MASKS: bool = false;

@group(0) @binding(0) var<uniform> strip: ComputeStrip;
@group(0) @binding(1) var<storage, read> instances: array<GhostInstance>;
// Per sprite: its first item and its first row in this strip; then (items, 0).
@group(0) @binding(2) var<storage, read> items: array<vec2<u32>>;
// The aperture mask's levels (one buffer: four storage buffers are all a downlevel adapter has), each level of
// n texels a side in turn: first, per band of mask rows (n + 1 of them), u where the bilinear sample is exactly
// 1 (lo, hi) and u outside which it is 0 (lo, hi), as f32 bits; then each bilinear footprint's four 8-bit texels
// in one word (mask_texels.wgsl); then up to three words of padding, so that each level starts at a multiple of
// four words (a row of its table is one texel of `mask_texels`).
@group(0) @binding(3) var<storage, read> mask: array<u32>;
// Per strip row, per column 0..=width, per channel R, G, B: a 64-bit difference as (low word, high word).
// All zero between strips: `resolve` clears what it read.
@group(0) @binding(4) var<storage, read_write> diff: array<atomic<u32>>;
// The same buffer as `resolve` reads and clears it, after `spans` (bound apart: a pass boundary between).
@group(0) @binding(7) var<storage, read_write> columns: array<u32>;
// The same words as `mask` as rows of texels (word_texels.wgsl), read where GATHER_MASKS is false.
@group(0) @binding(10) var mask_texels: texture_2d<u32>;
// The same mask as a texture (R8Unorm) and a sampler clamped to the edge, for `textureGather`: the base level,
// then the finer ones (a level the mask lacks binds the base again, and no stop map names it).
@group(0) @binding(8) var mask_texture: texture_2d<f32>;
@group(0) @binding(12) var mask_texture_finer: texture_2d<f32>;
@group(0) @binding(13) var mask_texture_finest: texture_2d<f32>;
@group(0) @binding(9) var mask_sampler: sampler;
@group(0) @binding(5) var hdr: texture_storage_2d<rgba16float, write>;
// The LUT layer of this frame, (A, K): the pixel becomes A + K x the ghosts (a 1 x 1 texture when `lut` is 0).
@group(0) @binding(6) var lut_layer: texture_2d<f32>;

// ---- the aperture mask (ApertureMask::sample) ----

// A word of `mask`, or of `mask_texels`, which a software rasteriser reads (word_texels.wgsl): there a row of
// a level's table is one texel.
fn mask_quad(w: u32) -> u32 {
    if (GATHER_MASKS) {
        return mask[w];
    }
    return texel_at(mask_texels, w / 4u)[w % 4u];
}

// The level a stop map's last field names (1 the base; `GhostMasks::level`, clamped to the levels there are).
fn level_of(code: f32) -> u32 {
    return min(u32(max(code, 1.0)) - 1u, strip.mask_levels - 1u);
}

// Texels a side of level `level`.
fn level_size(level: u32) -> u32 {
    return strip.mask_size << level;
}

// The word of `mask` where level `level` starts (its table, then its footprints).
fn level_start(level: u32) -> u32 {
    if (level == 0u) {
        return strip.level_start0;
    }
    if (level == 1u) {
        return strip.level_start1;
    }
    return strip.level_start2;
}

// Band `band`'s row of level `level`'s table: (lo, hi) of u where the bilinear sample is exactly 1, and of u
// outside which it is 0.
fn mask_row(level: u32, band: u32) -> vec4<f32> {
    let at = level_start(level) + band * 4u;
    if (GATHER_MASKS) {
        return bitcast<vec4<f32>>(vec4<u32>(mask[at], mask[at + 1u], mask[at + 2u], mask[at + 3u]));
    }
    return bitcast<vec4<f32>>(texel_at(mask_texels, at / 4u));
}

fn mask_sample(u: f32, v: f32, level: u32) -> f32 {
    if (GATHER_MASKS) {
        return mask_gathered(u, v, level);
    }
    let n = level_size(level);
    return mask_bilinear(u, v, n, level_start(level) + (n + 1u) * 4u);
}

// `mask_bilinear` with the four texels fetched by one gather from the level's texture: the same texels (asked
// for at the corner they share, where the hardware's choice of footprint is unambiguous), turned back into
// 0..255, and the same `mask_spot` and `mask_mix` (mask_texels.wgsl), so the same value.
fn mask_gathered(u: f32, v: f32, level: u32) -> f32 {
    if (!(abs(u) <= 1.0 && abs(v) <= 1.0)) {
        return 0.0;
    }
    let n = level_size(level);
    let s = mask_spot(u, v, n);
    let corner = vec2<f32>(f32(s.x0) + 1.0, f32(s.y0) + 1.0) / f32(n);
    // Components: x (x0, y0 + 1), y (x0 + 1, y0 + 1), z (x0 + 1, y0), w (x0, y0).
    var g: vec4<f32>;
    if (level == 0u) {
        g = textureGather(0, mask_texture, mask_sampler, corner);
    } else if (level == 1u) {
        g = textureGather(0, mask_texture_finer, mask_sampler, corner);
    } else {
        g = textureGather(0, mask_texture_finest, mask_sampler, corner);
    }
    g = round(g * 255.0);
    return mask_mix(vec4<f32>(g.w, g.z, g.x, g.y), s);
}

// The band of level `level`'s mask rows a sample at v reads (MaskRows::at); -1 outside [-1, 1].
fn mask_band(v: f32, level: u32) -> i32 {
    if (!(abs(v) <= 1.0)) {
        return -1;
    }
    let y = (0.5 - v * 0.5) * f32(level_size(level)) - 0.5;
    let y0 = i32(y + 1.0) - 1;
    return max(y0 + 1, 0);
}

// ---- one fragment (ghosts.wgsl's fs_main) ----

fn stop_mask(map: vec4<f32>, scale_y: f32, q: vec2<f32>) -> f32 {
    if (map.w == 0.0) {
        return 1.0;
    }
    return mask_sample(map.x * q.x + map.y, scale_y * q.y + map.z, level_of(map.w));
}

// An anti-aliased unit disc: the coverage of a clear aperture (an anti-alias width of 0 marks an empty slot: 1).
fn disc_mask(map: vec4<f32>, scale_y: f32, q: vec2<f32>) -> f32 {
    if (map.w == 0.0) {
        return 1.0;
    }
    let x = map.x * q.x + map.y;
    let y = scale_y * q.y + map.z;
    let r = sqrt(x * x + y * y);
    return clamp(0.5 + (1.0 - r) / map.w, 0.0, 1.0);
}

// A stop map left out of a pixel's product (an off map: 1 everywhere).
const MAP_OFF = vec4<f32>(0.0);
// An open interval's bound where a mask does not narrow it (the CPU twin's `OPEN_FAR`).
const OPEN_FAR = 1.0e30;
// The bit of stop crossing 0 in a walk's live set (disc k is bit k).
const FIRST_STOP_BIT = 4u;

// The masks' product at q, only the masks of `live` evaluated (the CPU twin's `mask_product_of`): the others
// are exactly 1 at every pixel of the walk (`sprite_walk`), and a factor of 1 changes no bit of the product.
fn mask_product(inst: GhostInstance, q: vec2<f32>, live: u32) -> f32 {
    if (abs(q.x) > 1.0 || abs(q.y) > 1.0) {
        return 0.0;
    }
    // Constant indices, in the CPU twin's order (a software rasteriser keeps no array in memory).
    var m = 1.0;
    if ((live & 1u) != 0u) {
        m = m * disc_mask(inst.discs[0], inst.disc_scale_y.x, q);
    }
    if ((live & 2u) != 0u) {
        m = m * disc_mask(inst.discs[1], inst.disc_scale_y.y, q);
    }
    if ((live & 4u) != 0u) {
        m = m * disc_mask(inst.discs[2], inst.disc_scale_y.z, q);
    }
    if ((live & 8u) != 0u) {
        m = m * disc_mask(inst.discs[3], inst.disc_scale_y.w, q);
    }
    let stop0 = select(MAP_OFF, inst.stop0, (live & (1u << FIRST_STOP_BIT)) != 0u);
    let stop1 = select(MAP_OFF, inst.stop1, (live & (2u << FIRST_STOP_BIT)) != 0u);
    let stop2 = select(MAP_OFF, inst.stop2, (live & (4u << FIRST_STOP_BIT)) != 0u);
    if (GATHER_MASKS) {
        // Every lookup issued at once (a GPU waits on one fetch at a time otherwise); each factor is in
        // [0, 1], so a factor of 0 gives the 0 the early returns below give, and the products are taken in
        // their order: the same value.
        let s0 = stop_mask(stop0, inst.scale_y.x, q);
        let s1 = stop_mask(stop1, inst.scale_y.y, q);
        let s2 = stop_mask(stop2, inst.scale_y.z, q);
        return ((max(m, 0.0) * s0) * s1) * s2;
    }
    if (m <= 0.0) {
        return 0.0;
    }
    m = m * stop_mask(stop0, inst.scale_y.x, q);
    if (m <= 0.0) {
        return 0.0;
    }
    m = m * stop_mask(stop1, inst.scale_y.y, q);
    if (m <= 0.0) {
        return 0.0;
    }
    return m * stop_mask(stop2, inst.scale_y.z, q);
}

// ---- intervals of the quad coordinate q_x along a row ----

// `scale q + offset` within [-reach, reach] narrows [lo, hi] (row_support's clip); false when never.
fn clip_reach(span: ptr<function, vec2<f32>>, scale: f32, offset: f32, reach: f32) -> bool {
    if (scale == 0.0) {
        return abs(offset) <= reach;
    }
    let a = (-reach - offset) / scale;
    let b = (reach - offset) / scale;
    (*span).x = max((*span).x, min(a, b));
    (*span).y = min((*span).y, max(a, b));
    return true;
}

// `scale q + offset` within [u.x, u.y] narrows [lo, hi] (sweep_instance's clip): empty when u is.
fn clip_to(span: ptr<function, vec2<f32>>, scale: f32, offset: f32, u: vec2<f32>) {
    if (u.x > u.y) {
        *span = vec2<f32>(1.0, -1.0);
    } else if (scale == 0.0) {
        if (offset < u.x || offset > u.y) {
            *span = vec2<f32>(1.0, -1.0);
        }
    } else {
        let a = (u.x - offset) / scale;
        let b = (u.y - offset) / scale;
        (*span).x = max((*span).x, min(a, b));
        (*span).y = min((*span).y, max(a, b));
    }
}

fn stop_of(inst: GhostInstance, k: u32) -> vec4<f32> {
    if (k == 0u) {
        return inst.stop0;
    }
    if (k == 1u) {
        return inst.stop1;
    }
    return inst.stop2;
}

// ---- the atomic sum: two 32-bit words a channel, neither waiting for the other ----

// A step d (|d| <= 2^30 units: no sprite exceeds that) goes in as d = hi 2^k + lo with lo in [-2^(k-1), 2^(k-1)):
// lo to the low word, hi (0 for most steps) to the high word, each by an atomic whose result is not read, so
// no invocation waits on one. Integer sums do not depend on order, and the CPU side picks k and the unit so
// that neither word's sum can wrap (at most one step per sprite and column in a strip): `resolve` rebuilds the
// exact 64-bit sum as high 2^k + low.
fn atomic_add_split(word: u32, d: i32) {
    let k = strip.split_bits;
    let hi = (d + (1i << (k - 1u))) >> k;
    let lo = d - (hi << k);
    if (lo != 0i) {
        atomicAdd(&diff[word], bitcast<u32>(lo));
    }
    if (hi != 0i) {
        atomicAdd(&diff[word + 1u], bitcast<u32>(hi));
    }
}

// Adds F(x) - F(x - 1) for the three channels at column x of strip row `row`.
fn put(row: u32, x: u32, now: vec3<i32>, before: vec3<i32>) {
    let word = (row * (strip.width + 1u) + x) * 6u;
    let d = now - before;
    for (var c = 0u; c < 3u; c = c + 1u) {
        if (d[c] != 0i) {
            atomic_add_split(word + 2u * c, d[c]);
        }
    }
}

// The sprite's colour x m in fixed-point units, rounded (at most 2^30: the unit is chosen so).
fn fixed_colour(colour: vec4<f32>, m: f32) -> vec3<i32> {
    return vec3<i32>(round(colour.xyz * (m * strip.fixed_per_unit)));
}

// ---- the passes ----

// One (sprite, row) item's walk: the pixels `first..` up to the open span (`n_left` of them), the open span's
// first pixel (the sprite's colour), the pixels after it up to `last`, and `last` itself (0): `n` positions.
struct Walk {
    first: u32,
    last: u32,
    n_left: u32,
    n: u32,          // 0: the item draws nothing
    open_first: u32,
    right_first: u32,
    has_open: u32,   // 1: the row has an open span
    q_y: f32,
    sprite: u32,
    row: u32,        // the strip row
    live: u32,       // the masks its edge pixels evaluate (bits 0-3 the discs, 4-6 the stops; `mask_product`)
};

// Per item of the strip, its walk, worked out once by `walks_setup` (where `ComputeForm::setup_once`).
@group(0) @binding(11) var<storage, read_write> walks: array<Walk>;

// The column of position i of the walk.
fn walk_x(w: Walk, i: u32) -> u32 {
    if (i < w.n_left) {
        return w.first + i;
    }
    if (i == w.n - 1u) {
        return w.last;
    }
    if (i == w.n_left) {
        return w.open_first;
    }
    return w.right_first + (i - w.n_left - 1u);
}

// F at position i of the walk: the sprite's colour x its masks, in fixed-point units.
fn walk_value(inst: GhostInstance, w: Walk, i: u32) -> vec3<i32> {
    if (i == w.n - 1u) {
        return vec3<i32>(0i);
    }
    if (w.has_open == 1u && i == w.n_left) {
        return fixed_colour(inst.colour, 1.0);
    }
    let x = walk_x(w, i);
    let q = vec2<f32>(((f32(x) + 0.5) * strip.scale_x - inst.centre_half.x) / inst.centre_half.z, w.q_y);
    let m = mask_product(inst, q, w.live);
    if (m > 0.0) {
        return fixed_colour(inst.colour, m);
    }
    return vec3<i32>(0i);
}

// The walk of (sprite, row) item `item` of this strip (n = 0 where it draws nothing).
fn item_walk(item: u32) -> Walk {
    // The sprite whose items hold this one: the last k with items[k].x <= item.
    var lo = 0u;
    var hi = strip.instances;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (items[mid].x <= item) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return sprite_walk(instances[lo], lo, items[lo], item);
}

// The columns whose centres lie inside the open interval `open` of q by a pixel's margin: first, last (as f32).
fn open_columns(open: vec2<f32>, cx: f32, hx: f32, sx: f32) -> vec2<f32> {
    let a = (cx + open.x * hx) / sx - 0.5;
    let b = (cx + open.y * hx) / sx - 0.5;
    return vec2<f32>(ceil(min(a, b)) + 1.0, floor(max(a, b)) - 1.0);
}

// ---- one mask's intervals along a row (constant indices only: a software rasteriser keeps no array in memory) ----

// A disc's part of row_support: false when the row misses the disc (grown by its anti-alias half-width).
fn disc_support(span: ptr<function, vec2<f32>>, f: vec4<f32>, scale_y: f32, q_y: f32) -> bool {
    if (f.w == 0.0) {
        return true;
    }
    let reach = 1.0 + 0.5 * f.w;
    let fy = scale_y * q_y + f.z;
    return abs(fy) <= reach && clip_reach(span, f.x, f.y, sqrt(max(reach * reach - fy * fy, 0.0)));
}

// A disc's own open interval of q along the row (fully open within radius 1 - w / 2 of its centre): all of it
// (+-OPEN_FAR) for an empty slot, empty (x > y) where the row passes outside that radius.
fn disc_open(f: vec4<f32>, scale_y: f32, q_y: f32) -> vec2<f32> {
    var own = vec2<f32>(-OPEN_FAR, OPEN_FAR);
    if (f.w == 0.0) {
        return own;
    }
    let inner = 1.0 - 0.5 * f.w;
    let fy = scale_y * q_y + f.z;
    if (inner <= abs(fy)) {
        return vec2<f32>(1.0, -1.0);
    }
    let half_width = sqrt(inner * inner - fy * fy);
    clip_to(&own, f.x, f.y, vec2<f32>(-half_width, half_width));
    return own;
}

// A stop crossing's own intervals of q along the row, from the mask's row table: where it is exactly 1 (.xy)
// and where it is not 0 (.zw); all of it for an off map. `missed` is set where the row passes outside the mask.
struct StopRow {
    open: vec2<f32>,
    support: vec2<f32>,
    missed: bool,
};

fn stop_row(s: vec4<f32>, scale_y: f32, q_y: f32) -> StopRow {
    var open = vec2<f32>(-OPEN_FAR, OPEN_FAR);
    var support = open;
    if (s.w == 0.0) {
        return StopRow(open, support, false);
    }
    let level = level_of(s.w);
    let band = mask_band(scale_y * q_y + s.z, level);
    if (band < 0) {
        return StopRow(open, support, true);
    }
    let rows = mask_row(level, u32(band));
    clip_to(&open, s.x, s.y, rows.xy);
    clip_to(&support, s.x, s.y, rows.zw);
    return StopRow(open, support, false);
}

// `span` narrowed to `by` (clip_to's intersection; an empty `by` leaves it empty).
fn narrowed(span: vec2<f32>, by: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(max(span.x, by.x), min(span.y, by.y));
}

// `bit` when the mask whose own open interval is `own` is not exactly 1 at every column first..last - 1 (by the
// open span's pixel margin): its edge pixels must evaluate it.
fn live_bit(own: vec2<f32>, bit: u32, cx: f32, hx: f32, sx: f32, first: f32, last: f32) -> u32 {
    if (own.x < own.y) {
        let o = open_columns(own, cx, hx, sx);
        if (o.x <= first && o.y >= last - 1.0) {
            return 0u;
        }
    }
    return 1u << bit;
}

// The walk of item `item` of sprite `sprite` (`inst`), whose first item and first row are `start`.
fn sprite_walk(inst: GhostInstance, sprite: u32, start: vec2<u32>, item: u32) -> Walk {
    var walk: Walk;
    walk.n = 0u;
    let y = start.y + (item - start.x);
    let cx = inst.centre_half.x;
    let cy = inst.centre_half.y;
    let hx = inst.centre_half.z;
    let hy = inst.centre_half.w;
    let sx = strip.scale_x;
    let sy = strip.scale_y;
    let q_y = ((f32(y) + 0.5) * sy - cy) / hy;
    // row_support: where in this row the masks can be non-zero.
    if (abs(q_y) > 1.0) {
        return walk;
    }
    var support = vec2<f32>(-1.0, 1.0);
    if (!disc_support(&support, inst.discs[0], inst.disc_scale_y.x, q_y)
        || !disc_support(&support, inst.discs[1], inst.disc_scale_y.y, q_y)
        || !disc_support(&support, inst.discs[2], inst.disc_scale_y.z, q_y)
        || !disc_support(&support, inst.discs[3], inst.disc_scale_y.w, q_y)) {
        return walk;
    }
    for (var k = 0u; k < 3u; k = k + 1u) {
        let s = stop_of(inst, k);
        if (s.w != 0.0 && (abs(inst.scale_y[k] * q_y + s.z) > 1.0 || !clip_reach(&support, s.x, s.y, 1.0))) {
            return walk;
        }
    }
    if (support.x > support.y) {
        return walk;
    }
    // Each mask's own open interval; the open interval is where all are open, the support narrowed by where
    // each stop's mask is non-zero.
    let d0 = disc_open(inst.discs[0], inst.disc_scale_y.x, q_y);
    let d1 = disc_open(inst.discs[1], inst.disc_scale_y.y, q_y);
    let d2 = disc_open(inst.discs[2], inst.disc_scale_y.z, q_y);
    let d3 = disc_open(inst.discs[3], inst.disc_scale_y.w, q_y);
    let s0 = stop_row(inst.stop0, inst.scale_y.x, q_y);
    let s1 = stop_row(inst.stop1, inst.scale_y.y, q_y);
    let s2 = stop_row(inst.stop2, inst.scale_y.z, q_y);
    if (s0.missed || s1.missed || s2.missed) {
        return walk;
    }
    let open = narrowed(narrowed(narrowed(narrowed(narrowed(narrowed(narrowed(support, d0), d1), d2), d3), s0.open),
        s1.open), s2.open);
    support = narrowed(narrowed(narrowed(support, s0.support), s1.support), s2.support);
    if (support.x > support.y) {
        return walk;
    }
    // The sprite's columns (the rasteriser's coverage), then this row's.
    let col_lo = max(floor((cx - abs(hx)) / sx), 0.0);
    let col_hi = min(max(ceil((cx + abs(hx)) / sx), 0.0), f32(strip.width));
    let a = (cx + support.x * hx) / sx - 0.5;
    let b = (cx + support.y * hx) / sx - 0.5;
    let first = u32(max(floor(min(a, b)) - 1.0, col_lo));
    let last = u32(min(max(ceil(max(a, b)) + 2.0, 0.0), col_hi));
    var open_first = 0xffffffffu;
    var open_last = 0u;
    if (open.x < open.y) {
        let o = open_columns(open, cx, hx, sx);
        let o_lo = max(o.x, f32(first));
        let o_hi = min(o.y, f32(last) - 1.0);
        if (o_lo <= o_hi) {
            open_first = u32(o_lo);
            open_last = u32(o_hi);
        }
    }
    if (first >= last) {
        return walk;
    }
    // The live masks: those not open (by the same pixel's margin) at every column the row shades.
    let f = f32(first);
    let l = f32(last);
    walk.live = live_bit(d0, 0u, cx, hx, sx, f, l) | live_bit(d1, 1u, cx, hx, sx, f, l)
        | live_bit(d2, 2u, cx, hx, sx, f, l) | live_bit(d3, 3u, cx, hx, sx, f, l)
        | live_bit(s0.open, FIRST_STOP_BIT, cx, hx, sx, f, l) | live_bit(s1.open, FIRST_STOP_BIT + 1u, cx, hx, sx, f, l)
        | live_bit(s2.open, FIRST_STOP_BIT + 2u, cx, hx, sx, f, l);
    let has_open = open_first <= open_last;
    walk.first = first;
    walk.last = last;
    walk.has_open = select(0u, 1u, has_open);
    walk.open_first = open_first;
    walk.right_first = open_last + 1u;
    walk.n_left = select(last, open_first, has_open) - first;
    walk.n = walk.n_left + select(0u, 1u + last - walk.right_first, has_open) + 1u;
    walk.q_y = q_y;
    walk.sprite = sprite;
    walk.row = y - strip.first_row;
    return walk;
}

// Piece `piece` (of `strip.pieces`) of `walk`: its positions' steps put as F(i) - F(i - 1), F before the walk's
// first position being 0 (the value just before the piece is worked out once more).
fn walk_piece(inst: GhostInstance, walk: Walk, piece: u32) {
    let per = (walk.n + strip.pieces - 1u) / strip.pieces;
    let start = piece * per;
    let end = min(start + per, walk.n);
    if (start >= end) {
        return;
    }
    var before = vec3<i32>(0i);
    if (start > 0u) {
        before = walk_value(inst, walk, start - 1u);
    }
    for (var i = start; i < end; i = i + 1u) {
        let now = walk_value(inst, walk, i);
        put(walk.row, walk_x(walk, i), now, before);
        before = now;
    }
}

// One invocation a piece of an item: each of an item's pieces works the item out and walks its share.
@compute @workgroup_size(64)
fn spans(@builtin(global_invocation_id) gid: vec3<u32>) {
    let invocation = gid.y * strip.groups_x * 64u + gid.x;
    if (invocation < strip.items * strip.pieces) {
        let walk = item_walk(invocation / strip.pieces);
        walk_piece(instances[walk.sprite], walk, invocation % strip.pieces);
    }
}

// One workgroup a sprite, its invocations taking the sprite's items (rows) in turn, one invocation an item, in
// one piece (a software rasteriser: `ComputeForm::sprite_groups`). The sprite is read at the top, before any
// branch, from an index that is the same for the whole workgroup: lavapipe then loads each word once for its
// SIMD batch, where `spans` loads it lane by lane (and searches for the sprite first). Workgroup x draws sprite
// x * `spread` mod sprites (`spread` coprime with the sprites): lavapipe hands each thread a contiguous run of
// workgroups, and in the sprites' own order (ghost by ghost, the large ones together) one thread worked 30%
// longer than the other.
@compute @workgroup_size(64)
fn spans_sprites(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let raw = wid.y * groups.x + wid.x;
    let sprite = select(raw, (raw * strip.spread) % max(strip.instances, 1u), raw < strip.instances);
    let k = min(sprite, max(strip.instances, 1u) - 1u);
    let inst = instances[k];
    let first = items[k];
    let end = select(first.x, items[k + 1u].x, sprite < strip.instances);
    for (var item = first.x + t; item < end; item = item + 64u) {
        walk_piece(inst, sprite_walk(inst, k, first, item), 0u);
    }
}

// Each item worked out once, one invocation an item, into `walks` (for `spans_walks`).
@compute @workgroup_size(64)
fn walks_setup(@builtin(global_invocation_id) gid: vec3<u32>) {
    let item = gid.y * strip.groups_x * 64u + gid.x;
    if (item < strip.items) {
        walks[item] = item_walk(item);
    }
}

// `spans` with each item's walk read from `walks`.
@compute @workgroup_size(64)
fn spans_walks(@builtin(global_invocation_id) gid: vec3<u32>) {
    let invocation = gid.y * strip.groups_x * 64u + gid.x;
    if (invocation < strip.items * strip.pieces) {
        let walk = walks[invocation / strip.pieces];
        walk_piece(instances[walk.sprite], walk, invocation % strip.pieces);
    }
}


// ---- the per-row sum ----

// The sums (`Sums`, `add_sums`, `float_sums`) and the workgroup's scan (`scan_chunk`) come from scan64.wgsl.

// The sums of steps in a column's six words (per channel: low, high), each high 2^k + low.
fn load_column(at: u32) -> Sums {
    let lo = bitcast<vec3<i32>>(vec3<u32>(columns[at], columns[at + 2u], columns[at + 4u]));
    let hi = bitcast<vec3<i32>>(vec3<u32>(columns[at + 1u], columns[at + 3u], columns[at + 5u]));
    let k = strip.split_bits;
    let shifted = Sums(bitcast<vec3<u32>>(hi) << vec3<u32>(k), bitcast<vec3<u32>>(hi >> vec3<u32>(32u - k)));
    let low = Sums(bitcast<vec3<u32>>(lo), select(vec3<u32>(0u), vec3<u32>(0xffffffffu), lo < vec3<i32>(0i)));
    return add_sums(shifted, low);
}

// A channel's sum of steps from its two words (low, high), high 2^k + low: `load_column` for one channel
// (`resolve_rows`).
fn join64(lo_word: u32, hi_word: u32) -> vec2<u32> {
    let lo = bitcast<i32>(lo_word);
    let hi = bitcast<i32>(hi_word);
    let k = strip.split_bits;
    let shifted = vec2<u32>(bitcast<u32>(hi) << k, bitcast<u32>(hi >> (32u - k)));
    return add64(shifted, vec2<u32>(bitcast<u32>(lo), select(0u, 0xffffffffu, lo < 0i)));
}

// Zeroes a column's six words for the next strip.
fn clear_column(at: u32) {
    for (var w = at; w < at + 6u; w = w + 1u) {
        columns[w] = 0u;
    }
}

// Writes the sums `acc` of row `row`'s columns up to x into the HDR texture (`float_sums` of scan64.wgsl,
// times the unit; the LUT layer applied where the frame has one).
fn write_pixel(row: u32, x: u32, acc: Sums) {
    store_pixel(row, x, float_sums(acc) * strip.unit_per_fixed);
}

// Writes the irradiance `rgb` at pixel x of strip row `row` (the LUT layer applied where the frame has one).
fn store_pixel(row: u32, x: u32, rgb: vec3<f32>) {
    var value = vec4<f32>(rgb, 0.0);
    if (strip.lut == 1u) {
        let layer = textureLoad(lut_layer, vec2<u32>(x, strip.first_row + row), 0);
        value = vec4<f32>(layer.rgb + layer.a * value.rgb, 0.0);
    }
    textureStore(hdr, vec2<u32>(x, strip.first_row + row), value);
}

// `resolve` for a software rasteriser (lavapipe): one invocation a strip row, summing it column by column,
// each column's words read once (and cleared for the next strip), no workgroup barrier. Neighbouring
// invocations are neighbouring rows; lavapipe loads a storage word lane by lane anyway. On lavapipe at 480x320
// (the Nikon zoom) the pass took 7 ms by timestamps against 28 ms for a workgroup a row, each invocation a run
// of columns (each column read twice: its run's sum, then the running sums; a barrier between), and the whole
// frame 155 against 180 ms. The same sums as `resolve`, kept as a (low, high) pair a channel: with `Sums` and
// `load_column` the pass took 9.2-10.5 ms against 6.8-7.9 ms on lavapipe (three runs each, this machine).
@compute @workgroup_size(8)
fn resolve_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let row = gid.x;
    if (row >= strip.rows) {
        return;
    }
    let base = row * (strip.width + 1u) * 6u;
    var acc = array<vec2<u32>, 3>(vec2<u32>(0u), vec2<u32>(0u), vec2<u32>(0u));
    for (var x = 0u; x < strip.width; x = x + 1u) {
        let at = base + x * 6u;
        for (var c = 0u; c < 3u; c = c + 1u) {
            acc[c] = add64(acc[c], join64(columns[at + 2u * c], columns[at + 2u * c + 1u]));
        }
        let u = strip.unit_per_fixed;
        store_pixel(row, x, vec3<f32>(float64(acc[0]) * u, float64(acc[1]) * u, float64(acc[2]) * u));
        clear_column(at);
    }
    // The row's last column (written by `spans` at a sprite's right end, never read).
    clear_column(base + strip.width * 6u);
}

// ---- the per-row sum in chunks of 256 columns (hardware GPUs) ----

// One workgroup of 256 per strip row, walking it in chunks of 256 columns, one column an invocation
// (neighbouring invocations read neighbouring words): each chunk's sums are scanned by `scan_chunk` and added
// to the sum of the chunks before it; each invocation writes its pixel and clears its column's words for the
// next strip. Plain loads and stores: the atomics of `spans` are done (a pass boundary lies between). On an
// H200 at 4K: 0.44 ms (0.12 ms at 1920x1080). The same scan with the sums as arrays of three (low, high) pairs
// took 0.78 ms, and without its loads, clears and texture stores still 0.68 ms (a development build; with
// nothing in it 0.01 ms): the arrays, not the memory, were the cost. Tried and not kept: two columns an
// invocation (0.65 ms); the scan by subgroup operations, two barriers a chunk (0.92 ms; with the chunk staged
// through workgroup memory 2.38 ms); a subgroup a row, no barrier (1.03 ms); every chunk of every row at once
// (1.13 ms, arrays); workgroups of 64 (0.85 ms, arrays).
@compute @workgroup_size(256)
fn resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let row = wid.x;
    let base = row * (strip.width + 1u) * 6u;
    var before = no_sums();
    for (var x0 = 0u; x0 < strip.width; x0 = x0 + CHUNK) {
        let x = x0 + t;
        var column = no_sums();
        if (x < strip.width) {
            column = load_column(base + x * 6u);
        }
        let acc = add_sums(before, scan_chunk(t, column));
        if (x < strip.width) {
            write_pixel(row, x, acc);
            clear_column(base + x * 6u);
        }
        before = add_sums(before, chunk[CHUNK - 1u]);
        workgroupBarrier();
    }
    if (t < 6u) {
        columns[base + strip.width * 6u + t] = 0u;
    }
}
