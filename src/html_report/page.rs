//! The report page: sections in the order a reader checks a calibration (who and what
//! it cost; the verification: patches, white and contrast, gamut, greys; then the
//! model: curves, primaries, the screen, the error, the assumptions), each a heading,
//! a figure or two and the table behind them.
//!
//! The page is a `maud` template: every value put in it is escaped unless it is
//! marked as markup (`PreEscaped`), which only the figures' SVG is.

use maud::{DOCTYPE, Markup, PreEscaped, html};

use super::figures::{self, Curve};
use super::markup::{facts, figure, note, signed, swatch_span, table};
use super::{
    ReportError, ReportInput, candidate_curve, chromaticities, measured_greys, measured_shares,
    sampled, smallest_drive, uniformity_data,
};
use crate::profile::Profile;
use crate::verification::{PatchUse, Verification, verify};
use chromacal_color::spaces::xyz_to_xyy;
use chromacal_model::CHANNELS;
use chromacal_model::fit::checks::Verdict;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::spatial::SpatialMap;
use chromacal_model::transfer::LawKind;

const STYLE: &str = "
body { font-family: sans-serif; max-width: 1100px; margin: 1.5em auto; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child, td.text { text-align: left; }
th { background: #f4f4f4; }
tr.fit td { color: #888; }
figure { display: inline-block; margin: 0.4em; vertical-align: top; }
figure svg { max-width: 100%; height: auto; }
figcaption { font-size: 0.85em; color: #555; max-width: 520px; }
.swatch { display: inline-block; width: 2.2em; height: 1.2em; border: 1px solid #888; vertical-align: middle; }
.note { color: #6a4a00; background: #fff8e0; padding: 0.3em 0.6em; border-left: 3px solid #e0b000; }
.fails { color: #a00; font-weight: bold; }
.passes { color: #060; font-weight: bold; }
@media print { body { max-width: none; } section { break-inside: avoid; } figure { break-inside: avoid; } }
";

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
        // Small values (a curved PQ law's toe, 10⁻⁵ of the peak's light) in
        // scientific notation, not as 0.0000.
        _ if value != 0.0 && value.abs() < 1e-3 => format!("{name} {value:.3e}"),
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

/// The verification of the profile: against the readings measured to verify it, or
/// else its own readings with the held-out patches judged; `None` without readings.
fn verification_of(input: &ReportInput) -> Option<(Verification, String)> {
    let profile = input.profile;
    if let Some(set) = input.checked {
        let what = format!("the readings of {} measured to verify it", set.source);
        return Some((verify(&profile.model, set, None, &input.criteria), what));
    }
    let set = input.readings?;
    let held = &profile.report.held_out_patches;
    let what = format!(
        "the readings it was fitted on, judged on the {} patches held out of the fit (as the fit scored them, on its drift-corrected readings)",
        held.len()
    );
    Some((
        verify(&profile.model, set, Some(held), &input.criteria),
        what,
    ))
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
    let verification = verification_of(input);
    let verified = verification.as_ref().map(|(v, what)| (v, what.as_str()));
    let calibrated = match input.verified {
        Some(v) => super::calibrated::calibrated(profile, v)?,
        None => html! {},
    };
    let sections = [
        calibrated,
        identity(profile),
        summary(profile, verified),
        super::hdr::hdr(profile)?,
        patches(verified.map(|v| v.0)),
        greys(profile, verified.map(|v| v.0))?,
        transfer(input)?,
        laws(profile),
        primaries(input)?,
        gamut(verified.map(|v| v.0)),
        uniformity(input, verified.map(|v| v.0))?,
        held_out(profile)?,
        checks(profile),
        calibration(profile)?,
        history(input)?,
    ];
    let device = input.device.as_deref();
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title {
                    "chromacal report: " @if let Some(d) = device { "device " (d) ", " }
                    (display) " (" (profile.id) ")"
                }
                style { (PreEscaped(STYLE)) }
            }
            body {
                @if device.is_some() { p { a href="/" { "← all devices" } } }
                h1 { "Calibration report: " @if let Some(d) = device { "device " (d) ", " } (display) }
                @for section in &sections { (section) }
                footer { p { "Made by " (profile.provenance.program) " from profile " (profile.id) "." } }
            }
        }
    };
    Ok(page.into_string())
}

fn identity(profile: &Profile) -> Markup {
    let p = &profile.provenance;
    let c = &profile.report.counts;
    let mut rows: Vec<(&str, String)> = vec![
        ("profile", profile.id.clone()),
        ("made", profile.created.clone()),
        ("display", p.display.clone().unwrap_or("–".into())),
        (
            "instrument",
            p.instrument
                .as_ref()
                .map_or("–".into(), |i| match &i.serial {
                    Some(s) => format!("{} (serial {s})", i.name),
                    None => i.name.clone(),
                }),
        ),
        (
            "readings taken",
            p.measured_at
                .clone()
                .unwrap_or_else(|| "– (not said in the file)".into()),
        ),
        ("readings from", p.source.clone()),
        ("units", profile.units.to_string()),
        (
            "readings",
            format!(
                "{} ({} usable; {} in the fit's kinds, {} held out, {} uniformity)",
                c.readings, c.usable, c.budget_readings, c.held_out, c.uniformity
            ),
        ),
    ];
    match &profile.cost {
        Some(cost) => {
            rows.push((
                "instrument time",
                cost.instrument_s
                    .map_or("not recorded in the file".into(), seconds),
            ));
            rows.push(("fit time", seconds(cost.fit_s)));
        }
        None => rows.push((
            "cost",
            "not recorded (a profile made before chromacal recorded it)".into(),
        )),
    }
    if let Some(c) = &p.correction {
        rows.push(("correction", c.describe()));
    }
    rows.push(("program", p.program.clone()));
    html! {
        section #identity {
            h2 { "Run and cost" }
            (facts(&rows))
            @if let Some(why) = &profile.report.luminance_only { (note(why)) }
            @if let Some(warning) = &p.uncorrected { p.note #uncorrected { "Warning: " (warning) } }
        }
    }
}

/// The verdict against the criteria, the white, the black and the contrast.
fn summary(profile: &Profile, verified: Option<(&Verification, &str)>) -> Markup {
    let Some((v, what)) = verified else {
        return html! {
            section #verification {
                h2 { "Verification" }
                (note("Without the readings nothing can be verified: give them with --readings, or measure a verification set and run `chromacal check --report`."))
            }
        };
    };
    let j = &v.judgement;
    let w = &v.white;
    let unit = profile.units.to_string();
    let judged = v.patches.iter().filter(|p| p.judged).count();
    let white_from = if w.white_measured {
        "measured"
    } else {
        "the model's (no white reading)"
    };
    let black_from = if w.black_measured {
        "measured"
    } else {
        "the model's (no black reading)"
    };
    html! {
        section #verification {
            h2 { "Verification" }
            p { "Of " (what) ". Criteria: " (j.criteria.describe()) "." }
            @match &j.stats {
                Some(s) => p {
                    (judged) " patches judged: mean ΔE00 "
                    span #judged-mean { (format!("{:.3}", s.mean)) }
                    ", 95th percentile " (format!("{:.3}", s.p95))
                    ", max " (format!("{:.3}", s.max))
                    @if let Some(i) = &j.itp {
                        "; mean ΔE ITP " span #judged-itp { (format!("{:.3}", i.mean)) }
                    }
                    "; " (j.failing_patches) " above the patch limit. "
                    @if j.passes { span.passes #verdict { "Passes." } }
                    @else { span.fails #verdict { "Fails." } }
                },
                None => (note(if v.patches.is_empty() {
                    "No patch to judge: the readings hold none that can be scored."
                } else {
                    "No patch to judge: every reading was in the fit."
                })),
            }
            @if v.unscorable > 0 {
                (note(&format!("{} readings are left out: their ΔE00 cannot be computed (a value out of all range).", v.unscorable)))
            }
            h3 { "White, black and contrast" }
            table {
                tr { th { "white luminance" } td #white-luminance { (format!("{:.2}", w.white.y)) } td.text { (unit) ", " (white_from) } }
                tr { th { "white x, y" } td #white-xy { (format!("{:.4}, {:.4}", w.white_xy[0], w.white_xy[1])) } td.text { "CIE 1931" } }
                tr {
                    th { "correlated colour temperature" }
                    td #white-cct { (w.temperature.map_or("–".into(), |t| format!("{:.0} K", t.cct_k))) }
                    td.text { "nearest Planckian point in CIE 1960 u, v (CIE 15:2004 §9.5)" }
                }
                tr {
                    th { "Duv" }
                    td #white-duv { (w.temperature.map_or("–".into(), |t| format!("{:+.4}", t.duv))) }
                    td.text { "distance from the Planckian locus, positive above it" }
                }
                tr { th { "black luminance" } td #black-luminance { (format!("{:.4}", w.black.y)) } td.text { (unit) ", " (black_from) } }
                tr {
                    th { "contrast ratio" }
                    td #contrast { (w.contrast.map_or("–".into(), |c| format!("{c:.0}:1"))) }
                    td.text { "white luminance over black luminance" }
                }
            }
        }
    }
}

/// Every patch: nominal (the profile's prediction) and measured, side by side.
fn patches(verified: Option<&Verification>) -> Markup {
    let Some(v) = verified else {
        return html! {};
    };
    let white = v.white.white;
    let lab =
        |l: &chromacal_color::Lab| format!("{:.2} {} {}", l.l, signed(l.a, 2), signed(l.b, 2));
    html! {
        section #patches {
            h2 { "Patches" }
            p {
                "Every usable reading against what the profile predicts for its drive (the nominal), in CIELAB against the model's white: "
                "ΔL*, ΔC*ab and ΔH*ab (CIE 15:2004 §8.2.2, measured less nominal) and ΔE00. "
                "Patches in the fit are shown grey and not judged"
                @if v.judgement.criteria.max_patch.is_finite() {
                    "; the result is against the patch limit of " (v.judgement.criteria.max_patch)
                }
                "."
            }
            table #patch-table {
                tr {
                    th { "patch" } th { "use" } th { "drive R, G, B" } th { "nominal" } th { "measured" }
                    th { "nominal L* a* b*" } th { "measured L* a* b*" }
                    th { "ΔL*" } th { "ΔC*" } th { "ΔH*" } th { "ΔE00" } th { "result" }
                }
                @for p in &v.patches {
                    tr.fit[p.used == PatchUse::Fit] data-patch=(p.index) {
                        td { (p.index) }
                        td.text { (p.used.name()) }
                        td { (format!("{:.3}, {:.3}, {:.3}", p.drive[0], p.drive[1], p.drive[2])) }
                        td { (swatch_span(&p.nominal, &white)) }
                        td { (swatch_span(&p.measured, &white)) }
                        td { (lab(&p.nominal_lab)) }
                        td { (lab(&p.measured_lab)) }
                        td { (signed(p.delta_l, 2)) }
                        td { (signed(p.delta_c, 2)) }
                        td { (signed(p.delta_h, 2)) }
                        td.de { (format!("{:.3}", p.delta_e00)) }
                        @if !p.judged { td { "–" } }
                        @else if p.passes { td.text.passes { "pass" } }
                        @else { td.text.fails { "fail" } }
                    }
                }
            }
        }
    }
}

/// The tone response on log axes and the grey balance along the grey ramp.
fn greys(profile: &Profile, verified: Option<&Verification>) -> Result<Markup, ReportError> {
    let Some(v) = verified.filter(|v| !v.greys.is_empty()) else {
        return Ok(html! {});
    };
    let measured: Curve = v.greys.iter().map(|g| (g.drive, g.relative)).collect();
    let model = &profile.model;
    let span = model.white().y - model.black.y;
    let model_curve: Curve = (1..=200)
        .map(|i| {
            let d = i as f64 / 200.0;
            (d, (model.forward_centre([d; 3]).y - model.black.y) / span)
        })
        .collect();
    let target: Option<Curve> = profile.calibration.as_ref().and_then(|c| {
        let black = c.levels.iter().find(|l| l.input == 0.0)?.target_luminance;
        let white = c.levels.iter().find(|l| l.input == 1.0)?.target_luminance;
        (white > black).then(|| {
            c.levels
                .iter()
                .map(|l| (l.input, (l.target_luminance - black) / (white - black)))
                .collect()
        })
    });
    let tone = figures::tone_log(
        &measured,
        &model_curve,
        target.as_ref().map(|t| ("calibration target", t)),
    )?;
    let a: Curve = v.greys.iter().map(|g| (g.drive, g.a)).collect();
    let b: Curve = v.greys.iter().map(|g| (g.drive, g.b)).collect();
    let duv: Curve = v
        .greys
        .iter()
        .map(|g| (g.drive, 1000.0 * g.delta_uv))
        .collect();
    let balance = figures::grey_balance(&a, &b, &duv)?;
    let gamma = |g: Option<f64>| g.map_or("–".into(), |g| format!("{g:.3}"));
    let rows: Vec<Vec<String>> = v
        .greys
        .iter()
        .map(|g| {
            vec![
                format!("{:.3}", g.drive),
                format!("{:.4}", g.luminance),
                format!("{:.5}", g.relative),
                format!("{:.5}", g.model_relative),
                gamma(g.effective_gamma),
                gamma(g.model_effective_gamma),
                signed(g.a, 2),
                signed(g.b, 2),
                format!("{:.4}", g.delta_uv),
                g.temperature
                    .map_or("–".into(), |t| format!("{:.0} K", t.cct_k)),
            ]
        })
        .collect();
    Ok(html! {
        section #greys {
            h2 { "Tone response and grey balance" }
            (figure("fig-tone", &tone, "The greys' luminance above black, relative to the white's, against drive on log–log axes: a power law is a straight line whose slope is its exponent, and the dark end is spread out."))
            (figure("fig-grey-balance", &balance, "Each grey's a* and b* against the white, and its distance from the white's chromaticity: a neutral ramp stays at zero."))
            (table(&["drive", "Y", "relative", "model relative", "effective gamma", "model's", "a*", "b*", "Δu′v′", "CCT"], &rows))
            p { "Effective gamma is ln(relative) / ln(drive), the exponent of the power law through that grey, with luminance taken above black." }
        }
    })
}

/// How a channel's law is named on its panel: the law the selection chose, and, when
/// a correction at the measured levels or codes turned it into a table, that too.
fn law_title(profile: &Profile, channel: usize) -> (String, Option<LawKind>) {
    let law = &profile.model.laws[channel];
    let chosen = profile.report.chosen_law();
    match chosen {
        Some(kind) if kind != LawKind::Table && law.kind() == LawKind::Table => {
            let how = match (
                &profile.report.code_correction,
                &profile.report.law_correction,
            ) {
                (Some(c), _) if c.kept => "corrected at the measured codes",
                _ => "corrected at the measured levels",
            };
            (format!("{kind}, {how}"), Some(kind))
        }
        _ => (law.kind().to_string(), None),
    }
}

fn transfer(input: &ReportInput) -> Result<Markup, ReportError> {
    let profile = input.profile;
    let model = &profile.model;
    let chosen_kind = profile.report.chosen_law();
    let mut residuals: [Curve; 3] = Default::default();
    let mut panels = Vec::new();
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
        let (title, corrected) = law_title(profile, channel);
        let candidate = |kind: LawKind, params: &[chromacal_model::fit::laws::FittedParameter]| {
            candidate_curve(kind, params, toe)
        };
        let candidates: Vec<(String, Curve)> = profile
            .report
            .laws
            .iter()
            .filter_map(|l| {
                if Some(l.law) == chosen_kind {
                    // The chosen law as fitted, before its correction, when corrected.
                    corrected?;
                    let curve = candidate(l.law, &l.parameters[channel])?;
                    return Some((format!("{} before correction", l.law.name()), curve));
                }
                Some((
                    l.law.name().to_string(),
                    candidate(l.law, &l.parameters[channel])?,
                ))
            })
            .collect();
        residuals[channel] = measured
            .iter()
            .map(|&(v, share)| (v, share - law.excitation(v)))
            .collect();
        let svg = figures::transfer(
            channel,
            &format!("{name}: {title}"),
            (&title, &sampled(law)),
            &candidates,
            &measured,
        )?;
        let params: Vec<String> = law
            .parameters()
            .iter()
            .map(|(n, v)| parameter(n, *v))
            .collect();
        panels.push(figure(
            &format!("fig-transfer-{name}"),
            &svg,
            &format!(
                "{name}: the chosen law ({title}; {}), the other candidates dashed, and the {} single-channel readings at the centre.",
                params.join(", "),
                measured.len()
            ),
        ));
    }
    let mut extra = Vec::new();
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
        extra.push(figure(
            "fig-greys",
            &svg,
            &format!(
                "{} greys against the whole model (matrix, laws and any terms kept): where the greys leave the line, additivity fails.",
                greys.len()
            ),
        ));
        let svg = figures::residuals(&residuals)?;
        extra.push(figure(
            "fig-residuals",
            &svg,
            "Each single-channel reading's share of full drive less the chosen law's.",
        ));
    }
    Ok(html! {
        section #transfer {
            h2 { "Transfer curves" }
            @if let Some(why) = &input.readings_note { (note(why)) }
            @for p in &panels { (p) }
            @for p in &extra { (p) }
        }
    })
}

fn laws(profile: &Profile) -> Markup {
    let r = &profile.report;
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
    let terms: Vec<Vec<String>> = r
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
    let kept = |k: bool| if k { "kept" } else { "not kept" };
    html! {
        section #laws {
            h2 { "Law selection" }
            p { (r.law_rule) }
            (table(&["law", "CV mean ΔE00", "p95", "max", "greys mean", "parameters"], &rows))
            @if !terms.is_empty() {
                p { (r.terms_rule) }
                (table(&["terms", "CV mean ΔE00", "p95", "max"], &terms))
            }
            @if let Some(c) = &r.law_correction {
                p {
                    "Correction of the " (c.law) " law at the measured levels: CV mean "
                    (stats_cells(c.law_cv.as_ref())[0]) " alone, " (stats_cells(c.corrected_cv.as_ref())[0])
                    " corrected; " (kept(c.kept)) ". " (c.rule)
                }
            }
            @if let Some(c) = &r.code_correction {
                p {
                    "Correction at the measured codes (" (c.codes) " codes, " (c.replicates)
                    " measured both as a ramp reading and as a grey): replicates predicted with mean ΔE00 "
                    (stats_cells(c.uncorrected.as_ref())[0]) " uncorrected, " (stats_cells(c.corrected.as_ref())[0])
                    " corrected; " (kept(c.kept)) ". " (c.rule)
                }
            }
        }
    }
}

fn primaries(input: &ReportInput) -> Result<Markup, ReportError> {
    let profile = input.profile;
    let data = chromaticities(&profile.model, input.readings);
    let svg = figures::chromaticity(&data)?;
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
    for (name, xyz, digits) in [("white", model.white(), 3), ("black", model.black, 4)] {
        let xyy = xyz_to_xyy(&xyz, [0.3127, 0.3290]);
        rows.push(vec![
            name.into(),
            format!("{:.4}", xyy.x),
            format!("{:.4}", xyy.y),
            format!("{:.digits$}", xyy.big_y),
            "".into(),
        ]);
    }
    let edid = profile
        .provenance
        .edid
        .as_ref()
        .zip(profile.edid_comparison());
    Ok(html! {
        section #primaries {
            h2 { "Primaries and white" }
            (figure("fig-chromaticity", &svg, "The display's primaries (circles) and white (cross), each channel's chromaticity at every measured level (dots; a spread shows chromaticity that moves with drive), with sRGB, Adobe RGB, Display P3 and Rec. 2020 for scale."))
            (table(&["", "x", "y", "Y", "levels"], &rows))
            p { "Condition number of the primary matrix: " (format!("{:.2}", profile.report.condition_number)) "." }
            @if let Some((edid, comparison)) = edid {
                h3 #edid { "What the monitor's EDID states" }
                p { (edid.describe()) }
                (table(&["", "EDID xy", "measured xy", "apart"], &comparison.table_rows()))
                @if comparison.mismatch() {
                    (note(&format!("The EDID's chromaticities are up to {:.3} from the measured ones: is this the display you meant?", comparison.worst)))
                }
            }
        }
    })
}

