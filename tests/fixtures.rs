//! The recorded measurement fixtures in `fixtures/` are what the simulator produces:
//! this test makes them again and compares. With CHROMACAL_WRITE_FIXTURES=1 it writes
//! them instead (after a deliberate change of the simulator).

use std::path::{Path, PathBuf};

use chromacal::calibrate::session::{block_on, measure_simulated};
use chromacal::config::{DEFAULT_CONFIG, parse_config};
use chromacal::journal::Journal;
use chromacal_formats::cgats::to_ti3;

mod common;
use common::{LCD_CONFIG, fixture};

/// Readings kept in the interrupted fixture (of 96).
const INTERRUPTED_AFTER: usize = 40;

/// The built-in config with the plan the fixtures were recorded with, the default
/// before it became a sequential plan: fixed, 48 counted patches, 24 held out, a 5 × 5
/// grid.
fn recorded_default() -> String {
    let mut text = DEFAULT_CONFIG.to_string();
    for (now, then) in [
        ("strategy = \"sequential\"", "strategy = \"fixed\""),
        ("budget = 40 ", "budget = 48 "),
        ("verification = 12 ", "verification = 24 "),
        ("uniformity_grid = 3 ", "uniformity_grid = 5 "),
    ] {
        assert!(text.contains(now), "the built-in config has no '{now}'");
        text = text.replacen(now, then, 1);
    }
    text
}

fn generate(dir: &Path) {
    let journals = dir.join("journals");
    let ti3 = dir.join("ti3");
    std::fs::create_dir_all(&journals).unwrap();
    std::fs::create_dir_all(&ti3).unwrap();
    let here = Path::new(".");

    let default_text = recorded_default();
    let crt = parse_config(&default_text, "default").unwrap();
    let path = journals.join("crt-default.jsonl");
    let _ = std::fs::remove_file(&path);
    let journal = block_on(measure_simulated(&crt, &default_text, here, &path))
        .unwrap()
        .unwrap();
    std::fs::write(
        ti3.join("crt-default.ti3"),
        to_ti3(&journal.measurement_set()),
    )
    .unwrap();

    let lcd_text = LCD_CONFIG.to_string();
    let lcd = parse_config(&lcd_text, "lcd").unwrap();
    let path = journals.join("lcd-interrupted.jsonl");
    let _ = std::fs::remove_file(&path);
    block_on(measure_simulated(&lcd, &lcd_text, here, &path))
        .unwrap()
        .unwrap();
    // Keep the header and the first readings, and end in a line cut short, as a
    // run killed while writing leaves it.
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut cut = lines[..=INTERRUPTED_AFTER].join("\n");
    cut.push('\n');
    cut.push_str(&lines[INTERRUPTED_AFTER + 1][..40]);
    std::fs::write(&path, cut).unwrap();

    let lcd2_text = lcd_text.replace("seed = 11", "seed = 12");
    let lcd2 = parse_config(&lcd2_text, "lcd2").unwrap();
    let path = dir.join("lcd-seed12.jsonl");
    let _ = std::fs::remove_file(&path);
    let journal = block_on(measure_simulated(&lcd2, &lcd2_text, here, &path))
        .unwrap()
        .unwrap();
    std::fs::write(
        ti3.join("lcd-seed12.ti3"),
        to_ti3(&journal.measurement_set()),
    )
    .unwrap();
    let _ = std::fs::remove_file(&path);
}

fn entries(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn fixtures_are_what_the_simulator_makes() {
    if std::env::var_os("CHROMACAL_WRITE_FIXTURES").is_some() {
        generate(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures"));
    }
    let fresh = tempfile::tempdir().unwrap();
    generate(fresh.path());
    for journal in [
        "journals/crt-default.jsonl",
        "journals/lcd-interrupted.jsonl",
    ] {
        let recorded = entries(&fixture(journal));
        let made = entries(&fresh.path().join(journal));
        assert!(!recorded.is_empty(), "{journal} has no readings");
        assert_eq!(
            recorded, made,
            "{journal} differs from what the simulator makes now"
        );
    }
    for ti3 in ["ti3/crt-default.ti3", "ti3/lcd-seed12.ti3"] {
        let recorded = std::fs::read_to_string(fixture(ti3)).unwrap();
        let made = std::fs::read_to_string(fresh.path().join(ti3)).unwrap();
        assert_eq!(
            recorded, made,
            "{ti3} differs from what the simulator makes now"
        );
    }
    // The interrupted journal ends in a torn line that reading drops.
    let (_, entries, recovery) = Journal::read(&fixture("journals/lcd-interrupted.jsonl")).unwrap();
    assert_eq!(entries.len(), INTERRUPTED_AFTER);
    assert!(recovery.dropped_tail.is_some());
}
