//! Ray diagram (egui_plot, zoom and pan): the lens the view is drawn with (the last valid one, with the reason
//! when the edited lens is refused) to scale, each surface's arc up to its semi-aperture, the stop open at the
//! current f-number, the sensor at that lens's paraxial focus; and a fan of exact rays at the current light
//! angle, in the meridional plane of the light: the image path, or the selected ghost's path, its legs
//! coloured by direction (towards the sensor, back towards the front) with arrows, its two reflections marked.
//!
//! # How it works
//! The diagram takes the prepared flare's lens and first-order data together, so the sensor and the stop
//! always belong to the lens drawn. Its stop's clear radius is scaled to the f-number
//! ([`flare_core::ghost::GhostSystem`]'s stop scale) and the fan spans the entrance pupil scaled alike.
//! Rays start on a line across that pupil (`pupil_ray`) and are traced by the exact f64 tracer with the clear
//! apertures applied and every intersection recorded. A ray stopped early (vignetted, missed or totally
//! reflected) is drawn grey up to where it stopped. The ghost path reflects first at surface `j` then at `i`,
//! so its recorded points are: the start, the hits on surfaces `0..=j` (the last one is the first
//! reflection), then on `j-1` down to `i` (the second reflection, where the backward leg ends), then on to
//! the sensor. With a ghost selected, the clear apertures that cut its sprites at the light (the live flare's
//! discs, [`flare_core::ghost::GhostSystem::sprite_masks`]) are marked by a red tick at their rims and named in
//! the title.
//!
//! An anamorphic lens has two sections: a choice above the plot draws the y-z section (the light's y angle,
//! surfaces by their y-z profile) or the x-z section (rays in the x-z plane at the light's x angle across the
//! x section's paraxial entrance pupil, surfaces by their x-z sag), both through the real 3D lens.

use eframe::egui;
use egui_plot::{Arrows, Legend, Line, Plot, PlotPoints, Points};
use flare_core::flare::PreparedFlare;
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::{EntrancePupil, Lens, LightPath, Ray, Section, TraceOptions, TraceStatus, Tracer, pupil_ray};

use super::LensProblem;

/// The diagram's plot height (points).
pub const RAY_DIAGRAM_HEIGHT: f32 = 150.0;

/// Rays across the pupil.
const FAN: usize = 11;

/// One traced ray: its points (z, y), how it ended, and for a landed ghost ray the indices of its two
/// reflections among the points.
type TracedRay = (Vec<[f64; 2]>, TraceStatus, Option<(usize, usize)>);

/// What a fan is traced for: the prepared flare's identity, the field angle's bits, the ghost and the section.
type FanKey = (u64, u64, Option<(usize, usize)>, Section);

/// The traced fan and the lens it was traced through, cached while the prepared flare, the light and the ghost
/// are unchanged.
#[derive(Default)]
pub struct RayDiagram {
    /// What the fan was traced for.
    key: Option<FanKey>,
    /// The flare's lens with its stop opened to the f-number ([`lens_at_f_number`]).
    lens: Option<Lens>,
    /// Each ray's points, how it ended, and for a landed ghost ray the index of its first and second
    /// reflection among the points.
    rays: Vec<TracedRay>,
    reflections: Vec<[f64; 2]>,
    /// The section drawn (an anamorphic lens has two; a lens of revolution's y-z section stands for all).
    section: Option<Section>,
    /// The clear apertures that cut the selected ghost at the light (every wavelength's sprite), and what they
    /// were found for: the flare's identity, the light's bits and the ghost.
    cutting: Vec<usize>,
    cutting_key: Option<(u64, [u64; 2], (usize, usize))>,
}

impl RayDiagram {
    /// The surfaces whose clear apertures cut ghost (i, j)'s sprites at the light
    /// (`GhostSystem::cutting_surfaces`, as the live flare and the report cut them), found again when the flare,
    /// the light or the ghost changed.
    fn cutting_surfaces(&mut self, flare: &PreparedFlare, light_deg: [f64; 2], (i, j): (usize, usize)) -> &[usize] {
        let key = (flare.id, light_deg.map(f64::to_bits), (i, j));
        if self.cutting_key != Some(key) {
            self.cutting_key = Some(key);
            let system = &flare.system;
            let u = flare_core::ghost::light_slopes_for_frame_position(light_deg[0], light_deg[1]);
            self.cutting = system
                .ghosts
                .iter()
                .position(|h| (h.i, h.j) == (i, j))
                .map_or_else(Vec::new, |g| system.cutting_surfaces(g, u));
        }
        &self.cutting
    }
}

