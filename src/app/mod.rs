//! The desktop app (eframe + egui + wgpu): a viewport where the light is dragged across the frame, panels
//! that edit the document (lens, aperture, coatings, ghosts, blend), a ray diagram, presets, undo and redo.
//!
//! # How it works
//! `FlareLabApp` is a thin shell over four parts, each the only writer of its state (private fields): the
//! [`session`] (the [`Document`] the panels edit, its undo [`crate::history::History`], the selection, the tab,
//! the status line), the [`view`] (the viewport's layout and drawing size, the playhead, drafts, and
//! [`view::LightMap`], the one conversion between the viewport's points and the light), the frame source
//! [`derived`] (what the document implies, rebuilt only when it changes, and the frame; it reads the document
//! and never writes it) and the [`jobs`] board (every thread: the bake and its automatic policy, exports, the
//! shot's jobs, the depth of field, the ray grid, the looks, the report). Each UI frame the shell hands the frame
//! source the view's playhead, size and draft and lets it sync: the prepared flare (ghost matrices, aperture
//! mask, starburst, and their GPU textures) when [`Document::optics_fingerprint`] changes (an impossible lens
//! keeps the last valid flare and marks the bad cell), the plate's texture when the plate file changes, then the
//! frame ([`Frame::build`], the one frame pipeline) when its `FrameRequest` (light, gains, blend, exposures,
//! tonemap, view size) or the LUT changed; display settings never rebuild the optics or a texture
//! ([`derived::RebuildCounts`]). It polls the board once ([`jobs::JobBoard::poll`]) and routes what comes back
//! (a LUT to show, the light found, a sentence) to the part that owns it; panels edit the document through
//! [`session::Session::edit`], and the session turns every gesture (a whole drag at once) into one undo step.
//! A new frame goes to the viewport's paint callback ([`crate::viewport`]); otherwise the callback re-draws the
//! last texture, and the app asks for a repaint only while something is under way (a job, playback, a drag
//! bench), so an idle window costs nothing. Images are exported through the same frame pipeline and writer as
//! `flarelab render`. The README's "The app's house" says which part may call which.

use jobs::{JobBoard, JobEvent, Live};
use session::Session;
pub use session::Tab;
use ui_state::UiState;
use view::View;

mod colour;
pub mod derived;
mod dof_row;
pub mod draft;
pub mod drag_bench;
mod file_actions;
pub mod files;
pub mod frame_log;
mod ghost_report_panel;
pub mod jobs;
mod looks_panel;
pub mod options;
mod plates;
pub mod session;
mod shot_panel;
pub mod timeline;
pub mod ui_state;
pub mod view;

pub use jobs::shot::DEFAULT_EXPORT_PX;

use crate::panels::aperture::AperturePreview;
use crate::panels::coatings::CoatingsState;
use crate::panels::ray_diagram::RayDiagram;
use crate::panels::{Action, BakeStatus, PanelContext};
use crate::viewport::{FlareCallback, ViewportResources};
use anyhow::{Result, bail};

use derived::{Derived, SyncEvent};
use drag_bench::DragBench;
use eframe::egui_wgpu::RenderState;
use eframe::{egui, wgpu};
use files::FileUse;
use flare_core::flare::PreparedFlare;
use flare_core::frame::{Device, Frame, Sources};
use flare_core::lut::{GhostLut, LutKind};
use flare_core::optics::formats::{LoadedLens, read_lens_file};
use flare_core::preset::{Document, LutSource};

const NO_DISPLAY: &str = "no display to open the app's window on (DISPLAY and WAYLAND_DISPLAY are unset). \
The command line works without one: `flarelab lens list`, `flarelab lens info LENS`, \
`flarelab trace LENS --field-deg T --pupil PX,PY [--ghost I,J]`; see `flarelab --help`";

/// The key eframe stores the last session's document under.
const STORAGE_KEY: &str = "flarelab_document";
/// The key of the recent files (a JSON list of paths).
const RECENT_KEY: &str = "flarelab_recent_files";

/// Opens the app window; without a display, explains how to use the command line instead.
pub fn run() -> Result<()> {
    if cfg!(target_os = "linux")
        && std::env::var_os("DISPLAY").is_none()
        && std::env::var_os("WAYLAND_DISPLAY").is_none()
    {
        bail!(NO_DISPLAY);
    }
    // Every FLARELAB_* variable the window reads, read once here.
    let app_options = options::AppOptions::from_env();
    let size = [app_options.window.0, app_options.window.1];
    let mut options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size(size).with_title("FlareLab"),
        ..Default::default()
    };

    // The device also asks for the timestamp queries the adapter offers (the renderer times its passes on the
    // GPU; the status bar shows them) and for blending into 32-bit float targets.
    if let eframe::egui_wgpu::WgpuSetup::CreateNew(create) = &mut options.wgpu_options.wgpu_setup {
        let base = create.device_descriptor.clone();
        create.device_descriptor = std::sync::Arc::new(move |adapter| {
            let mut descriptor = base(adapter);
            descriptor.required_features |= flare_core::render::gpu::wanted_features(adapter);
            descriptor
        });
    }
    let result = eframe::run_native(
        "FlareLab",
        options,
        Box::new(|cc| {
            // FLARELAB_PRESET=FILE opens a preset; FLARELAB_FRESH=1 starts from the default document instead of
            // the last session.
            let preset = app_options.preset.as_ref().and_then(|p| {
                Document::open(p)
                    .map_err(|e| eprintln!("flarelab: FLARELAB_PRESET {}: {e}; starting without it", p.display()))
                    .ok()
            });
            let stored = if preset.is_some() || app_options.fresh { preset } else { cc.storage.and_then(restore) };
            let mut app = FlareLabApp::with_options(cc.wgpu_render_state.clone(), stored, &app_options);
            // eframe clears the window to the panels' colour (`clear_color`).
            app.cleared_by_window = true;
            if let Some(storage) = cc.storage {
                app.files.recent = restore_recent(storage);
                app.ui = UiState::restore(storage);
            }
            Ok(Box::new(app))
        }),
    );
    if let Err(e) = result {
        bail!("could not open the app's window ({e}). The command line works without one: see `flarelab --help`");
    }
    Ok(())
}

pub struct FlareLabApp {
    /// The document, its history, the selection, the tab and the status line (see [`session`]).
    session: Session,
    gpu: Option<RenderState>,
    /// The frame source: what the app derives from the document, and the frame (see [`derived`]).
    derived: Derived,
    /// What loading the open lens file had to decide (clipped apertures, the system aperture), with the id of
    /// the lens it applies to: shown in the lens panel while that lens is open.
    lens_warnings: Option<(String, Vec<String>)>,
    /// File choosers and recent files (see [`files`]).
    files: files::Files,
    // Panels' own state.
    aperture_preview: AperturePreview,
    coatings: CoatingsState,
    ray_diagram: RayDiagram,
    drag_bench: Option<DragBench>,
    /// The size File > Export image and sequence draw at, when the user set one; `None`: the plate's size, else
    /// [`DEFAULT_EXPORT_PX`] (what the command line does without --size). See [`FlareLabApp::export_px`].
    export_size: Option<(u32, u32)>,
    /// The viewport's layout, the pointer <-> light mapping, the playhead, drafts (see [`view`]).
    view: View,
    /// Every job on a thread: one poll, one status area, one priority rule (see [`jobs`]).
    jobs: JobBoard,
    /// The Shot panel's text fields.
    shot_fields: shot_panel::ShotFields,
    /// The colour row's text fields: a config file and a `.cube`, applied with their buttons.
    colour_fields: colour::ColourFields,
    /// The window's render pass clears it to the panels' colour ([`eframe::App::clear_color`]), so the panels
    /// are drawn unfilled; without it (the UI tests' harness clears to transparent) one rectangle paints the
    /// same colour under them.
    cleared_by_window: bool,
    /// The window's own state: the tab, the folded panels and sections (see [`ui_state`]).
    ui: UiState,
    /// The height (points) the rows under the viewport took in the last frame: the viewport takes the rest.
    under_view: f32,
    /// Every UI frame's start and duration, when `FLARELAB_FRAME_LOG` asks (see [`frame_log`]).
    frame_log: Option<frame_log::FrameLog>,
    /// Whether the draft passes were warmed on a software adapter (see [`FlareLabApp::warm_drafts`]).
    drafts_warmth: draft::DraftWarmth,
}

impl FlareLabApp {
    /// The app on `gpu` (none in UI tests: no viewport), from `stored` or the default document, with the default
    /// options (whatever the environment says).
    pub fn new(gpu: Option<RenderState>, stored: Option<Document>) -> Self {
        Self::with_options(gpu, stored, &options::AppOptions::default())
    }

