//! Link faults for the emulators, drawn from a seed: a reply that never comes, comes
//! too late, comes with garbage in front, stops short, or the device vanishing in the
//! middle of a reply. Device faults (low light, overload, sync failure) are the
//! [`super::Meter`]'s.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{DeviceFaults, Scheduled};

/// How often each fault happens, per reply (link faults) or per measurement (device
/// faults), and the seed they are drawn from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultSpec {
    pub no_reply: f64,
    pub late: f64,
    pub garbage: f64,
    pub truncated: f64,
    pub vanish: f64,
    pub low_light: f64,
    pub overload: f64,
    pub sync_failure: f64,
    /// A reading whose value is 10⁹ times the light (units lost on the way): more
    /// than any display emits, even at its black.
    pub misread: f64,
    /// How much later than due a late reply comes, in device seconds: past the short
    /// timeouts of settings and queries, inside the drivers' drain window.
    pub late_s: f64,
    /// Link faults start after this many replies (so a session can connect first).
    pub start_after: u64,
    pub seed: u64,
}

impl Default for FaultSpec {
    fn default() -> Self {
        FaultSpec {
            no_reply: 0.0,
            late: 0.0,
            garbage: 0.0,
            truncated: 0.0,
            vanish: 0.0,
            low_light: 0.0,
            overload: 0.0,
            sync_failure: 0.0,
            misread: 0.0,
            late_s: 4.0,
            start_after: 0,
            seed: 1,
        }
    }
}

/// Longest extra delay of a late reply: an hour is far past any driver's timeout.
const MAX_LATE_S: f64 = 3600.0;
/// Largest count (`start_after`, `seed`): 2^53, beyond which an f64 skips integers.
const MAX_COUNT: f64 = 9_007_199_254_740_992.0;

impl FaultSpec {
    /// From `name=value,…`, e.g. `no_reply=0.05,garbage=0.02,seed=7`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut spec = FaultSpec::default();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (name, value) = part
                .split_once('=')
                .ok_or_else(|| format!("'{part}' is not name=value"))?;
            let number: f64 = value
                .trim()
                .parse()
                .map_err(|_| format!("'{value}' in '{part}' is not a number"))?;
            let slot = match name.trim() {
                "no_reply" => &mut spec.no_reply,
                "late" => &mut spec.late,
                "garbage" => &mut spec.garbage,
                "truncated" => &mut spec.truncated,
                "vanish" => &mut spec.vanish,
                "low_light" => &mut spec.low_light,
                "overload" => &mut spec.overload,
                "sync_failure" => &mut spec.sync_failure,
                "misread" => &mut spec.misread,
                "late_s" => &mut spec.late_s,
                "start_after" | "seed" => {
                    // Counts: whole, not negative, and small enough to be exact.
                    if !(number >= 0.0 && number.fract() == 0.0 && number <= MAX_COUNT) {
                        return Err(format!(
                            "{name} must be a whole number from 0 to {MAX_COUNT}, not {value}"
                        ));
                    }
                    if name.trim() == "seed" {
                        spec.seed = number as u64;
                    } else {
                        spec.start_after = number as u64;
                    }
                    continue;
                }
                other => {
                    return Err(format!(
                        "unknown fault '{other}' (known: no_reply, late, garbage, truncated, vanish, low_light, overload, sync_failure, misread, late_s, start_after, seed)"
                    ));
                }
            };
            if name.trim() == "late_s" {
                if !(0.0..=MAX_LATE_S).contains(&number) {
                    return Err(format!(
                        "late_s must be from 0 to {MAX_LATE_S} s, not {value}"
                    ));
                }
            } else if !(0.0..=1.0).contains(&number) {
                return Err(format!(
                    "the rate of {name} must be in [0, 1], not {number}"
                ));
            }
            *slot = number;
        }
        Ok(spec)
    }

    pub fn device(&self) -> DeviceFaults {
        DeviceFaults {
            low_light: self.low_light,
            overload: self.overload,
            sync_failure: self.sync_failure,
            misread: self.misread,
        }
    }
}

