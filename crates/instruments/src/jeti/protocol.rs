//! The JETI specbos 1211 remote language (ArgyllCMS `spectro/specbos.c`;
//! `../shared/PROTOCOLS.md` §8): `*`-commands ended by CR; queries answered by text
//! lines ended by CR, settings by ACK or NAK, `*init` by ACK then BEL when done; ENQ
//! bytes may appear anywhere and mean nothing.

pub const ACK: u8 = 0x06;
pub const NAK: u8 = 0x15;
pub const BEL: u8 = 0x07;
pub const ENQ: u8 = 0x05;
pub const CR: &[u8] = b"\r";

/// Baud rates tried when probing, in Argyll's order.
pub const BAUD_RATES: [u32; 3] = [921_600, 115_200, 38_400];
/// Wavelength range and step the driver asks for (Argyll limits the long end to 830).
pub const WAVELENGTH_START: u32 = 380;
pub const WAVELENGTH_END: u32 = 830;

pub fn bands() -> usize {
    (WAVELENGTH_END - WAVELENGTH_START) as usize + 1
}

/// Timeouts (s).
pub const SETTING_TIMEOUT_S: f64 = 1.0;
pub const PROBE_TIMEOUT_S: f64 = 0.5;
/// `*init` on a 1211: its target measurement time (9.6 s) plus 10 s.
pub const INIT_TIMEOUT_S: f64 = 19.6;
pub const FETCH_XYZ_TIMEOUT_S: f64 = 0.5;
pub const FETCH_SPECTRUM_TIMEOUT_S: f64 = 6.0;
pub const CYCLE_TIMEOUT_S: f64 = 5.0;

/// What an error code from `*stat:err?` means for a measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    Overexposure,
    Underexposure,
    /// 123 (adaptation of integration time): a misread, measure again.
    Misread,
    /// 160 (timeout cycle on optical trigger), 161: sync failed.
    SyncFailure,
    Other,
}

pub fn classify(code: u32) -> ErrorKind {
    match code {
        120 => ErrorKind::Overexposure,
        121 => ErrorKind::Underexposure,
        123 => ErrorKind::Misread,
        160 | 161 => ErrorKind::SyncFailure,
        _ => ErrorKind::Other,
    }
}

pub fn meaning(code: u32) -> &'static str {
    match code {
        4 => "command",
        7 => "password",
        8 => "digit",
        10..=13 => "argument",
        20..=27 => "parameter, config, control, read, fetch, measure, calc or calibration argument",
        120 => "overexposure",
        121 => "underexposure",
        123 => "adaptation of integration time",
        130 => "no shutter",
        131 => "no dark measurement",
        134 => "no radiometric calculation",
        138 => "no light measurement",
        141 => "exceeded calibration wavelength",
        160 => "timeout cycle on optical trigger",
        161 => "divider cycle time",
        _ => "instrument error",
    }
}

/// Remove ENQ bytes, which the specbos sends at random.
pub fn strip_enq(bytes: &[u8]) -> Vec<u8> {
    bytes.iter().copied().filter(|b| *b != ENQ).collect()
}

/// The number after the label of a `label:<whitespace>value` line.
pub fn labelled_value(line: &str) -> Result<f64, String> {
    let (_, value) = line
        .rsplit_once(':')
        .ok_or_else(|| format!("'{line}' is not 'label: value'"))?;
    match value.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("'{}' in '{line}' is not a number", value.trim())),
    }
}

/// The code of `Error Code: <n>` (1201/1211) or a bare `<n>` (15x1).
pub fn parse_error_code(line: &str) -> Result<u32, String> {
    let text = line.rsplit(':').next().unwrap_or(line).trim();
    text.parse()
        .map_err(|_| format!("'{line}' is not an error code"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_labels_and_codes() {
        assert_eq!(labelled_value("X:\t95.12").unwrap(), 95.12);
        assert_eq!(
            labelled_value("Predefined start wave:\t380").unwrap(),
            380.0
        );
        assert!(labelled_value("X:\tnan").is_err());
        assert_eq!(parse_error_code("Error Code: 121").unwrap(), 121);
        assert_eq!(parse_error_code("121").unwrap(), 121);
        assert_eq!(strip_enq(b"\x05X:\t1\x05\r"), b"X:\t1\r");
        assert_eq!(bands(), 451);
    }
}
