//! The `.flut` file: one LUT (ray-traced or photo), versioned, checked on load, streamed.
//!
//! # How it works
//! Layout (all integers little-endian):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `FLUT\r\n\x1a\n` (catches text-mode transfers, like PNG's) |
//! | 4 | format version (`VERSION`) |
//! | 8 | header length H |
//! | 8 | FNV-1a 64 of the header bytes |
//! | H | header: UTF-8 JSON, [`Header`]: kind, lens id, fingerprint and its scheme, wavelengths, f-number, symmetry, theta range, per ghost its surfaces, key, thetas, azimuths and per entry its light, paraxial frame, window, size, and where its data lies |
//! | ... | per entry, in header order: its texels compressed with deflate (zlib, `flate2`) |
//!
//! An entry's uncompressed data is `width x height` RGB half floats (rounded to
//! `super::TEXEL_MANTISSA_BITS` mantissa bits), byte-shuffled for compression: the low bytes of channel R of
//! every texel, then its high bytes, then G, B (6 planes of w x h bytes). Alpha (coverage) is not stored: it is
//! computed on load from the RGB (`super::set_coverage`). Version 1 files stored RGBA (8 planes) and no
//! `fitted` flags; they still load. Each entry carries the FNV-1a 64 of its uncompressed bytes, and the header
//! the FNV-1a 64 of all the entries' compressed bytes (`data_checksum`; absent in files written before it).
//!
//! Loading ([`read_lut`]) streams the file: it checks the magic, the version, that the header fits the file
//! and its checksum, then every field of the header (finite, in range, sizes that match, data inside the
//! file, totals under `MAX_TEXELS`) before allocating anything for the texels, then reads each entry's
//! compressed bytes and inflates them, the entries in parallel, each into a buffer of exactly its declared size
//! (never more), and checks its checksum and that every value is finite and non-negative; last, the data's
//! checksum. A still's read ([`read_lut_near`]) inflates only the entries its light angle draws and passes over
//! the others' bytes, summing them into the data's checksum: a file damaged anywhere is still refused (one
//! without that checksum is read whole). Every failure is a [`LutError`] that names what is wrong; none panics. Writing
//! ([`write_lut`]) goes to a temporary file renamed over the target, so a user's file is never half-written.

use std::io::{Read, Write};
use std::path::Path;

use flate2::Compression;
use flate2::read::ZlibDecoder;
use flate2::write::ZlibEncoder;
use half::f16;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{GhostLut, LutEntry, LutGhost, LutKind, Symmetry};
use crate::fingerprint::{FNV_OFFSET, fnv1a};
use crate::ghost::ParaxialFrame;

/// The file's magic bytes.
pub(crate) const MAGIC: [u8; 8] = *b"FLUT\r\n\x1a\n";
/// The format version this build writes; it reads this one and the ones before it ([`OLDEST_VERSION`]).
/// Version 2 added the per-interval `fitted` flags.
pub(crate) const VERSION: u32 = 2;
/// The oldest format version this build reads.
pub(crate) const OLDEST_VERSION: u32 = 1;
/// Most header bytes accepted.
pub(crate) const MAX_HEADER_BYTES: u64 = 64 << 20;
/// Most texels accepted over all entries (2 GiB of half floats).
pub(crate) const MAX_TEXELS: u64 = 1 << 28;
/// Most texels across an entry: what an atlas page holds inside its zero border ([`super::blend::ATLAS_PAGE`]),
/// so the GPU draws every texel the CPU twin draws (a bake makes at most [`crate::bake::MAX_ENTRY_TEXELS`]).
pub const MAX_SIDE: u32 = super::blend::ATLAS_PAGE - 2;

