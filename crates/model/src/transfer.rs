//! Transfer laws: how a channel's drive v ∈ [0, 1] becomes its excitation E, the
//! fraction of the full-drive output above black. Every law here has its inverse,
//! `drive(e)`, and every published law is monotone on [0, 1] so that inverse exists.
//!
//! | law | form | source |
//! |---|---|---|
//! | [`Power`] | E = v^γ | the usual one |
//! | [`Cowan`] | ln E = A ln v + B ln²v | Cowan 1983 |
//! | [`ThreeTerm`] | ln E = A ln v + B ln²v + C | Rougeron & Péroche 1998, §4.3.1 |
//! | [`GainOffsetGamma`] | E = (a·v + (1 − a))^γ, 0 below the cut-off | Berns 1996 |
//! | [`Table`] | monotone cubic through the measured ramp | Fritsch & Carlson 1980 |
//! | [`Pq`] | E = (L(v) / peak)^a, or ln E = a ln x + b ln²x of x = L(v) / peak | SMPTE ST 2084, BT.2390; Cowan 1983 for b |
//! | [`Hlg`] | E = E_s(v)^p of BT.2100's scene light, or ln E = p ln E_s + b ln²E_s | ITU-R BT.2100; Cowan 1983 for b |
//!
//! The log laws are undefined at v = 0 and, with B > 0, turn back near it: ln²v grows
//! faster than ln v falls, so E rises again as v → 0. They therefore carry a *toe*, the
//! smallest drive they were fitted on; below it E runs linearly to 0. A fitted curve
//! whose turning point lies between the toe and full drive is not monotone where it is
//! used; [`TransferLaw::monotonicity`] finds it and the fitting refuses to publish it.

use chromacal_color::hdr::{bt2390_eetf, hlg_inverse_oetf, hlg_oetf, hlg_scene_light};
use chromacal_color::ictcp::{PQ_PEAK, pq_eotf, pq_inverse_eotf};
use serde::{Deserialize, Serialize};

/// Why a law cannot be used as a monotone map from drive to excitation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TransferError {
    #[error("{law} turns back at drive {at:.4}: its inverse would not be unique")]
    TurnsBack { law: &'static str, at: f64 },
    #[error("{law} has an invalid parameter: {what}")]
    InvalidParameter { law: &'static str, what: String },
}

/// E = v^γ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Power {
    pub gamma: f64,
}

impl Power {
    pub fn excitation(&self, v: f64) -> f64 {
        let v = v.clamp(0.0, 1.0);
        if v == 0.0 { 0.0 } else { v.powf(self.gamma) }
    }

    pub fn drive(&self, e: f64) -> f64 {
        e.clamp(0.0, 1.0).powf(1.0 / self.gamma)
    }
}

/// ln E = A ln v + B ln²v + C for v ≥ toe, linear from 0 to the toe: the common core
/// of [`Cowan`] (C = 0) and [`ThreeTerm`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct LogQuadratic {
    a: f64,
    b: f64,
    c: f64,
    toe: f64,
}

impl LogQuadratic {
    fn formula(&self, v: f64) -> f64 {
        let u = v.ln();
        (self.a * u + self.b * u * u + self.c).exp()
    }

    fn excitation(&self, v: f64) -> f64 {
        let v = v.clamp(0.0, 1.0);
        if v <= 0.0 {
            0.0
        } else if v < self.toe {
            self.formula(self.toe) * v / self.toe
        } else {
            self.formula(v)
        }
    }

    fn drive(&self, e: f64) -> f64 {
        let top = self.formula(1.0);
        if e <= 0.0 {
            return 0.0;
        }
        if e >= top {
            return 1.0;
        }
        let at_toe = self.formula(self.toe);
        if e < at_toe {
            return self.toe * e / at_toe;
        }
        // Solve B u² + A u − (ln e − C) = 0 for u = ln v on the rising branch, in the
        // form that stays exact as B → 0: u = 2L / (A + √(A² + 4BL)).
        let l = e.ln() - self.c;
        let discriminant = self.a * self.a + 4.0 * self.b * l;
        if discriminant < 0.0 {
            return self.toe;
        }
        let u = 2.0 * l / (self.a + discriminant.sqrt());
        u.exp().clamp(self.toe, 1.0)
    }

    /// The drive in (toe, 1) where d ln E / d ln v = A + 2B ln v changes sign, if any.
    fn turning_point(&self) -> Option<f64> {
        if self.b == 0.0 {
            return (self.a <= 0.0).then_some(1.0);
        }
        let v = (-self.a / (2.0 * self.b)).exp();
        let slope_at_top = self.a;
        let slope_at_toe = self.a + 2.0 * self.b * self.toe.ln();
        if slope_at_top <= 0.0 || slope_at_toe <= 0.0 {
            Some(v.clamp(self.toe, 1.0))
        } else {
            None
        }
    }
}

/// Cowan's law, ln E = A ln v + B ln²v (Cowan 1983, as given in Rougeron & Péroche,
/// §4.3.1), linear below `toe`. It passes through E(1) = 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cowan {
    pub a: f64,
    pub b: f64,
    /// Smallest drive the law was fitted on; E is linear in v below it.
    pub toe: f64,
}

impl Cowan {
    fn core(&self) -> LogQuadratic {
        LogQuadratic {
            a: self.a,
            b: self.b,
            c: 0.0,
            toe: self.toe,
        }
    }

    pub fn excitation(&self, v: f64) -> f64 {
        self.core().excitation(v)
    }

    pub fn drive(&self, e: f64) -> f64 {
        self.core().drive(e)
    }
}

