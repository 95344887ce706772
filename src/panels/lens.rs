//! Lens panel: the built-in library, opening a lens file (and what loading it decided), first-order data, and the
//! interface table (radius, conic with the aspheric terms on hover, thickness, n_d / V_d, semi-aperture, stop;
//! for an anamorphic lens also each toroid's x-z radius); each row's number is a menu that adds a dummy surface
//! after it, removes it, moves it and opens its coating. A cell whose value
//! makes the lens impossible is marked with the reason; the viewport keeps the last valid lens meanwhile.

use eframe::egui;
use flare_core::optics::Surface;
use flare_core::optics::library::{builtin_lens, ids};

use super::{Action, PanelContext, labelled_check, labelled_value};
use flare_core::preset::Document;

/// The most characters of the lens's name the lens choice shows (the whole name on hover).
const NAME_CHARS: usize = 28;
/// The surface table's type size (points).
const TABLE_TEXT_PT: f32 = 12.0;
const BAD: egui::Color32 = egui::Color32::from_rgb(255, 110, 110);
const WARN: egui::Color32 = egui::Color32::from_rgb(240, 200, 90);

pub fn lens_ui(ui: &mut egui::Ui, doc: &mut Document, ctx: &PanelContext, actions: &mut Vec<Action>) {
    ui.horizontal(|ui| {
        let mut chosen = doc.lens.id.clone();
        let name = if doc.lens.name.is_empty() { doc.lens.id.clone() } else { doc.lens.name.clone() };
        // A long name is cut (whole on hover), so that the choice, its label and Open fit the panel.
        let shown = match name.char_indices().nth(NAME_CHARS) {
            Some((at, _)) => format!("{}…", name[..at].trim_end()),
            None => name.clone(),
        };
        // 200 points: the choice, its label and Open fit the panel at its least width.
        egui::ComboBox::from_label("lens")
            .selected_text(shown)
            .width(200.0)
            .show_ui(ui, |ui| {
                for id in ids() {
                    // The lens's name (its patent or source), the id on hover.
                    let name = builtin_lens(id).map(|l| l.name).unwrap_or_else(|_| id.to_owned());
                    ui.selectable_value(&mut chosen, id.to_owned(), name).on_hover_text(id);
                }
            })
            .response
            .on_hover_text(&name);
        if chosen != doc.lens.id
            && let Ok(lens) = builtin_lens(&chosen)
        {
            doc.lens = lens;
            doc.aperture.f_number = None;
            doc.ghosts.clear();
            doc.solo = None;
        }
        if ui
            .button("Open…")
            .on_hover_text("a lens file: .json, .zmx (Zemax), .dat (pbrt), .lens (FlareSim), .xml (OpenLensFlare)")
            .clicked()
        {
            actions.push(Action::OpenLensFile);
        }
    });
    for warning in ctx.lens_warnings {
        ui.colored_label(WARN, format!("(i) {warning}"));
    }
    // One line, always there: the lens's first-order data, or why an edit is refused (one line, the whole
    // reason on hover and on the cell's red frame). The table below never moves when a value is refused, so
    // the next click lands on the row the user aimed at.
    match (ctx.lens_problem, ctx.first_order) {
        (Some(problem), _) => {
            let text = format!("(!) {} (the view shows the last valid lens)", problem.reason);
            ui.add(egui::Label::new(egui::RichText::new(&text).color(BAD)).truncate()).on_hover_text(&text);
        }
        (None, Some(fo)) => {
            // An anamorphic lens: the y-z section's focal length, then the x-z section's and the squeeze (one line,
            // so the table below does not move).
            let sections = fo.sections.as_ref().map_or(String::new(), |both| {
                format!(", f_x = {:.2} mm (squeeze {:.3})", both[0].efl_mm, both[1].efl_mm / both[0].efl_mm)
            });
            // One line at any panel width (cut, whole on hover), as the refusal's.
            let text = format!(
                "f = {:.2} mm{sections}, f/{:.2}, BFD {:.2} mm, {} surfaces, {} ghosts",
                fo.efl_mm,
                fo.f_number,
                fo.bfd_mm,
                doc.lens.surfaces.len(),
                doc.lens.ghost_pairs().len()
            );
            ui.add(egui::Label::new(&text).truncate()).on_hover_text(&text);
        }
        (None, None) => {
            ui.label("");
        }
    }
    surface_table_ui(ui, doc, ctx, actions);
}

