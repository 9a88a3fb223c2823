//! Issue 12, done-when: every parser of outside input, fed seeded mutations of real
//! files, for a bounded number of cases: no panic, no hang, and what it accepts holds
//! no number that is not finite. Then a sample of the same mutations through the real
//! commands: no crash, and no output with NaN or ∞ under exit 0.
//!
//! `CHROMACAL_FUZZ_CASES` sets the cases per parser (default 1500; `scripts/test.sh
//! --soak` runs more). A failing input is written to the temporary directory and its
//! path printed, to be replayed by hand.

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod common;
use common::{chromacal, fixture, shared_text};

fn cases() -> usize {
    std::env::var("CHROMACAL_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1500)
}

/// Tokens that broke parsers before: numbers out of all range, not numbers, signs,
/// quotes, NUL, separators.
const NASTY: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e-320",
    "-0",
    "0",
    "9223372036854775807",
    "18446744073709551616",
    "4294967295",
    "-1",
    "",
    "\"",
    "\0",
    ",",
    "[",
    "{",
    "}",
    "=",
    "\n",
    "BEGIN_DATA",
    "END_DATA",
];

/// One to three seeded edits of `seed`: a number replaced by a nasty token, a line
/// deleted, duplicated or swapped, the text cut short, or a nasty token inserted.
fn mutate(seed: &str, rng: &mut ChaCha8Rng) -> String {
    let mut text = seed.to_string();
    for _ in 0..rng.random_range(1..=3) {
        let nasty = NASTY[rng.random_range(0..NASTY.len())];
        match rng.random_range(0..6) {
            0 => {
                // Replace a number.
                let starts: Vec<usize> = text
                    .char_indices()
                    .filter(|(i, c)| {
                        c.is_ascii_digit()
                            && text[..*i]
                                .chars()
                                .last()
                                .is_none_or(|p| !p.is_ascii_alphanumeric() && p != '.')
                    })
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&at) = starts.get(rng.random_range(0..starts.len().max(1))) {
                    let end = text[at..]
                        .find(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)))
                        .map_or(text.len(), |n| at + n);
                    text.replace_range(at..end, nasty);
                }
            }
            1..=3 => {
                let mut lines: Vec<&str> = text.lines().collect();
                if lines.is_empty() {
                    continue;
                }
                let i = rng.random_range(0..lines.len());
                match rng.random_range(0..3) {
                    0 => {
                        lines.remove(i);
                    }
                    1 => lines.insert(i, lines[i]),
                    _ => {
                        let j = rng.random_range(0..lines.len());
                        lines.swap(i, j);
                    }
                }
                text = lines.join("\n") + "\n";
            }
            4 => {
                let mut cut = rng.random_range(0..=text.len());
                while !text.is_char_boundary(cut) {
                    cut -= 1;
                }
                text.truncate(cut);
            }
            _ => {
                let mut at = rng.random_range(0..=text.len());
                while !text.is_char_boundary(at) {
                    at -= 1;
                }
                text.insert_str(at, nasty);
            }
        }
    }
    text
}

/// What the worker says: an input about to be parsed, or how its parse ended.
enum Step {
    Started(usize, String),
    Ended(usize, Result<bool, String>),
}

