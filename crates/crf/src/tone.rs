//! Tone reproduction: scene luminance to the luminance a display can give (seed §4.2.4,
//! "Known solutions"). Each operator maps a luminance; the colour keeps its
//! chromaticity (XYZ scaled by L_d / L_s), so these are the grey-scale "tone
//! reproduction functions" the survey describes, applied to colour images.
//!
//! Luminances are in cd/m²: the scene's absolute, or relative ones given a white
//! luminance; the display's from its profile (black and white at the centre).

use serde::{Deserialize, Serialize};

use super::scene::Placement;

/// Which operator maps scene luminance to display luminance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ToneOperator {
    /// L_d = L_s: the display shows the scene's own luminance (colorimetric
    /// reproduction); what is brighter than the display's white is left to gamut
    /// mapping.
    Colorimetric,
    /// L_d = L_dmax · L_s / L_ref, L_ref the scene's white (or, without one, its
    /// largest luminance): the scene's white on the display's white.
    Linear,
    /// Ward's contrast-based scale factor (Ward 1994, "A contrast-based scalefactor for
    /// luminance display", Graphics Gems IV; seed §4.2.4): L_d = m L_s with
    /// m = [(1.219 + L_da^0.4) / (1.219 + L_sa^0.4)]^2.5, from Blackwell's threshold
    /// ΔL(L_a) = 0.054 (1.219 + L_a^0.4)^2.5, so that a just-noticeable difference in
    /// the scene is one on the display. L_da = L_dmax / 2 (Ward), L_sa the scene's
    /// adaptation luminance: the mean luminance over the area the observer looks at
    /// (seed §4.2.4: "the luminance average on that area"), `focus`, or over the
    /// whole scene when no area is given.
    Ward { focus: Option<Placement> },
    /// Tumblin and Rushmeier (1993), "Tone reproduction for realistic images", IEEE
    /// CG&A 13(6) (seed §4.2.4): equal Stevens brightness B = 10^β L^α for scene and
    /// display observer gives L_d = L_s^(α_s/α_d) · 10^((β_s − β_d)/α_d), with
    /// α(L_a) = 0.4 log₁₀ L_a + 2.92 and
    /// β(L_a) = −0.4 (log₁₀ L_a)² − 2.584 log₁₀ L_a + 2.0208; the scene's adaptation
    /// is log₁₀ L_sa = E(log₁₀ L_s) + 0.84 and the display's L_da = L_dmax / √C_max,
    /// C_max the display's usable contrast (35 in the survey; a parameter here).
    TumblinRushmeier { display_contrast: f64 },
}

/// The survey's typical usable contrast of a display for Tumblin–Rushmeier.
pub const TUMBLIN_RUSHMEIER_CONTRAST: f64 = 35.0;

/// What an operator needs to know of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneLuminance {
    /// Exp of the mean log luminance of the lit pixels (cd/m²).
    pub log_mean: f64,
    /// Mean luminance of the pixels, dark ones included (cd/m²): over the focus
    /// area, for Ward, when one is given.
    pub mean: f64,
    pub max: f64,
    /// The scene's white, when known (a reflectance scene's perfect diffuser).
    pub white: Option<f64>,
}

/// Below this a pixel counts as unlit in the log mean (log 0 is not a number).
const LIT: f64 = 1e-6;

impl SceneLuminance {
    /// Statistics of the scene's luminances (cd/m²); `None` if no pixel is lit.
    pub fn of(luminances: impl Iterator<Item = f64>, white: Option<f64>) -> Option<Self> {
        let (mut sum, mut n, mut max) = (0.0, 0usize, 0.0f64);
        // The mean counts every pixel, dark ones too: an area that is mostly black
        // adapts the eye to little light.
        let (mut linear, mut all) = (0.0, 0usize);
        for l in luminances.filter(|l| l.is_finite() && *l >= 0.0) {
            linear += l;
            all += 1;
            if l > LIT {
                sum += l.ln();
                n += 1;
                max = max.max(l);
            }
        }
        (n > 0).then(|| SceneLuminance {
            log_mean: (sum / n as f64).exp(),
            mean: linear / all as f64,
            max,
            white,
        })
    }
}

/// An operator fitted to one scene and one display: luminance in, luminance out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ToneCurve {
    /// L_d = scale · L_s (colorimetric, linear and Ward).
    Scale(f64),
    /// L_d = L_s^exponent · factor (Tumblin–Rushmeier).
    Power { exponent: f64, factor: f64 },
}

/// Stevens and Stevens' α and β at adaptation luminance `la` (seed §4.2.2).
fn stevens(la: f64) -> (f64, f64) {
    let l = la.log10();
    (0.4 * l + 2.92, -0.4 * l * l - 2.584 * l + 2.0208)
}

