//! Emulators: the instruments' protocols answered by models of the devices, which
//! measure a virtual monitor. Each device's model lives with its driver
//! (`instrument/<family>/emulator.rs`); this module has what they share:
//!
//! * [`DeviceModel`]: bytes in, scheduled replies out, on the device's own clock;
//! * [`Meter`]: the measurement a model reports, from the simulated instrument, with
//!   the device faults (low light, overload, sync failure) drawn from a seed;
//! * [`faults`]: link faults (no reply, late reply, garbage, truncated reply, the
//!   device vanishing), drawn from a seed;
//! * two runners: [`pty::PtyEmulator`] on a real pseudo-terminal in real time, and
//!   [`memory::MemoryTransport`] in-process on virtual time.

pub mod faults;
pub mod memory;
pub mod pty;
pub mod screen;

use std::sync::{Arc, Mutex};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::simulated::{SimulatedInstrument, SimulatedInstrumentSpec};
use super::{Reading, ReadingStatus};
use chromacal_sim::monitor::VirtualMonitor;

/// Bytes a device will send `delay` device-seconds after the event that caused them.
#[derive(Debug, Clone, PartialEq)]
pub struct Scheduled {
    pub delay: f64,
    pub bytes: Vec<u8>,
}

impl Scheduled {
    pub fn now(bytes: impl Into<Vec<u8>>) -> Self {
        Scheduled {
            delay: 0.0,
            bytes: bytes.into(),
        }
    }

    pub fn after(delay: f64, bytes: impl Into<Vec<u8>>) -> Self {
        Scheduled {
            delay,
            bytes: bytes.into(),
        }
    }
}

/// A model of an instrument's side of the wire.
pub trait DeviceModel: Send {
    fn name(&self) -> &'static str;
    /// Bytes from the host arrive at device time `now` on a line set to `baud`.
    fn receive(&mut self, bytes: &[u8], now: f64, baud: u32) -> Vec<Scheduled>;
    /// Bytes the device sends on its own up to device time `until` (measurement
    /// streams), each with the absolute time it is sent.
    fn poll(&mut self, _until: f64) -> Vec<(f64, Vec<u8>)> {
        Vec::new()
    }
}

/// What the screen shows now, for an emulator that looks at a real one.
pub type ScreenSource =
    Box<dyn FnMut() -> Result<chromacal_model::screen::ScreenContent, String> + Send>;

/// Device faults: how often a measurement reports each of these instead of its value.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeviceFaults {
    pub low_light: f64,
    pub overload: f64,
    /// Only when the host asked for sync.
    pub sync_failure: f64,
    /// A value 10⁹ times the light (see `FaultSpec::misread`).
    pub misread: f64,
}

/// What a measurement gives a device model to report.
#[derive(Debug, Clone, PartialEq)]
pub enum Measured {
    /// In range.
    Ok(Reading),
    /// Too little light: the value, if the device gives one, is only indicative.
    LowLight(Reading),
    /// Too much light: no value.
    Overload { integration_s: f64 },
    /// The device could not lock to the display's refresh.
    SyncFailed { integration_s: f64 },
}

impl Measured {
    pub fn integration_s(&self) -> f64 {
        match self {
            Measured::Ok(r) | Measured::LowLight(r) => r.integration_s,
            Measured::Overload { integration_s } | Measured::SyncFailed { integration_s } => {
                *integration_s
            }
        }
    }
}

/// The measuring part of an emulated device: the simulated instrument aimed at the
/// virtual monitor, and the seeded device faults.
pub struct Meter {
    instrument: SimulatedInstrument,
    monitor: Arc<Mutex<VirtualMonitor>>,
    /// Where the monitor's screen comes from before each reading, when it is not set
    /// from outside (an X output read back: `chromacal emulate --x-display`).
    screen_source: Option<ScreenSource>,
    faults: DeviceFaults,
    rng: ChaCha8Rng,
    faults_on: Arc<std::sync::atomic::AtomicBool>,
}

