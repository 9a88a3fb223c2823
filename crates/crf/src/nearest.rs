//! The nearest of a pixel's candidate codes in ΔE00, without a ΔE00 for each.
//!
//! A pixel's drive lies between 8 codes (each channel's code below and above it), and
//! the default render keeps the one whose colour, by the forward model, is nearest in
//! ΔE00 to the colour asked for. Taken literally that is eight CIEDE2000 differences
//! and eight L*a*b* conversions a pixel: four fifths of a whole render's time. The
//! candidates are close to the colour asked for (a code step away), so each one's
//! ΔE00 is first bounded from the colour's tangent: L*a*b* to first order in the XYZ
//! step ([`LabTangent`]), and CIEDE2000 to first order in the L*a*b* step
//! ([`LocalDeltaE2000`]), each with a bound on what the first order leaves out. Only
//! the candidates whose bounds overlap the best one's are measured exactly, in the
//! order and with the ties of the literal search, so the codes are the same; at 16
//! bits that is one candidate for most pixels.

use chromacal_color::Xyz;
use chromacal_color::difference::{LocalDeltaE2000, delta_e_2000};
use chromacal_color::spaces::{Lab, LabTangent, xyz_to_lab};

/// The most candidates a pixel has: its rounded codes, then the 8 corners.
pub const MOST: usize = 9;

/// Of `candidates` (codes and the colour they show, the first the rounded codes), the
/// index of the first whose colour is nearest in ΔE00 to `asked` (whose L*a*b* against
/// `white` is `asked_lab`): the same index as measuring each and keeping the first
/// strictly smaller. With it, the winner's ΔE00 when `error_wanted` or when it had to be
/// measured anyway.
pub fn nearest(
    candidates: &[([u32; 3], Xyz)],
    asked: &Xyz,
    asked_lab: &Lab,
    white: &Xyz,
    error_wanted: bool,
) -> (usize, Option<f64>) {
    let exact = |k: usize| delta_e_2000(asked_lab, &xyz_to_lab(&candidates[k].1, white));
    let mut possible = [true; MOST];
    if let Some(local) = LocalDeltaE2000::at(asked_lab) {
        let tangent = LabTangent::at(asked, white, asked_lab);
        // Each candidate's ΔE00 bounded: its step to first order, the first order's
        // error for that step, and the form's error for its size.
        let mut ranges = [(0.0, f64::INFINITY); MOST];
        for (range, (_, shown)) in ranges.iter_mut().zip(candidates) {
            let step = [shown.x - asked.x, shown.y - asked.y, shown.z - asked.z];
            let delta = tangent.delta(step);
            let lab_error = tangent.error(step);
            let size = delta.iter().fold(lab_error, |m, d| m.max(d.abs()));
            let relative = local.bound(size);
            if relative < 1.0 && lab_error.is_finite() {
                // |ΔE00 − d| ≤ relative · ΔE00 for the step taken, and ΔE00 moves by
                // at most 4 × the step's error (its weights are at most 1, R_T at
                // most 2 in size).
                let d = local.delta_e(delta);
                let slack = 4.0 * lab_error;
                *range = (d / (1.0 + relative) - slack, d / (1.0 - relative) + slack);
            }
        }
        let ranges = &ranges[..candidates.len()];
        let least_upper = ranges.iter().fold(f64::INFINITY, |m, r| m.min(r.1));
        for (p, range) in possible.iter_mut().zip(ranges) {
            *p = range.0 <= least_upper;
        }
    }
    let mut best: Option<(usize, f64)> = None;
    let survivors = possible[..candidates.len()].iter().filter(|p| **p).count();
    for k in (0..candidates.len()).filter(|&k| possible[k]) {
        if survivors == 1 {
            return (k, error_wanted.then(|| exact(k)));
        }
        let error = exact(k);
        if best.is_none_or(|(_, e)| error < e) {
            best = Some((k, error));
        }
    }
    match best {
        Some((k, error)) => (k, Some(error)),
        // Unreachable: the least square's own candidate always survives.
        None => (0, Some(exact(0))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The literal search: every candidate measured, the first strictly smaller kept.
    fn literal(candidates: &[([u32; 3], Xyz)], asked_lab: &Lab, white: &Xyz) -> (usize, f64) {
        let mut best = (
            0,
            delta_e_2000(asked_lab, &xyz_to_lab(&candidates[0].1, white)),
        );
        for (k, (_, shown)) in candidates.iter().enumerate().skip(1) {
            let e = delta_e_2000(asked_lab, &xyz_to_lab(shown, white));
            if e < best.1 {
                best = (k, e);
            }
        }
        best
    }

    /// Candidates a code step around random colours, from black to white and from
    /// neutral to saturated, steps from 16-bit to 6-bit sizes, some of them equal: the
    /// same winner as the literal search, every time.
    #[test]
    fn the_bounded_search_finds_the_literal_one() {
        let white = Xyz::new(95.0, 100.0, 108.9);
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x1234_5678_9ABC_DEF1);
        let mut uniform = move || rng.random::<f64>();
        let mut measured = 0;
        for i in 0..100_000 {
            let y = 100.0 * uniform().powi(3);
            // One in four near the neutral axis (within 10⁻³ of the white's
            // chromaticity), where the hue has no direction.
            let spread = if i % 4 == 0 { 1e-3 } else { 1.0 };
            let asked = Xyz::new(
                y * 0.95 * (1.0 + spread * (uniform() - 0.5)),
                y,
                y * 1.089 * (1.0 + spread * (uniform() - 0.5)),
            );
            let step = y.max(0.01) * 10f64.powf(-5.0 + 3.5 * uniform());
            let mut candidates = Vec::new();
            for _ in 0..MOST {
                let shown = Xyz::new(
                    (asked.x + step * (2.0 * uniform() - 1.0)).max(0.0),
                    (asked.y + step * (2.0 * uniform() - 1.0)).max(0.0),
                    (asked.z + step * (2.0 * uniform() - 1.0)).max(0.0),
                );
                candidates.push(([0, 0, 0], shown));
            }
            if i % 7 == 0 {
                candidates[3] = candidates[1];
            }
            let asked_lab = xyz_to_lab(&asked, &white);
            let (k, error) = nearest(&candidates, &asked, &asked_lab, &white, true);
            let (want, want_error) = literal(&candidates, &asked_lab, &white);
            assert_eq!(k, want, "{asked:?}, step {step}: {candidates:?}");
            assert_eq!(error, Some(want_error));
            let (k, error) = nearest(&candidates, &asked, &asked_lab, &white, false);
            assert_eq!(k, want);
            measured += usize::from(error.is_some());
        }
        // Most pixels are decided without a ΔE00.
        assert!(measured < 50_000, "{measured} of 100000 measured");
    }
}
