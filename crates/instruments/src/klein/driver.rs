//! Driver for the Klein K-10 and K-10A colorimeters.
//!
//! Session (as ArgyllCMS): `P0` (model and serial), `D7` (stored calibrations), `L0`
//! (aiming lights off; some K-10As never answer it, which is not an error), `J8`
//! (auto-ranging), `P2` (firmware). A measurement is `N5`: X, Y, Z in the instrument's
//! factory calibration, a range byte and a status. Range errors (`u`, `v`) are measured
//! again up to four times; a `u` that stays is a reading flagged below range, a `v` or
//! `w` one flagged overload. At low light several readings are averaged, as Argyll does
//! (20 below 0.2 cd/m², 10 below 2, 4 below 20, 2 below 50).

use super::protocol::{
    StatusKind, classify, decode_value, meaning, reply_length, timeout_s, unframe,
};
use crate::driver::Protocol;
use crate::transport::{Link, escape};
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus};
use chromacal_color::Xyz;

/// Range errors measured again before they are reported.
const RANGE_RETRIES: usize = 4;

pub struct KleinK10 {
    link: Link,
    /// Names of the calibrations stored in the instrument.
    pub calibrations: Vec<String>,
}

impl KleinK10 {
    pub fn new(link: Link) -> Self {
        KleinK10 {
            link,
            calibrations: Vec::new(),
        }
    }

    /// Send a two-letter command and read its fixed-length reply; the payload and the
    /// status character.
    fn command(&mut self, command: &[u8; 2]) -> Result<(Vec<u8>, u8), InstrumentError> {
        let length = reply_length(command).ok_or_else(|| {
            InstrumentError::Protocol(format!("no reply length for {}", escape(command)))
        })?;
        // Argyll flushes before every write: a stale reply must not be read as this one.
        self.link.clear()?;
        self.link.send(&[command[0], command[1], b'\r'])?;
        let reply = self.link.read_exact(length, timeout_s(command))?;
        let (payload, status) = unframe(command, &reply).map_err(InstrumentError::Protocol)?;
        Ok((payload.to_vec(), status))
    }

    /// One `N5`, decoded: XYZ, ranges byte, status character.
    fn single_shot(&mut self) -> Result<(Xyz, u8), InstrumentError> {
        let (payload, status) = self.command(b"N5")?;
        let xyz = Xyz::new(
            decode_value(&payload[0..3]),
            decode_value(&payload[3..6]),
            decode_value(&payload[6..9]),
        );
        if !xyz.iter().all(|v| v.is_finite()) {
            return Err(InstrumentError::Protocol("N5 values are not finite".into()));
        }
        Ok((xyz, status))
    }
}

/// Readings Argyll averages at a given brightness (max of X, Y, Z in cd/m²).
pub fn readings_to_average(brightest: f64) -> usize {
    match brightest {
        v if v < 0.2 => 20,
        v if v < 2.0 => 10,
        v if v < 20.0 => 4,
        v if v < 50.0 => 2,
        _ => 1,
    }
}

impl Protocol for KleinK10 {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        let (id, status) = self.command(b"P0")?;
        if classify(status) != StatusKind::Ok {
            return Err(InstrumentError::Device {
                code: (status as char).to_string(),
                meaning: meaning(status).into(),
            });
        }
        let model = String::from_utf8_lossy(&id[..7]).trim().to_string();
        let serial = String::from_utf8_lossy(&id[7..16]).trim().to_string();
        if !model.starts_with("K") && !model.starts_with("KV") {
            return Err(InstrumentError::Protocol(format!(
                "P0 names '{model}', not a Klein K-10"
            )));
        }
        let (list, _) = self.command(b"D7")?;
        self.calibrations = list
            .chunks(20)
            .filter(|slot| slot.first() != Some(&0xFF))
            .map(|slot| String::from_utf8_lossy(slot).trim().to_string())
            .collect();
        match self.command(b"L0") {
            Ok(_) | Err(InstrumentError::Timeout { .. }) => {}
            Err(e) => return Err(e),
        }
        self.command(b"J8")?;
        let (firmware, _) = self.command(b"P2")?;
        tracing::debug!(firmware = %String::from_utf8_lossy(&firmware), "Klein firmware");
        Ok(InstrumentInfo {
            name: format!("Klein {model}"),
            serial: Some(serial),
            capability: Capability::Tristimulus,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        let mut tries = 0;
        let (first, status) = loop {
            let (xyz, status) = self.single_shot()?;
            match classify(status) {
                StatusKind::Under | StatusKind::Over if tries < RANGE_RETRIES => tries += 1,
                _ => break (xyz, status),
            }
        };
        let base = Reading {
            device_code: Some((status as char).to_string()),
            raw: Some(format!("N5 {:?} <{}>", first.as_slice(), status as char)),
            ..Default::default()
        };
        match classify(status) {
            StatusKind::Over => {
                return Ok(Reading {
                    status: ReadingStatus::Overload,
                    ..base
                });
            }
            StatusKind::Fault => {
                return Err(InstrumentError::Device {
                    code: (status as char).to_string(),
                    meaning: meaning(status).into(),
                });
            }
            StatusKind::Under => {
                return Ok(Reading {
                    xyz: Some(first),
                    status: ReadingStatus::BelowRange,
                    ..base
                });
            }
            StatusKind::Ok => {}
        }
        let n = readings_to_average(first.max());
        let mut sum = first;
        let mut taken = 1;
        while taken < n {
            let (xyz, status) = self.single_shot()?;
            if classify(status) == StatusKind::Ok {
                sum += xyz;
                taken += 1;
            } else {
                break;
            }
        }
        Ok(Reading {
            xyz: Some(sum / taken as f64),
            status: ReadingStatus::Ok,
            ..base
        })
    }

    fn resync(&mut self) -> Result<(), InstrumentError> {
        // Stop a flicker stream if one is running, then drop what is pending.
        let _ = self.link.send(b"N5\r");
        self.link.drain().map_err(InstrumentError::from)
    }
}