impl RayDiagram {
    /// Traces the fan again when the flare (its lens, stop or f-number), the field or the ghost changed; the
    /// flare's identity stands for all of its optics, so nothing is hashed or copied on an unchanged frame.
    fn update(&mut self, flare: &PreparedFlare, field_deg: f64, ghost: Option<(usize, usize)>, section: Section) {
        let key = (flare.id, field_deg.to_bits(), ghost, section);
        if self.key == Some(key) {
            return;
        }
        self.key = Some(key);
        let lens = self.lens.insert(lens_at_f_number(flare));
        self.rays.clear();
        self.reflections.clear();
        let fo = &flare.system.first_order;
        let stop_scale = flare.system.settings.stop_scale;
        // A section's coordinate across the axis: y, or x in the x-z section.
        let across = |p: glam::DVec3| if section == Section::X { p.x } else { p.y };
        let path = match ghost {
            Some((i, j)) => match LightPath::ghost(lens, i, j) {
                Ok(p) => p,
                Err(_) => return,
            },
            None => LightPath::image(lens),
        };
        let tracer = Tracer::new(lens, &path, D_LINE_NM, fo.sensor_z_mm());
        let theta = field_deg.to_radians();
        let full = fo.section(section).entrance_pupil();
        let pupil = EntrancePupil { z_mm: full.z_mm, radius_mm: full.radius_mm * stop_scale };
        for k in 0..FAN {
            let py = -1.0 + 2.0 * k as f64 / (FAN - 1) as f64;
            let ray = match section {
                Section::Y => pupil_ray(&pupil, theta, 0.0, py),
                // The same fan turned into the x-z plane.
                Section::X => {
                    let r = pupil_ray(&pupil, theta, 0.0, py);
                    let swap = |v: glam::DVec3| glam::DVec3::new(v.y, v.x, v.z);
                    Ray { origin_mm: swap(r.origin_mm), direction: swap(r.direction) }
                }
            };
            let out = tracer.trace(&ray, TraceOptions { apply_apertures: true, record_points: true });
            let mut points: Vec<[f64; 2]> = out.points_mm.iter().map(|p| [p.z, across(*p)]).collect();
            // Start the drawn ray in front of the lens, not at the (often virtual) entrance pupil.
            if let Some(second) = points.get(1).copied() {
                let z0 = -0.15 * fo.total_track_mm;
                points[0] = [z0, second[1] + (z0 - second[0]) * theta.tan()];
            }
            let mut legs = None;
            if let (Some((i, j)), TraceStatus::Landed) = (ghost, out.status) {
                let (first, second) = (1 + j, 1 + 2 * j - i);
                if second < points.len() {
                    self.reflections.extend([points[first], points[second]]);
                    legs = Some((first, second));
                }
            }
            if points.iter().all(|p| p.iter().all(|v| v.is_finite())) {
                self.rays.push((points, out.status, legs));
            }
        }
    }
}

/// The lens the diagram draws: the prepared flare's (the last valid one), its stop opened to the f-number.
fn lens_at_f_number(flare: &PreparedFlare) -> Lens {
    let mut lens = flare.system.lens.clone();
    let scale = flare.system.settings.stop_scale;
    for s in lens.surfaces.iter_mut().filter(|s| s.stop) {
        s.semi_aperture_mm *= scale;
    }
    lens
}

/// The middle of a polyline's part from point `a` to point `b` and a short step along it there (an arrow).
fn arrow_on(points: &[[f64; 2]], a: usize, b: usize, length: f64) -> Option<([f64; 2], [f64; 2])> {
    let part = points.get(a..=b)?;
    let total: f64 = part.windows(2).map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).sum();
    let mut walked = 0.0;
    for w in part.windows(2) {
        let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        if d > 0.0 && walked + d >= 0.5 * total {
            let t = (0.5 * total - walked) / d;
            let at = [w[0][0] + t * (w[1][0] - w[0][0]), w[0][1] + t * (w[1][1] - w[0][1])];
            let dir = [(w[1][0] - w[0][0]) / d, (w[1][1] - w[0][1]) / d];
            return Some((at, [at[0] + length * dir[0], at[1] + length * dir[1]]));
        }
        walked += d;
    }
    None
}

