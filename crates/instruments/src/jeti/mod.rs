//! JETI specbos 1211 spectroradiometer (FTDI virtual COM port, 921600/115200/38400
//! baud 8N1, `*`-commands, ACK/NAK/BEL control bytes).

pub mod driver;
pub mod emulator;
pub mod protocol;
