//! The report's first section when the profile has been verified (`chromacal
//! verify`, or the verification that ends a calibration with a target): the display
//! as measured through what it holds, beside the native display the profile
//! describes ("before → after"), the criteria with their intervals and verdicts, the
//! tone curve against the target with the readings through the curves, the grey
//! balance, and every patch with its verdict.

use maud::{Markup, html};

use super::ReportError;
use super::figures::{self, Curve};
use super::markup::{note, signed, swatch_span};
use crate::profile::Profile;
use crate::verify::uniformity::{DELTA_UV_LIMIT, LEVELS, Uniformity};
use crate::verify::{GreyBalance, Metric, Verdict, VerifyReport, grey_chroma};
use chromacal_color::Xyz;
use chromacal_color::spaces::xyz_to_xyy;
use chromacal_color::temperature::xyz_to_cct_duv;
use chromacal_color::{delta_e_2000, xyz_to_lab};

/// The native display's grey balance, by the profile's model, at the inputs the
/// verification read.
fn native_greys(profile: &Profile, inputs: &[f64], metric: Metric) -> Vec<(f64, f64)> {
    let model = &profile.model;
    let white = model.white();
    inputs
        .iter()
        .map(|&x| {
            let grey = model.forward_centre([x; 3]);
            (x, grey_chroma(metric, &grey, &white).0)
        })
        .collect()
}

fn verdict_span(verdict: Verdict, id: Option<&str>) -> Markup {
    let class = match verdict {
        Verdict::Pass => "passes",
        Verdict::Fail => "fails",
        Verdict::Undecided => "undecided",
    };
    html! {
        @if let Some(id) = id { span class=(class) id=(id) { (verdict.name()) } }
        @else { span class=(class) { (verdict.name()) } }
    }
}

fn interval(i: [f64; 2]) -> String {
    format!("[{:.3}, {:.3}]", i[0], i[1])
}

