//! The monitor model and its fit: the transfer laws, the spatial gain map and the
//! forward and inverse model built from them with the primary matrix and the black
//! (`monitor`, `transfer`, `spatial`, `target`); what a screen is sent (`screen`),
//! what an instrument reads (`reading`), measurements as data (`measurement`), the
//! patch sequence (`plan`); and the fit of the model to measurements with its model
//! selection on held-out data and the checks of the assumptions it rests on (`fit`).
//! Plain data and functions: no I/O beyond what a caller hands in, no async runtime.

pub mod fit;
pub mod grey_correction;
pub mod measurement;
pub mod monitor;
pub mod plan;
pub mod reading;
pub mod screen;
pub mod spatial;
pub mod target;
pub mod transfer;

pub use monitor::{CHANNELS, Drive, MonitorModel};
pub use spatial::{ScreenPosition, SpatialMap, Surface};
pub use transfer::{LawKind, TransferLaw};
