//! The job board: every piece of work the app runs on a thread, each kind in a module of this folder: the bake
//! ([`bake`]) and its automatic policy ([`autobake`]), File > Export image, the shot's jobs ([`shot`]: finding
//! the light and exporting a sequence), the depth of field ([`dof`]), the ray-grid view ([`raygrid_view`]), the
//! looks' thumbnails ([`looks`]) and the ghost report ([`report`]); polled in one place, shown in one status
//! row, bounded by one rule and run under one priority rule.
//!
//! # How it works
//! [`JobBoard`] owns the jobs and what they said (its fields are private; it is their only writer). Each UI
//! frame the app calls [`JobBoard::poll`] once with [`Live`], what the live document and optics are: it takes
//! the progress and outcome of the bake, the export and the shot job, runs the automatic bake's policy (see
//! [`autobake`]: the bake restarts only for the optics it serves, once an edit has stood, and keeps
//! finished ghosts) and hands the app back [`JobEvent`]s (a LUT to show, a light found, a sentence for the
//! status line); the board never touches the document or the frame source itself. The depth of field, the
//! ray-grid view, the looks and the report keep their own step (each needs its own inputs), but live here:
//! [`JobBoard::busy`] answers for all of them (the app repaints only while something runs) and
//! [`JobBoard::status_ui`] draws every running job's progress with its Cancel, in one row.
//!
//! **Bounded**: the bake, the cache lookup, a LUT's landing (its atlas made on a thread), the depth of field,
//! the ray-grid trace, the report and the shot job each sit in a [`job::Slot`]: at most one job of a kind runs; a new request cancels it (its thread is watched until it
//! ends, and each checks its cancel flag inside the loops that take time) and waits until it has ended, a
//! newer request replacing the waiting one. The export and the thumbnails run one at a time by their own rule
//! (a second export is refused; the thumbnails start once). **Priorities** ([`job::Priority`]): the window at
//! the app's; what the user waits for (a focus, an export, a sequence, a ray-grid trace, the report) is
//! interactive, a step below; what only improves the view later (the bake, the thumbnails) is background.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use eframe::egui;
use flare_core::bake::classify::GhostClass;
use flare_core::flare::PreparedFlare;
use flare_core::lut::blend::LiveLut;
use flare_core::preset::{Document, LutSource};
use flare_core::render::gpu::LutAtlas;
use flare_core::shot::plan::ShotPlan;
use flare_core::shot::sequence::SequenceReport;

use crate::panels::BakeStatus;
use autobake::{AutoBake, Baked};
use bake::BakeOutcome;
use dof::DofWork;
use job::{Done, Job, JobPoll, Slot};
use looks::Looks;
use raygrid_view::RayGridView;
use report::ReportState;
use shot::{ShotKind, ShotOutcome, ShotResult, light_key};

pub mod autobake;
mod autobake_step;
pub mod bake;
pub mod dof;
pub mod job;
pub mod looks;
pub mod raygrid_view;
pub mod report;
pub mod shot;

/// What the board needs to know of the live state to poll: the document, the prepared flare, its optics
/// key, whether the lens is refused, whether a LUT is on screen.
pub struct Live<'a> {
    pub doc: &'a Document,
    pub flare: Option<&'a Arc<PreparedFlare>>,
    pub optics_key: Option<u64>,
    pub lens_refused: bool,
    pub lut_shown: bool,
}

/// What a job hands the app (the board never writes the document or the frame source).
pub enum JobEvent {
    /// Says this in the status line (replacing what it said).
    Say(String),
    /// Put this LUT on screen: the background bake's (or the cache's) LUT ghosts for the live optics.
    ShowLut(Arc<LiveLut>, Option<LutAtlas>),
    /// The light found in the plates for the live document.
    LightFound(ShotPlan),
}

/// A LUT prepared for the view on a thread: the LUT, its atlas on the app's device, its classification (when
/// this session baked it) and where it came from.
struct Landing {
    live: Arc<LiveLut>,
    atlas: Option<LutAtlas>,
    classes: Option<Vec<GhostClass>>,
    source: String,
}

/// An image export on its thread: the file it writes and the job.
type ExportJob = (PathBuf, Job<Result<(), String>>);

