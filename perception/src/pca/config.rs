//! `[perception.pca]`: the hierarchical-PCA evaluator's keys and their
//! checks.

use arcnav_vehicle::VehicleConfig;
use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[perception.pca]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PcaConfig {
    /// The smallest region, m (001 §3.2: 10 cm × 10 cm).
    pub cell_size_m: f64,
    /// Square tiles the recursion starts from, m (a whole number of cells).
    pub tile_m: f64,
    /// A region is flat when the standard deviation of its points along
    /// its most vertical eigenvector is at most this, m (t = this²).
    pub max_disturbance_m: f64,
    /// A region with fewer returns is not judged (4: three points always
    /// lie in a plane; a 10 cm cell on a box's edge 6 m from a 64-beam
    /// lidar holds about five).
    pub min_points: u32,
    /// A flat region steeper than this is an obstacle, degrees.
    pub max_slope_deg: f64,
    /// ... judged only when its points spread this much (standard
    /// deviation) along x and along y, m.
    pub min_plane_spread_m: f64,
    /// σ_L: the sensor's range noise, removed from the roughness, m.
    pub range_noise_m: f64,
    /// The mean filter along each scan line, returns (001 §3.3: 9).
    pub roughness_window: u32,
    /// A return whose filter window spans more than this fraction of its
    /// range straddles an edge (an obstacle against the ground behind it)
    /// and gives no deviation (5 cm bumps seen from 2.4 m span about 4 %).
    pub roughness_max_jump: f64,
    /// σ̂_δ² (eq. 3) of a cell is taken over the returns of the cells in a
    /// square of this side around it, m (001: the cell alone; a 10 cm cell
    /// holds 2-5 returns of a 64-beam lidar, too few for a variance).
    pub roughness_pool_m: f64,
    /// A cell judged flat whose bump height (eq. 2 solved for h₂) reaches
    /// this is reported as graded ground, m (below it: the noise of open
    /// ground).
    pub rough_from_m: f64,
    /// ... with cost `rough_max_cost · min(1, h₂ / rough_full_m)`: the
    /// bump height at which the cost is highest, m.
    pub rough_full_m: f64,
    /// The cost of the roughest ground, below 1: rough ground is passable
    /// (001 §3.3), only less preferred.
    pub rough_max_cost: f64,
}

impl Default for PcaConfig {
    fn default() -> Self {
        let vehicle = VehicleConfig::default();
        Self {
            cell_size_m: 0.1,
            tile_m: 0.8,
            max_disturbance_m: 0.03,
            min_points: 4,
            max_slope_deg: vehicle.max_slope_deg,
            min_plane_spread_m: 0.03,
            range_noise_m: 0.02,
            roughness_window: 9,
            roughness_max_jump: 0.1,
            roughness_pool_m: 0.5,
            rough_from_m: 0.01,
            rough_full_m: 0.05,
            rough_max_cost: 0.9,
        }
    }
}

impl PcaConfig {
    /// Keys relative to `[perception]`.
    pub(crate) fn validate(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        let key = |k: &str| format!("pca.{k}");
        config::in_range(&key("cell_size_m"), self.cell_size_m, 0.02, 1.0)?;
        config::in_range(&key("tile_m"), self.tile_m, self.cell_size_m, 20.0)?;
        config::positive(&key("max_disturbance_m"), self.max_disturbance_m)?;
        if !(4..=1_000_000).contains(&self.min_points) {
            return Err(ConfigError::new(
                key("min_points"),
                format!(
                    "is {}, must be at least 4 (three points always lie in a plane)",
                    self.min_points
                ),
            ));
        }
        config::in_range(&key("max_slope_deg"), self.max_slope_deg, 0.1, 89.0)?;
        if self.max_slope_deg > vehicle.max_slope_deg {
            return Err(ConfigError::new(
                key("max_slope_deg"),
                format!(
                    "is {}, more than vehicle.max_slope_deg ({}): perception would pass \
                     terrain the vehicle cannot drive",
                    self.max_slope_deg, vehicle.max_slope_deg
                ),
            ));
        }
        // A region holding a step of the tolerated height half on each
        // side has σ = step / 2: a laxer t passes it.
        if self.max_disturbance_m > vehicle.tolerated_step_m / 2.0 {
            return Err(ConfigError::new(
                key("max_disturbance_m"),
                format!(
                    "is {}, more than half vehicle.tolerated_step_m ({}): a region split evenly \
                     by a step the vehicle cannot drive would pass as flat",
                    self.max_disturbance_m, vehicle.tolerated_step_m
                ),
            ));
        }
        config::non_negative(&key("min_plane_spread_m"), self.min_plane_spread_m)?;
        config::non_negative(&key("range_noise_m"), self.range_noise_m)?;
        if !(1..=101).contains(&self.roughness_window) {
            return Err(ConfigError::new(
                key("roughness_window"),
                format!("is {}, must be 1 to 101", self.roughness_window),
            ));
        }
        config::in_range(
            &key("roughness_max_jump"),
            self.roughness_max_jump,
            0.001,
            10.0,
        )?;
        config::in_range(&key("roughness_pool_m"), self.roughness_pool_m, 0.0, 5.0)?;
        config::positive(&key("rough_from_m"), self.rough_from_m)?;
        if self.rough_full_m.is_nan() || self.rough_full_m <= self.rough_from_m {
            return Err(ConfigError::new(
                key("rough_full_m"),
                format!(
                    "is {}, must be more than rough_from_m ({})",
                    self.rough_full_m, self.rough_from_m
                ),
            ));
        }
        if !(self.rough_max_cost > 0.0 && self.rough_max_cost < 1.0) {
            return Err(ConfigError::new(
                key("rough_max_cost"),
                format!(
                    "is {}, must be above 0 and below 1 (a cost of 1 is an obstacle; rough \
                     ground is passable)",
                    self.rough_max_cost
                ),
            ));
        }
        Ok(())
    }
}
