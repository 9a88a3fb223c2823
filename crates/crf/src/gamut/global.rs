//! Global transformations of a whole scene (seed §4.3.2): Stone, Cowan and Beatty's
//! transform in XYZ, and Smith's in the RGB cube. Each is chosen once from all the
//! scene's colours and then applied to every one of them, so a colour's result
//! depends on the rest of the scene (unlike clipping, which sees one colour at a time).

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::{GamutAt, ray_exit};
use chromacal_color::Xyz;
use chromacal_color::spaces::luminance_to_lightness;

/// What the user chooses of Stone–Cowan–Beatty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScbOptions {
    /// The share of the scene's colours (highlights apart) the transform may leave
    /// outside, for the projection to bring in.
    pub outside: f64,
    /// The umbrella transformation: every colour's distance from the scene's grey
    /// axis multiplied by this (above 1 saturates, below 1 desaturates; 1: none).
    pub umbrella: f64,
}

impl Default for ScbOptions {
    fn default() -> Self {
        ScbOptions {
            outside: 0.01,
            umbrella: 1.0,
        }
    }
}

/// The Stone–Cowan–Beatty transform chosen for a scene:
/// X_d = B_d + bs (W_d − B_d) + csf R U(X_i − B_i).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StoneCowanBeatty {
    /// bs: the black shift, as a share of the way from the display's black to white.
    pub black_shift: f64,
    /// csf: the contrast scale factor.
    pub contrast_scale: f64,
    /// B_i: the scene's black, on its grey axis at its darkest luminance (not the
    /// darkest colour, whose hue would tint every grey).
    pub scene_black: [f64; 3],
    /// W_i: the scene's white on its grey axis: its own white when known, else its
    /// lightest luminance.
    pub scene_white: [f64; 3],
    /// R, row by row: the rotation taking the scene's grey axis onto the display's
    /// (the identity when they are parallel).
    pub rotation: [[f64; 3]; 3],
    /// The umbrella factor U applied about the scene's grey axis.
    pub umbrella: f64,
    /// Colours brighter than the scene's white: specular highlights and light
    /// sources, left outside for the projection rather than compressing the scene.
    pub highlights: usize,
    /// Colours the transform leaves outside, highlights included.
    pub left_outside: usize,
    /// L* (against the display's white) of the scene's black and white on the
    /// display: the contrast the choice maximised.
    pub lightness: [f64; 2],
    /// B_d and W_d − B_d: the display's black and white at the centre.
    display_black: [f64; 3],
    display_range: [f64; 3],
}

/// Black shifts tried, as shares of the display's range (Stone et al. move black up
/// a little to keep dark saturated colours inside).
const BLACK_SHIFTS: [f64; 9] = [0.0, 0.0025, 0.005, 0.01, 0.02, 0.035, 0.05, 0.1, 0.2];

