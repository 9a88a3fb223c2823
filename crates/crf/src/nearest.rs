//! The nearest of a pixel's candidate codes in ΔE00, without a ΔE00 for each.
//!
//! A pixel's drive lies between 8 codes (each channel's code below and above it), and
//! the default render keeps the one whose colour, by the forward model, is nearest in
//! ΔE00 to the colour asked for. Taken literally that is eight CIEDE2000 differences
//! and eight L*a*b* conversions a pixel: four fifths of a whole render's time. The
//! candidates are close to the colour asked for (a code step away), so each one's
//! ΔE00 is first bounded from the colour's tangent: L*a*b* to second order in the XYZ
//! step ([`LabTangent`]), and CIEDE2000 to first order in the L*a*b* step
//! ([`LocalDeltaE2000`]), each with a bound on what it leaves out. Only the
//! candidates whose bounds overlap the best one's are measured exactly, in the order
//! and with the ties of the literal search, so the codes are the same. On random
//! 2048² scenes in the gamut one candidate is left for 97–99.9 % of pixels at 16
//! bits and for 73–83 % at 8 bits (7–37 % with L*a*b* to first order). The bounds take
//! the candidates as steps from the colour asked, which for a profile without
//! additivity terms are the low corner's step and the box's three edges added: no
//! matrix product a candidate until one is measured.
//! From 10 bits the candidates are screened first with one bound for all of them
//! ([`Neighbourhood::sole_candidate`]), which compares their forms squared; from 12
//! bits, before that, with the tangent to first order, which gives the eight corners'
//! forms from four weighted steps by additions ([`Neighbourhood::sole_corner`]).

use chromacal_color::Xyz;
use chromacal_color::difference::LocalDeltaE2000;
use chromacal_color::spaces::{Lab, LabTangent};

/// Of candidates whose ΔE00 to the colour asked lies in `ranges` (from
/// [`Neighbourhood::ranges`]), and is `exact(k)` when measured, the index of the first whose
/// ΔE00 is least: the same index as measuring each and keeping the first strictly
/// smaller. With it, the winner's ΔE00 when `error_wanted` or when it had to be
/// measured anyway.
pub fn choose(
    ranges: &[(f64, f64)],
    exact: impl Fn(usize) -> f64,
    error_wanted: bool,
) -> (usize, Option<f64>) {
    let least_upper = least_upper(ranges);
    let possible = |k: usize| ranges[k].0 <= least_upper;
    let survivors = survivors(ranges);
    let mut best: Option<(usize, f64)> = None;
    for k in (0..ranges.len()).filter(|&k| possible(k)) {
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
        // Unreachable: the least upper bound's own candidate always survives.
        None => (0, Some(exact(0))),
    }
}

/// The least of the ranges' upper ends: no candidate whose lower end lies above it
/// can be nearest.
fn least_upper(ranges: &[(f64, f64)]) -> f64 {
    ranges.iter().fold(f64::INFINITY, |m, r| m.min(r.1))
}

/// How many of the candidates whose ΔE00 lies in `ranges` could be nearest.
fn survivors(ranges: &[(f64, f64)]) -> usize {
    let least_upper = least_upper(ranges);
    ranges.iter().filter(|r| r.0 <= least_upper).count()
}

/// The colour asked for, prepared for bounding the ΔE00 of steps from it: its
/// L*a*b* tangent and its local CIEDE2000 form (none on the neutral axis).
pub struct Neighbourhood {
    tangent: LabTangent,
    local: Option<LocalDeltaE2000>,
}

impl Neighbourhood {
    pub fn at(asked: &Xyz, asked_lab: &Lab, white: &Xyz) -> Neighbourhood {
        Neighbourhood {
            tangent: LabTangent::at(asked, white, asked_lab),
            local: LocalDeltaE2000::at(asked_lab),
        }
    }

