//! Helpers shared by the integration tests: reading the public reference data in
//! `../shared/data`, which tests use but the project does not carry.
#![allow(dead_code)]

pub mod argyll;
pub mod bus;
pub mod daemon;
pub mod images;
pub mod sway;
pub mod xserver;

use std::path::PathBuf;

use chromacal_color::Xyz;
use chromacal_instruments::{Reading, ReadingStatus};
use chromacal_model::measurement::{Measurement, MeasurementSet, Role, Units};

/// `../shared/data`, relative to the crate root.
pub fn shared_data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

pub fn shared_path(relative: &str) -> PathBuf {
    shared_data_dir().join(relative)
}

pub fn shared_text(relative: &str) -> String {
    let path = shared_path(relative);
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("the tests need {}: {e}", path.display()))
}

/// A numeric CSV with one header row.
pub fn shared_table(relative: &str) -> Vec<Vec<f64>> {
    shared_text(relative)
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect()
}

/// A file under the project's `fixtures/`.
pub fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(relative)
}

/// The simulated LCD with its own seeds and the fixed plan of 96 patches, as the
/// fixtures were recorded with it.
pub const LCD_CONFIG: &str = "[monitor]\npreset = \"lcd\"\n[instrument.simulated]\nseed = 11\n[plan]\nseed = 11\nstrategy = \"fixed\"\nbudget = 48\nverification = 24\nuniformity_grid = 5\n";

/// Path of the built `chromacal` binary.
pub fn chromacal() -> std::process::Command {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_chromacal"));
    // A config in the tester's own ~/.config must not change what the tests run.
    command.env("XDG_CONFIG_HOME", "/nonexistent/chromacal-tests-config");
    command
}

