//! What a child process prints, read within a bound and a time limit.
//!
//! chromacal runs other programs (ArgyllCMS's `spotread -?`, `colprof`, `xicclu`,
//! `profcheck`) and reads what they print. A program that prints without end (a
//! wrapper in a loop, a stand-in on the PATH) must not grow chromacal until the kernel
//! kills it, nor one that never ends hang it: each stream is read on a thread of its
//! own (so that a full stderr cannot block a child still writing stdout), at most
//! `limit` bytes of each are kept, and past the limit or the time the child is killed
//! and named in the error.

use std::io::{Read, Write};
use std::process::{Child, ExitStatus};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What a child printed, and how it ended.
#[derive(Debug)]
pub struct ChildOutput {
    pub status: ExitStatus,
    pub stdout: Vec<u8>,
    pub stderr: Vec<u8>,
}

/// Why a child's output could not be had.
#[derive(Debug, thiserror::Error)]
pub enum ChildError {
    #[error("{program} printed more than {limit} bytes on its {stream} (it was stopped)")]
    TooLong {
        program: String,
        stream: &'static str,
        limit: usize,
    },
    #[error("{program} did not finish within {seconds} s (it was stopped)")]
    Timeout { program: String, seconds: u64 },
    #[error("{program}: {error}")]
    Io {
        program: String,
        error: std::io::Error,
    },
}

/// Read one stream of a child, keeping at most `limit` bytes: past it, `over` is set
/// and the reading stops.
fn read_bounded(
    mut stream: impl Read + Send + 'static,
    limit: usize,
    over: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut kept = Vec::new();
        let mut chunk = [0u8; 8192];
        loop {
            match stream.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) if kept.len() + n > limit => {
                    over.store(true, Ordering::SeqCst);
                    break;
                }
                Ok(n) => kept.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
        kept
    })
}

/// Wait for `child` (spawned with its stdout and stderr piped, and its stdin piped
/// when `input` is given), feeding it `input`, keeping at most `limit` bytes of each
/// stream, for at most `timeout`. `program` names it in errors.
pub fn output_within(
    program: &str,
    mut child: Child,
    input: Option<Vec<u8>>,
    limit: usize,
    timeout: Duration,
) -> Result<ChildOutput, ChildError> {
    let stop = |child: &mut Child| {
        let _ = child.kill();
        let _ = child.wait();
    };
    let (out_over, err_over) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicBool::new(false)),
    );
    let out = child
        .stdout
        .take()
        .map(|s| read_bounded(s, limit, out_over.clone()));
    let err = child
        .stderr
        .take()
        .map(|s| read_bounded(s, limit, err_over.clone()));
    // The input on a thread too: a child that prints before reading it all would
    // otherwise fill its pipe while we fill its input's.
    if let (Some(mut stdin), Some(input)) = (child.stdin.take(), input) {
        std::thread::spawn(move || {
            let _ = stdin.write_all(&input);
        });
    }
    let deadline = Instant::now() + timeout;
    let too_long = |stream| ChildError::TooLong {
        program: program.to_string(),
        stream,
        limit,
    };
    let status = loop {
        if out_over.load(Ordering::SeqCst) {
            stop(&mut child);
            return Err(too_long("output"));
        }
        if err_over.load(Ordering::SeqCst) {
            stop(&mut child);
            return Err(too_long("error output"));
        }
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(10)),
            Ok(None) => {
                stop(&mut child);
                return Err(ChildError::Timeout {
                    program: program.to_string(),
                    seconds: timeout.as_secs(),
                });
            }
            Err(error) => {
                stop(&mut child);
                return Err(ChildError::Io {
                    program: program.to_string(),
                    error,
                });
            }
        }
    };
    let stdout = out.and_then(|t| t.join().ok()).unwrap_or_default();
    let stderr = err.and_then(|t| t.join().ok()).unwrap_or_default();
    // The child ended, but may have printed past the limit before it did.
    if out_over.load(Ordering::SeqCst) {
        return Err(too_long("output"));
    }
    if err_over.load(Ordering::SeqCst) {
        return Err(too_long("error output"));
    }
    Ok(ChildOutput {
        status,
        stdout,
        stderr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::{Command, Stdio};

    fn sh(script: &str) -> Child {
        Command::new("sh")
            .args(["-c", script])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    }

    #[test]
    fn a_child_that_prints_without_end_is_stopped_at_the_limit() {
        let result = output_within(
            "yes",
            sh("yes usage"),
            None,
            1 << 16,
            Duration::from_secs(20),
        );
        match result {
            Err(ChildError::TooLong { stream, limit, .. }) => {
                assert_eq!(stream, "output");
                assert_eq!(limit, 1 << 16);
            }
            other => panic!("{other:?}"),
        }
        let result = output_within(
            "yes",
            sh("yes usage >&2"),
            None,
            1 << 16,
            Duration::from_secs(20),
        );
        assert!(
            matches!(
                result,
                Err(ChildError::TooLong {
                    stream: "error output",
                    ..
                })
            ),
            "{result:?}"
        );
    }

    #[test]
    fn a_child_within_the_limit_gives_both_streams_and_reads_its_input() {
        let out = output_within(
            "cat",
            sh("cat; echo done >&2"),
            Some(b"three\nlines\nhere\n".to_vec()),
            1 << 16,
            Duration::from_secs(20),
        )
        .unwrap();
        assert!(out.status.success());
        assert_eq!(out.stdout, b"three\nlines\nhere\n");
        assert_eq!(out.stderr, b"done\n");
    }

    #[test]
    fn a_child_that_never_ends_is_stopped_at_the_time() {
        let started = Instant::now();
        let result = output_within(
            "sleep",
            sh("sleep 30"),
            None,
            1024,
            Duration::from_millis(300),
        );
        assert!(
            matches!(result, Err(ChildError::Timeout { .. })),
            "{result:?}"
        );
        assert!(started.elapsed() < Duration::from_secs(10));
    }
}
