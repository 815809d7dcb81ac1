//! Watched threads: a reader or worker thread that panics, or ends when nobody asked it to,
//! becomes a named, counted failure its owner can see — never a silent stall.
//!
//! The thread runs its work through [`Watch::run`]: a panic is caught (the panic hook has
//! already printed it), counted and kept in words; the owner reads [`Watch::failures`] (one
//! atomic load: the control loop may ask every cycle) and [`Watch::last`] (for an event or the
//! summary), and restarts the work where that makes sense (a client reconnects).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// A thread's failures: how many, and the last in words.
#[derive(Debug, Default)]
pub struct Watch {
    failures: AtomicU64,
    last: Mutex<Option<String>>,
}

/// What a panic said, as text.
pub fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<String>()
        .cloned()
        .or_else(|| p.downcast_ref::<&str>().map(|s| (*s).to_string()))
        .unwrap_or_else(|| "a panic without a message".into())
}

impl Watch {
    /// No failure yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs `work` on the calling thread; a panic becomes a failure of `thread` (counted, kept
    /// in words) and `None`.
    pub fn run<T>(&self, thread: &str, work: impl FnOnce() -> T) -> Option<T> {
        match catch_unwind(AssertUnwindSafe(work)) {
            Ok(v) => Some(v),
            Err(p) => {
                self.fail(format!("thread {thread} panicked: {}", panic_message(&*p)));
                None
            }
        }
    }

    /// Records a failure (a panic, or an end nobody asked for), in words.
    pub fn fail(&self, what: String) {
        if let Ok(mut g) = self.last.lock() {
            *g = Some(what);
        }
        self.failures.fetch_add(1, Ordering::Release);
    }

    /// Failures so far (lock-free).
    pub fn failures(&self) -> u64 {
        self.failures.load(Ordering::Acquire)
    }

    /// The last failure, in words.
    pub fn last(&self) -> Option<String> {
        self.last.lock().ok().and_then(|g| g.clone())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::panic)]
    use super::*;

    #[test]
    fn a_panic_is_counted_and_named_and_work_that_returns_is_not() {
        let w = Watch::new();
        assert_eq!(w.run("reader", || 7), Some(7));
        assert_eq!(w.failures(), 0);
        assert_eq!(w.run("reader", || -> u8 { panic!("bad byte at 13") }), None);
        assert_eq!(w.failures(), 1);
        let last = w.last().unwrap_or_default();
        assert!(
            last.contains("reader") && last.contains("bad byte at 13"),
            "{last}"
        );
        let n = 4;
        assert_eq!(w.run("worker", || -> u8 { panic!("{n} entries") }), None);
        assert_eq!(w.failures(), 2);
        assert!(
            w.last()
                .unwrap_or_default()
                .contains("worker panicked: 4 entries")
        );
    }
}
