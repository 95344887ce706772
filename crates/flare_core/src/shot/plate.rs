//! A frame's plate as every caller gets it: read from disk and, when the document's depth of field is on,
//! defocused through the flare's own lens and stop with that frame's depth map ([`crate::dof`]).
//!
//! # How it works
//! [`frame_plate`] reads the plate file ([`crate::output::read_plate_checked`], with what it clamped), and with the depth of field on reads
//! the frame's depth map ([`crate::preset::Document::depth_at`]: a file, or a sequence's file of the frame),
//! checks it against the plate and defocuses the plate on the CPU by the document's method (the live method's
//! CPU twin, or the reference). The command line's stills, sequences and the app all take their plate from
//! here, so a look renders the same everywhere. The flare is drawn over the result, unblurred.

use std::path::Path;

use crate::dof::{self, DofLens};
use crate::flare::PreparedFlare;
use crate::image::HdrImage;
use crate::output::read_plate_checked;
use crate::preset::Document;

/// Why a frame's plate could not be made: the plate file itself, or its depth of field (a bad depth map is
/// not the plate's fault). Each message says which file and why.
#[derive(Debug, Clone, PartialEq)]
pub enum FramePlateError {
    Plate(String),
    DepthOfField(String),
}

/// The plate at `path` for `frame` of `doc`, defocused when the document's depth of field is on, with what
/// reading it clamped (to be said once).
pub fn frame_plate(
    doc: &Document,
    flare: &PreparedFlare,
    frame: i64,
    path: &Path,
) -> Result<(HdrImage, Option<String>), FramePlateError> {
    let (plate, warning) = read_plate_checked(path).map_err(|e| FramePlateError::Plate(e.to_string()))?;
    // With the depth of field off the plate is handed on as read (no copy of a frame per frame).
    if !doc.dof.enabled {
        return Ok((plate, warning));
    }
    let defocused = defocus(doc, flare, frame, &plate).map_err(FramePlateError::DepthOfField)?;
    Ok((defocused, warning))
}

/// `plate` defocused as `doc`'s depth of field says for `frame` (unchanged when it is off).
pub fn defocus(doc: &Document, flare: &PreparedFlare, frame: i64, plate: &HdrImage) -> Result<HdrImage, String> {
    if !doc.dof.enabled {
        return Ok(plate.clone());
    }
    let depth = doc.depth_at(frame).ok_or("the depth of field is on and has no depth map")?;
    dof::defocus_plate(&doc.dof, dof_lens(doc, flare), &depth, plate).map_err(|e| format!("depth of field: {e}"))
}

/// The lens, stop, sensor and aperture shape the depth of field shares with the flare.
pub fn dof_lens<'a>(doc: &'a Document, flare: &'a PreparedFlare) -> DofLens<'a> {
    DofLens {
        lens: &flare.system.lens,
        stop_scale: flare.system.settings.stop_scale,
        sensor_width_mm: doc.sensor_width_mm,
        mask: &flare.mask,
    }
}
