//! The native JSON lens form (`lenses/README.md`): read with the path of any bad value, written back
//! losslessly (unknown keys are kept, numbers are written in their shortest exact form).

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
    finish_loaded(lens, Vec::new(), &[])
}

fn json_error(e: &serde_json::Error, path: String) -> FormatError {
    let full = e.to_string();
    // serde_json appends " at line L column C"; the error names the position itself.
    let message = match full.rfind(" at line ") {
        Some(i) => full[..i].to_owned(),
        None => full,
    };
    FormatError::Json { line: e.line(), column: e.column(), path, message }
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
