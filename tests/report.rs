//! The HTML report as a user meets it: written by `calibrate --report`, by `fit
//! --report` on a real .ti3 and by `chromacal report`, served by the daemon's
//! `GET /report`, and loaded in headless Chromium: no console error, every figure's
//! SVG present and drawn, the measured points the readings hold, a screenshot that is
//! not blank.

#[path = "common/browser.rs"]
mod browser;
mod common;

use std::path::Path;
use std::time::Duration;

use browser::Browser;
use chromacal::measurement_file::read_measurements;
use common::daemon::{events_of_job, get, start_daemon, start_job, subscribe};
use common::{chromacal, shared_path, succeed};

const TARGET: &str = "[target]\nwhite = \"D65\"\ntone = \"srgb\"\nluminance = 80.0\n";

/// For each figure id: (children of its SVG, its drawn width, circles in it), or null
/// when the figure is not on the page.
fn figure_shape(browser: &mut Browser, id: &str) -> Option<(u64, f64, u64)> {
    let value = browser.evaluate(&format!(
        "(() => {{ const s = document.querySelector('#{id} svg'); if (!s) return null; \
         return [s.querySelectorAll('*').length, s.getBoundingClientRect().width, \
         s.querySelectorAll('circle').length]; }})()"
    ));
    let a = value.as_array()?;
    Some((a[0].as_u64()?, a[1].as_f64()?, a[2].as_u64()?))
}

/// Load the page at `path` and check what every report must hold: no error reported,
/// nothing fetched from outside, each of `figures` drawn, a screenshot with content.
/// Returns the browser for further questions.
fn open_report(path: &Path, figures: &[&str]) -> Browser {
    let page = std::fs::read_to_string(path).unwrap();
    for outside in ["src=\"http", "href=\"http", "<script", "url(http"] {
        assert!(
            !page.contains(outside),
            "the page reaches outside: {outside}"
        );
    }
    let mut browser = Browser::open("about:blank", 1200, 900);
    let url = format!("file://{}", path.canonicalize().unwrap().display());
    let errors = browser.navigate(&url);
    assert!(errors.is_empty(), "the page reported errors: {errors:#?}");
    for id in figures {
        let (elements, width, _) =
            figure_shape(&mut browser, id).unwrap_or_else(|| panic!("no SVG in #{id}"));
        assert!(elements > 20, "#{id} holds only {elements} elements");
        assert!(width > 200.0, "#{id} is drawn {width} px wide");
    }
    // The first screen: the identity table and the first transfer curves.
    let image = browser.screenshot();
    let mut colours = std::collections::HashSet::new();
    let mut inked = 0usize;
    for y in 0..image.height {
        for x in 0..image.width {
            let p = image.pixel(x, y);
            colours.insert(p);
            inked += usize::from(p != [255, 255, 255]);
        }
    }
    let share = inked as f64 / (image.width * image.height) as f64;
    assert!(share > 0.03, "the screenshot is {share:.4} inked");
    assert!(colours.len() > 50, "{} colours on screen", colours.len());
    browser
}

/// Centre single-channel readings of red in a measurement file.
fn red_ramp_readings(path: &Path) -> u64 {
    read_measurements(path)
        .unwrap()
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition() && m.usable_xyz().is_some())
        .filter(|m| m.drive[0] > 0.0 && m.drive[1] == 0.0 && m.drive[2] == 0.0)
        .count() as u64
}

