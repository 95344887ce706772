//! Paraxial optics: 2x2 ray-transfer matrices, first-order data, and the matrix of any light path.
//!
//! # How it works
//! Near the axis (sin t ~ t, cos t ~ 1) a meridional ray is the 2-vector (y, u): its height and its slope
//! along the direction of travel. Every interaction is a 2x2 matrix ([`Mat2`]), the forms of
//! `crates/flare_core/METHOD.md` (Lee & Eisemann 2013; KR 10-1465658):
//! - translation over the axial distance d = |dz|: `T(d) = [[1, d], [0, 1]]`;
//! - refraction at curvature c from index n1 to n2: `[[1, 0], [-s (n2 - n1) c / n2, n1 / n2]]`;
//! - reflection at curvature c in any medium: `[[1, 0], [2 s c, 1]]`;
//!
//! where s = +1 when the light arrives travelling towards +z and s = -1 when it arrives travelling back
//! (after an odd number of reflections), and c is the surface's vertex curvature (`1/R + 2 A2` for an even
//! asphere: the conic and the terms from r^4 up do not act near the axis). For forward travel these are exactly METHOD.md's `T`, `R` and `L`;
//! s carries the backward case, which METHOD.md writes with inverse matrices of a slope measured along +z
//! instead of along the travel direction (the two agree on every height). Multiplying the matrices along a
//! [`LightPath`] gives its matrix from the *entrance plane* (the plane of the first vertex, z = 0, in object
//! space) to the sensor. From the image path come the first-order data ([`FirstOrder`]); for a ghost the
//! matrix is split where the path crosses the stop: `M_f = M_s M_a` ([`PathMatrices`]).
//!
//! An anamorphic lens (toroidal surfaces aligned with x and y) acts near the axis on x and y apart, each by
//! these matrices with that section's vertex curvatures: [`Lens::section`] gives the lens of revolution of
//! each section, and [`FirstOrder`] keeps both sections' data.
//!
//! Singular cases: a lens whose system matrix has C = 0 is afocal (no focus) and one whose entrance-to-stop
//! matrix has A = 0 has its entrance pupil at infinity; both are refused by [`FirstOrder::compute`] with
//! the reason, so no division by zero ever happens downstream.

use serde::Serialize;

use super::glass::D_LINE_NM;
use super::lens::{Lens, Section};
use super::path::{Interaction, LightPath};

/// A 2x2 ray-transfer matrix acting on (y, u): `[[a, b], [c, d]]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Mat2 {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
}

impl Mat2 {
    pub const IDENTITY: Self = Self { a: 1.0, b: 0.0, c: 0.0, d: 1.0 };

    /// Translation over the axial distance `d_mm` (>= 0, along the direction of travel).
    pub fn translation(d_mm: f64) -> Self {
        Self { a: 1.0, b: d_mm, c: 0.0, d: 1.0 }
    }

    /// Refraction at curvature `c_per_mm` from index `n1` to `n2`, arriving in direction `s` (+1 / -1).
    pub fn refraction(c_per_mm: f64, n1: f64, n2: f64, s: f64) -> Self {
        Self { a: 1.0, b: 0.0, c: -s * (n2 - n1) * c_per_mm / n2, d: n1 / n2 }
    }

    /// Reflection at curvature `c_per_mm`, arriving in direction `s` (+1 / -1).
    pub fn reflection(c_per_mm: f64, s: f64) -> Self {
        Self { a: 1.0, b: 0.0, c: 2.0 * s * c_per_mm, d: 1.0 }
    }

    /// `self * rhs`: apply `rhs` first, then `self`.
    pub fn mul(&self, rhs: &Self) -> Self {
        Self {
            a: self.a * rhs.a + self.b * rhs.c,
            b: self.a * rhs.b + self.b * rhs.d,
            c: self.c * rhs.a + self.d * rhs.c,
            d: self.c * rhs.b + self.d * rhs.d,
        }
    }

    /// Maps the ray (y, u).
    pub fn apply(&self, y: f64, u: f64) -> (f64, f64) {
        (self.a * y + self.b * u, self.c * y + self.d * u)
    }

    /// The inverse; a ray-transfer matrix's determinant is a ratio of indices, never 0.
    pub fn inverse(&self) -> Self {
        let det = self.determinant();
        Self { a: self.d / det, b: -self.b / det, c: -self.c / det, d: self.a / det }
    }

