//! The Report tab: the ghost report of the frame shown (see [`super::jobs::report`]) as a sortable table, the
//! coating sensitivity, and the export to CSV or JSON. Functions of what they edit: the report's state (its job,
//! its order) and the session (the ghost selected); the file chooser is asked for through the answer.

use eframe::egui;
use flare_core::files::write_atomic;
use flare_core::report::{GhostReport, GhostRow, to_csv};

use std::sync::Arc;

use flare_core::flare::PreparedFlare;

use super::files::FileUse;
use super::jobs::report::{ReportColumn, ReportKey, ReportState};
use super::session::Session;

/// The Report tab (see the module documentation) for `flare` (`None`: no valid lens) with the light at `light`
/// degrees; `Some(FileUse::ExportReport)` when Export was clicked (the caller opens the file chooser).
pub(super) fn report_ui(
    ui: &mut egui::Ui,
    state: &mut ReportState,
    session: &mut Session,
    flare: Option<Arc<PreparedFlare>>,
    light: [f64; 2],
) -> Option<FileUse> {
    let Some(flare) = flare else {
        ui.label("No valid lens: the report needs one (see the Lens tab).");
        return None;
    };
    let mut pick = None;
    let u = super::view::light_slopes(light);
    let key = ReportKey::new(&flare, u);
    if state.step(key, &session.doc().lens, &flare, u) {
        ui.ctx().request_repaint_after(super::jobs::job::PROGRESS_REPAINT);
    }
    let stale = state.stale(key);
    ui.horizontal_wrapped(|ui| {
        ui.label(format!(
            "Light at ({:.1}, {:.1}) deg, f/{:.2}",
            light[0],
            light[1],
            flare.system.first_order.f_number / flare.system.settings.stop_scale
        ));
        // Words, not a spinner: a spinner repaints the window every frame while it shows.
        if stale {
            ui.weak("computing…");
        }
        let ready = matches!(&state.shown, Some((_, Ok(_))));
        if ui
            .add_enabled(ready, egui::Button::new("Export…"))
            .on_hover_text("the table as CSV, or all as JSON")
            .clicked()
        {
            pick = Some(FileUse::ExportReport);
        }
    });
    let Some((_, shown)) = &state.shown else { return pick };
    let report = match shown {
        Ok(r) => r.clone(),
        Err(e) => {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 110), format!("no report: {e}"));
            return pick;
        }
    };
    ui.label(format!(
        "{} ghosts carry {:.2e} of the light entering the pupil. Peak and mean irradiance are relative to the \
             peak of the source's own (diffraction-limited) image; focus is from the image plane, + behind it.",
        report.ghosts.len(),
        report.total_energy_fraction
    ));
    report_table(ui, state, session, &report, &flare);
    ui.separator();
    ui.strong("Coating sensitivity");
    ui.label(format!(
        "Share of the bare lens's ghost energy removed when one surface alone wears the {}:",
        report.sensitivity_coating
    ));
    egui::Grid::new("coating_sensitivity").num_columns(2).striped(true).show(ui, |ui| {
        for s in &report.sensitivity {
            ui.label(format!("surface {}", s.surface));
            ui.label(format!("{:+.1} %", 100.0 * s.energy_drop));
            ui.end_row();
        }
    });
    pick
}