/// Coverage and relative volume of the reference spaces.
fn gamut(verified: Option<&Verification>) -> Markup {
    let Some(v) = verified.filter(|v| !v.gamut.is_empty()) else {
        return html! {};
    };
    let percent = |f: f64| format!("{:.1} %", 100.0 * f);
    html! {
        section #gamut {
            h2 { "Gamut" }
            p {
                "The model's colour solid in CIELAB (D50, each gamut relative to its own white, as an ICC profile's relative colorimetric rendering places it): "
                span #gamut-volume { (v.volume.map_or("–".into(), |x| format!("{x:.0}"))) } " cubic ΔE*ab. "
                "Coverage is the share of the reference's volume the display reaches too; the u′v′ figures are the triangles of the chromaticity diagram above."
            }
            table {
                tr { th { "reference" } th { "coverage (CIELAB)" } th { "relative volume" } th { "coverage (u′v′ area)" } th { "relative area (u′v′)" } }
                @for g in &v.gamut {
                    tr data-reference=(g.reference) {
                        td { (g.reference) }
                        td.coverage { (percent(g.coverage)) }
                        td { (percent(g.relative_volume)) }
                        td.uv-coverage { (percent(g.uv_coverage)) }
                        td { (percent(g.uv_relative_area)) }
                    }
                }
            }
        }
    }
}