    pub fn determinant(&self) -> f64 {
        self.a * self.d - self.b * self.c
    }

    pub fn as_rows(&self) -> [[f64; 2]; 2] {
        [[self.a, self.b], [self.c, self.d]]
    }
}

/// The matrices of one light path at one wavelength.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PathMatrices {
    /// Entrance plane (z = 0) to sensor: the flare matrix M_f for a ghost.
    pub sensor_from_entrance: Mat2,
    /// Entrance plane to the stop plane, at each crossing of the stop in path order (one crossing for the
    /// image and most ghosts, three for a ghost whose reflections straddle the stop). `[0]` is M_a.
    pub stop_from_entrance: Vec<Mat2>,
    /// Last stop crossing to sensor: M_s, so that `sensor_from_entrance = M_s * stop_from_entrance.last()`.
    pub sensor_from_stop: Mat2,
}

impl PathMatrices {
    /// Where a collimated beam along this path comes to a paraxial focus, measured along the axis from the
    /// sensor plane (positive towards the image side): with `sensor_from_entrance = [[A, B], [C, D]]`, the rays
    /// of one direction meet where `A + C d = 0`, so `d = -A / C`. `None` when `C = 0`: the path is afocal
    /// (its rays leave parallel, there is no focus).
    pub fn focus_after_sensor_mm(&self) -> Option<f64> {
        let m = &self.sensor_from_entrance;
        let d = -m.a / m.c;
        (m.c != 0.0 && d.is_finite()).then_some(d)
    }

    /// Multiplies the matrices along `path` at `wavelength_nm`, ending on the plane `sensor_z_mm`.
    pub fn compute(lens: &Lens, path: &LightPath, wavelength_nm: f64, sensor_z_mm: f64) -> Self {
        let n = lens.media_indices_at(wavelength_nm);
        let z = lens.vertex_z_mm();
        Self::walk(lens, &z, &n, path, sensor_z_mm, |_, _| {})
    }

    /// The same product from precomputed vertex positions `z` and medium indices `n` (see
    /// [`Lens::media_indices_at`]), calling `visit(step_index, arriving)` with the entrance-to-arrival matrix
    /// at each step, before its interaction: what the ghost module needs for angles of incidence.
    pub fn walk(
        lens: &Lens,
        z: &[f64],
        n: &[f64],
        path: &LightPath,
        sensor_z_mm: f64,
        mut visit: impl FnMut(usize, &Mat2),
    ) -> Self {
        let stop = lens.stop_index();
        let mut total = Mat2::IDENTITY;
        let mut since_stop = Mat2::IDENTITY;
        let mut stop_from_entrance = Vec::with_capacity(1);
        let mut z_now = 0.0;
        for (index, step) in path.steps.iter().enumerate() {
            let k = step.surface;
            let travel = Mat2::translation((z[k] - z_now).abs());
            total = travel.mul(&total);
            since_stop = travel.mul(&since_stop);
            visit(index, &total);
            let c = lens.surfaces[k].vertex_curvature_per_mm();
            let s = step.arriving_direction;
            let m = match step.interaction {
                Interaction::Refract => Mat2::refraction(c, n[step.medium_in], n[step.medium_out], s),
                Interaction::Reflect => Mat2::reflection(c, s),
            };
            z_now = z[k];
            total = m.mul(&total);
            since_stop = m.mul(&since_stop);
            if k == stop {
                stop_from_entrance.push(total);
                since_stop = Mat2::IDENTITY;
            }
        }
        let to_sensor = Mat2::translation((sensor_z_mm - z_now).abs());
        Self {
            sensor_from_entrance: to_sensor.mul(&total),
            stop_from_entrance,
            sensor_from_stop: to_sensor.mul(&since_stop),
        }
    }

    /// Paraxial landing height on the sensor of the ray through the entrance pupil at height
    /// `pupil_height_mm` with slope `slope` (tan of the field angle), the convention of [`pupil_ray`].
    ///
    /// [`pupil_ray`]: crate::optics::trace::pupil_ray
    pub fn landing_height_mm(&self, pupil: &EntrancePupil, pupil_height_mm: f64, slope: f64) -> f64 {
        let y0 = pupil_height_mm - pupil.z_mm * slope;
        self.sensor_from_entrance.apply(y0, slope).0
    }
}

