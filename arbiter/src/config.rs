//! `[arbiter]`: how votes are fused and turned into a command.

use std::collections::BTreeMap;

use arcnav_vehicle::config::{self, ConfigError};

use crate::recovery::RecoveryConfig;
use serde::{Deserialize, Serialize};

/// Lives in `[arbiter]`; the weights in `[arbiter.weights]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArbiterConfig {
    /// Behaviours that must have voted within the timeout, or the command is stop.
    pub required: Vec<String>,
    /// Votes older than this are ignored, s.
    pub vote_timeout_s: f64,
    /// Weight of a behaviour missing from `weights`.
    pub default_weight: f64,
    /// Standard deviation of the Gaussian smoothing across neighbouring arcs,
    /// in arcs (0 = off). A forbidden arc lowers its neighbours.
    pub smoothing_sigma_arcs: f64,
    /// Fit a parabola through the winning arc and its neighbours and steer at
    /// its peak instead of the arc's own curvature.
    pub interpolate_peak: bool,
    /// If the best fused vote is below this, no arc is acceptable: stop.
    pub min_acceptable_vote: f64,
    /// Speed when no behaviour asks for less, m/s (002 §2: 2-3 m/s).
    pub cruise_speed_mps: f64,
    /// Below this fused vote the speed is lowered in proportion...
    pub slow_below_vote: f64,
    /// ... down to this fraction of it at `min_acceptable_vote`.
    pub min_speed_fraction: f64,
    /// Speed on an arc is limited so that v²·|k| stays below this, m/s².
    pub max_lateral_accel_mps2: f64,
    /// Arcs whose fused vote is within this of the best are near-ties; of
    /// them the arbiter takes the one it may drive fastest (0 = the best
    /// vote always wins).
    pub speed_tie_vote: f64,
    /// Weight of each behaviour in the fused vote; 0 skips a behaviour. A
    /// `[arbiter.weights]` table changes the weights it names; the others
    /// keep their defaults.
    #[serde(deserialize_with = "weights_over_defaults")]
    pub weights: BTreeMap<String, f64>,
    /// Backing up when the way forward is blocked (`[arbiter.recovery]`).
    pub recovery: RecoveryConfig,
}

fn weights_over_defaults<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<BTreeMap<String, f64>, D::Error> {
    let mut weights = ArbiterConfig::default().weights;
    weights.extend(BTreeMap::<String, f64>::deserialize(deserializer)?);
    Ok(weights)
}

impl Default for ArbiterConfig {
    fn default() -> Self {
        Self {
            required: vec!["obstacle_avoidance".into()],
            vote_timeout_s: 1.0,
            default_weight: 1.0,
            smoothing_sigma_arcs: 1.0,
            interpolate_peak: false,
            min_acceptable_vote: -0.5,
            cruise_speed_mps: 2.5,
            slow_below_vote: 0.5,
            min_speed_fraction: 0.3,
            max_lateral_accel_mps2: 1.5,
            speed_tie_vote: 0.0,
            weights: BTreeMap::from([
                ("obstacle_avoidance".into(), 1.0),
                ("route".into(), 0.5),
                ("goal_seeking".into(), 0.0),
            ]),
            recovery: RecoveryConfig::default(),
        }
    }
}

impl ArbiterConfig {
    /// Keys relative to `[arbiter]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::positive("vote_timeout_s", self.vote_timeout_s)?;
        config::non_negative("default_weight", self.default_weight)?;
        config::in_range(
            "smoothing_sigma_arcs",
            self.smoothing_sigma_arcs,
            0.0,
            100.0,
        )?;
        config::in_range("min_acceptable_vote", self.min_acceptable_vote, -1.0, 1.0)?;
        config::positive("cruise_speed_mps", self.cruise_speed_mps)?;
        config::in_range("slow_below_vote", self.slow_below_vote, -1.0, 1.0)?;
        if self.slow_below_vote <= self.min_acceptable_vote {
            return Err(ConfigError::new(
                "slow_below_vote",
                format!(
                    "is {}, must be above min_acceptable_vote ({})",
                    self.slow_below_vote, self.min_acceptable_vote
                ),
            ));
        }
        config::in_range("min_speed_fraction", self.min_speed_fraction, 0.0, 1.0)?;
        config::positive("max_lateral_accel_mps2", self.max_lateral_accel_mps2)?;
        config::in_range("speed_tie_vote", self.speed_tie_vote, 0.0, 0.5)?;
        for (name, weight) in &self.weights {
            config::non_negative(&format!("weights.{name}"), *weight)?;
        }
        self.recovery.validate().map_err(|e| e.within("recovery"))?;
        Ok(())
    }

    /// The weight of `behaviour`.
    pub fn weight(&self, behaviour: &str) -> f64 {
        self.weights
            .get(behaviour)
            .copied()
            .unwrap_or(self.default_weight)
    }
}
