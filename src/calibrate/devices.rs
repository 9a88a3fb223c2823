//! The display and instrument a run uses, chosen from the config: the simulated rig, or
//! a serial instrument with a patch display: a Resolve pattern generator, the web patch
//! page, or the screen of an emulator (`chromacal emulate`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::Matrix3;

use crate::calibrate::rig::SimulatedRig;
use crate::config::{Config, Correction, Sink};
use chromacal_display::emulator_link::EmulatorScreen;
use chromacal_display::resolve::ResolveDisplay;
use chromacal_display::simulated::SimulatedDisplay;
use chromacal_display::wayland::surface::{PatchSurface, SurfaceTarget};
use chromacal_display::web::WebDisplay;
use chromacal_display::window::{PatchWindow, WindowTarget};
use chromacal_display::{DisplayError, PatchDisplay};
use chromacal_formats::time::{TimeSource, WallClock};
use chromacal_instruments::devices::InstrumentAddress;
use chromacal_instruments::driver::AsyncSerialInstrument;
use chromacal_instruments::simulated::SimulatedInstrument;
use chromacal_instruments::{Capability, Instrument, InstrumentError, InstrumentInfo, Reading};
use chromacal_model::screen::Patch;
use chromacal_model::target::CalibrationCurves;
use chromacal_sim::clock::VirtualClock;
use chromacal_sim::monitor::SimError;

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
    pub instrument: Option<InstrumentAddress>,
    pub screen: Option<PathBuf>,
    pub timing_scale: Option<f64>,
    pub sink: Option<Sink>,
    /// Where the Resolve server or the web page listens.
    pub listen: Option<String>,
    pub prompt_positions: bool,
    /// The window sink's output (`--display window:OUTPUT`).
    pub output: Option<chromacal_display::x11::OutputSelector>,
    /// The window sink's X display (`--x-display`).
    pub x_display: Option<String>,
    /// The wayland sink's Wayland display (`--wayland-display`).
    pub wayland_display: Option<String>,
}

impl Overrides {
    pub fn apply(&self, config: &mut Config) {
        if let Some(address) = &self.instrument {
            config.instrument.driver = Some(address.driver());
            config.instrument.port = Some(address.port());
            config.instrument.simulated = None;
        }
        if let Some(screen) = &self.screen {
            config.display.screen = Some(screen.clone());
        }
        if let Some(scale) = self.timing_scale {
            config.instrument.options.timing_scale = scale;
        }
        if let Some(sink) = self.sink {
            config.display.sink = Some(sink);
        }
        if let Some(address) = &self.listen {
            match config.display.sink() {
                Sink::Web => config.display.web.address = address.clone(),
                _ => config.display.resolve.address = address.clone(),
            }
        }
        if self.prompt_positions {
            config.display.prompt_positions = true;
        }
        if let Some(output) = &self.output {
            config.display.output = Some(output.clone());
        }
        if let Some(wayland_display) = &self.wayland_display {
            config.display.wayland_display = Some(wayland_display.clone());
        }
        if let Some(x_display) = &self.x_display {
            config.display.x_display = Some(x_display.clone());
        }
    }
}

/// A display of any kind a run can use.
pub enum RunDisplay {
    Simulated(SimulatedDisplay),
    Emulator(EmulatorScreen),
    Resolve(ResolveDisplay),
    Web(WebDisplay),
    Window(PatchWindow),
    Wayland(Box<PatchSurface>),
}

impl RunDisplay {
    /// The native window, when the run has one (it holds a video LUT).
    pub fn window(&mut self) -> Option<&mut PatchWindow> {
        match self {
            RunDisplay::Window(w) => Some(w),
            _ => None,
        }
    }

    /// For chromacal's own window or surface: the bits per channel it paints, and
    /// what it is on (for messages).
    pub fn painted_bits(&self) -> Option<(u32, String)> {
        match self {
            RunDisplay::Window(w) => Some((
                w.channel_bits(),
                format!("the window on {}", w.output().name),
            )),
            RunDisplay::Wayland(s) => Some((
                s.channel_bits(),
                format!("the Wayland surface on {}", s.output().name),
            )),
            _ => None,
        }
    }
}

