//! The display and instrument a run uses, chosen from the config: the simulated rig, or
//! a serial instrument with the screen of an emulator (`chromacal emulate`) as display.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::Matrix3;

use crate::config::Config;
use crate::display::emulator_link::EmulatorScreen;
use crate::display::simulated::SimulatedDisplay;
use crate::display::{DisplayError, Patch, PatchDisplay};
use crate::instrument::devices::DeviceKind;
use crate::instrument::driver::AsyncSerialInstrument;
use crate::instrument::simulated::SimulatedInstrument;
use crate::instrument::{Capability, Instrument, InstrumentError, InstrumentInfo, Reading};
use crate::sim::clock::VirtualClock;
use crate::sim::monitor::SimError;
use crate::sim::rig::SimulatedRig;
use crate::time::{TimeSource, WallClock};

/// Why the devices of a run could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum DevicesError {
    #[error("monitor: {0}")]
    Simulation(#[from] SimError),
    #[error("instrument: {0}")]
    Instrument(#[from] InstrumentError),
    #[error("display: {0}")]
    Display(#[from] DisplayError),
    #[error("{0}")]
    Config(String),
}

/// Settings given on the command line that win over the config's.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    pub instrument: Option<(DeviceKind, String)>,
    pub screen: Option<PathBuf>,
    pub timing_scale: Option<f64>,
}

impl Overrides {
    pub fn apply(&self, config: &mut Config) {
        if let Some((kind, port)) = &self.instrument {
            config.instrument.driver = Some(kind.name().to_string());
            config.instrument.port = Some(port.clone());
            config.instrument.simulated = None;
        }
        if let Some(screen) = &self.screen {
            config.display.screen = Some(screen.clone());
        }
        if let Some(scale) = self.timing_scale {
            config.instrument.options.timing_scale = scale;
        }
    }
}

/// A display of any kind a run can use.
pub enum RunDisplay {
    Simulated(SimulatedDisplay),
    Emulator(EmulatorScreen),
}

impl PatchDisplay for RunDisplay {
    fn name(&self) -> String {
        match self {
            RunDisplay::Simulated(d) => d.name(),
            RunDisplay::Emulator(d) => d.name(),
        }
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        match self {
            RunDisplay::Simulated(d) => d.show(patch).await,
            RunDisplay::Emulator(d) => d.show(patch).await,
        }
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        match self {
            RunDisplay::Simulated(d) => d.blank().await,
            RunDisplay::Emulator(d) => d.blank().await,
        }
    }
}

/// An instrument of any kind a run can use, with an optional correction matrix.
pub enum RunInstrument {
    Simulated(SimulatedInstrument),
    Serial {
        instrument: AsyncSerialInstrument,
        correction: Option<Matrix3<f64>>,
    },
}

impl Instrument for RunInstrument {
    fn info(&self) -> InstrumentInfo {
        match self {
            RunInstrument::Simulated(i) => i.info(),
            RunInstrument::Serial { instrument, .. } => instrument.info(),
        }
    }

    async fn measure(&mut self) -> Result<Reading, InstrumentError> {
        match self {
            RunInstrument::Simulated(i) => i.measure().await,
            RunInstrument::Serial {
                instrument,
                correction,
            } => {
                let mut reading = instrument.measure().await?;
                if let (Some(m), Some(xyz)) = (correction, reading.xyz) {
                    reading.xyz = Some(*m * xyz);
                }
                Ok(reading)
            }
        }
    }
}

impl RunInstrument {
    /// Leave the instrument's remote mode (serial instruments).
    pub fn close(&self) {
        if let RunInstrument::Serial { instrument, .. } = self {
            instrument.close();
        }
    }
}

/// What a run measures with.
pub struct Devices {
    pub display: RunDisplay,
    pub instrument: RunInstrument,
    pub clock: Arc<dyn TimeSource>,
    /// The simulated rig's clock, which a resumed run sets to where it stopped.
    pub virtual_clock: Option<Arc<VirtualClock>>,
}

/// Open the devices `config` names; relative paths from `base_dir`.
pub async fn open_devices(
    config: &Config,
    base_dir: &Path,
    realtime_scale: Option<f64>,
) -> Result<Devices, DevicesError> {
    let serial = config.instrument.serial().map_err(DevicesError::Config)?;
    let Some((kind, port)) = serial else {
        let rig = SimulatedRig::new(
            config.monitor.resolve(base_dir)?,
            config.instrument.simulated.clone().unwrap_or_default(),
            config.display.settle_s,
            realtime_scale,
        )?;
        return Ok(Devices {
            display: RunDisplay::Simulated(rig.display),
            instrument: RunInstrument::Simulated(rig.instrument),
            clock: rig.clock.clone(),
            virtual_clock: Some(rig.clock),
        });
    };
    let Some(screen) = &config.display.screen else {
        return Err(DevicesError::Config(format!(
            "the {kind} needs a display to measure: give --screen (or display.screen), the socket `chromacal emulate` prints; patch displays for real screens come with the display issue"
        )));
    };
    let correction = match config.instrument.correction {
        Some(rows) if kind.capability() == Capability::Spectral => {
            let _ = rows;
            return Err(DevicesError::Config(format!(
                "instrument.correction is for colorimeters; the {kind} is a spectroradiometer"
            )));
        }
        Some(rows) => Some(Matrix3::from_fn(|r, c| rows[r][c])),
        None => None,
    };
    let options = config.instrument.options;
    let instrument = tokio::task::spawn_blocking(move || kind.open(&port, options))
        .await
        .map_err(|e| DevicesError::Config(format!("the driver's thread failed: {e}")))??;
    let display = EmulatorScreen::connect(
        &if screen.is_absolute() {
            screen.clone()
        } else {
            base_dir.join(screen)
        },
        config.display.settle_s,
    )?;
    Ok(Devices {
        display: RunDisplay::Emulator(display),
        instrument: RunInstrument::Serial {
            instrument: AsyncSerialInstrument::new(instrument),
            correction,
        },
        clock: Arc::new(WallClock),
        virtual_clock: None,
    })
}