/// The job board (see the module documentation).
pub struct JobBoard {
    /// The bake running (or waiting for a cancelled one to stop) and the cache key of the optics it is for.
    bake: Slot<u64, BakeOutcome>,
    bake_status: BakeStatus,
    /// The classification of the LUT on screen, when this session baked it.
    classes: Option<Vec<GhostClass>>,
    autobake: AutoBake,
    /// Reading the live optics' LUT from the disk cache and preparing it for the frame, on a thread.
    lookup: Slot<u64, autobake::Found>,
    /// A LUT about to be shown, its atlas texture made and filled on a thread (see [`LutAtlas`]).
    landing: Slot<u64, Landing>,
    /// The app's wgpu device and queue, for the atlases (`None` without a GPU: the tests' harness).
    device: Option<(wgpu::Device, wgpu::Queue)>,
    export: Option<ExportJob>,
    /// Finding the light or exporting a sequence: one shot job at a time.
    shot: Slot<ShotKind, ShotResult>,
    shot_status: String,
    /// What the light found in the plates was (or is being) found for.
    light_key: Option<u64>,
    last_export: Option<SequenceReport>,
    dof: DofWork,
    raygrid: RayGridView,
    looks: Looks,
    report: ReportState,
}

impl Default for JobBoard {
    fn default() -> Self {
        Self {
            bake: Slot::default(),
            bake_status: BakeStatus::Idle,
            classes: None,
            autobake: AutoBake::default(),
            lookup: Slot::default(),
            landing: Slot::default(),
            device: None,
            export: None,
            shot: Slot::default(),
            shot_status: String::new(),
            light_key: None,
            last_export: None,
            dof: DofWork::default(),
            raygrid: RayGridView::default(),
            looks: Looks::default(),
            report: ReportState::default(),
        }
    }
}

impl JobBoard {
    /// Polls every job with a thread of its own and runs the automatic bake (see the module documentation).
    pub fn poll(&mut self, live: &Live) -> Vec<JobEvent> {
        let mut events = Vec::new();
        self.poll_bake(live, &mut events);
        self.poll_landing(live, &mut events);
        self.poll_export(&mut events);
        self.poll_shot(&mut events);
        self.auto_bake_step(live, &mut events);
        events
    }

    /// True while any job runs (the app then repaints to show its progress).
    pub fn busy(&self) -> bool {
        self.bake.busy()
            || self.lookup.busy()
            || self.landing.busy()
            || self.export.is_some()
            || self.shot.busy()
            || self.dof.busy()
            || self.raygrid.busy()
            || self.looks.busy()
            || self.report.busy()
    }

    /// Every job in the status bar's one row: what it does (truncated to a fixed width, the whole text on
    /// hover), its progress and its Cancel, each item where the one before leaves it (nothing wraps, the row
    /// never grows); `lut_shown`: LUT ghosts are on screen (a bake then says they stay until it lands, not that
    /// the paraxial flare stands in).
    pub fn status_ui(&mut self, ui: &mut egui::Ui, lut_shown: bool) {
        // The bake first: it runs longest, so the items after it move least.
        if let (true, BakeStatus::Running { fraction, text }) = (self.bake.active(), &self.bake_status) {
            let meanwhile = if lut_shown { "the LUT ghosts shown" } else { "the paraxial flare" };
            let text = format!("baking LUT ghosts, {meanwhile} until then: {text}");
            if job_cell(ui, &text, Some(*fraction), "Cancel bake") {
                self.cancel_bake();
            }
        }
        if let Some((path, job)) = &self.export {
            let (fraction, text) = job.progress();
            if job_cell(ui, &format!("exporting {}: {text}", path.display()), Some(fraction), "Cancel export") {
                job.cancel();
            }
        }
        // A shot job, whichever panel is open.
        if let Some((fraction, _)) = self.shot.progress()
            && job_cell(ui, &self.shot_status, Some(fraction), "Cancel")
        {
            self.cancel_shot();
        }
        if let Some((fraction, text)) = self.looks.progress()
            && job_cell(ui, &text, Some(fraction), "Cancel looks")
        {
            self.looks.cancel();
        }
        if let Some((fraction, text)) = self.report.progress()
            && job_cell(ui, &format!("ghost report: {text}"), Some(fraction), "Cancel report")
        {
            self.report.cancel();
        }
        // The ray-grid view and the depth of field: what they show, or their work with Cancel, in a cell of the
        // same width either way (a job that ends moves nothing after it).
        match self.raygrid.progress() {
            Some((fraction, text)) => {
                if job_cell(ui, &text, Some(fraction), "Cancel trace") {
                    self.raygrid.cancel();
                }
            }
            None => status_cell(ui, &self.raygrid.status),
        }
        match self.dof.progress() {
            Some((fraction, text)) => {
                if job_cell(ui, &format!("depth of field: {text}"), Some(fraction), "Cancel defocus") {
                    self.dof.cancel();
                }
            }
            None => status_cell(ui, &self.dof.status),
        }
    }

