//! Blending LUT ghosts into the live flare: the run-time half of the patent, on the GPU (`lut_compute.wgsl`,
//! binned by `bin_instances`; `lut_ghosts.wgsl` where the device has no compute) and its CPU twin
//! ([`lut_pass`]).
//!
//! # How it works
//! For a light of slopes u, [`LutScene::build`] takes the light's (theta, alpha), reduces alpha to the
//! symmetry wedge ([`super::Symmetry::reduce`]) and, per LUT ghost, picks the two baked thetas around theta
//! and the two baked azimuths around the reduced one (linear weights; outside the baked range the nearest
//! entry alone). Each picked entry becomes one [`LutInstance`]: a quad whose corners map the entry's image
//! from its baked paraxial frame into the live one: a texel at sensor point p sits at the normalised position
//! `n = (p - c_baked) / s_baked`, which is rotated (and mirrored) by the symmetry's transform and the remaining
//! azimuth difference, then placed at `c_live + s_live n` (c, s: the ghost's paraxial centre and half-size).
//! Its brightness is scaled by the live paraxial energy over the baked one interpolated the same way (1 when
//! nothing but the light moved), so a changed coating or f-number dims the LUT ghost as it dims the sprite.
//! A photo LUT is one image of the whole frame per theta: rotated about the axis, never fitted.
//!
//! The [`BlendMode`] sets how much of each non-linear ghost comes from its LUT image (w) and how much from its
//! paraxial sprite (1 - w), globally or per ghost: **additive** (w = 1: the LUT image replaces the sprite and
//! adds onto the linear flare), **linear** or **smooth** (w ramps with theta between two angles, linearly
//! or by smoothstep: paraxial near the axis where it is right, the LUT further out), or **alpha** (the LUT
//! layer is composited over the linear flare with its coverage: `out = lut + (1 - alpha) linear`).
//!
//! Instances reference their entry in an atlas ([`AtlasLayout`]): pages of [`ATLAS_PAGE`] texels with a
//! zero border of one texel around every entry, so the GPU's bilinear sampler returns what
//! [`super::LutEntry::sample`] does (0 outside the image). Each entry's [`Footprint`] (size, the box of its lit
//! texels, its brightest texel) is measured once per LUT: the CPU pass samples only where an entry is lit,
//! `bin_instances` bins instances into tiles by it, and [`LutScene::cull_faint`] leaves out the images that
//! cannot be seen at the frame's exposure. An added instance magnified so that a texel spans a pixel or more
//! is sampled every 2 or 4 pixels and its samples bilinearly upsampled ([`instance_levels`]), in the twin and
//! the compute pass alike.
//!
//! An entry of twice [`MIP_FLOOR_TEXELS`] or more across (one baked finer than the default for its detail,
//! `bake::BakeSettings::diagonal_texels`, or with a larger `res`) gets mip levels on load ([`LiveLut::mips`],
//! each [`super::LutEntry::halved`] from the one before, while they keep [`MIP_FLOOR_TEXELS`] across), each a
//! slot of its own in the atlas. [`LutScene::choose_mips`] draws each instance from the finest level whose
//! texels span at least `MIP_TEXEL_PX` accumulation pixels: the instance keeps its quad and takes the level's
//! atlas rectangle (the same window), so the shaders need nothing new, and a small frame samples a fine entry
//! about as often as the default one.

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::{
    EntryShape, Fit, GhostLut, LutEntry, LutKind, fit_picks, light_direction_deg, mat_apply, mat_mul, rotation,
};
use crate::ghost::{GhostSystem, ParaxialFrame};
use crate::image::HdrImage;
use crate::raytrace::Window;

/// Side of an atlas page (texels): within every adapter's limits (WebGL2's 2048 included).
pub const ATLAS_PAGE: u32 = 2048;

/// How a non-linear ghost's LUT image and its paraxial sprite are mixed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BlendMode {
    /// The LUT image replaces the sprite (w = 1) and adds onto the linear flare.
    Additive,
    /// w rises linearly from 0 at `from_deg` to 1 at `to_deg`.
    Linear { from_deg: f64, to_deg: f64 },
    /// w rises by smoothstep from 0 at `from_deg` to 1 at `to_deg` (a non-linear weight curve).
    Smooth { from_deg: f64, to_deg: f64 },
    /// The LUT layer over the linear flare through its alpha (coverage) channel.
    Alpha,
}

impl BlendMode {
    /// The LUT image's weight w at light angle `theta_deg` (the sprite gets 1 - w).
    pub fn weight(self, theta_deg: f64) -> f64 {
        let ramp = |from: f64, to: f64| {
            if to <= from {
                if theta_deg >= to { 1.0 } else { 0.0 }
            } else {
                ((theta_deg - from) / (to - from)).clamp(0.0, 1.0)
            }
        };
        match self {
            Self::Additive | Self::Alpha => 1.0,
            Self::Linear { from_deg, to_deg } => ramp(from_deg, to_deg),
            Self::Smooth { from_deg, to_deg } => {
                let x = ramp(from_deg, to_deg);
                x * x * (3.0 - 2.0 * x)
            }
        }
    }

    /// `additive`, `alpha`, `linear:FROM:TO` or `smooth:FROM:TO` (degrees).
    pub fn parse(text: &str) -> Result<Self, String> {
        let parts: Vec<&str> = text.trim().split(':').collect();
        let angles = || -> Result<(f64, f64), String> {
            let bad = || format!("`{text}`: write {}:FROM_DEG:TO_DEG with 0 <= FROM <= TO <= 89", parts[0]);
            if parts.len() != 3 {
                return Err(bad());
            }
            let from: f64 = parts[1].parse().map_err(|_| bad())?;
            let to: f64 = parts[2].parse().map_err(|_| bad())?;
            if !(0.0..=89.0).contains(&from) || !(from..=89.0).contains(&to) {
                return Err(bad());
            }
            Ok((from, to))
        };
        match parts[0] {
            "additive" if parts.len() == 1 => Ok(Self::Additive),
            "alpha" if parts.len() == 1 => Ok(Self::Alpha),
            "linear" => angles().map(|(from_deg, to_deg)| Self::Linear { from_deg, to_deg }),
            "smooth" => angles().map(|(from_deg, to_deg)| Self::Smooth { from_deg, to_deg }),
            _ => Err(format!("`{text}`: the blend modes are additive, alpha, linear:FROM:TO and smooth:FROM:TO")),
        }
    }
}

/// The blend, globally and per ghost.
#[derive(Clone, Debug, PartialEq)]
pub struct BlendSettings {
    pub mode: BlendMode,
    /// Per lens ghost index: a mode of its own (alpha applies to the whole LUT layer, so only globally).
    pub per_ghost: Vec<(u32, BlendMode)>,
    /// Multiplies every LUT image (1: physically matched).
    pub gain: f64,
}

impl Default for BlendSettings {
    fn default() -> Self {
        Self { mode: BlendMode::Additive, per_ghost: Vec::new(), gain: 1.0 }
    }
}

impl BlendSettings {
    fn mode_of(&self, ghost: u32) -> BlendMode {
        self.per_ghost.iter().find(|(g, _)| *g == ghost).map_or(self.mode, |(_, m)| *m)
    }
}

