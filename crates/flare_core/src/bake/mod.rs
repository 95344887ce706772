//! The LUT generator: each non-linear ghost ray-traced at the thetas and azimuths the run time interpolates.
//!
//! The room holds what makes a LUT: [`classify`] (which ghosts need one), this module (the bake), [`check`]
//! (whether a LUT belongs to a lens: its fingerprint) and [`cache`] (the on-disk cache). It sits above the frame
//! pipeline ([`crate::flare`], [`crate::render`]'s CPU twin), which it uses to compare the paraxial sprites;
//! what a LUT is and how it is drawn at run time is [`crate::lut`], below the renderer.
//!
//! # How it works
//! Per ghost (ghosts in parallel with rayon; inside a ghost, its wavelengths in parallel too), and per azimuth
//! of the symmetry wedge ([`crate::lut::Symmetry::phi_samples`]):
//! 1. **A column of entries** at theta, one per azimuth phi of the wedge (the light at `theta` from the axis
//!    with the azimuth `axis + phi`), from one set of traced rays: the lens is rotationally symmetric, so the
//!    rays traced for the first azimuth, turned about the axis, are the rays of every other; only the stop's
//!    blades do not turn, and the mask is looked up at the turned stop coordinates
//!    ([`crate::raytrace::RayGridRequest`]'s views). Where the ghost lands is found by a scout
//!    ([`RayGridRenderer::scout`]); the window around it gets at most [`BakeSettings::res`] texels across
//!    (never finer than `crate::lut::MIN_TEXEL_MM`), and the ghost alone is rendered into it by the reference
//!    renderer ([`Grid::Adaptive`], up to [`BakeSettings::grid`] cells, over only the region the scout saw
//!    light pass: [`crate::raytrace::Ghosts::Scouted`]). Alpha is the coverage ([`crate::lut::texels_with_coverage`]).
//!    **Detail**: where the ghost is large on the sensor (`res` texels coarser than
//!    [`BakeSettings::diagonal_texels`] across the sensor's diagonal) and an entry loses more than
//!    [`BakeSettings::detail_tolerance`] of its light's placement when halved ([`crate::lut::LutEntry::detail_lost`]: a
//!    sharp rim or caustic reaches its texels), the column is drawn again with texels `res`'s halved the number
//!    of times that comes nearest, on a grid refined as often (up to the reference's
//!    [`crate::raytrace::REFERENCE_GRID`] cells: cells several texels wide draw a smooth interior as rings of
//!    flat triangles), and each entry is halved back while that loses no more than the tolerance. A
//!    smooth ghost keeps its `res` entries, byte for byte; a sharp one is drawn finer and stored as fine as its
//!    detail needs (the run time's mip levels, [`crate::lut::blend::LiveLut`], draw it on small frames for the cost
//!    of the `res` entry).
//! 2. **Thetas where the pattern changes**: the angles start at `initial_steps` even steps from 0 to the
//!    useful field (the light angle whose image reaches the corner of the 36 x 24 mm sensor). Every interval
//!    wider than twice [`BakeSettings::min_step_deg`] gets its middle rendered and kept; while the run time's
//!    prediction of that middle (the two neighbours interpolated in their paraxial frames, exactly as
//!    [`crate::lut::blend`] draws them, plainly and fitted onto one shape by [`crate::lut::fit_picks`]) is off by more
//!    than [`BakeSettings::tolerance`] (relative L1 of luminance, worst azimuth), both halves are split again,
//!    unless the error is moderate (under [`REFINE_ALWAYS_ABOVE`] x the tolerance) and halving the step did
//!    not improve the prediction by [`REFINE_GAIN`] (then the error is not the spacing, and more entries would
//!    not mend it): [`refinement_done`]. Both halves are fitted at run time when the fitted prediction of
//!    their middle was the better one (a half split again decides for itself; one narrower than twice the
//!    finest step keeps that choice).
//!
//! What draws a column once the scout has placed it is a [`ColumnTracer`]: the CPU reference renderer
//! (`CpuTracing`, [`bake`]) or its GPU twin (`render::raygrid::GpuBake` through [`bake_with`]); the scouts and
//! the refinement are the same for both.
//!
//! Progress is reported per entry through a callback, and the bake stops at the next entry when the cancel
//! flag is set. Its memory is bounded before it starts (`BakeMemory`: each thread's working memory must fit)
//! and as it goes: the texels it keeps are counted and it stops, naming the figures, when they pass the bound. Given the previous LUT, a ghost whose key (the lens fingerprint, the ghost, the bake
//! settings and the bake's revision) is unchanged is kept, not re-baked: re-classifying, forcing a ghost or
//! changing the theta range re-bakes only what changed. Any edit of the lens, its coatings, spectrum or stop
//! changes every ghost's key, because every ghost path crosses every surface (as a refraction at least).

pub mod cache;
pub mod check;
pub mod classify;

pub use check::lut_fingerprint;

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

use half::f16;
use rayon::prelude::*;

