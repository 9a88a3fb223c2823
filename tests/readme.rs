//! The README as a new user reads it: its `sh` examples run as written, and every
//! command and option its command table names exists.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::shared_data_dir;

fn readme() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap()
}

/// The ```sh blocks, with the line each starts on.
fn sh_blocks(text: &str) -> Vec<(usize, String)> {
    let mut blocks = Vec::new();
    let mut current: Option<(usize, String)> = None;
    for (n, line) in text.lines().enumerate() {
        match (&mut current, line.trim_end()) {
            (None, "```sh") => current = Some((n + 1, String::new())),
            (Some(_), "```") => blocks.extend(current.take()),
            (Some((_, block)), _) => {
                block.push_str(line);
                block.push('\n');
            }
            _ => {}
        }
    }
    blocks
}

/// Run `script` with bash in `dir`, `chromacal` on the PATH and a home of its own;
/// `(success, output)`, killed after `limit`.
fn run_script(script: &str, dir: &Path, limit: Duration) -> (bool, String) {
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_chromacal"));
    let path = format!(
        "{}:{}",
        bin.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let file = dir.join("example.sh");
    std::fs::write(&file, script).unwrap();
    let log = dir.join("example.log");
    let mut child = Command::new("bash")
        .args(["-e", "-o", "pipefail"])
        .arg(&file)
        .current_dir(dir)
        .env("PATH", path)
        .env("HOME", dir)
        .env("XDG_CONFIG_HOME", dir.join(".config"))
        .env_remove("XDG_STATE_HOME")
        .env_remove("STATE_DIRECTORY")
        .env_remove("RUNTIME_DIRECTORY")
        .env_remove("CHROMACAL_LOG")
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&log).unwrap())
        .stderr(std::fs::File::options().append(true).open(&log).unwrap())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let output = std::fs::read_to_string(&log).unwrap_or_default();
    (status.is_some_and(|s| s.success()), output)
}

/// The pages a user reads: the README, then every page of `docs/`.
fn pages() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut pages = vec![("README.md".to_string(), readme())];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    assert!(docs.len() >= 6, "docs/: {docs:?}");
    for path in docs {
        let name = format!("docs/{}", path.file_name().unwrap().to_string_lossy());
        pages.push((name, std::fs::read_to_string(&path).unwrap()));
    }
    pages
}

/// The README is read to the end: the rest is in `docs/`.
#[test]
fn the_readme_is_short_enough_to_read_to_the_end() {
    let lines = readme().lines().count();
    assert!(lines <= 300, "README.md has {lines} lines");
}

/// Every `sh` block of the README but the first (the two setup commands, which build a
/// release binary and run this very suite), and every one in `docs/`, runs as written,
/// in a fresh directory with a home of its own; `../shared/data` is where the shared
/// data really is.
#[test]
fn the_examples_run_as_written() {
    let blocks: Vec<(String, usize, String)> = pages()
        .into_iter()
        .flat_map(|(page, text)| {
            sh_blocks(&text)
                .into_iter()
                .map(move |(line, block)| (page.clone(), line, block))
        })
        .collect();
    assert!(blocks[0].0 == "README.md" && blocks[0].2.contains("scripts/test.sh"));
    assert!(blocks.len() >= 3, "{} sh blocks", blocks.len());
    let data = shared_data_dir().canonicalize().unwrap();
    for (page, line, block) in &blocks[1..] {
        let dir = tempfile::tempdir().unwrap();
        let script = block.replace("../shared/data", &data.display().to_string());
        let (ok, output) = run_script(&script, dir.path(), Duration::from_secs(180));
        assert!(ok, "{page} line {line}:\n{block}\n---\n{output}");
        // What each block says it writes is there.
        for word in block.split_whitespace() {
            let written = [".html", ".icc", ".toml"]
                .iter()
                .any(|e| word.ends_with(e) && !word.contains('/') && !word.starts_with('~'));
            if written && !word.starts_with('-') {
                let file = dir.path().join(word);
                assert!(
                    file.metadata().is_ok_and(|m| m.len() > 0),
                    "{page} line {line}: {word} was not written\n{output}"
                );
            }
        }
    }
}

