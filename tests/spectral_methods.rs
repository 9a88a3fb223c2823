//! Issue 13, item 2: the survey's spectral methods, each against the direct
//! weighted-ordinate reference, on the ColorChecker under A, D65 and F11, the CIE
//! illuminants and the measured display primaries of the shared data.

use chromacal_color::spectrum::Spectrum;
use chromacal_color::spectrum::{Illuminant, Observer, reflectance_to_xyz};
use chromacal_crf::spectral::{Band, GRID_LEN, MethodKind, Operations, SpectralMethod, grid_nm};
use chromacal_crf::spectral_table::{
    Case, Family, Row, cheapest_below, colorchecker_family, display_family, family_table, findings,
    illuminant_family, standard_methods, survey_families, survey_methods,
};

mod common;
use common::{chromacal, shared_path};

fn row<'a>(rows: &'a [Row], kind: &MethodKind) -> &'a Row {
    rows.iter().find(|r| &r.method == kind).unwrap()
}

fn families() -> Vec<Family> {
    vec![
        colorchecker_family(Illuminant::A, "A"),
        colorchecker_family(Illuminant::D65, "D65"),
        colorchecker_family(Illuminant::F11, "F11"),
        illuminant_family(),
        display_family(&shared_path("displays/spd")).unwrap(),
    ]
}

#[test]
fn the_direct_method_is_chromacals_own_colorimetry() {
    // The reference of the table is the XYZ `chromacal spectrum --reflectance` gives.
    let family = colorchecker_family(Illuminant::D65, "D65");
    let direct = SpectralMethod::new(MethodKind::Direct, Observer::default(), &[]).unwrap();
    let light = direct.represent(family.light.as_ref().unwrap());
    let white_y = direct.integrate(&light).y;
    for case in &family.cases {
        let Case::Reflected { reflectance, .. } = case else {
            unreachable!()
        };
        let got = direct.integrate(&direct.product(&direct.reflectance(reflectance), &light))
            * (100.0 / white_y);
        let spectrum =
            Spectrum::new((0..GRID_LEN).map(grid_nm).collect(), reflectance.clone()).unwrap();
        let want = reflectance_to_xyz(&spectrum, Illuminant::D65, Observer::default()).unwrap();
        assert!(
            (got - want).norm() < 1e-9 * want.norm(),
            "{got:?} vs {want:?}"
        );
    }
}

#[test]
fn every_method_is_scored_against_the_reference_and_converges() {
    for family in families() {
        let rows = family_table(
            &family,
            &standard_methods(),
            Observer::default(),
            0,
            Band::FULL,
        )
        .unwrap();
        assert_eq!(rows.len(), standard_methods().len(), "{}", family.name);
        for r in &rows {
            assert!(r.delta_e00.mean.is_finite() && r.delta_e_uv.mean.is_finite());
            assert_eq!(r.delta_e00.n, family.cases.len());
        }
        assert_eq!(row(&rows, &MethodKind::Direct).delta_e00.max, 0.0);
        // More samples, a higher degree, more vectors: less error.
        let mean = |k: MethodKind| row(&rows, &k).delta_e00.mean;
        assert!(
            mean(MethodKind::Sampling { step_nm: 10 }) < mean(MethodKind::Sampling { step_nm: 40 }),
            "{}",
            family.name
        );
        assert!(
            mean(MethodKind::RasoFournier { degree: 6 })
                < mean(MethodKind::RasoFournier { degree: 3 }),
            "{}",
            family.name
        );
        assert!(
            mean(MethodKind::CharacteristicVectors { m: 10 })
                < mean(MethodKind::CharacteristicVectors { m: 3 }),
            "{}",
            family.name
        );
    }
}

#[test]
fn peaky_light_is_the_hard_case_as_the_survey_says() {
    // Under F11's three narrow bands, sampling every 10 nm misses what it does not hit;
    // under D65 it is nearly exact. Characteristic vectors of the scene handle both.
    let d65 = family_table(
        &colorchecker_family(Illuminant::D65, "D65"),
        &standard_methods(),
        Observer::default(),
        0,
        Band::FULL,
    )
    .unwrap();
    let f11 = family_table(
        &colorchecker_family(Illuminant::F11, "F11"),
        &standard_methods(),
        Observer::default(),
        0,
        Band::FULL,
    )
    .unwrap();
    let ten = MethodKind::Sampling { step_nm: 10 };
    assert!(row(&d65, &ten).delta_e00.mean < 0.1);
    assert!(row(&f11, &ten).delta_e00.mean > 1.0);
    let cva = MethodKind::CharacteristicVectors { m: 10 };
    assert!(row(&f11, &cva).delta_e00.mean < 0.1);
    // Gaussian quadrature, exact for smooth spectra of low degree, is the worst on F11.
    let gauss = MethodKind::Gauss { points: 8 };
    assert!(row(&f11, &gauss).delta_e00.mean > 10.0 * row(&d65, &gauss).delta_e00.mean);
}

