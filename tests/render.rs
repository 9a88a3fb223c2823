//! Issue 13: the colour reproduction function. A default calibration of the simulated
//! CRT (15 % falloff at the corners, so its profile has a spatial map) renders scenes;
//! what the codes show, by the profile's forward model, is checked against what was
//! asked, everywhere on the screen, and each gamut mapping and tone operator is held
//! to what it promises.

use std::ffi::OsStr;
use std::path::PathBuf;
use std::sync::OnceLock;

use chromacal::profile::Profile;
use chromacal_color::spectrum::{Illuminant, Observer};
use chromacal_color::{Xyz, xyz_to_lab};
use chromacal_crf::gamut::{GamutMapping, ScbOptions, SgckSource, UniformSpace};
use chromacal_crf::spectral_table::colorchecker_xyz;
use chromacal_crf::tone::ToneOperator;
use chromacal_crf::{CodeChoice, ColourReproduction, RenderSettings, Scene, ScenePixel};
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::spatial::SpatialMap;
use chromacal_model::{MonitorModel, ScreenPosition};

mod common;
use common::chromacal;

/// The default calibration's profile, made once for this file's tests.
fn profile_path() -> &'static PathBuf {
    static PROFILE: OnceLock<PathBuf> = OnceLock::new();
    PROFILE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let state = dir.join("state");
        let out = chromacal()
            .args(["calibrate", "--state-dir"])
            .arg(&state)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        state.join("current.toml")
    })
}

/// `chromacal render PROFILE ARGS…` with the default calibration's profile.
fn render_command(args: &[&OsStr]) -> std::process::Output {
    chromacal()
        .arg("render")
        .arg(profile_path())
        .args(args)
        .output()
        .unwrap()
}

/// The same, which must succeed: its standard output.
fn render_ok(args: &[&OsStr]) -> String {
    let out = render_command(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// Width, height and samples (R, G, B a pixel) of a 16-bit RGB PNG, as the `png`
/// crate decodes it.
fn read_png16(path: &std::path::Path) -> (u32, u32, Vec<u16>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
    let samples = buffer[..info.buffer_size()]
        .chunks(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    (info.width, info.height, samples)
}

fn model() -> MonitorModel {
    Profile::read(profile_path()).unwrap().model
}

fn settings(gamut: GamutMapping, bits: u32) -> RenderSettings {
    RenderSettings {
        adaptation: None,
        tone: ToneOperator::Colorimetric,
        gamut,
        bits,
        codes: CodeChoice::default(),
    }
}

/// Positions over the whole screen, corners included.
fn grid(n: usize) -> Vec<ScreenPosition> {
    (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .map(|(i, j)| {
            ScreenPosition::new(
                0.02 + 0.96 * i as f64 / (n - 1) as f64,
                0.02 + 0.96 * j as f64 / (n - 1) as f64,
            )
        })
        .collect()
}

/// The ColorChecker under `illuminant` with its white at `white` cd/m².
fn colorchecker(white: f64, illuminant: Illuminant) -> Vec<Xyz> {
    colorchecker_xyz(illuminant, white).unwrap()
}

fn at_centre(xyz: &[Xyz]) -> Scene {
    Scene {
        pixels: xyz
            .iter()
            .map(|x| ScenePixel {
                xyz: *x,
                position: ScreenPosition::CENTRE,
            })
            .collect(),
        white: None,
    }
}

#[test]
fn in_gamut_colours_round_trip_everywhere_on_the_screen() {
    let model = model();
    assert!(
        !matches!(model.spatial, SpatialMap::Uniform),
        "the default calibration fits a spatial map"
    );
    let crf = ColourReproduction::new(&model).unwrap();
    // Colours made by the display itself at each position (so inside its gamut
    // there), from drives well inside the cube.
    let mut pixels = Vec::new();
    for (k, position) in grid(9).into_iter().enumerate() {
        let f = |s: usize| 0.1 + 0.8 * (((k * 7 + s * 3) % 11) as f64 / 10.0);
        let drive = [f(0), f(1), f(2)];
        pixels.push(ScenePixel {
            xyz: model.forward(drive, position),
            position,
        });
    }
    let scene = Scene {
        pixels: pixels.clone(),
        white: None,
    };
    let rendering = crf
        .render(&scene, &settings(GamutMapping::Clip, 16))
        .unwrap();
    assert_eq!(rendering.summary.outside, 0);
    let white = model.white();
    for (p, r) in pixels.iter().zip(&rendering.pixels) {
        let shown = model.forward(r.codes.map(|c| c as f64 / 65535.0), p.position);
        let error = delta_e00_xyz(&p.xyz, &shown, &white);
        assert!(error < 0.01, "{p:?}: ΔE00 {error}");
    }
    // At 8 bits the codes' steps are what remains.
    let eight = crf
        .render(&scene, &settings(GamutMapping::Clip, 8))
        .unwrap();
    let stats = eight.summary.inversion.unwrap();
    assert!(stats.mean < 0.3 && stats.max < 1.0, "{stats:?}");
}

#[test]
fn a_corner_gets_the_drive_that_gives_the_colour_there() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let colour = model.forward([0.5, 0.4, 0.3], ScreenPosition::CENTRE);
    let corner = ScreenPosition::new(0.05, 0.05);
    let scene = Scene {
        pixels: vec![
            ScenePixel {
                xyz: colour,
                position: ScreenPosition::CENTRE,
            },
            ScenePixel {
                xyz: colour,
                position: corner,
            },
        ],
        white: None,
    };
    let r = crf
        .render(&scene, &settings(GamutMapping::Clip, 16))
        .unwrap();
    // The corner is dimmer, so it is driven harder for the same colour…
    for c in 0..3 {
        assert!(
            r.pixels[1].codes[c] > r.pixels[0].codes[c],
            "{:?}",
            r.pixels
        );
    }
    // …and shows it, which the centre's codes would not.
    let white = model.white();
    let shown = |codes: [u32; 3]| model.forward(codes.map(|c| c as f64 / 65535.0), corner);
    assert!(delta_e00_xyz(&colour, &shown(r.pixels[1].codes), &white) < 0.01);
    assert!(delta_e00_xyz(&colour, &shown(r.pixels[0].codes), &white) > 1.0);
}

/// The ColorChecker with its white 30 % above the display's: the light patches are
/// too bright, the saturated ones too saturated.
fn hard_scene(model: &MonitorModel) -> Vec<Xyz> {
    colorchecker(1.3 * model.white().y, Illuminant::D65)
}

#[test]
fn clipping_leaves_what_is_inside_and_puts_the_rest_on_the_boundary() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let colours = hard_scene(&model);
    let r = crf
        .render(&at_centre(&colours), &settings(GamutMapping::Clip, 16))
        .unwrap();
    let gamut = crf.gamut_at(ScreenPosition::CENTRE).unwrap();
    let outside = r.pixels.iter().filter(|p| p.outside).count();
    assert!((3..24).contains(&outside), "{outside} of 24 outside");
    for (x, p) in colours.iter().zip(&r.pixels) {
        let a = gamut.to_cube(&Xyz::from(p.mapped));
        if p.outside {
            assert!(
                a.iter().any(|v| v.abs() < 1e-9 || (v - 1.0).abs() < 1e-9),
                "{a:?}"
            );
            assert!(p.mapping_delta_e00 > 0.0);
        } else {
            assert_eq!(Xyz::from(p.mapped), *x);
            assert_eq!(p.mapping_delta_e00, 0.0);
        }
    }
}

#[test]
fn the_grey_axis_clip_keeps_hue_and_the_projection_is_nearest() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let colours = hard_scene(&model);
    let white = crf.white();
    let gamut = crf.gamut_at(ScreenPosition::CENTRE).unwrap();
    let clip = crf
        .render(&at_centre(&colours), &settings(GamutMapping::Clip, 16))
        .unwrap();
    let grey = crf
        .render(
            &at_centre(&colours),
            &settings(GamutMapping::GreyAxis(UniformSpace::Lab), 16),
        )
        .unwrap();
    let perpendicular = crf
        .render(
            &at_centre(&colours),
            &settings(GamutMapping::Perpendicular, 16),
        )
        .unwrap();
    let mut hue_kept = 0;
    for (k, x) in colours.iter().enumerate() {
        let (c, g, p) = (&clip.pixels[k], &grey.pixels[k], &perpendicular.pixels[k]);
        if !c.outside {
            assert_eq!(g.mapped, c.mapped);
            assert_eq!(p.mapped, c.mapped);
            continue;
        }
        // Grey-axis clip: hue angle and (within the display's range) lightness kept,
        // chroma lower.
        let (before, after) = (
            xyz_to_lab(x, &white),
            xyz_to_lab(&Xyz::from(g.mapped), &white),
        );
        let lightest = xyz_to_lab(&gamut.white(), &white).l;
        if before.l <= lightest && before.a.hypot(before.b) > 1.0 {
            let angle = |l: &chromacal_color::Lab| l.b.atan2(l.a);
            assert!(
                (angle(&before) - angle(&after)).abs() < 1e-6,
                "{before:?} {after:?}"
            );
            assert!((before.l - after.l).abs() < 1e-6);
            hue_kept += 1;
        }
        // Clipping per channel turns hue; this one does not.
        let clipped = xyz_to_lab(&Xyz::from(c.mapped), &white);
        let turn = |l: &chromacal_color::Lab| (l.b.atan2(l.a) - before.b.atan2(before.a)).abs();
        assert!(turn(&after) <= turn(&clipped) + 1e-9);
        // Perpendicular projection: on the boundary, and no farther than the clip.
        let distance = |m: [f64; 3]| (Xyz::from(m) - x).norm();
        assert!(distance(p.mapped) <= distance(c.mapped) + 1e-9);
        assert!(!gamut.contains(x) && gamut.contains(&Xyz::from(p.mapped)));
    }
    assert!(
        hue_kept >= 1,
        "no saturated colour was mapped at constant lightness"
    );
}

/// D65's white at luminance `y`.
fn d65_white(y: f64) -> Xyz {
    chromacal_color::spectrum::white_point(Illuminant::D65, Observer::default()).unwrap()
        * (y / 100.0)
}

#[test]
fn stone_cowan_beatty_moves_the_whole_set_and_keeps_the_grey_axis() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let colours = hard_scene(&model);
    // Seen by a viewer adapted to the screen: the scene's D65 white carried to the
    // display's, so that the scene's greys are the display's greys.
    let scene = Scene {
        white: Some(d65_white(1.3 * model.white().y)),
        ..at_centre(&colours)
    };
    let settings = RenderSettings {
        adaptation: Some(chromacal_color::adaptation::AdaptationTransform::Bradford),
        ..settings(scb(0.0), 16)
    };
    let r = crf.render(&scene, &settings).unwrap();
    let scb = r.summary.stone_cowan_beatty.unwrap();
    assert!(
        scb.contrast_scale > 0.0 && scb.contrast_scale < 1.0,
        "{scb:?}"
    );
    // Every colour moved, not just those outside; with nothing allowed outside,
    // the transform alone brought them all in.
    assert!(r.pixels.iter().all(|p| p.mapping_delta_e00 > 0.0));
    let gamut = crf.gamut_at(ScreenPosition::CENTRE).unwrap();
    for p in &r.pixels {
        assert!(gamut.contains(&scb.apply(&Xyz::from(p.target))));
    }
    // SCB's first rule: the grey axis is kept. The ColorChecker's neutrals (19–23)
    // stay neutral on the display (a* and b* of the scene's own greys, about 1).
    let white = crf.white();
    let mut lightness = Vec::new();
    for k in 18..24 {
        let target = xyz_to_lab(&Xyz::from(r.pixels[k].target), &white);
        let mapped = xyz_to_lab(&Xyz::from(r.pixels[k].mapped), &white);
        assert!(
            target.a.hypot(target.b) < 2.0,
            "patch {}: {target:?}",
            k + 1
        );
        assert!(
            mapped.a.hypot(mapped.b) < 2.0,
            "patch {}: {mapped:?}",
            k + 1
        );
        lightness.push((target.l, mapped.l));
    }
    // The too-bright white comes down, the black may go up (the black shift), and
    // the greys keep their order.
    assert!(lightness[0].1 < lightness[0].0, "{lightness:?}");
    assert!(
        lightness.windows(2).all(|w| w[1].1 < w[0].1),
        "{lightness:?}"
    );
}

