//! The Resolve server against a pattern generator over real TCP: the generator is the
//! virtual monitor (`run_client`), which shows what it reads off the socket.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use chromacal_display::PatchDisplay;
use chromacal_display::resolve::{
    ClientOptions, Flavour, ResolveConfig, ResolveDisplay, run_client,
};
use chromacal_model::screen::{Codes, Geometry, Patch, ScreenContent};
use chromacal_sim::monitor::VirtualMonitor;

mod common;

/// A generator client on its own thread, stopped when dropped.
struct Generator {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Generator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn generator(
    address: String,
    monitor: Arc<Mutex<VirtualMonitor>>,
    options: ClientOptions,
) -> Generator {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let thread = std::thread::spawn(move || run_client(&address, monitor, options, flag));
    Generator {
        stop,
        thread: Some(thread),
    }
}

async fn server(config: ResolveConfig) -> ResolveDisplay {
    ResolveDisplay::bind(
        ResolveConfig {
            address: "127.0.0.1:0".into(),
            ..config
        },
        0.0,
    )
    .await
    .unwrap()
}

fn patches(bit_depth: u32) -> Vec<Patch> {
    let max = Codes::max(bit_depth);
    (0..6u32)
        .map(|i| Patch {
            codes: Codes {
                rgb: [
                    max * i / 5,
                    max - max * i / 5,
                    (max / 3 + 17 * i) % (max + 1),
                ],
                bit_depth,
            },
            background: Codes {
                rgb: [max / 5, max / 4, max / 3],
                bit_depth,
            },
            geometry: Geometry {
                x: 0.05 * i as f64,
                y: 0.1,
                width: 0.3,
                height: 0.25,
            },
        })
        .collect()
}

/// Does the generator's screen show `want`, within `tolerance` per channel?
fn shows(shown: &ScreenContent, want: &ScreenContent, tolerance: f64) -> bool {
    let (g, w) = (shown.geometry, want.geometry);
    (0..3).all(|c| {
        (shown.patch[c] - want.patch[c]).abs() <= tolerance
            && (shown.background[c] - want.background[c]).abs() <= tolerance
    }) && (g.x - w.x).abs() < 1e-4
        && (g.y - w.y).abs() < 1e-4
        && (g.width - w.width).abs() < 1e-4
        && (g.height - w.height).abs() < 1e-4
}

/// Show each patch and check the generator's screen afterwards. The Resolve protocol
/// has no acknowledgement (the generator answers nothing), so `show` returns once the
/// message is sent and the settle time has passed; on a loaded machine the
/// generator's thread may paint a moment later. The screen must come to show exactly
/// the patch within a second.
async fn show_and_check(
    display: &mut ResolveDisplay,
    monitor: &Arc<Mutex<VirtualMonitor>>,
    patches: &[Patch],
    tolerance: f64,
) {
    for patch in patches {
        tokio::time::timeout(Duration::from_secs(20), display.show(patch))
            .await
            .expect("show hung")
            .unwrap();
        let want = patch.content();
        let deadline = std::time::Instant::now() + Duration::from_secs(1);
        loop {
            let shown = *monitor.lock().unwrap().screen();
            if shows(&shown, &want, tolerance) {
                break;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "{shown:?} vs {want:?}"
            );
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_generator_shows_exactly_what_is_sent_in_each_flavour_and_range() {
    for (flavour, video_levels, bits, tolerance) in [
        (Flavour::Cm, false, 8, 0.0),
        (Flavour::Cm, false, 10, 0.0),
        (Flavour::Cm, true, 10, 0.5 / 876.0),
        (Flavour::Ls, false, 8, 0.0),
    ] {
        let mut display = server(ResolveConfig {
            flavour,
            video_levels,
            ..ResolveConfig::default()
        })
        .await;
        let monitor = common::virtual_monitor("crt", [0.0; 3]);
        let _generator = generator(
            display.local_addr().unwrap().to_string(),
            monitor.clone(),
            ClientOptions {
                video_levels,
                ..ClientOptions::default()
            },
        );
        let mut sent = patches(bits);
        if flavour == Flavour::Ls {
            // LightSpace has no background: the generator shows black around the patch.
            for p in &mut sent {
                p.background = Codes {
                    rgb: [0; 3],
                    bit_depth: 8,
                };
            }
        }
        show_and_check(&mut display, &monitor, &sent, tolerance).await;
        assert_eq!(display.disconnections, 0);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_run_waits_for_a_generator_and_sends_again_after_a_drop() {
    let mut display = server(ResolveConfig::default()).await;
    let address = display.local_addr().unwrap().to_string();
    let monitor = common::virtual_monitor("crt", [0.0; 3]);
    let sent = patches(8);
    // No generator yet: the patch waits.
    let waiting = tokio::time::timeout(Duration::from_millis(400), display.show(&sent[0])).await;
    assert!(
        waiting.is_err(),
        "show returned with no generator connected"
    );
    // A generator that drops its connection after its second pattern and comes back.
    let _generator = generator(
        address,
        monitor.clone(),
        ClientOptions {
            drop_after: Some(2),
            reconnect_after_s: 0.3,
            ..ClientOptions::default()
        },
    );
    show_and_check(&mut display, &monitor, &sent, 0.0).await;
    assert_eq!(display.disconnections, 1);
}

#[tokio::test]
async fn no_generator_within_the_connect_timeout_is_a_clean_error() {
    let mut display = server(ResolveConfig {
        connect_timeout_s: Some(0.3),
        ..ResolveConfig::default()
    })
    .await;
    let error = display.show(&patches(8)[0]).await.unwrap_err().to_string();
    assert!(error.contains("no pattern generator connected"), "{error}");
}
