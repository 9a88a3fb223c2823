//! Plain-text reports for people: the summary after a calibration or a fit, the
//! description of a profile, the result of a check.

use std::fmt::Write as _;

use crate::profile::Profile;
use chromacal_color::spaces::xyz_to_xyy;
use chromacal_model::fit::checks::Verdict;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::{Evaluation, delta_e_itp_stats};
use chromacal_model::fit::{FitReport, WhiteAnchor};
use chromacal_model::plan::BudgetBreakdown;
use chromacal_model::spatial::SpatialMap;
use chromacal_model::{CHANNELS, MonitorModel};

/// Columns aligned: the first to the left, the others to the right.
pub fn table(headers: &[&str], rows: &[Vec<String>]) -> String {
    let columns = headers.len();
    let mut widths: Vec<usize> = headers.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (i, cell) in row.iter().enumerate().take(columns) {
            widths[i] = widths[i].max(cell.chars().count());
        }
    }
    let line = |cells: Vec<&str>| -> String {
        let mut out = String::from("  ");
        for (i, cell) in cells.iter().enumerate() {
            let pad = widths[i].saturating_sub(cell.chars().count());
            if i == 0 {
                out.push_str(cell);
                out.push_str(&" ".repeat(pad));
            } else {
                out.push_str("  ");
                out.push_str(&" ".repeat(pad));
                out.push_str(cell);
            }
        }
        out.trim_end().to_string() + "\n"
    };
    let mut out = line(headers.to_vec());
    for row in rows {
        out.push_str(&line(row.iter().map(String::as_str).collect()));
    }
    out
}

fn stats_cells(s: Option<ErrorStats>) -> Vec<String> {
    match s {
        Some(s) => vec![
            format!("{:.3}", s.mean),
            format!("{:.3}", s.p95),
            format!("{:.3}", s.max),
        ],
        None => vec!["–".into(), "–".into(), "–".into()],
    }
}

/// "mean 0.043  p95 0.085  max 0.100 (24 patches)".
pub fn stats_line(s: &ErrorStats) -> String {
    format!(
        "mean {:.3}  p95 {:.3}  max {:.3}  ({} patches)",
        s.mean, s.p95, s.max, s.n
    )
}

/// Seconds as "5 min 02 s" or "1.8 s".
pub fn duration(seconds: f64) -> String {
    if seconds >= 60.0 {
        let s = seconds.round() as u64;
        if s >= 3600 {
            format!("{} h {:02} min", s / 3600, (s % 3600) / 60)
        } else {
            format!("{} min {:02} s", s / 60, s % 60)
        }
    } else if seconds >= 1.0 {
        format!("{seconds:.1} s")
    } else {
        format!("{:.1} ms", seconds * 1000.0)
    }
}

/// The budget line: what counts as measured.
pub fn budget_line(b: &BudgetBreakdown) -> String {
    let windows = if b.window > 0 {
        format!(" + {} windows", b.window)
    } else {
        String::new()
    };
    format!(
        "{} counted ({} black, {} levels × 3 ramps, {} grey, {} surround, {} reference) + {} held out + {} uniformity{windows} = {} patches",
        b.counted,
        b.black,
        b.ramp_levels_per_channel,
        b.grey,
        b.surround,
        b.reference,
        b.verification,
        b.uniformity,
        b.counted + b.verification + b.uniformity + b.window
    )
}

/// The part of a summary that any fit has: laws tried, spatial map, held-out error,
/// assumptions.
/// One line on how the model was anchored at the measured white.
pub fn white_anchor_line(w: &WhiteAnchor) -> String {
    let xyz = |v: &chromacal_color::Xyz| format!("{:.4} {:.4} {:.4}", v.x, v.y, v.z);
    let gains = format!("{:.4} {:.4} {:.4}", w.gains[0], w.gains[1], w.gains[2]);
    let how = if w.anchored {
        format!("the model made to pass through it (each channel's light × {gains})")
    } else {
        format!(
            "the model not made to pass through it ({}; it would take each channel's light × {gains})",
            w.note.as_deref().unwrap_or("-")
        )
    };
    format!(
        "white: measured XYZ {}, the fit gave {} ({:+.2} % in Y); every export is relative to the measured white; {how}",
        xyz(&w.measured),
        xyz(&w.predicted),
        (w.predicted.y / w.measured.y - 1.0) * 100.0
    )
}