fn surface_table_ui(ui: &mut egui::Ui, doc: &mut Document, ctx: &PanelContext, actions: &mut Vec<Action>) {
    let problem = ctx.lens_problem;
    let bad_cell = |k: usize, field: &str| {
        problem.filter(|p| p.surface == Some(k) && p.field.is_some_and(|f| f == field)).map(|p| p.reason.clone())
    };
    let mut edit: Option<RowEdit> = None;
    // The table takes the panel's height below the summary (the panel itself scrolls sideways if narrow).
    let height = ui.available_height().max(200.0);
    // An anamorphic lens shows its toroids' x-z radii (Zemax's radius of rotation) beside the profile's radius.
    let anamorphic = doc.lens.is_anamorphic();
    egui::ScrollArea::vertical().id_salt("surfaces").max_height(height).show(ui, |ui| {
        // Cells as wide as their values, so the table fits the side panel at its least width: the row's moves and
        // its coating are in the menu under its number.
        super::compact_cells(ui);
        ui.spacing_mut().button_padding = egui::vec2(2.0, 1.0);
        // A table's type, a little smaller than the panels' (12 points for 14): the numbers stay legible.
        for style in [egui::TextStyle::Body, egui::TextStyle::Button] {
            if let Some(font) = ui.style_mut().text_styles.get_mut(&style) {
                font.size = TABLE_TEXT_PT;
            }
        }
        let columns = 8 + usize::from(anamorphic);
        egui::Grid::new("surface_table").num_columns(columns).striped(true).spacing([4.0, 2.0]).show(ui, |ui| {
            for (h, hover) in SURFACE_COLUMNS {
                if h != "radius x" || anamorphic {
                    ui.strong(h).on_hover_text(hover);
                }
            }
            ui.end_row();
            let count = doc.lens.surfaces.len();
            let doc_override = doc.coating_override.clone();
            for (k, s) in doc.lens.surfaces.iter_mut().enumerate() {
                // The row's number opens its menu: moves, and the coating in use (edited in the Coatings panel).
                let coating = doc_override.as_ref().unwrap_or(&s.coating);
                let coating_item = match doc_override {
                    Some(_) => format!("coating: {} on every surface…", super::coatings::kind(coating)),
                    None => format!("coating: {}…", super::coatings::kind(coating)),
                };
                row_menu_ui(ui, k, count, &coating_item, &mut edit, actions);
                let cell = |ui: &mut egui::Ui, value: &mut f64, field: &'static str, label: &str, speed: f64| {
                    value_cell(ui, value, (field, &format!("{label} {k}")), speed, bad_cell(k, field));
                };
                cell(ui, &mut s.radius_mm, "radius", "radius", 0.1);
                if anamorphic {
                    match &mut s.radius_x_mm {
                        Some(r) => {
                            let response = ui.scope(|ui| cell(ui, r, "radius_x", "radius x", 0.1)).response;
                            response.on_hover_text(
                                "the toroid's x-z radius (0: flat in x); the radius and conic are its y-z profile",
                            );
                        }
                        None => {
                            ui.label("=").on_hover_text("a surface of revolution: the same radius in x");
                        }
                    }
                }
                // The conic constant; the even aspheric terms (read from the file) on hover.
                let terms = aspheric_terms(s);
                let bad_terms = bad_cell(k, "aspheric");
                let response = ui.scope(|ui| cell(ui, &mut s.conic, "conic", "conic", 0.01)).response;
                response.on_hover_text(match bad_terms {
                    Some(reason) => format!("{terms}\n(!) {reason}"),
                    None => terms,
                });
                let mut t = s.thickness_mm.unwrap_or(0.0);
                cell(ui, &mut t, "thickness", "thickness", 0.05);
                if s.thickness_mm.is_some() || t != 0.0 {
                    s.thickness_mm = Some(t);
                }
                let (glass, n_before) = (s.medium.glass.clone(), s.medium.n_d);
                let hover = glass.unwrap_or_else(|| "no catalogue glass: n_d and V_d as given".into());
                ui.scope(|ui| cell(ui, &mut s.medium.n_d, "nd", "nd", 0.001)).response.on_hover_text(hover);
                if s.medium.n_d != n_before && !s.medium.is_air() {
                    // An edited index is no longer the catalogue glass.
                    s.medium.glass = None;
                }
                let mut v = s.medium.v_d.unwrap_or(0.0);
                cell(ui, &mut v, "vd", "Vd", 0.1);
                s.medium.v_d = (v > 0.0).then_some(v);
                cell(ui, &mut s.semi_aperture_mm, "semi_aperture", "semi-aperture", 0.05);
                let stop = s.stop;
                labelled_check(ui.checkbox(&mut s.stop, ""), &format!("stop {k}"), stop);
                ui.end_row();
            }
        });
    });
    match edit {
        Some(RowEdit::Swap(a, b)) => doc.lens.surfaces.swap(a, b),
        Some(RowEdit::InsertAfter(k)) => {
            // A dummy surface, one medium on both sides (`Lens::insert_dummy_after`): optically nothing changes.
            if let Err(reason) = doc.lens.insert_dummy_after(k) {
                actions.push(Action::Message(reason));
            }
        }
        Some(RowEdit::Remove(k)) => {
            // Every other surface stays where it was (`Lens::remove_surface`).
            if let Err(reason) = doc.lens.remove_surface(k) {
                actions.push(Action::Message(reason));
            }
        }
        _ => {}
    }
}

