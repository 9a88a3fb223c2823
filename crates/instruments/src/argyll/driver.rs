//! The spotread dialogue as a [`Protocol`]: start (wait for the reading prompt), one
//! key per reading, results and failures turned into readings and instrument errors.
//! The recovery policy is the serial drivers' ([`crate::driver`]): a
//! failed reading is taken again, and a spotread that has gone is started again.

use std::path::Path;

use super::protocol::{Event, is_saturation, is_spectral, next_event};
use super::transport::{SpotreadTransport, spotread_program, usage_text};
use crate::driver::{DriverOptions, Protocol, RefreshMode, SerialInstrument};
use crate::transport::{Link, TransportError};
use crate::{Capability, InstrumentError, InstrumentInfo, Reading, ReadingStatus};

/// How long `spotread -?` may take to scan the ports (s).
const SCAN_TIMEOUT_S: u64 = 60;

/// spotread's arguments for port `port` and `options` (emissive mode; spectra shown
/// for a `spectral` instrument: asked of a colorimeter, spotread refuses to start),
/// with relative paths taken from `base_dir`.
pub fn spotread_args(
    port: u32,
    options: &DriverOptions,
    base_dir: &Path,
    spectral: bool,
) -> Vec<String> {
    let mut args = vec!["-c".to_string(), port.to_string(), "-e".into()];
    if spectral {
        args.push("-s".into());
    }
    if let Some(t) = &options.display_type {
        args.extend(["-y".to_string(), t.clone()]);
    }
    match options.refresh_mode {
        Some(RefreshMode::Refresh) => args.extend(["-Y".to_string(), "r".into()]),
        Some(RefreshMode::NonRefresh) => args.extend(["-Y".to_string(), "n".into()]),
        None => {}
    }
    if options.averaging.is_some_and(|n| n >= 2) {
        args.extend(["-Y".to_string(), "a".to_string()]);
    }
    if let Some(file) = &options.argyll_correction {
        let path = if file.is_absolute() {
            file.clone()
        } else {
            base_dir.join(file)
        };
        args.extend(["-X".to_string(), path.display().to_string()]);
    }
    args
}

/// The ports ArgyllCMS sees and the instruments it identified on them (`spotread -?`),
/// within `timeout`: Argyll's scan reads every serial port it lists, and one that never
/// answers holds it up.
/// When it does not finish, the serial ports of this machine (and `extra`) that do
/// not even open are named, with ArgyllCMS's own way to leave them out of its scan
/// (`ARGYLL_EXCLUDE_SERIAL_SCAN`, which spotread inherits).
pub fn list_ports(
    program: &str,
    timeout: std::time::Duration,
    extra: &[String],
) -> Result<Vec<super::protocol::ArgyllPort>, String> {
    let usage = usage_text(program, timeout).map_err(|e| {
        if !e.contains("did not finish") {
            return e;
        }
        let ports = crate::serial::candidate_ports(extra);
        let hung = ports_that_hang(&ports, std::time::Duration::from_secs(3));
        let (named, list) = if hung.is_empty() {
            ("the serial ports here are", ports.join(","))
        } else {
            ("it hangs on opening", hung.join(","))
        };
        format!(
            "{e}; {named} {}: ArgyllCMS leaves out of its scan the ports in ARGYLL_EXCLUDE_SERIAL_SCAN, e.g. `export ARGYLL_EXCLUDE_SERIAL_SCAN={list}` (those without an instrument)",
            if list.is_empty() { "none".to_string() } else { list.replace(',', ", ") }
        )
    })?;
    if !usage.contains("-c listno") {
        return Err(format!(
            "{program} -? printed no port list; is it ArgyllCMS's spotread?"
        ));
    }
    Ok(super::protocol::parse_port_list(&usage))
}