    /// The shot job's progress (finding the light or exporting) while it runs or waits.
    pub fn shot_progress(&self) -> Option<(f32, String)> {
        self.shot.progress()
    }

    // The bake.

    /// Where the bake stands (the Blend panel, the status area, the tests).
    pub fn bake_status(&self) -> &BakeStatus {
        &self.bake_status
    }

    /// The classification of the LUT on screen, when this session baked it.
    pub fn classes(&self) -> Option<&[GhostClass]> {
        self.classes.as_deref()
    }

    /// The automatic bake's state and settings (see [`autobake`]).
    pub fn autobake(&self) -> &AutoBake {
        &self.autobake
    }

    /// Its settings, to change (the tests make bakes coarse, move the cache and the settling time).
    pub fn autobake_mut(&mut self) -> &mut AutoBake {
        &mut self.autobake
    }

    /// Turns the automatic bake on or off (the Blend panel); off, the LUT it showed leaves the screen (the app
    /// drops it from the frame source) and comes back when it is turned on again.
    pub fn set_auto_bake(&mut self, on: bool) {
        self.autobake.enabled = on;
        if !on {
            self.autobake.shown = None;
        }
    }

    /// The Bake button: a bake of the live optics now (the automatic bake does the same by itself).
    pub fn start_bake(&mut self, live: &Live) {
        if self.bake.active() {
            return;
        }
        let (Some(key), Some(flare)) = (self.live_key(live), live.flare) else { return };
        self.spawn_bake(flare.clone(), key);
    }

    /// Bakes cancelled for optics the user left whose threads have not ended yet.
    pub fn stopping_bakes(&self) -> usize {
        self.bake.stopping()
    }

    /// Cancels the running bake when it is for other optics than `key` (an undo to a lens whose LUT is at hand):
    /// no bake for optics the user left goes on in the background; its thread is watched until it ends.
    fn stop_bake_unless_for(&mut self, key: u64) {
        if self.bake.active() && !self.bakes(key) {
            self.bake.cancel();
            self.bake_status = BakeStatus::Idle;
        }
    }

    /// Cancel (the Blend panel, the status bar): the running bake stops at its next check and is not started
    /// again for these optics; a bake waiting for a cancelled one is dropped.
    pub fn cancel_bake(&mut self) {
        if self.bake.running_for().is_some() {
            self.bake.ask_to_stop();
        } else if let Some(key) = self.bake.waiting_for().copied() {
            self.bake.cancel();
            self.autobake.declined = Some(key);
            self.bake_status = BakeStatus::Failed("bake stopped: cancelled".into());
        }
    }

    /// True when the bake running or waiting is for the optics of cache key `key`.
    fn bakes(&self, key: u64) -> bool {
        self.bake.running_for() == Some(&key) || self.bake.waiting_for() == Some(&key)
    }

    /// The LUT on screen was dropped (the optics changed under a ray-traced LUT): what to say.
    pub fn lut_dropped(&mut self) -> String {
        self.classes = None;
        self.autobake.shown = None;
        let said: String = if self.autobake.enabled {
            "the optics changed: the paraxial flare until their LUT ghosts are ready".into()
        } else {
            "the optics changed: bake again for LUT ghosts".into()
        };
        // Replaces what the Blend panel said (a landed bake's "LUT ghosts ... replace ..." is no longer true).
        self.bake_status = BakeStatus::Done(said.clone());
        said
    }

    fn poll_bake(&mut self, live: &Live, events: &mut Vec<JobEvent>) {
        match self.bake.poll() {
            Some(done) => self.finish_bake(done.key, done.outcome, live, events),
            None => {
                if let Some((fraction, text)) = self.bake.progress() {
                    self.bake_status = BakeStatus::Running { fraction, text };
                }
            }
        }
    }

