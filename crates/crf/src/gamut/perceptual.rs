//! Gamut mappings judged where people see: the nearest boundary point under ΔE00,
//! and CIE 156:2004's hue-preserving minimum ΔE clipping (HPMINDE).
//!
//! Both work on the exact gamut: under the additive model its boundary is the six
//! faces of the unit cube in cube coordinates (`GamutAt`), so a boundary point is a
//! face and two coordinates on it, and membership is three comparisons. What is not
//! exact is the search: ΔE00 over a face is smooth but not convex, so the nearest
//! point is found from many starts (a grid on every face, and the answers of the
//! simpler mappings) refined by compass search. Because those simpler answers are
//! among the starts, the result is never farther in ΔE00 than clipping, the XYZ
//! projection or the grey-axis clip.

use nalgebra::Vector3;

use super::{GamutAt, UniformSpace, clip, grey_axis_clip, last_inside, perpendicular};
use chromacal_color::Xyz;
use chromacal_color::difference::{delta_e_1976, delta_e_2000};
use chromacal_color::spaces::{Lab, lab_to_xyz, xyz_to_lab};

/// A point on the cube's surface: coordinate `axis` held at `value` (0 or 1), the
/// other two, in increasing axis order, at `u`³ and `w`³.
///
/// The cube is searched in the cube roots of its coordinates, as CIELAB itself
/// takes cube roots of light: a uniform grid in u is then roughly uniform in
/// lightness, and the narrow basins of dark colours near the black corner (a dark
/// violet's nearest point sat at 0.017 of full drive) are not stepped over.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FacePoint {
    axis: usize,
    value: f64,
    u: f64,
    w: f64,
}

impl FacePoint {
    fn cube(&self) -> Vector3<f64> {
        let mut a = Vector3::repeat(self.value);
        let [i, j] = others(self.axis);
        a[i] = self.u.powi(3);
        a[j] = self.w.powi(3);
        a
    }

    /// The face point of a cube point on the surface (one coordinate at 0 or 1
    /// within `SURFACE`), if any.
    fn of(a: &Vector3<f64>) -> Option<FacePoint> {
        (0..3).find_map(|axis| {
            let value = [0.0, 1.0]
                .into_iter()
                .find(|v| (a[axis] - v).abs() < SURFACE)?;
            let [i, j] = others(axis);
            Some(FacePoint {
                axis,
                value,
                u: a[i].clamp(0.0, 1.0).cbrt(),
                w: a[j].clamp(0.0, 1.0).cbrt(),
            })
        })
    }
}

/// Cube coordinates closer than this to 0 or 1 count as on the surface.
const SURFACE: f64 = 1e-7;

fn others(axis: usize) -> [usize; 2] {
    match axis {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    }
}

/// Grid points per side of each face for the starts: a step of 1/8.
const GRID: usize = 9;
/// Starts refined besides each face's best: the best few of the grid and the
/// simpler mappings.
const REFINED: usize = 4;
/// Compass search stops when its step is below this (in cube coordinates, far
/// below a 16-bit code step) or after `MAX_EVALUATIONS`.
const SMALLEST_STEP: f64 = 1e-7;
const MAX_EVALUATIONS: usize = 400;

/// The point of the gamut's boundary nearest to `xyz` under CIEDE2000 (CIE 142-2001),
/// L*a*b* against `white`; `xyz` itself when inside.
///
/// Cost: about 500 ΔE00 evaluations for the starts and up to 400 for each of up to 10
/// refinements (the best 4 starts and each face's best), per colour outside.
pub fn perpendicular_lab(gamut: &GamutAt, xyz: &Xyz, white: &Xyz) -> Xyz {
    if gamut.contains(xyz) {
        return *xyz;
    }
    let target = xyz_to_lab(xyz, white);
    let cost =
        |p: &FacePoint| delta_e_2000(&target, &xyz_to_lab(&gamut.from_cube(&p.cube()), white));
    let mut starts: Vec<(f64, FacePoint, f64)> = Vec::new();
    for simpler in [
        clip(gamut, xyz),
        perpendicular(gamut, xyz),
        grey_axis_clip(gamut, xyz, UniformSpace::Lab, white),
    ] {
        if let Some(p) = FacePoint::of(&gamut.to_cube(&simpler)) {
            starts.push((cost(&p), p, 1.0 / 16.0));
        }
    }
    let step = 1.0 / (GRID - 1) as f64;
    for axis in 0..3 {
        for value in [0.0, 1.0] {
            for i in 0..GRID {
                for j in 0..GRID {
                    let p = FacePoint {
                        axis,
                        value,
                        u: i as f64 * step,
                        w: j as f64 * step,
                    };
                    starts.push((cost(&p), p, step));
                }
            }
        }
    }
    starts.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The best few overall and the best of every face: ΔE00 has separate basins on
    // different faces (a dark saturated colour is near both the black corner's faces
    // and its primary's).
    let mut chosen: Vec<&(f64, FacePoint, f64)> = starts.iter().take(REFINED).collect();
    for axis in 0..3 {
        for value in [0.0, 1.0] {
            if let Some(s) = starts
                .iter()
                .find(|(_, p, _)| p.axis == axis && p.value == value)
            {
                chosen.push(s);
            }
        }
    }
    let best = chosen
        .into_iter()
        .map(|(f, p, step)| compass_search(*p, *f, *step, &cost))
        .min_by(|a, b| a.0.total_cmp(&b.0));
    match best {
        Some((_, p)) => gamut.from_cube(&p.cube()),
        None => clip(gamut, xyz),
    }
}

