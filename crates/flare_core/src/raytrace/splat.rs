//! Splatting traced triangles with their energy conserved: each triangle box-filtered into the pixels it covers,
//! its attributes interpolated at each covered part, the aperture mask looked up at every stop crossing, and the
//! light added to a frame's [`FrameAcc`], band of rows by band, that becomes a [`RayGridImage`].
//!
//! # How it works
//! [`splat_triangle`] walks the triangle's rows in one band of the frame. In each row the pixels it covers
//! whole (both of its sections at the row's edges lie beyond the pixel on either side) are one run: where the
//! triangle's light is linear (no mask edge, nothing vignetted, no negative weight: most triangles) the run is
//! four adds to the row's second differences ([`BandAcc::add_linear_run`]), else each pixel is shaded at its
//! centre ([`BandAcc::add_run`]). Every other pixel it touches gets the area of the triangle's part in it and
//! that part's first moments in closed form from the three edges ([`Band`]: Green's theorem, no polygon cut),
//! the same steps as the GPU's `raygrid_box.wgsl` (`band_of`, `band_part`), in f64; its light is the area times
//! the light at the part's centroid. A triangle collapsed to a line or a point, or inside one pixel, puts all of
//! its light in one pixel. All of it goes first into the band's task's own scratch, one value per pixel before
//! the job's RGB weight; when the job is done in the band, two running sums turn the differences into light
//! and the scratch goes into each of the frame's red, green and blue planes times the job's weight there
//! ([`BandAcc::flush`]). Each band is drawn by one task, every job's triangles in the jobs' order: the image
//! does not depend on the threads.

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
    /// Jobs with light left out as too dim to see ([`super::Dim::Below`]).
    pub dim_jobs: usize,
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
/// Rows of a band: a frame is splatted band by band, each band by one task that draws every job's triangles
/// crossing it in the jobs' order.
pub(super) const BAND_ROWS: usize = 16;
/// How many bands of [`BAND_ROWS`] rows a frame `height` rows high has.
pub(super) fn band_count(height: usize) -> usize {
    height.div_ceil(BAND_ROWS).max(1)
}
/// Planes of a row: red, green and blue. A band's rows hold them in the frame; while a job is drawn in a band,
/// the task holds its light before the RGB weight in a [`Scratch`] of its own, put into the planes when the job
/// is done ([`BandAcc::flush`]).
const PLANES: usize = 3;

thread_local! {
    /// A task's [`Scratch`], zero outside the rows' reach between bands (kept by the thread: a band's draw finds
    /// it made).
    static SCRATCH: std::cell::RefCell<Scratch> = const { std::cell::RefCell::new(Scratch::new()) };
}
/// What a band's task adds the light of the job being drawn into, before the job's RGB weight: per row, the
/// light of the pixels its triangles cut and the second differences of the runs of pixels they cover whole,
/// `width` values each, zero outside the row's reach (the columns `[first, end)` either was added to; none:
/// `first >= end`).
struct Scratch {
    cut: Vec<f64>,
    diffs: Vec<f64>,
    reach: Vec<[usize; 2]>,
}
impl Scratch {
    const fn new() -> Self {
        Self { cut: Vec::new(), diffs: Vec::new(), reach: Vec::new() }
    }

    /// Grown to `rows` rows of `width` pixels (what it held stays zero).
    fn fit(&mut self, width: usize, rows: usize) {
        if self.cut.len() < width * rows {
            self.cut.resize(width * rows, 0.0);
            self.diffs.resize(width * rows, 0.0);
        }
        if self.reach.len() < rows {
            self.reach.resize(rows, [usize::MAX, 0]);
        }
    }
}

