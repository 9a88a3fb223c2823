//! A PsychoPy monitor file: the calibration as PsychoPy's Monitor Center stores it in
//! `~/.psychopy3/monitors/<name>.json` (`psychopy.monitors.calibTools.Monitor`), so
//! that `monitors.Monitor(name)` loads it and its windows linearise with it.
//!
//! The file maps a calibration name (`%Y_%m_%d %H:%M`, as `strFromDate` makes it) to
//! a dict. PsychoPy writes it with `json_tricks`, which stores a numpy array as
//! `{"__ndarray__": rows, "dtype": "float64", "shape": [...], "Corder": true}`; the
//! arrays here are written that way so that `json_tricks.load` gives numpy arrays.
//!
//! What PsychoPy reads:
//! * `gammaGrid`, 4 × 6: rows luminance (grey), R, G, B; columns min, max, gamma, a,
//!   b, k. With `linearizeMethod` 1 PsychoPy inverts y = a + (b·x)^γ: min is the
//!   black's luminance and max each row's full-drive luminance, both in cd/m²; γ is
//!   fitted here to the model's curve of that row (least squares on the share of the
//!   way from black to full drive, 256 levels). b = 0 and k = (max − min)^(1/γ) give
//!   the same curve under PsychoPy's method 4 (Pelli & Zhang 1991), y = a + (b + k·x)^γ.
//! * `lumsPre` (4 × n) at `levelsPre` (0..255): the model's luminance series.
//! * `spectraNM`, `spectraRGB` (3 × n): the full-drive spectra of R, G and B, when the
//!   run measured spectra.
//! * `calibDate` (seconds since the epoch), `notes`, `width`, `distance`, `sizePix`
//!   (unknown to chromacal: null, set them in Monitor Center), `usebits`,
//!   `psychopyVersion`.

use serde_json::{Value, json};

use chromacal_model::MonitorModel;
use chromacal_model::measurement::{MeasurementSet, Role};

/// Levels of the luminance series (PsychoPy's `DACrange(17)`-like spacing).
const SERIES_LEVELS: usize = 17;

/// A numpy array in json_tricks' form.
fn ndarray(rows: &[Vec<f64>]) -> Value {
    let shape = if rows.len() == 1 {
        json!([rows[0].len()])
    } else {
        json!([rows.len(), rows.first().map_or(0, Vec::len)])
    };
    let data = if rows.len() == 1 {
        json!(rows[0])
    } else {
        json!(rows)
    };
    json!({"__ndarray__": data, "dtype": "float64", "shape": shape, "Corder": true})
}

/// The γ of y = x^γ that best fits `shares` (the share of the way from black to full
/// drive at inputs i/(n−1)), by golden-section search on the squared error.
pub fn fit_gamma(shares: &[f64]) -> f64 {
    let n = shares.len();
    let error = |g: f64| -> f64 {
        shares
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let x = i as f64 / (n - 1) as f64;
                (x.powf(g) - s).powi(2)
            })
            .sum()
    };
    let (mut lo, mut hi) = (0.5_f64, 5.0_f64);
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let a = hi - ratio * (hi - lo);
        let b = lo + ratio * (hi - lo);
        if error(a) < error(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    (lo + hi) / 2.0
}

/// The luminance of drive `d` under the model.
fn luminance(model: &MonitorModel, d: [f64; 3]) -> f64 {
    model.forward_centre(d).y
}

/// The drive of row `row` (0 grey, 1..3 one channel) at input x.
fn row_drive(row: usize, x: f64) -> [f64; 3] {
    match row {
        0 => [x; 3],
        c => {
            let mut d = [0.0; 3];
            d[c - 1] = x;
            d
        }
    }
}

/// The gamma grid: rows grey, R, G, B; columns min, max, gamma, a, b, k.
pub fn gamma_grid(model: &MonitorModel) -> [[f64; 6]; 4] {
    let black = luminance(model, [0.0; 3]);
    [0, 1, 2, 3].map(|row| {
        let max = luminance(model, row_drive(row, 1.0));
        let shares: Vec<f64> = (0..256)
            .map(|i| {
                let y = luminance(model, row_drive(row, i as f64 / 255.0));
                (y - black) / (max - black)
            })
            .collect();
        let gamma = fit_gamma(&shares);
        [
            black,
            max,
            gamma,
            black,
            0.0,
            (max - black).powf(1.0 / gamma),
        ]
    })
}