fn scb(outside: f64) -> GamutMapping {
    GamutMapping::StoneCowanBeatty(ScbOptions {
        outside,
        ..ScbOptions::default()
    })
}

/// ΔE00 from `xyz` to the display's grey axis (its black to its white at the centre).
fn off_grey_axis(crf: &ColourReproduction, xyz: &Xyz) -> f64 {
    let gamut = crf.gamut_at(ScreenPosition::CENTRE).unwrap();
    let (black, white) = (gamut.black(), gamut.white());
    (0..=4000)
        .map(|k| black + (white - black) * (k as f64 / 4000.0))
        .map(|g| delta_e00_xyz(xyz, &g, &crf.white()))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn stone_cowan_beatty_keeps_neutrals_on_the_grey_axis_whatever_dark_colour_the_scene_holds() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let white = model.white().y;
    // Greys of the scene's own white (D65, carried to the display's), and one dark,
    // saturated colour darker than any of them: the scene's darkest colour.
    let greys: Vec<Xyz> = [0.03, 0.1, 0.2, 0.4, 0.7, 1.0]
        .iter()
        .map(|k| d65_white(1.2 * white * k))
        .collect();
    for dark in [
        Xyz::new(0.6, 0.2, 3.0) * (white / 100.0),
        Xyz::new(1.2, 0.6, 0.1) * (white / 100.0),
        Xyz::new(0.3, 0.5, 0.2) * (white / 100.0),
    ] {
        let mut colours = greys.clone();
        colours.push(dark);
        let scene = Scene {
            white: Some(d65_white(1.2 * white)),
            ..at_centre(&colours)
        };
        let settings = RenderSettings {
            adaptation: Some(chromacal_color::adaptation::AdaptationTransform::Bradford),
            ..settings(scb(0.01), 16)
        };
        let r = crf.render(&scene, &settings).unwrap();
        for (k, p) in r.pixels[..greys.len()].iter().enumerate() {
            let off = off_grey_axis(&crf, &Xyz::from(p.mapped));
            assert!(
                off < 0.5,
                "{dark:?}: grey {k} lands {off:.2} ΔE00 off the grey axis"
            );
        }
        // The contrast is not bought with a lifted black: the scene's grey axis spans
        // most of the display's.
        let scb = r.summary.stone_cowan_beatty.unwrap();
        assert!(scb.lightness[0] < 20.0, "{dark:?}: {scb:?}");
    }
}

#[test]
fn one_highlight_does_not_darken_the_scene_under_stone_cowan_beatty() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let white = model.white().y;
    let chart = colorchecker(white, Illuminant::D65);
    let render = |colours: &[Xyz]| {
        let scene = Scene {
            white: Some(d65_white(white)),
            ..at_centre(colours)
        };
        let settings = RenderSettings {
            adaptation: Some(chromacal_color::adaptation::AdaptationTransform::Bradford),
            ..settings(scb(0.01), 16)
        };
        crf.render(&scene, &settings).unwrap()
    };
    let plain = render(&chart);
    let mut with_highlight = chart.clone();
    with_highlight.push(d65_white(10.0 * white));
    let lit = render(&with_highlight);
    let lightness =
        |r: &chromacal_crf::Rendering| xyz_to_lab(&Xyz::from(r.pixels[18].mapped), &crf.white()).l;
    assert!(
        (lightness(&plain) - lightness(&lit)).abs() < 5.0,
        "the white patch: L* {:.1} alone, {:.1} beside a highlight",
        lightness(&plain),
        lightness(&lit)
    );
    let scb = lit.summary.stone_cowan_beatty.unwrap();
    assert_eq!(scb.highlights, 1);
    // The highlight itself is projected, to the display's white or next to it.
    let top = xyz_to_lab(&Xyz::from(lit.pixels[24].mapped), &crf.white());
    assert!(top.l > 99.0 && top.a.hypot(top.b) < 1.0, "{top:?}");
}

