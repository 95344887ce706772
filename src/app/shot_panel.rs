//! The shot's two panels as functions of what they edit: the timeline strip under the viewport
//! ([`timeline_ui`]: play and pause, scrub, the frame number, set and delete a key, the light's intensity, the
//! keys as ticks, the sections' toggles) and the Shot tab ([`shot_ui`]: frame range and rate, interpolation,
//! shutter, the plate, the sensor and desqueeze, the light found in the plate, a tracker's CSV, the sequence
//! export).
//!
//! # How it works
//! Each takes the session (the document and its history: every edit here is undoable), the view (the
//! playhead, playback), its own text fields ([`ShotFields`]) and what it only shows ([`ShotInfo`]: the light,
//! the selected ghost's surfaces, the light found in the plate, the lens's squeeze, the shot job's progress).
//! What needs more than that (a file chooser, reading a track or a plate, starting or cancelling a job) comes
//! back as a [`ShotAction`] that the app carries out ([`super::timeline`]). A key ([`set_key`]) is a function
//! of the session alone.

use std::path::PathBuf;

use eframe::egui;
use flare_core::footage::detect::AutoLight;
use flare_core::footage::pattern::FramePattern;
use flare_core::preset::ghost_key;
use flare_core::shot::ShotPlan;
use flare_core::timeline::Interpolation;

use super::derived::Derived;
use super::files::FileUse;
use super::jobs::JobBoard;
use super::session::Session;
use super::ui_state::{UiState, sections_ui};
use super::view::View;
use crate::panels::labelled_value;

/// The Shot panel's text fields (paths typed before their button applies them).
pub struct ShotFields {
    pub track_path: String,
    pub sequence_path: String,
    pub plate_path: String,
}

impl Default for ShotFields {
    fn default() -> Self {
        Self { track_path: String::new(), sequence_path: "flare.####.exr".into(), plate_path: String::new() }
    }
}

/// What the shot's panels show and do not edit.
pub struct ShotInfo<'a> {
    /// The light where the frame draws it (degrees): what a key records.
    pub light_deg: [f64; 2],
    /// The selected ghost's two surfaces: a key records its gain too.
    pub ghost: Option<(usize, usize)>,
    /// The light found in the plate (its visibility is drawn along the scrub bar).
    pub plan: Option<&'a ShotPlan>,
    /// The lens's anamorphic squeeze, if it has one (the desqueeze row shows with it).
    pub squeeze: Option<f64>,
    /// The size an export draws at and why (the plate's, or File > export size).
    pub export_size: String,
    /// The shot job's progress (finding the light or exporting), while it runs.
    pub job: Option<(f32, String)>,
    /// What the last shot job said.
    pub job_status: &'a str,
    /// A sequence export runs.
    pub exporting: bool,
}

impl<'a> ShotInfo<'a> {
    /// What the shot's panels show: the light, the selected ghost, the light found, the squeeze, the export's size
    /// (`export_px`, and whether the plate decides it), the shot job.
    pub fn new(
        session: &Session,
        derived: &'a Derived,
        jobs: &'a JobBoard,
        export_px: (u32, u32),
        plate_decides: bool,
    ) -> Self {
        let (doc, selected) = (session.doc(), session.selected());
        let ghost = selected.and_then(|g| derived.flare().as_ref()?.system.ghosts.get(g).map(|g| (g.i, g.j)));
        let export_size = if plate_decides {
            format!("{}x{} (the plate's size)", export_px.0, export_px.1)
        } else {
            format!("{}x{} (File > export size)", export_px.0, export_px.1)
        };
        Self {
            light_deg: derived.light_deg(doc),
            ghost,
            plan: derived.shot_plan().as_deref(),
            squeeze: derived.first_order().as_ref().and_then(|fo| fo.squeeze()),
            export_size,
            job: jobs.shot_running().then(|| jobs.shot_progress()).flatten(),
            job_status: jobs.shot_status(),
            exporting: jobs.exporting_sequence(),
        }
    }
}

/// What the Shot panel asks the app to do.
#[derive(Debug, PartialEq)]
pub enum ShotAction {
    /// Use this file as the plate (a numbered file with siblings becomes its sequence).
    UsePlate(PathBuf),
    /// Open the file chooser for this use.
    Browse(FileUse),
    /// Import this tracker's CSV as light keys.
    ImportTrack(PathBuf),
    /// Export the timeline's range to this sequence.
    ExportSequence(String),
    /// Cancel the shot job.
    CancelShot,
}

