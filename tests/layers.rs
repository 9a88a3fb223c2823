//! The shape of the code, checked: the library's top-level modules stand in layers and
//! import only from layers below their own (so no two modules import each other, and
//! no longer loop either), `main.rs` only parses and dispatches, and the fit's steps
//! stay short enough to read. Read from the source files, as `use crate::` lines and
//! `crate::` paths, outside comments and test modules.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

/// The layers, lowest first. A module may import from any layer below its own and
/// from none at or above it. A new top-level module must be placed here.
const LAYERS: &[&[&str]] = &[
    // Foundations: crash-safe and size-limited files, decompositions that end.
    &["durable", "linalg"],
    // Colorimetry, numeric CSV tables, clocks.
    &["color", "numeric_csv", "time"],
    // The monitor model: transfer laws, spatial map, targets.
    &["model"],
    // What a screen shows: codes, patch windows, content.
    // What a screen shows, and what a monitor says of itself (its EDID).
    &["screen", "edid"],
    // The X server of a real screen: outputs, gamma ramps, pixels.
    &["x11"],
    // The virtual monitor and its clock.
    &["sim"],
    // Instruments: drivers, protocols, emulators.
    &["instrument"],
    // Patch displays: the sinks.
    &["display"],
    // Measurements as data.
    &["measurement"],
    // The patch sequence.
    &["plan"],
    // The two measurement file formats.
    &["journal", "cgats"],
    // Reading either of them; ArgyllCMS as a yardstick, fed the same files.
    &["measurement_file", "argyll", "ccmx", "ccss"],
    &["fit"],
    &["profile"],
    // The colour reproduction function: scenes through a profile's model.
    &["crf"],
    &["export"],
    &["config"],
    &["calibrate"],
    // A profile verified against readings, in the terms calibration people use.
    &["verification"],
    // The HTML report: a profile, its readings and its history as a page.
    &["html_report"],
    // The service, the text a command prints, and comparisons with other tools.
    &["daemon", "report", "comparison"],
];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The file's code without its test module (which may build on anything) and without
/// comments, with each kept line's number.
fn code_lines(text: &str) -> Vec<(usize, String)> {
    let mut lines = Vec::new();
    let all: Vec<&str> = text.lines().collect();
    for (i, line) in all.iter().enumerate() {
        // The test module, which ends the file by this crate's custom; a `#[cfg(test)]`
        // on anything else hides nothing.
        let next = all.get(i + 1).map_or("", |l| l.trim_start());
        if line.trim() == "#[cfg(test)]" && next.starts_with("mod ") {
            break;
        }
        let code = match line.find("//") {
            Some(k) => &line[..k],
            None => line,
        };
        if !code.trim().is_empty() {
            lines.push((i + 1, code.to_string()));
        }
    }
    lines
}

/// Top-level module of a file under src/ (`fit/laws.rs` → `fit`, `plan.rs` → `plan`).
fn top_module(path: &Path) -> String {
    let relative = path.strip_prefix(src()).unwrap();
    let first = relative.components().next().unwrap();
    let name = first.as_os_str().to_string_lossy();
    name.trim_end_matches(".rs").to_string()
}

/// Every `crate::NAME` in the library: (importing module, imported module) → where.
fn imports() -> BTreeMap<(String, String), Vec<String>> {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut found: BTreeMap<(String, String), Vec<String>> = BTreeMap::new();
    for path in files {
        let from = top_module(&path);
        if from == "main" || from == "lib" || from == "cli" {
            continue;
        }
        let text = fs::read_to_string(&path).unwrap();
        for (number, line) in code_lines(&text) {
            let mut rest = line.as_str();
            while let Some(k) = rest.find("crate::") {
                let after = &rest[k + "crate::".len()..];
                // `crate::name…`, or a group `crate::{a::x, b::y}` (on this line).
                let names: Vec<String> = match after.strip_prefix('{') {
                    Some(group) => group
                        .split(['}', ','])
                        .map(|item| leading_name(item.trim()))
                        .collect(),
                    None => vec![leading_name(after)],
                };
                for name in names {
                    if !name.is_empty() && name != from {
                        let relative = path.strip_prefix(src()).unwrap().display().to_string();
                        found
                            .entry((from.clone(), name))
                            .or_default()
                            .push(format!("src/{relative}:{number}"));
                    }
                }
                rest = after;
            }
        }
    }
    found
}

