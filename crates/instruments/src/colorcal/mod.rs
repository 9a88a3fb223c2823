//! CRS ColorCAL MKII colorimeter (USB CDC serial port, any baud, LF-terminated
//! commands, `\n\r`-framed replies ending in a `>` prompt).

pub mod driver;
pub mod emulator;
pub mod protocol;