impl PatchDisplay for RunDisplay {
    fn name(&self) -> String {
        match self {
            RunDisplay::Simulated(d) => d.name(),
            RunDisplay::Emulator(d) => d.name(),
            RunDisplay::Resolve(d) => d.name(),
            RunDisplay::Web(d) => d.name(),
            RunDisplay::Window(d) => d.name(),
            RunDisplay::Wayland(d) => d.name(),
        }
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        match self {
            RunDisplay::Simulated(d) => d.show(patch).await,
            RunDisplay::Emulator(d) => d.show(patch).await,
            RunDisplay::Resolve(d) => d.show(patch).await,
            RunDisplay::Web(d) => d.show(patch).await,
            RunDisplay::Window(d) => d.show(patch).await,
            RunDisplay::Wayland(d) => d.show(patch).await,
        }
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        match self {
            RunDisplay::Simulated(d) => d.blank().await,
            RunDisplay::Emulator(d) => d.blank().await,
            RunDisplay::Resolve(d) => d.blank().await,
            RunDisplay::Web(d) => d.blank().await,
            RunDisplay::Window(d) => d.blank().await,
            RunDisplay::Wayland(d) => d.blank().await,
        }
    }

    fn load_curves(&mut self, curves: Option<&CalibrationCurves>) -> Result<bool, DisplayError> {
        match self {
            RunDisplay::Window(d) => d.load_curves(curves),
            _ => Ok(false),
        }
    }
}

/// An instrument of any kind a run can use, with an optional correction matrix.
pub enum RunInstrument {
    Simulated {
        instrument: SimulatedInstrument,
        correction: Option<Matrix3<f64>>,
    },
    Serial {
        instrument: AsyncSerialInstrument,
        correction: Option<Matrix3<f64>>,
    },
    /// A serial instrument let go of (`release_instrument`): its port is free for
    /// another display's job, and it measures nothing until opened again.
    Released(InstrumentInfo),
}

impl Instrument for RunInstrument {
    fn info(&self) -> InstrumentInfo {
        match self {
            RunInstrument::Simulated { instrument, .. } => instrument.info(),
            RunInstrument::Serial { instrument, .. } => instrument.info(),
            RunInstrument::Released(info) => info.clone(),
        }
    }

    async fn measure(&mut self) -> Result<Reading, InstrumentError> {
        match self {
            RunInstrument::Simulated {
                instrument,
                correction,
            } => {
                let reading = instrument.measure().await?;
                Ok(corrected(reading, correction.as_ref()))
            }
            RunInstrument::Serial {
                instrument,
                correction,
            } => {
                let reading = instrument.measure().await?;
                Ok(corrected(reading, correction.as_ref()))
            }
            RunInstrument::Released(info) => Err(InstrumentError::Disconnected(format!(
                "the {} was handed to another display",
                info.name
            ))),
        }
    }
}

/// A colorimeter's reading through its correction matrix.
fn corrected(mut reading: Reading, correction: Option<&Matrix3<f64>>) -> Reading {
    if let (Some(m), Some(xyz)) = (correction, reading.xyz) {
        reading.xyz = Some(m * xyz);
    }
    reading
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
    /// Where the config's relative paths (a `.ccmx`) are taken from.
    pub base_dir: PathBuf,
}

/// Open the devices `config` names; relative paths from `base_dir`.
pub async fn open_devices(
    config: &Config,
    base_dir: &Path,
    realtime_scale: Option<f64>,
) -> Result<Devices, DevicesError> {
    let Some(address) = config.instrument.address().map_err(DevicesError::Config)? else {
        let rig = SimulatedRig::new(
            config
                .monitor
                .resolve(base_dir)?
                .in_mode(config.plan.signal),
            config.instrument.simulated.clone().unwrap_or_default(),
            config.display.settle_s,
            realtime_scale,
        )?;
        // A simulated colorimeter (it reads through filters) takes a correction as a
        // real one does; a simulated spectroradiometer has none to take.
        let correction = match &config.instrument.correction {
            Some(_) if rig.instrument.info().capability == Capability::Spectral => {
                return Err(DevicesError::Config(
                    "instrument.correction is for colorimeters; the simulated instrument is a spectroradiometer (instrument.simulated.kind)".into(),
                ));
            }
            Some(c) => Some(
                c.matrix(base_dir)
                    .map_err(|e| DevicesError::Config(e.to_string()))?,
            ),
            None => None,
        };
        return Ok(Devices {
            display: RunDisplay::Simulated(rig.display),
            instrument: RunInstrument::Simulated {
                instrument: rig.instrument,
                correction,
            },
            clock: rig.clock.clone(),
            virtual_clock: Some(rig.clock),
            base_dir: base_dir.to_path_buf(),
        });
    };
    let instrument = open_instrument(config, base_dir, &address).await?;
    let settle_s = config.display.settle_s;
    let display = match (config.display.sink(), &config.display.screen) {
        (Sink::Resolve, _) => RunDisplay::Resolve(
            ResolveDisplay::bind(config.display.resolve.clone(), settle_s).await?,
        ),
        (Sink::Web, _) => {
            RunDisplay::Web(WebDisplay::bind(config.display.web.clone(), settle_s).await?)
        }
        (Sink::Window, _) => RunDisplay::Window(PatchWindow::open(
            &WindowTarget {
                x_display: config.display.x_display.clone(),
                output: config.display.output.clone().unwrap_or_default(),
            },
            settle_s,
        )?),
        (Sink::Wayland, _) => RunDisplay::Wayland(Box::new(PatchSurface::open(
            &SurfaceTarget {
                wayland_display: config.display.wayland_display.clone(),
                output: config.display.output.clone().unwrap_or_default(),
            },
            settle_s,
        )?)),
        (Sink::Emulator, Some(screen)) => RunDisplay::Emulator(EmulatorScreen::connect(
            &if screen.is_absolute() {
                screen.clone()
            } else {
                base_dir.join(screen)
            },
            settle_s,
        )?),
        (sink, _) => {
            return Err(DevicesError::Config(format!(
                "the {address} needs a display it can measure, not '{}': set display.sink (--display) to window, wayland, resolve or web, or give an emulator's --screen",
                sink.name()
            )));
        }
    };
    Ok(Devices {
        display,
        instrument,
        clock: Arc::new(WallClock),
        virtual_clock: None,
        base_dir: base_dir.to_path_buf(),
    })
}

