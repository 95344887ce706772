//! The ghost sprites as a compute pass (`shaders/ghosts_compute.wgsl`) on a headless adapter (lavapipe in CI,
//! where `FLARELAB_REQUIRE_GPU=1` makes a missing adapter a failure): against its CPU twin, the same bytes on
//! every run, a frame drawn in strips (as one beyond the adapter's storage binding limit is) the same as in one
//! piece, and the raster path it replaces still in step.

use flare_core::aperture::{Aperture, ApertureShape};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, GpuDrawer, Sources};
use flare_core::optics::library::builtin_lens;
use flare_core::render::cpu::tonemap_pixel;
use flare_core::render::gpu::test_context;
use flare_core::render::gpu_ghosts::ComputeForm;
use flare_core::render::{DisplaySettings, HdrImage};

mod common;

fn prepared(lens: &str, blades: u32) -> PreparedFlare {
    let shape = if blades == 0 {
        ApertureShape::Circle
    } else {
        ApertureShape::Blades { count: blades, rotation_deg: 10.0, roundness: 0.0 }
    };
    let config = FlareConfig { aperture: Aperture { shape, f_number: None }, ..FlareConfig::default() };
    // `toroidal`: the anamorphic test lens of tests/data/reference/toroidal (elliptical sprites).
    let lens = if lens == "toroidal" { common::toroidal_test_lens() } else { builtin_lens(lens).unwrap() };
    PreparedFlare::new(&lens, &config).unwrap()
}

fn request(light_deg: [f64; 2], width: u32, height: u32, divisor: u32) -> FrameRequest {
    FrameRequest {
        light_deg,
        width,
        height,
        display: DisplaySettings { starburst: false, accumulation_divisor: divisor, ..DisplaySettings::default() },
        ..FrameRequest::default()
    }
}

/// The worst and mean display difference (in 8-bit steps, as floats: before quantisation) between two
/// accumulations of `frame`, and the share of lit pixels.
fn display_difference(frame: &Frame, a: &HdrImage, b: &HdrImage) -> (f32, f64, f64) {
    let gain = frame.scene.globals.flare_gain;
    let (mut worst, mut sum, mut lit) = (0.0f32, 0.0f64, 0usize);
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        let (dp, dq) = (
            tonemap_pixel([p[0], p[1], p[2]].map(|v| v * gain), &frame.scene),
            tonemap_pixel([q[0], q[1], q[2]].map(|v| v * gain), &frame.scene),
        );
        for c in 0..3 {
            let d = (dp[c] - dq[c]).abs() * 255.0;
            worst = worst.max(d);
            sum += f64::from(d);
        }
        lit += usize::from(q[0] + q[1] + q[2] > 0.0);
    }
    (worst, sum / (3 * a.pixels.len()) as f64, lit as f64 / a.pixels.len() as f64)
}

