//! The renderer and the one frame pipeline: shaders validated with naga and the shared uniforms checked
//! against the Rust struct (no GPU needed), frames drawn on a headless adapter compared with the CPU twin
//! (lavapipe in CI, where `FLARELAB_REQUIRE_GPU=1` makes a missing adapter a failure), and frames written as
//! PNG and layered EXR and read back.

use std::path::Path;

use flare_core::color::Tonemap;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Device, Frame, FrameRequest, GpuDrawer, LayerChoice, Sources};
use flare_core::image::HdrImage;
use flare_core::optics::library::builtin_lens;
use flare_core::output;
use flare_core::render::gpu::test_context;
use flare_core::render::{DisplaySettings, shaders};

#[test]
fn every_shader_parses_and_validates_with_naga() {
    for (name, source) in shaders::ALL {
        let module =
            naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        let entries: &[&str] = match *name {
            "common.wgsl" => &[],
            "raygrid_trace.wgsl" => &["trace_main"],
            "raygrid_splat.wgsl" => &["vs_splat", "fs_splat"],
            "raygrid_box.wgsl" => &["splat_box", "resolve_box"],
            "dof.wgsl" => &["split", "gather", "composite", "resolve"],
            "ghosts_compute.wgsl" => &["spans", "resolve"],
            "lut_compute.wgsl" => &["lut_tiles"],
            _ => &["vs_main", "fs_main"],
        };
        for entry in entries {
            assert!(module.entry_points.iter().any(|e| e.name == *entry), "{name} lacks {entry}");
        }
    }
}

/// `Globals` is declared once, in `common.wgsl` (its layout against the Rust struct: the crate's
/// `render::layouts` test); no embedded shader carries a copy of its own, and no shader compares a float with a
/// fraction to read a code (`> 0.5`): codes are `u32`s.
#[test]
fn globals_are_declared_once_and_no_shader_reads_a_float_code() {
    for (name, source) in shaders::ALL {
        assert!(source.matches("struct Globals").count() <= 1, "{name} declares Globals twice");
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shaders");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for fraction in ["> 0.5", "< 0.5", "> 1.5", "> 2.5", ">= 0.5"] {
                assert!(!code.contains(fraction), "{}:{}: a float read as a code: {line}", path.display(), n + 1);
            }
        }
    }
}

fn flare(lens: &str) -> PreparedFlare {
    PreparedFlare::new(&builtin_lens(lens).unwrap(), &FlareConfig::default()).unwrap()
}

fn request(light_deg: [f64; 2], width: u32, height: u32, divisor: u32) -> FrameRequest {
    FrameRequest {
        light_deg,
        width,
        height,
        display: DisplaySettings { flare_ev: 6.5, accumulation_divisor: divisor, ..DisplaySettings::default() },
        ..FrameRequest::default()
    }
}

#[test]
fn frame_instances_are_finite_and_within_budget() {
    for (lens, light) in
        [("heliar", [0.0, 0.0]), ("wide", [20.0, -10.0]), ("fisheye", [60.0, 30.0]), ("telephoto", [3.0, 1.0])]
    {
        let flare = flare(lens);
        let frame = Frame::build(&flare, None, &request(light, 320, 200, 1));
        assert_eq!(frame.scene.dropped_non_finite, 0);
        assert!(frame.scene.instances.iter().all(|i| i.is_finite()));
        assert!(!frame.scene.instances.is_empty(), "{lens}: some ghost is drawn");
    }
}

#[test]
fn ghost_gains_are_applied_as_the_frame_is_built() {
    let flare = flare("heliar");
    let full = Frame::build(&flare, None, &request([6.0, 4.0], 160, 100, 1));
    let g = full.scene.instance_ghosts[0];
    let mut gains = vec![1.0; flare.system.ghosts.len()];
    gains[g as usize] = 0.5;
    let other = full.scene.instance_ghosts.iter().copied().find(|&h| h != g).unwrap();
    gains[other as usize] = 0.0;
    let half = Frame::build(&flare, None, &FrameRequest { ghost_gains: gains, ..request([6.0, 4.0], 160, 100, 1) });
    assert!(!half.scene.instance_ghosts.contains(&other), "a ghost at gain 0 makes no instance");
    let pick = |f: &Frame| f.scene.instances[f.scene.instance_ghosts.iter().position(|&h| h == g).unwrap()];
    for k in 0..3 {
        assert_eq!(pick(&half).colour[k], pick(&full).colour[k] * 0.5);
    }
}

