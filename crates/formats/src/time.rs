//! Where a run takes its time stamps from: the wall clock for real devices, the
//! virtual clock (`sim::clock`) for simulated ones. Drift is measured against these
//! stamps, so both count seconds.

use std::time::{SystemTime, UNIX_EPOCH};

/// A source of time stamps in seconds.
pub trait TimeSource: Send + Sync {
    fn now(&self) -> f64;
}

/// Seconds since the Unix epoch.
#[derive(Debug, Default, Clone, Copy)]
pub struct WallClock;

impl TimeSource for WallClock {
    fn now(&self) -> f64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0)
    }
}

/// `t` as an RFC 3339 time stamp in UTC to the second (`2026-12-04T05:22:31Z`), the form
/// of every stored time stamp (profiles, journals, history). Truncated, not rounded, so
/// a stamp never lies in the future of its event.
pub fn rfc3339_seconds(t: SystemTime) -> String {
    jiff::Timestamp::try_from(t)
        .map(|ts| ts.strftime("%Y-%m-%dT%H:%M:%SZ").to_string())
        .unwrap_or_else(|_| "1970-01-01T00:00:00Z".into())
}

/// The wall clock now, as [`rfc3339_seconds`].
pub fn now_rfc3339() -> String {
    rfc3339_seconds(SystemTime::now())
}

/// The wall clock now to the millisecond (`2026-12-04T05:22:31.123Z`), for events.
pub fn now_rfc3339_millis() -> String {
    jiff::Timestamp::now()
        .strftime("%Y-%m-%dT%H:%M:%S%.3fZ")
        .to_string()
}

/// An RFC 3339 time stamp read back: with an offset (`Z`, `+01:00`), or without one as
/// UTC (as older files wrote them); `None` if it is not one.
pub fn parse_rfc3339(text: &str) -> Option<SystemTime> {
    let text = text.trim();
    let timestamp = text.parse::<jiff::Timestamp>().ok().or_else(|| {
        text.parse::<jiff::civil::DateTime>()
            .ok()?
            .to_zoned(jiff::tz::TimeZone::UTC)
            .ok()
            .map(|z| z.timestamp())
    })?;
    Some(SystemTime::from(timestamp))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn time_stamps_are_utc_to_the_second_and_read_back() {
        let t = UNIX_EPOCH + Duration::from_millis(1_796_361_751_987);
        assert_eq!(rfc3339_seconds(t), "2026-12-04T05:22:31Z");
        assert_eq!(
            parse_rfc3339("2026-12-04T05:22:31Z"),
            Some(UNIX_EPOCH + Duration::from_secs(1_796_361_751))
        );
        // An offset is honoured; no offset is UTC.
        assert_eq!(
            parse_rfc3339("2026-12-04T06:22:31+01:00"),
            parse_rfc3339("2026-12-04T05:22:31")
        );
        assert_eq!(parse_rfc3339("yesterday"), None);
        assert!(now_rfc3339_millis().ends_with('Z'));
        assert_eq!(now_rfc3339_millis().len(), "2026-12-04T05:22:31.123Z".len());
    }
}
