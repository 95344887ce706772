//! Ghosts panel: every ghost sorted by brightness (surface pair, colour swatch, intensity, linear or
//! non-linear when the LUT classification ran, culled and why), with a toggle, solo and gain per ghost.
//! Clicking a row selects the ghost: the viewport rings it and the ray diagram traces it.

use eframe::egui;

use super::{Action, PanelContext, labelled_check, labelled_value};
use flare_core::preset::{Document, ghost_key};

pub fn ghosts_ui(ui: &mut egui::Ui, doc: &mut Document, ctx: &PanelContext, actions: &mut Vec<Action>) {
    let mut rows: Vec<_> = ctx.ghosts.iter().collect();
    rows.sort_by(|a, b| b.intensity().total_cmp(&a.intensity()));
    let brightest = rows.first().map_or(1.0, |r| r.intensity()).max(1e-30);
    let drawn = rows.iter().filter(|r| r.culled.is_none()).count();
    ui.horizontal(|ui| {
        ui.label(format!("{} ghosts, {drawn} drawn", rows.len()));
        if doc.solo.is_some() && ui.button("un-solo").clicked() {
            doc.solo = None;
        }
        if ui.button("all on").clicked() {
            doc.ghosts.clear();
            doc.solo = None;
        }
    });
    // The list takes the whole panel below its header.
    let height = ui.available_height().max(200.0);
    egui::ScrollArea::vertical().id_salt("ghost_list").max_height(height).auto_shrink([false, false]).show(ui, |ui| {
        // Cells as wide as their content and short words (the whole on hover), so the table fits the side panel at
        // its least width.
        super::compact_cells(ui);
        egui::Grid::new("ghost_table").num_columns(7).striped(true).spacing([6.0, 2.0]).show(ui, |ui| {
            let headers = [
                ("on", "drawn or not"),
                ("pair", "the two reflecting surfaces (click: select the ghost)"),
                ("", ""),
                ("level", "its light against the brightest ghost's (the irradiance on hover)"),
                ("kind", "how it is drawn (why, on hover)"),
                ("gain", "the artist's gain on its light"),
                ("", ""),
            ];
            for (h, hover) in headers {
                ui.strong(h).on_hover_text(hover);
            }
            ui.end_row();
            for row in rows {
                let key = ghost_key(row.i, row.j);
                let mut enabled = doc.ghosts.get(&key).is_none_or(|g| g.enabled);
                if labelled_check(ui.checkbox(&mut enabled, ""), &format!("ghost {key}"), enabled).changed() {
                    doc.ghost_mut(row.i, row.j).enabled = enabled;
                }
                let selected = ctx.selected == Some(row.ghost);
                if ui.selectable_label(selected, &key).clicked() {
                    actions.push(Action::SelectGhost(if selected { None } else { Some(row.ghost) }));
                }
                let peak = row.rgb.iter().copied().fold(0.0, f64::max).max(1e-30);
                let swatch = egui::Color32::from_rgb(
                    (255.0 * row.rgb[0] / peak) as u8,
                    (255.0 * row.rgb[1] / peak) as u8,
                    (255.0 * row.rgb[2] / peak) as u8,
                );
                let (rect, _) = ui.allocate_exact_size(egui::vec2(14.0, 14.0), egui::Sense::hover());
                ui.painter().rect_filled(rect, 2.0, swatch);
                let db = 10.0 * (row.intensity() / brightest).max(1e-12).log10();
                ui.label(format!("{db:.0} dB")).on_hover_text(format!("relative irradiance {:.2e}", row.intensity()));
                let (short, kind) = kind_words(ctx, row.ghost);
                match row.culled {
                    Some(reason) => {
                        ui.weak("culled").on_hover_text(format!("{kind}; culled: {}", culled_words(reason)))
                    }
                    None => ui.label(short).on_hover_text(kind),
                };
                let mut gain = doc.ghosts.get(&key).map_or(1.0, |g| g.gain);
                let r = ui.add(egui::DragValue::new(&mut gain).range(0.0..=100.0).speed(0.02).max_decimals(2));
                if labelled_value(r, &format!("gain {key}"), gain).changed() {
                    doc.ghost_mut(row.i, row.j).gain = gain;
                }
                let solo = doc.solo.as_deref() == Some(key.as_str());
                if ui.selectable_label(solo, "solo").clicked() {
                    doc.solo = if solo { None } else { Some(key.clone()) };
                }
                ui.end_row();
            }
        });
    });
}

/// The kind column: a word for the table and the words for its hover (how the ghost is drawn and why).
pub fn kind_words(ctx: &PanelContext, ghost: usize) -> (&'static str, &'static str) {
    let baked = ctx.lut.is_some_and(|lut| {
        lut.kind == flare_core::lut::LutKind::RayTraced && lut.ghosts.iter().any(|g| g.ghost as usize == ghost)
    });
    match ctx.classes.and_then(|c| c.get(ghost)) {
        _ if baked => ("baked", "non-linear: drawn from the LUT (ray-traced)"),
        Some(c) if c.nonlinear() => ("non-linear", "non-linear, drawn paraxial until its LUT entries are baked"),
        Some(c) if c.faint => ("faint", "non-linear, too faint to bake: drawn paraxial"),
        Some(_) => ("linear", "linear: the paraxial sprite is exact enough"),
        None => ("paraxial", "paraxial (not classified: no LUT baked in this session)"),
    }
}

/// Why a ghost is not drawn, in words.
pub fn culled_words(reason: &str) -> &'static str {
    match reason {
        "below_threshold" => "too dim",
        "off_sensor" => "off the frame",
        "empty_entrance_region" => "no light gets through",
        _ => "no sprite",
    }
}
