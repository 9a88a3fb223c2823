//! The shape of the code, checked where Cargo cannot check it.
//!
//! Cargo keeps the layers between the workspace's crates: a crate cannot use one
//! that depends on it. What Cargo does not know, this file checks: the order of the
//! layers (each crate depends only on crates below it in [`CRATES`]); that the
//! colorimetry, model and instrument crates build without an async runtime, X11,
//! HTTP, D-Bus or MQTT; that no two files of a crate import each other, however
//! long the way round (no circles); that the application's modules stand in layers
//! of their own; that commands stay thin; and that the fit's steps stay short. Read
//! from the source files, as `crate::`, `super::` and `self::` paths outside comments
//! and test modules.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The workspace's crates, lowest first, with their folders. A crate may depend on
/// crates before it and on none after it.
const CRATES: &[(&str, &str)] = &[
    ("chromacal-color", "crates/color"),
    ("chromacal-model", "crates/model"),
    ("chromacal-formats", "crates/formats"),
    ("chromacal-sim", "crates/sim"),
    ("chromacal-instruments", "crates/instruments"),
    ("chromacal-display", "crates/display"),
    ("chromacal-crf", "crates/crf"),
    ("chromacal", "."),
];

/// Crates others may use on their own: none of these in their dependency tree.
const STANDALONE: &[&str] = &[
    "chromacal-color",
    "chromacal-model",
    "chromacal-instruments",
];
const HEAVY: &[&str] = &["tokio", "x11rb", "axum", "hyper", "zbus", "rumqttc"];

/// The application crate's top-level modules in layers, lowest first: a module may
/// import from layers below its own and from none at or above it.
const APP_LAYERS: &[&[&str]] = &[
    // The run's journal, reading it or a `.ti3`, ArgyllCMS as a yardstick.
    &["journal"],
    &["measurement_file", "argyll"],
    // The native profile and its store; what goes out to other tools.
    &["profile"],
    &["export"],
    &["config"],
    // The calibrated display verified: charts, criteria, judgement.
    &["verify"],
    // The calibration loop.
    &["calibrate"],
    // A profile verified against readings, in the terms calibration people use.
    &["verification"],
    // The HTML report: a profile, its readings and its history as a page.
    &["html_report"],
    // The service, the text a command prints, comparisons with other tools.
    &["daemon", "report", "comparison"],
    // Speed against error, as tables.
    &["bench"],
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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
        // The test module, which ends the file by this project's custom; a
        // `#[cfg(test)]` on anything else hides nothing.
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

/// A module's path inside its crate, from its file (`fit/laws.rs` → `fit::laws`,
/// `fit/mod.rs` → `fit`, `lib.rs` → the root).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The identifier a path starts with, and the rest.
fn split_name(path: &str) -> (&str, &str) {
    let end = path
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(path.len());
    path.split_at(end)
}

/// The segments of each path in `code` that starts with `crate::`, `super::` or
/// `self::`, resolved against `module` to a path from the crate's root; a group
/// (`super::{a::x, b}`) gives one path an item.
fn paths_in(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    let mut rest = code;
    while let Some(k) = ["crate::", "super::", "self::"]
        .iter()
        .filter_map(|p| rest.find(p).map(|k| (k, *p)))
        .min()
    {
        let (k, prefix) = k;
        // Part of a longer name (`$crate::`, `my_self::`) is not a path of ours.
        let before = rest[..k].chars().last();
        rest = &rest[k + prefix.len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let mut base: Vec<String> = match prefix {
            "crate::" => Vec::new(),
            "super::" => module[..module.len().saturating_sub(1)].to_vec(),
            _ => module.to_vec(),
        };
        let mut tail = rest;
        loop {
            if let Some(group) = tail.strip_prefix('{') {
                let inner = group.split('}').next().unwrap_or("");
                for item in inner.split(',') {
                    let mut path = base.clone();
                    path.extend(item.trim().split("::").map(|s| split_name(s).0.to_string()));
                    found.push(path);
                }
                break;
            }
            let (name, after) = split_name(tail);
            if name.is_empty() {
                found.push(base);
                break;
            }
            if name == "super" {
                base.pop();
            } else {
                base.push(name.to_string());
            }
            match after.strip_prefix("::") {
                Some(next) => tail = next,
                None => {
                    found.push(base);
                    break;
                }
            }
        }
    }
    found
}

/// Every file of a crate's `src` as its module path, and which other modules of the
/// crate each one imports (the longest module path a path names), with where.
fn file_imports(src: &Path) -> BTreeMap<Vec<String>, BTreeMap<Vec<String>, String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeSet<Vec<String>> = files.iter().map(|f| module_of(src, f)).collect();
    let mut imports = BTreeMap::new();
    for file in &files {
        let module = module_of(src, file);
        let text = fs::read_to_string(file).unwrap();
        let mut targets: BTreeMap<Vec<String>, String> = BTreeMap::new();
        for (number, line) in code_lines(&text) {
            for path in paths_in(&line, &module) {
                let target = (0..=path.len())
                    .rev()
                    .map(|k| path[..k].to_vec())
                    .find(|p| modules.contains(p));
                let Some(target) = target else { continue };
                // A module's own parts, and the modules that hold it, are not an import
                // that can close a circle through it.
                if target == module || module.starts_with(&target) || target.starts_with(&module) {
                    continue;
                }
                let place = format!("{}:{number}", file.strip_prefix(root()).unwrap().display());
                targets.entry(target).or_insert(place);
            }
        }
        imports.insert(module, targets);
    }
    imports
}

/// The circles of an import graph (its strongly connected parts of more than one
/// module), by Tarjan's algorithm.
fn circles(graph: &BTreeMap<Vec<String>, BTreeMap<Vec<String>, String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<Vec<String>, BTreeMap<Vec<String>, String>>,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Vec<String>) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        let graph = s.graph;
        for w in graph.get(v).into_iter().flat_map(|t| t.keys()) {
            let Some((w, _)) = graph.get_key_value(w) else {
                continue;
            };
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[w].min(s.low[v]);
                s.low.insert(v, low);
            } else if s.stack.contains(&w) {
                let low = s.index[w].min(s.low[v]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut part = Vec::new();
            while let Some(w) = s.stack.pop() {
                part.push(w.join("::"));
                if w == v {
                    break;
                }
            }
            if part.len() > 1 {
                part.sort();
                s.found.push(part);
            }
        }
    }
    let mut state = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for v in graph.keys() {
        if !state.index.contains_key(v) {
            visit(&mut state, v);
        }
    }
    state.found
}

