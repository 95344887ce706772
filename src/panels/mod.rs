//! The app's panels, one file each. A panel edits the [`flare_core::preset::Document`] it is given and reads
//! derived state from a [`PanelContext`]; what needs the app (file dialogs, the bake thread, selection) it
//! asks for by pushing an [`Action`].

pub mod aperture;
pub mod blend;
pub mod coatings;
pub mod ghosts;
pub mod lens;
pub mod ray_diagram;

use eframe::egui;
use flare_core::bake::classify::GhostClass;
use flare_core::flare::PreparedFlare;
use flare_core::optics::FirstOrder;

/// One ghost as the list shows it (from the last rendered frame).
#[derive(Clone, Debug, PartialEq)]
pub struct GhostRow {
    pub ghost: usize,
    pub i: usize,
    pub j: usize,
    /// Summed linear RGB irradiance of its sprites (before the user's gain).
    pub rgb: [f64; 3],
    /// Why it is not drawn, if it is not.
    pub culled: Option<&'static str>,
}

impl GhostRow {
    pub fn intensity(&self) -> f64 {
        flare_core::metrics::luminance(self.rgb)
    }
}

/// Where a bake stands.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum BakeStatus {
    #[default]
    Idle,
    Running {
        fraction: f32,
        text: String,
    },
    Done(String),
    Failed(String),
}

/// The lens field the last edit made invalid, with the reason (the viewport keeps the last valid lens).
#[derive(Clone, Debug, PartialEq)]
pub struct LensProblem {
    pub surface: Option<usize>,
    pub field: Option<&'static str>,
    pub reason: String,
}

/// What panels read but do not edit.
pub struct PanelContext<'a> {
    /// The last valid flare (it may be older than the document when the lens is invalid).
    pub flare: Option<&'a PreparedFlare>,
    pub first_order: Option<&'a FirstOrder>,
    pub lens_problem: Option<&'a LensProblem>,
    /// What loading the open lens file had to decide, one sentence each (empty for most lenses).
    pub lens_warnings: &'a [String],
    pub ghosts: &'a [GhostRow],
    pub classes: Option<&'a [GhostClass]>,
    /// The LUT in use (its ghosts are drawn from it).
    pub lut: Option<&'a flare_core::lut::GhostLut>,
    pub selected: Option<usize>,
    pub bake: &'a BakeStatus,
    /// LUT ghosts are baked by themselves when the optics change.
    pub auto_bake: bool,
    pub lut_summary: Option<&'a str>,
}

/// Requests from the panels to the app.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    OpenLensFile,
    SelectGhost(Option<usize>),
    Bake,
    CancelBake,
    /// Turn the automatic bake on or off.
    SetAutoBake(bool),
    OpenLut,
    ExportLut,
    OpenApertureImage,
    OpenDirtImage,
    /// Show surface `k`'s coating in the Coatings panel.
    EditCoating(usize),
    /// Say something in the status bar (an edit a panel refused, with the reason).
    Message(String),
}

/// Gives a number widget (a table cell) an accessible label with its value: what screen readers and the UI
/// tests find it by.
pub fn labelled_value(response: egui::Response, label: &str, value: f64) -> egui::Response {
    response.widget_info(|| {
        let mut info = egui::WidgetInfo::drag_value(true, value);
        info.label = Some(label.to_owned());
        info
    });
    response
}

/// A table's cells as wide as their content, not egui's 40-point least: the Lens and Ghosts tables fit the side
/// panel at its least width (`PANEL_MIN_WIDTH`).
pub fn compact_cells(ui: &mut egui::Ui) {
    ui.spacing_mut().interact_size.x = 20.0;
}

/// Gives a check box without text an accessible label.
pub fn labelled_check(response: egui::Response, label: &str, checked: bool) -> egui::Response {
    response.widget_info(|| egui::WidgetInfo::selected(egui::Role::CheckBox, true, checked, label));
    response
}
