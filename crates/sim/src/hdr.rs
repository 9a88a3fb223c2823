//! What an HDR display does between the signal and its panel, and the limits of its
//! power supply: the physics the `hdr-oled` and `hdr-lcd` presets add to a virtual
//! monitor.
//!
//! * **Signal processing.** In its PQ mode (HDR10) a display decodes each channel's
//!   code as PQ (SMPTE ST 2084), absolute cd/m², rolls the top off to its own peak as
//!   BT.2390's EETF does from the mastering peak it assumes, clips what falls below
//!   its darkest controllable level to black, and drives the panel through the
//!   inverse of the panel's nominal gamma. In its HLG mode it applies BT.2100's HLG
//!   EOTF instead: each channel's scene light from the inverse OETF, then the OOTF,
//!   which scales all three by the scene luminance to the power γ − 1 (the system
//!   gamma of the display's peak): a channel's light depends on the other two, so
//!   the display is not additive channel by channel. The panel's real transfer (a
//!   law or a measured table) then makes the light, so its departures from the
//!   nominal gamma are the tracking error a calibration has to find.
//! * **Automatic brightness limiting (ABL).** An OLED's supply (and an LCD's backlight
//!   budget) limits the light the whole screen may emit: with the screen's average
//!   light p (cd/m², the average picture level times the peak) every emitter's light
//!   is scaled by g(p) = (F / p) · tanh((p / F)^k)^(1/k), 1 for small windows and
//!   F / p for a full field, F being the full-field white: the screen's light is
//!   held below F with a knee of sharpness k. (The model's limiter term,
//!   `fit::limiter`, is another family with the same limits, so that fitting it
//!   here tests more than the optimiser.) The limiter follows a change of the picture
//!   with a time constant, as the supply's control loop does.
//! * **Global dimming (LCD).** The backlight follows the brightest content on the
//!   screen, down to a floor; the panel's leakage (its black) scales with it, so a
//!   black patch on a black screen is darker than the black beside a bright window.

use serde::{Deserialize, Serialize};

use chromacal_color::hdr::{HLG_REFERENCE_AMBIENT, bt2390_eetf, hlg_eotf, hlg_system_gamma};
use chromacal_color::ictcp::pq_eotf;
use chromacal_model::plan::Signal;

/// An HDR display's processing and limits (`[monitor.hdr]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HdrBehaviour {
    /// The signal the display decodes: `pq` (its HDR10 mode) or `hlg`. A display is
    /// put in one mode or the other by the signal's metadata or its menu; a simulated
    /// rig puts it in the mode of the run's `plan.signal`.
    #[serde(default = "pq_mode")]
    pub decodes: Signal,
    /// The mastering peak (cd/m²) the display's tone mapping assumes: it rolls PQ
    /// signals off from there to its own peak (the monitor's `white_luminance`).
    pub rolloff_from: f64,
    /// The panel gamma the processing inverts to drive the panel.
    pub panel_gamma: f64,
    /// Below this luminance (cd/m²) the display shows its black.
    pub black_clip: f64,
    /// The brightness limiter, if the display has one.
    pub abl: Option<Abl>,
    /// Global dimming: the lowest backlight level (fraction of full), if the display
    /// dims its backlight with the content.
    pub global_dimming_floor: Option<f64>,
}

/// The mode a display decodes in when its config does not say.
fn pq_mode() -> Signal {
    Signal::Pq
}

/// Automatic brightness limiting: g(p) = (F / p) · tanh((p / F)^k)^(1/k) of the
/// screen's mean light p.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Abl {
    /// F: the full-field white, cd/m².
    pub full_field: f64,
    /// k: how sharply the limiter sets in (large: a hard knee).
    pub sharpness: f64,
    /// τ: seconds the limiter takes to follow a change of the picture.
    pub time_constant_s: f64,
}

