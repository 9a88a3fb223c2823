//! A small ICC encoder for matrix/TRC display profiles, version 4.4 and 2.4.
//!
//! Layouts follow ICC.1:2022 (v4) and ICC.1:2001-04 (v2): a 128-byte header, the tag
//! table, then the tag data, every element starting on a 4-byte boundary with the
//! padding counted in the profile size but not in the tag sizes (§7.1.2, §7.3). The
//! crates that write ICC do not fit (no v2, no padding or no `vcgt`; see
//! `../shared/INTERFACES.md` B1.8), so chromacal writes its own.
//!
//! What differs between the versions, by each version's rules:
//! * v4: `desc` and `cprt` as `mluc`; `wtpt` is D50 and `chad` holds the Bradford
//!   matrix from the display's white; TRCs are `para` where the law is one exactly;
//!   the header carries the MD5 profile ID (§7.2.18).
//! * v2: `desc` as `textDescriptionType`, `cprt` as `textType`; `wtpt` is the
//!   display's own white (Y = 1) and there is no `chad` (readers derive Bradford from
//!   `wtpt`, as Little CMS and ArgyllCMS do); TRCs are `curv` only; `bkpt` is written.
//!
//! A model with additivity terms also gets `A2B0` and `B2A0` (`icc_lut`), which carry
//! them.
//!
//! Both carry the colorants adapted to D50, `lumi`, the `meta` dict with colord's
//! metadata keys and, with calibration curves, the Apple `vcgt` tag (3 × 256 16-bit
//! entries, as ArgyllCMS writes it).

use md5::{Digest, Md5};
use nalgebra::Matrix3;

use super::icc_lut::D50;
use super::icc_lut::lut16_bytes;
use super::matrix_trc::{MatrixTrc, Trc};
use chromacal_color::Xyz;
use chromacal_model::target::CURVE_ENTRIES;

/// The ICC version written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IccVersion {
    V2,
    V4,
}

/// Entries of a v2 `curv` (or a v4 one where `para` cannot express the law).
pub const CURV_ENTRIES: usize = 1024;

/// What goes into the profile besides the model.
#[derive(Debug, Clone)]
pub struct IccText {
    /// `desc`: the name system pickers show, so short.
    pub description: String,
    /// `dmdd` (device model description): everything else worth saying.
    pub details: String,
    pub copyright: String,
    /// Creation time, UTC: year, month, day, hour, minute, second.
    pub created: [u16; 6],
}

/// s15Fixed16Number: round(v·65536) as i32 (ICC.1 §4.6).
fn s15f16(v: f64) -> [u8; 4] {
    let n = (v * 65536.0 + 0.5)
        .floor()
        .clamp(i32::MIN as f64, i32::MAX as f64) as i32;
    n.to_be_bytes()
}

fn u16_be(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_be_bytes());
}

fn u32_be(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_be_bytes());
}

/// The 8-byte start of every tag element: type signature and 4 reserved bytes.
fn element(signature: &[u8; 4]) -> Vec<u8> {
    let mut out = signature.to_vec();
    out.extend_from_slice(&[0; 4]);
    out
}

/// `XYZ ` (XYZType), one value.
fn xyz_type(v: &Xyz) -> Vec<u8> {
    let mut out = element(b"XYZ ");
    for c in [v.x, v.y, v.z] {
        out.extend_from_slice(&s15f16(c));
    }
    out
}

/// `sf32` (s15Fixed16ArrayType) of a 3×3 matrix, row by row.
fn sf32_matrix(m: &Matrix3<f64>) -> Vec<u8> {
    let mut out = element(b"sf32");
    for r in 0..3 {
        for c in 0..3 {
            out.extend_from_slice(&s15f16(m[(r, c)]));
        }
    }
    out
}

/// `curv` over evenly spaced inputs, values 0..65535.
fn curv(values: &[f64]) -> Vec<u8> {
    let mut out = element(b"curv");
    u32_be(&mut out, values.len() as u32);
    for v in values {
        u16_be(&mut out, (v.clamp(0.0, 1.0) * 65535.0).round() as u16);
    }
    out
}

/// `para` function type 2: g, a, b, c (ICC.1:2022 §10.18).
fn para_type2(g: f64, a: f64, b: f64, c: f64) -> Vec<u8> {
    let mut out = element(b"para");
    u16_be(&mut out, 2);
    u16_be(&mut out, 0);
    for v in [g, a, b, c] {
        out.extend_from_slice(&s15f16(v));
    }
    out
}

