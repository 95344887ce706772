//! Front-element dirt: dust, smudges or a film on the first surface scatter a share of the light that reaches
//! them into a wide, dim glow whose structure is the dirt seen out of focus, brightest around the light.
//!
//! # How it works
//! - **The dirt** is a share map `s(p)` in [0, 1] over the entrance plane (the first vertex, the plane of the
//!   ghosts' entrance regions; the front surface's sag is neglected), 0 beyond the front element's clear radius
//!   `h_0`: procedural ([`DirtPattern`]: dust specks, smudges with fingerprint ridges, an even haze) or the
//!   user's grey image (white is dirt) stretched over the element's square, its top-left corner seen at the
//!   frame's top-left. The display's `dirt_amount` scales it: the share of the light scattered where the dirt
//!   is densest.
//! - **Who looks through which dirt**: a sensor point x sees the object-space direction of slopes `u(x)`; the
//!   rays of that direction that reach the sensor cross the entrance plane on a footprint: the entrance pupil's
//!   shape (the stop's, upright or turned over as the image path's `A` of entrance to stop says, paraxial
//!   semi-axes `r_EP` per section) centred where that direction's chief ray crosses the plane, by exact tracing
//!   ([`crate::ghost::GhostSystem::light_entrance_mm`]; `-z_EP u` near the axis). Per frame, both `u(x)` (the
//!   inverse of the lens's own mapping, [`crate::optics::mapping`]) and the footprint's centre are linearised
//!   about the light ([`crate::render::FlareScene::place_dirt`]): exact at the light, where the lobe puts the
//!   glow (a test finds the pass's `D` within 0.02 of the exactly traced footprint's 14 degrees off the axis).
//!   Vignetting by the elements behind the front one is neglected, as the paraxial ghosts neglect it. The mean
//!   share over the footprint, `D(c)`, is the dirt convolved with the pupil's shape: the dirt seen out of
//!   focus, each speck drawn as the aperture's shape. [`PreparedDirt::new`] computes it by FFT once per lens,
//!   stop and pattern, on a `DIRT_MAP_SIZE`^2 grid over `[-L, L]^2`, `L = h_0 + r_EP` (beyond it D is 0: no
//!   footprint there touches the element), kept in half floats as the GPU holds it.
//! - **Scattering**: each dirty point scatters the share `s(p)` of the light falling on it (the light's
//!   irradiance `cos(theta_s)` of 1 across its beam) into directions by a Henyey-Greenstein lobe about the
//!   light's direction, normalised over the sphere: `P(alpha) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos alpha)^1.5)`,
//!   `g` set by `dirt_spread_deg`, the angle at which the lobe falls to half its peak ([`henyey_greenstein_g`]).
//! - **Glow**: the power landing per sensor mm^2 at x is
//!   `amount A_EP cos(theta_s) T D(c(x)) P(alpha(x)) dOmega/dS`, with `dOmega/dS = |det du/dx| / (1 + |u|^2)^1.5`
//!   (the mapping's derivative at the light), `A_EP` the pupil's open area and `T` the image path's transmission, per wavelength weighted into RGB as the
//!   ghosts are ([`PreparedDirt::colour_rgb`]). `shaders/dirt.wgsl` evaluates it per pixel; its CPU twin is
//!   [`crate::render::cpu::dirt_pass`], reading the same uniforms ([`crate::render::Globals`]) and half-float map.
//! - **Energy**: the light that forms the image, every ghost and the starburst crosses the footprint of the
//!   light's own direction, so the dirt takes the share `amount D(c_s)` of it ([`PreparedDirt::taken_share`]) and
//!   they are all drawn times `1 - amount D(c_s)`. The glow is where that light goes: with even dirt the glow's
//!   power on the sensor is exactly the power taken times the share of the lobe that falls in the frame (a
//!   test integrates it); with patchy dirt the glow also holds light that dirt outside the light's own
//!   footprint scatters into the pupil, as on a real lens. Light the dirt scatters from ghosts (1e-4 of the
//!   light's) is left out.
//! - **Moves with the light**: the lobe is centred on the light, the dirt stays fixed to the lens: dragging the
//!   light slides a window of glow over the same specks.
//! - **A clean lens** (no pattern, or an amount of 0) makes no glow, multiplies nothing and uploads nothing: the
//!   frame is the one drawn before dirt existed, bit for bit (a test keeps the hashes).
//!
//! Singular cases: a pupil narrower than a texel convolves with one texel (the dirt seen sharp); a light at 90
//! degrees or more has no finite slope and makes no glow; the map samples 0 outside its grid.

