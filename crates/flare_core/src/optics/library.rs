//! The built-in lens library: the twenty-one prescriptions of `lenses/`, embedded in the binary so that the app
//! and the command line work from any folder.
//!
//! # How it works
//! Each file is included as text at compile time and parsed on demand with the ordinary JSON reader, so a
//! built-in lens goes through exactly the validation a user's file does (a test parses all of them).
//! Look-up is by id, or by any unambiguous part of it (`heliar`, `dgauss`).

use super::formats::{FormatError, json};
use super::lens::Lens;

/// (id, JSON text) of every built-in lens, the default first.
pub const BUILTIN_LENSES: &[(&str, &str)] = &[
    ("heliar_tronnier_us2645156", include_str!("../../../../lenses/heliar_tronnier_us2645156.json")),
    ("pbrt_dgauss_50mm", include_str!("../../../../lenses/pbrt_dgauss_50mm.json")),
    ("pbrt_wide_22mm", include_str!("../../../../lenses/pbrt_wide_22mm.json")),
    ("pbrt_telephoto_250mm", include_str!("../../../../lenses/pbrt_telephoto_250mm.json")),
    ("pbrt_fisheye_10mm", include_str!("../../../../lenses/pbrt_fisheye_10mm.json")),
    ("brendel_tessar_usp2854889", include_str!("../../../../lenses/brendel_tessar_usp2854889.json")),
    ("nikon_zoom_28_75mm", include_str!("../../../../lenses/nikon_zoom_28_75mm.json")),
    ("zeiss_master_prime_us5537259", include_str!("../../../../lenses/zeiss_master_prime_us5537259.json")),
    ("aspheric_zoom_us5793533", include_str!("../../../../lenses/aspheric_zoom_us5793533.json")),
    ("kreitzer_tele_400mm", include_str!("../../../../lenses/kreitzer_tele_400mm.json")),
    ("canon_zoom_70_200mm_at_70mm", include_str!("../../../../lenses/canon_zoom_70_200mm_at_70mm.json")),
    ("canon_zoom_70_200mm_at_200mm", include_str!("../../../../lenses/canon_zoom_70_200mm_at_200mm.json")),
    ("itoh_zoom_at_100mm", include_str!("../../../../lenses/itoh_zoom_at_100mm.json")),
    ("itoh_zoom_at_123mm", include_str!("../../../../lenses/itoh_zoom_at_123mm.json")),
    ("itoh_zoom_at_146mm", include_str!("../../../../lenses/itoh_zoom_at_146mm.json")),
    ("canon_50mm_f1_8_jp1987_087922", include_str!("../../../../lenses/canon_50mm_f1_8_jp1987_087922.json")),
    ("angenieux_double_gauss_us2701982", include_str!("../../../../lenses/angenieux_double_gauss_us2701982.json")),
    ("kodak_petzval_us2500046", include_str!("../../../../lenses/kodak_petzval_us2500046.json")),
    ("sigma_21mm_f1_4_art", include_str!("../../../../lenses/sigma_21mm_f1_4_art.json")),
    ("aspherical_fish_eye_jp", include_str!("../../../../lenses/aspherical_fish_eye_jp.json")),
    (
        "panavision_anamorphic_us20060050403",
        include_str!("../../../../lenses/panavision_anamorphic_us20060050403.json"),
    ),
];

/// `lens` with its iris removed and the stop moved onto the lens surface in front of it (the habit of many
/// patent tables): that surface's clear aperture becomes the iris's, and the iris's gap joins the one in front.
/// `None` when the stop is not an iris in air behind a lens surface.
pub fn with_stop_on_front_surface(lens: &Lens) -> Option<Lens> {
    let s = lens.stop_index();
    if s == 0 || lens.stop_on_lens_surface() {
        return None;
    }
    let mut out = lens.clone();
    let iris = out.surfaces.remove(s);
    let front = &mut out.surfaces[s - 1];
    front.thickness_mm = Some(front.thickness_mm.unwrap_or(0.0) + iris.thickness_mm.unwrap_or(0.0));
    front.semi_aperture_mm = front.semi_aperture_mm.min(iris.semi_aperture_mm);
    front.stop = true;
    out.id = format!("{}_stop_on_{}", lens.id, s - 1);
    out.validate().ok().map(|()| out)
}

/// The lens the app opens with: the Nikon 28-75 mm zoom, whose chain of polygonal ghosts is what an artist
/// expects a lens flare to look like.
pub const DEFAULT_LENS_ID: &str = "nikon_zoom_28_75mm";

/// Why a built-in lens could not be found.
#[derive(Debug, thiserror::Error)]
pub enum LibraryError {
    #[error("no built-in lens matches `{0}` (built-in: {list})", list = ids().join(", "))]
    NotFound(String),
    #[error("`{name}` matches several built-in lenses: {}", .matches.join(", "))]
    Ambiguous { name: String, matches: Vec<String> },
    #[error("built-in lens {id} is broken: {source}")]
    Broken { id: String, source: FormatError },
}

/// Ids of the built-in lenses.
pub fn ids() -> Vec<&'static str> {
    BUILTIN_LENSES.iter().map(|(id, _)| *id).collect()
}