/// Run `command`; its output, or the test fails with its stderr.
pub fn succeed(command: &mut std::process::Command) -> std::process::Output {
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "{command:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Calibrate the simulated default into the state directory `state` (its profile is
/// then `state/current.toml`).
pub fn calibrate_default(state: &std::path::Path) {
    succeed(chromacal().arg("calibrate").arg("--state-dir").arg(state));
}

/// The plan the fit's tests were written against, the default until the default
/// became a sequential plan: fixed, 48 counted patches, 24 held out, a 5 × 5 grid.
/// Under `[plan]`.
pub const FIXED_PLAN_KEYS: [(&str, &str); 4] = [
    ("strategy", "\"fixed\""),
    ("budget", "48"),
    ("verification", "24"),
    ("uniformity_grid", "5"),
];

/// [`FIXED_PLAN_KEYS`] as a `[plan]` section, for a config that has none.
pub const FIXED_PLAN: &str =
    "[plan]\nstrategy = \"fixed\"\nbudget = 48\nverification = 24\nuniformity_grid = 5\n";

/// `config_text` with each key of [`FIXED_PLAN_KEYS`] it does not give itself.
pub fn with_fixed_plan(config_text: &str) -> String {
    let missing: String = FIXED_PLAN_KEYS
        .iter()
        .filter(|(key, _)| {
            !config_text.lines().any(|l| {
                l.trim_start().starts_with(&format!("{key} "))
                    || l.trim_start().starts_with(&format!("{key}="))
            })
        })
        .map(|(key, value)| format!("{key} = {value}\n"))
        .collect();
    match config_text.find("[plan]\n") {
        Some(at) => {
            let at = at + "[plan]\n".len();
            format!("{}{missing}{}", &config_text[..at], &config_text[at..])
        }
        None => format!("{config_text}\n[plan]\n{missing}"),
    }
}

/// Simulate the run a config describes (relative paths from `base_dir`), and return
/// its measurements with the virtual monitor's true model. The plan is the fixed one
/// the fit's tests were written against ([`FIXED_PLAN_KEYS`]) in what the config
/// leaves out.
pub fn simulate(
    config_text: &str,
    base_dir: &std::path::Path,
) -> (MeasurementSet, chromacal_model::MonitorModel) {
    let config_text = &with_fixed_plan(config_text);
    let config = chromacal::config::parse_config(config_text, "test config").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let journal =
        chromacal::calibrate::session::block_on(chromacal::calibrate::session::measure_simulated(
            &config,
            config_text,
            base_dir,
            &dir.path().join("journal.jsonl"),
        ))
        .unwrap()
        .unwrap();
    let rig = chromacal::calibrate::session::rig_for(&config, base_dir, None).unwrap();
    let truth = rig.monitor.lock().unwrap().true_model();
    (journal.measurement_set(), truth)
}

/// A `[monitor]` section for an ISETBio display of ../shared/data: real measured
/// primary spectra and a real measured transfer table.
pub fn isetbio_monitor(stem: &str, extra: &str) -> String {
    format!(
        "[monitor]\nprimaries_csv = \"{}\"\ntransfer_csv = \"{}\"\n{extra}\n",
        shared_path(&format!("displays/spd/{stem}_spd.csv")).display(),
        shared_path(&format!("displays/gamma/{stem}_gamma.csv")).display()
    )
}

/// The HDR runs' config: a virtual Sony OLED (ISETBio's spectra and measured table)
/// in the `hdr-oled` preset, calibrated in 10 bits to PQ with a 600 cd/m² peak at 17
/// levels; `extra` after it.
pub fn hdr_oled_pq_config(extra: &str) -> String {
    format!(
        "{}[plan]\nbit_depth = 10\n\
         [target]\nwhite = \"D65\"\ntone = \"pq\"\npeak = 600.0\nlevels = 17\n{extra}",
        isetbio_monitor("isetbio_oled_sony", "preset = \"hdr-oled\""),
    )
}

/// A virtual monitor of a preset on its own clock, showing `drive` at the centre.
pub fn virtual_monitor(
    preset: &str,
    drive: [f64; 3],
) -> std::sync::Arc<std::sync::Mutex<chromacal_sim::monitor::VirtualMonitor>> {
    let clock = std::sync::Arc::new(chromacal_sim::clock::VirtualClock::new(None));
    let mut monitor = chromacal_sim::monitor::VirtualMonitor::new(
        chromacal_sim::presets::preset(preset).unwrap(),
        clock,
    )
    .unwrap();
    monitor.show(chromacal_sim::monitor::centre_patch(drive));
    std::sync::Arc::new(std::sync::Mutex::new(monitor))
}

/// The true XYZ the monitor shows at its patch now.
pub fn true_xyz(
    monitor: &std::sync::Arc<std::sync::Mutex<chromacal_sim::monitor::VirtualMonitor>>,
) -> chromacal_color::Xyz {
    let m = monitor.lock().unwrap();
    m.xyz_at(m.patch_centre()).unwrap()
}

/// A meter on `monitor` with the default simulated instrument and these faults.
pub fn meter(
    monitor: &std::sync::Arc<std::sync::Mutex<chromacal_sim::monitor::VirtualMonitor>>,
    faults: &chromacal_instruments::emulator::faults::FaultSpec,
) -> chromacal_instruments::emulator::Meter {
    chromacal_instruments::emulator::Meter::new(
        monitor.clone(),
        chromacal_instruments::simulated::SimulatedInstrumentSpec::default(),
        faults.device(),
        faults.seed,
    )
}

/// A `chromacal emulate` process, stopped when dropped.
pub struct Emulator {
    pub child: std::process::Child,
    pub device: String,
    pub screen: String,
}

impl Drop for Emulator {
    /// SIGTERM first, as a user's Ctrl-C or systemd would: the emulator removes its
    /// screen socket then. (A SIGKILL cannot be caught, and every test that ended
    /// with one left a socket in the temporary directory: a thousand per suite.)
    fn drop(&mut self) {
        terminate(&mut self.child, std::time::Duration::from_secs(2));
    }
}

/// Stop `child` as a service manager would: SIGTERM, so that it can clean up after
/// itself, then SIGKILL if it has not gone within `grace`.
pub fn terminate(child: &mut std::process::Child, grace: std::time::Duration) {
    // Already reaped: its pid may be another process's by now.
    if let Ok(Some(_)) = child.try_wait() {
        return;
    }
    let _ = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let deadline = std::time::Instant::now() + grace;
    while std::time::Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Start `chromacal emulate` with `args`; returns once it has printed its device and
/// screen.
pub fn emulate(args: &[&str]) -> Emulator {
    use std::io::BufRead;
    let mut child = chromacal()
        .arg("emulate")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let device = lines
        .next()
        .unwrap()
        .unwrap()
        .trim_start_matches("device ")
        .to_string();
    let screen = lines
        .next()
        .unwrap()
        .unwrap()
        .trim_start_matches("screen ")
        .to_string();
    // Keep reading what else it prints, so that it never writes to a closed pipe.
    std::thread::spawn(move || lines.for_each(drop));
    Emulator {
        child,
        device,
        screen,
    }
}

/// The Brainard CRT phosphors of the `crt` preset, as a manufacturer would give them.
pub const CRT_PRIMARIES: &str =
    "[fit]\nprimaries_xy = [[0.6190, 0.3440], [0.2765, 0.6050], [0.1513, 0.0611]]\n";

/// Two profiles of the same monitor agree within the instrument's noise: white within
/// 1.5 %, each primary's chromaticity within 0.005.
pub fn assert_same_model(
    label: &str,
    profile: &chromacal::profile::Profile,
    reference: &chromacal::profile::Profile,
) {
    use chromacal_color::spaces::xyz_to_xyy;
    let (white, reference_white) = (profile.model.white(), reference.model.white());
    assert!(
        (white - reference_white).norm() / reference_white.norm() < 0.015,
        "{label}: white {white:?} vs {reference_white:?}"
    );
    for c in 0..3 {
        let a = xyz_to_xyy(&profile.model.matrix.column(c).into_owned(), [0.0, 0.0]);
        let b = xyz_to_xyy(&reference.model.matrix.column(c).into_owned(), [0.0, 0.0]);
        assert!(
            (a.x - b.x).abs() < 0.005 && (a.y - b.y).abs() < 0.005,
            "{label}: primary {c} at {a:?} vs {b:?}"
        );
    }
}

/// Calibrate with `config` on the in-process simulated rig (the `chromacal` command)
/// into `state`, and return the published profile: the reference the serial and
/// network paths are compared with.
pub fn in_process_profile(
    config: &std::path::Path,
    state: &std::path::Path,
) -> chromacal::profile::Profile {
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(config)
        .arg("--state-dir")
        .arg(state)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    chromacal::profile::Profile::read(&state.join("current.toml")).unwrap()
}

/// The journals of the calibration runs in a state directory, oldest first.
pub fn daemon_runs(state: &std::path::Path) -> Vec<PathBuf> {
    let mut runs: Vec<PathBuf> = std::fs::read_dir(state.join("runs"))
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path().join("journal.jsonl")))
                .filter(|p| p.exists())
                .collect()
        })
        .unwrap_or_default();
    runs.sort();
    runs
}