#[test]
fn the_perceptual_mappings_leave_colours_inside_alone_and_beat_clipping() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let white = crf.white();
    // The ColorChecker under a bright light, and saturated colours beyond the display.
    let mut colours = hard_scene(&model);
    for k in 0..24 {
        let h = k as f64 * 15f64.to_radians();
        let lab = chromacal_color::Lab {
            l: 30.0 + 2.5 * k as f64,
            a: 110.0 * h.cos(),
            b: 110.0 * h.sin(),
        };
        colours.push(chromacal_color::spaces::lab_to_xyz(&lab, &white));
    }
    let render = |gamut| {
        crf.render(&at_centre(&colours), &settings(gamut, 16))
            .unwrap()
    };
    let clip = render(GamutMapping::Clip);
    let lab = render(GamutMapping::PerpendicularLab);
    let hp = render(GamutMapping::Hpminde);
    let sgck = render(GamutMapping::Sgck(SgckSource::Rec2020));
    let mean = |r: &chromacal_crf::Rendering| {
        r.pixels.iter().map(|p| p.mapping_delta_e00).sum::<f64>() / r.pixels.len() as f64
    };
    assert!(clip.summary.outside > 20, "{}", clip.summary.outside);
    assert!(
        mean(&lab) <= mean(&clip),
        "{} > {}",
        mean(&lab),
        mean(&clip)
    );
    for (k, x) in colours.iter().enumerate() {
        let (c, l, h) = (&clip.pixels[k], &lab.pixels[k], &hp.pixels[k]);
        if !c.outside {
            assert_eq!(Xyz::from(l.mapped), *x);
            assert_eq!(Xyz::from(h.mapped), *x);
            continue;
        }
        assert!(l.mapping_delta_e00 <= c.mapping_delta_e00 + 1e-9, "{k}");
        let (before, after) = (
            xyz_to_lab(x, &white),
            xyz_to_lab(&Xyz::from(h.mapped), &white),
        );
        if before.a.hypot(before.b) > 1.0 && after.a.hypot(after.b) > 1e-3 {
            let hue = |l: &chromacal_color::Lab| l.b.atan2(l.a).to_degrees();
            let turn = ((hue(&after) - hue(&before) + 540.0) % 360.0 - 180.0).abs();
            assert!(turn < 1.0, "colour {k}: HPMINDE turned hue by {turn}°");
        }
    }
    // SGCK compresses from Rec. 2020 at constant hue: what it makes is inside the
    // display and keeps each colour's CIELAB hue.
    let centre = crf.gamut_at(ScreenPosition::CENTRE).unwrap();
    for (k, x) in colours.iter().enumerate() {
        let mapped = Xyz::from(sgck.pixels[k].mapped);
        assert!(centre.contains(&mapped), "colour {k}: SGCK left it outside");
        let (before, after) = (xyz_to_lab(x, &white), xyz_to_lab(&mapped, &white));
        if before.a.hypot(before.b) > 1.0 && after.a.hypot(after.b) > 1e-3 {
            let hue = |l: &chromacal_color::Lab| l.b.atan2(l.a).to_degrees();
            let turn = ((hue(&after) - hue(&before) + 540.0) % 360.0 - 180.0).abs();
            assert!(turn < 1.0, "colour {k}: SGCK turned hue by {turn}°");
        }
    }
}

#[test]
fn the_tone_operators_map_a_bright_scene_into_the_display() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    // A sunlit ColorChecker: white at 5000 cd/m², fifty times the display's.
    let colours = colorchecker(5000.0, Illuminant::D65);
    let scene = Scene {
        white: Some(d65_white(5000.0)),
        ..at_centre(&colours)
    };
    let render = |tone| {
        crf.render(
            &scene,
            &RenderSettings {
                adaptation: None,
                tone,
                gamut: GamutMapping::Clip,
                bits: 16,
                codes: CodeChoice::default(),
            },
        )
        .unwrap()
    };
    let colorimetric = render(ToneOperator::Colorimetric);
    assert_eq!(
        colorimetric.summary.outside, 24,
        "all far too bright as they are"
    );
    let linear = render(ToneOperator::Linear);
    // The scene's white on the display's: the white patch (Y 90 %) just below it.
    let ratio = linear.pixels[18].target[1] / model.white().y;
    assert!((ratio - colours[18].y / 5000.0).abs() < 1e-9);
    let ward = render(ToneOperator::Ward { focus: None });
    let tr = render(ToneOperator::TumblinRushmeier {
        display_contrast: 35.0,
    });
    for r in [&linear, &ward, &tr] {
        assert!(r.summary.outside < 24, "{}", r.summary.tone);
        // Chromaticity kept: each target is the scene colour scaled.
        for (x, p) in colours.iter().zip(&r.pixels) {
            let t = Xyz::from(p.target);
            assert!((t.x / t.y - x.x / x.y).abs() < 1e-9);
        }
    }
    // Ward scales by one factor; Tumblin–Rushmeier by a power (it changes contrast).
    let factor = |r: &chromacal_crf::Rendering, k: usize| r.pixels[k].target[1] / colours[k].y;
    assert!((factor(&ward, 0) - factor(&ward, 18)).abs() < 1e-12);
    assert!((factor(&tr, 0) - factor(&tr, 18)).abs() > 1e-3);
}

#[test]
fn render_writes_codes_a_png_reader_gets_back() {
    let dir = tempfile::tempdir().unwrap();
    // A 4 × 3 PFM of a mid grey at 20 cd/m² over the whole screen.
    let model = model();
    let grey = model.forward([0.5; 3], ScreenPosition::CENTRE);
    let image = chromacal_crf::scene::XyzImage {
        width: 4,
        height: 3,
        xyz: vec![grey; 12],
    };
    let pfm = dir.path().join("grey.pfm");
    chromacal_crf::scene::write_pfm(&pfm, &image).unwrap();
    let png = dir.path().join("grey.png");
    let stdout = render_ok(&[
        "--image".as_ref(),
        pfm.as_os_str(),
        "-o".as_ref(),
        png.as_os_str(),
        "--bits".as_ref(),
        "10".as_ref(),
    ]);
    assert!(stdout.contains("rendered 12 pixels"), "{stdout}");
    let (width, height, samples) = read_png16(&png);
    assert_eq!((width, height), (4, 3));
    let value = |pixel: usize, c: usize| samples[pixel * 3 + c] as f64 / 65535.0;
    // The centre pixels are driven at about half; the corners, dimmer, harder.
    let centre = value(5, 1);
    assert!((centre - 0.5).abs() < 0.02, "{centre}");
    assert!(value(0, 1) > centre);
    // What the display shows for the corner pixel's codes is the grey asked for.
    let position = chromacal_crf::scene::Placement::FULL.position(0, 0, 4, 3);
    let shown = model.forward([value(0, 0), value(0, 1), value(0, 2)], position);
    assert!(delta_e00_xyz(&grey, &shown, &model.white()) < 0.3);
}

#[test]
fn render_refuses_bad_scenes_naming_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("scene.csv");
    let list_png = dir.path().join("list.png");
    let to_stdout: [&OsStr; 4] = [
        "--xyz".as_ref(),
        csv.as_os_str(),
        "-o".as_ref(),
        "-".as_ref(),
    ];
    for (text, args, named) in [
        (
            "X,Y,Z,screen_x,screen_y\n10,10,10,1.5,0.5\n",
            to_stdout,
            "row 1: screen position (1.5, 0.5) is not on the screen",
        ),
        ("X,Y,Q\n1,2,3\n", to_stdout, "no column named 'Z'"),
        // A list cannot be a PNG.
        (
            "X,Y,Z\n1,2,3\n",
            [
                "--xyz".as_ref(),
                csv.as_os_str(),
                "-o".as_ref(),
                list_png.as_os_str(),
            ],
            "a PNG needs an image scene",
        ),
    ] {
        std::fs::write(&csv, text).unwrap();
        let out = render_command(&args);
        assert!(!out.status.success(), "{text}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(named), "{stderr}");
    }
}

#[test]
fn explain_drops_the_spatial_map_for_a_centre_scene_and_keeps_it_for_a_full_screen_one() {
    use chromacal_crf::explain::{Part, explain};
    let model = model();
    let colours = colorchecker(0.8 * model.white().y, Illuminant::D65);
    let cost = |scene: &Scene| {
        let e = explain(&model, scene, &settings(GamutMapping::Clip, 16), 0.5).unwrap();
        let spatial = e
            .parts
            .iter()
            .find(|p| p.part == Part::SpatialMap)
            .unwrap()
            .clone();
        (e, spatial)
    };
    let (centre, spatial) = cost(&at_centre(&colours));
    assert!(spatial.present && spatial.dropped, "{spatial:?}");
    assert!(spatial.cost.unwrap().max < 1e-9);
    assert_eq!(centre.reduced.spatial, SpatialMap::Uniform);
    // The same colours over the whole screen, corners included.
    let positions = grid(5);
    let full = Scene {
        pixels: colours
            .iter()
            .zip(positions.iter().cycle())
            .map(|(x, p)| ScenePixel {
                xyz: *x,
                position: *p,
            })
            .collect(),
        white: None,
    };
    let (everywhere, spatial) = cost(&full);
    assert!(spatial.present && !spatial.dropped, "{spatial:?}");
    assert!(spatial.cost.unwrap().max > 0.5);
    assert_eq!(everywhere.reduced.spatial, model.spatial);
    // Whatever was dropped costs, together, less than the threshold.
    for e in [&centre, &everywhere] {
        assert!(e.combined.as_ref().is_none_or(|c| c.max < 0.5));
    }
}