impl StoneCowanBeatty {
    /// Choose bs and csf for `scene` (colours with the gamut of their positions) by
    /// Stone, Cowan and Beatty's rules in order:
    ///
    /// 1. **the grey axis is kept**: B_i and W_i lie on the scene's grey axis (the
    ///    direction `grey`, the chromaticity of the scene's neutrals) and R turns
    ///    that axis onto the display's B_d → W_d, so every neutral lands on the
    ///    display's grey axis whatever else the scene holds;
    /// 2. **luminance contrast is maximised**: of the black shifts tried, the one
    ///    whose scene white and black land furthest apart in L* wins (not the one
    ///    with the largest csf: a shift of 0.2 buys csf at the price of a black at
    ///    L* 50);
    /// 3. **few colours stay outside**: for each black shift, csf is the largest that
    ///    leaves at most `options.outside` of the colours outside. A colour moves
    ///    along a ray from the shifted black (inside) and a ray leaves the
    ///    parallelepiped once, so each colour's largest csf is exact and the csf
    ///    for a share is a quantile of them (the share rounded up to whole colours,
    ///    so a small scene may leave one out). Colours brighter than the scene's
    ///    white (`scene_white`, when the scene has one) are highlights: they do not
    ///    count, and are projected instead of darkening the scene. The scene's white
    ///    itself must land inside.
    pub fn fit(
        scene: &[(Xyz, &GamutAt)],
        centre: &GamutAt,
        grey: &Xyz,
        scene_white: Option<f64>,
        options: ScbOptions,
    ) -> Option<StoneCowanBeatty> {
        if !(grey.y > 0.0 && grey.iter().all(|v| v.is_finite())) {
            return None;
        }
        let g = grey / grey.y;
        let lightest = scene.iter().map(|(x, _)| x.y).fold(f64::NAN, f64::max);
        let darkest = scene
            .iter()
            .map(|(x, _)| x.y.max(0.0))
            .fold(f64::NAN, f64::min);
        if !(lightest.is_finite() && darkest.is_finite()) {
            return None;
        }
        let given_white = scene_white.filter(|w| *w > darkest && w.is_finite());
        let white_y = given_white.unwrap_or(lightest);
        let scene_black = g * darkest;
        let scene_white = g * white_y;
        let display_black = centre.black();
        let display_range = centre.white() - display_black;
        let rotation = rotation_between(&g, &display_range);
        let direction = |x: &Xyz| rotation * umbrella(&(x - scene_black), &g, options.umbrella);
        let is_highlight = |x: &Xyz| given_white.is_some() && x.y > white_y * (1.0 + 1e-9);
        let highlights = scene.iter().filter(|(x, _)| is_highlight(x)).count();
        let counted: Vec<&(Xyz, &GamutAt)> =
            scene.iter().filter(|(x, _)| !is_highlight(x)).collect();
        // Rounded up: 1 % of a 24-colour chart is one colour, not none (rounding down
        // forced small scenes to keep every colour inside, whatever the contrast).
        let allowed = (options.outside.clamp(0.0, 1.0) * counted.len() as f64 - 1e-9)
            .ceil()
            .max(0.0) as usize;
        let white_lightness = |y: f64| luminance_to_lightness(y / centre.white().y);
        let mut best: Option<StoneCowanBeatty> = None;
        for bs in BLACK_SHIFTS {
            let shifted = display_black + display_range * bs;
            let white_limit = ray_exit(
                &centre.to_cube(&shifted),
                &(centre.inverse * direction(&scene_white)),
            );
            let mut limits: Vec<f64> = counted
                .iter()
                .map(|(x, gamut)| {
                    ray_exit(&gamut.to_cube(&shifted), &(gamut.inverse * direction(x)))
                })
                .collect();
            limits.sort_by(f64::total_cmp);
            let share_limit = limits.get(allowed).copied().unwrap_or(f64::INFINITY);
            let csf = share_limit.min(white_limit);
            let csf = if csf.is_finite() {
                csf
            } else {
                // Nothing bounds it (a scene of one grey): its white on the display's.
                let span = (direction(&scene_white)).y;
                if span > 0.0 {
                    display_range.y * (1.0 - bs) / span
                } else {
                    1.0
                }
            };
            if !(csf > 0.0) {
                continue;
            }
            let black_out = shifted;
            let white_out = shifted + direction(&scene_white) * csf;
            let lightness = [white_lightness(black_out.y), white_lightness(white_out.y)];
            let contrast = lightness[1] - lightness[0];
            let better = best
                .as_ref()
                .is_none_or(|b| contrast > b.lightness[1] - b.lightness[0] + 1e-9);
            if better {
                let left = limits.iter().filter(|t| **t < csf * (1.0 - 1e-12)).count();
                best = Some(StoneCowanBeatty {
                    black_shift: bs,
                    contrast_scale: csf,
                    scene_black: scene_black.into(),
                    scene_white: scene_white.into(),
                    rotation: [0, 1, 2].map(|r| [0, 1, 2].map(|c| rotation[(r, c)])),
                    umbrella: options.umbrella,
                    highlights,
                    left_outside: left + highlights,
                    lightness,
                    display_black: display_black.into(),
                    display_range: display_range.into(),
                });
            }
        }
        best
    }

