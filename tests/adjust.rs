//! `chromacal adjust` with an emulated PR-670 whose virtual monitor has controls of
//! its own (its on-screen display, set over the emulator's screen socket): started far
//! from the target, a test moves the controls as each printed advice says, and the
//! white ends on the target within the instrument's repeatability in a few rounds.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::process::Stdio;

use chromacal_color::Xyz;
use chromacal_color::difference::delta_e_2000;
use chromacal_color::spaces::xyz_to_lab;
use chromacal_model::screen::{Geometry, ScreenContent};
use common::{chromacal, emulate, succeed};

/// Send one JSON line to the emulator's screen socket; its answer must be `ok`.
fn tell(socket: &str, line: &str) {
    let mut stream = UnixStream::connect(socket).unwrap();
    stream.write_all(format!("{line}\n").as_bytes()).unwrap();
    let mut answer = String::new();
    BufReader::new(stream).read_line(&mut answer).unwrap();
    assert_eq!(answer.trim(), "ok", "{line}");
}

fn set_controls(socket: &str, gains: [f64; 3], brightness: f64) {
    tell(
        socket,
        &serde_json::json!({"osd": {"gains": gains, "brightness": brightness}}).to_string(),
    );
}

/// The D65 white at 80 cd/m².
fn target() -> Xyz {
    let (x, y) = (0.3127, 0.3290);
    Xyz::new(x / y * 80.0, 80.0, (1.0 - x - y) / y * 80.0)
}

#[test]
fn the_white_reaches_the_target_as_the_advice_is_followed() {
    let emulator = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    // The monitor as it came, and then some: green low, blue high, too bright.
    let (mut gains, mut brightness) = ([1.0, 0.93, 1.12], 1.25);
    set_controls(&emulator.screen, gains, brightness);
    // Controls a monitor cannot have are refused.
    let mut stream = UnixStream::connect(&emulator.screen).unwrap();
    stream
        .write_all(b"{\"osd\": {\"gains\": [1, -1, 1], \"brightness\": 1}}\n")
        .unwrap();
    let mut answer = String::new();
    BufReader::new(stream).read_line(&mut answer).unwrap();
    assert!(
        answer.starts_with("error") && answer.contains("positive"),
        "{answer}"
    );

    let mut child = chromacal()
        .args(["adjust", "--json", "--white", "D65", "--luminance", "80"])
        .args(["--instrument", &format!("pr670:{}", emulator.device)])
        .args(["--screen", &emulator.screen, "--timing-scale", "0.002"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut rounds = 0;
    let mut first_off = None;
    let last = loop {
        let line = lines.next().expect("adjust ended early").unwrap();
        let advice: serde_json::Value = serde_json::from_str(&line).unwrap();
        let off = advice["delta_e00"].as_f64().unwrap();
        first_off.get_or_insert(off);
        rounds += 1;
        eprintln!(
            "round {rounds}: ΔE00 {off:.3}, {} cd/m²",
            advice["luminance"]
        );
        if advice["on_target"] == true {
            stdin.write_all(b"\n").unwrap();
            break advice;
        }
        assert!(rounds < 8, "not on target after {rounds} rounds: {advice}");
        // Move the controls as it says.
        for c in 0..3 {
            gains[c] *= advice["gains"][c].as_f64().unwrap();
        }
        brightness *= advice["brightness"].as_f64().unwrap();
        set_controls(&emulator.screen, gains, brightness);
    };
    assert!(child.wait().unwrap().success());
    assert!(
        first_off.unwrap() > 3.0,
        "it started near the target already"
    );
    assert!(
        (last["luminance"].as_f64().unwrap() - 80.0).abs() < 0.8,
        "{last}"
    );
    // Read again from outside, eight times: the white lies from the target about as
    // far as the readings scatter.
    let white = ScreenContent {
        patch: [1.0; 3],
        background: [0.0; 3],
        geometry: Geometry::centred(0.2),
    };
    tell(
        &emulator.screen,
        &serde_json::json!({"content": white, "settle_s": 0.0}).to_string(),
    );
    let out = succeed(chromacal().args([
        "measure",
        "--instrument",
        &format!("pr670:{}", emulator.device),
        "--timing-scale",
        "0.002",
        "--count",
        "8",
        "--json",
    ]));
    let readings: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    let whites: Vec<Xyz> = readings
        .iter()
        .map(|r| {
            Xyz::new(
                r["xyz"][0].as_f64().unwrap(),
                r["xyz"][1].as_f64().unwrap(),
                r["xyz"][2].as_f64().unwrap(),
            )
        })
        .collect();
    let mean = whites.iter().sum::<Xyz>() / whites.len() as f64;
    let t = target();
    let de = |a: &Xyz, b: &Xyz| delta_e_2000(&xyz_to_lab(a, &t), &xyz_to_lab(b, &t));
    let spread = (whites.iter().map(|w| de(w, &mean).powi(2)).sum::<f64>() / 7.0).sqrt();
    let off = de(&mean, &t);
    eprintln!(
        "after {rounds} rounds: {off:.3} ΔE00 from D65 at 80 cd/m², one reading's scatter {spread:.3}"
    );
    assert!(off <= 3.0 * spread.max(0.05), "{off} against {spread}");
}
