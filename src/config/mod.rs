//! The configuration file (TOML). Unknown keys are errors, and every error names the
//! file, line and column.
//!
//! `config/default.toml` is compiled into the program and used when no `--config` is
//! given: a calibration of the simulated CRT with a simulated spectroradiometer.

pub mod calibration;
pub mod corrections;
pub mod daemon;
pub mod devices;
pub mod ranges;
pub mod verify;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use calibration::{Stability, TargetConfig, WarmupConfig};
pub use daemon::{DaemonConfig, MqttConfig, OnStart, ScheduleConfig};
pub use devices::{DEFAULT_DEVICE, DeviceConfig, device_configs};
pub use verify::VerifyConfig;

use crate::profile::toml_error_position;
use chromacal_display::resolve::ResolveConfig;
use chromacal_display::web::WebConfig;
use chromacal_instruments::devices::InstrumentAddress;
use chromacal_instruments::driver::DriverOptions;
use chromacal_instruments::simulated::SimulatedInstrumentSpec;
use chromacal_model::fit::FitOptions;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::plan::{PlanConfig, Signal};
use chromacal_model::target::ToneCurve;
use chromacal_model::transfer::LawKind;
use chromacal_sim::presets::MonitorConfig;

/// The default configuration, as shipped.
pub const DEFAULT_CONFIG: &str = include_str!("../../config/default.toml");

/// Why a configuration could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: String,
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Invalid { path: String, message: String },
}

/// `[instrument]`: which instrument measures: a serial one (`driver` and `port`), or
/// else the simulated one (`[instrument.simulated]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct InstrumentConfig {
    /// The simulated instrument (used when no `driver` is given).
    pub simulated: Option<SimulatedInstrumentSpec>,
    /// A serial instrument: pr650, pr655, pr670, k10a, specbos1211, ls100, ls110,
    /// cs100a, colorcal2.
    pub driver: Option<String>,
    /// Its port, e.g. `/dev/ttyACM0`.
    pub port: Option<String>,
    #[serde(default)]
    pub options: DriverOptions,
    /// A colorimeter's correction against a reference spectroradiometer: a 3×3 matrix
    /// applied to its XYZ (rows), or an ArgyllCMS `.ccmx` file holding one
    /// (`correction = "display.ccmx"`, relative to the config's directory).
    pub correction: Option<Correction>,
}

/// `instrument.correction`: a matrix written out, or a `.ccmx` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Correction {
    Matrix([[f64; 3]; 3]),
    File(PathBuf),
}

impl Correction {
    /// The matrix, read from its file relative to `base_dir` if need be, and checked
    /// (`ccmx::check_matrix`).
    pub fn matrix(
        &self,
        base_dir: &Path,
    ) -> Result<nalgebra::Matrix3<f64>, chromacal_formats::ccmx::CcmxError> {
        match self {
            Correction::Matrix(rows) => {
                let m = nalgebra::Matrix3::from_fn(|r, c| rows[r][c]);
                chromacal_formats::ccmx::check_matrix(&m, "instrument.correction")?;
                Ok(m)
            }
            Correction::File(path) => {
                let path = corrections::resolve(path, base_dir);
                Ok(chromacal_formats::ccmx::read_ccmx(&path)?.matrix)
            }
        }
    }
}

impl InstrumentConfig {
    /// The real instrument this section names (a serial one, or ArgyllCMS's), if it
    /// names one.
    pub fn address(&self) -> Result<Option<InstrumentAddress>, String> {
        match (&self.driver, &self.port) {
            (None, None) => Ok(None),
            (Some(d), p) => InstrumentAddress::from_parts(d, p.as_deref())
                .map(Some)
                .map_err(|e| format!("instrument: {e}")),
            (None, Some(_)) => Err("instrument.port needs instrument.driver".into()),
        }
    }
}

/// Where patches go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sink {
    /// The in-process virtual monitor (with the simulated instrument).
    Simulated,
    /// The virtual monitor of `chromacal emulate`, through its screen socket.
    Emulator,
    /// A network pattern generator speaking the Resolve protocol (`[display.resolve]`).
    Resolve,
    /// A browser showing chromacal's patch page (`[display.web]`).
    Web,
    /// chromacal's own full-screen window on an X11 output (`x_display`, `output`),
    /// whose video LUT the run holds.
    Window,
    /// chromacal's own full-screen surface on a Wayland output (`wayland_display`,
    /// `output`).
    Wayland,
}

impl Sink {
    pub fn name(self) -> &'static str {
        match self {
            Sink::Simulated => "simulated",
            Sink::Emulator => "emulator",
            Sink::Resolve => "resolve",
            Sink::Web => "web",
            Sink::Window => "window",
            Sink::Wayland => "wayland",
        }
    }

    pub fn parse(text: &str) -> Result<Sink, String> {
        match text.to_ascii_lowercase().as_str() {
            "simulated" => Ok(Sink::Simulated),
            "emulator" => Ok(Sink::Emulator),
            "resolve" => Ok(Sink::Resolve),
            "web" => Ok(Sink::Web),
            "window" => Ok(Sink::Window),
            "wayland" => Ok(Sink::Wayland),
            _ => Err(format!(
                "unknown display '{text}': window[:OUTPUT], wayland[:OUTPUT], resolve, web, emulator or simulated"
            )),
        }
    }
}

