//! Time in arcnav: every timestamp is a `utime`, signed microseconds (the LCM
//! convention). Nodes never read a clock; time always arrives as an argument.

/// A timestamp or a duration in microseconds.
pub type Utime = i64;

/// Microseconds in one second.
pub const MICROS_PER_SECOND: i64 = 1_000_000;

/// Seconds → microseconds, rounded to the nearest microsecond.
///
/// Values outside the `i64` range saturate, NaN maps to 0 (Rust's `as` rules);
/// configuration validation keeps such values from reaching here.
pub fn seconds_to_micros(seconds: f64) -> Utime {
    (seconds * MICROS_PER_SECOND as f64).round() as Utime
}

/// Microseconds → seconds.
pub fn micros_to_seconds(micros: Utime) -> f64 {
    micros as f64 / MICROS_PER_SECOND as f64
}

#[cfg(test)]
mod tests {
    use super::*;

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
