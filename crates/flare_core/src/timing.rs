//! Where a command's time goes: named spans of wall time, recorded while a collector is on
//! (`flarelab render --timings`).
//!
//! # How it works
//! [`span`] runs a closure and, when [`start`] has switched the collector on, records its wall time under a
//! name with its depth: on the thread that called [`start`], a span inside another is one level deeper; a span
//! on another thread (a rayon task the command waits for) is one level deeper than the command's innermost span
//! open at that moment. [`finish`] switches the collector off and returns the spans in the order they began.
//! Off (the app, the tests, every command not asked for timings), a span costs one relaxed atomic load and
//! records nothing.

use std::cell::Cell;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

static ON: AtomicBool = AtomicBool::new(false);
/// Per span: when it began, its name, its depth, how long it took.
static SPANS: Mutex<Vec<(Instant, &'static str, usize, Duration)>> = Mutex::new(Vec::new());
/// How many spans the thread that called [`start`] has open.
static MAIN_DEPTH: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    /// Whether this thread called [`start`] (its spans nest).
    static MAIN: Cell<bool> = const { Cell::new(false) };
}

/// One recorded span.
#[derive(Clone, Debug, PartialEq)]
pub struct Span {
    pub name: &'static str,
    /// 0 for a span of the command itself, 1 for a span inside one, and so on.
    pub depth: usize,
    pub ms: f64,
}

/// Switches the collector on (and forgets what an earlier one recorded).
pub fn start() {
    if let Ok(mut spans) = SPANS.lock() {
        spans.clear();
    }
    MAIN.set(true);
    MAIN_DEPTH.store(0, Ordering::Relaxed);
    ON.store(true, Ordering::Relaxed);
}

/// Runs `f`, recording its wall time under `name` while the collector is on.
pub fn span<T>(name: &'static str, f: impl FnOnce() -> T) -> T {
    if !ON.load(Ordering::Relaxed) {
        return f();
    }
    let main = MAIN.get();
    let depth = MAIN_DEPTH.load(Ordering::Relaxed);
    if main {
        MAIN_DEPTH.store(depth + 1, Ordering::Relaxed);
    }
    let began = Instant::now();
    let out = f();
    let took = began.elapsed();
    if main {
        MAIN_DEPTH.store(depth, Ordering::Relaxed);
    }
    if let Ok(mut spans) = SPANS.lock() {
        spans.push((began, name, depth, took));
    }
    out
}

/// Switches the collector off: the spans recorded since [`start`], in the order they began.
pub fn finish() -> Vec<Span> {
    ON.store(false, Ordering::Relaxed);
    MAIN.set(false);
    let mut spans = SPANS.lock().map(|mut s| std::mem::take(&mut *s)).unwrap_or_default();
    spans.sort_by_key(|s| s.0);
    spans.into_iter().map(|(_, name, depth, took)| Span { name, depth, ms: took.as_secs_f64() * 1e3 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_nest_in_the_order_they_began_and_nothing_is_kept_while_off() {
        span("before", || ());
        start();
        let x = span("outer", || {
            std::thread::sleep(Duration::from_millis(2));
            span("inner", || 7)
        });
        // (Other tests of this binary may record spans of their own meanwhile: only these two are looked at.)
        let spans: Vec<Span> = finish().into_iter().filter(|s| ["outer", "inner"].contains(&s.name)).collect();
        span("after", || ());
        assert_eq!(x, 7);
        let names: Vec<_> = spans.iter().map(|s| (s.name, s.depth)).collect();
        assert_eq!(names, [("outer", 0), ("inner", 1)]);
        assert!(spans[0].ms >= 2.0 && spans[0].ms >= spans[1].ms, "{spans:?}");
        assert!(finish().iter().all(|s| s.name != "after"));
    }
}
