//! The live depth of field: a few depth layers, each gathered at a resolution that keeps its kernel about
//! `TAPS_ACROSS` texels across, composited far to near. `render::dof_gpu` runs it in WGSL
//! (`shaders/dof.wgsl`); [`LivePlan::render_cpu`] is its twin, step for step in f32.
//!
//! # How it works
//! The CPU plans ([`LivePlan::new`]): every pixel's signed defocus, and layer centres spaced evenly over the
//! defocus range (at most `MAX_LAYERS`, at least 1 px apart; a layer no pixel reaches is dropped). A pixel
//! belongs to its two nearest layers with hat weights (`1 - |sigma - sigma_k| / spacing`, summing to 1), so no
//! band shows where one layer meets the next. A layer of defocus sigma_k is gathered at `1 / factor` of the
//! resolution, `factor = max(1, round(|sigma_k| / TAPS_ACROSS))`, over taps on its texel grid whose weights are
//! the kernel ([`super::kernel`]) averaged over 3 x 3 points of each tap's cell. Per layer, four steps (the
//! WGSL entry points of the same names):
//! 1. `split`: each pixel's premultiplied colour and coverage `(rgb w_k, w_k)` shared among its four nearest
//!    texels by tent weights (its light and its position kept), per texel area;
//! 2. `gather`: each texel sums its neighbours, each at the tap from it (scatter as gather: the weight is the
//!    kernel of the *source* texel, cut by the cat's eye at the source's position), times the source's
//!    normalisation, bilinear in a 17 x 17 table over the frame (the kernel's taps summed there);
//! 3. `composite`: every pixel samples the gathered layer bilinearly and puts it over what is behind
//!    ([`super::over`]);
//!
//! Each step runs only over the layer's region: the plan keeps the box of the layer's pixels, grown by the tent
//! (`low`, the texels the split can fill) and by the taps' reach (`out`, the texels its light can reach); the
//! composite covers the pixels those texels touch. A layer of a thin band of depths costs a thin band.
//! 4. after the nearest layer, `resolve` divides by the coverage ([`super::resolve`]).

use rayon::prelude::*;

use super::kernel::{Cat, pupil_point_xy, weight};
use super::model::{DofError, DofModel, defocus_map, over, resolve};
use crate::aperture::ApertureMask;
use crate::image::HdrImage;

/// Most layers a frame is split into (the default).
pub(crate) const MAX_LAYERS: usize = 24;
/// A layer's kernel spans about this many texels across at its resolution (the default).
pub(crate) const TAPS_ACROSS: f64 = 12.0;

/// The live method's speed against its error: how many layers at most, how many taps across a kernel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiveSettings {
    pub max_layers: usize,
    pub taps_across: f64,
}

impl Default for LiveSettings {
    fn default() -> Self {
        Self { max_layers: MAX_LAYERS, taps_across: TAPS_ACROSS }
    }
}
/// Cells of the normalisation table across the frame (nodes: one more).
pub(crate) const NORM_CELLS: usize = 16;

/// One layer of a plan. Must be kept in sync with `struct Layer` in `shaders/dof.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LiveLayer {
    /// Frame width, height; the layer's width, height (texels).
    pub size: [u32; 4],
    /// First tap, tap count, factor (pixels per texel), first normalisation node.
    pub taps: [u32; 4],
    /// The texels where the layer's split can be other than zero: x0, y0, x1, y1 (ends excluded).
    pub low: [u32; 4],
    /// The texels where its gathered light can be other than zero: `low` grown by the taps' reach.
    pub out: [u32; 4],
    /// The pixels the composite covers (`composite_pixels`).
    pub pixels: [u32; 4],
    /// The layer's defocus, the spacing of the layers (hat weights), the lowest and the highest layer's defocus.
    pub shape: [f32; 4],
    /// The cat's eye: up to `MAX_LAYER_CATS` clear apertures' circles, each centre (pupil radii) at pixel (x, y)
    /// `[c0x + cx x, c0y + cy y]`: c0x, cx, c0y, cy.
    pub cat: [[f32; 4]; MAX_LAYER_CATS],
    /// Each circle's radius (pupil radii; 0: an empty slot).
    pub cat_radius: [f32; MAX_LAYER_CATS],
    /// Each circle's x scale ([`super::kernel::Cat::x_scale`]: 1 for a lens of revolution; an anamorphic lens's
    /// regions are ellipses).
    pub cat_x_scale: [f32; MAX_LAYER_CATS],
    /// Circles in use.
    pub cat_count: u32,
    /// The circles' soft edge (pupil radii).
    pub cat_edge: f32,
    /// 1 when the cat's eye is on, else 0.
    pub cat_on: u32,
    pub _pad0: u32,
    /// Pupil radii per pixel of offset along x and along y, `2 / sigma` of each axis (signed: reflected in front of
    /// its focus; equal for a lens of revolution), unused, unused.
    pub pupil: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<LiveLayer>() == 224);

