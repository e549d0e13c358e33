//! `[arbiter.recovery]`: the recovery's keys and their checks.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[arbiter.recovery]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecoveryConfig {
    /// Back up when blocked (false: stop and wait, as 002's vehicle did).
    pub enabled: bool,
    /// Blocked this long with the vehicle standing before backing up, s.
    pub wait_s: f64,
    /// Backing-up speed, m/s.
    pub speed_mps: f64,
    /// Distance backed per recovery, m.
    pub distance_m: f64,
    /// A backward arc must be clear this much further than the distance, m.
    pub margin_m: f64,
    /// Back up only along an arc clear for at least this much (when none is
    /// clear for `distance_m`), m.
    pub min_distance_m: f64,
    /// Recoveries in a row without `progress_m` of forward driving between
    /// them; then the vehicle stops.
    pub max_attempts: u32,
    /// Forward driving that shows a recovery worked, m.
    pub progress_m: f64,
    /// Commands slower than this count as standing (blocked when the arcs'
    /// limits force it), m/s.
    pub creep_mps: f64,
    /// Turn round with a K-point turn when blocked with the way to the side
    /// or behind (false: back up once, as for any block).
    pub turn_round: bool,
    /// Legs (backing and forward) in one turn at most.
    pub turn_max_legs: u32,
    /// The turn ends when the wished-for arc curves less than this fraction
    /// of the hardest arc towards the turn's side.
    pub turn_exit_fraction: f64,
    /// Back out the way the vehicle came when no manoeuvre can start or a
    /// turn round found no leg clear.
    pub retrace: bool,
    /// The vehicle's own motions are remembered this far back, and one
    /// retrace goes at most this far, m.
    pub retrace_max_m: f64,
    /// Retracing towards a turn ends where an arc curving towards the way
    /// is clear this far ahead, m.
    pub retrace_room_m: f64,
    /// A turn round that found no leg clear before turning this far was in
    /// a lane too narrow to turn in: the next recovery retraces, degrees.
    pub retrace_below_deg: f64,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            wait_s: 1.5,
            speed_mps: 1.0,
            distance_m: 4.0,
            margin_m: 0.5,
            min_distance_m: 1.0,
            max_attempts: 8,
            progress_m: 8.0,
            creep_mps: 0.1,
            turn_round: true,
            turn_max_legs: 12,
            turn_exit_fraction: 0.5,
            retrace: true,
            retrace_max_m: 50.0,
            retrace_room_m: 8.0,
            retrace_below_deg: 45.0,
        }
    }
}

impl RecoveryConfig {
    /// Keys relative to `[arbiter.recovery]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("wait_s", self.wait_s, 0.0, 60.0)?;
        config::in_range("speed_mps", self.speed_mps, 0.05, 5.0)?;
        config::in_range("distance_m", self.distance_m, 0.1, 50.0)?;
        config::in_range("min_distance_m", self.min_distance_m, 0.0, self.distance_m)?;
        config::non_negative("margin_m", self.margin_m)?;
        config::non_negative("progress_m", self.progress_m)?;
        config::in_range("creep_mps", self.creep_mps, 0.0, 1.0)?;
        config::in_range("turn_exit_fraction", self.turn_exit_fraction, 0.0, 1.0)?;
        config::in_range("retrace_max_m", self.retrace_max_m, 0.0, 1000.0)?;
        config::in_range("retrace_room_m", self.retrace_room_m, 0.0, 100.0)?;
        config::in_range("retrace_below_deg", self.retrace_below_deg, 0.0, 360.0)?;
        for (key, value) in [
            ("max_attempts", self.max_attempts),
            ("turn_max_legs", self.turn_max_legs),
        ] {
            if value > 1000 {
                return Err(ConfigError::new(key, format!("is {value}, at most 1000")));
            }
        }
        Ok(())
    }
}
