//! HDR signals: the Hybrid Log-Gamma of ITU-R BT.2100 and the tone mapping of ITU-R
//! BT.2390 that brings a PQ signal mastered on a bright display onto a dimmer one.
//! (The PQ itself, SMPTE ST 2084, lives with ICtCp in [`crate::ictcp`].)
//!
//! A PQ signal is absolute: code 0.58 asks for 203 cd/m² on every display. A display
//! whose peak is below the signal's mastering peak must bend the top of the curve down
//! to its own peak; BT.2390 §5.4 does it in the PQ domain with a Hermite spline above a
//! knee, leaving everything below the knee exact. HLG is relative: the signal is scene
//! light, and the display's system gamma (BT.2100 Table 5, note 5f) depends on its peak.

use crate::ictcp::{pq_eotf, pq_inverse_eotf};

/// BT.2100 Table 5, the HLG OETF's constants a, b = 1 − 4a, c = 0.5 − a ln 4a.
const HLG_A: f64 = 0.178_832_77;
const HLG_B: f64 = 0.284_668_92;
const HLG_C: f64 = 0.559_910_73;

/// BT.2100 Table 5 HLG OETF: the signal E′ in [0, 1] of normalised scene light E.
pub fn hlg_oetf(e: f64) -> f64 {
    let e = e.clamp(0.0, 1.0);
    if e <= 1.0 / 12.0 {
        (3.0 * e).sqrt()
    } else {
        HLG_A * (12.0 * e - HLG_B).ln() + HLG_C
    }
}

/// BT.2100 Table 5 HLG inverse OETF: normalised scene light E of the signal E′.
pub fn hlg_inverse_oetf(signal: f64) -> f64 {
    let s = signal.clamp(0.0, 1.0);
    if s <= 0.5 {
        s * s / 3.0
    } else {
        (((s - HLG_C) / HLG_A).exp() + HLG_B) / 12.0
    }
}

/// The room luminance (cd/m²) of BT.2100's reference viewing environment, which the
/// HLG system gamma assumes unless told otherwise.
pub const HLG_REFERENCE_AMBIENT: f64 = 5.0;

/// The scene light of HLG signal `signal`, the inverse OETF normalised to 1 at full
/// signal (which the published constants miss by 10⁻⁸).
pub fn hlg_scene_light(signal: f64) -> f64 {
    hlg_inverse_oetf(signal) / hlg_inverse_oetf(1.0)
}

/// BT.2100 Table 5 note 5f, extended as BT.2390 §6.2 recommends: the HLG system gamma
/// of a display of nominal peak `peak` cd/m² (1.2 at 1,000 cd/m², γ = 1.2 · 1.111^log₂(L_W/1000)),
/// lowered for a room brighter than the reference 5 cd/m² (−0.076 log₁₀(L_amb / 5)).
pub fn hlg_system_gamma(peak: f64, ambient: f64) -> f64 {
    let gamma = 1.2 * 1.111f64.powf((peak.max(1.0) / 1000.0).log2());
    gamma - 0.076 * (ambient.max(0.01) / HLG_REFERENCE_AMBIENT).log10()
}

/// BT.2100 Table 5 HLG EOTF on the grey axis (R = G = B, so the OOTF's luminance is the
/// channel's): the displayed luminance of signal `signal`, cd/m², on a display of
/// nominal peak `white` and black `black`, for system gamma `gamma`. The black enters
/// as BT.2100 has it, in the signal: E = OETF⁻¹(max(0, (1 − β) E′ + β)) with
/// β = √(3 (L_B / L_W)^(1/γ)), and F_D = L_W · E^γ, so signal 0 shows L_B and 1 shows
/// L_W (to the constants' digits: E is divided by its value at 1).
pub fn hlg_eotf_grey(signal: f64, white: f64, black: f64, gamma: f64) -> f64 {
    hlg_eotf([signal; 3], white, black, gamma)[1]
}