/// The cat's eye's soft edge in tap cells. The taps average the mask over 3 x 3 points of their cell, the cat's
/// eye is a ramp at each tap's pupil point: a ramp a whole cell wide, times the mask's own averaged rim, darkened
/// the rim twice where an aperture's edge runs close to the pupil's (a toroidal test lens whose rear apertures
/// are 7 mm: the axial bokeh 11 % dimmer than the reference's, the corner's share 0.87 against exact rays' 0.80).
/// Half a cell keeps an interior cut's mean area and halves that (0.81; the double Gauss's corner 0.570 against
/// 0.581, was 0.577).
pub(crate) const CAT_EDGE_CELLS: f64 = 0.5;

/// The most clear-aperture circles a layer's cat's eye carries: those that cut deepest into the pupil at the
/// frame's corners ([`LivePlan::new`]).
pub(crate) const MAX_LAYER_CATS: usize = 4;

/// Everything the live method needs, planned on the CPU for either twin.
#[derive(Clone, Debug)]
pub struct LivePlan {
    pub width: u32,
    pub height: u32,
    /// Signed defocus per pixel (pixels).
    pub sigma: Vec<f32>,
    /// Layers, far first.
    pub layers: Vec<LiveLayer>,
    /// All layers' taps: offset (texels, X right, Y down: source = target - offset), base weight, unused.
    pub taps: Vec<[f32; 4]>,
    /// All layers' normalisation tables, (NORM_CELLS + 1)^2 nodes each, row by row.
    pub norm: Vec<f32>,
}

/// The hat weight of defocus `s` in the layer `layer` (the end layers take everything beyond them).
#[inline]
pub(crate) fn hat(layer: &LiveLayer, s: f32) -> f32 {
    let [centre, spacing, lo, hi] = layer.shape;
    let s = s.clamp(lo, hi);
    if spacing <= 0.0 {
        return 1.0;
    }
    (1.0 - (s - centre).abs() / spacing).max(0.0)
}

/// The cat's eye factor of a tap at the pupil point `q` from the source texel centre at pixel (`x`, `y`).
#[inline]
fn cat_factor(layer: &LiveLayer, q: [f32; 2], x: f32, y: f32) -> f32 {
    if layer.cat_on == 0 {
        return 1.0;
    }
    let mut m = 1.0f32;
    for ((cat, &radius), &x_scale) in layer.cat.iter().zip(&layer.cat_radius).zip(&layer.cat_x_scale) {
        if radius == 0.0 {
            continue;
        }
        let c = [cat[0] + cat[1] * x, cat[2] + cat[3] * y];
        let qx = q[0] * x_scale;
        let d = ((qx - c[0]) * (qx - c[0]) + (q[1] - c[1]) * (q[1] - c[1])).sqrt();
        m *= (0.5 + (radius - d) / layer.cat_edge).clamp(0.0, 1.0);
    }
    m
}

/// The pupil point of tap offset `t` (texels, Y down) in `layer`.
#[inline]
fn tap_pupil(layer: &LiveLayer, t: [f32; 2]) -> [f32; 2] {
    let f = layer.taps[2] as f32;
    [t[0] * (layer.pupil[0] * f), -t[1] * (layer.pupil[1] * f)]
}

