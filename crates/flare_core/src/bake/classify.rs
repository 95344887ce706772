//! Which ghosts are non-linear: the paraxial sprite against the ray-traced footprint, per ghost, over theta.
//!
//! # How it works
//! For each ghost and each of a few light angles from 0 to the useful field (at the symmetry axis's azimuth),
//! both images of that ghost alone are rendered into the same window of the sensor (the union of the two
//! footprints, [`ClassifySettings::res`] texels across): the ray-traced one on a coarse fixed grid
//! ([`crate::raytrace`]) and the paraxial sprites through the CPU twin of the GPU renderer. These measures
//! compare them, each the worst over the angles:
//! - the **centroid** offset (mm, and in units of the paraxial half-size);
//! - the **size** ratio of the rms radii about each centroid (reported as the larger of r and 1 / r);
//! - the **image error**: the total-variation distance of the two footprints, each normalised to unit
//!   energy, `0.5 sum |T / E_T - P / E_P|`, from 0 (same shape and place) to 1 (disjoint).
//!
//! A ghost is **non-linear** when its image error, or its energy ratio less 1, exceeds
//! [`ClassifySettings::threshold`] at an angle where the ghost is visible: its peak irradiance reaches
//! [`ClassifySettings::visible_irradiance`] (by default a quarter of an 8-bit step at the fixed gain
//! [`VISIBILITY_GAIN`] or at the lens's own auto exposure, whichever shows more: [`ClassifySettings::for_flare`])
//! (a sprite of the right shape with the wrong light is as wrong in
//! a frame: the 28-surface zoom's ghost (4, 5) on the axis carries 0.85 of its traced light); and it is
//! baked only when it is also bright enough to matter: a **faint** ghost, whose traced peak stays under
//! [`ClassifySettings::faint_fraction`] of the brightest ghost's, stays paraxial (its misplaced light is
//! below the other ghosts' by that ratio, and a 25-surface lens has dozens of them: baking them would cost
//! most of the bake time for almost none of the image). The user's forced choices override the measure (and
//! are reported as such). A ghost with no light at any angle is linear (nothing to bake).

use rayon::prelude::*;

use crate::color::luminance;
use crate::flare::PreparedFlare;
use crate::ghost::{CullReason, Sensor};
use crate::image::HdrImage;
use crate::raytrace::{Grid, RayGridRenderer, RayGridRequest, View, Window};
use crate::render::{FlareScene, cpu};

/// The default [`ClassifySettings::faint_fraction`]: 0, every non-linear ghost is baked. Measured on the
/// double Gauss at 20 degrees: at 2e-3 (11 of its 28 non-linear ghosts baked) the blended frame loses 5 dB
/// PSNR and 0.07 SSIM, because in the sRGB display a ghost at 1/500 of the brightest one is still plainly
/// visible; on the 28-surface Nikon zoom, 2e-3 bakes 34 of 91 ghosts in 40% of the time. A speed knob.
pub const DEFAULT_FAINT_FRACTION: f64 = 0.0;

/// How ghosts are measured.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassifySettings {
    /// Light angles from 0 to `theta_max_deg` (inclusive).
    pub angles: usize,
    pub theta_max_deg: f64,
    /// Image error (and energy ratio less 1) above which a visible ghost is non-linear.
    pub threshold: f64,
    /// Peak relative irradiance from which a ghost counts as visible.
    pub visible_irradiance: f64,
    /// A non-linear ghost whose traced peak is under this fraction of the brightest ghost's is faint: it
    /// stays paraxial.
    pub faint_fraction: f64,
    /// Texels across the comparison window.
    pub res: u32,
    /// Ray-grid cells across each ghost's entrance region.
    pub grid: usize,
}

/// The flare gain (about 6.6 stops) at which classification judges a ghost visible, or the lens's own auto
/// exposure where that is higher ([`ClassifySettings::for_flare`]). Neither is the user's exposure, so that a
/// LUT does not depend on a display setting.
pub const VISIBILITY_GAIN: f32 = 100.0;

impl ClassifySettings {
    /// Defaults for `flare`: 4 angles to `theta_max_deg`, threshold 0.15, visible from a quarter of an 8-bit
    /// step (the culling level of the paraxial renderer) at the flare gain [`VISIBILITY_GAIN`] or at the lens's
    /// own auto exposure on the full-frame sensor ([`crate::exposure::auto_flare_ev`]), whichever shows more:
    /// a lens whose ghosts are all dim is exposed up to them, and its ghosts are judged as a frame shows them.
    /// Both depend on the optics alone, so a LUT does not depend on a display setting. The Heliar (auto
    /// +9.5 EV, gain 724) had its three largest misdrawn ghosts judged invisible at gain 100 alone.
    pub fn for_flare(flare: &PreparedFlare, theta_max_deg: f64) -> Self {
        let auto_gain =
            2f64.powf(crate::exposure::auto_flare_ev(&flare.system, crate::optics::sensor::FULL_FRAME_WIDTH_MM));
        let gain = (auto_gain as f32).max(VISIBILITY_GAIN);
        Self {
            angles: 4,
            theta_max_deg,
            threshold: 0.15,
            visible_irradiance: flare.config.threshold(gain),
            faint_fraction: DEFAULT_FAINT_FRACTION,
            res: 64,
            grid: 32,
        }
    }
}

