//! The survey's comparison of spectral methods (seed §3.4), measured: for families of
//! spectra, each method's counted operations, time per conversion and error against
//! the reference (ΔE*uv, as the survey scores, and ΔE00).
//!
//! Families:
//! * the 24 ColorChecker reflectances (Ohta) under illuminants A, D65 and F11, light
//!   reflected once (a spectrum–reflectance product, then an integration), each method
//!   normalising by its own integral of the illuminant (Y = 100), as a renderer would;
//! * emission spectra (the CIE illuminants, and the measured display primaries of the
//!   shared data when given), integrated alone and scored against their own reference
//!   XYZ scaled to Y = 100 (so L* = 100 and the error is the method's alone).
//!
//! Characteristic vectors are computed from the family itself (the survey's S, S·R_i
//! for a reflectance scene): Peercy's method is "representative of the scene" by
//! design, so its figures are for a basis that has seen the scene.

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use chromacal_color::difference::delta_e_uv;
use chromacal_color::spaces::xyz_to_luv;
use chromacal_color::spectrum::{Illuminant, Observer};
use chromacal_color::tables::COLORCHECKER_OHTA_5NM;
use chromacal_color::{Xyz, delta_e_2000, xyz_to_lab};
use chromacal_formats::numeric_csv::{CsvError, NumericTable};
use chromacal_model::fit::stats::ErrorStats;

use super::spectral::{
    Band, GRID_LEN, GRID_START_NM, GRID_STEP_NM, MethodKind, Operations, SpectralError,
    SpectralMethod, grid_nm, onto_grid,
};

/// One spectrum to convert.
#[derive(Debug, Clone, PartialEq)]
pub enum Case {
    /// A light seen directly.
    Emission { name: String, spectrum: Vec<f64> },
    /// `reflectance` under the family's light.
    Reflected { name: String, reflectance: Vec<f64> },
}

/// A family of spectra the table is made for.
#[derive(Debug, Clone, PartialEq)]
pub struct Family {
    pub name: String,
    /// The light of a reflectance family.
    pub light: Option<Vec<f64>>,
    pub cases: Vec<Case>,
}

impl Family {
    /// Spectra representative of the family, for characteristic vectors: the light
    /// and each reflected spectrum, or the emission spectra.
    pub fn representative(&self) -> Vec<Vec<f64>> {
        let mut out: Vec<Vec<f64>> = self.light.iter().cloned().collect();
        for case in &self.cases {
            out.push(match (case, &self.light) {
                (Case::Emission { spectrum, .. }, _) => spectrum.clone(),
                (Case::Reflected { reflectance, .. }, Some(light)) => {
                    reflectance.iter().zip(light).map(|(r, s)| r * s).collect()
                }
                (Case::Reflected { reflectance, .. }, None) => reflectance.clone(),
            });
        }
        out
    }
}

fn illuminant_on_grid(illuminant: Illuminant) -> Vec<f64> {
    let s = illuminant.spectrum();
    onto_grid(s.wavelengths_nm(), s.values())
}

/// The ColorChecker (Ohta, 380–780 nm at 5 nm: the grid itself) under `illuminant`.
pub fn colorchecker_family(illuminant: Illuminant, label: &str) -> Family {
    colorchecker_under(illuminant_on_grid(illuminant), label)
}

/// The survey's third light (seed §3.4, "a fluorescent source with four peaks"; it
/// gives no spectrum): the four mercury lines of a fluorescent tube, 404.7, 435.8,
/// 546.1 and 578 nm, each on the 5 nm sample nearest it (the survey spreads a peak
/// over the 5 nm band around it), over a flat continuum at 5 % of the highest peak
/// for the phosphor.
pub fn four_peak_fluorescent() -> Vec<f64> {
    let mut light = vec![0.05; GRID_LEN];
    for (nm, height) in [(404.7, 0.4), (435.8, 0.8), (546.1, 1.0), (578.0, 0.6)] {
        let i = ((nm - GRID_START_NM) / GRID_STEP_NM).round() as usize;
        light[i] += height;
    }
    light
}

