//! A whole verification (`crate::verify`) on the devices of a run, as `chromacal
//! verify` runs it and as a calibration with a target ends: the chart planned
//! against what the display holds now, read, read again where a verdict is
//! undecided, judged, and kept: the result beside the profile in the store
//! (`verifications/<profile>.json`, which the report shows), a line in the store's
//! verification log, and the readings as a `.ti3`.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use chromacal_display::PatchDisplay;
use chromacal_formats::durable::write_atomic_named;
use chromacal_instruments::{Instrument, Reading, ReadingStatus};
use chromacal_model::ScreenPosition;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::measurement::{Measurement, MeasurementSet, Role, Units};

use crate::calibrate::devices::{Devices, Overrides, open_devices};
use crate::config::{LoadedConfig, check_config};
use crate::profile::Profile;
use crate::profile::store::{ProfileStore, VerificationRecord};
use crate::verify::criteria::{CriteriaSet, Statistic, Verdict};
use crate::verify::{
    Against, AimPrompt, Chart, Loaded, MeasureOptions, Metric, PlannedPatch, Readings, Setting,
    VerifyReport, evaluate, measure_chart, plan, read_again,
};

/// Why a verification could not be made.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    #[error("{0}")]
    Profile(String),
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    Devices(#[from] crate::calibrate::devices::DevicesError),
    #[error("while measuring the chart: {0}")]
    Measure(#[from] crate::verify::MeasureError),
    #[error("{0}")]
    Store(#[from] crate::profile::store::StoreError),
    #[error("{0}")]
    Judge(String),
    #[error(
        "the uniformity grid is read by moving the instrument to each position: the display shows the patch off the centre and the instrument stays where it is aimed; add --prompt-positions to be asked for each move"
    )]
    UniformityUnseen,
    #[error(
        "display.prompt_positions is set, but nothing here can ask someone to move the instrument"
    )]
    NoPrompt,
}

/// What to verify, and how.
pub struct VerifyOptions {
    pub state_dir: PathBuf,
    /// The profile; the store's current one when `None`.
    pub profile: Option<PathBuf>,
    pub chart: Chart,
    pub against: Against,
    pub metric: Metric,
    pub criteria: CriteriaSet,
    /// Readings more allowed for patches whose verdict is undecided.
    pub until_decided: Option<usize>,
    pub overrides: Overrides,
    /// The correction the instrument's readings go through (the config's).
    pub correction: Option<crate::profile::CorrectionRecord>,
    /// Read white, grey and dark grey on an n × n grid too, and judge the screen's
    /// uniformity (`crate::verify::uniformity`).
    pub uniformity: Option<usize>,
}

/// What a verification did and found.
pub struct VerifyOutcome {
    pub report: VerifyReport,
    pub profile: Profile,
    pub profile_path: PathBuf,
    /// The readings as an ArgyllCMS `.ti3`.
    pub ti3: String,
    /// Where the result was kept.
    pub saved: PathBuf,
}

/// Where the newest verification of profile `id` is kept in the store at `root`; an
/// id that is not one the store gives (a hand-edited `current.toml` with `../` in
/// it) names no file.
pub fn saved_path(root: &Path, id: &str) -> Result<PathBuf, crate::profile::store::StoreError> {
    if !crate::profile::store::is_valid_id(id) {
        return Err(crate::profile::store::StoreError::InvalidId(id.to_string()));
    }
    Ok(root.join("verifications").join(format!("{id}.json")))
}

/// The newest verification of profile `id` kept in the store at `root`, if any.
pub fn saved_in(root: &Path, id: &str) -> Option<VerifyReport> {
    let text = chromacal_formats::durable::read_text_limited(
        &saved_path(root, id).ok()?,
        chromacal_formats::durable::limits::PROFILE,
    )
    .ok()?;
    serde_json::from_str(&text).ok()
}

/// The newest verification of `profile` kept beside it, if any: in the store the
/// profile is in (`current.toml`, or `profiles/<id>.toml`).
pub fn saved_for(profile_path: &Path, profile: &Profile) -> Option<VerifyReport> {
    let dir = profile_path.parent()?;
    let mut roots = vec![dir.to_path_buf()];
    roots.extend(dir.parent().map(Path::to_path_buf));
    roots.iter().find_map(|root| saved_in(root, &profile.id))
}

