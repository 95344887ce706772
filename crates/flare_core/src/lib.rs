//! FlareLab's rendering core, with no UI dependency: tested headless, used by the app and the command line.
//!
//! # How it works
//! [`optics`] is the foundation: a lens prescription, its files, exact f64 ray tracing and the paraxial
//! ray-transfer matrices of every ghost path. [`ghost`] turns those matrices into one sprite per ghost and
//! wavelength (with [`coating`] reflectances, [`spectrum`] colours and the [`aperture`] shape); [`starburst`]
//! diffracts the aperture; [`render`] draws it all with wgpu (WGSL in `shaders/`) or its CPU twin; [`flare`]
//! ties a lens and its settings into something that renders any light position. [`raytrace`] is the other
//! family: ghosts ray-traced exactly on a grid (the ground-truth reference, and Hullin 2011's ray grids), and
//! [`metrics`] measures any image against the reference. All numerics are f64 on the
//! CPU; every singular case (total internal reflection, a ray missing a surface, a flat surface, an afocal
//! lens, a ghost focused to a point) is an explicit outcome or a bounded value, never a NaN, and only
//! finite values reach GPU buffers.

pub mod aperture;
pub mod coating;
pub mod color;
pub mod files;
pub mod fingerprint;
pub mod flare;
pub mod frame;
pub mod ghost;
pub mod image;
pub mod lut;
pub mod metrics;
pub mod optics;
pub mod output;
pub mod preset;
pub mod raytrace;
pub mod render;
pub mod spectrum;
pub mod starburst;
