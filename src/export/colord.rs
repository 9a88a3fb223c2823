//! Registering an exported ICC profile with colord, the freedesktop colour manager
//! that GNOME and KDE ask which profile a display has. colord lives on the system
//! D-Bus as `org.freedesktop.ColorManager` (its interface XML; the flow is the one
//! colormgr and DisplayCAL use, `../shared/INTERFACES.md` B4):
//!
//! 1. the profile's id is `icc-` and the hex MD5 (the header's profile ID, or the MD5
//!    of the file when that is zero); `FindProfileById`, else `CreateProfile` with its
//!    `Filename`;
//! 2. the display: `FindDeviceById`, else `CreateDevice` (kind display);
//! 3. `Device.AddProfile("hard", …)` and `Device.MakeProfileDefault(…)`.
//!
//! The system bus is the one `DBUS_SYSTEM_BUS_ADDRESS` names, else the standard socket.

use std::collections::HashMap;
use std::path::Path;

use zbus::zvariant::{ObjectPath, OwnedObjectPath};

#[zbus::proxy(
    interface = "org.freedesktop.ColorManager",
    default_service = "org.freedesktop.ColorManager",
    default_path = "/org/freedesktop/ColorManager"
)]
trait ColorManager {
    fn find_profile_by_id(&self, profile_id: &str) -> zbus::Result<OwnedObjectPath>;
    fn create_profile(
        &self,
        profile_id: &str,
        scope: &str,
        properties: HashMap<&str, &str>,
    ) -> zbus::Result<OwnedObjectPath>;
    fn find_device_by_id(&self, device_id: &str) -> zbus::Result<OwnedObjectPath>;
    fn create_device(
        &self,
        device_id: &str,
        scope: &str,
        properties: HashMap<&str, &str>,
    ) -> zbus::Result<OwnedObjectPath>;
}

#[zbus::proxy(
    interface = "org.freedesktop.ColorManager.Device",
    default_service = "org.freedesktop.ColorManager"
)]
trait ColorDevice {
    fn add_profile(&self, relation: &str, profile: &ObjectPath<'_>) -> zbus::Result<()>;
    fn make_profile_default(&self, profile: &ObjectPath<'_>) -> zbus::Result<()>;
    #[zbus(property)]
    fn profiles(&self) -> zbus::Result<Vec<OwnedObjectPath>>;
}

/// Why a profile could not be registered. The exported file is written either way.
#[derive(Debug, thiserror::Error)]
pub enum ColordError {
    #[error(
        "no system D-Bus to reach colord ({address}): {message}. The profile was written but not registered"
    )]
    NoBus { address: String, message: String },
    #[error(
        "colord is not running on the system bus ({message}). The profile was written but not registered"
    )]
    NoColord { message: String },
    #[error("colord refused {call}: {message}")]
    Refused { call: &'static str, message: String },
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}

/// What colord now holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    pub profile_id: String,
    pub profile_object: String,
    pub device_object: String,
    /// The profile was already known to colord.
    pub profile_existed: bool,
    pub device_existed: bool,
}

/// colord's id of an ICC file: `icc-` and the header ID, or the file's MD5.
pub fn colord_profile_id(bytes: &[u8]) -> String {
    use md5::{Digest, Md5};
    let header: [u8; 16] = bytes
        .get(84..100)
        .and_then(|b| b.try_into().ok())
        .unwrap_or([0; 16]);
    let id: [u8; 16] = if header == [0; 16] {
        Md5::digest(bytes).into()
    } else {
        header
    };
    format!(
        "icc-{}",
        id.iter().map(|b| format!("{b:02x}")).collect::<String>()
    )
}

fn refused(call: &'static str) -> impl Fn(zbus::Error) -> ColordError {
    move |e| ColordError::Refused {
        call,
        message: e.to_string(),
    }
}

/// Register the ICC file at `icc` as the default profile of display `device_id`.
pub async fn register(icc: &Path, device_id: &str) -> Result<Registration, ColordError> {
    let path = std::fs::canonicalize(icc).map_err(|source| ColordError::Io {
        path: icc.display().to_string(),
        source,
    })?;
    let bytes = std::fs::read(&path).map_err(|source| ColordError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let address = std::env::var("DBUS_SYSTEM_BUS_ADDRESS")
        .unwrap_or_else(|_| "unix:path=/var/run/dbus/system_bus_socket".into());
    let connection = zbus::Connection::system()
        .await
        .map_err(|e| ColordError::NoBus {
            address: address.clone(),
            message: e.to_string(),
        })?;
    let manager = ColorManagerProxy::new(&connection)
        .await
        .map_err(|e| ColordError::NoColord {
            message: e.to_string(),
        })?;
    let profile_id = colord_profile_id(&bytes);
    let filename = path.display().to_string();
    let (profile_object, profile_existed) = match manager.find_profile_by_id(&profile_id).await {
        Ok(p) => (p, true),
        Err(zbus::Error::MethodError(name, _, _)) if name.as_str().ends_with("ServiceUnknown") => {
            return Err(ColordError::NoColord {
                message: name.to_string(),
            });
        }
        Err(_) => {
            let checksum = profile_id.trim_start_matches("icc-").to_string();
            let properties = HashMap::from([
                ("Filename", filename.as_str()),
                ("FILE_checksum", checksum.as_str()),
                ("CMF_product", "chromacal"),
                ("DATA_source", "calib"),
            ]);
            let created = manager
                .create_profile(&profile_id, "normal", properties)
                .await
                .map_err(|e| match e {
                    zbus::Error::MethodError(name, _, _)
                        if name.as_str().ends_with("ServiceUnknown") =>
                    {
                        ColordError::NoColord {
                            message: name.to_string(),
                        }
                    }
                    e => refused("CreateProfile")(e),
                })?;
            (created, false)
        }
    };
    let (device_object, device_existed) = match manager.find_device_by_id(device_id).await {
        Ok(d) => (d, true),
        Err(_) => {
            let properties = HashMap::from([
                ("Kind", "display"),
                ("Mode", "physical"),
                ("Colorspace", "RGB"),
            ]);
            let created = manager
                .create_device(device_id, "normal", properties)
                .await
                .map_err(refused("CreateDevice"))?;
            (created, false)
        }
    };
    let device = ColorDeviceProxy::builder(&connection)
        .path(device_object.clone())
        .map_err(refused("Device"))?
        .build()
        .await
        .map_err(refused("Device"))?;
    let already = device
        .profiles()
        .await
        .map_err(refused("Device.Profiles"))?
        .contains(&profile_object);
    if !already {
        device
            .add_profile("hard", &profile_object)
            .await
            .map_err(refused("Device.AddProfile"))?;
    }
    device
        .make_profile_default(&profile_object)
        .await
        .map_err(refused("Device.MakeProfileDefault"))?;
    Ok(Registration {
        profile_id,
        profile_object: profile_object.to_string(),
        device_object: device_object.to_string(),
        profile_existed,
        device_existed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_id_is_the_header_id_or_the_file_md5() {
        let mut bytes = vec![0u8; 128];
        bytes[84] = 0xab;
        assert!(colord_profile_id(&bytes).starts_with("icc-ab00"));
        let zero = vec![0u8; 128];
        assert_eq!(
            colord_profile_id(&zero),
            "icc-f09f35a5637839458e462e6350ecbce4"
        );
    }
}
