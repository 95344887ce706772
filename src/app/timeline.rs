//! The app's shot: the timeline strip under the viewport (play and pause, scrub, the frame number, set and
//! delete a key, the keys shown as ticks), the Shot panel (frame range and rate, interpolation, the light
//! found in the plate, a tracker's CSV, the plate sequence, the sensor, File > Export sequence), and the jobs
//! they start.
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
use flare_core::preset::ghost_key;
use flare_core::shot::detect::AutoLight;
use flare_core::shot::pattern::{FramePattern, sequence_of};
use flare_core::shot::track::{read_track, to_keys};
use flare_core::timeline::Interpolation;

use super::FlareLabApp;
use super::jobs::shot;

impl FlareLabApp {
    /// The timeline strip (see the module documentation).
    pub fn timeline_ui(&mut self, ui: &mut egui::Ui) {
        let (first, last) = (self.session.doc().timeline.first_frame, self.session.doc().timeline.last_frame);
        ui.horizontal(|ui| {
            let playing = self.view.playing();
            if ui.button(if playing { "Pause" } else { "Play" }).clicked() {
                self.toggle_play();
            }
            if ui.button("|<").on_hover_text("first frame").clicked() {
                self.seek(first);
            }
            if ui.button("<").on_hover_text("previous frame").clicked() {
                self.seek(self.view.playhead() - 1);
            }
            if ui.button(">").on_hover_text("next frame").clicked() {
                self.seek(self.view.playhead() + 1);
            }
            let mut frame = self.view.playhead();
            let r = ui.add(egui::DragValue::new(&mut frame).range(first..=last).prefix("frame "));
            crate::panels::labelled_value(r, "frame", frame as f64);
            if frame != self.view.playhead() {
                self.seek(frame);
            }
            let keyed = self.session.doc().timeline.has_key_at(self.view.playhead());
            if ui
                .button(if keyed { "Update key" } else { "Set key" })
                .on_hover_text("key the light's position and intensity (and the selected ghost's gain) at this frame")
                .clicked()
            {
                self.set_key();
            }
            if ui.add_enabled(keyed, egui::Button::new("Delete key")).clicked() {
                self.session.edit().timeline.delete_keys_at(self.view.playhead());
            }
            let mut ev = self.session.doc().timeline.sample(self.view.playhead() as f64).light_ev;
            let r = ui.add(egui::DragValue::new(&mut ev).range(-64.0..=64.0).speed(0.05).suffix(" EV"));
            crate::panels::labelled_value(
                r.on_hover_text("the light's intensity at this frame (sets a key)"),
                "light intensity",
                ev,
            );
            if ev != self.session.doc().timeline.sample(self.view.playhead() as f64).light_ev {
                self.session.edit().timeline.light_ev.set(self.view.playhead(), ev);
            }
            ui.separator();
            self.sections_ui(ui);
        });
        self.scrub_bar_ui(ui, first, last);
    }

