//! The whole model, additivity terms included, as the ICC `lut16Type` tags `A2B0`
//! (device → PCS) and `B2A0` (PCS → device) beside the matrix/TRC tags.
//!
//! Why: a matrix/TRC profile is additive, so a model that keeps a channel-interaction,
//! crosstalk or chromaticity-shift term (`fit::terms`) lost it in every ICC profile, and with it
//! what the fit won on a non-additive panel. Readers prefer the LUT tags when a
//! profile has both (ICC.1:2001-04 §6.3.1.2; ArgyllCMS and Little CMS do), and a
//! reader that knows only matrix/TRC still finds the additive part. The same tables
//! are written as `A2B1`/`B2A1` too, since moxcms looks only there for colorimetric
//! intents. A model without terms gets no LUT: the matrix/TRC is exact for it while
//! the black lies inside the primaries' triangle.
//!
//! The tables are laid out so that the grid holds what is smooth and the 1-D tables
//! what is not (ICC.1:2001-04 §6.5.7):
//! * `A2B0`: each input table maps the device value to its channel's share of full
//!   light, ê = E(v) / E(1) (through the calibration curves, if any); the grid, over
//!   the three shares, holds PCS XYZ as fractions of each output table's top (a
//!   straight line from 0, chosen by `output_top` so that the black falls on a grid
//!   step, as near the identity as that allows). The additive model is linear in the shares and
//!   the interaction term bilinear and the crosstalk term cubic, so the grid
//!   interpolates them almost exactly; the crosstalk in drive follows each channel's
//!   drive, E⁻¹ of its share, steep near black, and is interpolated to 3 × 10⁻⁴ of
//!   white.
//! * `B2A0`: the input tables scale each PCS component to the grid's range (the most
//!   any code gives); the grid holds the shares the model's inverse gives, which are
//!   linear in XYZ for the additive part, so the grid interpolates them almost
//!   exactly; the output tables clip each share to [0, 1] and invert its channel's
//!   curve back to the device. The shares come from the inverse with the terms'
//!   polynomials carried on beyond the gamut (`MonitorModel::extended_light_of`) and
//!   are stored unclipped from −0.25 to 1.25: clamped, the cells crossing the gamut's
//!   surface bent (device white came back as 254.6, edge colours 0.25 ΔE00 off).
//!   Near black the output tables cannot resolve single codes (one entry is 3.7·10⁻⁴
//!   of full light, code 7 of a γ 2.2 channel), but a share of exactly 0 falls on an
//!   entry, so a channel that is off comes back off.
//!
//! The HLG OOTF (`AdditivityTerms::hlg_ootf`) is no polynomial: its gains depend on
//! the direction from black, so the light is homogeneous of degree 1 there rather
//! than smooth (from the shares; through the laws the gains change along a ray from
//! black too). A2B0's grid even in the shares, whose first cell reaches L* 20, gave
//! colours in it up to 2.7 ΔE*ab off; for the OOTF it is even in the shares' cube
//! roots (`grid_exponent`): 0.15 at most over a cube of device values. B2A0's is
//! even in the square roots of XYZ for it (`b2a0_exponent`): a round trip through it
//! and the model over a cube of device values is within 0.23–0.41 ΔE*ab on average
//! and 1.5–1.9 at worst, where even in XYZ it was 0.34–0.84 and 2.6–5.2 (an HLG
//! law's mid-grey, a twentieth of white, came back as device 0.514 for 0.5); its
//! dark greys come back high (device 0.1 within 0.02).
//!
//! PCS XYZ is relative to the profile's white and adapted to D50 as the matrix/TRC
//! tags are, in lut16's XYZ encoding: 0x8000 is 1.0 (ICC.1:2001-04 Table 41).

use nalgebra::{Matrix3, Vector3};

use chromacal_color::Xyz;
use chromacal_model::target::{CalibrationCurves, interpolate};
use chromacal_model::{MonitorModel, ScreenPosition};

/// The ICC PCS illuminant, D50, as ICC.1 gives it (and as it encodes in s15Fixed16).
pub const D50: [f64; 3] = [0.9642, 1.0, 0.8249];

