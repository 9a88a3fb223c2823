//! The `chromacal` command.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};

use chromacal::calibrate::devices::Overrides;
use chromacal::calibrate::run::Progress;
use chromacal::calibrate::session::{CalibrateOptions, calibrate as calibrate_session};
use chromacal::color::spaces::{Xyz, xyz_to_luv, xyz_to_uv_prime, xyz_to_xyy};
use chromacal::color::spectrum::{
    Illuminant, Observer, Spectrum, emission_to_relative_xyz, emission_to_xyz, photopic_luminance,
    reflectance_to_xyz, scotopic_luminance, white_point,
};
use chromacal::color::xyz_to_lab;
use chromacal::config::{Sink, load_config};
use chromacal::fit::validate::evaluate;
use chromacal::fit::{FitOptions, fit_monitor};
use chromacal::instrument::devices::DeviceKind;
use chromacal::instrument::driver::DriverOptions;
use chromacal::measurement::Units;
use chromacal::measurement_file::read_measurements;
use chromacal::model::ScreenPosition;
use chromacal::model::transfer::LawKind;
use chromacal::numeric_csv::NumericTable;
use chromacal::profile::store::default_state_dir;
use chromacal::profile::{Profile, Provenance, SCHEMA_VERSION};
use chromacal::report;

mod bench;
mod emulate;
mod remote;

