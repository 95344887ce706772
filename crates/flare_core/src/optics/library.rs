//! The built-in lens library: the six prescriptions of `lenses/`, embedded in the binary so that the app
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
];

/// The lens the app opens with: the Heliar of the paraxial-flare patent's Table 1.
pub const DEFAULT_LENS_ID: &str = "heliar_tronnier_us2645156";

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
    json::parse(text).map_err(|source| LibraryError::Broken { id: id.to_owned(), source })
}

/// The default lens.
pub fn default_lens() -> Lens {
    builtin_lens(DEFAULT_LENS_ID).unwrap_or_else(|e| panic!("the default lens ships with the binary: {e}"))
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
    fn lookup_by_part_of_the_id() {
        assert_eq!(builtin_lens("heliar").unwrap().id, DEFAULT_LENS_ID);
        assert_eq!(builtin_lens("TESSAR").unwrap().id, "brendel_tessar_usp2854889");
        assert!(matches!(builtin_lens("pbrt"), Err(LibraryError::Ambiguous { .. })));
        assert!(matches!(builtin_lens("zeiss"), Err(LibraryError::NotFound(_))));
    }
}