impl ToneOperator {
    /// The curve for `scene` on a display whose white has luminance `display_max`.
    pub fn curve(&self, scene: &SceneLuminance, display_max: f64) -> ToneCurve {
        match *self {
            ToneOperator::Colorimetric => ToneCurve::Scale(1.0),
            ToneOperator::Linear => {
                let reference = scene.white.unwrap_or(scene.max);
                ToneCurve::Scale(display_max / reference)
            }
            ToneOperator::Ward { .. } => {
                let display_adaptation = display_max / 2.0;
                let m = ((1.219 + display_adaptation.powf(0.4)) / (1.219 + scene.mean.powf(0.4)))
                    .powf(2.5);
                ToneCurve::Scale(m)
            }
            ToneOperator::TumblinRushmeier { display_contrast } => {
                let scene_adaptation = 10f64.powf(scene.log_mean.log10() + 0.84);
                let display_adaptation = display_max / display_contrast.max(1.0).sqrt();
                let (alpha_s, beta_s) = stevens(scene_adaptation);
                let (alpha_d, beta_d) = stevens(display_adaptation);
                ToneCurve::Power {
                    exponent: alpha_s / alpha_d,
                    factor: 10f64.powf((beta_s - beta_d) / alpha_d),
                }
            }
        }
    }

    pub fn name(&self) -> String {
        match self {
            ToneOperator::Colorimetric => "colorimetric (L_d = L_s)".into(),
            ToneOperator::Linear => "linear scale to the display's white".into(),
            ToneOperator::Ward { focus: None } => {
                "Ward (1994) contrast-based scale factor, adapted to the whole scene's mean luminance"
                    .into()
            }
            ToneOperator::Ward { focus: Some(f) } => format!(
                "Ward (1994) contrast-based scale factor, adapted to the mean luminance of the focus area {},{},{},{}",
                f.left, f.top, f.width, f.height
            ),
            ToneOperator::TumblinRushmeier { display_contrast } => {
                format!("Tumblin–Rushmeier (1993), C_max {display_contrast}")
            }
        }
    }
}

impl ToneCurve {
    pub fn display_luminance(&self, scene: f64) -> f64 {
        match *self {
            ToneCurve::Scale(m) => m * scene,
            ToneCurve::Power { exponent, factor } => {
                if scene > 0.0 {
                    scene.powf(exponent) * factor
                } else {
                    0.0
                }
            }
        }
    }

    /// The factor a colour of luminance `scene` is scaled by (chromaticity kept).
    pub fn factor(&self, scene: f64) -> f64 {
        match *self {
            ToneCurve::Scale(m) => m,
            ToneCurve::Power { .. } => {
                if scene > 0.0 {
                    self.display_luminance(scene) / scene
                } else {
                    0.0
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(log_mean: f64, max: f64) -> SceneLuminance {
        SceneLuminance {
            log_mean,
            mean: log_mean,
            max,
            white: None,
        }
    }

    #[test]
    fn linear_puts_the_scene_maximum_on_the_display_white() {
        let c = ToneOperator::Linear.curve(&scene(50.0, 4000.0), 100.0);
        assert!((c.display_luminance(4000.0) - 100.0).abs() < 1e-9);
        assert!((c.display_luminance(400.0) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn ward_is_one_when_scene_and_display_adapt_alike() {
        // Scene adapted to 50 cd/m², display white 100 (L_da = 50): m = 1.
        let c = ToneOperator::Ward { focus: None }.curve(&scene(50.0, 500.0), 100.0);
        assert!((c.factor(10.0) - 1.0).abs() < 1e-12);
        // A brighter scene is scaled down, and a just-noticeable step in the scene
        // (Blackwell's ΔL at its adaptation) becomes one on the display.
        let bright = scene(5000.0, 50_000.0);
        let m = ToneOperator::Ward { focus: None }
            .curve(&bright, 100.0)
            .factor(1.0);
        let threshold = |la: f64| 0.054 * (1.219 + la.powf(0.4)).powf(2.5);
        assert!((m * threshold(5000.0) - threshold(50.0)).abs() < 1e-9);
    }

    #[test]
    fn tumblin_rushmeier_matches_brightness() {
        let s = scene(2000.0, 20_000.0);
        let c = ToneOperator::TumblinRushmeier {
            display_contrast: TUMBLIN_RUSHMEIER_CONTRAST,
        }
        .curve(&s, 100.0);
        let brightness = |l: f64, la: f64| {
            let (a, b) = stevens(la);
            10f64.powf(b) * l.powf(a)
        };
        let (la_s, la_d) = (10f64.powf(2000f64.log10() + 0.84), 100.0 / 35f64.sqrt());
        for l in [1.0, 100.0, 5000.0] {
            let ld = c.display_luminance(l);
            let (bs, bd) = (brightness(l, la_s), brightness(ld, la_d));
            assert!((bs / bd - 1.0).abs() < 1e-9, "{l}: {bs} vs {bd}");
        }
        // A scene brighter than the display is shown with more contrast, not less
        // (α grows with adaptation): the operator's known expansion.
        let ToneCurve::Power { exponent, .. } = c else {
            panic!("{c:?}")
        };
        assert!(exponent > 1.0);
        assert!(c.display_luminance(20_000.0) / c.display_luminance(20.0) > 1000.0);
    }
}
