//! Work on a thread with progress and Cancel, polled by the UI each frame (the window never blocks): every
//! job kind of the board ([`super`]) is a [`Job`], most of them held in a [`Slot`] (one at a time, the latest
//! request waiting, cancelled ones watched until their threads end).
//!
//! One priority rule ([`Priority`]), three levels: the window (its UI thread, and on a software adapter the
//! rasteriser's threads that draw it) at the app's priority; what the user waits for (the depth of field's
//! focus, an export, a ray-grid view) is **interactive** and runs on a pool of its own a step below (nice 10
//! on Linux); what only improves the view later (the bake, the looks' thumbnails) is **background** and runs
//! on a pool of its own whose threads, and the job's own thread, run at the lowest priority the system gives
//! (nice 19). On a 2-core machine a bake at full speed then no longer starves a focus click (the scheduler
//! gives the interactive threads nearly all of the processor while both run, and the bake the rest), and no
//! job starves the window: on lavapipe a ray-grid trace or a defocus at the app's priority held a frame for
//! 170-500 ms after an input (issue 60's replay under Xvfb). **No job runs on rayon's global pool**:
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
    /// The progress as the UI last read it: shown again while the job's thread holds the lock (the UI thread
    /// never waits on a job's lock; a background job's thread, at the lowest priority, may be preempted while it
    /// holds it, and the window would wait for it: a priority inversion that cost 3 s frames).
    seen: Mutex<(f32, String)>,
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
    /// The user waits for it: a pool of its own, a step below the window ([`INTERACTIVE_NICE`]).
    Interactive,
    /// It only improves the view later: its own pool at the lowest priority.
    Background,
}

/// The pool jobs of `priority` run their parallel work on, made on first use: as many threads as the global
/// pool, named `job-N` (interactive, at [`INTERACTIVE_NICE`]) or `background-N` (each at the lowest priority). Both
/// stay apart from the global pool, which the UI thread's frame uses. `None` if the system refuses the threads
/// (the job then runs on its own thread alone).
fn pool(priority: Priority) -> Option<&'static rayon::ThreadPool> {
    type Cell = std::sync::OnceLock<Option<rayon::ThreadPool>>;
    static INTERACTIVE: Cell = Cell::new();
    static BACKGROUND: Cell = Cell::new();
    let (cell, name, lowered) = match priority {
        Priority::Interactive => (&INTERACTIVE, "job", INTERACTIVE_NICE),
        Priority::Background => (&BACKGROUND, "background", BACKGROUND_NICE),
    };
    cell.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(move |k| format!("{name}-{k}"))
            .start_handler(move |_| {
                lower_this_threads_priority(lowered);
            })
            .build()
            .ok()
    })
    .as_ref()
}

/// The nice value of the interactive jobs' threads: below the window, above the background.
pub const INTERACTIVE_NICE: i32 = 10;

/// The nice value of the background jobs' threads: the lowest priority.
pub const BACKGROUND_NICE: i32 = 19;