/// The `chromacal-*` crates a crate's manifest names, in any dependency table.
fn workspace_dependencies(dir: &str) -> Vec<String> {
    let manifest = fs::read_to_string(root().join(dir).join("Cargo.toml")).unwrap();
    let mut names = Vec::new();
    let mut in_dependencies = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_dependencies = line.contains("dependencies") && !line.starts_with("[workspace");
            continue;
        }
        if in_dependencies && line.starts_with("chromacal-") {
            names.push(split_name_dash(line));
        }
    }
    names
}

fn split_name_dash(line: &str) -> String {
    line.chars()
        .take_while(|c| c.is_alphanumeric() || *c == '-' || *c == '_')
        .collect()
}

#[test]
fn every_crate_of_the_workspace_has_a_layer() {
    let mut folders: Vec<String> = fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|e| format!("crates/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    folders.sort();
    let mut listed: Vec<String> = CRATES
        .iter()
        .filter(|(_, dir)| *dir != ".")
        .map(|(_, dir)| dir.to_string())
        .collect();
    listed.sort();
    assert_eq!(folders, listed, "crates/ and CRATES differ");
}

#[test]
fn crates_depend_only_on_crates_below_them() {
    let mut wrong = Vec::new();
    for (level, (name, dir)) in CRATES.iter().enumerate() {
        for dependency in workspace_dependencies(dir) {
            match CRATES.iter().position(|(n, _)| *n == dependency) {
                Some(below) if below < level => {}
                Some(_) => wrong.push(format!("{name} depends on {dependency}, at or above it")),
                None => wrong.push(format!(
                    "{name} depends on {dependency}, which has no layer"
                )),
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_standalone_crates_need_no_runtime_x11_http_dbus_or_mqtt() {
    for name in STANDALONE {
        let output = std::process::Command::new(env!("CARGO"))
            .args(["tree", "--locked", "--offline", "--prefix", "none"])
            .args(["-e", "normal,build,dev", "-p", name])
            .current_dir(root())
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "cargo tree -p {name}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let tree = String::from_utf8_lossy(&output.stdout);
        let packages: BTreeSet<&str> = tree
            .lines()
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        assert!(packages.len() > 3, "cargo tree -p {name} printed:\n{tree}");
        let found: Vec<&&str> = HEAVY.iter().filter(|h| packages.contains(**h)).collect();
        assert!(found.is_empty(), "{name} pulls in {found:?}");
    }
}

#[test]
fn no_two_files_of_a_crate_import_each_other_even_the_long_way_round() {
    let mut found = Vec::new();
    for (name, dir) in CRATES {
        let src = root().join(dir).join("src");
        for circle in circles(&file_imports(&src)) {
            found.push(format!("{name}: {}", circle.join(" ⇄ ")));
        }
    }
    assert!(found.is_empty(), "import circles:\n{}", found.join("\n"));
}

#[test]
fn the_circle_finder_finds_a_circle() {
    // What the test above relies on, on a made-up graph: a → b → c → a and d → a.
    let module = |s: &str| vec![s.to_string()];
    let mut graph = BTreeMap::new();
    for (from, to) in [("a", "b"), ("b", "c"), ("c", "a"), ("d", "a")] {
        graph
            .entry(module(from))
            .or_insert_with(BTreeMap::new)
            .insert(module(to), String::new());
    }
    graph.insert(module("e"), BTreeMap::new());
    assert_eq!(circles(&graph), vec![vec!["a", "b", "c"]]);
    // And the paths it reads: a group, `super::`, and a name that only ends in `crate`.
    let paths = paths_in(
        "use super::{x::y, z}; let a = crate::fit::laws::f(); my_crate::q();",
        &["calibrate".into(), "run".into()],
    );
    assert_eq!(
        paths,
        vec![
            vec!["calibrate", "x", "y"],
            vec!["calibrate", "z"],
            vec!["fit", "laws", "f"],
        ]
    );
}

#[test]
fn the_applications_modules_import_only_from_layers_below_their_own() {
    let layer_of = |m: &str| APP_LAYERS.iter().position(|l| l.contains(&m));
    let src = root().join("src");
    let mut wrong = Vec::new();
    for (module, targets) in file_imports(&src) {
        let Some(from) = module.first() else { continue };
        if from == "cli" {
            continue; // the binary's own modules
        }
        let Some(a) = layer_of(from) else {
            wrong.push(format!("{from} has no place in APP_LAYERS"));
            continue;
        };
        for (target, place) in targets {
            let to = &target[0];
            if to == from {
                continue;
            }
            match layer_of(to) {
                Some(b) if b < a => {}
                _ => wrong.push(format!("{from} imports {to} at {place}")),
            }
        }
    }
    wrong.dedup();
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn commands_stay_thin() {
    let main = fs::read_to_string(root().join("src/main.rs")).unwrap();
    let lines = main.lines().count();
    assert!(lines < 150, "src/main.rs has {lines} lines");
    let mut files = Vec::new();
    rust_files(&root().join("src/cli"), &mut files);
    let long: Vec<String> = files
        .iter()
        .map(|f| (f, fs::read_to_string(f).unwrap().lines().count()))
        .filter(|(_, n)| *n > 300)
        .map(|(f, n)| format!("{}: {n} lines", f.display()))
        .collect();
    assert!(
        long.is_empty(),
        "command files over 300 lines:\n{}",
        long.join("\n")
    );
    // The bench command prints what `chromacal::bench` makes: no table of its own.
    let bench = fs::read_to_string(root().join("src/cli/bench.rs")).unwrap();
    let functions = bench.matches("fn ").count();
    assert!(
        functions == 1 && bench.contains("chromacal::bench::run("),
        "src/cli/bench.rs holds {functions} functions"
    );
    let stray: Vec<&PathBuf> = files
        .iter()
        .filter(|f| {
            f.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("bench_"))
        })
        .collect();
    assert!(
        stray.is_empty(),
        "bench code in the command line: {stray:?}"
    );
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
    rust_files(&root().join("crates/model/src/fit"), &mut files);
    assert!(files.len() > 10, "the fit's files: {files:?}");
    let long: Vec<String> = files.iter().flat_map(|f| long_functions(f, 80)).collect();
    assert!(long.is_empty(), "{}", long.join("\n"));
}

#[test]
fn every_crate_says_what_it_is_and_can_be_published() {
    for (name, dir) in CRATES {
        let folder = root().join(dir);
        let manifest = fs::read_to_string(folder.join("Cargo.toml")).unwrap();
        for key in ["description", "license", "readme"] {
            assert!(
                manifest.lines().any(|l| l.starts_with(&format!("{key} "))
                    || l.starts_with(&format!("{key}.workspace"))),
                "{name}: no {key} in its Cargo.toml"
            );
        }
        let readme = folder.join("README.md");
        assert!(readme.is_file(), "{name}: no README.md");
        // A crate doc of at least a paragraph, first in its root file.
        let lib = fs::read_to_string(folder.join("src/lib.rs")).unwrap();
        let doc: Vec<&str> = lib.lines().take_while(|l| l.starts_with("//!")).collect();
        assert!(
            doc.len() >= 3,
            "{name}: src/lib.rs opens with {} lines of crate doc",
            doc.len()
        );
    }
}