    /// Starts a bake of `flare` (cache key `key`) on its thread, at the background priority.
    fn spawn_bake(&mut self, flare: Arc<PreparedFlare>, key: u64) {
        if let Err(why) = flare_core::lut::Symmetry::of(&flare.system.lens, &flare.config.aperture) {
            // An anamorphic lens whose blades break its mirror symmetry: said once, and not tried again for these
            // optics (as a cancelled bake is not); the paraxial flare stays.
            self.autobake.declined = Some(key);
            self.bake_status = BakeStatus::Failed(format!("no LUT ghosts: {why}; the paraxial flare is shown"));
            return;
        }
        self.autobake.declined = None;
        if self.bakes(key) {
            return;
        }
        let previous = self.autobake.latest();
        let (settings, cache) = (self.autobake.settings.clone(), self.autobake.cache.clone());
        self.bake.request(key, move || bake::start_bake(flare, previous, settings, cache));
        self.autobake.bakes_started += 1;
        self.bake_status = BakeStatus::Running { fraction: 0.0, text: bake::CLASSIFYING.into() };
    }

    /// The cache key of the live optics (`None` while there is no valid flare).
    fn live_key(&mut self, live: &Live) -> Option<u64> {
        let (flare, optics) = (live.flare?, live.optics_key?);
        Some(self.autobake.key(flare, optics))
    }

    /// A finished bake (already in the disk cache): kept in memory, and shown if its optics are still the
    /// live ones.
    fn finish_bake(&mut self, key: u64, outcome: BakeOutcome, live: &Live, events: &mut Vec<JobEvent>) {
        match outcome {
            Ok(done) => {
                if let Err(e) = done.cached {
                    events.push(JobEvent::Say(e));
                }
                let ghosts = done.lut.lut.ghosts.len();
                let source = format!("baked {}", done.device);
                let baked = (Arc::new(done.lut), Some(done.classes));
                self.autobake.remember(key, baked.clone());
                if Some(key) == self.live_key(live) {
                    self.show_baked(key, baked, &source);
                } else {
                    self.bake_status = BakeStatus::Done(format!("baked {ghosts} ghosts for earlier optics (kept)"));
                }
            }
            Err(e) => {
                if e.contains("cancelled") {
                    self.autobake.declined = Some(key);
                }
                self.bake_status = BakeStatus::Failed(format!("bake stopped: {e}"));
            }
        }
    }

    /// Hands a baked LUT to the screen: its atlas is made on a thread first ([`Self::poll_landing`] shows it and
    /// says that it replaces the paraxial ghosts).
    fn show_baked(&mut self, key: u64, (live, classes): Baked, source: &str) {
        self.autobake.shown = Some(key);
        let device = self.device.clone();
        let source = source.to_owned();
        self.landing.request(key, move || {
            Job::spawn("preparing the LUT ghosts for the view", move |_, _| {
                let atlas = device.map(|(device, queue)| LutAtlas::new(&device, &queue, &live));
                Landing { live, atlas, classes, source }
            })
        });
    }

    /// True while the LUT of `key` is being prepared for the view.
    fn landing(&self, key: u64) -> bool {
        self.landing.running_for() == Some(&key) || self.landing.waiting_for() == Some(&key)
    }

    /// A LUT whose atlas is ready: shown if it is still for the live optics, with what the status says.
    fn poll_landing(&mut self, live: &Live, events: &mut Vec<JobEvent>) {
        let Some(done) = self.landing.poll() else { return };
        // Still the live optics', still wanted (automatic baking not turned off, no LUT file opened meanwhile).
        let no_file = matches!(live.doc.blend.lut, LutSource::None | LutSource::Simulated { path: None });
        let wanted = self.autobake.shown == Some(done.key) && no_file;
        if Some(done.key) != self.live_key(live) || !wanted {
            return;
        }
        let Landing { live, atlas, classes, source } = done.outcome;
        let (ghosts, entries) = (live.lut.ghosts.len(), live.lut.entry_count());
        self.classes = classes;
        self.bake_status =
            BakeStatus::Done(format!("LUT ghosts on: {ghosts} non-linear ghosts, {entries} entries ({source})"));
        events.push(JobEvent::ShowLut(live, atlas));
        // The look changes under the artist: said in the status bar, replacing what it said.
        events.push(JobEvent::Say(format!(
            "LUT ghosts ({source}) now replace the paraxial flare's {ghosts} non-linear ghosts"
        )));
    }

