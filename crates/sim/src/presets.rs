//! Virtual monitors: the built-in presets and the `[monitor]` config section that
//! picks one, changes it, or builds one from files of real measurements.
//!
//! The presets carry only data the program may ship (colour-science's display
//! primaries), with transfer laws typical of their kind. A monitor whose transfer is a
//! real measured table and whose primaries are real spectra is built from files, e.g.
//! the ISETBio tables in `../shared/data/displays`:
//!
//! ```toml
//! [monitor]
//! primaries_csv = "../shared/data/displays/spd/isetbio_crt_dell_spd.csv"
//! transfer_csv = "../shared/data/displays/gamma/isetbio_crt_dell_gamma.csv"
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::hdr::{Abl, HdrBehaviour};
use super::monitor::{
    Failures, MeasuredTransfer, MonitorSpec, PrimarySpectra, SimError, SimTransfer,
};
use chromacal_model::plan::Signal;
use chromacal_model::transfer::{Cowan, GainOffsetGamma, Power, TransferLaw};

/// Names of the built-in virtual monitors.
pub const PRESET_NAMES: [&str; 4] = ["crt", "lcd", "hdr-oled", "hdr-lcd"];

/// A built-in virtual monitor.
///
/// * `crt`: the "typical CRT" phosphors of Brainard (1997), gain-offset-gamma transfer
///   (Berns 1996) with a small cut-off, 100 cd/m² white, 15 % falloff at the corners
///   (Brainard measured up to 20 %).
/// * `lcd`: the Apple Studio Display primaries (Fairchild & Wyble 1998), a Cowan law
///   whose toe is lifted as LCD curves are, 160 cd/m² white, 1000:1 contrast, 5 %
///   falloff.
/// * `hdr-oled`: an OLED TV in its PQ mode (`hdr`; its HLG mode for a run sending HLG,
///   `MonitorSpec::in_mode`): 800 cd/m² on a small window,
///   180 on a full field (the limiter, time constant 2 s), BT.2390 roll-off from a
///   4,000 cd/m² master, black clipped below 0.02 cd/m², 10 bits; panel laws off the
///   nominal 2.2 by ±0.06. Its emitters are the CRT's phosphors (the only other
///   spectra the program may ship); `primaries_csv` puts real ones in.
/// * `hdr-lcd`: a 1,000 cd/m² LCD with a global-dimming backlight (floor 10 %) and
///   600 cd/m² full-field white, 4,000:1 native contrast, 10 bits.
pub fn preset(name: &str) -> Result<MonitorSpec, SimError> {
    match name.to_ascii_lowercase().as_str() {
        "crt" => Ok(MonitorSpec {
            name: "crt".into(),
            primaries: PrimarySpectra::typical_crt(),
            transfer: SimTransfer::Laws([
                TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.040, 2.45)),
                TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.050, 2.40)),
                TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.030, 2.52)),
            ]),
            white_luminance: Some(100.0),
            black_luminance: 0.02,
            flare_luminance: 0.05,
            bit_depth: 8,
            falloff: [0.15; 3],
            failures: Failures::default(),
            hdr: None,
        }),
        "lcd" => {
            let toe = 1.0 / 255.0;
            Ok(MonitorSpec {
                name: "lcd".into(),
                primaries: PrimarySpectra::apple_studio_display(),
                transfer: SimTransfer::Laws([
                    TransferLaw::Cowan(Cowan {
                        a: 2.30,
                        b: 0.060,
                        toe,
                    }),
                    TransferLaw::Cowan(Cowan {
                        a: 2.25,
                        b: 0.050,
                        toe,
                    }),
                    TransferLaw::Cowan(Cowan {
                        a: 2.20,
                        b: 0.045,
                        toe,
                    }),
                ]),
                white_luminance: Some(160.0),
                black_luminance: 0.16,
                flare_luminance: 0.05,
                bit_depth: 8,
                falloff: [0.05; 3],
                failures: Failures::default(),
                hdr: None,
            })
        }
        "hdr-oled" => Ok(MonitorSpec {
            name: "hdr-oled".into(),
            // The program ships no OLED spectra: give primaries_csv for real ones
            // (ISETBio's Sony OLED, say).
            primaries: PrimarySpectra::typical_crt(),
            // The panel's own transfer: near the nominal 2.2 the processing inverts,
            // not on it, and not the same in each channel (the tracking error).
            transfer: SimTransfer::Laws([
                TransferLaw::Power(Power { gamma: 2.26 }),
                TransferLaw::Power(Power { gamma: 2.20 }),
                TransferLaw::Power(Power { gamma: 2.14 }),
            ]),
            white_luminance: Some(800.0),
            black_luminance: 0.0005,
            flare_luminance: 0.01,
            bit_depth: 10,
            falloff: [0.03; 3],
            failures: Failures::default(),
            hdr: Some(HdrBehaviour {
                decodes: Signal::Pq,
                rolloff_from: 4000.0,
                panel_gamma: 2.2,
                black_clip: 0.02,
                abl: Some(Abl {
                    full_field: 180.0,
                    sharpness: 4.0,
                    time_constant_s: 2.0,
                }),
                global_dimming_floor: None,
            }),
        }),
        "hdr-lcd" => {
            let toe = 1.0 / 1023.0;
            let cowan = |a: f64, b: f64| TransferLaw::Cowan(Cowan { a, b, toe });
            Ok(MonitorSpec {
                name: "hdr-lcd".into(),
                primaries: PrimarySpectra::apple_studio_display(),
                transfer: SimTransfer::Laws([
                    cowan(2.25, 0.030),
                    cowan(2.20, 0.025),
                    cowan(2.15, 0.020),
                ]),
                white_luminance: Some(1000.0),
                black_luminance: 0.25,
                flare_luminance: 0.01,
                bit_depth: 10,
                falloff: [0.06; 3],
                failures: Failures::default(),
                hdr: Some(HdrBehaviour {
                    decodes: Signal::Pq,
                    rolloff_from: 4000.0,
                    panel_gamma: 2.2,
                    black_clip: 0.0,
                    abl: Some(Abl {
                        full_field: 600.0,
                        sharpness: 4.0,
                        time_constant_s: 1.0,
                    }),
                    global_dimming_floor: Some(0.1),
                }),
            })
        }
        other => Err(SimError::BadSpec {
            name: other.into(),
            what: format!("no such preset (there are: {})", PRESET_NAMES.join(", ")),
        }),
    }
}