use crate::color::luminance;
use crate::flare::PreparedFlare;
use crate::ghost::light_slopes_for_frame_position;
use crate::lut::{
    Fit, GhostLut, LutEntry, LutGhost, LutKind, MIN_TEXEL_MM, Mat2, Symmetry, fit_picks, light_position_deg, mat_apply,
    mat_det, mat_inverse, texels_with_coverage,
};
use crate::raytrace::{ColumnTracer, CpuTracing, Grid, RayGridRenderer, Scout, View, Window};

/// How a LUT is baked.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BakeSettings {
    /// Largest theta (default: the lens's useful field, [`useful_field_deg`]).
    pub theta_max_deg: Option<f64>,
    /// Most texels across an entry of a ghost small on the sensor.
    pub res: u32,
    /// Texels across the sensor's diagonal that an entry of a ghost large on the sensor is baked at when its
    /// detail needs them ([`Self::detail_tolerance`]): its texels are those of `res` halved the number of times
    /// that comes nearest (up to [`MAX_ENTRY_TEXELS`] across), so that stretched over the frame it does not show
    /// its texels as stair steps. 0: `res` alone. The run time draws such an entry from a mip pyramid
    /// ([`crate::lut::blend::LiveLut`]), so a small frame samples it about as often as the `res` entry. Measured
    /// (README, "LUT images without stair steps"): the Heliar's rim ghost at 1536x1024 goes from 31.5 dB at `res`
    /// alone to 33.8 dB at 512 (the default: 4-pixel beading left along the rim) and 35.0 dB at 1024 (no steps
    /// seen), the Nikon zoom's LUT from 45 M texels to 58 M and 95 M.
    pub diagonal_texels: u32,
    /// An entry of a large ghost is baked finer ([`Self::diagonal_texels`]) where halving it at `res` loses more
    /// than this share of its light's placement ([`crate::lut::LutEntry::detail_lost`]: relative L1 of luminance
    /// against the halved image's bilinear upsample): a sharp rim or caustic, not a smooth blur; the finer entry
    /// is then halved back while that loses no more than this. On the Heliar the rim ghost loses 0.16-0.24 at
    /// `res`, the smooth one 0.010-0.015; on the Nikon zoom 99 of 1031 large entries lose more than 0.05.
    pub detail_tolerance: f64,
    /// Most ray-grid cells across a ghost's entrance region (the reference renderer's adaptive grid) for a
    /// `res` entry; an entry drawn finer ([`Self::diagonal_texels`]) gets this many times its halvings, up to
    /// [`crate::raytrace::REFERENCE_GRID`]. 64 by default: over the scouted region that is about one cell per
    /// two texels; 32 costs the double Gauss 0.002-0.004 SSIM at 0 and 13 deg (how the default was chosen:
    /// CHANGELOG.md).
    pub grid: usize,
    /// Azimuth steps over the symmetry wedge (0: one azimuth, rotation only).
    pub phi_steps: u32,
    /// Even theta steps before refinement.
    pub initial_steps: u32,
    /// Refine an interval while the interpolated middle is off by more than this (relative L1).
    pub tolerance: f64,
    /// Finest theta step.
    pub min_step_deg: f64,
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            theta_max_deg: None,
            res: 128,
            diagonal_texels: 512,
            detail_tolerance: 0.05,
            grid: 64,
            phi_steps: 2,
            initial_steps: 4,
            tolerance: 0.12,
            min_step_deg: 0.75,
        }
    }
}

/// Why a bake stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BakeError {
    #[error("the bake was cancelled")]
    Cancelled,
    #[error("bake setting `{field}`: {reason}")]
    Setting { field: &'static str, reason: String },
    #[error("ghost {0} does not exist (the lens has {1} ghosts)")]
    NoGhost(usize, usize),
    /// An anamorphic lens whose stop breaks its mirror symmetry (the reason).
    #[error("{0}")]
    Anamorphic(String),
    /// The bake would need more memory than it may take (`BakeMemory`): the figures and what to change.
    #[error("{0}")]
    TooLarge(String),
}

/// What one baked texel keeps (bytes): its RGBA in half floats ([`LutEntry::texels`]).
pub(crate) const BYTES_PER_TEXEL: u64 = 8;

/// What each thread of a bake holds at most while it draws a column (bytes): the ray grid's image of an entry
/// of [`MAX_ENTRY_TEXELS`] a side (RGBA floats, 16 bytes a texel) and as much again for the grid, the entry's
/// halvings and its texels before they are kept.
pub(crate) const THREAD_BYTES: u64 = (MAX_ENTRY_TEXELS as u64) * (MAX_ENTRY_TEXELS as u64) * 32;

