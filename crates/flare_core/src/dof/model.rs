//! The defocus model: the blur diameter of every depth from the lens's first-order data, and the compositing
//! both methods share (see the parent module's documentation for the derivation).

use super::kernel::Cat;
use crate::image::HdrImage;
use crate::optics::{D_LINE_NM, Lens, LightPath, PathMatrices};

/// Why a depth of field is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DofError {
    #[error("focus distance {0} m: must be a finite distance above 0")]
    Focus(f64),
    #[error(
        "focus distance {focus_m} m is inside the lens: the front vertex is {front_m:.3} m in front of the entrance pupil"
    )]
    FocusInsideLens { focus_m: f64, front_m: f64 },
    #[error(
        "focus distance {focus_m} m is closer than this lens can focus (its image would be virtual; the focal length is {efl_mm:.1} mm)"
    )]
    TooClose { focus_m: f64, efl_mm: f64 },
    /// Axial colour: at this wavelength no real object plane is imaged onto the sensor (the lens's axial colour
    /// moves that wavelength's focus past infinity), which the model cannot draw.
    #[error(
        "axial colour: at {wavelength_nm:.0} nm this lens focuses past infinity when the d-line focuses at {focus_m} m \
         (its axial colour is larger than the focus travel from there to infinity); focus closer or draw without \
         axial colour"
    )]
    ColourPastInfinity { wavelength_nm: f64, focus_m: f64 },
    #[error("the lens has no usable first-order data: {0}")]
    Lens(String),
    #[error("sensor width {0} mm: must be finite and positive")]
    Sensor(f64),
    #[error("depth map is {depth_w}x{depth_h}, the plate {plate_w}x{plate_h}: they must be the same size")]
    DepthSize { depth_w: u32, depth_h: u32, plate_w: u32, plate_h: u32 },
    #[error("depth map, pixel ({x}, {y}): depth {value} m is {reason}")]
    Depth { x: u32, y: u32, value: f64, reason: &'static str },
    #[error("depth map {path}: {reason}")]
    DepthFile { path: String, reason: String },
    #[error("cancelled")]
    Cancelled,
    #[error("focus pixel ({x}, {y}) is outside the {width}x{height} depth map")]
    FocusPixel { x: u32, y: u32, width: u32, height: u32 },
}

/// How the plate is defocused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum DofMethod {
    /// The layered gather ([`live`](super::live)): the app's and the default.
    #[default]
    Live,
    /// Every pixel's own kernel scattered into thin layers ([`reference`]): slow and exact.
    Reference,
}

impl DofMethod {
    pub fn word(self) -> &'static str {
        match self {
            Self::Live => "live",
            Self::Reference => "reference",
        }
    }
}

/// The lens's defocus model for one focus distance, f-number and frame (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct DofModel {
    /// Entrance pupil: distance behind the first vertex, radius at the chosen f-number (mm).
    pub pupil_z_mm: f64,
    pub pupil_radius_mm: f64,
    /// Focus distance from the entrance pupil (mm).
    pub focus_mm: f64,
    /// Lateral magnification of the focus plane onto the sensor (negative: a real, inverted image).
    pub focus_magnification: f64,
    /// Front clear semi-aperture (mm).
    pub front_radius_mm: f64,
    /// Every clear aperture of a lens of revolution but the stop's, the front one first: `[A, B, semi-aperture]`
    /// with `[[A, B], ..]` the d-line image path's matrix from the entrance plane to that surface, so that a ray
    /// of entrance height `y0` and slope `u` crosses it at `A y0 + B u` (empty for an anamorphic lens: each of
    /// its sections holds its own, [`SectionDefocus::clear_apertures`]).
    pub clear_apertures: Vec<[f64; 3]>,
    /// +1 or -1: the stop's image in the entrance pupil is upright or inverted (the mask's orientation).
    pub mask_sign: f64,
    /// Sensor millimetres per pixel (the plate spans the sensor width).
    pub pixel_mm: f64,
    pub width: u32,
    pub height: u32,
    /// Cut the kernel off axis by the lens's clear apertures (the cat's eye).
    pub cat_eye: bool,
    /// The wavelength this model's light has (the d-line unless axial colour is drawn per channel).
    pub wavelength_nm: f64,
    /// An anamorphic lens's two sections (`None` for a lens of revolution): the model's own pupil, focus
    /// magnification and mask orientation are then the y-z section's, with the sensor half way between where
    /// the two sections image the focus plane (the plane of least confusion).
    pub sections: Option<Box<[SectionDefocus; 2]>>,
}

