//! Driver for the JETI specbos 1211.
//!
//! Session (as ArgyllCMS): probe 921600, 115200 and 38400 baud with `*idn?`; then
//! `*conf:default`, `*para:calibn 0`, `*para:expo 1`, `*conf:maxtin 3000`,
//! `*conf:func 6`, `*conf:form 4`, `*conf:wran 380 830 1`, `*conf:aver 1`. A
//! measurement: `*contr:mhead?` (the diffuser must be off), `*contr:laser 0`, refresh
//! sync (`*contr:cyctim 200 4000`, `*conf:cycmod 1`) where asked for, `*init` (ACK, then
//! BEL when done, or NAK), `*fetch:XYZ`, `*fetch:sprad`.
//!
//! After a NAK the error is read with `*stat:err?`: 121 (underexposure) → a reading
//! flagged below range; 120 (overexposure) → flagged overload; 160/161 (sync) → sync
//! off (`*conf:cycmod 0`) and measure again; 123 → measure again; others → a device
//! error. The spectrum fetch is retried up to 5 times, as Argyll does, because the
//! specbos can overrun its own serial buffer.

use super::protocol::{
    ACK, BAUD_RATES, BEL, CR, CYCLE_TIMEOUT_S, ENQ, ErrorKind, FETCH_SPECTRUM_TIMEOUT_S,
    FETCH_XYZ_TIMEOUT_S, INIT_TIMEOUT_S, NAK, PROBE_TIMEOUT_S, SETTING_TIMEOUT_S, WAVELENGTH_END,
    WAVELENGTH_START, bands, classify, labelled_value, meaning, parse_error_code, strip_enq,
};
use crate::driver::Protocol;
use crate::transport::{Link, escape};
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus, check_spectrum};
use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

const FETCH_TRIES: usize = 5;

pub struct Specbos {
    link: Link,
    sync: bool,
    sync_off: bool,
}

fn protocol(e: String) -> InstrumentError {
    InstrumentError::Protocol(e)
}

impl Specbos {
    pub fn new(link: Link, sync: bool) -> Self {
        Specbos {
            link,
            sync,
            sync_off: false,
        }
    }

    fn send(&mut self, command: &str) -> Result<(), InstrumentError> {
        self.link.clear()?;
        self.link.send(format!("{command}\r").as_bytes())?;
        Ok(())
    }

    /// A text line ended by CR, without ENQ bytes.
    fn line(&mut self, timeout: f64) -> Result<String, InstrumentError> {
        loop {
            let raw = self.link.read_line(CR, timeout)?;
            let text = String::from_utf8_lossy(&strip_enq(&raw)).trim().to_string();
            if !text.is_empty() {
                return Ok(text);
            }
        }
    }

    /// Wait for one of `wanted` control bytes (ENQ ignored); NAK is an instrument error.
    fn control(&mut self, wanted: &[u8], timeout: f64) -> Result<u8, InstrumentError> {
        loop {
            let chunk = self.link.read_until_any(&[ACK, NAK, BEL], timeout)?;
            let Some(&last) = chunk.last() else { continue };
            let stray: Vec<u8> = chunk[..chunk.len() - 1]
                .iter()
                .copied()
                .filter(|b| *b != ENQ)
                .collect();
            if !stray.is_empty() {
                return Err(protocol(format!(
                    "unexpected bytes before a control byte: {}",
                    escape(&stray)
                )));
            }
            if last == NAK {
                return Err(self.error_code());
            }
            if wanted.contains(&last) {
                return Ok(last);
            }
        }
    }

    /// After a NAK: the error the instrument reports.
    fn error_code(&mut self) -> InstrumentError {
        let result = self
            .send("*stat:err?")
            .and_then(|_| self.line(SETTING_TIMEOUT_S));
        match result.map(|l| parse_error_code(&l)) {
            Ok(Ok(code)) => InstrumentError::Device {
                code: code.to_string(),
                meaning: meaning(code).into(),
            },
            Ok(Err(e)) => protocol(e),
            Err(e) => e,
        }
    }

    fn setting(&mut self, command: &str) -> Result<(), InstrumentError> {
        self.send(command)?;
        self.control(&[ACK], SETTING_TIMEOUT_S).map(|_| ())
    }

    fn query(&mut self, command: &str, timeout: f64) -> Result<String, InstrumentError> {
        self.send(command)?;
        self.line(timeout)
    }

    fn probe(&mut self) -> Result<String, InstrumentError> {
        let mut last = None;
        for baud in BAUD_RATES {
            self.link.set_baud(baud)?;
            match self.query("*idn?", PROBE_TIMEOUT_S) {
                Ok(id) if id.contains("JETI_SB") || id.starts_with("SB05") => return Ok(id),
                Ok(other) => {
                    last = Some(protocol(format!("*idn? answered '{other}' at {baud} baud")))
                }
                Err(e @ InstrumentError::Disconnected(_)) => return Err(e),
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| protocol("no answer to *idn?".into())))
    }

    fn fetch_xyz(&mut self) -> Result<Xyz, InstrumentError> {
        self.send("*fetch:XYZ")?;
        let mut v = [0.0; 3];
        for (i, label) in ["X", "Y", "Z"].iter().enumerate() {
            let line = self.line(FETCH_XYZ_TIMEOUT_S)?;
            if !line.starts_with(label) {
                return Err(protocol(format!("expected '{label}: …', got '{line}'")));
            }
            v[i] = labelled_value(&line).map_err(protocol)?;
        }
        Ok(Xyz::new(v[0], v[1], v[2]))
    }

