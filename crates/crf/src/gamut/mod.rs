//! The display's gamut at a point of the screen, and the survey's ways of bringing a
//! colour outside it back in (seed §4.3.2, "Monitor limitations").
//!
//! Under the additive model a display shows, at position p, exactly the colours
//!
//! XYZ = XYZ_black + Σ_c a_c P_c(p),   0 ≤ a_c ≤ 1,
//!
//! with P_c(p) = K_c(p) E_c(1) m_c the full-drive light of channel c there (m_c the
//! primary's column of the matrix, K_c the spatial gain, E_c(1) the law's full-drive
//! excitation). So the gamut is a parallelepiped, and `a` (the *cube coordinates*,
//! linear light of each channel as a share of its full drive) says at once whether a
//! colour is inside: all three in [0, 1]. Every mapping here works in those
//! coordinates; a corner of the screen that loses light has a smaller gamut, and a
//! colour is mapped into the gamut of the position it is shown at.
//!
//! The additivity terms a fit may keep (`model::monitor::AdditivityTerms`, a few per
//! cent at most) bend the gamut slightly; the mappings use the additive part, and the
//! final inversion through the whole model clips what the terms move outside.

mod global;
mod perceptual;
mod sgck;

pub use global::{ScbOptions, Smith, StoneCowanBeatty};
pub use perceptual::{hpminde, perpendicular_lab};
pub use sgck::{SgckSource, sgck};

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use chromacal_color::Xyz;
use chromacal_color::spaces::{Lab, Luv, lab_to_xyz, luv_to_xyz, xyz_to_lab, xyz_to_luv};

/// The colours a display can show at one position.
#[derive(Debug, Clone, PartialEq)]
pub struct GamutAt {
    black: Xyz,
    /// Columns: P_c, the full-drive light of each channel at this position.
    primaries: Matrix3<f64>,
    /// P⁻¹: XYZ above black to cube coordinates.
    inverse: Matrix3<f64>,
}

/// Slack for "inside": cube coordinates within this of [0, 1] count as inside, so
/// that a colour computed from the boundary is not sent round again by rounding.
pub const INSIDE_TOLERANCE: f64 = 1e-9;

impl GamutAt {
    /// The gamut with black `black` and full-drive channel lights `primaries`
    /// (columns), or `None` when those are collinear (no inverse).
    pub fn new(black: Xyz, primaries: Matrix3<f64>) -> Option<GamutAt> {
        let inverse = primaries.try_inverse()?;
        Some(GamutAt {
            black,
            primaries,
            inverse,
        })
    }

    /// Cube coordinates of `xyz`: a = P⁻¹ (XYZ − XYZ_black).
    pub fn to_cube(&self, xyz: &Xyz) -> Vector3<f64> {
        self.inverse * (xyz - self.black)
    }

    /// XYZ of cube coordinates `a`.
    pub fn from_cube(&self, a: &Vector3<f64>) -> Xyz {
        self.black + self.primaries * a
    }

    pub fn black(&self) -> Xyz {
        self.black
    }

    /// Full white at this position.
    pub fn white(&self) -> Xyz {
        self.from_cube(&Vector3::repeat(1.0))
    }

    pub fn contains(&self, xyz: &Xyz) -> bool {
        cube_contains(&self.to_cube(xyz))
    }
}

fn cube_contains(a: &Vector3<f64>) -> bool {
    a.iter()
        .all(|v| (-INSIDE_TOLERANCE..=1.0 + INSIDE_TOLERANCE).contains(v))
}

/// The uniform colour space a hue is kept in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UniformSpace {
    Lab,
    Luv,
}

/// How a colour outside the gamut is brought in (seed §4.3.2; CIE 156:2004).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GamutMapping {
    /// Each channel clipped to [0, 1] on its own: "values greater than 255 are changed
    /// to 255, and negative ones to zero". The baseline; it shifts hue.
    Clip,
    /// Toward the grey axis at constant lightness and hue angle in CIELAB or CIELUV,
    /// as far as the boundary: chroma is what gives way.
    GreyAxis(UniformSpace),
    /// The nearest point of the gamut in XYZ: the perpendicular projection onto the
    /// boundary that Stone, Cowan and Beatty (1988) suggest for what their global
    /// transform leaves outside. Exact, but XYZ is not a space where distance means
    /// what it looks like: it is often farther than plain clipping in ΔE00 and can
    /// turn hue (the survey's own closing remark in §4.3.2).
    Perpendicular,
    /// The nearest point of the gamut's boundary under ΔE00 (CIEDE2000 against the
    /// display's white): what the survey asks for when it says distance must be
    /// judged in a uniform space.
    PerpendicularLab,
    /// CIE 156:2004's HPMINDE: hue-preserving minimum ΔE*ab clipping, the nearest
    /// point of the gamut in the colour's own CIELAB hue plane.
    Hpminde,
    /// CIE 156:2004's SGCK: Braun and Fairchild's sigmoidal lightness mapping
    /// weighted by chroma, then knee scaling toward the grey at the cusp's
    /// lightness, from the source gamut of the given RGB space.
    Sgck(SgckSource),
    /// Smith (1993), seed §4.3.2: in the RGB cube, bright colours turned toward the
    /// grey axis and every colour's luminance compressed by a power of Y / Y_max.
    Smith,
    /// Stone, Cowan and Beatty (1988): one transform of the whole scene,
    /// X_d = B_d + bs (W_d − B_d) + csf R (X_i − B_i), chosen by their rules in order
    /// (grey axis, contrast, few outside), then what stays outside projected.
    StoneCowanBeatty(ScbOptions),
}

