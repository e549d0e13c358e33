//! `[perception.height_diff]`: the multi-scale height-difference
//! evaluator's keys and their checks.

use arcnav_vehicle::VehicleConfig;
use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[perception.height_diff]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeightDiffConfig {
    /// Height-map cell, m (000: 5 cm for its 8 m map).
    pub cell_size_m: f64,
    /// Median window, degrees of beam angle (000: 10 × 10 pixels of 0.09°).
    pub median_window_deg: f64,
    /// A return farther than `outlier_m + outlier_fraction · median` from
    /// its window's median is removed, m.
    pub outlier_m: f64,
    pub outlier_fraction: f64,
    /// δ0 of the gap-filling distance δ = δ0 + Δ·r, m (000 §4.2: 4 cells of 5 cm).
    pub gap_base_m: f64,
    /// Δ of δ = δ0 + Δ·r, m per m (000 §4.2: 0.054).
    pub gap_per_m: f64,
    /// The scales l, in cells (000 §4.3: 1, 3, 6).
    pub scales: [u32; 3],
    /// λ_l (000 Table 1: 5.0, 2.5, 3.5), per m.
    pub weights: [f64; 3],
    /// Each scale's summand is capped at this (000 §5.1: 0.5).
    pub cap: f64,
    /// A cell whose D̃ reaches this is untraversable (000 §5.1: 1, which the
    /// caps let no single scale reach alone), besides absolute obstacles.
    pub obstacle_cost: f64,
    /// Cells with D̃ of at least this fraction of `obstacle_cost` are
    /// reported as graded ground with cost D̃ / obstacle_cost (0: none).
    pub graded_from: f64,
    /// Absolute obstacles are inflated by this radius in the drivability
    /// map D_D, m (default: half the vehicle's width).
    pub robot_radius_m: f64,
}

impl Default for HeightDiffConfig {
    fn default() -> Self {
        Self {
            cell_size_m: 0.1,
            median_window_deg: 0.9,
            outlier_m: 0.3,
            outlier_fraction: 0.05,
            gap_base_m: 0.2,
            gap_per_m: 0.054,
            scales: [1, 3, 6],
            weights: [5.0, 2.5, 3.5],
            cap: 0.5,
            obstacle_cost: 1.0,
            graded_from: 0.75,
            robot_radius_m: VehicleConfig::default().width_m / 2.0,
        }
    }
}

impl HeightDiffConfig {
    /// Keys relative to `[perception]`.
    pub(crate) fn validate(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        let key = |k: &str| format!("height_diff.{k}");
        config::in_range(&key("cell_size_m"), self.cell_size_m, 0.02, 1.0)?;
        config::in_range(&key("median_window_deg"), self.median_window_deg, 0.0, 10.0)?;
        config::non_negative(&key("outlier_m"), self.outlier_m)?;
        config::in_range(&key("outlier_fraction"), self.outlier_fraction, 0.0, 1.0)?;
        config::non_negative(&key("gap_base_m"), self.gap_base_m)?;
        config::in_range(&key("gap_per_m"), self.gap_per_m, 0.0, 1.0)?;
        if self.scales[0] == 0 || !self.scales.is_sorted() || self.scales[2] > 50 {
            return Err(ConfigError::new(
                key("scales"),
                format!(
                    "is {:?}, must be increasing, from 1 to 50 cells",
                    self.scales
                ),
            ));
        }
        for (i, w) in self.weights.iter().enumerate() {
            config::positive(&format!("{}[{i}]", key("weights")), *w)?;
        }
        config::in_range(&key("cap"), self.cap, 0.01, 1.0)?;
        config::positive(&key("obstacle_cost"), self.obstacle_cost)?;
        config::in_range(&key("graded_from"), self.graded_from, 0.0, 1.0)?;
        config::non_negative(&key("robot_radius_m"), self.robot_radius_m)?;
        // An absolute obstacle at the finest scale is a step of 1/λ_1.
        let step = 1.0 / self.weights[0];
        if step > vehicle.tolerated_step_m + 1e-9 {
            return Err(ConfigError::new(
                format!("{}[0]", key("weights")),
                format!(
                    "is {}: a step is an obstacle only from 1/λ_1 = {step:.3} m, more than \
                     vehicle.tolerated_step_m ({}): perception would pass terrain the vehicle \
                     cannot drive",
                    self.weights[0], vehicle.tolerated_step_m
                ),
            ));
        }
        Ok(())
    }
}
