//! Stopping a fit from outside: a daemon job that is cancelled, or a SIGTERM, must
//! not wait for a fit that takes seconds (a large uniformity grid) or one stuck on
//! absurd data.
//!
//! The stop check is scoped to the thread the fit runs on (`with_stop`), instead of
//! being passed down through every function of the fit: the fit is single-threaded,
//! its iterative parts ask `requested()` between steps, and code that never sets a
//! check (the CLI's `fit`, the tests) pays one thread-local read per step.

use std::cell::RefCell;
use std::sync::Arc;

/// A check that says whether the work should stop now.
pub type StopCheck = Arc<dyn Fn() -> bool + Send + Sync>;

thread_local! {
    static STOP: RefCell<Option<StopCheck>> = const { RefCell::new(None) };
}

/// Run `work` on this thread with `stop` as its stop check (none: it runs to its end).
pub fn with_stop<T>(stop: Option<StopCheck>, work: impl FnOnce() -> T) -> T {
    /// Puts the previous check back, also when the work panics: the blocking pool
    /// reuses its threads, and a stale check would stop another fit.
    struct Restore(Option<StopCheck>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0.take();
            STOP.with(|s| *s.borrow_mut() = previous);
        }
    }
    let _restore = Restore(STOP.with(|s| s.replace(stop)));
    work()
}

/// Has the work running on this thread been asked to stop?
pub fn requested() -> bool {
    STOP.with(|s| s.borrow().as_ref().is_some_and(|stop| stop()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, Ordering};

    #[test]
    fn the_check_holds_inside_its_scope_only() {
        let flag = Arc::new(AtomicBool::new(false));
        let check: StopCheck = {
            let flag = flag.clone();
            Arc::new(move || flag.load(Ordering::SeqCst))
        };
        assert!(!requested());
        with_stop(Some(check), || {
            assert!(!requested());
            flag.store(true, Ordering::SeqCst);
            assert!(requested());
            // Another thread has no check.
            assert!(!std::thread::spawn(requested).join().unwrap());
        });
        assert!(!requested(), "the check ended with its scope");
    }
}