/// Open the real instrument `config` names (at `address`), with its correction matrix.
pub async fn open_instrument(
    config: &Config,
    base_dir: &Path,
    address: &InstrumentAddress,
) -> Result<RunInstrument, DevicesError> {
    let mut options = config.instrument.options.clone();
    // A .ccss is spectral samples of the display type: only a colorimeter whose
    // spectral sensitivities are known can use it, and of chromacal's instruments only
    // ArgyllCMS knows them (for the ones it drives). It is handed to Argyll.
    // A correction named by its name is the installed file of that name.
    let named = match &config.instrument.correction {
        Some(Correction::File(path)) => Some(Correction::File(
            crate::config::corrections::resolve(path, base_dir),
        )),
        other => other.clone(),
    };
    let correction: Option<Matrix3<f64>> = match (&named, address) {
        (Some(Correction::File(path)), InstrumentAddress::Argyll { .. })
            if chromacal_formats::ccss::is_ccss_path(path) =>
        {
            if options.argyll_correction.is_some() {
                return Err(DevicesError::Config(
                    "instrument.correction and instrument.options.argyll_correction both name a correction: keep one".into(),
                ));
            }
            options.argyll_correction = Some(path.clone());
            None
        }
        (Some(Correction::File(path)), InstrumentAddress::Serial { kind, .. })
            if chromacal_formats::ccss::is_ccss_path(path) =>
        {
            return Err(DevicesError::Config(format!(
                "{}: a .ccss needs the colorimeter's spectral sensitivities, which chromacal does not have for the {kind}; make a .ccmx against a spectroradiometer with `chromacal correction make`",
                path.display()
            )));
        }
        (Some(_), _) if address.capability() == Some(Capability::Spectral) => {
            return Err(DevicesError::Config(format!(
                "instrument.correction is for colorimeters; the {address} is a spectroradiometer"
            )));
        }
        (Some(c), _) => Some(
            c.matrix(base_dir)
                .map_err(|e| DevicesError::Config(e.to_string()))?,
        ),
        (None, _) => None,
    };
    let address_owned = address.clone();
    let base = base_dir.to_path_buf();
    let instrument = tokio::task::spawn_blocking(move || address_owned.open(options, &base))
        .await
        .map_err(|e| DevicesError::Config(format!("the driver's thread failed: {e}")))??;
    if correction.is_some() && instrument.info().capability == Capability::Spectral {
        return Err(DevicesError::Config(format!(
            "instrument.correction is for colorimeters; the {} is a spectrometer",
            instrument.info().name
        )));
    }
    Ok(RunInstrument::Serial {
        instrument: AsyncSerialInstrument::new(instrument),
        correction,
    })
}

/// Open again the serial instrument of `devices` after `release_instrument` (an
/// instrument shared by several displays: the daemon hands it from one to the next).
/// A simulated instrument is part of its rig and stays as it is.
pub async fn reopen_instrument(devices: &mut Devices, config: &Config) -> Result<(), DevicesError> {
    if let (RunInstrument::Released(_), Some(address)) = (
        &devices.instrument,
        config.instrument.address().map_err(DevicesError::Config)?,
    ) {
        devices.instrument = open_instrument(config, &devices.base_dir, &address).await?;
    }
    Ok(())
}

/// Close a serial instrument and let go of its port, keeping the display: another
/// display's job may open it next. `reopen_instrument` takes it back.
pub fn release_instrument(devices: &mut Devices) {
    if let RunInstrument::Serial { instrument, .. } = &devices.instrument {
        instrument.close();
        let info = instrument.info();
        devices.instrument = RunInstrument::Released(info);
    }
}