/// One section (x-z or y-z) of an anamorphic lens, for the defocus along its axis.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionDefocus {
    /// `[A + b C, B + b D]`: the section's entrance plane to the sensor plane (`b` behind the last vertex), so a
    /// ray of entrance height `y0` and slope `u` lands at `to_sensor[0] y0 + to_sensor[1] u`.
    pub to_sensor: [f64; 2],
    /// The sensor plane's distance behind the last vertex (the same for both sections).
    pub sensor_mm: f64,
    /// The section's entrance pupil: distance behind the first vertex, radius at the chosen f-number (mm).
    pub pupil_z_mm: f64,
    pub pupil_radius_mm: f64,
    /// The section's clear apertures as [`DofModel::clear_apertures`] holds a lens of revolution's: `[A, B,
    /// semi-aperture]`, the section's matrix from the entrance plane to each (the same surfaces in both sections).
    pub clear_apertures: Vec<[f64; 3]>,
}

impl SectionDefocus {
    /// The signed blur diameter (mm) along this section's axis of an object `d_mm` in front of the first vertex
    /// (infinite: the far field): the cone from the object through the pupil's rim, `-2 r (n0 d + n1) / (d +
    /// z_EP)`, positive behind the plane this section focuses on the sensor (for an inverting section).
    fn blur_mm(&self, d_mm: f64) -> f64 {
        let [n0, n1] = self.to_sensor;
        if d_mm.is_infinite() {
            return -2.0 * self.pupil_radius_mm * n0;
        }
        -2.0 * self.pupil_radius_mm * (n0 * d_mm + n1) / (d_mm + self.pupil_z_mm)
    }

    /// The object distance in front of the first vertex whose blur is `blur_mm` (the inverse of [`Self::blur_mm`],
    /// a Moebius map, monotonic); infinite at and beyond the far field's.
    fn distance_for(&self, blur_mm: f64) -> f64 {
        let [n0, n1] = self.to_sensor;
        let r2 = 2.0 * self.pupil_radius_mm;
        let denominator = blur_mm + r2 * n0;
        let d = -(r2 * n1 + blur_mm * self.pupil_z_mm) / denominator;
        if denominator == 0.0 || !d.is_finite() || d <= 0.0 { f64::INFINITY } else { d }
    }
}

/// The lens's paraxial data a model needs, from the d-line image path.
struct LensData {
    system: [f64; 4],
    clear_apertures: Vec<[f64; 3]>,
    pupil_z_mm: f64,
    pupil_radius_mm: f64,
    efl_mm: f64,
    mask_sign: f64,
}

fn lens_data(lens: &Lens) -> Result<LensData, DofError> {
    if lens.is_anamorphic() {
        // An anamorphic lens is modelled section by section ([`DofModel::new`]), never as one round lens.
        return Err(DofError::Lens(
            crate::ghost::GhostError::anamorphic(lens, "axial colour in the depth of field").to_string(),
        ));
    }
    let fo = crate::optics::FirstOrder::d_line(lens).map_err(|e| DofError::Lens(e.to_string()))?;
    let z_last = lens.vertex_z_mm().last().copied().unwrap_or(0.0);
    let path = LightPath::image(lens);
    let (z, n, stop) = (lens.vertex_z_mm(), lens.media_indices_at(D_LINE_NM), lens.stop_index());
    let mut clear_apertures = Vec::new();
    let m = PathMatrices::walk(lens, &z, &n, &path, z_last, |step, arriving| {
        let k = path.steps[step].surface;
        let a = lens.surfaces[k].semi_aperture_mm;
        if k != stop && a.is_finite() && a > 0.0 {
            clear_apertures.push([arriving.a, arriving.b, a]);
        }
    });
    let a_stop = m.stop_from_entrance.first().map_or(1.0, |s| s.a);
    let s = fo.system;
    Ok(LensData {
        system: [s.a, s.b, s.c, s.d],
        clear_apertures,
        pupil_z_mm: fo.entrance_pupil_z_mm,
        pupil_radius_mm: fo.entrance_pupil_radius_mm(),
        efl_mm: fo.efl_mm,
        mask_sign: if a_stop < 0.0 { -1.0 } else { 1.0 },
    })
}

/// The image distance behind the last vertex and the magnification of an object `d_mm` in front of the first
/// vertex, through the system matrix `[a, b, c, d]`; `None` for a virtual image or none.
fn conjugate(system: [f64; 4], d_mm: f64) -> Option<(f64, f64)> {
    let [a, b, c, d] = system;
    let denominator = c * d_mm + d;
    if denominator == 0.0 || !denominator.is_finite() {
        return None;
    }
    let image_mm = -(a * d_mm + b) / denominator;
    (image_mm > 0.0 && image_mm.is_finite()).then_some((image_mm, a + image_mm * c))
}