/// The section.
pub fn calibrated(profile: &Profile, v: &VerifyReport) -> Result<Markup, ReportError> {
    let s = &v.state;
    let model = &profile.model;
    let native_white = model.white();
    let native_xy = xyz_to_xyy(&native_white, [0.3127, 0.3290]);
    let native_t = xyz_to_cct_duv(&native_white);
    let target = Xyz::from(s.target_white);
    let native_to_target = delta_e_2000(
        &xyz_to_lab(&native_white, &target),
        &xyz_to_lab(&target, &target),
    );
    let native_contrast = (model.black.y > 0.0).then(|| native_white.y / model.black.y);
    let grey_inputs: Vec<f64> = s
        .tone
        .iter()
        .map(|t| t.input)
        .filter(|x| *x < 1.0)
        .collect();
    let native = native_greys(profile, &grey_inputs, v.metric);
    let native_grey_mean = if native.is_empty() {
        0.0
    } else {
        native.iter().map(|g| g.1).sum::<f64>() / native.len() as f64
    };
    let unit = profile.units.to_string();
    let cct = |t: Option<f64>| t.map_or("–".into(), |k| format!("{k:.0} K"));
    let duv = |d: Option<f64>| d.map_or("–".into(), |d| format!("{d:+.4}"));
    let contrast = |c: Option<f64>| c.map_or("–".into(), |c| format!("{c:.0}:1"));
    let metric = v.metric.name();
    // The tone curve: the target's and the readings through the curves, relative to
    // the white above black, on log axes; the native model beside them.
    let span = (s.luminance - s.black_luminance).max(f64::MIN_POSITIVE);
    let measured: Curve = s
        .tone
        .iter()
        .map(|t| (t.input, (t.measured - s.black_luminance) / span))
        .collect();
    let target_curve: Curve = s
        .tone
        .iter()
        .map(|t| (t.input, (t.target - s.black_luminance) / span))
        .collect();
    let native_span = native_white.y - model.black.y;
    let native_curve: Curve = (1..=100)
        .map(|i| {
            let d = i as f64 / 100.0;
            (
                d,
                (model.forward_centre([d; 3]).y - model.black.y) / native_span,
            )
        })
        .collect();
    let tone = figures::tone_log(&measured, &native_curve, Some(("target", &target_curve)))?;
    // The greys in order of lightness, placed by their luminance's 2.2 root.
    let mut greys: Vec<&GreyBalance> = s.greys.iter().collect();
    greys.sort_by(|a, b| a.luminance.total_cmp(&b.luminance));
    let level = |g: &GreyBalance| (g.luminance / s.luminance).max(0.0).powf(1.0 / 2.2);
    let a: Curve = greys.iter().map(|g| (level(g), g.a)).collect();
    let b: Curve = greys.iter().map(|g| (level(g), g.b)).collect();
    let duv_curve: Curve = greys
        .iter()
        .map(|g| (level(g), 1000.0 * g.delta_uv))
        .collect();
    let balance = figures::grey_balance(&a, &b, &duv_curve)?;
    Ok(html! {
        section #calibrated {
            h2 { "The calibrated display" }
            p {
                "Measured through what the display holds now (chart " (v.chart) ", " (v.readings)
                " readings), set against " (v.against) ". Criteria: " (v.criteria) ". Verdict: "
                (verdict_span(v.verdict, Some("calibrated-verdict"))) ". Every figure comes with its 95 % interval, from this session's repeats of the white and the black."
            }
            @if let Some(warning) = &v.uncorrected { p.note #verify-uncorrected { "Warning: " (warning) } }
            // Whether the chart went through the calibration's measured greys, as
            // `lut3d`, `render` and the ICC export do (`Profile::output_model`).
            @if let Some(greys) = &v.greys { p.note #verify-greys { "The chart's codes as lut3d, render and the ICC export make them: " (greys) "." } }
            table #before-after {
                tr { th { "" } th { "native (the profile)" } th { "calibrated (measured)" } th { "" } }
                tr { th { "white luminance" } td { (format!("{:.2}", native_white.y)) } td #cal-luminance { (format!("{:.2}", s.luminance)) } td.text { (unit) } }
                tr { th { "white x, y" } td { (format!("{:.4}, {:.4}", native_xy.x, native_xy.y)) } td #cal-xy { (format!("{:.4}, {:.4}", s.xy[0], s.xy[1])) } td.text { "CIE 1931" } }
                tr { th { "correlated colour temperature" } td { (cct(native_t.map(|t| t.cct_k))) } td #cal-cct { (cct(s.cct_k)) } td.text { "CIE 15:2004 §9.5" } }
                tr { th { "Duv" } td { (duv(native_t.map(|t| t.duv))) } td #cal-duv { (duv(s.duv)) } td.text { "from the Planckian locus" } }
                tr {
                    th { "white against the target" }
                    td { (format!("{native_to_target:.3}")) }
                    td #cal-white-de { (format!("{:.3}", s.white_delta_e)) }
                    td.text { (metric) " " (interval(s.white_interval)) }
                }
                tr { th { "black luminance" } td { (format!("{:.4}", model.black.y)) } td #cal-black { (format!("{:.4}", s.black_luminance)) } td.text { (unit) } }
                tr { th { "contrast ratio" } td { (contrast(native_contrast)) } td #cal-contrast { (contrast(s.contrast)) } td.text { "" } }
                tr {
                    th { "grey balance, mean chroma" }
                    td { (format!("{native_grey_mean:.2}")) }
                    td #cal-grey-balance { (format!("{:.2}", s.grey_balance_mean)) }
                    td.text { (if v.metric == Metric::Itp { "CtCp" } else { "|ΔC′00|" }) " over " (greys.len()) " greys of ≥ 1 % luminance, against the white" }
                }
                tr { th { "grey balance, a* and b* range" } td { "" } td #cal-grey-range { (format!("{:.2}", s.grey_balance_range)) } td.text { "" } }
                tr { th { "tone curve, largest miss" } td { "" } td #cal-tone { (format!("{:.1} %", 100.0 * s.tone_error)) } td.text { "of the target luminance, over the calibration greys" } }
            }
            h3 { "Criteria" }
            table #criteria {
                tr { th { "criterion" } th { "limit" } th { "value" } th { "95 % interval" } th { "verdict" } }
                @for (k, r) in v.results.iter().enumerate() {
                    tr {
                        td.text { (r.description) }
                        td { (r.limit) }
                        td { (format!("{:.3}", r.value)) }
                        td { (interval(r.interval)) }
                        td { (verdict_span(r.verdict, Some(&format!("criterion-{k}")))) }
                    }
                }
            }
            div.figures { (maud::PreEscaped(tone)) (maud::PreEscaped(balance)) }
            p.note { "Tone: the target (line), the readings through the curves (points) and the native display (the profile's model), relative to the white above black. Grey balance: a*, b* and 1000 Δu′v′ of each grey against the measured white." }
            h3 { "Patches" }
            table #verify-patches {
                tr {
                    th { "patch" } th { "codes" } th { "reference" } th { "measured" }
                    th { "reference L* a* b*" } th { "measured L* a* b*" }
                    th { (metric) } th { "95 % interval" } th { (metric) " to the profile" } th { "verdict" }
                }
                @for p in &v.patches {
                    tr {
                        td.text { (p.label) @if p.outside { " (outside the gamut)" } @if p.reads > 1 { " ×" (p.reads) } }
                        td { (format!("{}, {}, {}", p.codes[0], p.codes[1], p.codes[2])) }
                        td { (swatch_span(&Xyz::from(p.reference), &target)) }
                        td { (swatch_span(&Xyz::from(p.measured), &target)) }
                        td { (format!("{:.2} {} {}", p.reference_lab[0], signed(p.reference_lab[1], 2), signed(p.reference_lab[2], 2))) }
                        td { (format!("{:.2} {} {}", p.lab[0], signed(p.lab[1], 2), signed(p.lab[2], 2))) }
                        td.de { (format!("{:.3}", p.delta_e)) }
                        td { (interval(p.interval)) }
                        td { (format!("{:.3}", p.delta_e_to_profile)) }
                        td { @match p.verdict { Some(verdict) => (verdict_span(verdict, None)), None => "–" } }
                    }
                }
            }
            @if v.patches.iter().any(|p| p.outside) {
                (note("Patches outside the gamut ask for a colour the display cannot show: their reference is the nearest colour it can show (clipped, as a colour-managed application asks for it), so their ΔE is what the calibration and the profile miss, not the gamut."))
            }
            @if let Some(u) = &v.uniformity { (uniformity(u)) }
        }
    })
}

/// The uniformity grid, one table a level: each position's luminance against the
/// centre's and its Δu′v′ from the centre's chromaticity, with its verdict.
fn uniformity(u: &Uniformity) -> Markup {
    let at = |row: usize, column: usize, level: f64| {
        u.points
            .iter()
            .find(|p| p.row == row && p.column == column && p.level == level)
    };
    html! {
        h3 { "Uniformity" }
        p {
            "White, grey and dark grey read on a " (u.grid) " × " (u.grid)
            " grid and set against the centre, by ISO 12646's tolerances (luminance within 10, 13 and 15 %, 5, 6.5 and 7.5 % recommended; Δu′v′ within "
            (DELTA_UV_LIMIT) "). Verdict: " (verdict_span(u.verdict, Some("uniformity-verdict")))
            @if u.recommended { ", within the recommended tolerances too" } "."
        }
        @for (k, &(level, limit, _)) in LEVELS.iter().enumerate() {
            table.uniformity id=(format!("uniformity-grid-{k}")) {
                caption { (format!("{:.0} % grey: luminance against the centre (≤ {:.0} %) and Δu′v′", 100.0 * level, 100.0 * limit)) }
                @for row in 0..u.grid {
                    tr {
                        @for column in 0..u.grid {
                            @match at(row, column, level) {
                                Some(p) => td title=(format!("95 % interval {:+.1} to {:+.1} %", 100.0 * p.luminance_interval[0], 100.0 * p.luminance_interval[1])) {
                                    (format!("{:+.1} %", 100.0 * p.luminance_deviation)) br;
                                    (format!("{:.4}", p.delta_uv)) " " (verdict_span(p.verdict, None))
                                },
                                None => td.text { "centre" },
                            }
                        }
                    }
                }
            }
        }
    }
}