/// Grid points a dimension: 33 keeps the interaction term's curvature under 10⁻⁴ of
/// full light between grid points.
pub const GRID_POINTS: usize = 33;

/// Entries of each 1-D table.
pub const TABLE_ENTRIES: usize = 4096;

/// The B2A0 grid spans each PCS component up to this share above the most any device
/// colour gives (with a brightness limiter, a secondary can be brighter than white).
const PCS_HEADROOM: f64 = 1.02;

/// The largest PCS XYZ component lut16 can encode: 1 + 32767/32768.
const PCS_MAX: f64 = 65535.0 / 32768.0;

/// The B2A0 grid's shares: from `SHARE_LOW`, in `SHARE_STEP`s of the output tables'
/// entries, so that share 0 and share 1 fall exactly on entries 682 and 3410.
const SHARE_LOW: f64 = -0.25;
const SHARE_STEP: f64 = 0.25 / 682.0;

/// One `lut16Type`: three inputs, three outputs, identity matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut16 {
    pub input: [Vec<u16>; 3],
    /// Grid points, first input slowest, three outputs each.
    pub grid: Vec<[u16; 3]>,
    pub output: [Vec<u16>; 3],
}

/// The two tags.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelLuts {
    pub a2b0: Lut16,
    pub b2a0: Lut16,
}

/// A value in [0, 1] as a 16-bit table entry.
fn unit16(v: f64) -> u16 {
    (v * 65535.0).round().clamp(0.0, 65535.0) as u16
}

/// A PCS XYZ component in lut16's encoding, 1.0 at 0x8000.
fn xyz16(v: f64) -> u16 {
    (v * 32768.0).round().clamp(0.0, 65535.0) as u16
}

/// The k-th of `n` evenly spaced values over [0, 1].
fn step(k: usize, n: usize) -> f64 {
    k as f64 / (n - 1) as f64
}

/// g: the A2B0 grid is even in ê^(1/g): 1 for the terms that are polynomials in
/// the shares, 3 with the HLG OOTF (2 left a red with a trace of blue 0.46 ΔE*ab
/// off; 4 and 5 no better than 3).
fn grid_exponent(model: &MonitorModel) -> f64 {
    if model.terms.hlg_ootf.is_some() {
        3.0
    } else {
        1.0
    }
}

/// h: the B2A0 grid is even in XYZ^(1/h): 1 for the terms that are polynomials in
/// the shares, 2 with the HLG OOTF, whose gains turn with the direction from black,
/// so that more of the grid lies where they turn. Over a cube of device values (0.1
/// to 1 in tenths) the round trip through B2A0 and the model went from 0.34–0.84 mean
/// and 2.6–5.2 worst ΔE*ab to 0.23–0.41 and 1.5–1.9 (power and HLG laws, the OOTF
/// from the shares and through the laws); 3 was no better than 2.
fn b2a0_exponent(model: &MonitorModel) -> f64 {
    if model.terms.hlg_ootf.is_some() {
        2.0
    } else {
        1.0
    }
}

/// v^g, v itself for g = 1 (so that those grids are as they always were).
fn spaced(v: f64, g: f64) -> f64 {
    if g == 1.0 { v } else { v.max(0.0).powf(g) }
}

