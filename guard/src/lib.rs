//! A guard that stops or slows the vehicle whatever the pipeline decides.
//!
//! Everything else that keeps the vehicle off an obstacle goes through one
//! chain: perception → local map → obstacle avoidance → arbiter. The guard
//! is a second, simple code path beside it (it shares only the range-image
//! and pose types): from each range image or slice and the pose, the
//! returns that stand above the ground or lie far below it
//! ([`returns`]), remembered until the sensor looks at them again for
//! `memory_s` without seeing them, are tested against zones
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

use std::collections::HashMap;

use arcnav_perception::{RangeImage, RangeSlice, SensorModel};
use arcnav_vehicle::command::SteeringCommand;
use arcnav_vehicle::frames::{Pose, level_frame};
use arcnav_vehicle::model::VehicleConfig;
use arcnav_vehicle::time::Utime;
use arcnav_vehicle::{DrivenPath, Steering, SteeringResponse};
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
    /// The vehicle stops, holding `curvature`: the path it was last sent
    /// (which the guard let through), not the new command's, which may be
    /// the one that turns it into the hazard.
    Stop { reason: Reason, curvature: f64 },
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
            Self::Stop { curvature, .. } => SteeringCommand {
                speed_mps: 0.0,
                curvature: *curvature,
                arc_index: None,
                turn_rate_radps: 0.0,
                ..*command
            },
        }
    }

    /// Its reason, if it is not clear.
    pub fn reason(&self) -> Option<&Reason> {
        match self {
            Self::Clear => None,
            Self::Slow { reason, .. } | Self::Stop { reason, .. } => Some(reason),
        }
    }
}

/// What the guard took in and remembered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
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
    /// Returns walked (of the columns walked: see
    /// [`returns::Profile::column_stride`]).
    pub returns: u64,
    pub standing: u64,
    pub holes: u64,
    /// Hazardous returns forgotten because `max_cells` were held.
    pub forgotten: u64,
}

/// A cell of the ground that hazardous returns fell in.
#[derive(Debug, Clone, Copy)]
struct Cell {
    /// The latest return in it.
    hazard: Hazard,
    /// Returns in it, and when the last one came.
    count: u32,
    last: Utime,
    /// How long images that looked at it have not seen it again, µs, and
    /// when one last looked.
    missing: Utime,
    looked: Utime,
}

/// The directions an image or slice looks in, in its sensor's frame: a
/// held hazard whose direction is among them was looked at (and is
/// forgotten when looked at for `memory_s` without being seen); one
/// below the lowest beam (the blind zone round a roof sensor), beside a
/// narrow field of view or beyond `range_m` was not, and is kept.
#[derive(Debug, Clone, Copy)]
struct View {
    world_to_sensor: arcnav_vehicle::frames::Isometry,
    azimuth: [f64; 2],
    elevation: [f64; 2],
    range_m: f64,
}

impl View {
    fn of(
        beams: &arcnav_perception::BeamTable,
        world_from_sensor: arcnav_vehicle::frames::Isometry,
        range_m: f64,
    ) -> Option<Self> {
        let span = |angles: &[f32]| {
            let (lo, hi) = angles
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &a| {
                    (lo.min(f64::from(a)), hi.max(f64::from(a)))
                });
            // Half a pixel beyond the outer centres.
            let half = if angles.len() > 1 {
                (hi - lo) / (angles.len() - 1) as f64 / 2.0
            } else {
                0.0
            };
            (lo <= hi).then_some([lo - half, hi + half])
        };
        Some(Self {
            world_to_sensor: world_from_sensor.inverse(),
            azimuth: span(&beams.azimuth)?,
            elevation: span(&beams.elevation)?,
            range_m,
        })
    }

    fn sees(&self, world: &nalgebra::Point3<f64>) -> bool {
        let p = self.world_to_sensor * world;
        let horizontal = p.x.hypot(p.y);
        if horizontal > self.range_m {
            return false;
        }
        let (azimuth, elevation) = (p.y.atan2(p.x), p.z.atan2(horizontal));
        let within = |[lo, hi]: [f64; 2], a: f64| (lo..=hi).contains(&a);
        (self.azimuth[1] - self.azimuth[0] >= std::f64::consts::TAU - 1e-3
            || within(self.azimuth, azimuth))
            && within(self.elevation, elevation)
    }
}

