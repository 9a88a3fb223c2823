//! Each fault kind, against every driver and its emulator (in-process, on virtual
//! time): the driver's answer is the one the recovery policy states.

use std::sync::atomic::Ordering;

use chromacal_color::Xyz;
use chromacal_instruments::devices::DeviceKind;
use chromacal_instruments::driver::{DriverOptions, SerialInstrument};
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::memory::{MemoryControls, MemoryTransport};
use chromacal_instruments::{InstrumentError, Reading, ReadingStatus};

mod common;
use common::{meter, true_xyz, virtual_monitor};

struct Session {
    instrument: SerialInstrument,
    controls: MemoryControls,
    truth: Xyz,
}

/// Connect with no faults, measure once cleanly (the Minolta meters sulk after a dark
/// first reading), then switch the faults on.
fn session(kind: DeviceKind, faults: FaultSpec) -> Session {
    let monitor = virtual_monitor("crt", [0.8, 0.7, 0.6]);
    let truth = true_xyz(&monitor);
    let meter = meter(&monitor, &faults);
    let device_faults = meter.fault_switch();
    device_faults.store(false, Ordering::Relaxed);
    let transport = MemoryTransport::new(kind.emulator(meter), faults, kind.settings().baud);
    let controls = transport.controls();
    controls.set_faults(false);
    let mut instrument = kind
        .connect(Box::new(transport), DriverOptions::default())
        .unwrap();
    instrument.measure().unwrap();
    controls.set_faults(true);
    device_faults.store(true, Ordering::Relaxed);
    Session {
        instrument,
        controls,
        truth,
    }
}

/// The longest wait a measurement may take: every attempt waiting out the longest
/// timeout of the protocol, with time to resynchronise.
fn bound_s(kind: DeviceKind) -> f64 {
    let longest = match kind {
        DeviceKind::Pr670 => 300.0,
        DeviceKind::Pr650 | DeviceKind::Pr655 => 30.0,
        DeviceKind::Specbos1211 => 20.0,
        _ => 10.0,
    };
    let options = DriverOptions::default();
    options.attempts as f64 * (longest + 20.0) + options.reconnects as f64 * 5.0
}

fn assert_correct(kind: DeviceKind, reading: &Reading, truth: &Xyz) {
    assert_eq!(reading.status, ReadingStatus::Ok, "{kind}: {reading:?}");
    let y = reading.luminance().unwrap();
    assert!(
        (y - truth.y).abs() / truth.y < 0.03,
        "{kind}: Y {y} vs {}",
        truth.y
    );
}

#[test]
fn no_reply_ends_in_a_timeout_after_bounded_retries() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                no_reply: 1.0,
                ..Default::default()
            },
        );
        let start = s.controls.now();
        let result = s.instrument.measure();
        let waited = s.controls.now() - start;
        assert!(
            matches!(
                result,
                Err(InstrumentError::Timeout { .. }) | Err(InstrumentError::Protocol(_))
            ),
            "{kind}: {result:?}"
        );
        assert!(
            waited > 0.0 && waited <= bound_s(kind),
            "{kind}: waited {waited} s"
        );
    }
}

#[test]
fn late_replies_are_never_taken_for_the_next_ones() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                late: 0.1,
                seed: 3,
                ..Default::default()
            },
        );
        let mut good = 0;
        for _ in 0..12 {
            match s.instrument.measure() {
                Ok(r) => {
                    assert_correct(kind, &r, &s.truth);
                    good += 1;
                }
                Err(e) => assert!(
                    !matches!(e, InstrumentError::Disconnected(_)),
                    "{kind}: {e}"
                ),
            }
        }
        assert!(
            good >= 6,
            "{kind}: only {good} of 12 measurements got through"
        );
    }
}

#[test]
fn garbage_and_truncated_replies_are_measured_again() {
    for kind in DeviceKind::ALL {
        for faults in [
            FaultSpec {
                garbage: 0.05,
                seed: 5,
                ..Default::default()
            },
            FaultSpec {
                truncated: 0.05,
                seed: 6,
                ..Default::default()
            },
        ] {
            let mut s = session(kind, faults);
            let mut good = 0;
            for _ in 0..12 {
                match s.instrument.measure() {
                    Ok(r) => {
                        assert_correct(kind, &r, &s.truth);
                        good += 1;
                    }
                    Err(e) => assert!(
                        !matches!(e, InstrumentError::Disconnected(_)),
                        "{kind}: {e}"
                    ),
                }
            }
            assert!(
                good >= 8,
                "{kind} with {faults:?}: only {good} of 12 got through"
            );
        }
    }
}

#[test]
fn a_vanished_device_is_reconnected_then_fails_cleanly() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                vanish: 1.0,
                ..Default::default()
            },
        );
        match s.instrument.measure() {
            Err(InstrumentError::Disconnected(why)) => {
                assert!(
                    why.contains("reconnection attempts failed"),
                    "{kind}: {why}"
                )
            }
            other => panic!("{kind}: {other:?}"),
        }
    }
}

#[test]
fn low_light_is_flagged_below_range_never_a_silent_zero() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                low_light: 1.0,
                ..Default::default()
            },
        );
        let r = s.instrument.measure().unwrap();
        assert_eq!(r.status, ReadingStatus::BelowRange, "{kind}: {r:?}");
        assert!(r.device_code.is_some(), "{kind}");
    }
}

#[test]
fn overload_is_flagged_with_no_value() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                overload: 1.0,
                ..Default::default()
            },
        );
        let r = s.instrument.measure().unwrap();
        assert_eq!(r.status, ReadingStatus::Overload, "{kind}: {r:?}");
        assert!(r.xyz.is_none() && r.luminance.is_none(), "{kind}");
    }
}

#[test]
fn a_sync_failure_is_measured_again_without_sync() {
    for kind in DeviceKind::ALL {
        let mut s = session(
            kind,
            FaultSpec {
                sync_failure: 1.0,
                ..Default::default()
            },
        );
        for _ in 0..3 {
            let r = s.instrument.measure().unwrap();
            assert_correct(kind, &r, &s.truth);
        }
    }
}