/// Run the verification `options` asks for, on the devices of `loaded` (with the
/// command line's overrides); `progress(done, total)` after each reading.
/// With `options.uniformity`, `aim` asks for the instrument to be moved to each
/// position where the config says someone must (`display.prompt_positions`).
pub async fn verify(
    loaded: &LoadedConfig,
    options: &VerifyOptions,
    progress: &mut (dyn FnMut(usize, usize) + Send),
    aim: Option<AimPrompt<'_>>,
) -> Result<VerifyOutcome, VerifyError> {
    options.criteria.check().map_err(VerifyError::Config)?;
    if let Some(grid) = options.uniformity {
        crate::verify::uniformity::check_grid(grid).map_err(VerifyError::Config)?;
    }
    let store = ProfileStore::new(&options.state_dir);
    let _lock = store.lock("chromacal verify")?;
    let profile_path = options
        .profile
        .clone()
        .unwrap_or_else(|| store.current_path());
    let profile = Profile::read(&profile_path).map_err(|e| {
        VerifyError::Profile(match &options.profile {
            Some(_) => e.to_string(),
            None => format!(
                "{e} (no current profile in {}: calibrate first, or name a profile)",
                store.root().display()
            ),
        })
    })?;
    // Checked before anything is measured: the result is kept under its id.
    saved_path(store.root(), &profile.id)?;
    if options.metric == Metric::Itp && profile.units != Units::Absolute {
        return Err(VerifyError::Config(
            "ΔE ITP is defined on absolute light, and the profile is relative (white Y = 100)"
                .into(),
        ));
    }
    let mut config = loaded.config.clone();
    options.overrides.apply(&mut config);
    check_config(&config).map_err(VerifyError::Config)?;
    let aim = match (options.uniformity, config.display.prompt_positions, aim) {
        (None, _, _) | (Some(_), false, _) => None,
        (Some(_), true, Some(aim)) => Some(aim),
        (Some(_), true, None) => return Err(VerifyError::NoPrompt),
    };
    // A real screen shows the grid's patches away from where the instrument is aimed;
    // only the simulated screens' instruments follow the patch.
    use crate::config::Sink;
    if options.uniformity.is_some()
        && aim.is_none()
        && matches!(
            config.display.sink(),
            Sink::Window | Sink::Wayland | Sink::Resolve | Sink::Web
        )
    {
        return Err(VerifyError::UniformityUnseen);
    }
    let mut devices = open_devices(&config, &loaded.base_dir, None).await?;
    let mut result = verify_on(
        &profile,
        options,
        config.plan.bit_depth,
        &mut devices,
        progress,
    )
    .await;
    if let (Ok((report, _, _)), Some(grid)) = (&mut result, options.uniformity) {
        let bits = config.plan.bit_depth;
        if let Err(e) =
            uniformity_on(&profile, report, grid, bits, &mut devices, aim, progress).await
        {
            result = Err(e);
        }
    }
    devices.instrument.close();
    let (mut report, planned, readings) = result?;
    said_of_the_instrument(
        &mut report,
        devices.instrument.info(),
        options.correction.clone(),
    );
    let ti3 = chromacal_formats::cgats::to_ti3(&measurement_set(
        &planned,
        &readings,
        &profile,
        devices.display.name(),
        devices.instrument.info(),
    ));
    let saved = keep(&store, &profile, &report)?;
    Ok(VerifyOutcome {
        report,
        profile,
        profile_path,
        ti3,
        saved,
    })
}

/// The verification a calibration with a target ends with: the default chart through
/// the new curves, on the run's own devices, against sRGB (for a PQ signal the
/// bt2100 chart against BT.2100 PQ in ΔE ITP, for HLG bt2100-hlg against BT.2100
/// HLG), judged by `[verify]`'s criteria
/// (DisplayCAL's defaults when it names none), and kept in `store`.
pub async fn after_calibration(
    store: &ProfileStore,
    profile: &Profile,
    config: &crate::config::VerifyConfig,
    bits: u32,
    devices: &mut Devices,
    progress: &mut (dyn FnMut(usize, usize) + Send),
) -> Result<VerifyReport, VerifyError> {
    use chromacal_crf::lut3d::SourceSpace;
    let (chart, against, metric) = match profile.provenance.signal {
        Some(chromacal_model::plan::Signal::Pq) => (
            crate::verify::chart::bt2100_chart(),
            Against::Encoding(SourceSpace::Rec2100Pq),
            Metric::Itp,
        ),
        Some(chromacal_model::plan::Signal::Hlg) => (
            crate::verify::chart::bt2100_hlg_chart(),
            Against::Encoding(SourceSpace::Rec2100Hlg),
            Metric::Itp,
        ),
        _ => (
            crate::verify::chart::default_chart(),
            Against::Encoding(SourceSpace::Srgb),
            Metric::De00,
        ),
    };
    let criteria = match (&config.criteria, config.criterion.is_empty()) {
        (None, false) => {
            if metric == Metric::Itp {
                tracing::warn!(
                    "the config's [[verify.criterion]] limits are read as ΔE ITP on this HDR run: a limit written for ΔE00 does not mean the same there"
                );
            }
            CriteriaSet {
                name: format!("the config's [[verify.criterion]] ({})", metric.name()),
                criteria: config.criterion.clone(),
            }
        }
        (name, _) => {
            crate::verify::criteria::preset(name.as_deref().unwrap_or("displaycal"), metric)
                .ok_or_else(|| VerifyError::Config(format!("no criteria {name:?}")))?
        }
    };
    let options = VerifyOptions {
        state_dir: store.root().to_path_buf(),
        profile: None,
        chart,
        against,
        metric,
        criteria,
        until_decided: None,
        overrides: Overrides::default(),
        correction: profile.provenance.correction.clone(),
        uniformity: None,
    };
    let (mut report, _, _) = verify_on(profile, &options, bits, devices, progress).await?;
    said_of_the_instrument(
        &mut report,
        devices.instrument.info(),
        profile.provenance.correction.clone(),
    );
    keep(store, profile, &report)?;
    Ok(report)
}

