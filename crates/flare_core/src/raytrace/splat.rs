//! Splatting traced triangles with their energy conserved: each triangle box-filtered into the pixels it covers,
//! its attributes interpolated at each covered part, the aperture mask looked up at every stop crossing, and the
//! light added to a per-thread [`Accumulator`] that becomes a [`RayGridImage`].
//!
//! # How it works
//! [`splat_triangle`] walks the triangle's rows in the frame. In each row the pixels it covers whole (both of
//! its sections at the row's edges lie beyond the pixel on either side) are one run, each shaded at its centre
//! ([`Accumulator::add_run`]); every other pixel it touches gets the area of the triangle's part in it and that
//! part's centroid in closed form from the three edges ([`Band`]: Green's theorem, no polygon cut), the same
//! steps as the GPU's `raygrid_box.wgsl` (`band_of`, `band_part`), in f64. A triangle collapsed to a line or a
//! point, or inside one pixel, puts all of its light in one pixel.

use rayon::prelude::*;

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
/// Pixels in a tile; its three channels are planes of this many values each.
const TILE_PIXELS: usize = TILE * TILE;

/// Per-thread accumulation: energy per pixel (relative irradiance x mm^2) and per-ghost moments.
///
/// The energy is held in tiles of [`TILE`] x [`TILE`] pixels, each made (zeroed) when a triangle first lands
/// in it: rayon's fold starts a fresh accumulator for every piece of the job list it hands a thread, and a
/// ghost's light covers a part of the frame, so the cost of an accumulator (made, merged) follows the pixels
/// its jobs touch, not the frame's size. The sums are those of one frame-sized buffer, bit for bit (a tile not
/// yet made holds zeros). A tile holds its red, green and blue as three planes: a wavelength that weighs one
/// channel (the RGB spectrum's three) reads and writes a third of the bytes it would with the channels side
/// by side, and the splat's loops are bound by those bytes.
pub(super) struct Accumulator {
    pub(super) width: usize,
    pub(super) height: usize,
    tiles_x: usize,
    tiles: Vec<Option<Vec<f64>>>,
    pub(super) moments: Vec<GhostMoments>,
    pub(super) stats: RayGridStats,
}
/// A tile of zeros, its memory written as it is made: memory the system hands out zeroed is mapped to one
/// shared page of zeros until it is written, so a first `+=` would read it there and fault again to write it
/// (a TLB shoot-down on every other thread, each time).
fn new_tile() -> Vec<f64> {
    let mut tile = vec![0.0; 3 * TILE_PIXELS];
    // One value a 4 KiB page; `black_box` keeps the compiler from dropping stores of what the memory holds.
    for value in tile.iter_mut().step_by(512) {
        *value = std::hint::black_box(0.0);
    }
    tile
}
/// Pixel `i` of a tile (row-major in the tile) as red, green and blue, one from each plane.
fn tile_rgb(tile: &[f64], i: usize) -> [f64; 3] {
    [tile[i], tile[TILE_PIXELS + i], tile[2 * TILE_PIXELS + i]]
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
                    let i = (y - y0) * TILE + (x - x0);
                    out[y * self.width + x] = tile_rgb(tile, i);
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
                        *p += q;
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
        // Pixels no tile reached stay black; the tiles are read where they are (no frame of f64 made), a row of
        // tiles a thread.
        let mut pixels = vec![[0.0, 0.0, 0.0, 1.0]; self.width * self.height];
        let (width, tiles_x) = (self.width, self.tiles_x);
        pixels.par_chunks_mut((width * TILE).max(1)).zip(self.tiles.par_chunks(tiles_x.max(1))).for_each(
            |(band, tiles)| {
                for (tx, tile) in tiles.iter().enumerate() {
                    let Some(tile) = tile else { continue };
                    for (y, row) in band.chunks_exact_mut(width).enumerate() {
                        let columns = tx * TILE..((tx + 1) * TILE).min(width);
                        for (i, pixel) in (y * TILE..).zip(&mut row[columns]) {
                            let v = tile_rgb(tile, i).map(|c| (c / pixel_area_mm2) as f32);
                            let v = v.map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 });
                            *pixel = [v[0], v[1], v[2], 1.0];
                        }
                    }
                }
            },
        );
        RayGridImage {
            hdr: HdrImage { width: self.width as u32, height: self.height as u32, pixels },
            moments,
            stats: self.stats,
        }
    }

    /// The tile holding pixel (x, y) of the frame, made when it is not yet.
    #[inline(always)]
    fn tile_at(&mut self, x: usize, y: usize) -> &mut [f64] {
        self.tiles[(y / TILE) * self.tiles_x + x / TILE].get_or_insert_with(new_tile)
    }

    /// Adds `energy` (scalar, before the spectral weight) at pixel (x, y) when it lies in the frame.
    #[inline(always)]
    pub(super) fn add(&mut self, x: i64, y: i64, energy: f64, job: &JobFrame) {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 || energy.is_nan() || energy <= 0.0 {
            return;
        }
        let (x, y) = (x as usize, y as usize);
        let i = (y % TILE) * TILE + x % TILE;
        let tile = self.tile_at(x, y);
        // A channel the wavelength does not weigh is left alone (adding 0 would change nothing).
        for (plane, weight) in tile.chunks_exact_mut(TILE_PIXELS).zip(job.rgb) {
            if weight != 0.0 {
                plane[i] += energy * weight;
            }
        }
        let luma = energy * job.luma;
        self.moments[job.ghost].add_sample(luma, [x as f64 + 0.5, y as f64 + 0.5]);
    }

    /// Adds `energy(x_centre)` at each pixel of row `y` from column `x_lo` to before `x_hi` (the pixels a row of a
    /// triangle covers whole): the same sums as [`Self::add`] pixel by pixel, with the tile looked up once per
    /// tile the run crosses, the planes of channels the wavelength does not weigh not touched, and the ghost's
    /// moments summed once for the run.
    #[inline(always)]
    pub(super) fn add_run(&mut self, y: i64, x_lo: i64, x_hi: i64, job: &JobFrame, energy: impl Fn(f64) -> f64) {
        let (x_lo, x_hi) = (x_lo.max(0), x_hi.min(self.width as i64));
        if y < 0 || y >= self.height as i64 || x_lo >= x_hi {
            return;
        }
        let (y, x_hi) = (y as usize, x_hi as usize);
        // The planes the wavelength weighs, each with its weight: one for the RGB spectrum's wavelengths.
        let mut planes = [(0, 0.0); 3];
        let mut weighed = 0;
        for (c, weight) in job.rgb.into_iter().enumerate() {
            if weight != 0.0 {
                planes[weighed] = (c * TILE_PIXELS, weight);
                weighed += 1;
            }
        }
        let planes = &planes[..weighed];
        let (mut sum, mut sum_x) = (0.0, 0.0);
        let mut x = x_lo as usize;
        while x < x_hi {
            let end = ((x / TILE + 1) * TILE).min(x_hi);
            let first = (y % TILE) * TILE + x % TILE;
            let tile = self.tile_at(x, y);
            for (i, column) in (first..).zip(x..end) {
                let centre = column as f64 + 0.5;
                let e = energy(centre);
                if e > 0.0 {
                    for &(plane, weight) in planes {
                        tile[plane + i] += e * weight;
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
    /// The triangle's winding: 1 where twice its signed area `(v1 - v0) x (v2 - v0)` is positive, else -1.
    pub(super) sign: f64,
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
        let sign = if area2 < 0.0 { -1.0 } else { 1.0 };
        Some(Self { bary: [plane(v[1], v[2]), plane(v[2], v[0]), plane(v[0], v[1])], sign })
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

    /// The weight at the pixel position `p`, 0 where vignetted, with no aperture mask: [`Self::shade`] of a
    /// triangle that is [`Self::open`].
    #[inline(always)]
    pub(super) fn shade_open(&self, p: [f64; 2]) -> f64 {
        if self.ratio.at(p) > 1.0 { 0.0 } else { self.weight.at(p).max(0.0) }
    }

    /// Weight x aperture masks at the pixel position `p`; 0 where vignetted.
    #[inline(always)]
    pub(super) fn shade(&self, p: [f64; 2]) -> f64 {
        let mut m = self.shade_open(p);
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
    // centroid of that part: the box filter a sensor pixel applies. Rows and columns outside the frame are
    // skipped (the part of the triangle in the frame is what each pixel's own area counts).
    let irradiance = frame.triangle_flux / area_px;
    let sign = interp.sign;
    let mut y = y_lo.floor().max(0.0);
    let y_last = y_hi.floor().min(h - 1.0);
    while y <= y_last {
        // The columns the row touches, and those it covers whole (the triangle spans the row and both of its
        // sections lie beyond the pixel on either side: a convex section's extent is extreme at the band's ends).
        let (top, bottom) = (section(pixels, y), section(pixels, y + 1.0));
        let (mut row_lo, mut row_hi) = (top[0].min(bottom[0]), top[1].max(bottom[1]));
        for v in pixels.iter().filter(|v| v[1] > y && v[1] < y + 1.0) {
            (row_lo, row_hi) = (row_lo.min(v[0]), row_hi.max(v[0]));
        }
        let x_first = row_lo.floor().max(0.0);
        let x_end = row_hi.floor().min(w - 1.0) + 1.0;
        if x_end > x_first {
            let spans = y_lo <= y && y_hi >= y + 1.0;
            let full_lo = if spans { top[0].max(bottom[0]).ceil() } else { x_end }.clamp(x_first, x_end);
            let full_hi = if spans { top[1].min(bottom[1]).floor() } else { x_end }.clamp(full_lo, x_end);
            let band = Band::new(pixels, y);
            let mut x = x_first;
            while x < x_end {
                if x == full_lo && full_lo < full_hi {
                    let (centre_y, (lo, hi)) = (y + 0.5, (full_lo as i64, full_hi as i64));
                    // A triangle clear of the masks' edges (most) shades without the lookups' loop, inlined.
                    if shader.open {
                        acc.add_run(y as i64, lo, hi, frame, |x| irradiance * shader.shade_open([x, centre_y]));
                    } else {
                        acc.add_run(y as i64, lo, hi, frame, |x| irradiance * shader.shade([x, centre_y]));
                    }
                    x = full_hi;
                    continue;
                }
                if let Some((area, centroid)) = band.part(x, y, sign) {
                    acc.add(x as i64, y as i64, irradiance * area * shader.shade(centroid), frame);
                }
                x += 1.0;
            }
        }
        y += 1.0;
    }
    true
}
/// The x extent `[min, max]` of the triangle's section by the line at height `at`; empty (min > max) when the
/// line misses it. A horizontal edge on the line adds nothing its two neighbours do not.
#[inline(always)]
fn section(p: [[f64; 2]; 3], at: f64) -> [f64; 2] {
    let mut s = [f64::INFINITY, f64::NEG_INFINITY];
    for i in 0..3 {
        let (u, v) = (p[i], p[(i + 1) % 3]);
        if u[1] != v[1] && u[1].min(v[1]) <= at && at <= u[1].max(v[1]) {
            let x = u[0] + (at - u[1]) * (v[0] - u[0]) / (v[1] - u[1]);
            s = [s[0].min(x), s[1].max(x)];
        }
    }
    s
}
/// The triangle's three edges cut to the band of rows `[y, y + 1]`, for the part of the triangle in each pixel
/// of the row in closed form ([`Self::part`]; the GPU's `band_of` and `band_part` in
/// `shaders/raygrid_box.wgsl`). Per edge: the ends' heights relative to the row, clamped to `[0, 1]` (`ya`,
/// `yb`), the x at the first end (frame pixels), the x run to the second (`dx`) and its inverse (0 for a part of
/// no run).
struct Band {
    ya: [f64; 3],
    yb: [f64; 3],
    xa: [f64; 3],
    dx: [f64; 3],
    inv: [f64; 3],
}
impl Band {
    #[inline(always)]
    fn new(p: [[f64; 2]; 3], y: f64) -> Self {
        let mut band = Self { ya: [0.0; 3], yb: [0.0; 3], xa: [0.0; 3], dx: [0.0; 3], inv: [0.0; 3] };
        for i in 0..3 {
            let (a, b) = (p[i], p[(i + 1) % 3]);
            let (py, qy) = (a[1] - y, b[1] - y);
            let dy = qy - py;
            let k = if dy == 0.0 { 0.0 } else { (b[0] - a[0]) / dy };
            band.ya[i] = py.clamp(0.0, 1.0);
            band.yb[i] = qy.clamp(0.0, 1.0);
            band.xa[i] = a[0] + (band.ya[i] - py) * k;
            band.dx[i] = a[0] + (band.yb[i] - py) * k - band.xa[i];
            band.inv[i] = if band.dx[i] == 0.0 { 0.0 } else { 1.0 / band.dx[i] };
        }
        band
    }

    /// The area (px^2) of the triangle's part in pixel (x, y) of the band's row and the centroid of that part
    /// (frame pixels); `None` where it has no area. `sign` is that of the triangle's winding.
    ///
    /// By Green's theorem, with G(u) = clamp(u, 0, 1) in the pixel's own unit square and each edge's integral
    /// over its y clamped to the row, signed by its direction (the sum is the signed area):
    /// area = sum of integral G dy, area x cx = sum of integral G^2 / 2 dy, area x cy = sum of integral y G dy.
    /// On an edge G is linear in y between the points where it crosses u = 0 and u = 1, so each integral is
    /// three trapezoids. No cutting, no branch on the polygon's shape: the same steps in every pixel.
    #[inline(always)]
    fn part(&self, x: f64, y: f64, sign: f64) -> Option<(f64, [f64; 2])> {
        let (mut area, mut mx, mut my) = (0.0, 0.0, 0.0);
        for i in 0..3 {
            let (ya, yb, dx, inv) = (self.ya[i], self.yb[i], self.dx[i], self.inv[i]);
            let xa = self.xa[i] - x;
            let t0 = (-xa * inv).clamp(0.0, 1.0);
            let t1 = ((1.0 - xa) * inv).clamp(0.0, 1.0);
            let (tl, th) = (t0.min(t1), t0.max(t1));
            let y1 = ya + tl * (yb - ya);
            let y2 = ya + th * (yb - ya);
            let g0 = xa.clamp(0.0, 1.0);
            let g1 = (xa + tl * dx).clamp(0.0, 1.0);
            let g2 = (xa + th * dx).clamp(0.0, 1.0);
            let g3 = (xa + dx).clamp(0.0, 1.0);
            let (d0, d1, d2) = (y1 - ya, y2 - y1, yb - y2);
            area += d0 * (g0 + g1) + d1 * (g1 + g2) + d2 * (g2 + g3);
            mx += d0 * (g0 * g0 + g0 * g1 + g1 * g1)
                + d1 * (g1 * g1 + g1 * g2 + g2 * g2)
                + d2 * (g2 * g2 + g2 * g3 + g3 * g3);
            my += d0 * (ya * (2.0 * g0 + g1) + y1 * (g0 + 2.0 * g1))
                + d1 * (y1 * (2.0 * g1 + g2) + y2 * (g1 + 2.0 * g2))
                + d2 * (y2 * (2.0 * g2 + g3) + yb * (g2 + 2.0 * g3));
        }
        let area = sign * 0.5 * area;
        (area > 0.0).then(|| (area, [x + sign * mx / (6.0 * area), y + sign * my / (6.0 * area)]))
    }
}