    /// The ΔE00 from the colour asked to each colour `steps[k]` away in XYZ, bounded
    /// below and above, (0, ∞) where it cannot be: the step to second order and what
    /// that leaves out ([`LabTangent::delta_to_second_order`]: at 8 bits the first
    /// order's remainder was most of a range's width, and kept three candidates in
    /// four to be measured), and the form's error for its size
    /// ([`LocalDeltaE2000::bound`]). The form about the colour is d(δ); the true step
    /// is within `e` of δ in each coordinate, which moves d by at most 4 e (the form's
    /// weights are at most 1, 1 + G at most 1.5 and R_T at most 2 in size: 2.1
    /// measured); and the exact ΔE00 E has |d − E| ≤ r E at the true step. So E lies
    /// in [(d − 4e) / (1 + r), (d + 4e) / (1 − r)], widened by 10⁻⁹ for the rounding
    /// of the exact formula itself, which a real-number bound does not see.
    pub fn ranges<const N: usize>(&self, steps: &[[f64; N]; 3]) -> [(f64, f64); N] {
        let mut ranges = [(0.0, f64::INFINITY); N];
        let Some(local) = &self.local else {
            return ranges;
        };
        // The steps' X, Y and Z each in one array, and the ends apart: the same
        // arithmetic for every step, so that the compiler takes several steps at a
        // time through the vector lanes (each range made whole, branch by branch, was
        // a tenth more instructions at 8 bits).
        let (mut least, mut most) = ([0.0; N], [0.0; N]);
        for k in 0..N {
            let step = [steps[0][k], steps[1][k], steps[2][k]];
            let (delta, lab_error) = self.tangent.delta_to_second_order(step);
            let slack = 4.0 * lab_error;
            let size = delta[0].abs().max(delta[1].abs()).max(delta[2].abs()) + lab_error;
            let relative = local.bound(size);
            let d = local.delta_e(delta);
            least[k] = (d - slack) / (1.0 + relative) - ROUNDING;
            most[k] = if relative < 1.0 {
                (d + slack) / (1.0 - relative) + ROUNDING
            } else {
                f64::INFINITY
            };
        }
        for (range, (least, most)) in ranges.iter_mut().zip(least.into_iter().zip(most)) {
            if least.is_finite() && most.is_finite() {
                *range = (least, most);
            }
        }
        ranges
    }

    /// Of the candidates `steps[candidates[i]]`, in the literal search's order, the
    /// index `i` of the nearest (the first of least ΔE00) and its ΔE00 as [`choose`]
    /// gives them, `exact(i)` measuring candidate `i`: screened first by
    /// [`Self::sole_candidate`] when `screen_first`, then each candidate bounded at
    /// its own step's size ([`Self::ranges`]).
    pub fn nearest<const N: usize>(
        &self,
        steps: &[[f64; N]; 3],
        candidates: &[usize],
        exact: impl Fn(usize) -> f64,
        error_wanted: bool,
        screen_first: bool,
    ) -> (usize, Option<f64>) {
        if let Some(i) = screen_first
            .then(|| self.sole_candidate(steps, candidates))
            .flatten()
        {
            return (i, error_wanted.then(|| exact(i)));
        }
        let ranges = self.ranges(steps);
        let mut chosen = [(0.0, f64::INFINITY); N];
        for (range, &k) in chosen.iter_mut().zip(candidates) {
            *range = ranges[k];
        }
        choose(&chosen[..candidates.len()], exact, error_wanted)
    }