/// The instrument, its correction, or the warning that a colorimeter had none.
fn said_of_the_instrument(
    report: &mut VerifyReport,
    instrument: chromacal_instruments::InstrumentInfo,
    correction: Option<crate::profile::CorrectionRecord>,
) {
    let mut provenance = crate::profile::Provenance {
        source: String::new(),
        display: None,
        instrument: Some(instrument.clone()),
        measured_at: None,
        config_digest: None,
        program: String::new(),
        settings_at_resume: None,
        edid: None,
        correction: None,
        uncorrected: None,
        signal: None,
    };
    provenance.set_correction(correction);
    report.instrument = Some(instrument.name);
    report.correction = provenance.correction;
    report.uncorrected = provenance.uncorrected;
}

/// Keep `report` beside `profile` in `store`, and a line of it in the store's log.
fn keep(
    store: &ProfileStore,
    profile: &Profile,
    report: &VerifyReport,
) -> Result<PathBuf, VerifyError> {
    let saved = saved_path(store.root(), &profile.id)?;
    let json =
        serde_json::to_string_pretty(report).map_err(|e| VerifyError::Judge(e.to_string()))?;
    if let Some(dir) = saved.parent() {
        chromacal_formats::durable::create_dir(dir)
            .map_err(|e| VerifyError::Judge(format!("{}: {e}", dir.display())))?;
    }
    write_atomic_named(&saved, json.as_bytes()).map_err(|e| VerifyError::Judge(e.to_string()))?;
    let delta_e: Vec<f64> = report.patches.iter().map(|p| p.delta_e).collect();
    store.append_verification(&VerificationRecord {
        at: chromacal_formats::time::now_rfc3339(),
        profile_id: profile.id.clone(),
        metric: report.metric,
        stats: ErrorStats::of(&delta_e),
        delta_e,
        // Criteria without a mean limit: none to be past (a number JSON can carry
        // and read back, which NaN and infinity are not).
        threshold: report
            .results
            .iter()
            .find(|r| r.statistic == Statistic::Mean)
            .map_or(f64::MAX, |r| r.limit),
        escalated: false,
        journal: None,
        verdict: Some(report.verdict.name().to_string()),
    })?;
    Ok(saved)
}

/// What the display holds between the codes and the panel, for `profile`: its video
/// LUT as read back now, else the profile's curves applied to the codes (as the
/// calibration applied them where there is no LUT), else nothing.
fn loaded_now(devices: &mut Devices, profile: &Profile) -> Result<Loaded, VerifyError> {
    if let Some(window) = devices.display.window()
        && window.output().gamma_size >= 2
    {
        return window.gamma().map(Loaded::Ramp).map_err(|e| {
            VerifyError::Devices(chromacal_display::DisplayError::Lost(e.to_string()).into())
        });
    }
    Ok(match &profile.calibration {
        Some(c) => Loaded::Curves(c.curves.clone()),
        None => Loaded::Straight,
    })
}

/// Read the uniformity grid through what the display holds, judge it with the
/// session's noise (the chart's), and let its verdict join the report's.
async fn uniformity_on(
    profile: &Profile,
    report: &mut VerifyReport,
    grid: usize,
    bits: u32,
    devices: &mut Devices,
    aim: Option<AimPrompt<'_>>,
    progress: &mut (dyn FnMut(usize, usize) + Send),
) -> Result<(), VerifyError> {
    use crate::verify::uniformity;
    let loaded = loaded_now(devices, profile)?;
    let setting = Setting {
        model: &profile.model,
        curves: None,
        against: Against::Profile,
        bits,
    };
    let levels = plan(&uniformity::chart(), &setting, &loaded).map_err(VerifyError::Judge)?;
    let (readings, seconds) = crate::verify::measure_grid(
        &levels,
        grid,
        &mut devices.display,
        &mut devices.instrument,
        aim,
        progress,
    )
    .await?;
    let noise = uniformity::Noise {
        relative: report.noise.relative,
        independent: report.independent_noise,
        floor: report.noise.floor,
    };
    let judged = uniformity::judge(grid, &readings, noise).map_err(VerifyError::Judge)?;
    report.readings += grid * grid * levels.len();
    report.instrument_s += seconds;
    report.verdict = Verdict::all([report.verdict, judged.verdict]);
    report.uniformity = Some(judged);
    Ok(())
}