#[test]
fn render_explain_chooses_a_cheaper_spectral_method_within_the_limit() {
    let checker = common::shared_path("colorchecker/colorchecker_n_ohta_5nm.csv");
    let out = render_command(&[
        "--reflectance".as_ref(),
        checker.as_os_str(),
        "--illuminant".as_ref(),
        "D65".as_ref(),
        "--explain".as_ref(),
        "--max-de00".as_ref(),
        "0.5".as_ref(),
        "-o".as_ref(),
        "-".as_ref(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = String::from_utf8_lossy(&out.stderr);
    assert!(
        report.contains("spatial map: without it mean 0.000"),
        "{report}"
    );
    assert!(
        report.contains("spatial map") && report.contains("→ dropped"),
        "{report}"
    );
    let chosen = report
        .lines()
        .find(|l| l.contains("chosen:"))
        .unwrap_or_default();
    assert!(!chosen.contains("direct"), "{report}");
    // The chosen method's line says its largest ΔE00 is within the limit.
    let name = chosen.trim().trim_start_matches("chosen: ");
    let line = report
        .lines()
        .find(|l| l.trim().starts_with(name) && l.contains("largest ΔE00"))
        .unwrap();
    let worst: f64 = line.rsplit(' ').next().unwrap().parse().unwrap();
    assert!(worst < 0.5, "{line}");
    // The codes went to standard output.
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("index,screen_x"));
}

#[test]
fn check_weighs_the_verification_by_a_scenes_colours() {
    let state = profile_path().parent().unwrap();
    let journal = common::daemon_runs(state).pop().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let model = model();
    // `check --json --scene` on a CSV of this text: its scene weighting.
    let weighted = |text: String| {
        let csv = dir.path().join("scene.csv");
        std::fs::write(&csv, text).unwrap();
        let out = chromacal()
            .arg("check")
            .arg(profile_path())
            .arg(&journal)
            .arg("--scene")
            .arg(&csv)
            .arg("--json")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        json["scene_weighted"].clone()
    };
    let run = |scene: &[Xyz]| {
        let mut text = String::from("X,Y,Z\n");
        for x in scene {
            text.push_str(&format!("{},{},{}\n", x.x, x.y, x.z));
        }
        weighted(text)
    };
    let dark: Vec<Xyz> = (1..6)
        .map(|k| model.forward([0.05 * k as f64; 3], ScreenPosition::CENTRE))
        .collect();
    let bright: Vec<Xyz> = (1..6)
        .map(|k| model.forward([0.75 + 0.05 * k as f64; 3], ScreenPosition::CENTRE))
        .collect();
    let (d, b) = (run(&dark), run(&bright));
    assert_eq!(d["colours"], 5);
    // The two scenes sample different patches, so they see different errors.
    assert_ne!(d["mean"], b["mean"], "{d} {b}");
    assert!(d["patches_used"].as_u64().unwrap() >= 1);

    // The same greys shown at the centre and in the top-left corner: the run's
    // uniformity grid measured both places, and each scene is judged where it is.
    let run_at = |x: f64, y: f64| {
        let mut text = String::from("X,Y,Z,screen_x,screen_y\n");
        for c in &bright {
            text.push_str(&format!("{},{},{},{x},{y}\n", c.x, c.y, c.z));
        }
        weighted(text)
    };
    let (centre, corner) = (run_at(0.5, 0.5), run_at(0.02, 0.03));
    assert!(
        centre["positions_measured"].as_u64().unwrap() > 1,
        "{centre}"
    );
    assert_eq!(centre["positions_used"], 1);
    assert_eq!(
        centre["mean"], b["mean"],
        "the centre is where a list without positions is"
    );
    assert_ne!(centre["mean"], corner["mean"], "{centre} {corner}");

    // A spectral scene is read by the same reader as spectrum's: its colours are
    // the ones spectrum integrates.
    let spectra = dir.path().join("spectra.csv");
    let mut text = String::from("wavelength_nm,a\n");
    for nm in (400..=700).step_by(10) {
        text.push_str(&format!("{nm},0.0004\n"));
    }
    std::fs::write(&spectra, text).unwrap();
    let out = chromacal()
        .arg("check")
        .arg(profile_path())
        .arg(&journal)
        .arg("--scene")
        .arg(&spectra)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(said.contains("weighted by the scene's 1 colours"), "{said}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("extended to 380 to 780 nm"),
        "the same warning as spectrum's"
    );
}

/// A ZIP-compressed OpenEXR of 4096 × 4096 zeros, a few megabytes, once took 7.4 GB
/// to render: its size is refused from the header, before any pixel is allocated,
/// under an address-space limit of 1.5 GB (`prlimit`) that an allocation of the
/// image would break (an abort, not this error).
#[test]
fn a_small_compressed_exr_of_sixteen_megapixels_is_refused_within_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let exr = dir.path().join("zeros.exr");
    exr::prelude::write_rgb_file(&exr, 4096, 4096, |_, _| (0.0f32, 0.0f32, 0.0f32)).unwrap();
    let bytes = std::fs::metadata(&exr).unwrap().len();
    assert!(bytes < 8 << 20, "{bytes} bytes");
    let out = std::process::Command::new("prlimit")
        .arg("--as=1500000000")
        .arg(env!("CARGO_BIN_EXE_chromacal"))
        .arg("render")
        .arg(profile_path())
        .arg("--image")
        .arg(&exr)
        .arg("-o")
        .arg(dir.path().join("out.png"))
        .env("XDG_CONFIG_HOME", "/nonexistent/chromacal-tests-config")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("4096 × 4096 pixels would take about 8.1 GB to render"),
        "{stderr}"
    );
    assert!(!dir.path().join("out.png").exists());
}

/// A spectral image of two 2048² planes (33 MB) once took 5.5 GB: every pixel's
/// spectrum on the 5 nm grid was held, twice. Integrated pixel by pixel from the
/// planes' own samples, it renders within an address-space limit of 3 GB (measured:
/// 1.7 GB resident, the render's own pixels, against 5.5 GB before).
#[test]
fn a_two_plane_spectral_image_of_four_megapixels_renders_within_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let stack = dir.path().join("stack");
    std::fs::create_dir(&stack).unwrap();
    for (nm, y) in [(400, 0.01), (700, 0.02)] {
        chromacal_crf::scene::write_pfm(
            &stack.join(format!("{nm}.pfm")),
            &chromacal_crf::scene::XyzImage {
                width: 2048,
                height: 2048,
                xyz: vec![Xyz::new(y, y, y); 2048 * 2048],
            },
        )
        .unwrap();
    }
    let png = dir.path().join("out.png");
    let out = std::process::Command::new("prlimit")
        .arg("--as=3000000000")
        .arg(env!("CARGO_BIN_EXE_chromacal"))
        .arg("render")
        .arg(profile_path())
        .arg("--spectral-image")
        .arg(&stack)
        .arg("-o")
        .arg(&png)
        .env("XDG_CONFIG_HOME", "/nonexistent/chromacal-tests-config")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (2048, 2048));
}

#[test]
fn an_openexr_image_renders_like_the_same_pfm() {
    let dir = tempfile::tempdir().unwrap();
    let model = model();
    let colour = model.forward([0.6, 0.3, 0.2], ScreenPosition::CENTRE);
    let (x, y, z) = (colour.x as f32, colour.y as f32, colour.z as f32);
    let exr = dir.path().join("scene.exr");
    exr::prelude::write_rgb_file(&exr, 3, 2, |_, _| (x, y, z)).unwrap();
    let pfm = dir.path().join("scene.pfm");
    chromacal_crf::scene::write_pfm(
        &pfm,
        &chromacal_crf::scene::XyzImage {
            width: 3,
            height: 2,
            xyz: vec![Xyz::new(x.into(), y.into(), z.into()); 6],
        },
    )
    .unwrap();
    let codes = |image: &std::path::Path| {
        render_ok(&[
            "--image".as_ref(),
            image.as_os_str(),
            "-o".as_ref(),
            "-".as_ref(),
        ])
    };
    let (a, b) = (codes(&exr), codes(&pfm));
    assert_eq!(a.lines().count(), 7);
    assert_eq!(a, b);
}

