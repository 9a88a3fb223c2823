//! Making a colorimeter correction on a display: show a set of patches, read each with
//! a reference spectroradiometer and with the colorimeter, and fit the 3 × 3 matrix
//! that takes the colorimeter's XYZ to the reference's (as ArgyllCMS `ccxxmake` does),
//! scored on patches held out of the fit.
//!
//! The fit is weighted least squares in XYZ, each patch weighted by the reference's
//! noise at its luminance (1 / (s²·Y² + f²), s the reference's relative repeatability
//! read from repeated whites, f a floor of 0.1 % of white), so that a dim primary
//! counts for what its reading is worth. Every pair of readings is appended to a
//! journal as it is taken; a run stopped part way goes on from it (`--resume`).

use std::io::Write;
use std::path::Path;

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use chromacal_color::Xyz;
use chromacal_color::difference::delta_e_2000;
use chromacal_color::spaces::xyz_to_lab;
use chromacal_display::{DisplayError, PatchDisplay};
use chromacal_instruments::{Instrument, InstrumentError, Reading, ReadingStatus};
use chromacal_model::Drive;
use chromacal_model::screen::{Codes, Geometry, Patch};

/// Why no correction was made.
#[derive(Debug, thiserror::Error)]
pub enum CorrectionError {
    #[error("reference instrument: {0}")]
    Reference(InstrumentError),
    #[error("colorimeter: {0}")]
    Colorimeter(InstrumentError),
    #[error("display: {0}")]
    Display(#[from] DisplayError),
    #[error("journal {path}: {reason}")]
    Journal { path: String, reason: String },
    #[error("{0}")]
    Fit(String),
    #[error("stopped at the user's request")]
    Stopped,
}

/// One patch of the set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CorrectionPatch {
    pub index: usize,
    pub drive: Drive,
    /// Kept out of the fit, to score it.
    pub held_out: bool,
    /// A second reading of an earlier patch, for the instruments' repeatability.
    pub repeat_of: Option<usize>,
}

/// The patch set: primaries, white and greys, secondaries and a few mixtures fitted;
/// other mixtures held out, and the held-out patches read twice.
pub fn correction_patches() -> Vec<CorrectionPatch> {
    let fitted: [Drive; 14] = [
        [1.0, 1.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.75, 0.75, 0.75],
        [0.5, 0.5, 0.5],
        [0.25, 0.25, 0.25],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 1.0],
        [1.0, 0.0, 1.0],
        [0.9, 0.6, 0.3],
        [0.3, 0.6, 0.9],
        [0.6, 0.9, 0.3],
        [0.7, 0.3, 0.5],
    ];
    let held_out: [Drive; 6] = [
        [0.8, 0.5, 0.4],
        [0.4, 0.7, 0.6],
        [0.5, 0.4, 0.8],
        [0.9, 0.9, 0.5],
        [0.35, 0.35, 0.35],
        [0.2, 0.6, 0.3],
    ];
    let mut patches = Vec::new();
    for (drive, held) in fitted
        .iter()
        .map(|d| (*d, false))
        .chain(held_out.iter().map(|d| (*d, true)))
    {
        patches.push(CorrectionPatch {
            index: patches.len(),
            drive,
            held_out: held,
            repeat_of: None,
        });
    }
    // The white twice more (the reference's repeatability, for the weights), and every
    // held-out patch once more (the instruments' repeatability, to judge the fit).
    let repeats: Vec<usize> = std::iter::repeat_n(0, 2)
        .chain(patches.iter().filter(|p| p.held_out).map(|p| p.index))
        .collect();
    for of in repeats {
        let p = patches[of];
        patches.push(CorrectionPatch {
            index: patches.len(),
            repeat_of: Some(of),
            ..p
        });
    }
    patches
}

/// One patch read by both instruments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairedReading {
    pub patch: CorrectionPatch,
    pub reference: Reading,
    pub colorimeter: Reading,
}

impl PairedReading {
    fn xyz(&self) -> Option<(Xyz, Xyz)> {
        match (
            self.reference.status,
            self.reference.xyz,
            self.colorimeter.status,
            self.colorimeter.xyz,
        ) {
            (ReadingStatus::Ok, Some(r), ReadingStatus::Ok, Some(c)) => Some((r, c)),
            _ => None,
        }
    }
}

