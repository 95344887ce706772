//! Depth of field from the flare's own lens: the plate defocused through the same aperture that shapes the
//! ghosts and the starburst.
//!
//! # How it works
//! **The model** ([`DofModel`]). The lens focuses as a unit: it moves so that the sensor sits at the paraxial
//! conjugate of the focus plane, and every distance S is measured along the axis from the entrance pupil (which
//! moves with the lens). From the lens's own first-order data at the d-line: the system matrix `[[A, B], [C, D]]`
//! from the entrance plane (the first vertex) to the last vertex, the entrance pupil at `z_ep` behind the first
//! vertex, its radius `r_ep` at the chosen f-number. An object at S from the pupil lies `d = S - z_ep` in front
//! of the first vertex; its image lies `b = -(A d + B) / (C d + D)` behind the last vertex with the lateral
//! magnification `m = A + b C` (translations `T(d)` before and `T(b)` after the system matrix, the image where
//! the product's B term vanishes). For the focus distance S_f that gives `m_f`.
//!
//! *Derivation of the blur.* The rays from an object point at S that the lens accepts fill the cone from the
//! point to the entrance pupil (diameter `D_ep = 2 r_ep`). The focus plane is imaged sharply onto the sensor, so
//! the blur on the sensor is the cone's section in the focus plane, magnified by `m_f`. By similar triangles
//! (apex at the object, base at the pupil) the section at S_f has the diameter `D_ep |S - S_f| / S`, hence
//! `c = D_ep |S - S_f| / S |m_f|`; at S = infinity, `c = D_ep |m_f|`. The section is the pupil itself, scaled
//! by `(S - S_f) / S`: upright behind the focus plane and point-reflected in front of it (the factor changes
//! sign). [`DofModel::defocus_px`] is that signed factor in pixels (positive behind the focus plane): it grows
//! monotonically with S, so it also orders depths.
//!
//! **The kernel** ([`kernel`]) is the stop's shape (blades, rotation, roundness or a custom image: the same
//! [`crate::aperture::ApertureMask`] as the ghosts) seen through the entrance pupil, scaled to c. With the cat's
//! eye on, it is cut off-axis by every clear aperture of the image path, as the ghost sprites are by theirs: a
//! ray from an object point at S, whose chief ray has the slope u, through the pupil point P crosses the first
//! vertex's plane at `P (1 - z_ep / S) - u z_ep` with the slope `P / S + u`, and each surface's plane at the
//! paraxial height its entrance matrix gives, which must lie within its semi-aperture: a circle in the pupil per
//! surface ([`DofModel::cat_circles_at`]; the front one cuts the outer side of a corner's pupil, the rear group's
//! the inner side: the lemon-shaped bokeh). The reference cuts each pixel's kernel by every circle that cuts it;
//! the live method takes per layer the `live::MAX_LAYER_CATS` that cut deepest at the frame's corners. Against
//! exact rays through a fast double Gauss (a test), the share of the pupil left at a corner is within 2 %. The cut
//! is paraxial: on a wide lens whose real entrance pupil moves with the field it cuts too much off axis. Every
//! kernel is normalised to 1: energy is conserved.
//!
//! **Occlusion** (both methods). The scene is a plate with one depth per pixel (2.5D). Pixels are grouped into
//! layers by depth; each layer scatters (or gathers) its premultiplied colour and its coverage with its own
//! kernel, and the layers are composited far to near, `out = C + (1 - A) out`: a nearer layer occludes a pixel's
//! cone by its blurred coverage, so an in-focus edge occludes sharply and a blurred foreground covers what is
//! behind it partly, as a lens does. What a 2.5D plate hides behind a foreground is unknown; the composite is
//! divided by its accumulated coverage, which fills such holes with the mean of the visible neighbours instead of
//! darkening them. [`reference`](mod@reference) is the exact method (every pixel's own kernel, layers 1/2 px of defocus thin),
//! [`live`] the fast one (a few layers, each gathered at a resolution that keeps its kernel a dozen texels across)
//! that `render::dof_gpu` runs on the GPU, its CPU twin beside it.
//!
//! **An anamorphic lens** (toroids aligned with x and y) is modelled section by section ([`model::SectionDefocus`]):
//! each section, a lens of revolution ([`crate::optics::Lens::section`]), images the focus plane at its own
//! distance; the sensor sits half way between the two (the plane of least confusion, as the first-order data
//! place it at infinity), and an object at S blurs along x by the cone through the x section's pupil onto that
//! plane, `-2 r_x (n0 d + n1) / (d + z_x)` with `[n0, n1]` the section's entrance-to-sensor row, along y by the
//! y section's. The kernel is the stop's shape stretched to those two widths: an oval bokeh, each axis
//! point-reflected in front of its own focus, whose aspect changes with depth where the sections focus apart.
//! Layers are keyed by the y blur (monotonic in depth); each layer and each reference kernel takes the x blur of
//! the same depth ([`DofModel::defocus_x_for`]). The cat's eye cuts it by every clear aperture, each axis
//! through its own section: the crossing `(P_x alpha_x - u_x o_x, P_y alpha_y - u_y o_y)` within the round
//! semi-aperture is an ellipse in the pupil ([`kernel::Cat`], its x scale `alpha_x r_x / alpha_y r_y`), each
//! pixel's chief slope per section from where the chief ray lands on the sensor. A test traces an axial point
//! through the real toroids and finds the spot's width and height within 4 % of the model's; both methods draw
//! them. Another traces a far point near a corner through a toroidal lens whose rear apertures cut: the share of
//! the pupil its bokeh keeps is within 3 % (reference) and 2 % (live) of the exact rays'.
//! Axial colour is refused for an anamorphic lens, with the reason.
//!
//! **Inputs** ([`depth`]): a depth map in metres (EXR: channel `Z`, else the first; a 16-bit PNG with a near/far
//! range), the focus distance or a pixel to focus on. Refused with the reason: a depth map of another size than
//! the plate, a depth that is negative, zero, NaN or inside the lens, a focus distance inside the lens or closer
//! than the lens can focus (a virtual image). An infinite depth is the far field.
//!
//! **Axial colour** (optional, [`DofDoc::axial_colour`]): the sensor stays where the d-line focuses, and each of
//! R, G and B is defocused with the model of its own wavelength ([`DofModel::at_wavelength`]: the object plane
//! that wavelength images onto the sensor), so out-of-focus edges take the lens's colour fringes; the clear
//! apertures' circles stay the d-line's.

