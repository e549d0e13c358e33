//! Frames and poses (REP 103).
//!
//! - **Vehicle frame**: x forward, y left, z up; the origin is on the ground
//!   under the middle of the rear axle, the paper's control point (002 §4).
//! - **World frame**: x east, y north, z up.
//! - **Gravity-aligned (level) frame**: the vehicle frame's origin and heading,
//!   with z along gravity (the vehicle's roll and pitch removed). Perception
//!   bins points in it.
//!
//! Quaternions travel as `[w, x, y, z]`. Transforms are named after what they
//! do: `world_from_vehicle` maps a point in the vehicle frame to the world.

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::time::Utime;

/// A rigid transform in 3-D.
pub type Isometry = Isometry3<f64>;

/// A quaternion on the wire was not a rotation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("quaternion [w, x, y, z] = {0:?} is not a rotation (zero length or not finite)")]
    InvalidQuaternion([f64; 4]),
    #[error("position {0:?} is not finite")]
    NonFinitePosition([f64; 3]),
    #[error(
        "position {0:?} lies farther than {MAX_COORDINATE_M} m from the frame's origin on an axis"
    )]
    PositionTooFar([f64; 3]),
}

/// Positions (a pose, a sensor mount) lie within this of their frame's
/// origin on every axis, m: 10 000 km holds a UTM grid (northings up to
/// 10⁷ m) and the Earth-centred frame. Poses 10¹⁹ m out had overflowed the
/// local map's cell indices and aborted the process (a replayed log, a
/// pose from the network); 10⁸ m out the map refused reports.
pub const MAX_COORDINATE_M: f64 = 1e7;

/// A `[w, x, y, z]` quaternion as a rotation; normalised, refused if not
/// finite or of (near) zero length.
pub fn rotation_from_wxyz(wxyz: [f64; 4]) -> Result<UnitQuaternion<f64>, FrameError> {
    let [w, x, y, z] = wxyz;
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    if !norm.is_finite() || norm < 1e-9 {
        return Err(FrameError::InvalidQuaternion(wxyz));
    }
    Ok(UnitQuaternion::from_quaternion(q))
}

/// A rotation as `[w, x, y, z]`.
pub fn rotation_to_wxyz(rotation: &UnitQuaternion<f64>) -> [f64; 4] {
    let q = rotation.quaternion();
    [q.w, q.i, q.j, q.k]
}

/// A transform from a position and a `[w, x, y, z]` orientation, as carried
/// by `pose_t` and `range_image_t`.
pub fn isometry_from_parts(position: [f64; 3], wxyz: [f64; 4]) -> Result<Isometry, FrameError> {
    if position.iter().any(|v| !v.is_finite()) {
        return Err(FrameError::NonFinitePosition(position));
    }
    if position.iter().any(|v| v.abs() > MAX_COORDINATE_M) {
        return Err(FrameError::PositionTooFar(position));
    }
    let rotation = rotation_from_wxyz(wxyz)?;
    Ok(Isometry::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        rotation,
    ))
}

/// A transform from position and roll, pitch, yaw (intrinsic z-y'-x'', the
/// aerospace convention: yaw about z, then pitch about the new y, then roll).
pub fn isometry_from_xyz_rpy(position: [f64; 3], roll: f64, pitch: f64, yaw: f64) -> Isometry {
    Isometry::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// A transform on the ground plane: position (x, y), heading `yaw`, z = 0.
pub fn planar_isometry(x: f64, y: f64, yaw: f64) -> Isometry {
    isometry_from_xyz_rpy([x, y, 0.0], 0.0, 0.0, yaw)
}

/// Heading of the frame's x axis projected on the world's ground plane,
/// radians CCW from world x. Well defined unless the x axis points straight up.
pub fn yaw_of(world_from_frame: &Isometry) -> f64 {
    let x_axis = world_from_frame.rotation * Vector3::x();
    x_axis.y.atan2(x_axis.x)
}

/// The gravity-aligned frame of a vehicle pose: same origin and heading, roll
/// and pitch removed (`world_from_level`).
pub fn level_frame(world_from_vehicle: &Isometry) -> Isometry {
    Isometry::from_parts(
        world_from_vehicle.translation,
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_of(world_from_vehicle)),
    )
}

/// The vehicle's state at one instant, as carried by `pose_t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Time at which this pose is valid.
    pub utime: Utime,
    /// Vehicle → world.
    pub world_from_vehicle: Isometry,
    /// Velocity in the world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Yaw rate, rad/s, positive turning left.
    pub yaw_rate: f64,
}

