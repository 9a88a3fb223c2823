//! The simulated display: shows patches on a virtual monitor and settles on the
//! virtual clock.

use std::sync::{Arc, Mutex};

use super::{DisplayError, PatchDisplay};
use chromacal_model::screen::{Patch, ScreenContent};
use chromacal_sim::clock::VirtualClock;
use chromacal_sim::monitor::VirtualMonitor;

/// Drives a [`VirtualMonitor`].
#[derive(Debug, Clone)]
pub struct SimulatedDisplay {
    monitor: Arc<Mutex<VirtualMonitor>>,
    /// Seconds the display takes to settle after a change.
    settle_s: f64,
}

/// How the in-process virtual monitor's name begins (in journals and provenance), so
/// that a profile can be told to be of the simulation ([`is_simulated_display`]).
const SIMULATED_NAME: &str = "virtual monitor";

/// Whether `name`, a display's name as a journal records it, is the in-process
/// virtual monitor's.
pub fn is_simulated_display(name: &str) -> bool {
    name.starts_with(SIMULATED_NAME)
}

impl SimulatedDisplay {
    pub fn new(monitor: Arc<Mutex<VirtualMonitor>>, settle_s: f64) -> Self {
        SimulatedDisplay { monitor, settle_s }
    }

    /// Put `content` on the monitor; returns the monitor's clock to settle on.
    fn put(&self, content: ScreenContent) -> Result<Arc<VirtualClock>, DisplayError> {
        let mut monitor = self
            .monitor
            .lock()
            .map_err(|_| DisplayError::Lost("the virtual monitor's lock is poisoned".into()))?;
        monitor.show(content);
        Ok(monitor.clock().clone())
    }
}

impl PatchDisplay for SimulatedDisplay {
    fn name(&self) -> String {
        match self.monitor.lock() {
            Ok(m) => format!("{SIMULATED_NAME} '{}'", m.spec().name),
            Err(_) => SIMULATED_NAME.into(),
        }
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        let clock = self.put(patch.content())?;
        clock.wait(self.settle_s).await;
        Ok(())
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        self.put(ScreenContent::default())?;
        Ok(())
    }
}
