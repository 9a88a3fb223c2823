//! `[[device]]` and `[instruments.NAME]`: one daemon for several display–instrument
//! pairs.
//!
//! A config without `[[device]]` is one device, named `default`, whose store is the
//! state directory itself (as before there were several). With `[[device]]` entries,
//! each is the top-level config with the entry's sections laid over it, and keeps its
//! store in `<state>/<name>/`:
//!
//! * `monitor` and `instrument` replace the top-level section whole: a device's
//!   monitor is another monitor, its instrument another instrument, and half of one
//!   merged with half of another describes neither.
//! * `display`, `plan`, `fit`, `publish`, `schedule`, `warmup` and `target` are merged
//!   key by key, so a device can change one key (say `schedule.verify_every_s`) and
//!   keep the rest.
//! * `[daemon]` and `[mqtt]` are the daemon's, not a device's.
//!
//! An instrument moved by hand between displays is declared once, as
//! `[instruments.NAME]`, and named by each device that uses it (`instrument =
//! "NAME"`): the daemon runs one job at a time on it. Two devices that open the same
//! serial port other than through one such declaration are an error, since they would
//! open it at once.

use std::collections::BTreeMap;

use super::{Config, LoadedConfig, parse_config};

/// The name of the one device of a config without `[[device]]`.
pub const DEFAULT_DEVICE: &str = "default";

/// Sections a `[[device]]` entry may give, and whether they replace the top-level
/// section (true) or are merged into it key by key.
const DEVICE_SECTIONS: [(&str, bool); 9] = [
    ("monitor", true),
    ("instrument", true),
    ("display", false),
    ("plan", false),
    ("fit", false),
    ("publish", false),
    ("schedule", false),
    ("warmup", false),
    ("target", false),
];

/// One device of the daemon: its name, its own effective config, and the shared
/// instrument it uses, if any.
#[derive(Debug, Clone)]
pub struct DeviceConfig {
    pub name: String,
    /// The top-level config with the device's sections laid over it; its `text` is
    /// that whole config, so a device's journals carry what it ran with.
    pub loaded: LoadedConfig,
    /// `[instruments.NAME]` it names: jobs of devices sharing one run one at a time.
    pub shared_instrument: Option<String>,
    /// Its store is a folder of the state directory named after it (false only for
    /// the one device of a config without `[[device]]`).
    pub own_folder: bool,
}

impl DeviceConfig {
    /// Its store: `<state>/<name>/`, or the state directory itself for the one
    /// device of a config without `[[device]]`.
    pub fn store_dir(&self, state_dir: &std::path::Path) -> std::path::PathBuf {
        match self.own_folder {
            true => state_dir.join(&self.name),
            false => state_dir.to_path_buf(),
        }
    }
}

/// Why no device was found by a name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoDevice {
    #[error("no device is named \"{name}\" (there are {known})")]
    Unknown { name: String, known: String },
    #[error(
        "there are several devices ({0}): name one (`--device NAME`, or /devices/NAME/… in the API)"
    )]
    Ambiguous(String),
}

/// The device `name` of `devices`, or without a name the only one.
pub fn find_device<'a, T>(
    devices: &'a [T],
    name: Option<&str>,
    name_of: impl Fn(&T) -> &str,
) -> Result<&'a T, NoDevice> {
    let known = || devices.iter().map(&name_of).collect::<Vec<_>>().join(", ");
    match (name, devices) {
        (Some(name), _) => {
            devices
                .iter()
                .find(|d| name_of(d) == name)
                .ok_or_else(|| NoDevice::Unknown {
                    name: name.to_string(),
                    known: known(),
                })
        }
        (None, [only]) => Ok(only),
        (None, _) => Err(NoDevice::Ambiguous(known())),
    }
}

/// A device or instrument name: it becomes a folder, a URL segment, an MQTT topic
/// level and a Prometheus label, so letters, digits, `-` and `_` only.
pub fn check_name(what: &str, name: &str) -> Result<(), String> {
    let fine = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if fine {
        Ok(())
    } else {
        Err(format!(
            "{what} name \"{name}\" must be 1 to 64 letters, digits, '-' or '_' (it names a folder, a URL and an MQTT topic)"
        ))
    }
}

