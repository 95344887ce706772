//! `starburst.wgsl` on the CPU: the light's diffraction evaluated per pixel out to its reach, additive.

use rayon::prelude::*;

use super::quads::{accumulation_scale, covered};
use crate::image::HdrImage;
use crate::render::{FlareScene, STARBURST_MAX};
use crate::starburst::Starburst;

/// The starburst's angular profile as the GPU holds it: rounded to half floats.
#[derive(Clone, Debug, PartialEq)]
pub struct StarburstTexture {
    pub profile: Vec<f32>,
}

impl StarburstTexture {
    pub fn from_starburst(s: &Starburst) -> Self {
        Self { profile: s.profile.iter().map(|v| half::f16::from_f32(*v).to_f32()).collect() }
    }
}

/// `starburst.wgsl`: the starburst added onto `hdr`.
pub fn starburst_pass(scene: &FlareScene, texture: &StarburstTexture, hdr: &mut HdrImage) {
    let [cx, cy, reach, core_px] = scene.globals.starburst;
    if reach <= 0.0 {
        return;
    }
    let [kr, kg, kb, mm_per_px] = scene.globals.starburst_far;
    let core = scene.globals.starburst_core;
    let (w, h) = (hdr.width as usize, hdr.height as usize);
    // An anamorphic lens's far field is stretched along x by N_x / N_y (1 for a lens of revolution).
    let stretch = if core[3] > 0.0 { core[3] } else { 1.0 };
    let (sx, sy) = accumulation_scale(scene);
    let (rows, columns) = (covered(cy, reach, sy, h), covered(cx, reach * stretch.max(1.0), sx, w));
    // Rows in parallel: each pixel's sum is its own, so the image is the same on any number of threads.
    let band = &mut hdr.pixels[rows.start * w..rows.end * w];
    band.par_chunks_mut(w.max(1)).zip(rows).for_each(|(row, y)| {
        for x in columns.clone() {
            let (px, py) = ((x as f32 + 0.5) * sx - cx, (y as f32 + 0.5) * sy - cy);
            // The far field's own coordinates, in which it is the round pattern.
            let (dx, dy) = (px / stretch, py);
            let r_px = dx.hypot(dy);
            if r_px > reach {
                continue;
            }
            let c = if r_px < core_px {
                [core[0], core[1], core[2]]
            } else {
                let r_mm = r_px * mm_per_px;
                let p = Starburst::profile_at(&texture.profile, dx, dy) / (r_mm * r_mm * r_mm) / stretch;
                [kr * p, kg * p, kb * p]
            };
            let px = &mut row[x];
            for k in 0..3 {
                px[k] += c[k].min(STARBURST_MAX as f32);
            }
        }
    });
}