/// The three-term law, ln E = A ln v + B ln²v + C (Rougeron & Péroche, §4.3.1): Cowan's
/// law that is not forced through the full-drive reading, E(1) = e^C.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThreeTerm {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub toe: f64,
}

impl ThreeTerm {
    fn core(&self) -> LogQuadratic {
        LogQuadratic {
            a: self.a,
            b: self.b,
            c: self.c,
            toe: self.toe,
        }
    }

    pub fn excitation(&self, v: f64) -> f64 {
        self.core().excitation(v)
    }

    pub fn drive(&self, e: f64) -> f64 {
        self.core().drive(e)
    }
}

/// Gain-offset-gamma, E = (a·v + (1 − a))^γ where that base is positive, else 0
/// (Berns 1996, the GOG model of CRTs). With the black taken off, the offset 1 − a is
/// not positive (a ≥ 1), so light starts at the cut-off v₀ = (a − 1)/a.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainOffsetGamma {
    pub gain: f64,
    pub gamma: f64,
}

impl GainOffsetGamma {
    /// The law whose light starts at drive `cutoff` (0 ≤ cutoff < 1).
    pub fn from_cutoff(cutoff: f64, gamma: f64) -> Self {
        GainOffsetGamma {
            gain: 1.0 / (1.0 - cutoff),
            gamma,
        }
    }

    /// v₀ = (a − 1)/a, the drive below which the channel emits nothing.
    pub fn cutoff(&self) -> f64 {
        (self.gain - 1.0) / self.gain
    }

    pub fn excitation(&self, v: f64) -> f64 {
        let base = self.gain * v.clamp(0.0, 1.0) + (1.0 - self.gain);
        if base <= 0.0 {
            0.0
        } else {
            base.powf(self.gamma)
        }
    }

    pub fn drive(&self, e: f64) -> f64 {
        if e <= 0.0 {
            return 0.0;
        }
        let base = e.min(1.0).powf(1.0 / self.gamma);
        ((base - (1.0 - self.gain)) / self.gain).clamp(0.0, 1.0)
    }
}

/// E of a relative light x ∈ [0, 1] for the HDR laws: x^a, or, with a curvature
/// b ≠ 0, Cowan's log-quadratic ln E = a ln x + b ln²x (Cowan 1983) above `toe` and
/// the power of x with the slope it has there below it, so that it never turns back.
#[derive(Debug, Clone, Copy)]
struct CurvedPower {
    exponent: f64,
    curvature: f64,
    toe: f64,
}

impl CurvedPower {
    /// ln E at ln x (b ≠ 0): log-quadratic above the toe, log-linear below it.
    fn log_excitation(&self, ln_x: f64) -> f64 {
        let (a, b, ln_toe) = (self.exponent, self.curvature, self.toe.ln());
        if ln_x >= ln_toe {
            (a + b * ln_x) * ln_x
        } else {
            (a + b * ln_toe) * ln_toe + (a + 2.0 * b * ln_toe) * (ln_x - ln_toe)
        }
    }

    /// E at the relative light x.
    fn of(&self, x: f64) -> f64 {
        if self.curvature == 0.0 {
            x.powf(self.exponent)
        } else if x > 0.0 {
            self.log_excitation(x.ln()).exp()
        } else {
            0.0
        }
    }

    /// The relative light x of excitation `e` in (0, 1): the root of b L² + a L = ln e
    /// that goes to ln e / a as b does, 2 ln e / (a + √(a² + 4 b ln e)), above the toe
    /// (where a² + 4 b ln e is the slope's square, (a + 2 b ln x)², so never negative).
    fn inverse(&self, e: f64) -> f64 {
        let (a, b) = (self.exponent, self.curvature);
        if b == 0.0 {
            return e.powf(1.0 / a);
        }
        let (ln_e, ln_toe) = (e.ln(), self.toe.ln());
        let at_toe = (a + b * ln_toe) * ln_toe;
        let ln_x = if ln_e < at_toe {
            ln_toe + (ln_e - at_toe) / (a + 2.0 * b * ln_toe)
        } else {
            2.0 * ln_e / (a + (a * a + 4.0 * b * ln_e).max(0.0).sqrt())
        };
        ln_x.exp()
    }

    /// `Ok` for a plain curve, or a curved one whose toe lies in (0, 1) with a
    /// positive slope there, a + 2 b ln toe (the slope a + 2 b ln x is then positive
    /// from the toe to x = 1, where it is a).
    fn check(&self, law: &'static str) -> Result<(), TransferError> {
        if self.curvature == 0.0
            || (self.curvature.is_finite()
                && self.toe > 0.0
                && self.toe < 1.0
                && self.exponent + 2.0 * self.curvature * self.toe.ln() > 0.0)
        {
            return Ok(());
        }
        Err(TransferError::InvalidParameter {
            law,
            what: "toe must lie in (0, 1) and the slope there, exponent + 2 curvature ln toe, be positive".into(),
        })
    }
}