/// The memory a bake may take, worked out before it starts (issue 61: memory known before work). A bake's
/// entries are refined where the ghost changes (their number is not known before), so its kept texels are
/// counted as it goes and the bake stops, naming the figures, when they pass [`Self::texels`]: the most a LUT
/// file holds ([`crate::lut::format::MAX_TEXELS`], 2 GiB of texels) or what nine tenths of the memory available
/// leaves after every thread's working memory ([`THREAD_BYTES`]), whichever is less. A machine without that
/// working memory free is refused before any work.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct BakeMemory {
    /// The most texels the bake keeps.
    pub texels: u64,
    /// Whether [`Self::texels`] is the machine's memory (else the LUT file's limit).
    pub machine_bound: bool,
}

impl BakeMemory {
    /// The bound for `threads` threads and `available` bytes free (`None`: unknown, the file's limit alone).
    pub fn new(threads: usize, available: Option<u64>) -> Result<Self, BakeError> {
        let file = crate::lut::format::MAX_TEXELS;
        let Some(available) = available else {
            return Ok(Self { texels: file, machine_bound: false });
        };
        let working = threads.max(1) as u64 * THREAD_BYTES;
        let usable = crate::frame::usable_memory_bytes(available);
        // At least a few hundred entries of `res` texels: less than that is no LUT worth baking.
        let least = working + (1 << 24) * BYTES_PER_TEXEL;
        if usable < least {
            return Err(BakeError::TooLarge(format!(
                "a bake on {threads} threads needs at least {:.1} GB (each thread's working memory, {:.0} MB, and \
                 room for the LUT), more than nine tenths of the {:.1} GB this machine has free",
                least as f64 / 1e9,
                THREAD_BYTES as f64 / 1e6,
                available as f64 / 1e9
            )));
        }
        let machine = (usable - working) / BYTES_PER_TEXEL;
        Ok(Self { texels: machine.min(file), machine_bound: machine < file })
    }

    /// The refusal of a bake whose kept texels reached `texels`.
    fn refusal(&self, texels: u64) -> BakeError {
        let bound = if self.machine_bound { "what this machine's free memory holds" } else { "a LUT file holds" };
        BakeError::TooLarge(format!(
            "the LUT grew past {:.0} M texels ({:.1} GB), more than the {:.0} M {bound}: bake fewer texels \
             (--res, --diagonal-texels), fewer steps (--min-step, --tolerance, --phi-steps) or fewer ghosts",
            texels as f64 / 1e6,
            (texels * BYTES_PER_TEXEL) as f64 / 1e9,
            self.texels as f64 / 1e6,
        ))
    }
}

/// Progress of a bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeProgress {
    /// Entries rendered so far (all ghosts).
    pub entries: usize,
    /// Ghosts finished (kept ones included) out of `ghosts_total`.
    pub ghosts_done: usize,
    pub ghosts_total: usize,
    /// Ghosts kept from the previous LUT.
    pub ghosts_kept: usize,
}

/// The light angle whose image reaches the corner of the 36 x 24 mm sensor (the lens's useful field), from
/// its focal length; at most 60 degrees.
pub fn useful_field_deg(flare: &PreparedFlare) -> f64 {
    let f = flare.system.first_order.efl_mm.abs();
    if f > 0.0 && f.is_finite() {
        (crate::lut::SENSOR_HALF_DIAGONAL_MM / f).atan().to_degrees().min(60.0)
    } else {
        20.0
    }
}

impl BakeSettings {
    fn validate(&self) -> Result<(), BakeError> {
        let bad = |field, reason: &str| Err(BakeError::Setting { field, reason: reason.into() });
        if let Some(t) = self.theta_max_deg
            && !(t.is_finite() && t > 0.0 && t <= 85.0)
        {
            return bad("theta_max_deg", "must be above 0 and at most 85 degrees");
        }
        if !(8..=1024).contains(&self.res) {
            return bad("res", "use 8 to 1024 texels");
        }
        if self.diagonal_texels > 4096 {
            return bad("diagonal_texels", "use 0 (off) to 4096 texels");
        }
        if !(self.detail_tolerance.is_finite() && self.detail_tolerance >= 0.0) {
            return bad("detail_tolerance", "must be 0 or more");
        }
        if !(4..=crate::raytrace::REFERENCE_GRID * 2).contains(&self.grid) {
            return bad("grid", "use 4 to 512 cells");
        }
        if self.phi_steps > 16 || !(1..=64).contains(&self.initial_steps) {
            return bad("phi_steps/initial_steps", "at most 16 azimuth steps, 1 to 64 initial theta steps");
        }
        if !(self.tolerance.is_finite()
            && self.tolerance > 0.0
            && self.min_step_deg.is_finite()
            && self.min_step_deg > 0.0)
        {
            return bad("tolerance/min_step_deg", "must be positive");
        }
        Ok(())
    }
}

/// Refinement stops where halving the theta step improved the prediction of the middle by less than this
/// factor (the error stays above `REFINE_GAIN` x the error of the interval it was split from), as long as the
/// error is under [`REFINE_ALWAYS_ABOVE`] x the tolerance.
pub const REFINE_GAIN: f64 = 0.75;

