//! What ArgyllCMS `spotread` prints, read as events: the port list of its usage text,
//! the prompts of its reading loop, its results and spectra, and its failures.
//!
//! The texts are those of `spotread.c` in ArgyllCMS 2.3.1 (the version tested): its
//! loop prints a menu ending in "any other key to take a reading: ", then, after a key,
//! either " Result is XYZ: X Y Z, D50 Lab: …" (with `-s` first "Spectrum from A to B nm
//! in N steps" and a line of values) or one of its failures ("Spot read failed due to
//! misread (…)", "… communication problem.", "… because instruments needs
//! calibration.", "Got fatal error '…' (…)"), most of them followed by "Hit Esc or Q to
//! give up, any other key to retry:". Nothing here talks to a process; the driver
//! (`driver.rs`) feeds the text in and acts on the events.

use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

/// The prompt that ends the reading loop's menu: spotread waits for a key.
pub const READY_PROMPT: &str = "any other key to take a reading:";
/// The prompt after a failed or stopped reading.
pub const RETRY_PROMPT: &str = "any other key to retry:";
/// The prompts of Argyll's calibration handler (`inst_handle_calibrate`).
pub const CALIBRATION_PROMPTS: [&str; 2] = [
    "and then hit any key to continue,",
    "any other key to continue",
];

/// One instrument port as `spotread -?` lists it under `-c listno`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArgyllPort {
    /// The number `-c` takes (from 1).
    pub number: u32,
    /// The device path or USB location, e.g. `/dev/ttyUSB0` or `/dev/bus/usb/001/004`.
    pub path: String,
    /// The instrument Argyll identified there, e.g. `Klein K-10` or
    /// `X-Rite i1 DisplayPro, ColorMunki Display` (none on a port it could not identify).
    pub instrument: Option<String>,
}

/// The port list of `spotread -?`: the lines `    N = 'PATH (INSTRUMENT)'` that follow
/// "-c listno". Lines of diagnostics Argyll interleaves (its port scan reports
/// failures on stderr) are skipped.
pub fn parse_port_list(usage: &str) -> Vec<ArgyllPort> {
    let mut ports = Vec::new();
    let mut in_list = false;
    for line in usage.lines() {
        let trimmed = line.trim();
        if trimmed.starts_with("-c ") {
            in_list = true;
            continue;
        }
        if !in_list {
            continue;
        }
        if trimmed.starts_with('-') {
            break;
        }
        let Some((number, rest)) = trimmed.split_once(" = ") else {
            continue;
        };
        let Ok(number) = number.trim().parse::<u32>() else {
            continue;
        };
        let quoted = rest.trim().trim_matches('\'');
        let (path, instrument) = match quoted.split_once(" (") {
            Some((path, name)) if name.ends_with(')') => (
                path.to_string(),
                Some(name[..name.len() - 1].trim().to_string()),
            ),
            _ => (quoted.to_string(), None),
        };
        ports.push(ArgyllPort {
            number,
            path,
            instrument,
        });
    }
    ports
}

/// Whether an instrument Argyll names is a spectrometer (it gives spectra with `-s`):
/// ArgyllCMS's spectral families. Everything else it drives is a colorimeter.
pub fn is_spectral(instrument: &str) -> bool {
    const SPECTRAL: [&str; 12] = [
        "i1 pro",
        "i1pro",
        "colormunki",
        "specbos",
        "spectraval",
        "spectrolino",
        "spectroscan",
        "dtp20",
        "dtp22",
        "dtp41",
        "dtp51",
        "ex1",
    ];
    let name = instrument.to_ascii_lowercase();
    // The ColorMunki Display is a colorimeter (Argyll names it with the i1 Display Pro).
    if name.contains("colormunki display") || name.contains("i1 displaypro") {
        return false;
    }
    SPECTRAL.iter().any(|s| name.contains(s))
}

/// What one stretch of spotread's output amounts to.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The menu's prompt: spotread waits for a key to take a reading.
    Ready,
    /// A reading: XYZ in cd/m² and, with `-s`, its spectrum.
    Result {
        xyz: Xyz,
        spectrum: Option<Spectrum>,
    },
    /// The reading failed (Argyll's "misread"); its reason as Argyll gives it. The
    /// retry prompt follows.
    Misread(String),
    /// The instrument stopped answering ("communication problem"); the retry prompt
    /// follows.
    CommunicationFailed,
    /// The instrument wants a calibration (a dark or white reference, a cap on or off);
    /// Argyll's instructions to the user. Its calibration prompt follows.
    NeedsCalibration(String),
    /// The sensor is set wrong (a dial in the wrong position); Argyll's reason.
    WrongPosition(String),
    /// A fatal error: spotread ends. Its message.
    Fatal(String),
    /// spotread could not start the instrument ("Failed to initialise
    /// communications"), or refused its arguments (a "Diagnostic:" with the usage).
    StartFailed(String),
    /// The prompt after a failed reading.
    RetryPrompt,
    /// Something Argyll says that asks nothing (a calibration it did by itself).
    Notice(String),
}

