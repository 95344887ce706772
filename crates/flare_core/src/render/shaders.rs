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
//! by lane. A test parses every shader with naga; `layout` (a test helper) checks every struct the GPU reads,
//! member by member, against naga's reflection of its WGSL (`render::layouts`). The tonemap pass is the one shader put together at run time: [`tonemap_wgsl`] puts the OCIO
//! display transform's WGSL (made for the document's display and view, or `ocio_lut.wgsl` after its constants for
//! the view's cube, [`crate::view_lut`]) before `tonemap.wgsl`; a test in `tests/colour.rs` validates it with the
//! cube.

/// The shared uniforms (prepended to the shaders below).
pub(crate) const COMMON_WGSL: &str = include_str!("../../../../shaders/common.wgsl");
/// Instanced ghost sprites.
pub(crate) const GHOSTS_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/aperture.wgsl"),
    include_str!("../../../../shaders/ghosts.wgsl")
);
/// Ghost sprites as compute: open spans and edges into per-row differences, then one sum per row.
pub(crate) const GHOSTS_COMPUTE_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/fixed64.wgsl"),
    include_str!("../../../../shaders/scan64.wgsl"),
    include_str!("../../../../shaders/mask_texels.wgsl"),
    include_str!("../../../../shaders/ghosts_compute.wgsl")
);
/// The starburst quad.
pub(crate) const STARBURST_WGSL: &str =
    concat!(include_str!("../../../../shaders/common.wgsl"), include_str!("../../../../shaders/starburst.wgsl"));
/// The front dirt's glow over the whole accumulation.
pub(crate) const DIRT_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/fullscreen.wgsl"),
    include_str!("../../../../shaders/dirt.wgsl")
);
/// Flare and plate exposures, tonemap, sRGB, with the identity in place of the OCIO display transform (what
/// the validation reads; the renderer builds [`tonemap_wgsl`] of the document's view).
pub(crate) const TONEMAP_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/ocio_identity.wgsl"),
    include_str!("../../../../shaders/tonemap.wgsl")
);

/// The identity in place of the OCIO display transform: the tonemap pass of frames drawn through FlareLab's own
/// curves, which never call it (`render::gpu_view::ViewPass::curves`).
pub(crate) const OCIO_IDENTITY_WGSL: &str = include_str!("../../../../shaders/ocio_identity.wgsl");

/// The tonemap shader with `ocio`, the WGSL OCIO generated for a display and view
/// ([`crate::view_transform::WgslShader`]), as its `ocio_display`.
pub fn tonemap_wgsl(ocio: &str) -> String {
    [COMMON_WGSL, ocio, include_str!("../../../../shaders/tonemap.wgsl")].join("\n")
}
/// LUT ghosts from the atlas.
pub(crate) const LUT_GHOSTS_WGSL: &str =
    concat!(include_str!("../../../../shaders/common.wgsl"), include_str!("../../../../shaders/lut_ghosts.wgsl"));
/// The run of a LUT ghost's instances laid over the accumulation at once (the rasterised LUT layer through alpha).
pub(crate) const LUT_RUNS_WGSL: &str =
    concat!(include_str!("../../../../shaders/fullscreen.wgsl"), include_str!("../../../../shaders/lut_runs.wgsl"));
/// LUT ghosts as compute: the instances binned to each tile, sampled per pixel.
pub(crate) const LUT_COMPUTE_WGSL: &str = include_str!("../../../../shaders/lut_compute.wgsl");
/// Ray grids on the GPU, pass 1: the compute tracer (with the declarations both passes share).
pub(crate) const RAYGRID_TRACE_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/raygrid_trace.wgsl")
);
/// Ray grids on the GPU, pass 2: the triangles splatted, energy conserved.
pub(crate) const RAYGRID_SPLAT_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/aperture.wgsl"),
    include_str!("../../../../shaders/raygrid_splat.wgsl")
);
/// Ray grids on the GPU, pass 2 as compute: each triangle box-filtered as the CPU twin does.
pub(crate) const RAYGRID_BOX_WGSL: &str = concat!(
    include_str!("../../../../shaders/word_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_common.wgsl"),
    include_str!("../../../../shaders/fixed64.wgsl"),
    include_str!("../../../../shaders/scan64.wgsl"),
    include_str!("../../../../shaders/mask_texels.wgsl"),
    include_str!("../../../../shaders/raygrid_box.wgsl")
);
/// The live depth of field: split, gather, composite, resolve (`crate::dof::live`).
pub(crate) const DOF_WGSL: &str = include_str!("../../../../shaders/dof.wgsl");
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

