//! The minimum Rust version stated is the true one: `Cargo.toml`'s `rust-version` is
//! not below what any locked dependency declares, and the README says the same. (That
//! the code itself builds with it is checked by `cargo +1.89 check --locked`; see the
//! README.)

use std::path::Path;

mod common;

fn version(text: &str) -> Vec<u32> {
    text.split('.').map(|p| p.parse().unwrap_or(0)).collect()
}

#[test]
fn the_stated_minimum_rust_version_covers_every_locked_dependency() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = common::succeed(
        std::process::Command::new(env!("CARGO"))
            .args([
                "metadata",
                "--offline",
                "--locked",
                "--format-version",
                "1",
                "--filter-platform",
                "x86_64-unknown-linux-gnu",
            ])
            .current_dir(root),
    );
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Only the packages the build resolves for this platform.
    let used: Vec<&str> = metadata["resolve"]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["id"].as_str().unwrap())
        .collect();
    let mut ours = None;
    let mut highest = (vec![0], String::new());
    for package in metadata["packages"].as_array().unwrap() {
        if !used.contains(&package["id"].as_str().unwrap()) {
            continue;
        }
        let Some(required) = package["rust_version"].as_str() else {
            continue;
        };
        let name = package["name"].as_str().unwrap();
        if name == "chromacal" {
            ours = Some(required.to_string());
        } else if version(required) > highest.0 {
            highest = (version(required), format!("{name} {}", package["version"]));
        }
    }
    let ours = ours.expect("Cargo.toml states a rust-version");
    assert!(
        version(&ours) >= highest.0,
        "rust-version {ours} is below what {} needs ({:?})",
        highest.1,
        highest.0
    );
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(
        readme.contains(&format!("Rust toolchain ({ours} or later")),
        "the README states another minimum than Cargo.toml's {ours}"
    );
}
