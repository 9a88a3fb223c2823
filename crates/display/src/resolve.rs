//! The DaVinci Resolve calibration protocol, as pattern generators speak it
//! (PGenerator, pgen_client; DisplayCAL's senders; `../shared/INTERFACES.md` A1).
//!
//! chromacal is the TCP server (default 127.0.0.1:20002); a pattern generator connects
//! to it and shows each message: a 4-byte big-endian length, then UTF-8 XML, in the
//! Calman flavour (`<color … bits>`, `<background>`, `<geometry x y cx cy>`) or the
//! LightSpace one (`<shapes><rectangle>`). Nothing comes back, so there is no
//! acknowledgement: after each patch the run waits the display's settle time. A
//! generator that disconnects (a write fails, or the socket reads end-of-file) pauses
//! the run until one connects again; the patch is then sent again, so nothing measured
//! is lost and nothing is measured on a screen that did not change.

use std::io::Read;
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream as AsyncTcpStream};

use super::{DisplayError, PatchDisplay};
use chromacal_model::screen::{Codes, Geometry, Patch, ScreenContent};
use chromacal_sim::monitor::VirtualMonitor;

/// Which XML the messages use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Flavour {
    /// Calman style (DisplayCAL's default): colour, background and their bit depth.
    #[default]
    Cm,
    /// LightSpace style: one rectangle, 8-bit, no background.
    Ls,
}

/// `[display.resolve]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ResolveConfig {
    /// Where to listen; loopback unless you mean to let another machine's generator in.
    pub address: String,
    pub flavour: Flavour,
    /// Video levels (16–235 at 8 bits) instead of full range.
    pub video_levels: bool,
    /// Give up when no generator connects for this long (seconds); none: wait forever.
    pub connect_timeout_s: Option<f64>,
}

impl Default for ResolveConfig {
    fn default() -> Self {
        ResolveConfig {
            address: "127.0.0.1:20002".into(),
            flavour: Flavour::Cm,
            video_levels: false,
            connect_timeout_s: None,
        }
    }
}

/// Code value of a normalised drive, full range or video levels (DisplayCAL
/// `_get_rgb`; for more than 8 bits the video range is the 8-bit one shifted up).
pub fn code_value(v: f64, bits: u32, video_levels: bool) -> u32 {
    let max = ((1u64 << bits) - 1) as f64;
    let v = v.clamp(0.0, 1.0);
    if !video_levels {
        return (v * max).round() as u32;
    }
    let shift = (1u64 << bits.saturating_sub(8)) as f64;
    let low = 16.0 * shift;
    let high = 235.0 * shift;
    (low + v * (high - low)).round() as u32
}

/// Normalised drive of a code value (inverse of [`code_value`]).
pub fn drive_of(code: u32, bits: u32, video_levels: bool) -> f64 {
    let max = ((1u64 << bits) - 1) as f64;
    if !video_levels {
        return (code as f64 / max).clamp(0.0, 1.0);
    }
    let shift = (1u64 << bits.saturating_sub(8)) as f64;
    ((code as f64 - 16.0 * shift) / (219.0 * shift)).clamp(0.0, 1.0)
}

/// Code values of `codes` as sent: the patch's own codes at full range, or mapped
/// onto video levels at the same depth.
fn sent_codes(codes: &Codes, video_levels: bool) -> [u32; 3] {
    if video_levels {
        codes.drive().map(|v| code_value(v, codes.bit_depth, true))
    } else {
        codes.rgb
    }
}

