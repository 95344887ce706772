// LUT ghosts as compute: every accumulation pixel samples the LUT instances binned to its tile, in the frame's
// order, and writes once. CPU twin: crates/flare_core/src/lut/blend.rs, `lut_pass` (the same instances, the same
// order per pixel). Must be kept in sync with `LutInstance` in crates/flare_core/src/lut/blend.rs and with
// `TiledInstance` and `LutTiles` in crates/flare_core/src/render/gpu_lut.rs.
//
// How it works. The CPU bins each instance into the square tiles its lit texels can reach
// (`lut::blend::bin_instances`). One invocation per pixel walks its tile's list: q = the instance's inverse map of
// the pixel centre, outside the quad nothing, else the atlas sampled as the raster pass sampled it. The pass does
// not read the ghosts: it writes what the LUT layer does to any accumulation beneath it, (A, K) with
// `out = A + K x under`: added, A is the sum of the instances and K is 1; composited over through alpha, each run
// of consecutive instances of one LUT ghost (its interpolated entries, and under motion blur its time samples) is
// summed first, colour S and coverage a, then makes A = S + (1 - a) A and K = (1 - a) K (the CPU's
// `composite_runs`). The ghost pass's `resolve` applies it as it writes each pixel, so the accumulation is written
// once.
//
// An instance magnified enough is sampled coarsely (`lut::blend::instance_levels`, its `level`): the CPU draws it every 2^level pixels into a smaller image and adds that image's bilinear
// upsample, and so does the GPU where it can bind those images (`coarse_images` 1): `lut_coarse` draws each
// coarse level's instances, in the frame's order, at the centres of that level's pixels (one invocation a
// coarse pixel, the list of the tile holding its centre) into `coarse`, and `lut_tiles` adds each level's
// bilinear upsample (indices clamped at the edges, the weights of the CPU's `add_upsampled`). At 4K the default
// bake's instances are mostly level 2, about 22 of them over a pixel: one sample a coarse pixel instead of four a
// pixel. Where the images cannot be bound (`coarse_images` 0), each pixel samples each coarse instance at the
// four coarse pixel centres around it and interpolates them with the same weights. Levels above 0 are only
// used when the instances are added.
//
// An instance's `rect` is the atlas rectangle of the mip level it is drawn from (`LutScene::choose_mips`): the
// same window of the sensor at the level's texels, so nothing here depends on the level.

struct TiledInstance {
    centre_axis_x: vec4<f32>, // quad centre (image pixels); pixels per unit q.x
    axis_y: vec2<f32>,        // pixels per unit q.y
    page: u32,                // the atlas page that holds the entry
    _pad0: u32,
    rect: vec4<f32>,          // the entry in its page: u0, v0, u1, v1
    colour: vec4<f32>,        // RGB gain, alpha gain
    level: u32,               // sampled every 2^level pixels (0: every pixel)
    ghost: u32,               // the LUT ghost: through alpha, a run of one ghost's instances is laid over at once
    unused0: u32,
    unused1: u32,
};

struct LutTiles {
    width: u32,       // the accumulation (pixels)
    height: u32,
    tile: u32,        // pixels a side of a tile, tiles across
    tiles_x: u32,
    scale_x: f32,     // image pixels per accumulation pixel
    scale_y: f32,
    alpha_over: u32,  // 1: composited over through alpha
    coarse_images: u32, // bit L (1, 2): level L's instances are drawn into `coarse` and upsampled from it
};

@group(0) @binding(0) var<uniform> tiles: LutTiles;
@group(0) @binding(1) var<storage, read> instances: array<TiledInstance>;
// Per tile, where its list starts; then the lists' total length. Then the lists (per tile its instances of
// level 0, then level 1, then level 2, each in the frame's order). Then per tile where its level 1 and its
// level 2 instances start.
@group(0) @binding(2) var<storage, read> bins: array<u32>;
@group(0) @binding(3) var atlas: texture_2d_array<f32>;
@group(0) @binding(4) var atlas_sampler: sampler;
@group(0) @binding(5) var layer: texture_storage_2d<rgba16float, write>;
// The coarse levels' images (RGB, the fourth float unused), level 1 then level 2, rows from the top: level L is
// ceil(width / 2^L) x ceil(height / 2^L) pixels.
@group(0) @binding(6) var<storage, read_write> coarse: array<vec4<f32>>;

