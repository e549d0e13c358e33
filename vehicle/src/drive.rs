//! The path the vehicle actually drives when commanded onto an arc (020
//! item 2).
//!
//! A command does not put the vehicle on its arc at once. For
//! `command_latency_s` it goes on steering towards the command already on
//! its way; then its curvature moves towards the new one at
//! `max_curvature_rate` per second, so over the ground at `dk/ds = rate / v`;
//! only then does it drive the arc. With `v` the speed, `τ` the latency,
//! `ρ` the rate, `k₀` the curvature now, `k_c` the command in flight and
//! `k` the arc's:
//!
//! ```text
//! κ(s) = ramp from k₀ towards k_c at ρ/v      for 0 ≤ s < v·τ
//!        ramp from κ(v·τ) towards k at ρ/v      until it reaches k
//!        k                                      after
//! ```
//!
//! Nav2's DWB limits its trajectories to what the vehicle can reach for
//! the same reason; at 10 m/s a turn from straight to the tightest arc
//! (8 m) takes 8.3 m, and the turn is felt as if it began 4.2 m + 2.5 m
//! later than the arc. Standing still (`v = 0`) the path is the arc.
//!
//! Poses are integrated as [`crate::MotionModel`] integrates them: short
//! arcs at the mean curvature of each step, 0.1 m or less (the model's
//! 10 ms at 10 m/s), so the path judged is the path driven.

use crate::arcs::{Arc, ArcPose};
use crate::frames::Pose;
use crate::model::VehicleConfig;

/// Longest integration step along a curvature ramp, m.
const RAMP_STEP_M: f64 = 0.1;

/// How the vehicle is steering when a command is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Steering {
    /// Speed, m/s (its magnitude: the path is driven forwards).
    pub speed_mps: f64,
    /// Curvature driven now, 1/m.
    pub curvature: f64,
    /// Curvature of the command already on its way, 1/m: the vehicle
    /// steers towards it until a new command takes effect.
    pub commanded_curvature: f64,
}

impl Steering {
    /// How the vehicle at `pose` steers, its last command's curvature
    /// `commanded` (if any) on its way: its speed forwards (0 backing up),
    /// the curvature it drives (yaw rate over speed when it moves faster
    /// than 0.5 m/s; the command's otherwise) and the command on its way.
    pub fn of(pose: &Pose, commanded: Option<f64>) -> Self {
        let (sin, cos) = pose.yaw().sin_cos();
        let forwards = (pose.velocity.x * cos + pose.velocity.y * sin).max(0.0);
        let curvature = if forwards > 0.5 {
            pose.yaw_rate / forwards
        } else {
            commanded.unwrap_or(0.0)
        };
        Self {
            speed_mps: forwards,
            curvature,
            commanded_curvature: commanded.unwrap_or(curvature),
        }
    }
}

/// How the vehicle's steering answers a command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringResponse {
    /// Command to effect, s.
    pub latency_s: f64,
    /// Curvature change per second, 1/(m·s).
    pub curvature_rate: f64,
    /// Largest curvature it steers, 1/m.
    pub max_curvature: f64,
}

impl SteeringResponse {
    /// The response of a configured vehicle.
    pub fn of(vehicle: &VehicleConfig) -> Self {
        Self {
            latency_s: vehicle.command_latency_s,
            curvature_rate: vehicle.max_curvature_rate,
            max_curvature: vehicle.max_curvature(),
        }
    }

    /// A vehicle that takes every arc at once: paths are arcs.
    pub fn immediate() -> Self {
        Self {
            latency_s: 0.0,
            curvature_rate: f64::INFINITY,
            max_curvature: f64::INFINITY,
        }
    }
}

/// The path driven after a command onto one arc, in the vehicle frame of
/// the moment the command is chosen (rear axle at the origin, heading +x):
/// a curvature profile, piecewise linear in distance, that ends on the
/// arc's curvature and stays there.
/// Fixed-size, so that behaviours build paths every cycle without
/// allocating.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrivenPath {
    /// (distance, curvature) where the profile bends, `count` of them;
    /// the last holds on.
    knots: [(f64, f64); MAX_KNOTS],
    /// The pose at each knot.
    poses: [ArcPose; MAX_KNOTS],
    count: usize,
}

/// Knots of a profile: the start, the command in flight reached, the
/// latency's end, the arc reached.
const MAX_KNOTS: usize = 4;

