//! The job board: every piece of work the app runs on a thread (the bake and its automatic policy, File >
//! Export image, the shot's jobs: finding the light and exporting a sequence, the depth of field, the ray-grid
//! view, the looks' thumbnails, the ghost report), polled in one place, shown in one status area, under one
//! priority rule.
//!
//! # How it works
//! [`JobBoard`] owns the jobs and what they said (its fields are private; it is their only writer). Each UI
//! frame the app calls [`JobBoard::poll`] once with [`Live`], what the live document and optics are: it takes
//! the progress and outcome of the bake, the export and the shot job, runs the automatic bake's policy (see
//! [`super::autobake`]: the bake restarts only for the optics it serves, once an edit has stood, and keeps
//! finished ghosts) and hands the app back [`JobEvent`]s (a LUT to show, a light found, a sentence for the
//! status line); the board never touches the document or the frame source itself. The depth of field, the
//! ray-grid view, the looks and the report keep their own step (each needs its own inputs), but live here:
//! [`JobBoard::busy`] answers for all of them (the app repaints only while something runs) and
//! [`JobBoard::status_ui`] draws every running job's progress with its Cancel. The priority rule is
//! [`super::job::Priority`]: what the user waits for (a focus, an export, a sequence, a ray-grid trace, the
//! report) is interactive; what only improves the view later (the bake, the thumbnails) is background.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use eframe::egui;
use flare_core::flare::PreparedFlare;
use flare_core::lut::GhostLut;
use flare_core::lut::classify::GhostClass;
use flare_core::preset::{Document, LutSource};
use flare_core::shot::plan::ShotPlan;
use flare_core::shot::sequence::SequenceReport;

use super::autobake::{AutoBake, Baked};
use super::bake::{self, BakeJob, BakeOutcome, BakePoll};
use super::dof::DofWork;
use super::ghost_report::ReportState;
use super::job::{Job, JobPoll, Stopping};
use super::looks::Looks;
use super::raygrid_view::RayGridView;
use super::shot::{ShotJob, ShotOutcome, light_key};
use crate::panels::BakeStatus;

mod auto_bake;

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
    ShowLut(Arc<GhostLut>),
    /// The light found in the plates for the live document.
    LightFound(ShotPlan),
}

/// An image export on its thread: the file it writes and the job.
type ExportJob = (PathBuf, Job<Result<(), String>>);