/// A GPU device lost between frames: the pipeline does not panic, it draws that frame and the next on the CPU
/// twin and its name says why.
#[test]
fn a_lost_device_falls_back_to_the_cpu_twin() {
    let Some(ctx) = test_context() else { return };
    let flare = flare("heliar");
    let frame = Frame::build(&flare, None, &request([6.0, 4.0], 96, 64, 1));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let mut device = Device::Gpu(Box::new(GpuDrawer::on(ctx)));
    device.draw(&frame, &sources).unwrap();
    assert!(matches!(device, Device::Gpu(_)));
    if let Device::Gpu(g) = &device {
        g.ctx.device.destroy();
    }
    let drawn = device.draw(&frame, &sources).unwrap();
    assert!(matches!(device, Device::LostGpu(_)), "{}", device.name());
    assert!(device.name().contains("CPU twin (the GPU device was lost"), "{}", device.name());
    assert_eq!(drawn, frame::draw_cpu(&frame, &sources));
    // And the frames after it.
    assert_eq!(device.draw(&frame, &sources).unwrap(), drawn);
    eprintln!("{}", device.name());
    // A frame beyond the adapter's texture limit is refused with the limit named, before anything is made.
    let Some(ctx) = test_context() else { return };
    let max = ctx.device.limits().max_texture_dimension_2d;
    let mut drawer = GpuDrawer::on(ctx);
    let wide = Frame::build(&flare, None, &request([6.0, 4.0], max + 1, 2, 1));
    let e = drawer.draw(&wide, &sources).unwrap_err();
    assert!(e.to_string().contains("max_texture_dimension_2d"), "{e}");
    assert!(drawer.ctx.failure().is_none(), "refused, not a validation error");
}

/// A draft keeps the brightest sprites within its fragment budget, at its divisor; with a budget that holds
/// everything it is the frame at that divisor; it never reaches an export (a full request has no draft).
#[test]
fn a_draft_keeps_the_brightest_sprites_within_its_budget() {
    let flare = flare("nikon_zoom_28_75mm");
    let base = request([8.0, 5.0], 640, 360, 1);
    let full = Frame::build(&flare, None, &base);
    assert!(full.draft.is_none());
    // A draft of divisor 4 is the frame at half the size, accumulated at half of that.
    let quarter = Frame::build(&flare, None, &request([8.0, 5.0], 320, 180, 2));
    let all: u64 = quarter.scene.instances.iter().map(|i| quarter.scene.fragments(i)).sum();
    let roomy = Frame::build(
        &flare,
        None,
        &FrameRequest { draft: Some(frame::Draft { divisor: 4, fragment_budget: all }), ..base.clone() },
    );
    assert_eq!(roomy.scene, quarter.scene, "a draft with room for every sprite is that frame");
    assert_eq!(roomy.draft.unwrap().divisor, 4);
    assert_eq!(roomy.draft.unwrap().skipped, 0);
    let budget = all / 10;
    let draft = Frame::build(
        &flare,
        None,
        &FrameRequest { draft: Some(frame::Draft { divisor: 4, fragment_budget: budget }), ..base.clone() },
    );
    let outcome = draft.draft.unwrap();
    assert_eq!((draft.scene.hdr_width, draft.scene.hdr_height), (160, 90));
    assert!(outcome.fragments <= budget && outcome.fragments > budget / 2, "{outcome:?} budget {budget}");
    assert_eq!(outcome.drawn + outcome.skipped, quarter.scene.instances.len());
    assert!(outcome.skipped > 0 && outcome.drawn > 0, "{outcome:?}");
    // Every skipped sprite that would have fitted alone is no brighter than the faintest one drawn with it...
    let peak = |i: &flare_core::render::GhostInstance| i.colour[0].max(i.colour[1]).max(i.colour[2]);
    let brightest = quarter.scene.instances.iter().map(peak).fold(0.0, f32::max);
    assert!(draft.scene.instances.iter().any(|i| peak(i) == brightest), "the brightest sprite is drawn");
    // ... and the draft's light is most of the frame's: the faint sprites it skips carry little.
    let energy = |s: &flare_core::render::FlareScene| -> f64 {
        s.instances.iter().map(|i| f64::from(peak(i)) * s.fragments(i) as f64).sum()
    };
    let share = energy(&draft.scene) / energy(&quarter.scene);
    assert!(share > 0.5, "the draft draws {share:.2} of the frame's light");
    eprintln!(
        "draft: {outcome:?}, {share:.2} of the light for {:.2} of the fragments",
        outcome.fragments as f64 / all as f64
    );
}

