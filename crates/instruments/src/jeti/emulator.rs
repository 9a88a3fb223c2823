//! Emulated JETI specbos 1211: it talks only at its own baud rate (garbage at any other,
//! so drivers must probe), answers queries with CR-ended lines, settings with ACK or
//! NAK, `*init` with ACK and, when the integration is done, BEL (or NAK); `*stat:err?`
//! gives the last error; `*contr:mhead?` and `*contr:laser?` are answered at any time;
//! stray ENQ bytes are sent now and then.

use super::protocol::{ACK, BEL, ENQ, NAK, WAVELENGTH_END, WAVELENGTH_START};
use crate::Reading;
use crate::emulator::{CommandLines, DeviceModel, Measured, Meter, Scheduled};
use chromacal_color::spaces::xyz_to_xyy;

/// Fixed overhead of a measurement on a 1211 (s).
const OVERHEAD_S: f64 = 3.6;

pub struct SpecbosEmulator {
    meter: Meter,
    baud: u32,
    input: CommandLines,
    last_error: u32,
    last: Option<Reading>,
    cycle_mode: bool,
    range: (u32, u32),
    /// Count of replies, to put an ENQ in some of them.
    replies: u64,
}

impl SpecbosEmulator {
    /// A specbos set to `baud`.
    pub fn new(meter: Meter, baud: u32) -> Self {
        SpecbosEmulator {
            meter,
            baud,
            input: CommandLines::default(),
            last_error: 0,
            last: None,
            cycle_mode: false,
            range: (WAVELENGTH_START, WAVELENGTH_END),
            replies: 0,
        }
    }

    fn text(&mut self, delay: f64, text: &str) -> Scheduled {
        self.replies += 1;
        let mut bytes = Vec::with_capacity(text.len() + 1);
        // Every seventh reply carries a stray ENQ, as the real instrument's do.
        if self.replies.is_multiple_of(7) {
            bytes.push(ENQ);
        }
        bytes.extend_from_slice(text.as_bytes());
        Scheduled::after(delay, bytes)
    }

    fn nak(&mut self, code: u32) -> Vec<Scheduled> {
        self.last_error = code;
        vec![Scheduled::after(0.02, vec![NAK])]
    }

    fn ack() -> Vec<Scheduled> {
        vec![Scheduled::after(0.02, vec![ACK])]
    }

    fn spectrum_reply(&mut self) -> Vec<Scheduled> {
        let Some(reading) = &self.last else {
            return self.nak(138);
        };
        let (start, end) = self.range;
        let mut text =
            format!("Spectral radiance [W/(sr*sqm*nm)]\rWavelength {start} to {end} nm, 1 nm\r");
        for nm in start..=end {
            let v = reading
                .spectrum
                .as_ref()
                .and_then(|s| s.value_at(nm as f64))
                .unwrap_or(0.0);
            text += &format!("{v:.6e}\r");
        }
        text.push('\r');
        vec![self.text(0.3, &text)]
    }

    fn command(&mut self, line: &str) -> Vec<Scheduled> {
        let lower = line.to_ascii_lowercase();
        let (name, args) = match lower.split_once(' ') {
            Some((n, a)) => (n.to_string(), a.trim().to_string()),
            None => (lower.clone(), String::new()),
        };
        match name.as_str() {
            "*idn?" => vec![self.text(0.05, "JETI_SB1211 v4.1\r")],
            "*vers?" => vec![self.text(0.05, "4.1.2\r")],
            "*para:spnum?" => vec![self.text(0.05, "spectrometer number: 10271\r")],
            "*para:wavbeg?" => vec![self.text(0.05, "Predefined start wave:\t350\r")],
            "*para:wavend?" => vec![self.text(0.05, "Predefined end wave:\t1000\r")],
            "*contr:mhead?" => vec![self.text(0.05, "mhead: 0\r")],
            "*contr:laser?" => vec![self.text(0.05, "laser: 0\r")],
            "*stat:err?" => {
                let code = self.last_error;
                vec![self.text(0.05, &format!("Error Code: {code}\r"))]
            }
            "*conf:wran" => {
                let n: Vec<u32> = args
                    .split_whitespace()
                    .filter_map(|a| a.parse().ok())
                    .collect();
                match n.as_slice() {
                    [a, b, 1] if a < b && *a >= 350 && *b <= 1000 => {
                        self.range = (*a, *b);
                        Self::ack()
                    }
                    _ => self.nak(10),
                }
            }
            "*conf:cycmod" => {
                self.cycle_mode = args == "1";
                Self::ack()
            }
            "*contr:cyctim" => {
                if self.meter.sync_fails() {
                    self.nak(160)
                } else {
                    let mut out = Self::ack();
                    out.push(self.text(1.0, "cyctim[ms]:\t16.667\r"));
                    out
                }
            }
            n if n.starts_with("*conf:") || n.starts_with("*para:") || n == "*contr:laser" => {
                Self::ack()
            }
            "*init" => {
                let measured = self.meter.measure(self.cycle_mode);
                let delay = measured.integration_s() + OVERHEAD_S;
                let mut out = Self::ack();
                let finish = match measured {
                    Measured::Ok(r) => {
                        self.last = Some(r);
                        self.last_error = 0;
                        BEL
                    }
                    Measured::LowLight(_) => {
                        self.last_error = 121;
                        NAK
                    }
                    Measured::Overload { .. } => {
                        self.last_error = 120;
                        NAK
                    }
                    Measured::SyncFailed { .. } => {
                        self.last_error = 160;
                        NAK
                    }
                };
                out.push(Scheduled::after(delay, vec![finish]));
                out
            }
            "*fetch:xyz" => match &self.last {
                Some(r) => {
                    let x = r.xyz.unwrap_or_default();
                    let text = format!("X:\t{:.4}\rY:\t{:.4}\rZ:\t{:.4}\r", x.x, x.y, x.z);
                    vec![self.text(0.05, &text)]
                }
                None => self.nak(138),
            },
            "*fetch:photometric" => match &self.last {
                Some(r) => {
                    let text = format!("Luminance[cd/m^2]:\t{:.4}\r", r.luminance().unwrap_or(0.0));
                    vec![self.text(0.05, &text)]
                }
                None => self.nak(138),
            },
            "*fetch:chromxy" => match &self.last {
                Some(r) => {
                    let xyy = xyz_to_xyy(&r.xyz.unwrap_or_default(), [0.0, 0.0]);
                    let text = format!("Chrom_x:\t{:.4}\rChrom_y:\t{:.4}\r", xyy.x, xyy.y);
                    vec![self.text(0.05, &text)]
                }
                None => self.nak(138),
            },
            "*fetch:sprad" => self.spectrum_reply(),
            _ => self.nak(4),
        }
    }
}

impl DeviceModel for SpecbosEmulator {
    fn name(&self) -> &'static str {
        "specbos 1211"
    }

    fn receive(&mut self, bytes: &[u8], _now: f64, baud: u32) -> Vec<Scheduled> {
        if baud != self.baud {
            // At the wrong rate the instrument sees framing errors and its reply reaches
            // the host as noise.
            self.input.clear();
            let noise: Vec<u8> = bytes.iter().map(|b| b.rotate_left(3) ^ 0xA5).collect();
            return vec![Scheduled::after(0.01, noise)];
        }
        let lines = self.input.push(bytes);
        lines.iter().flat_map(|l| self.command(l)).collect()
    }
}