/// The timeline strip (see the module documentation).
pub fn timeline_ui(ui: &mut egui::Ui, session: &mut Session, view: &mut View, state: &mut UiState, info: &ShotInfo) {
    let (first, last) = (session.doc().timeline.first_frame, session.doc().timeline.last_frame);
    let mut seek = None;
    ui.horizontal(|ui| {
        if ui.button(if view.playing() { "Pause" } else { "Play" }).clicked() {
            view.toggle_play();
        }
        if ui.button("|<").on_hover_text("first frame").clicked() {
            seek = Some(first);
        }
        if ui.button("<").on_hover_text("previous frame").clicked() {
            seek = Some(view.playhead() - 1);
        }
        if ui.button(">").on_hover_text("next frame").clicked() {
            seek = Some(view.playhead() + 1);
        }
        let mut frame = view.playhead();
        let r = ui.add(egui::DragValue::new(&mut frame).range(first..=last).prefix("frame "));
        labelled_value(r, "frame", frame as f64);
        if frame != view.playhead() {
            seek = Some(frame);
        }
        let keyed = session.doc().timeline.has_key_at(view.playhead());
        if ui
            .button(if keyed { "Update key" } else { "Set key" })
            .on_hover_text("key the light's position and intensity (and the selected ghost's gain) at this frame")
            .clicked()
        {
            set_key(session, view.playhead(), info.light_deg, info.ghost);
        }
        if ui.add_enabled(keyed, egui::Button::new("Delete key")).clicked() {
            session.edit().timeline.delete_keys_at(view.playhead());
            session.say(format!("deleted the keys at frame {}", view.playhead()));
        }
        let now = session.doc().timeline.sample(view.playhead() as f64).light_ev;
        let mut ev = now;
        let r = ui.add(egui::DragValue::new(&mut ev).range(-64.0..=64.0).speed(0.05).suffix(" EV"));
        labelled_value(r.on_hover_text("the light's intensity at this frame (sets a key)"), "light intensity", ev);
        if ev != now {
            session.edit().timeline.light_ev.set(view.playhead(), ev);
        }
        ui.separator();
        sections_ui(ui, state, session.doc().dof.enabled);
    });
    if let Some(frame) = seek {
        view.seek(frame, first, last);
    }
    scrub_bar_ui(ui, session, view, info.plan, first, last);
}

/// The scrub bar: the range, a tick per key frame, the light's visibility found in the plate, the playhead;
/// click or drag to move the playhead.
fn scrub_bar_ui(ui: &mut egui::Ui, session: &Session, view: &mut View, plan: Option<&ShotPlan>, first: i64, last: i64) {
    let (rect, response) =
        ui.allocate_exact_size(egui::vec2(ui.available_width(), 18.0), egui::Sense::click_and_drag());
    let span = (last - first).max(1) as f32;
    let x_of = |f: i64| rect.left() + 6.0 + (f - first) as f32 / span * (rect.width() - 12.0);
    if (response.dragged() || response.clicked())
        && let Some(p) = response.interact_pointer_pos()
    {
        let t = ((p.x - rect.left() - 6.0) / (rect.width() - 12.0)).clamp(0.0, 1.0);
        view.seek(first + (t * span).round() as i64, first, last);
    }
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 3.0, egui::Color32::from_gray(28));
    let timeline = &session.doc().timeline;
    for f in timeline.key_frames() {
        let colour = if timeline.light_deg.keys.iter().any(|k| k.frame == f) {
            egui::Color32::from_rgb(255, 210, 90)
        } else {
            egui::Color32::from_rgb(120, 200, 255)
        };
        let x = x_of(f);
        painter.line_segment([egui::pos2(x, rect.top() + 3.0), egui::pos2(x, rect.bottom() - 3.0)], (2.0, colour));
    }
    if let Some(plan) = plan {
        let points: Vec<egui::Pos2> = plan
            .frames
            .iter()
            .map(|p| egui::pos2(x_of(p.frame), rect.bottom() - 2.0 - p.visibility as f32 * (rect.height() - 4.0)))
            .collect();
        painter.add(egui::Shape::line(points, (1.0, egui::Color32::from_rgb(140, 230, 140))));
    }
    let x = x_of(view.playhead());
    painter.line_segment(
        [egui::pos2(x, rect.top()), egui::pos2(x, rect.bottom())],
        (2.0, egui::Color32::from_rgb(255, 80, 80)),
    );
}