/// The normalisation at pixel (`x`, `y`), bilinear in the layer's table.
#[inline]
fn norm_at(layer: &LiveLayer, norm: &[f32], x: f32, y: f32) -> f32 {
    if layer.cat_on == 0 {
        return norm[layer.taps[3] as usize];
    }
    let n = NORM_CELLS as f32;
    let gx = (x / layer.size[0] as f32 * n).clamp(0.0, n);
    let gy = (y / layer.size[1] as f32 * n).clamp(0.0, n);
    let (ix, iy) = ((gx as usize).min(NORM_CELLS - 1), (gy as usize).min(NORM_CELLS - 1));
    let (fx, fy) = (gx - ix as f32, gy - iy as f32);
    let at = |i: usize, j: usize| norm[layer.taps[3] as usize + j * (NORM_CELLS + 1) + i];
    let top = at(ix, iy) * (1.0 - fx) + at(ix + 1, iy) * fx;
    let bottom = at(ix, iy + 1) * (1.0 - fx) + at(ix + 1, iy + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

impl LivePlan {
    /// Plans the live method for the depth map `depth_mm` (mm from the entrance pupil, one per pixel).
    pub fn new(depth_mm: &[f64], model: &DofModel, mask: &ApertureMask) -> Result<Self, DofError> {
        Self::with_settings(depth_mm, model, mask, LiveSettings::default())
    }

    /// [`Self::new`] with other settings than the default.
    pub fn with_settings(
        depth_mm: &[f64],
        model: &DofModel,
        mask: &ApertureMask,
        settings: LiveSettings,
    ) -> Result<Self, DofError> {
        let sigma = defocus_map(model, depth_mm)?;
        Ok(Self::from_defocus(&sigma, model, mask, settings))
    }

    /// Plans the live method for per-pixel defocus `sigma` (checked already).
    pub fn from_defocus(sigma: &[f64], model: &DofModel, mask: &ApertureMask, settings: LiveSettings) -> Self {
        // A blur past four times the frame's diagonal looks as that one does (every pixel spread over the whole
        // frame): clamped there, so that no layer's size or reach overflows (issue 61's walk: a focus of 1e300 m).
        let most_px = 4.0 * f64::from(model.width).hypot(f64::from(model.height));
        let clamped: Vec<f64> =
            sigma.iter().map(|&s| if s.is_nan() { 0.0 } else { s.clamp(-most_px, most_px) }).collect();
        let sigma = clamped.as_slice();
        let (lo, hi) = sigma.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &s| (a.min(s), b.max(s)));
        let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 0.0) };
        let range = hi - lo;
        // In f64 before the cast: a range too large for a count (or not finite) is the most layers allowed.
        let most = settings.max_layers.max(1);
        let count = if range.is_finite() { (range.floor() + 1.0).clamp(1.0, most as f64) as usize } else { most };
        let spacing = if count > 1 { range / (count - 1) as f64 } else { 0.0 };
        let centres: Vec<f64> = (0..count).map(|k| hi - spacing * k as f64).collect();
        // Where each layer's pixels are (x0, y0, x1, y1, ends excluded; empty: none).
        let (width, height) = (model.width, model.height);
        let mut boxes = vec![[u32::MAX, u32::MAX, 0, 0]; count];
        for (i, &s) in sigma.iter().enumerate() {
            let pos = if spacing > 0.0 { (hi - s) / spacing } else { 0.0 };
            let k = (pos.floor().max(0.0) as usize).min(count - 1);
            let (x, y) = ((i % width as usize) as u32, (i / width as usize) as u32);
            let grow = |b: &mut [u32; 4]| *b = [b[0].min(x), b[1].min(y), b[2].max(x + 1), b[3].max(y + 1)];
            grow(&mut boxes[k]);
            if pos.fract() > 0.0 && k + 1 < count {
                grow(&mut boxes[k + 1]);
            }
        }
        let mut plan = Self {
            width,
            height,
            sigma: sigma.iter().map(|&s| s as f32).collect(),
            layers: Vec::new(),
            taps: Vec::new(),
            norm: Vec::new(),
        };
        for (k, &centre) in centres.iter().enumerate() {
            if boxes[k][0] == u32::MAX {
                continue;
            }
            plan.add_layer(centre, [spacing, lo, hi], boxes[k], model, mask, settings.taps_across.max(1.0));
        }
        plan
    }

    fn add_layer(
        &mut self,
        centre: f64,
        [spacing, lo, hi]: [f64; 3],
        pixels: [u32; 4],
        model: &DofModel,
        mask: &ApertureMask,
        taps_across: f64,
    ) {
        // An anamorphic lens's layer blurs along x by the x blur of the layer's depth (the y blur is `centre`).
        let sigma = [model.defocus_x_for(centre), centre];
        let diameter = sigma[0].abs().max(sigma[1].abs());
        // At most `taps_across` texels across the kernel (so at most ~0.8 taps_across^2 taps).
        let factor = (diameter / taps_across).ceil().max(1.0) as u32;
        let (lw, lh) = (self.width.div_ceil(factor), self.height.div_ceil(factor));
        let f = f64::from(factor);
        let small = diameter < 1e-3;
        let pupil_per_px = sigma.map(|s| if small || s.abs() < 1e-9 { 0.0 } else { 2.0 / s });
        let cats = layer_cats(model, depth_of(model, centre), self.width, self.height);
        let cell_pupil = if small { 1.0 } else { 2.0 * f / diameter };
        let reach = if small { 0 } else { (diameter / (2.0 * f) + 0.5).ceil() as u32 };
        // The texels a pixel's tent weights reach, and those the taps reach from them.
        let low = [
            (pixels[0] / factor).saturating_sub(1),
            (pixels[1] / factor).saturating_sub(1),
            (pixels[2].div_ceil(factor) + 1).min(lw),
            (pixels[3].div_ceil(factor) + 1).min(lh),
        ];
        let out = [
            low[0].saturating_sub(reach),
            low[1].saturating_sub(reach),
            low[2].saturating_add(reach).min(lw),
            low[3].saturating_add(reach).min(lh),
        ];
        let mut layer = LiveLayer {
            size: [self.width, self.height, lw, lh],
            taps: [self.taps.len() as u32, 0, factor, self.norm.len() as u32],
            low,
            out,
            pixels: [0; 4],
            shape: [centre as f32, spacing as f32, lo as f32, hi as f32],
            cat: cats.coeffs,
            cat_radius: cats.radius,
            cat_x_scale: cats.x_scale,
            cat_count: cats.count,
            cat_edge: (CAT_EDGE_CELLS * cell_pupil) as f32,
            cat_on: u32::from(model.cat_eye && cats.count > 0),
            _pad0: 0,
            pupil: [pupil_per_px[0] as f32, pupil_per_px[1] as f32, 0.0, 0.0],
        };
        let taps = kernel_taps(mask, model.mask_sign, sigma, reach, f);
        layer.taps[1] = taps.len() as u32;
        // Normalisation: one value, or a table over the frame with the cat's eye.
        if layer.cat_on == 0 {
            let total: f32 = taps.iter().map(|t| t[2]).sum();
            self.norm.push(1.0 / total);
        } else {
            let n = NORM_CELLS + 1;
            for j in 0..n {
                for i in 0..n {
                    let x = i as f32 / NORM_CELLS as f32 * self.width as f32;
                    let y = j as f32 / NORM_CELLS as f32 * self.height as f32;
                    let total: f32 =
                        taps.iter().map(|t| t[2] * cat_factor(&layer, tap_pupil(&layer, [t[0], t[1]]), x, y)).sum();
                    // A cat's eye that closes the pupil: the centre tap keeps the light (as the reference does).
                    self.norm.push(if total > 1e-12 { 1.0 / total } else { 0.0 });
                }
            }
        }
        layer.pixels = composite_pixels(&layer);
        self.taps.extend(taps);
        self.layers.push(layer);
    }

    /// The live method on the CPU: the twin of `render::dof_gpu` (see the module documentation).
    pub fn render_cpu(&self, plate: &HdrImage) -> HdrImage {
        self.render_cpu_until(plate, &std::sync::atomic::AtomicBool::new(false)).expect("never cancelled")
    }

    /// [`Self::render_cpu`] that stops between layers once `cancel` is set (`None`): the app's focus slider
    /// starts a new defocus at every step and must not leave the old ones running.
    pub fn render_cpu_until(&self, plate: &HdrImage, cancel: &std::sync::atomic::AtomicBool) -> Option<HdrImage> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut out = vec![[0.0f32; 4]; w * h];
        for layer in &self.layers {
            if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                return None;
            }
            let low = self.split(layer, plate);
            let gathered = self.gather(layer, &low);
            composite(layer, &gathered, &mut out);
        }
        Some(HdrImage { width: self.width, height: self.height, pixels: out.into_par_iter().map(resolve).collect() })
    }

    /// Step 1: the layer's premultiplied colour and coverage, each pixel shared among the four nearest texel
    /// centres by tent weights (`1 - |distance| / factor` on each axis: a partition of unity, so every pixel's
    /// light and its position are kept), divided by the texel's area.
    pub fn split(&self, layer: &LiveLayer, plate: &HdrImage) -> Vec<[f32; 4]> {
        let [w, h, lw, lh] = layer.size.map(|v| v as usize);
        let [x0, y0, x1, y1] = layer.low.map(|v| v as usize);
        let f = layer.taps[2] as usize;
        let ff = f as f32;
        let scale = 1.0 / (ff * ff);
        let tent = |p: usize, t: usize| (1.0 - ((p as f32 + 0.5) - (t as f32 + 0.5) * ff).abs() / ff).max(0.0);
        let mut low = vec![[0.0f32; 4]; lw * lh];
        low.par_chunks_mut(lw).enumerate().skip(y0).take(y1.saturating_sub(y0)).for_each(|(ty, row)| {
            for (tx, texel) in row.iter_mut().enumerate().take(x1).skip(x0) {
                let mut acc = [0.0f32; 4];
                for y in (ty * f).saturating_sub(f)..((ty + 2) * f).min(h) {
                    let wy = tent(y, ty);
                    if wy == 0.0 {
                        continue;
                    }
                    for x in (tx * f).saturating_sub(f)..((tx + 2) * f).min(w) {
                        let i = y * w + x;
                        let wgt = hat(layer, self.sigma[i]) * wy * tent(x, tx);
                        if wgt > 0.0 {
                            let p = plate.pixels[i];
                            acc = [acc[0] + p[0] * wgt, acc[1] + p[1] * wgt, acc[2] + p[2] * wgt, acc[3] + wgt];
                        }
                    }
                }
                *texel = acc.map(|v| v * scale);
            }
        });
        low
    }

    /// Step 2: scatter as gather over the layer's taps.
    pub fn gather(&self, layer: &LiveLayer, low: &[[f32; 4]]) -> Vec<[f32; 4]> {
        let [_, _, lw, lh] = layer.size.map(|v| v as i32);
        let [lx0, ly0, lx1, ly1] = layer.low.map(|v| v as i32);
        let [x0, y0, x1, y1] = layer.out.map(|v| v as usize);
        let taps = &self.taps[layer.taps[0] as usize..][..layer.taps[1] as usize];
        let f = layer.taps[2] as f32;
        let mut gathered = vec![[0.0f32; 4]; (lw * lh) as usize];
        gathered.par_chunks_mut(lw as usize).enumerate().skip(y0).take(y1.saturating_sub(y0)).for_each(|(y, row)| {
            let y = y as i32;
            for (x, texel) in row.iter_mut().enumerate().take(x1).skip(x0) {
                let x = x as i32;
                let mut acc = [0.0f32; 4];
                for t in taps {
                    let (sx, sy) = (x - t[0] as i32, y - t[1] as i32);
                    // Outside the split's region the layer is empty.
                    if sx < lx0 || sy < ly0 || sx >= lx1 || sy >= ly1 {
                        continue;
                    }
                    let src = low[(sy * lw + sx) as usize];
                    if src[3] == 0.0 {
                        continue;
                    }
                    let (px, py) = ((sx as f32 + 0.5) * f, (sy as f32 + 0.5) * f);
                    let wgt = t[2]
                        * cat_factor(layer, tap_pupil(layer, [t[0], t[1]]), px, py)
                        * norm_at(layer, &self.norm, px, py);
                    acc = [acc[0] + src[0] * wgt, acc[1] + src[1] * wgt, acc[2] + src[2] * wgt, acc[3] + src[3] * wgt];
                }
                *texel = acc;
            }
        });
        gathered
    }
}

