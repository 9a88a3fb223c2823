//! Emulated PR-655 and PR-670 (`../shared/PROTOCOLS.md` §3.2 state machine and §9.2
//! checklist): local until the exact characters `PHOTO`, ` REMOTE MODE` with no
//! terminator, and on a PR-670 only for the first `PHOTO` until `Q`; commands ended by
//! CR, LF or CR LF at any pace; `M`/`D` reports 1–6, 110, 111, 120, 601, 602; the
//! spectrum on the model's grid (PR-655 rows with 3-digit exponents); status codes −8,
//! −2 and −10 for low light, overload and sync failure.

use super::protocol::Model;
use crate::emulator::{DeviceModel, Measured, Meter, Scheduled, scientific};
use chromacal_color::spaces::{UvPrime, xyz_to_uv_prime, xyz_to_xyy};
use chromacal_color::spectrum::Spectrum;

/// Seconds a PR-6xx adds to each measurement (dark reading, processing).
const MEASUREMENT_OVERHEAD_S: f64 = 1.5;

/// The device side of a PR-655 or PR-670.
pub struct Pr6xxEmulator {
    model: Model,
    meter: Meter,
    remote: bool,
    /// PHOTO was answered since the last `Q` (the PR-670 answers only once).
    photo_answered: bool,
    input: Vec<u8>,
    sync_mode: u32,
    last: Option<Measured>,
    serial: String,
}

impl Pr6xxEmulator {
    pub fn new(model: Model, meter: Meter) -> Self {
        Pr6xxEmulator {
            model,
            meter,
            remote: false,
            photo_answered: false,
            input: Vec::new(),
            sync_mode: 0,
            last: None,
            serial: format!("{}00042", if model == Model::Pr670 { "67" } else { "65" }),
        }
    }

    fn number(&self, v: f64) -> String {
        scientific(v, 3, 2)
    }

    /// Report `code` of the last measurement.
    fn report(&self, code: u32) -> String {
        let status = |c: i32| format!("{c:05}");
        match code {
            110 => return format!("00000,{}\r\n", self.serial),
            111 => return format!("00000,{}\r\n", self.model.name()),
            120 => {
                return format!(
                    "00000,201,0.00,380,780,{},{},7,247\r\n",
                    self.model.step_nm(),
                    self.model.rows()
                );
            }
            601 => {
                return format!(
                    "00000,0,-1,-1,-1,0,1,0,0,0,1,2,0,{},0,60.00\r\n",
                    self.sync_mode
                );
            }
            602 => {
                return format!(
                    "00000,MS-75,None,None,None,1 deg,Metric,Adaptive,0 msec,Normal,1 cycles,2 deg,No Smart Dark,{},Standard Sensitivity,60.00 Hertz\r\n",
                    if self.sync_mode == 0 {
                        "No Sync"
                    } else {
                        "Auto Sync"
                    }
                );
            }
            _ => {}
        }
        let reading = match &self.last {
            Some(Measured::Ok(r)) => r,
            Some(Measured::LowLight(_)) => return format!("{}\r\n", status(-8)),
            Some(Measured::Overload { .. }) => return format!("{}\r\n", status(-2)),
            Some(Measured::SyncFailed { .. }) => return format!("{}\r\n", status(-10)),
            None => return format!("{}\r\n", status(-4)),
        };
        let xyz = reading.xyz.unwrap_or_default();
        let xyy = xyz_to_xyy(&xyz, [0.3127, 0.329]);
        let uv = xyz_to_uv_prime(
            &xyz,
            UvPrime {
                u: 0.1978,
                v: 0.4683,
            },
        );
        let y = self.number(xyz.y);
        match code {
            1 => format!("00000,0,{y},{:.4},{:.4}\r\n", xyy.x, xyy.y),
            2 => format!(
                "00000,0,{},{y},{}\r\n",
                self.number(xyz.x),
                self.number(xyz.z)
            ),
            3 => format!("00000,0,{y},{:.4},{:.4}\r\n", uv.u, uv.v),
            4 => {
                // McCamy (1992) CCT from x, y.
                let n = (xyy.x - 0.3320) / (0.1858 - xyy.y);
                let cct = 449.0 * n.powi(3) + 3525.0 * n.powi(2) + 6823.3 * n + 5520.33;
                format!("00000,0,{y},{:5.0},0.0000\r\n", cct)
            }
            5 => self.spectrum_report(reading.spectrum.as_ref()),
            6 => format!(
                "00000,0,{y},{:.4},{:.4},{:.4},{:.4}\r\n",
                xyy.x, xyy.y, uv.u, uv.v
            ),
            _ => format!("{}\r\n", status(-4)),
        }
    }

