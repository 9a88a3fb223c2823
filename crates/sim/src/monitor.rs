//! The virtual monitor: a physical model of a display that emits spectra.
//!
//! What reaches an instrument aimed at screen position p while drive d is shown:
//!
//! S(λ) = g(t) · g_mix · g_surround · Σ_c K_c(p) · o_c(d_c) · [P_c(λ) + ν (1 − ô_c) P_{c+1}(λ)]
//!        + S_black(λ) + S_flare(λ)
//!
//! * P_c: measured primary spectra (real displays, see `data/` and `../shared/data`),
//!   scaled so that full white has the configured luminance.
//! * o_c: the channel's output for the drive quantised to the panel's bit depth, from a
//!   transfer law or from a real measured transfer table (which may carry the panel's
//!   own black offset, as LCD tables do).
//! * K_c(p): radial falloff following the cos⁴ law, up to `falloff` less at the corners.
//! * S_black, S_flare: emitted black (white's shape) and reflected ambient light (D65).
//! * The switchable failures of Brainard's assumptions: ν, primary non-constancy (a
//!   level-dependent admixture of the next primary, ô_c being the output above the
//!   channel's own black); g_mix, channel interaction (a supply that sags with the mean
//!   output); g_surround, surround dependence (the same with the screen's mean output,
//!   patch and background weighted by area); g(t), warm-up and slow drift.

use std::path::Path;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::clock::VirtualClock;
use super::hdr::HdrBehaviour;
use chromacal_color::Xyz;
use chromacal_color::spectrum::{Illuminant, Observer, Spectrum, SpectrumError, emission_to_xyz};
use chromacal_color::tables;
use chromacal_formats::numeric_csv::{CsvError, NumericTable};
use chromacal_model::screen::{Geometry, ScreenContent};
use chromacal_model::transfer::{Table, TransferLaw};
use chromacal_model::{Drive, MonitorModel, ScreenPosition, SpatialMap};

/// Why a virtual monitor could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Csv(#[from] CsvError),
    #[error("{path}: {what}")]
    BadData { path: String, what: String },
    #[error("spectra: {0}")]
    Spectrum(#[from] SpectrumError),
    #[error("monitor '{name}': {what}")]
    BadSpec { name: String, what: String },
}

/// Spectral radiance of each primary at full output, on one wavelength grid.
#[derive(Debug, Clone, PartialEq)]
pub struct PrimarySpectra {
    pub wavelengths_nm: Vec<f64>,
    pub channels: [Vec<f64>; 3],
    /// Where they came from, for provenance.
    pub source: String,
}

impl PrimarySpectra {
    fn from_rows(rows: &[[f64; 4]], source: &str) -> Self {
        PrimarySpectra {
            wavelengths_nm: rows.iter().map(|r| r[0]).collect(),
            channels: [1, 2, 3].map(|c| rows.iter().map(|r| r[c]).collect()),
            source: source.to_string(),
        }
    }

    /// "Typical CRT" phosphors of Brainard (1997), via colour-science (relative units).
    pub fn typical_crt() -> Self {
        Self::from_rows(
            tables::PRIMARIES_TYPICAL_CRT_BRAINARD1997_5NM,
            "colour-science: Typical CRT Brainard 1997",
        )
    }

    /// Apple Studio Display LCD of Fairchild and Wyble (1998), via colour-science.
    pub fn apple_studio_display() -> Self {
        Self::from_rows(
            tables::PRIMARIES_APPLE_STUDIO_DISPLAY_5NM,
            "colour-science: Apple Studio Display (Fairchild & Wyble 1998)",
        )
    }

    /// Primaries from a CSV with columns `wavelength_nm, R, G, B` (others ignored).
    pub fn from_csv(path: &Path) -> Result<Self, SimError> {
        let table = NumericTable::read(path)?;
        let w = table.column_index("wavelength_nm")?;
        let columns = [
            table.column_index("R")?,
            table.column_index("G")?,
            table.column_index("B")?,
        ];
        let primaries = PrimarySpectra {
            wavelengths_nm: table.column(w),
            channels: columns.map(|c| table.column(c)),
            source: path.display().to_string(),
        };
        for channel in &primaries.channels {
            Spectrum::new(primaries.wavelengths_nm.clone(), channel.clone())?;
        }
        Ok(primaries)
    }