    /// Of the candidates `steps[candidates[i]]`, the one nearest, when it is the only
    /// one that can be: every step's range as [`Self::ranges`] makes it, but with the
    /// bounds taken at the largest step's size, one L*a*b* remainder and one form
    /// bound for all of them rather than one each (both grow with the step, so each
    /// range still holds the step's exact ΔE00). A range is then a function of its
    /// step's form alone, in the form's order, so the candidates are compared by
    /// their forms squared, and one square root a pixel is taken rather than one a
    /// candidate (in a 16-bit render the eight ranges, their square roots one after
    /// another, were a fifth of the time). At 16 bits, where the steps are alike and the bounds tiny, this
    /// decides nearly every pixel; `None` where more than one candidate remains.
    pub fn sole_candidate<const N: usize>(
        &self,
        steps: &[[f64; N]; 3],
        candidates: &[usize],
    ) -> Option<usize> {
        let local = self.local.as_ref()?;
        let (mut squares, mut size, mut reach) = ([0.0; N], 0.0f64, [0.0f64; 3]);
        for (square, &k) in squares.iter_mut().zip(candidates) {
            let step = [steps[0][k], steps[1][k], steps[2][k]];
            let delta = self.tangent.second_order_delta(step);
            *square = local.delta_e_squared(delta);
            size = size.max(delta[0].abs().max(delta[1].abs()).max(delta[2].abs()));
            for (r, s) in reach.iter_mut().zip(step) {
                *r = r.max(s.abs());
            }
        }
        let lab_error = self.tangent.second_order_error(reach);
        sole_of(local, &squares[..candidates.len()], size, lab_error)
    }

    /// [`Self::sole_candidate`] for a box of codes: of its corners `corners[i]` (bit
    /// c set where the corner takes channel c's higher code), the low corner
    /// `low_step` from the colour asked in XYZ and each channel's code step `edges[c]`,
    /// the one nearest when it is the only one that can be. Without additivity terms
    /// a corner's step is the low corner's plus the edges it is high in, and the
    /// tangent to first order and the form's weighting ([`LocalDeltaE2000::weighted`])
    /// are linear: the four weighted steps give the eight corners' by additions, where
    /// [`Self::sole_candidate`] takes each corner's step through the tangent's second
    /// order and the weighting (in a 16-bit render that was a sixth of the time). What
    /// the first order leaves out ([`LabTangent::error`]) is larger than what the
    /// second leaves out, but from 12 bits it is a small part of what separates two
    /// corners (it decides 97 % of random boxes at 16 bits, 81 % at 12, 53 % at 10): a
    /// pixel it does not decide goes on to the search with both screens. Run with
    /// `arch`'s instructions ([`CornerScreen`]).
    pub fn sole_corner(
        &self,
        low_step: [f64; 3],
        edges: &[[f64; 3]; 3],
        corners: &[usize],
        arch: pulp::Arch,
    ) -> Option<usize> {
        arch.dispatch(CornerScreen {
            neighbourhood: self,
            low_step,
            edges,
            corners,
        })
    }

    /// [`Self::sole_corner`] in the instructions it is compiled for.
    #[inline(always)]
    fn sole_corner_here(
        &self,
        low_step: [f64; 3],
        edges: &[[f64; 3]; 3],
        corners: &[usize],
    ) -> Option<usize> {
        let local = self.local.as_ref()?;
        let (forms, size, lab_error) = self.box_forms(local, low_step, edges);
        let mut squares = [0.0; 8];
        for (square, &corner) in squares.iter_mut().zip(corners) {
            *square = forms[corner & 7];
        }
        sole_of(local, &squares[..corners.len()], size, lab_error)
    }

    /// The forms squared of the eight corners of a box, corner k high in the channels
    /// of k's bits, from the tangent to first order; the largest L*a*b* step over
    /// them; and what the first order leaves out over them.
    #[inline(always)]
    fn box_forms(
        &self,
        local: &LocalDeltaE2000,
        low_step: [f64; 3],
        edges: &[[f64; 3]; 3],
    ) -> ([f64; 8], f64, f64) {
        let low = self.tangent.delta(low_step);
        let edge = edges.map(|e| self.tangent.delta(e));
        let weighted = local.weighted(low);
        let edge_weighted = edge.map(|d| local.weighted(d));
        // Every corner's weighted step, each from one before it and one edge. The
        // largest XYZ and L*a*b* steps over the corners, from the two corners at the
        // ends of each coordinate (a corner left out of a render's candidates has the
        // step of one in it: its edge is 0).
        let weighted = box_corners(weighted, &edge_weighted);
        let reach = largest_over_box(low_step, edges);
        let lab_reach = largest_over_box(low, &edge);
        let size = larger(lab_reach[0], larger(lab_reach[1], lab_reach[2]));
        (
            weighted.map(|w| local.squared(w)),
            size,
            self.tangent.error(reach),
        )
    }

