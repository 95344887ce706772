//! The command line as scripts use it: exact JSON keys, agreement with the reference figures, exit code 2
//! with a one-line reason on every error, and no panic on hostile input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use flare_core::optics::{D_LINE_NM, FirstOrder, LightPath, TraceOptions, Tracer, pupil_ray};
use serde_json::Value;

fn flarelab(args: &[&str]) -> Output {
    // The tests' LUT cache: never the user's.
    let cache = std::env::temp_dir().join(format!("flarelab-test-cache-{}", std::process::id()));
    flarelab_cached(args, &cache)
}

/// `flarelab` with its LUT cache in `cache`.
fn flarelab_cached(args: &[&str], cache: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_flarelab"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env("FLARELAB_CACHE_DIR", cache)
        .output()
        .expect("runs")
}

fn json_of(out: &Output) -> Value {
    assert!(out.status.success(), "failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON document")
}

fn repo(path: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path).display().to_string()
}

fn reference(id: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(repo(&format!("tests/data/reference/{id}.json"))).unwrap()).unwrap()
}

/// Runs a command that must fail: exit code 2, one line on stderr, no panic.
fn refusal(args: &[&str]) -> String {
    let out = flarelab(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked") && !stderr.contains("internal error"), "{args:?}: {stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: one line please: {stderr}");
    stderr
}

#[test]
fn lens_info_json_has_the_documented_keys_and_reference_values() {
    for id in ["heliar_tronnier_us2645156", "pbrt_wide_22mm"] {
        let file = repo(&format!("lenses/{id}.json"));
        let info = json_of(&flarelab(&["lens", "info", &file, "--json"]));
        let r = &reference(id)["first_order"];
        for (ours, theirs) in [("efl_mm", "efl"), ("bfd_mm", "bfd"), ("entrance_pupil_diameter_mm", "enp_diameter")] {
            let (a, b) = (info[ours].as_f64().unwrap(), r[theirs].as_f64().unwrap());
            assert!((a - b).abs() < 1e-9 * b.abs(), "{id} {ours}: {a} vs {b}");
        }
        for key in ["entrance_pupil_z_mm", "f_number"] {
            assert!(info[key].as_f64().is_some(), "{id}: {key}");
        }
        let n = reference(id)["ghosts"]["count"].as_u64().unwrap();
        assert_eq!(info["ghost_count"].as_u64(), Some(n));
        assert_eq!(info["surfaces"].as_u64().unwrap() as usize, info["surface_table"].as_array().unwrap().len());
    }
    // A built-in lens by name works from any folder.
    let info = json_of(&flarelab(&["lens", "info", "heliar", "--json"]));
    assert_eq!(info["ghost_count"], 28);
    let human = String::from_utf8(flarelab(&["lens", "info", "tessar"]).stdout).unwrap();
    assert!(human.contains("focal length") && human.contains("(stop)"), "{human}");
}

#[test]
fn trace_json_matches_reference_rays_and_ghosts() {
    let id = "pbrt_dgauss_50mm";
    let file = repo(&format!("lenses/{id}.json"));
    let r = reference(id);
    // Our entrance pupil differs from ray-optics' by up to 1e-7 relative (see the core's reference test),
    // which moves a landing by well under 1e-6 mm.
    for ray in r["rays"].as_array().unwrap().iter().filter(|x| !x["x"].is_null()).step_by(5) {
        let pupil = format!("{},{}", ray["px"], ray["py"]);
        let out = json_of(&flarelab(&[
            "trace",
            &file,
            "--field-deg",
            &ray["theta_deg"].to_string(),
            "--pupil",
            &pupil,
            "--json",
        ]));
        assert_eq!(out["status"], "ok");
        for (ours, theirs) in [("x_mm", "x"), ("y_mm", "y")] {
            let (a, b) = (out[ours].as_f64().unwrap(), ray[theirs].as_f64().unwrap());
            assert!((a - b).abs() < 1e-6, "{ray}: {ours} {a} vs {b}");
        }
    }
    // Ghost rays: the command line answers exactly what the library answers (the library's agreement with
    // the reference, to 1e-9 mm from the reference's own pupil, is the core's reference test).
    let lens = flare_core::optics::formats::load_lens_file(Path::new(&file)).unwrap();
    let fo = FirstOrder::d_line(&lens).unwrap();
    for (i, j) in [(0, 9), (2, 4), (6, 10)] {
        let tracer = Tracer::new(&lens, &LightPath::ghost(&lens, i, j).unwrap(), D_LINE_NM, fo.sensor_z_mm());
        for (theta_deg, py) in [(0.0, 0.5), (10.0, -1.0), (-15.0, 0.25), (20.0, 0.0)] {
            let expected = tracer
                .trace(&pupil_ray(&fo.entrance_pupil(), f64::to_radians(theta_deg), 0.0, py), TraceOptions::default());
            let out = json_of(&flarelab(&[
                "trace",
                &file,
                "--field-deg",
                &theta_deg.to_string(),
                "--pupil",
                &format!("0,{py}"),
                "--ghost",
                &format!("{i},{j}"),
                "--json",
            ]));
            assert_eq!(out["status"], expected.status.word(), "ghost {i},{j} at {theta_deg} deg, py {py}");
            assert_eq!(out["surface"].as_u64().map(|s| s as usize), expected.status.surface());
            assert_eq!(
                out["y_mm"].as_f64(),
                expected.sensor_point_mm.map(|p| p.y),
                "ghost {i},{j} at {theta_deg} deg, py {py}"
            );
        }
    }
}

#[test]
fn the_same_lens_in_three_formats_gives_the_same_answers() {
    let dir = tempfile::tempdir().unwrap();
    let mut answers = Vec::new();
    for (format, ext) in [("json", "json"), ("zmx", "zmx"), ("dat", "dat")] {
        let path = dir.path().join(format!("tessar.{ext}"));
        let out = flarelab(&["lens", "convert", "tessar", "--to", format, "-o", path.to_str().unwrap()]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let p = path.to_str().unwrap();
        let info = json_of(&flarelab(&["lens", "info", p, "--json"]));
        let trace =
            json_of(&flarelab(&["trace", p, "--field-deg", "12", "--pupil", "0.2,-0.6", "--ghost", "1,6", "--json"]));
        answers.push((
            info["efl_mm"].as_f64().unwrap(),
            info["ghost_count"].clone(),
            trace["x_mm"].as_f64(),
            trace["y_mm"].as_f64(),
        ));
    }
    for a in &answers[1..] {
        assert!((a.0 - answers[0].0).abs() < 1e-12 && a.1 == answers[0].1, "{answers:?}");
        let (y, y0) = (a.3.unwrap(), answers[0].3.unwrap());
        assert!((y - y0).abs() < 1e-11 && (a.2.unwrap() - answers[0].2.unwrap()).abs() < 1e-11, "{answers:?}");
    }
}

#[test]
fn errors_exit_2_with_one_line_and_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p.to_str().unwrap().to_owned()
    };
    let empty = write("empty.json", b"");
    let garbage = write("garbage.zmx", &(0..2000u32).map(|i| (i * 7919 % 251) as u8).collect::<Vec<_>>());
    let truncated = write("cut.json", &std::fs::read(repo("lenses/pbrt_fisheye_10mm.json")).unwrap()[..900]);
    let afocal = write("afocal.dat", b"0 5 0 10\n0 10 1.5 20\n0 40 1 20\n");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["lens", "info", "no/such/file.json"], "no such file"),
        (vec!["lens", "info", &empty], "empty"),
        (vec!["lens", "info", &garbage], "not text"),
        (vec!["lens", "info", &truncated], "JSON line"),
        (vec!["lens", "info", &afocal], "afocal"),
        (vec!["trace", &afocal, "--field-deg", "1", "--pupil", "0,0"], "afocal"),
        (vec!["trace", "heliar", "--field-deg", "90", "--pupil", "0,0"], "--field-deg"),
        (vec!["trace", "heliar", "--field-deg", "NaN", "--pupil", "0,0"], "--field-deg"),
        (vec!["trace", "heliar", "--field-deg", "1", "--pupil", "0,0", "--ghost", "5,7"], "aperture stop"),
        (vec!["trace", "heliar", "--field-deg", "1", "--pupil", "0,0", "--ghost", "7,2"], "i < j"),
        (vec!["trace", "heliar", "--field-deg", "1", "--pupil", "0,0", "--ghost", "1,99"], "only 9 surfaces"),
        (vec!["trace", "heliar", "--field-deg", "1", "--pupil", "0,0", "--wavelength-nm", "-3"], "wavelength"),
        (vec!["lens", "convert", "heliar", "--to", "zmx", "-o", "/nonexistent-dir/x.zmx"], "writing"),
    ];
    for (args, word) in cases {
        let message = refusal(&args);
        assert!(message.contains(word), "{args:?}: `{message}` lacks `{word}`");
    }
    // A failed ray is an answer, not an error.
    let out =
        json_of(&flarelab(&["trace", "heliar", "--field-deg", "20", "--pupil", "0,-1", "--apply-apertures", "--json"]));
    assert_eq!(out["status"], "vignetted");
    assert_eq!(out["surface"], 0);
}

