//! What every lens format shares: the error a reader returns ([`FormatError`]: each message one line, naming
//! the file line or JSON path), the last step of every text reader ([`finish_text_lens`]: name, validate,
//! and map a validation error to the surface's line), and the number form every writer uses ([`exact`]:
//! the shortest text that reads back to the same f64).

use crate::optics::lens::{Lens, LensError, Surface};
use crate::optics::tolerance;

/// A lens as read from a file, with what the reader had to decide for it (clipped clear apertures, which
/// system aperture won): one sentence per warning, for `lens info`, stderr and the app's lens panel.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedLens {
    pub lens: Lens,
    pub warnings: Vec<String>,
}

/// Validates `lens` tolerantly ([`tolerance::repair`]), adding its warnings after the reader's own;
/// `surface_lines[k]` is the file line of surface k, so that a refusal names it.
pub(crate) fn finish_loaded(
    mut lens: Lens,
    mut warnings: Vec<String>,
    surface_lines: &[usize],
) -> Result<LoadedLens, FormatError> {
    let repaired = tolerance::repair(&mut lens).map_err(|e| FormatError::invalid(e, surface_lines))?;
    warnings.extend(repaired);
    Ok(LoadedLens { lens, warnings })
}

/// Lens files larger than this are refused before they are read.
pub const MAX_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// Why a lens file could not be read. Each message fits on one line.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    // The causes are part of each message and deliberately not `source`s: an error chain printed with
    // its sources would say them twice.
    #[error("cannot read {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("the file is {bytes} bytes; lens files are small (at most {MAX_FILE_BYTES})")]
    TooLarge { bytes: u64 },
    #[error("the file is empty")]
    Empty,
    #[error("the file is not text (binary bytes near byte {offset})")]
    NotText { offset: usize },
    #[error(
        "not a lens file: it is neither JSON, a Zemax .zmx, a pbrt .dat, a FlareSim .lens nor an OpenLensFlare .xml"
    )]
    UnknownFormat,
    #[error("JSON line {line}, column {column}{at}: {message}", at = json_at(.path))]
    Json { line: usize, column: usize, path: String, message: String },
    #[error("{format} line {line}: {message}")]
    Line { format: &'static str, line: usize, message: String },
    #[error("{format} line {line}: {what} is not supported")]
    Unsupported { format: &'static str, line: usize, what: String },
    #[error("{format}: {message}")]
    Structure { format: &'static str, message: String },
    #[error("{where_}{error}", where_ = line_prefix(.line))]
    Invalid { line: Option<usize>, error: LensError },
}

fn json_at(path: &str) -> String {
    if path.is_empty() || path == "." { String::new() } else { format!(", at `{path}`") }
}

fn line_prefix(line: &Option<usize>) -> String {
    line.map(|l| format!("line {l}: ")).unwrap_or_default()
}

impl FormatError {
    /// Wraps a validation error, naming the file line of the surface where the format has lines.
    pub(crate) fn invalid(error: LensError, surface_lines: &[usize]) -> Self {
        let line = match &error {
            LensError::Field { surface, .. } => surface_lines.get(*surface).copied(),
            _ => None,
        };
        Self::Invalid { line, error }
    }
}

/// Names, validates and returns a lens read from a text format; `surface_lines[k]` is the file line of
/// surface k, so that a validation error names it.
pub(crate) fn finish_text_lens(
    surfaces: Vec<Surface>,
    name: String,
    id_hint: &str,
    surface_lines: &[usize],
    warnings: Vec<String>,
) -> Result<LoadedLens, FormatError> {
    let lens = Lens {
        id: id_hint.to_owned(),
        name: if name.is_empty() { id_hint.to_owned() } else { name },
        surfaces,
        extra: Default::default(),
    };
    finish_loaded(lens, warnings, surface_lines)
}

/// Formats a number so that it reads back to the same f64 (shortest round-trip form).
pub(crate) fn exact(v: f64) -> String {
    let s = format!("{v:?}");
    s.strip_suffix(".0").map(str::to_owned).unwrap_or(s)
}
