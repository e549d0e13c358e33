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
        }
    }

    /// True when the command asks the vehicle to stand still.
    pub fn is_stop(&self) -> bool {
        self.arc_index.is_none() || self.speed_mps == 0.0
    }

    /// True when the command backs the vehicle up.
    pub fn is_reverse(&self) -> bool {
        !self.is_stop() && self.speed_mps < 0.0
    }
}