/// `[display]`: how patches are shown.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisplayConfig {
    /// Where patches go. Unset: the emulator's screen when `screen` is given, else the
    /// in-process virtual monitor.
    pub sink: Option<Sink>,
    /// Seconds to wait after a patch is on the screen (acknowledged by the web page,
    /// sent to a generator) before measuring.
    pub settle_s: f64,
    /// The screen socket of an emulator (`chromacal emulate`) whose virtual monitor
    /// shows the patches.
    pub screen: Option<PathBuf>,
    /// Re-read each patch until two readings agree.
    pub stability: Option<Stability>,
    /// Ask on the terminal to aim the instrument whenever the patch moves (uniformity
    /// grid), for instruments that cannot see the whole screen.
    pub prompt_positions: bool,
    pub resolve: ResolveConfig,
    pub web: WebConfig,
    /// The X display of the window sink (`:0`); unset: `$DISPLAY`.
    pub x_display: Option<String>,
    /// The Wayland display of the wayland sink (`wayland-0`, or a socket path); unset:
    /// `$WAYLAND_DISPLAY`.
    pub wayland_display: Option<String>,
    /// The window's output: a RandR or wl_output name (`output = "DP-1"`; on Wayland
    /// also the output's description or "make model") or the monitor's EDID serial
    /// (`output = { edid_serial = "…" }`); unset: the primary (X11) or first (Wayland)
    /// output.
    pub output: Option<chromacal_display::x11::OutputSelector>,
    /// Put the current profile's curves back into the video LUT whenever something else
    /// overwrote them (the daemon checks every `lut_check_s`).
    pub keep_lut: bool,
    /// Seconds between the daemon's read-backs of the video LUT.
    pub lut_check_s: f64,
}

impl Default for DisplayConfig {
    fn default() -> Self {
        DisplayConfig {
            sink: None,
            settle_s: 0.2,
            screen: None,
            stability: None,
            prompt_positions: false,
            resolve: ResolveConfig::default(),
            web: WebConfig::default(),
            x_display: None,
            wayland_display: None,
            output: None,
            keep_lut: false,
            lut_check_s: 30.0,
        }
    }
}

impl DisplayConfig {
    /// The sink in use: the configured one, or the one `screen` implies.
    pub fn sink(&self) -> Sink {
        self.sink.unwrap_or(if self.screen.is_some() {
            Sink::Emulator
        } else {
            Sink::Simulated
        })
    }
}

/// `[publish]`: what a profile must achieve to replace the current one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PublishConfig {
    /// Largest mean held-out ΔE00.
    pub max_mean_de00: f64,
    /// Largest 95th-percentile held-out ΔE00.
    pub max_p95_de00: f64,
    /// Largest mean held-out ΔE ITP (ITU-R BT.2124), for a profile of an HDR signal
    /// only: its light is absolute, and ΔE00 against an 800 cd/m² white passes a
    /// 10 % miss at 0.5 cd/m². 1 is DisplayCAL's recommended HDR limit.
    pub max_mean_itp: f64,
}

impl PublishConfig {
    /// Both limits finite and positive: `nan` would let every profile through (or none).
    pub fn check(&self) -> Result<(), String> {
        for (key, value) in [
            ("publish.max_mean_de00", self.max_mean_de00),
            ("publish.max_p95_de00", self.max_p95_de00),
            ("publish.max_mean_itp", self.max_mean_itp),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{key} must be a positive number, not {value}"));
            }
        }
        Ok(())
    }

    /// The one gate every publishing path goes through (with
    /// [`PublishConfig::hdr_rejection`] for a profile of an HDR signal): why a profile
    /// whose error (on held-out patches, or the spatial map's cross-validation) is
    /// `stats` may not replace the current one, or `None` when it may. A figure that is not a finite
    /// number is refused: an error that cannot be told is not within any limit.
    pub fn rejection(&self, stats: Option<&ErrorStats>, what: &str) -> Option<String> {
        let Some(s) = stats else {
            return Some(format!(
                "no {what} ΔE00 (no patches to score), so the profile's error is unknown"
            ));
        };
        if !(s.mean.is_finite() && s.p95.is_finite()) {
            return Some(format!(
                "{what} mean ΔE00 {} / 95th percentile {} is not a number",
                s.mean, s.p95
            ));
        }
        if !(s.mean <= self.max_mean_de00) {
            return Some(format!(
                "{what} mean ΔE00 {:.3} is above the limit {}",
                s.mean, self.max_mean_de00
            ));
        }
        if !(s.p95 <= self.max_p95_de00) {
            return Some(format!(
                "{what} 95th-percentile ΔE00 {:.3} is above the limit {}",
                s.p95, self.max_p95_de00
            ));
        }
        None
    }

    /// The HDR half of the gate: why a profile of `signal` whose held-out patches are
    /// `patches` may not replace the current one, or `None` when it may (always for
    /// an SDR signal). Applied on top of [`PublishConfig::rejection`], never instead of
    /// it, by every path that publishes.
    pub fn hdr_rejection(
        &self,
        signal: Option<chromacal_model::plan::Signal>,
        patches: &[chromacal_model::fit::validate::PatchError],
    ) -> Option<String> {
        signal.filter(|s| s.is_hdr())?;
        self.itp_rejection(chromacal_model::fit::validate::delta_e_itp_stats(patches).as_ref())
    }

    /// Why a held-out ΔE ITP of `stats` misses `max_mean_itp`, or `None`.
    pub fn itp_rejection(&self, stats: Option<&ErrorStats>) -> Option<String> {
        let Some(s) = stats else {
            return Some(
                "no held-out ΔE ITP (no patches to score), so the HDR profile's error is unknown"
                    .to_string(),
            );
        };
        if !s.mean.is_finite() {
            return Some(format!("held-out mean ΔE ITP {} is not a number", s.mean));
        }
        if !(s.mean <= self.max_mean_itp) {
            return Some(format!(
                "held-out mean ΔE ITP {:.3} is above the limit {} (publish.max_mean_itp: an HDR signal's light is absolute, and ΔE00 relative to the white passes misses near black)",
                s.mean, self.max_mean_itp
            ));
        }
        None
    }
}

