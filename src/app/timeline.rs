//! The app's shot operations: what the timeline strip and the Shot panel ([`super::shot_panel`]) ask for that
//! needs more than the session (reading a tracker's CSV or a plate, starting or cancelling the shot's jobs), the
//! light placed by a drag, playback, and the job that finds the light in the plate.
//!
//! # How it works
//! The playhead is the app's, not the document's (moving it is not an edit): the frame shown is the
//! timeline's sample at the playhead ([`flare_core::preset::Document::frame_request_at`]), with the plate of
//! that frame and, when the document finds the light in the plate, the light found there (a job scans every
//! plate of the range once per change of what it depends on, [`super::jobs::shot::light_key`]). Keys are document
//! edits, so undo covers them. Dragging the light when the timeline has light keys sets the key at the
//! playhead (editing it when there is one); with no keys it moves the static light. Playback advances the
//! playhead at the timeline's rate, looping over the range, and asks for a repaint only while it plays.

use eframe::egui;
use flare_core::footage::pattern::{FramePattern, sequence_of};
use flare_core::shot::track::{read_track, to_keys};

use super::FlareLabApp;
use super::jobs::shot;
use super::shot_panel::ShotAction;

impl FlareLabApp {
    /// Carries out what the Shot panel asked for.
    pub(super) fn shot_action(&mut self, action: ShotAction) {
        match action {
            ShotAction::UsePlate(path) => self.set_background(&path),
            ShotAction::Browse(use_) => self.pick_file(use_),
            ShotAction::ImportTrack(path) => self.import_track(&path),
            ShotAction::ExportSequence(pattern) => self.export_sequence(&pattern, true),
            ShotAction::CancelShot => self.jobs.cancel_shot(),
        }
    }

    /// Advances the playhead while playing (looping over the range).
    pub fn step_playback(&mut self, ctx: &egui::Context) {
        let timeline = &self.session.doc().timeline;
        if self.view.step_playback(timeline.first_frame, timeline.last_frame, timeline.fps) {
            ctx.request_repaint();
        }
    }

    /// Puts the light at `deg`: the key at the playhead when the timeline has light keys, else the static
    /// light. With the light found in the plate, the plate decides and the user is told.
    pub fn set_light(&mut self, deg: [f64; 2]) {
        if self.session.doc().auto_light.is_some() && self.session.doc().background.is_some() {
            self.session.say("the light is found in the plate: switch the Shot panel's light to keys to place it");
            return;
        }
        if self.session.doc().timeline.light_deg.is_empty() {
            self.session.edit().light_deg = deg;
        } else {
            self.session.edit().timeline.light_deg.set(self.view.playhead(), deg);
        }
    }

    /// The frame size a track's pixels refer to: the plate's, else the export size.
    fn track_frame_size(&self) -> (u32, u32) {
        self.derived.plate().as_ref().map_or(self.export_px(), |p| (p.width, p.height))
    }

    /// Imports a tracker's CSV as light keys (replacing the light keys; intensity keys too when it has them).
    pub fn import_track(&mut self, path: &std::path::Path) {
        let Some(flare) = self.derived.flare().clone() else {
            self.session.say("no valid lens to map the track through");
            return;
        };
        let (w, h) = self.track_frame_size();
        let doc = self.session.doc();
        let (sensor_mm, desqueeze) = (doc.sensor_width_mm, doc.desqueeze);
        let keys =
            read_track(path).and_then(|rows| to_keys(&rows, &flare.system.mapping, sensor_mm, (w, h), desqueeze));
        match keys {
            Ok((position, intensity)) => {
                let (a, b) = (position.keys[0].frame, position.keys[position.keys.len() - 1].frame);
                let count = position.keys.len();
                self.session.edit().timeline.light_deg = position;
                if !intensity.is_empty() {
                    self.session.edit().timeline.light_ev = intensity;
                }
                if self.session.doc().background.as_deref().is_none_or(|b| !FramePattern::is_pattern(b)) {
                    self.session.edit().timeline.first_frame = self.session.doc().timeline.first_frame.min(a);
                    self.session.edit().timeline.last_frame = self.session.doc().timeline.last_frame.max(b);
                }
                self.session.say(format!("{}: {count} light keys, frames {a}-{b} ({w}x{h} pixels)", path.display()));
            }
            Err(e) => self.session.say(format!("{}: {e}", path.display())),
        }
    }

