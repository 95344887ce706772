//! Splatting traced triangles with their energy conserved: each triangle clipped to the pixels it covers (a box
//! filter, [`Polygon`]), its attributes interpolated at each covered part, the aperture mask looked up at every
//! stop crossing, and the light added to a per-thread [`Accumulator`] that becomes a [`RayGridImage`].

use crate::aperture::ApertureMask;
use crate::image::{GhostMoments, HdrImage};

use super::grid::{Vertex, Window};

/// Counts of one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayGridStats {
    pub jobs: usize,
    pub rays: u64,
    pub triangles: u64,
    /// Jobs (ghost x wavelength) where no ray passed everything.
    pub empty_jobs: usize,
}
/// A ray-traced ghost image and what it is made of.
#[derive(Clone, Debug)]
pub struct RayGridImage {
    /// Linear irradiance relative to the light, ghosts only, `width` x `height`.
    pub hdr: HdrImage,
    /// Per ghost: luminance-weighted energy and its first moments, over the pixels in the frame.
    pub moments: Vec<GhostMoments>,
    pub stats: RayGridStats,
}
/// Pixels a side of an accumulator's tile.
const TILE: usize = 32;

/// Per-thread accumulation: energy per pixel (relative irradiance x mm^2) and per-ghost moments.
///
/// The energy is held in tiles of [`TILE`] x [`TILE`] pixels, each made (zeroed) when a triangle first lands
/// in it: rayon's fold starts a fresh accumulator for every piece of the job list it hands a thread, and a
/// ghost's light covers a part of the frame, so the cost of an accumulator (made, merged) follows the pixels
/// its jobs touch, not the frame's size. The sums are those of one frame-sized buffer, bit for bit (a tile not
/// yet made holds zeros).
pub(super) struct Accumulator {
    pub(super) width: usize,
    pub(super) height: usize,
    tiles_x: usize,
    tiles: Vec<Option<Vec<[f64; 3]>>>,
    pub(super) moments: Vec<GhostMoments>,
    pub(super) stats: RayGridStats,
}
impl Accumulator {
    pub(super) fn new(width: usize, height: usize, ghosts: usize) -> Self {
        let tiles_x = width.div_ceil(TILE);
        Self {
            width,
            height,
            tiles_x,
            tiles: vec![None; tiles_x * height.div_ceil(TILE)],
            moments: vec![GhostMoments::default(); ghosts],
            stats: RayGridStats::default(),
        }
    }