impl DofModel {
    /// The model of `lens` stopped down by `stop_scale` (the flare's: chosen stop radius / full), focused at
    /// `focus_m` metres from the entrance pupil, for a `width` x `height` frame spanning `sensor_width_mm`.
    pub fn new(
        lens: &Lens,
        stop_scale: f64,
        focus_m: f64,
        sensor_width_mm: f64,
        (width, height): (u32, u32),
        cat_eye: bool,
    ) -> Result<Self, DofError> {
        if !(focus_m.is_finite() && focus_m > 0.0) {
            return Err(DofError::Focus(focus_m));
        }
        if !(sensor_width_mm.is_finite() && sensor_width_mm > 0.0) {
            return Err(DofError::Sensor(sensor_width_mm));
        }
        if lens.is_anamorphic() {
            return Self::anamorphic(lens, stop_scale, focus_m, sensor_width_mm, (width, height), cat_eye);
        }
        let data = lens_data(lens)?;
        let focus_mm = focus_m * 1000.0;
        let d_mm = focus_mm - data.pupil_z_mm;
        if d_mm <= 0.0 {
            return Err(DofError::FocusInsideLens { focus_m, front_m: data.pupil_z_mm / 1000.0 });
        }
        let (_, focus_magnification) =
            conjugate(data.system, d_mm).ok_or(DofError::TooClose { focus_m, efl_mm: data.efl_mm })?;
        Ok(Self {
            pupil_z_mm: data.pupil_z_mm,
            pupil_radius_mm: data.pupil_radius_mm * stop_scale.clamp(1e-3, 1.0),
            focus_mm,
            focus_magnification,
            front_radius_mm: lens.surfaces.first().map_or(f64::INFINITY, |s| s.semi_aperture_mm),
            clear_apertures: data.clear_apertures,
            mask_sign: data.mask_sign,
            pixel_mm: sensor_width_mm / f64::from(width.max(1)),
            width,
            height,
            cat_eye,
            wavelength_nm: D_LINE_NM,
            sections: None,
        })
    }

    /// [`Self::new`] of an anamorphic lens: each section (a lens of revolution, [`Lens::section`]) images the
    /// focus plane at its own distance behind the last vertex; the sensor sits half way between (the plane of
    /// least confusion, as [`crate::optics::FirstOrder`] places it at infinity), and each section blurs along
    /// its axis by its own pupil and its own defocus there: the stop's shape stretched per axis, an oval bokeh
    /// whose aspect changes with depth when the sections focus apart.
    fn anamorphic(
        lens: &Lens,
        stop_scale: f64,
        focus_m: f64,
        sensor_width_mm: f64,
        (width, height): (u32, u32),
        cat_eye: bool,
    ) -> Result<Self, DofError> {
        let sections = [crate::optics::Section::X, crate::optics::Section::Y].map(|s| lens_data(&lens.section(s)));
        let [x, y] = sections;
        let (x, y) = (x?, y?);
        let focus_mm = focus_m * 1000.0;
        let d_mm = focus_mm - y.pupil_z_mm;
        if d_mm <= 0.0 || focus_mm - x.pupil_z_mm <= 0.0 {
            return Err(DofError::FocusInsideLens { focus_m, front_m: y.pupil_z_mm.max(x.pupil_z_mm) / 1000.0 });
        }
        let too_close = |efl_mm| DofError::TooClose { focus_m, efl_mm };
        let (image_x, _) = conjugate(x.system, d_mm).ok_or(too_close(x.efl_mm))?;
        let (image_y, _) = conjugate(y.system, d_mm).ok_or(too_close(y.efl_mm))?;
        let b = 0.5 * (image_x + image_y);
        let section = |data: &LensData| {
            let [a, bb, c, d] = data.system;
            SectionDefocus {
                to_sensor: [a + b * c, bb + b * d],
                sensor_mm: b,
                pupil_z_mm: data.pupil_z_mm,
                pupil_radius_mm: data.pupil_radius_mm * stop_scale.clamp(1e-3, 1.0),
                clear_apertures: data.clear_apertures.clone(),
            }
        };
        let (sx, sy) = (section(&x), section(&y));
        Ok(Self {
            pupil_z_mm: y.pupil_z_mm,
            pupil_radius_mm: sy.pupil_radius_mm,
            focus_mm,
            focus_magnification: sy.to_sensor[0],
            front_radius_mm: lens.surfaces.first().map_or(f64::INFINITY, |s| s.semi_aperture_mm),
            clear_apertures: Vec::new(),
            mask_sign: y.mask_sign,
            pixel_mm: sensor_width_mm / f64::from(width.max(1)),
            width,
            height,
            cat_eye,
            wavelength_nm: D_LINE_NM,
            sections: Some(Box::new([sx, sy])),
        })
    }

