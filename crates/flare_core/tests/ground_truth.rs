//! The ray-traced reference: it converges as its grid doubles, it agrees with the paraxial method where that
//! method is exact (a small aperture, light near the axis), and it conserves the light that enters.

use flare_core::aperture::Aperture;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::metrics::{self, GhostMoments};
use flare_core::optics::library::{builtin_lens, with_stop_on_front_surface};
use flare_core::raytrace::Grid;
use flare_core::render::cpu;

fn prepared(lens: &flare_core::optics::Lens, f_number: Option<f64>) -> PreparedFlare {
    let config = FlareConfig {
        aperture: Aperture { f_number, ..Aperture::default() },
        intensity_threshold: Some(0.0),
        ..FlareConfig::default()
    };
    PreparedFlare::new(lens, &config).unwrap()
}

/// Doubling the grid changes the image less and less (the table in the README is `flarelab bench`'s).
#[test]
fn the_reference_converges_as_its_grid_doubles() {
    let flare = prepared(&builtin_lens("brendel_tessar_usp2854889").unwrap(), None);
    let renderer = flare.ray_grid_renderer();
    let (w, h) = (120, 80);
    for light in [[0.0, 0.0], [6.0, 4.0]] {
        let images: Vec<_> =
            [32, 64, 128].iter().map(|&n| renderer.render(light, w, h, Grid::Adaptive(n)).unwrap()).collect();
        let change = |coarse: usize, fine: usize| {
            let (a, b) = (&images[coarse], &images[fine]);
            metrics::compare(&a.hdr, &a.moments, &b.hdr, &b.moments)
        };
        let (first, second) = (change(0, 1), change(1, 2));
        eprintln!(
            "light {light:?}: 32 -> 64: L1 {:.4}, PSNR {:.1} dB; 64 -> 128: L1 {:.4}, PSNR {:.1} dB",
            first.relative_l1, first.psnr_db, second.relative_l1, second.psnr_db
        );
        assert!(second.relative_l1 < first.relative_l1, "{first:?} then {second:?}");
        assert!(second.psnr_db > first.psnr_db, "{first:?} then {second:?}");
        assert!(second.relative_l1 < 0.05, "{second:?}");
    }
}

/// In-frame energy of each ghost, by method.
fn energies(m: &[GhostMoments]) -> Vec<f64> {
    m.iter().map(|g| g.energy).collect()
}

/// Stopped down to f/22 with the light near the axis, the paraxial approximation is nearly exact: the two
/// families agree on where each ghost is and how much light it carries, and far better than wide open.
#[test]
fn paraxial_and_reference_agree_where_the_paraxial_method_is_exact() {
    let psnr = paraxial_against_reference(&builtin_lens("brendel_tessar_usp2854889").unwrap(), &[]);
    assert!(psnr[0] > 35.0 && psnr[0] > psnr[1] + 10.0, "PSNR at f/22 then wide open: {psnr:?}");
}

/// The Tessar with its stop on the lens surface in front of the iris (as patent tables often have it): the
/// ghosts that reflect at the stop surface cross it twice, and the paraxial entrance regions still match the
/// ray-traced reference, which applies the aperture at every crossing.
#[test]
fn a_stop_on_a_lens_surface_agrees_with_the_reference_too() {
    let lens = with_stop_on_front_surface(&builtin_lens("brendel_tessar_usp2854889").unwrap()).unwrap();
    let stop = lens.stop_index();
    assert!(lens.stop_on_lens_surface() && lens.reflecting_surfaces().contains(&stop));
    let at_stop: Vec<usize> =
        lens.ghost_pairs().iter().enumerate().filter(|(_, (i, j))| *i == stop || *j == stop).map(|(g, _)| g).collect();
    assert!(at_stop.len() >= 5, "{at_stop:?}");
    let psnr = paraxial_against_reference(&lens, &at_stop);
    assert!(psnr[0] > 35.0, "PSNR at f/22: {psnr:?}");
}

/// Renders `lens` at f/22 and wide open by both methods; at f/22 the centroids agree within half a pixel and
/// each visible ghost's energy within 5 %, and at least one of `must_be_visible` is visible. PSNRs returned.
fn paraxial_against_reference(lens: &flare_core::optics::Lens, must_be_visible: &[usize]) -> Vec<f64> {
    let (w, h) = (240, 160);
    let light = [1.5, 1.0];
    let mut psnr = Vec::new();
    for f_number in [Some(22.0), None] {
        let flare = prepared(lens, f_number);
        let reference = flare.ray_grid_renderer().render(light, w, h, Grid::Adaptive(256)).unwrap();
        let (scene, _) = flare.scene(light, w, h);
        let paraxial = cpu::ghost_pass(&scene, &flare.ghost_masks);
        let moments = cpu::ghost_moments(&scene, &flare.ghost_masks, flare.system.ghosts.len());
        let c = metrics::compare(&paraxial, &moments, &reference.hdr, &reference.moments);
        eprintln!("{} f/{f_number:?}: {c:?}", lens.id);
        if f_number.is_some() {
            assert!(c.centroid_px < 0.5, "{c:?}");
            // Each visible ghost's energy in the frame, within 5% (transmission is paraxial at normal
            // incidence in one, per ray in the other).
            let (a, b) = (energies(&moments), energies(&reference.moments));
            let brightest = b.iter().cloned().fold(0.0, f64::max);
            let mut seen = must_be_visible.is_empty();
            for (g, (p, r)) in a.iter().zip(&b).enumerate() {
                if *r > 0.05 * brightest {
                    assert!((p / r - 1.0).abs() < 0.05, "ghost {g}: paraxial {p} against reference {r}");
                    seen |= must_be_visible.contains(&g);
                }
            }
            assert!(seen, "none of ghosts {must_be_visible:?} is visible");
        }
        psnr.push(c.psnr_db);
    }
    psnr
}