#[test]
fn the_readme_example_writes_the_colorchecker_as_a_png_laid_out_on_the_screen() {
    let dir = tempfile::tempdir().unwrap();
    let checker = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/color/data/colorchecker/colorchecker_n_ohta_5nm.csv");
    let run = |output: &std::path::Path| {
        let mut args: Vec<&OsStr> = vec!["--reflectance".as_ref(), checker.as_os_str()];
        for a in [
            "--illuminant",
            "D65",
            "--white-luminance",
            "90",
            "--grid",
            "6x4",
            "--at",
            "0.25,0.25,0.5,0.5",
            "--gamut",
            "grey-lab",
            "--explain",
            "-o",
        ] {
            args.push(a.as_ref());
        }
        args.push(output.as_os_str());
        render_ok(&args)
    };
    let png_path = dir.path().join("checker.png");
    let said = run(&png_path);
    assert!(said.contains("rendered 24 pixels"), "{said}");
    let csv_path = dir.path().join("checker.csv");
    run(&csv_path);
    let (width, height, samples) = read_png16(&png_path);
    assert_eq!((width, height), (6, 4));
    // Row by row from the top left: the PNG's pixel k is the list's patch k, its
    // codes those of the CSV, scaled from 8 bits to 16, and its place on the screen
    // the middle half.
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    for (k, line) in csv.lines().skip(1).enumerate() {
        let fields: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        let (x, y) = (fields[1], fields[2]);
        assert!((x - (0.25 + 0.5 * ((k % 6) as f64 + 0.5) / 6.0)).abs() < 1e-12);
        assert!((y - (0.25 + 0.5 * ((k / 6) as f64 + 0.5) / 4.0)).abs() < 1e-12);
        for c in 0..3 {
            let v = samples[k * 3 + c];
            assert_eq!(
                v as f64,
                fields[3 + c] * 257.0,
                "patch {} channel {c}",
                k + 1
            );
        }
    }
}

/// Screen position of pixel k of a `side` × `side` image over the whole screen, row
/// by row from the top left.
fn row_major(side: usize) -> impl Fn(usize) -> ScreenPosition + Copy {
    move |k| {
        ScreenPosition::new(
            ((k % side) as f64 + 0.5) / side as f64,
            ((k / side) as f64 + 0.5) / side as f64,
        )
    }
}

#[test]
fn the_fast_loop_round_trips_a_whole_screen_image_through_the_spatial_map() {
    // 256 × 256 pixels over the whole screen, colours the display makes there: the
    // batch loop's 16-bit codes show them, and agree with the exact inversion.
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let side = 256;
    let at = row_major(side);
    let asked: Vec<Xyz> = (0..side * side)
        .map(|k| {
            let f = |s: usize| 0.03 + 0.9 * (((k * 7919 + s * 104_729) % 1000) as f64 / 999.0);
            model.forward([f(0), f(1), f(2)], at(k))
        })
        .collect();
    let mut codes = vec![[0u16; 3]; asked.len()];
    crf.codes16(&asked, at, &mut codes);
    let white = model.white();
    let (mut worst, mut worst_against_exact): (f64, f64) = (0.0, 0.0);
    for (k, (x, c)) in asked.iter().zip(&codes).enumerate() {
        let shown = model.forward(c.map(|v| v as f64 / 65535.0), at(k));
        worst = worst.max(delta_e00_xyz(x, &shown, &white));
        // Against the exact inversion, in what the display shows (near a law's
        // cut-off drives differ by more than a code and give the same light).
        let exact = crf.drive_exact_for(x, at(k));
        let exact_shown = model.forward(exact, at(k));
        worst_against_exact = worst_against_exact.max(delta_e00_xyz(&exact_shown, &shown, &white));
    }
    assert!(worst < 0.05, "worst ΔE00 {worst}");
    assert!(worst_against_exact < 0.05, "{worst_against_exact}");
}

#[test]
fn a_four_megapixel_image_renders_through_the_whole_model() {
    // 2048 × 2048 over the whole screen, through the spatial map; the round trip is
    // checked on a spread sample of 16,384 pixels.
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let side = 2048;
    let at = row_major(side);
    // Colours the display makes where they are shown: a drive pattern that varies
    // over the screen, put through the forward model row by row.
    let drive = |k: usize| {
        let (x, y) = (k % side, k / side);
        [
            0.05 + 0.9 * (x as f64 / (side - 1) as f64),
            0.05 + 0.9 * (y as f64 / (side - 1) as f64),
            0.05 + 0.9 * (((x * 31 + y * 17) % 997) as f64 / 996.0),
        ]
    };
    let asked: Vec<Xyz> = (0..side * side)
        .map(|k| model.forward(drive(k), at(k)))
        .collect();
    let mut codes = vec![[0u16; 3]; asked.len()];
    crf.codes16(&asked, at, &mut codes);
    let white = model.white();
    let worst = (0..asked.len())
        .step_by(256)
        .map(|k| {
            let shown = model.forward(codes[k].map(|v| v as f64 / 65535.0), at(k));
            delta_e00_xyz(&asked[k], &shown, &white)
        })
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "worst ΔE00 {worst}");
}

