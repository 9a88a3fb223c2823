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

/// Every `sh` block but the first (the two setup commands, which build a release
/// binary and run this very suite) runs as written, in a fresh directory with a home of
/// its own; `../shared/data` is where the shared data really is.
#[test]
fn the_readme_examples_run_as_written() {
    let text = readme();
    let blocks = sh_blocks(&text);
    assert!(blocks.len() >= 3, "{} sh blocks", blocks.len());
    assert!(blocks[0].1.contains("scripts/test.sh"));
    let data = shared_data_dir().canonicalize().unwrap();
    for (line, block) in &blocks[1..] {
        let dir = tempfile::tempdir().unwrap();
        let script = block.replace("../shared/data", &data.display().to_string());
        let (ok, output) = run_script(&script, dir.path(), Duration::from_secs(180));
        assert!(ok, "README line {line}:\n{block}\n---\n{output}");
        // What each block says it writes is there.
        for word in block.split_whitespace() {
            let written = [".html", ".icc", ".toml"]
                .iter()
                .any(|e| word.ends_with(e) && !word.contains('/') && !word.starts_with('~'));
            if written && !word.starts_with('-') {
                let file = dir.path().join(word);
                assert!(
                    file.metadata().is_ok_and(|m| m.len() > 0),
                    "README line {line}: {word} was not written\n{output}"
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
