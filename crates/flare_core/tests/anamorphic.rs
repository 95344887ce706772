//! Anamorphic optics: toroidal and cylindrical surfaces traced exactly, against the independent figures of
//! `tests/data/reference/toroidal/` (`make_reference.py`: an mpmath tracer at 50 digits that writes the toroid
//! as an implicit surface, shares no code with FlareLab, and finds each section's paraxial focus by its own
//! y-nu trace). Rays start at explicit points with explicit directions (no pupil to agree on), on the image
//! path and every ghost path: landings and directions to 1e-9, the same failures at the same surfaces, the same
//! clear apertures passed outside; each section's focal length and focus to 1e-9 relative, and the sensor half
//! way between the two foci.

use std::path::PathBuf;

use flare_core::optics::{D_LINE_NM, FirstOrder, Lens, LightPath, Ray, Section, TraceOptions, TraceStatus, Tracer};
use glam::DVec3;
use serde_json::Value;

fn folder() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference/toroidal")
}

mod common;
use common::toroidal_test_lens as test_lens;

fn figures() -> Value {
    serde_json::from_str(&std::fs::read_to_string(folder().join("toroidal_test_lens_reference.json")).unwrap()).unwrap()
}

fn vec3(v: &Value) -> DVec3 {
    DVec3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
}

#[test]
fn each_section_focuses_where_the_independent_paraxial_trace_says() {
    let lens = test_lens();
    assert!(lens.is_anamorphic());
    let r = figures();
    let fo = FirstOrder::d_line(&lens).unwrap();
    for (section, word) in [(Section::X, "x"), (Section::Y, "y")] {
        let s = fo.section(section);
        let efl = r["sections"][word]["efl_mm"].as_f64().unwrap();
        let focus = r["sections"][word]["focus_z_mm"].as_f64().unwrap();
        assert!((s.efl_mm - efl).abs() <= 1e-9 * efl.abs(), "{word}: EFL {} vs {efl}", s.efl_mm);
        assert!(
            (s.total_track_mm - focus).abs() <= 1e-9 * focus.abs(),
            "{word}: focus {} vs {focus}",
            s.total_track_mm
        );
    }
    let sensor = r["sensor_z_mm"].as_f64().unwrap();
    assert!((fo.sensor_z_mm() - sensor).abs() <= 1e-9 * sensor, "sensor {} vs {sensor}", fo.sensor_z_mm());
    // The two sections really differ (the lens squeezes), and the sensor is between the foci.
    let (x, y) = (fo.section(Section::X), fo.section(Section::Y));
    assert!((x.efl_mm - y.efl_mm).abs() > 1.0, "{} {}", x.efl_mm, y.efl_mm);
    assert!(fo.sensor_z_mm() > x.total_track_mm.min(y.total_track_mm));
    assert!(fo.sensor_z_mm() < x.total_track_mm.max(y.total_track_mm));
}

