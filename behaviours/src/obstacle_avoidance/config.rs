//! `[behaviours.obstacle_avoidance]`: the behaviour's keys and their
//! defaults.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

use crate::behaviour::Setup;
use crate::terrain::TerrainConfig;

/// Lives in `[behaviours.obstacle_avoidance]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObstacleAvoidanceConfig {
    /// A collision closer than this along the arc forbids the arc, m.
    pub min_distance_m: f64,
    /// An arc clear this far along is a good arc, m.
    pub max_distance_m: f64,
    /// Cells closer than this to the swept footprint count as near misses, m.
    pub near_miss_m: f64,
    /// Vote lost by a clear arc whose footprint grazes a cell.
    pub near_miss_penalty: f64,
    /// Clearance bands between 0 and `near_miss_m` (the penalty's resolution).
    pub near_miss_bands: u32,
    /// Resolution of the collision grid, m.
    pub grid_resolution_m: f64,
    /// Vote a speed at which the vehicle can stop within the best arc's free
    /// distance (minus `stop_margin_m`), reacting after `reaction_s`.
    pub speed_vote: bool,
    pub stop_margin_m: f64,
    pub reaction_s: f64,
    /// Fraction of `vehicle.max_deceleration_mps2` the speed votes count
    /// on when stopping (the rest is margin for ground that brakes worse).
    pub braking_fraction: f64,
    /// What ground no image has seen is: slow (drive only as fast as the
    /// vehicle can stop within seen ground), obstacle, or free.
    pub unseen_ground: UnseenGround,
    /// The speed governor's reaction time (`unseen_ground = "slow"`):
    /// from an image to the brakes acting, s (0: the pipeline's, derived
    /// from the sensor, the perception latency, the command period and
    /// the actuation delay: `speed_bound.reaction_s`; a behaviour built
    /// from a configuration never resolved uses `reaction_s`).
    pub governor_reaction_s: f64,
    /// How far the front is from a hole when the ray grazing its edge flags
    /// it, m: a suspected drop-off (graded ground with the reason
    /// drop-off) slows an arc only to the speed at which the vehicle stops
    /// within this of it (0: stop short of it; the pipeline sets it from
    /// the sensor, `speed_bound.hole_grazed_m` less the sensor's setback).
    pub hole_seen_within_m: f64,
    /// Backward arcs are checked this far, m (0: no opinion on backing up,
    /// so the arbiter never backs up).
    pub reverse_reach_m: f64,
    /// Clearance kept to each side of the body when backing up, m; creeping
    /// forwards in a manoeuvre, the widest near-miss band within it.
    pub reverse_margin_m: f64,
    /// Attitude, chassis clearance and roughness along the arcs, from the
    /// map's elevation layer (004 §IV).
    pub terrain: TerrainConfig,
}

/// What obstacle avoidance makes of ground no image has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UnseenGround {
    /// Drive only as fast as the vehicle can stop within seen ground.
    Slow,
    /// Unseen ground is an obstacle (000 §4.2).
    Obstacle,
    /// Unseen ground is free (002's behaviour).
    Free,
}

impl Default for ObstacleAvoidanceConfig {
    fn default() -> Self {
        Self {
            min_distance_m: 6.0,
            max_distance_m: 18.0,
            near_miss_m: 1.0,
            near_miss_penalty: 0.5,
            near_miss_bands: 4,
            grid_resolution_m: 0.2,
            speed_vote: true,
            stop_margin_m: 2.0,
            reaction_s: 0.75,
            braking_fraction: 0.5,
            unseen_ground: UnseenGround::Slow,
            governor_reaction_s: 0.0,
            hole_seen_within_m: 0.0,
            reverse_reach_m: 5.0,
            reverse_margin_m: 0.3,
            terrain: TerrainConfig::default(),
        }
    }
}

impl ObstacleAvoidanceConfig {
    /// Checks the keys (relative to the table) and the terrain's against
    /// the vehicle.
    pub(crate) fn validate(&self, setup: &Setup<'_>) -> Result<(), ConfigError> {
        let c = self;
        config::positive("min_distance_m", c.min_distance_m)?;
        config::positive("max_distance_m", c.max_distance_m)?;
        if c.max_distance_m <= c.min_distance_m {
            return Err(ConfigError::new(
                "max_distance_m",
                format!(
                    "is {} m, must exceed min_distance_m ({} m)",
                    c.max_distance_m, c.min_distance_m
                ),
            ));
        }
        if c.max_distance_m > 100.0 {
            return Err(ConfigError::new(
                "max_distance_m",
                format!("is {} m, at most 100 m", c.max_distance_m),
            ));
        }
        // The footprint is widened by it over the grid of every arc: 1e300
        // had hung the first vote.
        config::in_range("near_miss_m", c.near_miss_m, 0.01, 10.0)?;
        config::in_range("near_miss_penalty", c.near_miss_penalty, 0.0, 2.0)?;
        if !(1..=16).contains(&c.near_miss_bands) {
            return Err(ConfigError::new(
                "near_miss_bands",
                format!("is {}, must be 1 to 16", c.near_miss_bands),
            ));
        }
        config::in_range("grid_resolution_m", c.grid_resolution_m, 0.05, 1.0)?;
        config::non_negative("stop_margin_m", c.stop_margin_m)?;
        config::non_negative("reaction_s", c.reaction_s)?;
        config::in_range("governor_reaction_s", c.governor_reaction_s, 0.0, 10.0)?;
        config::in_range("braking_fraction", c.braking_fraction, 0.1, 1.0)?;
        config::in_range("reverse_reach_m", c.reverse_reach_m, 0.0, 20.0)?;
        config::in_range("reverse_margin_m", c.reverse_margin_m, 0.0, 2.0)?;
        c.terrain
            .validate(setup.vehicle)
            .map_err(|e| e.within("terrain"))
    }
}
