//! The instruments chromacal drives, by name: their port settings, drivers and
//! emulators.

use serde::{Deserialize, Serialize};

use super::driver::{DriverOptions, Protocol, SerialInstrument};
use super::emulator::{DeviceModel, Meter};
use super::serial::{SerialSettings, SerialTransport};
use super::transport::{Link, Transport};
use super::{Capability, InstrumentError};
use super::{colorcal, jeti, klein, minolta, pr6xx, pr650};

/// A kind of instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    Pr650,
    Pr655,
    Pr670,
    Ls100,
    Ls110,
    Cs100a,
    K10a,
    Specbos1211,
    ColorCal2,
}

impl DeviceKind {
    pub const ALL: [DeviceKind; 9] = [
        DeviceKind::Pr650,
        DeviceKind::Pr655,
        DeviceKind::Pr670,
        DeviceKind::Ls100,
        DeviceKind::Ls110,
        DeviceKind::Cs100a,
        DeviceKind::K10a,
        DeviceKind::Specbos1211,
        DeviceKind::ColorCal2,
    ];

    /// The name used on the command line and in configs.
    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Pr650 => "pr650",
            DeviceKind::Pr655 => "pr655",
            DeviceKind::Pr670 => "pr670",
            DeviceKind::Ls100 => "ls100",
            DeviceKind::Ls110 => "ls110",
            DeviceKind::Cs100a => "cs100a",
            DeviceKind::K10a => "k10a",
            DeviceKind::Specbos1211 => "specbos1211",
            DeviceKind::ColorCal2 => "colorcal2",
        }
    }

    pub fn parse(text: &str) -> Result<Self, String> {
        let wanted = text.trim().to_ascii_lowercase().replace(['-', '_'], "");
        Self::ALL
            .into_iter()
            .find(|k| k.name() == wanted)
            .ok_or_else(|| {
                format!(
                    "unknown instrument '{text}' (known: {})",
                    Self::ALL.map(|k| k.name()).join(", ")
                )
            })
    }

    pub fn capability(self) -> Capability {
        match self {
            DeviceKind::Pr650 | DeviceKind::Pr655 | DeviceKind::Pr670 | DeviceKind::Specbos1211 => {
                Capability::Spectral
            }
            DeviceKind::Ls100 | DeviceKind::Ls110 => Capability::Luminance,
            DeviceKind::Cs100a | DeviceKind::K10a | DeviceKind::ColorCal2 => {
                Capability::Tristimulus
            }
        }
    }

    /// The filters of a tristimulus colorimeter (what its emulator reads through).
    pub fn filter_model(self) -> Option<super::filters::FilterModel> {
        use super::filters::FilterModel;
        match self {
            DeviceKind::K10a => Some(FilterModel::K10a),
            DeviceKind::Cs100a => Some(FilterModel::Cs100a),
            DeviceKind::ColorCal2 => Some(FilterModel::Colorcal2),
            _ => None,
        }
    }

    /// Line settings the instrument uses.
    pub fn settings(self) -> SerialSettings {
        match self {
            DeviceKind::Pr650 | DeviceKind::Pr655 | DeviceKind::Pr670 | DeviceKind::K10a => {
                SerialSettings::eight_n_one(9600)
            }
            // Any rate works over its USB port; PsychoPy uses 115200.
            DeviceKind::ColorCal2 => SerialSettings::eight_n_one(115_200),
            DeviceKind::Specbos1211 => SerialSettings::eight_n_one(921_600),
            DeviceKind::Ls100 | DeviceKind::Ls110 | DeviceKind::Cs100a => {
                SerialSettings::seven_e_two(4800)
            }
        }
    }

    fn minolta_model(self) -> minolta::protocol::Model {
        match self {
            DeviceKind::Ls110 => minolta::protocol::Model::Ls110,
            DeviceKind::Cs100a => minolta::protocol::Model::Cs100a,
            _ => minolta::protocol::Model::Ls100,
        }
    }

    /// The driver's protocol over `link`.
    pub fn protocol(self, link: Link, options: &DriverOptions) -> Box<dyn Protocol> {
        match self {
            DeviceKind::Pr650 => Box::new(pr650::driver::Pr650::new(link, options.sync)),
            DeviceKind::ColorCal2 => Box::new(colorcal::driver::ColorCal::new(link)),
            DeviceKind::K10a => Box::new(klein::driver::KleinK10::new(link)),
            DeviceKind::Specbos1211 => Box::new(jeti::driver::Specbos::new(link, options.sync)),
            DeviceKind::Ls100 | DeviceKind::Ls110 | DeviceKind::Cs100a => {
                Box::new(minolta::driver::Minolta::new(link, self.minolta_model()))
            }
            DeviceKind::Pr655 => Box::new(pr6xx::driver::Pr6xx::new(
                link,
                pr6xx::protocol::Model::Pr655,
                options.sync,
            )),
            DeviceKind::Pr670 => Box::new(pr6xx::driver::Pr6xx::new(
                link,
                pr6xx::protocol::Model::Pr670,
                options.sync,
            )),
        }
    }

    /// An emulated device of this kind, measuring with `meter`.
    pub fn emulator(self, meter: Meter) -> Box<dyn DeviceModel> {
        match self {
            DeviceKind::Pr650 => Box::new(pr650::emulator::Pr650Emulator::new(
                meter,
                pr650::protocol::ARMING_WINDOW_S,
            )),
            DeviceKind::ColorCal2 => {
                Box::new(colorcal::emulator::ColorCalEmulator::new(meter, 877))
            }
            DeviceKind::K10a => Box::new(klein::emulator::K10Emulator::new(meter)),
            // Set to 115200 so that a driver has to probe past its first guess.
            DeviceKind::Specbos1211 => {
                Box::new(jeti::emulator::SpecbosEmulator::new(meter, 115_200))
            }
            DeviceKind::Ls100 | DeviceKind::Ls110 | DeviceKind::Cs100a => Box::new(
                minolta::emulator::MinoltaEmulator::new(self.minolta_model(), meter, true),
            ),
            DeviceKind::Pr655 => Box::new(pr6xx::emulator::Pr6xxEmulator::new(
                pr6xx::protocol::Model::Pr655,
                meter,
            )),
            DeviceKind::Pr670 => Box::new(pr6xx::emulator::Pr6xxEmulator::new(
                pr6xx::protocol::Model::Pr670,
                meter,
            )),
        }
    }

    /// An emulated device of this kind as `quirks` asks, measuring with `meter`.
    pub fn emulator_with(
        self,
        meter: Meter,
        quirks: EmulatorQuirks,
    ) -> Result<Box<dyn DeviceModel>, String> {
        Ok(match self {
            DeviceKind::Ls100 | DeviceKind::Ls110 | DeviceKind::Cs100a if quirks.not_remote => {
                Box::new(minolta::emulator::MinoltaEmulator::new(
                    self.minolta_model(),
                    meter,
                    false,
                ))
            }
            // The PR-650's arming window is a human's time (switch on, connect at once),
            // so it lasts 5 real seconds however fast the device's time runs: scaled, it
            // would be 10 ms at a time scale of 0.002, less than a loaded machine takes to
            // start the host program.
            DeviceKind::Pr650 => Box::new(pr650::emulator::Pr650Emulator::new(
                meter,
                pr650::protocol::ARMING_WINDOW_S
                    / if quirks.time_scale > 0.0 {
                        quirks.time_scale
                    } else {
                        1.0
                    },
            )),
            DeviceKind::Specbos1211 if quirks.baud.is_some() => Box::new(
                jeti::emulator::SpecbosEmulator::new(meter, quirks.baud.unwrap_or_default()),
            ),
            _ if quirks.baud.is_some() => {
                return Err(format!(
                    "--baud is for the specbos1211, whose rate is a setting; the {self} has a fixed rate"
                ));
            }
            _ => self.emulator(meter),
        })
    }

    /// Connect to an instrument of this kind over `transport`.
    pub fn connect(
        self,
        transport: Box<dyn Transport>,
        options: DriverOptions,
    ) -> Result<SerialInstrument, InstrumentError> {
        let link = Link::new(transport, options.timing_scale);
        SerialInstrument::connect(self.protocol(link, &options), options)
    }

    /// Connect to an instrument of this kind on the serial port at `path`.
    pub fn open(
        self,
        path: &str,
        options: DriverOptions,
    ) -> Result<SerialInstrument, InstrumentError> {
        // A port that cannot be opened: what the system said, and where to look.
        let transport = SerialTransport::open(path, self.settings()).map_err(|e| {
            InstrumentError::Unavailable(format!(
                "cannot open the {self}'s port {e}; `chromacal instruments` lists the serial ports and what answers on each"
            ))
        })?;
        // Silence or nonsense at connect is mostly another instrument (or none) on
        // the port: name the port and the way to find the right one.
        let attempts = options.attempts.max(1);
        self.connect(Box::new(transport), options)
            .map_err(|e| match e {
                InstrumentError::Timeout { .. } | InstrumentError::Protocol(_) => {
                    InstrumentError::Unavailable(format!(
                        "no {self} answered on {path} ({attempts} attempts; the last: {e}): is that its port, and is it switched on? `chromacal instruments` says what answers on each port"
                    ))
                }
                other => other,
            })
    }
}

