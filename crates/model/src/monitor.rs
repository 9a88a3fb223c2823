//! The monitor model, forward and inverse:
//!
//! XYZ(d, p) = M · diag(K(p)) · E(d) + XYZ_black
//!
//! with M the primary matrix (Rougeron & Péroche eq. 3; its columns are the XYZ of
//! each primary at full drive, black taken off), E the per-channel transfer laws,
//! K the spatial gain map and XYZ_black the light at zero drive, flare included.
//!
//! Optional terms (`AdditivityTerms`) model what the additive form misses, and are
//! kept by the fit only where cross-validation shows they lower the error
//! (`fit::terms`): channel interaction, crosstalk between channels (following their
//! light or their drives), primary chromaticity that moves with drive, and, for a
//! display decoding an HLG signal, BT.2100's OOTF.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::spatial::{ScreenPosition, SpatialMap};
use super::transfer::{TransferError, TransferLaw};
use chromacal_color::Xyz;
use chromacal_color::hdr::{hlg_inverse_oetf, hlg_oetf, hlg_scene_light};

/// Drive values of R, G, B, each normalised to [0, 1].
pub type Drive = [f64; 3];

/// Channel names in model order.
pub const CHANNELS: [&str; 3] = ["red", "green", "blue"];

/// Why an XYZ could not be turned back into drive values.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InverseError {
    #[error("the primary matrix is singular, so no drive reproduces a given XYZ")]
    SingularMatrix,
}

/// Drive values found for a requested XYZ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseResult {
    pub drive: Drive,
    /// Excitations before clipping to what the channels can give.
    pub excitation: [f64; 3],
    /// True when a channel had to be clipped: the XYZ is outside the gamut at this
    /// position. (Mapping such colours into the gamut is the job of `crf`.)
    pub clipped: bool,
    /// False when the terms' fixed point did not converge (then `clipped` too).
    pub converged: bool,
}

/// A fitted (or simulated) monitor model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(into = "ModelFile", try_from = "ModelFile")]
pub struct MonitorModel {
    /// Columns: XYZ of R, G, B at full drive with black taken off, at the centre.
    pub matrix: Matrix3<f64>,
    /// XYZ at zero drive (the display's black plus flare).
    pub black: Xyz,
    /// Transfer law of R, G and B.
    pub laws: [TransferLaw; 3],
    pub spatial: SpatialMap,
    /// What additivity and primary constancy miss, when the data showed it.
    pub terms: AdditivityTerms,
}

/// Corrections to the additive model, each `None` unless the fit kept it. With
/// l_c = K_c E_c the light of channel c in units of its primary, and ê_c = l_c / E_c(1)
/// its share of full drive (clamped to [0, 1]), the light above black is
///
/// XYZ − XYZ_black = Σ_c m_c l_c (1 + γ_c s_c + κ_c (1 − ê_c) s_c + λ_c (1 − δ_c) t_c)
///                  + Σ_c u_c ê_c (1 − ê_c),
/// s_c = Σ_{k≠c} ê_k, t_c = Σ_{k≠c} δ_k
///
/// with δ_c = E_c⁻¹(ê_c E_c(1)) the channel's drive (`MonitorModel::drives_of_shares`).
///
/// γ (interaction): a channel's light changes in proportion to what the other channels
/// give, as when a shared supply sags (Brainard 1989's channel independence failing);
/// alone, a channel is unaffected, so the ramps still define the curves. κ
/// (crosstalk): the same, but fading as the channel itself nears full drive, where it
/// has no more to give: an LCD whose subpixels are brighter with their neighbours lit
/// (the charge of a lit neighbour's data line couples into the subpixel), so that its
/// greys read above the sum of its ramps at mid drive and on the sum at white (the
/// shared MacBook Pro: +2.3 % at 0.5, +0.4 % at white; a brightness limiter instead
/// departs most at white, which γ models). λ (crosstalk in drive): the same coupling
/// following the neighbours' drives rather than their light. The charge a lit
/// neighbour's data line couples into a subpixel follows that line's voltage, which the
/// panel's driver sets from the code, so a dark grey's neighbours at drive 0.3 couple
/// in 30 % of their full effect where they give 7 % of their light: in light (κ) the
/// term cannot lift the dim greys that the dense LCD sets show lifted by 3–5 % from
/// drive 0.15 up (`docs/benchmarks.md`), in drive it can. The simulated crosstalk
/// (`channel_crosstalk`) is of this kind. Both are candidates; cross-validation
/// chooses (never both). u
/// (chromaticity shift): the XYZ a channel adds besides its primary's direction,
/// largest at mid drive and none at black and full drive, as a TN panel's or a CRT's
/// blue moves in chromaticity with drive (the channel's own curve is still E_c).
///
/// γ_S (the HLG OOTF, `hlg_ootf`): a display decoding HLG (BT.2100 Table 5) scales
/// each channel's scene light E_c by the scene luminance to the power γ_S − 1, the
/// system gamma, Y_S = Σ_k w_k E_k on BT.2020's weights, so that a channel's light
/// depends on the other two by a factor, not by a small term: alone, channel c
/// shows (w_c E_c)^(γ_S − 1) E_c, in a mixture Y_S^(γ_S − 1) E_c. Its ramps give
/// ê_c = E_c^γ_S, so its gain in a mixture is (Y_S / (w_c E_c))^(γ_S − 1) with
/// E_k = ê_k^(1/γ_S) (`ootf_gains`): a red in a white gives 1 / 0.2627^0.2 = 1.31
/// times its light alone at γ_S = 1.2. The gain multiplies the others'.
///
/// That gain is the light's, and it holds where the panel after the OOTF follows the
/// gamma the display's processing inverts. Through the laws instead
/// (`hlg_ootf_through_laws`), the OOTF acts on the signal, before the panel, as
/// BT.2100's display model has it: E_k is the scene light of each channel's code (its
/// law inverted), and channel c in a mixture shows what it shows alone at the code u
/// whose OOTF output is the same, E_s(u)^γ_S = (Y_S / w_c)^(γ_S − 1) E_c: its own
/// law at u, whatever the panel's transfer, so the gain is E(u) / E(v)
/// (`MonitorModel::ootf_gains`). Above full signal (a channel in a bright mixture is
/// driven harder than alone ever: blue in a white at γ_S 1.2 is at 1.6 times its full
/// scene light, and alone never passes 0.57 of the OOTF output it has there) the light
/// is a power of E_s measured on the greys and whites (`hlg_ootf_beyond`), which reach
/// there; without them an HLG law goes on as its formula does, another law as the
/// power of E_s it has over its top. The spatial map's gain is part of the share a
/// channel's code is taken from, so away from the centre the code is off by what the
/// map takes (a few per cent of light); the shares' form depends on their ratios only.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdditivityTerms {
    /// γ of red, green and blue.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interaction: Option<[f64; 3]>,
    /// κ of red, green and blue.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crosstalk: Option<[f64; 3]>,
    /// λ of red, green and blue: crosstalk that follows the other channels' drives.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drive_crosstalk: Option<[f64; 3]>,
    /// u of red, green and blue, XYZ each.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chromaticity_shift: Option<[[f64; 3]; 3]>,
    /// γ_S, the system gamma of BT.2100's HLG OOTF.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hlg_ootf: Option<f64>,
    /// The OOTF's gains taken through the laws, from each channel's code, rather than
    /// from its share of light (see above).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub hlg_ootf_through_laws: bool,
    /// Through the laws, each channel's light beyond full signal as a power of its
    /// scene light, measured on the greys and whites (see above), within
    /// [`BEYOND_POWERS`]; 0 for a channel no reading took there, which goes on as its
    /// law does, as every channel does when this is unset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hlg_ootf_beyond: Option<[f64; 3]>,
    /// The brightness limiter (`fit::limiter`): not a term of a patch's colour (the
    /// model is defined for the plan's patch on black, which it does not dim) but of a
    /// whole screen's, its light scaled by g(p) of the screen's mean light p
    /// (`MonitorModel::image_light`). Not counted by `is_empty`: the colour of a
    /// patch, and so every export of the model, is the same with or without it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limiter: Option<Limiter>,
}