    /// A spectrum on the primaries' wavelengths.
    fn spectrum(&self, values: Vec<f64>) -> Result<Spectrum, SpectrumError> {
        Spectrum::new(self.wavelengths_nm.clone(), values)
    }
}

/// A measured transfer table: output fraction (1 at full drive, possibly above 0 at
/// drive 0) of each channel against normalised drive.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredTransfer {
    pub input: Vec<f64>,
    pub output: [Vec<f64>; 3],
    pub source: String,
}

impl MeasuredTransfer {
    /// From a CSV with columns `input_norm, R, G, B` (the ISETBio gamma tables).
    pub fn from_csv(path: &Path) -> Result<Self, SimError> {
        let table = NumericTable::read(path)?;
        let input = table.column(table.column_index("input_norm")?);
        let output = [
            table.column(table.column_index("R")?),
            table.column(table.column_index("G")?),
            table.column(table.column_index("B")?),
        ];
        let bad = |what: String| SimError::BadData {
            path: path.display().to_string(),
            what,
        };
        if input.len() < 2 || input.windows(2).any(|p| p[1] <= p[0]) {
            return Err(bad("input_norm must increase".into()));
        }
        for (c, out) in output.iter().enumerate() {
            let top = out[out.len() - 1];
            if !(top > 0.0) {
                return Err(bad(format!("channel {c} has no output at full drive")));
            }
        }
        Ok(MeasuredTransfer {
            input,
            output,
            source: path.display().to_string(),
        })
    }

    /// Output of channel `c` at drive `v`, by linear interpolation, normalised so that
    /// full drive gives 1.
    pub fn output(&self, c: usize, v: f64) -> f64 {
        let out = &self.output[c];
        let top = out[out.len() - 1];
        let v = v.clamp(self.input[0], self.input[self.input.len() - 1]);
        let upper = self
            .input
            .partition_point(|x| *x < v)
            .clamp(1, self.input.len() - 1);
        let (x0, x1) = (self.input[upper - 1], self.input[upper]);
        let (y0, y1) = (out[upper - 1], out[upper]);
        (y0 + (y1 - y0) * (v - x0) / (x1 - x0)) / top
    }
}

/// How the virtual monitor turns drive into output.
#[derive(Debug, Clone, PartialEq)]
pub enum SimTransfer {
    Laws([TransferLaw; 3]),
    Measured(MeasuredTransfer),
}

impl SimTransfer {
    fn output(&self, c: usize, v: f64) -> f64 {
        match self {
            SimTransfer::Laws(laws) => laws[c].excitation(v),
            SimTransfer::Measured(t) => t.output(c, v),
        }
    }
}

/// Switchable failures of the assumptions a monitor model rests on. All zero: an
/// ideal display.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Failures {
    /// ν: fraction of the next primary's spectrum mixed into a channel near black,
    /// fading to none at full output (primary non-constancy).
    pub primary_nonconstancy: f64,
    /// α: the light above black drops by α times the mean channel output (channel
    /// interaction: white is dimmer than the sum of its channels).
    pub channel_interaction: f64,
    /// χ: a subpixel's drive rises by χ d (1 − d) times the mean drive of the other
    /// two channels (crosstalk, as an LCD's lit neighbours couple into a subpixel): a
    /// channel alone is unaffected, greys read above the sum of their channels at mid
    /// drive and on it at black and white.
    pub channel_crosstalk: f64,
    /// β: a patch's light drops by β times the screen's mean output (surround
    /// dependence).
    pub surround_dependence: f64,
    /// Fraction dimmer at switch-on, fading with `warmup_time_constant_s`.
    pub warmup_amplitude: f64,
    pub warmup_time_constant_s: f64,
    /// Relative change of the light per hour (slow drift).
    pub drift_per_hour: f64,
    /// Time constant (s) of the screen's response to a change: the light moves from
    /// the old content's to the new one's as 1 − exp(−t/τ) (LCD liquid-crystal
    /// response, CRT phosphor persistence; 0: instant). What a display's settle time
    /// and the run's stability check are for.
    pub response_time_s: f64,
}

