//! The virtual clock that simulated devices run on.
//!
//! A simulated run takes minutes of instrument time but should finish in
//! milliseconds in a test, so simulated devices advance this clock instead of
//! sleeping. With a real-time scale set they also sleep, scaled, so a person can
//! watch a run at its real pace (or a test can kill one part way). Simulated time
//! passes only through `wait`, `advance` and `set`, so the readings of a run depend
//! on nothing but its seeds: a daemon that wants its monitor to age while idle
//! advances the clock itself.

use std::sync::Mutex;
use std::time::Duration;

/// Real waits shorter than this are not slept (`VirtualClock::wait`).
const MIN_SLEEP_S: f64 = 1e-5;

/// Seconds of simulated time, shared by the simulated display and instrument.
#[derive(Debug, Default)]
pub struct VirtualClock {
    seconds: Mutex<f64>,
    /// Real seconds slept per simulated second; `None` runs as fast as possible.
    realtime_scale: Option<f64>,
}

impl VirtualClock {
    pub fn new(realtime_scale: Option<f64>) -> Self {
        VirtualClock {
            seconds: Mutex::new(0.0),
            realtime_scale,
        }
    }

    /// Simulated seconds since the clock started.
    pub fn now(&self) -> f64 {
        *self
            .seconds
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Set the time, as when a run resumes from its journal.
    pub fn set(&self, seconds: f64) {
        *self
            .seconds
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) = seconds;
    }

    /// Let `seconds` of simulated time pass at once, without sleeping (for code that
    /// keeps real time itself, such as the emulators).
    pub fn advance(&self, seconds: f64) {
        if seconds > 0.0 {
            *self
                .seconds
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner()) += seconds;
        }
    }

    /// Let `seconds` of simulated time pass (sleeping, scaled, in real-time mode).
    pub async fn wait(&self, seconds: f64) {
        if !(seconds > 0.0) {
            return;
        }
        if let Some(scale) = self.realtime_scale {
            let real = seconds * scale;
            // Tokio's timer counts whole milliseconds: a wait far below one would
            // last a millisecond, so it only lets the other tasks run.
            if real < MIN_SLEEP_S {
                #[cfg(feature = "tokio")]
                tokio::task::yield_now().await;
            } else {
                sleep(Duration::from_secs_f64(real)).await;
            }
        }
        *self
            .seconds
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) += seconds;
    }
}

impl chromacal_formats::time::TimeSource for VirtualClock {
    fn now(&self) -> f64 {
        VirtualClock::now(self)
    }
}

/// A real-time wait: on tokio's timer with the `tokio` feature, so other tasks run
/// meanwhile; without it (no runtime to hand the time back to) the thread sleeps.
#[cfg(feature = "tokio")]
async fn sleep(duration: Duration) {
    tokio::time::sleep(duration).await;
}

#[cfg(not(feature = "tokio"))]
async fn sleep(duration: Duration) {
    std::thread::sleep(duration);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs a future to its end: on a tokio runtime when the clock sleeps on tokio's
    /// timer (the `tokio` feature, as the workspace builds it), else on this thread.
    fn block_on<F: std::future::Future>(future: F) -> F::Output {
        #[cfg(feature = "tokio")]
        return tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .unwrap()
            .block_on(future);
        #[cfg(not(feature = "tokio"))]
        pollster::block_on(future)
    }

    #[test]
    fn time_passes_only_when_waited_for() {
        block_on(async {
            let clock = VirtualClock::new(None);
            assert_eq!(clock.now(), 0.0);
            clock.wait(2.5).await;
            clock.wait(-1.0).await;
            assert_eq!(clock.now(), 2.5);
            clock.set(10.0);
            assert_eq!(clock.now(), 10.0);
        });
    }

    #[test]
    fn in_real_time_a_wait_sleeps_scaled() {
        block_on(async {
            let clock = VirtualClock::new(Some(0.001)); // a simulated second per real ms
            let started = std::time::Instant::now();
            clock.wait(50.0).await;
            assert!(started.elapsed() >= Duration::from_millis(50));
            assert_eq!(clock.now(), 50.0);
        });
    }
}
