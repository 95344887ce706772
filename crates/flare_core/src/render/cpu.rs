//! The CPU twin of the GPU renderer: the same passes, the same names, the same steps as `shaders/*.wgsl`.
//!
//! # How it works
//! [`ghost_pass`] is `ghosts.wgsl`: for each instance it visits the pixels whose centres fall inside the
//! quad, recovers the quad coordinate q, multiplies the aperture mask (bilinear, 0 outside [-1, 1]^2) at every
//! enabled stop crossing and the anti-aliased front disc, and adds the colour. [`starburst_pass`] is
//! `starburst.wgsl` and [`tonemap_pass`] is `tonemap.wgsl`. [`ghost_moments`] walks the same fragments to measure
//! each ghost's energy and centroid for the metrics. The GPU accumulates in half floats and the CPU in
//! f32; the comparison test bounds the mean difference. The twin also renders on machines with no GPU
//! adapter at all (`flarelab render --device cpu`).

use rayon::prelude::*;

use super::{FlareScene, GhostInstance};
use crate::aperture::ApertureMask;
use crate::color::{display_value, luminance, to_u8};
use crate::image::{DisplayImage, GhostMoments, HdrImage, Sampling};
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
    let (x, y) = (map[0] * q[0] + map[1], map[0] * q[1] + map[2]);
    let r = (x * x + y * y).sqrt();
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

/// The fragments of one instance in the accumulation rows `rows`: `fragment(x, y, m)` for every covered pixel
/// with the mask product m > 0, exactly as `ghosts.wgsl` shades them.
fn shade_instance(
    inst: &GhostInstance,
    mask: &ApertureMask,
    open_radius: f32,
    scale: (f32, f32),
    size: (usize, usize),
    rows: std::ops::Range<usize>,
    mut fragment: impl FnMut(usize, usize, f32),
) {
    let [cx, cy, hx, hy] = inst.centre_half;
    // A mask whose whole quad maps inside its fully open disc is 1 everywhere (a speed-up only): skip it.
    let reach = |map: [f32; 4]| (map[1].abs() + map[0].abs()).hypot(map[2].abs() + map[0].abs());
    let mut inst = *inst;
    for stop in &mut inst.stops {
        if stop[3] != 0.0 && reach(*stop) <= open_radius {
            stop[3] = 0.0;
        }
    }
    let front_open = reach(inst.front) <= 1.0 - 0.5 * inst.front[3];
    let inst = &inst;
    let (sx, sy) = scale;
    let covered_rows = covered(cy, hy, sy, size.1);
    let columns = covered(cx, hx, sx, size.0);
    for y in covered_rows.start.max(rows.start)..covered_rows.end.min(rows.end) {
        // Where in this row the masks can be non-zero (a speed-up only: the skipped pixels would shade to exactly
        // 0, and a margin of a pixel keeps rounding on the safe side).
        let Some((q_lo, q_hi)) = row_support(inst, ((y as f32 + 0.5) * sy - cy) / hy) else { continue };
        let to_column = |q: f32| (cx + q * hx) / sx - 0.5;
        let (a, b) = (to_column(q_lo), to_column(q_hi));
        let first = (a.min(b).floor() - 1.0).max(columns.start as f32) as usize;
        let last = ((a.max(b).ceil() + 2.0).max(0.0) as usize).min(columns.end);
        for x in first..last {
            // The accumulation pixel's centre, in image pixels.
            let q = [((x as f32 + 0.5) * sx - cx) / hx, ((y as f32 + 0.5) * sy - cy) / hy];
            if q[0].abs() > 1.0 || q[1].abs() > 1.0 {
                continue;
            }
            // The front disc first: outside it nothing passes, and the aperture lookups are skipped.
            let front = if front_open { 1.0 } else { front_mask(inst.front, q) };
            if front <= 0.0 {
                continue;
            }
            let mut m = front;
            for stop in &inst.stops {
                if m <= 0.0 {
                    break;
                }
                m *= stop_mask(mask, *stop, q);
            }
            if m > 0.0 {
                fragment(x, y, m);
            }
        }
    }
}

