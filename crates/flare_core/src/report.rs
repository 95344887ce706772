//! The ghost report a lens designer asks for first: where each ghost focuses, how big and how bright it is
//! on the sensor, which ones are worst, and which surface's coating would help most.
//!
//! # How it works
//! Everything comes from the paraxial ghost system the frame is drawn from ([`GhostSystem`]), for one light
//! direction. Per ghost (surface pair i, j):
//! - `focus_mm`: `-A / C` of the d-line ghost path from the entrance plane to the image plane: where its rays
//!   from the light focus, measured from the image plane (+ towards the image side); `None` when afocal.
//! - `f_number`: the ghost's working f-number, `|1 / C| / D` with D the entrance pupil's diameter at the
//!   current stop (the cone of a ghost focused at `-1/C` behind its principal plane); `None` when afocal.
//! - `image_diameter_mm`: the stop's image through the ghost path on the sensor (Lee and Eisemann's sprite)
//!   at the spectrum's middle wavelength.
//! - `vignetted_by` and `vignetted_share`: the surfaces whose clear apertures cut the ghost's sprites at this
//!   light ([`crate::ghost::SpriteMasks::cutting_surfaces`]) and the share of the light its stop crossings pass
//!   that they take (the same grid sampled without the discs).
//! - Irradiance on the sensor: each wavelength's sprite is uniform inside the masks the frame applies (the
//!   aperture at every stop crossing, every clear aperture that cuts it); sampling those masks on a grid over the
//!   union of the ghost's sprites gives its luminance-weighted irradiance map, whose **peak** and **mean**
//!   (over the lit area) are reported relative to the peak irradiance of the source's own image, taken as
//!   the diffraction-limited Airy pattern at the d-line and the working f-number (`pi P / (4 lambda^2 F^2)`
//!   for the power P through the pupil). The map's integral is the ghost's **energy** as a fraction of the
//!   light entering the pupil, and its **share** of all the ghosts' energy.
//! - `straddles_stop` and `stop_crossings` say whether its reflections lie on both sides of the stop.
//! - An anamorphic lens focuses each ghost twice, once per section: `focus_mm`, `f_number` and
//!   `image_diameter_mm` are then its y-z section's (the image's height), and `focus_x_mm` and
//!   `image_width_mm` its x-z section's (for a lens of revolution they repeat `focus_mm` and
//!   `image_diameter_mm`).
//!
//! Ghosts are ranked worst first by peak irradiance (a small bright ghost shows more than a wide faint
//! one). The **coating sensitivity** answers "which surface to coat first": it rebuilds the system with every
//! surface bare but one, which wears the chosen AR coating (the current override, else the broadband
//! multilayer), and reports how much of the bare lens's total ghost energy that removes (negative where the
//! coating adds light: an air-glass AR stack on a cemented interface reflects more than the bare interface,
//! and a coated surface transmits more of every other ghost). All numbers are finite: a ghost whose sprite is
//! degenerate gets zeros, never NaN. [`ghost_report_until`] stops between ghosts and between coating trials when
//! asked (the app's Cancel).

use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::aperture::ApertureMask;
use crate::color::luminance;
use crate::ghost::{FrameSettings, GhostError, GhostSystem, MaskMap};
use crate::optics::glass::D_LINE_NM;
use crate::optics::path::LightPath;
use crate::optics::{Coating, Lens, PathMatrices};

/// Samples per side of the grid over a ghost's sprites for its peak, mean and energy.
pub(crate) const REPORT_GRID: usize = 48;
/// Samples per side for the coating sensitivity's energies (many systems are built).
pub(crate) const SENSITIVITY_GRID: usize = 20;