/// For a profile of an HDR signal: the held-out error in ΔE ITP (ITU-R BT.2124, on
/// absolute light, where ΔE00's lightness relative to the white says little), and the
/// peak and black the model gives.
pub fn hdr_summary(profile: &Profile) -> String {
    let Some(signal) = profile.provenance.signal.filter(|s| s.is_hdr()) else {
        return String::new();
    };
    let mut out = format!(
        "HDR signal: {}; model peak {:.1} cd/m², black {:.4} cd/m²\n",
        signal.describe(),
        profile.model.white().y,
        profile.model.black.y
    );
    match delta_e_itp_stats(&profile.report.held_out_patches) {
        Some(s) => {
            let _ = writeln!(
                out,
                "held-out ΔE ITP (BT.2124, patches in no fit): {}",
                stats_line(&s)
            );
        }
        None => out.push_str("held-out ΔE ITP: no held-out patches\n"),
    }
    out
}

/// After a sequential run of an HLG signal whose held-out mixtures miss by more than
/// the default `[publish] max_mean_itp` (DisplayCAL's recommended mean for HDR): what
/// to measure instead. The OOTF through the laws is as right as each channel's law,
/// and a sequential plan spends its patches on greys, leaving a table law a few ramp
/// levels to follow a panel's knees with (docs/hdr.md, HDR LCDs of measured tables);
/// empty otherwise.
fn hlg_plan_hint(outcome: &crate::calibrate::session::CalibrationOutcome) -> String {
    let hlg = outcome.profile.provenance.signal == Some(chromacal_model::plan::Signal::Hlg);
    let missed = delta_e_itp_stats(&outcome.profile.report.held_out_patches)
        .filter(|s| s.mean > crate::config::PublishConfig::default().max_mean_itp);
    match missed {
        Some(s) if hlg && outcome.plan.sequential.is_some() => format!(
            "HLG: the held-out mixtures miss by {:.2} ΔE ITP on average. An HLG panel that is not a smooth law needs more ramp levels than a sequential plan measures: [plan] strategy = \"fixed\" with budget = 120 (33 levels a channel) took virtual LCDs of ISETBio's HP and Dell tables from 5.6 and 9.2 to 0.24–0.37 and 0.25–0.33 ΔE ITP (docs/hdr.md)\n",
            s.mean
        ),
        _ => String::new(),
    }
}

/// The brightness limiter: each window measured, as the additive model and as the
/// limiter fitted without it predict it, and whether the term was kept.
pub fn limiter_summary(l: &chromacal_model::fit::limiter::LimiterReport) -> String {
    let mut out = format!(
        "brightness limiter (windows of the screen on black; predicted with the limiter fitted without each): {}\n",
        match (&l.limiter, l.kept) {
            (Some(limiter), true) => format!(
                "kept: the screen's light is held to {:.1} cd/m² (knee {:.1})",
                limiter.full_field, limiter.sharpness
            ),
            (Some(_), false) => "not kept (the additive model)".into(),
            (None, _) => "none fits (the additive model)".into(),
        }
    );
    let rows: Vec<Vec<String>> = l
        .windows
        .iter()
        .map(|w| {
            vec![
                format!("{:.0} %", 100.0 * w.area),
                format!("{:.3}", w.level),
                format!("{:.2}", w.measured_y),
                format!("{:+.1} %", 100.0 * (w.additive_y / w.measured_y - 1.0)),
                format!("{:+.1} %", 100.0 * (w.left_out_y / w.measured_y - 1.0)),
            ]
        })
        .collect();
    out += &table(
        &["window", "level", "measured Y", "additive", "limiter"],
        &rows,
    );
    let _ = writeln!(out, "  rule: {}", l.rule);
    out
}