/// Everything that defines a virtual monitor.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorSpec {
    pub name: String,
    pub primaries: PrimarySpectra,
    pub transfer: SimTransfer,
    /// Luminance of full white above black (cd/m²); `None` takes the primary spectra
    /// as absolute radiances (W·sr⁻¹·m⁻²·nm⁻¹).
    pub white_luminance: Option<f64>,
    /// Emitted black, cd/m², with the spectral shape of white.
    pub black_luminance: f64,
    /// Reflected ambient light, cd/m², with the shape of D65.
    pub flare_luminance: f64,
    pub bit_depth: u32,
    /// Fraction of light lost at the corners, per channel (cos⁴-law shape).
    pub falloff: [f64; 3],
    pub failures: Failures,
    /// An HDR display's signal processing and power limits (`hdr`); `None` for an
    /// SDR display, whose drive goes to the panel as it is.
    pub hdr: Option<HdrBehaviour>,
}

impl MonitorSpec {
    /// The display put in the HDR mode of `signal` (its HLG or its PQ mode), as a
    /// signal's metadata or its user does before a run: unchanged for an SDR signal,
    /// none, or a display without an HDR mode.
    pub fn in_mode(mut self, signal: Option<chromacal_model::plan::Signal>) -> MonitorSpec {
        if let (Some(hdr), Some(signal)) = (self.hdr.as_mut(), signal)
            && signal.is_hdr()
        {
            hdr.decodes = signal;
        }
        self
    }
}

/// The cos⁴ falloff shape h(r) = 1 − cos⁴θ with tan θ = r / 2 (the eye or instrument
/// two half-widths from the screen), scaled to 1 at the corners (r = √2).
fn falloff_shape(r: f64) -> f64 {
    let h = |r: f64| 1.0 - 1.0 / (1.0 + (r / 2.0).powi(2)).powi(2);
    h(r) / h(std::f64::consts::SQRT_2)
}

/// The monitor's own controls, as its on-screen display sets them: a gain on each
/// channel's light and a brightness on all three (the black stays), 1 as it came.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Osd {
    pub gains: [f64; 3],
    pub brightness: f64,
}

impl Default for Osd {
    fn default() -> Self {
        Osd {
            gains: [1.0; 3],
            brightness: 1.0,
        }
    }
}

/// A virtual monitor showing some content, on a shared clock.
#[derive(Debug)]
pub struct VirtualMonitor {
    spec: MonitorSpec,
    primaries: [Vec<f64>; 3],
    black: Vec<f64>,
    flare: Vec<f64>,
    screen: ScreenContent,
    /// What the screen showed before the last change, and when the change came.
    previous: ScreenContent,
    changed_at: f64,
    /// The mean light an HDR display's limiter was following at the last change
    /// (cd/m²): where it decays from towards the new screen's.
    limiter_from: f64,
    clock: Arc<VirtualClock>,
    osd: Osd,
}

impl VirtualMonitor {
    pub fn new(spec: MonitorSpec, clock: Arc<VirtualClock>) -> Result<Self, SimError> {
        let bad = |what: &str| SimError::BadSpec {
            name: spec.name.clone(),
            what: what.to_string(),
        };
        if !(1..=16).contains(&spec.bit_depth) {
            return Err(bad("bit_depth must be 1 to 16"));
        }
        if spec.falloff.iter().any(|f| !(0.0..1.0).contains(f)) {
            return Err(bad("falloff must be in [0, 1)"));
        }
        if !(spec.black_luminance >= 0.0 && spec.flare_luminance >= 0.0) {
            return Err(bad("black and flare luminances must not be negative"));
        }
        if let Some(hdr) = &spec.hdr {
            let Some(peak) = spec.white_luminance else {
                return Err(bad(
                    "an HDR display needs white_luminance (its peak, cd/m²)",
                ));
            };
            hdr.check(peak).map_err(|e| bad(&e))?;
        }
        let grid = &spec.primaries;
        let white: Vec<f64> = (0..grid.wavelengths_nm.len())
            .map(|i| (0..3).map(|c| grid.channels[c][i]).sum())
            .collect();
        let white_y = emission_to_xyz(&grid.spectrum(white.clone())?, Observer::default())?.y;
        if !(white_y > 0.0) {
            return Err(bad("the primaries emit no light"));
        }
        let scale = match spec.white_luminance {
            Some(y) if y > 0.0 => y / white_y,
            Some(_) => return Err(bad("white_luminance must be positive")),
            None => 1.0,
        };
        let primaries = grid
            .channels
            .clone()
            .map(|ch| ch.iter().map(|v| v * scale).collect());
        let black: Vec<f64> = white
            .iter()
            .map(|v| v * spec.black_luminance / white_y)
            .collect();
        let d65 = Illuminant::D65.spectrum();
        let d65_on_grid: Vec<f64> = grid
            .wavelengths_nm
            .iter()
            .map(|w| d65.value_at(*w).unwrap_or(0.0))
            .collect();
        let d65_y = emission_to_xyz(&grid.spectrum(d65_on_grid.clone())?, Observer::default())?.y;
        let flare = d65_on_grid
            .iter()
            .map(|v| v * spec.flare_luminance / d65_y)
            .collect();
        Ok(VirtualMonitor {
            spec,
            primaries,
            black,
            flare,
            screen: ScreenContent::default(),
            previous: ScreenContent::default(),
            changed_at: f64::NEG_INFINITY,
            limiter_from: 0.0,
            clock,
            osd: Osd::default(),
        })
    }