    /// [`Self::box_forms`] as ranges of each corner's exact ΔE00, as
    /// [`Self::sole_corner`] takes them; (0, ∞) each near the neutral axis.
    #[cfg(test)]
    fn box_ranges(&self, low_step: [f64; 3], edges: &[[f64; 3]; 3]) -> [(f64, f64); 8] {
        let Some(local) = &self.local else {
            return [(0.0, f64::INFINITY); 8];
        };
        let (forms, size, lab_error) = self.box_forms(local, low_step, edges);
        let relative = local.bound(size + lab_error);
        forms.map(|q| range_of(q.sqrt(), 4.0 * lab_error, relative))
    }
}

/// [`Neighbourhood::sole_corner`] as `pulp` runs it, compiled for the instructions it
/// is given (the same operations in the same order, so the same answer: AVX2 takes a
/// third fewer instructions for it than the baseline x86-64, whose registers take
/// two operands, and adds four doubles at once).
struct CornerScreen<'a> {
    neighbourhood: &'a Neighbourhood,
    low_step: [f64; 3],
    edges: &'a [[f64; 3]; 3],
    corners: &'a [usize],
}

impl pulp::WithSimd for CornerScreen<'_> {
    type Output = Option<usize>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Option<usize> {
        self.neighbourhood
            .sole_corner_here(self.low_step, self.edges, self.corners)
    }
}

/// The largest size of each coordinate over the corners of a box from its low corner
/// `low` and its three edges: at the corner high in the channels whose edges add to
/// the coordinate, or at the one high in those that take from it.
#[inline(always)]
fn largest_over_box(low: [f64; 3], edges: &[[f64; 3]; 3]) -> [f64; 3] {
    std::array::from_fn(|axis| {
        let (mut most, mut least) = (low[axis], low[axis]);
        for edge in edges {
            if edge[axis] > 0.0 {
                most += edge[axis];
            } else {
                least += edge[axis];
            }
        }
        larger(most.abs(), least.abs())
    })
}