/// Above this many times the tolerance an interval is split whatever the last halving gained: an error that
/// large is the ghost changing shape within the interval (a vignetting edge sweeping across it, a ghost
/// shrinking to nothing), which finer steps do mend. Ghost (4, 5) of the Nikon zoom shrinks from frame-filling
/// to nothing between 6.9 and 9.2 deg; stopping there for lack of gain (0.63 over 0 to 9.2 deg, 0.84 over
/// 4.6 to 9.2) left a cross-fade of the two: the blended frame at 8 deg scored 30.3 dB, 37.3 dB now.
pub const REFINE_ALWAYS_ABOVE: f64 = 2.0;

/// Whether an interval whose middle was predicted with relative L1 `error` is final, given the error of the
/// interval it was split from (`parent_error`, infinite for the initial ones): predicted within `tolerance`,
/// or the error is moderate and halving the step did not make the prediction clearly better (what is left is
/// not the theta spacing: a rim the grids draw differently, a ring thinner than a texel).
pub fn refinement_done(error: f64, parent_error: f64, tolerance: f64) -> bool {
    error <= tolerance || (error <= REFINE_ALWAYS_ABOVE * tolerance && error > REFINE_GAIN * parent_error)
}

/// An entry's window reaches this many times the sensor's half-diagonal from the axis, at most.
pub(crate) const VISIBLE_MARGIN: f64 = 1.15;
/// The most texels across an entry (a large ghost's, [`BakeSettings::diagonal_texels`]): an atlas page
/// ([`crate::lut::blend::ATLAS_PAGE`]) less the zero border, with room to spare.
pub const MAX_ENTRY_TEXELS: u32 = 2040;

/// Renders one entry: ghost `g` with the light at `theta_deg` and the azimuth `axis + phi_deg`.
pub fn render_entry(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    g: usize,
    theta_deg: f64,
    phi_deg: f64,
    symmetry: &Symmetry,
    settings: &BakeSettings,
) -> LutEntry {
    render_column(flare, renderer, &CpuTracing, g, theta_deg, &[phi_deg], symmetry, settings).remove(0)
}

/// Renders the entries of ghost `g` at `theta_deg` for every azimuth `axis + phi` of `phis_deg`, from one
/// set of traced rays (a view per azimuth: the lens turns the image with the light), drawn by `tracing`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_column(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    tracing: &dyn ColumnTracer,
    g: usize,
    theta_deg: f64,
    phis_deg: &[f64],
    symmetry: &Symmetry,
    settings: &BakeSettings,
) -> Vec<LutEntry> {
    if flare.system.lens.is_anamorphic() && phis_deg.len() > 1 {
        // No rotation turns an anamorphic lens's ghost into its ghost at another azimuth: each azimuth is traced
        // on its own (what a lens of revolution saves, an anamorphic bake pays: a trace per azimuth).
        return phis_deg
            .iter()
            .flat_map(|&phi| render_column(flare, renderer, tracing, g, theta_deg, &[phi], symmetry, settings))
            .collect();
    }
    // Traced for the light at the first azimuth; each entry's view turns it on to its own.
    let base_deg = phis_deg.first().copied().unwrap_or(0.0);
    let base = light_position_deg(theta_deg, symmetry.axis_deg + base_deg);
    let turns: Vec<f64> = phis_deg.iter().map(|p| p - base_deg).collect();
    let scout = renderer.scout(g, base, 48, &turns);
    // Only what can reach the frame: the sensor's corners at any azimuth, with a margin for the frames that
    // interpolation and fitting move an entry by.
    let reach = VISIBLE_MARGIN * crate::lut::SENSOR_HALF_DIAGONAL_MM;
    let boxes: Vec<Option<[f64; 4]>> = scout
        .footprints_mm
        .iter()
        .map(|f| {
            f.map(|b| [b[0].max(-reach), b[1].max(-reach), b[2].min(reach), b[3].min(reach)])
                .filter(|b| b[0] < b[2] && b[1] < b[3])
        })
        .collect();
    let empty: Vec<LutEntry> = phis_deg
        .iter()
        .map(|&phi_deg| {
            let light = light_position_deg(theta_deg, symmetry.axis_deg + phi_deg);
            let u = light_slopes_for_frame_position(light[0], light[1]);
            LutEntry::empty(theta_deg, phi_deg, flare.system.paraxial_frame(g, u, MIN_TEXEL_MM))
        })
        .collect();
    // The column at `res` texels across (halvings 0), then, where a ghost is large on the sensor and an entry
    // loses more than `detail_tolerance` of its light's placement when halved (its detail reaches its texels),
    // again with texels 2^halvings finer, each entry then halved back while that loses no more.
    let mut entries = draw_column(renderer, tracing, &scout, &boxes, &empty, base_deg, settings, 0);
    let finest = boxes.iter().flatten().map(|b| finer_halvings(b, settings)).max().unwrap_or(0);
    let detailed = |e: &LutEntry| !e.is_empty() && e.detail_lost(&e.halved()) > settings.detail_tolerance;
    if finest > 0 && entries.iter().any(detailed) {
        let fine = draw_column(renderer, tracing, &scout, &boxes, &empty, base_deg, settings, finest);
        entries = fine
            .into_iter()
            .zip(entries)
            .map(|(mut e, coarse)| {
                if e.is_empty() {
                    return coarse;
                }
                while e.texel_mm < 0.75 * coarse.texel_mm {
                    let halved = e.halved();
                    if e.detail_lost(&halved) > settings.detail_tolerance {
                        break;
                    }
                    e = halved;
                }
                crate::lut::set_coverage(&mut e.texels);
                e
            })
            .collect();
    }
    entries
}