    /// The signed blur diameters in pixels along x and along y of an object `depth_mm` from the entrance pupil
    /// (equal for a lens of revolution: [`Self::defocus_px`] twice).
    pub fn defocus_xy_px(&self, depth_mm: f64) -> [f64; 2] {
        match &self.sections {
            None => [self.defocus_px(depth_mm); 2],
            Some(s) => {
                let d = depth_mm - self.pupil_z_mm;
                [s[0].blur_mm(d) / self.pixel_mm, s[1].blur_mm(d) / self.pixel_mm]
            }
        }
    }

    /// The blur along x (pixels, signed) of the depth whose blur along y is `sigma_y`: `sigma_y` itself for a lens
    /// of revolution; for an anamorphic lens through the depth (`depth_of_defocus`), so that layers and kernels
    /// keyed by the y blur carry the x blur of the same depth.
    pub fn defocus_x_for(&self, sigma_y: f64) -> f64 {
        match &self.sections {
            None => sigma_y,
            Some(_) => self.defocus_xy_px(depth_of_defocus(self, sigma_y))[0],
        }
    }

    /// Axial colour: the model for light of `wavelength_nm`, the sensor staying where the d-line focuses
    /// (`self`). With the system matrix `[[A, B], [C, D]]` at that wavelength, the object plane imaged onto the
    /// sensor (b behind the last vertex) lies `d = -(B + b D) / (A + b C)` in front of the first vertex, with
    /// the magnification `A + b C`: the lens is in focus at another distance for each colour, and every blur
    /// follows from there. Refused when no real object plane is imaged there ([`DofError::ColourPastInfinity`]:
    /// the Nikon zoom's 650 nm when the d-line focuses at 2 m or farther; its 620 nm at 63 m when the d-line is
    /// at 3 m).
    pub fn at_wavelength(&self, lens: &Lens, wavelength_nm: f64) -> Result<Self, DofError> {
        // An anamorphic lens: refused with the reason (its sections' colours are not modelled).
        let d_line = lens_data(lens)?;
        let d_mm = self.focus_mm - d_line.pupil_z_mm;
        let too_close = DofError::TooClose { focus_m: self.focus_mm / 1000.0, efl_mm: d_line.efl_mm };
        let (image_mm, _) = conjugate(d_line.system, d_mm).ok_or(too_close)?;
        let z_last = lens.vertex_z_mm().last().copied().unwrap_or(0.0);
        let m = PathMatrices::compute(lens, &LightPath::image(lens), wavelength_nm, z_last).sensor_from_entrance;
        let denominator = m.a + image_mm * m.c;
        let d_lambda = -(m.b + image_mm * m.d) / denominator;
        if !(d_lambda.is_finite() && d_lambda > 0.0 && denominator.is_finite()) {
            // The d-line's focus is real (checked above): the colour's is past infinity, a virtual object.
            return Err(DofError::ColourPastInfinity { wavelength_nm, focus_m: self.focus_mm / 1000.0 });
        }
        Ok(Self {
            focus_mm: d_lambda + d_line.pupil_z_mm,
            focus_magnification: denominator,
            wavelength_nm,
            ..self.clone()
        })
    }