/// The table of `report`, in `state`'s order; a click on a pair selects its ghost in `session`.
fn report_table(
    ui: &mut egui::Ui,
    state: &mut ReportState,
    session: &mut Session,
    report: &GhostReport,
    flare: &PreparedFlare,
) {
    let (column, descending) = state.sort;
    let mut rows: Vec<(usize, &GhostRow)> = report.ghosts.iter().enumerate().collect();
    let value = |r: &GhostRow, rank: usize| -> f64 {
        match column {
            ReportColumn::Rank => rank as f64,
            ReportColumn::Pair => (r.i * 10_000 + r.j) as f64,
            ReportColumn::Focus => r.focus_mm.map_or(f64::INFINITY, f64::abs),
            ReportColumn::Size => r.image_diameter_mm,
            ReportColumn::FNumber => r.f_number.unwrap_or(f64::INFINITY),
            ReportColumn::Peak => r.peak_vs_source,
            ReportColumn::Mean => r.mean_vs_source,
            ReportColumn::Share => r.energy_share,
            ReportColumn::Stop => r.stop_crossings as f64,
            ReportColumn::Vignetted => r.vignetted_share,
        }
    };
    rows.sort_by(|a, b| {
        let o = value(a.1, a.0).total_cmp(&value(b.1, b.0));
        if descending { o.reverse() } else { o }
    });
    // Every column, for the sort chooser: (column, its header, what it is).
    let columns = [
        (ReportColumn::Rank, "#", "rank, worst (highest peak) first"),
        (ReportColumn::Pair, "pair", "the surfaces it reflects at (j, then i)"),
        (ReportColumn::Focus, "focus mm", "where it focuses, from the image plane (sorts by |focus|)"),
        (ReportColumn::Size, "size mm", "its diameter on the sensor"),
        (ReportColumn::FNumber, "f/#", "its working f-number"),
        (ReportColumn::Peak, "peak", "peak irradiance / the source image's peak"),
        (ReportColumn::Mean, "mean", "mean irradiance over its lit area / the same"),
        (ReportColumn::Share, "share", "its share of all the ghosts' energy"),
        (ReportColumn::Stop, "stop", "how many times it crosses the stop"),
        (
            ReportColumn::Vignetted,
            "cut by",
            "the surfaces whose clear apertures cut it at this light, and the share of its light they take \
                 (sorts by the share)",
        ),
    ];
    let title = |c: ReportColumn| columns.iter().find(|(k, _, _)| *k == c).map_or("", |(_, t, _)| *t);
    // Sorting by any column; the table shows five (so it fits the side panel), each row's other figures on
    // its pair's hover (and all of them in the CSV export).
    let mut sort = (column, descending);
    ui.horizontal(|ui| {
        egui::ComboBox::from_label("sort by").selected_text(title(column)).show_ui(ui, |ui| {
            for (c, t, hover) in columns {
                ui.selectable_value(&mut sort.0, c, t).on_hover_text(hover);
            }
        });
        let word = if descending { "highest first" } else { "lowest first" };
        if ui.button(word).on_hover_text("reverse the order").clicked() {
            sort.1 = !descending;
        }
    });
    if sort.0 != column {
        sort.1 = sort.0 != ReportColumn::Rank;
    }
    if sort != (column, descending) {
        state.sort = sort;
    }
    let height = (ui.available_height() * 0.6).max(200.0);
    egui::ScrollArea::vertical().id_salt("report_rows").max_height(height).auto_shrink([false, false]).show(ui, |ui| {
        egui::Grid::new("report_table").num_columns(5).striped(true).spacing([6.0, 2.0]).show(ui, |ui| {
            for (c, title, hover) in columns {
                if !matches!(
                    c,
                    ReportColumn::Rank
                        | ReportColumn::Pair
                        | ReportColumn::Peak
                        | ReportColumn::Share
                        | ReportColumn::Vignetted
                ) {
                    continue;
                }
                let arrow = if c == column { if descending { " v" } else { " ^" } } else { "" };
                if ui.button(format!("{title}{arrow}")).on_hover_text(hover).clicked() {
                    state.sort = (c, if c == column { !descending } else { c != ReportColumn::Rank });
                }
            }
            ui.end_row();
            let opt = |v: Option<f64>, p: usize| v.map_or_else(|| "afocal".to_owned(), |v| format!("{v:.p$}"));
            for (rank, r) in rows {
                ui.label(format!("{}", rank + 1));
                let g = flare.system.ghosts.iter().position(|g| g.i == r.i && g.j == r.j);
                let selected = g.is_some() && session.selected() == g;
                // Its other figures on hover: where it focuses and its size (each section's on an
                // anamorphic lens), its f-number, mean and stop crossings.
                let (focus, size) = if flare.system.is_anamorphic() {
                    (
                        format!("{} / {} (y-z / x-z)", opt(r.focus_mm, 2), opt(r.focus_x_mm, 2)),
                        format!("{:.3} x {:.3} (height x width)", r.image_diameter_mm, r.image_width_mm),
                    )
                } else {
                    (opt(r.focus_mm, 2), format!("{:.3}", r.image_diameter_mm))
                };
                let stop = if r.stop_crossings == 1 { "once".to_owned() } else { format!("{}x", r.stop_crossings) };
                let figures = format!(
                    "focus {focus} mm, size {size} mm, f/{}, mean {:.2e}, crosses the stop {stop}",
                    opt(r.f_number, 1),
                    r.mean_vs_source
                );
                if ui.selectable_label(selected, format!("{}-{}", r.i, r.j)).on_hover_text(figures).clicked() {
                    session.select(if selected { None } else { g });
                }
                ui.label(format!("{:.2e}", r.peak_vs_source));
                ui.label(format!("{:.2} %", 100.0 * r.energy_share));
                let cut = r.vignetting_words();
                ui.add(egui::Label::new(&cut).truncate()).on_hover_text(&cut);
                ui.end_row();
            }
        });
    });
}

/// Writes the report shown in `state`: CSV (the ghost table, the command line's `--report --csv`) or JSON (all
/// of it), by the file name, through a temporary file and a rename; what to say of it.
pub(super) fn export_report(state: &ReportState, path: &std::path::Path) -> String {
    let Some((_, Ok(report))) = &state.shown else {
        return "no ghost report to export yet (open the Report tab)".into();
    };
    let json = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let text = if json {
        serde_json::to_string_pretty(report).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    } else {
        to_csv(report)
    };
    match write_atomic(path, text.as_bytes()) {
        Ok(()) => format!("wrote {} ({} ghosts)", path.display(), report.ghosts.len()),
        Err(e) => format!("could not write {}: {e}", path.display()),
    }
}
