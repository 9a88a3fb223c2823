//! Colorimeter corrections where they are installed, by name: ArgyllCMS's `oeminst`
//! puts the `.ccmx` and `.ccss` files of a vendor's software in
//! `$XDG_DATA_HOME/ArgyllCMS` (the user's) and `$XDG_DATA_DIRS/ArgyllCMS` (every
//! user's); Debian's `argyll-ref` in `/usr/share/color/argyll/ref`; and chromacal keeps
//! the user's own in `$XDG_DATA_HOME/chromacal/corrections`. `[instrument] correction`
//! takes a path or the name of one of these (its file name, with or without the
//! extension), and every profile records which one it was made with (its name, its
//! file's SHA-256, the display type and the reference instrument it names), or that a
//! colorimeter was used without one.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::Correction;
use crate::profile::CorrectionRecord;

/// The folders corrections are looked for in, the user's first.
pub fn correction_dirs() -> Vec<PathBuf> {
    let home = std::env::var_os("HOME").map(PathBuf::from);
    let data_home = std::env::var_os("XDG_DATA_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| home.map(|h| h.join(".local/share")));
    let mut dirs = Vec::new();
    if let Some(d) = &data_home {
        dirs.push(d.join("chromacal/corrections"));
        dirs.push(d.join("ArgyllCMS"));
    }
    let data_dirs = std::env::var("XDG_DATA_DIRS")
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "/usr/local/share:/usr/share".into());
    for d in data_dirs.split(':').filter(|d| d.starts_with('/')) {
        dirs.push(Path::new(d).join("ArgyllCMS"));
    }
    dirs.push(PathBuf::from("/usr/share/color/argyll/ref"));
    dirs
}

fn keyword(text: &str, name: &str) -> Option<String> {
    text.lines().find_map(|line| {
        let rest = line.trim().strip_prefix(name)?;
        let value = rest.trim();
        (rest.starts_with(char::is_whitespace) && value.starts_with('"'))
            .then(|| value.trim_matches('"').to_string())
            .filter(|v| !v.is_empty())
    })
}

/// What a correction file is: its keywords and digest; `None` when it cannot be read.
pub fn describe(path: &Path) -> Option<CorrectionRecord> {
    let bytes =
        chromacal_formats::durable::read_limited(path, chromacal_formats::durable::limits::TABLE)
            .ok()?;
    let text = String::from_utf8_lossy(&bytes);
    let kind = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .filter(|e| e == "ccmx" || e == "ccss")?;
    Some(CorrectionRecord {
        name: path.file_name()?.to_string_lossy().into_owned(),
        kind,
        path: Some(path.display().to_string()),
        sha256: Some(format!("{:x}", Sha256::digest(&bytes))),
        display: keyword(&text, "DISPLAY").or_else(|| keyword(&text, "TECHNOLOGY")),
        instrument: keyword(&text, "INSTRUMENT"),
        reference: keyword(&text, "REFERENCE"),
    })
}

/// Every correction file in the folders, by folder, then name.
pub fn installed() -> Vec<CorrectionRecord> {
    let mut found = Vec::new();
    for dir in correction_dirs() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        found.extend(paths.iter().filter_map(|p| describe(p)));
    }
    found
}

/// The file a correction names: a path as it is (relative ones from `base_dir`), or
/// when there is no such file and it is a bare name, the installed file of that name
/// (with or without its extension).
pub fn resolve(path: &Path, base_dir: &Path) -> PathBuf {
    let direct = if path.is_absolute() {
        path.to_path_buf()
    } else {
        base_dir.join(path)
    };
    if direct.exists() || path.components().count() > 1 {
        return direct;
    }
    let name = path.to_string_lossy();
    installed()
        .into_iter()
        .find(|c| {
            c.name == name
                || Path::new(&c.name)
                    .file_stem()
                    .is_some_and(|s| s.to_string_lossy() == name)
        })
        .and_then(|c| c.path.map(PathBuf::from))
        .unwrap_or(direct)
}

impl Correction {
    /// What the profile records of this correction.
    pub fn record(&self, base_dir: &Path) -> CorrectionRecord {
        match self {
            Correction::Matrix(_) => CorrectionRecord {
                name: "a matrix in the config".into(),
                kind: "matrix".into(),
                path: None,
                sha256: None,
                display: None,
                instrument: None,
                reference: None,
            },
            Correction::File(path) => {
                let file = resolve(path, base_dir);
                describe(&file).unwrap_or_else(|| CorrectionRecord {
                    name: path.display().to_string(),
                    kind: "unread".into(),
                    path: Some(file.display().to_string()),
                    sha256: None,
                    display: None,
                    instrument: None,
                    reference: None,
                })
            }
        }
    }
}