/// What the link does with a reply.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkAction {
    Send(Scheduled),
    /// Send `partial` after `delay`, then disappear.
    Vanish {
        delay: f64,
        partial: Vec<u8>,
    },
}

/// Applies link faults to replies.
pub struct FaultInjector {
    spec: FaultSpec,
    rng: ChaCha8Rng,
    replies: u64,
}

impl FaultInjector {
    pub fn new(spec: FaultSpec) -> Self {
        FaultInjector {
            spec,
            rng: ChaCha8Rng::seed_from_u64(spec.seed),
            replies: 0,
        }
    }

    pub fn spec(&self) -> &FaultSpec {
        &self.spec
    }

    /// The reply as the link delivers it.
    pub fn apply(&mut self, reply: Scheduled) -> Vec<LinkAction> {
        let s = self.spec;
        self.replies += 1;
        if self.replies <= s.start_after {
            return vec![LinkAction::Send(reply)];
        }
        let draw: f64 = self.rng.random();
        let mut edge = 0.0;
        let mut hit = |rate: f64| {
            let inside = draw >= edge && draw < edge + rate;
            edge += rate;
            inside
        };
        if hit(s.no_reply) {
            return Vec::new();
        }
        if hit(s.late) {
            return vec![LinkAction::Send(Scheduled::after(
                reply.delay + s.late_s,
                reply.bytes,
            ))];
        }
        if hit(s.garbage) {
            let n = self.rng.random_range(1..24);
            let mut bytes: Vec<u8> = (0..n).map(|_| self.rng.random()).collect();
            bytes.extend_from_slice(&reply.bytes);
            return vec![LinkAction::Send(Scheduled::after(reply.delay, bytes))];
        }
        if hit(s.truncated) && reply.bytes.len() > 1 {
            let keep = self.rng.random_range(1..reply.bytes.len());
            return vec![LinkAction::Send(Scheduled::after(
                reply.delay,
                reply.bytes[..keep].to_vec(),
            ))];
        }
        if hit(s.vanish) {
            let keep = self.rng.random_range(0..reply.bytes.len().max(1));
            return vec![LinkAction::Vanish {
                delay: reply.delay,
                partial: reply.bytes[..keep.min(reply.bytes.len())].to_vec(),
            }];
        }
        vec![LinkAction::Send(reply)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses_with_reasons() {
        let s = FaultSpec::parse("no_reply=0.1, garbage=0.05,seed=9").unwrap();
        assert_eq!((s.no_reply, s.garbage, s.seed), (0.1, 0.05, 9));
        assert!(
            FaultSpec::parse("noreply=0.1")
                .unwrap_err()
                .contains("unknown fault")
        );
        assert!(FaultSpec::parse("late=2").unwrap_err().contains("[0, 1]"));
        assert!(FaultSpec::parse("late").unwrap_err().contains("name=value"));
        // Times and counts out of range are refused, not handed to a thread to panic on.
        for bad in [
            "late_s=1e308",
            "late_s=-1",
            "late_s=nan",
            "start_after=-3",
            "seed=1.5",
            "seed=1e300",
        ] {
            let why = FaultSpec::parse(bad).unwrap_err();
            assert!(why.contains("must be"), "{bad}: {why}");
        }
        assert_eq!(FaultSpec::parse("late_s=2.5").unwrap().late_s, 2.5);
    }

    #[test]
    fn faults_happen_at_their_rates_and_repeat_with_the_seed() {
        let spec = FaultSpec {
            no_reply: 0.2,
            truncated: 0.2,
            ..FaultSpec::default()
        };
        let run = || {
            let mut f = FaultInjector::new(spec);
            (0..1000)
                .map(|_| f.apply(Scheduled::now(b"00000,0\r\n".to_vec())))
                .collect::<Vec<_>>()
        };
        let a = run();
        assert_eq!(a, run());
        let dropped = a.iter().filter(|x| x.is_empty()).count();
        let cut = a
            .iter()
            .filter(|x| matches!(x.first(), Some(LinkAction::Send(s)) if s.bytes.len() < 9))
            .count();
        assert!((150..250).contains(&dropped), "{dropped}");
        assert!((150..250).contains(&cut), "{cut}");
    }
}
