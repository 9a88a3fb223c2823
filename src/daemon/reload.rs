//! Rereading the config in a running daemon: SIGHUP (systemd's `ExecReload`),
//! `chromacal daemon reload` and `POST /reload`.
//!
//! Only the devices change. A device the new config adds starts at once; one it
//! removes or changes is *retired*: it takes no new job, its running job carries on
//! to its end, and then it leaves, giving back its store's lock, so that a changed
//! device starts again on its new config (schedule, thresholds, monitor, instrument)
//! with the same store. Devices the reload leaves as they were are not touched, nor
//! are their jobs. A config that does not load or check is refused as a whole and the
//! daemon runs on with the one it had; so is one whose new devices' stores cannot be
//! locked. `[daemon]` (listeners, limits, token) and `[mqtt]` apply at the next
//! restart: the reload says so.

use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;

use super::events::Event;
use super::{Daemon, Device, open_device, restore_device, start_device_jobs};
use crate::config::{DeviceConfig, device_configs};

/// What a reload changed.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Reloaded {
    /// Devices started.
    pub added: Vec<String>,
    /// Devices retired for good (after their running job).
    pub removed: Vec<String>,
    /// Devices retired and started again on their new config (after their job).
    pub changed: Vec<String>,
    /// Sections whose changes wait for a restart.
    pub restart_needed: Vec<String>,
}

/// What makes two configs of a device the same device: everything but the daemon's
/// own sections, which a reload does not apply (so a change there restarts no device).
fn fingerprint(config: &DeviceConfig) -> String {
    let mut device = config.loaded.config.clone();
    device.daemon = Default::default();
    device.mqtt = None;
    format!(
        "{}\n{:?}\n{}\n{}",
        toml::to_string(&device).unwrap_or_default(),
        config.shared_instrument,
        config.own_folder,
        config.loaded.base_dir.display()
    )
}

/// The daemon-wide sections that differ between `old` and `new`.
fn restart_needed(old: &crate::config::Config, new: &crate::config::Config) -> Vec<String> {
    fn text<T: Serialize>(section: &T) -> String {
        serde_json::to_string(section).unwrap_or_default()
    }
    let mut sections = Vec::new();
    if text(&old.daemon) != text(&new.daemon) {
        sections.push("[daemon]".to_string());
    }
    if text(&old.mqtt) != text(&new.mqtt) {
        sections.push("[mqtt]".to_string());
    }
    sections
}

impl Daemon {
    /// Reread the config and apply it to the devices; the outcome is logged and told
    /// as an event (`config_reloaded` or `config_refused`) and in the metrics.
    pub async fn reload(self: &Arc<Self>, origin: &str) -> Result<Reloaded, String> {
        let _one_at_a_time = self.reloading.lock().await;
        let outcome = self.apply_reload();
        match &outcome {
            Ok(r) => {
                tracing::info!(
                    origin,
                    added = ?r.added,
                    removed = ?r.removed,
                    changed = ?r.changed,
                    "config reloaded"
                );
                if !r.restart_needed.is_empty() {
                    tracing::warn!(sections = ?r.restart_needed, "changes to these sections take effect at the next restart");
                }
                self.bus.publish_daemon(Event::ConfigReloaded {
                    origin: origin.into(),
                    added: r.added.clone(),
                    removed: r.removed.clone(),
                    changed: r.changed.clone(),
                    restart_needed: r.restart_needed.clone(),
                });
            }
            Err(error) => {
                tracing::error!(origin, %error, "config reload refused; the daemon runs on with the config it had");
                self.bus.publish_daemon(Event::ConfigRefused {
                    origin: origin.into(),
                    error: error.clone(),
                });
            }
        }
        outcome
    }

    /// The reload proper: nothing changes unless all of it can.
    fn apply_reload(self: &Arc<Self>) -> Result<Reloaded, String> {
        if self.is_shutting_down() {
            return Err("the daemon is shutting down".into());
        }
        let loaded = self.options.load_config()?;
        let configs = device_configs(&loaded).map_err(|e| match e.contains(&loaded.origin) {
            true => e,
            false => format!("{}: {e}", loaded.origin),
        })?;
        let mut wanted = self.wanted.lock().map_err(|_| "poisoned".to_string())?;
        let serving = self.devices();
        let mut reloaded = Reloaded {
            restart_needed: restart_needed(&self.loaded.config, &loaded.config),
            ..Reloaded::default()
        };
        // The new devices' stores are locked before anything changes: a store another
        // process holds refuses the reload.
        let keep = self.loaded.config.daemon.keep_profiles;
        let mut opened = Vec::new();
        for config in &configs {
            let known = wanted.iter().any(|w| w.name == config.name);
            let serving_now = serving.iter().any(|d| d.name == config.name);
            if known {
                continue;
            }
            reloaded.added.push(config.name.clone());
            // A device of this name still finishing a job (retired by an earlier
            // reload) is followed by its successor when that job ends.
            if !serving_now {
                let device = open_device(
                    config.clone(),
                    keep,
                    &self.options.state_dir,
                    &self.turns,
                    &self.bus,
                )
                .map_err(|e| format!("device \"{}\": {e}", config.name))?;
                opened.push(device);
            }
        }
        for old in wanted.iter() {
            match configs.iter().find(|c| c.name == old.name) {
                None => reloaded.removed.push(old.name.clone()),
                Some(new) if fingerprint(new) != fingerprint(old) => {
                    reloaded.changed.push(old.name.clone())
                }
                Some(_) => {}
            }
        }
        *wanted = configs;
        drop(wanted);

        for name in reloaded.removed.iter().chain(&reloaded.changed) {
            if let Some(device) = serving.iter().find(|d| &d.name == name && !d.is_retired()) {
                device.retire();
                tokio::spawn(self.clone().replace_when_idle(device.clone()));
            }
        }
        for device in opened {
            self.bus.metrics.add_device(&device.name);
            if let Ok(mut devices) = self.devices.write() {
                devices.push(device.clone());
            }
            restore_device(&device);
            start_device_jobs(&device);
        }
        self.tell_mqtt_devices();
        Ok(reloaded)
    }

