//! The web patch page in a real browser: headless Chromium loads it, paints what the
//! run shows and acknowledges; screenshots taken after each acknowledgement are read
//! back pixel by pixel.

#[path = "common/browser.rs"]
mod browser;

use std::time::Duration;

use browser::{Browser, Image};
use chromacal_display::PatchDisplay;
use chromacal_display::web::{WebConfig, WebDisplay};
use chromacal_model::screen::{Codes, Geometry, Patch};

fn codes(rgb: [u32; 3]) -> Codes {
    Codes { rgb, bit_depth: 8 }
}

async fn serve() -> WebDisplay {
    WebDisplay::bind(
        WebConfig {
            address: "127.0.0.1:0".into(),
            ..WebConfig::default()
        },
        0.0,
    )
    .await
    .unwrap()
}

/// Check that `image` shows `patch` exactly: every pixel inside the geometry is the
/// patch colour, every pixel outside is the background.
fn assert_painted(image: &Image, patch: &Patch) {
    let g = patch.geometry;
    let (w, h) = (image.width as f64, image.height as f64);
    let (x0, x1) = (
        (g.x * w).round() as u32,
        ((g.x + g.width) * w).round() as u32,
    );
    let (y0, y1) = (
        (g.y * h).round() as u32,
        ((g.y + g.height) * h).round() as u32,
    );
    let fg = patch.codes.rgb.map(|c| c as u8);
    let bg = patch.background.rgb.map(|c| c as u8);
    let mut wrong = Vec::new();
    for y in 0..image.height {
        for x in 0..image.width {
            let inside = (x0..x1).contains(&x) && (y0..y1).contains(&y);
            let want = if inside { fg } else { bg };
            if image.pixel(x, y) != want {
                wrong.push((x, y, image.pixel(x, y), want));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "{} of {} pixels wrong, first: {:?}",
        wrong.len(),
        image.width * image.height,
        &wrong[..wrong.len().min(5)]
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_paints_each_patch_exactly_where_asked_and_acknowledges_it() {
    let mut display = serve().await;
    let url = display.url();
    let patches = [
        Patch {
            codes: codes([255, 128, 0]),
            background: codes([32, 48, 64]),
            geometry: Geometry {
                x: 0.25,
                y: 0.25,
                width: 0.5,
                height: 0.5,
            },
        },
        // Codes one step from black and white, where a colour-managed or dithered
        // path would show.
        Patch {
            codes: codes([1, 2, 3]),
            background: codes([254, 253, 252]),
            geometry: Geometry {
                x: 0.0,
                y: 0.6,
                width: 0.3,
                height: 0.4,
            },
        },
        Patch {
            codes: codes([127, 128, 129]),
            background: codes([0, 0, 0]),
            geometry: Geometry {
                x: 0.0,
                y: 0.0,
                width: 1.0,
                height: 1.0,
            },
        },
    ];
    let mut browser = tokio::task::spawn_blocking(move || Browser::open(&url, 400, 300))
        .await
        .unwrap();
    for (n, patch) in patches.iter().enumerate() {
        tokio::time::timeout(Duration::from_secs(30), display.show(patch))
            .await
            .expect("the page never acknowledged")
            .unwrap();
        assert_eq!(display.acknowledged(), n as u64 + 1);
        let (b, image) = tokio::task::spawn_blocking(move || {
            let image = browser.screenshot();
            (browser, image)
        })
        .await
        .unwrap();
        browser = b;
        assert_eq!((image.width, image.height), (400, 300));
        assert_painted(&image, patch);
    }
    display.blank().await.unwrap();
    let image = tokio::task::spawn_blocking(move || browser.screenshot())
        .await
        .unwrap();
    assert_eq!(image.pixel(200, 150), [0, 0, 0]);
}

/// An HTTP agent that returns 4xx and 5xx answers instead of failing on them.
fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into()
}

/// GET `url` on a blocking thread: (status, content type, body).
async fn get(url: String) -> (u16, String, String) {
    tokio::task::spawn_blocking(move || {
        let mut reply = agent().get(&url).call().unwrap();
        let content_type = reply
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_string();
        (
            reply.status().as_u16(),
            content_type,
            reply.body_mut().read_to_string().unwrap(),
        )
    })
    .await
    .unwrap()
}

async fn post(url: String) -> u16 {
    tokio::task::spawn_blocking(move || agent().post(&url).send_empty().unwrap().status().as_u16())
        .await
        .unwrap()
}

/// Open the event stream by hand and return the first `data:` line.
/// The first event that carries a shown patch (id 1 on): a client that connects
/// before the patch is published first gets the page's state before it (id 0).
fn first_event(address: std::net::SocketAddr) -> (std::net::TcpStream, String) {
    use std::io::{BufRead, BufReader, Write};
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    stream
        .write_all(b"GET /events HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n")
        .unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut line = String::new();
    loop {
        line.clear();
        assert!(reader.read_line(&mut line).unwrap() > 0, "the stream ended");
        if let Some(data) = line.trim().strip_prefix("data:") {
            let shown = serde_json::from_str::<serde_json::Value>(data.trim())
                .ok()
                .and_then(|state| state["id"].as_u64())
                .is_some_and(|id| id >= 1);
            if shown {
                return (stream, data.trim().to_string());
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn show_waits_for_the_acknowledgement_and_only_for_it() {
    let mut display = serve().await;
    let base = display.url();
    let address = display.local_addr();
    let patch = Patch {
        codes: codes([10, 20, 30]),
        background: codes([0, 0, 0]),
        geometry: Geometry::centred(0.1),
    };
    let client = tokio::task::spawn_blocking(move || first_event(address));
    let showing = tokio::spawn(async move {
        display.show(&patch).await.unwrap();
        display
    });
    let (_stream, data) = client.await.unwrap();
    let state: serde_json::Value = serde_json::from_str(&data).unwrap();
    let id = state["id"].as_u64().unwrap();
    // The page has the patch but has not confirmed it: the run must still be waiting.
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(
        !showing.is_finished(),
        "show returned before the page acknowledged"
    );
    // The page can acknowledge only what was shown.
    assert_eq!(post(format!("{base}ack?id={}", id + 1)).await, 400);
    assert_eq!(post(format!("{base}ack")).await, 400);
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(!showing.is_finished());
    assert_eq!(post(format!("{base}ack?id={id}")).await, 204);
    let display = tokio::time::timeout(Duration::from_secs(5), showing)
        .await
        .expect("show did not return after the acknowledgement")
        .unwrap();
    assert_eq!(display.acknowledged(), id);
    // Nothing else is served, and the page cannot be used to change anything.
    assert_eq!(get(format!("{base}config")).await.0, 404);
    assert_eq!(post(format!("{base}events")).await, 405);
    let (status, content_type, page) = get(base.clone()).await;
    assert_eq!(status, 200);
    assert!(content_type.starts_with("text/html"));
    assert!(!page.contains("<button") && !page.contains("<input") && !page.contains("<form"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_browser_that_never_paints_is_reported_lost() {
    let mut display = WebDisplay::bind(
        WebConfig {
            address: "127.0.0.1:0".into(),
            ack_timeout_s: 0.5,
            ..WebConfig::default()
        },
        0.0,
    )
    .await
    .unwrap();
    let address = display.local_addr();
    // A connected client (a hidden tab, say) that receives but never acknowledges.
    let client = tokio::task::spawn_blocking(move || first_event(address));
    let result = tokio::time::timeout(
        Duration::from_secs(10),
        display.show(&Patch {
            codes: codes([1, 1, 1]),
            background: codes([0, 0, 0]),
            geometry: Geometry::centred(0.2),
        }),
    )
    .await
    .expect("show hung instead of reporting the display lost");
    let _ = client.await;
    let error = result.unwrap_err().to_string();
    assert!(
        error.contains("did not confirm painting patch 1"),
        "{error}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_argyll_endpoint_answers_as_argyll_does() {
    let mut display = serve().await;
    let base = display.url();
    let first = Patch {
        codes: codes([26, 128, 230]),
        background: codes([0, 0, 0]),
        geometry: Geometry::centred(0.2),
    };
    // Argyll's page polls with its current background as the (ignored) query.
    let showing = tokio::spawn(async move {
        display.show(&first).await.unwrap();
        display
    });
    tokio::time::sleep(Duration::from_millis(100)).await;
    let (status, content_type, body) = get(format!("{base}ajax/messages?%23808080")).await;
    assert_eq!(
        (status, content_type.as_str(), body.as_str()),
        (200, "text/plain", "#1A80E6")
    );
    // Receipt is not yet acknowledged: that takes the next poll, which then waits for
    // the next colour.
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!showing.is_finished());
    let poll = tokio::spawn(get(format!("{base}ajax/messages?%231A80E6%200.123")));
    let mut display = tokio::time::timeout(Duration::from_secs(5), showing)
        .await
        .expect("the next poll did not acknowledge")
        .unwrap();
    assert_eq!(display.acknowledged(), 1);
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        !poll.is_finished(),
        "the poll should be held until a new colour"
    );
    let second = Patch {
        codes: codes([255, 0, 1]),
        ..first
    };
    let showing = tokio::spawn(async move {
        display.show(&second).await.unwrap();
        display
    });
    let (_, _, body) = tokio::time::timeout(Duration::from_secs(5), poll)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(body, "#FF0001");
    // The next poll acknowledges, then is held; closing the display lets it go.
    let held = tokio::spawn(get(format!("{base}ajax/messages?%23FF0001")));
    let display = tokio::time::timeout(Duration::from_secs(5), showing)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(display.acknowledged(), 2);
    drop(display);
    let (status, _, _) = tokio::time::timeout(Duration::from_secs(5), held)
        .await
        .expect("a held poll outlived the display")
        .unwrap();
    assert_eq!(status, 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_displaycal_form_carries_background_and_geometry() {
    let mut display = serve().await;
    let base = display.url();
    let patch = Patch {
        codes: codes([255, 128, 0]),
        background: codes([32, 48, 64]),
        geometry: Geometry {
            x: 0.25,
            y: 0.25,
            width: 0.5,
            height: 0.5,
        },
    };
    let showing = tokio::spawn(async move {
        display.show(&patch).await.unwrap();
        display
    });
    // DisplayCAL's client sends its current six fields and a random number, encoded.
    let (status, content_type, body) = get(format!(
        "{base}ajax/messages?%23808080%7C%23808080%7C0%7C0%7C1%7C1%7C0.42"
    ))
    .await;
    assert_eq!(status, 200);
    assert_eq!(content_type, "text/plain; charset=UTF-8");
    assert_eq!(body, "#FF8000|#203040|0.2500|0.2500|0.5000|0.5000");
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!showing.is_finished());
    // Reporting the new pattern as shown acknowledges it.
    let echo = body.replace('|', "%7C").replace('#', "%23");
    let held = tokio::spawn(get(format!("{base}ajax/messages?{echo}%7C0.7")));
    let display = tokio::time::timeout(Duration::from_secs(5), showing)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(display.acknowledged(), 1);
    drop(display);
    tokio::time::timeout(Duration::from_secs(5), held)
        .await
        .expect("a held poll outlived the display")
        .unwrap();
}
