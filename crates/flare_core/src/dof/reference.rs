//! The reference depth of field: every pixel's own kernel scattered into thin depth layers, composited far to
//! near with occlusion. Slow and exact for the 2.5D scene.
//!
//! # How it works
//! Each pixel's signed defocus ([`super::DofModel::defocus_px`]) orders it (far first). Consecutive pixels whose
//! defocus lies within [`LAYER_PX`] of the layer's first form a layer: within it, the pixels' kernels hardly
//! differ in size, and occlusion between them is ignored. Per layer, every pixel scatters its colour and its
//! coverage with its own kernel ([`super::kernel::raster`], the defocus quantised to 1/16 px and each cutting clear
//! aperture's circle to 1/32 of a pupil radius, so that the kernels of a layer are made once), into f64 sums, in parallel over bands
//! of target rows; the band is then composited over what is behind it ([`super::over`]). At the end the
//! composite is divided by its coverage ([`super::resolve`]). Light scattered beyond the frame is lost, as it is
//! on a sensor.

use std::collections::HashMap;

use rayon::prelude::*;

use super::kernel::{Cat, RasterKernel, raster_xy};
use super::model::{DofError, DofModel, defocus_map, over, resolve};
use crate::aperture::ApertureMask;
use crate::image::HdrImage;

/// The thickness of a layer in defocus (pixels).
pub const LAYER_PX: f64 = 0.5;
/// Rows of one band of the parallel scatter.
const BAND_ROWS: usize = 16;

/// A kernel's key: the defocus in 1/16 px, then each cutting clear aperture's region (centre and radius in 1/32
/// pupil radius, a radius beyond [`MAX_KEY_RADIUS`] pupil radii recorded as that; its x scale in 1/1024).
type Key = Vec<i64>;

/// The largest circle radius (pupil radii) a key records; a larger circle holds the unit pupil wherever its
/// centre is within `MAX_KEY_RADIUS - 1` of the axis, and a circle farther out than that cuts everything.
const MAX_KEY_RADIUS: f64 = 1e6;

fn key(model: &DofModel, sigma: f64, x: f64, y: f64, depth_mm: f64) -> Key {
    let mut key = vec![(sigma * 16.0).round() as i64];
    for cat in model.cat_eyes_at(x, y, depth_mm) {
        let [cx, cy] = cat.centre;
        key.extend([cx, cy, cat.radius.min(MAX_KEY_RADIUS)].map(|v| (v * 32.0).round() as i64));
        key.push((cat.x_scale * 1024.0).round() as i64);
    }
    key
}

fn kernel_of(key: &Key, model: &DofModel, mask: &ApertureMask) -> RasterKernel {
    let sigma = key[0] as f64 / 16.0;
    let cats: Vec<Cat> = key[1..]
        .chunks_exact(4)
        .map(|c| Cat {
            centre: [c[0] as f64 / 32.0, c[1] as f64 / 32.0],
            radius: c[2] as f64 / 32.0,
            x_scale: c[3] as f64 / 1024.0,
        })
        .collect();
    raster_xy(mask, model.mask_sign, [model.defocus_x_for(sigma), sigma], &cats)
}

/// The plate defocused by the reference method (see the module documentation); `depth_mm` per pixel from the
/// entrance pupil.
pub fn render(plate: &HdrImage, depth_mm: &[f64], model: &DofModel, mask: &ApertureMask) -> Result<HdrImage, DofError> {
    render_layers(plate, depth_mm, model, mask, LAYER_PX)
}

/// [`render`] with layers `layer_px` of defocus thick (thicker is faster and ignores more occlusion).
pub fn render_layers(
    plate: &HdrImage,
    depth_mm: &[f64],
    model: &DofModel,
    mask: &ApertureMask,
    layer_px: f64,
) -> Result<HdrImage, DofError> {
    render_until(plate, depth_mm, model, mask, layer_px, &std::sync::atomic::AtomicBool::new(false))
}