impl AdditivityTerms {
    pub fn is_empty(&self) -> bool {
        self.interaction.is_none()
            && self.crosstalk.is_none()
            && self.drive_crosstalk.is_none()
            && self.chromaticity_shift.is_none()
            && self.hlg_ootf.is_none()
    }

    /// No term at all, the limiter included: nothing to write in a model file.
    pub fn is_absent(&self) -> bool {
        self.is_empty() && self.limiter.is_none()
    }

    /// Each channel's gain at light shares `shares` and drives `drives`:
    /// 1 + γ_c s_c + κ_c (1 − ê_c) s_c + λ_c (1 − δ_c) t_c, times the HLG OOTF's,
    /// `ootf` (`MonitorModel::ootf_gains`).
    pub fn gains(&self, shares: &[f64; 3], drives: &[f64; 3], ootf: &[f64; 3]) -> [f64; 3] {
        let s = interaction_basis(shares);
        let x = crosstalk_basis(shares);
        let y = crosstalk_basis(drives);
        [0, 1, 2].map(|c| {
            (1.0 + self.interaction.map_or(0.0, |g| g[c] * s[c])
                + self.crosstalk.map_or(0.0, |k| k[c] * x[c])
                + self.drive_crosstalk.map_or(0.0, |l| l[c] * y[c]))
                * ootf[c]
        })
    }

    /// Names of the terms present, for reports and export notes.
    pub fn names(&self) -> Vec<&'static str> {
        let mut names = Vec::new();
        if self.interaction.is_some() {
            names.push("channel interaction");
        }
        if self.crosstalk.is_some() {
            names.push("crosstalk between channels");
        }
        if self.drive_crosstalk.is_some() {
            names.push("crosstalk between channels' drives");
        }
        if self.chromaticity_shift.is_some() {
            names.push("drive-dependent primary chromaticity");
        }
        if self.hlg_ootf.is_some() && self.hlg_ootf_through_laws {
            names.push("the HLG OOTF (BT.2100) through the laws");
        } else if self.hlg_ootf.is_some() {
            names.push("the HLG OOTF (BT.2100)");
        }
        names
    }

    /// Every coefficient is a finite number (and the powers beyond full signal in
    /// their range, with the OOTF through the laws they belong to).
    fn is_finite(&self) -> bool {
        self.interaction.iter().flatten().all(|v| v.is_finite())
            && self.crosstalk.iter().flatten().all(|v| v.is_finite())
            && self.drive_crosstalk.iter().flatten().all(|v| v.is_finite())
            && self
                .chromaticity_shift
                .iter()
                .flatten()
                .flatten()
                .all(|v| v.is_finite())
            && self.hlg_ootf.is_none_or(|g| g.is_finite() && g > 0.0)
            && self.hlg_ootf_beyond.is_none_or(|p| {
                self.hlg_ootf.is_some()
                    && self.hlg_ootf_through_laws
                    && p.iter().all(|&p| p == 0.0 || BEYOND_POWERS.contains(&p))
            })
            && self.limiter.is_none_or(|l| {
                l.full_field > 0.0
                    && l.full_field.is_finite()
                    && l.sharpness > 0.0
                    && l.sharpness.is_finite()
            })
    }
}

/// The powers of scene light a channel's light beyond full signal may have
/// (`AdditivityTerms::hlg_ootf_beyond`): a panel's gamma behind an OOTF of system gamma
/// 0.8–1.8 gives 1–2.5 where it follows a law, less where its table flattens (0.54
/// for a panel that goes from gamma 2.2 to 0.8 at 80 % of its drive); 1 / p is taken
/// in the inverse, so p near 0 is refused.
pub const BEYOND_POWERS: std::ops::RangeInclusive<f64> = 0.2..=5.0;

/// The brightness limiter g(p) = (1 + (p / F)^k)^(−1/k) of a screen's mean light p
/// (fitted by `fit::limiter`, whose documentation says why this family).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limiter {
    /// F: the screen's mean light the cap holds to (the full-field white), cd/m².
    pub full_field: f64,
    /// k: the knee's sharpness.
    pub sharpness: f64,
}

/// The mean light of a screen whose share `area` shows `light` on a black of `black`:
/// what a brightness limiter follows (the fit's p, `fit::limiter`).
pub fn screen_mean_light(area: f64, light: f64, black: f64) -> f64 {
    let area = area.clamp(0.0, 1.0);
    area * light + (1.0 - area) * black
}

impl Limiter {
    /// The gain on every emitter for a screen of mean light `mean_light` cd/m².
    pub fn gain(&self, mean_light: f64) -> f64 {
        let ratio = (mean_light.max(0.0) / self.full_field).powf(self.sharpness);
        (1.0 + ratio).powf(-1.0 / self.sharpness)
    }
}

/// A whole image's light as a brightness limiter sees it (`MonitorModel::image_light`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageLight {
    /// The screen's mean light, in the model's units (cd/m² for absolute readings).
    pub mean_light: f64,
    /// The limiter's gain on all the screen's light.
    pub gain: f64,
    /// The limiter's full-field white.
    pub full_field: f64,
}

/// ê_c: each channel's light as a share of its full drive, clamped to [0, 1].
pub fn drive_shares(light: &Vector3<f64>, full: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        if full[c] > 0.0 {
            (light[c] / full[c]).clamp(0.0, 1.0)
        } else {
            0.0
        }
    })
}

/// s_c = Σ_{k≠c} ê_k: what the other channels give, the multiplier of γ_c.
pub fn interaction_basis(shares: &[f64; 3]) -> [f64; 3] {
    let total: f64 = shares.iter().sum();
    shares.map(|s| total - s)
}

/// (1 − ê_c) s_c: the multiplier of κ_c, what the others give while channel c has
/// room to rise; of drives δ instead of shares, (1 − δ_c) t_c, the multiplier of λ_c.
pub fn crosstalk_basis(shares: &[f64; 3]) -> [f64; 3] {
    let s = interaction_basis(shares);
    [0, 1, 2].map(|c| (1.0 - shares[c]) * s[c])
}

/// The HLG OOTF's gain on each channel at light shares `shares` for system gamma
/// `gamma` (`AdditivityTerms`): (Y_S / (w_c E_c))^(γ − 1), E_k = ê_k^(1/γ),
/// Y_S = Σ_k w_k E_k. It depends on the shares' ratios only, so a grey keeps its
/// gains at every level. 1 for a channel giving no light (whose light the gain
/// multiplies is 0: its product with the gain goes to 0 with ê_c as ê_c^(1/γ)), and
/// for shares below 0 (the extended inverse's), taken as 0.
pub fn ootf_gains(shares: &[f64; 3], gamma: f64) -> [f64; 3] {
    let w = chromacal_color::hdr::BT2020_LUMINANCE;
    let scene = shares.map(|s| s.max(0.0).powf(1.0 / gamma));
    let luminance: f64 = (0..3).map(|k| w[k] * scene[k]).sum();
    [0, 1, 2].map(|c| {
        let own = w[c] * scene[c];
        if own > 0.0 {
            (luminance / own).powf(gamma - 1.0)
        } else {
            1.0
        }
    })
}

/// The scene light E_s of the code at which `law` gives `share` of its full light
/// `full` (its law inverted). Beyond full light (the extended inverse's shares above
/// one) it is the scene light at which the light carried on beyond full signal
/// ([`light_at_scene_light`], with the measured power `beyond` where there is one)
/// gives it, so that a channel alone keeps a gain of 1 there. At share 0 the code is
/// taken as 0. For a law whose light starts above code zero (a gain-offset-gamma
/// cut-off, a table's flat start) a share just above 0 is its start's code, so the
/// other channels' Y_S steps there by that code's scene light (what the display's
/// processing sees), and the channel's own light by what the law gives at the code
/// the OOTF moves it to (0.2 % of full red at a cut-off of 0.1 in full green).
fn scene_light_of_share(law: &TransferLaw, share: f64, full: f64, beyond: Option<f64>) -> f64 {
    if share <= 0.0 {
        0.0
    } else if share <= 1.0 {
        hlg_scene_light(law.drive(share * full).clamp(0.0, 1.0))
    } else if let (TransferLaw::Hlg(hlg), None) = (law, beyond) {
        hlg.scene_light_of(share)
    } else {
        share.powf(1.0 / beyond.or_else(|| top_exponent(law)).unwrap_or(1.0))
    }
}

