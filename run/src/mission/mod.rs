//! A simulated mission: the simulator closes the loop around the real
//! pipeline in lock-step on simulated time.
//!
//! Every pose tick (50 Hz) the vehicle model advances under the commands it
//! has received, is draped on the terrain and checked against the true
//! hazards; the pipeline gets the pose (with noise and drift if configured)
//! and, at the sensor's rate, a range image ray-cast from the true pose. The
//! pipeline sees nothing else of the world: no shortcut through ground truth.

pub mod first_seen;
pub(crate) mod guarded;
pub mod report;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use arcnav_arbiter::{BehaviourVotes, Decision};
use arcnav_behaviours::{Mission, Waypoint};
use arcnav_bus::lcmtypes::pose_t;
use arcnav_bus::messages::channels;
use arcnav_localmap::MapSnapshot;
use arcnav_perception::{ObstacleReport, Reasons, SensorModel};
use arcnav_sim::World;
use arcnav_sim::simulator::{self, Simulator, Step, Stepped};
use arcnav_vehicle::time::{micros_to_seconds, seconds_to_micros};
use arcnav_vehicle::{SteeringCommand, Utime};

use crate::recorder::{Recorder, WriteFailed};
use crate::render;
use arcnav_config::Resolved;
use arcnav_pipeline::{Input, Pipeline, Sink};
use arcnav_wire as wire;
pub use guarded::{GuardEvent, GuardReport};
pub use report::{
    FaultReport, MissionProgress, MissionReport, MissionRun, NearMissReport, Outcome, StopStats,
    TrackPoint, TurnInPlaceMark, VerifiedDistanceReport,
};

/// Simulated time starts here: 2026-01-01T00:00:00Z, µs.
pub const SIM_EPOCH_US: Utime = 1_767_225_600_000_000;

/// What goes into the mission's LCM log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogMode {
    /// Everything, range images included (what `arcnav replay` needs).
    #[default]
    All,
    /// Everything but range images (much smaller with a lidar).
    NoImages,
}

/// How a mission is run and what it writes.
#[derive(Debug, Clone, Default)]
pub struct MissionOptions {
    /// Write the LCM event log here.
    pub log: Option<PathBuf>,
    pub log_mode: LogMode,
    /// Write a local-map picture every this many simulated seconds, into `snapshot_dir`.
    pub snapshot_every_s: Option<f64>,
    pub snapshot_dir: Option<PathBuf>,
    /// Other missions run beside this one and keep the cores busy: images
    /// are rendered when due, never ahead (`sim.render_ahead` would only add
    /// threads competing for them).
    pub beside_others: bool,
}

impl From<WriteFailed> for MissionError {
    fn from(WriteFailed { path, source }: WriteFailed) -> Self {
        Self::Log { path, source }
    }
}

