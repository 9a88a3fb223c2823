//! Recorded transcripts of each instrument's session (fixtures/transcripts/<kind>/):
//! real bytes recorded through a real pseudo-terminal by the emulator, replayed to the
//! driver with no emulator and no tty. The driver must write exactly the recorded
//! bytes and read exactly the recorded readings. CHROMACAL_WRITE_FIXTURES=1 records
//! them again.

use std::path::Path;

use chromacal_instruments::Reading;
use chromacal_instruments::devices::DeviceKind;
use chromacal_instruments::driver::DriverOptions;
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::pty::{PtyEmulator, PtyOptions};
use chromacal_instruments::transcript::{Direction, ReplayTransport, read_transcript};

mod common;
use common::{fixture, meter, virtual_monitor};

const MEASUREMENTS: usize = 2;

fn record(kind: DeviceKind, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let monitor = virtual_monitor("lcd", [0.6, 0.5, 0.4]);
    let emulator = PtyEmulator::spawn(
        kind.emulator(meter(&monitor, &FaultSpec::default())),
        PtyOptions {
            time_scale: 0.01,
            record: Some(dir.join("session.jsonl")),
            ..Default::default()
        },
    )
    .unwrap();
    let options = DriverOptions {
        timing_scale: 0.05,
        ..Default::default()
    };
    let mut instrument = kind.open(emulator.path(), options).unwrap();
    let readings: Vec<Reading> = (0..MEASUREMENTS)
        .map(|_| instrument.measure().unwrap())
        .collect();
    // Let the last reply reach the recorder before the emulator stops.
    std::thread::sleep(std::time::Duration::from_millis(50));
    drop(emulator);
    std::fs::write(
        dir.join("readings.json"),
        serde_json::to_string_pretty(&readings).unwrap(),
    )
    .unwrap();
}

#[test]
fn each_driver_replays_its_recorded_session_byte_for_byte() {
    for kind in DeviceKind::ALL {
        let dir = fixture(&format!("transcripts/{}", kind.name()));
        if std::env::var_os("CHROMACAL_WRITE_FIXTURES").is_some() {
            record(kind, &dir);
        }
        let (header, events) = read_transcript(&dir.join("session.jsonl")).unwrap();
        assert!(events.iter().any(|e| e.dir == Direction::Host), "{kind}");
        assert!(events.iter().any(|e| e.dir == Direction::Device), "{kind}");
        assert!(!header.instrument.is_empty());
        let expected: Vec<Reading> =
            serde_json::from_str(&std::fs::read_to_string(dir.join("readings.json")).unwrap())
                .unwrap();

        let replay = ReplayTransport::open(&dir.join("session.jsonl")).unwrap();
        let mut instrument = kind
            .connect(Box::new(replay), DriverOptions::default())
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        for (i, want) in expected.iter().enumerate() {
            let mut got = instrument
                .measure()
                .unwrap_or_else(|e| panic!("{kind} reading {i}: {e}"));
            // The time a measurement took is the replay's, not the recording's.
            got.integration_s = want.integration_s;
            assert_eq!(&got, want, "{kind} reading {i}");
        }
    }
}

#[test]
fn a_driver_that_writes_other_bytes_is_caught_by_the_replay() {
    let replay_path = fixture("transcripts/pr670/session.jsonl");
    // The PR-670's session replayed to the PR-650 driver diverges at once.
    let replay = ReplayTransport::open(&replay_path).unwrap();
    let err = DeviceKind::Pr650
        .connect(
            Box::new(replay),
            DriverOptions {
                attempts: 1,
                ..Default::default()
            },
        )
        .err()
        .expect("a PR-650 driver cannot follow a PR-670 session");
    assert!(err.to_string().contains("replay diverged"), "{err}");
}
