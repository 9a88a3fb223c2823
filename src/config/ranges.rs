//! The range of every numeric key of the configuration, checked when a config is
//! loaded.
//!
//! One table, not a check per struct, so that a key added later without a range is
//! caught: `check_ranges` refuses any number whose key the table does not name, and a
//! test walks a config with every section filled in. A value outside its range (NaN
//! included) is refused with the key, the value and the range, before anything is
//! measured: a budget of 2^63 patches, an integration time of NaN or a uniformity grid
//! of 1000 × 1000 once panicked, wrote unreadable journals or ran for ever.
//!
//! Checks between keys (black below white, the longest integration not below the
//! first) are in `check_config`.

use super::Config;

/// A key's allowed values, both ends included.
#[derive(Debug, Clone, Copy)]
pub struct Range {
    /// Dotted path; `[]` stands for every element of an array.
    pub key: &'static str,
    pub min: f64,
    pub max: f64,
}

const fn r(key: &'static str, min: f64, max: f64) -> Range {
    Range { key, min, max }
}

/// Seeds are any whole number TOML can write.
const SEED_MAX: f64 = i64::MAX as f64;

/// Every numeric key, with its range. The README's configuration section and
/// `config/default.toml` repeat these.
pub const RANGES: &[Range] = &[
    // [monitor]: the virtual monitor.
    r("monitor.white_luminance", 0.01, 100_000.0),
    r("monitor.black_luminance", 0.0, 10_000.0),
    r("monitor.flare_luminance", 0.0, 10_000.0),
    r("monitor.bit_depth", 1.0, 16.0),
    r("monitor.falloff", 0.0, 1.0),
    r("monitor.falloff[]", 0.0, 1.0),
    r("monitor.failures.primary_nonconstancy", 0.0, 1.0),
    r("monitor.failures.channel_interaction", -1.0, 1.0),
    r("monitor.failures.channel_crosstalk", -1.0, 1.0),
    r("monitor.failures.surround_dependence", -1.0, 1.0),
    r("monitor.failures.warmup_amplitude", -1.0, 1.0),
    r("monitor.failures.warmup_time_constant_s", 0.0, 1e6),
    r("monitor.failures.drift_per_hour", -1.0, 1.0),
    r("monitor.failures.response_time_s", 0.0, 60.0),
    // [instrument]
    r("instrument.simulated.gain_noise", 0.0, 1.0),
    r("instrument.simulated.relative_noise", 0.0, 1.0),
    r("instrument.simulated.noise_floor", 0.0, 1000.0),
    r("instrument.simulated.low_light_limit", 0.0, 1000.0),
    r("instrument.simulated.overload_limit", 0.001, 1e7),
    r("instrument.simulated.integration_s", 1e-4, 3600.0),
    r("instrument.simulated.max_integration_s", 1e-4, 3600.0),
    r("instrument.simulated.seed", 0.0, SEED_MAX),
    r("instrument.options.timing_scale", 1e-6, 1000.0),
    r("instrument.options.attempts", 1.0, 100.0),
    r("instrument.options.argyll_timeout_s", 1.0, 3600.0),
    r("instrument.options.averaging", 1.0, 2.0),
    r("instrument.options.reconnects", 0.0, 100.0),
    r("instrument.correction[][]", -1000.0, 1000.0),
    // [display]
    r("display.settle_s", 0.0, 600.0),
    r("display.lut_check_s", 1.0, 86_400.0),
    r("display.stability.tolerance", 0.0, 1.0),
    r("display.stability.floor", 0.0, 10_000.0),
    r("display.stability.max_reads", 2.0, 100.0),
    r("display.resolve.connect_timeout_s", 0.1, 86_400.0),
    r("display.web.ack_timeout_s", 0.1, 3600.0),
    r("display.web.connect_timeout_s", 0.1, 86_400.0),
    // [plan]
    r("plan.budget", 0.0, 20_000.0),
    r("plan.verification", 0.0, 10_000.0),
    r("plan.uniformity_grid", 0.0, 40.0),
    r("plan.bit_depth", 1.0, 16.0),
    r("plan.patch_size", 0.001, 1.0),
    r("plan.seed", 0.0, SEED_MAX),
    r("plan.seed_budget", 0.0, 20_000.0),
    r("plan.target_de00", 0.0, 100.0),
    // [fit]
    r("fit.max_condition_number", 1.0, 1e12),
    r("fit.primaries_xy[][]", 0.0, 1.0),
    r("fit.white_xy[]", 0.0, 1.0),
    // [publish]
    r("publish.max_mean_de00", 1e-6, 1000.0),
    r("publish.max_p95_de00", 1e-6, 1000.0),
    r("publish.max_mean_itp", 1e-6, 1000.0),
    // [daemon]
    r("daemon.stop_timeout_s", 0.0, 3600.0),
    r("daemon.simulated_time_scale", 1e-6, 1000.0),
    r("daemon.keep_profiles", 2.0, 10_000.0),
    r("daemon.max_body_bytes", 64.0, 16_777_216.0),
    r("daemon.requests_per_s", 0.01, 1e6),
    r("daemon.burst", 1.0, 1e6),
    r("daemon.max_event_streams", 1.0, 1024.0),
    r("daemon.max_connections", 1.0, 10_000.0),
    r("daemon.max_local_connections", 1.0, 10_000.0),
    r("daemon.header_timeout_s", 0.1, 86_400.0),
    r("daemon.idle_timeout_s", 0.1, 86_400.0),
    r("daemon.request_timeout_s", 0.1, 86_400.0),
    // [mqtt]
    r("mqtt.queue", 1.0, 1e6),
    r("mqtt.keep_alive_s", 1.0, 3600.0),
    // [schedule]
    r("schedule.verify_every_s", 0.01, 1e8),
    r("schedule.verify_patches", 5.0, 1000.0),
    r("schedule.threshold_de00", 1e-6, 1000.0),
    r("schedule.threshold_itp", 1e-6, 1000.0),
    // [warmup]
    r("warmup.interval_s", 0.1, 3600.0),
    r("warmup.window", 3.0, 1000.0),
    r("warmup.max_slope_per_min", 1e-9, 1.0),
    r("warmup.max_s", 0.0, 86_400.0),
    // [target]
    r("target.luminance", 0.01, 100_000.0),
    r("target.peak", 0.01, 100_000.0),
    r("target.mastering_peak", 100.0, 10_000.0),
    r("target.refine_passes", 0.0, 5.0),
    r("target.levels", 3.0, 33.0),
    r("target.bit_depth", 8.0, 16.0),
    // [verify]: limits of one's own (ΔE, percent for the tone).
    r("verify.criterion[].limit", 1e-6, 1000.0),
];