const ORIGIN: ArcPose = ArcPose {
    position: nalgebra::Point2::new(0.0, 0.0),
    heading: 0.0,
};

impl DrivenPath {
    /// The path driven from `steering` after commanding curvature `target`.
    pub fn new(steering: &Steering, response: &SteeringResponse, target: f64) -> Self {
        let limit = response.max_curvature;
        let clamp = |k: f64| {
            if limit.is_finite() {
                k.clamp(-limit, limit)
            } else {
                k
            }
        };
        let v = steering.speed_mps.abs();
        let per_m = if v > 0.0 {
            response.curvature_rate / v
        } else {
            f64::INFINITY
        };
        // A turn in place (±∞) is not steered towards: its path is its arc,
        // which drives nowhere.
        let target = if target.is_infinite() {
            target
        } else {
            clamp(target)
        };
        if v == 0.0 || per_m.is_infinite() || target.is_infinite() {
            // Standing, or steering at once: the arc.
            return Self {
                knots: [(0.0, target); MAX_KNOTS],
                poses: [ORIGIN; MAX_KNOTS],
                count: 1,
            };
        }
        let mut knots = [(0.0, clamp(steering.curvature)); MAX_KNOTS];
        let mut count = 1;
        // Distance to move the curvature from `from` to `to`.
        let ramp = |from: f64, to: f64| (to - from).abs() / per_m;
        // A knot further on, or a new curvature at the same distance.
        let push = |knots: &mut [(f64, f64); MAX_KNOTS], count: &mut usize, s: f64, k: f64| {
            if s > knots[*count - 1].0 && *count < MAX_KNOTS {
                knots[*count] = (s, k);
                *count += 1;
            } else {
                knots[*count - 1].1 = k;
            }
        };
        // The latency: steering on towards the command in flight.
        let latency_m = v * response.latency_s;
        let (_, k0) = knots[0];
        let in_flight = clamp(steering.commanded_curvature);
        let reach = ramp(k0, in_flight);
        let k_effect = if reach <= latency_m {
            push(&mut knots, &mut count, reach, in_flight);
            in_flight
        } else {
            k0 + (in_flight - k0).signum() * latency_m * per_m
        };
        push(&mut knots, &mut count, latency_m, k_effect);
        // Then towards the new command.
        let start = knots[count - 1].0;
        push(
            &mut knots,
            &mut count,
            start + ramp(k_effect, target),
            target,
        );
        let mut path = Self {
            knots,
            poses: [ORIGIN; MAX_KNOTS],
            count,
        };
        for i in 1..count {
            path.poses[i] = path.advance(i - 1, path.poses[i - 1], knots[i].0 - knots[i - 1].0);
        }
        path
    }

    /// The arc itself, taken at once.
    pub fn arc(curvature: f64) -> Self {
        Self::new(
            &Steering {
                curvature,
                commanded_curvature: curvature,
                ..Default::default()
            },
            &SteeringResponse::immediate(),
            curvature,
        )
    }

    /// True when the path is its arc from the start (standing, or a
    /// vehicle that takes arcs at once).
    pub fn is_arc(&self) -> bool {
        self.count == 1
    }

    /// Where the curvature reaches the arc's: from here on the path is
    /// the arc, m.
    pub fn settled_at(&self) -> f64 {
        self.knots[self.count - 1].0
    }

    /// The pose at [`DrivenPath::settled_at`].
    pub fn settled_pose(&self) -> ArcPose {
        self.poses[self.count - 1]
    }

    /// Curvature at `s`, 1/m.
    pub fn curvature_at(&self, s: f64) -> f64 {
        let i = self.segment(s);
        self.profile(i, s - self.knots[i].0)
    }

    /// The pose after `s` metres (`s` ≥ 0).
    pub fn pose_at(&self, s: f64) -> ArcPose {
        let s = s.max(0.0);
        if self.count == 1 {
            return Arc::new(self.knots[0].1).pose_at(s);
        }
        let i = self.segment(s);
        self.advance(i, self.poses[i], s - self.knots[i].0)
    }

    /// Poses every `step_m` from 0 to `length_m` inclusive, with their
    /// distances (as [`Arc::sample`]), integrated once along the way.
    pub fn sample(&self, length_m: f64, step_m: f64) -> Vec<(f64, ArcPose)> {
        let mut out = Vec::new();
        self.sample_into(length_m, step_m, &mut out);
        out
    }

