//! Ray diagram (egui_plot, zoom and pan): the lens cross-section to scale (each surface's arc up to its
//! semi-aperture, the stop, the sensor at the paraxial focus) and a fan of exact rays at the current light
//! angle, in the meridional plane of the light: the image path, or the selected ghost's path with its two
//! reflections marked.
//!
//! # How it works
//! Rays start on a line across the entrance pupil (`pupil_ray`) and are traced by the exact f64 tracer
//! with the clear apertures applied and every intersection recorded. A ray stopped early (vignetted, missed
//! or totally reflected) is drawn grey up to where it stopped. The ghost path reflects first at surface `j`
//! then at `i`, so its recorded points are: the start, the hits on surfaces `0..=j` (the last one is the
//! first reflection), then on `j-1` down to `i` (the second reflection), then on to the sensor.

use eframe::egui;
use egui_plot::{Legend, Line, Plot, PlotPoints, Points};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::{FirstOrder, Lens, LightPath, TraceOptions, TraceStatus, Tracer, pupil_ray};

/// Rays across the pupil.
const FAN: usize = 11;

/// The traced fan, cached while the lens, the light and the ghost are unchanged.
#[derive(Default)]
pub struct RayDiagram {
    /// The stable fingerprint of what the fan was traced for (see `flare_core::fingerprint`).
    key: Option<u64>,
    rays: Vec<(Vec<[f64; 2]>, TraceStatus)>,
    reflections: Vec<[f64; 2]>,
}

impl RayDiagram {
    fn update(&mut self, lens: &Lens, fo: &FirstOrder, field_deg: f64, ghost: Option<(usize, usize)>) {
        let key = flare_core::fingerprint::of(&(lens, field_deg, ghost));
        if self.key == Some(key) {
            return;
        }
        self.key = Some(key);
        self.rays.clear();
        self.reflections.clear();
        let path = match ghost {
            Some((i, j)) => match LightPath::ghost(lens, i, j) {
                Ok(p) => p,
                Err(_) => return,
            },
            None => LightPath::image(lens),
        };
        let tracer = Tracer::new(lens, &path, D_LINE_NM, fo.sensor_z_mm());
        let theta = field_deg.to_radians();
        let pupil = fo.entrance_pupil();
        for k in 0..FAN {
            let py = -1.0 + 2.0 * k as f64 / (FAN - 1) as f64;
            let out = tracer
                .trace(&pupil_ray(&pupil, theta, 0.0, py), TraceOptions { apply_apertures: true, record_points: true });
            let mut points: Vec<[f64; 2]> = out.points_mm.iter().map(|p| [p.z, p.y]).collect();
            // Start the drawn ray in front of the lens, not at the (often virtual) entrance pupil.
            if let Some(second) = points.get(1).copied() {
                let z0 = -0.15 * fo.total_track_mm;
                points[0] = [z0, second[1] + (z0 - second[0]) * theta.tan()];
            }
            if let (Some((i, j)), TraceStatus::Landed) = (ghost, out.status) {
                for index in [1 + j, 1 + 2 * j - i] {
                    if let Some(p) = points.get(index) {
                        self.reflections.push(*p);
                    }
                }
            }
            if points.iter().all(|p| p.iter().all(|v| v.is_finite())) {
                self.rays.push((points, out.status));
            }
        }
    }
}

pub fn ray_diagram_ui(
    ui: &mut egui::Ui,
    diagram: &mut RayDiagram,
    lens: &Lens,
    fo: Option<&FirstOrder>,
    light_deg: [f64; 2],
    ghost: Option<(usize, usize)>,
) {
    let Some(fo) = fo else {
        ui.label("no ray diagram: this lens has no real focus");
        return;
    };
    let field_deg = light_deg[0].hypot(light_deg[1]);
    diagram.update(lens, fo, field_deg, ghost);
    let z = lens.vertex_z_mm();
    let h_max = lens.surfaces.iter().map(|s| s.semi_aperture_mm).fold(1.0, f64::max);
    let title = match ghost {
        Some((i, j)) => format!("ghost {i}-{j}: exact rays at {field_deg:.1} deg (reflections marked)"),
        None => format!("image path: exact rays at {field_deg:.1} deg (select a ghost to trace it)"),
    };
    ui.label(title);
    Plot::new("ray_diagram")
        .data_aspect(1.0)
        .legend(Legend::default())
        .x_axis_label("z (mm)")
        .y_axis_label("y (mm)")
        .show(ui, |plot| {
            let glass = egui::Color32::from_rgb(150, 200, 255);
            for (k, s) in lens.surfaces.iter().enumerate() {
                if s.stop {
                    for sign in [-1.0, 1.0] {
                        let pts = vec![[z[k], sign * s.semi_aperture_mm], [z[k], sign * h_max * 1.1]];
                        plot.line(
                            Line::new("stop", PlotPoints::from(pts))
                                .color(egui::Color32::from_rgb(240, 200, 80))
                                .width(3.0),
                        );
                    }
                    continue;
                }
                let pts: Vec<[f64; 2]> = (0..=40)
                    .map(|n| {
                        let h = s.semi_aperture_mm * (n as f64 / 20.0 - 1.0);
                        [z[k] + s.sag_mm(h).unwrap_or(0.0), h]
                    })
                    .collect();
                plot.line(Line::new("surfaces", PlotPoints::from(pts)).color(glass).width(1.5));
            }
            let sensor = fo.sensor_z_mm();
            plot.line(
                Line::new("sensor", PlotPoints::from(vec![[sensor, -h_max], [sensor, h_max]]))
                    .color(egui::Color32::from_gray(200))
                    .width(2.0),
            );
            for (points, status) in &diagram.rays {
                let (name, color) = match status {
                    TraceStatus::Landed => ("rays", egui::Color32::from_rgb(255, 140, 60)),
                    _ => ("stopped rays", egui::Color32::from_gray(130)),
                };
                plot.line(Line::new(name, PlotPoints::from(points.clone())).color(color).width(1.0));
            }
            if !diagram.reflections.is_empty() {
                plot.points(
                    Points::new("reflections", PlotPoints::from(diagram.reflections.clone()))
                        .radius(3.0)
                        .color(egui::Color32::from_rgb(255, 60, 200)),
                );
            }
        });
}
