//! Byte transports to instruments and the framings their protocols need.
//!
//! A [`Transport`] moves bytes and keeps time: a real serial port
//! ([`super::serial::SerialTransport`]), an in-process emulator on virtual time
//! ([`super::emulator::memory::MemoryTransport`]) or a recorded session
//! ([`super::transcript::ReplayTransport`]). A [`Link`] adds what the drivers share on
//! top of any of them: a read buffer and the framings of the instruments (lines with a
//! chosen terminator, replies ended by silence, fixed-length binary frames, single
//! control bytes), every read bounded by a deadline, and a timing scale so that tests
//! can run the protocols' timeouts fast.

/// Why a transport operation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TransportError {
    /// Nothing (or not enough) arrived in time. `got` holds what did arrive.
    #[error("no complete reply within {waited:.3} s (got {} bytes: {})", got.len(), escape(got))]
    Timeout { waited: f64, got: Vec<u8> },
    /// The device is gone (cable pulled, pseudo-terminal closed).
    #[error("the device is gone: {0}")]
    Disconnected(String),
    #[error("{0}")]
    Io(String),
}

/// Moves bytes to and from a device, and keeps time.
pub trait Transport: Send {
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError>;
    /// Wait up to `timeout` seconds for bytes: at least one byte, or `Timeout`.
    fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError>;
    /// Drop whatever has arrived and not been read.
    fn clear_input(&mut self) -> Result<(), TransportError>;
    fn set_baud(&mut self, baud: u32) -> Result<(), TransportError>;
    /// Close and open the port again, after the device vanished.
    fn reopen(&mut self) -> Result<(), TransportError>;
    /// Let `seconds` pass (character pacing, settling).
    fn sleep(&mut self, seconds: f64);
    /// Seconds on this transport's clock.
    fn now(&self) -> f64;
    /// The port, for messages.
    fn describe(&self) -> String;
}

/// Bytes as text with control characters escaped, for messages and transcripts.
pub fn escape(bytes: &[u8]) -> String {
    let mut out = String::new();
    for b in bytes {
        match b {
            b'\r' => out.push_str("\\r"),
            b'\n' => out.push_str("\\n"),
            b'\t' => out.push_str("\\t"),
            b'\\' => out.push_str("\\\\"),
            0x20..=0x7e => out.push(*b as char),
            other => out.push_str(&format!("\\x{other:02X}")),
        }
    }
    out
}

/// Shortest timeout or silence a sped-up link waits (s of its own time).
pub const MIN_WAIT_S: f64 = 0.05;

/// How long [`Link::drain`] waits for a late reply to start (protocol seconds).
pub const DRAIN_WAIT_S: f64 = 6.0;

/// The longest reply any instrument here gives is a spectrum of some kilobytes; a
/// device (or emulator, or program on a pseudo-terminal) that sends more without ending
/// its reply is answered with an error, not read into memory.
pub const MAX_REPLY: usize = 1 << 20;

/// A transport with a read buffer and framings. Every timeout given to it is in the
/// protocol's seconds and multiplied by `timing_scale` (1 for real devices).
pub struct Link {
    transport: Box<dyn Transport>,
    buffer: Vec<u8>,
    timing_scale: f64,
}

impl Link {
    pub fn new(transport: Box<dyn Transport>, timing_scale: f64) -> Self {
        Link {
            transport,
            buffer: Vec::new(),
            timing_scale,
        }
    }

    pub fn transport(&mut self) -> &mut dyn Transport {
        self.transport.as_mut()
    }

    pub fn describe(&self) -> String {
        self.transport.describe()
    }

    /// A protocol duration in this link's time (pauses and pacing).
    pub fn scaled(&self, seconds: f64) -> f64 {
        seconds * self.timing_scale
    }

    /// A protocol timeout in this link's time: scaled, but never under
    /// [`MIN_WAIT_S`], because the operating system alone can take a few milliseconds
    /// to pass bytes through a pseudo-terminal.
    pub fn wait(&self, seconds: f64) -> f64 {
        if self.timing_scale < 1.0 {
            (seconds * self.timing_scale).max(MIN_WAIT_S.min(seconds))
        } else {
            seconds * self.timing_scale
        }
    }

    pub fn send(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.transport.write(bytes)
    }

    /// Send one byte at a time with `gap` seconds between them, for instruments whose
    /// USB firmware drops characters that arrive too fast (Photo Research).
    pub fn send_paced(&mut self, bytes: &[u8], gap: f64) -> Result<(), TransportError> {
        for (i, b) in bytes.iter().enumerate() {
            if i > 0 {
                let pause = self.scaled(gap);
                self.transport.sleep(pause);
            }
            self.transport.write(&[*b])?;
        }
        Ok(())
    }