use std::f64::consts::PI;
use std::path::Path;

use rustfft::FftPlanner;
use rustfft::num_complex::Complex32;
use serde::{Deserialize, Serialize};

use crate::aperture::ApertureMask;
use crate::ghost::GhostSystem;
use crate::starburst::fft_2d;

/// Texels across the dirt map's side.
pub(crate) const DIRT_MAP_SIZE: usize = 320;
/// Texels across a user's dirt image as kept (resampled from the file).
pub(crate) const DIRT_IMAGE_SIZE: usize = 512;
/// The narrowest and widest scattering lobes (`dirt_spread_deg`, half width at half peak).
pub const SPREAD_RANGE_DEG: (f64, f64) = (0.5, 60.0);

/// Where the dirt comes from (the optics part: changing it prepares the map again; the amount and spread are
/// display settings).
#[derive(Clone, Debug, PartialEq)]
pub enum DirtPattern {
    /// Specks of dust of many sizes and a few larger blotches.
    Dust { seed: u64 },
    /// Wiped smears and fingerprint ridges.
    Smudges { seed: u64 },
    /// An even film over the whole element.
    Haze,
    /// The user's grey image (white is dirt), `size` x `size` values in [0, 1], row 0 at the top.
    Image { size: usize, luminance: Vec<f32> },
}

/// Why a dirt pattern cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DirtError {
    #[error("dirt image: {0}")]
    Image(String),
}

impl DirtPattern {
    /// Loads a grey dirt image (PNG, JPEG, EXR or HDR, 1 to [`crate::output::MAX_IMAGE_SIDE_PX`] pixels a side,
    /// read through `crate::output::read_grey_square`) resampled to `DIRT_IMAGE_SIZE`^2. An image that is black
    /// everywhere is refused: it holds no dirt.
    pub fn image_from_file(path: &Path) -> Result<Self, DirtError> {
        let luminance =
            crate::output::read_grey_square(path, "dirt image", DIRT_IMAGE_SIZE).map_err(DirtError::Image)?;
        if luminance.iter().all(|&v| v < 1.0 / 255.0) {
            return Err(DirtError::Image(format!(
                "{}: the dirt image is black everywhere: it holds no dirt (white is dirt, black is clean glass)",
                path.display()
            )));
        }
        Ok(Self::Image { size: DIRT_IMAGE_SIZE, luminance })
    }

