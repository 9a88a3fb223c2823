//! Photo Research PR-650 spectroradiometer (RS-232, 9600 8N1, LF-terminated commands,
//! CR LF replies, remote control armed at power-up).

pub mod driver;
pub mod emulator;
pub mod protocol;