/// Keys the light's position (`light_deg`) and intensity, and the gain of the ghost between surfaces `ghost`
/// when one is selected, at `frame`; says what it keyed.
pub fn set_key(session: &mut Session, frame: i64, light_deg: [f64; 2], ghost: Option<(usize, usize)>) {
    let sample = session.doc().timeline.sample(frame as f64);
    session.edit().timeline.light_deg.set(frame, light_deg);
    session.edit().timeline.light_ev.set(frame, sample.light_ev);
    let mut said = format!(
        "keyed frame {frame}: the light at ({:.2}, {:.2}) deg, {:+.1} EV",
        light_deg[0], light_deg[1], sample.light_ev
    );
    if let Some((i, j)) = ghost {
        let key = ghost_key(i, j);
        let gain = sample
            .ghost_gain
            .get(&key)
            .copied()
            .unwrap_or_else(|| session.doc().ghosts.get(&key).map_or(1.0, |d| d.gain));
        session.edit().timeline.ghost_gain.entry(key).or_default().set(frame, gain);
        said.push_str(&format!(", ghost {i}-{j} at gain {gain:.2}"));
    }
    session.say(said);
}

/// The Shot panel (see the module documentation).
pub fn shot_ui(
    ui: &mut egui::Ui,
    session: &mut Session,
    view: &mut View,
    fields: &mut ShotFields,
    info: &ShotInfo,
) -> Option<ShotAction> {
    let mut action = None;
    timeline_rows(ui, session, view);
    ui.separator();
    ui.heading("Plate");
    // Each path field takes the panel's width, its buttons under it.
    ui.add(
        egui::TextEdit::singleline(&mut fields.plate_path)
            .hint_text("plates/shot.####.exr")
            .desired_width(ui.available_width()),
    )
    .on_hover_text("a plate, or a sequence with #### or %04d for the frame number");
    ui.horizontal(|ui| {
        if ui.button("Use").clicked() {
            let text = fields.plate_path.trim().to_string();
            if text.is_empty() {
                session.edit().background = None;
            } else if FramePattern::is_pattern(&text) {
                session.edit().background = Some(text);
            } else {
                action = Some(ShotAction::UsePlate(PathBuf::from(text)));
            }
        }
        if ui.button("Browse…").clicked() {
            action = Some(ShotAction::Browse(FileUse::Background));
        }
    });
    sensor_rows(ui, session, info.squeeze);
    ui.separator();
    ui.heading("Light");
    light_rows(ui, session);
    if let Some((fraction, _)) = &info.job {
        ui.horizontal(|ui| {
            ui.add(egui::ProgressBar::new(*fraction).text(info.job_status).desired_width(240.0))
                .on_hover_text(info.job_status);
            if ui.button("Cancel").clicked() {
                action = Some(ShotAction::CancelShot);
            }
        });
    } else if !info.job_status.is_empty() {
        ui.label(info.job_status);
    }
    ui.add(
        egui::TextEdit::singleline(&mut fields.track_path).hint_text("track.csv").desired_width(ui.available_width()),
    )
    .on_hover_text("a tracker's CSV: frame,x_px,y_px[,intensity_ev], pixels from the top-left corner, y down");
    ui.horizontal(|ui| {
        if ui.button("Import track").clicked() {
            action = Some(ShotAction::ImportTrack(PathBuf::from(fields.track_path.trim())));
        }
        if ui.button("Browse…").clicked() {
            action = Some(ShotAction::Browse(FileUse::Track));
        }
    });
    ui.separator();
    ui.heading("Export sequence");
    ui.add(
        egui::TextEdit::singleline(&mut fields.sequence_path)
            .hint_text("out/flare.####.exr")
            .desired_width(ui.available_width()),
    )
    .on_hover_text("EXR: linear layers (composite, flare, starburst, plate); PNG: tonemapped");
    if ui.add_enabled(!info.exporting, egui::Button::new("Export sequence")).clicked() {
        action = Some(ShotAction::ExportSequence(fields.sequence_path.trim().to_string()));
    }
    let timeline = &session.doc().timeline;
    ui.label(format!("frames {}-{}, {}", timeline.first_frame, timeline.last_frame, info.export_size));
    action
}

