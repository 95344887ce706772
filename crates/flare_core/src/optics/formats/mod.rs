//! Lens files: the native JSON form, Zemax OpticStudio `.zmx` and pbrt `.dat`, read and written; the
//! formats of other flare tools, FlareSim `.lens` (read and written) and OpenLensFlare `.xml` (read).
//!
//! # How it works
//! [`load_lens_file`] reads at most [`MAX_FILE_BYTES`], decodes the text (UTF-8, or UTF-16 with or without a
//! byte-order mark as OpticStudio writes it, or Latin-1 for old `.zmx` files), picks the format by extension
//! and then by content ([`LensFormat::detect`]), parses it, and validates the lens
//! tolerantly (`crate::optics::tolerance::repair`: guessed clear apertures that make neighbours cross are
//! clipped, with a warning, where no axial light passes). Every failure is a [`FormatError`] that names the file's line
//! (text formats) or the JSON path, and the field; nothing is half-loaded. Writers produce text that the
//! readers read back to the same lens ([`to_json`], [`zmx::write`], [`pbrt::write`]), and
//! [`crate::files::write_atomic`] puts it on disk through a temporary file and a rename, so a crash never
//! leaves half a file.

pub mod flaresim;
pub mod json;
pub mod olf;
pub mod pbrt;
mod text;
pub mod zmx;

pub use text::{FormatError, LoadedLens, MAX_FILE_BYTES};

use std::io::Read;
use std::path::Path;

use super::lens::Lens;

/// The file formats FlareLab reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LensFormat {
    /// The native JSON form of `lenses/README.md`.
    Json,
    /// Zemax OpticStudio sequential lens file.
    Zmx,
    /// pbrt's realistic-camera lens table.
    PbrtDat,
    /// FlareSim's lens prescription.
    FlareSimLens,
    /// OpenLensFlare's optical system.
    OpenLensFlareXml,
}

impl LensFormat {
    pub fn name(self) -> &'static str {
        match self {
            Self::Json => "JSON",
            Self::Zmx => "Zemax .zmx",
            Self::PbrtDat => "pbrt .dat",
            Self::FlareSimLens => "FlareSim .lens",
            Self::OpenLensFlareXml => "OpenLensFlare .xml",
        }
    }

    /// The format an extension names, if any.
    pub fn from_extension(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "json" => Some(Self::Json),
            "zmx" => Some(Self::Zmx),
            "dat" => Some(Self::PbrtDat),
            "lens" => Some(Self::FlareSimLens),
            "xml" => Some(Self::OpenLensFlareXml),
            _ => None,
        }
    }

    /// The format the text looks like: JSON starts with `{`, OpenLensFlare XML has an `<opticalSystem>`, a
    /// FlareSim .lens a `surfaces:` line, a .zmx has SURF/VERS/MODE keywords, a .dat has rows of numbers.
    pub fn detect(text: &str) -> Option<Self> {
        let trimmed = text.trim_start();
        if trimmed.starts_with('{') {
            return Some(Self::Json);
        }
        if olf::looks_like(text) {
            return Some(Self::OpenLensFlareXml);
        }
        if flaresim::looks_like(text) {
            return Some(Self::FlareSimLens);
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

/// Parses lens text in `format` (or the detected one) and validates it tolerantly, with the reader's
/// warnings. `id_hint` names the lens when the format has no id of its own (the file stem).
pub fn read_lens(text: &str, format: Option<LensFormat>, id_hint: &str) -> Result<LoadedLens, FormatError> {
    let format = match format {
        Some(f) => f,
        None => LensFormat::detect(text).ok_or(FormatError::UnknownFormat)?,
    };
    match format {
        LensFormat::Json => json::parse(text),
        LensFormat::Zmx => zmx::parse(text, id_hint),
        LensFormat::PbrtDat => pbrt::parse(text, id_hint),
        LensFormat::FlareSimLens => flaresim::parse(text, id_hint),
        LensFormat::OpenLensFlareXml => olf::parse(text, id_hint),
    }
}

/// [`read_lens`] without the warnings.
pub fn parse_lens(text: &str, format: Option<LensFormat>, id_hint: &str) -> Result<Lens, FormatError> {
    read_lens(text, format, id_hint).map(|l| l.lens)
}

/// Reads lens file bytes: decoding, format from the extension of `name` or the content, validation.
pub fn read_lens_bytes(bytes: &[u8], name: &Path) -> Result<LoadedLens, FormatError> {
    let text = decode_text(bytes)?;
    let stem = name.file_stem().and_then(|s| s.to_str()).unwrap_or("lens");
    let format = LensFormat::from_extension(name).or_else(|| LensFormat::detect(&text));
    read_lens(&text, format, stem)
}

/// [`read_lens_bytes`] without the warnings.
pub fn parse_lens_bytes(bytes: &[u8], name: &Path) -> Result<Lens, FormatError> {
    read_lens_bytes(bytes, name).map(|l| l.lens)
}

/// Reads and validates a lens file of any supported format, with the reader's warnings.
pub fn read_lens_file(path: &Path) -> Result<LoadedLens, FormatError> {
    let io = |error| FormatError::Io { path: path.display().to_string(), error };
    // A FIFO or device is refused before it is opened (opening a FIFO waits for a writer).
    let file = crate::files::open_regular(path)
        .map_err(|reason| io(std::io::Error::new(std::io::ErrorKind::InvalidInput, reason)))?;
    let bytes = file.metadata().map_err(io)?.len();
    if bytes > MAX_FILE_BYTES {
        return Err(FormatError::TooLarge { bytes });
    }
    let mut data = Vec::with_capacity(bytes as usize);
    file.take(MAX_FILE_BYTES + 1).read_to_end(&mut data).map_err(io)?;
    if data.len() as u64 > MAX_FILE_BYTES {
        // A FIFO or a device claims no length: what it gave is what counts.
        return Err(FormatError::TooLarge { bytes: data.len() as u64 });
    }
    read_lens_bytes(&data, path)
}

/// [`read_lens_file`] without the warnings.
pub fn load_lens_file(path: &Path) -> Result<Lens, FormatError> {
    read_lens_file(path).map(|l| l.lens)
}

/// The native JSON text of a lens (pretty, one key per line), which [`json::parse`] reads back identically.
pub fn to_json(lens: &Lens) -> String {
    json::write(lens)
}

/// Reads an AGF glass catalogue (any text encoding lens files may have) and adds its glasses to the ones
/// found by name (`crate::optics::glass::add_catalogue`); the catalogue is named by the file stem in
/// capitals (`ohara.agf` is OHARA). Returns how many glasses it holds; a broken file adds nothing.
pub fn load_glass_catalogue(path: &Path) -> Result<usize, String> {
    let bytes = crate::files::read_bounded(path, crate::files::MAX_TEXT_BYTES)?;
    let text = decode_text(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("USER").to_ascii_uppercase();
    crate::optics::glass::add_catalogue(&text, &name).map_err(|e| format!("{}: {e}", path.display()))
}
