//! Emulated PR-650: remote control is armed only if a complete command arrives within
//! the arming window after power-up (5 s unless set), otherwise it stays silent;
//! `b<n>` → `000`, `s…` → `00`, `f` → `00,<Hz>`, `m0` → `000` (or the quality code)
//! after the integration, `d1`/`d2`/`d5`/`d110`/`d120` in the fixed widths of the
//! manual (17-byte spectral rows), echo with `E`.

use super::protocol::format_number;
use crate::emulator::{DeviceModel, Measured, Meter, Scheduled};
use chromacal_color::spaces::xyz_to_xyy;

pub struct Pr650Emulator {
    meter: Meter,
    arming_window_s: f64,
    /// None until the first command decides; then armed or not.
    armed: Option<bool>,
    input: Vec<u8>,
    sync: bool,
    last: Option<Measured>,
    echo: bool,
}

impl Pr650Emulator {
    pub fn new(meter: Meter, arming_window_s: f64) -> Self {
        Pr650Emulator {
            meter,
            arming_window_s,
            armed: None,
            input: Vec::new(),
            sync: false,
            last: None,
            echo: false,
        }
    }

    fn quality(&self) -> u32 {
        match &self.last {
            Some(Measured::Ok(_)) => 0,
            Some(Measured::LowLight(_)) => 18,
            Some(Measured::Overload { .. }) => 19,
            Some(Measured::SyncFailed { .. }) => 7,
            None => 13,
        }
    }

    fn report(&self, code: u32) -> String {
        let q = self.quality();
        let reading = match &self.last {
            Some(Measured::Ok(r)) | Some(Measured::LowLight(r)) => Some(r),
            _ => None,
        };
        let xyz = reading.and_then(|r| r.xyz).unwrap_or_default();
        match code {
            1 => {
                let xyy = xyz_to_xyy(&xyz, [0.3127, 0.329]);
                let fraction = |v: f64| format!("{:.4}", v).trim_start_matches('0').to_string();
                format!(
                    "{q:02},0,{},{},{}\r\n",
                    format_number(xyz.y),
                    fraction(xyy.x),
                    fraction(xyy.y)
                )
            }
            2 => format!(
                "{q:02},0,{},{},{}\r\n",
                format_number(xyz.x),
                format_number(xyz.y),
                format_number(xyz.z)
            ),
            5 => {
                let spectrum = reading.and_then(|r| r.spectrum.as_ref());
                let value = |nm: f64| spectrum.and_then(|s| s.value_at(nm)).unwrap_or(0.0);
                let rows: Vec<(f64, f64)> = (0..101)
                    .map(|i| (380.0 + 4.0 * i as f64, 0.0))
                    .map(|(w, _)| (w, value(w)))
                    .collect();
                let integrated: f64 = rows.iter().map(|r| r.1).sum::<f64>() * 4.0;
                let mut out = format!("{q:02},0\r\n{}\r\n", format_number(integrated));
                for (w, v) in rows {
                    out += &format!("{w:04.0}.,{}\r\n", format_number(v));
                }
                out
            }
            110 => "60912345\r\n".into(),
            120 => "0101,008.0,0380.,0780.,004.\r\n".into(),
            _ => format!("{q:02}\r\n"),
        }
    }

    fn command(&mut self, line: &str) -> Vec<Scheduled> {
        let lower = line.to_ascii_lowercase();
        let (letter, rest) = lower.split_at(1);
        match letter {
            "b" => vec![Scheduled::after(0.1, "000\r\n")],
            "s" => {
                // s[acc1],[acc2],[acc3],[acc4],[syncfreq],[inttime],[avgcnt],[units]
                let fields: Vec<&str> = rest.split(',').collect();
                self.sync = fields.get(4).is_some_and(|f| !f.trim().is_empty());
                vec![Scheduled::after(0.1, "00\r\n")]
            }
            "f" => vec![Scheduled::after(1.0, "00,60.00\r\n")],
            "m" => {
                let measured = self.meter.measure(self.sync);
                let delay = measured.integration_s() + 1.0;
                self.last = Some(measured);
                let code: u32 = rest.trim().parse().unwrap_or(0);
                let reply = if code == 0 {
                    format!("{:03}\r\n", self.quality())
                } else {
                    self.report(code)
                };
                vec![Scheduled::after(delay, reply)]
            }
            "d" => {
                let code: u32 = rest.trim().parse().unwrap_or(0);
                vec![Scheduled::after(0.1, self.report(code))]
            }
            "e" => {
                self.echo = true;
                Vec::new()
            }
            _ => Vec::new(),
        }
    }
}

impl DeviceModel for Pr650Emulator {
    fn name(&self) -> &'static str {
        "PR-650"
    }

    fn receive(&mut self, bytes: &[u8], now: f64, _baud: u32) -> Vec<Scheduled> {
        let mut out = Vec::new();
        for &b in bytes {
            if self.armed == Some(false) {
                continue;
            }
            if self.echo {
                out.push(Scheduled::now(vec![b]));
            }
            if b == b'\r' || b == b'\n' {
                let line = String::from_utf8_lossy(&self.input).trim().to_string();
                self.input.clear();
                if line.is_empty() {
                    continue;
                }
                if self.armed.is_none() {
                    self.armed = Some(now <= self.arming_window_s);
                    if self.armed == Some(false) {
                        continue;
                    }
                }
                out.extend(self.command(&line));
                if self.echo {
                    out.push(Scheduled::after(0.2, ">"));
                }
            } else if self.input.len() < 128 {
                self.input.push(b);
            }
        }
        out
    }
}