/// The light of `law` at scene light `scene` (1 at full signal): the law at the code
/// of that scene light; beyond full signal, its full light `full` times the scene
/// light to the power `beyond` measured on the greys and whites, and without one an
/// HLG law carried on as its formula goes (`Hlg::of_scene_light`), another to the
/// power the law has over its top ([`top_exponent`], a secant, so its slope steps at
/// full signal).
fn light_at_scene_light(law: &TransferLaw, scene: f64, full: f64, beyond: Option<f64>) -> f64 {
    match (law, beyond) {
        (TransferLaw::Hlg(hlg), None) => hlg.of_scene_light(scene),
        _ if scene <= 1.0 => {
            law.excitation(hlg_oetf(scene * hlg_inverse_oetf(1.0)).clamp(0.0, 1.0))
        }
        _ => full * scene.powf(beyond.or_else(|| top_exponent(law)).unwrap_or(1.0)),
    }
}

/// d ln E / d ln E_s of an HLG channel's law over its top, from 95 % of full scene
/// light to full: the power it goes on with beyond full signal. `None` where the law
/// gives no light there.
fn top_exponent(law: &TransferLaw) -> Option<f64> {
    let below = law.excitation(hlg_oetf(0.95 * hlg_inverse_oetf(1.0)));
    let exponent = (law.excitation(1.0) / below).ln() / (1.0f64 / 0.95).ln();
    (exponent.is_finite() && exponent > 0.0).then_some(exponent)
}

/// ê_c (1 − ê_c): the weight of u_c.
pub fn chromaticity_shift_basis(shares: &[f64; 3]) -> [f64; 3] {
    shares.map(|s| s * (1.0 - s))
}

