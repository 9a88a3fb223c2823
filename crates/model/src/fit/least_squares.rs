//! Weighted least squares: linear (for starting values, polynomials and surfaces) and
//! nonlinear (Gauss–Newton with a backtracking line search, from `argmin`), with the
//! parameter covariance from the Jacobian.
//!
//! Residuals are (f(xᵢ; θ) − yᵢ) / σᵢ, so each point counts by its real noise σᵢ: the
//! maximum-likelihood fit under Gaussian noise. The covariance is (JᵀJ)⁻¹ scaled by
//! the reduced χ² when that exceeds 1 (the model misses by more than the noise), so a
//! standard error is never smaller than the noise alone allows.

use argmin::core::{Error as ArgminError, Executor, Jacobian, Operator};
use argmin::solver::gaussnewton::GaussNewtonLS;
use argmin::solver::linesearch::BacktrackingLineSearch;
use argmin::solver::linesearch::condition::ArmijoCondition;
use nalgebra::{DMatrix, DVector};

/// A curve f(x; θ) that writes ∂f/∂θ into `gradient` and returns f.
pub type Curve<'a> = &'a (dyn Fn(&[f64], f64, &mut [f64]) -> f64 + Sync);

/// Result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LeastSquares {
    pub params: Vec<f64>,
    /// Covariance of the parameters; `None` when there are no degrees of freedom or
    /// the normal matrix is singular.
    pub covariance: Option<DMatrix<f64>>,
    /// Σ rᵢ² at the solution.
    pub chi2: f64,
    /// Points minus parameters.
    pub dof: usize,
    /// (JᵀJ)⁻¹ Jᵀ with weighted rows: how each weighted point moves the parameters.
    pub sensitivity: Option<DMatrix<f64>>,
}

impl LeastSquares {
    /// Standard errors, or `None` each when the covariance is unknown.
    pub fn standard_errors(&self) -> Vec<Option<f64>> {
        match &self.covariance {
            Some(c) => (0..self.params.len())
                .map(|i| Some(c[(i, i)].max(0.0).sqrt()))
                .collect(),
            None => vec![None; self.params.len()],
        }
    }
}

/// Why a least-squares fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LeastSquaresError {
    #[error("{points} points cannot determine {params} parameters")]
    TooFewPoints { points: usize, params: usize },
    #[error("the fit did not converge: {0}")]
    NoConvergence(String),
    #[error("the fit gave parameters that are not finite")]
    NotFinite,
}

struct Problem<'a> {
    curve: Curve<'a>,
    x: &'a [f64],
    y: &'a [f64],
    sigma: &'a [f64],
    /// Evaluations of the residuals so far: argmin's backtracking line search has no
    /// bound of its own, so the fit ends itself after `MAX_EVALUATIONS`.
    evaluations: std::sync::atomic::AtomicUsize,
}

/// Most evaluations of the residuals one fit may make (100 Gauss–Newton steps of a
/// line search each take a few dozen at most); past it the fit fails with a reason
/// instead of running for ever on data that make no sense.
const MAX_EVALUATIONS: usize = 20_000;

/// What a residual that is not finite (or absurdly large) counts as: large enough to
/// reject any step, small enough that a sum of squares of thousands of them stays
/// finite, so the line search always compares numbers.
const RESIDUAL_CAP: f64 = 1e100;

impl Problem<'_> {
    /// The weighted residuals alone: what the line search asks for most often, without
    /// building a Jacobian it would throw away.
    fn residuals(&self, theta: &[f64]) -> DVector<f64> {
        let mut gradient = vec![0.0; theta.len()];
        DVector::from_iterator(
            self.x.len(),
            (0..self.x.len()).map(|i| {
                ((self.curve)(theta, self.x[i], &mut gradient) - self.y[i]) / self.sigma[i]
            }),
        )
    }

    fn residuals_and_jacobian(&self, theta: &[f64]) -> (DVector<f64>, DMatrix<f64>) {
        let n = self.x.len();
        let p = theta.len();
        let mut r = DVector::zeros(n);
        let mut j = DMatrix::zeros(n, p);
        let mut gradient = vec![0.0; p];
        for i in 0..n {
            let f = (self.curve)(theta, self.x[i], &mut gradient);
            r[i] = (f - self.y[i]) / self.sigma[i];
            for k in 0..p {
                j[(i, k)] = gradient[k] / self.sigma[i];
            }
        }
        (r, j)
    }
}

