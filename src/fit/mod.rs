//! Fitting the monitor model to measurements, choosing among its candidate parts on
//! held-out data, and testing the assumptions it rests on.

pub mod least_squares;
pub mod stats;
