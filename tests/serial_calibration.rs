//! `chromacal calibrate --instrument KIND:/dev/pts/N` against `chromacal emulate`, for
//! every instrument: real serial bytes through a real pseudo-terminal, patches through
//! the emulator's screen socket. The profile must be the one the in-process simulated
//! instrument gives, within noise (colorimeters with ideal filters).

use chromacal::profile::Profile;
use chromacal_instruments::devices::DeviceKind;

mod common;
use common::{CRT_PRIMARIES, chromacal, emulate, in_process_profile};

const TIME_SCALE: &str = "0.002";

#[test]
fn every_instrument_calibrates_through_its_emulator_like_the_simulated_one() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, CRT_PRIMARIES).unwrap();
    let reference = in_process_profile(&config, &dir.path().join("reference"));

    for kind in DeviceKind::ALL {
        // The protocol is what is tested here: an emulated colorimeter reads exact CIE
        // XYZ (its filters' error, and its correction, are tests/ccmx.rs's and
        // tests/colorimeter_filters.rs's).
        let mut args = vec!["--instrument", kind.name(), "--time-scale", TIME_SCALE];
        if kind.filter_model().is_some() {
            args.push("--ideal-filters");
        }
        let emulator = emulate(&args);
        let state = dir.path().join(kind.name());
        let out = chromacal()
            .args(["calibrate", "--config"])
            .arg(&config)
            .arg("--instrument")
            .arg(format!("{}:{}", kind.name(), emulator.device))
            .args([
                "--screen",
                &emulator.screen,
                "--timing-scale",
                TIME_SCALE,
                "--state-dir",
            ])
            .arg(&state)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let profile = Profile::read(&state.join("current.toml")).unwrap();
        let name = profile.provenance.instrument.as_ref().unwrap().name.clone();
        assert!(!name.contains("simulated"), "{kind}: measured with {name}");
        common::assert_same_model(kind.name(), &profile, &reference);
        let held = profile.report.held_out.unwrap();
        assert!(held.mean < 0.5, "{kind}: {held:?}");
        assert_eq!(
            profile.report.luminance_only.is_some(),
            matches!(kind, DeviceKind::Ls100 | DeviceKind::Ls110),
            "{kind}"
        );
        eprintln!(
            "{kind}: held-out {held:?}, law {:?}",
            profile.report.chosen_law()
        );
    }
}