pub fn fit_summary(report: &FitReport) -> String {
    let mut out = String::new();
    let rows: Vec<Vec<String>> = report
        .laws
        .iter()
        .map(|l| {
            let mut row = vec![format!(
                "{}{}",
                l.law,
                if l.chosen { "  ← chosen" } else { "" }
            )];
            row.extend(stats_cells(l.cross_validation));
            row.extend(stats_cells(l.greys).into_iter().take(1));
            row
        })
        .collect();
    let _ = writeln!(
        out,
        "transfer laws (ΔE00 on readings each was not fitted on):"
    );
    out.push_str(&table(
        &["law", "CV mean", "CV p95", "CV max", "greys mean"],
        &rows,
    ));
    let _ = writeln!(out, "  rule: {}", report.law_rule);
    if let Some(c) = &report.law_correction {
        let mean =
            |s: Option<ErrorStats>| s.map_or("—".to_string(), |s| format!("{:.3}", s.mean));
        let _ = writeln!(
            out,
            "  correction at the measured levels: {} (CV mean {} alone, {} corrected; kept only if lower by more than two standard errors and than noise)",
            if c.kept { "kept" } else { "not kept" },
            mean(c.law_cv),
            mean(c.corrected_cv),
        );
    }
    if let Some(c) = &report.code_correction {
        let mean =
            |s: Option<ErrorStats>| s.map_or("—".to_string(), |s| format!("{:.3}", s.mean));
        let _ = writeln!(
            out,
            "  correction at the measured codes: {} ({} codes, {} measured twice, noise × {}; replicates predicted {} uncorrected, {} corrected)",
            if c.kept { "kept" } else { "not kept" },
            c.codes,
            c.replicates,
            c.noise_scale.map_or("—".to_string(), |k| format!("{k:.2}")),
            mean(c.uncorrected),
            mean(c.corrected),
        );
        let _ = writeln!(out, "  rule: {}", c.rule);
    }
    for l in &report.laws {
        for n in &l.notes {
            let _ = writeln!(out, "  note ({}): {n}", l.law);
        }
    }
    if !report.terms.is_empty() {
        let rows: Vec<Vec<String>> = report
            .terms
            .iter()
            .map(|t| {
                let mut row = vec![format!(
                    "{}{}",
                    t.terms.name(),
                    if t.kept { "  ← kept" } else { "" }
                )];
                row.extend(stats_cells(t.cross_validation));
                row
            })
            .collect();
        let _ = writeln!(
            out,
            "\nwhat additivity misses (ΔE00 on ramps, greys and whites left out by level):"
        );
        out.push_str(&table(&["terms", "CV mean", "CV p95", "CV max"], &rows));
        let _ = writeln!(out, "  rule: {}", report.terms_rule);
    }
    if let Some(w) = &report.white_anchor {
        let _ = writeln!(out, "\n{}", white_anchor_line(w));
    }
    if report.spatial.positions > 0 {
        let rows: Vec<Vec<String>> = report
            .spatial
            .candidates
            .iter()
            .map(|c| {
                let mut row = vec![format!(
                    "{}{}",
                    c.name,
                    if c.chosen { "  ← chosen" } else { "" }
                )];
                row.extend(stats_cells(c.cross_validation));
                row
            })
            .collect();
        let _ = writeln!(
            out,
            "\nspatial map ({} grid positions, up to {:.1} % less light than the centre; leave-one-position-out ΔE00):",
            report.spatial.positions,
            report.spatial.largest_falloff_percent.unwrap_or(0.0)
        );
        out.push_str(&table(&["map", "mean", "p95", "max"], &rows));
    }
    if report.spatial.unseen > 0 {
        let _ = writeln!(
            out,
            "\nWARNING: {} uniformity-grid reading(s) under {:.0} % of the centre's light were left out of the spatial map: the instrument did not see the patch there. A real instrument has to be moved to each position: --prompt-positions asks for it (or plan.uniformity_grid = 0 measures the centre only).",
            report.spatial.unseen,
            100.0 * chromacal_model::fit::spatial::MIN_PLAUSIBLE_GAIN
        );
    }
    let _ = writeln!(out);
    if let Some(note) = &report.luminance_only {
        let _ = writeln!(out, "NOTE: {note}\n");
    }
    if let Some(l) = &report.limiter {
        out.push_str(&limiter_summary(l));
    }
    match &report.held_out {
        Some(s) => {
            let _ = writeln!(out, "held-out ΔE00 (patches in no fit): {}", stats_line(s));
        }
        None => {
            let _ = writeln!(
                out,
                "held-out ΔE00: no held-out patches in these measurements"
            );
        }
    }
    let c = &report.checks;
    let verdicts = [
        ("primary constancy", c.primary_constancy_verdict),
        ("additivity", c.additivity_verdict),
        ("spatial independence", c.spatial_independence_verdict),
        ("temporal stability", c.temporal_stability_verdict),
        ("monotonicity", c.monotonicity_verdict),
    ];
    let _ = writeln!(out, "\nassumptions:");
    for (name, verdict) in verdicts {
        let figure = match name {
            "primary constancy" => c
                .primary_constancy
                .iter()
                .map(|p| match p.delta_e00 {
                    Some(cost) => {
                        format!("{} Δu′v′ {:.4} (ΔE00 {cost:.2})", p.channel, p.max_delta_uv)
                    }
                    None => format!("{} Δu′v′ {:.4}", p.channel, p.max_delta_uv),
                })
                .collect::<Vec<_>>()
                .join(", "),
            "additivity" => c
                .additivity
                .iter()
                .map(|a| {
                    // The tristimulus value furthest off the sum, and what it costs.
                    let departures = a.xyz_departure_percent.unwrap_or([0.0; 3]);
                    let (j, d) = departures.iter().enumerate().fold(
                        (1, a.luminance_departure_percent),
                        |w, (j, d)| {
                            if d.abs() > w.1.abs() { (j, *d) } else { w }
                        },
                    );
                    format!(
                        "{:.2}: {} {d:+.2} % (ΔE00 {:.2})",
                        a.drive,
                        ["X", "Y", "Z"][j],
                        a.delta_e00
                    )
                })
                .collect::<Vec<_>>()
                .join(", "),
            "spatial independence" => c
                .spatial_independence
                .as_ref()
                .map(|s| {
                    format!(
                        "white surround {:+.2} % (noise {:.2} %)",
                        s.luminance_change_percent, s.noise_percent
                    )
                })
                .unwrap_or_default(),
            "temporal stability" => c.temporal_stability.note.clone(),
            _ => c
                .monotonicity
                .iter()
                .map(|m| format!("{} {} reversal(s)", m.channel, m.reversals_beyond_noise))
                .collect::<Vec<_>>()
                .join(", "),
        };
        let mark = if verdict == Verdict::Fails { "!" } else { " " };
        let verdict = verdict.to_string();
        let _ = writeln!(out, " {mark}{name:<22} {verdict:<26} {figure}");
    }
    let _ = writeln!(
        out,
        "  primary matrix condition number {:.2}; noise {:.2} % + {:.2e} (relative from {}, floor from {})",
        report.condition_number,
        report.noise.relative * 100.0,
        report.noise.floor,
        report.noise.relative_from,
        report.noise.floor_from
    );
    out
}

