//! FlareLab's rendering core, with no UI dependency: tested headless, used by the app and the command line.
//!
//! # How it works
//! [`optics`] is the foundation: a lens prescription, its files, exact f64 ray tracing and the paraxial
//! ray-transfer matrices of every ghost path. [`ghost`] turns those matrices into one sprite per ghost and
//! wavelength (with [`coating`] reflectances, [`spectrum`] colours and the [`aperture`] shape); [`starburst`]
//! diffracts the aperture; [`flare`] prepares a lens and its optics settings once; [`exposure`] picks the flare's
//! exposure from the optics. [`preset`] is the document
//! the user edits (the app's and the command line's), [`frame`] the one pipeline every frame goes through
//! (request, frame, drawn by [`render`]'s wgpu renderer or its CPU twin, layers), and [`output`] the one image
//! writer. [`raytrace`] is the other family: ghosts ray-traced exactly on a grid (the ground-truth reference,
//! and Hullin 2011's ray grids, which [`render`]'s `raygrid` also traces and draws on the GPU, in f32, the f64
//! tracer its twin); [`lut`] holds the non-linear ones as LUTs blended at run time and [`bake`] bakes them; [`metrics`]
//! measures any image against the reference. [`timeline`] animates a document over frames and [`shot`] makes
//! a shot of it: plate sequences ([`footage`]), tracks, the light found in the plate, and sequences rendered frame by frame
//! through [`frame`]. [`dof`] defocuses the plate through the same lens and aperture from a depth map (an
//! exact layered reference and a live layered method that `render` also runs on the GPU) before the flare is
//! drawn over it. [`view_transform`] is the colour management (an OCIO config's display and view, its CPU
//! processor the twin of its shader) and [`view_lut`] that view baked into a cube for a software adapter's
//! drafts. [`color`], [`image`], [`files`] and [`fingerprint`] are the small
//! shared pieces (tonemaps and exposures in stops, images, atomic writes, stable hashes).
//!
//! # Layers
//! Every module (a file or a folder, a "room") sits in one layer, and imports only from its own layer and the
//! layers below; no two rooms import each other, directly or around a loop. `tests/architecture.rs` reads
//! this list and checks every import of the code against it:
//! 1. **Shared pieces**: [`color`], [`files`], [`fingerprint`], [`image`], [`timing`], [`metrics`],
//!    [`output`], [`ocio_files`].
//! 2. **Optics**: [`optics`], [`spectrum`], [`coating`], [`aperture`].
//! 3. **What the light does, and what is read for it**: [`ghost`], [`raytrace`], [`starburst`], [`dirt`],
//!    [`dof`], [`lut`], [`exposure`], [`report`], [`view_transform`], [`view_lut`], [`footage`].
//! 4. **Drawing**: [`render`] (the GPU renderer and its CPU twin; it knows scenes, never a lens or a document).
//! 5. **One frame**: [`flare`], [`shutter`], [`frame`], [`traced`], [`bake`].
//! 6. **The document and its shots**: [`timeline`], [`preset`], [`shot`].
//!
//! All numerics are f64 on the CPU; every singular case (total internal reflection, a ray missing a surface,
//! a flat surface, an afocal lens, a ghost focused to a point) is an explicit outcome or a bounded value, never
//! a NaN, and only finite values reach GPU buffers. The physics and the two patented methods are summed up in
//! `crates/flare_core/METHOD.md`.

pub mod aperture;
pub mod bake;
pub mod coating;
pub mod color;
pub mod dirt;
pub mod dof;
pub mod exposure;
pub mod files;
pub mod fingerprint;
pub mod flare;
pub mod footage;
pub mod frame;
pub mod ghost;
pub mod image;
pub mod lut;
pub mod metrics;
pub mod ocio_files;
pub mod optics;
pub mod output;
pub mod preset;
pub mod raytrace;
pub mod render;
pub mod report;
pub mod shot;
pub mod shutter;
pub mod spectrum;
pub mod starburst;
pub mod timeline;
pub mod timing;
pub mod traced;
pub mod view_lut;
pub mod view_transform;

// What callers need most, at the crate root: the document, the prepared optics, the frame pipeline and the
// writer. Everything else is reached through its module.
pub use flare::{FlareConfig, PreparedFlare};
pub use frame::{Device, Drawn, Frame, FrameLayers, FrameRequest, LayerChoice, LutUse, Sources};
pub use image::{DisplayImage, HdrImage};
pub use optics::Lens;

pub use output::{ImageKind, read_plate};
pub use preset::Document;
pub use render::DisplaySettings;
