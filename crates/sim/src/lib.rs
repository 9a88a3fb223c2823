//! The virtual monitor and the virtual clock it runs on: a physical model of a
//! display built from measured primary spectra and transfer tables, with black,
//! flare, spatial falloff, optional failures of each of the model's assumptions,
//! drift and warm-up (`monitor`, `presets`). The simulated display
//! (`chromacal_display::simulated`), the simulated instrument and every instrument
//! emulator (`chromacal_instruments`) show patches on it and read it, so whole
//! calibrations run in tests without hardware, in milliseconds of virtual time or in
//! real time when a person watches.

pub mod clock;
pub mod hdr;
pub mod monitor;
pub mod presets;
