//! The charts `verify` measures: which patches, and what each one stands for.
//!
//! A patch is asked for in one of three ways: as the display's own codes (the white,
//! the black and the calibration greys, judged against the calibration's target); as
//! codes of the reference encoding a colour-managed application would send (`verify
//! --against srgb` and the others: greys, primaries and secondaries at several
//! levels); or as a colour (the ColorChecker's, under D65), which the display is asked
//! to show relative to its white and which is left out where the display cannot show
//! it. The built-in charts hold what the criteria need: at least 17 grey levels, the
//! white and the black read several times (their scatter is the instrument's
//! repeatability in this session), primaries and secondaries, and the ColorChecker.

use std::path::Path;

use chromacal_color::Xyz;
use chromacal_color::spectrum::Illuminant;
use chromacal_crf::spectral_table::colorchecker_xyz;
use chromacal_formats::cgats::parse_cgats;

/// What a patch is asked as.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "as", content = "value")]
pub enum Input {
    /// The display's codes, as drive in [0, 1] (through whatever the video LUT holds).
    Display([f64; 3]),
    /// Codes in [0, 1] of the reference encoding (`--against`); the display's codes
    /// when verifying against the profile.
    Encoded([f64; 3]),
    /// A colour relative to a D65 white of Y = 1.
    Colour([f64; 3]),
}

/// What a patch is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    White,
    Black,
    /// A grey of the calibration: the display's codes R = G = B.
    Grey,
    /// A grey of the reference encoding.
    EncodedGrey,
    Primary,
    Secondary,
    ColorChecker,
    /// A patch of the user's own chart.
    User,
}

/// One patch of a chart.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChartPatch {
    pub label: String,
    pub kind: Kind,
    pub input: Input,
}

/// A chart: its name and its patches, in the order they are measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Chart {
    pub name: String,
    pub patches: Vec<ChartPatch>,
}

/// Why a chart could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ChartError {
    #[error("{path}: {message}")]
    File { path: String, message: String },
}

/// The ColorChecker's names, in its order (row by row from the top left).
const COLORCHECKER: [&str; 24] = [
    "dark skin",
    "light skin",
    "blue sky",
    "foliage",
    "blue flower",
    "bluish green",
    "orange",
    "purplish blue",
    "moderate red",
    "purple",
    "yellow green",
    "orange yellow",
    "blue",
    "green",
    "red",
    "yellow",
    "magenta",
    "cyan",
    "white 9.5",
    "neutral 8",
    "neutral 6.5",
    "neutral 5",
    "neutral 3.5",
    "black 2",
];

fn patch(label: impl Into<String>, kind: Kind, input: Input) -> ChartPatch {
    ChartPatch {
        label: label.into(),
        kind,
        input,
    }
}

/// The white and the black, `n` times each, interleaved with the rest so that a
/// drift shows as scatter rather than as a step.
fn repeats(n: usize) -> Vec<ChartPatch> {
    (0..n)
        .flat_map(|k| {
            [
                patch(
                    format!("white {}", k + 1),
                    Kind::White,
                    Input::Display([1.0; 3]),
                ),
                patch(
                    format!("black {}", k + 1),
                    Kind::Black,
                    Input::Display([0.0; 3]),
                ),
            ]
        })
        .collect()
}

/// `levels` calibration greys strictly between black and white, k / (levels + 1).
fn display_greys(levels: usize) -> Vec<ChartPatch> {
    (1..=levels)
        .map(|k| {
            let x = k as f64 / (levels + 1) as f64;
            patch(
                format!("grey {:.1} %", 100.0 * x),
                Kind::Grey,
                Input::Display([x; 3]),
            )
        })
        .collect()
}

/// Greys of the reference encoding at the levels given in percent.
fn encoded_greys(levels: &[f64]) -> Vec<ChartPatch> {
    levels
        .iter()
        .map(|p| {
            patch(
                format!("reference grey {p} %"),
                Kind::EncodedGrey,
                Input::Encoded([p / 100.0; 3]),
            )
        })
        .collect()
}