/// The ColorChecker under a light given on the grid.
pub fn colorchecker_under(light: Vec<f64>, label: &str) -> Family {
    let cases = (0..24)
        .map(|patch| Case::Reflected {
            name: format!("patch {}", patch + 1),
            reflectance: (0..GRID_LEN)
                .map(|i| {
                    COLORCHECKER_OHTA_5NM
                        .iter()
                        .find(|row| (row[0] - grid_nm(i)).abs() < 1e-9)
                        .map_or(0.0, |row| row[patch + 1])
                })
                .collect(),
        })
        .collect();
    Family {
        name: format!("ColorChecker under {label}"),
        light: Some(light),
        cases,
    }
}

/// XYZ of the ColorChecker's 24 patches under `illuminant` by the direct sum, scaled
/// so that a perfect white would have luminance `white`; `None` if the tables are
/// unusable.
pub fn colorchecker_xyz(illuminant: Illuminant, white: f64) -> Option<Vec<Xyz>> {
    let family = colorchecker_family(illuminant, "");
    let direct = SpectralMethod::new(MethodKind::Direct, Observer::default(), &[]).ok()?;
    let light = direct.represent(family.light.as_ref()?);
    let y = direct.integrate(&light).y;
    family
        .cases
        .iter()
        .map(|c| match c {
            Case::Reflected { reflectance, .. } => Some(
                direct.integrate(&direct.product(&direct.reflectance(reflectance), &light))
                    * (white / y),
            ),
            Case::Emission { .. } => None,
        })
        .collect()
}

/// The CIE illuminants carried by chromacal, seen directly.
pub fn illuminant_family() -> Family {
    let cases = [
        (Illuminant::A, "A"),
        (Illuminant::C, "C"),
        (Illuminant::D50, "D50"),
        (Illuminant::D65, "D65"),
        (Illuminant::F2, "F2"),
        (Illuminant::F7, "F7"),
        (Illuminant::F11, "F11"),
    ]
    .into_iter()
    .map(|(i, name)| Case::Emission {
        name: name.into(),
        spectrum: illuminant_on_grid(i),
    })
    .collect();
    Family {
        name: "CIE illuminants".into(),
        light: None,
        cases,
    }
}