/// The XML message for a patch. The Calman flavour sends the plan's codes at the
/// plan's depth, so what the generator shows is exactly what the journal records; the
/// LightSpace flavour is 8-bit only (checked when the display is opened).
pub fn message(patch: &Patch, config: &ResolveConfig) -> String {
    let g = patch.geometry;
    match config.flavour {
        Flavour::Cm => {
            let c = sent_codes(&patch.codes, config.video_levels);
            let b = sent_codes(&patch.background, config.video_levels);
            let (cb, bb) = (patch.codes.bit_depth, patch.background.bit_depth);
            format!(
                r#"<?xml version="1.0" encoding="utf-8"?><calibration><color red="{}" green="{}" blue="{}" bits="{cb}"/><background red="{}" green="{}" blue="{}" bits="{bb}"/><geometry x="{:.4}" y="{:.4}" cx="{:.4}" cy="{:.4}"/></calibration>"#,
                c[0], c[1], c[2], b[0], b[1], b[2], g.x, g.y, g.width, g.height
            )
        }
        Flavour::Ls => {
            let c = patch
                .codes
                .drive()
                .map(|v| code_value(v, 8, config.video_levels));
            format!(
                r#"<?xml version="1.0" encoding="UTF-8" ?><calibration><shapes><rectangle><color red="{}" green="{}" blue="{}" /><geometry x="{:.4}" y="{:.4}" cx="{:.4}" cy="{:.4}" /></rectangle></shapes></calibration>"#,
                c[0], c[1], c[2], g.x, g.y, g.width, g.height
            )
        }
    }
}

/// Length-prefixed frame of a message.
pub fn frame(xml: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + xml.len());
    out.extend_from_slice(&(xml.len() as u32).to_be_bytes());
    out.extend_from_slice(xml.as_bytes());
    out
}

/// The first child element of `parent` called `name`.
fn child<'a, 'input>(
    parent: roxmltree::Node<'a, 'input>,
    name: &str,
) -> Option<roxmltree::Node<'a, 'input>> {
    parent
        .children()
        .find(|n| n.is_element() && n.tag_name().name() == name)
}

/// What a generator shows for one message: drives in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pattern {
    pub content: ScreenContent,
    pub bits: u32,
}

/// Read a message as a generator does (PGenerator `resolve.pm`): `color@bits` defaults
/// to 8, the background takes the colour's depth, geometry defaults to full field, a
/// decimal comma is read as a point, and geometry above 1 is in pixels of a 1920×1080
/// screen. LightSpace `<shapes>`: with two rectangles the first is the background.
pub fn parse_message(xml: &str, video_levels: bool) -> Result<Pattern, String> {
    let doc = roxmltree::Document::parse(xml).map_err(|e| format!("not XML: {e}"))?;
    let root = doc.root_element();
    if root.tag_name().name() != "calibration" {
        return Err(format!(
            "root element <{}>, not <calibration>",
            root.tag_name().name()
        ));
    }
    let number = |node: roxmltree::Node<'_, '_>, name: &str, default: f64| -> Result<f64, String> {
        match node.attribute(name) {
            None => Ok(default),
            Some(text) => text
                .replace(',', ".")
                .trim()
                .parse::<f64>()
                .map_err(|_| format!("{name}=\"{text}\" is not a number")),
        }
    };
    let rgb = |node: roxmltree::Node<'_, '_>| -> Result<[f64; 3], String> {
        Ok([
            number(node, "red", 0.0)?,
            number(node, "green", 0.0)?,
            number(node, "blue", 0.0)?,
        ])
    };
    let (color, background, geometry) = match child(root, "shapes") {
        Some(shapes) => {
            let rects: Vec<_> = shapes
                .children()
                .filter(|n| n.is_element() && n.tag_name().name() == "rectangle")
                .collect();
            let (bg, patch) = match rects.as_slice() {
                [p] => (None, *p),
                [b, p, ..] => (Some(*b), *p),
                [] => return Err("<shapes> has no <rectangle>".into()),
            };
            let color = child(patch, "colex").or(child(patch, "color"));
            (
                color,
                bg.and_then(|b| child(b, "colex").or(child(b, "color"))),
                child(patch, "geometry"),
            )
        }
        None => (
            child(root, "color"),
            child(root, "background"),
            child(root, "geometry"),
        ),
    };
    let color = color.ok_or("no <color>")?;
    let bits = number(color, "bits", 8.0)? as u32;
    if !(1..=16).contains(&bits) {
        return Err(format!("bits=\"{bits}\" is out of range"));
    }
    let to_drive = |c: [f64; 3]| c.map(|v| drive_of(v.max(0.0).round() as u32, bits, video_levels));
    let patch = to_drive(rgb(color)?);
    let background = match background {
        Some(b) => {
            let bg_bits = number(b, "bits", bits as f64)? as u32;
            if !(1..=16).contains(&bg_bits) {
                return Err(format!("background bits=\"{bg_bits}\" is out of range"));
            }
            rgb(b)?.map(|v| drive_of(v.max(0.0).round() as u32, bg_bits, video_levels))
        }
        None => [0.0; 3],
    };
    let mut g = match geometry {
        Some(g) => [
            number(g, "x", 0.0)?,
            number(g, "y", 0.0)?,
            number(g, "cx", 1.0)?,
            number(g, "cy", 1.0)?,
        ],
        None => [0.0, 0.0, 1.0, 1.0],
    };
    if g[2] > 1.0 || g[3] > 1.0 {
        g = [g[0] / 1920.0, g[1] / 1080.0, g[2] / 1920.0, g[3] / 1080.0];
    }
    Ok(Pattern {
        content: ScreenContent {
            patch,
            background,
            geometry: Geometry {
                x: g[0],
                y: g[1],
                width: g[2],
                height: g[3],
            },
        },
        bits,
    })
}