    /// The share map on a `n` x `n` grid over `[-half_extent_mm, half_extent_mm]^2` (row 0 at +y), 0 beyond the
    /// front radius `front_mm`.
    pub fn rasterise(&self, n: usize, half_extent_mm: f64, front_mm: f64) -> Vec<f32> {
        let texel_mm = 2.0 * half_extent_mm / n as f64;
        let centre = |i: usize| -half_extent_mm + (i as f64 + 0.5) * texel_mm;
        // Transmission (1 - share) per texel: overlapping specks combine as 1 - prod(1 - a).
        let mut clear = vec![1.0f64; n * n];
        let splat = |clear: &mut [f64], at: [f64; 2], reach_mm: f64, share: &dyn Fn(f64, f64) -> f64| {
            let to_index = |v: f64| (v + half_extent_mm) / texel_mm - 0.5;
            let (i0, i1) = (to_index(at[0] - reach_mm).floor().max(0.0), to_index(at[0] + reach_mm).ceil());
            let (j0, j1) = (to_index(-at[1] - reach_mm).floor().max(0.0), to_index(-at[1] + reach_mm).ceil());
            for j in j0 as usize..=(j1.min(n as f64 - 1.0).max(0.0) as usize) {
                for i in i0 as usize..=(i1.min(n as f64 - 1.0).max(0.0) as usize) {
                    let (dx, dy) = (centre(i) - at[0], -centre(j) - at[1]);
                    let a = share(dx, dy).clamp(0.0, 1.0);
                    clear[j * n + i] *= 1.0 - a;
                }
            }
        };
        let h = front_mm;
        match self {
            Self::Haze => clear.iter_mut().for_each(|c| *c = 0.0),
            Self::Dust { seed } => {
                let mut rng = SplitMix(*seed);
                // Specks 0.4% to 4% of the front radius (log-uniform), then a few faint blotches.
                for (count, lo, hi, opacity) in [(700, -2.4, -1.4, (0.25, 0.9)), (30, -1.4, -0.9, (0.05, 0.2))] {
                    for _ in 0..count {
                        let at = rng.in_disc(0.97 * h);
                        let r = h * 10f64.powf(rng.between(lo, hi));
                        let a = rng.between(opacity.0, opacity.1);
                        // A speck narrower than a texel keeps its area: widened, fainter.
                        let r_eff = r.max(0.6 * texel_mm);
                        let a = a * (r / r_eff).powi(2);
                        let edge = (0.15 * r_eff).max(0.5 * texel_mm);
                        splat(&mut clear, at, r_eff + edge, &|dx, dy| a * smooth_edge(dx.hypot(dy), r_eff, edge));
                    }
                }
            }
            Self::Smudges { seed } => {
                let mut rng = SplitMix(*seed);
                clear.iter_mut().for_each(|c| *c = 0.98);
                for _ in 0..7 {
                    let at = rng.in_disc(0.8 * h);
                    let angle = rng.between(0.0, PI);
                    let (half_len, half_width) = (h * rng.between(0.1, 0.35), h * rng.between(0.02, 0.06));
                    let a = rng.between(0.15, 0.35);
                    let (c, s) = (angle.cos(), angle.sin());
                    splat(&mut clear, at, half_len + 3.0 * half_width, &|dx, dy| {
                        let (along, across) = (dx * c + dy * s, -dx * s + dy * c);
                        let taper = smooth_edge(along.abs(), half_len, 0.3 * half_len);
                        a * taper * (-0.5 * (across / half_width).powi(2)).exp()
                    });
                }
                for _ in 0..3 {
                    let at = rng.in_disc(0.7 * h);
                    let radius = h * rng.between(0.12, 0.22);
                    let period = (h * rng.between(0.025, 0.035)).max(2.5 * texel_mm);
                    let (stretch, angle, a) = (rng.between(0.7, 1.0), rng.between(0.0, PI), rng.between(0.2, 0.35));
                    let (c, s) = (angle.cos(), angle.sin());
                    splat(&mut clear, at, radius, &|dx, dy| {
                        let (x, y) = (dx * c + dy * s, (-dx * s + dy * c) / stretch);
                        let d = x.hypot(y);
                        let ridges = 0.5 * (1.0 + (std::f64::consts::TAU * d / period).cos());
                        a * ridges * smooth_edge(d, 0.8 * radius, 0.2 * radius)
                    });
                }
            }
            Self::Image { size, luminance } => {
                let m = *size as f64;
                for j in 0..n {
                    for i in 0..n {
                        // The image spans the element's square [-h, h]^2, its top row at +y.
                        let (x, y) = (centre(i), -centre(j));
                        let (fx, fy) = ((x / h * 0.5 + 0.5) * m - 0.5, (0.5 - y / h * 0.5) * m - 0.5);
                        clear[j * n + i] = 1.0 - bilinear(luminance, *size, fx, fy);
                    }
                }
            }
        }
        (0..n * n)
            .map(|k| {
                let (x, y) = (centre(k % n), centre(k / n));
                if x.hypot(y) <= front_mm { (1.0 - clear[k]).clamp(0.0, 1.0) as f32 } else { 0.0 }
            })
            .collect()
    }
}

/// 1 inside `radius`, 0 beyond `radius + edge`, smooth between.
fn smooth_edge(d: f64, radius: f64, edge: f64) -> f64 {
    let t = ((d - radius) / edge.max(1e-12)).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// Bilinear sample of a `size`^2 grid at texel coordinates (`fx`, `fy`: texel centres at integers), clamped at
/// the edges.
fn bilinear(values: &[f32], size: usize, fx: f64, fy: f64) -> f64 {
    let last = size as i64 - 1;
    let (x0, y0) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - x0, fy - y0);
    let at = |i: i64, j: i64| f64::from(values[(j.clamp(0, last) * size as i64 + i.clamp(0, last)) as usize]);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = at(x0, y0) * (1.0 - tx) + at(x0 + 1, y0) * tx;
    let bottom = at(x0, y0 + 1) * (1.0 - tx) + at(x0 + 1, y0 + 1) * tx;
    top * (1.0 - ty) + bottom * ty
}