#[derive(Parser)]
#[command(
    name = "chromacal",
    version,
    about = "Monitor calibration: measure, fit a physical model, test its assumptions, publish a profile"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a calibration (by default of the simulated CRT, no hardware needed) and
    /// publish the profile to the state directory.
    Calibrate {
        /// Configuration file (TOML); the built-in config/default.toml when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Profile store and run journals [default: $STATE_DIRECTORY, else
        /// $XDG_STATE_HOME/chromacal, else ~/.local/state/chromacal].
        #[arg(long)]
        state_dir: Option<PathBuf>,
        /// Resume the newest unfinished run, measuring only what it lacks.
        #[arg(long)]
        resume: bool,
        /// Take the simulated instrument's time for real (scaled by --time-scale).
        #[arg(long)]
        realtime: bool,
        /// Real seconds per simulated second with --realtime.
        #[arg(long, default_value_t = 1.0, requires = "realtime")]
        time_scale: f64,
        /// Print the profile's report as JSON instead of the summary.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        devices: DeviceArgs,
    },
    /// Fit a profile to recorded measurements: a run journal or an ArgyllCMS .ti3.
    Fit {
        measurements: PathBuf,
        /// Where to write the profile (TOML).
        #[arg(short, long)]
        output: PathBuf,
        /// Take the [fit] options from this configuration file.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Candidate laws (comma-separated), instead of the config's.
        #[arg(long, value_delimiter = ',')]
        laws: Option<Vec<LawArg>>,
        #[arg(long)]
        json: bool,
    },
    /// Predict every measured patch from a profile and report the ΔE00.
    Check {
        profile: PathBuf,
        measurements: PathBuf,
        /// Machine-readable output with every patch's prediction.
        #[arg(long)]
        json: bool,
        /// How many of the worst patches to list.
        #[arg(long, default_value_t = 10)]
        worst: usize,
    },
    /// Integrate spectra to XYZ, xyY, u′v′, L*a*b* and L*u*v*.
    ///
    /// The CSV's first column is `wavelength_nm`, each further column a sample. A
    /// sample on a uniform grid of whole nanometres (1, 4, 5, 10 nm …) is summed on
    /// its own grid, the colour-matching functions read at its wavelengths and Δλ its
    /// step (CIE 15 weighted ordinates). Any other grid (uneven, or steps such as
    /// 3.333 nm) is interpolated linearly onto the CMFs' 1 nm grid and summed with
    /// Δλ = 1 nm. Sums run only where the sample, the CMFs (360–830 nm) and the
    /// illuminant are all defined; nothing is extrapolated.
    Spectrum {
        file: PathBuf,
        /// Columns are radiance spectra (the default).
        #[arg(long, conflicts_with = "reflectance")]
        emission: bool,
        /// Columns are reflectance factors (0–1) under --illuminant, with Y of the
        /// illuminant = 100.
        #[arg(long)]
        reflectance: bool,
        /// Emission: scale each sample to Y = 100 instead of absolute Y = 683 Σ S ȳ Δλ.
        #[arg(long)]
        relative: bool,
        /// Illuminant for --reflectance; for emission, the chromaticity of the
        /// reference white of L*a*b* and L*u*v*.
        #[arg(long, value_enum, default_value = "d65")]
        illuminant: IlluminantArg,
        /// Emission: luminance of the reference white [default: the brightest sample's].
        #[arg(long)]
        white_y: Option<f64>,
        /// Standard observer: 2 (CIE 1931) or 10 (CIE 1964).
        #[arg(long, default_value = "2", value_parser = ["2", "10"])]
        observer: String,
        #[arg(long)]
        json: bool,
    },
    /// Emulate a serial instrument on a pseudo-terminal: prints the device path to open
    /// and the screen socket to show patches on, then answers as the instrument would,
    /// measuring a virtual monitor, until stopped.
    Emulate(emulate::EmulateArgs),
    /// Measure what the display shows now with a serial instrument.
    Measure {
        /// KIND:PORT, e.g. pr670:/dev/ttyACM0.
        #[arg(long)]
        instrument: String,
        #[arg(long, default_value_t = 1)]
        count: usize,
        /// Multiplies the protocol's timeouts (for emulators run faster than real time).
        #[arg(long, default_value_t = 1.0)]
        timing_scale: f64,
        #[arg(long)]
        json: bool,
    },
    /// List serial ports and identify the instruments on them.
    Instruments {
        /// Also probe this port (pseudo-terminals are not listed by the system).
        #[arg(long)]
        port: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Write a profile for other tools: ICC v4 or v2 display profiles (with vcgt when a
    /// target is given), ArgyllCMS .ti3 (the run's measurements) and .cal (calibration
    /// curves to a target), a PsychoPy monitor file, or the profile as JSON or TOML.
    Export {
        /// The profile (a chromacal .toml).
        profile: PathBuf,
        #[arg(long, value_parser = ["icc4", "icc2", "ti3", "cal", "psychopy", "json", "toml"])]
        format: String,
        /// Where to write it.
        #[arg(short, long)]
        output: PathBuf,
        /// The measurements for .ti3 and PsychoPy spectra [default: the run journal the
        /// profile names].
        #[arg(long)]
        measurements: Option<PathBuf>,
        /// Calibration target white: native, D50, D55, D65, D75, 6500K or x,y.
        #[arg(long)]
        white: Option<String>,
        /// Calibration target tone curve: gamma:G, srgb, bt1886 or lstar [default: gamma:2.2].
        #[arg(long)]
        tone: Option<String>,
        /// Calibration target white luminance in cd/m², or max [default: max].
        #[arg(long)]
        luminance: Option<String>,
        /// Also make the ICC file the default profile of this display in colord
        /// (e.g. xrandr-Dell-U2713HM-SN123, the id GNOME or KDE gave it), over the system
        /// D-Bus ($DBUS_SYSTEM_BUS_ADDRESS). Exit 4 when colord cannot be reached.
        #[arg(long, value_name = "DEVICE_ID")]
        register_colord: Option<String>,
    },
    /// Work with profiles.
    Profile {
        #[command(subcommand)]
        command: ProfileCommand,
    },
    /// Run as a service: hold the instrument and the display, run one job at a time,
    /// verify on a schedule and recalibrate when the screen moved, and answer the
    /// control API (HTTP on a unix socket, mode 0600; optionally loopback TCP with a
    /// token): GET /status, POST /jobs {"kind": …}, POST /jobs/cancel, GET /events
    /// (server-sent events), GET /profile[?format=json|icc4|icc2|ti3|cal|psychopy],
    /// GET /history, POST /rollback.
    /// Stops on SIGTERM after the reading under way; an interrupted calibration
    /// resumes at the next start.
    Daemon {
        /// Configuration file [default: the built-in one].
        #[arg(long)]
        config: Option<PathBuf>,
        /// Profile store, journals, history [default: as for calibrate].
        #[arg(long)]
        state_dir: Option<PathBuf>,
        /// The API's unix socket [default: $RUNTIME_DIRECTORY/api.sock, else <state>/api.sock].
        #[arg(long)]
        socket: Option<PathBuf>,
        /// Also serve the API on this loopback TCP address (token in <state>/api.token).
        #[arg(long, value_name = "ADDR")]
        tcp: Option<String>,
        /// Real seconds per simulated second for the simulated monitor and instrument
        /// (`daemon.simulated_time_scale`; 0.01 runs a 5-minute calibration in 3 s).
        #[arg(long, value_name = "S")]
        time_scale: Option<f64>,
    },
    /// Ask a running daemon how it is.
    Status {
        #[command(flatten)]
        api: remote::ApiArgs,
        #[arg(long)]
        json: bool,
    },
    /// Start, follow or cancel a daemon's job.
    Job {
        #[command(subcommand)]
        command: JobCommand,
        #[command(flatten)]
        api: remote::ApiArgs,
    },
    /// The daemon's profiles (made current, oldest first) and verifications.
    History {
        #[command(flatten)]
        api: remote::ApiArgs,
        #[arg(long)]
        json: bool,
    },
    /// Make an earlier profile current again (default: the one before the current).
    Rollback {
        /// The profile id to go back to.
        to: Option<String>,
        #[command(flatten)]
        api: remote::ApiArgs,
    },
    /// Speed against error: fit time per law against readings, and held-out ΔE00
    /// against patch budget, on simulated monitors (and on real measured displays when
    /// ../shared/data is present).
    Bench {
        /// Fewer repeats, for a quick look.
        #[arg(long)]
        quick: bool,
        /// Directory of the shared reference data [default: ../shared/data].
        #[arg(long)]
        data: Option<PathBuf>,
    },
}

/// Which instrument and display a calibration uses, when not the config's.
#[derive(clap::Args, Default)]
struct DeviceArgs {
    /// A serial instrument as KIND:PORT, e.g. pr670:/dev/ttyACM0 (see `chromacal instruments`).
    #[arg(long)]
    instrument: Option<String>,
    /// The screen socket of `chromacal emulate`, whose virtual monitor shows the patches.
    #[arg(long)]
    screen: Option<PathBuf>,
    /// Multiplies the instrument protocol's timeouts (for emulators run faster than real time).
    #[arg(long)]
    timing_scale: Option<f64>,
    /// Where patches go: resolve (a pattern generator connects to chromacal), web (a
    /// browser opens chromacal's patch page), emulator or simulated.
    #[arg(long, value_name = "SINK")]
    display: Option<String>,
    /// Address the Resolve server or the web page listens on, e.g. 127.0.0.1:20002.
    #[arg(long, value_name = "ADDR")]
    listen: Option<String>,
    /// Ask on the terminal to aim the instrument each time the patch moves.
    #[arg(long)]
    prompt_positions: bool,
}

impl DeviceArgs {
    fn overrides(&self) -> Result<Overrides, Failure> {
        Ok(Overrides {
            instrument: match &self.instrument {
                Some(spec) => Some(parse_instrument(spec)?),
                None => None,
            },
            screen: self.screen.clone(),
            timing_scale: self.timing_scale,
            sink: match &self.display {
                Some(text) => Some(Sink::parse(text).map_err(Failure::from)?),
                None => None,
            },
            listen: self.listen.clone(),
            prompt_positions: self.prompt_positions,
        })
    }
}

/// KIND:PORT.
fn parse_instrument(spec: &str) -> Result<(DeviceKind, String), Failure> {
    let (kind, port) = spec.split_once(':').ok_or_else(|| {
        Failure::from(format!(
            "--instrument wants KIND:PORT, e.g. pr670:/dev/ttyACM0, not '{spec}'"
        ))
    })?;
    Ok((
        DeviceKind::parse(kind).map_err(Failure::from)?,
        port.to_string(),
    ))
}

#[derive(Subcommand)]
enum ProfileCommand {
    /// Print the model in words and numbers.
    Show { profile: PathBuf },
    /// The current profile of a running daemon (TOML, or JSON).
    Current {
        #[command(flatten)]
        api: remote::ApiArgs,
        #[arg(long)]
        json: bool,
        /// Any export format (the daemon exports it): icc4, icc2, ti3, psychopy, json, toml.
        #[arg(long, value_parser = ["icc4", "icc2", "ti3", "psychopy", "json", "toml"])]
        format: Option<String>,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum JobCommand {
    /// Start a job: calibrate, verify or uniformity.
    Start {
        /// calibrate (a whole calibration, published if it passes), verify (a few
        /// patches against the current profile's prediction) or uniformity (the grid
        /// alone: a new spatial map for the current profile).
        #[arg(value_parser = ["calibrate", "verify", "uniformity"])]
        kind: String,
        /// Follow it to its end with a progress bar.
        #[arg(long)]
        watch: bool,
    },
    /// Follow the running job to its end.
    Watch,
    /// Stop the running job after the reading under way (a cancelled calibration is
    /// not resumed).
    Cancel,
}

#[derive(Clone, Copy, ValueEnum)]
enum LawArg {
    Power,
    GainOffsetGamma,
    Cowan,
    ThreeTerm,
    Table,
}

impl From<LawArg> for LawKind {
    fn from(l: LawArg) -> Self {
        match l {
            LawArg::Power => LawKind::Power,
            LawArg::GainOffsetGamma => LawKind::GainOffsetGamma,
            LawArg::Cowan => LawKind::Cowan,
            LawArg::ThreeTerm => LawKind::ThreeTerm,
            LawArg::Table => LawKind::Table,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum IlluminantArg {
    A,
    C,
    D50,
    D65,
    F2,
    F7,
    F11,
}

impl From<IlluminantArg> for Illuminant {
    fn from(i: IlluminantArg) -> Self {
        match i {
            IlluminantArg::A => Illuminant::A,
            IlluminantArg::C => Illuminant::C,
            IlluminantArg::D50 => Illuminant::D50,
            IlluminantArg::D65 => Illuminant::D65,
            IlluminantArg::F2 => Illuminant::F2,
            IlluminantArg::F7 => Illuminant::F7,
            IlluminantArg::F11 => Illuminant::F11,
        }
    }
}

/// A failure to report and the exit code to leave with.
struct Failure {
    message: String,
    code: u8,
}

impl<E: std::fmt::Display> From<E> for Failure {
    fn from(e: E) -> Self {
        Failure {
            message: e.to_string(),
            code: 1,
        }
    }
}

/// Exit code when a profile was made but did not pass the publishing limits.
const NOT_PUBLISHED: u8 = 3;

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A service logs what it does; a command only what went wrong. One line per event,
    // without colour when stderr is not a terminal (the systemd journal).
    let default_level = match cli.command {
        Command::Daemon { .. } => "info",
        _ => "warn",
    };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("CHROMACAL_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_level)),
        )
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Calibrate {
            config,
            state_dir,
            resume,
            realtime,
            time_scale,
            json,
            devices,
        } => devices.overrides().and_then(|overrides| {
            calibrate(
                config.as_deref(),
                state_dir,
                resume,
                realtime.then_some(time_scale),
                json,
                overrides,
            )
        }),
        Command::Emulate(args) => emulate::run(args).map_err(Failure::from),
        Command::Measure {
            instrument,
            count,
            timing_scale,
            json,
        } => measure(&instrument, count, timing_scale, json),
        Command::Instruments { port, json } => instruments(&port, json),
        Command::Fit {
            measurements,
            output,
            config,
            laws,
            json,
        } => fit(&measurements, &output, config.as_deref(), laws, json),
        Command::Check {
            profile,
            measurements,
            json,
            worst,
        } => check(&profile, &measurements, json, worst),
        Command::Spectrum {
            file,
            emission: _,
            reflectance,
            relative,
            illuminant,
            white_y,
            observer,
            json,
        } => spectrum(
            &file,
            reflectance,
            relative,
            illuminant.into(),
            white_y,
            &observer,
            json,
        ),
        Command::Profile {
            command: ProfileCommand::Show { profile },
        } => Profile::read(&profile)
            .map(|p| print!("{}", report::describe_profile(&p)))
            .map_err(Failure::from),
        Command::Profile {
            command:
                ProfileCommand::Current {
                    api,
                    json,
                    format,
                    output,
                },
        } => remote::current_profile(&api, json, format.as_deref(), output.as_deref())
            .map_err(Failure::from),
        Command::Export {
            profile,
            format,
            output,
            measurements,
            white,
            tone,
            luminance,
            register_colord,
        } => export(
            &profile,
            &format,
            &output,
            measurements.as_deref(),
            [white, tone, luminance],
            register_colord.as_deref(),
        ),
        Command::Bench { quick, data } => bench::run(quick, data).map_err(Failure::from),
        Command::Daemon {
            config,
            state_dir,
            socket,
            tcp,
            time_scale,
        } => daemon(config.as_deref(), state_dir, socket, tcp, time_scale),
        Command::Status { api, json } => remote::status(&api, json).map_err(Failure::from),
        Command::Job { command, api } => match command {
            JobCommand::Start { kind, watch } => remote::job_start(&api, &kind, watch),
            JobCommand::Watch => remote::job_watch(&api),
            JobCommand::Cancel => remote::job_cancel(&api),
        }
        .map_err(Failure::from),
        Command::History { api, json } => remote::history(&api, json).map_err(Failure::from),
        Command::Rollback { to, api } => remote::rollback(&api, to).map_err(Failure::from),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("chromacal: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}

fn export(
    profile_path: &Path,
    format: &str,
    output: &Path,
    measurements: Option<&Path>,
    target: [Option<String>; 3],
    register_colord: Option<&str>,
) -> Result<(), Failure> {
    use chromacal::export::{ExportOptions, Format, parse_target};
    let profile = Profile::read(profile_path).map_err(Failure::from)?;
    let format = Format::parse(format).map_err(|e| Failure::from(e.to_string()))?;
    if register_colord.is_some() && !matches!(format, Format::Icc4 | Format::Icc2) {
        return Err(Failure::from(
            "--register-colord needs an ICC format (icc4 or icc2)".to_string(),
        ));
    }
    let [white, tone, luminance] = target;
    let target = parse_target(white.as_deref(), tone.as_deref(), luminance.as_deref())
        .map_err(|e| Failure::from(e.to_string()))?;
    let measurements = match measurements {
        Some(path) => Some(
            chromacal::measurement_file::read_measurements(path)
                .map_err(|e| Failure::from(e.to_string()))?,
        ),
        None => None,
    };
    let options = ExportOptions {
        target,
        measurements,
    };
    let exported = chromacal::export::export(&profile, format, &options)
        .map_err(|e| Failure::from(e.to_string()))?;
    std::fs::write(output, &exported.bytes)
        .map_err(|e| Failure::from(format!("{}: {e}", output.display())))?;
    println!(
        "wrote {} ({}, {} bytes)",
        output.display(),
        format.name(),
        exported.bytes.len()
    );
    match (&options.target, &profile.calibration, &exported.calibration) {
        (None, Some(stored), Some(_)) => println!(
            "calibration curves to {} (the profile's, measured into place): measured white ΔE00 {:.3}, tone within {:.2} % at {} levels",
            stored.curves.target.describe(),
            stored.measured_white_de00,
            100.0 * stored.measured_tone_error,
            stored.levels.len()
        ),
        (_, _, Some(k)) => println!(
            "calibration curves to {} (from the model): predicted white ΔE00 {:.3}, tone within {:.2} % at 9 levels",
            k.target.describe(),
            k.predicted_white_de00,
            100.0 * k.predicted_tone_error
        ),
        _ => {}
    }
    for note in &exported.not_carried {
        println!("not carried: {note}");
    }
    for warning in &exported.warnings {
        println!("warning: {warning}");
    }
    if let Some(device) = register_colord {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let registered = runtime
            .block_on(chromacal::export::colord::register(output, device))
            .map_err(|e| Failure {
                message: format!("colord: {e}"),
                code: COLORD_UNAVAILABLE,
            })?;
        println!(
            "colord: {} is the default profile of {} ({}{})",
            registered.profile_id,
            device,
            registered.device_object,
            if registered.device_existed {
                ""
            } else {
                ", a device chromacal created"
            }
        );
    }
    Ok(())
}

/// Exit code when an export was written but colord could not take it.
const COLORD_UNAVAILABLE: u8 = 4;

fn daemon(
    config: Option<&Path>,
    state_dir: Option<PathBuf>,
    socket: Option<PathBuf>,
    tcp: Option<String>,
    time_scale: Option<f64>,
) -> Result<(), Failure> {
    let mut loaded = load_config(config)?;
    if let Some(scale) = time_scale {
        loaded.config.daemon.simulated_time_scale = scale;
        loaded.config.daemon.check().map_err(Failure::from)?;
    }
    let options = chromacal::daemon::DaemonOptions {
        state_dir: state_dir.unwrap_or_else(default_state_dir),
        socket,
        tcp,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let result = runtime.block_on(chromacal::daemon::run(loaded, options));
    // The daemon has stopped its job and left its devices; connections still open
    // (event streams) are simply dropped.
    runtime.shutdown_timeout(std::time::Duration::from_millis(200));
    result.map_err(|e| Failure::from(e.to_string()))
}

fn calibrate(
    config: Option<&Path>,
    state_dir: Option<PathBuf>,
    resume: bool,
    realtime_scale: Option<f64>,
    json: bool,
    overrides: Overrides,
) -> Result<(), Failure> {
    let loaded = load_config(config)?;
    let options = CalibrateOptions {
        state_dir: state_dir.unwrap_or_else(default_state_dir),
        resume,
        realtime_scale,
        overrides,
    };
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} measuring [{bar:40}] {pos}/{len} patches  {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let mut on_progress = |p: &Progress| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        bar.set_message(match p.luminance {
            Some(y) => format!("{:?} Y {y:.3}", p.role).to_lowercase(),
            None => format!("{:?} {:?}", p.role, p.status).to_lowercase(),
        });
    };
    announce_display(&loaded, &options);
    let mut ask = |position: ScreenPosition| aim_prompt(&bar, position);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let outcome = runtime.block_on(calibrate_session(
        &loaded,
        &options,
        &mut on_progress,
        Some(&mut ask),
    ));
    bar.finish_and_clear();
    let outcome = outcome?;
    if json {
        println!("{}", serde_json::to_string_pretty(&outcome.profile.report)?);
    } else {
        let mut out = format!(
            "chromacal: calibrated {} with {}\n",
            outcome.display,
            outcome
                .profile
                .provenance
                .instrument
                .as_ref()
                .map_or("an instrument", |i| i.name.as_str())
        );
        out += &format!(
            "  patches measured: {}\n",
            report::budget_line(&outcome.plan.budget)
        );
        if outcome.run.extra_reads > 0 || outcome.run.unsettled > 0 {
            out += &format!(
                "  stability check: {} extra readings; {} patches never agreed (last reading kept)\n",
                outcome.run.extra_reads, outcome.run.unsettled
            );
        }
        if outcome.run.already_measured > 0 {
            out += &format!(
                "  resumed: {} patches were in the journal, {} measured now\n",
                outcome.run.already_measured, outcome.run.measured_now
            );
        }
        out += &format!(
            "  simulated instrument time {} (integration and settling), fit time {}\n\n",
            report::duration(outcome.instrument_seconds),
            report::duration(outcome.fit_seconds)
        );
        out += &report::fit_summary(&outcome.fitted.report);
        if let Some(c) = &outcome.profile.calibration {
            out += &report::calibration_summary(c);
        }
        if let Some(why) = &outcome.calibration_error {
            out += &format!("\ncalibration curves: none ({why})\n");
        }
        out += &format!("\njournal: {}\n", outcome.journal_path.display());
        match &outcome.rejection {
            None => {
                out += &format!(
                    "profile: {} (published as current)\n",
                    outcome.profile_path.display()
                )
            }
            Some(why) => {
                out += &format!(
                    "profile: {} (NOT published: {why})\n",
                    outcome.profile_path.display()
                )
            }
        }
        print!("{out}");
    }
    match outcome.rejection {
        None => Ok(()),
        Some(why) => Err(Failure {
            message: format!("the profile was not published: {why}"),
            code: NOT_PUBLISHED,
        }),
    }
}

/// Tell the user where the patches will be, for the sinks that wait for a peer.
fn announce_display(loaded: &chromacal::config::LoadedConfig, options: &CalibrateOptions) {
    let mut config = loaded.config.clone();
    options.overrides.apply(&mut config);
    if options.resume || chromacal::config::check_config(&config).is_err() {
        return; // the session reports the error, or resumes with the journal's config
    }
    match config.display.sink() {
        Sink::Web => eprintln!(
            "chromacal: open http://{}/ full-screen on the display to measure (e.g. chromium --kiosk)",
            config.display.web.address
        ),
        Sink::Resolve => eprintln!(
            "chromacal: waiting for a Resolve pattern generator to connect to {}",
            config.display.resolve.address
        ),
        Sink::Simulated | Sink::Emulator => {}
    }
}

/// Ask on the terminal to aim the instrument at `position`; Enter goes on.
fn aim_prompt(bar: &indicatif::ProgressBar, position: ScreenPosition) -> Result<(), String> {
    bar.suspend(|| {
        eprintln!(
            "chromacal: aim the instrument at the patch now shown at ({:.3}, {:.3}) (fractions of the screen's width and height from the top left), then press Enter",
            position.x, position.y
        );
        let mut line = String::new();
        match std::io::stdin().read_line(&mut line) {
            Ok(0) => Err("the terminal closed while waiting for the instrument to be aimed".into()),
            Ok(_) => Ok(()),
            Err(e) => Err(format!("cannot read the terminal: {e}")),
        }
    })
}

fn fit(
    measurements: &Path,
    output: &Path,
    config: Option<&Path>,
    laws: Option<Vec<LawArg>>,
    json: bool,
) -> Result<(), Failure> {
    let mut options = match config {
        Some(path) => load_config(Some(path))?.config.fit,
        None => FitOptions::default(),
    };
    if let Some(laws) = laws {
        options.laws = laws.into_iter().map(LawKind::from).collect();
    }
    let set = read_measurements(measurements)?;
    let started = std::time::Instant::now();
    let fitted = fit_monitor(&set, &options)?;
    let fit_seconds = started.elapsed().as_secs_f64();
    let id = output
        .file_stem()
        .map_or_else(|| "profile".into(), |s| s.to_string_lossy().into_owned());
    let profile = Profile {
        schema_version: SCHEMA_VERSION,
        id,
        created: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
        units: set.units,
        model: fitted.model.clone(),
        provenance: Provenance {
            source: measurements.display().to_string(),
            display: set.display.clone(),
            instrument: set.instrument.clone(),
            config_digest: None,
            program: format!("chromacal {}", env!("CARGO_PKG_VERSION")),
        },
        report: fitted.report.clone(),
        calibration: None,
    };
    profile.write(output)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&fitted.report)?);
    } else {
        let c = &fitted.report.counts;
        print!(
            "chromacal: fitted {} ({} readings, {} usable; {} in the fit's budgeted kinds, {} held out, {} uniformity; XYZ {})\n  fit time {}\n\n{}\nprofile: {}\n",
            measurements.display(),
            c.readings,
            c.usable,
            c.budget_readings,
            c.held_out,
            c.uniformity,
            set.units,
            report::duration(fit_seconds),
            report::fit_summary(&fitted.report),
            output.display()
        );
    }
    Ok(())
}

fn check(
    profile_path: &Path,
    measurements: &Path,
    json: bool,
    worst: usize,
) -> Result<(), Failure> {
    let profile = Profile::read(profile_path)?;
    let set = read_measurements(measurements)?;
    let mut model = profile.model.clone();
    let mut note = None;
    if profile.units != set.units {
        // Compare like with like: bring the profile to the measurements' scale.
        if set.units == Units::Relative {
            let y = model.white().y;
            if y > 0.0 {
                model = model.scaled(100.0 / y);
            }
        } else {
            return Err(Failure::from(
                "the profile is relative (white Y = 100) but the measurements are in cd/m²; \
                 fit the profile from measurements in cd/m², or check against relative ones",
            ));
        }
        note = Some(
            "the profile is in cd/m² and the measurements relative: the profile was scaled to white Y = 100",
        );
    }
    let evaluation = evaluate(
        &model,
        set.measurements
            .iter()
            .filter_map(|m| Some((m, m.usable_xyz()?))),
    );
    if json {
        #[derive(serde::Serialize)]
        struct Output<'a> {
            profile: String,
            measurements: String,
            note: Option<&'a str>,
            #[serde(flatten)]
            evaluation: &'a chromacal::fit::validate::Evaluation,
        }
        println!(
            "{}",
            serde_json::to_string_pretty(&Output {
                profile: profile_path.display().to_string(),
                measurements: measurements.display().to_string(),
                note,
                evaluation: &evaluation,
            })?
        );
    } else {
        println!(
            "chromacal: {} against {} ({} usable readings of {})",
            profile_path.display(),
            measurements.display(),
            evaluation.patches.len(),
            set.measurements.len()
        );
        if let Some(n) = note {
            println!("  note: {n}");
        }
        print!("{}", report::check_summary(&evaluation, worst));
    }
    Ok(())
}

fn measure(spec: &str, count: usize, timing_scale: f64, json: bool) -> Result<(), Failure> {
    let (kind, port) = parse_instrument(spec)?;
    let options = DriverOptions {
        timing_scale,
        ..DriverOptions::default()
    };
    let mut instrument = kind.open(&port, options)?;
    let info = instrument.info().clone();
    if !json {
        println!(
            "{} (serial {}) on {port}",
            info.name,
            info.serial.as_deref().unwrap_or("unknown")
        );
    }
    let mut readings = Vec::new();
    for _ in 0..count.max(1) {
        let reading = instrument.measure()?;
        if !json {
            let status = format!("{:?}", reading.status).to_lowercase();
            match (reading.xyz, reading.luminance()) {
                (Some(xyz), _) => {
                    let xyy = xyz_to_xyy(&xyz, [0.0, 0.0]);
                    println!(
                        "  XYZ {:.4} {:.4} {:.4}  x {:.4} y {:.4}  [{status}, code {}]",
                        xyz.x,
                        xyz.y,
                        xyz.z,
                        xyy.x,
                        xyy.y,
                        reading.device_code.as_deref().unwrap_or("-")
                    )
                }
                (None, Some(y)) => println!(
                    "  Y {y:.4} cd/m²  [{status}, code {}]",
                    reading.device_code.as_deref().unwrap_or("-")
                ),
                (None, None) => println!(
                    "  no value  [{status}, code {}]",
                    reading.device_code.as_deref().unwrap_or("-")
                ),
            }
        }
        readings.push(reading);
    }
    instrument.close();
    if json {
        println!("{}", serde_json::to_string_pretty(&readings)?);
    }
    Ok(())
}

fn instruments(extra: &[String], json: bool) -> Result<(), Failure> {
    use chromacal::instrument::scan::{PortFinding, candidate_ports, scan};
    let ports = candidate_ports(extra);
    let findings = scan(&ports);
    if json {
        let rows: Vec<serde_json::Value> = findings
            .iter()
            .map(|(port, f)| match f {
                PortFinding::Found { kind, identity } => serde_json::json!({"port": port, "instrument": kind.name(), "identity": identity}),
                PortFinding::Silent => serde_json::json!({"port": port, "instrument": null}),
                PortFinding::Unopenable(why) => serde_json::json!({"port": port, "error": why}),
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    if findings.is_empty() {
        println!("no serial ports found (pseudo-terminals must be named with --port)");
    }
    for (port, finding) in findings {
        match finding {
            PortFinding::Found { kind, identity } => {
                println!("{port}: {identity}  (--instrument {kind}:{port})")
            }
            PortFinding::Silent => println!("{port}: no known instrument answered"),
            PortFinding::Unopenable(why) => println!("{port}: cannot open: {why}"),
        }
    }
    Ok(())
}

#[derive(serde::Serialize)]
struct SpectrumResult {
    sample: String,
    xyz: [f64; 3],
    x: f64,
    y: f64,
    u_prime: f64,
    v_prime: f64,
    lab: [f64; 3],
    luv: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    photopic_cd_m2: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scotopic_cd_m2: Option<f64>,
}

fn spectrum(
    file: &Path,
    reflectance: bool,
    relative: bool,
    illuminant: Illuminant,
    white_y: Option<f64>,
    observer: &str,
    json: bool,
) -> Result<(), Failure> {
    let observer = if observer == "10" {
        Observer::Cie1964TenDegree
    } else {
        Observer::Cie1931TwoDegree
    };
    let table = NumericTable::read(file)?;
    if !table.header[0].eq_ignore_ascii_case("wavelength_nm") {
        return Err(Failure::from(format!(
            "{}: the first column must be wavelength_nm, not '{}'",
            file.display(),
            table.header[0]
        )));
    }
    if table.header.len() < 2 {
        return Err(Failure::from(format!(
            "{}: no sample columns",
            file.display()
        )));
    }
    let wavelengths = table.column(0);
    let mut results = Vec::new();
    let mut absolute = Vec::new();
    for (k, name) in table.header.iter().enumerate().skip(1) {
        let sample = Spectrum::new(wavelengths.clone(), table.column(k))
            .map_err(|e| Failure::from(format!("{}, column '{name}': {e}", file.display())))?;
        let in_column = |e: chromacal::color::spectrum::SpectrumError| {
            Failure::from(format!("{}, column '{name}': {e}", file.display()))
        };
        let xyz = if reflectance {
            reflectance_to_xyz(&sample, illuminant, observer).map_err(in_column)?
        } else if relative {
            emission_to_relative_xyz(&sample, observer).map_err(in_column)?
        } else {
            emission_to_xyz(&sample, observer).map_err(in_column)?
        };
        let luminances = if !reflectance && !relative {
            Some((
                photopic_luminance(&sample).map_err(in_column)?,
                scotopic_luminance(&sample).ok(),
            ))
        } else {
            None
        };
        absolute.push(luminances);
        results.push((name.clone(), xyz));
    }
    // The reference white for L*a*b* and L*u*v*.
    let white_xyz = white_point(illuminant, observer)?;
    let white_luminance = if reflectance || relative {
        100.0
    } else {
        white_y.unwrap_or_else(|| results.iter().map(|r| r.1.y).fold(0.0, f64::max))
    };
    let white: Xyz = white_xyz * (white_luminance / 100.0);
    let out: Vec<SpectrumResult> = results
        .iter()
        .zip(&absolute)
        .map(|((name, xyz), lum)| {
            let xyy = xyz_to_xyy(xyz, [0.0, 0.0]);
            let uv = xyz_to_uv_prime(xyz, chromacal::color::UvPrime { u: 0.0, v: 0.0 });
            let lab = xyz_to_lab(xyz, &white);
            let luv = xyz_to_luv(xyz, &white);
            SpectrumResult {
                sample: name.clone(),
                xyz: [xyz.x, xyz.y, xyz.z],
                x: xyy.x,
                y: xyy.y,
                u_prime: uv.u,
                v_prime: uv.v,
                lab: [lab.l, lab.a, lab.b],
                luv: [luv.l, luv.u, luv.v],
                photopic_cd_m2: lum.map(|l| l.0),
                scotopic_cd_m2: lum.and_then(|l| l.1),
            }
        })
        .collect();
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let mode = if reflectance {
        format!("reflectance under {illuminant:?}, Y of the illuminant = 100")
    } else if relative {
        "emission, each sample scaled to Y = 100".into()
    } else {
        "emission, absolute (Y in cd/m² for radiance in W·sr⁻¹·m⁻²·nm⁻¹)".into()
    };
    println!(
        "{} ({mode}; {} observer; L*a*b*/L*u*v* against {illuminant:?} white, Y = {white_luminance:.4})",
        file.display(),
        observer
    );
    let rows: Vec<Vec<String>> = out
        .iter()
        .map(|r| {
            vec![
                r.sample.clone(),
                format!("{:.4}", r.xyz[0]),
                format!("{:.4}", r.xyz[1]),
                format!("{:.4}", r.xyz[2]),
                format!("{:.4}", r.x),
                format!("{:.4}", r.y),
                format!("{:.4}", r.u_prime),
                format!("{:.4}", r.v_prime),
                format!("{:.2}", r.lab[0]),
                format!("{:.2}", r.lab[1]),
                format!("{:.2}", r.lab[2]),
                format!("{:.2}", r.luv[1]),
                format!("{:.2}", r.luv[2]),
            ]
        })
        .collect();
    print!(
        "{}",
        report::table(
            &[
                "sample", "X", "Y", "Z", "x", "y", "u′", "v′", "L*", "a*", "b*", "u*", "v*"
            ],
            &rows
        )
    );
    if out.iter().any(|r| r.scotopic_cd_m2.is_some()) {
        for r in &out {
            if let Some(s) = r.scotopic_cd_m2 {
                println!("  {}: scotopic luminance {s:.4} scotopic cd/m²", r.sample);
            }
        }
    }
    Ok(())
}
