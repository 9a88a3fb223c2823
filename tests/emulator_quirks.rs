//! The device quirks the emulators reproduce (`../shared/PROTOCOLS.md`), and what the
//! drivers make of them.

use chromacal_instruments::devices::DeviceKind;
use chromacal_instruments::driver::DriverOptions;
use chromacal_instruments::emulator::faults::FaultSpec;
use chromacal_instruments::emulator::memory::MemoryTransport;
use chromacal_instruments::emulator::{DeviceModel, Meter};
use chromacal_instruments::transport::Transport;
use chromacal_instruments::{klein, minolta, pr6xx, pr650};

mod common;
use common::{meter, virtual_monitor};

fn a_meter() -> Meter {
    meter(
        &virtual_monitor("crt", [1.0, 1.0, 1.0]),
        &FaultSpec::default(),
    )
}

/// Everything the device says within `seconds` after `bytes`.
fn exchange(t: &mut MemoryTransport, bytes: &[u8], seconds: f64) -> Vec<u8> {
    t.write(bytes).unwrap();
    let mut out = Vec::new();
    let end = t.now() + seconds;
    while t.now() < end {
        match t.read(end - t.now()) {
            Ok(b) => out.extend(b),
            Err(_) => break,
        }
    }
    out
}

fn device(model: Box<dyn DeviceModel>) -> MemoryTransport {
    MemoryTransport::new(model, FaultSpec::default(), 9600)
}

#[test]
fn the_pr670_answers_photo_only_once_until_q() {
    let mut t = device(Box::new(pr6xx::emulator::Pr6xxEmulator::new(
        pr6xx::protocol::Model::Pr670,
        a_meter(),
    )));
    assert_eq!(exchange(&mut t, b"PHOTO", 1.0), b" REMOTE MODE");
    assert_eq!(
        exchange(&mut t, b"PHOTO", 1.0),
        b"",
        "a second PHOTO is ignored"
    );
    assert_eq!(exchange(&mut t, b"Q", 1.0), b"");
    assert_eq!(exchange(&mut t, b"PHOTO", 1.0), b" REMOTE MODE");
    // Commands at any pace, ended by CR, LF or CR LF; the status has 5 digits.
    assert_eq!(exchange(&mut t, b"S", 0.01), b"");
    assert_eq!(exchange(&mut t, b"U1\r\n", 1.0), b"00000\r\n");
    let d111 = exchange(&mut t, b"D111\n", 1.0);
    assert_eq!(d111, b"00000,PR-670\r\n");
    // The PR-670's spectrum has 201 rows and no spaces inside rows.
    let m5 = String::from_utf8(exchange(&mut t, b"M5\r", 30.0)).unwrap();
    let rows: Vec<&str> = m5.split("\r\n").filter(|l| !l.is_empty()).collect();
    assert_eq!(rows.len(), 202);
    assert!(rows[1].starts_with("380,") && rows[201].starts_with("780,"));
    assert!(rows.iter().all(|r| !r.contains(' ')));
}

#[test]
fn the_pr655_spectral_rows_are_16_bytes_as_ptb_cuts_them() {
    let mut t = device(Box::new(pr6xx::emulator::Pr6xxEmulator::new(
        pr6xx::protocol::Model::Pr655,
        a_meter(),
    )));
    exchange(&mut t, b"PHOTO", 1.0);
    let m5 = String::from_utf8(exchange(&mut t, b"M5\r", 30.0)).unwrap();
    let rows: Vec<&str> = m5.split_inclusive("\r\n").skip(1).collect();
    assert_eq!(rows.len(), 101);
    assert!(rows.iter().all(|r| r.len() == 16), "{:?}", rows[0]);
}