/// Falloff in config: one number for all channels or one per channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum FalloffConfig {
    All(f64),
    PerChannel([f64; 3]),
}

/// The `[monitor]` section: a preset, changed by whatever else is given, or a monitor
/// built from files when `primaries_csv` is given without a preset. With neither, the
/// first preset (`crt`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MonitorConfig {
    pub preset: Option<String>,
    /// CSV with columns `wavelength_nm, R, G, B`: the primaries' spectra.
    pub primaries_csv: Option<PathBuf>,
    /// CSV with columns `input_norm, R, G, B`: a measured transfer table.
    pub transfer_csv: Option<PathBuf>,
    /// Transfer laws of R, G, B (instead of a table).
    pub laws: Option<[TransferLaw; 3]>,
    pub white_luminance: Option<f64>,
    pub black_luminance: Option<f64>,
    pub flare_luminance: Option<f64>,
    pub bit_depth: Option<u32>,
    pub falloff: Option<FalloffConfig>,
    pub failures: Option<Failures>,
    /// An HDR display's processing and limits (replacing the preset's).
    pub hdr: Option<HdrBehaviour>,
}

impl MonitorConfig {
    /// The monitor this section describes; relative paths are taken from `base_dir`.
    pub fn resolve(&self, base_dir: &Path) -> Result<MonitorSpec, SimError> {
        let path = |p: &PathBuf| {
            if p.is_absolute() {
                p.clone()
            } else {
                base_dir.join(p)
            }
        };
        let transfer = match (&self.transfer_csv, &self.laws) {
            (Some(_), Some(_)) => {
                return Err(SimError::BadSpec {
                    name: "monitor".into(),
                    what: "give transfer_csv or laws, not both".into(),
                });
            }
            (Some(t), None) => Some(SimTransfer::Measured(MeasuredTransfer::from_csv(&path(t))?)),
            (None, Some(laws)) => {
                for law in laws {
                    law.monotonicity().map_err(|e| SimError::BadSpec {
                        name: "monitor".into(),
                        what: e.to_string(),
                    })?;
                }
                Some(SimTransfer::Laws(laws.clone()))
            }
            (None, None) => None,
        };
        let primaries = match &self.primaries_csv {
            Some(p) => Some(PrimarySpectra::from_csv(&path(p))?),
            None => None,
        };
        let mut spec = match (&self.preset, primaries, transfer) {
            (Some(name), primaries, transfer) => {
                let mut spec = preset(name)?;
                if let Some(p) = primaries {
                    spec.primaries = p;
                }
                if let Some(t) = transfer {
                    spec.transfer = t;
                }
                spec
            }
            (None, Some(primaries), Some(transfer)) => MonitorSpec {
                name: file_stem(&primaries.source),
                primaries,
                transfer,
                white_luminance: None,
                black_luminance: 0.0,
                flare_luminance: 0.0,
                bit_depth: 8,
                falloff: [0.0; 3],
                failures: Failures::default(),
                hdr: None,
            },
            (None, Some(_), None) => {
                return Err(SimError::BadSpec {
                    name: "monitor".into(),
                    what: "a monitor built from primaries_csv also needs transfer_csv or laws"
                        .into(),
                });
            }
            // Nothing named: the default preset, changed by whatever else is given.
            (None, None, transfer) => {
                let mut spec = preset(PRESET_NAMES[0])?;
                if let Some(t) = transfer {
                    spec.transfer = t;
                }
                spec
            }
        };
        if self.white_luminance.is_some() {
            spec.white_luminance = self.white_luminance;
        }
        if let Some(v) = self.black_luminance {
            spec.black_luminance = v;
        }
        if let Some(v) = self.flare_luminance {
            spec.flare_luminance = v;
        }
        if let Some(v) = self.bit_depth {
            spec.bit_depth = v;
        }
        match self.falloff {
            Some(FalloffConfig::All(f)) => spec.falloff = [f; 3],
            Some(FalloffConfig::PerChannel(f)) => spec.falloff = f,
            None => {}
        }
        if let Some(f) = &self.failures {
            spec.failures = f.clone();
        }
        if let Some(h) = &self.hdr {
            spec.hdr = Some(h.clone());
        }
        Ok(spec)
    }
}