    /// [`Self::new`] with `options` (the window's: [`options::AppOptions::from_env`]).
    pub fn with_options(gpu: Option<RenderState>, stored: Option<Document>, options: &options::AppOptions) -> Self {
        let software = gpu.as_ref().is_some_and(|r| r.adapter.get_info().device_type == wgpu::DeviceType::Cpu);
        if let Some(rs) = &gpu {
            ViewportResources::install(rs);
        }
        let doc = stored.unwrap_or_default();
        let first_frame = doc.timeline.first_frame;
        let drag_bench = options.drag_bench.map(|(frames, what)| DragBench::new(frames, what));
        let mut app = Self {
            session: Session::new(doc),
            gpu,
            derived: Derived::new(software),
            lens_warnings: None,
            files: files::Files::default(),
            aperture_preview: AperturePreview::default(),
            coatings: CoatingsState::default(),
            ray_diagram: RayDiagram::default(),
            drag_bench,
            export_size: None,
            view: View::new(software, first_frame, options.view_px),
            jobs: JobBoard::default(),
            shot_fields: shot_panel::ShotFields::default(),
            colour_fields: colour::ColourFields::default(),

            cleared_by_window: false,
            ui: UiState::default(),
            under_view: 80.0,
            frame_log: options.frame_log.clone().map(frame_log::FrameLog::new),
            drafts_warmth: if software { draft::DraftWarmth::Cold } else { draft::DraftWarmth::Warm },
        };
        // FLARELAB_RAYGRID=N starts the view in its ray-grid mode (the Xvfb test and screenshots); FLARELAB_AUTO_BAKE=0
        // turns the automatic bake off (measurements: no background bake competing for the cores).
        app.jobs.raygrid_mut().grid = options.raygrid;
        app.jobs.set_device(app.gpu.as_ref().map(|rs| (rs.device.clone(), rs.queue.clone())));
        if !options.auto_bake {
            app.jobs.autobake_mut().enabled = false;
        }
        app.shot_fields.plate_path = app.session.doc().background.clone().unwrap_or_default();
        app.sync();
        app
    }

    /// Marks the draft passes warm without warming them: a test's reference window, drawn without the warm-up.
    pub fn skip_draft_warm_up(&mut self) {
        self.drafts_warmth = draft::DraftWarmth::Warm;
    }

    /// Whether the draft passes are warm: on a software adapter, a draft was drawn aside through the view's baked
    /// cube after the first frame was shown (see [`FlareLabApp::warm_drafts`]); always on a hardware GPU.
    pub fn drafts_warm(&self) -> bool {
        self.drafts_warmth == draft::DraftWarmth::Warm
    }

    /// Whether the viewport shows the ray-grid view's traced image of the frame on screen (not its paraxial
    /// drawing).
    pub fn view_shows_traced(&self) -> bool {
        let Some((generation, _)) = &self.derived.view_frame() else { return false };
        self.jobs.raygrid().traced(*generation).is_some()
            && self.gpu.as_ref().is_some_and(|rs| crate::viewport::ViewportResources::shows_image(rs, *generation))
    }

    /// The document as the user left it (see [`session`]).
    pub fn doc(&self) -> &Document {
        self.session.doc()
    }

    /// The document to edit, as a panel does: one undo step at the end of the gesture.
    pub fn edit(&mut self) -> &mut Document {
        self.session.edit()
    }

    /// What the status line says.
    pub fn message(&self) -> Option<&str> {
        self.session.message()
    }

    /// Opens `tab` in the side panel, as its button does.
    pub fn show_tab(&mut self, tab: Tab) {
        self.ui.tab = tab;
    }

    /// The viewport's rectangle laid out last (points).
    pub fn view_rect(&self) -> Option<egui::Rect> {
        self.view.rect()
    }

    /// The window's own state (see [`ui_state`]).
    pub fn ui_state(&self) -> &UiState {
        &self.ui
    }

    /// The window's own state, to set as the user does (the tests open the sections under the view).
    pub fn ui_state_mut(&mut self) -> &mut UiState {
        &mut self.ui
    }

    /// Selects a ghost (an index into the live flare's ghosts), as a click on it does.
    pub fn select(&mut self, ghost: Option<usize>) {
        self.session.select(ghost);
    }

    /// The timeline frame the view shows.
    pub fn playhead(&self) -> i64 {
        self.view.playhead()
    }

    /// Whether the next click in the viewport focuses the depth of field.
    pub fn focus_pick(&self) -> bool {
        self.view.focus_pick()
    }

    /// The session (document, history, selection, tab, status line), to read.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The prepared flare in use (the last valid one).
    pub fn flare(&self) -> Option<&PreparedFlare> {
        self.derived.flare().as_deref()
    }

    /// The LUT in use, if any.
    pub fn lut(&self) -> Option<&GhostLut> {
        self.derived.lut().as_deref().map(|l| &l.lut)
    }

    /// Where the bake stands (for the Blend panel and the tests).
    pub fn bake_status(&self) -> &BakeStatus {
        self.jobs.bake_status()
    }

    /// The frame source (see [`derived`]), to read.
    pub fn derived(&self) -> &Derived {
        &self.derived
    }

    /// Shows the LUT in use again as a new one (what a bake landing with the same ghosts does): a new frame
    /// that differs only in its LUT generation.
    pub fn show_lut_again(&mut self) {
        let lut = self.lut().cloned();
        self.set_lut(lut);
    }

    /// The file choosers and recent files (see [`files`]).
    pub fn files(&self) -> &files::Files {
        &self.files
    }

    /// The file choosers' settings (the tests turn the native dialog off).
    pub fn files_mut(&mut self) -> &mut files::Files {
        &mut self.files
    }

    /// Writes `color` into the document when it resolves, as the colour row does; else says why.
    pub fn set_color(&mut self, color: flare_core::view_transform::ColorDoc) {
        colour::set_color(&mut self.session, color);
    }

    /// Focus by click: the plate pixel under `pointer` in the view `rect` (see [`dof_row::focus_at`]).
    pub fn focus_from_pointer(&mut self, pointer: egui::Pos2, rect: egui::Rect) {
        let plate = self.derived.sharp_plate().clone();
        dof_row::focus_at(&mut self.session, &mut self.view, plate.as_deref(), pointer, rect);
    }

    /// Applies shipped look `k` as the Looks panel does (one undo step).
    pub fn apply_look(&mut self, k: usize) {
        looks_panel::apply_look(&mut self.session, k);
    }

    /// The job board (see [`jobs`]), to read.
    pub fn jobs(&self) -> &JobBoard {
        &self.jobs
    }

    /// The job board, to steer its parts (the tests cancel a trace, make bakes coarse).
    pub fn jobs_mut(&mut self) -> &mut JobBoard {
        &mut self.jobs
    }

    /// Re-derives what changed in the document (see the module documentation).
    pub fn sync(&mut self) {
        let timeline = &self.session.doc().timeline;
        self.view.clamp_playhead(timeline.first_frame, timeline.last_frame);
        self.derived.set_playhead(self.view.playhead());
        let mut events = self.derived.sync(self.session.doc(), self.gpu.as_ref());
        self.jobs.dof_mut().sync(&mut self.derived, self.session.doc(), self.gpu.as_ref(), &mut events);
        // A defocused plate that just arrived is a new plate for the frame.
        self.derived.sync_frame(self.session.doc());
        for event in events {
            match event {
                SyncEvent::Message(text) => self.session.say(text),
                SyncEvent::LutDropped => {
                    let said = self.jobs.lut_dropped();
                    self.session.say(said);
                }
            }
        }
    }

    /// Builds the frame again if what it shows changed (after the view was resized).
    fn sync_frame(&mut self) {
        self.derived.sync_frame(self.session.doc());
    }

    fn set_lut(&mut self, lut: Option<GhostLut>) {
        self.derived.set_lut(lut, self.gpu.as_ref());
    }

    /// Undo and redo from the keyboard and the menu.
    pub fn undo(&mut self) {
        self.walk_history(true);
    }

    pub fn redo(&mut self) {
        self.walk_history(false);
    }

    /// Undo (`back`) or redo, saying in the status bar what it undid or redid (then what that made the app
    /// say: a dropped LUT), or that there is nothing to; the message before is replaced.
    fn walk_history(&mut self, back: bool) {
        let verb = if back { "undid" } else { "redid" };
        let what = match self.session.walk(back) {
            Ok(what) => what,
            Err(nothing) => return self.session.say(nothing),
        };
        self.session.hush();
        self.sync();
        let said = match self.session.take_message() {
            Some(then) => format!("{verb}: {what}; {then}"),
            None => format!("{verb}: {what}"),
        };
        self.session.say(said);
    }

