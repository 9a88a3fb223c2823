//! What the display side adds to the run loop: the stability check on a slow screen,
//! and prompts to aim the instrument when the uniformity grid moves the patch.

use std::io::Write;
use std::process::Stdio;

use chromacal::calibrate::session::{CalibrateOptions, calibrate};
use chromacal::config::{LoadedConfig, parse_config};
use chromacal::journal::Journal;

mod common;
use common::chromacal;

/// A CRT whose light takes τ = 0.5 s to follow a change, read with no settle time:
/// the first reading of each patch (1 s integration, stamped at its middle) still has
/// e^-1 of the previous patch in it.
const SLOW_SCREEN: &str = "[monitor]\npreset = \"crt\"\n[monitor.failures]\nresponse_time_s = 0.5\n[display]\nsettle_s = 0.0\n";

async fn run(text: &str) -> chromacal::calibrate::session::CalibrationOutcome {
    let state = tempfile::tempdir().unwrap();
    let loaded = LoadedConfig {
        config: parse_config(text, "test").unwrap(),
        text: text.into(),
        origin: "test".into(),
        base_dir: state.path().to_path_buf(),
    };
    let options = CalibrateOptions {
        state_dir: state.path().to_path_buf(),
        resume: None,
        resume_settings: false,
        realtime_scale: None,
        overrides: Default::default(),
        stop: None,
    };
    calibrate(&loaded, &options, &mut |_| {}, None)
        .await
        .unwrap()
}

#[tokio::test]
async fn the_stability_check_waits_out_a_slow_screen() {
    let hasty = run(SLOW_SCREEN).await;
    let checked = run(&format!(
        "{SLOW_SCREEN}[display.stability]\ntolerance = 0.01\n"
    ))
    .await;
    let err = |o: &chromacal::calibrate::session::CalibrationOutcome| {
        o.fitted.report.held_out.as_ref().unwrap().mean
    };
    eprintln!(
        "held-out mean ΔE00: {:.3} without the check, {:.3} with it ({} extra readings, {} unsettled)",
        err(&hasty),
        err(&checked),
        checked.run.extra_reads,
        checked.run.unsettled
    );
    assert_eq!(hasty.run.extra_reads, 0);
    let patches = checked.run.measured_now;
    assert!(checked.run.extra_reads > patches, "{:?}", checked.run);
    assert!(err(&checked) < 0.5, "{}", err(&checked));
    assert!(
        err(&hasty) > 3.0 * err(&checked),
        "{} vs {}",
        err(&hasty),
        err(&checked)
    );

    // On a screen that settles at once the check costs one extra reading a patch.
    let quick = run("[monitor]\npreset = \"crt\"\n[display.stability]\ntolerance = 0.01\n").await;
    let patches = quick.run.measured_now;
    assert!(
        quick.run.extra_reads >= patches && quick.run.extra_reads <= patches + patches / 10,
        "{:?}",
        quick.run
    );
}

/// Runs `chromacal calibrate --prompt-positions` with `answers` Enter presses on stdin.
fn prompted(state: &std::path::Path, answers: usize, resume: bool) -> std::process::Output {
    let mut command = chromacal();
    command
        .args(["calibrate", "--prompt-positions", "--state-dir"])
        .arg(state);
    if resume {
        command.arg("--resume");
    }
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all("\n".repeat(answers).as_bytes()).unwrap();
    drop(stdin);
    child.wait_with_output().unwrap()
}

#[test]
fn each_new_patch_position_is_prompted_and_a_closed_terminal_keeps_the_readings() {
    let state = tempfile::tempdir().unwrap();
    // Three answers, then the terminal closes: the run stops at the fourth position.
    let out = prompted(state.path(), 3, false);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(
        stderr.matches("aim the instrument at").count(),
        4,
        "{stderr}"
    );
    // The command it gives finds the run: it names the state directory it was given.
    assert!(
        stderr.contains("terminal closed")
            && stderr.contains(&format!(
                "chromacal calibrate --resume --state-dir {}",
                state.path().display()
            )),
        "{stderr}"
    );
    let run = std::fs::read_dir(state.path().join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let journal = run.join("journal.jsonl");
    let (header, before, _) = Journal::read(&journal).unwrap();
    assert!(!before.is_empty());

    // Resume with enough answers: one prompt per change of position, nothing lost.
    let out = prompted(state.path(), 1000, true);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let (_, after, _) = Journal::read(&journal).unwrap();
    assert_eq!(&after[..before.len()], &before[..]);
    // The default plan is a sequential one: its seed plan, then what it adds.
    assert!(after.len() >= header.plan.patches.len());
    let rest = &after[before.len()..];
    let moves = 1 + rest
        .windows(2)
        .filter(|w| w[0].position != w[1].position)
        .count();
    assert_eq!(
        stderr.matches("aim the instrument at").count(),
        moves,
        "{stderr}"
    );
    assert!(
        moves >= 9,
        "the default 3 × 3 grid has 9 positions, prompted {moves}"
    );
}
