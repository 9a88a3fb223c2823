//! ArgyllCMS `.cal` calibration curves (CGATS; ArgyllCMS `doc/cal_format.html`): one
//! `CAL` table, fields `RGB_I RGB_R RGB_G RGB_B`, all in 0..1, 256 rows at inputs
//! i/255, the values never video-encoded (0 is the device's minimum).

use crate::model::target::{CURVE_ENTRIES, CalibrationCurves};

/// The `.cal` text of `curves`; `created` is the CREATED keyword's text.
pub fn cal_text(curves: &CalibrationCurves, created: &str) -> String {
    let mut out = String::from("CAL    \n\n");
    out += "DESCRIPTOR \"Argyll Device Calibration State\"\n";
    out += &format!("ORIGINATOR \"chromacal {}\"\n", env!("CARGO_PKG_VERSION"));
    out += &format!("CREATED \"{created}\"\n");
    out += "DEVICE_CLASS \"DISPLAY\"\nCOLOR_REP \"RGB\"\n";
    out += "VIDEO_LUT_CALIBRATION_POSSIBLE \"YES\"\nTV_OUTPUT_ENCODING \"NO\"\n";
    out += &format!(
        "TARGET_WHITE_XYZ \"{:.6} {:.6} {:.6}\"\n",
        curves.white[0], curves.white[1], curves.white[2]
    );
    out += &format!("TARGET_DESCRIPTION \"{}\"\n", curves.target.describe());
    out += "\nNUMBER_OF_FIELDS 4\nBEGIN_DATA_FORMAT\nRGB_I RGB_R RGB_G RGB_B\nEND_DATA_FORMAT\n\n";
    out += &format!("NUMBER_OF_SETS {CURVE_ENTRIES}\nBEGIN_DATA\n");
    for i in 0..CURVE_ENTRIES {
        out += &format!(
            "{:.7} {:.7} {:.7} {:.7}\n",
            i as f64 / (CURVE_ENTRIES - 1) as f64,
            curves.curves[0][i],
            curves.curves[1][i],
            curves.curves[2][i]
        );
    }
    out += "END_DATA\n";
    out
}