    /// The whole window: menus, status bar, panels, viewport, ray diagram; then the frame's bookkeeping.
    pub fn ui_root(&mut self, ui: &mut egui::Ui) {
        // Whatever changed the document since the last frame (a test, a restored session) is drawn now.
        self.step_playback(ui.ctx());
        self.sync();
        self.sync_shot_light();
        self.keys(ui.ctx());
        self.poll_jobs();
        self.files_step(ui.ctx());
        self.drag_bench_step(ui.ctx());
        self.draft_step(ui.ctx());
        let mut actions = Vec::new();
        // The panels' background is the window's clear colour, not four filled rectangles: on a software
        // rasteriser (lavapipe) egui's shader filling the window cost 29 ms of every frame at 1280x720 (a
        // blank window: 33.8 ms a frame filled, 4.4 ms cleared), the flare's own passes 11 ms.
        if !self.cleared_by_window {
            ui.painter().rect_filled(ui.max_rect(), 0.0, ui.visuals().panel_fill);
        }
        let unfilled = |frame: egui::Frame| frame.fill(egui::Color32::TRANSPARENT);
        let side = unfilled(egui::Frame::side_top_panel(ui.style()));
        egui::Panel::top("menu").frame(side).show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("status").frame(side).show(ui, |ui| self.status_ui(ui));
        // Resizable and foldable (View > Panels): the picture first. At first a quarter of the window's width,
        // from `PANEL_MIN_WIDTH` (what every tab needs without a sideways scroll) to 600 points: 360 of a
        // 1440-point window, whose view then takes over 60 % of it (with a fixed 600 it took 31 %).
        let width = ui.available_width();
        let first_width = (0.25 * width).clamp(PANEL_MIN_WIDTH, 600.0);
        let panels = egui::Panel::right("panels")
            .frame(side)
            .default_size(first_width)
            .min_size(PANEL_MIN_WIDTH)
            .resizable(true);
        if !self.ui.panels_hidden {
            panels.show(ui, |ui| {
                // The tables fit the panel's width: a little less room between items.
                ui.spacing_mut().item_spacing.x = 6.0;
                ui.horizontal_wrapped(|ui| {
                    for tab in Tab::ALL {
                        if ui.selectable_label(self.ui.tab == tab, tab.name()).clicked() {
                            self.ui.tab = tab;
                        }
                    }
                });
                ui.separator();
                self.panel_ui(ui, &mut actions);
            });
        }
        egui::CentralPanel::default().frame(unfilled(egui::Frame::central_panel(ui.style()))).show(ui, |ui| {
            // The viewport takes what the rows under it (as tall as they were last frame) leave.
            let height = (ui.available_height() - self.under_view).max(120.0);
            ui.allocate_ui(egui::vec2(ui.available_width(), height), |ui| self.viewport_ui(ui, &mut actions));
            let under_top = ui.cursor().top();
            let info = shot_panel::ShotInfo::new(&self.session, &self.derived, &self.jobs, self.export_px(), false);
            shot_panel::timeline_ui(ui, &mut self.session, &mut self.view, &mut self.ui, &info);
            self.display_ui(ui);
            // The sections under the view, each open by its toggle ([`Self::sections_ui`]); folded, the
            // viewport takes their height.
            if self.ui.colour_open {
                colour::colour_ui(ui, &mut self.session, &mut self.colour_fields);
            }
            if self.ui.dof_open {
                let defocusing = self.jobs.dof().busy();
                if let Some(use_) = dof_row::dof_ui(ui, &mut self.session, &mut self.view, defocusing) {
                    self.pick_file(use_);
                }
            }
            if self.ui.rays_open {
                let ghost = self
                    .session
                    .selected()
                    .and_then(|g| self.derived.flare().as_ref().map(|f| &f.system.ghosts[g]))
                    .map(|g| (g.i, g.j));
                crate::panels::ray_diagram::ray_diagram_ui(
                    ui,
                    &mut self.ray_diagram,
                    self.derived.flare().as_deref(),
                    self.derived.lens_problem().as_ref(),
                    self.derived.light_deg(self.session.doc()),
                    ghost,
                );
            }
            let used = ui.cursor().top() - under_top;
            if (used - self.under_view).abs() > 0.5 {
                self.under_view = used;
                ui.ctx().request_repaint();
            }
        });
        for action in actions {
            self.act(action);
        }
        self.sync();
        self.jobs.raygrid_mut().step(&self.derived, self.gpu.as_ref());
        self.warm_drafts(ui.ctx());
        // An edit in this frame made a new scene after the viewport was painted: paint once more.
        if self.derived.frame_pending() && self.gpu.is_some() {
            ui.ctx().request_repaint();
        }
        // One undo step per gesture: commit when no button is held.
        if !ui.ctx().input(|i| i.pointer.any_down()) {
            self.session.commit();
        }
        if self.jobs.busy() {
            ui.ctx().request_repaint_after(jobs::job::PROGRESS_REPAINT);
        }
    }