/// Why a LUT file is refused.
#[derive(Debug, thiserror::Error)]
pub enum LutError {
    // The cause is the message and deliberately not a `source`: a chain printed with its sources said it twice
    // ("cannot read nope.flut: No such file ...: cannot read nope.flut: No such file ...", issue 61).
    #[error("{0}")]
    Io(std::io::Error),
    #[error("not a FlareLab LUT (.flut) file: wrong magic bytes")]
    Magic,
    #[error("LUT format version {found}; this FlareLab reads versions {OLDEST_VERSION} to {VERSION}")]
    Version { found: u32 },
    #[error("the file is truncated: {0}")]
    Truncated(String),
    #[error("the header is corrupt: {0}")]
    Header(String),
    #[error("ghost {ghost}, entry {entry}: {reason}")]
    Entry { ghost: usize, entry: usize, reason: String },
    #[error(
        "this LUT was baked for another lens or settings (`{lut_lens}`, fingerprint {lut:016x}; the live lens `{lens}` has {live:016x}): bake it again"
    )]
    OtherLens { lut_lens: String, lut: u64, lens: String, live: u64 },
    #[error(
        "this LUT (`{lut_lens}`) was baked by an older FlareLab whose lens fingerprint this one cannot compare: bake it again (`flarelab bake LENS`)"
    )]
    OldFingerprint { lut_lens: String },
    #[error(
        "LUT ghost {entry} names ghost {ghost} (surfaces {i}-{j}), which the lens `{lens}` does not have ({reason}): the file does not belong to this lens"
    )]
    NoSuchGhost { entry: usize, ghost: u32, i: u32, j: u32, lens: String, reason: String },
}

