//! The command line, one file a command: each holds its clap arguments beside the code
//! that runs it, and ends in `run(args) -> Result<(), Failure>`. `main.rs` only parses
//! and dispatches; what the commands share is in `shared`.

pub mod bench;
pub mod bench_render;
pub mod bench_spectral;
pub mod calibrate;
pub mod check;
pub mod daemon;
pub mod emulate;
pub mod export;
pub mod fit;
pub mod instruments;
pub mod measure;
pub mod profile;
pub mod render;
pub mod report;
pub mod shared;
pub mod spectrum;