/// The Shot panel's timeline rows: range, rate, interpolation, shutter, the keys' counts and Clear.
fn timeline_rows(ui: &mut egui::Ui, session: &mut Session, view: &mut View) {
    let tl = &mut session.edit().timeline;
    ui.heading("Timeline");
    ui.horizontal(|ui| {
        let r = ui.add(egui::DragValue::new(&mut tl.first_frame).prefix("first "));
        labelled_value(r, "first frame", tl.first_frame as f64);
        let r = ui.add(egui::DragValue::new(&mut tl.last_frame).prefix("last "));
        labelled_value(r, "last frame", tl.last_frame as f64);
        tl.last_frame = tl.last_frame.max(tl.first_frame);
        let r = ui.add(egui::DragValue::new(&mut tl.fps).range(0.001..=1000.0).suffix(" fps"));
        labelled_value(r, "fps", tl.fps);
    });
    ui.horizontal(|ui| {
        ui.label("between keys:");
        ui.selectable_value(&mut tl.interpolation, Interpolation::Linear, "linear");
        ui.selectable_value(&mut tl.interpolation, Interpolation::Smooth, "smooth");
    });
    let r = ui.add(
        egui::DragValue::new(&mut tl.shutter_deg)
            .range(0.0..=flare_core::shutter::MAX_SHUTTER_DEG)
            .speed(1.0)
            .prefix("shutter ")
            .suffix("°"),
    );
    labelled_value(
        r.on_hover_text(
            "open this part of each frame (180°: half): a light that moves while it is open streaks its ghosts; 0°: \
             no motion blur",
        ),
        "shutter",
        tl.shutter_deg,
    );
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
    let timeline = &session.doc().timeline;
    view.clamp_playhead(timeline.first_frame, timeline.last_frame);
}

/// The sensor's width and, for an anamorphic lens or a desqueezed document, the desqueeze (with the lens's own
/// squeeze one click away).
fn sensor_rows(ui: &mut egui::Ui, session: &mut Session, squeeze: Option<f64>) {
    let r =
        ui.add(egui::DragValue::new(&mut session.edit().sensor_width_mm).range(1.0..=200.0).speed(0.1).suffix(" mm"));
    labelled_value(
        r.on_hover_text("the width of the sensor the frame (and the plate) spans"),
        "sensor width",
        session.doc().sensor_width_mm,
    );
    if squeeze.is_none() && session.doc().desqueeze == 1.0 {
        return;
    }
    ui.horizontal(|ui| {
        let max = flare_core::frame::MAX_DESQUEEZE;
        let r =
            ui.add(egui::DragValue::new(&mut session.edit().desqueeze).range(1.0 / max..=max).speed(0.01).prefix("x"));
        labelled_value(
            r.on_hover_text(
                "the delivered frame shows the sensor stretched along x by this factor (an anamorphic lens's squeeze \
                 undone, for desqueezed plates); 1: the sensor as it is",
            ),
            "desqueeze",
            session.doc().desqueeze,
        );
        if let Some(s) = squeeze.filter(|s| (1.0 / max..=max).contains(s))
            && ui.button(format!("the lens's x{s:.3}")).clicked()
        {
            session.edit().desqueeze = s;
        }
    });
}

/// Where the light comes from: keys, or found in the plate (with its threshold and smoothing).
fn light_rows(ui: &mut egui::Ui, session: &mut Session) {
    let has_plate = session.doc().background.is_some();
    let mut auto = session.doc().auto_light.is_some();
    ui.horizontal(|ui| {
        ui.radio_value(&mut auto, false, "keys");
        ui.add_enabled_ui(has_plate, |ui| ui.radio_value(&mut auto, true, "found in the plate"))
            .response
            .on_disabled_hover_text("needs a plate");
    });
    match (auto, session.doc().auto_light.is_some()) {
        (true, false) => session.edit().auto_light = Some(AutoLight::default()),
        (false, true) => session.edit().auto_light = None,
        _ => {}
    }
    if let Some(a) = &mut session.edit().auto_light {
        ui.horizontal(|ui| {
            let r = ui.add(egui::DragValue::new(&mut a.threshold).range(1e-6..=1e9).speed(0.05).prefix("threshold "));
            labelled_value(
                r.on_hover_text("plate luminance above which a pixel is the light"),
                "light threshold",
                a.threshold,
            );
            let mut n = a.smooth_frames as i64;
            let r = ui.add(egui::DragValue::new(&mut n).range(1..=101).prefix("smooth ").suffix(" frames"));
            labelled_value(
                r.on_hover_text(
                    "an optional denoise of the measured visibility over this many frames (odd; 1: off, the flare \
                     follows each frame)",
                ),
                "smooth frames",
                n as f64,
            );
            a.smooth_frames = (n.max(1) as usize) | 1;
        });
    }
}
