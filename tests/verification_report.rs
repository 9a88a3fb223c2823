//! The report's verification sections as a calibration person reads them, loaded in
//! headless Chromium and read back from the page: the per-patch table against
//! `check --json`, the white's correlated colour temperature against an independent
//! formula, the contrast against the readings, the coverage of sRGB by a virtual
//! monitor whose primaries are sRGB's, the grey ramp, the uniformity table, the
//! calibration's measured white, and the three faults of the old page (a corrected
//! law called a table, unreadable colour-bar labels, the predicted white ΔE00 shown in
//! place of the measured one).

#[path = "common/browser.rs"]
mod browser;
mod common;

use std::path::Path;

use browser::Browser;
use chromacal::measurement_file::read_measurements;
use chromacal::profile::Profile;
use chromacal_color::Xyz;
use chromacal_color::spectrum::{Observer, Spectrum, emission_to_xyz};
use common::{chromacal, shared_path, shared_table, succeed};
use serde_json::Value;

/// McCamy (1992, *Color Res. Appl.* 17(2) 142–144) eq. 3: correlated colour
/// temperature from CIE 1931 xy by a cubic, good to a few kelvin between 5000 and
/// 7000 K near the locus. Independent of chromacal's search along Planck's locus.
fn mccamy_cct(x: f64, y: f64) -> f64 {
    let n = (x - 0.3320) / (0.1858 - y);
    449.0 * n.powi(3) + 3525.0 * n.powi(2) + 6823.3 * n + 5520.33
}

/// Mean XYZ of the centre readings on a black surround at `drive`.
fn mean_at(path: &Path, drive: [f64; 3]) -> Xyz {
    let set = read_measurements(path).unwrap();
    let readings: Vec<Xyz> = set
        .measurements
        .iter()
        .filter(|m| m.drive == drive && m.is_standard_condition())
        .filter_map(|m| m.usable_xyz())
        .collect();
    assert!(!readings.is_empty(), "no reading at {drive:?}");
    readings.iter().sum::<Xyz>() / readings.len() as f64
}

fn open(page: &Path) -> Browser {
    let mut browser = Browser::open("about:blank", 1200, 900);
    let errors = browser.navigate(&format!(
        "file://{}",
        page.canonicalize().unwrap().display()
    ));
    assert!(errors.is_empty(), "the page reported errors: {errors:#?}");
    browser
}

fn text_of(browser: &mut Browser, selector: &str) -> String {
    let value = browser.evaluate(&format!(
        "(() => {{ const e = document.querySelector('{selector}'); return e ? e.innerText : null; }})()"
    ));
    value
        .as_str()
        .unwrap_or_else(|| panic!("nothing at {selector}"))
        .to_string()
}

/// The first number in `text` ("6470 K" → 6470, "803:1" → 803).
fn number(text: &str) -> f64 {
    let start = text
        .find(|c: char| c.is_ascii_digit() || c == '-' || c == '+')
        .unwrap_or_else(|| panic!("no number in {text:?}"));
    let digits: String = text[start..]
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+'))
        .collect();
    digits
        .parse()
        .unwrap_or_else(|_| panic!("no number in {text:?}"))
}

/// Check the white against the readings: CCT within 10 K of McCamy's, luminance to
/// the page's two decimals.
fn assert_white(browser: &mut Browser, white: &Xyz) {
    let sum = white.x + white.y + white.z;
    let (x, y) = (white.x / sum, white.y / sum);
    let cct = number(&text_of(browser, "#white-cct"));
    let independent = mccamy_cct(x, y);
    assert!(
        (cct - independent).abs() < 10.0,
        "page {cct} K, McCamy {independent:.1} K"
    );
    let luminance = number(&text_of(browser, "#white-luminance"));
    assert!(
        (luminance - white.y).abs() < 0.006,
        "{luminance} against {}",
        white.y
    );
}

