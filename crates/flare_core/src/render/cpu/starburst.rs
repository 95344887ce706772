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
    if !scene.draws_starburst() {
        return;
    }
    let g = &scene.globals;
    let ([cx, cy], reach, core_px) = (g.starburst_centre_px, g.starburst_reach_px, g.starburst_core_px);
    let ([kr, kg, kb], mm_per_px) = (g.starburst_far_k, g.starburst_mm_per_px);
    let core = g.starburst_core_rgb;
    let (w, h) = (hdr.width as usize, hdr.height as usize);
    // An anamorphic lens's far field is stretched along x by N_x / N_y (1 for a lens of revolution).
    let stretch = if g.starburst_stretch_x > 0.0 { g.starburst_stretch_x } else { 1.0 };
    let (sx, sy) = accumulation_scale(scene);
    let (rows, columns) = (covered(cy, reach, sy, h), covered(cx, reach * stretch.max(1.0), sx, w));
    // A reach that ends short of the frame is an empty range whose start may lie past its end (or the frame).
    let rows = rows.start.min(rows.end)..rows.end;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flare::{FlareConfig, PreparedFlare};
    use crate::frame::{Frame, FrameRequest};
    use crate::optics::library::builtin_lens;

    /// A light whose starburst reaches the frame adds to it; one whose reach ends short of the frame on any side
    /// (its rows or columns an empty range, the first past the last) adds nothing and is no error.
    #[test]
    fn a_starburst_that_misses_the_frame_adds_nothing() {
        let flare = PreparedFlare::new(&builtin_lens("tessar").unwrap(), &FlareConfig::default()).unwrap();
        let frame = Frame::build(&flare, None, &FrameRequest { width: 64, height: 48, ..FrameRequest::default() });
        let (sx, sy) = accumulation_scale(&frame.scene);
        let (w, h) = (frame.scene.hdr_width as f32 * sx, frame.scene.hdr_height as f32 * sy);
        let lit = |cx: f32, cy: f32| {
            let mut scene = frame.scene.clone();
            (scene.globals.starburst_centre_px, scene.globals.starburst_reach_px) = ([cx, cy], 6.0);
            scene.globals.starburst_core_px = 1.0;
            let mut hdr = HdrImage::black(scene.hdr_width, scene.hdr_height);
            starburst_pass(&scene, &flare.starburst_texture, &mut hdr);
            hdr.pixels.iter().filter(|p| p[..3].iter().any(|&v| v > 0.0)).count()
        };
        assert!(lit(0.5 * w, 0.5 * h) > 0);
        for (cx, cy) in [(0.5 * w, 3.0 * h), (0.5 * w, -2.0 * h), (3.0 * w, 0.5 * h), (-2.0 * w, 0.5 * h)] {
            assert_eq!(lit(cx, cy), 0, "light at ({cx}, {cy})");
        }
    }
}