    /// Checks one depth (mm from the entrance pupil): positive, not NaN, in front of the first vertex. Infinity
    /// is the far field.
    pub fn check_depth_mm(&self, depth_mm: f64) -> Result<(), &'static str> {
        if depth_mm.is_nan() {
            Err("not a number")
        } else if depth_mm <= 0.0 {
            Err("not above 0")
        } else if depth_mm <= self.pupil_z_mm {
            Err("inside the lens (behind its front vertex)")
        } else {
            Ok(())
        }
    }

    /// The signed blur diameter in pixels of an object `depth_mm` from the entrance pupil: positive behind the
    /// focus plane, negative in front of it; its magnitude is `D_ep |S - S_f| / S |m_f|` (module documentation).
    pub fn defocus_px(&self, depth_mm: f64) -> f64 {
        if let Some(s) = &self.sections {
            return s[1].blur_mm(depth_mm - self.pupil_z_mm) / self.pixel_mm;
        }
        let factor = if depth_mm.is_infinite() { 1.0 } else { (depth_mm - self.focus_mm) / depth_mm };
        2.0 * self.pupil_radius_mm * factor * self.focus_magnification.abs() / self.pixel_mm
    }

    /// The blur diameter on the sensor (mm) of an object `depth_mm` from the entrance pupil.
    pub fn coc_mm(&self, depth_mm: f64) -> f64 {
        self.defocus_px(depth_mm).abs() * self.pixel_mm
    }

    /// The largest blur a depth can have (pixels): that of the far field.
    pub fn far_defocus_px(&self) -> f64 {
        self.defocus_px(f64::INFINITY)
    }

    /// Every clear aperture's region in the pupil ([`Cat`], pupil radii) for a source pixel at (`x`, `y`) (pixel
    /// centres, from the top-left) at depth `depth_mm`, cutting or not, the front one first; empty when the cat's
    /// eye is off. A pupil point q passes an aperture when it lies inside its region.
    ///
    /// Frame millimetres (X right, Y up) are minus the sensor's (the display is turned by 180 degrees). An object
    /// at height X in the focus plane images at m_f X on the sensor, and its chief ray has the slope u = -X / S_f,
    /// so u = frame / (m_f S_f). The ray from the object (S from the pupil) through the pupil point P (mm) has
    /// the slope `P / S + u` and crosses the first vertex's plane at `P (1 - z_ep / S) - u z_ep`; at a surface
    /// whose entrance matrix row is `[A, B]` it is at `P alpha - u (A z_ep - B)` with `alpha = A (1 - z_ep / S) +
    /// B / S`, inside the semi-aperture a when `|P - c| <= a / |alpha|`, `c = u (A z_ep - B) / alpha`: a circle.
    /// An anamorphic lens does this per section (x with the x section's matrices, pupil and magnification, y with
    /// the y section's): the crossing `(P_x alpha_x - u_x o_x, P_y alpha_y - u_y o_y)` must lie within the
    /// surface's round semi-aperture, an ellipse in the pupil whose x is stretched by `alpha_x / alpha_y` beside
    /// the pupil's own `r_x / r_y` ([`Cat::x_scale`]). A surface with `alpha = 0` (the object imaged onto it, in
    /// either section) passes the whole pupil or none of it, as the chief ray passes or not: a radius of infinity
    /// or 0.
    pub fn cat_circles_at(&self, x: f64, y: f64, depth_mm: f64) -> Vec<Cat> {
        if !self.cat_eye {
            return Vec::new();
        }
        let frame_mm =
            [(x - 0.5 * f64::from(self.width)) * self.pixel_mm, (0.5 * f64::from(self.height) - y) * self.pixel_mm];
        // Per axis: the magnification, the pupil's place and radius; and each aperture's rows in x and in y.
        type Rows = ([f64; 2], [f64; 2], f64);
        type Axes = ([f64; 2], [f64; 2], [f64; 2]);
        let front = || vec![([1.0, 0.0], [1.0, 0.0], self.front_radius_mm)];
        // `m`: the frame's millimetres per unit of the chief ray's slope, `m_f S_f`. A section, whose sensor is not
        // where it images the focus plane, lands the chief ray of slope u through its pupil (z behind the first
        // vertex, so crossing it at -u z) at `A' (-u z) + B' u` on the sensor, with `[A', B']` its `to_sensor`:
        // `(A' z - B') u` in the frame (turned by 180 degrees), which is `m_f S_f u` where the section is in focus.
        let ((m, z, r), rows): (Axes, Vec<Rows>) = match &self.sections {
            None => {
                let rows: Vec<Rows> = self.clear_apertures.iter().map(|&[a, b, semi]| ([a, b], [a, b], semi)).collect();
                let m_f_s_f = self.focus_magnification * self.focus_mm;
                let axes = ([m_f_s_f; 2], [self.pupil_z_mm; 2], [self.pupil_radius_mm; 2]);
                (axes, if rows.is_empty() { front() } else { rows })
            }
            Some(s) => {
                let (sx, sy) = (&s[0], &s[1]);
                let same = sx.clear_apertures.len() == sy.clear_apertures.len() && !sx.clear_apertures.is_empty();
                let rows: Vec<Rows> = sx
                    .clear_apertures
                    .iter()
                    .zip(&sy.clear_apertures)
                    .map(|(&[ax, bx, semi], &[ay, by, _])| ([ax, bx], [ay, by], semi))
                    .collect();
                let chief = |s: &SectionDefocus| s.to_sensor[0] * s.pupil_z_mm - s.to_sensor[1];
                let axes =
                    ([chief(sx), chief(sy)], [sx.pupil_z_mm, sy.pupil_z_mm], [sx.pupil_radius_mm, sy.pupil_radius_mm]);
                (axes, if same { rows } else { front() })
            }
        };
        let slope = [frame_mm[0] / m[0], frame_mm[1] / m[1]];
        // The object's distance in front of the first vertex, then per axis from that axis's pupil.
        let front_mm = depth_mm - self.pupil_z_mm;
        let inverse_depth = z.map(|z| if front_mm.is_infinite() { 0.0 } else { 1.0 / (front_mm + z) });
        let shrink = [0, 1].map(|k| (1.0 - z[k] * inverse_depth[k]).max(1e-6));
        rows.iter()
            .map(|&(row_x, row_y, semi)| {
                let alpha = [0, 1].map(|k| {
                    let [a, b] = if k == 0 { row_x } else { row_y };
                    a * shrink[k] + b * inverse_depth[k]
                });
                let offset = [row_x[0] * z[0] - row_x[1], row_y[0] * z[1] - row_y[1]];
                if alpha[0].abs() < 1e-12 || alpha[1].abs() < 1e-12 {
                    let passes = (slope[0] * offset[0]).hypot(slope[1] * offset[1]) <= semi;
                    return Cat::circle([0.0, 0.0], if passes { f64::INFINITY } else { 0.0 });
                }
                let unit = alpha[1] * r[1];
                Cat {
                    centre: [slope[0] * offset[0] / unit, slope[1] * offset[1] / unit],
                    radius: semi / unit.abs(),
                    x_scale: alpha[0] * r[0] / unit,
                }
            })
            .collect()
    }

    /// The regions of [`Self::cat_circles_at`] that cut the pupil there (those that do not hold the whole unit
    /// pupil), in the same order.
    pub fn cat_eyes_at(&self, x: f64, y: f64, depth_mm: f64) -> Vec<Cat> {
        let mut cats = self.cat_circles_at(x, y, depth_mm);
        cats.retain(Cat::cuts);
        cats
    }

    /// The front aperture's region alone ([`Self::cat_circles_at`]'s first): `None` when the cat's eye is off.
    pub fn cat_eye_at(&self, x: f64, y: f64, depth_mm: f64) -> Option<Cat> {
        self.cat_circles_at(x, y, depth_mm).into_iter().next()
    }
}