    /// [`DrivenPath::sample`] into `out` (cleared first), allocating only
    /// when it must grow.
    pub fn sample_into(&self, length_m: f64, step_m: f64, out: &mut Vec<(f64, ArcPose)>) {
        let steps = if step_m > 0.0 && length_m > 0.0 {
            (length_m / step_m).ceil() as usize
        } else {
            0
        };
        out.clear();
        let (mut at, mut pose) = (0.0, self.poses[0]);
        for i in 0..=steps {
            let s = (i as f64 * step_m).min(length_m.max(0.0));
            // From `at` to `s`, knot by knot.
            while at < s {
                let segment = self.segment(at);
                let end = self
                    .knots()
                    .get(segment + 1)
                    .map_or(s, |&(next, _)| next.min(s));
                let end = if end > at { end } else { s };
                pose = self.advance_between(segment, pose, at, end);
                at = end;
            }
            out.push((s, pose));
        }
    }

    /// The profile's knots in use.
    fn knots(&self) -> &[(f64, f64)] {
        &self.knots[..self.count]
    }

    /// The knot segment holding distance `s`.
    fn segment(&self, s: f64) -> usize {
        self.knots()
            .partition_point(|&(start, _)| start <= s)
            .saturating_sub(1)
    }

    /// Curvature `d` metres into segment `i`.
    fn profile(&self, i: usize, d: f64) -> f64 {
        let (s0, k0) = self.knots[i];
        match self.knots().get(i + 1) {
            Some(&(s1, k1)) if s1 > s0 => k0 + (k1 - k0) * (d / (s1 - s0)).clamp(0.0, 1.0),
            _ => k0,
        }
    }

    /// The pose `d` metres into segment `i` from its start pose `from`.
    fn advance(&self, i: usize, from: ArcPose, d: f64) -> ArcPose {
        let s0 = self.knots[i].0;
        self.advance_between(i, from, s0, s0 + d)
    }

    /// The pose at `to` from the pose `from` at `at`, both in segment `i`.
    fn advance_between(&self, i: usize, from: ArcPose, at: f64, to: f64) -> ArcPose {
        let (s0, k0) = self.knots[i];
        let ramped = self.knots().get(i + 1).is_some_and(|&(_, k1)| k1 != k0);
        if !ramped {
            // On an arc: from the knot, in closed form (an arc taken at
            // once samples exactly as `Arc::sample`).
            return compose(self.poses[i], Arc::new(k0).pose_at(to - s0));
        }
        let steps = ((to - at) / RAMP_STEP_M).ceil().max(1.0) as usize;
        let h = (to - at) / steps as f64;
        let mut pose = from;
        for j in 0..steps {
            let mid = self.profile(i, at + (j as f64 + 0.5) * h - self.knots[i].0);
            pose = compose(pose, Arc::new(mid).pose_at(h));
        }
        pose
    }
}

