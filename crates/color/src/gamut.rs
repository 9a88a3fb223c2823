//! Gamut volume and coverage of additive displays against the reference RGB spaces.
//!
//! An additive display's colours fill a parallelepiped in XYZ: its black plus every
//! mixture of its three primaries. To compare two displays whose whites differ, each
//! is seen relative to its own white (Y = 1) and adapted to D50 (Bradford), as an ICC
//! profile's relative colorimetric rendering places it in the profile connection
//! space, and the solids are compared in CIE 1976 L*a*b* under D50: volume in cubic
//! ΔE*ab, and the coverage of a reference (the share of its volume the display also
//! reaches). This is how ArgyllCMS's `viewgam` and DisplayCAL's report compare gamuts;
//! the volume here is counted on a lattice of L*a*b* points rather than from a mesh,
//! which is exact for any solid to the lattice's resolution (§ `LATTICE_STEP`).
//!
//! The chromaticity gamut is also given as the u′v′ triangle's area and the share of
//! a reference triangle it covers (convex polygon clipping, Sutherland and Hodgman
//! 1974, *Reentrant polygon clipping*, CACM 17(1)).

use nalgebra::Matrix3;

use super::adaptation::{AdaptationTransform, adapt};
use super::spaces::{
    Lab, Xyy, Xyz, lab_to_xyz, xy_to_uv_prime, xyy_to_xyz, xyz_to_lab, xyz_to_uv_prime,
};

/// CIE 1931 xy of D65 (CIE 15:2004 Table T.3).
const D65_XY: [f64; 2] = [0.3127, 0.3290];

/// The ICC profile connection space's white, D50 (ISO 15076-1 §7.2.16), Y = 1.
pub const D50: Xyz = Xyz::new(0.9642, 1.0, 0.8249);

/// Spacing of the L*a*b* lattice the volumes are counted on, in ΔE*ab. At 1.5 the
/// count of sRGB's volume (about 830 000 ΔE³, 250 000 points) is within 0.1 % of the
/// count at half the spacing (test `the_lattice_is_fine_enough`).
const LATTICE_STEP: f64 = 1.5;

/// A reference RGB colour space: its primaries' and white's CIE 1931 xy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbSpace {
    pub name: &'static str,
    pub primaries: [[f64; 2]; 3],
    pub white: [f64; 2],
}

/// IEC 61966-2-1 sRGB (the ITU-R BT.709 primaries), D65.
pub const SRGB: RgbSpace = RgbSpace {
    name: "sRGB",
    primaries: [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]],
    white: D65_XY,
};
/// Adobe RGB (1998) Color Image Encoding, version 2005-05, §4.3: D65.
pub const ADOBE_RGB: RgbSpace = RgbSpace {
    name: "Adobe RGB",
    primaries: [[0.64, 0.33], [0.21, 0.71], [0.15, 0.06]],
    white: D65_XY,
};
/// Display P3: the SMPTE RP 431-2 (DCI-P3) primaries with a D65 white (SMPTE EG 432-1).
pub const DISPLAY_P3: RgbSpace = RgbSpace {
    name: "Display P3",
    primaries: [[0.680, 0.320], [0.265, 0.690], [0.150, 0.060]],
    white: D65_XY,
};
/// ITU-R BT.2020, D65.
pub const REC_2020: RgbSpace = RgbSpace {
    name: "Rec. 2020",
    primaries: [[0.708, 0.292], [0.170, 0.797], [0.131, 0.046]],
    white: D65_XY,
};

/// The spaces a display's gamut is set against, smallest first.
pub const REFERENCE_SPACES: [RgbSpace; 4] = [SRGB, ADOBE_RGB, DISPLAY_P3, REC_2020];

/// An additive display's colour solid relative to its own white: XYZ = black +
/// primaries · rgb for rgb in [0, 1]³, with black + the primaries' sum at Y = 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdditiveGamut {
    /// Columns: the primaries' XYZ above black.
    pub primaries: Matrix3<f64>,
    pub black: Xyz,
}

