//! The daemon keeps each window device's calibration in its video LUT: the current
//! profile's curves are loaded at start, after every job (a job measures through the
//! straight ramp), after a publish or a rollback, after a RandR change of the X
//! screen (a monitor plugged in, a mode changed) and after the machine resumes from
//! suspend (logind's `PrepareForSleep(false)`). Every `display.lut_check_s` the LUT is
//! read back; a ramp something else wrote (a game, a night-light tool) is reported as
//! `lut_overwritten` and, with `display.keep_lut`, replaced.
//!
//! Where a desktop loads curves itself from colord (GNOME's gsd-color, xiccd), the
//! keeper says so once and leaves the LUT alone.
//!
//! One thread a device: X calls are blocking, short, and this keeps them off the
//! runtime. It talks to the rest of the daemon through the event bus only.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use tokio::sync::broadcast::error::TryRecvError;

use super::events::Event;
use super::jobs::current_profile;
use super::{Device, DeviceEvent};
use crate::calibrate::keep_lut::made_on_another_monitor;
use crate::calibrate::video_lut::desktop_lut_loader;
use crate::config::Sink;
use chromacal_display::x11::watch::Watch;
use chromacal_display::x11::{GammaRamp, OutputSelector, X11Error};

/// How often the keeper looks at its inputs.
const TICK: Duration = Duration::from_millis(100);

/// Start the keeper of `device`'s LUT, if its patches go to the native window.
pub(crate) fn start(device: &Arc<Device>) {
    if device.loaded.config.display.sink() != Sink::Window {
        return;
    }
    let device = device.clone();
    let events = device.bus.events.subscribe();
    let spawned = std::thread::Builder::new()
        .name(format!("lut-{}", device.name))
        .spawn(move || Keeper::new(device).run(events));
    if let Err(e) = spawned {
        tracing::error!(error = %e, "cannot start the video LUT keeper");
    }
}

struct Keeper {
    device: Arc<Device>,
    /// The bus's count of resumes from suspend when the keeper last looked.
    resumes_seen: u64,
    selector: OutputSelector,
    /// What the keeper last loaded (none: nothing to keep, or a job holds the LUT).
    expected: Option<GammaRamp>,
    /// A load is due, and why.
    due: Option<&'static str>,
    next_check: Instant,
    warned: Option<String>,
    /// The output's ownership (`keep_lut::own_output`), while the keeper has it.
    owned: Option<(String, std::fs::File)>,
}

impl Keeper {
    fn new(device: Arc<Device>) -> Self {
        let selector = device
            .loaded
            .config
            .display
            .output
            .clone()
            .unwrap_or_default();
        Keeper {
            resumes_seen: device.bus.resumes.load(Ordering::SeqCst),
            device,
            selector,
            expected: None,
            due: Some("start"),
            next_check: Instant::now(),
            warned: None,
            owned: None,
        }
    }

    fn check_every(&self) -> Duration {
        Duration::from_secs_f64(self.device.loaded.config.display.lut_check_s.max(1.0))
    }

    /// Warn once for each different reason.
    fn warn_once(&mut self, message: String) {
        if self.warned.as_deref() != Some(message.as_str()) {
            tracing::warn!(device = %self.device.name, "{message}");
            self.warned = Some(message);
        }
    }