/// The directions compass search tries: along u and w and the diagonals (ΔE00 has
/// creases, along which moves on one axis alone stall).
const COMPASS: [(f64, f64); 8] = [
    (1.0, 0.0),
    (-1.0, 0.0),
    (0.0, 1.0),
    (0.0, -1.0),
    (1.0, 1.0),
    (-1.0, -1.0),
    (1.0, -1.0),
    (-1.0, 1.0),
];

/// Compass search on one face: try a step each way, move on the first improvement,
/// halve the step when none improves.
fn compass_search(
    mut p: FacePoint,
    mut f: f64,
    mut step: f64,
    cost: &impl Fn(&FacePoint) -> f64,
) -> (f64, FacePoint) {
    let mut evaluations = 0;
    while step > SMALLEST_STEP && evaluations < MAX_EVALUATIONS {
        let mut moved = false;
        for (du, dw) in COMPASS {
            let q = FacePoint {
                u: (p.u + du * step).clamp(0.0, 1.0),
                w: (p.w + dw * step).clamp(0.0, 1.0),
                ..p
            };
            if q == p {
                continue;
            }
            evaluations += 1;
            let g = cost(&q);
            if g < f {
                (p, f, moved) = (q, g, true);
                break;
            }
        }
        if !moved {
            step *= 0.5;
        }
    }
    (f, p)
}

/// Lightness samples of the grey axis HPMINDE searches first, before refining.
const HPMINDE_LIGHTNESS_SAMPLES: usize = 65;
/// Golden-section steps for the lightness (the largest chroma at a lightness is
/// bisected by `last_inside`): both far below 0.001 ΔE*ab.
const LIGHTNESS_REFINEMENT: usize = 40;