// Tile t's run of list entries [x, y) of instances of sampling level `level` (0, 1, 2), or of every level.
fn tile_run(t: u32, level: u32) -> vec2<u32> {
    let tiles_total = (tiles.width + tiles.tile - 1u) / tiles.tile * ((tiles.height + tiles.tile - 1u) / tiles.tile);
    let lists = tiles_total + 1u;
    let splits = lists + bins[tiles_total] + 2u * t;
    let first = bins[t];
    let end = bins[t + 1u];
    if (level == 0u) {
        return vec2<u32>(first, bins[splits]);
    }
    if (level == 1u) {
        return vec2<u32>(bins[splits], bins[splits + 1u]);
    }
    if (level == 2u) {
        return vec2<u32>(bins[splits + 1u], end);
    }
    return vec2<u32>(first, end);
}

// The size of coarse level `level` and where its pixels start in `coarse`.
fn coarse_size(level: u32) -> vec2<u32> {
    let step = 1u << level;
    return vec2<u32>((tiles.width + step - 1u) / step, (tiles.height + step - 1u) / step);
}

fn coarse_start(level: u32) -> u32 {
    if (level == 1u) {
        return 0u;
    }
    let one = coarse_size(1u);
    return one.x * one.y;
}

// The instance's texel at the image pixel position p (RGBA, before its colour), and whether p is in its quad.
fn sample_instance(inst: TiledInstance, p: vec2<f32>) -> vec4<f32> {
    let c = inst.centre_axis_x.xy;
    let ax = inst.centre_axis_x.zw;
    let ay = inst.axis_y;
    let det = ax.x * ay.y - ay.x * ax.y;
    let d = p - c;
    let q = vec2<f32>(ay.y * d.x - ay.x * d.y, ax.x * d.y - ax.y * d.x) / det;
    if (!(abs(q.x) <= 1.0 && abs(q.y) <= 1.0)) {
        return vec4<f32>(0.0);
    }
    let st = q * 0.5 + vec2<f32>(0.5);
    let uv = mix(inst.rect.xy, inst.rect.zw, st);
    return textureSampleLevel(atlas, atlas_sampler, uv, i32(inst.page), 0.0);
}

// The two clamped coarse indices around accumulation pixel `x` at `k` pixels a sample, and the fraction.
fn coarse_at(x: u32, k: f32, n: u32) -> vec3<f32> {
    let u = (f32(x) + 0.5) / k - 0.5;
    let i = floor(u);
    let last = f32(n) - 1.0;
    return vec3<f32>(clamp(i, 0.0, last), clamp(i + 1.0, 0.0, last), u - i);
}

// One pixel of coarse level gid.z + 1: the level's instances on its tile's list (the tile holding the pixel's
// centre), sampled at that centre, in the frame's order (the CPU's `draw_level` into the smaller image).
@compute @workgroup_size(8, 8)
fn lut_coarse(@builtin(global_invocation_id) gid: vec3<u32>) {
    let level = gid.z + 1u;
    let size = coarse_size(level);
    if ((tiles.coarse_images & (1u << level)) == 0u || gid.x >= size.x || gid.y >= size.y) {
        return;
    }
    let step = 1u << level;
    let kf = f32(step);
    let scale = vec2<f32>(tiles.scale_x, tiles.scale_y);
    let centre = min(gid.xy * step + vec2<u32>(step / 2u), vec2<u32>(tiles.width - 1u, tiles.height - 1u));
    let t = (centre.y / tiles.tile) * tiles.tiles_x + centre.x / tiles.tile;
    let lists = (tiles.width + tiles.tile - 1u) / tiles.tile * ((tiles.height + tiles.tile - 1u) / tiles.tile) + 1u;
    let p = (vec2<f32>(gid.xy) + 0.5) * kf * scale;
    var add = vec3<f32>(0.0);
    let run = tile_run(t, level);
    for (var k = run.x; k < run.y; k = k + 1u) {
        let inst = instances[bins[lists + k]];
        add = add + sample_instance(inst, p).rgb * inst.colour.rgb;
    }
    coarse[coarse_start(level) + gid.y * size.x + gid.x] = vec4<f32>(add, 0.0);
}

