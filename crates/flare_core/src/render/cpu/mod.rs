//! The CPU twin of the GPU renderer: one file beside each shader, the same passes, the same names, the same
//! steps as `shaders/*.wgsl`.
//!
//! # How it works
//! `ghosts::ghost_pass_direct` (the tests' oracle) is `ghosts.wgsl` step for step: for each instance it visits the pixels whose
//! centres fall inside the quad, recovers the quad coordinate q, multiplies the aperture mask (bilinear, 0
//! outside [-1, 1]^2, at the resolution the stop map names: [`ghosts::GhostMasks`]) at every enabled stop
//! crossing and the anti-aliased front disc, and adds the colour.
//! [`ghosts::ghost_pass`] draws the same image for a fraction of the work (what every caller uses): per row of
//! a sprite, the span where every mask is exactly 1 is added in O(1) to a difference buffer and only its
//! edges are shaded as above (a test holds the two within 0.2/255). [`ghosts::ghost_moments`] walks the
//! direct pass's fragments to measure each ghost's energy and centroid for the metrics. [`starburst::starburst_pass`] is `starburst.wgsl`, [`dirt::dirt_pass`] is `dirt.wgsl` (the front dirt's glow) and `tonemap::tonemap_pass` is `tonemap.wgsl`
//! (the composite of the exposed flare and plate, the tonemap, sRGB). [`ghosts::ghost_pass`] is also the twin of
//! the compute pass `ghosts_compute.wgsl` (its `spans` is [`ghosts::ghost_pass`]'s sweep of one sprite's row,
//! its `resolve` the per-row sum). `lut_ghosts.wgsl`'s and `lut_compute.wgsl`'s twin,
//! [`crate::lut::blend::lut_pass`], lives beside the LUT instances it draws. The GPU accumulates in half floats
//! and the CPU in f32; the comparison tests bound the difference. The twin also renders on machines with no GPU
//! adapter at all (`flarelab render --device cpu`).

pub mod dirt;
pub mod ghosts;
pub(crate) mod quads;
pub mod starburst;
pub mod tonemap;

pub use dirt::dirt_pass;

pub use ghosts::{ghost_moments, ghost_pass};
pub use starburst::StarburstTexture;
pub use starburst::starburst_pass;
pub(crate) use tonemap::tonemap_pass;
pub use tonemap::{composite, flare_layer, plate_layer, tonemap_pixel};