/// The compute pass draws the CPU twin's image: every display value within half an 8-bit step (the GPU keeps
/// half floats; the twin f32 with f64 spans), on frame-filling zoom ghosts, blades and a round stop, a light
/// off the frame and a quarter accumulation.
#[test]
fn the_compute_pass_draws_the_cpu_twins_image() {
    let Some(ctx) = test_context() else { return };
    let mut drawer = GpuDrawer::on(ctx);
    assert!(drawer.renderer.ghosts_as_compute(), "lavapipe runs the compute pass");
    for (lens, blades, light, divisor, (w, h)) in [
        // Large: a stop's texel spans several pixels, and an edge many.
        ("nikon_zoom_28_75mm", 6, [9.0, 5.0], 1, (1600, 900)),
        ("nikon_zoom_28_75mm", 6, [9.0, 5.0], 1, (320, 200)),
        ("pbrt_dgauss_50mm", 5, [-8.0, 4.0], 1, (320, 200)),
        ("heliar", 0, [12.0, -3.0], 2, (320, 200)),
        ("pbrt_dgauss_50mm", 7, [30.0, 25.0], 1, (320, 200)),
        ("toroidal", 6, [8.0, 5.0], 1, (320, 200)),
    ] {
        let flare = prepared(lens, blades);
        let frame = Frame::build(&flare, None, &request(light, w, h, divisor));
        assert!(frame.scene.instances.len() > 10, "{lens}: {} sprites", frame.scene.instances.len());
        if w == 1600 {
            // The large frame's sprites read every level of the mask (`GhostMasks`).
            let level = |code: f32| frame.scene.instances.iter().any(|i| i.stops.iter().any(|s| s[3] == code));
            assert!(level(1.0) && level(2.0) && level(3.0), "{lens}: not every mask level is read");
        }
        let sources = Sources { flare: &flare, lut: None, plate: None };
        let gpu = drawer.draw(&frame, &sources).unwrap();
        let cpu = frame::draw_cpu(&frame, &sources);
        let (worst, mean, lit) = display_difference(&frame, &gpu.hdr, &cpu.hdr);
        eprintln!(
            "{lens} {w}x{h} ({blades} blades, 1/{divisor}): {} sprites, display worst {worst:.3}/255, mean {mean:.5}/255, {:.0}% lit",
            frame.scene.instances.len(),
            100.0 * lit
        );
        assert!(lit > 0.05, "{lens}: only {:.1}% of the pixels are lit", 100.0 * lit);
        assert!(worst < 0.5, "{lens}: display values differ by {worst}/255");
    }
}

/// The same frame twice gives the same bytes (the fixed-point sums do not depend on which sprite lands first),
/// and a frame drawn in strips of a few rows (as a frame beyond the adapter's storage binding limit is) gives
/// the bytes of one piece.
#[test]
fn the_compute_pass_is_deterministic_and_draws_in_strips() {
    let Some(ctx) = test_context() else { return };
    let mut drawer = GpuDrawer::on(ctx);
    let flare = prepared("nikon_zoom_28_75mm", 6);
    let frame = Frame::build(&flare, None, &request([6.0, -4.0], 300, 170, 1));
    // Its largest sprites read the finer mask levels, so that every form's lookups of them are compared.
    let level = |code: f32| frame.scene.instances.iter().any(|i| i.stops.iter().any(|s| s[3] == code));
    assert!(level(1.0) && level(2.0) && level(3.0), "not every mask level is read");
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let first = drawer.draw(&frame, &sources).unwrap();
    let again = drawer.draw(&frame, &sources).unwrap();
    assert!(first.hdr.pixels.iter().any(|p| p[0] > 0.0));
    assert!(first == again, "two runs differ");
    // Every form of the pass (a hardware GPU's where lavapipe draws its own, and the reverse: the per-row
    // scan or runs, the masks gathered from the texture or read from the buffer, each item's walk in one
    // piece or split between invocations, each item worked out by its pieces or once into a buffer, or a
    // workgroup a sprite): the same bytes, in one piece and in strips.
    let own = drawer.renderer.ghost_compute_form().expect("lavapipe draws the ghosts by compute");
    for strips in [false, true] {
        if strips {
            drawer.renderer.limit_ghost_strip_bytes(5 * 301 * 24);
        }
        for scan in [false, true] {
            for gather_masks in [false, true] {
                let spread = [Some(1), Some(3), Some(8), None]
                    .into_iter()
                    .flat_map(|pieces| [false, true].map(|setup_once| (pieces, setup_once, false)));
                for (pieces, setup_once, sprite_groups) in spread.chain([(Some(1), false, true)]) {
                    let form = ComputeForm { scan, gather_masks, pieces, setup_once, sprite_groups };
                    drawer.renderer.set_ghost_compute_form(form);
                    let drawn = drawer.draw(&frame, &sources).unwrap();
                    assert!(drawn == first, "{form:?} (strips: {strips}) differs");
                }
            }
        }
    }
    drawer.renderer.set_ghost_compute_form(own);
    // Strips of 3 rows (the buffer holds (width + 1) x 24 bytes a row): 57 strips.
    drawer.renderer.limit_ghost_strip_bytes(3 * 301 * 24);
    let strips = drawer.draw(&frame, &sources).unwrap();
    assert!(strips == first, "drawn in strips, the frame differs");
    // A frame whose width needs more than the whole buffer for one row is still drawn, a row at a time.
    drawer.renderer.limit_ghost_strip_bytes(1);
    let rows = drawer.draw(&frame, &sources).unwrap();
    assert!(rows == first, "drawn a row at a time, the frame differs");
}

