//! Monitors' EDIDs as the kernel read them: each DRM connector's `edid` file under
//! `/sys/class/drm/card*-*/` (`card0-DP-1/edid`: card 0's connector DP-1). Wayland
//! compositors give no EDID to clients, and some X drivers put none on their RandR
//! outputs (XWayland, some proprietary ones); the kernel has it either way. The root
//! is `/sys` unless `CHROMACAL_SYSFS_ROOT` names another (a directory laid out the
//! same way, as the tests give).

use std::path::{Path, PathBuf};

/// The variable that moves the sysfs root (for tests and for a system whose sysfs is
/// mounted elsewhere).
pub const SYSFS_ROOT_VARIABLE: &str = "CHROMACAL_SYSFS_ROOT";

/// Largest EDID read: a base block and up to 255 extensions of 128 bytes.
const MAX_EDID_BYTES: u64 = 128 * 256;

/// One connector's EDID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConnectorEdid {
    /// The connector's name as the kernel gives it: `DP-1`, `HDMI-A-1`, `eDP-1`.
    pub connector: String,
    /// The file it was read from.
    pub path: PathBuf,
    pub edid: Vec<u8>,
}

/// The sysfs root: `CHROMACAL_SYSFS_ROOT`, else `/sys`.
pub fn sysfs_root() -> PathBuf {
    std::env::var_os(SYSFS_ROOT_VARIABLE)
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("/sys"), PathBuf::from)
}

/// Every connector under `root/class/drm` with an EDID (a connector with no monitor
/// has an empty file), ordered by name. What cannot be read is left out: an EDID is
/// an aid to naming a monitor, never a reason to fail.
pub fn connector_edids(root: &Path) -> Vec<ConnectorEdid> {
    let Ok(entries) = std::fs::read_dir(root.join("class/drm")) else {
        return Vec::new();
    };
    let mut found: Vec<ConnectorEdid> = entries
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            let connector = connector_of(&name)?;
            let path = entry.path().join("edid");
            let edid = chromacal_formats::durable::read_limited(&path, MAX_EDID_BYTES).ok()?;
            (!edid.is_empty()).then(|| ConnectorEdid {
                connector: connector.to_string(),
                path,
                edid,
            })
        })
        .collect();
    found.sort_by(|a, b| a.connector.cmp(&b.connector).then(a.path.cmp(&b.path)));
    found
}

/// `DP-1` of `card0-DP-1`; `None` for `card0` itself and what is not a connector.
fn connector_of(entry: &str) -> Option<&str> {
    let rest = entry.strip_prefix("card")?;
    let (card, connector) = rest.split_once('-')?;
    (!card.is_empty() && card.bytes().all(|b| b.is_ascii_digit()) && !connector.is_empty())
        .then_some(connector)
}

/// The EDID of the connector an output of `name` is on, when exactly one connector
/// matches: the same name (`DP-1`, `eDP-1`, as the modesetting driver and the
/// compositors name them), or the modesetting driver's `HDMI-1` for the kernel's
/// `HDMI-A-1`. Two cards with a connector of the same name leave it undecided.
pub fn edid_for_output<'a>(edids: &'a [ConnectorEdid], name: &str) -> Option<&'a ConnectorEdid> {
    let renamed = |kernel: &str| {
        kernel
            .strip_prefix("HDMI-A-")
            .is_some_and(|n| name.strip_prefix("HDMI-") == Some(n))
    };
    let matching: Vec<&ConnectorEdid> = edids
        .iter()
        .filter(|e| e.connector == name || renamed(&e.connector))
        .collect();
    match matching[..] {
        [one] => Some(one),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connector_names_come_from_the_directory_names() {
        assert_eq!(connector_of("card0-DP-1"), Some("DP-1"));
        assert_eq!(connector_of("card1-HDMI-A-2"), Some("HDMI-A-2"));
        assert_eq!(connector_of("card0"), None);
        assert_eq!(connector_of("renderD128"), None);
        assert_eq!(connector_of("cardX-DP-1"), None);
        assert_eq!(connector_of("card0-"), None);
    }

    fn edid(connector: &str, card: u32) -> ConnectorEdid {
        ConnectorEdid {
            connector: connector.into(),
            path: PathBuf::from(format!("/sys/class/drm/card{card}-{connector}/edid")),
            edid: vec![0; 128],
        }
    }

    #[test]
    fn outputs_find_their_connector_by_name_or_by_modesetting_s_hdmi_name() {
        let edids = [edid("DP-1", 0), edid("HDMI-A-1", 0), edid("eDP-1", 0)];
        assert_eq!(edid_for_output(&edids, "DP-1"), Some(&edids[0]));
        assert_eq!(edid_for_output(&edids, "HDMI-A-1"), Some(&edids[1]));
        assert_eq!(edid_for_output(&edids, "HDMI-1"), Some(&edids[1]));
        assert_eq!(edid_for_output(&edids, "eDP-1"), Some(&edids[2]));
        assert_eq!(edid_for_output(&edids, "DP-2"), None);
        assert_eq!(edid_for_output(&edids, "HDMI-2"), None);
        // Two cards with a DP-1 each: not decided by a guess.
        let two = [edid("DP-1", 0), edid("DP-1", 1)];
        assert_eq!(edid_for_output(&two, "DP-1"), None);
    }
}