/// Where every entry's image (and each of its mip levels) lies in the atlas: per LUT ghost, entry and level,
/// `(page, x, y)` of its top-left texel (inside its one-texel zero border).
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasLayout {
    pub pages: u32,
    /// `slots[lut_ghost][entry][level]`; empty for an empty entry.
    pub slots: Vec<Vec<Vec<(u32, u32, u32)>>>,
}

impl AtlasLayout {
    /// Shelf packing, tallest images first, into as many [`ATLAS_PAGE`] pages as needed: every level of
    /// `levels` (per LUT ghost and entry, its images finest first).
    pub fn new(levels: &[Vec<Vec<&LutEntry>>]) -> Self {
        let mut order: Vec<(usize, usize, usize, u32, u32)> = levels
            .iter()
            .enumerate()
            .flat_map(|(g, ghost)| {
                ghost.iter().enumerate().flat_map(move |(k, entry)| {
                    entry
                        .iter()
                        .enumerate()
                        .filter(|(_, e)| !e.is_empty())
                        .map(move |(m, e)| (g, k, m, e.width, e.height))
                })
            })
            .collect();
        order.sort_by_key(|&(g, k, m, _, h)| (std::cmp::Reverse(h), g, k, m));
        let mut slots: Vec<Vec<Vec<(u32, u32, u32)>>> =
            levels.iter().map(|g| g.iter().map(|e| vec![(0, 0, 0); e.len()]).collect()).collect();
        let (mut page, mut x, mut y, mut shelf) = (0u32, 0u32, 0u32, 0u32);
        let mut used = false;
        for (g, k, m, w, h) in order {
            let (w, h) = ((w + 2).min(ATLAS_PAGE), (h + 2).min(ATLAS_PAGE));
            if x + w > ATLAS_PAGE {
                (x, y) = (0, y + shelf);
                shelf = 0;
            }
            if y + h > ATLAS_PAGE {
                (page, x, y, shelf) = (page + 1, 0, 0, 0);
            }
            slots[g][k][m] = (page, x + 1, y + 1);
            used = true;
            x += w;
            shelf = shelf.max(h);
        }
        // Empty entries keep no slot.
        for (g, ghost) in levels.iter().enumerate() {
            for (k, entry) in ghost.iter().enumerate() {
                if entry.first().is_none_or(|e| e.is_empty()) {
                    slots[g][k].clear();
                }
            }
        }
        Self { pages: if used { page + 1 } else { 0 }, slots }
    }

    /// Atlas page `page` as RGBA half-float texels (rows from the top), zero between images: the atlas is
    /// written a page at a time (one page is 32 MB; a large LUT's thirteen at once, and their staging copy,
    /// were most of the app's memory).
    pub fn page_f16(&self, levels: &[Vec<Vec<&LutEntry>>], page: u32) -> Vec<[half::f16; 4]> {
        let side = ATLAS_PAGE as usize;
        let mut texels = vec![[half::f16::ZERO; 4]; side * side];
        for (g, ghost) in levels.iter().enumerate() {
            for (k, (m, e)) in ghost.iter().enumerate().flat_map(|(k, l)| l.iter().enumerate().map(move |i| (k, i))) {
                let Some(&(on, x0, y0)) = self.slots[g][k].get(m) else { continue };
                if on != page {
                    continue;
                }
                let (w, h) = ((e.width as usize).min(side - 2), (e.height as usize).min(side - 2));
                for y in 0..h {
                    let start = (y0 as usize + y) * side + x0 as usize;
                    texels[start..start + w].copy_from_slice(&e.texels[y * e.width as usize..y * e.width as usize + w]);
                }
            }
        }
        texels
    }
}

/// One LUT image drawn as a quad. Must be kept in sync with `struct LutInstance` in `shaders/lut_ghosts.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LutInstance {
    /// Quad centre x, y (image pixels); pixels per unit of the quad coordinate q.x (x, y).
    pub centre_axis_x: [f32; 4],
    /// Pixels per unit of q.y (x, y).
    pub axis_y: [f32; 2],
    /// The atlas page that holds the entry.
    pub page: u32,
    pub _pad0: u32,
    /// The entry's texels in the atlas page: u0, v0, u1, v1 (texture coordinates).
    pub rect: [f32; 4],
    /// RGB gain and alpha gain.
    pub colour: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<LutInstance>() == 64);

impl LutInstance {
    /// Whether every float of the instance is finite.
    pub fn is_finite(&self) -> bool {
        let floats = [&self.centre_axis_x[..], &self.axis_y, &self.rect, &self.colour];
        floats.iter().all(|values| values.iter().all(|v| v.is_finite()))
    }

    /// q for the image pixel position `p`, `None` when the quad is degenerate.
    fn inverse(&self) -> Option<impl Fn([f32; 2]) -> [f32; 2]> {
        let [cx, cy, ax, ay] = self.centre_axis_x;
        let [bx, by] = self.axis_y;
        let det = ax * by - bx * ay;
        (det != 0.0 && det.is_finite()).then_some(move |p: [f32; 2]| {
            let (dx, dy) = (p[0] - cx, p[1] - cy);
            [(by * dx - bx * dy) / det, (ax * dy - ay * dx) / det]
        })
    }
}

/// What one frame draws of a LUT.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LutScene {
    pub instances: Vec<LutInstance>,
    /// Per instance: (LUT ghost, entry, mip level) it draws ([`LiveLut::level`]).
    pub sources: Vec<(u32, u32, u32)>,
    /// Composite over the linear flare through alpha (else add).
    pub alpha_over: bool,
    /// Per lens ghost with a LUT image: the weight its paraxial sprites keep (1 - w).
    pub paraxial_weights: Vec<(u32, f32)>,
    /// Instances dropped because a value was not finite (expected: always 0).
    pub dropped_non_finite: usize,
}

/// Linear weights of the samples around `x` in the increasing list `xs`: one or two `(index, weight)`.
fn bracket(xs: &[f64], x: f64) -> Vec<(usize, f64)> {
    match xs.iter().position(|&v| v > x) {
        _ if xs.len() == 1 => vec![(0, 1.0)],
        Some(0) => vec![(0, 1.0)],
        None => vec![(xs.len() - 1, 1.0)],
        Some(k) => {
            let t = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
            vec![(k - 1, 1.0 - t), (k, t)]
        }
    }
}

/// The indices of the baked thetas `thetas_deg` whose images a frame with the light `theta_deg` off the axis
/// may draw ([`LutScene::build`]'s bracket), with those of a light a hair either side of it (the light's angle
/// worked out again elsewhere rounds alike, or picks no other sample).
pub(crate) fn thetas_drawn(thetas_deg: &[f64], theta_deg: f64) -> Vec<usize> {
    if thetas_deg.is_empty() || !theta_deg.is_finite() {
        return (0..thetas_deg.len()).collect();
    }
    let mut drawn: Vec<usize> = [theta_deg - 1e-9, theta_deg, theta_deg + 1e-9]
        .into_iter()
        .flat_map(|t| bracket(thetas_deg, t).into_iter().map(|(k, _)| k))
        .collect();
    drawn.sort_unstable();
    drawn.dedup();
    drawn
}