#[test]
fn the_pr650_is_silent_unless_addressed_soon_after_power_up() {
    let mut t = device(Box::new(pr650::emulator::Pr650Emulator::new(
        a_meter(),
        5.0,
    )));
    assert_eq!(exchange(&mut t, b"b3\n", 1.0), b"000\r\n");
    let mut late = device(Box::new(pr650::emulator::Pr650Emulator::new(
        a_meter(),
        5.0,
    )));
    late.sleep(6.0);
    assert_eq!(exchange(&mut late, b"b3\n", 2.0), b"");
    assert_eq!(exchange(&mut late, b"b3\n", 2.0), b"", "and stays silent");
    // The driver says what to do about it.
    let mut late = device(Box::new(pr650::emulator::Pr650Emulator::new(
        a_meter(),
        5.0,
    )));
    late.sleep(6.0);
    let err = DeviceKind::Pr650.connect(
        Box::new(late),
        DriverOptions {
            attempts: 1,
            ..Default::default()
        },
    );
    assert!(
        err.err()
            .unwrap()
            .to_string()
            .contains("switch it off and on")
    );
    // The spectrum rows are 17 bytes.
    let m0 = exchange(&mut t, b"m0\n", 30.0);
    assert_eq!(m0, b"000\r\n");
    let d5 = String::from_utf8(exchange(&mut t, b"d5\n", 2.0)).unwrap();
    let rows: Vec<&str> = d5.split_inclusive("\r\n").skip(2).collect();
    assert_eq!(rows.len(), 101);
    assert!(rows.iter().all(|r| r.len() == 17));
}

#[test]
fn the_minolta_meters_need_f_at_power_on_and_sulk_after_a_dark_first_reading() {
    use minolta::emulator::MinoltaEmulator;
    use minolta::protocol::Model;
    let mut not_remote = device(Box::new(MinoltaEmulator::new(
        Model::Ls100,
        a_meter(),
        false,
    )));
    assert_eq!(exchange(&mut not_remote, b"MDS,04\r\n", 1.0), b"");
    let err = DeviceKind::Ls100.connect(
        Box::new(not_remote),
        DriverOptions {
            attempts: 1,
            ..Default::default()
        },
    );
    assert!(err.err().unwrap().to_string().contains("F held"));

    let dark = meter(
        &virtual_monitor("crt", [0.0, 0.0, 0.0]),
        &FaultSpec::default(),
    );
    let mut t = device(Box::new(MinoltaEmulator::new(Model::Ls100, dark, true)));
    assert_eq!(exchange(&mut t, b"MDS,04\r\n", 1.0), b"OK00\r\n");
    assert_eq!(
        exchange(&mut t, b"MES\r\n", 2.0),
        b"",
        "sulks on a dark first reading"
    );
    assert_eq!(
        exchange(&mut t, b"MDS,04\r\n", 1.0),
        b"",
        "and stays silent"
    );

    // The CS-100A's reply is 28 bytes.
    let mut cs = device(Box::new(MinoltaEmulator::new(
        Model::Cs100a,
        a_meter(),
        true,
    )));
    let reply = exchange(&mut cs, b"MES\r\n", 2.0);
    assert_eq!(reply.len(), 28, "{}", String::from_utf8_lossy(&reply));
}

#[test]
fn the_klein_streams_until_n5_and_frames_every_reply() {
    let mut t = device(Box::new(klein::emulator::K10Emulator::new(a_meter())));
    let p0 = exchange(&mut t, b"P0\r", 1.0);
    assert_eq!(p0.len(), 21);
    assert_eq!(&p0[p0.len() - 3..], b"<0>");
    assert_eq!(exchange(&mut t, b"D7\r", 1.0).len(), 1925);
    let d1 = exchange(&mut t, b"D1\r", 0.5);
    assert_eq!(d1, b"D1");
    assert_eq!(exchange(&mut t, &[1, b'\r'], 1.0).len(), 131);
    // Streaming: 96-byte packets, 8 a second, until N5.
    let stream = exchange(&mut t, b"T2\r", 1.0);
    assert_eq!(stream.len(), 96 * 8);
    assert_eq!(&stream[0..1], b"T");
    assert_eq!(stream[3], b'2');
    let n5 = exchange(&mut t, b"N5\r", 1.0);
    assert_eq!(&n5[..2], b"N5", "N5 stops the stream and answers");
    assert_eq!(exchange(&mut t, b"", 1.0), b"", "and the stream is over");
}

