//! Choosing files: the desktop's native dialog where there is one, else FlareLab's own file browser
//! (egui_file), and the recent files. No file action ever fails silently.
//!
//! # How it works
//! [`FileUse`] says what a file is for (its title, extensions, open or save). The app's `pick_file`
//! ([`super::file_actions`]) asks the native dialog (rfd: the desktop portal over D-Bus, else zenity) on a thread,
//! so the window keeps drawing while it is open; where neither exists (no `DBUS_SESSION_BUS_ADDRESS`, no `zenity`
//! on `PATH`), or when the native dialog returned at once without showing (it could not open), the in-app browser
//! opens instead and the status bar says why. Whatever picks the file, the app's `use_file` does the one thing the
//! action does (each of which reports success or failure in the status bar) and the file joins the recent files
//! (File > Open recent; kept with the session).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::jobs::job::Job;

/// Recent files kept.
pub const RECENT: usize = 10;
/// A native dialog that returns sooner than this never showed.
pub(super) const NATIVE_TOO_FAST: Duration = Duration::from_millis(250);

/// What a chosen file is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileUse {
    OpenPreset,
    SavePreset,
    ExportImage,
    OpenLens,
    OpenLut,
    ExportLut,
    Background,
    Track,
    ApertureImage,
    DirtImage,
    ExportSequence,
    ExportReport,
    GlassCatalogue,
    DepthMap,
}

impl FileUse {
    pub fn title(self) -> &'static str {
        match self {
            Self::OpenPreset => "Open preset",
            Self::SavePreset => "Save preset",
            Self::ExportImage => "Export image",
            Self::OpenLens => "Open lens",
            Self::OpenLut => "Open LUT",
            Self::ExportLut => "Export LUT",
            Self::Background => "Background plate",
            Self::Track => "Import light track",
            Self::ApertureImage => "Custom aperture image",
            Self::DirtImage => "Front dirt image",
            Self::ExportSequence => "Export sequence",
            Self::ExportReport => "Export ghost report",
            Self::GlassCatalogue => "Add glass catalogue",
            Self::DepthMap => "Depth map",
        }
    }

    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            Self::OpenPreset | Self::SavePreset => &["json"],
            Self::ExportImage | Self::ExportSequence => &["png", "exr"],
            Self::OpenLens => &["json", "zmx", "dat", "lens", "xml"],
            Self::OpenLut | Self::ExportLut => &["flut"],
            Self::Background => &["exr", "png", "hdr", "jpg", "jpeg"],
            Self::Track => &["csv", "txt"],
            Self::ApertureImage => &["png", "jpg", "exr"],
            Self::DirtImage => &["png", "jpg", "jpeg", "exr", "hdr"],
            Self::ExportReport => &["csv", "json"],
            Self::GlassCatalogue => &["agf"],
            Self::DepthMap => &["exr", "png"],
        }
    }

    /// True for a file to write.
    pub fn saving(self) -> bool {
        matches!(
            self,
            Self::SavePreset | Self::ExportImage | Self::ExportLut | Self::ExportSequence | Self::ExportReport
        )
    }

    pub(super) fn default_name(self) -> &'static str {
        match self {
            Self::SavePreset => "flare.json",
            Self::ExportImage => "flare.png",
            Self::ExportLut => "flare.flut",
            Self::ExportSequence => "flare.####.exr",
            Self::ExportReport => "ghost-report.csv",
            _ => "",
        }
    }
}

/// The file choosers' state.
pub struct Files {
    /// Use the native dialog (false: the in-app browser).
    pub native: bool,
    pub(super) browser: Option<(FileUse, egui_file::FileDialog)>,
    pub(super) pending: Option<(FileUse, Instant, Job<Option<PathBuf>>)>,
    /// Most recent first.
    pub recent: Vec<PathBuf>,
    /// Whether the status bar said why the in-app browser is used (said once a session).
    pub(super) told: bool,
}

impl Default for Files {
    fn default() -> Self {
        Self { native: native_dialog_available(), browser: None, pending: None, recent: Vec::new(), told: false }
    }
}

/// Whether this desktop can show rfd's native dialog: a session bus (for the portal) or zenity.
pub fn native_dialog_available() -> bool {
    let bus = std::env::var_os("DBUS_SESSION_BUS_ADDRESS").is_some_and(|v| !v.is_empty());
    let zenity = std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join("zenity").is_file()));
    bus || zenity
}

impl Files {
    /// True while a chooser is open.
    pub fn busy(&self) -> bool {
        self.browser.is_some() || self.pending.is_some()
    }

    /// The in-app browser's kind, when it is open (for the tests).
    pub fn browsing(&self) -> Option<FileUse> {
        self.browser.as_ref().map(|(u, _)| *u)
    }

    /// Puts `path` first in the recent files.
    pub fn remember(&mut self, path: &Path) {
        let path = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        self.recent.retain(|p| *p != path);
        self.recent.insert(0, path);
        self.recent.truncate(RECENT);
    }

    /// The folder a chooser starts in: the latest recent file's.
    pub(super) fn start_dir(&self) -> Option<PathBuf> {
        self.recent.first().and_then(|p| p.parent()).map(Path::to_path_buf)
    }

    pub(super) fn open_browser(&mut self, use_: FileUse) {
        let extensions = use_.extensions();
        let filter: egui_file::Filter<PathBuf> = Box::new(move |p: &Path| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| extensions.contains(&e.to_ascii_lowercase().as_str()))
        });
        let mut dialog = if use_.saving() {
            egui_file::FileDialog::save_file().default_filename(use_.default_name())
        } else {
            // egui_file's open dialog opens only a file picked in its list: its Open button ignores a typed name
            // (Enter does not). Its save dialog takes the name field, which a click in the list fills, for
            // both: so files are opened through it, its button named Open, without its folder and rename
            // buttons. Enter and Open then do the same.
            egui_file::FileDialog::save_file()
                .save_button_text("Open".into())
                .show_new_folder(false)
                .show_rename(false)
                .show_files_filter(filter)
        };
        dialog = dialog.title(use_.title());
        if let Some(dir) = self.start_dir().or_else(|| std::env::current_dir().ok()) {
            dialog = dialog.initial_path(dir);
        }
        dialog.open();
        self.browser = Some((use_, dialog));
    }
}