/// A frame's accumulation: energy per pixel (relative irradiance x mm^2) and per-ghost moments, split into
/// bands of [`BAND_ROWS`] rows that are splatted in parallel, each by one task ([`Self::splat`]).
///
/// Every pixel belongs to one band and every band draws the jobs in the order given, so each pixel's sum is
/// made in one order whatever the threads: the image is the same to the bit on any machine. A band's rows
/// (about `16 x 5 x width` values with the task's scratch) stay in the core's cache while it draws, and the
/// frame is one buffer: no copy per thread to make and merge. Each row holds its red, green and blue as
/// planes. A job's light goes first into the task's [`Scratch`], one value per pixel whatever the job's RGB
/// weight: a pixel a triangle cuts is one add where it is; a run of pixels a triangle covers whole, whose
/// light is linear along the run, is four adds whatever its length to the row's second differences
/// ([`BandAcc::add_linear_run`]). When the job is done in the band ([`BandAcc::flush`]) two running sums turn
/// the differences into light, and the scratch goes into each plane times the job's weight there.
pub(super) struct FrameAcc {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Per band, its rows' planes; made when a triangle first lands in the band (a ghost's window in a LUT bake
    /// is lit in part, and a band no light reaches costs nothing).
    bands: Vec<Option<Vec<f64>>>,
    /// Per band, per ghost.
    moments: Vec<Vec<GhostMoments>>,
    /// The scratch of [`Self::whole`]'s band.
    #[cfg(test)]
    whole_scratch: Scratch,
}
/// One band of a [`FrameAcc`]: rows `y0..y1` of a frame `width` x `height`.
pub(super) struct BandAcc<'a> {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) y0: usize,
    pub(super) y1: usize,
    rows: &'a mut Option<Vec<f64>>,
    /// The light of the job in `pending` before its RGB weight ([`Scratch`]'s, rows `y0..y1`): it goes into
    /// the rows when another job is pended or the band is done ([`Self::flush`]).
    cut: &'a mut [f64],
    diffs: &'a mut [f64],
    reach: &'a mut [[usize; 2]],
    pending: Option<Pending>,
    moments: &'a mut [GhostMoments],
}
/// The job whose light a [`BandAcc`]'s `cut` holds: what its values are weighed by.
#[derive(Clone, Copy, PartialEq)]
struct Pending {
    ghost: usize,
    rgb: [f64; 3],
    luma: f64,
}
impl Pending {
    #[inline(always)]
    fn of(job: &JobFrame) -> Self {
        Self { ghost: job.ghost, rgb: job.rgb, luma: job.luma }
    }
}
impl FrameAcc {
    pub(super) fn new(width: usize, height: usize, ghosts: usize) -> Self {
        let bands = band_count(height);
        Self {
            width,
            height,
            bands: vec![None; bands],
            moments: vec![vec![GhostMoments::default(); ghosts]; bands],
            #[cfg(test)]
            whole_scratch: Scratch::new(),
        }
    }

    /// How many bands of [`BAND_ROWS`] rows the frame has.
    pub(super) fn bands(&self) -> usize {
        self.bands.len()
    }

    /// Runs `draw` on every band, the bands in parallel.
    pub(super) fn splat(&mut self, draw: impl Fn(&mut BandAcc) + Sync) {
        let (width, height) = (self.width, self.height);
        self.bands.par_iter_mut().zip(self.moments.par_iter_mut()).enumerate().for_each(|(b, (rows, moments))| {
            let y0 = b * BAND_ROWS;
            let y1 = (y0 + BAND_ROWS).min(height);
            SCRATCH.with_borrow_mut(|scratch| {
                let rows_drawn = y1 - y0;
                scratch.fit(width, rows_drawn);
                draw(&mut BandAcc {
                    width,
                    height,
                    y0,
                    y1,
                    rows,
                    cut: &mut scratch.cut[..width * rows_drawn],
                    diffs: &mut scratch.diffs[..width * rows_drawn],
                    reach: &mut scratch.reach[..rows_drawn],
                    pending: None,
                    moments,
                });
            });
        });
    }

