//! Calibrating an HDR display to PQ: a virtual OLED in its PQ mode whose emitters are
//! ISETBio's measured Sony OLED spectra and whose panel follows the Sony's measured
//! transfer table (so the PQ law the fit keeps is not the law that made the light),
//! with a brightness limiter, 10-bit codes, and the instrument's noise. Once in
//! process, once across a real TCP socket (the Resolve protocol, `bits="10"`) and a
//! real tty (an emulated PR-670).

use chromacal::journal::Journal;
use chromacal::profile::Profile;
use chromacal::report::held_out_itp;
use chromacal_model::plan::Signal;
use chromacal_model::transfer::LawKind;

mod common;
use common::{assert_same_model, chromacal, emulate, in_process_profile, shared_path};

fn hdr_oled_config(dir: &std::path::Path) -> std::path::PathBuf {
    let config = dir.join("config.toml");
    std::fs::write(
        &config,
        format!(
            "[monitor]\npreset = \"hdr-oled\"\nprimaries_csv = \"{}\"\ntransfer_csv = \"{}\"\n\
             [plan]\nbit_depth = 10\n\
             [target]\nwhite = \"D65\"\ntone = \"pq\"\npeak = 600.0\nlevels = 17\n\
             [display.resolve]\nconnect_timeout_s = 60.0\n",
            shared_path("displays/spd/isetbio_oled_sony_spd.csv").display(),
            shared_path("displays/gamma/isetbio_oled_sony_gamma.csv").display(),
        ),
    )
    .unwrap();
    config
}

/// The simulated instrument's noise floor (the built-in `[instrument.simulated]`),
/// cd/m²: a reading of 0.1 cd/m² scatters by about 0.0005 + 0.3 %.
const NOISE_FLOOR: f64 = 0.0005;

/// What the done-when of HDR calibration asks: a published profile whose held-out
/// error is at most 1 ΔE ITP on average, measured grey tracking the PQ within 3 %
/// (plus three times the instrument's noise floor) from 0.1 cd/m² to 90 % of the
/// peak, the signal said in the profile, and the PQ law kept by cross-validation
/// over every SDR law.
fn assert_calibrated_to_pq(label: &str, profile: &Profile) {
    assert_eq!(profile.provenance.signal, Some(Signal::Pq), "{label}");
    assert_eq!(profile.report.chosen_law(), Some(LawKind::Pq), "{label}");
    let itp = held_out_itp(&profile.report.held_out_patches).unwrap();
    assert!(
        itp.n >= 12 && itp.mean <= 1.0,
        "{label}: held-out {itp:?} ΔE ITP"
    );
    let calibration = profile.calibration.as_ref().unwrap();
    let mut tracked = 0;
    for level in &calibration.levels {
        let target = level.target_luminance;
        if (0.1..=0.9 * 600.0).contains(&target) {
            let off = level.measured_luminance - target;
            assert!(
                off.abs() < 0.03 * target + 3.0 * NOISE_FLOOR,
                "{label}: {level:?} is {:+.3} off the PQ",
                off / target
            );
            tracked += 1;
        }
    }
    assert!(
        tracked >= 8,
        "{label}: only {tracked} levels between 0.1 cd/m² and the peak"
    );
    let white = calibration.levels.last().unwrap().measured_luminance;
    assert!((white / 600.0 - 1.0).abs() < 0.03, "{label}: white {white}");
    // The white the model is anchored to is the patch's, not the limited windows'
    // (a full-field white is a quarter of it).
    let anchor = profile.report.white_anchor.as_ref().unwrap();
    assert!(
        (anchor.measured.y / anchor.predicted.y - 1.0).abs() < 0.02,
        "{label}: {anchor:?}"
    );
}

#[test]
fn an_hdr_oled_calibrated_to_pq_tracks_it_and_predicts_held_out_colours_within_one_itp() {
    let dir = tempfile::tempdir().unwrap();
    let config = hdr_oled_config(dir.path());
    let state = dir.path().join("state");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("held-out ΔE ITP"), "{stdout}");
    assert!(stdout.contains("PQ (SMPTE ST 2084)"), "{stdout}");
    // The limiter shows: the patch on a white surround is far dimmer.
    assert!(stdout.contains("spatial independence   FAILS"), "{stdout}");
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    assert_calibrated_to_pq("in process", &profile);
}

