//! `[lookahead]`: whether and how far the distances that look ahead move
//! out with the cruise speed (the derivation is the parent module's).

use arcnav_vehicle::ConfigError;
use arcnav_vehicle::config;
use serde::{Deserialize, Serialize};

/// Lives in `[lookahead]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LookaheadConfig {
    /// Move the distances that look ahead out with the cruise speed.
    pub from_speed: bool,
    /// The map window never reaches farther ahead than this, m.
    pub max_ahead_m: f64,
    /// Hold the cruise speed to the speed from which the vehicle stops
    /// within the range at which the sensor first suspects a hole the
    /// wheels do not bridge (`speed_bound.suspect_bound_mps`).
    pub hole_speed_cap: bool,
}

impl Default for LookaheadConfig {
    fn default() -> Self {
        Self {
            // On: nothing moves below 5.9 m/s, and above 3 m/s arcs are
            // judged along driven paths (`[arcs] driven_paths = "auto"`),
            // without which a ditch seen 5-9 m ahead was driven into at
            // 10 m/s (see `config/default.toml`).
            from_speed: true,
            max_ahead_m: 60.0,
            // Off: the speed governor (obstacle avoidance's unseen ground,
            // with the hole evidence's verified ground) slows where a hole
            // may hide, and only there (issue 63; docs/tuning.md).
            hole_speed_cap: false,
        }
    }
}

impl LookaheadConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("max_ahead_m", self.max_ahead_m, 5.0, 200.0)
    }
}