    pub fn spec(&self) -> &MonitorSpec {
        &self.spec
    }

    pub fn clock(&self) -> &Arc<VirtualClock> {
        &self.clock
    }

    /// Put `content` on the screen. (A change during a change's transition starts
    /// from the content before it, not from the blend on the screen: a simplification
    /// that only matters when patches change faster than the response time.)
    pub fn show(&mut self, content: ScreenContent) {
        if content != self.screen {
            let now = self.clock.now();
            self.limiter_from = self.limiter_light(now);
            self.previous = self.screen;
            self.changed_at = now;
            self.screen = content;
        }
    }

    pub fn screen(&self) -> &ScreenContent {
        &self.screen
    }

    /// Set the monitor's own controls (`chromacal adjust` tells a user which way).
    /// Controls that are not finite and positive are refused.
    pub fn set_osd(&mut self, osd: Osd) -> Result<(), SimError> {
        if !osd
            .gains
            .iter()
            .chain([&osd.brightness])
            .all(|v| v.is_finite() && *v > 0.0)
        {
            return Err(SimError::BadSpec {
                name: self.spec.name.clone(),
                what: format!("the monitor's controls must be positive: {osd:?}"),
            });
        }
        self.osd = osd;
        Ok(())
    }

    pub fn osd(&self) -> Osd {
        self.osd
    }

    fn quantise(&self, v: f64) -> f64 {
        let levels = ((1u32 << self.spec.bit_depth) - 1) as f64;
        (v.clamp(0.0, 1.0) * levels).round() / levels
    }

    /// Output of each channel for a drive (quantised), crosstalk included (after the
    /// codes: it is analogue).
    fn outputs(&self, drive: Drive) -> [f64; 3] {
        let mut q = drive.map(|v| self.quantise(v));
        if let (Some(hdr), Some(peak)) = (&self.spec.hdr, self.spec.white_luminance) {
            q = hdr.panel_drives(q, peak);
        }
        let chi = self.spec.failures.channel_crosstalk;
        [0, 1, 2].map(|c| {
            let others = (q.iter().sum::<f64>() - q[c]) / 2.0;
            let effective = q[c] + chi * q[c] * (1.0 - q[c]) * others;
            self.spec.transfer.output(c, effective)
        })
    }

    /// Output above the channel's own black, in [0, 1].
    fn outputs_above_black(&self, drive: Drive) -> [f64; 3] {
        let zero = self.outputs([0.0; 3]);
        let o = self.outputs(drive);
        [0, 1, 2].map(|c| ((o[c] - zero[c]) / (1.0 - zero[c]).max(1e-12)).clamp(0.0, 1.0))
    }

    /// Radiance reaching an instrument aimed at `position` now. (An error only when
    /// the spec's numbers make the radiance non-finite.)
    pub fn radiance_at(&self, position: ScreenPosition) -> Result<Spectrum, SpectrumError> {
        let t = self.clock.now();
        let mut values = self.radiance_of(&self.screen, position, t);
        let tau = self.spec.failures.response_time_s;
        if tau > 0.0 {
            let old = (-(t - self.changed_at).max(0.0) / tau).exp();
            if old > 1e-12 {
                let before = self.radiance_of(&self.previous, position, t);
                for (v, b) in values.iter_mut().zip(before) {
                    *v = (1.0 - old) * *v + old * b;
                }
            }
        }
        self.spec.primaries.spectrum(values)
    }

