//! A kinematic motion model: advances the vehicle on the ground plane under
//! steering commands, with command latency, steering-rate and acceleration
//! limits. The simulator drapes the result on its terrain; tests use it to
//! check what a command sequence does.
//!
//! Between events the vehicle drives a constant-curvature arc, integrated in
//! closed form in sub-steps of at most [`MAX_SUBSTEP_US`], so with no limits it
//! follows an arc exactly.

use std::collections::VecDeque;

use crate::command::SteeringCommand;
use crate::frames::wrap_angle;
use crate::model::VehicleConfig;
use crate::time::{Utime, micros_to_seconds, seconds_to_micros};

/// Longest integration step, µs.
pub const MAX_SUBSTEP_US: Utime = 10_000;

/// The vehicle on the ground plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlanarState {
    /// World x of the rear-axle centre, m.
    pub x: f64,
    /// World y of the rear-axle centre, m.
    pub y: f64,
    /// Heading, radians CCW from world x, wrapped to (-π, π].
    pub yaw: f64,
    /// Speed along the heading, m/s (negative: backing up).
    pub speed_mps: f64,
    /// Curvature being driven, 1/m.
    pub curvature: f64,
}

/// Limits of the actuators. `f64::INFINITY` disables a limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    pub max_speed_mps: f64,
    pub max_acceleration_mps2: f64,
    pub max_deceleration_mps2: f64,
    pub max_curvature: f64,
    pub max_curvature_rate: f64,
    pub latency_us: Utime,
    /// Fastest turn in place, rad/s; 0 for a vehicle that cannot (a turn
    /// in place asked of it is a stop).
    pub max_turn_rate: f64,
    /// How far ahead of the origin a turn in place turns about, m.
    pub turn_centre_x_m: f64,
}

/// A turn in place reaches its rate (or stops) in this long, s.
pub const TURN_RATE_RAMP_S: f64 = 0.25;

impl MotionLimits {
    /// The limits of a configured vehicle.
    pub fn from_vehicle(vehicle: &VehicleConfig) -> Self {
        Self {
            max_speed_mps: vehicle.max_speed_mps,
            max_acceleration_mps2: vehicle.max_acceleration_mps2,
            max_deceleration_mps2: vehicle.max_deceleration_mps2,
            max_curvature: vehicle.max_curvature(),
            max_curvature_rate: vehicle.max_curvature_rate,
            latency_us: seconds_to_micros(vehicle.command_latency_s),
            max_turn_rate: vehicle.turn_in_place_rate(),
            turn_centre_x_m: vehicle.turn_centre().x,
        }
    }

    /// How long a turn in place goes on once told to stop, s: the
    /// command's latency at its rate, then the rate's ramp down (half of
    /// [`TURN_RATE_RAMP_S`] at that rate). Times the rate, the angle.
    pub fn turn_stop_s(&self) -> f64 {
        micros_to_seconds(self.latency_us) + 0.5 * TURN_RATE_RAMP_S
    }

    /// An ideal vehicle: commands act at once and in full.
    pub fn unlimited() -> Self {
        Self {
            max_speed_mps: f64::INFINITY,
            max_acceleration_mps2: f64::INFINITY,
            max_deceleration_mps2: f64::INFINITY,
            max_curvature: f64::INFINITY,
            max_curvature_rate: f64::INFINITY,
            latency_us: 0,
            max_turn_rate: f64::INFINITY,
            turn_centre_x_m: 0.0,
        }
    }
}

/// The vehicle's response to commands over time.
#[derive(Debug, Clone)]
pub struct MotionModel {
    limits: MotionLimits,
    state: PlanarState,
    utime: Utime,
    target_curvature: f64,
    target_speed_mps: f64,
    /// Turning in place: the yaw rate asked for, rad/s (0: not turning).
    target_turn_rate: f64,
    /// The yaw rate of the turn in place under way, rad/s.
    turn_rate: f64,
    /// Commands not yet acting, with the time they take effect.
    pending: VecDeque<(Utime, SteeringCommand)>,
    /// Signed distance driven (backing up counts down), m.
    odometer_m: f64,
}

