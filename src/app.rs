//! The desktop app (eframe + egui): opens on the built-in default lens with its flare, rendered by
//! `flare_core`'s wgpu renderer into a texture that egui shows; click or drag in the image (or use the arrow
//! keys) to move the light. Below it, the lens cross-section to scale with a fan of exact rays; on the left
//! the lens choice, first-order data, aperture, coating and exposure. The flare is re-rendered only when
//! something changed, and the status bar reports the last frame's time and the culling counts.

use anyhow::{Result, bail};
use eframe::{egui, egui_wgpu, wgpu};
use flare_core::aperture::ApertureShape;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::ghost::FrameStats;
use flare_core::optics::Coating;
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::library::{DEFAULT_LENS_ID, builtin_lens, ids};
use flare_core::optics::{FirstOrder, Lens, LightPath, TraceOptions, TraceStatus, Tracer, pupil_ray};
use flare_core::render::gpu::FlareRenderer;

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
    let result = eframe::run_native(
        "FlareLab",
        options,
        Box::new(|cc| Ok(Box::new(FlareLabApp::new(cc.wgpu_render_state.clone())))),
    );
    if let Err(e) = result {
        bail!("could not open the app's window ({e}). The command line works without one: see `flarelab --help`");
    }
    Ok(())
}

/// Internal resolution of the flare view (shown scaled to the panel).
const VIEW_SIZE: (u32, u32) = (960, 540);
/// The view's texture format: sRGB, so that egui samples linear values.
const VIEW_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The flare view's GPU side: the renderer and the texture egui shows.
struct FlareView {
    render_state: egui_wgpu::RenderState,
    renderer: FlareRenderer,
    target: wgpu::Texture,
    texture_id: egui::TextureId,
}

impl FlareView {
    fn new(render_state: egui_wgpu::RenderState) -> Self {
        let device = &render_state.device;
        let renderer = FlareRenderer::new(device, &render_state.queue, VIEW_FORMAT);
        let target = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("flare view"),
            size: wgpu::Extent3d { width: VIEW_SIZE.0, height: VIEW_SIZE.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: VIEW_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let texture_id = render_state.renderer.write().register_native_texture(device, &view, wgpu::FilterMode::Linear);
        Self { render_state, renderer, target, texture_id }
    }
}

struct FlareLabApp {
    lens_id: String,
    lens: Lens,
    first_order: Option<FirstOrder>,
    field_deg: f64,
    rays: Vec<(Vec<[f64; 2]>, TraceStatus)>,
    /// Where the light appears in the frame (degrees, X right, Y up).
    light_deg: [f64; 2],
    config: FlareConfig,
    blades: u32,
    quarter_wave: bool,
    flare: Option<PreparedFlare>,
    view: Option<FlareView>,
    /// The flare must be rendered again (light, lens or settings changed).
    dirty: bool,
    /// The settings changed: prepare the flare again.
    stale: bool,
    last_frame_ms: f64,
    last_stats: FrameStats,
    message: Option<String>,
}

impl FlareLabApp {
    fn new(render_state: Option<egui_wgpu::RenderState>) -> Self {
        let lens = builtin_lens(DEFAULT_LENS_ID).unwrap_or_else(|_| flare_core::optics::library::default_lens());
        // On a software adapter (lavapipe, llvmpipe) frame-filling ghosts cost the most: accumulate them at
        // half resolution there.
        let software = render_state.as_ref().is_some_and(|r| r.adapter.get_info().device_type == wgpu::DeviceType::Cpu);
        let mut app = Self {
            lens_id: DEFAULT_LENS_ID.to_owned(),
            first_order: None,
            lens,
            field_deg: 10.0,
            rays: Vec::new(),
            light_deg: [6.0, 4.0],
            // Coated ghosts are ~100x dimmer than bare ones: open the exposure to match the coating default.
            config: FlareConfig {
                display: flare_core::render::DisplaySettings {
                    exposure: 1500.0,
                    accumulation_divisor: if software { 2 } else { 1 },
                    ..Default::default()
                },
                ..FlareConfig::default()
            },
            blades: 6,
            quarter_wave: true,
            flare: None,
            view: render_state.map(FlareView::new),
            dirty: true,
            stale: true,
            last_frame_ms: 0.0,
            last_stats: FrameStats::default(),
            message: None,
        };
        app.rebuild();
        app
    }

    /// Prepares the flare for the current lens and settings (on edits, not per frame).
    fn prepare_flare(&mut self) {
        self.config.aperture.shape = ApertureShape::Blades { count: self.blades, rotation_deg: 0.0, roundness: 0.0 };
        self.config.coating_override =
            self.quarter_wave.then_some(Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None });
        match PreparedFlare::new(&self.lens, &self.config) {
            Ok(flare) => {
                if let Some(view) = &mut self.view {
                    let (device, queue) = (&view.render_state.device, &view.render_state.queue);
                    view.renderer.set_aperture(device, queue, &flare.mask);
                    view.renderer.set_starburst(device, queue, &flare.starburst);
                }
                self.flare = Some(flare);
                self.message = None;
            }
            // Keep the last valid flare and say why the new settings were refused.
            Err(e) => self.message = Some(e.to_string()),
        }
        self.stale = false;
        self.dirty = true;
    }