    /// Radiance values at `position` of a screen showing `screen`, settled, at time `t`.
    fn radiance_of(&self, screen: &ScreenContent, position: ScreenPosition, t: f64) -> Vec<f64> {
        let inside = screen.geometry.contains(position);
        let drive = if inside {
            screen.patch
        } else {
            screen.background
        };
        let f = &self.spec.failures;
        let mut gain = 1.0 + f.drift_per_hour * t / 3600.0;
        if f.warmup_amplitude != 0.0 && f.warmup_time_constant_s > 0.0 {
            gain *= 1.0 - f.warmup_amplitude * (-t / f.warmup_time_constant_s).exp();
        }
        let above = self.outputs_above_black(drive);
        gain *= 1.0 - f.channel_interaction * above.iter().sum::<f64>() / 3.0;
        if f.surround_dependence != 0.0 {
            let area = screen.geometry.area();
            let mean = |d: Drive| self.outputs_above_black(d).iter().sum::<f64>() / 3.0;
            let screen_mean = area * mean(screen.patch) + (1.0 - area) * mean(screen.background);
            gain *= 1.0 - f.surround_dependence * screen_mean;
        }
        let (limiter, backlight) = self.hdr_gains(screen, t);
        gain *= limiter;
        let output = self.outputs(drive);
        let shape = falloff_shape(position.radius());
        let mut values: Vec<f64> = self
            .black
            .iter()
            .zip(&self.flare)
            .map(|(b, f)| b * backlight + f)
            .collect();
        for c in 0..3 {
            let k = 1.0 - self.spec.falloff[c] * shape;
            let weight = gain * k * output[c] * self.osd.brightness * self.osd.gains[c];
            let admixture = f.primary_nonconstancy * (1.0 - above[c]);
            let next = (c + 1) % 3;
            for (i, v) in values.iter_mut().enumerate() {
                *v += weight * (self.primaries[c][i] + admixture * self.primaries[next][i]);
            }
        }
        values
    }

    /// The screen's mean light (cd/m², without the limiter) while `screen` is shown.
    fn mean_light(&self, screen: &ScreenContent) -> f64 {
        let Some(peak) = self.spec.white_luminance else {
            return 0.0;
        };
        let mean = |d: Drive| self.outputs_above_black(d).iter().sum::<f64>() / 3.0;
        let area = screen.geometry.area();
        peak * (area * mean(screen.patch) + (1.0 - area) * mean(screen.background))
    }

    /// The mean light an HDR display's limiter follows at time `t`: the screen's,
    /// reached with the limiter's time constant from what it followed at the last
    /// change (so a full field two patches ago still holds it down).
    fn limiter_light(&self, t: f64) -> f64 {
        let now = self.mean_light(&self.screen);
        let tau = match self.spec.hdr.as_ref().and_then(|h| h.abl.as_ref()) {
            Some(abl) if abl.time_constant_s > 0.0 => abl.time_constant_s,
            _ => return now,
        };
        let old = (-(t - self.changed_at).max(0.0) / tau).exp();
        now + (self.limiter_from - now) * old
    }

    /// An HDR display's limiter gain on all light at time `t` and its backlight level
    /// (the factor on its black) while `screen` is shown: (1, 1) for an SDR display.
    /// The limiter is one supply for the whole screen (`limiter_light`).
    fn hdr_gains(&self, screen: &ScreenContent, t: f64) -> (f64, f64) {
        let Some(hdr) = &self.spec.hdr else {
            return (1.0, 1.0);
        };
        let backlight = match hdr.global_dimming_floor {
            Some(floor) => {
                let brightest =
                    |d: Drive| self.outputs_above_black(d).into_iter().fold(0.0, f64::max);
                let mut b = brightest(screen.patch);
                if screen.geometry.area() < 1.0 {
                    b = b.max(brightest(screen.background));
                }
                b.max(floor)
            }
            None => 1.0,
        };
        (hdr.abl_gain(self.limiter_light(t)), backlight)
    }

