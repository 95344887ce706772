//! Ghost sprites against the paraxial figures of `tests/data/reference/`: for every ghost of the six lenses at
//! 0, 10 and 20 degrees, the sprite (the stop's opening imaged through the ghost path: centre and radius)
//! agrees with the reference's paraxial fan to 1e-9 mm.
//!
//! The reference gives, per ghost, the paraxial landing heights of a meridional pupil fan. Those heights are
//! linear in the pupil coordinate, y(py) = alpha + beta py, so the sprite the fan implies is: centre =
//! y(py*) where py* is the pupil coordinate of the ray through the stop centre, and radius = |beta| times the
//! stop's entrance radius in pupil units. The stop crossing (M_a) is ours; the landing map is the reference's.

use std::path::PathBuf;

use flare_core::ghost::{GhostSettings, GhostSystem};
use flare_core::optics::library::{builtin_lens, ids};
use flare_core::spectrum::Spectrum;
use serde_json::Value;

fn reference(id: &str) -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference").join(format!("{id}.json"));
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn sprites_agree_with_the_reference_paraxial_fans_to_1e_9() {
    let mut checked = 0;
    let mut worst = 0.0_f64;
    for id in with_figures() {
        let lens = builtin_lens(id).unwrap();
        let settings =
            GhostSettings { spectrum: Spectrum::single(flare_core::optics::D_LINE_NM).unwrap(), ..Default::default() };
        let system = GhostSystem::build(&lens, &settings).unwrap();
        let r = reference(id);
        let fo = &r["first_order"];
        let (z_ep, r_ep) = (fo["enp_dist"].as_f64().unwrap(), 0.5 * fo["enp_diameter"].as_f64().unwrap());
        let fan: Vec<f64> =
            r["ghosts"]["pupil_fan_py"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(fan, [-1.0, -0.5, 0.0, 0.5, 1.0]);
        for entry in r["ghosts"]["table"].as_array().unwrap() {
            let (i, j) = (entry["i"].as_u64().unwrap() as usize, entry["j"].as_u64().unwrap() as usize);
            let g = system.ghosts.iter().position(|m| (m.i, m.j) == (i, j)).unwrap();
            let a = system.ghosts[g].per_wavelength[0].matrices.stop_from_entrance[0];
            for by in entry["by_theta"].as_array().unwrap() {
                let theta = by["theta_deg"].as_f64().unwrap().to_radians();
                let u = theta.tan();
                let y: Vec<f64> =
                    by["paraxial_y_fan"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                let (alpha, beta) = (y[2], (y[4] - y[0]) / 2.0);
                // The fan really is linear (it is paraxial).
                for (k, py) in fan.iter().enumerate() {
                    assert!((alpha + beta * py - y[k]).abs() < 1e-9 * (1.0 + y[k].abs()));
                }
                let x0_centre = -a.b / a.a * u;
                let py_centre = (x0_centre + z_ep * u) / r_ep;
                let expected_centre = alpha + beta * py_centre;
                let expected_radius = beta.abs() * (system.stop_radius_mm / a.a.abs()) / r_ep;
                let (centre, radius) = system.stop_image_sprite(g, 0, [0.0, u]).unwrap();
                let what = format!("{id} ghost ({i}, {j}) at {} deg", by["theta_deg"]);
                assert_eq!(centre[0], 0.0, "{what}: meridional light keeps x = 0");
                let (dc, dr) = ((centre[1] - expected_centre).abs(), (radius - expected_radius).abs());
                assert!(
                    dc < 1e-9 && dr < 1e-9,
                    "{what}: centre {} vs {expected_centre}, radius {radius} vs {expected_radius}",
                    centre[1]
                );
                worst = worst.max(dc).max(dr);
                checked += 1;
            }
        }
    }
    println!("{checked} sprites agree with the reference, worst difference {worst:.1e} mm");
    assert_eq!(checked, 3 * (28 + 45 + 66 + 15 + 55 + 21));
}

/// The built-in lenses that have independent reference figures (all but the benchmark's Nikon zoom).
fn with_figures() -> Vec<&'static str> {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/reference");
    let found: Vec<&'static str> = ids().into_iter().filter(|id| dir.join(format!("{id}.json")).exists()).collect();
    assert_eq!(found.len(), 6, "reference figures for the six lenses of shared/reference: {found:?}");
    found
}