pub fn ray_diagram_ui(
    ui: &mut egui::Ui,
    diagram: &mut RayDiagram,
    flare: Option<&PreparedFlare>,
    problem: Option<&LensProblem>,
    light_deg: [f64; 2],
    ghost: Option<(usize, usize)>,
) {
    let Some(flare) = flare else {
        ui.label("no ray diagram: no valid lens yet");
        return;
    };
    let fo = &flare.system.first_order;
    let stop_scale = flare.system.settings.stop_scale;
    let anamorphic = flare.system.lens.is_anamorphic();
    let mut section = diagram.section.filter(|_| anamorphic).unwrap_or(Section::Y);
    if anamorphic {
        ui.horizontal(|ui| {
            ui.label("anamorphic lens, section:");
            ui.selectable_value(&mut section, Section::Y, "y-z (vertical)");
            ui.selectable_value(&mut section, Section::X, "x-z (horizontal)");
        });
        diagram.section = Some(section);
    }
    // The light's angle in the section drawn; a lens of revolution turns the light into its meridional plane.
    let field_deg = match (anamorphic, section) {
        (false, _) => light_deg[0].hypot(light_deg[1]),
        (true, Section::X) => light_deg[0],
        (true, Section::Y) => light_deg[1],
    };
    diagram.update(flare, field_deg, ghost, section);
    let cutting = ghost.map(|g| diagram.cutting_surfaces(flare, light_deg, g).to_vec()).unwrap_or_default();
    let Some(lens) = diagram.lens.as_ref() else { return };
    let h_max = flare.system.lens.surfaces.iter().map(|s| s.semi_aperture_mm).fold(1.0, f64::max);
    let f_number = fo.f_number / stop_scale;
    let title = diagram_title(ghost, f_number, field_deg, &cutting);
    // Wrapped: a long title must not widen the central panel under the side panel.
    ui.add(egui::Label::new(title).wrap());
    if let Some(problem) = problem {
        let text = format!("showing the last valid lens: the edited one is refused ({})", problem.reason);
        ui.add(egui::Label::new(egui::RichText::new(text).color(egui::Color32::from_rgb(255, 170, 90))).wrap());
    }
    // A fixed height: the viewport above takes what the rows under it leave, so a diagram that filled the
    // leftover height would shrink to a sliver.
    Plot::new("ray_diagram")
        .height(RAY_DIAGRAM_HEIGHT)
        .data_aspect(1.0)
        .legend(Legend::default().position(egui_plot::Corner::LeftTop))
        .x_axis_label("z (mm)")
        .y_axis_label(if section == Section::X { "x (mm)" } else { "y (mm)" })
        .show(ui, |plot| {
            plot_lens(plot, lens, section, h_max, &cutting);
            let sensor = fo.sensor_z_mm();
            plot.line(
                Line::new("sensor", PlotPoints::from(vec![[sensor, -h_max], [sensor, h_max]]))
                    .color(egui::Color32::from_gray(200))
                    .width(2.0),
            );
            plot_rays(plot, diagram, 0.04 * fo.total_track_mm.abs().max(1.0));
            if !diagram.reflections.is_empty() {
                plot.points(
                    Points::new("reflections", PlotPoints::from(diagram.reflections.clone()))
                        .radius(3.0)
                        .color(egui::Color32::from_rgb(255, 60, 200)),
                );
            }
        });
}

/// The diagram's title: the ghost traced (or the image path), its f-number, the light's angle and what cuts it.
fn diagram_title(ghost: Option<(usize, usize)>, f_number: f64, field_deg: f64, cutting: &[usize]) -> String {
    let cut_words = match cutting {
        [] => "no clear aperture cuts it here".to_string(),
        [k] => format!("the clear aperture of surface {k} cuts it here (marked red)"),
        many => format!(
            "the clear apertures of surfaces {} cut it here (marked red)",
            many.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(", ")
        ),
    };
    match ghost {
        Some((i, j)) => format!(
            "ghost {i}-{j} at f/{f_number:.1}: exact rays at {field_deg:.1} deg, towards the sensor orange, back \
             towards the front blue, reflections marked; {cut_words}"
        ),
        None => format!("image path at f/{f_number:.1}: exact rays at {field_deg:.1} deg (select a ghost to trace it)"),
    }
}

