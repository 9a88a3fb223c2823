//! What every serial instrument driver shares: the options, the recovery policy, and
//! the adapter that turns a blocking driver into an async [`Instrument`].
//!
//! Recovery policy, the same for every instrument:
//! * a reply that does not come, comes garbled or comes short: clear the line, bring the
//!   instrument back to a known state ([`Protocol::resync`]), and measure again, up to
//!   `attempts` times in all;
//! * light below the range or above it: reported in the reading's status, never as a
//!   zero or an error;
//! * a sync failure: measure again without sync (each protocol does this itself);
//! * the device gone: reopen the port and reconnect, `reconnects` times with a growing
//!   pause, then a clean error.

use serde::{Deserialize, Serialize};

use super::transport::{Link, TransportError};
use super::{InstrumentError, InstrumentInfo, Reading};

/// Options common to the serial drivers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriverOptions {
    /// Multiplies every protocol timeout and pause (1 for real instruments; tests run
    /// emulators faster and scale the driver to match).
    pub timing_scale: f64,
    /// Tries per measurement before an error is returned.
    pub attempts: usize,
    /// Reconnections tried when the device vanishes.
    pub reconnects: usize,
    /// Synchronise integration to the display's refresh where the instrument can.
    pub sync: bool,
    /// ArgyllCMS bridge: the display type, as `spotread -y` takes it for the
    /// instrument (`l`, `c`, `e`… as `spotread -?` lists them; for a colorimeter it
    /// picks the built-in calibration).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub display_type: Option<String>,
    /// ArgyllCMS bridge: `refresh` or `non-refresh` (`spotread -Y r|n`), for
    /// instruments that synchronise to a CRT's or a PWM backlight's refresh.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refresh_mode: Option<RefreshMode>,
    /// ArgyllCMS bridge: a `.ccss` or `.ccmx` Argyll applies itself (`spotread -X`),
    /// relative to the config's directory.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub argyll_correction: Option<std::path::PathBuf>,
    /// ArgyllCMS bridge: 2 asks the instrument to average readings where it can
    /// (`spotread -Y a`), for longer integration at low light; 1 leaves it off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub averaging: Option<u8>,
    /// ArgyllCMS bridge: seconds to wait for spotread to start the instrument (its
    /// port scan and initialisation) and for one reading.
    pub argyll_timeout_s: f64,
}

/// Whether an instrument synchronises its integration to the display's refresh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RefreshMode {
    Refresh,
    NonRefresh,
}

impl Default for DriverOptions {
    fn default() -> Self {
        DriverOptions {
            timing_scale: 1.0,
            attempts: 3,
            reconnects: 3,
            sync: true,
            display_type: None,
            refresh_mode: None,
            argyll_correction: None,
            averaging: None,
            argyll_timeout_s: 60.0,
        }
    }
}

impl From<TransportError> for InstrumentError {
    fn from(e: TransportError) -> Self {
        match e {
            TransportError::Timeout { waited, got } if got.is_empty() => {
                InstrumentError::Timeout { seconds: waited }
            }
            TransportError::Timeout { waited, got } => InstrumentError::Protocol(format!(
                "a reply stopped short after {waited:.3} s: {}",
                super::transport::escape(&got)
            )),
            TransportError::Disconnected(m) => InstrumentError::Disconnected(m),
            TransportError::Io(m) => InstrumentError::Protocol(m),
        }
    }
}

/// One instrument's protocol over a link.
pub trait Protocol: Send {
    fn link(&mut self) -> &mut Link;
    /// Bring the instrument under remote control, identify and configure it.
    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError>;
    /// One measurement of what is on the screen, with the protocol's own handling of
    /// range and sync codes.
    fn measure_once(&mut self) -> Result<Reading, InstrumentError>;
    /// After a timeout or a garbled reply: back to a state where commands work. By
    /// default the line is drained ([`Link::drain`]).
    fn resync(&mut self) -> Result<(), InstrumentError> {
        self.link().drain().map_err(InstrumentError::from)
    }
    /// Leave remote control (best effort).
    fn disconnect(&mut self) {}
}

/// A connected instrument behind a protocol, with the recovery policy.
pub struct SerialInstrument {
    protocol: Box<dyn Protocol>,
    info: InstrumentInfo,
    options: DriverOptions,
}