#[test]
fn a_simulated_calibration_writes_a_report_with_every_figure() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    // The fixed plan of 96 patches: many red readings and a 5 × 5 grid to draw.
    std::fs::write(&config, format!("{TARGET}{}", common::FIXED_PLAN)).unwrap();
    let page = dir.path().join("report.html");
    let out = succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(dir.path().join("state"))
            .arg("--report")
            .arg(&page),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("report written to"), "{stderr}");

    let mut browser = open_report(
        &page,
        &[
            "fig-transfer-red",
            "fig-transfer-green",
            "fig-transfer-blue",
            "fig-greys",
            "fig-residuals",
            "fig-chromaticity",
            "fig-uniformity",
            "fig-held-out",
            "fig-calibration",
        ],
    );
    // The red curve shows each red reading of the run's journal (plus the legend's
    // circle); the uniformity map each grid position.
    let journal = std::fs::read_dir(dir.path().join("state/runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl");
    let red = red_ramp_readings(&journal);
    assert!(red >= 6, "{red} red readings");
    let (_, _, circles) = figure_shape(&mut browser, "fig-transfer-red").unwrap();
    assert_eq!(circles, red + 1);
    let (_, _, circles) = figure_shape(&mut browser, "fig-uniformity").unwrap();
    assert_eq!(
        circles,
        2 * 24,
        "two circles (fill and ring) per grid position"
    );
    // The run's cost is stated.
    let text = browser.evaluate("document.querySelector('#identity').innerText");
    let text = text.as_str().unwrap();
    assert!(
        text.contains("instrument time") && text.contains("fit time"),
        "{text}"
    );
    assert!(!text.contains("not recorded"), "{text}");
    // The worst patches carry a measured and a predicted swatch each.
    let swatches = browser.evaluate("document.querySelectorAll('#held-out .swatch').length");
    assert_eq!(swatches.as_u64(), Some(20));
}