pub mod depth;
pub mod kernel;
pub mod live;
pub mod model;
pub mod reference;
pub mod scene;

pub(crate) use model::check_size;
pub use model::{DofError, DofMethod, DofModel, defocus_map, over, resolve};

use crate::aperture::ApertureMask;
use crate::image::HdrImage;
use crate::optics::Lens;

/// The document's depth of field (the app's DoF panel, a preset's `"dof"`, the command line's flags).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DofDoc {
    /// Defocus the plate (the flare is added after, unblurred: ghosts are not in the scene).
    pub enabled: bool,
    /// The depth map (EXR in metres, or a 16-bit PNG with `depth_range_m`); a sequence when it has a frame
    /// field, like the background.
    pub depth: Option<String>,
    /// How a 16-bit PNG depth map's values map to metres.
    pub depth_range_m: Option<depth::PngRange>,
    /// Focus distance from the entrance pupil (m).
    pub focus_m: f64,
    /// Focus on the depth at this plate pixel (x, y from the top-left) instead of `focus_m`.
    pub focus_px: Option<[u32; 2]>,
    /// Cut the kernel off-axis by the lens's clear apertures (the cat's eye).
    pub cat_eye: bool,
    /// Axial colour: each of R, G and B defocused at its own wavelength (the RGB spectrum's, 650, 510 and 475
    /// nm), the sensor where the d-line focuses; three times the work.
    pub axial_colour: bool,
    pub method: DofMethod,
}

impl Default for DofDoc {
    fn default() -> Self {
        Self {
            enabled: false,
            depth: None,
            depth_range_m: None,
            focus_m: 3.0,
            focus_px: None,
            cat_eye: true,
            axial_colour: false,
            method: DofMethod::Live,
        }
    }
}

/// The farthest focus distance (m): 1000 km, past any lens's hyperfocal distance (a 250 mm lens at f/1 is
/// sharp to infinity from about 2 km), so farther is the same picture. Issue 61's walk: `--focus-m 1e300` was
/// accepted, echoed in 301 digits and overflowed the live method's layer count.
pub(crate) const MAX_FOCUS_M: f64 = 1e6;

impl DofDoc {
    /// Values serde cannot check: `(field, reason)`. (On with no depth map is kept, as the app saves it while
    /// the user picks one; drawing it then says so.)
    pub fn check(&self) -> Result<(), (String, String)> {
        if !(self.focus_m.is_finite() && self.focus_m > 0.0 && self.focus_m <= MAX_FOCUS_M) {
            let shown = crate::files::shorten_numbers(&self.focus_m.to_string());
            return Err((
                "dof.focus_m".into(),
                format!("{shown} m: a finite distance above 0, at most {MAX_FOCUS_M} m"),
            ));
        }
        Ok(())
    }

