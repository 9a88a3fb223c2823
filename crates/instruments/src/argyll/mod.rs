//! The ArgyllCMS bridge: any instrument ArgyllCMS drives (some thirty USB colorimeters
//! and spectrometers, the i1Display Pro, SpyderX, ColorMunki and i1Pro among them),
//! through its `spotread` run on a pseudo-terminal.
//!
//! One spotread process serves a whole run, so the instrument is initialised once;
//! each reading is one keystroke and a parsed "Result is XYZ" line (and the spectrum,
//! from spectrometers). ArgyllCMS is an optional runtime dependency: without it the
//! bridge fails with an error saying so. Tested with ArgyllCMS 2.3.1 (Debian's
//! `argyll`).
//!
//! `protocol.rs` reads spotread's output as events, `transport.rs` runs the process on
//! its terminal, `driver.rs` holds the dialogue between them.

pub mod driver;
pub mod protocol;
pub mod transport;