impl Pose {
    /// A pose with zero velocity.
    pub fn at_rest(utime: Utime, world_from_vehicle: Isometry) -> Self {
        Self {
            utime,
            world_from_vehicle,
            velocity: Vector3::zeros(),
            yaw_rate: 0.0,
        }
    }

    /// This pose carried `dt_us` ahead at its velocity and yaw rate (a
    /// constant twist, turning about the world's vertical).
    pub fn extrapolated(&self, dt_us: Utime) -> Pose {
        let dt = dt_us as f64 * 1e-6;
        let turn =
            nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_rate * dt);
        let mut world_from_vehicle = self.world_from_vehicle;
        world_from_vehicle.translation.vector += self.velocity * dt;
        world_from_vehicle.rotation = turn * world_from_vehicle.rotation;
        Pose {
            utime: self.utime + dt_us,
            world_from_vehicle,
            ..*self
        }
    }

    /// Origin of the vehicle frame in the world.
    pub fn position(&self) -> Point3<f64> {
        Point3::from(self.world_from_vehicle.translation.vector)
    }

    /// Heading, radians CCW from world x.
    pub fn yaw(&self) -> f64 {
        yaw_of(&self.world_from_vehicle)
    }

    /// Speed over ground, m/s.
    pub fn ground_speed(&self) -> f64 {
        self.velocity.xy().norm()
    }

    /// True when every component is a finite number.
    pub fn is_finite(&self) -> bool {
        let t = &self.world_from_vehicle.translation.vector;
        let q = self.world_from_vehicle.rotation.quaternion();
        t.iter().all(|v| v.is_finite())
            && q.coords.iter().all(|v| v.is_finite())
            && self.velocity.iter().all(|v| v.is_finite())
            && self.yaw_rate.is_finite()
    }
}

/// Wraps an angle to (-π, π].
pub fn wrap_angle(angle: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let wrapped = angle.rem_euclid(two_pi);
    if wrapped > std::f64::consts::PI {
        wrapped - two_pi
    } else {
        wrapped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn vehicle_x_is_forward_and_y_is_left() {
        let world_from_vehicle = planar_isometry(10.0, 5.0, FRAC_PI_2);
        // One metre ahead of a vehicle heading north is one metre further north.
        let ahead = world_from_vehicle * Point3::new(1.0, 0.0, 0.0);
        assert_relative_eq!(ahead, Point3::new(10.0, 6.0, 0.0), epsilon = 1e-12);
        // One metre to its left is one metre to the west.
        let left = world_from_vehicle * Point3::new(0.0, 1.0, 0.0);
        assert_relative_eq!(left, Point3::new(9.0, 5.0, 0.0), epsilon = 1e-12);
    }

    #[test]
    fn level_frame_drops_roll_and_pitch_but_keeps_heading() {
        let tilted = isometry_from_xyz_rpy([1.0, 2.0, 3.0], 0.1, -0.2, 0.7);
        let level = level_frame(&tilted);
        assert_relative_eq!(yaw_of(&level), 0.7, epsilon = 1e-12);
        assert_relative_eq!(level.rotation * Vector3::z(), Vector3::z(), epsilon = 1e-12);
        assert_eq!(level.translation, tilted.translation);
    }

    #[test]
    fn quaternions_round_trip_and_bad_ones_are_refused() {
        let q = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let back = rotation_from_wxyz(rotation_to_wxyz(&q)).unwrap();
        assert_relative_eq!(back, q, epsilon = 1e-12);
        // Not normalised on the wire: accepted and normalised.
        let doubled = rotation_from_wxyz([2.0, 0.0, 0.0, 0.0]).unwrap();
        assert_relative_eq!(doubled, UnitQuaternion::identity());
        assert!(rotation_from_wxyz([0.0; 4]).is_err());
        assert!(rotation_from_wxyz([f64::NAN, 0.0, 0.0, 1.0]).is_err());
        assert!(isometry_from_parts([f64::INFINITY, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]).is_err());
        // Finite but beyond any frame a vehicle drives in.
        let far = isometry_from_parts([1e19, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        assert!(matches!(far, Err(FrameError::PositionTooFar(_))), "{far:?}");
        let utm = [500_000.0, 9_999_999.0, 120.0];
        assert!(isometry_from_parts(utm, [1.0, 0.0, 0.0, 0.0]).is_ok());
    }

    #[test]
    fn wrap_angle_stays_in_half_open_interval() {
        assert_relative_eq!(wrap_angle(3.0 * PI), PI, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(-PI), PI, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(0.5), 0.5);
        assert_relative_eq!(wrap_angle(-0.5 - 4.0 * PI), -0.5, epsilon = 1e-12);
    }
}