    fn run(mut self, mut events: tokio::sync::broadcast::Receiver<DeviceEvent>) {
        let x_display = self.device.loaded.config.display.x_display.clone();
        let mut watch: Option<Watch> = None;
        // A device retired by a reload leaves its LUT to the device that replaces it.
        while !self.device.is_shutting_down() && !self.device.is_retired() {
            loop {
                match events.try_recv() {
                    Ok(e) if e.device == self.device.name => self.on_event(&e.event),
                    Ok(_) => {}
                    // A job's end may be among what was missed.
                    Err(TryRecvError::Lagged(_)) => self.due = Some("events were missed"),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Closed) => return,
                }
            }
            let resumes = self.device.bus.resumes.load(Ordering::SeqCst);
            if resumes != self.resumes_seen {
                self.resumes_seen = resumes;
                self.due = Some("resume from suspend");
            }
            if watch.is_none() {
                match Watch::open(x_display.as_deref(), &self.selector) {
                    Ok(w) => {
                        watch = Some(w);
                        self.warned = None;
                    }
                    Err(e) => {
                        self.warn_once(format!("cannot reach the video LUT: {e}"));
                        std::thread::sleep(Duration::from_secs(1));
                        continue;
                    }
                }
            }
            if let Some(w) = &watch
                && self
                    .owned
                    .as_ref()
                    .is_none_or(|(name, _)| *name != w.output.name)
            {
                let holder = format!(
                    "chromacal daemon on {} (device {})",
                    self.device.store().root().display(),
                    self.device.name
                );
                match crate::calibrate::keep_lut::own_output(
                    x_display.as_deref(),
                    &w.output.name,
                    &holder,
                ) {
                    Ok(file) => self.owned = Some((w.output.name.clone(), file)),
                    Err(owned) => {
                        self.warn_once(format!("{} is also kept by {}", w.output.name, owned.0))
                    }
                }
            }
            if let Some(w) = &mut watch {
                match w.randr_changed() {
                    Ok(true) => {
                        // A hotplug or a mode change: the output may have a new CRTC.
                        match w.x.output(&self.selector) {
                            Ok(output) => w.output = output,
                            Err(e) => self.warn_once(e.to_string()),
                        }
                        self.due = Some("the X screen changed (RandR)");
                    }
                    Ok(false) => {}
                    Err(e) => {
                        self.warn_once(format!("lost the X display: {e}"));
                        watch = None;
                        continue;
                    }
                }
            }
            // A job sets the LUT itself (straight, then the curves it measures).
            if self.device.job().is_none()
                && let Some(w) = &watch
            {
                let due = self.due.take();
                let result = match due {
                    Some(reason) => self.load(w, reason),
                    None if Instant::now() >= self.next_check => self.check(w),
                    None => Ok(()),
                };
                if let Err(e) = result {
                    self.warn_once(format!("video LUT of {}: {e}", w.output.name));
                    // Tried again once the display is reached again.
                    self.due = due;
                    watch = None;
                }
            }
            std::thread::sleep(TICK);
        }
    }

    fn on_event(&mut self, event: &Event) {
        match event {
            Event::JobStarted { .. } => self.expected = None,
            Event::JobFinished { .. } => self.due = Some("a job ended"),
            Event::Published { .. } => self.due = Some("a profile was published"),
            Event::RolledBack { .. } => self.due = Some("rolled back"),
            _ => {}
        }
    }

    /// Load the current profile's curves (the straight ramp for a profile without
    /// any: it was measured through one); nothing without a current profile.
    fn load(&mut self, w: &Watch, reason: &'static str) -> Result<(), X11Error> {
        self.next_check = Instant::now() + self.check_every();
        let Some(profile) = current_profile(&self.device) else {
            self.expected = None;
            return Ok(());
        };
        if let Some(loader) = desktop_lut_loader() {
            self.warn_once(format!(
                "{loader} loads the video LUT of {}: chromacal leaves it alone (export the profile to colord instead: `chromacal export --register-colord`)",
                w.output.name
            ));
            self.expected = None;
            return Ok(());
        }
        // The profile of another monitor (a laptop docked: the external monitor
        // became the primary output) is not loaded onto this one.
        if let Some(why) = made_on_another_monitor(&profile, &w.output) {
            self.warn_once(why);
            self.expected = None;
            return Ok(());
        }
        let size = w.output.gamma_size;
        if size < 2 {
            self.warn_once(format!(
                "{} has no video LUT chromacal can set",
                w.output.name
            ));
            self.expected = None;
            return Ok(());
        }
        let ramp = match &profile.calibration {
            Some(c) => GammaRamp::from_curves(&c.curves, size),
            None => GammaRamp::identity(size),
        };
        w.x.set_gamma(&w.output, &ramp)?;
        tracing::info!(device = %self.device.name, output = %w.output.name, profile = %profile.id, reason, "video LUT loaded");
        self.expected = Some(ramp);
        self.device.emit(Event::LutLoaded {
            output: w.output.name.clone(),
            profile_id: profile.id,
            reason: reason.to_string(),
        });
        Ok(())
    }

    /// Read the LUT back; report (and with `keep_lut` replace) a foreign ramp.
    fn check(&mut self, w: &Watch) -> Result<(), X11Error> {
        self.next_check = Instant::now() + self.check_every();
        let Some(expected) = &self.expected else {
            return Ok(());
        };
        let actual = w.x.gamma(&w.output)?;
        let steps = actual.max_difference(expected);
        if steps <= 1.0 {
            return Ok(());
        }
        let keep = self.device.loaded.config.display.keep_lut;
        tracing::warn!(device = %self.device.name, output = %w.output.name, steps, reloading = keep, "something else overwrote the video LUT");
        self.device.emit(Event::LutOverwritten {
            output: w.output.name.clone(),
            steps,
            reloading: keep,
        });
        if keep {
            self.due = Some("the LUT was overwritten");
        } else {
            // Said once; watched again after the next load.
            self.expected = None;
        }
        Ok(())
    }
}

/// Count a resume in `bus` whenever logind says the machine woke (`PrepareForSleep(false)` on
/// the system bus). Without a system bus this does nothing.
pub(crate) async fn watch_resume(bus: Arc<super::Bus>) {
    use tokio_stream::StreamExt;
    let Ok(connection) = zbus::Connection::system().await else {
        tracing::debug!("no system bus: resume from suspend is not watched");
        return;
    };
    let rule = zbus::MatchRule::builder()
        .msg_type(zbus::message::Type::Signal)
        .interface("org.freedesktop.login1.Manager")
        .and_then(|r| r.member("PrepareForSleep"))
        .map(|r| r.build());
    let Ok(rule) = rule else {
        return;
    };
    let Ok(mut stream) = zbus::MessageStream::for_match_rule(rule, &connection, None).await else {
        tracing::debug!("cannot watch logind's PrepareForSleep");
        return;
    };
    while let Some(Ok(message)) = stream.next().await {
        if let Ok(false) = message.body().deserialize::<bool>() {
            tracing::info!("the machine resumed from suspend");
            bus.resumes.fetch_add(1, Ordering::SeqCst);
        }
    }
}