/// One ghost's measures.
#[derive(Clone, Debug, PartialEq)]
pub struct GhostClass {
    pub ghost: usize,
    pub surfaces: (usize, usize),
    /// Worst centroid offset, mm, and in paraxial half-sizes.
    pub centroid_mm: f64,
    pub centroid_rel: f64,
    /// Worst rms-radius ratio (>= 1).
    pub size_ratio: f64,
    /// Worst image error at a visible angle (0 to 1).
    pub image_error: f64,
    /// Worst energy ratio of traced to paraxial light at a visible angle (reported as the larger of r and 1 / r).
    pub energy_ratio: f64,
    /// Worst luminance the paraxial sprite puts in the wrong place, unnormalised: `0.5 sum |T - P|` over the
    /// window, in relative irradiance x mm^2 (what the ghost's error weighs in a frame).
    pub misplaced_energy: f64,
    /// Brightest traced irradiance over the angles.
    pub peak_irradiance: f64,
    /// The measure's verdict.
    pub measured_nonlinear: bool,
    /// Non-linear by the image error, but too faint to bake (see the module documentation).
    pub faint: bool,
    /// The user's choice, when forced.
    pub forced: Option<bool>,
}

impl GhostClass {
    /// The verdict in use: forced, else measured.
    pub fn nonlinear(&self) -> bool {
        self.forced.unwrap_or(self.measured_nonlinear)
    }
}

/// Energy, centroid and rms radius of a luminance image with `texel_mm` texels in `window` (mm).
fn shape(image: &HdrImage, window: &Window) -> (f64, [f64; 2], f64, f64) {
    let (mut e, mut sx, mut sy, mut sxx, mut peak) = (0.0, 0.0, 0.0, 0.0, 0.0f64);
    for (k, p) in image.pixels.iter().enumerate() {
        let l = luminance([p[0], p[1], p[2]].map(f64::from));
        if l <= 0.0 {
            continue;
        }
        let (x, y) = ((k % image.width as usize) as f64 + 0.5, (k / image.width as usize) as f64 + 0.5);
        let m = window.to_mm([x, y]);
        e += l;
        sx += l * m[0];
        sy += l * m[1];
        sxx += l * (m[0] * m[0] + m[1] * m[1]);
        peak = peak.max(l);
    }
    if e <= 0.0 {
        return (0.0, [0.0; 2], 0.0, 0.0);
    }
    let c = [sx / e, sy / e];
    let rms = (sxx / e - c[0] * c[0] - c[1] * c[1]).max(0.0).sqrt();
    (e, c, rms, peak)
}

/// The paraxial sprites of ghost `g` alone, through the CPU twin, into `window`.
pub(crate) fn paraxial_image(flare: &PreparedFlare, g: usize, light_deg: [f64; 2], window: &Window) -> HdrImage {
    let u = crate::ghost::light_slopes_for_frame_position(light_deg[0], light_deg[1]);
    let display = crate::render::DisplaySettings::default();
    let mut settings = flare.frame_settings(window.width, window.height, display.flare_gain());
    settings.sensor = Sensor {
        width_mm: window.width_mm,
        height_mm: window.width_mm * f64::from(window.height) / f64::from(window.width),
    };
    settings.min_half_size_mm = 0.75 * window.width_mm / f64::from(window.width);
    let mut frame = flare.system.frame(u, &settings);
    for sprite in &mut frame.sprites {
        sprite.culled = if sprite.ghost != g || sprite.irradiance <= 0.0 { Some(CullReason::OffSensor) } else { None };
    }
    let mut scene = FlareScene::build(&flare.system, &frame, u, &settings, &display, window.width, window.height, &[]);
    let k = window.px_per_mm();
    for inst in &mut scene.instances {
        inst.centre_half[0] += (window.centre_mm[0] * k) as f32;
        inst.centre_half[1] -= (window.centre_mm[1] * k) as f32;
    }
    flare.ghost_masks.assign_levels(&mut scene);
    cpu::ghost_pass(&scene, &flare.ghost_masks)
}

/// Measures every ghost of `flare`; `forced` lists (ghost, non-linear?) choices of the user.
pub fn classify(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    settings: &ClassifySettings,
    forced: &[(usize, bool)],
) -> Vec<GhostClass> {
    let never = std::sync::atomic::AtomicBool::new(false);
    classify_until(flare, renderer, settings, forced, &never).unwrap_or_default()
}