/// The texel (mm) of an entry whose ghost lands on `b` (x0, y0, x1, y1 in mm) at `res` texels across.
fn res_texel_mm(b: &[f64; 4], settings: &BakeSettings) -> f64 {
    ((b[2] - b[0]).max(b[3] - b[1]) / f64::from(settings.res - 2)).max(MIN_TEXEL_MM)
}

/// How many halvings of [`res_texel_mm`] come nearest [`BakeSettings::diagonal_texels`] across the sensor's
/// diagonal for a ghost landing on `b`, no finer than [`MIN_TEXEL_MM`] and at most [`MAX_ENTRY_TEXELS`] across
/// with the margin: 0 when the ghost is small on the sensor (or the setting is off).
fn finer_halvings(b: &[f64; 4], settings: &BakeSettings) -> u32 {
    if settings.diagonal_texels == 0 {
        return 0;
    }
    let coarse = res_texel_mm(b, settings);
    let target = 2.0 * crate::lut::SENSOR_HALF_DIAGONAL_MM / f64::from(settings.diagonal_texels);
    let extent_mm = (b[2] - b[0]).max(b[3] - b[1]);
    let mut k = (coarse / target).log2().round().clamp(0.0, 16.0) as u32;
    while k > 0 && {
        let texel = coarse / f64::from(1u32 << k);
        texel < MIN_TEXEL_MM || (extent_mm / texel).ceil() + f64::from(4u32 << k) > f64::from(MAX_ENTRY_TEXELS)
    } {
        k -= 1;
    }
    k
}

/// The column's entries (`empty`'s lights and paraxial frames) drawn with texels `2^-halvings` of
/// [`res_texel_mm`] into windows around `boxes` (the scouted footprints; `None`: the entry stays empty).
#[allow(clippy::too_many_arguments)]
fn draw_column(
    renderer: &RayGridRenderer,
    tracing: &dyn ColumnTracer,
    scout: &Scout,
    boxes: &[Option<[f64; 4]>],
    empty: &[LutEntry],
    base_deg: f64,
    settings: &BakeSettings,
    halvings: u32,
) -> Vec<LutEntry> {
    let mut entries = empty.to_vec();
    let mut views = Vec::new();
    for (k, (entry, b)) in entries.iter_mut().zip(boxes).enumerate() {
        let Some(b) = b else { continue };
        let (w_mm, h_mm) = (b[2] - b[0], b[3] - b[1]);
        let texel_mm = res_texel_mm(b, settings) / f64::from(1u32 << halvings);
        // Two `res` texels of margin each side: the bilinear splats of the rim's triangles land there, and the
        // light the scout's coarse cells did not see reaches there (a finer entry keeps the margin in mm).
        let margin = 4 << halvings;
        let (width, height) = ((w_mm / texel_mm).ceil() as u32 + margin, (h_mm / texel_mm).ceil() as u32 + margin);
        let window = Window {
            centre_mm: [0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])],
            width_mm: texel_mm * f64::from(width),
            width,
            height,
        };
        (entry.centre_mm, entry.texel_mm, entry.width, entry.height) = (window.centre_mm, texel_mm, width, height);
        views.push((k, View { window, turn_deg: entry.phi_deg - base_deg }));
    }
    if views.is_empty() {
        return entries;
    }
    let only: Vec<View> = views.iter().map(|v| v.1).collect();
    // A finer entry gets a finer grid as well (the grid's cells kept to the same texels each), up to the
    // reference's: cells several texels wide draw a large ghost's smooth interior as rings of flat triangles.
    let cells = (settings.grid << halvings).min(crate::raytrace::REFERENCE_GRID);
    let Some(images) = tracing.trace_column(renderer, scout, only, Grid::Adaptive(cells)) else {
        return empty.to_vec();
    };
    for ((k, _), image) in views.into_iter().zip(images) {
        let entry = &mut entries[k];
        let peak = image.pixels.iter().map(|p| luminance([p[0], p[1], p[2]].map(f64::from))).fold(0.0, f64::max);
        if peak <= 0.0 {
            *entry = empty[k].clone();
            continue;
        }
        entry.texels = texels_with_coverage(image.pixels.iter().map(|p| [p[0], p[1], p[2]]));
    }
    entries
}