/// BT.2020's luminance weights of linear R, G, B (BT.2100 Table 5's Y_S).
pub const BT2020_LUMINANCE: [f64; 3] = [0.2627, 0.6780, 0.0593];

/// BT.2100 Table 5 HLG EOTF of a BT.2020 R′G′B′ signal: each channel's scene light
/// E = OETF⁻¹(max(0, (1 − β) E′ + β)) (β lifting the display's black `black`), then
/// the OOTF F_D = L_W · Y_S^(γ−1) · E, the system gamma acting on the scene's
/// luminance Y_S so that hues keep their ratios. Linear R, G, B in cd/m² of a display
/// of nominal peak `white`.
pub fn hlg_eotf(signal: [f64; 3], white: f64, black: f64, gamma: f64) -> [f64; 3] {
    let beta = (3.0 * (black.max(0.0) / white).powf(1.0 / gamma)).sqrt();
    let scene = signal.map(|e| hlg_scene_light(((1.0 - beta) * e.clamp(0.0, 1.0) + beta).max(0.0)));
    let luminance: f64 = (0..3).map(|c| BT2020_LUMINANCE[c] * scene[c]).sum();
    if !(luminance > 0.0) {
        return [0.0; 3];
    }
    let ootf = white * luminance.powf(gamma - 1.0);
    scene.map(|e| ootf * e)
}