/// The JSON header.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// "ray-traced" or "photo".
    pub kind: String,
    pub lens_id: String,
    /// 16 hex digits.
    pub lens_fingerprint: String,
    /// The rule the fingerprint was made by (`crate::fingerprint::SCHEME`); absent in files from before
    /// schemes (read as 0: a ray-traced LUT among them is refused with a request to bake it again).
    #[serde(default)]
    pub fingerprint_scheme: u32,
    pub wavelengths_nm: Vec<f64>,
    pub f_number: f64,
    pub symmetry_order: u32,
    pub symmetry_axis_deg: f64,
    pub theta_max_deg: f64,
    pub ghosts: Vec<GhostHeader>,
    /// FNV-1a 64 of every entry's compressed bytes in the file's order, 16 hex digits: what lets a read that
    /// inflates only some entries ([`read_lut_near`]) still refuse a file damaged anywhere. Absent in files
    /// written before it (such a file is read whole, every entry checked by its own checksum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_checksum: Option<String>,
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GhostHeader {
    pub ghost: u32,
    pub surfaces: [u32; 2],
    pub key: String,
    pub thetas_deg: Vec<f64>,
    /// Per theta interval, whether it is fitted (version 2; absent in version 1: none is).
    #[serde(default)]
    pub fitted: Vec<bool>,
    pub phis_deg: Vec<f64>,
    pub entries: Vec<EntryHeader>,
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EntryHeader {
    pub theta_deg: f64,
    pub phi_deg: f64,
    pub paraxial_centre_mm: [f64; 2],
    pub paraxial_half_mm: f64,
    pub paraxial_energy: f64,
    pub centre_mm: [f64; 2],
    pub texel_mm: f64,
    pub width: u32,
    pub height: u32,
    /// Compressed bytes that follow for this entry.
    pub compressed_bytes: u64,
    /// FNV-1a 64 of the uncompressed bytes, 16 hex digits.
    pub checksum: String,
}

fn hex(v: u64) -> String {
    format!("{v:016x}")
}

fn unhex(text: &str, what: &str) -> Result<u64, LutError> {
    u64::from_str_radix(text, 16).map_err(|_| LutError::Header(format!("{what} `{text}` is not 16 hex digits")))
}

/// The byte-shuffled planes of the first `channels` channels of an entry's texels.
fn shuffle(texels: &[[f16; 4]], channels: usize) -> Vec<u8> {
    let n = texels.len();
    let mut out = vec![0u8; n * 2 * channels];
    for (k, t) in texels.iter().enumerate() {
        for (c, v) in t[..channels].iter().enumerate() {
            let [lo, hi] = v.to_bits().to_le_bytes();
            out[(2 * c) * n + k] = lo;
            out[(2 * c + 1) * n + k] = hi;
        }
    }
    out
}

/// Texels from `channels` byte-shuffled planes (the others zero).
fn unshuffle(bytes: &[u8], channels: usize) -> Vec<[f16; 4]> {
    let n = bytes.len() / (2 * channels);
    (0..n)
        .map(|k| {
            std::array::from_fn(|c| {
                if c < channels {
                    f16::from_bits(u16::from_le_bytes([bytes[2 * c * n + k], bytes[(2 * c + 1) * n + k]]))
                } else {
                    f16::ZERO
                }
            })
        })
        .collect()
}

/// Channels stored per texel in a file of `version`.
fn stored_channels(version: u32) -> usize {
    if version == 1 { 4 } else { 3 }
}

/// The file's bytes.
pub fn encode(lut: &GhostLut) -> Vec<u8> {
    encode_version(lut, VERSION)
}

/// The file's bytes in format `version` (1 for the tests of old files: RGBA, no `fitted` flags).
fn encode_version(lut: &GhostLut, version: u32) -> Vec<u8> {
    // Every entry compressed in parallel (the bytes do not depend on the order they are made in).
    let compressed: Vec<Vec<(EntryHeader, Vec<u8>)>> = lut
        .ghosts
        .iter()
        .map(|g| {
            g.entries
                .par_iter()
                .map(|e| {
                    let raw = shuffle(&e.texels, stored_channels(version));
                    let mut encoder = ZlibEncoder::new(Vec::new(), Compression::default());
                    encoder.write_all(&raw).expect("writing to memory");
                    let compressed = encoder.finish().expect("writing to memory");
                    let header = EntryHeader {
                        theta_deg: e.theta_deg,
                        phi_deg: e.phi_deg,
                        paraxial_centre_mm: e.paraxial.centre_mm,
                        paraxial_half_mm: e.paraxial.half_mm,
                        paraxial_energy: e.paraxial.energy,
                        centre_mm: e.centre_mm,
                        texel_mm: e.texel_mm,
                        width: e.width,
                        height: e.height,
                        compressed_bytes: compressed.len() as u64,
                        checksum: hex(fnv1a(&raw, FNV_OFFSET)),
                    };
                    (header, compressed)
                })
                .collect()
        })
        .collect();
    let mut blobs = Vec::new();
    let ghosts = lut
        .ghosts
        .iter()
        .zip(compressed)
        .map(|(g, entries)| GhostHeader {
            ghost: g.ghost,
            surfaces: g.surfaces,
            key: hex(g.key),
            thetas_deg: g.thetas_deg.clone(),
            fitted: if version == 1 { Vec::new() } else { g.fitted.clone() },
            phis_deg: g.phis_deg.clone(),
            entries: entries
                .into_iter()
                .map(|(header, blob)| {
                    blobs.push(blob);
                    header
                })
                .collect(),
        })
        .collect();
    let header = Header {
        kind: match lut.kind {
            LutKind::RayTraced => "ray-traced".into(),
            LutKind::Photo => "photo".into(),
        },
        lens_id: lut.lens_id.clone(),
        lens_fingerprint: hex(lut.lens_fingerprint),
        fingerprint_scheme: lut.fingerprint_scheme,
        wavelengths_nm: lut.wavelengths_nm.clone(),
        f_number: lut.f_number,
        symmetry_order: lut.symmetry.order,
        symmetry_axis_deg: lut.symmetry.axis_deg,
        theta_max_deg: lut.theta_max_deg,
        ghosts,
        data_checksum: Some(hex(blobs.iter().fold(FNV_OFFSET, |sum, blob| fnv1a(blob, sum)))),
    };
    let json = serde_json::to_vec(&header).expect("the header serialises");
    let mut out = Vec::with_capacity(28 + json.len() + blobs.iter().map(Vec::len).sum::<usize>());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&fnv1a(&json, FNV_OFFSET).to_le_bytes());
    out.extend_from_slice(&json);
    for blob in blobs {
        out.extend_from_slice(&blob);
    }
    out
}