/// A small deterministic generator (SplitMix64) for the procedural patterns: a seed always draws the same dirt.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn between(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A point uniform in the disc of `radius`.
    fn in_disc(&mut self, radius: f64) -> [f64; 2] {
        let (r, phi) = (radius * self.between(0.0, 1.0).sqrt(), self.between(0.0, std::f64::consts::TAU));
        [r * phi.cos(), r * phi.sin()]
    }
}

/// The Henyey-Greenstein `g` whose lobe falls to half its peak at `spread_deg` (clamped to
/// [`SPREAD_RANGE_DEG`]): `1 + g^2 - 2 g cos(alpha) = 2^(2/3) (1 - g)^2`, solved by bisection.
pub fn henyey_greenstein_g(spread_deg: f64) -> f64 {
    let spread = if spread_deg.is_finite() { spread_deg } else { SPREAD_RANGE_DEG.1 };
    let c = spread.clamp(SPREAD_RANGE_DEG.0, SPREAD_RANGE_DEG.1).to_radians().cos();
    let f = |g: f64| 1.0 + g * g - 2.0 * g * c - 2f64.powf(2.0 / 3.0) * (1.0 - g) * (1.0 - g);
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// The Henyey-Greenstein lobe per steradian at `cos_alpha` (normalised over the sphere).
pub fn henyey_greenstein(g: f64, cos_alpha: f64) -> f64 {
    (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos_alpha).powf(1.5))
}

/// The dirt of a lens at its stop: the mean share over each footprint (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedDirt {
    /// Texels across the map.
    pub size: usize,
    /// The map spans `[-half_extent_mm, half_extent_mm]^2` of the entrance plane.
    pub half_extent_mm: f64,
    /// The dirt's share per texel (row 0 at +y), before the footprint.
    pub share: Vec<f32>,
    /// `D`: the mean share over the footprint centred at each texel, in half floats as the GPU holds them.
    pub map: Vec<f32>,
    /// The largest `D` (what a frame's glow can reach at most, for culling a glow no pixel would show).
    pub map_peak: f32,
    /// The entrance pupil's semi-axes at the stop's f-number, per axis.
    pub pupil_radius_mm: [f64; 2],
    /// The entrance pupil's open area (the stop's shape).
    pub pupil_area_mm2: f64,
    /// `sum_w weight_rgb(w) T(w)`: the light's colour through the image path.
    pub colour_rgb: [f64; 3],
    /// The front element's clear radius.
    pub front_radius_mm: f64,
}

impl PreparedDirt {
    /// The dirt `pattern` on the front element of `system`'s lens, seen through the stop `mask`.
    pub fn new(system: &GhostSystem, mask: &ApertureMask, pattern: &DirtPattern) -> Self {
        let x = system.x_system();
        let stop_scale = system.settings.stop_scale.clamp(1e-6, 1.0);
        let radius = |s: &GhostSystem| 0.5 * s.first_order.entrance_pupil_diameter_mm.abs() * stop_scale;
        let pupil_radius_mm = [radius(x), radius(system)];
        let front_radius_mm = system.front_radius_mm.abs();
        let reach = pupil_radius_mm[0].max(pupil_radius_mm[1]);
        let n = DIRT_MAP_SIZE;
        let half_extent_mm = (front_radius_mm + reach) * (1.0 + 2.0 / n as f64);
        let share = pattern.rasterise(n, half_extent_mm, front_radius_mm);
        let texel_mm = 2.0 * half_extent_mm / n as f64;
        // The footprint seen from its centre: the stop's shape, turned over when the pupil is.
        let flip = if system.image_stop_a < 0.0 { -1.0 } else { 1.0 };
        let map = convolve_footprint(&share, n, texel_mm, |qx, qy| {
            // The convolution's kernel is the footprint reflected: D(c) = sum_q s(c + q) K(q).
            mask.sample((-flip * qx / pupil_radius_mm[0]) as f32, (-flip * qy / pupil_radius_mm[1]) as f32)
        });
        let map: Vec<f32> = map.into_iter().map(|v| half::f16::from_f32(v.clamp(0.0, 1.0)).to_f32()).collect();
        let map_peak = map.iter().copied().fold(0.0, f32::max);
        let pupil_area_mm2 = mask.open_fraction() * 4.0 * pupil_radius_mm[0] * pupil_radius_mm[1];
        let spectrum = &system.settings.spectrum;
        let mut colour_rgb = [0.0; 3];
        for (w, weight) in spectrum.weights_rgb.iter().enumerate() {
            let t = system.image_transmission.get(w).copied().unwrap_or(1.0);
            for c in 0..3 {
                colour_rgb[c] += weight[c] * t;
            }
        }
        Self {
            size: n,
            half_extent_mm,
            share,
            map,
            map_peak,
            pupil_radius_mm,
            pupil_area_mm2,
            colour_rgb,
            front_radius_mm,
        }
    }