/// The model in words and numbers.
pub fn describe_model(model: &MonitorModel, units: &str) -> String {
    let mut out = String::new();
    let white = model.white();
    let w = xyz_to_xyy(&white, [0.0, 0.0]);
    let b = xyz_to_xyy(&model.black, [w.x, w.y]);
    let _ = writeln!(
        out,
        "XYZ(d, p) = K(p) · M · E(d) + black   (XYZ in {units})\n"
    );
    let _ = writeln!(out, "white  Y {:.4}  x {:.4}  y {:.4}", white.y, w.x, w.y);
    // A black of 0 (an OLED, a model without a black term) has no finite ratio.
    let contrast = white.y / model.black.y;
    let _ = writeln!(
        out,
        "black  Y {:.5}  x {:.4}  y {:.4}   contrast {}",
        model.black.y,
        b.x,
        b.y,
        if model.black.y > 0.0 && contrast.is_finite() {
            format!("{contrast:.0}:1")
        } else {
            "not finite (black is 0)".to_string()
        }
    );
    let rows: Vec<Vec<String>> = (0..3)
        .map(|c| {
            let col = model.matrix.column(c).into_owned();
            let xyy = xyz_to_xyy(&col, [0.0, 0.0]);
            vec![
                CHANNELS[c].to_string(),
                format!("{:.4}", col.x),
                format!("{:.4}", col.y),
                format!("{:.4}", col.z),
                format!("{:.4}", xyy.x),
                format!("{:.4}", xyy.y),
            ]
        })
        .collect();
    let _ = writeln!(
        out,
        "\nprimary matrix M (columns: XYZ of each primary at full drive, black taken off):"
    );
    out.push_str(&table(&["primary", "X", "Y", "Z", "x", "y"], &rows));
    let _ = writeln!(out, "  condition number {:.2}", model.condition_number());
    let _ = writeln!(out, "\ntransfer laws E(v):");
    for (c, law) in model.laws.iter().enumerate() {
        let params = law
            .parameters()
            .iter()
            .map(|(n, v)| format!("{n} = {v:.5}"))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            out,
            "  {:<6} {:<18} {params}   (E at drive 0.5: {:.4})",
            CHANNELS[c],
            law.kind().name(),
            law.excitation(0.5)
        );
    }
    let _ = writeln!(out, "\nspatial map: {}", model.spatial.describe());
    if !matches!(model.spatial, SpatialMap::Uniform) {
        let corners = [
            (0.1, 0.1),
            (0.9, 0.1),
            (0.1, 0.9),
            (0.9, 0.9),
            (0.5, 0.1),
            (0.1, 0.5),
        ];
        let gains = corners
            .iter()
            .map(|(x, y)| {
                let g = model
                    .spatial
                    .gains(chromacal_model::ScreenPosition::new(*x, *y));
                format!("({x:.1}, {y:.1}): {:.3}", g[1])
            })
            .collect::<Vec<_>>()
            .join("  ");
        let _ = writeln!(out, "  gain K at {gains}");
    }
    out
}

