//! Uniformity over the screen, judged as the soft-proofing standards judge it (ISO
//! 12646:2008/2015 §4, the tolerances ISO 14861:2015's displays are held to): white
//! (255), grey (128) and dark grey (64), through what the display holds, read at every
//! position of an n × n grid (the instrument moved there by hand, at a prompt); each
//! position's luminance against the centre's, within 10, 13 and 15 % (5, 6.5 and
//! 7.5 % recommended), and the chromaticity of each grey within Δu′v′ 0.01 of the
//! centre's.
//!
//! Every deviation comes with its 95 % interval from the session's noise (the same
//! relative noise, floor and per-component noise the chart's intervals rest on:
//! `evaluate`), drawn as the chart's are, and every position with a verdict.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use chromacal_color::spaces::xyz_to_uv_prime;
use chromacal_color::{UvPrime, Xyz};

use super::criteria::Verdict;

/// The levels read at each position, as the display's codes (R = G = B), and the
/// largest luminance deviation from the centre each may have: ISO 12646's "shall",
/// and its "should".
pub const LEVELS: [(f64, f64, f64); 3] = [
    (1.0, 0.10, 0.05),
    (128.0 / 255.0, 0.13, 0.065),
    (64.0 / 255.0, 0.15, 0.075),
];

/// The largest Δu′v′ of a neutral from the centre's (ISO 12646).
pub const DELTA_UV_LIMIT: f64 = 0.01;

/// Draws of the readings for the intervals.
const DRAWS: usize = 400;

/// One level at one position, against the centre.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UniformityPoint {
    /// Column and row of the grid, from the top left.
    pub column: usize,
    pub row: usize,
    /// The patch's centre, fractions of the screen's width and height.
    pub position: [f64; 2],
    /// The code level, R = G = B in [0, 1].
    pub level: f64,
    pub xyz: [f64; 3],
    /// Luminance over the centre's, minus one, with its 95 % interval.
    pub luminance_deviation: f64,
    pub luminance_interval: [f64; 2],
    /// Distance in u′v′ from the centre's chromaticity, with its 95 % interval.
    pub delta_uv: f64,
    pub delta_uv_interval: [f64; 2],
    pub verdict: Verdict,
}

/// The grid, judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uniformity {
    pub grid: usize,
    pub points: Vec<UniformityPoint>,
    /// The largest |luminance deviation| at each level, in the order of [`LEVELS`].
    pub worst_luminance: Vec<f64>,
    pub worst_delta_uv: f64,
    /// Within the recommended tolerances everywhere too.
    pub recommended: bool,
    pub verdict: Verdict,
}

/// The session's noise the intervals are drawn from: the relative noise of a
/// reading, the part of it each component has on its own, and the floor.
#[derive(Debug, Clone, Copy)]
pub struct Noise {
    pub relative: f64,
    pub independent: f64,
    pub floor: f64,
}

/// The levels of [`LEVELS`] as a chart of the display's own codes (through
/// whatever its video LUT holds, as the standard reads them).
pub fn chart() -> super::Chart {
    super::Chart {
        name: "uniformity (ISO 12646)".into(),
        patches: LEVELS
            .iter()
            .map(|&(level, _, _)| super::ChartPatch {
                label: format!("grey {:.0}", 255.0 * level),
                kind: super::Kind::Grey,
                input: super::Input::Display([level; 3]),
            })
            .collect(),
    }
}

/// A grid has a centre to set the rest against: an odd size, at least 3 (and at
/// most 15: 675 readings by hand are more than anyone moves an instrument for).
pub fn check_grid(grid: usize) -> Result<(), String> {
    if grid < 3 || grid.is_multiple_of(2) || grid > 15 {
        return Err(format!(
            "the uniformity grid is {grid} × {grid}: it needs an odd size from 3 to 15, for a centre"
        ));
    }
    Ok(())
}

/// The 95 % interval of `value` from its draws (the basic bootstrap, as the chart's).
fn interval(draws: &mut [f64], value: f64, floor_at_zero: bool) -> [f64; 2] {
    draws.sort_by(f64::total_cmp);
    let q = |p: f64| draws[((draws.len() - 1) as f64 * p).round() as usize];
    let (lo, hi) = (2.0 * value - q(0.975), 2.0 * value - q(0.025));
    let lo = if floor_at_zero { lo.max(0.0) } else { lo };
    [lo.min(value), hi.max(value)]
}