/// Whether a misread reason means too much light (the reading is an overload, not an
/// error): the wordings Argyll's drivers use for saturation.
pub fn is_saturation(reason: &str) -> bool {
    let r = reason.to_ascii_lowercase();
    [
        "satur",
        "too bright",
        "too much light",
        "overexpos",
        "over range",
    ]
    .iter()
    .any(|w| r.contains(w))
}

/// The first complete event at the start of `text` (spotread's output since the last
/// event), and how many bytes of `text` it used; `None` while the text does not yet
/// hold a complete event. Text that cannot be one of spotread's answers comes back as
/// an error naming it.
pub fn next_event(text: &str) -> Result<Option<(Event, usize)>, String> {
    // The earliest marker in the text decides which event comes first.
    const MARKERS: [&str; 12] = [
        "Failed to initialise communications with instrument",
        "Diagnostic: ",
        "Got fatal error ",
        "Spot read failed due to misread",
        "Spot read failed due to communication problem",
        "Spot read failed due to the sensor being in the wrong position",
        "Spot read failed because instruments needs calibration",
        "Spot read needs a calibration before continuing",
        "Spectrum from ",
        " Result is XYZ:",
        RETRY_PROMPT,
        READY_PROMPT,
    ];
    let Some((at, marker)) = MARKERS
        .iter()
        .filter_map(|m| text.find(m).map(|i| (i, *m)))
        .min_by_key(|(i, _)| *i)
    else {
        return Ok(None);
    };
    let line_end = |from: usize| text[from..].find('\n').map(|nl| from + nl);
    let after = at + marker.len();
    Ok(match marker {
        // Argyll adds the reason on the next lines.
        "Failed to initialise communications with instrument" => {
            lines_after(text, at, 2).map(|(msg, end)| (Event::StartFailed(msg), end))
        }
        "Diagnostic: " => line_end(at).map(|nl| {
            (
                Event::StartFailed(text[after..nl].trim().to_string()),
                nl + 1,
            )
        }),
        "Got fatal error " => {
            line_end(at).map(|nl| (Event::Fatal(text[after..nl].trim().to_string()), nl + 1))
        }
        "Spot read failed due to misread" => line_end(at).map(|nl| {
            let reason = text[after..nl]
                .trim()
                .trim_start_matches('(')
                .trim_end_matches(')')
                .to_string();
            (Event::Misread(reason), nl + 1)
        }),
        "Spot read failed due to communication problem" => {
            line_end(at).map(|nl| (Event::CommunicationFailed, nl + 1))
        }
        "Spot read failed due to the sensor being in the wrong position" => {
            lines_after(text, at, 1).map(|(msg, end)| (Event::WrongPosition(msg), end))
        }
        "Spot read failed because instruments needs calibration"
        | "Spot read needs a calibration before continuing" => calibration_request(text, at),
        "Spectrum from " | " Result is XYZ:" => {
            let Some(result_at) = text[at..].find(" Result is XYZ:").map(|i| at + i) else {
                return Ok(None);
            };
            let Some(nl) = line_end(result_at) else {
                return Ok(None);
            };
            let xyz = parse_result(&text[result_at..nl])?;
            let spectrum = if marker == "Spectrum from " {
                Some(parse_spectrum(&text[at..result_at])?)
            } else {
                None
            };
            Some((Event::Result { xyz, spectrum }, nl + 1))
        }
        RETRY_PROMPT => Some((Event::RetryPrompt, after)),
        _ => Some((Event::Ready, after)),
    })
}

