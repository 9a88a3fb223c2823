//! `[verify]`: what `chromacal verify` judges by when the command line does not say:
//! a named set of criteria, or the user's own limits.
//!
//! ```toml
//! [verify]
//! criteria = "displaycal-recommended"   # or displaycal, iso14861
//! # or limits of one's own:
//! [[verify.criterion]]
//! statistic = "mean"
//! limit = 0.8
//! ```

use serde::{Deserialize, Serialize};

/// The named sets of criteria (`chromacal::verify::criteria::preset`).
pub const CRITERIA_SETS: [&str; 3] = ["displaycal", "displaycal-recommended", "iso14861"];

/// The `[verify]` section.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VerifyConfig {
    /// A named set (`displaycal`, `displaycal-recommended`, `iso14861`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub criteria: Option<String>,
    /// Limits of one's own, used when no set is named.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub criterion: Vec<Criterion>,
}

impl VerifyConfig {
    pub fn is_default(&self) -> bool {
        self == &VerifyConfig::default()
    }

    /// Limits that are not finite and positive, and a named set with limits of its
    /// own beside it, named.
    pub fn check(&self) -> Result<(), String> {
        if self.criteria.is_some() && !self.criterion.is_empty() {
            return Err(
                "verify: give a named set (verify.criteria) or limits of your own ([[verify.criterion]]), not both".into(),
            );
        }
        if let Some(name) = &self.criteria
            && !CRITERIA_SETS.contains(&name.as_str())
        {
            return Err(format!(
                "verify.criteria: no set '{name}' ({})",
                CRITERIA_SETS.join(", ")
            ));
        }
        for (k, c) in self.criterion.iter().enumerate() {
            if !(c.limit > 0.0 && c.limit.is_finite()) {
                return Err(format!(
                    "verify.criterion {}: the limit of '{}' must be a positive number, not {}",
                    k + 1,
                    c.statistic.describe(),
                    c.limit
                ));
            }
        }
        Ok(())
    }
}

/// What a criterion looks at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Statistic {
    /// The measured white against the calibration's target white.
    WhiteToTarget,
    /// The measured white against the profile's prediction of it.
    WhiteToProfile,
    /// The mean ΔE over the judged patches.
    Mean,
    /// The largest ΔE.
    Max,
    /// The 99th percentile of ΔE.
    Percentile99,
    /// Grey balance: the mean of each grey's chroma against the white (|ΔC′00|, or
    /// the CtCp distance for ΔE ITP).
    GreyBalanceMean,
    /// The calibration greys' luminance against the target's tone curve: the largest
    /// miss, in percent of the target (greys of at least 1 % of the white).
    Tone,
    /// Grey balance: the range of the greys' a* and b* values taken together, largest
    /// less smallest (Ct and Cp for ΔE ITP), as DisplayCAL's "combined Δa* and Δb*
    /// range".
    GreyBalanceRange,
}

impl Statistic {
    pub fn describe(self) -> &'static str {
        match self {
            Statistic::WhiteToTarget => "white against the target",
            Statistic::WhiteToProfile => "white against the profile",
            Statistic::Mean => "mean",
            Statistic::Max => "largest",
            Statistic::Percentile99 => "99th percentile",
            Statistic::GreyBalanceMean => "grey balance, mean chroma",
            Statistic::GreyBalanceRange => "grey balance, a* and b* range",
            Statistic::Tone => "tone curve, largest miss (%)",
        }
    }
}

/// One limit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Criterion {
    pub statistic: Statistic,
    pub limit: f64,
}