/// The pairs read so far: an append-only JSON-lines file, one pair a line, flushed
/// and synced as each is taken.
pub struct PairJournal {
    /// None: kept in memory only (benches).
    path: Option<std::path::PathBuf>,
    pub pairs: Vec<PairedReading>,
}

impl PairJournal {
    /// A journal that writes nothing (for benches on emulators).
    pub fn in_memory() -> Self {
        PairJournal {
            path: None,
            pairs: Vec::new(),
        }
    }

    /// Open `path`: with `resume`, the pairs in it are kept (a torn last line, from a
    /// crash, is dropped; a line repeated is kept once); without, it must not exist
    /// yet. A damaged line elsewhere is named by its number, and with `discard_damaged`
    /// set aside in `<path>.damaged` (its patch is read again).
    pub fn open(path: &Path, resume: bool, discard_damaged: bool) -> Result<Self, CorrectionError> {
        let err = |reason: String| CorrectionError::Journal {
            path: path.display().to_string(),
            reason,
        };
        let mut pairs = Vec::new();
        if path.exists() {
            if !resume {
                return Err(err(
                    "it holds readings of an earlier run: give --resume to go on with them, or remove it".into(),
                ));
            }
            let text = chromacal_formats::durable::read_text_limited(path, 64 << 20)
                .map_err(|e| err(e.to_string()))?;
            let lines: Vec<&str> = text.lines().collect();
            let mut damaged = String::new();
            for (n, line) in lines.iter().enumerate() {
                match serde_json::from_str::<PairedReading>(line) {
                    Ok(p) if pairs.contains(&p) => {}
                    Ok(p) => pairs.push(p),
                    // Only the last line may be torn.
                    Err(_) if n + 1 == lines.len() && !text.ends_with('\n') => {}
                    Err(_) if discard_damaged => {
                        damaged.push_str(line);
                        damaged.push('\n');
                    }
                    Err(e) => {
                        return Err(err(format!(
                            "line {} is damaged ({e}): --resume --discard-damaged sets it aside in {}.damaged and reads its patch again",
                            n + 1,
                            path.display()
                        )));
                    }
                }
            }
            if !damaged.is_empty() {
                let mut aside = path.as_os_str().to_owned();
                aside.push(".damaged");
                let aside = std::path::PathBuf::from(aside);
                let mut kept = std::fs::read(&aside).unwrap_or_default();
                kept.extend_from_slice(damaged.as_bytes());
                chromacal_formats::durable::write_atomic(&aside, &kept)
                    .map_err(|e| err(e.to_string()))?;
            }
            // Rewrite without the torn line, so that appends start on a new line.
            let mut clean = String::new();
            for p in &pairs {
                clean.push_str(&serde_json::to_string(p).map_err(|e| err(e.to_string()))?);
                clean.push('\n');
            }
            chromacal_formats::durable::write_atomic(path, clean.as_bytes())
                .map_err(|e| err(e.to_string()))?;
        }
        Ok(PairJournal {
            path: Some(path.to_path_buf()),
            pairs,
        })
    }

    fn append(&mut self, pair: PairedReading) -> Result<(), CorrectionError> {
        let Some(path) = &self.path else {
            self.pairs.push(pair);
            return Ok(());
        };
        let err = |reason: String| CorrectionError::Journal {
            path: path.display().to_string(),
            reason,
        };
        let mut line = serde_json::to_string(&pair).map_err(|e| err(e.to_string()))?;
        line.push('\n');
        let mut file = chromacal_formats::durable::open_options(path)
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| err(e.to_string()))?;
        file.write_all(line.as_bytes())
            .and_then(|_| file.sync_data())
            .map_err(|e| err(e.to_string()))?;
        self.pairs.push(pair);
        Ok(())
    }

    /// How many patches have been read by both, in range (each once, however many
    /// lines it has).
    pub fn done(&self) -> usize {
        let mut indices: Vec<usize> = self
            .pairs
            .iter()
            .filter(|p| p.xyz().is_some())
            .map(|p| p.patch.index)
            .collect();
        indices.sort_unstable();
        indices.dedup();
        indices.len()
    }

    /// Whether patch `index` has been read by both, in range (a patch that overloaded
    /// or gave no value is read again on resume).
    fn has(&self, index: usize) -> bool {
        self.pairs
            .iter()
            .any(|p| p.patch.index == index && p.xyz().is_some())
    }
}

