//! The daemon's fleet page (`GET /`) and its login page: every device at a glance —
//! its state, current profile, last verification against its threshold, next
//! scheduled verification, white luminance drift as a sparkline — with a link to each
//! device's report. Plain data in, one self-contained page out: no script, no network,
//! refreshed by the browser every 30 s.

use maud::{DOCTYPE, Markup, PreEscaped, html};

/// One device as the fleet page shows it.
#[derive(Debug, Clone, Default)]
pub struct FleetDevice {
    pub name: String,
    /// Its instrument and display answered its last job.
    pub up: bool,
    /// The running job, said in words (`calibrate: measuring, 12/40 patches`).
    pub job: Option<String>,
    /// A reload removed or changed it: it leaves after its job.
    pub retiring: bool,
    /// The current profile's id and held-out mean ΔE00.
    pub profile: Option<(String, Option<f64>)>,
    pub verification: Option<FleetVerification>,
    /// RFC 3339.
    pub next_verification: Option<String>,
    /// Recent full whites at the centre: (seconds, cd/m²), oldest first.
    pub whites: Vec<(f64, f64)>,
    /// Their least-squares slope and its standard error, cd/m² per second.
    pub drift: Option<(f64, f64)>,
}

/// The last verification of the current profile.
#[derive(Debug, Clone, PartialEq)]
pub struct FleetVerification {
    /// RFC 3339.
    pub at: String,
    /// What `mean` and `threshold` measure: ΔE00, or ΔE ITP for a profile of an HDR
    /// signal.
    pub metric: crate::verify::Metric,
    pub mean: Option<f64>,
    pub threshold: f64,
    /// As the record says (`VerificationRecord::passed`).
    pub passed: bool,
}