impl ModelLuts {
    /// The tags of `model` at the centre of the screen, through `calibration` when
    /// given, relative to white luminance `white_y` and adapted by `chad` (the same
    /// normalisation as the matrix/TRC tags). `None` for a model without terms, or
    /// one whose matrix cannot be inverted.
    pub fn of(
        model: &MonitorModel,
        calibration: Option<&CalibrationCurves>,
        white_y: f64,
        chad: &Matrix3<f64>,
    ) -> Option<Self> {
        if model.terms.is_empty() || !(white_y > 0.0) {
            return None;
        }
        let unchad = chad.try_inverse()?;
        let gains = model.spatial.gains(ScreenPosition::CENTRE);
        let full: [f64; 3] = [0, 1, 2].map(|c| model.laws[c].full_drive_excitation());
        if full.iter().any(|f| !(*f > 0.0)) {
            return None;
        }
        // ê_c(x): the share of full light at device value x.
        let share = |c: usize, x: f64| -> f64 {
            let drive = calibration.map_or(x, |k| interpolate(&k.curves[c], x));
            (model.laws[c].excitation(drive) / full[c]).clamp(0.0, 1.0)
        };
        let n = GRID_POINTS;
        let g = grid_exponent(model);
        let grid_points =
            || (0..n).flat_map(move |i| (0..n).flat_map(move |j| (0..n).map(move |k| [i, j, k])));
        let pcs_grid: Vec<Vector3<f64>> = grid_points()
            .map(|p| {
                let light = Vector3::from_fn(|c, _| spaced(step(p[c], n), g) * full[c] * gains[c]);
                let xyz = model.light_above_black(&light) + model.black;
                chad * (xyz / white_y)
            })
            .collect();
        let most = [0, 1, 2].map(|j| pcs_grid.iter().map(|v| v[j]).fold(0.0, f64::max));
        // The grid's first point is the black (every share 0).
        let tops = [0, 1, 2].map(|j| output_top(pcs_grid[0][j], most[j]));
        let a2b0 = Lut16 {
            input: [0, 1, 2].map(|c| {
                (0..TABLE_ENTRIES)
                    .map(|i| unit16(spaced(share(c, step(i, TABLE_ENTRIES)), 1.0 / g)))
                    .collect()
            }),
            grid: pcs_grid
                .iter()
                .map(|pcs| [0, 1, 2].map(|j| unit16(pcs[j] / tops[j])))
                .collect(),
            output: tops.map(|top| vec![0, xyz16(top)]),
        };
        // Each PCS component's grid range: the most any device colour gives.
        let range = Vector3::from_fn(|j, _| (most[j] * PCS_HEADROOM).clamp(D50[j], PCS_MAX));
        let high = SHARE_LOW + SHARE_STEP * (TABLE_ENTRIES - 1) as f64;
        let h = b2a0_exponent(model);
        let b2a0 = Lut16 {
            // Entry i stands for the encoded value i/(N − 1) · 65535, that is XYZ
            // PCS_MAX · i/(N − 1).
            input: [0, 1, 2].map(|j| {
                (0..TABLE_ENTRIES)
                    .map(|i| {
                        let x = (step(i, TABLE_ENTRIES) * PCS_MAX / range[j]).min(1.0);
                        unit16(spaced(x, 1.0 / h))
                    })
                    .collect()
            }),
            grid: grid_points()
                .map(|p| {
                    let pcs = Vector3::from_fn(|j, _| spaced(step(p[j], n), h) * range[j]);
                    let xyz: Xyz = unchad * pcs * white_y;
                    let excitation: [f64; 3] = model
                        .extended_light_of(&xyz)
                        .map(|light| [0, 1, 2].map(|c| light[c] / gains[c]))
                        .or_else(|| {
                            let found = model.inverse(&xyz, ScreenPosition::CENTRE).ok()?;
                            Some(found.excitation)
                        })
                        .unwrap_or([0.0; 3]);
                    [0, 1, 2].map(|c| {
                        let e = excitation[c] / full[c];
                        unit16((e - SHARE_LOW) / (high - SHARE_LOW))
                    })
                })
                .collect(),
            output: [0, 1, 2].map(|c| {
                (0..TABLE_ENTRIES)
                    .map(|i| {
                        let e = SHARE_LOW + SHARE_STEP * i as f64;
                        unit16(device_for_share(|x| share(c, x), e))
                    })
                    .collect()
            }),
        };
        Some(ModelLuts { a2b0, b2a0 })
    }
}

