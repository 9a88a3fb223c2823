//! `chromacal emulate`: an emulated serial instrument on a pseudo-terminal, measuring a
//! virtual monitor whose screen other processes set through a socket, or that shows
//! what chromacal's Resolve server sends it (`--resolve`).

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

use chromacal::config::load_config;
use chromacal_display::resolve::{ClientOptions, run_client};
use chromacal_instruments::devices::{DeviceKind, EmulatorQuirks};
use chromacal_instruments::emulator::Meter;
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::pty::{PtyEmulator, PtyOptions};
use chromacal_instruments::emulator::screen::serve_screen;
use chromacal_instruments::simulated::SimulatedInstrumentSpec;
use chromacal_sim::clock::VirtualClock;
use chromacal_sim::monitor::VirtualMonitor;

use chromacal_display::wayland::capture::watch_wayland_output;
use chromacal_display::x11::OutputSelector;
use chromacal_display::x11::capture::watch_output;

use super::shared::Failure;

/// `X,Y` in [0, 1].
fn parse_aim(text: &str) -> Result<(f64, f64), String> {
    let bad = || format!("--aim wants X,Y as fractions of the output, e.g. 0.5,0.5, not '{text}'");
    let (x, y) = text.split_once(',').ok_or_else(bad)?;
    let (x, y): (f64, f64) = (
        x.trim().parse().map_err(|_| bad())?,
        y.trim().parse().map_err(|_| bad())?,
    );
    if !((0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y)) {
        return Err(bad());
    }
    Ok((x, y))
}

/// Emulate a serial instrument on a pseudo-terminal: prints the device path to open
/// and the screen socket to show patches on, then answers as the instrument would,
/// measuring a virtual monitor, until stopped.
#[derive(clap::Args)]
pub struct EmulateArgs {
    /// pr650, pr655, pr670, k10a, specbos1211, ls100, ls110, cs100a, colorcal2.
    #[arg(long)]
    pub instrument: String,
    /// Virtual monitor preset (crt, lcd, hdr-oled, hdr-lcd) [default: the config's monitor].
    #[arg(long)]
    pub monitor: Option<String>,
    /// Take [monitor] and [instrument.simulated] (noise, seed) from this config
    /// [default: the built-in one; an emulator is a test device, so no user or system
    /// config is looked for].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Faults to inject, e.g. "no_reply=0.05,garbage=0.02,low_light=0.1,seed=7"
    /// (for tests; hidden from --help).
    #[arg(long, default_value = "", hide = true)]
    pub faults: String,
    /// Record the session, byte for byte, to this transcript file (for fixtures;
    /// hidden from --help).
    #[arg(long, hide = true)]
    pub record: Option<PathBuf>,
    /// Real seconds per instrument second (0.01 answers a hundred times faster).
    #[arg(long, default_value_t = 1.0, value_parser = super::shared::positive_number)]
    pub time_scale: f64,
    /// Where to put the screen socket [default: a file in the temporary directory].
    #[arg(long)]
    pub screen: Option<PathBuf>,
    /// Emulate a Minolta meter that was switched on without F held (not in remote
    /// mode; for tests, hidden from --help).
    #[arg(long, hide = true)]
    pub not_remote: bool,
    /// Also be a Resolve pattern generator: connect to chromacal's Resolve server at
    /// ADDR and show what it sends on the virtual monitor (reconnecting when the
    /// connection drops).
    #[arg(long, value_name = "ADDR")]
    pub resolve: Option<String>,
    /// A fault for tests: drop the generator's connection once, after N patterns
    /// (hidden from --help).
    #[arg(long, value_name = "N", requires = "resolve", hide = true)]
    pub resolve_drop_after: Option<usize>,
    /// The generator reads video levels (16–235) rather than full range.
    #[arg(long, requires = "resolve")]
    pub video_levels: bool,
    /// Look at this X display's screen instead: before each reading the virtual monitor
    /// shows the pixels under the aim point, through the output's CRTC gamma ramp as a
    /// video card sends them (e.g. :1, an X server showing `--display window`: Xorg with
    /// the dummy driver keeps the ramp; Xvfb's reads back straight whatever is set).
    #[arg(long, value_name = "DISPLAY", conflicts_with = "wayland_display")]
    pub x_display: Option<String>,
    /// Look at this Wayland display's screen instead (wayland-1 or a socket path): the
    /// pixels under the aim point, copied through wlr-screencopy (wlroots compositors),
    /// sent to the virtual monitor as they are (no gamma ramp can be read back there).
    #[arg(long, value_name = "NAME")]
    pub wayland_display: Option<String>,
    /// An emulated colorimeter (k10a, cs100a, colorcal2) reads exact CIE XYZ instead of
    /// reading through its filters (for tests; hidden from --help).
    #[arg(long, hide = true)]
    pub ideal_filters: bool,
    /// The baud rate an emulated specbos 1211 is set to [default: 115200, so that a
    /// driver has to look past the factory 921600; for tests, hidden from --help].
    #[arg(long, value_name = "BAUD", hide = true)]
    pub baud: Option<u32>,
    /// Also emulate this instrument, on a pseudo-terminal of its own, aimed at the same
    /// virtual monitor (e.g. a colorimeter beside a reference spectroradiometer, for
    /// `correction make`); printed as `also KIND /dev/pts/N`.
    #[arg(long, value_name = "KIND")]
    pub also: Vec<String>,
    /// The output looked at, by RandR or wl_output name [default: the primary, or
    /// the first Wayland output].
    #[arg(long)]
    pub output: Option<String>,
    /// Where the instrument is aimed, as fractions of the output's width and height.
    #[arg(long, value_name = "X,Y", default_value = "0.5,0.5")]
    pub aim: String,
}