/// Those of `ports` whose plain (blocking) open does not return within `wait`, as a
/// port whose driver waits for a carrier does: the one a scan hangs on. Each is tried
/// on a thread of its own, left behind if it never returns.
pub fn ports_that_hang(ports: &[String], wait: std::time::Duration) -> Vec<String> {
    let (sender, receiver) = std::sync::mpsc::channel();
    for port in ports {
        let (sender, port) = (sender.clone(), port.clone());
        std::thread::spawn(move || {
            let _ = std::fs::File::open(&port);
            let _ = sender.send(port);
        });
    }
    drop(sender);
    let deadline = std::time::Instant::now() + wait;
    let mut answered = Vec::new();
    while let Some(left) = deadline.checked_duration_since(std::time::Instant::now()) {
        match receiver.recv_timeout(left) {
            Ok(port) => answered.push(port),
            Err(_) => break,
        }
    }
    ports
        .iter()
        .filter(|p| !answered.contains(p))
        .cloned()
        .collect()
}

/// The instrument ArgyllCMS sees on port `port` (`spotread -?`), or an error naming the
/// ports it does see.
pub fn identify(program: &str, port: u32) -> Result<String, InstrumentError> {
    let ports = list_ports(program, std::time::Duration::from_secs(SCAN_TIMEOUT_S), &[])
        .map_err(InstrumentError::Unavailable)?;
    match ports.iter().find(|p| p.number == port) {
        Some(p) => Ok(p.instrument.clone().unwrap_or_else(|| p.path.clone())),
        None if ports.is_empty() => Err(InstrumentError::Unavailable(
            "ArgyllCMS sees no instrument: is one plugged in, and may this user open it?".into(),
        )),
        None => Err(InstrumentError::Unavailable(format!(
            "ArgyllCMS has no instrument {port}; it sees: {}",
            ports
                .iter()
                .map(|p| format!(
                    "{} = {}{}",
                    p.number,
                    p.path,
                    p.instrument
                        .as_ref()
                        .map(|i| format!(" ({i})"))
                        .unwrap_or_default()
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// Start spotread on ArgyllCMS port `port` and connect to the instrument there.
pub fn open(
    port: u32,
    options: DriverOptions,
    base_dir: &Path,
) -> Result<SerialInstrument, InstrumentError> {
    let program = spotread_program();
    let name = identify(&program, port)?;
    let args = spotread_args(port, &options, base_dir, is_spectral(&name));
    let transport = SpotreadTransport::spawn(&program, &args).map_err(|e| match e {
        TransportError::Disconnected(m) => InstrumentError::Unavailable(m),
        other => InstrumentError::from(other),
    })?;
    let link = Link::new(Box::new(transport), options.timing_scale);
    let protocol = Spotread::new(link, name, options.argyll_timeout_s);
    SerialInstrument::connect(Box::new(protocol), options)
}

/// A fatal error spotread reported (it ends after it).
fn fatal(why: String) -> InstrumentError {
    InstrumentError::Device {
        code: "fatal".into(),
        meaning: why,
    }
}

/// spotread, driven key by key.
pub struct Spotread {
    link: Link,
    name: String,
    timeout_s: f64,
    /// Output read and not yet taken as an event.
    text: String,
    /// spotread is at its reading prompt, waiting for a key: only then is a key a
    /// reading (at any other prompt it would answer a question, a calibration's
    /// among them).
    at_prompt: bool,
}

impl Spotread {
    pub fn new(link: Link, name: String, timeout_s: f64) -> Self {
        Spotread {
            link,
            name,
            timeout_s,
            text: String::new(),
            at_prompt: false,
        }
    }

    /// The next event, reading spotread's output for up to `timeout_s`. Its end of
    /// output is an error holding the last of what it printed.
    fn next(&mut self) -> Result<Event, InstrumentError> {
        let deadline = self.link.transport().now() + self.link.wait(self.timeout_s);
        loop {
            match next_event(&self.text) {
                Ok(Some((event, used))) => {
                    self.text.drain(..used);
                    tracing::debug!(?event, "spotread");
                    return Ok(event);
                }
                Ok(None) => {}
                Err(why) => {
                    self.text.clear();
                    return Err(InstrumentError::Protocol(why));
                }
            }
            let remaining = deadline - self.link.transport().now();
            if remaining <= 0.0 {
                return Err(InstrumentError::Timeout {
                    seconds: self.link.wait(self.timeout_s),
                });
            }
            match self.link.transport().read(remaining.min(0.5)) {
                Ok(bytes) => self.text.push_str(&String::from_utf8_lossy(&bytes)),
                Err(TransportError::Timeout { .. }) => {}
                Err(TransportError::Disconnected(why)) => {
                    let last = self.last_words();
                    return Err(InstrumentError::Disconnected(format!("{why}{last}")));
                }
                Err(e) => return Err(e.into()),
            }
            // Keep the buffer bounded when spotread prints what we do not parse.
            if self.text.len() > 1 << 20 {
                let cut = self.text.len() - (1 << 16);
                let cut = (cut..self.text.len())
                    .find(|i| self.text.is_char_boundary(*i))
                    .unwrap_or(0);
                self.text.drain(..cut);
            }
        }
    }

    /// What spotread last printed that was not an event, for an error message.
    fn last_words(&mut self) -> String {
        let words: Vec<&str> = self
            .text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect();
        let tail = words[words.len().saturating_sub(3)..].join(" / ");
        self.text.clear();
        if tail.is_empty() {
            String::new()
        } else {
            format!("; it last said: {tail}")
        }
    }

    /// Press a key.
    fn key(&mut self, key: u8) -> Result<(), InstrumentError> {
        self.at_prompt = false;
        self.link.send(&[key]).map_err(InstrumentError::from)
    }

    /// A calibration request: it needs a person at the instrument (a cap, a tile),
    /// which an unattended run cannot be, and pressing on would calibrate against the
    /// screen. Not retried.
    fn needs_calibration(&self, instructions: &str) -> InstrumentError {
        InstrumentError::Unavailable(format!(
            "the {} needs a calibration (run spotread once and follow it, then start again): {instructions}",
            self.name
        ))
    }

    /// After a failure that ends at the retry prompt: back to the reading prompt.
    fn retry(&mut self) -> Result<(), InstrumentError> {
        loop {
            match self.next()? {
                Event::RetryPrompt => {
                    self.key(b' ')?;
                }
                Event::Ready => {
                    self.at_prompt = true;
                    return Ok(());
                }
                Event::NeedsCalibration(instructions) => {
                    return Err(self.needs_calibration(&instructions));
                }
                _ => {}
            }
        }
    }
}

impl Protocol for Spotread {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn connect(&mut self) -> Result<InstrumentInfo, InstrumentError> {
        // After a resync spotread is already at its prompt.
        let first = loop {
            match if self.at_prompt {
                Event::Ready
            } else {
                self.next()?
            } {
                Event::Notice(what) => tracing::info!(%what, "spotread"),
                event => break event,
            }
        };
        match first {
            Event::Ready => self.at_prompt = true,
            Event::StartFailed(why) => {
                return Err(InstrumentError::Unavailable(format!(
                    "spotread could not start the {}: {why}",
                    self.name
                )));
            }
            Event::NeedsCalibration(instructions) => {
                return Err(self.needs_calibration(&instructions));
            }
            Event::Fatal(why) => return Err(fatal(why)),
            other => {
                return Err(InstrumentError::Protocol(format!(
                    "spotread said {other:?} before its first prompt"
                )));
            }
        }
        let capability = if is_spectral(&self.name) {
            Capability::Spectral
        } else {
            Capability::Tristimulus
        };
        Ok(InstrumentInfo {
            name: format!("{} (ArgyllCMS)", self.name),
            serial: None,
            capability,
        })
    }

    fn measure_once(&mut self) -> Result<Reading, InstrumentError> {
        if !self.at_prompt {
            return Err(InstrumentError::Protocol(
                "spotread is not at its reading prompt".into(),
            ));
        }
        self.key(b' ')?;
        loop {
            match self.next()? {
                Event::Result { xyz, spectrum } => {
                    // The prompt for the next reading follows.
                    loop {
                        match self.next()? {
                            Event::Ready => {
                                self.at_prompt = true;
                                break;
                            }
                            Event::NeedsCalibration(instructions) => {
                                return Err(self.needs_calibration(&instructions));
                            }
                            Event::Result { .. } => {
                                return Err(InstrumentError::Protocol(
                                    "spotread gave two results for one key".into(),
                                ));
                            }
                            _ => {}
                        }
                    }
                    let spectrum = match spectrum {
                        Some(s) => match crate::check_spectrum(
                            &s,
                            &xyz,
                            s.wavelengths_nm()[0],
                            s.wavelengths_nm()[1] - s.wavelengths_nm()[0],
                            s.wavelengths_nm().len(),
                        ) {
                            Ok(()) => Some(s),
                            Err(e) => {
                                tracing::warn!(error = %e, "spotread's spectrum is dropped");
                                None
                            }
                        },
                        None => None,
                    };
                    return Ok(Reading {
                        xyz: Some(xyz),
                        luminance: None,
                        spectrum,
                        status: ReadingStatus::Ok,
                        integration_s: 0.0,
                        device_code: None,
                        raw: Some(format!("Result is XYZ: {} {} {}", xyz.x, xyz.y, xyz.z)),
                    });
                }
                Event::Misread(reason) => {
                    self.retry()?;
                    if is_saturation(&reason) {
                        return Ok(Reading {
                            status: ReadingStatus::Overload,
                            device_code: Some(reason),
                            ..Reading::default()
                        });
                    }
                    return Err(InstrumentError::Device {
                        code: "misread".into(),
                        meaning: reason,
                    });
                }
                Event::CommunicationFailed => {
                    self.retry()?;
                    return Err(InstrumentError::Protocol(format!(
                        "spotread lost the {} (communication problem)",
                        self.name
                    )));
                }
                Event::Notice(what) => tracing::info!(%what, "spotread"),
                Event::WrongPosition(why) => {
                    // spotread shows its menu again.
                    self.retry()?;
                    return Err(InstrumentError::Device {
                        code: "wrong-position".into(),
                        meaning: why,
                    });
                }
                Event::NeedsCalibration(instructions) => {
                    return Err(self.needs_calibration(&instructions));
                }
                Event::Fatal(why) => return Err(fatal(why)),
                Event::StartFailed(why) => {
                    return Err(InstrumentError::Unavailable(why));
                }
                // The reading was stopped ("Spot read stopped at user request!"):
                // back to the prompt, and the reading is taken again.
                Event::RetryPrompt => {
                    self.key(b' ')?;
                    self.retry()?;
                    return Err(InstrumentError::Protocol(
                        "spotread stopped the reading".into(),
                    ));
                }
                Event::Ready => {
                    // A prompt without a result: the key was taken as a command.
                    self.at_prompt = true;
                    return Err(InstrumentError::Protocol(
                        "spotread showed its prompt again without a reading".into(),
                    ));
                }
            }
        }
    }

    /// After a failure: spotread back at its prompt needs nothing (a misread is
    /// answered there); one that is not (a timeout, nonsense) is started again, up to
    /// its prompt.
    fn resync(&mut self) -> Result<(), InstrumentError> {
        if self.at_prompt {
            return Ok(());
        }
        self.text.clear();
        self.link.reopen().map_err(InstrumentError::from)?;
        self.connect().map(|_| ())
    }

    fn disconnect(&mut self) {
        let _ = self.key(b'q');
        let _ = self.key(b'q');
    }
}
