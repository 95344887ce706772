// The app's viewport: the tonemapped flare texture drawn into egui's render pass (src/viewport.rs).
// One triangle covers the callback's viewport; egui sets the viewport and scissor to the widget's rect.
// CPU twin: none needed, this pass only resamples; `encode_srgb` mirrors flare_core's tonemap encoding.

struct Params {
    // 1 when egui's target is not an sRGB format (encode here), else 0.
    encode_srgb: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var flare_texture: texture_2d<f32>;
@group(0) @binding(1) var flare_sampler: sampler;
@group(0) @binding(2) var<uniform> params: Params;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VertexOut {
    let x = f32((index << 1u) & 2u);
    let y = f32(index & 2u);
    var out: VertexOut;
    out.position = vec4<f32>(x * 2.0 - 1.0, 1.0 - y * 2.0, 0.0, 1.0);
    out.uv = vec2<f32>(x, y);
    return out;
}

fn encode_srgb(c: vec3<f32>) -> vec3<f32> {
    let low = c * 12.92;
    let high = 1.055 * pow(max(c, vec3<f32>(0.0)), vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let linear = textureSample(flare_texture, flare_sampler, in.uv).rgb;
    let rgb = select(linear, encode_srgb(linear), params.encode_srgb != 0u);
    return vec4<f32>(rgb, 1.0);
}
