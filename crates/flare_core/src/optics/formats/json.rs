//! The native JSON lens form (`lenses/README.md`): read with the path of any bad value, written back
//! losslessly (numbers are written in their shortest exact form).
//!
//! A surface key the reader does not know is refused with its name and, when it is a near miss of a known
//! one (`conci`), the key meant: a misspelled optional key would otherwise be dropped silently and change the
//! optics. Top-level keys beyond the lens's own and its documented metadata are kept (written back) with a
//! warning naming them.

use super::text::{FormatError, LoadedLens, finish_loaded};
use crate::optics::lens::Lens;

/// Parses and validates a JSON lens (tolerantly: see [`crate::optics::tolerance`]).
pub fn parse(text: &str) -> Result<LoadedLens, FormatError> {
    let mut de = serde_json::Deserializer::from_str(text);
    let lens: Lens = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        json_error(&inner, path)
    })?;
    de.end().map_err(|e| json_error(&e, String::new()))?;
    for (k, surface) in lens.surfaces.iter().enumerate() {
        if let Some(key) = surface.extra.keys().next() {
            let hint = near_miss(key, SURFACE_KEYS).map_or(String::new(), |m| format!(" (did you mean `{m}`?)"));
            let (line, column) = position_of(text, key);
            return Err(FormatError::Json {
                line,
                column,
                path: format!("surfaces[{k}].{}", crate::files::shorten(key)),
                message: format!(
                    "unknown surface key `{}`{hint}; a surface has {}",
                    crate::files::shorten(key),
                    SURFACE_KEYS.join(", ")
                ),
            });
        }
    }
    let unknown: Vec<String> =
        lens.extra.keys().filter(|k| !LENS_METADATA.contains(&k.as_str())).map(|k| crate::files::shorten(k)).collect();
    let mut warnings = Vec::new();
    if !unknown.is_empty() {
        warnings.push(format!("unknown top-level keys kept as metadata (they change nothing): {}", unknown.join(", ")));
    }
    finish_loaded(lens, warnings, &[])
}

/// Every key a surface may have.
pub(crate) const SURFACE_KEYS: &[&str] = &[
    "radius",
    "thickness",
    "nd",
    "vd",
    "glass",
    "conic",
    "aspheric_r2",
    "aspheric",
    "semi_aperture",
    "stop",
    "coating",
];

/// The top-level keys besides `id`, `name` and `surfaces` the lens files document (`lenses/README.md`).
pub(crate) const LENS_METADATA: &[&str] =
    &["image_distance_source", "source", "published", "format", "units", "wavelength_nm", "object_index", "notes"];

/// The known key `key` is a near miss of (at most two edits away), if any.
pub(crate) fn near_miss<'a>(key: &str, known: &[&'a str]) -> Option<&'a str> {
    known.iter().copied().filter(|k| edits(key, k) <= 2).min_by_key(|k| edits(key, k))
}

/// The edit distance between `a` and `b` (insertions, deletions, substitutions, adjacent swaps).
fn edits(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().take(64).collect(), b.chars().collect());
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in d[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            d[i][j] = (d[i - 1][j] + 1).min(d[i][j - 1] + 1).min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                d[i][j] = d[i][j].min(d[i - 2][j - 2] + 1);
            }
        }
    }
    d[a.len()][b.len()]
}

/// The line and column (1-based) of the first `"key"` in `text` (0, 0 when not found).
fn position_of(text: &str, key: &str) -> (usize, usize) {
    let Some(at) = text.find(&format!("\"{key}\"")) else { return (0, 0) };
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    (line, at - before.rfind('\n').map_or(0, |n| n + 1) + 1)
}

fn json_error(e: &serde_json::Error, path: String) -> FormatError {
    let full = e.to_string();
    // serde_json appends " at line L column C"; the error names the position itself.
    let message = match full.rfind(" at line ") {
        Some(i) => full[..i].to_owned(),
        None => full,
    };
    FormatError::Json { line: e.line(), column: e.column(), path, message: crate::files::one_line(&message) }
}

/// The lens as pretty JSON that [`parse`] reads back to an identical lens.
pub fn write(lens: &Lens) -> String {
    let mut text = serde_json::to_string_pretty(lens).unwrap_or_else(|e| {
        // Serialising plain data to a string cannot fail; keep the promise of never panicking anyway.
        format!("{{\"error\": \"{e}\"}}")
    });
    text.push('\n');
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_misspelled_surface_key_is_refused_naming_the_key_meant() {
        let text = crate::optics::formats::to_json(&crate::optics::library::builtin_lens("tessar").unwrap());
        let bad = text.replacen("\"radius\"", "\"conci\": -0.5,\n      \"radius\"", 1);
        let e = parse(&bad).unwrap_err().to_string();
        assert!(e.contains("unknown surface key `conci` (did you mean `conic`?)") && e.contains("surfaces[0]"), "{e}");
        assert!(e.starts_with("JSON line "), "{e}");
        let extra = text.replacen("\"surfaces\"", "\"camera\": \"x\",\n  \"surfaces\"", 1);
        let loaded = parse(&extra).unwrap();
        assert!(loaded.warnings.iter().any(|w| w.contains("camera")), "{:?}", loaded.warnings);
    }
}