    /// The whole frame as one band (the unit tests' way to splat single triangles).
    #[cfg(test)]
    pub(super) fn whole(&mut self) -> BandAcc<'_> {
        self.bands.truncate(1);
        self.moments.truncate(1);
        self.whole_scratch = Scratch::new();
        self.whole_scratch.fit(self.width, self.height);
        BandAcc {
            width: self.width,
            height: self.height,
            y0: 0,
            y1: self.height,
            rows: &mut self.bands[0],
            cut: &mut self.whole_scratch.cut,
            diffs: &mut self.whole_scratch.diffs,
            reach: &mut self.whole_scratch.reach,
            pending: None,
            moments: &mut self.moments[0],
        }
    }

    /// Row `y`'s energy, channel by channel (zeros for a row no light reached).
    fn resolve_row(width: usize, row: Option<&[f64]>, out: &mut [[f64; 3]]) {
        let Some(row) = row else { return };
        for c in 0..3 {
            for (x, v) in row[c * width..(c + 1) * width].iter().enumerate() {
                out[x][c] = *v;
            }
        }
    }

    /// Row `y`'s planes, where its band was made. (A band made for the whole frame by [`Self::whole`] holds
    /// every row.)
    fn row(&self, y: usize) -> Option<&[f64]> {
        let len = PLANES * self.width;
        let (band, first) = if self.bands.len() == 1 { (0, 0) } else { (y / BAND_ROWS, y / BAND_ROWS * BAND_ROWS) };
        self.bands[band].as_ref().map(|rows| &rows[(y - first) * len..(y - first + 1) * len])
    }

    /// The energy of every pixel, rows from the top.
    #[cfg(test)]
    pub(super) fn energy(&self) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; self.width * self.height];
        for y in 0..self.height {
            Self::resolve_row(self.width, self.row(y), &mut out[y * self.width..(y + 1) * self.width]);
        }
        out
    }

    /// The image of `window`: energy per pixel / pixel area = irradiance; moments likewise in irradiance x
    /// pixel^2, as the paraxial renderer's. The bands' moments are summed in the bands' order.
    pub(super) fn into_image(self, window: &Window, stats: RayGridStats) -> RayGridImage {
        let pixel_area_mm2 = window.px_per_mm().powi(-2);
        let mut total = vec![GhostMoments::default(); self.moments.first().map_or(0, Vec::len)];
        for band in &self.moments {
            for (a, b) in total.iter_mut().zip(band) {
                a.add(b);
            }
        }
        let moments = total
            .iter()
            .map(|m| GhostMoments {
                energy: m.energy / pixel_area_mm2,
                sum_x: m.sum_x / pixel_area_mm2,
                sum_y: m.sum_y / pixel_area_mm2,
            })
            .collect();
        let width = self.width;
        let mut pixels = vec![[0.0, 0.0, 0.0, 1.0]; width * self.height];
        pixels.par_chunks_mut(width.max(1)).enumerate().for_each(|(y, out)| {
            let Some(row) = self.row(y) else { return };
            let mut energy = vec![[0.0; 3]; width];
            Self::resolve_row(width, Some(row), &mut energy);
            for (pixel, e) in out.iter_mut().zip(energy) {
                let v = e.map(|c| (c / pixel_area_mm2) as f32);
                let v = v.map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 });
                *pixel = [v[0], v[1], v[2], 1.0];
            }
        });
        RayGridImage { hdr: HdrImage { width: width as u32, height: self.height as u32, pixels }, moments, stats }
    }
}
impl BandAcc<'_> {
    /// The planes of row `y` (in the band) from the band's buffer `rows` (rows `band[0]..band[1]` of `width`),
    /// the buffer made at the first.
    #[inline(always)]
    fn row_of(rows: &mut Option<Vec<f64>>, width: usize, band: [usize; 2], y: usize) -> &mut [f64] {
        let len = PLANES * width;
        let rows = rows.get_or_insert_with(|| {
            let mut rows = vec![0.0; len * (band[1] - band[0])];
            // Zeroed memory from the system is one shared page of zeros until written: a first `+=` would read
            // it there and fault again to write it (a TLB shoot-down on every other thread). A write to each
            // 4 KiB page first makes each page once.
            for value in rows.iter_mut().step_by(512) {
                *value = std::hint::black_box(0.0);
            }
            rows
        });
        &mut rows[(y - band[0]) * len..(y - band[0] + 1) * len]
    }

    /// Adds `energy` (scalar, before the job's RGB weight) at pixel (x, y) when it lies in the band: into the
    /// task's scratch, for the job pended last ([`Self::pend`]).
    #[inline(always)]
    pub(super) fn add(&mut self, x: i64, y: i64, energy: f64) {
        if x < 0
            || y < self.y0 as i64
            || x >= self.width as i64
            || y >= self.y1 as i64
            || energy.is_nan()
            || energy <= 0.0
        {
            return;
        }
        let (x, r) = (x as usize, y as usize - self.y0);
        debug_assert!(self.pending.is_some(), "light added before its job was pended");
        self.cut[r * self.width + x] += energy;
        let reach = &mut self.reach[r];
        *reach = [reach[0].min(x), reach[1].max(x + 1)];
    }

    /// Makes `job` the one whose light the scratch holds, the light of the one before put in the rows first:
    /// what [`splat_triangle`] does before it adds ([`Self::add`], [`Self::add_run`], [`Self::add_linear_run`]
    /// add to the job pended last).
    #[inline(always)]
    pub(super) fn pend(&mut self, job: &JobFrame) {
        let pending = Pending::of(job);
        if self.pending != Some(pending) {
            self.flush();
            self.pending = Some(pending);
        }
    }

    /// Puts the pending job's light into the rows, each channel times its weight (a channel the wavelength does
    /// not weigh is left alone): the cut pixels' (whose moments it adds to the ghost's) and the runs' from their
    /// second differences. Leaves the scratch zero. Compiled for AVX2 too, used where the processor has it (the
    /// same results: no sum changes its order).
    fn flush(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if crate::optics::simd_level() >= 1 {
            // SAFETY: the processor has AVX2 (checked once by `simd_level`).
            return unsafe { self.flush_avx2() };
        }
        self.flush_body()
    }

    /// [`Self::flush_body`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn flush_avx2(&mut self) {
        self.flush_body()
    }

    /// The body of [`Self::flush`].
    #[inline(always)]
    fn flush_body(&mut self) {
        let Some(job) = self.pending.take() else { return };
        let width = self.width;
        for r in 0..self.y1 - self.y0 {
            let [lo, hi] = self.reach[r];
            if lo >= hi {
                continue;
            }
            self.reach[r] = [usize::MAX, 0];
            let row = Self::row_of(self.rows, width, [self.y0, self.y1], self.y0 + r);
            let cut = &mut self.cut[r * width + lo..r * width + hi];
            let diffs = &mut self.diffs[r * width + lo..r * width + hi];
            // The cut pixels' light and its first moment along the row, in four lanes summed in a fixed order
            // (the runs' moments were added in closed form).
            let (mut sum, mut sum_x) = ([0.0f64; 4], [0.0f64; 4]);
            let mut centre = lo as f64 + 0.5;
            let mut quads = cut.chunks_exact(4);
            for quad in &mut quads {
                for lane in 0..4 {
                    sum[lane] += quad[lane];
                    sum_x[lane] += quad[lane] * (centre + lane as f64);
                }
                centre += 4.0;
            }
            for (lane, e) in quads.remainder().iter().enumerate() {
                sum[lane] += *e;
                sum_x[lane] += *e * (centre + lane as f64);
            }
            // The runs' light from their second differences: two running sums along the reach (past it what
            // they leave is rounding, not light).
            let (mut slope, mut level) = (0.0, 0.0);
            for (value, d) in cut.iter_mut().zip(diffs.iter_mut()) {
                slope += *d;
                level += slope;
                *value += level;
                *d = 0.0;
            }
            for (c, weight) in job.rgb.into_iter().enumerate() {
                if weight != 0.0 {
                    for (value, e) in row[c * width + lo..c * width + hi].iter_mut().zip(cut.iter()) {
                        *value += e * weight;
                    }
                }
            }
            cut.fill(0.0);
            let total = |s: [f64; 4]| (s[0] + s[1]) + (s[2] + s[3]);
            let y = self.y0 + r;
            let m = &mut self.moments[job.ghost];
            let sum = total(sum);
            m.energy += sum * job.luma;
            m.sum_x += total(sum_x) * job.luma;
            m.sum_y += sum * job.luma * (y as f64 + 0.5);
        }
    }

    /// Adds `energy(x_centre)` at each pixel of row `y` from column `x_lo` to before `x_hi` (the pixels a row of a
    /// triangle covers whole): the same sums as [`Self::add`] pixel by pixel, the row's reach widened once.
    #[inline(always)]
    pub(super) fn add_run(&mut self, y: i64, x_lo: i64, x_hi: i64, energy: impl Fn(f64) -> f64) {
        let (x_lo, x_hi) = (x_lo.max(0), x_hi.min(self.width as i64));
        if y < self.y0 as i64 || y >= self.y1 as i64 || x_lo >= x_hi {
            return;
        }
        let (r, lo, hi) = (y as usize - self.y0, x_lo as usize, x_hi as usize);
        debug_assert!(self.pending.is_some(), "light added before its job was pended");
        let cut = &mut self.cut[r * self.width..(r + 1) * self.width];
        for (x, value) in cut.iter_mut().enumerate().take(hi).skip(lo) {
            let e = energy(x as f64 + 0.5);
            if e > 0.0 {
                *value += e;
            }
        }
        let reach = &mut self.reach[r];
        *reach = [reach[0].min(lo), reach[1].max(hi)];
    }

    /// Adds `a + b x_centre` at each pixel of row `y` from column `x_lo` to before `x_hi`, where that is never
    /// negative over the run (a triangle's linear light over pixels it covers whole): four adds to the row's
    /// second differences whatever the run's length, the moments in closed form. `false` (nothing added) when
    /// `a` or `b` is not finite.
    #[inline(always)]
    pub(super) fn add_linear_run(&mut self, y: i64, x_lo: i64, x_hi: i64, job: &JobFrame, a: f64, b: f64) -> bool {
        if !(a.is_finite() && b.is_finite()) {
            return false;
        }
        let (x_lo, x_hi) = (x_lo.max(0), x_hi.min(self.width as i64));
        if y < self.y0 as i64 || y >= self.y1 as i64 || x_lo >= x_hi {
            return true;
        }
        let (y, lo, hi, width) = (y as usize, x_lo as usize, x_hi as usize, self.width);
        debug_assert!(self.pending == Some(Pending::of(job)), "light added before its job was pended");
        // g(p): the run's light at column p (0 outside it); the second difference at p is
        // g(p) - 2 g(p - 1) + g(p - 2), non-zero only at lo, lo + 1, hi and hi + 1.
        let g = |p: usize| if (lo..hi).contains(&p) { a + b * (p as f64 + 0.5) } else { 0.0 };
        let second = |p: usize| g(p) - 2.0 * g(p.wrapping_sub(1)) + g(p.wrapping_sub(2));
        let at = [lo, lo + 1, hi, hi + 1];
        let diffs = &mut self.diffs[(y - self.y0) * width..(y - self.y0 + 1) * width];
        for (k, &p) in at.iter().enumerate() {
            if p >= width || (k == 2 && hi == lo + 1) {
                continue;
            }
            diffs[p] += second(p);
        }
        let reach = &mut self.reach[y - self.y0];
        *reach = [reach[0].min(lo), reach[1].max((hi + 2).min(width))];
        // Sums over the centres c = lo + 1/2 .. hi - 1/2: n, sum c and sum c^2 (from S(m) = m (4 m^2 - 1) / 12,
        // the sum of (k + 1/2)^2 for k < m).
        let n = (hi - lo) as f64;
        let sum_c = 0.5 * n * (lo + hi) as f64;
        let s = |m: f64| m * (4.0 * m * m - 1.0) * (1.0 / 12.0);
        let sum_c2 = s(hi as f64) - s(lo as f64);
        self.add_moments(job, y, n * a + b * sum_c, a * sum_c + b * sum_c2);
        true
    }

    /// The ghost's moments of a run in row `y` of light `sum` and first moment `sum_x` along the row.
    #[inline(always)]
    fn add_moments(&mut self, job: &JobFrame, y: usize, sum: f64, sum_x: f64) {
        let m = &mut self.moments[job.ghost];
        m.energy += sum * job.luma;
        m.sum_x += sum_x * job.luma;
        m.sum_y += sum * job.luma * (y as f64 + 0.5);
    }
}
impl Drop for BandAcc<'_> {
    /// Puts the last job's light into the rows ([`Self::flush`]), leaving the task's scratch zero for the next
    /// band.
    fn drop(&mut self) {
        self.flush();
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
        // An open triangle never looks its stop coordinates up: their planes are left at zero.
        let open = Self::open(tri, frame);
        Self {
            ratio: attr(&|v| v.ratio),
            weight: attr(&|v| v.weight),
            stops: std::array::from_fn(|k| {
                if k < frame.stop_count && !open {
                    [attr(&|v| v.stops[k][0]), attr(&|v| v.stops[k][1])]
                } else {
                    [Plane { a0: 0.0, ax: 0.0, ay: 0.0 }; 2]
                }
            }),
            open,
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
/// Pixels across a tile of [`PeakTiles`].
const PEAK_TILE: usize = 8;
/// A bound of the most one job adds to any pixel of a view (its peak, for [`super::Dim::Below`]): over tiles of
/// [`PEAK_TILE`] x [`PEAK_TILE`] pixels, the sum of what each triangle whose box touches the tile can add to one
/// pixel. [`splat_triangle`] adds to a pixel the triangle's irradiance (its flux over its area) times the light
/// of the part in the pixel, which is at most the part's area times the largest vertex weight (the weight is
/// linear between the vertices, vignetting and the masks only take from it): so at most the irradiance times
/// that weight, or the whole flux times it for a triangle under a pixel (or collapsed into one), times the
/// largest of the wavelength's RGB weights, in the image's unit. Every pixel a triangle adds to lies in its box.
pub(super) struct PeakTiles {
    /// Tiles across and down.
    across: usize,
    down: usize,
    /// The frame's pixels across and down.
    width: f64,
    height: f64,
    tiles: Vec<f64>,
    /// The job's flux per triangle times its largest RGB weight, over a pixel's area: the image's unit.
    flux: f64,
}
impl PeakTiles {
    pub(super) fn new(window: &Window, frame: &JobFrame) -> Self {
        let (width, height) = (window.width as usize, window.height as usize);
        let (across, down) = (width.div_ceil(PEAK_TILE).max(1), height.div_ceil(PEAK_TILE).max(1));
        let rgb = frame.rgb.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let pixel_area_mm2 = window.px_per_mm().powi(-2);
        Self {
            across,
            down,
            width: width as f64,
            height: height as f64,
            tiles: vec![0.0; across * down],
            flux: frame.triangle_flux * rgb / pixel_area_mm2,
        }
    }

    /// Adds what triangle `tri`, of pixel box `[x_lo, y_lo, x_hi, y_hi]`, can add to any pixel.
    #[inline(always)]
    pub(super) fn add(&mut self, tri: [&Vertex; 3], [x_lo, y_lo, x_hi, y_hi]: [f64; 4]) {
        let p = [tri[0].pixel, tri[1].pixel, tri[2].pixel];
        let area_px =
            0.5 * ((p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0])).abs();
        let weight = tri.iter().fold(0.0f64, |m, v| m.max(v.weight));
        // Over a pixel or more: the irradiance; under one (or of no area, or none found): the whole flux.
        let spread = if area_px >= 1.0 { 1.0 / area_px } else { 1.0 };
        let bound = self.flux * weight * spread;
        let tile = |v: f64, size: f64| (v.floor().clamp(0.0, size - 1.0) as usize) / PEAK_TILE;
        let (tx0, tx1) = (tile(x_lo, self.width), tile(x_hi, self.width));
        let (ty0, ty1) = (tile(y_lo, self.height), tile(y_hi, self.height));
        for ty in ty0..=ty1.min(self.down - 1) {
            for t in &mut self.tiles[ty * self.across + tx0..=ty * self.across + tx1.min(self.across - 1)] {
                *t += bound;
            }
        }
    }

    /// The largest tile: the job's peak bound (infinite when a bound was not finite).
    pub(super) fn peak(&self) -> f64 {
        self.tiles.iter().fold(0.0f64, |m, &t| if t.is_nan() { f64::INFINITY } else { m.max(t) })
    }
}
/// Whether a triangle carries light: its three vertices traced, not all vignetted, and not entirely outside the
/// mask's square on one side at some stop crossing.
#[inline(always)]
pub(super) fn carries_light(tri: [&Vertex; 3], frame: &JobFrame) -> bool {
    if !tri.iter().all(|v| v.valid) || tri.iter().all(|v| v.ratio > 1.0) {
        return false;
    }
    for k in 0..frame.stop_count {
        for axis in 0..2 {
            if tri.iter().all(|v| v.stops[k][axis] > 1.0) || tri.iter().all(|v| v.stops[k][axis] < -1.0) {
                return false;
            }
        }
    }
    true
}
/// Splats the part in `acc`'s band of one triangle that [`carries_light`], with its energy conserved.
#[inline(always)]
pub(super) fn splat_triangle(tri: [&Vertex; 3], frame: &JobFrame, acc: &mut BandAcc) {
    let pixels = [tri[0].pixel, tri[1].pixel, tri[2].pixel];
    let x_lo = pixels.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let x_hi = pixels.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
    let y_lo = pixels.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let y_hi = pixels.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let (w, h) = (acc.width as f64, acc.height as f64);
    if x_lo > w + 1.0 || y_lo > h + 1.0 || x_hi < -1.0 || y_hi < -1.0 {
        return; // Its light is real but lands off the frame.
    }
    // Outside the band: another band draws it.
    if y_hi < acc.y0 as f64 || y_lo >= acc.y1 as f64 {
        return;
    }
    acc.pend(frame);
    let at = |l: [f64; 3]| [0, 1].map(|c| l[0] * pixels[0][c] + l[1] * pixels[1][c] + l[2] * pixels[2][c]);
    let Some(interp) = Interpolator::new(pixels) else {
        // Collapsed to a line or a point (a ghost focused there): all of its energy in the pixel of its centroid.
        let c = at([1.0 / 3.0; 3]);
        let energy = frame.triangle_flux * TriangleShader::mean(tri, frame).shade(c);
        acc.add(c[0].floor() as i64, c[1].floor() as i64, energy);
        return;
    };
    let shader = TriangleShader::new(tri, &interp, frame);
    let b = &interp.bary;
    let area_px = 0.5 / (b[0].ax * b[1].ay - b[0].ay * b[1].ax).abs();
    let (col, row) = (x_lo.floor(), y_lo.floor());
    if x_hi < col + 1.0 && y_hi < row + 1.0 {
        // Inside one pixel: all of it there.
        acc.add(col as i64, row as i64, frame.triangle_flux * shader.shade(at([1.0 / 3.0; 3])));
        return;
    }
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies. Rows and columns outside the frame are
    // skipped (the part of the triangle in the frame is what each pixel's own area counts). Where the light is
    // linear over the triangle (no mask to look up, nothing vignetted, no weight below 0: most triangles), a
    // part's light is its area times the light at its centroid, in closed form from the part's moments, and a
    // run of whole pixels is added as a line ([`BandAcc::add_linear_run`]).
    let irradiance = frame.triangle_flux / area_px;
    let linear = shader.open && tri.iter().all(|v| v.ratio <= 1.0 && v.weight >= 0.0);
    let weight = shader.weight;
    let sign = interp.sign;
    let mut y = y_lo.floor().max(0.0).max(acc.y0 as f64);
    let y_last = y_hi.floor().min(h - 1.0).min(acc.y1 as f64 - 1.0);
    let edges = Edges::new(pixels);
    let mut top = edges.section(y);
    while y <= y_last {
        // The columns the row touches, and those it covers whole (the triangle spans the row and both of its
        // sections lie beyond the pixel on either side: a convex section's extent is extreme at the band's ends).
        let bottom = edges.section(y + 1.0);
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
            let band = Band::new(&edges, y);
            let centre_y = y + 0.5;
            let mut x = x_first;
            while x < x_end {
                if x == full_lo && full_lo < full_hi {
                    let (lo, hi) = (full_lo as i64, full_hi as i64);
                    // A triangle clear of the masks' edges (most) shades without the lookups' loop, inlined.
                    let a = irradiance * (weight.a0 + weight.ay * centre_y);
                    if !(linear && acc.add_linear_run(y as i64, lo, hi, frame, a, irradiance * weight.ax)) {
                        if shader.open {
                            acc.add_run(y as i64, lo, hi, |x| irradiance * shader.shade_open([x, centre_y]));
                        } else {
                            acc.add_run(y as i64, lo, hi, |x| irradiance * shader.shade([x, centre_y]));
                        }
                    }
                    x = full_hi;
                    continue;
                }
                let (area, mx, my) = band.moments(x, sign);
                if area > 0.0 {
                    let light = if linear {
                        area * weight.at([x, y]) + weight.ax * mx + weight.ay * my
                    } else {
                        area * shader.shade([x + mx / area, y + my / area])
                    };
                    acc.add(x as i64, y as i64, irradiance * light);
                }
                x += 1.0;
            }
        }
        y += 1.0;
        top = bottom;
    }
}
/// A triangle's three edges, each from `p[i]` to `p[i + 1]`, with its run in x per unit of y (0 for a
/// horizontal edge): worked out once per triangle, used in every row.
struct Edges {
    p: [[f64; 2]; 3],
    slope: [f64; 3],
}
impl Edges {
    #[inline(always)]
    fn new(p: [[f64; 2]; 3]) -> Self {
        let slope = std::array::from_fn(|i| {
            let (a, b) = (p[i], p[(i + 1) % 3]);
            if b[1] == a[1] { 0.0 } else { (b[0] - a[0]) / (b[1] - a[1]) }
        });
        Self { p, slope }
    }