const STYLE: &str = "
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 70em; color: #222; }
table { border-collapse: collapse; width: 100%; }
th, td { text-align: left; padding: 0.35em 0.6em; border-bottom: 1px solid #ddd; vertical-align: middle; }
th { background: #f3f3f3; }
.pass { color: #070; font-weight: bold; }
.fail { color: #a00; font-weight: bold; }
.down { color: #a00; }
.muted { color: #777; }
form.inline { display: inline; }
";

/// The fleet page of the daemon on `host`: one row a device. `logout` adds a button
/// ending the browser session (over TCP).
pub fn fleet_html(host: &str, version: &str, devices: &[FleetDevice], logout: bool) -> String {
    let n = devices.len();
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta http-equiv="refresh" content="30";
                title { "chromacal on " (host) }
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { "chromacal on " (host) }
                p.muted {
                    "version " (version) ", " (n) " device" @if n != 1 { "s" } "; this page refreshes every 30 s."
                    @if logout {
                        " " form.inline method="post" action="/logout" { button { "Log out" } }
                    }
                }
                table #devices {
                    thead {
                        tr {
                            th { "device" } th { "state" } th { "current profile (held-out mean ΔE00)" }
                            th { "last verification" } th { "next verification" } th { "white luminance" } th { "report" }
                        }
                    }
                    tbody { @for d in devices { (row(d)) } }
                }
            }
        }
    }
    .into_string()
}

fn row(d: &FleetDevice) -> Markup {
    html! {
        tr data-device=(d.name) {
            td.name { (d.name) }
            td.state {
                @match (&d.job, d.retiring, d.up) {
                    (Some(job), true, _) => { (job) "; leaving after it" },
                    (Some(job), false, _) => { (job) },
                    (None, true, _) => "leaving",
                    (None, false, true) => "idle",
                    (None, false, false) => span.down { "instrument or display failed its last job" },
                }
            }
            td.profile {
                @match &d.profile {
                    Some((id, held_out)) => { (id) @if let Some(m) = held_out { (format!(" ({m:.3})")) } },
                    None => span.muted { "none yet" },
                }
            }
            td.verification {
                @match &d.verification {
                    Some(v) => {
                        @let word = if v.passed { "pass" } else { "fail" };
                        span class=(word) { (word) }
                        " " (v.mean.map_or("–".to_string(), |m| format!("{m:.3}"))) " " (v.metric.name()) " against " (v.threshold) " "
                        span.muted { (v.at) }
                    },
                    None => span.muted { "none of this profile" },
                }
            }
            td.next {
                @match &d.next_verification {
                    Some(at) => (at),
                    None => span.muted { "not scheduled" },
                }
            }
            td.white { (white_cell(&d.whites, d.drift)) }
            td {
                @if d.profile.is_some() { a href={ "/devices/" (d.name) "/report" } { "report" } }
                @else { span.muted { "–" } }
            }
        }
    }
}

/// The newest white, its drift in % an hour with its standard error, and a sparkline
/// of the recent whites.
fn white_cell(whites: &[(f64, f64)], drift: Option<(f64, f64)>) -> Markup {
    let Some(&(_, last)) = whites.last() else {
        return html! { span.muted { "no white measured since start" } };
    };
    let drift = drift.map_or(String::new(), |(per_s, se)| {
        let per_hour = |v: f64| v * 3600.0 / last * 100.0;
        format!(", drift {:+.2} ± {:.2} %/h", per_hour(per_s), per_hour(se))
    });
    html! { (format!("{last:.2} cd/m²{drift} ")) (sparkline(whites)) }
}

/// An inline SVG line of `points` (x, y), scaled to 120 × 24 px; titled with the range.
pub fn sparkline(points: &[(f64, f64)]) -> Markup {
    let (w, h) = (120.0, 24.0);
    let range = |f: fn(&(f64, f64)) -> f64| {
        points
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    let (x0, x1) = range(|p| p.0);
    let (y0, y1) = range(|p| p.1);
    if points.len() < 2 || !(x1 > x0) {
        return html! {};
    }
    // A flat series is drawn in the middle, not blown up from its noise.
    let (lo, hi) = if y1 - y0 < 1e-9 * y1.abs().max(1.0) {
        (y0 - 1.0, y1 + 1.0)
    } else {
        (y0, y1)
    };
    let coordinates: Vec<String> = points
        .iter()
        .map(|(x, y)| {
            format!(
                "{:.1},{:.1}",
                (x - x0) / (x1 - x0) * w,
                h - (y - lo) / (hi - lo) * h
            )
        })
        .collect();
    html! {
        svg.sparkline width=(w) height=(h) viewBox={ "-1 -1 " (w + 2.0) " " (h + 2.0) } role="img" {
            title { (points.len()) " whites, " (format!("{y0:.2} to {y1:.2}")) " cd/m²" }
            polyline fill="none" stroke="#36c" stroke-width="1.5" points=(coordinates.join(" ")) {}
        }
    }
}

/// The login page of the TCP listener: the API token, once, for a session cookie.
pub fn login_html(host: &str, error: Option<&str>) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "chromacal on " (host) ": log in" }
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { "chromacal on " (host) }
                @if let Some(e) = error { p.fail #error { (e) } }
                form method="post" action="/login" {
                    p {
                        label {
                            "API token (the daemon's " code { "daemon.token_file" } ", by default " code { "<state>/api.token" } ")"
                            br;
                            input type="password" name="token" autocomplete="current-password" size="70" autofocus;
                        }
                    }
                    p { button type="submit" { "Log in" } }
                }
                p.muted { "The session lets this browser look (GET) for 12 hours; starting or cancelling jobs needs the token itself." }
            }
        }
    }
    .into_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_names_each_device_and_escapes_what_it_shows() {
        let devices = [
            FleetDevice {
                name: "crt".into(),
                up: true,
                profile: Some(("p1".into(), Some(0.1234))),
                verification: Some(FleetVerification {
                    at: "2026-12-03T10:00:00Z".into(),
                    metric: crate::verify::Metric::De00,
                    mean: Some(1.5),
                    threshold: 1.0,
                    passed: false,
                }),
                whites: vec![(0.0, 100.0), (60.0, 101.0), (120.0, 102.0)],
                drift: Some((1.0 / 60.0, 0.001)),
                ..FleetDevice::default()
            },
            FleetDevice {
                name: "lcd".into(),
                up: false,
                job: Some("verify <measuring>".into()),
                ..FleetDevice::default()
            },
        ];
        let page = fleet_html("lab&1", "1.0", &devices, true);
        assert!(page.contains("chromacal on lab&amp;1"));
        assert!(page.contains("<tr data-device=\"crt\">"));
        assert!(page.contains("href=\"/devices/crt/report\""));
        assert!(
            page.contains("class=\"fail\">fail</span> 1.500 ΔE00 against 1 "),
            "{page}"
        );
        assert!(page.contains("p1 (0.123)"));
        // 1/60 cd/m² a second at 102 cd/m²: 58.8 %/h.
        assert!(page.contains("drift +58.82 ± 3.53 %/h"), "{page}");
        assert!(page.contains("<polyline"));
        assert!(page.contains("verify &lt;measuring&gt;"));
        assert!(!page.contains("href=\"/devices/lcd/report\""));
        assert!(page.contains("action=\"/logout\""));
        assert!(!fleet_html("h", "1", &devices, false).contains("/logout"));
    }

    #[test]
    fn a_sparkline_spans_its_box_and_a_flat_one_sits_in_the_middle() {
        let line = sparkline(&[(0.0, 1.0), (1.0, 3.0), (2.0, 2.0)]).into_string();
        assert!(
            line.contains("points=\"0.0,24.0 60.0,0.0 120.0,12.0\""),
            "{line}"
        );
        let flat = sparkline(&[(0.0, 5.0), (1.0, 5.0)]).into_string();
        assert!(flat.contains("points=\"0.0,12.0 120.0,12.0\""), "{flat}");
        assert_eq!(sparkline(&[(0.0, 5.0)]).into_string(), "");
    }
}
