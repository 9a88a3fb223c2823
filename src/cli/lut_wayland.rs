//! `chromacal lut` on Wayland: the curves where the compositor applies them
//! (`calibrate::wayland_lut`): held through wlroots' gamma control, set as the
//! output's profile through KDE's kscreen-doctor, or registered with colord for GNOME.

use std::borrow::Cow;
use std::path::Path;

use super::shared::{Failure, outln};
use chromacal::calibrate::wayland_lut::{
    CurvesPath, find_output, hold_until_gone, holder, load_kde, release_held, reset_kde, write_icc,
};
use chromacal::export::calibration_for;
use chromacal::profile::Profile;
use chromacal::profile::store::ProfileStore;
use chromacal_display::wayland::gamma::{GammaOffer, gamma_offers};
use chromacal_display::wayland::offered_interfaces;
use chromacal_display::x11::OutputSelector;
use chromacal_model::target::Target;

/// What `lut` is asked to do, on a Wayland output.
pub enum Action {
    /// Load the profile at this path (its curves, or curves for `target`).
    Load {
        profile: Option<std::path::PathBuf>,
        hold: bool,
        target: Option<Target>,
    },
    Show {
        json: bool,
    },
    Reset,
    Save,
}

/// `lut` on Wayland display `name`, output `output`, curves `via` (auto when `None`).
pub fn run(
    action: Action,
    name: &str,
    output: Option<&str>,
    via: Option<CurvesPath>,
    state_dir: &Path,
) -> Result<(), Failure> {
    let name = Some(name);
    let selector = output.map(OutputSelector::parse).unwrap_or_default();
    let output = find_output(name, &selector)?;
    let via = match via {
        Some(via) => via,
        None => CurvesPath::of_interfaces(&offered_interfaces(name)?),
    };
    let store = ProfileStore::new(state_dir);
    match action {
        Action::Load {
            profile,
            hold,
            target,
        } => {
            let path = profile.unwrap_or_else(|| store.current_path());
            let profile = Profile::read(&path)?;
            match via {
                CurvesPath::Wlroots => {
                    let (model, said_of_greys) = profile.output_model();
                    let curves = calibration_for(&profile, &model, target.as_ref())?
                        .ok_or_else(|| {
                            format!(
                                "{} carries no calibration curves: calibrate with a [target], or give --white/--tone",
                                path.display()
                            )
                        })?;
                    // Curves solved now go through the greys where the model does.
                    if let (Some(_), Cow::Owned(_), Some(said)) = (&target, &model, &said_of_greys)
                    {
                        eprintln!("chromacal: {said}");
                    }
                    if !hold {
                        return Err(Failure::from(
                            chromacal::calibrate::wayland_lut::WaylandLutError::NotHeld.to_string(),
                        ));
                    }
                    let mut said = Ok(());
                    let mut say = |line: &str| {
                        if said.is_ok() {
                            said = outln!("{line} (from {})", path.display());
                        }
                    };
                    hold_until_gone(name, &selector, &curves, &profile.id, state_dir, &mut say)?;
                    said?;
                }
                CurvesPath::Kde => {
                    let icc = write_icc(&profile, target.as_ref(), &output.name, state_dir)?;
                    load_kde(&output.name, &icc)?;
                    outln!(
                        "set {} (the profile {} with its curves in vcgt) as the colour profile of {} through kscreen-doctor; KWin applies it",
                        icc.display(),
                        profile.id,
                        output.name
                    )?;
                }
                CurvesPath::Colord => {
                    let icc = write_icc(&profile, target.as_ref(), &output.name, state_dir)?;
                    let edid = output
                        .edid
                        .as_deref()
                        .and_then(|b| chromacal_formats::edid::Edid::parse(b).ok());
                    let device = chromacal_formats::edid::colord_device_id(
                        edid.as_ref(),
                        &output.name,
                        chromacal::calibrate::displays::pnp_vendor_name,
                    );
                    let registered = tokio::runtime::Builder::new_current_thread()
                        .enable_all()
                        .build()?
                        .block_on(chromacal::export::colord::register(&icc, &device))
                        .map_err(|e| format!("colord: {e}"))?;
                    if !registered.device_existed {
                        return Err(Failure::from(format!(
                            "colord had no device {device}: the desktop did not register this monitor under that id, so it would not apply the profile (registered on a new device). `colormgr get-devices` lists the ones it has; give that id to `chromacal export --register-colord ID`"
                        )));
                    }
                    outln!(
                        "colord: {} ({}) is the default profile of {device}; GNOME applies it, vcgt included",
                        registered.profile_id,
                        icc.display()
                    )?;
                }
            }
        }
        Action::Show { json } => {
            let offer = gamma_offers(name)?
                .into_iter()
                .find(|(n, _)| *n == output.name)
                .map(|(_, g)| g);
            let held = holder(state_dir, &output.name);
            if json {
                outln!(
                    "{}",
                    serde_json::to_string_pretty(&serde_json::json!({
                        "output": output.name,
                        "via": via,
                        "gamma": offer,
                        "held_by": held,
                    }))?
                )?;
            } else {
                outln!(
                    "{} on Wayland: curves go {}",
                    output.name,
                    match via {
                        CurvesPath::Wlroots =>
                            "into its gamma ramp (wlr-gamma-control), held by a client",
                        CurvesPath::Kde => "into its colour profile's vcgt (KWin, kscreen-doctor)",
                        CurvesPath::Colord =>
                            "into its colour profile's vcgt (colord; GNOME applies it)",
                    }
                )?;
                if let Some(offer) = offer.filter(|_| held.is_none()) {
                    outln!("  {}", offer.describe())?;
                }
                match held {
                    Some(h) => outln!(
                        "  held by chromacal lut load --hold (pid {}), profile {}",
                        h.pid,
                        h.profile
                    )?,
                    None if via == CurvesPath::Wlroots => outln!(
                        "  held by no chromacal process{}",
                        match offer {
                            Some(GammaOffer::Size(_)) => ": the compositor's own ramp",
                            _ => " (another program may hold it)",
                        }
                    )?,
                    None => {}
                }
            }
        }
        Action::Reset => match via {
            CurvesPath::Wlroots => match release_held(
                state_dir,
                &chromacal_display::wayland::socket_path(name)?
                    .display()
                    .to_string(),
                &output.name,
            ) {
                Some(h) => outln!(
                    "stopped chromacal's holder of the gamma ramp of {} (pid {}): the compositor's own ramp is back",
                    output.name,
                    h.pid
                )?,
                None => outln!(
                    "no chromacal process holds the gamma ramp of {}: it is the compositor's own",
                    output.name
                )?,
            },
            CurvesPath::Kde => {
                reset_kde(&output.name)?;
                outln!(
                    "{} is back on sRGB, without a profile (kscreen-doctor)",
                    output.name
                )?;
            }
            CurvesPath::Colord => {
                return Err(Failure::from(
                    "on GNOME the output's profile is colord's: choose another in Settings → Colour (chromacal does not remove profiles from colord)",
                ));
            }
        },
        Action::Save => {
            return Err(Failure::from(
                "no Wayland protocol reads a gamma ramp back: lut save works on X11 only (the curves are the profile's: export --format cal)",
            ));
        }
    }
    Ok(())
}