/// Mean relative HDR difference, the mean and worst 8-bit display difference, and the share of channels that
/// differ by more than 2 steps, GPU against CPU.
fn compare(gpu: &frame::Drawn, cpu: &frame::Drawn) -> (f64, f64, u8, f64) {
    assert_eq!((gpu.hdr.width, gpu.hdr.height), (cpu.hdr.width, cpu.hdr.height));
    let (mut diff, mut level) = (0.0f64, 0.0f64);
    for (g, c) in gpu.hdr.pixels.iter().zip(&cpu.hdr.pixels) {
        for k in 0..3 {
            diff += (g[k] - c[k]).abs() as f64;
            level += c[k].abs() as f64;
        }
    }
    assert!(level > 0.0, "the image is not black");
    let (mut sum, mut worst, mut over_two) = (0.0f64, 0u8, 0usize);
    for (g, c) in gpu.display.pixels.iter().zip(&cpu.display.pixels) {
        for k in 0..3 {
            let d = g[k].abs_diff(c[k]);
            sum += d as f64;
            worst = worst.max(d);
            over_two += usize::from(d > 2);
        }
    }
    let channels = 3 * gpu.display.pixels.len();
    (diff / level, sum / channels as f64, worst, over_two as f64 / channels as f64)
}

#[test]
fn gpu_matches_its_cpu_twin() {
    let Some(ctx) = test_context() else { return };
    let mut device = Device::Gpu(Box::new(GpuDrawer::on(ctx)));
    let plate = HdrImage { width: 64, height: 40, pixels: vec![[0.02, 0.03, 0.05, 1.0]; 64 * 40] };
    // One device for every case, as the app and the command line keep one: each case's mask, starburst and
    // plate must be uploaded when they change (the last case has 9 blades: a stale 6-blade mask would show).
    for (lens, light, divisor, with_plate, blades) in [
        ("heliar", [6.0, 4.0], 1, false, 6),
        ("dgauss", [-12.0, 7.0], 1, true, 6),
        ("tessar", [5.0, -3.0], 2, false, 6),
        ("tessar", [5.0, -3.0], 1, false, 9),
    ] {
        let shape = flare_core::aperture::ApertureShape::Blades { count: blades, rotation_deg: 0.0, roundness: 0.0 };
        let config = FlareConfig {
            aperture: flare_core::aperture::Aperture { shape, f_number: None },
            ..FlareConfig::default()
        };
        let flare = PreparedFlare::new(&builtin_lens(lens).unwrap(), &config).unwrap();
        let frame = Frame::build(&flare, None, &request(light, 256, 160, divisor));
        let sources = Sources { flare: &flare, lut: None, plate: with_plate.then_some(&plate) };
        let gpu = device.draw(&frame, &sources).unwrap();
        let cpu = frame::draw_cpu(&frame, &sources);
        let (relative, mean, worst, over_two) = compare(&gpu, &cpu);
        println!(
            "{lens} ({blades} blades, accumulation 1/{divisor}, plate {with_plate}): HDR relative mean difference {relative:.2e}; display mean {mean:.3}/255, worst {worst}/255, {:.4}% of channels over 2/255",
            100.0 * over_two
        );
        // The GPU accumulates in half floats (11-bit mantissa): a relative error of 2^-11 per sprite, which
        // averages well under 1%.
        assert!(relative < 0.01, "{lens}: HDR differs by {relative}");
        assert!(mean < 0.5, "{lens}: display differs by {mean}/255 on average");
        // Away from edges a half-float step at a display value of 1 moves ACES by under 1/255: 2 steps with
        // rounding. On an aperture edge the sampler's fixed-point bilinear weights (8-bit subtexel precision on
        // lavapipe) and the twin's exact ones put a few pixels further apart: measured on lavapipe, worst 1/255
        // with 6 blades and 3/255 on one 9-blade edge pixel (a 3.6% difference there, not explained further).
        // So: no channel beyond 4 steps, and at most 1 in 10000 beyond 2. A stale mask or a wrong pass moves
        // whole edges, thousands of pixels, by far more.
        assert!(worst <= 4, "{lens}: the worst pixel differs by {worst}/255");
        assert!(over_two <= 1e-4, "{lens}: {:.4}% of channels differ by more than 2/255", 100.0 * over_two);
    }
}