/// Writes `lut` to `path` atomically (temporary file, then rename). A LUT this build's reader would refuse for
/// its size (more than `MAX_TEXELS` in all, an entry wider than [`MAX_SIDE`]) is refused here instead of
/// written (issue 61: a photo LUT of 70 large photos was written, then refused by `--lut` as corrupt).
pub fn write_lut(path: &Path, lut: &GhostLut) -> std::io::Result<u64> {
    let entries = || lut.ghosts.iter().flat_map(|g| &g.entries);
    let texels: u64 = entries().map(|e| u64::from(e.width) * u64::from(e.height)).sum();
    if texels > MAX_TEXELS {
        return Err(std::io::Error::other(format!(
            "{texels} texels in all, more than the {MAX_TEXELS} a LUT file holds: not written"
        )));
    }
    if let Some(e) = entries().find(|e| e.width.max(e.height) > MAX_SIDE) {
        return Err(std::io::Error::other(format!(
            "an entry of {}x{} texels, wider than the {MAX_SIDE} a LUT file holds: not written",
            e.width, e.height
        )));
    }
    let bytes = encode(lut);
    crate::files::write_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

/// Reads and checks a LUT file.
pub fn read_lut(path: &Path) -> Result<GhostLut, LutError> {
    read_lut_near(path, None)
}

/// [`read_lut`], with only the images a frame whose light is `near_theta_deg` off the axis draws when that is
/// given (per ghost, the baked thetas around it, every azimuth: `super::blend::thetas_drawn`); every other
/// entry keeps its place and its paraxial frame with no image ([`LutEntry::empty`]), its data passed over
/// unread. A still pays for the few images it draws, not for the whole LUT.
pub fn read_lut_near(path: &Path, near_theta_deg: Option<f64>) -> Result<GhostLut, LutError> {
    // A FIFO or device is refused before it is opened (opening a FIFO waits for a writer).
    let file = crate::files::open_regular(path)
        .map_err(|reason| LutError::Io(std::io::Error::new(std::io::ErrorKind::InvalidInput, reason)))?;
    let length = file.metadata()?.len();
    crate::timing::span("read and decode the LUT file", || {
        decode_near(std::io::BufReader::new(file), length, near_theta_deg)
    })
}

impl From<std::io::Error> for LutError {
    fn from(error: std::io::Error) -> Self {
        Self::Io(error)
    }
}

fn read_exact_or(reader: &mut impl Read, buf: &mut [u8], what: &str) -> Result<(), LutError> {
    reader.read_exact(buf).map_err(|e| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => LutError::Truncated(format!("it ends inside the {what}")),
        _ => LutError::Io(e),
    })
}

/// Decodes a LUT from a stream of `length` bytes.
pub fn decode(reader: impl Read, length: u64) -> Result<GhostLut, LutError> {
    decode_near(reader, length, None)
}

/// The fixed part and the header of a LUT file of `length` bytes: its version and its header, checked
/// against the bytes after it.
fn read_header(mut reader: impl Read, length: u64) -> Result<(u32, Header), LutError> {
    let mut magic = [0u8; 8];
    read_exact_or(&mut reader, &mut magic, "magic bytes").map_err(|e| match e {
        LutError::Truncated(_) => LutError::Magic,
        other => other,
    })?;
    if magic != MAGIC {
        return Err(LutError::Magic);
    }
    let mut word = [0u8; 4];
    read_exact_or(&mut reader, &mut word, "version")?;
    let version = u32::from_le_bytes(word);
    if !(OLDEST_VERSION..=VERSION).contains(&version) {
        return Err(LutError::Version { found: version });
    }
    let mut long = [0u8; 8];
    read_exact_or(&mut reader, &mut long, "header length")?;
    let header_len = u64::from_le_bytes(long);
    read_exact_or(&mut reader, &mut long, "header checksum")?;
    let header_sum = u64::from_le_bytes(long);
    let fixed = 28u64;
    if header_len > MAX_HEADER_BYTES || fixed + header_len > length {
        return Err(LutError::Truncated(format!(
            "the header says it has {header_len} bytes, the file has {} after the fixed part",
            length.saturating_sub(fixed)
        )));
    }
    let mut json = vec![0u8; header_len as usize];
    read_exact_or(&mut reader, &mut json, "header")?;
    if fnv1a(&json, FNV_OFFSET) != header_sum {
        return Err(LutError::Header("its checksum does not match (the file is damaged)".into()));
    }
    let header: Header = serde_json::from_slice(&json).map_err(|e| LutError::Header(e.to_string()))?;
    let data_len = length - fixed - header_len;
    check_header(&header, data_len)?;
    Ok((version, header))
}

