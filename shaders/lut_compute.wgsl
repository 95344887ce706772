// LUT ghosts as compute: every accumulation pixel samples the LUT instances binned to its tile, in the frame's
// order, and writes once. CPU twin: crates/flare_core/src/lut/blend.rs, `lut_pass` (the same instances, the same
// order per pixel). Must be kept in sync with `LutInstance` in crates/flare_core/src/lut/blend.rs and `LutTiles` in
// crates/flare_core/src/render/gpu_lut.rs.
//
// How it works. The CPU bins each instance into the square tiles its lit texels can reach
// (`lut::blend::bin_instances`). One invocation per pixel walks its tile's list: q = the instance's inverse map of
// the pixel centre, outside the quad nothing, else the atlas sampled as the raster pass sampled it. The pass does
// not read the ghosts: it writes what the LUT layer does to any accumulation beneath it, (A, K) with
// `out = A + K x under`: added, A is the sum of the instances and K is 1; composited over through alpha, each
// instance i makes A = lut_i + (1 - alpha_i) A and K = (1 - alpha_i) K. The ghost pass's `resolve` applies it as it
// writes each pixel, so the accumulation is written once.
//
// An instance magnified enough is sampled coarsely (`lut::blend::instance_levels`, its level in
// `axis_y_page.w`): the CPU draws it every 2^level pixels into a smaller image and adds that image's bilinear
// upsample; here each pixel samples the instance at the four coarse pixel centres around it (indices clamped at
// the edges as the CPU's `add_upsampled` does) and interpolates them with the same weights. Levels above 0 are
// only used when the instances are added.
//
// An instance's `rect` is the atlas rectangle of the mip level it is drawn from (`LutScene::choose_mips`): the
// same window of the sensor at the level's texels, so nothing here depends on the level.

struct LutInstance {
    centre_axis_x: vec4<f32>, // quad centre (image pixels); pixels per unit q.x
    axis_y_page: vec4<f32>,   // pixels per unit q.y; atlas page; sampling level (0: every pixel)
    rect: vec4<f32>,          // the entry in its page: u0, v0, u1, v1
    colour: vec4<f32>,        // RGB gain, alpha gain
};

struct LutTiles {
    width: u32,       // the accumulation (pixels)
    height: u32,
    tile: u32,        // pixels a side of a tile, tiles across
    tiles_x: u32,
    scale_x: f32,     // image pixels per accumulation pixel
    scale_y: f32,
    alpha_over: u32,  // 1: composited over through alpha
    unused: u32,
};

@group(0) @binding(0) var<uniform> tiles: LutTiles;
@group(0) @binding(1) var<storage, read> instances: array<LutInstance>;
// Per tile, where its list starts; then the list's length. Then the lists.
@group(0) @binding(2) var<storage, read> bins: array<u32>;
@group(0) @binding(3) var atlas: texture_2d_array<f32>;
@group(0) @binding(4) var atlas_sampler: sampler;
@group(0) @binding(5) var layer: texture_storage_2d<rgba16float, write>;

// The instance's texel at the image pixel position p (RGBA, before its colour), and whether p is in its quad.
fn sample_instance(inst: LutInstance, p: vec2<f32>) -> vec4<f32> {
    let c = inst.centre_axis_x.xy;
    let ax = inst.centre_axis_x.zw;
    let ay = inst.axis_y_page.xy;
    let det = ax.x * ay.y - ay.x * ax.y;
    let d = p - c;
    let q = vec2<f32>(ay.y * d.x - ay.x * d.y, ax.x * d.y - ax.y * d.x) / det;
    if (!(abs(q.x) <= 1.0 && abs(q.y) <= 1.0)) {
        return vec4<f32>(0.0);
    }
    let st = q * 0.5 + vec2<f32>(0.5);
    let uv = mix(inst.rect.xy, inst.rect.zw, st);
    return textureSampleLevel(atlas, atlas_sampler, uv, i32(inst.axis_y_page.z), 0.0);
}

// The two clamped coarse indices around accumulation pixel `x` at `k` pixels a sample, and the fraction.
fn coarse_at(x: u32, k: f32, n: u32) -> vec3<f32> {
    let u = (f32(x) + 0.5) / k - 0.5;
    let i = floor(u);
    let last = f32(n) - 1.0;
    return vec3<f32>(clamp(i, 0.0, last), clamp(i + 1.0, 0.0, last), u - i);
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
    for (var k = bins[t]; k < bins[t + 1u]; k = k + 1u) {
        let inst = instances[bins[lists + k]];
        let level = u32(inst.axis_y_page.w);
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
        let rgb = texel.rgb * inst.colour.rgb;
        if (tiles.alpha_over == 1u) {
            let through = 1.0 - clamp(texel.a * inst.colour.a, 0.0, 1.0);
            add = rgb + add * through;
            keep = keep * through;
        } else {
            add = add + rgb;
        }
    }
    textureStore(layer, vec2<u32>(gid.x, gid.y), vec4<f32>(add, keep));
}