/// The raster pass (`ghosts.wgsl`), kept for adapters without compute, still draws the twin's image (within
/// the bounds of `tests/render.rs`), and the compute pass draws it closer.
#[test]
fn the_raster_pass_stays_in_step() {
    let Some(ctx) = test_context() else { return };
    let flare = prepared("pbrt_dgauss_50mm", 6);
    let frame = Frame::build(&flare, None, &request([-5.0, 3.0], 256, 160, 1));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let cpu = frame::draw_cpu(&frame, &sources);
    let mut raster = GpuDrawer::on(ctx);
    raster.renderer.force_raster_ghosts();
    assert!(!raster.renderer.ghosts_as_compute());
    let rastered = raster.draw(&frame, &sources).unwrap();
    let (worst_raster, mean_raster, _) = display_difference(&frame, &rastered.hdr, &cpu.hdr);
    let Some(ctx) = test_context() else { return };
    let computed = GpuDrawer::on(ctx).draw(&frame, &sources).unwrap();
    let (worst_compute, mean_compute, _) = display_difference(&frame, &computed.hdr, &cpu.hdr);
    eprintln!(
        "raster: worst {worst_raster:.3}/255, mean {mean_raster:.5}/255; compute: worst {worst_compute:.3}/255, mean {mean_compute:.5}/255"
    );
    assert!(mean_raster < 0.5 && worst_raster < 4.0, "raster {mean_raster} / {worst_raster}");
    assert!(worst_compute < 0.5 && mean_compute <= mean_raster, "compute {mean_compute} / {worst_compute}");
}

/// An anamorphic lens's frame (elliptical sprites: a y scale per mask apart from the x one; the starburst
/// stretched by N_x / N_y) on the GPU, raster and compute, against the CPU twin, the starburst on.
#[test]
fn an_anamorphic_frame_draws_the_cpu_twins_image() {
    let Some(ctx) = test_context() else { return };
    let flare = prepared("toroidal", 5);
    assert!(flare.system.is_anamorphic());
    let mut req = request([7.0, -4.0], 300, 180, 1);
    req.display.starburst = true;
    let frame = Frame::build(&flare, None, &req);
    let ellipse = |i: &flare_core::render::GhostInstance| {
        (0..3).any(|k| i.stops[k][3] != 0.0 && (i.scale_y[k] / i.stops[k][0] - 1.0).abs() > 0.1)
    };
    assert!(frame.scene.instances.iter().any(ellipse), "ellipses");
    assert!(frame.scene.globals.starburst_stretch_x > 1.0, "a stretched starburst");
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let cpu = frame::draw_cpu(&frame, &sources);
    let computed = GpuDrawer::on(ctx).draw(&frame, &sources).unwrap();
    let (worst_compute, mean_compute, lit) = display_difference(&frame, &computed.hdr, &cpu.hdr);
    let Some(ctx) = test_context() else { return };
    let mut raster = GpuDrawer::on(ctx);
    raster.renderer.force_raster_ghosts();
    let rastered = raster.draw(&frame, &sources).unwrap();
    let (worst_raster, mean_raster, _) = display_difference(&frame, &rastered.hdr, &cpu.hdr);
    eprintln!(
        "anamorphic: compute worst {worst_compute:.3}/255 mean {mean_compute:.5}/255; raster worst {worst_raster:.3}/255 \
         mean {mean_raster:.5}/255; {:.0}% lit",
        100.0 * lit
    );
    assert!(lit > 0.05);
    assert!(worst_compute < 0.5, "compute {worst_compute}");
    assert!(mean_raster < 0.5 && worst_raster < 4.0, "raster {mean_raster} / {worst_raster}");
}
