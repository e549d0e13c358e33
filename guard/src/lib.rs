//! A guard that stops or slows the vehicle whatever the pipeline decides.
//!
//! Everything else that keeps the vehicle off an obstacle goes through one
//! chain: perception → local map → obstacle avoidance → arbiter. The guard
//! is a second, simple code path beside it (it shares only the range-image
//! and pose types): from each range image or slice and the pose, the
//! returns that stand above the ground or lie far below it
//! ([`returns`]), remembered for `memory_s`, are tested against zones
//! around the commanded path ([`zones`]); tilt and missing data stop the
//! vehicle too. Nav2's collision monitor is the model (stop and slow
//! polygons, an approach mode, `block_if_invalid`); the zones here follow
//! the command's arc and the vehicle's braking instead of fixed polygons.
//!
//! [`Guard::check`] gives the verdict on a command; [`Verdict::apply`] the
//! command the vehicle is sent.

pub mod config;
pub mod returns;
pub mod zones;

use std::collections::VecDeque;

use arcnav_perception::{RangeImage, RangeSlice, SensorModel};
use arcnav_vehicle::command::SteeringCommand;
use arcnav_vehicle::frames::{Pose, level_frame};
use arcnav_vehicle::model::VehicleConfig;
use arcnav_vehicle::time::Utime;
use nalgebra::Point2;

pub use config::GuardConfig;
pub use returns::{Hazard, HazardKind};
use returns::{Profile, Returns};
use zones::{Braking, nearest_contact};

/// Why the guard stopped or slowed the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub enum Reason {
    /// Hazardous returns on the commanded path: the nearest at `distance_m`
    /// along it, at `at` (world frame).
    Hazard {
        kind: HazardKind,
        at: [f64; 2],
        distance_m: f64,
    },
    /// Measured roll or pitch beyond the limit, degrees.
    Tilt { roll_deg: f64, pitch_deg: f64 },
    /// A sensor has sent nothing for `age_s` (or nothing yet: `None`).
    NoImage { sensor: String, age_s: Option<f64> },
    /// The pose is `age_s` old (or there is none yet: `None`).
    StalePose { age_s: Option<f64> },
}

impl Reason {
    /// A short name for counts and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Hazard { kind, .. } => kind.name(),
            Self::Tilt { .. } => "tilt",
            Self::NoImage { .. } => "no image",
            Self::StalePose { .. } => "stale pose",
        }
    }
}

impl std::fmt::Display for Reason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Hazard {
                kind,
                at,
                distance_m,
            } => write!(
                f,
                "{} {distance_m:.1} m along the path, at ({:.1}, {:.1})",
                kind.name(),
                at[0],
                at[1]
            ),
            Self::Tilt {
                roll_deg,
                pitch_deg,
            } => write!(f, "tilt: roll {roll_deg:.1}°, pitch {pitch_deg:.1}°"),
            Self::NoImage { sensor, age_s } => match age_s {
                Some(age) => write!(f, "no image from {sensor} for {age:.2} s"),
                None => write!(f, "no image from {sensor} yet"),
            },
            Self::StalePose { age_s } => match age_s {
                Some(age) => write!(f, "pose {age:.2} s old"),
                None => write!(f, "no pose yet"),
            },
        }
    }
}

/// The guard's verdict on one command.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The command goes as it is.
    Clear,
    /// Its speed is capped to `cap_mps`.
    Slow { cap_mps: f64, reason: Reason },
    /// The vehicle stops.
    Stop { reason: Reason },
}

impl Verdict {
    /// The command the vehicle is sent.
    pub fn apply(&self, command: &SteeringCommand) -> SteeringCommand {
        match self {
            Self::Clear => *command,
            Self::Slow { cap_mps, .. } => SteeringCommand {
                speed_mps: command.speed_mps.clamp(-cap_mps, *cap_mps),
                ..*command
            },
            Self::Stop { .. } => SteeringCommand {
                speed_mps: 0.0,
                arc_index: None,
                ..*command
            },
        }
    }

    /// Its reason, if it is not clear.
    pub fn reason(&self) -> Option<&Reason> {
        match self {
            Self::Clear => None,
            Self::Slow { reason, .. } | Self::Stop { reason } => Some(reason),
        }
    }
}

/// What the guard took in and remembered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GuardCounts {
    pub images: u64,
    pub slices: u64,
    /// Images and slices of a sensor the guard was not given.
    pub unknown_sensor: u64,
    /// Images and slices that came before any pose (not tested: nothing
    /// places them).
    pub before_pose: u64,
    /// Images and slices whose shape does not match their beams.
    pub malformed: u64,
    pub returns: u64,
    pub standing: u64,
    pub holes: u64,
    /// Hazardous returns forgotten because `max_points` were held.
    pub forgotten: u64,
}

struct Remembered {
    hazard: Hazard,
    utime: Utime,
}

/// The guard: see the crate documentation.
pub struct Guard {
    config: GuardConfig,
    profile: Profile,
    braking: Braking,
    footprint: arcnav_vehicle::model::Footprint,
    max_tilt_rad: f64,
    /// Each sensor's id, period and last image or slice.
    sensors: Vec<(String, Utime, Option<Utime>)>,
    pose: Option<Pose>,
    hazards: VecDeque<Remembered>,
    scratch: Vec<Hazard>,
    counts: GuardCounts,
}