    /// The app's wgpu device and queue, on which LUT atlases are made.
    pub fn set_device(&mut self, device: Option<(wgpu::Device, wgpu::Queue)>) {
        self.device = device;
    }

    /// Whether the automatic bake may serve `doc` (it named no LUT file).
    fn auto_bake_serves(&self, doc: &Document) -> bool {
        self.autobake.enabled && matches!(doc.blend.lut, LutSource::None | LutSource::Simulated { path: None })
    }

    // File > Export image.

    /// Starts an image export (one at a time: `Err` while one runs).
    pub fn start_export(&mut self, path: &Path, job: Job<Result<(), String>>) -> Result<(), &'static str> {
        if self.export.is_some() {
            job.cancel();
            return Err("an export is running: wait for it or cancel it");
        }
        self.export = Some((path.to_path_buf(), job));
        Ok(())
    }

    /// True while an image export runs.
    pub fn exporting_image(&self) -> bool {
        self.export.is_some()
    }

    fn poll_export(&mut self, events: &mut Vec<JobEvent>) {
        let Some((path, job)) = &self.export else { return };
        if let JobPoll::Finished(outcome) = job.poll() {
            events.push(JobEvent::Say(match outcome {
                Ok(()) => format!("wrote {}", path.display()),
                Err(e) => format!("could not export {}: {e}", path.display()),
            }));
            self.export = None;
        }
    }

    // The shot's jobs.

    /// True while a sequence exports.
    pub fn exporting_sequence(&self) -> bool {
        self.shot.running_for() == Some(&ShotKind::Export)
    }

    /// True while a shot job (finding the light or exporting) runs or waits.
    pub fn shot_running(&self) -> bool {
        self.shot.active()
    }

    /// Cancels the running shot job, if any: it stops at its next plate or frame and says what it did (an
    /// export, the frames it wrote); a request waiting behind it is dropped.
    pub fn cancel_shot(&mut self) {
        if self.shot.running_for().is_some() {
            self.shot.ask_to_stop();
        } else {
            self.shot.cancel();
        }
    }

    /// What the last shot job said (or the running one says).
    pub fn shot_status(&self) -> &str {
        &self.shot_status
    }

    /// The last exported sequence's records.
    pub fn last_export(&self) -> Option<&SequenceReport> {
        self.last_export.as_ref()
    }

    /// Whether the light found in the plates was found for `doc` as it is (and no shot job replaces it).
    pub fn light_found_for(&self, doc: &Document) -> bool {
        doc.auto_light.is_some() && self.light_key == Some(light_key(doc)) && !self.shot.active()
    }

    /// Starts a sequence export (replacing a search for the light, which is cancelled).
    pub fn start_sequence(&mut self, job: Job<ShotResult>) {
        self.shot.replace(ShotKind::Export, job);
        self.shot_status = "exporting…".into();
    }

    /// Starts or replaces the search for the light when what it depends on changed; forgets it when `doc` no
    /// longer asks for it (`false`: the light found must be dropped).
    pub fn sync_light(
        &mut self,
        doc: &Document,
        resolved: impl FnOnce() -> Document,
        flare: Option<&Arc<PreparedFlare>>,
    ) -> bool {
        let wanted = doc.auto_light.is_some() && doc.background.is_some();
        if !wanted {
            self.light_key = None;
            if !self.exporting_sequence() {
                self.shot.cancel();
            }
            return false;
        }
        let key = light_key(doc);
        if self.light_key == Some(key) || self.exporting_sequence() {
            return true;
        }
        let Some(flare) = flare else { return true };
        self.light_key = Some(key);
        let (doc, flare) = (resolved(), flare.clone());
        self.shot.request(ShotKind::Light(key), move || shot::find_light(doc, flare));
        true
    }

    fn poll_shot(&mut self, events: &mut Vec<JobEvent>) {
        let Some(Done { outcome, cancelled, .. }) = self.shot.poll() else {
            if let Some((_, text)) = self.shot.progress() {
                self.shot_status = text;
            }
            return;
        };
        {
            {
                match outcome {
                    Ok(ShotOutcome::Light { plan, key }) => {
                        let found = plan.frames.iter().filter(|f| f.visibility > 0.0).count();
                        self.shot_status = format!("light found on {found} of {} frames", plan.frames.len());
                        if self.light_key == Some(key) {
                            events.push(JobEvent::LightFound(plan));
                        }
                    }
                    Ok(ShotOutcome::Exported { report, pattern, device }) => {
                        let median = report.median_ms();
                        let failed: Vec<&str> = report.failures().into_iter().map(|(_, e)| e).collect();
                        self.shot_status = format!(
                            "{}{} frames written to {pattern} on {device} ({median:.0} ms a frame){}",
                            if cancelled { "cancelled: " } else { "" },
                            report.rendered(),
                            if failed.is_empty() {
                                String::new()
                            } else {
                                format!("; {} failed: {}", failed.len(), failed.join("; "))
                            }
                        );
                        let said = match &report.plate_warning {
                            Some(warning) => format!("{}; {warning}", self.shot_status),
                            None => self.shot_status.clone(),
                        };
                        events.push(JobEvent::Say(said));
                        self.last_export = Some(report);
                    }
                    Err(e) => {
                        if self.light_key.is_some() && !cancelled {
                            events.push(JobEvent::Say(e.clone()));
                        }
                        self.shot_status = if cancelled { "cancelled".into() } else { e };
                    }
                }
            }
        }
    }

    // The parts with their own step.

    /// The depth of field's work (see [`dof`]).
    pub fn dof(&self) -> &DofWork {
        &self.dof
    }

    pub fn dof_mut(&mut self) -> &mut DofWork {
        &mut self.dof
    }

    /// The ray-grid view (see [`raygrid_view`]).
    pub fn raygrid(&self) -> &RayGridView {
        &self.raygrid
    }

    pub fn raygrid_mut(&mut self) -> &mut RayGridView {
        &mut self.raygrid
    }

    /// The looks' thumbnails (see [`looks`]).
    pub fn looks(&self) -> &Looks {
        &self.looks
    }

    pub fn looks_mut(&mut self) -> &mut Looks {
        &mut self.looks
    }

    /// The ghost report (see [`report`]).
    pub fn report(&self) -> &ReportState {
        &self.report
    }

    pub fn report_mut(&mut self) -> &mut ReportState {
        &mut self.report
    }
}

