//! Colorimetry: the CIE observers and illuminants, spectra to tristimulus values,
//! the CIE colour spaces, colour differences and chromatic adaptation.
//!
//! Each function names the standard or paper and the equation it implements.

pub mod adaptation;
pub mod difference;
pub mod gamut;
pub mod spaces;
pub mod spectrum;
pub mod tables;
pub mod temperature;

pub use difference::delta_e_2000;
pub use spaces::{Lab, Luv, UvPrime, Xyy, Xyz, xyz_to_lab};
