//! `ghosts.wgsl` on the CPU: the instanced ghost sprites into the HDR accumulation, and the per-ghost moments
//! of the same fragments. Each mask map is affine per axis, `(scale_x q_x, scale_y q_y) + offset`: the x scale
//! in the map, the y scale in `GhostInstance::scale_y` (the same number for a lens of revolution; an
//! anamorphic lens's sprites are ellipses).
//!
//! Each enabled stop map names the level of [`GhostMasks`] it reads (`stops[k][3]`: 1 the base mask of
//! [`crate::aperture::DEFAULT_MASK_SIZE`] texels, 2 and 3 the same shape rasterised at twice and four times
//! that), picked per sprite by [`GhostMasks::assign_levels`] so that a texel spans at most
//! `MAX_PIXELS_PER_TEXEL` accumulation pixels where a finer level exists. A mask's edge is a texel wide (the
//! rasteriser's anti-aliasing) and the bilinear lookup widens it to two: at the base size a frame-filling sprite
//! of a 4K frame has edges 32 pixels wide, which the fast pass shades pixel by pixel, while the sprites
//! smaller than the base mask would alias if they read a finer one. The fast pass ([`ghost_pass`]) shades a row's
//! open span (every mask exactly 1) as one run and its edge pixels one by one, each evaluating only the masks not
//! open over the row's whole walk (`mask_product_of`; a factor of 1 changes no bit of the product).

use rayon::prelude::*;

use super::quads::{accumulation_scale, covered};
use crate::aperture::{Aperture, ApertureMask, ApertureShape};
use crate::color::luminance;
use crate::ghost::MAX_DISCS;
use crate::image::{GhostMoments, HdrImage};
use crate::render::{FlareScene, GhostInstance};

/// A stop map `[x scale, offset x, offset y, level]` with its y scale `scale_y` (level 0: not enabled).
fn stop_mask(masks: &GhostMasks, map: [f32; 4], scale_y: f32, q: [f32; 2]) -> f32 {
    if map[3] == 0.0 {
        return 1.0;
    }
    masks.mask(map[3]).sample(map[0] * q[0] + map[1], scale_y * q[1] + map[2])
}

/// An anti-aliased unit disc in the map `[x scale, offset x, offset y, anti-alias width]` with y scale `scale_y`:
/// the coverage of a clear aperture (a width of 0 marks an empty slot: 1).
fn disc_mask(map: [f32; 4], scale_y: f32, q: [f32; 2]) -> f32 {
    if map[3] == 0.0 {
        return 1.0;
    }
    let (x, y) = (map[0] * q[0] + map[1], scale_y * q[1] + map[2]);
    let r = (x * x + y * y).sqrt();
    (0.5 + (1.0 - r) / map[3]).clamp(0.0, 1.0)
}

/// The fragment shader's mask product at the quad coordinate `q`: 0 outside the quad, else every clear-aperture
/// disc times the aperture mask at every enabled stop crossing. The discs first: outside one nothing passes,
/// and the aperture lookups are skipped.
fn mask_product(inst: &GhostInstance, masks: &GhostMasks, q: [f32; 2]) -> f32 {
    mask_product_of(inst, masks, q, ALL_MASKS)
}

/// Every mask of a sprite live: bits 0-3 its discs, bits 4-6 its stop crossings.
const ALL_MASKS: u32 = (1 << (FIRST_STOP_BIT + 3)) - 1;
/// The bit of stop crossing 0 in a live set (disc k is bit k; the shader's four discs).
const FIRST_STOP_BIT: usize = MAX_DISCS;
/// An open interval's bound where a mask does not narrow it (far beyond any quad's [-1, 1], and finite: a
/// column worked out from it stays finite; `OPEN_FAR` in ghosts_compute.wgsl).
const OPEN_FAR: f32 = 1.0e30;

/// [`mask_product`] with only the masks of `live` evaluated: the others are exactly 1 at `q` (a row's walk
/// leaves out those whose fully open interval holds all its edge pixels; `sweep_instance`), and a factor of 1
/// changes no bit of the product.
fn mask_product_of(inst: &GhostInstance, masks: &GhostMasks, q: [f32; 2], live: u32) -> f32 {
    if q[0].abs() > 1.0 || q[1].abs() > 1.0 {
        return 0.0;
    }
    let mut m = 1.0;
    for (k, (disc, &scale_y)) in inst.discs.iter().zip(&inst.disc_scale_y).enumerate() {
        if live & (1 << k) != 0 {
            m *= disc_mask(*disc, scale_y, q);
        }
    }
    for (k, (stop, &scale_y)) in inst.stops.iter().zip(&inst.scale_y).enumerate() {
        if live & (1 << (FIRST_STOP_BIT + k)) == 0 {
            continue;
        }
        if m <= 0.0 {
            return 0.0;
        }
        m *= stop_mask(masks, *stop, scale_y, q);
    }
    m
}

