//! The simulated instrument: reads the virtual monitor where its patch is shown, with
//! the noise, range limits and integration times of a real one, on the virtual clock.
//!
//! Noise model (seeded, so runs repeat):
//! * a gain error common to the whole reading, N(0, `gain_noise`): lamp flicker and
//!   integration jitter, which move luminance but not chromaticity;
//! * an independent relative error per spectral band (spectroradiometer) or per
//!   tristimulus channel (colorimeter), N(0, `relative_noise`);
//! * an additive floor, N(0, `noise_floor`) in cd/m² of Y, which dominates near black.
//!
//! The noise of a reading is drawn from the seed and the virtual time of the reading,
//! so a run resumed from its journal at the same virtual time reads exactly what the
//! uninterrupted run would have.

use std::sync::{Arc, Mutex};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::{Capability, Instrument, InstrumentError, InstrumentInfo, Reading, ReadingStatus};
use chromacal_color::Xyz;
use chromacal_color::spectrum::{Observer, Spectrum, emission_to_xyz};
use chromacal_sim::clock::VirtualClock;
use chromacal_sim::monitor::VirtualMonitor;

/// What kind of instrument to simulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SimulatedKind {
    /// A spectroradiometer (like a PR-670): spectra, XYZ from them.
    #[default]
    Spectral,
    /// A colorimeter: XYZ only.
    Tristimulus,
}

/// The simulated instrument's characteristics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulatedInstrumentSpec {
    pub kind: SimulatedKind,
    /// Relative standard deviation of the gain common to a whole reading.
    pub gain_noise: f64,
    /// Relative standard deviation per band or channel.
    pub relative_noise: f64,
    /// Additive standard deviation, cd/m² of Y.
    pub noise_floor: f64,
    /// Below this luminance (cd/m²) readings are flagged below range.
    pub low_light_limit: f64,
    /// Above this luminance (cd/m²) the instrument overloads and gives no value.
    pub overload_limit: f64,
    /// Integration time at 10 cd/m² and above, seconds.
    pub integration_s: f64,
    /// Longest integration, used for dim patches, seconds.
    pub max_integration_s: f64,
    pub seed: u64,
    /// A colorimeter's filters (`kind = "tristimulus"`): unset, it reads exact CIE
    /// XYZ; `"k10a"`, `"cs100a"` or `"colorcal2"`, through filters that are not the
    /// CIE functions, as those instruments read (`instrument::filters`).
    pub filters: Option<super::filters::FilterModel>,
}

impl Default for SimulatedInstrumentSpec {
    fn default() -> Self {
        SimulatedInstrumentSpec {
            kind: SimulatedKind::Spectral,
            gain_noise: 0.002,
            relative_noise: 0.002,
            noise_floor: 0.0005,
            low_light_limit: 0.003,
            overload_limit: 3000.0,
            integration_s: 1.0,
            max_integration_s: 10.0,
            seed: 1,
            filters: None,
        }
    }
}

/// Luminance at and above which the base integration time suffices.
const FULL_SIGNAL_CD_M2: f64 = 10.0;

/// A simulated colorimeter or spectroradiometer aimed at a virtual monitor.
#[derive(Debug, Clone)]
pub struct SimulatedInstrument {
    monitor: Arc<Mutex<VirtualMonitor>>,
    spec: SimulatedInstrumentSpec,
    /// The filters `spec.filters` names, built once.
    filters: Option<Arc<super::filters::ColorimeterFilters>>,
}

impl SimulatedInstrument {
    pub fn new(monitor: Arc<Mutex<VirtualMonitor>>, spec: SimulatedInstrumentSpec) -> Self {
        let filters = spec
            .filters
            .filter(|_| spec.kind == SimulatedKind::Tristimulus)
            .and_then(|model| super::filters::ColorimeterFilters::new(model).ok())
            .map(Arc::new);
        SimulatedInstrument {
            monitor,
            spec,
            filters,
        }
    }

    pub fn spec(&self) -> &SimulatedInstrumentSpec {
        &self.spec
    }

    /// A generator for the reading taken at virtual time `t`: SplitMix64 of the seed
    /// and the time in whole microseconds, so nearby times give unrelated streams and
    /// a time restored from a journal (with its rounding) gives the same one.
    fn rng_at(&self, t: f64) -> ChaCha8Rng {
        let micros = (t * 1e6).round() as u64;
        let mut z = self.spec.seed ^ micros.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ChaCha8Rng::seed_from_u64(z ^ (z >> 31))
    }

    /// Integration time for a patch of luminance `y`: longer for dim patches, as
    /// auto-ranging instruments do.
    fn integration_for(&self, y: f64) -> f64 {
        let factor = if y > 0.0 {
            (FULL_SIGNAL_CD_M2 / y).max(1.0)
        } else {
            f64::INFINITY
        };
        (self.spec.integration_s * factor).min(self.spec.max_integration_s)
    }