/// The paraxial entrance pupil: where rays are aimed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EntrancePupil {
    /// Position from the first vertex (+ behind it).
    pub z_mm: f64,
    pub radius_mm: f64,
}

/// Why first-order data cannot be computed for a lens.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParaxialError {
    #[error("the lens is afocal (system matrix C = 0): it has no focal length or focal plane")]
    Afocal,
    #[error("the entrance pupil is at infinity (the stop's image through the front group does not exist)")]
    PupilAtInfinity,
    #[error("the paraxial focus lies {bfd_mm:.3} mm in front of the last surface: no real image plane")]
    VirtualFocus { bfd_mm: f64 },
    /// One section of an anamorphic lens has no first-order data (a lone cylinder has no power in its other
    /// section: it is afocal there).
    #[error("in its {section}-z section (the lens is anamorphic), {error}")]
    Section { section: &'static str, error: Box<ParaxialError> },
}

/// First-order (Gaussian) data of a lens at one wavelength, in the conventions of `tests/data/reference`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FirstOrder {
    pub wavelength_nm: f64,
    /// Effective focal length, -1/C of the system matrix.
    pub efl_mm: f64,
    /// Back focal distance: last vertex to the paraxial focus.
    pub bfd_mm: f64,
    /// Entrance pupil position from the first vertex (+ behind it).
    pub entrance_pupil_z_mm: f64,
    pub entrance_pupil_diameter_mm: f64,
    /// efl / entrance pupil diameter.
    pub f_number: f64,
    /// Exit pupil position from the last vertex (+ behind it).
    pub exit_pupil_z_mm: f64,
    pub stop_surface: usize,
    /// First vertex to the paraxial focus: where the sensor sits.
    pub total_track_mm: f64,
    /// The system matrix, entrance plane to last vertex.
    pub system: Mat2,
    /// For an anamorphic lens, the first-order data of each section (x, y), each the lens of revolution
    /// [`Lens::section`] gives; `None` for a lens of revolution. An anamorphic lens's own fields are its y-z
    /// section's, but for the sensor plane: `total_track_mm` (and `bfd_mm` with it) is half way between the
    /// two sections' paraxial foci, the plane of least confusion (both sections focus there when the lens is
    /// designed to, as an anamorphic camera lens is).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sections: Option<Box<[FirstOrder; 2]>>,
}

impl FirstOrder {
    /// First-order data at the d-line: the sensor position every trace uses.
    pub fn d_line(lens: &Lens) -> Result<Self, ParaxialError> {
        Self::compute(lens, D_LINE_NM)
    }

    pub fn compute(lens: &Lens, wavelength_nm: f64) -> Result<Self, ParaxialError> {
        if !lens.is_anamorphic() {
            return Self::of_revolution(lens, wavelength_nm);
        }
        let of = |s: Section| {
            Self::of_revolution(&lens.section(s), wavelength_nm)
                .map_err(|e| ParaxialError::Section { section: s.word(), error: Box::new(e) })
        };
        let (x, y) = (of(Section::X)?, of(Section::Y)?);
        let z_last = y.total_track_mm - y.bfd_mm;
        let total_track_mm = 0.5 * (x.total_track_mm + y.total_track_mm);
        Ok(Self { total_track_mm, bfd_mm: total_track_mm - z_last, sections: Some(Box::new([x, y.clone()])), ..y })
    }

    /// The first-order data of `section` (the lens's own for a lens of revolution).
    /// An anamorphic lens's squeeze, `EFL_y / EFL_x` (how much wider the x field is: what a desqueeze of the
    /// frame undoes); `None` for a lens of revolution.
    pub fn squeeze(&self) -> Option<f64> {
        self.sections.as_ref().map(|both| both[1].efl_mm / both[0].efl_mm).filter(|s| s.is_finite())
    }

    pub fn section(&self, section: Section) -> &FirstOrder {
        match (&self.sections, section) {
            (Some(both), Section::X) => &both[0],
            (Some(both), Section::Y) => &both[1],
            (None, _) => self,
        }
    }

