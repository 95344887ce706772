//! The front element's dirt ([`flare_core::dirt`]): a clean lens draws the frame it always drew (hashes kept
//! from before dirt existed), the glow's power is the power the dirt took times the share of the lobe in the
//! frame, the dirt each pixel sees is the dirt over the footprint the exact tracer finds, the glow moves with the
//! light while the dirt stays on the lens, the GPU draws what its CPU twin draws, and every method and file
//! carries it.

mod common;

use flare_core::aperture::{Aperture, ApertureShape};
use flare_core::dirt::{DirtPattern, henyey_greenstein, henyey_greenstein_g, sample_map};
use flare_core::fingerprint::{FNV_OFFSET, fnv1a};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, Sources};
use flare_core::ghost::light_slopes_for_frame_position;
use flare_core::image::HdrImage;
use flare_core::optics::library::default_lens;
use flare_core::optics::trace::{Ray, Tracer};
use flare_core::optics::{Lens, LightPath};
use flare_core::render::{DisplaySettings, cpu};
use glam::DVec3;

fn prepared(lens: &Lens, dirt: Option<DirtPattern>, blades: u32, f_number: Option<f64>) -> PreparedFlare {
    let shape = if blades == 0 {
        ApertureShape::Circle
    } else {
        ApertureShape::Blades { count: blades, rotation_deg: 10.0, roundness: 0.0 }
    };
    let config = FlareConfig { aperture: Aperture { shape, f_number }, dirt, ..FlareConfig::default() };
    PreparedFlare::new(lens, &config).unwrap()
}

fn request(light_deg: [f64; 2], size: (u32, u32), amount: f64, spread_deg: f64) -> FrameRequest {
    FrameRequest {
        light_deg,
        width: size.0,
        height: size.1,
        display: DisplaySettings { dirt_amount: amount, dirt_spread_deg: spread_deg, ..DisplaySettings::default() },
        ..FrameRequest::default()
    }
}

/// The glow alone: the dirt pass into a black accumulation (relative irradiance, before any gain).
fn glow(frame: &Frame, flare: &PreparedFlare) -> HdrImage {
    let mut image = HdrImage::black(frame.scene.hdr_width, frame.scene.hdr_height);
    cpu::dirt_pass(&frame.scene, flare.dirt.as_ref(), &mut image);
    image
}

fn hashes(drawn: &frame::Drawn) -> (u64, u64) {
    (
        fnv1a(bytemuck::cast_slice(&drawn.hdr.pixels), FNV_OFFSET),
        fnv1a(bytemuck::cast_slice(&drawn.display.pixels), FNV_OFFSET),
    )
}

/// The frames of the default lens as the CPU twin draws them since sprites of two pixels or less are drawn as
/// points (before: since every clear aperture cuts the ghosts; before that: since the ghost passes read finer levels of the mask for large sprites; before that, the frames of
/// commit 1f2819d, before dirt existed), by hash: a clean lens, a dirty one at an amount of 0 and an amount with
/// no pattern all draw exactly them.
#[test]
fn a_clean_lens_draws_the_frame_it_always_drew() {
    let lens = default_lens();
    let expected = [
        ([6.0, 4.0], (0x934a_9cac_65f2_4ad2u64, 0x0075_e298_a90e_6804u64)),
        ([-12.0, 3.0], (0xbd5c_dd70_db4d_c7fb, 0xe0af_e1dd_17ec_afc3)),
    ];
    let clean = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let dusty =
        PreparedFlare::new(&lens, &FlareConfig { dirt: Some(DirtPattern::Dust { seed: 2 }), ..FlareConfig::default() })
            .unwrap();
    for (light, hash) in expected {
        for (flare, amount) in [(&clean, 0.0), (&clean, 0.05), (&dusty, 0.0)] {
            let req = FrameRequest { light_deg: light, width: 320, height: 180, ..FrameRequest::default() };
            let req = FrameRequest { display: DisplaySettings { dirt_amount: amount, ..req.display }, ..req };
            let frame = Frame::build(flare, None, &req);
            assert!(!frame.scene.has_dirt_glow() && frame.dirt_taken == 0.0);
            let drawn = frame::draw_cpu(&frame, &Sources { flare, lut: None, plate: None });
            assert_eq!(hashes(&drawn), hash, "light {light:?}, amount {amount}");
            let layers = drawn.layers(&frame, &Sources { flare, lut: None, plate: None });
            assert!(layers.dirt.is_none(), "a clean lens writes no dirt layer");
        }
    }
}

