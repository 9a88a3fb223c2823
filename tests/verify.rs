//! `chromacal verify` on the simulated display: a calibration to a target ends with a
//! verification through its curves; `verify` measures a chart through what is loaded,
//! sets it against sRGB and the profile, gives every ΔE an interval and every
//! criterion a verdict, reads undecided patches again, writes a `.ti3` that ArgyllCMS
//! reads, and the report opens with the calibrated display, read back in Chromium
//! equal to `verify --json`.

#[path = "common/browser.rs"]
mod browser;
mod common;

use std::path::{Path, PathBuf};

use browser::Browser;
use common::{chromacal, succeed};
use serde_json::Value;

/// The simulated CRT calibrated to D65, gamma 2.2, 80 cd/m² (its own white is near
/// 8300 K at 100): its state directory and config.
fn calibrated(dir: &Path, extra: &str) -> (PathBuf, PathBuf, String) {
    let config = dir.join("config.toml");
    std::fs::write(
        &config,
        format!("[target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\nluminance = 80.0\n{extra}"),
    )
    .unwrap();
    let state = dir.join("state");
    let out = succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state),
    );
    (
        state,
        config,
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

fn verify(state: &Path, config: &Path, args: &[&str]) -> (Option<i32>, Value) {
    let out = chromacal()
        .arg("verify")
        .arg("--state-dir")
        .arg(state)
        .arg("--config")
        .arg(config)
        .arg("--json")
        .args(args)
        .output()
        .unwrap();
    let json = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "verify {args:?}: {e}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.code(), json)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The criterion of `statistic` in a verification's results.
fn criterion<'a>(report: &'a Value, statistic: &str) -> &'a Value {
    report["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["statistic"] == statistic)
        .unwrap_or_else(|| panic!("no {statistic} in {}", report["results"]))
}

#[test]
fn a_calibration_to_a_target_verifies_through_its_curves_and_passes_displaycals_recommended_set() {
    let dir = tempfile::tempdir().unwrap();
    let (state, config, summary) = calibrated(dir.path(), "");
    // The calibration ends with a verification through its curves, kept beside it.
    assert!(
        summary.contains("chromacal: verified against sRGB with the default chart"),
        "{summary}"
    );
    let (code, report) = verify(
        &state,
        &config,
        &["--against", "srgb", "--criteria", "displaycal-recommended"],
    );
    eprintln!(
        "{}",
        serde_json::to_string_pretty(&report["results"]).unwrap()
    );
    assert_eq!(code, Some(0), "{}", report["verdict"]);
    assert_eq!(report["verdict"], "pass");
    let patches = report["patches"].as_array().unwrap();
    assert!(patches.len() >= 40, "{} patches", patches.len());
    // Every ΔE with its interval, which holds the value.
    for p in patches {
        let (v, lo, hi) = (f(&p["delta_e"]), f(&p["interval"][0]), f(&p["interval"][1]));
        assert!(lo >= 0.0 && lo <= v && v <= hi, "{p}");
    }
    let state_ = &report["state"];
    // The white: D65 and 80 cd/m² within the instrument's repeatability.
    let white_interval = &state_["white_interval"];
    assert_eq!(f(&white_interval[0]), 0.0, "white off D65: {state_}");
    let noise = &report["noise"];
    let sigma = (f(&noise["floor"]).powi(2) + (f(&noise["relative"]) * 80.0).powi(2)).sqrt();
    let luminance = f(&state_["luminance"]);
    assert!(
        (luminance - 80.0).abs() <= 3.0 * sigma,
        "white {luminance} cd/m², σ {sigma}"
    );
    // Grey balance over at least 17 greys within DisplayCAL's recommended limit.
    assert!(state_["greys"].as_array().unwrap().len() >= 17);
    assert!(f(&state_["grey_balance_mean"]) <= 0.5, "{state_}");
    assert_eq!(criterion(&report, "grey-balance-mean")["verdict"], "pass");
}

/// The report's first section, in Chromium, shows the calibrated display as `verify
/// --json` measured it, beside the native one.
#[test]
fn the_report_opens_with_the_calibrated_display_as_verify_measured_it() {
    let dir = tempfile::tempdir().unwrap();
    let (state, config, _) = calibrated(dir.path(), "");
    let own_page = dir.path().join("verified.html");
    let (_, report) = verify(&state, &config, &["--report", own_page.to_str().unwrap()]);
    let page_path = dir.path().join("page.html");
    succeed(
        chromacal()
            .arg("report")
            .arg(state.join("current.toml"))
            .arg("-o")
            .arg(&page_path),
    );
    let mut browser = Browser::open("about:blank", 1200, 900);
    let errors = browser.navigate(&format!("file://{}", page_path.display()));
    assert!(errors.is_empty(), "{errors:#?}");
    let text = |browser: &mut Browser, selector: &str| -> String {
        browser
            .evaluate(&format!(
                "(() => {{ const e = document.querySelector('{selector}'); return e ? e.innerText : null; }})()"
            ))
            .as_str()
            .unwrap_or_else(|| panic!("no {selector} on the page"))
            .to_string()
    };
    // The first section is the calibrated display.
    let first = browser.evaluate("document.querySelector('section').id");
    assert_eq!(first, "calibrated");
    let s = &report["state"];
    let number = |t: &str| -> f64 {
        t.trim_end_matches(" K")
            .trim_end_matches(":1")
            .parse()
            .unwrap_or_else(|_| panic!("'{t}' is not a number"))
    };
    for (selector, value, decimals) in [
        ("#cal-luminance", f(&s["luminance"]), 2),
        ("#cal-cct", f(&s["cct_k"]), 0),
        ("#cal-duv", f(&s["duv"]), 4),
        ("#cal-contrast", f(&s["contrast"]), 0),
        ("#cal-grey-balance", f(&s["grey_balance_mean"]), 2),
    ] {
        let shown = number(&text(&mut browser, selector));
        assert!(
            (shown - value).abs() <= 0.5 * 10f64.powi(-decimals),
            "{selector}: page {shown}, verify --json {value}"
        );
    }
    // Native beside: the CRT's own white, near 8300 K at 100 cd/m².
    let row = text(&mut browser, "#before-after");
    assert!(
        row.contains("native (the profile)") && row.contains("100.2"),
        "{row}"
    );
    assert_eq!(
        text(&mut browser, "#calibrated-verdict"),
        report["verdict"].as_str().unwrap()
    );
    // verify's own report opens the same way.
    let own = std::fs::read_to_string(&own_page).unwrap();
    assert!(
        own.contains("<section id=\"calibrated\">"),
        "{}",
        &own[..500.min(own.len())]
    );
}

#[test]
fn undecided_verdicts_are_read_again_until_decided_and_failures_exit_five() {
    let dir = tempfile::tempdir().unwrap();
    let (state, config, _) = calibrated(dir.path(), "");
    // A limit just under the measured mean, above the bottom of its interval:
    // undecided, by construction.
    let (_, first) = verify(&state, &config, &["--against", "profile"]);
    let mean_result = criterion(&first, "mean");
    let mean = 0.97 * f(&mean_result["value"]);
    assert!(f(&mean_result["interval"][0]) < mean, "{mean_result}");
    let own = dir.path().join("own.toml");
    std::fs::write(
        &own,
        format!(
            "{}\n[[verify.criterion]]\nstatistic = \"mean\"\nlimit = {mean}\n",
            std::fs::read_to_string(&config).unwrap()
        ),
    )
    .unwrap();
    let (code, undecided) = verify(&state, &own, &["--against", "profile"]);
    assert_eq!(undecided["verdict"], "undecided");
    assert_eq!(code, Some(6));
    let readings = f(&undecided["readings"]) as usize;
    let (_, decided) = verify(
        &state,
        &own,
        &["--against", "profile", "--until-decided", "200"],
    );
    let again = f(&decided["readings"]) as usize;
    assert!(again > readings, "{again} readings against {readings}");
    let read_twice = decided["patches"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| f(&p["reads"]) > 1.0)
        .count();
    assert!(read_twice > 0);
    // A limit far below what any display reaches fails, exit 5, and names it.
    std::fs::write(
        &own,
        format!(
            "{}\n[[verify.criterion]]\nstatistic = \"mean\"\nlimit = 0.01\n",
            std::fs::read_to_string(&config).unwrap()
        ),
    )
    .unwrap();
    let out = chromacal()
        .args(["verify", "--state-dir"])
        .arg(&state)
        .arg("--config")
        .arg(&own)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(5));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("mean") && said.contains("verdict: fail"),
        "{said}"
    );
}

