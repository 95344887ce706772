//! Colour management by OCIO: the built-in view against values PyOpenColorIO 2.6 gave for the same config,
//! display and view (stored here, so this runs everywhere), a `.cube` look applied where OCIO applies looks,
//! and the GPU's tonemap pass (OCIO's WGSL) against its CPU twin (OCIO's CPU processor).

use flare_core::color::Tonemap;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Device, Frame, FrameRequest, GpuDrawer, Sources};
use flare_core::image::HdrImage;
use flare_core::render::DisplaySettings;
use flare_core::render::gpu::{GpuContext, gl_test_context, test_context};
use flare_core::view_lut::ViewLut;
use flare_core::view_transform::{ColorDoc, ViewTransform};

/// `(linear Rec. 709, display values)` from PyOpenColorIO 2.6.0: `ocio://studio-config-latest`, its default
/// display and view ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)"), CPU processor.
const PYOPENCOLORIO: [([f32; 3], [f32; 3]); 9] = [
    ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([0.001, 0.002, 0.003], [0.000_107_790_7, 0.000_245_272_2, 0.000_385_763_2]),
    ([0.18, 0.18, 0.18], [0.349_187_6, 0.349_188_1, 0.349_187_9]),
    ([0.5, 0.25, 0.1], [0.575_917_4, 0.420_354_3, 0.272_580_8]),
    ([1.0, 1.0, 1.0], [0.706_683, 0.706_683_6, 0.706_683_3]),
    ([4.0, 2.0, 1.0], [0.924_156_5, 0.826_801_6, 0.758_402_6]),
    ([0.05, 0.6, 0.9], [0.292_624_7, 0.605_127_5, 0.707_070_5]),
    ([20.0, 20.0, 20.0], [0.980_346_6, 0.980_346_6, 0.980_346_5]),
    ([1000.0, 10.0, 0.1], [1.000_007, 1.000_007, 1.000_007]),
];

#[test]
fn the_builtin_view_matches_pyopencolorio() {
    let view = ViewTransform::builtin();
    assert_eq!((view.display.as_str(), view.view.as_str()), ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)"));
    for (linear, expected) in PYOPENCOLORIO {
        let got = view.apply(linear);
        for c in 0..3 {
            assert!((got[c] - expected[c]).abs() <= 1e-5, "{linear:?}: {got:?} vs PyOpenColorIO {expected:?}");
        }
    }
}

/// A 9^3 `.cube` that warms and darkens: red up, blue down.
pub fn warm_cube(path: &std::path::Path) {
    let n = 9;
    let mut text = String::from("TITLE \"warm\"\nLUT_3D_SIZE 9\n");
    for b in 0..n {
        for g in 0..n {
            for r in 0..n {
                let f = |k: usize| k as f32 / (n - 1) as f32;
                let (r, g, b) = (f(r), f(g), f(b));
                text += &format!("{:.6} {:.6} {:.6}\n", (r * 1.1).min(1.0), g * 0.95, b * 0.8);
            }
        }
    }
    std::fs::write(path, text).unwrap();
}

/// One device drawing the view, then each of FlareLab's curves (its tonemap pass then holds no view's code,
/// `gpu_view::ViewPass::curves`), then the view again: every frame within 1/255 of its CPU twin, and a curve's
/// frame differs from the view's (the pass was not left behind).
#[test]
fn the_gpu_switches_between_the_view_and_the_curves() {
    let Some(ctx) = test_context() else { return };
    let mut device = Device::Gpu(Box::new(GpuDrawer::on(ctx)));
    let view = ViewTransform::cached(&ColorDoc::default()).unwrap();
    let tonemaps = [Tonemap::View, Tonemap::Aces, Tonemap::Reinhard, Tonemap::None, Tonemap::View];
    let mut displays = Vec::new();
    for tonemap in tonemaps {
        let (flare, mut frame, plate) = frame_of(Some(view.clone()));
        let request = FrameRequest { display: DisplaySettings { tonemap, ..frame.request.display }, ..frame.request };
        frame = Frame::build(&flare, None, &request);
        let sources = Sources { flare: &flare, lut: None, plate: Some(&plate) };
        let cpu = frame::draw_cpu(&frame, &sources);
        let gpu = device.draw(&frame, &sources).unwrap();
        assert!(matches!(device, Device::Gpu(_)), "the GPU drew it");
        let worst = cpu.display.worst_difference(&gpu.display);
        assert!(worst <= 1, "{tonemap:?}: worst display difference {worst}/255");
        displays.push(gpu.display);
    }
    assert_eq!(displays[0].worst_difference(&displays[4]), 0, "the view, drawn again, is the same");
    for (k, curve) in displays[1..4].iter().enumerate() {
        assert!(displays[0].worst_difference(curve) > 8, "curve {k} drew the view's image");
    }
}