fn trc_tag(trc: &Trc, version: IccVersion) -> Vec<u8> {
    match (trc, version) {
        // Little CMS gives 0 rather than c at X = −b/a exactly (it takes the power
        // branch and finds a zero base), which would drop the black at code 0 when b
        // is 0. One unit of s15Fixed16 below zero moves the threshold off X = 0 and
        // changes the curve by less than 1e-5 relative at the first code.
        (Trc::Parametric { g, a, b, c }, IccVersion::V4) => {
            para_type2(*g, *a, b.min(-1.0 / 65536.0), *c)
        }
        _ => curv(&trc.sampled(CURV_ENTRIES)),
    }
}

/// `mluc` with one en-US record (v4 text).
fn mluc(text: &str) -> Vec<u8> {
    let utf16: Vec<u16> = text.encode_utf16().collect();
    let mut out = element(b"mluc");
    u32_be(&mut out, 1);
    u32_be(&mut out, 12);
    out.extend_from_slice(b"enUS");
    u32_be(&mut out, (utf16.len() * 2) as u32);
    u32_be(&mut out, 28);
    for u in utf16 {
        u16_be(&mut out, u);
    }
    out
}

/// Printable ASCII of `text` (other characters become '?').
fn ascii(text: &str) -> Vec<u8> {
    text.chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c as u8
            } else {
                b'?'
            }
        })
        .collect()
}

/// `desc` (textDescriptionType, v2): ASCII, a Unicode copy, and an empty ScriptCode
/// record (ICC.1:2001-04 §6.5.17).
fn text_description(text: &str) -> Vec<u8> {
    let mut out = element(b"desc");
    let a = ascii(text);
    u32_be(&mut out, a.len() as u32 + 1);
    out.extend_from_slice(&a);
    out.push(0);
    let utf16: Vec<u16> = text.encode_utf16().chain([0]).collect();
    u32_be(&mut out, 0); // Unicode language code
    u32_be(&mut out, utf16.len() as u32);
    for u in utf16 {
        u16_be(&mut out, u);
    }
    u16_be(&mut out, 0); // ScriptCode code
    out.push(0); // ScriptCode count
    out.extend_from_slice(&[0; 67]);
    out
}

/// `text` (textType, v2 `cprt`): ASCII with its NUL.
fn text_type(text: &str) -> Vec<u8> {
    let mut out = element(b"text");
    out.extend_from_slice(&ascii(text));
    out.push(0);
    out
}

/// `dict` (dictType, ICC.1:2022 §10.8) of name/value pairs, as the `meta` tag that
/// colord reads a profile's metadata from: records of four offsets and sizes from the
/// start of the tag, then the strings in UTF-16BE.
fn dict(pairs: &[(&str, &str)]) -> Vec<u8> {
    let mut out = element(b"dict");
    u32_be(&mut out, pairs.len() as u32);
    u32_be(&mut out, 16);
    let mut strings: Vec<u8> = Vec::new();
    let strings_start = 16 + 16 * pairs.len();
    for (name, value) in pairs {
        for text in [name, value] {
            let bytes: Vec<u8> = text.encode_utf16().flat_map(u16::to_be_bytes).collect();
            u32_be(&mut out, (strings_start + strings.len()) as u32);
            u32_be(&mut out, bytes.len() as u32);
            strings.extend_from_slice(&bytes);
        }
    }
    out.extend_from_slice(&strings);
    out
}

/// Apple's `vcgt`, table form: 3 channels × 256 entries × 2 bytes, channel by channel.
/// Each curve is resampled at i/255 (the identity for chromacal's own 256-entry curves),
/// so a curve of another length read from a profile file still makes a valid tag.
fn vcgt(curves: &[Vec<f64>; 3]) -> Vec<u8> {
    let mut out = element(b"vcgt");
    u32_be(&mut out, 0); // gammaType 0: table
    u16_be(&mut out, 3);
    u16_be(&mut out, CURVE_ENTRIES as u16);
    u16_be(&mut out, 2);
    for curve in curves {
        for i in 0..CURVE_ENTRIES {
            let x = i as f64 / (CURVE_ENTRIES - 1) as f64;
            let v = chromacal_model::target::interpolate(curve, x);
            u16_be(&mut out, (v.clamp(0.0, 1.0) * 65535.0).round() as u16);
        }
    }
    out
}

