//! The daemon's fleet page (`GET /`) and its login page: every device at a glance —
//! its state, current profile, last verification against its threshold, next
//! scheduled verification, white luminance drift as a sparkline — with a link to each
//! device's report. Plain data in, one self-contained page out: no script, no network,
//! refreshed by the browser every 30 s.

use std::fmt::Write;

use super::page::escape;

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
    pub mean: Option<f64>,
    pub threshold: f64,
}

impl FleetVerification {
    /// Passed: its mean ΔE00 within the threshold.
    pub fn passed(&self) -> bool {
        self.mean.is_some_and(|m| m <= self.threshold)
    }
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
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n\
         <meta http-equiv=\"refresh\" content=\"30\">\n\
         <title>chromacal on {host}</title>\n<style>{STYLE}</style></head>\n<body>\n\
         <h1>chromacal on {host}</h1>\n<p class=\"muted\">version {version}, {n} device{s}; \
         this page refreshes every 30 s.",
        host = escape(host),
        version = escape(version),
        n = devices.len(),
        s = if devices.len() == 1 { "" } else { "s" },
    );
    if logout {
        out.push_str(
            " <form class=\"inline\" method=\"post\" action=\"/logout\"><button>Log out</button></form>",
        );
    }
    out.push_str(
        "</p>\n<table id=\"devices\">\n<thead><tr><th>device</th><th>state</th>\
         <th>current profile (held-out mean ΔE00)</th><th>last verification</th>\
         <th>next verification</th><th>white luminance</th><th>report</th></tr></thead>\n<tbody>\n",
    );
    for device in devices {
        row(&mut out, device);
    }
    out.push_str("</tbody></table>\n</body></html>\n");
    out
}

fn row(out: &mut String, d: &FleetDevice) {
    let name = escape(&d.name);
    let state = match (&d.job, d.retiring, d.up) {
        (Some(job), true, _) => format!("{}; leaving after it", escape(job)),
        (Some(job), false, _) => escape(job),
        (None, true, _) => "leaving".to_string(),
        (None, false, true) => "idle".to_string(),
        (None, false, false) => {
            "<span class=\"down\">instrument or display failed its last job</span>".to_string()
        }
    };
    let profile = match &d.profile {
        Some((id, held_out)) => format!(
            "{}{}",
            escape(id),
            held_out.map_or(String::new(), |m| format!(" ({m:.3})"))
        ),
        None => "<span class=\"muted\">none yet</span>".into(),
    };
    let verification = match &d.verification {
        Some(v) => format!(
            "<span class=\"{class}\">{word}</span> {mean} against {threshold} <span class=\"muted\">{at}</span>",
            class = if v.passed() { "pass" } else { "fail" },
            word = if v.passed() { "pass" } else { "fail" },
            mean = v.mean.map_or("–".to_string(), |m| format!("{m:.3}")),
            threshold = v.threshold,
            at = escape(&v.at),
        ),
        None => "<span class=\"muted\">none of this profile</span>".into(),
    };
    let next = d.next_verification.as_deref().map_or(
        "<span class=\"muted\">not scheduled</span>".to_string(),
        escape,
    );
    let report = match &d.profile {
        Some(_) => format!("<a href=\"/devices/{name}/report\">report</a>"),
        None => "<span class=\"muted\">–</span>".into(),
    };
    let _ = writeln!(
        out,
        "<tr data-device=\"{name}\"><td class=\"name\">{name}</td><td class=\"state\">{state}</td>\
         <td class=\"profile\">{profile}</td><td class=\"verification\">{verification}</td>\
         <td class=\"next\">{next}</td><td class=\"white\">{white}</td><td>{report}</td></tr>",
        white = white_cell(&d.whites, d.drift),
    );
}

/// The newest white, its drift in % an hour with its standard error, and a sparkline
/// of the recent whites.
fn white_cell(whites: &[(f64, f64)], drift: Option<(f64, f64)>) -> String {
    let Some(&(_, last)) = whites.last() else {
        return "<span class=\"muted\">no white measured since start</span>".into();
    };
    let drift = drift.map_or(String::new(), |(per_s, se)| {
        let per_hour = |v: f64| v * 3600.0 / last * 100.0;
        format!(", drift {:+.2} ± {:.2} %/h", per_hour(per_s), per_hour(se))
    });
    format!("{last:.2} cd/m²{drift} {}", sparkline(whites))
}

/// An inline SVG line of `points` (x, y), scaled to 120 × 24 px; titled with the range.
pub fn sparkline(points: &[(f64, f64)]) -> String {
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
        return String::new();
    }
    // A flat series is drawn in the middle, not blown up from its noise.
    let (y0, y1) = if y1 - y0 < 1e-9 * y1.abs().max(1.0) {
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
                h - (y - y0) / (y1 - y0) * h
            )
        })
        .collect();
    format!(
        "<svg class=\"sparkline\" width=\"{w}\" height=\"{h}\" viewBox=\"-1 -1 {} {}\" role=\"img\"><title>{} whites, {:.2} to {:.2} cd/m²</title><polyline fill=\"none\" stroke=\"#36c\" stroke-width=\"1.5\" points=\"{}\"/></svg>",
        w + 2.0,
        h + 2.0,
        points.len(),
        range(|p| p.1).0,
        range(|p| p.1).1,
        coordinates.join(" ")
    )
}

/// The login page of the TCP listener: the API token, once, for a session cookie.
pub fn login_html(host: &str, error: Option<&str>) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n\
         <title>chromacal on {host}: log in</title>\n<style>{STYLE}</style></head>\n<body>\n\
         <h1>chromacal on {host}</h1>\n{error}\
         <form method=\"post\" action=\"/login\">\n\
         <p><label>API token (the daemon's <code>daemon.token_file</code>, by default \
         <code>&lt;state&gt;/api.token</code>)<br>\
         <input type=\"password\" name=\"token\" autocomplete=\"current-password\" size=\"70\" autofocus></label></p>\n\
         <p><button type=\"submit\">Log in</button></p>\n</form>\n\
         <p class=\"muted\">The session lets this browser look (GET) for 12 hours; \
         starting or cancelling jobs needs the token itself.</p>\n</body></html>\n",
        host = escape(host),
        error = error.map_or(String::new(), |e| format!(
            "<p class=\"fail\" id=\"error\">{}</p>\n",
            escape(e)
        )),
    )
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
                    mean: Some(1.5),
                    threshold: 1.0,
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
        assert!(page.contains("class=\"fail\">fail</span> 1.500 against 1"));
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
        let line = sparkline(&[(0.0, 1.0), (1.0, 3.0), (2.0, 2.0)]);
        assert!(
            line.contains("points=\"0.0,24.0 60.0,0.0 120.0,12.0\""),
            "{line}"
        );
        let flat = sparkline(&[(0.0, 5.0), (1.0, 5.0)]);
        assert!(flat.contains("points=\"0.0,12.0 120.0,12.0\""), "{flat}");
        assert_eq!(sparkline(&[(0.0, 5.0)]), "");
    }
}