/// How the two instruments are aimed.
pub enum Aiming<'a> {
    /// Both at the patch at once: each patch is read by one, then the other.
    Together,
    /// One at a time: every patch with the reference, then `swap` (the user puts the
    /// colorimeter where the reference was), then every patch with the colorimeter.
    /// The reference's readings wait in memory, so a run stopped before the
    /// colorimeter's turn reads them again.
    OneAtATime { swap: Box<dyn FnMut() -> bool + 'a> },
}

fn patch_for(drive: Drive) -> Patch {
    Patch {
        codes: Codes::from_drive(drive, 8),
        background: Codes::from_drive([0.0; 3], 8),
        geometry: Geometry::default(),
    }
}

/// What a run asks between patches: whether to stop, and where it is.
pub struct Hooks<'a> {
    pub stop: Box<dyn Fn() -> bool + 'a>,
    /// Pairs read so far, of how many.
    pub progress: Box<dyn Fn(usize, usize) + 'a>,
}

/// Read every patch not yet in `journal` with both instruments. `hooks.stop` is
/// asked between patches.
pub async fn measure_pairs(
    display: &mut impl PatchDisplay,
    reference: &mut impl Instrument,
    colorimeter: &mut impl Instrument,
    patches: &[CorrectionPatch],
    journal: &mut PairJournal,
    aiming: Aiming<'_>,
    hooks: &Hooks<'_>,
) -> Result<(), CorrectionError> {
    let (stop, progress) = (&hooks.stop, &hooks.progress);
    let todo: Vec<CorrectionPatch> = patches
        .iter()
        .filter(|p| !journal.has(p.index))
        .copied()
        .collect();
    let total = patches.len();
    // One at a time: the reference reads every patch first, and its readings wait here.
    let mut references: Vec<Option<Reading>> = vec![None; todo.len()];
    if let Aiming::OneAtATime { mut swap } = aiming {
        for (p, slot) in todo.iter().zip(references.iter_mut()) {
            if stop() {
                return Err(CorrectionError::Stopped);
            }
            display.show(&patch_for(p.drive)).await?;
            *slot = Some(
                reference
                    .measure()
                    .await
                    .map_err(CorrectionError::Reference)?,
            );
        }
        if !todo.is_empty() && !swap() {
            return Err(CorrectionError::Stopped);
        }
    }
    for (p, read) in todo.into_iter().zip(references) {
        if stop() {
            return Err(CorrectionError::Stopped);
        }
        display.show(&patch_for(p.drive)).await?;
        let r = match read {
            Some(r) => r,
            None => reference
                .measure()
                .await
                .map_err(CorrectionError::Reference)?,
        };
        let c = colorimeter
            .measure()
            .await
            .map_err(CorrectionError::Colorimeter)?;
        journal.append(PairedReading {
            patch: p,
            reference: r,
            colorimeter: c,
        })?;
        progress(journal.done(), total);
    }
    Ok(())
}

/// Mean and largest ΔE00 over a set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Errors {
    pub mean: f64,
    pub max: f64,
    pub count: usize,
}

impl Errors {
    fn of(values: &[f64]) -> Self {
        Errors {
            mean: values.iter().sum::<f64>() / values.len().max(1) as f64,
            max: values.iter().cloned().fold(0.0, f64::max),
            count: values.len(),
        }
    }
}

/// A fitted correction and how well it does.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CorrectionFit {
    pub matrix: Matrix3<f64>,
    /// ΔE00 of the colorimeter against the reference on the fitted patches, before and
    /// after the correction (CIELAB relative to the reference's white).
    pub fitted_uncorrected: Errors,
    pub fitted_corrected: Errors,
    /// The same on the held-out patches.
    pub held_out_uncorrected: Errors,
    pub held_out_corrected: Errors,
    /// ΔE00 between two readings of the same held-out patch by the colorimeter
    /// (corrected), and by the reference: what no correction can go below.
    pub colorimeter_repeatability: Errors,
    pub reference_repeatability: Errors,
    /// The reference's relative noise used in the weights.
    pub reference_noise: f64,
}