/// Lay `over` onto `base` key by key (tables merged, anything else replaced).
fn merge_tables(base: &mut toml::Table, over: &toml::Table) {
    for (key, value) in over {
        match (base.get_mut(key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            _ => {
                base.insert(key.clone(), value.clone());
            }
        }
    }
}

/// Names a device may not have: its folder would sit among the store files of the
/// state directory itself (a config without `[[device]]` keeps its store there).
const RESERVED_DEVICE_NAMES: [&str; 3] = ["profiles", "runs", "lock"];

/// The devices `loaded` describes, each with its effective config, checked as far as
/// can be without opening hardware: a simulated monitor's section is resolved (its
/// preset named, its tables read), so that a daemon refuses it at start or reload
/// rather than failing its first job.
pub fn device_configs(loaded: &LoadedConfig) -> Result<Vec<DeviceConfig>, String> {
    let devices = split_devices(loaded)?;
    for device in &devices {
        let config = &device.loaded.config;
        if config.instrument.address()?.is_none() {
            config
                .monitor
                .resolve(&device.loaded.base_dir)
                .map_err(|e| match devices.len() {
                    1 if !device.own_folder => format!("[monitor]: {e}"),
                    _ => format!("device \"{}\": [monitor]: {e}", device.name),
                })?;
        }
    }
    Ok(devices)
}

/// The devices `loaded` describes, each with its effective config.
fn split_devices(loaded: &LoadedConfig) -> Result<Vec<DeviceConfig>, String> {
    let config = &loaded.config;
    if config.device.is_empty() {
        if !config.instruments.is_empty() {
            return Err(
                "[instruments.*] are shared by [[device]] entries, and there are none".into(),
            );
        }
        return Ok(vec![DeviceConfig {
            name: DEFAULT_DEVICE.into(),
            loaded: loaded.clone(),
            shared_instrument: None,
            own_folder: false,
        }]);
    }
    for name in config.instruments.keys() {
        check_name("instruments.*", name)?;
    }
    // The top level, every default filled in, without the lists of devices.
    let mut top = config.clone();
    top.device.clear();
    top.instruments.clear();
    let top = toml::Table::try_from(&top).map_err(|e| format!("the config: {e}"))?;
    let mut devices: Vec<DeviceConfig> = Vec::new();
    let mut ports: BTreeMap<String, (String, Option<String>)> = BTreeMap::new();
    let mut listeners: BTreeMap<String, String> = BTreeMap::new();
    let mut used: BTreeMap<&str, usize> = BTreeMap::new();
    for (index, entry) in config.device.iter().enumerate() {
        let at = format!("[[device]] number {}", index + 1);
        let name = match entry.get("name") {
            Some(toml::Value::String(name)) => name.clone(),
            Some(_) => return Err(format!("{at}: name must be a string")),
            None => return Err(format!("{at}: give it a name")),
        };
        check_name(&at, &name)?;
        if RESERVED_DEVICE_NAMES.contains(&name.as_str()) {
            return Err(format!(
                "{at}: \"{name}\" is reserved (the state directory's own {} are named so); name the device otherwise",
                RESERVED_DEVICE_NAMES.join(", ")
            ));
        }
        let at = format!("device \"{name}\"");
        if devices.iter().any(|d| d.name == name) {
            return Err(format!("{at} is named twice"));
        }
        let mut merged = top.clone();
        let mut shared_instrument = None;
        for (key, value) in entry {
            if key == "name" {
                continue;
            }
            let Some(&(_, replaces)) = DEVICE_SECTIONS.iter().find(|(k, _)| k == key) else {
                return Err(format!(
                    "{at}: '{key}' is not a device's section (a device takes {}; [daemon] and [mqtt] are the whole daemon's)",
                    DEVICE_SECTIONS.map(|(k, _)| k).join(", ")
                ));
            };
            let value = match (key.as_str(), value) {
                ("instrument", toml::Value::String(shared)) => {
                    let Some(instrument) = config.instruments.get(shared) else {
                        return Err(format!(
                            "{at}: instrument = \"{shared}\" names no [instruments.{shared}] (declared: {})",
                            config
                                .instruments
                                .keys()
                                .cloned()
                                .collect::<Vec<_>>()
                                .join(", ")
                        ));
                    };
                    *used.entry(shared.as_str()).or_default() += 1;
                    shared_instrument = Some(shared.clone());
                    toml::Value::Table(
                        toml::Table::try_from(instrument).map_err(|e| format!("{at}: {e}"))?,
                    )
                }
                (_, toml::Value::Table(_)) => value.clone(),
                _ => {
                    return Err(format!(
                        "{at}: '{key}' must be a table ([device.{key}]){}",
                        if key == "instrument" {
                            " or the name of an [instruments.NAME]"
                        } else {
                            ""
                        }
                    ));
                }
            };
            match (replaces, value, merged.get_mut(key)) {
                (false, toml::Value::Table(over), Some(toml::Value::Table(base))) => {
                    merge_tables(base, &over)
                }
                (_, value, _) => {
                    merged.insert(key.clone(), value);
                }
            }
        }
        let text = toml::to_string(&merged).map_err(|e| format!("{at}: {e}"))?;
        let origin = format!("{} ({at})", loaded.origin);
        let device: Config = parse_config(&text, &origin).map_err(|e| e.to_string())?;
        // One port, one instrument: devices may name it only through one shared
        // [instruments.NAME].
        if let Some(address) = device.instrument.address()?
            && let port = address.resource()
            && let Some((other, other_shared)) =
                ports.insert(port.clone(), (name.clone(), shared_instrument.clone()))
            && (shared_instrument.is_none() || other_shared != shared_instrument)
        {
            return Err(format!(
                "devices \"{other}\" and \"{name}\" both open {port}: declare the instrument once as [instruments.NAME] and name it in both (their jobs then take turns)"
            ));
        }
        // A patch page or a Resolve server listens on its address for one display.
        let listen = match device.display.sink() {
            super::Sink::Web => Some(("display.web.address", &device.display.web.address)),
            super::Sink::Resolve => {
                Some(("display.resolve.address", &device.display.resolve.address))
            }
            _ => None,
        };
        if let Some((key, address)) = listen
            && let Some(other) = listeners.insert(address.clone(), name.clone())
        {
            return Err(format!(
                "devices \"{other}\" and \"{name}\" both listen on {address}: give each display its own {key}"
            ));
        }
        // A window's output has one video LUT: two devices would fight over it.
        let screen = match device.display.sink() {
            super::Sink::Window => Some(format!(
                "X display {}",
                device.display.x_display.as_deref().unwrap_or("$DISPLAY")
            )),
            super::Sink::Wayland => Some(format!(
                "Wayland display {}",
                device
                    .display
                    .wayland_display
                    .as_deref()
                    .unwrap_or("$WAYLAND_DISPLAY")
            )),
            _ => None,
        };
        if let Some(screen) = screen {
            let output = format!(
                "{} of {screen}",
                device.display.output.clone().unwrap_or_default().describe(),
            );
            if let Some(other) = listeners.insert(output.clone(), name.clone()) {
                return Err(format!(
                    "devices \"{other}\" and \"{name}\" both put their window on {output}: give each its own display.output (one video LUT, one device)"
                ));
            }
        }
        devices.push(DeviceConfig {
            name,
            loaded: LoadedConfig {
                config: device,
                text,
                origin,
                base_dir: loaded.base_dir.clone(),
            },
            shared_instrument,
            own_folder: true,
        });
    }
    if let Some(unused) = config
        .instruments
        .keys()
        .find(|k| !used.contains_key(k.as_str()))
    {
        return Err(format!(
            "[instruments.{unused}] is named by no device: name it with instrument = \"{unused}\" in a [[device]], or remove it"
        ));
    }
    Ok(devices)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loaded(text: &str) -> Result<LoadedConfig, String> {
        Ok(LoadedConfig {
            config: parse_config(text, "test.toml").map_err(|e| e.to_string())?,
            text: text.into(),
            origin: "test.toml".into(),
            base_dir: ".".into(),
        })
    }

    fn devices(text: &str) -> Result<Vec<DeviceConfig>, String> {
        device_configs(&loaded(text)?)
    }

    #[test]
    fn a_config_without_devices_is_one_device_in_the_state_directory_itself() {
        let d = devices("[schedule]\nverify_every_s = 60.0\n").unwrap();
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].name, DEFAULT_DEVICE);
        assert!(!d[0].own_folder);
        assert_eq!(d[0].loaded.config.schedule.verify_every_s, Some(60.0));
    }

    #[test]
    fn a_device_merges_its_sections_key_by_key_and_replaces_monitor_and_instrument() {
        let text = r#"
[monitor]
preset = "lcd"
[display]
settle_s = 0.7
[schedule]
verify_every_s = 600.0
threshold_de00 = 1.5
[[device]]
name = "left"
[device.schedule]
verify_every_s = 60.0
[[device]]
name = "right"
[device.monitor]
preset = "crt"
[device.instrument.simulated]
relative_noise = 0.002
"#;
        let d = devices(text).unwrap();
        assert_eq!(d.len(), 2);
        let (left, right) = (&d[0].loaded.config, &d[1].loaded.config);
        // Merged: the one key changed, the other kept.
        assert_eq!(left.schedule.verify_every_s, Some(60.0));
        assert_eq!(left.schedule.threshold_de00, 1.5);
        assert_eq!(right.schedule.verify_every_s, Some(600.0));
        assert_eq!(left.display.settle_s, 0.7);
        // Replaced whole.
        assert_eq!(left.monitor.preset.as_deref(), Some("lcd"));
        assert_eq!(right.monitor.preset.as_deref(), Some("crt"));
        assert!(right.instrument.simulated.is_some());
        // Each device's text reads back as its own config.
        let again = parse_config(&d[1].loaded.text, "again").unwrap();
        assert_eq!(&again, right);
        assert!(
            d.iter()
                .all(|d| d.own_folder && d.shared_instrument.is_none())
        );
    }

    #[test]
    fn a_shared_instrument_is_declared_once_and_named_by_each_device() {
        let text = r#"
[instruments.meter.simulated]
relative_noise = 0.003
[[device]]
name = "a"
instrument = "meter"
[[device]]
name = "b"
instrument = "meter"
[[device]]
name = "c"
"#;
        let d = devices(text).unwrap();
        assert_eq!(d[0].shared_instrument.as_deref(), Some("meter"));
        assert_eq!(d[1].shared_instrument.as_deref(), Some("meter"));
        assert_eq!(d[2].shared_instrument, None);
        assert_eq!(
            d[0].loaded
                .config
                .instrument
                .simulated
                .as_ref()
                .unwrap()
                .relative_noise,
            0.003
        );
        // A serial port shared the declared way is no conflict (each page on its own
        // address).
        let serial = "[display]\nsink = \"web\"\n[instruments.x]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[[device]]\nname = \"a\"\ninstrument = \"x\"\n[[device]]\nname = \"b\"\ninstrument = \"x\"\n[device.display.web]\naddress = \"127.0.0.1:8081\"\n";
        assert_eq!(devices(serial).unwrap().len(), 2);
    }

    #[test]
    fn a_device_is_found_by_name_or_as_the_only_one() {
        let names = ["a", "b"];
        assert_eq!(find_device(&names, Some("b"), |n| n), Ok(&"b"));
        assert!(
            matches!(find_device(&names, None, |n| n), Err(NoDevice::Ambiguous(k)) if k == "a, b")
        );
        assert!(matches!(
            find_device(&names, Some("c"), |n| n),
            Err(NoDevice::Unknown { .. })
        ));
        assert_eq!(find_device(&names[..1], None, |n| n), Ok(&"a"));
        let dir = std::path::Path::new("/state");
        let d = devices("[[device]]\nname = \"x\"\n").unwrap();
        assert_eq!(d[0].store_dir(dir), dir.join("x"));
        let d = devices("").unwrap();
        assert_eq!(d[0].store_dir(dir), dir);
    }

    #[test]
    fn device_mistakes_are_named() {
        let cases = [
            ("[[device]]\n", "give it a name"),
            ("[[device]]\nname = \"a b\"\n", "letters, digits"),
            (
                "[[device]]\nname = \"a\"\n[[device]]\nname = \"a\"\n",
                "named twice",
            ),
            (
                "[[device]]\nname = \"a\"\n[device.daemon]\nstop_timeout_s = 1.0\n",
                "whole daemon's",
            ),
            (
                "[[device]]\nname = \"a\"\ninstrument = \"nope\"\n",
                "names no [instruments.nope]",
            ),
            (
                "[instruments.spare.simulated]\n[[device]]\nname = \"a\"\n",
                "named by no device",
            ),
            ("[instruments.meter.simulated]\n", "there are none"),
            ("[[device]]\nname = \"runs\"\n", "\"runs\" is reserved"),
            (
                "[[device]]\nname = \"a\"\n[[device]]\nname = \"b\"\n[device.monitor]\npreset = \"plasma\"\n",
                "device \"b\": [monitor]",
            ),
            ("[monitor]\npreset = \"plasma\"\n", "[monitor]"),
            (
                "[[device]]\nname = \"a\"\n[device.schedule]\nthreshold_de00 = -1.0\n",
                "device \"a\"",
            ),
            (
                "[[device]]\nname = \"a\"\n[device.display]\nsink = \"web\"\n[device.instrument]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[[device]]\nname = \"b\"\n[device.display]\nsink = \"web\"\n[device.instrument]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n",
                "both open /dev/ttyUSB0",
            ),
            // Two patch pages on one address.
            (
                "[display]\nsink = \"web\"\n[instruments.x]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[[device]]\nname = \"a\"\ninstrument = \"x\"\n[[device]]\nname = \"b\"\ninstrument = \"x\"\n",
                "both listen on 127.0.0.1:8080",
            ),
            // Two declarations of one port, and a shared one beside a device's own.
            (
                "[display]\nsink = \"web\"\n[instruments.x]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[instruments.y]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[[device]]\nname = \"a\"\ninstrument = \"x\"\n[[device]]\nname = \"b\"\ninstrument = \"y\"\n",
                "both open /dev/ttyUSB0",
            ),
            (
                "[display]\nsink = \"web\"\n[instruments.x]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n[[device]]\nname = \"a\"\ninstrument = \"x\"\n[[device]]\nname = \"b\"\n[device.instrument]\ndriver = \"pr670\"\nport = \"/dev/ttyUSB0\"\n",
                "both open /dev/ttyUSB0",
            ),
        ];
        for (text, expected) in cases {
            let error = devices(text).expect_err(text);
            assert!(error.contains(expected), "{text}: {error}");
        }
    }
}