#[test]
fn a_real_ti3_fit_reports_alike_from_fit_and_from_report_and_says_what_it_lacks() {
    let dir = tempfile::tempdir().unwrap();
    let ti3 = dir.path().join("samsung.ti3");
    std::fs::copy(
        shared_path("measurements/samsung_s24a350h_colormunki_spectral_57.ti3"),
        &ti3,
    )
    .unwrap();
    let profile = dir.path().join("samsung.toml");
    let from_fit = dir.path().join("fit.html");
    succeed(
        chromacal()
            .arg("fit")
            .arg(&ti3)
            .arg("-o")
            .arg(&profile)
            .arg("--report")
            .arg(&from_fit),
    );

    // `report` finds the readings the profile names and writes the same page, to a
    // file or to standard output.
    let from_report = dir.path().join("report.html");
    let out = succeed(
        chromacal()
            .arg("report")
            .arg(&profile)
            .arg("-o")
            .arg(&from_report),
    );
    assert!(
        out.stdout.is_empty(),
        "a page written to a file prints nothing"
    );
    let page = std::fs::read(&from_fit).unwrap();
    assert_eq!(page, std::fs::read(&from_report).unwrap());
    let out = chromacal()
        .arg("report")
        .arg(&profile)
        .args(["-o", "-"])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_eq!(out.stdout, page, "-o - writes the page to standard output");
    assert!(!dir.path().join("-").exists());

    let mut browser = open_report(
        &from_fit,
        &[
            "fig-transfer-red",
            "fig-transfer-green",
            "fig-transfer-blue",
            "fig-greys",
            "fig-residuals",
            "fig-chromaticity",
            "fig-held-out",
        ],
    );
    let red = red_ramp_readings(&ti3);
    let (_, _, circles) = figure_shape(&mut browser, "fig-transfer-red").unwrap();
    assert_eq!(circles, red + 1);
    // A .ti3 has no uniformity grid and no instrument time: said, not drawn.
    assert_eq!(figure_shape(&mut browser, "fig-uniformity"), None);
    let text = browser.evaluate("document.body.innerText");
    let text = text.as_str().unwrap();
    assert!(text.contains("No uniformity grid was measured"), "{text}");
    assert!(text.contains("not recorded in the file"), "{text}");
    drop(browser);

    // With the readings gone, the report is still written and says why its curves
    // have no points; `--readings` gives them back.
    std::fs::remove_file(&ti3).unwrap();
    let bare = dir.path().join("bare.html");
    let out = chromacal()
        .arg("report")
        .arg(&profile)
        .arg("-o")
        .arg(&bare)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("are not here"), "{stderr}");
    let bare_page = std::fs::read_to_string(&bare).unwrap();
    assert!(bare_page.contains("measured points are not drawn"));
    assert!(!bare_page.contains("id=\"fig-greys\""));
    let out = chromacal()
        .arg("report")
        .arg(&profile)
        .arg("-o")
        .arg(&bare)
        .arg("--readings")
        .arg(shared_path(
            "measurements/samsung_s24a350h_colormunki_spectral_57.ti3",
        ))
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(
        std::fs::read_to_string(&bare)
            .unwrap()
            .contains("id=\"fig-greys\"")
    );

    // Not a profile: named.
    let out = chromacal()
        .arg("report")
        .arg(shared_path(
            "measurements/samsung_s24a350h_colormunki_spectral_57.ti3",
        ))
        .arg("-o")
        .arg(dir.path().join("x.html"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(!dir.path().join("x.html").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_serves_the_report_with_its_history() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(
        dir.path(),
        "[daemon]\nsimulated_time_scale = 0.001\n[plan]\nstrategy = \"fixed\"\nbudget = 48\nuniformity_grid = 3\n",
    );
    let api = daemon.endpoint();
    let none = get(&api, "/report").await;
    assert_eq!(none.status, 404, "{}", none.text());
    let mut events = subscribe(&api);
    for kind in ["calibrate", "verify", "calibrate", "verify"] {
        let id = start_job(&api, kind).await;
        let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(120)).await;
        assert_eq!(outcome.result, "ok", "{kind}: {outcome:?}");
        assert!(!outcome.escalated, "{kind}: {outcome:?}");
    }
    let reply = get(&api, "/report").await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let page = dir.path().join("daemon.html");
    std::fs::write(&page, reply.text()).unwrap();
    let history = get(&api, "/history").await.json().unwrap();
    let profiles = history["profiles"].as_array().unwrap().len() as u64;
    assert_eq!(profiles, 2);
    let mut browser = tokio::task::spawn_blocking(move || {
        let browser = open_report(
            &page,
            &[
                "fig-transfer-red",
                "fig-chromaticity",
                "fig-uniformity",
                "fig-held-out",
                "fig-history-error",
                "fig-history-white",
            ],
        );
        (browser, page)
    })
    .await
    .unwrap()
    .0;
    // Two profiles in the white-luminance figure (plus the legend has no circle), and
    // two profiles and two verifications in the error figure.
    let (_, _, white) = figure_shape(&mut browser, "fig-history-white").unwrap();
    assert_eq!(white, profiles);
    let (_, _, errors) = figure_shape(&mut browser, "fig-history-error").unwrap();
    assert_eq!(errors, profiles + 2);
    // The verification sections judge the newest verification of the current
    // profile: its patches, with the ΔE00 the daemon recorded for them.
    let said = browser.evaluate("document.querySelector('#verification').innerText");
    assert!(
        said.as_str().unwrap().contains("measured to verify it"),
        "{said}"
    );
    let recorded = history["verifications"].as_array().unwrap().last().unwrap()["delta_e"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| format!("{:.3}", v.as_f64().unwrap()))
        .collect::<Vec<_>>();
    let shown = browser.evaluate(
        "[...document.querySelectorAll('#patch-table tr[data-patch] td.de')].map(c => c.innerText)",
    );
    let shown: Vec<String> = shown
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    assert!(!recorded.is_empty());
    assert_eq!(shown, recorded);
    // The time axis is in dates (UTC), not seconds since the first profile: today's
    // month and day, and a time of day, on its ticks.
    let labels = browser.evaluate("document.querySelector('#fig-history-white svg').textContent");
    let labels = labels.as_str().unwrap();
    // (The first profile's month and day: not today's, which a run across midnight
    // would change.)
    let first = history["profiles"][0]["at"].as_str().unwrap().to_string();
    let month_day = &first[5..10];
    assert!(labels.contains("date and time (UTC)"), "{labels}");
    assert!(
        labels.contains(&format!("{month_day} ")),
        "no {month_day} on the axis: {labels}"
    );
    assert!(!labels.contains("since the first"), "{labels}");
}

/// The browser check can fail: a page with a script error and an image that does not
/// load reports both.
#[test]
fn the_browser_check_sees_a_broken_page() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("broken.html");
    std::fs::write(
        &page,
        "<!DOCTYPE html><html><body><img src=\"missing.png\"><script>undefined_function();</script></body></html>",
    )
    .unwrap();
    let mut browser = Browser::open("about:blank", 400, 300);
    let errors = browser.navigate(&format!("file://{}", page.display()));
    assert!(
        errors.iter().any(|e| e.contains("undefined_function")),
        "{errors:#?}"
    );
    assert!(
        errors
            .iter()
            .any(|e| e.contains("missing.png") || e.contains("ERR_FILE_NOT_FOUND")),
        "{errors:#?}"
    );
}