impl LutScene {
    /// The instances of every LUT ghost for light slopes `u` in the frame `out` (the whole sensor). `system` is the live
    /// lens's (for a photo LUT it is not used). `gains[g]` multiplies the images of lens ghost `g` as it does
    /// its sprites (missing entries are 1; a photo LUT's single image is not one ghost and keeps gain 1).
    #[allow(clippy::too_many_arguments)]
    pub fn build(
        live_lut: &LiveLut,
        system: &GhostSystem,
        u: [f64; 2],
        out: Window,
        blend: &BlendSettings,
        gains: &[f32],
    ) -> Self {
        let (lut, layout) = (&live_lut.lut, &live_lut.layout);
        let (theta, alpha) = light_direction_deg(u);
        let (beta, base) = lut.symmetry.reduce(alpha);
        let min_half_mm = super::MIN_TEXEL_MM;
        let mut scene = Self { alpha_over: blend.mode == BlendMode::Alpha, ..Self::default() };
        for (lg, ghost) in lut.ghosts.iter().enumerate() {
            let photo = lut.kind == LutKind::Photo || ghost.ghost == super::PHOTO_GHOST;
            if !photo && ghost.ghost as usize >= system.ghosts.len() {
                // A LUT is checked against its lens before it is used (`GhostLut::check_for`); one that was
                // not draws nothing for a ghost the lens lacks instead of indexing past its list.
                continue;
            }
            let mode = if photo { blend.mode } else { blend.mode_of(ghost.ghost) };
            let w = mode.weight(theta);
            if !photo {
                scene.paraxial_weights.push((ghost.ghost, (1.0 - w) as f32));
            }
            let user_gain =
                if photo { 1.0 } else { f64::from(gains.get(ghost.ghost as usize).copied().unwrap_or(1.0)) };
            if w <= 0.0 || ghost.entries.is_empty() || user_gain.is_nan() || user_gain <= 0.0 {
                continue;
            }
            let live = if photo {
                ParaxialFrame { centre_mm: [0.0; 2], half_mm: 1.0, energy: 0.0 }
            } else {
                system.paraxial_frame(ghost.ghost as usize, u, min_half_mm)
            };
            let thetas = bracket(&ghost.thetas_deg, theta);
            let fitted = thetas.len() == 2 && ghost.fitted.get(thetas[0].0).copied().unwrap_or(false);
            let picks: Vec<(usize, f64)> = thetas
                .into_iter()
                .flat_map(|(t, wt)| {
                    bracket(&ghost.phis_deg, beta)
                        .into_iter()
                        .map(move |(p, wp)| (t * ghost.phis_deg.len() + p, wt * wp))
                })
                .filter(|&(_, weight)| weight > 0.0)
                .collect();
            let baked_energy: f64 = picks.iter().map(|&(k, weight)| weight * ghost.entries[k].paraxial.energy).sum();
            let ratio = if !photo && live.energy > 0.0 && baked_energy > 0.0 {
                (live.energy / baked_energy).clamp(0.25, 4.0)
            } else {
                1.0
            };
            let turned: Vec<_> = picks
                .iter()
                .map(|&(k, weight)| {
                    // The entry turned from its azimuth to the light's: a lens of revolution's ghost turns with
                    // the light; an anamorphic lens's does not (its azimuths are interpolated, not turned).
                    let residual = if system.is_anamorphic() { 0.0 } else { beta - ghost.entries[k].phi_deg };
                    let transform = mat_mul(base, rotation(residual));
                    (if fitted { live_lut.shapes[lg][k] } else { None }, transform, weight)
                })
                .collect();
            for ((k, weight), fit) in picks.into_iter().zip(fit_picks(&turned)) {
                let entry = &ghost.entries[k];
                let Some(&(page, x0, y0)) = layout.slots[lg][k].first() else { continue };
                let instance = place(
                    entry,
                    &entry.paraxial,
                    &live,
                    fit,
                    &out,
                    page,
                    [x0, y0],
                    (weight * ratio * w * blend.gain * user_gain) as f32,
                );
                if instance.is_finite() {
                    scene.instances.push(instance);
                    scene.sources.push((lg as u32, k as u32, 0));
                } else {
                    scene.dropped_non_finite += 1;
                }
            }
        }
        scene
    }

    /// Leaves out the faintest instances, as many as can go while their peaks (the entry's brightest texel
    /// times the instance's gain) sum to at most `threshold` (linear relative irradiance): what is left out
    /// adds at most `threshold` to any pixel, however many overlap, as the paraxial sprites are culled
    /// ([`crate::ghost::GhostSystem::frame_into`]); the rule a ray grid's dim jobs are chosen by
    /// ([`crate::raytrace::faintest`]). Returns how many were left out. In the alpha mode nothing is left out (a
    /// faint image still covers what lies beneath it).
    pub fn cull_faint(&mut self, threshold: f64, footprints: &[Vec<Vec<Footprint>>]) -> usize {
        if self.alpha_over || threshold.is_nan() || threshold <= 0.0 {
            return 0;
        }
        let peak = |k: usize| -> f64 {
            let texel = footprint_of(footprints, self.sources[k]).map_or(f32::MAX, |f| f.peak);
            let c = self.instances[k].colour;
            f64::from(texel) * f64::from(c[0].max(c[1]).max(c[2]).max(0.0))
        };
        let peaks: Vec<f64> = (0..self.instances.len()).map(peak).collect();
        let culled = crate::raytrace::faintest(&peaks, threshold);
        let count = culled.iter().filter(|&&c| c).count();
        if count > 0 {
            let mut k = 0;
            self.instances.retain(|_| {
                k += 1;
                !culled[k - 1]
            });
            let mut k = 0;
            self.sources.retain(|_| {
                k += 1;
                !culled[k - 1]
            });
        }
        count
    }

    /// Draws each instance from the finest mip level of its entry ([`LiveLut::level`]) whose texels span at
    /// least `MIP_TEXEL_PX` accumulation pixels of `divisor` frame pixels each, or from its coarsest level when
    /// none does (an entry without finer-than-needed texels has one level: nothing changes). The instance's quad is
    /// kept; its atlas rectangle becomes the level's, which covers the same window (a level's extent in its own
    /// texels is the entry's halved, the zero padding of an odd edge outside the quad). Alpha-composited
    /// instances keep level 0.
    pub fn choose_mips(&mut self, live: &LiveLut, divisor: u32) {
        if self.alpha_over {
            return;
        }
        let scale = divisor.max(1) as f32;
        for (inst, source) in self.instances.iter_mut().zip(self.sources.iter_mut()) {
            let (g, k) = (source.0 as usize, source.1 as usize);
            let Some(levels) = live.footprints.get(g).and_then(|f| f.get(k)).filter(|l| l.len() > 1) else {
                continue;
            };
            let Some(map) = TexelMap::new(inst, levels[0], (scale, scale)) else { continue };
            // Texels of level 0 per accumulation pixel, the largest along either axis of the pixel grid.
            let step = map.d_di[0].hypot(map.d_di[1]).max(map.d_dj[0].hypot(map.d_dj[1]));
            let mut m = 0;
            while m + 1 < levels.len() && step * MIP_TEXEL_PX > (1u32 << m) as f32 {
                m += 1;
            }
            // Level 0 is where `build` placed it.
            let Some(&(page, x0, y0)) = live.layout.slots[g][k].get(m).filter(|_| m > 0) else { continue };
            inst.rect = atlas_rect([x0, y0], levels[m].extent.map(f64::from));
            inst.page = page;
            source.2 = m as u32;
        }
    }

