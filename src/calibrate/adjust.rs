//! Adjusting the monitor's own controls before calibrating, as dispcal's and
//! DisplayCAL's adjustment step does: the video LUT then has less to do, and fewer
//! codes are lost to it (an 8-bit LUT that takes a white 15 % down in blue bands).
//!
//! The primaries are read once (red, green, blue and black at full drive), which gives
//! the matrix that turns a white's XYZ into the share of each channel in it. Then the
//! white is read again and again: the channel shares the target white needs over the
//! ones measured are the change of light each channel's gain must make, with the
//! white's luminance held (the shares' changes weighted by each channel's luminance
//! sum to none); and the target's luminance over the white's, once balanced, is the
//! change the brightness must make. The user moves the controls that way until the
//! readout says the white is on target (or presses Enter, which ends the step).

use nalgebra::Matrix3;
use serde::Serialize;

use chromacal_color::spaces::xyz_to_xyy;
use chromacal_color::temperature::xyz_to_cct_duv;
use chromacal_color::{Xyz, delta_e_2000, xyz_to_lab};
use chromacal_display::PatchDisplay;
use chromacal_instruments::Instrument;
use chromacal_model::screen::{Codes, Geometry, Patch};

/// What the adjustment aims at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjustTarget {
    /// CIE 1931 xy of the white.
    pub white_xy: [f64; 2],
    /// cd/m²; `None`: as bright as the monitor is.
    pub luminance: Option<f64>,
}

/// The display's primaries at full drive, above its black: the columns of the matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Primaries {
    pub matrix: Matrix3<f64>,
    pub black: Xyz,
}

/// One reading of the white and what to do about it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Advice {
    pub white: [f64; 3],
    pub luminance: f64,
    pub xy: [f64; 2],
    pub cct_k: Option<f64>,
    pub duv: Option<f64>,
    /// ΔE00 to the target white (at the target luminance, or at the white's own).
    pub delta_e00: f64,
    /// The change of light each of the red, green and blue gains must make, as
    /// factors (1.05: up 5 %), with the luminance held.
    pub gains: [f64; 3],
    /// The change of light the brightness must make, once the gains are set.
    pub brightness: f64,
    /// Within the step a reading can tell: ΔE00 under `tolerance` and the luminance
    /// within its share of it.
    pub on_target: bool,
    pub tolerance: f64,
}

/// Why the adjustment could not go on.
#[derive(Debug, thiserror::Error)]
pub enum AdjustError {
    #[error(transparent)]
    Display(#[from] chromacal_display::DisplayError),
    #[error("the instrument: {0}")]
    Instrument(#[from] chromacal_instruments::InstrumentError),
    #[error(
        "the instrument gave no XYZ for the {0}: adjusting needs a colorimeter or spectroradiometer"
    )]
    NoXyz(&'static str),
    #[error("the primaries read are not independent (is the instrument aimed at the patch?)")]
    Singular,
}

fn patch(drive: [f64; 3], bits: u32) -> Patch {
    Patch {
        codes: Codes::from_drive(drive, bits),
        background: Codes::from_drive([0.0; 3], bits),
        geometry: Geometry::centred(0.2),
    }
}

async fn read<D: PatchDisplay, I: Instrument>(
    display: &mut D,
    instrument: &mut I,
    drive: [f64; 3],
    bits: u32,
    what: &'static str,
) -> Result<Xyz, AdjustError> {
    display.show(&patch(drive, bits)).await?;
    let reading = instrument.measure().await?;
    reading
        .xyz
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .ok_or(AdjustError::NoXyz(what))
}

/// Read black and the three primaries at full drive.
pub async fn measure_primaries<D: PatchDisplay, I: Instrument>(
    display: &mut D,
    instrument: &mut I,
    bits: u32,
) -> Result<Primaries, AdjustError> {
    let black = read(display, instrument, [0.0; 3], bits, "black").await?;
    let mut columns = [Xyz::zeros(); 3];
    for (c, name) in ["red", "green", "blue"].into_iter().enumerate() {
        let mut drive = [0.0; 3];
        drive[c] = 1.0;
        columns[c] = read(display, instrument, drive, bits, name).await? - black;
    }
    let matrix = Matrix3::from_columns(&columns);
    matrix.try_inverse().ok_or(AdjustError::Singular)?;
    Ok(Primaries { matrix, black })
}

/// The advice for a white reading `measured`, with `noise` the relative scatter of
/// one reading (the on-target tolerance is what that scatter moves the white by).
pub fn advise(primaries: &Primaries, measured: &Xyz, target: &AdjustTarget, noise: f64) -> Advice {
    let xyy = xyz_to_xyy(measured, target.white_xy);
    let luminance = target.luminance.unwrap_or(measured.y);
    let [x, y] = target.white_xy;
    let target_xyz = Xyz::new(x / y * luminance, luminance, (1.0 - x - y) / y * luminance);
    let lab = |v: &Xyz| xyz_to_lab(v, &target_xyz);
    let delta_e00 = delta_e_2000(&lab(measured), &lab(&target_xyz));
    let inverse = primaries
        .matrix
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    let shares = inverse * (measured - primaries.black);
    let needed = inverse * (target_xyz - primaries.black);
    // The change of each channel's light toward the target's chromaticity, scaled so
    // that the white's luminance stays; the brightness then takes it to the target's.
    let raw = [0, 1, 2].map(|c| {
        let r = needed[c] / shares[c];
        if r.is_finite() && r > 0.0 { r } else { 1.0 }
    });
    let y_of = |f: [f64; 3]| -> f64 {
        (0..3)
            .map(|c| primaries.matrix[(1, c)] * shares[c] * f[c])
            .sum()
    };
    let keep = y_of([1.0; 3]) / y_of(raw);
    let gains = raw.map(|r| if keep.is_finite() { r * keep } else { 1.0 });
    let brightness = match target.luminance {
        Some(l) if measured.y > primaries.black.y => {
            (l - primaries.black.y) / (measured.y - primaries.black.y)
        }
        _ => 1.0,
    };
    // A reading's chromaticity scatters by about 0.1 ΔE00 at a relative noise of
    // 0.3 %: on target within half again that, never asking for less than 0.15.
    let tolerance = (50.0 * noise).max(0.15);
    let temperature = xyz_to_cct_duv(measured);
    Advice {
        white: (*measured).into(),
        luminance: measured.y,
        xy: [xyy.x, xyy.y],
        cct_k: temperature.map(|t| t.cct_k),
        duv: temperature.map(|t| t.duv),
        delta_e00,
        gains,
        brightness,
        on_target: delta_e00 <= tolerance,
        tolerance,
    }
}

/// How the white is read and judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Readout {
    pub primaries: Primaries,
    pub target: AdjustTarget,
    /// Bits of the codes sent.
    pub bits: u32,
    /// The relative scatter of one reading.
    pub noise: f64,
}