impl Default for PublishConfig {
    fn default() -> Self {
        PublishConfig {
            max_mean_de00: 1.0,
            max_p95_de00: 2.0,
            max_mean_itp: 1.0,
        }
    }
}

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub monitor: MonitorConfig,
    #[serde(default)]
    pub instrument: InstrumentConfig,
    #[serde(default)]
    pub display: DisplayConfig,
    #[serde(default)]
    pub plan: PlanConfig,
    #[serde(default)]
    pub fit: FitOptions,
    #[serde(default)]
    pub publish: PublishConfig,
    #[serde(default)]
    pub daemon: DaemonConfig,
    #[serde(default)]
    pub schedule: ScheduleConfig,
    #[serde(default)]
    pub warmup: WarmupConfig,
    /// Calibration curves to a target, measured into place after the fit.
    #[serde(default)]
    pub target: Option<TargetConfig>,
    /// Publish the daemon's state and events to an MQTT broker.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mqtt: Option<MqttConfig>,
    /// What `chromacal verify` judges by.
    #[serde(default, skip_serializing_if = "VerifyConfig::is_default")]
    pub verify: VerifyConfig,
    /// Instruments shared by several devices, declared once (`devices`).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub instruments: std::collections::BTreeMap<String, InstrumentConfig>,
    /// Several display–instrument pairs in one daemon, each laid over the top-level
    /// sections (`devices`); none: the config is one device.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub device: Vec<toml::Table>,
}

/// A configuration with the text it came from.
#[derive(Debug, Clone)]
pub struct LoadedConfig {
    pub config: Config,
    pub text: String,
    /// Where it came from ("built-in default" for the embedded one).
    pub origin: String,
    /// Directory relative paths in it are taken from.
    pub base_dir: PathBuf,
}

impl LoadedConfig {
    /// SHA-256 of the text, hex.
    pub fn digest(&self) -> String {
        digest(&self.text)
    }
}

/// SHA-256 of a text, hex.
pub fn digest(text: &str) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Parse configuration text; `origin` names it in errors.
pub fn parse_config(text: &str, origin: &str) -> Result<Config, ConfigError> {
    let config = parse_config_unchecked(text, origin)?;
    check_config(&config).map_err(|message| ConfigError::Invalid {
        path: origin.into(),
        message,
    })?;
    Ok(config)
}

/// Parse without `check_config`: for a run's own config read back from its journal,
/// which was checked when the run started (perhaps by an older version with other
/// ranges), and is checked again once `--resume` has put new settings in. What an HDR
/// signal implies is filled in here, so that a resumed run plans what it began with.
pub fn parse_config_unchecked(text: &str, origin: &str) -> Result<Config, ConfigError> {
    let mut config: Config = toml::from_str(text).map_err(|e| {
        let (line, column, message) = toml_error_position(text, &e);
        ConfigError::Parse {
            path: origin.into(),
            line,
            column,
            message,
        }
    })?;
    hdr_defaults(&mut config);
    Ok(config)
}

/// The fit options for readings taken with `signal` (a journal's, which says, SDR
/// included; `None` for a file that does not, a `.ti3`): the config's, with what the
/// readings' signal asks of a fit instead of what the config's own asked
/// ([`hdr_defaults`]): `fit` of an HLG run's journal models the OOTF and tries the HLG
/// law as the run did, whatever the config found says, and a PQ or SDR journal is not
/// fitted as HLG because the config is. The readings' signal wins over the config's:
/// it is a fact about them. What the signal adds is added to the config as written
/// (`loaded.text`), not taken back from the config as read: what the user wrote stays
/// as written, a list of laws whatever it holds, and `hlg_ootf = true` on any signal.
/// A `LoadedConfig` whose text does not read back into its config (one made in
/// code) keeps its own options, as they are.
pub fn fit_options_for_signal(loaded: &LoadedConfig, signal: Option<Signal>) -> FitOptions {
    let config = &loaded.config;
    let Some(signal) = signal else {
        return config.fit.clone();
    };
    if config.plan.signal.unwrap_or_default() == signal {
        return config.fit.clone();
    }
    let Ok(written) = toml::from_str::<Config>(&loaded.text) else {
        return config.fit.clone();
    };
    let with_defaults = |mut c: Config| {
        hdr_defaults(&mut c);
        c.fit
    };
    if with_defaults(written.clone()) != config.fit {
        return config.fit.clone();
    }
    let mut for_signal = written;
    for_signal.plan.signal = Some(signal);
    with_defaults(for_signal)
}

