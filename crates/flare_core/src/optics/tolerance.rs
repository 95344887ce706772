//! Tolerant loading: a prescription whose guessed clear apertures make neighbouring surfaces cross is
//! loaded with the apertures clipped to where the surfaces meet, when that costs no light the lens is
//! designed to pass, and refused otherwise.
//!
//! # How it works
//! Patents give no clear apertures, so transcriptions guess them, and a guess is often too wide: two
//! surfaces of an air gap "cross" at the given semi-apertures. Glass cannot extend beyond the height where
//! the two surfaces meet, so the physical lens was clipped there; `repair` does the same, and refuses only
//! when the clip would cut into the axial beam, i.e. when on-axis light through the full stop reaches the
//! meeting height at either surface (then the stop would no longer be the aperture stop and the f-number
//! would be wrong). The axial beam is found by exact rays: an on-axis fan across the paraxial entrance pupil
//! (out to 1.5 times its radius), the rays kept that pass the stop and every clear aperture except those of
//! crossing surfaces. Each clip is a warning that also says from which field angle the clip vignettes
//! light the file's own apertures passed (the same exact rays over a pupil grid, the field in 0.5 degree
//! steps), so a user knows what the guess cost. Everything else is validated as strictly as
//! [`Lens::validate`] does; the repaired lens passes it.

use super::glass::D_LINE_NM;
use super::lens::{EdgeCrossing, Lens, LensError, round};
use super::paraxial::{EntrancePupil, FirstOrder};
use super::path::LightPath;
use super::trace::{Tracer, pupil_ray};

/// Rays in the on-axis fan that measures the axial beam's height.
const AXIAL_FAN_RAYS: usize = 401;
/// Pupil grid (per side) of the field scan that says where a clip starts to vignette.
const FIELD_GRID: usize = 16;

/// Loads `lens` tolerantly: validates it, clips crossing neighbours where that is harmless, and returns the
/// warnings (one sentence each). The lens is left untouched when it is refused.
pub(crate) fn repair(lens: &mut Lens) -> Result<Vec<String>, LensError> {
    lens.validate_except_edges()?;
    let crossings = lens.edge_crossings();
    if crossings.is_empty() {
        return Ok(Vec::new());
    }
    let stop = lens.stop_index();
    if let Some(c) = crossings.iter().find(|c| c.surface == stop || c.surface + 1 == stop) {
        return Err(LensError::field(
            c.surface,
            "thickness",
            format!("{}; one of them is the aperture stop, so the lens cannot be as given", c.describe()),
        ));
    }
    let first_order = FirstOrder::d_line(lens).map_err(|e| LensError::LensField {
        field: "surfaces",
        reason: format!("the lens forms no image ({e}), so its clear apertures cannot be checked"),
    })?;
    let rays = LightProbe::new(lens, &first_order, &crossings);
    let mut repaired = lens.clone();
    let mut warnings = Vec::with_capacity(crossings.len());
    for c in &crossings {
        let axial = rays.axial_height_mm(c.surface);
        if axial >= c.meet_height_mm {
            return Err(LensError::field(
                c.surface,
                "thickness",
                format!(
                    "{}, where on-axis light through the stop passes (up to {} mm): the lens cannot be as given",
                    c.describe(),
                    round(axial)
                ),
            ));
        }
        // Just inside the meeting height, so the clipped edges touch but never cross.
        let clip = c.meet_height_mm - 1e-6;
        for k in [c.surface, c.surface + 1] {
            let s = &mut repaired.surfaces[k].semi_aperture_mm;
            *s = s.min(clip);
        }
        let cost = match rays.first_clipped_field_deg(c.surface, c.meet_height_mm) {
            Some(deg) => format!("from {} deg off axis this cuts light the given apertures passed", round(deg)),
            None => "no light that passes the stop reaches that height".to_owned(),
        };
        warnings.push(format!("{}: both clipped to {} mm ({cost})", c.describe(), round(c.meet_height_mm)));
    }
    repaired.validate()?;
    *lens = repaired;
    Ok(warnings)
}

