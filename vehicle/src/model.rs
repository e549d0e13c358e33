//! The vehicle model: its size, its kinematic limits and the terrain it can
//! negotiate. Defaults are the paper's HMMWV (002 §2, §7).

use nalgebra::Point2;

pub use crate::footprint::Footprint;
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError};

/// How far from the rear axle the body may reach, m: every sweep and
/// raster of the body is sized by it.
pub const MAX_BODY_REACH_M: f64 = 50.0;

/// Everything arcnav needs to know about the vehicle. Lives in `[vehicle]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// The body's outline: `rectangle` (`length_m`, `width_m`,
    /// `rear_overhang_m`), `circle` (`radius_m` about `centre_m`) or
    /// `polygon` (`vertices_m`).
    pub footprint: FootprintShape,
    /// Body length, bumper to bumper, m (a rectangle's).
    pub length_m: f64,
    /// Body width, m (a rectangle's).
    pub width_m: f64,
    /// How far the body reaches behind the origin (the rear axle), m. The
    /// footprint spans x ∈ [-rear_overhang_m, length_m - rear_overhang_m]
    /// (a rectangle's).
    pub rear_overhang_m: f64,
    /// A circle's radius, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    /// A circle's centre in the vehicle frame, m (default: the origin).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_m: Option<[f64; 2]>,
    /// A polygon's vertices in the vehicle frame (x forward, y left), m,
    /// in order round it, either way; convex or not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vertices_m: Option<Vec<[f64; 2]>>,
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
    /// How the vehicle steers: `ackermann` (steered wheels, a minimum
    /// turning radius; the HMMWV) or `skid_steer` (wheels or tracks driven
    /// at different speeds on each side: it also turns in place, about the
    /// middle of its wheelbase).
    pub kinematics: Kinematics,
    /// A skid-steer vehicle's fastest turn in place, degrees per second
    /// (needed with `kinematics = "skid_steer"`, refused otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_yaw_rate_dps: Option<f64>,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        // HMMWV M998: 4.57 m × 2.16 m, 3.30 m wheelbase, 0.41 m clearance.
        Self {
            footprint: FootprintShape::Rectangle,
            length_m: 4.6,
            width_m: 2.2,
            rear_overhang_m: 0.6,
            radius_m: None,
            centre_m: None,
            vertices_m: None,
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
            kinematics: Kinematics::Ackermann,
            max_yaw_rate_dps: None,
        }
    }
}

