//! Footage: the plate's files and the light found in them, below the document that names them and the shots
//! that draw them.
//!
//! # How it works
//! [`pattern`] parses a sequence's file name (`shot.####.exr` or `shot.%04d.exr`) and lists the frames on disk;
//! [`detect`] finds the light in one linear plate and `detect::solve` turns a range of detections into one
//! light per frame (visibility, position). Both read only images and text: the document
//! ([`crate::preset::Document`]) holds their settings ([`pattern::FramePattern`], [`detect::AutoLight`]) and
//! [`crate::shot`] uses them frame by frame.

pub mod detect;
pub mod pattern;