/// Feed `cases()` mutations of each seed to `parse` on a worker thread; a panic, an
/// accepted input holding a number that is not finite, or one input taking over 10 s
/// fails the test with the input saved.
fn fuzz(name: &str, seeds: &[String], parse: fn(&str) -> Result<bool, String>) {
    let (send, receive) = mpsc::channel::<Step>();
    let seeds = seeds.to_vec();
    let total = cases();
    std::thread::spawn(move || {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for case in 0..total {
            let input = mutate(&seeds[case % seeds.len()], &mut rng);
            if send.send(Step::Started(case, input.clone())).is_err() {
                return;
            }
            let problem = match std::panic::catch_unwind(|| parse(&input)) {
                Err(_) => Err("panicked".to_string()),
                Ok(outcome) => outcome,
            };
            if send.send(Step::Ended(case, problem)).is_err() {
                return;
            }
        }
    });
    let save = |case: &str, input: &str| {
        let saved = std::env::temp_dir().join(format!("chromacal-fuzz-{name}-{case}"));
        std::fs::write(&saved, input).unwrap();
        saved
    };
    let mut current = (0, String::new());
    let (mut done, mut accepted) = (0, 0);
    while done < total {
        match receive.recv_timeout(Duration::from_secs(10)) {
            Ok(Step::Started(case, input)) => current = (case, input),
            Ok(Step::Ended(_, Ok(was_accepted))) => {
                done += 1;
                accepted += usize::from(was_accepted);
            }
            Ok(Step::Ended(case, Err(problem))) => {
                let saved = save(&case.to_string(), &current.1);
                panic!(
                    "{name}, case {case}: {problem}; input saved in {}",
                    saved.display()
                );
            }
            Err(_) => {
                let saved = save(&format!("{}-hang", current.0), &current.1);
                panic!(
                    "{name}, case {}: over 10 s on one input (a hang); saved in {}",
                    current.0,
                    saved.display()
                );
            }
        }
    }
    eprintln!(
        "{name}: {total} mutated inputs ({accepted} accepted), no panic, no hang, nothing accepted that is not finite"
    );
    // Mutations that the parser always refuses, or always accepts, test little.
    assert!(
        accepted > total / 20 && accepted < total - total / 20,
        "{name}: {accepted} of {total} accepted"
    );
}

/// Every float in a TOML or JSON text of a value is finite.
fn finite_json(value: &serde_json::Value) -> bool {
    match value {
        serde_json::Value::Number(n) => n.as_f64().is_none_or(f64::is_finite),
        serde_json::Value::Array(items) => items.iter().all(finite_json),
        serde_json::Value::Object(map) => map.values().all(finite_json),
        _ => true,
    }
}

fn accepted_but_not_finite(what: &str) -> Result<bool, String> {
    Err(format!(
        "accepted, but {what} holds a number that is not finite"
    ))
}

fn parse_ti3(text: &str) -> Result<bool, String> {
    let Ok(set) = chromacal_formats::cgats::ti3_from_text(text, "fuzz.ti3") else {
        return Ok(false);
    };
    let finite = set.measurements.iter().all(|m| {
        m.drive.iter().all(|d| d.is_finite())
            && m.reading
                .xyz
                .is_none_or(|x| x.iter().all(|v| v.is_finite()))
    });
    if !finite {
        return accepted_but_not_finite("a measurement set");
    }
    Ok(true)
}

fn parse_journal(text: &str) -> Result<bool, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let path = dir.path().join("journal.jsonl");
    std::fs::write(&path, text).map_err(|e| e.to_string())?;
    let Ok((_, entries, _)) = chromacal::journal::Journal::read(&path) else {
        return Ok(false);
    };
    for m in &entries {
        let value = serde_json::to_value(m).map_err(|e| e.to_string())?;
        if !finite_json(&value)
            || m.reading
                .xyz
                .is_some_and(|x| x.iter().any(|v| !v.is_finite()))
        {
            return accepted_but_not_finite("a journal entry");
        }
    }
    Ok(true)
}

fn parse_config(text: &str) -> Result<bool, String> {
    let Ok(config) = chromacal::config::parse_config(text, "fuzz.toml") else {
        return Ok(false);
    };
    // An accepted config builds its plan without running away.
    let _ = chromacal_model::plan::make_plan(&config.plan);
    Ok(true)
}

fn parse_profile(text: &str) -> Result<bool, String> {
    let Ok(profile) = chromacal::profile::Profile::from_toml(text, "fuzz.toml") else {
        return Ok(false);
    };
    // An accepted profile can be used: forward and inverse at a few drives and
    // places end, and what they give is finite.
    let model = &profile.model;
    for drive in [[0.0; 3], [0.5, 0.2, 0.9], [1.0; 3]] {
        for position in [
            chromacal_model::ScreenPosition::CENTRE,
            chromacal_model::ScreenPosition::new(0.05, 0.95),
        ] {
            let xyz = model.forward(drive, position);
            if xyz.iter().any(|v| !v.is_finite()) {
                return accepted_but_not_finite("a profile's forward model");
            }
            let _ = model.inverse(&xyz, position);
        }
    }
    Ok(true)
}

fn parse_csv(text: &str) -> Result<bool, String> {
    let Ok(table) =
        chromacal_formats::numeric_csv::NumericTable::parse(text, Path::new("fuzz.csv"))
    else {
        return Ok(false);
    };
    if table.rows.iter().flatten().any(|v| !v.is_finite()) {
        return accepted_but_not_finite("a numeric table");
    }
    Ok(true)
}

