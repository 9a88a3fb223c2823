//! `chromacal correction make`: a colorimeter correction (.ccmx) made on a display
//! against a reference spectroradiometer.

use super::shared::outln;
use std::io::BufRead;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use chromacal::calibrate::correction::{
    Aiming, CorrectionFit, Errors, Hooks, MakeRequest, make_correction, pairs_path,
};
use chromacal::calibrate::devices::Overrides;
use chromacal::config::{config_search_paths, load_config_searching};
use chromacal::report::table;

use super::args::{parse_instrument, parse_sink, parse_sink_output};
use super::shared::Failure;

/// Colorimeter corrections.
#[derive(clap::Args)]
pub struct CorrectionArgs {
    #[command(subcommand)]
    command: CorrectionCommand,
}

#[derive(clap::Subcommand)]
enum CorrectionCommand {
    /// Make a correction (.ccmx) for a colorimeter on this display, against a reference
    /// spectroradiometer: each patch of a set is read by both, and the 3 × 3 matrix
    /// taking the colorimeter's XYZ to the reference's is fitted and scored on patches
    /// held out of the fit.
    Make(Box<MakeArgs>),
    /// The corrections installed where ArgyllCMS's oeminst puts them
    /// ($XDG_DATA_HOME/ArgyllCMS, $XDG_DATA_DIRS/ArgyllCMS, /usr/share/color/argyll/ref)
    /// and the user's own ($XDG_DATA_HOME/chromacal/corrections): their names are what
    /// [instrument] correction takes.
    List {
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args)]
struct MakeArgs {
    /// The reference spectroradiometer, KIND:PORT or argyll[:N].
    #[arg(long)]
    reference: String,
    /// The colorimeter to correct, KIND:PORT or argyll[:N].
    #[arg(long)]
    instrument: String,
    /// The .ccmx to write (the readings are kept beside it in FILE.pairs.jsonl).
    #[arg(short, long)]
    output: PathBuf,
    /// Go on from the readings kept beside the output.
    #[arg(long)]
    resume: bool,
    /// With --resume: set damaged lines of the readings aside (in FILE.pairs.jsonl.damaged)
    /// and read their patches again.
    #[arg(long, requires = "resume")]
    discard_damaged: bool,
    /// One instrument at a time: every patch with the reference, then you swap, then
    /// every patch with the colorimeter [default: both aimed at the patch at once].
    #[arg(long)]
    one_at_a_time: bool,
    /// The display's name in the file [default: the display's own].
    #[arg(long)]
    display_name: Option<String>,
    /// Display technology, e.g. "LCD White LED", "OLED", "CRT".
    #[arg(long, default_value = "")]
    technology: String,
    /// Config whose [display] and [instrument.options] are used [default: searched].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where patches go: window[:OUTPUT], resolve, web or emulator.
    #[arg(long, value_name = "SINK")]
    display: Option<String>,
    /// The screen socket of `chromacal emulate`.
    #[arg(long)]
    screen: Option<PathBuf>,
    /// Multiplies the instruments' protocol timeouts (for emulators run faster).
    #[arg(long, value_parser = super::shared::positive_number)]
    timing_scale: Option<f64>,
    /// Print the fit as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: CorrectionArgs) -> Result<(), Failure> {
    match args.command {
        CorrectionCommand::Make(args) => make(*args),
        CorrectionCommand::List { json } => list(json),
    }
}

fn list(json: bool) -> Result<(), Failure> {
    let found = chromacal::config::corrections::installed();
    if json {
        return outln!("{}", serde_json::to_string_pretty(&found)?);
    }
    if found.is_empty() {
        let dirs: Vec<String> = chromacal::config::corrections::correction_dirs()
            .iter()
            .map(|d| d.display().to_string())
            .collect();
        return outln!("no .ccmx or .ccss files in {}", dirs.join(", "));
    }
    for c in found {
        outln!("{}\n    {}", c.describe(), c.path.unwrap_or_default())?;
    }
    Ok(())
}