/// The primaries and secondaries of the reference encoding at the levels given in
/// percent.
fn primaries_and_secondaries(levels: &[f64]) -> Vec<ChartPatch> {
    let colours: [(&str, [f64; 3], Kind); 6] = [
        ("red", [1.0, 0.0, 0.0], Kind::Primary),
        ("green", [0.0, 1.0, 0.0], Kind::Primary),
        ("blue", [0.0, 0.0, 1.0], Kind::Primary),
        ("cyan", [0.0, 1.0, 1.0], Kind::Secondary),
        ("magenta", [1.0, 0.0, 1.0], Kind::Secondary),
        ("yellow", [1.0, 1.0, 0.0], Kind::Secondary),
    ];
    levels
        .iter()
        .flat_map(|p| {
            colours.map(|(name, rgb, kind)| {
                patch(
                    format!("{name} {p} %"),
                    kind,
                    Input::Encoded(rgb.map(|v| v * p / 100.0)),
                )
            })
        })
        .collect()
}

/// The ColorChecker's colours under D65 (Ohta's reflectances, the direct sum), the
/// first `count` of them; relative to the perfect white, Y = 1.
fn colorchecker(count: usize) -> Vec<ChartPatch> {
    let Some(colours) = colorchecker_xyz(Illuminant::D65, 1.0) else {
        return Vec::new();
    };
    COLORCHECKER
        .iter()
        .zip(colours)
        .take(count)
        .map(|(name, xyz)| {
            patch(
                format!("ColorChecker {name}"),
                Kind::ColorChecker,
                Input::Colour([xyz.x, xyz.y, xyz.z]),
            )
        })
        .collect()
}

/// The chart `verify` uses by default: the white and the black three times each, 17
/// calibration greys (15 between black and white), five reference greys, the
/// primaries and secondaries at 25, 50, 75 and 100 %, and the ColorChecker.
pub fn default_chart() -> Chart {
    let mut patches = repeats(3);
    patches.extend(display_greys(15));
    patches.extend(encoded_greys(&[10.0, 25.0, 50.0, 75.0, 90.0]));
    patches.extend(primaries_and_secondaries(&[25.0, 50.0, 75.0, 100.0]));
    patches.extend(colorchecker(24));
    Chart {
        name: "default".into(),
        patches,
    }
}

/// 26 patches: the white and the black once, six calibration greys, the primaries
/// and secondaries at 50 and 100 %, and the ColorChecker's first six colours.
pub fn short_chart() -> Chart {
    let mut patches = repeats(1);
    patches.extend(display_greys(6));
    patches.extend(primaries_and_secondaries(&[50.0, 100.0]));
    patches.extend(colorchecker(6));
    Chart {
        name: "short".into(),
        patches,
    }
}

/// At least 100 patches: the white and the black four times, 31 calibration greys,
/// nine reference greys, the primaries and secondaries at six levels, and the
/// ColorChecker.
pub fn long_chart() -> Chart {
    let mut patches = repeats(4);
    patches.extend(display_greys(31));
    patches.extend(encoded_greys(&[
        5.0, 10.0, 20.0, 30.0, 40.0, 60.0, 70.0, 80.0, 95.0,
    ]));
    patches.extend(primaries_and_secondaries(&[
        10.0, 25.0, 40.0, 60.0, 80.0, 100.0,
    ]));
    patches.extend(colorchecker(24));
    Chart {
        name: "long".into(),
        patches,
    }
}

/// BT.2408's HDR reference white, cd/m²: where a PQ chart puts the ColorChecker's.
pub const HDR_REFERENCE_WHITE: f64 = 203.0;

/// The chart for an HDR display in its PQ mode (`--chart bt2100`, read with
/// `--against rec2100-pq`): the white and the black three times each, 15 calibration
/// greys, PQ greys from 0.1 to 1,000 cd/m² (those above the display's peak are
/// judged against the peak), and the ColorChecker under D65 with its perfect white at
/// BT.2408's 203 cd/m², all as BT.2100 PQ codes on BT.2020 primaries.
pub fn bt2100_chart() -> Chart {
    use chromacal_color::gamut::{AdditiveGamut, REC_2020};
    use chromacal_color::ictcp::pq_inverse_eotf;
    let mut patches = repeats(3);
    patches.extend(display_greys(15));
    for nits in [0.1, 0.5, 1.0, 5.0, 10.0, 50.0, 100.0, 203.0, 400.0, 1000.0] {
        patches.push(patch(
            format!("PQ grey {nits} cd/m²"),
            Kind::EncodedGrey,
            Input::Encoded([pq_inverse_eotf(nits); 3]),
        ));
    }
    let to_rgb = AdditiveGamut::of_space(&REC_2020).and_then(|g| g.primaries.try_inverse());
    if let (Some(to_rgb), Some(colours)) = (to_rgb, colorchecker_xyz(Illuminant::D65, 1.0)) {
        for (name, xyz) in COLORCHECKER.iter().zip(colours) {
            // Every ColorChecker colour is inside BT.2020 (a rounding's negative is 0).
            let rgb = to_rgb * (xyz * HDR_REFERENCE_WHITE);
            patches.push(patch(
                format!("ColorChecker {name}"),
                Kind::ColorChecker,
                Input::Encoded([rgb.x, rgb.y, rgb.z].map(|v| pq_inverse_eotf(v.max(0.0)))),
            ));
        }
    }
    Chart {
        name: "bt2100".into(),
        patches,
    }
}

