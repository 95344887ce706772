//! The lens's own mapping from a light's direction to where its image lands on the sensor, by exact ray
//! tracing: what turns a tracked pixel into a light angle, and places the light's image (its starburst) in a
//! frame. A fisheye's mapping is far from a pinhole's `f tan(theta)`; this one is the lens's.
//!
//! # How it works
//! The light's image is where its chief ray lands: the real ray from the field angle theta that crosses the
//! stop at its centre. [`ImageMapping::new`] aims that ray for a table of angles (0 to 89 degrees, every
//! degree): starting from the entrance height the last two angles' heights extrapolate to (the paraxial
//! entrance pupil's centre at first), it moves the ray's entrance height by secant steps until the ray crosses
//! the stop within 1e-9 of its semi-aperture of the axis (at most 40 steps; two or three usually), then traces
//! it to the sensor (the paraxial focal plane) at one wavelength. The table ends at the first angle whose chief ray cannot be traced (it misses a
//! surface, is totally internally reflected, or the aiming does not converge) or whose landing height no
//! longer grows with the angle (the mapping must be one-to-one to be inverted). The lens is rotationally
//! symmetric, so a light of slope vector `u` (tan of the angle, along its azimuth) lands at
//! `h(atan |u|) u / |u|`, with `h` interpolated linearly in the table. [`ImageMapping::height_mm`] beyond the
//! table's last angle continues it as `h_last tan(theta) / tan(theta_last)` (the paraxial shape, scaled to
//! meet the table), so a light far outside the field still has an image to place; the inverse
//! ([`ImageMapping::slope_for_height`]) refuses a height past the table's last one: no traced ray lands there.
//! A lens whose chief ray cannot be traced even on the axis has the paraxial mapping alone, `k u`.

use super::lens::Lens;
use super::paraxial::EntrancePupil;
use super::path::LightPath;
use super::sensor::{Sensor, light_slopes_for_frame_position, pixel_to_sensor, sensor_to_pixel};
use super::trace::{Ray, Tracer, pupil_ray};

/// Angles of the table (degrees). Heights are interpolated linearly in tan(theta), in which a rectilinear
/// lens's mapping is a straight line up to its distortion, so a degree apart is enough: the fisheye's
/// interpolation error is under 2 um at 60 degrees.
const STEP_DEG: f64 = 1.0;
const MAX_DEG: f64 = 89.0;

/// The light-direction to sensor-point mapping of one lens at one wavelength (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageMapping {
    /// The paraxial image height per unit slope (mm; its sign is the image's orientation).
    pub paraxial_mm_per_slope: f64,
    /// (tan theta, landing height in mm), from theta = 0 up; the heights have the sign of
    /// `paraxial_mm_per_slope` and grow in size.
    table: Vec<(f64, f64)>,
    /// The paraxial chief ray's height on the entrance plane (the first vertex) per unit slope: `-z_EP`.
    pub paraxial_entrance_per_slope: f64,
    /// Per entry of `table`, the traced chief ray's height on the entrance plane (mm, signed along the slope):
    /// where the beam that images at that height crosses the front element.
    entrance: Vec<f64>,
}