/// The larger of `a` and `b`, in one instruction. A NaN in `a` is passed over and one
/// in `b` returned; either way a step that is not a number leaves its corner's form
/// squared not a number, which no screen takes as the only one.
#[inline(always)]
fn larger(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// The eight corners of a box from its low corner `low` and its three edges: corner
/// k is `low` plus the edges of k's bits, each made from the corner without its
/// highest bit.
#[inline(always)]
fn box_corners(low: [f64; 3], edges: &[[f64; 3]; 3]) -> [[f64; 3]; 8] {
    let add = |a: [f64; 3], b: [f64; 3]| [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
    let (c1, c2, c4) = (add(low, edges[0]), add(low, edges[1]), add(low, edges[2]));
    let c3 = add(c1, edges[1]);
    [
        low,
        c1,
        c2,
        c3,
        c4,
        add(c1, edges[2]),
        add(c2, edges[2]),
        add(c3, edges[2]),
    ]
}

/// Of candidates whose forms squared are `squares`, their largest L*a*b* step `size`
/// and the tangent's remainder `lab_error` over all of them, the index of the one
/// nearest when it is the only one that can be ([`Neighbourhood::sole_candidate`]).
#[inline(always)]
fn sole_of(local: &LocalDeltaE2000, squares: &[f64], size: f64, lab_error: f64) -> Option<usize> {
    let relative = local.bound(size + lab_error);
    let (least, least_square) = squares.iter().enumerate().fold(
        (0, f64::INFINITY),
        |m, (i, &q)| if q < m.1 { (i, q) } else { m },
    );
    let (_, least_upper) = range_of(least_square.sqrt(), 4.0 * lab_error, relative);
    // A candidate whose lower end, (d − 4e) / (1 + r) − 10⁻⁹, lies above the least
    // upper end cannot be nearest: d above (least_upper + 10⁻⁹)(1 + r) + 4e.
    let over = (least_upper + ROUNDING) * (1.0 + relative) + 4.0 * lab_error;
    let beyond = over * over;
    let alone = over.is_finite()
        && squares
            .iter()
            .enumerate()
            .all(|(i, &q)| i == least || q > beyond);
    alone.then_some(least)
}

/// The range of an exact ΔE00 whose form gives `form`, within `slack` of it from the
/// L*a*b* step's remainder and `relative` of it from the form's own error (see
/// [`Neighbourhood::ranges`]); (0, ∞) where either is not finite or the form's error may
/// be all of it.
#[inline(always)]
fn range_of(form: f64, slack: f64, relative: f64) -> (f64, f64) {
    if !(relative < 1.0 && slack.is_finite()) {
        return (0.0, f64::INFINITY);
    }
    let least = (form - slack) / (1.0 + relative) - ROUNDING;
    let most = (form + slack) / (1.0 - relative) + ROUNDING;
    if least.is_finite() && most.is_finite() {
        (least, most)
    } else {
        (0.0, f64::INFINITY)
    }
}

/// What the exact formula's own rounding may add to or take from a ΔE00 (its L*a*b*
/// carry about 10⁻¹⁴ of noise; this is far above that and far below any difference a
/// code makes).
const ROUNDING: f64 = 1e-9;

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_color::difference::delta_e_2000;
    use chromacal_color::spaces::xyz_to_lab;

    /// The most candidates a pixel has: its rounded codes, then the 8 corners.
    const MOST: usize = 9;

    /// The nearest of candidates given by their colours, as a render's codes are,
    /// screened first or not.
    fn nearest(
        candidates: &[([u32; 3], Xyz)],
        asked: &Xyz,
        asked_lab: &Lab,
        white: &Xyz,
        error_wanted: bool,
        screen_first: bool,
    ) -> (usize, Option<f64>) {
        let exact = |k: usize| delta_e_2000(asked_lab, &xyz_to_lab(&candidates[k].1, white));
        let order: Vec<usize> = (0..candidates.len()).collect();
        Neighbourhood::at(asked, asked_lab, white).nearest(
            &steps(candidates, asked),
            &order,
            exact,
            error_wanted,
            screen_first,
        )
    }

    /// The candidates' steps from the colour asked, X, Y and Z each in one array.
    fn steps(candidates: &[([u32; 3], Xyz)], asked: &Xyz) -> [[f64; MOST]; 3] {
        // Unused places step as far as the last candidate, bounded as it is.
        let shown = |k: usize| candidates[k.min(candidates.len() - 1)].1;
        [
            std::array::from_fn(|k| shown(k).x - asked.x),
            std::array::from_fn(|k| shown(k).y - asked.y),
            std::array::from_fn(|k| shown(k).z - asked.z),
        ]
    }

    /// [`Neighbourhood::ranges`] of candidates given by their colours.
    fn ranges(
        candidates: &[([u32; 3], Xyz)],
        asked: &Xyz,
        asked_lab: &Lab,
        white: &Xyz,
    ) -> [(f64, f64); MOST] {
        Neighbourhood::at(asked, asked_lab, white).ranges(&steps(candidates, asked))
    }

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

    /// The `i`th colour of a test of the bounds, in turn where they are tightest: hue
    /// within 0.1° of 0° (eq. 20's Δθ jumps there), C* near 25 at 270° (G and R_T
    /// change fastest), L* below `dark` (the tangent's curvature), and anywhere.
    fn tight_colour(i: usize, dark: f64, uniform: &mut impl FnMut() -> f64) -> Lab {
        let (lightness, chroma, hue) = match i % 4 {
            0 => (100.0 * uniform(), 80.0 * uniform(), 0.2 * uniform() - 0.1),
            1 => (
                100.0 * uniform(),
                20.0 + 10.0 * uniform(),
                265.0 + 10.0 * uniform(),
            ),
            2 => (dark * uniform(), 20.0 * uniform(), 360.0 * uniform()),
            _ => (100.0 * uniform(), 100.0 * uniform(), 360.0 * uniform()),
        };
        let hue: f64 = hue.to_radians();
        Lab {
            l: lightness,
            a: chroma * hue.cos(),
            b: chroma * hue.sin(),
        }
    }

    /// Every candidate's exact ΔE00 lies inside the range it is given, where the bounds
    /// are tightest: hues within 0.1° of 0° (eq. 20's Δθ jumps there), C* near 25 at
    /// 270° (G and R_T change fastest), near black (the tangent's curvature), and steps
    /// from a 16-bit code's to 20 in L*a*b*. More sensitive than comparing winners, as
    /// it judges every candidate: ranges from a fifth of the form's bound fail it.
    #[test]
    fn every_exact_delta_e_lies_in_its_range() {
        use chromacal_color::spaces::lab_to_xyz;
        use rand::{Rng, SeedableRng};
        let white = Xyz::new(95.0, 100.0, 108.9);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0xB0B5_1EDD_CAFE_F00D);
        let mut uniform = move || rng.random::<f64>();
        let (mut judged, mut nearest_edge) = (0, f64::INFINITY);
        for i in 0..200_000 {
            let asked = lab_to_xyz(&tight_colour(i, 3.0, &mut uniform), &white);
            // Steps of 10⁻⁶ to 0.3 of the colour's own XYZ (and of 10⁻⁴ of the white).
            let step = 10f64.powf(-6.0 + 5.5 * uniform());
            let candidates: Vec<([u32; 3], Xyz)> = (0..MOST)
                .map(|_| {
                    let mut jitter = |v: f64, w: f64| {
                        (v + (v + 1e-4 * w) * step * (2.0 * uniform() - 1.0)).max(0.0)
                    };
                    let shown = Xyz::new(
                        jitter(asked.x, white.x),
                        jitter(asked.y, white.y),
                        jitter(asked.z, white.z),
                    );
                    ([0; 3], shown)
                })
                .collect();
            let asked_lab = xyz_to_lab(&asked, &white);
            let ranges = ranges(&candidates, &asked, &asked_lab, &white);
            for ((_, shown), (least, most)) in candidates.iter().zip(ranges) {
                if most.is_finite() {
                    let exact = delta_e_2000(&asked_lab, &xyz_to_lab(shown, &white));
                    assert!(
                        least <= exact && exact <= most,
                        "{asked_lab:?} to {shown:?}: {exact} outside [{least}, {most}]"
                    );
                    // How near the exact value comes to an end, in the range's own
                    // half-width: a range 2 × too narrow would put some outside.
                    let half = 0.5 * (most - least);
                    if half > 0.0 {
                        nearest_edge = nearest_edge.min((exact - least).min(most - exact) / half);
                    }
                    judged += 1;
                }
            }
        }
        assert!(judged > 1_000_000, "{judged}");
        eprintln!("closest to an end: {nearest_edge:.3} of the half-width");
    }

    /// Every corner's exact ΔE00 lies in the range the first-order screen gives it,
    /// on boxes around colours where the bounds are tightest: hues within 0.1° of 0°,
    /// C* near 25 at 270°, near black (across L*'s linear part), and random colours;
    /// steps from 10⁻⁷ of the colour to a third of it (where the tangent gives up), some
    /// channels on a code (no edge).
    #[test]
    fn every_corner_s_exact_delta_e_lies_in_its_first_order_range() {
        use chromacal_color::spaces::lab_to_xyz;
        use rand::{Rng, SeedableRng};
        let white = Xyz::new(95.0, 100.0, 108.9);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x000F_1257_0DE2);
        let mut uniform = move || rng.random::<f64>();
        let (mut judged, mut nearest_edge) = (0, f64::INFINITY);
        for i in 0..100_000 {
            let asked = lab_to_xyz(&tight_colour(i, 12.0, &mut uniform), &white);
            let asked_lab = xyz_to_lab(&asked, &white);
            let size = 10f64.powf(-7.0 + 6.5 * uniform());
            let mut edge = |v: f64| (v + 0.01) * size * uniform();
            let mut edges: [[f64; 3]; 3] =
                std::array::from_fn(|_| [edge(asked.x), edge(asked.y), edge(asked.z)]);
            if i % 5 == 0 {
                edges[i % 3] = [0.0; 3];
            }
            let inside: [f64; 3] = std::array::from_fn(|_| uniform());
            let low_step: [f64; 3] =
                std::array::from_fn(|a| -(0..3).map(|c| inside[c] * edges[c][a]).sum::<f64>());
            let ranges = Neighbourhood::at(&asked, &asked_lab, &white).box_ranges(low_step, &edges);
            for (corner, (least, most)) in ranges.into_iter().enumerate() {
                if !most.is_finite() {
                    continue;
                }
                let mut shown = [
                    asked.x + low_step[0],
                    asked.y + low_step[1],
                    asked.z + low_step[2],
                ];
                for (c, e) in edges.iter().enumerate() {
                    if corner >> c & 1 == 1 {
                        for a in 0..3 {
                            shown[a] += e[a];
                        }
                    }
                }
                let shown = Xyz::new(shown[0], shown[1], shown[2]);
                let exact = delta_e_2000(&asked_lab, &xyz_to_lab(&shown, &white));
                assert!(
                    least <= exact && exact <= most,
                    "{asked_lab:?}, corner {corner} of {edges:?}: {exact} outside [{least}, {most}]"
                );
                let half = 0.5 * (most - least);
                if half > 0.0 {
                    nearest_edge = nearest_edge.min((exact - least).min(most - exact) / half);
                }
                judged += 1;
            }
        }
        assert!(judged > 400_000, "{judged}");
        eprintln!("closest to an end: {nearest_edge:.3} of the half-width");
    }

    /// The corners of boxes of codes around random colours, from black to white and
    /// from neutral to saturated, each channel's code step a 16-bit or a 12-bit
    /// display's: where [`Neighbourhood::sole_corner`] names one, it is the
    /// literal search's, and it names one for most boxes (at 16 bits nearly all),
    /// whether compiled for the processor's best instructions or the baseline.
    #[test]
    fn the_first_order_corner_screen_finds_the_literal_one() {
        use rand::{Rng, SeedableRng};
        let white = Xyz::new(95.0, 100.0, 108.9);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5EED_C0DE_0BAD_F00D);
        let mut uniform = move || rng.random::<f64>();
        // Primaries' full light, as columns (an sRGB-like display).
        let primaries = [[41.2, 21.3, 1.9], [35.8, 71.5, 11.9], [18.0, 7.2, 95.0]];
        let (mut decided, mut boxes) = ([0usize; 2], [0usize; 2]);
        for i in 0..60_000 {
            let sixteen = i % 2 == 0;
            let top = if sixteen { 65535.0 } else { 4095.0 };
            let light: [f64; 3] = std::array::from_fn(|_| uniform().powf(2.2));
            // One code step of each channel at its light, a 2.2 power law.
            let step_of = |l: f64| {
                let drive = l.powf(1.0 / 2.2);
                ((drive + 1.0 / top).min(1.0).powf(2.2) - drive.powf(2.2)).max(1e-12)
            };
            let edges: [[f64; 3]; 3] = std::array::from_fn(|c| {
                let s = step_of(light[c]);
                primaries[c].map(|p| p * s)
            });
            // The colour asked lies inside the box: its low corner a random fraction of
            // each edge below it.
            let inside: [f64; 3] = std::array::from_fn(|_| uniform());
            let asked = Xyz::new(
                (0..3).map(|c| primaries[c][0] * light[c]).sum::<f64>() + 0.05,
                (0..3).map(|c| primaries[c][1] * light[c]).sum::<f64>() + 0.05,
                (0..3).map(|c| primaries[c][2] * light[c]).sum::<f64>() + 0.05,
            );
            let low_step: [f64; 3] =
                std::array::from_fn(|a| -(0..3).map(|c| inside[c] * edges[c][a]).sum::<f64>());
            let corner_xyz = |corner: usize| {
                let mut xyz = [
                    asked.x + low_step[0],
                    asked.y + low_step[1],
                    asked.z + low_step[2],
                ];
                for (c, edge) in edges.iter().enumerate() {
                    if corner >> c & 1 == 1 {
                        for a in 0..3 {
                            xyz[a] += edge[a];
                        }
                    }
                }
                Xyz::new(xyz[0], xyz[1], xyz[2])
            };
            // The rounded corner first, then the others in order, as a render has them.
            let rounded = (0..3).fold(0, |k, c| k | usize::from(inside[c] > 0.5) << c);
            let mut corners = vec![rounded];
            corners.extend((0..8).filter(|&k| k != rounded));
            let asked_lab = xyz_to_lab(&asked, &white);
            let candidates: Vec<([u32; 3], Xyz)> =
                corners.iter().map(|&k| ([0; 3], corner_xyz(k))).collect();
            let (want, _) = literal(&candidates, &asked_lab, &white);
            let neighbourhood = Neighbourhood::at(&asked, &asked_lab, &white);
            boxes[usize::from(sixteen)] += 1;
            // Compiled for the processor's best instructions, and for the baseline:
            // the same answer.
            let best = neighbourhood.sole_corner(low_step, &edges, &corners, pulp::Arch::new());
            let baseline =
                neighbourhood.sole_corner(low_step, &edges, &corners, pulp::Arch::Scalar);
            assert_eq!(
                best, baseline,
                "{asked:?}, edges {edges:?}, inside {inside:?}"
            );
            if let Some(k) = best {
                assert_eq!(k, want, "{asked:?}, edges {edges:?}, inside {inside:?}");
                decided[usize::from(sixteen)] += 1;
            }
        }
        eprintln!(
            "decided at 12 bits {} of {}, at 16 bits {} of {}",
            decided[0], boxes[0], decided[1], boxes[1]
        );
        // 97 % and 81 % when written.
        assert!(decided[1] * 100 > boxes[1] * 95, "{decided:?} of {boxes:?}");
        assert!(decided[0] * 100 > boxes[0] * 75, "{decided:?} of {boxes:?}");
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
        let (mut measured, mut screened) = (0, 0);
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
            let (want, want_error) = literal(&candidates, &asked_lab, &white);
            for screen_first in [false, true] {
                let (k, error) =
                    nearest(&candidates, &asked, &asked_lab, &white, true, screen_first);
                assert_eq!(k, want, "{asked:?}, step {step}: {candidates:?}");
                assert_eq!(error, Some(want_error));
                let (k, error) =
                    nearest(&candidates, &asked, &asked_lab, &white, false, screen_first);
                assert_eq!(k, want);
                if !screen_first {
                    measured += usize::from(error.is_some());
                }
            }
            let neighbourhood = Neighbourhood::at(&asked, &asked_lab, &white);
            let order: Vec<usize> = (0..MOST).collect();
            if let Some(k) = neighbourhood.sole_candidate(&steps(&candidates, &asked), &order) {
                assert_eq!(k, want);
                screened += 1;
            }
        }
        // Most pixels are decided without a ΔE00, and most by the screen alone.
        assert!(measured < 50_000, "{measured} of 100000 measured");
        assert!(screened > 50_000, "{screened} of 100000 screened");
        eprintln!("{measured} measured, {screened} screened");
    }
}
