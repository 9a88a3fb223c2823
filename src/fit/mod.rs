//! Fitting the monitor model to measurements, choosing among its candidate parts on
//! held-out data, and testing the assumptions it rests on.

pub mod laws;
pub mod least_squares;
pub mod noise;
pub mod primaries;
pub mod select;
pub mod stats;