    /// The x extent `[min, max]` of the triangle's section by the line at height `at`; empty (min > max) when
    /// the line misses it. A horizontal edge on the line adds nothing its two neighbours do not.
    #[inline(always)]
    fn section(&self, at: f64) -> [f64; 2] {
        let mut s = [f64::INFINITY, f64::NEG_INFINITY];
        for i in 0..3 {
            let (u, v) = (self.p[i], self.p[(i + 1) % 3]);
            if u[1] != v[1] && u[1].min(v[1]) <= at && at <= u[1].max(v[1]) {
                let x = u[0] + (at - u[1]) * self.slope[i];
                s = [s[0].min(x), s[1].max(x)];
            }
        }
        s
    }
}
/// The triangle's three edges cut to the band of rows `[y, y + 1]`, for the part of the triangle in each pixel
/// of the row in closed form ([`Self::part`]; the GPU's `band_of` and `band_part` in
/// `shaders/raygrid_box.wgsl`). Per edge: the ends' heights relative to the row, clamped to `[0, 1]` (`ya`,
/// `yb`), the x at the first end (frame pixels), the x run to the second (`dx`) and its inverse (0 for a part of
/// no run).
struct Band {
    ya: [f64; LANES4],
    yb: [f64; LANES4],
    xa: [f64; LANES4],
    dx: [f64; LANES4],
    inv: [f64; LANES4],
    /// The edge's x extent in the row, `[min, max]` (frame pixels).
    reach: [[f64; 2]; LANES4],
}
/// A [`Band`] holds its three edges in arrays of four (the fourth, of no height, is never looked at).
const LANES4: usize = 4;
impl Band {
    #[inline(always)]
    fn new(edges: &Edges, y: f64) -> Self {
        let mut band =
            Self { ya: [0.0; 4], yb: [0.0; 4], xa: [0.0; 4], dx: [0.0; 4], inv: [0.0; 4], reach: [[0.0; 2]; 4] };
        for i in 0..3 {
            let (a, b, k) = (edges.p[i], edges.p[(i + 1) % 3], edges.slope[i]);
            let (py, qy) = (a[1] - y, b[1] - y);
            band.ya[i] = py.clamp(0.0, 1.0);
            band.yb[i] = qy.clamp(0.0, 1.0);
            band.xa[i] = a[0] + (band.ya[i] - py) * k;
            band.dx[i] = a[0] + (band.yb[i] - py) * k - band.xa[i];
            // A run too short for its inverse (a vertical edge): its G is one value, whatever t is. An edge of
            // no height in the row is never looked at.
            let inv = if band.dx[i] == 0.0 || band.ya[i] == band.yb[i] { 0.0 } else { 1.0 / band.dx[i] };
            band.inv[i] = if inv.is_finite() { inv } else { 0.0 };
            let end = band.xa[i] + band.dx[i];
            band.reach[i] = [band.xa[i].min(end), band.xa[i].max(end)];
        }
        band
    }

