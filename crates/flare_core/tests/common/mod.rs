//! Shared by the stress suites: a generator of random lenses that are valid by construction.

#![allow(dead_code)]

use flare_core::optics::{Lens, Medium, Surface};
use proptest::prelude::*;

/// The number of cases a property test runs: `PROPTEST_CASES` when set (a sweep for rare failures, e.g.
/// `PROPTEST_CASES=5000`), else the suite's own `default`. Every property test of the suites reads it.
pub fn cases_or(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

pub fn surface(radius_mm: f64, thickness_mm: f64, medium: Medium, semi_aperture_mm: f64) -> Surface {
    Surface::new(radius_mm, Some(thickness_mm), medium, semi_aperture_mm)
}

pub fn glass(n_d: f64, v_d: f64) -> Medium {
    Medium { n_d, v_d: Some(v_d), glass: None }
}

/// One random interface before assembly: curvature sign and size, aperture, the medium after it, the gap.
#[derive(Clone, Debug)]
pub struct Draft {
    flat: bool,
    radius_over_aperture: f64,
    negative: bool,
    semi_aperture_mm: f64,
    to_glass: bool,
    n_d: f64,
    v_d: f64,
    gap_mm: f64,
    /// Conic constant and the sag departures (mm, at the rim) of the r^2, r^4 and r^6 terms; used on
    /// every third surface, so the stress suites cover conics and even aspheres.
    aspheric: Option<(f64, [f64; 3])>,
}

pub fn draft() -> impl Strategy<Value = Draft> {
    let shape = (any::<u8>(), -3.0..0.2f64, -0.05..0.05f64, -0.2..0.2f64, -0.05..0.05f64);
    (
        (
            any::<u8>(),
            1.1..40.0f64,
            any::<bool>(),
            3.0..15.0f64,
            any::<u8>(),
            1.45..1.95f64,
            20.0..80.0f64,
            0.1..12.0f64,
        ),
        shape,
    )
        .prop_map(|((f, r, negative, h, g, n_d, v_d, gap_mm), (a, k, d2, d4, d6))| Draft {
            flat: f % 7 == 0,
            radius_over_aperture: r,
            negative,
            semi_aperture_mm: h,
            to_glass: g % 3 != 0,
            n_d,
            v_d,
            gap_mm,
            aspheric: (a % 3 == 0).then_some((k, [d2, d4, d6])),
        })
}

/// Assembles drafts into a lens that passes validation by construction: media alternate sensibly, the
/// last medium is air, the stop is a flat air surface inserted in an air gap (or, one time in four, a lens
/// surface with air in front, its clear aperture narrowed), and every gap is widened so
/// that neighbouring surfaces never cross inside their clear apertures.
pub fn assemble(drafts: &[Draft], stop_choice: usize) -> Lens {
    let mut surfaces = Vec::with_capacity(drafts.len() + 1);
    let mut in_glass = false;
    for (k, d) in drafts.iter().enumerate() {
        let last = k + 1 == drafts.len();
        // Glass follows air unless the draft says air (the first surface always enters glass).
        let medium = if last || (!d.to_glass && (in_glass || k > 0)) { Medium::air() } else { glass(d.n_d, d.v_d) };
        in_glass = !medium.is_air();
        let r = if d.flat {
            0.0
        } else {
            d.radius_over_aperture * d.semi_aperture_mm * if d.negative { -1.0 } else { 1.0 }
        };
        let mut s = surface(r, d.gap_mm, medium, d.semi_aperture_mm);
        if let Some((k, [d2, d4, d6])) = d.aspheric {
            // |c| h <= 1 / 1.1 and 1 + k <= 1.2 keep the sag defined across the aperture.
            let h = d.semi_aperture_mm;
            s.conic = k;
            s.aspheric_r2 = d2 / (h * h);
            s.aspheric = vec![d4 / h.powi(4), d6 / h.powi(6)];
        }
        surfaces.push(s);
    }
    // The stop goes in front of a surface that has air before it.
    let candidates: Vec<usize> = (0..surfaces.len()).filter(|&k| k == 0 || surfaces[k - 1].medium.is_air()).collect();
    let at = candidates[stop_choice % candidates.len()];
    let h = surfaces[at].semi_aperture_mm * 0.7;
    if stop_choice % 4 == 3 {
        // A patent's habit: the stop on a lens surface, whose clear aperture it is.
        surfaces[at].stop = true;
        surfaces[at].semi_aperture_mm = h;
    } else {
        let mut stop = surface(0.0, 1.0, Medium::air(), h);
        stop.stop = true;
        surfaces.insert(at, stop);
    }
    for k in 0..surfaces.len() - 1 {
        let h = surfaces[k].semi_aperture_mm.min(surfaces[k + 1].semi_aperture_mm);
        // Aspheric terms can make the surfaces come closest inside the rim: look across the aperture.
        let overlap = (0..=64)
            .map(|i| {
                let y = h * f64::from(i) / 64.0;
                surfaces[k].sag_mm(y).unwrap() - surfaces[k + 1].sag_mm(y).unwrap()
            })
            .fold(0.0, f64::max);
        let t = surfaces[k].thickness_mm.unwrap() + overlap + 1e-6;
        surfaces[k].thickness_mm = Some(t);
    }
    let lens = Lens { id: "random".into(), name: "random".into(), surfaces, extra: Default::default() };
    lens.validate().unwrap_or_else(|e| panic!("generator made an invalid lens: {e}\n{lens:?}"));
    lens
}

pub fn lens_strategy(min: usize, max: usize) -> impl Strategy<Value = Lens> {
    (prop::collection::vec(draft(), min..=max), any::<usize>()).prop_map(|(d, s)| assemble(&d, s))
}

/// [`lens_strategy`] kept to the lenses that form a real image (most long random stacks do not: their paraxial
/// focus lies in front of the last surface, and they are refused with that reason), so that a property that
/// needs a flare gets one.
pub fn focusing_lens_strategy(min: usize, max: usize) -> impl Strategy<Value = Lens> {
    lens_strategy(min, max)
        .prop_filter("the lens forms a real image", |lens| flare_core::optics::FirstOrder::d_line(lens).is_ok())
}

/// The anamorphic test lens of `tests/data/reference/toroidal/` (toroids, cylinders along x and y, a spherical
/// group), with its independent figures beside it.
pub fn toroidal_test_lens() -> Lens {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/reference/toroidal/toroidal_test_lens.json");
    flare_core::optics::formats::load_lens_file(&path).unwrap()
}
