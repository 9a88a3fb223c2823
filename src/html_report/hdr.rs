//! The report's section for a display calibrated in its HDR mode: the PQ tracking
//! (target and measured luminance against the signal, log scale, BT.2100's darkest
//! levels to the peak), the brightness limiter (the peak at each window size, the
//! full-field white, the additive model and the limiter term), and the black.

use maud::{Markup, html};

use super::ReportError;
use super::figures::{self, Curve, LimiterSeries};
use super::markup::{facts, figure, table};
use crate::profile::Profile;
use chromacal_model::fit::limiter::LimiterReport;
use chromacal_model::target::target_luminance;

/// The darkest luminance the tracking figure shows, cd/m² (the 0.005: below
/// it no HDR master has detail worth a reading).
const TRACKING_FLOOR: f64 = 0.005;

/// The section, for a profile whose plan sent an HDR signal (nothing otherwise).
pub fn hdr(profile: &Profile) -> Result<Markup, ReportError> {
    let Some(signal) = profile.provenance.signal.filter(|s| s.is_hdr()) else {
        return Ok(html! {});
    };
    let tracking = match &profile.calibration {
        Some(stored) if stored.curves.target.tone.is_hdr() => {
            let (tone, curves) = (stored.curves.target.tone, &stored.curves);
            let (black, white) = (curves.black[1], curves.white[1]);
            let target: Curve = (0..=400)
                .map(|i| {
                    let x = f64::from(i) / 400.0;
                    (x, target_luminance(tone, x, black, white))
                })
                .collect();
            let measured: Curve = stored
                .levels
                .iter()
                .map(|l| (l.input, l.measured_luminance))
                .collect();
            let svg = figures::pq_tracking(&target, &measured, TRACKING_FLOOR)?;
            html! {
                (figure("fig-pq-tracking", &svg, &format!(
                    "Greys measured through the calibration curves against the target ({}), from {TRACKING_FLOOR} cd/m² to the peak.",
                    curves.describe()
                )))
            }
        }
        _ => html! {},
    };
    let limiter = match &profile.report.limiter {
        Some(report) => limiter_part(report)?,
        None => html! {},
    };
    let model = &profile.model;
    Ok(html! {
        section #hdr {
            h2 { "HDR" }
            (facts(&[
                ("signal", signal.describe().to_string()),
                ("peak (white at the plan's patch size)", format!("{:.1} cd/m²", model.white().y)),
                ("black", format!("{:.4} cd/m²", model.black.y)),
            ]))
            (tracking)
            (limiter)
        }
    })
}

/// The limiter's figure and table.
fn limiter_part(report: &LimiterReport) -> Result<Markup, ReportError> {
    let mut levels: Vec<f64> = report.windows.iter().map(|w| w.level).collect();
    levels.sort_by(|a, b| b.total_cmp(a));
    levels.dedup();
    let series: Vec<LimiterSeries> = levels
        .iter()
        .map(|&level| {
            let mut windows: Vec<_> = report.windows.iter().filter(|w| w.level == level).collect();
            windows.sort_by(|a, b| a.area.total_cmp(&b.area));
            let points = |y: &dyn Fn(&chromacal_model::fit::limiter::WindowPoint) -> f64| -> Curve {
                windows.iter().map(|w| (100.0 * w.area, y(w))).collect()
            };
            LimiterSeries {
                name: if level >= 1.0 {
                    "white".into()
                } else {
                    format!("grey {level:.2}")
                },
                measured: points(&|w| w.measured_y),
                additive: points(&|w| w.additive_y),
                limited: report
                    .limiter
                    .as_ref()
                    .map(|l| points(&|w| w.additive_y * l.gain(w.mean_light))),
            }
        })
        .collect();
    let svg = figures::brightness_limiter(&series)?;
    let mut whites: Vec<_> = report.windows.iter().filter(|w| w.level >= 1.0).collect();
    whites.sort_by(|a, b| a.area.total_cmp(&b.area));
    let rows: Vec<Vec<String>> = whites
        .iter()
        .map(|w| {
            vec![
                format!("{:.0} %", 100.0 * w.area),
                format!("{:.1}", w.measured_y),
                format!("{:.1}", w.additive_y),
                format!("{:.1}", w.left_out_y),
            ]
        })
        .collect();
    let verdict = match (&report.limiter, report.kept) {
        (Some(l), true) => format!(
            "Kept: full-field white F = {:.1} cd/m², knee sharpness {:.1}; {}",
            l.full_field, l.sharpness, report.rule
        ),
        _ => format!("Not kept: {}", report.rule),
    };
    let full_field = report
        .full_field_white()
        .map_or("not measured".into(), |w| {
            format!("{:.1} cd/m²", w.measured_y)
        });
    Ok(html! {
        (figure("fig-brightness-limiter", &svg, "White and grey windows on black: measured, as the additive model predicts them, and with the limiter term of the screen's mean light."))
        p #limiter-verdict { (verdict) }
        p { "Full-field white: " span #full-field-white { (full_field) } "." }
        (table(&["window", "white measured, cd/m²", "additive model", "limiter (window left out)"], &rows))
    })
}