/// Reads `reader` to its end a block at a time, summing what it reads into `sum`; the bytes read.
fn sum_blocks(mut reader: impl Read, sum: &mut u64) -> Result<u64, LutError> {
    let mut block = [0u8; 1 << 16];
    let mut read = 0u64;
    loop {
        let n = reader.read(&mut block)?;
        if n == 0 {
            return Ok(read);
        }
        *sum = fnv1a(&block[..n], *sum);
        read += n as u64;
    }
}

/// The header's ghosts with the entries' texels, `texels_of` by (ghost, entry); an entry with none there
/// (not drawn at the angle read near) keeps its place with no image.
fn ghosts_of(
    header: &Header,
    mut texels_of: std::collections::HashMap<(usize, usize), Vec<[f16; 4]>>,
) -> Result<Vec<LutGhost>, LutError> {
    let mut ghosts = Vec::with_capacity(header.ghosts.len());
    for (gi, g) in header.ghosts.iter().enumerate() {
        let mut entries = Vec::with_capacity(g.entries.len());
        for (ei, e) in g.entries.iter().enumerate() {
            let paraxial = ParaxialFrame {
                centre_mm: e.paraxial_centre_mm,
                half_mm: e.paraxial_half_mm,
                energy: e.paraxial_energy,
            };
            let Some(texels) = texels_of.remove(&(gi, ei)) else {
                entries.push(LutEntry::empty(e.theta_deg, e.phi_deg, paraxial));
                continue;
            };
            entries.push(LutEntry {
                theta_deg: e.theta_deg,
                phi_deg: e.phi_deg,
                paraxial,
                centre_mm: e.centre_mm,
                texel_mm: e.texel_mm,
                width: e.width,
                height: e.height,
                texels,
            });
        }
        ghosts.push(LutGhost {
            ghost: g.ghost,
            surfaces: g.surfaces,
            key: unhex(&g.key, "ghost key")?,
            thetas_deg: g.thetas_deg.clone(),
            fitted: g.fitted.clone(),
            phis_deg: g.phis_deg.clone(),
            entries,
        });
    }
    Ok(ghosts)
}