/// The Resolve server as a patch display.
pub struct ResolveDisplay {
    listener: TcpListener,
    stream: Option<AsyncTcpStream>,
    config: ResolveConfig,
    settle_s: f64,
    /// Times a generator went away during the run.
    pub disconnections: usize,
}

fn lost(e: impl std::fmt::Display) -> DisplayError {
    DisplayError::Lost(e.to_string())
}

impl ResolveDisplay {
    /// Listen on `config.address` (port 0 picks a free one).
    pub async fn bind(config: ResolveConfig, settle_s: f64) -> Result<Self, DisplayError> {
        let listener = TcpListener::bind(&config.address)
            .await
            .map_err(|e| DisplayError::Lost(format!("cannot listen on {}: {e}", config.address)))?;
        if let Ok(addr) = listener.local_addr()
            && !addr.ip().is_loopback()
        {
            tracing::warn!(%addr, "the Resolve server listens beyond this machine: any host that can reach it can show patterns");
        }
        Ok(ResolveDisplay {
            listener,
            stream: None,
            config,
            settle_s,
            disconnections: 0,
        })
    }

    pub fn local_addr(&self) -> Result<SocketAddr, DisplayError> {
        self.listener.local_addr().map_err(lost)
    }

    /// True when the generator has closed its side (a read would give end-of-file).
    fn peer_closed(&self) -> bool {
        let Some(stream) = &self.stream else {
            return true;
        };
        let mut probe = [0u8; 1];
        match stream.try_read(&mut probe) {
            Ok(0) => true,
            Ok(_) => false, // generators send nothing; ignore anything they do
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => false,
            Err(_) => true,
        }
    }

    async fn wait_for_generator(&mut self) -> Result<(), DisplayError> {
        let accept = self.listener.accept();
        let (stream, peer) = match self.config.connect_timeout_s {
            Some(t) => tokio::time::timeout(Duration::from_secs_f64(t), accept)
                .await
                .map_err(|_| {
                    DisplayError::Lost(format!(
                        "no pattern generator connected to {} within {t} s",
                        self.config.address
                    ))
                })?
                .map_err(lost)?,
            None => accept.await.map_err(lost)?,
        };
        let _ = stream.set_nodelay(true);
        tracing::info!(%peer, "pattern generator connected");
        self.stream = Some(stream);
        Ok(())
    }

