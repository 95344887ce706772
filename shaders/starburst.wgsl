// The starburst: the light's own image spread by diffraction, evaluated per pixel on a quad centred on the
// light's image out to its reach, additive (crates/flare_core/src/starburst.rs has the physics).
// CPU twin: crates/flare_core/src/render/cpu/starburst.rs, `starburst_pass`.
// The uniforms `Globals` come from common.wgsl, prepended when the shader is embedded.

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    // Image pixels (not accumulation pixels).
    @location(0) pixel: vec2<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
// The angular profile c(phi) / peak, one texel per bin in the red channel.
@group(0) @binding(1) var starburst_profile: texture_2d<f32>;

const TAU: f32 = 6.283185307179586;
const STARBURST_MAX: f32 = 3.0e4;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> VertexOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let q = corners[vertex];
    let pixel = globals.starburst_centre_px + globals.starburst_reach_px * vec2<f32>(max(stretch(), 1.0), 1.0) * q;
    var out: VertexOut;
    out.position = vec4<f32>(pixel.x * globals.inv_viewport_px.x * 2.0 - 1.0, 1.0 - pixel.y * globals.inv_viewport_px.y * 2.0, 0.0, 1.0);
    out.pixel = pixel;
    return out;
}

// c(phi) / peak towards the offset d (x right, y down), between the two nearest bins, wrapping.
fn profile_at(d: vec2<f32>) -> f32 {
    let n = textureDimensions(starburst_profile).x;
    let turn = atan2(d.y, d.x) / TAU;
    var t = (turn - floor(turn)) * f32(n) - 0.5;
    if (t < 0.0) {
        t = t + f32(n);
    }
    let i0 = min(u32(t), n - 1u);
    let f = t - f32(i0);
    let a = textureLoad(starburst_profile, vec2<i32>(i32(i0), 0), 0).r;
    let b = textureLoad(starburst_profile, vec2<i32>(i32((i0 + 1u) % n), 0), 0).r;
    return a * (1.0 - f) + b * f;
}

// An anamorphic lens's far field is stretched along x by N_x / N_y (1 for a lens of revolution).
fn stretch() -> f32 {
    return select(1.0, globals.starburst_stretch_x, globals.starburst_stretch_x > 0.0);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // The far field's own coordinates, in which it is the round pattern.
    let s = stretch();
    let d = (in.pixel - globals.starburst_centre_px) / vec2<f32>(s, 1.0);
    let r_px = length(d);
    if (r_px > globals.starburst_reach_px) {
        return vec4<f32>(0.0);
    }
    var c: vec3<f32>;
    if (r_px < globals.starburst_core_px) {
        c = globals.starburst_core_rgb;
    } else {
        let r_mm = r_px * globals.starburst_mm_per_px;
        c = globals.starburst_far_k * (profile_at(d) / (r_mm * r_mm * r_mm) / s);
    }
    return vec4<f32>(min(c, vec3<f32>(STARBURST_MAX)), 0.0);
}
