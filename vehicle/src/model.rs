//! The vehicle model: its size, its kinematic limits and the terrain it can
//! negotiate. Defaults are the paper's HMMWV (002 §2, §7).

use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError};

/// Everything arcnav needs to know about the vehicle. Lives in `[vehicle]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// Body length, bumper to bumper, m.
    pub length_m: f64,
    /// Body width, m.
    pub width_m: f64,
    /// How far the body reaches behind the origin (the rear axle), m. The
    /// footprint spans x ∈ [-rear_overhang_m, length_m - rear_overhang_m].
    pub rear_overhang_m: f64,
    /// Distance between the axles, m.
    pub wheelbase_m: f64,
    /// Tightest turn the vehicle can drive, m (002 §7: 7.5 m).
    pub min_turning_radius_m: f64,
    /// Top speed the controller accepts, m/s.
    pub max_speed_mps: f64,
    /// Acceleration limit, m/s².
    pub max_acceleration_mps2: f64,
    /// Braking limit, m/s².
    pub max_deceleration_mps2: f64,
    /// Steering-rate limit expressed as curvature change per second, 1/(m·s).
    pub max_curvature_rate: f64,
    /// Delay between a command leaving the arbiter and the vehicle acting on it, s.
    pub command_latency_s: f64,
    /// Height of the lowest point of the chassis above the ground, m.
    pub ground_clearance_m: f64,
    /// Largest elevation discontinuity the vehicle drives over, m (002 §7: 20 cm).
    pub tolerated_step_m: f64,
    /// Steepest slope the vehicle drives on, degrees.
    pub max_slope_deg: f64,
    /// Radius of the wheels, m (M998: 37" tyres, 0.47 m). With the
    /// tolerated step it sets the widest gap the vehicle rolls across
    /// ([`VehicleConfig::bridgeable_gap_m`]).
    pub wheel_radius_m: f64,
    /// Wheel centre to wheel centre across an axle, m (M998: 1.82 m).
    pub track_m: f64,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        // HMMWV M998: 4.57 m × 2.16 m, 3.30 m wheelbase, 0.41 m clearance.
        Self {
            length_m: 4.6,
            width_m: 2.2,
            rear_overhang_m: 0.6,
            wheelbase_m: 3.3,
            min_turning_radius_m: 7.5,
            max_speed_mps: 10.0,
            max_acceleration_mps2: 1.0,
            max_deceleration_mps2: 3.0,
            max_curvature_rate: 0.15,
            command_latency_s: 0.25,
            ground_clearance_m: 0.4,
            tolerated_step_m: 0.2,
            max_slope_deg: 25.0,
            wheel_radius_m: 0.47,
            track_m: 1.82,
        }
    }
}

impl VehicleConfig {
    /// Checks every value; keys are relative to `[vehicle]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::positive("length_m", self.length_m)?;
        config::positive("width_m", self.width_m)?;
        config::non_negative("rear_overhang_m", self.rear_overhang_m)?;
        config::positive("wheelbase_m", self.wheelbase_m)?;
        config::positive("min_turning_radius_m", self.min_turning_radius_m)?;
        config::positive("max_speed_mps", self.max_speed_mps)?;
        config::positive("max_acceleration_mps2", self.max_acceleration_mps2)?;
        config::positive("max_deceleration_mps2", self.max_deceleration_mps2)?;
        config::positive("max_curvature_rate", self.max_curvature_rate)?;
        config::non_negative("command_latency_s", self.command_latency_s)?;
        config::positive("ground_clearance_m", self.ground_clearance_m)?;
        config::positive("tolerated_step_m", self.tolerated_step_m)?;
        config::in_range("max_slope_deg", self.max_slope_deg, 0.1, 89.0)?;
        config::positive("wheel_radius_m", self.wheel_radius_m)?;
        config::positive("track_m", self.track_m)?;
        if self.track_m > self.width_m {
            return Err(ConfigError::new(
                "track_m",
                format!(
                    "is {} m, wider than the body (width_m {} m)",
                    self.track_m, self.width_m
                ),
            ));
        }
        if self.rear_overhang_m >= self.length_m {
            return Err(ConfigError::new(
                "rear_overhang_m",
                format!(
                    "is {} m, must be shorter than length_m ({} m): the rear axle must lie under the body",
                    self.rear_overhang_m, self.length_m
                ),
            ));
        }
        if self.wheelbase_m > self.length_m - self.rear_overhang_m {
            return Err(ConfigError::new(
                "wheelbase_m",
                format!(
                    "is {} m, but the body reaches only {} m ahead of the rear axle (length_m - rear_overhang_m)",
                    self.wheelbase_m,
                    self.length_m - self.rear_overhang_m
                ),
            ));
        }
        Ok(())
    }

    /// The widest gap in the ground a wheel rolls across, m: a wheel of
    /// radius R spanning a gap of width w sags `R - sqrt(R² - (w/2)²)` into
    /// it, and the sag may be at most the tolerated step s, so
    /// `w = 2·sqrt(2·R·s - s²)` (0.77 m for the HMMWV: R = 0.47 m,
    /// s = 0.2 m). A wheel smaller than the step bridges its diameter.
    pub fn bridgeable_gap_m(&self) -> f64 {
        let (r, s) = (
            self.wheel_radius_m,
            self.tolerated_step_m.min(self.wheel_radius_m),
        );
        2.0 * (2.0 * r * s - s * s).max(0.0).sqrt()
    }

    /// The body outline in the vehicle frame.
    pub fn footprint(&self) -> Footprint {
        Footprint {
            x_min: -self.rear_overhang_m,
            x_max: self.length_m - self.rear_overhang_m,
            half_width: self.width_m / 2.0,
        }
    }

    /// Largest curvature the vehicle can steer, 1/m.
    pub fn max_curvature(&self) -> f64 {
        1.0 / self.min_turning_radius_m
    }

    /// Maximum slope in radians.
    pub fn max_slope_rad(&self) -> f64 {
        self.max_slope_deg.to_radians()
    }
}