    async fn send(&mut self, bytes: &[u8]) -> bool {
        match self.stream.as_mut() {
            Some(s) => s.write_all(bytes).await.is_ok() && s.flush().await.is_ok(),
            None => false,
        }
    }

    fn gone(&mut self) {
        if self.stream.take().is_some() {
            self.disconnections += 1;
            tracing::warn!("the pattern generator went away; the run waits for it to reconnect");
        }
    }
}

impl PatchDisplay for ResolveDisplay {
    fn name(&self) -> String {
        format!("Resolve pattern generator via {}", self.config.address)
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        let bytes = frame(&message(patch, &self.config));
        loop {
            if self.stream.is_none() || self.peer_closed() {
                self.gone();
                self.wait_for_generator().await?;
            }
            if !self.send(&bytes).await {
                self.gone();
                continue;
            }
            tokio::time::sleep(Duration::from_secs_f64(self.settle_s)).await;
            // A generator that left while the patch settled may never have shown it.
            if self.peer_closed() {
                self.gone();
                continue;
            }
            return Ok(());
        }
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        if let Some(_s) = &self.stream {
            let black = Patch {
                codes: chromacal_model::screen::Codes::from_drive([0.0; 3], 8),
                background: chromacal_model::screen::Codes::from_drive([0.0; 3], 8),
                geometry: Geometry {
                    x: 0.0,
                    y: 0.0,
                    width: 1.0,
                    height: 1.0,
                },
            };
            let bytes = frame(&message(&black, &self.config));
            let _ = self.send(&bytes).await;
        }
        Ok(())
    }
}

/// Options of the generator client that drives a virtual monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientOptions {
    /// Simulated seconds the virtual monitor takes to settle on each pattern.
    pub settle_s: f64,
    pub video_levels: bool,
    /// A fault: close the connection after this many patterns (once), and connect
    /// again after `reconnect_after_s` real seconds.
    pub drop_after: Option<usize>,
    pub reconnect_after_s: f64,
}

impl Default for ClientOptions {
    fn default() -> Self {
        ClientOptions {
            settle_s: 0.2,
            video_levels: false,
            drop_after: None,
            reconnect_after_s: 0.5,
        }
    }
}