/// The identifier a path starts with.
fn leading_name(path: &str) -> String {
    path.chars()
        .take_while(|c| c.is_alphanumeric() || *c == '_')
        .collect()
}

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|layer| layer.contains(&module))
}

#[test]
fn every_top_level_module_has_a_layer() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut missing: Vec<String> = files
        .iter()
        .map(|p| top_module(p))
        .filter(|m| !matches!(m.as_str(), "main" | "lib" | "cli"))
        .filter(|m| layer_of(m).is_none())
        .collect();
    missing.dedup();
    assert!(
        missing.is_empty(),
        "modules with no place in tests/layers.rs LAYERS: {missing:?}"
    );
}

#[test]
fn modules_import_only_from_layers_below_their_own() {
    let mut wrong = Vec::new();
    for ((from, to), places) in imports() {
        let (Some(a), Some(b)) = (layer_of(&from), layer_of(&to)) else {
            // A path this test cannot place (an item re-exported at the crate root, a
            // module with no layer) would hide an import: name it.
            wrong.push(format!(
                "{from} imports crate::{to}, which has no layer, at {}",
                places.join(", ")
            ));
            continue;
        };
        if b >= a {
            wrong.push(format!("{from} imports {to} at {}", places.join(", ")));
        }
    }
    assert!(
        wrong.is_empty(),
        "imports that go up or sideways:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn no_two_modules_import_each_other() {
    let found = imports();
    let loops: Vec<String> = found
        .keys()
        .filter(|(a, b)| a < b && found.contains_key(&(b.clone(), a.clone())))
        .map(|(a, b)| format!("{a} ⇄ {b}"))
        .collect();
    assert!(loops.is_empty(), "import loops: {loops:?}");
}

#[test]
fn config_and_measurement_stand_below_the_run() {
    let found = imports();
    for (from, banned) in [
        ("config", &["calibrate", "daemon"][..]),
        ("measurement", &["calibrate", "journal", "cgats"][..]),
    ] {
        for to in banned {
            assert!(
                !found.contains_key(&(from.to_string(), to.to_string())),
                "{from} imports {to}: {:?}",
                found[&(from.to_string(), to.to_string())]
            );
        }
    }
}

#[test]
fn main_only_parses_and_dispatches() {
    let text = fs::read_to_string(src().join("main.rs")).unwrap();
    let lines = text.lines().count();
    assert!(lines < 150, "src/main.rs has {lines} lines");
    for command in [
        "bench",
        "calibrate",
        "check",
        "daemon",
        "emulate",
        "export",
        "fit",
        "instruments",
        "measure",
        "profile",
        "spectrum",
    ] {
        assert!(
            src().join("cli").join(format!("{command}.rs")).is_file(),
            "src/cli/{command}.rs is missing"
        );
    }
}

/// Functions (with their name and first line) longer than `limit` lines: from a line
/// that starts a `fn` to the closing brace at the same indentation.
fn long_functions(path: &Path, limit: usize) -> Vec<String> {
    let text = fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut long = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let indent = &line[..line.len() - trimmed.len()];
        let signature = [
            "fn ",
            "pub fn ",
            "pub(crate) fn ",
            "pub(super) fn ",
            "async fn ",
        ]
        .iter()
        .find_map(|p| trimmed.strip_prefix(p));
        let Some(signature) = signature else { continue };
        if trimmed.ends_with(';') {
            continue; // a declaration in a trait
        }
        let end = lines[i..]
            .iter()
            .position(|l| *l == format!("{indent}}}"))
            .map(|k| i + k);
        let Some(end) = end else { continue };
        let length = end - i + 1;
        if length > limit {
            let name: String = signature
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            long.push(format!(
                "{}:{} {name}: {length} lines",
                path.display(),
                i + 1
            ));
        }
    }
    long
}

#[test]
fn no_function_in_the_fit_is_longer_than_80_lines() {
    let mut files = Vec::new();
    rust_files(&src().join("fit"), &mut files);
    let long: Vec<String> = files.iter().flat_map(|f| long_functions(f, 80)).collect();
    assert!(long.is_empty(), "{}", long.join("\n"));
}
