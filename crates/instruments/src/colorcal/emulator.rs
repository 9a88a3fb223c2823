//! Emulated CRS ColorCAL MKII: `IDR`, `r01`–`r09` (a calibration matrix in "Minolta
//! format"), `MES` (raw values that the matrix turns into XYZ), `UZC` (ER11 while light
//! reaches the sensor), `?`; every reply framed as `\n\r` … `\n\r>`.

use nalgebra::Matrix3;

use super::protocol::{float_to_minolta, frame};
use crate::emulator::{CommandLines, DeviceModel, Measured, Meter, Scheduled};
use chromacal_color::Xyz;

pub struct ColorCalEmulator {
    meter: Meter,
    /// The device's calibration matrix: XYZ = matrix · raw.
    matrix: Matrix3<f64>,
    build: u32,
    input: CommandLines,
}

impl ColorCalEmulator {
    /// A ColorCAL with firmware `build` (877 and later are factory zero-calibrated).
    pub fn new(meter: Meter, build: u32) -> Self {
        ColorCalEmulator {
            meter,
            // A plausible sensor: a little cross-talk between the channels.
            matrix: Matrix3::new(
                1.063, -0.0347, 0.012, 0.021, 0.9871, -0.0093, -0.004, 0.0188, 1.0412,
            ),
            build,
            input: CommandLines::default(),
        }
    }

    fn reply(lines: &[String], delay: f64) -> Vec<Scheduled> {
        vec![Scheduled::after(delay, frame(lines))]
    }

    fn command(&mut self, line: &str) -> Vec<Scheduled> {
        match line.to_ascii_uppercase().as_str() {
            "IDR" => Self::reply(&[format!("OK00,1,102,100.10,07A2C91,{}", self.build)], 0.05),
            "MES" => {
                let measured = self.meter.measure(false);
                let delay = measured.integration_s().min(2.0) + 0.2;
                let xyz = match measured {
                    Measured::Ok(r) => r.xyz.unwrap_or_default(),
                    Measured::LowLight(_) => Xyz::zeros(),
                    Measured::Overload { .. } | Measured::SyncFailed { .. } => {
                        return Self::reply(&["ER10".to_string()], delay);
                    }
                };
                let raw = self.matrix.try_inverse().unwrap_or_else(Matrix3::identity) * xyz;
                Self::reply(
                    &[format!("OK00,{:6.2},{:6.2},{:6.2}", raw.x, raw.y, raw.z)],
                    delay,
                )
            }
            "UZC" => {
                let measured = self.meter.measure(false);
                let dark = match measured {
                    Measured::Ok(r) | Measured::LowLight(r) => r.luminance().unwrap_or(0.0) < 0.01,
                    _ => false,
                };
                Self::reply(&[if dark { "OK00" } else { "ER11" }.to_string()], 1.0)
            }
            "?" => Self::reply(
                &[
                    "OK00".into(),
                    "ColorCAL MKII commands: IDR MES UZC r01-r09".into(),
                ],
                0.05,
            ),
            cmd if cmd.len() == 3 && cmd.starts_with('R') => {
                let n: usize = cmd[1..].parse().unwrap_or(0);
                if !(1..=9).contains(&n) {
                    return Self::reply(&["ER00".into()], 0.05);
                }
                let m = if n <= 3 {
                    self.matrix
                } else {
                    Matrix3::identity()
                };
                let row = (n - 1) % 3;
                Self::reply(
                    &[format!(
                        "OK00,{:5},{:5},{:5}",
                        float_to_minolta(m[(row, 0)]),
                        float_to_minolta(m[(row, 1)]),
                        float_to_minolta(m[(row, 2)])
                    )],
                    0.05,
                )
            }
            _ => Self::reply(&["ER00".into()], 0.05),
        }
    }
}

impl DeviceModel for ColorCalEmulator {
    fn name(&self) -> &'static str {
        "ColorCAL MKII"
    }

    fn receive(&mut self, bytes: &[u8], _now: f64, _baud: u32) -> Vec<Scheduled> {
        let lines = self.input.push(bytes);
        lines.iter().flat_map(|l| self.command(l)).collect()
    }
}