/// A display in its HDR mode decoding a PQ signal (SMPTE ST 2084): the channel's
/// light is the PQ's absolute luminance L(v), clipped at the display's `peak` or
/// rolled off to it from `rolloff_from` by BT.2390's EETF, and E = (L(v) / peak)^a,
/// a = 1 when the display tracks the PQ exactly (the panel's departure from the gamma
/// its processing assumes shows as a ≠ 1). Light is absolute here: E reaches 1 at
/// the signal of `rolloff_from` (or of `peak`, clipping) and stays there.
///
/// With a `curvature` b ≠ 0 (the `pq-cowan` candidate), ln E = a ln x + b ln²x of
/// the relative light x = L(v) / peak: Cowan's log-quadratic law (Cowan 1983) on the
/// light the display decoded rather than on the code. A display re-encodes that light
/// for its panel through the gamma it assumes; a panel whose own law bends away from
/// that gamma (an LCD's Cowan curve, whose local exponent falls toward black) makes
/// the tracking exponent drift with x, which PQ's four decades of light below the
/// peak turn into 10 % and more near black. Below `toe` (the least relative light the
/// law was fitted on) it goes on as a power of x with the slope it has there, so it
/// never turns back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pq {
    /// cd/m² at full excitation.
    pub peak: f64,
    /// cd/m² of the master the roll-off starts from (equal to `peak`: a clip).
    pub rolloff_from: f64,
    /// a: the tracking exponent.
    pub exponent: f64,
    /// b: the log-quadratic term (0: the plain PQ law).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub curvature: f64,
    /// The relative light below which the curved law is a power of x (with b ≠ 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub toe: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Pq {
    /// L(v) / peak in [0, 1].
    fn relative_light(&self, v: f64) -> f64 {
        let light = if self.rolloff_from > self.peak {
            bt2390_eetf(v.clamp(0.0, 1.0), self.rolloff_from, self.peak, 0.0)
        } else {
            pq_eotf(v).min(self.peak)
        };
        (light / self.peak).clamp(0.0, 1.0)
    }

    /// The exponent, curvature and toe as one log-quadratic curve.
    fn curve(&self) -> CurvedPower {
        CurvedPower {
            exponent: self.exponent,
            curvature: self.curvature,
            toe: self.toe,
        }
    }

    pub fn excitation(&self, v: f64) -> f64 {
        self.curve().of(self.relative_light(v))
    }

    /// The smallest drive of excitation `e`: the PQ's inverse below the roll-off's knee,
    /// bisection on the EETF above it.
    pub fn drive(&self, e: f64) -> f64 {
        if e <= 0.0 {
            return 0.0;
        }
        let top = pq_inverse_eotf(self.rolloff_from.max(self.peak));
        if e >= 1.0 {
            return top;
        }
        let want = self.curve().inverse(e);
        let exact = pq_inverse_eotf(want * self.peak);
        if self.rolloff_from <= self.peak || (self.relative_light(exact) - want).abs() < 1e-12 {
            return exact;
        }
        let (mut lo, mut hi) = (0.0, top);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.relative_light(mid) < want {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }
}

/// One channel of a display decoding HLG (BT.2100 Table 5), shown alone: the inverse
/// OETF's scene light E(v), 1 at full signal, to a power p, E(v)^p. Alone, channel c
/// shows (w_c E)^(γ_S − 1) E through the OOTF, which is E^γ_S of its full light: p is
/// the system gamma γ_S where the panel tracks the gamma its processing inverts, and
/// departs from it where the panel does. What the channel gives beside the others is
/// the OOTF's (`AdditivityTerms::hlg_ootf`).
///
/// With a `curvature` b ≠ 0 (the `hlg-cowan` candidate), ln E = p ln E_s + b ln²E_s:
/// Cowan's log-quadratic law on the scene light, as `pq-cowan` is on PQ's light, for a
/// panel whose own law bends away from the gamma the processing inverts. Alone, the
/// channel's light is a power of E_s (the OOTF's γ_S), so a Cowan panel (A, B) behind
/// a gamma g gives b = B γ_S² / g² exactly. Below `toe` (the least scene light fitted)
/// it is a power of E_s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hlg {
    /// p.
    pub exponent: f64,
    /// b: the log-quadratic term (0: the plain HLG law).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub curvature: f64,
    /// The scene light below which the curved law is a power of it (with b ≠ 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub toe: f64,
}

impl Hlg {
    /// The exponent, curvature and toe as one log-quadratic curve.
    fn curve(&self) -> CurvedPower {
        CurvedPower {
            exponent: self.exponent,
            curvature: self.curvature,
            toe: self.toe,
        }
    }

    pub fn excitation(&self, v: f64) -> f64 {
        self.of_scene_light(hlg_scene_light(v.clamp(0.0, 1.0)))
    }

    /// E at scene light `scene` (1 at full signal), beyond full signal too: the light
    /// a channel gives where the OOTF drives it harder than its full signal alone
    /// (`AdditivityTerms::hlg_ootf_through_laws`). Beyond it the formula goes on (a
    /// Cowan panel's light rises ever faster, b > 0); with b < 0 it would turn back at
    /// e^(−p / 2b), so from where its log-log slope has fallen to p / 2,
    /// e^(−p / 4b), it goes on as the power of that slope instead.
    pub fn of_scene_light(&self, scene: f64) -> f64 {
        match self.beyond_knee() {
            Some(knee) if scene > knee => {
                self.curve().of(knee) * (scene / knee).powf(0.5 * self.exponent)
            }
            _ => self.curve().of(scene),
        }
    }

    /// The scene light of excitation `e`, above 1 too: the inverse of
    /// [`Self::of_scene_light`].
    pub fn scene_light_of(&self, e: f64) -> f64 {
        match self.beyond_knee() {
            Some(knee) if e > self.curve().of(knee) => {
                knee * (e / self.curve().of(knee)).powf(2.0 / self.exponent)
            }
            _ => self.curve().inverse(e),
        }
    }

    /// Where a curvature below 0 has halved the law's log-log slope, e^(−p / 4b) > 1.
    fn beyond_knee(&self) -> Option<f64> {
        (self.curvature < 0.0).then(|| (-self.exponent / (4.0 * self.curvature)).exp())
    }