    /// The scrub bar: the range, a tick per key frame, the playhead; click or drag to move the playhead.
    fn scrub_bar_ui(&mut self, ui: &mut egui::Ui, first: i64, last: i64) {
        let (rect, response) =
            ui.allocate_exact_size(egui::vec2(ui.available_width(), 18.0), egui::Sense::click_and_drag());
        let span = (last - first).max(1) as f32;
        let x_of = |f: i64| rect.left() + 6.0 + (f - first) as f32 / span * (rect.width() - 12.0);
        if (response.dragged() || response.clicked())
            && let Some(p) = response.interact_pointer_pos()
        {
            let t = ((p.x - rect.left() - 6.0) / (rect.width() - 12.0)).clamp(0.0, 1.0);
            self.seek(first + (t * span).round() as i64);
        }
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 3.0, egui::Color32::from_gray(28));
        let light_keys: Vec<i64> = self.session.doc().timeline.light_deg.keys.iter().map(|k| k.frame).collect();
        for f in self.session.doc().timeline.key_frames() {
            let colour = if light_keys.contains(&f) {
                egui::Color32::from_rgb(255, 210, 90)
            } else {
                egui::Color32::from_rgb(120, 200, 255)
            };
            let x = x_of(f);
            painter.line_segment([egui::pos2(x, rect.top() + 3.0), egui::pos2(x, rect.bottom() - 3.0)], (2.0, colour));
        }
        if let Some(plan) = &self.derived.shot_plan() {
            // The light's visibility found in the plate, as a curve along the bar.
            let points: Vec<egui::Pos2> = plan
                .frames
                .iter()
                .map(|p| egui::pos2(x_of(p.frame), rect.bottom() - 2.0 - p.visibility as f32 * (rect.height() - 4.0)))
                .collect();
            painter.add(egui::Shape::line(points, (1.0, egui::Color32::from_rgb(140, 230, 140))));
        }
        let x = x_of(self.view.playhead());
        painter.line_segment(
            [egui::pos2(x, rect.top()), egui::pos2(x, rect.bottom())],
            (2.0, egui::Color32::from_rgb(255, 80, 80)),
        );
    }

    /// Moves the playhead to `frame` (clamped to the range).
    pub fn seek(&mut self, frame: i64) {
        let timeline = &self.session.doc().timeline;
        self.view.seek(frame, timeline.first_frame, timeline.last_frame);
    }

    pub fn toggle_play(&mut self) {
        self.view.toggle_play();
    }

    /// Advances the playhead while playing (looping over the range).
    pub fn step_playback(&mut self, ctx: &egui::Context) {
        let timeline = &self.session.doc().timeline;
        if self.view.step_playback(timeline.first_frame, timeline.last_frame, timeline.fps) {
            ctx.request_repaint();
        }
    }

    /// Keys the light's position and intensity, and the selected ghost's gain, at the playhead.
    pub fn set_key(&mut self) {
        let frame = self.view.playhead();
        let light = self.derived.light_deg(self.session.doc());
        let sample = self.session.doc().timeline.sample(frame as f64);
        self.session.edit().timeline.light_deg.set(frame, light);
        self.session.edit().timeline.light_ev.set(frame, sample.light_ev);
        let mut said = format!(
            "keyed frame {frame}: the light at ({:.2}, {:.2}) deg, {:+.1} EV",
            light[0], light[1], sample.light_ev
        );
        if let Some(g) =
            self.session.selected().and_then(|g| self.derived.flare().as_ref().map(|f| f.system.ghosts[g].clone()))
        {
            let key = ghost_key(g.i, g.j);
            let gain = sample
                .ghost_gain
                .get(&key)
                .copied()
                .unwrap_or_else(|| self.session.doc().ghosts.get(&key).map_or(1.0, |d| d.gain));
            self.session.edit().timeline.ghost_gain.entry(key).or_default().set(frame, gain);
            said.push_str(&format!(", ghost {}-{} at gain {gain:.2}", g.i, g.j));
        }
        self.session.say(said);
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
        self.plate_path = self.session.doc().background.clone().unwrap_or_default();
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
        self.sequence_path = text.clone();
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

    /// The Shot panel (see the module documentation).
    pub fn shot_panel_ui(&mut self, ui: &mut egui::Ui) {
        let tl = &mut self.session.edit().timeline;
        ui.heading("Timeline");
        ui.horizontal(|ui| {
            let r = ui.add(egui::DragValue::new(&mut tl.first_frame).prefix("first "));
            crate::panels::labelled_value(r, "first frame", tl.first_frame as f64);
            let r = ui.add(egui::DragValue::new(&mut tl.last_frame).prefix("last "));
            crate::panels::labelled_value(r, "last frame", tl.last_frame as f64);
            tl.last_frame = tl.last_frame.max(tl.first_frame);
            let r = ui.add(egui::DragValue::new(&mut tl.fps).range(0.001..=1000.0).suffix(" fps"));
            crate::panels::labelled_value(r, "fps", tl.fps);
        });
        ui.horizontal(|ui| {
            ui.label("between keys:");
            ui.selectable_value(&mut tl.interpolation, Interpolation::Linear, "linear");
            ui.selectable_value(&mut tl.interpolation, Interpolation::Smooth, "smooth");
        });
        ui.horizontal(|ui| {
            let r = ui.add(
                egui::DragValue::new(&mut tl.shutter_deg)
                    .range(0.0..=flare_core::shutter::MAX_SHUTTER_DEG)
                    .speed(1.0)
                    .prefix("shutter ")
                    .suffix("°"),
            );
            crate::panels::labelled_value(
                r.on_hover_text(
                    "open this part of each frame (180°: half): a light that moves while it is open streaks its \
                     ghosts; 0°: no motion blur",
                ),
                "shutter",
                tl.shutter_deg,
            );
        });
        ui.label(format!(
            "{} light keys, {} intensity keys, {} ghost tracks",
            tl.light_deg.keys.len(),
            tl.light_ev.keys.len(),
            tl.ghost_gain.len()
        ));
        if ui.button("Clear all keys").clicked() {
            tl.light_deg.keys.clear();
            tl.light_ev.keys.clear();
            tl.ghost_gain.clear();
        }
        let timeline = &self.session.doc().timeline;
        self.view.clamp_playhead(timeline.first_frame, timeline.last_frame);
        ui.separator();
        ui.heading("Plate");
        // Each path field takes the panel's width, its buttons under it.
        let r = ui.add(
            egui::TextEdit::singleline(&mut self.plate_path)
                .hint_text("plates/shot.####.exr")
                .desired_width(ui.available_width()),
        );
        r.on_hover_text("a plate, or a sequence with #### or %04d for the frame number");
        ui.horizontal(|ui| {
            if ui.button("Use").clicked() {
                let text = self.plate_path.trim().to_string();
                if text.is_empty() {
                    self.session.edit().background = None;
                } else if FramePattern::is_pattern(&text) {
                    self.session.edit().background = Some(text);
                } else {
                    self.set_background(std::path::Path::new(&text));
                }
            }
            if ui.button("Browse…").clicked() {
                self.pick_file(super::files::FileUse::Background);
            }
        });
        let r = ui.add(
            egui::DragValue::new(&mut self.session.edit().sensor_width_mm).range(1.0..=200.0).speed(0.1).suffix(" mm"),
        );
        crate::panels::labelled_value(
            r.on_hover_text("the width of the sensor the frame (and the plate) spans"),
            "sensor width",
            self.session.doc().sensor_width_mm,
        );
        let squeeze = self.derived.first_order().as_ref().and_then(|fo| fo.squeeze());
        if squeeze.is_some() || self.session.doc().desqueeze != 1.0 {
            ui.horizontal(|ui| {
                let max = flare_core::frame::MAX_DESQUEEZE;
                let r = ui.add(
                    egui::DragValue::new(&mut self.session.edit().desqueeze)
                        .range(1.0 / max..=max)
                        .speed(0.01)
                        .prefix("x"),
                );
                crate::panels::labelled_value(
                    r.on_hover_text(
                        "the delivered frame shows the sensor stretched along x by this factor (an anamorphic lens's \
                         squeeze undone, for desqueezed plates); 1: the sensor as it is",
                    ),
                    "desqueeze",
                    self.session.doc().desqueeze,
                );
                if let Some(s) = squeeze.filter(|s| (1.0 / max..=max).contains(s))
                    && ui.button(format!("the lens's x{s:.3}")).clicked()
                {
                    self.session.edit().desqueeze = s;
                }
            });
        }
        ui.separator();
        ui.heading("Light");
        let has_plate = self.session.doc().background.is_some();
        let mut auto = self.session.doc().auto_light.is_some();
        ui.horizontal(|ui| {
            ui.radio_value(&mut auto, false, "keys");
            ui.add_enabled_ui(has_plate, |ui| ui.radio_value(&mut auto, true, "found in the plate"))
                .response
                .on_disabled_hover_text("needs a plate");
        });
        match (auto, self.session.doc().auto_light.is_some()) {
            (true, false) => self.session.edit().auto_light = Some(AutoLight::default()),
            (false, true) => self.session.edit().auto_light = None,
            _ => {}
        }
        if let Some(a) = &mut self.session.edit().auto_light {
            ui.horizontal(|ui| {
                let r =
                    ui.add(egui::DragValue::new(&mut a.threshold).range(1e-6..=1e9).speed(0.05).prefix("threshold "));
                crate::panels::labelled_value(
                    r.on_hover_text("plate luminance above which a pixel is the light"),
                    "light threshold",
                    a.threshold,
                );
                let mut n = a.smooth_frames as i64;
                let r = ui.add(egui::DragValue::new(&mut n).range(1..=101).prefix("smooth ").suffix(" frames"));
                crate::panels::labelled_value(
                    r.on_hover_text(
                        "an optional denoise of the measured visibility over this many frames (odd; 1: off, the \
                         flare follows each frame)",
                    ),
                    "smooth frames",
                    n as f64,
                );
                a.smooth_frames = (n.max(1) as usize) | 1;
            });
        }
        if self.jobs.shot_running() {
            self.jobs.shot_progress_ui(ui);
        } else if !self.jobs.shot_status().is_empty() {
            ui.label(self.jobs.shot_status());
        }
        ui.add(
            egui::TextEdit::singleline(&mut self.track_path).hint_text("track.csv").desired_width(ui.available_width()),
        )
        .on_hover_text("a tracker's CSV: frame,x_px,y_px[,intensity_ev], pixels from the top-left corner, y down");
        ui.horizontal(|ui| {
            if ui.button("Import track").clicked() {
                let path = std::path::PathBuf::from(self.track_path.trim());
                self.import_track(&path);
            }
            if ui.button("Browse…").clicked() {
                self.pick_file(super::files::FileUse::Track);
            }
        });
        ui.separator();
        ui.heading("Export sequence");
        ui.add(
            egui::TextEdit::singleline(&mut self.sequence_path)
                .hint_text("out/flare.####.exr")
                .desired_width(ui.available_width()),
        )
        .on_hover_text("EXR: linear layers (composite, flare, starburst, plate); PNG: tonemapped");
        ui.horizontal(|ui| {
            let exporting = self.jobs.exporting_sequence();
            if ui.add_enabled(!exporting, egui::Button::new("Export sequence")).clicked() {
                let pattern = self.sequence_path.trim().to_string();
                self.export_sequence(&pattern, true);
            }
        });
        ui.label(format!(
            "frames {}-{}, {}",
            self.session.doc().timeline.first_frame,
            self.session.doc().timeline.last_frame,
            match &self.derived.plate() {
                Some(p) if has_plate && self.export_size.is_none() => {
                    format!("{}x{} (the plate's size)", p.width, p.height)
                }
                _ => format!("{}x{} (File > export size)", self.export_px().0, self.export_px().1),
            }
        ));
    }
}