/// Three spectra mixed from the ISETBio Sony OLED's measured primaries (a wide gamut)
/// whose chromaticities are sRGB's (IEC 61966-2-1), as a primaries CSV.
fn srgb_primaries_csv(path: &Path) {
    let table = shared_table("displays/spd/isetbio_oled_sony_spd.csv");
    let wavelengths: Vec<f64> = table.iter().map(|r| r[0]).collect();
    let basis: Vec<Spectrum> = (1..=3)
        .map(|c| Spectrum::new(wavelengths.clone(), table.iter().map(|r| r[c]).collect()).unwrap())
        .collect();
    let columns: Vec<Xyz> = basis
        .iter()
        .map(|s| emission_to_xyz(s, Observer::Cie1931TwoDegree).unwrap())
        .collect();
    let inverse = nalgebra::Matrix3::from_columns(&columns)
        .try_inverse()
        .unwrap();
    // Each primary at its share of a D65 white's luminance (IEC 61966-2-1 eq. 5's
    // second row), so that the white is D65's.
    let weights: Vec<Xyz> = [
        ([0.64, 0.33], 0.2126),
        ([0.30, 0.60], 0.7152),
        ([0.15, 0.06], 0.0722),
    ]
    .iter()
    .map(|([x, y], luminance)| {
        let w = inverse * Xyz::new(x / y, 1.0, (1.0 - x - y) / y) * *luminance;
        assert!(
            w.iter().all(|v| *v >= 0.0),
            "sRGB's primary {x}, {y} is outside: {w:?}"
        );
        w
    })
    .collect();
    let mut csv = String::from("wavelength_nm,R,G,B\n");
    for (i, nm) in wavelengths.iter().enumerate() {
        let mixed: Vec<String> = weights
            .iter()
            .map(|w| format!("{:e}", (0..3).map(|j| w[j] * table[i][j + 1]).sum::<f64>()))
            .collect();
        csv += &format!("{nm},{}\n", mixed.join(","));
    }
    std::fs::write(path, csv).unwrap();
}

/// ArgyllCMS's coverage of sRGB, percent, by an ICC v2 profile fitted on `readings`:
/// `iccgamut -ir` (relative colorimetric, L*a*b*) of that profile and of the sRGB
/// profile Argyll ships, then `viewgam -i`'s share of sRGB's volume in both.
fn argyll_srgb_coverage(dir: &Path, readings: &Path) -> f64 {
    let profile = dir.join("plain.toml");
    succeed(chromacal().arg("fit").arg(readings).arg("-o").arg(&profile));
    let icc = dir.join("plain.icc");
    succeed(
        chromacal()
            .arg("export")
            .arg(&profile)
            .args(["--format", "icc2", "-o"])
            .arg(&icc),
    );
    let srgb = dir.join("srgb.icm");
    std::fs::copy("/usr/share/color/argyll/ref/sRGB.icm", &srgb).unwrap();
    for file in [&icc, &srgb] {
        succeed(
            std::process::Command::new("iccgamut")
                .args(["-ir", "-pl"])
                .arg(file),
        );
    }
    let out = succeed(
        std::process::Command::new("viewgam")
            .arg("-i")
            .arg(dir.join("plain.gam"))
            .arg(dir.join("srgb.gam"))
            .arg(dir.join("both.wrl")),
    );
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    // "'…/srgb.gam' volume = 833533.7 cubic units, intersect = 88.91%"
    let line = text
        .lines()
        .find(|l| l.contains("srgb.gam' volume"))
        .unwrap_or_else(|| panic!("viewgam said: {text}"));
    number(&line[line.find("intersect").unwrap()..])
}