/// [`decode`], with only the images drawn at `near_theta_deg` when it is given ([`read_lut_near`]).
fn decode_near(mut reader: impl Read, length: u64, near_theta_deg: Option<f64>) -> Result<GhostLut, LutError> {
    let (version, header) = read_header(&mut reader, length)?;
    let kind = match header.kind.as_str() {
        "ray-traced" => LutKind::RayTraced,
        "photo" => LutKind::Photo,
        other => return Err(LutError::Header(format!("kind `{other}`: expected `ray-traced` or `photo`"))),
    };
    // Each entry's compressed texels are read in turn (an entry a frame at `near_theta_deg` does not draw is
    // passed over), then inflated and checked in parallel; the first entry in the file's order that fails is
    // the error.
    let channels = stored_channels(version);
    let data_checksum = header.data_checksum.as_deref().map(|h| unhex(h, "data checksum")).transpose()?;
    // Without the data's checksum a damaged entry is found only by inflating it: every entry is.
    let near_theta_deg = near_theta_deg.filter(|_| data_checksum.is_some());
    let mut data_sum = FNV_OFFSET;
    let mut blobs: Vec<(usize, usize, Vec<u8>)> = Vec::new();
    for (gi, g) in header.ghosts.iter().enumerate() {
        // Entry `t * phis + p` is baked at theta `t` (the layout `LutScene::build` reads).
        let drawn = near_theta_deg
            .filter(|_| !g.phis_deg.is_empty())
            .map(|theta| super::blend::thetas_drawn(&g.thetas_deg, theta));
        for (ei, e) in g.entries.iter().enumerate() {
            let mut limited = (&mut reader).take(e.compressed_bytes);
            let skipped = drawn.as_ref().is_some_and(|thetas| !thetas.contains(&(ei / g.phis_deg.len())));
            let mut compressed = Vec::new();
            // One passed over is summed into the data's checksum a block at a time.
            let read = if skipped {
                sum_blocks(&mut limited, &mut data_sum)?
            } else {
                limited.read_to_end(&mut compressed)? as u64
            };
            if read != e.compressed_bytes {
                return Err(LutError::Truncated(format!("ghost {gi}, entry {ei}: its data ends early")));
            }
            if !skipped {
                data_sum = fnv1a(&compressed, data_sum);
                blobs.push((gi, ei, compressed));
            }
        }
    }
    let decoded: Vec<Result<Vec<[f16; 4]>, LutError>> = blobs
        .par_iter()
        .map(|(gi, ei, compressed)| entry_texels(&header.ghosts[*gi].entries[*ei], compressed, channels, (*gi, *ei)))
        .collect();
    let mut texels_of = std::collections::HashMap::new();
    for ((gi, ei, _), texels) in blobs.iter().zip(decoded) {
        texels_of.insert((*gi, *ei), texels?);
    }
    // (An entry read and damaged is named above; one passed over is found here.)
    if data_checksum.is_some_and(|sum| sum != data_sum) {
        return Err(LutError::Header("its data's checksum does not match (the file is damaged)".into()));
    }
    let ghosts = ghosts_of(&header, texels_of)?;
    let mut rest = [0u8; 1];
    if reader.read(&mut rest)? != 0 {
        return Err(LutError::Header("there are bytes after the last entry".into()));
    }
    Ok(GhostLut {
        kind,
        lens_id: header.lens_id,
        lens_fingerprint: unhex(&header.lens_fingerprint, "lens fingerprint")?,
        fingerprint_scheme: header.fingerprint_scheme,
        wavelengths_nm: header.wavelengths_nm,
        f_number: header.f_number,
        symmetry: Symmetry { order: header.symmetry_order, axis_deg: header.symmetry_axis_deg },
        theta_max_deg: header.theta_max_deg,
        ghosts,
    })
}

/// The texels of entry `ei` of ghost `gi` (`e` its header) from its `compressed` bytes: inflated to exactly its
/// size, its checksum matched, every texel finite and not negative.
fn entry_texels(
    e: &EntryHeader,
    compressed: &[u8],
    channels: usize,
    (gi, ei): (usize, usize),
) -> Result<Vec<[f16; 4]>, LutError> {
    let bad = |reason: String| LutError::Entry { ghost: gi, entry: ei, reason };
    let raw_len = u64::from(e.width) * u64::from(e.height) * 2 * channels as u64;
    let mut raw = Vec::with_capacity(raw_len as usize);
    ZlibDecoder::new(compressed).take(raw_len + 1).read_to_end(&mut raw).map_err(|err| match err.kind() {
        std::io::ErrorKind::UnexpectedEof => {
            LutError::Truncated(format!("ghost {gi}, entry {ei}: its data ends early"))
        }
        _ => bad(format!("its compressed data is corrupt ({err})")),
    })?;
    if raw.len() as u64 != raw_len {
        return Err(bad(format!("{} bytes of texels where {}x{} needs {raw_len}", raw.len(), e.width, e.height)));
    }
    if unhex(&e.checksum, "checksum")? != fnv1a(&raw, FNV_OFFSET) {
        return Err(bad("its checksum does not match (the data is damaged)".into()));
    }
    let mut texels = unshuffle(&raw, channels);
    if let Some(k) = texels.iter().position(|t| t.iter().any(|v| !v.is_finite() || v.to_f32() < 0.0)) {
        return Err(bad(format!("texel {k} is not finite or negative")));
    }
    if channels == 3 {
        super::set_coverage(&mut texels);
    }
    Ok(texels)
}

