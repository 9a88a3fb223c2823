//! The remote language of the Konica Minolta LS-100 / LS-110 luminance meters and the
//! CS-100A chroma meter (4800 baud 7E2, CR LF; `../shared/PROTOCOLS.md` §4–5). Formats
//! and parsers shared by the driver and the emulator.

/// Which meter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    Ls100,
    Ls110,
    Cs100a,
}

impl Model {
    pub fn name(self) -> &'static str {
        match self {
            Model::Ls100 => "LS-100",
            Model::Ls110 => "LS-110",
            Model::Cs100a => "CS-100A",
        }
    }

    /// True for the chroma meter, which gives Y, x, y; the others give luminance only.
    pub fn has_chromaticity(self) -> bool {
        self == Model::Cs100a
    }

    /// Lowest luminance the meter measures (LS-100: 0.001 cd/m²; CS-100A: 0.01).
    pub fn lowest_cd_m2(self) -> f64 {
        match self {
            Model::Ls100 | Model::Ls110 => 0.001,
            Model::Cs100a => 0.01,
        }
    }
}

pub const EOL: &[u8] = b"\r\n";
/// PsychoPy's read timeout for these meters.
pub const REPLY_TIMEOUT_S: f64 = 5.0;

/// A status and what it means for a reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StatusKind {
    Ok,
    /// OK11 (chromaticity range over), OK13 (display range under): values only indicative.
    Below,
    /// OK12, ER10, ER12, ER19: too much light.
    Over,
    /// ER00: the command was not understood.
    Unknown,
    Error,
}

pub fn classify(status: &str) -> StatusKind {
    match status {
        "OK00" => StatusKind::Ok,
        "OK11" | "OK13" => StatusKind::Below,
        "OK12" | "ER10" | "ER12" | "ER19" => StatusKind::Over,
        "ER00" => StatusKind::Unknown,
        _ => StatusKind::Error,
    }
}

pub fn meaning(status: &str) -> &'static str {
    match status {
        "OK00" => "normal",
        "OK11" => "chromaticity measuring range over",
        "OK12" => "luminance display range over",
        "OK13" => "luminance display range under",
        "ER00" => "command error or parameter out of range",
        "ER01" => "setting error",
        "ER10" => "measuring range over",
        "ER11" => "memory value error",
        "ER12" => "luminance and chromaticity display range over",
        "ER19" => "display range over",
        "ER20" => "EEPROM error: the meter needs repair",
        "ER30" => "battery exhausted",
        _ => "unknown status",
    }
}

/// A meter's reply: its 4-character status and its numbers (sign position `+`, `-` or
/// a space, fields separated by commas).
pub fn parse_reply(line: &str) -> Result<(String, Vec<f64>), String> {
    let line = line.trim_end();
    let status = line
        .get(..4)
        .ok_or_else(|| format!("'{line}' is too short for a status"))?;
    if !(status.starts_with("OK") || status.starts_with("ER"))
        || !status[2..].chars().all(|c| c.is_ascii_digit())
    {
        return Err(format!("'{line}' does not start with OKnn or ERnn"));
    }
    let mut values = Vec::new();
    for field in line[4..].split(',').skip(1) {
        let v: f64 = field
            .trim()
            .parse()
            .map_err(|_| format!("'{}' in '{line}' is not a number", field.trim()))?;
        if !v.is_finite() {
            return Err(format!("'{}' in '{line}' is not finite", field.trim()));
        }
        values.push(v);
    }
    Ok((status.to_string(), values))
}

/// A number in the meters' 7-character field: the sign position (a space for positive
/// numbers), then 6 characters.
pub fn field(v: f64) -> String {
    let sign = if v < 0.0 { '-' } else { ' ' };
    let a = v.abs();
    let body = if a >= 99999.5 {
        format!("{:6.0}", a.min(999999.0))
    } else {
        let digits = if a >= 1.0 {
            a.log10().floor() as usize + 1
        } else {
            1
        };
        let decimals = 5usize.saturating_sub(digits);
        format!("{:6.*}", decimals, a)
    };
    format!("{sign}{body}")
}

/// A chromaticity in the CS-100A's 6-character field: sign position then `.xxxx`.
pub fn chromaticity_field(v: f64) -> String {
    let text = format!("{:.4}", v.abs().min(0.9999));
    format!(
        "{}{}",
        if v < 0.0 { '-' } else { ' ' },
        text.trim_start_matches('0')
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_have_the_documented_widths() {
        assert_eq!(field(123.45), " 123.45");
        assert_eq!(field(0.0123), " 0.0123");
        assert_eq!(field(-5.0), "-5.0000");
        assert_eq!(field(12345.6), "  12346");
        assert_eq!(chromaticity_field(0.3127), " .3127");
        // A CS-100A reply is 28 bytes with CR LF.
        let line = format!(
            "OK00,{},{},{}\r\n",
            field(123.45),
            chromaticity_field(0.3127),
            chromaticity_field(0.329)
        );
        assert_eq!(line.len(), 28, "{line:?}");
        assert_eq!(
            parse_reply(&line).unwrap(),
            ("OK00".into(), vec![123.45, 0.3127, 0.329])
        );
        assert_eq!(parse_reply("OK00,+123.4").unwrap().1, vec![123.4]);
        assert!(parse_reply("OK00, nan").is_err());
        assert!(parse_reply("HELLO").is_err());
    }
}
