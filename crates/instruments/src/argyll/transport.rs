//! ArgyllCMS `spotread` as a byte transport: one process on a pseudo-terminal, whose
//! output is read as an instrument's replies and to which keystrokes are written as
//! commands. `reopen` starts a fresh spotread (the instrument initialised again).
//!
//! spotread reads its keys from its standard input through termios, so it needs a
//! terminal there: it gets the slave side of a pseudo-terminal as stdin, stdout and
//! stderr, in a process group of its own (a Ctrl-C meant for chromacal must not reach
//! it: chromacal closes it itself). When the transport is dropped spotread is asked to
//! quit, then killed if it has not within two seconds.

use std::io::{Read, Write};
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::transport::{Transport, TransportError};

/// The program run, found on the PATH (or `CHROMACAL_SPOTREAD`, for a wrapper).
pub fn spotread_program() -> String {
    std::env::var("CHROMACAL_SPOTREAD").unwrap_or_else(|_| "spotread".to_string())
}

/// The message for a spotread that could not be started.
pub fn missing_message(program: &str, error: &std::io::Error) -> String {
    if error.kind() == std::io::ErrorKind::NotFound {
        format!(
            "ArgyllCMS's {program} was not found on the PATH: install ArgyllCMS (Debian and Ubuntu: argyll; https://www.argyllcms.com) to use --instrument argyll"
        )
    } else {
        format!("ArgyllCMS's {program} could not be started: {error}")
    }
}

/// spotread running on a pseudo-terminal.
pub struct SpotreadTransport {
    program: String,
    args: Vec<String>,
    child: Option<Child>,
    master: Option<TTYPort>,
    started: Instant,
}

impl SpotreadTransport {
    /// Start `program` (spotread) with `args`.
    pub fn spawn(program: &str, args: &[String]) -> Result<Self, TransportError> {
        let mut transport = SpotreadTransport {
            program: program.to_string(),
            args: args.to_vec(),
            child: None,
            master: None,
            started: Instant::now(),
        };
        transport.start()?;
        Ok(transport)
    }

    fn start(&mut self) -> Result<(), TransportError> {
        let (mut master, slave) =
            TTYPort::pair().map_err(|e| TransportError::Io(format!("no pseudo-terminal: {e}")))?;
        let slave_path = slave
            .name()
            .ok_or_else(|| TransportError::Io("the pseudo-terminal has no name".into()))?;
        master
            .set_timeout(Duration::from_millis(20))
            .map_err(|e| TransportError::Io(e.to_string()))?;
        let open = || {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&slave_path)
                .map_err(|e| TransportError::Io(format!("{slave_path}: {e}")))
        };
        let child = Command::new(&self.program)
            .args(&self.args)
            .stdin(Stdio::from(open()?))
            .stdout(Stdio::from(open()?))
            .stderr(Stdio::from(open()?))
            .process_group(0)
            .spawn()
            .map_err(|e| TransportError::Disconnected(missing_message(&self.program, &e)))?;
        // Our copies of the slave side close here, so that spotread's exit reads as the
        // end of the terminal.
        drop(slave);
        self.child = Some(child);
        self.master = Some(master);
        Ok(())
    }

    /// Whether spotread has exited, and how.
    pub fn exit_status(&mut self) -> Option<std::process::ExitStatus> {
        self.child
            .as_mut()
            .and_then(|c| c.try_wait().ok().flatten())
    }

    /// Ask spotread to quit (Esc twice: the loop's, then the retry prompt's), give it
    /// two seconds, then kill it.
    fn stop(&mut self) {
        if let Some(master) = self.master.as_mut() {
            let _ = master.write_all(b"\x1b");
            std::thread::sleep(Duration::from_millis(50));
            let _ = master.write_all(b"\x1b");
        }
        if let Some(mut child) = self.child.take() {
            let deadline = Instant::now() + Duration::from_secs(2);
            loop {
                // Keep its output flowing, so that it never blocks writing.
                if let Some(m) = self.master.as_mut() {
                    let mut sink = [0u8; 4096];
                    let _ = m.read(&mut sink);
                }
                match child.try_wait() {
                    Ok(Some(_)) => break,
                    Ok(None) if Instant::now() < deadline => {}
                    _ => {
                        let _ = child.kill();
                        let _ = child.wait();
                        break;
                    }
                }
            }
        }
        self.master = None;
    }

    fn gone(&mut self, why: String) -> TransportError {
        let status = self
            .exit_status()
            .map(|s| format!(" (spotread exited: {s})"))
            .unwrap_or_default();
        TransportError::Disconnected(format!("{why}{status}"))
    }
}

impl Drop for SpotreadTransport {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Transport for SpotreadTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        let Some(master) = self.master.as_mut() else {
            return Err(TransportError::Disconnected(
                "spotread is not running".into(),
            ));
        };
        let result = master.write_all(bytes).and_then(|_| master.flush());
        result.map_err(|e| self.gone(format!("spotread's terminal: {e}")))
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError> {
        let deadline = Instant::now() + Duration::from_secs_f64(timeout.max(0.0));
        let mut buffer = [0u8; 4096];
        loop {
            let Some(master) = self.master.as_mut() else {
                return Err(TransportError::Disconnected(
                    "spotread is not running".into(),
                ));
            };
            match master.read(&mut buffer) {
                Ok(0) => return Err(self.gone("spotread's output ended".into())),
                Ok(n) => return Ok(buffer[..n].to_vec()),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                // EIO: every slave descriptor is closed, spotread has gone.
                Err(e) => return Err(self.gone(format!("spotread's output ended ({e})"))),
            }
            if Instant::now() >= deadline {
                return Err(TransportError::Timeout {
                    waited: timeout,
                    got: Vec::new(),
                });
            }
        }
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        loop {
            match self.read(0.0) {
                Ok(_) => {}
                Err(TransportError::Timeout { .. }) => return Ok(()),
                Err(e) => return Err(e),
            }
        }
    }

    fn set_baud(&mut self, _baud: u32) -> Result<(), TransportError> {
        Ok(())
    }

    fn reopen(&mut self) -> Result<(), TransportError> {
        self.stop();
        self.start()
    }

    fn sleep(&mut self, seconds: f64) {
        std::thread::sleep(Duration::from_secs_f64(seconds.max(0.0)));
    }

    fn now(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    fn describe(&self) -> String {
        format!("{} {}", self.program, self.args.join(" "))
    }
}

/// The most `spotread -?` may print: its usage text with a port list is a few
/// kilobytes; one that prints without end is stopped here, not read into memory.
pub const USAGE_LIMIT: usize = 1 << 20;

/// Run `spotread -?` and return what it printed (its usage, with the port list), within
/// `timeout`: Argyll scans every port, and a port that never answers must not hang us;
/// and within [`USAGE_LIMIT`] bytes.
pub fn usage_text(program: &str, timeout: Duration) -> Result<String, String> {
    use chromacal_formats::child::{ChildError, output_within};
    let child = Command::new(program)
        .arg("-?")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .map_err(|e| missing_message(program, &e))?;
    match output_within(&format!("{program} -?"), child, None, USAGE_LIMIT, timeout) {
        Ok(out) => Ok(String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr)),
        Err(ChildError::Timeout { .. }) => Err(format!(
            "{program} -? did not finish within {} s: its scan reads every serial port, and one never answered",
            timeout.as_secs()
        )),
        Err(e) => Err(format!("{e}: is it ArgyllCMS's spotread?")),
    }
}
