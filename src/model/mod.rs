//! The monitor model: transfer laws, the spatial gain map, and the forward and
//! inverse model built from them with the primary matrix and the black.

pub mod monitor;
pub mod spatial;
pub mod target;
pub mod transfer;

pub use monitor::{CHANNELS, Drive, MonitorModel};
pub use spatial::{ScreenPosition, SpatialMap, Surface};
pub use transfer::{LawKind, TransferLaw};