// Coarse level `level`'s image, bilinearly upsampled at accumulation pixel `at` (`add_upsampled`).
fn upsampled(level: u32, at: vec2<u32>) -> vec3<f32> {
    let size = coarse_size(level);
    let start = coarse_start(level);
    let kf = f32(1u << level);
    let cx = coarse_at(at.x, kf, size.x);
    let cy = coarse_at(at.y, kf, size.y);
    let top_row = start + u32(cy.x) * size.x;
    let bottom_row = start + u32(cy.y) * size.x;
    let top = coarse[top_row + u32(cx.x)].rgb * (1.0 - cx.z) + coarse[top_row + u32(cx.y)].rgb * cx.z;
    let bottom = coarse[bottom_row + u32(cx.x)].rgb * (1.0 - cx.z) + coarse[bottom_row + u32(cx.y)].rgb * cx.z;
    return top * (1.0 - cy.z) + bottom * cy.z;
}

@compute @workgroup_size(8, 8)
fn lut_tiles(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= tiles.width || gid.y >= tiles.height) {
        return;
    }
    let t = (gid.y / tiles.tile) * tiles.tiles_x + gid.x / tiles.tile;
    let lists = (tiles.width + tiles.tile - 1u) / tiles.tile * ((tiles.height + tiles.tile - 1u) / tiles.tile) + 1u;
    let scale = vec2<f32>(tiles.scale_x, tiles.scale_y);
    let p = (vec2<f32>(gid.xy) + 0.5) * scale;
    var add = vec3<f32>(0.0);
    var keep = 1.0;
    // Through alpha: the run of one ghost's instances being summed (colour, coverage) and its ghost.
    var run_sum = vec4<f32>(0.0);
    var run_ghost = 0xffffffffu;
    // With the coarse images, the tile's level 0 instances alone (the others are drawn by `lut_coarse` and
    // added below); else every instance of the tile.
    let run = tile_run(t, select(3u, 0u, tiles.coarse_images != 0u));
    for (var k = run.x; k < run.y; k = k + 1u) {
        let inst = instances[bins[lists + k]];
        let level = inst.level;
        if (level > 0u) {
            // Sampled coarsely: the bilinear upsample of the samples at the four coarse pixel centres around.
            let step = 1u << level;
            let kf = f32(step);
            let cx = coarse_at(gid.x, kf, (tiles.width + step - 1u) / step);
            let cy = coarse_at(gid.y, kf, (tiles.height + step - 1u) / step);
            let s00 = sample_instance(inst, (vec2<f32>(cx.x, cy.x) + 0.5) * kf * scale).rgb;
            let s10 = sample_instance(inst, (vec2<f32>(cx.y, cy.x) + 0.5) * kf * scale).rgb;
            let s01 = sample_instance(inst, (vec2<f32>(cx.x, cy.y) + 0.5) * kf * scale).rgb;
            let s11 = sample_instance(inst, (vec2<f32>(cx.y, cy.y) + 0.5) * kf * scale).rgb;
            let top = s00 * (1.0 - cx.z) + s10 * cx.z;
            let bottom = s01 * (1.0 - cx.z) + s11 * cx.z;
            add = add + (top * (1.0 - cy.z) + bottom * cy.z) * inst.colour.rgb;
            continue;
        }
        let texel = sample_instance(inst, p);
        if (tiles.alpha_over == 1u) {
            if (inst.ghost != run_ghost) {
                let through = 1.0 - clamp(run_sum.a, 0.0, 1.0);
                add = run_sum.rgb + add * through;
                keep = keep * through;
                run_sum = vec4<f32>(0.0);
                run_ghost = inst.ghost;
            }
            run_sum = texel * inst.colour + run_sum;
        } else {
            add = add + texel.rgb * inst.colour.rgb;
        }
    }
    if (tiles.alpha_over == 1u) {
        let through = 1.0 - clamp(run_sum.a, 0.0, 1.0);
        add = run_sum.rgb + add * through;
        keep = keep * through;
    }
    for (var level = 1u; level <= 2u; level = level + 1u) {
        if ((tiles.coarse_images & (1u << level)) != 0u) {
            add = add + upsampled(level, gid.xy);
        }
    }
    textureStore(layer, vec2<u32>(gid.x, gid.y), vec4<f32>(add, keep));
}
