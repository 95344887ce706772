//! `starburst.wgsl` on the CPU: the aperture's diffraction texture on a quad at the light's image, additive.

use super::quads::{accumulation_scale, covered};
use crate::image::HdrImage;
use crate::render::FlareScene;
use crate::starburst::Starburst;

/// Starburst texture as the GPU holds it: RGBA rounded to half floats.
#[derive(Clone, Debug, PartialEq)]
pub struct StarburstTexture {
    pub image: HdrImage,
}

impl StarburstTexture {
    pub fn from_starburst(s: &Starburst) -> Self {
        let pixels = s.rgba.iter().map(|t| t.map(|v| half::f16::from_f32(v).to_f32())).collect();
        Self { image: HdrImage { width: s.size as u32, height: s.size as u32, pixels } }
    }
}

/// `starburst.wgsl`: the starburst quad added onto `hdr`.
pub fn starburst_pass(scene: &FlareScene, texture: &StarburstTexture, hdr: &mut HdrImage) {
    let [cx, cy, half, intensity] = scene.globals.starburst;
    if half <= 0.0 || intensity == 0.0 {
        return;
    }
    let (w, h) = (hdr.width as usize, hdr.height as usize);
    let (sx, sy) = accumulation_scale(scene);
    for y in covered(cy, half, sy, h) {
        for x in covered(cx, half, sx, w) {
            let q = [((x as f32 + 0.5) * sx - cx) / half, ((y as f32 + 0.5) * sy - cy) / half];
            if q[0].abs() > 1.0 || q[1].abs() > 1.0 {
                continue;
            }
            let t = texture.image.sample_bilinear(q[0] * 0.5 + 0.5, q[1] * 0.5 + 0.5);
            let p = &mut hdr.pixels[y * w + x];
            for c in 0..3 {
                p[c] += t[c] * intensity;
            }
        }
    }
}
