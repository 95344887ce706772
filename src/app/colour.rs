//! The colour row under the view: how the frame is displayed (the OCIO display and view, or one of
//! FlareLab's own curves), the config, looks, a `.cube`, and the plates' input space, written into the
//! document's `color` only once they resolve ([`flare_core::view_transform::ViewTransform::cached`]): a
//! name the config lacks or a file that cannot be read is said in the status line and the document keeps
//! the last valid settings. Functions of what they edit: the session (the document) and the row's own text
//! fields.

use flare_core::color::Tonemap;
use flare_core::view_transform::{ColorDoc, DISPLAY_INPUT, ViewTransform};

use super::session::Session;

/// What the colour row's text fields hold until applied (UI state: never in the document).
#[derive(Default)]
pub struct ColourFields {
    /// An OCIO config's path or `ocio://NAME`.
    pub config: String,
    /// A `.cube` file's path.
    pub cube: String,
}

/// Writes `color` into the document when it resolves; else says why and keeps the document as it is.
pub fn set_color(session: &mut Session, color: ColorDoc) {
    if color == session.doc().color {
        return;
    }
    match ViewTransform::cached(&color) {
        Ok(_) => session.edit().color = color,
        Err(e) => session.say(format!("colour: {e}; the last valid colour settings are kept")),
    }
}

/// The colour row (see the module documentation).
pub(super) fn colour_ui(ui: &mut egui::Ui, session: &mut Session, fields: &mut ColourFields) {
    let color = session.doc().color.clone();
    let Ok(view) = session.doc().view_transform() else {
        ui.label("colour: the document's settings do not resolve");
        return;
    };
    let mut next = color.clone();
    let tonemap = session.doc().tonemap;
    ui.horizontal_wrapped(|ui| {
        let label = |t: Tonemap| match t {
            Tonemap::View => "OCIO view".to_owned(),
            other => format!("{} + sRGB", other.name()),
        };
        egui::ComboBox::from_label("display with").selected_text(label(tonemap)).show_ui(ui, |ui| {
            for t in Tonemap::ALL {
                ui.selectable_value(&mut session.edit().tonemap, t, label(t));
            }
        })
        .response
        .on_hover_text("the OCIO display and view of the config, or one of FlareLab's curves (they bypass the view and its looks)");
        if tonemap == Tonemap::View {
            let mut display = view.display.clone();
            egui::ComboBox::from_label("display").selected_text(&display).width(120.0).show_ui(ui, |ui| {
                for d in &view.menus.displays {
                    ui.selectable_value(&mut display, d.clone(), d);
                }
            });
            if display != view.display {
                // Another display: its own default view.
                next.display = Some(display);
                next.view = None;
            }
            let mut chosen = view.view.clone();
            egui::ComboBox::from_label("view").selected_text(&chosen).width(200.0).show_ui(ui, |ui| {
                for v in &view.menus.views {
                    ui.selectable_value(&mut chosen, v.clone(), v);
                }
            });
            if chosen != view.view {
                next.view = Some(chosen);
            }
            let mut look = color.looks.clone().unwrap_or_default();
            egui::ComboBox::from_label("look").selected_text(if look.is_empty() { "none" } else { &look }).show_ui(ui, |ui| {
                ui.selectable_value(&mut look, String::new(), "none");
                for l in &view.menus.looks {
                    ui.selectable_value(&mut look, l.clone(), l);
                }
            });
            next.looks = (!look.is_empty()).then_some(look);
        }
    });
    ui.horizontal_wrapped(|ui| {
        let mut input = color.input_space.clone();
        let name = |i: &Option<String>| i.clone().unwrap_or_else(|| "by file type".into());
        egui::ComboBox::from_label("plates in")
            .selected_text(name(&input))
            .width(120.0)
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut input, None, "by file type (PNG sRGB, EXR linear)");
                ui.selectable_value(
                    &mut input,
                    Some(DISPLAY_INPUT.to_owned()),
                    "display (inverse of the view: as shot)",
                );
                for s in &view.menus.spaces {
                    ui.selectable_value(&mut input, Some(s.clone()), s);
                }
            })
            .response
            .on_hover_text("the colour space of the plate files");
        next.input_space = input;
        ui.add(egui::TextEdit::singleline(&mut fields.cube).hint_text("look.cube").desired_width(100.0));
        if ui.button("Apply cube").clicked() {
            let cube = fields.cube.trim();
            next.cube = (!cube.is_empty()).then(|| cube.to_owned());
        }
        ui.add(
            egui::TextEdit::singleline(&mut fields.config)
                .hint_text(flare_core::view_transform::DEFAULT_CONFIG)
                .desired_width(150.0),
        );
        if ui.button("Use config").on_hover_text("an .ocio/.ocioz file or ocio://NAME; empty: the built-in").clicked() {
            let config = fields.config.trim();
            next.config = (!config.is_empty()).then(|| config.to_owned());
            next.display = None;
            next.view = None;
            next.looks = None;
        }
    });
    set_color(session, next);
}
