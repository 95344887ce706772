// The front dirt's glow: the dirt seen out of focus through a Henyey-Greenstein lobe about the light,
// evaluated per pixel over the whole accumulation, additive (crates/flare_core/src/dirt.rs has the physics).
// CPU twin: crates/flare_core/src/render/cpu/dirt.rs, `dirt_glow_at`.
// The uniforms `Globals` come from common.wgsl, prepended when the shader is embedded.

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    // Image pixels (not accumulation pixels).
    @location(0) pixel: vec2<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
// D: the mean share of dirt over each footprint, in the red channel.
@group(0) @binding(1) var dirt_map: texture_2d<f32>;

// One triangle covering the frame.
@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> VertexOut {
    let q = fullscreen_corner(vertex);
    var out: VertexOut;
    out.position = fullscreen_clip(q);
    out.pixel = q * globals.viewport_px;
    return out;
}

fn texel(i: i32, j: i32, n: i32) -> f32 {
    if (i < 0 || j < 0 || i >= n || j >= n) {
        return 0.0;
    }
    return textureLoad(dirt_map, vec2<i32>(i, j), 0).r;
}

// D at texel coordinates t (texel centres at integers), bilinear, 0 outside the map.
fn sample_map(t: vec2<f32>) -> f32 {
    let n = i32(textureDimensions(dirt_map).x);
    let size = f32(n);
    if (!(t.x > -1.0 && t.x < size && t.y > -1.0 && t.y < size)) {
        return 0.0;
    }
    let t0 = floor(t);
    let f = t - t0;
    let i = i32(t0.x);
    let j = i32(t0.y);
    let top = texel(i, j, n) * (1.0 - f.x) + texel(i + 1, j, n) * f.x;
    let bottom = texel(i, j + 1, n) * (1.0 - f.x) + texel(i + 1, j + 1, n) * f.x;
    return top * (1.0 - f.y) + bottom * f.y;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let a = globals.dirt_slopes_per_px;
    let j = globals.dirt_footprint;
    let lobe_g = globals.dirt_g;
    let u_s = globals.dirt_light_slopes;
    let p = in.pixel - globals.dirt_light_px;
    let du = vec2<f32>(a.x * p.x + a.y * p.y, a.z * p.x + a.w * p.y);
    let u = u_s + du;
    let n_u = sqrt(1.0 + u.x * u.x + u.y * u.y);
    let inv_ns = globals.dirt_inv_ns;
    // 1 - cos(alpha) = |v - v_s|^2 / 2 with v = (u, 1) / |(u, 1)|: no cancellation near the light.
    let d = vec3<f32>(u.x / n_u - u_s.x * inv_ns, u.y / n_u - u_s.y * inv_ns, 1.0 / n_u - inv_ns);
    let q = (1.0 - lobe_g) * (1.0 - lobe_g) + lobe_g * dot(d, d);
    let lobe = globals.dirt_hg_norm / (q * sqrt(q));
    let jacobian = globals.dirt_per_mm2 / (n_u * n_u * n_u);
    let t = globals.dirt_centre_texels + vec2<f32>(j.x * du.x + j.y * du.y, j.z * du.x + j.w * du.y);
    let share = sample_map(t);
    return vec4<f32>(globals.dirt_power_rgb * (lobe * jacobian * share), 0.0);
}