/// A mission that could not run.
#[derive(Debug, thiserror::Error)]
pub enum MissionError {
    #[error(transparent)]
    Config(#[from] arcnav_vehicle::ConfigError),
    #[error(transparent)]
    World(#[from] arcnav_sim::WorldError),
    #[error("cannot write the log {path}: {source}")]
    Log {
        path: PathBuf,
        source: arcnav_bus::log::LogWriteError,
    },
    #[error("cannot create the log {path}: {source}")]
    CreateLog {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write a snapshot picture: {0}")]
    Picture(#[from] render::RenderError),
    #[error(transparent)]
    External(#[from] crate::external::ExternalError),
    #[error(
        "the start ({:.1}, {:.1}) lies outside the operating area ([mission] area): give an area that holds it, or area = \"none\"",
        start[0], start[1]
    )]
    StartOutsideArea { start: [f64; 2] },
}

/// Receives the pipeline's outputs during a mission.
struct MissionSink<'a> {
    /// The mission log, and the first error of the mission.
    log: Recorder<'a, MissionError>,
    /// How commands go on the wire (`[vehicle] kinematics`).
    kinematics: arcnav_vehicle::Kinematics,
    arcs: arcnav_vehicle::ArcSet,
    commands: Vec<SteeringCommand>,
    previous_curvature: Option<f64>,
    curvature_change: (f64, u64),
    stops: StopStats,
    stopped: bool,
    patches: BTreeMap<(i64, i64), (Reasons, f32)>,
    seen: SeenPatches,
    snapshot: Option<(f64, &'a Path, Utime)>,
    snapshots: Vec<PathBuf>,
    config: &'a Resolved,
    track: Vec<TrackPoint>,
    /// Where the vehicle turned in place, and how far.
    turns_in_place: Vec<TurnInPlaceMark>,
    /// The heading at the last command, while turning in place.
    turning_from: Option<f64>,
    /// The behaviours' overlays of the cycle whose snapshot is due.
    overlays: Vec<(String, arcnav_behaviours::Overlay)>,
    /// When each drop hazard was first reported (ground truth).
    drops: first_seen::DropWatch,
}

impl MissionSink<'_> {
    /// Marks a turn in place: begun where the first of its commands was
    /// sent, the heading turned summed over the decisions it lasted.
    fn mark_turn_in_place(&mut self, at: Utime, command: &SteeringCommand, map: &MapSnapshot) {
        let yaw = arcnav_vehicle::frames::yaw_of(&map.world_from_vehicle);
        // The heading when the last command turned in place: a turn under way.
        let under_way = self.turning_from.take();
        if let (Some(before), Some(mark)) = (under_way, self.turns_in_place.last_mut()) {
            mark.turned_deg += arcnav_vehicle::frames::wrap_angle(yaw - before).to_degrees();
        }
        if command.is_turn_in_place() {
            if under_way.is_none() {
                let t = map.world_from_vehicle.translation.vector;
                self.turns_in_place.push(TurnInPlaceMark {
                    x: t.x,
                    y: t.y,
                    utime: at,
                    turned_deg: 0.0,
                });
            }
            self.turning_from = Some(yaw);
        }
    }
}

impl Sink for MissionSink<'_> {
    fn on_obstacles(&mut self, at: Utime, report: &ObstacleReport) {
        self.log.obstacles(at, report);
        self.drops.report(report);
    }

    fn on_votes(&mut self, at: Utime, votes: &[BehaviourVotes]) {
        self.log.votes(at, votes, &self.arcs);
    }

    fn wants_overlays(&self, at: Utime) -> bool {
        self.snapshot
            .as_ref()
            .is_some_and(|(_, _, next)| at >= *next)
    }

    fn on_overlays(&mut self, _at: Utime, overlays: Vec<(String, arcnav_behaviours::Overlay)>) {
        self.overlays = overlays;
    }

    fn on_command(
        &mut self,
        at: Utime,
        command: &SteeringCommand,
        reason: &arcnav_arbiter::Reason,
        decision: Option<&Decision>,
        map: &MapSnapshot,
    ) {
        self.log.command(at, command, self.kinematics, reason);
        self.commands.push(*command);
        // Steering between driving arcs: a turn in place (±∞) steers no
        // wheels, and is marked on the map instead.
        if command.curvature.is_finite() {
            if let Some(previous) = self.previous_curvature {
                self.curvature_change.0 += (command.curvature - previous).abs();
                self.curvature_change.1 += 1;
            }
            self.previous_curvature = Some(command.curvature);
        }
        self.mark_turn_in_place(at, command, map);
        if command.is_stop() {
            self.stops.stop_commands += 1;
            if !self.stopped {
                self.stops.episodes += 1;
            }
        }
        self.stopped = command.is_stop();
        for p in &map.patches {
            let (reasons, cost) = self
                .patches
                .entry((p.i, p.j))
                .or_insert((Reasons::NONE, 0.0));
            reasons.insert(p.reasons);
            *cost = cost.max(p.cost);
        }
        // The seen ground, for the picture: every 10th decision is enough
        // (the vehicle moves less than the window meanwhile).
        if self.commands.len() % 10 == 1 {
            self.seen.add(map.seen.iter());
        }
        if let Some((every, dir, next)) = &mut self.snapshot
            && at >= *next
            && self.log.error.is_none()
        {
            *next = at + seconds_to_micros(*every);
            let path = dir.join(format!(
                "snapshot-{:08.3}s.png",
                micros_to_seconds(at - SIM_EPOCH_US)
            ));
            match render::snapshot_picture(
                &path,
                self.config,
                &self.arcs,
                map,
                decision,
                at - SIM_EPOCH_US,
                &std::mem::take(&mut self.overlays),
                None,
            ) {
                Ok(()) => self.snapshots.push(path),
                Err(e) => self.log.error = Some(e.into()),
            }
        }
    }
}

/// Every patch the map has seen, for the mission's picture. A window of
/// thousands of patches, most of them already in, is added every tenth
/// decision: the patches are kept as bits of 8 × 8 blocks, and a run of
/// patches in one block costs one look-up.
#[derive(Debug, Default)]
struct SeenPatches {
    blocks: HashMap<(i64, i64), u64>,
}

impl SeenPatches {
    fn add(&mut self, patches: impl Iterator<Item = (i64, i64)>) {
        let mut last: Option<((i64, i64), &mut u64)> = None;
        for (i, j) in patches {
            let block = (i.div_euclid(8), j.div_euclid(8));
            let bit = 1u64 << (i.rem_euclid(8) + 8 * j.rem_euclid(8));
            match &mut last {
                Some((at, bits)) if *at == block => **bits |= bit,
                _ => {
                    let bits = self.blocks.entry(block).or_default();
                    *bits |= bit;
                    last = Some((block, bits));
                }
            }
        }
    }

