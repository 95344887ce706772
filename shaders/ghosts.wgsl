// Ghost sprites: one instanced quad per (ghost, wavelength), additively blended into the HDR target.
// CPU twin: crates/flare_core/src/render/cpu/ghosts.rs, `ghost_pass` (same names, same steps).
// Must be kept in sync with `GhostInstance` in crates/flare_core/src/render/mod.rs (the uniforms `Globals`
// come from common.wgsl).

struct GhostInstance {
    @location(0) centre_half: vec4<f32>, // centre x, y (pixels); half-size x, y (pixels, signed: q -> pixel)
    @location(1) colour: vec4<f32>,      // linear RGB irradiance
    @location(2) stop0: vec4<f32>,       // aperture map of stop crossing 0: scale, offset x, offset y, level (0: off)
    @location(3) stop1: vec4<f32>,
    @location(4) stop2: vec4<f32>,
    @location(5) scale_y: vec4<f32>,     // the y scales of stop0..2 (.x above: x; equal when round); .w unused
    @location(6) disc0: vec4<f32>,       // clear-aperture disc maps: scale, offset x, offset y, anti-alias width
    @location(7) disc1: vec4<f32>,       // (0: no disc)
    @location(8) disc2: vec4<f32>,
    @location(9) disc3: vec4<f32>,
    @location(10) disc_scale_y: vec4<f32>, // the y scales of disc0..3
};

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) q: vec2<f32>,
    @location(1) colour: vec4<f32>,
    @location(2) stop0: vec4<f32>,
    @location(3) stop1: vec4<f32>,
    @location(4) stop2: vec4<f32>,
    @location(5) scale_y: vec4<f32>,
    @location(6) disc0: vec4<f32>,
    @location(7) disc1: vec4<f32>,
    @location(8) disc2: vec4<f32>,
    @location(9) disc3: vec4<f32>,
    @location(10) disc_scale_y: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var aperture_texture: texture_2d<f32>;
@group(0) @binding(2) var aperture_sampler: sampler;
// The finer levels of the mask (`GhostMasks`: twice and four times the base's texels), named by a stop map's
// level 2 and 3.
@group(0) @binding(3) var aperture_finer: texture_2d<f32>;
@group(0) @binding(4) var aperture_finest: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, instance: GhostInstance) -> VertexOut {
    // Two triangles over q in [-1, 1]^2.
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let q = corners[vertex];
    let pixel = instance.centre_half.xy + instance.centre_half.zw * q;
    let ndc = vec2<f32>(pixel.x * globals.inv_viewport_px.x * 2.0 - 1.0, 1.0 - pixel.y * globals.inv_viewport_px.y * 2.0);
    var out: VertexOut;
    out.position = vec4<f32>(ndc, 0.0, 1.0);
    out.q = q;
    out.colour = instance.colour;
    out.stop0 = instance.stop0;
    out.stop1 = instance.stop1;
    out.stop2 = instance.stop2;
    out.scale_y = instance.scale_y;
    out.disc0 = instance.disc0;
    out.disc1 = instance.disc1;
    out.disc2 = instance.disc2;
    out.disc3 = instance.disc3;
    out.disc_scale_y = instance.disc_scale_y;
    return out;
}

fn stop_mask(map: vec4<f32>, scale_y: f32, q: vec2<f32>) -> f32 {
    if (map.w == 0.0) {
        return 1.0;
    }
    let uv = vec2<f32>(map.x, scale_y) * q + map.yz;
    if (map.w < 1.5) {
        return aperture_at(uv);
    }
    if (map.w < 2.5) {
        return aperture_in(aperture_finer, uv);
    }
    return aperture_in(aperture_finest, uv);
}

// Anti-aliased unit disc: coverage of a clear aperture (an anti-alias width of 0 marks an empty slot: 1).
fn disc_mask(map: vec4<f32>, scale_y: f32, q: vec2<f32>) -> f32 {
    if (map.w == 0.0) {
        return 1.0;
    }
    let r = length(vec2<f32>(map.x, scale_y) * q + map.yz);
    return clamp(0.5 + (1.0 - r) / map.w, 0.0, 1.0);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // The discs first: outside one nothing passes, and the aperture lookups are skipped.
    let discs = disc_mask(in.disc0, in.disc_scale_y.x, in.q) * disc_mask(in.disc1, in.disc_scale_y.y, in.q)
        * disc_mask(in.disc2, in.disc_scale_y.z, in.q) * disc_mask(in.disc3, in.disc_scale_y.w, in.q);
    if (discs <= 0.0) {
        return vec4<f32>(0.0);
    }
    let mask = discs * stop_mask(in.stop0, in.scale_y.x, in.q) * stop_mask(in.stop1, in.scale_y.y, in.q)
        * stop_mask(in.stop2, in.scale_y.z, in.q);
    return vec4<f32>(in.colour.rgb * mask, 0.0);
}
