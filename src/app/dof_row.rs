//! The DoF rows under the view, open by their toggle (on/off, the depth map, the focus distance or focus by click, method, cat's eye)
//! and focus by click: with it on, the next click in the view focuses on the depth under it
//! ([`flare_core::dof::DofDoc::focus_px`]). The defocus itself is `super::jobs::dof`. The rows are a function
//! of what they edit: the session (the document's depth of field) and the view (focus by click).

use eframe::egui;
use flare_core::dof::DofMethod;
use flare_core::dof::depth::PngRange;
use flare_core::image::HdrImage;

use super::files::FileUse;
use super::session::Session;
use super::view::View;

/// The DoF row under the view: on/off, the depth map, the focus (distance or click), method, cat's eye;
/// `defocusing`: a defocus is running. `Some(FileUse::DepthMap)` when the depth map's chooser was asked for.
pub(super) fn dof_ui(ui: &mut egui::Ui, session: &mut Session, view: &mut View, defocusing: bool) -> Option<FileUse> {
    let mut pick = None;
    ui.horizontal(|ui| {
        ui.checkbox(&mut session.edit().dof.enabled, "depth of field")
            .on_hover_text("defocus the plate through this lens and aperture (the flare is added after, sharp)");
        if ui.button("Depth map…").on_hover_text("EXR in metres (channel Z), or a 16-bit PNG").clicked() {
            pick = Some(FileUse::DepthMap);
        }
        match &session.doc().dof.depth {
            Some(path) => ui.weak(path.clone()),
            None => ui.weak("no depth map"),
        };
        if session.doc().dof.enabled {
            // Words, not a spinner (it would repaint the window every frame while the defocus runs).
            if defocusing {
                ui.weak("defocusing…");
            }
        }
    });
    if !session.doc().dof.enabled {
        return pick;
    }
    ui.horizontal(|ui| {
        let mut focus = session.doc().dof.focus_m;
        let r = ui.add(
            egui::Slider::new(&mut focus, 0.2..=200.0).logarithmic(true).fixed_decimals(2).suffix(" m").text("focus"),
        );
        if r.changed() {
            session.edit().dof.focus_m = focus;
            session.edit().dof.focus_px = None;
        }
        let picking = view.focus_pick();
        if ui
            .selectable_label(picking, "focus by click")
            .on_hover_text("then click in the view: the lens focuses on the depth there")
            .clicked()
        {
            view.set_focus_pick(!picking);
        }
        if let Some([x, y]) = session.doc().dof.focus_px {
            ui.weak(format!("on pixel ({x}, {y})"));
        }
        egui::ComboBox::from_label("method").selected_text(session.doc().dof.method.word()).show_ui(ui, |ui| {
            ui.selectable_value(&mut session.edit().dof.method, DofMethod::Live, "live");
            ui.selectable_value(&mut session.edit().dof.method, DofMethod::Reference, "reference");
        });
        ui.checkbox(&mut session.edit().dof.cat_eye, "cat's eye")
            .on_hover_text("cut the blur off-axis by the front lens's clear aperture");
        ui.checkbox(&mut session.edit().dof.axial_colour, "axial colour")
            .on_hover_text("R, G and B each defocused at its own wavelength, as the lens focuses them (3x the work)");
    });
    if session.doc().dof.depth.as_deref().is_some_and(|d| d.to_ascii_lowercase().ends_with(".png")) {
        ui.horizontal(|ui| {
            let range = session.edit().dof.depth_range_m.get_or_insert(PngRange { near_m: 0.5, far_m: 100.0 });
            ui.label("PNG depth: 0 is");
            ui.add(egui::DragValue::new(&mut range.near_m).range(0.01..=1e4).suffix(" m"));
            ui.label("65535 is");
            let near = range.near_m;
            ui.add(egui::DragValue::new(&mut range.far_m).range(near * 1.001..=1e6).suffix(" m"));
        });
    }
    pick
}

/// Chooses the depth map (a PNG gets a near/far range to edit) and turns the depth of field on.
pub(super) fn set_depth_map(session: &mut Session, path: &std::path::Path) {
    let text = path.display().to_string();
    if text.to_ascii_lowercase().ends_with(".png") && session.doc().dof.depth_range_m.is_none() {
        session.edit().dof.depth_range_m = Some(PngRange { near_m: 0.5, far_m: 100.0 });
        session.say("a PNG depth map: 0 is 0.5 m and 65535 is 100 m until you edit the range");
    }
    session.edit().dof.depth = Some(text);
    session.edit().dof.enabled = true;
}

/// Focus by click: the pixel of the sharp `plate` under `pointer` in the view `rect` (`None`: no plate, said).
pub(super) fn focus_at(
    session: &mut Session,
    view: &mut View,
    plate: Option<&HdrImage>,
    pointer: egui::Pos2,
    rect: egui::Rect,
) {
    view.set_focus_pick(false);
    let Some(plate) = plate else {
        session.say("focus by click needs a plate (File > Background plate)");
        return;
    };
    let [x, y] = super::view::image_pixel_at(rect, pointer, plate.width, plate.height);
    session.edit().dof.focus_px = Some([x, y]);
    session.say(format!("focus on the depth at plate pixel ({x}, {y})"));
}
