//! The Photo Research PR-650's remote language (manual excerpts in Mcalibrator2 and
//! BrainardLabToolbox, drivers of PTB and PsychoPy; `../shared/PROTOCOLS.md` §2):
//! lower-case commands ended by LF, replies ended by CR LF, numbers `d.dddE±dd`.

pub const EOL: &[u8] = b"\r\n";
/// Drivers wait up to 30 s for a measurement.
pub const MEASURE_TIMEOUT_S: f64 = 30.0;
/// PTB waits up to 10 s for the first reply (`b3`); 2 s for the others.
pub const FIRST_REPLY_TIMEOUT_S: f64 = 10.0;
pub const COMMAND_TIMEOUT_S: f64 = 2.0;
/// Seconds after power-up within which a command must arrive to arm remote mode.
pub const ARMING_WINDOW_S: f64 = 5.0;

/// What a quality code says (PR-650 Operating Manual p. B-30, via BrainardLabToolbox).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QualityKind {
    Ok,
    /// 10 weak light signal, 18 low light level.
    LowLight,
    /// 19 light level too high.
    Overload,
    /// 7 unable to sync, 8 sync lost, 20 no sync signal.
    SyncFailure,
    Other,
}

pub fn classify(code: u32) -> QualityKind {
    match code {
        0 => QualityKind::Ok,
        10 | 18 => QualityKind::LowLight,
        19 => QualityKind::Overload,
        7 | 8 | 20 => QualityKind::SyncFailure,
        _ => QualityKind::Other,
    }
}

pub fn meaning(code: u32) -> &'static str {
    match code {
        0 => "measurement okay",
        1 => "no EOS signal at start of measurement",
        3 => "no start signal",
        4 => "no EOS signal to start integration time",
        5 => "DMA failure",
        6 => "no EOS after changed to SYNC mode",
        7 => "unable to sync to light source",
        8 => "sync lost during measurement",
        10 => "weak light signal",
        12 => "unspecified hardware malfunction",
        13 => "software error",
        14 => "no sample in L*u*v* or L*a*b* calculation",
        16 => "adaptive integration taking too long",
        17 => "main battery is low",
        18 => "low light level",
        19 => "light level too high (overload)",
        20 => "no sync signal",
        21 => "RAM error",
        29 => "corrupted data",
        30 => "noisy signal",
        _ => "unknown quality code",
    }
}

/// A number as the PR-650 prints it: `d.dddE±dd`, 9 characters.
pub fn format_number(v: f64) -> String {
    crate::emulator::scientific(v, 3, 2).to_ascii_uppercase()
}

/// The leading number of a reply.
pub fn parse_code(line: &str) -> Result<u32, String> {
    line.split(',')
        .next()
        .unwrap_or("")
        .trim()
        .parse()
        .map_err(|_| format!("'{line}' does not start with a code"))
}

/// D2: `qq,U,X,Y,Z` → (quality, [X, Y, Z]).
pub fn parse_xyz(line: &str) -> Result<(u32, [f64; 3]), String> {
    let f: Vec<&str> = line.split(',').map(str::trim).collect();
    if f.len() != 5 {
        return Err(format!("D2 has 5 fields, '{line}' has {}", f.len()));
    }
    let n = |s: &str| match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("'{s}' in '{line}' is not a number")),
    };
    Ok((parse_code(line)?, [n(f[2])?, n(f[3])?, n(f[4])?]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_manuals_formats() {
        assert_eq!(format_number(61.36), "6.136E+01");
        assert_eq!(
            parse_xyz("00,0,6.136E+01,1.865E+01,2.681E+01").unwrap(),
            (0, [61.36, 18.65, 26.81])
        );
        // A spectral row is 17 bytes with CR LF, as PTB's parser cuts them.
        let row = format!("{:04.0}.,{}\r\n", 380.0, format_number(1.234e-5));
        assert_eq!(row, "0380.,1.234E-05\r\n");
        assert_eq!(row.len(), 17);
        assert_eq!(classify(18), QualityKind::LowLight);
        assert_eq!(classify(7), QualityKind::SyncFailure);
    }
}