fn read_exr(path: &Path) -> std::collections::BTreeMap<String, Vec<f32>> {
    output::read_exr_channels(path).unwrap().channels
}

#[test]
fn a_frame_is_written_as_png_and_as_a_layered_exr() {
    // Faint frame-filling ghosts culled, so that some of the plate has no flare over it.
    let coating = flare_core::optics::Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None };
    let config =
        FlareConfig { intensity_threshold: Some(1e-4), coating_override: Some(coating), ..FlareConfig::default() };
    let flare = PreparedFlare::new(&builtin_lens("tessar").unwrap(), &config).unwrap();
    let (w, h) = (96u32, 64u32);
    let mut plate = HdrImage::black(w, h);
    for (k, p) in plate.pixels.iter_mut().enumerate() {
        *p = [0.1 + 0.001 * (k % 97) as f32, 0.2, 0.3, 1.0];
    }
    let dir = tempfile::tempdir().unwrap();
    let write = |plate_ev: f64, plate: Option<&HdrImage>, name: &str, ghosts: bool| {
        let mut req = request([16.0, 10.0], w, h, 1);
        req.display.plate_ev = plate_ev;
        let frame = Frame::build(&flare, None, &req);
        let sources = Sources { flare: &flare, lut: None, plate };
        let path = dir.path().join(name);
        // 32-bit floats: the layers' sums below are exact.
        let exr = output::ExrSettings { pixel_type: output::ExrPixel::Float, ..Default::default() };
        frame::render_to_file(&mut Device::Cpu, &frame, &sources, LayerChoice { ghosts, exr }, &path).unwrap();
        (path, frame::draw_cpu(&frame, &sources), frame)
    };
    // PNG: the tonemapped composite, byte for byte.
    let (png, drawn, _) = write(1.0, Some(&plate), "flare.png", false);
    let back = image::open(&png).unwrap().to_rgba8();
    assert_eq!(
        back.as_raw().as_slice(),
        drawn.display.pixels.iter().flatten().copied().collect::<Vec<u8>>().as_slice()
    );
    // EXR: composite = plate + flare; the plate layer is the plate times 2^plate_ev; the flare layer does not
    // change with the plate or its exposure.
    let (exr1, _, frame) = write(1.0, Some(&plate), "a.exr", true);
    let (exr2, _, _) = write(-2.0, Some(&plate), "b.exr", false);
    let (exr3, drawn3, frame3) = write(0.0, None, "c.exr", false);
    let (a, b, c) = (read_exr(&exr1), read_exr(&exr2), read_exr(&exr3));
    // `render_to_file` writes an EXR from the accumulation alone (no display image made): the same layers as
    // the EXR of a whole draw.
    let whole = tempfile::tempdir().unwrap();
    let exr = output::ExrSettings { pixel_type: output::ExrPixel::Float, ..Default::default() };
    let sources3 = Sources { flare: &flare, lut: None, plate: None };
    let path = whole.path().join("whole.exr");
    frame::write_drawn(&mut Device::Cpu, &frame3, &sources3, &drawn3, LayerChoice { ghosts: false, exr }, &path)
        .unwrap();
    assert_eq!(read_exr(&path), c, "an EXR of the accumulation alone is that of the whole draw");
    for name in ["R", "G", "B", "A", "flare.R", "flare.G", "flare.B", "starburst.R", "plate.R", "plate.B"] {
        assert!(a.contains_key(name), "layer {name} in {:?}", a.keys());
    }
    assert!(!c.contains_key("plate.R"), "no plate layer without a plate");
    for ch in ["R", "G", "B"] {
        let (composite, flare_layer, plate_layer) = (&a[ch], &a[&format!("flare.{ch}")], &a[&format!("plate.{ch}")]);
        for k in 0..composite.len() {
            assert_eq!(composite[k], flare_layer[k] + plate_layer[k], "composite = flare + plate at {k}");
        }
        assert_eq!(flare_layer, &b[&format!("flare.{ch}")], "the flare layer ignores --plate-ev");
        assert_eq!(flare_layer, &c[&format!("flare.{ch}")], "the flare layer ignores the plate");
    }
    // A plate pixel far from the flare (where the flare adds nothing) is the plate's own value times 2^plate_ev.
    let corner = (0..a["R"].len())
        .find(|&k| ["flare.R", "flare.G", "flare.B"].iter().all(|c| a[*c][k] == 0.0))
        .unwrap_or_else(|| {
            let lit: Vec<usize> = ["flare.R", "flare.G", "flare.B", "R"]
                .iter()
                .map(|c| a[*c].iter().filter(|v| **v != 0.0).count())
                .collect();
            let min = a["flare.G"].iter().copied().fold(f32::MAX, f32::min);
            panic!(
                "no pixel without flare: {lit:?} lit of {}, min {min}, {} instances",
                a["R"].len(),
                frame.scene.instances.len()
            )
        });
    assert_eq!(a["R"][corner], plate.pixels[corner][0] * 2.0);
    assert_eq!(b["plate.G"][corner], plate.pixels[corner][1] * 0.25);
    // Ghost layers: one per drawn ghost, named by its surfaces, adding up to the ghosts' share of the flare.
    let ghosts: Vec<&String> = a.keys().filter(|k| k.starts_with("ghost_") && k.ends_with(".R")).collect();
    assert!(!ghosts.is_empty(), "some ghost is drawn");
    assert_eq!(ghosts.len(), frame.drawn_ghosts(None).len());
    let ghost_sum: f64 = ghosts.iter().flat_map(|k| a[*k].iter()).map(|&v| f64::from(v)).sum();
    let flare_sum: f64 = a["flare.R"].iter().map(|&v| f64::from(v)).sum();
    let starburst_sum: f64 = a["starburst.R"].iter().map(|&v| f64::from(v)).sum();
    // Ghost layers add up to the flare.
    assert!(
        ((ghost_sum + starburst_sum) / flare_sum - 1.0).abs() < 1e-3,
        "ghosts {ghost_sum} + starburst {starburst_sum} = flare {flare_sum}"
    );
    let exr = output::read_exr_channels(&exr1).unwrap();
    let ghost_bits = exr.parts.iter().flat_map(|p| &p.bits).find(|(name, _)| name.starts_with("ghost_")).map(|b| b.1);
    assert_eq!(ghost_bits, Some(32), "--exr-type float: ghost layers in 32-bit floats");
    // Bad output: no folder, or a PNG asked for ghost layers; nothing is left behind.
    let frame = Frame::build(&flare, None, &request([8.0, 3.0], w, h, 1));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let bad = dir.path().join("missing/dir/x.png");
    assert!(frame::render_to_file(&mut Device::Cpu, &frame, &sources, LayerChoice::default(), &bad).is_err());
    let e = frame::render_to_file(
        &mut Device::Cpu,
        &frame,
        &sources,
        LayerChoice { ghosts: true, ..Default::default() },
        &dir.path().join("x.png"),
    )
    .unwrap_err();
    assert!(e.to_string().contains("EXR"), "{e}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4, "only the four files written");
    // A plate reads back as written (EXR plates are linear).
    let back = output::read_plate(&exr1).unwrap();
    assert_eq!(back.pixels[corner][0], a["R"][corner]);
}