/// A calibration request at `at`: everything up to Argyll's calibration prompt is the
/// user's instructions.
fn calibration_request(text: &str, at: usize) -> Option<(Event, usize)> {
    let prompt = CALIBRATION_PROMPTS
        .iter()
        .filter_map(|p| text[at..].find(p).map(|i| (at + i, *p)))
        .min_by_key(|(i, _)| *i);
    // Argyll calibrates by itself when no one need do anything, and goes on to its
    // menu (or a result): then the request was only news.
    let moved_on = [
        READY_PROMPT,
        RETRY_PROMPT,
        " Result is XYZ:",
        "Spectrum from ",
    ]
    .iter()
    .filter_map(|p| text[at..].find(p).map(|i| at + i))
    .min();
    if let Some(next) = moved_on
        && prompt.is_none_or(|(p, _)| next < p)
    {
        let end = text[at..]
            .find('\n')
            .map_or(next, |nl| (at + nl + 1).min(next));
        return Some((Event::Notice(text[at..end].trim().to_string()), end));
    }
    let (prompt_at, prompt) = prompt?;
    let end = prompt_at + prompt.len();
    // The prompt's last line ("or hit Esc or Q to abort: ") belongs to it.
    let end = match text[end..].find(':') {
        Some(colon) if !text[end..end + colon].contains("Result") => end + colon + 1,
        _ => return None,
    };
    let instructions = text[at..end]
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    Some((Event::NeedsCalibration(instructions), end))
}

/// The line at `at` and up to `more` non-empty lines after it, joined, once the text
/// holds them all or spotread's output has plainly moved on; the end offset.
fn lines_after(text: &str, at: usize, more: usize) -> Option<(String, usize)> {
    let rest = &text[at..];
    let mut lines = Vec::new();
    let mut end = 0;
    for line in rest.split_inclusive('\n') {
        if !line.ends_with('\n') {
            break;
        }
        end += line.len();
        let t = line.trim();
        if !t.is_empty() {
            lines.push(t.to_string());
        }
        if lines.len() > more {
            break;
        }
    }
    if lines.is_empty() {
        return None;
    }
    Some((lines.join(" "), at + end))
}