    /// The energy of every pixel, rows from the top (zeros where nothing landed).
    #[cfg(test)]
    pub(super) fn energy(&self) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; self.width * self.height];
        for (t, tile) in self.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            let (x0, y0) = ((t % self.tiles_x) * TILE, (t / self.tiles_x) * TILE);
            for y in y0..(y0 + TILE).min(self.height) {
                for x in x0..(x0 + TILE).min(self.width) {
                    out[y * self.width + x] = tile[(y - y0) * TILE + (x - x0)];
                }
            }
        }
        out
    }

    pub(super) fn merge(mut self, other: Self) -> Self {
        for (a, b) in self.tiles.iter_mut().zip(other.tiles) {
            match (a.as_mut(), b) {
                (Some(a), Some(b)) => {
                    for (p, q) in a.iter_mut().zip(&b) {
                        for c in 0..3 {
                            p[c] += q[c];
                        }
                    }
                }
                (None, Some(b)) => *a = Some(b),
                (_, None) => {}
            }
        }
        for (a, b) in self.moments.iter_mut().zip(&other.moments) {
            a.add(b);
        }
        self.stats.jobs += other.stats.jobs;
        self.stats.rays += other.stats.rays;
        self.stats.triangles += other.stats.triangles;
        self.stats.empty_jobs += other.stats.empty_jobs;
        self
    }

    /// The image of `window`: energy per pixel / pixel area = irradiance; moments likewise in irradiance x
    /// pixel^2, as the paraxial renderer's.
    pub(super) fn into_image(self, window: &Window) -> RayGridImage {
        let pixel_area_mm2 = window.px_per_mm().powi(-2);
        let moments = self
            .moments
            .iter()
            .map(|m| GhostMoments {
                energy: m.energy / pixel_area_mm2,
                sum_x: m.sum_x / pixel_area_mm2,
                sum_y: m.sum_y / pixel_area_mm2,
            })
            .collect();
        // Pixels no tile reached stay black; the tiles are read where they are (no frame of f64 made).
        let mut pixels = vec![[0.0, 0.0, 0.0, 1.0]; self.width * self.height];
        for (t, tile) in self.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            let (x0, y0) = ((t % self.tiles_x) * TILE, (t / self.tiles_x) * TILE);
            for y in y0..(y0 + TILE).min(self.height) {
                for x in x0..(x0 + TILE).min(self.width) {
                    let v = tile[(y - y0) * TILE + (x - x0)].map(|c| (c / pixel_area_mm2) as f32);
                    let v = v.map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 });
                    pixels[y * self.width + x] = [v[0], v[1], v[2], 1.0];
                }
            }
        }
        RayGridImage {
            hdr: HdrImage { width: self.width as u32, height: self.height as u32, pixels },
            moments,
            stats: self.stats,
        }
    }

    /// Adds `energy` (scalar, before the spectral weight) at pixel (x, y) when it lies in the frame.
    #[inline(always)]
    pub(super) fn add(&mut self, x: i64, y: i64, energy: f64, job: &JobFrame) {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 || energy.is_nan() || energy <= 0.0 {
            return;
        }
        let (x, y) = (x as usize, y as usize);
        let tile = self.tiles[(y / TILE) * self.tiles_x + x / TILE].get_or_insert_with(|| vec![[0.0; 3]; TILE * TILE]);
        let p = &mut tile[(y % TILE) * TILE + x % TILE];
        // A channel the wavelength does not weigh is left alone (adding 0 would change nothing).
        for (value, weight) in p.iter_mut().zip(job.rgb) {
            if weight != 0.0 {
                *value += energy * weight;
            }
        }
        let luma = energy * job.luma;
        self.moments[job.ghost].add_sample(luma, [x as f64 + 0.5, y as f64 + 0.5]);
    }

    /// Adds `energy(x_centre)` at each pixel of row `y` from column `x_lo` to before `x_hi` (the pixels a row of a
    /// triangle covers whole): the same sums as [`Self::add`] pixel by pixel, with the tile looked up once per
    /// tile the run crosses and the ghost's moments summed once for the run.
    #[inline(always)]
    pub(super) fn add_run(&mut self, y: i64, x_lo: i64, x_hi: i64, job: &JobFrame, energy: impl Fn(f64) -> f64) {
        let (x_lo, x_hi) = (x_lo.max(0), x_hi.min(self.width as i64));
        if y < 0 || y >= self.height as i64 || x_lo >= x_hi {
            return;
        }
        let (y, x_hi) = (y as usize, x_hi as usize);
        let (mut sum, mut sum_x) = (0.0, 0.0);
        let mut x = x_lo as usize;
        while x < x_hi {
            let end = ((x / TILE + 1) * TILE).min(x_hi);
            let tile =
                self.tiles[(y / TILE) * self.tiles_x + x / TILE].get_or_insert_with(|| vec![[0.0; 3]; TILE * TILE]);
            let row = &mut tile[(y % TILE) * TILE..(y % TILE + 1) * TILE];
            for (p, column) in row[x % TILE..x % TILE + (end - x)].iter_mut().zip(x..end) {
                let centre = column as f64 + 0.5;
                let e = energy(centre);
                if e > 0.0 {
                    // Sums of non-negative terms from +0, so adding 0 for a channel the wavelength does not weigh
                    // leaves it as `add` does by skipping it.
                    for (value, weight) in p.iter_mut().zip(job.rgb) {
                        *value += e * weight;
                    }
                    sum += e;
                    sum_x += e * centre;
                }
            }
            x = end;
        }
        let m = &mut self.moments[job.ghost];
        m.energy += sum * job.luma;
        m.sum_x += sum_x * job.luma;
        m.sum_y += sum * job.luma * (y as f64 + 0.5);
    }
}
/// What a job's triangles need besides their vertices.
pub(super) struct JobFrame<'a> {
    pub(super) ghost: usize,
    pub(super) rgb: [f64; 3],
    pub(super) luma: f64,
    pub(super) stop_count: usize,
    pub(super) mask: &'a ApertureMask,
    /// [`RayGridRenderer::open_radius2`].
    pub(super) open_radius2: f64,
    /// cos(theta) x the entrance area of one triangle (mm^2).
    pub(super) triangle_flux: f64,
}
/// A quantity linear over a triangle: `a0 + ax x + ay y` at the pixel position (x, y).
#[derive(Clone, Copy, Debug)]
pub(super) struct Plane {
    pub(super) a0: f64,
    pub(super) ax: f64,
    pub(super) ay: f64,
}
impl Plane {
    #[inline(always)]
    pub(super) fn at(&self, p: [f64; 2]) -> f64 {
        self.a0 + self.ax * p[0] + self.ay * p[1]
    }
}
/// Barycentric interpolation over one triangle in pixel space: the three barycentric coordinates as planes.
pub(super) struct Interpolator {
    pub(super) bary: [Plane; 3],
}
impl Interpolator {
    /// `None` for a triangle of zero area.
    pub(super) fn new(v: [[f64; 2]; 3]) -> Option<Self> {
        let area2 = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
        if area2 == 0.0 || !area2.is_finite() {
            return None;
        }
        // l_i is the edge function of the opposite edge (q, r) over twice the area.
        let plane = |q: [f64; 2], r: [f64; 2]| Plane {
            a0: (q[0] * r[1] - q[1] * r[0]) / area2,
            ax: (q[1] - r[1]) / area2,
            ay: (r[0] - q[0]) / area2,
        };
        Some(Self { bary: [plane(v[1], v[2]), plane(v[2], v[0]), plane(v[0], v[1])] })
    }

