//! EDID parsing, checked against an independent decoder: Debian's `edid-decode` reads
//! the same fixtures (`fixtures/edid/`, made from the VESA E-EDID structure), and every
//! field chromacal uses must agree.

use std::path::{Path, PathBuf};
use std::process::Command;

use chromacal_formats::edid::{Edid, EdidError};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/edid")
        .join(name)
}

/// `edid-decode`'s text for a file.
fn edid_decode(path: &Path) -> String {
    let out = Command::new("edid-decode")
        .arg(path)
        .output()
        .expect("edid-decode runs (scripts/test.sh installs it)");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The value after `key:` on the first line that has it.
fn field<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines()
        .map(str::trim)
        .find_map(|l| l.strip_prefix(key))
        .map(|rest| rest.trim_start_matches(':').trim())
}

fn xy(text: &str, key: &str) -> [f64; 2] {
    let value = field(text, key).unwrap_or_else(|| panic!("no {key} in\n{text}"));
    let (x, y) = value.split_once(',').unwrap();
    [x.trim().parse().unwrap(), y.trim().parse().unwrap()]
}

#[test]
fn three_edids_read_as_edid_decode_reads_them() {
    for name in [
        "srgb_office_1080p.bin",
        "wide_gamut_1440p.bin",
        "p3_laptop_panel.bin",
    ] {
        let path = fixture(name);
        let bytes = std::fs::read(&path).unwrap();
        let ours = Edid::parse(&bytes).unwrap();
        let theirs = edid_decode(&path);
        assert_eq!(
            Some(ours.manufacturer.as_str()),
            field(&theirs, "Manufacturer"),
            "{name}"
        );
        assert_eq!(
            field(&theirs, "Model").map(str::to_string),
            Some(ours.product_code.to_string()),
            "{name}"
        );
        assert_eq!(
            field(&theirs, "Serial Number").map(str::to_string),
            ours.serial_number.map(|n| n.to_string()),
            "{name}"
        );
        assert_eq!(
            field(&theirs, "Display Product Serial Number").map(|s| s.trim_matches('\'')),
            ours.serial_text.as_deref(),
            "{name}"
        );
        assert_eq!(
            field(&theirs, "Display Product Name").map(|s| s.trim_matches('\'')),
            ours.name.as_deref(),
            "{name}"
        );
        if ours.model_year {
            assert_eq!(
                field(&theirs, "Model year"),
                Some(ours.year.to_string().as_str())
            );
        } else {
            assert_eq!(
                field(&theirs, "Made in"),
                Some(format!("week {} of {}", ours.week.unwrap(), ours.year).as_str()),
                "{name}"
            );
        }
        for (key, value) in [
            ("Red  ", ours.red),
            ("Green", ours.green),
            ("Blue ", ours.blue),
            ("White", ours.white),
        ] {
            let [x, y] = xy(&theirs, key);
            assert!(
                (x - value[0]).abs() <= 1.01e-4 && (y - value[1]).abs() <= 1.01e-4,
                "{name} {key}: edid-decode {x},{y}, chromacal {value:?}"
            );
        }
        let extensions = field(&theirs, "Extension blocks").map_or(0, |n| n.parse().unwrap());
        assert_eq!(ours.extensions, extensions, "{name}");
        eprintln!("{name}: {}", ours.describe());
    }
}

#[test]
fn a_serial_matches_as_text_or_number_and_nothing_else() {
    let office = Edid::parse(&std::fs::read(fixture("srgb_office_1080p.bin")).unwrap()).unwrap();
    assert!(office.matches_serial("7MT0186J1T3L"));
    assert!(office.matches_serial("1278488880"));
    assert!(office.matches_serial("0x4C343130"));
    assert!(!office.matches_serial("23150512"));
    let laptop = Edid::parse(&std::fs::read(fixture("p3_laptop_panel.bin")).unwrap()).unwrap();
    assert_eq!(laptop.serial(), None);
    assert!(!laptop.matches_serial("0"));
}

#[test]
fn a_damaged_edid_is_refused_with_its_fault() {
    let mut bytes = std::fs::read(fixture("wide_gamut_1440p.bin")).unwrap();
    assert_eq!(Edid::parse(&bytes[..100]), Err(EdidError::Short(100)));
    bytes[30] ^= 0x04;
    let err = Edid::parse(&bytes).unwrap_err();
    assert!(matches!(err, EdidError::Checksum(4 | 252)), "{err}");
    assert!(err.to_string().contains("checksum"), "{err}");
}