/// What an HDR signal asks of the rest of a run, where the config does not say: the
/// plan's signal is the target tone's (`pq`, `hlg`); a PQ display's law is among the
/// candidates (when the laws are the default ones); and each patch is read until two
/// readings agree (up to 10), because a display's brightness limiter takes seconds to
/// recover from a bright screen (the surround check's white, a uniformity patch).
/// Applying it twice changes nothing.
pub(crate) fn hdr_defaults(config: &mut Config) {
    let tone = config
        .target
        .as_ref()
        .and_then(|t| chromacal_model::target::parse_tone(&t.tone).ok());
    if config.plan.signal.is_none() {
        config.plan.signal = match tone {
            Some(ToneCurve::Pq { .. }) => Some(Signal::Pq),
            Some(ToneCurve::Hlg { .. }) => Some(Signal::Hlg),
            _ => None,
        };
    }
    let signal = config.plan.signal.unwrap_or_default();
    if signal == Signal::Pq && config.fit.laws == LawKind::ALL {
        config.fit.laws.push(LawKind::Pq);
    }
    if signal == Signal::Hlg {
        if config.fit.laws == LawKind::ALL {
            config.fit.laws.push(LawKind::Hlg);
        }
        config.fit.hlg_ootf = true;
    }
    if signal.is_hdr() && config.display.stability.is_none() {
        config.display.stability = Some(Stability {
            max_reads: 10,
            ..Stability::default()
        });
    }
}

/// Where the patches of a run with `config` will be, for the sinks a user has to
/// attend to (a browser to open, a generator to connect, a screen to aim at).
pub fn where_patches_go(config: &Config) -> Option<String> {
    let output = || config.display.output.clone().unwrap_or_default().describe();
    let named = |given: &Option<String>, variable: &str| {
        given
            .clone()
            .or_else(|| std::env::var(variable).ok())
            .unwrap_or_default()
    };
    Some(match config.display.sink() {
        Sink::Web => format!(
            "open http://{}/ full-screen on the display to measure (e.g. chromium --kiosk)",
            config.display.web.address
        ),
        Sink::Resolve => format!(
            "waiting for a Resolve pattern generator to connect to {}",
            config.display.resolve.address
        ),
        Sink::Window => format!(
            "patches full-screen on {} of X display {}; aim the instrument at the screen's centre",
            output(),
            named(&config.display.x_display, "DISPLAY")
        ),
        Sink::Wayland => format!(
            "patches full-screen on {} of Wayland display {}; aim the instrument at the screen's centre",
            match &config.display.output {
                None => "the first output".to_string(),
                Some(selector) => selector.describe(),
            },
            named(&config.display.wayland_display, "WAYLAND_DISPLAY")
        ),
        Sink::Simulated | Sink::Emulator => return None,
    })
}

/// What the user must set on the display before an HDR run, for the sinks that send
/// no HDR metadata themselves (all of them: chromacal sends codes, not InfoFrames).
pub fn hdr_mode_advice(config: &Config) -> Option<String> {
    let signal = config.plan.signal.filter(|s| s.is_hdr())?;
    let mode = match signal {
        Signal::Hlg => "HLG",
        _ => "HDR10 (PQ)",
    };
    let how = match config.display.sink() {
        Sink::Resolve => format!(
            "set the pattern generator to send {mode} metadata with BT.2020 primaries, so that the display switches to that mode"
        ),
        Sink::Window => format!(
            "X11 sends no HDR metadata: put the display in its {mode} mode from its own menu"
        ),
        Sink::Wayland => format!(
            "the surface is not described as HDR to the compositor: put the display in its {mode} mode from its own menu, with the compositor's HDR off"
        ),
        Sink::Simulated | Sink::Emulator | Sink::Web => return None,
    };
    Some(format!(
        "the patches are a {} signal in {} bits; chromacal sends no HDR metadata: {how}, and leave its picture settings as they will be used",
        signal.describe(),
        config.plan.bit_depth
    ))
}

/// The rules that tie one key to another (the ranges of single keys are in `ranges`).
fn check_between_keys(config: &Config) -> Result<(), String> {
    let monitor = &config.monitor;
    if let (Some(black), Some(white)) = (monitor.black_luminance, monitor.white_luminance)
        && !(black < white)
    {
        return Err(format!(
            "monitor.black_luminance = {black} is not below monitor.white_luminance = {white}"
        ));
    }
    // A PQ target on an HLG signal (or the other way) would aim each code at light
    // the display was never sent.
    if let (Some(signal), Some(target)) = (config.plan.signal, &config.target)
        && let Ok(tone) = chromacal_model::target::parse_tone(&target.tone)
    {
        let wants = match tone {
            ToneCurve::Pq { .. } => Some(Signal::Pq),
            ToneCurve::Hlg { .. } => Some(Signal::Hlg),
            _ => None,
        };
        if let Some(wants) = wants
            && wants != signal
        {
            return Err(format!(
                "plan.signal = \"{}\" does not carry target.tone = \"{}\" (it needs plan.signal = \"{}\")",
                signal.name(),
                target.tone,
                wants.name()
            ));
        }
        if wants.is_none() && signal.is_hdr() {
            return Err(format!(
                "plan.signal = \"{}\" is an HDR signal, but target.tone = \"{}\" is an SDR curve (use tone = \"{}\")",
                signal.name(),
                target.tone,
                if signal == Signal::Pq { "pq" } else { "hlg" }
            ));
        }
    }
    if let Some(sim) = &config.instrument.simulated {
        if !(sim.max_integration_s >= sim.integration_s) {
            return Err(format!(
                "instrument.simulated.max_integration_s = {} is below integration_s = {}",
                sim.max_integration_s, sim.integration_s
            ));
        }
        if !(sim.low_light_limit < sim.overload_limit) {
            return Err(format!(
                "instrument.simulated.low_light_limit = {} is not below overload_limit = {}",
                sim.low_light_limit, sim.overload_limit
            ));
        }
    }
    Ok(())
}