    /// Puts each LUT ghost's instances next to each other, the ghosts in the order they first appear and each
    /// ghost's instances in their order (a stable sort). Composited through alpha, the passes lay a run of one
    /// ghost's instances over what lies beneath at once ([`lut_pass`]): a motion-blurred frame, whose instances
    /// come time sample by time sample, is grouped so that each ghost's samples make one run. A still frame's
    /// instances are grouped already ([`LutScene::build`] places each ghost's entries together).
    pub fn group_by_ghost(&mut self) {
        let mut first = std::collections::HashMap::new();
        for (k, s) in self.sources.iter().enumerate() {
            first.entry(s.0).or_insert(k);
        }
        let mut order: Vec<usize> = (0..self.instances.len()).collect();
        order.sort_by_key(|&k| first[&self.sources[k].0]);
        self.instances = order.iter().map(|&k| self.instances[k]).collect();
        self.sources = order.iter().map(|&k| self.sources[k]).collect();
    }

    /// The weight the paraxial sprites of lens ghost `g` keep (1 for a ghost the LUT does not hold).
    pub fn paraxial_weight(&self, g: u32) -> f32 {
        self.paraxial_weights.iter().find(|(h, _)| *h == g).map_or(1.0, |(_, w)| *w)
    }
}

/// The instance drawing `entry` (baked in the paraxial frame `baked`) in the live frame `live`, laid on by
/// `fit` (normalised coordinates), into the frame `out`, with the gain `gain`.
#[allow(clippy::too_many_arguments)]
fn place(
    entry: &super::LutEntry,
    baked: &ParaxialFrame,
    live: &ParaxialFrame,
    fit: Fit,
    out: &Window,
    page: u32,
    origin: [u32; 2],
    gain: f32,
) -> LutInstance {
    let window = entry.window();
    let (w, h) = (f64::from(entry.width), f64::from(entry.height));
    let scale = live.half_mm / baked.half_mm;
    let to_pixel = |q: [f64; 2]| {
        let p = window.to_mm([(q[0] + 1.0) * 0.5 * w, (q[1] + 1.0) * 0.5 * h]);
        let n = [(p[0] - baked.centre_mm[0]) / baked.half_mm, (p[1] - baked.centre_mm[1]) / baked.half_mm];
        let m = mat_apply(fit.linear, n);
        let n = [fit.offset[0] + m[0], fit.offset[1] + m[1]];
        out.to_pixel([live.centre_mm[0] + live.half_mm * n[0], live.centre_mm[1] + live.half_mm * n[1]])
    };
    // Irradiance falls as the area grows: energy is kept when the frame is scaled (and fitted).
    let area = scale * scale * super::mat_det(fit.linear).abs();
    let (c, x1, y1) = (to_pixel([0.0, 0.0]), to_pixel([1.0, 0.0]), to_pixel([0.0, 1.0]));
    LutInstance {
        centre_axis_x: [c[0] as f32, c[1] as f32, (x1[0] - c[0]) as f32, (x1[1] - c[1]) as f32],
        axis_y: [(y1[0] - c[0]) as f32, (y1[1] - c[1]) as f32],
        page,
        _pad0: 0,
        rect: atlas_rect(origin, [w, h]),
        colour: [gain / area as f32, gain / area as f32, gain / area as f32, gain],
    }
}

/// The texture coordinates (u0, v0, u1, v1) of an image whose top-left texel is at `origin` in its atlas page
/// and whose window spans `extent` of its texels (for a mip level, the entry's size halved per level).
fn atlas_rect(origin: [u32; 2], extent: [f64; 2]) -> [f32; 4] {
    let page_side = f64::from(ATLAS_PAGE);
    let (u0, v0) = (f64::from(origin[0]) / page_side, f64::from(origin[1]) / page_side);
    [u0 as f32, v0 as f32, (u0 + extent[0] / page_side) as f32, (v0 + extent[1] / page_side) as f32]
}

/// Rows per parallel band of the CPU pass.
const BAND_ROWS: usize = 16;

/// An entry's size and the box of its lit texels (any channel non-zero; x0, x1, y0, y1 inclusive, or an
/// empty box, x0 > x1, when none is lit): what placing and binning an instance need of it, measured once per
/// LUT ([`LiveLut::footprints`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    pub width: u32,
    pub height: u32,
    /// The entry's window in this image's texels: its size at level 0, halved per mip level (a level's
    /// padded edge lies outside it). What placing maps the quad onto.
    pub extent: [f32; 2],
    pub lit: [u32; 4],
    /// The largest value of any channel of any texel (a sample never exceeds it).
    pub peak: f32,
}

/// Where an instance's entry lies over the accumulation: its texel coordinates as an affine function of the
/// accumulation pixel, and the box of texel coordinates outside which its samples are 0.
#[derive(Clone, Copy, Debug)]
struct TexelMap {
    /// Texel coordinates (x, y: `s w - 0.5`, `t h - 0.5`, as the bilinear sample takes them) of the
    /// accumulation pixel (i, j): `origin + i d_di + j d_dj`.
    origin: [f32; 2],
    d_di: [f32; 2],
    d_dj: [f32; 2],
    /// Where a sample can be non-zero: inside the quad (|q| <= 1 is -0.5..w - 0.5 in texel coordinates) and
    /// within a texel of the entry's lit texels. x_lo, x_hi, y_lo, y_hi.
    support: [f32; 4],
    /// The same, without the lit texels (the quad alone): the per-pixel test of the shader.
    quad: [f32; 4],
}

/// One instance made ready for [`lut_pass`]: its entry, colour and texel map.
struct Prepared<'a> {
    entry: &'a LutEntry,
    colour: [f32; 4],
    map: TexelMap,
    /// The LUT ghost it draws: composited through alpha, a run of instances of one ghost is composited once.
    ghost: u32,
}

impl TexelMap {
    /// `scale`: image pixels per accumulation pixel. `None` for an empty entry, a degenerate quad or no lit
    /// texel.
    fn new(inst: &LutInstance, footprint: Footprint, scale: (f32, f32)) -> Option<Self> {
        if footprint.width == 0 || footprint.height == 0 {
            return None;
        }
        // texel = (q * 0.5 + 0.5) * size - 0.5 at p = ((i + 0.5) sx, (j + 0.5) sy): affine in (i, j).
        let q_of = inst.inverse()?;
        let [w, h] = footprint.extent;
        let (sx, sy) = scale;
        let texel = |q: [f32; 2]| [(q[0] * 0.5 + 0.5) * w - 0.5, (q[1] * 0.5 + 0.5) * h - 0.5];
        let origin = texel(q_of([0.5 * sx, 0.5 * sy]));
        let step_i = texel(q_of([1.5 * sx, 0.5 * sy]));
        let step_j = texel(q_of([0.5 * sx, 1.5 * sy]));
        let d_di = [step_i[0] - origin[0], step_i[1] - origin[1]];
        let d_dj = [step_j[0] - origin[0], step_j[1] - origin[1]];
        let quad = [-0.5, w - 0.5, -0.5, h - 0.5];
        let [lx0, lx1, ly0, ly1] = footprint.lit.map(|v| v as f32);
        let support = [quad[0].max(lx0 - 1.0), quad[1].min(lx1 + 1.0), quad[2].max(ly0 - 1.0), quad[3].min(ly1 + 1.0)];
        let finite = origin.iter().chain(&d_di).chain(&d_dj).all(|v| v.is_finite());
        (finite && support[0] <= support[1] && support[2] <= support[3]).then_some(Self {
            origin,
            d_di,
            d_dj,
            support,
            quad,
        })
    }

