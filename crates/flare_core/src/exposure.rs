//! Auto exposure: the flare's exposure (stops) that puts the brightest ghost at a chosen display level, so a
//! lens, coating or stop change does not need the exposure retuned by hand.
//!
//! # How it works
//! [`auto_flare_ev`] lays out the paraxial sprites of every ghost (no culling) for one canonical light: on the
//! frame's diagonal at half the lens's half-diagonal field of view (capped at 20 degrees), on the document's
//! sensor. Each ghost's peak is its sprites' RGB irradiance summed over the wavelengths (they overlap), the
//! largest channel; a ghost focused smaller than `MIN_GHOST_FRACTION` of the sensor's width counts as that
//! size (its energy spread, as a photograph's small hot spots clip without deciding the exposure). The exposure
//! is the one that puts the brightest such peak at [`AUTO_DISPLAY_LEVEL`] (linear, before the tonemap):
//! `ev = log2(level / peak)`, or less when the ghosts' light spread over the frame (each sprite's irradiance
//! times its square's share of the frame, summed) would lift the frame's mean above `MAX_FRAME_MEAN`: a
//! lens with hundreds of large faint ghosts is not exposed into a wash. The result is bounded to the
//! document's range of -40 to 40 stops. A lens with no ghost light
//! at all (every entrance region empty) gets `DEFAULT_FLARE_EV`.
//!
//! The exposure depends on the optics and the sensor width only, never on the light's position or a display
//! setting: it is the same for every frame of a shot and the same in the app and on the command line.

use crate::ghost::{FrameSettings, GhostSystem};
use crate::optics::sensor::Sensor;

/// The default flare exposure (stops): a quarter-wave coated lens's ghosts (about 1e-4 of the light) show.
pub(crate) const DEFAULT_FLARE_EV: f64 = 10.5;

/// The display level (linear, before the tonemap) the brightest ghost is exposed to.
pub const AUTO_DISPLAY_LEVEL: f64 = 0.6;
/// The most the ghosts may lift the frame's mean (linear display level): the background stays dark.
pub(crate) const MAX_FRAME_MEAN: f64 = 0.05;
/// Ghosts smaller than this fraction of the sensor width count as this size when judging the brightest.
pub(crate) const MIN_GHOST_FRACTION: f64 = 0.02;
/// The canonical light's field angle is at most this.
const MAX_CANONICAL_DEG: f64 = 20.0;

/// The canonical light's field angle (degrees on the diagonal) for `system` on a sensor `sensor_width_mm`
/// wide (3:2): half the lens's half-diagonal field, at most 20 degrees (`MAX_CANONICAL_DEG`).
pub(crate) fn canonical_light_deg(system: &GhostSystem, sensor_width_mm: f64) -> f64 {
    let half_diagonal_mm = 0.5 * sensor_width_mm * (1.0f64 + (2.0f64 / 3.0).powi(2)).sqrt();
    let efl = system.first_order.efl_mm.abs().max(1e-3);
    (0.5 * (half_diagonal_mm / efl).atan().to_degrees()).min(MAX_CANONICAL_DEG)
}

/// What auto exposure judges, for the canonical light (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct GhostLevels {
    /// The brightest ghost's peak relative irradiance (0 when no ghost receives light).
    pub brightest_peak: f64,
    /// The ghosts' light spread over the frame: the mean relative irradiance they add to it (the haze that
    /// hundreds of large faint ghosts make together).
    pub frame_mean: f64,
}