impl AdditiveGamut {
    /// The solid of a reference space: primaries scaled so that they sum to its white
    /// (SMPTE RP 177-1993 §3.3), black at zero. `None` for degenerate primaries.
    pub fn of_space(space: &RgbSpace) -> Option<AdditiveGamut> {
        let xyz = |[x, y]: [f64; 2]| xyy_to_xyz(&Xyy { x, y, big_y: 1.0 });
        let unscaled = Matrix3::from_columns(&space.primaries.map(xyz));
        let white = xyz(space.white);
        let scale = unscaled.try_inverse()? * white;
        Some(AdditiveGamut {
            primaries: unscaled * Matrix3::from_diagonal(&scale),
            black: Xyz::zeros(),
        })
    }

    /// A display's solid from its primary matrix (columns above black) and black, in
    /// any unit: divided by the white's Y. `None` when the white is not positive.
    pub fn of_display(primaries: &Matrix3<f64>, black: &Xyz) -> Option<AdditiveGamut> {
        let white_y = black.y + primaries.row(1).sum();
        (white_y > 0.0 && white_y.is_finite()).then(|| AdditiveGamut {
            primaries: primaries / white_y,
            black: black / white_y,
        })
    }

    pub fn white(&self) -> Xyz {
        self.black + self.primaries.column_sum()
    }

    /// The primaries' chromaticities, u′v′.
    pub fn primaries_uv(&self) -> [(f64, f64); 3] {
        [0, 1, 2].map(|c| {
            let p = xyz_to_uv_prime(&self.primaries.column(c).into(), D65_UV);
            (p.u, p.v)
        })
    }

    /// The solid as seen in the profile connection space: adapted from its white to
    /// D50 (Bradford), ready to be tested point by point.
    fn in_pcs(&self) -> Option<PcsSolid> {
        let white = self.white();
        let to_d50 = |xyz: Xyz| adapt(&xyz, AdaptationTransform::Bradford, &white, &D50);
        let primaries =
            Matrix3::from_columns(&[0, 1, 2].map(|c| to_d50(self.primaries.column(c).into())));
        Some(PcsSolid {
            inverse: primaries.try_inverse()?,
            black: to_d50(self.black),
            primaries,
        })
    }
}

const D65_UV: super::spaces::UvPrime = super::spaces::UvPrime {
    u: 0.1978,
    v: 0.4683,
};

/// A solid in D50 XYZ, with the inverse that tells whether a colour is inside.
struct PcsSolid {
    primaries: Matrix3<f64>,
    inverse: Matrix3<f64>,
    black: Xyz,
}

impl PcsSolid {
    fn contains(&self, xyz: &Xyz) -> bool {
        let rgb = self.inverse * (xyz - self.black);
        rgb.iter().all(|c| (-1e-12..=1.0 + 1e-12).contains(c))
    }

    /// The L*a*b* box the solid lies in: its eight corners do not bound it in L*a*b*
    /// (the edges bow), so the edges are sampled.
    fn lab_bounds(&self) -> [(f64, f64); 3] {
        let mut bounds = [(f64::INFINITY, f64::NEG_INFINITY); 3];
        let n = 24;
        for i in 0..=n {
            for j in 0..=n {
                for k in [0, n] {
                    // Every face of the cube: k on one axis, i and j on the others.
                    for rgb in [[i, j, k], [i, k, j], [k, i, j]] {
                        let t = rgb.map(|v| v as f64 / n as f64);
                        let xyz = self.black + self.primaries * Xyz::new(t[0], t[1], t[2]);
                        let lab = xyz_to_lab(&xyz, &D50);
                        for (b, v) in bounds.iter_mut().zip([lab.l, lab.a, lab.b]) {
                            *b = (b.0.min(v), b.1.max(v));
                        }
                    }
                }
            }
        }
        bounds
    }
}

/// A display's gamut against one reference space.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GamutComparison {
    pub reference: &'static str,
    /// Share of the reference's L*a*b* volume the display reaches, 0–1.
    pub coverage: f64,
    /// The display's L*a*b* volume over the reference's.
    pub relative_volume: f64,
    /// Share of the reference's u′v′ triangle the display's triangle covers, 0–1.
    pub uv_coverage: f64,
    /// The display's u′v′ triangle's area over the reference's.
    pub uv_relative_area: f64,
}