impl SerialInstrument {
    /// Connect over `protocol`'s link (retrying as a measurement would).
    pub fn connect(
        mut protocol: Box<dyn Protocol>,
        options: DriverOptions,
    ) -> Result<Self, InstrumentError> {
        let mut last = None;
        for attempt in 1..=options.attempts.max(1) {
            match protocol.connect() {
                Ok(info) => {
                    return Ok(SerialInstrument {
                        protocol,
                        info,
                        options,
                    });
                }
                Err(e @ (InstrumentError::Disconnected(_) | InstrumentError::Unavailable(_))) => {
                    return Err(e);
                }
                Err(e) => {
                    tracing::warn!(attempt, error = %e, "could not connect");
                    last = Some(e);
                    let _ = protocol.resync();
                }
            }
        }
        Err(last.unwrap_or(InstrumentError::Protocol("no attempt made".into())))
    }

    pub fn info(&self) -> &InstrumentInfo {
        &self.info
    }

    /// Measure, recovering as the module documentation says.
    pub fn measure(&mut self) -> Result<Reading, InstrumentError> {
        let mut last = None;
        for attempt in 1..=self.options.attempts.max(1) {
            let started = self.protocol.link().transport().now();
            match self.protocol.measure_once() {
                Ok(mut reading) => {
                    if reading.integration_s == 0.0 {
                        // The driver cannot ask how long the instrument integrated: the
                        // time the measurement took stands in for it.
                        let elapsed = self.protocol.link().transport().now() - started;
                        reading.integration_s = elapsed / self.options.timing_scale.max(1e-12);
                    }
                    return Ok(reading);
                }
                Err(e @ InstrumentError::Unavailable(_)) => return Err(e),
                Err(InstrumentError::Disconnected(why)) => {
                    tracing::warn!(%why, "the instrument vanished; reconnecting");
                    self.reconnect(&why)?;
                    last = Some(InstrumentError::Disconnected(why));
                }
                Err(e) => {
                    tracing::warn!(attempt, error = %e, "measurement failed");
                    last = Some(e);
                    if let Err(InstrumentError::Disconnected(why)) = self.protocol.resync() {
                        self.reconnect(&why)?;
                    }
                }
            }
        }
        Err(last.unwrap_or(InstrumentError::Protocol("no attempt made".into())))
    }

    fn reconnect(&mut self, why: &str) -> Result<(), InstrumentError> {
        for attempt in 1..=self.options.reconnects {
            self.protocol.link().sleep(0.5 * attempt as f64);
            if self.protocol.link().reopen().is_ok() && self.protocol.connect().is_ok() {
                tracing::info!(attempt, "reconnected");
                return Ok(());
            }
        }
        Err(InstrumentError::Disconnected(format!(
            "{why}; {} reconnection attempts failed",
            self.options.reconnects
        )))
    }

    pub fn close(&mut self) {
        self.protocol.disconnect();
    }
}

#[cfg(feature = "tokio")]
pub use adapter::AsyncSerialInstrument;

/// The async adapter, with the `tokio` feature: a blocking driver on tokio's blocking
/// pool.
#[cfg(feature = "tokio")]
mod adapter {
    use std::sync::{Arc, Mutex};

    use super::SerialInstrument;
    use crate::{Instrument, InstrumentError, InstrumentInfo, Reading};

    /// A [`SerialInstrument`] as an async [`Instrument`]: its blocking I/O runs on
    /// tokio's blocking pool.
    #[derive(Clone)]
    pub struct AsyncSerialInstrument {
        inner: Arc<Mutex<SerialInstrument>>,
        info: InstrumentInfo,
    }

    impl AsyncSerialInstrument {
        pub fn new(instrument: SerialInstrument) -> Self {
            let info = instrument.info().clone();
            AsyncSerialInstrument {
                inner: Arc::new(Mutex::new(instrument)),
                info,
            }
        }

        pub fn close(&self) {
            if let Ok(mut i) = self.inner.lock() {
                i.close();
            }
        }
    }

    impl Instrument for AsyncSerialInstrument {
        fn info(&self) -> InstrumentInfo {
            self.info.clone()
        }

        async fn measure(&mut self) -> Result<Reading, InstrumentError> {
            let inner = self.inner.clone();
            tokio::task::spawn_blocking(move || match inner.lock() {
                Ok(mut i) => i.measure(),
                Err(_) => Err(InstrumentError::Disconnected(
                    "the driver's lock is poisoned".into(),
                )),
            })
            .await
            .map_err(|e| InstrumentError::Protocol(format!("the driver's thread failed: {e}")))?
        }
    }
}
