// The uniforms every pass reads: the one WGSL declaration, prepended to each shader when it is embedded
// (crates/flare_core/src/render/shaders.rs). Mirrors `Globals` in crates/flare_core/src/render/mod.rs; a test
// checks with naga that both have the same size and member offsets.

struct Globals {
    viewport: vec4<f32>,   // width, height, 1/width, 1/height (pixels)
    starburst: vec4<f32>,  // centre x, centre y, reach (pixels; 0: none), core radius (pixels)
    tonemap: vec4<f32>,    // flare gain (2^flare_ev), operator (0 none, 1 Reinhard, 2 ACES), encode sRGB (0/1), unused
    plate: vec4<f32>,      // plate gain (2^plate_ev), plate present (0/1), 1 / width, 1 / height of the delivered image
    starburst_far: vec4<f32>,  // far field K per channel (I = K c(phi) / r_mm^3), mm per pixel
    starburst_core: vec4<f32>, // core relative irradiance per channel, the far field's x stretch N_x / N_y
    dirt_light: vec4<f32>,     // the front dirt's glow: the light's image (pixels), its slopes u_s
    dirt_geom: vec4<f32>,      // slopes per image pixel about the light, row-major 2x2
    dirt_footprint: vec4<f32>, // the footprint's centre in map texels per unit slope, row-major 2x2
    dirt_centre: vec4<f32>,    // the footprint's centre for the light (texels x, y), unused, unused
    dirt_lobe: vec4<f32>,      // Henyey-Greenstein g, |det A| (mm^-2), 1 / sqrt(1 + |u_s|^2), unused
    dirt_colour: vec4<f32>,    // the glow's power per channel (0: none), (1 - g^2) / (4 pi)
};
