//! FlareLab's rendering core, with no UI dependency: tested headless, used by the app and the command line.
//!
//! # How it works
//! [`optics`] is the foundation: a lens prescription, its files, exact f64 ray tracing and the paraxial
//! ray-transfer matrices of every ghost path. All numerics are f64 on the CPU; every singular case (total
//! internal reflection, a ray missing a surface, a flat surface, an afocal lens) is an explicit outcome or
//! error, never a NaN.

pub mod aperture;
pub mod coating;
pub mod ghost;
pub mod optics;
pub mod spectrum;
pub mod starburst;
