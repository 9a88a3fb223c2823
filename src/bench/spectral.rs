//! `chromacal bench spectral`: the survey's spectral methods (seed §3.4) measured,
//! family by family: counted operations, time per conversion, and ΔE*uv and ΔE00
//! against the direct weighted-ordinate reference, with the survey's own figures
//! beside; then, per family, the cheapest method under a mean ΔE00 of 0.5 and of 0.1.

use std::fmt::Write as _;

use super::{BenchError, Tables};
use std::path::Path;

use crate::report::table;
use chromacal_color::spectrum::{Illuminant, Observer};
use chromacal_crf::spectral::{Band, MethodKind, Operations};
use chromacal_crf::spectral_table::{
    Family, Row, cheapest_below, colorchecker_family, display_family, family_table, findings,
    grid_description, illuminant_family, standard_methods, survey_families, survey_figure,
    survey_methods,
};

/// Print the tables; the display primaries come from `data/displays/spd` when there.
pub(super) fn spectral_tables(
    out: &mut Tables,
    data: &Path,
    quick: bool,
) -> Result<(), BenchError> {
    let repeats = if quick { 200 } else { 2000 };
    survey_setting(out)?;
    let mut families = vec![
        (colorchecker_family(Illuminant::A, "A"), true),
        (colorchecker_family(Illuminant::D65, "D65"), true),
        (colorchecker_family(Illuminant::F11, "F11"), true),
        (illuminant_family(), false),
    ];
    let displays = data.join("displays/spd");
    if displays.is_dir() {
        families.push((display_family(&displays).map_err(|e| e.to_string())?, false));
    } else {
        out.notes.push(format!(
            "note: {} is not there: the display primaries are left out",
            displays.display()
        ));
    }
    writeln!(
        out.text,
        "Spectral methods (seed §3): spectra on {}, CIE 1931 2°; error against the direct sum on that grid; time per conversion on one core\n",
        grid_description()
    )?;
    let methods = standard_methods();
    let mut summary = Vec::new();
    for (family, reflective) in &families {
        let rows = family_table(family, &methods, Observer::default(), repeats, Band::FULL)
            .map_err(|e| e.to_string())?;
        print_family(out, family, *reflective, &rows)?;
        let pick = |limit: f64| {
            cheapest_below(&rows, *reflective, limit).map_or("none".to_string(), |r| {
                format!(
                    "{} ({}), {} ops",
                    r.method.name(),
                    r.method.parameter(),
                    r.operations(*reflective)
                )
            })
        };
        summary.push(vec![family.name.clone(), pick(0.5), pick(0.1)]);
    }
    writeln!(
        out.text,
        "Cheapest method per conversion (operations: product and integration for reflected light)"
    )?;
    writeln!(
        out.text,
        "{}",
        table(&["family", "mean ΔE00 < 0.5", "mean ΔE00 < 0.1"], &summary)
    )?;
    Ok(())
}

fn print_family(
    out: &mut Tables,
    family: &Family,
    reflective: bool,
    rows: &[Row],
) -> Result<(), BenchError> {
    writeln!(
        out.text,
        "{} ({} spectra{})",
        family.name,
        family.cases.len(),
        if reflective {
            ", reflected once: product then integration"
        } else {
            ", integration alone"
        }
    )?;
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.method.name().to_string(),
                if r.spans_the_family {
                    format!("{} (spans the family)", r.method.parameter())
                } else {
                    r.method.parameter()
                },
                operations(&r.product),
                operations(&r.integration),
                r.nanoseconds.map_or("-".into(), |n| format!("{n:.0}")),
                format!("{:.3} / {:.3}", r.delta_e_uv.mean, r.delta_e_uv.max),
                format!("{:.3} / {:.3}", r.delta_e00.mean, r.delta_e00.max),
                survey_column(&r.method),
            ]
        })
        .collect();
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "method",
                "parameters",
                "product",
                "integration",
                "ns/conv",
                "ΔE*uv mean / max",
                "ΔE00 mean / max",
                "the survey says",
            ],
            &cells
        )
    )?;
    Ok(())
}

/// The survey's figure, shown once per method (on its first parameter).
fn survey_column(kind: &MethodKind) -> String {
    let first = match kind {
        MethodKind::Direct => true,
        MethodKind::Sampling { step_nm } => *step_nm == 10,
        MethodKind::Gauss { points } => *points == 2,
        MethodKind::RasoFournier { degree } => *degree == 3,
        MethodKind::CharacteristicVectors { m } => *m == 3,
    };
    if first {
        survey_figure(kind).to_string()
    } else {
        String::new()
    }
}

/// The survey's own test (seed §3.4) in its own setting, 380–700 nm: each family's
/// rows (counted operations and ΔE*uv, every m for characteristic vectors), then its
/// conclusions measured.
fn survey_setting(out: &mut Tables) -> Result<(), BenchError> {
    writeln!(
        out.text,
        "In the survey's setting (seed §3.4): 380–700 nm, the direct sum at 5 nm (65 samples) as reference, the 24 ColorChecker reflectances reflected once under illuminants C and D65 and a four-peak fluorescent source, ΔE*uv as the survey scores\n"
    )?;
    // The family is the light and its 24 products: 25 vectors span it.
    let methods = survey_methods(24);
    let mut claims = Vec::new();
    for family in survey_families() {
        let rows = family_table(&family, &methods, Observer::default(), 0, Band::SURVEY)
            .map_err(|e| e.to_string())?;
        writeln!(out.text, "{}", family.name)?;
        let cells: Vec<Vec<String>> = rows
            .iter()
            .map(|r| {
                vec![
                    r.method.name().to_string(),
                    r.method.parameter_in(Band::SURVEY),
                    operations(&r.product),
                    operations(&r.integration),
                    format!("{:.3} / {:.3}", r.delta_e_uv.mean, r.delta_e_uv.max),
                ]
            })
            .collect();
        writeln!(
            out.text,
            "{}",
            table(
                &[
                    "method",
                    "parameters",
                    "product",
                    "integration",
                    "ΔE*uv mean / max"
                ],
                &cells
            )
        )?;
        let f = findings(&rows, 1.0);
        let name = |m: &Option<MethodKind>| {
            m.as_ref().map_or("none".to_string(), |m| {
                format!("{} ({})", m.name(), m.parameter_in(Band::SURVEY))
            })
        };
        claims.push(vec![
            f.family.clone(),
            f.least_degree.map_or("none".into(), |d| d.to_string()),
            f.fewest_vectors.map_or("none".into(), |m| m.to_string()),
            name(&f.cheapest_product),
            name(&f.cheapest_integration),
        ]);
    }
    writeln!(
        out.text,
        "The survey's conclusions, measured in its setting (mean ΔE*uv < 1):"
    )?;
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "family",
                "Raso–Fournier degree",
                "characteristic vectors",
                "cheapest product",
                "cheapest integration",
            ],
            &claims
        )
    )?;
    writeln!(
        out.text,
        "The survey says: degree 4; a basis of \"θ\" vectors (the number is illegible in its text); point sampling best for products under C and D65; characteristic vectors cheapest for integration; under the fluorescent source only segmentation (not here) and characteristic vectors cope, the first better for products\n"
    )?;
    Ok(())
}

/// Operations as the tables print them: "m × a +".
fn operations(o: &Operations) -> String {
    format!("{} × {} +", o.multiplications, o.additions)
}