/// Keys whose numbers are checked by their own type, not by a range: the virtual
/// monitor's transfer laws (each law checks its parameters: finite, monotone) and its
/// HDR behaviour (`HdrBehaviour::check`, against the monitor's peak).
///
/// A `[[device]]` entry and an `[instruments.NAME]` are checked as parts of each
/// device's own config (`devices::device_configs`), where every key has its place.
const CHECKED_ELSEWHERE: &[&str] = &["monitor.laws", "monitor.hdr", "device[]", "instruments."];

/// Refuse any number of `config` outside its key's range, or whose key has none.
pub fn check_ranges(config: &Config) -> Result<(), String> {
    let value = toml::Value::try_from(config)
        .map_err(|e| format!("the config cannot be written back as TOML: {e}"))?;
    let mut numbers = Vec::new();
    collect_numbers(&value, "", &mut numbers);
    for (key, number) in numbers {
        if CHECKED_ELSEWHERE.iter().any(|k| key.starts_with(k)) {
            continue;
        }
        let range = RANGES.iter().find(|r| r.key == key).ok_or_else(|| {
            format!("{key} has no documented range (a bug: add it to config/ranges.rs)")
        })?;
        if !(number >= range.min && number <= range.max) {
            let shown = key.replace("[]", "");
            return Err(format!(
                "{shown} = {number} is out of range: it must be from {} to {}",
                range.min, range.max
            ));
        }
    }
    Ok(())
}

