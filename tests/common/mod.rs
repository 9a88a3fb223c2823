//! Helpers shared by the integration tests: reading the public reference data in
//! `../shared/data`, which tests use but the project does not carry.
#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared/data`, relative to the crate root.
pub fn shared_data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

pub fn shared_path(relative: &str) -> PathBuf {
    shared_data_dir().join(relative)
}

pub fn shared_text(relative: &str) -> String {
    let path = shared_path(relative);
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("the tests need {}: {e}", path.display()))
}

/// A numeric CSV with one header row.
pub fn shared_table(relative: &str) -> Vec<Vec<f64>> {
    shared_text(relative)
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect()
}

/// A file under the project's `fixtures/`.
pub fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(relative)
}

/// The simulated LCD with its own seeds, as the fixtures use it.
pub const LCD_CONFIG: &str =
    "[monitor]\npreset = \"lcd\"\n[instrument.simulated]\nseed = 11\n[plan]\nseed = 11\n";

/// Path of the built `chromacal` binary.
pub fn chromacal() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_chromacal"))
}
