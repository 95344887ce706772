//! The window's own state: which tab the side panel shows, whether the panels are folded away, and which
//! sections under the view are open (colour, depth of field, ray diagram).
//!
//! # How it works
//! [`UiState`] is apart from the document: it is not in the undo history and never in a preset, and the app
//! is its only writer (the tab bar, the View menu and the section toggles under the view). It is stored with
//! the window (eframe's storage, [`UI_STATE_KEY`], as JSON) and read back on the next start; a missing or
//! damaged record gives the defaults (the Ghosts tab, the panels shown, every section folded: the picture
//! first), a missing field its default.

use eframe::egui;
use serde::{Deserialize, Serialize};

use super::session::Tab;

/// eframe's storage key of the window's state.
pub const UI_STATE_KEY: &str = "flarelab.ui";

/// The window's own state (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct UiState {
    /// The side panel's tab.
    pub tab: Tab,
    /// The side panel is folded away (View > Panels): the viewport takes the window's width.
    pub panels_hidden: bool,
    /// The colour rows under the view (display, view, look, plates' space, `.cube`, config).
    pub colour_open: bool,
    /// The depth of field's rows under the view (they open by themselves when a depth map is chosen).
    pub dof_open: bool,
    /// The ray diagram under the view.
    pub rays_open: bool,
}

impl Default for UiState {
    fn default() -> Self {
        Self { tab: Tab::Ghosts, panels_hidden: false, colour_open: false, dof_open: false, rays_open: false }
    }
}

impl UiState {
    /// The stored state, or the defaults when there is none or it cannot be read (said on stderr).
    pub fn restore(storage: &dyn eframe::Storage) -> Self {
        let Some(text) = storage.get_string(UI_STATE_KEY) else { return Self::default() };
        serde_json::from_str(&text).unwrap_or_else(|e| {
            eprintln!("flarelab: the window's last layout could not be read ({e}); starting from the default");
            Self::default()
        })
    }

    /// Stores the state (JSON) under [`UI_STATE_KEY`].
    pub fn store(&self, storage: &mut dyn eframe::Storage) {
        if let Ok(text) = serde_json::to_string(self) {
            storage.set_string(UI_STATE_KEY, text);
        }
    }
}

/// The toggles of the sections under the view (colour, depth of field, ray diagram), in the timeline's row:
/// each opens its rows under the view; folded, the picture takes their height. `dof_on`: the document's depth
/// of field is on (the toggle says so while its rows are folded).
pub fn sections_ui(ui: &mut egui::Ui, state: &mut UiState, dof_on: bool) {
    let dof = if dof_on { "DoF (on)" } else { "DoF" };
    let toggles = [
        (
            &mut state.colour_open,
            "colour",
            "the OCIO display, view and look, the plates' colour space, a .cube, the config",
        ),
        (&mut state.dof_open, dof, "depth of field: the plate defocused through this lens (depth map, focus)"),
        (&mut state.rays_open, "ray diagram", "the selected ghost's path through the lens"),
    ];
    for (open, text, hover) in toggles {
        if ui.selectable_label(*open, text).on_hover_text(hover).clicked() {
            *open = !*open;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_reads_back_and_a_damaged_record_gives_the_defaults() {
        let state =
            UiState { tab: Tab::Lens, panels_hidden: true, colour_open: true, dof_open: false, rays_open: true };
        let text = serde_json::to_string(&state).unwrap();
        assert_eq!(serde_json::from_str::<UiState>(&text).unwrap(), state);
        // A field missing (an older record) takes its default; the others are kept.
        let older: UiState = serde_json::from_str(r#"{"tab":"Report"}"#).unwrap();
        assert_eq!(older, UiState { tab: Tab::Report, ..UiState::default() });
        assert!(serde_json::from_str::<UiState>(r#"{"tab":"Nowhere"}"#).is_err());
    }
}
