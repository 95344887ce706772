//! The UI frames' own record, for measuring the window as a user meets it (`FLARELAB_FRAME_LOG=FILE`, read by
//! [`super::options`]): the Xvfb replay of issue 60's hang (`tests/hang_replay.sh`) sends inputs with xdotool,
//! notes when it sent each, and works out from this record how long the window took to answer every one.
//!
//! # How it works
//! Each UI frame adds a line `frame START_S TOOK_MS LAST_MS` (its start as seconds since the Unix epoch, how long
//! the app's own work took, and how long the frame before took in all, painting included, as eframe says), and the app adds `event START_S TEXT` lines for what a measurement waits for (the
//! looks' thumbnails all made, a LUT shown), and `gpu START_S SUMMARY` lines with the viewport's GPU passes
//! as timed (timestamp queries), each time they change. Each line is written as it comes (a few dozen bytes: one write
//! call, microseconds), so the record is whole even when the window is killed; a file that cannot be written
//! is said once on stderr and the record stops.

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The record (see the module documentation).
pub struct FrameLog {
    path: PathBuf,
    file: Option<std::fs::File>,
    /// The GPU passes' summary last written.
    last_gpu: Option<String>,
}

/// Seconds since the Unix epoch of `at`.
fn epoch_s(at: SystemTime) -> f64 {
    at.duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

impl FrameLog {
    /// A record written to `path` (emptied first).
    pub fn new(path: PathBuf) -> Self {
        let file = std::fs::File::create(&path)
            .map_err(|e| eprintln!("FLARELAB_FRAME_LOG: {}: {e}; no frame record", path.display()))
            .ok();
        Self { path, file, last_gpu: None }
    }

    /// One UI frame that began at `began` and took `took`; `last_cpu_s`: what eframe says the frame before took
    /// in all (its UI and its painting, the viewport's GPU submission included).
    pub fn frame(&mut self, began: SystemTime, took: Duration, last_cpu_s: Option<f32>) {
        let last_ms = last_cpu_s.map_or(-1.0, |s| f64::from(s) * 1e3);
        self.line(&format!("frame {:.6} {:.3} {last_ms:.3}\n", epoch_s(began), took.as_secs_f64() * 1e3));
    }

    /// The viewport's GPU passes as last timed (`summary`: [`flare_core::render::gpu::PassTimes::summary`]),
    /// written when they change: a `gpu START_S SUMMARY` line.
    pub fn gpu(&mut self, summary: &str) {
        if self.last_gpu.as_deref() != Some(summary) {
            self.line(&format!("gpu {:.6} {summary}\n", epoch_s(SystemTime::now())));
            self.last_gpu = Some(summary.to_owned());
        }
    }

    /// Something a measurement waits for, now.
    pub fn event(&mut self, text: &str) {
        self.line(&format!("event {:.6} {text}\n", epoch_s(SystemTime::now())));
    }

    fn line(&mut self, line: &str) {
        let Some(file) = &mut self.file else { return };
        if let Err(e) = file.write_all(line.as_bytes()) {
            eprintln!("FLARELAB_FRAME_LOG: {}: {e}; the frame record stops", self.path.display());
            self.file = None;
        }
    }
}