#[test]
fn no_display_prints_how_to_use_the_command_line() {
    let out = flarelab(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("no display") && stderr.contains("flarelab lens info") && stderr.contains("flarelab trace"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
    assert!(Path::new(&repo("lenses/README.md")).exists(), "the lens sources ship with the lenses");
}

#[test]
fn ghosts_json_lists_every_ghost_with_its_sprite() {
    let out = json_of(&flarelab(&["ghosts", "heliar", "--field-deg", "10", "--wavelength-nm", "587.5618", "--json"]));
    let ghosts = out["ghosts"].as_array().unwrap();
    assert_eq!(ghosts.len(), 28);
    let lens = flare_core::optics::library::builtin_lens("heliar").unwrap();
    let settings = flare_core::ghost::GhostSettings {
        spectrum: flare_core::spectrum::Spectrum::single(D_LINE_NM).unwrap(),
        ..Default::default()
    };
    let system = flare_core::ghost::GhostSystem::build(&lens, &settings).unwrap();
    let u = [0.0, 10f64.to_radians().tan()];
    for (g, row) in ghosts.iter().enumerate() {
        for key in ["i", "j", "center_mm", "radius_mm", "intensity", "rgb", "straddles_stop", "culled", "focus_mm"] {
            assert!(row.get(key).is_some(), "ghost {g} lacks {key}: {row}");
        }
        // focus_mm is -A/C of the ghost's d-line matrix from the entrance to the image plane (null: afocal).
        let (i, j) = (row["i"].as_u64().unwrap() as usize, row["j"].as_u64().unwrap() as usize);
        let fo = FirstOrder::d_line(&lens).unwrap();
        let m = flare_core::optics::PathMatrices::compute(
            &lens,
            &LightPath::ghost(&lens, i, j).unwrap(),
            D_LINE_NM,
            fo.sensor_z_mm(),
        )
        .sensor_from_entrance;
        match row["focus_mm"].as_f64() {
            Some(focus) => assert_eq!(focus, -m.a / m.c, "ghost {i}-{j}"),
            None => assert_eq!(m.c, 0.0, "ghost {i}-{j} is not afocal"),
        }
        let (centre, radius) = system.stop_image_sprite(g, 0, u).unwrap();
        assert_eq!(row["center_mm"][1].as_f64().unwrap(), centre[1]);
        assert_eq!(row["radius_mm"].as_f64().unwrap(), radius);
        assert!(row["culled"].is_null() || row["culled"].is_string());
        assert_eq!(
            row["straddles_stop"].as_bool().unwrap(),
            row["i"].as_u64().unwrap() < 5 && row["j"].as_u64().unwrap() > 5
        );
    }
    let sprites = &out["sprites"];
    let sum = ["drawn", "below_threshold", "off_sensor", "empty_entrance_region"]
        .iter()
        .map(|k| sprites[k].as_u64().unwrap())
        .sum::<u64>();
    assert_eq!(sum, sprites["total"].as_u64().unwrap());
}

#[test]
fn render_writes_png_and_exr_and_refuses_bad_options() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("flare.png");
    let exr = dir.path().join("flare.exr");
    for (out, extra) in [
        (&png, vec!["--coating", "quarter-wave:520"]),
        (&exr, vec!["--aperture", "blades:7:10:0.3", "--f-number", "5.6"]),
    ] {
        let mut args = vec![
            "render",
            "dgauss",
            "--light-deg",
            "6,-3",
            "--size",
            "160x90",
            "--device",
            "cpu",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        let result = flarelab(&args);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    }
    let image = image::open(&png).unwrap().to_rgba8();
    assert_eq!((image.width(), image.height()), (160, 90));
    let lit = image.pixels().filter(|p| p[0] > 40 || p[1] > 40 || p[2] > 40).count();
    assert!(lit > 50, "a flare is visible: {lit} lit pixels");
    let hdr = image::open(&exr).unwrap().to_rgba32f();
    assert!(hdr.pixels().all(|p| p.0.iter().all(|v| v.is_finite() && *v >= 0.0)));
    assert!(hdr.pixels().any(|p| p[0] > 1.0), "EXR keeps HDR values above 1");
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_owned();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--size".into(), "0x10".into(), "-o".into(), out("a.png")], "--size"),
        (vec!["--aperture".into(), "blades:40".into(), "-o".into(), out("a.png")], "blades"),
        (vec!["--coating".into(), "sparkly".into(), "-o".into(), out("a.png")], "--coating"),
        (vec!["--spectrum".into(), "64".into(), "-o".into(), out("a.png")], "--spectrum"),
        (vec!["-o".into(), out("a.jpg")], ".png or .exr"),
        (vec!["--method".into(), "magic".into(), "-o".into(), out("a.png")], "--method"),
        (vec!["--light-deg".into(), "95,0".into(), "-o".into(), out("a.png")], "--light-deg"),
        (vec!["--background".into(), out("nope.png"), "-o".into(), out("a.png")], "nope.png"),
    ];
    for (extra, word) in cases {
        let mut args: Vec<&str> = vec!["render", "heliar", "--device", "cpu"];
        args.extend(extra.iter().map(String::as_str));
        let message = refusal(&args);
        assert!(message.contains(word), "{args:?}: `{message}` lacks `{word}`");
    }
    assert!(!dir.path().join("a.png").exists(), "nothing is written on an error");
}

#[test]
fn render_on_the_gpu_matches_the_cpu_twin() {
    let dir = tempfile::tempdir().unwrap();
    let (gpu_png, cpu_png) = (dir.path().join("gpu.png"), dir.path().join("cpu.png"));
    let run = |device: &str, out: &Path| {
        flarelab(&[
            "render",
            "tessar",
            "--light-deg",
            "5,2",
            "--size",
            "192x108",
            "--device",
            device,
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let gpu = run("gpu", &gpu_png);
    if !gpu.status.success() {
        let stderr = String::from_utf8_lossy(&gpu.stderr);
        assert!(stderr.contains("no GPU adapter"), "{stderr}");
        flare_core::render::gpu::skip_without_gpu(&stderr);
        return;
    }
    assert!(run("cpu", &cpu_png).status.success());
    let (a, b) = (image::open(&gpu_png).unwrap().to_rgba8(), image::open(&cpu_png).unwrap().to_rgba8());
    let mean =
        a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y) as f64).sum::<f64>() / a.as_raw().len() as f64;
    assert!(mean < 1.0, "GPU and CPU images differ by {mean}/255 on average");
}

/// A render on the GPU with no runtime folder in the environment (a container, ssh, cron) prints no error line:
/// libwayland's "XDG_RUNTIME_DIR is invalid or not set" came on every GPU device made, although nothing was
/// wrong (issue 60).
#[test]
fn a_render_without_a_runtime_folder_prints_no_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    let cache = dir.path().join("cache");
    let output = Command::new(env!("CARGO_BIN_EXE_flarelab"))
        .args(["render", "tessar", "--size", "96x64", "--device", "gpu", "-o", out.to_str().unwrap()])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("XDG_RUNTIME_DIR")
        .env("FLARELAB_CACHE_DIR", &cache)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() {
        assert!(stderr.contains("no GPU adapter"), "{stderr}");
        flare_core::render::gpu::skip_without_gpu(&stderr);
        return;
    }
    assert!(stderr.lines().all(|l| !l.to_lowercase().contains("error")), "{stderr}");
    assert!(stderr.contains("rendered on"), "{stderr}");
}

#[test]
fn render_takes_an_aperture_image_and_a_background_plate() {
    let dir = tempfile::tempdir().unwrap();
    // A grayscale aperture: a bright square on black.
    let aperture = dir.path().join("square.png");
    image::GrayImage::from_fn(64, 64, |x, y| {
        image::Luma([if (16..48).contains(&x) && (16..48).contains(&y) { 255 } else { 0 }])
    })
    .save(&aperture)
    .unwrap();
    // A mid-grey plate (sRGB 128).
    let plate = dir.path().join("plate.png");
    image::RgbImage::from_pixel(32, 18, image::Rgb([128, 128, 128])).save(&plate).unwrap();
    let out = dir.path().join("flare.png");
    let result = flarelab(&[
        "render",
        "heliar",
        "--light-deg",
        "3,2",
        "--size",
        "128x72",
        "--device",
        "cpu",
        "--tonemap",
        "none",
        "--exposure-ev",
        "0",
        "--aperture",
        &format!("image:{}", aperture.display()),
        "--background",
        plate.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let image = image::open(&out).unwrap().to_rgb8();
    // With the flare at 0 EV (x1), the plate at 0 EV and no tonemap the plate comes back as itself wherever the
    // flare adds next to nothing.
    let corner = image.get_pixel(2, 70);
    assert!(corner.0.iter().all(|&c| (126..=140).contains(&c)), "plate pixel {corner:?}");
}

#[test]
fn render_without_any_adapter_says_so_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    // Ask wgpu for a backend this platform does not have: no adapter at all.
    let backend = if cfg!(target_os = "macos") { "dx12" } else { "metal" };
    let run = |device: &str| {
        Command::new(env!("CARGO_BIN_EXE_flarelab"))
            .args(["render", "heliar", "--size", "64x36", "--device", device, "-o", out.to_str().unwrap()])
            .env("WGPU_BACKEND", backend)
            .output()
            .unwrap()
    };
    let result = run("gpu");
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no GPU adapter") && stderr.contains("--device cpu"), "{stderr}");
    assert!(!out.exists());
    // The default, auto, says so and draws on the CPU twin.
    let result = run("auto");
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert!(stderr.contains("no GPU") && stderr.contains("CPU twin"), "{stderr}");
    assert!(out.exists());
}

#[test]
fn render_with_the_ray_traced_methods() {
    let dir = tempfile::tempdir().unwrap();
    for (method, grid) in [("raygrid", Some("16")), ("reference", Some("32")), ("reference", None)] {
        let out = dir.path().join(format!("{method}-{}.png", grid.unwrap_or("default")));
        let mut args = vec!["render", "tessar", "--light-deg", "5,3", "--size", "96x64", "--method", method];
        args.extend(grid.iter().flat_map(|g| ["--grid", g]));
        args.extend(["--exposure-ev", "11.55", "--coating", "lens", "-o", out.to_str().unwrap()]);
        let result = flarelab(&args);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(result.status.success(), "{args:?}: {stderr}");
        // Ray grids trace on the GPU when there is one (lavapipe counts), the reference on the CPU.
        let expected = if method == "raygrid" && !std::env::var("FLARELAB_REQUIRE_GPU").is_ok_and(|v| v == "1") {
            "ray"
        } else if method == "raygrid" {
            "ray grids on the GPU"
        } else {
            "ray-traced on the CPU"
        };
        assert!(stderr.contains(expected), "{stderr}");
        let image = image::open(&out).unwrap().to_rgba8();
        assert_eq!((image.width(), image.height()), (96, 64));
        let lit = image.pixels().filter(|p| p[0] > 40 || p[1] > 40 || p[2] > 40).count();
        assert!(lit > 50, "{method}: a flare is visible: {lit} lit pixels");
    }
    // Sequences and per-ghost layers as with the other methods: a tracked light over two frames.
    let track = dir.path().join("track.csv");
    std::fs::write(&track, "frame,x_px,y_px\n1,30,20\n2,60,40\n").unwrap();
    for method in [["--method", "raygrid", "--grid", "16"], ["--method", "reference", "--grid", "16"]] {
        let pattern = dir.path().join(format!("{}/f.####.exr", method[1]));
        let mut args = vec!["render", "tessar", "--size", "96x64", "--frames", "1-2", "--layers", "ghosts"];
        args.extend(method);
        args.extend(["--track", track.to_str().unwrap(), "-o", pattern.to_str().unwrap()]);
        let result = flarelab(&args);
        assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
        for frame in ["0001", "0002"] {
            let file = dir.path().join(format!("{}/f.{frame}.exr", method[1]));
            let names = exr_channels(&file);
            assert!(names.iter().any(|n| n == "flare.R"), "{names:?}");
            assert!(names.iter().filter(|n| n.starts_with("ghost_") && n.ends_with(".R")).count() > 3, "{names:?}");
        }
    }
    // Asked for the CPU, ray grids stay there; the reference is never on the GPU.
    let out = dir.path().join("cpu.png");
    let result = flarelab(&[
        "render",
        "tessar",
        "--size",
        "96x64",
        "--method",
        "raygrid",
        "--grid",
        "16",
        "--device",
        "cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&result.stderr).contains("ray-traced on the CPU"));
    let out = dir.path().join("bad.png");
    let out = out.to_str().unwrap();
    for (args, word) in [
        (vec!["render", "tessar", "--method", "reference", "--device", "gpu", "-o", out], "f64 CPU tracer"),
        (vec!["render", "tessar", "--method", "raygrid", "--grid", "16", "--gpu-samples", "9", "-o", out], "1 to 8"),
        (vec!["render", "tessar", "--method", "raygrid", "-o", out], "--grid"),
        (vec!["render", "tessar", "--grid", "32", "-o", out], "--grid"),
        (vec!["render", "tessar", "--method", "reference", "--grid", "1", "-o", out], "--grid 1"),
        (vec!["render", "tessar", "--method", "raygrid", "--grid", "99999", "-o", out], "--grid 99999"),
    ] {
        let message = refusal(&args);
        assert!(message.contains(word), "{args:?}: `{message}` lacks `{word}`");
    }
}

/// The ray-traced methods draw the frame's own sensor: an 18 mm sensor at 160x96 is the middle of the 36 mm
/// frame at 320x192 (the same pixels a millimetre, the same pixel centres), ghost for ghost.
#[test]
fn the_ray_traced_methods_draw_the_frames_own_sensor() {
    let dir = tempfile::tempdir().unwrap();
    let devices: &[&str] =
        if std::env::var("FLARELAB_REQUIRE_GPU").is_ok_and(|v| v == "1") { &["cpu", "gpu"] } else { &["cpu"] };
    for &device in devices {
        let render = |sensor_mm: &str, size: &str| {
            let out = dir.path().join(format!("{device}-{sensor_mm}.exr"));
            let args = [
                "render",
                "tessar",
                "--light-deg",
                "5,3",
                "--size",
                size,
                "--sensor-mm",
                sensor_mm,
                "--method",
                "raygrid",
                "--grid",
                "16",
                "--device",
                device,
                "--no-starburst",
                "--exposure-ev",
                "10",
                "--coating",
                "lens",
                "-o",
                out.to_str().unwrap(),
            ];
            let result = flarelab(&args);
            assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
            flare_core::output::read_exr_channels(&out).unwrap()
        };
        let (small, whole) = (render("18", "160x96"), render("36", "320x192"));
        assert_eq!((small.width, small.height), (160, 96));
        // The grid follows the part of each ghost that lands in the window, so the smaller window samples its
        // ghosts more finely: the same light in the same place, not the same bytes.
        let (mut sums, mut difference) = ([[0.0f64; 3]; 2], 0.0f64);
        for c in ["flare.R", "flare.G", "flare.B"] {
            let (a, b) = (&small.channels[c], &whole.channels[c]);
            for y in 0..96 {
                for x in 0..160 {
                    let (p, q) = (f64::from(a[y * 160 + x]), f64::from(b[(y + 48) * 320 + x + 80]));
                    for (k, v) in [p, q].into_iter().enumerate() {
                        sums[k][0] += v;
                        sums[k][1] += v * (x as f64 + 0.5);
                        sums[k][2] += v * (y as f64 + 0.5);
                    }
                    difference += (p - q).abs();
                }
            }
        }
        let [a, b] = sums;
        assert!(b[0] > 0.0, "{device}: the middle of the frame has ghosts");
        let (energy, mean_difference) = (a[0] / b[0], difference / b[0]);
        let shift = (a[1] / a[0] - b[1] / b[0]).hypot(a[2] / a[0] - b[2] / b[0]);
        eprintln!(
            "{device}: energy 18 mm / 36 mm {energy:.4}, centroid {shift:.3} px apart, mean difference {mean_difference:.3}"
        );
        assert!((energy - 1.0).abs() < 0.02, "{device}: energy ratio {energy}");
        assert!(shift < 0.25, "{device}: the ghosts' centroid moved {shift} px");
        assert!(mean_difference < 0.12, "{device}: mean difference {mean_difference} of the light");
    }
}

#[test]
fn bench_writes_csv_markdown_and_plot_and_updates_the_readme() {
    let dir = tempfile::tempdir().unwrap();
    let readme = dir.path().join("README.md");
    std::fs::write(&readme, "# Title\n\nBefore.\n\n<!-- bench:start -->\nold table\n<!-- bench:end -->\n\nAfter.\n")
        .unwrap();
    let out = dir.path().join("bench");
    let result = flarelab(&[
        "bench",
        "--lens",
        "tessar",
        "--field-deg",
        "0,8",
        "--size",
        "96x64",
        "--grids",
        "8,16",
        "--reference-grid",
        "64",
        "--repeats",
        "2",
        "--update-readme",
        readme.to_str().unwrap(),
        "--images",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    for method in ["reference", "paraxial", "raygrid-16"] {
        let path = out.join(format!("images/brendel_tessar_usp2854889_8deg_{method}.png"));
        let image = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8();
        assert_eq!((image.width(), image.height()), (96, 64));
    }
    let csv = std::fs::read_to_string(out.join("bench.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for column in ["lens", "field_deg", "method", "ms_median", "psnr_db", "ssim"] {
        assert!(header.contains(&column), "{header:?} lacks {column}");
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let column = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r[column("method")]).collect();
    assert_eq!(methods.iter().filter(|m| **m == "paraxial").count(), 2, "{methods:?}");
    for m in ["reference", "raygrid-8", "raygrid-16"] {
        assert_eq!(methods.iter().filter(|x| **x == m).count(), 2, "{m}: {methods:?}");
    }
    for r in &rows {
        let number = |name: &str| r[column(name)].parse::<f64>().unwrap();
        assert!(number("ms_median") > 0.0, "{r:?}");
        let (psnr, ssim) = (number("psnr_db"), number("ssim"));
        assert!(psnr.is_finite() && psnr > 5.0 && (-1.0..=1.0).contains(&ssim), "{r:?}");
        if r[column("method")] == "reference" {
            assert_eq!(psnr, 100.0, "the reference against itself");
        }
    }
    // A finer ray grid is closer to the reference than a coarser one.
    let psnr_of = |method: &str, field: &str| {
        rows.iter().find(|r| r[column("method")] == method && r[column("field_deg")] == field).unwrap()
            [column("psnr_db")]
        .parse::<f64>()
        .unwrap()
    };
    assert!(psnr_of("raygrid-16", "8") > psnr_of("raygrid-8", "8"));
    // The blended method (paraxial + baked LUT ghosts) is closer to the reference than paraxial alone.
    assert!(psnr_of("blended", "8") > psnr_of("paraxial", "8") + 3.0, "{csv}");
    let md = std::fs::read_to_string(out.join("bench.md")).unwrap();
    assert!(md.contains("| brendel_tessar_usp2854889 | 8 | paraxial |"), "{md}");
    assert!(md.contains("Convergence of the reference"), "{md}");
    assert!(md.contains("Blended LUT ghosts") && md.contains("| brendel_tessar_usp2854889 | 8 | blended |"), "{md}");
    let plot = image::open(out.join("bench.png")).unwrap().to_rgb8();
    assert!(plot.width() > 500 && plot.height() > 300);
    let coloured = plot.pixels().filter(|p| p[0].abs_diff(p[1]) > 60 || p[1].abs_diff(p[2]) > 60).count();
    assert!(coloured > 50, "the plot has coloured points: {coloured}");
    let updated = std::fs::read_to_string(&readme).unwrap();
    assert!(updated.starts_with("# Title\n\nBefore.\n\n<!-- bench:start -->\n"), "{updated}");
    assert!(updated.contains("| brendel_tessar_usp2854889 | 8 | raygrid-16 |") && !updated.contains("old table"));
    assert!(updated.ends_with("<!-- bench:end -->\n\nAfter.\n"), "{updated}");
    // A README without the markers is refused and left as it was.
    std::fs::write(&readme, "no markers\n").unwrap();
    let message = refusal(&[
        "bench",
        "--lens",
        "tessar",
        "--field-deg",
        "0",
        "--size",
        "32x24",
        "--grids",
        "4",
        "--reference-grid",
        "8",
        "--repeats",
        "1",
        "--update-readme",
        readme.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(message.contains("bench:start"), "{message}");
    assert_eq!(std::fs::read_to_string(&readme).unwrap(), "no markers\n");
    let message = refusal(&["bench", "--lens", "tessar", "--field-deg", "95", "--out", out.to_str().unwrap()]);
    assert!(message.contains("--field-deg"), "{message}");
}

#[test]
fn classify_bake_and_render_blended_and_photo_luts() {
    let dir = tempfile::tempdir().unwrap();
    let lut = dir.path().join("tessar.flut");
    let lut_s = lut.display().to_string();
    // Classify: a verdict per ghost, forced choices reported as such.
    let out = flarelab(&["classify", "tessar", "--json", "--force-nonlinear", "0-1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let classes = json_of(&out);
    let ghosts = classes["ghosts"].as_array().unwrap();
    assert!(ghosts.iter().any(|g| g["forced"] == true && g["nonlinear"] == true));
    // Bake (small settings so the test is quick), then render with it on the CPU twin.
    let out = flarelab(&[
        "bake",
        "tessar",
        "--out",
        &lut_s,
        "--theta-max",
        "12",
        "--res",
        "32",
        "--grid",
        "32",
        "--tolerance",
        "0.5",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("baked") && text.contains("MB"), "{text}");
    let png = dir.path().join("blended.png");
    let out = flarelab(&[
        "render",
        "tessar",
        "--method",
        "blended",
        "--lut",
        &lut_s,
        "--device",
        "cpu",
        "--size",
        "96x64",
        "--light-deg",
        "5,3",
        "--blend",
        "smooth:2:8",
        "-o",
        &png.display().to_string(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("LUT images"));
    assert!(image::open(&png).is_ok());
    // The LUT is refused for another lens, a damaged file is refused, both with exit 2 and one line.
    let e = refusal(&[
        "render",
        "pbrt_dgauss_50mm",
        "--method",
        "blended",
        "--lut",
        &lut_s,
        "-o",
        &png.display().to_string(),
    ]);
    assert!(e.contains("another lens"), "{e}");
    let mut bytes = std::fs::read(&lut).unwrap();
    let n = bytes.len();
    bytes.truncate(n / 2);
    let broken = dir.path().join("broken.flut");
    std::fs::write(&broken, &bytes).unwrap();
    let e =
        refusal(&["render", "tessar", "--method", "blended", "--lut", &broken.display().to_string(), "-o", "x.png"]);
    assert!(e.contains("truncated"), "{e}");
    let e = refusal(&["render", "tessar", "--method", "photo", "--lut", &lut_s, "-o", "x.png"]);
    assert!(e.contains("photo LUT"), "{e}");
    // A photo LUT from a folder of images named by angle, played back alone.
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for theta in [0, 8] {
        image::RgbImage::from_pixel(48, 32, image::Rgb([40, 30, 20]))
            .save(photos.join(format!("f_{theta}deg.png")))
            .unwrap();
    }
    let photo_lut = dir.path().join("photo.flut").display().to_string();
    let out = flarelab(&["photo-lut", &photos.display().to_string(), "--out", &photo_lut]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = flarelab(&[
        "render",
        "tessar",
        "--method",
        "photo",
        "--lut",
        &photo_lut,
        "--device",
        "cpu",
        "--size",
        "48x32",
        "-o",
        &png.display().to_string(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn render_reads_presets_and_flags_override_their_fields() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).display().to_string();
    // `preset new` writes the default document; rendering it equals rendering with no flags at all.
    let out = flarelab(&["preset", "new", "-o", &path("default.json")]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let render = |extra: &[&str], name: &str| {
        let mut args = vec!["render", "--size", "120x68", "--device", "cpu", "-o"];
        let out_path = path(name);
        args.push(&out_path);
        args.extend(extra);
        let result = flarelab(&args);
        assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
        std::fs::read(dir.path().join(name)).unwrap()
    };
    let plain = render(&[], "plain.png");
    let preset_file = path("default.json");
    assert_eq!(render(&["--preset", &preset_file], "preset.png"), plain, "the default document is the default");
    assert_eq!(render(&["--preset", "default"], "shipped.png"), plain, "so is the shipped `default`");
    // A flag overrides the preset's field.
    assert_ne!(render(&["--preset", "default", "--exposure-ev", "8"], "ev8.png"), plain);
    // The default exposure is automatic: `auto` spelled out is the same frame.
    assert_eq!(render(&["--exposure-ev", "auto"], "auto.png"), plain);
    // Every shipped preset renders, and no two look the same.
    let list = flarelab(&["preset", "list", "--json"]);
    let shipped = json_of(&list);
    assert!(shipped.as_array().unwrap().len() >= 12);
    let mut images: Vec<(String, Vec<u8>)> = Vec::new();
    for p in shipped.as_array().unwrap() {
        let name = p["name"].as_str().unwrap();
        assert!(p["lens"].is_string() && p["title"].is_string());
        let file = format!("{name}.png");
        let bytes = render(&["--preset", name], &file);
        let decoded = image::open(dir.path().join(&file)).unwrap().to_rgb8();
        assert!(decoded.pixels().any(|px| px.0.iter().any(|&v| v > 40)), "{name} shows a flare");
        assert!(images.iter().all(|(other, b)| *b != bytes || other == name), "{name} repeats another look");
        images.push((name.to_owned(), bytes));
    }
}

#[test]
fn bad_presets_plates_and_layers_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.exr");
    let out_s = out.display().to_string();
    let e = refusal(&["render", "--preset", "no-such-look", "-o", &out_s]);
    assert!(e.contains("no-such-look") && e.contains("default") && e.contains("fisheye-10"), "{e}");
    let e = refusal(&["render", "--exposure-ev", "bright", "-o", &out_s]);
    assert!(e.contains("bright") && e.contains("auto"), "{e}");
    let newer = dir.path().join("newer.json");
    std::fs::write(&newer, r#"{"version": 99, "flare_ev": 3}"#).unwrap();
    let e = refusal(&["render", "--preset", &newer.display().to_string(), "-o", &out_s]);
    assert!(e.contains("99") && e.contains("newer"), "{e}");
    let bad_field = dir.path().join("bad.json");
    std::fs::write(&bad_field, r#"{"version": 2, "plate_ev": "bright"}"#).unwrap();
    let e = refusal(&["render", "--preset", &bad_field.display().to_string(), "-o", &out_s]);
    assert!(e.contains("plate_ev"), "{e}");
    let plate = dir.path().join("plate.png");
    std::fs::write(&plate, b"not an image").unwrap();
    let e = refusal(&["render", "--background", &plate.display().to_string(), "-o", &out_s]);
    assert!(e.contains("plate.png") && e.contains("plate"), "{e}");
    let e = refusal(&["render", "--layers", "shadows", "-o", &out_s]);
    assert!(e.contains("shadows") && e.contains("ghosts"), "{e}");
    let png = dir.path().join("out.png").display().to_string();
    let e = refusal(&["render", "--layers", "ghosts", "-o", &png]);
    assert!(e.contains("EXR"), "{e}");
    let e = refusal(&["render", "--exposure", "1024", "-o", &png]);
    assert!(e.contains("--exposure-ev 10.00"), "{e}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3, "only the three inputs: nothing half-written");
}

#[test]
fn render_writes_compositing_layers_with_the_plate_apart() {
    let dir = tempfile::tempdir().unwrap();
    let plate = dir.path().join("plate.exr");
    let plate_image = image::Rgb32FImage::from_fn(80, 45, |x, _| image::Rgb([0.05 + 0.01 * x as f32, 0.2, 0.4]));
    image::DynamicImage::ImageRgb32F(plate_image.clone()).save(&plate).unwrap();
    let render = |plate_ev: &str, name: &str| {
        let out = dir.path().join(name);
        let result = flarelab(&[
            "render",
            "--preset",
            "default",
            "--size",
            "80x45",
            "--device",
            "cpu",
            "--background",
            &plate.display().to_string(),
            "--plate-ev",
            plate_ev,
            "--layers",
            "ghosts",
            // 32-bit: the sums below are exact.
            "--exr-type",
            "float",
            "-o",
            &out.display().to_string(),
        ]);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        // Every part: the ghost layers are parts of their own, placed at their data windows.
        flare_core::output::read_exr_channels(&out).unwrap().channels
    };
    let (a, b) = (render("1", "a.exr"), render("-1", "b.exr"));
    assert!(a.keys().any(|k| k.starts_with("ghost_") && k.ends_with(".G")), "ghost layers: {:?}", a.keys());
    for c in ["R", "G", "B"] {
        let (flare, plate_layer) = (&a[&format!("flare.{c}")], &a[&format!("plate.{c}")]);
        for k in 0..flare.len() {
            assert_eq!(a[c][k], flare[k] + plate_layer[k]);
        }
        assert_eq!(flare, &b[&format!("flare.{c}")], "the flare layer ignores --plate-ev");
    }
    // The plate layer is the plate times 2^plate_ev, pixel for pixel.
    for (k, p) in plate_image.pixels().enumerate() {
        assert_eq!(a["plate.R"][k], p[0] * 2.0);
        assert_eq!(b["plate.B"][k], p[2] * 0.5);
    }
}

/// A synthetic plate sequence (`flarelab synth-shot`, 160x90) of `frames` in `dir`: the plates' pattern and
/// the true track's path.
fn synth_shot(dir: &Path, frames: &str, occluder: bool) -> (String, PathBuf) {
    let plates = dir.join("plates/sun.####.exr").display().to_string();
    let track = dir.join("track.csv");
    let mut args =
        vec!["synth-shot", "--size", "160x90", "--frames", frames, "--track", track.to_str().unwrap(), "-o", &plates];
    if !occluder {
        args.push("--no-occluder");
    }
    let out = flarelab(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    (plates, track)
}

fn exr_channels(path: &Path) -> Vec<String> {
    flare_core::output::read_exr_channels(path).unwrap().channels.into_keys().collect()
}

#[test]
fn render_a_sequence_with_the_light_found_in_the_plate_and_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let (plates, track) = synth_shot(dir.path(), "1-6", true);
    let out = dir.path().join("out/flare.####.exr").display().to_string();
    let log = dir.path().join("log.json");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--background", &plates, "--light", "auto", "--frames", "1-6", "--device", "cpu"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--log", log.to_str().unwrap(), "-o", &out]);
        let result = flarelab(&args);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        serde_json::from_str::<Value>(&std::fs::read_to_string(&log).unwrap()).unwrap()
    };
    let records = render(&[]);
    let records = records.as_array().unwrap();
    assert_eq!(records.len(), 6);
    let truth: Vec<Vec<f64>> = std::fs::read_to_string(&track)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
        .collect();
    for (k, r) in records.iter().enumerate() {
        for key in ["frame", "light_px", "light_deg", "visibility", "ms"] {
            assert!(r.get(key).is_some(), "record {k} lacks {key}: {r}");
        }
        assert_eq!(r["status"], "rendered");
        let px = r["light_px"].as_array().unwrap();
        let (x, y) = (px[0].as_f64().unwrap(), px[1].as_f64().unwrap());
        assert!((x - truth[k][0]).hypot(y - truth[k][1]) < 0.5, "frame {}: ({x}, {y}) vs {:?}", k + 1, truth[k]);
        let file = dir.path().join(format!("out/flare.{:04}.exr", k + 1));
        let channels = exr_channels(&file);
        for c in ["R", "G", "B", "A", "flare.R", "starburst.G", "plate.B"] {
            assert!(channels.iter().any(|n| n == c), "{}: {c} in {channels:?}", file.display());
        }
    }
    // Resume: only the missing frame and a truncated one (issue 33: it was trusted by its name) are drawn
    // again; a stale temporary file of ours in the output folder is removed by the next write.
    std::fs::remove_file(dir.path().join("out/flare.0003.exr")).unwrap();
    let five = dir.path().join("out/flare.0005.exr");
    let whole = std::fs::read(&five).unwrap();
    std::fs::write(&five, &whole[..whole.len() / 2]).unwrap();
    let stale = dir.path().join("out/.flarelab-tmp-killed");
    std::fs::write(&stale, b"half a frame").unwrap();
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
    std::fs::File::options().write(true).open(&stale).unwrap().set_modified(old).unwrap();
    let records = render(&["--skip-existing"]);
    let status: Vec<&str> = records.as_array().unwrap().iter().map(|r| r["status"].as_str().unwrap()).collect();
    assert_eq!(status, ["skipped", "skipped", "rendered", "skipped", "rendered", "skipped"]);
    assert!(dir.path().join("out/flare.0003.exr").exists());
    assert_eq!(std::fs::read(&five).unwrap().len(), whole.len(), "the truncated frame is whole again");
    assert!(!stale.exists(), "the killed write's temporary file is cleaned up");
    // A PNG sequence with a printf field, and a light off the plate has no pixel.
    let png = dir.path().join("png/f.%04d.png").display().to_string();
    let result = flarelab(&[
        "render",
        "--light-deg",
        "60,0",
        "--frames",
        "1-2",
        "--device",
        "cpu",
        "--size",
        "96x54",
        "--log",
        log.to_str().unwrap(),
        "-o",
        &png,
    ]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert!(dir.path().join("png/f.0001.png").exists() && dir.path().join("png/f.0002.png").exists());
    let records: Value = serde_json::from_str(&std::fs::read_to_string(&log).unwrap()).unwrap();
    assert!(records[0]["light_px"].is_null(), "{records}");
}

#[test]
fn a_track_csv_and_light_auto_render_the_same_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let (plates, track) = synth_shot(dir.path(), "1-3", false);
    let render = |how: &[&str], name: &str| {
        let out = dir.path().join(format!("{name}.####.png")).display().to_string();
        let mut args = vec!["render", "--background", &plates, "--frames", "1-3", "--device", "cpu"];
        args.extend_from_slice(how);
        args.extend_from_slice(&["-o", &out]);
        let result = flarelab(&args);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        (1..=3)
            .map(|f| image::open(dir.path().join(format!("{name}.{f:04}.png"))).unwrap().to_rgb8())
            .collect::<Vec<_>>()
    };
    let auto = render(&["--light", "auto"], "auto");
    let tracked = render(&["--track", track.to_str().unwrap()], "track");
    for (a, t) in auto.iter().zip(&tracked) {
        let diff: f64 = a.as_raw().iter().zip(t.as_raw()).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>();
        let mean = diff / a.as_raw().len() as f64;
        assert!(mean < 0.5, "mean difference {mean} of 255");
    }
}

#[test]
fn a_missing_plate_frame_fails_that_frame_only() {
    let dir = tempfile::tempdir().unwrap();
    let (plates, _) = synth_shot(dir.path(), "1-5", true);
    std::fs::remove_file(dir.path().join("plates/sun.0003.exr")).unwrap();
    let out = dir.path().join("out/f.####.png").display().to_string();
    let result = flarelab(&["render", "--background", &plates, "--frames", "1-5", "--device", "cpu", "-o", &out]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("frame 3") && stderr.contains("sun.0003.exr"), "{stderr}");
    assert!(!stderr.contains("panicked"));
    for f in [1, 2, 4, 5] {
        assert!(dir.path().join(format!("out/f.{f:04}.png")).exists(), "frame {f}");
    }
    assert!(!dir.path().join("out/f.0003.png").exists());
}

#[test]
fn bad_shot_input_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let (plates, _) = synth_shot(dir.path(), "1-5", true);
    let out_dir = dir.path().join("out");
    let out = out_dir.join("f.####.exr").display().to_string();
    let track = dir.path().join("bad.csv");
    std::fs::write(&track, "frame,x_px,y_px\n1,80,45\n2,eighty,45\n").unwrap();
    let e = refusal(&["render", "--track", track.to_str().unwrap(), "--frames", "1-2", "--device", "cpu", "-o", &out]);
    assert!(e.contains("bad.csv") && e.contains("line 3") && e.contains("x_px `eighty`"), "{e}");
    let e = refusal(&["render", "--background", &plates, "--frames", "1-9", "--device", "cpu", "-o", &out]);
    assert!(e.contains("outside the plate sequence") && e.contains("1-5"), "{e}");
    let still = out_dir.join("f.exr").display().to_string();
    let e = refusal(&["render", "--frames", "1-3", "--device", "cpu", "-o", &still]);
    assert!(e.contains("frame field"), "{e}");
    let e = refusal(&["render", "--device", "cpu", "-o", &out]);
    assert!(e.contains("--frames"), "{e}");
    let e = refusal(&["render", "--light", "auto", "--frames", "1-2", "--device", "cpu", "-o", &out]);
    assert!(e.contains("--background"), "{e}");
    let e = refusal(&[
        "render",
        "--background",
        &plates,
        "--light",
        "auto",
        "--light-smooth",
        "4",
        "--frames",
        "1-2",
        "-o",
        &out,
    ]);
    assert!(e.contains("--light-smooth 4"), "{e}");
    let far = dir.path().join("far.csv");
    std::fs::write(&far, "1,80,45\n2,100000,45\n").unwrap();
    let e = refusal(&["render", "--track", far.to_str().unwrap(), "--frames", "1-2", "--device", "cpu", "-o", &out]);
    assert!(e.contains("line 2") && e.contains("outside the lens"), "{e}");
    assert!(!out_dir.exists(), "nothing was written");
}

/// The share of the starburst layer's light (R + G + B) more than `radius` pixels from the light's pixel
/// (the brightest), in a render at `f_number`.
fn starburst_share_beyond(dir: &Path, f_number: &str, radius: f64) -> f64 {
    let out = dir.join(format!("f{f_number}.exr"));
    let mut args: Vec<&str> =
        "render pbrt_dgauss_50mm --light-deg 0,0 --size 320x180 --exposure-ev 30 --device cpu".split(' ').collect();
    args.extend(["--f-number", f_number, "-o", out.to_str().unwrap()]);
    let result = flarelab(&args);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let image = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    let layer = &image.layer_data[0];
    let width = layer.size.0;
    let channel = |name: &str| -> Vec<f32> {
        let c = layer.channel_data.list.iter().find(|c| c.name.to_string() == name).expect(name);
        c.sample_data.values_as_f32().collect()
    };
    let (r, g, b) = (channel("starburst.R"), channel("starburst.G"), channel("starburst.B"));
    let light: Vec<f64> = (0..r.len()).map(|k| f64::from(r[k] + g[k] + b[k])).collect();
    assert!(light.iter().all(|v| v.is_finite() && *v >= 0.0));
    let centre = (0..light.len()).max_by(|&a, &b| light[a].total_cmp(&light[b])).unwrap();
    let (cx, cy) = ((centre % width) as f64, (centre / width) as f64);
    let total: f64 = light.iter().sum();
    let beyond: f64 = light
        .iter()
        .enumerate()
        .filter(|(k, _)| ((k % width) as f64 - cx).hypot((k / width) as f64 - cy) > radius)
        .map(|(_, v)| v)
        .sum();
    assert!(total > 0.0);
    beyond / total
}

#[test]
fn the_starburst_spreads_in_proportion_to_the_f_number() {
    // Fraunhofer: the pattern scales with lambda N, so the share of its energy beyond a radius far outside
    // the core (a few microns; 20 pixels here are 2.25 mm) grows in proportion to N. The double Gauss is
    // f/2 wide open, so f/4 and f/8 are both set by the stop.
    let dir = tempfile::tempdir().unwrap();
    let f4 = starburst_share_beyond(dir.path(), "4", 20.0);
    let f8 = starburst_share_beyond(dir.path(), "8", 20.0);
    let ratio = f8 / f4;
    assert!((ratio - 2.0).abs() <= 0.2, "f/4 {f4:.3e}, f/8 {f8:.3e}: ratio {ratio:.3}");
    assert!(f4 > 1e-5, "the rays carry light: {f4:.3e}");
    eprintln!("starburst share beyond 20 px: f/4 {f4:.3e}, f/8 {f8:.3e}, ratio {ratio:.3}");
}

#[test]
fn blended_renders_share_the_lut_cache_and_a_damaged_entry_is_baked_again() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let render = |name: &str| {
        let out = dir.path().join(name);
        let mut args: Vec<&str> = "render heliar --method blended --size 160x90 --device cpu -o".split(' ').collect();
        args.push(out.to_str().unwrap());
        let result = flarelab_cached(&args, &cache);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        (std::fs::read(&out).unwrap(), String::from_utf8_lossy(&result.stderr).into_owned())
    };
    let (first, said) = render("first.png");
    assert!(said.contains("cached the LUT as"), "{said}");
    let entries: Vec<_> = std::fs::read_dir(&cache).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(entries.len(), 1, "{entries:?}");
    // The second render reads the cache: no bake, the same frame.
    let (second, said) = render("second.png");
    assert!(said.contains("from the cache") && !said.contains("baked"), "{said}");
    assert_eq!(second, first);
    // A damaged cache file is never trusted: reported, baked again, the same frame.
    let mut bytes = std::fs::read(&entries[0]).unwrap();
    let n = bytes.len();
    bytes[n / 3] ^= 0x33;
    std::fs::write(&entries[0], &bytes).unwrap();
    let (third, said) = render("third.png");
    assert!(said.contains("ignored") && said.contains("baking it again") && said.contains("cached the LUT"), "{said}");
    assert_eq!(third, first);
}

#[test]
fn a_transcription_with_crossing_apertures_loads_with_a_warning_said_once_and_renders() {
    let dir = tempfile::tempdir().unwrap();
    // The Nikon of Hullin et al. as the public transcription gives it: semi-apertures 26.2 and 20 on surfaces
    // 3 and 4, which meet at 18.61 mm.
    let mut value: Value =
        serde_json::from_str(&std::fs::read_to_string(repo("lenses/nikon_zoom_28_75mm.json")).unwrap()).unwrap();
    value["surfaces"][3]["semi_aperture"] = 26.2.into();
    value["surfaces"][4]["semi_aperture"] = 20.0.into();
    let file = dir.path().join("nikon_transcribed.json");
    std::fs::write(&file, serde_json::to_vec_pretty(&value).unwrap()).unwrap();
    let file = file.display().to_string();

    let info = json_of(&flarelab(&["lens", "info", &file, "--json"]));
    let warnings = info["warnings"].as_array().unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = warnings[0].as_str().unwrap();
    assert!(w.contains("surfaces 3 and 4 meet at a height of 18.61 mm") && w.contains("clipped"), "{w}");
    assert!((info["surface_table"][3]["semi_aperture_mm"].as_f64().unwrap() - 18.608).abs() < 1e-3);
    // A lens that needs nothing has an empty list, and the aspheric terms are in the surface table.
    let zoom = json_of(&flarelab(&["lens", "info", "aspheric_zoom_us5793533", "--json"]));
    assert_eq!(zoom["warnings"], serde_json::json!([]));
    assert_eq!(zoom["surface_table"][13]["conic"], serde_json::json!(-1.0));
    assert_eq!(zoom["surface_table"][13]["aspheric"].as_array().unwrap().len(), 4);

    // Commands say it on stderr, once, and go on.
    let png = dir.path().join("nikon.png");
    let out = flarelab(&["render", &file, "--size", "320x180", "-o", png.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert_eq!(stderr.matches("meet at a height").count(), 1, "{stderr}");
    assert!(stderr.contains("warning: "), "{stderr}");
    assert!(png.exists());

    // Surfaces that meet where on-axis light passes are refused, with the reason once.
    value["surfaces"][3]["thickness"] = 0.01.into();
    std::fs::write(dir.path().join("crossing.json"), serde_json::to_vec_pretty(&value).unwrap()).unwrap();
    let e = refusal(&["lens", "info", dir.path().join("crossing.json").to_str().unwrap()]);
    assert_eq!(e.matches("meet at a height").count(), 1, "{e}");
    assert!(e.contains("on-axis light through the stop"), "{e}");
}

#[test]
fn the_ghost_report_ranks_ghosts_and_surfaces_as_text_json_and_csv() {
    let report = json_of(&flarelab(&["ghosts", "dgauss", "--field-deg", "5", "--report", "--json"]));
    let r = &report["report"];
    let ghosts = r["ghosts"].as_array().unwrap();
    assert_eq!(ghosts.len(), 45);
    for key in [
        "i",
        "j",
        "focus_mm",
        "image_diameter_mm",
        "f_number",
        "peak_vs_source",
        "mean_vs_source",
        "energy_fraction",
        "energy_share",
        "straddles_stop",
        "stop_crossings",
    ] {
        assert!(ghosts.iter().all(|g| g.get(key).is_some()), "{key}");
    }
    let peaks: Vec<f64> = ghosts.iter().map(|g| g["peak_vs_source"].as_f64().unwrap()).collect();
    assert!(peaks.windows(2).all(|w| w[0] >= w[1]), "worst first");
    let shares: f64 = ghosts.iter().map(|g| g["energy_share"].as_f64().unwrap()).sum();
    assert!((shares - 1.0).abs() < 1e-9);
    // The focus is the same number `ghosts --json` gives.
    let listing = json_of(&flarelab(&["ghosts", "dgauss", "--field-deg", "5", "--json"]));
    let first = &ghosts[0];
    let same =
        listing["ghosts"].as_array().unwrap().iter().find(|g| g["i"] == first["i"] && g["j"] == first["j"]).unwrap();
    assert_eq!(same["focus_mm"], first["focus_mm"]);
    let sensitivity = r["sensitivity"].as_array().unwrap();
    assert_eq!(sensitivity.len(), 10, "one row per reflecting surface");
    assert_eq!(r["sensitivity_coating"], "broadband multilayer (3 layers)");

    let csv = flarelab(&["ghosts", "dgauss", "--field-deg", "5", "--report", "--csv"]);
    assert!(csv.status.success());
    let text = String::from_utf8(csv.stdout).unwrap();
    assert_eq!(text.lines().count(), 46);
    assert!(text.starts_with(flare_core::report::CSV_HEADER));
    let text = flarelab(&["ghosts", "dgauss", "--field-deg", "5", "--report", "--f-number", "8"]);
    let text = String::from_utf8(text.stdout).unwrap();
    assert!(text.contains("f/8.00") && text.contains("coating sensitivity"), "{text}");
    assert!(refusal(&["ghosts", "dgauss", "--field-deg", "5", "--csv"]).contains("--report"));
}

#[test]
fn a_vendor_catalogue_adds_glasses_that_lens_files_name() {
    let dir = tempfile::tempdir().unwrap();
    // A vendor file in the AGF layout (with the lines FlareLab skips), one glass in formula 1 (Schott) and one
    // in formula 2 (Sellmeier 1, N-BK7's published coefficients under another name).
    let agf = dir.path().join("acme.agf");
    std::fs::write(
        &agf,
        "CC ACME optical glass\nNM AC-BK 2 517642 1.5168 64.17 0 0\nGC\nED 7.1 8.3 2.51 -0.0009 0\n\
         CD 1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653 0 0 0 0\n\
         TD 0 0 0 0 0 0 20\nOD 2 0 1 0 2.3 0\nLD 0.3 2.5\nIT 0.35 0.99 25\n",
    )
    .unwrap();
    let zmx = dir.path().join("singlet.zmx");
    std::fs::write(
        &zmx,
        "MODE SEQ\nUNIT MM X W X CM MR CPMM\nSURF 0\n  DISZ INFINITY\nSURF 1\n  STOP\n  DISZ 2\n  DIAM 5\n\
         SURF 2\n  CURV 0.02\n  DISZ 4\n  GLAS AC-BK 0 0\n  DIAM 8\nSURF 3\n  CURV -0.005\n  DISZ 90\n  DIAM 8\nSURF 4\n",
    )
    .unwrap();
    let (agf, zmx) = (agf.to_str().unwrap(), zmx.to_str().unwrap());
    // Without the catalogue the glass is unknown and the file gives no index: refused with the line.
    let e = refusal(&["lens", "info", zmx]);
    assert!(e.contains("line 12") && e.contains("AC-BK"), "{e}");
    // With it, the glass is found by name and its formula gives the dispersion.
    let info = json_of(&flarelab(&["--catalog", agf, "lens", "info", zmx, "--json"]));
    let s = &info["surface_table"][1];
    assert_eq!(s["nd"], 1.5168);
    assert_eq!(s["dispersion"], "ACME AC-BK (AGF formula 2)");
    // A broken line: the file and its line named, nothing run.
    let broken = dir.path().join("broken.agf");
    std::fs::write(&broken, "NM AC-X 2 1 1.6 40 0 0\nCD 1.2 0.01 oops\n").unwrap();
    let e = refusal(&["--catalog", broken.to_str().unwrap(), "lens", "info", "heliar"]);
    assert!(e.contains("broken.agf") && e.contains("line 2") && e.contains("oops"), "{e}");
}

/// `flarelab dof`: the synthetic street defocused (EXR and PNG, live and reference), and bad input refused with
/// the reason and nothing written.
#[test]
fn dof_defocuses_a_plate_and_refuses_bad_depths_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    let out = flarelab(&["synth-dof", "--size", "240x135", "-o", &p("street.exr"), "--depth", &p("z.exr")]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let run = |extra: &[&str], target: &str| {
        let (plate, z, target) = (p("street.exr"), p("z.exr"), p(target));
        let mut args = vec!["dof", plate.as_str(), "--depth"];
        args.extend([z.as_str(), "--lens", "heliar", "--focus-m", "5", "-o", target.as_str()]);
        args.extend(extra);
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        flarelab(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let out = run(&["--device", "cpu"], "live.exr");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && stderr.contains("live on the CPU"), "{stderr}");
    let plate = flare_core::output::read_plate(Path::new(&p("street.exr"))).unwrap();
    let live = flare_core::output::read_plate(Path::new(&p("live.exr"))).unwrap();
    assert_eq!((live.width, live.height), (240, 135));
    assert!(live.pixels.iter().zip(&plate.pixels).filter(|(a, b)| (a[0] - b[0]).abs() > 1e-3).count() > 1000);
    let out = run(&["--method", "reference"], "reference.png");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(image::open(p("reference.png")).is_ok());
    // A depth map of another size.
    let small = flare_core::dof::depth::DepthMap { width: 10, height: 10, metres: vec![3.0; 100] };
    flare_core::dof::depth::write_exr(Path::new(&p("small.exr")), &small).unwrap();
    let e = refusal(&[
        "dof",
        &p("street.exr"),
        "--depth",
        &p("small.exr"),
        "--focus-m",
        "5",
        "--device",
        "cpu",
        "-o",
        &p("bad1.exr"),
    ]);
    assert!(e.contains("10x10") && e.contains("240x135"), "{e}");
    // Negative and NaN depths, named by pixel.
    for (value, reason) in [(-1.0, "not above 0"), (f64::NAN, "not a number")] {
        // Written by the exr crate itself (FlareLab's writer never writes a NaN): no Z channel, so the first
        // channel is read.
        let map = flare_core::dof::depth::DepthMap::read(Path::new(&p("z.exr")), None).unwrap();
        exr::prelude::write_rgb_file(p("broken.exr"), 240, 135, |x, y| {
            let d = if (x, y) == (142, 0) { value as f32 } else { map.metres[y * 240 + x] as f32 };
            (d, d, d)
        })
        .unwrap();
        let e = refusal(&[
            "dof",
            &p("street.exr"),
            "--depth",
            &p("broken.exr"),
            "--focus-m",
            "5",
            "--device",
            "cpu",
            "-o",
            &p("bad2.exr"),
        ]);
        assert!(e.contains("pixel (142, 0)") && e.contains(reason), "{e}");
    }
    // A focus distance inside the lens, and one closer than it focuses.
    for (focus_m, out, reason) in
        [("0.001", "bad3.exr", "inside the lens"), ("0.1", "bad4.exr", "closer than this lens can focus")]
    {
        let (street, depth, out) = (p("street.exr"), p("z.exr"), p(out));
        let e = refusal(&["dof", &street, "--depth", &depth, "--lens", "heliar", "--focus-m", focus_m, "-o", &out]);
        assert!(e.contains(reason), "{e}");
    }
    let e = refusal(&[
        "dof",
        &p("street.exr"),
        "--depth",
        &p("z.exr"),
        "--method",
        "reference",
        "--device",
        "gpu",
        "-o",
        &p("bad5.exr"),
    ]);
    assert!(e.contains("reference runs on the CPU"), "{e}");
    for bad in ["bad1.exr", "bad2.exr", "bad3.exr", "bad4.exr", "bad5.exr"] {
        assert!(!dir.path().join(bad).exists(), "{bad} was written");
    }
}

/// A preset with its depth of field on: `render --preset` defocuses the plate before the flare, for a still and
/// for every frame of a sequence, and `--no-dof` leaves it sharp.
#[test]
fn render_with_a_preset_whose_depth_of_field_is_on() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    assert!(
        flarelab(&["synth-dof", "--size", "192x108", "-o", &p("street.exr"), "--depth", &p("z.exr")]).status.success()
    );
    assert!(flarelab(&["preset", "new", "heliar", "-o", &p("look.json")]).status.success());
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(p("look.json")).unwrap()).unwrap();
    doc["dof"] = serde_json::json!({"enabled": true, "depth": p("z.exr"), "focus_m": 2.0});
    std::fs::write(p("look.json"), serde_json::to_string(&doc).unwrap()).unwrap();
    let render = |extra: &[&str], out: &str| {
        let (look, plate, target) = (p("look.json"), p("street.exr"), p(out));
        let mut args = vec!["render", "--preset", look.as_str(), "--background", plate.as_str(), "--device", "cpu"];
        args.extend(extra);
        args.extend(["-o", target.as_str()]);
        flarelab(&args)
    };
    let out = render(&[], "dof.exr");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && stderr.contains("depth of field: live method, focus 2 m"), "{stderr}");
    let out = render(&["--no-dof"], "sharp.exr");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The EXR's plate layer: defocused, against the sharp one.
    let plate_layer = |name: &str| {
        let image = exr::prelude::read_all_flat_layers_from_file(p(name)).unwrap();
        let channel = image.layer_data[0].channel_data.list.iter().find(|c| c.name.to_string() == "plate.R").unwrap();
        channel.sample_data.values_as_f32().collect::<Vec<f32>>()
    };
    let (dof, sharp) = (plate_layer("dof.exr"), plate_layer("sharp.exr"));
    let changed = dof.iter().zip(&sharp).filter(|(a, b)| (*a - *b).abs() > 1e-3).count();
    assert!(changed > dof.len() / 10, "{changed} of {} plate pixels changed", dof.len());
    // A sequence: every frame defocused the same (one plate, one depth map).
    let out = render(&["--frames", "1-2"], "seq.####.png");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (a, b) = (image::open(p("seq.0001.png")).unwrap().to_rgb8(), image::open(p("seq.0002.png")).unwrap().to_rgb8());
    assert_eq!(a, b);
}

/// Negative frame numbers are values, not flags (issue 33: `--frames -2--1` said "unexpected argument").
#[test]
fn negative_frame_ranges_are_values() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("neg.####.png").display().to_string();
    let result = flarelab(&["render", "tessar", "--size", "16x16", "--frames", "-2--1", "--device", "cpu", "-o", &out]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    // A negative frame keeps its sign inside the field's width.
    assert!(dir.path().join("neg.-002.png").exists() && dir.path().join("neg.-001.png").exists());
    let e = String::from_utf8_lossy(&flarelab(&["render", "tessar", "--frames", "1-100000000", "-o", &out]).stderr)
        .to_string();
    assert!(e.contains("more than 1000000 frames") && e.lines().count() <= 2, "{e}");
}

/// Issue 33's messages and targets from the command line: each refusal is one line that names its file once
/// and blames what caused it, before any long work; limits agree between the core and the flags.
#[test]
fn hostile_targets_and_inputs_are_refused_in_one_line_blaming_their_cause() {
    let dir = tempfile::tempdir().unwrap();
    // A FIFO as -o: refused, not replaced; the cause said once.
    let fifo = dir.path().join("out.png");
    assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let fifo_s = fifo.display().to_string();
    let e = refusal(&["render", "tessar", "--size", "16x16", "--device", "cpu", "-o", &fifo_s]);
    assert!(e.contains("a FIFO") && e.matches("not a regular file").count() == 1, "{e}");
    assert_eq!(e.matches(&fifo_s).count(), 1, "the file named once: {e}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
    // A bad depth map is the depth map's fault, not the plate's.
    let plate = dir.path().join("plate.png");
    image::RgbImage::from_pixel(32, 18, image::Rgb([90, 90, 90])).save(&plate).unwrap();
    let depth = dir.path().join("z.exr");
    std::fs::write(&depth, b"not an exr").unwrap();
    let out = dir.path().join("dof.png").display().to_string();
    let e = refusal(&[
        "render",
        "tessar",
        "--size",
        "32x18",
        "--device",
        "cpu",
        "--background",
        plate.to_str().unwrap(),
        "--depth",
        depth.to_str().unwrap(),
        "-o",
        &out,
    ]);
    assert!(e.contains("depth map") && e.contains("z.exr") && !e.contains("plate cannot be used"), "{e}");
    // bake: a folder that does not exist is found before the bake, not after it.
    let e = refusal(&["bake", "tessar", "-o", &dir.path().join("nope/x.flut").display().to_string()]);
    assert!(e.contains("does not exist"), "{e}");
    // One wavelength range and one blade range everywhere.
    let e = refusal(&["trace", "heliar", "--field-deg", "1", "--pupil", "0,0", "--wavelength-nm", "1500"]);
    assert!(e.contains("300-1000 nm"), "{e}");
    let ok =
        flarelab(&["render", "tessar", "--size", "16x16", "--device", "cpu", "--aperture", "blades:24", "-o", &out]);
    assert!(ok.status.success(), "24 blades, as presets allow: {}", String::from_utf8_lossy(&ok.stderr));
    let e = refusal(&["render", "tessar", "--aperture", "blades:40", "-o", &out]);
    assert!(e.contains("3 to 32 blades"), "{e}");
    // Control characters in what is echoed (here a file name) are escaped, never sent to the terminal.
    let e = refusal(&["lens", "info", "/tmp/a\u{1b}[2Jb.zmx"]);
    assert!(!e.contains('\u{1b}') && e.contains("\\u{1b}[2J"), "{e}");
    // A negative number reaches the flag's own check (it was "unexpected argument '-2'").
    let e = refusal(&["render", "tessar", "--f-number", "-2", "-o", &out]);
    assert!(e.contains("--f-number -2") && e.contains("above 0"), "{e}");
    let e =
        refusal(&["dof", plate.to_str().unwrap(), "--depth", depth.to_str().unwrap(), "--focus-m", "-3", "-o", &out]);
    assert!(!e.contains("unexpected argument"), "{e}");
}

/// A plate sequence whose values overflow when exposed: clamped, said once for the whole sequence.
#[test]
fn an_overflowing_plate_sequence_is_clamped_with_one_warning() {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, WritableImage,
    };
    let dir = tempfile::tempdir().unwrap();
    for frame in 1..=3 {
        let values = vec![3e38f32, f32::INFINITY, 0.5, 0.25];
        let channels = ["R", "G", "B"].map(|c| AnyChannel::new(c, FlatSamples::F32(values.clone())));
        let layer = Layer::new(
            (2, 2),
            LayerAttributes::default(),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(channels.to_vec())),
        );
        Image::from_layer(layer).write().to_file(dir.path().join(format!("sun.{frame:04}.exr"))).unwrap();
    }
    let plates = dir.path().join("sun.####.exr").display().to_string();
    let out = dir.path().join("out/f.####.exr").display().to_string();
    let result = flarelab(&[
        "render",
        "tessar",
        "--background",
        &plates,
        "--frames",
        "1-3",
        "--plate-ev",
        "1",
        "--device",
        "cpu",
        "-o",
        &out,
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert_eq!(stderr.matches("warning:").count(), 1, "{stderr}");
    assert!(stderr.contains("clamped"), "{stderr}");
    let image = exr::prelude::read_all_flat_layers_from_file(dir.path().join("out/f.0002.exr")).unwrap();
    let composite: Vec<f32> = image.layer_data[0]
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "R")
        .unwrap()
        .sample_data
        .values_as_f32()
        .collect();
    assert!(composite.iter().all(|v| v.is_finite()) && composite[0] > 1e19, "bright, finite: {composite:?}");
}

/// `--exr-type` and `--exr-compression`: the default still with its ghost layers, each layer read back (by the
/// exr crate always, and by OpenImageIO's `oiiotool --info -v` where it is installed), the working space named.
#[test]
fn exr_type_and_compression_flags_write_every_layer_for_compositors() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["render", "--size", "240x160", "--layers", "ghosts", "--device", "cpu"];
        args.extend_from_slice(extra);
        args.extend(["-o", out.to_str().unwrap()]);
        let result = flarelab(&args);
        assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
        (out.clone(), std::fs::metadata(&out).unwrap().len())
    };
    let (float, float_bytes) = write("float.exr", &["--exr-type", "float"]);
    let (auto, auto_bytes) = write("auto.exr", &[]);
    let (half, half_bytes) = write("half.exr", &["--exr-type", "half"]);
    let (piz, piz_bytes) = write("piz.exr", &["--exr-type", "half", "--exr-compression", "piz"]);
    println!(
        "default still 240x160 with ghost layers, zip: float {float_bytes} B, auto {auto_bytes} B, half {half_bytes} B; \
         half with piz {piz_bytes} B"
    );
    assert!(half_bytes <= auto_bytes && auto_bytes < float_bytes);
    let (f, a) =
        (flare_core::output::read_exr_channels(&float).unwrap(), flare_core::output::read_exr_channels(&auto).unwrap());
    assert_eq!(f.channels.keys().collect::<Vec<_>>(), a.channels.keys().collect::<Vec<_>>(), "the same layers");
    let ghosts = a.parts.iter().filter(|p| p.name.as_deref().is_some_and(|n| n.starts_with("ghost_"))).count();
    assert!(ghosts > 10, "{ghosts} ghost parts");
    let (h, p) =
        (flare_core::output::read_exr_channels(&half).unwrap(), flare_core::output::read_exr_channels(&piz).unwrap());
    assert_eq!(h.channels, p.channels, "piz is lossless");
    // DWAA is refused with the reason, and nothing is written.
    let result = flarelab(&["render", "--exr-compression", "dwaa", "-o", dir.path().join("d.exr").to_str().unwrap()]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("cannot be written"));
    assert!(!dir.path().join("d.exr").exists());
    // A preset carries the settings: the same file from `exr` in the document.
    let preset = dir.path().join("p.json");
    std::fs::write(&preset, r#"{"version": 3, "exr": {"pixel_type": "half", "compression": "piz"}}"#).unwrap();
    let (from_preset, bytes) = write("preset.exr", &["--preset", preset.to_str().unwrap()]);
    assert_eq!(bytes, piz_bytes, "{}", from_preset.display());
    // OpenImageIO sees every part with its layer and the working space, where it is installed.
    match Command::new("oiiotool").args(["--info", "-v", auto.to_str().unwrap()]).output() {
        Ok(info) if info.status.success() => {
            let text = String::from_utf8_lossy(&info.stdout);
            assert!(text.contains(&format!("{} subimages", ghosts + 1)), "{text}");
            assert!(text.contains("colorspace: \"Linear Rec.709 (sRGB)\""), "{text}");
            assert!(text.contains("chromaticities: 0.64, 0.33"), "{text}");
        }
        _ => println!("oiiotool is not installed (Debian openimageio-tools): the exr crate's reading stands alone"),
    }
}

/// Writes a 9^3 `.cube` that warms the picture (red up, blue down).
fn warm_cube(path: &Path) {
    let n = 9;
    let mut text = String::from("LUT_3D_SIZE 9\n");
    for b in 0..n {
        for g in 0..n {
            for r in 0..n {
                let f = |k: usize| k as f32 / (n - 1) as f32;
                text += &format!("{:.6} {:.6} {:.6}\n", (f(r) * 1.1).min(1.0), f(g) * 0.95, f(b) * 0.8);
            }
        }
    }
    std::fs::write(path, text).unwrap();
}

/// A gradient plate PNG (every 8-bit level of red and green, saturated corners).
fn gradient_plate(path: &Path) {
    let (w, h) = (160u32, 90u32);
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x * 255 / (w - 1)) as u8, (y * 255 / (h - 1)) as u8, ((x + y) * 7 % 256) as u8])
    });
    img.save(path).unwrap();
}

/// The PNG of a frame is PyOpenColorIO's display of the EXR's composite (same config, display, view and
/// looks) within 1/255, for the built-in config's default view, another display and a `.cube` look; runs
/// where Python has PyOpenColorIO and OpenEXR (`pip install opencolorio==2.6.0 OpenEXR`; .ci/run installs
/// them), and says so where it does not.
#[test]
fn the_png_is_pyopencolorios_display_of_the_exr_composite() {
    let dir = tempfile::tempdir().unwrap();
    let plate = dir.path().join("plate.png");
    gradient_plate(&plate);
    let cube = dir.path().join("warm.cube");
    warm_cube(&cube);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ocio_reference.py");
    let cases: [(&str, Vec<&str>); 3] = [
        ("default", vec![]),
        ("p3", vec!["--display", "Display P3 - Display"]),
        ("cube", vec!["--cube", cube.to_str().unwrap()]),
    ];
    let mut pngs = Vec::new();
    for (name, extra) in &cases {
        let (png, exr) = (dir.path().join(format!("{name}.png")), dir.path().join(format!("{name}.exr")));
        for out in [&png, &exr] {
            let mut args =
                vec!["render", "--size", "160x90", "--background", plate.to_str().unwrap(), "--device", "cpu"];
            args.extend(["--exr-type", "float", "-o", out.to_str().unwrap()]);
            args.extend(extra.iter().copied());
            let result = flarelab(&args);
            assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
        }
        pngs.push(std::fs::read(&png).unwrap());
        let mut args = vec![script.to_str().unwrap().to_owned(), exr.display().to_string(), png.display().to_string()];
        args.extend(extra.iter().map(|s| {
            // The script names the display as OCIO does and the cube as --cube.
            s.to_string()
        }));
        let Ok(check) = Command::new("python3").args(&args).output() else {
            println!(
                "no python3: the PyOpenColorIO check is skipped (crates/flare_core/tests/colour.rs holds its values)"
            );
            return;
        };
        let said = String::from_utf8_lossy(&check.stdout);
        match check.status.code() {
            Some(0) => println!("{name}: {said}"),
            Some(2) => {
                println!(
                    "PyOpenColorIO or OpenEXR is not installed ({said}): skipped; crates/flare_core/tests/colour.rs holds its values"
                );
                return;
            }
            _ => panic!(
                "{name}: the PNG is not PyOpenColorIO's display of the composite: {said}{}",
                String::from_utf8_lossy(&check.stderr)
            ),
        }
    }
    assert_ne!(pngs[0], pngs[2], "the cube changed the picture");
}

/// A plate read through the inverse of the display and view comes out as shot at 0 EV with no flare, on
/// the CPU twin and on the GPU.
#[test]
fn a_plate_through_the_inverse_view_comes_out_as_shot() {
    let dir = tempfile::tempdir().unwrap();
    let plate = dir.path().join("plate.png");
    gradient_plate(&plate);
    let original = image::open(&plate).unwrap().to_rgb8();
    for device in ["cpu", "gpu"] {
        let out = dir.path().join(format!("{device}.png"));
        let result = flarelab(&[
            "render",
            "--background",
            plate.to_str().unwrap(),
            "--input-space",
            "display",
            "--exposure-ev",
            "-40",
            "--no-starburst",
            "--device",
            device,
            "-o",
            out.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&result.stderr);
        if device == "gpu" && !result.status.success() && stderr.contains("no GPU") {
            flare_core::render::gpu::skip_without_gpu(&stderr);
            continue;
        }
        assert!(result.status.success(), "{stderr}");
        let back = image::open(&out).unwrap().to_rgb8();
        let worst =
            original.pixels().zip(back.pixels()).flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c]))).max();
        println!("{device}: worst {worst:?}/255");
        assert!(worst.unwrap() <= 1, "{device}: the plate differs by {worst:?}/255");
    }
    // Without the input space, the plate comes in as sRGB and goes out through the ACES view: not as shot.
    let out = dir.path().join("aces.png");
    let result = flarelab(&[
        "render",
        "--background",
        plate.to_str().unwrap(),
        "--exposure-ev",
        "-40",
        "--device",
        "cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(result.status.success());
    let back = image::open(&out).unwrap().to_rgb8();
    assert!(original.pixels().zip(back.pixels()).any(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > 10)));
    // An unknown input space is refused naming the flag.
    let result = flarelab(&[
        "render",
        "--background",
        plate.to_str().unwrap(),
        "--input-space",
        "Nope",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        String::from_utf8_lossy(&result.stderr).contains("--input-space Nope"),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
}

/// A sequence with an open shutter draws each frame as the still of that frame does (one frame, one truth),
/// blurred: a 0-degree shutter gives other pixels.
#[test]
fn a_sequence_with_a_shutter_is_its_stills_blurred() {
    let dir = tempfile::tempdir().unwrap();
    let preset = dir.path().join("moving.json");
    std::fs::write(
        &preset,
        r#"{"version": 3, "timeline": {"interpolation": "linear", "shutter_deg": 180,
            "light_deg": [{"frame": 1, "value": [-8.0, 3.0]}, {"frame": 11, "value": [8.0, -3.0]}]}}"#,
    )
    .unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    let render = |extra: &[&str], out: &str| {
        let mut args = vec!["render", "--preset", preset.to_str().unwrap(), "--size", "160x90", "--device", "cpu"];
        args.extend_from_slice(extra);
        args.extend(["-o", out]);
        let result = flarelab(&args);
        assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
        String::from_utf8_lossy(&result.stderr).into_owned()
    };
    let said = render(&["--frame", "5"], &p("still.png"));
    assert!(said.contains("motion blur (180 degree shutter)"), "{said}");
    render(&["--frames", "4-6"], &p("seq.####.png"));
    render(&["--frame", "5", "--shutter-deg", "0"], &p("sharp.png"));
    let (still, frame, sharp) = (
        image::open(p("still.png")).unwrap().to_rgb8(),
        image::open(p("seq.0005.png")).unwrap().to_rgb8(),
        image::open(p("sharp.png")).unwrap().to_rgb8(),
    );
    assert_eq!(still, frame, "the sequence's frame 5 is the still of frame 5");
    assert_ne!(still, sharp, "the shutter blurs it");
}

/// `trace --start X,Y,Z --dir L,M,N`: any ray by a point and a direction. The pupil form's own rays, given by
/// a point moved along them (in front of the lens, or the pupil point itself) and a direction of any length,
/// land where the pupil form lands, image and ghost paths; bad rays are refused with the reason.
#[test]
fn trace_from_any_point_lands_where_the_pupil_form_does() {
    let file = repo("lenses/pbrt_dgauss_50mm.json");
    let lens = flare_core::optics::formats::load_lens_file(Path::new(&file)).unwrap();
    let fo = FirstOrder::d_line(&lens).unwrap();
    let mut checked = 0;
    for ghost in [None, Some("2,4"), Some("0,9")] {
        for (theta_deg, py) in [(0.0, 0.5), (10.0, -0.8), (-15.0, 0.25), (5.0, 0.0)] {
            let ray = pupil_ray(&fo.entrance_pupil(), f64::to_radians(theta_deg), 0.0, py);
            let mut base = vec![
                "trace".to_owned(),
                file.clone(),
                "--field-deg".into(),
                theta_deg.to_string(),
                "--pupil".into(),
                format!("0,{py}"),
                "--json".into(),
            ];
            if let Some(g) = ghost {
                base.extend(["--ghost".into(), g.into()]);
            }
            let args: Vec<&str> = base.iter().map(String::as_str).collect();
            let expected = json_of(&flarelab(&args));
            for (k, scale) in [(0.0, 1.0), (-30.0, 3.0), (-100.0, 0.25)] {
                let p = ray.origin_mm + ray.direction * k;
                let d = ray.direction * scale;
                let start = format!("{:e},{:e},{:e}", p.x, p.y, p.z);
                let dir = format!("{:e},{:e},{:e}", d.x, d.y, d.z);
                let mut args = vec!["trace", &file, "--start", &start, "--dir", &dir, "--json"];
                if let Some(g) = ghost {
                    args.extend(["--ghost", g]);
                }
                let out = json_of(&flarelab(&args));
                assert_eq!(out["status"], expected["status"], "{args:?}");
                if expected["status"] == "ok" {
                    for key in ["x_mm", "y_mm"] {
                        let (a, b) = (out[key].as_f64().unwrap(), expected[key].as_f64().unwrap());
                        assert!((a - b).abs() < 1e-9, "{args:?}: {key} {a} vs {b}");
                    }
                    checked += 1;
                }
            }
        }
    }
    assert!(checked >= 20, "{checked} landings compared");
    for (dir, why) in [("0,1,-1", "towards the lens"), ("0,0,0", "needs a length")] {
        let result = flarelab(&["trace", &file, "--start", "0,0,0", "--dir", dir]);
        assert!(!result.status.success());
        assert!(String::from_utf8_lossy(&result.stderr).contains(why), "{}", String::from_utf8_lossy(&result.stderr));
    }
    let result = flarelab(&["trace", &file, "--field-deg", "3", "--start", "0,0,0", "--dir", "0,0,1"]);
    assert!(!result.status.success(), "the two forms do not mix");
}

/// An anamorphic lens on the command line: `lens info --json` gives both sections, `trace --start` lands where
/// the independent mpmath figures say, `ghosts --json` gives each ghost's semi-axes, `lens convert` writes a
/// `.zmx` TOROIDAL that reads back, the paraxial and reference renders write images, and LUT ghosts with blades
/// that break the lens's mirror symmetry are refused in one line with the reason.
#[test]
fn anamorphic_lenses_on_the_command_line() {
    let file = repo("tests/data/reference/toroidal/toroidal_test_lens.json");
    let info = json_of(&flarelab(&["lens", "info", &file, "--json"]));
    let sections = &info["sections"];
    let figures: Value = serde_json::from_str(
        &std::fs::read_to_string(repo("tests/data/reference/toroidal/toroidal_test_lens_reference.json")).unwrap(),
    )
    .unwrap();
    for s in ["x", "y"] {
        let (ours, theirs) =
            (sections[s]["efl_mm"].as_f64().unwrap(), figures["sections"][s]["efl_mm"].as_f64().unwrap());
        assert!((ours - theirs).abs() < 1e-9 * theirs.abs(), "{s}: {ours} vs {theirs}");
    }
    assert!(info["surface_table"][0]["radius_x_mm"].as_f64() == Some(40.0));
    // One skew ghost ray and one image ray of the figures, traced from their start points.
    let mut traced = 0;
    for ray in figures["rays"].as_array().unwrap().iter().filter(|r| r["status"] == "ok").step_by(50) {
        let v = |key: &str| {
            ray[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| format!("{:e}", x.as_f64().unwrap()))
                .collect::<Vec<_>>()
                .join(",")
        };
        let (start, dir) = (v("start_mm"), v("dir"));
        let mut args =
            vec!["trace".to_owned(), file.clone(), "--start".into(), start, "--dir".into(), dir, "--json".into()];
        if let Some(p) = ray["path"].as_array() {
            args.extend(["--ghost".into(), format!("{},{}", p[0], p[1])]);
        }
        let out = json_of(&flarelab(&args.iter().map(String::as_str).collect::<Vec<_>>()));
        let point = ray["point_mm"].as_array().unwrap();
        for (key, k) in [("x_mm", 0), ("y_mm", 1)] {
            let (a, b) = (out[key].as_f64().unwrap(), point[k].as_f64().unwrap());
            assert!((a - b).abs() < 1e-9, "{args:?}: {key} {a} vs {b}");
        }
        assert!(out["section_focus_z_mm"]["x"].as_f64().is_some());
        traced += 1;
    }
    assert!(traced >= 5, "{traced}");
    let ghosts = json_of(&flarelab(&["ghosts", &file, "--field-deg", "3", "--json"]));
    let streak = ghosts["ghosts"].as_array().unwrap().iter().find(|g| g["i"] == 7 && g["j"] == 8).unwrap();
    let axes = [streak["semi_axes_mm"][0].as_f64().unwrap(), streak["semi_axes_mm"][1].as_f64().unwrap()];
    assert!(axes[0] < 0.05 * axes[1], "ghost 7-8 is a streak along y: {axes:?}");
    let dir = std::env::temp_dir().join(format!("flarelab-anamorphic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let zmx = dir.join("toroidal.zmx").display().to_string();
    assert!(flarelab(&["lens", "convert", &file, "--to", "zmx", "-o", &zmx]).status.success());
    let back = json_of(&flarelab(&["lens", "info", &zmx, "--json"]));
    assert!(
        (back["sections"]["x"]["efl_mm"].as_f64().unwrap() - sections["x"]["efl_mm"].as_f64().unwrap()).abs() < 1e-9
    );
    for method in ["paraxial", "reference"] {
        let out = dir.join(format!("{method}.png")).display().to_string();
        let run =
            flarelab(&["render", &file, "--method", method, "--size", "96x64", "--light-deg", "6,3", "--out", &out]);
        assert!(run.status.success(), "{method}: {}", String::from_utf8_lossy(&run.stderr));
        let img = image::open(&out).unwrap().to_rgb8();
        assert!(img.pixels().any(|p| p.0.iter().any(|&c| c > 40)), "{method}: the flare shows");
    }
    // LUT ghosts need the lens's mirror symmetry: blades turned off its axes are refused before any tracing.
    let blended = dir.join("blended.png").display().to_string();
    let e = refusal(&[
        "render",
        &file,
        "--method",
        "blended",
        "--aperture",
        "blades:5:10",
        "--size",
        "96x64",
        "--out",
        &blended,
    ]);
    assert!(e.contains("mirror symmetry") && e.contains("blades"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `render --dirt`: each pattern and a dirt image give a `dirt` layer that the flare layer holds; a clean lens
/// writes none; bad dirt flags are refused with the reason, naming the flag or the preset's field.
#[test]
fn render_with_front_dirt_writes_its_layer() {
    let dir = tempfile::tempdir().unwrap();
    let speck = dir.path().join("speck.png");
    image::GrayImage::from_fn(64, 64, |x, y| image::Luma([if (x / 8 + y / 8) % 3 == 0 { 255 } else { 0 }]))
        .save(&speck)
        .unwrap();
    let image_spec = format!("image:{}", speck.display());
    for (spec, expect_layer) in
        [("none", false), ("dust:3", true), ("smudges", true), ("haze", true), (&image_spec, true)]
    {
        let out = dir.path().join("d.exr");
        let args = [
            "render",
            "--size",
            "96x54",
            "--device",
            "cpu",
            "--f-number",
            "11",
            "--dirt",
            spec,
            "--dirt-amount",
            "0.05",
            "--exr-type",
            "float",
            "-o",
            &out.display().to_string(),
        ];
        let result = flarelab(&args);
        assert!(result.status.success(), "{spec}: {}", String::from_utf8_lossy(&result.stderr));
        let channels = flare_core::output::read_exr_channels(&out).unwrap().channels;
        assert_eq!(channels.contains_key("dirt.G"), expect_layer, "{spec}: {:?}", channels.keys());
        if expect_layer {
            let (dirt, flare) = (&channels["dirt.G"], &channels["flare.G"]);
            assert!(dirt.iter().any(|&v| v > 0.0), "{spec}: a glow");
            assert!(dirt.iter().zip(flare).all(|(d, f)| *d <= *f * (1.0 + 1e-6) + 1e-6), "{spec}: the flare holds it");
        }
    }
    assert!(refusal(&["render", "--dirt", "mud", "-o", "x.png"]).contains("--dirt mud"));
    assert!(refusal(&["render", "--dirt", "image:/no/such.png", "-o", "x.png"]).contains("no such image"));
    assert!(
        refusal(&["render", "--dirt", "dust", "--dirt-amount", "2", "-o", "x.png"])
            .contains("--dirt-amount 2: 2 must be from 0 to 1")
    );
    assert!(
        refusal(&["render", "--dirt", "dust", "--dirt-spread-deg", "0", "-o", "x.png"]).contains("--dirt-spread-deg 0")
    );
    let black = dir.path().join("black.png");
    image::GrayImage::new(8, 8).save(&black).unwrap();
    let why = refusal(&["render", "--dirt", &format!("image:{}", black.display()), "-o", "x.png"]);
    assert!(why.contains("black everywhere"), "{why}");
}

/// `render --desqueeze`: the file has the asked size, the flare averaged from the sensor's rows; `auto` takes an
/// anamorphic lens's squeeze and is refused, with the reason, for a lens of revolution.
#[test]
fn render_desqueezes_to_the_asked_size() {
    let dir = tempfile::tempdir().unwrap();
    let lens = repo("tests/data/reference/toroidal/toroidal_test_lens.json");
    for (spec, name) in [("2", "a.exr"), ("auto", "b.png")] {
        let out = dir.path().join(name);
        let args = [
            "render",
            &lens,
            "--desqueeze",
            spec,
            "--size",
            "96x54",
            "--device",
            "cpu",
            "-o",
            &out.display().to_string(),
        ];
        let result = flarelab(&args);
        assert!(result.status.success(), "{spec}: {}", String::from_utf8_lossy(&result.stderr));
        if name.ends_with(".png") {
            assert_eq!(image::open(&out).unwrap().into_rgba8().dimensions(), (96, 54));
        } else {
            let read = flare_core::output::read_exr_channels(&out).unwrap();
            assert_eq!((read.width, read.height), (96, 54));
        }
    }
    assert!(refusal(&["render", "--desqueeze", "auto", "-o", "x.png"]).contains("not anamorphic"));
    assert!(refusal(&["render", "--desqueeze", "9", "-o", "x.png"]).contains("--desqueeze 9"));
}

/// Issue 61's command-line cases: each refused at once with exit 2 and one line naming its cause.
/// - `%070000d` in `-o`: "internal error ... Formatting argument out of range", exit 101.
/// - an unwritable output folder: found only after the whole bake or every frame (`/sys` takes no file,
///   even for root, so this holds where the tests run as root).
/// - `preset new -o` into such a folder: the reason printed twice.
/// - B44: panicked on a rayon thread (SIGABRT) for thin ghost layers; now refused by name.
/// - `--size 8192x8192`, `--desqueeze 4` on a wide frame: aborted at 5.1-5.4 GB; now refused with the figure.
/// - a FIFO as the lens, the preset or `--cube`: blocked forever in `open()`.
#[test]
fn issue_61_inputs_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).display().to_string();
    let e = refusal(&["render", "--frames", "1-2", "-o", &out("f.%070000d.png")]);
    assert!(e.contains("at most 20"), "{e}");
    let e = refusal(&["synth-shot", "-o", &out("s.%070000d.png")]);
    assert!(e.contains("at most 20"), "{e}");
    let started = std::time::Instant::now();
    let e = refusal(&["render", "--method", "blended", "-o", "/sys/flarelab-still.exr"]);
    assert!(e.contains("cannot write in the folder /sys"), "{e}");
    let e = refusal(&["render", "--frames", "1-3", "-o", "/sys/seq/f.####.png"]);
    assert!(e.contains("cannot write in the folder /sys"), "{e}");
    println!("refused in {:.1} s, no bake", started.elapsed().as_secs_f64());
    let e = refusal(&["preset", "new", "-o", "/sys/flarelab-preset.json"]);
    assert_eq!(e.matches("Permission denied").count(), 1, "the reason once: {e}");
    for c in ["b44", "b44a"] {
        let e = refusal(&["render", "--layers", "ghosts", "--exr-compression", c, "-o", &out("b.exr")]);
        assert!(e.contains("not written here"), "{e}");
    }
    let e = refusal(&["render", "--size", "8192x8192", "-o", &out("big.exr")]);
    assert!(e.contains("8192x8192") && e.contains("GB"), "{e}");
    let e = refusal(&["render", "--size", "8192x4320", "--desqueeze", "4", "-o", &out("wide.exr")]);
    assert!(e.contains("drawn at 8192x17280"), "{e}");
    #[cfg(unix)]
    for (flag, name) in [(None, "l.json"), (Some("--preset"), "p.json"), (Some("--cube"), "c.cube")] {
        let fifo = dir.path().join(name).display().to_string();
        assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let png = out("fifo.png");
        let args: Vec<&str> = ["render"].into_iter().chain(flag).chain([fifo.as_str(), "-o", png.as_str()]).collect();
        let e = refusal(&args);
        assert!(e.contains("not a regular file"), "{flag:?}: {e}");
    }
}

/// What the command line's random walk (`tests/cli_walk.rs`) found once it reached every subcommand (issue 61):
/// each refused with one line before any work, nothing written.
#[test]
fn issue_61_the_walks_findings_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).display().to_string();
    // A LUT named as an image was baked and written.
    let e = refusal(&["bake", "heliar", "--res", "8", "--grid", "4", "--theta-max", "2", "-o", &out("l.png")]);
    assert!(e.contains("a LUT file is named .flut"), "{e}");
    let e = refusal(&["photo-lut", &out(""), "-o", &out("p.png")]);
    assert!(e.contains("a LUT file is named .flut"), "{e}");
    // An unwritable folder was found after the work: the street drawn, its plate written, then the depth map
    // refused; the defocused plate and the photo LUT likewise.
    let e = refusal(&["synth-dof", "--size", "64x36", "-o", &out("street.exr"), "--depth", "/sys/z.exr"]);
    assert!(e.contains("/sys"), "{e}");
    assert!(!dir.path().join("street.exr").exists(), "nothing written before the refusal");
    flarelab(&["synth-dof", "--size", "64x36", "-o", &out("street.exr"), "--depth", &out("z.exr")]);
    let e = refusal(&["dof", &out("street.exr"), "--depth", &out("z.exr"), "--device", "cpu", "-o", "/sys/d.exr"]);
    assert!(e.contains("cannot write in the folder /sys"), "{e}");
    let e = refusal(&["photo-lut", &out(""), "-o", "/sys/p.flut"]);
    assert!(e.contains("cannot write in the folder /sys"), "{e}");
    // A README that is a FIFO blocked `bench --update-readme` forever; a billion repeats ran for days.
    let fifo = dir.path().join("README.md");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let e = refusal(&["bench", "--lens", "heliar", "--update-readme", &fifo.display().to_string(), "-o", &out("b")]);
    assert!(e.contains("a FIFO"), "{e}");
    let e = refusal(&["bench", "--repeats", "1000000000", "-o", &out("b")]);
    assert!(e.contains("at most 100"), "{e}");
    // An f-number of 1e300 was accepted (and baked for minutes); its refusal echoes it short.
    let e = refusal(&["bake", "heliar", "--f-number", "1e300", "-o", &out("l.flut")]);
    assert!(e.contains("1.000e300") && e.contains("at most 1024") && e.len() < 200, "{e}");
    // An error whose message is its cause's was said twice.
    let e = refusal(&["bake", "heliar", "--update", &out("nope.flut"), "-o", &out("l.flut")]);
    assert_eq!(e.matches("No such file").count(), 1, "{e}");
}

/// `--timings` names where a whole command's time went: the document, the lens, the frame's passes and the
/// writer, each with a number, the parts of a span indented under it, and the command's total last.
#[test]
fn render_timings_name_where_the_time_went() {
    let dir = tempfile::tempdir().unwrap();
    let exr = dir.path().join("flare.exr");
    let out =
        flarelab(&["render", "dgauss", "--size", "96x64", "--device", "cpu", "--timings", "-o", exr.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().skip_while(|l| !l.starts_with("timings")).collect();
    let ms = |name: &str| -> f64 {
        let line =
            lines.iter().find(|l| l.trim_start().starts_with(name)).unwrap_or_else(|| panic!("{name}: {stderr}"));
        line.split_whitespace().last().unwrap().parse().unwrap_or_else(|_| panic!("{line}"))
    };
    for name in ["read the document", "prepare the lens", "draw", "write", "EXR encode and write"] {
        assert!(ms(name) >= 0.0, "{name}");
    }
    assert!(lines.iter().any(|l| l.starts_with("    ghosts")), "the draw's passes indented under it: {stderr}");
    let total = ms("the command");
    assert!(total >= ms("write") + ms("draw"), "{stderr}");
    assert!(lines.last().unwrap().trim_start().starts_with("the command"), "{stderr}");
    // Without the flag nothing is printed.
    let plain = flarelab(&["render", "dgauss", "--size", "64x36", "--device", "cpu", "-o", exr.to_str().unwrap()]);
    assert!(!String::from_utf8_lossy(&plain.stderr).contains("timings"));
}
