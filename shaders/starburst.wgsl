// The starburst: the aperture's diffraction texture on a quad centred on the light's image, additive.
// CPU twin: crates/flare_core/src/render/cpu/starburst.rs, `starburst_pass`.
// The uniforms `Globals` come from common.wgsl, prepended when the shader is embedded.

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) tex: vec2<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var starburst_texture: texture_2d<f32>;
@group(0) @binding(2) var starburst_sampler: sampler;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> VertexOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let q = corners[vertex];
    let pixel = globals.starburst.xy + globals.starburst.z * q;
    var out: VertexOut;
    out.position = vec4<f32>(pixel.x * globals.viewport.z * 2.0 - 1.0, 1.0 - pixel.y * globals.viewport.w * 2.0, 0.0, 1.0);
    out.tex = q * 0.5 + 0.5;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let c = textureSampleLevel(starburst_texture, starburst_sampler, in.tex, 0.0).rgb;
    return vec4<f32>(c * globals.starburst.w, 0.0);
}