/// The built-in lens whose id is `name` or contains it (case-insensitive) when only one does.
pub fn builtin_lens(name: &str) -> Result<Lens, LibraryError> {
    let key = name.trim().to_ascii_lowercase();
    let exact = BUILTIN_LENSES.iter().find(|(id, _)| *id == key);
    let (id, text) = match exact {
        Some(hit) => *hit,
        None => {
            let hits: Vec<_> = BUILTIN_LENSES.iter().filter(|(id, _)| !key.is_empty() && id.contains(&key)).collect();
            match hits.as_slice() {
                [one] => **one,
                [] => return Err(LibraryError::NotFound(name.to_owned())),
                many => {
                    return Err(LibraryError::Ambiguous {
                        name: name.to_owned(),
                        matches: many.iter().map(|(id, _)| (*id).to_owned()).collect(),
                    });
                }
            }
        }
    };
    json::parse(text).map(|loaded| loaded.lens).map_err(|source| LibraryError::Broken { id: id.to_owned(), source })
}

/// The default lens.
pub fn default_lens() -> Lens {
    builtin_lens(DEFAULT_LENS_ID).unwrap_or_else(|e| panic!("the default lens ships with the binary: {e}"))
}

/// A synthetic lens of `surface_count` surfaces (at least 3): equiconvex singlets of N-BK7 and F2 sharing
/// a total power of 1 / 50 mm, 10 mm semi-apertures, the stop (semi-aperture 8 mm) in the middle air gap.
/// Not a real design: it exists for benchmarks and stress tests that need many surfaces. One surface is the
/// stop, which reflects nothing: 61 surfaces have 60 reflecting ones and 1770 ghosts, 60 surfaces 1711. An even
/// count leaves an odd number of glass surfaces, so the last singlet is a plano-convex lens.
pub fn synthetic_lens(surface_count: usize) -> Lens {
    use super::lens::{Medium, Surface};
    let count = surface_count.max(3);
    let glass_surfaces = count - 1;
    let elements = glass_surfaces.div_ceil(2);
    let power_per_element = 1.0 / 50.0 / elements as f64;
    // Keep the whole stack about 60 mm long so that the focus stays behind it.
    let (thickness, gap) = ((36.0 / elements as f64).min(4.0), (24.0 / elements as f64).min(3.0));
    let mut surfaces = Vec::with_capacity(count);
    for e in 0..elements {
        let (n_d, v_d, name) = if e % 2 == 0 { (1.5168, 64.17, "N-BK7") } else { (1.62004, 36.37, "F2") };
        let glass = Medium { n_d, v_d: Some(v_d), glass: Some(name.to_owned()) };
        let last_single = surfaces.len() + 2 > glass_surfaces;
        if last_single {
            // One surface left: a plano-convex element's curved face (into air, so the image space is air).
            let r = (n_d - 1.0) / power_per_element;
            surfaces.push(Surface::new(-r, Some(gap), Medium::air(), 10.0));
            if let Some(prev) = surfaces.len().checked_sub(2) {
                surfaces[prev].medium = glass;
                surfaces[prev].radius_mm = 0.0;
            }
            break;
        }
        let r = 2.0 * (n_d - 1.0) / power_per_element;
        surfaces.push(Surface::new(r, Some(thickness), glass, 10.0));
        surfaces.push(Surface::new(-r, Some(gap), Medium::air(), 10.0));
    }
    let mut stop = Surface::new(0.0, Some(gap), Medium::air(), 8.0);
    stop.stop = true;
    let middle = (surfaces.len() / 2) & !1;
    surfaces.insert(middle, stop);
    if let Some(last) = surfaces.last_mut() {
        last.thickness_mm = Some(40.0);
    }
    Lens {
        id: format!("synthetic_{count}"),
        name: format!("Synthetic {count}-surface lens (benchmarks and stress tests only)"),
        surfaces,
        extra: Default::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_lens_parses_and_validates() {
        for id in ids() {
            let lens = builtin_lens(id).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(lens.id, id);
        }
        assert_eq!(default_lens().id, DEFAULT_LENS_ID);
    }

    #[test]
    fn synthetic_lenses_are_valid_and_focus() {
        for n in [3, 4, 11, 26, 29, 60] {
            let lens = synthetic_lens(n);
            assert_eq!(lens.surfaces.len(), n, "{n}");
            lens.validate().unwrap_or_else(|e| panic!("{n}: {e}"));
            let fo = crate::optics::FirstOrder::d_line(&lens).unwrap_or_else(|e| panic!("{n}: {e}"));
            assert!(fo.bfd_mm > 0.0 && fo.efl_mm > 20.0 && fo.efl_mm < 80.0, "{n}: {fo:?}");
            assert_eq!(lens.ghost_pairs().len(), (n - 1) * (n - 2) / 2, "{n}");
        }
    }

    #[test]
    fn lookup_by_part_of_the_id() {
        assert_eq!(builtin_lens("heliar").unwrap().id, "heliar_tronnier_us2645156");
        assert_eq!(builtin_lens("nikon").unwrap().id, DEFAULT_LENS_ID);
        assert_eq!(builtin_lens("TESSAR").unwrap().id, "brendel_tessar_usp2854889");
        assert!(matches!(builtin_lens("pbrt"), Err(LibraryError::Ambiguous { .. })));
        assert!(matches!(builtin_lens("leica"), Err(LibraryError::NotFound(_))));
    }
}