    /// The area (px^2) of the triangle's part in pixel x of the band's row y and its first moments about the
    /// pixel's corner (x, y): area x (centroid - corner), so that the centroid is `(x + mx / area, y + my / area)`
    /// where the area is positive (none where it is not). `sign` is that of the triangle's winding.
    ///
    /// By Green's theorem, with G(u) = clamp(u, 0, 1) in the pixel's own unit square and each edge's integral
    /// over its y clamped to the row, signed by its direction (the sum is the signed area):
    /// area = sum of integral G dy, area x cx = sum of integral G^2 / 2 dy, area x cy = sum of integral y G dy.
    /// On an edge G is linear in y between the points where it crosses u = 0 and u = 1, so each integral is
    /// three trapezoids. An edge left of the pixel adds nothing and one right of it adds G = 1 in closed form;
    /// only an edge that crosses the pixel takes the trapezoids.
    #[inline(always)]
    fn moments(&self, x: f64, sign: f64) -> (f64, f64, f64) {
        let (mut area, mut mx, mut my) = (0.0, 0.0, 0.0);
        for i in 0..3 {
            let (ya, yb, dx, inv) = (self.ya[i], self.yb[i], self.dx[i], self.inv[i]);
            if ya == yb || self.reach[i][1] <= x {
                // No height in the row, or left of the pixel (G = 0 all along): nothing.
                continue;
            }
            if self.reach[i][0] >= x + 1.0 {
                // Right of the pixel: G = 1 all along, the three integrals in closed form.
                area += 2.0 * (yb - ya);
                mx += 3.0 * (yb - ya);
                my += 3.0 * (yb * yb - ya * ya);
                continue;
            }
            let xa = self.xa[i] - x;
            let t0 = (-xa * inv).clamp(0.0, 1.0);
            let t1 = ((1.0 - xa) * inv).clamp(0.0, 1.0);
            let (tl, th) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
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
        let sixth = sign * (1.0 / 6.0);
        (sign * 0.5 * area, mx * sixth, my * sixth)
    }
}