impl MotionModel {
    /// A vehicle in `state` at time `utime`, holding its current speed and
    /// curvature until commanded otherwise.
    pub fn new(limits: MotionLimits, state: PlanarState, utime: Utime) -> Self {
        Self {
            limits,
            state,
            utime,
            target_curvature: state.curvature,
            target_speed_mps: state.speed_mps,
            target_turn_rate: 0.0,
            turn_rate: 0.0,
            pending: VecDeque::new(),
            odometer_m: 0.0,
        }
    }

    pub fn state(&self) -> &PlanarState {
        &self.state
    }

    pub fn utime(&self) -> Utime {
        self.utime
    }

    pub fn limits(&self) -> &MotionLimits {
        &self.limits
    }

    /// Signed distance driven since the model began: forwards counts up,
    /// backing up counts down, m.
    pub fn odometer_m(&self) -> f64 {
        self.odometer_m
    }

    /// Hands a command to the vehicle; it takes effect `latency` after its
    /// `utime` (or after the vehicle's current time, if that is later).
    pub fn command(&mut self, command: SteeringCommand) {
        let effective = command
            .utime
            .max(self.utime)
            .saturating_add(self.limits.latency_us);
        // Keep the queue ordered by effective time.
        let at = self.pending.partition_point(|(t, _)| *t <= effective);
        self.pending.insert(at, (effective, command));
    }

    /// Drives until `utime` and returns the new state. A time in the past
    /// leaves the state as it is.
    pub fn advance_to(&mut self, utime: Utime) -> PlanarState {
        while self.utime < utime {
            // Apply every command due now.
            while let Some(&(due, command)) = self.pending.front() {
                if due > self.utime {
                    break;
                }
                self.pending.pop_front();
                if command.is_turn_in_place() {
                    // Brake to a stand, then turn: the wheels' curvature
                    // is left as it is.
                    self.target_speed_mps = 0.0;
                    self.target_turn_rate =
                        clamp_abs(command.turn_rate_radps, self.limits.max_turn_rate);
                    continue;
                }
                self.target_turn_rate = 0.0;
                self.target_curvature = command.curvature;
                self.target_speed_mps = if command.is_stop() {
                    0.0
                } else {
                    command.speed_mps
                };
            }
            let mut end = self.utime.saturating_add(MAX_SUBSTEP_US).min(utime);
            if let Some(&(due, _)) = self.pending.front() {
                end = end.min(due);
            }
            self.step(end);
        }
        self.state
    }

    /// The yaw rate of a turn in place under way, rad/s (0 otherwise).
    pub fn turn_rate(&self) -> f64 {
        self.turn_rate
    }

    /// One sub-step to `end`: controls move towards their targets within the
    /// limits; the pose follows the arc of the mean curvature at mean speed.
    /// A turn in place starts once the vehicle stands, and turns it about
    /// the turn centre.
    fn step(&mut self, end: Utime) {
        let dt = micros_to_seconds(end - self.utime);
        let standing = self.state.speed_mps == 0.0;
        if self.turn_rate != 0.0 || (standing && self.target_turn_rate != 0.0) {
            let target = if standing { self.target_turn_rate } else { 0.0 };
            let rate = self.limits.max_turn_rate / TURN_RATE_RAMP_S;
            let (w1, w_mean) = ramp(self.turn_rate, target, rate, dt);
            let turn = w_mean * dt;
            let c = self.limits.turn_centre_x_m;
            let (x, y, yaw) = (self.state.x, self.state.y, self.state.yaw);
            // The origin swings about the centre, c ahead of it.
            let (cx, cy) = (x + c * yaw.cos(), y + c * yaw.sin());
            let after = yaw + turn;
            self.state = PlanarState {
                x: cx - c * after.cos(),
                y: cy - c * after.sin(),
                yaw: wrap_angle(after),
                ..self.state
            };
            self.turn_rate = w1;
            self.utime = end;
            return;
        }
        let limits = &self.limits;
        let k_target = clamp_abs(self.target_curvature, limits.max_curvature);
        let v_target = clamp_abs(self.target_speed_mps, limits.max_speed_mps);
        let k0 = self.state.curvature;
        let (k1, k_mean) = curvature_ramp(k0, k_target, limits, dt);
        let (v1, v_mean) = speed_ramp(self.state.speed_mps, v_target, limits, dt);
        let distance = v_mean * dt;
        self.odometer_m += distance;
        let k = k_mean;
        let (x, y, yaw) = (self.state.x, self.state.y, self.state.yaw);
        let dyaw = k * distance;
        let (dx, dy) = if dyaw.abs() < 1e-9 {
            let mid = yaw + 0.5 * dyaw;
            (distance * mid.cos(), distance * mid.sin())
        } else {
            (
                ((yaw + dyaw).sin() - yaw.sin()) / k,
                (yaw.cos() - (yaw + dyaw).cos()) / k,
            )
        };
        self.state = PlanarState {
            x: x + dx,
            y: y + dy,
            yaw: wrap_angle(yaw + dyaw),
            speed_mps: v1,
            curvature: k1,
        };
        self.utime = end;
    }
}

