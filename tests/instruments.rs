//! Every driver against its emulator: in-process on virtual time, and over a real
//! pseudo-terminal in (scaled) real time.

use chromacal_color::Xyz;
use chromacal_instruments::devices::DeviceKind;
use chromacal_instruments::driver::{DriverOptions, SerialInstrument};
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::memory::MemoryTransport;
use chromacal_instruments::emulator::pty::{PtyEmulator, PtyOptions};
use chromacal_instruments::{Capability, Reading, ReadingStatus};

mod common;
use common::{meter, true_xyz, virtual_monitor};

/// The reading agrees with the truth: luminance for every instrument, XYZ for those
/// that give it.
fn assert_close(kind: DeviceKind, reading: &Reading, truth: &Xyz) {
    let y = reading.luminance().unwrap();
    assert!(
        (y - truth.y).abs() / truth.y < 0.02,
        "{kind}: Y {y} vs {}",
        truth.y
    );
    match kind.capability() {
        Capability::Luminance => assert!(reading.xyz.is_none(), "{kind}"),
        _ => {
            let xyz = reading.xyz.unwrap();
            assert!(
                (xyz - truth).norm() / truth.norm() < 0.02,
                "{kind}: {xyz:?} vs {truth:?}"
            );
        }
    }
}

fn memory(kind: DeviceKind, drive: [f64; 3], faults: FaultSpec) -> (SerialInstrument, Xyz) {
    let monitor = virtual_monitor("crt", drive);
    let truth = true_xyz(&monitor);
    let device = kind.emulator(meter(&monitor, &faults));
    let transport = MemoryTransport::new(device, faults, kind.settings().baud);
    let instrument = kind
        .connect(Box::new(transport), DriverOptions::default())
        .unwrap();
    (instrument, truth)
}

#[test]
fn each_driver_measures_its_emulator_in_process() {
    for kind in DeviceKind::ALL {
        let (mut instrument, truth) = memory(kind, [1.0, 1.0, 1.0], FaultSpec::default());
        let reading = instrument.measure().unwrap();
        assert_eq!(reading.status, ReadingStatus::Ok, "{kind}");
        assert_close(kind, &reading, &truth);
        assert!(instrument.info().serial.is_some());
        assert!(
            reading.device_code.is_some() && reading.raw.is_some(),
            "{kind}"
        );
        assert_eq!(instrument.info().capability, kind.capability());
    }
}

#[test]
fn each_driver_measures_its_emulator_over_a_pty() {
    for kind in DeviceKind::ALL {
        let monitor = virtual_monitor("lcd", [0.2, 0.6, 0.9]);
        let truth = true_xyz(&monitor);
        let emulator = PtyEmulator::spawn(
            kind.emulator(meter(&monitor, &FaultSpec::default())),
            PtyOptions {
                time_scale: 0.01,
                ..Default::default()
            },
        )
        .unwrap();
        let options = DriverOptions {
            timing_scale: 0.01,
            ..Default::default()
        };
        let mut instrument = kind.open(emulator.path(), options).unwrap();
        for _ in 0..2 {
            let reading = instrument.measure().unwrap();
            assert_close(kind, &reading, &truth);
        }
    }
}