/// The run time's prediction of `target` from `a` and `b` (weights 1 - t, t), in `target`'s texels, and its
/// relative L1 error (luminance) against `target`. With `fitted` the two are first fitted onto one shape
/// ([`crate::lut::fit_picks`]), as the run time does for an interval baked as fitted.
pub fn interpolation_error(a: &LutEntry, b: &LutEntry, t: f64, target: &LutEntry, fitted: bool) -> f64 {
    if target.is_empty() {
        // All of the neighbours' light would be drawn where there is none.
        let predicted = (1.0 - t) * a.energy() + t * b.energy();
        return if predicted > 0.0 { 1.0 } else { 0.0 };
    }
    let actual: f64 = target.texels.iter().map(|p| luminance([p[0], p[1], p[2]].map(f16::to_f64))).sum();
    let baked = (1.0 - t) * a.paraxial.energy + t * b.paraxial.energy;
    let ratio = if baked > 0.0 && target.paraxial.energy > 0.0 {
        (target.paraxial.energy / baked).clamp(0.25, 4.0)
    } else {
        1.0
    };
    let window = target.window();
    let identity = [[1.0, 0.0], [0.0, 1.0]];
    let fits = if fitted {
        fit_picks(&[(a.shape(), identity, 1.0 - t), (b.shape(), identity, t)])
    } else {
        vec![Fit { linear: identity, offset: [0.0; 2] }; 2]
    };
    // Per neighbour: the inverse of its fit (target's normalised position to its own) and its area factor.
    let inverse = |f: &Fit| (mat_inverse(f.linear), f.offset, mat_det(f.linear).abs());
    let maps = [inverse(&fits[0]), inverse(&fits[1])];
    let decoded = [a.decoded(), b.decoded()];
    let sample =
        |e: &LutEntry, texels: &[[f32; 4]], (inv, offset, det): (Mat2, [f64; 2], f64), p_mm: [f64; 2]| -> f64 {
            if e.is_empty() {
                return 0.0;
            }
            // The target's normalised position, carried back through e's fit into e's paraxial frame.
            let n = [
                (p_mm[0] - target.paraxial.centre_mm[0]) / target.paraxial.half_mm - offset[0],
                (p_mm[1] - target.paraxial.centre_mm[1]) / target.paraxial.half_mm - offset[1],
            ];
            let n = mat_apply(inv, n);
            let q = [
                e.paraxial.centre_mm[0] + e.paraxial.half_mm * n[0],
                e.paraxial.centre_mm[1] + e.paraxial.half_mm * n[1],
            ];
            // Irradiance scales with 1 / area when the frame is scaled (and fitted).
            let area = (e.paraxial.half_mm / target.paraxial.half_mm).powi(2) / det;
            let px = e.window().to_pixel(q);
            let v = e.sample_decoded(texels, (px[0] / f64::from(e.width)) as f32, (px[1] / f64::from(e.height)) as f32);
            luminance([v[0], v[1], v[2]].map(f64::from)) * area
        };
    let mut error = 0.0;
    let mut predicted_sum = 0.0;
    for y in 0..target.height {
        for x in 0..target.width {
            let p_mm = window.to_mm([f64::from(x) + 0.5, f64::from(y) + 0.5]);
            let predicted =
                ratio * ((1.0 - t) * sample(a, &decoded[0], maps[0], p_mm) + t * sample(b, &decoded[1], maps[1], p_mm));
            let p = target.texels[(y * target.width + x) as usize];
            error += (predicted - luminance([p[0], p[1], p[2]].map(f16::to_f64))).abs();
            predicted_sum += predicted;
        }
    }
    if actual > 0.0 {
        error / actual
    } else if predicted_sum > 0.0 {
        1.0
    } else {
        0.0
    }
}

/// Revision of how entries are chosen and rendered, part of every ghost's key: a LUT baked by an older
/// revision is re-baked, not kept, by `--update` (what each revision changed: CHANGELOG.md).
const BAKE_REVISION: u32 = 5;

/// The key of ghost `g` for these settings (see the module documentation): a [`crate::fingerprint::of`] of
/// the bake revision, the lens's fingerprint, the ghost and the settings.
fn ghost_key(fingerprint: u64, g: usize, surfaces: (usize, usize), theta_max: f64, settings: &BakeSettings) -> u64 {
    crate::fingerprint::of(&(BAKE_REVISION, fingerprint, g, surfaces, theta_max, settings))
}

/// Bakes `ghosts` of `flare` (lens indices) on the CPU: [`bake_with`] and `CpuTracing`.
pub fn bake(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    ghosts: &[usize],
    settings: &BakeSettings,
    previous: Option<&GhostLut>,
    progress: &(dyn Fn(BakeProgress) + Sync),
    cancel: &AtomicBool,
) -> Result<GhostLut, BakeError> {
    bake_with(flare, renderer, &CpuTracing, ghosts, settings, previous, progress, cancel)
}

