//! The arbiter's output: what the vehicle is asked to do.

use crate::time::Utime;

/// A steering and speed command (wire type `steering_command_t`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringCommand {
    /// Time the command was issued.
    pub utime: Utime,
    /// 1/m, positive turning left.
    pub curvature: f64,
    /// m/s along the vehicle's heading: positive forwards, negative
    /// backing up (as ROS `Twist` and `AckermannDrive`); 0 means stop.
    pub speed_mps: f64,
    /// Index into the arbiter's arc set (driven backwards when the speed is
    /// negative); `None` for a stop.
    pub arc_index: Option<usize>,
    /// Fused vote of the chosen arc.
    pub vote: f32,
    /// Turning in place (a skid-steer vehicle, on an arc of curvature
    /// ±∞): the yaw rate, rad/s, positive turning left, with the speed 0.
    /// 0 on every other command (on an arc the yaw rate is
    /// `speed_mps · curvature`).
    pub turn_rate_radps: f64,
}

impl SteeringCommand {
    /// Stop, keeping the wheels straight.
    pub fn stop(utime: Utime) -> Self {
        Self {
            utime,
            curvature: 0.0,
            speed_mps: 0.0,
            arc_index: None,
            vote: 0.0,
            turn_rate_radps: 0.0,
        }
    }

    /// Turn in place at `rate_radps` (positive left) on the arc
    /// `arc_index` (curvature ±∞ of its sign).
    pub fn turn_in_place(utime: Utime, rate_radps: f64, arc_index: usize, vote: f32) -> Self {
        Self {
            utime,
            curvature: f64::INFINITY.copysign(rate_radps),
            speed_mps: 0.0,
            arc_index: Some(arc_index),
            vote,
            turn_rate_radps: rate_radps,
        }
    }

    /// True when the command asks the vehicle to stand still (neither
    /// driving nor turning in place).
    pub fn is_stop(&self) -> bool {
        self.arc_index.is_none() || (self.speed_mps == 0.0 && !self.is_turn_in_place())
    }

    /// True when the command turns the vehicle in place.
    pub fn is_turn_in_place(&self) -> bool {
        self.arc_index.is_some() && self.turn_rate_radps != 0.0 && self.turn_rate_radps.is_finite()
    }

    /// The yaw rate the command asks for, rad/s, positive left.
    pub fn yaw_rate(&self) -> f64 {
        if self.is_turn_in_place() {
            self.turn_rate_radps
        } else if self.is_stop() {
            0.0
        } else {
            self.speed_mps * self.curvature
        }
    }

    /// True when the command backs the vehicle up.
    pub fn is_reverse(&self) -> bool {
        !self.is_stop() && self.speed_mps < 0.0
    }
}
