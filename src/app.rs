//! The desktop app (eframe + egui): opens on the built-in default lens and shows its cross-section to
//! scale with a fan of exact rays at an adjustable field angle, its first-order data and its surfaces.
//! The live flare viewport and the editing panels build on this window.

use anyhow::{Result, bail};
use eframe::egui;
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::library::{DEFAULT_LENS_ID, builtin_lens, ids};
use flare_core::optics::{FirstOrder, Lens, LightPath, TraceOptions, TraceStatus, Tracer, pupil_ray};

const NO_DISPLAY: &str = "no display to open the app's window on (DISPLAY and WAYLAND_DISPLAY are unset). \
The command line works without one: `flarelab lens list`, `flarelab lens info LENS`, \
`flarelab trace LENS --field-deg T --pupil PX,PY [--ghost I,J]`; see `flarelab --help`";

/// Opens the app window; without a display, explains how to use the command line instead.
pub fn run() -> Result<()> {
    if cfg!(target_os = "linux")
        && std::env::var_os("DISPLAY").is_none()
        && std::env::var_os("WAYLAND_DISPLAY").is_none()
    {
        bail!(NO_DISPLAY);
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size([1280.0, 800.0]).with_title("FlareLab"),
        ..Default::default()
    };
    let result = eframe::run_native("FlareLab", options, Box::new(|_cc| Ok(Box::new(FlareLabApp::new()))));
    if let Err(e) = result {
        bail!("could not open the app's window ({e}). The command line works without one: see `flarelab --help`");
    }
    Ok(())
}

struct FlareLabApp {
    lens_id: String,
    lens: Lens,
    first_order: Option<FirstOrder>,
    field_deg: f64,
    rays: Vec<(Vec<[f64; 2]>, TraceStatus)>,
}

impl FlareLabApp {
    fn new() -> Self {
        let lens = builtin_lens(DEFAULT_LENS_ID).unwrap_or_else(|_| flare_core::optics::library::default_lens());
        let mut app =
            Self { lens_id: DEFAULT_LENS_ID.to_owned(), first_order: None, lens, field_deg: 10.0, rays: Vec::new() };
        app.rebuild();
        app
    }

    /// Recomputes first-order data and the ray fan after the lens or the field angle changed.
    fn rebuild(&mut self) {
        self.first_order = FirstOrder::d_line(&self.lens).ok();
        self.rays.clear();
        let Some(fo) = &self.first_order else { return };
        let tracer = Tracer::new(&self.lens, &LightPath::image(&self.lens), D_LINE_NM, fo.sensor_z_mm());
        for k in 0..=8 {
            let py = -1.0 + 0.25 * k as f64;
            let ray = pupil_ray(&fo.entrance_pupil(), self.field_deg.to_radians(), 0.0, py);
            let out = tracer.trace(&ray, TraceOptions { apply_apertures: true, record_points: true });
            let mut points: Vec<[f64; 2]> = out.points_mm.iter().map(|p| [p.z, p.y]).collect();
            // Start the drawn ray in front of the lens, not at the (often virtual) entrance pupil.
            if let Some(second) = points.get(1).copied() {
                let slope = self.field_deg.to_radians().tan();
                let z0 = -0.15 * fo.total_track_mm;
                points[0] = [z0, second[1] + (z0 - second[0]) * slope];
            }
            self.rays.push((points, out.status));
        }
    }