    /// After a reply went missing or came garbled: wait for the line to be quiet (up to
    /// [`DRAIN_WAIT_S`] for a straggler to start, then until 0.5 s pass with nothing),
    /// and drop everything. A reply that comes after its timeout is thus thrown away
    /// rather than read as the answer to the next command.
    pub fn drain(&mut self) -> Result<(), TransportError> {
        match self.read_until_silence(DRAIN_WAIT_S, 0.5) {
            Ok(_) | Err(TransportError::Timeout { .. }) => {}
            Err(e) => return Err(e),
        }
        self.clear()
    }

    /// Drop buffered and pending input, so a new command does not read an old reply.
    pub fn clear(&mut self) -> Result<(), TransportError> {
        self.buffer.clear();
        self.transport.clear_input()
    }

    pub fn sleep(&mut self, seconds: f64) {
        let s = self.scaled(seconds);
        self.transport.sleep(s);
    }

    pub fn set_baud(&mut self, baud: u32) -> Result<(), TransportError> {
        self.buffer.clear();
        self.transport.set_baud(baud)
    }

    pub fn reopen(&mut self) -> Result<(), TransportError> {
        self.buffer.clear();
        self.transport.reopen()
    }

    /// Add `bytes` to the buffer, or drop it all when a reply would pass [`MAX_REPLY`].
    fn take(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        if self.buffer.len() + bytes.len() > MAX_REPLY {
            let tail = self.buffer.len().saturating_sub(48);
            let last = escape(&self.buffer[tail..]);
            self.buffer.clear();
            return Err(TransportError::Io(format!(
                "{} sent more than {MAX_REPLY} bytes without ending its reply (it last sent: {last})",
                self.transport.describe()
            )));
        }
        self.buffer.extend_from_slice(bytes);
        Ok(())
    }