/// The depth (mm from the pupil) whose defocus (along y for an anamorphic lens) is `sigma` pixels: for a lens of
/// revolution `S_f / (1 - sigma / sigma_far)`; infinite at and beyond the far field's.
pub(crate) fn depth_of_defocus(model: &DofModel, sigma: f64) -> f64 {
    if let Some(s) = &model.sections {
        return s[1].distance_for(sigma * model.pixel_mm) + model.pupil_z_mm;
    }
    let far = model.far_defocus_px();
    if far <= 0.0 || sigma >= far {
        return f64::INFINITY;
    }
    model.focus_mm / (1.0 - sigma / far)
}

/// The defocus of every pixel (signed diameter, pixels) of a depth map in mm, checking each depth.
pub fn defocus_map(model: &DofModel, depth_mm: &[f64]) -> Result<Vec<f64>, DofError> {
    let w = model.width.max(1) as usize;
    depth_mm
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            model.check_depth_mm(d).map(|()| model.defocus_px(d)).map_err(|reason| DofError::Depth {
                x: (k % w) as u32,
                y: (k / w) as u32,
                value: d / 1000.0,
                reason,
            })
        })
        .collect()
}

/// Refuses a plate or depth map of another size than the model's frame.
pub(crate) fn check_size(plate: &HdrImage, depth_mm: &[f64], model: &DofModel) -> Result<(), DofError> {
    let expected = model.width as usize * model.height as usize;
    if plate.width != model.width || plate.height != model.height || depth_mm.len() != expected {
        let (depth_w, depth_h) =
            if depth_mm.len() == expected { (model.width, model.height) } else { (depth_mm.len() as u32, 1) };
        return Err(DofError::DepthSize { depth_w, depth_h, plate_w: plate.width, plate_h: plate.height });
    }
    Ok(())
}

/// Composites one layer (premultiplied colour and coverage, `[r, g, b, a]`) over what is behind it:
/// `out = C + (1 - A) out`, the coverage clamped to 1. Both methods and the GPU use this order of operations.
#[inline]
pub fn over(out: &mut [f32; 4], layer: [f32; 4]) {
    let keep = 1.0 - layer[3].min(1.0);
    for k in 0..3 {
        out[k] = layer[k] + keep * out[k];
    }
    out[3] = layer[3].min(1.0) + keep * out[3];
}