    /// The plane of a quantity with values `f` at the three vertices.
    #[inline(always)]
    pub(super) fn attribute(&self, f: [f64; 3]) -> Plane {
        let [l0, l1, l2] = self.bary;
        Plane {
            a0: l0.a0 * f[0] + l1.a0 * f[1] + l2.a0 * f[2],
            ax: l0.ax * f[0] + l1.ax * f[1] + l2.ax * f[2],
            ay: l0.ay * f[0] + l1.ay * f[1] + l2.ay * f[2],
        }
    }
}
/// The attributes of one triangle as planes: the light passing at a pixel is `shade`.
pub(super) struct TriangleShader<'a> {
    pub(super) ratio: Plane,
    pub(super) weight: Plane,
    pub(super) stops: [[Plane; 2]; 3],
    /// Every stop crossing of the triangle lies in the disc where the mask is fully open (the stop coordinates
    /// are linear over it, so it does if its corners do): no mask lookup needed.
    pub(super) open: bool,
    pub(super) frame: &'a JobFrame<'a>,
}
impl<'a> TriangleShader<'a> {
    #[inline(always)]
    pub(super) fn new(tri: [&Vertex; 3], interp: &Interpolator, frame: &'a JobFrame<'a>) -> Self {
        let attr = |f: &dyn Fn(&Vertex) -> f64| interp.attribute([f(tri[0]), f(tri[1]), f(tri[2])]);
        Self {
            ratio: attr(&|v| v.ratio),
            weight: attr(&|v| v.weight),
            stops: std::array::from_fn(|k| {
                if k < frame.stop_count {
                    [attr(&|v| v.stops[k][0]), attr(&|v| v.stops[k][1])]
                } else {
                    [Plane { a0: 0.0, ax: 0.0, ay: 0.0 }; 2]
                }
            }),
            open: Self::open(tri, frame),
            frame,
        }
    }

