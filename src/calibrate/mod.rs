//! A calibration run: the plan, the measuring loop, the journal.

pub mod adjust;
pub mod correction;
pub mod devices;
pub mod displays;
pub mod keep_lut;
pub mod refine;
pub mod retention;
pub mod rig;
pub mod run;
pub mod sequential;
pub mod session;
pub mod verify;
pub mod video_lut;
pub mod warmup;
pub mod wayland_lut;