/// `chromacal profile show`.
/// The calibration curves' target and their measured check, level by level.
pub fn calibration_summary(c: &crate::profile::StoredCalibration) -> String {
    let mut out = format!(
        "\ncalibration curves to {} ({} correction passes, {} readings, {}):\n",
        c.curves.describe(),
        c.passes,
        c.readings,
        duration(c.instrument_s)
    );
    out += &format!(
        "  measured {}: white ΔE00 {:.3}, tone within {:.2} % at {} levels above black (predicted from the model alone: {:.3}, {:.2} %)\n",
        if c.through_lut {
            "through the curves loaded in the video LUT"
        } else {
            "through the curves applied to the codes"
        },
        c.measured_white_de00,
        100.0 * c.measured_tone_error,
        c.levels.len(),
        c.curves.predicted_white_de00,
        100.0 * c.curves.predicted_tone_error
    );
    if let Some(white) = c.levels.iter().find(|l| l.input >= 1.0) {
        let [x, y, z] = white.measured_xyz;
        let t = c.curves.white;
        let sum = x + y + z;
        let target_sum = t[0] + t[1] + t[2];
        if sum > 0.0 && target_sum > 0.0 {
            out += &format!(
                "  white measured x {:.4} y {:.4}, Y {:.2} (target x {:.4} y {:.4}, Y {:.2})\n",
                x / sum,
                y / sum,
                y,
                t[0] / target_sum,
                t[1] / target_sum,
                t[1]
            );
        }
    }
    let rows: Vec<Vec<String>> = c
        .levels
        .iter()
        .map(|l| {
            vec![
                format!("{:.3}", l.input),
                format!("{:.4}", l.target_luminance),
                format!("{:.4}", l.measured_luminance),
                format!(
                    "{:+.2} %",
                    100.0 * (l.measured_luminance / l.target_luminance - 1.0)
                ),
            ]
        })
        .collect();
    out += &table(&["input", "target Y", "measured Y", "off"], &rows);
    if c.curves.luminance_limited {
        out += "  (the white point allowed less luminance than asked for)\n";
    }
    out
}

/// The monitor's EDID identity and its stated chromaticities beside the measured ones,
/// with a warning when they are grossly apart.
/// What the colorimeter's readings went through: the correction, by name and digest,
/// or the warning that there was none.
pub fn correction_summary(profile: &Profile) -> String {
    let p = &profile.provenance;
    match (&p.correction, &p.uncorrected) {
        (Some(c), _) => format!("correction: {}\n", c.describe()),
        (None, Some(warning)) => format!("WARNING: {warning}\n"),
        (None, None) => String::new(),
    }
}

pub fn edid_summary(profile: &Profile) -> String {
    let (Some(edid), Some(comparison)) = (&profile.provenance.edid, profile.edid_comparison())
    else {
        return String::new();
    };
    let mut out = format!("monitor (EDID): {}\n", edid.describe());
    let rows = comparison.table_rows();
    out += &table(&["", "EDID xy", "measured xy", "apart"], &rows);
    if comparison.mismatch() {
        out += &format!(
            "  WARNING: the EDID's chromaticities are up to {:.3} from the measured ones (more than {}): is this the display you meant?\n",
            comparison.worst,
            crate::profile::EDID_MISMATCH_XY
        );
    }
    out.push('\n');
    out
}