/// The speed moving from `v0` towards `target` for `dt` seconds within the
/// acceleration limits (speeding up at `max_acceleration_mps2`, slowing at
/// `max_deceleration_mps2`; from forwards to backwards it brakes to a stand
/// first): its final value and its mean over the interval.
pub fn speed_ramp(v0: f64, target: f64, limits: &MotionLimits, dt: f64) -> (f64, f64) {
    let target = if v0 * target < 0.0 { 0.0 } else { target };
    let rate = if target.abs() > v0.abs() {
        limits.max_acceleration_mps2
    } else {
        limits.max_deceleration_mps2
    };
    ramp(v0, target, rate, dt)
}

/// The curvature moving from `k0` towards `target` for `dt` seconds at the
/// steering's rate (moving or standing): its final value and its mean over
/// the interval.
pub fn curvature_ramp(k0: f64, target: f64, limits: &MotionLimits, dt: f64) -> (f64, f64) {
    ramp(k0, target, limits.max_curvature_rate, dt)
}

fn clamp_abs(value: f64, limit: f64) -> f64 {
    value.clamp(-limit, limit)
}

/// A value moving from `from` towards `to` at `rate` per second for `dt`
/// seconds: its final value and its mean over the interval (an infinite rate
/// jumps to `to` at once).
fn ramp(from: f64, to: f64, rate: f64, dt: f64) -> (f64, f64) {
    let gap = to - from;
    if dt <= 0.0 {
        return (from, from);
    }
    let time_to_reach = gap.abs() / rate;
    if time_to_reach >= dt {
        let end = from + (rate * dt).copysign(gap);
        (end, 0.5 * (from + end))
    } else {
        // Ramp for time_to_reach, then hold `to`.
        let mean = (0.5 * (from + to) * time_to_reach + to * (dt - time_to_reach)) / dt;
        (to, mean)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Point2;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn drive(curvature: f64, speed_mps: f64) -> SteeringCommand {
        SteeringCommand {
            utime: 0,
            curvature,
            speed_mps,
            arc_index: Some(0),
            vote: 1.0,
            turn_rate_radps: 0.0,
        }
    }

    #[test]
    fn with_no_limits_it_follows_an_arc_exactly() {
        let mut model = MotionModel::new(MotionLimits::unlimited(), PlanarState::default(), 0);
        model.command(drive(1.0 / 8.0, 2.0));
        // A quarter circle of radius 8 m at 2 m/s takes 2π s.
        let quarter_us = seconds_to_micros(8.0 * FRAC_PI_2 / 2.0);
        let s = model.advance_to(quarter_us);
        assert_relative_eq!(s.x, 8.0, epsilon = 1e-5);
        assert_relative_eq!(s.y, 8.0, epsilon = 1e-5);
        assert_relative_eq!(s.yaw, FRAC_PI_2, epsilon = 1e-6);
        // Half a circle to the right from a start heading west.
        let start = PlanarState {
            yaw: PI,
            ..Default::default()
        };
        let mut model = MotionModel::new(MotionLimits::unlimited(), start, 0);
        model.command(drive(-0.25, 1.0));
        let s = model.advance_to(seconds_to_micros(4.0 * PI));
        assert_relative_eq!(s.x, 0.0, epsilon = 1e-5);
        assert_relative_eq!(s.y, 8.0, epsilon = 1e-5);
    }

    #[test]
    fn steering_rate_limit_delays_the_curvature_change() {
        let limits = MotionLimits {
            max_curvature_rate: 0.1,
            ..MotionLimits::unlimited()
        };
        let mut model = MotionModel::new(limits, PlanarState::default(), 0);
        model.command(drive(0.1, 1.0));
        assert_relative_eq!(model.advance_to(500_000).curvature, 0.05, epsilon = 1e-12);
        assert_relative_eq!(model.advance_to(999_000).curvature, 0.0999, epsilon = 1e-12);
        assert_eq!(model.advance_to(1_000_000).curvature, 0.1);
        assert_eq!(model.advance_to(3_000_000).curvature, 0.1);
    }

    #[test]
    fn latency_delays_the_command() {
        let limits = MotionLimits {
            latency_us: 300_000,
            ..MotionLimits::unlimited()
        };
        let mut model = MotionModel::new(limits, PlanarState::default(), 0);
        model.command(drive(0.1, 2.0));
        let before = model.advance_to(299_999);
        assert_eq!(
            (before.curvature, before.speed_mps, before.x),
            (0.0, 0.0, 0.0)
        );
        let after = model.advance_to(300_001);
        assert_eq!((after.curvature, after.speed_mps), (0.1, 2.0));
        let later = model.advance_to(1_300_000);
        assert_relative_eq!(later.yaw, 0.2, epsilon = 1e-9, max_relative = 1e-9);
    }

    #[test]
    fn acceleration_and_braking_are_limited_and_stop_means_zero_speed() {
        let limits = MotionLimits {
            max_acceleration_mps2: 1.0,
            max_deceleration_mps2: 2.0,
            ..MotionLimits::unlimited()
        };
        let mut model = MotionModel::new(limits, PlanarState::default(), 0);
        model.command(drive(0.0, 3.0));
        assert_relative_eq!(model.advance_to(1_000_000).speed_mps, 1.0, epsilon = 1e-12);
        assert_relative_eq!(model.state().x, 0.5, epsilon = 1e-9);
        assert_eq!(model.advance_to(5_000_000).speed_mps, 3.0);
        model.command(SteeringCommand::stop(5_000_000));
        assert_relative_eq!(model.advance_to(5_500_000).speed_mps, 2.0, epsilon = 1e-12);
        assert_eq!(model.advance_to(7_000_000).speed_mps, 0.0);
    }

    #[test]
    fn a_negative_speed_backs_along_the_arc_after_braking_to_a_stand() {
        let limits = MotionLimits {
            max_acceleration_mps2: 1.0,
            max_deceleration_mps2: 2.0,
            ..MotionLimits::unlimited()
        };
        let mut model = MotionModel::new(limits, PlanarState::default(), 0);
        model.command(drive(0.0, 2.0));
        model.advance_to(2_000_000);
        let x_forward = model.state().x;
        // Asked to back up while rolling forwards at 2 m/s, it first brakes
        // to a stand (1 s at 2 m/s², 1 m) ...
        model.command(SteeringCommand {
            utime: 2_000_000,
            ..drive(0.0, -1.0)
        });
        let braked = model.advance_to(3_000_000);
        assert_relative_eq!(braked.speed_mps, 0.0, epsilon = 1e-9);
        assert_relative_eq!(braked.x, x_forward + 1.0, epsilon = 1e-6);
        // ... then backs up. With the wheels turned left the rear axle moves
        // to -x and +y and the nose swings right (yaw falls).
        model.command(SteeringCommand {
            utime: 3_000_000,
            ..drive(0.125, -1.0)
        });
        let s = model.advance_to(3_000_000 + seconds_to_micros(1.0 + 8.0 * FRAC_PI_2));
        assert_relative_eq!(s.speed_mps, -1.0, epsilon = 1e-9);
        // 0.5 m while reaching 1 m/s, then a quarter circle of radius 8 m.
        let turned = (0.5 + 8.0 * FRAC_PI_2) / 8.0;
        assert_relative_eq!(s.yaw, -turned, epsilon = 1e-6);
        assert_relative_eq!(s.x, braked.x - 8.0 * turned.sin(), epsilon = 1e-5);
        assert_relative_eq!(s.y, 8.0 * (1.0 - turned.cos()), epsilon = 1e-5);
    }

    #[test]
    fn curvature_and_speed_are_clamped_to_the_vehicle() {
        let vehicle = VehicleConfig::default();
        let limits = MotionLimits {
            latency_us: 0,
            max_curvature_rate: f64::INFINITY,
            max_acceleration_mps2: f64::INFINITY,
            ..MotionLimits::from_vehicle(&vehicle)
        };
        let mut model = MotionModel::new(limits, PlanarState::default(), 0);
        model.command(drive(1.0, 100.0));
        let s = model.advance_to(10_000);
        assert_relative_eq!(s.curvature, 1.0 / 7.5);
        assert_eq!(s.speed_mps, vehicle.max_speed_mps);
    }

    #[test]
    fn commands_apply_in_order_of_effect() {
        let mut model = MotionModel::new(MotionLimits::unlimited(), PlanarState::default(), 0);
        model.command(SteeringCommand {
            utime: 200_000,
            ..drive(0.05, 1.0)
        });
        model.command(SteeringCommand {
            utime: 100_000,
            ..drive(-0.05, 1.0)
        });
        assert_eq!(model.advance_to(150_000).curvature, -0.05);
        assert_eq!(model.advance_to(250_000).curvature, 0.05);
    }

    fn skid_steer() -> VehicleConfig {
        VehicleConfig {
            kinematics: crate::model::Kinematics::SkidSteer,
            max_yaw_rate_dps: Some(90.0),
            wheelbase_m: 1.0,
            ..VehicleConfig::default()
        }
    }

    #[test]
    fn a_skid_steer_vehicle_brakes_then_turns_in_place_about_the_middle_of_its_wheelbase() {
        let vehicle = skid_steer();
        let limits = MotionLimits::from_vehicle(&vehicle);
        let moving = PlanarState {
            speed_mps: 1.5,
            ..PlanarState::default()
        };
        let mut model = MotionModel::new(limits, moving, 0);
        model.command(SteeringCommand::turn_in_place(0, FRAC_PI_2, 0, 1.0));
        // Latency 0.25 s, braking 1.5 m/s at 3 m/s² 0.5 s, then the turn:
        // by 2.2 s, 1.45 s of it less half its 0.25 s ramp at π/2 rad/s.
        let braked = model.advance_to(760_000);
        assert!(
            braked.speed_mps == 0.0 && braked.yaw.abs() < 0.01,
            "{braked:?}"
        );
        let stopped_at = Point2::new(braked.x, braked.y);
        let s = model.advance_to(2_200_000);
        assert_relative_eq!(model.turn_rate(), FRAC_PI_2);
        // The centre of the turn, half the wheelbase ahead of the origin,
        // stays where it was; the origin swings round it.
        let centre =
            |s: &PlanarState| Point2::new(s.x + 0.5 * s.yaw.cos(), s.y + 0.5 * s.yaw.sin());
        assert!((centre(&s) - centre(&braked)).norm() < 1e-9);
        let expected = (1.45 - 0.125) * FRAC_PI_2;
        assert!((s.yaw - expected).abs() < 0.02, "turned {} rad", s.yaw);
        assert!((Point2::new(s.x, s.y) - stopped_at).norm() < 1.0);
        assert_eq!(s.speed_mps, 0.0);
        // A drive command ends the turn (its rate ramps down) and drives on.
        model.command(SteeringCommand {
            utime: 2_200_000,
            ..drive(0.0, 1.0)
        });
        let after = model.advance_to(4_000_000);
        assert_eq!(model.turn_rate(), 0.0);
        assert!(after.speed_mps > 0.5);
    }

    #[test]
    fn an_ackermann_vehicle_asked_to_turn_in_place_stops() {
        let mut model = MotionModel::new(
            MotionLimits::from_vehicle(&VehicleConfig::default()),
            PlanarState {
                speed_mps: 2.0,
                ..PlanarState::default()
            },
            0,
        );
        model.command(SteeringCommand::turn_in_place(0, 1.0, 0, 1.0));
        let s = model.advance_to(3_000_000);
        assert_eq!((s.speed_mps, s.yaw), (0.0, 0.0));
    }
}
