// HDR to display: the composite flare * 2^flare_ev (accumulation upsampled) + plate * 2^plate_ev, then the
// tonemap (none / Reinhard / ACES filmic) and sRGB encoding.
// CPU twin: crates/flare_core/src/render/cpu/tonemap.rs, `tonemap_pass` and `tonemap_pixel`.
// The uniforms `Globals` come from common.wgsl, prepended when the shader is embedded.

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var hdr_texture: texture_2d<f32>;
@group(0) @binding(2) var background_texture: texture_2d<f32>;
@group(0) @binding(3) var hdr_sampler: sampler;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the screen.
    let x = f32(i32(vertex & 1u) * 4 - 1);
    let y = f32(i32(vertex >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

fn aces(x: vec3<f32>) -> vec3<f32> {
    // Narkowicz 2015 fit of the ACES filmic curve.
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
}

fn encode_srgb(c: vec3<f32>) -> vec3<f32> {
    let low = c * 12.92;
    let high = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    // The accumulation may be smaller than the image: sample it bilinearly (exact texels when it is not).
    var c = textureSampleLevel(hdr_texture, hdr_sampler, position.xy * globals.viewport.zw, 0.0).rgb * globals.tonemap.x;
    if (globals.plate.y > 0.5) {
        let size = vec2<f32>(textureDimensions(background_texture));
        let at = vec2<i32>(position.xy * size * globals.viewport.zw);
        c = c + textureLoad(background_texture, at, 0).rgb * globals.plate.x;
    }
    c = max(c, vec3<f32>(0.0));
    if (globals.tonemap.y > 1.5) {
        c = aces(c);
    } else if (globals.tonemap.y > 0.5) {
        c = c / (vec3<f32>(1.0) + c);
    }
    c = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    if (globals.tonemap.z > 0.5) {
        c = encode_srgb(c);
    }
    return vec4<f32>(c, 1.0);
}