/// The interval of the quad coordinate q_x in which a row at `q_y` can have light: inside the quad, the front
/// disc (grown by its anti-aliasing half-width) and the mask square [-1, 1]^2 of every stop crossing; `None`
/// when the row has none.
fn row_support(inst: &GhostInstance, q_y: f32) -> Option<(f32, f32)> {
    if q_y.abs() > 1.0 {
        return None;
    }
    let (mut lo, mut hi) = (-1.0f32, 1.0f32);
    // An affine coordinate `scale q + offset` within [-reach, reach].
    let mut clip = |scale: f32, offset: f32, reach: f32| {
        if scale == 0.0 {
            return offset.abs() <= reach;
        }
        let (a, b) = ((-reach - offset) / scale, (reach - offset) / scale);
        lo = lo.max(a.min(b));
        hi = hi.min(a.max(b));
        true
    };
    let [scale, ox, oy, aa] = inst.front;
    let reach = 1.0 + 0.5 * aa;
    let fy = scale * q_y + oy;
    if fy.abs() > reach || !clip(scale, ox, (reach * reach - fy * fy).max(0.0).sqrt()) {
        return None;
    }
    for [scale, ox, oy, enabled] in inst.stops {
        if enabled != 0.0 && ((scale * q_y + oy).abs() > 1.0 || !clip(scale, ox, 1.0)) {
            return None;
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Rows per parallel band of the CPU ghost pass.
const BAND_ROWS: usize = 16;

/// `ghosts.wgsl`: every instance into a cleared HDR accumulation image (`hdr_width` x `hdr_height`). Bands of
/// rows run in parallel (rayon); each pixel still sums the instances in order, so the result does not depend
/// on the thread count.
pub fn ghost_pass(scene: &FlareScene, mask: &ApertureMask) -> HdrImage {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let scale = accumulation_scale(scene);
    let open_radius = mask.open_radius();
    let mut pixels = vec![[0.0f32; 4]; w * h];
    pixels.par_chunks_mut(w * BAND_ROWS).enumerate().for_each(|(band, chunk)| {
        let y0 = band * BAND_ROWS;
        let rows = y0..(y0 + BAND_ROWS).min(h);
        for inst in &scene.instances {
            shade_instance(inst, mask, open_radius, scale, (w, h), rows.clone(), |x, y, m| {
                let p = &mut chunk[(y - y0) * w + x];
                for (value, colour) in p.iter_mut().zip(inst.colour).take(3) {
                    *value += colour * m;
                }
            });
        }
    });
    HdrImage { width: scene.hdr_width, height: scene.hdr_height, pixels }
}

/// Per ghost (`ghosts` of them), the luminance-weighted energy [`ghost_pass`] draws in the frame and its
/// first moments in image pixels: what the metrics compare with the reference's ghosts.
pub fn ghost_moments(scene: &FlareScene, mask: &ApertureMask, ghosts: usize) -> Vec<GhostMoments> {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let (sx, sy) = accumulation_scale(scene);
    let mut moments = vec![GhostMoments::default(); ghosts];
    let open_radius = mask.open_radius();
    for (inst, &g) in scene.instances.iter().zip(&scene.instance_ghosts) {
        let luma = luminance([inst.colour[0], inst.colour[1], inst.colour[2]].map(f64::from));
        // Each accumulation pixel stands for sx x sy image pixels.
        let area = f64::from(sx * sy);
        shade_instance(inst, mask, open_radius, (sx, sy), (w, h), 0..h, |x, y, m| {
            let p = [(x as f64 + 0.5) * f64::from(sx), (y as f64 + 0.5) * f64::from(sy)];
            moments[g as usize].add_sample(luma * f64::from(m) * area, p);
        });
    }
    moments
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

/// `tonemap.wgsl` for one composite value (flare and plate already multiplied by their gains): the operator,
/// a clamp and the sRGB encoding.
pub fn tonemap_pixel(c: [f32; 3], globals: &super::Globals) -> [f32; 3] {
    let encode = globals.tonemap[2] > 0.5;
    c.map(|v| display_value(v, globals.operator(), encode))
}

/// The first step of `tonemap.wgsl`: the composite `flare * 2^flare_ev + plate * 2^plate_ev` at the image
/// size, the HDR accumulation read bilinearly (upsampled when it is smaller) and the plate at its nearest
/// texel, linear.
pub fn composite(scene: &FlareScene, hdr: &HdrImage, plate: Option<&HdrImage>) -> HdrImage {
    let flare = flare_layer(scene, hdr);
    match plate {
        Some(plate) => flare.plus(&plate_layer(scene, plate)),
        None => flare,
    }
}

/// The flare alone at the image size, times its gain (what the EXR's `flare` layer holds).
pub fn flare_layer(scene: &FlareScene, hdr: &HdrImage) -> HdrImage {
    hdr.resampled(scene.width, scene.height, Sampling::Bilinear, scene.globals.flare_gain())
}

/// The plate at the image size, times its gain (what the EXR's `plate` layer holds).
pub fn plate_layer(scene: &FlareScene, plate: &HdrImage) -> HdrImage {
    let mut layer = plate.resampled(scene.width, scene.height, Sampling::Nearest, scene.globals.plate_gain());
    for p in &mut layer.pixels {
        p[3] = 1.0;
    }
    layer
}

/// `tonemap.wgsl`: [`composite`], then tonemap and sRGB into 8-bit display pixels.
pub fn tonemap_pass(scene: &FlareScene, hdr: &HdrImage, plate: Option<&HdrImage>) -> DisplayImage {
    display_of(scene, &composite(scene, hdr, plate))
}

/// The display image of a composite already at the image size.
pub fn display_of(scene: &FlareScene, composite: &HdrImage) -> DisplayImage {
    let pixels = composite
        .pixels
        .iter()
        .map(|p| {
            let t = tonemap_pixel([p[0], p[1], p[2]], &scene.globals);
            [to_u8(t[0]), to_u8(t[1]), to_u8(t[2]), 255]
        })
        .collect();
    DisplayImage { width: scene.width, height: scene.height, pixels }
}

/// The whole frame on the CPU: ghosts, starburst, then (for display) tonemapping.
pub fn render_hdr(scene: &FlareScene, mask: &ApertureMask, starburst: Option<&StarburstTexture>) -> HdrImage {
    let mut hdr = ghost_pass(scene, mask);
    if let Some(texture) = starburst {
        starburst_pass(scene, texture, &mut hdr);
    }
    hdr
}
