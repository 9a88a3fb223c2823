//! Colorimetry for chromacal, and for anyone who needs it without a monitor: the CIE
//! observers and illuminants (compiled in from the tables in `data/`), spectra to
//! tristimulus values, the CIE colour spaces, colour differences (CIEDE2000 and
//! others), correlated colour temperature, chromatic adaptation, and the small
//! decompositions (`linalg`) the layers above share. It depends on nothing of
//! chromacal's; each function names the standard or paper and the equation it
//! implements.

pub mod adaptation;
pub mod difference;
pub mod gamut;
pub mod hdr;
pub mod ictcp;
pub mod linalg;
pub mod spaces;
pub mod spectrum;
pub mod tables;
pub mod temperature;

pub use difference::delta_e_2000;
pub use spaces::{Lab, Luv, UvPrime, Xyy, Xyz, xyz_to_lab};