    /// The tab's panel: one match over [`Tab`], the app's own panels first, then the document's.
    fn panel_ui(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        match self.ui.tab {
            Tab::Shot => {
                let decides = self.export_size.is_none() && self.derived.plate().is_some();
                let info =
                    shot_panel::ShotInfo::new(&self.session, &self.derived, &self.jobs, self.export_px(), decides);
                let (session, view, fields) = (&mut self.session, &mut self.view, &mut self.shot_fields);
                let action = panel_scroll().show(ui, |ui| shot_panel::shot_ui(ui, session, view, fields, &info)).inner;
                if let Some(action) = action {
                    self.shot_action(action);
                }
                return;
            }
            Tab::Looks => {
                let (looks, session) = (self.jobs.looks_mut(), &mut self.session);
                return panel_scroll().show(ui, |ui| looks_panel::looks_ui(ui, looks, session)).inner;
            }
            Tab::Report => {
                let (flare, light) = (self.derived.flare().clone(), self.derived.light_deg(self.session.doc()));
                let (state, session) = (self.jobs.report_mut(), &mut self.session);
                let pick =
                    panel_scroll().show(ui, |ui| ghost_report_panel::report_ui(ui, state, session, flare, light)).inner;
                if let Some(use_) = pick {
                    self.pick_file(use_);
                }
                return;
            }
            Tab::Lens | Tab::Aperture | Tab::Coatings | Tab::Ghosts | Tab::Blend => {}
        }
        let ctx = PanelContext {
            flare: self.derived.flare().as_deref(),
            first_order: self.derived.first_order().as_ref(),
            lens_problem: self.derived.lens_problem().as_ref(),
            lens_warnings: match &self.lens_warnings {
                Some((id, warnings)) if *id == self.session.doc().lens.id => warnings,
                _ => &[],
            },
            ghosts: self.derived.ghosts(),
            classes: self.jobs.classes(),
            lut: self.derived.lut().as_deref().map(|l| &l.lut),
            selected: self.session.selected(),
            bake: self.jobs.bake_status(),
            auto_bake: self.jobs.autobake().enabled,
            lut_summary: None,
        };
        let summary = self.derived.lut().as_ref().map(|l| {
            format!(
                "LUT: {} ghosts, {} entries, theta 0 to {:.1} deg ({})",
                l.lut.ghosts.len(),
                l.lut.entry_count(),
                l.lut.theta_max_deg,
                if l.lut.kind == LutKind::Photo { "photo" } else { "ray-traced" }
            )
        });
        let ctx = PanelContext { lut_summary: summary.as_deref(), ..ctx };
        panel_scroll().show(ui, |ui| match self.ui.tab {
            Tab::Lens => crate::panels::lens::lens_ui(ui, self.session.edit(), &ctx, actions),
            Tab::Aperture => {
                crate::panels::aperture::aperture_ui(
                    ui,
                    self.session.edit(),
                    &ctx,
                    &mut self.aperture_preview,
                    actions,
                );
            }
            Tab::Coatings => crate::panels::coatings::coatings_ui(ui, self.session.edit(), &mut self.coatings),
            Tab::Ghosts => crate::panels::ghosts::ghosts_ui(ui, self.session.edit(), &ctx, actions),
            Tab::Blend => crate::panels::blend::blend_ui(ui, self.session.edit(), &ctx, actions),
            Tab::Shot | Tab::Looks | Tab::Report => {}
        });
    }

    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open preset…").clicked() {
                    self.pick_file(FileUse::OpenPreset);
                }
                ui.menu_button("Open recent", |ui| {
                    if self.files.recent.is_empty() {
                        ui.weak("no recent files yet");
                    }
                    for path in self.files.recent.clone() {
                        if ui.button(path.display().to_string()).clicked() {
                            self.open_recent(&path);
                        }
                    }
                });
                if ui.button("Save preset…").clicked() {
                    self.pick_file(FileUse::SavePreset);
                }
                ui.separator();
                if ui.button("Background plate…").clicked() {
                    self.pick_file(FileUse::Background);
                }
                // Always there (greyed without a plate), so the menu's items never move.
                if ui
                    .add_enabled(self.session.doc().background.is_some(), egui::Button::new("Remove background"))
                    .clicked()
                {
                    self.session.edit().background = None;
                    self.shot_fields.plate_path.clear();
                    self.session.say("background plate removed");
                }
                if ui.button("Import light track…").clicked() {
                    self.pick_file(FileUse::Track);
                }
                if ui
                    .button("Add glass catalogue…")
                    .on_hover_text("a vendor's Zemax .agf file: lens files may name its glasses")
                    .clicked()
                {
                    self.pick_file(FileUse::GlassCatalogue);
                }
                ui.separator();
                ui.horizontal(|ui| {
                    // The plate's size until the user sets one (as the command line without --size).
                    let (mut w, mut h) = self.export_px();
                    let r = ui.add(egui::DragValue::new(&mut w).range(16..=8192).suffix(" px"));
                    let mut changed = r.changed();
                    crate::panels::labelled_value(r, "export width", f64::from(w));
                    ui.label("x");
                    let r = ui.add(egui::DragValue::new(&mut h).range(16..=8192).suffix(" px"));
                    changed |= r.changed();
                    crate::panels::labelled_value(r, "export height", f64::from(h));
                    if changed {
                        self.export_size = Some((w, h));
                    }
                    if self.export_size.is_none() && self.derived.plate().is_some() {
                        ui.label("(the plate's)");
                    }
                    if ui.button("Export image…").on_hover_text("PNG (tonemapped) or EXR (linear)").clicked() {
                        self.pick_file(FileUse::ExportImage);
                    }
                });
                self.exr_settings_ui(ui);
                if ui.button("Export sequence…").on_hover_text("the timeline's frames, on a thread").clicked() {
                    self.export_sequence_dialog();
                }
                if ui.button("Export LUT…").clicked() {
                    self.act(Action::ExportLut);
                }
            });
            ui.menu_button("View", |ui| {
                let mut shown = !self.ui.panels_hidden;
                if ui
                    .checkbox(&mut shown, "Panels")
                    .on_hover_text("the side panel; folded, the view takes the width")
                    .changed()
                {
                    self.ui.panels_hidden = !shown;
                    self.session.say(if shown {
                        "the side panel is back"
                    } else {
                        "the side panel is folded away: the view takes the window's width (View > Panels brings it back)"
                    });
                }
            });
            ui.menu_button("Edit", |ui| {
                if ui.add_enabled(self.session.can_undo(), egui::Button::new("Undo  (Ctrl+Z)")).clicked() {
                    self.undo();
                }
                if ui.add_enabled(self.session.can_redo(), egui::Button::new("Redo  (Ctrl+Shift+Z)")).clicked() {
                    self.redo();
                }
            });
        });
    }

    /// How EXR files are written (the document's `exr`, as `--exr-type` and `--exr-compression` set it).
    fn exr_settings_ui(&mut self, ui: &mut egui::Ui) {
        use flare_core::output::{ExrCompression, ExrPixel};
        let exr = self.session.doc().exr;
        let (mut pixel, mut compression) = (exr.pixel_type, exr.compression);
        ui.horizontal(|ui| {
            ui.label("EXR");
            egui::ComboBox::from_id_salt("exr values")
                .selected_text(pixel.name())
                .show_ui(ui, |ui| {
                    for p in ExrPixel::ALL {
                        ui.selectable_value(&mut pixel, p, p.name());
                    }
                })
                .response
                .on_hover_text("auto: half where a layer's values fit (the ghost layers), float for the light's core");
            egui::ComboBox::from_label("EXR compression").selected_text(compression.name()).show_ui(ui, |ui| {
                for c in ExrCompression::ALL {
                    ui.selectable_value(&mut compression, c, c.name());
                }
            });
        });
        if (pixel, compression) != (exr.pixel_type, exr.compression) {
            let e = &mut self.session.edit().exr;
            e.pixel_type = pixel;
            e.compression = compression;
        }
    }

    /// The status bar: one row of fixed height (issue 60: it grew to 5-7 lines and moved the Cancel buttons
    /// under the pointer). Left to right: every job with its progress and Cancel, what the last action said, and
    /// the frame in a few words; the frame's details (sprites, culling, GPU pass times, motion blur) on hover.
    fn status_ui(&mut self, ui: &mut egui::Ui) {
        let dt_ms = ui.ctx().input(|i| i.unstable_dt) * 1e3;
        let light = self.derived.light_deg(self.session.doc());
        let frame_details = format!(
            "frame {} | light ({:.1}, {:.1}) deg | scene {:.2} ms, frame {:.1} ms at {}x{} | sprites drawn {}, culled {} dim / {} off sensor / {} empty entrance{}",
            self.view.playhead(),
            light[0],
            light[1],
            self.derived.scene_ms(),
            dt_ms,
            self.derived.view_px().0,
            self.derived.view_px().1,
            self.derived.stats().drawn,
            self.derived.stats().below_threshold,
            self.derived.stats().off_sensor,
            self.derived.stats().empty_entrance_region,
            if self.derived.lut().is_some() { " | LUT ghosts on" } else { "" }
        );
        // One line, always there: whether the view shows a draft, and the GPU's own time of the flare's passes.
        let quality = match self.derived.draft_shown() {
            Some(d) => format!(
                "draft while dragging: 1/{} resolution, the {} brightest of {} sprites (aiming at {:.0} ms a frame); full quality when you let go",
                d.divisor,
                d.drawn,
                d.drawn + d.skipped,
                draft::TARGET_MS
            ),
            None => "full quality".to_owned(),
        };
        let shutter = self.derived.view_frame().as_ref().and_then(|(_, f)| f.shutter.clone());
        let quality = match shutter {
            Some(s) => format!(
                "{quality} | motion blur: up to {} time samples over the open shutter ({:.1} a ghost on average; the \
                 fastest ghost moves {:.0} px)",
                s.count,
                s.mean_per_ghost(),
                s.longest_px
            ),
            None => quality,
        };
        // The viewport draws only when the frame changes; until the last frame's timestamps are back, UI frames
        // keep coming so that it can take them (else the times shown would be those of the frame before: a draft's).
        let pending = self.gpu_times_pending();
        if pending {
            ui.ctx().request_repaint_after(std::time::Duration::from_millis(50));
        }
        // lavapipe's timestamps misplace its compute work (in other scopes, or in none: the README's benchmark
        // section): said beside them.
        let gpu_time = match (self.gpu.as_ref(), self.gpu_pass_times()) {
            (_, Some((adapter, times))) => format!(
                "GPU time ({adapter}, timestamp queries{}){}: {}",
                if self.derived.software() { ", unreliable on a software adapter" } else { "" },
                if pending { ", the frame before (this one's not back yet)" } else { "" },
                times.summary()
            ),
            (Some(_), None) if pending => "GPU time: waiting for the frame's timestamps".to_owned(),
            (Some(_), None) => "GPU time: not measured (this adapter has no timestamp queries)".to_owned(),
            (None, None) => "no GPU".to_owned(),
        };
        let short = format!(
            "frame {} | light ({:.1}, {:.1}) deg | {} sprites{} | {}",
            self.view.playhead(),
            light[0],
            light[1],
            self.derived.stats().drawn,
            if self.derived.lut().is_some() { ", LUT ghosts on" } else { "" },
            if self.derived.draft_shown().is_some() { "draft while dragging" } else { "full quality" },
        );
        let details = format!("{frame_details}\n{quality}\n{gpu_time}");
        ui.horizontal(|ui| {
            ui.set_height(ui.spacing().interact_size.y);
            ui.style_mut().wrap_mode = Some(egui::TextWrapMode::Truncate);
            self.jobs.status_ui(ui, self.derived.lut().is_some());
            // What the last action did (or why it failed) stays here until the next one says something.
            if let Some(message) = self.session.message().map(str::to_owned) {
                let room = (ui.available_width() - 260.0).max(120.0);
                ui.allocate_ui_with_layout(
                    egui::vec2(room, ui.spacing().interact_size.y),
                    egui::Layout::left_to_right(egui::Align::Center),
                    |ui| {
                        ui.set_max_width(room);
                        if ui.small_button("x").on_hover_text("dismiss").clicked() {
                            self.session.hush();
                        }
                        let text = egui::RichText::new(&message).color(egui::Color32::from_rgb(255, 170, 90));
                        ui.add(egui::Label::new(text).truncate()).on_hover_text(&message);
                    },
                );
            }
            ui.add(egui::Label::new(short).truncate()).on_hover_text(details);
        });
    }

    /// The display settings under the view: the exposures, then the ghosts' method and the starburst, in one
    /// row where the view is `DISPLAY_ONE_ROW` wide (`DISPLAY_ONE_ROW_WITH_PLATE` with a plate), else in two (a slider and its value never part).
    fn display_ui(&mut self, ui: &mut egui::Ui) {
        let plate = self.session.doc().background.is_some();
        if ui.available_width() >= if plate { DISPLAY_ONE_ROW_WITH_PLATE } else { DISPLAY_ONE_ROW } {
            ui.horizontal(|ui| {
                self.exposure_ui(ui);
                self.ghosts_method_ui(ui);
            });
        } else {
            ui.horizontal(|ui| self.exposure_ui(ui));
            ui.horizontal(|ui| self.ghosts_method_ui(ui));
        }
    }

    /// The exposures: the flare's (with "auto") and, with a plate, the plate's.
    fn exposure_ui(&mut self, ui: &mut egui::Ui) {
        // Exposures in stops: the flare's relative irradiance times 2^EV, the plate as shot at 0 EV. Moving
        // the flare's exposure locks it; "auto" hands it back to the optics.
        // The slider shows the exposure the view uses (the automatic one is derived, never written into the
        // document); moving it writes the user's value and locks it.
        let mut ev = self.derived.flare_ev(self.session.doc());
        let moved = stops_slider(ui, &mut ev, -4.0..=28.0, "flare exposure", None).changed();
        if moved {
            self.session.edit().flare_ev = ev;
            self.session.edit().exposure_auto = false;
        }
        let mut auto = self.session.doc().exposure_auto;
        let toggled = ui
            .checkbox(&mut auto, "auto")
            .on_hover_text(
                "the brightest ghost at a fixed display level, set again when the lens, coating or stop change",
            )
            .changed();
        if toggled {
            // Locking keeps the exposure shown: the automatic value becomes the user's.
            if !auto {
                self.session.edit().flare_ev = self.derived.flare_ev(self.session.doc());
            }
            self.session.edit().exposure_auto = auto;
        }
        if self.session.doc().background.is_some() {
            stops_slider(ui, &mut self.session.edit().plate_ev, -8.0..=8.0, "plate exposure", None);
        }
    }

    /// The ghosts' method (the look or a ray grid) and the starburst.
    fn ghosts_method_ui(&mut self, ui: &mut egui::Ui) {
        let before = self.jobs.raygrid().grid;
        let ghosts_label = |grid: Option<usize>| match grid {
            None => "look".to_owned(),
            Some(n) => format!("ray grid {n}"),
        };
        egui::ComboBox::from_label("ghosts")
            .selected_text(ghosts_label(self.jobs.raygrid().grid))
            .width(90.0)
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut self.jobs.raygrid_mut().grid, None, "look (paraxial + LUT)");
                for n in jobs::raygrid_view::GRIDS {
                    ui.selectable_value(&mut self.jobs.raygrid_mut().grid, Some(n), format!("ray grid {n} (exact)"));
                }
            })
            .response
            .on_hover_text(
                "the view's ghosts ray-traced exactly on an N x N grid per ghost (Hullin 2011), on a hardware GPU when there is one: drafts while dragging, traced when input stops; exports draw the look",
            );
        // A change of what the view draws is said (a view setting, not the document: undo does not take it back).
        let after = self.jobs.raygrid().grid;
        if after != before {
            self.session.say(match after {
                None => "the view's ghosts: the look (paraxial and LUT ghosts)".to_owned(),
                Some(n) => format!(
                    "the view's ghosts: ray grid {n}, traced exactly when input stops (drafts while dragging); \
                     exports still draw the look"
                ),
            });
        }
        ui.checkbox(&mut self.session.edit().starburst, "starburst");
        if self.session.doc().starburst {
            let what = "the starburst's brightness against the physical one (0 EV)";
            stops_slider(ui, &mut self.session.edit().starburst_ev, -12.0..=4.0, "starburst", Some(what));
        }
    }

    /// The viewport: the flare, the light's drag and arrow keys, a click selects the ghost under it.
    fn viewport_ui(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        let avail = ui.available_size();
        let (outer, _) = ui.allocate_exact_size(avail, egui::Sense::hover());
        let export = self.export_px();
        let shape = view_shape(avail, export, self.session.doc().background.is_some());
        let rect = egui::Rect::from_center_size(outer.center(), shape.size);
        let response = ui.interact(rect, egui::Id::unique("flare viewport"), egui::Sense::click_and_drag());
        let px = self.view.layout(rect, ui.ctx().pixels_per_point());
        if px != self.derived.view_px() {
            self.derived.set_view_px(px);
            self.sync_frame();
        }
        // Files dropped on the window: a background plate, a preset or a lens.
        let dropped: Vec<std::path::PathBuf> = ui.ctx().input(|i| {
            i.raw.dropped_files.iter().map(|f| f.path().to_path_buf()).filter(|p| !p.as_os_str().is_empty()).collect()
        });
        for path in dropped {
            self.open_dropped(&path);
        }
        if self.gpu.is_none() {
            ui.painter().rect_filled(rect, 0.0, egui::Color32::from_gray(10));
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "no wgpu device: no viewport",
                egui::FontId::proportional(16.0),
                egui::Color32::GRAY,
            );
        } else {
            FlareCallback::paint(ui.painter(), rect, self.derived.view_frame().clone());
            self.derived.painted();
            if let Some(band) = shape.export_band {
                export_guide(ui.painter(), rect, band, export);
            }
        }
        if response.dragged()
            && let Some(p) = response.interact_pointer_pos()
        {
            self.light_from_pointer(p);
        }
        if response.clicked()
            && let Some(p) = response.interact_pointer_pos()
        {
            if self.view.focus_pick() {
                self.focus_from_pointer(p, rect);
            } else {
                actions.push(Action::SelectGhost(self.ghost_at(p)));
            }
        }
        if response.hovered() || response.has_focus() {
            let step = 0.25;
            let light = self.derived.light_deg(self.session.doc());
            let mut moved = None;
            ui.input(|i| {
                for (key, dx, dy) in [
                    (egui::Key::ArrowLeft, -step, 0.0),
                    (egui::Key::ArrowRight, step, 0.0),
                    (egui::Key::ArrowUp, 0.0, step),
                    (egui::Key::ArrowDown, 0.0, -step),
                ] {
                    if i.key_pressed(key) {
                        moved = Some([(light[0] + dx).clamp(-85.0, 85.0), (light[1] + dy).clamp(-85.0, 85.0)]);
                    }
                }
            });
            if let Some(deg) = moved {
                self.set_light(deg);
            }
        }
        self.overlay_ui(ui, rect);
    }

    /// The one mapping between the viewport's points and the live optics (see [`view::LightMap`]).
    fn light_map(&self) -> Option<view::LightMap<'_>> {
        let flare = self.derived.flare().as_deref()?;
        let doc = self.session.doc();
        self.view.light_map(flare, self.derived.view_px(), doc.sensor_width_mm, doc.desqueeze)
    }

    /// Where the light's image (the starburst's centre) is drawn in the viewport, in points.
    pub fn light_on_screen(&self) -> Option<egui::Pos2> {
        Some(self.light_map()?.light_on_screen(self.derived.light_deg(self.session.doc())))
    }

    /// A sprite's centre and radius in the viewport (points; at least 4 so that a tiny one can be clicked).
    fn sprite_on_screen(map: &view::LightMap<'_>, s: &flare_core::ghost::Sprite) -> (egui::Pos2, f32) {
        let c = map.to_screen(s.centre_mm);
        let edge =
            map.to_screen([s.centre_mm[0] + s.half_size_mm[0].abs().max(s.half_size_mm[1].abs()), s.centre_mm[1]]);
        (c, (edge.x - c.x).abs().max(4.0))
    }

    /// The light's marker and the selected ghost's ring.
    fn overlay_ui(&self, ui: &egui::Ui, rect: egui::Rect) {
        let painter = ui.painter().with_clip_rect(rect);
        let Some(map) = self.light_map() else { return };
        let Some(flare) = &self.derived.flare() else { return };
        let p = map.light_on_screen(self.derived.light_deg(self.session.doc()));
        painter.circle_stroke(p, 7.0, egui::Stroke::new(1.5, egui::Color32::from_rgb(255, 230, 120)));
        let Some(g) = self.session.selected() else { return };
        for s in self.derived.sprites().iter().filter(|s| s.ghost == g && s.wavelength == 1) {
            let (c, r) = Self::sprite_on_screen(&map, s);
            painter.circle_stroke(c, r, egui::Stroke::new(2.0, egui::Color32::from_rgb(255, 60, 200)));
            let m = &flare.system.ghosts[g];
            painter.text(
                c + egui::vec2(r * 0.7, -r * 0.7),
                egui::Align2::LEFT_BOTTOM,
                format!("{}-{}", m.i, m.j),
                egui::FontId::proportional(14.0),
                egui::Color32::from_rgb(255, 60, 200),
            );
        }
    }

    /// The brightest drawn ghost whose (green) sprite covers `p`, if any.
    fn ghost_at(&self, p: egui::Pos2) -> Option<usize> {
        let map = self.light_map()?;
        let mut best: Option<(usize, f64)> = None;
        for s in self.derived.sprites().iter().filter(|s| s.culled.is_none() && s.wavelength == 1) {
            let (c, r) = Self::sprite_on_screen(&map, s);
            let m = &self.derived.ghosts()[s.ghost];
            let lum = m.intensity() * self.session.doc().ghost_gain(m.i, m.j);
            if c.distance(p) <= r && lum > 0.0 && best.is_none_or(|(_, b)| lum > b) {
                best = Some((s.ghost, lum));
            }
        }
        best.map(|(g, _)| g)
    }

    /// Puts the light where the pointer is, through the lens's own mapping (it may leave the frame: its ghosts
    /// keep coming; past the lens's traced field the paraxial mapping continues it).
    fn light_from_pointer(&mut self, pointer: egui::Pos2) {
        if let Some(deg) = self.light_map().and_then(|map| map.light_deg_at(pointer)) {
            self.set_light(deg);
        }
    }

    fn keys(&mut self, ctx: &egui::Context) {
        let (undo, redo) = ctx.input_mut(|i| {
            let redo = i.consume_key(egui::Modifiers::COMMAND | egui::Modifiers::SHIFT, egui::Key::Z)
                || i.consume_key(egui::Modifiers::COMMAND, egui::Key::Y);
            let undo = i.consume_key(egui::Modifiers::COMMAND, egui::Key::Z);
            (undo, redo)
        });
        if redo {
            self.redo();
        } else if undo {
            self.undo();
        }
    }

    fn act(&mut self, action: Action) {
        match action {
            Action::SelectGhost(g) => self.session.select(g),
            Action::Message(text) => self.session.say(text),
            Action::EditCoating(k) => {
                self.coatings.surface = k;
                self.ui.tab = Tab::Coatings;
            }
            Action::OpenLensFile => self.pick_file(FileUse::OpenLens),
            Action::Bake => {
                let live = Self::live(&self.session, &self.derived);
                self.jobs.start_bake(&live);
            }
            Action::SetAutoBake(on) => {
                self.jobs.set_auto_bake(on);
                if !on {
                    self.derived.drop_auto_lut(self.gpu.as_ref());
                }
            }
            Action::CancelBake => self.jobs.cancel_bake(),
            Action::OpenLut => self.pick_file(FileUse::OpenLut),
            Action::ExportLut => {
                if self.derived.lut().is_none() {
                    let why = self.no_lut_to_export();
                    self.session.say(why);
                    return;
                }
                self.pick_file(FileUse::ExportLut);
            }
            Action::OpenApertureImage => self.pick_file(FileUse::ApertureImage),
            Action::OpenDirtImage => self.pick_file(FileUse::DirtImage),
        }
    }

    /// Adds a glass catalogue (.agf): lens files opened afterwards may name its glasses, and the open lens
    /// takes their dispersion when it names them. A broken file adds nothing and says where.
    pub fn add_glass_catalogue(&mut self, path: &std::path::Path) {
        self.session.say(match flare_core::optics::formats::load_glass_catalogue(path) {
            Ok(n) => {
                // The lens may name glasses it now finds: rebuild what depends on its dispersion.
                self.derived.invalidate_optics();
                format!("{}: {n} glasses added", path.display())
            }
            Err(e) => e,
        });
    }

    /// Opens a lens file into the document; a bad file leaves the document as it was.
    pub fn open_lens(&mut self, path: &std::path::Path) {
        match read_lens_file(path) {
            Ok(LoadedLens { lens, warnings }) => {
                // Said either way, replacing the message before: the file's first warning, or that it opened.
                self.session.say(match warnings.first() {
                    Some(w) => {
                        let more = if warnings.len() > 1 {
                            format!(" (and {} more in the Lens panel)", warnings.len() - 1)
                        } else {
                            String::new()
                        };
                        format!("{}: {w}{more}", path.display())
                    }
                    None => format!("opened {} ({} surfaces)", path.display(), lens.surfaces.len()),
                });
                self.lens_warnings = Some((lens.id.clone(), warnings));
                self.session.edit().lens = lens;
                self.session.edit().aperture.f_number = None;
                self.session.edit().ghosts.clear();
                self.session.edit().solo = None;
                self.session.select(None);
            }
            Err(e) => self.session.say(format!("{}: {e}", path.display())),
        }
    }

    /// Opens a `.flut`: a photo LUT for any lens, a ray-traced one only for the lens it was baked for.
    pub fn open_lut(&mut self, path: &std::path::Path) {
        let Some(flare) = self.derived.flare().clone() else { return };
        match flare_core::lut::format::read_lut(path) {
            Ok(lut) => {
                if lut.kind == LutKind::RayTraced
                    && let Err(e) = lut.check_for(&self.session.doc().lens, &flare.config)
                {
                    self.session.say(format!("{}: {e}", path.display()));
                    return;
                }
                let p = path.display().to_string();
                self.session.edit().blend.lut = if lut.kind == LutKind::Photo {
                    LutSource::Photo { path: p }
                } else {
                    LutSource::Simulated { path: Some(p) }
                };
                self.set_lut(Some(lut));
                self.session.hush();
            }
            Err(e) => self.session.say(format!("{}: {e}", path.display())),
        }
    }

    fn open_dropped(&mut self, path: &std::path::Path) {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        match ext.as_str() {
            "png" | "exr" | "hdr" | "jpg" | "jpeg" => self.set_background(path),
            "csv" => self.import_track(path),
            "flut" => self.open_lut(path),
            "zmx" | "dat" => self.open_lens(path),
            "json" => match Document::open(path) {
                Ok(doc) => {
                    self.session.open(doc);
                }
                Err(_) => self.open_lens(path),
            },
            _ => self.session.say(format!("{}: drop a lens, a preset, a LUT or an image", path.display())),
        }
    }

    /// Opens a preset file as the new document (a bad file changes nothing).
    fn open_preset_file(&mut self, path: &std::path::Path) {
        match Document::open(path) {
            Ok(doc) => {
                self.session.open(doc);
                self.session.say(format!("opened {}", path.display()));
            }
            // The document in the window stays as it was.
            Err(e) => self.session.say(format!("{}: {e}", path.display())),
        }
    }

    fn save_preset_to(&mut self, path: &std::path::Path) {
        // With the exposure the view shows, also when it is automatic (the file says so; a reader resolves it).
        self.session.say(match self.derived.resolved(self.session.doc()).save(path) {
            Ok(()) => format!("saved {}", path.display()),
            Err(e) => format!("could not save {}: {e}", path.display()),
        });
    }

    /// Why there is no LUT to export: a bake still running (with how far it is), or none baked or opened.
    fn no_lut_to_export(&self) -> String {
        match self.jobs.bake_status() {
            BakeStatus::Running { fraction, text } => format!(
                "no LUT to export yet: the bake is at {:.0} % ({text}); export it when it lands",
                100.0 * fraction
            ),
            _ => "no LUT to export: bake one (Blend panel) or open one".to_owned(),
        }
    }

    /// Writes the LUT in use to `path`.
    fn export_lut_to(&mut self, path: &std::path::Path) {
        let Some(live) = self.derived.lut().clone() else {
            let why = self.no_lut_to_export();
            self.session.say(why);
            return;
        };
        self.session.say(match flare_core::lut::format::write_lut(path, &live.lut) {
            Ok(bytes) => format!("wrote {} ({:.1} MB)", path.display(), bytes as f64 / 1e6),
            Err(e) => format!("could not write {}: {e}", path.display()),
        });
    }

    /// Uses a grey image as the stop (a bad image changes nothing).
    fn use_aperture_image(&mut self, path: &std::path::Path) {
        let size = flare_core::aperture::DEFAULT_MASK_SIZE;
        match flare_core::aperture::Aperture::image_shape_from_file(path, size) {
            Ok(_) => {
                self.session.edit().aperture.image = Some(path.display().to_string());
                self.session.say(format!("aperture image {}", path.display()));
            }
            Err(e) => self.session.say(e.to_string()),
        }
    }

    /// Uses the grey image at `path` as the front element's dirt (read first: a bad file is refused with the
    /// reason and the document keeps its dirt).
    fn use_dirt_image(&mut self, path: &std::path::Path) {
        match flare_core::dirt::DirtPattern::image_from_file(path) {
            Ok(_) => {
                let dirt = &mut self.session.edit().dirt;
                dirt.pattern = flare_core::dirt::DirtKind::Image;
                dirt.image = Some(path.display().to_string());
                self.session.say(format!("dirt image {}", path.display()));
            }
            Err(e) => self.session.say(e.to_string()),
        }
    }

    /// Renders the document's frame at the export size through the CPU twin and writes PNG (8-bit,
    /// tonemapped) or EXR (linear), chosen by the file name, on a thread: the status bar shows it with Cancel
    /// (a cancelled export writes nothing), and the window goes on meanwhile (a blended 1920x1080 frame takes
    /// seconds on the CPU).
    pub fn export_image_file(&mut self, path: &std::path::Path) {
        if self.jobs.exporting_image() {
            self.session.say("an export is running: wait for it or cancel it");
            return;
        }
        let prepared = match self.export_frame(self.export_px()) {
            Ok(p) => p,
            Err(e) => {
                self.session.say(format!("could not export {}: {e:#}", path.display()));
                return;
            }
        };
        let target = path.to_path_buf();
        let choice = self.session.doc().layer_choice(false);
        let job = jobs::job::Job::spawn("drawing the frame on the CPU", move |cancel, report| {
            let (frame, flare, lut, plate) = prepared;
            let plate = plate.resolve(&flare, report)?;
            let sources = Sources { flare: &flare, lut: lut.as_deref(), plate: plate.as_deref() };
            let mut device = Device::Cpu;
            // An EXR's frame without its display image (the file holds none): see `frame::Made`.
            let made = flare_core::frame::draw_for_file(&mut device, &frame, &sources, choice, &target)
                .map_err(|e| e.to_string())?;
            if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                return Err("cancelled: nothing written".into());
            }
            report(0.5, format!("writing {}", target.display()));
            flare_core::frame::write_made(&mut device, &frame, &sources, &made, choice, &target)
                .map_err(|e| e.to_string())
        });
        self.session.say(format!("exporting {}", path.display()));
        if let Err(e) = self.jobs.start_export(path, job) {
            self.session.say(e);
        }
    }

    /// What the job board needs of the live state.
    fn live<'a>(session: &'a Session, derived: &'a Derived) -> Live<'a> {
        Live {
            doc: session.doc(),
            flare: derived.flare().as_ref(),
            optics_key: derived.optics_key(),
            lens_refused: derived.lens_problem().is_some(),
            lut_shown: derived.lut().is_some(),
        }
    }

    /// Polls every job (see [`jobs`]) and takes what they hand back: a LUT to show (drawn by the frame source
    /// without writing the document: [`Derived::show_auto_lut`]), the light found, what to say.
    fn poll_jobs(&mut self) {
        let live = Self::live(&self.session, &self.derived);
        for event in self.jobs.poll(&live) {
            match event {
                JobEvent::Say(text) => self.session.say(text),
                JobEvent::ShowLut(live, atlas) => self.derived.show_auto_lut(live, atlas, self.gpu.as_ref()),
                JobEvent::LightFound(plan) => self.derived.set_shot_plan(Some(plan)),
            }
        }
    }

    /// Whether the viewport's last frame's GPU times have yet to come back (see `FlareRenderer::pass_times_pending`).
    fn gpu_times_pending(&self) -> bool {
        self.gpu
            .as_ref()
            .and_then(|rs| ViewportResources::read(rs, |res| res.renderer.pass_times_pending()))
            .unwrap_or(false)
    }

    /// The adapter's name and the GPU pass times of the latest viewport frame whose timestamps came back.
    fn gpu_pass_times(&self) -> Option<(String, flare_core::render::gpu::PassTimes)> {
        let rs = self.gpu.as_ref()?;
        let times = ViewportResources::read(rs, |res| res.renderer.pass_times().cloned())??;
        Some((rs.adapter.get_info().name, times))
    }

    /// Whether this UI frame draws a draft (see [`draft`]): while a drag moves (the light, a slider, a drag
    /// value), an arrow key is held or the drag bench sweeps. The frame is rebuilt when that changes.
    fn draft_step(&mut self, ctx: &egui::Context) {
        let dragging =
            ctx.dragged_id().is_some() && ctx.input(|i| i.pointer.time_since_last_movement() < draft::STILL_S);
        let arrows = ctx.input(|i| {
            [egui::Key::ArrowLeft, egui::Key::ArrowRight, egui::Key::ArrowUp, egui::Key::ArrowDown]
                .iter()
                .any(|k| i.key_down(*k))
        });
        let sweeping = self.drag_bench.as_ref().is_some_and(DragBench::sweeping);
        let flare_gpu_ms = self.gpu_pass_times().map(|(_, t)| t.total_ms());
        let draft = self.view.draft_step(dragging || arrows || sweeping, flare_gpu_ms);
        if draft.is_some() && !sweeping {
            // Refine to the full frame once the pointer rests, even if nothing else repaints.
            ctx.request_repaint_after(std::time::Duration::from_secs_f32(draft::STILL_S));
        }
        if draft != self.derived.draft() {
            self.derived.set_draft(draft);
            self.sync_frame();
        }
    }

    /// Warms the draft passes on a software adapter ([`draft::DraftWarmth`]), outside a drag (a drag's own
    /// drafts need no warming) and never in the UI frame that hands the viewport its first frame (that frame
    /// is not delayed by the warm-up's GPU work).
    fn warm_drafts(&mut self, ctx: &egui::Context) {
        use draft::DraftWarmth::{AwaitingCube, Cold, Shown, Warm};
        let Some(rs) = self.gpu.as_ref().filter(|_| self.drafts_warmth != Warm) else { return };
        let Some((_, shown)) = self.derived.view_frame() else { return };
        if self.drafts_warmth == Cold {
            self.drafts_warmth = Shown;
            ctx.request_repaint();
            return;
        }
        if self.derived.draft().is_some() {
            return;
        }
        if self.drafts_warmth == AwaitingCube && !ViewportResources::draft_through_cube(&shown.scene) {
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
            return;
        }
        let first = draft::DraftControl::first_draft(true);
        let Some(frame) = self.derived.draft_of_view(self.session.doc(), first) else { return };
        self.drafts_warmth = match ViewportResources::warm_up_drafts(rs, &frame) {
            Some(false) if self.drafts_warmth == Shown => {
                ctx.request_repaint_after(std::time::Duration::from_millis(250));
                AwaitingCube
            }
            _ => Warm,
        };
    }

    /// One frame of the drag bench (see [`DragBench`]); closes the window when it is done.
    fn drag_bench_step(&mut self, ctx: &egui::Context) {
        let flare_gpu = self.gpu_pass_times().map(|(adapter, t)| (adapter, t.total_ms(), t.summary()));
        let Some(bench) = &mut self.drag_bench else { return };
        match bench.step(
            self.session.edit(),
            self.view.playhead_mut(),
            self.derived.scene_ms(),
            self.derived.rebuilds(),
            self.derived.view_px(),
            self.derived.draft_shown(),
            flare_gpu,
        ) {
            Some(line) => {
                println!("{line}");
                self.drag_bench = None;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            None => ctx.request_repaint(),
        }
    }
}