impl Meter {
    pub fn new(
        monitor: Arc<Mutex<VirtualMonitor>>,
        spec: SimulatedInstrumentSpec,
        faults: DeviceFaults,
        seed: u64,
    ) -> Self {
        Meter {
            instrument: SimulatedInstrument::new(monitor.clone(), spec),
            monitor,
            screen_source: None,
            faults,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_FA17),
            faults_on: Arc::new(std::sync::atomic::AtomicBool::new(true)),
        }
    }

    /// Read the screen from `source` before every reading.
    pub fn with_screen_source(mut self, source: ScreenSource) -> Self {
        self.screen_source = Some(source);
        self
    }

    /// A switch for the device faults (on at first), kept by tests that want a clean
    /// start before the faults begin.
    pub fn fault_switch(&self) -> Arc<std::sync::atomic::AtomicBool> {
        self.faults_on.clone()
    }

    fn faults(&self) -> DeviceFaults {
        if self.faults_on.load(std::sync::atomic::Ordering::Relaxed) {
            self.faults
        } else {
            DeviceFaults::default()
        }
    }

    /// Whether an attempt to lock to the display's refresh fails (for instruments that
    /// measure the refresh in a command of its own).
    pub fn sync_fails(&mut self) -> bool {
        let draw: f64 = self.rng.random();
        draw < self.faults().sync_failure
    }

    /// Measure what the screen shows, `synced` to its refresh or not.
    pub fn measure(&mut self, synced: bool) -> Measured {
        if let Some(source) = &mut self.screen_source {
            match source() {
                Ok(content) => {
                    if let Ok(mut m) = self.monitor.lock() {
                        m.show(content);
                    }
                }
                // The screen keeps what it last showed; say why it was not read.
                Err(e) => tracing::warn!(error = %e, "the emulator could not read its screen"),
            }
        }
        let reading = match self.instrument.measure_now() {
            Ok(r) => r,
            Err(_) => {
                return Measured::Overload { integration_s: 1.0 };
            }
        };
        let integration_s = reading.integration_s;
        let draw: f64 = self.rng.random();
        let f = self.faults();
        if synced && draw < f.sync_failure {
            return Measured::SyncFailed { integration_s };
        }
        let draw = draw - if synced { f.sync_failure } else { 0.0 };
        if draw >= 0.0 && draw < f.low_light {
            return Measured::LowLight(reading);
        }
        if draw >= f.low_light && draw < f.low_light + f.overload {
            return Measured::Overload { integration_s };
        }
        let draw = draw - f.low_light - f.overload;
        if draw >= 0.0 && draw < f.misread && reading.status == ReadingStatus::Ok {
            let mut wrong = reading;
            wrong.xyz = wrong.xyz.map(|xyz| xyz * 1e9);
            wrong.luminance = wrong.luminance.map(|l| l * 1e9);
            return Measured::Ok(wrong);
        }
        match reading.status {
            ReadingStatus::Ok => Measured::Ok(reading),
            ReadingStatus::BelowRange => Measured::LowLight(reading),
            ReadingStatus::Overload => Measured::Overload { integration_s },
        }
    }
}

/// Bytes from the host gathered into commands ended by CR, LF or CR LF, at any pace
/// and in any chunks; empty lines are dropped and overlong input is cut.
#[derive(Debug, Default)]
pub struct CommandLines {
    pending: Vec<u8>,
}

impl CommandLines {
    /// Longest command kept.
    const LIMIT: usize = 256;

    /// The complete commands in `bytes` (trimmed); an unfinished one is kept.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<String> {
        let mut lines = Vec::new();
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                let line = String::from_utf8_lossy(&self.pending).trim().to_string();
                self.pending.clear();
                if !line.is_empty() {
                    lines.push(line);
                }
            } else if self.pending.len() < Self::LIMIT {
                self.pending.push(b);
            }
        }
        lines
    }

    pub fn clear(&mut self) {
        self.pending.clear();
    }
}

/// A number in a fixed format, as instruments print them: `d.ddde±dd` with `digits`
/// exponent digits.
pub fn scientific(value: f64, mantissa_digits: usize, exponent_digits: usize) -> String {
    let text = format!("{:.*e}", mantissa_digits, value);
    let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let sign = if exponent < 0 { '-' } else { '+' };
    format!(
        "{mantissa}e{sign}{:0width$}",
        exponent.abs(),
        width = exponent_digits
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scientific_numbers_have_fixed_widths() {
        assert_eq!(scientific(18.65, 3, 2), "1.865e+01");
        assert_eq!(scientific(0.001627, 3, 3), "1.627e-003");
        assert_eq!(scientific(0.0, 3, 2), "0.000e+00");
    }
}