fn parse_ccmx(text: &str) -> Result<bool, String> {
    let Ok(ccmx) = chromacal_formats::ccmx::parse_ccmx(text, "fuzz.ccmx") else {
        return Ok(false);
    };
    // Accepted: a matrix the check itself passes (finite, invertible, light kept
    // light).
    if chromacal_formats::ccmx::check_matrix(&ccmx.matrix, "fuzz").is_err() {
        return Err("accepted a matrix its own check refuses".into());
    }
    Ok(true)
}

fn parse_ccss(text: &str) -> Result<bool, String> {
    let Ok(ccss) = chromacal_formats::ccss::parse_ccss(text, "fuzz.ccss") else {
        return Ok(false);
    };
    for s in &ccss.samples {
        if s.values()
            .iter()
            .chain(s.wavelengths_nm())
            .any(|v| !v.is_finite())
        {
            return accepted_but_not_finite("a .ccss sample");
        }
    }
    Ok(true)
}

/// EDID is binary: the seed is its hex, and what the mutations leave of hex digit
/// pairs is the blob.
fn parse_edid(text: &str) -> Result<bool, String> {
    let digits: Vec<u8> = text.bytes().filter(u8::is_ascii_hexdigit).collect();
    let bytes: Vec<u8> = digits
        .chunks_exact(2)
        .filter_map(|pair| u8::from_str_radix(std::str::from_utf8(pair).ok()?, 16).ok())
        .collect();
    let Ok(edid) = chromacal_formats::edid::Edid::parse(&bytes) else {
        return Ok(false);
    };
    let xy = [edid.red, edid.green, edid.blue, edid.white];
    if xy
        .iter()
        .flatten()
        .chain(edid.gamma.iter())
        .any(|v| !v.is_finite())
    {
        return accepted_but_not_finite("an EDID");
    }
    Ok(true)
}

fn parse_spectra(text: &str) -> Result<bool, String> {
    let Ok(file) = chromacal_crf::spectral_file::SpectralFile::parse(text, Path::new("fuzz.csv"))
    else {
        return Ok(false);
    };
    // Accepted spectra integrate to finite light.
    match file.emission_xyz() {
        Ok(xyz) if xyz.iter().all(|v| v.iter().all(|c| c.is_finite())) => Ok(true),
        Ok(_) => accepted_but_not_finite("a spectral file's XYZ"),
        Err(_) => Ok(true),
    }
}

#[test]
fn colorimeter_corrections() {
    let ccmx = chromacal_formats::ccmx::Ccmx {
        matrix: nalgebra::Matrix3::new(1.02, 0.01, -0.005, 0.0, 0.99, 0.01, 0.003, -0.02, 1.05),
        description: "fuzz seed".into(),
        display: "LCD".into(),
        instrument: "Klein K-10A".into(),
        reference: "Photo Research PR-670".into(),
        technology: "LCD White LED".into(),
    };
    fuzz(
        "ccmx",
        &[chromacal_formats::ccmx::ccmx_text(&ccmx, "now")],
        parse_ccmx,
    );
    let mut ccss = String::from(
        "CCSS\n\nDESCRIPTOR \"fuzz\"\nKEYWORD \"DISPLAY\"\nDISPLAY \"LCD\"\n\nNUMBER_OF_FIELDS 5\nBEGIN_DATA_FORMAT\nSAMPLE_ID SPEC_400 SPEC_500 SPEC_600 SPEC_700\nEND_DATA_FORMAT\n\nNUMBER_OF_SETS 4\nBEGIN_DATA\n",
    );
    for (i, row) in [
        "0.1 0.2 2.0 0.3",
        "0.1 2.0 0.4 0.1",
        "2.0 0.3 0.1 0.05",
        "1.0 1.1 1.2 0.9",
    ]
    .iter()
    .enumerate()
    {
        ccss += &format!("{} {row}\n", i + 1);
    }
    ccss += "END_DATA\n";
    fuzz("ccss", &[ccss], parse_ccss);
}

#[test]
fn edids() {
    let seeds: Vec<String> = ["srgb_office_1080p.bin", "wide_gamut_1440p.bin"]
        .iter()
        .map(|name| {
            std::fs::read(fixture(&format!("edid/{name}")))
                .unwrap()
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect()
        })
        .collect();
    fuzz("edid", &seeds, parse_edid);
}

