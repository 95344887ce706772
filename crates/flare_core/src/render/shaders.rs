//! The WGSL shaders, embedded at compile time from `shaders/` (never read from the working folder).

/// Instanced ghost sprites.
pub const GHOSTS_WGSL: &str = include_str!("../../../../shaders/ghosts.wgsl");
/// The starburst quad.
pub const STARBURST_WGSL: &str = include_str!("../../../../shaders/starburst.wgsl");
/// Background, exposure, tonemap, sRGB.
pub const TONEMAP_WGSL: &str = include_str!("../../../../shaders/tonemap.wgsl");

/// LUT ghosts from the atlas.
pub const LUT_GHOSTS_WGSL: &str = include_str!("../../../../shaders/lut_ghosts.wgsl");

/// The app's viewport pass (the flare texture into egui's render pass; used by the app, validated here).
pub const VIEWPORT_WGSL: &str = include_str!("../../../../shaders/viewport.wgsl");

/// Every shader with its file name (for validation and error messages).
pub const ALL: &[(&str, &str)] = &[
    ("ghosts.wgsl", GHOSTS_WGSL),
    ("starburst.wgsl", STARBURST_WGSL),
    ("tonemap.wgsl", TONEMAP_WGSL),
    ("lut_ghosts.wgsl", LUT_GHOSTS_WGSL),
    ("viewport.wgsl", VIEWPORT_WGSL),
];