/// BT.2408's HLG reference white: 75 % of the signal.
pub const HLG_REFERENCE_WHITE: f64 = 0.75;

/// The chart for an HDR display in its HLG mode (`--chart bt2100-hlg`, read with
/// `--against rec2100-hlg`): the white and the black three times each, 15 calibration
/// greys, HLG greys from 5 to 90 % of the signal, and the ColorChecker under D65 with
/// its perfect white at BT.2408's reference white (75 %: scene light 0.265 of the
/// signal's top), all as BT.2100 HLG codes on BT.2020 primaries. HLG is relative: what
/// each code asks for comes from the display's own peak and system gamma.
pub fn bt2100_hlg_chart() -> Chart {
    use chromacal_color::gamut::{AdditiveGamut, REC_2020};
    use chromacal_color::hdr::{hlg_inverse_oetf, hlg_oetf, hlg_scene_light};
    let mut patches = repeats(3);
    patches.extend(display_greys(15));
    for percent in [5.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 75.0, 90.0] {
        patches.push(patch(
            format!("HLG grey {percent} %"),
            Kind::EncodedGrey,
            Input::Encoded([percent / 100.0; 3]),
        ));
    }
    let to_rgb = AdditiveGamut::of_space(&REC_2020).and_then(|g| g.primaries.try_inverse());
    if let (Some(to_rgb), Some(colours)) = (to_rgb, colorchecker_xyz(Illuminant::D65, 1.0)) {
        let white = hlg_scene_light(HLG_REFERENCE_WHITE);
        for (name, xyz) in COLORCHECKER.iter().zip(colours) {
            // Scene light relative to the signal's top (a rounding's negative is 0).
            let rgb = to_rgb * (xyz * white);
            let scene = [rgb.x, rgb.y, rgb.z].map(|v| v.max(0.0) * hlg_inverse_oetf(1.0));
            patches.push(patch(
                format!("ColorChecker {name}"),
                Kind::ColorChecker,
                Input::Encoded(scene.map(hlg_oetf)),
            ));
        }
    }
    Chart {
        name: "bt2100-hlg".into(),
        patches,
    }
}

/// A chart by name (`default`, `short`, `long`, `bt2100`, `bt2100-hlg`) or from a file: an ArgyllCMS `.ti1` or
/// `.ti3` (its `RGB_R RGB_G RGB_B` columns, 0–100), or a CSV with a header naming `R`,
/// `G` and `B` columns (0–1). Its patches are codes of the reference encoding.
pub fn chart(name: &str) -> Result<Chart, ChartError> {
    match name {
        "default" => Ok(default_chart()),
        "short" => Ok(short_chart()),
        "long" => Ok(long_chart()),
        "bt2100" => Ok(bt2100_chart()),
        "bt2100-hlg" => Ok(bt2100_hlg_chart()),
        path => read_chart(Path::new(path)),
    }
}

fn read_chart(path: &Path) -> Result<Chart, ChartError> {
    let bad = |message: String| ChartError::File {
        path: path.display().to_string(),
        message,
    };
    let text = chromacal_formats::durable::read_text_limited(
        path,
        chromacal_formats::durable::limits::TABLE,
    )
    .map_err(|e| bad(e.to_string()))?;
    let rows: Vec<[f64; 3]> =
        if text.trim_start().starts_with("CTI1") || text.trim_start().starts_with("CTI3") {
            let tables =
                parse_cgats(&text, &path.display().to_string()).map_err(|e| bad(e.to_string()))?;
            let table = tables.first().ok_or_else(|| bad("no table".into()))?;
            let column = |name: &str| {
                table
                    .fields
                    .iter()
                    .position(|f| f == name)
                    .ok_or_else(|| bad(format!("no {name} column (an RGB chart is needed)")))
            };
            let (r, g, b) = (column("RGB_R")?, column("RGB_G")?, column("RGB_B")?);
            table
                .rows
                .iter()
                .map(|(line, row)| {
                    let value = |k: usize| -> Result<f64, ChartError> {
                        let v: f64 = row
                            .get(k)
                            .and_then(|v| v.parse().ok())
                            .ok_or_else(|| bad(format!("line {line}: not a number")))?;
                        if (0.0..=100.0).contains(&v) {
                            Ok(v / 100.0)
                        } else {
                            Err(bad(format!("line {line}: {v} is outside 0–100")))
                        }
                    };
                    Ok([value(r)?, value(g)?, value(b)?])
                })
                .collect::<Result<_, _>>()?
        } else {
            read_csv_rows(&text).map_err(bad)?
        };
    if rows.is_empty() {
        return Err(bad("no patches".into()));
    }
    Ok(Chart {
        name: path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        ),
        patches: rows
            .into_iter()
            .enumerate()
            .map(|(i, rgb)| patch(format!("patch {}", i + 1), Kind::User, Input::Encoded(rgb)))
            .collect(),
    })
}

