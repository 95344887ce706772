//! Lens files: the native JSON form, Zemax OpticStudio `.zmx`, and pbrt `.dat`, read and written.
//!
//! # How it works
//! [`load_lens_file`] reads at most [`MAX_FILE_BYTES`], decodes the text (UTF-8, or UTF-16 with or without a
//! byte-order mark as OpticStudio writes it, or Latin-1 for old `.zmx` files), picks the format by extension
//! and then by content ([`LensFormat::detect`]), parses it, and validates the lens
//! ([`crate::optics::lens::Lens::validate`]). Every failure is a [`FormatError`] that names the file's line
//! (text formats) or the JSON path, and the field; nothing is half-loaded. Writers produce text that the
//! readers read back to the same lens ([`to_json`], [`zmx::write`], [`pbrt::write`]), and
//! [`crate::files::write_atomic`] puts it on disk through a temporary file and a rename, so a crash never
//! leaves half a file.

pub mod json;
pub mod pbrt;
pub mod zmx;

use std::io::Read;
use std::path::Path;

use super::lens::{Lens, LensError, Surface};

/// Lens files are a few kilobytes; anything beyond this is refused before it is read.
pub const MAX_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// The file formats FlareLab reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LensFormat {
    /// The native JSON form of `lenses/README.md`.
    Json,
    /// Zemax OpticStudio sequential lens file.
    Zmx,
    /// pbrt's realistic-camera lens table.
    PbrtDat,
}

impl LensFormat {
    pub fn name(self) -> &'static str {
        match self {
            Self::Json => "JSON",
            Self::Zmx => "Zemax .zmx",
            Self::PbrtDat => "pbrt .dat",
        }
    }

    /// The format an extension names, if any.
    pub fn from_extension(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "json" => Some(Self::Json),
            "zmx" => Some(Self::Zmx),
            "dat" => Some(Self::PbrtDat),
            _ => None,
        }
    }

    /// The format the text looks like: JSON starts with `{`, a .zmx has SURF/VERS/MODE keywords, a .dat
    /// has rows of numbers.
    pub fn detect(text: &str) -> Option<Self> {
        let trimmed = text.trim_start();
        if trimmed.starts_with('{') {
            return Some(Self::Json);
        }
        let mut numeric_rows = 0;
        for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
            let word = line.split_whitespace().next().unwrap_or("");
            if matches!(word, "SURF" | "VERS" | "MODE" | "UNIT") {
                return Some(Self::Zmx);
            }
            if line.starts_with('#') {
                continue;
            }
            if line.split_whitespace().all(|t| t.parse::<f64>().is_ok()) {
                numeric_rows += 1;
            } else {
                return None;
            }
        }
        (numeric_rows > 0).then_some(Self::PbrtDat)
    }
}

/// Why a lens file could not be read. Each message fits on one line.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("the file is {bytes} bytes; lens files are small (at most {MAX_FILE_BYTES})")]
    TooLarge { bytes: u64 },
    #[error("the file is empty")]
    Empty,
    #[error("the file is not text (binary bytes near byte {offset})")]
    NotText { offset: usize },
    #[error("not a lens file: it is neither JSON, a Zemax .zmx nor a pbrt .dat")]
    UnknownFormat,
    #[error("JSON line {line}, column {column}{at}: {message}", at = json_at(.path))]
    Json { line: usize, column: usize, path: String, message: String },
    #[error("{format} line {line}: {message}")]
    Line { format: &'static str, line: usize, message: String },
    #[error("{format} line {line}: {what} is not supported")]
    Unsupported { format: &'static str, line: usize, what: String },
    #[error("{format}: {message}")]
    Structure { format: &'static str, message: String },
    #[error("{where_}{source}", where_ = line_prefix(.line))]
    Invalid { line: Option<usize>, source: LensError },
}

fn json_at(path: &str) -> String {
    if path.is_empty() || path == "." { String::new() } else { format!(", at `{path}`") }
}

fn line_prefix(line: &Option<usize>) -> String {
    line.map(|l| format!("line {l}: ")).unwrap_or_default()
}

impl FormatError {
    /// Wraps a validation error, naming the file line of the surface where the format has lines.
    pub(crate) fn invalid(source: LensError, surface_lines: &[usize]) -> Self {
        let line = match &source {
            LensError::Field { surface, .. } => surface_lines.get(*surface).copied(),
            _ => None,
        };
        Self::Invalid { line, source }
    }
}

/// Decodes file bytes to text: UTF-8 (with or without BOM), UTF-16 LE/BE (with a BOM, or detected by its
/// zero bytes), else Latin-1 for old Windows files. Binary data is refused.
pub fn decode_text(bytes: &[u8]) -> Result<String, FormatError> {
    if bytes.is_empty() {
        return Err(FormatError::Empty);
    }
    let utf16 = |body: &[u8], little: bool| -> Result<String, FormatError> {
        let units: Vec<u16> = body
            .chunks(2)
            .map(|c| {
                let pair = [c[0], *c.get(1).unwrap_or(&0)];
                if little { u16::from_le_bytes(pair) } else { u16::from_be_bytes(pair) }
            })
            .collect();
        String::from_utf16(&units).map_err(|_| FormatError::NotText { offset: 0 })
    };
    let text = if let Some(body) = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]) {
        String::from_utf8(body.to_vec())
            .map_err(|e| FormatError::NotText { offset: e.utf8_error().valid_up_to() + 3 })?
    } else if let Some(body) = bytes.strip_prefix(&[0xFF, 0xFE]) {
        utf16(body, true)?
    } else if let Some(body) = bytes.strip_prefix(&[0xFE, 0xFF]) {
        utf16(body, false)?
    } else if bytes.len() >= 4 && bytes[1] == 0 && bytes[3] == 0 && bytes[0] != 0 {
        utf16(bytes, true)?
    } else if bytes.len() >= 4 && bytes[0] == 0 && bytes[2] == 0 && bytes[1] != 0 {
        utf16(bytes, false)?
    } else {
        match String::from_utf8(bytes.to_vec()) {
            Ok(s) => s,
            Err(_) => bytes.iter().map(|&b| b as char).collect(),
        }
    };
    if let Some(offset) =
        text.char_indices().find(|(_, c)| c.is_control() && !matches!(c, '\n' | '\r' | '\t')).map(|(i, _)| i)
    {
        return Err(FormatError::NotText { offset });
    }
    if text.trim().is_empty() {
        return Err(FormatError::Empty);
    }
    Ok(text)
}

