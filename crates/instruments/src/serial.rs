//! The transport over a real serial port (or USB virtual COM port, or the slave side of
//! a pseudo-terminal), on the `serialport` crate.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use serialport::{ClearBuffer, DataBits, Parity, SerialPort, StopBits, TTYPort};

use super::transport::{Transport, TransportError};

/// Line settings of a port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialSettings {
    pub baud: u32,
    pub data_bits: DataBits,
    pub parity: Parity,
    pub stop_bits: StopBits,
}

impl SerialSettings {
    /// 8 data bits, no parity, 1 stop bit.
    pub const fn eight_n_one(baud: u32) -> Self {
        SerialSettings {
            baud,
            data_bits: DataBits::Eight,
            parity: Parity::None,
            stop_bits: StopBits::One,
        }
    }

    /// 7 data bits, even parity, 2 stop bits (Konica Minolta).
    pub const fn seven_e_two(baud: u32) -> Self {
        SerialSettings {
            baud,
            data_bits: DataBits::Seven,
            parity: Parity::Even,
            stop_bits: StopBits::Two,
        }
    }
}

/// A serial port.
pub struct SerialTransport {
    path: String,
    settings: SerialSettings,
    port: Option<TTYPort>,
    started: Instant,
}

fn io_error(path: &str) -> impl Fn(serialport::Error) -> TransportError + '_ {
    move |e| match e.kind() {
        serialport::ErrorKind::NoDevice => TransportError::Disconnected(format!("{path}: {e}")),
        serialport::ErrorKind::Io(std::io::ErrorKind::NotFound) => {
            TransportError::Disconnected(format!("{path}: {e}"))
        }
        serialport::ErrorKind::Io(std::io::ErrorKind::PermissionDenied) => {
            TransportError::Io(format!(
                "{path}: {e} (serial ports belong to group dialout: add yourself to it and log in again)"
            ))
        }
        _ => TransportError::Io(format!("{path}: {e}")),
    }
}

fn open_port(path: &str, settings: SerialSettings) -> Result<TTYPort, TransportError> {
    serialport::new(path, settings.baud)
        .data_bits(settings.data_bits)
        .parity(settings.parity)
        .stop_bits(settings.stop_bits)
        .flow_control(serialport::FlowControl::None)
        .timeout(Duration::from_millis(100))
        .open_native()
        .map_err(io_error(path))
}

impl SerialTransport {
    /// Open the port. One that cannot be opened never had a device to lose: its
    /// error is `Io` (what the system said), never `Disconnected`, which `reopen`
    /// gives when a device that was there has gone.
    pub fn open(path: &str, settings: SerialSettings) -> Result<Self, TransportError> {
        let port = open_port(path, settings).map_err(|e| match e {
            TransportError::Disconnected(m) => TransportError::Io(m),
            other => other,
        })?;
        Ok(SerialTransport {
            path: path.to_string(),
            settings,
            port: Some(port),
            started: Instant::now(),
        })
    }

    fn port(&mut self) -> Result<&mut TTYPort, TransportError> {
        self.port
            .as_mut()
            .ok_or_else(|| TransportError::Disconnected(format!("{}: closed", self.path)))
    }

    fn gone(&mut self, what: std::io::Error) -> TransportError {
        self.port = None;
        TransportError::Disconnected(format!("{}: {what}", self.path))
    }
}

impl Transport for SerialTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        let result = self
            .port()?
            .write_all(bytes)
            .and_then(|_| self.port.as_mut().map_or(Ok(()), |p| p.flush()));
        result.map_err(|e| self.gone(e))
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError> {
        let wait = Duration::from_secs_f64(timeout.max(0.0));
        let port = self.port()?;
        port.set_timeout(wait.max(Duration::from_millis(1)))
            .map_err(|e| TransportError::Io(e.to_string()))?;
        let mut buffer = [0u8; 4096];
        match port.read(&mut buffer) {
            Ok(0) => Err(self.gone(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "end of file",
            ))),
            Ok(n) => Ok(buffer[..n].to_vec()),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Err(TransportError::Timeout {
                waited: timeout,
                got: Vec::new(),
            }),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(Vec::new()),
            Err(e) => Err(self.gone(e)),
        }
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        let path = self.path.clone();
        self.port()?
            .clear(ClearBuffer::Input)
            .map_err(io_error(&path))
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), TransportError> {
        self.settings.baud = baud;
        let path = self.path.clone();
        self.port()?.set_baud_rate(baud).map_err(io_error(&path))
    }

    fn reopen(&mut self) -> Result<(), TransportError> {
        self.port = None;
        self.port = Some(open_port(&self.path, self.settings)?);
        Ok(())
    }

    fn sleep(&mut self, seconds: f64) {
        if seconds > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(seconds));
        }
    }

    fn now(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    fn describe(&self) -> String {
        self.path.clone()
    }
}

/// Ports the system lists, plus `extra` (pseudo-terminals are not listed).
pub fn candidate_ports(extra: &[String]) -> Vec<String> {
    let mut ports: Vec<String> = serialport::available_ports()
        .map(|v| v.into_iter().map(|p| p.port_name).collect())
        .unwrap_or_default();
    for p in extra {
        if !ports.contains(p) {
            ports.push(p.clone());
        }
    }
    ports
}