#[test]
fn operations_are_the_survey_formulas() {
    let family = colorchecker_family(Illuminant::D65, "D65").representative();
    for m in [3usize, 6, 10] {
        let cva = SpectralMethod::new(
            MethodKind::CharacteristicVectors { m },
            Observer::default(),
            &family,
        )
        .unwrap();
        assert_eq!(
            cva.product_operations(),
            Operations {
                multiplications: m * m,
                additions: m * (m - 1)
            }
        );
        assert_eq!(
            cva.integration_operations(),
            Operations {
                multiplications: 3 * m,
                additions: 3 * (m - 1)
            }
        );
    }
    for points in [2usize, 5] {
        let gauss =
            SpectralMethod::new(MethodKind::Gauss { points }, Observer::default(), &[]).unwrap();
        assert_eq!(
            gauss.integration_operations(),
            Operations {
                multiplications: 3 * points,
                additions: 3 * (points - 1)
            }
        );
        assert_eq!(gauss.product_operations().multiplications, 3 * points);
    }
    let ten = SpectralMethod::new(
        MethodKind::Sampling { step_nm: 10 },
        Observer::default(),
        &[],
    )
    .unwrap();
    assert_eq!(ten.product_operations().multiplications, 41);
}

#[test]
fn the_cheapest_method_meets_its_limit_and_a_spanning_basis_does_not_count() {
    let family = illuminant_family();
    let rows = family_table(
        &family,
        &standard_methods(),
        Observer::default(),
        0,
        Band::FULL,
    )
    .unwrap();
    // Seven illuminants and m = 8 vectors: the basis holds them all.
    let spanning = row(&rows, &MethodKind::CharacteristicVectors { m: 8 });
    assert!(spanning.spans_the_family && spanning.delta_e00.max < 1e-9);
    let pick = cheapest_below(&rows, false, 0.5).unwrap();
    assert!(!pick.spans_the_family && pick.delta_e00.mean < 0.5);
    let cheaper: Vec<&Row> = rows
        .iter()
        .filter(|r| r.operations(false) < pick.operations(false) && !r.spans_the_family)
        .collect();
    assert!(cheaper.iter().all(|r| r.delta_e00.mean >= 0.5));
}

#[test]
fn bench_spectral_prints_the_table_with_the_survey_beside() {
    let out = chromacal()
        .args(["bench", "spectral", "--quick", "--data"])
        .arg(shared_path(""))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    for family in [
        "ColorChecker under A",
        "ColorChecker under D65",
        "ColorChecker under F11",
        "CIE illuminants",
        "display primaries",
    ] {
        assert!(text.contains(family), "{family}: {text}");
    }
    assert!(text.contains("integration 192 × 189 +"), "{text}");
    assert!(text.contains("Cheapest method per conversion"), "{text}");
    // Without --data, from any working directory, it finds the shared data beside the
    // project and prints the same tables (the display primaries need it; the times
    // differ from run to run, the operation counts do not).
    let elsewhere = tempfile::tempdir().unwrap();
    let again = chromacal()
        .current_dir(elsewhere.path())
        .args(["bench", "spectral", "--quick"])
        .output()
        .unwrap();
    assert!(again.status.success());
    let again = String::from_utf8_lossy(&again.stdout);
    let counts = |t: &str| -> Vec<String> {
        t.lines()
            .map(|l| l.split(" µs").next().unwrap_or(l).to_string())
            .filter(|l| l.contains("display primaries") || l.contains(" × "))
            .collect()
    };
    assert!(again.contains("display primaries"), "{again}");
    assert_eq!(counts(&again).len(), counts(&text).len());
}

#[test]
fn the_survey_setting_reproduces_its_findings() {
    // 380–700 nm, the ColorChecker under C, D65 and a four-peak fluorescent source,
    // reflected once, ΔE*uv < 1 (seed §3.4).
    let methods = survey_methods(24);
    let tables: Vec<Vec<Row>> = survey_families()
        .iter()
        .map(|f| family_table(f, &methods, Observer::default(), 0, Band::SURVEY).unwrap())
        .collect();
    let found: Vec<_> = tables.iter().map(|rows| findings(rows, 1.0)).collect();
    for f in &found[..2] {
        // Degree 4 is the least that gives ΔE*uv < 1 after one reflection.
        assert_eq!(f.least_degree, Some(4), "{f:?}");
        // Point sampling (fewer points than the reference) is the cheapest product.
        assert!(
            matches!(f.cheapest_product, Some(MethodKind::Sampling { .. })),
            "{f:?}"
        );
    }
    // Characteristic vectors are the cheapest integration under every light.
    for f in &found {
        assert!(
            matches!(
                f.cheapest_integration,
                Some(MethodKind::CharacteristicVectors { .. })
            ),
            "{f:?}"
        );
    }
    // Under the four peaks, sampling with fewer points and polynomials cannot cope;
    // characteristic vectors can.
    let fluorescent = &tables[2];
    assert!(
        row(fluorescent, &MethodKind::Sampling { step_nm: 10 })
            .delta_e_uv
            .mean
            > 10.0
    );
    assert_eq!(found[2].least_degree, None);
    assert!(found[2].fewest_vectors.is_some());
    // The setting matters: over 380–780 nm degree 4 misses under D65.
    let wide = family_table(
        &colorchecker_family(Illuminant::D65, "D65"),
        &[MethodKind::RasoFournier { degree: 4 }],
        Observer::default(),
        0,
        Band::FULL,
    )
    .unwrap();
    assert!(wide[0].delta_e_uv.mean > 1.0, "{:?}", wide[0].delta_e_uv);
}