    fn lens_panel_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Lens");
        let mut chosen = self.lens_id.clone();
        egui::ComboBox::from_id_salt("lens_choice").selected_text(&chosen).show_ui(ui, |ui| {
            for id in ids() {
                ui.selectable_value(&mut chosen, id.to_owned(), id);
            }
        });
        if chosen != self.lens_id
            && let Ok(lens) = builtin_lens(&chosen)
        {
            self.lens = lens;
            self.lens_id = chosen;
            self.rebuild();
        }
        ui.label(&self.lens.name);
        ui.separator();
        if ui.add(egui::Slider::new(&mut self.field_deg, -40.0..=40.0).text("field angle (deg)")).changed() {
            self.rebuild();
        }
        ui.separator();
        match &self.first_order {
            Some(fo) => {
                egui::Grid::new("first_order").num_columns(2).striped(true).show(ui, |ui| {
                    let rows = [
                        ("focal length", format!("{:.3} mm", fo.efl_mm)),
                        ("f-number", format!("f/{:.2}", fo.f_number)),
                        ("back focal distance", format!("{:.3} mm", fo.bfd_mm)),
                        (
                            "entrance pupil",
                            format!("{:.3} mm at z = {:.3} mm", fo.entrance_pupil_diameter_mm, fo.entrance_pupil_z_mm),
                        ),
                        ("surfaces", format!("{} (stop: {})", self.lens.surfaces.len(), fo.stop_surface)),
                        ("two-reflection ghosts", self.lens.ghost_pairs().len().to_string()),
                    ];
                    for (label, value) in rows {
                        ui.label(label);
                        ui.label(value);
                        ui.end_row();
                    }
                });
            }
            None => {
                ui.colored_label(egui::Color32::LIGHT_RED, "this lens has no real focus");
            }
        }
        ui.separator();
        egui::ScrollArea::vertical().show(ui, |ui| {
            egui::Grid::new("surfaces").num_columns(5).striped(true).show(ui, |ui| {
                for h in ["#", "radius", "thickness", "nd", "semi-ap"] {
                    ui.strong(h);
                }
                ui.end_row();
                for (k, s) in self.lens.surfaces.iter().enumerate() {
                    ui.label(if s.stop { format!("{k} stop") } else { k.to_string() });
                    ui.label(if s.is_flat() { "flat".to_owned() } else { format!("{:.3}", s.radius_mm) });
                    ui.label(s.thickness_mm.map(|t| format!("{t:.3}")).unwrap_or_else(|| "-".into()));
                    ui.label(format!("{:.4}", s.medium.n_d));
                    ui.label(format!("{:.2}", s.semi_aperture_mm));
                    ui.end_row();
                }
            });
        });
    }

    fn cross_section_ui(&self, ui: &mut egui::Ui) {
        let (response, painter) = ui.allocate_painter(ui.available_size(), egui::Sense::hover());
        let rect = response.rect;
        painter.rect_filled(rect, 0.0, egui::Color32::from_gray(18));
        let Some(fo) = &self.first_order else { return };
        let z = self.lens.vertex_z_mm();
        let z_min = -0.15 * fo.total_track_mm;
        let z_max = fo.total_track_mm * 1.03;
        let h_max = self.lens.surfaces.iter().map(|s| s.semi_aperture_mm).fold(1.0, f64::max) * 1.6;
        let scale = ((rect.width() as f64 - 40.0) / (z_max - z_min)).min((rect.height() as f64 - 40.0) / (2.0 * h_max));
        let to_screen = |zz: f64, y: f64| {
            egui::pos2(rect.left() + 20.0 + ((zz - z_min) * scale) as f32, rect.center().y - (y * scale) as f32)
        };
        painter.line_segment(
            [to_screen(z_min, 0.0), to_screen(z_max, 0.0)],
            egui::Stroke::new(1.0, egui::Color32::from_gray(70)),
        );
        let glass = egui::Stroke::new(1.5, egui::Color32::from_rgb(150, 200, 255));
        for (k, s) in self.lens.surfaces.iter().enumerate() {
            if s.stop {
                let stroke = egui::Stroke::new(3.0, egui::Color32::from_rgb(240, 200, 80));
                for sign in [-1.0, 1.0] {
                    painter.line_segment(
                        [to_screen(z[k], sign * s.semi_aperture_mm), to_screen(z[k], sign * h_max * 0.8)],
                        stroke,
                    );
                }
                continue;
            }
            let points: Vec<egui::Pos2> = (0..=40)
                .map(|i| {
                    let h = s.semi_aperture_mm * (i as f64 / 20.0 - 1.0);
                    to_screen(z[k] + s.sag_mm(h).unwrap_or(0.0), h)
                })
                .collect();
            painter.add(egui::Shape::line(points, glass));
        }
        let sensor = fo.sensor_z_mm();
        painter.line_segment(
            [to_screen(sensor, -h_max * 0.9), to_screen(sensor, h_max * 0.9)],
            egui::Stroke::new(2.0, egui::Color32::from_gray(200)),
        );
        for (points, status) in &self.rays {
            let color = match status {
                TraceStatus::Landed => egui::Color32::from_rgba_unmultiplied(255, 120, 60, 200),
                _ => egui::Color32::from_rgba_unmultiplied(160, 160, 160, 120),
            };
            let pts: Vec<egui::Pos2> = points.iter().map(|p| to_screen(p[0], p[1])).collect();
            painter.add(egui::Shape::line(pts, egui::Stroke::new(1.0, color)));
        }
        painter.text(
            rect.left_top() + egui::vec2(10.0, 10.0),
            egui::Align2::LEFT_TOP,
            format!("{}: exact rays at {:.1} deg, sensor at the paraxial focus", self.lens.id, self.field_deg),
            egui::FontId::proportional(14.0),
            egui::Color32::from_gray(220),
        );
    }
}

impl eframe::App for FlareLabApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        egui::Panel::left("lens_panel").default_size(330.0).resizable(true).show(ui, |ui| self.lens_panel_ui(ui));
        egui::CentralPanel::default().show(ui, |ui| self.cross_section_ui(ui));
    }
}
