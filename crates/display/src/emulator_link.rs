//! A patch display that is the screen of an emulator running in another process
//! (`chromacal emulate`), reached over its screen socket.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

use super::{DisplayError, PatchDisplay};
use chromacal_instruments::emulator::screen::ScreenMessage;
use chromacal_model::screen::{Patch, ScreenContent};

/// The emulator's virtual monitor, as a display.
pub struct EmulatorScreen {
    path: PathBuf,
    stream: BufReader<UnixStream>,
    settle_s: f64,
}

impl EmulatorScreen {
    pub fn connect(path: &Path, settle_s: f64) -> Result<Self, DisplayError> {
        let stream = UnixStream::connect(path)
            .map_err(|e| DisplayError::Lost(format!("{}: {e}", path.display())))?;
        Ok(EmulatorScreen {
            path: path.to_path_buf(),
            stream: BufReader::new(stream),
            settle_s,
        })
    }

    fn send(&mut self, content: ScreenContent, settle_s: f64) -> Result<(), DisplayError> {
        let lost = |e: std::io::Error| DisplayError::Lost(format!("{}: {e}", self.path.display()));
        let message = serde_json::to_string(&ScreenMessage { content, settle_s })
            .map_err(|e| DisplayError::Lost(e.to_string()))?;
        let stream = self.stream.get_mut();
        stream
            .write_all(format!("{message}\n").as_bytes())
            .map_err(lost)?;
        let mut reply = String::new();
        self.stream.read_line(&mut reply).map_err(lost)?;
        if reply.trim() == "ok" {
            Ok(())
        } else {
            Err(DisplayError::Lost(format!(
                "{}: the emulator answered '{}'",
                self.path.display(),
                reply.trim()
            )))
        }
    }
}

impl PatchDisplay for EmulatorScreen {
    fn name(&self) -> String {
        format!("emulator screen at {}", self.path.display())
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        let settle = self.settle_s;
        self.send(patch.content(), settle)
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        self.send(ScreenContent::default(), 0.0)
    }
}