/// One ghost in the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GhostRow {
    pub i: usize,
    pub j: usize,
    /// Paraxial focus of the ghost's rays from the light, from the image plane (+ image side); `None`: afocal.
    /// An anamorphic lens's y-z section.
    pub focus_mm: Option<f64>,
    /// The same in the x-z section (equal to `focus_mm` for a lens of revolution).
    pub focus_x_mm: Option<f64>,
    /// The ghost image's width along x (equal to `image_diameter_mm` for a lens of revolution).
    pub image_width_mm: f64,
    /// Diameter of the ghost's image on the sensor (the stop's image through the ghost path).
    pub image_diameter_mm: f64,
    /// Working f-number of the ghost's cone; `None`: afocal.
    pub f_number: Option<f64>,
    /// Peak irradiance relative to the peak of the source's diffraction-limited image.
    pub peak_vs_source: f64,
    /// Mean irradiance over the ghost's lit area, relative to the same.
    pub mean_vs_source: f64,
    /// The ghost's energy on the sensor as a fraction of the light entering the pupil.
    pub energy_fraction: f64,
    /// Its share of all the ghosts' energy (the shares add up to 1).
    pub energy_share: f64,
    pub straddles_stop: bool,
    pub stop_crossings: usize,
    /// Centre of the ghost on the sensor (mm, sensor coordinates) at the middle wavelength.
    pub centre_mm: [f64; 2],
    /// The surfaces whose clear apertures cut the ghost at this light (any wavelength's sprite), in order.
    pub vignetted_by: Vec<usize>,
    /// The share of the ghost's light (what its stop crossings pass) that those apertures remove.
    pub vignetted_share: f64,
}

impl GhostRow {
    /// The clear apertures that cut the ghost and the share of its light they take, in a few words
    /// ("7, 8 (20 %)"), or "-" when none cuts it: the text table's and the app's words.
    pub fn vignetting_words(&self) -> String {
        if self.vignetted_by.is_empty() {
            return "-".to_owned();
        }
        let surfaces: Vec<String> = self.vignetted_by.iter().map(|k| k.to_string()).collect();
        format!("{} ({:.0} %)", surfaces.join(", "), 100.0 * self.vignetted_share)
    }
}

/// What coating one surface alone would do.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoatingSensitivity {
    pub surface: usize,
    /// Fraction of the bare lens's total ghost energy removed when this surface alone wears the coating.
    pub energy_drop: f64,
}

/// The whole report for one light direction.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GhostReport {
    /// The light's slopes (tan of its angles, the convention of [`GhostSystem::frame`]).
    pub light_slope: [f64; 2],
    /// Ghosts, worst (highest peak) first.
    pub ghosts: Vec<GhostRow>,
    /// Total ghost energy as a fraction of the light entering the pupil.
    pub total_energy_fraction: f64,
    /// The coating the sensitivity applies, in words.
    pub sensitivity_coating: String,
    /// Surfaces, most helpful first.
    pub sensitivity: Vec<CoatingSensitivity>,
}

/// The ghost report of `system` (built for `lens`) with the aperture `mask`, for light arriving with slopes `u`
/// (see [`crate::optics::sensor::light_slopes_for_frame_position`] for a frame position in degrees).
pub fn ghost_report(
    lens: &Lens,
    system: &GhostSystem,
    mask: &ApertureMask,
    u: [f64; 2],
) -> Result<GhostReport, GhostError> {
    let never = AtomicBool::new(false);
    Ok(ghost_report_until(lens, system, mask, u, &never)?.expect("never cancelled"))
}