    /// Noise-free XYZ (CIE 1931 2°) at `position` now.
    pub fn xyz_at(&self, position: ScreenPosition) -> Result<Xyz, SpectrumError> {
        emission_to_xyz(&self.radiance_at(position)?, Observer::default())
    }

    /// Where an instrument aimed at the patch reads: the centre of its geometry.
    pub fn patch_centre(&self) -> ScreenPosition {
        self.screen.geometry.centre()
    }

    /// The monitor model this display follows when none of its failures is switched
    /// on, at time zero: the truth a fit is compared with.
    pub fn true_model(&self) -> MonitorModel {
        // Every spectrum here was integrated once already in `new`.
        let xyz_of = |values: &Vec<f64>| {
            self.spec
                .primaries
                .spectrum(values.clone())
                .and_then(|s| emission_to_xyz(&s, Observer::default()))
                .unwrap_or_default()
        };
        let zero = self.outputs([0.0; 3]);
        let mut matrix = nalgebra::Matrix3::zeros();
        let mut black = xyz_of(&self.black) + xyz_of(&self.flare);
        for (c, (spectrum, offset)) in self.primaries.iter().zip(zero).enumerate() {
            let primary = xyz_of(spectrum);
            matrix.set_column(c, &(primary * (1.0 - offset)));
            black += primary * offset;
        }
        let laws = match (&self.spec.transfer, &self.spec.hdr) {
            (SimTransfer::Laws(laws), None) => laws.clone(),
            (transfer, hdr) => [0, 1, 2].map(|c| {
                // An HDR display's processing comes before the panel's transfer: its
                // law is tabulated at every code the display takes.
                let drive: Vec<f64> = match (transfer, hdr) {
                    (SimTransfer::Measured(t), None) => t.input.clone(),
                    _ => {
                        let levels = ((1u32 << self.spec.bit_depth) - 1) as f64;
                        (0..=levels as u32).map(|k| k as f64 / levels).collect()
                    }
                };
                let output = |v: f64| match hdr {
                    None => transfer.output(c, v),
                    Some(_) => {
                        let mut d = [0.0; 3];
                        d[c] = v;
                        self.outputs(d)[c]
                    }
                };
                let excitation: Vec<f64> = drive
                    .iter()
                    .map(|v| ((output(*v) - zero[c]) / (1.0 - zero[c])).max(0.0))
                    .collect();
                let mut running = 0.0f64;
                let monotone: Vec<f64> = excitation
                    .iter()
                    .map(|e| {
                        running = running.max(*e);
                        running
                    })
                    .collect();
                match Table::new(drive, monotone) {
                    Ok(table) => TransferLaw::Table(table),
                    Err(_) => TransferLaw::Power(chromacal_model::transfer::Power { gamma: 2.2 }),
                }
            }),
        };
        MonitorModel {
            matrix,
            black,
            laws,
            spatial: SpatialMap::Uniform,
            terms: Default::default(),
        }
    }

    /// True spatial gain of channel `c` at `position` (1 at the centre).
    pub fn true_gain(&self, c: usize, position: ScreenPosition) -> f64 {
        1.0 - self.spec.falloff[c] * falloff_shape(position.radius())
    }
}

