//! The virtual clock that simulated devices run on.
//!
//! A simulated run takes minutes of instrument time but should finish in
//! milliseconds in a test, so simulated devices advance this clock instead of
//! sleeping. With a real-time scale set they also sleep, scaled, so a person can
//! watch a run at its real pace (or a test can kill one part way).

use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Seconds of simulated time, shared by the simulated display and instrument.
///
/// As fast as possible (no scale), time passes only when something waits for it. In
/// real-time mode simulated time follows the wall clock, scaled, so that it also
/// passes while nothing is measured: a simulated monitor left alone in a running
/// daemon warms up and drifts as a real one does.
#[derive(Debug)]
pub struct VirtualClock {
    /// Simulated seconds added to the scaled wall time (all of the time, without a
    /// scale).
    offset: Mutex<f64>,
    /// Real seconds per simulated second, and when the clock started.
    realtime: Option<(f64, Instant)>,
}

impl Default for VirtualClock {
    fn default() -> Self {
        VirtualClock::new(None)
    }
}

impl VirtualClock {
    pub fn new(realtime_scale: Option<f64>) -> Self {
        VirtualClock {
            offset: Mutex::new(0.0),
            realtime: realtime_scale
                .filter(|s| *s > 0.0 && s.is_finite())
                .map(|s| (s, Instant::now())),
        }
    }

    fn offset(&self) -> std::sync::MutexGuard<'_, f64> {
        self.offset
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Simulated seconds of wall time since the clock started (0 without a scale).
    fn scaled_wall(&self) -> f64 {
        self.realtime
            .map_or(0.0, |(scale, start)| start.elapsed().as_secs_f64() / scale)
    }

    /// Simulated seconds since the clock started.
    pub fn now(&self) -> f64 {
        *self.offset() + self.scaled_wall()
    }

    /// Set the time, as when a run resumes from its journal.
    pub fn set(&self, seconds: f64) {
        *self.offset() = seconds - self.scaled_wall();
    }

    /// Let `seconds` of simulated time pass at once, without sleeping (for code that
    /// keeps real time itself, such as the emulators).
    pub fn advance(&self, seconds: f64) {
        if seconds > 0.0 {
            *self.offset() += seconds;
        }
    }

    /// Let `seconds` of simulated time pass (sleeping, scaled, in real-time mode).
    pub async fn wait(&self, seconds: f64) {
        if !(seconds > 0.0) {
            return;
        }
        match self.realtime {
            Some((scale, _)) => {
                let until = self.now() + seconds;
                tokio::time::sleep(Duration::from_secs_f64(seconds * scale)).await;
                // A sleep that woke early must not shorten the simulated wait.
                let short = until - self.now();
                if short > 0.0 {
                    self.advance(short);
                }
            }
            None => self.advance(seconds),
        }
    }
}

impl crate::time::TimeSource for VirtualClock {
    fn now(&self) -> f64 {
        VirtualClock::now(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn time_passes_only_when_waited_for() {
        let clock = VirtualClock::new(None);
        assert_eq!(clock.now(), 0.0);
        clock.wait(2.5).await;
        clock.wait(-1.0).await;
        assert_eq!(clock.now(), 2.5);
        clock.set(10.0);
        assert_eq!(clock.now(), 10.0);
    }

    #[tokio::test]
    async fn in_real_time_simulated_time_follows_the_wall_clock() {
        let clock = VirtualClock::new(Some(0.001)); // a simulated second per real ms
        tokio::time::sleep(Duration::from_millis(50)).await;
        let idle = clock.now();
        assert!((50.0..5000.0).contains(&idle), "{idle}");
        clock.wait(100.0).await;
        assert!(clock.now() >= idle + 100.0);
        clock.set(1.0e6);
        assert!((clock.now() - 1.0e6).abs() < 50.0);
    }
}
