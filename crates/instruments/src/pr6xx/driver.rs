//! Driver for the Photo Research PR-655 and PR-670.
//!
//! Session: `Q` then `PHOTO` (no terminator; the PR-670 answers only the first `PHOTO`
//! after a `Q`), ` REMOTE MODE` within 10 s, `D111` (model), `D110` (serial), `SU1`
//! (metric units), `SS1` or `SS0` (auto sync or none). Every character goes out alone,
//! 50 ms apart (the USB firmware drops characters that come faster). A measurement is
//! `M5` (measure, spectrum) then `D2` (XYZ of the same measurement).
//!
//! Codes: −8 → a reading flagged below range, no value; −2 → flagged overload; −1, −3,
//! −9, −10 (sync) → sync is switched off (`SS0`) and the patch measured again; any
//! other code → a device error.

use super::protocol::{
    CHARACTER_GAP_S, COMMAND_TIMEOUT_S, EOL, Model, REMOTE_TIMEOUT_S, StatusKind, classify,
    meaning, parse_row, parse_status, parse_text_report, parse_xyz,
};
use crate::driver::Protocol;
use crate::transport::{Link, escape};
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus, check_spectrum};
use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

/// A PR-655 or PR-670 on a link.
pub struct Pr6xx {
    link: Link,
    expected: Model,
    model: Model,
    sync: bool,
    /// Sync failed in this session: measure without it.
    sync_off: bool,
}

fn protocol_error(e: String) -> InstrumentError {
    InstrumentError::Protocol(e)
}

impl Pr6xx {
    pub fn new(link: Link, model: Model, sync: bool) -> Self {
        Pr6xx {
            link,
            expected: model,
            model,
            sync,
            sync_off: false,
        }
    }

    /// Send `text` with a CR, paced, and read one reply line.
    fn command(&mut self, text: &str, timeout: f64) -> Result<String, InstrumentError> {
        self.link.clear()?;
        self.link
            .send_paced(format!("{text}\r").as_bytes(), CHARACTER_GAP_S)?;
        let line = self.link.read_line(EOL, timeout)?;
        Ok(String::from_utf8_lossy(&line).trim().to_string())
    }

    /// A setup command whose reply is a bare status.
    fn setting(&mut self, text: &str) -> Result<(), InstrumentError> {
        let reply = self.command(text, COMMAND_TIMEOUT_S)?;
        match parse_status(&reply).map_err(protocol_error)? {
            0 => Ok(()),
            code => Err(InstrumentError::Device {
                code: code.to_string(),
                meaning: format!("{} (after {text})", meaning(code)),
            }),
        }
    }

    fn set_sync(&mut self, on: bool) -> Result<(), InstrumentError> {
        self.setting(if on { "SS1" } else { "SS0" })
    }

    fn spectrum_rows(&mut self) -> Result<Spectrum, InstrumentError> {
        let mut wavelengths = Vec::with_capacity(self.model.rows());
        let mut values = Vec::with_capacity(self.model.rows());
        for _ in 0..self.model.rows() {
            let row = self.link.read_line(EOL, COMMAND_TIMEOUT_S)?;
            let (w, v) = parse_row(String::from_utf8_lossy(&row).trim()).map_err(protocol_error)?;
            wavelengths.push(w);
            values.push(v);
        }
        Spectrum::new(wavelengths, values)
            .map_err(|e| InstrumentError::Protocol(format!("spectrum: {e}")))
    }
}

impl Protocol for Pr6xx {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        // Leave remote mode first: the PR-670 answers only the first PHOTO after it.
        self.link.send_paced(b"Q", CHARACTER_GAP_S)?;
        self.link.sleep(0.5);
        self.link.clear()?;
        self.link.send_paced(b"PHOTO", CHARACTER_GAP_S)?;
        let reply = self.link.read_until_silence(REMOTE_TIMEOUT_S, 0.3)?;
        if !String::from_utf8_lossy(&reply).contains("REMOTE MODE") {
            return Err(InstrumentError::Protocol(format!(
                "expected ' REMOTE MODE' after PHOTO, got '{}'",
                escape(&reply)
            )));
        }
        let name =
            parse_text_report(&self.command("D111", COMMAND_TIMEOUT_S)?).map_err(protocol_error)?;
        self.model = if name.contains("670") {
            Model::Pr670
        } else if name.contains("655") {
            Model::Pr655
        } else {
            return Err(InstrumentError::Protocol(format!(
                "D111 names '{name}', not a PR-655 or PR-670"
            )));
        };
        if self.model != self.expected {
            tracing::warn!(expected = self.expected.name(), found = %name, "another model answered");
        }
        let serial =
            parse_text_report(&self.command("D110", COMMAND_TIMEOUT_S)?).map_err(protocol_error)?;
        self.setting("SU1")?;
        self.set_sync(self.sync && !self.sync_off)?;
        Ok(InstrumentInfo {
            name: format!("Photo Research {}", self.model.name()),
            serial: Some(serial.trim().to_string()),
            capability: Capability::Spectral,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        let header = self.command("M5", self.model.measure_timeout_s())?;
        let code = parse_status(&header).map_err(protocol_error)?;
        let flagged = |status| Reading {
            status,
            device_code: Some(code.to_string()),
            raw: Some(header.clone()),
            ..Default::default()
        };
        match classify(code) {
            StatusKind::Ok => {}
            StatusKind::WeakLight => return Ok(flagged(ReadingStatus::BelowRange)),
            StatusKind::Overload => return Ok(flagged(ReadingStatus::Overload)),
            StatusKind::SyncFailure if self.sync && !self.sync_off => {
                tracing::warn!(code, "sync failed; measuring again without sync");
                self.sync_off = true;
                self.set_sync(false)?;
                return self.measure_once();
            }
            StatusKind::SyncFailure | StatusKind::Other => {
                return Err(InstrumentError::Device {
                    code: code.to_string(),
                    meaning: meaning(code).into(),
                });
            }
        }
        let spectrum = self.spectrum_rows()?;
        let d2 = self.command("D2", COMMAND_TIMEOUT_S)?;
        let (status, xyz) = parse_xyz(&d2).map_err(protocol_error)?;
        if status != 0 {
            return Err(InstrumentError::Protocol(format!(
                "D2 after a good M5 reports status {status}"
            )));
        }
        let xyz = Xyz::new(xyz[0], xyz[1], xyz[2]);
        check_spectrum(
            &spectrum,
            &xyz,
            380.0,
            self.model.step_nm(),
            self.model.rows(),
        )?;
        Ok(Reading {
            xyz: Some(xyz),
            spectrum: Some(spectrum),
            status: ReadingStatus::Ok,
            device_code: Some(code.to_string()),
            raw: Some(format!("{header}\\r\\n…\\r\\n{d2}")),
            ..Default::default()
        })
    }

    fn disconnect(&mut self) {
        let _ = self.link.send_paced(b"Q", CHARACTER_GAP_S);
    }
}
