//! Driver for the Konica Minolta LS-100, LS-110 and CS-100A.
//!
//! The meter must be put in remote mode by hand (switch on with F held). Session:
//! `MDS,04` (absolute measurements) answered `OK00`; a measurement is `MES`, answered
//! `OK00, <Y>` (LS) or `OK00, <Y>, <x>, <y>` (CS-100A).
//!
//! Codes: OK13 and OK11 (CS-100A) → flagged below range with the indicated values, and
//! an LS luminance under 0.001 cd/m² likewise; OK12, ER10, ER12, ER19 → flagged
//! overload, no value; ER00 → the command was garbled on the way, measure again; other
//! ER codes → a device error.

use super::protocol::{EOL, Model, REPLY_TIMEOUT_S, StatusKind, classify, meaning, parse_reply};
use crate::driver::Protocol;
use crate::transport::Link;
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus};
use chromacal_color::spaces::{Xyy, xyy_to_xyz};

pub struct Minolta {
    link: Link,
    model: Model,
    /// The meter has answered at least once.
    answered: bool,
}

impl Minolta {
    pub fn new(link: Link, model: Model) -> Self {
        Minolta {
            link,
            model,
            answered: false,
        }
    }

    fn command(&mut self, text: &str) -> Result<String, InstrumentError> {
        self.link.clear()?;
        self.link.send(format!("{text}\r\n").as_bytes())?;
        let answered = self.answered;
        let name = self.model.name();
        let line = self.link.read_line(EOL, REPLY_TIMEOUT_S).map_err(|e| match e {
            crate::transport::TransportError::Timeout { got, .. } if got.is_empty() => {
                if answered {
                    InstrumentError::Protocol(format!(
                        "the {name} stopped answering ({text}): it does so when its first reading after switching on is too dark, until it is switched off and on again (with F held)"
                    ))
                } else {
                    InstrumentError::Protocol(format!(
                        "the {name} does not answer {text}: it accepts remote commands only when switched on with F held"
                    ))
                }
            }
            other => other.into(),
        })?;
        self.answered = true;
        Ok(String::from_utf8_lossy(&line).to_string())
    }
}

impl Protocol for Minolta {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        self.link.sleep(0.2);
        let reply = self.command("MDS,04")?;
        let (status, _) = parse_reply(&reply).map_err(InstrumentError::Protocol)?;
        if !status.starts_with("OK") {
            return Err(InstrumentError::Device {
                meaning: format!("{} (after MDS,04)", meaning(&status)),
                code: status,
            });
        }
        Ok(InstrumentInfo {
            name: format!("Konica Minolta {}", self.model.name()),
            serial: Some("unknown (the meter does not report one)".into()),
            capability: if self.model.has_chromaticity() {
                Capability::Tristimulus
            } else {
                Capability::Luminance
            },
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        let reply = self.command("MES")?;
        let (status, values) = parse_reply(&reply).map_err(InstrumentError::Protocol)?;
        let kind = classify(&status);
        let base = Reading {
            device_code: Some(status.clone()),
            raw: Some(reply.trim_end().to_string()),
            ..Default::default()
        };
        match kind {
            StatusKind::Over => {
                return Ok(Reading {
                    status: ReadingStatus::Overload,
                    ..base
                });
            }
            StatusKind::Unknown => {
                return Err(InstrumentError::Protocol(format!(
                    "the meter did not understand MES: {reply}"
                )));
            }
            StatusKind::Error => {
                return Err(InstrumentError::Device {
                    meaning: meaning(&status).into(),
                    code: status,
                });
            }
            StatusKind::Ok | StatusKind::Below => {}
        }
        let expected = if self.model.has_chromaticity() { 3 } else { 1 };
        if values.len() != expected {
            return Err(InstrumentError::Protocol(format!(
                "'{}' has {} numbers, the {} sends {expected}",
                reply.trim_end(),
                values.len(),
                self.model.name()
            )));
        }
        let y = values[0];
        let below = kind == StatusKind::Below || y < self.model.lowest_cd_m2();
        let status = if below {
            ReadingStatus::BelowRange
        } else {
            ReadingStatus::Ok
        };
        Ok(if self.model.has_chromaticity() {
            Reading {
                xyz: Some(xyy_to_xyz(&Xyy {
                    x: values[1],
                    y: values[2],
                    big_y: y,
                })),
                status,
                ..base
            }
        } else {
            Reading {
                luminance: Some(y),
                status,
                ..base
            }
        })
    }
}
