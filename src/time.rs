//! Where a run takes its time stamps from: the wall clock for real devices, the
//! virtual clock (`sim::clock`) for simulated ones. Drift is measured against these
//! stamps, so both count seconds.

use std::time::{SystemTime, UNIX_EPOCH};

/// A source of time stamps in seconds.
pub trait TimeSource: Send + Sync {
    fn now(&self) -> f64;
}

/// Seconds since the Unix epoch.
#[derive(Debug, Default, Clone, Copy)]
pub struct WallClock;

impl TimeSource for WallClock {
    fn now(&self) -> f64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0)
    }
}
