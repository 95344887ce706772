//! Agreement with the independent reference figures of `tests/data/reference/` (ray-optics 0.9.8, cross-checked
//! by a second exact tracer; for the two aspheric lenses, `aspheric/make_reference.py`, an mpmath tracer
//! written apart from FlareLab, with skew rays): first-order data to 1e-9 relative, every ray and ghost-ray landing to 1e-9 mm,
//! the same rays failing (TIR / missed) at the same surfaces, the same clear apertures passed outside, and the
//! paraxial ghost fans to 1e-9 mm.
//!
//! Three ray-optics first-order numbers (entrance pupil position, f-number, exit pupil position) carry errors
//! of up to 1.4e-7 relative of their own; `exact_first_order.py` shows it with rational arithmetic. Those three
//! are checked against the exact values to 1e-12, and against ray-optics to its own error (2e-7). The rays
//! are defined by the reference's pupil numbers, so they are launched from those.

use std::collections::BTreeSet;
use std::path::PathBuf;

use flare_core::optics::library::{builtin_lens, ids};
use flare_core::optics::{
    D_LINE_NM, EntrancePupil, FirstOrder, LightPath, PathMatrices, TraceOptions, TraceStatus, Tracer, pupil_ray,
};
use serde_json::Value;

fn data(name: &str) -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

/// The figures of a lens: `tests/data/reference/` for the six lenses of shared/reference, its `aspheric/`
/// folder for the aspheric lenses (made by `aspheric/make_reference.py`, an independent mpmath tracer).
fn reference(id: &str) -> Value {
    if is_aspheric(id) { data(&format!("aspheric/{id}.json")) } else { data(&format!("{id}.json")) }
}

fn is_aspheric(id: &str) -> bool {
    ASPHERIC.contains(&id)
}

/// The built-in aspheric lenses with independent figures.
const ASPHERIC: [&str; 2] = ["zeiss_master_prime_us5537259", "aspheric_zoom_us5793533"];

