//! What every lens format shares: the error a reader returns ([`FormatError`]: each message one line, naming
//! the file line or JSON path), the last step of every text reader ([`finish_text_lens`]: name, validate,
//! and map a validation error to the surface's line), the stop sizing that a file's system aperture asks
//! for ([`scale_stop_to_pupil`]), and the number form every writer uses ([`exact`]: the shortest text that
//! reads back to the same f64).

use crate::optics::lens::{Lens, LensError, Surface};
use crate::optics::paraxial::{FirstOrder, ParaxialError};
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
    #[error("the file is {bytes} bytes or more; lens files are small (at most {MAX_FILE_BYTES})")]
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

/// What [`scale_stop_to_pupil`] did: the stop's surface index and its semi-diameter before and after.
pub(crate) struct StopScaling {
    pub stop: usize,
    pub given_mm: f64,
    pub semi_mm: f64,
}

/// Why [`scale_stop_to_pupil`] could not size the stop.
pub(crate) enum StopScalingError {
    /// The lens has no first-order data (afocal, or a paraxial ray that cannot pass).
    NoFirstOrder(ParaxialError),
    /// The scaled semi-diameter is not a positive finite number.
    NoUsableSize,
}

/// Scales the stop's semi-diameter so that the paraxial entrance pupil (d line) has the diameter
/// `wanted_epd_mm` computes from the lens's first-order data (ENPD as given, or EFL / F-number). `Ok(None)`
/// when no surface is the stop; the caller words each error with its own line and field.
pub(crate) fn scale_stop_to_pupil(
    surfaces: &mut [Surface],
    wanted_epd_mm: impl FnOnce(&FirstOrder) -> f64,
) -> Result<Option<StopScaling>, StopScalingError> {
    let Some(stop) = surfaces.iter().position(|s| s.stop) else { return Ok(None) };
    let probe = Lens { id: String::new(), name: String::new(), surfaces: surfaces.to_vec(), extra: Default::default() };
    let first_order = FirstOrder::d_line(&probe).map_err(StopScalingError::NoFirstOrder)?;
    let given_mm = surfaces[stop].semi_aperture_mm;
    let semi_mm = given_mm * wanted_epd_mm(&first_order) / first_order.entrance_pupil_diameter_mm;
    if !(semi_mm.is_finite() && semi_mm > 0.0) {
        return Err(StopScalingError::NoUsableSize);
    }
    surfaces[stop].semi_aperture_mm = semi_mm;
    Ok(Some(StopScaling { stop, given_mm, semi_mm }))
}

/// Formats a number so that it reads back to the same f64 (shortest round-trip form).
pub(crate) fn exact(v: f64) -> String {
    let s = format!("{v:?}");
    s.strip_suffix(".0").map(str::to_owned).unwrap_or(s)
}