/// The mapping of ITU-R BT.2390-10 §5.4.1 (the EETF) from a PQ signal mastered on a
/// display of `mastering_peak` cd/m² (and black 0) to a display of peak
/// `display_peak` and black `display_black` cd/m²: the luminance the display should
/// show for `signal`. Below the knee it is the PQ itself; above, a Hermite spline
/// meets the display's peak with slope 0 at the mastering peak. A display at least as
/// bright as the mastering peak shows the PQ as it is, up to the mastering peak.
pub fn bt2390_eetf(signal: f64, mastering_peak: f64, display_peak: f64, display_black: f64) -> f64 {
    // §5.4.1 eq. (5): the source's range normalised (source black 0, so PQ(0) is the
    // bottom only through its own value).
    let source_top = pq_inverse_eotf(mastering_peak);
    let source_bottom = pq_inverse_eotf(0.0);
    let span = source_top - source_bottom;
    if !(span > 0.0) {
        return display_black;
    }
    let e1 = ((signal - source_bottom) / span).clamp(0.0, 1.0);
    let min_lum = (pq_inverse_eotf(display_black) - source_bottom) / span;
    let max_lum = ((pq_inverse_eotf(display_peak) - source_bottom) / span).min(1.0);
    // Eq. (6): the knee, and the spline above it.
    let knee = 1.5 * max_lum - 0.5;
    let e2 = if e1 < knee || knee >= 1.0 {
        e1
    } else {
        let t = (e1 - knee) / (1.0 - knee);
        let (t2, t3) = (t * t, t * t * t);
        (2.0 * t3 - 3.0 * t2 + 1.0) * knee
            + (t3 - 2.0 * t2 + t) * (1.0 - knee)
            + (-2.0 * t3 + 3.0 * t2) * max_lum
    };
    // Eq. (7): the black lifted to the display's, fading out by mid-range.
    let e3 = e2 + min_lum.max(0.0) * (1.0 - e2).max(0.0).powi(4);
    pq_eotf(e3 * span + source_bottom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hlg_round_trips_and_meets_its_reference_points() {
        // BT.2100: E = 1/12 gives E′ = 0.5, E = 1 gives E′ = 1 (to the constants' digits).
        assert!((hlg_oetf(1.0 / 12.0) - 0.5).abs() < 1e-12);
        assert!((hlg_oetf(1.0) - 1.0).abs() < 1e-7);
        for e in [0.0, 0.001, 0.05, 1.0 / 12.0, 0.3, 0.9] {
            assert!((hlg_inverse_oetf(hlg_oetf(e)) - e).abs() < 1e-12, "{e}");
        }
        // The curve is continuous at its knee.
        let below = hlg_inverse_oetf(0.5 - 1e-9);
        let above = hlg_inverse_oetf(0.5 + 1e-9);
        assert!((below - above).abs() < 1e-8);
    }

    #[test]
    fn the_hlg_eotf_shows_the_display_s_black_at_0_and_its_peak_at_1() {
        let (white, black, gamma) = (1000.0, 0.25, 1.2);
        assert!((hlg_eotf_grey(0.0, white, black, gamma) / black - 1.0).abs() < 1e-6);
        assert!((hlg_eotf_grey(1.0, white, black, gamma) / white - 1.0).abs() < 1e-6);
        // With no black, signal 0.5 is scene light 1/12 through the system gamma.
        let mid = hlg_eotf_grey(0.5, white, 0.0, gamma);
        assert!((mid / (white * (1.0f64 / 12.0).powf(gamma)) - 1.0).abs() < 1e-7);
        // The black lifts the low signals more than linear light would (BT.2100's β).
        let low = hlg_eotf_grey(0.1, white, black, gamma);
        let linear = black + (white - black) * (hlg_eotf_grey(0.1, white, 0.0, gamma) / white);
        assert!(low > 1.5 * linear, "{low} {linear}");
    }

    #[test]
    fn the_hlg_ootf_keeps_a_colour_s_channel_ratios() {
        let (white, gamma) = (1000.0, 1.2);
        let rgb = hlg_eotf([0.7, 0.4, 0.2], white, 0.0, gamma);
        let scene = [0.7, 0.4, 0.2].map(hlg_inverse_oetf);
        assert!((rgb[0] / rgb[2] - scene[0] / scene[2]).abs() < 1e-9);
        // The luminance goes through the system gamma, not each channel.
        let y = |v: [f64; 3]| (0..3).map(|c| BT2020_LUMINANCE[c] * v[c]).sum::<f64>();
        assert!((y(rgb) / (white * y(scene).powf(gamma)) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_hlg_system_gamma_is_1_2_at_1000_nits_and_grows_with_the_peak() {
        assert!((hlg_system_gamma(1000.0, 5.0) - 1.2).abs() < 1e-12);
        // 1.04 at 400 cd/m² by BT.2390's extension of BT.2100 note 5f.
        let g400 = hlg_system_gamma(400.0, 5.0);
        assert!(g400 > 1.0 && g400 < 1.1, "{g400}");
        assert!(hlg_system_gamma(2000.0, 5.0) > 1.3);
        // A brighter room lowers it.
        assert!(hlg_system_gamma(1000.0, 50.0) < 1.2 - 0.07);
    }

    #[test]
    fn the_eetf_is_the_pq_below_its_knee_and_meets_the_peak_smoothly() {
        let (mastering, peak) = (4000.0, 600.0);
        // Well below the knee the display shows exactly what the signal asks.
        for nits in [0.01, 1.0, 100.0, 200.0] {
            let s = pq_inverse_eotf(nits);
            assert!((bt2390_eetf(s, mastering, peak, 0.0) / nits - 1.0).abs() < 1e-9);
        }
        // The mastering peak lands on the display's peak, and nothing passes it.
        let top = bt2390_eetf(pq_inverse_eotf(mastering), mastering, peak, 0.0);
        assert!((top / peak - 1.0).abs() < 1e-9, "{top}");
        let mut last = 0.0;
        for k in 0..=1000 {
            let y = bt2390_eetf(k as f64 / 1000.0, mastering, peak, 0.0);
            assert!(y >= last - 1e-12 && y <= peak * (1.0 + 1e-9), "{k}: {y}");
            last = y;
        }
        // A display brighter than the mastering peak is not tone-mapped.
        let s = pq_inverse_eotf(900.0);
        assert!((bt2390_eetf(s, 1000.0, 1500.0, 0.0) / 900.0 - 1.0).abs() < 1e-9);
        // A display black lifts the bottom to it.
        let black = bt2390_eetf(0.0, mastering, peak, 0.05);
        assert!((black / 0.05 - 1.0).abs() < 0.02, "{black}");
    }
}
