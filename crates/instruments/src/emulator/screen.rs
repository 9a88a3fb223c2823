//! The emulator's screen link: until the display issue brings the Resolve link, a
//! calibration run tells an emulator in another process what the screen shows over a
//! local (Unix) socket. One JSON line per patch, answered with `ok`.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use chromacal_model::screen::ScreenContent;
use chromacal_sim::monitor::VirtualMonitor;

/// One message: what to show, and how long the display takes to settle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenMessage {
    pub content: ScreenContent,
    pub settle_s: f64,
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
            Err(e) => format!("error: {e}\n"),
        };
        if writer.write_all(reply.as_bytes()).is_err() {
            return;
        }
    }
}
