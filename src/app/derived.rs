//! What the app derives from the document, kept apart from the UI: what a frame was built from (a new frame
//! is built only when it changes), how often anything was rebuilt, and the ghost list of a frame.

use flare_core::frame::FrameRequest;
use flare_core::ghost::{GhostFrame, GhostSystem};

use crate::panels::GhostRow;

/// How often the app rebuilt what the document implies, for the tests and the status bar: display settings
/// (exposures, tonemap, starburst, plate exposure) must change only `frames`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RebuildCounts {
    /// Prepared flares built (ghost system, aperture mask, starburst FFT).
    pub optics: u64,
    /// GPU texture uploads (aperture, starburst, plate, LUT atlas).
    pub textures: u64,
    /// Frames built.
    pub frames: u64,
}

/// What the latest frame was built from: a new frame is built only when this changes.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameKey {
    pub optics: u64,
    pub request: FrameRequest,
    pub lut_generation: u64,
    pub plate_generation: u64,
}

/// The ghost list of a frame: each ghost's light summed over its wavelengths, and why it is culled.
pub fn ghost_rows(system: &GhostSystem, frame: &GhostFrame) -> Vec<GhostRow> {
    let mut rows: Vec<GhostRow> = system
        .ghosts
        .iter()
        .enumerate()
        .map(|(ghost, m)| GhostRow { ghost, i: m.i, j: m.j, rgb: [0.0; 3], culled: Some("no sprite") })
        .collect();
    for s in &frame.sprites {
        let row = &mut rows[s.ghost];
        for c in 0..3 {
            row.rgb[c] += s.rgb[c];
        }
        row.culled = match (row.culled, s.culled) {
            (_, None) => None,
            (None, Some(_)) => None,
            (Some("no sprite"), Some(r)) => Some(r.word()),
            (other, Some(_)) => other,
        };
    }
    rows
}