impl Operator for Problem<'_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;

    fn apply(&self, theta: &Self::Param) -> Result<Self::Output, ArgminError> {
        let n = self
            .evaluations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if super::cancel::requested() {
            return Err(ArgminError::msg("stopped"));
        }
        if n >= MAX_EVALUATIONS {
            return Err(ArgminError::msg(format!(
                "no step lowered the misfit in {MAX_EVALUATIONS} evaluations (readings out of all proportion?)"
            )));
        }
        let r = self.residuals(theta.as_slice());
        Ok(r.map(|v| {
            if v.is_finite() {
                v.clamp(-RESIDUAL_CAP, RESIDUAL_CAP)
            } else {
                RESIDUAL_CAP
            }
        }))
    }
}

impl Jacobian for Problem<'_> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;

    fn jacobian(&self, theta: &Self::Param) -> Result<Self::Jacobian, ArgminError> {
        let (_, j) = self.residuals_and_jacobian(theta.as_slice());
        Ok(j.map(|v| if v.is_finite() { v } else { 0.0 }))
    }
}

/// Fit `curve` to points (x, y) with standard deviations `sigma`, from `start`.
pub fn fit_curve(
    curve: Curve<'_>,
    x: &[f64],
    y: &[f64],
    sigma: &[f64],
    start: &[f64],
) -> Result<LeastSquares, LeastSquaresError> {
    let p = start.len();
    if x.len() < p {
        return Err(LeastSquaresError::TooFewPoints {
            points: x.len(),
            params: p,
        });
    }
    let problem = Problem {
        curve,
        x,
        y,
        sigma,
        evaluations: Default::default(),
    };
    let condition =
        ArmijoCondition::new(1e-4).map_err(|e| LeastSquaresError::NoConvergence(e.to_string()))?;
    let solver = GaussNewtonLS::new(BacktrackingLineSearch::new(condition))
        .with_tolerance(1e-12)
        .map_err(|e| LeastSquaresError::NoConvergence(e.to_string()))?;
    let result = Executor::new(problem, solver)
        .configure(|state| {
            state
                .param(DVector::from_column_slice(start))
                .max_iters(100)
        })
        .run()
        .map_err(|e| LeastSquaresError::NoConvergence(e.to_string()))?;
    let state = result.state();
    let theta = state
        .best_param
        .clone()
        .or_else(|| state.param.clone())
        .ok_or_else(|| LeastSquaresError::NoConvergence("no parameters".into()))?;
    if theta.iter().any(|v| !v.is_finite()) {
        return Err(LeastSquaresError::NotFinite);
    }
    let problem = Problem {
        curve,
        x,
        y,
        sigma,
        evaluations: Default::default(),
    };
    Ok(summarise(&problem, theta.as_slice()))
}

fn summarise(problem: &Problem<'_>, theta: &[f64]) -> LeastSquares {
    let (r, j) = problem.residuals_and_jacobian(theta);
    let chi2 = r.norm_squared();
    let dof = problem.x.len().saturating_sub(theta.len());
    let normal = j.transpose() * &j;
    let inverse = normal.try_inverse();
    let covariance = match (&inverse, dof) {
        (Some(inv), d) if d > 0 => Some(inv * (chi2 / d as f64).max(1.0)),
        _ => None,
    };
    let sensitivity = inverse.map(|inv| inv * j.transpose());
    LeastSquares {
        params: theta.to_vec(),
        covariance,
        chi2,
        dof,
        sensitivity,
    }
}