    /// Uses `path` as the plate: a numbered file with siblings becomes its sequence, and the timeline spans it.
    pub fn set_background(&mut self, path: &std::path::Path) {
        match sequence_of(path) {
            Some((pattern, frames)) => {
                self.session.edit().background = Some(pattern.text.clone());
                self.session.edit().timeline.first_frame = frames[0];
                self.session.edit().timeline.last_frame = frames[frames.len() - 1];
                self.view.clamp_playhead(frames[0], frames[frames.len() - 1]);
                self.session.say(format!("plate sequence {} ({} frames)", pattern.text, frames.len()));
            }
            None => {
                // A file that is no usable image (by its header) changes nothing: the plate before stays.
                if let Err(e) = flare_core::output::image_size(path, "plate") {
                    self.session.say(e);
                    return;
                }
                self.session.edit().background = Some(path.display().to_string());
                self.session.say(format!("background plate {}", path.display()));
            }
        }
        self.shot_fields.plate_path = self.session.doc().background.clone().unwrap_or_default();
    }

    /// Starts exporting the timeline's range to the sequence `pattern` (on a thread, with progress and Cancel).
    pub fn export_sequence(&mut self, pattern: &str, gpu: bool) {
        if self.jobs.exporting_sequence() {
            self.session.say("an export is already running");
            return;
        }
        let Some(flare) = self.derived.flare().clone() else {
            self.session.say("no valid lens to render");
            return;
        };
        let checked = FramePattern::parse(pattern).and_then(|p| {
            p.ok_or_else(|| {
                format!("`{pattern}` has no frame field: name the files like out/flare.####.exr or out/flare.%04d.png")
            })
        });
        let pattern = match checked.and_then(|p| {
            flare_core::frame::check_output(std::path::Path::new(&p.text), Default::default())
                .map(|_| p)
                .map_err(|e| e.to_string())
        }) {
            Ok(p) => p,
            Err(e) => {
                self.session.say(e);
                return;
            }
        };
        if let Err(e) = flare_core::shot::plan::check_range(self.session.doc(), &self.session.doc().timeline.frames()) {
            self.session.say(e.to_string());
            return;
        }
        // The light found in the plates serves the export when it was found for this very document.
        let found = self.derived.shot_plan().clone().filter(|_| self.jobs.light_found_for(self.session.doc()));
        self.jobs.start_sequence(shot::export(
            self.derived.resolved(self.session.doc()),
            flare,
            self.derived.lut().clone(),
            found,
            pattern,
            self.export_size,
            gpu,
        ));
    }

    /// File > Export sequence…: the file chooser for the first file's name (a name without a frame field
    /// gets one).
    pub fn export_sequence_dialog(&mut self) {
        self.pick_file(super::files::FileUse::ExportSequence);
    }

    /// Exports the sequence named like `path` (`flare.exr` becomes `flare.####.exr`).
    pub fn export_sequence_named(&mut self, path: &std::path::Path) {
        let mut text = path.display().to_string();
        if !FramePattern::is_pattern(&text) {
            let dot = text.rfind('.').filter(|&d| d > text.rfind('/').unwrap_or(0)).unwrap_or(text.len());
            text.insert_str(dot, ".####");
        }
        self.shot_fields.sequence_path = text.clone();
        self.export_sequence(&text, true);
    }

    /// Starts or replaces the job finding the light when what it depends on changed; drops the light found
    /// when the document no longer asks for it.
    pub fn sync_shot_light(&mut self) {
        let (session, derived) = (&self.session, &self.derived);
        let wanted = self.jobs.sync_light(session.doc(), || derived.resolved(session.doc()), derived.flare().as_ref());
        if !wanted && self.derived.shot_plan().is_some() {
            self.derived.set_shot_plan(None);
        }
    }
}