/// Every header field in range, before anything is allocated for the texels.
fn check_header(h: &Header, data_len: u64) -> Result<(), LutError> {
    let bad = |what: String| Err(LutError::Header(what));
    let finite_in = |v: f64, lo: f64, hi: f64| v.is_finite() && (lo..=hi).contains(&v);
    if h.wavelengths_nm.is_empty() || !h.wavelengths_nm.iter().all(|w| finite_in(*w, 200.0, 2000.0)) {
        return bad(format!("wavelengths {:?}: 1 or more, each 200 to 2000 nm", h.wavelengths_nm));
    }
    if !finite_in(h.f_number, 0.0, 1000.0) || !finite_in(h.symmetry_axis_deg, -360.0, 360.0) || h.symmetry_order > 64 {
        return bad("f-number, symmetry order or axis out of range".into());
    }
    if !finite_in(h.theta_max_deg, 0.0, 89.0) {
        return bad(format!("theta_max_deg {}: 0 to 89", h.theta_max_deg));
    }
    let wedge = Symmetry { order: h.symmetry_order, axis_deg: 0.0 }.wedge_deg();
    let (mut texels, mut bytes) = (0u64, 0u64);
    for (gi, g) in h.ghosts.iter().enumerate() {
        let increasing = |xs: &[f64], hi: f64| {
            !xs.is_empty() && xs.iter().all(|x| finite_in(*x, 0.0, hi)) && xs.windows(2).all(|w| w[0] < w[1])
        };
        if !increasing(&g.thetas_deg, 89.0) {
            return bad(format!("ghost {gi}: thetas {:?} must increase within 0 to 89 degrees", g.thetas_deg));
        }
        if !increasing(&g.phis_deg, wedge) {
            return bad(format!("ghost {gi}: azimuths {:?} must increase within the wedge 0 to {wedge}", g.phis_deg));
        }
        if !(g.fitted.is_empty() || g.fitted.len() + 1 == g.thetas_deg.len()) {
            return bad(format!(
                "ghost {gi}: {} fitted flags for {} thetas (one per interval, or none)",
                g.fitted.len(),
                g.thetas_deg.len()
            ));
        }
        if g.entries.len() != g.thetas_deg.len() * g.phis_deg.len() {
            return bad(format!(
                "ghost {gi}: {} entries for {} thetas x {} azimuths",
                g.entries.len(),
                g.thetas_deg.len(),
                g.phis_deg.len()
            ));
        }
        for (ei, e) in g.entries.iter().enumerate() {
            let entry_bad = |reason: &str| Err(LutError::Entry { ghost: gi, entry: ei, reason: reason.into() });
            let (t, p) = (ei / g.phis_deg.len(), ei % g.phis_deg.len());
            if e.theta_deg != g.thetas_deg[t] || e.phi_deg != g.phis_deg[p] {
                return entry_bad("its light direction does not match the ghost's thetas and azimuths");
            }
            if e.width > MAX_SIDE || e.height > MAX_SIDE || (e.width == 0) != (e.height == 0) {
                return entry_bad(&format!(
                    "its size {} x {} is out of range (0 x 0 for no light, else 1 to {MAX_SIDE} texels a side)",
                    e.width, e.height
                ));
            }
            let geometry = [e.paraxial_centre_mm[0], e.paraxial_centre_mm[1], e.centre_mm[0], e.centre_mm[1]];
            if !geometry.iter().all(|v| finite_in(*v, -1e4, 1e4))
                || !finite_in(e.paraxial_half_mm, 1e-9, 1e4)
                || !finite_in(e.texel_mm, 1e-9, 1e4)
                || !finite_in(e.paraxial_energy, 0.0, 1e12)
            {
                return entry_bad("a position, size or energy is not finite or out of range");
            }
            texels += u64::from(e.width) * u64::from(e.height);
            bytes = bytes.saturating_add(e.compressed_bytes);
        }
    }
    if texels > MAX_TEXELS {
        return bad(format!("{texels} texels in all: at most {MAX_TEXELS}"));
    }
    if bytes != data_len {
        if bytes > data_len {
            return Err(LutError::Truncated(format!(
                "the entries need {bytes} bytes of data, the file has {data_len}"
            )));
        }
        return bad(format!("the entries need {bytes} bytes of data but the file has {data_len}"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-ghost LUT of two 3 x 2 entries, stored as the bake stores texels.
    fn tiny() -> GhostLut {
        let entry = |theta_deg: f64, scale: f32| LutEntry {
            theta_deg,
            phi_deg: 0.0,
            paraxial: ParaxialFrame { centre_mm: [0.5, -0.25], half_mm: 2.0, energy: 3.0 },
            centre_mm: [0.4, -0.2],
            texel_mm: 0.5,
            width: 3,
            height: 2,
            texels: super::super::texels_with_coverage((0..6).map(|k| [k as f32 * scale, 0.5 * scale, 0.01])),
        };
        GhostLut {
            kind: LutKind::RayTraced,
            lens_id: "tiny".into(),
            lens_fingerprint: 42,
            fingerprint_scheme: crate::fingerprint::SCHEME,
            wavelengths_nm: vec![650.0, 510.0, 475.0],
            f_number: 2.0,
            symmetry: Symmetry { order: 0, axis_deg: 0.0 },
            theta_max_deg: 10.0,
            ghosts: vec![LutGhost {
                ghost: 3,
                surfaces: [1, 4],
                key: 7,
                thetas_deg: vec![0.0, 10.0],
                fitted: vec![true],
                phis_deg: vec![0.0],
                entries: vec![entry(0.0, 1.0), entry(10.0, 1.7)],
            }],
        }
    }

    /// Issue 61: the writer refuses a LUT the reader would refuse for its size, instead of writing it.
    #[test]
    fn a_lut_too_large_to_read_back_is_not_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wide.flut");
        let mut lut = tiny();
        lut.ghosts[0].entries[0].width = MAX_SIDE + 1;
        let e = write_lut(&path, &lut).unwrap_err().to_string();
        assert!(e.contains("wider than") && !path.exists(), "{e}");
        let mut lut = tiny();
        lut.ghosts[0].entries[0].height = (MAX_TEXELS / 3 + 1) as u32;
        let e = write_lut(&path, &lut).unwrap_err().to_string();
        assert!(e.contains("texels in all") && !path.exists(), "{e}");
        write_lut(&path, &tiny()).unwrap();
    }

    #[test]
    fn version_2_round_trips_and_version_1_files_still_load() {
        let lut = tiny();
        let bytes = encode(&lut);
        assert_eq!(decode(bytes.as_slice(), bytes.len() as u64).unwrap(), lut);
        // Version 1 stored alpha and no flags: the same texels (alpha as computed), no interval fitted.
        let old = encode_version(&lut, 1);
        assert_eq!(u32::from_le_bytes(old[8..12].try_into().unwrap()), 1);
        assert!(old.len() > bytes.len(), "RGBA takes more room than RGB");
        let back = decode(old.as_slice(), old.len() as u64).unwrap();
        let mut expected = lut.clone();
        expected.ghosts[0].fitted.clear();
        assert_eq!(back, expected);
        // A version from the future is refused by name.
        let mut future = bytes.clone();
        future[8..12].copy_from_slice(&(VERSION + 1).to_le_bytes());
        let err = decode(future.as_slice(), future.len() as u64).unwrap_err();
        assert!(err.to_string().contains("versions 1 to 2"), "{err}");
        // Flags that do not match the thetas are refused.
        let mut bad = lut.clone();
        bad.ghosts[0].fitted = vec![true, false];
        let bytes = encode(&bad);
        let err = decode(bytes.as_slice(), bytes.len() as u64).unwrap_err();
        assert!(err.to_string().contains("fitted flags"), "{err}");
    }

    #[test]
    fn stored_texels_keep_seven_mantissa_bits() {
        for v in [0.0f32, 1e-7, 0.3, 1.0, 1234.5, 65504.0, 1e9, f32::NAN, -2.0] {
            let t = super::super::texel_value(v);
            assert!(t.is_finite() && t.to_f32() >= 0.0, "{v} -> {t}");
            assert_eq!(t.to_bits() & 0b111, 0, "{v}");
            if v.is_finite() && v > 1e-4 && v < 65000.0 {
                assert!((t.to_f32() / v - 1.0).abs() <= 1.0 / 256.0 + 1e-3, "{v} -> {t}");
            }
        }
    }
}