    /// The attributes averaged over the vertices, constant: for a triangle collapsed to a line or a point.
    pub(super) fn mean(tri: [&Vertex; 3], frame: &'a JobFrame<'a>) -> Self {
        let mean = |f: &dyn Fn(&Vertex) -> f64| {
            let value = (f(tri[0]) + f(tri[1]) + f(tri[2])) / 3.0;
            Plane { a0: value, ax: 0.0, ay: 0.0 }
        };
        Self {
            ratio: mean(&|v| v.ratio),
            weight: mean(&|v| v.weight),
            stops: std::array::from_fn(|k| [mean(&|v| v.stops[k][0]), mean(&|v| v.stops[k][1])]),
            open: Self::open(tri, frame),
            frame,
        }
    }

    pub(super) fn open(tri: [&Vertex; 3], frame: &JobFrame) -> bool {
        let inside = |s: [f64; 2]| s[0] * s[0] + s[1] * s[1] < frame.open_radius2;
        tri.iter().all(|v| v.stops[..frame.stop_count].iter().all(|&s| inside(s)))
    }

    /// Weight x aperture masks at the pixel position `p`; 0 where vignetted.
    #[inline(always)]
    pub(super) fn shade(&self, p: [f64; 2]) -> f64 {
        if self.ratio.at(p) > 1.0 {
            return 0.0;
        }
        let mut m = self.weight.at(p).max(0.0);
        if self.open {
            return m;
        }
        for [su, sv] in &self.stops[..self.frame.stop_count] {
            if m == 0.0 {
                break;
            }
            m *= f64::from(self.frame.mask.sample(su.at(p) as f32, sv.at(p) as f32));
        }
        m
    }
}
/// Splats one triangle with its energy conserved; `false` when it carries no light.
#[inline(always)]
pub(super) fn splat_triangle(tri: [&Vertex; 3], frame: &JobFrame, acc: &mut Accumulator) -> bool {
    if !tri.iter().all(|v| v.valid) || tri.iter().all(|v| v.ratio > 1.0) {
        return false;
    }
    // Entirely outside the mask's square on one side at some crossing: nothing passes.
    for k in 0..frame.stop_count {
        for axis in 0..2 {
            if tri.iter().all(|v| v.stops[k][axis] > 1.0) || tri.iter().all(|v| v.stops[k][axis] < -1.0) {
                return false;
            }
        }
    }
    let pixels = [tri[0].pixel, tri[1].pixel, tri[2].pixel];
    let x_lo = pixels.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let x_hi = pixels.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
    let y_lo = pixels.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let y_hi = pixels.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let (w, h) = (acc.width as f64, acc.height as f64);
    if x_lo > w + 1.0 || y_lo > h + 1.0 || x_hi < -1.0 || y_hi < -1.0 {
        return true; // Its light is real but lands off the frame.
    }
    let at = |l: [f64; 3]| [0, 1].map(|c| l[0] * pixels[0][c] + l[1] * pixels[1][c] + l[2] * pixels[2][c]);
    let Some(interp) = Interpolator::new(pixels) else {
        // Collapsed to a line or a point (a ghost focused there): all of its energy in the pixel of its centroid.
        let c = at([1.0 / 3.0; 3]);
        let energy = frame.triangle_flux * TriangleShader::mean(tri, frame).shade(c);
        acc.add(c[0].floor() as i64, c[1].floor() as i64, energy, frame);
        return true;
    };
    let shader = TriangleShader::new(tri, &interp, frame);
    let b = &interp.bary;
    let area_px = 0.5 / (b[0].ax * b[1].ay - b[0].ay * b[1].ax).abs();
    let (col, row) = (x_lo.floor(), y_lo.floor());
    if x_hi < col + 1.0 && y_hi < row + 1.0 {
        // Inside one pixel: all of it there.
        acc.add(col as i64, row as i64, frame.triangle_flux * shader.shade(at([1.0 / 3.0; 3])), frame);
        return true;
    }
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies.
    let irradiance = frame.triangle_flux / area_px;
    // The part in the frame, cut into rows, each row into pixels.
    let mut rows = Polygon::triangle(pixels);
    if x_lo < 0.0 || y_lo < 0.0 || x_hi > w || y_hi > h {
        rows = rows.clip(0, 0.0, false).clip(0, w, true).clip(1, 0.0, false).clip(1, h, true);
    }
    let Some([_, y_first, ..]) = rows.bounds() else { return true };
    // Cut in place, row by row and pixel by pixel (no polygon is copied whole: at 136 bytes each, copies were
    // a tenth of a bake's time).
    let mut rows = Cutter::new(rows);
    let (mut columns, mut piece) = (Cutter::new(Polygon::EMPTY), Polygon::EMPTY);
    let mut y = y_first.floor();
    while rows.rest().count >= 3 {
        rows.cut_below(1, y + 1.0, columns.reset());
        if let Some([x_first, ..]) = columns.rest().bounds() {
            // The pixels the row's part covers whole (area 1, centroid at the centre) are added without cutting.
            let (full_lo, full_hi) = columns.rest().full_columns(y);
            let mut x = x_first.floor();
            while columns.rest().count >= 3 {
                if x == full_lo {
                    let centre_y = y + 0.5;
                    acc.add_run(y as i64, full_lo as i64, full_hi as i64, frame, |centre_x| {
                        irradiance * shader.shade([centre_x, centre_y])
                    });
                    columns.cut_below(0, full_hi, &mut piece);
                    x = full_hi;
                    continue;
                }
                columns.cut_below(0, x + 1.0, &mut piece);
                if let Some((area, centroid)) = piece.area_centroid() {
                    acc.add(x as i64, y as i64, irradiance * area * shader.shade(centroid), frame);
                }
                x += 1.0;
            }
        }
        y += 1.0;
    }
    true
}
/// A polygon cut into pieces from one side, in place: [`Self::cut_below`] moves the part below a line out and
/// keeps the rest, alternating between two buffers.
struct Cutter {
    buffers: [Polygon; 2],
    current: usize,
}
impl Cutter {
    fn new(polygon: Polygon) -> Self {
        Self { buffers: [polygon, Polygon::EMPTY], current: 0 }
    }