pub fn describe_profile(profile: &Profile) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "profile {}  (schema {}, created {})",
        profile.id, profile.schema_version, profile.created
    );
    let p = &profile.provenance;
    let _ = writeln!(out, "measured from {}", p.source);
    if let Some(d) = &p.display {
        let _ = writeln!(out, "display: {d}");
    }
    if let Some(i) = &p.instrument {
        let _ = writeln!(out, "instrument: {} ({:?})", i.name, i.capability);
    }
    let _ = writeln!(out, "made by {}\n", p.program);
    out.push_str(&edid_summary(profile));
    out.push_str(&correction_summary(profile));
    out.push_str(&describe_model(&profile.model, &profile.units.to_string()));
    let _ = writeln!(out, "\nprimaries with standard errors:");
    for pr in &profile.report.primaries {
        let _ = writeln!(
            out,
            "  {:<6} X {:.4} ± {:.4}  Y {:.4} ± {:.4}  Z {:.4} ± {:.4}{}",
            pr.channel,
            pr.xyz.x,
            pr.standard_error.x,
            pr.xyz.y,
            pr.standard_error.y,
            pr.xyz.z,
            pr.standard_error.z,
            if pr.full_drive_measured {
                ""
            } else {
                "  (full drive extrapolated)"
            }
        );
    }
    if let Some(chosen) = profile.report.laws.iter().find(|l| l.chosen) {
        let _ = writeln!(out, "law parameters with standard errors ({}):", chosen.law);
        for (c, params) in chosen.parameters.iter().enumerate() {
            let text = params
                .iter()
                .map(|p| match p.standard_error {
                    Some(se) => format!("{} = {:.5} ± {:.5}", p.name, p.value, se),
                    None => format!("{} = {:.5}", p.name, p.value),
                })
                .collect::<Vec<_>>()
                .join(", ");
            let _ = writeln!(out, "  {:<6} {text}", CHANNELS[c]);
        }
    }
    let _ = writeln!(out);
    out.push_str(&fit_summary(&profile.report));
    out.push_str(&hdr_summary(profile));
    if let Some(c) = &profile.calibration {
        out.push_str(&calibration_summary(c));
    }
    out
}

/// `chromacal check`: the errors and the worst patches.
pub fn check_summary(evaluation: &Evaluation, worst: usize) -> String {
    let mut out = String::new();
    match &evaluation.stats {
        Some(s) => {
            let _ = writeln!(out, "ΔE00 of the profile's predictions: {}", stats_line(s));
        }
        None => {
            let _ = writeln!(out, "no usable readings to check");
            return out;
        }
    }
    let rows: Vec<Vec<String>> = evaluation
        .worst(worst)
        .iter()
        .map(|p| {
            vec![
                p.index.to_string(),
                format!("{:?}", p.role).to_lowercase(),
                format!("{:.3} {:.3} {:.3}", p.drive[0], p.drive[1], p.drive[2]),
                format!(
                    "{:.4} {:.4} {:.4}",
                    p.measured.x, p.measured.y, p.measured.z
                ),
                format!(
                    "{:.4} {:.4} {:.4}",
                    p.predicted.x, p.predicted.y, p.predicted.z
                ),
                format!("{:.3}", p.delta_e00),
            ]
        })
        .collect();
    let _ = writeln!(out, "\nworst patches:");
    out.push_str(&table(
        &[
            "patch",
            "role",
            "drive R G B",
            "measured X Y Z",
            "predicted X Y Z",
            "ΔE00",
        ],
        &rows,
    ));
    out
}

/// `chromacal lut show`: an output's video LUT in words.
pub fn describe_lut(status: &crate::calibrate::video_lut::LutStatus) -> String {
    let mut out = format!(
        "video LUT of {} on X display {}: {} entries, {}\n",
        status.output,
        status.x_display,
        status.size,
        if status.identity {
            "straight (output = input)"
        } else {
            "curves loaded"
        }
    );
    match status.from_profile_steps {
        Some(steps) if steps <= 1.0 => out += "  it holds the current profile's curves\n",
        Some(steps) => {
            out += &format!(
                "  it differs from the current profile's curves by up to {steps:.0} of 65535\n"
            )
        }
        None => {}
    }
    if let Some(loader) = &status.desktop_loader {
        out += &format!(
            "  {loader} loads curves into this LUT itself: chromacal's daemon leaves it alone\n"
        );
    }
    out += "  input     R        G        B\n";
    for [v, r, g, b] in &status.samples {
        out += &format!("  {v:.4}  {r:.5}  {g:.5}  {b:.5}\n");
    }
    out
}

