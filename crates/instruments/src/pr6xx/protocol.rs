//! The remote-control language of the Photo Research PR-655 and PR-670 (PR-655/670
//! User Manual, report formats pp. 126–132; error codes from the PR-653 manual of the
//! same family). Formats and parsers only: the driver and the emulator both use them.
//! See `../shared/PROTOCOLS.md` §3.

/// The two members of the family this module speaks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    Pr655,
    Pr670,
}

impl Model {
    pub fn name(self) -> &'static str {
        match self {
            Model::Pr655 => "PR-655",
            Model::Pr670 => "PR-670",
        }
    }

    /// Spectral grid: 380–780 nm in 4 nm (PR-655) or 2 nm (PR-670) steps.
    pub fn step_nm(self) -> f64 {
        match self {
            Model::Pr655 => 4.0,
            Model::Pr670 => 2.0,
        }
    }

    pub fn rows(self) -> usize {
        (400.0 / self.step_nm()) as usize + 1
    }

    /// Longest wait for a spectral measurement (PTB and BLT: 30 s for the PR-655,
    /// 300 s for the PR-670).
    pub fn measure_timeout_s(self) -> f64 {
        match self {
            Model::Pr655 => 30.0,
            Model::Pr670 => 300.0,
        }
    }

    /// Exponent digits in spectral rows: PTB's PR-655 parser cuts 16-byte rows, so
    /// 3 digits; the PR-670's rows are parsed by field, 2 digits as in the manual.
    pub fn row_exponent_digits(self) -> usize {
        match self {
            Model::Pr655 => 3,
            Model::Pr670 => 2,
        }
    }
}

/// Pause between characters the USB firmware needs (PTB, BrainardLabToolbox: 50 ms).
pub const CHARACTER_GAP_S: f64 = 0.05;
/// Wait for ` REMOTE MODE` after `PHOTO`.
pub const REMOTE_TIMEOUT_S: f64 = 10.0;
/// Wait for the reply to a setup or data command.
pub const COMMAND_TIMEOUT_S: f64 = 10.0;
/// Reply terminator.
pub const EOL: &[u8] = b"\r\n";

/// What a status code says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StatusKind {
    Ok,
    /// −8: insufficient signal.
    WeakLight,
    /// −2: signal too intense.
    Overload,
    /// −1, −3, −9, −10: the source is not constant or sync failed: measure without sync.
    SyncFailure,
    Other,
}

/// Classify a status code by the vendor's table.
pub fn classify(code: i32) -> StatusKind {
    match code {
        0 => StatusKind::Ok,
        -8 => StatusKind::WeakLight,
        -2 => StatusKind::Overload,
        -1 | -3 | -9 | -10 => StatusKind::SyncFailure,
        _ => StatusKind::Other,
    }
}

/// The vendor's meaning of a status code.
pub fn meaning(code: i32) -> &'static str {
    match code {
        0 => "measurement okay",
        -1 => "light source not constant",
        -2 => "light overload: signal too intense",
        -3 => "cannot sync to light source",
        -4 => "adaptive mode error",
        -8 => "weak light: insufficient signal",
        -9 => "sync error",
        -10 => "cannot auto-sync to light source",
        -12 => "adaptive mode time out: light source not constant",
        _ => "unknown error",
    }
}

/// The status that starts every reply: the first comma field, a signed integer.
pub fn parse_status(line: &str) -> Result<i32, String> {
    let field = line.split(',').next().unwrap_or("").trim();
    field
        .parse::<i32>()
        .map_err(|_| format!("'{line}' does not start with a status code"))
}

fn number(field: &str, line: &str) -> Result<f64, String> {
    match field.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("'{}' in '{line}' is not a number", field.trim())),
    }
}

/// Report 2: `qqqqq,U,X,Y,Z` → (status, [X, Y, Z]).
pub fn parse_xyz(line: &str) -> Result<(i32, [f64; 3]), String> {
    let status = parse_status(line)?;
    let f: Vec<&str> = line.split(',').collect();
    if f.len() != 5 {
        return Err(format!("report 2 has 5 fields, '{line}' has {}", f.len()));
    }
    Ok((
        status,
        [
            number(f[2], line)?,
            number(f[3], line)?,
            number(f[4], line)?,
        ],
    ))
}

/// A spectral row `wl,value` → (nm, W·sr⁻¹·m⁻²·nm⁻¹).
pub fn parse_row(line: &str) -> Result<(f64, f64), String> {
    let (w, v) = line
        .split_once(',')
        .ok_or_else(|| format!("'{line}' is not a 'wavelength,value' row"))?;
    Ok((number(w, line)?, number(v, line)?))
}

/// The second field of a name or serial report (`00000,PR-670`).
pub fn parse_text_report(line: &str) -> Result<String, String> {
    let status = parse_status(line)?;
    if status != 0 {
        return Err(format!("status {status} ({}) in '{line}'", meaning(status)));
    }
    Ok(line
        .split(',')
        .skip(1)
        .collect::<Vec<_>>()
        .join(",")
        .trim()
        .to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_manuals_examples() {
        assert_eq!(
            parse_xyz("00000,0,6.136e+01,1.865e+01,2.681e+01").unwrap(),
            (0, [61.36, 18.65, 26.81])
        );
        assert_eq!(parse_row("380,1.627e-003").unwrap(), (380.0, 0.001627));
        assert_eq!(parse_status("-0008").unwrap(), -8);
        assert_eq!(parse_status("-8,0").unwrap(), -8);
        assert_eq!(parse_text_report("00000,PR-670").unwrap(), "PR-670");
        assert!(parse_xyz("00000,0,6.1e+01,nan,2e+01").is_err());
        assert!(parse_status(" REMOTE MODE").is_err());
        assert_eq!(Model::Pr670.rows(), 201);
        assert_eq!(Model::Pr655.rows(), 101);
    }
}
