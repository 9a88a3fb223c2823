//! Emulated Konica Minolta LS-100 / LS-110 / CS-100A: silent unless switched on with F
//! held (an option, on by default); `MDS,nn` and `CLE` answered `OK00`; `MES` answered
//! in the fixed-width reply (28 bytes for the CS-100A); and the meter's sulk: when the
//! first `MES` after power-on is too dark it leaves remote mode and answers nothing
//! more until switched off and on.

use super::protocol::{Model, chromaticity_field, field};
use crate::emulator::{CommandLines, DeviceModel, Measured, Meter, Scheduled};
use chromacal_color::spaces::xyz_to_xyy;

/// Seconds from `MES` to its reply.
const RESPONSE_S: f64 = 0.5;

/// Luminance below which a first measurement makes the meter sulk (cd/m²).
pub const SULK_BELOW_CD_M2: f64 = 0.5;

pub struct MinoltaEmulator {
    model: Model,
    meter: Meter,
    remote: bool,
    measured_once: bool,
    input: CommandLines,
}

impl MinoltaEmulator {
    /// `remote`: the meter was switched on with F held.
    pub fn new(model: Model, meter: Meter, remote: bool) -> Self {
        MinoltaEmulator {
            model,
            meter,
            remote,
            measured_once: false,
            input: CommandLines::default(),
        }
    }

    fn measurement(&mut self) -> Vec<Scheduled> {
        let measured = self.meter.measure(false);
        // The meters answer within their response time (FAST 100 ms, SLOW 400 ms),
        // whatever the light.
        let delay = RESPONSE_S;
        let (status, y, chroma) = match &measured {
            Measured::Ok(r) => ("OK00", r.luminance().unwrap_or(0.0), r.xyz),
            Measured::LowLight(r) if self.model.has_chromaticity() => {
                ("OK13", r.luminance().unwrap_or(0.0), r.xyz)
            }
            // The luminance meters have no low-light code: they read (next to) nothing.
            Measured::LowLight(_) => ("OK00", 0.0, None),
            Measured::Overload { .. } | Measured::SyncFailed { .. } => {
                let reply = if self.model.has_chromaticity() {
                    format!(
                        "OK12,{},{},{}\r\n",
                        field(-999999.0),
                        chromaticity_field(0.0),
                        chromaticity_field(0.0)
                    )
                } else {
                    "ER10\r\n".to_string()
                };
                return vec![Scheduled::after(delay, reply)];
            }
        };
        if !self.measured_once {
            self.measured_once = true;
            if y < SULK_BELOW_CD_M2 {
                self.remote = false;
                return Vec::new();
            }
        }
        let reply = if self.model.has_chromaticity() {
            let xyy = xyz_to_xyy(&chroma.unwrap_or_default(), [0.0, 0.0]);
            format!(
                "{status},{},{},{}\r\n",
                field(y),
                chromaticity_field(xyy.x),
                chromaticity_field(xyy.y)
            )
        } else {
            format!("{status},{}\r\n", field(y))
        };
        vec![Scheduled::after(delay, reply)]
    }

    fn command(&mut self, line: &str) -> Vec<Scheduled> {
        let upper = line.to_ascii_uppercase();
        if upper == "MES" {
            self.measurement()
        } else if upper.starts_with("MDS,") || upper == "CLE" {
            vec![Scheduled::after(0.1, "OK00\r\n")]
        } else {
            vec![Scheduled::after(0.1, "ER00\r\n")]
        }
    }
}

impl DeviceModel for MinoltaEmulator {
    fn name(&self) -> &'static str {
        self.model.name()
    }

    fn receive(&mut self, bytes: &[u8], _now: f64, _baud: u32) -> Vec<Scheduled> {
        // Seven data bits on the wire.
        let seven: Vec<u8> = bytes.iter().map(|b| b & 0x7f).collect();
        let mut out = Vec::new();
        for line in self.input.push(&seven) {
            // Silent unless in remote mode (which a dark first reading ends).
            if !self.remote {
                break;
            }
            out.extend(self.command(&line));
        }
        out
    }
}