/// The lens in `section`: each surface's arc up to its semi-aperture, the stop open from its rim to past the
/// tallest surface (`h_max`), and a red tick on each rim in `cutting`.
fn plot_lens(plot: &mut egui_plot::PlotUi<'_>, lens: &Lens, section: Section, h_max: f64, cutting: &[usize]) {
    let z = lens.vertex_z_mm();
    let glass = egui::Color32::from_rgb(150, 200, 255);
    for (k, s) in lens.surfaces.iter().enumerate() {
        if s.stop {
            for sign in [-1.0, 1.0] {
                let pts = vec![[z[k], sign * s.semi_aperture_mm], [z[k], sign * h_max * 1.1]];
                plot.line(
                    Line::new("stop", PlotPoints::from(pts)).color(egui::Color32::from_rgb(240, 200, 80)).width(3.0),
                );
            }
            if !lens.stop_on_lens_surface() {
                continue;
            }
        }
        let pts: Vec<[f64; 2]> = (0..=40)
            .map(|n| {
                let h = s.semi_aperture_mm * (n as f64 / 20.0 - 1.0);
                let sag = if section == Section::X { s.sag_xy_mm(h, 0.0) } else { s.sag_mm(h) };
                [z[k] + sag.unwrap_or(0.0), h]
            })
            .collect();
        plot.line(Line::new("surfaces", PlotPoints::from(pts)).color(glass).width(1.5));
        if cutting.contains(&k) {
            // The rim that cuts the selected ghost: a thick red tick outwards from each edge.
            let a = s.semi_aperture_mm;
            for sign in [-1.0, 1.0] {
                let h = sign * a;
                let sag = if section == Section::X { s.sag_xy_mm(h, 0.0) } else { s.sag_mm(h) };
                let zk = z[k] + sag.unwrap_or(0.0);
                let tick = vec![[zk, h], [zk, h + sign * 0.08 * h_max]];
                plot.line(
                    Line::new("cuts the ghost", PlotPoints::from(tick))
                        .color(egui::Color32::from_rgb(255, 70, 70))
                        .width(4.0),
                );
            }
        }
    }
}

/// The colour of rays travelling towards the sensor.
const FORWARD: egui::Color32 = egui::Color32::from_rgb(255, 140, 60);
/// The colour of rays travelling back towards the front.
const BACKWARD: egui::Color32 = egui::Color32::from_rgb(90, 170, 255);

/// The traced rays: a ghost's legs in two colours with an arrow each on the middle ray, an image ray in one,
/// rays the lens stops in grey; arrows `arrow` mm long.
fn plot_rays(plot: &mut egui_plot::PlotUi<'_>, diagram: &RayDiagram, arrow: f64) {
    let (mut origins, mut tips) = (Vec::new(), Vec::new());
    for (n, (points, status, legs)) in diagram.rays.iter().enumerate() {
        match (status, legs) {
            (TraceStatus::Landed, Some((first, second))) => {
                // In, back between the reflections, out: two colours, one arrow per leg on the middle ray.
                let parts = [(0, *first, FORWARD), (*first, *second, BACKWARD), (*second, points.len() - 1, FORWARD)];
                for (a, b, color) in parts {
                    let name = if color == FORWARD { "to the sensor" } else { "backwards" };
                    plot.line(Line::new(name, PlotPoints::from(points[a..=b].to_vec())).color(color).width(1.0));
                    if n == diagram.rays.len() / 2
                        && let Some((o, t)) = arrow_on(points, a, b, arrow)
                    {
                        origins.push(o);
                        tips.push(t);
                    }
                }
            }
            (TraceStatus::Landed, None) => {
                plot.line(Line::new("rays", PlotPoints::from(points.clone())).color(FORWARD).width(1.0));
                if n == diagram.rays.len() / 2
                    && let Some((o, t)) = arrow_on(points, 0, points.len() - 1, arrow)
                {
                    origins.push(o);
                    tips.push(t);
                }
            }
            _ => plot.line(
                Line::new("stopped rays", PlotPoints::from(points.clone()))
                    .color(egui::Color32::from_gray(130))
                    .width(1.0),
            ),
        }
    }
    if !origins.is_empty() {
        plot.arrows(
            Arrows::new("direction", PlotPoints::from(origins), PlotPoints::from(tips))
                .color(egui::Color32::WHITE)
                .tip_length(10.0),
        );
    }
}