fn make(args: MakeArgs) -> Result<(), Failure> {
    let reference = parse_instrument(&args.reference)?;
    let colorimeter = parse_instrument(&args.instrument)?;
    let loaded = load_config_searching(args.config.as_deref(), &config_search_paths())?;
    let overrides = Overrides {
        screen: args.screen.clone(),
        timing_scale: args.timing_scale,
        sink: parse_sink(args.display.as_deref())?,
        output: parse_sink_output(args.display.as_deref()),
        ..Overrides::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let aiming = if args.one_at_a_time {
        Aiming::OneAtATime {
            swap: Box::new(|| {
                eprintln!(
                    "The reference has read every patch. Aim the colorimeter where the reference was, then press Enter (Ctrl-D stops)."
                );
                let mut line = String::new();
                std::io::stdin()
                    .lock()
                    .read_line(&mut line)
                    .is_ok_and(|n| n > 0)
            }),
        }
    } else {
        Aiming::Together
    };
    let request = MakeRequest {
        reference,
        colorimeter,
        output: args.output.clone(),
        resume: args.resume,
        discard_damaged: args.discard_damaged,
        aiming,
        display_name: args.display_name.clone(),
        technology: args.technology.clone(),
        overrides,
        hooks: Hooks {
            stop: Box::new(move || flag.load(Ordering::SeqCst)),
            progress: Box::new(|done, total| eprintln!("  {done}/{total} patches read by both")),
        },
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let made = runtime.block_on(async {
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::select! {
            made = make_correction(&loaded.config, &loaded.base_dir, request) => Some(made),
            _ = ctrl_c => { stop.store(true, Ordering::SeqCst); None }
        }
    });
    let (fit, ccmx) = match made {
        Some(Ok(made)) => made,
        Some(Err(e)) if e.resumable() => {
            return Err(Failure::from(format!(
                "{e}\nthe readings taken are kept in {}: run again with --resume to go on",
                pairs_path(&args.output).display()
            )));
        }
        Some(Err(e)) => return Err(Failure::from(e.to_string())),
        None => {
            return Err(Failure {
                message: format!(
                    "stopped; the readings taken are kept in {}: run again with --resume to go on",
                    pairs_path(&args.output).display()
                ),
                code: 130,
            });
        }
    };
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&fit)?)?;
        return Ok(());
    }
    outln!(
        "{} corrected against {} on {}",
        ccmx.instrument,
        ccmx.reference,
        ccmx.display
    )?;
    outln!("{}", fit_table(&fit))?;
    outln!("matrix (reference XYZ = M · colorimeter XYZ):")?;
    for r in 0..3 {
        outln!(
            "  {:>9.5} {:>9.5} {:>9.5}",
            fit.matrix[(r, 0)],
            fit.matrix[(r, 1)],
            fit.matrix[(r, 2)]
        )?;
    }
    outln!("wrote {}", args.output.display())?;
    Ok(())
}

/// The fit as a table: uncorrected and corrected ΔE00 on fitted and held-out patches,
/// beside the instruments' repeatability.
fn fit_table(fit: &CorrectionFit) -> String {
    let row = |name: &str, e: &Errors| {
        vec![
            name.to_string(),
            e.count.to_string(),
            format!("{:.3}", e.mean),
            format!("{:.3}", e.max),
        ]
    };
    table(
        &["ΔE00 against the reference", "patches", "mean", "max"],
        &[
            row("fitted, uncorrected", &fit.fitted_uncorrected),
            row("fitted, corrected", &fit.fitted_corrected),
            row("held out, uncorrected", &fit.held_out_uncorrected),
            row("held out, corrected", &fit.held_out_corrected),
            row("colorimeter repeatability", &fit.colorimeter_repeatability),
            row("reference repeatability", &fit.reference_repeatability),
        ],
    )
}