impl MonitorModel {
    /// E(1) of each channel.
    fn full_drive_excitations(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.laws[c].full_drive_excitation())
    }

    /// δ: each channel's drive at light shares `shares` (its law inverted at the
    /// centre), what the crosstalk in drive follows, taken from where the channel's
    /// light starts (d₀, the law's drive just above 0) to full drive:
    /// δ = (E⁻¹(ê E(1)) − d₀) / (E⁻¹(E(1)) − d₀). So δ is 0 for a channel that gives no
    /// light and does not jump when it starts to (a law with a cut-off, GOG's or a
    /// table's flat start, would jump to d₀ there: the forward model would step and
    /// the inverse of a colour with a channel off have two answers), and 1 at full
    /// drive whatever the law's top (a PQ law's E(1) is its peak's code, below 1).
    /// Beyond [0, 1] (the extended inverse's shares) carried on by the share's excess,
    /// so that the terms stay continuous there.
    pub fn drives_of_shares(&self, shares: &[f64; 3]) -> [f64; 3] {
        let full = self.full_drive_excitations();
        [0, 1, 2].map(|c| {
            let law = &self.laws[c];
            let inside = shares[c].clamp(0.0, 1.0);
            let start = law.drive(1e-12 * full[c]);
            let span = law.drive(full[c]) - start;
            let drive = if inside > 0.0 && span > 0.0 {
                ((law.drive(inside * full[c]) - start) / span).clamp(0.0, 1.0)
            } else {
                0.0
            };
            drive + (shares[c] - inside)
        })
    }

    /// The HLG OOTF's gain on each channel at light shares `shares` (1 without the
    /// term): from the shares (`ootf_gains`), or through the laws
    /// (`AdditivityTerms::hlg_ootf_through_laws`): E_k the scene light of channel k's
    /// code, Y_S = Σ w_k E_k, and channel c's gain E_c(u) / E_c(v) at the code u of
    /// scene light ((Y_S / w_c)^(γ − 1) E_c)^(1/γ) ([`light_at_scene_light`],
    /// [`scene_light_of_share`] for what goes beyond full signal).
    pub fn ootf_gains(&self, shares: &[f64; 3]) -> [f64; 3] {
        let Some(gamma) = self.terms.hlg_ootf else {
            return [1.0; 3];
        };
        if !self.terms.hlg_ootf_through_laws {
            return ootf_gains(shares, gamma);
        }
        let full = self.full_drive_excitations();
        let beyond = |c: usize| {
            self.terms
                .hlg_ootf_beyond
                .map(|p| p[c])
                .filter(|&p| p > 0.0)
        };
        let scene =
            [0, 1, 2].map(|c| scene_light_of_share(&self.laws[c], shares[c], full[c], beyond(c)));
        let w = chromacal_color::hdr::BT2020_LUMINANCE;
        let luminance: f64 = (0..3).map(|k| w[k] * scene[k]).sum();
        [0, 1, 2].map(|c| {
            let (law, alone) = (&self.laws[c], shares[c] * full[c]);
            if !(scene[c] > 0.0 && alone > 0.0) {
                return 1.0;
            }
            let at = ((luminance / w[c]).powf(gamma - 1.0) * scene[c]).powf(1.0 / gamma);
            light_at_scene_light(law, at, full[c], beyond(c)) / alone
        })
    }

    /// [`Self::drives_of_shares`] where the crosstalk in drive needs them, zeros without
    /// it (the only term that uses them; a law's inverse is not free).
    fn term_drives(&self, shares: &[f64; 3]) -> [f64; 3] {
        if self.terms.drive_crosstalk.is_none() {
            return [0.0; 3];
        }
        self.drives_of_shares(shares)
    }

    /// The light above black of channel lights `light` (l_c = K_c E_c), terms included:
    /// the sum of [`Self::channel_contributions`].
    pub fn light_above_black(&self, light: &Vector3<f64>) -> Xyz {
        if self.terms.is_empty() {
            return self.matrix * light;
        }
        let shares = drive_shares(light, &self.full_drive_excitations());
        let contributions = self.channel_contributions(light, &shares);
        contributions.column(0) + contributions.column(1) + contributions.column(2)
    }

    /// Each channel's light above black at channel lights `light` whose drive shares
    /// are `shares`, terms included: m_c l_c (1 + γ_c s_c + κ_c (1 − ê_c) s_c + λ_c (1 − δ_c) t_c)
    /// + u_c ê_c (1 − ê_c), one column a channel.
    fn channel_contributions(&self, light: &Vector3<f64>, shares: &[f64; 3]) -> Matrix3<f64> {
        let gains = self
            .terms
            .gains(shares, &self.term_drives(shares), &self.ootf_gains(shares));
        let w = chromaticity_shift_basis(shares);
        let mut contributions = Matrix3::zeros();
        for c in 0..3 {
            let mut column = self.matrix.column(c) * (light[c] * gains[c]);
            if let Some(u) = self.terms.chromaticity_shift {
                column += Xyz::from(u[c]) * w[c];
            }
            contributions.set_column(c, &column);
        }
        contributions
    }

    /// The channel lights l that give `above` (the light above black): M⁻¹ applied to
    /// `above` for the additive model; with terms, the fixed point of
    /// l_c = [M⁻¹(above − Σ u ê(1 − ê))]_c / g_c (the gains), which converges because
    /// the terms are small next to the primaries (a few per cent; the fit keeps none
    /// beyond `fit::terms::MAX_TERM`), slowly near that bound, where Newton's method
    /// finishes what 100 steps leave. Also says whether it converged.
    fn light_of(&self, inverse: &Matrix3<f64>, above: &Xyz) -> (Vector3<f64>, bool) {
        self.light_of_shares(inverse, above, drive_shares)
    }

    /// The channel lights at the centre whose XYZ, with the terms' polynomials carried
    /// on beyond black and full drive (shares not clamped to [0, 1]), is `xyz`: inside
    /// the gamut what [`Self::inverse`] finds, outside it the smooth continuation, for
    /// a table that interpolates across the gamut's surface (`export::icc_lut`). `None`
    /// when the matrix is singular or the fixed point does not converge.
    pub fn extended_light_of(&self, xyz: &Xyz) -> Option<Vector3<f64>> {
        let inverse = self.matrix.try_inverse()?;
        let unclamped = |light: &Vector3<f64>, full: &[f64; 3]| {
            [0, 1, 2].map(|c| {
                if full[c] > 0.0 {
                    light[c] / full[c]
                } else {
                    0.0
                }
            })
        };
        let (light, converged) = self.light_of_shares(&inverse, &(xyz - self.black), unclamped);
        (converged && light.iter().all(|v| v.is_finite())).then_some(light)
    }

    /// [`Self::light_of`] with the shares ê taken by `shares`.
    fn light_of_shares(
        &self,
        inverse: &Matrix3<f64>,
        above: &Xyz,
        shares: impl Fn(&Vector3<f64>, &[f64; 3]) -> [f64; 3],
    ) -> (Vector3<f64>, bool) {
        let mut light = inverse * above;
        if self.terms.is_empty() {
            return (light, true);
        }
        let full = self.full_drive_excitations();
        for _ in 0..100 {
            let shares = shares(&light, &full);
            let mut target = *above;
            if let Some(u) = self.terms.chromaticity_shift {
                let w = chromaticity_shift_basis(&shares);
                for c in 0..3 {
                    target -= Xyz::from(u[c]) * w[c];
                }
            }
            let mut next = inverse * target;
            let drives = self.term_drives(&shares);
            let ootf = self.ootf_gains(&shares);
            for (c, gain) in self
                .terms
                .gains(&shares, &drives, &ootf)
                .into_iter()
                .enumerate()
            {
                next[c] /= gain.max(1e-3);
            }
            let step = (next - light).abs().max();
            light = next;
            if step <= 1e-13 * full.iter().fold(0.0, |a: f64, b| a.max(b.abs())) {
                return (light, true);
            }
        }
        // Not settled in 100 steps: near the fit's bound on γ the iteration contracts
        // by a factor close to 1 near white. Newton's method on the same equations
        // finishes from where it stopped.
        let residual = |light: &Vector3<f64>| {
            let c = self.channel_contributions(light, &shares(light, &full));
            c.column(0) + c.column(1) + c.column(2) - above
        };
        let scale = full.iter().fold(0.0, |a: f64, b| a.max(b.abs())).max(1e-12);
        let h = 1e-7 * scale;
        let picard = light;
        for _ in 0..20 {
            let r = residual(&light);
            let mut jacobian = Matrix3::zeros();
            for k in 0..3 {
                let mut moved = light;
                moved[k] += h;
                jacobian.set_column(k, &((residual(&moved) - r) / h));
            }
            let Some(step) = jacobian.lu().solve(&r) else {
                break;
            };
            light -= step;
            if step.abs().max() <= 1e-13 * scale {
                break;
            }
        }
        // Newton far from the answer can run off (or to NaN): the better of the two.
        let (mut miss, picard_miss) = (residual(&light).norm(), residual(&picard).norm());
        if !(miss <= picard_miss) {
            (light, miss) = (picard, picard_miss);
        }
        // Judged by the equations solved, with the shares as given (clamped for the
        // inverse, carried on beyond the gamut for the extended table): judging the
        // extended solution by the clamped forward called a third of them unsolved.
        let converged = miss <= 1e-6 * above.norm().max(f64::MIN_POSITIVE);
        (light, converged)
    }

    /// E(d): the three excitations.
    pub fn excitations(&self, drive: Drive) -> Vector3<f64> {
        Vector3::new(
            self.laws[0].excitation(drive[0]),
            self.laws[1].excitation(drive[1]),
            self.laws[2].excitation(drive[2]),
        )
    }

    /// XYZ of drive `d` shown at `position`.
    pub fn forward(&self, drive: Drive, position: ScreenPosition) -> Xyz {
        let k = self.spatial.gains(position);
        let e = self.excitations(drive);
        self.light_above_black(&Vector3::new(k[0] * e[0], k[1] * e[1], k[2] * e[2])) + self.black
    }

    /// XYZ of drive `d` at the centre of the screen.
    pub fn forward_centre(&self, drive: Drive) -> Xyz {
        self.forward(drive, ScreenPosition::CENTRE)
    }

    /// What a brightness limiter makes of a screen whose share `area` shows an image
    /// of pixels driven at `drives` (equal shares of it) on black: the screen's mean
    /// light p and the gain g(p) on all of its light. None without a limiter (or
    /// without pixels). p is reckoned as the limiter was fitted (`fit::limiter`): each
    /// pixel's Y at the centre of the screen, the spatial map left out.
    pub fn image_light(
        &self,
        drives: impl Iterator<Item = Drive>,
        area: f64,
    ) -> Option<ImageLight> {
        let limiter = self.terms.limiter?;
        let (mut sum, mut n) = (0.0, 0usize);
        for drive in drives {
            sum += self.forward_centre(drive).y;
            n += 1;
        }
        (n > 0).then(|| {
            let mean_light = screen_mean_light(area, sum / n as f64, self.black.y);
            ImageLight {
                mean_light,
                gain: limiter.gain(mean_light),
                full_field: limiter.full_field,
            }
        })
    }

    /// XYZ of a patch of drive `drive` at `position`, shown as a window of `area` of
    /// the screen on black: as `forward`, dimmed by the limiter for the screen's mean
    /// light where the model has one (a window of the plan's own size is hardly dimmed:
    /// the model's readings were taken on it).
    pub fn forward_in_window(&self, drive: Drive, position: ScreenPosition, area: f64) -> Xyz {
        let xyz = self.forward(drive, position);
        match self.terms.limiter {
            Some(l) => xyz * l.gain(screen_mean_light(area, xyz.y, self.black.y)),
            None => xyz,
        }
    }

    /// XYZ of full white at the centre: the reference white for L*a*b*.
    pub fn white(&self) -> Xyz {
        self.forward_centre([1.0; 3])
    }

    /// The drive that reproduces `xyz` at `position`: E = diag(K)⁻¹ M⁻¹ (XYZ − black)
    /// (with the terms, `light_of`), each excitation clipped to what its channel can
    /// give, then each law inverted.
    pub fn inverse(
        &self,
        xyz: &Xyz,
        position: ScreenPosition,
    ) -> Result<InverseResult, InverseError> {
        let inverse = self
            .matrix
            .try_inverse()
            .ok_or(InverseError::SingularMatrix)?;
        let k = self.spatial.gains(position);
        // A colour the terms' fixed point cannot reach is flagged as out of reach.
        let (t, converged) = self.light_of(&inverse, &(xyz - self.black));
        let mut excitation = [0.0; 3];
        let mut drive = [0.0; 3];
        let mut clipped = !converged;
        for c in 0..3 {
            excitation[c] = t[c] / k[c];
            let top = self.laws[c].full_drive_excitation();
            let tolerance = 1e-9 * top;
            if excitation[c] < -tolerance || excitation[c] > top + tolerance {
                clipped = true;
            }
            drive[c] = self.laws[c].drive(excitation[c].clamp(0.0, top));
        }
        Ok(InverseResult {
            drive,
            excitation,
            clipped,
            converged,
        })
    }

    /// The same display with `spatial` as its map.
    pub fn with_spatial(self, spatial: SpatialMap) -> MonitorModel {
        MonitorModel { spatial, ..self }
    }

    /// The same display with all light scaled by `factor` (to compare a profile in
    /// cd/m² with measurements relative to white, say).
    pub fn scaled(&self, factor: f64) -> MonitorModel {
        let mut terms = self.terms.clone();
        if let Some(u) = terms.chromaticity_shift.as_mut() {
            for v in u.iter_mut().flatten() {
                *v *= factor;
            }
        }
        // The limiter's F is a light, in the same units.
        if let Some(l) = terms.limiter.as_mut() {
            l.full_field *= factor;
        }
        MonitorModel {
            matrix: self.matrix * factor,
            black: self.black * factor,
            terms,
            ..self.clone()
        }
    }

    /// Each channel's light above black at `drive` at the centre, terms included
    /// (m_c l_c g_c + u_c ê_c (1 − ê_c), g_c the gain of `AdditivityTerms::gains`): the columns of a matrix whose row
    /// sums, with black, give the XYZ of `drive`. Each column is linear in m_c and u_c
    /// together, which is what lets [`Self::anchored_at`] solve for one gain a channel.
    pub fn contributions_at(&self, drive: Drive) -> Matrix3<f64> {
        let k = self.spatial.gains(ScreenPosition::CENTRE);
        let e = self.excitations(drive);
        let light = Vector3::new(k[0] * e[0], k[1] * e[1], k[2] * e[2]);
        self.channel_contributions(
            &light,
            &drive_shares(&light, &self.full_drive_excitations()),
        )
    }

    /// The same display with each channel's light scaled by its own gain g_c (its
    /// column and its chromaticity shift alike), so that full white at the centre
    /// gives `white` ([`Self::anchored_at`] at full drive). This is how a fit is
    /// anchored at the measured white (`fit::anchor_at_measured_white`): an ICC
    /// profile, a `.cal` target and every relative export are normalised to the
    /// white, so a model that misses the measured white rescales every colour it
    /// exports.
    pub fn anchored_at_white(&self, white: &Xyz) -> Option<(MonitorModel, [f64; 3])> {
        self.anchored_at([1.0; 3], white)
    }

    /// The same display with each channel's light scaled by its own gain g_c (its
    /// column and its chromaticity shift alike), so that `drive` at the centre gives
    /// `target`: g = C⁻¹ (target − black), with C the channels' contributions at
    /// `drive` (`contributions_at`). `None` when C is singular or a gain is not a
    /// positive finite number.
    pub fn anchored_at(&self, drive: Drive, target: &Xyz) -> Option<(MonitorModel, [f64; 3])> {
        let gains = self
            .contributions_at(drive)
            .try_inverse()
            .map(|inverse| inverse * (target - self.black))?;
        let gains = [gains[0], gains[1], gains[2]];
        if !gains.iter().all(|g| g.is_finite() && *g > 0.0) {
            return None;
        }
        let mut anchored = self.clone();
        for (c, g) in gains.iter().enumerate() {
            let column = anchored.matrix.column(c) * *g;
            anchored.matrix.set_column(c, &column);
            if let Some(u) = anchored.terms.chromaticity_shift.as_mut() {
                u[c] = u[c].map(|v| v * g);
            }
        }
        Some((anchored, gains))
    }

    /// 2-norm condition number of the primary matrix: how much the inverse amplifies
    /// relative errors. Near-collinear primaries make it large.
    pub fn condition_number(&self) -> f64 {
        matrix_condition_number(&self.matrix)
    }
}