    fn of_revolution(lens: &Lens, wavelength_nm: f64) -> Result<Self, ParaxialError> {
        let image = LightPath::image(lens);
        let z = lens.vertex_z_mm();
        let z_last = *z.last().unwrap_or(&0.0);
        // The image path ends on the last vertex (sensor plane = last vertex, distance 0).
        let m = PathMatrices::compute(lens, &image, wavelength_nm, z_last);
        let system = m.sensor_from_entrance;
        if system.c == 0.0 || !system.c.is_finite() {
            return Err(ParaxialError::Afocal);
        }
        let efl_mm = -1.0 / system.c;
        let bfd_mm = -system.a / system.c;
        if bfd_mm <= 0.0 {
            return Err(ParaxialError::VirtualFocus { bfd_mm });
        }
        let stop = lens.stop_index();
        let stop_from_entrance = m.stop_from_entrance[0];
        if stop_from_entrance.a == 0.0 {
            return Err(ParaxialError::PupilAtInfinity);
        }
        // A chief ray (through the stop centre) crosses the axis, in object space, at z = B / A.
        let entrance_pupil_z_mm = stop_from_entrance.b / stop_from_entrance.a;
        // A ray parallel to the axis at height y reaches the stop at A y.
        let entrance_pupil_diameter_mm = 2.0 * lens.surfaces[stop].semi_aperture_mm / stop_from_entrance.a.abs();
        let rear = m.sensor_from_stop;
        let exit_pupil_z_mm = if rear.d == 0.0 { f64::INFINITY } else { -rear.b / rear.d };
        Ok(Self {
            wavelength_nm,
            efl_mm,
            bfd_mm,
            entrance_pupil_z_mm,
            entrance_pupil_diameter_mm,
            f_number: efl_mm / entrance_pupil_diameter_mm,
            exit_pupil_z_mm,
            stop_surface: stop,
            total_track_mm: z_last + bfd_mm,
            system,
            sections: None,
        })
    }

    /// Entrance pupil radius.
    pub fn entrance_pupil_radius_mm(&self) -> f64 {
        0.5 * self.entrance_pupil_diameter_mm
    }

    /// The entrance pupil rays are aimed at.
    pub fn entrance_pupil(&self) -> EntrancePupil {
        EntrancePupil { z_mm: self.entrance_pupil_z_mm, radius_mm: self.entrance_pupil_radius_mm() }
    }

