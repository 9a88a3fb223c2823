//! Konica Minolta LS-100 / LS-110 luminance meters and the CS-100A chroma meter
//! (RS-232, 4800 baud 7E2, CR LF).

pub mod driver;
pub mod emulator;
pub mod protocol;
