//! The CPU twin of the GPU renderer: the same passes, the same names, the same steps as `shaders/*.wgsl`.
//!
//! # How it works
//! [`ghost_pass`] is `ghosts.wgsl`: for each instance it visits the pixels whose centres fall inside the
//! quad, recovers the quad coordinate q, multiplies the aperture mask (bilinear, 0 outside [-1, 1]^2) at every
//! enabled stop crossing and the anti-aliased front disc, and adds the colour. [`starburst_pass`] is
//! `starburst.wgsl` and [`tonemap_pass`] is `tonemap.wgsl`. The GPU accumulates in half floats and the CPU in
//! f32; the comparison test bounds the mean difference. The twin also renders on machines with no GPU
//! adapter at all (`flarelab render --device cpu`).

use super::{DisplayImage, FlareScene, HdrImage};
use crate::aperture::ApertureMask;
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

fn stop_mask(mask: &ApertureMask, map: [f32; 4], q: [f32; 2]) -> f32 {
    if map[3] == 0.0 {
        return 1.0;
    }
    mask.sample(map[0] * q[0] + map[1], map[0] * q[1] + map[2])
}

fn front_mask(map: [f32; 4], q: [f32; 2]) -> f32 {
    let r = (map[0] * q[0] + map[1]).hypot(map[0] * q[1] + map[2]);
    (0.5 + (1.0 - r) / map[3]).clamp(0.0, 1.0)
}

/// Image-pixel coordinates per accumulation pixel, horizontally and vertically.
fn accumulation_scale(scene: &FlareScene) -> (f32, f32) {
    (scene.width as f32 / scene.hdr_width as f32, scene.height as f32 / scene.hdr_height as f32)
}

/// The accumulation pixels a quad of centre `c` and half-size `half` (image pixels) covers.
fn covered(c: f32, half: f32, scale: f32, size: usize) -> std::ops::Range<usize> {
    let lo = ((c - half.abs()) / scale).floor().max(0.0) as usize;
    let hi = (((c + half.abs()) / scale).ceil().max(0.0) as usize).min(size);
    lo..hi
}

/// `ghosts.wgsl`: every instance into a cleared HDR accumulation image (`hdr_width` x `hdr_height`).
pub fn ghost_pass(scene: &FlareScene, mask: &ApertureMask) -> HdrImage {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let (sx, sy) = accumulation_scale(scene);
    let mut pixels = vec![[0.0f32; 4]; w * h];
    for inst in &scene.instances {
        let [cx, cy, hx, hy] = inst.centre_half;
        for y in covered(cy, hy, sy, h) {
            for x in covered(cx, hx, sx, w) {
                // The accumulation pixel's centre, in image pixels.
                let q = [((x as f32 + 0.5) * sx - cx) / hx, ((y as f32 + 0.5) * sy - cy) / hy];
                if q[0].abs() > 1.0 || q[1].abs() > 1.0 {
                    continue;
                }
                // The front disc first: outside it nothing passes, and the aperture lookups are skipped.
                let front = front_mask(inst.front, q);
                if front <= 0.0 {
                    continue;
                }
                let m = front
                    * stop_mask(mask, inst.stops[0], q)
                    * stop_mask(mask, inst.stops[1], q)
                    * stop_mask(mask, inst.stops[2], q);
                let p = &mut pixels[y * w + x];
                for c in 0..3 {
                    p[c] += inst.colour[c] * m;
                }
            }
        }
    }
    HdrImage { width: scene.hdr_width, height: scene.hdr_height, pixels }
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

fn aces(x: f32) -> f32 {
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

fn encode_srgb(c: f32) -> f32 {
    if c <= 0.0031308 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

/// `tonemap.wgsl` for one linear HDR value: exposure, operator, clamp, sRGB encode.
pub fn tonemap_pixel(c: [f32; 3], globals: &super::Globals) -> [f32; 3] {
    let [exposure, operator, encode, _] = globals.tonemap;
    c.map(|v| {
        let mut v = (v * exposure).max(0.0);
        if operator > 1.5 {
            v = aces(v);
        } else if operator > 0.5 {
            v /= 1.0 + v;
        }
        v = v.clamp(0.0, 1.0);
        if encode > 0.5 { encode_srgb(v) } else { v }
    })
}

/// The first step of `tonemap.wgsl`: the HDR accumulation (bilinear, upsampled to the image size) plus the
/// optional background plate (nearest sample), linear and before the exposure. The EXR output is this times
/// the exposure.
pub fn composite(scene: &FlareScene, hdr: &HdrImage, background: Option<&HdrImage>) -> HdrImage {
    let (w, h) = (scene.width as usize, scene.height as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (s, t) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            let mut p = hdr.sample_bilinear(s, t);
            if let Some(bg) = background {
                let b = bg.sample_nearest(s, t);
                for k in 0..3 {
                    p[k] += b[k];
                }
            }
            pixels.push(p);
        }
    }
    HdrImage { width: scene.width, height: scene.height, pixels }
}

/// `tonemap.wgsl`: [`composite`], then exposure, tonemap and sRGB into 8-bit display pixels.
pub fn tonemap_pass(scene: &FlareScene, hdr: &HdrImage, background: Option<&HdrImage>) -> DisplayImage {
    let linear = composite(scene, hdr, background);
    let pixels = linear
        .pixels
        .iter()
        .map(|p| {
            let t = tonemap_pixel([p[0], p[1], p[2]], &scene.globals);
            [to_u8(t[0]), to_u8(t[1]), to_u8(t[2]), 255]
        })
        .collect();
    DisplayImage { width: scene.width, height: scene.height, pixels }
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// The whole frame on the CPU: ghosts, starburst, then (for display) tonemapping.
pub fn render_hdr(scene: &FlareScene, mask: &ApertureMask, starburst: Option<&StarburstTexture>) -> HdrImage {
    let mut hdr = ghost_pass(scene, mask);
    if let Some(texture) = starburst {
        starburst_pass(scene, texture, &mut hdr);
    }
    hdr
}