/// Bakes `ghosts` of `flare` (lens indices), each column's entries drawn by `tracing`. `previous` lends the
/// ghosts whose key is unchanged; `progress` is called after every entry and kept ghost; `cancel` stops the
/// bake.
#[allow(clippy::too_many_arguments)]
pub fn bake_with(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    tracing: &dyn ColumnTracer,
    ghosts: &[usize],
    settings: &BakeSettings,
    previous: Option<&GhostLut>,
    progress: &(dyn Fn(BakeProgress) + Sync),
    cancel: &AtomicBool,
) -> Result<GhostLut, BakeError> {
    settings.validate()?;
    let memory = BakeMemory::new(rayon::current_num_threads(), crate::frame::available_memory_bytes())?;
    bake_within(flare, renderer, tracing, ghosts, settings, previous, (progress, cancel), memory)
}

/// One column of a ghost's bake: its theta, its entries (one per phi), and whether the interval from it to
/// the next is fitted.
type Column = (f64, Vec<LutEntry>, bool);

/// A ghost's columns from 0 to `theta_max` degrees: `settings.initial_steps` intervals, each then refined
/// ([`refinement_done`]), every column drawn by `render`.
fn refined_columns(
    theta_max: f64,
    settings: &BakeSettings,
    render: impl Fn(f64) -> Result<Vec<LutEntry>, BakeError>,
) -> Result<Vec<Column>, BakeError> {
    let steps = settings.initial_steps;
    let mut columns: Vec<Column> = (0..=steps)
        .map(|k| {
            let theta = theta_max * f64::from(k) / f64::from(steps);
            render(theta).map(|e| (theta, e, false))
        })
        .collect::<Result<_, _>>()?;
    // Refine: split each interval while its middle is mispredicted both plainly and fitted
    // (depth-first, left to right); a kept interval is fitted when that predicted its middle better.
    // `errors[k]` is the error of the interval that interval k was split from (infinite for the
    // initial ones).
    let mut errors = vec![f64::INFINITY; columns.len()];
    let mut k = 0;
    while k + 1 < columns.len() {
        let (a, b) = (columns[k].0, columns[k + 1].0);
        if b - a < 2.0 * settings.min_step_deg {
            k += 1;
            continue;
        }
        let middle = 0.5 * (a + b);
        let entries = render(middle)?;
        let worst = |fitted: bool| {
            entries
                .iter()
                .enumerate()
                .map(|(p, e)| interpolation_error(&columns[k].1[p], &columns[k + 1].1[p], 0.5, e, fitted))
                .fold(0.0, f64::max)
        };
        let (plain, fitted) = (worst(false), worst(true));
        let error = plain.min(fitted);
        let done = refinement_done(error, errors[k], settings.tolerance);
        // The middle is kept either way (it cost a render). Both halves are fitted or not as the
        // better prediction of the middle says; a half that is split again gets its own say, and one
        // too narrow to split (under twice the finest step) keeps this one.
        columns[k].2 = fitted < plain;
        columns.insert(k + 1, (middle, entries, fitted < plain));
        errors[k] = error;
        errors.insert(k + 1, error);
        if done {
            k += 2;
        }
    }
    Ok(columns)
}