    /// The patches, in order.
    fn patches(&self) -> BTreeSet<(i64, i64)> {
        let mut out = BTreeSet::new();
        for (&(bi, bj), &bits) in &self.blocks {
            let mut bits = bits;
            while bits != 0 {
                let b = i64::from(bits.trailing_zeros());
                bits &= bits - 1;
                out.insert((bi * 8 + b % 8, bj * 8 + b / 8));
            }
        }
        out
    }
}

/// The mission of `world` as the goal-seeking behaviour sees it.
pub fn mission_of(world: &World, version: Utime) -> Mission {
    Mission {
        version,
        waypoints: world
            .waypoints
            .iter()
            .map(|w| Waypoint {
                x: w.x,
                y: w.y,
                radius_m: w.radius_m,
            })
            .collect(),
    }
}

/// Runs a mission of `world` to its end.
pub fn run_mission(
    config: &Resolved,
    world: Arc<World>,
    options: &MissionOptions,
    progress: &mut dyn FnMut(&MissionProgress),
) -> Result<MissionRun, MissionError> {
    let wall = Instant::now();
    let config = &*config.in_world(&world.area(config.mission.area_margin_m));
    if let Some(area) = config.area()
        && !area.contains(world.start.0)
    {
        return Err(MissionError::StartOutsideArea {
            start: world.start.0,
        });
    }
    let sensors: &[SensorModel] = &config.sensors;
    let sim = &config.sim;
    let t0 = SIM_EPOCH_US;
    let mut simulator = Simulator::new(
        Arc::clone(&world),
        simulator::Setup {
            vehicle: &config.vehicle,
            sim,
            sensors,
            evaluated_range_m: config.perception.max_range_m,
            exclusive: !options.beside_others,
            start: t0,
            area: config.area(),
        },
    )?;
    let mut pipeline = config.lockstep()?;
    crate::external::attach(config, &mut pipeline)?;
    let mut guard = guarded::GuardWatch::new(config, sensors);
    pipeline.time_stages(Instant::now);
    pipeline.set_explain(options.snapshot_every_s.is_some());
    let log = Recorder::create(options.log.as_deref())
        .map_err(|(path, source)| MissionError::CreateLog { path, source })?;
    let mut sink = MissionSink {
        log,
        kinematics: config.vehicle.kinematics,
        arcs: pipeline.arcs().clone(),
        commands: Vec::new(),
        previous_curvature: None,
        curvature_change: (0.0, 0),
        stops: StopStats::default(),
        stopped: false,
        patches: BTreeMap::new(),
        seen: SeenPatches::default(),
        snapshot: match (options.snapshot_every_s, &options.snapshot_dir) {
            (Some(every), Some(dir)) => Some((every, dir.as_path(), t0)),
            _ => None,
        },
        snapshots: Vec::new(),
        config,
        track: Vec::new(),
        turns_in_place: Vec::new(),
        turning_from: None,
        overlays: Vec::new(),
        drops: first_seen::DropWatch::new(&world, &config.vehicle, sensors),
    };
    let mission = mission_of(&world, t0);
    sink.log
        .message(t0, channels::WAYPOINTS, &wire::mission_to_wire(&mission));
    pipeline.input(Input::Waypoints(mission), &mut sink);

    let time_limit = t0 + seconds_to_micros(sim.time_limit_s);
    let mut next_progress = t0;
    let mut stuck = StuckWatch::new(sim.stuck_after_s, sim.stuck_radius_m);
    let outcome;
    let mut t;
    loop {
        t = simulator.time();
        let step = match simulator.step() {
            Stepped::Sensed(step) => step,
            Stepped::Collided { .. } => {
                outcome = Outcome::Collision;
                break;
            }
        };
        let state = step.state;
        sink.drops.pose(t, [state.x, state.y, state.yaw]);
        if step.tick.is_multiple_of(5) {
            sink.track.push(TrackPoint {
                utime: t,
                x: state.x,
                y: state.y,
                speed_mps: state.speed_mps,
                governed: pipeline.arbiter.governed(),
            });
        }
        // The guard takes the tick's pose and images before the pipeline
        // does, on the pipeline's thread: the images are rendered ahead on
        // another (`sim.render_ahead`), and the renderer, not the
        // pipeline, sets the pace; a third thread would take from it.
        if let Some(guard) = guard.as_mut() {
            guard.observe(
                &step.pose,
                step.slices.iter().map(|(_, _, s)| s),
                step.images.iter().map(|(_, i)| i),
            );
        }
        feed(step, t, options.log_mode, sensors, &mut pipeline, &mut sink);
        pipeline.run_until(t, &mut sink);
        let commands = std::mem::take(&mut sink.commands);
        let commands = match guard.as_mut() {
            Some(guard) => {
                let sent =
                    guard.commands(commands, t, t0, [state.x, state.y], 1.0 / sim.pose_rate_hz);
                for status in guard.said() {
                    sink.log.message(t, channels::GUARD_STATUS, &status);
                }
                sent
            }
            None => commands,
        };
        for command in commands {
            simulator.command(command);
        }
        if let Some(e) = sink.log.error.take() {
            return Err(e);
        }
        if pipeline.behaviours.faults().iter().any(|(name, _)| {
            config.arbiter.required.iter().any(|r| r == name) && config.arbiter.weight(name) > 0.0
        }) {
            outcome = Outcome::BehaviourFailed;
            break;
        }
        let status = pipeline.behaviours.progress();
        if status.is_some_and(|p| p.complete) {
            outcome = Outcome::Completed;
            break;
        }
        if status.is_some_and(|p| p.unreachable) {
            outcome = Outcome::Unreachable;
            break;
        }
        if let Some(p) = status
            && let Some(w) = world.waypoints.get(p.current)
            && stuck.is_stuck(p.current, [w.x, w.y], [state.x, state.y], t)
        {
            outcome = Outcome::Stuck;
            break;
        }
        if t >= time_limit {
            outcome = Outcome::Timeout;
            break;
        }
        if t >= next_progress {
            next_progress = t + 1_000_000;
            progress(&MissionProgress {
                sim_time_s: micros_to_seconds(t - t0),
                distance_m: simulator.distance_m(),
                waypoint: status.map_or(0, |p| p.current),
                waypoints: world.waypoints.len(),
                speed_mps: state.speed_mps,
                time_limit_s: sim.time_limit_s,
            });
        }
    }
    let no_routes = pipeline.behaviours.no_routes();
    let report = mission_report(&Ended {
        config,
        world: &world,
        simulator: &simulator,
        pipeline: &pipeline,
        sink: &sink,
        guard: guard.as_ref().map(guarded::GuardWatch::report),
        no_routes: &no_routes,
        outcome,
        duration_s: micros_to_seconds(t - t0),
        wall_time_s: wall.elapsed().as_secs_f64(),
    });
    sink.log.finish()?;
    Ok(MissionRun {
        report,
        track: sink.track,
        turns_in_place: sink.turns_in_place,
        image_positions: simulator.image_positions().to_vec(),
        obstacle_patches: sink.patches,
        seen_patches: sink.seen.patches(),
        patch_size_m: config.localmap.patch_size_m,
        snapshots: sink.snapshots,
        no_routes,
    })
}

/// One step's inputs, logged (range data only with [`LogMode::All`]) and
/// given to the pipeline: the slices that completed, the pose, the whole
/// images.
fn feed(
    Step {
        slices,
        pose,
        images,
        ..
    }: Step,
    t: Utime,
    log_mode: LogMode,
    sensors: &[SensorModel],
    pipeline: &mut Pipeline,
    sink: &mut MissionSink<'_>,
) {
    for (i, done, slice) in slices {
        if log_mode == LogMode::All {
            sink.log.message(
                done,
                &channels::range_image(&sensors[i].id),
                &wire::range_slice_to_wire(&slice),
            );
        }
        pipeline.input(Input::Slice(slice), sink);
    }
    sink.log.message(t, channels::POSE, &pose_t::from(&pose));
    pipeline.input(Input::Pose(pose), sink);
    for (i, image) in images {
        if log_mode == LogMode::All {
            sink.log.message(
                t,
                &channels::range_image(&sensors[i].id),
                &wire::range_image_to_wire(&image),
            );
        }
        pipeline.input(Input::Image(image), sink);
    }
}

/// What a mission's report is made from, at its end.
struct Ended<'e, 'a> {
    config: &'e Resolved,
    world: &'e World,
    simulator: &'e Simulator,
    pipeline: &'e Pipeline,
    sink: &'e MissionSink<'a>,
    guard: Option<GuardReport>,
    /// The waypoints the behaviours found no route to.
    no_routes: &'e [arcnav_behaviours::NoRoute],
    outcome: Outcome,
    duration_s: f64,
    wall_time_s: f64,
}

/// The report of a mission that has ended.
fn mission_report(ended: &Ended<'_, '_>) -> MissionReport {
    let Ended {
        config,
        world,
        simulator,
        pipeline,
        sink,
        guard: _,
        no_routes: _,
        outcome,
        duration_s: duration,
        wall_time_s: wall_time,
    } = *ended;
    let t0 = SIM_EPOCH_US;
    let sensors: &[SensorModel] = &config.sensors;
    let arbiter = pipeline.arbiter.stats();
    let mut stops = sink.stops.clone();
    stops.no_votes = arbiter.stops_no_votes;
    stops.required_stale = arbiter.stops_required_stale;
    stops.all_arcs_forbidden = arbiter.stops_all_forbidden;
    stops.no_acceptable_arc = arbiter.stops_no_acceptable;
    stops.stuck = arbiter.stops_stuck;
    stops.stopped_s = arbiter.stopped.seconds().into_iter().collect();
    let recovery = *pipeline.arbiter.recovery_stats();
    let behaviour_counters = pipeline
        .behaviours
        .counters()
        .into_iter()
        .map(|(name, counters)| (name, counters.into_iter().collect()))
        .collect();
    let behaviour_faults = pipeline
        .behaviours
        .faults()
        .into_iter()
        .map(|(name, why)| (name.to_owned(), why.to_owned()))
        .collect();
    let progress = pipeline.behaviours.progress();
    let skipped = progress.map_or(0, |p| p.skipped);
    let reached = progress.map_or(0, |p| p.current) - skipped;
    let unreachable = ended
        .no_routes
        .iter()
        .map(|n| report::NoRouteReport {
            waypoint: n.waypoint + 1,
            position: n.position,
            no_way_since_s: micros_to_seconds(n.since - t0),
            given_up_at_s: micros_to_seconds(n.decided - t0),
            vehicle_at: n.vehicle_at,
            known_m2: n.known_m2,
            area_m2: n.area_m2,
            ring_cells: n.ring.len(),
            skipped: n.skipped,
        })
        .collect();
    let drops = pipeline.perception.drops;
    let average_speed = if duration > 0.0 {
        simulator.distance_m() / duration
    } else {
        0.0
    };
    let (fault, fault_counts) = pipeline.fault();
    MissionReport {
        fault: (fault != arcnav_pipeline::Fault::None).then(|| report::FaultReport {
            fault: fault.name(),
            after_s: config.pipeline.fault_after_s,
            counts: fault_counts,
        }),
        guard: ended.guard.clone(),
        world: world.spec.name.clone(),
        sensor: sensors
            .iter()
            .map(|s| s.id.as_str())
            .collect::<Vec<_>>()
            .join("+"),
        success: outcome == Outcome::Completed && simulator.truth().collisions.is_empty(),
        outcome,
        waypoints_reached: reached,
        waypoints: world.waypoints.len(),
        waypoints_skipped: skipped,
        unreachable,
        area: config.area().map(|a| a.vertices().to_vec()),
        distance_m: simulator.distance_m(),
        duration_s: duration,
        average_speed_mps: average_speed,
        max_speed_mps: simulator.max_speed_mps(),
        cruise_mps: config.cruise.mps,
        cruise_asked_mps: config.cruise.asked_mps,
        cruise_cap_mps: config.cruise.cap_mps,
        images: simulator.images(),
        images_dropped: drops.total(),
        slices: (pipeline.perception.slices.received > 0).then_some(pipeline.perception.slices),
        fused: pipeline.perception.fusion(),
        untraversable_cells: Reasons::ALL
            .iter()
            .zip(pipeline.perception.totals.by_reason)
            .map(|(&(_, name), count)| (name, u64::from(count)))
            .collect(),
        graded_cells: u64::from(pipeline.perception.totals.graded),
        suspected_drop_offs: u64::from(pipeline.perception.totals.suspected),
        evidence_suspected: pipeline.perception.evidence_totals.suspected,
        collisions: simulator.truth().collisions.clone(),
        closest_approach_m: simulator
            .truth()
            .closest_approach_m
            .is_finite()
            .then_some(simulator.truth().closest_approach_m),
        closest_approach: simulator
            .truth()
            .closest_at
            .as_ref()
            .map(|m| NearMissReport {
                at_s: micros_to_seconds(m.utime - t0),
                position: m.position,
                hazard: m.hazard.clone(),
            }),
        drops_first_seen: sink.drops.first_seen(t0),
        stops,
        ride: simulator.ride().report(),
        recovery,
        behaviour_counters,
        behaviour_faults,
        steering_activity: sink.curvature_change.0 / sink.curvature_change.1.max(1) as f64,
        map_resets: pipeline.cycle.counts().map_resets,
        localmap: *pipeline.cycle.map.map.stats(),
        stage_times: pipeline.times,
        images_rendered_ahead: simulator.frames_rendered_ahead().0,
        images_rendered_again: simulator.frames_rendered_ahead().1,
        render_ms_mean: if simulator.images() > 0 {
            simulator.render_ms() / simulator.images() as f64
        } else {
            0.0
        },
        wall_time_s: wall_time,
        realtime_factor: if wall_time > 0.0 {
            duration / wall_time
        } else {
            0.0
        },
        speed_fraction_of_bound: average_speed / config.speed_bound.bound_mps.max(1e-9),
        speed_bound: config.speed_bound.clone(),
        speed_limited_by_s: arbiter.moving.seconds().into_iter().collect(),
        verified_distance_m: arbiter
            .verified
            .min_m()
            .zip(arbiter.verified.median_m())
            .map(|(min, median)| VerifiedDistanceReport {
                min,
                median,
                decisions: arbiter.verified.len(),
            }),
        evidence_unverified: pipeline.perception.evidence_totals.unverified,
    }
}

/// When a simulated mission is stuck: for `after` no nearer to its
/// current waypoint (by a metre) while staying within `radius` of where
/// that span began. A vehicle that drives along a ledge to its end, or
/// backs out of a lane, gets no nearer for a while and is not stuck.
#[derive(Debug, Clone)]
struct StuckWatch {
    after: Utime,
    radius: f64,
    /// The waypoint sought and the nearest the vehicle came to it.
    best: (usize, f64),
    /// Where and when the span without progress began.
    anchor: ([f64; 2], Utime),
}

impl StuckWatch {
    fn new(after_s: f64, radius_m: f64) -> Self {
        Self {
            after: seconds_to_micros(after_s),
            radius: radius_m,
            best: (usize::MAX, f64::INFINITY),
            anchor: ([f64::NAN; 2], 0),
        }
    }