#[test]
fn the_readings_go_to_a_ti3_argyll_reads_and_bad_charts_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (state, config, _) = calibrated(dir.path(), "");
    let ti3 = dir.path().join("verify.ti3");
    let out = chromacal()
        .args(["verify", "--chart", "short", "--state-dir"])
        .arg(&state)
        .arg("--config")
        .arg(&config)
        .arg("--ti3")
        .arg(&ti3)
        .output()
        .unwrap();
    assert!(
        out.status
            .code()
            .is_some_and(|c| c == 0 || c == 5 || c == 6)
    );
    // ArgyllCMS's own reader takes it: profcheck judges all 26 patches against the
    // exported profile.
    let text = std::fs::read_to_string(&ti3).unwrap();
    assert!(text.starts_with("CTI3"), "{text}");
    let icc = dir.path().join("p.icc");
    succeed(
        chromacal()
            .arg("export")
            .arg(state.join("current.toml"))
            .args(["--format", "icc2", "-o"])
            .arg(&icc),
    );
    common::need_tool("profcheck", "argyll");
    let judged = chromacal::argyll::profcheck_delta_e00(&ti3, &icc).unwrap();
    assert_eq!(judged.len(), 26, "{text}");
    // A chart of the user's own, and charts that are wrong.
    let csv = dir.path().join("mine.csv");
    std::fs::write(&csv, "R,G,B\n1,1,1\n0,0,0\n0.5,0.5,0.5\n").unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "R,G,B\n1,1,7\n").unwrap();
    for (chart, expected) in [
        (bad.display().to_string(), "line 2: 7 is outside 0–1"),
        (
            "/nonexistent/chart.ti1".to_string(),
            "/nonexistent/chart.ti1",
        ),
    ] {
        let out = chromacal()
            .args(["verify", "--chart", &chart, "--state-dir"])
            .arg(&state)
            .arg("--config")
            .arg(&config)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1));
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(said.contains(expected), "{said}");
    }
}