    fn noisy_spectrum(
        &self,
        clean: &Spectrum,
        rng: &mut ChaCha8Rng,
    ) -> Result<Spectrum, InstrumentError> {
        let s = &self.spec;
        let n: f64 = StandardNormal.sample(rng);
        let gain = 1.0 + s.gain_noise * n;
        // The floor per band that gives `noise_floor` in Y: σ_Y = Km σ_band Δλ √Σȳ².
        let w = clean.wavelengths_nm();
        let step = (w[w.len() - 1] - w[0]) / (w.len() - 1) as f64;
        let ybar_norm = w
            .iter()
            .filter_map(|nm| Observer::default().cmf_at(nm.round()))
            .map(|c| c[1] * c[1])
            .sum::<f64>()
            .sqrt();
        let band_floor = s.noise_floor / (683.0 * step * ybar_norm.max(1e-12));
        let values = clean
            .values()
            .iter()
            .map(|v| {
                let n1: f64 = StandardNormal.sample(rng);
                let n2: f64 = StandardNormal.sample(rng);
                v * gain + v * s.relative_noise * n1 + band_floor * n2
            })
            .collect();
        clean
            .with_values(values)
            .map_err(|e| InstrumentError::Protocol(format!("simulated spectrum: {e}")))
    }

    fn noisy_xyz(&self, clean: &Xyz, rng: &mut ChaCha8Rng) -> Xyz {
        let s = &self.spec;
        let n: f64 = StandardNormal.sample(rng);
        let gain = 1.0 + s.gain_noise * n;
        clean.map(|v| {
            let n1: f64 = StandardNormal.sample(rng);
            let n2: f64 = StandardNormal.sample(rng);
            v * gain + v * s.relative_noise * n1 + s.noise_floor * n2
        })
    }
}

fn simulation_error(e: impl std::fmt::Display) -> InstrumentError {
    InstrumentError::Protocol(format!("virtual monitor: {e}"))
}

impl Instrument for SimulatedInstrument {
    fn info(&self) -> InstrumentInfo {
        InstrumentInfo {
            name: match self.spec.kind {
                SimulatedKind::Spectral => "simulated spectroradiometer".into(),
                SimulatedKind::Tristimulus => "simulated colorimeter".into(),
            },
            serial: Some(format!("seed-{}", self.spec.seed)),
            capability: match self.spec.kind {
                SimulatedKind::Spectral => Capability::Spectral,
                SimulatedKind::Tristimulus => Capability::Tristimulus,
            },
        }
    }

    async fn measure(&mut self) -> Result<Reading, InstrumentError> {
        // Range the integration on what is shown, then integrate: the reading is taken
        // at the middle of the integration, which is when its time is stamped.
        let (clock, integration) = self.range()?;
        clock.wait(integration / 2.0).await;
        let (clean, time) = self.capture(&clock)?;
        clock.wait(integration / 2.0).await;
        self.finish(&clean, time, integration)
    }
}

impl SimulatedInstrument {
    /// The same measurement as [`Instrument::measure`], for callers that are not async
    /// (the emulators): the virtual clock advances, nothing sleeps.
    pub fn measure_now(&mut self) -> Result<Reading, InstrumentError> {
        let (clock, integration) = self.range()?;
        clock.advance(integration / 2.0);
        let (clean, time) = self.capture(&clock)?;
        clock.advance(integration / 2.0);
        self.finish(&clean, time, integration)
    }