    /// X_d = B_d + bs (W_d − B_d) + csf R U(X_i − B_i).
    pub fn apply(&self, xyz: &Xyz) -> Xyz {
        let rotation = Matrix3::from_fn(|r, c| self.rotation[r][c]);
        let black = Xyz::from(self.scene_black);
        let g = Xyz::from(self.scene_white) - black;
        let axis = if g.y > 0.0 {
            g / g.y
        } else {
            Xyz::new(1.0, 1.0, 1.0)
        };
        Xyz::from(self.display_black)
            + Xyz::from(self.display_range) * self.black_shift
            + rotation * umbrella(&(xyz - black), &axis, self.umbrella) * self.contrast_scale
    }
}

/// The umbrella transformation about the axis `g`: the part of `v` across the axis
/// scaled by `factor`, the part along it kept.
fn umbrella(v: &Xyz, g: &Xyz, factor: f64) -> Xyz {
    if factor == 1.0 {
        return *v;
    }
    let along = g * (g.dot(v) / g.dot(g));
    along + (v - along) * factor
}

/// The rotation (Rodrigues) taking the direction of `from` onto that of `to`; the
/// identity when they are parallel or either is zero.
fn rotation_between(from: &Xyz, to: &Xyz) -> Matrix3<f64> {
    let (Some(u), Some(v)) = (from.try_normalize(1e-300), to.try_normalize(1e-300)) else {
        return Matrix3::identity();
    };
    let k = u.cross(&v);
    let (s, c) = (k.norm(), u.dot(&v));
    if s < 1e-12 {
        return Matrix3::identity();
    }
    let kx = k.cross_matrix();
    Matrix3::identity() + kx + kx * kx * ((1.0 - c) / (s * s))
}

/// Smith's global transformation (seed §4.3.2, after Smith 1993), in the display's
/// RGB cube (cube coordinates: each channel's linear light as a share of its full
/// drive, above black).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Smith {
    /// Y_max: "the luminance of the most luminous object in the scene, except light
    /// sources": the scene's white when known, else its lightest colour.
    pub y_max: f64,
    pub alpha: f64,
    pub beta: f64,
    pub gamma: f64,
}

impl Smith {
    /// The survey's values "after perceptual experiments": α = β = 0.75, γ = 5.
    pub const ALPHA: f64 = 0.75;
    pub const BETA: f64 = 0.75;
    pub const GAMMA: f64 = 5.0;

    /// Smith's transform for a scene with these luminances and, when known, white.
    pub fn fit(luminances: impl Iterator<Item = f64>, scene_white: Option<f64>) -> Option<Smith> {
        let y_max = match scene_white {
            Some(w) if w > 0.0 && w.is_finite() => w,
            _ => luminances
                .filter(|y| y.is_finite())
                .fold(f64::NAN, f64::max),
        };
        (y_max > 0.0).then_some(Smith {
            y_max,
            alpha: Self::ALPHA,
            beta: Self::BETA,
            gamma: Self::GAMMA,
        })
    }