/// σ_max / σ_min of a 3×3 matrix (∞ when it is singular).
pub fn matrix_condition_number(m: &Matrix3<f64>) -> f64 {
    let Some(svd) = chromacal_color::linalg::bounded_svd(*m) else {
        return f64::INFINITY;
    };
    let s = svd.singular_values;
    let max = s.max();
    let min = s.min();
    if min <= 0.0 { f64::INFINITY } else { max / min }
}

/// Largest |X|, |Y| or |Z| of a black or a primary a model file may hold.
pub const MAX_TRISTIMULUS: f64 = 1e7;

/// The model as written in a file: named primaries and laws, so a person can read
/// it; checked when read (finite numbers, monotone laws).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// XYZ at zero drive.
    black: [f64; 3],
    primaries: PerChannel<[f64; 3]>,
    laws: PerChannel<TransferLaw>,
    #[serde(default)]
    spatial: SpatialMap,
    #[serde(default, skip_serializing_if = "AdditivityTerms::is_absent")]
    terms: AdditivityTerms,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PerChannel<T> {
    red: T,
    green: T,
    blue: T,
}

/// Why a model in a file is not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelFileError {
    #[error("model: {0} is not a finite number within ±1e7")]
    NotFinite(&'static str),
    #[error("model: the spatial map has {0}")]
    Spatial(String),
    #[error("model: the {channel} law: {source}")]
    Law {
        channel: &'static str,
        source: TransferError,
    },
}

impl From<MonitorModel> for ModelFile {
    fn from(m: MonitorModel) -> Self {
        let column = |c: usize| [m.matrix[(0, c)], m.matrix[(1, c)], m.matrix[(2, c)]];
        let [red, green, blue] = m.laws;
        ModelFile {
            black: [m.black.x, m.black.y, m.black.z],
            primaries: PerChannel {
                red: column(0),
                green: column(1),
                blue: column(2),
            },
            laws: PerChannel { red, green, blue },
            spatial: m.spatial,
            terms: m.terms,
        }
    }
}

impl TryFrom<ModelFile> for MonitorModel {
    type Error = ModelFileError;