    fn monitor(&self) -> Result<std::sync::MutexGuard<'_, VirtualMonitor>, InstrumentError> {
        self.monitor.lock().map_err(|_| {
            InstrumentError::Disconnected("the virtual monitor's lock is poisoned".into())
        })
    }

    /// The clock, and the integration time for what the screen shows now.
    fn range(&self) -> Result<(Arc<VirtualClock>, f64), InstrumentError> {
        let monitor = self.monitor()?;
        let y = monitor
            .xyz_at(monitor.patch_centre())
            .map_err(simulation_error)?
            .y;
        Ok((monitor.clock().clone(), self.integration_for(y)))
    }

    /// The clean radiance at the patch now, and the time.
    fn capture(&self, clock: &VirtualClock) -> Result<(Spectrum, f64), InstrumentError> {
        let monitor = self.monitor()?;
        let spectrum = monitor
            .radiance_at(monitor.patch_centre())
            .map_err(simulation_error)?;
        Ok((spectrum, clock.now()))
    }

    /// The reading an instrument makes of `clean`, taken at `time`: range flags and noise.
    fn finish(
        &self,
        clean: &Spectrum,
        time: f64,
        integration: f64,
    ) -> Result<Reading, InstrumentError> {
        let clean_xyz = emission_to_xyz(clean, Observer::default()).map_err(simulation_error)?;
        let status = if clean_xyz.y > self.spec.overload_limit {
            ReadingStatus::Overload
        } else if clean_xyz.y < self.spec.low_light_limit {
            ReadingStatus::BelowRange
        } else {
            ReadingStatus::Ok
        };
        if status == ReadingStatus::Overload {
            return Ok(Reading {
                status,
                integration_s: integration,
                ..Default::default()
            });
        }
        let mut rng = self.rng_at(time);
        let (xyz, spectrum) = match self.spec.kind {
            SimulatedKind::Spectral => {
                let noisy = self.noisy_spectrum(clean, &mut rng)?;
                let xyz = emission_to_xyz(&noisy, Observer::default()).map_err(simulation_error)?;
                (xyz, Some(noisy))
            }
            SimulatedKind::Tristimulus => {
                let seen = match &self.filters {
                    Some(filters) => filters.xyz(clean),
                    None => clean_xyz,
                };
                (self.noisy_xyz(&seen, &mut rng), None)
            }
        };
        Ok(Reading {
            xyz: Some(xyz),
            spectrum,
            status,
            integration_s: integration,
            ..Default::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_sim::clock::VirtualClock;
    use chromacal_sim::monitor::centre_patch;
    use chromacal_sim::presets::preset;

    fn setup(spec: SimulatedInstrumentSpec) -> (Arc<Mutex<VirtualMonitor>>, SimulatedInstrument) {
        let clock = Arc::new(VirtualClock::new(None));
        let monitor = VirtualMonitor::new(preset("crt").unwrap(), clock).unwrap();
        let monitor = Arc::new(Mutex::new(monitor));
        let instrument = SimulatedInstrument::new(monitor.clone(), spec);
        (monitor, instrument)
    }

    #[test]
    fn noise_has_the_stated_size() {
        pollster::block_on(async {
            for kind in [SimulatedKind::Spectral, SimulatedKind::Tristimulus] {
                let spec = SimulatedInstrumentSpec {
                    kind,
                    ..Default::default()
                };
                let (monitor, mut instrument) = setup(spec.clone());
                monitor.lock().unwrap().show(centre_patch([1.0; 3]));
                let truth = {
                    let m = monitor.lock().unwrap();
                    m.xyz_at(m.patch_centre()).unwrap().y
                };
                let n = 400;
                let mut ys = Vec::new();
                for _ in 0..n {
                    let r = instrument.measure().await.unwrap();
                    assert_eq!(r.status, ReadingStatus::Ok);
                    ys.push(r.xyz.unwrap().y);
                }
                let mean = ys.iter().sum::<f64>() / n as f64;
                let sd =
                    (ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
                // Relative noise of Y: at least the common gain noise, and not much more
                // than gain and per-channel noise together.
                let rel = sd / truth;
                assert!(
                    rel > 0.8 * spec.gain_noise
                        && rel < 1.5 * (spec.gain_noise + spec.relative_noise),
                    "{kind:?}: relative sd {rel}"
                );
                assert!(
                    (mean - truth).abs() < 4.0 * sd / (n as f64).sqrt(),
                    "{kind:?}: biased"
                );
            }
        });
    }

    #[test]
    fn dim_and_bright_patches_are_flagged_not_zeroed() {
        pollster::block_on(async {
            let spec = SimulatedInstrumentSpec {
                low_light_limit: 1.0,
                overload_limit: 50.0,
                ..Default::default()
            };
            let (monitor, mut instrument) = setup(spec);
            monitor.lock().unwrap().show(centre_patch([0.0; 3]));
            let dim = instrument.measure().await.unwrap();
            assert_eq!(dim.status, ReadingStatus::BelowRange);
            assert!(dim.xyz.is_some());
            assert!(dim.integration_s > 1.0, "dim patches integrate longer");
            monitor.lock().unwrap().show(centre_patch([1.0; 3]));
            let bright = instrument.measure().await.unwrap();
            assert_eq!(bright.status, ReadingStatus::Overload);
            assert!(bright.xyz.is_none());
        });
    }

    #[test]
    fn the_same_virtual_time_gives_the_same_reading() {
        pollster::block_on(async {
            let (monitor, mut instrument) = setup(SimulatedInstrumentSpec::default());
            monitor.lock().unwrap().show(centre_patch([0.5; 3]));
            let clock = monitor.lock().unwrap().clock().clone();
            let a = instrument.measure().await.unwrap();
            clock.set(0.0);
            let b = instrument.measure().await.unwrap();
            let c = instrument.measure().await.unwrap();
            assert_eq!(a, b);
            assert_ne!(a.xyz, c.xyz);
        });
    }
}