    /// The accumulation pixels (x range, y range) of the support box's corners: where a sample can be
    /// non-zero. `None` when the map from pixels to texels is singular.
    fn pixel_bounds(&self) -> Option<[[f32; 2]; 2]> {
        let det = self.d_di[0] * self.d_dj[1] - self.d_dj[0] * self.d_di[1];
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let [x0, x1, y0, y1] = self.support;
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for t in [[x0, y0], [x1, y0], [x0, y1], [x1, y1]] {
            let (dx, dy) = (t[0] - self.origin[0], t[1] - self.origin[1]);
            let p = [(self.d_dj[1] * dx - self.d_dj[0] * dy) / det, (self.d_di[0] * dy - self.d_di[1] * dx) / det];
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo.iter().chain(&hi).all(|v| v.is_finite())).then_some([[lo[0], hi[0]], [lo[1], hi[1]]])
    }

    /// The accumulation columns of row `j` in which a sample can be non-zero (a pixel of margin each side:
    /// the per-pixel test decides).
    fn columns(&self, j: usize, width: usize) -> std::ops::Range<usize> {
        let (mut lo, mut hi) = (f32::NEG_INFINITY, f32::INFINITY);
        let row = [self.origin[0] + j as f32 * self.d_dj[0], self.origin[1] + j as f32 * self.d_dj[1]];
        for (axis, (&start, &step)) in row.iter().zip(&self.d_di).enumerate() {
            let (from, to) = (self.support[2 * axis], self.support[2 * axis + 1]);
            if step == 0.0 {
                if start < from || start > to {
                    return 0..0;
                }
            } else {
                let (a, b) = ((from - start) / step, (to - start) / step);
                lo = lo.max(a.min(b));
                hi = hi.min(a.max(b));
            }
        }
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return 0..0;
        }
        let first = (lo - 1.0).floor().max(0.0).min(width as f32) as usize;
        let end = (hi + 2.0).ceil().max(0.0).min(width as f32) as usize;
        first..end
    }
}

/// The LUT instances of a frame binned into square tiles of the accumulation (what `lut_compute.wgsl` reads):
/// per tile, the instances whose lit texels can reach it, those of sampling level 0 first, then level 1, then
/// level 2 ([`instance_levels`]), each level in the frame's order (a pass over one level reads its own run).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct LutBins {
    /// Accumulation pixels a side of a tile.
    pub tile: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Per tile (rows of tiles from the top), where its list starts in `list`; then the list's length.
    pub starts: Vec<u32>,
    /// Instance indices.
    pub list: Vec<u32>,
    /// Per tile, where its instances of level 1 and of level 2 start in `list` (each run ends where the next
    /// level's, or the next tile's list, starts).
    pub splits: Vec<[u32; 2]>,
    /// Per instance, its sampling level ([`instance_levels`]).
    pub levels: Vec<u8>,
}

/// The bins of `lut_scene`'s instances over an accumulation of `acc_size` pixels for a frame of `frame_size`.
pub(crate) fn bin_instances(
    frame_size: (u32, u32),
    acc_size: (u32, u32),
    lut_scene: &LutScene,
    footprints: &[Vec<Vec<Footprint>>],
    tile: u32,
) -> LutBins {
    let (w, h) = (acc_size.0.max(1), acc_size.1.max(1));
    let tile = tile.max(1);
    let (tiles_x, tiles_y) = (w.div_ceil(tile), h.div_ceil(tile));
    let scale = (frame_size.0 as f32 / w as f32, frame_size.1 as f32 / h as f32);
    // Per instance, the tiles its lit support reaches: x0, x1, y0, y1 (inclusive), or none.
    let levels = instance_levels(frame_size, (w, h), lut_scene, footprints);
    let reach: Vec<Option<[u32; 4]>> = lut_scene
        .instances
        .iter()
        .zip(&lut_scene.sources)
        .zip(&levels)
        .map(|((inst, &source), &level)| {
            let footprint = footprint_of(footprints, source)?;
            let [bx, by] = TexelMap::new(inst, footprint, scale)?.pixel_bounds()?;
            // Sampled every 2^level pixels and upsampled, an instance reaches that much further.
            let reach = 1.0 + (1u32 << level) as f32;
            let tiles = |lo: f32, hi: f32, size: u32, count: u32| -> Option<(u32, u32)> {
                let (lo, hi) = ((lo - reach).floor().max(0.0), (hi + reach).ceil().min(size as f32 - 1.0));
                (lo <= hi).then(|| ((lo as u32 / tile).min(count - 1), (hi as u32 / tile).min(count - 1)))
            };
            let ((x0, x1), (y0, y1)) = (tiles(bx[0], bx[1], w, tiles_x)?, tiles(by[0], by[1], h, tiles_y)?);
            Some([x0, x1, y0, y1])
        })
        .collect();
    let tiles = (tiles_x * tiles_y) as usize;
    let mut counts = vec![0u32; tiles + 1];
    for r in reach.iter().flatten() {
        for ty in r[2]..=r[3] {
            for tx in r[0]..=r[1] {
                counts[(ty * tiles_x + tx) as usize] += 1;
            }
        }
    }
    let mut starts = Vec::with_capacity(tiles + 1);
    let mut total = 0u32;
    for c in &counts[..tiles] {
        starts.push(total);
        total += c;
    }
    starts.push(total);
    let mut fill = starts.clone();
    let mut list = vec![0u32; total as usize];
    for (index, r) in reach.iter().enumerate() {
        let Some(r) = r else { continue };
        for ty in r[2]..=r[3] {
            for tx in r[0]..=r[1] {
                let t = (ty * tiles_x + tx) as usize;
                list[fill[t] as usize] = index as u32;
                fill[t] += 1;
            }
        }
    }
    // Each tile's list by level, the frame's order kept within a level (a stable sort).
    let splits = (0..tiles)
        .map(|t| {
            let (start, end) = (starts[t] as usize, starts[t + 1] as usize);
            list[start..end].sort_by_key(|&i| levels[i as usize]);
            let first_of = |level: u8| start + list[start..end].partition_point(|&i| levels[i as usize] < level);
            [first_of(1) as u32, first_of(2) as u32]
        })
        .collect();
    LutBins { tile, tiles_x, tiles_y, starts, list, splits, levels }
}

/// The footprint of `(LUT ghost, entry, level)`.
fn footprint_of(footprints: &[Vec<Vec<Footprint>>], (g, k, m): (u32, u32, u32)) -> Option<Footprint> {
    footprints.get(g as usize)?.get(k as usize)?.get(m as usize).copied()
}

/// Per LUT ghost, entry and mip level, its [`Footprint`].
fn footprints(levels: &[Vec<Vec<&LutEntry>>]) -> Vec<Vec<Vec<Footprint>>> {
    levels
        .par_iter()
        .map(|ghost| {
            ghost
                .iter()
                .map(|entry| {
                    let extent = entry.first().map_or([0.0; 2], |e| [e.width as f32, e.height as f32]);
                    entry
                        .iter()
                        .enumerate()
                        .map(|(m, e)| footprint(e, extent.map(|v| v / (1u32 << m) as f32)))
                        .collect()
                })
                .collect()
        })
        .collect()
}