/// The L*a*b* volumes (cubic ΔE*ab) of `display`, of `reference` and of what both
/// reach, counted on a lattice of spacing `step` over the reference's box and the
/// display's.
fn lab_volumes(display: &PcsSolid, reference: &PcsSolid, step: f64) -> (f64, f64, f64) {
    let (d, r) = (display.lab_bounds(), reference.lab_bounds());
    let range = |i: usize| (d[i].0.min(r[i].0), d[i].1.max(r[i].1));
    let count = |(lo, hi): (f64, f64)| ((hi - lo) / step).ceil().max(1.0) as usize;
    let ranges = [range(0), range(1), range(2)];
    let [nl, na, nb] = ranges.map(count);
    let (mut both, mut only_display, mut only_reference) = (0usize, 0usize, 0usize);
    for i in 0..nl {
        let l = ranges[0].0 + (i as f64 + 0.5) * step;
        for j in 0..na {
            let a = ranges[1].0 + (j as f64 + 0.5) * step;
            for k in 0..nb {
                let b = ranges[2].0 + (k as f64 + 0.5) * step;
                let xyz = lab_to_xyz(&Lab { l, a, b }, &D50);
                match (display.contains(&xyz), reference.contains(&xyz)) {
                    (true, true) => both += 1,
                    (true, false) => only_display += 1,
                    (false, true) => only_reference += 1,
                    (false, false) => {}
                }
            }
        }
    }
    let cell = step.powi(3);
    (
        (both + only_display) as f64 * cell,
        (both + only_reference) as f64 * cell,
        both as f64 * cell,
    )
}

/// The L*a*b* volume of a solid in cubic ΔE*ab (D50, relative to its white).
pub fn lab_volume(gamut: &AdditiveGamut) -> Option<f64> {
    let solid = gamut.in_pcs()?;
    Some(lab_volumes(&solid, &solid, LATTICE_STEP).0)
}

/// `display`'s gamut against `reference`: coverage and relative volume in L*a*b*,
/// coverage and relative area in u′v′. `None` when either solid is degenerate.
pub fn compare(display: &AdditiveGamut, reference: &RgbSpace) -> Option<GamutComparison> {
    let reference_gamut = AdditiveGamut::of_space(reference)?;
    let (dv, rv, both) = lab_volumes(&display.in_pcs()?, &reference_gamut.in_pcs()?, LATTICE_STEP);
    let display_uv = display.primaries_uv();
    let reference_uv = reference_gamut.primaries_uv();
    let reference_area = polygon_area(&reference_uv);
    (rv > 0.0 && reference_area > 0.0).then(|| GamutComparison {
        reference: reference.name,
        coverage: both / rv,
        relative_volume: dv / rv,
        uv_coverage: polygon_area(&clip_convex(&reference_uv, &display_uv)) / reference_area,
        uv_relative_area: polygon_area(&display_uv) / reference_area,
    })
}

/// The u′v′ of a space's primaries, for drawing.
pub fn space_uv(space: &RgbSpace) -> [(f64, f64); 3] {
    space.primaries.map(|[x, y]| {
        let p = xy_to_uv_prime(x, y);
        (p.u, p.v)
    })
}