/// Encode `profile` as an ICC display profile.
pub fn encode(profile: &MatrixTrc, text: &IccText, version: IccVersion) -> Vec<u8> {
    let colorants = profile.colorants_d50();
    let d50 = Xyz::new(D50[0], D50[1], D50[2]);
    let column = |c: usize| Xyz::new(colorants[(0, c)], colorants[(1, c)], colorants[(2, c)]);
    let mut tags: Vec<([u8; 4], Vec<u8>)> = Vec::new();
    match version {
        IccVersion::V4 => {
            tags.push((*b"desc", mluc(&text.description)));
            tags.push((*b"dmdd", mluc(&text.details)));
            tags.push((*b"cprt", mluc(&text.copyright)));
            tags.push((*b"wtpt", xyz_type(&d50)));
            tags.push((*b"chad", sf32_matrix(&profile.chad())));
        }
        IccVersion::V2 => {
            tags.push((*b"desc", text_description(&text.description)));
            tags.push((*b"dmdd", text_description(&text.details)));
            tags.push((*b"cprt", text_type(&text.copyright)));
            tags.push((*b"wtpt", xyz_type(&profile.relative_white())));
            tags.push((*b"bkpt", xyz_type(&profile.black_d50())));
        }
    }
    tags.push((*b"rXYZ", xyz_type(&column(0))));
    tags.push((*b"gXYZ", xyz_type(&column(1))));
    tags.push((*b"bXYZ", xyz_type(&column(2))));
    tags.push((*b"rTRC", trc_tag(&profile.trcs[0], version)));
    tags.push((*b"gTRC", trc_tag(&profile.trcs[1], version)));
    tags.push((*b"bTRC", trc_tag(&profile.trcs[2], version)));
    tags.push((*b"lumi", xyz_type(&Xyz::new(0.0, profile.white.y, 0.0))));
    if let Some(luts) = &profile.luts {
        // The same tables for perceptual and for colorimetric intents: readers that
        // look for the colorimetric tag only (moxcms) find it, and `assemble` writes
        // the bytes once.
        let (a2b, b2a) = (lut16_bytes(&luts.a2b0), lut16_bytes(&luts.b2a0));
        tags.push((*b"A2B0", a2b.clone()));
        tags.push((*b"B2A0", b2a.clone()));
        tags.push((*b"A2B1", a2b));
        tags.push((*b"B2A1", b2a));
    }
    if let Some(calibration) = &profile.calibration {
        tags.push((*b"vcgt", vcgt(&calibration.curves)));
    }
    // colord's metadata keys (its metadata-spec; DisplayCAL writes them in v2 too).
    let version_text = env!("CARGO_PKG_VERSION");
    tags.push((
        *b"meta",
        dict(&[
            ("prefix", "CMF_,DATA_"),
            ("DATA_source", "calib"),
            ("CMF_product", "chromacal"),
            ("CMF_binary", "chromacal"),
            ("CMF_version", version_text),
        ]),
    ));
    assemble(&tags, text, version)
}

/// Header, tag table and tag data; identical tag data is written once and shared.
fn assemble(tags: &[([u8; 4], Vec<u8>)], text: &IccText, version: IccVersion) -> Vec<u8> {
    let table_end = 128 + 4 + 12 * tags.len();
    let mut data: Vec<u8> = Vec::new();
    let mut entries: Vec<([u8; 4], u32, u32)> = Vec::new();
    for (signature, bytes) in tags {
        let shared = tags
            .iter()
            .zip(&entries)
            .find(|((_, earlier), _)| earlier == bytes)
            .map(|(_, entry)| (entry.1, entry.2));
        let (offset, size) = shared.unwrap_or_else(|| {
            let offset = (table_end + data.len()) as u32;
            data.extend_from_slice(bytes);
            while !data.len().is_multiple_of(4) {
                data.push(0);
            }
            (offset, bytes.len() as u32)
        });
        entries.push((*signature, offset, size));
    }
    let size = table_end + data.len();
    let mut out = Vec::with_capacity(size);
    u32_be(&mut out, size as u32);
    out.extend_from_slice(b"ccal"); // preferred CMM: chromacal's own signature
    out.extend_from_slice(match version {
        IccVersion::V4 => &[4, 0x40, 0, 0],
        IccVersion::V2 => &[2, 0x40, 0, 0],
    });
    out.extend_from_slice(b"mntr");
    out.extend_from_slice(b"RGB ");
    out.extend_from_slice(b"XYZ ");
    for v in text.created {
        u16_be(&mut out, v);
    }
    out.extend_from_slice(b"acsp");
    u32_be(&mut out, 0); // platform
    u32_be(&mut out, 0); // flags
    u32_be(&mut out, 0); // manufacturer
    u32_be(&mut out, 0); // model
    out.extend_from_slice(&[0; 8]); // attributes
    u32_be(&mut out, 0); // rendering intent: perceptual
    for v in D50 {
        out.extend_from_slice(&s15f16(v));
    }
    out.extend_from_slice(b"ccal"); // creator
    out.extend_from_slice(&[0; 16]); // profile ID, below
    out.extend_from_slice(&[0; 28]);
    debug_assert_eq!(out.len(), 128);
    u32_be(&mut out, entries.len() as u32);
    for (signature, offset, size) in &entries {
        out.extend_from_slice(signature);
        u32_be(&mut out, *offset);
        u32_be(&mut out, *size);
    }
    out.extend_from_slice(&data);
    if version == IccVersion::V4 {
        let id = profile_id(&out);
        out[84..100].copy_from_slice(&id);
    }
    out
}

