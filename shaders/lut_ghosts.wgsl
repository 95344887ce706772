// LUT ghosts: one instanced quad per LUT entry drawn this frame, sampling the entry's image in the atlas.
// CPU twin: crates/flare_core/src/lut/blend.rs, `lut_pass` (same names, same steps).
// Must be kept in sync with `LutInstance` in crates/flare_core/src/lut/blend.rs (the uniforms `Globals` come
// from common.wgsl).
// Drawn after the paraxial ghosts into the same HDR target: added (blend One, One) or, in the alpha blend mode,
// composited over them (blend One, OneMinusSrcAlpha).

struct LutInstance {
    @location(0) centre_axis_x: vec4<f32>, // quad centre (pixels); pixels per unit q.x
    @location(1) axis_y: vec2<f32>,        // pixels per unit q.y
    @location(4) page: u32,                // the atlas page that holds the entry
    @location(5) _pad0: u32,
    @location(2) rect: vec4<f32>,          // the entry in its page: u0, v0, u1, v1
    @location(3) colour: vec4<f32>,        // RGB gain, alpha gain
};

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) q: vec2<f32>,
    @location(1) @interpolate(flat) page: i32,
    @location(2) rect: vec4<f32>,
    @location(3) colour: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var atlas: texture_2d_array<f32>;
@group(0) @binding(2) var atlas_sampler: sampler;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, instance: LutInstance) -> VertexOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let q = corners[vertex];
    let pixel = instance.centre_axis_x.xy + instance.centre_axis_x.zw * q.x + instance.axis_y * q.y;
    let ndc = vec2<f32>(pixel.x * globals.inv_viewport_px.x * 2.0 - 1.0, 1.0 - pixel.y * globals.inv_viewport_px.y * 2.0);
    var out: VertexOut;
    out.position = vec4<f32>(ndc, 0.0, 1.0);
    out.q = q;
    out.page = i32(instance.page);
    out.rect = instance.rect;
    out.colour = instance.colour;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let st = in.q * 0.5 + vec2<f32>(0.5);
    let uv = mix(in.rect.xy, in.rect.zw, st);
    let t = textureSampleLevel(atlas, atlas_sampler, uv, in.page, 0.0);
    return vec4<f32>(t.rgb * in.colour.rgb, clamp(t.a * in.colour.a, 0.0, 1.0));
}