/// The pixels (x0, y0, x1, y1, ends excluded) whose bilinear sample of the gathered layer can touch its `out`
/// texels.
pub(crate) fn composite_pixels(layer: &LiveLayer) -> [u32; 4] {
    let [w, h, ..] = layer.size;
    let f = layer.taps[2];
    let [x0, y0, x1, y1] = layer.out;
    [(x0 * f).saturating_sub(f), (y0 * f).saturating_sub(f), ((x1 + 1) * f).min(w), ((y1 + 1) * f).min(h)]
}

/// Step 3: every pixel samples the gathered layer bilinearly (clamped at the frame's edges; zero outside the
/// layer's `out` texels) and puts it over `out`.
pub fn composite(layer: &LiveLayer, gathered: &[[f32; 4]], out: &mut [[f32; 4]]) {
    let [w, ..] = layer.size.map(|v| v as usize);
    let [x0, y0, x1, y1] = layer.pixels.map(|v| v as usize);
    let f = layer.taps[2] as f32;
    out.par_chunks_mut(w).enumerate().skip(y0).take(y1.saturating_sub(y0)).for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate().take(x1).skip(x0) {
            let sample = sample_bilinear(layer, gathered, (x as f32 + 0.5) / f - 0.5, (y as f32 + 0.5) / f - 0.5);
            if sample[3] > 0.0 || sample[0] != 0.0 || sample[1] != 0.0 || sample[2] != 0.0 {
                over(o, sample);
            }
        }
    });
}

