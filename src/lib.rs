//! chromacal, the application: the calibration loop and what it publishes. It runs a
//! plan on a display through an instrument, journals every reading, fits the monitor
//! model, publishes the profile to its store and to other tools, reports it, and runs
//! all of it as a daemon with a control API.
//!
//! The path from a patch to a published profile:
//! `chromacal_model::plan` → [`calibrate::run`] (show on a `chromacal_display` sink,
//! measure with a `chromacal_instruments` instrument, [`journal`]) →
//! `chromacal_model::fit` (model, selection, checks) → [`profile`] (native TOML,
//! store) → [`export`] (ICC, CGATS, `.cal` through `chromacal_formats`).
//!
//! The workspace's crates stand in layers, each depending only on those below it, so
//! the compiler keeps the layering: `chromacal-color` → `chromacal-model` →
//! `chromacal-formats` → `chromacal-sim` → `chromacal-instruments` →
//! `chromacal-display`, `chromacal-crf` → `chromacal` (this crate and the
//! `chromacal` command). Inside this crate the modules stand in layers too (lowest
//! first): `journal`, `measurement_file`, `argyll` → `profile` → `export` → `config`
//! → `calibrate` → `verification` → `html_report` → `daemon`, `report`, `comparison`,
//! `bench`; `tests/layers.rs` holds that list and checks it.

pub mod argyll;
pub mod bench;
pub mod calibrate;
pub mod comparison;
pub mod config;
pub mod daemon;
pub mod export;
pub mod html_report;
pub mod journal;
pub mod measurement_file;
pub mod profile;
pub mod report;
pub mod verification;
pub mod verify;