/// [`bake_with`] keeping at most `memory.texels` texels.
#[allow(clippy::too_many_arguments)]
fn bake_within(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    tracing: &dyn ColumnTracer,
    ghosts: &[usize],
    settings: &BakeSettings,
    previous: Option<&GhostLut>,
    (progress, cancel): (&(dyn Fn(BakeProgress) + Sync), &AtomicBool),
    memory: BakeMemory,
) -> Result<GhostLut, BakeError> {
    let total = flare.system.ghosts.len();
    if let Some(&bad) = ghosts.iter().find(|&&g| g >= total) {
        return Err(BakeError::NoGhost(bad, total));
    }
    let lens = &flare.system.lens;
    let fingerprint = lut_fingerprint(lens, &flare.config);
    // A ghost's surfaces as the lens without its inert surfaces numbers them (the fingerprint's lens): the LUT
    // and its ghosts' keys hold for the lens with or without a dummy surface.
    let numbering = lens.without_inert().1;
    let canonical = |k: usize| numbering.iter().position(|&live| live == k).unwrap_or(k);
    let symmetry = Symmetry::of(lens, &flare.config.aperture).map_err(BakeError::Anamorphic)?;
    let texels_kept = AtomicU64::new(0);
    let keep = |entries: &[LutEntry]| -> Result<(), BakeError> {
        let texels: u64 = entries.iter().map(|e| e.texels.len() as u64).sum();
        let now = texels_kept.fetch_add(texels, Ordering::Relaxed) + texels;
        if now > memory.texels { Err(memory.refusal(now)) } else { Ok(()) }
    };
    let theta_max = settings.theta_max_deg.unwrap_or_else(|| useful_field_deg(flare));
    // An anamorphic lens's ghosts change shape with the light's azimuth (no rotation turns one into another):
    // its quadrant is sampled every 15 degrees at the least.
    let phi_steps = if lens.is_anamorphic() {
        settings.phi_steps.max((symmetry.wedge_deg() / 15.0).ceil() as u32)
    } else {
        settings.phi_steps
    };
    let phis = symmetry.phi_samples(phi_steps);
    let entries_done = AtomicUsize::new(0);
    let ghosts_done = AtomicUsize::new(0);
    let kept = AtomicUsize::new(0);
    let report = || {
        progress(BakeProgress {
            entries: entries_done.load(Ordering::Relaxed),
            ghosts_done: ghosts_done.load(Ordering::Relaxed),
            ghosts_total: ghosts.len(),
            ghosts_kept: kept.load(Ordering::Relaxed),
        })
    };
    let baked: Result<Vec<LutGhost>, BakeError> = ghosts
        .par_iter()
        .map(|&g| {
            let model = &flare.system.ghosts[g];
            let pair = (canonical(model.i), canonical(model.j));
            let key = ghost_key(fingerprint, g, pair, theta_max, settings);
            if let Some(old) = previous.filter(|p| p.lens_fingerprint == fingerprint).and_then(|p| p.ghost(g))
                && old.key == key
            {
                keep(&old.entries)?;
                kept.fetch_add(1, Ordering::Relaxed);
                ghosts_done.fetch_add(1, Ordering::Relaxed);
                report();
                return Ok(old.clone());
            }
            let render = |theta: f64| -> Result<Vec<LutEntry>, BakeError> {
                if cancel.load(Ordering::Relaxed) {
                    return Err(BakeError::Cancelled);
                }
                let column = render_column(flare, renderer, tracing, g, theta, &phis, &symmetry, settings);
                keep(&column)?;
                entries_done.fetch_add(column.len(), Ordering::Relaxed);
                report();
                Ok(column)
            };
            let columns = refined_columns(theta_max, settings, render)?;
            ghosts_done.fetch_add(1, Ordering::Relaxed);
            report();
            Ok(LutGhost {
                ghost: g as u32,
                surfaces: [pair.0 as u32, pair.1 as u32],
                key,
                thetas_deg: columns.iter().map(|c| c.0).collect(),
                fitted: columns[..columns.len() - 1].iter().map(|c| c.2).collect(),
                phis_deg: phis.clone(),
                entries: columns.into_iter().flat_map(|c| c.1).collect(),
            })
        })
        .collect();
    let f_number = flare.config.aperture.f_number.unwrap_or(flare.system.first_order.f_number);
    Ok(GhostLut {
        kind: LutKind::RayTraced,
        lens_id: lens.id.clone(),
        lens_fingerprint: fingerprint,
        fingerprint_scheme: crate::fingerprint::SCHEME,
        wavelengths_nm: flare.config.spectrum.wavelengths_nm.clone(),
        f_number,
        symmetry,
        theta_max_deg: theta_max,
        ghosts: baked?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A machine whose free memory does not hold the threads' working memory refuses the bake before any
    /// work, naming the figures; with memory to spare the bound is the LUT file's.
    #[test]
    fn a_bake_is_bounded_before_it_starts() {
        let e = BakeMemory::new(16, Some(1 << 30)).unwrap_err().to_string();
        assert!(e.contains("16 threads") && e.contains("1.1 GB this machine has free"), "{e}");
        let roomy = BakeMemory::new(2, Some(1 << 40)).unwrap();
        assert_eq!(roomy, BakeMemory { texels: crate::lut::format::MAX_TEXELS, machine_bound: false });
        let tight = BakeMemory::new(2, Some(2 << 30)).unwrap();
        assert!(tight.machine_bound && tight.texels < crate::lut::format::MAX_TEXELS);
        assert_eq!(BakeMemory::new(2, None).unwrap().texels, crate::lut::format::MAX_TEXELS);
    }

    /// A bake whose kept texels pass its bound stops there with the figures (issue 61: a bake that grows past
    /// what a LUT file holds was found only when the file was written, after the whole bake).
    #[test]
    fn a_bake_stops_when_its_texels_pass_the_bound() {
        let lens = crate::optics::library::builtin_lens("heliar").unwrap();
        let flare = PreparedFlare::new(&lens, &crate::flare::FlareConfig::default()).unwrap();
        let renderer = flare.ray_grid_renderer();
        let settings =
            BakeSettings { theta_max_deg: Some(4.0), res: 16, diagonal_texels: 0, grid: 8, ..BakeSettings::default() };
        let run = |texels| {
            let memory = BakeMemory { texels, machine_bound: false };
            let hooks: (&(dyn Fn(BakeProgress) + Sync), &AtomicBool) = (&|_| {}, &AtomicBool::new(false));
            bake_within(&flare, &renderer, &CpuTracing, &[3, 7], &settings, None, hooks, memory)
        };
        let lut = run(u64::MAX).unwrap();
        let texels: usize = lut.ghosts.iter().flat_map(|g| &g.entries).map(|e| e.texels.len()).sum();
        assert!(texels > 1000, "{texels}");
        let e = run(texels as u64 / 2).unwrap_err().to_string();
        assert!(e.contains("the LUT grew past") && e.contains("a LUT file holds") && e.contains("--res"), "{e}");
        assert!(run(texels as u64).is_ok(), "the bound itself is allowed");
    }
}