/// Even dirt (a haze of share 1 over the element) at amount a: the ghosts and the starburst keep exactly
/// 1 - a of their light, and the glow's power on the sensor is `a A_EP cos(theta) T` times the lobe's share
/// inside the frame, that share integrated here in f64 on a grid 8 times finer than the pixels. On the default
/// zoom and on the toroidal test lens (elliptical pupil, a focal length per axis).
#[test]
fn the_glow_adds_what_the_dirt_took() {
    let amount = 0.02;
    for (name, lens, light) in
        [("zoom", default_lens(), [3.0, 2.0]), ("toroidal", common::toroidal_test_lens(), [1.0, -0.5])]
    {
        let flare = prepared(&lens, Some(DirtPattern::Haze), 6, Some(8.0));
        let clean = prepared(&lens, None, 6, Some(8.0));
        let size = (720, 480);
        let req = request(light, size, amount, 2.0);
        let frame = Frame::build(&flare, None, &req);
        assert!(frame.scene.has_dirt_glow(), "{name}: a glow");
        assert!((frame.dirt_taken - amount).abs() < 1e-9, "{name}: takes {}", frame.dirt_taken);
        // The direct light: every sprite's colour, and the starburst, times 1 - a.
        let plain = Frame::build(&clean, None, &request(light, size, 0.0, 2.0));
        assert_eq!(frame.scene.instances.len(), plain.scene.instances.len());
        for (dirty, clean) in frame.scene.instances.iter().zip(&plain.scene.instances) {
            for k in 0..3 {
                let kept = f64::from(dirty.colour[k]) / f64::from(clean.colour[k]).max(1e-30);
                assert!(clean.colour[k] == 0.0 || (kept - (1.0 - amount)).abs() < 1e-6, "{name}: kept {kept}");
            }
        }
        let core = |f: &Frame| f64::from(f.scene.globals.starburst_core_rgb[0]);
        assert!((core(&frame) / core(&plain) - (1.0 - amount)).abs() < 1e-6, "{name}: starburst");

        // The glow's power against what the dirt took.
        let image = glow(&frame, &flare);
        let mm_per_px = 36.0 / f64::from(size.0);
        let power: [f64; 3] =
            std::array::from_fn(|k| image.pixels.iter().map(|p| f64::from(p[k])).sum::<f64>() * mm_per_px * mm_per_px);
        let u_s = light_slopes_for_frame_position(light[0], light[1]);
        let taken = flare.dirt.as_ref().unwrap().taken_power(&flare.system, u_s, amount);
        let [lx, ly] = frame.scene.globals.dirt_light_px.map(f64::from);
        let a = frame.scene.globals.dirt_slopes_per_px.map(f64::from);
        let g = henyey_greenstein_g(2.0);
        let v_s = DVec3::new(u_s[0], u_s[1], 1.0).normalize();
        let sub = 8;
        let mut in_frame = 0.0;
        for j in 0..size.1 * sub {
            for i in 0..size.0 * sub {
                let p = [(f64::from(i) + 0.5) / f64::from(sub), (f64::from(j) + 0.5) / f64::from(sub)];
                let (dx, dy) = (p[0] - lx, p[1] - ly);
                let u = [u_s[0] + a[0] * dx + a[1] * dy, u_s[1] + a[2] * dx + a[3] * dy];
                let n = (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
                let solid_angle = (a[0] * a[3] - a[1] * a[2]).abs() / f64::from(sub * sub) / (n * n * n);
                in_frame += henyey_greenstein(g, DVec3::new(u[0], u[1], 1.0).normalize().dot(v_s)) * solid_angle;
            }
        }
        for k in 0..3 {
            let ratio = power[k] / (taken[k] * in_frame);
            println!(
                "{name}: channel {k}: glow {:.5e}, taken {:.5e} x {in_frame:.4} in the frame: ratio {ratio:.5}",
                power[k], taken[k]
            );
            assert!((ratio - 1.0).abs() < 0.01, "{name}: channel {k}: the glow holds {ratio} of what was taken");
        }
        assert!(in_frame > 0.8 && in_frame < 1.0, "{name}: the lobe's share in the frame {in_frame}");
    }
}

/// The dirt each pixel sees, `D`, against the exact tracer: at 40 pixels within the glow of a light far off the
/// axis, the rays of the pixel's direction are traced exactly from a grid over the entrance plane, those that
/// pass the stop (its 5 blades, an odd count: turned over it would differ) and the front element's rim make the
/// footprint, and the mean share of the dirt over it is compared with what the pass samples (the map's FFT
/// convolution with the paraxial pupil, centred where the traced chief ray crosses, linearised about the light).
#[test]
fn each_pixel_sees_the_dirt_over_the_footprint_the_exact_tracer_finds() {
    let lens = default_lens();
    let flare = prepared(&lens, Some(DirtPattern::Dust { seed: 5 }), 5, Some(11.0));
    let dirt = flare.dirt.as_ref().unwrap();
    let size = (480, 320);
    let frame = Frame::build(&flare, None, &request([14.0, 9.0], size, 0.01, 8.0));
    let system = &flare.system;
    let wavelength = 587.56;
    let tracer = Tracer::new(&lens, &LightPath::image(&lens), wavelength, system.first_order.sensor_z_mm());
    let stop = lens.stop_index();
    let stop_radius = system.stop_radius_mm;
    let globals = frame.scene.globals;
    let ([lx, ly], [usx, usy]) = (globals.dirt_light_px.map(f64::from), globals.dirt_light_slopes.map(f64::from));
    let a = globals.dirt_slopes_per_px.map(f64::from);
    let scale = dirt.size as f64 / (2.0 * dirt.half_extent_mm);
    let share_at = |x: f64, y: f64| {
        let (tx, ty) = (x * scale + 0.5 * dirt.size as f64 - 0.5, -y * scale + 0.5 * dirt.size as f64 - 0.5);
        f64::from(sample_map(&dirt.share, dirt.size, tx as f32, ty as f32))
    };
    let (mut sum_d, mut sum_e, mut sum_dd, mut sum_ee, mut sum_de, mut worst) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0f64);
    let count = 40;
    let mut state = 7u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..count {
        // Within 60 pixels of the light (the lobe's half width at half peak is about 50 pixels here).
        let (radius, angle) = (60.0 * next().sqrt(), std::f64::consts::TAU * next());
        let p = [lx + radius * angle.cos(), ly + radius * angle.sin()];
        let (dx, dy) = (p[0] - lx, p[1] - ly);
        let u = [usx + a[0] * dx + a[1] * dy, usy + a[2] * dx + a[3] * dy];
        let d = DVec3::new(u[0], u[1], 1.0).normalize();
        let c = dirt.footprint_centre_mm(system, u);
        let r = dirt.pupil_radius_mm[1];
        let steps = 48;
        let (mut passed, mut total) = (0usize, 0.0);
        for j in 0..steps {
            for i in 0..steps {
                let x0 = c[0] + 1.6 * r * ((i as f64 + 0.5) / steps as f64 * 2.0 - 1.0);
                let y0 = c[1] + 1.6 * r * ((j as f64 + 0.5) / steps as f64 * 2.0 - 1.0);
                if x0.hypot(y0) > dirt.front_radius_mm {
                    continue;
                }
                let ray = Ray { origin_mm: DVec3::new(x0, y0, 0.0) - d * (20.0 / d.z), direction: d };
                let mut through = true;
                let landed = tracer.trace_visit(&ray, |hit| {
                    if hit.surface == stop {
                        let (sx, sy) = (hit.point_mm.x / stop_radius, hit.point_mm.y / stop_radius);
                        through = flare.mask().sample(sx as f32, sy as f32) >= 0.5;
                    }
                    through
                });
                if landed.is_ok() && through {
                    passed += 1;
                    total += share_at(x0, y0);
                }
            }
        }
        assert!(passed > steps * steps / 8, "the footprint at {p:?} is lit ({passed} rays)");
        let exact = total / passed as f64;
        // What the pass samples: the centre linearised about the light.
        let j = globals.dirt_footprint.map(f64::from);
        let (du, dv) = (u[0] - usx, u[1] - usy);
        let t = [
            f64::from(globals.dirt_centre_texels[0]) + j[0] * du + j[1] * dv,
            f64::from(globals.dirt_centre_texels[1]) + j[2] * du + j[3] * dv,
        ];
        let map = f64::from(sample_map(&dirt.map, dirt.size, t[0] as f32, t[1] as f32));
        worst = worst.max((map - exact).abs());
        (sum_d, sum_e, sum_dd, sum_ee, sum_de) =
            (sum_d + map, sum_e + exact, sum_dd + map * map, sum_ee + exact * exact, sum_de + map * exact);
    }
    let n = count as f64;
    let covariance = sum_de / n - sum_d / n * sum_e / n;
    let correlation = covariance / ((sum_dd / n - (sum_d / n).powi(2)) * (sum_ee / n - (sum_e / n).powi(2))).sqrt();
    println!(
        "D against the exact footprints: mean {:.4} vs {:.4}, correlation {correlation:.4}, worst difference {worst:.4}",
        sum_d / n,
        sum_e / n
    );
    assert!(correlation > 0.95, "correlation {correlation}");
    assert!(((sum_d - sum_e) / sum_e).abs() < 0.05, "means {} and {}", sum_d / n, sum_e / n);
}