/// [`classify`], stopped when `cancel` is set: every ghost and light angle not yet measured is skipped (the
/// Panavision lens's 1540 ghosts take a minute on two cores), and the answer is `None`.
pub fn classify_until(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    settings: &ClassifySettings,
    forced: &[(usize, bool)],
    cancel: &std::sync::atomic::AtomicBool,
) -> Option<Vec<GhostClass>> {
    let cancelled = || cancel.load(std::sync::atomic::Ordering::Relaxed);
    let axis = crate::lut::Symmetry::of(&flare.system.lens, &flare.config.aperture)
        .unwrap_or_else(|_| crate::lut::Symmetry::of_aperture(&flare.config.aperture))
        .axis_deg;
    let angles: Vec<f64> = (0..settings.angles.max(1))
        .map(|k| settings.theta_max_deg * k as f64 / (settings.angles.max(2) - 1) as f64)
        .collect();
    let mut classes: Vec<GhostClass> = (0..flare.system.ghosts.len())
        .into_par_iter()
        .map(|g| {
            let ghost = &flare.system.ghosts[g];
            let mut class = GhostClass {
                ghost: g,
                surfaces: (ghost.i, ghost.j),
                centroid_mm: 0.0,
                centroid_rel: 0.0,
                size_ratio: 1.0,
                image_error: 0.0,
                energy_ratio: 1.0,
                misplaced_energy: 0.0,
                peak_irradiance: 0.0,
                measured_nonlinear: false,
                faint: false,
                forced: forced.iter().find(|(h, _)| *h == g).map(|(_, f)| *f),
            };
            for &theta in &angles {
                if cancelled() {
                    break;
                }
                let light = crate::lut::light_position_deg(theta, axis);
                let u = crate::ghost::light_slopes_for_frame_position(light[0], light[1]);
                let para = flare.system.paraxial_frame(g, u, crate::lut::MIN_TEXEL_MM);
                let Some(traced) = renderer.footprint_mm(g, light, 24) else { continue };
                let r = 1.5 * para.half_mm;
                let b = [
                    traced[0].min(para.centre_mm[0] - r),
                    traced[1].min(para.centre_mm[1] - r),
                    traced[2].max(para.centre_mm[0] + r),
                    traced[3].max(para.centre_mm[1] + r),
                ];
                let side = (b[2] - b[0]).max(b[3] - b[1]) * 1.05;
                let window = Window {
                    centre_mm: [0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])],
                    width_mm: side,
                    width: settings.res,
                    height: settings.res,
                };
                if !(side.is_finite() && side > 0.0) {
                    continue;
                }
                let view = View { window, turn_deg: 0.0 };
                let request = RayGridRequest::views(light, vec![view], Grid::Fixed(settings.grid)).only(g);
                let Ok(t) = renderer.render_request(&request).map(|mut images| images.remove(0)) else {
                    continue;
                };
                let p = paraxial_image(flare, g, light, &window);
                let (et, ct, rt, peak_t) = shape(&t.hdr, &window);
                let (ep, cp, rp, peak_p) = shape(&p, &window);
                class.peak_irradiance = class.peak_irradiance.max(peak_t);
                if et <= 0.0 {
                    continue;
                }
                // One pass over the two images: the distance of the normalised footprints and the unnormalised
                // one (luminance put in the wrong place).
                let (mut distance, mut misplaced) = (0.0, 0.0);
                for (a, b) in t.hdr.pixels.iter().zip(&p.pixels) {
                    let la = luminance([a[0], a[1], a[2]].map(f64::from));
                    let lb = luminance([b[0], b[1], b[2]].map(f64::from));
                    if ep > 0.0 {
                        distance += (la / et - lb / ep).abs();
                    }
                    misplaced += (la - lb).abs();
                }
                let error = if ep <= 0.0 { 1.0 } else { 0.5 * distance };
                let misplaced = 0.5 * misplaced * (window.width_mm / f64::from(window.width)).powi(2);
                let offset = (ct[0] - cp[0]).hypot(ct[1] - cp[1]);
                class.centroid_mm = class.centroid_mm.max(offset);
                class.centroid_rel = class.centroid_rel.max(offset / para.half_mm);
                if rt > 0.0 && rp > 0.0 {
                    class.size_ratio = class.size_ratio.max((rt / rp).max(rp / rt));
                }
                if peak_t.max(peak_p) >= settings.visible_irradiance {
                    class.image_error = class.image_error.max(error);
                    if ep > 0.0 {
                        class.energy_ratio = class.energy_ratio.max((et / ep).max(ep / et));
                    }
                    class.misplaced_energy = class.misplaced_energy.max(misplaced);
                }
            }
            // Its shape, or its light: a sprite of the right shape that carries the wrong light (a clear aperture
            // cutting the real ghost where the paraxial disc does not) is as wrong in a frame.
            class.measured_nonlinear =
                class.image_error > settings.threshold || class.energy_ratio > 1.0 + settings.threshold;
            class
        })
        .collect();
    if cancelled() {
        return None;
    }
    let brightest = classes.iter().map(|c| c.peak_irradiance).fold(0.0, f64::max);
    for class in &mut classes {
        if class.measured_nonlinear && class.peak_irradiance < settings.faint_fraction * brightest {
            class.measured_nonlinear = false;
            class.faint = true;
        }
    }
    Some(classes)
}