impl ImageMapping {
    /// Traces the chief rays of `lens` at `wavelength_nm` onto the plane `sensor_z_mm`; `pupil` is the
    /// paraxial entrance pupil (where aiming starts) and `paraxial_mm_per_slope` the paraxial image height per
    /// unit slope.
    pub fn new(
        lens: &Lens,
        pupil: EntrancePupil,
        sensor_z_mm: f64,
        wavelength_nm: f64,
        paraxial_mm_per_slope: f64,
    ) -> Self {
        let tracer = Tracer::new(lens, &LightPath::image(lens), wavelength_nm, sensor_z_mm);
        let stop = lens.stop_index();
        let stop_radius_mm = lens.surfaces.get(stop).map_or(1.0, |s| s.semi_aperture_mm.max(1e-6));
        let sign = if paraxial_mm_per_slope < 0.0 { -1.0 } else { 1.0 };
        let mut table = Vec::new();
        let mut entrance = Vec::new();
        let (mut py, mut py_before) = (0.0, 0.0);
        let steps = (MAX_DEG / STEP_DEG).round() as usize;
        for n in 0..=steps {
            let theta = (n as f64 * STEP_DEG).to_radians();
            let guess = if n >= 2 { 2.0 * py - py_before } else { py };
            let Some((height_mm, aimed)) = chief_ray_height(&tracer, stop, stop_radius_mm, pupil, theta, guess) else {
                break;
            };
            let h = height_mm;
            if n > 0 && table.last().is_some_and(|&(_, last): &(f64, f64)| h * sign <= last * sign) {
                break;
            }
            if n == 0 && h.abs() > 1e-6 * paraxial_mm_per_slope.abs().max(1.0) {
                // An axial chief ray that misses the axis: not a centred lens; use the paraxial mapping.
                break;
            }
            table.push((theta.tan(), if n == 0 { 0.0 } else { h }));
            // The pupil ray starts at (0, py r, z_EP) with slope tan(theta): at z = 0 it is at py r - z_EP tan.
            entrance.push(if n == 0 { 0.0 } else { aimed * pupil.radius_mm - pupil.z_mm * theta.tan() });
            (py_before, py) = (py, aimed);
        }
        if table.len() < 2 {
            table.clear();
            entrance.clear();
        }
        Self { paraxial_mm_per_slope, table, paraxial_entrance_per_slope: -pupil.z_mm, entrance }
    }

    /// The pure paraxial mapping `k u` (what a lens without a traced table uses), its chief rays crossing the
    /// entrance plane at `entrance_per_slope u`.
    pub fn paraxial(paraxial_mm_per_slope: f64, entrance_per_slope: f64) -> Self {
        Self {
            paraxial_mm_per_slope,
            table: Vec::new(),
            paraxial_entrance_per_slope: entrance_per_slope,
            entrance: Vec::new(),
        }
    }

    /// Where the chief ray of a light of slopes `u` crosses the entrance plane (the first vertex), mm: the
    /// traced table's, interpolated in tan(theta) as the heights are; beyond it the paraxial rate continues
    /// from its last entry; without a table the paraxial `-z_EP u`.
    pub fn entrance_mm(&self, u: [f64; 2]) -> [f64; 2] {
        let t = u[0].hypot(u[1]);
        if t == 0.0 || !t.is_finite() {
            return [0.0, 0.0];
        }
        let rate = self.paraxial_entrance_per_slope;
        let e = match (self.table.last(), self.entrance.last()) {
            (Some(&(t_last, _)), Some(&e_last)) if t >= t_last => e_last + rate * (t - t_last),
            (Some(_), Some(_)) => {
                let i = self.table.partition_point(|&(tt, _)| tt <= t).max(1);
                let (t0, t1) = (self.table[i - 1].0, self.table[i].0);
                self.entrance[i - 1] + (self.entrance[i] - self.entrance[i - 1]) * (t - t0) / (t1 - t0)
            }
            _ => rate * t,
        };
        [e * u[0] / t, e * u[1] / t]
    }

    /// The largest angle the table reaches (degrees; 0 when only the paraxial mapping is known).
    pub fn traced_max_deg(&self) -> f64 {
        self.table.last().map_or(0.0, |&(t, _)| t.atan().to_degrees())
    }

    /// The landing height (mm, signed as the paraxial one) of a light of slope `tan_theta >= 0`.
    pub fn height_mm(&self, tan_theta: f64) -> f64 {
        let k = self.paraxial_mm_per_slope;
        let Some(&(t_last, h_last)) = self.table.last() else { return k * tan_theta };
        if tan_theta >= t_last {
            return h_last * tan_theta / t_last;
        }
        let i = self.table.partition_point(|&(t, _)| t <= tan_theta).max(1);
        let ((t0, h0), (t1, h1)) = (self.table[i - 1], self.table[i]);
        h0 + (h1 - h0) * (tan_theta - t0) / (t1 - t0)
    }

