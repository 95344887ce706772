//! Blend panel: how LUT ghosts join the paraxial flare (additive, a linear or smooth weight curve over the
//! light angle, or the alpha channel), the LUT layer's gain, the LUT source (none, simulated: baked here or
//! opened, photo: opened), and the bake with its progress bar and cancel.

use eframe::egui;

use super::{Action, BakeStatus, PanelContext};
use flare_core::preset::{Document, LutSource};

pub fn blend_ui(ui: &mut egui::Ui, doc: &mut Document, ctx: &PanelContext, actions: &mut Vec<Action>) {
    // The mode as its parts: name, and the ramp's angles for the two curves.
    let text = doc.blend.mode.clone();
    let mut parts = text.split(':');
    let mut name = parts.next().unwrap_or("additive").to_owned();
    let mut from: f64 = parts.next().and_then(|p| p.parse().ok()).unwrap_or(0.0);
    let mut to: f64 = parts.next().and_then(|p| p.parse().ok()).unwrap_or(10.0);
    egui::ComboBox::from_label("blend mode").selected_text(&name).show_ui(ui, |ui| {
        for (k, hint) in [
            ("additive", "the LUT image replaces the sprite"),
            ("linear", "sprite to LUT image, a linear weight over the light angle"),
            ("smooth", "sprite to LUT image, a smoothstep weight over the light angle"),
            ("alpha", "the LUT layer over the flare through its alpha"),
        ] {
            ui.selectable_value(&mut name, k.to_owned(), k).on_hover_text(hint);
        }
    });
    if name == "linear" || name == "smooth" {
        ui.add(egui::Slider::new(&mut from, 0.0..=60.0).text("LUT weight from (deg)"));
        ui.add(egui::Slider::new(&mut to, 0.0..=60.0).text("full LUT weight at (deg)"));
        to = to.max(from);
        doc.blend.mode = format!("{name}:{from}:{to}");
    } else {
        doc.blend.mode = name;
    }
    ui.add(egui::Slider::new(&mut doc.blend.gain, 0.0..=4.0).text("LUT gain"));
    ui.separator();
    ui.label("LUT source");
    // A document that names no LUT is served by the automatic bake while it is on: shown as "simulated".
    let shown = match &doc.blend.lut {
        LutSource::None if ctx.auto_bake => 1,
        LutSource::None => 0,
        LutSource::Simulated { .. } => 1,
        LutSource::Photo { .. } => 2,
    };
    let mut source = shown;
    ui.horizontal(|ui| {
        ui.radio_value(&mut source, 0, "none");
        ui.radio_value(&mut source, 1, "simulated");
        ui.radio_value(&mut source, 2, "photo");
    });
    match source {
        _ if source == shown => {}
        0 => {
            // Paraxial only: the automatic bake would bring the LUT back.
            doc.blend.lut = LutSource::None;
            actions.push(Action::SetAutoBake(false));
        }
        1 => {
            // LUT ghosts for this lens: baked (or fetched) by themselves again.
            doc.blend.lut = LutSource::Simulated { path: None };
            actions.push(Action::SetAutoBake(true));
        }
        _ => actions.push(Action::OpenLut),
    }
    let mut auto = ctx.auto_bake;
    if ui
        .checkbox(&mut auto, "bake LUT ghosts by themselves")
        .on_hover_text("when the lens, stop or coatings change: from the cache, else baked in the background")
        .changed()
    {
        actions.push(Action::SetAutoBake(auto));
    }
    if let Some(summary) = ctx.lut_summary {
        ui.label(summary);
    }
    ui.horizontal(|ui| {
        let running = matches!(ctx.bake, BakeStatus::Running { .. });
        if ui
            .add_enabled(!running, egui::Button::new("Bake"))
            .on_hover_text("classify and ray-trace the non-linear ghosts")
            .clicked()
        {
            actions.push(Action::Bake);
        }
        if running && ui.button("Cancel").clicked() {
            actions.push(Action::CancelBake);
        }
        if ui.button("Open LUT…").clicked() {
            actions.push(Action::OpenLut);
        }
        if ui.button("Export LUT…").clicked() {
            actions.push(Action::ExportLut);
        }
    });
    match ctx.bake {
        BakeStatus::Idle => {}
        BakeStatus::Running { fraction, text } => {
            // Not animated: an animated bar repaints the window every frame for as long as the bake runs.
            ui.add(egui::ProgressBar::new(*fraction).text(text.as_str()));
        }
        BakeStatus::Done(text) => {
            ui.label(text);
        }
        BakeStatus::Failed(text) => {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 110), text);
        }
    }
}