    /// Read until `frame_end` finds the end of a frame in the buffer (returning its
    /// length), within `timeout` protocol seconds. Returns the frame; what follows
    /// stays buffered.
    pub fn read_frame(
        &mut self,
        timeout: f64,
        frame_end: impl Fn(&[u8]) -> Option<usize>,
    ) -> Result<Vec<u8>, TransportError> {
        let limit = self.wait(timeout);
        let deadline = self.transport.now() + limit;
        loop {
            if let Some(end) = frame_end(&self.buffer) {
                return Ok(self.buffer.drain(..end).collect());
            }
            let remaining = deadline - self.transport.now();
            if remaining <= 0.0 {
                return Err(TransportError::Timeout {
                    waited: limit,
                    got: std::mem::take(&mut self.buffer),
                });
            }
            match self.transport.read(remaining) {
                Ok(bytes) => self.take(&bytes)?,
                Err(TransportError::Timeout { .. }) => {
                    return Err(TransportError::Timeout {
                        waited: limit,
                        got: std::mem::take(&mut self.buffer),
                    });
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// A line ending in `terminator` (returned without it).
    pub fn read_line(
        &mut self,
        terminator: &[u8],
        timeout: f64,
    ) -> Result<Vec<u8>, TransportError> {
        let mut line = self.read_frame(timeout, |b| {
            find(b, terminator).map(|i| i + terminator.len())
        })?;
        line.truncate(line.len() - terminator.len());
        Ok(line)
    }

    /// Exactly `n` bytes.
    pub fn read_exact(&mut self, n: usize, timeout: f64) -> Result<Vec<u8>, TransportError> {
        self.read_frame(timeout, |b| (b.len() >= n).then_some(n))
    }

    /// Everything up to and including the first byte in `stops`.
    pub fn read_until_any(
        &mut self,
        stops: &[u8],
        timeout: f64,
    ) -> Result<Vec<u8>, TransportError> {
        self.read_frame(timeout, |b| {
            b.iter().position(|c| stops.contains(c)).map(|i| i + 1)
        })
    }

    /// A reply ended by silence: wait up to `first` protocol seconds for it to start,
    /// then take bytes until none arrive for `gap` protocol seconds.
    pub fn read_until_silence(&mut self, first: f64, gap: f64) -> Result<Vec<u8>, TransportError> {
        if self.buffer.is_empty() {
            let start = self.wait(first);
            match self.transport.read(start) {
                Ok(bytes) => self.buffer.extend_from_slice(&bytes),
                Err(TransportError::Timeout { .. }) => {
                    return Err(TransportError::Timeout {
                        waited: start,
                        got: Vec::new(),
                    });
                }
                Err(e) => return Err(e),
            }
        }
        let quiet = self.wait(gap);
        loop {
            match self.transport.read(quiet) {
                Ok(bytes) => self.take(&bytes)?,
                Err(TransportError::Timeout { .. }) => return Ok(std::mem::take(&mut self.buffer)),
                Err(e) => return Err(e),
            }
        }
    }
}

/// Position of `needle` in `haystack`.
pub fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    if needle.is_empty() || haystack.len() < needle.len() {
        return None;
    }
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    /// Bytes that arrive at given times, on a virtual clock.
    struct Script {
        now: f64,
        arrivals: VecDeque<(f64, Vec<u8>)>,
        written: Vec<u8>,
    }

    impl Transport for Script {
        fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
            self.written.extend_from_slice(bytes);
            Ok(())
        }
        fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError> {
            match self.arrivals.front() {
                Some((t, _)) if *t <= self.now + timeout => {
                    let (t, b) = self.arrivals.pop_front().unwrap_or_default();
                    self.now = self.now.max(t);
                    Ok(b)
                }
                _ => {
                    self.now += timeout;
                    Err(TransportError::Timeout {
                        waited: timeout,
                        got: Vec::new(),
                    })
                }
            }
        }
        fn clear_input(&mut self) -> Result<(), TransportError> {
            Ok(())
        }
        fn set_baud(&mut self, _: u32) -> Result<(), TransportError> {
            Ok(())
        }
        fn reopen(&mut self) -> Result<(), TransportError> {
            Ok(())
        }
        fn sleep(&mut self, seconds: f64) {
            self.now += seconds;
        }
        fn now(&self) -> f64 {
            self.now
        }
        fn describe(&self) -> String {
            "script".into()
        }
    }

    fn link(arrivals: &[(f64, &[u8])], scale: f64) -> Link {
        Link::new(
            Box::new(Script {
                now: 0.0,
                arrivals: arrivals.iter().map(|(t, b)| (*t, b.to_vec())).collect(),
                written: Vec::new(),
            }),
            scale,
        )
    }

    #[test]
    fn lines_are_framed_across_reads_and_leftovers_kept() {
        let mut l = link(&[(0.1, b"00000,0,1.2"), (0.2, b"e+01\r\nnext\r\n")], 1.0);
        assert_eq!(l.read_line(b"\r\n", 1.0).unwrap(), b"00000,0,1.2e+01");
        assert_eq!(l.read_line(b"\r\n", 1.0).unwrap(), b"next");
    }

    #[test]
    fn deadlines_hold_and_partial_replies_are_reported() {
        let mut l = link(&[(0.1, b"00000,0,1.2"), (5.0, b"\r\n")], 1.0);
        match l.read_line(b"\r\n", 1.0) {
            Err(TransportError::Timeout { waited, got }) => {
                assert_eq!(waited, 1.0);
                assert_eq!(got, b"00000,0,1.2");
            }
            other => panic!("{other:?}"),
        }
        // With a timing scale of 0.01, a 100 s protocol timeout is 1 s of link time.
        let mut l = link(&[(0.5, b"N5")], 0.01);
        assert_eq!(l.read_exact(2, 100.0).unwrap(), b"N5");
        let mut l = link(&[(1.5, b"N5")], 0.01);
        assert!(l.read_exact(2, 100.0).is_err());
        // A sped-up 0.5 s timeout still waits the 50 ms a pseudo-terminal may need.
        let mut l = link(&[(0.04, b"P0")], 0.001);
        assert_eq!(l.read_exact(2, 0.5).unwrap(), b"P0");
    }

    #[test]
    fn silence_ends_a_reply() {
        let mut l = link(&[(0.5, b"000"), (0.52, b"\r\n"), (2.0, b"late")], 1.0);
        assert_eq!(l.read_until_silence(1.0, 0.1).unwrap(), b"000\r\n");
        assert!(matches!(
            link(&[], 1.0).read_until_silence(1.0, 0.1),
            Err(TransportError::Timeout { .. })
        ));
    }

    #[test]
    fn a_reply_without_end_is_refused_at_the_bound_not_read_into_memory() {
        let chunk = vec![b'x'; 64 * 1024];
        let arrivals: Vec<(f64, &[u8])> = (0..40).map(|i| (i as f64 * 0.001, &chunk[..])).collect();
        let mut l = link(&arrivals, 1.0);
        match l.read_line(b"\r\n", 10.0) {
            Err(TransportError::Io(why)) => {
                assert!(why.contains("more than 1048576 bytes"), "{why}");
                assert!(why.contains("script"), "{why}");
            }
            other => panic!("{other:?}"),
        }
        assert!(l.buffer.is_empty());
        let mut l = link(&arrivals, 1.0);
        assert!(matches!(
            l.read_until_silence(1.0, 0.1),
            Err(TransportError::Io(_))
        ));
        // Under the bound a long reply is whole.
        let mut l = link(&arrivals[..15], 1.0);
        assert_eq!(
            l.read_until_silence(1.0, 0.1).unwrap().len(),
            15 * 64 * 1024
        );
    }

    #[test]
    fn escapes_control_bytes() {
        assert_eq!(escape(b"OK\r\n\x06\x07"), "OK\\r\\n\\x06\\x07");
    }
}