/// The vehicle body as a rectangle in the vehicle frame (x forward, y left).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Rear edge, m (negative: behind the rear axle).
    pub x_min: f64,
    /// Front edge, m.
    pub x_max: f64,
    /// Half the width, m.
    pub half_width: f64,
}

impl Footprint {
    /// True when `p` (vehicle frame) lies inside or on the outline.
    pub fn contains(&self, p: Point2<f64>) -> bool {
        (self.x_min..=self.x_max).contains(&p.x) && p.y.abs() <= self.half_width
    }

    /// The same rectangle widened by `margin_m` on both sides (used for
    /// near-miss clearance bands).
    #[must_use]
    pub fn widened(&self, margin_m: f64) -> Self {
        Self {
            half_width: self.half_width + margin_m,
            ..*self
        }
    }

    /// Corners in the vehicle frame, counter-clockwise from rear right.
    pub fn corners(&self) -> [Point2<f64>; 4] {
        [
            Point2::new(self.x_min, -self.half_width),
            Point2::new(self.x_max, -self.half_width),
            Point2::new(self.x_max, self.half_width),
            Point2::new(self.x_min, self.half_width),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_papers_hmmwv_and_valid() {
        let v = VehicleConfig::default();
        assert_eq!(v.min_turning_radius_m, 7.5);
        assert_eq!(v.tolerated_step_m, 0.2);
        v.validate().unwrap();
    }

    #[test]
    fn footprint_extends_behind_and_ahead_of_the_rear_axle() {
        let f = VehicleConfig::default().footprint();
        assert_eq!((f.x_min, f.half_width), (-0.6, 1.1));
        assert!((f.x_max - 4.0).abs() < 1e-12);
        assert!(f.contains(Point2::new(0.0, 0.0)));
        assert!(f.contains(Point2::new(3.9, -1.0)));
        assert!(!f.contains(Point2::new(4.1, 0.0)));
        assert!(!f.contains(Point2::new(1.0, 1.2)));
        assert!(f.widened(0.2).contains(Point2::new(1.0, 1.2)));
    }

    #[test]
    fn contradictory_body_dimensions_are_refused() {
        let v = VehicleConfig {
            rear_overhang_m: 5.0,
            ..VehicleConfig::default()
        };
        assert_eq!(v.validate().unwrap_err().key, "rear_overhang_m");
        let v = VehicleConfig {
            wheelbase_m: 4.5,
            ..VehicleConfig::default()
        };
        assert_eq!(v.validate().unwrap_err().key, "wheelbase_m");
        let v = VehicleConfig {
            max_slope_deg: 95.0,
            ..VehicleConfig::default()
        };
        assert_eq!(v.validate().unwrap_err().key, "max_slope_deg");
    }
}