#[test]
fn a_simulated_run_s_page_verifies_white_gamut_greys_uniformity_and_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let primaries = dir.path().join("srgb_primaries.csv");
    srgb_primaries_csv(&primaries);
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        format!(
            "[monitor]\nprimaries_csv = \"{}\"\ntransfer_csv = \"{}\"\nwhite_luminance = 100.0\nblack_luminance = 0.0\nflare_luminance = 0.0\n\
             [target]\nwhite = \"D65\"\ntone = \"srgb\"\nluminance = 80.0\n{}",
            primaries.display(),
            shared_path("displays/gamma/isetbio_lcd_dell_gamma.csv").display(),
            common::FIXED_PLAN
        ),
    )
    .unwrap();
    let page = dir.path().join("report.html");
    succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(dir.path().join("state"))
            .arg("--report")
            .arg(&page),
    );
    let journal = std::fs::read_dir(dir.path().join("state/runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl");
    let profile = Profile::read(&dir.path().join("state/current.toml")).unwrap();
    let mut browser = open(&page);

    assert_white(&mut browser, &mean_at(&journal, [1.0; 3]));

    // The monitor's primaries are sRGB's: its u′v′ triangle covers sRGB's to within
    // 0.5 %. In CIELAB its black (the measured table's, 0.3 % of white) costs it the
    // dark saturated colours: the coverage is ArgyllCMS's for the same readings
    // (`viewgam -i` on `iccgamut` solids of an ICC profile of them and of Argyll's
    // own sRGB profile) to within half a percent.
    let coverage = |b: &mut Browser, reference: &str, column: &str| {
        number(&text_of(
            b,
            &format!("#gamut tr[data-reference=\"{reference}\"] td.{column}"),
        ))
    };
    let uv = coverage(&mut browser, "sRGB", "uv-coverage");
    assert!(
        (99.5..=100.0).contains(&uv),
        "u′v′ coverage of sRGB: {uv} %"
    );
    let lab = coverage(&mut browser, "sRGB", "coverage");
    let argyll = argyll_srgb_coverage(dir.path(), &journal);
    assert!(
        (lab - argyll).abs() < 0.5,
        "coverage of sRGB {lab} %, ArgyllCMS {argyll} %"
    );
    for column in ["coverage", "uv-coverage"] {
        let wide = coverage(&mut browser, "Rec. 2020", column);
        assert!(wide < 80.0, "{column} of Rec. 2020: {wide} %");
    }
    let rows = browser.evaluate("document.querySelectorAll('#gamut tr[data-reference]').length");
    assert_eq!(
        rows.as_u64(),
        Some(4),
        "sRGB, Adobe RGB, Display P3, Rec. 2020"
    );
    let legend = text_of(&mut browser, "#fig-chromaticity");
    let drawn = browser.evaluate("document.querySelector('#fig-chromaticity svg').textContent");
    for name in ["sRGB", "Adobe RGB", "Display P3", "Rec. 2020"] {
        assert!(
            drawn.as_str().unwrap().contains(name),
            "{name} not drawn: {legend}"
        );
    }

    // The grey ramp: a row for each grey the run measured, and both figures drawn.
    let set = read_measurements(&journal).unwrap();
    let mut greys: Vec<f64> = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition() && m.usable_xyz().is_some())
        .filter(|m| {
            m.drive.iter().all(|d| *d == m.drive[0]) && m.drive[0] > 0.0 && m.drive[0] < 1.0
        })
        .map(|m| m.drive[0])
        .collect();
    greys.sort_by(f64::total_cmp);
    greys.dedup();
    assert!(greys.len() >= 3, "{greys:?}");
    let rows = browser.evaluate("document.querySelectorAll('#greys table tr').length");
    assert_eq!(rows.as_u64(), Some(greys.len() as u64 + 1));
    for figure in ["fig-tone", "fig-grey-balance"] {
        let n = browser.evaluate(&format!(
            "document.querySelectorAll('#{figure} svg *').length"
        ));
        assert!(n.as_u64().unwrap() > 20, "{figure}: {n}");
    }

    // Uniformity: each of the 24 positions of the 5 × 5 grid against the centre, and
    // the colour bar's labels big enough to read (they were drawn under 2 px high).
    let rows = browser.evaluate(
        "document.querySelectorAll('#uniformity table')[0].querySelectorAll('tr').length",
    );
    assert_eq!(rows.as_u64(), Some(25), "a header and 24 positions");
    let sizes = browser.evaluate(
        "[...document.querySelectorAll('#fig-uniformity svg text')].map(t => [t.textContent.trim(), parseFloat(getComputedStyle(t).fontSize)])",
    );
    for label in sizes.as_array().unwrap() {
        let size = label[1].as_f64().unwrap();
        assert!(
            size >= 8.0,
            "the uniformity figure's label {} is drawn at {size} px",
            label[0]
        );
    }

    // The calibration section shows the white ΔE00 measured through the curves.
    let calibration = profile.calibration.as_ref().expect("a calibration");
    let shown = text_of(&mut browser, "#calibration-white-de00");
    assert_eq!(shown, format!("{:.2}", calibration.measured_white_de00));
    assert!(calibration.measured_white_de00 > 0.0);
}

