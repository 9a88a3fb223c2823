//! An emulated device on a real pseudo-terminal: the driver opens the slave path
//! (`/dev/pts/N`) like any serial port and talks to it in real time. Replies go out as
//! one burst each, when due; device time runs `1 / time_scale` times faster than real
//! time, so tests can make a 10 s integration take 0.1 s (drivers scale their timeouts
//! by the same factor).

use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use super::faults::{FaultInjector, FaultSpec, LinkAction};
use super::{DeviceModel, Scheduled};
use crate::transcript::{Direction, Recorder};

/// How an emulator runs.
#[derive(Debug, Clone, Default)]
pub struct PtyOptions {
    /// Real seconds per device second (1 for real time).
    pub time_scale: f64,
    pub faults: FaultSpec,
    /// Record the session to this transcript file.
    pub record: Option<std::path::PathBuf>,
}

/// A running emulator. Dropping it stops it.
pub struct PtyEmulator {
    path: String,
    stop: Arc<AtomicBool>,
    gone: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

enum Due {
    Bytes(Vec<u8>),
    Vanish,
}

impl PtyEmulator {
    /// Open a pseudo-terminal pair and serve `device` on it.
    pub fn spawn(mut device: Box<dyn DeviceModel>, options: PtyOptions) -> std::io::Result<Self> {
        let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::other)?;
        let path = slave
            .name()
            .ok_or_else(|| std::io::Error::other("the pseudo-terminal has no name"))?;
        master
            .set_timeout(Duration::from_millis(2))
            .map_err(std::io::Error::other)?;
        let mut recorder = match &options.record {
            Some(p) => Some(Recorder::create(Path::new(p), device.name())?),
            None => None,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let gone = Arc::new(AtomicBool::new(false));
        let (stop_flag, gone_flag) = (stop.clone(), gone.clone());
        let scale = if options.time_scale > 0.0 {
            options.time_scale
        } else {
            1.0
        };
        let mut faults = FaultInjector::new(options.faults);
        let thread = std::thread::spawn(move || {
            // Keep the slave open ourselves, so the terminal stays raw and alive
            // between the driver's sessions; its termios tells us the driver's baud.
            let slave = slave;
            let started = Instant::now();
            let device_now = || started.elapsed().as_secs_f64() / scale;
            let mut due: Vec<(Instant, Due)> = Vec::new();
            let schedule =
                |due: &mut Vec<(Instant, Due)>, reply: Scheduled, faults: &mut FaultInjector| {
                    let base = Instant::now();
                    let at = |delay: f64| base + Duration::from_secs_f64((delay * scale).max(0.0));
                    for action in faults.apply(reply) {
                        match action {
                            LinkAction::Send(s) => due.push((at(s.delay), Due::Bytes(s.bytes))),
                            LinkAction::Vanish { delay, partial } => {
                                due.push((at(delay), Due::Bytes(partial)));
                                due.push((at(delay), Due::Vanish));
                            }
                        }
                    }
                    due.sort_by_key(|d| d.0);
                };
            let mut buffer = [0u8; 4096];
            while !stop_flag.load(Ordering::Relaxed) {
                match master.read(&mut buffer) {
                    Ok(n) if n > 0 => {
                        let bytes = &buffer[..n];
                        if let Some(r) = recorder.as_mut() {
                            r.record(Direction::Host, bytes);
                        }
                        let baud = slave.baud_rate().unwrap_or(9600);
                        for reply in device.receive(bytes, device_now(), baud) {
                            schedule(&mut due, reply, &mut faults);
                        }
                    }
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                    Err(_) => std::thread::sleep(Duration::from_millis(2)),
                }
                let horizon = device_now();
                for (at, bytes) in device.poll(horizon) {
                    let delay = (at - horizon).max(0.0);
                    schedule(&mut due, Scheduled::after(delay, bytes), &mut faults);
                }
                let now = Instant::now();
                while due.first().is_some_and(|d| d.0 <= now) {
                    let (_, what) = due.remove(0);
                    match what {
                        Due::Bytes(bytes) => {
                            if bytes.is_empty() {
                                continue;
                            }
                            if let Some(r) = recorder.as_mut() {
                                r.record(Direction::Device, &bytes);
                            }
                            let _ = master.write_all(&bytes);
                            let _ = master.flush();
                        }
                        Due::Vanish => {
                            if let Some(r) = recorder.as_mut() {
                                r.record(Direction::Closed, &[]);
                            }
                            gone_flag.store(true, Ordering::Relaxed);
                            return;
                        }
                    }
                }
            }
        });
        Ok(PtyEmulator {
            path,
            stop,
            gone,
            thread: Some(thread),
        })
    }

    /// The device path to open, e.g. `/dev/pts/7`.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// True after the emulated device vanished (a fault).
    pub fn vanished(&self) -> bool {
        self.gone.load(Ordering::Relaxed)
    }

    /// Run until stopped from elsewhere (the `emulate` command).
    pub fn wait(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for PtyEmulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