impl HdrBehaviour {
    /// Check the numbers make a display.
    pub fn check(&self, peak: f64) -> Result<(), String> {
        let finite = [
            self.rolloff_from,
            self.panel_gamma,
            self.black_clip,
            self.global_dimming_floor.unwrap_or(0.5),
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite {
            return Err("hdr: every number must be finite".into());
        }
        if !self.decodes.is_hdr() {
            return Err("hdr.decodes must be \"pq\" or \"hlg\"".into());
        }
        if !(self.rolloff_from >= peak && self.rolloff_from <= 10_000.0) {
            return Err(format!(
                "hdr.rolloff_from must be from the peak ({peak}) to 10000 cd/m², not {}",
                self.rolloff_from
            ));
        }
        if !(1.0..=4.0).contains(&self.panel_gamma) {
            return Err("hdr.panel_gamma must be 1 to 4".into());
        }
        if !(0.0..peak).contains(&self.black_clip) {
            return Err("hdr.black_clip must be from 0 to below the peak".into());
        }
        if let Some(f) = self.global_dimming_floor
            && !(0.0 < f && f <= 1.0)
        {
            return Err("hdr.global_dimming_floor must be in (0, 1]".into());
        }
        if let Some(abl) = &self.abl
            && !(abl.full_field > 0.0
                && abl.full_field <= peak
                && abl.sharpness >= 1.0
                && abl.sharpness <= 50.0
                && abl.time_constant_s >= 0.0
                && abl.time_constant_s.is_finite())
        {
            return Err(format!(
                "hdr.abl: full_field must be in (0, peak = {peak}], sharpness 1 to 50, time_constant_s not negative"
            ));
        }
        Ok(())
    }

    /// The panel drives (before the panel's own transfer) for the codes `signal` of
    /// the three channels on a display of peak `peak` cd/m²: PQ channel by channel,
    /// HLG through its OOTF, which couples them.
    pub fn panel_drives(&self, signal: [f64; 3], peak: f64) -> [f64; 3] {
        match self.decodes {
            Signal::Hlg => {
                // BT.2100's HLG EOTF for this peak, black 0 (the panel's own black is
                // added after it, as the PQ mode's is).
                let gamma = hlg_system_gamma(peak, HLG_REFERENCE_AMBIENT);
                hlg_eotf(signal, peak, 0.0, gamma).map(|nits| self.panel_drive_of_light(nits, peak))
            }
            _ => signal.map(|v| self.panel_drive(v, peak)),
        }
    }

    /// The panel drive for light `nits` cd/m² asked of it: black below the clip, else
    /// through the inverse of the panel's nominal gamma.
    fn panel_drive_of_light(&self, nits: f64, peak: f64) -> f64 {
        if nits < self.black_clip {
            return 0.0;
        }
        (nits / peak).clamp(0.0, 1.0).powf(1.0 / self.panel_gamma)
    }

    /// The panel drive (before the panel's own transfer) for PQ code `signal` on a
    /// display of peak `peak` cd/m².
    pub fn panel_drive(&self, signal: f64, peak: f64) -> f64 {
        let nits = if self.rolloff_from > peak {
            bt2390_eetf(signal, self.rolloff_from, peak, 0.0)
        } else {
            pq_eotf(signal).min(peak)
        };
        self.panel_drive_of_light(nits, peak)
    }

    /// The limiter's gain on every emitter for a screen whose mean light is
    /// `mean_light` cd/m² (1 without a limiter).
    pub fn abl_gain(&self, mean_light: f64) -> f64 {
        match &self.abl {
            Some(abl) => {
                // (F/p) tanh(y)^(1/k) = (tanh(y) / y)^(1/k) with y = (p/F)^k, which
                // stays 1 where y underflows.
                let k = abl.sharpness;
                let y = (mean_light.max(0.0) / abl.full_field).powf(k);
                if y < 1e-12 {
                    return 1.0;
                }
                (y.tanh() / y).powf(1.0 / k)
            }
            None => 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_color::ictcp::pq_inverse_eotf;

    fn oled() -> HdrBehaviour {
        HdrBehaviour {
            decodes: Signal::Pq,
            rolloff_from: 4000.0,
            panel_gamma: 2.2,
            black_clip: 0.0,
            abl: Some(Abl {
                full_field: 180.0,
                sharpness: 4.0,
                time_constant_s: 2.0,
            }),
            global_dimming_floor: None,
        }
    }

    #[test]
    fn the_panel_follows_the_pq_below_its_knee_and_reaches_its_peak() {
        let hdr = oled();
        let peak = 800.0;
        for nits in [0.1, 10.0, 100.0, 300.0] {
            let u = hdr.panel_drive(pq_inverse_eotf(nits), peak);
            assert!(
                (u.powf(2.2) * peak / nits - 1.0).abs() < 1e-6,
                "{nits}: {u}"
            );
        }
        assert!((hdr.panel_drive(1.0, peak) - 1.0).abs() < 1e-9);
        let clipped = HdrBehaviour {
            black_clip: 0.05,
            ..oled()
        };
        assert_eq!(clipped.panel_drive(pq_inverse_eotf(0.04), peak), 0.0);
        assert!(clipped.panel_drive(pq_inverse_eotf(0.06), peak) > 0.0);
    }

    #[test]
    fn in_its_hlg_mode_the_panel_follows_bt2100_s_eotf_and_its_ootf_couples_the_channels() {
        let hdr = HdrBehaviour {
            decodes: Signal::Hlg,
            ..oled()
        };
        let peak = 800.0;
        let gamma = hlg_system_gamma(peak, HLG_REFERENCE_AMBIENT);
        assert!((gamma - 1.2 * 1.111f64.powf((0.8f64).log2())).abs() < 1e-12);
        // A grey asks for BT.2100's luminance of its signal: 75 % HLG is about a
        // fifth of the peak on an 800 cd/m² display (γ 1.16), 100 % the peak.
        for signal in [0.1, 0.5, 0.75, 1.0] {
            let asked = chromacal_color::hdr::hlg_eotf_grey(signal, peak, 0.0, gamma);
            let u = hdr.panel_drives([signal; 3], peak);
            for v in u {
                assert!(
                    (v.powf(2.2) * peak / asked - 1.0).abs() < 1e-9,
                    "{signal}: {u:?}"
                );
            }
        }
        let grey = hdr
            .panel_drives([0.75; 3], peak)
            .map(|u| u.powf(2.2) * peak);
        assert!((grey[1] / peak - 0.2).abs() < 0.03, "{grey:?}");
        // A channel alone gets less light than it has in the grey: the OOTF scales
        // it by the scene's luminance, which is the channel's weight of the grey's,
        // to the power γ − 1. So the display is not the sum of its channels.
        for (c, weight) in chromacal_color::hdr::BT2020_LUMINANCE
            .into_iter()
            .enumerate()
        {
            let mut alone = [0.0; 3];
            alone[c] = 0.75;
            let light = hdr.panel_drives(alone, peak).map(|u| u.powf(2.2) * peak);
            let ratio = light[c] / grey[c];
            assert!(
                (ratio / weight.powf(gamma - 1.0) - 1.0).abs() < 1e-9,
                "{c}: {ratio}"
            );
            assert!(ratio < 0.95, "{c}: {ratio}");
        }
        // The PQ mode is per channel, as before.
        let pq = oled().panel_drives([0.75, 0.0, 0.0], peak);
        assert_eq!(pq[0], oled().panel_drive(0.75, peak));
        assert_eq!(pq[1], 0.0);
        // An SDR "mode" is no HDR mode.
        let sdr = HdrBehaviour {
            decodes: Signal::Sdr,
            ..oled()
        };
        assert!(sdr.check(peak).unwrap_err().contains("decodes"));
    }

    #[test]
    fn the_limiter_spares_small_windows_and_holds_a_full_field_to_its_white() {
        let hdr = oled();
        let peak = 800.0;
        // A 10 % window of white: within 1 % of the peak.
        assert!(hdr.abl_gain(0.1 * peak) > 0.99);
        // A full field of white: the full-field white, within 1 %.
        let full = peak * hdr.abl_gain(peak);
        assert!((full / 180.0 - 1.0).abs() < 0.01, "{full}");
        assert_eq!(
            HdrBehaviour {
                abl: None,
                ..oled()
            }
            .abl_gain(peak),
            1.0
        );
        // A dim screen is not limited, however sharp the knee (no underflow to 0).
        let sharp = HdrBehaviour {
            abl: Some(Abl {
                sharpness: 50.0,
                ..oled().abl.unwrap()
            }),
            ..oled()
        };
        assert_eq!(sharp.abl_gain(1e-6), 1.0);
        assert!(oled().check(peak).is_ok());
        assert!(oled().check(5000.0).is_err(), "a roll-off below the peak");
    }
}