/// Fit the correction to `pairs` (first readings of the non-held-out patches) and
/// score it.
pub fn fit_pairs(pairs: &[PairedReading]) -> Result<CorrectionFit, CorrectionError> {
    // One reading a patch: the first usable one (a patch read again on resume after
    // an overload counts once).
    let mut usable: Vec<(&PairedReading, Xyz, Xyz)> = Vec::new();
    for p in pairs {
        if let Some((r, c)) = p.xyz()
            && !usable
                .iter()
                .any(|(q, _, _)| q.patch.index == p.patch.index)
        {
            usable.push((p, r, c));
        }
    }
    let whites: Vec<f64> = usable
        .iter()
        .filter(|(p, _, _)| p.patch.drive == [1.0; 3])
        .map(|(_, r, _)| r.y)
        .collect();
    let Some(&white_y) = whites.first() else {
        return Err(CorrectionError::Fit(
            "the white was not read by both instruments".into(),
        ));
    };
    let white = usable
        .iter()
        .find(|(p, _, _)| p.patch.drive == [1.0; 3])
        .map(|(_, r, _)| *r)
        .unwrap_or(Xyz::new(white_y, white_y, white_y));
    // The reference's relative repeatability from its whites (a prior of 0.2 % when
    // there are too few to tell).
    let reference_noise = if whites.len() >= 3 {
        let mean = whites.iter().sum::<f64>() / whites.len() as f64;
        let var =
            whites.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / (whites.len() - 1) as f64;
        (var.sqrt() / mean).max(1e-4)
    } else {
        0.002
    };
    let floor = 1e-3 * white_y;
    // (colorimeter, reference, weight): the map is fitted from the first to the second.
    let fit: Vec<(Xyz, Xyz, f64)> = usable
        .iter()
        .filter(|(p, _, _)| !p.patch.held_out && p.patch.repeat_of.is_none())
        .map(|(_, r, c)| {
            let w = 1.0 / ((reference_noise * r.y).powi(2) + floor.powi(2));
            (*c, *r, w)
        })
        .collect();
    if fit.len() < 4 {
        return Err(CorrectionError::Fit(format!(
            "{} patches read by both instruments: at least 4 are needed",
            fit.len()
        )));
    }
    let matrix = chromacal_color::linalg::weighted_linear_map(&fit).ok_or_else(|| {
        CorrectionError::Fit(
            "the colorimeter's readings do not span three dimensions: is it a colorimeter, aimed at the patch?".into(),
        )
    })?;
    chromacal_formats::ccmx::check_matrix(&matrix, "the fitted correction")
        .map_err(|e| CorrectionError::Fit(e.to_string()))?;
    let de = |a: &Xyz, b: &Xyz| delta_e_2000(&xyz_to_lab(a, &white), &xyz_to_lab(b, &white));
    let score = |held: bool, corrected: bool| {
        let values: Vec<f64> = usable
            .iter()
            .filter(|(p, _, _)| p.patch.held_out == held && p.patch.repeat_of.is_none())
            .map(|(_, r, c)| {
                let c = if corrected { matrix * c } else { *c };
                de(r, &c)
            })
            .collect();
        Errors::of(&values)
    };
    let repeat = |colorimeter: bool| {
        let values: Vec<f64> = usable
            .iter()
            .filter(|(p, _, _)| p.patch.held_out)
            .filter_map(|(p, r, c)| {
                let of = p.patch.repeat_of?;
                let (_, r0, c0) = usable.iter().find(|(q, _, _)| q.patch.index == of)?;
                Some(if colorimeter {
                    de(&(matrix * c0), &(matrix * c))
                } else {
                    de(r0, r)
                })
            })
            .collect();
        Errors::of(&values)
    };
    Ok(CorrectionFit {
        matrix,
        fitted_uncorrected: score(false, false),
        fitted_corrected: score(false, true),
        held_out_uncorrected: score(true, false),
        held_out_corrected: score(true, true),
        colorimeter_repeatability: repeat(true),
        reference_repeatability: repeat(false),
        reference_noise,
    })
}

