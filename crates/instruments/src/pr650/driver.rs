//! Driver for the Photo Research PR-650.
//!
//! There is no handshake: the PR-650 accepts remote control only if a command arrives
//! within a few seconds of its power-up (or of its RTS line rising, which a
//! pseudo-terminal does not have). Session: `b3` (backlight; its answer is the contact),
//! then per measurement `f` (refresh frequency) and `s01,,,,1,0,01,1` (sync to it) or
//! `s01,,,,,0,01,1` (no sync), `m0` (measure and hold), `d5` (spectrum, 101 rows of
//! 17 bytes) and `d2` (XYZ).
//!
//! Quality codes: 10 and 18 → flagged below range (the values kept); 19 → flagged
//! overload; 7, 8, 20 (sync) → measured again without sync; others → a device error.

use super::protocol::{
    COMMAND_TIMEOUT_S, EOL, FIRST_REPLY_TIMEOUT_S, MEASURE_TIMEOUT_S, QualityKind, classify,
    meaning, parse_code, parse_xyz,
};
use crate::driver::Protocol;
use crate::transport::Link;
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus, check_spectrum};
use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

pub struct Pr650 {
    link: Link,
    sync: bool,
    sync_off: bool,
}

fn protocol(e: String) -> InstrumentError {
    InstrumentError::Protocol(e)
}

impl Pr650 {
    pub fn new(link: Link, sync: bool) -> Self {
        Pr650 {
            link,
            sync,
            sync_off: false,
        }
    }

    fn command(&mut self, text: &str, timeout: f64) -> Result<String, InstrumentError> {
        self.link.clear()?;
        self.link.send(format!("{text}\n").as_bytes())?;
        let line = self.link.read_line(EOL, timeout)?;
        Ok(String::from_utf8_lossy(&line).trim().to_string())
    }

    /// Quality of a report, as an error when it is not usable.
    fn setup(&mut self) -> Result<(), InstrumentError> {
        let synced = if self.sync && !self.sync_off {
            let reply = self.command("f", FIRST_REPLY_TIMEOUT_S)?;
            parse_code(&reply).map_err(protocol)? == 0
        } else {
            false
        };
        let command = if synced {
            "s01,,,,1,0,01,1"
        } else {
            "s01,,,,,0,01,1"
        };
        let reply = self.command(command, COMMAND_TIMEOUT_S)?;
        match parse_code(&reply).map_err(protocol)? {
            0 => Ok(()),
            n => Err(InstrumentError::Device {
                code: n.to_string(),
                meaning: format!("parameter {n} of the setup was refused"),
            }),
        }
    }

    fn spectrum(&mut self) -> Result<(u32, Spectrum), InstrumentError> {
        let header = self.command("d5", COMMAND_TIMEOUT_S)?;
        let quality = parse_code(&header).map_err(protocol)?;
        let _integrated = self.link.read_line(EOL, COMMAND_TIMEOUT_S)?;
        let mut wavelengths = Vec::with_capacity(101);
        let mut values = Vec::with_capacity(101);
        for _ in 0..101 {
            let row = self.link.read_line(EOL, COMMAND_TIMEOUT_S)?;
            let text = String::from_utf8_lossy(&row);
            let (w, v) = text
                .split_once(',')
                .ok_or_else(|| protocol(format!("'{text}' is not a spectral row")))?;
            match (
                w.trim().trim_end_matches('.').parse::<f64>(),
                v.trim().parse::<f64>(),
            ) {
                (Ok(w), Ok(v)) if v.is_finite() => {
                    wavelengths.push(w);
                    values.push(v);
                }
                _ => return Err(protocol(format!("'{text}' is not a spectral row"))),
            }
        }
        let spectrum =
            Spectrum::new(wavelengths, values).map_err(|e| protocol(format!("spectrum: {e}")))?;
        Ok((quality, spectrum))
    }
}

impl Protocol for Pr650 {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        let reply = self.command("b3", FIRST_REPLY_TIMEOUT_S).map_err(|e| match e {
            InstrumentError::Timeout { seconds } => InstrumentError::Protocol(format!(
                "no answer in {seconds:.1} s: the PR-650 accepts remote control only within a few seconds of switching on; switch it off and on and connect at once"
            )),
            other => other,
        })?;
        parse_code(&reply).map_err(protocol)?;
        let serial = self.command("d110", COMMAND_TIMEOUT_S)?;
        Ok(InstrumentInfo {
            name: "Photo Research PR-650".into(),
            serial: Some(serial.chars().take(8).collect()),
            capability: Capability::Spectral,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        self.setup()?;
        let held = self.command("m0", MEASURE_TIMEOUT_S)?;
        let code = parse_code(&held).map_err(protocol)?;
        let d2 = self.command("d2", COMMAND_TIMEOUT_S)?;
        let (quality, xyz) = parse_xyz(&d2).map_err(protocol)?;
        let quality = quality.max(code);
        let base = Reading {
            device_code: Some(format!("{quality:02}")),
            raw: Some(d2.clone()),
            ..Default::default()
        };
        let status = match classify(quality) {
            QualityKind::Ok => ReadingStatus::Ok,
            QualityKind::LowLight => ReadingStatus::BelowRange,
            QualityKind::Overload => {
                return Ok(Reading {
                    status: ReadingStatus::Overload,
                    ..base
                });
            }
            QualityKind::SyncFailure if self.sync && !self.sync_off => {
                tracing::warn!(quality, "sync failed; measuring again without sync");
                self.sync_off = true;
                return self.measure_once();
            }
            QualityKind::SyncFailure | QualityKind::Other => {
                return Err(InstrumentError::Device {
                    code: format!("{quality:02}"),
                    meaning: meaning(quality).into(),
                });
            }
        };
        let (_, spectrum) = self.spectrum()?;
        let xyz = Xyz::new(xyz[0], xyz[1], xyz[2]);
        check_spectrum(&spectrum, &xyz, 380.0, 4.0, 101)?;
        Ok(Reading {
            xyz: Some(xyz),
            spectrum: Some(spectrum),
            status,
            ..base
        })
    }
}
