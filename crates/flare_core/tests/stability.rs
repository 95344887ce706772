//! Numerical stability of everything that turns a lens into pixels: paraxial ghosts, coatings, the CPU twin and
//! the ray-traced renderers, over random lenses (3 to 60 surfaces) and light up to 89 degrees, plus the named
//! singular cases: a flat-only lens, R -> infinity, a ghost focused exactly onto the sensor (zero size), a stop
//! crossing whose M_a11 -> 0, light at exactly 0 and 89 degrees, and a lens of 60 reflecting surfaces (1770 ghosts).
//!
//! What must hold everywhere: no panic; no NaN or infinity in any sprite, GPU instance, image or moment; energy
//! never negative; and continuity: a tiny move of the light moves the ghosts a tiny amount (the flicker test
//! below halves the step and expects the image change to halve).

use flare_core::coating::stack_reflection;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::ghost::{FrameSettings, GhostSettings, GhostSystem};
use flare_core::metrics::relative_l1;
use flare_core::optics::library::{builtin_lens, ids, synthetic_lens};
use flare_core::optics::{Coating, CoatingLayer, Lens};
use flare_core::raytrace::{Grid, RayGridImage};
use flare_core::render::{FlareScene, HdrImage, cpu, light_slopes_for_frame_position, sensor_to_pixel};
use flare_core::spectrum::Spectrum;
use proptest::prelude::*;

mod common;
use common::{focusing_lens_strategy, lens_strategy};

/// Frame position (X, Y field angles, degrees) of a light `theta_deg` off the axis at `azimuth_deg`.
fn light(theta_deg: f64, azimuth_deg: f64) -> [f64; 2] {
    let t = theta_deg.to_radians().tan();
    let a = azimuth_deg.to_radians();
    [(t * a.cos()).atan().to_degrees(), (t * a.sin()).atan().to_degrees()]
}

fn assert_image_ok(image: &HdrImage, what: &str) {
    assert!(
        image.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0),
        "{what}: a pixel is NaN, infinite or negative"
    );
}

fn assert_ray_grid_ok(image: &RayGridImage, what: &str) {
    assert_image_ok(&image.hdr, what);
    assert!(
        image
            .moments
            .iter()
            .all(|m| m.energy.is_finite() && m.energy >= 0.0 && m.sum_x.is_finite() && m.sum_y.is_finite()),
        "{what}: a ghost's moments are not finite"
    );
}

/// Paraxial sprites, GPU instances and the CPU twin's image at one light position: all finite, energy >= 0.
fn check_paraxial(flare: &PreparedFlare, light_deg: [f64; 2], what: &str) -> FlareScene {
    let (scene, frame) = flare.scene(light_deg, 64, 48);
    for s in &frame.sprites {
        assert!(
            s.centre_mm.iter().all(|c| c.is_finite()) && s.half_size_mm.iter().all(|h| h.is_finite() && *h != 0.0),
            "{what}: {s:?}"
        );
        assert!(s.irradiance.is_finite() && s.irradiance >= 0.0, "{what}: {s:?}");
        assert!(s.rgb.iter().all(|c| c.is_finite() && *c >= 0.0), "{what}: {s:?}");
    }
    assert_eq!(scene.dropped_non_finite, 0, "{what}: a sprite was not finite");
    assert!(scene.instances.iter().all(|i| i.is_finite()), "{what}");
    // What reaches the GPU is f32: each instance's centre and half-size equal the f64 sprite's to f32 rounding.
    let settings = flare.frame_settings(64, 48, 1.0);
    let k = 64.0 / settings.sensor.width_mm;
    let drawn = frame.sprites.iter().filter(|s| s.culled.is_none());
    for (sprite, instance) in drawn.zip(&scene.instances) {
        let c = sensor_to_pixel(sprite.centre_mm, &settings.sensor, 64, 48);
        let [cx, cy, _, half] = instance.centre_half.map(f64::from);
        let close = |a: f64, b: f64| (a - b).abs() <= F32_RELATIVE_BOUND * (1.0 + b.abs());
        // A sprite of two pixels or less is drawn as a point exactly two pixels a side, its sign kept.
        let point = f64::from(flare_core::render::cpu::ghosts::POINT_SPRITE_PX) / 2.0;
        let [hx, hy] = sprite.half_size_mm.map(|h| h * k);
        let expected_half = if hx.abs() <= point && hy.abs() <= point { point.copysign(hy) } else { hy };
        assert!(close(cx, c[0]) && close(cy, c[1]) && close(half, expected_half), "{what}: {sprite:?} {instance:?}");
    }
    assert!(bytemuck::cast_slice::<_, f32>(&[scene.globals]).iter().all(|v| v.is_finite()), "{what}");
    assert_image_ok(&cpu::ghost_pass(&scene, &flare.ghost_masks), what);
    scene
}

