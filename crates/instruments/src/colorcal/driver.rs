//! Driver for the CRS ColorCAL MKII over its USB serial port.
//!
//! Session: `IDR` (firmware, serial, build), `r01`–`r03` (the rows of the calibration
//! matrix held in the device, in "Minolta format"), and, for builds before 877, a zero
//! calibration (`UZC`, which fails with ER11 unless the sensor is covered). A
//! measurement is `MES`: raw tristimulus values that the host multiplies by the
//! matrix, giving XYZ in cd/m². Low light has no code: a luminance under 0.005 cd/m² is
//! flagged below range. Overload is undocumented; an `ER` reply to `MES` is reported as
//! a device error, except ER10, read as overload (an assumption).

use nalgebra::Matrix3;

use super::protocol::{
    COMMAND_TIMEOUT_S, FACTORY_CALIBRATED_BUILD, MEASURE_TIMEOUT_S, PROMPT, minolta_to_float,
    parse_fields, payload_lines,
};
use crate::driver::Protocol;
use crate::transport::Link;
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus};
use chromacal_color::Xyz;

/// Lowest luminance the ColorCAL MKII reads reliably (cd/m²).
const LOWEST_CD_M2: f64 = 0.005;

pub struct ColorCal {
    link: Link,
    matrix: Matrix3<f64>,
}

impl ColorCal {
    pub fn new(link: Link) -> Self {
        ColorCal {
            link,
            matrix: Matrix3::identity(),
        }
    }

    /// Send a command; the payload lines up to the prompt.
    fn command(&mut self, text: &str, timeout: f64) -> Result<Vec<String>, InstrumentError> {
        self.link.clear()?;
        self.link.send(format!("{text}\n").as_bytes())?;
        let reply = self.link.read_until_any(&[PROMPT], timeout)?;
        let lines = payload_lines(&reply);
        if lines.is_empty() {
            return Err(InstrumentError::Protocol(format!(
                "{text} got an empty reply"
            )));
        }
        Ok(lines)
    }

    fn fields(&mut self, text: &str, timeout: f64) -> Result<(String, Vec<f64>), InstrumentError> {
        let lines = self.command(text, timeout)?;
        parse_fields(&lines[lines.len() - 1]).map_err(InstrumentError::Protocol)
    }
}

impl Protocol for ColorCal {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        let lines = self.command("IDR", COMMAND_TIMEOUT_S)?;
        let id = &lines[lines.len() - 1];
        let f: Vec<&str> = id.split(',').map(str::trim).collect();
        if f.first() != Some(&"OK00") || f.len() < 6 {
            return Err(InstrumentError::Protocol(format!("IDR answered '{id}'")));
        }
        let serial = f[4].to_string();
        let build: u32 = f[f.len() - 1].parse().unwrap_or(0);
        for row in 0..3 {
            let (status, v) = self.fields(&format!("r0{}", row + 1), COMMAND_TIMEOUT_S)?;
            if status != "OK00" || v.len() != 3 {
                return Err(InstrumentError::Protocol(format!(
                    "matrix row {} answered {status} {v:?}",
                    row + 1
                )));
            }
            for (c, value) in v.iter().enumerate() {
                self.matrix[(row, c)] = minolta_to_float(value.round() as i64);
            }
        }
        if build < FACTORY_CALIBRATED_BUILD {
            let (status, _) = self.fields("UZC", COMMAND_TIMEOUT_S)?;
            if status != "OK00" {
                return Err(InstrumentError::Device {
                    code: status,
                    meaning: format!(
                        "zero calibration failed: firmware build {build} needs one after every power-up; cover the sensor and connect again"
                    ),
                });
            }
        }
        Ok(InstrumentInfo {
            name: "CRS ColorCAL MKII".into(),
            serial: Some(serial),
            capability: Capability::Tristimulus,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        let (status, raw) = self.fields("MES", MEASURE_TIMEOUT_S)?;
        let base = Reading {
            device_code: Some(status.clone()),
            raw: Some(format!("{status},{raw:?}")),
            ..Default::default()
        };
        if status == "ER10" {
            return Ok(Reading {
                status: ReadingStatus::Overload,
                ..base
            });
        }
        if status != "OK00" {
            return Err(InstrumentError::Device {
                code: status,
                meaning: "MES failed".into(),
            });
        }
        if raw.len() != 3 {
            return Err(InstrumentError::Protocol(format!(
                "MES gave {} numbers, not 3",
                raw.len()
            )));
        }
        let xyz = self.matrix * Xyz::new(raw[0], raw[1], raw[2]);
        Ok(Reading {
            xyz: Some(xyz),
            status: if xyz.y < LOWEST_CD_M2 {
                ReadingStatus::BelowRange
            } else {
                ReadingStatus::Ok
            },
            ..base
        })
    }
}