fn uniformity(input: &ReportInput, verified: Option<&Verification>) -> Result<Markup, ReportError> {
    let profile = input.profile;
    let spatial = &profile.report.spatial;
    let (surface, points) = uniformity_data(&profile.model, input.readings);
    let map = if points.is_empty() && profile.model.spatial == SpatialMap::Uniform {
        note(&format!(
            "No uniformity grid was measured{}: the model is uniform over the screen.",
            if spatial.positions > 0 {
                " that the page can show"
            } else {
                ""
            }
        ))
    } else {
        let svg = figures::uniformity(&surface, &points)?;
        figure(
            "fig-uniformity",
            &svg,
            &format!(
                "The spatial map kept ({}) as light relative to the centre, with the {} measured positions (percent of the centre's light).",
                profile.model.spatial.describe(),
                points.len()
            ),
        )
    };
    let unseen = (spatial.unseen > 0).then(|| {
        note(&format!(
            "{} grid reading(s) under {:.0} % of the centre's light were left out of the spatial map: the instrument did not see the patch there (a real instrument has to be moved to each position: --prompt-positions). The table below shows them as read.",
            spatial.unseen,
            100.0 * chromacal_model::fit::spatial::MIN_PLAUSIBLE_GAIN
        ))
    });
    let cells = verified
        .map(|v| v.uniformity.as_slice())
        .unwrap_or_default();
    let drive = |d: [f64; 3]| match d {
        [1.0, 1.0, 1.0] => "white".to_string(),
        [1.0, 0.0, 0.0] => "red".to_string(),
        [0.0, 1.0, 0.0] => "green".to_string(),
        [0.0, 0.0, 1.0] => "blue".to_string(),
        d => format!("{:.2}, {:.2}, {:.2}", d[0], d[1], d[2]),
    };
    let rows: Vec<Vec<String>> = cells
        .iter()
        .map(|c| {
            vec![
                format!("{:.3}, {:.3}", c.position.x, c.position.y),
                drive(c.drive),
                format!("{:.1} %", c.luminance_percent),
                format!("{:.4}", c.delta_uv),
                format!("{:.2}", c.delta_e00),
            ]
        })
        .collect();
    let worst = |f: fn(&crate::verification::UniformityCell) -> f64| {
        cells.iter().map(f).fold(0.0_f64, f64::max)
    };
    let candidates: Vec<Vec<String>> = spatial
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
    Ok(html! {
        section #uniformity {
            h2 { "Uniformity" }
            @if let Some(unseen) = unseen {
                (unseen)
            }
            (map)
            @if !rows.is_empty() {
                p {
                    "Each measured position against the centre at the same drive, as ISO 12646 and DisplayCAL's uniformity report compare them: luminance, Δu′v′, and ΔE00 in CIELAB relative to the centre's reading. "
                    "Worst: Δu′v′ " span #uniformity-worst-uv { (format!("{:.4}", worst(|c| c.delta_uv))) }
                    ", ΔE00 " (format!("{:.2}", worst(|c| c.delta_e00))) "."
                }
                (table(&["position x, y", "drive", "luminance of the centre's", "Δu′v′", "ΔE00"], &rows))
            }
            @if !candidates.is_empty() {
                (table(&["map", "CV mean ΔE00", "p95", "max", "note"], &candidates))
            }
        }
    })
}

