//! A simulated rig: a virtual monitor on a virtual clock, with the simulated display
//! that shows patches on it and the simulated instrument that reads it.

use std::sync::{Arc, Mutex};

use chromacal_display::simulated::SimulatedDisplay;
use chromacal_instruments::simulated::{SimulatedInstrument, SimulatedInstrumentSpec};
use chromacal_sim::clock::VirtualClock;
use chromacal_sim::monitor::{MonitorSpec, SimError, VirtualMonitor};

/// Everything a simulated calibration needs.
#[derive(Debug, Clone)]
pub struct SimulatedRig {
    pub clock: Arc<VirtualClock>,
    pub monitor: Arc<Mutex<VirtualMonitor>>,
    pub display: SimulatedDisplay,
    pub instrument: SimulatedInstrument,
}

impl SimulatedRig {
    /// `realtime_scale`: real seconds per simulated second, or `None` to run at once.
    pub fn new(
        monitor: MonitorSpec,
        instrument: SimulatedInstrumentSpec,
        settle_s: f64,
        realtime_scale: Option<f64>,
    ) -> Result<Self, SimError> {
        let clock = Arc::new(VirtualClock::new(realtime_scale));
        let monitor = Arc::new(Mutex::new(VirtualMonitor::new(monitor, clock.clone())?));
        Ok(SimulatedRig {
            display: SimulatedDisplay::new(monitor.clone(), settle_s),
            instrument: SimulatedInstrument::new(monitor.clone(), instrument),
            clock,
            monitor,
        })
    }
}