/// Check what the types cannot: ranges, and that the instrument, display and plan go
/// together. Run again after command-line overrides.
pub fn check_config(config: &Config) -> Result<(), String> {
    ranges::check_ranges(config)?;
    config.daemon.check()?;
    if let Some(mqtt) = &config.mqtt {
        mqtt.check()?;
    }
    // With [[device]] entries, the rest is checked on each device's own config
    // (`devices::device_configs`): the top level alone need not be a whole rig (a
    // web sink there may be for devices that each bring their serial instrument).
    if !config.device.is_empty() {
        return Ok(());
    }
    check_between_keys(config)?;
    config.publish.check()?;
    config.verify.check()?;
    config.schedule.check()?;
    config.warmup.check()?;
    if let Some(target) = &config.target {
        target.check()?;
    }
    if !(config.display.settle_s >= 0.0) {
        return Err("display.settle_s must not be negative".into());
    }
    if config.fit.laws.is_empty() {
        return Err("fit.laws must name at least one law".into());
    }
    let serial = config.instrument.address()?;
    // A light meter's readings make no model without the primaries' chromaticities:
    // say so now, not after every patch has been measured.
    if let Some(InstrumentAddress::Serial { kind, .. }) = &serial
        && kind.capability() == chromacal_instruments::Capability::Luminance
        && config.fit.primaries_xy.is_none()
    {
        return Err(format!(
            "the {kind} measures luminance only: give the primaries' chromaticities in [fit] primaries_xy = [[xr, yr], [xg, yg], [xb, yb]] (the manufacturer's figures) before measuring"
        ));
    }
    let sink = config.display.sink();
    match (sink, serial.is_some()) {
        (Sink::Simulated, true) => {
            return Err(
                "a serial instrument needs a display it can measure: set display.sink to window, wayland, resolve or web (or give an emulator's screen)".into());
        }
        (Sink::Resolve | Sink::Web | Sink::Emulator | Sink::Window | Sink::Wayland, false) => {
            return Err(format!(
                "display.sink = \"{}\" needs a serial instrument (instrument.driver and port): the simulated instrument can only measure the in-process virtual monitor",
                sink.name()
            ));
        }
        _ => {}
    }
    if sink == Sink::Emulator && config.display.screen.is_none() {
        return Err("display.sink = \"emulator\" needs display.screen".into());
    }
    let signal = config.plan.signal.unwrap_or_default();
    if signal.is_hdr() && sink == Sink::Web {
        return Err(format!(
            "plan.signal = \"{}\" is an HDR signal, and the web patch page paints 8-bit sRGB through the browser's colour management: use display.sink = \"resolve\" (10 bits, the pattern generator in HDR10 or HLG mode) or a 30-bit window",
            signal.name()
        ));
    }
    if signal.is_hdr() && config.plan.bit_depth < 10 {
        return Err(format!(
            "plan.signal = \"{}\" is carried in 10 or 12 bits (BT.2100; in 8, PQ's steps show as bands): set plan.bit_depth = 10",
            signal.name()
        ));
    }
    if sink == Sink::Web && config.plan.bit_depth != 8 {
        return Err(format!(
            "the web patch page paints 8 bits per channel: set plan.bit_depth = 8, not {}",
            config.plan.bit_depth
        ));
    }
    if sink == Sink::Resolve
        && config.display.resolve.flavour == chromacal_display::resolve::Flavour::Ls
        && config.plan.bit_depth != 8
    {
        return Err(format!(
            "the LightSpace flavour sends 8-bit colours: set plan.bit_depth = 8, not {}, or use flavour = \"cm\"",
            config.plan.bit_depth
        ));
    }
    if let Some(s) = config.display.stability
        && !(s.tolerance >= 0.0 && s.floor >= 0.0 && s.max_reads >= 2)
    {
        return Err(
            "display.stability needs tolerance and floor not negative and max_reads at least 2"
                .into(),
        );
    }
    if serial.is_some() && config.instrument.simulated.is_some() {
        return Err(
            "instrument: give either [instrument.simulated] or a driver and port, not both".into(),
        );
    }
    if let Some(Correction::Matrix(rows)) = &config.instrument.correction {
        let m = nalgebra::Matrix3::from_fn(|r, c| rows[r][c]);
        chromacal_formats::ccmx::check_matrix(&m, "instrument.correction")
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Load `path`, or the built-in default when `None`.
pub fn load_config(path: Option<&Path>) -> Result<LoadedConfig, ConfigError> {
    match path {
        None => Ok(LoadedConfig {
            config: parse_config(DEFAULT_CONFIG, "built-in config/default.toml")?,
            text: DEFAULT_CONFIG.to_string(),
            origin: "built-in config/default.toml".into(),
            base_dir: std::env::current_dir().unwrap_or_else(|_| PathBuf::from(".")),
        }),
        Some(path) => {
            let text = chromacal_formats::durable::read_text_limited(
                path,
                chromacal_formats::durable::limits::CONFIG,
            )
            .map_err(|source| ConfigError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            let origin = path.display().to_string();
            Ok(LoadedConfig {
                config: parse_config(&text, &origin)?,
                text,
                origin,
                base_dir: path
                    .parent()
                    .filter(|p| !p.as_os_str().is_empty())
                    .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
            })
        }
    }
}

/// Where a config is looked for when none is named, first found first: the user's
/// (`$XDG_CONFIG_HOME/chromacal/config.toml`, else `~/.config/chromacal/config.toml`,
/// per the XDG Base Directory specification), then the system's
/// (`/etc/chromacal/config.toml`, where the systemd unit reads it).
pub fn config_search_paths() -> Vec<PathBuf> {
    let user = std::env::var_os("XDG_CONFIG_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".config")));
    user.map(|dir| dir.join("chromacal").join("config.toml"))
        .into_iter()
        .chain([PathBuf::from("/etc/chromacal/config.toml")])
        .collect()
}

/// Load the config named, else the first of `search` that exists, else the built-in
/// one. `LoadedConfig::origin` says which.
pub fn load_config_searching(
    path: Option<&Path>,
    search: &[PathBuf],
) -> Result<LoadedConfig, ConfigError> {
    match path {
        Some(path) => load_config(Some(path)),
        None => load_config(search.iter().find(|p| p.is_file()).map(PathBuf::as_path)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_name_the_first_config_found_is_read_else_the_built_in_one() {
        let dir = tempfile::tempdir().unwrap();
        let user = dir.path().join("user.toml");
        let system = dir.path().join("system.toml");
        let search = [user.clone(), system.clone()];
        let origin = |path: Option<&Path>| load_config_searching(path, &search).unwrap().origin;
        assert_eq!(origin(None), "built-in config/default.toml");
        std::fs::write(&system, "[plan]\nbudget = 60\n").unwrap();
        assert_eq!(origin(None), system.display().to_string());
        std::fs::write(&user, "[plan]\nbudget = 70\n").unwrap();
        let loaded = load_config_searching(None, &search).unwrap();
        assert_eq!(loaded.origin, user.display().to_string());
        assert_eq!(loaded.config.plan.budget, 70);
        // One named wins over both; a broken one found is an error, not skipped.
        let named = dir.path().join("named.toml");
        std::fs::write(&named, "[plan]\nbudget = 80\n").unwrap();
        assert_eq!(origin(Some(&named)), named.display().to_string());
        std::fs::write(&user, "[plan]\nbugdet = 70\n").unwrap();
        assert!(load_config_searching(None, &search).is_err());
    }

    #[test]
    fn a_light_meter_without_chromaticities_is_refused_before_measuring() {
        let text = "[instrument]\ndriver = \"ls100\"\nport = \"/dev/ttyUSB0\"\n[display]\nsink = \"web\"\n";
        let error = parse_config(text, "c.toml").unwrap_err().to_string();
        assert!(error.contains("primaries_xy"), "{error}");
        let fixed =
            format!("{text}[fit]\nprimaries_xy = [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]]\n");
        parse_config(&fixed, "c.toml").unwrap();
    }

    #[test]
    fn an_hdr_tone_sets_the_signal_and_a_contradicting_signal_is_refused() {
        let pq = "[target]\ntone = \"pq\"\npeak = 600\n[plan]\nbit_depth = 10\n";
        for parse in [parse_config, parse_config_unchecked] {
            let config = parse(pq, "c.toml").unwrap();
            assert_eq!(config.plan.signal, Some(Signal::Pq));
            assert!(config.fit.laws.contains(&LawKind::Pq));
            assert!(config.display.stability.is_some());
            // Filled in twice is filled in once.
            let mut again = config.clone();
            hdr_defaults(&mut again);
            assert_eq!(again.fit.laws, config.fit.laws);
        }
        let hlg_on_pq = format!("{pq}signal = \"hlg\"\n");
        let error = parse_config(&hlg_on_pq, "c.toml").unwrap_err().to_string();
        assert!(error.contains("needs plan.signal = \"pq\""), "{error}");
        let sdr_tone = "[target]\ntone = \"srgb\"\n[plan]\nsignal = \"pq\"\nbit_depth = 10\n";
        let error = parse_config(sdr_tone, "c.toml").unwrap_err().to_string();
        assert!(error.contains("is an SDR curve"), "{error}");
        let sdr = parse_config("[target]\ntone = \"srgb\"\n", "c.toml").unwrap();
        assert_eq!(sdr.plan.signal, None);
        assert!(!sdr.fit.laws.contains(&LawKind::Pq));
        // HLG: its law and its OOTF are tried, and only for it.
        let hlg = "[target]\ntone = \"hlg\"\npeak = 1000\n[plan]\nbit_depth = 10\n";
        let config = parse_config(hlg, "c.toml").unwrap();
        assert_eq!(config.plan.signal, Some(Signal::Hlg));
        assert!(config.fit.laws.contains(&LawKind::Hlg) && !config.fit.laws.contains(&LawKind::Pq));
        assert!(config.fit.hlg_ootf);
        let mut again = config.clone();
        hdr_defaults(&mut again);
        assert_eq!(again.fit.laws, config.fit.laws);
        for other in [sdr, parse_config(pq, "c.toml").unwrap()] {
            assert!(!other.fit.hlg_ootf && !other.fit.laws.contains(&LawKind::Hlg));
        }
    }

    /// A fit takes what the readings' signal asks, not what the config's did: an HLG
    /// journal fitted with a PQ config tries the HLG law and its OOTF and not the PQ
    /// law; a PQ or SDR journal with an HLG config is not fitted as HLG; a listed set
    /// of laws is left as listed; a file that does not say (a `.ti3`) keeps the
    /// config's.
    #[test]
    fn a_fit_follows_the_signal_its_readings_were_taken_with() {
        let loaded = |text: &str| LoadedConfig {
            config: parse_config(text, "c.toml").unwrap(),
            text: text.into(),
            origin: "c.toml".into(),
            base_dir: PathBuf::from("."),
        };
        let pq = loaded("[target]\ntone = \"pq\"\n[plan]\nbit_depth = 10\n");
        let hlg = loaded("[target]\ntone = \"hlg\"\npeak = 1000\n[plan]\nbit_depth = 10\n");
        let sdr = loaded("[target]\ntone = \"srgb\"\n");
        let with = |kind: LawKind| [LawKind::ALL.as_slice(), &[kind]].concat();
        let options = fit_options_for_signal(&pq, Some(Signal::Hlg));
        assert_eq!(options.laws, with(LawKind::Hlg));
        assert!(options.hlg_ootf);
        let options = fit_options_for_signal(&hlg, Some(Signal::Pq));
        assert_eq!(options.laws, with(LawKind::Pq));
        assert!(!options.hlg_ootf);
        let options = fit_options_for_signal(&hlg, Some(Signal::Sdr));
        assert_eq!(options.laws, LawKind::ALL);
        assert!(!options.hlg_ootf);
        let options = fit_options_for_signal(&sdr, Some(Signal::Hlg));
        assert_eq!(options.laws, with(LawKind::Hlg));
        assert!(options.hlg_ootf);
        // The same signal, or none said: the config's own.
        assert_eq!(
            fit_options_for_signal(&hlg, Some(Signal::Hlg)),
            hlg.config.fit
        );
        assert_eq!(fit_options_for_signal(&hlg, None), hlg.config.fit);
        assert_eq!(
            fit_options_for_signal(&sdr, Some(Signal::Sdr)),
            sdr.config.fit
        );
        // Laws the user listed stay as listed, whatever they are: the default ones
        // with the PQ law among them too (which the config's PQ signal would have
        // added, and so were once taken back for an HLG journal).
        let names = |laws: &[LawKind]| {
            laws.iter()
                .map(|l| format!("\"{}\"", l.name()))
                .collect::<Vec<_>>()
                .join(", ")
        };
        for laws in [
            vec![LawKind::Table, LawKind::Pq, LawKind::PqCowan],
            with(LawKind::Pq),
        ] {
            let listed = loaded(&format!(
                "[target]\ntone = \"pq\"\n[plan]\nbit_depth = 10\n[fit]\nlaws = [{}]\n",
                names(&laws)
            ));
            assert_eq!(listed.config.fit.laws, laws);
            let options = fit_options_for_signal(&listed, Some(Signal::Hlg));
            assert_eq!(options.laws, laws);
            assert!(options.hlg_ootf);
        }
        // The OOTF the user asked for in an SDR config stays asked for.
        let asked = loaded("[target]\ntone = \"srgb\"\n[fit]\nhlg_ootf = true\n");
        assert!(fit_options_for_signal(&asked, Some(Signal::Pq)).hlg_ootf);
        // A config whose text is not what it was read from keeps its own options.
        let made = LoadedConfig {
            text: String::new(),
            ..loaded("[target]\ntone = \"pq\"\n[plan]\nbit_depth = 10\n")
        };
        assert_eq!(
            fit_options_for_signal(&made, Some(Signal::Hlg)),
            made.config.fit
        );
    }

    #[test]
    fn a_patch_decaying_towards_its_light_is_not_settled_until_little_is_left() {
        use chromacal_instruments::{Reading, ReadingStatus};
        let reading = |y: f64| Reading {
            xyz: Some(chromacal_color::Xyz::new(0.95 * y, y, 1.09 * y)),
            luminance: None,
            spectrum: None,
            status: ReadingStatus::Ok,
            integration_s: 1.0,
            device_code: None,
            raw: None,
        };
        let s = Stability::default(); // 1 %
        // A limiter settling on 180 cd/m² from above, by 0.6 a reading: the last two
        // agree within 1 % (0.8 % apart) while 1.3 % is still to go.
        let decay = |n: i32| 180.0 * (1.0 + 0.25 * 0.6f64.powi(n));
        let (a, b, c) = (reading(decay(4)), reading(decay(5)), reading(decay(6)));
        assert!(s.agree(&b, &c));
        assert!(!s.settled(Some(&a), &b, &c));
        // Later, little is left; and readings that only scatter are settled at once.
        let (a, b, c) = (reading(decay(9)), reading(decay(10)), reading(decay(11)));
        assert!(s.settled(Some(&a), &b, &c));
        let (a, b, c) = (reading(180.3), reading(179.8), reading(180.1));
        assert!(s.settled(Some(&a), &b, &c) && s.settled(None, &b, &c));
    }

    #[test]
    fn publishing_limits_must_be_numbers_and_the_gate_refuses_figures_that_are_not() {
        for text in [
            "[publish]\nmax_mean_de00 = nan\n",
            "[publish]\nmax_p95_de00 = inf\n",
            "[publish]\nmax_mean_de00 = -1.0\n",
        ] {
            let error = parse_config(text, "c.toml").unwrap_err().to_string();
            assert!(
                error.contains("is out of range: it must be from 0.000001 to 1000"),
                "{text}: {error}"
            );
        }
        let limits = PublishConfig::default();
        let stats = |mean: f64, p95: f64| ErrorStats {
            n: 10,
            mean,
            p95,
            max: p95,
        };
        assert_eq!(limits.rejection(Some(&stats(0.5, 1.0)), "held-out"), None);
        for (mean, p95) in [(f64::NAN, 1.0), (0.5, f64::NAN), (f64::INFINITY, 1.0)] {
            let why = limits
                .rejection(Some(&stats(mean, p95)), "held-out")
                .unwrap();
            assert!(why.contains("is not a number"), "{why}");
        }
        assert!(
            limits
                .rejection(Some(&stats(1.5, 1.0)), "held-out")
                .unwrap()
                .contains("above the limit")
        );
        assert!(
            limits
                .rejection(None, "held-out")
                .unwrap()
                .contains("unknown")
        );
        // The HDR half: the mean ΔE ITP alone, a NaN refused, no patches unknown.
        assert_eq!(limits.itp_rejection(Some(&stats(0.9, 3.0))), None);
        let why = limits.itp_rejection(Some(&stats(1.2, 1.0))).unwrap();
        assert!(
            why.contains("mean ΔE ITP 1.200") && why.contains("limit 1"),
            "{why}"
        );
        let why = limits.itp_rejection(Some(&stats(f64::NAN, 1.0))).unwrap();
        assert!(why.contains("is not a number"), "{why}");
        assert!(limits.itp_rejection(None).unwrap().contains("unknown"));
    }

    #[test]
    fn the_default_config_parses_and_builds_a_monitor() {
        let loaded = load_config(None).unwrap();
        assert_eq!(loaded.digest().len(), 64);
        loaded.config.monitor.resolve(&loaded.base_dir).unwrap();
    }

    #[test]
    fn instrument_display_and_plan_must_go_together() {
        let error = |text: &str| parse_config(text, "c.toml").unwrap_err().to_string();
        let serial = "[instrument]\ndriver = \"pr670\"\nport = \"/dev/ttyACM0\"\n";
        assert!(error("[display]\nsink = \"web\"\n").contains("needs a serial instrument"));
        assert!(error(serial).contains("needs a display it can measure"));
        assert!(
            error(&format!("{serial}[display]\nsink = \"emulator\"\n"))
                .contains("needs display.screen")
        );
        assert!(
            error(&format!(
                "{serial}[display]\nsink = \"web\"\n[plan]\nbit_depth = 10\n"
            ))
            .contains("8 bits per channel")
        );
        assert!(
            error(&format!("{serial}[display]\nsink = \"resolve\"\n[display.resolve]\nflavour = \"ls\"\n[plan]\nbit_depth = 10\n"))
                .contains("LightSpace")
        );
        assert!(
            error(&format!(
                "{serial}[display]\nsink = \"web\"\n[display.stability]\nmax_reads = 1\n"
            ))
            .contains("max_reads")
        );
        // An HDR plan: never on the web page, never in 8 bits; said before measuring.
        let pq = "[target]\ntone = \"pq\"\n";
        let web = error(&format!("{serial}{pq}[display]\nsink = \"web\"\n"));
        assert!(web.contains("HDR signal") && web.contains("8-bit"), "{web}");
        let eight = error(&format!("{serial}{pq}[display]\nsink = \"resolve\"\n"));
        assert!(eight.contains("set plan.bit_depth = 10"), "{eight}");
        let resolve = parse_config(
            &format!("{serial}{pq}[display]\nsink = \"resolve\"\n[plan]\nbit_depth = 10\n"),
            "c.toml",
        )
        .unwrap();
        let advice = hdr_mode_advice(&resolve).unwrap();
        assert!(advice.contains("HDR10 (PQ)"), "{advice}");
        let ok = parse_config(
            &format!("{serial}[display]\nsink = \"resolve\"\n[display.resolve]\naddress = \"127.0.0.1:0\"\n[plan]\nbit_depth = 10\n"),
            "c.toml",
        )
        .unwrap();
        assert_eq!(ok.display.sink(), Sink::Resolve);
    }

    #[test]
    fn unknown_keys_are_errors_with_line_and_column() {
        let text = "[plan]\nbudget = 48\nbugdet = 12\n";
        match parse_config(text, "test.toml") {
            Err(ConfigError::Parse {
                line,
                column,
                message,
                ..
            }) => {
                assert_eq!((line, column), (3, 1), "{message}");
                assert!(message.contains("bugdet"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        let text = "[plan]\nbudget = \"many\"\n";
        let err = parse_config(text, "test.toml").unwrap_err().to_string();
        assert!(err.starts_with("test.toml:2:10"), "{err}");
    }
}
