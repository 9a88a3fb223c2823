//! The Klein K-10 / K-10A protocol (ArgyllCMS `spectro/kleink10.c`, BrainardLabToolbox
//! `K10A_device.c`; `../shared/PROTOCOLS.md` §7): two-letter commands ended by CR,
//! binary replies of fixed length `<echo><payload><e>` with a status character.

/// Reply lengths (bytes) of the commands the driver and the emulator use.
pub fn reply_length(command: &[u8]) -> Option<usize> {
    Some(match command {
        b"P0" => 21,
        b"P2" => 13,
        b"N5" => 15,
        b"D7" => 1925,
        b"M6" => 20,
        b"B9" => 43,
        [b'J', b'1'..=b'8'] | [b'L', b'0' | b'1'] => 5,
        _ => return None,
    })
}

/// Timeouts (s): Argyll's, the longer where BLT's differ.
pub fn timeout_s(command: &[u8]) -> f64 {
    match command {
        b"P0" | b"L0" | b"L1" => 0.5,
        b"D7" => 6.0,
        b"B9" => 15.0,
        _ => 2.0,
    }
}

/// What the status character between `<` and `>` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StatusKind {
    Ok,
    /// `u`: bottom under range.
    Under,
    /// `v` (top over range), `w` (over high range).
    Over,
    /// Firmware, black-calibration or aiming-light errors.
    Fault,
}

pub fn classify(status: u8) -> StatusKind {
    match status {
        b'0' => StatusKind::Ok,
        b'u' => StatusKind::Under,
        b'v' | b'w' => StatusKind::Over,
        _ => StatusKind::Fault,
    }
}

pub fn meaning(status: u8) -> &'static str {
    match status {
        b'0' => "OK",
        b'B' | b'X' => "firmware error",
        b'b' => "black excessive",
        b's' => "black overdrive",
        b't' => "black zero",
        b'w' => "over high range",
        b'v' => "top over range",
        b'u' => "bottom under range",
        b'L' => "aiming lights on while measuring",
        _ => "unknown status",
    }
}

/// A measurement value: bytes 0–1 a big-endian word (bit 15 the sign, bits 14–0 the
/// mantissa m), byte 2 a signed exponent e; value = ±m·2^(e−16).
pub fn decode_value(b: &[u8]) -> f64 {
    let word = u16::from_be_bytes([b[0], b[1]]);
    let sign = if word & 0x8000 != 0 { -1.0 } else { 1.0 };
    let mantissa = (word & 0x7fff) as f64;
    let exponent = b[2] as i8 as i32;
    sign * mantissa * 2f64.powi(exponent - 16)
}

/// The inverse of [`decode_value`], normalised so the mantissa keeps 15 bits.
pub fn encode_value(v: f64) -> [u8; 3] {
    if v == 0.0 || !v.is_finite() {
        return [0, 0, 0];
    }
    let a = v.abs();
    let mut e = a.log2().floor() as i32 + 2;
    let mut m = (a * 2f64.powi(16 - e)).round();
    if m >= 32768.0 {
        e += 1;
        m = (a * 2f64.powi(16 - e)).round();
    }
    let word = (m as u16 & 0x7fff) | if v < 0.0 { 0x8000 } else { 0 };
    let [hi, lo] = word.to_be_bytes();
    [hi, lo, e.clamp(-128, 127) as i8 as u8]
}

/// A calibration value (Klein-format matrices): as [`decode_value`] with 2^(e−15).
pub fn decode_calibration_value(b: &[u8]) -> f64 {
    decode_value(b) * 2.0
}

/// Ranges of X, Y, Z (1–6) from the range byte: bits 7, 6, 5 are per-channel flags,
/// the low 5 bits d_X·9 + d_Y·3 + d_Z; range = 1 + 2·d + flag.
pub fn decode_ranges(byte: u8) -> [u8; 3] {
    let digits = byte & 0x1f;
    let d = [digits / 9, (digits / 3) % 3, digits % 3];
    let flags = [(byte >> 7) & 1, (byte >> 6) & 1, (byte >> 5) & 1];
    [
        1 + 2 * d[0] + flags[0],
        1 + 2 * d[1] + flags[1],
        1 + 2 * d[2] + flags[2],
    ]
}

/// The inverse of [`decode_ranges`].
pub fn encode_ranges(ranges: [u8; 3]) -> u8 {
    let d: Vec<u8> = ranges.iter().map(|r| (r.clamp(&1, &6) - 1) / 2).collect();
    let f: Vec<u8> = ranges.iter().map(|r| (r.clamp(&1, &6) - 1) % 2).collect();
    (f[0] << 7) | (f[1] << 6) | (f[2] << 5) | (d[0] * 9 + d[1] * 3 + d[2])
}

/// Check a reply's echo and trailer; returns the payload and the status character.
pub fn unframe<'a>(command: &[u8], reply: &'a [u8]) -> Result<(&'a [u8], u8), String> {
    if reply.len() < 5 {
        return Err(format!("a {}-byte reply is too short", reply.len()));
    }
    if &reply[..2] != command {
        return Err(format!(
            "the reply does not echo {}: {}",
            String::from_utf8_lossy(command),
            crate::transport::escape(&reply[..2])
        ));
    }
    let n = reply.len();
    if reply[n - 3] != b'<' || reply[n - 1] != b'>' {
        return Err(format!(
            "the reply does not end in <e>: {}",
            crate::transport::escape(&reply[n - 3..])
        ));
    }
    Ok((&reply[2..n - 3], reply[n - 2]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_match_the_documented_bytes() {
        assert_eq!(decode_value(&[0x64, 0x00, 0x08]), 100.0);
        assert!((decode_value(&[0x5F, 0x0D, 0x08]) - 95.0508).abs() < 1e-4);
        assert_eq!(decode_value(&[0x40, 0x00, 0x01]), 0.5);
        assert_eq!(encode_value(100.0), [0x64, 0x00, 0x08]);
        assert_eq!(encode_value(0.5), [0x40, 0x00, 0x01]);
        for v in [0.000123, 0.0456, 1.0, 95.05, 3999.0, -12.5] {
            let back = decode_value(&encode_value(v));
            assert!((back - v).abs() / v.abs() < 1e-4, "{v} → {back}");
        }
    }

    #[test]
    fn ranges_match_the_documented_bytes() {
        assert_eq!(decode_ranges(0x00), [1, 1, 1]);
        assert_eq!(decode_ranges(0x0D), [3, 3, 3]);
        assert_eq!(decode_ranges(0xE0), [2, 2, 2]);
        assert_eq!(decode_ranges(0xED), [4, 4, 4]);
        for r in [[1, 2, 3], [6, 5, 4], [2, 2, 6]] {
            assert_eq!(decode_ranges(encode_ranges(r)), r);
        }
    }

    #[test]
    fn frames_are_checked() {
        let reply = [
            b'N', b'5', 0x5F, 0x0D, 0x08, 0x64, 0, 8, 0x6C, 0xE6, 8, 0, b'<', b'0', b'>',
        ];
        let (payload, status) = unframe(b"N5", &reply).unwrap();
        assert_eq!((payload.len(), status), (10, b'0'));
        assert!(unframe(b"P0", &reply).is_err());
        assert!(unframe(b"N5", &reply[..14]).is_err());
    }
}