/// Where a real instrument is: a serial instrument of a known kind on a port, or
/// whatever ArgyllCMS drives on its port N (the bridge, [`super::argyll`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InstrumentAddress {
    Serial { kind: DeviceKind, port: String },
    Argyll { port: u32 },
}

impl InstrumentAddress {
    /// The driver name of the ArgyllCMS bridge.
    pub const ARGYLL: &'static str = "argyll";

    /// From the command line: `KIND:PORT` (e.g. `pr670:/dev/ttyACM0`) or `argyll[:N]`.
    pub fn parse(spec: &str) -> Result<Self, String> {
        let (kind, port) = match spec.split_once(':') {
            Some((k, p)) => (k, Some(p)),
            None => (spec, None),
        };
        Self::from_parts(kind, port).map_err(|e| format!("--instrument {spec}: {e}"))
    }

    /// From a config's `driver` and `port`.
    pub fn from_parts(driver: &str, port: Option<&str>) -> Result<Self, String> {
        if driver.trim().eq_ignore_ascii_case(Self::ARGYLL) {
            let port = match port.map(str::trim) {
                None | Some("") => 1,
                Some(p) => p.parse::<u32>().ok().filter(|n| *n >= 1).ok_or_else(|| {
                    format!(
                        "the ArgyllCMS port is the number `spotread -?` lists (1, 2, …), not '{p}'"
                    )
                })?,
            };
            return Ok(InstrumentAddress::Argyll { port });
        }
        let kind = DeviceKind::parse(driver).map_err(|e| format!("{e}, or argyll"))?;
        match port {
            Some(p) if !p.trim().is_empty() => Ok(InstrumentAddress::Serial {
                kind,
                port: p.to_string(),
            }),
            _ => Err(format!(
                "the {kind} needs its port, e.g. {kind}:/dev/ttyUSB0 (see `chromacal instruments`)"
            )),
        }
    }