impl VehicleConfig {
    /// A Warthog-class skid-steer vehicle (Clearpath Warthog: 1.52 m ×
    /// 1.38 m, 0.25 m clearance, 5 m/s), turning in place at 60°/s about
    /// the middle of its 1 m wheelbase: the `[vehicle]` of
    /// `config/skid_steer.toml` (a test holds the two equal).
    pub fn warthog() -> Self {
        Self {
            length_m: 1.52,
            width_m: 1.38,
            rear_overhang_m: 0.26,
            wheelbase_m: 1.0,
            min_turning_radius_m: 1.0,
            max_speed_mps: 5.0,
            max_curvature_rate: 1.0,
            ground_clearance_m: 0.25,
            wheel_radius_m: 0.3,
            track_m: 1.1,
            kinematics: Kinematics::SkidSteer,
            max_yaw_rate_dps: Some(60.0),
            ..Self::default()
        }
    }

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
        match (self.kinematics, self.max_yaw_rate_dps) {
            (Kinematics::SkidSteer, None) => {
                return Err(ConfigError::new(
                    "max_yaw_rate_dps",
                    "is needed with kinematics = \"skid_steer\": how fast the vehicle turns in place, degrees per second",
                ));
            }
            (Kinematics::SkidSteer, Some(rate)) => {
                config::in_range("max_yaw_rate_dps", rate, 1.0, 720.0)?;
            }
            (Kinematics::Ackermann, Some(_)) => {
                return Err(ConfigError::new(
                    "max_yaw_rate_dps",
                    "is read only with kinematics = \"skid_steer\" (an Ackermann vehicle does not turn in place)",
                ));
            }
            (Kinematics::Ackermann, None) => {}
        }
        let body = self.try_footprint()?;
        let shape = self.footprint.name();
        // The key that placed the body's outline where it is (a rectangle's
        // `rectangle_key`).
        let outline_key = |rectangle_key: &'static str| match self.footprint {
            FootprintShape::Rectangle => rectangle_key,
            FootprintShape::Circle => "radius_m",
            FootprintShape::Polygon => "vertices_m",
        };
        if body.reach() > MAX_BODY_REACH_M {
            return Err(ConfigError::new(
                outline_key("length_m"),
                format!(
                    "puts a point of the body {:.1} m from the rear axle; at most {MAX_BODY_REACH_M} m is accepted",
                    body.reach()
                ),
            ));
        }
        if self.track_m > 2.0 * body.half_width {
            return Err(ConfigError::new(
                "track_m",
                format!(
                    "is {} m, wider than the body ({} m across its {shape})",
                    self.track_m,
                    2.0 * body.half_width
                ),
            ));
        }
        if body.x_min > 0.0 || body.x_max <= 0.0 {
            let key = match self.footprint {
                FootprintShape::Circle => "centre_m",
                _ => outline_key("rear_overhang_m"),
            };
            return Err(ConfigError::new(
                key,
                format!(
                    "puts the body from x = {} m to {} m: the rear axle (x = 0) must lie under it, with body ahead of it",
                    body.x_min, body.x_max
                ),
            ));
        }
        if self.wheelbase_m > body.x_max {
            return Err(ConfigError::new(
                "wheelbase_m",
                format!(
                    "is {} m, but the body reaches only {} m ahead of the rear axle",
                    self.wheelbase_m, body.x_max
                ),
            ));
        }
        Ok(())
    }

    /// The body's outline from the keys of its shape, or which key is wrong.
    pub fn try_footprint(&self) -> Result<Footprint, ConfigError> {
        let only = |key: &str, given: bool, with: FootprintShape| {
            if given && self.footprint != with {
                Err(ConfigError::new(
                    key,
                    format!(
                        "is read only with footprint = \"{}\" (footprint is \"{}\")",
                        with.name(),
                        self.footprint.name()
                    ),
                ))
            } else {
                Ok(())
            }
        };
        only("radius_m", self.radius_m.is_some(), FootprintShape::Circle)?;
        only("centre_m", self.centre_m.is_some(), FootprintShape::Circle)?;
        only(
            "vertices_m",
            self.vertices_m.is_some(),
            FootprintShape::Polygon,
        )?;
        match self.footprint {
            FootprintShape::Rectangle => Ok(Footprint::rectangle(
                -self.rear_overhang_m,
                self.length_m - self.rear_overhang_m,
                self.width_m / 2.0,
            )),
            FootprintShape::Circle => {
                let radius = self.radius_m.ok_or_else(|| {
                    ConfigError::new("radius_m", "is needed with footprint = \"circle\"")
                })?;
                config::positive("radius_m", radius)?;
                let [x, y] = self.centre_m.unwrap_or([0.0, 0.0]);
                Footprint::circle(Point2::new(x, y), radius)
                    .map_err(|e| ConfigError::new("centre_m", e.to_string()))
            }
            FootprintShape::Polygon => {
                let vertices: Vec<Point2<f64>> = self
                    .vertices_m
                    .as_deref()
                    .ok_or_else(|| {
                        ConfigError::new(
                            "vertices_m",
                            "is needed with footprint = \"polygon\": [[x, y], ...] in the vehicle frame, m",
                        )
                    })?
                    .iter()
                    .map(|&[x, y]| Point2::new(x, y))
                    .collect();
                Footprint::polygon(&vertices)
                    .map_err(|e| ConfigError::new("vertices_m", e.to_string()))
            }
        }
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

    /// The body outline in the vehicle frame. [`VehicleConfig::validate`]
    /// refuses the keys that give no outline; unvalidated, those give the
    /// rectangle of `length_m`, `width_m` and `rear_overhang_m`.
    pub fn footprint(&self) -> Footprint {
        self.try_footprint().unwrap_or(Footprint::rectangle(
            -self.rear_overhang_m,
            self.length_m - self.rear_overhang_m,
            self.width_m / 2.0,
        ))
    }

    /// Largest curvature the vehicle can steer, 1/m.
    pub fn max_curvature(&self) -> f64 {
        1.0 / self.min_turning_radius_m
    }

    /// Maximum slope in radians.
    pub fn max_slope_rad(&self) -> f64 {
        self.max_slope_deg.to_radians()
    }

    /// How fast the vehicle turns in place, rad/s: 0 for an Ackermann
    /// vehicle, which cannot.
    pub fn turn_in_place_rate(&self) -> f64 {
        match self.kinematics {
            Kinematics::Ackermann => 0.0,
            Kinematics::SkidSteer => self.max_yaw_rate_dps.unwrap_or(0.0).to_radians(),
        }
    }

    /// The point a turn in place turns about, vehicle frame: the middle of
    /// the wheelbase, where a skid-steer vehicle's wheels slip evenly.
    pub fn turn_centre(&self) -> Point2<f64> {
        Point2::new(0.5 * self.wheelbase_m, 0.0)
    }
}