    /// Renders the flare into the view's texture when something changed.
    fn render_flare(&mut self) {
        if self.stale {
            self.prepare_flare();
        }
        let (Some(view), Some(flare)) = (&mut self.view, &self.flare) else { return };
        if !self.dirty {
            return;
        }
        let started = std::time::Instant::now();
        let (scene, frame) = flare.scene(self.light_deg, VIEW_SIZE.0, VIEW_SIZE.1);
        let (device, queue) = (&view.render_state.device, &view.render_state.queue);
        let target = view.target.create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("flare view") });
        view.renderer.render(device, queue, &mut encoder, &target, &scene);
        queue.submit(Some(encoder.finish()));
        // Wait, so that the status bar reports the whole frame (CPU and GPU).
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        self.last_frame_ms = started.elapsed().as_secs_f64() * 1e3;
        self.last_stats = frame.stats;
        self.dirty = false;
    }

    /// Puts the light where the pointer is in the flare view.
    fn light_from_pointer(&mut self, pointer: egui::Pos2, rect: egui::Rect) {
        let Some(flare) = &self.flare else { return };
        let k_px_per_mm = rect.width() as f64 / flare.frame_settings(VIEW_SIZE.0, VIEW_SIZE.1).sensor.width_mm;
        let x_mm = (pointer.x - rect.center().x) as f64 / k_px_per_mm;
        let y_mm = (rect.center().y - pointer.y) as f64 / k_px_per_mm;
        // The light images at (sensor mm per unit slope) x tan(angle); the display is the sensor turned round.
        let per_slope = flare.system.light_image_mm([1.0, 0.0])[0];
        if per_slope.abs() > 1e-9 {
            self.light_deg = [(x_mm / per_slope).atan().to_degrees(), (y_mm / per_slope).atan().to_degrees()];
            self.dirty = true;
        }
    }

    fn flare_view_ui(&mut self, ui: &mut egui::Ui) {
        let Some(view) = &self.view else {
            ui.label("No wgpu device: the flare view needs the wgpu renderer (the command line renders on the CPU).");
            return;
        };
        let width = ui.available_width();
        let height = (width * VIEW_SIZE.1 as f32 / VIEW_SIZE.0 as f32).min(ui.available_height() * 0.62);
        let size = egui::vec2(height * VIEW_SIZE.0 as f32 / VIEW_SIZE.1 as f32, height);
        let image = egui::Image::from_texture((view.texture_id, size)).sense(egui::Sense::click_and_drag());
        let response = ui.add(image);
        if (response.dragged() || response.clicked())
            && let Some(pointer) = response.interact_pointer_pos()
        {
            self.light_from_pointer(pointer, response.rect);
        }
        let step = 0.5;
        ui.input(|i| {
            for (key, dx, dy) in [
                (egui::Key::ArrowLeft, -step, 0.0),
                (egui::Key::ArrowRight, step, 0.0),
                (egui::Key::ArrowUp, 0.0, step),
                (egui::Key::ArrowDown, 0.0, -step),
            ] {
                if i.key_pressed(key) {
                    self.light_deg[0] = (self.light_deg[0] + dx).clamp(-85.0, 85.0);
                    self.light_deg[1] = (self.light_deg[1] + dy).clamp(-85.0, 85.0);
                    self.dirty = true;
                }
            }
        });
    }

    fn flare_settings_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Flare");
        let mut changed = false;
        changed |= ui.add(egui::Slider::new(&mut self.blades, 3..=16).text("aperture blades")).changed();
        let nominal = self.first_order.as_ref().map_or(1.0, |fo| fo.f_number);
        let mut f_number = self.config.aperture.f_number.unwrap_or(nominal);
        if ui.add(egui::Slider::new(&mut f_number, nominal..=22.0).text("f-number")).changed() {
            self.config.aperture.f_number = Some(f_number);
            changed = true;
        }
        changed |= ui.checkbox(&mut self.quarter_wave, "quarter-wave AR coating (550 nm) on every surface").changed();
        changed |= ui
            .add(egui::Slider::new(&mut self.config.display.exposure, 1.0..=10000.0).logarithmic(true).text("exposure"))
            .changed();
        changed |= ui.checkbox(&mut self.config.display.starburst, "starburst").changed();
        if changed {
            self.stale = true;
        }
        if let Some(message) = &self.message {
            ui.colored_label(egui::Color32::LIGHT_RED, message);
        }
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
            self.config.aperture.f_number = None;
            self.rebuild();
            self.stale = true;
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
        self.render_flare();
        let status = format!(
            "light ({:.1}, {:.1}) deg | last flare frame {:.1} ms at {}x{} | sprites drawn {}, culled {} dim / {} off sensor / {} empty entrance",
            self.light_deg[0],
            self.light_deg[1],
            self.last_frame_ms,
            VIEW_SIZE.0,
            VIEW_SIZE.1,
            self.last_stats.drawn,
            self.last_stats.below_threshold,
            self.last_stats.off_sensor,
            self.last_stats.empty_entrance_region
        );
        egui::Panel::bottom("status").show(ui, |ui| {
            ui.label(status);
        });
        egui::Panel::left("lens_panel").default_size(330.0).resizable(true).show(ui, |ui| {
            self.flare_settings_ui(ui);
            ui.separator();
            self.lens_panel_ui(ui);
        });
        egui::CentralPanel::default().show(ui, |ui| {
            self.flare_view_ui(ui);
            self.cross_section_ui(ui);
        });
        if self.dirty || self.stale {
            ui.ctx().request_repaint();
        }
    }
}