fn held_out(profile: &Profile) -> Result<Markup, ReportError> {
    let r = &profile.report;
    let Some(stats) = &r.held_out else {
        return Ok(html! {
            section #held-out {
                h2 { "Error on patches held out of the fit" }
                (note("No patch was held out of the fit, so there is no honest error to show."))
            }
        });
    };
    let values: Vec<f64> = r.held_out_patches.iter().map(|p| p.delta_e00).collect();
    let svg = figures::histogram(&values, "Held-out ΔE00")?;
    let white = profile.model.white();
    let mut worst: Vec<_> = r.held_out_patches.iter().collect();
    worst.sort_by(|a, b| b.delta_e00.total_cmp(&a.delta_e00));
    Ok(html! {
        section #held-out {
            h2 { "Error on patches held out of the fit" }
            (figure("fig-held-out", &svg, &format!(
                "{} patches held out of every fit: mean ΔE00 {:.3}, p95 {:.3}, max {:.3}.",
                stats.n, stats.mean, stats.p95, stats.max
            )))
            h3 { "Worst patches" }
            table {
                tr { th { "patch" } th { "drive R, G, B" } th { "measured" } th { "predicted" } th { "ΔE00" } }
                @for p in worst.iter().take(10) {
                    tr {
                        td { (p.index) }
                        td { (format!("{:.3}, {:.3}, {:.3}", p.drive[0], p.drive[1], p.drive[2])) }
                        td { (swatch_span(&p.measured, &white)) }
                        td { (swatch_span(&p.predicted, &white)) }
                        td { (format!("{:.3}", p.delta_e00)) }
                    }
                }
            }
        }
    })
}