    /// The footprint's centre on the entrance plane for light slopes `u`: where the chief ray crosses it
    /// ([`GhostSystem::light_entrance_mm`], by exact tracing; `-z_EP u` paraxially).
    pub fn footprint_centre_mm(&self, system: &GhostSystem, u: [f64; 2]) -> [f64; 2] {
        system.light_entrance_mm(u)
    }

    /// `D` at the entrance-plane point `c_mm`: bilinear between texel centres, 0 outside the grid, in f32 as
    /// the shader computes it.
    pub fn mean_share_at(&self, c_mm: [f64; 2]) -> f32 {
        let n = self.size as f32;
        let scale = n / (2.0 * self.half_extent_mm) as f32;
        let tx = c_mm[0] as f32 * scale + 0.5 * n - 0.5;
        let ty = -(c_mm[1] as f32) * scale + 0.5 * n - 0.5;
        sample_map(&self.map, self.size, tx, ty)
    }

    /// The share of the light of slopes `u` that the dirt takes from the image and every ghost:
    /// `amount D(c_s)`, in [0, 1]; 0 for an amount of 0 (or not finite).
    pub fn taken_share(&self, system: &GhostSystem, u: [f64; 2], amount: f64) -> f64 {
        if !(amount.is_finite() && amount > 0.0 && u.iter().all(|v| v.is_finite())) {
            return 0.0;
        }
        (amount * f64::from(self.mean_share_at(self.footprint_centre_mm(system, u)))).clamp(0.0, 1.0)
    }