/// A CSV chart: a header naming R, G and B (either case), then rows of values 0–1.
fn read_csv_rows(text: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<String> = lines
        .next()
        .ok_or("empty")?
        .split(',')
        .map(|h| h.trim().to_ascii_uppercase())
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| format!("the header names no {name} column (R, G, B, 0–1)"))
    };
    let (r, g, b) = (column("R")?, column("G")?, column("B")?);
    lines
        .enumerate()
        .map(|(i, line)| {
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            let value = |k: usize| -> Result<f64, String> {
                let v: f64 = cells
                    .get(k)
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| format!("line {}: not a number", i + 2))?;
                if (0.0..=1.0).contains(&v) {
                    Ok(v)
                } else {
                    Err(format!("line {}: {v} is outside 0–1", i + 2))
                }
            };
            Ok([value(r)?, value(g)?, value(b)?])
        })
        .collect()
}

impl Chart {
    /// The number of grey levels the chart holds (black and white included).
    pub fn grey_levels(&self) -> usize {
        let mut levels: Vec<u64> = self
            .patches
            .iter()
            .filter(|p| matches!(p.kind, Kind::White | Kind::Black | Kind::Grey))
            .filter_map(|p| match p.input {
                Input::Display(rgb) => Some((rgb[0] * 1e6).round() as u64),
                _ => None,
            })
            .collect();
        levels.sort_unstable();
        levels.dedup();
        levels.len()
    }
}

/// A colour of a chart relative to a D65 white of Y = 1, as `Xyz`.
pub fn colour_xyz(value: [f64; 3]) -> Xyz {
    Xyz::new(value[0], value[1], value[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_charts_hold_what_the_criteria_need() {
        let chart = default_chart();
        assert!(chart.patches.len() >= 40, "{}", chart.patches.len());
        assert!(chart.grey_levels() >= 17, "{}", chart.grey_levels());
        let count = |kind: Kind| chart.patches.iter().filter(|p| p.kind == kind).count();
        assert!(count(Kind::White) >= 3 && count(Kind::Black) >= 3);
        assert_eq!(count(Kind::ColorChecker), 24);
        assert_eq!(short_chart().patches.len(), 26);
        assert!(long_chart().patches.len() >= 100);
        // The HLG chart: its reference white's grey at 75 % of the signal, and the
        // ColorChecker's white patch (its reflectance about 0.9) just below it.
        let hlg = bt2100_hlg_chart();
        let encoded = |label: &str| {
            hlg.patches
                .iter()
                .find(|p| p.label == label)
                .map(|p| match p.input {
                    Input::Encoded(rgb) => rgb,
                    _ => panic!("{label} is not encoded"),
                })
                .unwrap()
        };
        assert_eq!(encoded("HLG grey 75 %"), [0.75; 3]);
        let white = encoded("ColorChecker white 9.5");
        assert!(white.iter().all(|v| (0.70..0.75).contains(v)), "{white:?}");
        assert_eq!(
            hlg.patches
                .iter()
                .filter(|p| p.kind == Kind::ColorChecker)
                .count(),
            24
        );
    }

    #[test]
    fn a_csv_chart_is_read_and_a_bad_one_named() {
        let rows = read_csv_rows("r,g,b\n0,0.5,1\n1,1,1\n").unwrap();
        assert_eq!(rows, vec![[0.0, 0.5, 1.0], [1.0; 3]]);
        let err = read_csv_rows("R,G,B\n0,2,1\n").unwrap_err();
        assert!(
            err.contains("line 2") && err.contains("outside 0–1"),
            "{err}"
        );
        assert!(
            read_csv_rows("x,y\n1,2\n")
                .unwrap_err()
                .contains("no R column")
        );
    }
}