/// The largest difference between PsychoPy's curve y = a + (b·x)^γ of each row and
/// the model, as a share of the row's full-drive luminance.
pub fn power_law_error(model: &MonitorModel, grid: &[[f64; 6]; 4]) -> f64 {
    let mut worst: f64 = 0.0;
    for (row, r) in grid.iter().enumerate() {
        let (min, max, gamma) = (grid[1][0], r[1], r[2]);
        let b = (max - min).powf(1.0 / gamma);
        for i in 0..256 {
            let x = i as f64 / 255.0;
            let psychopy = min + (b * x).powf(gamma);
            let y = luminance(model, row_drive(row, x));
            worst = worst.max((psychopy - y).abs() / max);
        }
    }
    worst
}

/// The monitor file's JSON text.
pub fn monitor_file(
    model: &MonitorModel,
    measurements: Option<&MeasurementSet>,
    calibration_name: &str,
    calib_date_epoch_s: f64,
    notes: &str,
) -> String {
    let grid = gamma_grid(model);
    let notes = format!(
        "{notes}; PsychoPy's power law (linearizeMethod 1) follows chromacal's fitted model within {:.1} % of full luminance",
        100.0 * power_law_error(model, &grid)
    );
    let levels: Vec<f64> = (0..SERIES_LEVELS)
        .map(|i| (255.0 * i as f64 / (SERIES_LEVELS - 1) as f64).round())
        .collect();
    let lums: Vec<Vec<f64>> = (0..4)
        .map(|row| {
            levels
                .iter()
                .map(|l| luminance(model, row_drive(row, l / 255.0)))
                .collect()
        })
        .collect();
    let mut calibration = json!({
        "calibDate": calib_date_epoch_s,
        "gamma": grid[0][2],
        "gammaGrid": ndarray(&grid.iter().map(|r| r.to_vec()).collect::<Vec<_>>()),
        "linearizeMethod": 1,
        "lumsPre": ndarray(&lums),
        "levelsPre": ndarray(&[levels]),
        "lumsPost": null,
        "levelsPost": null,
        "meanLum": luminance(model, [0.5; 3]),
        "width": null,
        "distance": null,
        "sizePix": null,
        "notes": notes.as_str(),
        "usebits": false,
        "psychopyVersion": format!("chromacal {}", env!("CARGO_PKG_VERSION")),
    });
    if let Some((nm, rgb)) = measurements.and_then(primary_spectra) {
        calibration["spectraNM"] = ndarray(&[nm]);
        calibration["spectraRGB"] = ndarray(&rgb);
    }
    let file = json!({ calibration_name: calibration });
    serde_json::to_string_pretty(&file).unwrap_or_default()
}

/// Wavelengths and the spectra of R, G and B at full drive (the first usable
/// reading of each), when all three were measured on one wavelength grid.
fn primary_spectra(set: &MeasurementSet) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
    let mut grid: Option<Vec<f64>> = None;
    let mut rows = Vec::new();
    for c in 0..3 {
        let mut drive = [0.0; 3];
        drive[c] = 1.0;
        let spectrum = set
            .measurements
            .iter()
            .filter(|m| m.role == Role::Ramp && m.drive == drive && m.is_standard_condition())
            .find_map(|m| m.usable_xyz().and(m.reading.spectrum.as_ref()))?;
        let nm = spectrum.wavelengths_nm().to_vec();
        if grid.as_ref().is_some_and(|g| *g != nm) {
            return None;
        }
        grid = Some(nm);
        rows.push(spectrum.values().to_vec());
    }
    Some((grid?, rows))
}

/// PsychoPy's name for a calibration made at `time`: `%Y_%m_%d %H:%M` in local time,
/// as its Monitor Center names one (`time.strftime` on the calibrating machine).
pub fn calibration_name(time: jiff::Timestamp, local: &jiff::tz::TimeZone) -> String {
    time.to_zoned(local.clone())
        .strftime("%Y_%m_%d %H:%M")
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_is_recovered_from_a_power_curve() {
        let shares: Vec<f64> = (0..256).map(|i| (i as f64 / 255.0).powf(2.37)).collect();
        assert!((fit_gamma(&shares) - 2.37).abs() < 1e-6);
    }

    #[test]
    fn a_calibration_is_named_in_local_time() {
        let made: jiff::Timestamp = "2026-12-02T22:30:00Z".parse().unwrap();
        let utc = jiff::tz::TimeZone::UTC;
        assert_eq!(calibration_name(made, &utc), "2026_12_02 22:30");
        // Tokyo is nine hours ahead: the next day there.
        let tokyo = jiff::tz::TimeZone::fixed(jiff::tz::offset(9));
        assert_eq!(calibration_name(made, &tokyo), "2026_12_03 07:30");
        let new_york = jiff::tz::TimeZone::fixed(jiff::tz::offset(-5));
        assert_eq!(calibration_name(made, &new_york), "2026_12_02 17:30");
    }
}