    /// What is left.
    #[inline(always)]
    fn rest(&self) -> &Polygon {
        &self.buffers[self.current]
    }

    /// Empties it, for a polygon to be written into.
    #[inline(always)]
    fn reset(&mut self) -> &mut Polygon {
        self.current = 0;
        &mut self.buffers[0]
    }

    /// Moves the part with `p[axis] <= at` into `lower`; the rest, `p[axis] >= at`, stays.
    #[inline(always)]
    fn cut_below(&mut self, axis: usize, at: f64, lower: &mut Polygon) {
        let [first, second] = &mut self.buffers;
        let (from, to) = if self.current == 0 { (&*first, second) } else { (&*second, first) };
        from.split_into(axis, at, lower, to);
        self.current = 1 - self.current;
    }
}
/// A convex polygon in pixel space: a triangle clipped to an axis-aligned box (the frame, a row of it, a pixel),
/// so at most seven vertices (each side of the box adds at most one).
#[derive(Clone, Copy)]
pub(super) struct Polygon {
    pub(super) vertices: [[f64; 2]; 8],
    pub(super) count: usize,
}
impl Polygon {
    const EMPTY: Self = Self { vertices: [[0.0; 2]; 8], count: 0 };

    pub(super) fn triangle(v: [[f64; 2]; 3]) -> Self {
        let mut vertices = [[0.0; 2]; 8];
        vertices[..3].copy_from_slice(&v);
        Self { vertices, count: 3 }
    }

    /// The part with `p[axis] <= at` (`below`) or `p[axis] >= at`.
    pub(super) fn clip(&self, axis: usize, at: f64, below: bool) -> Self {
        let (mut lower, mut upper) = (Self::EMPTY, Self::EMPTY);
        self.split_into(axis, at, &mut lower, &mut upper);
        if below { lower } else { upper }
    }

