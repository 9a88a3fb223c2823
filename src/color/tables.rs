//! The CIE and colour-science tables compiled into the program (see `data/README.md`
//! for where each comes from). Rows are `[wavelength_nm, values...]`.

include!(concat!(env!("OUT_DIR"), "/tables.rs"));