/// Parses lens text in `format` (or the detected one) and validates it. `id_hint` names the lens when the
/// format has no id of its own (the file stem).
pub fn parse_lens(text: &str, format: Option<LensFormat>, id_hint: &str) -> Result<Lens, FormatError> {
    let format = match format {
        Some(f) => f,
        None => LensFormat::detect(text).ok_or(FormatError::UnknownFormat)?,
    };
    match format {
        LensFormat::Json => json::parse(text),
        LensFormat::Zmx => zmx::parse(text, id_hint),
        LensFormat::PbrtDat => pbrt::parse(text, id_hint),
    }
}

/// Parses lens file bytes: decoding, format from the extension of `name` or the content, validation.
pub fn parse_lens_bytes(bytes: &[u8], name: &Path) -> Result<Lens, FormatError> {
    let text = decode_text(bytes)?;
    let stem = name.file_stem().and_then(|s| s.to_str()).unwrap_or("lens");
    let format = LensFormat::from_extension(name).or_else(|| LensFormat::detect(&text));
    parse_lens(&text, format, stem)
}

/// Reads and validates a lens file of any supported format.
pub fn load_lens_file(path: &Path) -> Result<Lens, FormatError> {
    let io = |source| FormatError::Io { path: path.display().to_string(), source };
    let file = std::fs::File::open(path).map_err(io)?;
    let bytes = file.metadata().map_err(io)?.len();
    if bytes > MAX_FILE_BYTES {
        return Err(FormatError::TooLarge { bytes });
    }
    let mut data = Vec::with_capacity(bytes as usize);
    file.take(MAX_FILE_BYTES + 1).read_to_end(&mut data).map_err(io)?;
    parse_lens_bytes(&data, path)
}

/// The native JSON text of a lens (pretty, one key per line), which [`json::parse`] reads back identically.
pub fn to_json(lens: &Lens) -> String {
    json::write(lens)
}

/// Names, validates and returns a lens read from a text format; `surface_lines[k]` is the file line of
/// surface k, so that a validation error names it.
pub(crate) fn finish_text_lens(
    surfaces: Vec<Surface>,
    name: String,
    id_hint: &str,
    surface_lines: &[usize],
) -> Result<Lens, FormatError> {
    let lens = Lens {
        id: id_hint.to_owned(),
        name: if name.is_empty() { id_hint.to_owned() } else { name },
        surfaces,
        extra: Default::default(),
    };
    lens.validate().map_err(|e| FormatError::invalid(e, surface_lines))?;
    Ok(lens)
}

/// Formats a number so that it reads back to the same f64 (shortest round-trip form).
pub(crate) fn exact(v: f64) -> String {
    let s = format!("{v:?}");
    s.strip_suffix(".0").map(str::to_owned).unwrap_or(s)
}
