//! Transcripts: byte-exact recordings of a session with an instrument, each chunk with
//! its direction and time, and a transport that replays one to a driver so driver
//! tests run without the emulator (or the instrument).
//!
//! Format (JSON Lines): a header `{"format":"chromacal-transcript","version":1,
//! "instrument":…}`, then one event per line: `{"t":seconds,"dir":"host"|"device"|
//! "closed","hex":"…","text":"…"}` (`text` is the same bytes escaped, for reading).

use std::collections::VecDeque;
use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::transport::{Transport, TransportError, escape};

pub const TRANSCRIPT_FORMAT: &str = "chromacal-transcript";

/// Who sent a chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    Host,
    Device,
    /// The device closed the line.
    Closed,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TranscriptHeader {
    pub format: String,
    pub version: u32,
    pub instrument: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TranscriptEvent {
    pub t: f64,
    pub dir: Direction,
    pub hex: String,
    pub text: String,
}

impl TranscriptEvent {
    pub fn bytes(&self) -> Result<Vec<u8>, String> {
        if !self.hex.len().is_multiple_of(2) {
            return Err(format!("odd number of hex digits in '{}'", self.hex));
        }
        (0..self.hex.len())
            .step_by(2)
            .map(|i| {
                u8::from_str_radix(&self.hex[i..i + 2], 16)
                    .map_err(|_| format!("'{}' is not hex", &self.hex[i..i + 2]))
            })
            .collect()
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Writes a transcript as a session goes.
pub struct Recorder {
    file: File,
    started: Instant,
}

impl Recorder {
    pub fn create(path: &Path, instrument: &str) -> std::io::Result<Self> {
        let mut file = File::create(path)?;
        let header = TranscriptHeader {
            format: TRANSCRIPT_FORMAT.into(),
            version: 1,
            instrument: instrument.into(),
        };
        writeln!(
            file,
            "{}",
            serde_json::to_string(&header).map_err(std::io::Error::other)?
        )?;
        Ok(Recorder {
            file,
            started: Instant::now(),
        })
    }

    pub fn record(&mut self, dir: Direction, bytes: &[u8]) {
        let event = TranscriptEvent {
            t: (self.started.elapsed().as_secs_f64() * 1e6).round() / 1e6,
            dir,
            hex: hex(bytes),
            text: escape(bytes),
        };
        if let Ok(line) = serde_json::to_string(&event) {
            let _ = writeln!(self.file, "{line}");
            let _ = self.file.flush();
        }
    }
}

/// Why a transcript could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TranscriptError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}, line {line}: {message}")]
    Bad {
        path: String,
        line: usize,
        message: String,
    },
}

/// Read a transcript file.
pub fn read_transcript(
    path: &Path,
) -> Result<(TranscriptHeader, Vec<TranscriptEvent>), TranscriptError> {
    let name = path.display().to_string();
    let text = chromacal_formats::durable::read_text_limited(
        path,
        chromacal_formats::durable::limits::TABLE,
    )
    .map_err(|source| TranscriptError::Io {
        path: name.clone(),
        source,
    })?;
    let bad = |line: usize, message: String| TranscriptError::Bad {
        path: name.clone(),
        line,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, first) = lines
        .next()
        .ok_or_else(|| bad(1, "empty transcript".into()))?;
    let header: TranscriptHeader =
        serde_json::from_str(first).map_err(|e| bad(1, e.to_string()))?;
    if header.format != TRANSCRIPT_FORMAT {
        return Err(bad(
            1,
            format!("not a transcript: format '{}'", header.format),
        ));
    }
    let mut events = Vec::new();
    for (i, line) in lines {
        let event: TranscriptEvent =
            serde_json::from_str(line).map_err(|e| bad(i + 1, e.to_string()))?;
        event.bytes().map_err(|m| bad(i + 1, m))?;
        events.push(event);
    }
    Ok((header, events))
}

/// Plays a transcript back as the device: the host's writes must match what was
/// recorded, in order (however they are split); the device's chunks are read in turn.
pub struct ReplayTransport {
    name: String,
    events: VecDeque<(f64, Direction, Vec<u8>)>,
    /// Host bytes still expected from the current host event.
    expected: VecDeque<u8>,
    written: usize,
    now: f64,
    closed: bool,
}

impl ReplayTransport {
    pub fn open(path: &Path) -> Result<Self, TranscriptError> {
        let (header, events) = read_transcript(path)?;
        let events = events
            .into_iter()
            .filter_map(|e| e.bytes().ok().map(|b| (e.t, e.dir, b)))
            .collect();
        Ok(ReplayTransport {
            name: format!("replay of {} ({})", path.display(), header.instrument),
            events,
            expected: VecDeque::new(),
            written: 0,
            now: 0.0,
            closed: false,
        })
    }

    /// True when every recorded event has been played.
    pub fn finished(&self) -> bool {
        self.expected.is_empty() && self.events.is_empty()
    }
}

impl Transport for ReplayTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        if self.closed {
            return Err(TransportError::Disconnected(
                "the recorded device closed the line".into(),
            ));
        }
        for b in bytes {
            if self.expected.is_empty() {
                match self.events.front() {
                    Some((_, Direction::Host, _)) => {
                        if let Some((t, _, chunk)) = self.events.pop_front() {
                            self.now = self.now.max(t);
                            self.expected.extend(chunk);
                        }
                    }
                    next => {
                        return Err(TransportError::Io(format!(
                            "replay diverged at host byte {}: the driver wrote {}, the recording has {}",
                            self.written,
                            escape(&[*b]),
                            match next {
                                Some((_, _, chunk)) =>
                                    format!("the device sending {}", escape(chunk)),
                                None => "nothing more".into(),
                            }
                        )));
                    }
                }
            }
            match self.expected.pop_front() {
                Some(e) if e == *b => self.written += 1,
                Some(e) => {
                    return Err(TransportError::Io(format!(
                        "replay diverged at host byte {}: the driver wrote {}, the recording has {}",
                        self.written,
                        escape(&[*b]),
                        escape(&[e])
                    )));
                }
                None => {}
            }
        }
        Ok(())
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError> {
        if self.expected.is_empty() {
            match self.events.front() {
                Some((_, Direction::Device, _)) => {
                    if let Some((t, _, chunk)) = self.events.pop_front() {
                        self.now = self.now.max(t);
                        return Ok(chunk);
                    }
                }
                Some((_, Direction::Closed, _)) => {
                    self.events.pop_front();
                    self.closed = true;
                    return Err(TransportError::Disconnected(
                        "the recorded device closed the line".into(),
                    ));
                }
                _ => {}
            }
        }
        self.now += timeout;
        Err(TransportError::Timeout {
            waited: timeout,
            got: Vec::new(),
        })
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        Ok(())
    }

    fn set_baud(&mut self, _baud: u32) -> Result<(), TransportError> {
        Ok(())
    }

    fn reopen(&mut self) -> Result<(), TransportError> {
        if self.closed {
            Err(TransportError::Disconnected(
                "the recorded device is gone".into(),
            ))
        } else {
            Ok(())
        }
    }

    fn sleep(&mut self, seconds: f64) {
        self.now += seconds.max(0.0);
    }

    fn now(&self) -> f64 {
        self.now
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}