/// CIE 156:2004's HPMINDE (hue-preserving minimum ΔE): a colour outside is moved to
/// the point of the gamut, in its own CIELAB hue plane (against `white`), nearest in
/// ΔE*ab; a colour inside stays.
///
/// In the hue plane the gamut is, at each lightness L on the display's grey axis,
/// the chroma segment [0, C_max(L)] (found by bisection against the exact gamut).
/// The nearest point of the plane's section to (L₀, C₀) at lightness L is
/// (L, min(C₀, C_max(L))), so the search is over L alone: a grid, then golden
/// section around its best. Hue is kept exactly wherever the grey at that lightness
/// is inside; a display whose black differs in chromaticity from its white has a
/// dark end where it is not, and a colour whose every candidate lies there is
/// clipped instead.
pub fn hpminde(gamut: &GamutAt, xyz: &Xyz, white: &Xyz) -> Xyz {
    if gamut.contains(xyz) {
        return *xyz;
    }
    let lab = xyz_to_lab(xyz, white);
    let c0 = lab.a.hypot(lab.b);
    let (cos, sin) = if c0 > 1e-12 {
        (lab.a / c0, lab.b / c0)
    } else {
        (1.0, 0.0)
    };
    let at = |l: f64, c: f64| {
        lab_to_xyz(
            &Lab {
                l,
                a: c * cos,
                b: c * sin,
            },
            white,
        )
    };
    let largest_chroma = |l: f64| last_inside(|c| gamut.contains(&at(l, c)), c0.max(1.0));
    let nearest_at = |l: f64| -> Option<(f64, Lab)> {
        let c = c0.min(largest_chroma(l)?);
        let candidate = Lab {
            l,
            a: c * cos,
            b: c * sin,
        };
        Some((delta_e_1976(&lab, &candidate), candidate))
    };
    let lightest = xyz_to_lab(&gamut.white(), white).l;
    let darkest = xyz_to_lab(&gamut.black(), white).l;
    let step = (lightest - darkest) / (HPMINDE_LIGHTNESS_SAMPLES - 1) as f64;
    let grid_best = (0..HPMINDE_LIGHTNESS_SAMPLES)
        .filter_map(|k| {
            let l = darkest + k as f64 * step;
            nearest_at(l).map(|(d, _)| (d, l))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    let Some((_, l_grid)) = grid_best else {
        return clip(gamut, xyz);
    };
    // Golden section on [l − step, l + step] (within the axis), keeping the best seen.
    let (mut lo, mut hi) = ((l_grid - step).max(darkest), (l_grid + step).min(lightest));
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let distance = |l: f64| nearest_at(l).map_or(f64::INFINITY, |(d, _)| d);
    let mut best = l_grid;
    let mut best_d = distance(l_grid);
    for _ in 0..LIGHTNESS_REFINEMENT {
        let (m1, m2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
        let (d1, d2) = (distance(m1), distance(m2));
        for (m, d) in [(m1, d1), (m2, d2)] {
            if d < best_d {
                (best, best_d) = (m, d);
            }
        }
        if d1 <= d2 {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    match nearest_at(best) {
        Some((_, candidate)) => lab_to_xyz(&candidate, white),
        None => clip(gamut, xyz),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_color::spaces::lab_to_lch;

    use super::super::tests::gamut;

    fn outside_colours(g: &GamutAt) -> Vec<Xyz> {
        [
            [1.4, 0.5, 0.5],
            [-0.3, 0.2, 1.3],
            [1.2, 1.3, -0.4],
            [0.5, -0.2, 0.5],
            [0.05, 0.02, 1.6],
            [1.5, 1.5, 1.5],
        ]
        .iter()
        .map(|a| g.from_cube(&Vector3::new(a[0], a[1], a[2])))
        .collect()
    }

    #[test]
    fn the_cielab_projection_is_no_farther_than_a_fine_search_of_the_surface() {
        let g = gamut();
        let white = g.white();
        for x in outside_colours(&g) {
            let p = perpendicular_lab(&g, &x, &white);
            assert!(g.contains(&p));
            let target = xyz_to_lab(&x, &white);
            let found = delta_e_2000(&target, &xyz_to_lab(&p, &white));
            // A 61 × 61 grid on every face finds nothing nearer by more than its
            // own resolution allows.
            let n = 60;
            let mut finest = f64::INFINITY;
            for axis in 0..3 {
                for value in [0.0, 1.0] {
                    for i in 0..=n {
                        for j in 0..=n {
                            // Uniform in the coordinates themselves, not their
                            // cube roots as the search is.
                            let q = FacePoint {
                                axis,
                                value,
                                u: (i as f64 / n as f64).cbrt(),
                                w: (j as f64 / n as f64).cbrt(),
                            };
                            let d =
                                delta_e_2000(&target, &xyz_to_lab(&g.from_cube(&q.cube()), &white));
                            finest = finest.min(d);
                        }
                    }
                }
            }
            assert!(
                found <= finest + 1e-6,
                "{x:?}: found {found}, grid {finest}"
            );
            let clipped = delta_e_2000(&target, &xyz_to_lab(&clip(&g, &x), &white));
            assert!(found <= clipped + 1e-12);
        }
    }

    #[test]
    fn hpminde_keeps_hue_and_is_nearest_in_its_hue_plane() {
        let g = gamut();
        let white = g.white();
        for x in outside_colours(&g) {
            let p = hpminde(&g, &x, &white);
            assert!(g.contains(&p), "{x:?}");
            let (before, after) = (xyz_to_lab(&x, &white), xyz_to_lab(&p, &white));
            let (_, c0, h0) = lab_to_lch(&before);
            let (_, c1, h1) = lab_to_lch(&after);
            if c0 > 1.0 && c1 > 1e-3 {
                let turn = ((h1 - h0 + 540.0) % 360.0 - 180.0).abs();
                assert!(turn < 1e-6, "{x:?}: hue turned {turn}°");
            }
            // No point of the hue plane's section on a fine (L, C) grid is nearer.
            let found = delta_e_1976(&before, &after);
            let (cos, sin) = (before.a / c0.max(1e-12), before.b / c0.max(1e-12));
            for i in 0..=200 {
                for j in 0..=300 {
                    let q = Lab {
                        l: i as f64 * 0.5,
                        a: j as f64 * 0.5 * cos,
                        b: j as f64 * 0.5 * sin,
                    };
                    if g.contains(&lab_to_xyz(&q, &white)) {
                        assert!(delta_e_1976(&before, &q) >= found - 0.5, "{x:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn colours_inside_stay_where_they_are() {
        let g = gamut();
        let white = g.white();
        for a in [
            [0.2, 0.7, 1.0],
            [0.0, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [1.0, 0.0, 0.3],
        ] {
            let x = g.from_cube(&Vector3::new(a[0], a[1], a[2]));
            assert_eq!(perpendicular_lab(&g, &x, &white), x);
            assert_eq!(hpminde(&g, &x, &white), x);
        }
    }
}