/// A pattern generator that shows what it is sent on a virtual monitor: it connects to
/// `address` (again and again, until `stop`), reads messages and puts them on the
/// screen. Runs on the calling thread.
pub fn run_client(
    address: &str,
    monitor: Arc<Mutex<VirtualMonitor>>,
    options: ClientOptions,
    stop: Arc<std::sync::atomic::AtomicBool>,
) {
    use std::sync::atomic::Ordering;
    let mut shown = 0usize;
    let mut dropped = false;
    while !stop.load(Ordering::Relaxed) {
        let Ok(mut stream) = TcpStream::connect(address) else {
            std::thread::sleep(Duration::from_millis(50));
            continue;
        };
        let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
        loop {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            let mut header = [0u8; 4];
            match stream.read_exact(&mut header) {
                Ok(()) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    continue;
                }
                Err(_) => break,
            }
            let length = u32::from_be_bytes(header) as usize;
            if length == 0 || length > 65536 {
                break;
            }
            let mut body = vec![0u8; length];
            let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
            if stream.read_exact(&mut body).is_err() {
                break;
            }
            let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
            match parse_message(&String::from_utf8_lossy(&body), options.video_levels) {
                Ok(pattern) => {
                    if let Ok(mut m) = monitor.lock() {
                        m.show(pattern.content);
                        m.clock().advance(options.settle_s);
                    }
                    shown += 1;
                }
                Err(e) => tracing::warn!(error = %e, "unreadable pattern message"),
            }
            if options.drop_after == Some(shown) && !dropped {
                dropped = true;
                let _ = stream.shutdown(std::net::Shutdown::Both);
                drop(stream);
                std::thread::sleep(Duration::from_secs_f64(options.reconnect_after_s));
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn code_values_match_displaycal() {
        assert_eq!(code_value(0.5, 10, false), 512);
        assert_eq!(code_value(1.0, 8, false), 255);
        assert_eq!(code_value(0.0, 10, true), 64);
        assert_eq!(code_value(1.0, 10, true), 940);
        assert_eq!(code_value(1.0, 8, true), 235);
        for bits in [8, 10] {
            for video in [false, true] {
                for v in [0.0, 0.25, 0.5, 1.0] {
                    let back = drive_of(code_value(v, bits, video), bits, video);
                    assert!((back - v).abs() < 1.0 / 200.0, "{bits} {video} {v} {back}");
                }
            }
        }
    }

    #[test]
    fn messages_read_back_in_both_flavours() {
        let patch = Patch {
            codes: Codes {
                rgb: [128, 64, 255],
                bit_depth: 8,
            },
            background: Codes {
                rgb: [0, 0, 0],
                bit_depth: 8,
            },
            geometry: Geometry::centred(0.1),
        };
        let config = ResolveConfig::default();
        let ten_bit = Patch {
            codes: Codes {
                rgb: [514, 257, 1023],
                bit_depth: 10,
            },
            ..patch
        };
        let xml = message(&ten_bit, &config);
        assert!(
            xml.contains(r#"<color red="514" green="257" blue="1023" bits="10"/>"#),
            "{xml}"
        );
        assert!(
            xml.contains(r#"<background red="0" green="0" blue="0" bits="8"/>"#),
            "{xml}"
        );
        assert!(xml.contains(r#"<geometry x="0.4500" y="0.4500" cx="0.1000" cy="0.1000"/>"#));
        let p = parse_message(&xml, false).unwrap();
        assert_eq!(p.bits, 10);
        assert!((p.content.patch[0] - 514.0 / 1023.0).abs() < 1e-12);
        assert_eq!(p.content.geometry, patch.geometry);
        let ls = message(
            &patch,
            &ResolveConfig {
                flavour: Flavour::Ls,
                ..config
            },
        );
        let p = parse_message(&ls, false).unwrap();
        assert_eq!(p.bits, 8);
        assert!((p.content.patch[1] - 64.0 / 255.0).abs() < 1e-12);
        assert_eq!(frame("ab"), vec![0, 0, 0, 2, b'a', b'b']);
    }

    #[test]
    fn readers_tolerate_what_generators_meet() {
        // Decimal commas, no bits, pixel geometry, LightSpace background rectangle.
        let p = parse_message(
            r#"<calibration><color red="255" green="0" blue="0"/><geometry x="0,25" y="0,25" cx="0,5" cy="0,5"/></calibration>"#,
            false,
        )
        .unwrap();
        assert_eq!(p.bits, 8);
        assert_eq!(p.content.geometry.x, 0.25);
        let p = parse_message(
            r#"<calibration><color red="255" green="255" blue="255"/><geometry x="0" y="0" cx="1920.0000" cy="1080.0000"/></calibration>"#,
            false,
        )
        .unwrap();
        assert_eq!(p.content.geometry.width, 1.0);
        let p = parse_message(
            r#"<calibration><shapes><rectangle><color red="10" green="20" blue="30"/></rectangle><rectangle><colex red="1023" green="0" blue="0" bits="10"/><geometry x="0.4" y="0.4" cx="0.2" cy="0.2"/></rectangle></shapes></calibration>"#,
            false,
        )
        .unwrap();
        assert_eq!(p.content.patch[0], 1.0);
        assert!(p.content.background[0] > 0.0);
        assert!(parse_message("<other/>", false).is_err());
        assert!(parse_message("not xml", false).is_err());
        assert!(parse_message(r#"<calibration><color red="x"/></calibration>"#, false).is_err());
    }
}