/// " Result is XYZ: X Y Z, D50 Lab: L a b" → XYZ (cd/m² in spotread's emissive mode).
pub fn parse_result(line: &str) -> Result<Xyz, String> {
    let bad = || format!("spotread's result line makes no sense: '{}'", line.trim());
    let after = line.split_once("XYZ:").ok_or_else(bad)?.1;
    let numbers = after.split(',').next().ok_or_else(bad)?;
    let values: Vec<f64> = numbers
        .split_whitespace()
        .map(|v| v.parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match values.as_slice() {
        [x, y, z] if values.iter().all(|v| v.is_finite()) => Ok(Xyz::new(*x, *y, *z)),
        _ => Err(bad()),
    }
}

/// "Spectrum from A to B nm in N steps" and the line of N comma-separated values, in
/// mW·sr⁻¹·m⁻²·nm⁻¹ (ArgyllCMS's emissive unit) → a spectrum in W·sr⁻¹·m⁻²·nm⁻¹.
pub fn parse_spectrum(block: &str) -> Result<Spectrum, String> {
    let mut lines = block.lines().map(str::trim).filter(|l| !l.is_empty());
    let header = lines.next().unwrap_or_default();
    let bad = |why: &str| format!("spotread's spectrum makes no sense ({why}): '{header}'");
    let words: Vec<&str> = header.split_whitespace().collect();
    // Spectrum from 380.000 to 780.000 nm in 401 steps
    let (first, last, count) = match words.as_slice() {
        ["Spectrum", "from", a, "to", b, "nm", "in", n, "steps"] => (
            a.parse::<f64>().map_err(|_| bad("first wavelength"))?,
            b.parse::<f64>().map_err(|_| bad("last wavelength"))?,
            n.parse::<usize>().map_err(|_| bad("count"))?,
        ),
        _ => return Err(bad("header")),
    };
    if count < 2 || !(first < last) {
        return Err(bad("grid"));
    }
    let values: Vec<f64> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(|v| v.trim().parse::<f64>().map(|w| w * 1e-3))
        .collect::<Result<_, _>>()
        .map_err(|_| bad("a value is not a number"))?;
    if values.len() != count {
        return Err(bad(&format!("{} values for {count} steps", values.len())));
    }
    let step = (last - first) / (count - 1) as f64;
    let wavelengths = (0..count).map(|i| first + step * i as f64).collect();
    Spectrum::new(wavelengths, values).map_err(|e| bad(&e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    const USAGE: &str = "usage: spotread [-options] [logfile]\n -v                   Verbose mode\n -c listno            Set instrument port from the following list (default 1)\nicoms_set_ser_port: tcgetattr on '/dev/ttyS0' failed\n    1 = '/dev/ttyUSB0 (JETI specbos)'\n    2 = '/dev/bus/usb/001/004 (X-Rite i1 DisplayPro, ColorMunki Display)'\n    3 = '/dev/ttyS0'\n -t                   Use transmission measurement mode\n";

    #[test]
    fn the_port_list_is_read_past_interleaved_diagnostics() {
        let ports = parse_port_list(USAGE);
        assert_eq!(ports.len(), 3);
        assert_eq!(ports[0].path, "/dev/ttyUSB0");
        assert_eq!(ports[0].instrument.as_deref(), Some("JETI specbos"));
        assert_eq!(
            ports[1].instrument.as_deref(),
            Some("X-Rite i1 DisplayPro, ColorMunki Display")
        );
        assert_eq!(ports[2].instrument, None);
        assert!(is_spectral("JETI specbos"));
        assert!(!is_spectral("X-Rite i1 DisplayPro, ColorMunki Display"));
        assert!(!is_spectral("Klein K-10"));
        assert!(is_spectral("X-Rite i1 Pro 2"));
    }

    #[test]
    fn a_result_with_its_spectrum_is_one_event() {
        let text = "Hit ESC or Q to exit, any other key to take a reading:  \nSpectrum from 380.000 to 382.000 nm in 3 steps\n1.5, 2, 0.5\n \n Result is XYZ: 0.188600 0.210500 0.201800, D50 Lab: 1.901439 -0.580057 -0.531607\n\nPlace instrument";
        // The ready prompt comes first in this stretch, then the result.
        let (event, used) = next_event(text).unwrap().unwrap();
        assert_eq!(event, Event::Ready);
        let text = &text[used..];
        let (event, used) = next_event(text).unwrap().unwrap();
        let Event::Result { xyz, spectrum } = event else {
            unreachable!()
        };
        assert_eq!(xyz, Xyz::new(0.1886, 0.2105, 0.2018));
        let s = spectrum.unwrap();
        assert_eq!(s.wavelengths_nm(), &[380.0, 381.0, 382.0]);
        assert!((s.values()[0] - 1.5e-3).abs() < 1e-12);
        assert!(text[used..].starts_with("\nPlace"));
    }

    #[test]
    fn failures_are_named() {
        let (e, _) = next_event("\n\nSpot read failed due to misread (Too much light)\nHit Esc or Q to give up, any other key to retry:")
            .unwrap()
            .unwrap();
        assert_eq!(e, Event::Misread("Too much light".into()));
        assert!(is_saturation("Too much light"));
        assert!(!is_saturation("Not enough light"));
        let (e, _) = next_event("\nGot fatal error 'Hardware Failure' (No device)\n")
            .unwrap()
            .unwrap();
        assert_eq!(e, Event::Fatal("'Hardware Failure' (No device)".into()));
        let (e, _) =
            next_event("Diagnostic: Failed to locate display type matching 'l'\nusage: spotread")
                .unwrap()
                .unwrap();
        assert_eq!(
            e,
            Event::StartFailed("Failed to locate display type matching 'l'".into())
        );
        let (e, _) = next_event("Failed to initialise communications with instrument\nor wrong instrument or bad configuration!\n('Communication protocol breakdown' + 'No device error')\n")
            .unwrap()
            .unwrap();
        let Event::StartFailed(m) = e else { panic!() };
        assert!(m.contains("Communication protocol breakdown"), "{m}");
        let (e, _) = next_event("\nSpot read needs a calibration before continuing\nPlace the instrument on its reflective white reference XX,\n and then hit any key to continue,\n or hit Esc or Q to abort: ")
            .unwrap()
            .unwrap();
        let Event::NeedsCalibration(m) = e else {
            panic!()
        };
        assert!(m.contains("reflective white reference"), "{m}");
    }

    #[test]
    fn a_calibration_argyll_does_by_itself_is_news_not_a_request() {
        let text = "\nSpot read needs a calibration before continuing\n\nPlace instrument on spot to be measured,\nHit ESC or Q to exit, any other key to take a reading: ";
        let (e, used) = next_event(text).unwrap().unwrap();
        assert!(matches!(e, Event::Notice(_)), "{e:?}");
        assert_eq!(next_event(&text[used..]).unwrap().unwrap().0, Event::Ready);
    }

    #[test]
    fn incomplete_text_waits_and_nonsense_is_refused() {
        assert_eq!(next_event(" Result is XYZ: 0.1 0.2").unwrap(), None);
        assert_eq!(next_event("Spectrum from 380").unwrap(), None);
        assert!(next_event(" Result is XYZ: 0.1 nan-ish 0.3, D50 Lab: 1 2 3\n").is_err());
        assert!(next_event(" Result is XYZ: 0.1 0.2, D50 Lab: 1 2 3\n").is_err());
        assert!(
            next_event(
                "Spectrum from 380.000 to 382.000 nm in 3 steps\n1, 2\n Result is XYZ: 1 1 1, D50\n"
            )
            .is_err()
        );
    }
}