/// Every column of every `*.csv` in `directory` (a `wavelength_nm` column, then one
/// per primary), seen directly: the measured display primaries of the shared data.
pub fn display_family(directory: &Path) -> Result<Family, CsvError> {
    let mut files: Vec<_> = std::fs::read_dir(directory)
        .map_err(|source| CsvError::Io {
            path: directory.to_path_buf(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    let mut cases = Vec::new();
    for file in files {
        let table = NumericTable::read(&file)?;
        let wavelengths = table.column(0);
        let stem = file
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        for (k, column) in table.header.iter().enumerate().skip(1) {
            let spectrum = onto_grid(&wavelengths, &table.column(k));
            if spectrum.iter().any(|v| *v > 0.0) {
                cases.push(Case::Emission {
                    name: format!("{stem} {column}"),
                    spectrum,
                });
            }
        }
    }
    Ok(Family {
        name: "display primaries".into(),
        light: None,
        cases,
    })
}

/// The methods and parameters the table compares.
pub fn standard_methods() -> Vec<MethodKind> {
    let mut methods = vec![MethodKind::Direct];
    methods.extend([10, 20, 40].map(|step_nm| MethodKind::Sampling { step_nm }));
    methods.extend([2, 3, 4, 6, 8].map(|points| MethodKind::Gauss { points }));
    methods.extend([3, 4, 6].map(|degree| MethodKind::RasoFournier { degree }));
    methods.extend([3, 4, 6, 8, 10].map(|m| MethodKind::CharacteristicVectors { m }));
    methods
}

/// What the survey says of a method's cost or error, to print beside the measured.
pub fn survey_figure(kind: &MethodKind) -> &'static str {
    match kind {
        MethodKind::Direct => "64 samples (380–700 nm): product 64 ×; integration 192 × 189 +",
        MethodKind::Sampling { .. } => "best for products under C and D65 (no figure)",
        MethodKind::Gauss { .. } => "product Σm ×; integration Σm × Σ(m − 1) +",
        MethodKind::RasoFournier { .. } => {
            "cubic: product 80 × 58 +, integration 46 × 30 +; degree 4 for ΔE*uv < 1"
        }
        MethodKind::CharacteristicVectors { .. } => {
            "product m² × m(m − 1) +; integration 3m × 3(m − 1) +; cheapest integration"
        }
    }
}

/// One row of the table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    pub family: String,
    pub method: MethodKind,
    pub product: Operations,
    pub integration: Operations,
    /// Nanoseconds per conversion (product and integration for reflected light),
    /// when timed.
    pub nanoseconds: Option<f64>,
    pub delta_e_uv: ErrorStats,
    pub delta_e00: ErrorStats,
    /// Characteristic vectors at least as many as the family's spectra: the basis
    /// holds every one of them, so the error is nil by construction and says nothing
    /// of the method.
    pub spans_the_family: bool,
}

impl Row {
    /// Operations of one conversion of a case of this family.
    pub fn operations(&self, reflective: bool) -> usize {
        let integration = self.integration.multiplications + self.integration.additions;
        if reflective {
            integration + self.product.multiplications + self.product.additions
        } else {
            integration
        }
    }
}

/// XYZ of each case by `method`, Y of the family's light (or of the reference) = 100.
fn convert(method: &SpectralMethod, family: &Family) -> Vec<Xyz> {
    let light = family.light.as_ref().map(|s| method.represent(s));
    let light_y = light.as_ref().map(|l| method.integrate(l).y);
    family
        .cases
        .iter()
        .map(|case| match (case, &light, light_y) {
            (Case::Reflected { reflectance, .. }, Some(light), Some(y)) => {
                let r = method.reflectance(reflectance);
                method.integrate(&method.product(&r, light)) * (100.0 / y)
            }
            (Case::Emission { spectrum, .. }, _, _)
            | (
                Case::Reflected {
                    reflectance: spectrum,
                    ..
                },
                _,
                _,
            ) => method.integrate(&method.represent(spectrum)),
        })
        .collect()
}

/// Time per conversion of `method` on the family, in nanoseconds (the representation
/// made beforehand, as a renderer holds it).
fn time_per_conversion(method: &SpectralMethod, family: &Family, repeats: usize) -> f64 {
    let light = family.light.as_ref().map(|s| method.represent(s));
    let prepared: Vec<_> = family
        .cases
        .iter()
        .map(|case| match case {
            Case::Reflected { reflectance, .. } => (Some(method.reflectance(reflectance)), None),
            Case::Emission { spectrum, .. } => (None, Some(method.represent(spectrum))),
        })
        .collect();
    let start = Instant::now();
    let mut sink = 0.0;
    for _ in 0..repeats {
        for (reflectance, emission) in &prepared {
            let xyz = match (reflectance, emission, &light) {
                (Some(r), _, Some(l)) => method.integrate(&method.product(r, l)),
                (_, Some(e), _) => method.integrate(e),
                _ => Xyz::zeros(),
            };
            sink += std::hint::black_box(xyz.y);
        }
    }
    std::hint::black_box(sink);
    start.elapsed().as_nanos() as f64 / (repeats * prepared.len().max(1)) as f64
}

/// The table for one family: every method against the direct reference, both over
/// `band`. `repeats` of 0 skips the timing.
pub fn family_table(
    family: &Family,
    methods: &[MethodKind],
    observer: Observer,
    repeats: usize,
    band: Band,
) -> Result<Vec<Row>, SpectralError> {
    let reference = SpectralMethod::in_band(MethodKind::Direct, observer, &[], band)?;
    let truth = convert(&reference, family);
    // The white of the ΔE: the light's (Y = 100), or each emission's own.
    let light_white = family.light.as_ref().map(|light| {
        let xyz = reference.integrate(&reference.represent(light));
        xyz * (100.0 / xyz.y)
    });
    let white = |k: usize| light_white.unwrap_or_else(|| truth[k] * (100.0 / truth[k].y));
    let representative = family.representative();
    let mut rows = Vec::new();
    for kind in methods {
        let method = SpectralMethod::in_band(kind.clone(), observer, &representative, band)?;
        let got = convert(&method, family);
        let (mut uv, mut de00) = (Vec::new(), Vec::new());
        for (k, (g, t)) in got.iter().zip(&truth).enumerate() {
            let w = white(k);
            // An emission case is compared at its own scale (Y = 100 by the reference).
            let scale = if family.light.is_some() {
                1.0
            } else {
                100.0 / t.y
            };
            let (g, t) = (g * scale, t * scale);
            uv.push(delta_e_uv(&xyz_to_luv(&g, &w), &xyz_to_luv(&t, &w)));
            de00.push(delta_e_2000(&xyz_to_lab(&g, &w), &xyz_to_lab(&t, &w)));
        }
        let (Some(delta_e_uv), Some(delta_e00)) = (ErrorStats::of(&uv), ErrorStats::of(&de00))
        else {
            continue;
        };
        rows.push(Row {
            family: family.name.clone(),
            method: kind.clone(),
            product: method.product_operations(),
            integration: method.integration_operations(),
            nanoseconds: (repeats > 0).then(|| time_per_conversion(&method, family, repeats)),
            delta_e_uv,
            delta_e00,
            spans_the_family: matches!(kind, MethodKind::CharacteristicVectors { m } if *m >= representative.len()),
        });
    }
    Ok(rows)
}

/// The method of least operations per conversion whose mean ΔE00 is below `limit`
/// (a basis that spans the whole family does not count).
pub fn cheapest_below(rows: &[Row], reflective: bool, limit: f64) -> Option<&Row> {
    rows.iter()
        .filter(|r| r.delta_e00.mean < limit && !r.spans_the_family)
        .min_by_key(|r| r.operations(reflective))
}

/// The survey's test (seed §3.4): the 24 ColorChecker reflectances under
/// illuminants C and D65 and a four-peak fluorescent source, reflected once, over
/// 380–700 nm ([`Band::SURVEY`]).
pub fn survey_families() -> Vec<Family> {
    vec![
        colorchecker_family(Illuminant::C, "C"),
        colorchecker_family(Illuminant::D65, "D65"),
        colorchecker_under(four_peak_fluorescent(), "a four-peak fluorescent"),
    ]
}

/// The methods tried in the survey's setting: the direct sum, point sampling with
/// fewer points, Gaussian quadrature, Raso–Fournier of degree 2 to 6, and
/// characteristic vectors for every m from 1 to `max_m`.
pub fn survey_methods(max_m: usize) -> Vec<MethodKind> {
    let mut methods = vec![MethodKind::Direct];
    methods.extend([10, 20, 40].map(|step_nm| MethodKind::Sampling { step_nm }));
    methods.extend([2, 3, 4, 6, 8].map(|points| MethodKind::Gauss { points }));
    methods.extend((2..=6).map(|degree| MethodKind::RasoFournier { degree }));
    methods.extend((1..=max_m).map(|m| MethodKind::CharacteristicVectors { m }));
    methods
}

/// What the survey concluded, measured on one family's rows: the least Raso–Fournier
/// degree and the fewest characteristic vectors with a mean ΔE*uv below `limit`, and
/// the cheapest methods for the product and for the integration at that limit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Findings {
    pub family: String,
    pub least_degree: Option<usize>,
    pub fewest_vectors: Option<usize>,
    pub cheapest_product: Option<MethodKind>,
    pub cheapest_integration: Option<MethodKind>,
}

