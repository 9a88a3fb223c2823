//! The spatial gain map K(p): how much of the centre's light a patch gives at screen
//! position p (Brainard 1989 measured up to 20 % less at the edges of a CRT).
//!
//! K is a smooth surface, a polynomial in the centred screen coordinates
//! u = 2x − 1, v = 2y − 1 with every monomial of total degree 1 to `degree`, and
//! K = 1 at the centre by construction (the primary matrix is measured there).

use serde::{Deserialize, Serialize};

/// A position on the screen as fractions of its width and height, (0, 0) at the top
/// left and (0.5, 0.5) at the centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScreenPosition {
    pub x: f64,
    pub y: f64,
}

impl ScreenPosition {
    pub const CENTRE: ScreenPosition = ScreenPosition { x: 0.5, y: 0.5 };

    pub fn new(x: f64, y: f64) -> Self {
        ScreenPosition { x, y }
    }

    /// Distance from the centre in centred coordinates (the corners are at √2).
    pub fn radius(&self) -> f64 {
        (2.0 * self.x - 1.0).hypot(2.0 * self.y - 1.0)
    }

    pub fn is_centre(&self) -> bool {
        (self.x - 0.5).abs() < 1e-9 && (self.y - 0.5).abs() < 1e-9
    }
}

impl Default for ScreenPosition {
    fn default() -> Self {
        ScreenPosition::CENTRE
    }
}

/// The monomials uⁱvʲ with 1 ≤ i + j ≤ `degree`, in order of degree, then of i.
pub fn surface_basis(position: ScreenPosition, degree: u32) -> Vec<f64> {
    let u = 2.0 * position.x - 1.0;
    let v = 2.0 * position.y - 1.0;
    let mut terms = Vec::new();
    for total in 1..=degree {
        for i in (0..=total).rev() {
            terms.push(u.powi(i as i32) * v.powi((total - i) as i32));
        }
    }
    terms
}

/// Number of monomials in [`surface_basis`] for `degree`.
pub fn surface_term_count(degree: u32) -> usize {
    let d = degree as usize;
    d * (d + 3) / 2
}

/// K(p) = 1 + Σ c_k φ_k(p).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    pub degree: u32,
    pub coefficients: Vec<f64>,
}

impl Surface {
    /// K(p), the monomials of `surface_basis` in the same order, made on the way (no
    /// allocation: this runs once a pixel when a scene is rendered).
    pub fn gain(&self, position: ScreenPosition) -> f64 {
        let degree = (self.degree as usize).min(MAX_SURFACE_DEGREE as usize);
        let (mut u, mut v) = (
            [1.0; MAX_SURFACE_DEGREE as usize + 1],
            [1.0; MAX_SURFACE_DEGREE as usize + 1],
        );
        for k in 1..=degree {
            u[k] = u[k - 1] * (2.0 * position.x - 1.0);
            v[k] = v[k - 1] * (2.0 * position.y - 1.0);
        }
        let mut coefficients = self.coefficients.iter();
        let mut sum = 1.0;
        for total in 1..=degree {
            for i in (0..=total).rev() {
                let Some(c) = coefficients.next() else {
                    return sum;
                };
                sum += c * u[i] * v[total - i];
            }
        }
        sum
    }
}

/// The spatial part of the monitor model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SpatialMap {
    /// K = 1 everywhere: no map was needed, or none was measured.
    #[default]
    Uniform,
    /// One gain for all three channels.
    Scalar { surface: Surface },
    /// A gain per channel (R, G, B).
    PerChannel { surfaces: [Surface; 3] },
}

/// Highest degree of a surface a profile may hold: the fit tries 2 and 4; a degree
/// of 4294967295 in a hand-edited file once made every use of the profile hang.
pub const MAX_SURFACE_DEGREE: u32 = 8;

/// Largest size of a surface coefficient a profile may hold. Fitted surfaces move the
/// light by fractions (coefficients of 0.1 or so for a 15 % falloff); a coefficient of
/// 1e308, finite as it is, made every forward prediction infinite.
pub const MAX_SURFACE_COEFFICIENT: f64 = 100.0;

impl SpatialMap {
    /// Why the map is not usable, if it is not: a degree above `MAX_SURFACE_DEGREE`,
    /// a number of coefficients that is not the degree's, or one not finite.
    pub fn problem(&self) -> Option<String> {
        let surfaces: &[Surface] = match self {
            SpatialMap::Uniform => &[],
            SpatialMap::Scalar { surface } => std::slice::from_ref(surface),
            SpatialMap::PerChannel { surfaces } => surfaces,
        };
        surfaces.iter().find_map(|s| {
            if s.degree > MAX_SURFACE_DEGREE {
                Some(format!(
                    "a surface of degree {} (at most {MAX_SURFACE_DEGREE})",
                    s.degree
                ))
            } else if s.coefficients.len() != surface_term_count(s.degree) {
                Some(format!(
                    "a surface of degree {} with {} coefficients (it has {})",
                    s.degree,
                    s.coefficients.len(),
                    surface_term_count(s.degree)
                ))
            } else if s.coefficients.iter().any(|c| !c.is_finite()) {
                Some("a surface coefficient that is not a finite number".to_string())
            } else {
                s.coefficients
                    .iter()
                    .find(|c| c.abs() > MAX_SURFACE_COEFFICIENT)
                    .map(|c| {
                        format!(
                            "a surface coefficient of {c:e} (at most {MAX_SURFACE_COEFFICIENT:e} in size)"
                        )
                    })
            }
        })
    }

    /// Gains of the R, G and B channels at `position`.
    pub fn gains(&self, position: ScreenPosition) -> [f64; 3] {
        match self {
            SpatialMap::Uniform => [1.0; 3],
            SpatialMap::Scalar { surface } => [surface.gain(position); 3],
            SpatialMap::PerChannel { surfaces } => [
                surfaces[0].gain(position),
                surfaces[1].gain(position),
                surfaces[2].gain(position),
            ],
        }
    }

    pub fn describe(&self) -> String {
        match self {
            SpatialMap::Uniform => "uniform (no spatial map)".into(),
            SpatialMap::Scalar { surface } => {
                format!(
                    "one gain surface for all channels, degree {}",
                    surface.degree
                )
            }
            SpatialMap::PerChannel { surfaces } => {
                format!("a gain surface per channel, degree {}", surfaces[0].degree)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_sizes_and_centre() {
        for d in 0..5 {
            assert_eq!(
                surface_basis(ScreenPosition::new(0.2, 0.7), d).len(),
                surface_term_count(d)
            );
        }
        let s = Surface {
            degree: 2,
            coefficients: vec![0.1, -0.2, -0.05, 0.01, -0.04],
        };
        assert!((s.gain(ScreenPosition::CENTRE) - 1.0).abs() < 1e-15);
        // At the right edge (u = 1, v = 0): 1 + 0.1 − 0.05.
        assert!((s.gain(ScreenPosition::new(1.0, 0.5)) - 1.05).abs() < 1e-12);
        // Anywhere: the sum over the basis.
        let p = ScreenPosition::new(0.13, 0.71);
        let by_basis: f64 = 1.0
            + surface_basis(p, 2)
                .iter()
                .zip(&s.coefficients)
                .map(|(phi, c)| phi * c)
                .sum::<f64>();
        assert!((s.gain(p) - by_basis).abs() < 1e-15);
    }
}
