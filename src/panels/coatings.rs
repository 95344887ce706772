//! Coatings panel: one coating for every surface, or each surface's own (none / quarter-wave single layer /
//! multilayer stack, layers listed from the surface outwards); the chosen surface's reflectance against
//! wavelength at normal incidence, plotted with egui_plot from `flare_core::coating::reflection`.

use eframe::egui;
use egui_plot::{Legend, Line, Plot, PlotPoints};
use flare_core::coating::reflection;
use flare_core::optics::Coating;
use flare_core::optics::CoatingLayer;

use super::labelled_value;

use flare_core::preset::Document;

/// Which surface the plot and the editor show.
#[derive(Default)]
pub struct CoatingsState {
    pub surface: usize,
}

const QUARTER_WAVE: Coating = Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None };

/// The coating's kind in words.
pub fn kind(c: &Coating) -> &'static str {
    match c {
        Coating::Uncoated => "none",
        Coating::QuarterWave { .. } => "quarter-wave",
        Coating::Multilayer { .. } => "multilayer",
    }
}

/// Edits one coating; true when it changed.
fn coating_editor_ui(ui: &mut egui::Ui, coating: &mut Coating, id: &str) -> bool {
    let before = coating.clone();
    let mut chosen = kind(coating);
    egui::ComboBox::from_label(id).selected_text(chosen).show_ui(ui, |ui| {
        for k in ["none", "quarter-wave", "multilayer"] {
            ui.selectable_value(&mut chosen, k, k);
        }
    });
    if chosen != kind(coating) {
        *coating = match chosen {
            "none" => Coating::Uncoated,
            "quarter-wave" => QUARTER_WAVE,
            // A new multilayer starts as a real broadband AR design (quarter-half-quarter, cited there).
            _ => Coating::broadband(),
        };
    }
    match coating {
        Coating::Uncoated => {}
        Coating::QuarterWave { design_wavelength_nm, layer_index } => {
            ui.add(egui::Slider::new(design_wavelength_nm, 380.0..=780.0).text("design wavelength (nm)"));
            let mut auto = layer_index.is_none();
            ui.horizontal(|ui| {
                ui.checkbox(&mut auto, "layer index sqrt(n0 n2), at least MgF2's 1.38");
                if auto {
                    *layer_index = None;
                } else {
                    let mut n = layer_index.unwrap_or(1.38);
                    let r = ui.add(egui::DragValue::new(&mut n).range(1.0..=3.0).speed(0.005).prefix("n = "));
                    labelled_value(r, "layer index", n);
                    *layer_index = Some(n);
                }
            });
        }
        Coating::Multilayer { layers } => {
            let mut remove = None;
            for (k, layer) in layers.iter_mut().enumerate() {
                ui.horizontal(|ui| {
                    ui.label(format!("layer {k}"));
                    let r = ui.add(egui::DragValue::new(&mut layer.index).range(1.0..=3.0).speed(0.005).prefix("n = "));
                    labelled_value(r, &format!("layer {k} index"), layer.index);
                    let r = ui.add(egui::DragValue::new(&mut layer.thickness_nm).range(0.0..=2000.0).suffix(" nm"));
                    labelled_value(r, &format!("layer {k} thickness"), layer.thickness_nm);
                    if ui.small_button("x").clicked() {
                        remove = Some(k);
                    }
                });
            }
            if let Some(k) = remove {
                layers.remove(k);
            }
            if ui.small_button("+ layer").clicked() {
                layers.push(CoatingLayer { index: 1.38, thickness_nm: 100.0 });
            }
        }
    }
    *coating != before
}

pub fn coatings_ui(ui: &mut egui::Ui, doc: &mut Document, state: &mut CoatingsState) {
    let mut every = doc.coating_override.is_some();
    ui.checkbox(&mut every, "one coating on every surface");
    if every && doc.coating_override.is_none() {
        doc.coating_override = Some(QUARTER_WAVE);
    } else if !every {
        doc.coating_override = None;
    }
    let count = doc.lens.surfaces.len();
    state.surface = state.surface.min(count.saturating_sub(1));
    if let Some(c) = &mut doc.coating_override {
        coating_editor_ui(ui, c, "coating");
    } else {
        ui.horizontal(|ui| {
            ui.label("surface");
            let r = ui.add(egui::DragValue::new(&mut state.surface).range(0..=count.saturating_sub(1)));
            labelled_value(r, "coated surface", state.surface as f64);
        });
        let s = state.surface;
        if let Some(surface) = doc.lens.surfaces.get_mut(s) {
            coating_editor_ui(ui, &mut surface.coating, "coating of this surface");
        }
    }
    // Reflectance of the shown surface against wavelength, at normal incidence, from the lighter side.
    let s = state.surface;
    let Some(surface) = doc.lens.surfaces.get(s) else { return };
    let coating = doc.coating_override.clone().unwrap_or_else(|| surface.coating.clone());
    let before = if s == 0 { 1.0 } else { doc.lens.surfaces[s - 1].medium.n_d };
    let after = surface.medium.n_d;
    let curve = |c: &Coating| -> Vec<[f64; 2]> {
        (380..=780)
            .step_by(5)
            .map(|w| [f64::from(w), 100.0 * reflection(c, before, after, f64::from(w), 0.0).reflectance])
            .collect()
    };
    // The scale: 0 to at least 5 %, a labelled tick every percent, the average over 430-670 nm written out.
    let average = {
        let band: Vec<f64> =
            curve(&coating).into_iter().filter(|p| (430.0..=670.0).contains(&p[0])).map(|p| p[1]).collect();
        band.iter().sum::<f64>() / band.len().max(1) as f64
    };
    ui.label(format!("reflectance at normal incidence: {average:.2} % on average from 430 to 670 nm"));
    Plot::new("reflectance")
        .height(220.0)
        .legend(Legend::default())
        .x_axis_label("wavelength (nm)")
        .y_axis_label("reflectance (%)")
        .y_axis_formatter(|mark, _range| format!("{:.0} %", mark.value))
        .y_grid_spacer(egui_plot::uniform_grid_spacer(|_| [1.0, 5.0, 10.0]))
        .allow_scroll(false)
        .include_y(0.0)
        .include_y(5.0)
        .show(ui, |plot| {
            plot.line(Line::new(format!("surface {s} ({})", kind(&coating)), PlotPoints::from(curve(&coating))));
            plot.line(
                Line::new("uncoated", PlotPoints::from(curve(&Coating::Uncoated)))
                    .color(egui::Color32::GRAY)
                    .style(egui_plot::LineStyle::dashed_loose()),
            );
        });
}