#[test]
fn tonemaps_and_exposures_reach_the_display_image() {
    let flare = flare("heliar");
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let mean = |display: DisplaySettings| {
        let frame = Frame::build(&flare, None, &FrameRequest { display, ..request([6.0, 4.0], 64, 40, 1) });
        let d = frame::draw_cpu(&frame, &sources).display;
        d.pixels.iter().map(|p| f64::from(p[1])).sum::<f64>() / d.pixels.len() as f64
    };
    let base = DisplaySettings { flare_ev: 8.0, tonemap: Tonemap::Reinhard, ..DisplaySettings::default() };
    assert!(mean(DisplaySettings { flare_ev: 9.0, ..base }) > mean(base), "a stop more is brighter");
    assert!(mean(DisplaySettings { tonemap: Tonemap::None, ..base }) != mean(base));
}

#[test]
fn exr_value_types_compressions_and_ghost_data_windows() {
    let flare = flare("tessar");
    let (w, h) = (120u32, 80u32);
    let mut req = request([12.0, 7.0], w, h, 1);
    req.display.flare_ev = 22.0;
    let frame = Frame::build(&flare, None, &req);
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let dir = tempfile::tempdir().unwrap();
    let write = |pixel_type, compression, name: &str| {
        let exr = output::ExrSettings { pixel_type, compression };
        let path = dir.path().join(name);
        frame::render_to_file(&mut Device::Cpu, &frame, &sources, LayerChoice { ghosts: true, exr }, &path).unwrap();
        (output::read_exr_channels(&path).unwrap(), std::fs::metadata(&path).unwrap().len())
    };
    let (float, float_bytes) = write(output::ExrPixel::Float, output::ExrCompression::Zip, "float.exr");
    // The starburst's core is far beyond half's range: auto keeps the layers that hold it in 32 bits and writes
    // the ghost layers (and any layer that fits) in 16.
    let core = float.channels["flare.G"].iter().copied().fold(0.0f32, f32::max);
    assert!(core > output::HALF_MAX, "the light's core: {core}");
    let (auto, auto_bytes) = write(output::ExrPixel::Auto, output::ExrCompression::Zip, "auto.exr");
    let bits =
        |c: &output::ExrChannels, name: &str| c.parts.iter().flat_map(|p| &p.bits).find(|b| b.0 == name).unwrap().1;
    assert_eq!(bits(&auto, "flare.G"), 32);
    let ghost_names: Vec<String> =
        auto.channels.keys().filter(|k| k.starts_with("ghost_") && k.ends_with(".G")).cloned().collect();
    assert!(ghost_names.len() > 3, "{ghost_names:?}");
    // Every ghost layer is its own part, named after it, whose data window holds every lit pixel and no
    // more than the frame; the values placed back equal the float file's within half's precision.
    let fits = |name: &str| float.channels[name].iter().all(|v| v.abs() <= output::HALF_MAX);
    assert!(ghost_names.iter().any(|n| fits(n)), "some ghost layer fits half");
    for name in &ghost_names {
        let layer_fits = ["R", "G", "B"].iter().all(|c| fits(&name.replace(".G", &format!(".{c}"))));
        assert_eq!(bits(&auto, name), if layer_fits { 16 } else { 32 }, "{name}");
        let layer = name.trim_end_matches(".G");
        let part = auto.parts.iter().find(|p| p.name.as_deref() == Some(layer)).expect(layer);
        assert!(part.size.0 <= w as usize && part.size.1 <= h as usize);
        let (f, a) = (&float.channels[name], &auto.channels[name]);
        for k in 0..f.len() {
            assert!((f[k] - a[k]).abs() <= f[k].abs() * 1e-3 + 1e-3, "{name} at {k}: {} vs {}", f[k], a[k]);
        }
    }
    assert!(
        auto.parts.iter().any(|p| p.name.as_deref().is_some_and(|n| n.starts_with("ghost_"))
            && p.size.0 * p.size.1 < (w * h / 4) as usize),
        "some ghost covers less than a quarter of the frame and its part is that small"
    );
    assert_eq!(auto.parts[0].name.as_deref(), Some("rgba"));
    assert!(auto_bytes < float_bytes, "auto {auto_bytes} B, float {float_bytes} B");
    // Half: every layer 16 bits, the core clamped to half's largest value.
    let (half, half_bytes) = write(output::ExrPixel::Half, output::ExrCompression::Zip, "half.exr");
    assert_eq!(bits(&half, "flare.G"), 16);
    assert_eq!(half.channels["flare.G"].iter().copied().fold(0.0f32, f32::max), output::HALF_MAX);
    assert!(half_bytes < auto_bytes);
    // Every compression the crate writes reads back (the lossless ones exactly).
    for c in output::ExrCompression::ALL {
        let (back, bytes) = write(output::ExrPixel::Float, c, &format!("{}.exr", c.name()));
        let lossless = matches!(
            c,
            output::ExrCompression::None
                | output::ExrCompression::Rle
                | output::ExrCompression::Zips
                | output::ExrCompression::Zip
                | output::ExrCompression::Piz
        );
        if lossless {
            assert_eq!(back.channels, float.channels, "{} is lossless", c.name());
        } else {
            let (a, b) = (&back.channels["R"], &float.channels["R"]);
            let worst = a.iter().zip(b).map(|(x, y)| ((x - y) / y.abs().max(1e-3)).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-2, "{}: worst relative error {worst}", c.name());
        }
        println!("{}: {bytes} bytes", c.name());
    }
    assert!(output::ExrCompression::parse("DWAA").unwrap_err().contains("cannot be written"));
    // Issue 61: B44 panicked on a rayon thread (SIGABRT) for one-pixel-tall parts and lost 65504 and negatives:
    // refused by name, in a document, and by the writer itself.
    for c in [output::ExrCompression::B44, output::ExrCompression::B44a] {
        assert!(output::ExrCompression::parse(c.name()).unwrap_err().contains("not written here"));
        let settings = output::ExrSettings { pixel_type: output::ExrPixel::Float, compression: c };
        let thin = flare_core::image::HdrImage::black(50, 1);
        let layers = output::FrameLayers {
            composite: thin.clone(),
            flare: thin.clone(),
            starburst: thin.clone(),
            dirt: None,
            plate: None,
            ghosts: vec![("ghost_1_2".into(), thin)],
        };
        let e = output::write_exr_layers(&dir.path().join("thin.exr"), &layers, settings).unwrap_err();
        assert!(e.to_string().contains("not written here"), "{e}");
        assert!(!dir.path().join("thin.exr").exists());
        let doc = flare_core::preset::Document { exr: settings, ..Default::default() };
        assert!(doc.check().unwrap_err().to_string().contains("exr.compression"));
    }
    assert!(output::ExrCompression::parse("zip").is_ok());
}

#[test]
fn an_exr_names_its_working_space_and_primaries() {
    let flare = flare("tessar");
    let frame = Frame::build(&flare, None, &request([12.0, 7.0], 64, 40, 1));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.exr");
    frame::render_to_file(&mut Device::Cpu, &frame, &sources, LayerChoice::default(), &path).unwrap();
    let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
    let attributes = &meta.headers[0].shared_attributes;
    let c = attributes.chromaticities.expect("chromaticities");
    assert_eq!((c.red.0, c.green.1, c.white.0), (0.64, 0.60, 0.3127));
    let key = exr::meta::attribute::Text::from("colorspace");
    let own = &meta.headers[0].own_attributes.other;
    let name = attributes.other.get(&key).or_else(|| own.get(&key)).expect("colorspace");
    assert!(format!("{name:?}").contains(output::WORKING_SPACE), "{name:?}");
}