#[test]
fn toroidal_landings_match_the_independent_tracer_to_1e_9_mm() {
    let lens = test_lens();
    let r = figures();
    let sensor_z = FirstOrder::d_line(&lens).unwrap().sensor_z_mm();
    let (mut landed, mut ghost_landed, mut failed, mut skipped, mut skew) = (0, 0, 0, 0, 0);
    let mut worst = 0.0f64;
    for ray in r["rays"].as_array().unwrap() {
        let path = match &ray["path"] {
            Value::String(s) if s == "image" => LightPath::image(&lens),
            p => LightPath::ghost(&lens, p[0].as_u64().unwrap() as usize, p[1].as_u64().unwrap() as usize).unwrap(),
        };
        let tracer = Tracer::new(&lens, &path, D_LINE_NM, sensor_z);
        let start = vec3(&ray["start_mm"]);
        let dir = vec3(&ray["dir"]);
        let ours = tracer.trace(&Ray { origin_mm: start, direction: dir }, TraceOptions::default());
        let what = format!("{} from {start} along {dir}", ray["path"]);
        let clipped: Vec<usize> =
            ray["clipped_at"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        match ray["status"].as_str().unwrap() {
            "beyond" => {
                // Outside a toroid's clear aperture the surface is not the lens: not compared, but FlareLab saw
                // the same clear apertures passed outside up to there.
                assert!(ours.clipped_at.starts_with(&clipped[..clipped.len() - 1]), "{what}: {:?}", ours.clipped_at);
                skipped += 1;
            }
            "ok" => {
                assert_eq!(ours.status, TraceStatus::Landed, "{what}");
                let p = ours.sensor_point_mm.unwrap();
                let d = ours.sensor_direction.unwrap();
                let (rp, rd) = (vec3(&ray["point_mm"]), vec3(&ray["direction"]));
                let err = (p - rp).length();
                worst = worst.max(err);
                assert!(err <= 1e-9, "{what}: landed at {p}, the reference at {rp} ({err:e} mm)");
                assert!((d - rd).length() <= 1e-9, "{what}: direction {d} vs {rd}");
                assert_eq!(ours.clipped_at, clipped, "{what}: clear apertures passed outside");
                landed += 1;
                ghost_landed += usize::from(ray["path"].is_array());
                skew += usize::from(dir.x != 0.0 && start.y != 0.0 || start.x != 0.0 && dir.y != 0.0);
            }
            word => {
                let surface = ray["surface"].as_u64().map(|s| s as usize);
                assert_eq!(ours.status.word(), word, "{what}");
                assert_eq!(ours.status.surface(), surface, "{what}");
                failed += 1;
            }
        }
    }
    eprintln!(
        "toroidal test lens: {landed} rays landed ({ghost_landed} on ghost paths, {skew} skew), worst {worst:.1e} mm; \
         {failed} failed alike; {skipped} beyond a toroid's clear aperture (not compared)"
    );
    assert!(landed >= 300 && ghost_landed >= 100 && skew >= 50, "{landed} {ghost_landed} {skew}");
    assert!(failed >= 1, "a failure (TIR) is compared too");
}

#[test]
fn a_toroid_with_equal_sections_is_the_sphere_and_sections_of_a_round_lens_are_the_lens() {
    // A torus whose radius of rotation equals its profile's radius is that sphere: every landing agrees to
    // rounding with the sphere's exact formulas.
    let sphere = test_lens().section(Section::Y);
    let mut torus = sphere.clone();
    for s in torus.surfaces.iter_mut().filter(|s| s.is_spherical() && !s.is_flat()) {
        s.radius_x_mm = Some(s.radius_mm);
    }
    assert!(torus.is_anamorphic() && !sphere.is_anamorphic());
    let z = FirstOrder::d_line(&sphere).unwrap().sensor_z_mm();
    assert_eq!(FirstOrder::d_line(&torus).unwrap().sensor_z_mm(), z, "equal sections focus together");
    let (a, b) = (
        Tracer::new(&sphere, &LightPath::image(&sphere), D_LINE_NM, z),
        Tracer::new(&torus, &LightPath::image(&torus), D_LINE_NM, z),
    );
    for (x, y, l, m) in [(0.0, 0.0, 0.0, 0.0), (2.0, -3.0, 0.05, 0.02), (-5.0, 4.0, -0.1, 0.08)] {
        let ray = Ray { origin_mm: DVec3::new(x, y, -10.0), direction: DVec3::new(l, m, 1.0) };
        let (p, q) = (a.trace(&ray, TraceOptions::default()), b.trace(&ray, TraceOptions::default()));
        assert!((p.sensor_point_mm.unwrap() - q.sensor_point_mm.unwrap()).length() < 1e-10);
    }
    // A lens of revolution is its own section, field for field; the one anamorphic built-in is not.
    for id in flare_core::optics::library::ids() {
        let lens = flare_core::optics::library::builtin_lens(id).unwrap();
        assert_eq!(lens.is_anamorphic(), id == "panavision_anamorphic_us20060050403", "{id}");
        if lens.is_anamorphic() {
            assert_ne!(lens.section(Section::X), lens, "{id}");
            assert!(FirstOrder::d_line(&lens).unwrap().sections.is_some(), "{id}");
            continue;
        }
        assert_eq!(lens.section(Section::X), lens, "{id}");
        assert_eq!(FirstOrder::d_line(&lens).unwrap().sections, None, "{id}");
    }
}

#[test]
fn impossible_toroids_are_refused_with_the_reason() {
    let lens = test_lens();
    // A radius of rotation smaller than the clear aperture: the torus does not reach the rim.
    let mut narrow = lens.clone();
    narrow.surfaces[0].radius_x_mm = Some(10.0);
    let e = narrow.validate().unwrap_err().to_string();
    assert!(e.contains("surface 0") && e.contains("radius_x") && e.contains("not defined"), "{e}");
    // Not finite.
    let mut nan = lens.clone();
    nan.surfaces[2].radius_x_mm = Some(f64::NAN);
    let e = nan.validate().unwrap_err().to_string();
    assert!(e.contains("surface 2") && e.contains("radius_x"), "{e}");
    // A toroidal stop: the iris is round.
    let mut stop = lens.clone();
    stop.surfaces[4].radius_x_mm = Some(50.0);
    let e = stop.validate().unwrap_err().to_string();
    assert!(e.contains("surface 4") && e.contains("stop"), "{e}");
    // Two surfaces that cross in the x-z section only (the y-z profiles stay apart).
    let mut crossing = lens.clone();
    crossing.surfaces[1].radius_x_mm = Some(8.0e3);
    crossing.surfaces[0].radius_x_mm = Some(14.0);
    crossing.surfaces[0].thickness_mm = Some(3.0);
    let e = crossing.validate().unwrap_err().to_string();
    assert!(e.contains("surfaces 0 and 1 meet"), "{e}");
    // A lone cylinder (power in x only) has no focus in y: no sensor plane, refused naming the section.
    let text = r#"{"id": "cyl", "surfaces": [
        {"radius": 0, "radius_x": 50, "thickness": 4, "nd": 1.5, "vd": 60, "semi_aperture": 10},
        {"radius": 0, "thickness": 5, "nd": 1.0, "semi_aperture": 10},
        {"radius": 0, "thickness": 40, "nd": 1.0, "semi_aperture": 5, "stop": true}]}"#;
    let cylinder: Lens = serde_json::from_str(text).unwrap();
    cylinder.validate().unwrap();
    let e = FirstOrder::d_line(&cylinder).unwrap_err().to_string();
    assert!(e.contains("y-z section") && e.contains("afocal"), "{e}");
}

