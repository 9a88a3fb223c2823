//! chromacal: measure a display, fit a physical model of it, test the assumptions the
//! model rests on, and publish the result as a monitor profile.
//!
//! The path from a patch to a published profile:
//! [`plan`] → [`calibrate::run`] (show, settle, measure, [`journal`]) →
//! [`fit`] (model, selection, checks) → [`profile`] (native TOML, store).
//!
//! The modules stand in layers, each importing only from those below it (lowest
//! first): `durable`, `linalg` → `color`, `numeric_csv`, `time` → `model` → `screen`, `edid` → `x11` → `sim` →
//! `instrument` → `display` → `measurement` → `plan` → `journal`, `cgats` →
//! `measurement_file`, `argyll`, `ccmx` → `fit` → `profile` → `export` → `config` →
//! `calibrate` → `daemon`, `report`, `comparison`. `tests/layers.rs` holds the list
//! and checks it.

// `!(x > 0.0)` is how this crate says "x is not positive, or not a number": NaN
// must fail every such check, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod argyll;
pub mod calibrate;
pub mod ccmx;
pub mod ccss;
pub mod cgats;
pub mod color;
pub mod comparison;
pub mod config;
pub mod crf;
pub mod daemon;
pub mod display;
pub mod durable;
pub mod edid;
pub mod export;
pub mod fit;
pub mod html_report;
pub mod instrument;
pub mod journal;
pub mod linalg;
pub mod measurement;
pub mod measurement_file;
pub mod model;
pub mod numeric_csv;
pub mod plan;
pub mod profile;
pub mod report;
pub mod screen;
pub mod sim;
pub mod time;
pub mod verification;
pub mod x11;
