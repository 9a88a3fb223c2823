//! `chromacal spectrum`: spectra to XYZ, xyY, u′v′, L*a*b* and L*u*v*.

use super::shared::{out, outln};
use std::path::{Path, PathBuf};

use chromacal::report;
use chromacal_color::spaces::{Xyz, xyz_to_luv, xyz_to_uv_prime, xyz_to_xyy};
use chromacal_color::spectrum::{
    Illuminant, Observer, Spectrum, SpectrumError, emission_to_relative_xyz, emission_to_xyz,
    photopic_luminance, reflectance_to_xyz, scotopic_luminance,
};
use chromacal_color::{UvPrime, xyz_to_lab};
use chromacal_crf::spectral_file::SpectralFile;

use super::args::IlluminantArg;
use super::shared::Failure;

/// Integrate spectra to XYZ, xyY, u′v′, L*a*b* and L*u*v*.
///
/// The CSV's first column is `wavelength_nm`, each further column a sample; it is
/// read by the same rule as `render`'s: the samples must cover 400–700 nm; where
/// they stop inside 380–780 nm they are extended by repeating the nearest measured
/// value (and a warning says so). A uniform grid of whole nanometres no coarser than
/// 5 nm (1, 2, 5 nm …) is summed on its own wavelengths, the colour-matching
/// functions read there and Δλ its step (CIE 15 weighted ordinates); any other is
/// interpolated linearly first, onto the 5 nm grid when coarser (10 nm, uneven) and
/// onto 1 nm when finer (a spectrometer's 0.4 nm steps). L*a*b* and L*u*v* are taken
/// against the perfect reflector summed on the same wavelengths.
#[derive(clap::Args)]
pub struct SpectrumArgs {
    /// A CSV of spectra: wavelength (nm) in the first column, one sample a column.
    file: PathBuf,
    /// Columns are radiance spectra (the default).
    #[arg(long, conflicts_with = "reflectance")]
    emission: bool,
    /// Columns are reflectance factors (0–1) under --illuminant, with Y of the
    /// illuminant = 100.
    #[arg(long)]
    reflectance: bool,
    /// Emission: scale each sample to Y = 100 instead of absolute Y = 683 Σ S ȳ Δλ.
    #[arg(long)]
    relative: bool,
    /// Illuminant for --reflectance; for emission, the chromaticity of the
    /// reference white of L*a*b* and L*u*v*.
    #[arg(long, value_enum, ignore_case = true, default_value = "d65")]
    illuminant: IlluminantArg,
    /// Emission: luminance of the reference white [default: the brightest sample's].
    #[arg(long)]
    white_y: Option<f64>,
    /// Standard observer: 2 (CIE 1931) or 10 (CIE 1964).
    #[arg(long, default_value = "2", value_parser = ["2", "10"])]
    observer: String,
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: SpectrumArgs) -> Result<(), Failure> {
    spectrum(
        &args.file,
        args.reflectance,
        args.relative,
        args.illuminant.into(),
        args.white_y,
        &args.observer,
        args.json,
    )
}

#[derive(serde::Serialize)]
struct SpectrumResult {
    sample: String,
    xyz: [f64; 3],
    /// Chromaticity: none (null) for a sample with no light, where it is undefined.
    x: Option<f64>,
    y: Option<f64>,
    u_prime: Option<f64>,
    v_prime: Option<f64>,
    lab: [f64; 3],
    luv: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    photopic_cd_m2: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scotopic_cd_m2: Option<f64>,
}

