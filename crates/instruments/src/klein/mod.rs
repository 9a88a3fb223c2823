//! Klein K-10 / K-10A colorimeters (FTDI virtual COM port, 9600 8N1, binary replies).

pub mod driver;
pub mod emulator;
pub mod protocol;