/// The layout of the structs the GPU reads, checked against naga's reflection of the WGSL that declares them.
#[cfg(test)]
pub(crate) mod layout {
    /// Each field of a Rust struct: its name and offset (`fields!(Type: a, b, c)`), and the struct's size.
    macro_rules! fields {
        ($t:ty: $($f:ident),+ $(,)?) => {
            (std::mem::size_of::<$t>(), vec![$((stringify!($f), std::mem::offset_of!($t, $f))),+])
        };
    }
    pub(crate) use fields;

    /// The struct `name` of the WGSL `source`: its size and each member's name and offset (naga's layout).
    pub(crate) fn wgsl_layout(source: &str, name: &str) -> (usize, Vec<(String, usize)>) {
        let module = naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{}", e.emit_to_string(source)));
        let (_, ty) =
            module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).unwrap_or_else(|| panic!("no {name}"));
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
        let members = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect();
        (*span as usize, members)
    }

    /// Asserts that the WGSL struct `name` of `source` has the Rust struct's `size` and that each of its members
    /// lies where the Rust field of its name does: the same name at the same offset, or the members `stop0`,
    /// `stop1`, ... of a WGSL that spells an array out within the Rust array field `stops` (or `stop`), in order.
    /// Every Rust field is met by some member.
    pub(crate) fn assert_same_layout(source: &str, name: &str, (size, rust): (usize, Vec<(&str, usize)>)) {
        let (span, members) = wgsl_layout(source, name);
        assert_eq!(span, size, "{name}: WGSL size {span}, Rust size {size}");
        let end = |k: usize| rust.get(k + 1).map_or(size, |f| f.1);
        let mut met = vec![false; rust.len()];
        let mut last = None;
        for (member, offset) in &members {
            let stem = member.trim_end_matches(|c: char| c.is_ascii_digit());
            let k = rust.iter().position(|(f, _)| f == member).or_else(|| {
                (stem.len() < member.len())
                    .then(|| rust.iter().position(|(f, _)| *f == format!("{stem}s") || *f == stem))
                    .flatten()
            });
            let Some(k) = k else { panic!("{name}: WGSL member {member} has no Rust field") };
            let (field, at) = rust[k];
            if field == member {
                assert_eq!(*offset, at, "{name}.{member}: WGSL offset {offset}, Rust {at}");
            } else {
                assert!((at..end(k)).contains(offset), "{name}.{member}: offset {offset} outside the field {field}");
            }
            assert!(last < Some(*offset), "{name}.{member}: members out of order");
            (met[k], last) = (true, Some(*offset));
        }
        assert!(met.iter().all(|&m| m), "{name}: Rust fields no WGSL member meets: {rust:?} / {members:?}");
    }

    #[test]
    fn the_checker_refuses_a_moved_or_missing_member() {
        let wgsl = "struct S { a: vec2<f32>, b0: f32, b1: f32, c: u32, _pad: u32 };";
        let rust = |names: [&'static str; 4], offsets: [usize; 4]| (24, names.into_iter().zip(offsets).collect());
        assert_same_layout(wgsl, "S", rust(["a", "b", "c", "_pad"], [0, 8, 16, 20]));
        for bad in [rust(["a", "b", "c", "_pad"], [0, 8, 12, 20]), rust(["a", "bb", "c", "_pad"], [0, 8, 16, 20])] {
            assert!(std::panic::catch_unwind(|| assert_same_layout(wgsl, "S", bad)).is_err());
        }
    }
}
