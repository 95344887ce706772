//! `ghosts.wgsl` on the CPU: the instanced ghost sprites into the HDR accumulation, and the per-ghost moments
//! of the same fragments.

use rayon::prelude::*;

use super::quads::{accumulation_scale, covered};
use crate::aperture::ApertureMask;
use crate::color::luminance;
use crate::image::{GhostMoments, HdrImage};
use crate::render::{FlareScene, GhostInstance};

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
