//! ArgyllCMS `.cal` calibration curves (CGATS; ArgyllCMS `doc/cal_format.html`): one
//! `CAL` table, fields `RGB_I RGB_R RGB_G RGB_B`, all in 0..1, 256 rows at inputs
//! i/255, the values never video-encoded (0 is the device's minimum).

use chromacal_model::target::{CURVE_ENTRIES, CalibrationCurves};

/// The `.cal` text of `curves`; `created` is the CREATED keyword's text.
pub fn cal_text(curves: &CalibrationCurves, created: &str) -> String {
    let keywords = format!(
        "TARGET_WHITE_XYZ \"{:.6} {:.6} {:.6}\"\nTARGET_DESCRIPTION \"{}\"\n",
        curves.white[0],
        curves.white[1],
        curves.white[2],
        curves.describe()
    );
    // Resampled, so that curves of another length read from a profile file cannot
    // index past their end (for chromacal's own curves this is the identity).
    cal_document(&keywords, created, |x| curves.apply([x; 3]))
}

/// The `.cal` text of curves given as a function of the input (a video LUT read back
/// from the card), with `description` as the target's.
pub fn curves_cal_text(at: impl Fn(f64) -> [f64; 3], description: &str, created: &str) -> String {
    cal_document(
        &format!("TARGET_DESCRIPTION \"{description}\"\n"),
        created,
        at,
    )
}

/// A `.cal` document: the fixed keywords, `keywords`, and 256 rows of `at`.
fn cal_document(keywords: &str, created: &str, at: impl Fn(f64) -> [f64; 3]) -> String {
    let mut out = String::from("CAL    \n\n");
    out += "DESCRIPTOR \"Argyll Device Calibration State\"\n";
    out += &format!("ORIGINATOR \"chromacal {}\"\n", env!("CARGO_PKG_VERSION"));
    out += &format!("CREATED \"{created}\"\n");
    out += "DEVICE_CLASS \"DISPLAY\"\nCOLOR_REP \"RGB\"\n";
    // No TV_OUTPUT_ENCODING: "NO" is what its absence means, and ArgyllCMS (xcal.c)
    // finds that keyword in the table it reads but takes its value from the file's
    // first table, so in a .ti3 with this table appended colprof reads past the
    // readings' keywords (and crashed on ours).
    out += "VIDEO_LUT_CALIBRATION_POSSIBLE \"YES\"\n";
    out += keywords;
    out += "\nNUMBER_OF_FIELDS 4\nBEGIN_DATA_FORMAT\nRGB_I RGB_R RGB_G RGB_B\nEND_DATA_FORMAT\n\n";
    out += &format!("NUMBER_OF_SETS {CURVE_ENTRIES}\nBEGIN_DATA\n");
    for i in 0..CURVE_ENTRIES {
        let x = i as f64 / (CURVE_ENTRIES - 1) as f64;
        let [r, g, b] = at(x);
        out += &format!("{x:.7} {r:.7} {g:.7} {b:.7}\n");
    }
    out += "END_DATA\n";
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::target::{Target, ToneCurve, WhiteTarget};

    #[test]
    fn curves_of_another_length_are_resampled_to_256_rows() {
        // As a hand-edited profile might hold them.
        let ramp = vec![0.0, 0.25, 0.5, 0.75, 1.0];
        let curves = CalibrationCurves {
            target: Target {
                white: WhiteTarget::Native,
                tone: ToneCurve::Power(2.2),
                luminance: None,
            },
            curves: [ramp.clone(), ramp.clone(), ramp],
            white: [95.0, 100.0, 108.0],
            black: [0.1, 0.1, 0.1],
            luminance_limited: false,
            predicted_white_de00: 0.0,
            predicted_tone_error: 0.0,
            predicted_grey_de00: 0.0,
        };
        let text = cal_text(&curves, "now");
        let rows: Vec<&str> = text
            .lines()
            .skip_while(|l| *l != "BEGIN_DATA")
            .skip(1)
            .take_while(|l| *l != "END_DATA")
            .collect();
        assert_eq!(rows.len(), CURVE_ENTRIES);
        assert_eq!(rows[128], "0.5019608 0.5019608 0.5019608 0.5019608");
    }
}
