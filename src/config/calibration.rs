//! The sections that configure a calibration's measuring: `[display.stability]`,
//! `[warmup]` and `[target]`. The code they configure is in `calibrate`.

use serde::{Deserialize, Serialize};

use chromacal_instruments::Reading;
use chromacal_model::target::{Target, TargetError, ToneCurve, parse_tone, parse_white};

/// `[display.stability]`: after the settle time, read again until two readings in a
/// row agree, for displays whose settle time is not known well enough (slow LCD
/// response, CRT persistence, a generator whose frame latency varies). The second
/// reading of the agreeing pair is kept.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Stability {
    /// Relative agreement asked of each of X, Y, Z (each relative to itself: a blue
    /// patch's Z is ten times its Y): set it to about three times the
    /// instrument's repeatability (the difference of two readings has √2 times its
    /// noise).
    pub tolerance: f64,
    /// Absolute agreement (cd/m²) for dim patches, where the instrument's noise floor
    /// dominates.
    pub floor: f64,
    /// Readings per patch at most; the last is kept, with a warning, if none agree.
    pub max_reads: usize,
}

impl Default for Stability {
    fn default() -> Self {
        Stability {
            tolerance: 0.01,
            floor: 0.005,
            max_reads: 6,
        }
    }
}

impl Stability {
    /// Do two readings agree? Tristimulus values where both have them, else luminance.
    pub fn agree(&self, a: &Reading, b: &Reading) -> bool {
        let close =
            |u: f64, v: f64, scale: f64| (u - v).abs() <= self.tolerance * scale + self.floor;
        match (a.xyz, b.xyz) {
            (Some(p), Some(q)) => (0..3).all(|i| close(p[i], q[i], p[i].abs().max(q[i].abs()))),
            _ => match (a.luminance(), b.luminance()) {
                (Some(p), Some(q)) => close(p, q, p.abs().max(q.abs())),
                _ => false,
            },
        }
    }

    /// Has the patch settled at `next`? The last two readings agree (the first two to
    /// within half the tolerance), and where three show a clear trend (the first step beyond the tolerance), what is left of it is
    /// within half the tolerance: a display that decays towards its light (a
    /// brightness limiter after a bright screen, τ of seconds) moves by a factor r a
    /// reading, and after a step d has d · r / (1 − r) still to go, which two readings
    /// that agree do not see.
    pub fn settled(&self, earlier: Option<&Reading>, last: &Reading, next: &Reading) -> bool {
        if !self.agree(last, next) {
            return false;
        }
        let (Some(b), Some(c)) = (last.luminance(), next.luminance()) else {
            return true;
        };
        let step = self.tolerance * c.abs() + self.floor;
        // Two readings alone cannot tell a slow decay from noise: where they are
        // more than half the tolerance apart, a third reading decides.
        let Some(a) = earlier.and_then(Reading::luminance) else {
            return (c - b).abs() <= step / 2.0;
        };
        let (first, second) = (b - a, c - b);
        if first.abs() <= step {
            return true; // no trend beyond the noise
        }
        let r = second / first;
        if !(r > 0.0 && r < 1.0) {
            return r <= 0.0; // a reversal is noise; r ≥ 1 is not settling
        }
        (second * r / (1.0 - r)).abs() <= step / 2.0
    }
}

/// `[warmup]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WarmupConfig {
    /// Wait for warm-up before every job.
    pub enabled: bool,
    /// Seconds between readings of the white patch.
    pub interval_s: f64,
    /// Readings the slope is fitted over.
    pub window: usize,
    /// Go on when |slope| of luminance is below this, relative per minute.
    pub max_slope_per_min: f64,
    /// Go on anyway after this many seconds (with a warning).
    pub max_s: f64,
}

impl Default for WarmupConfig {
    fn default() -> Self {
        WarmupConfig {
            enabled: false,
            interval_s: 30.0,
            window: 5,
            max_slope_per_min: 0.001,
            max_s: 3600.0,
        }
    }
}