    /// The sensor point (mm) where a light of slopes `u` images.
    pub fn image_mm(&self, u: [f64; 2]) -> [f64; 2] {
        let t = u[0].hypot(u[1]);
        if t == 0.0 || !t.is_finite() {
            // On the axis (or a slope that is not finite: placed on the axis rather than at infinity).
            return [0.0, 0.0];
        }
        let h = self.height_mm(t);
        [h * u[0] / t, h * u[1] / t]
    }

    /// The slope `tan theta` whose image lands at the height `height_mm` (signed as the paraxial one), or
    /// `None` past the table's last traced height (no traced chief ray lands there).
    pub fn slope_for_height(&self, height_mm: f64) -> Option<f64> {
        let k = self.paraxial_mm_per_slope;
        if self.table.is_empty() {
            return (k != 0.0).then(|| height_mm / k);
        }
        let h = height_mm.abs();
        let sign = k.signum();
        let i = self.table.partition_point(|&(_, hh)| hh * sign <= h);
        if i == 0 {
            return Some(0.0);
        }
        if i >= self.table.len() {
            let (t_last, h_last) = self.table[self.table.len() - 1];
            return (h <= h_last * sign).then_some(t_last);
        }
        let ((t0, h0), (t1, h1)) = (self.table[i - 1], self.table[i]);
        let (h0, h1) = (h0 * sign, h1 * sign);
        Some(t0 + (t1 - t0) * (h - h0) / (h1 - h0))
    }

    /// The light slopes whose image lands at the sensor point `p_mm`, or `None` past the traced field.
    pub fn slopes_for_image(&self, p_mm: [f64; 2]) -> Option<[f64; 2]> {
        let r = p_mm[0].hypot(p_mm[1]);
        if r == 0.0 {
            return Some([0.0, 0.0]);
        }
        let t = self.slope_for_height(r * self.paraxial_mm_per_slope.signum())?;
        let s = self.paraxial_mm_per_slope.signum();
        Some([s * t * p_mm[0] / r, s * t * p_mm[1] / r])
    }
}

impl ImageMapping {
    /// The frame position (degrees, X right, Y up) of a light whose image lands on pixel `px` of a
    /// `width` x `height` image spanning `sensor`; `None` past the traced field.
    pub fn light_deg_for_pixel(&self, px: [f64; 2], sensor: &Sensor, width: u32, height: u32) -> Option<[f64; 2]> {
        let u = self.slopes_for_image(pixel_to_sensor(px, sensor, width, height))?;
        // Slopes (-tan X, -tan Y) for the frame position (X, Y): see `optics::sensor`.
        Some([(-u[0]).atan().to_degrees(), (-u[1]).atan().to_degrees()])
    }

    /// The pixel where a light seen at the frame position `light_deg` images (it may lie outside the image).
    pub fn pixel_for_light_deg(&self, light_deg: [f64; 2], sensor: &Sensor, width: u32, height: u32) -> [f64; 2] {
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        sensor_to_pixel(self.image_mm(u), sensor, width, height)
    }
}