    /// The drive of excitation `e`: the OETF of e^(1/p).
    pub fn drive(&self, e: f64) -> f64 {
        if e <= 0.0 {
            return 0.0;
        }
        // Full signal exactly (the OETF of its own inverse at 1 misses it by 10⁻⁸).
        if e >= 1.0 {
            return 1.0;
        }
        let scene = self.curve().inverse(e) * hlg_inverse_oetf(1.0);
        hlg_oetf(scene).clamp(0.0, 1.0)
    }
}

/// Monotone piecewise-cubic interpolation of a measured ramp (Fritsch & Carlson 1980,
/// with the end conditions of Fritsch & Butland 1984 as in SciPy's PCHIP). The knots
/// start at (0, 0) and their excitations never decrease, so the curve never does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "TableKnots")]
pub struct Table {
    pub drive: Vec<f64>,
    pub excitation: Vec<f64>,
    /// Slopes at the knots, derived from the knots when the table is built.
    #[serde(skip_serializing)]
    slopes: Vec<f64>,
}

/// A table as written in a profile: the knots only; reading one checks it again.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TableKnots {
    drive: Vec<f64>,
    excitation: Vec<f64>,
}

impl TryFrom<TableKnots> for Table {
    type Error = TransferError;

    fn try_from(knots: TableKnots) -> Result<Self, Self::Error> {
        Table::new(knots.drive, knots.excitation)
    }
}

impl Table {
    /// A table law through `(drive, excitation)` knots. The knots must have increasing
    /// drives in [0, 1] and non-decreasing excitations; a knot at (0, 0) is added when
    /// missing.
    pub fn new(drive: Vec<f64>, excitation: Vec<f64>) -> Result<Self, TransferError> {
        let invalid = |what: String| TransferError::InvalidParameter { law: "table", what };
        if drive.len() != excitation.len() || drive.is_empty() {
            return Err(invalid(format!(
                "{} drives but {} excitations",
                drive.len(),
                excitation.len()
            )));
        }
        let (mut drive, mut excitation) = (drive, excitation);
        if drive[0] > 0.0 {
            drive.insert(0, 0.0);
            excitation.insert(0, 0.0);
        }
        for (i, pair) in drive.windows(2).enumerate() {
            if pair[1] <= pair[0] {
                return Err(invalid(format!("drive {} does not increase", i + 1)));
            }
        }
        for (i, pair) in excitation.windows(2).enumerate() {
            if pair[1] < pair[0] {
                return Err(TransferError::TurnsBack {
                    law: "table",
                    at: drive[i + 1],
                });
            }
        }
        if drive.iter().chain(&excitation).any(|v| !v.is_finite()) {
            return Err(invalid("a knot is not finite".into()));
        }
        let slopes = pchip_slopes(&drive, &excitation);
        Ok(Table {
            drive,
            excitation,
            slopes,
        })
    }

    fn segment(&self, v: f64) -> usize {
        let upper = self.drive.partition_point(|d| *d <= v);
        upper.clamp(1, self.drive.len() - 1) - 1
    }

    fn hermite(&self, k: usize, v: f64) -> f64 {
        let (x0, x1) = (self.drive[k], self.drive[k + 1]);
        let (y0, y1) = (self.excitation[k], self.excitation[k + 1]);
        let h = x1 - x0;
        let t = (v - x0) / h;
        let (m0, m1) = (self.slopes[k], self.slopes[k + 1]);
        let t2 = t * t;
        let t3 = t2 * t;
        (2.0 * t3 - 3.0 * t2 + 1.0) * y0
            + (t3 - 2.0 * t2 + t) * h * m0
            + (-2.0 * t3 + 3.0 * t2) * y1
            + (t3 - t2) * h * m1
    }

    pub fn excitation(&self, v: f64) -> f64 {
        if self.drive.len() == 1 {
            return self.excitation[0];
        }
        let v = v.clamp(0.0, *self.drive.last().unwrap_or(&1.0));
        self.hermite(self.segment(v), v)
    }

    /// The smallest drive whose excitation reaches `e`, by bisection inside the
    /// segment that brackets it (each segment is monotone).
    pub fn drive(&self, e: f64) -> f64 {
        let n = self.excitation.len();
        if n == 1 || e <= self.excitation[0] {
            return self.drive[0];
        }
        if e >= self.excitation[n - 1] {
            return self.drive[n - 1];
        }
        let k = self.excitation.partition_point(|x| *x < e).clamp(1, n - 1) - 1;
        let (mut lo, mut hi) = (self.drive[k], self.drive[k + 1]);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.hermite(k, mid) < e {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// Knot slopes of the monotone cubic (Fritsch & Carlson 1980; end slopes by the
/// shape-preserving three-point formula of Fritsch & Butland 1984).
fn pchip_slopes(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let h: Vec<f64> = x.windows(2).map(|p| p[1] - p[0]).collect();
    let delta: Vec<f64> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
    if n == 2 {
        return vec![delta[0]; 2];
    }
    let mut m = vec![0.0; n];
    for k in 1..n - 1 {
        if delta[k - 1] * delta[k] > 0.0 {
            let w1 = 2.0 * h[k] + h[k - 1];
            let w2 = h[k] + 2.0 * h[k - 1];
            m[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k]);
        }
    }
    let end = |h0: f64, h1: f64, d0: f64, d1: f64| -> f64 {
        let s = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
        if s.signum() != d0.signum() || d0 == 0.0 {
            0.0
        } else if d0.signum() != d1.signum() && s.abs() > 3.0 * d0.abs() {
            3.0 * d0
        } else {
            s
        }
    };
    m[0] = end(h[0], h[1], delta[0], delta[1]);
    m[n - 1] = end(h[n - 2], h[n - 3], delta[n - 2], delta[n - 3]);
    m
}

/// The kinds of law chromacal can fit, in order of increasing complexity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LawKind {
    Power,
    GainOffsetGamma,
    Cowan,
    ThreeTerm,
    Table,
    /// Tried only for a display sent PQ signals (not in `ALL`).
    Pq,
    /// The PQ law with Cowan's log-quadratic term (`Pq::curvature`); tried only when
    /// `[fit] laws` names it (not in `ALL`, not added for PQ signals).
    PqCowan,
    /// Tried only for a display sent HLG signals (not in `ALL`).
    Hlg,
    /// The HLG law with Cowan's log-quadratic term (`Hlg::curvature`); tried only when
    /// `[fit] laws` names it (not in `ALL`, not added for HLG signals).
    HlgCowan,
}

impl LawKind {
    pub const ALL: [LawKind; 5] = [
        LawKind::Power,
        LawKind::GainOffsetGamma,
        LawKind::Cowan,
        LawKind::ThreeTerm,
        LawKind::Table,
    ];