    /// The config's `driver` value.
    pub fn driver(&self) -> String {
        match self {
            InstrumentAddress::Serial { kind, .. } => kind.name().to_string(),
            InstrumentAddress::Argyll { .. } => Self::ARGYLL.to_string(),
        }
    }

    /// The config's `port` value.
    pub fn port(&self) -> String {
        match self {
            InstrumentAddress::Serial { port, .. } => port.clone(),
            InstrumentAddress::Argyll { port } => port.to_string(),
        }
    }

    /// What one process at a time may open: the serial port, or Argyll's port N.
    pub fn resource(&self) -> String {
        match self {
            InstrumentAddress::Serial { port, .. } => port.clone(),
            InstrumentAddress::Argyll { port } => format!("ArgyllCMS port {port}"),
        }
    }

    /// What the instrument measures, where known before it is opened (an Argyll
    /// instrument says when spotread has identified it).
    pub fn capability(&self) -> Option<Capability> {
        match self {
            InstrumentAddress::Serial { kind, .. } => Some(kind.capability()),
            InstrumentAddress::Argyll { .. } => None,
        }
    }

    /// Connect; relative paths in `options` from `base_dir`.
    pub fn open(
        &self,
        options: DriverOptions,
        base_dir: &std::path::Path,
    ) -> Result<SerialInstrument, InstrumentError> {
        match self {
            InstrumentAddress::Serial { kind, port } => kind.open(port, options),
            InstrumentAddress::Argyll { port } => {
                super::argyll::driver::open(*port, options, base_dir)
            }
        }
    }
}

impl std::fmt::Display for InstrumentAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InstrumentAddress::Serial { kind, port } => write!(f, "{kind} on {port}"),
            InstrumentAddress::Argyll { port } => write!(f, "ArgyllCMS instrument {port}"),
        }
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How an emulated device departs from the factory one (for tests), and how fast its
/// time runs.
#[derive(Debug, Clone, Copy, Default)]
pub struct EmulatorQuirks {
    /// A Minolta meter switched on without F held (not in remote mode).
    pub not_remote: bool,
    /// The specbos 1211's baud rate setting [default: 115200].
    pub baud: Option<u32>,
    /// Real seconds per device second.
    pub time_scale: f64,
}