/// The contact last found, followed as the vehicle drives on.
#[derive(Debug, Clone, Copy)]
struct Contact {
    /// For this command (its time and curvature) and these hazards.
    command: (Utime, f64),
    version: u64,
    /// Where the vehicle was (world, m), and the contact then: the
    /// distance along the path and the hazard.
    from: [f64; 2],
    found: Option<(f64, Hazard)>,
}

/// The guard: see the crate documentation.
pub struct Guard {
    config: GuardConfig,
    profile: Profile,
    braking: Braking,
    response: SteeringResponse,
    footprint: arcnav_vehicle::model::Footprint,
    /// Where a turn in place turns about (vehicle frame), and how far the
    /// vehicle turns once told to stop turning: the command's latency at
    /// its rate, then the rate's ramp down, radians per rad/s.
    turn_centre: Point2<f64>,
    turn_stop_s: f64,
    max_tilt_rad: f64,
    /// Each sensor's id, period and last image or slice.
    sensors: Vec<(String, Utime, Option<Utime>)>,
    pose: Option<Pose>,
    /// Hazardous cells by (column, row) of `cell_size_m` in the world.
    cells: HashMap<(i64, i64), Cell, foldhash::fast::RandomState>,
    /// Bumped whenever `cells` changes.
    version: u64,
    scratch: Vec<Hazard>,
    /// The last command checked, and the curvature of the one before it
    /// (on its way to the wheels while the latest takes effect).
    current: Option<SteeringCommand>,
    in_flight: f64,
    /// The curvature the last verdict sent the vehicle on.
    sent: Option<f64>,
    /// The last verdict stopped or slowed the vehicle for a hazard: the
    /// next ones hold it one cell nearer (see [`Guard::judge`]).
    held_for_hazard: bool,
    contact: Option<Contact>,
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
                max_gap_m: Profile::bridged_gap_m(vehicle.wheel_radius_m, vehicle.tolerated_step_m),
                cell_m: config.cell_size_m,
            },
            braking: Braking::of(vehicle, config.margin_m),
            response: SteeringResponse::of(vehicle),
            footprint: vehicle.footprint().widened(config.side_margin_m),
            turn_centre: vehicle.turn_centre(),
            turn_stop_s: arcnav_vehicle::MotionLimits::from_vehicle(vehicle).turn_stop_s(),
            max_tilt_rad: (vehicle.max_slope_deg - config.tilt_margin_deg)
                .max(0.0)
                .to_radians(),
            sensors: sensors
                .iter()
                .map(|s| (s.id.clone(), s.period_us(), None))
                .collect(),
            config: config.clone(),
            pose: None,
            cells: HashMap::default(),
            version: 0,
            scratch: Vec::new(),
            current: None,
            in_flight: 0.0,
            sent: None,
            held_for_hazard: false,
            contact: None,
            counts: GuardCounts::default(),
        }
    }

    pub fn config(&self) -> &GuardConfig {
        &self.config
    }

    pub fn counts(&self) -> GuardCounts {
        self.counts
    }

    /// The hazards held: the latest return of each cell that `min_points`
    /// hazardous returns fell in (cells are forgotten as images look at
    /// them again and do not see them, not by the clock).
    pub fn hazards(&self) -> impl Iterator<Item = &Hazard> {
        let min = self.config.min_points;
        self.cells
            .values()
            .filter(move |c| c.count as usize >= min)
            .map(|c| &c.hazard)
    }

    fn memory_us(&self) -> Utime {
        (self.config.memory_s * 1e6) as Utime
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
        let period = entry.1;
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
        let mut changed = false;
        let size = self.config.cell_size_m;
        for hazard in self.scratch.drain(..) {
            let key = (
                (hazard.position.x / size).floor() as i64,
                (hazard.position.y / size).floor() as i64,
            );
            let full = self.cells.len() >= self.config.max_cells;
            match self.cells.entry(key) {
                std::collections::hash_map::Entry::Occupied(mut cell) => {
                    let cell = cell.get_mut();
                    cell.hazard = hazard;
                    cell.count = cell.count.saturating_add(1);
                    cell.last = cell.last.max(utime);
                }
                std::collections::hash_map::Entry::Vacant(_) if full => {
                    self.counts.forgotten += 1;
                    continue;
                }
                std::collections::hash_map::Entry::Vacant(cell) => {
                    cell.insert(Cell {
                        hazard,
                        count: 1,
                        last: utime,
                        missing: 0,
                        looked: utime,
                    });
                }
            }
            changed = true;
        }
        changed |= self.forget(
            utime,
            View::of(
                beams,
                pose.world_from_vehicle * vehicle_from_sensor,
                self.config.range_m,
            ),
            &pose,
            period,
        );
        if changed {
            self.version += 1;
        }
    }

    /// Ages every held cell that `view` (an image or slice at `utime`)
    /// looked at without seeing it, and forgets those missing for longer
    /// than `memory_s`, and those twice `range_m` from the vehicle; true
    /// when any was forgotten. A look adds the time since the one before,
    /// at most the sensor's `period`: time in the blind zone is not time
    /// missing.
    fn forget(&mut self, utime: Utime, view: Option<View>, pose: &Pose, period: Utime) -> bool {
        let memory = self.memory_us();
        let far = 2.0 * self.config.range_m;
        let at = pose.world_from_vehicle.translation.vector;
        let before = self.cells.len();
        self.cells.retain(|_, c| {
            let p = c.hazard.position;
            if (p.x - at.x).hypot(p.y - at.y) > far {
                return false;
            }
            if c.last >= utime {
                c.missing = 0;
                c.looked = utime;
            } else if view.is_some_and(|v| v.sees(&p)) {
                c.missing += (utime - c.looked.max(c.last)).min(period);
                c.looked = utime;
            }
            c.missing <= memory
        });
        self.cells.len() != before
    }

    /// The verdict on `command` at `now`.
    pub fn check(&mut self, command: &SteeringCommand, now: Utime) -> Verdict {
        let hold = self.sent.unwrap_or(command.curvature);
        let verdict = match self.judge(command, now) {
            Ok(verdict) => verdict,
            Err(reason) => Verdict::Stop {
                reason,
                curvature: hold,
            },
        };
        self.sent = Some(match verdict {
            Verdict::Stop { curvature, .. } => curvature,
            // A turn in place leaves the wheels' curvature as it was.
            _ if command.is_turn_in_place() => hold,
            _ => command.curvature,
        });
        verdict
    }

    /// The verdict on `command` at `now`, or why it stops.
    fn judge(&mut self, command: &SteeringCommand, now: Utime) -> Result<Verdict, Reason> {
        let age = |t: Utime| (now - t) as f64 * 1e-6;
        if self
            .current
            .is_none_or(|c| c.utime != command.utime || c.curvature != command.curvature)
        {
            self.in_flight = self.current.map_or(command.curvature, |c| c.curvature);
            self.current = Some(*command);
        }
        // A stop is as safe as it gets, whatever the data.
        if command.is_stop() {
            return Ok(Verdict::Clear);
        }
        let Some(pose) = self.pose else {
            return Err(Reason::StalePose { age_s: None });
        };
        if age(pose.utime) > self.config.pose_timeout_s {
            return Err(Reason::StalePose {
                age_s: Some(age(pose.utime)),
            });
        }
        for (id, period, last) in &self.sensors {
            let limit = *period as f64 * 1e-6 * self.config.image_timeout_periods;
            let silent = last.map(age);
            if silent.is_none_or(|a| a > limit) {
                return Err(Reason::NoImage {
                    sensor: id.clone(),
                    age_s: silent,
                });
            }
        }
        let (roll, pitch, _) = pose.world_from_vehicle.rotation.euler_angles();
        if roll.abs() > self.max_tilt_rad || pitch.abs() > self.max_tilt_rad {
            return Err(Reason::Tilt {
                roll_deg: roll.to_degrees(),
                pitch_deg: pitch.to_degrees(),
            });
        }
        if command.is_turn_in_place() {
            return self.judge_turn(command, &pose);
        }
        let Some((s, hazard)) = self.contact(command, &pose) else {
            self.held_for_hazard = false;
            return Ok(Verdict::Clear);
        };
        let reason = Reason::Hazard {
            kind: hazard.kind,
            at: [hazard.position.x, hazard.position.y],
            distance_m: s,
        };
        // Hazards are held by cells of `cell_size_m`, and the distance to
        // the nearest jitters by a cell from image to image: a vehicle
        // stopped or slowed for one is let go only once it is a cell clear
        // of that (at the edge of the stop zone, the verdict went stop,
        // clear, stop with each image).
        let s = if self.held_for_hazard {
            s - self.config.cell_size_m
        } else {
            s
        };
        let speed = pose.velocity.xy().norm();
        let verdict = if s - self.braking.margin_m <= self.braking.stopping_m(speed) {
            Err(reason)
        } else {
            let cap = self.braking.allowed_mps(s);
            Ok(if cap < command.speed_mps.abs() {
                Verdict::Slow {
                    cap_mps: cap,
                    reason,
                }
            } else {
                Verdict::Clear
            })
        };
        self.held_for_hazard = !matches!(verdict, Ok(Verdict::Clear));
        verdict
    }

    /// A turn in place: stopped when a hazard stands where the body turns
    /// before it could stop turning (with `side_margin_m` all round, and a
    /// tenth of a radian more).
    fn judge_turn(&mut self, command: &SteeringCommand, pose: &Pose) -> Result<Verdict, Reason> {
        let rate = command.turn_rate_radps.abs();
        let turn = arcnav_vehicle::TurnInPlace {
            centre: self.turn_centre,
            left: command.turn_rate_radps > 0.0,
            footprint: self.footprint.grown(
                self.config.side_margin_m,
                self.config.side_margin_m,
                0.0,
            ),
            max_angle: rate * self.turn_stop_s + 0.1,
        };
        let to_level = level_frame(&pose.world_from_vehicle).inverse();
        let met = self
            .hazards()
            .filter_map(|h| {
                let p = to_level * h.position;
                let p = Point2::new(p.x, p.y);
                // How far the body turns to meet it, along the hazard's
                // circle about the centre, m.
                let along = turn.first_contact(p)? * (p - turn.centre).norm();
                Some((along, *h))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match met {
            Some((along, hazard)) => Err(Reason::Hazard {
                kind: hazard.kind,
                at: [hazard.position.x, hazard.position.y],
                distance_m: along,
            }),
            None => Ok(Verdict::Clear),
        }
    }

    /// The nearest hazard on the path `command` puts the vehicle on, and
    /// how far along it. Found again when the command or the hazards
    /// change, or the vehicle has driven `RECHECK_M` since; in between,
    /// the distance is what it was less the distance driven.
    fn contact(&mut self, command: &SteeringCommand, pose: &Pose) -> Option<(f64, Hazard)> {
        /// Driven this far, the contact is found again, m.
        const RECHECK_M: f64 = 0.5;
        let at = pose.world_from_vehicle.translation.vector;
        let key = (command.utime, command.curvature);
        if let Some(c) = self.contact
            && c.command == key
            && c.version == self.version
        {
            let driven = (at.x - c.from[0]).hypot(at.y - c.from[1]);
            if driven < RECHECK_M {
                return c.found.map(|(s, h)| (s - driven, h));
            }
        }
        let level = level_frame(&pose.world_from_vehicle);
        let to_level = level.inverse();
        let steering = Steering::of(pose, Some(self.in_flight));
        let path = DrivenPath::new(&steering, &self.response, command.curvature);
        let held: Vec<Hazard> = self.hazards().copied().collect();
        let found = nearest_contact(
            self.footprint,
            &path,
            command.is_reverse(),
            self.braking.reach_m(),
            held.iter().map(|h| {
                let p = to_level * h.position;
                Point2::new(p.x, p.y)
            }),
        )
        .map(|(s, k)| (s, held[k]));
        self.contact = Some(Contact {
            command: key,
            version: self.version,
            from: [at.x, at.y],
            found,
        });
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_perception::scene::HeightFunction;
    use arcnav_vehicle::frames::Isometry;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    const T0: Utime = 10_000_000;

    fn command(speed_mps: f64, curvature: f64) -> SteeringCommand {
        SteeringCommand {
            utime: T0,
            curvature,
            speed_mps,
            arc_index: Some(0),
            vote: 1.0,
            turn_rate_radps: 0.0,
        }
    }

    /// The default vehicle at the origin facing +x at `speed` m/s, having
    /// seen `height` with the ERIM.
    fn guard_seeing(height: impl Fn(f64, f64) -> f64 + Sync, speed: f64) -> Guard {
        let sensor = SensorModel::erim();
        let mut guard = Guard::new(
            &GuardConfig::default(),
            &VehicleConfig::default(),
            std::slice::from_ref(&sensor),
        );
        let pose = Pose {
            velocity: Vector3::new(speed, 0.0, 0.0),
            ..Pose::at_rest(T0, Isometry::identity())
        };
        guard.observe_pose(&pose);
        let image = sensor.render(T0, &pose.world_from_vehicle, &HeightFunction::new(height));
        guard.observe_image(&image);
        guard
    }

    /// A box 0.6 m tall, 1 m deep and 2 m wide, its near face `s` ahead of
    /// the default vehicle's front (x = 4 m).
    fn box_at(s: f64) -> impl Fn(f64, f64) -> f64 + Sync {
        move |x, y| {
            if (4.0 + s..5.0 + s).contains(&x) && y.abs() < 1.0 {
                0.6
            } else {
                0.0
            }
        }
    }

    fn reason_name(verdict: &Verdict) -> Option<&'static str> {
        verdict.reason().map(Reason::name)
    }

    #[test]
    fn level_open_ground_lets_every_command_through() {
        let mut guard = guard_seeing(|_, _| 0.0, 8.0);
        for curvature in [-0.2, 0.0, 0.1] {
            assert_eq!(guard.check(&command(8.0, curvature), T0), Verdict::Clear);
        }
        assert_eq!(guard.counts().standing + guard.counts().holes, 0);
        assert!(guard.counts().returns > 10_000, "{:?}", guard.counts());
    }

    #[test]
    fn a_box_within_the_stopping_distance_stops_beyond_it_slows_to_the_speed_that_stops_short() {
        // At 5 m/s d(v) = 5·0.25 + 25/6 = 5.4 m: a box 4 m ahead is in the
        // stop zone.
        let near = guard_seeing(box_at(4.0), 5.0).check(&command(8.0, 0.0), T0);
        assert!(matches!(near, Verdict::Stop { .. }), "{near:?}");
        assert_eq!(reason_name(&near), Some("obstacle"));
        // 11 m ahead: v_allowed = 3·(−0.25 + sqrt(0.0625 + 2·10/3)) ≈ 7.0 m/s.
        let mut far = guard_seeing(box_at(11.0), 5.0);
        let verdict = far.check(&command(8.0, 0.0), T0);
        let Verdict::Slow { cap_mps, reason } = &verdict else {
            panic!("{verdict:?}");
        };
        let Reason::Hazard { distance_m, .. } = reason else {
            panic!("{reason:?}");
        };
        assert!((distance_m - 11.0).abs() < 0.3, "{distance_m}");
        let braking = Braking::of(&VehicleConfig::default(), 1.0);
        assert!((cap_mps - braking.allowed_mps(*distance_m)).abs() < 1e-9);
        assert!((6.5..7.5).contains(cap_mps), "{cap_mps}");
        // Slowed, the command keeps its arc; under the cap it goes as it is.
        assert_eq!(verdict.apply(&command(8.0, 0.0)).speed_mps, *cap_mps);
        assert_eq!(far.check(&command(4.0, 0.0), T0), Verdict::Clear);
        // An arc curving away from the box does not meet it.
        assert_eq!(far.check(&command(8.0, 0.2), T0), Verdict::Clear);
        // A stop is a stop.
        assert_eq!(far.check(&SteeringCommand::stop(T0), T0), Verdict::Clear);
    }

    /// Issue 68: a skid-steer vehicle's turn in place sweeps its body
    /// (widened by `side_margin_m` all round) about the middle of its
    /// wheelbase. A box seen 6 m back, now beside the body's right side:
    /// turning left swings the rear right corner into it, turning right
    /// the front right one, within what the vehicle turns before it stops
    /// turning (at 1 rad/s: 0.25 s of latency, half the 0.25 s ramp, and
    /// 0.1 rad); both are stopped, as a stop. The same box 1.5 m farther
    /// out lets both through.
    #[test]
    fn a_turn_in_place_is_stopped_where_a_corner_would_swing_into_a_box_beside_it() {
        let vehicle = VehicleConfig::warthog();
        let verdicts = |off: f64| {
            let sensor = SensorModel::erim();
            let mut guard = Guard::new(
                &GuardConfig::default(),
                &vehicle,
                std::slice::from_ref(&sensor),
            );
            let beside = move |x: f64, y: f64| {
                if (0.0..1.2).contains(&x) && (-1.25 - off..-0.95 - off).contains(&y) {
                    0.6
                } else {
                    0.0
                }
            };
            let back = Pose::at_rest(T0, Isometry::translation(-6.0, 0.0, 0.0));
            guard.observe_pose(&back);
            let image = sensor.render(T0, &back.world_from_vehicle, &HeightFunction::new(beside));
            guard.observe_image(&image);
            let now = T0 + 100_000;
            guard.observe_pose(&Pose::at_rest(now, Isometry::identity()));
            [1.0, -1.0].map(|rate| {
                let turn = SteeringCommand::turn_in_place(now, rate, 0, 1.0);
                let verdict = guard.check(&turn, now);
                (verdict.clone(), verdict.apply(&turn))
            })
        };
        for (verdict, sent) in verdicts(0.0) {
            assert!(matches!(verdict, Verdict::Stop { .. }), "{verdict:?}");
            assert_eq!(reason_name(&verdict), Some("obstacle"));
            assert!(sent.is_stop() && !sent.is_turn_in_place(), "{sent:?}");
        }
        for (verdict, sent) in verdicts(1.5) {
            assert_eq!(verdict, Verdict::Clear);
            assert!(sent.is_turn_in_place());
        }
    }

    /// A vehicle stopped for a hazard is let go only a cell (0.2 m) clear
    /// of the stop zone: the distance to held cells jitters by that much
    /// from image to image, and at the zone's edge the verdict flipped
    /// stop, clear, stop (`the_vehicle_side_guard_stops_commands_that_drive_at_a_box_it_sees`,
    /// one run in four). Stopped for a box at 5.2 m/s, then at the speed
    /// whose stopping distance leaves 0.1 m more than the margin, it stays
    /// stopped; a command slow enough for the box a cell nearer goes.
    #[test]
    fn a_stop_for_a_hazard_is_let_go_only_a_cell_clear_of_the_stop_zone() {
        let mut guard = guard_seeing(box_at(6.3), 5.2);
        let verdict = guard.check(&command(5.2, 0.0), T0);
        let Verdict::Stop {
            reason: Reason::Hazard { distance_m: s, .. },
            ..
        } = verdict
        else {
            panic!("{verdict:?}");
        };
        let braking = Braking::of(&VehicleConfig::default(), GuardConfig::default().margin_m);
        let edge = braking.allowed_mps(s - 0.1);
        let at_edge = Pose {
            velocity: Vector3::new(edge, 0.0, 0.0),
            ..Pose::at_rest(T0, Isometry::identity())
        };
        guard.observe_pose(&at_edge);
        let again = guard.check(&command(edge, 0.0), T0);
        assert!(matches!(again, Verdict::Stop { .. }), "{again:?}");
        // Standing, a command slow enough for the box a cell nearer goes.
        guard.observe_pose(&Pose::at_rest(T0, Isometry::identity()));
        let creep = braking.allowed_mps(s - 0.25);
        assert_eq!(guard.check(&command(creep, 0.0), T0), Verdict::Clear);
        // ... and then, clear, it is judged at the distance measured.
        let faster = braking.allowed_mps(s - 0.05);
        assert_eq!(guard.check(&command(faster, 0.0), T0), Verdict::Clear);
    }

    /// A command that turns into a hazard is stopped on the path the
    /// vehicle was on: braking on the new arc would steer it into what
    /// the guard stopped it for.
    #[test]
    fn a_stop_holds_the_path_the_vehicle_was_sent_not_the_new_arc() {
        // A box 4 m ahead and 3 m to the left; driving straight at 5 m/s
        // passes it, a hard left runs into it within the stopping distance.
        let left_box = |x: f64, y: f64| {
            if (7.0..9.0).contains(&x) && (2.0..4.0).contains(&y) {
                0.6
            } else {
                0.0
            }
        };
        let mut guard = guard_seeing(left_box, 5.0);
        assert_eq!(guard.check(&command(5.0, 0.0), T0), Verdict::Clear);
        let turn = SteeringCommand {
            utime: T0 + 100_000,
            ..command(5.0, 0.15)
        };
        let verdict = guard.check(&turn, T0 + 100_000);
        let Verdict::Stop { curvature, .. } = verdict else {
            panic!("{verdict:?}");
        };
        assert_eq!(curvature, 0.0);
        let sent = verdict.apply(&turn);
        assert_eq!((sent.speed_mps, sent.curvature), (0.0, 0.0));
        // The stop is what was sent: the next command into the box holds
        // the same path.
        let again = guard.check(
            &SteeringCommand {
                utime: T0 + 200_000,
                ..command(5.0, 0.15)
            },
            T0 + 100_000,
        );
        assert!(
            matches!(again, Verdict::Stop { curvature, .. } if curvature == 0.0),
            "{again:?}"
        );
    }

    #[test]
    fn a_ditch_ahead_is_a_hole_and_stops_the_vehicle() {
        let ditch = |x: f64, _: f64| if (7.0..9.0).contains(&x) { -1.5 } else { 0.0 };
        let mut guard = guard_seeing(ditch, 5.0);
        assert!(guard.counts().holes > 0, "{:?}", guard.counts());
        let verdict = guard.check(&command(5.0, 0.0), T0);
        assert!(matches!(verdict, Verdict::Stop { .. }), "{verdict:?}");
        assert_eq!(reason_name(&verdict), Some("hole"));
    }

    /// A hazard the sensor looks at again and does not see for
    /// `memory_s` is forgotten (it moved); one in the blind zone in front
    /// of the bumper is held however long the vehicle stands before it.
    #[test]
    fn hazards_are_forgotten_only_when_looked_at_and_not_seen_for_memory_s() {
        let sensor = SensorModel::erim();
        let period = sensor.period_us();
        fn images<F: Fn(f64, f64) -> f64 + Sync>(
            guard: &mut Guard,
            from: Utime,
            seconds: i64,
            x: f64,
            height: &HeightFunction<F>,
        ) -> Utime {
            let sensor = SensorModel::erim();
            let period = sensor.period_us();
            let mut t = from;
            while t < from + seconds * 1_000_000 {
                let pose = Pose::at_rest(t, Isometry::translation(x, 0.0, 0.0));
                guard.observe_pose(&pose);
                guard.observe_image(&sensor.render(t, &pose.world_from_vehicle, height));
                t += period;
            }
            t
        }
        let with_box = HeightFunction::new(box_at(4.0));
        let open = HeightFunction::new(|_, _| 0.0);
        // Seen from 4 m, then stood 0.8 m short of it (below the lowest
        // beam) for 20 s of images: still held, and it stops the vehicle.
        let mut guard = guard_seeing(box_at(4.0), 0.0);
        let held = guard.hazards().count();
        assert!(held > 0);
        let t = images(&mut guard, T0, 20, 3.2, &with_box);
        assert!(
            guard.hazards().count() >= held,
            "{}",
            guard.hazards().count()
        );
        guard.observe_pose(&Pose::at_rest(t, Isometry::translation(3.2, 0.0, 0.0)));
        let verdict = guard.check(
            &SteeringCommand {
                utime: t,
                ..command(1.0, 0.0)
            },
            t,
        );
        assert_eq!(reason_name(&verdict), Some("obstacle"), "{verdict:?}");
        // The box taken away and looked at from 4 m: forgotten after
        // memory_s (5 s), not before.
        let mut guard = guard_seeing(box_at(4.0), 0.0);
        let t = images(&mut guard, T0 + period, 4, 0.0, &open);
        assert!(guard.hazards().count() > 0);
        images(&mut guard, t, 2, 0.0, &open);
        assert_eq!(guard.hazards().count(), 0);
    }

    #[test]
    fn missing_data_and_tilt_stop_the_vehicle() {
        let config = GuardConfig::default();
        let vehicle = VehicleConfig::default();
        let sensor = SensorModel::erim();
        let mut guard = Guard::new(&config, &vehicle, std::slice::from_ref(&sensor));
        let go = command(2.0, 0.0);
        assert_eq!(
            guard.check(&go, T0),
            Verdict::Stop {
                reason: Reason::StalePose { age_s: None },
                curvature: 0.0
            }
        );
        guard.observe_pose(&Pose::at_rest(T0, Isometry::identity()));
        assert_eq!(
            guard.check(&go, T0),
            Verdict::Stop {
                reason: Reason::NoImage {
                    sensor: sensor.id.clone(),
                    age_s: None
                },
                curvature: 0.0
            }
        );
        let image = sensor.render(T0, &Isometry::identity(), &HeightFunction::new(|_, _| 0.0));
        guard.observe_image(&image);
        assert_eq!(guard.check(&go, T0), Verdict::Clear);
        // A pose older than pose_timeout_s.
        let verdict = guard.check(&go, T0 + 600_000);
        assert_eq!(reason_name(&verdict), Some("stale pose"), "{verdict:?}");
        // Images more than image_timeout_periods apart.
        let silent = T0 + 2 * sensor.period_us() + sensor.period_us() * 3 / 2;
        guard.observe_pose(&Pose::at_rest(silent, Isometry::identity()));
        let verdict = guard.check(&go, silent);
        assert_eq!(reason_name(&verdict), Some("no image"), "{verdict:?}");
        guard.observe_image(&RangeImage {
            utime: silent,
            ..image.clone()
        });
        assert_eq!(guard.check(&go, silent), Verdict::Clear);
        // Rolled beyond max_slope_deg − tilt_margin_deg (25 − 2).
        let tilted = Isometry::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_euler_angles(24f64.to_radians(), 0.0, 0.0),
        );
        guard.observe_pose(&Pose::at_rest(silent, tilted));
        let verdict = guard.check(&go, silent);
        assert_eq!(reason_name(&verdict), Some("tilt"), "{verdict:?}");
        // Inputs it cannot use are counted.
        let other = SensorModel::lidar64();
        guard.observe_image(&other.blank_image(silent));
        assert_eq!(guard.counts().unknown_sensor, 1);
    }
}
