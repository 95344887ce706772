//! The Looks panel's UI and applying a look (see [`super::jobs::looks`]).

use eframe::egui;
use flare_core::preset::shipped;

use super::FlareLabApp;
use super::jobs::looks::THUMB;

impl FlareLabApp {
    /// The Looks panel (see the module documentation).
    pub(super) fn looks_ui(&mut self, ui: &mut egui::Ui) {
        self.jobs.looks_mut().start();
        if self.jobs.looks_mut().poll(ui.ctx()) {
            ui.ctx().request_repaint_after(super::jobs::job::PROGRESS_REPAINT);
            if let Some((fraction, text)) = self.jobs.looks().progress() {
                ui.horizontal(|ui| {
                    ui.add(egui::ProgressBar::new(fraction).text(text).desired_width(ui.available_width() - 70.0));
                    if ui.button("Cancel").clicked() {
                        self.jobs.looks_mut().cancel();
                    }
                });
            }
        } else if self.jobs.looks().cancelled && !self.jobs.looks().ready() {
            ui.horizontal_wrapped(|ui| {
                ui.label("The thumbnails were cancelled.");
                if ui.button("Render the rest").clicked() {
                    self.jobs.looks_mut().resume();
                }
            });
        }
        ui.label("A look replaces the lens, stop, coatings, sensor and display; your plate and timeline, if you have them, stay.");
        let mut chosen = None;
        // Two thumbnails a row, shrunk to fit the panel's width.
        let width = ((ui.available_width() - 8.0) / 2.0).clamp(80.0, THUMB.0 as f32);
        let size = egui::vec2(width, width * THUMB.1 as f32 / THUMB.0 as f32);
        egui::Grid::new("looks").num_columns(2).spacing([8.0, 8.0]).show(ui, |ui| {
            for (k, preset) in shipped().iter().enumerate() {
                ui.vertical(|ui| {
                    let response = match self.jobs.looks_mut().thumbnails.get(k).cloned().flatten() {
                        Some(Ok(texture)) => {
                            ui.add(egui::Image::from_texture((texture.id(), size)).sense(egui::Sense::click()))
                        }
                        Some(Err(e)) => ui.colored_label(egui::Color32::from_rgb(255, 110, 110), e),
                        // A still placeholder: a spinner would repaint the window every frame until the
                        // thumbnails are made (31 frames a second beside a bake, 17 % of a core).
                        None => ui.add_sized(size, egui::Label::new(egui::RichText::new("rendering…").weak())),
                    };
                    let button = ui.button(preset.name).on_hover_text(preset.title);
                    if response.on_hover_text(preset.title).clicked() || button.clicked() {
                        chosen = Some(k);
                    }
                });
                if k % 2 == 1 {
                    ui.end_row();
                }
            }
        });
        if let Some(k) = chosen {
            self.apply_look(k);
        }
    }

    /// Applies shipped look `k` (one undo step).
    pub fn apply_look(&mut self, k: usize) {
        let Some(preset) = shipped().get(k) else { return };
        match preset.document() {
            Ok(look) => {
                let look_doc = self.session.doc().with_look(&look);
                *self.session.edit() = look_doc;
                self.session.say(format!("look: {} ({})", preset.name, preset.title));
            }
            Err(e) => self.session.say(format!("look {}: {e}", preset.name)),
        }
    }
}
