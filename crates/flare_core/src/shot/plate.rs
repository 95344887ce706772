//! A frame's plate as every caller gets it: read from disk and, when the document's depth of field is on,
//! defocused through the flare's own lens and stop with that frame's depth map ([`crate::dof`]).
//!
//! # How it works
//! [`read_plate_in`] reads a plate file into the working space: by file type ([`crate::output::read_plate_checked`],
//! with what it clamped), or, when the document names an input space, the file's own values converted by OCIO
//! ([`crate::view_transform::ViewTransform::plate_to_working`]). [`frame_plate`] reads the frame's plate so, and with the depth of field on reads
//! the frame's depth map ([`crate::preset::Document::depth_at`]: a file, or a sequence's file of the frame),
//! checks it against the plate and defocuses the plate on the CPU by the document's method (the live method's
//! CPU twin, or the reference). The command line's stills, sequences and the app all take their plate from
//! here, so a look renders the same everywhere. The flare is drawn over the result, unblurred.

use std::path::Path;

use crate::dof::{self, DofLens};
use crate::flare::PreparedFlare;
use crate::image::HdrImage;
use crate::output::{read_plate_checked, read_plate_values};
use crate::preset::Document;
use crate::view_transform::{ColorDoc, ViewTransform};

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
    let (plate, warning) = read_plate_in(&doc.color, path).map_err(FramePlateError::Plate)?;
    // With the depth of field off the plate is handed on as read (no copy of a frame per frame).
    if !doc.dof.enabled {
        return Ok((plate, warning));
    }
    let defocused = defocus(doc, flare, frame, &plate).map_err(FramePlateError::DepthOfField)?;
    Ok((defocused, warning))
}

/// The plate file `path` in the working space as `color` says (see the module documentation), with what
/// reading it clamped; the message names the file and why it could not be read.
pub fn read_plate_in(color: &ColorDoc, path: &Path) -> Result<(HdrImage, Option<String>), String> {
    if color.input_space.is_none() {
        return read_plate_checked(path).map_err(|e| e.to_string());
    }
    let view = ViewTransform::cached(color).map_err(|e| format!("{}: {e}", path.display()))?;
    let (mut plate, warning) = read_plate_values(path, false).map_err(|e| e.to_string())?;
    view.plate_to_working(&mut plate);
    for p in &mut plate.pixels {
        for v in &mut p[..3] {
            // Negative values are kept: they are colours outside the working space's gamut, which the view
            // (or the inverse it came through) maps back.
            *v = v.clamp(-crate::output::MAX_PLATE_VALUE, crate::output::MAX_PLATE_VALUE);
        }
    }
    Ok((plate, warning))
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
        mask: flare.mask(),
    }
}
