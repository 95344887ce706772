//! The renderer: shaders validated with naga (no GPU needed), the GPU image compared with its CPU twin on a
//! headless adapter (lavapipe in CI; skipped with the reason printed where no adapter exists), and image
//! files written and read back.

use flare_core::aperture::Aperture;
use flare_core::ghost::{FrameSettings, GhostSettings, GhostSystem, Sensor};
use flare_core::optics::library::builtin_lens;
use flare_core::render::cpu::{self, StarburstTexture};
use flare_core::render::gpu::{FlareRenderer, GpuContext, read_hdr, render_display};
use flare_core::render::{DisplaySettings, FlareScene, light_slopes_for_frame_position, output, shaders};
use flare_core::spectrum::Spectrum;
use flare_core::starburst::Starburst;

#[test]
fn every_shader_parses_and_validates_with_naga() {
    for (name, source) in shaders::ALL {
        let module =
            naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        for entry in ["vs_main", "fs_main"] {
            assert!(module.entry_points.iter().any(|e| e.name == entry), "{name} lacks {entry}");
        }
    }
}

struct Fixture {
    scene: FlareScene,
    mask: flare_core::aperture::ApertureMask,
    starburst: Starburst,
}

fn fixture(lens: &str, light_deg: (f64, f64), width: u32, height: u32) -> Fixture {
    fixture_with(lens, light_deg, width, height, 1)
}

fn fixture_with(lens: &str, light_deg: (f64, f64), width: u32, height: u32, divisor: u32) -> Fixture {
    let lens = builtin_lens(lens).unwrap();
    let settings = GhostSettings { spectrum: Spectrum::rgb(), ..Default::default() };
    let system = GhostSystem::build(&lens, &settings).unwrap();
    let frame_settings = FrameSettings { sensor: Sensor::full_frame_for(width, height), ..Default::default() };
    let u = light_slopes_for_frame_position(light_deg.0, light_deg.1);
    let frame = system.frame(u, &frame_settings);
    let display = DisplaySettings { accumulation_divisor: divisor, ..DisplaySettings::default() };
    let scene = FlareScene::build(&system, &frame, u, &frame_settings, &display, width, height);
    let aperture = Aperture::default();
    let mask = aperture.rasterise(256);
    let starburst = Starburst::compute(&mask, &settings.spectrum);
    Fixture { scene, mask, starburst }
}

fn gpu() -> Option<GpuContext> {
    match GpuContext::headless(true) {
        Ok(ctx) => {
            println!("GPU adapter: {} ({:?}, {:?})", ctx.adapter.name, ctx.adapter.device_type, ctx.adapter.backend);
            Some(ctx)
        }
        Err(e) => {
            println!("SKIPPED (no GPU adapter): {e}");
            None
        }
    }
}

#[test]
fn scene_instances_are_finite_and_within_budget() {
    for (lens, light) in
        [("heliar", (0.0, 0.0)), ("wide", (20.0, -10.0)), ("fisheye", (60.0, 30.0)), ("telephoto", (3.0, 1.0))]
    {
        let f = fixture(lens, light, 320, 200);
        assert_eq!(f.scene.dropped_non_finite, 0);
        assert!(f.scene.instances.iter().all(|i| i.is_finite()));
        assert!(!f.scene.instances.is_empty(), "{lens}: some ghost is drawn");
    }
}

#[test]
fn gpu_matches_its_cpu_twin() {
    let Some(ctx) = gpu() else { return };
    for (lens, light, divisor) in [("heliar", (6.0, 4.0), 1), ("dgauss", (-12.0, 7.0), 1), ("tessar", (5.0, -3.0), 2)] {
        let f = fixture_with(lens, light, 256, 160, divisor);
        let mut renderer = FlareRenderer::new(&ctx.device, &ctx.queue, wgpu::TextureFormat::Rgba8Unorm);
        renderer.set_aperture(&ctx.device, &ctx.queue, &f.mask);
        renderer.set_starburst(&ctx.device, &ctx.queue, &f.starburst);
        let gpu_display = render_display(&ctx, &mut renderer, &f.scene).unwrap();
        let gpu_hdr = read_hdr(&ctx, &renderer).unwrap();

        let texture = StarburstTexture::from_starburst(&f.starburst);
        let cpu_hdr = cpu::render_hdr(&f.scene, &f.mask, Some(&texture));
        let cpu_display = cpu::tonemap_pass(&f.scene, &cpu_hdr, None);

        // HDR: mean absolute difference relative to the mean level (half-float accumulation on the GPU).
        assert_eq!((gpu_hdr.width, gpu_hdr.height), (cpu_hdr.width, cpu_hdr.height));
        let n = (f.scene.width * f.scene.height) as usize;
        let (mut diff, mut level) = (0.0f64, 0.0f64);
        for (g, c) in gpu_hdr.pixels.iter().zip(&cpu_hdr.pixels) {
            for k in 0..3 {
                diff += (g[k] - c[k]).abs() as f64;
                level += c[k].abs() as f64;
            }
        }
        let relative = diff / level.max(1e-30);
        // Display: mean and worst 8-bit difference.
        let mut sum = 0.0f64;
        let mut worst = 0u8;
        for (g, c) in gpu_display.pixels.iter().zip(&cpu_display.pixels) {
            for k in 0..3 {
                let d = g[k].abs_diff(c[k]);
                sum += d as f64;
                worst = worst.max(d);
            }
        }
        let mean = sum / (3 * n) as f64;
        println!(
            "{lens} (accumulation 1/{divisor}): HDR relative mean difference {relative:.2e}; display mean {mean:.3}/255, worst {worst}/255"
        );
        assert!(level > 0.0, "the image is not black");
        assert!(relative < 0.01, "{lens}: HDR differs by {relative}");
        assert!(mean < 0.5, "{lens}: display differs by {mean}/255 on average");
    }
}

#[test]
fn png_and_exr_are_written_whole_and_read_back() {
    let f = fixture("tessar", (8.0, 3.0), 96, 64);
    let hdr = cpu::render_hdr(&f.scene, &f.mask, Some(&StarburstTexture::from_starburst(&f.starburst)));
    let display = cpu::tonemap_pass(&f.scene, &hdr, None);
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("flare.png");
    let exr = dir.path().join("flare.exr");
    output::write_png(&png, &display).unwrap();
    output::write_exr(&exr, &hdr).unwrap();
    let back = image::open(&png).unwrap().to_rgba8();
    assert_eq!((back.width(), back.height()), (96, 64));
    assert_eq!(back.as_raw().as_slice(), display.pixels.iter().flatten().copied().collect::<Vec<u8>>().as_slice());
    let back = output::read_plate(&exr).unwrap();
    for (a, b) in back.pixels.iter().zip(&hdr.pixels) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() <= 1e-6 * b[k].abs().max(1.0), "EXR is linear float: {a:?} vs {b:?}");
        }
    }
    assert!(output::write_png(&dir.path().join("missing/dir/x.png"), &display).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2, "no temporary files are left");
}