    /// Takes the vehicle at `position` at time `t`, seeking waypoint
    /// `index` at `waypoint`; true when it is stuck.
    fn is_stuck(&mut self, index: usize, waypoint: [f64; 2], position: [f64; 2], t: Utime) -> bool {
        let gap = (waypoint[0] - position[0]).hypot(waypoint[1] - position[1]);
        let (from, since) = self.anchor;
        let roamed = (position[0] - from[0]).hypot(position[1] - from[1]) > self.radius;
        if index != self.best.0 || gap < self.best.1 - 1.0 {
            self.best = (index, gap);
            self.anchor = (position, t);
        } else if roamed {
            self.anchor = (position, t);
        } else if t - since > self.after {
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::{SeenPatches, StuckWatch};
    use std::collections::BTreeSet;

    /// Windows of patches added again and again, either side of zero and
    /// across blocks, come out each once, in order.
    #[test]
    fn seen_patches_are_each_patch_added_once_in_order() {
        let mut seen = SeenPatches::default();
        let mut expected = BTreeSet::new();
        for (i0, j0) in [(-13i64, -5i64), (-9, -1), (20, 3), (-13, -5)] {
            let window: Vec<(i64, i64)> = (j0..j0 + 11)
                .flat_map(|j| (i0..i0 + 17).map(move |i| (i, j)))
                .filter(|&(i, j)| (i + 3 * j).rem_euclid(5) != 0)
                .collect();
            expected.extend(window.iter().copied());
            seen.add(window.into_iter());
        }
        assert_eq!(seen.patches(), expected);
    }

    #[test]
    fn a_mission_is_stuck_only_when_it_neither_gains_on_its_waypoint_nor_roams() {
        let s = 1_000_000;
        let goal = [100.0, 0.0];
        // Standing 100 m from its waypoint: stuck after 90 s.
        let mut watch = StuckWatch::new(90.0, 15.0);
        assert!(!watch.is_stuck(0, goal, [0.0, 0.0], 0));
        assert!(!watch.is_stuck(0, goal, [0.5, 0.0], 90 * s));
        assert!(watch.is_stuck(0, goal, [0.0, 0.5], 91 * s));
        // Driving along a ledge 20 m to one side and back, a minute each
        // way: never nearer, never stuck while it roams; stuck 90 s after
        // it stops roaming.
        let mut watch = StuckWatch::new(90.0, 15.0);
        assert!(!watch.is_stuck(0, goal, [0.0, 0.0], 0));
        for k in 1..=20 {
            let side = if k % 2 == 1 { 20.0 } else { -20.0 };
            assert!(!watch.is_stuck(0, goal, [0.0, side], k * 60 * s), "{k}");
        }
        assert!(!watch.is_stuck(0, goal, [0.0, -20.0], 1290 * s));
        assert!(watch.is_stuck(0, goal, [0.0, -20.0], 1291 * s));
        // Gaining a metre on the waypoint, or a new waypoint, starts afresh.
        let mut watch = StuckWatch::new(90.0, 15.0);
        assert!(!watch.is_stuck(0, goal, [0.0, 0.0], 0));
        assert!(!watch.is_stuck(0, goal, [2.0, 0.0], 80 * s));
        assert!(!watch.is_stuck(0, goal, [2.0, 0.0], 160 * s));
        assert!(!watch.is_stuck(1, goal, [2.0, 0.0], 250 * s));
        assert!(watch.is_stuck(1, goal, [2.0, 0.0], 341 * s));
    }
}