/// Dragging the light slides the lobe over dirt that stays on the lens: the glow's centroid follows the light,
/// and the glow divided by the lobe (the dirt each pixel sees) is the same at both positions.
#[test]
fn the_glow_moves_with_the_light_over_dirt_that_stays() {
    let lens = default_lens();
    let flare = prepared(&lens, Some(DirtPattern::Smudges { seed: 9 }), 6, Some(8.0));
    let size = (480, 320);
    let lights = [[-4.0, 2.0], [6.0, -3.0]];
    let mut centroids = Vec::new();
    let mut seen = Vec::new();
    let mut light_px = Vec::new();
    for light in lights {
        let frame = Frame::build(&flare, None, &request(light, size, 0.01, 4.0));
        let image = glow(&frame, &flare);
        let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
        for (k, p) in image.pixels.iter().enumerate() {
            let v = f64::from(p[1]);
            let (x, y) = ((k % size.0 as usize) as f64 + 0.5, (k / size.0 as usize) as f64 + 0.5);
            (sx, sy, s) = (sx + v * x, sy + v * y, s + v);
        }
        centroids.push([sx / s, sy / s]);
        let g = frame.scene.globals;
        light_px.push(g.dirt_light_px.map(f64::from));
        // The glow over the lobe and the Jacobian: colour x D at each pixel.
        let lobe = |x: f32, y: f32| {
            // The same pass over a map of ones (every texel 1): the lobe and the Jacobian alone.
            let one = vec![1.0f32; 4];
            let mut flat = frame.scene.clone();
            flat.globals.dirt_footprint = [0.0; 4];
            flat.globals.dirt_centre_texels = [0.5, 0.5];
            cpu::dirt::dirt_glow_at(&flat, &one, 2, [x, y])[1]
        };
        seen.push(
            image
                .pixels
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    let (x, y) = ((k % size.0 as usize) as f32 + 0.5, (k / size.0 as usize) as f32 + 0.5);
                    f64::from(p[1]) / f64::from(lobe(x, y)).max(1e-30)
                })
                .collect::<Vec<f64>>(),
        );
    }
    let moved = [light_px[1][0] - light_px[0][0], light_px[1][1] - light_px[0][1]];
    let followed = [centroids[1][0] - centroids[0][0], centroids[1][1] - centroids[0][1]];
    let along = (followed[0] * moved[0] + followed[1] * moved[1]) / (moved[0].hypot(moved[1]));
    println!("light moved {moved:?} px, the glow's centroid {followed:?} px ({along:.1} px along)");
    assert!(along > 0.5 * moved[0].hypot(moved[1]), "the glow follows the light");
    let peak = seen[0].iter().copied().fold(0.0, f64::max);
    let (mut close, mut lit) = (0usize, 0usize);
    for (a, b) in seen[0].iter().zip(&seen[1]) {
        if *a > 0.1 * peak {
            lit += 1;
            close += usize::from((a - b).abs() <= 0.02 * a);
        }
    }
    println!("the dirt seen: {close} of {lit} well-lit pixels agree within 2% at both light positions");
    assert!(lit > 1000 && close as f64 >= 0.95 * lit as f64, "{close} of {lit}");
}

