// The uniforms every pass reads: the one WGSL declaration, prepended to each shader when it is embedded
// (crates/flare_core/src/render/shaders.rs). Mirrors `Globals` in crates/flare_core/src/render/mod.rs; a test
// checks with naga that both have the same size and member offsets.

// Codes of `tonemap_operator` (Rust: `Tonemap::code`).
const TONEMAP_NONE: u32 = 0u;
const TONEMAP_REINHARD: u32 = 1u;
const TONEMAP_ACES: u32 = 2u;
const TONEMAP_VIEW: u32 = 3u;

struct Globals {
    viewport_px: vec2<f32>,          // width, height (pixels)
    inv_viewport_px: vec2<f32>,      // 1 / width, 1 / height
    starburst_centre_px: vec2<f32>,  // the light's image
    starburst_reach_px: f32,         // how far the starburst is drawn (0: none)
    starburst_core_px: f32,          // the blown-out core's radius
    flare_gain: f32,                 // 2^flare_ev
    tonemap_operator: u32,           // TONEMAP_*
    encode_srgb: u32,                // 1: the shader encodes sRGB (the target does not)
    plate_present: u32,              // 1: a background plate is bound
    inv_output_px: vec2<f32>,        // 1 / width, 1 / height of the delivered image
    plate_gain: f32,                 // 2^plate_ev
    _pad0: u32,
    starburst_far_k: vec3<f32>,      // the far field's K per channel (I = K c(phi) / r_mm^3)
    starburst_mm_per_px: f32,
    starburst_core_rgb: vec3<f32>,   // the core's relative irradiance per channel
    starburst_stretch_x: f32,        // the far field's x stretch N_x / N_y (0: 1)
    dirt_light_px: vec2<f32>,        // the front dirt's glow: the light's image (pixels)
    dirt_light_slopes: vec2<f32>,    // the light's slopes u_s
    dirt_slopes_per_px: vec4<f32>,   // slopes per image pixel about the light, row-major 2x2
    dirt_footprint: vec4<f32>,       // the footprint's centre in map texels per unit slope, row-major 2x2
    dirt_centre_texels: vec2<f32>,   // the footprint's centre for the light
    dirt_g: f32,                     // Henyey-Greenstein g
    dirt_per_mm2: f32,               // |det A| (mm^-2)
    dirt_power_rgb: vec3<f32>,       // the glow's power per channel (0: none)
    dirt_hg_norm: f32,               // (1 - g^2) / (4 pi)
    dirt_inv_ns: f32,                // 1 / sqrt(1 + |u_s|^2)
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
};