impl Guard {
    /// A guard for `vehicle` with `sensors`, configured by `config`
    /// (validated by the caller).
    pub fn new(config: &GuardConfig, vehicle: &VehicleConfig, sensors: &[SensorModel]) -> Self {
        Self {
            profile: Profile {
                step_m: vehicle.tolerated_step_m,
                max_rise_per_m: vehicle.max_slope_rad().tan(),
                range_m: config.range_m,
                noise_m: config.ground_noise_m,
            },
            braking: Braking::of(vehicle, config.margin_m),
            footprint: vehicle.footprint().widened(config.side_margin_m),
            max_tilt_rad: (vehicle.max_slope_deg - config.tilt_margin_deg)
                .max(0.0)
                .to_radians(),
            sensors: sensors
                .iter()
                .map(|s| (s.id.clone(), s.period_us(), None))
                .collect(),
            config: config.clone(),
            pose: None,
            hazards: VecDeque::new(),
            scratch: Vec::new(),
            counts: GuardCounts::default(),
        }
    }

    pub fn config(&self) -> &GuardConfig {
        &self.config
    }

    pub fn counts(&self) -> GuardCounts {
        self.counts
    }

    /// The hazardous returns remembered now.
    pub fn hazards(&self) -> impl Iterator<Item = &Hazard> {
        self.hazards.iter().map(|r| &r.hazard)
    }

    /// The latest pose.
    pub fn observe_pose(&mut self, pose: &Pose) {
        if self.pose.is_none_or(|p| pose.utime >= p.utime) {
            self.pose = Some(*pose);
        }
    }

    /// A whole range image, placed with the latest pose.
    pub fn observe_image(&mut self, image: &RangeImage) {
        self.counts.images += 1;
        self.observe(
            &image.sensor,
            image.utime,
            &image.beams,
            &image.range,
            &image.vehicle_from_sensor,
        );
    }

    /// A slice of an image, placed with the latest pose.
    pub fn observe_slice(&mut self, slice: &RangeSlice) {
        self.counts.slices += 1;
        self.observe(
            &slice.sensor,
            slice.utime,
            &slice.beams,
            &slice.range,
            &slice.vehicle_from_sensor,
        );
    }

    fn observe(
        &mut self,
        sensor: &str,
        utime: Utime,
        beams: &arcnav_perception::BeamTable,
        range: &[f32],
        vehicle_from_sensor: &arcnav_vehicle::frames::Isometry,
    ) {
        let Some(entry) = self.sensors.iter_mut().find(|(id, ..)| id == sensor) else {
            self.counts.unknown_sensor += 1;
            return;
        };
        entry.2 = Some(entry.2.map_or(utime, |t| t.max(utime)));
        let Some(pose) = self.pose else {
            self.counts.before_pose += 1;
            return;
        };
        if beams.rows() * beams.cols() != range.len() {
            self.counts.malformed += 1;
            return;
        }
        self.scratch.clear();
        let found = self.profile.hazards(
            &Returns {
                beams,
                range,
                vehicle_from_sensor,
                world_from_vehicle: &pose.world_from_vehicle,
            },
            &mut self.scratch,
        );
        self.counts.returns += found.returns;
        self.counts.standing += found.standing;
        self.counts.holes += found.holes;
        for hazard in self.scratch.drain(..) {
            if self.hazards.len() >= self.config.max_points {
                self.hazards.pop_front();
                self.counts.forgotten += 1;
            }
            self.hazards.push_back(Remembered { hazard, utime });
        }
    }

    /// The verdict on `command` at `now`.
    pub fn check(&mut self, command: &SteeringCommand, now: Utime) -> Verdict {
        let memory = (self.config.memory_s * 1e6) as Utime;
        while self.hazards.front().is_some_and(|r| now - r.utime > memory) {
            self.hazards.pop_front();
        }
        let age = |t: Utime| (now - t) as f64 * 1e-6;
        let Some(pose) = self.pose else {
            return Verdict::Stop {
                reason: Reason::StalePose { age_s: None },
            };
        };
        if age(pose.utime) > self.config.pose_timeout_s {
            return Verdict::Stop {
                reason: Reason::StalePose {
                    age_s: Some(age(pose.utime)),
                },
            };
        }
        for (id, period, last) in &self.sensors {
            let limit = *period as f64 * 1e-6 * self.config.image_timeout_periods;
            let silent = last.map(age);
            if silent.is_none_or(|a| a > limit) {
                return Verdict::Stop {
                    reason: Reason::NoImage {
                        sensor: id.clone(),
                        age_s: silent,
                    },
                };
            }
        }
        let (roll, pitch, _) = pose.world_from_vehicle.rotation.euler_angles();
        if roll.abs() > self.max_tilt_rad || pitch.abs() > self.max_tilt_rad {
            return Verdict::Stop {
                reason: Reason::Tilt {
                    roll_deg: roll.to_degrees(),
                    pitch_deg: pitch.to_degrees(),
                },
            };
        }
        if command.is_stop() {
            return Verdict::Clear;
        }
        let level = level_frame(&pose.world_from_vehicle);
        let to_level = level.inverse();
        let local = |h: &Hazard| {
            let p = to_level * h.position;
            Point2::new(p.x, p.y)
        };
        let Some((s, k)) = nearest_contact(
            self.footprint,
            command.curvature,
            command.is_reverse(),
            self.braking.reach_m(),
            self.config.min_points,
            self.hazards.iter().map(|r| local(&r.hazard)),
        ) else {
            return Verdict::Clear;
        };
        let hazard = &self.hazards[k].hazard;
        let reason = Reason::Hazard {
            kind: hazard.kind,
            at: [hazard.position.x, hazard.position.y],
            distance_m: s,
        };
        let speed = pose.velocity.xy().norm();
        if s - self.braking.margin_m <= self.braking.stopping_m(speed) {
            return Verdict::Stop { reason };
        }
        let cap = self.braking.allowed_mps(s);
        if cap < command.speed_mps.abs() {
            Verdict::Slow {
                cap_mps: cap,
                reason,
            }
        } else {
            Verdict::Clear
        }
    }
}