    /// The power the dirt scatters out of the light of slopes `u` that enters the pupil, per channel (relative
    /// irradiance x mm^2, before the light's gain): `amount D(c_s) A_EP cos(theta_s) T`. The glow puts it on
    /// the sensor, less what falls outside the frame (see the module documentation).
    pub fn taken_power(&self, system: &GhostSystem, u: [f64; 2], amount: f64) -> [f64; 3] {
        let cos_theta = 1.0 / (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
        let p = self.taken_share(system, u, amount) * self.pupil_area_mm2 * cos_theta;
        self.colour_rgb.map(|c| c * p)
    }
}

/// `D` sampled at texel coordinates (`tx`, `ty`, texel centres at integers) of an `n`^2 map, bilinear, texels
/// outside the map 0: the CPU twin of `sample_map` in `shaders/dirt.wgsl`.
pub fn sample_map(map: &[f32], n: usize, tx: f32, ty: f32) -> f32 {
    let size = n as f32;
    if !(tx > -1.0 && tx < size && ty > -1.0 && ty < size) {
        return 0.0;
    }
    let (x0, y0) = (tx.floor(), ty.floor());
    let (fx, fy) = (tx - x0, ty - y0);
    let (x0, y0) = (x0 as i32, y0 as i32);
    let texel = |i: i32, j: i32| {
        if i < 0 || j < 0 || i >= n as i32 || j >= n as i32 { 0.0 } else { map[j as usize * n + i as usize] }
    };
    let top = texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx;
    let bottom = texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// `share` (n x n) convolved with the kernel `kernel(qx, qy)` (qx, qy in mm, texel centres at multiples of
/// `texel_mm`, y up), normalised to sum 1, by FFT on a grid padded to 2n (no wrap: the kernel's reach is at
/// most n / 2 texels). Each kernel texel is the mean of 3 x 3 samples; a kernel with nothing open (a pupil
/// narrower than its samples) is one texel.
fn convolve_footprint(share: &[f32], n: usize, texel_mm: f64, kernel: impl Fn(f64, f64) -> f32) -> Vec<f32> {
    let m = 2 * n;
    let reach = (n / 2) as i64;
    let mut k = vec![Complex32::new(0.0, 0.0); m * m];
    let mut sum = 0.0f64;
    for dj in -reach..=reach {
        for di in -reach..=reach {
            let mut v = 0.0f64;
            for sj in [-1.0, 0.0, 1.0] {
                for si in [-1.0, 0.0, 1.0] {
                    let (qx, qy) = ((di as f64 + si / 3.0) * texel_mm, -(dj as f64 + sj / 3.0) * texel_mm);
                    v += f64::from(kernel(qx, qy)) / 9.0;
                }
            }
            if v > 0.0 {
                let (i, j) = (di.rem_euclid(m as i64) as usize, dj.rem_euclid(m as i64) as usize);
                k[j * m + i] = Complex32::new(v as f32, 0.0);
                sum += v;
            }
        }
    }
    if !(sum > 0.0 && sum.is_finite()) {
        k.iter_mut().for_each(|c| *c = Complex32::new(0.0, 0.0));
        k[0] = Complex32::new(1.0, 0.0);
        sum = 1.0;
    }
    let mut s = vec![Complex32::new(0.0, 0.0); m * m];
    for j in 0..n {
        for i in 0..n {
            s[j * m + i] = Complex32::new(share[j * n + i], 0.0);
        }
    }
    let mut planner = FftPlanner::<f32>::new();
    let (forward, inverse) = (planner.plan_fft_forward(m), planner.plan_fft_inverse(m));
    fft_2d(&mut s, m, forward.as_ref());
    fft_2d(&mut k, m, forward.as_ref());
    let scale = (1.0 / (sum * (m * m) as f64)) as f32;
    for (a, b) in s.iter_mut().zip(&k) {
        *a = *a * *b * scale;
    }
    fft_2d(&mut s, m, inverse.as_ref());
    (0..n * n).map(|q| s[(q / n) * m + q % n].re.max(0.0)).collect()
}

/// The document's dirt (the preset's `dirt`): which pattern, and the display's amount and spread.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DirtDoc {
    pub pattern: DirtKind,
    /// The procedural patterns' seed.
    pub seed: u64,
    /// The image of [`DirtKind::Image`] (grey, white is dirt).
    pub image: Option<String>,
    /// The share of the light scattered where the dirt is densest, 0 to 1.
    pub amount: f64,
    /// The scattering lobe's half width at half peak (degrees, 0.5 to 60).
    pub spread_deg: f64,
}

/// A dirt pattern's kind as the preset names it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DirtKind {
    /// A clean lens.
    #[default]
    None,
    Dust,
    Smudges,
    Haze,
    Image,
}

impl DirtKind {
    pub const ALL: [DirtKind; 5] = [Self::None, Self::Dust, Self::Smudges, Self::Haze, Self::Image];

    pub fn word(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Dust => "dust",
            Self::Smudges => "smudges",
            Self::Haze => "haze",
            Self::Image => "image",
        }
    }
}

/// The amount a fresh dirt pattern starts with: 1% scattered where the dirt is densest.
pub(crate) const DEFAULT_DIRT_AMOUNT: f64 = 0.01;
/// The spread a fresh dirt pattern starts with (degrees).
pub(crate) const DEFAULT_DIRT_SPREAD_DEG: f64 = 8.0;

impl Default for DirtDoc {
    fn default() -> Self {
        Self {
            pattern: DirtKind::None,
            seed: 1,
            image: None,
            amount: DEFAULT_DIRT_AMOUNT,
            spread_deg: DEFAULT_DIRT_SPREAD_DEG,
        }
    }
}

