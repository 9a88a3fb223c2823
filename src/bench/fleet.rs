//! `chromacal bench fleet`: how many devices one daemon carries on this machine.
//!
//! For each fleet size it starts a real `chromacal daemon` (this binary, a child
//! process) with that many simulated devices at a time scale of 1e-6, so that the
//! simulated monitor's settle and integration times are next to nothing and what is
//! left per patch is the daemon's own work: the simulated reading, the journal's
//! write and fsync, the events, the metrics and (when Mosquitto is installed) the MQTT
//! messages. It calibrates every device at once, follows `GET /events` from outside
//! as a client would, and prints per fleet size: the events per second the daemon
//! sent, and each device's time per patch (between its first and last reading, as
//! the client saw them) — the per-patch overhead.

use std::fmt::Write as _;

use super::{BenchError, Tables};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::daemon::client::{Endpoint, follow_events_at, request};
use crate::report::table;

/// Fleet sizes measured.
const SIZES: [usize; 5] = [1, 4, 8, 16, 32];

/// A child process stopped (SIGTERM, then SIGKILL) when dropped.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A loopback port nothing listens on now.
fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| e.to_string())
}

/// Mosquitto on a loopback port, if it is installed.
fn broker(dir: &Path) -> Result<Option<(Child, u16)>, String> {
    let Some(program) = ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
        .into_iter()
        .find(|p| Path::new(p).is_file())
    else {
        return Ok(None);
    };
    let port = free_port()?;
    let config = dir.join("mosquitto.conf");
    std::fs::write(
        &config,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"),
    )
    .map_err(|e| e.to_string())?;
    let child = Command::new(program)
        .arg("-c")
        .arg(&config)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("{program}: {e}"))?;
    let child = Child(child);
    let deadline = Instant::now() + Duration::from_secs(10);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if Instant::now() > deadline {
            return Err("mosquitto did not start".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(Some((child, port)))
}

/// What one fleet size measured.
struct Run {
    events: usize,
    seconds: f64,
    /// Each device's seconds per patch.
    per_patch: Vec<f64>,
    patches: usize,
    mqtt: Option<(f64, f64)>,
}

/// A number from the metrics text: the first line that starts with `name`.
fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find(|l| l.starts_with(name))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

fn run_fleet(devices: usize, dir: &Path, mqtt: Option<u16>) -> Result<Run, String> {
    let dir = dir.join(format!("fleet-{devices}"));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let mut config = String::from(
        "[daemon]\nsimulated_time_scale = 0.000001\nsimulated_idle_ages = false\nmax_event_streams = 4\n",
    );
    if let Some(port) = mqtt {
        config += &format!("[mqtt]\nbroker = \"127.0.0.1:{port}\"\nhost = \"bench\"\n");
    }
    for i in 0..devices {
        config += &format!("[[device]]\nname = \"d{i}\"\n");
        if i % 2 == 1 {
            config += "[device.monitor]\npreset = \"lcd\"\n";
        }
    }
    let config_path = dir.join("config.toml");
    std::fs::write(&config_path, config).map_err(|e| e.to_string())?;
    let socket = dir.join("api.sock");
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let _daemon = Child(
        Command::new(exe)
            .arg("daemon")
            .arg("--config")
            .arg(&config_path)
            .arg("--state-dir")
            .arg(dir.join("state"))
            .arg("--socket")
            .arg(&socket)
            .arg("-q")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| e.to_string())?,
    );
    let deadline = Instant::now() + Duration::from_secs(20);
    while std::os::unix::net::UnixStream::connect(&socket).is_err() {
        if Instant::now() > deadline {
            return Err("the daemon did not start".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let endpoint = Endpoint::Unix(socket);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    runtime.block_on(async {
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        let follower = {
            let endpoint = endpoint.clone();
            tokio::spawn(async move {
                let _ = follow_events_at(&endpoint, "/events", |name, data| {
                    let device = serde_json::from_str::<serde_json::Value>(data)
                        .ok()
                        .and_then(|v| v["device"].as_str().map(String::from))
                        .unwrap_or_default();
                    tx.send((Instant::now(), name.to_string(), device)).is_ok()
                })
                .await;
            })
        };
        tokio::time::sleep(Duration::from_millis(200)).await;
        let started = Instant::now();
        for i in 0..devices {
            let body = bytes::Bytes::from_static(br#"{"kind": "calibrate"}"#);
            let reply = request(
                &endpoint,
                "POST",
                &format!("/devices/d{i}/jobs"),
                Some(body),
            )
            .await
            .map_err(|e| e.to_string())?;
            if reply.status != 202 {
                return Err(format!("d{i}: {}", reply.text()));
            }
        }
        let mut finished = 0;
        let mut events = 0;
        let mut progress: std::collections::BTreeMap<String, Vec<Instant>> = Default::default();
        let deadline = tokio::time::Instant::now() + Duration::from_secs(900);
        while finished < devices {
            let Ok(Some((at, name, device))) = tokio::time::timeout_at(deadline, rx.recv()).await
            else {
                return Err(format!(
                    "{finished} of {devices} calibrations ended in time"
                ));
            };
            events += 1;
            match name.as_str() {
                "progress" => progress.entry(device).or_default().push(at),
                "job_finished" => finished += 1,
                _ => {}
            }
        }
        let seconds = started.elapsed().as_secs_f64();
        follower.abort();
        let per_patch: Vec<f64> = progress
            .values()
            .filter(|t| t.len() > 1)
            .filter_map(|t| {
                let span = t.last()?.duration_since(*t.first()?).as_secs_f64();
                Some(span / (t.len() - 1) as f64)
            })
            .collect();
        let patches = progress.values().map(Vec::len).sum();
        let metrics = request(&endpoint, "GET", "/metrics", None)
            .await
            .map_err(|e| e.to_string())?
            .text();
        let mqtt = mqtt.and_then(|_| {
            Some((
                metric(&metrics, "chromacal_mqtt_messages_queued_total")?,
                metric(&metrics, "chromacal_mqtt_messages_dropped_total")?,
            ))
        });
        Ok(Run {
            events,
            seconds,
            per_patch,
            patches,
            mqtt,
        })
    })
}

/// The fleet table; `quick` stops at 8 devices.
pub(super) fn fleet_table(out: &mut Tables, quick: bool) -> Result<(), BenchError> {
    let dir = tempfile_dir()?;
    let broker = broker(&dir)?;
    let port = broker.as_ref().map(|(_, p)| *p);
    writeln!(
        out.text,
        "one daemon, N simulated devices calibrating at once (time scale 1e-6: the per-patch time is the daemon's own work), {} cores{}:",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        if port.is_some() {
            ", events also to a Mosquitto broker on loopback"
        } else {
            " (Mosquitto not installed: no MQTT)"
        }
    )?;
    let mut rows = Vec::new();
    for devices in SIZES.into_iter().filter(|n| !quick || *n <= 8) {
        let run = run_fleet(devices, &dir, port)?;
        let mut per_patch = run.per_patch.clone();
        per_patch.sort_by(f64::total_cmp);
        let median = per_patch
            .get(per_patch.len() / 2)
            .copied()
            .unwrap_or(f64::NAN);
        let worst = per_patch.last().copied().unwrap_or(f64::NAN);
        rows.push(vec![
            devices.to_string(),
            run.patches.to_string(),
            format!("{:.1}", run.seconds),
            format!("{:.0}", run.events as f64 / run.seconds),
            format!("{:.2}", median * 1e3),
            format!("{:.2}", worst * 1e3),
            run.mqtt.map_or("-".into(), |(queued, dropped)| {
                format!("{queued:.0} / {dropped:.0}")
            }),
        ]);
    }
    write!(
        out.text,
        "{}",
        table(
            &[
                "devices",
                "readings",
                "seconds",
                "events/s",
                "ms/patch median",
                "ms/patch worst",
                "MQTT queued / dropped",
            ],
            &rows
        )
    )?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A scratch directory for the daemons' state (removed after).
fn tempfile_dir() -> Result<std::path::PathBuf, String> {
    let dir = std::env::temp_dir().join(format!("chromacal-bench-fleet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    Ok(dir)
}