/// f32 against f64 for what reaches the GPU: relative to (1 + |value|), a few f32 roundings.
const F32_RELATIVE_BOUND: f64 = 2.5e-7;

/// The share of the paraxial property's random lenses that must render: 3 in 4 are drawn from lenses that
/// form an image (all of those render), 1 in 4 from any lens (most long ones are refused).
const MIN_RENDERED: f64 = 0.6;

fn quarter_wave() -> Coating {
    Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None }
}

proptest! {
    // PROPTEST_CASES=N runs more cases (the closing note reports a run of 1000).
    #![proptest_config(ProptestConfig {
        cases: cases(),
        ..ProptestConfig::default()
    })]

    /// Any stack of non-absorbing layers, any angle and wavelength: R and T in [0, 1], R + T = 1, and R = 1
    /// past the critical angle.
    #[test]
    fn coatings_conserve_energy(
        layers in prop::collection::vec((1.2..2.6f64, 0.0..600.0f64), 0..7),
        n0 in 1.0..2.0f64,
        ns in 1.0..2.0f64,
        wavelength_nm in 380.0..780.0f64,
        sin_incidence in 0.0..=1.0f64,
    ) {
        let layers: Vec<CoatingLayer> = layers.into_iter().map(|(index, thickness_nm)| CoatingLayer { index, thickness_nm }).collect();
        let r = stack_reflection(&layers, n0, ns, wavelength_nm, sin_incidence);
        prop_assert!(r.reflectance.is_finite() && r.transmittance.is_finite());
        prop_assert!((-1e-12..=1.0 + 1e-12).contains(&r.reflectance), "{r:?}");
        prop_assert!((-1e-12..=1.0 + 1e-12).contains(&r.transmittance), "{r:?}");
        if n0 * sin_incidence < ns * (1.0 - 1e-9) {
            prop_assert!((r.reflectance + r.transmittance - 1.0).abs() < 1e-9, "{r:?}");
        } else if n0 * sin_incidence > ns * (1.0 + 1e-9) {
            prop_assert!((r.reflectance - 1.0).abs() < 1e-9, "total internal reflection: {r:?}");
        }
    }
}

/// Cases a counted property runs (`PROPTEST_CASES=N` for more; the closing note reports a run of 1000).
fn cases() -> u32 {
    common::cases_or(32)
}