/// The GPU's dirt pass (`dirt.wgsl`) draws what its CPU twin draws, at full and half accumulation, on one
/// device that uploads each flare's map.
#[test]
fn the_gpu_draws_the_glow_its_cpu_twin_draws() {
    let Some(ctx) = flare_core::render::gpu::test_context() else { return };
    let mut device = frame::Device::Gpu(Box::new(frame::GpuDrawer::on(ctx)));
    for (pattern, divisor, lens) in [
        (DirtPattern::Dust { seed: 1 }, 1, default_lens()),
        (DirtPattern::Smudges { seed: 3 }, 2, default_lens()),
        (DirtPattern::Dust { seed: 4 }, 1, common::toroidal_test_lens()),
    ] {
        let flare = prepared(&lens, Some(pattern), 6, Some(11.0));
        let mut req = request([5.0, 3.0], (320, 200), 0.5, 6.0);
        req.display.accumulation_divisor = divisor;
        req.display.flare_ev = 4.0;
        // The starburst's core (3e4 a pixel) would hide the glow in the comparison.
        req.display.starburst = false;
        let frame = Frame::build(&flare, None, &req);
        assert!(frame.scene.has_dirt_glow());
        let sources = Sources { flare: &flare, lut: None, plate: None };
        let gpu = device.draw(&frame, &sources).unwrap();
        let cpu = frame::draw_cpu(&frame, &sources);
        let glow_level: f64 = glow(&frame, &flare).pixels.iter().map(|p| f64::from(p[1])).sum();
        let (mut diff, mut level) = (0.0f64, 0.0f64);
        for (g, c) in gpu.hdr.pixels.iter().zip(&cpu.hdr.pixels) {
            diff += f64::from((g[1] - c[1]).abs());
            level += f64::from(c[1].abs());
        }
        let worst = gpu.display.pixels.iter().zip(&cpu.display.pixels).map(|(g, c)| g[1].abs_diff(c[1])).max();
        println!(
            "dirt divisor {divisor}: glow {:.0}% of the frame's light; HDR mean relative difference {:.2e}, display worst {worst:?}/255",
            100.0 * glow_level / level,
            diff / level
        );
        assert!(glow_level > 0.2 * level, "the glow is a large part of the frame");
        assert!(diff / level < 0.01, "HDR differs by {}", diff / level);
        assert!(worst.unwrap() <= 4);
    }
}

