//! Time in arcnav: every timestamp is a `utime`, signed microseconds (the LCM
//! convention). Nodes never read a clock; time always arrives as an argument.

/// A timestamp or a duration in microseconds.
pub type Utime = i64;

/// Microseconds in one second.
pub const MICROS_PER_SECOND: i64 = 1_000_000;

/// The latest time an input may carry: 2⁵³ µs, in the year 2255 on the
/// Unix epoch's clock (and far past any since-boot clock), the largest
/// time a double still holds to the microsecond. Inputs carry times on
/// one of those two clocks, never before 0.
pub const MAX_UTIME: Utime = 1 << 53;

/// A time off the wire or out of a log that no clock gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "time {0} µs is not on a vehicle's clock (0 to 2^53 µs: Unix-epoch or since-boot microseconds)"
)]
pub struct ImplausibleTime(pub Utime);

/// `t`, when it is a time some clock gives (0 to [`MAX_UTIME`]): times
/// that come off the wire or out of a log are checked with this before any
/// clock joins them, so that differences of two times never overflow and
/// a clock never restarts at the far end of the range.
pub fn plausible(t: Utime) -> Result<Utime, ImplausibleTime> {
    if (0..=MAX_UTIME).contains(&t) {
        Ok(t)
    } else {
        Err(ImplausibleTime(t))
    }
}

/// Seconds → microseconds, rounded to the nearest microsecond.
///
/// Values outside the `i64` range saturate, NaN maps to 0 (Rust's `as` rules);
/// configuration validation keeps such values from reaching here.
pub fn seconds_to_micros(seconds: f64) -> Utime {
    (seconds * MICROS_PER_SECOND as f64).round() as Utime
}

/// `later − earlier` in seconds, for any two times: never overflows.
pub fn seconds_between(earlier: Utime, later: Utime) -> f64 {
    (i128::from(later) - i128::from(earlier)) as f64 / MICROS_PER_SECOND as f64
}

/// Microseconds → seconds.
pub fn micros_to_seconds(micros: Utime) -> f64 {
    micros as f64 / MICROS_PER_SECOND as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_times_a_clock_gives_are_plausible() {
        for t in [0, 1_700_000_000_000_000, MAX_UTIME] {
            assert_eq!(plausible(t), Ok(t));
        }
        for t in [-1, i64::MIN, i64::MIN + 1, MAX_UTIME + 1, i64::MAX] {
            assert_eq!(plausible(t), Err(ImplausibleTime(t)));
        }
        // Two plausible times never overflow when subtracted.
        assert_eq!(MAX_UTIME as f64 as i64, MAX_UTIME);
    }

    #[test]
    fn conversions_round_trip() {
        assert_eq!(seconds_to_micros(0.6), 600_000);
        assert_eq!(seconds_to_micros(-1.5), -1_500_000);
        assert_eq!(micros_to_seconds(2_500_000), 2.5);
        assert_eq!(
            seconds_to_micros(micros_to_seconds(1_700_000_000_123_456)),
            1_700_000_000_123_456
        );
    }
}