/// Plan, measure, judge, and read again while undecided.
async fn verify_on(
    profile: &Profile,
    options: &VerifyOptions,
    bits: u32,
    devices: &mut Devices,
    progress: &mut (dyn FnMut(usize, usize) + Send),
) -> Result<(VerifyReport, Vec<PlannedPatch>, Readings), VerifyError> {
    let loaded = loaded_now(devices, profile)?;
    let curves = profile.calibration.as_ref().map(|c| &c.curves);
    // The model corrected by the calibration's greys only where the chart asks for
    // colours (sent as `lut3d` sends them): judged against the profile, the
    // correction's own greys would grade themselves.
    let (model, greys) = match options.against {
        Against::Encoding(_) => profile.output_model(),
        Against::Profile => (Cow::Borrowed(&profile.model), None),
    };
    let setting = Setting {
        model: &model,
        curves,
        against: options.against,
        bits,
    };
    let planned = plan(&options.chart, &setting, &loaded).map_err(VerifyError::Judge)?;
    let measure = MeasureOptions::default();
    let mut readings = measure_chart(
        &planned,
        &measure,
        &mut devices.display,
        &mut devices.instrument,
        progress,
    )
    .await?;
    let judge = |readings: &Readings| {
        evaluate(
            &planned,
            readings,
            options.metric,
            &options.criteria,
            setting.white(),
            &options.chart.name,
            &options.against.name(),
        )
        .map_err(VerifyError::Judge)
    };
    let mut report = judge(&readings)?;
    let mut budget = options.until_decided.unwrap_or(0);
    while report.verdict == Verdict::Undecided && budget > 0 {
        let mut again = undecided_patches(&report, &planned);
        again.truncate(budget);
        if again.is_empty() {
            break;
        }
        budget -= again.len();
        read_again(
            &planned,
            &again,
            &mut readings,
            &measure,
            &mut devices.display,
            &mut devices.instrument,
        )
        .await?;
        report = judge(&readings)?;
    }
    report.greys = greys;
    Ok((report, planned, readings))
}

/// The patches whose readings would settle the undecided criteria: the whites for
/// the white, the greys (and whites) for grey balance, and for the ΔE statistics the
/// patches whose own interval reaches the limit (all judged patches for the mean).
fn undecided_patches(report: &VerifyReport, planned: &[PlannedPatch]) -> Vec<usize> {
    use crate::verify::Kind;
    let mut chosen: Vec<usize> = Vec::new();
    for result in report
        .results
        .iter()
        .filter(|r| r.verdict == Verdict::Undecided)
    {
        for (i, (p, r)) in planned.iter().zip(&report.patches).enumerate() {
            let pick = match result.statistic {
                Statistic::WhiteToTarget | Statistic::WhiteToProfile => p.patch.kind == Kind::White,
                Statistic::Tone => matches!(p.patch.kind, Kind::White | Kind::Grey),
                Statistic::GreyBalanceMean | Statistic::GreyBalanceRange => {
                    matches!(p.patch.kind, Kind::White | Kind::Grey | Kind::EncodedGrey)
                }
                Statistic::Mean => true,
                Statistic::Max | Statistic::Percentile99 => {
                    r.interval[0] <= result.limit && r.interval[1] > result.limit
                        || r.delta_e >= result.value - (result.interval[1] - result.interval[0])
                }
            };
            if pick && !chosen.contains(&i) {
                chosen.push(i);
            }
        }
    }
    chosen
}

/// The readings as a measurement set (each patch's mean), for the `.ti3`.
fn measurement_set(
    planned: &[PlannedPatch],
    readings: &Readings,
    profile: &Profile,
    display: String,
    instrument: chromacal_instruments::InstrumentInfo,
) -> MeasurementSet {
    MeasurementSet {
        source: format!("verification of {}", profile.id),
        units: profile.units,
        instrument: Some(instrument),
        display: Some(display),
        measured_at: Some(chromacal_formats::time::now_rfc3339()),
        measurements: planned
            .iter()
            .enumerate()
            .filter_map(|(index, p)| {
                let xyz = readings.mean(index)?;
                Some(Measurement {
                    index,
                    role: Role::Verification,
                    drive: p.codes.drive(),
                    codes: Some(p.codes),
                    position: ScreenPosition::CENTRE,
                    background: [0.0; 3],
                    window: None,
                    time_s: None,
                    reading: Reading {
                        xyz: Some(xyz),
                        status: ReadingStatus::Ok,
                        ..Reading::default()
                    },
                })
            })
            .collect(),
    }
}
