//! The Looks panel's UI and applying a look (see [`super::jobs::looks`]): functions of what they edit, the
//! thumbnails' state and the session (a look is one undo step).

use eframe::egui;
use flare_core::preset::shipped;

use super::jobs::looks::{Looks, THUMB};
use super::session::Session;

/// The Looks panel (see the module documentation).
pub(super) fn looks_ui(ui: &mut egui::Ui, looks: &mut Looks, session: &mut Session) {
    looks.start();
    if looks.poll(ui.ctx()) {
        ui.ctx().request_repaint_after(super::jobs::job::PROGRESS_REPAINT);
        if let Some((fraction, text)) = looks.progress() {
            ui.horizontal(|ui| {
                ui.add(egui::ProgressBar::new(fraction).text(text).desired_width(ui.available_width() - 70.0));
                if ui.button("Cancel").clicked() {
                    looks.cancel();
                }
            });
        }
    } else if looks.cancelled && !looks.ready() {
        ui.horizontal_wrapped(|ui| {
            ui.label("The thumbnails were cancelled.");
            if ui.button("Render the rest").clicked() {
                looks.resume();
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
                let response = match looks.thumbnails.get(k).cloned().flatten() {
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
        apply_look(session, k);
    }
}

/// Applies shipped look `k` (one undo step).
pub fn apply_look(session: &mut Session, k: usize) {
    let Some(preset) = shipped().get(k) else { return };
    match preset.document() {
        Ok(look) => {
            let look_doc = session.doc().with_look(&look);
            *session.edit() = look_doc;
            session.say(format!("look: {} ({})", preset.name, preset.title));
        }
        Err(e) => session.say(format!("look {}: {e}", preset.name)),
    }
}