/// The side panel's scroll area: it fills the panel and scrolls up and down; its content is laid out to the
/// panel's width (text wraps, tables are made to fit it: a test holds every tab inside), so no tab's content can
/// widen the panel (the panel keeps its width across tabs).
fn panel_scroll() -> egui::ScrollArea {
    egui::ScrollArea::vertical().id_salt("panel_scroll").auto_shrink([false, false])
}

/// The recent files from eframe's storage (none when absent or unreadable).
pub fn restore_recent(storage: &dyn eframe::Storage) -> Vec<std::path::PathBuf> {
    let text = storage.get_string(RECENT_KEY).unwrap_or_default();
    let paths: Vec<String> = serde_json::from_str(&text).unwrap_or_default();
    paths.into_iter().map(std::path::PathBuf::from).take(files::RECENT).collect()
}

/// The last session's document from eframe's storage, if there is a valid one (a damaged or newer one is
/// ignored, with the reason on stderr, and the app starts from the default).
pub fn restore(storage: &dyn eframe::Storage) -> Option<Document> {
    let text = storage.get_string(STORAGE_KEY)?;
    match Document::from_json(&text) {
        Ok(doc) => Some(doc),
        Err(e) => {
            eprintln!("flarelab: the last session could not be restored ({e}); starting from the default");
            None
        }
    }
}

