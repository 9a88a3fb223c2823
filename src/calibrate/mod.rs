//! A calibration run: the plan, the measuring loop, the journal.

pub mod devices;
pub mod journal;
pub mod plan;
pub mod refine;
pub mod run;
pub mod session;
pub mod warmup;