/// One image's [`Footprint`], its window `extent` texels.
fn footprint(e: &LutEntry, extent: [f32; 2]) -> Footprint {
    let mut b = [u32::MAX, 0, u32::MAX, 0];
    let mut peak = 0.0f32;
    for (k, t) in e.texels.iter().enumerate() {
        peak = peak.max(t[0].to_f32()).max(t[1].to_f32()).max(t[2].to_f32());
        if t.iter().any(|v| v.to_bits() & 0x7fff != 0) {
            let (x, y) = ((k % e.width as usize) as u32, (k / e.width as usize) as u32);
            b = [b[0].min(x), b[1].max(x), b[2].min(y), b[3].max(y)];
        }
    }
    let lit = if b[0] == u32::MAX { [1, 0, 1, 0] } else { b };
    Footprint { width: e.width, height: e.height, extent, lit, peak: if peak.is_finite() { peak } else { f32::MAX } }
}

/// `lut_compute.wgsl` and `lut_ghosts.wgsl`: every LUT instance onto the HDR accumulation `hdr` of a
/// `frame_width` x `frame_height` frame (the accumulation may be smaller; instances are in frame pixels), added
/// or composited over it through alpha, sampling each instance's entry exactly as the GPU samples the atlas
/// (bilinear, 0 outside the entry).
///
/// Cost follows the pixels where an entry is lit, not its quad: per instance and row, the columns where its
/// texel coordinates fall within a texel of the entry's lit texels are solved for (texel coordinates are
/// affine in the pixel), and only those are sampled (the per-pixel test of the quad is the shader's). Where
/// the processor has AVX2 and F16C each pixel's four channels are one SSE register, the half floats converted
/// by F16C, with the scalar path's products and sums in its order: the same image, bit for bit
/// ([`lut_pass_scalar`] is the scalar path alone, which a test holds it to). Bands of rows run in parallel;
/// within a pixel the instances are applied in order, so the image does not depend on the thread count.
///
/// Added instances magnified so that a texel spans a pixel or more are sampled every 2 or 4 pixels into a
/// smaller image whose bilinear upsample is added (`LUT_LEVELS`, [`instance_levels`]): on the Nikon zoom at
/// 480x320 this took the blended frame from 1.74x to 1.14x the paraxial frame at the same PSNR against the
/// reference (39.0 dB); a test holds it within 50 dB of [`lut_pass_every_pixel`].
pub fn lut_pass(frame_size: (u32, u32), lut_scene: &LutScene, live: &LiveLut, hdr: &mut HdrImage) {
    lut_pass_on(frame_size, lut_scene, live, hdr, true, true);
}

/// [`lut_pass`] without the SSE path, whatever the processor (what the SSE path is tested against).
pub fn lut_pass_scalar(frame_size: (u32, u32), lut_scene: &LutScene, live: &LiveLut, hdr: &mut HdrImage) {
    lut_pass_on(frame_size, lut_scene, live, hdr, false, true);
}

/// [`lut_pass`] with every instance sampled at every pixel (no coarse `LUT_LEVELS`): what the coarse levels
/// are measured against.
pub fn lut_pass_every_pixel(frame_size: (u32, u32), lut_scene: &LutScene, live: &LiveLut, hdr: &mut HdrImage) {
    lut_pass_on(frame_size, lut_scene, live, hdr, true, false);
}

fn lut_pass_on(
    frame_size: (u32, u32),
    lut_scene: &LutScene,
    live: &LiveLut,
    hdr: &mut HdrImage,
    simd: bool,
    coarse: bool,
) {
    let (w, h) = (hdr.width, hdr.height);
    let scale = (frame_size.0 as f32 / w as f32, frame_size.1 as f32 / h as f32);
    let alpha_over = lut_scene.alpha_over;
    // Per level (1, 2, 4 accumulation pixels a sample), the instances drawn at it, in the frame's order.
    let mut levels: [Vec<Prepared>; LUT_LEVELS] = Default::default();
    let of = instance_levels(frame_size, (w, h), lut_scene, &live.footprints);
    for ((inst, &source), &level) in lut_scene.instances.iter().zip(&lut_scene.sources).zip(&of) {
        let level = if coarse { level } else { 0 };
        let (Some(entry), Some(footprint)) = (live.level(source), footprint_of(&live.footprints, source)) else {
            continue;
        };
        let k = (1u32 << level) as f32;
        if let Some(map) = TexelMap::new(inst, footprint, (scale.0 * k, scale.1 * k)) {
            levels[usize::from(level)].push(Prepared { entry, colour: inst.colour, map, ghost: source.0 });
        }
    }
    draw_level(&levels[0], alpha_over, hdr, simd);
    for (level, prepared) in levels.iter().enumerate().skip(1) {
        if prepared.is_empty() {
            continue;
        }
        let k = 1u32 << level;
        let mut coarse = HdrImage::black(w.div_ceil(k), h.div_ceil(k));
        draw_level(prepared, false, &mut coarse, simd);
        add_upsampled(&coarse, k, hdr);
    }
}

/// Levels of sampling density of the LUT pass: a LUT image magnified so that one texel spans at least
/// `1 / MAX_TEXELS_PER_SAMPLE` accumulation pixels x 2^level is sampled every 2^level pixels (level 1: 2, level 2:
/// 4) into an image that much smaller, then added to the accumulation by bilinear upsampling (the same
/// interpolation the texels get): a quarter or a sixteenth of the samples, where the samples would otherwise
/// repeat the texels' own interpolation. Alpha blending composites instances in order, so it stays at level 0.
pub(crate) const LUT_LEVELS: usize = 3;
/// The most texels between neighbouring samples at a coarser level (see [`LUT_LEVELS`]).
pub(crate) const MAX_TEXELS_PER_SAMPLE: f32 = 1.0;

/// Per instance of `lut_scene`, the level (`LUT_LEVELS`) it is sampled at over an accumulation of `acc_size`
/// pixels for a frame of `frame_size`: the coarsest at which neighbouring samples stay within
/// `MAX_TEXELS_PER_SAMPLE` texels; 0 when composited through alpha, or when the instance draws nothing. The
/// CPU twin ([`lut_pass`]), the bins (`bin_instances`) and the compute pass (`lut_compute.wgsl`) all take it from
/// here.
pub fn instance_levels(
    frame_size: (u32, u32),
    acc_size: (u32, u32),
    lut_scene: &LutScene,
    footprints: &[Vec<Vec<Footprint>>],
) -> Vec<u8> {
    let scale = (frame_size.0 as f32 / acc_size.0.max(1) as f32, frame_size.1 as f32 / acc_size.1.max(1) as f32);
    lut_scene
        .instances
        .iter()
        .zip(&lut_scene.sources)
        .map(|(inst, &source)| {
            let Some(map) = footprint_of(footprints, source).and_then(|f| TexelMap::new(inst, f, scale)) else {
                return 0;
            };
            if lut_scene.alpha_over {
                return 0;
            }
            let step = map.d_di[0].hypot(map.d_di[1]).max(map.d_dj[0].hypot(map.d_dj[1]));
            let mut level = 0;
            while level + 1 < LUT_LEVELS && step * (2u32 << level) as f32 <= MAX_TEXELS_PER_SAMPLE {
                level += 1;
            }
            level as u8
        })
        .collect()
}