impl FlareLabApp {
    /// The document's frame at the playhead at `size` (pixels), drawn by the CPU twin through the one frame pipeline and
    /// written by the one writer (PNG tonemapped, EXR linear with layers), exactly as `flarelab render
    /// --preset` of this document with `--size` and `--device cpu` does.
    pub fn export_image_to(&self, size: (u32, u32), path: &std::path::Path) -> Result<()> {
        let (frame, flare, lut, plate) = self.export_frame(size)?;
        let plate = plate.resolve(&flare, &|_, _| {}).map_err(|e| anyhow::anyhow!(e))?;
        let sources = Sources { flare: &flare, lut: lut.as_deref(), plate: plate.as_deref() };
        let choice = self.session.doc().layer_choice(false);
        flare_core::frame::render_to_file(&mut Device::Cpu, &frame, &sources, choice, path)?;
        Ok(())
    }

    /// The size an export draws at: the user's, else the plate's, else [`DEFAULT_EXPORT_PX`].
    pub fn export_px(&self) -> (u32, u32) {
        self.export_size
            .or_else(|| self.derived.plate().as_ref().map(|p| (p.width, p.height)))
            .unwrap_or(DEFAULT_EXPORT_PX)
    }

    /// The frame an export draws at `size` and what it reads, owned (for a thread).
    #[allow(clippy::type_complexity)]
    fn export_frame(
        &self,
        size: (u32, u32),
    ) -> Result<(
        Frame,
        std::sync::Arc<flare_core::flare::PreparedFlare>,
        Option<std::sync::Arc<flare_core::lut::blend::LiveLut>>,
        ExportPlate,
    )> {
        let Some(flare) = self.derived.flare().clone() else { bail!("no valid lens") };
        // Refused before any work when the frame would need more memory than it may take.
        let plate = self.derived.plate().is_some();
        flare_core::frame::check_frame_memory(size.0, size.1, self.session.doc().desqueeze, plate)?;
        let request = self.derived.request_at(self.session.doc(), &flare, size.0, size.1, 1);
        let frame = Frame::build(&flare, self.derived.lut().as_deref(), &request);
        // The plate the view shows, or the sharp one to defocus on the export's thread when the view's depth
        // of field is not done yet (an export never waits for the view, nor goes out without its DoF).
        let plate = if self.jobs.dof().ready(&self.derived, self.session.doc()) {
            ExportPlate::Ready(self.derived.plate().clone())
        } else {
            ExportPlate::Defocus(
                Box::new(self.derived.resolved(self.session.doc())),
                self.view.playhead(),
                self.derived.sharp_plate().clone(),
            )
        };
        Ok((frame, flare, self.derived.lut().clone(), plate))
    }
}