    pub fn name(self) -> &'static str {
        match self {
            LawKind::Power => "power",
            LawKind::GainOffsetGamma => "gain-offset-gamma",
            LawKind::Cowan => "cowan",
            LawKind::ThreeTerm => "three-term",
            LawKind::Table => "table",
            LawKind::Pq => "pq",
            LawKind::PqCowan => "pq-cowan",
            LawKind::Hlg => "hlg",
            LawKind::HlgCowan => "hlg-cowan",
        }
    }

    /// Number of free parameters for a channel with `levels` measured drive levels
    /// above zero: what "simplest" means when laws are compared.
    pub fn parameter_count(self, levels: usize) -> usize {
        match self {
            LawKind::Power | LawKind::Hlg => 1,
            LawKind::GainOffsetGamma | LawKind::Cowan | LawKind::Pq | LawKind::HlgCowan => 2,
            LawKind::ThreeTerm | LawKind::PqCowan => 3,
            LawKind::Table => levels,
        }
    }
}

impl std::fmt::Display for LawKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One channel's transfer law.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "law", rename_all = "kebab-case")]
pub enum TransferLaw {
    Power(Power),
    Cowan(Cowan),
    ThreeTerm(ThreeTerm),
    GainOffsetGamma(GainOffsetGamma),
    Table(Table),
    Pq(Pq),
    Hlg(Hlg),
}

impl TransferLaw {
    pub fn kind(&self) -> LawKind {
        match self {
            TransferLaw::Power(_) => LawKind::Power,
            TransferLaw::Cowan(_) => LawKind::Cowan,
            TransferLaw::ThreeTerm(_) => LawKind::ThreeTerm,
            TransferLaw::GainOffsetGamma(_) => LawKind::GainOffsetGamma,
            TransferLaw::Table(_) => LawKind::Table,
            TransferLaw::Pq(l) if l.curvature != 0.0 => LawKind::PqCowan,
            TransferLaw::Pq(_) => LawKind::Pq,
            TransferLaw::Hlg(l) if l.curvature != 0.0 => LawKind::HlgCowan,
            TransferLaw::Hlg(_) => LawKind::Hlg,
        }
    }

    /// Excitation at drive `v` (clamped to [0, 1]).
    pub fn excitation(&self, v: f64) -> f64 {
        match self {
            TransferLaw::Power(l) => l.excitation(v),
            TransferLaw::Cowan(l) => l.excitation(v),
            TransferLaw::ThreeTerm(l) => l.excitation(v),
            TransferLaw::GainOffsetGamma(l) => l.excitation(v),
            TransferLaw::Table(l) => l.excitation(v),
            TransferLaw::Pq(l) => l.excitation(v),
            TransferLaw::Hlg(l) => l.excitation(v),
        }
    }

    /// The drive that gives excitation `e`: the inverse of [`Self::excitation`],
    /// clamped to [0, 1].
    pub fn drive(&self, e: f64) -> f64 {
        match self {
            TransferLaw::Power(l) => l.drive(e),
            TransferLaw::Cowan(l) => l.drive(e),
            TransferLaw::ThreeTerm(l) => l.drive(e),
            TransferLaw::GainOffsetGamma(l) => l.drive(e),
            TransferLaw::Table(l) => l.drive(e),
            TransferLaw::Pq(l) => l.drive(e),
            TransferLaw::Hlg(l) => l.drive(e),
        }
    }

    /// Excitation at full drive: 1 for every law but the three-term one.
    pub fn full_drive_excitation(&self) -> f64 {
        self.excitation(1.0)
    }

    /// The parameters by name, for reports.
    pub fn parameters(&self) -> Vec<(&'static str, f64)> {
        match self {
            TransferLaw::Power(l) => vec![("gamma", l.gamma)],
            TransferLaw::Cowan(l) => vec![("A", l.a), ("B", l.b), ("toe", l.toe)],
            TransferLaw::ThreeTerm(l) => vec![("A", l.a), ("B", l.b), ("C", l.c), ("toe", l.toe)],
            TransferLaw::GainOffsetGamma(l) => {
                vec![("gain", l.gain), ("gamma", l.gamma), ("cutoff", l.cutoff())]
            }
            TransferLaw::Table(l) => vec![("knots", l.drive.len() as f64)],
            TransferLaw::Pq(l) if l.curvature != 0.0 => vec![
                ("peak", l.peak),
                ("rolloff_from", l.rolloff_from),
                ("exponent", l.exponent),
                ("curvature", l.curvature),
                ("toe", l.toe),
            ],
            TransferLaw::Pq(l) => vec![
                ("peak", l.peak),
                ("rolloff_from", l.rolloff_from),
                ("exponent", l.exponent),
            ],
            TransferLaw::Hlg(l) if l.curvature != 0.0 => vec![
                ("exponent", l.exponent),
                ("curvature", l.curvature),
                ("toe", l.toe),
            ],
            TransferLaw::Hlg(l) => vec![("exponent", l.exponent)],
        }
    }