/// The survey's claims on `rows` of one family, at a mean ΔE*uv below `limit` (the
/// survey's 1, "non-perceptible").
pub fn findings(rows: &[Row], limit: f64) -> Findings {
    let good: Vec<&Row> = rows
        .iter()
        .filter(|r| r.delta_e_uv.mean < limit && !r.spans_the_family)
        .collect();
    let ops = |o: &Operations| o.multiplications + o.additions;
    Findings {
        family: rows.first().map_or(String::new(), |r| r.family.clone()),
        least_degree: good
            .iter()
            .filter_map(|r| match r.method {
                MethodKind::RasoFournier { degree } => Some(degree),
                _ => None,
            })
            .min(),
        fewest_vectors: good
            .iter()
            .filter_map(|r| match r.method {
                MethodKind::CharacteristicVectors { m } => Some(m),
                _ => None,
            })
            .min(),
        cheapest_product: good
            .iter()
            .min_by_key(|r| ops(&r.product))
            .map(|r| r.method.clone()),
        cheapest_integration: good
            .iter()
            .min_by_key(|r| ops(&r.integration))
            .map(|r| r.method.clone()),
    }
}

/// The grid as the tables describe it.
pub fn grid_description() -> String {
    format!(
        "{GRID_START_NM}–{} nm every {GRID_STEP_NM} nm ({GRID_LEN} samples)",
        grid_nm(GRID_LEN - 1)
    )
}