impl WarmupConfig {
    pub fn check(&self) -> Result<(), String> {
        if !(self.interval_s > 0.0 && self.max_s >= 0.0 && self.max_slope_per_min > 0.0) {
            return Err(
                "warmup: interval_s and max_slope_per_min must be positive, max_s not negative"
                    .into(),
            );
        }
        if self.window < 3 {
            return Err("warmup.window must be at least 3 readings".into());
        }
        Ok(())
    }
}

/// `[target]`: calibrate the display to this after the profile is fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetConfig {
    /// native, D50, D55, D65, D75, a temperature such as "6500K", or "x,y".
    #[serde(default = "native")]
    pub white: String,
    /// "gamma:2.2", "srgb", "bt1886", "lstar", or for HDR signals "pq" and "hlg".
    #[serde(default = "gamma22")]
    pub tone: String,
    /// White luminance, cd/m² (unset: the most the white point allows).
    pub luminance: Option<f64>,
    /// For `tone = "pq"` or `"hlg"`: the display's peak, cd/m² (the same as
    /// `luminance`, by the name HDR uses; give one of the two).
    pub peak: Option<f64>,
    /// For `tone = "pq"`: roll the signal off from this mastering peak (cd/m²) to
    /// the display's peak by BT.2390's EETF instead of clipping at the peak.
    pub mastering_peak: Option<f64>,
    /// Measured correction passes (0: the model's curves as they are).
    #[serde(default = "two")]
    pub refine_passes: usize,
    /// Grey levels measured in each pass, black to white inclusive.
    #[serde(default = "nine")]
    pub levels: usize,
    /// Bit depth the curves' output reaches the panel at: the codes' where chromacal
    /// applies the curves itself (default: the plan's), the video LUT's output as the
    /// display takes it (the video card's; unknown unless given). Where it is known
    /// the curves are set to the best colours that depth can show.
    pub bit_depth: Option<u32>,
    /// After the curves, measure `chromacal verify`'s default chart through them
    /// against sRGB, so that the calibration report leads with the calibrated display.
    #[serde(default = "yes")]
    pub verify: bool,
}

fn yes() -> bool {
    true
}

fn native() -> String {
    "native".into()
}
fn gamma22() -> String {
    "gamma:2.2".into()
}
fn two() -> usize {
    2
}
fn nine() -> usize {
    9
}

impl TargetConfig {
    pub fn target(&self) -> Result<Target, TargetError> {
        let mut tone = parse_tone(&self.tone)?;
        if let (ToneCurve::Pq { mastering_peak }, Some(m)) = (&mut tone, self.mastering_peak) {
            *mastering_peak = Some(m);
        }
        Ok(Target {
            white: parse_white(&self.white)?,
            tone,
            luminance: self.luminance.or(self.peak),
        })
    }

    pub fn check(&self) -> Result<(), String> {
        let target = self.target().map_err(|e| format!("target: {e}"))?;
        if self.peak.is_some() && self.luminance.is_some() {
            return Err("target: give peak or luminance, not both (they are the same)".into());
        }
        if self.peak.is_some_and(|l| !(l > 0.0 && l.is_finite())) {
            return Err("target.peak must be a positive number".into());
        }
        if let Some(m) = self.mastering_peak {
            if !matches!(target.tone, ToneCurve::Pq { .. }) {
                return Err(format!(
                    "target.mastering_peak is for tone = \"pq\", not \"{}\"",
                    self.tone
                ));
            }
            if !(100.0..=10_000.0).contains(&m) {
                return Err(format!(
                    "target.mastering_peak must be 100 to 10000 cd/m², not {m}"
                ));
            }
        }
        if !(3..=33).contains(&self.levels) {
            return Err("target.levels must be 3 to 33".into());
        }
        if self.refine_passes > 5 {
            return Err("target.refine_passes must be at most 5".into());
        }
        if self.luminance.is_some_and(|l| !(l > 0.0 && l.is_finite())) {
            return Err("target.luminance must be a positive number".into());
        }
        if self.bit_depth.is_some_and(|d| !(8..=16).contains(&d)) {
            return Err("target.bit_depth must be 8 to 16".into());
        }
        Ok(())
    }
}
