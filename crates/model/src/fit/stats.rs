//! Small statistics used across fitting and reporting.

use serde::{Deserialize, Serialize};

/// Mean, 95th percentile and maximum of a set of errors (ΔE00 unless stated).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    pub n: usize,
    pub mean: f64,
    pub p95: f64,
    pub max: f64,
}

impl ErrorStats {
    /// `None` for an empty set.
    pub fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        Some(ErrorStats {
            n: values.len(),
            mean: mean(values),
            p95: percentile(values, 95.0),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        })
    }
}

impl ErrorStats {
    /// As [`ErrorStats::of`] the values and `zeros` more values of 0, for errors
    /// (never below 0) most of which are 0: a render's pixels the mapping left as
    /// they were. The same numbers as `of` over all of them in any order of the
    /// zeros (a sum is unchanged by adding 0), without holding the zeros.
    pub fn of_with_zeros(values: &[f64], zeros: usize) -> Option<Self> {
        let n = values.len() + zeros;
        if n == 0 {
            return None;
        }
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(ErrorStats {
            n,
            // A sum starts from −0, which a zero added makes +0.
            mean: if zeros > 0 {
                values.iter().sum::<f64>() + 0.0
            } else {
                values.iter().sum::<f64>()
            } / n as f64,
            p95: percentile_with_zeros(values, zeros, 95.0),
            max: if zeros > 0 { max.max(0.0) } else { max },
        })
    }
}

pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Sample standard deviation (n − 1); 0 for fewer than two values.
pub fn standard_deviation(values: &[f64]) -> f64 {
    if values.len() < 2 {
        return 0.0;
    }
    let m = mean(values);
    (values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt()
}

/// The `p`-th percentile by linear interpolation between order statistics
/// (Hyndman & Fan 1996, definition 7, as NumPy's default).
///
/// The two order statistics are selected, not sorted for (Hoare's selection, O(n)):
/// `render` takes the percentiles of a ΔE00 for every pixel of an image, where a sort
/// of 4 million values was a tenth of the command's time.
pub fn percentile(values: &[f64], p: f64) -> f64 {
    let mut order = values.to_vec();
    let rank = (p / 100.0).clamp(0.0, 1.0) * (order.len() - 1) as f64;
    let lo = rank.floor() as usize;
    let hi = rank.ceil() as usize;
    let (_, at_lo, above) = order.select_nth_unstable_by(lo, |a, b| a.total_cmp(b));
    let at_lo = *at_lo;
    // The next order statistic is the least of those above.
    let at_hi = if hi > lo {
        above
            .iter()
            .copied()
            .min_by(|a, b| a.total_cmp(b))
            .unwrap_or(at_lo)
    } else {
        at_lo
    };
    at_lo + (at_hi - at_lo) * (rank - lo as f64)
}

/// [`percentile`] of the values and `zeros` more values of 0: in the order
/// `total_cmp` gives, the zeros come after the values below +0 (none for errors, but
/// a NaN with its sign set sorts there) and before the rest.
fn percentile_with_zeros(values: &[f64], zeros: usize, p: f64) -> f64 {
    let n = values.len() + zeros;
    let rank = (p / 100.0).clamp(0.0, 1.0) * (n - 1) as f64;
    let (lo, hi) = (rank.floor() as usize, rank.ceil() as usize);
    let below = values.iter().filter(|v| v.total_cmp(&0.0).is_lt()).count();
    let mut order = values.to_vec();
    let mut statistic = |i: usize| {
        if (below..below + zeros).contains(&i) {
            0.0
        } else {
            let i = if i < below { i } else { i - zeros };
            *order.select_nth_unstable_by(i, |a, b| a.total_cmp(b)).1
        }
    };
    let at_lo = statistic(lo);
    let at_hi = if hi > lo { statistic(hi) } else { at_lo };
    at_lo + (at_hi - at_lo) * (rank - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_like_numpy() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(percentile(&v, 50.0), 3.0);
        assert!((percentile(&v, 95.0) - 4.8).abs() < 1e-12);
        let s = ErrorStats::of(&v).unwrap();
        assert_eq!((s.n, s.mean, s.max), (5, 3.0, 5.0));
        assert!(ErrorStats::of(&[]).is_none());
        assert!((standard_deviation(&[1.0, 3.0]) - 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn selected_percentiles_equal_the_sorted_ones() {
        // A fixed pseudo-random sample with ties.
        let values: Vec<f64> = (0..1001u64)
            .map(|i| ((i * 7919) % 613) as f64 / 17.0)
            .collect();
        let mut sorted = values.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        for p in [0.0, 1.0, 50.0, 95.0, 99.9, 100.0] {
            let rank = p / 100.0 * (sorted.len() - 1) as f64;
            let (lo, hi) = (rank.floor() as usize, rank.ceil() as usize);
            let expected = sorted[lo] + (sorted[hi] - sorted[lo]) * (rank - lo as f64);
            assert_eq!(percentile(&values, p), expected, "p{p}");
        }
        assert_eq!(percentile(&[2.5], 95.0), 2.5);
    }

    /// Errors with zeros counted equal the same errors with the zeros held, for any
    /// share of zeros (none, a few, most, all but one, all) and any rank.
    #[test]
    fn zeros_counted_give_the_statistics_of_zeros_held() {
        let mut values: Vec<f64> = (0..997u64)
            .map(|i| ((i * 7919) % 613) as f64 / 17.0 + 0.01)
            .collect();
        // A NaN with its sign set (as x86 makes ∞ − ∞), which sorts below the zeros.
        values[1] = -f64::NAN;
        for zeros in [0, 1, 30, 5_000, 20_000] {
            for kept in [0, 1, 2, 50, 997] {
                let kept = &values[..kept];
                // The zeros among the values, the values in their order, as a render
                // meets them.
                let half = kept.len() / 2;
                let mut held = kept[..half].to_vec();
                held.extend(std::iter::repeat_n(0.0, zeros));
                held.extend_from_slice(&kept[half..]);
                let counted = ErrorStats::of_with_zeros(kept, zeros);
                // To the bit (a mean of −0 prints as "-0.000"; a NaN is not equal to
                // itself).
                let bits = |s: Option<ErrorStats>| {
                    s.map(|s| (s.n, [s.mean, s.p95, s.max].map(f64::to_bits)))
                };
                assert_eq!(
                    bits(counted),
                    bits(ErrorStats::of(&held)),
                    "{zeros} zeros, {kept:?}"
                );
                for p in [0.0, 50.0, 95.0, 99.99, 100.0] {
                    if !held.is_empty() {
                        assert_eq!(
                            percentile_with_zeros(kept, zeros, p).to_bits(),
                            percentile(&held, p).to_bits(),
                            "p{p}, {zeros} zeros, {} kept",
                            kept.len()
                        );
                    }
                }
            }
        }
    }
}