/// Each command line of the "What you can do" table names a real command, and each
/// `--option` it shows is one that command takes.
#[test]
fn the_readme_command_table_names_real_commands_and_options() {
    let text = readme();
    let table: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("## What you can do"))
        .skip(1)
        .take_while(|l| !l.starts_with("## "))
        .filter(|l| l.starts_with("| `chromacal"))
        .collect();
    assert!(table.len() >= 15, "{} rows", table.len());
    let help = |words: &[&str]| {
        let out = common::chromacal()
            .args(words)
            .arg("--help")
            .output()
            .unwrap();
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let mut checked = 0;
    for row in table {
        let cell = row.split(" | ").next().unwrap().trim_start_matches("| ");
        // One cell may show several commands: `chromacal a`, `b`, `c`.
        for usage in cell.split("`, `").map(|c| c.trim_matches('`')) {
            let usage = usage.replace("\\|", "|");
            let words: Vec<&str> = usage
                .trim_start_matches("chromacal ")
                .split_whitespace()
                .collect();
            // The longest run of leading words that is a command.
            let mut command: Vec<&str> = Vec::new();
            let mut text = None;
            for word in &words {
                if !word
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
                    || word.starts_with('-')
                {
                    break;
                }
                let mut longer = command.clone();
                longer.push(word);
                match help(&longer) {
                    Some(h) if !longer.is_empty() => {
                        command = longer;
                        text = Some(h);
                    }
                    _ => break,
                }
            }
            let text = text.unwrap_or_else(|| panic!("README: `{usage}` names no command"));
            for option in usage
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .filter(|w| w.starts_with("--") && w.len() > 2)
            {
                assert!(
                    text.contains(option),
                    "README: `chromacal {}` has no {option} (from `{usage}`)",
                    command.join(" ")
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 20, "{checked} commands checked");
}

/// The command lines a page shows: every inline code span and code-block line (with
/// its `\\` continuations) that starts with `chromacal ` and a command word.
fn command_lines(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if in_block {
            let code = line.split(" # ").next().unwrap_or("").trim();
            let code = code.trim_start_matches("$ ");
            if !pending.is_empty() {
                pending.push(' ');
                pending.push_str(code.trim_end_matches('\\').trim());
            } else if code.starts_with("chromacal ") {
                pending = code.trim_end_matches('\\').trim().to_string();
            }
            if !pending.is_empty() && !code.ends_with('\\') {
                found.push(std::mem::take(&mut pending));
            }
            continue;
        }
        for (k, span) in line.split('`').enumerate() {
            if k % 2 == 1 && span.starts_with("chromacal ") {
                found.push(span.to_string());
            }
        }
    }
    found
}

/// What the built program says of itself, asked once a question.
struct Program {
    help: std::collections::HashMap<Vec<String>, Option<String>>,
    accepted: std::collections::HashMap<(Vec<String>, String), bool>,
}

impl Program {
    fn run(words: &[String]) -> std::process::Output {
        common::chromacal()
            .args(words)
            .env("HOME", "/nonexistent/chromacal-docs-test")
            .stdin(Stdio::null())
            .output()
            .unwrap()
    }

    /// `--help` of a command, if it is one.
    fn help(&mut self, command: &[String]) -> Option<String> {
        self.help
            .entry(command.to_vec())
            .or_insert_with(|| {
                let mut words = command.to_vec();
                words.push("--help".into());
                let out = Self::run(&words);
                out.status
                    .success()
                    .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
            })
            .clone()
    }

    /// Whether `command` takes `option`, shown in its help or not: given it and then
    /// an option no command has, the parser names the latter (or a missing value), not
    /// `option`, as what it did not expect. Nothing runs: the parse always fails.
    fn accepts(&mut self, command: &[String], option: &str) -> bool {
        if option == "--help" || option == "--version" {
            return true;
        }
        *self
            .accepted
            .entry((command.to_vec(), option.to_string()))
            .or_insert_with(|| {
                let mut words = command.to_vec();
                words.push(option.to_string());
                words.push("--no-such-option-for-the-docs-test".into());
                let out = Self::run(&words);
                let stderr = String::from_utf8_lossy(&out.stderr);
                !out.status.success()
                    && !stderr.contains(&format!("unexpected argument '{option}'"))
                    && !stderr.contains("unrecognized subcommand")
            })
    }
}

/// Every command a page of the README or `docs/` shows exists, with every option it
/// shows with it.
#[test]
fn every_command_and_option_the_docs_name_exists() {
    let mut program = Program {
        help: Default::default(),
        accepted: Default::default(),
    };
    let mut wrong = Vec::new();
    let mut checked = 0;
    for (page, text) in pages() {
        for usage in command_lines(&text) {
            let words: Vec<String> = usage
                .trim_start_matches("chromacal ")
                .split_whitespace()
                .map(|w| w.replace("\\|", "|"))
                .collect();
            let mut command: Vec<String> = Vec::new();
            for word in &words {
                let is_word = word
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
                    && !word.starts_with('-');
                if !is_word {
                    break;
                }
                let mut longer = command.clone();
                longer.push(word.clone());
                if program.help(&longer).is_none() {
                    break;
                }
                command = longer;
            }
            if command.is_empty() {
                if words
                    .first()
                    .is_some_and(|w| w.chars().all(|c| c.is_ascii_lowercase()))
                {
                    wrong.push(format!("{page}: `{usage}` names no command"));
                }
                continue;
            }
            for option in usage
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .filter(|w| w.starts_with("--") && w.len() > 2)
            {
                if !program.accepts(&command, option) {
                    wrong.push(format!(
                        "{page}: `chromacal {}` takes no {option} (from `{usage}`)",
                        command.join(" ")
                    ));
                }
            }
            checked += 1;
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    assert!(checked >= 60, "{checked} command lines checked");
}

/// The test above, on a command that is not there and an option that is not there.
#[test]
fn the_docs_check_tells_a_missing_option_from_a_hidden_one() {
    let mut program = Program {
        help: Default::default(),
        accepted: Default::default(),
    };
    let emulate = vec!["emulate".to_string()];
    assert!(program.accepts(&emulate, "--instrument"));
    assert!(
        program.accepts(&emulate, "--resolve-drop-after"),
        "hidden, but there"
    );
    assert!(!program.accepts(&emulate, "--resolve-drop-befor"));
    assert!(program.help(&["no-such-command".to_string()]).is_none());
    assert_eq!(
        command_lines(
            "a `chromacal fit X -o Y` b\n```\nchromacal lut3d P \\\n    --size 9 -o -\n```\n"
        ),
        vec!["chromacal fit X -o Y", "chromacal lut3d P --size 9 -o -"]
    );
}

/// What a developer uses and a user does not need: not in the user's help, manual
/// pages or shell completions (`chromacal bench --help` still answers).
const DEVELOPER_ONLY: [&str; 7] = [
    "bench",
    "--faults",
    "--record",
    "--not-remote",
    "--resolve-drop-after",
    "--ideal-filters",
    "--baud",
];

#[test]
fn the_users_help_names_no_developer_tool() {
    let out = common::chromacal().arg("--help").output().unwrap();
    let top = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        top.contains("calibrate") && top.contains("emulate"),
        "{top}"
    );
    let listed: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert!(listed.len() >= 20, "{listed:?}");
    assert!(!listed.contains(&"bench"), "{listed:?}");
    for command in &listed {
        if *command == "help" {
            continue;
        }
        let out = common::chromacal()
            .args([command, "--help"])
            .output()
            .unwrap();
        let help = String::from_utf8_lossy(&out.stdout);
        for name in &DEVELOPER_ONLY[1..] {
            assert!(
                !help.contains(name),
                "`chromacal {command} --help` names {name}"
            );
        }
    }
    let bench = common::chromacal()
        .args(["bench", "--help"])
        .output()
        .unwrap();
    assert!(bench.status.success() && String::from_utf8_lossy(&bench.stdout).contains("--quick"));
    // The manual pages and completions come from the same definitions.
    let dir = tempfile::tempdir().unwrap();
    common::succeed(common::chromacal().args(["man", "-o"]).arg(dir.path()));
    let mut pages: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    pages.sort();
    assert!(
        pages.iter().any(|p| p == "chromacal-calibrate.1"),
        "{pages:?}"
    );
    assert!(!pages.iter().any(|p| p.contains("bench")), "{pages:?}");
    let emulate = std::fs::read_to_string(dir.path().join("chromacal-emulate.1")).unwrap();
    for name in &DEVELOPER_ONLY[1..] {
        let roff = name.replace('-', "\\-");
        assert!(!emulate.contains(&roff), "chromacal-emulate.1 names {name}");
    }
    for shell in ["bash", "zsh", "fish"] {
        let out = common::succeed(common::chromacal().args(["completions", shell]));
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(script.contains("calibrate"), "{shell}");
        for name in DEVELOPER_ONLY {
            let whole = |s: &str| {
                s.match_indices(name).any(|(k, _)| {
                    let before = s[..k].chars().last();
                    let after = s[k + name.len()..].chars().next();
                    !before.is_some_and(|c| c.is_alphanumeric() || c == '-' || c == '_')
                        && !after.is_some_and(|c| c.is_alphanumeric() || c == '-' || c == '_')
                })
            };
            assert!(!whole(&script), "the {shell} completions name {name}");
        }
    }
}