    /// Writes the parts with `p[axis] <= at` into `lower` and with `p[axis] >= at` into `upper`
    /// (Sutherland-Hodgman against one line, both sides in one pass).
    #[inline(always)]
    pub(super) fn split_into(&self, axis: usize, at: f64, lower: &mut Self, upper: &mut Self) {
        let n = self.count;
        // Which vertices lie on each side, as bits (vertex i is bit i).
        let (mut below, mut above) = (0u32, 0u32);
        for (i, p) in self.vertices[..n].iter().enumerate() {
            below |= u32::from(p[axis] <= at) << i;
            above |= u32::from(p[axis] >= at) << i;
        }
        let all = (1u32 << n) - 1;
        if below == all {
            (lower.vertices, lower.count, upper.count) = (self.vertices, n, 0);
            return;
        }
        if above == all {
            (upper.vertices, upper.count, lower.count) = (self.vertices, n, 0);
            return;
        }
        lower.count = 0;
        upper.count = 0;
        let push = |poly: &mut Self, p: [f64; 2]| {
            if poly.count < poly.vertices.len() {
                poly.vertices[poly.count] = p;
                poly.count += 1;
            }
        };
        let mut a = self.vertices[n - 1];
        let mut a_bit = 1u32 << (n - 1);
        for (i, &b) in self.vertices[..n].iter().enumerate() {
            let b_bit = 1u32 << i;
            if below & a_bit != 0 {
                push(lower, a);
            }
            if above & a_bit != 0 {
                push(upper, a);
            }
            // The edge crosses the line when one end is strictly below and the other strictly above (so its
            // ends differ along `axis`): the crossing belongs to both.
            let strictly = |bit: u32| (below & bit != 0, above & bit != 0);
            let ((a_le, a_ge), (b_le, b_ge)) = (strictly(a_bit), strictly(b_bit));
            if (a_le && !a_ge && b_ge && !b_le) || (a_ge && !a_le && b_le && !b_ge) {
                let t = (at - a[axis]) / (b[axis] - a[axis]);
                let mut p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                p[axis] = at;
                push(lower, p);
                push(upper, p);
            }
            a = b;
            a_bit = b_bit;
        }
    }

    /// For a convex polygon within the row `y..y + 1`: the columns `[lo, hi)` of the pixels it covers whole
    /// (NaN when none). Only a polygon that spans the row's height covers any: its left side is convex
    /// and its right side concave in y, so both are furthest in at the row's edges, where its vertices lie on
    /// the cut lines.
    #[inline(always)]
    pub(super) fn full_columns(&self, y: f64) -> (f64, f64) {
        let (mut bottom, mut top) = ([f64::INFINITY, f64::NEG_INFINITY], [f64::INFINITY, f64::NEG_INFINITY]);
        for p in &self.vertices[..self.count] {
            if p[1] == y {
                bottom = [bottom[0].min(p[0]), bottom[1].max(p[0])];
            } else if p[1] == y + 1.0 {
                top = [top[0].min(p[0]), top[1].max(p[0])];
            }
        }
        let (lo, hi) = (bottom[0].max(top[0]).ceil(), bottom[1].min(top[1]).floor());
        if lo < hi { (lo, hi) } else { (f64::NAN, f64::NAN) }
    }

    /// `[x_min, y_min, x_max, y_max]`, `None` when the polygon is empty.
    #[inline(always)]
    pub(super) fn bounds(&self) -> Option<[f64; 4]> {
        (self.count >= 3).then(|| {
            self.vertices[..self.count]
                .iter()
                .fold([f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |b, p| {
                    [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])]
                })
        })
    }

    /// Area (px^2) and centroid; `None` when empty or of no area.
    #[inline(always)]
    pub(super) fn area_centroid(&self) -> Option<(f64, [f64; 2])> {
        if self.count < 3 {
            return None;
        }
        let o = self.vertices[0];
        let (mut area2, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for i in 1..self.count - 1 {
            let (a, b) = (self.vertices[i], self.vertices[i + 1]);
            let (ax, ay, bx, by) = (a[0] - o[0], a[1] - o[1], b[0] - o[0], b[1] - o[1]);
            let cross = ax * by - ay * bx;
            area2 += cross;
            cx += cross * (ax + bx);
            cy += cross * (ay + by);
        }
        (area2 != 0.0 && area2.is_finite())
            .then(|| (0.5 * area2.abs(), [o[0] + cx / (3.0 * area2), o[1] + cy / (3.0 * area2)]))
    }
}