/// The journal of the newest run under a daemon's `state`, by when its first reading
/// was taken on the daemon's clock: run directories started within one second sort
/// either way by name. A run without readings counts as the oldest.
pub fn newest_run(state: &std::path::Path) -> std::path::PathBuf {
    let started = |run: &std::path::PathBuf| {
        chromacal::journal::Journal::read(run)
            .ok()
            .and_then(|(_, entries, _)| {
                entries
                    .iter()
                    .filter_map(|m| m.time_s)
                    .min_by(f64::total_cmp)
            })
            .unwrap_or(f64::NEG_INFINITY)
    };
    daemon_runs(state)
        .into_iter()
        .max_by(|a, b| started(a).total_cmp(&started(b)))
        .expect("the daemon has no runs")
}

/// Every patch the journal's plan has is in it exactly once; for a sequential plan,
/// so is each patch it added, numbered on from the seed plan without a gap.
pub fn assert_each_planned_patch_once(
    header: &chromacal::journal::JournalHeader,
    entries: &[Measurement],
) {
    let mut seen: Vec<usize> = entries.iter().map(|m| m.index).collect();
    seen.sort();
    let mut planned: Vec<usize> = header.plan.patches.iter().map(|p| p.index).collect();
    if let Some(limits) = &header.plan.sequential {
        let added = seen.len().saturating_sub(planned.len());
        assert!(added <= limits.budget, "{added} patches added");
        planned.extend(planned.len()..planned.len() + added);
    }
    assert_eq!(seen, planned, "a patch was lost or measured twice");
}

/// Fail with what installs `tool` (a path or a command) when it is missing:
/// `scripts/test.sh` installs every Debian package the tests drive.
pub fn need_tool(tool: &str, package: &str) {
    let found = std::path::Path::new(tool).exists()
        || std::process::Command::new("sh")
            .args(["-c", &format!("command -v {tool}")])
            .output()
            .is_ok_and(|o| o.status.success());
    assert!(
        found,
        "{tool} is missing: scripts/test.sh installs it (Debian package {package})"
    );
}

/// One reading of XYZ at `drive`, at the centre on black, its role read from the drive.
pub fn xyz_measurement(index: usize, drive: [f64; 3], xyz: Xyz) -> Measurement {
    Measurement {
        index,
        role: Role::from_drive(drive),
        drive,
        codes: None,
        position: Default::default(),
        background: [0.0; 3],
        window: None,
        time_s: None,
        reading: Reading {
            xyz: Some(xyz),
            spectrum: None,
            status: ReadingStatus::Ok,
            integration_s: 1.0,
            ..Default::default()
        },
    }
}

/// Absolute readings from `source`.
pub fn measurement_set(source: &str, measurements: Vec<Measurement>) -> MeasurementSet {
    MeasurementSet {
        source: source.into(),
        units: Units::Absolute,
        instrument: None,
        display: None,
        measured_at: None,
        measurements,
    }
}
