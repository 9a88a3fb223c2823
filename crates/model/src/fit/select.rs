//! "Model only what is needed": among candidates scored on the same held-out items,
//! keep the simplest whose error is within noise of the best.
//!
//! Rule: candidates come in order of complexity. For each, the paired differences
//! dᵢ = errᵢ(candidate) − errᵢ(best) over the held-out items are formed; the first
//! candidate whose mean difference is at most one standard error of that mean (the
//! one-standard-error rule of Breiman et al. 1984, on paired differences), or at most
//! `noise_tolerance` (what measurement noise alone does to an item's error), is kept.
//! The second bound keeps a consistent but invisible gain, such as 0.002 ΔE00, from
//! buying a parameter.

use super::stats::{mean, standard_deviation};

/// Index of the candidate to keep. `errors[k]` holds candidate k's error on each
/// held-out item (the same items, in the same order, for every candidate); `None`
/// marks a candidate that could not be scored. `None` overall when no candidate was.
pub fn simplest_within_noise(errors: &[Option<Vec<f64>>], noise_tolerance: f64) -> Option<usize> {
    simplest_within(errors, noise_tolerance, 1.0)
}

/// As [`simplest_within_noise`], with the bound on the paired mean difference at
/// `standard_errors` standard errors instead of one: a stricter test for a candidate
/// that adds a term to the model rather than choosing among laws (two standard errors
/// keep a useless term's chance of being kept near 2 %, one-sided).
pub fn simplest_within(
    errors: &[Option<Vec<f64>>],
    noise_tolerance: f64,
    standard_errors: f64,
) -> Option<usize> {
    let best = errors
        .iter()
        .enumerate()
        .filter_map(|(k, e)| e.as_ref().filter(|e| !e.is_empty()).map(|e| (k, mean(e))))
        .min_by(|a, b| a.1.total_cmp(&b.1))?
        .0;
    let best_errors = errors[best].as_ref()?;
    for (k, candidate) in errors.iter().enumerate() {
        let Some(candidate) = candidate else { continue };
        if candidate.len() != best_errors.len() {
            continue;
        }
        let d: Vec<f64> = candidate
            .iter()
            .zip(best_errors)
            .map(|(c, b)| c - b)
            .collect();
        let se = standard_errors * standard_deviation(&d) / (d.len() as f64).sqrt();
        if mean(&d) <= se.max(noise_tolerance) {
            return Some(k);
        }
    }
    Some(best)
}

/// Does `candidate` lower the error of `base` (the same held-out items, in the same
/// order) by more than `standard_errors` standard errors of the paired differences and
/// more than `noise_tolerance`? The test for adding a term to a model: it is asked of
/// the model the term adds to, never of a third candidate.
pub fn improves_on(
    candidate: &[f64],
    base: &[f64],
    noise_tolerance: f64,
    standard_errors: f64,
) -> bool {
    if candidate.is_empty() || candidate.len() != base.len() {
        return false;
    }
    let gain: Vec<f64> = base.iter().zip(candidate).map(|(b, c)| b - c).collect();
    let se = standard_errors * standard_deviation(&gain) / (gain.len() as f64).sqrt();
    mean(&gain) > se.max(noise_tolerance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simpler_candidate_within_noise_wins() {
        let simple = vec![1.0, 1.2, 0.9, 1.1, 1.0];
        let complex = vec![0.98, 1.21, 0.88, 1.12, 0.97];
        assert_eq!(
            simplest_within_noise(&[Some(simple.clone()), Some(complex.clone())], 0.0),
            Some(0)
        );
        // Consistently but invisibly worse: kept only with a noise tolerance.
        let worse: Vec<f64> = complex.iter().map(|c| c + 0.01).collect();
        assert_eq!(
            simplest_within_noise(&[Some(worse.clone()), Some(complex.clone())], 0.0),
            Some(1)
        );
        assert_eq!(
            simplest_within_noise(&[Some(worse), Some(complex)], 0.05),
            Some(0)
        );
    }

    #[test]
    fn a_term_improves_only_on_what_it_adds_to() {
        let base = vec![1.0, 1.2, 0.9, 1.1, 1.0, 1.3];
        let better: Vec<f64> = base.iter().map(|b| b - 0.2).collect();
        let noisy = vec![0.7, 1.5, 0.6, 1.4, 0.8, 1.5];
        assert!(improves_on(&better, &base, 0.05, 2.0));
        // The same gain is not enough when noise alone explains it.
        assert!(!improves_on(&better, &base, 0.3, 2.0));
        // Lower on some items, higher on others: not an improvement.
        assert!(!improves_on(&noisy, &base, 0.0, 2.0));
        assert!(!improves_on(&base, &better, 0.0, 2.0));
        assert!(!improves_on(&[], &[], 0.0, 2.0));
    }

    #[test]
    fn a_clearly_better_complex_candidate_wins() {
        let simple = vec![2.0, 2.2, 1.9, 2.1, 2.0];
        let complex = vec![0.5, 0.6, 0.4, 0.5, 0.55];
        assert_eq!(
            simplest_within_noise(&[Some(simple), None, Some(complex)], 0.05),
            Some(2)
        );
        assert_eq!(simplest_within_noise(&[None, None], 0.0), None);
    }
}