/// Every method draws the glow and dims the ghosts the same way: the ray-traced reference's frame with dirt is
/// its clean frame times 1 - taken plus the same glow; a layered EXR holds `dirt.R/G/B`.
#[test]
fn the_reference_method_and_the_exr_carry_the_dirt() {
    let lens = default_lens();
    let flare = prepared(&lens, Some(DirtPattern::Dust { seed: 1 }), 6, Some(11.0));
    let frame = Frame::build(&flare, None, &request([5.0, 3.0], (96, 64), 0.05, 6.0));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let mut traced = HdrImage::black(96, 64);
    traced.pixels[96 * 20 + 30] = [1.0, 2.0, 3.0, 0.0];
    let with = frame::drawn_with_traced_ghosts(&frame, &sources, traced.clone());
    let mut expected = frame::traced_accumulation(&frame, &traced);
    cpu::starburst_pass(&frame.scene, &flare.starburst_texture, &mut expected);
    cpu::dirt_pass(&frame.scene, flare.dirt.as_ref(), &mut expected);
    assert_eq!(with.hdr, expected);
    let kept = f64::from(frame::traced_accumulation(&frame, &traced).pixels[96 * 20 + 30][1]) / 2.0;
    assert!((kept - (1.0 - frame.dirt_taken)).abs() < 1e-6 && frame.dirt_taken > 0.0, "kept {kept}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dirt.exr");
    frame::write_drawn(&mut frame::Device::Cpu, &frame, &sources, &with, frame::LayerChoice::default(), &path).unwrap();
    let read = flare_core::output::read_exr_channels(&path).unwrap();
    for c in ["dirt.R", "dirt.G", "dirt.B"] {
        let values = &read.channels[c];
        assert!(values.iter().any(|&v| v > 0.0), "{c} holds the glow");
    }
}