    /// `Ok` when the law is a strictly usable monotone map on [0, 1]; otherwise where
    /// and why it is not.
    pub fn monotonicity(&self) -> Result<(), TransferError> {
        let invalid = |law: &'static str, what: &str| {
            Err(TransferError::InvalidParameter {
                law,
                what: what.to_string(),
            })
        };
        match self {
            TransferLaw::Power(l) if !(l.gamma > 0.0 && l.gamma.is_finite()) => {
                invalid("power", "gamma must be positive")
            }
            TransferLaw::GainOffsetGamma(l) if !(l.gamma > 0.0 && l.gamma.is_finite()) => {
                invalid("gain-offset-gamma", "gamma must be positive")
            }
            TransferLaw::GainOffsetGamma(l) if !(l.gain >= 1.0 && l.gain.is_finite()) => {
                invalid("gain-offset-gamma", "gain must be at least 1")
            }
            TransferLaw::Cowan(l) => log_law_monotonicity("cowan", l.core()),
            TransferLaw::ThreeTerm(l) => log_law_monotonicity("three-term", l.core()),
            TransferLaw::Table(l) => Table::new(l.drive.clone(), l.excitation.clone()).map(|_| ()),
            TransferLaw::Pq(l)
                if !(l.peak > 0.0
                    && l.peak <= PQ_PEAK
                    && l.rolloff_from >= l.peak
                    && l.rolloff_from <= PQ_PEAK
                    && l.exponent > 0.0
                    && l.exponent.is_finite()) =>
            {
                invalid(
                    "pq",
                    "peak must be in (0, 10000], rolloff_from from the peak to 10000, exponent positive",
                )
            }
            TransferLaw::Pq(l) => l.curve().check("pq-cowan"),
            TransferLaw::Hlg(l) if !(l.exponent > 0.0 && l.exponent.is_finite()) => {
                invalid("hlg", "exponent must be positive")
            }
            TransferLaw::Hlg(l) => l.curve().check("hlg-cowan"),
            _ => Ok(()),
        }
    }
}

