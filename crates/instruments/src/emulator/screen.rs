//! The emulator's screen link: a calibration run tells an emulator in another process
//! what the screen shows over a local (Unix) socket, one JSON line per patch, answered
//! with `ok`; and a test sets the monitor's own controls (its on-screen display) on the
//! same socket, as a user would press its buttons.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use chromacal_model::screen::ScreenContent;
use chromacal_sim::monitor::{Osd, VirtualMonitor};

/// One message: what to show, and how long the display takes to settle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenMessage {
    pub content: ScreenContent,
    pub settle_s: f64,
}

/// The other message: the monitor's own controls set, as a user sets them on its
/// on-screen display (`{"osd": {"gains": [1, 0.95, 0.9], "brightness": 0.8}}`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OsdMessage {
    pub osd: Osd,
}

/// Serve screen updates for `monitor` on a socket at `path` (removed first if stale).
pub fn serve_screen(path: &Path, monitor: Arc<Mutex<VirtualMonitor>>) -> std::io::Result<PathBuf> {
    let _ = std::fs::remove_file(path);
    let listener = UnixListener::bind(path)?;
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let monitor = monitor.clone();
            std::thread::spawn(move || serve_client(stream, monitor));
        }
    });
    Ok(path.to_path_buf())
}

fn serve_client(stream: UnixStream, monitor: Arc<Mutex<VirtualMonitor>>) {
    let Ok(mut writer) = stream.try_clone() else {
        return;
    };
    for line in BufReader::new(stream).lines() {
        let Ok(line) = line else { return };
        let reply = match serde_json::from_str::<ScreenMessage>(&line) {
            Ok(message) => match monitor.lock() {
                Ok(mut m) => {
                    m.show(message.content);
                    m.clock().advance(message.settle_s);
                    "ok\n".to_string()
                }
                Err(_) => "error: the virtual monitor is gone\n".to_string(),
            },
            Err(e) => match serde_json::from_str::<OsdMessage>(&line) {
                Ok(message) => match monitor.lock() {
                    Ok(mut m) => match m.set_osd(message.osd) {
                        Ok(()) => "ok\n".to_string(),
                        Err(e) => format!("error: {e}\n"),
                    },
                    Err(_) => "error: the virtual monitor is gone\n".to_string(),
                },
                Err(_) => format!("error: {e}\n"),
            },
        };
        if writer.write_all(reply.as_bytes()).is_err() {
            return;
        }
    }
}