/// The surface table's columns and what each says ("radius x" only for an anamorphic lens).
const SURFACE_COLUMNS: [(&str, &str); 9] = [
    ("#", "the surface (its menu: add a dummy surface after it, remove it, move it, its coating)"),
    ("radius", "the radius of curvature, mm (0: flat; + centre behind)"),
    ("radius x", "the toroid's x-z radius, mm"),
    ("conic", "the conic constant (the aspheric terms on the cell's hover)"),
    ("thick", "the thickness to the next surface along the axis, mm"),
    ("nd", "the refractive index after the surface, at the d line"),
    ("Vd", "the Abbe number after the surface (blank: no dispersion)"),
    ("semi-ap", "the clear semi-aperture, mm"),
    ("stop", "the aperture stop"),
];

/// Row `k`'s menu under its number (of `count` rows): a dummy surface after it, its removal, its moves and
/// `coating_item`, which opens the Coatings panel.
fn row_menu_ui(
    ui: &mut egui::Ui,
    k: usize,
    count: usize,
    coating_item: &str,
    edit: &mut Option<RowEdit>,
    actions: &mut Vec<Action>,
) {
    ui.menu_button(k.to_string(), |ui| {
        if ui
            .button("+ dummy surface after")
            .on_hover_text("split the gap after this surface with a dummy surface, one medium on both sides (changes nothing optically: the LUT ghosts stay; removing it gives back the lens)")
            .clicked()
        {
            *edit = Some(RowEdit::InsertAfter(k));
        }
        if ui
            .add_enabled(count > 1, egui::Button::new("x remove"))
            .on_hover_text("remove this surface (the others stay where they are)")
            .clicked()
        {
            *edit = Some(RowEdit::Remove(k));
        }
        ui.separator();
        if ui.add_enabled(k > 0, egui::Button::new("move up")).clicked() {
            *edit = Some(RowEdit::Swap(k - 1, k));
        }
        if ui.add_enabled(k + 1 < count, egui::Button::new("move down")).clicked() {
            *edit = Some(RowEdit::Swap(k, k + 1));
        }
        if ui.button(coating_item).on_hover_text("edit in the Coatings panel").clicked() {
            actions.push(Action::EditCoating(k));
        }
    })
    .response
    .on_hover_text(format!("surface {k}: add a dummy surface after it, remove it, move it, its coating"));
}

/// One number of the table: `field` of the surface, its accessible `name`, dragged by `speed` a point, marked
/// with `bad`'s reason where the lens's problem is this cell.
fn value_cell(ui: &mut egui::Ui, value: &mut f64, (field, name): (&str, &str), speed: f64, bad: Option<String>) {
    // A typed value applies on Enter or when the cell loses focus, so a refused intermediate value
    // ("-1" on the way to "-12") never reaches the lens; Escape gives back the value the edit
    // started from (egui's DragValue would apply the typed text on the frame after Escape: the
    // value is put back then).
    let before = *value;
    let mut drag = egui::DragValue::new(&mut *value).speed(speed).max_decimals(4).update_while_editing(false);
    if field == "vd" {
        // An unknown Abbe number (0 here: dispersion assumed) shows blank, not as 0.0.
        drag = drag.custom_formatter(|v, _| if v > 0.0 { format!("{v:.1}") } else { String::new() });
    }
    if bad.is_some() {
        drag = drag.prefix("! ");
    }
    let response = labelled_value(ui.add(drag), name, *value);
    // While typing nothing applies, so the value before this frame is the one the edit started
    // from.
    let revert = response.id.with("revert");
    let escaped = ui.input(|i| i.key_pressed(egui::Key::Escape));
    if escaped && response.lost_focus() {
        ui.data_mut(|d| d.insert_temp(revert, before));
    } else if !escaped && let Some(v) = ui.data_mut(|d| d.remove_temp::<f64>(revert)) {
        *value = v;
    }
    if let Some(reason) = bad {
        ui.painter().rect_stroke(response.rect, 2.0, egui::Stroke::new(1.5, BAD), egui::StrokeKind::Outside);
        response.on_hover_text(reason);
    }
}

/// The surface's even aspheric terms, as the conic cell's hover says them.
fn aspheric_terms(s: &Surface) -> String {
    if s.aspheric_r2 == 0.0 && s.aspheric.is_empty() {
        return "no aspheric terms".to_owned();
    }
    let mut t = format!("A2 {:e}", s.aspheric_r2);
    for (i, a) in s.aspheric.iter().enumerate() {
        t.push_str(&format!(", A{} {a:e}", 2 * i + 4));
    }
    t
}

enum RowEdit {
    Swap(usize, usize),
    InsertAfter(usize),
    Remove(usize),
}