/// The top of an A2B0 output table (a straight line from 0), as a PCS value: the
/// grid then stores each component as a fraction of it, in steps of top/65535.
///
/// Why not always the identity (top 65535, one encoding step a grid step): in lut16's
/// XYZ encoding a step is 1/32768 of the white, and near black, where CIELAB's a* and
/// b* grow 3,900 times faster than X, Y and Z, rounding the black to a step moved a
/// panel's black 0.12 ΔE00 off the model for a reader that interpolates in floating
/// point (ArgyllCMS). So the top is the largest that holds `most` for which the `black`
/// falls on a grid step within 10⁻³ of an encoding step. Why the largest: a reader
/// that evaluates the tables in 16 bits (Little CMS) rounds twice when the top is not
/// the identity's, and the nearer the identity the less that second rounding costs; a
/// black below any step (an OLED's) keeps the identity.
fn output_top(black: f64, most: f64) -> f64 {
    let units = |v: f64| (v * 32768.0).clamp(0.0, 65535.0);
    let (black, least) = (units(black), units(most).ceil().max(1.0) as u32);
    let miss = |top: u32| {
        let steps = black * 65535.0 / top as f64;
        (steps - steps.round()).abs() * top as f64 / 65535.0
    };
    let top = (least..=65535)
        .rev()
        .find(|top| miss(*top) < 1e-3)
        .unwrap_or(65535);
    top as f64 / 32768.0
}