/// `b` (given in the frame of `a`) in the frame `a` is given in.
pub fn compose(a: ArcPose, b: ArcPose) -> ArcPose {
    ArcPose {
        position: a.transform_point(b.position),
        heading: a.heading + b.heading,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::SteeringCommand;
    use crate::motion::{MotionLimits, MotionModel, PlanarState};
    use crate::time::seconds_to_micros;
    use approx::assert_relative_eq;

    #[test]
    fn standing_still_the_path_is_the_arc() {
        let response = SteeringResponse::of(&VehicleConfig::default());
        let steering = Steering {
            speed_mps: 0.0,
            curvature: -0.1,
            commanded_curvature: 0.05,
        };
        for k in [-0.125, 0.0, 0.07] {
            let path = DrivenPath::new(&steering, &response, k);
            assert!(path.is_arc());
            assert_eq!(path.settled_at(), 0.0);
            for s in [0.0, 3.0, 17.5] {
                let (a, b) = (path.pose_at(s), Arc::new(k).pose_at(s));
                assert_relative_eq!(a.position, b.position, epsilon = 1e-12);
                assert_relative_eq!(a.heading, b.heading, epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn the_turn_comes_later_the_faster_the_vehicle_goes() {
        let response = SteeringResponse::of(&VehicleConfig::default());
        let straight = |v| Steering {
            speed_mps: v,
            ..Default::default()
        };
        // 0.25 s of latency, then 0.125 1/m at 0.15 1/(m·s): 0.83 s.
        let path = DrivenPath::new(&straight(10.0), &response, 0.125);
        assert!(!path.is_arc());
        assert_relative_eq!(path.settled_at(), 2.5 + 10.0 * 0.125 / 0.15, epsilon = 1e-9);
        assert_relative_eq!(path.curvature_at(2.5), 0.0);
        assert_relative_eq!(path.curvature_at(2.5 + 8.333 / 2.0), 0.0625, epsilon = 1e-3);
        assert_relative_eq!(path.curvature_at(50.0), 0.125);
        // Past the transition the heading lags the arc's by half of it:
        // the turn felt as if it began (2.5 + 8.33 / 2) m later.
        let lag = 0.125 * (2.5 + 8.333 / 2.0);
        assert_relative_eq!(
            path.pose_at(20.0).heading,
            0.125 * 20.0 - lag,
            epsilon = 1e-3
        );
        // Slower, sooner.
        let slow = DrivenPath::new(&straight(2.0), &response, 0.125);
        assert!(slow.settled_at() < 2.5);
        assert!(slow.pose_at(10.0).position.y > path.pose_at(10.0).position.y + 1.0);
    }

    #[test]
    fn an_arc_taken_at_once_samples_as_the_arc() {
        let arc = Arc::new(-0.07);
        let path = DrivenPath::arc(-0.07);
        let samples = path.sample(18.0, 0.5);
        let expected: Vec<_> = arc.sample(18.0, 0.5).collect();
        assert_eq!(samples.len(), expected.len());
        for ((_, a), b) in samples.iter().zip(&expected) {
            assert_eq!(a, b);
        }
    }

    #[test]
    fn samples_are_the_poses_at_their_distances() {
        let response = SteeringResponse::of(&VehicleConfig::default());
        let steering = Steering {
            speed_mps: 9.0,
            curvature: 0.08,
            commanded_curvature: -0.03,
        };
        let path = DrivenPath::new(&steering, &response, 0.11);
        let samples = path.sample(30.0, 0.35);
        assert_eq!(samples.len(), 87);
        assert_eq!(samples.last().unwrap().0, 30.0);
        for (s, pose) in samples {
            let direct = path.pose_at(s);
            assert_relative_eq!(pose.position, direct.position, epsilon = 1e-3);
            assert_relative_eq!(pose.heading, direct.heading, epsilon = 1e-4);
        }
    }

    /// The motion model driven through the same commands: where it is
    /// every metre against where the path says.
    #[test]
    fn the_path_is_where_the_motion_model_drives() {
        let vehicle = VehicleConfig::default();
        let response = SteeringResponse::of(&vehicle);
        let limits = MotionLimits {
            max_acceleration_mps2: f64::INFINITY,
            max_deceleration_mps2: f64::INFINITY,
            ..MotionLimits::from_vehicle(&vehicle)
        };
        let command = |utime, curvature, speed_mps| SteeringCommand {
            utime,
            curvature,
            speed_mps,
            arc_index: Some(0),
            vote: 1.0,
            turn_rate_radps: 0.0,
        };
        for (v, k_now, k_flight, k_new) in [
            (8.0, 0.0, 0.0, 0.125),
            (10.0, 0.1, -0.1, 0.125),
            (5.0, -0.05, 0.02, -0.125),
            (3.0, 0.0, 0.1, 0.0),
            (6.0, 0.125, 0.125, -0.125),
        ] {
            let start = PlanarState {
                speed_mps: v,
                curvature: k_now,
                ..Default::default()
            };
            let mut model = MotionModel::new(limits, start, 0);
            // The command in flight takes effect now (it left one latency
            // ago); the new one leaves now.
            model.command(command(0, k_flight, v));
            let t0 = seconds_to_micros(response.latency_s);
            let origin = model.advance_to(t0);
            let steering = Steering {
                speed_mps: v,
                curvature: origin.curvature,
                commanded_curvature: k_flight,
            };
            let path = DrivenPath::new(&steering, &response, k_new);
            model.command(command(t0, k_new, v));
            let (sin, cos) = origin.yaw.sin_cos();
            for metre in 1..=25 {
                let s = f64::from(metre);
                let state = model.advance_to(t0 + seconds_to_micros(s / v));
                let (dx, dy) = (state.x - origin.x, state.y - origin.y);
                let local = nalgebra::Point2::new(cos * dx + sin * dy, -sin * dx + cos * dy);
                let pose = path.pose_at(s);
                assert!(
                    (local - pose.position).norm() < 0.05,
                    "v {v}, {k_now} → {k_flight} → {k_new}, at {s} m: model {local}, path {}",
                    pose.position
                );
            }
        }
    }
}