/// Read the white until `done()` says to stop, calling `report` with the advice for
/// each reading; the last advice.
pub async fn adjust_white<D: PatchDisplay, I: Instrument>(
    display: &mut D,
    instrument: &mut I,
    readout: &Readout,
    done: &(dyn Fn() -> bool + Send + Sync),
    report: &mut (dyn FnMut(&Advice) + Send),
) -> Result<Advice, AdjustError> {
    loop {
        let white = read(display, instrument, [1.0; 3], readout.bits, "white").await?;
        let advice = advise(&readout.primaries, &white, &readout.target, readout.noise);
        report(&advice);
        if done() {
            let _ = display.blank().await;
            return Ok(advice);
        }
    }
}

/// In words: which control to move which way, the larger changes first.
pub fn describe(advice: &Advice) -> String {
    let mut moves: Vec<(f64, String)> = Vec::new();
    let percent = |f: f64| 100.0 * (f - 1.0);
    for (name, factor) in ["red", "green", "blue"].into_iter().zip(advice.gains) {
        let p = percent(factor);
        if p.abs() >= 0.5 {
            moves.push((
                p.abs(),
                format!(
                    "{name} gain {} {:.0} %",
                    if p > 0.0 { "up" } else { "down" },
                    p.abs()
                ),
            ));
        }
    }
    let p = percent(advice.brightness);
    if p.abs() >= 0.5 {
        moves.push((
            p.abs(),
            format!(
                "brightness {} {:.0} %",
                if p > 0.0 { "up" } else { "down" },
                p.abs()
            ),
        ));
    }
    moves.sort_by(|a, b| b.0.total_cmp(&a.0));
    let todo: Vec<String> = moves.into_iter().map(|m| m.1).collect();
    format!(
        "white {:.2} cd/m², x {:.4} y {:.4}, {}, Duv {}: ΔE00 {:.2} to the target — {}",
        advice.luminance,
        advice.xy[0],
        advice.xy[1],
        advice.cct_k.map_or("–".into(), |k| format!("{k:.0} K")),
        advice.duv.map_or("–".into(), |d| format!("{d:+.4}")),
        advice.delta_e00,
        if advice.on_target || todo.is_empty() {
            "on target: press Enter".to_string()
        } else {
            todo.join(", ")
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// sRGB-like primaries summing to D65 at 100 cd/m², no black.
    fn primaries() -> Primaries {
        let matrix = Matrix3::new(
            41.24, 35.76, 18.05, //
            21.26, 71.52, 7.22, //
            1.93, 11.92, 95.05,
        );
        Primaries {
            matrix,
            black: Xyz::zeros(),
        }
    }

    #[test]
    fn the_advice_undoes_a_gain_and_a_brightness() {
        let p = primaries();
        let target = AdjustTarget {
            white_xy: [0.3127, 0.3290],
            luminance: Some(80.0),
        };
        // Blue 10 % too strong, everything 20 % too bright.
        let measured = p.matrix * nalgebra::Vector3::new(1.0, 1.0, 1.1) * 1.2;
        let advice = advise(&p, &measured, &target, 0.002);
        assert!(!advice.on_target);
        // Applying it lands on the target.
        let shares = nalgebra::Vector3::new(1.0, 1.0, 1.1) * 1.2;
        let after = p.matrix
            * nalgebra::Vector3::from_iterator((0..3).map(|c| shares[c] * advice.gains[c]))
            * advice.brightness;
        let again = advise(&p, &after, &target, 0.002);
        assert!(again.on_target && again.delta_e00 < 0.01, "{again:?}");
        assert!((again.luminance - 80.0).abs() < 0.01);
        assert!(
            describe(&advice).contains("blue gain down"),
            "{}",
            describe(&advice)
        );
        assert!(describe(&again).contains("on target"));
    }
}