/// A patch filling a window at the centre with a black surround: the content most
/// tests want.
pub fn centre_patch(drive: Drive) -> ScreenContent {
    ScreenContent {
        patch: drive,
        background: [0.0; 3],
        geometry: Geometry::centred(0.2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::transfer::Power;

    fn ideal(primaries: PrimarySpectra) -> MonitorSpec {
        MonitorSpec {
            name: "test".into(),
            primaries,
            transfer: SimTransfer::Laws(
                [0, 1, 2].map(|_| TransferLaw::Power(Power { gamma: 2.2 })),
            ),
            white_luminance: Some(100.0),
            black_luminance: 0.0,
            flare_luminance: 0.0,
            bit_depth: 8,
            falloff: [0.0; 3],
            failures: Failures::default(),
            hdr: None,
        }
    }

    fn monitor(spec: MonitorSpec) -> VirtualMonitor {
        VirtualMonitor::new(spec, Arc::new(VirtualClock::new(None))).unwrap()
    }

    #[test]
    fn white_has_the_requested_luminance_and_is_additive() {
        let mut m = monitor(ideal(PrimarySpectra::typical_crt()));
        m.show(centre_patch([1.0; 3]));
        let white = m.xyz_at(ScreenPosition::CENTRE).unwrap();
        assert!((white.y - 100.0).abs() < 1e-9, "{white:?}");
        let mut sum = Xyz::zeros();
        for c in 0..3 {
            let mut d = [0.0; 3];
            d[c] = 1.0;
            m.show(centre_patch(d));
            sum += m.xyz_at(ScreenPosition::CENTRE).unwrap();
        }
        assert!((sum - white).norm() < 1e-9);
        let truth = m.true_model();
        assert!((truth.white() - white).norm() < 1e-9);
    }

    #[test]
    fn a_slow_screen_moves_to_a_new_patch_exponentially() {
        let mut spec = ideal(PrimarySpectra::typical_crt());
        spec.failures.response_time_s = 0.5;
        let mut m = monitor(spec);
        m.show(centre_patch([1.0; 3]));
        m.clock().advance(100.0);
        let white = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        m.show(centre_patch([0.0; 3]));
        assert!((m.xyz_at(ScreenPosition::CENTRE).unwrap().y - white).abs() < 1e-9);
        m.clock().advance(0.5);
        let y = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!((y / white - (-1.0f64).exp()).abs() < 1e-9, "{y}");
        // Showing the same content again is no change.
        m.show(centre_patch([0.0; 3]));
        assert_eq!(m.xyz_at(ScreenPosition::CENTRE).unwrap().y, y);
        m.clock().advance(10.0);
        assert!(m.xyz_at(ScreenPosition::CENTRE).unwrap().y < 1e-6);
    }

    #[test]
    fn quantisation_follows_the_bit_depth() {
        let mut spec = ideal(PrimarySpectra::apple_studio_display());
        spec.bit_depth = 2; // codes 0, 1/3, 2/3, 1
        let mut m = monitor(spec);
        m.show(centre_patch([0.40, 0.40, 0.40]));
        let a = m.xyz_at(ScreenPosition::CENTRE).unwrap();
        m.show(centre_patch([1.0 / 3.0; 3]));
        let b = m.xyz_at(ScreenPosition::CENTRE).unwrap();
        assert!((a - b).norm() < 1e-12);
    }

    #[test]
    fn falloff_reaches_its_value_at_the_corners_only() {
        let mut spec = ideal(PrimarySpectra::typical_crt());
        spec.falloff = [0.2; 3];
        let mut m = monitor(spec);
        let mut content = centre_patch([1.0; 3]);
        m.show(content);
        let centre = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        content.geometry = Geometry {
            x: 0.0,
            y: 0.0,
            width: 0.1,
            height: 0.1,
        };
        m.show(content);
        let corner = m.xyz_at(ScreenPosition::new(0.0, 0.0)).unwrap().y;
        let edge = m.xyz_at(ScreenPosition::new(0.05, 0.05)).unwrap().y;
        assert!((corner / centre - 0.8).abs() < 1e-9);
        assert!(edge / centre > 0.8 && edge / centre < 1.0);
    }

    #[test]
    fn failures_break_the_assumptions_they_name() {
        let mut spec = ideal(PrimarySpectra::typical_crt());
        spec.failures.channel_interaction = 0.05;
        let mut m = monitor(spec.clone());
        m.show(centre_patch([1.0; 3]));
        let white = m.xyz_at(ScreenPosition::CENTRE).unwrap();
        let mut sum = Xyz::zeros();
        for c in 0..3 {
            let mut d = [0.0; 3];
            d[c] = 1.0;
            m.show(centre_patch(d));
            sum += m.xyz_at(ScreenPosition::CENTRE).unwrap();
        }
        assert!(white.y < 0.97 * sum.y, "white {white:?} sum {sum:?}");

        let mut spec2 = ideal(PrimarySpectra::typical_crt());
        spec2.failures.surround_dependence = 0.1;
        let mut m = monitor(spec2);
        let mut content = centre_patch([0.5; 3]);
        m.show(content);
        let on_black = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        content.background = [1.0; 3];
        m.show(content);
        let on_white = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!(on_white < 0.95 * on_black);
    }

    /// The `hdr-oled` preset: 800 cd/m² on a small window, its full-field white held
    /// to 180 by the limiter, which recovers with its time constant after the screen
    /// goes dark again; PQ code 0.5081 shows 100 cd/m².
    #[test]
    fn an_hdr_oled_limits_a_full_field_and_decodes_the_pq() {
        let spec = crate::presets::preset("hdr-oled").unwrap();
        let mut m = monitor(spec);
        let window = centre_patch([1.0; 3]);
        m.show(window);
        m.clock().advance(100.0);
        let peak = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!((peak / 800.0 - 1.0).abs() < 0.01, "{peak}");
        let full = ScreenContent {
            background: [1.0; 3],
            ..window
        };
        m.show(full);
        m.clock().advance(100.0);
        let full_field = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!((full_field / 180.0 - 1.0).abs() < 0.02, "{full_field}");
        // Back to the window: dimmed still after one time constant, recovered later.
        m.show(window);
        m.clock().advance(2.0);
        let recovering = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!(recovering < 0.9 * peak, "{recovering}");
        m.clock().advance(60.0);
        assert!((m.xyz_at(ScreenPosition::CENTRE).unwrap().y / peak - 1.0).abs() < 1e-3);
        // The PQ: 100 cd/m² asked, 100 shown within the panel's tracking (its laws
        // are 2.14 to 2.26 where the processing assumes 2.2) and the flare.
        m.show(centre_patch([0.5081; 3]));
        m.clock().advance(100.0);
        let grey = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!((grey / 100.0 - 1.0).abs() < 0.05, "{grey}");
    }

    /// `hdr-oled` put in its HLG mode (as a run with an HLG signal puts it): a grey
    /// is brighter than the sum of its channels shown alone, by the OOTF's
    /// luminance-dependent gain; in its PQ mode the same codes add up.
    #[test]
    fn an_hdr_oled_in_its_hlg_mode_is_not_the_sum_of_its_channels() {
        use chromacal_model::plan::Signal;
        let shown = |spec: &MonitorSpec, drive: [f64; 3]| {
            let mut m = monitor(spec.clone());
            m.show(centre_patch(drive));
            m.clock().advance(100.0);
            m.xyz_at(ScreenPosition::CENTRE).unwrap()
        };
        let preset = crate::presets::preset("hdr-oled").unwrap();
        assert_eq!(preset.hdr.as_ref().unwrap().decodes, Signal::Pq);
        let sdr = preset.clone().in_mode(Some(Signal::Sdr));
        assert_eq!(sdr.hdr.as_ref().unwrap().decodes, Signal::Pq);
        let hlg = preset.clone().in_mode(Some(Signal::Hlg));
        assert_eq!(hlg.hdr.as_ref().unwrap().decodes, Signal::Hlg);
        assert_eq!(
            crate::presets::preset("crt")
                .unwrap()
                .in_mode(Some(Signal::Hlg))
                .hdr,
            None
        );
        for (spec, grey_over_sum) in [(&preset, 0.98..1.02), (&hlg, 1.08..1.25)] {
            let black = shown(spec, [0.0; 3]).y;
            let grey = shown(spec, [0.6; 3]).y - black;
            let sum: f64 = (0..3)
                .map(|c| {
                    let mut d = [0.0; 3];
                    d[c] = 0.6;
                    shown(spec, d).y - black
                })
                .sum();
            assert!(grey_over_sum.contains(&(grey / sum)), "{}", grey / sum);
        }
    }

    /// `hdr-lcd`: a black patch on a black screen is darker than the same black beside
    /// a bright window (the backlight follows the brightest content).
    #[test]
    fn a_global_dimming_backlight_lifts_the_black_beside_bright_content() {
        let spec = crate::presets::preset("hdr-lcd").unwrap();
        let mut m = monitor(spec);
        m.show(centre_patch([0.0; 3]));
        let alone = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        m.show(ScreenContent {
            background: [0.8; 3],
            ..centre_patch([0.0; 3])
        });
        m.clock().advance(100.0);
        let beside = m.xyz_at(ScreenPosition::CENTRE).unwrap().y;
        assert!(beside > 3.0 * alone, "{alone} {beside}");
    }
}