/// The preset's `dirt`: saved and read back whole; a clean lens keeps the optics fingerprint it had before dirt
/// (a preset without the field is that); a dirt pattern changes it (the map is prepared again) but the amount and
/// spread do not (display settings); bad values are refused naming the field.
#[test]
fn a_preset_keeps_its_dirt_and_refuses_bad_dirt() {
    use flare_core::dirt::{DirtDoc, DirtKind};
    use flare_core::preset::Document;
    let clean = Document::default();
    let mut dusty = clean.clone();
    dusty.dirt = DirtDoc { pattern: DirtKind::Dust, seed: 7, amount: 0.02, spread_deg: 5.0, image: None };
    let back = Document::from_json(&dusty.to_json()).unwrap();
    assert_eq!(back.dirt, dusty.dirt);
    let mut json: serde_json::Value = serde_json::from_str(&clean.to_json()).unwrap();
    json.as_object_mut().unwrap().remove("dirt");
    let old = Document::from_json(&json.to_string()).unwrap();
    assert_eq!(old.dirt.pattern, DirtKind::None);
    assert_eq!(old.optics_fingerprint(), clean.optics_fingerprint());
    assert_ne!(dusty.optics_fingerprint(), clean.optics_fingerprint());
    let mut brighter = dusty.clone();
    brighter.dirt.amount = 0.2;
    brighter.dirt.spread_deg = 20.0;
    assert_eq!(brighter.optics_fingerprint(), dusty.optics_fingerprint());
    assert!(dusty.flare_config().unwrap().dirt.is_some() && clean.flare_config().unwrap().dirt.is_none());
    assert_eq!(dusty.display(1).dirt_amount, 0.02);
    assert_eq!(clean.display(1).dirt_amount, 0.0, "no pattern: no glow whatever the amount");
    for (field, value, expect) in [
        ("amount", serde_json::json!(1.5), "dirt.amount"),
        ("amount", serde_json::json!(-0.1), "dirt.amount"),
        ("spread_deg", serde_json::json!(90.0), "dirt.spread_deg"),
        ("pattern", serde_json::json!("mud"), "dirt.pattern"),
        ("pattern", serde_json::json!("image"), "dirt.image"),
    ] {
        let mut json: serde_json::Value = serde_json::from_str(&dusty.to_json()).unwrap();
        json["dirt"][field] = value;
        let why = Document::from_json(&json.to_string()).unwrap_err().to_string();
        assert!(why.contains(expect), "{field}: {why}");
    }
}