impl GamutMapping {
    pub fn name(&self) -> String {
        match self {
            GamutMapping::Clip => "clip".into(),
            GamutMapping::GreyAxis(UniformSpace::Lab) => "grey-axis clip in CIELAB".into(),
            GamutMapping::GreyAxis(UniformSpace::Luv) => "grey-axis clip in CIELUV".into(),
            GamutMapping::Perpendicular => "perpendicular projection in XYZ".into(),
            GamutMapping::PerpendicularLab => {
                "perpendicular projection in CIELAB (nearest in ΔE00)".into()
            }
            GamutMapping::Hpminde => "HPMINDE (CIE 156, hue-preserving minimum ΔE*ab)".into(),
            GamutMapping::Sgck(source) => format!(
                "SGCK (CIE 156, sigmoidal lightness and cusp knee scaling from {})",
                source.space().name
            ),
            GamutMapping::Smith => "Smith (α = β = 0.75, γ = 5)".into(),
            GamutMapping::StoneCowanBeatty(o) => {
                let umbrella = if o.umbrella == 1.0 {
                    String::new()
                } else {
                    format!(", umbrella × {}", o.umbrella)
                };
                format!(
                    "Stone–Cowan–Beatty (≤ {:.1} % left outside{umbrella}, then projected in CIELAB)",
                    o.outside * 100.0
                )
            }
        }
    }

    /// Whether the mapping is one transform of the whole scene (chosen from all its
    /// colours), so that a colour's result depends on the others.
    pub fn is_scene_wide(&self) -> bool {
        matches!(
            self,
            GamutMapping::Smith | GamutMapping::StoneCowanBeatty(_)
        )
    }
}

/// Per-channel clipping in cube coordinates.
pub fn clip(gamut: &GamutAt, xyz: &Xyz) -> Xyz {
    let a = gamut.to_cube(xyz);
    if cube_contains(&a) {
        return *xyz;
    }
    let a = a.map(|v| v.clamp(0.0, 1.0));
    gamut.from_cube(&a)
}

/// Bisection steps of the grey-axis clip: the chroma found is within 2⁻⁴⁰ of the
/// boundary's, far below any display's code step.
const BISECTION_STEPS: usize = 40;

/// The largest t ≥ 0 with `inside(t)` along a ray that holds t = 0 and leaves the set
/// once: doubled from `start` until outside (unbounded rays stop at 10⁶), then
/// bisected. `None` when t = 0 is outside. HPMINDE's largest chroma at a lightness
/// and SGCK's boundaries along its lines are both this.
fn last_inside(inside: impl Fn(f64) -> bool, start: f64) -> Option<f64> {
    last_inside_within(inside, start, BISECTION_STEPS)
}

/// [`last_inside`] bisected `steps` times: within 2^−steps of the ray's length to the
/// first point found outside.
fn last_inside_within(inside: impl Fn(f64) -> bool, start: f64, steps: usize) -> Option<f64> {
    if !inside(0.0) {
        return None;
    }
    let mut outside = start;
    while inside(outside) {
        outside *= 2.0;
        if outside > 1e6 {
            return Some(outside);
        }
    }
    let mut inner = 0.0;
    for _ in 0..steps {
        let mid = 0.5 * (inner + outside);
        if inside(mid) {
            inner = mid;
        } else {
            outside = mid;
        }
    }
    Some(inner)
}