    /// The focus distance (m): `focus_m`, or the depth at `focus_px` of `map`.
    pub fn focus_on(&self, map: &depth::DepthMap) -> Result<f64, DofError> {
        match self.focus_px {
            Some([x, y]) => map.at(x, y),
            None => Ok(self.focus_m),
        }
    }
}

/// The lens, stop and sensor a depth of field is drawn with: the flare's own.
#[derive(Clone, Copy)]
pub struct DofLens<'a> {
    pub lens: &'a Lens,
    /// The chosen stop radius over the full one (the flare's f-number).
    pub stop_scale: f64,
    pub sensor_width_mm: f64,
    pub mask: &'a ApertureMask,
}

/// The plate defocused as `doc` says with the depth map at `depth_path`, on the CPU (the live method's twin or
/// the reference); the plate unchanged when the depth of field is off.
pub(crate) fn defocus_plate(
    doc: &DofDoc,
    lens: DofLens,
    depth_path: &std::path::Path,
    plate: &HdrImage,
) -> Result<HdrImage, DofError> {
    if !doc.enabled {
        return Ok(plate.clone());
    }
    let (models, depth) = prepare(doc, lens, depth_path, (plate.width, plate.height))?;
    per_channel(plate, &models, |plate, model| apply(plate, &depth, model, lens.mask, doc.method))
}

/// The models (one, or one per R, G, B channel with axial colour) and the depths (mm) for a plate of `size`:
/// the depth map at `depth_path` read and checked against the plate's size, the focus found.
pub fn prepare(
    doc: &DofDoc,
    lens: DofLens,
    depth_path: &std::path::Path,
    size: (u32, u32),
) -> Result<(Vec<DofModel>, Vec<f64>), DofError> {
    let map = depth::DepthMap::read(depth_path, doc.depth_range_m)?;
    if (map.width, map.height) != size {
        return Err(DofError::DepthSize { depth_w: map.width, depth_h: map.height, plate_w: size.0, plate_h: size.1 });
    }
    let focus_m = doc.focus_on(&map)?;
    let model = DofModel::new(lens.lens, lens.stop_scale, focus_m, lens.sensor_width_mm, size, doc.cat_eye)?;
    let models = if doc.axial_colour {
        crate::spectrum::Spectrum::rgb()
            .wavelengths_nm
            .iter()
            .map(|&nm| model.at_wavelength(lens.lens, nm))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        vec![model]
    };
    Ok((models, map.millimetres()))
}

/// `draw` with one model, or once per channel with three (axial colour): channel k of the result is channel k
/// of `draw` on the plate's channel k alone, with model k.
pub fn per_channel<E>(
    plate: &HdrImage,
    models: &[DofModel],
    mut draw: impl FnMut(&HdrImage, &DofModel) -> Result<HdrImage, E>,
) -> Result<HdrImage, E> {
    if models.len() != 3 {
        return draw(plate, &models[0]);
    }
    let mut out =
        HdrImage { width: plate.width, height: plate.height, pixels: vec![[0.0, 0.0, 0.0, 1.0]; plate.pixels.len()] };
    for (k, model) in models.iter().enumerate() {
        let alone = HdrImage {
            width: plate.width,
            height: plate.height,
            pixels: plate
                .pixels
                .iter()
                .map(|p| {
                    let mut q = [0.0, 0.0, 0.0, p[3]];
                    q[k] = p[k];
                    q
                })
                .collect(),
        };
        let drawn = draw(&alone, model)?;
        for (o, d) in out.pixels.iter_mut().zip(&drawn.pixels) {
            o[k] = d[k];
        }
    }
    Ok(out)
}

/// The plate defocused by `method` (see the module documentation): the plate and the depth map (mm from the
/// entrance pupil, one per pixel) must have the model's size.
pub fn apply(
    plate: &HdrImage,
    depth_mm: &[f64],
    model: &DofModel,
    mask: &ApertureMask,
    method: DofMethod,
) -> Result<HdrImage, DofError> {
    check_size(plate, depth_mm, model)?;
    match method {
        DofMethod::Reference => reference::render(plate, depth_mm, model, mask),
        DofMethod::Live => live::LivePlan::new(depth_mm, model, mask).map(|plan| plan.render_cpu(plate)),
    }
}