/// What `chromacal calibrate` says of a run when it ends: the patches and what they
/// cost, the fit, the curves, the video LUT, and where the journal and the profile are.
pub fn calibration_outcome(outcome: &crate::calibrate::session::CalibrationOutcome) -> String {
    let mut out = format!(
        "chromacal: calibrated {} with {}\n",
        outcome.display,
        outcome
            .profile
            .provenance
            .instrument
            .as_ref()
            .map_or("an instrument", |i| i.name.as_str())
    );
    out += &format!(
        "  patches measured: {}\n",
        budget_line(&outcome.plan.budget)
    );
    if let Some(stop) = &outcome.run.sequential_stop {
        out += &format!(
            "  sequential plan: {} patches added to the seed plan's; stopped: {stop}\n",
            outcome.run.sequential_added
        );
    }
    if outcome.run.extra_reads > 0 || outcome.run.unsettled > 0 {
        out += &format!(
            "  stability check: {} extra readings; {} patches never settled (last reading kept)\n",
            outcome.run.extra_reads, outcome.run.unsettled
        );
    }
    if outcome.run.misreads > 0 {
        out += &format!(
            "  misreads: {} readings no display could have given (not a number, beyond 1e5 cd/m², or negative beyond noise), read again\n",
            outcome.run.misreads
        );
    }
    if outcome.run.already_measured > 0 {
        out += &format!(
            "  resumed: {} patches were in the journal, {} measured now\n",
            outcome.run.already_measured, outcome.run.measured_now
        );
    }
    // "Simulated" only when the instrument was: an emulated or real serial one
    // spent (or reported) this time itself.
    let simulated = outcome
        .profile
        .provenance
        .instrument
        .as_ref()
        .is_some_and(|i| i.name.starts_with("simulated"));
    out += &format!(
        "  {}instrument time {} (integration and settling), fit time {}\n\n",
        if simulated { "simulated " } else { "" },
        duration(outcome.instrument_seconds),
        duration(outcome.fit_seconds)
    );
    out += &edid_summary(&outcome.profile);
    out += &correction_summary(&outcome.profile);
    out += &fit_summary(&outcome.fitted.report);
    out += &hdr_summary(&outcome.profile);
    out += &hlg_plan_hint(outcome);
    if let Some(c) = &outcome.profile.calibration {
        out += &calibration_summary(c);
    }
    if let Some(why) = &outcome.calibration_error {
        out += &format!("\ncalibration curves: none ({why})\n");
    }
    if let Some(lut) = &outcome.lut {
        out += &format!("video LUT: {lut}\n");
    }
    if let Some(verified) = &outcome.verified {
        out += &format!("\n{}\n", verification_summary(verified));
    }
    if let Some(why) = &outcome.verify_error {
        out += &format!("\nverification through the curves: not made ({why})\n");
    }
    out += &format!("\njournal: {}\n", outcome.journal_path.display());
    match &outcome.rejection {
        None => {
            out += &format!(
                "profile: {} (published as current)\n",
                outcome.profile_path.display()
            )
        }
        Some(why) => {
            out += &format!(
                "profile: {} (NOT published: {why})\n",
                outcome.profile_path.display()
            )
        }
    }
    out
}

/// The uniformity lines of a verification's summary.
fn uniformity_summary(u: &crate::verify::uniformity::Uniformity) -> String {
    use crate::verify::uniformity::{DELTA_UV_LIMIT, LEVELS};
    let levels: Vec<String> = LEVELS
        .iter()
        .zip(&u.worst_luminance)
        .map(|((level, limit, _), worst)| {
            format!(
                "{:.0} % within {:.1} % (≤ {:.0} %)",
                100.0 * level,
                100.0 * worst,
                100.0 * limit
            )
        })
        .collect();
    format!(
        "uniformity over a {n} × {n} grid (ISO 12646 tolerances): {}{}; luminance against the centre's at {}; greys within Δu′v′ {:.4} of the centre's (≤ {DELTA_UV_LIMIT})\n",
        u.verdict.name(),
        if u.recommended {
            ", within the recommended tolerances too"
        } else {
            ""
        },
        levels.join(", "),
        u.worst_delta_uv,
        n = u.grid
    )
}

