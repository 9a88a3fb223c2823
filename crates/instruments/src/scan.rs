//! Finding instruments: probe serial ports for each known protocol, with a short bound
//! per port so a silent port never stalls the scan. Ports are probed in parallel.
//!
//! Each family is asked its own identification, with probe-length timeouts: Klein
//! `P0`, JETI `*idn?` at its three rates, ColorCAL `IDR`, Minolta `MDS,04`, PR-650
//! `b3`, PR-655/670 `PHOTO` … `D111` (then `Q`). A port that fails to open is reported
//! as such, not probed.

use std::time::{Duration, Instant};

use super::devices::DeviceKind;
use super::serial::{SerialSettings, SerialTransport};
use super::transport::{Link, TransportError};

/// Longest time one port may take.
pub const PORT_BUDGET_S: f64 = 6.0;

/// What a port turned out to be.
#[derive(Debug, Clone, PartialEq)]
pub enum PortFinding {
    Found { kind: DeviceKind, identity: String },
    Silent,
    Unopenable(String),
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).trim().to_string()
}

/// Open `path` with `settings` and run `ask` on it.
fn try_with(
    path: &str,
    settings: SerialSettings,
    ask: impl FnOnce(&mut Link) -> Result<Option<(DeviceKind, String)>, TransportError>,
) -> Result<Option<(DeviceKind, String)>, TransportError> {
    let transport = SerialTransport::open(path, settings)?;
    let mut link = Link::new(Box::new(transport), 1.0);
    // Drop what an earlier probe's question may still be bringing back.
    link.sleep(0.05);
    link.clear()?;
    ask(&mut link)
}

fn klein(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    link.send(b"P0\r")?;
    let reply = link.read_exact(21, 0.5)?;
    Ok((reply.starts_with(b"P0") && reply[2] == b'K').then(|| {
        (
            DeviceKind::K10a,
            format!("{} serial {}", text(&reply[2..9]), text(&reply[9..18])),
        )
    }))
}

fn jeti(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    for baud in super::jeti::protocol::BAUD_RATES {
        link.set_baud(baud)?;
        link.send(b"*idn?\r")?;
        if let Ok(line) = link.read_line(b"\r", 0.3) {
            let id = text(&super::jeti::protocol::strip_enq(&line));
            if id.contains("JETI_SB") {
                return Ok(Some((
                    DeviceKind::Specbos1211,
                    format!("{id} at {baud} baud"),
                )));
            }
        }
    }
    Ok(None)
}

fn colorcal(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    link.send(b"IDR\n")?;
    let reply = link.read_until_any(b">", 0.5)?;
    let lines = super::colorcal::protocol::payload_lines(&reply);
    Ok(lines
        .last()
        .filter(|l| l.starts_with("OK00,1,"))
        .map(|l| (DeviceKind::ColorCal2, format!("ColorCAL MKII, IDR {l}"))))
}

fn minolta(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    link.send(b"MDS,04\r\n")?;
    // Another device's late answer may come first; look at every line for 0.5 s.
    let started = link.transport().now();
    while link.transport().now() - started < 0.5 {
        let line = text(&link.read_line(b"\r\n", 0.5)?);
        if line.starts_with("OK") {
            return Ok(Some((
                DeviceKind::Ls100,
                "Konica Minolta LS-100, LS-110 or CS-100A (the protocol does not say which)"
                    .to_string(),
            )));
        }
    }
    Ok(None)
}

fn pr650(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    link.send(b"b3\n")?;
    let line = text(&link.read_line(b"\r\n", 0.5)?);
    Ok((line == "000").then(|| (DeviceKind::Pr650, "Photo Research PR-650".to_string())))
}

fn pr6xx(link: &mut Link) -> Result<Option<(DeviceKind, String)>, TransportError> {
    link.send_paced(b"Q", 0.05)?;
    link.sleep(0.2);
    link.clear()?;
    link.send_paced(b"PHOTO", 0.05)?;
    let reply = link.read_until_silence(1.0, 0.2)?;
    if !text(&reply).contains("REMOTE MODE") {
        return Ok(None);
    }
    link.send_paced(b"D111\r", 0.05)?;
    let name = text(&link.read_line(b"\r\n", 1.0)?);
    link.send_paced(b"Q", 0.05)?;
    let kind = if name.contains("655") {
        DeviceKind::Pr655
    } else {
        DeviceKind::Pr670
    };
    Ok(Some((
        kind,
        format!(
            "Photo Research {}",
            name.rsplit(',').next().unwrap_or(&name)
        ),
    )))
}

/// Probe one port for every known instrument, within [`PORT_BUDGET_S`].
pub fn probe_port(path: &str) -> PortFinding {
    let started = Instant::now();
    type Probe = fn(&mut Link) -> Result<Option<(DeviceKind, String)>, TransportError>;
    let probes: [(SerialSettings, Probe); 6] = [
        (SerialSettings::eight_n_one(9600), klein),
        (SerialSettings::eight_n_one(921_600), jeti),
        (SerialSettings::eight_n_one(115_200), colorcal),
        (SerialSettings::seven_e_two(4800), minolta),
        (SerialSettings::eight_n_one(9600), pr650),
        (SerialSettings::eight_n_one(9600), pr6xx),
    ];
    for (i, (settings, probe)) in probes.into_iter().enumerate() {
        if started.elapsed() > Duration::from_secs_f64(PORT_BUDGET_S) {
            break;
        }
        match try_with(path, settings, probe) {
            Ok(Some((kind, identity))) => return PortFinding::Found { kind, identity },
            Ok(None) | Err(TransportError::Timeout { .. }) => {}
            Err(e) if i == 0 => return PortFinding::Unopenable(e.to_string()),
            Err(_) => {}
        }
    }
    PortFinding::Silent
}

/// Probe every port in parallel.
pub fn scan(ports: &[String]) -> Vec<(String, PortFinding)> {
    let handles: Vec<_> = ports
        .iter()
        .cloned()
        .map(|p| std::thread::spawn(move || (p.clone(), probe_port(&p))))
        .collect();
    handles.into_iter().filter_map(|h| h.join().ok()).collect()
}