/// Runs `property` on `cases()` values of `strategy`; the property says whether the case was really exercised
/// (a random lens that is refused as impossible, with a reason, is a case, but not one that rendered). At
/// least `min_share` of the cases must have been exercised, so that a generator drifting into lenses that are
/// all refused cannot make the property pass by testing nothing.
fn counted<S: Strategy>(
    name: &str,
    strategy: S,
    min_share: f64,
    property: impl Fn(S::Value) -> Result<bool, TestCaseError>,
) {
    use std::sync::atomic::{AtomicU32, Ordering};
    let (tried, exercised) = (AtomicU32::new(0), AtomicU32::new(0));
    // Strategies that keep to focusing lenses reject most long random stacks before a case is made.
    let config = ProptestConfig { cases: cases(), max_global_rejects: 200 * cases(), ..ProptestConfig::default() };
    let mut runner = proptest::test_runner::TestRunner::new(config);
    let result = runner.run(&strategy, |value| {
        tried.fetch_add(1, Ordering::Relaxed);
        if property(value)? {
            exercised.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    let (tried, exercised) = (tried.into_inner(), exercised.into_inner());
    println!("{name}: {exercised} of {tried} random cases exercised");
    assert!(
        f64::from(exercised) >= min_share * f64::from(tried),
        "{name}: only {exercised} of {tried} random cases were exercised (at least {min_share} wanted)"
    );
}

/// Random lenses up to 60 surfaces, any light up to 89 degrees: sprites, instances and the CPU twin's image
/// are finite and never negative; an afocal lens is refused with a reason, not a NaN.
#[test]
fn paraxial_flares_of_random_lenses_stay_finite() {
    // Mostly lenses that form an image (they render); some of any kind (they may be refused, with a reason).
    let lenses = prop_oneof![3 => focusing_lens_strategy(2, 59), 1 => lens_strategy(2, 59)];
    let strategy = (lenses, 0.0..89.0f64, 0.0..360.0f64, any::<bool>());
    counted("paraxial flares", strategy, MIN_RENDERED, |(lens, theta, azimuth, coated)| {
        let config = FlareConfig { coating_override: coated.then(quarter_wave), ..FlareConfig::default() };
        match PreparedFlare::new(&lens, &config) {
            Ok(flare) => {
                check_paraxial(&flare, light(theta, azimuth), "random lens");
                Ok(true)
            }
            Err(e) => {
                prop_assert!(!e.to_string().is_empty());
                Ok(false)
            }
        }
    });
}

/// The ray-traced renderer on random lenses (single wavelength, coarse grid to keep it quick).
#[test]
fn ray_grids_of_random_lenses_stay_finite() {
    let strategy = (focusing_lens_strategy(2, 11), 0.0..89.0f64, 0.0..360.0f64);
    counted("ray grids", strategy, 0.9, |(lens, theta, azimuth)| {
        let config = FlareConfig { spectrum: Spectrum::single(550.0).unwrap(), ..FlareConfig::default() };
        let Ok(flare) = PreparedFlare::new(&lens, &config) else { return Ok(false) };
        let image = flare.ray_grid_renderer().render(light(theta, azimuth), 32, 24, Grid::Fixed(6)).unwrap();
        assert_ray_grid_ok(&image, "random lens");
        Ok(true)
    });
}

/// A tiny move of the light changes every sprite a tiny amount: positions linearly, brightness by a relative
/// amount of the order of the move (no jumps).
#[test]
fn sprites_move_continuously_with_the_light() {
    let strategy = (focusing_lens_strategy(2, 30), 0.0..80.0f64, 0.0..360.0f64);
    counted("continuous sprites", strategy, 0.9, |(lens, theta, azimuth)| {
        let Ok(system) = GhostSystem::build(&lens, &GhostSettings::default()) else { return Ok(false) };
        let settings = FrameSettings { intensity_threshold: 0.0, ..FrameSettings::default() };
        let at = |t: f64| {
            let [x, y] = light(t, azimuth);
            system.frame(light_slopes_for_frame_position(x, y), &settings)
        };
        let delta_deg = 1e-6;
        let (a, b, c) = (at(theta), at(theta + delta_deg), at(theta + 2.0 * delta_deg));
        for ((p, q), r) in a.sprites.iter().zip(&b.sprites).zip(&c.sprites) {
            // Centres are linear in the slope: equal steps move them by equal amounts (to rounding).
            for k in 0..2 {
                let (d1, d2) = (q.centre_mm[k] - p.centre_mm[k], r.centre_mm[k] - q.centre_mm[k]);
                prop_assert!((d1 - d2).abs() <= 1e-6 * (1.0 + p.centre_mm[k].abs()), "{p:?} {q:?} {r:?}");
            }
            // Brightness: a relative change of the order of the step (1e-6 degrees), or an entrance region
            // that just emptied (exactly at its edge).
            if p.irradiance > 0.0 && q.irradiance > 0.0 {
                prop_assert!(((q.irradiance - p.irradiance) / p.irradiance).abs() < 1e-3, "{p:?} {q:?}");
            }
        }
        Ok(true)
    });
}

/// Flicker while dragging: the light moves in steps along a drag; the image change over half a step must be
/// about half the change over the whole step (continuous motion), never a pop.
#[test]
fn dragging_the_light_does_not_flicker() {
    for id in ["brendel_tessar_usp2854889", "pbrt_dgauss_50mm"] {
        let config = FlareConfig { intensity_threshold: Some(0.0), ..FlareConfig::default() };
        let flare = PreparedFlare::new(&builtin_lens(id).unwrap(), &config).unwrap();
        let image = |theta: f64| {
            let (scene, _) = flare.scene(light(theta, 30.0), 120, 80);
            cpu::ghost_pass(&scene, &flare.ghost_masks)
        };
        let step_deg = 0.1;
        let mut worst_ratio = 0.0f64;
        for k in 0..6 {
            let theta = 1.0 + 3.0 * k as f64;
            let here = image(theta);
            let full = relative_l1(&image(theta + step_deg), &here);
            let half = relative_l1(&image(theta + step_deg / 2.0), &here);
            assert!(full < 0.1, "{id} at {theta} deg: a {step_deg} deg step changes the image by {full}");
            if full > 1e-4 {
                worst_ratio = worst_ratio.max(half / full);
            }
        }
        eprintln!("{id}: worst (change over half a step) / (change over a step) = {worst_ratio:.3}");
        assert!(worst_ratio < 0.75, "{id}: the image jumps ({worst_ratio})");
    }
}

/// A lens with only flat surfaces is afocal: a flare needs a focus, so it is refused with that reason.
#[test]
fn a_flat_only_lens_is_refused_with_a_reason() {
    let mut lens = builtin_lens("brendel_tessar_usp2854889").unwrap();
    for s in &mut lens.surfaces {
        s.radius_mm = 0.0;
    }
    let error = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap_err().to_string();
    assert!(error.contains("afocal") || error.contains("focus"), "{error}");
}

/// R -> infinity: the flare of a surface with R = 1e15 mm is the flare of the flat surface.
#[test]
fn huge_radius_flares_equal_the_flat_ones() {
    let base = builtin_lens("pbrt_dgauss_50mm").unwrap();
    let k = base.surfaces.iter().position(|s| !s.stop && s.radius_mm.abs() > 50.0).unwrap();
    let (mut flat, mut huge) = (base.clone(), base);
    flat.surfaces[k].radius_mm = 0.0;
    huge.surfaces[k].radius_mm = 1e15;
    let config = FlareConfig::default();
    let (a, b) = (PreparedFlare::new(&flat, &config).unwrap(), PreparedFlare::new(&huge, &config).unwrap());
    let u = light_slopes_for_frame_position(4.0, 7.0);
    let settings = FrameSettings::default();
    let (fa, fb) = (a.system.frame(u, &settings), b.system.frame(u, &settings));
    for (p, q) in fa.sprites.iter().zip(&fb.sprites) {
        assert!((p.centre_mm[1] - q.centre_mm[1]).abs() < 1e-9 * (1.0 + p.centre_mm[1].abs()), "{p:?} {q:?}");
        assert!((p.half_size_mm[0] - q.half_size_mm[0]).abs() < 1e-9 * p.half_size_mm[0].abs(), "{p:?} {q:?}");
        assert!((p.irradiance - q.irradiance).abs() <= 1e-9 * p.irradiance, "{p:?} {q:?}");
    }
    let (ia, ib) = (
        a.ray_grid_renderer().render([4.0, 7.0], 48, 32, Grid::Fixed(16)).unwrap(),
        b.ray_grid_renderer().render([4.0, 7.0], 48, 32, Grid::Fixed(16)).unwrap(),
    );
    assert!(relative_l1(&ib.hdr, &ia.hdr) < 1e-6);
}

/// Scales surface `k`'s radius by `s` (the sensor follows the paraxial focus).
fn with_radius_scaled(lens: &Lens, k: usize, s: f64) -> Lens {
    let mut out = lens.clone();
    out.surfaces[k].radius_mm *= s;
    out
}

/// Finds a surface, a ghost and a radius scale in [0.85, 1.15] where `quantity` of that ghost crosses zero,
/// and bisects to it: the lens where the quantity is 0 (to rounding), and the ghost's index.
fn bisect_to_zero(lens: &Lens, quantity: impl Fn(&GhostSystem, usize) -> Option<f64>) -> Option<(Lens, usize, f64)> {
    let settings = GhostSettings { spectrum: Spectrum::single(587.5618).unwrap(), ..GhostSettings::default() };
    let build = |l: &Lens| GhostSystem::build(l, &settings).ok();
    for k in (0..lens.surfaces.len()).filter(|&k| !lens.surfaces[k].stop && lens.surfaces[k].radius_mm != 0.0) {
        let (lo_lens, hi_lens) = (with_radius_scaled(lens, k, 0.85), with_radius_scaled(lens, k, 1.15));
        let (Some(lo), Some(hi)) = (build(&lo_lens), build(&hi_lens)) else { continue };
        for g in 0..lo.ghosts.len() {
            let (Some(a), Some(b)) = (quantity(&lo, g), quantity(&hi, g)) else { continue };
            if a.signum() == b.signum() {
                continue;
            }
            let (mut s_lo, mut s_hi, mut q_lo) = (0.85, 1.15, a);
            for _ in 0..200 {
                let mid = 0.5 * (s_lo + s_hi);
                let Some(q) = build(&with_radius_scaled(lens, k, mid)).and_then(|sys| quantity(&sys, g)) else { break };
                if q.signum() == q_lo.signum() {
                    (s_lo, q_lo) = (mid, q);
                } else {
                    s_hi = mid;
                }
                if s_hi - s_lo <= f64::EPSILON * 2.0 {
                    break;
                }
            }
            let lens = with_radius_scaled(lens, k, s_lo);
            let q = build(&lens).and_then(|sys| quantity(&sys, g))?;
            return Some((lens, g, q));
        }
    }
    None
}

fn render_everything(lens: &Lens, what: &str) {
    let config = FlareConfig {
        spectrum: Spectrum::single(587.5618).unwrap(),
        intensity_threshold: Some(0.0),
        ..FlareConfig::default()
    };
    let flare = PreparedFlare::new(lens, &config).unwrap();
    for theta in [0.0, 1.0, 10.0] {
        check_paraxial(&flare, light(theta, 30.0), what);
        let image = flare.ray_grid_renderer().render(light(theta, 30.0), 48, 32, Grid::Fixed(32)).unwrap();
        assert_ray_grid_ok(&image, what);
    }
}

/// A ghost focused exactly onto the sensor: A_f = 0, a sprite of zero size. It is drawn at the minimum size
/// with its energy, and the ray-traced renderers splat its collapsed triangles at a point.
#[test]
fn a_ghost_focused_exactly_onto_the_sensor() {
    let lens = builtin_lens("brendel_tessar_usp2854889").unwrap();
    let (lens, g, a_f) =
        bisect_to_zero(&lens, |s, g| Some(s.ghosts[g].per_wavelength[0].matrices.sensor_from_entrance.a))
            .expect("some ghost of the tessar focuses on the sensor for a radius within 15%");
    assert!(a_f.abs() < 1e-12, "A_f = {a_f}");
    let settings = FrameSettings::default();
    let system = GhostSystem::build(
        &lens,
        &GhostSettings { spectrum: Spectrum::single(587.5618).unwrap(), ..GhostSettings::default() },
    )
    .unwrap();
    let sprite = &system.frame([0.0, 0.0], &settings).sprites[g];
    assert_eq!(sprite.half_size_mm[0].abs(), settings.min_half_size_mm, "{sprite:?}");
    assert!(sprite.irradiance.is_finite() && sprite.irradiance > 0.0, "{sprite:?}");
    render_everything(&lens, "focused ghost");
}

/// A stop crossing with M_a11 -> 0 (the stop's image through the path at infinity): the front disc bounds the
/// entrance region and nothing divides by zero.
#[test]
fn a_stop_crossing_with_m_a11_zero() {
    let lens = builtin_lens("pbrt_dgauss_50mm").unwrap();
    let (lens, _, a) = bisect_to_zero(&lens, |s, g| {
        let crossings = &s.ghosts[g].per_wavelength[0].matrices.stop_from_entrance;
        (crossings.len() > 1).then(|| crossings[1].a)
    })
    .expect("some straddling ghost of the double Gauss has M_a11 = 0 for a radius within 15%");
    assert!(a.abs() < 1e-12, "M_a11 = {a}");
    render_everything(&lens, "M_a11 = 0");
}

/// Light exactly on the axis and at 89 degrees, every built-in lens, both families.
#[test]
fn light_at_exactly_0_and_89_degrees() {
    for id in ids() {
        let config = FlareConfig { spectrum: Spectrum::single(550.0).unwrap(), ..FlareConfig::default() };
        let flare = PreparedFlare::new(&builtin_lens(id).unwrap(), &config).unwrap();
        let renderer = flare.ray_grid_renderer();
        for theta in [0.0, 89.0] {
            for azimuth in [0.0, 90.0, 217.0] {
                let what = format!("{id} at {theta} deg, azimuth {azimuth}");
                check_paraxial(&flare, light(theta, azimuth), &what);
                assert_ray_grid_ok(&renderer.render(light(theta, azimuth), 32, 24, Grid::Fixed(8)).unwrap(), &what);
            }
        }
    }
}

/// A lens of 60 reflecting surfaces (and the stop): 1770 ghosts, every one enumerated, drawn or culled with a
/// reason, all finite.
#[test]
fn a_sixty_surface_lens() {
    let lens = synthetic_lens(61);
    let config = FlareConfig { spectrum: Spectrum::single(550.0).unwrap(), ..FlareConfig::default() };
    let flare = PreparedFlare::new(&lens, &config).unwrap();
    assert_eq!(flare.system.ghosts.len(), 1770);
    let (_, frame) = flare.scene(light(12.0, 30.0), 64, 48);
    let st = frame.stats;
    assert_eq!(st.sprites, 1770);
    assert_eq!(st.drawn + st.below_threshold + st.off_sensor + st.empty_entrance_region, st.sprites);
    for theta in [0.0, 12.0, 60.0] {
        check_paraxial(&flare, light(theta, 30.0), "60 surfaces");
    }
    let image = flare.ray_grid_renderer().render(light(12.0, 30.0), 32, 24, Grid::Fixed(4)).unwrap();
    assert_ray_grid_ok(&image, "60 surfaces");
    assert_eq!(image.stats.jobs, 1770);
}
