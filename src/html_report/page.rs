//! The report page: sections in the order a reader checks a calibration (who and what
//! it cost, the curves, the primaries, the screen, the error, the assumptions), each a
//! heading, a figure or two and the table behind them.

use std::fmt::Write as _;

use super::figures::{self, Curve};
use super::{
    ReportError, ReportInput, candidate_curve, chromaticities, measured_greys, measured_shares,
    sampled, smallest_drive, swatch, uniformity_data,
};
use crate::color::spaces::xyz_to_xyy;
use crate::fit::checks::Verdict;
use crate::fit::stats::ErrorStats;
use crate::model::CHANNELS;
use crate::model::spatial::SpatialMap;
use crate::profile::Profile;

const STYLE: &str = "
body { font-family: sans-serif; max-width: 1100px; margin: 1.5em auto; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child, td.text { text-align: left; }
th { background: #f4f4f4; }
figure { display: inline-block; margin: 0.4em; vertical-align: top; }
figure svg { max-width: 100%; height: auto; }
figcaption { font-size: 0.85em; color: #555; max-width: 520px; }
.swatch { display: inline-block; width: 2.2em; height: 1.2em; border: 1px solid #888; vertical-align: middle; }
.note { color: #6a4a00; background: #fff8e0; padding: 0.3em 0.6em; border-left: 3px solid #e0b000; }
.fails { color: #a00; font-weight: bold; }
@media print { body { max-width: none; } section { break-inside: avoid; } figure { break-inside: avoid; } }
";

/// `s` with the five characters HTML gives meaning escaped.
pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

fn figure(out: &mut String, id: &str, svg: &str, caption: &str) {
    let _ = writeln!(
        out,
        "<figure id=\"{id}\">{svg}<figcaption>{}</figcaption></figure>",
        escape(caption)
    );
}

fn note(out: &mut String, text: &str) {
    let _ = writeln!(out, "<p class=\"note\">{}</p>", escape(text));
}

/// An HTML table; cells are escaped.
fn table(out: &mut String, headers: &[&str], rows: &[Vec<String>]) {
    out.push_str("<table><tr>");
    for h in headers {
        let _ = write!(out, "<th>{}</th>", escape(h));
    }
    out.push_str("</tr>\n");
    for row in rows {
        out.push_str("<tr>");
        for cell in row {
            // Figures to the right, so that their decimals line up; words to the left.
            let numeric = cell.trim_end_matches(" %").parse::<f64>().is_ok() || cell == "–";
            let class = if numeric { "" } else { " class=\"text\"" };
            let _ = write!(out, "<td{class}>{}</td>", escape(cell));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n");
}

fn stats_cells(stats: Option<&ErrorStats>) -> [String; 3] {
    match stats {
        Some(s) => [
            format!("{:.3}", s.mean),
            format!("{:.3}", s.p95),
            format!("{:.3}", s.max),
        ],
        None => ["–".into(), "–".into(), "–".into()],
    }
}

/// A law's parameter as "name value" (a table's knot count as a count).
fn parameter(name: &str, value: f64) -> String {
    match name {
        "knots" => format!("{value:.0} knots"),
        _ => format!("{name} {value:.4}"),
    }
}

fn seconds(s: f64) -> String {
    if !(s.is_finite() && s >= 0.0) {
        // A run's cost read from a file written by hand, say: nothing to print.
        "–".to_string()
    } else if s >= 60.0 {
        format!("{:.0} min {:.0} s", (s / 60.0).floor(), s % 60.0)
    } else if s >= 1.0 {
        format!("{s:.1} s")
    } else {
        format!("{:.1} ms", s * 1000.0)
    }
}

/// The report of `input` as a self-contained HTML page.
pub fn report_html(input: &ReportInput) -> Result<String, ReportError> {
    let profile = input.profile;
    // A file that names no display is named by its own file name.
    let source_name = std::path::Path::new(&profile.provenance.source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned());
    let display = profile
        .provenance
        .display
        .clone()
        .or(source_name)
        .unwrap_or_else(|| profile.id.clone());
    let display = display.as_str();
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>chromacal report: {device}{} ({})</title>\n<style>{STYLE}</style></head>\n<body>\n{back}<h1>Calibration report: {device}{}</h1>\n",
        escape(display),
        escape(&profile.id),
        escape(display),
        device = input
            .device
            .as_deref()
            .map_or(String::new(), |d| format!("device {}, ", escape(d))),
        back = match input.device {
            Some(_) => "<p><a href=\"/\">← all devices</a></p>\n",
            None => "",
        },
    );
    identity(&mut out, profile);
    transfer(&mut out, input)?;
    laws(&mut out, profile);
    primaries(&mut out, input)?;
    uniformity(&mut out, input)?;
    held_out(&mut out, profile)?;
    checks(&mut out, profile);
    calibration(&mut out, profile)?;
    history(&mut out, input)?;
    let _ = write!(
        out,
        "<footer><p>Made by {} from profile {}.</p></footer>\n</body></html>\n",
        escape(&profile.provenance.program),
        escape(&profile.id)
    );
    Ok(out)
}

fn identity(out: &mut String, profile: &Profile) {
    out.push_str("<section id=\"identity\"><h2>Run and cost</h2>\n");
    let p = &profile.provenance;
    let c = &profile.report.counts;
    let mut rows = vec![
        vec!["profile".into(), profile.id.clone()],
        vec!["made".into(), profile.created.clone()],
        vec!["display".into(), p.display.clone().unwrap_or("–".into())],
        vec![
            "instrument".into(),
            p.instrument
                .as_ref()
                .map_or("–".into(), |i| match &i.serial {
                    Some(s) => format!("{} (serial {s})", i.name),
                    None => i.name.clone(),
                }),
        ],
        vec!["readings from".into(), p.source.clone()],
        vec!["units".into(), profile.units.to_string()],
        vec![
            "readings".into(),
            format!(
                "{} ({} usable; {} in the fit's kinds, {} held out, {} uniformity)",
                c.readings, c.usable, c.budget_readings, c.held_out, c.uniformity
            ),
        ],
    ];
    match &profile.cost {
        Some(cost) => {
            rows.push(vec![
                "instrument time".into(),
                cost.instrument_s
                    .map_or("not recorded in the file".into(), seconds),
            ]);
            rows.push(vec!["fit time".into(), seconds(cost.fit_s)]);
        }
        None => rows.push(vec![
            "cost".into(),
            "not recorded (a profile made before chromacal recorded it)".into(),
        ]),
    }
    rows.push(vec!["program".into(), p.program.clone()]);
    out.push_str("<table>\n");
    for row in rows {
        let _ = writeln!(
            out,
            "<tr><th>{}</th><td style=\"text-align:left\">{}</td></tr>",
            escape(&row[0]),
            escape(&row[1])
        );
    }
    out.push_str("</table>\n");
    if let Some(why) = &profile.report.luminance_only {
        note(out, why);
    }
    out.push_str("</section>\n");
}

fn transfer(out: &mut String, input: &ReportInput) -> Result<(), ReportError> {
    let profile = input.profile;
    let model = &profile.model;
    out.push_str("<section id=\"transfer\"><h2>Transfer curves</h2>\n");
    if let Some(why) = &input.readings_note {
        note(out, why);
    }
    let chosen_kind = profile.report.chosen_law();
    let mut residuals: [Curve; 3] = Default::default();
    for (channel, name) in CHANNELS.iter().enumerate() {
        let law = &model.laws[channel];
        let measured = input
            .readings
            .map(|set| measured_shares(model, set, channel))
            .unwrap_or_default();
        let toe = input
            .readings
            .map(|set| smallest_drive(set, channel))
            .unwrap_or(1.0 / 255.0);
        let candidates: Vec<(String, Curve)> = profile
            .report
            .laws
            .iter()
            .filter(|l| Some(l.law) != chosen_kind)
            .filter_map(|l| {
                let curve = candidate_curve(l.law, &l.parameters[channel], toe)?;
                Some((l.law.name().to_string(), curve))
            })
            .collect();
        residuals[channel] = measured
            .iter()
            .map(|&(v, share)| (v, share - law.excitation(v)))
            .collect();
        let svg = figures::transfer(
            channel,
            &format!("{name}: {}", law.kind()),
            (law.kind().name(), &sampled(law)),
            &candidates,
            &measured,
        )?;
        let params: Vec<String> = law
            .parameters()
            .iter()
            .map(|(n, v)| parameter(n, *v))
            .collect();
        figure(
            out,
            &format!("fig-transfer-{name}"),
            &svg,
            &format!(
                "{name}: the chosen law ({}; {}), the other candidates dashed, and the {} single-channel readings at the centre.",
                law.kind(),
                params.join(", "),
                measured.len()
            ),
        );
    }
    if let Some(set) = input.readings {
        let greys = measured_greys(model, set);
        let white = model.white().y - model.black.y;
        let curve: Curve = (0..=100)
            .map(|i| {
                let v = i as f64 / 100.0;
                (v, (model.forward_centre([v; 3]).y - model.black.y) / white)
            })
            .collect();
        let svg = figures::greys(&curve, &greys)?;
        figure(
            out,
            "fig-greys",
            &svg,
            &format!(
                "{} greys against the whole model (matrix, laws and any terms kept): where the greys leave the line, additivity fails.",
                greys.len()
            ),
        );
        let svg = figures::residuals(&residuals)?;
        figure(
            out,
            "fig-residuals",
            &svg,
            "Each single-channel reading's share of full drive less the chosen law's.",
        );
    }
    out.push_str("</section>\n");
    Ok(())
}

fn laws(out: &mut String, profile: &Profile) {
    let r = &profile.report;
    out.push_str("<section id=\"laws\"><h2>Law selection</h2>\n");
    let _ = writeln!(out, "<p>{}</p>", escape(&r.law_rule));
    let rows: Vec<Vec<String>> = r
        .laws
        .iter()
        .map(|l| {
            let [mean, p95, max] = stats_cells(l.cross_validation.as_ref());
            let params = (0..3)
                .map(|c| {
                    let p: Vec<String> = l.parameters[c]
                        .iter()
                        .map(|p| parameter(&p.name, p.value))
                        .collect();
                    format!("{}: {}", CHANNELS[c], p.join(" "))
                })
                .collect::<Vec<_>>()
                .join("; ");
            vec![
                format!("{}{}", l.law, if l.chosen { " (chosen)" } else { "" }),
                mean,
                p95,
                max,
                l.greys
                    .as_ref()
                    .map_or("–".into(), |g| format!("{:.3}", g.mean)),
                params,
            ]
        })
        .collect();
    table(
        out,
        &[
            "law",
            "CV mean ΔE00",
            "p95",
            "max",
            "greys mean",
            "parameters",
        ],
        &rows,
    );
    if !r.terms.is_empty() {
        let _ = writeln!(out, "<p>{}</p>", escape(&r.terms_rule));
        let rows: Vec<Vec<String>> = r
            .terms
            .iter()
            .map(|t| {
                let [mean, p95, max] = stats_cells(t.cross_validation.as_ref());
                vec![
                    format!("{}{}", t.terms.name(), if t.kept { " (kept)" } else { "" }),
                    mean,
                    p95,
                    max,
                ]
            })
            .collect();
        table(out, &["terms", "CV mean ΔE00", "p95", "max"], &rows);
    }
    if let Some(c) = &r.law_correction {
        let [law, _, _] = stats_cells(c.law_cv.as_ref());
        let [corrected, _, _] = stats_cells(c.corrected_cv.as_ref());
        let _ = writeln!(
            out,
            "<p>Correction of the {} law at the measured levels: CV mean {law} alone, {corrected} corrected; {}. {}</p>",
            c.law,
            if c.kept { "kept" } else { "not kept" },
            escape(&c.rule)
        );
    }
    if let Some(c) = &r.code_correction {
        let [uncorrected, _, _] = stats_cells(c.uncorrected.as_ref());
        let [corrected, _, _] = stats_cells(c.corrected.as_ref());
        let _ = writeln!(
            out,
            "<p>Correction at the measured codes ({} codes, {} measured both as a ramp reading and as a grey): replicates predicted with mean ΔE00 {uncorrected} uncorrected, {corrected} corrected; {}. {}</p>",
            c.codes,
            c.replicates,
            if c.kept { "kept" } else { "not kept" },
            escape(&c.rule)
        );
    }
    out.push_str("</section>\n");
}

fn primaries(out: &mut String, input: &ReportInput) -> Result<(), ReportError> {
    let profile = input.profile;
    out.push_str("<section id=\"primaries\"><h2>Primaries and white</h2>\n");
    let data = chromaticities(&profile.model, input.readings);
    let svg = figures::chromaticity(&data)?;
    figure(
        out,
        "fig-chromaticity",
        &svg,
        "The display's primaries (circles) and white (cross), each channel's chromaticity at every measured level (dots; a spread shows chromaticity that moves with drive), with sRGB, DCI-P3 and BT.2020 for scale.",
    );
    let model = &profile.model;
    let mut rows: Vec<Vec<String>> = profile
        .report
        .primaries
        .iter()
        .map(|p| {
            vec![
                p.channel.clone(),
                format!("{:.4}", p.chromaticity[0]),
                format!("{:.4}", p.chromaticity[1]),
                format!("{:.3}", p.xyz.y),
                format!("{}", p.levels),
            ]
        })
        .collect();
    let white = xyz_to_xyy(&model.white(), [0.3127, 0.3290]);
    rows.push(vec![
        "white".into(),
        format!("{:.4}", white.x),
        format!("{:.4}", white.y),
        format!("{:.3}", white.big_y),
        "".into(),
    ]);
    let black = xyz_to_xyy(&model.black, [0.3127, 0.3290]);
    rows.push(vec![
        "black".into(),
        format!("{:.4}", black.x),
        format!("{:.4}", black.y),
        format!("{:.4}", black.big_y),
        "".into(),
    ]);
    table(out, &["", "x", "y", "Y", "levels"], &rows);
    let _ = writeln!(
        out,
        "<p>Condition number of the primary matrix: {:.2}.</p>",
        profile.report.condition_number
    );
    if let (Some(edid), Some(comparison)) = (&profile.provenance.edid, profile.edid_comparison()) {
        let _ = writeln!(
            out,
            "<h3 id=\"edid\">What the monitor's EDID states</h3>\n<p>{}</p>",
            escape(&edid.describe())
        );
        let rows = comparison.table_rows();
        table(out, &["", "EDID xy", "measured xy", "apart"], &rows);
        if comparison.mismatch() {
            note(
                out,
                &format!(
                    "The EDID's chromaticities are up to {:.3} from the measured ones: is this the display you meant?",
                    comparison.worst
                ),
            );
        }
    }
    out.push_str("</section>\n");
    Ok(())
}

fn uniformity(out: &mut String, input: &ReportInput) -> Result<(), ReportError> {
    let profile = input.profile;
    let spatial = &profile.report.spatial;
    out.push_str("<section id=\"uniformity\"><h2>Uniformity</h2>\n");
    let (surface, points) = uniformity_data(&profile.model, input.readings);
    if points.is_empty() && profile.model.spatial == SpatialMap::Uniform {
        note(
            out,
            &format!(
                "No uniformity grid was measured{}: the model is uniform over the screen.",
                if spatial.positions > 0 {
                    " that the page can show"
                } else {
                    ""
                }
            ),
        );
    } else {
        let svg = figures::uniformity(&surface, &points)?;
        figure(
            out,
            "fig-uniformity",
            &svg,
            &format!(
                "The spatial map kept ({}) as light relative to the centre, with the {} measured positions (percent of the centre's light).",
                profile.model.spatial.describe(),
                points.len()
            ),
        );
    }
    if !spatial.candidates.is_empty() {
        let rows: Vec<Vec<String>> = spatial
            .candidates
            .iter()
            .map(|c| {
                let [mean, p95, max] = stats_cells(c.cross_validation.as_ref());
                vec![
                    format!("{}{}", c.name, if c.chosen { " (chosen)" } else { "" }),
                    mean,
                    p95,
                    max,
                    c.note.clone().unwrap_or_default(),
                ]
            })
            .collect();
        table(out, &["map", "CV mean ΔE00", "p95", "max", "note"], &rows);
    }
    out.push_str("</section>\n");
    Ok(())
}

fn held_out(out: &mut String, profile: &Profile) -> Result<(), ReportError> {
    let r = &profile.report;
    out.push_str("<section id=\"held-out\"><h2>Error on patches held out of the fit</h2>\n");
    let Some(stats) = &r.held_out else {
        note(
            out,
            "No patch was held out of the fit, so there is no honest error to show.",
        );
        out.push_str("</section>\n");
        return Ok(());
    };
    let values: Vec<f64> = r.held_out_patches.iter().map(|p| p.delta_e00).collect();
    let svg = figures::histogram(&values, "Held-out ΔE00")?;
    figure(
        out,
        "fig-held-out",
        &svg,
        &format!(
            "{} patches held out of every fit: mean ΔE00 {:.3}, p95 {:.3}, max {:.3}.",
            stats.n, stats.mean, stats.p95, stats.max
        ),
    );
    let white = profile.model.white();
    let mut worst: Vec<_> = r.held_out_patches.iter().collect();
    worst.sort_by(|a, b| b.delta_e00.total_cmp(&a.delta_e00));
    out.push_str("<h3>Worst patches</h3>\n<table><tr><th>patch</th><th>drive R, G, B</th><th>measured</th><th>predicted</th><th>ΔE00</th></tr>\n");
    for p in worst.iter().take(10) {
        let hex = |xyz| {
            let [r, g, b] = swatch(xyz, &white);
            format!("#{r:02x}{g:02x}{b:02x}")
        };
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{:.3}, {:.3}, {:.3}</td><td><span class=\"swatch\" style=\"background:{}\"></span></td><td><span class=\"swatch\" style=\"background:{}\"></span></td><td>{:.3}</td></tr>",
            p.index,
            p.drive[0],
            p.drive[1],
            p.drive[2],
            hex(&p.measured),
            hex(&p.predicted),
            p.delta_e00
        );
    }
    out.push_str("</table>\n</section>\n");
    Ok(())
}

fn checks(out: &mut String, profile: &Profile) {
    let c = &profile.report.checks;
    out.push_str("<section id=\"checks\"><h2>Assumption checks</h2>\n");
    let constancy = c
        .primary_constancy
        .iter()
        .map(|k| {
            format!(
                "{}: Δu′v′ {:.4} (noise {:.4}){}",
                k.channel,
                k.max_delta_uv,
                k.noise_delta_uv,
                k.delta_e00
                    .map_or(String::new(), |d| format!(", costs ΔE00 {d:.2}"))
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    let additivity = c
        .additivity
        .iter()
        .map(|a| {
            format!(
                "grey {:.2}: {:+.1} % luminance, ΔE00 {:.2}",
                a.drive, a.luminance_departure_percent, a.delta_e00
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    let surround = c.spatial_independence.as_ref().map_or("–".into(), |s| {
        format!(
            "{:+.2} % on a white surround (noise {:.2} %), ΔE00 {:.2}",
            s.luminance_change_percent, s.noise_percent, s.delta_e00
        )
    });
    let drift = &c.temporal_stability;
    let monotonicity = c
        .monotonicity
        .iter()
        .map(|m| format!("{}: {} reversals", m.channel, m.reversals_beyond_noise))
        .collect::<Vec<_>>()
        .join("; ");
    let rows: [(&str, &Verdict, String); 5] = [
        ("primary constancy", &c.primary_constancy_verdict, constancy),
        ("additivity", &c.additivity_verdict, additivity),
        (
            "spatial independence",
            &c.spatial_independence_verdict,
            surround,
        ),
        (
            "temporal stability",
            &c.temporal_stability_verdict,
            format!(
                "{} references, drift {:.2} %{}; {}",
                drift.references,
                drift.amplitude_percent,
                if drift.corrected { ", corrected" } else { "" },
                drift.note
            ),
        ),
        ("monotonicity", &c.monotonicity_verdict, monotonicity),
    ];
    out.push_str("<table><tr><th>assumption</th><th>verdict</th><th>figures</th></tr>\n");
    for (assumption, verdict, figures) in rows {
        let class = if *verdict == Verdict::Fails {
            " class=\"fails\""
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td{class}>{}</td><td style=\"text-align:left\">{}</td></tr>",
            escape(assumption),
            escape(&verdict.to_string()),
            escape(&figures)
        );
    }
    out.push_str("</table>\n");
    let noise = &profile.report.noise;
    let _ = writeln!(
        out,
        "<p>Noise: {:.3} % of the reading ({}), floor {:.4} ({}).</p>",
        noise.relative * 100.0,
        escape(&noise.relative_from),
        noise.floor,
        escape(&noise.floor_from)
    );
    out.push_str("</section>\n");
}

fn calibration(out: &mut String, profile: &Profile) -> Result<(), ReportError> {
    let Some(stored) = &profile.calibration else {
        return Ok(());
    };
    out.push_str("<section id=\"calibration\"><h2>Calibration curves</h2>\n");
    let curves = stored.curves.curves.clone().map(|c| {
        let n = c.len().max(2) - 1;
        c.iter()
            .enumerate()
            .map(|(i, v)| (i as f64 / n as f64, *v))
            .collect::<Curve>()
    });
    let svg = figures::calibration(&curves)?;
    figure(
        out,
        "fig-calibration",
        &svg,
        &format!(
            "Curves to {} after {} measured passes: predicted white ΔE00 {:.3}, measured tone error {:.2} %.",
            stored.curves.describe(),
            stored.passes,
            stored.curves.predicted_white_de00,
            stored.measured_tone_error * 100.0
        ),
    );
    let rows: Vec<Vec<String>> = stored
        .levels
        .iter()
        .map(|l| {
            vec![
                format!("{:.3}", l.input),
                format!("{:.3}", l.target_luminance),
                format!("{:.3}", l.measured_luminance),
                format!(
                    "{:+.2} %",
                    (l.measured_luminance / l.target_luminance - 1.0) * 100.0
                ),
            ]
        })
        .collect();
    table(out, &["input", "target Y", "measured Y", "error"], &rows);
    out.push_str("</section>\n");
    Ok(())
}

fn history(out: &mut String, input: &ReportInput) -> Result<(), ReportError> {
    let Some(history) = &input.history else {
        return Ok(());
    };
    out.push_str("<section id=\"history\"><h2>History</h2>\n");
    if history.profiles.is_empty() && history.verifications.is_empty() {
        note(out, "The daemon has no history yet.");
        out.push_str("</section>\n");
        return Ok(());
    }
    let (errors, white, unit) = history.series();
    let since = format!("{unit} since the first");
    let svg = figures::over_time("ΔE00 over time", "mean ΔE00", &since, &errors)?;
    figure(
        out,
        "fig-history-error",
        &svg,
        "Each profile's held-out mean ΔE00 when it was made, and each verification's mean ΔE00 against the profile current then.",
    );
    let svg = figures::over_time("White luminance over time", "Y", &since, &white)?;
    figure(
        out,
        "fig-history-white",
        &svg,
        "The white luminance of each profile in the history (the profile's units).",
    );
    let rows: Vec<Vec<String>> = history
        .profiles
        .iter()
        .map(|p| {
            vec![
                p.id.clone(),
                p.how.clone(),
                p.held_out_mean.map_or("–".into(), |m| format!("{m:.3}")),
                p.white_luminance.map_or("–".into(), |y| format!("{y:.2}")),
            ]
        })
        .collect();
    table(out, &["profile", "how", "held-out mean", "white Y"], &rows);
    out.push_str("</section>\n");
    Ok(())
}
