//! Optics: lenses, their files, dispersion, light paths, exact tracing and paraxial matrices.
//!
//! # How it works
//! [`lens`] holds the prescription and its one sign convention; [`formats`] reads and writes it (JSON,
//! Zemax .zmx, pbrt .dat); [`glass`] gives each medium's index per wavelength, from catalogues read by
//! [`agf`]; [`path`] lists the surface
//! interactions of the image and of every ghost; [`trace`] follows real rays along a path exactly, and
//! [`paraxial`] multiplies the 2x2 matrices of the same path. [`mapping`] traces chief rays to map a light's
//! direction to where it images (and back, for tracked pixels); [`sensor`] writes the frame convention down
//! once. [`library`] embeds the shipped lenses. [`tolerance`] loads a prescription whose guessed clear apertures
//! cross, clipped where that is harmless, with a warning.

pub mod agf;
pub mod formats;
pub mod glass;
pub mod lens;
pub mod library;
pub mod mapping;
pub mod paraxial;
pub mod path;
pub mod sensor;
pub mod tolerance;
pub mod trace;

pub use glass::D_LINE_NM;
pub use lens::{Coating, CoatingLayer, Lens, LensError, Medium, Section, Surface};
pub use paraxial::Mat2;
pub use paraxial::{EntrancePupil, FirstOrder, ParaxialError, PathMatrices};
pub use path::{Interaction, Step};
pub use path::{LightPath, PathKind};
#[cfg(target_arch = "x86_64")]
pub(crate) use trace::simd_level;
pub(crate) use trace::table_at;
pub use trace::{Landing, Ray, TraceOptions, TraceResult, TraceStatus, Tracer, pupil_ray};
pub use trace::{StepHit, VertexRecipe, VertexRecord};
