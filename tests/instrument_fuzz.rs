//! Every driver against its emulator through 1,000 seeded random fault schedules each
//! (link faults from the first byte, device faults, random patches): no panic, no wait
//! past the protocol's timeouts, and every run ends in a reading or a clean error.
//! A reading in range must be the right one.

use chromacal_instruments::devices::DeviceKind;
use chromacal_instruments::driver::DriverOptions;
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::memory::MemoryTransport;
use chromacal_instruments::{InstrumentError, ReadingStatus};
use rand::{Rng, SeedableRng};

mod common;
use common::{meter, true_xyz, virtual_monitor};

const SCHEDULES: u64 = 1000;
const MEASUREMENTS: usize = 3;

/// Longest a connection or a measurement may take on virtual time.
fn bound_s(kind: DeviceKind) -> f64 {
    let longest = match kind {
        DeviceKind::Pr670 => 300.0,
        DeviceKind::Pr650 | DeviceKind::Pr655 => 30.0,
        DeviceKind::Specbos1211 => 25.0,
        _ => 15.0,
    };
    let o = DriverOptions::default();
    // Every attempt (and every reconnection's new connect) may wait out the longest
    // timeout of the protocol, with a drain after it.
    (o.attempts * (o.reconnects + 1)) as f64 * (longest + 10.0) * 3.0
}

#[test]
fn a_thousand_fault_schedules_per_instrument() {
    let mut outcomes = std::collections::BTreeMap::new();
    for kind in DeviceKind::ALL {
        for seed in 0..SCHEDULES {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed * 31 + kind as u64);
            let faults = FaultSpec {
                no_reply: rng.random_range(0.0..0.06),
                late: rng.random_range(0.0..0.06),
                garbage: rng.random_range(0.0..0.06),
                truncated: rng.random_range(0.0..0.06),
                vanish: rng.random_range(0.0..0.02),
                low_light: rng.random_range(0.0..0.2),
                overload: rng.random_range(0.0..0.2),
                sync_failure: rng.random_range(0.0..0.3),
                seed,
                ..Default::default()
            };
            let drive = [rng.random(), rng.random(), rng.random()];
            let monitor = virtual_monitor("crt", drive);
            let truth = true_xyz(&monitor);
            let transport = MemoryTransport::new(
                kind.emulator(meter(&monitor, &faults)),
                faults,
                kind.settings().baud,
            );
            let clock = transport.controls();
            let tally = outcomes.entry(kind.name()).or_insert([0usize; 4]);
            let started = clock.now();
            let mut instrument = match kind.connect(Box::new(transport), DriverOptions::default()) {
                Ok(i) => i,
                Err(e) => {
                    assert!(
                        clock.now() - started <= bound_s(kind),
                        "{kind} seed {seed}: connecting took {} s",
                        clock.now() - started
                    );
                    assert!(!e.to_string().is_empty());
                    tally[3] += 1;
                    continue;
                }
            };
            for _ in 0..MEASUREMENTS {
                let before = clock.now();
                let result = instrument.measure();
                let took = clock.now() - before;
                assert!(
                    took <= bound_s(kind),
                    "{kind} seed {seed}: a measurement took {took} s"
                );
                match result {
                    Ok(r) => match r.status {
                        ReadingStatus::Ok => {
                            let y = r.luminance().unwrap();
                            assert!(
                                (y - truth.y).abs() <= 0.03 * truth.y + 0.01,
                                "{kind} seed {seed}: a wrong reading passed for a good one: Y {y} vs {}",
                                truth.y
                            );
                            tally[0] += 1;
                        }
                        ReadingStatus::BelowRange | ReadingStatus::Overload => {
                            assert!(r.device_code.is_some());
                            tally[1] += 1;
                        }
                    },
                    Err(e) => {
                        assert!(!e.to_string().is_empty());
                        tally[2] += 1;
                        if matches!(e, InstrumentError::Disconnected(_)) {
                            break;
                        }
                    }
                }
            }
        }
    }
    for (kind, [good, flagged, failed, unconnected]) in &outcomes {
        eprintln!(
            "{kind}: {good} good, {flagged} flagged, {failed} clean errors, {unconnected} not connected"
        );
        assert!(
            *good >= 500,
            "{kind}: too few good readings for the schedules to mean much"
        );
    }
}