/// What `chromacal verify` says: the calibrated white, black and contrast, the grey
/// balance and the tone, each criterion with its interval and verdict, and the worst
/// patches.
pub fn verification_summary(v: &crate::verify::VerifyReport) -> String {
    let s = &v.state;
    let metric = v.metric.name();
    let mut out = format!(
        "chromacal: verified against {} with the {} chart ({} readings, instrument {})\n",
        v.against,
        v.chart,
        v.readings,
        duration(v.instrument_s)
    );
    out += &format!(
        "  white: {:.2} cd/m², x {:.4} y {:.4}, {}, Duv {}; {metric} {:.3} [{:.3}, {:.3}] from the target\n",
        s.luminance,
        s.xy[0],
        s.xy[1],
        s.cct_k.map_or("–".into(), |k| format!("{k:.0} K")),
        s.duv.map_or("–".into(), |d| format!("{d:+.4}")),
        s.white_delta_e,
        s.white_interval[0],
        s.white_interval[1]
    );
    out += &format!(
        "  black: {:.4} cd/m², contrast {}\n",
        s.black_luminance,
        s.contrast.map_or("–".into(), |c| format!("{c:.0}:1"))
    );
    out += &format!(
        "  grey balance over {} greys: mean {:.2}, a*/b* range {:.2}; tone within {:.1} % of the target\n",
        s.greys.len(),
        s.grey_balance_mean,
        s.grey_balance_range,
        100.0 * s.tone_error
    );
    if let Some(c) = &v.correction {
        out += &format!("  correction: {}\n", c.describe());
    }
    if let Some(warning) = &v.uncorrected {
        out += &format!("  WARNING: {warning}\n");
    }
    if let Some(greys) = &v.greys {
        out += &format!("  sent as lut3d sends: {greys}\n");
    }
    out += &format!("criteria: {}\n", v.criteria);
    let rows: Vec<Vec<String>> = v
        .results
        .iter()
        .map(|r| {
            vec![
                r.description.clone(),
                format!("{}", r.limit),
                format!("{:.3}", r.value),
                format!("[{:.3}, {:.3}]", r.interval[0], r.interval[1]),
                r.verdict.name().to_string(),
            ]
        })
        .collect();
    out += &table(
        &["criterion", "limit", "value", "95 % interval", "verdict"],
        &rows,
    );
    let mut worst: Vec<&crate::verify::PatchResult> = v.patches.iter().collect();
    worst.sort_by(|a, b| b.delta_e.total_cmp(&a.delta_e));
    out += &format!("worst patches ({metric}):\n");
    for p in worst.iter().take(5) {
        out += &format!(
            "  {:<28} {:.3} [{:.3}, {:.3}]{}\n",
            p.label,
            p.delta_e,
            p.interval[0],
            p.interval[1],
            if p.outside {
                " (outside the gamut: against its clipped colour)"
            } else {
                ""
            }
        );
    }
    let mut failed: Vec<String> = v
        .results
        .iter()
        .filter(|r| r.verdict != crate::verify::Verdict::Pass)
        .map(|r| {
            format!(
                "{} {:.3} ({}, limit {})",
                r.description,
                r.value,
                r.verdict.name(),
                r.limit
            )
        })
        .collect();
    if let Some(u) = &v.uniformity {
        out += &uniformity_summary(u);
        failed.extend(
            u.points
                .iter()
                .filter(|p| p.verdict != crate::verify::Verdict::Pass)
                .map(|p| {
                    format!(
                        "uniformity at column {} row {}, {:.0} % grey: luminance {:+.1} %, Δu′v′ {:.4} ({})",
                        p.column + 1,
                        p.row + 1,
                        100.0 * p.level,
                        100.0 * p.luminance_deviation,
                        p.delta_uv,
                        p.verdict.name()
                    )
                }),
        );
    }
    if !failed.is_empty() {
        out += &format!("what misses: {}\n", failed.join("; "));
    }
    out += &format!("verdict: {}", v.verdict.name());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_align_and_durations_read_well() {
        let t = table(
            &["a", "bb"],
            &[
                vec!["xxx".into(), "1".into()],
                vec!["y".into(), "22".into()],
            ],
        );
        assert_eq!(t, "  a    bb\n  xxx   1\n  y    22\n");
        assert_eq!(duration(302.0), "5 min 02 s");
        assert_eq!(duration(1.84), "1.8 s");
        assert_eq!(duration(0.0051), "5.1 ms");
        assert_eq!(duration(7300.0), "2 h 01 min");
    }
}