/// An HDR calibration's report draws the PQ tracking (each grey measured through the
/// curves) and the brightness limiter (each window), and states the full-field white.
#[test]
fn an_hdr_calibration_s_report_draws_its_pq_tracking_and_its_limiter() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        format!(
            "{}[plan]\nbit_depth = 10\n[target]\nwhite = \"D65\"\ntone = \"pq\"\npeak = 600.0\n",
            common::isetbio_monitor("isetbio_oled_sony", "preset = \"hdr-oled\""),
        ),
    )
    .unwrap();
    let page = dir.path().join("report.html");
    let state = dir.path().join("state");
    succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state)
            .arg("--report")
            .arg(&page),
    );
    // Judged by the limits it was published by, the HDR half included.
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("mean ΔE ITP ≤ 1"), "{html:.2000}");
    assert!(html.contains("id=\"judged-itp\""), "{html:.2000}");
    // `report` of the profile alone judges it the same way.
    let out = chromacal()
        .arg("report")
        .arg(state.join("current.toml"))
        .args(["-o", "-"])
        .output()
        .unwrap();
    let alone = String::from_utf8_lossy(&out.stdout);
    assert!(alone.contains("mean ΔE ITP ≤ 1"), "{alone:.2000}");
    // So does the page of a refit of its journal.
    let refit_page = dir.path().join("refit.html");
    let current = chromacal::profile::Profile::read(&state.join("current.toml")).unwrap();
    succeed(
        chromacal()
            .arg("fit")
            .arg(&current.provenance.source)
            .arg("-o")
            .arg(dir.path().join("refit.toml"))
            .arg("--report")
            .arg(&refit_page),
    );
    let refit = std::fs::read_to_string(&refit_page).unwrap();
    assert!(refit.contains("mean ΔE ITP ≤ 1"), "{refit:.2000}");
    let profile = chromacal::profile::Profile::read(&state.join("current.toml")).unwrap();
    let levels = profile.calibration.as_ref().unwrap().levels.len() as u64;
    let limiter = profile.report.limiter.as_ref().unwrap();
    let mut browser = open_report(&page, &["fig-pq-tracking", "fig-brightness-limiter"]);
    // Each level measured through the curves, each window, and one legend circle per
    // series of points.
    let (_, _, circles) = figure_shape(&mut browser, "fig-pq-tracking").unwrap();
    assert_eq!(circles, levels + 1);
    let (_, _, circles) = figure_shape(&mut browser, "fig-brightness-limiter").unwrap();
    assert_eq!(circles, limiter.windows.len() as u64 + 2);
    let said = browser.evaluate("document.querySelector('#full-field-white').innerText");
    let full = limiter.full_field_white().unwrap().measured_y;
    assert_eq!(said.as_str(), Some(format!("{full:.1} cd/m²").as_str()));
    let verdict = browser.evaluate("document.querySelector('#limiter-verdict').innerText");
    assert!(verdict.as_str().unwrap().starts_with("Kept"), "{verdict}");
}