/// `verify --uniformity` reads white, grey and dark grey over a grid and judges each
/// position against the centre by ISO 12646's tolerances: an even screen passes; one
/// whose corners fall 13 % (red more than blue) fails there, named by position, in the
/// summary, the JSON and the report, while the centre's chart still passes.
#[test]
fn uniformity_passes_an_even_screen_and_names_the_positions_of_an_uneven_one() {
    let dir = tempfile::tempdir().unwrap();
    let (state, even, _) = calibrated(dir.path(), "[monitor]\nfalloff = 0.02\n");
    let (code, report) = verify(&state, &even, &["--uniformity"]);
    let u = &report["uniformity"];
    assert_eq!(code, Some(0), "{u}");
    assert_eq!(u["grid"], 5);
    assert_eq!(u["verdict"], "pass");
    assert_eq!(u["points"].as_array().unwrap().len(), 24 * 3);
    assert!(f(&u["worst_luminance"][0]) < 0.05, "{u}");
    // The same profile on a screen whose corners fall off, red most.
    let uneven = dir.path().join("uneven.toml");
    let text = std::fs::read_to_string(&even)
        .unwrap()
        .replace("falloff = 0.02", "falloff = [0.35, 0.2, 0.05]");
    std::fs::write(&uneven, text).unwrap();
    let page = dir.path().join("uniformity.html");
    let (code, report) = verify(
        &state,
        &uneven,
        &["--uniformity", "3", "--report", page.to_str().unwrap()],
    );
    let u = &report["uniformity"];
    assert_eq!(code, Some(5), "{u}");
    assert_eq!(report["verdict"], "fail");
    assert_eq!(u["verdict"], "fail");
    // The chart at the centre is untouched by the falloff.
    assert!(
        report["results"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["verdict"] != "fail"),
        "{}",
        report["results"]
    );
    let points = u["points"].as_array().unwrap();
    let white_at = |column: u64, row: u64| {
        points
            .iter()
            .find(|p| p["column"] == column && p["row"] == row && f(&p["level"]) == 1.0)
            .unwrap()
    };
    for (column, row) in [(0, 0), (2, 0), (0, 2), (2, 2)] {
        let corner = white_at(column, row);
        assert_eq!(corner["verdict"], "fail", "{corner}");
        assert!(f(&corner["luminance_deviation"]) < -0.10, "{corner}");
        assert!(f(&corner["luminance_interval"][1]) < -0.10, "{corner}");
    }
    // The edge's middles fall less than the corners.
    let edge = white_at(1, 0);
    assert!(
        f(&edge["luminance_deviation"]) > f(&white_at(0, 0)["luminance_deviation"]),
        "{edge}"
    );
    // The page shows the grid, one table a level, with the failing cells.
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("id=\"uniformity-verdict\""), "no verdict");
    for k in 0..3 {
        let table = html
            .split(&format!("id=\"uniformity-grid-{k}\""))
            .nth(1)
            .and_then(|rest| rest.split("</table>").next())
            .unwrap_or_else(|| panic!("no uniformity-grid-{k}"));
        assert_eq!(table.matches("<td").count(), 9, "{table}");
        assert!(table.contains(">centre<"), "{table}");
    }
    // A summary names the positions; an even grid is refused before anything is read.
    let out = chromacal()
        .args(["verify", "--uniformity", "3", "--state-dir"])
        .arg(&state)
        .arg("--config")
        .arg(&uneven)
        .output()
        .unwrap();
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(
        summary.contains("uniformity at column 1 row 1, 100 % grey"),
        "{summary}"
    );
    let out = chromacal()
        .args(["verify", "--uniformity", "4", "--state-dir"])
        .arg(&state)
        .arg("--config")
        .arg(&uneven)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("odd size from 3 to 15"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// On a real screen the grid's patches move away from the instrument: without
/// --prompt-positions the uniformity is refused before anything is shown.
#[test]
fn uniformity_on_a_real_screen_asks_for_prompt_positions() {
    let dir = tempfile::tempdir().unwrap();
    let (state, config, _) = calibrated(dir.path(), "");
    let out = chromacal()
        .args(["verify", "--uniformity", "--display", "window"])
        .args([
            "--instrument",
            "pr670:/dev/chromacal-no-such-port",
            "--state-dir",
        ])
        .arg(&state)
        .arg("--config")
        .arg(&config)
        .env_remove("DISPLAY")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("add --prompt-positions"), "{stderr}");
}