fn checks(profile: &Profile) -> Markup {
    let c = &profile.report.checks;
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
    let noise = &profile.report.noise;
    html! {
        section #checks {
            h2 { "Assumption checks" }
            table {
                tr { th { "assumption" } th { "verdict" } th { "figures" } }
                @for (assumption, verdict, figures) in &rows {
                    tr {
                        td { (assumption) }
                        td.fails[**verdict == Verdict::Fails] { (verdict.to_string()) }
                        td style="text-align:left" { (figures) }
                    }
                }
            }
            p {
                "Noise: " (format!("{:.3}", noise.relative * 100.0)) " % of the reading (" (noise.relative_from)
                "), floor " (format!("{:.4}", noise.floor)) " (" (noise.floor_from) ")."
            }
        }
    }
}

fn calibration(profile: &Profile) -> Result<Markup, ReportError> {
    let Some(stored) = &profile.calibration else {
        return Ok(html! {});
    };
    let curves = stored.curves.curves.clone().map(|c| {
        let n = c.len().max(2) - 1;
        c.iter()
            .enumerate()
            .map(|(i, v)| (i as f64 / n as f64, *v))
            .collect::<Curve>()
    });
    let svg = figures::calibration(&curves)?;
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
    Ok(html! {
        section #calibration {
            h2 { "Calibration curves" }
            (figure("fig-calibration", &svg, &format!(
                "Curves to {} after {} measured passes.",
                stored.curves.describe(),
                stored.passes,
            )))
            p {
                "Measured through the curves: white ΔE00 "
                span #calibration-white-de00 { (format!("{:.2}", stored.measured_white_de00)) }
                " from the target white (the model predicted " (format!("{:.3}", stored.curves.predicted_white_de00))
                "), tone error up to " (format!("{:.2}", stored.measured_tone_error * 100.0)) " %."
            }
            (table(&["input", "target Y", "measured Y", "error"], &rows))
        }
    })
}

