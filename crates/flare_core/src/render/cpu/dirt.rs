//! `dirt.wgsl` on the CPU: the front dirt's glow ([`crate::dirt`]) evaluated per accumulation pixel, additive.

use rayon::prelude::*;

use super::quads::accumulation_scale;
use crate::dirt::{PreparedDirt, sample_map};
use crate::image::HdrImage;
use crate::render::FlareScene;

/// The glow at the image pixel `pixel` (f32, as the shader computes it), before it is added.
pub fn dirt_glow_at(scene: &FlareScene, map: &[f32], size: usize, pixel: [f32; 2]) -> [f32; 3] {
    let g = &scene.globals;
    let ([lx, ly], [usx, usy]) = (g.dirt_light_px, g.dirt_light_slopes);
    let [a00, a01, a10, a11] = g.dirt_slopes_per_px;
    let [j00, j01, j10, j11] = g.dirt_footprint;
    let (hg_g, per_mm2, inv_ns) = (g.dirt_g, g.dirt_per_mm2, g.dirt_inv_ns);
    let ([r, gr, b], norm) = (g.dirt_power_rgb, g.dirt_hg_norm);
    let p = [pixel[0] - lx, pixel[1] - ly];
    let du = [a00 * p[0] + a01 * p[1], a10 * p[0] + a11 * p[1]];
    let u = [usx + du[0], usy + du[1]];
    let n_u = (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
    // 1 - cos(alpha) = |v - v_s|^2 / 2 with v = (u, 1) / |(u, 1)|: no cancellation near the light.
    let d = [u[0] / n_u - usx * inv_ns, u[1] / n_u - usy * inv_ns, 1.0 / n_u - inv_ns];
    let q = (1.0 - hg_g) * (1.0 - hg_g) + hg_g * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    let lobe = norm / (q * q.sqrt());
    let jacobian = per_mm2 / (n_u * n_u * n_u);
    let [cx, cy] = g.dirt_centre_texels;
    let t = [cx + j00 * du[0] + j01 * du[1], cy + j10 * du[0] + j11 * du[1]];
    let share = sample_map(map, size, t[0], t[1]);
    let k = lobe * jacobian * share;
    [r * k, gr * k, b * k]
}

/// `dirt.wgsl`: the glow of `dirt` added onto `hdr` (nothing when the scene places none).
pub fn dirt_pass(scene: &FlareScene, dirt: Option<&PreparedDirt>, hdr: &mut HdrImage) {
    let Some(dirt) = dirt.filter(|_| scene.has_dirt_glow()) else { return };
    let (sx, sy) = accumulation_scale(scene);
    let w = hdr.width as usize;
    hdr.pixels.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let pixel = [(x as f32 + 0.5) * sx, (y as f32 + 0.5) * sy];
            let c = dirt_glow_at(scene, &dirt.map, dirt.size, pixel);
            for k in 0..3 {
                px[k] += c[k];
            }
        }
    });
}