#[test]
fn the_json_format_keeps_radius_x() {
    let lens = test_lens();
    let text = serde_json::to_string(&lens).unwrap();
    assert!(text.contains("\"radius_x\":40.0") && text.contains("\"radius_x\":0.0"), "{text}");
    let back: Lens = serde_json::from_str(&text).unwrap();
    assert_eq!(back, lens);
    assert_eq!(back.surfaces.iter().filter(|s| s.is_toroidal()).count(), 4);
}

#[test]
fn zemax_toroidal_surfaces_read_and_write_back() {
    use flare_core::optics::formats::{LensFormat, parse_lens, zmx};
    let lens = test_lens();
    let text = zmx::write(&lens).unwrap();
    assert_eq!(text.matches("TYPE TOROIDAL").count(), 4, "{text}");
    let back = parse_lens(&text, Some(LensFormat::Zmx), "toroidal_test_lens").unwrap();
    for (k, (a, b)) in lens.surfaces.iter().zip(&back.surfaces).enumerate() {
        assert_eq!(a.radius_x_mm, b.radius_x_mm, "surface {k}");
        assert_eq!((a.conic, a.aspheric_r2, &a.aspheric), (b.conic, b.aspheric_r2, &b.aspheric), "surface {k}");
        assert!((a.radius_mm - b.radius_mm).abs() <= 1e-12 * a.radius_mm.abs(), "surface {k}");
    }
    // A file in inches: PARM 1 (the radius of rotation) is a length, PARM 2 (y^2) is 1/length, PARM 3 (y^4)
    // 1/length^3; XDAT all 0 (no Zernike terms) is a plain toroid.
    let inches = "MODE SEQ\nUNIT IN\nSURF 0\n  DISZ INFINITY\nSURF 1\n  TYPE TOROIDAL\n  CURV 0.5\n  CONI -0.25\n  \
                  PARM 1 -3\n  PARM 2 0.01\n  PARM 3 0.002\n  XDAT 1 0 0 0 0 0 0 \"\"\n  XDAT 2 0 0 0 0 0 0 \"\"\n  \
                  DISZ 0.2\n  GLAS N-BK7 0 0 1.5168 64.17\n  DIAM 0.4 1 0 0 1 \"\"\nSURF 2\n  STOP\n  CURV 0\n  DISZ 1.5\n  \
                  DIAM 0.4 1 0 0 1 \"\"\nSURF 3\n";
    let lens = parse_lens(inches, Some(LensFormat::Zmx), "inches").unwrap();
    let s = &lens.surfaces[0];
    let inch = 25.4;
    assert_eq!(s.radius_x_mm, Some(-3.0 * inch));
    assert!((s.radius_mm - 2.0 * inch).abs() < 1e-12);
    assert_eq!(s.conic, -0.25);
    assert!((s.aspheric_r2 - 0.01 / inch).abs() < 1e-18 && (s.aspheric[0] - 0.002 / inch.powi(3)).abs() < 1e-20);
    // Zernike terms on the toroid change the surface: refused by line.
    let zernike = inches.replace("XDAT 2 0 0", "XDAT 2 0.5 0");
    let e = parse_lens(&zernike, Some(LensFormat::Zmx), "z").unwrap_err().to_string();
    assert!(e.contains("line 13") && e.contains("XDAT"), "{e}");
    // A y^16 term cannot be written as a TOROIDAL.
    let mut long = test_lens();
    long.surfaces[0].aspheric = vec![1e-7; 7];
    let e = zmx::write(&long).unwrap_err().to_string();
    assert!(e.contains("surface 0") && e.contains("y^14"), "{e}");
    // The formats with spheres only refuse the toroid by name.
    for e in [
        flare_core::optics::formats::pbrt::write(&test_lens()).unwrap_err().to_string(),
        flare_core::optics::formats::flaresim::write(&test_lens()).unwrap_err().to_string(),
    ] {
        assert!(e.contains("surface 0"), "{e}");
    }
}

