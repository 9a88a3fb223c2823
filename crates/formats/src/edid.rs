//! The EDID a monitor gives its video card (VESA E-EDID Standard, release A, revision
//! 2, 2006: EDID structure 1.3 and 1.4): who made it, which model and which unit,
//! when, and the chromaticities of its primaries and white as the maker measured them.
//!
//! Only the 128-byte base block is read: it holds everything chromacal uses; the
//! extension blocks that may follow (CTA-861, DisplayID) are counted, not parsed.

use serde::{Deserialize, Serialize};

/// The fixed first eight bytes of every EDID (§3.3).
const HEADER: [u8; 8] = [0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x00];

/// Why bytes are not an EDID.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EdidError {
    #[error("an EDID has at least 128 bytes; this has {0}")]
    Short(usize),
    #[error("the EDID header (00 FF FF FF FF FF FF 00) is missing")]
    Header,
    #[error("the EDID base block's checksum is off by {0} (bytes 0–127 must sum to 0 mod 256)")]
    Checksum(u8),
}

/// A parsed EDID base block.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Edid {
    /// Three-letter PNP manufacturer ID (`DEL`, `APP`, `SAM`).
    pub manufacturer: String,
    pub product_code: u16,
    /// The numeric serial, when the maker set one (0 means none).
    pub serial_number: Option<u32>,
    /// The serial text descriptor (tag FFh), when present.
    pub serial_text: Option<String>,
    /// The product name descriptor (tag FCh), when present.
    pub name: Option<String>,
    /// Week of manufacture (1–54), when given.
    pub week: Option<u8>,
    /// Year of manufacture, or the model year when `model_year` is set.
    pub year: u16,
    pub model_year: bool,
    /// EDID structure version and revision (1.3, 1.4).
    pub version: (u8, u8),
    /// Display gamma the maker states, when stated.
    pub gamma: Option<f64>,
    /// CIE 1931 xy of red, green, blue and white (10-bit values over 1024).
    pub red: [f64; 2],
    pub green: [f64; 2],
    pub blue: [f64; 2],
    pub white: [f64; 2],
    /// Image size, cm (0 when undefined).
    pub size_cm: [u8; 2],
    /// Extension blocks that follow the base block.
    pub extensions: u8,
}

impl Edid {
    /// Parse the base block of `bytes` (§3.1–3.10).
    pub fn parse(bytes: &[u8]) -> Result<Self, EdidError> {
        if bytes.len() < 128 {
            return Err(EdidError::Short(bytes.len()));
        }
        let b = &bytes[..128];
        if b[..8] != HEADER {
            return Err(EdidError::Header);
        }
        let sum = b.iter().fold(0u8, |s, &v| s.wrapping_add(v));
        if sum != 0 {
            return Err(EdidError::Checksum(sum));
        }
        // §3.4: three 5-bit letters, 1 = 'A', big-endian.
        let id = u16::from_be_bytes([b[8], b[9]]);
        let letter = |shift: u16| (b'A' - 1 + ((id >> shift) & 0x1F) as u8) as char;
        let manufacturer: String = [letter(10), letter(5), letter(0)].iter().collect();
        let serial = u32::from_le_bytes([b[12], b[13], b[14], b[15]]);
        // §3.4.4: week FFh means the year is a model year; week 0 means not given.
        let model_year = b[16] == 0xFF;
        let week = (1..=54).contains(&b[16]).then_some(b[16]);
        // §3.7: 10-bit chromaticities, high 8 bits in 27–34, low 2 bits packed in 25–26.
        let low = |byte: u8, shift: u8| u16::from((byte >> shift) & 0b11);
        let coordinate =
            |high: u8, low_bits: u16| f64::from((u16::from(high) << 2) | low_bits) / 1024.0;
        let red = [
            coordinate(b[27], low(b[25], 6)),
            coordinate(b[28], low(b[25], 4)),
        ];
        let green = [
            coordinate(b[29], low(b[25], 2)),
            coordinate(b[30], low(b[25], 0)),
        ];
        let blue = [
            coordinate(b[31], low(b[26], 6)),
            coordinate(b[32], low(b[26], 4)),
        ];
        let white = [
            coordinate(b[33], low(b[26], 2)),
            coordinate(b[34], low(b[26], 0)),
        ];
        let mut edid = Edid {
            manufacturer,
            product_code: u16::from_le_bytes([b[10], b[11]]),
            serial_number: (serial != 0).then_some(serial),
            serial_text: None,
            name: None,
            week,
            year: 1990 + u16::from(b[17]),
            model_year,
            version: (b[18], b[19]),
            // §3.6.3: (gamma × 100) − 100; FFh means stated elsewhere.
            gamma: (b[23] != 0xFF).then(|| (f64::from(b[23]) + 100.0) / 100.0),
            red,
            green,
            blue,
            white,
            size_cm: [b[21], b[22]],
            extensions: b[126],
        };
        // §3.10: four 18-byte descriptors; a display descriptor starts 00 00 00 tag.
        for d in b[54..126].chunks_exact(18) {
            if d[0] != 0 || d[1] != 0 {
                continue; // a detailed timing
            }
            let text = || descriptor_text(&d[5..18]);
            match d[3] {
                0xFF => edid.serial_text = Some(text()),
                0xFC => edid.name = Some(text()),
                _ => {}
            }
        }
        Ok(edid)
    }