    fn try_from(f: ModelFile) -> Result<Self, Self::Error> {
        // Finite, and within what any display gives: 10⁷ cd/m² is a thousand times the
        // brightest HDR screen, and keeps every sum of the model finite.
        let finite = |v: &[f64; 3], what| {
            if v.iter()
                .all(|x| x.is_finite() && x.abs() <= MAX_TRISTIMULUS)
            {
                Ok(())
            } else {
                Err(ModelFileError::NotFinite(what))
            }
        };
        finite(&f.black, "black")?;
        finite(&f.primaries.red, "primaries.red")?;
        finite(&f.primaries.green, "primaries.green")?;
        finite(&f.primaries.blue, "primaries.blue")?;
        if !f.terms.is_finite() {
            return Err(ModelFileError::NotFinite("terms"));
        }
        if let Some(problem) = f.spatial.problem() {
            return Err(ModelFileError::Spatial(problem));
        }
        let laws = [f.laws.red, f.laws.green, f.laws.blue];
        for (law, channel) in laws.iter().zip(CHANNELS) {
            law.monotonicity()
                .map_err(|source| ModelFileError::Law { channel, source })?;
        }
        let p = &f.primaries;
        Ok(MonitorModel {
            matrix: Matrix3::from_columns(&[
                Xyz::from(p.red),
                Xyz::from(p.green),
                Xyz::from(p.blue),
            ]),
            black: Xyz::from(f.black),
            laws,
            spatial: f.spatial,
            terms: f.terms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::Surface;
    use crate::transfer::{Power, TransferLaw};

    fn srgb_like() -> MonitorModel {
        MonitorModel {
            matrix: Matrix3::new(
                41.24, 35.76, 18.05, //
                21.26, 71.52, 7.22, //
                1.93, 11.92, 95.05,
            ),
            black: Xyz::new(0.1, 0.11, 0.12),
            laws: [
                TransferLaw::Power(Power { gamma: 2.2 }),
                TransferLaw::Power(Power { gamma: 2.3 }),
                TransferLaw::Power(Power { gamma: 2.1 }),
            ],
            spatial: SpatialMap::Scalar {
                surface: Surface {
                    degree: 2,
                    coefficients: vec![0.0, 0.0, -0.1, 0.0, -0.1],
                },
            },
            terms: AdditivityTerms::default(),
        }
    }

    #[test]
    fn the_limiter_dims_a_whole_image_and_large_windows_and_survives_the_file() {
        let mut m = srgb_like();
        let white = m.white().y;
        assert_eq!(m.image_light([[1.0; 3]].into_iter(), 1.0), None);
        let limiter = Limiter {
            full_field: 30.0,
            sharpness: 4.0,
        };
        m.terms.limiter = Some(limiter);
        // A full field of white: its mean light is white's, dimmed to about F.
        let full = m
            .image_light(std::iter::repeat_n([1.0; 3], 10), 1.0)
            .unwrap();
        assert!((full.mean_light / white - 1.0).abs() < 1e-9);
        assert!((full.gain - limiter.gain(white)).abs() < 1e-12 && full.gain < 0.35);
        // Mostly black: hardly dimmed; a window's patch likewise by its area.
        let pixels = (0..100).map(|i| if i == 0 { [1.0; 3] } else { [0.0; 3] });
        assert!(m.image_light(pixels, 1.0).unwrap().gain > 0.999);
        // The same white image on a quarter of the screen: a quarter of the light.
        let quarter = m
            .image_light(std::iter::repeat_n([1.0; 3], 10), 0.25)
            .unwrap();
        assert!((quarter.mean_light - (0.25 * white + 0.75 * m.black.y)).abs() < 1e-9);
        // check of relative readings scales the model, and F with it.
        let scaled = m.scaled(0.5);
        assert_eq!(scaled.terms.limiter.unwrap().full_field, 15.0);
        let small = m
            .forward_in_window([1.0; 3], ScreenPosition::CENTRE, 0.01)
            .y;
        let whole = m.forward_in_window([1.0; 3], ScreenPosition::CENTRE, 1.0).y;
        assert!((small / white - 1.0).abs() < 1e-3 && whole < 0.35 * white);
        // A patch's colour, and so every export, is the limiter's alone to leave.
        assert!(m.terms.is_empty() && !m.terms.is_absent());
        let text = toml::to_string(&m).unwrap();
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back.terms.limiter, Some(limiter));
    }

    /// Beyond the gamut the extended inverse solves the terms' equations carried on
    /// (shares outside [0, 1]); a limiter near the fit's bound needs Newton there, and
    /// its answer is judged by those equations, not by the clamped forward (a review
    /// found a third of such points returned as unsolved).
    #[test]
    fn the_extended_inverse_solves_beyond_the_gamut_near_the_bound() {
        let mut m = srgb_like();
        m.spatial = SpatialMap::Uniform;
        m.terms.interaction = Some([-0.249, -0.24, -0.245]);
        let full = m.full_drive_excitations();
        // Shares from −0.6 to 1.2 in steps of 0.225: 729 points in and around the
        // gamut (18 of them were returned as unsolved, all with a share of 1.2).
        let step = |i: usize| -0.6 + 0.225 * i as f64;
        for i in 0..729 {
            let shares = [step(i / 81), step(i / 9 % 9), step(i % 9)];
            let light = Vector3::from_fn(|c, _| shares[c] * full[c]);
            let c = m.channel_contributions(&light, &shares);
            let xyz = m.black + c.column(0) + c.column(1) + c.column(2);
            let found = m.extended_light_of(&xyz);
            let found = found.unwrap_or_else(|| panic!("{shares:?}: not solved"));
            // Far out the equations may have more than one root: any that solves them.
            let at = [0, 1, 2].map(|k| found[k] / full[k]);
            let c = m.channel_contributions(&found, &at);
            let back = m.black + c.column(0) + c.column(1) + c.column(2);
            assert!(
                (back - xyz).norm() < 1e-6 * xyz.norm(),
                "{shares:?}: {found:?}"
            );
        }
    }

    #[test]
    fn forward_then_inverse_returns_the_drive() {
        let m = srgb_like();
        for pos in [ScreenPosition::CENTRE, ScreenPosition::new(0.1, 0.9)] {
            for d in [[0.5, 0.2, 0.9], [0.01, 0.0, 0.3], [1.0, 1.0, 1.0]] {
                let xyz = m.forward(d, pos);
                let back = m.inverse(&xyz, pos).unwrap();
                assert!(!back.clipped);
                // A zero drive comes back as a drive whose excitation is at rounding
                // level (1e-18 here), so compare light as well as drives.
                let again = m.forward(back.drive, pos);
                assert!((again - xyz).norm() < 1e-9 * xyz.norm(), "{d:?} at {pos:?}");
                for c in 0..3 {
                    assert!(
                        (back.drive[c] - d[c]).abs() < 1e-6,
                        "{d:?} at {pos:?}: {back:?}"
                    );
                }
            }
        }
    }

    fn with_terms() -> MonitorModel {
        MonitorModel {
            terms: AdditivityTerms {
                interaction: Some([-0.03, -0.02, -0.05]),
                crosstalk: Some([0.04, 0.03, 0.05]),
                drive_crosstalk: None,
                chromaticity_shift: Some([[0.0, 0.5, 1.5], [0.8, 0.0, -0.4], [-1.0, 1.2, 0.0]]),
                hlg_ootf: None,
                hlg_ootf_through_laws: false,
                hlg_ootf_beyond: None,
                limiter: None,
            },
            ..srgb_like()
        }
    }

    /// A display that is BT.2100's HLG processing (OOTF on the signal, then the light
    /// re-encoded with gamma 2.2) in front of Cowan panels, which do not follow 2.2,
    /// modelled by each channel's HLG law with Cowan's term (exact for it alone): the
    /// OOTF through the laws is that display at every mixture, white included, and
    /// inverts; from the shares it misses by more than 1 %. With laws that are the
    /// nominal E_s^γ, the two forms are one.
    #[test]
    fn the_hlg_ootf_through_the_laws_follows_a_panel_that_departs_from_the_gamma() {
        let (gamma, g) = (1.2, 2.2);
        let w = chromacal_color::hdr::BT2020_LUMINANCE;
        let panels = [(2.25, 0.03), (2.20, 0.025), (2.15, 0.02)];
        let panel = |c: usize, d: f64| {
            let (a, b) = panels[c];
            let ln_d = d.ln();
            (a * ln_d + b * ln_d * ln_d).exp()
        };
        // Channel c's light, 1 at its full signal alone, at the scene lights `scene`.
        let shown = |c: usize, scene: [f64; 3]| {
            if scene[c] <= 0.0 {
                return 0.0;
            }
            let y: f64 = (0..3).map(|k| w[k] * scene[k]).sum();
            let alone_full = panel(c, w[c].powf((gamma - 1.0) / g));
            panel(c, (y.powf(gamma - 1.0) * scene[c]).powf(1.0 / g)) / alone_full
        };
        let laws = [0, 1, 2].map(|c| {
            let (a, b) = panels[c];
            let k = w[c].powf(gamma - 1.0).ln() / g;
            TransferLaw::Hlg(crate::transfer::Hlg {
                exponent: gamma / g * (a + 2.0 * b * k),
                curvature: b * (gamma / g).powi(2),
                toe: 1e-6,
            })
        });
        let model = |through_laws: bool| MonitorModel {
            matrix: Matrix3::identity(),
            black: Xyz::zeros(),
            laws: laws.clone(),
            terms: AdditivityTerms {
                hlg_ootf: Some(gamma),
                hlg_ootf_through_laws: through_laws,
                ..AdditivityTerms::default()
            },
            spatial: SpatialMap::Uniform,
        };
        let (through, shares) = (model(true), model(false));
        let p = ScreenPosition::CENTRE;
        let (mut worst_through, mut worst_shares): (f64, f64) = (0.0, 0.0);
        for drive in [
            [0.3, 0.8, 0.5],
            [0.9, 0.1, 0.0],
            [0.6; 3],
            [0.05, 0.5, 1.0],
            [1.0; 3],
        ] {
            let scene = drive.map(hlg_scene_light);
            let want = Xyz::from([0, 1, 2].map(|c| shown(c, scene)));
            let miss = |m: &MonitorModel| (m.forward(drive, p) - want).norm() / want.norm();
            worst_through = worst_through.max(miss(&through));
            worst_shares = worst_shares.max(miss(&shares));
            let back = through.inverse(&want, p).unwrap();
            assert!(back.converged, "{drive:?}: {back:?}");
            let again = through.forward(back.drive, p);
            assert!((again - want).norm() < 1e-9 * want.norm(), "{drive:?}");
        }
        assert!(worst_through < 1e-9, "{worst_through}");
        assert!(worst_shares > 0.01, "{worst_shares}");
        // The nominal laws, E_s^γ: both forms give the same gains, beyond full
        // signal too (red in white, where the OOTF drives it past its full signal
        // alone; a share above 1, as the extended inverse carries the shares on).
        let nominal = |through_laws: bool| MonitorModel {
            laws: [0, 1, 2].map(|_| {
                TransferLaw::Hlg(crate::transfer::Hlg {
                    exponent: gamma,
                    curvature: 0.0,
                    toe: 0.0,
                })
            }),
            ..model(through_laws)
        };
        for shares in [[1.0; 3], [0.2, 0.7, 0.05], [0.0, 0.4, 0.9], [1.1, 0.3, 0.0]] {
            let (a, b) = (
                nominal(true).ootf_gains(&shares),
                nominal(false).ootf_gains(&shares),
            );
            assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-9), "{a:?} {b:?}");
        }
        // It survives the model file.
        let text = toml::to_string(&through).unwrap();
        assert!(text.contains("hlg_ootf_through_laws = true"), "{text}");
        // A channel alone keeps a gain of 1 beyond full light too.
        let alone = through.ootf_gains(&[1.2, 0.0, 0.0]);
        assert!((alone[0] - 1.0).abs() < 1e-9, "{alone:?}");
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back.terms, through.terms);
        assert!(!toml::to_string(&shares).unwrap().contains("through_laws"));
        // Powers measured beyond full signal (0: blue was not measured there) are
        // kept in the file, and a channel alone beyond full light still keeps a gain
        // of 1; a power out of its range, or one without the OOTF through the laws,
        // is refused when read.
        let mut measured = through.clone();
        measured.terms.hlg_ootf_beyond = Some([1.1, 1.3, 0.0]);
        let text = toml::to_string(&measured).unwrap();
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back.terms, measured.terms);
        for share in [[1.2, 0.0, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, 1.3]] {
            let alone = measured.ootf_gains(&share);
            assert!(alone.iter().all(|g| (g - 1.0).abs() < 1e-9), "{alone:?}");
        }
        let beyond = measured.ootf_gains(&[1.0, 1.0, 1.0]);
        assert!(beyond != through.ootf_gains(&[1.0, 1.0, 1.0]), "{beyond:?}");
        for bad in ["[0.1, 1.2, 1.2]", "[1.2, nan, 1.2]", "[-1.0, 1.2, 1.2]"] {
            let text = text.replace("[1.1, 1.3, 0.0]", bad);
            assert!(toml::from_str::<MonitorModel>(&text).is_err(), "{bad}");
        }
        let mut orphan = shares.clone();
        orphan.terms.hlg_ootf_beyond = Some([1.2; 3]);
        let text = toml::to_string(&orphan).unwrap();
        assert!(toml::from_str::<MonitorModel>(&text).is_err(), "{text}");
    }

    /// The HLG OOTF (BT.2100 Table 5) as a term: a channel alone is its law's, a
    /// mixture is what the OOTF makes of the channels' scene light, and the inverse
    /// finds the drive of every colour the model makes, near white too, where the
    /// gains are largest (blue 1/0.0593^0.2 = 1.76 at γ 1.2).
    #[test]
    fn the_hlg_ootf_scales_each_channel_by_the_scene_luminance_and_inverts() {
        let plain = srgb_like();
        let gamma = 1.2;
        let m = MonitorModel {
            terms: AdditivityTerms {
                hlg_ootf: Some(gamma),
                ..AdditivityTerms::default()
            },
            spatial: SpatialMap::Uniform,
            ..srgb_like()
        };
        let p = ScreenPosition::CENTRE;
        let w = chromacal_color::hdr::BT2020_LUMINANCE;
        for c in 0..3 {
            let mut alone = [0.0; 3];
            alone[c] = 0.7;
            assert!((m.forward(alone, p) - plain.forward(alone, p)).norm() < 1e-12);
        }
        // White: each channel's light alone times (1 / w_c)^(γ − 1).
        let expected: Xyz = (0..3)
            .map(|c| plain.matrix.column(c) * (1.0 / w[c]).powf(gamma - 1.0))
            .sum::<Xyz>()
            + plain.black;
        assert!((m.white() - expected).norm() < 1e-9 * expected.norm());
        // A display that is BT.2100's HLG EOTF exactly (BT.2020 primaries, each
        // channel the HLG law with p = γ, its column the channel's light alone):
        // the model is that EOTF (chromacal-color's) at every mixture.
        let bt2020 =
            chromacal_color::gamut::AdditiveGamut::of_space(&chromacal_color::gamut::REC_2020)
                .unwrap()
                .primaries;
        let hlg = MonitorModel {
            matrix: Matrix3::from_fn(|j, c| bt2020[(j, c)] * w[c].powf(gamma - 1.0)),
            black: Xyz::zeros(),
            laws: [0, 1, 2].map(|_| {
                TransferLaw::Hlg(crate::transfer::Hlg {
                    exponent: gamma,
                    curvature: 0.0,
                    toe: 0.0,
                })
            }),
            ..m.clone()
        };
        for drive in [[0.3, 0.8, 0.5], [0.9, 0.1, 0.0], [0.6; 3], [0.05, 0.5, 1.0]] {
            let eotf = chromacal_color::hdr::hlg_eotf(drive, 1.0, 0.0, gamma);
            let want = bt2020 * nalgebra::Vector3::from(eotf);
            let got = hlg.forward(drive, p);
            assert!(
                (got - want).norm() < 1e-9 * want.norm().max(1e-9),
                "{drive:?}: {got:?} {want:?}"
            );
        }
        // The gains depend on the shares' ratios only: a grey keeps them at every level.
        let (dim, bright) = (ootf_gains(&[0.2; 3], gamma), ootf_gains(&[0.9; 3], gamma));
        assert!(
            (0..3).all(|c| (dim[c] - bright[c]).abs() < 1e-12),
            "{dim:?} {bright:?}"
        );
        // Round trips over the cube, its top corner included.
        let mut worst: f64 = 0.0;
        for r in 0..=10 {
            for g in 0..=10 {
                for b in 0..=10 {
                    let d = [r, g, b].map(|v| 0.02 + 0.98 * f64::from(v) / 10.0);
                    let back = m.inverse(&m.forward(d, p), p).unwrap();
                    assert!(back.converged && !back.clipped, "{d:?}: {back:?}");
                    let shown = m.forward(back.drive, p);
                    worst = worst.max((shown - m.forward(d, p)).norm() / m.white().norm());
                }
            }
        }
        assert!(worst < 1e-9, "{worst}");
        // It survives the model file.
        let text = toml::to_string(&m).unwrap();
        assert!(text.contains("hlg_ootf = 1.2"), "{text}");
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back.terms.hlg_ootf, Some(gamma));
    }

    #[test]
    fn the_terms_leave_each_channel_alone_at_black_and_full_drive() {
        let plain = srgb_like();
        let m = with_terms();
        for c in 0..3 {
            let mut full = [0.0; 3];
            full[c] = 1.0;
            let p = ScreenPosition::CENTRE;
            assert!((m.forward(full, p) - plain.forward(full, p)).norm() < 1e-12);
            let mut half = [0.0; 3];
            half[c] = 0.5;
            // Mid drive carries the shift: u_c ê (1 − ê).
            let shift = (m.forward(half, p) - plain.forward(half, p)).norm();
            assert!(shift > 0.05, "channel {c}: {shift}");
        }
        // White: every channel loses γ_c times the two others' full drive.
        let expected: Xyz = (0..3)
            .map(|c| plain.matrix.column(c) * (2.0 * with_terms().terms.interaction.unwrap()[c]))
            .sum();
        let white_change = m.white() - plain.white();
        assert!((white_change - expected).norm() < 1e-9, "{white_change:?}");
    }

    /// The inverse of `m` gives back `d` from its forward at `pos`, unclipped.
    fn inverse_returns(m: &MonitorModel, d: Drive, pos: ScreenPosition) {
        let back = m.inverse(&m.forward(d, pos), pos).unwrap();
        assert!(!back.clipped, "{d:?}: {back:?}");
        for c in 0..3 {
            assert!(
                (back.drive[c] - d[c]).abs() < 1e-6,
                "{d:?} at {pos:?}: {back:?}"
            );
        }
    }

    #[test]
    fn forward_then_inverse_returns_the_drive_with_terms() {
        let m = with_terms();
        for pos in [ScreenPosition::CENTRE, ScreenPosition::new(0.1, 0.9)] {
            for d in [
                [0.5, 0.2, 0.9],
                [0.01, 0.0, 0.3],
                [1.0, 1.0, 1.0],
                [0.7, 0.7, 0.7],
            ] {
                inverse_returns(&m, d, pos);
            }
        }
        let text = toml::to_string(&m).unwrap();
        assert!(
            text.contains("[terms]") && text.contains("interaction"),
            "{text}"
        );
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back, m);
        assert!(!toml::to_string(&srgb_like()).unwrap().contains("[terms]"));
    }

    #[test]
    fn crosstalk_in_drive_lifts_dim_greys_and_inverts() {
        let plain = srgb_like();
        let m = MonitorModel {
            terms: AdditivityTerms {
                drive_crosstalk: Some([0.1, 0.08, 0.12]),
                ..AdditivityTerms::default()
            },
            ..srgb_like()
        };
        let lift = |level: f64| m.forward_centre([level; 3]).y / plain.forward_centre([level; 3]).y;
        // λ_c (1 − δ_c) t_c at a grey: 2 λ d (1 − d), in drive, not in light.
        let g = 0.2;
        let alone = plain.contributions_at([g; 3]);
        let expected: f64 = (0..3)
            .map(|c| alone[(1, c)] * m.terms.drive_crosstalk.unwrap()[c])
            .sum::<f64>()
            * 2.0
            * g
            * (1.0 - g);
        let added = m.forward_centre([g; 3]).y - plain.forward_centre([g; 3]).y;
        assert!(
            (added - expected).abs() < 1e-4 * expected,
            "{added} against {expected}"
        );
        assert!(lift(0.2) > 1.02 && (m.white() - plain.white()).norm() < 1e-12);
        for pos in [ScreenPosition::CENTRE, ScreenPosition::new(0.1, 0.9)] {
            for d in [
                [0.5, 0.2, 0.9],
                [0.01, 0.0, 0.3],
                [0.002, 0.6, 0.6],
                [0.7, 0.7, 0.7],
            ] {
                inverse_returns(&m, d, pos);
            }
        }
        let text = toml::to_string(&m).unwrap();
        assert!(text.contains("drive_crosstalk"), "{text}");
        assert_eq!(toml::from_str::<MonitorModel>(&text).unwrap(), m);
    }

    #[test]
    fn crosstalk_in_drive_does_not_jump_where_a_channel_with_a_cut_off_starts() {
        // GOG with light from v₀ = 0.05 / 1.05 on: δ runs from there, not from 0.
        let gog = TransferLaw::GainOffsetGamma(crate::transfer::GainOffsetGamma {
            gain: 1.05,
            gamma: 2.4,
        });
        let m = MonitorModel {
            laws: [gog.clone(), gog.clone(), gog],
            terms: AdditivityTerms {
                drive_crosstalk: Some([0.1, 0.1, 0.1]),
                ..AdditivityTerms::default()
            },
            ..srgb_like()
        };
        let cut_off = 0.05 / 1.05;
        let below = m.forward_centre([cut_off - 1e-6, 0.5, 0.5]);
        let above = m.forward_centre([cut_off + 1e-6, 0.5, 0.5]);
        assert!(
            (above - below).norm() < 1e-6 * m.white().norm(),
            "{below:?} {above:?}"
        );
        for d in [[0.0, 0.5, 0.5], [0.02, 0.3, 0.0], [0.2, 0.6, 0.9]] {
            let back = m
                .inverse(&m.forward_centre(d), ScreenPosition::CENTRE)
                .unwrap();
            let want = m.forward_centre(d);
            let got = m.forward_centre(back.drive);
            assert!(
                (got - want).norm() < 1e-9 * m.white().norm(),
                "{d:?}: {back:?}"
            );
        }
        // Full drive is δ = 1, where the term gives nothing.
        let plain = MonitorModel {
            terms: AdditivityTerms::default(),
            ..m.clone()
        };
        assert!((m.white() - plain.white()).norm() < 1e-12);
    }

    #[test]
    fn colours_outside_the_gamut_are_flagged_and_clipped() {
        let m = srgb_like();
        let too_bright = m.white() * 1.5;
        let r = m.inverse(&too_bright, ScreenPosition::CENTRE).unwrap();
        assert!(r.clipped);
        assert!(r.drive.iter().all(|d| (0.0..=1.0).contains(d)));
        let below_black = Xyz::zeros();
        assert!(
            m.inverse(&below_black, ScreenPosition::CENTRE)
                .unwrap()
                .clipped
        );
    }

    #[test]
    fn the_file_form_names_things_and_checks_them() {
        let m = srgb_like();
        let text = toml::to_string(&m).unwrap();
        assert!(
            text.contains("[primaries]") && text.contains("[laws.red]"),
            "{text}"
        );
        let back: MonitorModel = toml::from_str(&text).unwrap();
        assert_eq!(back, m);
        let turning = text.replace("gamma = 2.2\n", "gamma = -1.0\n");
        assert_ne!(turning, text);
        let err = toml::from_str::<MonitorModel>(&turning)
            .unwrap_err()
            .to_string();
        assert!(err.contains("red law"), "{err}");
    }

    /// A field this program does not know, in a law or the spatial map (what a later
    /// version would add, as `curvature` and `toe` were added to the PQ and HLG laws),
    /// is refused by name rather than dropped: a law read without it would show other
    /// light than the profile says. Every law, and the map with one surface and with
    /// one a channel, plain and with a field added; the plain forms still read.
    #[test]
    fn a_field_a_law_or_a_surface_does_not_know_is_refused_by_name() {
        use crate::transfer::{Cowan, GainOffsetGamma, Hlg, Pq, ThreeTerm};
        let laws = [
            TransferLaw::Power(crate::transfer::Power { gamma: 2.2 }),
            TransferLaw::Cowan(Cowan {
                a: 2.2,
                b: 0.0,
                toe: 0.01,
            }),
            TransferLaw::ThreeTerm(ThreeTerm {
                a: 2.2,
                b: 0.0,
                c: 0.0,
                toe: 0.01,
            }),
            TransferLaw::GainOffsetGamma(GainOffsetGamma {
                gain: 1.0,
                gamma: 2.2,
            }),
            TransferLaw::Table(
                crate::transfer::Table::new(vec![0.0, 0.5, 1.0], vec![0.0, 0.2, 1.0]).unwrap(),
            ),
            TransferLaw::Pq(Pq {
                peak: 600.0,
                rolloff_from: 600.0,
                exponent: 1.0,
                curvature: 0.0,
                toe: 0.0,
            }),
            TransferLaw::Hlg(Hlg {
                exponent: 1.0,
                curvature: 0.0,
                toe: 0.0,
            }),
        ];
        let surface = crate::spatial::Surface {
            degree: 1,
            coefficients: vec![0.01, -0.02],
        };
        let maps = [
            crate::spatial::SpatialMap::Scalar {
                surface: surface.clone(),
            },
            crate::spatial::SpatialMap::PerChannel {
                surfaces: [surface.clone(), surface.clone(), surface],
            },
        ];
        let mut judged = 0;
        for (k, law) in laws.into_iter().enumerate() {
            let m = MonitorModel {
                laws: [law.clone(), law.clone(), law],
                spatial: maps[k % 2].clone(),
                ..srgb_like()
            };
            let text = toml::to_string(&m).unwrap();
            assert_eq!(toml::from_str::<MonitorModel>(&text).unwrap(), m, "{text}");
            for (table, what) in [
                ("[laws.green]\n", "a law"),
                ("[spatial.surface]\n", "a surface"),
                ("[[spatial.surfaces]]\n", "a channel's surface"),
                ("[spatial]\n", "the map"),
            ] {
                if !text.contains(table) {
                    continue;
                }
                judged += 1;
                let later =
                    text.replace(table, &format!("{table}knee_from_a_later_version = 0.3\n"));
                let err = toml::from_str::<MonitorModel>(&later)
                    .unwrap_err()
                    .to_string();
                assert!(
                    err.contains("knee_from_a_later_version"),
                    "{what}: {err}\n{later}"
                );
            }
        }
        // A law and a surface (or a channel's) for each of the 7 laws, the map 7 times.
        assert_eq!(judged, 21, "a table looked for was not written");
    }

    #[test]
    fn singular_primaries_are_an_error_not_a_panic() {
        let mut m = srgb_like();
        m.matrix.set_column(2, &(m.matrix.column(0) * 2.0));
        assert_eq!(
            m.inverse(&Xyz::new(1.0, 1.0, 1.0), ScreenPosition::CENTRE),
            Err(InverseError::SingularMatrix)
        );
        assert!(m.condition_number() > 1e12);
    }
}