/// Random toroids (any radius of rotation of either sign, flat, or barely wider than the clear aperture) on
/// the test lens, and rays from anywhere in front of it up to grazing: every trace is an outcome, never a NaN,
/// and a landing is finite; paraxial rays land where each section's paraxial focus says.
mod stress {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: common::cases_or(64), ..ProptestConfig::default() })]
        #[test]
        fn toroids_never_give_nan(
            radii in proptest::collection::vec(prop_oneof![Just(0.0), -400.0..-12.0f64, 12.0..400.0f64], 4),
            start in (-12.0..12.0f64, -12.0..12.0f64, -40.0..-0.5f64),
            dir in (-3.0..3.0f64, -3.0..3.0f64, 0.001..1.0f64),
        ) {
            let mut lens = test_lens();
            for (k, r) in [0, 2, 6, 7].into_iter().zip(&radii) {
                lens.surfaces[k].radius_x_mm = Some(*r);
            }
            prop_assume!(lens.validate().is_ok());
            let Ok(fo) = FirstOrder::d_line(&lens) else { return Ok(()) };
            let (origin_mm, direction) = (DVec3::new(start.0, start.1, start.2), DVec3::new(dir.0, dir.1, dir.2));
            let ray = Ray { origin_mm, direction };
            let mut paths = vec![LightPath::image(&lens)];
            paths.extend(lens.ghost_pairs().iter().step_by(7).map(|&(i, j)| LightPath::ghost(&lens, i, j).unwrap()));
            for path in &paths {
                let out = Tracer::new(&lens, path, D_LINE_NM, fo.sensor_z_mm()).trace(&ray, TraceOptions::default());
                if out.status == TraceStatus::Landed {
                    prop_assert!(out.sensor_point_mm.unwrap().is_finite() && out.sensor_direction.unwrap().is_finite());
                } else {
                    prop_assert!(out.sensor_point_mm.is_none());
                }
            }
        }
    }

    /// A ray parallel to the axis, close to it, crosses the axis at each section's own paraxial focus: in x
    /// at the x-z focus, in y at the y-z focus (the error shrinks like h^2).
    #[test]
    fn near_axis_rays_focus_per_section() {
        let lens = test_lens();
        let fo = FirstOrder::d_line(&lens).unwrap();
        for (section, axis) in [(Section::X, DVec3::X), (Section::Y, DVec3::Y)] {
            let focus = fo.section(section).sensor_z_mm();
            let tracer = Tracer::new(&lens, &LightPath::image(&lens), D_LINE_NM, focus);
            let mut errors = Vec::new();
            for h in [0.02, 0.01] {
                let ray = Ray { origin_mm: axis * h + DVec3::new(0.0, 0.0, -5.0), direction: DVec3::Z };
                let landing = tracer.trace(&ray, TraceOptions::default()).sensor_point_mm.unwrap();
                errors.push(landing.x.hypot(landing.y) / h);
            }
            assert!(errors[0] < 1e-3 && errors[1] < errors[0] / 3.0, "{section:?}: {errors:?}");
        }
    }
}