/// [`ghost_report`] that stops when `cancel` is set (checked between ghosts and between the coating trials, so
/// within a few milliseconds): `Ok(None)` then.
pub fn ghost_report_until(
    lens: &Lens,
    system: &GhostSystem,
    mask: &ApertureMask,
    u: [f64; 2],
    cancel: &AtomicBool,
) -> Result<Option<GhostReport>, GhostError> {
    let cancelled = || cancel.load(Ordering::Relaxed);
    let measured = measure(system, mask, u, REPORT_GRID, cancel);
    if cancelled() {
        return Ok(None);
    }
    let total: f64 = measured.iter().map(|m| m.energy_fraction).sum();
    let sensor_z = system.first_order.sensor_z_mm();
    let epd = system.first_order.entrance_pupil_diameter_mm * system.settings.stop_scale;
    let middle = system.settings.spectrum.len() / 2;
    // The y-z section (the lens itself when it is of revolution) and the x-z section's lens of revolution.
    let (section_y, section_x) = (lens.section(crate::optics::Section::Y), lens.section(crate::optics::Section::X));
    let mut ghosts: Vec<GhostRow> = system
        .ghosts
        .iter()
        .enumerate()
        .map(|(g, ghost)| {
            let flare_matrix = |lens: &Lens| {
                LightPath::ghost(lens, ghost.i, ghost.j)
                    .ok()
                    .map(|p| PathMatrices::compute(lens, &p, D_LINE_NM, sensor_z).sensor_from_entrance)
            };
            let focus = |m: Option<crate::optics::Mat2>| {
                m.and_then(|m| (m.c != 0.0).then(|| -m.a / m.c)).filter(|v| v.is_finite())
            };
            let (d_line, d_line_x) = (flare_matrix(&section_y), flare_matrix(&section_x));
            let c = d_line.map_or(0.0, |m| m.c);
            let ellipse = system.stop_image_ellipse(g, middle, u);
            let sprite = ellipse.map(|(centre, semi)| (centre, semi[1]));
            let m = &measured[g];
            GhostRow {
                i: ghost.i,
                j: ghost.j,
                focus_mm: focus(d_line),
                focus_x_mm: focus(d_line_x),
                image_diameter_mm: sprite.map_or(0.0, |s| 2.0 * s.1).min(f64::MAX),
                image_width_mm: ellipse.map_or(0.0, |s| 2.0 * s.1[0]).min(f64::MAX),
                f_number: (c != 0.0 && epd > 0.0).then(|| (1.0 / c).abs() / epd).filter(|v| v.is_finite()),
                peak_vs_source: m.peak_vs_source,
                mean_vs_source: m.mean_vs_source,
                energy_fraction: m.energy_fraction,
                energy_share: if total > 0.0 { m.energy_fraction / total } else { 0.0 },
                straddles_stop: ghost.straddles_stop,
                stop_crossings: ghost.per_wavelength.first().map_or(1, |w| w.matrices.stop_from_entrance.len()),
                centre_mm: sprite.map_or([0.0; 2], |s| s.0),
                vignetted_by: m.vignetted_by.clone(),
                vignetted_share: m.vignetted_share,
            }
        })
        .collect();
    ghosts.sort_by(|a, b| b.peak_vs_source.total_cmp(&a.peak_vs_source).then(a.i.cmp(&b.i)).then(a.j.cmp(&b.j)));
    let coating = system.settings.coating_override.clone().unwrap_or_else(Coating::broadband);
    let Some(sensitivity) = coating_sensitivity(lens, system, mask, u, &coating, cancel)? else { return Ok(None) };
    Ok(Some(GhostReport {
        light_slope: u,
        ghosts,
        total_energy_fraction: total,
        sensitivity_coating: describe(&coating),
        sensitivity,
    }))
}

/// The CSV columns of [`to_csv`], in order.
pub const CSV_HEADER: &str = "rank,i,j,focus_mm,image_diameter_mm,f_number,peak_vs_source,mean_vs_source,\
energy_fraction,energy_share,straddles_stop,stop_crossings,centre_x_mm,centre_y_mm,focus_x_mm,image_width_mm,\
vignetted_by,vignetted_share";

/// The ghost table as CSV (one header line, one row per ghost, worst first; empty cells for afocal ghosts'
/// focus and f-number; the vignetting surfaces separated by spaces): what `flarelab ghosts --report --csv` prints and the app exports.
pub fn to_csv(report: &GhostReport) -> String {
    let opt = |v: Option<f64>| v.map(|v| format!("{v}")).unwrap_or_default();
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for (rank, g) in report.ghosts.iter().enumerate() {
        out.push_str(&format!(
            "{},{},{},{},{},{},{:e},{:e},{:e},{},{},{},{},{},{},{},{},{}\n",
            rank + 1,
            g.i,
            g.j,
            opt(g.focus_mm),
            g.image_diameter_mm,
            opt(g.f_number),
            g.peak_vs_source,
            g.mean_vs_source,
            g.energy_fraction,
            g.energy_share,
            g.straddles_stop,
            g.stop_crossings,
            g.centre_mm[0],
            g.centre_mm[1],
            opt(g.focus_x_mm),
            g.image_width_mm,
            g.vignetted_by.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(" "),
            g.vignetted_share
        ));
    }
    out
}

/// A coating in a few words.
pub fn describe(coating: &Coating) -> String {
    match coating {
        Coating::Uncoated => "uncoated".to_owned(),
        Coating::QuarterWave { design_wavelength_nm, .. } => format!("quarter-wave at {design_wavelength_nm} nm"),
        c if *c == Coating::broadband() => "broadband multilayer (3 layers)".to_owned(),
        Coating::Multilayer { layers } => format!("multilayer ({} layers)", layers.len()),
    }
}