impl DirtDoc {
    /// The pattern to prepare (`None`: a clean lens), the image read when there is one.
    pub fn pattern(&self) -> Result<Option<DirtPattern>, DirtError> {
        Ok(match self.pattern {
            DirtKind::None => None,
            DirtKind::Dust => Some(DirtPattern::Dust { seed: self.seed }),
            DirtKind::Smudges => Some(DirtPattern::Smudges { seed: self.seed }),
            DirtKind::Haze => Some(DirtPattern::Haze),
            DirtKind::Image => match &self.image {
                Some(path) => Some(DirtPattern::image_from_file(Path::new(path))?),
                None => {
                    return Err(DirtError::Image("the pattern `image` needs `dirt.image`, a grey image file".into()));
                }
            },
        })
    }

    /// The values serde cannot check: the field and the reason.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.amount.is_finite() && (0.0..=1.0).contains(&self.amount)) {
            return Err(("dirt.amount", format!("{} must be from 0 to 1 (a share of the light)", self.amount)));
        }
        let (lo, hi) = SPREAD_RANGE_DEG;
        if !(self.spread_deg.is_finite() && (lo..=hi).contains(&self.spread_deg)) {
            return Err(("dirt.spread_deg", format!("{} must be from {lo} to {hi} degrees", self.spread_deg)));
        }
        if self.pattern == DirtKind::Image && self.image.is_none() {
            return Err(("dirt.image", "the pattern `image` needs an image file".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lobe_is_normalised_and_half_peak_at_its_spread() {
        for spread in [1.0, 8.0, 30.0] {
            let g = henyey_greenstein_g(spread);
            let half = henyey_greenstein(g, spread.to_radians().cos()) / henyey_greenstein(g, 1.0);
            assert!((half - 0.5).abs() < 1e-9, "{spread}: {half}");
            // Over the sphere, on a grid fine near the peak (cos alpha = 1 - t^2).
            let samples = 200_000;
            let total: f64 = (0..samples)
                .map(|k| {
                    let t = 2f64.sqrt() * (k as f64 + 0.5) / samples as f64;
                    henyey_greenstein(g, 1.0 - t * t) * 2.0 * PI * 2.0 * t * (2f64.sqrt() / samples as f64)
                })
                .sum();
            assert!((total - 1.0).abs() < 1e-4, "{spread}: {total}");
        }
    }

    #[test]
    fn patterns_are_shares_inside_the_front_element() {
        for pattern in [DirtPattern::Dust { seed: 3 }, DirtPattern::Smudges { seed: 3 }, DirtPattern::Haze] {
            let map = pattern.rasterise(64, 12.0, 10.0);
            assert!(map.iter().all(|v| (0.0..=1.0).contains(v)));
            assert!(map.iter().any(|&v| v > 0.05), "{pattern:?} has dirt");
            let corner = map[0];
            assert_eq!(corner, 0.0, "nothing beyond the front radius");
        }
        assert_eq!(
            DirtPattern::Dust { seed: 3 }.rasterise(32, 12.0, 10.0),
            DirtPattern::Dust { seed: 3 }.rasterise(32, 12.0, 10.0)
        );
        assert_ne!(
            DirtPattern::Dust { seed: 3 }.rasterise(32, 12.0, 10.0),
            DirtPattern::Dust { seed: 4 }.rasterise(32, 12.0, 10.0)
        );
    }

    #[test]
    fn the_footprint_convolution_keeps_the_mean() {
        // A single speck spreads into the kernel's shape and keeps its sum.
        let n = 64;
        let mut share = vec![0.0f32; n * n];
        share[32 * n + 32] = 1.0;
        let out = convolve_footprint(&share, n, 1.0, |qx, qy| if qx.hypot(qy) <= 5.0 { 1.0 } else { 0.0 });
        let total: f32 = out.iter().sum();
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        assert!(out[32 * n + 36] > 0.0 && out[32 * n + 39] < 1e-5);
        // Even dirt stays even where the footprint is inside the map.
        let even = convolve_footprint(&vec![0.25; n * n], n, 1.0, |qx, qy| if qx.hypot(qy) <= 5.0 { 1.0 } else { 0.0 });
        assert!((even[32 * n + 32] - 0.25).abs() < 1e-5);
    }
}