/// The pupil the reference rays are defined by.
fn reference_pupil(r: &Value) -> EntrancePupil {
    let fo = &r["first_order"];
    EntrancePupil { z_mm: f(&fo["enp_dist"]), radius_mm: 0.5 * f(&fo["enp_diameter"]) }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn surfaces(v: Option<&Value>) -> Vec<usize> {
    v.and_then(Value::as_array).map(|a| a.iter().map(|x| x.as_u64().unwrap() as usize).collect()).unwrap_or_default()
}

fn failure_word(status: TraceStatus) -> String {
    match status {
        TraceStatus::Tir { surface } => format!("tir@{surface}"),
        TraceStatus::Missed { surface } => format!("miss@{surface}"),
        TraceStatus::Backward => "backward@sensor".to_owned(),
        other => panic!("unexpected {other:?} with apertures not applied"),
    }
}

#[test]
fn first_order_data_agree_to_1e_9_relative() {
    for id in with_figures() {
        let lens = builtin_lens(id).unwrap();
        let r = &reference(id)["first_order"];
        // The mpmath tracer's figures are exact to f64 already.
        let exact = if is_aspheric(id) { r } else { &data("exact_first_order.json")[id] };
        let fo = FirstOrder::compute(&lens, D_LINE_NM).unwrap();
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        let pairs = [
            ("efl", fo.efl_mm, 1e-9),
            ("bfd", fo.bfd_mm, 1e-9),
            ("enp_diameter", fo.entrance_pupil_diameter_mm, 1e-9),
            ("total_track", fo.total_track_mm, 1e-9),
            ("enp_dist", fo.entrance_pupil_z_mm, 2e-7),
            ("fno", fo.f_number, 2e-7),
            ("exp_dist", fo.exit_pupil_z_mm, 2e-7),
        ];
        for (key, ours, against_ray_optics) in pairs {
            let (theirs, exact) = (f(&r[key]), f(&exact[key]));
            assert!(rel(ours, exact) < 1e-12, "{id} {key}: ours {ours} exact {exact}");
            assert!(rel(ours, theirs) < against_ray_optics, "{id} {key}: ours {ours} reference {theirs}");
        }
        assert_eq!(fo.stop_surface as u64, r["stop_surface"].as_u64().unwrap(), "{id} stop surface");
    }
}

#[test]
fn image_rays_land_where_the_reference_says_to_1e_9_mm() {
    let (mut checked, mut skew, mut worst, mut beyond) = (0, 0, 0.0f64, 0);
    for id in with_figures() {
        let lens = builtin_lens(id).unwrap();
        let fo = FirstOrder::d_line(&lens).unwrap();
        let tracer = Tracer::new(&lens, &LightPath::image(&lens), D_LINE_NM, fo.sensor_z_mm());
        let reference = reference(id);
        let pupil = reference_pupil(&reference);
        for r in reference["rays"].as_array().unwrap() {
            if r.get("beyond_asphere").is_some() {
                // Outside an asphere's clear aperture the figures do not say (see make_reference.py).
                beyond += 1;
                continue;
            }
            let (theta_deg, px, py) = (f(&r["theta_deg"]), f(&r["px"]), f(&r["py"]));
            let ray = pupil_ray(&pupil, theta_deg.to_radians(), px, py);
            let out = tracer.trace(&ray, TraceOptions::default());
            checked += 1;
            skew += usize::from(px != 0.0);
            if r["x"].is_null() {
                // The reference lists a ray with no landing (telephoto at 20 degrees): it must fail here too.
                assert_ne!(out.status, TraceStatus::Landed, "{id} ray {r}: the reference says it fails");
                continue;
            }
            assert_eq!(out.status, TraceStatus::Landed, "{id} ray {r}");
            let p = out.sensor_point_mm.unwrap();
            worst = worst.max((p.x - f(&r["x"])).abs()).max((p.y - f(&r["y"])).abs());
            assert!(
                (p.x - f(&r["x"])).abs() < 1e-9 && (p.y - f(&r["y"])).abs() < 1e-9,
                "{id} ray {r}: ours ({}, {})",
                p.x,
                p.y
            );
            assert_eq!(out.clipped_at, surfaces(r.get("vignetted_at_surfaces")), "{id} ray {r}: clear apertures");
        }
    }
    println!("{checked} image rays ({skew} skew) within {worst:.1e} mm; {beyond} beyond an asphere's aperture");
    assert_eq!(checked + beyond, 6 * 24 + 2 * 28);
    assert!(beyond <= 8, "most rays are compared: {beyond} skipped");
    assert!(skew >= 2 * 8, "the aspheric figures hold skew rays: {skew}");
}

#[test]
fn ghost_fans_agree_exact_and_paraxial_to_1e_9_mm() {
    let (mut landed, mut failed, mut paraxial, mut skipped, mut aspheric_landed) = (0, 0, 0, 0, 0);
    let (mut worst_exact, mut worst_paraxial) = (0.0_f64, 0.0_f64);
    for id in with_figures() {
        let lens = builtin_lens(id).unwrap();
        let fo = FirstOrder::d_line(&lens).unwrap();
        let r = reference(id);
        let pupil = reference_pupil(&r);
        let g = &r["ghosts"];
        let pairs = lens.ghost_pairs();
        assert_eq!(pairs.len() as u64, g["count"].as_u64().unwrap(), "{id} ghost count");
        let fan: Vec<f64> = g["pupil_fan_py"].as_array().unwrap().iter().map(f).collect();
        for entry in g["table"].as_array().unwrap() {
            let (i, j) = (entry["i"].as_u64().unwrap() as usize, entry["j"].as_u64().unwrap() as usize);
            assert!(pairs.contains(&(i, j)), "{id}: reference ghost ({i}, {j}) not enumerated");
            let path = LightPath::ghost(&lens, i, j).unwrap();
            let tracer = Tracer::new(&lens, &path, D_LINE_NM, fo.sensor_z_mm());
            let matrices = PathMatrices::compute(&lens, &path, D_LINE_NM, fo.sensor_z_mm());
            for by in entry["by_theta"].as_array().unwrap() {
                let theta = f(&by["theta_deg"]).to_radians();
                let mut fails = BTreeSet::new();
                let beyond = surfaces(by.get("beyond_asphere"));
                for (k, &py) in fan.iter().enumerate() {
                    if beyond.contains(&k) {
                        skipped += 1;
                        continue;
                    }
                    let what = format!("{id} ghost ({i}, {j}) theta {} py {py}", by["theta_deg"]);
                    let out = tracer.trace(&pupil_ray(&pupil, theta, 0.0, py), TraceOptions::default());
                    match by["exact_y_fan"][k].as_f64() {
                        Some(y) => {
                            assert_eq!(out.status, TraceStatus::Landed, "{what}");
                            let ours = out.sensor_point_mm.unwrap().y;
                            assert!((ours - y).abs() < 1e-9, "{what}: exact y ours {ours} reference {y}");
                            worst_exact = worst_exact.max((ours - y).abs());
                            landed += 1;
                            aspheric_landed += usize::from(is_aspheric(id));
                        }
                        None => {
                            assert_ne!(out.status, TraceStatus::Landed, "{what}: reference says it fails");
                            fails.insert(failure_word(out.status));
                            failed += 1;
                        }
                    }
                    assert_eq!(out.clipped_at, surfaces(by["clipped_at"].get(k)), "{what}: clear apertures");
                    let para = matrices.landing_height_mm(&pupil, py * pupil.radius_mm, theta.tan());
                    let theirs = f(&by["paraxial_y_fan"][k]);
                    assert!((para - theirs).abs() < 1e-9, "{what}: paraxial ours {para} reference {theirs}");
                    worst_paraxial = worst_paraxial.max((para - theirs).abs());
                    paraxial += 1;
                }
                let theirs: BTreeSet<String> =
                    by["fails"].as_array().unwrap().iter().map(|s| s.as_str().unwrap().to_owned()).collect();
                assert_eq!(fails, theirs, "{id} ghost ({i}, {j}) theta {}: failures", by["theta_deg"]);
            }
        }
    }
    println!(
        "ghost rays: {landed} landed (worst {worst_exact:.1e} mm), {failed} failed as the reference says, \
         {paraxial} paraxial heights (worst {worst_paraxial:.1e} mm); aspheric lenses: {aspheric_landed} landed, \
         {skipped} beyond an asphere's aperture"
    );
    assert!(aspheric_landed >= 1500, "aspheric ghost rays compared: {aspheric_landed}");
    assert!(skipped < aspheric_landed, "most aspheric ghost rays are compared: {skipped} skipped");
    assert!(landed > 500 && failed > 300, "{landed} {failed}");
}

/// The built-in lenses that have independent reference figures: the six of shared/reference and the two
/// aspheric ones.
fn with_figures() -> Vec<&'static str> {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference");
    let found: Vec<&'static str> = ids().into_iter().filter(|id| dir.join(format!("{id}.json")).exists()).collect();
    assert_eq!(found.len(), 6, "reference figures for the six lenses of shared/reference: {found:?}");
    for id in ASPHERIC {
        assert!(dir.join(format!("aspheric/{id}.json")).exists(), "figures for {id}");
        assert!(builtin_lens(id).unwrap().surfaces.iter().any(|s| !s.is_spherical()), "{id} is aspheric");
    }
    found.into_iter().chain(ASPHERIC).collect()
}