/// Weighted linear least squares: minimise Σ ((A θ − y)ᵢ / σᵢ)², by SVD so that a
/// rank-deficient design gives the minimum-norm solution instead of a failure.
pub fn fit_linear(
    design: &DMatrix<f64>,
    y: &[f64],
    sigma: &[f64],
) -> Result<LeastSquares, LeastSquaresError> {
    let (n, p) = design.shape();
    if n < p || p == 0 {
        return Err(LeastSquaresError::TooFewPoints {
            points: n,
            params: p,
        });
    }
    let mut a = design.clone();
    let mut b = DVector::from_column_slice(y);
    for i in 0..n {
        let w = 1.0 / sigma[i];
        a.row_mut(i).scale_mut(w);
        b[i] *= w;
    }
    let svd =
        chromacal_color::linalg::bounded_svd(a.clone()).ok_or(LeastSquaresError::NotFinite)?;
    let theta = svd
        .solve(&b, 1e-12)
        .map_err(|e| LeastSquaresError::NoConvergence(e.to_string()))?;
    if theta.iter().any(|v| !v.is_finite()) {
        return Err(LeastSquaresError::NotFinite);
    }
    let r = &a * &theta - &b;
    let chi2 = r.norm_squared();
    let dof = n - p;
    let inverse = (a.transpose() * &a).try_inverse();
    let covariance = match (&inverse, dof) {
        (Some(inv), d) if d > 0 => Some(inv * (chi2 / d as f64).max(1.0)),
        _ => None,
    };
    let sensitivity = inverse.map(|inv| inv * a.transpose());
    Ok(LeastSquares {
        params: theta.iter().copied().collect(),
        covariance,
        chi2,
        dof,
        sensitivity,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_power_law_and_its_uncertainty() {
        // y = x^2.4 with 1 % noise drawn from a fixed pattern.
        let x: Vec<f64> = (1..=12).map(|i| i as f64 / 12.0).collect();
        let wiggle = [
            0.3, -0.8, 1.1, -0.2, 0.5, -1.4, 0.9, 0.1, -0.6, 1.2, -0.9, 0.4,
        ];
        let y: Vec<f64> = x
            .iter()
            .zip(wiggle)
            .map(|(x, w)| x.powf(2.4) * (1.0 + 0.01 * w))
            .collect();
        let sigma: Vec<f64> = y.iter().map(|y| 0.01 * y).collect();
        let curve = |t: &[f64], x: f64, g: &mut [f64]| {
            let f = x.powf(t[0]);
            g[0] = f * x.ln();
            f
        };
        let fit = fit_curve(&curve, &x, &y, &sigma, &[2.0]).unwrap();
        let se = fit.standard_errors()[0].unwrap();
        assert!((fit.params[0] - 2.4).abs() < 3.0 * se, "{fit:?}");
        assert!(se > 0.001 && se < 0.05, "{se}");
        assert_eq!(fit.dof, 11);
    }

    #[test]
    fn weights_make_the_precise_points_count() {
        // Two groups disagree; the precise one must win.
        let x = [1.0, 1.0, 1.0, 1.0];
        let y = [10.0, 10.0, 20.0, 20.0];
        let sigma = [0.1, 0.1, 10.0, 10.0];
        let design = DMatrix::from_row_slice(4, 1, &x);
        let fit = fit_linear(&design, &y, &sigma).unwrap();
        assert!((fit.params[0] - 10.0).abs() < 0.01, "{:?}", fit.params);
    }

    #[test]
    fn too_few_points_is_an_error() {
        let curve = |t: &[f64], x: f64, g: &mut [f64]| {
            g[0] = x;
            g[1] = 1.0;
            t[0] * x + t[1]
        };
        assert!(matches!(
            fit_curve(&curve, &[1.0], &[1.0], &[1.0], &[0.0, 0.0]),
            Err(LeastSquaresError::TooFewPoints { .. })
        ));
    }
}