fn log_law_monotonicity(law: &'static str, core: LogQuadratic) -> Result<(), TransferError> {
    if !(core.toe > 0.0 && core.toe < 1.0) {
        return Err(TransferError::InvalidParameter {
            law,
            what: format!("toe {} must lie in (0, 1)", core.toe),
        });
    }
    if [core.a, core.b, core.c].iter().any(|p| !p.is_finite()) {
        return Err(TransferError::InvalidParameter {
            law,
            what: "a parameter is not finite".into(),
        });
    }
    match core.turning_point() {
        Some(at) => Err(TransferError::TurnsBack { law, at }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn laws() -> Vec<TransferLaw> {
        vec![
            TransferLaw::Power(Power { gamma: 2.2 }),
            TransferLaw::Cowan(Cowan {
                a: 2.3,
                b: -0.05,
                toe: 1.0 / 255.0,
            }),
            TransferLaw::ThreeTerm(ThreeTerm {
                a: 2.1,
                b: -0.02,
                c: -0.01,
                toe: 1.0 / 255.0,
            }),
            TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.06, 2.4)),
            TransferLaw::Table(
                Table::new(
                    vec![0.0, 0.2, 0.5, 0.8, 1.0],
                    vec![0.0, 0.03, 0.2, 0.6, 1.0],
                )
                .unwrap(),
            ),
            TransferLaw::Pq(Pq {
                peak: 700.0,
                rolloff_from: 700.0,
                exponent: 1.03,
                curvature: 0.0,
                toe: 0.0,
            }),
            TransferLaw::Pq(Pq {
                peak: 700.0,
                rolloff_from: 4000.0,
                exponent: 0.97,
                curvature: 0.0,
                toe: 0.0,
            }),
            // The hdr-lcd's red panel (Cowan A 2.25, B 0.03 behind a 2.2 re-encoding)
            // in x: A / 2.2 and B / 2.2².
            TransferLaw::Pq(Pq {
                peak: 1000.0,
                rolloff_from: 4000.0,
                exponent: 1.0227,
                curvature: 0.0062,
                toe: 1e-4,
            }),
        ]
    }

    /// The curved HLG law is what a display shows, channel alone, that decodes HLG
    /// (OOTF gain (w E_s)^(γ − 1)), re-encodes the light with a gamma g and drives a
    /// Cowan panel: p = (γ / g)(A + 2 B k), b = B (γ / g)² with k = ln(w^(γ − 1)) / g,
    /// within 10⁻⁹; the plain law misses its dark end by more than 10 %.
    #[test]
    fn the_curved_hlg_law_is_a_cowan_panel_behind_the_hlg_decoding() {
        // Alone, a channel's light through the OOTF is (w E_s)^(γ − 1) E_s of the
        // peak; the display re-encodes it with gamma g for a Cowan panel (A, B).
        let (big_a, big_b, g, gamma, w) = (2.25, 0.03, 2.2, 1.2, 0.2627);
        let panel = Cowan {
            a: big_a,
            b: big_b,
            toe: 1e-9,
        };
        let shown = |scene: f64| {
            let light = (w * scene).powf(gamma - 1.0) * scene;
            panel.excitation(light.powf(1.0 / g))
        };
        let k = (w.powf(gamma - 1.0)).ln() / g;
        let curved = Hlg {
            exponent: gamma / g * (big_a + 2.0 * big_b * k),
            curvature: big_b * (gamma / g).powi(2),
            toe: 1e-4,
        };
        let mut worst: f64 = 0.0;
        for code in (40..=1000).step_by(20) {
            let v = code as f64 / 1023.0;
            let want = shown(hlg_scene_light(v)) / shown(1.0);
            worst = worst.max((curved.excitation(v) / want - 1.0).abs());
        }
        assert!(worst < 1e-9, "{worst}");
        // The plain law with the same exponent misses the dark end by more than 10 %.
        let plain = Hlg {
            curvature: 0.0,
            toe: 0.0,
            ..curved.clone()
        };
        let dark = 100.0 / 1023.0;
        assert!(curved.excitation(dark) / plain.excitation(dark) > 1.1);
        assert_eq!(TransferLaw::Hlg(curved.clone()).kind(), LawKind::HlgCowan);
        let turning = Hlg {
            curvature: 0.2,
            toe: 1e-4,
            ..curved.clone()
        };
        assert_curved_law_holds(
            TransferLaw::Hlg(curved),
            TransferLaw::Hlg(turning),
            TransferLaw::Hlg(plain),
        );
    }

    /// What every curved HDR law must do: invert at every 10-bit code (below its toe
    /// too) and be monotone, while the same law curved so that its slope at the toe is
    /// not positive is refused; its plain form is its own kind and is written as before,
    /// without a curvature or a toe.
    fn assert_curved_law_holds(curved: TransferLaw, turning: TransferLaw, plain: TransferLaw) {
        for code in 1..=1023 {
            let v = code as f64 / 1023.0;
            let e = curved.excitation(v);
            if e > 0.0 && e < 1.0 {
                let back = curved.drive(e);
                assert!((back - v).abs() < 1e-9, "code {code}: {back} for {v}");
            }
        }
        assert!(curved.monotonicity().is_ok());
        assert!(turning.monotonicity().is_err());
        assert_ne!(curved.kind(), plain.kind());
        let written = toml::to_string(&plain).unwrap();
        assert!(
            !written.contains("curvature") && !written.contains("toe"),
            "{written}"
        );
    }

    /// The curved PQ law is what a display shows that decodes PQ, re-encodes the light
    /// for its panel with a gamma g and drives a panel of Cowan's law (A, B in the
    /// panel's drive): Cowan's law of x^(1/g) is a = A / g, b = B / g² in x. Below the
    /// toe it goes on as a power of x, continuous in value and slope, and it inverts
    /// everywhere; a curvature that would turn it back is refused.
    #[test]
    fn the_curved_pq_law_is_a_cowan_panel_behind_the_pq_decoding() {
        let (big_a, big_b, g) = (2.25, 0.03, 2.2);
        let panel = TransferLaw::Cowan(Cowan {
            a: big_a,
            b: big_b,
            toe: 1e-6,
        });
        let curved = Pq {
            peak: 1000.0,
            rolloff_from: 1000.0,
            exponent: big_a / g,
            curvature: big_b / (g * g),
            toe: 1e-5,
        };
        let mut worst: f64 = 0.0;
        for code in (40..=700).step_by(20) {
            let v = code as f64 / 1023.0;
            let x = pq_eotf(v) / 1000.0;
            let want = panel.excitation(x.powf(1.0 / g));
            worst = worst.max((curved.excitation(v) / want - 1.0).abs());
        }
        assert!(worst < 1e-9, "{worst}");
        // The plain law with the same exponent misses the dark end by more than 10 %.
        let plain = Pq {
            curvature: 0.0,
            toe: 0.0,
            ..curved.clone()
        };
        let dark = pq_inverse_eotf(0.1);
        assert!(curved.excitation(dark) / plain.excitation(dark) > 1.1);
        // Continuous in value and in log-log slope across the toe.
        let toe_code = pq_inverse_eotf(curved.toe * 1000.0);
        let (below, above) = (toe_code * (1.0 - 1e-7), toe_code * (1.0 + 1e-7));
        let ratio = curved.excitation(above) / curved.excitation(below);
        assert!((ratio - 1.0).abs() < 1e-5, "{ratio}");
        let slope = |v: f64| {
            let (v0, v1) = (v * (1.0 - 1e-4), v * (1.0 + 1e-4));
            (curved.excitation(v1) / curved.excitation(v0)).ln() / (pq_eotf(v1) / pq_eotf(v0)).ln()
        };
        let (s_below, s_above) = (slope(toe_code * 0.97), slope(toe_code * 1.03));
        assert!((s_below - s_above).abs() < 1e-3, "{s_below} {s_above}");
        let turning = Pq {
            curvature: 0.2,
            toe: 1e-4,
            ..curved.clone()
        };
        assert_eq!(TransferLaw::Pq(plain.clone()).kind(), LawKind::Pq);
        assert_curved_law_holds(
            TransferLaw::Pq(curved),
            TransferLaw::Pq(turning),
            TransferLaw::Pq(plain),
        );
    }

    #[test]
    fn the_pq_law_is_the_pq_below_its_peak_and_flat_above_it() {
        let clip = Pq {
            peak: 600.0,
            rolloff_from: 600.0,
            exponent: 1.0,
            curvature: 0.0,
            toe: 0.0,
        };
        // ST 2084: code 0.5081 is 100 cd/m², a sixth of this display's peak.
        assert!((clip.excitation(0.5081) - 100.0 / 600.0).abs() < 2e-4);
        let top = pq_inverse_eotf(600.0);
        assert!((clip.excitation(top) - 1.0).abs() < 1e-12);
        assert_eq!(clip.excitation(0.9), 1.0);
        assert!(
            (clip.drive(1.0) - top).abs() < 1e-12,
            "the smallest drive of full light"
        );
        let rolled = Pq {
            rolloff_from: 4000.0,
            ..clip
        };
        // The roll-off reaches the peak only at the master's peak, and bends the top
        // below the clip's.
        assert!(rolled.excitation(top) < 0.95);
        assert!((rolled.drive(1.0) - pq_inverse_eotf(4000.0)).abs() < 1e-12);
        let bad = TransferLaw::Pq(Pq {
            rolloff_from: 500.0,
            ..clip
        });
        assert!(bad.monotonicity().is_err());
    }

    #[test]
    fn every_law_inverts_and_is_monotone() {
        for law in laws() {
            law.monotonicity().unwrap();
            let mut previous = -1.0;
            for i in 0..=1000 {
                let v = i as f64 / 1000.0;
                let e = law.excitation(v);
                assert!(e >= previous, "{law:?} decreases at {v}");
                previous = e;
                if e > 1e-9 && e < law.full_drive_excitation() {
                    let back = law.drive(e);
                    assert!(
                        (law.excitation(back) - e).abs() < 1e-9,
                        "{:?}: v {v} → e {e} → v {back}",
                        law.kind()
                    );
                }
            }
            assert_eq!(law.excitation(0.0), 0.0);
            assert_eq!(law.drive(0.0), 0.0);
        }
    }

    #[test]
    fn log_laws_are_defined_at_zero_drive() {
        let cowan = Cowan {
            a: 2.0,
            b: 0.0,
            toe: 0.01,
        };
        assert_eq!(cowan.excitation(0.0), 0.0);
        assert!(cowan.excitation(0.005).is_finite());
        assert!((cowan.excitation(0.005) - 0.5 * cowan.excitation(0.01)).abs() < 1e-15);
    }

    #[test]
    fn a_cowan_law_that_turns_back_near_zero_is_caught() {
        // B > 0: d ln E / d ln v = A + 2B ln v is negative below v = exp(−A/2B) = 0.0183.
        let law = TransferLaw::Cowan(Cowan {
            a: 2.0,
            b: 0.25,
            toe: 1.0 / 255.0,
        });
        match law.monotonicity() {
            Err(TransferError::TurnsBack { at, .. }) => {
                assert!((at - (-4.0f64).exp()).abs() < 1e-12)
            }
            other => panic!("not caught: {other:?}"),
        }
        // The same curve is acceptable when it is only used above its turning point.
        let used_above = TransferLaw::Cowan(Cowan {
            a: 2.0,
            b: 0.25,
            toe: 0.05,
        });
        assert!(used_above.monotonicity().is_ok());
    }

    #[test]
    fn a_law_that_turns_down_below_full_drive_is_caught() {
        // B < 0 and A < 0: the slope A + 2B ln v is negative above v = exp(−A/2B) ≈ 0.95.
        let law = TransferLaw::ThreeTerm(ThreeTerm {
            a: -0.1,
            b: -1.0,
            c: 0.0,
            toe: 0.01,
        });
        assert!(matches!(
            law.monotonicity(),
            Err(TransferError::TurnsBack { .. })
        ));
    }

    #[test]
    fn gog_emits_nothing_below_its_cutoff() {
        let gog = GainOffsetGamma::from_cutoff(0.1, 2.5);
        assert!((gog.cutoff() - 0.1).abs() < 1e-12);
        assert_eq!(gog.excitation(0.05), 0.0);
        assert!((gog.excitation(1.0) - 1.0).abs() < 1e-12);
        assert!((gog.drive(0.0)).abs() < 1e-12);
    }

    #[test]
    fn table_refuses_a_decreasing_ramp_and_keeps_monotone_data_exact() {
        assert!(matches!(
            Table::new(vec![0.5, 1.0], vec![0.3, 0.2]),
            Err(TransferError::TurnsBack { .. })
        ));
        let t = Table::new(vec![0.25, 0.5, 1.0], vec![0.05, 0.2, 1.0]).unwrap();
        assert_eq!(t.drive[0], 0.0);
        for (d, e) in [(0.25, 0.05), (0.5, 0.2), (1.0, 1.0)] {
            assert!((t.excitation(d) - e).abs() < 1e-12);
        }
        // A flat stretch inverts to its lowest drive.
        let flat = Table::new(vec![0.3, 0.6, 1.0], vec![0.1, 0.1, 1.0]).unwrap();
        // (The cubic meets the flat stretch with zero slope, so the bisection settles
        // within √ε of the knot.)
        assert!((flat.drive(0.1) - 0.3).abs() < 1e-6);
    }

    #[test]
    fn laws_survive_a_toml_round_trip() {
        #[derive(Serialize, Deserialize)]
        struct Holder {
            laws: Vec<TransferLaw>,
        }
        let text = toml::to_string(&Holder { laws: laws() }).unwrap();
        let back: Holder = toml::from_str(&text).unwrap();
        for (a, b) in laws().iter().zip(back.laws) {
            for v in [0.0, 0.1, 0.37, 0.9, 1.0] {
                assert_eq!(a.excitation(v), b.excitation(v));
            }
        }
    }
}