/// Puts the calling thread at nice `nice` (on Linux each thread has its own; a thread can only lower its
/// own priority). Elsewhere, or if the system refuses, it stays as it was: the rule is a courtesy, never an
/// error.
pub fn lower_this_threads_priority(nice: i32) {
    // SAFETY: setpriority has no memory effects; on Linux `who` 0 is the calling thread (elsewhere it would be
    // the whole process, so other systems are left alone).
    #[cfg(target_os = "linux")]
    unsafe {
        let now = libc::getpriority(libc::PRIO_PROCESS, 0);
        libc::setpriority(libc::PRIO_PROCESS, 0, nice.max(now));
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
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
            seen: Mutex::new((0.0, first.to_owned())),
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
            lower_this_threads_priority(match priority {
                Priority::Interactive => INTERACTIVE_NICE,
                Priority::Background => BACKGROUND_NICE,
            });
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
        let Ok(mut seen) = self.seen.lock() else { return Default::default() };
        if let Ok(now) = self.progress.try_lock() {
            *seen = now.clone();
        }
        seen.clone()
    }

    /// Where the job stands; a finished job's outcome is handed over once (never waiting on the job's lock: while
    /// its thread holds it the job is still running).
    pub fn poll(&self) -> JobPoll<T> {
        match self.result.try_lock().ok().and_then(|mut r| r.take()) {
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

/// A job's work, not started yet: what [`Slot::request`] keeps until the jobs it replaced have ended.
type Start<T> = Box<dyn FnOnce() -> Job<T>>;

/// One kind of job on the board, bounded: at most one job runs for it, the jobs it replaced are cancelled and
/// watched until their threads end, and at most one request waits for them (a newer request replaces it). A
/// drag, a scrub or an undo burst therefore never piles up threads or queued work: each change cancels the
/// running job, and only the last change starts one, once the cancelled one has stopped (each job checks its
/// cancel flag inside its loops, so that takes well under a second). `K` says what a job is for.
pub struct Slot<K, T> {
    running: Option<(K, Job<T>)>,
    waiting: Option<(K, Start<T>)>,
    stopping: Stopping<T>,
}

impl<K, T> Default for Slot<K, T> {
    fn default() -> Self {
        Self { running: None, waiting: None, stopping: Stopping::default() }
    }
}

/// A finished job taken from its [`Slot`]: what it was for, its outcome, and whether Cancel was asked for.
pub struct Done<K, T> {
    pub key: K,
    pub outcome: T,
    pub cancelled: bool,
}

impl<K: PartialEq, T: Send + 'static> Slot<K, T> {
    /// Asks for the work for `key`: nothing when the running (or waiting) job is for it already; otherwise the
    /// running job is cancelled and watched, a waiting request is dropped, and `start` runs at once if no
    /// cancelled job of this kind still runs, else as soon as they have all ended ([`Self::poll`]).
    pub fn request(&mut self, key: K, start: impl FnOnce() -> Job<T> + 'static) {
        if self.running_for() == Some(&key) || self.waiting_for() == Some(&key) {
            return;
        }
        if let Some((_, job)) = self.running.take() {
            self.stopping.stop(job);
        }
        self.waiting = Some((key, Box::new(start)));
        self.start_waiting();
    }

    /// Starts `job` for `key` now, cancelling (and watching) the running one and dropping a waiting request:
    /// for a job the user started by hand whose thread is already running (one at a time by the caller's rule).
    pub fn replace(&mut self, key: K, job: Job<T>) {
        self.waiting = None;
        if let Some((_, old)) = self.running.take() {
            self.stopping.stop(old);
        }
        self.running = Some((key, job));
    }

    /// Takes the running job's outcome once it has finished, and starts a waiting request when every cancelled
    /// job has ended. Call it once a frame.
    pub fn poll(&mut self) -> Option<Done<K, T>> {
        self.stopping.prune();
        let finished = match &self.running {
            Some((_, job)) => match job.poll() {
                JobPoll::Finished(outcome) => Some(outcome),
                JobPoll::Running(..) => None,
            },
            None => None,
        };
        let done = finished.and_then(|outcome| {
            let (key, job) = self.running.take()?;
            Some(Done { key, outcome, cancelled: job.cancelled() })
        });
        self.start_waiting();
        done
    }

    fn start_waiting(&mut self) {
        self.stopping.prune();
        if self.running.is_none()
            && self.stopping.running() == 0
            && let Some((key, start)) = self.waiting.take()
        {
            self.running = Some((key, start()));
        }
    }

    /// Cancels the running job (watched until its thread ends) and drops a waiting request; what the running
    /// job was for.
    pub fn cancel(&mut self) -> Option<K> {
        self.waiting = None;
        let (key, job) = self.running.take()?;
        self.stopping.stop(job);
        Some(key)
    }

    /// Asks the running job to stop but keeps it in the slot: its outcome (most often "cancelled") is still
    /// taken by [`Self::poll`].
    pub fn ask_to_stop(&self) {
        if let Some((_, job)) = &self.running {
            job.cancel();
        }
    }

    /// What the running job is for.
    pub fn running_for(&self) -> Option<&K> {
        self.running.as_ref().map(|(key, _)| key)
    }

    /// What the waiting request is for.
    pub fn waiting_for(&self) -> Option<&K> {
        self.waiting.as_ref().map(|(key, _)| key)
    }

    /// The running job's fraction done and what it says; a waiting request says that it waits.
    pub fn progress(&self) -> Option<(f32, String)> {
        match (&self.running, &self.waiting) {
            (Some((_, job)), _) => Some(job.progress()),
            (None, Some(_)) => Some((0.0, "waiting for the cancelled job to stop".into())),
            (None, None) => None,
        }
    }

    /// True while a job runs or waits (not counting the cancelled ones).
    pub fn active(&self) -> bool {
        self.running.is_some() || self.waiting.is_some()
    }

    /// True while a job runs, waits or is still stopping (the window repaints to follow it).
    pub fn busy(&self) -> bool {
        self.active() || self.stopping.running() > 0
    }

    /// Cancelled jobs whose threads have not ended yet.
    pub fn stopping(&self) -> usize {
        self.stopping.running()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;
    use std::time::{Duration, Instant};

    /// A job that counts itself while it runs and stops within a few milliseconds of Cancel.
    fn counted(live: &Arc<AtomicUsize>, peak: &Arc<AtomicUsize>, value: u32) -> impl FnOnce() -> Job<u32> + 'static {
        let (live, peak) = (live.clone(), peak.clone());
        move || {
            Job::spawn("", move |cancel, _| {
                let now = live.fetch_add(1, Ordering::SeqCst) + 1;
                peak.fetch_max(now, Ordering::SeqCst);
                let started = Instant::now();
                while !cancel.load(Ordering::Relaxed) && started.elapsed() < Duration::from_millis(300) {
                    std::thread::sleep(Duration::from_millis(5));
                }
                live.fetch_sub(1, Ordering::SeqCst);
                value
            })
        }
    }

    fn until_done(slot: &mut Slot<u32, u32>) -> Done<u32, u32> {
        let started = Instant::now();
        loop {
            if let Some(done) = slot.poll() {
                return done;
            }
            assert!(started.elapsed() < Duration::from_secs(10), "the job never finished");
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// A burst of requests (a drag) never runs two jobs of a kind at once; only the last one runs to its end,
    /// and its outcome is for its key.
    #[test]
    fn a_burst_of_requests_runs_one_job_at_a_time_and_the_last_one_finishes() {
        let (live, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let mut slot = Slot::default();
        for k in 0..50 {
            slot.request(k, counted(&live, &peak, k));
            assert!(slot.stopping() <= 1, "cancelled jobs pile up: {}", slot.stopping());
            let _ = slot.poll();
        }
        assert_eq!(slot.waiting_for().or(slot.running_for()), Some(&49));
        let done = until_done(&mut slot);
        assert_eq!((done.key, done.outcome, done.cancelled), (49, 49, false));
        assert_eq!(peak.load(Ordering::SeqCst), 1, "two jobs of one kind ran at once");
        assert!(!slot.busy());
        // The same request again while it runs starts nothing new.
        slot.request(7, counted(&live, &peak, 7));
        slot.request(7, counted(&live, &peak, 70));
        assert_eq!(until_done(&mut slot).outcome, 7);
    }

    /// Cancel stops the running job within a second and its thread ends; nothing waits behind it.
    #[test]
    fn cancel_stops_the_job_and_its_thread_ends() {
        let (live, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let mut slot = Slot::default();
        slot.request(1, counted(&live, &peak, 1));
        std::thread::sleep(Duration::from_millis(20));
        let asked = Instant::now();
        assert_eq!(slot.cancel(), Some(1));
        assert!(!slot.active());
        while slot.busy() {
            assert!(asked.elapsed() < Duration::from_secs(1), "the cancelled job still runs");
            std::thread::sleep(Duration::from_millis(2));
            let _ = slot.poll();
        }
        assert_eq!(live.load(Ordering::SeqCst), 0);
        assert!(slot.poll().is_none(), "a cancelled job's outcome is dropped");
    }
}