    fn fetch_spectrum(&mut self) -> Result<Spectrum, InstrumentError> {
        let mut last = None;
        for _ in 0..FETCH_TRIES {
            match self.fetch_spectrum_once() {
                Ok(s) => return Ok(s),
                Err(e @ InstrumentError::Disconnected(_)) => return Err(e),
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| protocol("no spectrum".into())))
    }

    fn fetch_spectrum_once(&mut self) -> Result<Spectrum, InstrumentError> {
        self.send("*fetch:sprad")?;
        // Two header lines, one value per band, then an empty line.
        for _ in 0..2 {
            self.link.read_line(CR, FETCH_SPECTRUM_TIMEOUT_S)?;
        }
        let n = bands();
        let mut values = Vec::with_capacity(n);
        for _ in 0..n {
            let raw = self.link.read_line(CR, FETCH_SPECTRUM_TIMEOUT_S)?;
            let text = String::from_utf8_lossy(&strip_enq(&raw)).trim().to_string();
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => values.push(v),
                _ => return Err(protocol(format!("spectrum value '{text}' is not a number"))),
            }
        }
        self.link.read_line(CR, FETCH_SPECTRUM_TIMEOUT_S)?;
        let wavelengths = (0..n)
            .map(|i| (WAVELENGTH_START as usize + i) as f64)
            .collect();
        Spectrum::new(wavelengths, values).map_err(|e| protocol(format!("spectrum: {e}")))
    }

    /// Turn refresh sync on (measuring the period first) or off.
    fn configure_sync(&mut self) -> Result<(), InstrumentError> {
        if !self.sync || self.sync_off {
            return self.setting("*conf:cycmod 0");
        }
        self.send("*contr:cyctim 200 4000")?;
        let period = match self.control(&[ACK], CYCLE_TIMEOUT_S) {
            Ok(_) => labelled_value(&self.line(CYCLE_TIMEOUT_S)?).map_err(protocol)?,
            Err(InstrumentError::Device { code, .. }) => {
                tracing::warn!(%code, "the specbos cannot find the refresh; measuring without sync");
                self.sync_off = true;
                return self.setting("*conf:cycmod 0");
            }
            Err(e) => return Err(e),
        };
        self.setting("*conf:cycmod 1")?;
        self.setting(&format!("*conf:cyctim {:.0}", period * 1000.0))
    }
}

impl Protocol for Specbos {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        let id = self.probe()?;
        let serial = self
            .query("*para:spnum?", SETTING_TIMEOUT_S)
            .map(|l| l.rsplit(':').next().unwrap_or("").trim().to_string())?;
        for setting in [
            "*conf:default",
            "*para:calibn 0",
            "*para:expo 1",
            "*conf:maxtin 3000",
            "*conf:func 6",
            "*conf:form 4",
        ] {
            self.setting(setting)?;
        }
        let start =
            labelled_value(&self.query("*para:wavbeg?", SETTING_TIMEOUT_S)?).map_err(protocol)?;
        let end =
            labelled_value(&self.query("*para:wavend?", SETTING_TIMEOUT_S)?).map_err(protocol)?;
        if start > WAVELENGTH_START as f64 || end < WAVELENGTH_END as f64 {
            return Err(protocol(format!(
                "the instrument covers {start}–{end} nm, not {WAVELENGTH_START}–{WAVELENGTH_END}"
            )));
        }
        self.setting(&format!("*conf:wran {WAVELENGTH_START} {WAVELENGTH_END} 1"))?;
        self.setting("*conf:aver 1")?;
        Ok(InstrumentInfo {
            name: format!("JETI {}", id.split_whitespace().next().unwrap_or("specbos")),
            serial: Some(serial),
            capability: Capability::Spectral,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        let head = self.query("*contr:mhead?", SETTING_TIMEOUT_S)?;
        if labelled_value(&head).map_err(protocol)? != 0.0 {
            return Err(InstrumentError::Device {
                code: "mhead".into(),
                meaning:
                    "the ambient diffuser is on the measuring head: remove it to measure a display"
                        .into(),
            });
        }
        self.setting("*contr:laser 0")?;
        self.configure_sync()?;
        self.setting("*conf:aver 1")?;
        self.send("*init")?;
        let outcome = self
            .control(&[ACK], SETTING_TIMEOUT_S)
            .and_then(|_| self.control(&[BEL], INIT_TIMEOUT_S));
        if let Err(InstrumentError::Device { code, meaning }) = outcome {
            let number: u32 = code.parse().unwrap_or(0);
            let flagged = |status| Reading {
                status,
                device_code: Some(code.clone()),
                raw: Some(format!("NAK, Error Code: {code}")),
                ..Default::default()
            };
            return match classify(number) {
                ErrorKind::Underexposure => Ok(flagged(ReadingStatus::BelowRange)),
                ErrorKind::Overexposure => Ok(flagged(ReadingStatus::Overload)),
                ErrorKind::SyncFailure if self.sync && !self.sync_off => {
                    tracing::warn!("sync failed; measuring again without sync");
                    self.sync_off = true;
                    self.measure_once()
                }
                ErrorKind::Misread => Err(protocol(format!("misread: {meaning}"))),
                _ => Err(InstrumentError::Device { code, meaning }),
            };
        }
        outcome?;
        let xyz = self.fetch_xyz()?;
        let spectrum = self.fetch_spectrum()?;
        check_spectrum(&spectrum, &xyz, WAVELENGTH_START as f64, 1.0, bands())?;
        Ok(Reading {
            xyz: Some(xyz),
            spectrum: Some(spectrum),
            status: ReadingStatus::Ok,
            device_code: Some("BEL".into()),
            raw: Some(format!("X:\t{}\rY:\t{}\rZ:\t{}\r", xyz.x, xyz.y, xyz.z)),
            ..Default::default()
        })
    }
}
