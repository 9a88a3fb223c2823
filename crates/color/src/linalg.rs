//! Matrix decompositions that always end.
//!
//! nalgebra's plain `svd` and `SymmetricEigen::new` iterate until they converge, which
//! a matrix holding NaN or ∞ never does: one absurd reading in a journal once hung the
//! fit for ever. Every decomposition in chromacal goes through here.

use nalgebra::{Matrix3, SymmetricEigen};

/// Most sweeps a decomposition may take before it is given up.
pub const MAX_DECOMPOSITION_SWEEPS: usize = 10_000;

/// The SVD of `m`, or `None` if it holds a number that is not finite or the
/// decomposition does not converge within `MAX_DECOMPOSITION_SWEEPS`.
pub fn bounded_svd<R, C>(m: nalgebra::OMatrix<f64, R, C>) -> Option<nalgebra::SVD<f64, R, C>>
where
    R: nalgebra::DimMin<C>,
    C: nalgebra::Dim,
    nalgebra::DimMinimum<R, C>: nalgebra::DimSub<nalgebra::U1>,
    nalgebra::DefaultAllocator: nalgebra::allocator::Allocator<R, C>
        + nalgebra::allocator::Allocator<C>
        + nalgebra::allocator::Allocator<R>
        + nalgebra::allocator::Allocator<nalgebra::DimDiff<nalgebra::DimMinimum<R, C>, nalgebra::U1>>
        + nalgebra::allocator::Allocator<nalgebra::DimMinimum<R, C>, C>
        + nalgebra::allocator::Allocator<R, nalgebra::DimMinimum<R, C>>
        + nalgebra::allocator::Allocator<nalgebra::DimMinimum<R, C>>,
{
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    m.try_svd(true, true, f64::EPSILON, MAX_DECOMPOSITION_SWEEPS)
}

/// The eigen-decomposition of a symmetric 3 × 3 matrix, or `None` as for `bounded_svd`.
pub fn bounded_symmetric_eigen(m: Matrix3<f64>) -> Option<SymmetricEigen<f64, nalgebra::U3>> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    SymmetricEigen::try_new(m, f64::EPSILON, MAX_DECOMPOSITION_SWEEPS)
}

/// The 3 × 3 matrix M minimising Σ wᵢ‖M·aᵢ − bᵢ‖² over `(a, b, w)` (weighted linear
/// least squares, by its normal equations M = (Σ w b aᵀ)(Σ w a aᵀ)⁻¹); `None` when the
/// `a` do not span three dimensions or a value is not finite.
pub fn weighted_linear_map(
    pairs: &[(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>, f64)],
) -> Option<Matrix3<f64>> {
    let mut aa = Matrix3::<f64>::zeros();
    let mut ba = Matrix3::<f64>::zeros();
    for (a, b, w) in pairs {
        aa += *w * a * a.transpose();
        ba += *w * b * a.transpose();
    }
    if !aa.iter().chain(ba.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let m = ba * aa.try_inverse()?;
    m.iter().all(|v| v.is_finite()).then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn a_matrix_with_a_non_finite_entry_has_no_decomposition() {
        let mut m = DMatrix::from_element(4, 3, 1.0);
        assert!(bounded_svd(m.clone()).is_some());
        m[(2, 1)] = f64::INFINITY;
        assert!(bounded_svd(m.clone()).is_none());
        m[(2, 1)] = f64::NAN;
        assert!(bounded_svd(m).is_none());
        let mut s = Matrix3::identity();
        assert!(bounded_symmetric_eigen(s).is_some());
        s[(0, 0)] = f64::NEG_INFINITY;
        assert!(bounded_symmetric_eigen(s).is_none());
    }
}