/// The brightest ghost's peak and the ghosts' mean over the frame for the canonical light (see the module
/// documentation).
pub(crate) fn ghost_levels(system: &GhostSystem, sensor_width_mm: f64) -> GhostLevels {
    let sensor = Sensor { width_mm: sensor_width_mm, height_mm: sensor_width_mm * 2.0 / 3.0 };
    let settings =
        FrameSettings { sensor, intensity_threshold: 0.0, min_half_size_mm: MIN_GHOST_FRACTION * sensor_width_mm };
    let angle = canonical_light_deg(system, sensor_width_mm).to_radians().tan() / std::f64::consts::SQRT_2;
    let frame = system.frame([-angle, -angle], &settings);
    let mut per_ghost = vec![[0.0f64; 3]; system.ghosts.len()];
    let frame_area = sensor.width_mm * sensor.height_mm;
    let mut frame_rgb = [0.0f64; 3];
    for s in &frame.sprites {
        // The sprite's share of the frame: its square (the aperture fills most of it), at most the frame.
        let share = (4.0 * (s.half_size_mm[0] * s.half_size_mm[1]).abs() / frame_area).min(1.0);
        for c in 0..3 {
            per_ghost[s.ghost][c] += s.rgb[c];
            frame_rgb[c] += s.rgb[c] * share;
        }
    }
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    GhostLevels {
        brightest_peak: per_ghost.iter().map(|rgb| finite(rgb[0].max(rgb[1]).max(rgb[2]))).fold(0.0, f64::max),
        frame_mean: finite(frame_rgb[0].max(frame_rgb[1]).max(frame_rgb[2])),
    }
}

/// The flare exposure in stops that puts the brightest ghost at [`AUTO_DISPLAY_LEVEL`], or lower when the
/// ghosts together would lift the whole frame above `MAX_FRAME_MEAN` (see the module documentation).
pub fn auto_flare_ev(system: &GhostSystem, sensor_width_mm: f64) -> f64 {
    let levels = ghost_levels(system, sensor_width_mm);
    if levels.brightest_peak <= 0.0 {
        return DEFAULT_FLARE_EV;
    }
    let gain = (AUTO_DISPLAY_LEVEL / levels.brightest_peak).min(if levels.frame_mean > 0.0 {
        MAX_FRAME_MEAN / levels.frame_mean
    } else {
        f64::INFINITY
    });
    // Rounded to a hundredth of a stop, so the number the panel shows is the number used.
    (gain.log2().clamp(-40.0, 40.0) * 100.0).round() / 100.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ghost::GhostSettings;
    use crate::optics::Coating;
    use crate::optics::library::builtin_lens;

    fn system(lens: &str, coating: Option<Coating>) -> GhostSystem {
        let settings = GhostSettings { coating_override: coating, ..GhostSettings::default() };
        GhostSystem::build(&builtin_lens(lens).unwrap(), &settings).unwrap()
    }

    #[test]
    fn bare_glass_is_exposed_about_a_hundred_times_less_than_a_quarter_wave_coat() {
        let bare = auto_flare_ev(&system("pbrt_dgauss_50mm", Some(Coating::Uncoated)), 36.0);
        let coated = auto_flare_ev(
            &system("pbrt_dgauss_50mm", Some(Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None })),
            36.0,
        );
        // A single MgF2 layer cuts each reflection from ~4-5% to ~1-2%: two reflections, 4 to 8 stops.
        assert!((4.0..=9.0).contains(&(coated - bare)), "bare {bare} coated {coated}");
        assert!(bare.is_finite() && (-40.0..=40.0).contains(&bare));
    }

    #[test]
    fn the_exposure_puts_the_brightest_ghost_at_the_display_level() {
        let s = system("nikon_zoom_28_75mm", None);
        let ev = auto_flare_ev(&s, 36.0);
        let levels = ghost_levels(&s, 36.0);
        let (peak, mean) = (levels.brightest_peak * 2f64.powf(ev), levels.frame_mean * 2f64.powf(ev));
        // One of the two limits decides, and neither is exceeded (to the rounding of a hundredth of a stop).
        assert!(peak <= AUTO_DISPLAY_LEVEL * 1.01 && mean <= MAX_FRAME_MEAN * 1.01, "{peak} {mean}");
        assert!(peak >= AUTO_DISPLAY_LEVEL * 0.99 || mean >= MAX_FRAME_MEAN * 0.99, "{peak} {mean}");
        // The canonical light is inside the field and independent of the frame.
        let deg = canonical_light_deg(&s, 36.0);
        assert!((5.0..=20.0).contains(&deg), "{deg}");
    }
}