/// The composite divided by its coverage (the holes of a 2.5D plate filled by their neighbours' mean); black
/// where nothing covers (no NaN).
#[inline]
pub fn resolve(out: [f32; 4]) -> [f32; 4] {
    if out[3] > 1e-6 { [out[0] / out[3], out[1] / out[3], out[2] / out[3], 1.0] } else { [0.0, 0.0, 0.0, 1.0] }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::library::builtin_lens;

    fn heliar_model(focus_m: f64) -> DofModel {
        DofModel::new(&builtin_lens("heliar").unwrap(), 1.0, focus_m, 36.0, (1920, 1080), false).unwrap()
    }

    #[test]
    fn the_blur_follows_the_cone_through_the_pupil() {
        let lens = builtin_lens("heliar").unwrap();
        let fo = crate::optics::FirstOrder::d_line(&lens).unwrap();
        let m = heliar_model(2.0);
        // In focus: no blur; the far field: D_ep |m_f|.
        assert!(m.defocus_px(2000.0).abs() < 1e-12);
        let far = fo.entrance_pupil_diameter_mm * m.focus_magnification.abs();
        assert!((m.coc_mm(f64::INFINITY) - far).abs() < 1e-12);
        // Twice as far: half the far field's; in front: negative (point-reflected), larger.
        assert!((m.coc_mm(4000.0) - 0.5 * far).abs() < 1e-12);
        assert!(m.defocus_px(1000.0) < 0.0 && (m.coc_mm(1000.0) - far).abs() < 1e-12);
        // Monotonic in depth.
        let d: Vec<f64> = [500.0, 1000.0, 2000.0, 8000.0, f64::INFINITY].iter().map(|&s| m.defocus_px(s)).collect();
        assert!(d.windows(2).all(|w| w[0] < w[1]), "{d:?}");
        // The thin-lens limit far away: m_f -> -f / (S_f - f) roughly; at 100 m it is within 0.5% of -f / S_f.
        let far_focus = heliar_model(100.0);
        let thin = -fo.efl_mm / 100_000.0;
        assert!((far_focus.focus_magnification / thin - 1.0).abs() < 5e-3, "{}", far_focus.focus_magnification);
    }

    #[test]
    fn the_magnification_is_the_conjugate_through_the_matrices() {
        // Check m_f by tracing a paraxial ray: from an axial object point at S_f, a ray at slope 0.001 through
        // the system crosses the axis at the image distance; the height ratio of an off-axis point is m_f.
        let lens = builtin_lens("heliar").unwrap();
        let data = lens_data(&lens).unwrap();
        let model = heliar_model(1.5);
        let d_mm = model.focus_mm - data.pupil_z_mm;
        let (image_mm, m) = conjugate(data.system, d_mm).unwrap();
        let [a, b, c, dd] = data.system;
        // An object at height 1 with slope 0 after d and the system: height a + ... then b more to the image.
        let (y0, u0) = (1.0, 0.0);
        let (y1, u1) = (y0 + d_mm * u0, u0);
        let (y2, u2) = (a * y1 + b * u1, c * y1 + dd * u1);
        let y_image = y2 + image_mm * u2;
        assert!((y_image - m).abs() < 1e-12);
        // And any ray from the axial point meets the axis there.
        let (y1, u1) = (0.0 + d_mm * 0.001, 0.001);
        let (y2, u2) = (a * y1 + b * u1, c * y1 + dd * u1);
        assert!((y2 + image_mm * u2).abs() < 1e-12);
        assert!((m - model.focus_magnification).abs() < 1e-15 && m < 0.0);
    }

    #[test]
    fn impossible_focus_and_depths_are_refused_with_the_reason() {
        let lens = builtin_lens("heliar").unwrap();
        let new = |f| DofModel::new(&lens, 1.0, f, 36.0, (64, 64), false);
        assert_eq!(new(0.0).unwrap_err(), DofError::Focus(0.0));
        assert!(matches!(new(f64::NAN), Err(DofError::Focus(_))));
        // 1 mm: inside the lens or closer than it can focus.
        let close = new(0.001).unwrap_err().to_string();
        assert!(close.contains("inside the lens") || close.contains("closer than"), "{close}");
        // Just beyond the front vertex but well inside the focal length: a virtual image.
        let fo = crate::optics::FirstOrder::d_line(&lens).unwrap();
        let inside_f = (fo.entrance_pupil_z_mm + 0.3 * fo.efl_mm) / 1000.0;
        assert!(matches!(new(inside_f), Err(DofError::TooClose { .. })), "{:?}", new(inside_f));
        let m = new(2.0).unwrap();
        assert_eq!(m.check_depth_mm(-1.0), Err("not above 0"));
        assert_eq!(m.check_depth_mm(f64::NAN), Err("not a number"));
        assert!(m.check_depth_mm(f64::INFINITY).is_ok());
        let m = DofModel { width: 2, height: 1, ..m };
        let err = defocus_map(&m, &[1000.0, f64::NAN]).unwrap_err().to_string();
        assert_eq!(err, "depth map, pixel (1, 0): depth NaN m is not a number");
    }

    #[test]
    fn axial_colour_moves_the_focus_plane_by_the_paraxial_colour_shift() {
        // The d-line's own model is the model; for red and blue, the plane in focus differs, and an axial ray
        // from it traced paraxially at that wavelength meets the axis on the sensor.
        let lens = builtin_lens("heliar").unwrap();
        let m = DofModel::new(&lens, 1.0, 3.0, 36.0, (1920, 1080), false).unwrap();
        let same = m.at_wavelength(&lens, D_LINE_NM).unwrap();
        assert!(
            (same.focus_mm - m.focus_mm).abs() < 1e-6
                && (same.focus_magnification - m.focus_magnification).abs() < 1e-12
        );
        for wavelength in [475.0, 650.0] {
            let c = m.at_wavelength(&lens, wavelength).unwrap();
            // Trace an axial ray from the colour's focus plane at that wavelength: it meets the axis on the sensor.
            let z_last = *lens.vertex_z_mm().last().unwrap();
            let sys = PathMatrices::compute(&lens, &LightPath::image(&lens), wavelength, z_last).sensor_from_entrance;
            let d = c.focus_mm - m.pupil_z_mm;
            let (y, u) = (d * 0.001, 0.001);
            let (y2, u2) = (sys.a * y + sys.b * u, sys.c * y + sys.d * u);
            let data = lens_data(&lens).unwrap();
            let (image_mm, _) = conjugate(data.system, m.focus_mm - m.pupil_z_mm).unwrap();
            assert!((y2 + image_mm * u2).abs() < 1e-9, "{wavelength}: {}", y2 + image_mm * u2);
            assert!((c.focus_mm - m.focus_mm).abs() > 1e-3, "{wavelength}: no colour shift at all");
        }
    }

    /// The Nikon zoom's axial colour moves 650 nm's focus past infinity when the d-line focuses at 2 m or
    /// farther: refused naming that (at 1 m it draws), where it was refused as "closer than this lens can focus".
    #[test]
    fn a_colour_focused_past_infinity_is_refused_as_that() {
        let lens = builtin_lens("nikon_zoom_28_75mm").unwrap();
        let m = DofModel::new(&lens, 1.0, 3.0, 36.0, (96, 54), false).unwrap();
        assert!(m.at_wavelength(&lens, 620.0).is_ok_and(|c| c.focus_mm > 10_000.0));
        let e = m.at_wavelength(&lens, 650.0).unwrap_err();
        assert_eq!(e, DofError::ColourPastInfinity { wavelength_nm: 650.0, focus_m: m.focus_mm / 1000.0 });
        assert!(e.to_string().contains("past infinity") && !e.to_string().contains("closer than"), "{e}");
        let near = DofModel::new(&lens, 1.0, 1.0, 36.0, (96, 54), false).unwrap();
        assert!(near.at_wavelength(&lens, 650.0).is_ok(), "focused at 1 m, 650 nm has a real plane in focus");
    }

    #[test]
    fn the_cat_eye_moves_with_the_field_and_is_off_on_axis() {
        let lens = builtin_lens("heliar").unwrap();
        let m = DofModel::new(&lens, 1.0, 2.0, 36.0, (1920, 1080), true).unwrap();
        let Cat { centre: c, radius: r, x_scale } = m.cat_eye_at(960.0, 540.0, 5000.0).unwrap();
        assert!(c[0].abs() < 1e-12 && c[1].abs() < 1e-12 && r > 1.0 && x_scale == 1.0);
        // The top-left corner: the front lens cuts the outer side of the pupil, so the circle that keeps the
        // light lies towards the frame's centre (right and down: +X, -Y).
        let corner = m.cat_eye_at(0.0, 0.0, 5000.0).unwrap().centre;
        assert!(corner[0] > 0.0 && corner[1] < 0.0, "{corner:?}");
        // Opposite corners cut opposite sides.
        let other = m.cat_eye_at(1920.0, 1080.0, 5000.0).unwrap().centre;
        assert!((corner[0] + other[0]).abs() < 1e-12 && (corner[1] + other[1]).abs() < 1e-12);
    }
}
