//! Colorimetry against published reference data.

use chromacal_color::adaptation::{AdaptationTransform, adaptation_matrix};
use chromacal_color::difference::delta_e_2000;
use chromacal_color::spaces::{Lab, Xyz};
use chromacal_color::spectrum::{Illuminant, Observer, Spectrum, reflectance_to_xyz};

mod common;

/// Sharma, Wu and Dalal (2005), Table 1: all 34 pairs to 1e-4.
#[test]
fn ciede2000_matches_all_34_pairs_of_sharmas_table() {
    let text = include_str!("../crates/color/data/deltae/sharma2005_ciede2000_testdata.csv");
    let mut pairs = 0;
    for line in text.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        let v: Vec<f64> = line.split(',').map(|x| x.trim().parse().unwrap()).collect();
        let lab1 = Lab {
            l: v[1],
            a: v[2],
            b: v[3],
        };
        let lab2 = Lab {
            l: v[4],
            a: v[5],
            b: v[6],
        };
        let got = delta_e_2000(&lab1, &lab2);
        assert!(
            (got - v[7]).abs() < 1e-4,
            "pair {}: got {got:.6}, published {}",
            v[0],
            v[7]
        );
        pairs += 1;
    }
    assert_eq!(pairs, 34);
}

/// The cone matrices compiled in match colour-science's table in ../shared.
#[test]
fn adaptation_matrices_match_colour_science() {
    let text = common::shared_text("standards/chromatic_adaptation_transforms.csv");
    for (name, transform) in [
        ("Bradford", AdaptationTransform::Bradford),
        ("Von Kries", AdaptationTransform::VonKries),
    ] {
        let m = transform.cone_matrix();
        for line in text.lines().filter(|l| l.starts_with(&format!("{name},"))) {
            let f: Vec<&str> = line.split(',').collect();
            let row: usize = f[1].parse().unwrap();
            for c in 0..3 {
                let want: f64 = f[2 + c].parse().unwrap();
                assert!((m[(row, c)] - want).abs() < 1e-12, "{name} [{row},{c}]");
            }
        }
    }
    // Adapting D65 to D50 carries the white exactly.
    let d65 = Xyz::new(95.047, 100.0, 108.883);
    let d50 = Xyz::new(96.422, 100.0, 82.521);
    let m = adaptation_matrix(AdaptationTransform::Bradford, &d65, &d50);
    assert!((m * d65 - d50).norm() < 1e-9);
}

/// Every tabulated illuminant white point (2°, 5 nm sums) comes back from a perfect
/// reflector, and the ColorChecker's white and black patches land where they should.
#[test]
fn illuminant_white_points_and_colorchecker() {
    let text = common::shared_text("illuminants/illuminant_whitepoints_XYZ_2deg_sum5nm.csv");
    let white = Spectrum::new(
        (0..81).map(|i| 380.0 + 5.0 * i as f64).collect(),
        vec![1.0; 81],
    )
    .unwrap();
    let mut checked = 0;
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let illuminant = match f[0] {
            "A" => Illuminant::A,
            "C" => Illuminant::C,
            "D50" => Illuminant::D50,
            "D65" => Illuminant::D65,
            "F2" => Illuminant::F2,
            "F7" => Illuminant::F7,
            "F11" => Illuminant::F11,
            other => panic!("unexpected illuminant {other}"),
        };
        let want = Xyz::new(
            f[3].parse().unwrap(),
            f[4].parse().unwrap(),
            f[5].parse().unwrap(),
        );
        let got = reflectance_to_xyz(&white, illuminant, Observer::Cie1931TwoDegree).unwrap();
        assert!((got - want).norm() < 1e-4, "{}: {got:?} vs {want:?}", f[0]);
        checked += 1;
    }
    assert_eq!(checked, 7);

    // ColorChecker (N. Ohta) white 9.5 and black 2: Y about 90 and about 3 under D65.
    let table = common::shared_table("colorchecker/colorchecker_n_ohta_5nm.csv");
    let wl: Vec<f64> = table.iter().map(|r| r[0]).collect();
    let patch = |column: usize| {
        let s = Spectrum::new(wl.clone(), table.iter().map(|r| r[column]).collect()).unwrap();
        reflectance_to_xyz(&s, Illuminant::D65, Observer::Cie1931TwoDegree).unwrap()
    };
    let white_patch = patch(19);
    let black_patch = patch(24);
    assert!((85.0..95.0).contains(&white_patch.y), "{white_patch:?}");
    assert!((2.0..4.0).contains(&black_patch.y), "{black_patch:?}");
}