fn file_stem(source: &str) -> String {
    Path::new(source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| source.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::VirtualClock;
    use crate::monitor::{VirtualMonitor, centre_patch};
    use chromacal_color::spaces::xyz_to_xyy;
    use std::sync::Arc;

    #[test]
    fn presets_have_plausible_primaries_and_white() {
        for name in PRESET_NAMES {
            let spec = preset(name).unwrap();
            let white_y = spec.white_luminance.unwrap();
            let mut m = VirtualMonitor::new(spec, Arc::new(VirtualClock::new(None))).unwrap();
            m.show(centre_patch([1.0, 0.0, 0.0]));
            let red = xyz_to_xyy(&m.xyz_at(m.patch_centre()).unwrap(), [0.0, 0.0]);
            assert!(red.x > 0.6 && red.y < 0.36, "{name}: red at {red:?}");
            m.show(centre_patch([1.0; 3]));
            let white = m.xyz_at(m.patch_centre()).unwrap();
            assert!(
                (white.y - white_y).abs() / white_y < 0.01,
                "{name}: {white:?}"
            );
        }
        assert!(preset("plasma").is_err());
    }

    #[test]
    fn config_changes_a_preset_and_rejects_a_turning_law() {
        let config: MonitorConfig = toml::from_str(
            r#"
            preset = "lcd"
            white_luminance = 300.0
            falloff = [0.1, 0.12, 0.08]
            laws = [
              { law = "power", gamma = 2.2 },
              { law = "power", gamma = 2.2 },
              { law = "cowan", a = 2.0, b = 0.5, toe = 0.004 },
            ]
            "#,
        )
        .unwrap();
        let err = config.resolve(Path::new(".")).unwrap_err().to_string();
        assert!(err.contains("turns back"), "{err}");

        let config: MonitorConfig =
            toml::from_str("preset = \"lcd\"\nwhite_luminance = 300.0\nfalloff = 0.1").unwrap();
        let spec = config.resolve(Path::new(".")).unwrap();
        assert_eq!(spec.white_luminance, Some(300.0));
        assert_eq!(spec.falloff, [0.1; 3]);

        let unknown = toml::from_str::<MonitorConfig>("preset = \"lcd\"\ngama = 2.2");
        assert!(unknown.is_err());
    }
}