#[test]
fn spectral_files() {
    fuzz(
        "spectra",
        &[std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("crates/color/data/displays/colour_typical_crt_brainard1997_5nm.csv"),
        )
        .unwrap()],
        parse_spectra,
    );
}

fn a_profile() -> String {
    let dir = tempfile::tempdir().unwrap();
    let out = chromacal()
        .args(["calibrate", "--state-dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read_to_string(dir.path().join("current.toml")).unwrap()
}

#[test]
fn cgats_files() {
    fuzz(
        "ti3",
        &[
            std::fs::read_to_string(fixture("ti3/lcd-seed12.ti3")).unwrap(),
            shared_text("measurements/macbookpro15_2014_colormunki_spectral_57.ti3"),
        ],
        parse_ti3,
    );
}

#[test]
fn journals() {
    fuzz(
        "journal",
        &[std::fs::read_to_string(fixture("journals/lcd-interrupted.jsonl")).unwrap()],
        parse_journal,
    );
}

#[test]
fn configs() {
    fuzz(
        "config",
        &[
            include_str!("../config/default.toml").to_string(),
            "[plan]\nstrategy = \"fixed\"\nbudget = 48\nuniformity_grid = 5\n[instrument.simulated]\nintegration_s = 1.0\n"
                .to_string(),
        ],
        parse_config,
    );
}

#[test]
fn profiles() {
    fuzz("profile", &[a_profile()], parse_profile);
}

#[test]
fn numeric_tables() {
    fuzz(
        "csv",
        &[std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("crates/color/data/displays/colour_typical_crt_brainard1997_5nm.csv"),
        )
        .unwrap()],
        parse_csv,
    );
}

/// A sample of mutated profiles and measurement files through the real commands:
/// every run ends with a status (no signal, no panic's 101), and a run that succeeds
/// prints no NaN or ∞.
#[test]
fn the_commands_on_mutated_files() {
    let dir = tempfile::tempdir().unwrap();
    let profile = a_profile();
    let good_profile = dir.path().join("good.toml");
    std::fs::write(&good_profile, &profile).unwrap();
    let ti3 = std::fs::read_to_string(fixture("ti3/lcd-seed12.ti3")).unwrap();
    let spectra = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("crates/color/data/displays/colour_typical_crt_brainard1997_5nm.csv"),
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let runs = (cases() / 25).max(20);
    let mut failures_refused = 0;
    for case in 0..runs {
        let (args, file): (Vec<String>, _) = if case % 3 == 2 {
            let path = dir.path().join(format!("s{case}.csv"));
            std::fs::write(&path, mutate(&spectra, &mut rng)).unwrap();
            (vec!["spectrum".into(), path.display().to_string()], path)
        } else if case % 2 == 0 {
            let path = dir.path().join(format!("p{case}.toml"));
            std::fs::write(&path, mutate(&profile, &mut rng)).unwrap();
            (
                vec!["profile".into(), "show".into(), path.display().to_string()],
                path,
            )
        } else {
            let path = dir.path().join(format!("m{case}.ti3"));
            std::fs::write(&path, mutate(&ti3, &mut rng)).unwrap();
            (
                vec![
                    "check".into(),
                    good_profile.display().to_string(),
                    path.display().to_string(),
                ],
                path,
            )
        };
        let out = chromacal().args(&args).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let code = out.status.code();
        assert!(
            code.is_some_and(|c| c != 101),
            "{args:?} ended with {:?}: {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        if code == Some(0) {
            // A number printed as NaN or ∞ (not those letters inside a word, which a
            // mutated text field may hold).
            let words: Vec<&str> = stdout
                .split(|c: char| c.is_whitespace() || "(),:=[]".contains(c))
                .collect();
            for word in ["NaN", "inf", "-inf", "+inf"] {
                if words.contains(&word) {
                    let saved = std::env::temp_dir().join(format!("chromacal-fuzz-command-{case}"));
                    std::fs::copy(&file, &saved).unwrap();
                    panic!(
                        "{args:?} succeeded printing {word}: {stdout}\n(input saved in {})",
                        saved.display()
                    );
                }
            }
        } else {
            failures_refused += 1;
        }
    }
    eprintln!("{runs} command runs on mutated files, {failures_refused} refused with a message");
}
