//! The report's figures, each an SVG drawn by `plotters` into a string and inlined in
//! the page. Each function takes plain data (points, curves, chromaticities) that
//! `super` computes from a profile, so what is drawn and how it is computed read apart.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;

/// Why a figure could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("the figure '{figure}' could not be drawn: {message}")]
pub struct FigureError {
    pub figure: &'static str,
    pub message: String,
}

/// A curve: (x, y) points joined by a line.
pub type Curve = Vec<(f64, f64)>;

/// Red, green and blue as the figures draw the channels.
pub const CHANNEL_COLOURS: [RGBColor; 3] = [
    RGBColor(200, 30, 30),
    RGBColor(20, 140, 40),
    RGBColor(30, 60, 200),
];

/// Lighter lines for the candidates that were not chosen.
const CANDIDATE_COLOURS: [RGBColor; 5] = [
    RGBColor(230, 150, 0),
    RGBColor(140, 80, 170),
    RGBColor(0, 150, 160),
    RGBColor(120, 120, 120),
    RGBColor(200, 90, 140),
];

const FONT: &str = "sans-serif";

/// Draw into a `width`×`height` SVG; `draw` gets the root area, white already.
fn svg(
    figure: &'static str,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
) -> Result<String, FigureError> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        let fail = |message: String| FigureError { figure, message };
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        draw(&root).map_err(fail)?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    Ok(out)
}

fn text<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A chart of two f64 axes drawn into an SVG.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A titled chart on `area` over `x` × `y`, with room for the axes' labels
/// (`y_labels` pixels for the y axis).
fn titled<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    title: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    y_labels: u32,
) -> Result<Chart<'a, 'b>, String> {
    ChartBuilder::on(area)
        .caption(title, (FONT, 16))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(y_labels)
        .build_cartesian_2d(x, y)
        .map_err(text)
}

/// The grid and the axes' names.
fn axes(chart: &mut Chart, x: &str, y: &str) -> Result<(), String> {
    chart
        .configure_mesh()
        .x_desc(x)
        .y_desc(y)
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(text)
}

/// The legend of the series that have a label, at `position`.
fn legend<'a, 'b: 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, CT>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font((FONT, 11))
        .draw()
        .map_err(text)
}

/// (lowest, highest) of `values`, widened by `pad` of the span, and never empty.
fn padded_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(1e-9 * lo.abs().max(1.0)).max(1e-12);
    (lo - pad * span, hi + pad * span)
}

