//! `[guard]`: the zones' margins, how many returns make a hazard, how long
//! they are remembered, and when missing data stops the vehicle.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[guard]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GuardConfig {
    /// The guard checks every command (false: commands go to the vehicle
    /// as the pipeline made them).
    pub enabled: bool,
    /// The vehicle stops this far short of a hazard on its path, m: the
    /// stop zone is the braking distance at the vehicle's speed plus this.
    pub margin_m: f64,
    /// The zones are the body's swept footprint widened by this much on
    /// each side, m.
    pub side_margin_m: f64,
    /// Hazardous returns are held in cells of this side on the ground, m.
    pub cell_size_m: f64,
    /// A cell holds a hazard when at least this many hazardous returns
    /// fell in it (one return may be noise).
    pub min_points: usize,
    /// Returns farther than this from the vehicle (horizontally) are not
    /// tested, m; the ground profile still runs through them.
    pub range_m: f64,
    /// A return this close to the ground profile's slope is ground whatever
    /// the rows' spacing (the range noise, and the roughness of ground the
    /// vehicle drives), m.
    pub ground_noise_m: f64,
    /// A hazard is forgotten when images have looked at it this long
    /// without seeing it again, s (it moved, or was noise). One the sensor
    /// cannot look at (in the blind zone in front of the bumper below the
    /// lowest beam, beside a narrow field of view) is held however long the
    /// vehicle stands before it, until it is twice `range_m` away.
    pub memory_s: f64,
    /// At most this many cells are held (hazardous returns in new cells
    /// beyond it are counted as forgotten).
    pub max_cells: usize,
    /// Measured roll or pitch beyond `vehicle.max_slope_deg` less this
    /// stops, degrees.
    pub tilt_margin_deg: f64,
    /// A sensor silent for this many of its periods stops the vehicle
    /// (Nav2's `block_if_invalid`).
    pub image_timeout_periods: f64,
    /// A pose older than this stops the vehicle, s.
    pub pose_timeout_s: f64,
}

impl Default for GuardConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            margin_m: 1.0,
            side_margin_m: 0.15,
            cell_size_m: 0.2,
            min_points: 3,
            range_m: 30.0,
            ground_noise_m: 0.05,
            memory_s: 5.0,
            max_cells: 200_000,
            tilt_margin_deg: 2.0,
            image_timeout_periods: 3.0,
            pose_timeout_s: 0.5,
        }
    }
}

impl GuardConfig {
    /// Checks every value's range (keys without the section).
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::non_negative("margin_m", self.margin_m)?;
        config::non_negative("side_margin_m", self.side_margin_m)?;
        config::in_range("cell_size_m", self.cell_size_m, 0.01, 2.0)?;
        if self.min_points == 0 {
            return Err(ConfigError::new("min_points", "must be at least 1"));
        }
        config::positive("range_m", self.range_m)?;
        config::non_negative("ground_noise_m", self.ground_noise_m)?;
        config::non_negative("memory_s", self.memory_s)?;
        if self.max_cells == 0 || self.max_cells > 10_000_000 {
            return Err(ConfigError::new("max_cells", "must be 1 to 10 000 000"));
        }
        config::in_range("tilt_margin_deg", self.tilt_margin_deg, 0.0, 90.0)?;
        config::positive("image_timeout_periods", self.image_timeout_periods)?;
        config::positive("pose_timeout_s", self.pose_timeout_s)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_each_bad_value_is_named() {
        GuardConfig::default().validate().unwrap();
        let bad = [
            GuardConfig {
                margin_m: -1.0,
                ..GuardConfig::default()
            },
            GuardConfig {
                min_points: 0,
                ..GuardConfig::default()
            },
            GuardConfig {
                range_m: f64::NAN,
                ..GuardConfig::default()
            },
            GuardConfig {
                max_cells: 0,
                ..GuardConfig::default()
            },
            GuardConfig {
                pose_timeout_s: 0.0,
                ..GuardConfig::default()
            },
        ];
        let keys = [
            "margin_m",
            "min_points",
            "range_m",
            "max_cells",
            "pose_timeout_s",
        ];
        for (config, key) in bad.iter().zip(keys) {
            let e = config.validate().unwrap_err();
            assert_eq!(e.key, key, "{e:?}");
        }
    }
}