/// How the vehicle steers (`[vehicle] kinematics`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kinematics {
    /// Steered wheels: arcs no tighter than `min_turning_radius_m`; a
    /// turn round is a K-point turn.
    #[default]
    Ackermann,
    /// Each side driven at its own speed: arcs of any radius and turns in
    /// place at `max_yaw_rate_dps`.
    SkidSteer,
}

/// The kinds of body outline (`[vehicle] footprint`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FootprintShape {
    /// `length_m` × `width_m`, `rear_overhang_m` of it behind the rear axle.
    #[default]
    Rectangle,
    /// `radius_m` about `centre_m`.
    Circle,
    /// `vertices_m`.
    Polygon,
}

impl FootprintShape {
    /// The name as the configuration spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Rectangle => "rectangle",
            Self::Circle => "circle",
            Self::Polygon => "polygon",
        }
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

    #[test]
    fn a_circle_and_a_polygon_are_bodies_and_their_keys_are_checked() {
        let circle = VehicleConfig {
            footprint: FootprintShape::Circle,
            radius_m: Some(0.6),
            wheelbase_m: 0.5,
            track_m: 1.0,
            ..VehicleConfig::default()
        };
        circle.validate().unwrap();
        let f = circle.footprint();
        assert!(!f.is_rectangle() && (f.x_max - 0.6).abs() < 0.003);
        let missing = VehicleConfig {
            radius_m: None,
            ..circle.clone()
        };
        assert_eq!(missing.validate().unwrap_err().key, "radius_m");
        let stray = VehicleConfig {
            vertices_m: Some(vec![[0.0, 0.0]]),
            ..circle.clone()
        };
        let err = stray.validate().unwrap_err();
        assert_eq!(err.key, "vertices_m");
        assert!(
            err.reason.contains("only with footprint = \"polygon\""),
            "{err}"
        );
        let ell = VehicleConfig {
            footprint: FootprintShape::Polygon,
            vertices_m: Some(vec![
                [-0.5, -1.0],
                [1.0, -1.0],
                [1.0, 0.0],
                [2.5, 0.0],
                [2.5, 1.0],
                [-0.5, 1.0],
            ]),
            wheelbase_m: 1.0,
            track_m: 1.6,
            ..VehicleConfig::default()
        };
        ell.validate().unwrap();
        assert!(!ell.footprint().contains(Point2::new(2.0, -0.5)));
        let crossed = VehicleConfig {
            vertices_m: Some(vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]),
            ..ell.clone()
        };
        let err = crossed.validate().unwrap_err();
        assert_eq!(err.key, "vertices_m");
        assert!(err.reason.contains("cross"), "{err}");
        let ahead = VehicleConfig {
            vertices_m: Some(vec![[1.0, -1.0], [3.0, -1.0], [3.0, 1.0], [1.0, 1.0]]),
            ..ell
        };
        assert_eq!(ahead.validate().unwrap_err().key, "vertices_m");
    }
}