/// The instances `prepared` onto `hdr` (their maps made for its size), in bands of rows in parallel: added, or
/// composited over it through alpha one run of a ghost's instances at a time ([`composite_runs`]).
fn draw_level(prepared: &[Prepared], alpha_over: bool, hdr: &mut HdrImage, simd: bool) {
    if prepared.is_empty() {
        return;
    }
    let (w, h) = (hdr.width as usize, hdr.height as usize);
    hdr.pixels.par_chunks_mut(w * BAND_ROWS).enumerate().for_each(|(band, chunk)| {
        let y0 = band * BAND_ROWS;
        let rows = y0..(y0 + BAND_ROWS).min(h);
        if alpha_over {
            composite_runs(prepared, rows, w, chunk, simd);
        } else {
            add_band(prepared, rows, w, chunk, simd, false);
        }
    });
}

/// The instances `prepared` added onto the rows `rows` of `chunk` (and their coverage to its fourth channel
/// when `with_coverage`): on the SSE path where `simd` and the processor allow, else the scalar one.
fn add_band(
    prepared: &[Prepared],
    rows: std::ops::Range<usize>,
    width: usize,
    chunk: &mut [[f32; 4]],
    simd: bool,
    with_coverage: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if simd && has_avx2_f16c() {
        // SAFETY: the processor has AVX2 and F16C (checked at run time).
        return unsafe { lut_band_avx2(prepared, rows, width, chunk, with_coverage) };
    }
    let _ = simd;
    lut_band(prepared, rows, width, chunk, |inst, i, f, p| bilinear_add(inst, with_coverage, i, f, p));
}

/// Composited through alpha: each run of consecutive instances of one LUT ghost (its up to four interpolated
/// entries, and under motion blur every time sample's, [`LutScene::group_by_ghost`]) is summed first, colour
/// and coverage (`s`), then laid over what lies beneath once: `p = s_rgb + (1 - clamp(s_a, 0, 1)) p`. So n
/// samples of a still light that each cover a pixel with a / n leave `1 - a` of what lies beneath, the time
/// average, where compositing them one after another left `(1 - a / n)^n`; a run of one instance is the plain
/// `over` (the same bits). Per row only the columns a run reached are composited.
fn composite_runs(
    prepared: &[Prepared],
    rows: std::ops::Range<usize>,
    width: usize,
    chunk: &mut [[f32; 4]],
    simd: bool,
) {
    let mut sum = vec![[0.0f32; 4]; chunk.len()];
    let mut reached = vec![(usize::MAX, 0usize); rows.len()];
    for run in prepared.chunk_by(|a, b| a.ghost == b.ghost) {
        for inst in run {
            for (y, span) in rows.clone().zip(reached.iter_mut()) {
                let columns = inst.map.columns(y, width);
                if !columns.is_empty() {
                    *span = (span.0.min(columns.start), span.1.max(columns.end));
                }
            }
        }
        add_band(run, rows.clone(), width, &mut sum, simd, true);
        for (r, span) in reached.iter_mut().enumerate() {
            if span.0 >= span.1 {
                continue;
            }
            let at = r * width;
            for (p, s) in chunk[at + span.0..at + span.1].iter_mut().zip(&mut sum[at + span.0..at + span.1]) {
                let keep = 1.0 - s[3].clamp(0.0, 1.0);
                for ch in 0..3 {
                    p[ch] = s[ch] + p[ch] * keep;
                }
                *s = [0.0; 4];
            }
            *span = (usize::MAX, 0);
        }
    }
}

/// The coarse image's bilinear upsample by `k` (its pixel (i, j) centred on accumulation pixel position
/// ((i + 0.5) k, (j + 0.5) k); indices clamped at the edges) added to `hdr`'s colour channels. What
/// `upsampled_at` in `lut_compute.wgsl` computes per instance.
fn add_upsampled(coarse: &HdrImage, k: u32, hdr: &mut HdrImage) {
    let (w, cw, ch) = (hdr.width as usize, coarse.width as usize, coarse.height as usize);
    let inv = 1.0 / k as f32;
    hdr.pixels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (j0, fy) = coarse_index((y as f32 + 0.5) * inv - 0.5, ch);
        let (top, bottom) = (&coarse.pixels[j0[0] * cw..][..cw], &coarse.pixels[j0[1] * cw..][..cw]);
        for (x, p) in row.iter_mut().enumerate() {
            let (i0, fx) = coarse_index((x as f32 + 0.5) * inv - 0.5, cw);
            for c in 0..3 {
                let t = top[i0[0]][c] * (1.0 - fx) + top[i0[1]][c] * fx;
                let b = bottom[i0[0]][c] * (1.0 - fx) + bottom[i0[1]][c] * fx;
                p[c] += t * (1.0 - fy) + b * fy;
            }
        }
    });
}

/// The two coarse indices either side of the coarse coordinate `u` (clamped to `0..n`) and the fraction.
#[inline(always)]
fn coarse_index(u: f32, n: usize) -> ([usize; 2], f32) {
    let i = u.floor();
    let last = n.saturating_sub(1) as f32;
    ([i.clamp(0.0, last) as usize, (i + 1.0).clamp(0.0, last) as usize], u - i)
}

#[cfg(target_arch = "x86_64")]
fn has_avx2_f16c() -> bool {
    crate::optics::simd_level() >= 1 && std::arch::is_x86_feature_detected!("f16c")
}

/// [`lut_band`] compiled for AVX2, each pixel's four channels in one SSE register: the texels converted by
/// F16C, then the same products and sums as [`bilinear_add`] in the same order (the same image, bit for bit),
/// the fourth channel (coverage) summed too when `with_coverage`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,f16c")]
unsafe fn lut_band_avx2(
    prepared: &[Prepared],
    rows: std::ops::Range<usize>,
    width: usize,
    chunk: &mut [[f32; 4]],
    with_coverage: bool,
) {
    use std::arch::x86_64::{
        __m128, _mm_add_ps, _mm_blend_ps, _mm_cvtph_ps, _mm_loadl_epi64, _mm_loadu_ps, _mm_mul_ps, _mm_set_ps,
        _mm_set1_ps, _mm_setzero_ps, _mm_storeu_ps,
    };
    lut_band(prepared, rows, width, chunk, |inst, [ix, iy], [fx, fy], p| {
        let (ew, eh) = (inst.entry.width as i32, inst.entry.height as i32);
        let texels = &inst.entry.texels;
        let at = |i: i32, j: i32| -> __m128 {
            if (i as u32) < ew as u32 && (j as u32) < eh as u32 {
                // SAFETY: the index is inside the entry's texels, each 8 readable bytes (four half floats).
                unsafe { _mm_cvtph_ps(_mm_loadl_epi64(texels.as_ptr().add((j * ew + i) as usize).cast())) }
            } else {
                _mm_setzero_ps()
            }
        };
        let (a, b, c, d) = (at(ix, iy), at(ix + 1, iy), at(ix, iy + 1), at(ix + 1, iy + 1));
        let (fxv, gxv, fyv, gyv) = (_mm_set1_ps(fx), _mm_set1_ps(1.0 - fx), _mm_set1_ps(fy), _mm_set1_ps(1.0 - fy));
        let top = _mm_add_ps(_mm_mul_ps(a, gxv), _mm_mul_ps(b, fxv));
        let bottom = _mm_add_ps(_mm_mul_ps(c, gxv), _mm_mul_ps(d, fxv));
        let t = _mm_add_ps(_mm_mul_ps(top, gyv), _mm_mul_ps(bottom, fyv));
        let [c0, c1, c2, c3] = inst.colour;
        // SAFETY: `p` is 16 readable and writable bytes.
        let old = unsafe { _mm_loadu_ps(p.as_ptr()) };
        let new = _mm_add_ps(_mm_mul_ps(t, _mm_set_ps(c3, c2, c1, c0)), old);
        if with_coverage {
            unsafe { _mm_storeu_ps(p.as_mut_ptr(), new) };
        } else {
            // The fourth channel is not an image channel: it keeps its value.
            unsafe { _mm_storeu_ps(p.as_mut_ptr(), _mm_blend_ps::<0b1000>(new, old)) };
        }
    });
}