/// Clip toward the grey axis at constant hue: keep the colour's lightness (brought into
/// the range of this position's grey axis first) and hue angle in `space`, and scale
/// its chroma down until it is inside. `white` is the reference white of `space`
/// (the display's centre white, so its greys are a* = b* = 0).
///
/// Near black a display's black can differ in chromaticity from its white, so the
/// neutral itself may lie just outside; what is left outside then is clipped per
/// channel (hue is kept exactly only where the neutral is inside).
pub fn grey_axis_clip(gamut: &GamutAt, xyz: &Xyz, space: UniformSpace, white: &Xyz) -> Xyz {
    if gamut.contains(xyz) {
        return *xyz;
    }
    let to = |x: &Xyz| to_uniform(space, x, white);
    let from = |c: [f64; 3]| from_uniform(space, c, white);
    let [l, c1, c2] = to(xyz);
    let lightest = to(&gamut.white())[0];
    let darkest = to(&gamut.black())[0];
    let l = l.clamp(darkest, lightest);
    let at = |t: f64| from([l, t * c1, t * c2]);
    if !gamut.contains(&at(0.0)) {
        return clip(gamut, &at(0.0));
    }
    let (mut inside, mut outside) = (0.0, 1.0);
    if gamut.contains(&at(1.0)) {
        return at(1.0);
    }
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (inside + outside);
        if gamut.contains(&at(mid)) {
            inside = mid;
        } else {
            outside = mid;
        }
    }
    at(inside)
}

/// L*, a*, b* (or L*, u*, v*) of `xyz` against `white`.
fn to_uniform(space: UniformSpace, xyz: &Xyz, white: &Xyz) -> [f64; 3] {
    match space {
        UniformSpace::Lab => {
            let c = xyz_to_lab(xyz, white);
            [c.l, c.a, c.b]
        }
        UniformSpace::Luv => {
            let c = xyz_to_luv(xyz, white);
            [c.l, c.u, c.v]
        }
    }
}

/// XYZ of L*, a*, b* (or L*, u*, v*) against `white`.
fn from_uniform(space: UniformSpace, c: [f64; 3], white: &Xyz) -> Xyz {
    match space {
        UniformSpace::Lab => lab_to_xyz(
            &Lab {
                l: c[0],
                a: c[1],
                b: c[2],
            },
            white,
        ),
        UniformSpace::Luv => luv_to_xyz(
            &Luv {
                l: c[0],
                u: c[1],
                v: c[2],
            },
            white,
        ),
    }
}

/// The point of the gamut nearest to `xyz` in XYZ: minimise |P (a − a₀)|² over the
/// unit cube. The problem is a convex quadratic over a box, so its minimum is the
/// stationary point of one face (each coordinate free, at 0 or at 1: 27 faces, edges,
/// corners and the interior); every feasible one is solved exactly and the nearest
/// kept.
///
/// The candidates are compared by aᵀGa − 2aᵀGa₀ (G = PᵀP), the distance less the
/// constant a₀ᵀGa₀, and each face's free coordinates solved from Ga₀ directly: far
/// outside (a grey of 10¹⁸ cd/m²) the distances themselves differ only below their
/// rounding, and the nearest corner would be lost.
pub fn perpendicular(gamut: &GamutAt, xyz: &Xyz) -> Xyz {
    let a0 = gamut.to_cube(xyz);
    if cube_contains(&a0) {
        return *xyz;
    }
    if !a0.iter().all(|v| v.is_finite()) {
        return gamut.from_cube(&a0.map(|v| if v > 0.5 { 1.0 } else { 0.0 }));
    }
    let g = gamut.primaries.transpose() * gamut.primaries;
    let pull = g * a0;
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for face in 0..27u32 {
        // Each coordinate: 0 free, 1 held at 0, 2 held at 1.
        let state = [face % 3, (face / 3) % 3, face / 9];
        let mut a = Vector3::zeros();
        for c in 0..3 {
            if state[c] == 2 {
                a[c] = 1.0;
            }
        }
        let free: Vec<usize> = (0..3).filter(|c| state[*c] == 0).collect();
        if !free.is_empty() {
            // Stationarity on the free coordinates: G_ff a_f = (G a₀)_f − G_fF a_F.
            let n = free.len();
            let gff = nalgebra::DMatrix::from_fn(n, n, |i, j| g[(free[i], free[j])]);
            let rhs = nalgebra::DVector::from_fn(n, |i, _| {
                pull[free[i]]
                    - (0..3)
                        .filter(|c| state[*c] != 0)
                        .map(|c| g[(free[i], c)] * a[c])
                        .sum::<f64>()
            });
            let Some(solution) = gff.lu().solve(&rhs) else {
                continue;
            };
            for (i, c) in free.iter().enumerate() {
                a[*c] = solution[i];
            }
        }
        if !cube_contains(&a) {
            continue;
        }
        let distance = (a.transpose() * g * a)[(0, 0)] - 2.0 * a.dot(&pull);
        if best.as_ref().is_none_or(|(b, _)| distance < *b) {
            best = Some((distance, a));
        }
    }
    let a = best.map_or_else(|| a0.map(|v| v.clamp(0.0, 1.0)), |(_, a)| a);
    gamut.from_cube(&a.map(|v| v.clamp(0.0, 1.0)))
}