/// Judge `readings[position][level]` of an `grid` × `grid` grid (positions in rows
/// from the top left, the levels of [`LEVELS`]), each a mean of one reading.
pub fn judge(grid: usize, readings: &[Vec<Xyz>], noise: Noise) -> Result<Uniformity, String> {
    check_grid(grid)?;
    if readings.len() != grid * grid || readings.iter().any(|r| r.len() != LEVELS.len()) {
        return Err("the uniformity readings do not fill the grid".into());
    }
    let centre = grid * grid / 2;
    let mut rng = ChaCha8Rng::seed_from_u64(14861);
    let unit = Normal::new(0.0, 1.0).map_err(|e| e.to_string())?;
    let shared = (noise.relative.powi(2) - noise.independent.powi(2))
        .max(0.0)
        .sqrt();
    // One draw of a reading: a gain common to X, Y, Z, each component's own noise,
    // the floor.
    let mut draw = |xyz: &Xyz| -> Xyz {
        let gain = 1.0 + shared * unit.sample(&mut rng);
        let mut out = [0.0; 3];
        for (c, v) in out.iter_mut().enumerate() {
            let own = 1.0 + noise.independent * unit.sample(&mut rng);
            *v = xyz[c] * gain * own + noise.floor * unit.sample(&mut rng);
        }
        Xyz::new(out[0], out[1], out[2])
    };
    let mut points = Vec::new();
    let mut worst_luminance = vec![0.0f64; LEVELS.len()];
    let (mut worst_delta_uv, mut verdicts, mut recommended) = (0.0f64, Vec::new(), true);
    for (position, levels) in readings.iter().enumerate() {
        if position == centre {
            continue;
        }
        let (row, column) = (position / grid, position % grid);
        for (k, &(level, limit, should)) in LEVELS.iter().enumerate() {
            let (here, middle) = (levels[k], readings[centre][k]);
            if !(middle.y > 0.0) {
                return Err(format!(
                    "the centre read no light at the {:.0} % level",
                    100.0 * level
                ));
            }
            let deviation = here.y / middle.y - 1.0;
            let uv = |c: &Xyz| xyz_to_uv_prime(c, UvPrime { u: 0.0, v: 0.0 });
            let delta_uv = |a: &Xyz, b: &Xyz| {
                let (p, q) = (uv(a), uv(b));
                ((p.u - q.u).powi(2) + (p.v - q.v).powi(2)).sqrt()
            };
            let distance = delta_uv(&here, &middle);
            let (mut lum, mut chroma): (Vec<f64>, Vec<f64>) = (0..DRAWS)
                .map(|_| {
                    let (a, b) = (draw(&here), draw(&middle));
                    ((a.y / b.y - 1.0).abs(), delta_uv(&a, &b))
                })
                .unzip();
            let luminance_interval = interval(&mut lum, deviation.abs(), true);
            let delta_uv_interval = interval(&mut chroma, distance, true);
            let v = Verdict::all([
                Verdict::of(luminance_interval, limit),
                Verdict::of(delta_uv_interval, DELTA_UV_LIMIT),
            ]);
            recommended &= deviation.abs() <= should && distance <= DELTA_UV_LIMIT;
            worst_luminance[k] = worst_luminance[k].max(deviation.abs());
            worst_delta_uv = worst_delta_uv.max(distance);
            verdicts.push(v);
            points.push(UniformityPoint {
                column,
                row,
                position: [
                    (column as f64 + 0.5) / grid as f64,
                    (row as f64 + 0.5) / grid as f64,
                ],
                level,
                xyz: [here.x, here.y, here.z],
                luminance_deviation: deviation,
                luminance_interval: if deviation < 0.0 {
                    [-luminance_interval[1], -luminance_interval[0]]
                } else {
                    luminance_interval
                },
                delta_uv: distance,
                delta_uv_interval,
                verdict: v,
            });
        }
    }
    let verdict = Verdict::all(verdicts);
    Ok(Uniformity {
        grid,
        points,
        worst_luminance,
        worst_delta_uv,
        recommended,
        verdict,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_of(falloff: f64) -> Vec<Vec<Xyz>> {
        let grey = |k: usize| [1.0, 0.5, 0.25][k];
        (0..25)
            .map(|p| {
                let (row, column) = (p / 5, p % 5);
                let r2 = ((row as f64 - 2.0).powi(2) + (column as f64 - 2.0).powi(2)) / 8.0;
                (0..3)
                    .map(|k| Xyz::new(95.0, 100.0, 108.0) * grey(k) * (1.0 - falloff * r2))
                    .collect()
            })
            .collect()
    }

    const QUIET: Noise = Noise {
        relative: 0.002,
        independent: 0.001,
        floor: 0.001,
    };

    #[test]
    fn a_screen_within_the_tolerances_passes_and_one_beyond_fails_at_its_corners() {
        let flat = judge(5, &grid_of(0.04), QUIET).unwrap();
        assert_eq!(flat.verdict, Verdict::Pass);
        assert!(flat.recommended);
        assert_eq!(flat.points.len(), 24 * 3);
        assert!((flat.worst_luminance[0] - 0.04).abs() < 1e-9);
        let dim = judge(5, &grid_of(0.2), QUIET).unwrap();
        assert_eq!(dim.verdict, Verdict::Fail);
        let failed: Vec<_> = dim
            .points
            .iter()
            .filter(|p| p.verdict == Verdict::Fail)
            .map(|p| (p.row, p.column))
            .collect();
        // The corners (20 % down) fail at every level; the edge centres (10 %, on
        // the limit) do not.
        assert!(failed.contains(&(0, 0)) && failed.contains(&(4, 4)));
        assert!(!failed.contains(&(0, 2)));
    }

    #[test]
    fn near_the_limit_the_noise_leaves_it_undecided_and_the_grid_needs_a_centre() {
        let noisy = Noise {
            relative: 0.02,
            independent: 0.005,
            floor: 0.001,
        };
        // Corners 9.5 % down, against 10 %, with 2 % noise a reading.
        let close = judge(5, &grid_of(0.095), noisy).unwrap();
        assert_eq!(close.verdict, Verdict::Undecided);
        assert!(judge(4, &vec![vec![Xyz::new(1.0, 1.0, 1.0); 3]; 16], QUIET).is_err());
        assert!(judge(5, &grid_of(0.0)[..24], QUIET).is_err());
    }
}
