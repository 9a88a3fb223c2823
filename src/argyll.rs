//! ArgyllCMS as a yardstick. `colprof -qm -as` builds its matrix/shaper display profile
//! (per-channel shaper curves and a matrix, fitted to every reading given) from a
//! training set, and `xicclu` (absolute colorimetric, XYZ out) predicts the XYZ of any
//! RGB through it. `chromacal bench` and the tests use this to score chromacal and
//! ArgyllCMS on one split, with one ΔE00 formula against one white. Needs ArgyllCMS on
//! the PATH (Debian's `argyll`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::cgats::to_ti3;
use crate::color::Xyz;
use crate::measurement::{MeasurementSet, Units};
use crate::model::Drive;

/// Why ArgyllCMS gave no predictions.
#[derive(Debug, thiserror::Error)]
pub enum ArgyllError {
    #[error("{program} could not be run ({source}); install ArgyllCMS (Debian: argyll)")]
    Missing {
        program: &'static str,
        source: std::io::Error,
    },
    #[error("{program} failed: {stderr}")]
    Failed {
        program: &'static str,
        stderr: String,
    },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("xicclu's line {line} is not RGB -> XYZ: '{text}'")]
    Unreadable { line: usize, text: String },
    #[error("the training set has no white reading to scale by")]
    NoWhite,
}

/// True when `colprof` and `xicclu` can be run.
pub fn available() -> bool {
    ["colprof", "xicclu"].iter().all(|p| {
        Command::new(p)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok()
    })
}

/// ArgyllCMS's matrix/shaper profile of `train`, made in `work` (a directory the caller
/// owns), and its XYZ for each of `drives`, in `train`'s units.
pub fn matrix_shaper_predictions(
    train: &MeasurementSet,
    drives: &[Drive],
    work: &Path,
) -> Result<Vec<Xyz>, ArgyllError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ArgyllError::Io { path, source }
    };
    std::fs::create_dir_all(work).map_err(io(work))?;
    let base = work.join("train");
    let ti3 = base.with_extension("ti3");
    std::fs::write(&ti3, to_ti3(train)).map_err(io(&ti3))?;
    run(
        "colprof",
        Command::new("colprof")
            .args(["-qm", "-as"])
            .arg(&base)
            .current_dir(work),
        None,
    )?;
    let input: String = drives
        .iter()
        .map(|d| format!("{} {} {}\n", d[0], d[1], d[2]))
        .collect();
    let output = run(
        "xicclu",
        Command::new("xicclu")
            .args(["-ia", "-pX"])
            .arg(base.with_extension("icc")),
        Some(input),
    )?;
    // Absolute colorimetric XYZ comes scaled to white Y = 100, as the .ti3 went in.
    let scale = match train.units {
        Units::Relative => 1.0,
        Units::Absolute => train.mean_white().ok_or(ArgyllError::NoWhite)?.y / 100.0,
    };
    let predictions: Vec<Xyz> = output
        .lines()
        .enumerate()
        .filter(|(_, l)| l.contains("[XYZ]"))
        .map(|(i, line)| parse_xicclu_line(line, i + 1).map(|xyz| xyz * scale))
        .collect::<Result<_, _>>()?;
    if predictions.len() != drives.len() {
        return Err(ArgyllError::Failed {
            program: "xicclu",
            stderr: format!(
                "{} predictions for {} colours",
                predictions.len(),
                drives.len()
            ),
        });
    }
    Ok(predictions)
}

/// `0.5 0.5 0.5 [RGB] -> MatrixFwd -> 20.39 21.46 23.56 [XYZ]` → the XYZ.
fn parse_xicclu_line(line: &str, number: usize) -> Result<Xyz, ArgyllError> {
    let unreadable = || ArgyllError::Unreadable {
        line: number,
        text: line.to_string(),
    };
    let after = line.rsplit("->").next().ok_or_else(unreadable)?;
    let values: Vec<f64> = after
        .split_whitespace()
        .take(3)
        .map(|v| v.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| unreadable())?;
    match values[..] {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(Xyz::new(x, y, z)),
        _ => Err(unreadable()),
    }
}

/// Run `command` (feeding `input` to it), its standard output on success.
fn run(
    program: &'static str,
    command: &mut Command,
    input: Option<String>,
) -> Result<String, ArgyllError> {
    use std::io::Write;
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| ArgyllError::Missing { program, source })?;
    if let (Some(text), Some(mut stdin)) = (input, child.stdin.take()) {
        stdin
            .write_all(text.as_bytes())
            .map_err(|source| ArgyllError::Missing { program, source })?;
    }
    let output = child
        .wait_with_output()
        .map_err(|source| ArgyllError::Missing { program, source })?;
    if !output.status.success() {
        return Err(ArgyllError::Failed {
            program,
            stderr: String::from_utf8_lossy(&output.stderr).trim().to_string(),
        });
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_xicclu_lines_and_refuses_others() {
        let xyz = parse_xicclu_line(
            "0.500000 0.500000 0.500000 [RGB] -> MatrixFwd -> 20.394763 21.464591 23.562378 [XYZ]",
            1,
        )
        .unwrap();
        assert_eq!(xyz, Xyz::new(20.394763, 21.464591, 23.562378));
        assert!(parse_xicclu_line("1 1 1 [RGB] -> MatrixFwd -> 1 nan 2 [XYZ]", 4).is_err());
        let err = parse_xicclu_line("garbage [XYZ]", 7)
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 7"), "{err}");
    }
}
