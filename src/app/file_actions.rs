//! The file actions of the app: choosing a file for a [`FileUse`] (the native dialog on a thread, else the
//! in-app browser; see [`super::files`]), doing the action with the chosen file, and File > Open recent.

use std::path::Path;
use std::time::{Duration, Instant};

use eframe::egui;

use super::FlareLabApp;
use super::files::{FileUse, NATIVE_TOO_FAST};
use super::jobs::job::{Job, JobPoll};

impl FlareLabApp {
    /// Chooses a file for `use_` (see the module documentation); the action happens when one is chosen.
    pub fn pick_file(&mut self, use_: FileUse) {
        if self.files.busy() {
            self.session.say("a file chooser is already open");
            return;
        }
        if !self.files.native {
            if !self.files.told {
                // Said once: why FlareLab's own browser and not the desktop's dialog.
                self.files.told = true;
                if !super::files::native_dialog_available() {
                    self.session.say(
                        "no desktop file dialog here (no D-Bus session for the portal, no zenity on PATH): using \
                         FlareLab's file browser",
                    );
                }
            }
            self.files.open_browser(use_);
            return;
        }
        let start = self.files.start_dir();
        let job = Job::spawn(use_.title(), move |_, _| {
            let mut dialog = rfd::FileDialog::new().set_title(use_.title()).add_filter(use_.title(), use_.extensions());
            if let Some(dir) = start {
                dialog = dialog.set_directory(dir);
            }
            if use_.saving() { dialog.set_file_name(use_.default_name()).save_file() } else { dialog.pick_file() }
        });
        self.files.pending = Some((use_, Instant::now(), job));
    }

    /// Each frame: the native dialog's answer, or the in-app browser drawn and its answer.
    pub(super) fn files_step(&mut self, ctx: &egui::Context) {
        if let Some((use_, started, job)) = &self.files.pending
            && let JobPoll::Finished(picked) = job.poll()
        {
            let (use_, quick) = (*use_, started.elapsed() < NATIVE_TOO_FAST);
            self.files.pending = None;
            match picked {
                Some(path) => self.use_file(use_, &path),
                None if quick => {
                    // The dialog could not show: from now on the in-app browser (said here, once).
                    self.files.native = false;
                    self.files.told = true;
                    self.session.say(
                        "the desktop's file dialog did not open (no portal or zenity?): using FlareLab's file browser",
                    );
                    self.files.open_browser(use_);
                }
                None => self.session.say(format!("{}: no file chosen", use_.title())),
            }
        } else if self.files.pending.is_some() {
            ctx.request_repaint_after(Duration::from_millis(100));
        }
        let Some((use_, dialog)) = &mut self.files.browser else { return };
        let use_ = *use_;
        match dialog.show(ctx).state() {
            egui_file::State::Open => {}
            egui_file::State::Selected => {
                let path = dialog.path().map(Path::to_path_buf);
                self.files.browser = None;
                match path {
                    Some(path) => self.use_file(use_, &path),
                    None => self.session.say(format!("{}: no file chosen", use_.title())),
                }
            }
            egui_file::State::Cancelled | egui_file::State::Closed => {
                self.files.browser = None;
                self.session.say(format!("{}: no file chosen", use_.title()));
            }
        }
    }

    /// Does what `use_` does with `path` (each action says in the status bar what happened) and remembers it.
    /// A file to write whose name has none of the action's extensions gets the first (`mylook` is saved as
    /// `mylook.json`).
    pub fn use_file(&mut self, use_: FileUse, path: &Path) {
        let named = use_.saving().then(|| with_extension(path, use_.extensions())).flatten();
        let path = named.as_deref().unwrap_or(path);
        match use_ {
            FileUse::OpenPreset => self.open_preset_file(path),
            FileUse::SavePreset => self.save_preset_to(path),
            FileUse::ExportImage => self.export_image_file(path),
            FileUse::OpenLens => self.open_lens(path),
            FileUse::OpenLut => self.open_lut(path),
            FileUse::ExportLut => self.export_lut_to(path),
            FileUse::Background => self.set_background(path),
            FileUse::Track => {
                self.shot_fields.track_path = path.display().to_string();
                self.import_track(path);
            }
            FileUse::ApertureImage => self.use_aperture_image(path),
            FileUse::DirtImage => self.use_dirt_image(path),
            FileUse::ExportSequence => self.export_sequence_named(path),
            FileUse::ExportReport => {
                let said = super::ghost_report_panel::export_report(self.jobs.report(), path);
                self.session.say(said);
            }
            FileUse::GlassCatalogue => self.add_glass_catalogue(path),
            FileUse::DepthMap => {
                super::dof_row::set_depth_map(&mut self.session, path);
                // Its rows open, so the focus that comes next is at hand.
                self.ui.dof_open = true;
            }
        }
        if path.exists() {
            self.files.remember(path);
        }
    }

    /// File > Open recent: a recent file opened by what it is.
    pub fn open_recent(&mut self, path: &Path) {
        if !path.exists() {
            self.session.say(format!("{} is gone", path.display()));
            self.files.recent.retain(|p| p != path);
            return;
        }
        self.open_dropped(path);
        self.files.remember(path);
    }
}

/// `path` with `extensions[0]` added when its name ends in none of `extensions` (compared without case); `None`
/// when it already does.
fn with_extension(path: &Path, extensions: &[&str]) -> Option<std::path::PathBuf> {
    let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
    if extensions.iter().any(|e| name.ends_with(&format!(".{e}"))) {
        return None;
    }
    let first = extensions.first()?;
    let mut named = path.as_os_str().to_owned();
    named.push(format!(".{first}"));
    Some(named.into())
}
