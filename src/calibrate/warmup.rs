//! Waiting for a display to warm up before a job: show white, read it at intervals,
//! and go on once its luminance has stopped moving (the slope of the last few readings
//! below a threshold), or once the time bound is reached.
//!
//! CRTs and LCD backlights take tens of minutes to settle after switch-on (Brainard,
//! Pelli & Robson 2002, "Display characterization", §"Warm-up"); a calibration taken
//! on a warming display is fitted to a screen that is not there an hour later.

use serde::{Deserialize, Serialize};

use crate::config::WarmupConfig;
use chromacal_display::PatchDisplay;
use chromacal_instruments::Instrument;
use chromacal_model::screen::{Codes, Geometry, Patch};

/// One reading of the warm-up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WarmupStep {
    /// Seconds since the warm-up began.
    pub elapsed_s: f64,
    pub luminance: f64,
    /// Relative slope per minute over the window, once there are enough readings.
    pub slope_per_min: Option<f64>,
}

/// How the warm-up ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupOutcome {
    pub steps: Vec<WarmupStep>,
    /// The slope fell below the threshold (false: the time bound was reached).
    pub settled: bool,
}

/// Least-squares slope of `(t, y)` divided by the mean of y, per minute.
pub fn relative_slope_per_min(points: &[(f64, f64)]) -> Option<f64> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let mt = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let stt: f64 = points.iter().map(|p| (p.0 - mt).powi(2)).sum();
    if !(stt > 0.0 && my.abs() > 0.0) {
        return None;
    }
    let sty: f64 = points.iter().map(|p| (p.0 - mt) * (p.1 - my)).sum();
    Some(sty / stt / my * 60.0)
}

/// Show white and read it until it settles. `wait(s)` lets `s` seconds pass (the
/// virtual clock for simulated devices, the wall clock otherwise); `now()` tells the
/// time; `on_step` hears each reading; `stop()` ends the wait early.
#[allow(clippy::too_many_arguments)]
pub async fn wait_for_warmup<D, I, W, F>(
    config: &WarmupConfig,
    bit_depth: u32,
    display: &mut D,
    instrument: &mut I,
    now: &(dyn Fn() -> f64 + Send + Sync),
    wait: W,
    on_step: &mut (dyn FnMut(&WarmupStep) + Send),
    stop: &(dyn Fn() -> bool + Send + Sync),
) -> Result<WarmupOutcome, String>
where
    D: PatchDisplay,
    I: Instrument,
    W: Fn(f64) -> F,
    F: std::future::Future<Output = ()>,
{
    let white = Patch {
        codes: Codes::from_drive([1.0; 3], bit_depth),
        background: Codes::from_drive([0.0; 3], bit_depth),
        geometry: Geometry::centred(0.2),
    };
    display.show(&white).await.map_err(|e| e.to_string())?;
    let start = now();
    let mut points: Vec<(f64, f64)> = Vec::new();
    let mut steps = Vec::new();
    loop {
        let reading = instrument.measure().await.map_err(|e| e.to_string())?;
        let elapsed = now() - start;
        if let Some(y) = reading.luminance() {
            points.push((elapsed, y));
        }
        let window = &points[points.len().saturating_sub(config.window)..];
        let slope = (window.len() >= config.window)
            .then(|| relative_slope_per_min(window))
            .flatten();
        let step = WarmupStep {
            elapsed_s: elapsed,
            luminance: points.last().map_or(f64::NAN, |p| p.1),
            slope_per_min: slope,
        };
        on_step(&step);
        steps.push(step);
        if slope.is_some_and(|s| s.abs() < config.max_slope_per_min) {
            return Ok(WarmupOutcome {
                steps,
                settled: true,
            });
        }
        if elapsed >= config.max_s || stop() {
            tracing::warn!(
                elapsed_s = elapsed,
                slope_per_min = ?slope,
                "the display did not settle within the warm-up bound; going on"
            );
            return Ok(WarmupOutcome {
                steps,
                settled: false,
            });
        }
        wait(config.interval_s).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slope_is_relative_and_per_minute() {
        // 1 % per minute around 100.
        let points: Vec<(f64, f64)> = (0..5)
            .map(|i| (i as f64 * 30.0, 100.0 + i as f64 * 0.5))
            .collect();
        let s = relative_slope_per_min(&points).unwrap();
        assert!((s - 0.01 / 1.01).abs() < 1e-3, "{s}");
        assert_eq!(relative_slope_per_min(&points[..1]), None);
        assert_eq!(relative_slope_per_min(&[(1.0, 0.0), (2.0, 0.0)]), None);
    }
}