pub fn run(args: EmulateArgs) -> Result<(), Failure> {
    emulate(args).map_err(Failure::from)
}

fn emulate(args: EmulateArgs) -> Result<(), String> {
    let kind = DeviceKind::parse(&args.instrument)?;
    let loaded = load_config(args.config.as_deref()).map_err(|e| e.to_string())?;
    let mut monitor_config = loaded.config.monitor.clone();
    if let Some(preset) = &args.monitor {
        monitor_config.preset = Some(preset.clone());
    }
    let spec = monitor_config
        .resolve(&loaded.base_dir)
        .map_err(|e| e.to_string())?
        .in_mode(loaded.config.plan.signal);
    let faults = FaultSpec::parse(&args.faults)?;
    let clock = Arc::new(VirtualClock::new(None));
    let monitor = Arc::new(Mutex::new(
        VirtualMonitor::new(spec, clock).map_err(|e| e.to_string())?,
    ));
    let mut simulated = loaded
        .config
        .instrument
        .simulated
        .clone()
        .unwrap_or_default();
    let base_spec = simulated.clone();
    // A colorimeter reads through its filters, as the real one does.
    let through_filters = |kind: DeviceKind, spec: &mut SimulatedInstrumentSpec| {
        if let Some(model) = kind.filter_model().filter(|_| !args.ideal_filters) {
            spec.kind = chromacal_instruments::simulated::SimulatedKind::Tristimulus;
            spec.filters = spec.filters.or(Some(model));
        }
    };
    through_filters(kind, &mut simulated);
    let also: Vec<DeviceKind> = args
        .also
        .iter()
        .map(|k| DeviceKind::parse(k))
        .collect::<Result<_, _>>()?;
    let mut others = Vec::new();
    for (n, other) in also.iter().enumerate() {
        let mut spec = base_spec.clone();
        through_filters(*other, &mut spec);
        // Its own noise: another seed.
        spec.seed = spec.seed.wrapping_add(1 + n as u64);
        let meter = Meter::new(monitor.clone(), spec, Default::default(), faults.seed);
        let emulator = PtyEmulator::spawn(
            other.emulator(meter),
            PtyOptions {
                time_scale: args.time_scale,
                ..PtyOptions::default()
            },
        )
        .map_err(|e| format!("cannot open a pseudo-terminal: {e}"))?;
        others.push((*other, emulator));
    }
    let mut meter = Meter::new(monitor.clone(), simulated, faults.device(), faults.seed);
    let aim = parse_aim(&args.aim)?;
    let selector = args
        .output
        .as_deref()
        .map(OutputSelector::parse)
        .unwrap_or_default();
    if let Some(display) = &args.x_display {
        let mut watch = watch_output(Some(display), &selector, aim).map_err(|e| e.to_string())?;
        meter = meter.with_screen_source(Box::new(move || watch().map_err(|e| e.to_string())));
    } else if let Some(display) = &args.wayland_display {
        let mut watch =
            watch_wayland_output(Some(display), &selector, aim).map_err(|e| e.to_string())?;
        meter = meter.with_screen_source(Box::new(move || watch().map_err(|e| e.to_string())));
    } else if args.output.is_some() || args.aim != "0.5,0.5" {
        return Err(
            "--output and --aim are for the screen of --x-display or --wayland-display".into(),
        );
    }
    let quirks = EmulatorQuirks {
        not_remote: args.not_remote,
        baud: args.baud,
        time_scale: args.time_scale,
    };
    let device = kind.emulator_with(meter, quirks)?;
    let screen = args.screen.unwrap_or_else(|| {
        std::env::temp_dir().join(format!(
            "chromacal-emulate-{}-{}.sock",
            kind,
            std::process::id()
        ))
    });
    let screen =
        serve_screen(&screen, monitor.clone()).map_err(|e| format!("{}: {e}", screen.display()))?;
    remove_when_stopped(screen.clone());
    if let Some(address) = &args.resolve {
        let options = ClientOptions {
            settle_s: loaded.config.display.settle_s,
            video_levels: args.video_levels,
            drop_after: args.resolve_drop_after,
            ..ClientOptions::default()
        };
        let address = address.clone();
        let stop = Arc::new(AtomicBool::new(false));
        std::thread::spawn(move || run_client(&address, monitor, options, stop));
    }
    let emulator = PtyEmulator::spawn(
        device,
        PtyOptions {
            time_scale: args.time_scale,
            faults,
            record: args.record,
        },
    )
    .map_err(|e| format!("cannot open a pseudo-terminal: {e}"))?;
    // Written without panicking: whoever started us may stop reading after the lines
    // it needs.
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "device {}", emulator.path());
    let _ = writeln!(out, "screen {}", screen.display());
    if let Some(address) = &args.resolve {
        let _ = writeln!(out, "resolve {address}");
    }
    for (other, emulator) in &others {
        let _ = writeln!(out, "also {other} {}", emulator.path());
    }
    let _ = out.flush();
    drop(out);
    emulator.wait();
    let _ = std::fs::remove_file(&screen);
    Err(format!("the emulated {kind} vanished (an injected fault)"))
}

/// On SIGTERM, SIGINT or SIGHUP, remove the screen socket and exit 0, so that a
/// stopped emulator leaves nothing behind in the temporary directory. (SIGKILL cannot
/// be caught; a socket left by one is replaced when its path is bound again.)
///
/// The handlers are in place when this returns (before the emulator says where it
/// is), so a stop that comes at once is caught too.
fn remove_when_stopped(socket: PathBuf) {
    use tokio::signal::unix::{SignalKind, signal};
    let Ok(runtime) = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    else {
        return;
    };
    let handlers = {
        let _context = runtime.enter();
        (
            signal(SignalKind::terminate()),
            signal(SignalKind::interrupt()),
            signal(SignalKind::hangup()),
        )
    };
    let (Ok(mut term), Ok(mut interrupt), Ok(mut hangup)) = handlers else {
        return;
    };
    std::thread::spawn(move || {
        runtime.block_on(async move {
            tokio::select! {
                _ = term.recv() => {}
                _ = interrupt.recv() => {}
                _ = hangup.recv() => {}
            }
            let _ = std::fs::remove_file(&socket);
            std::process::exit(0);
        });
    });
}
