//! Photo Research PR-655 and PR-670 spectroradiometers (USB virtual serial port,
//! 9600 8N1, CR-terminated commands sent one character at a time).

pub mod driver;
pub mod emulator;
pub mod protocol;