/// One channel's transfer: the chosen law, the candidates, the measured shares.
pub fn transfer(
    channel: usize,
    title: &str,
    chosen: (&str, &Curve),
    candidates: &[(String, Curve)],
    measured: &[(f64, f64)],
) -> Result<String, FigureError> {
    let colour = CHANNEL_COLOURS[channel % 3];
    svg("transfer", (420, 340), |root| {
        let top = measured
            .iter()
            .map(|p| p.1)
            .chain(chosen.1.iter().map(|p| p.1))
            .fold(1.0_f64, f64::max)
            * 1.05;
        let mut chart = titled(root, title, 0.0..1.0, 0.0..top, 44)?;
        axes(&mut chart, "drive", "share of full drive")?;
        for (i, (name, curve)) in candidates.iter().enumerate() {
            let c = CANDIDATE_COLOURS[i % CANDIDATE_COLOURS.len()];
            chart
                .draw_series(DashedLineSeries::new(
                    curve.iter().copied(),
                    4,
                    3,
                    c.stroke_width(1),
                ))
                .map_err(text)?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
        }
        chart
            .draw_series(LineSeries::new(
                chosen.1.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(text)?
            .label(format!("{} (chosen)", chosen.0))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
            });
        if !measured.is_empty() {
            chart
                .draw_series(
                    measured
                        .iter()
                        .map(|&(x, y)| Circle::new((x, y), 3, colour.filled())),
                )
                .map_err(text)?
                .label("measured")
                .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    })
}

/// Residuals, measured minus chosen law, of the three channels' shares against drive.
pub fn residuals(series: &[Vec<(f64, f64)>; 3]) -> Result<String, FigureError> {
    svg("residuals", (640, 300), |root| {
        let (lo, hi) = padded_range(series.iter().flatten().map(|p| p.1).chain([0.0]), 0.1);
        let reach = lo.abs().max(hi.abs());
        let mut chart = titled(
            root,
            "Residuals of the chosen law",
            0.0..1.0,
            -reach..reach,
            60,
        )?;
        axes(&mut chart, "drive", "measured − law (share)")?;
        chart
            .draw_series(LineSeries::new(
                [(0.0, 0.0), (1.0, 0.0)],
                BLACK.stroke_width(1),
            ))
            .map_err(text)?;
        for (channel, points) in series.iter().enumerate() {
            let colour = CHANNEL_COLOURS[channel];
            chart
                .draw_series(
                    points
                        .iter()
                        .map(|&(x, y)| Circle::new((x, y), 3, colour.filled())),
                )
                .map_err(text)?
                .label(["red", "green", "blue"][channel])
                .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    })
}

/// The greys: luminance over white's, as the model predicts it and as measured.
pub fn greys(model: &Curve, measured: &[(f64, f64)]) -> Result<String, FigureError> {
    svg("greys", (420, 340), |root| {
        let top = measured.iter().map(|p| p.1).fold(1.0_f64, f64::max) * 1.05;
        let mut chart = titled(root, "Greys (all three channels)", 0.0..1.0, 0.0..top, 44)?;
        axes(&mut chart, "drive", "Y / Y white")?;
        chart
            .draw_series(LineSeries::new(
                model.iter().copied(),
                BLACK.stroke_width(2),
            ))
            .map_err(text)?
            .label("model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        chart
            .draw_series(
                measured
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, RGBColor(90, 90, 90).filled())),
            )
            .map_err(text)?
            .label("measured")
            .legend(|(x, y)| Circle::new((x + 8, y), 3, RGBColor(90, 90, 90).filled()));
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    })
}

/// The tone response on log–log axes: relative luminance (above black) against
/// drive, measured and as the model predicts it, and the target where there is one.
/// A power law is a straight line here whose slope is its exponent, and the dark end,
/// flat on linear axes, is spread out.
pub fn tone_log(
    measured: &Curve,
    model: &Curve,
    target: Option<(&str, &Curve)>,
) -> Result<String, FigureError> {
    svg("tone", (460, 360), |root| {
        let positive = |c: &Curve| -> Curve {
            c.iter()
                .copied()
                .filter(|p| p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite())
                .collect()
        };
        let (measured, model) = (positive(measured), positive(model));
        let target = target.map(|(name, c)| (name, positive(c)));
        // The axes span what was measured (and the target): the model is drawn over
        // that span, not down to its own first sample.
        let x_lo = measured
            .iter()
            .chain(target.iter().flat_map(|(_, c)| c.iter()))
            .map(|p| p.0)
            .fold(1.0_f64, f64::min)
            .clamp(1e-3, 0.5);
        let y_lo = measured
            .iter()
            .map(|p| p.1)
            .chain(model.iter().filter(|p| p.0 >= x_lo).map(|p| p.1))
            .fold(1.0_f64, f64::min)
            .clamp(1e-6, 0.5);
        let mut chart = ChartBuilder::on(root)
            .caption("Tone response, log–log", (FONT, 16))
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(54)
            .build_cartesian_2d(
                (x_lo * 0.9..1.05).log_scale(),
                (y_lo * 0.7..1.3).log_scale(),
            )
            .map_err(text)?;
        chart
            .configure_mesh()
            .x_desc("drive (log)")
            .y_desc("(Y − Y black) / (Y white − Y black) (log)")
            .x_label_formatter(&|v| format!("{v:.3}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(text)?;
        chart
            .draw_series(LineSeries::new(
                model.iter().copied().filter(|p| p.0 >= x_lo * 0.9),
                BLACK.stroke_width(2),
            ))
            .map_err(text)?
            .label("model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        if let Some((name, curve)) = &target {
            let colour = CANDIDATE_COLOURS[0];
            chart
                .draw_series(DashedLineSeries::new(
                    curve.iter().copied().filter(|p| p.0 >= x_lo * 0.9),
                    5,
                    3,
                    colour.stroke_width(2),
                ))
                .map_err(text)?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        }
        chart
            .draw_series(
                measured
                    .iter()
                    .map(|&p| Circle::new(p, 3, RGBColor(90, 90, 90).filled())),
            )
            .map_err(text)?
            .label("measured greys")
            .legend(|(x, y)| Circle::new((x + 8, y), 3, RGBColor(90, 90, 90).filled()));
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    })
}

/// Grey balance along the ramp: each grey's a* and b* against the white, and its
/// distance Δu′v′ × 1000 from the white's chromaticity.
pub fn grey_balance(
    a: &Curve,
    b: &Curve,
    delta_uv_thousandths: &Curve,
) -> Result<String, FigureError> {
    svg("grey-balance", (460, 360), |root| {
        let (lo, hi) = padded_range(
            a.iter()
                .chain(b)
                .chain(delta_uv_thousandths)
                .map(|p| p.1)
                .chain([-1.0, 1.0]),
            0.1,
        );
        let mut chart = titled(root, "Grey balance", 0.0..1.0, lo..hi, 44)?;
        axes(&mut chart, "drive", "a*, b*, Δu′v′ × 1000")?;
        chart
            .draw_series(LineSeries::new(
                [(0.0, 0.0), (1.0, 0.0)],
                RGBColor(160, 160, 160).stroke_width(1),
            ))
            .map_err(text)?;
        let series: [(&str, &Curve, RGBColor); 3] = [
            ("a*", a, RGBColor(200, 30, 90)),
            ("b*", b, RGBColor(200, 160, 0)),
            ("Δu′v′ × 1000", delta_uv_thousandths, RGBColor(60, 60, 60)),
        ];
        for (name, curve, colour) in series {
            chart
                .draw_series(LineSeries::new(
                    curve.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(text)?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            chart
                .draw_series(curve.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(text)?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    })
}

/// What the chromaticity diagram shows, all in CIE 1976 u′v′.
pub struct Chromaticities {
    /// The spectrum locus, shortest wavelength first.
    pub locus: Curve,
    /// Reference gamuts by name, primaries R, G, B.
    pub references: Vec<(&'static str, [(f64, f64); 3])>,
    pub primaries: [(f64, f64); 3],
    pub white: (f64, f64),
    /// Each channel's chromaticity at every measured level, where readings are known.
    pub measured: [Vec<(f64, f64)>; 3],
}

/// The primaries and white on the CIE 1976 u′v′ diagram, the spectrum locus around
/// them and the reference gamuts for scale.
pub fn chromaticity(c: &Chromaticities) -> Result<String, FigureError> {
    svg("chromaticity", (520, 500), |root| {
        let mut chart = titled(
            root,
            "Primaries and white, CIE 1976 u′v′",
            0.0..0.65,
            0.0..0.62,
            44,
        )?;
        axes(&mut chart, "u′", "v′")?;
        let mut closed = c.locus.clone();
        if let Some(first) = c.locus.first() {
            closed.push(*first);
        }
        chart
            .draw_series(LineSeries::new(closed, BLACK.stroke_width(1)))
            .map_err(text)?
            .label("spectrum locus")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
        for (i, (name, primaries)) in c.references.iter().enumerate() {
            let colour = CANDIDATE_COLOURS[i % CANDIDATE_COLOURS.len()];
            let mut triangle = primaries.to_vec();
            triangle.push(primaries[0]);
            chart
                .draw_series(DashedLineSeries::new(
                    triangle,
                    5,
                    3,
                    colour.stroke_width(1),
                ))
                .map_err(text)?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        }
        chart
            .draw_series([Polygon::new(
                c.primaries.to_vec(),
                RGBColor(120, 120, 120).mix(0.18),
            )])
            .map_err(text)?;
        let mut triangle = c.primaries.to_vec();
        triangle.push(c.primaries[0]);
        chart
            .draw_series(LineSeries::new(triangle, BLACK.stroke_width(2)))
            .map_err(text)?
            .label("this display")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        for (channel, points) in c.measured.iter().enumerate() {
            let colour = CHANNEL_COLOURS[channel];
            chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 2, colour.filled())))
                .map_err(text)?;
            chart
                .draw_series([Circle::new(c.primaries[channel], 5, colour.stroke_width(2))])
                .map_err(text)?;
        }
        chart
            .draw_series([Cross::new(c.white, 5, BLACK.stroke_width(2))])
            .map_err(text)?
            .label("white")
            .legend(|(x, y)| Cross::new((x + 8, y), 4, BLACK.stroke_width(2)));
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    })
}

/// A measured point of the uniformity grid: position (fractions of width and height)
/// and light relative to the centre's, percent.
pub struct GridPoint {
    pub x: f64,
    pub y: f64,
    pub percent: f64,
}

/// The fitted surface as a heat map over the screen (rows of relative light, top
/// first), the measured positions on it with their figures.
pub fn uniformity(surface: &[Vec<f64>], points: &[GridPoint]) -> Result<String, FigureError> {
    svg("uniformity", (560, 380), |root| {
        let (lo, hi) = padded_range(
            surface
                .iter()
                .flatten()
                .copied()
                .chain(points.iter().map(|p| p.percent / 100.0)),
            0.0,
        );
        let (lo, hi) = if hi - lo < 1e-3 {
            (lo - 0.01, hi + 0.01)
        } else {
            (lo, hi)
        };
        let (map_area, scale_area) = root.split_horizontally(490);
        let mut chart = ChartBuilder::on(&map_area)
            .caption("Uniformity: light relative to the centre", (FONT, 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..1.0, 1.0..0.0)
            .map_err(text)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (fraction of width)")
            .y_desc("y")
            .draw()
            .map_err(text)?;
        let rows = surface.len().max(1);
        for (r, row) in surface.iter().enumerate() {
            let columns = row.len().max(1);
            for (k, gain) in row.iter().enumerate() {
                let (x0, y0) = (k as f64 / columns as f64, r as f64 / rows as f64);
                let (x1, y1) = (
                    (k + 1) as f64 / columns as f64,
                    (r + 1) as f64 / rows as f64,
                );
                let colour = ViridisRGB::get_color_normalized(*gain, lo, hi);
                chart
                    .draw_series([Rectangle::new([(x0, y0), (x1, y1)], colour.filled())])
                    .map_err(text)?;
            }
        }
        // Each measured position in its measured colour, ringed, with its figure
        // beside it: where the dot differs from the map around it, the map misses.
        for p in points {
            let colour = ViridisRGB::get_color_normalized(p.percent / 100.0, lo, hi);
            chart
                .draw_series([
                    Circle::new((p.x, p.y), 7, colour.filled()),
                    Circle::new((p.x, p.y), 7, BLACK.stroke_width(1)),
                ])
                .map_err(text)?;
            chart
                .draw_series([EmptyElement::at((p.x, p.y))
                    + Text::new(
                        format!("{:.1}", p.percent),
                        (9, -14),
                        (FONT, 11).into_font().color(&BLACK),
                    )])
                .map_err(text)?;
        }
        // The colour scale.
        let mut scale = ChartBuilder::on(&scale_area)
            .margin_top(36)
            .margin_bottom(38)
            .margin_right(4)
            .y_label_area_size(0)
            .right_y_label_area_size(46)
            .build_cartesian_2d(0.0..1.0, lo * 100.0..hi * 100.0)
            .map_err(text)?;
        scale
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            // A mesh's default label size is a share of its area's height: on this
            // narrow bar that came out at under 2 px, unreadable.
            .y_label_style((FONT, 11))
            .y_label_formatter(&|v| format!("{v:.1} %"))
            .draw()
            .map_err(text)?;
        let steps = 40;
        scale
            .draw_series((0..steps).map(|i| {
                let a = lo + (hi - lo) * i as f64 / steps as f64;
                let b = lo + (hi - lo) * (i + 1) as f64 / steps as f64;
                let colour = ViridisRGB::get_color_normalized((a + b) / 2.0, lo, hi);
                Rectangle::new([(0.0, a * 100.0), (1.0, b * 100.0)], colour.filled())
            }))
            .map_err(text)?;
        Ok(())
    })
}

/// Histogram of ΔE00 values with `bins` bins from 0 to the largest.
pub fn histogram(values: &[f64], title: &str) -> Result<String, FigureError> {
    svg("histogram", (560, 300), |root| {
        let max = values.iter().copied().fold(0.0_f64, f64::max);
        let bins = 20usize;
        let width = if max > 0.0 { max / bins as f64 } else { 0.05 };
        let mut counts = vec![0usize; bins];
        for v in values {
            let i = ((v / width) as usize).min(bins - 1);
            counts[i] += 1;
        }
        let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.1;
        let mut chart = titled(root, title, 0.0..width * bins as f64, 0.0..top, 44)?;
        chart
            .configure_mesh()
            .x_desc("ΔE00")
            .y_desc("patches")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(text)?;
        chart
            .draw_series(
                counts
                    .iter()
                    .enumerate()
                    .filter(|(_, n)| **n > 0)
                    .map(|(i, n)| {
                        Rectangle::new(
                            [(i as f64 * width, 0.0), ((i + 1) as f64 * width, *n as f64)],
                            RGBColor(70, 110, 170).filled(),
                        )
                    }),
            )
            .map_err(text)?;
        Ok(())
    })
}

/// The calibration curves: drive out of each channel against input.
pub fn calibration(curves: &[Curve; 3]) -> Result<String, FigureError> {
    svg("calibration", (420, 340), |root| {
        let mut chart = titled(root, "Calibration curves", 0.0..1.0, 0.0..1.0, 44)?;
        axes(&mut chart, "input", "drive out")?;
        for (channel, curve) in curves.iter().enumerate() {
            let colour = CHANNEL_COLOURS[channel];
            chart
                .draw_series(LineSeries::new(
                    curve.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(text)?
                .label(["red", "green", "blue"][channel])
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    })
}

/// One series over time: (seconds since the Unix epoch, value) with its name.
pub struct TimeSeries {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// A time on the history axis, as a date (and the time of day when the span is
/// under a few days): UTC, as the profiles' own dates are written.
fn date_label(epoch_s: f64, span: TimeSpan) -> String {
    let Ok(at) = jiff::Timestamp::from_second(epoch_s.round() as i64) else {
        return String::new();
    };
    at.strftime(match span {
        TimeSpan::Minutes => "%m-%d %H:%M:%S",
        TimeSpan::Days => "%m-%d %H:%M",
        TimeSpan::Longer => "%Y-%m-%d",
    })
    .to_string()
}

/// How long a history runs, for how its dates are written.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TimeSpan {
    /// Under an hour: ticks seconds or minutes apart, written to the second.
    Minutes,
    /// Under four days: to the minute.
    Days,
    /// Dates alone.
    Longer,
}

/// Values over time (the daemon's history): each series as a line with points, the
/// time axis in dates (UTC).
pub fn over_time(title: &str, y_label: &str, series: &[TimeSeries]) -> Result<String, FigureError> {
    svg("history", (640, 300), |root| {
        let (x0, x1) = padded_range(
            series.iter().flat_map(|s| s.points.iter().map(|p| p.0)),
            0.05,
        );
        let span = match x1 - x0 {
            s if s < 3600.0 => TimeSpan::Minutes,
            s if s < 4.0 * 86_400.0 => TimeSpan::Days,
            _ => TimeSpan::Longer,
        };
        let (_, y1) = padded_range(
            series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .chain([0.0]),
            0.1,
        );
        let mut chart = titled(root, title, x0..x1, 0.0..y1, 54)?;
        chart
            .configure_mesh()
            .x_desc(if span == TimeSpan::Longer {
                "date (UTC)"
            } else {
                "date and time (UTC)"
            })
            .y_desc(y_label)
            .x_labels(5)
            .x_label_formatter(&|v| date_label(*v, span))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(text)?;
        for (i, s) in series.iter().enumerate() {
            let colour = CANDIDATE_COLOURS[i % CANDIDATE_COLOURS.len()];
            chart
                .draw_series(LineSeries::new(
                    s.points.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(text)?
                .label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            chart
                .draw_series(s.points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(text)?;
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    })
}

/// An HDR display's PQ tracking: the target's luminance against the signal, and the
/// greys measured through the calibration, in cd/m² on a log scale from `floor` (the
/// darkest that matters, 0.005 cd/m²) to above the peak.
pub fn pq_tracking(target: &Curve, measured: &Curve, floor: f64) -> Result<String, FigureError> {
    svg("pq tracking", (460, 360), |root| {
        let top = target
            .iter()
            .chain(measured)
            .map(|p| p.1)
            .fold(floor * 10.0, f64::max)
            * 1.5;
        let visible = |c: &Curve| -> Curve { c.iter().copied().filter(|p| p.1 >= floor).collect() };
        let mut chart = ChartBuilder::on(root)
            .caption("PQ tracking", (FONT, 16))
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(54)
            .build_cartesian_2d(0.0..1.0, (floor..top).log_scale())
            .map_err(text)?;
        chart
            .configure_mesh()
            .x_desc("signal")
            .y_desc("luminance, cd/m² (log)")
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(text)?;
        let colour = CANDIDATE_COLOURS[0];
        chart
            .draw_series(LineSeries::new(visible(target), colour.stroke_width(2)))
            .map_err(text)?
            .label("target")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        chart
            .draw_series(
                visible(measured)
                    .into_iter()
                    .map(|p| Circle::new(p, 3, RGBColor(90, 90, 90).filled())),
            )
            .map_err(text)?
            .label("measured through the curves")
            .legend(|(x, y)| Circle::new((x + 8, y), 3, RGBColor(90, 90, 90).filled()));
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    })
}

/// The brightness limiter: each window's luminance against its share of the screen
/// (log), measured (points), as the additive model predicts it (dashed) and as the
/// limiter term does (lines, where one was fitted); one series per grey level.
pub fn brightness_limiter(series: &[LimiterSeries]) -> Result<String, FigureError> {
    svg("brightness limiter", (460, 360), |root| {
        let top = series
            .iter()
            .flat_map(|s| s.measured.iter().chain(&s.additive))
            .map(|p| p.1)
            .fold(1.0_f64, f64::max)
            // Room above the points for the legend.
            * 1.5;
        let mut chart = ChartBuilder::on(root)
            .caption("Brightness limiter", (FONT, 16))
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(54)
            .build_cartesian_2d((0.8..120.0).log_scale(), 0.0..top)
            .map_err(text)?;
        chart
            .configure_mesh()
            .x_desc("window, % of the screen (log)")
            .y_desc("luminance, cd/m²")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(text)?;
        for (i, s) in series.iter().enumerate() {
            let colour = CANDIDATE_COLOURS[i % CANDIDATE_COLOURS.len()];
            chart
                .draw_series(DashedLineSeries::new(
                    s.additive.iter().copied(),
                    5,
                    3,
                    colour.mix(0.6).stroke_width(1),
                ))
                .map_err(text)?
                .label(format!("{}: additive model", s.name))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.mix(0.6)));
            if let Some(limited) = &s.limited {
                chart
                    .draw_series(LineSeries::new(
                        limited.iter().copied(),
                        colour.stroke_width(2),
                    ))
                    .map_err(text)?
                    .label(format!("{}: limiter", s.name))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            }
            chart
                .draw_series(
                    s.measured
                        .iter()
                        .map(|&p| Circle::new(p, 3, colour.filled())),
                )
                .map_err(text)?
                .label(format!("{}: measured", s.name))
                .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    })
}

/// One grey level's windows for [`brightness_limiter`]: (area %, cd/m²) points.
pub struct LimiterSeries {
    pub name: String,
    pub measured: Curve,
    pub additive: Curve,
    pub limited: Option<Curve>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_dates_read_as_dates() {
        // 2026-12-04T10:30:00Z.
        assert_eq!(date_label(1_796_380_200.0, TimeSpan::Longer), "2026-12-04");
        assert_eq!(date_label(1_796_380_200.0, TimeSpan::Days), "12-04 10:30");
        assert_eq!(
            date_label(1_796_380_207.0, TimeSpan::Minutes),
            "12-04 10:30:07"
        );
    }
}
