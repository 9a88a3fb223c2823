//! The CIE and colour-science tables compiled into the program (see `data/README.md`
//! for where each comes from). Rows are `[wavelength_nm, values...]`.
//!
//! The numbers are measurements as published: a reflectance of 0.318 is not 1/π,
//! whatever clippy's `approx_constant` thinks of it.

#![allow(clippy::approx_constant)]

include!(concat!(env!("OUT_DIR"), "/tables.rs"));
