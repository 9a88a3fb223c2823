//! An emulated device in the same process, on virtual time: the transport for tests
//! that run a driver through thousands of fault schedules in a second. Timeouts cost
//! nothing, yet happen exactly as they would on the wire.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use super::faults::{FaultInjector, FaultSpec, LinkAction};
use super::{DeviceModel, Scheduled};
use crate::transport::{Transport, TransportError};

enum Delivery {
    Bytes(Vec<u8>),
    Vanish,
}

/// A device model behind a virtual wire.
pub struct MemoryTransport {
    device: Box<dyn DeviceModel>,
    faults: FaultInjector,
    now: f64,
    /// (time, what), in time order.
    queue: Vec<(f64, Delivery)>,
    vanished: bool,
    baud: u32,
    /// Bytes written by the host, in order (for tests that check pacing or content).
    pub written: Vec<(f64, Vec<u8>)>,
    controls: MemoryControls,
}

/// Handles a test keeps after the transport moves into a driver: the virtual time, and
/// a switch for the link faults.
#[derive(Debug, Clone)]
pub struct MemoryControls {
    time_bits: Arc<AtomicU64>,
    faults_on: Arc<AtomicBool>,
}

impl MemoryControls {
    /// Virtual seconds since the transport was made.
    pub fn now(&self) -> f64 {
        f64::from_bits(self.time_bits.load(Ordering::Relaxed))
    }

    pub fn set_faults(&self, on: bool) {
        self.faults_on.store(on, Ordering::Relaxed);
    }
}

impl MemoryTransport {
    pub fn new(device: Box<dyn DeviceModel>, faults: FaultSpec, baud: u32) -> Self {
        MemoryTransport {
            device,
            faults: FaultInjector::new(faults),
            now: 0.0,
            queue: Vec::new(),
            vanished: false,
            baud,
            written: Vec::new(),
            controls: MemoryControls {
                time_bits: Arc::new(AtomicU64::new(0f64.to_bits())),
                faults_on: Arc::new(AtomicBool::new(true)),
            },
        }
    }

    pub fn controls(&self) -> MemoryControls {
        self.controls.clone()
    }

    fn advance_to(&mut self, t: f64) {
        self.now = t;
        self.controls
            .time_bits
            .store(t.to_bits(), Ordering::Relaxed);
    }

    fn schedule(&mut self, at: f64, reply: Scheduled) {
        let actions = if self.controls.faults_on.load(Ordering::Relaxed) {
            self.faults
                .apply(Scheduled::after(reply.delay, reply.bytes))
        } else {
            vec![LinkAction::Send(reply)]
        };
        for action in actions {
            match action {
                LinkAction::Send(s) => self.push(at + s.delay, Delivery::Bytes(s.bytes)),
                LinkAction::Vanish { delay, partial } => {
                    if !partial.is_empty() {
                        self.push(at + delay, Delivery::Bytes(partial));
                    }
                    self.push(at + delay, Delivery::Vanish);
                }
            }
        }
    }

    fn push(&mut self, at: f64, what: Delivery) {
        let i = self.queue.partition_point(|(t, _)| *t <= at);
        self.queue.insert(i, (at, what));
    }
}

impl Transport for MemoryTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        if self.vanished {
            return Err(TransportError::Disconnected(
                "the emulated device vanished".into(),
            ));
        }
        self.written.push((self.now, bytes.to_vec()));
        let now = self.now;
        for reply in self.device.receive(bytes, now, self.baud) {
            self.schedule(now, reply);
        }
        Ok(())
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>, TransportError> {
        if self.vanished {
            return Err(TransportError::Disconnected(
                "the emulated device vanished".into(),
            ));
        }
        let horizon = self.now + timeout.max(0.0);
        for (at, bytes) in self.device.poll(horizon) {
            self.schedule(at, Scheduled::now(bytes));
        }
        match self.queue.first() {
            Some((at, _)) if *at <= horizon => {
                let (at, what) = self.queue.remove(0);
                self.advance_to(self.now.max(at));
                match what {
                    Delivery::Bytes(b) => Ok(b),
                    Delivery::Vanish => {
                        self.vanished = true;
                        self.queue.clear();
                        Err(TransportError::Disconnected(
                            "the emulated device vanished".into(),
                        ))
                    }
                }
            }
            _ => {
                self.advance_to(horizon);
                Err(TransportError::Timeout {
                    waited: timeout,
                    got: Vec::new(),
                })
            }
        }
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        let now = self.now;
        self.queue
            .retain(|(at, what)| *at > now || matches!(what, Delivery::Vanish));
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), TransportError> {
        self.baud = baud;
        Ok(())
    }

    fn reopen(&mut self) -> Result<(), TransportError> {
        if self.vanished {
            Err(TransportError::Disconnected(
                "the emulated device is still gone".into(),
            ))
        } else {
            Ok(())
        }
    }

    fn sleep(&mut self, seconds: f64) {
        self.advance_to(self.now + seconds.max(0.0));
    }

    fn now(&self) -> f64 {
        self.now
    }

    fn describe(&self) -> String {
        format!("in-process {}", self.device.name())
    }
}
