//! Simulation: the virtual monitor and the virtual clock it runs on. The simulated
//! display (`display::simulated`) and instrument (`instrument::simulated`) drive and
//! read a [`monitor::VirtualMonitor`].

pub mod clock;
pub mod monitor;
pub mod presets;
