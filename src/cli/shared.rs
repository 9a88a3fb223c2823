//! What the commands share: the failure they end with and its exit code, writing to
//! standard output, numbers on the command line, and logging. The arguments several
//! commands take are in `args`.

/// A failure to report and the exit code to leave with.
pub struct Failure {
    pub message: String,
    pub code: u8,
}

impl Failure {
    /// The reader of standard output went away (`chromacal check --json | head`): not a
    /// failure of the command. `main` ends quietly with success on it, as ripgrep does:
    /// what was asked for was read as far as the reader wanted.
    pub fn output_closed() -> Failure {
        Failure {
            message: String::new(),
            code: 0,
        }
    }

    /// Whether this is the closed output of `output_closed`.
    pub fn is_output_closed(&self) -> bool {
        self.code == 0
    }

    /// A write to standard output that failed: a closed pipe ends the command quietly,
    /// anything else is a failure that says it was the output.
    pub fn from_output(e: std::io::Error) -> Failure {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            Failure::output_closed()
        } else {
            Failure {
                message: format!("cannot write to standard output: {e}"),
                code: 1,
            }
        }
    }
}

/// `println!` that returns a `Failure` instead of panicking when standard output
/// cannot be written (a closed pipe, a full disk): `outln!("{x}")?;`.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
            .map_err($crate::cli::shared::Failure::from_output)
    }};
}
pub(crate) use outln;

/// `print!` that returns a `Failure`, as `outln!`.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let mut stdout = std::io::stdout().lock();
        write!(stdout, $($arg)*)
            .and_then(|()| stdout.flush())
            .map_err($crate::cli::shared::Failure::from_output)
    }};
}
pub(crate) use out;

/// Whether an output path names standard output: `-`, as for every command that writes
/// a file.
pub fn is_stdout(path: &std::path::Path) -> bool {
    path.as_os_str() == "-"
}

pub use chromacal::journal::absolute_path;

/// Write `bytes` whole to standard output and flush it (a closed pipe is
/// `Failure::output_closed`).
pub fn write_stdout(bytes: &[u8]) -> Result<(), Failure> {
    use std::io::Write as _;
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(bytes)
        .and_then(|()| stdout.flush())
        .map_err(Failure::from_output)
}

impl<E: std::fmt::Display> From<E> for Failure {
    fn from(e: E) -> Self {
        Failure {
            message: e.to_string(),
            code: 1,
        }
    }
}

/// A number of the command line: finite, and what `check` allows. clap names the
/// argument when one is refused (exit 2), so no NaN or infinity goes on to be printed
/// as a result.
fn number(text: &str, check: impl Fn(f64) -> bool, what: &str) -> Result<f64, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("'{text}' is not a number"))?;
    if value.is_finite() && check(value) {
        Ok(value)
    } else {
        Err(format!("'{text}': {what}"))
    }
}

/// Above zero (a time scale, a luminance).
pub fn positive_number(text: &str) -> Result<f64, String> {
    number(
        text,
        |v| v > 0.0 && v <= 1e9,
        "give a finite number above 0 (at most 1e9)",
    )
}

/// Zero or more (a tolerance).
pub fn non_negative_number(text: &str) -> Result<f64, String> {
    number(
        text,
        |v| (0.0..=1e9).contains(&v),
        "give a finite number of 0 or more (at most 1e9)",
    )
}

/// A share, 0 to 1.
pub fn share(text: &str) -> Result<f64, String> {
    number(
        text,
        |v| (0.0..=1.0).contains(&v),
        "give a share from 0 to 1",
    )
}

/// A contrast ratio: above 1.
pub fn contrast_ratio(text: &str) -> Result<f64, String> {
    number(
        text,
        |v| v > 1.0 && v <= 1e9,
        "give a contrast ratio above 1 (at most 1e9)",
    )
}

/// The exit codes, for `--help`.
pub const EXIT_CODES: &str = "Exit codes: 0 done; 1 failed (the message says why); 2 the command line is wrong; \
3 a profile was made but missed the [publish] limits (kept, not made current); \
4 an export was written but colord could not take it; \
5 a verification ran and failed; 6 a verification ran and is undecided (`--until-decided` reads again); \
130 stopped by Ctrl-C or SIGTERM (the journal keeps every reading: `chromacal calibrate --resume`).";

/// Exit code when a profile was made but did not pass the publishing limits.
pub const NOT_PUBLISHED: u8 = 3;

/// Exit code of a calibration stopped by Ctrl-C or SIGTERM (128 + SIGINT, as a shell
/// gives it).
pub const INTERRUPTED: u8 = 130;

/// Exit code when an export was written but colord could not take it.
pub const COLORD_UNAVAILABLE: u8 = 4;

/// Exit codes of a verification that ran and failed, or stayed undecided.
pub const VERIFICATION_FAILED: u8 = 5;
pub const VERIFICATION_UNDECIDED: u8 = 6;

/// The log level: a service logs what it does, a command only what went wrong; each
/// `-v` one level more, `-q` errors only.
pub fn log_level(service: bool, verbose: u8, quiet: bool) -> &'static str {
    const LEVELS: [&str; 5] = ["error", "warn", "info", "debug", "trace"];
    let base = if service { 2 } else { 1 };
    if quiet {
        return LEVELS[0];
    }
    LEVELS[(base + verbose as usize).min(LEVELS.len() - 1)]
}

/// Log through tracing to stderr, one line per event. `CHROMACAL_LOG`, else
/// `RUST_LOG`, sets the filter when present; else [`log_level`]. No colour when stderr
/// is not a terminal (the systemd journal) or `NO_COLOR` is set (no-color.org).
pub fn init_logging(service: bool, verbose: u8, quiet: bool) {
    let filter = ["CHROMACAL_LOG", "RUST_LOG"]
        .into_iter()
        .find_map(|name| tracing_subscriber::EnvFilter::try_from_env(name).ok())
        .unwrap_or_else(|| tracing_subscriber::EnvFilter::new(log_level(service, verbose, quiet)));
    let no_color = std::env::var_os("NO_COLOR").is_some_and(|v| !v.is_empty());
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(!no_color && std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .init();
}