#[test]
fn an_hdr_calibration_over_resolve_in_10_bits_matches_the_in_process_one() {
    let dir = tempfile::tempdir().unwrap();
    let config = hdr_oled_config(dir.path());
    let reference = in_process_profile(&config, &dir.path().join("reference"));
    let address = {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        listener.local_addr().unwrap().to_string()
    };
    let config_arg = config.to_string_lossy().into_owned();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--config",
        &config_arg,
        "--time-scale",
        "0.002",
        "--resolve",
        &address,
    ]);
    let state = dir.path().join("resolve");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--instrument")
        .arg(format!("pr670:{}", emulator.device))
        .args([
            "--display",
            "resolve",
            "--listen",
            &address,
            "--timing-scale",
            "0.002",
            "--state-dir",
        ])
        .arg(&state)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    assert_calibrated_to_pq("over Resolve", &profile);
    assert_same_model("hdr over resolve", &profile, &reference);
    // The journal says what was sent: 10-bit codes of a PQ signal.
    let run = std::fs::read_dir(state.join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let (header, entries, _) = Journal::read(&run.join("journal.jsonl")).unwrap();
    assert_eq!(header.plan.signal, Some(Signal::Pq));
    assert!(
        entries
            .iter()
            .all(|m| m.codes.is_some_and(|c| c.bit_depth == 10))
    );
}

/// Calibrate `config_text` in process and return the profile (published or not).
fn calibrate_profile(dir: &std::path::Path, name: &str, config_text: &str) -> Profile {
    let config = dir.join(format!("{name}.toml"));
    std::fs::write(&config, config_text).unwrap();
    let state = dir.join(name);
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Profile::read(&state.join("current.toml")).unwrap()
}

/// The limiter term on the HDR displays that have one (the OLED's supply, the LCD's
/// backlight budget): kept, and the full-field white predicted by the term fitted
/// without it within 2 %, where the additive model is over 30 % too bright; on the SDR
/// presets, which have none, the term is not kept, whatever the seed.
#[test]
fn the_brightness_limiter_is_kept_where_a_display_has_one_and_only_there() {
    let dir = tempfile::tempdir().unwrap();
    let sony = format!(
        "primaries_csv = \"{}\"\ntransfer_csv = \"{}\"\n",
        shared_path("displays/spd/isetbio_oled_sony_spd.csv").display(),
        shared_path("displays/gamma/isetbio_oled_sony_gamma.csv").display(),
    );
    for (name, monitor, seed) in [
        ("oled-1", format!("preset = \"hdr-oled\"\n{sony}"), 1),
        ("oled-2", format!("preset = \"hdr-oled\"\n{sony}"), 2),
        ("lcd-1", "preset = \"hdr-lcd\"\n".to_string(), 1),
    ] {
        let profile = calibrate_profile(
            dir.path(),
            name,
            &format!(
                "[monitor]\n{monitor}[plan]\nbit_depth = 10\nseed = {seed}\n\
                 [instrument.simulated]\nseed = {seed}\n[target]\ntone = \"pq\"\nwhite = \"D65\"\n"
            ),
        );
        let limiter = profile.report.limiter.as_ref().unwrap();
        assert!(limiter.kept, "{name}: {}", limiter.rule);
        let full = limiter.full_field_white().unwrap();
        assert!(
            full.additive_y / full.measured_y > 1.3,
            "{name}: the additive model is not far off: {full:?}"
        );
        assert!(
            (full.left_out_y / full.measured_y - 1.0).abs() < 0.02,
            "{name}: {full:?}"
        );
    }
    for preset in ["crt", "lcd"] {
        for seed in 1..=3 {
            let name = format!("{preset}-{seed}");
            let profile = calibrate_profile(
                dir.path(),
                &name,
                &format!(
                    "[monitor]\npreset = \"{preset}\"\n[plan]\nbrightness_limiter = true\nseed = {seed}\n\
                     [instrument.simulated]\nseed = {seed}\n"
                ),
            );
            let limiter = profile.report.limiter.as_ref().unwrap();
            assert_eq!(limiter.windows.len(), 18, "{name}");
            assert!(!limiter.kept, "{name}: {}", limiter.rule);
        }
    }
}