/// Per ghost: what the grid over its sprites measured.
#[derive(Clone, Debug, Default, PartialEq)]
struct Measured {
    peak_vs_source: f64,
    mean_vs_source: f64,
    energy_fraction: f64,
    vignetted_by: Vec<usize>,
    vignetted_share: f64,
}

/// Samples every ghost's sprites and masks on an `n` x `n` grid over the union of its sprites.
/// Stops early (the rest left at zero) when `cancel` is set.
fn measure(system: &GhostSystem, mask: &ApertureMask, u: [f64; 2], n: usize, cancel: &AtomicBool) -> Vec<Measured> {
    let settings = FrameSettings { intensity_threshold: 0.0, min_half_size_mm: 0.0, ..FrameSettings::default() };
    let frame = system.frame(u, &settings);
    let spectrum = &system.settings.spectrum;
    let lum: Vec<f64> = spectrum.weights_rgb.iter().map(|&w| luminance(w).max(0.0)).collect();
    let lum_total: f64 = lum.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    // The light entering the pupil (relative irradiance 1 across the stopped-down pupil, tilted by theta) and
    // the peak of its Airy image at the d-line.
    let fo = &system.first_order;
    let radius = fo.entrance_pupil_radius_mm() * system.settings.stop_scale;
    let cos_theta = 1.0 / (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
    let power_in = std::f64::consts::PI * radius * radius * cos_theta;
    let f_number = fo.efl_mm.abs() / (2.0 * radius);
    let lambda_mm = D_LINE_NM * 1e-6;
    let source_peak = power_in * std::f64::consts::PI / (4.0 * lambda_mm * lambda_mm * f_number * f_number);
    let mut per_ghost: Vec<Vec<usize>> = vec![Vec::new(); system.ghosts.len()];
    for (k, s) in frame.sprites.iter().enumerate() {
        if s.half_size_mm.iter().all(|h| h.is_finite() && *h != 0.0) && s.irradiance.is_finite() && s.irradiance > 0.0 {
            per_ghost[s.ghost].push(k);
        }
    }
    per_ghost
        .iter()
        .map(|sprites| {
            if sprites.is_empty() || !(source_peak > 0.0 && power_in > 0.0) || cancel.load(Ordering::Relaxed) {
                return Measured::default();
            }
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &k in sprites {
                let s = &frame.sprites[k];
                for a in 0..2 {
                    let h = s.half_size_mm[a].abs();
                    lo[a] = lo[a].min(s.centre_mm[a] - h);
                    hi[a] = hi[a].max(s.centre_mm[a] + h);
                }
            }
            let cell = [(hi[0] - lo[0]) / n as f64, (hi[1] - lo[1]) / n as f64];
            let masks: Vec<_> = sprites.iter().map(|&k| system.sprite_masks(k, u)).collect();
            let vignetted_by = crate::ghost::surfaces_cutting(masks.iter().copied());
            // The luminance at p relative to the source's, through every mask or (`cut` false) the stop crossings
            // alone, no clear aperture cutting.
            let light_at = |p: [f64; 2], cut: bool| {
                let mut value = 0.0;
                for (&k, m) in sprites.iter().zip(&masks) {
                    let s = &frame.sprites[k];
                    let q = [(p[0] - s.centre_mm[0]) / s.half_size_mm[0], (p[1] - s.centre_mm[1]) / s.half_size_mm[1]];
                    if q[0].abs() > 1.0 || q[1].abs() > 1.0 {
                        continue;
                    }
                    let open = mask_product(mask, if cut { m.discs() } else { &[] }, m.stops(), q);
                    value += lum[s.wavelength] * s.irradiance * open;
                }
                value / lum_total
            };
            let value_at = |p: [f64; 2]| light_at(p, true);
            let (mut peak, mut sum, mut lit, mut uncut) = (0.0f64, 0.0f64, 0usize, 0.0f64);
            for yi in 0..n {
                for xi in 0..n {
                    let p = [lo[0] + (xi as f64 + 0.5) * cell[0], lo[1] + (yi as f64 + 0.5) * cell[1]];
                    if !vignetted_by.is_empty() {
                        uncut += light_at(p, false);
                    }
                    let value = value_at(p);
                    if value > 0.0 {
                        peak = peak.max(value);
                        sum += value;
                        lit += 1;
                    }
                }
            }
            // A sprite far smaller than a cell (a ghost focused near the sensor) may fall between samples: its
            // centre is where the peak is, so look there too.
            for &k in sprites {
                peak = peak.max(value_at(frame.sprites[k].centre_mm));
            }
            let area = cell[0] * cell[1];
            let energy = sum * area;
            let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
            Measured {
                peak_vs_source: finite(peak / source_peak),
                mean_vs_source: if lit > 0 { finite(sum / lit as f64 / source_peak) } else { 0.0 },
                energy_fraction: finite(energy / power_in),
                vignetted_share: if uncut > 0.0 { finite(1.0 - sum / uncut).clamp(0.0, 1.0) } else { 0.0 },
                vignetted_by,
            }
        })
        .collect()
}

/// The frame's mask product at sprite point `q`: the clear-aperture discs that cut the sprite, then the aperture at each stop
/// crossing (the CPU twin's `shade_instance`, in f64 with hard disc edges).
fn mask_product(mask: &ApertureMask, discs: &[MaskMap], stops: &[MaskMap], q: [f64; 2]) -> f64 {
    let at = |m: &MaskMap| m.at(q);
    if discs.iter().any(|d| {
        let f = at(d);
        f[0].hypot(f[1]) > 1.0
    }) {
        return 0.0;
    }
    stops.iter().fold(1.0, |acc, m| {
        if acc <= 0.0 {
            return 0.0;
        }
        let s = at(m);
        acc * f64::from(mask.sample(s[0] as f32, s[1] as f32))
    })
}

/// For each reflecting surface, the share of the bare lens's total ghost energy removed when it alone wears
/// `coating` (every other surface bare); most helpful first.
fn coating_sensitivity(
    lens: &Lens,
    system: &GhostSystem,
    mask: &ApertureMask,
    u: [f64; 2],
    coating: &Coating,
    cancel: &AtomicBool,
) -> Result<Option<Vec<CoatingSensitivity>>, GhostError> {
    let settings = crate::ghost::GhostSettings { coating_override: None, ..system.settings.clone() };
    let total = |lens: &Lens| -> Result<f64, GhostError> {
        let s = GhostSystem::build(lens, &settings)?;
        Ok(measure(&s, mask, u, SENSITIVITY_GRID, cancel).iter().map(|m| m.energy_fraction).sum())
    };
    let mut bare = lens.clone();
    for s in &mut bare.surfaces {
        s.coating = Coating::Uncoated;
    }
    let base = total(&bare)?;
    let mut out = Vec::new();
    for k in lens.reflecting_surfaces() {
        if cancel.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let energy_drop = if base <= 0.0 || *coating == Coating::Uncoated {
            0.0
        } else {
            let mut coated = bare.clone();
            coated.surfaces[k].coating = coating.clone();
            ((base - total(&coated)?) / base).clamp(-1.0, 1.0)
        };
        out.push(CoatingSensitivity { surface: k, energy_drop });
    }
    out.sort_by(|a, b| b.energy_drop.total_cmp(&a.energy_drop).then(a.surface.cmp(&b.surface)));
    Ok((!cancel.load(Ordering::Relaxed)).then_some(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flare::{FlareConfig, PreparedFlare};
    use crate::optics::library::builtin_lens;
    use crate::optics::sensor::light_slopes_for_frame_position;

    fn report(id: &str, config: &FlareConfig, light_deg: [f64; 2]) -> GhostReport {
        let lens = builtin_lens(id).unwrap();
        let flare = PreparedFlare::new(&lens, config).unwrap();
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        ghost_report(&lens, &flare.system, flare.mask(), u).unwrap()
    }

    #[test]
    fn shares_add_up_and_the_worst_comes_first() {
        let r = report("tessar", &FlareConfig::default(), [5.0, 3.0]);
        assert_eq!(r.ghosts.len(), 21);
        let shares: f64 = r.ghosts.iter().map(|g| g.energy_share).sum();
        assert!((shares - 1.0).abs() < 1e-9, "{shares}");
        assert!(r.ghosts.windows(2).all(|w| w[0].peak_vs_source >= w[1].peak_vs_source));
        for g in &r.ghosts {
            assert!(g.peak_vs_source >= g.mean_vs_source * (1.0 - 1e-12) && g.mean_vs_source >= 0.0, "{g:?}");
            assert!(g.energy_fraction.is_finite() && g.image_diameter_mm >= 0.0);
        }
        // Uncoated glass reflects about 4 % at each surface: two reflections keep well under 1 % of the light.
        assert!(r.total_energy_fraction > 1e-4 && r.total_energy_fraction < 0.05, "{}", r.total_energy_fraction);
        // The CSV has the header and a row per ghost, worst first, with as many cells as the header.
        let csv = to_csv(&r);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(lines.len(), 22);
        let cells = CSV_HEADER.split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == cells), "{csv}");
        assert!(lines[1].starts_with(&format!("1,{},{},", r.ghosts[0].i, r.ghosts[0].j)));
    }

    /// Off axis the double Gauss's middle apertures cut some ghosts: the report names the surfaces and how much of
    /// the light they take; a ghost nothing cuts says so with a share of 0. Near the axis at f/16 nothing is cut.
    #[test]
    fn the_report_names_the_apertures_that_cut_each_ghost() {
        let r = report("dgauss", &FlareConfig::default(), [14.0, 6.0]);
        let stop = builtin_lens("dgauss").unwrap().stop_index();
        let cut: Vec<&GhostRow> = r.ghosts.iter().filter(|g| g.vignetted_by.iter().any(|&k| k != 0)).collect();
        assert!(cut.len() >= 3, "{} ghosts cut by a middle aperture", cut.len());
        assert!(cut.iter().any(|g| g.vignetted_share > 0.05), "{cut:?}");
        for g in &r.ghosts {
            assert!((0.0..=1.0).contains(&g.vignetted_share), "{g:?}");
            assert!(!g.vignetted_by.contains(&stop), "the stop is a mask of its own: {g:?}");
            assert!(g.vignetted_by.windows(2).all(|w| w[0] < w[1]), "{g:?}");
            if g.vignetted_by.is_empty() {
                assert_eq!(g.vignetted_share, 0.0, "{g:?}");
            }
        }
        let stopped = FlareConfig {
            aperture: crate::aperture::Aperture { f_number: Some(16.0), ..Default::default() },
            ..FlareConfig::default()
        };
        let r = report("dgauss", &stopped, [0.5, 0.2]);
        assert!(r.ghosts.iter().all(|g| g.vignetted_share < 0.01), "{:?}", r.ghosts);
    }

    #[test]
    fn energy_is_conserved_between_grids_and_matches_a_single_uniform_sprite() {
        // A ghost's energy is its irradiance times its lit area: the grid's integral does not depend on the grid.
        let lens = builtin_lens("heliar").unwrap();
        let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
        let u = light_slopes_for_frame_position(2.0, 1.0);
        let never = AtomicBool::new(false);
        let coarse = measure(&flare.system, flare.mask(), u, 24, &never);
        let fine = measure(&flare.system, flare.mask(), u, 96, &never);
        for (g, (a, b)) in coarse.iter().zip(&fine).enumerate() {
            if b.energy_fraction > 1e-6 {
                assert!((a.energy_fraction / b.energy_fraction - 1.0).abs() < 0.08, "ghost {g}: {a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn coating_sensitivity_ranks_surfaces_and_the_override_is_the_coating_tried() {
        let config = FlareConfig { coating_override: Some(Coating::broadband()), ..FlareConfig::default() };
        let r = report("dgauss", &config, [4.0, 2.0]);
        assert_eq!(r.sensitivity_coating, "broadband multilayer (3 layers)");
        assert_eq!(r.sensitivity.len(), builtin_lens("dgauss").unwrap().reflecting_surfaces().len());
        assert!(r.sensitivity.iter().all(|s| s.energy_drop > -1.0 && s.energy_drop < 1.0));
        // An air-glass AR stack on a cemented interface (surface 3 joins two glasses of nearly equal index)
        // reflects more than the bare interface did: coating it adds ghost light, and the report says so.
        let cemented = r.sensitivity.iter().find(|s| s.surface == 3).unwrap();
        assert!(
            r.sensitivity.iter().filter(|s| ![1, 3, 7].contains(&s.surface)).all(|s| s.energy_drop > 0.0),
            "{:?}",
            r.sensitivity
        );
        assert!(cemented.energy_drop < 0.0, "{cemented:?}");
        assert!(r.sensitivity[0].energy_drop > 0.05, "the best surface removes a real share: {:?}", r.sensitivity[0]);
        assert!(r.sensitivity.windows(2).all(|w| w[0].energy_drop >= w[1].energy_drop));
    }
}