/// Largest t with start + t·direction in the unit cube (start inside); ∞ when the
/// direction is zero.
fn ray_exit(start: &Vector3<f64>, direction: &Vector3<f64>) -> f64 {
    let mut t = f64::INFINITY;
    for c in 0..3 {
        let d = direction[c];
        if d > 0.0 {
            t = t.min((1.0 - start[c]) / d);
        } else if d < 0.0 {
            t = t.min(-start[c] / d);
        }
    }
    t.max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// sRGB-like primaries (columns, white Y = 100) and a black of 0.5: the gamut
    /// the mappings' unit tests work in.
    pub(super) fn gamut() -> GamutAt {
        let m = Matrix3::new(
            41.24, 35.76, 18.05, //
            21.26, 71.52, 7.22, //
            1.93, 11.92, 95.05,
        );
        GamutAt::new(Xyz::new(0.475, 0.5, 0.545), m).unwrap()
    }

    #[test]
    fn cube_coordinates_round_trip_and_say_inside() {
        let g = gamut();
        let a = Vector3::new(0.2, 0.7, 1.0);
        let xyz = g.from_cube(&a);
        assert!((g.to_cube(&xyz) - a).norm() < 1e-12);
        assert!(g.contains(&xyz));
        assert!(!g.contains(&g.from_cube(&Vector3::new(0.2, 1.1, 0.5))));
    }

    #[test]
    fn perpendicular_is_the_nearest_point_of_the_gamut() {
        let g = gamut();
        // Points outside in every direction: the projection is inside, on the
        // boundary, and no point of a fine grid of the cube is nearer.
        let outside = [
            Vector3::new(1.4, 0.5, 0.5),
            Vector3::new(-0.3, 0.2, 1.3),
            Vector3::new(1.2, 1.3, -0.4),
            Vector3::new(0.5, -0.2, 0.5),
        ];
        for a0 in outside {
            let xyz = g.from_cube(&a0);
            let p = perpendicular(&g, &xyz);
            let a = g.to_cube(&p);
            assert!(cube_contains(&a));
            assert!(a.iter().any(|v| v.abs() < 1e-9 || (v - 1.0).abs() < 1e-9));
            let d = (p - xyz).norm();
            let n = 20;
            for i in 0..=n {
                for j in 0..=n {
                    for k in 0..=n {
                        let q = g.from_cube(&Vector3::new(
                            i as f64 / n as f64,
                            j as f64 / n as f64,
                            k as f64 / n as f64,
                        ));
                        assert!((q - xyz).norm() >= d - 1e-9, "{a0:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_projection_of_a_very_bright_grey_is_the_white() {
        let g = gamut();
        for scale in [1e3, 1e9, 1e18] {
            let p = perpendicular(&g, &(g.white() * scale));
            assert!(
                (p - g.white()).norm() < 1e-9 * g.white().y,
                "{scale}: {p:?}"
            );
        }
    }

    #[test]
    fn grey_axis_clip_keeps_lightness_and_hue_and_lands_on_the_boundary() {
        let g = gamut();
        let white = g.white();
        for space in [UniformSpace::Lab, UniformSpace::Luv] {
            let xyz = g.from_cube(&Vector3::new(1.3, -0.2, 0.1));
            let mapped = grey_axis_clip(&g, &xyz, space, &white);
            let a = g.to_cube(&mapped);
            assert!(cube_contains(&a));
            assert!(a.iter().any(|v| v.abs() < 1e-6 || (v - 1.0).abs() < 1e-6));
            let (before, after) = match space {
                UniformSpace::Lab => {
                    let (p, q) = (xyz_to_lab(&xyz, &white), xyz_to_lab(&mapped, &white));
                    ([p.l, p.a, p.b], [q.l, q.a, q.b])
                }
                UniformSpace::Luv => {
                    let (p, q) = (xyz_to_luv(&xyz, &white), xyz_to_luv(&mapped, &white));
                    ([p.l, p.u, p.v], [q.l, q.u, q.v])
                }
            };
            assert!((before[0] - after[0]).abs() < 1e-6);
            let hue = |c: [f64; 3]| c[2].atan2(c[1]);
            assert!((hue(before) - hue(after)).abs() < 1e-6);
            assert!(after[1].hypot(after[2]) < before[1].hypot(before[2]));
        }
    }
}