/// The v4 profile ID: MD5 of the profile with the flags, the rendering intent and
/// the ID itself set to zero (ICC.1:2022 §7.2.18).
pub fn profile_id(bytes: &[u8]) -> [u8; 16] {
    let mut copy = bytes.to_vec();
    if copy.len() >= 100 {
        copy[44..48].fill(0);
        copy[64..68].fill(0);
        copy[84..100].fill(0);
    }
    Md5::digest(&copy).into()
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::transfer::{Power, TransferLaw};
    use chromacal_model::{MonitorModel, SpatialMap};

    fn profile(black: Xyz) -> MatrixTrc {
        let model = MonitorModel {
            matrix: Matrix3::new(41.2, 35.8, 18.0, 21.3, 71.5, 7.2, 1.9, 11.9, 95.0),
            black,
            laws: [0, 1, 2].map(|_| TransferLaw::Power(Power { gamma: 2.2 })),
            spatial: SpatialMap::Uniform,
            terms: Default::default(),
        };
        MatrixTrc::from_model(&model, None)
    }

    fn text() -> IccText {
        IccText {
            description: "test display".into(),
            details: "test details".into(),
            copyright: "no copyright".into(),
            created: [2026, 11, 23, 12, 0, 0],
        }
    }

    fn tag_table(bytes: &[u8]) -> Vec<(String, usize, usize)> {
        let count = u32::from_be_bytes(bytes[128..132].try_into().unwrap()) as usize;
        (0..count)
            .map(|i| {
                let e = &bytes[132 + 12 * i..144 + 12 * i];
                (
                    String::from_utf8_lossy(&e[..4]).to_string(),
                    u32::from_be_bytes(e[4..8].try_into().unwrap()) as usize,
                    u32::from_be_bytes(e[8..12].try_into().unwrap()) as usize,
                )
            })
            .collect()
    }

    #[test]
    fn layout_follows_the_rules_of_each_version() {
        for version in [IccVersion::V2, IccVersion::V4] {
            let bytes = encode(&profile(Xyz::new(0.2, 0.21, 0.25)), &text(), version);
            assert_eq!(
                u32::from_be_bytes(bytes[0..4].try_into().unwrap()) as usize,
                bytes.len()
            );
            assert_eq!(bytes.len() % 4, 0);
            assert_eq!(&bytes[36..40], b"acsp");
            assert_eq!(
                &bytes[68..80],
                &[0, 0, 0xF6, 0xD6, 0, 1, 0, 0, 0, 0, 0xD3, 0x2D]
            );
            let tags = tag_table(&bytes);
            for (name, offset, size) in &tags {
                assert_eq!(offset % 4, 0, "{name}");
                assert!(offset + size <= bytes.len(), "{name}");
            }
            let names: Vec<&str> = tags.iter().map(|t| t.0.as_str()).collect();
            let trc: Vec<_> = tags.iter().filter(|t| t.0.ends_with("TRC")).collect();
            // With a black, each channel's curve carries its own share of it; with
            // none, the three identical curves share their data.
            assert!(trc.windows(2).all(|w| w[0].1 != w[1].1));
            let shared = tag_table(&encode(&profile(Xyz::zeros()), &text(), version));
            let shared: Vec<_> = shared.iter().filter(|t| t.0.ends_with("TRC")).collect();
            assert!(shared.windows(2).all(|w| w[0].1 == w[1].1));
            match version {
                IccVersion::V4 => {
                    assert_eq!(bytes[8], 4);
                    assert!(names.contains(&"chad") && !names.contains(&"bkpt"));
                    assert_eq!(&bytes[trc[0].1..trc[0].1 + 4], b"para");
                    assert_eq!(&bytes[84..100], &profile_id(&bytes));
                    assert_ne!(&bytes[84..100], &[0; 16]);
                }
                IccVersion::V2 => {
                    assert_eq!(bytes[8], 2);
                    assert!(!names.contains(&"chad") && names.contains(&"bkpt"));
                    assert_eq!(&bytes[trc[0].1..trc[0].1 + 4], b"curv");
                    assert_eq!(&bytes[84..100], &[0; 16]);
                }
            }
        }
    }

    #[test]
    fn fixed_point_rounds_as_icc_says() {
        assert_eq!(s15f16(1.0), [0, 1, 0, 0]);
        assert_eq!(s15f16(0.9642), [0, 0, 0xF6, 0xD6]);
        assert_eq!(s15f16(-0.5), [0xFF, 0xFF, 0x80, 0]);
    }
}
