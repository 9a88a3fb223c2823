//! The CRS ColorCAL MKII's text commands over its USB CDC serial port (PsychoPy
//! `crs/colorcal.py`, pycrsltd, PTB `ColorCal2.m`; `../shared/PROTOCOLS.md` §6).
//! Replies: a blank `\n\r` line, payload lines each ended by `\n\r`, then a `>` prompt.

pub const PROMPT: u8 = b'>';
/// Timeouts (s): PsychoPy's per-reply limits.
pub const MEASURE_TIMEOUT_S: f64 = 5.0;
pub const COMMAND_TIMEOUT_S: f64 = 1.0;
/// Builds before this one must be zero-calibrated after every power cycle.
pub const FACTORY_CALIBRATED_BUILD: u32 = 877;

/// The payload lines of a framed reply (blank lines and the prompt removed).
pub fn payload_lines(reply: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(reply)
        .split(['\n', '\r'])
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != ">")
        .map(str::to_string)
        .collect()
}

/// A reply frame as the device sends it.
pub fn frame(lines: &[String]) -> Vec<u8> {
    let mut out = b"\n\r".to_vec();
    for l in lines {
        out.extend_from_slice(l.as_bytes());
        out.extend_from_slice(b"\n\r");
    }
    out.push(PROMPT);
    out
}

/// "Minolta format" integers of the calibration matrix: below 50000 a value is
/// +v/10000, from 50000 up it is −(v − 50000)/10000.
pub fn minolta_to_float(v: i64) -> f64 {
    if v < 50_000 {
        v as f64 / 10_000.0
    } else {
        -((v - 50_000) as f64) / 10_000.0
    }
}

pub fn float_to_minolta(f: f64) -> i64 {
    let v = (f.abs() * 10_000.0).round() as i64;
    if f < 0.0 { v + 50_000 } else { v }
}

/// `OKnn,a,b,c` → (status, numbers).
pub fn parse_fields(line: &str) -> Result<(String, Vec<f64>), String> {
    let mut fields = line.split(',');
    let status = fields.next().unwrap_or("").trim().to_string();
    if !(status.starts_with("OK") || status.starts_with("ER")) {
        return Err(format!("'{line}' does not start with OKnn or ERnn"));
    }
    let values = fields
        .map(|f| match f.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("'{}' in '{line}' is not a number", f.trim())),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((status, values))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minolta_format_matches_the_examples() {
        // The CRS demo: OK00, 8053,52040,50642 → 0.8053, −0.2040, −0.0642.
        assert_eq!(minolta_to_float(8053), 0.8053);
        assert_eq!(minolta_to_float(52040), -0.204);
        assert_eq!(minolta_to_float(50642), -0.0642);
        // PsychoPy's tests: 50347 → −0.0347, 10630 → 1.0630.
        assert_eq!(minolta_to_float(50347), -0.0347);
        assert_eq!(minolta_to_float(10630), 1.063);
        for f in [0.8053, -0.204, 1.063, 0.0] {
            assert_eq!(minolta_to_float(float_to_minolta(f)), f);
        }
    }

    #[test]
    fn frames_and_fields() {
        let reply = frame(&["OK00,242.85,248.11, 89.05".to_string()]);
        assert_eq!(reply, b"\n\rOK00,242.85,248.11, 89.05\n\r>");
        assert_eq!(payload_lines(&reply), vec!["OK00,242.85,248.11, 89.05"]);
        assert_eq!(
            parse_fields("OK00,242.85,248.11, 89.05").unwrap().1,
            vec![242.85, 248.11, 89.05]
        );
        assert!(parse_fields("hello").is_err());
    }
}