    /// The two steps, for a colour shown where `gamut` holds:
    ///
    /// 1. its RGB vector turned toward the grey axis (1, 1, 1) in the plane of the
    ///    two, from angle θ₀ to θ₁ = θ₀ (1 − (Y / γY_max)^β): "objects of high
    ///    luminance appear whiter than chromaticity would suggest";
    /// 2. scaled by (Y / Y_max)^α. The survey states R₂ = R₁ (Y / Y_max)^α; read with
    ///    R₁ as the colour's direction (normalised here to the display white's
    ///    luminance), so that luminance goes as a compressive power of Y / Y_max and
    ///    Y_max lands at the display's white. What is still outside the cube is
    ///    clipped, as the survey's RGB methods do.
    pub fn apply(&self, gamut: &GamutAt, xyz: &Xyz) -> Xyz {
        let ratio = (xyz.y / self.y_max).max(0.0);
        let a = gamut.to_cube(xyz);
        if ratio == 0.0 || !ratio.is_finite() || a.norm() == 0.0 {
            return gamut.black();
        }
        let n = Vector3::repeat(1.0 / 3f64.sqrt());
        let p = a.dot(&n);
        let across = a - n * p;
        let q = across.norm();
        let theta0 = q.atan2(p);
        let keep = (1.0 - (ratio / self.gamma).powf(self.beta)).max(0.0);
        let theta1 = theta0 * keep;
        let direction = if q > 0.0 {
            n * theta1.cos() + across / q * theta1.sin()
        } else {
            n
        };
        let luminance_row = gamut.primaries.row(1);
        let white_luminance = luminance_row.sum();
        let luminance = (luminance_row * direction)[(0, 0)];
        let direction = if luminance > 0.0 { direction } else { n };
        let luminance = (luminance_row * direction)[(0, 0)];
        let r2 = direction * (white_luminance / luminance * ratio.powf(self.alpha));
        gamut.from_cube(&r2.map(|v| v.clamp(0.0, 1.0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::super::tests::gamut;

    fn fit(g: &GamutAt, scene: &[Xyz], white: Option<f64>, outside: f64) -> StoneCowanBeatty {
        let with: Vec<(Xyz, &GamutAt)> = scene.iter().map(|x| (*x, g)).collect();
        let options = ScbOptions {
            outside,
            ..ScbOptions::default()
        };
        StoneCowanBeatty::fit(&with, g, &g.white(), white, options).unwrap()
    }

    #[test]
    fn scb_leaves_at_most_the_share_asked_outside() {
        let g = gamut();
        let scene: Vec<Xyz> = (0..50)
            .map(|i| {
                let t = i as f64 / 49.0;
                g.from_cube(&Vector3::new(1.5 * t, 1.2 - t, 0.3 + t))
            })
            .collect();
        for outside in [0.0, 0.1] {
            let scb = fit(&g, &scene, None, outside);
            let left = scene.iter().filter(|x| !g.contains(&scb.apply(x))).count();
            assert!(left as f64 <= outside * 50.0 + 1e-9, "{left}");
            assert_eq!(left, scb.left_outside);
            assert!(scb.contrast_scale > 0.0 && scb.contrast_scale < 1.0);
        }
    }

    #[test]
    fn the_rotation_takes_one_axis_onto_the_other() {
        let (from, to) = (Xyz::new(0.9, 1.0, 1.2), Xyz::new(1.1, 1.0, 0.7));
        let r = rotation_between(&from, &to);
        let turned = r * from;
        assert!((turned.normalize() - to.normalize()).norm() < 1e-12);
        assert!((turned.norm() - from.norm()).abs() < 1e-12);
        assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-12);
    }

    #[test]
    fn smith_whitens_bright_colours_and_compresses_luminance() {
        let g = gamut();
        let smith = Smith::fit([100.0].into_iter(), None).unwrap();
        let white = g.white();
        // A saturated red at full and at a tenth of Y_max.
        let bright = g.from_cube(&Vector3::new(1.0, 0.1, 0.1));
        let dim = g.from_cube(&Vector3::new(0.1, 0.01, 0.01));
        let angle = |x: &Xyz| {
            let a = g.to_cube(x);
            let n = Vector3::repeat(1.0 / 3f64.sqrt());
            (a - n * a.dot(&n)).norm().atan2(a.dot(&n))
        };
        let (b, d) = (smith.apply(&g, &bright), smith.apply(&g, &dim));
        // The bright one turned toward grey by more than the dim one (in proportion).
        let turn = |x: &Xyz, y: &Xyz| angle(y) / angle(x);
        assert!(turn(&bright, &b) < turn(&dim, &d));
        // Luminance: (Y/Y_max)^0.75 of the white, above the black.
        let expect = |x: &Xyz| (x.y / 100.0).powf(0.75) * (white.y - g.black().y) + g.black().y;
        assert!(
            (d.y - expect(&dim)).abs() < 1e-9 * white.y,
            "{} {}",
            d.y,
            expect(&dim)
        );
        assert!(g.contains(&b) && g.contains(&d));
    }
}