/// [`render_layers`] that stops between layers once `cancel` is set ([`DofError::Cancelled`]).
pub fn render_until(
    plate: &HdrImage,
    depth_mm: &[f64],
    model: &DofModel,
    mask: &ApertureMask,
    layer_px: f64,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<HdrImage, DofError> {
    super::model::check_size(plate, depth_mm, model)?;
    let sigma = defocus_map(model, depth_mm)?;
    let (w, h) = (plate.width as usize, plate.height as usize);
    let mut order: Vec<usize> = (0..w * h).collect();
    order.sort_by(|&a, &b| sigma[b].total_cmp(&sigma[a]));
    let mut out = vec![[0.0f32; 4]; w * h];
    let mut start = 0;
    while start < order.len() {
        if cancel.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(DofError::Cancelled);
        }
        let first = sigma[order[start]];
        let end = start + order[start..].partition_point(|&k| first - sigma[k] <= layer_px);
        let mut layer: Vec<(usize, Key)> = order[start..end]
            .iter()
            .map(|&k| {
                let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
                (k, key(model, sigma[k], x, y, depth_mm[k]))
            })
            .collect();
        layer.sort_unstable_by_key(|(k, _)| *k);
        scatter_layer(&layer, plate, model, mask, &mut out);
        start = end;
    }
    Ok(HdrImage { width: plate.width, height: plate.height, pixels: out.into_iter().map(resolve).collect() })
}

/// Scatters one layer's pixels (sorted by index, so by row) and composites it over `out`.
fn scatter_layer(
    layer: &[(usize, Key)],
    plate: &HdrImage,
    model: &DofModel,
    mask: &ApertureMask,
    out: &mut [[f32; 4]],
) {
    let w = plate.width as usize;
    let mut keys: Vec<&Key> = layer.iter().map(|(_, k)| k).collect();
    keys.sort_unstable();
    keys.dedup();
    let kernels: HashMap<&Key, RasterKernel> = keys.par_iter().map(|&k| (k, kernel_of(k, model, mask))).collect();
    let reach = kernels.values().map(|k| k.radius as usize).max().unwrap_or(0);
    out.par_chunks_mut(BAND_ROWS * w).enumerate().for_each(|(band, rows)| {
        let (y0, y1) = (band * BAND_ROWS, band * BAND_ROWS + rows.len() / w);
        // The pixels whose kernels can reach rows y0..y1.
        let from = layer.partition_point(|(k, _)| k / w + reach < y0);
        let to = layer.partition_point(|(k, _)| k / w < y1 + reach);
        if from >= to {
            return;
        }
        let mut sums = vec![[0.0f64; 4]; rows.len()];
        let mut touched = false;
        for (k, key) in &layer[from..to] {
            let (k, kernel) = (*k, &kernels[key]);
            let (sx, sy) = ((k % w) as i64, (k / w) as i64);
            let r = i64::from(kernel.radius);
            let side = (2 * r + 1) as usize;
            let p = plate.pixels[k];
            for ty in (sy - r).max(y0 as i64)..(sy + r + 1).min(y1 as i64) {
                let krow = &kernel.weights[(ty - sy + r) as usize * side..][..side];
                let row = &mut sums[(ty as usize - y0) * w..][..w];
                for tx in (sx - r).max(0)..(sx + r + 1).min(w as i64) {
                    let wgt = f64::from(krow[(tx - sx + r) as usize]);
                    if wgt == 0.0 {
                        continue;
                    }
                    let s = &mut row[tx as usize];
                    s[0] += wgt * f64::from(p[0]);
                    s[1] += wgt * f64::from(p[1]);
                    s[2] += wgt * f64::from(p[2]);
                    s[3] += wgt;
                    touched = true;
                }
            }
        }
        if touched {
            for (o, s) in rows.iter_mut().zip(sums) {
                if s[3] > 0.0 {
                    over(o, s.map(|v| v as f32));
                }
            }
        }
    });
}