/// Exact rays of the image path that pass the stop and every clear aperture but those of crossing
/// surfaces, as given in the file.
struct LightProbe {
    tracer: Tracer,
    pupil: EntrancePupil,
    stop: usize,
    stop_radius_mm: f64,
    /// Surfaces whose aperture is not applied (the crossing ones), by surface index.
    free: Vec<bool>,
    semi_apertures_mm: Vec<f64>,
}

impl LightProbe {
    fn new(lens: &Lens, first_order: &FirstOrder, crossings: &[EdgeCrossing]) -> Self {
        let mut free = vec![false; lens.surfaces.len()];
        for c in crossings {
            free[c.surface] = true;
            free[c.surface + 1] = true;
        }
        let stop = lens.stop_index();
        Self {
            tracer: Tracer::new(lens, &LightPath::image(lens), D_LINE_NM, first_order.sensor_z_mm()),
            pupil: EntrancePupil {
                z_mm: first_order.entrance_pupil_z_mm,
                radius_mm: first_order.entrance_pupil_radius_mm(),
            },
            stop,
            stop_radius_mm: lens.surfaces[stop].semi_aperture_mm,
            free,
            semi_apertures_mm: lens.surfaces.iter().map(|s| s.semi_aperture_mm).collect(),
        }
    }

    /// The largest height at surfaces `k` and `k + 1` of a passing ray at field `theta` through pupil
    /// point (`px`, `py`), or `None` when the ray does not pass.
    fn height_at_pair(&self, k: usize, theta: f64, px: f64, py: f64) -> Option<f64> {
        let ray = pupil_ray(&self.pupil, theta, px, py);
        let mut height = 0.0f64;
        let landed = self.tracer.trace_visit(&ray, |hit| {
            let h = hit.point_mm.x.hypot(hit.point_mm.y);
            if hit.surface == k || hit.surface == k + 1 {
                height = height.max(h);
            }
            if hit.surface == self.stop {
                h <= self.stop_radius_mm
            } else {
                self.free[hit.surface] || h <= self.semi_apertures_mm[hit.surface]
            }
        });
        landed.is_ok().then_some(height)
    }

    /// Height at surfaces `k`, `k + 1` of the axial beam through the full stop.
    fn axial_height_mm(&self, k: usize) -> f64 {
        (0..AXIAL_FAN_RAYS)
            .filter_map(|i| self.height_at_pair(k, 0.0, 0.0, 1.5 * i as f64 / (AXIAL_FAN_RAYS - 1) as f64))
            .fold(0.0, f64::max)
    }

    /// The smallest field angle (0.5 degree steps, up to 89.5) at which passing light reaches `height_mm`
    /// at surface `k` or `k + 1`; `None` when no field does.
    fn first_clipped_field_deg(&self, k: usize, height_mm: f64) -> Option<f64> {
        let n = FIELD_GRID as f64;
        let mut dark_steps = 0;
        for deg in (0..180).map(|i| 0.5 * i as f64) {
            let theta = deg.to_radians();
            let mut passed = false;
            for ix in 0..=FIELD_GRID {
                for iy in 0..=2 * FIELD_GRID {
                    let (px, py) = (3.0 * ix as f64 / n, 3.0 * (iy as f64 - n) / n);
                    if let Some(h) = self.height_at_pair(k, theta, px, py) {
                        if h > height_mm {
                            return Some(deg);
                        }
                        passed = true;
                    }
                }
            }
            // Past the field the lens passes light at all, larger fields pass none either.
            dark_steps = if passed { 0 } else { dark_steps + 1 };
            if dark_steps >= 20 && deg > 10.0 {
                return None;
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::library::builtin_lens;

    #[test]
    fn a_lens_that_does_not_cross_loads_without_warnings() {
        let mut lens = builtin_lens("dgauss").unwrap();
        let before = lens.clone();
        assert_eq!(repair(&mut lens).unwrap(), Vec::<String>::new());
        assert_eq!(lens, before);
    }
}
