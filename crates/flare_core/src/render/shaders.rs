//! The WGSL shaders, embedded at compile time from `shaders/` (never read from the working folder).
//!
//! # How it works
//! `shaders/common.wgsl` holds the one declaration of the uniforms every pass reads ([`super::Globals`]); it is
//! prepended to each shader that uses them here, at compile time, so no shader carries a copy to keep in sync.
//! Likewise `aperture.wgsl` (the mask lookup) for the two passes that read the aperture, and `raygrid_common.wgsl`
//! (the ray-grid structs) for the GPU ray grids' passes, and `fixed64.wgsl` (64-bit fixed point in two u32 words)
//! for the passes that sum light with integer atomics, `scan64.wgsl` (those sums as vectors and a workgroup's scan
//! of them) for the two resolves that sum a row 256 columns at a time on a GPU, `mask_texels.wgsl` (the mask looked
//! up one word a bilinear footprint) for the compute passes that read the aperture, and `word_texels.wgsl` (words
//! read as rows of Rgba32Uint texels) for the compute passes that read words a software rasteriser would load lane
//! by lane. A test parses every shader with naga and checks that the WGSL `Globals` has the Rust struct's size and
//! member offsets. The tonemap pass is the one shader put together at run time: [`tonemap_wgsl`] puts the OCIO
//! display transform's WGSL (made for the document's display and view, or `ocio_lut.wgsl` after its constants for
//! the view's cube, [`crate::view_lut`]) before `tonemap.wgsl`; a test in `tests/colour.rs` validates it with the
//! cube.

/// The shared uniforms (prepended to the shaders below).
pub const COMMON_WGSL: &str = include_str!("../../../../shaders/common.wgsl");
/// Instanced ghost sprites.
pub const GHOSTS_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/aperture.wgsl"),
    include_str!("../../../../shaders/ghosts.wgsl")
);
/// Ghost sprites as compute: open spans and edges into per-row differences, then one sum per row.
pub const GHOSTS_COMPUTE_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/fixed64.wgsl"),
    include_str!("../../../../shaders/scan64.wgsl"),
    include_str!("../../../../shaders/mask_texels.wgsl"),
    include_str!("../../../../shaders/ghosts_compute.wgsl")
);
/// The starburst quad.
pub const STARBURST_WGSL: &str =
    concat!(include_str!("../../../../shaders/common.wgsl"), include_str!("../../../../shaders/starburst.wgsl"));
/// The front dirt's glow over the whole accumulation.
pub const DIRT_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/fullscreen.wgsl"),
    include_str!("../../../../shaders/dirt.wgsl")
);
/// Flare and plate exposures, tonemap, sRGB, with the identity in place of the OCIO display transform (what
/// the validation reads; the renderer builds [`tonemap_wgsl`] of the document's view).
pub const TONEMAP_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/ocio_identity.wgsl"),
    include_str!("../../../../shaders/tonemap.wgsl")
);

/// The identity in place of the OCIO display transform: the tonemap pass of frames drawn through FlareLab's own
/// curves, which never call it (`render::gpu_view::ViewPass::curves`).
pub const OCIO_IDENTITY_WGSL: &str = include_str!("../../../../shaders/ocio_identity.wgsl");

/// The tonemap shader with `ocio`, the WGSL OCIO generated for a display and view
/// ([`crate::view_transform::WgslShader`]), as its `ocio_display`.
pub fn tonemap_wgsl(ocio: &str) -> String {
    [COMMON_WGSL, ocio, include_str!("../../../../shaders/tonemap.wgsl")].join("\n")
}
/// LUT ghosts from the atlas.
pub const LUT_GHOSTS_WGSL: &str =
    concat!(include_str!("../../../../shaders/common.wgsl"), include_str!("../../../../shaders/lut_ghosts.wgsl"));
/// The run of a LUT ghost's instances laid over the accumulation at once (the rasterised LUT layer through alpha).
pub const LUT_RUNS_WGSL: &str =
    concat!(include_str!("../../../../shaders/fullscreen.wgsl"), include_str!("../../../../shaders/lut_runs.wgsl"));
/// LUT ghosts as compute: the instances binned to each tile, sampled per pixel.
pub const LUT_COMPUTE_WGSL: &str = include_str!("../../../../shaders/lut_compute.wgsl");
/// Ray grids on the GPU, pass 1: the compute tracer (with the declarations both passes share).
pub const RAYGRID_TRACE_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/raygrid_trace.wgsl")
);
/// Ray grids on the GPU, pass 2: the triangles splatted, energy conserved.
pub const RAYGRID_SPLAT_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/aperture.wgsl"),
    include_str!("../../../../shaders/raygrid_splat.wgsl")
);
/// Ray grids on the GPU, pass 2 as compute: each triangle box-filtered as the CPU twin does.
pub const RAYGRID_BOX_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/fixed64.wgsl"),
    include_str!("../../../../shaders/scan64.wgsl"),
    include_str!("../../../../shaders/mask_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_box.wgsl")
);
/// The live depth of field: split, gather, composite, resolve (`crate::dof::live`).
pub const DOF_WGSL: &str = include_str!("../../../../shaders/dof.wgsl");
/// The app's viewport pass (the flare texture into egui's render pass; used by the app, validated here).
pub const VIEWPORT_WGSL: &str = include_str!("../../../../shaders/viewport.wgsl");

/// Every shader with its file name (for validation and error messages).
pub const ALL: &[(&str, &str)] = &[
    ("common.wgsl", COMMON_WGSL),
    ("ghosts.wgsl", GHOSTS_WGSL),
    ("ghosts_compute.wgsl", GHOSTS_COMPUTE_WGSL),
    ("starburst.wgsl", STARBURST_WGSL),
    ("dirt.wgsl", DIRT_WGSL),
    ("tonemap.wgsl", TONEMAP_WGSL),
    ("lut_ghosts.wgsl", LUT_GHOSTS_WGSL),
    ("lut_runs.wgsl", LUT_RUNS_WGSL),
    ("lut_compute.wgsl", LUT_COMPUTE_WGSL),
    ("viewport.wgsl", VIEWPORT_WGSL),
    ("raygrid_trace.wgsl", RAYGRID_TRACE_WGSL),
    ("raygrid_splat.wgsl", RAYGRID_SPLAT_WGSL),
    ("raygrid_box.wgsl", RAYGRID_BOX_WGSL),
    ("dof.wgsl", DOF_WGSL),
];