    fn spectrum_report(&self, spectrum: Option<&Spectrum>) -> String {
        let step = self.model.step_nm();
        let digits = self.model.row_exponent_digits();
        let value = |nm: f64| spectrum.and_then(|s| s.value_at(nm)).unwrap_or(0.0);
        let rows: Vec<(f64, f64)> = (0..self.model.rows())
            .map(|i| {
                let nm = 380.0 + step * i as f64;
                (nm, value(nm))
            })
            .collect();
        let integrated: f64 = rows.iter().map(|r| r.1).sum::<f64>() * step;
        let peak = rows
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0.0, |r| r.0);
        let mut out = format!(
            "00000,0,{},{},{}\r\n",
            scientific(peak, 3, 3),
            scientific(integrated, 3, 2),
            scientific(integrated * 5.0e18, 3, 2)
        );
        for (nm, v) in rows {
            out += &format!("{nm:.0},{}\r\n", scientific(v, 3, digits));
        }
        out
    }

    fn command(&mut self, line: &str) -> Vec<Scheduled> {
        let upper = line.to_ascii_uppercase();
        let (letter, rest) = upper.split_at(1);
        match letter {
            "M" => {
                let code: u32 = rest.trim().parse().unwrap_or(1);
                let measured = self.meter.measure(self.sync_mode != 0);
                let delay = measured.integration_s() + MEASUREMENT_OVERHEAD_S;
                self.last = Some(measured);
                vec![Scheduled::after(delay, self.report(code))]
            }
            "D" => {
                let code: u32 = rest.trim().parse().unwrap_or(1);
                vec![Scheduled::after(0.05, self.report(code))]
            }
            "S" => {
                if let Some(n) = rest.strip_prefix('S') {
                    self.sync_mode = n.trim().parse().unwrap_or(0);
                }
                vec![Scheduled::after(0.05, "00000\r\n")]
            }
            "F" => vec![Scheduled::after(
                1.0,
                "00000,60.00 Hertz (Period = 16.667 milliseconds)\r\n",
            )],
            "I" | "B" | "L" => vec![Scheduled::after(0.05, "00000\r\n")],
            // C clears an error, E toggles echo: no reply.
            _ => Vec::new(),
        }
    }
}

impl DeviceModel for Pr6xxEmulator {
    fn name(&self) -> &'static str {
        self.model.name()
    }

    fn receive(&mut self, bytes: &[u8], _now: f64, _baud: u32) -> Vec<Scheduled> {
        let mut out = Vec::new();
        for &b in bytes {
            if !self.remote {
                self.input.push(b);
                if self.input.ends_with(b"PHOTO") {
                    self.input.clear();
                    if !(self.model == Model::Pr670 && self.photo_answered) {
                        self.remote = true;
                        self.photo_answered = true;
                        out.push(Scheduled::after(0.2, " REMOTE MODE"));
                    }
                }
                if self.input.len() > 16 {
                    self.input.drain(..self.input.len() - 5);
                }
                continue;
            }
            match b {
                b'\r' | b'\n' => {
                    let line = String::from_utf8_lossy(&self.input).trim().to_string();
                    self.input.clear();
                    if !line.is_empty() {
                        out.extend(self.command(&line));
                    }
                }
                // Q leaves remote mode, with no terminator and no reply.
                b'Q' | b'q' if self.input.is_empty() => {
                    self.remote = false;
                    self.photo_answered = false;
                }
                _ => {
                    self.input.push(b);
                    // A PHOTO sent in remote mode is not a command: no reply, forgotten.
                    if self.input.ends_with(b"PHOTO") {
                        self.input.clear();
                    }
                }
            }
        }
        out
    }
}
