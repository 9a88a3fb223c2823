//! `chromacal lut3d`: a 3D LUT from a source encoding to this display
//! (`chromacal_crf::lut3d`), as a `.cube` or a `.3dl` file.

use std::path::PathBuf;

use chromacal::profile::Profile;
use chromacal_crf::lut3d::{LutOptions, SourceSpace, build_lut};

use super::args::GamutArg;
use super::shared::{Failure, is_stdout, write_stdout};
use chromacal_crf::gamut::{ScbOptions, SgckSource};

/// Write a 3D LUT that shows a source encoding (sRGB, BT.709/BT.1886, Display P3,
/// Rec. 2020, BT.2100 PQ or HLG) on this display, for mpv, madVR, Resolve or
/// ffmpeg's lut3d filter.
#[derive(clap::Args)]
pub struct Lut3dArgs {
    /// The display's profile (TOML).
    profile: PathBuf,
    /// The encoding of the LUT's input: srgb, bt709 (gamma 2.4), bt1886 (BT.709
    /// through BT.1886 with this display's black), p3 (Display P3), rec2020 (through
    /// BT.1886), rec2100-pq or rec2100-hlg (HDR: BT.2020 primaries, full-range codes,
    /// the display in its PQ or HLG mode).
    #[arg(long)]
    source: SourceSpace,
    /// With --source rec2100-pq: the peak of the display the video was mastered on
    /// (cd/m², e.g. 1000 or 4000 from its HDR10 metadata); BT.2390's EETF rolls it off
    /// to this display's peak. Without it the PQ is clipped at the peak.
    #[arg(long, value_name = "CD_M2", value_parser = super::shared::positive_number)]
    mastering_peak: Option<f64>,
    /// Points along each axis (2 to 129) [default: 33 for a .cube, 17 for a .3dl, the
    /// only size ffmpeg reads in that format].
    #[arg(long)]
    size: Option<usize>,
    /// Gamut mapping of the source colours the display cannot show.
    #[arg(long, value_enum, ignore_case = true, default_value = "clip")]
    gamut: GamutArg,
    /// Keep the source's D65 white rather than carry it to the display's white: a
    /// display whose white is not D65 then cannot show the source's white at full
    /// luminance, and it is gamut-mapped like any colour outside.
    #[arg(long)]
    absolute: bool,
    /// The LUT will run while the profile's calibration curves are in the video LUT:
    /// its output is taken back through them.
    #[arg(long)]
    through_calibration: bool,
    /// Where to write it: a `.cube` (Adobe Cube 1.0) or a `.3dl` (Lustre, 12-bit)
    /// file, by its extension; `-` writes a `.cube` to standard output.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Lut3dArgs) -> Result<(), Failure> {
    if args.mastering_peak.is_some_and(|m| m > 10000.0) {
        return Err(Failure::from(
            "--mastering-peak is at most 10000 cd/m² (the top of the PQ)".to_string(),
        ));
    }
    if args.mastering_peak.is_some() && args.source != SourceSpace::Rec2100Pq {
        return Err(Failure::from(
            "--mastering-peak is for --source rec2100-pq (a PQ master's peak)".to_string(),
        ));
    }
    let profile = Profile::read(&args.profile)?;
    let three_dl = args
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("3dl"));
    if !three_dl
        && !is_stdout(&args.output)
        && !args
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("cube"))
    {
        return Err(Failure::from(format!(
            "{}: name the LUT .cube or .3dl (or give - for a .cube on standard output)",
            args.output.display()
        )));
    }
    let size = args.size.unwrap_or(if three_dl { 17 } else { 33 });
    if three_dl && size != 17 {
        eprintln!(
            "chromacal: warning: ffmpeg reads a .3dl as 17 points a side; this one has {size}"
        );
    }
    let (model, said_of_greys) = profile.output_model();
    let lut = build_lut(
        &model,
        profile.calibration.as_ref().map(|c| &c.curves),
        &LutOptions {
            source: args.source,
            size,
            // SGCK's source is the LUT's own source space (build_lut sets it).
            gamut: args.gamut.mapping(ScbOptions::default(), SgckSource::Srgb),
            absolute: args.absolute,
            through_calibration: args.through_calibration,
            mastering_peak: args.mastering_peak,
        },
    )
    .map_err(|e| Failure::from(format!("{}: {e}", args.profile.display())))?;
    let mut lut = lut;
    if args.source.is_hdr()
        && let Some(full) = profile
            .report
            .limiter
            .as_ref()
            .and_then(|l| l.full_field_white())
    {
        // The peak is a small window's; a bright scene gets less (the limiter).
        lut.notes.push(format!(
            "The display's full-field white is {:.1} cd/m2 (its brightness limiter): bright scenes show less than this LUT asks",
            full.measured_y
        ));
    }
    let text = if three_dl {
        lut.to_3dl()
    } else {
        lut.to_cube(&format!("{} to {}", args.source.name(), profile.id))
    };
    if is_stdout(&args.output) {
        write_stdout(text.as_bytes())?;
    } else {
        chromacal_formats::durable::write_atomic_named(&args.output, text.as_bytes())
            .map_err(|e| Failure::from(format!("cannot write {}: {e}", args.output.display())))?;
    }
    let moved = match &lut.mapping {
        Some(s) => format!(
            "; {} of {} grid points were outside the display's gamut, moved by ΔE00 {:.2} on average ({:.2} at most)",
            lut.outside,
            lut.table.len(),
            s.mean,
            s.max
        ),
        None => "; every grid point is inside the display's gamut".into(),
    };
    eprintln!(
        "chromacal: {}³ LUT from {} to {} written to {}{moved}",
        lut.size,
        args.source.name(),
        profile.id,
        args.output.display()
    );
    for note in &lut.notes {
        eprintln!("chromacal: {note}");
    }
    if let Some(said) = said_of_greys {
        eprintln!("chromacal: {said}");
    }
    Ok(())
}
