//! Work on a thread with progress and Cancel, polled by the UI each frame (the window never blocks): the
//! bake ([`super::bake`]), the shot jobs ([`super::shot`]) and File > Export image.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Where a job stands.
pub enum JobPoll<T> {
    /// Still running: the fraction done and what it is doing.
    Running(f32, String),
    /// Finished (or stopped): handed over once.
    Finished(T),
}

/// A job running on its thread.
pub struct Job<T> {
    cancel: Arc<AtomicBool>,
    progress: Arc<Mutex<(f32, String)>>,
    result: Arc<Mutex<Option<T>>>,
}

impl<T: Send + 'static> Job<T> {
    /// Runs `work(cancel, report)` on a new thread; `report(fraction, text)` is what [`Self::poll`] shows
    /// while it runs, starting with `first`.
    pub fn spawn(
        first: &str,
        work: impl FnOnce(&AtomicBool, &(dyn Fn(f32, String) + Sync)) -> T + Send + 'static,
    ) -> Self {
        let job = Self {
            cancel: Arc::new(AtomicBool::new(false)),
            progress: Arc::new(Mutex::new((0.0, first.to_owned()))),
            result: Arc::new(Mutex::new(None)),
        };
        let (cancel, progress, result) = (job.cancel.clone(), job.progress.clone(), job.result.clone());
        std::thread::spawn(move || {
            let report = move |fraction: f32, text: String| {
                if let Ok(mut p) = progress.lock() {
                    *p = (fraction, text);
                }
            };
            let outcome = work(&cancel, &report);
            if let Ok(mut r) = result.lock() {
                *r = Some(outcome);
            }
        });
        job
    }

    /// Asks the thread to stop at its next check.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// True once Cancel was asked for.
    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// The fraction done and what it is doing (without taking a finished outcome).
    pub fn progress(&self) -> (f32, String) {
        self.progress.lock().map(|p| p.clone()).unwrap_or_default()
    }

    /// Where the job stands; a finished job's outcome is handed over once.
    pub fn poll(&self) -> JobPoll<T> {
        match self.result.lock().ok().and_then(|mut r| r.take()) {
            Some(outcome) => JobPoll::Finished(outcome),
            None => {
                let (fraction, text) = self.progress();
                JobPoll::Running(fraction, text)
            }
        }
    }
}