    /// Whether `serial` names this monitor: its serial text, or its numeric serial
    /// in decimal or as `0x…`.
    pub fn matches_serial(&self, serial: &str) -> bool {
        let serial = serial.trim();
        self.serial_text.as_deref() == Some(serial)
            || self.serial_number.is_some_and(|n| {
                serial == n.to_string()
                    || serial
                        .strip_prefix("0x")
                        .and_then(|h| u32::from_str_radix(h, 16).ok())
                        == Some(n)
            })
    }

    /// The serial to show: the text descriptor, else the number.
    pub fn serial(&self) -> Option<String> {
        self.serial_text
            .clone()
            .or_else(|| self.serial_number.map(|n| n.to_string()))
    }

    /// "DEL U2415 (serial 7MT0186J1T3L, week 12 of 2016)".
    pub fn describe(&self) -> String {
        let model = self
            .name
            .clone()
            .unwrap_or_else(|| format!("product {:04X}", self.product_code));
        let made = match (self.week, self.model_year) {
            (_, true) => format!("model year {}", self.year),
            (Some(w), false) => format!("week {w} of {}", self.year),
            (None, false) => format!("{}", self.year),
        };
        match self.serial() {
            Some(s) => format!("{} {model} (serial {s}, {made})", self.manufacturer),
            None => format!("{} {model} ({made})", self.manufacturer),
        }
    }
}

/// The id colord knows an X output's monitor by, as GNOME's and MATE's colour plugins
/// and mutter register it (colord's device and profile naming spec): `xrandr`, then
/// `-` and each of the EDID's maker, monitor name and serial it has, the maker by the
/// name `vendor_name` gives its three-letter PNP id (the hwdata `pnp.ids` those
/// desktops read) or else by the three letters; with none of them, or no EDID,
/// `xrandr-` and the output's name. `export --register-colord` takes it.
pub fn colord_device_id(
    edid: Option<&Edid>,
    output: &str,
    vendor_name: impl Fn(&str) -> Option<String>,
) -> String {
    let mut id = String::from("xrandr");
    let parts: Vec<String> = edid
        .map(|e| {
            let maker = (!e.manufacturer.is_empty())
                .then(|| vendor_name(&e.manufacturer).unwrap_or_else(|| e.manufacturer.clone()));
            [maker, e.name.clone(), e.serial()]
                .into_iter()
                .flatten()
                .collect()
        })
        .unwrap_or_default();
    if parts.is_empty() {
        id.push('-');
        id.push_str(output);
    }
    for part in parts {
        id.push('-');
        id.push_str(&part);
    }
    id
}

/// A descriptor's text: ASCII up to the line feed that ends it, spaces trimmed.
fn descriptor_text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&c| c == 0x0A).unwrap_or(bytes.len());
    bytes[..end]
        .iter()
        .map(|&c| {
            if c.is_ascii_graphic() || c == b' ' {
                c as char
            } else {
                '?'
            }
        })
        .collect::<String>()
        .trim()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A base block with the header, a manufacturer and chromaticities, checksummed.
    fn block() -> Vec<u8> {
        let mut b = vec![0u8; 128];
        b[..8].copy_from_slice(&HEADER);
        // "ABC": 1, 2, 3.
        let id: u16 = (1 << 10) | (2 << 5) | 3;
        b[8..10].copy_from_slice(&id.to_be_bytes());
        b[33] = 0xA0; // white x = 640/1024 + low bits
        b[26] = 0b0000_1100; // white x low bits = 3
        let sum = b.iter().fold(0u8, |s, &v| s.wrapping_add(v));
        b[127] = 0u8.wrapping_sub(sum);
        b
    }

    #[test]
    fn manufacturer_and_ten_bit_chromaticities() {
        let e = Edid::parse(&block()).unwrap();
        assert_eq!(e.manufacturer, "ABC");
        assert_eq!(e.white[0], (0xA0 * 4 + 3) as f64 / 1024.0);
        assert_eq!(e.serial_number, None);
    }

    #[test]
    fn broken_blocks_say_what_is_wrong() {
        assert_eq!(Edid::parse(&[0; 20]), Err(EdidError::Short(20)));
        let mut b = block();
        b[0] = 1;
        assert_eq!(Edid::parse(&b), Err(EdidError::Header));
        let mut b = block();
        b[40] ^= 0x10;
        assert!(matches!(Edid::parse(&b), Err(EdidError::Checksum(_))));
    }

    #[test]
    fn colord_ids_as_the_desktops_register_them() {
        let mut e = Edid::parse(&block()).unwrap();
        let pnp = |code: &str| (code == "ABC").then(|| "Abc Displays".to_string());
        assert_eq!(
            colord_device_id(Some(&e), "DP-1", pnp),
            "xrandr-Abc Displays"
        );
        assert_eq!(colord_device_id(Some(&e), "DP-1", |_| None), "xrandr-ABC");
        e.name = Some("View 27".into());
        e.serial_number = Some(1234);
        assert_eq!(
            colord_device_id(Some(&e), "DP-1", pnp),
            "xrandr-Abc Displays-View 27-1234"
        );
        e.serial_text = Some("SN9".into());
        assert_eq!(
            colord_device_id(Some(&e), "DP-1", |_| None),
            "xrandr-ABC-View 27-SN9"
        );
        assert_eq!(colord_device_id(None, "DUMMY0", pnp), "xrandr-DUMMY0");
    }
}