fn frame_of(view: Option<std::sync::Arc<ViewTransform>>) -> (PreparedFlare, Frame, HdrImage) {
    let flare =
        PreparedFlare::new(&flare_core::optics::library::builtin_lens("tessar").unwrap(), &FlareConfig::default())
            .unwrap();
    let mut request = FrameRequest { light_deg: [8.0, 5.0], width: 160, height: 100, view, ..FrameRequest::default() };
    request.display.flare_ev = 12.0;
    let frame = Frame::build(&flare, None, &request);
    let mut plate = HdrImage::black(160, 100);
    for (k, p) in plate.pixels.iter_mut().enumerate() {
        let t = (k % 160) as f32 / 160.0;
        *p = [0.02 + 2.0 * t, 0.3 * t, 0.1 + 0.5 * (1.0 - t), 1.0];
    }
    (flare, frame, plate)
}

#[test]
fn a_cube_is_applied_as_a_look_and_changes_the_display() {
    let dir = tempfile::tempdir().unwrap();
    let cube = dir.path().join("warm.cube");
    warm_cube(&cube);
    let plain = ViewTransform::builtin();
    let warm = ViewTransform::new(&ColorDoc { cube: Some(cube.display().to_string()), ..Default::default() }).unwrap();
    assert_eq!(warm.looks, flare_core::view_transform::CUBE_LOOK);
    let (a, b) = (plain.apply([0.3, 0.3, 0.3]), warm.apply([0.3, 0.3, 0.3]));
    assert!(b[0] > a[0] && b[2] < a[2], "warmer: {a:?} -> {b:?}");
    // A broken cube is refused naming the field.
    let broken = dir.path().join("broken.cube");
    std::fs::write(&broken, "LUT_3D_SIZE 9\n0 0 0\n").unwrap();
    let e = ViewTransform::new(&ColorDoc { cube: Some(broken.display().to_string()), ..Default::default() })
        .expect_err("a cube with one entry of 729");
    assert_eq!(e.field, "cube", "{e}");
}

#[test]
fn the_gpu_runs_the_views_wgsl_as_its_cpu_twin_runs_the_processor() {
    let Some(ctx) = test_context() else { return };
    views_draw_as_their_cpu_twins(ctx);
}

/// The same on wgpu's OpenGL ES backend (llvmpipe's OpenGL here; a machine without Vulkan draws on it): OpenGL
/// ES has no 1D textures, where the ACES 2.0 view's table of hues once lay, and a frame through the view came
/// out black without an error.
#[test]
fn the_views_draw_on_opengl_es_as_on_vulkan() {
    let Some(ctx) = gl_test_context() else { return };
    views_draw_as_their_cpu_twins(ctx);
}

/// Four views (the default, another view, another display, a `.cube` look) drawn on one device (as the app
/// keeps one: each view's pipeline made when a frame asks for it), each within 1/255 of its CPU twin.
fn views_draw_as_their_cpu_twins(ctx: GpuContext) {
    let dir = tempfile::tempdir().unwrap();
    let cube = dir.path().join("warm.cube");
    warm_cube(&cube);
    let mut device = Device::Gpu(Box::new(GpuDrawer::on(ctx)));
    let views = [
        ColorDoc::default(),
        ColorDoc { view: Some("Video (colorimetric)".into()), ..Default::default() },
        ColorDoc { display: Some("Display P3 - Display".into()), ..Default::default() },
        ColorDoc { cube: Some(cube.display().to_string()), ..Default::default() },
    ];
    for doc in views {
        let view = ViewTransform::cached(&doc).unwrap();
        let (flare, frame, plate) = frame_of(Some(view.clone()));
        let sources = Sources { flare: &flare, lut: None, plate: Some(&plate) };
        let cpu = frame::draw_cpu(&frame, &sources);
        let gpu = device.draw(&frame, &sources).unwrap();
        assert!(matches!(device, Device::Gpu(_)), "the GPU drew it");
        let worst = cpu.display.worst_difference(&gpu.display);
        println!("{} / {} [{}]: GPU vs CPU twin worst {worst}/255", view.display, view.view, view.looks);
        assert!(worst <= 1, "{view:?}: worst display difference {worst}/255");
    }
}