/// The job board (see the module documentation).
pub struct JobBoard {
    bake: Option<BakeJob>,
    /// Bakes cancelled because the user left their optics, until their threads end.
    stopping_bakes: Stopping<BakeOutcome>,
    bake_status: BakeStatus,
    /// The classification of the LUT on screen, when this session baked it.
    classes: Option<Vec<GhostClass>>,
    autobake: AutoBake,
    export: Option<ExportJob>,
    shot: Option<ShotJob>,
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
            bake: None,
            stopping_bakes: Stopping::default(),
            bake_status: BakeStatus::Idle,
            classes: None,
            autobake: AutoBake::default(),
            export: None,
            shot: None,
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
        self.stopping_bakes.prune();
        self.poll_bake(live, &mut events);
        self.poll_export(&mut events);
        self.poll_shot(&mut events);
        self.auto_bake_step(live, &mut events);
        events
    }

    /// True while any job runs (the app then repaints to show its progress).
    pub fn busy(&self) -> bool {
        self.bake.is_some()
            || self.export.is_some()
            || self.shot.is_some()
            || self.dof.busy()
            || self.raygrid.busy()
            || self.looks.job.is_some()
    }

    /// Every job in the status bar's one row: what it does (truncated to a fixed width, the whole text on
    /// hover), its progress and its Cancel, each item where the one before leaves it (nothing wraps, the row
    /// never grows); `lut_shown`: LUT ghosts are on screen (a bake then says they stay until it lands, not that
    /// the paraxial flare stands in).
    pub fn status_ui(&mut self, ui: &mut egui::Ui, lut_shown: bool) {
        if !self.dof.status.is_empty() {
            status_label(ui, &self.dof.status, 220.0);
        }
        // The ray-grid view: what it shows or is tracing, with Cancel.
        if !self.raygrid.status.is_empty() {
            if let Some((fraction, text)) = self.raygrid.progress() {
                ui.add(egui::ProgressBar::new(fraction).text(text).desired_width(240.0));
                if ui.button("Cancel trace").clicked() {
                    self.raygrid.cancel();
                }
            } else {
                status_label(ui, &self.raygrid.status, 260.0);
            }
        }
        // The bake (started by itself or from the Blend panel).
        if let (Some(job), BakeStatus::Running { fraction, text }) = (&self.bake, &self.bake_status) {
            let meanwhile = if lut_shown { "the LUT ghosts shown" } else { "the paraxial flare" };
            status_label(ui, &format!("baking LUT ghosts, {meanwhile} until then: {text}"), 260.0);
            ui.add(egui::ProgressBar::new(*fraction).desired_width(100.0));
            if ui.button("Cancel bake").clicked() {
                job.cancel();
            }
        }
        if let Some((path, job)) = &self.export {
            let (fraction, text) = job.progress();
            ui.add(egui::ProgressBar::new(fraction).text(text).desired_width(160.0));
            status_label(ui, &format!("exporting {}", path.display()), 200.0);
            if ui.button("Cancel export").clicked() {
                job.cancel();
            }
        }
        // A shot job, whichever panel is open.
        self.shot_progress_ui(ui);
    }

    /// The shot job's progress and Cancel, or what the last one said (the status area and the Shot panel).
    pub fn shot_progress_ui(&mut self, ui: &mut egui::Ui) {
        if let Some(job) = &self.shot {
            ui.horizontal(|ui| {
                let (fraction, _) = job.job.progress();
                ui.add(egui::ProgressBar::new(fraction).text(self.shot_status.clone()).desired_width(240.0))
                    .on_hover_text(self.shot_status.clone());
                if ui.button("Cancel").clicked() {
                    job.job.cancel();
                }
            });
        }
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

    /// The automatic bake's state and settings (see [`super::autobake`]).
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
        if self.bake.is_some() {
            return;
        }
        let (Some(key), Some(flare)) = (self.live_key(live), live.flare) else { return };
        self.spawn_bake(flare.clone(), key);
    }

    /// Bakes cancelled for optics the user left whose threads have not ended yet.
    pub fn stopping_bakes(&self) -> usize {
        self.stopping_bakes.running()
    }

    /// Cancels the running bake when it is for other optics than `key` (an undo to a lens whose LUT is at hand):
    /// no bake for optics the user left goes on in the background; its thread is watched until it ends.
    fn stop_bake_unless_for(&mut self, key: u64) {
        if self.autobake.baking != Some(key)
            && let Some(job) = self.bake.take()
        {
            self.stopping_bakes.stop(job);
            self.autobake.baking = None;
            self.bake_status = BakeStatus::Idle;
        }
    }

    pub fn cancel_bake(&self) {
        if let Some(job) = &self.bake {
            job.cancel();
        }
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
        let Some(job) = &self.bake else { return };
        match job.poll() {
            BakePoll::Running(fraction, text) => self.bake_status = BakeStatus::Running { fraction, text },
            BakePoll::Finished(outcome) => {
                self.bake = None;
                self.finish_bake(outcome, live, events);
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
        let previous = self.autobake.latest();
        let (settings, cache) = (self.autobake.settings.clone(), self.autobake.cache.clone());
        self.bake = Some(bake::start_bake(flare, previous, settings, cache));
        self.autobake.baking = Some(key);
        self.autobake.declined = None;
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
    fn finish_bake(&mut self, outcome: BakeOutcome, live: &Live, events: &mut Vec<JobEvent>) {
        let key = self.autobake.baking.take();
        match outcome {
            Ok(done) => {
                if let Err(e) = done.cached {
                    events.push(JobEvent::Say(e));
                }
                let ghosts = done.lut.ghosts.len();
                let source = format!("baked {}", done.device);
                let baked = (Arc::new(done.lut), Some(done.classes));
                let Some(key) = key else { return };
                self.autobake.remember(key, baked.clone());
                if Some(key) == self.live_key(live) {
                    self.show_baked(key, baked, &source, events);
                } else {
                    self.bake_status = BakeStatus::Done(format!("baked {ghosts} ghosts for earlier optics (kept)"));
                }
            }
            Err(e) => {
                if e.contains("cancelled") {
                    self.autobake.declined = key;
                }
                self.bake_status = BakeStatus::Failed(format!("bake stopped: {e}"));
            }
        }
    }

    /// Hands a baked LUT to the screen and says that it replaces the paraxial ghosts.
    fn show_baked(&mut self, key: u64, (lut, classes): Baked, source: &str, events: &mut Vec<JobEvent>) {
        let (ghosts, entries) = (lut.ghosts.len(), lut.entry_count());
        self.classes = classes;
        self.autobake.shown = Some(key);
        self.bake_status =
            BakeStatus::Done(format!("LUT ghosts on: {ghosts} non-linear ghosts, {entries} entries ({source})"));
        events.push(JobEvent::ShowLut(lut));
        // The look changes under the artist: said in the status bar, replacing what it said.
        events.push(JobEvent::Say(format!(
            "LUT ghosts ({source}) now replace the paraxial flare's {ghosts} non-linear ghosts"
        )));
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
        self.shot.as_ref().is_some_and(|j| j.exporting)
    }

    /// True while a shot job (finding the light or exporting) runs.
    pub fn shot_running(&self) -> bool {
        self.shot.is_some()
    }

    /// Cancels the running shot job, if any.
    pub fn cancel_shot(&self) {
        if let Some(job) = &self.shot {
            job.job.cancel();
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
        doc.auto_light.is_some() && self.light_key == Some(light_key(doc)) && self.shot.is_none()
    }

    /// Starts a sequence export (replacing a search for the light).
    pub fn start_sequence(&mut self, job: ShotJob) {
        if let Some(old) = self.shot.replace(job) {
            old.job.cancel();
        }
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
            if self.shot.as_ref().is_some_and(|j| !j.exporting) {
                self.shot = None;
            }
            return false;
        }
        let key = light_key(doc);
        if self.light_key == Some(key) || self.exporting_sequence() {
            return true;
        }
        let Some(flare) = flare else { return true };
        if let Some(job) = self.shot.take() {
            job.job.cancel();
        }
        self.light_key = Some(key);
        self.shot = Some(ShotJob::find_light(resolved(), flare.clone()));
        true
    }

    fn poll_shot(&mut self, events: &mut Vec<JobEvent>) {
        let Some(job) = &self.shot else { return };
        match job.job.poll() {
            JobPoll::Running(_, text) => self.shot_status = text,
            JobPoll::Finished(outcome) => {
                let cancelled = job.job.cancelled();
                self.shot = None;
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

    /// The depth of field's work (see [`super::dof`]).
    pub fn dof(&self) -> &DofWork {
        &self.dof
    }

    pub fn dof_mut(&mut self) -> &mut DofWork {
        &mut self.dof
    }

    /// The ray-grid view (see [`super::raygrid_view`]).
    pub fn raygrid(&self) -> &RayGridView {
        &self.raygrid
    }

    pub fn raygrid_mut(&mut self) -> &mut RayGridView {
        &mut self.raygrid
    }

    /// The looks' thumbnails (see [`super::looks`]).
    pub fn looks(&self) -> &Looks {
        &self.looks
    }

    pub fn looks_mut(&mut self) -> &mut Looks {
        &mut self.looks
    }

    /// The ghost report (see [`super::ghost_report`]).
    pub fn report(&self) -> &ReportState {
        &self.report
    }

    pub fn report_mut(&mut self) -> &mut ReportState {
        &mut self.report
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
