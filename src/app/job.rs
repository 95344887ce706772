//! Work on a thread with progress and Cancel, polled by the UI each frame (the window never blocks): the
//! bake ([`super::bake`]), the shot jobs ([`super::shot`]) and File > Export image.
//!
//! One priority rule ([`Priority`]): what the user waits for (the depth of field's focus, an export, a ray-grid
//! view) is **interactive** and runs on a pool of its own at the app's priority; what only improves the view
//! later (the bake, the looks' thumbnails) is **background** and runs on a pool of its own whose threads, and
//! the job's own thread, run at the lowest priority the system gives (nice 19 on Unix). On a 2-core machine a
//! bake at full speed then no longer starves a focus click: the scheduler gives the interactive threads
//! nearly all of the processor while both run, and the bake the rest. **No job runs on rayon's global pool**:
//! that pool is the UI thread's (the frame's CPU work, the LUT pass), so a frame never queues behind a job's
//! parallel work (a frame once waited there behind 136 ray-grid traces).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// How often the window repaints while a job runs and nothing else asks (its progress bar moves, a finished job
/// is taken): twice a second. Every repaint draws the whole window, which on a software rasteriser costs tens of
/// milliseconds of the cores the jobs work on; at 10 a second (issue 60) an idle window with a bake running took
/// half a core of two.
pub const PROGRESS_REPAINT: std::time::Duration = std::time::Duration::from_millis(500);

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
    /// Set when the job's thread has ended (its work returned or panicked).
    ended: Arc<AtomicBool>,
}

/// Sets its flag when dropped: a job's thread marks its end however its work ends.
struct EndGuard(Arc<AtomicBool>);

impl Drop for EndGuard {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// Whom a job yields to (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Priority {
    /// The user waits for it: a pool of its own, the app's priority.
    Interactive,
    /// It only improves the view later: its own pool at the lowest priority.
    Background,
}

/// The pool jobs of `priority` run their parallel work on, made on first use: as many threads as the global
/// pool, named `job-N` (interactive, at the app's priority) or `background-N` (each at the lowest priority). Both
/// stay apart from the global pool, which the UI thread's frame uses. `None` if the system refuses the threads
/// (the job then runs on its own thread alone).
fn pool(priority: Priority) -> Option<&'static rayon::ThreadPool> {
    type Cell = std::sync::OnceLock<Option<rayon::ThreadPool>>;
    static INTERACTIVE: Cell = Cell::new();
    static BACKGROUND: Cell = Cell::new();
    let (cell, name, lowered) = match priority {
        Priority::Interactive => (&INTERACTIVE, "job", false),
        Priority::Background => (&BACKGROUND, "background", true),
    };
    cell.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(move |k| format!("{name}-{k}"))
            .start_handler(move |_| {
                if lowered {
                    lower_this_threads_priority();
                }
            })
            .build()
            .ok()
    })
    .as_ref()
}

/// Puts the calling thread at the lowest priority (nice 19; on Linux each thread has its own). Elsewhere, or if
/// the system refuses, it stays as it was: the rule is a courtesy, never an error.
pub fn lower_this_threads_priority() {
    // SAFETY: setpriority has no memory effects; on Linux `who` 0 is the calling thread (elsewhere it would be
    // the whole process, so other systems are left alone).
    #[cfg(target_os = "linux")]
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 19);
    }
}

impl<T: Send + 'static> Job<T> {
    /// Runs `work(cancel, report)` on a new thread; `report(fraction, text)` is what [`Self::poll`] shows
    /// while it runs, starting with `first`. An interactive job ([`Self::spawn_with`]).
    pub fn spawn(
        first: &str,
        work: impl FnOnce(&AtomicBool, &(dyn Fn(f32, String) + Sync)) -> T + Send + 'static,
    ) -> Self {
        Self::spawn_with(Priority::Interactive, first, work)
    }

    /// [`Self::spawn`] at `priority`: a background job's thread and its parallel work run at the lowest
    /// priority, on a pool of their own.
    pub fn spawn_with(
        priority: Priority,
        first: &str,
        work: impl FnOnce(&AtomicBool, &(dyn Fn(f32, String) + Sync)) -> T + Send + 'static,
    ) -> Self {
        let job = Self {
            cancel: Arc::new(AtomicBool::new(false)),
            progress: Arc::new(Mutex::new((0.0, first.to_owned()))),
            result: Arc::new(Mutex::new(None)),
            ended: Arc::new(AtomicBool::new(false)),
        };
        let (cancel, progress, result) = (job.cancel.clone(), job.progress.clone(), job.result.clone());
        let ended = EndGuard(job.ended.clone());
        std::thread::spawn(move || {
            let _ended = ended;
            let report = move |fraction: f32, text: String| {
                if let Ok(mut p) = progress.lock() {
                    *p = (fraction, text);
                }
            };
            if priority == Priority::Background {
                lower_this_threads_priority();
            }
            let outcome = match pool(priority) {
                Some(pool) => pool.install(|| work(&cancel, &report)),
                None => work(&cancel, &report),
            };
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

    /// True once the job's thread has ended (whether or not its outcome was taken).
    pub fn ended(&self) -> bool {
        self.ended.load(Ordering::Acquire)
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

/// Jobs cancelled and not yet ended: each was asked to stop and is watched until its thread ends (its outcome is
/// dropped), so no cancelled work goes on unseen behind the UI.
pub struct Stopping<T>(Vec<Job<T>>);

impl<T> Default for Stopping<T> {
    fn default() -> Self {
        Self(Vec::new())
    }
}

impl<T: Send + 'static> Stopping<T> {
    /// Cancels `job` and watches it.
    pub fn stop(&mut self, job: Job<T>) {
        job.cancel();
        self.0.push(job);
    }

    /// Forgets the jobs whose threads have ended.
    pub fn prune(&mut self) {
        self.0.retain(|job| !job.ended());
    }

    /// How many of them still run.
    pub fn running(&self) -> usize {
        self.0.iter().filter(|job| !job.ended()).count()
    }
}
