//! Where a quad lands on the accumulation grid: shared by the ghost and starburst passes (the rasteriser's
//! job on the GPU).

use crate::render::FlareScene;

/// Image-pixel coordinates per accumulation pixel, horizontally and vertically.
pub(crate) fn accumulation_scale(scene: &FlareScene) -> (f32, f32) {
    (scene.width as f32 / scene.hdr_width as f32, scene.height as f32 / scene.hdr_height as f32)
}

/// The accumulation pixels a quad of centre `c` and half-size `half` (image pixels) covers.
pub(crate) fn covered(c: f32, half: f32, scale: f32, size: usize) -> std::ops::Range<usize> {
    let lo = ((c - half.abs()) / scale).floor().max(0.0) as usize;
    let hi = (((c + half.abs()) / scale).ceil().max(0.0) as usize).min(size);
    lo..hi
}