    /// Once `old`'s running job has ended, take it out of the daemon, give back its
    /// store, and start its successor if the newest config still has the device.
    async fn replace_when_idle(self: Arc<Self>, old: Arc<Device>) {
        let far = tokio::time::Instant::now() + Duration::from_secs(86_400 * 365);
        old.wait_idle(far).await;
        let _one_at_a_time = self.reloading.lock().await;
        if self.is_shutting_down() {
            return;
        }
        // Leave the screen black and the instrument out of remote mode; the
        // successor opens them again.
        if let Some(mut hardware) = old.hardware.lock().await.take() {
            use chromacal_display::PatchDisplay;
            let _ = tokio::time::timeout(Duration::from_secs(2), hardware.display.blank()).await;
            hardware.instrument.close();
        }
        if let Ok(mut lock) = old.store_lock.lock() {
            lock.take();
        }
        let successor = self
            .wanted
            .lock()
            .ok()
            .and_then(|w| w.iter().find(|c| c.name == old.name).cloned());
        let new = match successor {
            None => None,
            Some(config) => match open_device(
                config,
                self.loaded.config.daemon.keep_profiles,
                &self.options.state_dir,
                &self.turns,
                &self.bus,
            ) {
                Ok(device) => Some(device),
                Err(e) => {
                    tracing::error!(device = %old.name, error = %e, "the changed device cannot start; it is left out until the next reload");
                    None
                }
            },
        };
        if let Ok(mut devices) = self.devices.write() {
            match (devices.iter().position(|d| Arc::ptr_eq(d, &old)), &new) {
                (Some(at), Some(new)) => devices[at] = new.clone(),
                (Some(at), None) => {
                    devices.remove(at);
                }
                (None, Some(new)) => devices.push(new.clone()),
                (None, None) => {}
            }
        }
        match &new {
            Some(device) => {
                tracing::info!(device = %device.name, "device started again on its new config");
                restore_device(device);
                start_device_jobs(device);
            }
            None => {
                tracing::info!(device = %old.name, "device left the daemon");
                self.bus.metrics.remove_device(&old.name);
                if let Some(mqtt) = self.bus.mqtt.get() {
                    mqtt.forget_device(&old.name);
                }
            }
        }
        self.tell_mqtt_devices();
    }

    /// The retained status names the devices serving.
    fn tell_mqtt_devices(&self) {
        if let Some(mqtt) = self.bus.mqtt.get() {
            let names: Vec<String> = self.devices().iter().map(|d| d.name.clone()).collect();
            mqtt.set_devices(&names);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{LoadedConfig, parse_config};

    fn devices(text: &str) -> Vec<DeviceConfig> {
        let loaded = LoadedConfig {
            config: parse_config(text, "test").unwrap(),
            text: text.into(),
            origin: "test".into(),
            base_dir: "/".into(),
        };
        device_configs(&loaded).unwrap()
    }

    #[test]
    fn a_device_changes_with_its_sections_and_not_with_the_daemons() {
        let base = "[[device]]\nname = \"a\"\n[[device]]\nname = \"b\"\n";
        let old = devices(base);
        let daemon_only = devices(&format!("[daemon]\nkeep_profiles = 7\n{base}"));
        assert_eq!(fingerprint(&old[0]), fingerprint(&daemon_only[0]));
        let schedule = devices(&format!("{base}[device.schedule]\nverify_every_s = 60.0\n"));
        assert_eq!(fingerprint(&old[0]), fingerprint(&schedule[0]));
        assert_ne!(fingerprint(&old[1]), fingerprint(&schedule[1]));
        let top = devices(&format!("[schedule]\nthreshold_de00 = 3.0\n{base}"));
        assert_ne!(fingerprint(&old[0]), fingerprint(&top[0]));
        let old_config = parse_config(base, "t").unwrap();
        let new_config =
            parse_config(&format!("[daemon]\nkeep_profiles = 7\n{base}"), "t").unwrap();
        assert_eq!(restart_needed(&old_config, &new_config), ["[daemon]"]);
        assert!(restart_needed(&old_config, &old_config).is_empty());
    }
}