#[test]
fn spectra_and_a_spectral_image_render_as_their_xyz_would() {
    // Three emission spectra (the CRT preset's own primaries at full drive, radiance
    // scaled to a few cd/m²) as a CSV, and the same three as a 3 × 1 spectral image of
    // per-wavelength PFM planes: both give the codes of their XYZ.
    let dir = tempfile::tempdir().unwrap();
    let spd = common::shared_table("displays/spd/colour_typical_crt_brainard1997_5nm.csv");
    let scale = 0.0005;
    let mut csv = String::from("wavelength_nm,r,g,b\n");
    for row in &spd {
        csv.push_str(&format!(
            "{},{},{},{}\n",
            row[0],
            row[1] * scale,
            row[2] * scale,
            row[3] * scale
        ));
    }
    let spectra = dir.path().join("spectra.csv");
    std::fs::write(&spectra, csv).unwrap();
    let stack = dir.path().join("stack");
    std::fs::create_dir(&stack).unwrap();
    for row in &spd {
        let plane = chromacal_crf::scene::XyzImage {
            width: 3,
            height: 1,
            xyz: (1..4).map(|c| Xyz::new(0.0, row[c] * scale, 0.0)).collect(),
        };
        // Each plane a PFM whose Y is the radiance at its wavelength (the stack reader
        // takes Y from a three-channel plane and the value from a one-channel one).
        chromacal_crf::scene::write_pfm(&stack.join(format!("{}.pfm", row[0])), &plane).unwrap();
    }
    let run = |args: &[&OsStr]| {
        let mut args = args.to_vec();
        args.extend::<[&OsStr; 2]>(["-o".as_ref(), "-".as_ref()]);
        let text = render_ok(&args);
        text.lines()
            .skip(1)
            .map(|l| {
                l.split(',')
                    .skip(3)
                    .take(6)
                    .map(|v| v.parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    // The list laid out as the image is, so that both sit at the same places.
    let from_csv = run(&[
        "--spectra".as_ref(),
        spectra.as_os_str(),
        "--grid".as_ref(),
        "3x1".as_ref(),
    ]);
    let from_stack = run(&["--spectral-image".as_ref(), stack.as_os_str()]);
    assert_eq!(from_csv.len(), 3);
    // The same targets and codes, whatever the file form.
    for (a, b) in from_csv.iter().zip(&from_stack) {
        for k in 0..6 {
            assert!(
                (a[k] - b[k]).abs() <= 1e-6 * a[k].abs().max(1.0),
                "{a:?} {b:?}"
            );
        }
    }
    // Red's spectrum gives mostly red code.
    assert!(
        from_csv[0][0] > from_csv[0][1] && from_csv[0][0] > from_csv[0][2],
        "{from_csv:?}"
    );
}

/// The default codes come from a bounded search (`crf::nearest`) that measures only
/// the corners that could be nearest: they are the literal search's, which measures all
/// 8 in the same order and keeps the first strictly nearer, on every pixel of a scene
/// from below the display's black to beyond its white, neutral and saturated, all over
/// the screen, at 8, 10, 12 and 16 bits (screened from 10); for the profile as fitted
/// (additive: the corners' steps from its box's edges) and with additivity terms (each
/// corner's shown colour).
#[test]
fn the_bounded_nearest_codes_are_the_literal_search_s() {
    let additive = model();
    let mut with_terms = model();
    with_terms.terms.interaction = Some([0.03, -0.02, 0.025]);
    with_terms.terms.chromaticity_shift =
        Some([[0.8, -0.3, 0.4], [-0.2, 0.5, 0.1], [0.3, 0.2, -1.5]]);
    assert!(additive.terms.is_empty() && !with_terms.terms.is_empty());
    for model in [additive, with_terms] {
        nearest_codes_are_the_literal_search_s(&model);
    }
}

fn nearest_codes_are_the_literal_search_s(model: &MonitorModel) {
    use chromacal_color::delta_e_2000;
    let crf = ColourReproduction::new(model).unwrap();
    let white = crf.white();
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5DEE_CE66_D1CE_4E5B);
    let mut uniform = move || rng.random::<f64>();
    let pixels: Vec<ScenePixel> = (0..30_000)
        .map(|k| {
            let y = 1.1 * white.y * uniform().powi(3);
            // One in three on the white's own chromaticity.
            let tint = if k % 3 == 0 { 0.0 } else { 0.6 };
            let xyz = Xyz::new(
                y * white.x / white.y * (1.0 + tint * (uniform() - 0.5)),
                y,
                y * white.z / white.y * (1.0 + tint * (uniform() - 0.5)),
            );
            ScenePixel {
                xyz,
                position: ScreenPosition::new(uniform(), uniform()),
            }
        })
        .collect();
    let scene = Scene {
        pixels,
        white: None,
    };
    for bits in [8, 10, 12, 16] {
        let rendering = crf
            .render(&scene, &settings(GamutMapping::Clip, bits))
            .unwrap();
        let top = f64::from((1u32 << bits) - 1);
        for (k, (p, r)) in scene.pixels.iter().zip(&rendering.pixels).enumerate() {
            let mapped = Xyz::from(r.mapped);
            let mapped_lab = xyz_to_lab(&mapped, &white);
            let scaled = crf
                .drive_for(&mapped, p.position)
                .map(|d| d.clamp(0.0, 1.0) * top);
            let error = |codes: [u32; 3]| {
                let shown = model.forward(codes.map(|c| f64::from(c) / top), p.position);
                delta_e_2000(&mapped_lab, &xyz_to_lab(&shown, &white))
            };
            let rounded = scaled.map(|v| v.round() as u32);
            let mut best = (rounded, error(rounded));
            for corner in 0..8 {
                let codes = [0, 1, 2].map(|c| {
                    if corner >> c & 1 == 1 {
                        (scaled[c].ceil() as u32).min(top as u32)
                    } else {
                        scaled[c].floor() as u32
                    }
                });
                if codes != rounded {
                    let e = error(codes);
                    if e < best.1 {
                        best = (codes, e);
                    }
                }
            }
            assert_eq!(r.codes, best.0, "{bits} bits, pixel {k}: {:?}", p.xyz);
            assert_eq!(r.inversion_delta_e00, best.1, "{bits} bits, pixel {k}");
        }
    }
}

/// Issue 27: at 8 bits the codes are the nearest of the 8 around the exact drive, in
/// ΔE00 by the profile's forward model, not each channel rounded on its own. Never
/// worse than rounding, better on some colours, and no neighbour of the chosen codes
/// in its cell is nearer; everywhere on the screen.
#[test]
fn codes_are_the_nearest_of_their_cell_in_delta_e00() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let positions = grid(3);
    let pixels: Vec<ScenePixel> = (0..660)
        .map(|k| {
            let d = [
                0.03 + 0.94 * ((k * 37 % 101) as f64 / 100.0),
                0.03 + 0.94 * ((k * 53 % 103) as f64 / 102.0),
                0.03 + 0.94 * ((k * 71 % 107) as f64 / 106.0),
            ];
            let position = positions[k % positions.len()];
            ScenePixel {
                xyz: model.forward(d, position),
                position,
            }
        })
        .collect();
    let scene = Scene {
        pixels,
        white: None,
    };
    let render = |codes| {
        crf.render(
            &scene,
            &RenderSettings {
                codes,
                ..settings(GamutMapping::Clip, 8)
            },
        )
        .unwrap()
    };
    let nearest = render(CodeChoice::NearestInDeltaE00);
    let rounded = render(CodeChoice::Rounded);
    let white = crf.white();
    let mut better = 0;
    for ((n, r), p) in nearest
        .pixels
        .iter()
        .zip(&rounded.pixels)
        .zip(&scene.pixels)
    {
        assert!(!n.outside);
        assert!(n.inversion_delta_e00 <= r.inversion_delta_e00 + 1e-12);
        if n.inversion_delta_e00 < r.inversion_delta_e00 - 0.02 {
            better += 1;
        }
        // No code of the cell around the exact drive is nearer.
        let drive = crf
            .drive_for(&Xyz::from(n.mapped), p.position)
            .map(|d| d * 255.0);
        for corner in 0..8 {
            let codes = [0, 1, 2].map(|c| {
                let v = if corner >> c & 1 == 1 {
                    drive[c].ceil()
                } else {
                    drive[c].floor()
                };
                v.clamp(0.0, 255.0) / 255.0
            });
            let error = delta_e00_xyz(
                &Xyz::from(n.mapped),
                &model.forward(codes, p.position),
                &white,
            );
            assert!(
                error >= n.inversion_delta_e00 - 1e-12,
                "at {:?}: {codes:?} shows {error}, the chosen {:?} {}",
                p.position,
                n.codes,
                n.inversion_delta_e00
            );
        }
    }
    let (n, r) = (
        nearest.summary.inversion.unwrap(),
        rounded.summary.inversion.unwrap(),
    );
    eprintln!(
        "8 bits, 660 colours: rounded mean {:.4} max {:.4}; nearest mean {:.4} max {:.4}; {better} better by more than 0.02",
        r.mean, r.max, n.mean, n.max
    );
    assert!(better > 10, "{better}");
    assert!(n.mean < r.mean && n.max <= r.max);

    // The command takes `--codes rounded` and `--codes nearest`, and gives each.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("scene.csv");
    let mut text = String::from("X,Y,Z\n");
    for p in &scene.pixels[..40] {
        text += &format!("{},{},{}\n", p.xyz.x, p.xyz.y, p.xyz.z);
    }
    std::fs::write(&csv, text).unwrap();
    let codes_of = |choice: &str| {
        render_ok(&[
            OsStr::new("--xyz"),
            csv.as_os_str(),
            OsStr::new("--codes"),
            OsStr::new(choice),
            OsStr::new("-o"),
            OsStr::new("-"),
        ])
    };
    let (by_cli_nearest, by_cli_rounded) = (codes_of("nearest"), codes_of("rounded"));
    assert_ne!(by_cli_nearest, by_cli_rounded);
    assert_eq!(by_cli_nearest, codes_of("NEAREST"));
}

#[test]
fn bench_gamut_prints_every_mapping_and_the_cielab_projection_is_nearest() {
    let out = chromacal()
        .args(["bench", "gamut", "--quick"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    // Per scene: the mean ΔE00 of each mapping, read back from the table.
    let mean = |scene: &str, mapping: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.contains(scene) && l.contains(mapping))
            .unwrap_or_else(|| panic!("no row for {mapping} on {scene}:\n{text}"));
        let cell = line
            .split("  ")
            .map(str::trim)
            .find(|c| c.contains(" / "))
            .unwrap();
        cell.split(" / ").next().unwrap().parse().unwrap()
    };
    for scene in ["ColorChecker", "saturated colours"] {
        let clip = mean(scene, "  clip  ");
        let lab = mean(scene, "perpendicular projection in CIELAB");
        assert!(
            lab <= clip,
            "{scene}: CIELAB projection {lab} > clip {clip}"
        );
        for mapping in [
            "HPMINDE",
            "SGCK",
            "Smith",
            "Stone–Cowan–Beatty",
            "in XYZ",
            "grey-axis",
        ] {
            assert!(mean(scene, mapping).is_finite());
        }
        let hpminde = text
            .lines()
            .find(|l| l.contains(scene) && l.contains("HPMINDE"))
            .unwrap();
        assert!(hpminde.contains(" 0.00 "), "HPMINDE turned hue: {hpminde}");
    }
}

/// `spectrum --json FILE ARGS`: each sample's XYZ, or the error.
fn spectrum_xyz(file: &std::path::Path, args: &[&str]) -> Result<Vec<[f64; 3]>, String> {
    let out = chromacal()
        .arg("spectrum")
        .arg(file)
        .args(args)
        .arg("--json")
        .output()
        .unwrap();
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).to_string());
    }
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    Ok(json
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let v = r["xyz"].as_array().unwrap();
            [0, 1, 2].map(|k| v[k].as_f64().unwrap())
        })
        .collect())
}