/// Area of a simple polygon (the shoelace formula), whatever its winding.
pub fn polygon_area(points: &[(f64, f64)]) -> f64 {
    let n = points.len();
    let twice: f64 = (0..n)
        .map(|i| {
            let (a, b) = (points[i], points[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    twice.abs() / 2.0
}

/// The part of convex polygon `subject` inside convex polygon `clip`
/// (Sutherland–Hodgman: clip by each edge's half-plane in turn).
pub fn clip_convex(subject: &[(f64, f64)], clip: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let n = clip.len();
    // The side of the clip polygon's interior: the sign of its winding.
    let winding: f64 = (0..n)
        .map(|i| {
            let (a, b) = (clip[i], clip[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum::<f64>()
        .signum();
    let mut out: Vec<(f64, f64)> = subject.to_vec();
    for i in 0..n {
        let (a, b) = (clip[i], clip[(i + 1) % n]);
        let side =
            |p: (f64, f64)| winding * ((b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0));
        let input = std::mem::take(&mut out);
        for j in 0..input.len() {
            let (p, q) = (input[j], input[(j + 1) % input.len()]);
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                out.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                let t = sp / (sp - sq);
                out.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
            }
        }
        if out.is_empty() {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solid(space: &RgbSpace) -> AdditiveGamut {
        AdditiveGamut::of_space(space).unwrap()
    }

    #[test]
    fn a_space_covers_itself_and_the_wider_spaces_contain_srgb() {
        let srgb = solid(&SRGB);
        let own = compare(&srgb, &SRGB).unwrap();
        assert!((own.coverage - 1.0).abs() < 1e-12, "{own:?}");
        assert!((own.uv_coverage - 1.0).abs() < 1e-9, "{own:?}");
        for wider in [ADOBE_RGB, DISPLAY_P3, REC_2020] {
            let c = compare(&solid(&wider), &SRGB).unwrap();
            // Adobe RGB's blue-red edge is sRGB's, so it covers nearly all of sRGB.
            assert!(c.coverage > 0.98, "{} {c:?}", wider.name);
            assert!(c.relative_volume > 1.1, "{} {c:?}", wider.name);
            let back = compare(&srgb, &wider).unwrap();
            assert!(
                back.coverage < 0.9 && back.coverage > 0.4,
                "{} {back:?}",
                wider.name
            );
        }
    }

    #[test]
    fn the_volumes_are_argyll_s() {
        // ArgyllCMS 3.x `iccgamut -v -ir` on the profiles it ships in ref/ (sRGB.icm,
        // ClayRGB1998.icm (Adobe RGB), DisplayP3.icm, Rec2020.icm): total volume in
        // cubic L*a*b* units.
        for (space, argyll) in [
            (SRGB, 833_534.0),
            (ADOBE_RGB, 1_209_986.0),
            (DISPLAY_P3, 1_234_947.0),
            (REC_2020, 1_858_618.0),
        ] {
            let v = lab_volume(&solid(&space)).unwrap();
            assert!(
                (v / argyll - 1.0).abs() < 0.01,
                "{}: {v} against {argyll}",
                space.name
            );
        }
    }

    #[test]
    fn the_lattice_is_fine_enough() {
        let (p3, srgb) = (solid(&DISPLAY_P3), solid(&SRGB));
        let (a, b) = (p3.in_pcs().unwrap(), srgb.in_pcs().unwrap());
        let coarse = lab_volumes(&b, &a, LATTICE_STEP);
        let fine = lab_volumes(&b, &a, LATTICE_STEP / 2.0);
        for (c, f) in [(coarse.0, fine.0), (coarse.1, fine.1), (coarse.2, fine.2)] {
            assert!((c / f - 1.0).abs() < 1e-3, "{coarse:?} {fine:?}");
        }
    }

    #[test]
    fn a_raised_black_costs_volume_at_the_dark_end() {
        let srgb = solid(&SRGB);
        let lifted = AdditiveGamut {
            primaries: srgb.primaries * (1.0 - 0.005),
            black: srgb.white() * 0.005,
        };
        let c = compare(&lifted, &SRGB).unwrap();
        assert!(c.coverage < 0.99 && c.coverage > 0.9, "{c:?}");
        // The chromaticities are the same.
        assert!((c.uv_coverage - 1.0).abs() < 1e-9, "{c:?}");
    }

    #[test]
    fn clipping_two_triangles_gives_their_overlap() {
        let a = [(0.0, 0.0), (2.0, 0.0), (0.0, 2.0)];
        let b = [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0)]; // the other winding
        assert!((polygon_area(&clip_convex(&a, &b)) - 0.5).abs() < 1e-12);
        let apart = [(5.0, 5.0), (6.0, 5.0), (5.0, 6.0)];
        assert_eq!(polygon_area(&clip_convex(&a, &apart)), 0.0);
    }
}
