//! Anamorphic optics: toroidal and cylindrical surfaces traced exactly, against the independent figures of
//! `tests/data/reference/toroidal/` (`make_reference.py`: an mpmath tracer at 50 digits that writes the toroid
//! as an implicit surface, shares no code with FlareLab, and finds each section's paraxial focus by its own
//! y-nu trace). Rays start at explicit points with explicit directions (no pupil to agree on), on the image
//! path and every ghost path: landings and directions to 1e-9, the same failures at the same surfaces, the same
//! clear apertures passed outside; each section's focal length and focus to 1e-9 relative, and the sensor half
//! way between the two foci.

use std::path::PathBuf;

use flare_core::optics::formats::load_lens_file;
use flare_core::optics::{
    D_LINE_NM, FirstOrder, Lens, LightPath, Ray, Section, TraceOptions, TraceStatus, Tracer,
};
use glam::DVec3;
use serde_json::Value;

fn folder() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference/toroidal")
}

fn test_lens() -> Lens {
    load_lens_file(&folder().join("toroidal_test_lens.json")).unwrap()
}

fn figures() -> Value {
    serde_json::from_str(&std::fs::read_to_string(folder().join("toroidal_test_lens_reference.json")).unwrap())
        .unwrap()
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
        assert!((s.total_track_mm - focus).abs() <= 1e-9 * focus.abs(), "{word}: focus {} vs {focus}", s.total_track_mm);
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
    let (a, b) = (Tracer::new(&sphere, &LightPath::image(&sphere), D_LINE_NM, z), Tracer::new(&torus, &LightPath::image(&torus), D_LINE_NM, z));
    for (x, y, l, m) in [(0.0, 0.0, 0.0, 0.0), (2.0, -3.0, 0.05, 0.02), (-5.0, 4.0, -0.1, 0.08)] {
        let ray = Ray { origin_mm: DVec3::new(x, y, -10.0), direction: DVec3::new(l, m, 1.0) };
        let (p, q) = (a.trace(&ray, TraceOptions::default()), b.trace(&ray, TraceOptions::default()));
        assert!((p.sensor_point_mm.unwrap() - q.sensor_point_mm.unwrap()).length() < 1e-10);
    }
    // A lens of revolution is its own section, field for field.
    for id in flare_core::optics::library::ids() {
        let lens = flare_core::optics::library::builtin_lens(id).unwrap();
        assert!(!lens.is_anamorphic(), "{id}");
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