/// What `correction make` is asked.
pub struct MakeRequest<'a> {
    pub reference: chromacal_instruments::devices::InstrumentAddress,
    pub colorimeter: chromacal_instruments::devices::InstrumentAddress,
    /// The `.ccmx` to write; its pairs are journalled beside it (`<output>.pairs.jsonl`).
    pub output: std::path::PathBuf,
    pub resume: bool,
    /// At `resume`, set damaged lines of the pairs journal aside and go on.
    pub discard_damaged: bool,
    pub aiming: Aiming<'a>,
    /// The display's name in the file [default: the display's own].
    pub display_name: Option<String>,
    /// Display technology, free text ("LCD White LED", "OLED").
    pub technology: String,
    /// Command-line settings for the display.
    pub overrides: crate::calibrate::devices::Overrides,
    pub hooks: Hooks<'a>,
}

/// The journal beside a `.ccmx`.
pub fn pairs_path(output: &Path) -> std::path::PathBuf {
    let mut name = output.as_os_str().to_owned();
    name.push(".pairs.jsonl");
    std::path::PathBuf::from(name)
}

/// Show the patch set on the display `config` names, read it with both instruments,
/// fit the correction and write it as a `.ccmx`.
pub async fn make_correction(
    config: &crate::config::Config,
    base_dir: &Path,
    request: MakeRequest<'_>,
) -> Result<(CorrectionFit, chromacal_formats::ccmx::Ccmx), MakeError> {
    use crate::calibrate::devices::{open_devices, open_instrument};
    use chromacal_instruments::Capability;
    let mut config = config.clone();
    // Neither instrument is corrected while the correction is made: by chromacal or by
    // ArgyllCMS (the new matrix would be fitted on top of the old one).
    config.instrument.correction = None;
    config.instrument.options.argyll_correction = None;
    let mut overrides = request.overrides;
    overrides.instrument = Some(request.reference.clone());
    overrides.apply(&mut config);
    let mut journal = PairJournal::open(
        &pairs_path(&request.output),
        request.resume,
        request.discard_damaged,
    )?;
    let mut devices = open_devices(&config, base_dir, None).await?;
    let reference_info = devices.instrument.info();
    if reference_info.capability != Capability::Spectral {
        devices.instrument.close();
        return Err(MakeError::Setup(format!(
            "the reference must be a spectroradiometer; the {} is not",
            reference_info.name
        )));
    }
    let mut colorimeter = match open_instrument(&config, base_dir, &request.colorimeter).await {
        Ok(i) => i,
        Err(e) => {
            devices.instrument.close();
            return Err(e.into());
        }
    };
    let colorimeter_info = colorimeter.info();
    let patches = correction_patches();
    let measured = measure_pairs(
        &mut devices.display,
        &mut devices.instrument,
        &mut colorimeter,
        &patches,
        &mut journal,
        request.aiming,
        &request.hooks,
    )
    .await;
    devices.instrument.close();
    colorimeter.close();
    let _ = devices.display.blank().await;
    measured?;
    let fit = fit_pairs(&journal.pairs)?;
    let ccmx = chromacal_formats::ccmx::Ccmx {
        matrix: fit.matrix,
        description: format!(
            "{} corrected against {}",
            colorimeter_info.name, reference_info.name
        ),
        display: request
            .display_name
            .unwrap_or_else(|| devices.display.name()),
        instrument: colorimeter_info.name,
        reference: reference_info.name,
        technology: request.technology,
    };
    let created = jiff::Timestamp::now().to_string();
    chromacal_formats::durable::write_atomic(
        &request.output,
        chromacal_formats::ccmx::ccmx_text(&ccmx, &created).as_bytes(),
    )
    .map_err(|e| MakeError::Setup(format!("{}: {e}", request.output.display())))?;
    Ok((fit, ccmx))
}