/// The paraxial ghosts of the anamorphic lens, section by section: each ghost's image of the stop is an ellipse
/// whose centre and semi-axes agree with the independent script's own paraxial trace (slopes along +z, another
/// convention than FlareLab's) to 1e-9 mm (relative 1e-12 for the huge near-afocal ghosts); and the exact
/// tracer agrees with the ghost matrices of each section near the axis (the error shrinks like h^2).
#[test]
fn ghost_ellipses_match_the_independent_paraxial_trace_and_the_exact_tracer() {
    use flare_core::ghost::{GhostSettings, GhostSystem};
    use flare_core::spectrum::Spectrum;
    let lens = test_lens();
    let settings = GhostSettings { spectrum: Spectrum::single(D_LINE_NM).unwrap(), ..Default::default() };
    let system = GhostSystem::build(&lens, &settings).unwrap();
    assert!(system.is_anamorphic());
    struct Sections<'a> {
        x: &'a GhostSystem,
        y: &'a GhostSystem,
    }
    let ghosts = Sections { x: system.x_system(), y: &system };
    assert_eq!(ghosts.x.ghosts.len(), 45);
    let r = figures();
    let u = [0.03, -0.05];
    let mut elongated = 0;
    for e in r["ghost_ellipses"].as_array().unwrap() {
        let (i, j) = (e["i"].as_u64().unwrap() as usize, e["j"].as_u64().unwrap() as usize);
        let g = ghosts.x.ghosts.iter().position(|m| (m.i, m.j) == (i, j)).unwrap();
        assert_eq!((ghosts.y.ghosts[g].i, ghosts.y.ghosts[g].j), (i, j), "both sections list the ghosts alike");
        let (centre, semi) = system.stop_image_ellipse(g, 0, u).unwrap();
        let expect = |s: &str, field: &str| e[s][field].as_f64().unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 + 1e-12 * b.abs();
        let what = format!("ghost ({i}, {j})");
        assert!(close(centre[0], expect("x", "centre_per_slope") * u[0]), "{what}: x centre {}", centre[0]);
        assert!(close(centre[1], expect("y", "centre_per_slope") * u[1]), "{what}: y centre {}", centre[1]);
        assert!(close(semi[0], expect("x", "semi_axis_mm")), "{what}: x semi-axis {} vs {}", semi[0], e["x"]);
        assert!(close(semi[1], expect("y", "semi_axis_mm")), "{what}: y semi-axis {} vs {}", semi[1], e["y"]);
        elongated += usize::from((semi[0] / semi[1] - 1.0).abs() > 0.05);
    }
    assert!(elongated >= 20, "most ghosts of the test lens are ovals: {elongated}");
    // Exact ghost rays parallel to the axis at height h in one section land at A_f h (the section's ghost
    // matrix) up to O(h^3).
    let sensor_z = FirstOrder::d_line(&lens).unwrap().sensor_z_mm();
    for (g, &(i, j)) in lens.ghost_pairs().iter().enumerate().step_by(4) {
        let path = LightPath::ghost(&lens, i, j).unwrap();
        let tracer = Tracer::new(&lens, &path, D_LINE_NM, sensor_z);
        for (system, axis) in [(&ghosts.x, DVec3::X), (&ghosts.y, DVec3::Y)] {
            let a_f = system.ghosts[g].per_wavelength[0].matrices.sensor_from_entrance.a;
            let mut errors = Vec::new();
            for h in [0.02, 0.01] {
                let ray = Ray { origin_mm: axis * h + DVec3::new(0.0, 0.0, -5.0), direction: DVec3::Z };
                let landing = tracer.trace(&ray, TraceOptions::default()).sensor_point_mm.unwrap();
                errors.push((landing.dot(axis) - a_f * h).abs() / h);
                assert!(landing.dot(axis.cross(DVec3::Z)).abs() < 1e-12, "({i}, {j}): stays in its section");
            }
            assert!(errors[1] <= errors[0] / 3.0 + 1e-9, "({i}, {j}) {axis}: {errors:?} (A_f {a_f})");
            assert!(errors[0] < 1e-2 * (1.0 + a_f.abs()), "({i}, {j}) {axis}: {errors:?} (A_f {a_f})");
        }
    }
}

/// The anamorphic flare by the paraxial method against the ray-traced reference (the f64 tracer through the
/// real toroids) where the paraxial method is exact: at f/22 with the light near the axis, on the ghosts whose
/// entrance region the stop bounds in both sections (the method's premise: it clips by the stop and the front
/// element only). Measured as the round lenses are: centroids within half a pixel (median), PSNR above 35 dB,
/// and each visible ghost's energy within 5 % wherever the paraxial method meets that on both sections' lenses
/// of revolution (this test lens is aggressive: a few ghosts that run through its strongly curved rear group
/// miss it on the round sections too, by the paraxial method's own limits, and are reported). Each of the
/// brightest ghosts, drawn alone, has the same ellipse in both methods: its spread along x and along y (second
/// moments) within 5 %; and most of them are ovals, not circles.
#[test]
fn the_paraxial_ellipses_agree_with_the_ray_traced_reference() {
    let anamorphic = measure_against_reference(&test_lens());
    let c = &anamorphic.comparison;
    assert!(c.centroid_px < 0.5 && c.psnr_db > 35.0, "{c:?}");
    let round: Vec<Measured> =
        [Section::X, Section::Y].iter().map(|&s| measure_against_reference(&test_lens().section(s))).collect();
    let exact_on_sections = |g: usize| round.iter().all(|m| m.ratio[g].is_some_and(|r| (r - 1.0).abs() < 0.05));
    let (mut checked, mut left) = (0, Vec::new());
    for (g, ratio) in anamorphic.ratio.iter().enumerate() {
        let Some(ratio) = ratio else { continue };
        if exact_on_sections(g) {
            assert!((ratio - 1.0).abs() < 0.05, "ghost {g}: energy paraxial / reference {ratio}");
            checked += 1;
        } else {
            left.push((g, *ratio));
        }
    }
    eprintln!("{checked} visible ghosts within 5 %; left out (the round sections miss too): {left:.3?}");
    assert!(checked >= 15, "{checked}");
    let mut ovals = 0;
    for (g, ours, theirs) in &anamorphic.spreads {
        for axis in 0..2 {
            assert!((ours[axis] / theirs[axis] - 1.0).abs() < 0.05, "ghost {g} axis {axis}: {ours:?} vs {theirs:?}");
        }
        ovals += usize::from((ours[0] / ours[1] - 1.0).abs() > 0.1);
    }
    assert!(anamorphic.spreads.len() >= 3 && ovals >= 2, "the brightest ghosts are ovals: {ovals}");
}