/// Bilinear sample of the gathered layer at texel coordinates (`x`, `y`) (texel centres at integers), clamped to
/// the layer's texels; a texel outside its `out` region is zero.
#[inline]
pub(crate) fn sample_bilinear(layer: &LiveLayer, image: &[[f32; 4]], x: f32, y: f32) -> [f32; 4] {
    let [_, _, w, h] = layer.size.map(|v| v as usize);
    let [bx0, by0, bx1, by1] = layer.out.map(|v| v as usize);
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let (x0, y0) = (x as usize, y as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let at = |i: usize, j: usize| {
        if i < bx0 || j < by0 || i >= bx1 || j >= by1 { [0.0f32; 4] } else { image[j * w + i] }
    };
    let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
    let mut out = [0.0f32; 4];
    for k in 0..4 {
        let top = a[k] * (1.0 - fx) + b[k] * fx;
        let bottom = c[k] * (1.0 - fx) + d[k] * fx;
        out[k] = top * (1.0 - fy) + bottom * fy;
    }
    out
}

/// The depth (mm from the pupil) whose defocus is `sigma` pixels ([`super::model::depth_of_defocus`]).
pub(crate) fn depth_of(model: &DofModel, sigma: f64) -> f64 {
    super::model::depth_of_defocus(model, sigma)
}

/// The cat's eye of one layer ([`LayerCats`]).
struct LayerCats {
    /// Each circle's centre as `[x0, dx/dpx, y0, dy/dpx]`.
    coeffs: [[f32; 4]; MAX_LAYER_CATS],
    radius: [f32; MAX_LAYER_CATS],
    x_scale: [f32; MAX_LAYER_CATS],
    count: u32,
}

/// The cat's eye at `depth_mm` over a `width` x `height` frame: each clear aperture's circle, its centre linear
/// in the pixel position, its radius the same everywhere. Of those that cut the pupil at some corner of the
/// frame (the farthest a centre goes), the MAX_LAYER_CATS that cut deepest.
fn layer_cats(model: &DofModel, depth_mm: f64, width: u32, height: u32) -> LayerCats {
    let (fw, fh) = (f64::from(width), f64::from(height));
    let corners: Vec<Vec<Cat>> = [(0.0, 0.0), (fw, 0.0), (0.0, fh), (fw, fh)]
        .iter()
        .map(|&(x, y)| model.cat_circles_at(x, y, depth_mm))
        .collect();
    // The circles at pixel (0, 0), the first corner, and at (1, 1): each centre's linear coefficients.
    let (at0, at1) = (&corners[0], model.cat_circles_at(1.0, 1.0, depth_mm));
    let mut chosen: Vec<(f64, usize)> = (0..at0.len())
        .map(|k| {
            let depth = corners.iter().map(|c| c[k].cut_depth()).fold(f64::MIN, f64::max);
            (depth, k)
        })
        .filter(|&(depth, _)| depth > 0.0)
        .collect();
    chosen.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    chosen.truncate(MAX_LAYER_CATS);
    let mut cat_coeffs = [[0.0f32; 4]; MAX_LAYER_CATS];
    let mut cat_radius = [0.0f32; MAX_LAYER_CATS];
    let mut cat_x_scale = [1.0f32; MAX_LAYER_CATS];
    for (slot, &(_, k)) in chosen.iter().enumerate() {
        let (c0, c1) = (at0[k].centre, at1[k].centre);
        cat_coeffs[slot] = [c0[0], c1[0] - c0[0], c0[1], c1[1] - c0[1]].map(|v| v as f32);
        // A circle that passes nothing has radius 0, which marks an empty slot: the smallest radius instead.
        cat_radius[slot] = (at0[k].radius as f32).max(f32::MIN_POSITIVE);
        cat_x_scale[slot] = at0[k].x_scale as f32;
    }
    LayerCats { coeffs: cat_coeffs, radius: cat_radius, x_scale: cat_x_scale, count: chosen.len() as u32 }
}

/// A layer's taps: the kernel of blur `sigma` (px, x and y) averaged over 3 x 3 points of each `f`-pixel
/// texel cell out to `reach` cells (no cat's eye: that is per source), as `[x, y, weight, 0]`; one centre tap
/// where the kernel passes nothing.
fn kernel_taps(mask: &ApertureMask, mask_sign: f64, sigma: [f64; 2], reach: u32, f: f64) -> Vec<[f32; 4]> {
    let reach = reach as i32;
    let mut taps = Vec::new();
    for ty in -reach..=reach {
        for tx in -reach..=reach {
            let mut sum = 0.0;
            for sy in 0..3 {
                for sx in 0..3 {
                    let ox = (f64::from(tx) + (f64::from(sx) - 1.0) / 3.0) * f;
                    let oy = -(f64::from(ty) + (f64::from(sy) - 1.0) / 3.0) * f;
                    sum += weight(mask, mask_sign, pupil_point_xy([ox, oy], sigma), &[], 1.0);
                }
            }
            if sum > 0.0 {
                taps.push([tx as f32, ty as f32, (sum / 9.0) as f32, 0.0]);
            }
        }
    }
    if taps.is_empty() {
        taps.push([0.0, 0.0, 1.0, 0.0]);
    }
    taps
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::library::builtin_lens;

    #[test]
    fn hat_weights_sum_to_one_and_depth_inverts_the_defocus() {
        let model = DofModel::new(&builtin_lens("heliar").unwrap(), 1.0, 2.0, 36.0, (640, 360), false).unwrap();
        for s in [500.0, 1999.0, 2000.0, 3000.0, 1e6] {
            let sigma = model.defocus_px(s);
            assert!((depth_of(&model, sigma) / s - 1.0).abs() < 1e-9, "{s}");
        }
        let sigma: Vec<f64> = (0..200).map(|k| -10.0 + 0.173 * k as f64).collect();
        let mask = crate::aperture::Aperture::default().rasterise(64);
        let plan = LivePlan::from_defocus(&sigma, &model, &mask, LiveSettings::default());
        for &s in &sigma {
            let total: f32 = plan.layers.iter().map(|l| hat(l, s as f32)).sum();
            assert!((total - 1.0).abs() < 1e-5, "{s}: {total}");
        }
        assert!(plan.layers.windows(2).all(|l| l[0].shape[0] > l[1].shape[0]), "far first");
    }

    /// Issue 61's walk: a defocus range too large for a layer count (a focus of 1e300 m) overflowed it; a blur
    /// is clamped at four frame diagonals now, and a focus that far is refused before (`dof::MAX_FOCUS_M`).
    #[test]
    fn a_defocus_past_the_frame_is_clamped_and_planned() {
        let model = DofModel::new(&builtin_lens("heliar").unwrap(), 1.0, 2.0, 36.0, (64, 36), false).unwrap();
        let mask = crate::aperture::Aperture::default().rasterise(64);
        for far in [1e30, 1e300, f64::MAX] {
            let sigma = vec![0.0, 1.0, far];
            let plan = LivePlan::from_defocus(&sigma, &model, &mask, LiveSettings::default());
            assert!(plan.sigma.iter().all(|s| s.abs() <= 4.0 * 64f32.hypot(36.0) + 1e-3), "{far}");
            assert!(!plan.layers.is_empty() && plan.layers.len() <= LiveSettings::default().max_layers, "{far}");
        }
        let doc = crate::dof::DofDoc { focus_m: 1e300, ..crate::dof::DofDoc::default() };
        let (field, reason) = doc.check().unwrap_err();
        assert!(field == "dof.focus_m" && reason.contains("1.000e300 m") && reason.contains("at most"), "{reason}");
    }
}