/// Every number under `value`, with its dotted key (`[]` for array elements).
fn collect_numbers(value: &toml::Value, key: &str, out: &mut Vec<(String, f64)>) {
    match value {
        toml::Value::Integer(i) => out.push((key.to_string(), *i as f64)),
        toml::Value::Float(f) => out.push((key.to_string(), *f)),
        toml::Value::Array(items) => {
            for item in items {
                collect_numbers(item, &format!("{key}[]"), out);
            }
        }
        toml::Value::Table(table) => {
            for (name, item) in table {
                let key = if key.is_empty() {
                    name.clone()
                } else {
                    format!("{key}.{name}")
                };
                collect_numbers(item, &key, out);
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `config/default.toml` with every commented-out section and key switched on,
    /// and the optional keys it does not show: a config with every number there is.
    fn every_key() -> Config {
        let text: String = include_str!("../../config/default.toml")
            .lines()
            .map(|line| match line.strip_prefix("# ") {
                Some(rest)
                    if rest.starts_with('[')
                        || rest.split_once(" =").is_some_and(|(k, _)| {
                            !k.is_empty() && k.chars().all(|c| c.is_ascii_lowercase() || c == '_')
                        }) =>
                {
                    rest.to_string()
                }
                _ => line.to_string(),
            })
            .collect::<Vec<_>>()
            .join("\n");
        let mut config: Config = toml::from_str(&text).unwrap();
        config.monitor.white_luminance = Some(100.0);
        config.monitor.black_luminance = Some(0.1);
        config.monitor.flare_luminance = Some(0.0);
        config.monitor.bit_depth = Some(8);
        config.monitor.falloff = Some(chromacal_sim::presets::FalloffConfig::PerChannel([0.9; 3]));
        config.fit.primaries_xy = Some([[0.64, 0.33], [0.3, 0.6], [0.15, 0.06]]);
        config.fit.white_xy = Some([0.3127, 0.329]);
        config.instrument.correction = Some(crate::config::Correction::Matrix([
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]));
        config
    }

    #[test]
    fn every_numeric_key_has_a_range_and_the_defaults_are_in_it() {
        let config = every_key();
        let value = toml::Value::try_from(&config).unwrap();
        let mut numbers = Vec::new();
        collect_numbers(&value, "", &mut numbers);
        assert!(numbers.len() > 60, "{} numbers: {numbers:?}", numbers.len());
        check_ranges(&config).unwrap();
        // And the table names no key that does not exist.
        for range in RANGES {
            assert!(
                numbers.iter().any(|(k, _)| k == range.key) || range.key == "monitor.falloff",
                "{} is in the table but in no config",
                range.key
            );
        }
    }

    #[test]
    fn out_of_range_and_nan_values_are_refused_with_key_and_range() {
        let mut config = every_key();
        config.plan.budget = i64::MAX as usize;
        let e = check_ranges(&config).unwrap_err();
        assert!(e.contains("plan.budget") && e.contains("0 to 20000"), "{e}");
        let mut config = every_key();
        config.instrument.simulated.as_mut().unwrap().integration_s = f64::NAN;
        let e = check_ranges(&config).unwrap_err();
        assert!(
            e.contains("instrument.simulated.integration_s = NaN"),
            "{e}"
        );
        let mut config = every_key();
        config.fit.max_condition_number = 0.0;
        assert!(
            check_ranges(&config)
                .unwrap_err()
                .contains("fit.max_condition_number")
        );
        let mut config = every_key();
        config.fit.primaries_xy = Some([[0.64, 0.33], [0.3, 1.6], [0.15, 0.06]]);
        let e = check_ranges(&config).unwrap_err();
        assert!(e.contains("fit.primaries_xy = 1.6"), "{e}");
    }
}
