//! Emulated Klein K-10A: `P0`, `P2`, `D7` (96 slots, two in use), `D1` + slot (the
//! matrix of a slot), `N5`, `J1`–`J8`, `L0`/`L1`, `M6`, `B9`, and the `T2` flicker
//! stream (96-byte packets every 125 ms) that `N5` stops. Each reply is the echoed
//! command, the payload and `<status>`.
//!
//! It also answers the identification probe of ArgyllCMS's generic serial scan
//! (`ser_inst_type` in `spectro/inst.c`; PROTOCOLS.md §7): `;` alone, which a K-10
//! ignores, then `D024` + CR LF, which it answers with `D4`, its calibration list and
//! `<0>`. Only after that reply does the host send `P0`.

use super::protocol::{encode_ranges, encode_value};
use crate::emulator::{DeviceModel, Measured, Meter, Scheduled};
use chromacal_color::Xyz;

/// Time for an `N5` reply (the corrected XYZ updates at 8 Hz).
const N5_DELAY_S: f64 = 0.15;

pub struct K10Emulator {
    meter: Meter,
    input: Vec<u8>,
    /// Waiting for the slot byte after `D1`.
    awaiting_slot: bool,
    /// Streaming: the time of the next packet.
    stream_next: Option<f64>,
    last_xyz: Xyz,
}

fn frame(command: &[u8], payload: &[u8], status: u8) -> Vec<u8> {
    let mut out = command.to_vec();
    out.extend_from_slice(payload);
    out.extend_from_slice(&[b'<', status, b'>']);
    out
}

/// Ranges 1–6 a channel would auto-select for a value (cd/m² order of magnitude).
fn range_for(v: f64) -> u8 {
    match v.abs() {
        x if x < 0.1 => 1,
        x if x < 1.0 => 2,
        x if x < 10.0 => 3,
        x if x < 100.0 => 4,
        x if x < 1000.0 => 5,
        _ => 6,
    }
}

impl K10Emulator {
    pub fn new(meter: Meter) -> Self {
        K10Emulator {
            meter,
            input: Vec::new(),
            awaiting_slot: false,
            stream_next: None,
            last_xyz: Xyz::zeros(),
        }
    }

    fn n5(&mut self) -> Vec<u8> {
        let (xyz, status) = match self.meter.measure(false) {
            Measured::Ok(r) => (r.xyz.unwrap_or_default(), b'0'),
            Measured::LowLight(r) => (r.xyz.unwrap_or_default(), b'u'),
            Measured::Overload { .. } | Measured::SyncFailed { .. } => (Xyz::zeros(), b'v'),
        };
        self.last_xyz = xyz;
        let mut payload = Vec::with_capacity(10);
        for v in xyz.iter() {
            payload.extend_from_slice(&encode_value(*v));
        }
        payload.push(encode_ranges([
            range_for(xyz.x),
            range_for(xyz.y),
            range_for(xyz.z),
        ]));
        frame(b"N5", &payload, status)
    }

    /// The calibration list: 96 slots of 20 bytes, unused ones 0xFF.
    fn calibration_list() -> Vec<u8> {
        let mut payload = vec![0xFFu8; 96 * 20];
        for (slot, name) in ["Factory LCD", "Factory CRT"].iter().enumerate() {
            let mut field = format!("{name:<20}").into_bytes();
            field.truncate(20);
            payload[slot * 20..slot * 20 + 20].copy_from_slice(&field);
        }
        payload
    }

    fn d7(&self) -> Vec<u8> {
        frame(b"D7", &Self::calibration_list(), b'0')
    }

    /// A slot's 128 bytes: the name, then the identity matrix in Klein format at
    /// offset 101 (9 × 3 bytes, value = m·2^(e−15)).
    fn d1(&self, slot: u8) -> Vec<u8> {
        let mut payload = vec![b' '; 128];
        let name = format!("Factory slot {slot}");
        payload[..name.len()].copy_from_slice(name.as_bytes());
        for i in 0..9 {
            let v = if i % 4 == 0 { 0.5 } else { 0.0 }; // 0.5·2 = 1 in calibration format
            payload[101 + 3 * i..104 + 3 * i].copy_from_slice(&encode_value(v));
        }
        let mut out = payload;
        out.extend_from_slice(b"<0>");
        out
    }

    fn stream_packet(&self) -> Vec<u8> {
        let mut record = b"T2".to_vec();
        for v in self.last_xyz.iter() {
            record.extend_from_slice(&encode_value(*v));
        }
        record.push(0);
        record.extend_from_slice(b"<0>");
        record.resize(32, b'_');
        let y = (self.last_xyz.y.clamp(0.0, 4000.0) * 16.0) as u16;
        let mut packet = Vec::with_capacity(96);
        for r in record {
            packet.push(r);
            packet.extend_from_slice(&y.to_be_bytes());
        }
        packet
    }

    fn command(&mut self, command: &[u8], now: f64) -> Vec<Scheduled> {
        let reply = match command {
            b"P0" => frame(b"P0", b"K-10-A 000012345", b'0'),
            b"P2" => frame(b"P2", b"v01.09fh", b'0'),
            b"N5" => {
                self.stream_next = None;
                return vec![Scheduled::after(N5_DELAY_S, self.n5())];
            }
            b"D7" => self.d7(),
            b"D1" => {
                self.awaiting_slot = true;
                b"D1".to_vec()
            }
            b"M6" => {
                let mut payload = vec![0u8; 15];
                payload[12] = 100;
                payload[13] = 100;
                frame(b"M6", &payload, b'0')
            }
            b"B9" => {
                let mut payload = Vec::new();
                for _ in 0..19 {
                    payload.extend_from_slice(&1000u16.to_be_bytes());
                }
                frame(b"B9", &payload, b'0')
            }
            b"T2" => {
                self.stream_next = Some(now + 0.125);
                return Vec::new();
            }
            [b'J', b'1'..=b'8'] | [b'L', b'0' | b'1'] => frame(command, b"", b'0'),
            // An unknown command: the K-10 answers nothing.
            _ => return Vec::new(),
        };
        vec![Scheduled::after(0.05, reply)]
    }
}

impl DeviceModel for K10Emulator {
    fn name(&self) -> &'static str {
        "K-10A"
    }

    fn receive(&mut self, bytes: &[u8], now: f64, _baud: u32) -> Vec<Scheduled> {
        let mut out = Vec::new();
        for &b in bytes {
            if self.awaiting_slot {
                // The slot index is one binary byte, then CR.
                if b == b'\r' {
                    continue;
                }
                self.awaiting_slot = false;
                out.push(Scheduled::after(0.1, self.d1(b)));
                continue;
            }
            if b == b'\r' || b == b'\n' {
                let mut line = std::mem::take(&mut self.input);
                // A `;` sent alone (the probe's first step) is not answered, and is
                // no part of the command after it.
                line.retain(|c| *c != b';');
                if line == b"D024" {
                    let reply = frame(b"D4", &Self::calibration_list(), b'0');
                    out.push(Scheduled::after(0.05, reply));
                } else if line.len() >= 2 {
                    out.extend(self.command(&line[line.len() - 2..], now));
                }
            } else if self.input.len() < 64 {
                self.input.push(b);
            }
        }
        out
    }

    fn poll(&mut self, until: f64) -> Vec<(f64, Vec<u8>)> {
        let mut out = Vec::new();
        while let Some(next) = self.stream_next {
            if next > until {
                break;
            }
            out.push((next, self.stream_packet()));
            self.stream_next = Some(next + 0.125);
        }
        out
    }
}