/// Why `correction make` stopped.
#[derive(Debug, thiserror::Error)]
pub enum MakeError {
    #[error(transparent)]
    Correction(#[from] CorrectionError),
    #[error(transparent)]
    Devices(#[from] crate::calibrate::devices::DevicesError),
    #[error("{0}")]
    Setup(String),
}

impl MakeError {
    /// Whether running again with `--resume` goes on (not when the journal itself
    /// is what failed, or the set-up).
    pub fn resumable(&self) -> bool {
        !matches!(
            self,
            MakeError::Correction(CorrectionError::Journal { .. }) | MakeError::Setup(_)
        )
    }
}

/// The correction an emulated PR-670 and an emulated `colorimeter` (reading through
/// its filters) make on a virtual `monitor`, both in process over in-memory transports
/// on virtual time, with noise seeded by `seed` (`chromacal bench corrections`).
pub async fn emulated_correction(
    monitor: chromacal_sim::monitor::MonitorSpec,
    colorimeter: chromacal_instruments::devices::DeviceKind,
    seed: u64,
) -> Result<CorrectionFit, MakeError> {
    use chromacal_instruments::devices::DeviceKind;
    use chromacal_instruments::driver::{AsyncSerialInstrument, DriverOptions};
    use chromacal_instruments::emulator::Meter;
    use chromacal_instruments::emulator::faults::FaultSpec;
    use chromacal_instruments::emulator::memory::MemoryTransport;
    use chromacal_instruments::simulated::{SimulatedInstrumentSpec, SimulatedKind};
    use std::sync::{Arc, Mutex};
    let clock = Arc::new(chromacal_sim::clock::VirtualClock::new(None));
    let monitor = Arc::new(Mutex::new(
        chromacal_sim::monitor::VirtualMonitor::new(monitor, clock)
            .map_err(|e| MakeError::Setup(e.to_string()))?,
    ));
    let open = |kind: DeviceKind, seed: u64| -> Result<AsyncSerialInstrument, MakeError> {
        let mut spec = SimulatedInstrumentSpec {
            seed,
            ..SimulatedInstrumentSpec::default()
        };
        if let Some(filters) = kind.filter_model() {
            spec.kind = SimulatedKind::Tristimulus;
            spec.filters = Some(filters);
        }
        let meter = Meter::new(monitor.clone(), spec, Default::default(), seed);
        let transport = MemoryTransport::new(
            kind.emulator(meter),
            FaultSpec::default(),
            kind.settings().baud,
        );
        let instrument = kind
            .connect(Box::new(transport), DriverOptions::default())
            .map_err(|e| MakeError::Setup(format!("{kind}: {e}")))?;
        Ok(AsyncSerialInstrument::new(instrument))
    };
    let mut reference = open(DeviceKind::Pr670, seed)?;
    let mut colorimeter = open(colorimeter, seed.wrapping_add(1))?;
    let mut display = chromacal_display::simulated::SimulatedDisplay::new(monitor.clone(), 0.0);
    let mut journal = PairJournal::in_memory();
    measure_pairs(
        &mut display,
        &mut reference,
        &mut colorimeter,
        &correction_patches(),
        &mut journal,
        Aiming::Together,
        &Hooks {
            stop: Box::new(|| false),
            progress: Box::new(|_, _| {}),
        },
    )
    .await?;
    Ok(fit_pairs(&journal.pairs)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(index: usize) -> PairedReading {
        let reading = |y: f64| Reading {
            xyz: Some(Xyz::new(0.95 * y, y, 1.08 * y)),
            ..Reading::default()
        };
        PairedReading {
            patch: correction_patches()[index],
            reference: reading(10.0 + index as f64),
            colorimeter: reading(10.5 + index as f64),
        }
    }

    #[test]
    fn a_damaged_line_is_named_and_set_aside_on_request_and_a_repeated_one_counts_once() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ccmx.pairs.jsonl");
        let line = |k| serde_json::to_string(&pair(k)).unwrap() + "\n";
        let text = line(0) + &line(1) + &line(1) + "garbage, not a pair\n" + &line(2);
        std::fs::write(&path, &text).unwrap();
        // Without leave, the line is named, with what to do.
        let err = PairJournal::open(&path, true, false)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("line 4 is damaged"), "{err}");
        assert!(err.contains("--discard-damaged"), "{err}");
        // With it: three patches, once each; the line kept aside; the journal clean.
        let journal = PairJournal::open(&path, true, true).unwrap();
        assert_eq!(journal.pairs.len(), 3);
        assert_eq!(journal.done(), 3);
        let aside = std::fs::read_to_string(dir.path().join("c.ccmx.pairs.jsonl.damaged")).unwrap();
        assert_eq!(aside, "garbage, not a pair\n");
        let again = PairJournal::open(&path, true, false).unwrap();
        assert_eq!(again.pairs, journal.pairs);
    }
}