/// The plate of an export: ready, or to be defocused first (the document, its frame, the sharp plate).
pub enum ExportPlate {
    Ready(Option<std::sync::Arc<flare_core::image::HdrImage>>),
    Defocus(Box<Document>, i64, Option<std::sync::Arc<flare_core::image::HdrImage>>),
}

impl ExportPlate {
    /// The plate to draw under the flare, defocused first when it has to be (the CPU live method or the
    /// reference, as the document says: what the command line draws from the same preset).
    fn resolve(
        self,
        flare: &flare_core::flare::PreparedFlare,
        report: &(dyn Fn(f32, String) + Sync),
    ) -> Result<Option<std::sync::Arc<flare_core::image::HdrImage>>, String> {
        match self {
            Self::Ready(plate) => Ok(plate),
            Self::Defocus(_, _, None) => Ok(None),
            Self::Defocus(doc, frame, Some(sharp)) => {
                report(0.1, "the plate's depth of field".into());
                flare_core::shot::plate::defocus(&doc, flare, frame, &sharp).map(|p| Some(std::sync::Arc::new(p)))
            }
        }
    }
}

impl eframe::App for FlareLabApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let began = (std::time::SystemTime::now(), std::time::Instant::now());
        let (lut_before, looks_before) = (self.derived.lut().is_some(), self.jobs.looks().ready());
        self.ui_root(ui);
        let gpu = self.frame_log.as_ref().and_then(|_| self.gpu_pass_times()).map(|(_, t)| t.summary());
        if let Some(log) = &mut self.frame_log {
            if let Some(summary) = gpu {
                log.gpu(&summary);
            }
            if self.derived.lut().is_some() && !lut_before {
                log.event("lut-shown");
            }
            if self.jobs.looks().ready() && !looks_before {
                log.event("looks-ready");
            }
            log.frame(began.0, began.1.elapsed(), frame.info().cpu_usage);
        }
    }

    /// The panels' colour (gamma-encoded, as egui's non-sRGB target takes it): the window's background, drawn
    /// by the render pass's clear instead of by filling each panel ([`FlareLabApp::cleared_by_window`]).
    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        visuals.panel_fill.to_normalized_gamma_f32()
    }

    /// The session is stored as the preset's JSON (RON, eframe's own format, cannot carry the lens's free-form
    /// extra fields), and read back through the preset loader with all its checks ([`restore`]).
    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        storage.set_string(STORAGE_KEY, self.session.doc().to_json());
        let recent: Vec<String> = self.files.recent.iter().map(|p| p.display().to_string()).collect();
        storage.set_string(RECENT_KEY, serde_json::to_string(&recent).unwrap_or_default());
        self.ui.store(storage);
    }
}

