//! Shots: a light that moves over many frames, plates read per frame, the light found in the plate, and
//! sequences rendered through the one frame pipeline.
//!
//! # How it works
//! A shot is a document ([`crate::preset::Document`]) with a [`crate::timeline::Timeline`] and, when it has a
//! plate, a plate per frame ([`crate::footage::pattern::FramePattern`]: `shot.####.exr` or `shot.%04d.exr`). Where the light
//! is on each frame comes from one of three places, in this order: the light found in the plate
//! ([`crate::footage::detect`], when the document asks for it), the timeline's light keys (typed in the app or imported from
//! a tracker's CSV, [`track`]), or the document's static light. [`plan`] works that out for every frame of a
//! range before anything is drawn ([`FramePlan`]: light angle, light pixel, gain, visibility, plate file);
//! [`sequence`] then draws each planned frame with [`crate::frame`] and writes it with the one writer.
//! [`plate`] gives every caller a frame's plate, defocused when the document's depth of field is on.
//! [`synthetic`] makes a test shot (a sun crossing a sky, a bar crossing the sun) with its true track.

pub mod plan;
pub mod plate;
pub mod sequence;
pub mod synthetic;
pub mod track;

pub use plan::{FramePlan, ShotPlan};
