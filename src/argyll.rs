//! ArgyllCMS as a yardstick. `colprof -qm -as` builds its matrix/shaper display profile
//! (per-channel shaper curves and a matrix, fitted to every reading given) from a
//! training set, `xicclu` (absolute colorimetric, XYZ out) predicts the XYZ of any RGB
//! through it, and `profcheck -k` judges any profile on a `.ti3` of readings.
//! `chromacal bench` and the tests use these to score chromacal's exported profile and
//! ArgyllCMS's on one split, by one judge. Needs ArgyllCMS on the PATH (Debian's
//! `argyll`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use chromacal_color::Xyz;
use chromacal_formats::cgats::to_ti3;
use chromacal_model::Drive;
use chromacal_model::measurement::MeasurementSet;

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
    #[error("{program}'s line {line} is not what it prints: '{text}'")]
    Unreadable {
        program: &'static str,
        line: usize,
        text: String,
    },
    #[error("the training set has no white reading to scale by")]
    NoWhite,
}

/// True when `colprof`, `xicclu` and `profcheck` can be run.
pub fn available() -> bool {
    ["colprof", "xicclu", "profcheck"].iter().all(|p| {
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
    let icc = matrix_shaper_profile(&to_ti3(train), work, "train")?;
    // Absolute colorimetric XYZ comes scaled to white Y = 100, as the .ti3 went in.
    let scale = train.mean_white().ok_or(ArgyllError::NoWhite)?.y / 100.0;
    Ok(absolute_xyz(&icc, drives)?
        .into_iter()
        .map(|xyz| xyz * scale)
        .collect())
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> ArgyllError {
    let path = path.to_path_buf();
    move |source| ArgyllError::Io { path, source }
}

/// `colprof -qm -as` on the `.ti3` text `ti3`, written as `work/name.ti3`: the path of
/// the matrix/shaper profile it made.
pub fn matrix_shaper_profile(ti3: &str, work: &Path, name: &str) -> Result<PathBuf, ArgyllError> {
    std::fs::create_dir_all(work).map_err(io_error(work))?;
    let base = work.join(name);
    let ti3_path = base.with_extension("ti3");
    std::fs::write(&ti3_path, ti3).map_err(io_error(&ti3_path))?;
    run(
        "colprof",
        Command::new("colprof")
            .args(["-qm", "-as"])
            .arg(name)
            .current_dir(work),
        None,
    )?;
    Ok(base.with_extension("icc"))
}

/// `xicclu -ia -pX`: the absolute colorimetric XYZ (white Y = 100) of each of `drives`
/// through the profile at `icc`.
pub fn absolute_xyz(icc: &Path, drives: &[Drive]) -> Result<Vec<Xyz>, ArgyllError> {
    let input: String = drives
        .iter()
        .map(|d| format!("{} {} {}\n", d[0], d[1], d[2]))
        .collect();
    let output = run(
        "xicclu",
        Command::new("xicclu").args(["-ia", "-pX"]).arg(icc),
        Some(input),
    )?;
    let predictions: Vec<Xyz> = output
        .lines()
        .enumerate()
        .filter(|(_, l)| l.contains("[XYZ]"))
        .map(|(i, line)| parse_xicclu_line(line, i + 1))
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

/// ArgyllCMS's judge of a profile: `profcheck -v2 -k`, the CIEDE2000 error of each
/// patch of the `.ti3` at `ti3` against the profile at `icc`, absolute colorimetric,
/// L*a*b* taken against D50 from XYZ scaled to white Y = 100. In the file's order.
pub fn profcheck_delta_e00(ti3: &Path, icc: &Path) -> Result<Vec<f64>, ArgyllError> {
    let output = run(
        "profcheck",
        Command::new("profcheck")
            .args(["-v2", "-k"])
            .arg(ti3)
            .arg(icc),
        None,
    )?;
    output
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with('['))
        .map(|(i, line)| parse_profcheck_line(line, i + 1))
        .collect()
}

/// `[0.245] 12: 0.5 0.2 0.1 -> …` → 0.245.
fn parse_profcheck_line(line: &str, number: usize) -> Result<f64, ArgyllError> {
    line.strip_prefix('[')
        .and_then(|rest| rest.split(']').next())
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite())
        .ok_or_else(|| ArgyllError::Unreadable {
            program: "profcheck",
            line: number,
            text: line.to_string(),
        })
}

/// `0.5 0.5 0.5 [RGB] -> MatrixFwd -> 20.39 21.46 23.56 [XYZ]` → the XYZ.
fn parse_xicclu_line(line: &str, number: usize) -> Result<Xyz, ArgyllError> {
    let unreadable = || ArgyllError::Unreadable {
        program: "xicclu",
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
    use chromacal_formats::child::output_within;
    let child = command
        .stdin(if input.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| ArgyllError::Missing { program, source })?;
    let output = output_within(
        program,
        child,
        input.map(String::into_bytes),
        OUTPUT_LIMIT,
        std::time::Duration::from_secs(TIME_LIMIT_S),
    )
    .map_err(|e| ArgyllError::Failed {
        program,
        stderr: e.to_string(),
    })?;
    if !output.status.success() {
        return Err(ArgyllError::Failed {
            program,
            stderr: String::from_utf8_lossy(&output.stderr).trim().to_string(),
        });
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// The most an ArgyllCMS tool may print here: `xicclu` on a few thousand colours
/// prints some hundred kilobytes.
const OUTPUT_LIMIT: usize = 64 << 20;

/// How long one may take: `colprof` on a few hundred patches takes seconds.
const TIME_LIMIT_S: u64 = 600;

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
