//! A colorimeter without a correction is said to be one, in the summary, the profile
//! and both reports; with a `.ccmx` (named by its path, or by its name where ArgyllCMS
//! installs corrections) the profile records the file's SHA-256, its display type and
//! its reference; `chromacal correction list` shows what is installed.

mod common;

use std::path::Path;

use common::{chromacal, succeed};
use sha2::Digest;

/// A simulated K-10A-like colorimeter on the simulated CRT, calibrated to D65 (so the
/// calibration ends with a verification).
const COLORIMETER: &str = "[instrument.simulated]\nkind = \"tristimulus\"\nfilters = \"k10a\"\n[target]\nwhite = \"D65\"\n";

/// A correction for it, as `correction make` writes one (the matrix need not be good
/// to be recorded; it must pass the matrix checks).
const CCMX: &str = "CCMX\n\nDESCRIPTOR \"k10a on a CRT\"\nORIGINATOR \"chromacal test\"\nCREATED \"Sat Dec  5 12:00:00 2026\"\nKEYWORD \"INSTRUMENT\"\nINSTRUMENT \"Klein K-10A\"\nKEYWORD \"DISPLAY\"\nDISPLAY \"Simulated CRT\"\nKEYWORD \"REFERENCE\"\nREFERENCE \"Photo Research PR-670\"\nKEYWORD \"DISPLAY_TYPE_BASE_ID\"\nDISPLAY_TYPE_BASE_ID \"1\"\nKEYWORD \"DISPLAY_TYPE_REFRESH\"\nDISPLAY_TYPE_REFRESH \"NO\"\nKEYWORD \"COLOR_REP\"\nCOLOR_REP \"XYZ\"\n\nNUMBER_OF_FIELDS 3\nBEGIN_DATA_FORMAT\nXYZ_X XYZ_Y XYZ_Z\nEND_DATA_FORMAT\n\nNUMBER_OF_SETS 3\nBEGIN_DATA\n1.01 0.0 0.0\n0.0 1.0 0.0\n0.0 0.0 0.98\nEND_DATA\n";

fn calibrate(dir: &Path, config_text: &str, home: &Path) -> (String, String, String) {
    let config = dir.join("config.toml");
    std::fs::write(&config, config_text).unwrap();
    let state = dir.join("state");
    let page = dir.join("report.html");
    let out = succeed(
        chromacal()
            .env("XDG_DATA_HOME", home)
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state)
            .arg("--report")
            .arg(&page),
    );
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        std::fs::read_to_string(state.join("current.toml")).unwrap(),
        std::fs::read_to_string(&page).unwrap(),
    )
}

#[test]
fn a_colorimeter_without_a_correction_is_said_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let (summary, profile, page) = calibrate(dir.path(), COLORIMETER, dir.path());
    let said = "is a colorimeter used without a correction";
    assert!(
        summary.contains("WARNING: the simulated") && summary.contains(said),
        "{summary}"
    );
    assert!(
        profile.contains("uncorrected =") && profile.contains(said),
        "{profile}"
    );
    // The calibration report: in its run section and in its verification's.
    assert!(page.contains("id=\"uncorrected\"") && page.contains(said));
    assert!(page.contains("id=\"verify-uncorrected\""));
    // A spectroradiometer needs none, and is not warned about.
    let dir = tempfile::tempdir().unwrap();
    let (summary, profile, _) = calibrate(dir.path(), "[target]\nwhite = \"D65\"\n", dir.path());
    assert!(!summary.contains(said) && !profile.contains("uncorrected"));
}

#[test]
fn a_correction_is_recorded_by_its_digest_and_found_by_its_name() {
    let dir = tempfile::tempdir().unwrap();
    // Installed where ArgyllCMS's oeminst puts a user's corrections.
    let home = dir.path().join("data");
    std::fs::create_dir_all(home.join("ArgyllCMS")).unwrap();
    let file = home.join("ArgyllCMS/k10a_crt.ccmx");
    std::fs::write(&file, CCMX).unwrap();
    let digest = format!("{:x}", sha2::Sha256::digest(CCMX.as_bytes()));
    let listed =
        succeed(
            chromacal()
                .env("XDG_DATA_HOME", &home)
                .args(["correction", "list", "--json"]),
        );
    let listed: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    let entry = listed
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "k10a_crt.ccmx")
        .unwrap_or_else(|| panic!("not listed: {listed}"));
    assert_eq!(entry["sha256"], digest.as_str());
    assert_eq!(entry["display"], "Simulated CRT");
    // Named by its name alone in the config.
    let (summary, profile, page) = calibrate(
        dir.path(),
        &format!("{COLORIMETER}[instrument]\ncorrection = \"k10a_crt\"\n"),
        &home,
    );
    assert!(!summary.contains("without a correction"), "{summary}");
    assert!(summary.contains(&format!("SHA-256 {digest}")), "{summary}");
    let parsed: toml::Value = toml::from_str(&profile).unwrap();
    let recorded = &parsed["provenance"]["correction"];
    assert_eq!(recorded["sha256"].as_str(), Some(digest.as_str()));
    assert_eq!(recorded["display"].as_str(), Some("Simulated CRT"));
    assert_eq!(
        recorded["reference"].as_str(),
        Some("Photo Research PR-670")
    );
    assert!(page.contains(&digest));
    // A name that is nowhere is an error naming it.
    let config = dir.path().join("bad.toml");
    std::fs::write(
        &config,
        format!("{COLORIMETER}[instrument]\ncorrection = \"no_such_correction\"\n"),
    )
    .unwrap();
    let out = chromacal()
        .env("XDG_DATA_HOME", &home)
        .arg("calibrate")
        .arg("--config")
        .arg(&config)
        .arg("--state-dir")
        .arg(dir.path().join("bad"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("no_such_correction"), "{said}");
}