/// The chief ray's landing height for the field angle `theta` (radians) in the y-z plane, aimed through the
/// stop's centre starting from pupil height `py0` (in pupil radii); with the pupil height found.
fn chief_ray_height(
    tracer: &Tracer,
    stop: usize,
    stop_radius_mm: f64,
    pupil: EntrancePupil,
    theta: f64,
    py0: f64,
) -> Option<(f64, f64)> {
    let at_stop = |py: f64| -> Option<(f64, f64)> {
        let ray: Ray = pupil_ray(&pupil, theta, 0.0, py);
        let mut stop_y = None;
        let landing = tracer
            .trace_visit(&ray, |hit| {
                if hit.surface == stop && stop_y.is_none() {
                    stop_y = Some(hit.point_mm.y);
                }
                true
            })
            .ok()?;
        Some((stop_y?, landing.point_mm.y))
    };
    let tolerance = 1e-9 * stop_radius_mm;
    let (mut p0, (mut s0, mut h0)) = (py0, at_stop(py0)?);
    if s0.abs() <= tolerance {
        return Some((h0, p0));
    }
    // A second point a little away, then secant steps.
    let mut p1 = p0 + if s0 > 0.0 { -0.01 } else { 0.01 };
    let (mut s1, mut h1) = at_stop(p1)?;
    for _ in 0..40 {
        if s1.abs() <= tolerance {
            return (h1.is_finite()).then_some((h1, p1));
        }
        let ds = s1 - s0;
        if ds == 0.0 || !ds.is_finite() {
            return None;
        }
        let p2 = p1 - s1 * (p1 - p0) / ds;
        if !p2.is_finite() || p2.abs() > 50.0 {
            return None;
        }
        (p0, s0, h0) = (p1, s1, h1);
        p1 = p2;
        (s1, h1) = at_stop(p1)?;
    }
    let _ = h0;
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::FirstOrder;
    use crate::optics::library::builtin_lens;

    fn mapping(name: &str) -> ImageMapping {
        let lens = builtin_lens(name).unwrap();
        let fo = FirstOrder::d_line(&lens).unwrap();
        // Paraxial image height per unit slope: the focal length (a ray of slope u images at f u).
        let k = fo.efl_mm;
        ImageMapping::new(&lens, fo.entrance_pupil(), fo.sensor_z_mm(), crate::optics::D_LINE_NM, k)
    }

    #[test]
    fn near_the_axis_the_traced_mapping_is_the_paraxial_one() {
        let m = mapping("dgauss");
        assert!(m.traced_max_deg() > 15.0, "{}", m.traced_max_deg());
        let t = 0.25f64.to_radians().tan();
        let rel = (m.height_mm(t) - m.paraxial_mm_per_slope * t).abs() / (m.paraxial_mm_per_slope * t).abs();
        assert!(rel < 1e-3, "{rel}");
    }

    #[test]
    fn a_fisheye_maps_far_from_a_pinhole_and_the_inverse_returns_the_angle() {
        let m = mapping("fisheye");
        assert!(m.traced_max_deg() > 60.0, "fisheye traced to {} deg", m.traced_max_deg());
        let t = 60f64.to_radians().tan();
        let pinhole = m.paraxial_mm_per_slope * t;
        let traced = m.height_mm(t);
        assert!(traced.abs() < 0.8 * pinhole.abs(), "fisheye {traced} mm vs pinhole {pinhole} mm");
        for deg in [0.0f64, 3.0, 20.0, 45.0, 60.0] {
            let u = [deg.to_radians().tan() * 0.6, deg.to_radians().tan() * -0.8];
            let p = m.image_mm(u);
            let back = m.slopes_for_image(p).unwrap();
            assert!((back[0] - u[0]).abs() < 1e-9 && (back[1] - u[1]).abs() < 1e-9, "{deg}: {u:?} -> {back:?}");
        }
        assert!(m.slopes_for_image([1e4, 0.0]).is_none(), "a point past the traced field is refused");
        // The fisheye's image circle is smaller than a full frame: a sensor inside it.
        let sensor = Sensor::for_frame(2.0 * m.height_mm(60f64.to_radians().tan()).abs(), 1920, 1080);
        for px in [[960.0, 540.0], [100.0, 900.0], [1800.0, 50.0]] {
            let deg = m.light_deg_for_pixel(px, &sensor, 1920, 1080).unwrap();
            let back = m.pixel_for_light_deg(deg, &sensor, 1920, 1080);
            assert!((back[0] - px[0]).abs() < 1e-6 && (back[1] - px[1]).abs() < 1e-6, "{px:?} -> {deg:?} -> {back:?}");
        }
        // Up and right in the frame are positive angles.
        let deg = m.light_deg_for_pixel([1800.0, 50.0], &sensor, 1920, 1080).unwrap();
        assert!(deg[0] > 0.0 && deg[1] > 0.0, "{deg:?}");
    }
}