/// The fragments of one instance in the accumulation rows `rows`: `fragment(x, y, m)` for every covered pixel
/// with the mask product m > 0, exactly as `ghosts.wgsl` shades them.
fn shade_instance(
    inst: &GhostInstance,
    masks: &GhostMasks,
    scale: (f32, f32),
    size: (usize, usize),
    rows: std::ops::Range<usize>,
    mut fragment: impl FnMut(usize, usize, f32),
) {
    let [cx, cy, hx, hy] = inst.centre_half;
    // A mask whose whole quad maps inside its fully open disc is 1 everywhere (a speed-up only): skip it.
    let inst = masks.without_open_stops(inst);
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
            let m = mask_product(inst, masks, q);
            if m > 0.0 {
                fragment(x, y, m);
            }
        }
    }
}

/// The interval of the quad coordinate q_x in which a row at `q_y` can have light: inside the quad, every disc
/// (grown by its anti-aliasing half-width) and the mask square [-1, 1]^2 of every stop crossing; `None` when
/// the row has none.
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
    for ([scale, ox, oy, aa], scale_y) in inst.discs.into_iter().zip(inst.disc_scale_y) {
        if aa == 0.0 {
            continue;
        }
        let reach = 1.0 + 0.5 * aa;
        let fy = scale_y * q_y + oy;
        if fy.abs() > reach || !clip(scale, ox, (reach * reach - fy * fy).max(0.0).sqrt()) {
            return None;
        }
    }
    for ([scale, ox, oy, enabled], scale_y) in inst.stops.into_iter().zip(inst.scale_y) {
        if enabled != 0.0 && ((scale_y * q_y + oy).abs() > 1.0 || !clip(scale, ox, 1.0)) {
            return None;
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Rows per parallel band of the CPU ghost pass: small enough that the bands of a 480x320 frame share out
/// evenly over a few threads, large enough that each band's sweep over the instances stays cheap.
const BAND_ROWS: usize = 8;

/// `ghosts.wgsl` pixel by pixel: every instance into a cleared HDR accumulation image (`hdr_width` x
/// `hdr_height`), every covered pixel shaded with its mask lookups, as the fragment shader does. The oracle of
/// [`ghost_pass`] (a test holds the two within a fraction of an 8-bit step) and of the GPU comparison.
#[cfg(test)]
pub(crate) fn ghost_pass_direct(scene: &FlareScene, masks: &GhostMasks) -> HdrImage {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let scale = accumulation_scale(scene);
    let mut pixels = vec![[0.0f32; 4]; w * h];
    pixels.par_chunks_mut(w * BAND_ROWS).enumerate().for_each(|(band, chunk)| {
        let y0 = band * BAND_ROWS;
        let rows = y0..(y0 + BAND_ROWS).min(h);
        for inst in &scene.instances {
            shade_instance(inst, masks, scale, (w, h), rows.clone(), |x, y, m| {
                let p = &mut chunk[(y - y0) * w + x];
                for (value, colour) in p.iter_mut().zip(inst.colour).take(3) {
                    *value += colour * m;
                }
            });
        }
    });
    HdrImage { width: scene.hdr_width, height: scene.hdr_height, pixels }
}

/// `ghosts.wgsl` on the CPU, fast: the same image as `ghost_pass_direct` (to float rounding) for a fraction
/// of the work. In each row a sprite has an **open span**, where every clear-aperture disc and every stop mask
/// are exactly 1 (no lookup can change the fragment, which is the instance's colour), flanked by its edges. The
/// edges are shaded pixel by pixel as the shader does; the open span is added in O(1) as two entries of a
/// per-row difference buffer (f64), summed along the row once per band after every instance. A frame-filling
/// ghost then costs its edges, not its area. Where the open span lies comes from `MaskRows` (per band of
/// mask rows, where its bilinear sample is exactly 1 and where it can be non-zero), with half a texel of margin
/// on the safe side: a pixel in doubt is shaded. Bands of rows run in parallel (rayon); the result does not
/// depend on the thread count.
pub fn ghost_pass(scene: &FlareScene, masks: &GhostMasks) -> HdrImage {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let scale = accumulation_scale(scene);
    let instances: Vec<GhostInstance> = scene.instances.iter().map(|inst| masks.without_open_stops(inst)).collect();
    let mut pixels = vec![[0.0f32; 4]; w * h];
    pixels.par_chunks_mut(w * BAND_ROWS).enumerate().for_each(|(band, chunk)| {
        let y0 = band * BAND_ROWS;
        let rows = y0..(y0 + BAND_ROWS).min(h);
        // Per row of the band, w + 1 running differences of RGB.
        let mut spans = vec![[0.0f64; 3]; rows.len() * (w + 1)];
        for inst in &instances {
            sweep_instance(inst, masks, scale, (w, h), rows.clone(), |fragment| match fragment {
                Fragment::Open { y, x0, x1 } => {
                    let row = &mut spans[(y - y0) * (w + 1)..][..w + 1];
                    // RGB only: the fourth channel of `colour` is not an image channel.
                    for (c, colour) in inst.colour.iter().take(3).map(|&v| f64::from(v)).enumerate() {
                        row[x0][c] += colour;
                        row[x1 + 1][c] -= colour;
                    }
                }
                Fragment::Edge { x, y, m } => {
                    let p = &mut chunk[(y - y0) * w + x];
                    for (value, colour) in p.iter_mut().zip(inst.colour).take(3) {
                        *value += colour * m;
                    }
                }
            });
        }
        for (r, row) in spans.chunks_exact(w + 1).enumerate() {
            let mut run = [0.0f64; 3];
            for (x, d) in row[..w].iter().enumerate() {
                for c in 0..3 {
                    run[c] += d[c];
                }
                if run != [0.0; 3] {
                    let p = &mut chunk[r * w + x];
                    for c in 0..3 {
                        p[c] += run[c] as f32;
                    }
                }
            }
        }
    });
    HdrImage { width: scene.hdr_width, height: scene.hdr_height, pixels }
}

/// The instance with every stop crossing whose whole quad maps inside its mask level's fully open disc
/// disabled (its mask is 1 wherever the quad is); `open_radius(code)` is the open radius of the level that a
/// stop map's last field `code` names.
pub(crate) fn without_open_stops(inst: &GhostInstance, open_radius: impl Fn(f32) -> f32) -> GhostInstance {
    let mut inst = *inst;
    for (stop, &scale_y) in inst.stops.iter_mut().zip(&inst.scale_y) {
        if stop[3] != 0.0 && reach(*stop, scale_y) <= open_radius(stop[3]) {
            stop[3] = 0.0;
        }
    }
    inst
}

/// How far from its centre a map `[x scale, offset x, offset y, _]` with y scale `scale_y` reaches over the
/// quad [-1, 1]^2.
fn reach(map: [f32; 4], scale_y: f32) -> f32 {
    (map[1].abs() + map[0].abs()).hypot(map[2].abs() + scale_y.abs())
}

/// The most accumulation pixels one texel of a sprite's stop mask may span before the sprite reads the next
/// finer level of [`GhostMasks`] (where there is one): the texel of a finer level is never under a pixel.
pub(crate) const MAX_PIXELS_PER_TEXEL: f32 = 4.0;

/// The most levels [`GhostMasks`] has: [`crate::aperture::DEFAULT_MASK_SIZE`] x 1, 2 and 4 texels a side.
pub(crate) const MASK_LEVELS: usize = 3;

/// One level of [`GhostMasks`]: the mask, its per-band table and its fully open radius.
#[derive(Debug)]
pub struct MaskLevel {
    pub mask: ApertureMask,
    pub(crate) rows: MaskRows,
    pub open_radius: f32,
}

/// The stop's mask at the resolutions the ghost passes pick from, per sprite and stop crossing (see the module
/// documentation): level 0 is the base mask every other pass reads ([`crate::flare::PreparedFlare::mask`]);
/// a blade or round stop has `MASK_LEVELS` levels, each rasterised from the shape itself, while an image stop
/// has only its base (a finer raster of an image would repeat its texels, with no sharper edge).
#[derive(Debug)]
pub struct GhostMasks {
    levels: Vec<MaskLevel>,
}

impl GhostMasks {
    /// The levels of `aperture`'s shape: `base` (its raster at the base size), then, for blades or a circle,
    /// the shape rasterised at twice and four times that.
    pub fn new(aperture: &Aperture, base: ApertureMask) -> Self {
        let finer = match aperture.shape {
            ApertureShape::Image { .. } => 0,
            _ => MASK_LEVELS - 1,
        };
        let size = base.size;
        let masks = std::iter::once(base).chain((1..=finer).map(|l| aperture.rasterise(size << l)));
        Self::from_masks(masks.collect())
    }

    /// Levels from masks of any sizes, the coarsest first (tests; a single mask is a one-level set). At least
    /// one mask, and at most `MASK_LEVELS` (what the GPU passes bind): a caller's error otherwise, which
    /// panics.
    pub fn from_masks(masks: Vec<ApertureMask>) -> Self {
        assert!((1..=MASK_LEVELS).contains(&masks.len()), "{} mask levels", masks.len());
        let levels = masks
            .into_iter()
            .map(|mask| MaskLevel { rows: MaskRows::new(&mask), open_radius: mask.open_radius(), mask })
            .collect();
        Self { levels }
    }

    /// The levels, the coarsest first.
    pub fn levels(&self) -> &[MaskLevel] {
        &self.levels
    }

    /// The level a stop map's last field names (1 the first; clamped to the levels there are).
    pub fn level(&self, code: f32) -> &MaskLevel {
        &self.levels[level_index(code, self.levels.len())]
    }

    pub fn mask(&self, code: f32) -> &ApertureMask {
        &self.level(code).mask
    }

    /// [`without_open_stops`] with the open radius of the level each stop map names.
    pub(crate) fn without_open_stops(&self, inst: &GhostInstance) -> GhostInstance {
        without_open_stops(inst, |code| self.level(code).open_radius)
    }

    /// The level code (1 the coarsest) for a stop map whose mask coordinate moves `pixels_per_unit`
    /// accumulation pixels per unit: the coarsest level whose texel spans at most `MAX_PIXELS_PER_TEXEL`
    /// of them, else the finest.
    pub fn pick(&self, pixels_per_unit: f32) -> f32 {
        let fits = |l: &MaskLevel| pixels_per_unit * 2.0 / l.mask.size as f32 <= MAX_PIXELS_PER_TEXEL;
        let index = self.levels.iter().position(fits).unwrap_or(self.levels.len() - 1);
        (index + 1) as f32
    }

    /// Fits `scene`'s instances to its accumulation pixels: settles the point sprites
    /// ([`Self::settle_point_sprites`]), then names in each enabled stop map the level its sprite reads
    /// ([`Self::pick`] for the faster of the map's two axes, in the scene's accumulation pixels).
    pub fn assign_levels(&self, scene: &mut crate::render::FlareScene) {
        self.settle_point_sprites(scene);
        let (sx, sy) = accumulation_scale(scene);
        for inst in &mut scene.instances {
            let [_, _, hx, hy] = inst.centre_half;
            for (stop, &scale_y) in inst.stops.iter_mut().zip(&inst.scale_y) {
                if stop[3] != 0.0 {
                    // Pixels per unit of the mask coordinate; a map of scale 0 (the whole sprite one texel)
                    // reads the finest level, and so does one whose ratio is not a number.
                    let per_unit = (hx.abs() / (stop[0].abs() * sx)).max(hy.abs() / (scale_y.abs() * sy));
                    stop[3] = self.pick(if per_unit.is_nan() { f32::INFINITY } else { per_unit });
                }
            }
        }
    }
}

impl GhostMasks {
    /// Draws every sprite whose quad spans at most [`POINT_SPRITE_PX`] accumulation pixels along both axes (a
    /// ghost focused near the sensor, or one clamped to the frame's smallest sprite) as a point: a quad of
    /// exactly [`POINT_SPRITE_PX`] pixels a side with no masks, its colour the sprite's energy (its colour times
    /// its quad's area) times the share of the quad its masks let through, spread over the new quad's area.
    ///
    /// Why: a mask sampled at the centres of the one to four pixels such a quad covers lets through 0 to 4 times
    /// the light it should as the sprite moves by a fraction of a pixel, so a moving light strobes the ghost
    /// and a motion-blurred one breaks its streak into dashes; a quad of a whole number of pixels covers that
    /// many pixel centres wherever it lies, and its energy is the same at every position. The share is the mean
    /// over a `POINT_SHARE_GRID`-square grid of the quad of the mask product with hard disc edges and the
    /// base aperture mask (the detail no pixel can show). The three passes draw the instance this leaves.
    pub fn settle_point_sprites(&self, scene: &mut crate::render::FlareScene) {
        let (sx, sy) = accumulation_scale(scene);
        let base = &self.levels[0].mask;
        for inst in &mut scene.instances {
            let [cx, cy, hx, hy] = inst.centre_half;
            let point = 0.5 * POINT_SPRITE_PX;
            if !(hx.abs() <= point * sx && hy.abs() <= point * sy) {
                continue;
            }
            let mut lit = 0.0f64;
            for j in 0..POINT_SHARE_GRID {
                for i in 0..POINT_SHARE_GRID {
                    let cell = |k: usize| -1.0 + (2 * k + 1) as f32 / POINT_SHARE_GRID as f32;
                    let q = [cell(i), cell(j)];
                    let inside_discs = inst.discs.iter().zip(&inst.disc_scale_y).all(|(d, &scale_y)| {
                        let (x, y) = (d[0] * q[0] + d[1], scale_y * q[1] + d[2]);
                        d[3] == 0.0 || x * x + y * y <= 1.0
                    });
                    if !inside_discs {
                        continue;
                    }
                    let open = inst.stops.iter().zip(&inst.scale_y).fold(1.0f32, |m, (stop, &scale_y)| {
                        if stop[3] == 0.0 {
                            m
                        } else {
                            m * base.sample(stop[0] * q[0] + stop[1], scale_y * q[1] + stop[2])
                        }
                    });
                    lit += f64::from(open);
                }
            }
            let share = lit / (POINT_SHARE_GRID * POINT_SHARE_GRID) as f64;
            let (nx, ny) = (point * sx, point * sy);
            let gain = (share * f64::from(hx.abs() * hy.abs()) / f64::from(nx * ny)) as f32;
            for c in &mut inst.colour[..3] {
                *c *= gain;
            }
            inst.centre_half = [cx, cy, nx.copysign(hx), ny.copysign(hy)];
            inst.stops = [[0.0; 4]; 3];
            inst.discs = [[0.0; 4]; crate::ghost::MAX_DISCS];
        }
    }
}

/// The side (accumulation pixels) at and below which a sprite is drawn as a point
/// ([`GhostMasks::settle_point_sprites`]).
pub const POINT_SPRITE_PX: f32 = 2.0;
/// Samples a side of the grid a point sprite's lit share is measured on.
pub(crate) const POINT_SHARE_GRID: usize = 16;

/// The index of the level a stop map's last field `code` names among `levels` levels: 1 the first, clamped
/// to those there are (`ghosts_compute.wgsl`'s `level_of`).
pub(crate) fn level_index(code: f32, levels: usize) -> usize {
    (code.max(1.0) as usize - 1).min(levels.saturating_sub(1))
}

/// Per band of the mask's rows (the two texel rows a bilinear sample at one v reads): the interval of u where
/// the sample is exactly 1 (every texel it reads is 255; the longest such run) and the interval outside which
/// it is 0, each shrunk or grown by half a texel. Band b holds v whose sample reads rows b - 1 and b (clamped).
#[derive(Debug)]
pub(crate) struct MaskRows {
    size: usize,
    /// Per band: open u interval (empty when lo > hi), then the non-zero u interval.
    bands: Vec<([f32; 2], [f32; 2])>,
}

impl MaskRows {
    pub(crate) fn new(mask: &ApertureMask) -> Self {
        let n = mask.size;
        let last = n.saturating_sub(1);
        let texel_u = |x: f32| (x + 0.5) / n as f32 * 2.0 - 1.0;
        let margin = 1.0 / n as f32; // half a texel in u
        let bands = (0..=n)
            .into_par_iter()
            .map(|b| {
                let (r0, r1) = (b.saturating_sub(1).min(last), b.min(last));
                let row = |j: usize| &mask.texels[j * n..(j + 1) * n];
                let (a, c) = (row(r0), row(r1));
                let mut open = [1.0f32, -1.0f32];
                let (mut best, mut start) = (0usize, None);
                for i in 0..=n {
                    let full = i < n && a[i] == 255 && c[i] == 255;
                    match (full, start) {
                        (true, None) => start = Some(i),
                        (false, Some(s)) => {
                            // Columns s..i-1 are full: the sample reads only them for x in [s, i - 1).
                            if i - s > best && i - 1 > s {
                                best = i - s;
                                open = [texel_u(s as f32) + margin, texel_u((i - 1) as f32) - margin];
                            }
                            start = None;
                        }
                        _ => {}
                    }
                }
                let nonzero: Vec<usize> = (0..n).filter(|&i| a[i] != 0 || c[i] != 0).collect();
                let support = match (nonzero.first(), nonzero.last()) {
                    (Some(&lo), Some(&hi)) => [texel_u(lo as f32 - 1.0) - margin, texel_u(hi as f32 + 1.0) + margin],
                    _ => [1.0, -1.0],
                };
                (open, support)
            })
            .collect();
        Self { size: n, bands }
    }

    /// Per band: open u lo, hi, then non-zero u lo, hi (what `ghosts_compute.wgsl` reads).
    pub(crate) fn table(&self) -> Vec<[f32; 4]> {
        self.bands.iter().map(|(open, support)| [open[0], open[1], support[0], support[1]]).collect()
    }

    /// The open and non-zero u intervals of the mask's row band at `v` (the band [`ApertureMask::sample`]
    /// reads there); `None` outside [-1, 1], where the mask is 0.
    fn at(&self, v: f32) -> Option<([f32; 2], [f32; 2])> {
        if !(-1.0..=1.0).contains(&v) {
            return None;
        }
        let y = (0.5 - v * 0.5) * self.size as f32 - 0.5;
        let y0 = (y + 1.0) as i32 - 1;
        self.bands.get((y0 + 1).max(0) as usize).copied()
    }
}

/// What [`sweep_instance`] finds in a row.
enum Fragment {
    /// The pixels x0..=x1 of row y are open: each one's fragment is the instance's colour.
    Open { y: usize, x0: usize, x1: usize },
    /// An edge pixel with the mask product m > 0.
    Edge { x: usize, y: usize, m: f32 },
}

/// Narrows the interval `lo..=hi` of q to where `scale q + offset` lies in `u` (empty, `1..=-1`, where it
/// never does).
fn clip(lo: &mut f32, hi: &mut f32, scale: f32, offset: f32, u: [f32; 2]) {
    if u[0] > u[1] {
        *lo = 1.0;
        *hi = -1.0;
    } else if scale == 0.0 {
        if offset < u[0] || offset > u[1] {
            *lo = 1.0;
            *hi = -1.0;
        }
    } else {
        let (a, b) = ((u[0] - offset) / scale, (u[1] - offset) / scale);
        *lo = lo.max(a.min(b));
        *hi = hi.min(a.max(b));
    }
}

/// Where `scale q + offset` lies in `u`: a mask's own open interval (all of it, `OPEN_FAR`, before [`clip`]).
fn own_interval(scale: f32, offset: f32, u: [f32; 2]) -> (f32, f32) {
    let (mut lo, mut hi) = (-OPEN_FAR, OPEN_FAR);
    clip(&mut lo, &mut hi, scale, offset, u);
    (lo, hi)
}

/// One instance over the rows `rows` for [`ghost_pass`]: its open runs, and its edge pixels shaded as
/// [`shade_instance`] shades them.
fn sweep_instance(
    inst: &GhostInstance,
    masks: &GhostMasks,
    scale: (f32, f32),
    size: (usize, usize),
    rows: std::ops::Range<usize>,
    mut emit: impl FnMut(Fragment),
) {
    let [cx, cy, hx, hy] = inst.centre_half;
    let (sx, sy) = scale;
    let covered_rows = covered(cy, hy, sy, size.1);
    let columns = covered(cx, hx, sx, size.0);
    let to_column = |q: f32| (cx + q * hx) / sx - 0.5;
    for y in covered_rows.start.max(rows.start)..covered_rows.end.min(rows.end) {
        let q_y = ((y as f32 + 0.5) * sy - cy) / hy;
        let Some((mut q_lo, mut q_hi)) = row_support(inst, q_y) else { continue };
        // The open interval, narrowed by each mask below (`clip`); the support, by where each mask is non-zero.
        // Each mask's own open interval (all of it where it is off; empty where it is nowhere exactly 1 on the
        // row): the open interval is their intersection with the support, and the live set comes from them.
        let mut own = [(-OPEN_FAR, OPEN_FAR); FIRST_STOP_BIT + 3];
        // Each disc: fully open within radius 1 - aa / 2 of its centre.
        for (k, ([scale, ox, oy, aa], scale_y)) in inst.discs.into_iter().zip(inst.disc_scale_y).enumerate() {
            if aa == 0.0 {
                continue;
            }
            let (inner, fy) = (1.0 - 0.5 * aa, scale_y * q_y + oy);
            own[k] = if inner <= fy.abs() {
                (1.0, -1.0)
            } else {
                let half = (inner * inner - fy * fy).sqrt();
                own_interval(scale, ox, [-half, half])
            };
        }
        // The open interval starts from the row's support before the stops narrow it (as the shader's does).
        let support = (q_lo, q_hi);
        let mut lit = true;
        for (k, ([scale, ox, oy, enabled], scale_y)) in inst.stops.into_iter().zip(inst.scale_y).enumerate() {
            if enabled == 0.0 {
                continue;
            }
            let Some((open, support)) = masks.level(enabled).rows.at(scale_y * q_y + oy) else {
                lit = false;
                break;
            };
            own[FIRST_STOP_BIT + k] = own_interval(scale, ox, open);
            clip(&mut q_lo, &mut q_hi, scale, ox, support);
        }
        let (o_lo, o_hi) = own.iter().fold(support, |(lo, hi), &(a, b)| (lo.max(a), hi.min(b)));
        if !lit || q_lo > q_hi {
            continue;
        }
        let (a, b) = (to_column(q_lo), to_column(q_hi));
        let first = (a.min(b).floor() - 1.0).max(columns.start as f32) as usize;
        let last = ((a.max(b).ceil() + 2.0).max(0.0) as usize).min(columns.end);
        // Open columns: those whose centres lie inside the open interval by a pixel's margin.
        let open_columns = |lo: f32, hi: f32| {
            let (a, b) = (to_column(lo), to_column(hi));
            (a.min(b).ceil() + 1.0, a.max(b).floor() - 1.0)
        };
        let (open_first, open_last) = if o_lo < o_hi {
            let (lo, hi) = open_columns(o_lo, o_hi);
            let (lo, hi) = (lo.max(first as f32), hi.min(last as f32 - 1.0));
            if lo <= hi { (lo as usize, hi as usize) } else { (usize::MAX, 0) }
        } else {
            (usize::MAX, 0)
        };
        // The live masks: those not open (by the same pixel's margin) at every column the row shades.
        let mut live = 0;
        for (k, &(lo, hi)) in own.iter().enumerate() {
            let (lo, hi) = if lo < hi { open_columns(lo, hi) } else { (1.0, -1.0) };
            if !(lo <= first as f32 && hi >= last as f32 - 1.0) {
                live |= 1 << k;
            }
        }
        let has_open = open_first <= open_last;
        let mut x = first;
        while x < last {
            if has_open && x == open_first {
                emit(Fragment::Open { y, x0: open_first, x1: open_last });
                x = open_last + 1;
                continue;
            }
            let m = mask_product_of(inst, masks, [((x as f32 + 0.5) * sx - cx) / hx, q_y], live);
            if m > 0.0 {
                emit(Fragment::Edge { x, y, m });
            }
            x += 1;
        }
    }
}

/// Per ghost (`ghosts` of them), the luminance-weighted energy [`ghost_pass`] draws in the frame and its
/// first moments in image pixels: what the metrics compare with the reference's ghosts.
pub fn ghost_moments(scene: &FlareScene, masks: &GhostMasks, ghosts: usize) -> Vec<GhostMoments> {
    let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
    let (sx, sy) = accumulation_scale(scene);
    let mut moments = vec![GhostMoments::default(); ghosts];
    for (inst, &g) in scene.instances.iter().zip(&scene.instance_ghosts) {
        let luma = luminance([inst.colour[0], inst.colour[1], inst.colour[2]].map(f64::from));
        // Each accumulation pixel stands for sx x sy image pixels.
        let area = f64::from(sx * sy);
        shade_instance(inst, masks, (sx, sy), (w, h), 0..h, |x, y, m| {
            let p = [(x as f64 + 0.5) * f64::from(sx), (y as f64 + 0.5) * f64::from(sy)];
            moments[g as usize].add_sample(luma * f64::from(m) * area, p);
        });
    }
    moments
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aperture::{Aperture, ApertureShape};
    use crate::flare::{FlareConfig, PreparedFlare};
    use crate::optics::library::builtin_lens;
    use crate::render::cpu::tonemap_pixel;

    /// The fast pass draws the per-pixel pass's image: every display value within a fifth of an 8-bit step
    /// (the bound the fast renderer promises is half a step), on lenses with frame-filling ghosts, blades and a
    /// round stop, a light inside and outside the frame, full and quarter accumulation.
    #[test]
    fn the_fast_pass_draws_the_direct_pass_image() {
        let blades = |n, rotation_deg, roundness| ApertureShape::Blades { count: n, rotation_deg, roundness };
        let cases = [
            ("nikon_zoom_28_75mm", blades(6, 0.0, 0.0), [3.0, 2.0], 1),
            ("pbrt_dgauss_50mm", blades(5, 17.0, 0.3), [-8.0, 4.0], 1),
            ("heliar", ApertureShape::Circle, [12.0, -3.0], 2),
            ("pbrt_dgauss_50mm", blades(7, 3.0, 0.0), [30.0, 25.0], 1),
        ];
        let mut edge_share = Vec::new();
        for (id, shape, light, divisor) in cases {
            let config = FlareConfig { aperture: Aperture { shape, f_number: None }, ..FlareConfig::default() };
            let flare = PreparedFlare::new(&builtin_lens(id).unwrap(), &config).unwrap();
            let (mut scene, _) = flare.scene(light, 240, 160);
            if divisor > 1 {
                scene.hdr_width = scene.width.div_ceil(divisor);
                scene.hdr_height = scene.height.div_ceil(divisor);
            }
            assert!(scene.instances.len() > 10, "{id}: {} instances", scene.instances.len());
            let masks = &flare.ghost_masks;
            let (fast, direct) = (ghost_pass(&scene, masks), ghost_pass_direct(&scene, masks));
            let gain = scene.globals.flare_gain;
            let (mut worst, mut lit) = (0.0f32, 0);
            for (a, b) in fast.pixels.iter().zip(&direct.pixels) {
                let (da, db) = (
                    tonemap_pixel([a[0], a[1], a[2]].map(|v| v * gain), &scene),
                    tonemap_pixel([b[0], b[1], b[2]].map(|v| v * gain), &scene),
                );
                for c in 0..3 {
                    worst = worst.max((da[c] - db[c]).abs());
                    assert!(a[c].is_finite() && a[c] >= 0.0);
                }
                lit += usize::from(b[0] + b[1] + b[2] > 0.0);
            }
            assert!(lit > 1000, "{id}: only {lit} lit pixels");
            assert!(worst * 255.0 < 0.2, "{id}: display values differ by {} of an 8-bit step", worst * 255.0);
            // The fast pass shaded only the edges: count its per-pixel fragments against the direct pass's.
            let (w, h) = (scene.hdr_width as usize, scene.hdr_height as usize);
            let scale = accumulation_scale(&scene);
            let (mut edges, mut all) = (0usize, 0usize);
            for inst in &scene.instances {
                let inst = masks.without_open_stops(inst);
                sweep_instance(&inst, masks, scale, (w, h), 0..h, |f| match f {
                    Fragment::Edge { .. } => edges += 1,
                    Fragment::Open { .. } => {}
                });
                shade_instance(&inst, masks, scale, (w, h), 0..h, |_, _, _| all += 1);
            }
            edge_share.push((id, edges as f64 / all as f64));
        }
        eprintln!("edge pixels shaded / direct fragments: {edge_share:?}");
        // On the frame-filling ghosts of the Nikon most fragments are open.
        assert!(edge_share[0].1 < 0.25, "{edge_share:?}");
    }

    /// The sprites whose base mask texel would span more than `MAX_PIXELS_PER_TEXEL` pixels read a finer level
    /// (the Nikon's frame-filling ghosts at 960x540: every level is used), the small ones keep the base; the
    /// fast pass then shades far fewer edge pixels than with the base mask alone, and still draws the direct
    /// pass's image. An image stop has its base level only, and every sprite reads it.
    #[test]
    fn large_sprites_read_finer_levels_and_shade_fewer_edges() {
        let config = FlareConfig::default();
        let flare = PreparedFlare::new(&builtin_lens("nikon_zoom_28_75mm").unwrap(), &config).unwrap();
        let masks = &*flare.ghost_masks;
        assert_eq!(masks.levels().iter().map(|l| l.mask.size).collect::<Vec<_>>(), [256, 512, 1024]);
        assert_eq!(&masks.levels()[0].mask, flare.mask());
        let (scene, _) = flare.scene([9.0, 5.0], 960, 540);
        let mut per_level = [0usize; 4];
        for inst in &scene.instances {
            let [_, _, hx, hy] = inst.centre_half;
            for (stop, scale_y) in inst.stops.iter().zip(inst.scale_y) {
                per_level[stop[3] as usize] += 1;
                if stop[3] != 0.0 {
                    // The texel of the level read spans at most the bound, or the level is the finest.
                    let size = masks.mask(stop[3]).size as f32;
                    let texel_px = (hx.abs() / stop[0].abs()).max(hy.abs() / scale_y.abs()) * 2.0 / size;
                    assert!(texel_px <= MAX_PIXELS_PER_TEXEL || stop[3] == 3.0, "{texel_px} px a texel at {size}");
                    if stop[3] > 1.0 {
                        let coarser = texel_px * 2.0;
                        assert!(coarser > MAX_PIXELS_PER_TEXEL, "{coarser} px a texel would have done");
                    }
                }
            }
        }
        assert!(per_level[1..].iter().all(|&n| n > 50), "stop maps per level (0: off): {per_level:?}");
        // The edges at 1920x1080, where the level of most frame-filling sprites is finer.
        let base = GhostMasks::from_masks(vec![flare.mask().clone()]);
        let (large, _) = flare.scene([9.0, 5.0], 1920, 1080);
        let edges = |masks: &GhostMasks| {
            let mut edges = 0usize;
            for inst in &large.instances {
                let inst = masks.without_open_stops(inst);
                let size = (large.hdr_width as usize, large.hdr_height as usize);
                sweep_instance(&inst, masks, accumulation_scale(&large), size, 0..size.1, |f| {
                    edges += usize::from(matches!(f, Fragment::Edge { .. }))
                });
            }
            edges
        };
        let (coarse, fine) = (edges(&base), edges(masks));
        eprintln!("edge pixels at 1920x1080: {coarse} with the base mask, {fine} with its levels");
        assert!((fine as f64) < 0.7 * coarse as f64, "{fine} edge pixels against {coarse}");
        let (fast, direct) = (ghost_pass(&scene, masks), ghost_pass_direct(&scene, masks));
        let gain = scene.globals.flare_gain;
        let mut worst = 0.0f32;
        for (a, b) in fast.pixels.iter().zip(&direct.pixels) {
            let shown = |p: &[f32; 4]| tonemap_pixel([p[0], p[1], p[2]].map(|v| v * gain), &scene);
            let (da, db) = (shown(a), shown(b));
            worst = (0..3).fold(worst, |m, c| m.max((da[c] - db[c]).abs()));
        }
        assert!(worst * 255.0 < 0.2, "display values differ by {} of an 8-bit step", worst * 255.0);

        let image = ApertureShape::Image { size: 8, luminance: vec![1.0; 64] };
        let image = Aperture { shape: image, f_number: None };
        let masks = GhostMasks::new(&image, image.rasterise(256));
        assert_eq!(masks.levels().len(), 1);
        assert_eq!(masks.pick(1e9), 1.0);
    }
}