fn spectrum(
    file: &Path,
    reflectance: bool,
    relative: bool,
    illuminant: Illuminant,
    white_y: Option<f64>,
    observer: &str,
    json: bool,
) -> Result<(), Failure> {
    if let Some(w) = white_y
        && !(w > 0.0 && w.is_finite())
    {
        return Err(Failure::from(format!(
            "--white-y must be a positive luminance, not {w}: L*a*b* and L*u*v* are relative to it"
        )));
    }
    let observer = if observer == "10" {
        Observer::Cie1964TenDegree
    } else {
        Observer::Cie1931TwoDegree
    };
    let read = SpectralFile::read(file).map_err(|e| Failure::from(e.to_string()))?;
    let mut results = Vec::new();
    let mut absolute = Vec::new();
    for (name, sample) in read.names.iter().zip(&read.spectra) {
        let in_column =
            |e: SpectrumError| Failure::from(format!("{}, column '{name}': {e}", file.display()));
        let xyz = if reflectance {
            reflectance_to_xyz(sample, illuminant, observer).map_err(in_column)?
        } else if relative {
            emission_to_relative_xyz(sample, observer).map_err(in_column)?
        } else {
            emission_to_xyz(sample, observer).map_err(in_column)?
        };
        let luminances = if !reflectance && !relative {
            Some((
                photopic_luminance(sample).map_err(in_column)?,
                scotopic_luminance(sample).ok(),
            ))
        } else {
            None
        };
        absolute.push(luminances);
        results.push((name.clone(), xyz));
    }
    // The reference white for L*a*b* and L*u*v*: the perfect reflector under the
    // illuminant, summed on the samples' own wavelengths, so that a sample equal to
    // it reads a* = b* = 0 exactly.
    let white_xyz = perfect_reflector(&read, illuminant, observer)?;
    let white_luminance = if reflectance || relative {
        100.0
    } else {
        white_y.unwrap_or_else(|| results.iter().map(|r| r.1.y).fold(0.0, f64::max))
    };
    if !(white_luminance > 0.0 && white_luminance.is_finite()) {
        return Err(Failure::from(format!(
            "{}: no sample has any light, so L*a*b* and L*u*v* have no reference white: give --white-y",
            file.display()
        )));
    }
    let white: Xyz = white_xyz * (white_luminance / 100.0);
    let out: Vec<SpectrumResult> = results
        .iter()
        .zip(&absolute)
        .map(|((name, xyz), lum)| {
            let xyy = xyz_to_xyy(xyz, [0.0, 0.0]);
            let uv = xyz_to_uv_prime(xyz, UvPrime { u: 0.0, v: 0.0 });
            let lab = xyz_to_lab(xyz, &white);
            let luv = xyz_to_luv(xyz, &white);
            let has_light = xyz.x + xyz.y + xyz.z > 0.0;
            SpectrumResult {
                sample: name.clone(),
                xyz: [xyz.x, xyz.y, xyz.z],
                x: has_light.then_some(xyy.x),
                y: has_light.then_some(xyy.y),
                u_prime: has_light.then_some(uv.u),
                v_prime: has_light.then_some(uv.v),
                lab: [lab.l, lab.a, lab.b],
                luv: [luv.l, luv.u, luv.v],
                photopic_cd_m2: lum.map(|l| l.0),
                scotopic_cd_m2: lum.and_then(|l| l.1),
            }
        })
        .collect();
    // Never a NaN or ∞ printed with success: say which sample and stop.
    if let Some(r) = out.iter().find(|r| {
        r.xyz
            .iter()
            .chain(&r.lab)
            .chain(&r.luv)
            .chain([r.x, r.y, r.u_prime, r.v_prime].iter().flatten())
            .any(|v| !v.is_finite())
    }) {
        return Err(Failure::from(format!(
            "{}, column '{}': the result is not a finite number (values out of all range?)",
            file.display(),
            r.sample
        )));
    }
    if json {
        outln!("{}", serde_json::to_string_pretty(&out)?)?;
        return Ok(());
    }
    let mode = if reflectance {
        format!("reflectance under {illuminant:?}, Y of the illuminant = 100")
    } else if relative {
        "emission, each sample scaled to Y = 100".into()
    } else {
        "emission, absolute (Y in cd/m² for radiance in W·sr⁻¹·m⁻²·nm⁻¹)".into()
    };
    outln!(
        "{} ({mode}; {} observer; L*a*b*/L*u*v* against {illuminant:?} white, Y = {white_luminance:.4})",
        file.display(),
        observer
    )?;
    let rows: Vec<Vec<String>> = out
        .iter()
        .map(|r| {
            vec![
                r.sample.clone(),
                format!("{:.4}", r.xyz[0]),
                format!("{:.4}", r.xyz[1]),
                format!("{:.4}", r.xyz[2]),
                chromaticity(r.x),
                chromaticity(r.y),
                chromaticity(r.u_prime),
                chromaticity(r.v_prime),
                format!("{:.2}", r.lab[0]),
                format!("{:.2}", r.lab[1]),
                format!("{:.2}", r.lab[2]),
                format!("{:.2}", r.luv[1]),
                format!("{:.2}", r.luv[2]),
            ]
        })
        .collect();
    out!(
        "{}",
        report::table(
            &[
                "sample", "X", "Y", "Z", "x", "y", "u′", "v′", "L*", "a*", "b*", "u*", "v*"
            ],
            &rows
        )
    )?;
    if out.iter().any(|r| r.scotopic_cd_m2.is_some()) {
        for r in &out {
            if let Some(s) = r.scotopic_cd_m2 {
                outln!("  {}: scotopic luminance {s:.4} scotopic cd/m²", r.sample)?;
            }
        }
    }
    Ok(())
}

/// XYZ (Y = 100) of the perfect reflecting diffuser under `illuminant`, on the
/// wavelengths of `read`'s samples.
fn perfect_reflector(
    read: &SpectralFile,
    illuminant: Illuminant,
    observer: Observer,
) -> Result<Xyz, Failure> {
    let grid = read.spectra[0].wavelengths_nm().to_vec();
    let ones = Spectrum::new(grid.clone(), vec![1.0; grid.len()])?;
    Ok(reflectance_to_xyz(&ones, illuminant, observer)?)
}

/// A chromaticity coordinate, or "undefined" for a sample with no light.
fn chromaticity(value: Option<f64>) -> String {
    value.map_or_else(|| "undefined".to_string(), |v| format!("{v:.4}"))
}