/// The smallest device value whose share reaches `target`, by bisection (the share
/// never decreases with the device value); 0 below the least share, 1 above the most.
fn device_for_share(share: impl Fn(f64) -> f64, target: f64) -> f64 {
    if share(1.0) <= target {
        return 1.0;
    }
    if target <= share(0.0) {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if share(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A `lut16Type` element (ICC.1:2001-04 §6.5.7): signature, reserved, the channel and
/// grid counts, the identity matrix (s15Fixed16), the table lengths, then the input
/// tables, the grid and the output tables, big-endian.
pub fn lut16_bytes(lut: &Lut16) -> Vec<u8> {
    let grid_points = (lut.grid.len() as f64).cbrt().round() as u8;
    let mut out = Vec::with_capacity(52 + 2 * (3 * lut.input[0].len() + 3 * lut.grid.len()));
    out.extend_from_slice(b"mft2");
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&[3, 3, grid_points, 0]);
    for row in 0..3 {
        for column in 0..3 {
            let one: i32 = if row == column { 65536 } else { 0 };
            out.extend_from_slice(&one.to_be_bytes());
        }
    }
    out.extend_from_slice(&(lut.input[0].len() as u16).to_be_bytes());
    out.extend_from_slice(&(lut.output[0].len() as u16).to_be_bytes());
    let mut put = |v: u16| out.extend_from_slice(&v.to_be_bytes());
    lut.input.iter().flatten().copied().for_each(&mut put);
    lut.grid.iter().flatten().copied().for_each(&mut put);
    lut.output.iter().flatten().copied().for_each(&mut put);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::SpatialMap;
    use chromacal_model::monitor::AdditivityTerms;
    use chromacal_model::transfer::{Power, TransferLaw};

    fn model(terms: AdditivityTerms) -> MonitorModel {
        MonitorModel {
            matrix: Matrix3::new(
                41.24, 35.76, 18.05, //
                21.26, 71.52, 7.22, //
                1.93, 11.92, 95.05,
            ),
            black: Xyz::new(0.2, 0.21, 0.25),
            laws: [0, 1, 2].map(|_| TransferLaw::Power(Power { gamma: 2.2 })),
            spatial: SpatialMap::Uniform,
            terms,
        }
    }

    /// Trilinear lookup of a grid, coordinates in [0, 1].
    fn lookup(lut: &Lut16, t: [f64; 3]) -> [f64; 3] {
        let n = GRID_POINTS;
        let at = |i: usize, j: usize, k: usize| lut.grid[(i * n + j) * n + k];
        let cell = t.map(|v| ((v * (n - 1) as f64).floor() as usize).min(n - 2));
        let f = [0, 1, 2].map(|c| t[c] * (n - 1) as f64 - cell[c] as f64);
        let mut out = [0.0; 3];
        for corner in 0..8 {
            let d = [corner >> 2 & 1, corner >> 1 & 1, corner & 1];
            let w: f64 = (0..3)
                .map(|c| if d[c] == 1 { f[c] } else { 1.0 - f[c] })
                .product();
            let v = at(cell[0] + d[0], cell[1] + d[1], cell[2] + d[2]);
            for o in 0..3 {
                out[o] += w * v[o] as f64;
            }
        }
        out
    }

    /// Grid coordinates of inputs `v` (each in [0, 1]) through the input tables.
    fn through_inputs(lut: &Lut16, v: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|c| {
            let table: Vec<f64> = lut.input[c].iter().map(|e| *e as f64 / 65535.0).collect();
            interpolate(&table, v[c])
        })
    }

    /// A2B0 as a reader evaluates it: the grid, then the output tables, straight
    /// lines from 0; PCS XYZ.
    fn forward_lookup(lut: &Lut16, shares: [f64; 3]) -> [f64; 3] {
        let grid = lookup(lut, shares);
        [0, 1, 2].map(|o| {
            assert_eq!(lut.output[o].len(), 2);
            grid[o] / 65535.0 * lut.output[o][1] as f64 / 32768.0
        })
    }

    #[test]
    fn only_a_model_with_terms_gets_tables() {
        let chad = Matrix3::identity();
        assert!(ModelLuts::of(&model(AdditivityTerms::default()), None, 100.0, &chad).is_none());
    }

    /// A model with each gain term: the interaction, crosstalk, crosstalk in drive.
    fn gain_term_models() -> [MonitorModel; 3] {
        [
            model(AdditivityTerms {
                interaction: Some([-0.08, -0.05, -0.1]),
                ..Default::default()
            }),
            model(AdditivityTerms {
                crosstalk: Some([0.12, 0.08, 0.1]),
                ..Default::default()
            }),
            model(AdditivityTerms {
                drive_crosstalk: Some([0.09, 0.07, 0.1]),
                ..Default::default()
            }),
        ]
    }

    #[test]
    fn the_forward_grid_gives_the_model_with_its_gain_terms() {
        for m in gain_term_models() {
            forward_grid_gives_the_model(&m);
        }
    }

    fn forward_grid_gives_the_model(m: &MonitorModel) {
        let white_y = m.white().y;
        let chad = Matrix3::identity();
        let luts = ModelLuts::of(m, None, white_y, &chad).unwrap();
        let mut worst: f64 = 0.0;
        for rgb in [[0.5, 0.5, 0.5], [1.0, 0.3, 0.7], [0.2, 0.9, 0.1], [1.0; 3]] {
            let got = forward_lookup(&luts.a2b0, through_inputs(&luts.a2b0, rgb));
            let want = m.forward_centre(rgb) / white_y;
            for j in 0..3 {
                worst = worst.max((got[j] - want[j]).abs());
            }
        }
        // 1.5 × 10⁻⁵ is the encoding's step; the grid adds the term's curvature. The
        // crosstalk in drive follows δ = E⁻¹(ê), no polynomial in the grid's shares
        // (steepest near black), so it gets 3 × 10⁻⁴ of white at worst here; on the
        // Lenovo's profile the judge finds the ICC 0.002 ΔE00 behind its model.
        let tolerance = if m.terms.drive_crosstalk.is_some() {
            4e-4
        } else {
            1e-4
        };
        assert!(worst < tolerance, "{worst}");
        // The black, where a* and b* are most sensitive, comes out as the model's, to
        // far below the encoding's step.
        let black = forward_lookup(&luts.a2b0, through_inputs(&luts.a2b0, [0.0; 3]));
        let want = m.black / white_y;
        for j in 0..3 {
            assert!((black[j] - want[j]).abs() < 1e-7, "{black:?} {want:?}");
        }
        // Without the term the same colours would be off by it.
        let plain = model(AdditivityTerms::default());
        let grey = (plain.forward_centre([0.5; 3]) - m.forward_centre([0.5; 3])).norm() / white_y;
        assert!(grey > 5e-3, "{grey}");
    }

    #[test]
    fn the_output_top_holds_the_brightest_and_puts_the_black_on_a_step() {
        for (black, most) in [
            (0.00117, 0.9642),
            (0.0, 1.0),
            (0.0035, 1.7),
            (0.0021, 0.825),
        ] {
            let top = output_top(black, most);
            assert!(top >= most && top <= PCS_MAX, "{top}");
            // How far the black is from a grid step, in the encoding's steps.
            let steps = black / top * 65535.0;
            let miss = (steps - steps.round()).abs() * top / 65535.0 * 32768.0;
            assert!(miss < 1e-3, "black {black}, most {most}: {miss}");
        }
        // Beyond what lut16 can encode, and with a black no step can hold, the top is
        // the encoding's.
        assert_eq!(output_top(0.01, 2.5), PCS_MAX);
        assert_eq!(output_top(2e-8, 1.0), PCS_MAX);
        // The black on a step, as near the identity as that allows.
        assert!(output_top(0.00117, 0.9642) > 0.97 * PCS_MAX);
    }

    #[test]
    fn the_inverse_grid_and_output_tables_give_back_the_device_values() {
        // Through the input tables as a reader applies them (which put the crosstalk
        // in drive's dark red 2.1 × 10⁻³ off where the grid's range alone gave less).
        for m in gain_term_models() {
            inverse_gives_back_the_device_values(
                &m,
                &[[0.5, 0.5, 0.5], [0.9, 0.3, 0.7], [0.2, 0.8, 0.4]],
                2.5e-3,
            );
        }
    }

    fn inverse_gives_back_the_device_values(
        m: &MonitorModel,
        colours: &[[f64; 3]],
        tolerance: f64,
    ) {
        let white_y = m.white().y;
        let luts = ModelLuts::of(m, None, white_y, &Matrix3::identity()).unwrap();
        for &rgb in colours {
            let device = b2a0_device(&luts, &(m.forward_centre(rgb) / white_y));
            for c in 0..3 {
                assert!(
                    (device[c] - rgb[c]).abs() < tolerance,
                    "{rgb:?} channel {c}: {}",
                    device[c]
                );
            }
        }
    }

    /// The HLG OOTF through the tables: every colour of a cube of device values,
    /// the dark greys where its gains turn with the direction from black included,
    /// within 0.05 ΔE*ab of the model forward, and back to its device values.
    #[test]
    fn the_tables_carry_the_hlg_ootf_down_to_black() {
        let ootf = |through_laws: bool| AdditivityTerms {
            hlg_ootf: Some(1.16),
            hlg_ootf_through_laws: through_laws,
            ..Default::default()
        };
        // Power laws (not the HLG law, so the OOTF's two forms differ), and the HLG
        // law, what an HLG run publishes, where a mid-grey is a twentieth of white.
        let hlg_law = [0, 1, 2].map(|_| {
            TransferLaw::Hlg(chromacal_model::transfer::Hlg {
                exponent: 1.16,
                curvature: 0.0,
                toe: 0.0,
            })
        });
        for through_laws in [false, true] {
            hlg_ootf_tables_hold(&model(ootf(through_laws)), 0.2);
            hlg_ootf_tables_hold(
                &MonitorModel {
                    laws: hlg_law.clone(),
                    ..model(ootf(through_laws))
                },
                0.2,
            );
        }
        // Through the laws with the light beyond full signal measured, blue's bent
        // (a panel that flattens where only mixtures drive it), and blue unmeasured.
        for (beyond, tolerance) in [([1.2, 1.2, 0.54], 0.21), ([1.1, 1.3, 0.0], 0.2)] {
            let terms = AdditivityTerms {
                hlg_ootf_beyond: Some(beyond),
                ..ootf(true)
            };
            hlg_ootf_tables_hold(&model(terms.clone()), tolerance);
            hlg_ootf_tables_hold(
                &MonitorModel {
                    laws: hlg_law.clone(),
                    ..model(terms)
                },
                tolerance,
            );
        }
    }

    /// A2B0 within `a2b0_tolerance` ΔE*ab of the model over a cube of device values
    /// (0.2; 0.21 where blue's light beyond full signal bends to a power of 0.54, its
    /// slope stepping at full signal inside a grid cell: 0.203); B2A0 then the
    /// model back within 0.5 ΔE*ab on average and 2 at worst over another (0.1 to 1
    /// in tenths: with its grid even in XYZ, 0.34–0.84 and 2.6–5.2), and a dark grey
    /// back within 0.02 of its device value.
    fn hlg_ootf_tables_hold(m: &MonitorModel, a2b0_tolerance: f64) {
        use chromacal_color::spaces::xyz_to_lab;
        let white_y = m.white().y;
        let luts = ModelLuts::of(m, None, white_y, &Matrix3::identity()).unwrap();
        let white = m.white() / white_y;
        let lab_miss = |a: Xyz, b: Xyz| {
            let (a, b) = (xyz_to_lab(&a, &white), xyz_to_lab(&b, &white));
            ((a.l - b.l).powi(2) + (a.a - b.a).powi(2) + (a.b - b.b).powi(2)).sqrt()
        };
        let mut worst: f64 = 0.0;
        let levels = [0.0, 0.03, 0.06, 0.1, 0.2, 0.35, 0.5, 0.8, 1.0];
        for r in levels {
            for g in levels {
                for b in levels {
                    let rgb = [r, g, b];
                    let got = forward_lookup(&luts.a2b0, through_inputs(&luts.a2b0, rgb));
                    let want = m.forward_centre(rgb) / white_y;
                    worst = worst.max(lab_miss(Xyz::from(got), want));
                }
            }
        }
        assert!(worst < a2b0_tolerance, "A2B0 {:?}: {worst}", m.terms);
        let (mut worst, mut sum, mut n): (f64, f64, f64) = (0.0, 0.0, 0.0);
        let tenths: Vec<f64> = (1..=10).map(|k| f64::from(k) / 10.0).collect();
        for &r in &tenths {
            for &g in &tenths {
                for &b in &tenths {
                    let pcs = m.forward_centre([r, g, b]) / white_y;
                    let device = b2a0_device(&luts, &pcs);
                    let miss = lab_miss(m.forward_centre(device) / white_y, pcs);
                    (worst, sum, n) = (worst.max(miss), sum + miss, n + 1.0);
                }
            }
        }
        let mean = sum / n;
        assert!(
            mean < 0.5 && worst < 2.0,
            "B2A0 {:?} {:?}: mean {mean}, worst {worst}",
            m.laws[0].kind(),
            m.terms
        );
        inverse_gives_back_the_device_values(m, &[[0.1; 3]], 0.02);
    }

    /// The device values B2A0 gives for PCS XYZ `pcs` (relative to white): each input
    /// table's entry i stands for XYZ PCS_MAX · i / (N − 1).
    fn b2a0_device(luts: &ModelLuts, pcs: &Xyz) -> [f64; 3] {
        let t = through_inputs(&luts.b2a0, [0, 1, 2].map(|j| pcs[j] / PCS_MAX));
        let shares = lookup(&luts.b2a0, t).map(|v| v / 65535.0);
        [0, 1, 2].map(|c| {
            let table: Vec<f64> = luts.b2a0.output[c]
                .iter()
                .map(|v| *v as f64 / 65535.0)
                .collect();
            interpolate(&table, shares[c])
        })
    }

    #[test]
    fn the_element_has_the_layout_of_lut16() {
        let m = model(AdditivityTerms {
            interaction: Some([0.01, 0.02, 0.03]),
            ..Default::default()
        });
        let luts = ModelLuts::of(&m, None, m.white().y, &Matrix3::identity()).unwrap();
        let bytes = lut16_bytes(&luts.a2b0);
        assert_eq!(&bytes[0..4], b"mft2");
        assert_eq!(bytes[8..11], [3, 3, GRID_POINTS as u8]);
        assert_eq!(i32::from_be_bytes(bytes[12..16].try_into().unwrap()), 65536);
        assert_eq!(
            u16::from_be_bytes([bytes[48], bytes[49]]) as usize,
            TABLE_ENTRIES
        );
        assert_eq!(u16::from_be_bytes([bytes[50], bytes[51]]), 2);
        let expected = 52 + 2 * (3 * TABLE_ENTRIES + 3 * GRID_POINTS.pow(3) + 3 * 2);
        assert_eq!(bytes.len(), expected);
    }
}