/// The width of a job's cell in the status bar's row (points): its text, progress bar and Cancel.
const JOB_CELL: f32 = 400.0;

/// One job in the status bar's row, in a cell of fixed width: what it does (one line, cut, the whole text on
/// hover), and while it runs (`fraction`) its progress and its Cancel button (labelled `cancel`); true when
/// Cancel was clicked.
fn job_cell(ui: &mut egui::Ui, text: &str, fraction: Option<f32>, cancel: &str) -> bool {
    let height = ui.spacing().interact_size.y;
    let layout = egui::Layout::left_to_right(egui::Align::Center);
    ui.allocate_ui_with_layout(egui::vec2(JOB_CELL, height), layout, |ui| {
        ui.set_min_width(JOB_CELL);
        ui.set_max_width(JOB_CELL);
        let Some(fraction) = fraction else {
            status_label(ui, text, JOB_CELL);
            return false;
        };
        status_label(ui, text, JOB_CELL - 200.0);
        ui.add(egui::ProgressBar::new(fraction.clamp(0.0, 1.0)).desired_width(80.0));
        ui.button(cancel).clicked()
    })
    .inner
}

/// What a part with nothing running says (the ray-grid view, the depth of field), in a job's cell (nothing when
/// it says nothing).
fn status_cell(ui: &mut egui::Ui, text: &str) {
    if !text.is_empty() {
        job_cell(ui, text, None, "");
    }
}

/// A label of the status bar's row: `text` on one line at most `width` points wide (cut with an ellipsis), the
/// whole text on hover.
pub fn status_label(ui: &mut egui::Ui, text: &str, width: f32) {
    let height = ui.spacing().interact_size.y;
    ui.allocate_ui_with_layout(egui::vec2(width, height), egui::Layout::left_to_right(egui::Align::Center), |ui| {
        ui.set_max_width(width);
        ui.add(egui::Label::new(text).truncate()).on_hover_text(text);
    });
}