/// One accumulation pixel `p` of instance `inst`: the entry's bilinear sample at the texel `i` + `f` (0 outside
/// the entry) times the instance's colour added, and its coverage (alpha times the alpha gain) added to the
/// fourth channel when `with_coverage` (a run's sum, [`composite_runs`]).
#[inline(always)]
fn bilinear_add(inst: &Prepared, with_coverage: bool, [ix, iy]: [i32; 2], [fx, fy]: [f32; 2], p: &mut [f32; 4]) {
    let texels = &inst.entry.texels;
    let t = inst.entry.bilinear_at([i64::from(ix), i64::from(iy)], [fx, fy], |k| texels[k].map(half::f16::to_f32));
    let channels = if with_coverage { 4 } else { 3 };
    for ch in 0..channels {
        p[ch] += t[ch] * inst.colour[ch];
    }
}

/// The instances over the accumulation rows `rows` (`chunk` holds them, `width` pixels a row): per instance and
/// row the columns where it can be lit, per pixel inside its quad `pixel(instance, texel, fraction, p)` (the
/// texel coordinate's floor and fraction: [`bilinear_add`] or its SSE form).
#[inline(always)]
fn lut_band(
    prepared: &[Prepared],
    rows: std::ops::Range<usize>,
    width: usize,
    chunk: &mut [[f32; 4]],
    pixel: impl Fn(&Prepared, [i32; 2], [f32; 2], &mut [f32; 4]),
) {
    for inst in prepared {
        let [qx0, qx1, qy0, qy1] = inst.map.quad;
        for y in rows.clone() {
            let columns = inst.map.columns(y, width);
            if columns.is_empty() {
                continue;
            }
            let m = &inst.map;
            let row = [m.origin[0] + y as f32 * m.d_dj[0], m.origin[1] + y as f32 * m.d_dj[1]];
            let out = &mut chunk[(y - rows.start) * width..][..width];
            for x in columns {
                let (tx, ty) = (row[0] + x as f32 * m.d_di[0], row[1] + x as f32 * m.d_di[1]);
                if !(tx >= qx0 && tx <= qx1 && ty >= qy0 && ty <= qy1) {
                    continue;
                }
                // tx, ty >= -0.5 here: truncation of tx + 1 is the floor.
                let (ix, iy) = ((tx + 1.0) as i32 - 1, (ty + 1.0) as i32 - 1);
                pixel(inst, [ix, iy], [tx - ix as f32, ty - iy as f32], &mut out[x]);
            }
        }
    }
}

/// Mip levels are made of an entry while halving it leaves at least this many texels across (the default bake
/// `res`): an entry baked finer than that for its detail ([`crate::bake::BakeSettings::diagonal_texels`]) can be
/// drawn at the default's resolution where its texels would be smaller than the frame needs.
pub const MIP_FLOOR_TEXELS: u32 = 128;
/// [`LutScene::choose_mips`] draws an instance from the finest level whose texels span at least this many
/// accumulation pixels: finer texels would be sampled at every pixel ([`instance_levels`] samples every 2 pixels
/// from 2 on) for detail a bilinear sample between them cannot show. Measured on the Heliar's rim ghost (README,
/// "LUT images without stair steps"): 3 left the 480x320 frame at the default's 31.8 dB where 2 gives 33.3 dB,
/// and the Nikon zoom's blended frame at 480x320 costs the same with either.
pub(crate) const MIP_TEXEL_PX: f32 = 2.0;

/// A LUT ready to draw: the LUT, the mip levels of its fine entries and where they all lie in the atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveLut {
    pub lut: GhostLut,
    /// Per LUT ghost and entry, its mip levels beyond the entry itself (each [`LutEntry::halved`] from the one
    /// before) while they keep [`MIP_FLOOR_TEXELS`] texels across; none for a photo LUT.
    pub mips: Vec<Vec<Vec<LutEntry>>>,
    pub layout: AtlasLayout,
    /// Per LUT ghost and entry, its shape for [`super::fit_picks`] (measured once, on load).
    pub shapes: Vec<Vec<Option<EntryShape>>>,
    /// This LUT's identity (`crate::fingerprint::unique_id`; a clone keeps it), for upload caches.
    pub id: u64,
    /// Per LUT ghost, entry and level, its size and lit texels (measured once, on load): what [`lut_pass`]
    /// samples and `bin_instances` bins.
    pub footprints: Vec<Vec<Vec<Footprint>>>,
}

impl LiveLut {
    pub fn new(lut: GhostLut) -> Self {
        let photo = lut.kind == LutKind::Photo;
        let mips: Vec<Vec<Vec<LutEntry>>> = crate::timing::span("mip levels", || {
            lut.ghosts
                .par_iter()
                .map(|g| {
                    g.entries
                        .iter()
                        .map(|e| {
                            let mut levels: Vec<LutEntry> = Vec::new();
                            loop {
                                let last = levels.last().unwrap_or(e);
                                if photo || last.is_empty() || last.width.max(last.height) / 2 < MIP_FLOOR_TEXELS {
                                    break levels;
                                }
                                levels.push(last.halved());
                            }
                        })
                        .collect()
                })
                .collect()
        });
        let levels = all_levels(&lut, &mips);
        let layout = crate::timing::span("atlas layout", || AtlasLayout::new(&levels));
        let shapes = crate::timing::span("entry shapes", || {
            lut.ghosts.par_iter().map(|g| g.entries.iter().map(LutEntry::shape).collect()).collect()
        });
        let footprints = crate::timing::span("footprints", || footprints(&levels));
        Self { lut, mips, layout, shapes, id: crate::fingerprint::unique_id(), footprints }
    }

    /// Image `m` of entry `k` of LUT ghost `g` (0: the entry, then its [`Self::mips`]).
    pub fn level(&self, (g, k, m): (u32, u32, u32)) -> Option<&LutEntry> {
        let entry = self.lut.ghosts.get(g as usize)?.entries.get(k as usize)?;
        if m == 0 { Some(entry) } else { self.mips.get(g as usize)?.get(k as usize)?.get(m as usize - 1) }
    }

    /// Atlas page `page` ([`AtlasLayout::page_f16`]) of every level.
    pub fn atlas_page(&self, page: u32) -> Vec<[half::f16; 4]> {
        self.layout.page_f16(&all_levels(&self.lut, &self.mips), page)
    }
}

/// Per LUT ghost and entry, its images finest first: the entry, then its mip levels.
fn all_levels<'a>(lut: &'a GhostLut, mips: &'a [Vec<Vec<LutEntry>>]) -> Vec<Vec<Vec<&'a LutEntry>>> {
    lut.ghosts
        .iter()
        .zip(mips)
        .map(|(g, m)| g.entries.iter().zip(m).map(|(e, l)| std::iter::once(e).chain(l).collect()).collect())
        .collect()
}