/// `render … -o -`: each pixel's target XYZ, and what was said on stderr; or the error.
fn render_targets(args: &[&OsStr]) -> Result<(Vec<[f64; 3]>, String), String> {
    let mut args = args.to_vec();
    args.extend::<[&OsStr; 2]>(["-o".as_ref(), "-".as_ref()]);
    let out = render_command(&args);
    let said = String::from_utf8_lossy(&out.stderr).to_string();
    if !out.status.success() {
        return Err(said);
    }
    let rows = String::from_utf8_lossy(&out.stdout)
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            [v[6], v[7], v[8]]
        })
        .collect();
    Ok((rows, said))
}

#[test]
fn spectrum_and_render_read_a_spectral_file_alike() {
    let dir = tempfile::tempdir().unwrap();
    // Smooth radiances: on the 5 nm grid over 380–780 nm, then on an i1Pro's 10 nm
    // grid over 400–730 nm (extended and put on the 5 nm grid by the one rule).
    let radiance = |nm: f64, k: usize| {
        let centre = [450.0, 540.0, 610.0][k];
        0.004 * (-((nm - centre) / 40.0).powi(2)).exp() + 0.0005
    };
    let write = |name: &str, from: usize, to: usize, step: usize| {
        let mut csv = String::from("wavelength_nm,a,b,c\n");
        for nm in (from..=to).step_by(step) {
            let nm = nm as f64;
            csv.push_str(&format!(
                "{nm},{},{},{}\n",
                radiance(nm, 0),
                radiance(nm, 1),
                radiance(nm, 2)
            ));
        }
        let path = dir.path().join(name);
        std::fs::write(&path, csv).unwrap();
        path
    };
    let full = write("full.csv", 380, 780, 5);
    let partial = write("partial.csv", 400, 730, 10);
    let white = Xyz::new(95.0, 100.0, 108.9);
    for (file, tolerance) in [(&full, 1e-9), (&partial, 1e-9)] {
        let from_spectrum = spectrum_xyz(file, &[]).unwrap();
        let (from_render, said) =
            render_targets(&["--spectra".as_ref(), file.as_os_str()]).unwrap();
        assert_eq!(from_spectrum.len(), 3);
        assert_eq!(from_render.len(), 3);
        for (a, b) in from_spectrum.iter().zip(&from_render) {
            let (a, b) = (Xyz::new(a[0], a[1], a[2]), Xyz::new(b[0], b[1], b[2]));
            // Relative to the sample's own luminance: ΔE00 of the two against a
            // white at the sample's Y.
            let d = delta_e00_xyz(&a, &b, &(white * (a.y / 100.0)));
            assert!(
                d <= tolerance,
                "{}: {a:?} against {b:?}, ΔE00 {d}",
                file.display()
            );
        }
        let extended = said.contains("extended to 380 to 780 nm");
        assert_eq!(extended, file == &partial, "{said}");
    }
    // Files the rule refuses: both commands say the same.
    for (name, text, expected) in [
        (
            "one.csv",
            "wavelength_nm,a\n550,0.5\n",
            "cover 550 to 550 nm",
        ),
        (
            "narrow.csv",
            "wavelength_nm,a\n450,0.5\n650,0.5\n",
            "at least 400 to 700 nm",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let a = spectrum_xyz(&path, &["--reflectance"]).unwrap_err();
        let b = render_targets(&["--reflectance".as_ref(), path.as_os_str()]).unwrap_err();
        assert!(a.contains(expected), "spectrum: {a}");
        assert!(b.contains(expected), "render: {b}");
        let sentence = |s: &str| {
            s.lines()
                .find(|l| l.contains(expected))
                .map(|l| l[l.find(name).unwrap()..].to_string())
                .unwrap()
        };
        assert_eq!(sentence(&a), sentence(&b));
    }
}

#[test]
fn a_perfect_reflector_reads_as_the_white_it_is_measured_against() {
    // A perfect white sampled by an i1Pro (400–730 nm at 10 nm): spectrum's L*a*b*
    // is 100, 0, 0, and render --adapt carries it onto the display's white exactly.
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("wavelength_nm,white\n");
    for nm in (400..=730).step_by(10) {
        csv.push_str(&format!("{nm},1\n"));
    }
    let path = dir.path().join("white.csv");
    std::fs::write(&path, csv).unwrap();
    for illuminant in ["D65", "A"] {
        let out = chromacal()
            .arg("spectrum")
            .arg(&path)
            .args(["--reflectance", "--illuminant", illuminant, "--json"])
            .output()
            .unwrap();
        assert!(out.status.success());
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for (k, want) in [(0, 100.0), (1, 0.0), (2, 0.0)] {
            for key in ["lab", "luv"] {
                let v = json[0][key][k].as_f64().unwrap();
                assert!((v - want).abs() < 1e-9, "{illuminant} {key}[{k}] = {v}");
            }
        }
        let (targets, _) = render_targets(&[
            "--reflectance".as_ref(),
            path.as_os_str(),
            "--illuminant".as_ref(),
            illuminant.as_ref(),
            "--adapt".as_ref(),
        ])
        .unwrap();
        let profile = chromacal::profile::Profile::read(profile_path()).unwrap();
        let display = profile.model.white();
        let t = Xyz::new(targets[0][0], targets[0][1], targets[0][2]);
        let chromaticity = |x: &Xyz| [x.x / (x.x + x.y + x.z), x.y / (x.x + x.y + x.z)];
        let (a, b) = (chromaticity(&t), chromaticity(&display));
        assert!(
            (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9,
            "{illuminant}: the white lands at {a:?}, the display's is {b:?}"
        );
    }
}

#[test]
fn explain_reports_what_the_whole_profile_shows_for_its_codes() {
    // Greys and colours at the centre and a corner; --explain with a loose limit drops
    // parts of the model, and the shown XYZ written are still the full profile's.
    let dir = tempfile::tempdir().unwrap();
    let model = model();
    let mut csv = String::from("X,Y,Z,screen_x,screen_y\n");
    for (k, rgb) in [
        [0.2, 0.2, 0.2],
        [0.6, 0.3, 0.1],
        [0.1, 0.5, 0.7],
        [0.9, 0.9, 0.8],
    ]
    .iter()
    .enumerate()
    {
        let at = if k % 2 == 0 {
            ScreenPosition::CENTRE
        } else {
            ScreenPosition::new(0.1, 0.1)
        };
        let xyz = model.forward(*rgb, at);
        csv.push_str(&format!(
            "{},{},{},{},{}\n",
            xyz.x, xyz.y, xyz.z, at.x, at.y
        ));
    }
    let scene = dir.path().join("scene.csv");
    std::fs::write(&scene, csv).unwrap();
    let out = dir.path().join("out.csv");
    let said = render_ok(&[
        "--xyz".as_ref(),
        scene.as_os_str(),
        "--explain".as_ref(),
        "--max-de00".as_ref(),
        "5".as_ref(),
        "--bits".as_ref(),
        "10".as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    assert!(said.contains("→ dropped"), "{said}");
    let text = std::fs::read_to_string(&out).unwrap();
    let mut differs = 0;
    for line in text.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let at = ScreenPosition::new(v[1], v[2]);
        let full = model.forward([v[3] / 1023.0, v[4] / 1023.0, v[5] / 1023.0], at);
        let shown = Xyz::new(v[9], v[10], v[11]);
        assert!(
            (shown - full).norm() <= 1e-9 * full.norm().max(1.0),
            "{line}"
        );
        // The reduced model's codes miss the asked colour by what was dropped.
        let asked = Xyz::new(v[6], v[7], v[8]);
        if delta_e00_xyz(&asked, &full, &model.white()) > 0.05 {
            differs += 1;
        }
    }
    assert!(differs > 0, "nothing dropped made a difference:\n{text}");
}

#[test]
fn ward_adapts_to_the_mean_luminance_of_the_focus_area() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    // A sunlit left half (2000 cd/m²) and a shaded right half (20 cd/m²).
    let grey = |y: f64, x: f64| ScenePixel {
        xyz: d65_white(y),
        position: ScreenPosition::new(x, 0.5),
    };
    let scene = Scene {
        pixels: vec![
            grey(2000.0, 0.1),
            grey(1000.0, 0.3),
            grey(20.0, 0.7),
            grey(10.0, 0.9),
        ],
        white: None,
    };
    let factor = |focus| {
        let r = crf
            .render(
                &scene,
                &RenderSettings {
                    adaptation: None,
                    tone: ToneOperator::Ward { focus },
                    ..settings(GamutMapping::Clip, 16)
                },
            )
            .unwrap();
        r.pixels[3].target[1] / scene.pixels[3].xyz.y
    };
    let area = |left| chromacal_crf::scene::Placement {
        left,
        top: 0.0,
        width: 0.5,
        height: 1.0,
    };
    // Ward's m from an adaptation luminance, on this display (L_da = L_dmax / 2).
    let m = |la: f64| {
        let lda = model.white().y / 2.0;
        ((1.219 + lda.powf(0.4)) / (1.219 + la.powf(0.4))).powf(2.5)
    };
    let (sunlit, shaded, whole) = (
        factor(Some(area(0.0))),
        factor(Some(area(0.5))),
        factor(None),
    );
    assert!((sunlit / m(1500.0) - 1.0).abs() < 1e-9, "{sunlit}");
    assert!((shaded / m(15.0) - 1.0).abs() < 1e-9, "{shaded}");
    assert!((whole / m(757.5) - 1.0).abs() < 1e-9, "{whole}");
    assert!(shaded > 10.0 * sunlit);
    // A focus area with nothing in it is refused by name.
    let empty = crf.render(
        &Scene {
            pixels: vec![grey(100.0, 0.9)],
            white: None,
        },
        &RenderSettings {
            adaptation: None,
            tone: ToneOperator::Ward {
                focus: Some(area(0.0)),
            },
            ..settings(GamutMapping::Clip, 16)
        },
    );
    assert!(empty.unwrap_err().to_string().contains("focus area"));
    // From the command line, --focus is Ward's alone.
    let out = render_command(&[
        "--xyz".as_ref(),
        "nonexistent.csv".as_ref(),
        "--focus".as_ref(),
        "0,0,0.5,0.5".as_ref(),
        "-o".as_ref(),
        "-".as_ref(),
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--tone ward"));
}

/// Pixels are rendered over all cores a band at a time and handed on in the scene's
/// order: in a scene longer than two bands (2¹⁶ pixels each), every pixel (sampled,
/// and those at the bands' edges) is what it is rendered alone.
#[test]
fn a_scene_rendered_over_the_cores_keeps_its_order() {
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let n = 2 * 65_536 + 5;
    let pixels: Vec<ScenePixel> = (0..n)
        .map(|k| {
            let f = |m: usize| ((k * m) % 1009) as f64 / 1008.0;
            let position = ScreenPosition::new(f(3), f(5));
            ScenePixel {
                xyz: model.forward([f(7), f(11), f(13)], position) * 1.02,
                position,
            }
        })
        .collect();
    let scene = Scene {
        pixels,
        white: None,
    };
    let settings = settings(GamutMapping::Clip, 8);
    let whole = crf.render(&scene, &settings).unwrap();
    assert_eq!(whole.pixels.len(), n);
    let edges = [0, 65_535, 65_536, 65_537, 131_071, 131_072, n - 1];
    for k in (0..n).step_by(997).chain(edges) {
        let alone = Scene {
            pixels: vec![scene.pixels[k]],
            white: None,
        };
        let one = crf.render(&alone, &settings).unwrap();
        assert_eq!(whole.pixels[k], one.pixels[0], "pixel {k}");
    }
}

/// A scene larger than `INVERSION_SAMPLE` pixels has its inversion ΔE00 measured on a
/// sample when written as codes: the same codes and mapping ΔE00 as the whole
/// rendering, and the inversion's statistics those of the pixels `inversion_measured`
/// picks (70,000 pixels: one in two, about 35,000). The sample is spread over an
/// image's columns, not the same ones in every row.
#[test]
fn a_large_image_s_inversion_is_measured_on_a_stated_sample() {
    use chromacal_crf::{INVERSION_SAMPLE, inversion_measured};
    use chromacal_model::fit::stats::ErrorStats;
    let model = model();
    let crf = ColourReproduction::new(&model).unwrap();
    let n = 70_000;
    assert!(n > INVERSION_SAMPLE && n <= 2 * INVERSION_SAMPLE);
    let pixels: Vec<ScenePixel> = (0..n)
        .map(|k| {
            let f = |m: usize| ((k * m) % 997) as f64 / 996.0;
            ScenePixel {
                xyz: Xyz::new(90.0 * f(7), 0.5 + 90.0 * f(13), 100.0 * f(31)),
                position: ScreenPosition::new(f(3), f(5)),
            }
        })
        .collect();
    let scene = Scene {
        pixels,
        white: None,
    };
    let settings = settings(GamutMapping::Clip, 16);
    let whole = crf.render(&scene, &settings).unwrap();
    let (codes, summary) = crf.render_codes(&scene, &settings).unwrap();
    assert!(
        codes
            .iter()
            .zip(&whole.pixels)
            .all(|(c, p)| *c == p.codes.map(|v| v as u16))
    );
    assert_eq!(summary.mapping_all, whole.summary.mapping_all);
    assert_eq!(summary.mapping_outside, whole.summary.mapping_outside);
    let sampled: Vec<f64> = whole
        .pixels
        .iter()
        .enumerate()
        .filter(|(k, _)| inversion_measured(*k, 2))
        .map(|(_, p)| p.inversion_delta_e00)
        .collect();
    assert_eq!(summary.inversion, ErrorStats::of(&sampled));
    assert!(sampled.len().abs_diff(n / 2) < 10, "{}", sampled.len());
    // A 2048² image, one pixel in 64: every column is sampled, each about as often.
    let mut per_column = vec![0usize; 2048];
    for k in (0..2048 * 2048).filter(|&k| inversion_measured(k, 64)) {
        per_column[k % 2048] += 1;
    }
    let (least, most) = (
        per_column.iter().min().unwrap(),
        per_column.iter().max().unwrap(),
    );
    assert!(*least >= 24 && *most <= 40, "{least} to {most} a column");
}

/// An image written as a PNG keeps only its codes and ΔE00 (`render_codes`): the
/// same codes and summary as the whole rendering, for every mapping and both code
/// choices; and a 2048 × 2048 PFM renders in under 400 MB (1.83 GB when every
/// pixel's gamut, target, scene copy and whole rendered pixel were kept).
#[test]
fn an_image_renders_to_the_same_codes_in_a_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    common::calibrate_default(&state);
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    let crf = ColourReproduction::new(&profile.model).unwrap();
    // Colours in and out of the gamut, over the screen.
    let pixels: Vec<ScenePixel> = (0..400)
        .map(|k| {
            let f = |m: usize| ((k * m) % 97) as f64 / 96.0;
            ScenePixel {
                xyz: Xyz::new(150.0 * f(7), 0.5 + 140.0 * f(13), 170.0 * f(31)),
                position: chromacal_model::ScreenPosition::new(f(3), f(5)),
            }
        })
        .collect();
    let scene = Scene {
        pixels,
        white: None,
    };
    for gamut in [
        GamutMapping::Clip,
        GamutMapping::Hpminde,
        GamutMapping::Sgck(SgckSource::Rec2020),
    ] {
        for codes in [CodeChoice::Rounded, CodeChoice::NearestInDeltaE00] {
            let settings = RenderSettings {
                adaptation: None,
                tone: ToneOperator::Colorimetric,
                gamut,
                bits: 10,
                codes,
            };
            let whole = crf.render(&scene, &settings).unwrap();
            let (lean, summary) = crf.render_codes(&scene, &settings).unwrap();
            let whole_codes: Vec<[u16; 3]> = whole
                .pixels
                .iter()
                .map(|p| p.codes.map(|c| c as u16))
                .collect();
            assert_eq!(lean, whole_codes, "{gamut:?} {codes:?}");
            assert_eq!(summary, whole.summary, "{gamut:?} {codes:?}");
        }
    }
    // 2048 × 2048, peak memory from GNU time.
    let image = dir.path().join("scene.pfm");
    let (w, h) = (2048usize, 2048usize);
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for k in 0..w * h {
        let v = (k % 251) as f32;
        for c in [0.4 * v, 0.42 * v + 1.0, 0.5 * v] {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(&image, bytes).unwrap();
    let out = std::process::Command::new("/usr/bin/time")
        .args(["-f", "peak-kb %M"])
        .arg(env!("CARGO_BIN_EXE_chromacal"))
        .arg("render")
        .arg(state.join("current.toml"))
        .arg("--image")
        .arg(&image)
        .args(["--bits", "16", "-o"])
        .arg(dir.path().join("scene.png"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let peak_kb: u64 = stderr
        .lines()
        .find_map(|l| l.strip_prefix("peak-kb "))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no peak in {stderr}"));
    eprintln!("2048² PFM to a 16-bit PNG: peak {} MB", peak_kb / 1000);
    assert!(peak_kb < 400_000, "{peak_kb} kB");
    // The summary says what its inversion ΔE00 is over.
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("pixels spread over the image (one in 64)"),
        "{said}"
    );
}