#[test]
fn a_real_ti3_s_page_carries_its_metadata_and_the_table_is_check_s() {
    let dir = tempfile::tempdir().unwrap();
    let ti3 = shared_path("measurements/dell_u2713hm_i1d3_912.ti3");
    let profile = dir.path().join("dell.toml");
    succeed(chromacal().arg("fit").arg(&ti3).arg("-o").arg(&profile));
    let page = dir.path().join("check.html");
    let out = succeed(
        chromacal()
            .arg("check")
            .arg(&profile)
            .arg(&ti3)
            .arg("--json")
            .arg("--report")
            .arg(&page)
            .args(["--criteria", "strict"]),
    );
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    // The verdict is said on the terminal too.
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("judged by strict: mean ΔE00 ≤ 0.5"), "{said}");
    assert!(said.contains(": passes"), "{said}");
    let mut browser = open(&page);

    // Every patch `check` scored, with its ΔE00 to the page's three decimals.
    let table = browser.evaluate(
        "[...document.querySelectorAll('#patch-table tr[data-patch]')].map(r => [Number(r.dataset.patch), r.querySelector('td.de').innerText])",
    );
    let table = table.as_array().unwrap();
    let patches = json["patches"].as_array().unwrap();
    assert_eq!(table.len(), patches.len());
    assert!(table.len() > 900);
    for (row, patch) in table.iter().zip(patches) {
        assert_eq!(row[0].as_u64(), patch["index"].as_u64());
        let expected = format!("{:.3}", patch["delta_e00"].as_f64().unwrap());
        assert_eq!(row[1].as_str(), Some(expected.as_str()), "patch {}", row[0]);
    }
    // Judged against the criteria named.
    let verification = text_of(&mut browser, "#verification");
    assert!(
        verification.contains("strict: mean ΔE00 ≤ 0.5, 95th percentile ≤ 1, every patch ≤ 2"),
        "{verification}"
    );
    let mean = number(&text_of(&mut browser, "#judged-mean"));
    assert!((mean - json["stats"]["mean"].as_f64().unwrap()).abs() < 5e-4);

    // White, black and contrast from the file's own readings.
    let white = mean_at(&ti3, [1.0; 3]);
    let black = mean_at(&ti3, [0.0; 3]);
    assert_white(&mut browser, &white);
    let contrast = number(&text_of(&mut browser, "#contrast"));
    assert!(
        (contrast - white.y / black.y).abs() < 0.51,
        "{contrast} against {}",
        white.y / black.y
    );

    // The .ti3's own instrument, date and display.
    let identity = text_of(&mut browser, "#identity");
    for said in [
        "Xrite i1 DisplayPro, ColorMunki Display",
        "Fri Sep 27 22:13:05 2013",
        "DELL U2713HM",
    ] {
        assert!(identity.contains(said), "{said} missing: {identity}");
    }

    // Both want standard output: refused.
    let out = chromacal()
        .arg("check")
        .arg(&profile)
        .arg(&ti3)
        .args(["--json", "--report", "-"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    assert!(String::from_utf8_lossy(&out.stderr).contains("both want standard output"));

    // Checked against relative readings, the page is in their units, and says the
    // profile was scaled to them.
    let relative = dir.path().join("relative.html");
    succeed(
        chromacal()
            .arg("check")
            .arg(&profile)
            .arg(shared_path(
                "measurements/psychtoolbox/split/ptb_sony_pvm2541_oled_test.ti3",
            ))
            .arg("--report")
            .arg(&relative),
    );
    let text = std::fs::read_to_string(&relative).unwrap();
    assert!(text.contains("relative (white Y = 100)"), "units not said");
    assert!(text.contains("scaled to white Y = 100"), "scaling not said");
    assert!(
        !text.contains("cd/m², measured"),
        "relative figures called cd/m²"
    );

    // The law is named as the selection chose it, corrected, not as the table the
    // correction made; and the chosen law is in each panel's legend.
    let fitted = Profile::read(&profile).unwrap();
    let chosen = fitted.report.chosen_law().unwrap().name().to_string();
    for channel in ["red", "green", "blue"] {
        let svg = browser.evaluate(&format!(
            "document.querySelector('#fig-transfer-{channel} svg').textContent"
        ));
        let svg = svg.as_str().unwrap();
        assert!(!svg.contains("table (chosen)"), "{channel}: {svg}");
        assert!(
            svg.contains(&format!("{chosen}, corrected")),
            "{channel} does not name {chosen}: {svg}"
        );
    }
}
