//! `chromacal bench render` as a user runs it. With the `peer-engines` feature (as
//! `scripts/test.sh` builds the suite) it sets moxcms and Little CMS beside chromacal,
//! each transforming with the exported ICC profile and judged by the exact model;
//! without it, chromacal's rows alone and a message naming the feature.

mod common;

use common::chromacal;

/// The table's row whose first cell starts with `tool`: its cells (the columns are
/// set apart by two spaces or more).
fn row<'a>(table: &'a str, tool: &str) -> Option<Vec<&'a str>> {
    table
        .lines()
        .find(|l| l.trim_start().starts_with(tool))
        .map(|l| {
            l.split("  ")
                .map(str::trim)
                .filter(|c| !c.is_empty())
                .collect()
        })
}

/// "0.0011 / 0.011" → (mean, max).
#[cfg(feature = "peer-engines")]
fn error_cell(cell: &str) -> (f64, f64) {
    let (mean, max) = cell
        .split_once('/')
        .unwrap_or_else(|| panic!("not an error cell: {cell}"));
    (mean.trim().parse().unwrap(), max.trim().parse().unwrap())
}

fn bench_render() -> (String, String) {
    let out = chromacal()
        .args(["bench", "--only", "render", "--quick"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    (stdout, stderr)
}

#[cfg(feature = "peer-engines")]
#[test]
fn the_bench_sets_moxcms_and_little_cms_beside_chromacal() {
    let (table, stderr) = bench_render();
    assert!(!stderr.contains("left out of this build"), "{stderr}");
    assert!(row(&table, "chromacal").is_some(), "{table}");
    for tool in ["moxcms", "Little CMS"] {
        let cells = row(&table, tool).unwrap_or_else(|| panic!("no {tool} row: {table}"));
        // The peers transform with the exported ICC profile, fed colours relative to
        // the white it carries (the measured one): their error is their arithmetic's
        // (moxcms's f32 about 0.012, Little CMS's doubles 0.002), not the 0.06 of
        // colours taken relative to the model's own white, nor the several ΔE00 of a
        // wrong intent.
        let (mean, max) = error_cell(cells.last().unwrap());
        assert!(mean < 0.03 && max < 0.5, "{tool}: {mean} / {max}");
        // Mpixel/s is a positive number.
        let speed: f64 = cells[2].parse().unwrap();
        assert!(speed > 0.0, "{cells:?}");
    }
    the_whole_command_is_timed(&table);
}

/// The whole `render` command has its rows beside the loop: seconds, the same less
/// reading and writing, and that over the loop's time; the whole command's seconds
/// positive, the nearest codes taking longer than the rounded ones (about 3 ×).
fn the_whole_command_is_timed(table: &str) {
    assert!(table.contains("the whole `render` command"), "{table}");
    let cells = |name: &str| -> Vec<f64> {
        row(table, name)
            .unwrap_or_else(|| panic!("no row {name}: {table}"))
            .iter()
            .skip(1)
            .map(|c| c.parse::<f64>().unwrap())
            .collect()
    };
    let nearest = cells("16 bits, nearest codes");
    let rounded = cells("16 bits, --codes rounded");
    assert_eq!(nearest.len(), 3, "{table}");
    assert_eq!(rounded.len(), 3, "{table}");
    assert!(rounded[0] > 0.0, "{table}");
    assert!(nearest[0] > rounded[0], "{table}");
}

#[cfg(not(feature = "peer-engines"))]
#[test]
fn without_the_feature_the_bench_says_how_to_get_the_peers() {
    let (table, stderr) = bench_render();
    assert!(row(&table, "chromacal").is_some(), "{table}");
    assert!(row(&table, "moxcms").is_none(), "{table}");
    the_whole_command_is_timed(&table);
    assert!(
        stderr.contains("--features peer-engines -- bench --only render"),
        "{stderr}"
    );
}

/// The feature the message names is the one the manifest declares, with both crates.
#[test]
fn the_feature_named_is_the_manifest_s() {
    let manifest =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml")).unwrap();
    let line = manifest
        .lines()
        .find(|l| l.starts_with("peer-engines = "))
        .unwrap_or_else(|| panic!("no peer-engines feature in Cargo.toml"));
    assert!(
        line.contains("dep:moxcms") && line.contains("dep:lcms2"),
        "{line}"
    );
    for crate_name in ["moxcms", "lcms2"] {
        let declared = manifest
            .lines()
            .find(|l| l.starts_with(&format!("{crate_name} = ")))
            .unwrap();
        assert!(declared.contains("optional = true"), "{declared}");
    }
}