/// ArgyllCMS's generic serial scan (PROTOCOLS.md §7, step 0), byte for byte over a
/// real pseudo-terminal: `;` alone must get no reply (an echo would pass for a
/// Lumagen), `D024` CR LF a reply beginning `D4` (the calibration list, then `<0>`),
/// and only then `P0` names the model.
#[test]
fn the_klein_answers_argylls_identification_probe_over_a_pty() {
    use std::io::{Read, Write};
    use std::time::{Duration, Instant};
    let emulator = common::emulate(&["--instrument", "k10a"]);
    let mut port = serialport::new(&emulator.device, 9600)
        .timeout(Duration::from_millis(100))
        .open()
        .unwrap();
    // Everything the port says within `seconds` (as the probe reads: until silence).
    let listen = |port: &mut Box<dyn serialport::SerialPort>, seconds: f64| {
        let mut out = Vec::new();
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        let mut buffer = [0u8; 4096];
        while Instant::now() < end {
            match port.read(&mut buffer) {
                Ok(n) => out.extend_from_slice(&buffer[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => panic!("{e}"),
            }
        }
        out
    };
    port.write_all(b";").unwrap();
    assert_eq!(listen(&mut port, 0.2), b"", "';' alone gets no reply");
    port.write_all(b"D024\r\n").unwrap();
    let reply = listen(&mut port, 0.5);
    assert!(reply.len() >= 3 && reply.starts_with(b"D4"), "{reply:?}");
    assert!(
        reply.ends_with(b"<0>"),
        "{:?}",
        &reply[reply.len().saturating_sub(8)..]
    );
    assert_eq!(
        reply.len(),
        2 + 96 * 20 + 3,
        "D4, the calibration list, <0>"
    );
    assert_eq!(&reply[2..13], b"Factory LCD");
    port.write_all(b"P0\r").unwrap();
    let p0 = listen(&mut port, 0.5);
    assert!(
        p0.starts_with(b"P0K-10"),
        "{:?}",
        String::from_utf8_lossy(&p0)
    );
    // The probe left the emulator in its usual state: the driver's session works.
    port.write_all(b"N5\r").unwrap();
    let n5 = listen(&mut port, 0.5);
    assert!(n5.starts_with(b"N5") && n5.ends_with(b"<0>"), "{n5:?}");
}

#[test]
fn the_specbos_talks_only_at_its_baud_and_the_driver_finds_it() {
    let mut t = MemoryTransport::new(
        DeviceKind::Specbos1211.emulator(a_meter()),
        FaultSpec::default(),
        921_600,
    );
    let wrong = exchange(&mut t, b"*idn?\r", 0.5);
    assert!(!wrong.is_empty() && !String::from_utf8_lossy(&wrong).contains("JETI"));
    t.set_baud(115_200).unwrap();
    assert!(String::from_utf8_lossy(&exchange(&mut t, b"*idn?\r", 0.5)).starts_with("JETI_SB1211"));
    assert_eq!(exchange(&mut t, b"*conf:aver 1\r", 0.5), [0x06]);
    assert_eq!(exchange(&mut t, b"*bogus\r", 0.5), [0x15]);
    assert!(
        String::from_utf8_lossy(&exchange(&mut t, b"*stat:err?\r", 0.5)).contains("Error Code: 4")
    );
    let init = exchange(&mut t, b"*init\r", 30.0);
    assert_eq!(init, [0x06, 0x07], "ACK, then BEL when done");
    let instrument = DeviceKind::Specbos1211
        .connect(
            Box::new(MemoryTransport::new(
                DeviceKind::Specbos1211.emulator(a_meter()),
                FaultSpec::default(),
                921_600,
            )),
            DriverOptions::default(),
        )
        .unwrap();
    assert!(instrument.info().name.contains("JETI_SB1211"));
}