/// What [`measure_against_reference`] finds.
struct Measured {
    comparison: flare_core::metrics::Comparison,
    /// Per ghost, paraxial over traced energy in the frame, for the visible stop-bounded ghosts.
    ratio: Vec<Option<f64>>,
    /// Up to four of the brightest, a few pixels wide or more: ghost, spread (x, y) paraxial, spread traced (px).
    spreads: Vec<(usize, [f64; 2], [f64; 2])>,
}

/// `lens` at f/22, the light at (1.5, 1) degrees, 240 x 160, its stop-bounded ghosts by both methods.
fn measure_against_reference(lens: &Lens) -> Measured {
    use flare_core::aperture::Aperture;
    use flare_core::flare::{FlareConfig, PreparedFlare};
    use flare_core::image::{GhostMoments, HdrImage};
    use flare_core::metrics;
    use flare_core::optics::sensor::Sensor;
    use flare_core::raytrace::{Ghosts, Grid, RayGridRequest};
    use flare_core::render::{DisplaySettings, cpu};
    let (w, h) = (240, 160);
    let light = [1.5, 1.0];
    let config = FlareConfig {
        aperture: Aperture { f_number: Some(22.0), ..Aperture::default() },
        intensity_threshold: Some(0.0),
        ..FlareConfig::default()
    };
    let flare = PreparedFlare::new(lens, &config).unwrap();
    let system = &flare.system;
    assert_eq!(system.is_anamorphic(), lens.is_anamorphic());
    // The stop bounds a ghost's entrance region when its disc (r_a / |A|, per section) is well inside the front
    // element's.
    let stop_bounded = |g: usize| {
        [system.x_system(), system].iter().all(|s| {
            let a = s.ghosts[g].per_wavelength[0].matrices.stop_from_entrance[0].a;
            s.stop_radius_mm / a.abs() < 0.5 * s.front_radius_mm
        })
    };
    let gains: Vec<f32> = (0..system.ghosts.len()).map(|g| if stop_bounded(g) { 1.0 } else { 0.0 }).collect();
    let sensor = Sensor::full_frame_for(w, h);
    let renderer = flare.ray_grid_renderer();
    let render = |gains: &[f32]| {
        let (scene, _) = flare.scene_with(light, sensor, w, h, &DisplaySettings::default(), gains);
        let request = RayGridRequest {
            ghosts: Ghosts::Weighted(gains),
            ..RayGridRequest::frame(light, w, h, Grid::Adaptive(256))
        };
        let traced = renderer.render_request(&request).unwrap().remove(0);
        let paraxial = cpu::ghost_pass(&scene, &flare.ghost_masks);
        let moments = cpu::ghost_moments(&scene, &flare.ghost_masks, system.ghosts.len());
        (paraxial, moments, traced)
    };
    let (paraxial, moments, traced) = render(&gains);
    let comparison = metrics::compare(&paraxial, &moments, &traced.hdr, &traced.moments);
    eprintln!("{}: {} stop-bounded ghosts, {comparison:?}", lens.id, gains.iter().filter(|&&g| g > 0.0).count());
    let energy = |m: &[GhostMoments]| m.iter().map(|g| g.energy).collect::<Vec<_>>();
    let (a, b) = (energy(&moments), energy(&traced.moments));
    let brightest = b.iter().cloned().fold(0.0, f64::max);
    let visible = |g: usize| gains[g] > 0.0 && b[g] > 0.05 * brightest;
    let ratio: Vec<Option<f64>> = (0..b.len()).map(|g| visible(g).then(|| a[g] / b[g])).collect();
    // The spread of one ghost along x and y: the square roots of its second moments about its centroid.
    let spread = |img: &HdrImage| {
        let (mut e, mut sx, mut sy, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (k, p) in img.pixels.iter().enumerate() {
            let v = f64::from(p[0] + p[1] + p[2]);
            let (x, y) = ((k % img.width as usize) as f64, (k / img.width as usize) as f64);
            (e, sx, sy, sxx, syy) = (e + v, sx + v * x, sy + v * y, sxx + v * x * x, syy + v * y * y);
        }
        let (mx, my) = (sx / e, sy / e);
        [(sxx / e - mx * mx).sqrt(), (syy / e - my * my).sqrt()]
    };
    let mut order: Vec<usize> = (0..b.len()).filter(|&g| visible(g)).collect();
    order.sort_by(|&p, &q| b[q].total_cmp(&b[p]));
    // The brightest whose spreads span a few pixels (a ghost a pixel wide is measured by its pixels, not its
    // shape), at most four of the ten brightest.
    let mut spreads = Vec::new();
    for &g in order.iter().take(if lens.is_anamorphic() { 10 } else { 0 }) {
        let mut solo = vec![0.0f32; system.ghosts.len()];
        solo[g] = 1.0;
        let (paraxial, _, traced) = render(&solo);
        let (ours, theirs) = (spread(&paraxial), spread(&traced.hdr));
        eprintln!("ghost {g}: spread x, y {ours:.2?} px paraxial, {theirs:.2?} px traced");
        if ours.iter().all(|&s| s >= 2.5) {
            spreads.push((g, ours, theirs));
        }
        if spreads.len() == 4 {
            break;
        }
    }
    Measured { comparison, ratio, spreads }
}

/// The anamorphic streak, from the optics: surfaces 7 (a cylinder with power in y only) and 8 (flat) are flat
/// in the x-z section, so the ghost that reflects between them is, along x, a double reflection off two plane
/// mirrors: it adds no power, and the ghost focuses along x where the lens focuses x (1.05 mm behind the sensor,
/// half the distance between the two sections' foci), a thin line a fraction of a millimetre wide; along y the
/// cylinder's power throws it far out of focus, 11 mm tall. A ghost between surfaces curved in both sections is
/// an ordinary oval. The report says both foci, and the sprites have those extents.
#[test]
fn a_ghost_between_surfaces_flat_in_x_is_a_streak_along_y() {
    use flare_core::flare::{FlareConfig, PreparedFlare};
    use flare_core::report::ghost_report;
    let lens = test_lens();
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let u = [0.0, 3f64.to_radians().tan()];
    let report = ghost_report(&lens, &flare.system, flare.mask(), u).unwrap();
    let row = |i: usize, j: usize| report.ghosts.iter().find(|g| (g.i, g.j) == (i, j)).unwrap();
    let fo = FirstOrder::d_line(&lens).unwrap();
    let x_focus_behind_sensor = fo.section(Section::X).sensor_z_mm() - fo.sensor_z_mm();
    let streak = row(7, 8);
    assert!((streak.focus_x_mm.unwrap() - x_focus_behind_sensor).abs() < 0.1, "{streak:?} vs {x_focus_behind_sensor}");
    assert!(streak.image_width_mm < 0.05 * streak.image_diameter_mm, "{streak:?}");
    assert!(streak.focus_mm.unwrap().abs() > 10.0, "{streak:?}");
    let oval = row(3, 5);
    assert!(oval.image_width_mm > 0.3 * oval.image_diameter_mm && oval.image_width_mm < 3.0 * oval.image_diameter_mm);
    // For a lens of revolution the two foci and sizes are one.
    let round = flare_core::optics::library::builtin_lens("pbrt_dgauss_50mm").unwrap();
    let flare = PreparedFlare::new(&round, &FlareConfig::default()).unwrap();
    for g in ghost_report(&round, &flare.system, flare.mask(), u).unwrap().ghosts {
        assert_eq!((g.focus_x_mm, g.image_width_mm), (g.focus_mm, g.image_diameter_mm));
    }
}

/// The starburst of an anamorphic lens: diffraction scales with the working f-number, which differs per
/// section, so the far field is the round pattern stretched along x by N_x / N_y, its energy kept (divided by
/// the stretch, the Jacobian). Checked on the CPU twin with the light's image on a pixel centre and a stretch of
/// 2: the pixel 2k to the right holds half of what the round pattern has k to the right, exactly; the pixel k
/// below, half of the round one's. The test lens's stretch is its sections' f-numbers' ratio; a lens of
/// revolution's uniform keeps 0 (today's frame).
#[test]
fn the_starburst_stretches_with_the_sections_f_numbers() {
    use flare_core::flare::{FlareConfig, PreparedFlare};
    use flare_core::image::HdrImage;
    use flare_core::render::cpu;
    let lens = test_lens();
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let (scene, _) = flare.scene([3.0, 2.0], 200, 160);
    let fo = FirstOrder::d_line(&lens).unwrap();
    let expected = fo.section(Section::X).f_number / fo.section(Section::Y).f_number;
    assert!((f64::from(scene.globals.starburst_stretch_x) - expected).abs() < 1e-6 && (expected - 1.0).abs() > 0.05);
    let round = PreparedFlare::new(
        &flare_core::optics::library::builtin_lens("pbrt_dgauss_50mm").unwrap(),
        &FlareConfig::default(),
    )
    .unwrap();
    assert_eq!(round.scene([3.0, 2.0], 200, 160).0.globals.starburst_stretch_x, 0.0);
    let draw = |stretch: f32| {
        let mut s = scene.clone();
        s.globals.starburst_centre_px = [100.5, 80.5];
        s.globals.starburst_reach_px = 60.0;
        s.globals.starburst_stretch_x = stretch;
        let mut hdr = HdrImage::black(s.hdr_width, s.hdr_height);
        cpu::starburst_pass(&s, &flare.starburst_texture, &mut hdr);
        hdr
    };
    assert_eq!((scene.hdr_width, scene.hdr_height), (200, 160));
    let (plain, stretched) = (draw(0.0), draw(2.0));
    let at = |img: &HdrImage, x: usize, y: usize| img.pixels[y * 200 + x];
    let mut compared = 0;
    for k in 2..25 {
        let (wide, round) = (at(&stretched, 100 + 2 * k, 80), at(&plain, 100 + k, 80));
        let (below, round_below) = (at(&stretched, 100, 80 + k), at(&plain, 100, 80 + k));
        for c in 0..3 {
            assert_eq!(wide[c], round[c] / 2.0, "k {k}");
            assert_eq!(below[c], round_below[c] / 2.0, "k {k}");
        }
        compared += usize::from(round[0] > 0.0);
    }
    assert!(compared > 10);
}

/// The built-in anamorphic lens (Panavision's US 2006/0050403 A1, from a three-figure transcription): its
/// sections squeeze as the source says (1.3; EFL 19.7 mm), and its ghosts show the streaks the README explains
/// from the optics. A ghost between two of the rear cylinders with power in x (flat in y-z) adds no power in y:
/// it stays near focus along y, a horizontal line; between two with power in y, a vertical one. Light 3 degrees
/// up: 26 of the 28 visible ghosts between x cylinders are at least 3 times wider than tall (up to 32 mm by
/// 0.7 mm), and 14 of the 15 between y cylinders 3 times taller than wide (the exceptions pair a weak cylinder,
/// 386 or 262 mm, with a strong one, or sit far from focus).
#[test]
fn the_built_in_panavision_squeezes_and_streaks() {
    use flare_core::flare::{FlareConfig, PreparedFlare};
    use flare_core::report::ghost_report;
    let lens = flare_core::optics::library::builtin_lens("panavision_anamorphic_us20060050403").unwrap();
    let fo = FirstOrder::d_line(&lens).unwrap();
    let (x, y) = (fo.section(Section::X), fo.section(Section::Y));
    let squeeze = y.efl_mm / x.efl_mm;
    assert!((squeeze - 1.3).abs() < 0.015, "squeeze {squeeze}");
    assert!((y.efl_mm - 19.7).abs() < 0.05 * 19.7, "EFL {}", y.efl_mm);
    assert!((x.sensor_z_mm() - y.sensor_z_mm()).abs() < 0.5, "the sections' foci are far apart");
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let report = ghost_report(&lens, &flare.system, flare.mask(), [0.0, 3f64.to_radians().tan()]).unwrap();
    let powered_in_x = |s: usize| lens.surfaces[s].radius_mm == 0.0 && lens.surfaces[s].radius_x_mm.is_some();
    let powered_in_y = |s: usize| lens.surfaces[s].radius_x_mm == Some(0.0);
    // (ghosts, of them streaks) between x cylinders, then between y cylinders.
    let (mut horizontal, mut vertical) = ((0, 0), (0, 0));
    for g in report.ghosts.iter().filter(|g| g.image_diameter_mm > 0.0 && g.image_width_mm > 0.0) {
        let (w, h) = (g.image_width_mm, g.image_diameter_mm);
        if powered_in_x(g.i) && powered_in_x(g.j) {
            horizontal = (horizontal.0 + 1, horizontal.1 + usize::from(w > 3.0 * h));
        }
        if powered_in_y(g.i) && powered_in_y(g.j) {
            vertical = (vertical.0 + 1, vertical.1 + usize::from(h > 3.0 * w));
        }
    }
    eprintln!("streaks: {horizontal:?} horizontal, {vertical:?} vertical (ghosts, of them 3:1)");
    for (ghosts, streaks) in [horizontal, vertical] {
        assert!(ghosts >= 10 && streaks * 10 >= ghosts * 9, "{horizontal:?} {vertical:?}");
    }
}