fn history(input: &ReportInput) -> Result<Markup, ReportError> {
    let Some(history) = &input.history else {
        return Ok(html! {});
    };
    if history.profiles.is_empty()
        && history.verifications.is_empty()
        && history.verifications_itp.is_empty()
    {
        return Ok(html! {
            section #history { h2 { "History" } (note("The daemon has no history yet.")) }
        });
    }
    let (errors, white) = history.series();
    let error_svg = figures::over_time("ΔE00 over time", "mean ΔE00", &errors)?;
    let white_svg = figures::over_time("White luminance over time", "Y", &white)?;
    let itp_svg = match history.verifications_itp.is_empty() {
        true => None,
        false => Some(figures::over_time(
            "ΔE ITP over time",
            "mean ΔE ITP",
            &[figures::TimeSeries {
                name: "verification mean (HDR)".into(),
                points: history.verifications_itp.clone(),
            }],
        )?),
    };
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
    Ok(html! {
        section #history {
            h2 { "History" }
            (figure("fig-history-error", &error_svg, "Each profile's held-out mean ΔE00 when it was made, and each verification's mean ΔE00 against the profile current then."))
            @if let Some(svg) = &itp_svg {
                (figure("fig-history-itp", svg, "Each verification of a profile of an HDR signal in the error it is judged by, mean ΔE ITP (BT.2124, on absolute light): the daemon's checks against the profile current then, and the charts measured through its curves against the signal's encoding."))
            }
            (figure("fig-history-white", &white_svg, "The white luminance of each profile in the history (the profile's units)."))
            (table(&["profile", "how", "held-out mean", "white Y"], &rows))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_that_rounds_to_zero_has_no_sign() {
        assert_eq!(signed(-0.001, 2), "0.00");
        assert_eq!(signed(0.004, 2), "0.00");
        assert_eq!(signed(-0.006, 2), "-0.01");
        assert_eq!(signed(1.5, 1), "+1.5");
    }
}