    /// z of the sensor plane (the paraxial focus).
    pub fn sensor_z_mm(&self) -> f64 {
        self.total_track_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrices_compose_in_the_right_order_and_keep_determinants() {
        let r = Mat2::refraction(1.0 / 50.0, 1.0, 1.5, 1.0);
        assert!((r.determinant() - 1.0 / 1.5).abs() < 1e-15, "det of refraction is n1/n2");
        let t = Mat2::translation(10.0);
        let m = t.mul(&r);
        // A ray parallel to the axis at height 1 bends towards it, then travels 10 mm.
        let (y, u) = m.apply(1.0, 0.0);
        assert!((u - (-(0.5 / 50.0) / 1.5)).abs() < 1e-15);
        assert!((y - (1.0 + 10.0 * u)).abs() < 1e-15);
        assert_eq!(Mat2::reflection(0.0, 1.0), Mat2::IDENTITY, "a flat mirror keeps (y, u) along travel");
    }

    fn close(a: &Mat2, b: &Mat2) -> bool {
        let (a, b) = (a.as_rows(), b.as_rows());
        (0..2).all(|r| (0..2).all(|c| (a[r][c] - b[r][c]).abs() <= 1e-12 * (1.0 + b[r][c].abs())))
    }

    #[test]
    fn a_ghosts_paraxial_focus_is_where_the_exact_rays_near_the_axis_meet() {
        use crate::optics::{Ray, TraceOptions, TraceStatus, Tracer};
        let lens = crate::optics::library::builtin_lens("heliar").unwrap();
        let fo = FirstOrder::d_line(&lens).unwrap();
        let mut checked = 0;
        for (i, j) in lens.ghost_pairs() {
            let path = LightPath::ghost(&lens, i, j).unwrap();
            let m = PathMatrices::compute(&lens, &path, D_LINE_NM, fo.sensor_z_mm());
            let Some(focus) = m.focus_after_sensor_mm() else { continue };
            // Independently: an exact ray parallel to the axis at a small height crosses the axis at -y / slope
            // beyond the sensor plane.
            let tracer = Tracer::new(&lens, &path, D_LINE_NM, fo.sensor_z_mm());
            let h = 1e-4 * fo.entrance_pupil_radius_mm();
            let ray = Ray { origin_mm: glam::DVec3::new(0.0, h, -1.0), direction: glam::DVec3::new(0.0, 0.0, 1.0) };
            let out = tracer.trace(&ray, TraceOptions { apply_apertures: false, record_points: false });
            if out.status != TraceStatus::Landed {
                continue;
            }
            let (p, d) = (out.sensor_point_mm.unwrap(), out.sensor_direction.unwrap());
            let exact = -p.y / (d.y / d.z);
            assert!(
                (exact - focus).abs() <= 1e-6 * (1.0 + focus.abs()),
                "ghost {i}-{j}: paraxial focus {focus} mm, exact rays meet at {exact} mm"
            );
            checked += 1;
        }
        assert!(checked >= 20, "{checked} ghosts checked");
        // The image path focuses on the sensor itself.
        let image = PathMatrices::compute(&lens, &LightPath::image(&lens), D_LINE_NM, fo.sensor_z_mm());
        assert!(image.focus_after_sensor_mm().unwrap().abs() < 1e-9);
    }

    #[test]
    fn ghost_matrices_split_at_the_stop_and_keep_every_crossing() {
        let lens = crate::optics::library::builtin_lens("heliar").unwrap();
        let fo = FirstOrder::d_line(&lens).unwrap();
        let stop = lens.stop_index();
        let mut straddling = 0;
        for (i, j) in lens.ghost_pairs() {
            let path = LightPath::ghost(&lens, i, j).unwrap();
            let m = PathMatrices::compute(&lens, &path, D_LINE_NM, fo.sensor_z_mm());
            let expected_crossings = if i < stop && stop < j { 3 } else { 1 };
            assert_eq!(m.stop_from_entrance.len(), expected_crossings, "ghost ({i}, {j})");
            assert_eq!(path.straddles_stop(&lens), expected_crossings == 3);
            straddling += usize::from(expected_crossings == 3);
            // M_f = M_s M_a, with M_a the entrance-to-stop matrix of the last crossing.
            let product = m.sensor_from_stop.mul(m.stop_from_entrance.last().unwrap());
            assert!(
                close(&product, &m.sensor_from_entrance),
                "ghost ({i}, {j}): {product:?} vs {:?}",
                m.sensor_from_entrance
            );
            // Two reflections and refractions there and back: det = n_object / n_image = 1.
            assert!((m.sensor_from_entrance.determinant() - 1.0).abs() < 1e-12);
        }
        assert_eq!(straddling, 5 * 3, "Heliar: 5 reflecting surfaces before the stop, 3 after");
    }

    #[test]
    fn first_order_data_follow_the_wavelength() {
        let lens = crate::optics::library::builtin_lens("tessar").unwrap();
        let blue = FirstOrder::compute(&lens, 475.0).unwrap();
        let green = FirstOrder::compute(&lens, D_LINE_NM).unwrap();
        let red = FirstOrder::compute(&lens, 650.0).unwrap();
        // An achromat: the focal length changes little, and the pupil diameter hardly at all.
        assert!(
            (blue.efl_mm - red.efl_mm).abs() < 0.01 * green.efl_mm,
            "{} {} {}",
            blue.efl_mm,
            green.efl_mm,
            red.efl_mm
        );
        assert_ne!(blue.efl_mm, red.efl_mm, "the indices do depend on the wavelength");
        // A single positive lens of dispersive glass focuses blue shorter than red.
        let singlet = Lens {
            id: "singlet".into(),
            name: "singlet".into(),
            surfaces: serde_json::from_str(
                r#"[{"radius": 0, "thickness": 2, "nd": 1.0, "semi_aperture": 5, "stop": true},
                    {"radius": 50, "thickness": 5, "nd": 1.5168, "vd": 64.17, "glass": "N-BK7", "semi_aperture": 10},
                    {"radius": -50, "thickness": 45, "nd": 1.0, "semi_aperture": 10}]"#,
            )
            .unwrap(),
            extra: Default::default(),
        };
        singlet.validate().unwrap();
        let (b, r) = (FirstOrder::compute(&singlet, 475.0).unwrap(), FirstOrder::compute(&singlet, 650.0).unwrap());
        assert!(b.efl_mm < r.efl_mm - 0.5, "blue {} red {}", b.efl_mm, r.efl_mm);
    }
}