/// The width (points) the display settings under the view need in one row, and with a plate's exposure too.
const DISPLAY_ONE_ROW: f32 = 840.0;
const DISPLAY_ONE_ROW_WITH_PLATE: f32 = 1160.0;

/// The side panel's least width (points): what the widest tab's table (the Lens table) needs without a
/// sideways scroll.
const PANEL_MIN_WIDTH: f32 = 360.0;

/// The viewport's size in the room it has, and where in it the exported frame lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewShape {
    /// The viewport's size (points), centred in the room.
    pub size: egui::Vec2,
    /// The exported frame's rows as a fraction of the viewport's height, top and bottom, where the viewport
    /// shows more than it (`None`: the viewport is the exported frame).
    pub export_band: Option<(f32, f32)>,
}

/// The viewport in `room` (points) for a frame exported at `export` pixels: the frame spans the sensor's
/// width across the viewport's, so a viewport as wide as the room and taller than the exported frame shows it
/// whole, with more of the sensor above and below (marked by [`export_guide`]); a room wider than the
/// exported frame's shape gets the frame's shape, centred. With a plate the viewport is the plate's shape
/// (the plate spans the frame).
pub fn view_shape(room: egui::Vec2, export: (u32, u32), plate: bool) -> ViewShape {
    let aspect = export.0.max(1) as f32 / export.1.max(1) as f32;
    let room = egui::vec2(room.x.max(16.0), room.y.max(16.0));
    if plate || room.x / room.y > aspect {
        let width = room.x.min(room.y * aspect);
        return ViewShape { size: egui::vec2(width, width / aspect), export_band: None };
    }
    let band = room.x / aspect / room.y;
    let export_band = (band < 0.995).then_some((0.5 - 0.5 * band, 0.5 + 0.5 * band));
    ViewShape { size: room, export_band }
}

/// The exported frame's outline in the viewport `rect` (its rows `band`, [`ViewShape::export_band`]), what lies
/// outside it dimmed, and its size in the outline's corner.
fn export_guide(painter: &egui::Painter, rect: egui::Rect, band: (f32, f32), export: (u32, u32)) {
    let (top, bottom) = (rect.top() + band.0 * rect.height(), rect.top() + band.1 * rect.height());
    let dim = egui::Color32::from_black_alpha(110);
    painter.rect_filled(egui::Rect::from_x_y_ranges(rect.x_range(), rect.top()..=top), 0.0, dim);
    painter.rect_filled(egui::Rect::from_x_y_ranges(rect.x_range(), bottom..=rect.bottom()), 0.0, dim);
    let frame = egui::Rect::from_x_y_ranges(rect.x_range(), top..=bottom);
    painter.rect_stroke(frame, 0.0, egui::Stroke::new(1.0, egui::Color32::from_gray(120)), egui::StrokeKind::Inside);
    painter.text(
        frame.left_top() + egui::vec2(6.0, 4.0),
        egui::Align2::LEFT_TOP,
        format!("export {}x{}", export.0, export.1),
        egui::FontId::proportional(11.0),
        egui::Color32::from_gray(150),
    );
}

/// Pixels of drag per stop on an exposure slider's track ([`stops_slider`]).
pub const STOPS_TRACK_PX_PER_EV: f32 = 6.0;
/// Stops per pixel of drag on an exposure slider's value: 50 px a stop, ten times finer with Shift held (egui's
/// own slow drag), a click on it to type one.
pub const STOPS_VALUE_EV_PER_PX: f64 = 0.02;
/// How an exposure slider is steered, said on hover.
const STOPS_HINT: &str =
    "Drag the track for whole stops, the value for fine steps (Shift: ten times finer), click it to type.";

/// An exposure slider in stops over `range` (its track wide enough for [`STOPS_TRACK_PX_PER_EV`] pixels a
/// stop; values beyond the track typed or dragged in its value box), labelled `label`, with `what` it sets and
/// how to steer it on hover.
pub fn stops_slider(
    ui: &mut egui::Ui,
    value: &mut f64,
    range: std::ops::RangeInclusive<f64>,
    label: &str,
    what: Option<&str>,
) -> egui::Response {
    let stops = (range.end() - range.start()) as f32;
    ui.scope(|ui| {
        ui.spacing_mut().slider_width = (stops * STOPS_TRACK_PX_PER_EV).max(ui.spacing().slider_width);
        ui.add(
            egui::Slider::new(value, range)
                .clamping(egui::SliderClamping::Never)
                .fixed_decimals(2)
                .drag_value_speed(STOPS_VALUE_EV_PER_PX)
                .suffix(" EV")
                .text(label),
        )
    })
    .inner
    .on_hover_text(what.map_or_else(|| STOPS_HINT.to_owned(), |w| format!("{w}. {STOPS_HINT}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The viewport's shape: a room taller than the exported frame is filled, the frame's rows marked; a wider
    /// room gets the frame's shape, centred; with a plate the plate's shape, always; a degenerate room or export
    /// size gives a finite shape.
    #[test]
    fn the_view_fills_a_tall_room_and_keeps_the_frames_shape_in_a_wide_one() {
        let tall = view_shape(egui::vec2(1048.0, 751.0), (1920, 1080), false);
        assert_eq!(tall.size, egui::vec2(1048.0, 751.0));
        let (top, bottom) = tall.export_band.unwrap();
        assert!(((bottom - top) * 751.0 - 1048.0 * 1080.0 / 1920.0).abs() < 1e-3 && (top + bottom - 1.0).abs() < 1e-6);
        let wide = view_shape(egui::vec2(1600.0, 600.0), (1920, 1080), false);
        assert!((wide.size.x - 600.0 * 16.0 / 9.0).abs() < 1e-3 && wide.size.y == 600.0 && wide.export_band.is_none());
        let plate = view_shape(egui::vec2(1048.0, 751.0), (1920, 1080), true);
        assert!((plate.size.y - 1048.0 * 9.0 / 16.0).abs() < 1e-3 && plate.export_band.is_none());
        let odd = view_shape(egui::vec2(0.0, -5.0), (0, 0), false);
        assert!(odd.size.x.is_finite() && odd.size.y.is_finite() && odd.size.x > 0.0 && odd.size.y > 0.0);
    }
}