/// The display code values (0-255) of `rgb` through `f`, clamped as the tonemap clamps.
fn codes(f: impl Fn([f32; 3]) -> [f32; 3], rgb: [f32; 3]) -> [u8; 3] {
    f(rgb).map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

#[test]
fn the_views_cube_is_within_two_codes_of_the_view_on_a_frame() {
    // How far the drafts' cube is from the exact view (the CPU processor), in display code values: over every
    // pixel of a frame with a plate, and over colours spread over 26 stops with any hue.
    let view = ViewTransform::builtin();
    let cube = ViewLut::cached(&view);
    let (flare, frame, plate) = frame_of(Some(view.clone()));
    let sources = Sources { flare: &flare, lut: None, plate: Some(&plate) };
    let composite =
        flare_core::render::cpu::composite(&frame.scene, &frame::draw_cpu(&frame, &sources).hdr, Some(&plate));
    let mut seed = 12345u64;
    let mut random = || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let spread: Vec<[f32; 3]> = (0..20_000)
        .map(|_| {
            let scale = (random() * 26.0 - 14.0).exp2();
            [random() * scale, random() * scale, random() * scale]
        })
        .collect();
    let differences = |colours: &mut dyn Iterator<Item = [f32; 3]>| -> Vec<u8> {
        let mut d: Vec<u8> = colours
            .map(|c| {
                let (a, b) = (codes(|c| cube.apply(c), c), codes(|c| view.apply(c), c));
                (0..3).map(|k| a[k].abs_diff(b[k])).max().unwrap_or(0)
            })
            .collect();
        d.sort_unstable();
        d
    };
    let on_frame = differences(&mut composite.pixels.iter().map(|p| [p[0], p[1], p[2]]));
    let spread = differences(&mut spread.into_iter());
    let quantile = |d: &[u8], q: f64| d[((d.len() - 1) as f64 * q) as usize];
    println!(
        "the cube ({} nodes a side) against the view: frame worst {}, 99.9% {}; spread worst {}, 99.9% {}, 99% {}",
        cube.size,
        quantile(&on_frame, 1.0),
        quantile(&on_frame, 0.999),
        quantile(&spread, 1.0),
        quantile(&spread, 0.999),
        quantile(&spread, 0.99)
    );
    assert!(quantile(&on_frame, 1.0) <= 2, "the frame");
    assert!(quantile(&spread, 0.99) <= 1 && quantile(&spread, 0.999) <= 3, "the spread");
    // The most saturated colours, where ACES 2.0 compresses the gamut, are the farthest.
    assert!(quantile(&spread, 1.0) <= 10, "the spread's worst");
}

#[test]
fn a_draft_through_the_cube_is_its_cpu_twin_and_the_full_frame_the_exact_view() {
    let Some(ctx) = test_context() else { return };
    let view = ViewTransform::builtin();
    let cube = ViewLut::cached(&view);
    let mut drawer = GpuDrawer::on(ctx);
    let (flare, frame, plate) = frame_of(Some(view.clone()));
    let sources = Sources { flare: &flare, lut: None, plate: Some(&plate) };
    let exact = drawer.draw(&frame, &sources).unwrap();
    drawer.renderer.sample_view_from_cube(true);
    let drafted = drawer.draw(&frame, &sources).unwrap();
    // The CPU twin: the same accumulation composited, looked up in the cube by `ViewLut::apply`.
    let composite = flare_core::render::cpu::composite(&frame.scene, &drafted.hdr, Some(&plate));
    let twin: Vec<[u8; 3]> = composite.pixels.iter().map(|p| codes(|c| cube.apply(c), [p[0], p[1], p[2]])).collect();
    let worst_twin = drafted
        .display
        .pixels
        .iter()
        .zip(&twin)
        .flat_map(|(a, b)| (0..3).map(move |k| a[k].abs_diff(b[k])))
        .max()
        .unwrap();
    let worst_exact = drafted.display.worst_difference(&exact.display);
    println!("the draft through the cube: {worst_twin}/255 from its CPU twin, {worst_exact}/255 from the exact view");
    assert!(worst_twin <= 1, "GPU cube vs its CPU twin: {worst_twin}/255");
    assert!((1..=2).contains(&worst_exact), "the draft vs the exact view: {worst_exact}/255");
    // Letting go: the exact view again, to the byte; frames through a curve ignore the cube.
    drawer.renderer.sample_view_from_cube(false);
    assert_eq!(drawer.draw(&frame, &sources).unwrap().display.worst_difference(&exact.display), 0);
    let request = FrameRequest {
        display: DisplaySettings { tonemap: Tonemap::Aces, ..frame.request.display },
        ..frame.request.clone()
    };
    let aces = Frame::build(&flare, None, &request);
    let curve = drawer.draw(&aces, &sources).unwrap().display;
    drawer.renderer.sample_view_from_cube(true);
    assert_eq!(drawer.draw(&aces, &sources).unwrap().display.worst_difference(&curve), 0);
}

#[test]
fn the_tonemap_validates_with_the_views_shader_and_with_its_cube() {
    // The tonemap is the one shader put together at run time: validated here with both `ocio_display`s.
    let view = ViewTransform::builtin();
    let cube = ViewLut::bake(&view, 3);
    for (name, ocio) in [("the view", view.shader.text.clone()), ("the cube", cube.shader().text)] {
        let source = flare_core::render::shaders::tonemap_wgsl(&ocio);
        let module =
            naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}
