//! What a verification must achieve, as calibration users name it: DisplayCAL's
//! default tolerances (its "nominal" set) and its recommended ones, for the RGB chart
//! with grey balance; ISO 14861:2015's colour accuracy (mean ΔE00 ≤ 2.5, 99th
//! percentile ≤ 4.5); and the user's own (`[verify]` in the config).
//!
//! DisplayCAL's figures (its measurement report's `CRITERIA_RULES_DEFAULT` and
//! `CRITERIA_RULES_VERIFY`): the white against the target ΔE00 ≤ 2 (recommended 1),
//! against the profile recommended ≤ 1; mean ΔE00 ≤ 1.5 (1); largest ΔE00 ≤ 4 (3); grey
//! balance over the greys of at least 1 % luminance, mean |ΔC′00| ≤ 1 (0.5) and the
//! range of their a* and b* values taken together ≤ 2 (1.5). For ΔE ITP its limits are the white 2 (1),
//! the mean 1.5 (1), the largest 5 (3), grey balance in CtCp as for ΔC′00.
//!
//! chromacal adds one criterion to DisplayCAL's sets, since a verification through
//! the calibration is also a check of the calibration: the tone curve, the largest
//! miss of a calibration grey's luminance from the target's, 10 % (5 % recommended).

use serde::{Deserialize, Serialize};

use super::Metric;
pub use crate::config::verify::{Criterion, Statistic};

/// A named set of limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CriteriaSet {
    pub name: String,
    pub criteria: Vec<Criterion>,
}

/// The named sets, for `--criteria`.
pub const PRESETS: [&str; 3] = crate::config::verify::CRITERIA_SETS;

fn set(name: &str, limits: &[(Statistic, f64)]) -> CriteriaSet {
    CriteriaSet {
        name: name.to_string(),
        criteria: limits
            .iter()
            .map(|&(statistic, limit)| Criterion { statistic, limit })
            .collect(),
    }
}

/// A named set, for `metric`; `None` for an unknown name.
pub fn preset(name: &str, metric: Metric) -> Option<CriteriaSet> {
    use Statistic::*;
    let itp = metric == Metric::Itp;
    Some(match name {
        "displaycal" => set(
            "DisplayCAL's default tolerances",
            &[
                (WhiteToTarget, 2.0),
                (Mean, 1.5),
                (Max, if itp { 5.0 } else { 4.0 }),
                (GreyBalanceMean, 1.0),
                (GreyBalanceRange, 2.0),
                (Tone, 10.0),
            ],
        ),
        "displaycal-recommended" => set(
            "DisplayCAL's recommended tolerances",
            &[
                (WhiteToTarget, 1.0),
                (WhiteToProfile, 1.0),
                (Mean, 1.0),
                (Max, 3.0),
                (GreyBalanceMean, 0.5),
                (GreyBalanceRange, 1.5),
                (Tone, 5.0),
            ],
        ),
        "iso14861" => set(
            "ISO 14861:2015 colour accuracy",
            &[(Mean, 2.5), (Percentile99, 4.5)],
        ),
        _ => return None,
    })
}

impl CriteriaSet {
    /// In a sentence, for the page and the summary.
    pub fn describe(&self, metric: Metric) -> String {
        let limits: Vec<String> = self
            .criteria
            .iter()
            .map(|c| format!("{} ≤ {}", c.statistic.describe(), c.limit))
            .collect();
        format!("{} ({}): {}", self.name, metric.name(), limits.join(", "))
    }

    /// Limits that are not finite and positive, named.
    pub fn check(&self) -> Result<(), String> {
        for c in &self.criteria {
            if !(c.limit > 0.0 && c.limit.is_finite()) {
                return Err(format!(
                    "{}: the limit of '{}' must be a positive number, not {}",
                    self.name,
                    c.statistic.describe(),
                    c.limit
                ));
            }
        }
        if self.criteria.is_empty() {
            return Err(format!("{}: no criteria", self.name));
        }
        Ok(())
    }
}

/// The outcome of a criterion, or of a whole verification, with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// Passes even at the top of its 95 % interval.
    Pass,
    /// Fails even at the bottom of its 95 % interval.
    Fail,
    /// The limit lies inside the interval: more readings would tell.
    Undecided,
}

impl Verdict {
    /// A value against `limit`, given its 95 % interval.
    pub fn of(interval: [f64; 2], limit: f64) -> Verdict {
        if interval[1] <= limit {
            Verdict::Pass
        } else if interval[0] > limit {
            Verdict::Fail
        } else {
            Verdict::Undecided
        }
    }

    /// All of them together: any fail fails, else any undecided leaves it undecided.
    pub fn all(verdicts: impl IntoIterator<Item = Verdict>) -> Verdict {
        verdicts
            .into_iter()
            .fold(Verdict::Pass, |acc, v| match (acc, v) {
                (Verdict::Fail, _) | (_, Verdict::Fail) => Verdict::Fail,
                (Verdict::Undecided, _) | (_, Verdict::Undecided) => Verdict::Undecided,
                _ => Verdict::Pass,
            })
    }

    pub fn name(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Fail => "fail",
            Verdict::Undecided => "undecided",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_verdict_is_decided_only_outside_the_interval() {
        assert_eq!(Verdict::of([0.2, 0.8], 1.0), Verdict::Pass);
        assert_eq!(Verdict::of([1.2, 1.8], 1.0), Verdict::Fail);
        assert_eq!(Verdict::of([0.8, 1.2], 1.0), Verdict::Undecided);
        assert_eq!(
            Verdict::all([Verdict::Pass, Verdict::Undecided]),
            Verdict::Undecided
        );
        assert_eq!(
            Verdict::all([Verdict::Undecided, Verdict::Fail, Verdict::Pass]),
            Verdict::Fail
        );
    }

    #[test]
    fn the_presets_are_there_and_sound() {
        for name in PRESETS {
            for metric in [Metric::De00, Metric::Itp] {
                preset(name, metric).unwrap().check().unwrap();
            }
        }
        assert!(preset("strict", Metric::De00).is_none());
        let bad = set("mine", &[(Statistic::Mean, -1.0)]);
        assert!(bad.check().unwrap_err().contains("positive"));
    }
}
