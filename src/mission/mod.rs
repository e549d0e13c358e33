//! A simulated mission: the simulator closes the loop around the real
//! pipeline in lock-step on simulated time.
//!
//! Every pose tick (50 Hz) the vehicle model advances under the commands it
//! has received, is draped on the terrain and checked against the true
//! hazards; the pipeline gets the pose (with noise and drift if configured)
//! and, at the sensor's rate, a range image ray-cast from the true pose. The
//! pipeline sees nothing else of the world: no shortcut through ground truth.

mod ahead;
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
use arcnav_sim::drape::drape;
use arcnav_sim::rng::Rng;
use arcnav_sim::sensor::{SliceRequest, Slicer};
use arcnav_sim::tiles::{TileCache, TileView};
use arcnav_sim::{CollisionPolicy, Truth, World};
use arcnav_vehicle::frames::isometry_from_xyz_rpy;
use arcnav_vehicle::time::{micros_to_seconds, seconds_to_micros};
use arcnav_vehicle::{
    Isometry, MotionLimits, MotionModel, PlanarState, Pose, SteeringCommand, Utime,
};
use nalgebra::Vector3;

use crate::recorder::{Recorder, WriteFailed};
use crate::render;
use crate::wire;
use ahead::{FrameRequest, Frames, view_for};
use arcnav_config::Resolved;
use arcnav_pipeline::{Input, Sink};
pub use report::{
    MissionProgress, MissionReport, MissionRun, NearMissReport, Outcome, StopStats, TrackPoint,
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
}

/// Receives the pipeline's outputs during a mission.
struct MissionSink<'a> {
    /// The mission log, and the first error of the mission.
    log: Recorder<'a, MissionError>,
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
    /// The behaviours' overlays of the cycle whose snapshot is due.
    overlays: Vec<(String, arcnav_behaviours::Overlay)>,
}

impl Sink for MissionSink<'_> {
    fn on_obstacles(&mut self, at: Utime, report: &ObstacleReport) {
        self.log.obstacles(at, report);
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
        decision: Option<&Decision>,
        map: &MapSnapshot,
    ) {
        self.log.command(at, command);
        self.commands.push(*command);
        if let Some(previous) = self.previous_curvature {
            self.curvature_change.0 += (command.curvature - previous).abs();
            self.curvature_change.1 += 1;
        }
        self.previous_curvature = Some(command.curvature);
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
    world.validate_for(&config.vehicle, &world.spec.name)?;
    let sensors: &[SensorModel] = &config.sensors;
    // Returns beyond what perception evaluates are never used: not rendered.
    let evaluated = config.perception.max_range_m + config.sim.render_margin_m;
    let rendered: Vec<Arc<SensorModel>> = sensors
        .iter()
        .map(|sensor| {
            let mut rendered = sensor.clone();
            rendered.max_range_m = sensor.max_range_m.min(evaluated);
            Arc::new(rendered)
        })
        .collect();
    let sim = &config.sim;
    let mut pipeline = config.lockstep()?;
    pipeline.time_stages(Instant::now);
    pipeline.time_stages(Instant::now);
    pipeline.set_explain(options.snapshot_every_s.is_some());
    let threads = sim.thread_count();
    let dt = seconds_to_micros(1.0 / sim.pose_rate_hz);
    let t0 = SIM_EPOCH_US;
    let (start, heading) = world.start;
    let mut motion = MotionModel::new(
        MotionLimits::from_vehicle(&config.vehicle),
        PlanarState {
            x: start[0],
            y: start[1],
            yaw: heading,
            ..PlanarState::default()
        },
        t0,
    );
    let mut tiles = TileCache::new(Arc::clone(&world), 128, threads);
    let mut truth = Truth::new(&world, &config.vehicle);
    let mut pose_rng = Rng::stream(sim.seed, 0x0b5e_55ed);
    let log = Recorder::create(options.log.as_deref())
        .map_err(|(path, source)| MissionError::CreateLog { path, source })?;
    let mut sink = MissionSink {
        log,
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
        overlays: Vec::new(),
    };
    let mission = mission_of(&world, t0);
    sink.log
        .message(t0, channels::WAYPOINTS, &wire::mission_to_wire(&mission));
    pipeline.input(Input::Waypoints(mission), &mut sink);

    // Each sensor images at its own rate, the first image of each at t0.
    let mut next_images: Vec<Utime> = vec![t0; sensors.len()];
    // Sensors that send their images in slices: each one's slicer, and the
    // next slice of the frame under way.
    let slicers: Vec<Option<Slicer>> = rendered
        .iter()
        .map(|sensor| (sim.slice_lines > 0).then(|| Slicer::new(sensor, sim.slice_lines)))
        .collect();
    let mut next_slices: Vec<usize> = vec![0; sensors.len()];
    // Whole frames of one sensor are rendered ahead when the vehicle's path
    // until the next is fixed by then (see `ahead`).
    let mut frames: Vec<Frames> = rendered
        .iter()
        .map(|sensor| {
            let noise = (sim.range_noise_m, sim.dropout_probability);
            Frames::new(Arc::clone(sensor), noise, sim.seed, threads)
        })
        .collect();
    let render_ahead = sim.render_ahead
        && !options.beside_others
        && sensors.len() == 1
        && sim.slice_lines == 0
        && seconds_to_micros(config.vehicle.command_latency_s) >= sensors[0].period_us();
    let mut previous_stance: Option<(Utime, Isometry)> = None;
    let time_limit = t0 + seconds_to_micros(sim.time_limit_s);
    let (mut images, mut image_positions) = (0u64, Vec::new());
    let (mut distance, mut max_speed, mut drift) = (0.0f64, 0.0f64, [0.0f64; 2]);
    let (mut render_ms, mut next_progress) = (0.0f64, t0);
    let mut stuck = StuckWatch::new(sim.stuck_after_s, sim.stuck_radius_m);
    let mut previous = *motion.state();
    let mut ride = arcnav_sim::Ride::new(t0, config.vehicle.max_slope_deg);
    let outcome;
    let mut t = t0;
    let mut tick: u64 = 0;
    loop {
        let state = motion.advance_to(t);
        let stepped = (state.x - previous.x).hypot(state.y - previous.y);
        distance += stepped;
        previous = state;
        max_speed = max_speed.max(state.speed_mps);
        let stance = drape(&world, &config.vehicle, &state);
        ride.observe(t, &stance);
        if tick.is_multiple_of(5) {
            sink.track.push(TrackPoint {
                utime: t,
                x: state.x,
                y: state.y,
                speed_mps: state.speed_mps,
            });
        }
        let collided = !truth.check(&world, t, &stance).is_empty();
        if collided && sim.on_collision == CollisionPolicy::Stop {
            outcome = Outcome::Collision;
            break;
        }
        // What the pipeline is told: the pose, with noise and drift if configured.
        if sim.drift_per_m > 0.0 {
            drift[0] += stepped * sim.drift_per_m * pose_rng.normal();
            drift[1] += stepped * sim.drift_per_m * pose_rng.normal();
        }
        let (noise_x, noise_y, noise_yaw) = if sim.pose_noise_m > 0.0 || sim.heading_noise_deg > 0.0
        {
            (
                sim.pose_noise_m * pose_rng.normal(),
                sim.pose_noise_m * pose_rng.normal(),
                sim.heading_noise_deg.to_radians() * pose_rng.normal(),
            )
        } else {
            (0.0, 0.0, 0.0)
        };
        let true_position = stance.world_from_vehicle.translation.vector;
        let measured = Pose {
            utime: t,
            world_from_vehicle: isometry_from_xyz_rpy(
                [
                    true_position.x + drift[0] + noise_x,
                    true_position.y + drift[1] + noise_y,
                    true_position.z,
                ],
                stance.roll,
                stance.pitch,
                state.yaw + noise_yaw,
            ),
            velocity: Vector3::new(
                state.speed_mps * state.yaw.cos(),
                state.speed_mps * state.yaw.sin(),
                0.0,
            ),
            yaw_rate: state.speed_mps * state.curvature,
        };
        // Slices acquired since the last step come before this step's pose
        // (they wait in perception for the pose after them). Each is
        // rendered where the vehicle was at its middle line; those of one
        // step side by side, then handed over in order.
        for (i, slicer) in slicers.iter().enumerate() {
            let Some(slicer) = slicer else { continue };
            let mut due: Vec<(usize, Utime, Utime, Isometry, u64)> = Vec::new();
            loop {
                let frame = next_images[i];
                let k = next_slices[i];
                let (done, middle) = slicer.times(frame, k);
                if done > t {
                    break;
                }
                let at = match previous_stance {
                    Some((before, ref from)) if t > before => {
                        let f = ((middle - before) as f64 / (t - before) as f64).clamp(0.0, 1.0);
                        from.lerp_slerp(&stance.world_from_vehicle, f)
                    }
                    _ => stance.world_from_vehicle,
                };
                let stream = images.wrapping_mul(65_536).wrapping_add(k as u64);
                due.push((k, frame, done, at, stream));
                next_slices[i] = k + 1;
                if next_slices[i] == slicer.len() {
                    next_slices[i] = 0;
                    next_images[i] += sensors[i].period_us();
                    images += 1;
                    image_positions.push([state.x, state.y]);
                }
            }
            if due.is_empty() {
                continue;
            }
            let started = Instant::now();
            let views: Vec<TileView> = due
                .iter()
                .map(|(_, _, _, at, _)| view_for(&rendered[i], &mut tiles, at))
                .collect();
            let requests: Vec<SliceRequest<'_>> = due
                .iter()
                .zip(&views)
                .map(|(&(k, frame, _, at, stream), view)| SliceRequest {
                    k,
                    frame,
                    view,
                    world_from_vehicle: at,
                    stream,
                })
                .collect();
            let noise = (sim.range_noise_m, sim.dropout_probability);
            let slices = slicer.render_all(&requests, noise, sim.seed, threads);
            render_ms += started.elapsed().as_secs_f64() * 1e3;
            for ((_, _, done, _, _), slice) in due.iter().zip(slices) {
                if options.log_mode == LogMode::All {
                    sink.log.message(
                        *done,
                        &channels::range_image(&sensors[i].id),
                        &wire::range_slice_to_wire(&slice),
                    );
                }
                pipeline.input(Input::Slice(slice), &mut sink);
            }
        }
        previous_stance = Some((t, stance.world_from_vehicle));
        sink.log
            .message(t, channels::POSE, &pose_t::from(&measured));
        pipeline.input(Input::Pose(measured), &mut sink);
        for (((sensor, frames), next_image), slicer) in sensors
            .iter()
            .zip(&mut frames)
            .zip(&mut next_images)
            .zip(&slicers)
        {
            if slicer.is_some() || t < *next_image {
                continue;
            }
            let request = FrameRequest {
                utime: t,
                world_from_vehicle: stance.world_from_vehicle,
                stream: images,
            };
            let (image, ms) = frames.render(&mut tiles, &request);
            render_ms += ms;
            *next_image += sensor.period_us();
            // The next frame, rendered while perception works on this one.
            if render_ahead {
                let (utime, world_from_vehicle) =
                    pose_when_due(&motion, &world, config, (t0, dt, tick), *next_image);
                let request = FrameRequest {
                    utime,
                    world_from_vehicle,
                    stream: images + 1,
                };
                frames.render_ahead(&mut tiles, request);
            }
            if options.log_mode == LogMode::All {
                sink.log.message(
                    t,
                    &channels::range_image(&sensor.id),
                    &wire::range_image_to_wire(&image),
                );
            }
            pipeline.input(Input::Image(image), &mut sink);
            images += 1;
            image_positions.push([state.x, state.y]);
        }
        pipeline.run_until(t, &mut sink);
        for command in sink.commands.drain(..) {
            motion.command(command);
        }
        if let Some(e) = sink.log.error.take() {
            return Err(e);
        }
        let status = pipeline.behaviours.progress();
        if status.is_some_and(|p| p.complete) {
            outcome = Outcome::Completed;
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
                distance_m: distance,
                waypoint: status.map_or(0, |p| p.current),
                waypoints: world.waypoints.len(),
                speed_mps: state.speed_mps,
                time_limit_s: sim.time_limit_s,
            });
        }
        tick += 1;
        t = t0 + tick as i64 * dt;
    }
    let duration = micros_to_seconds(t - t0);
    let arbiter = pipeline.arbiter.stats();
    let mut stops = sink.stops;
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
    let reached = pipeline.behaviours.progress().map_or(0, |p| p.current);
    let drops = pipeline.perception.drops;
    let wall_time = wall.elapsed().as_secs_f64();
    let average_speed = if duration > 0.0 {
        distance / duration
    } else {
        0.0
    };
    let report = MissionReport {
        world: world.spec.name.clone(),
        sensor: sensors
            .iter()
            .map(|s| s.id.as_str())
            .collect::<Vec<_>>()
            .join("+"),
        success: outcome == Outcome::Completed && truth.collisions.is_empty(),
        outcome,
        waypoints_reached: reached,
        waypoints: world.waypoints.len(),
        distance_m: distance,
        duration_s: duration,
        average_speed_mps: average_speed,
        max_speed_mps: max_speed,
        cruise_mps: config.cruise.mps,
        cruise_asked_mps: config.cruise.asked_mps,
        cruise_cap_mps: config.cruise.cap_mps,
        images,
        images_dropped: drops.no_pose + drops.invalid + drops.out_of_order,
        slices: (pipeline.perception.slices.received > 0).then_some(pipeline.perception.slices),
        untraversable_cells: Reasons::ALL
            .iter()
            .zip(pipeline.perception.totals.by_reason)
            .map(|(&(_, name), count)| (name, u64::from(count)))
            .collect(),
        graded_cells: u64::from(pipeline.perception.totals.graded),
        suspected_drop_offs: u64::from(pipeline.perception.totals.suspected),
        collisions: truth.collisions.clone(),
        closest_approach_m: truth
            .closest_approach_m
            .is_finite()
            .then_some(truth.closest_approach_m),
        closest_approach: truth.closest_at.as_ref().map(|m| NearMissReport {
            at_s: micros_to_seconds(m.utime - t0),
            position: m.position,
            hazard: m.hazard.clone(),
        }),
        stops,
        ride: ride.report(),
        recovery,
        behaviour_counters,
        steering_activity: sink.curvature_change.0 / sink.curvature_change.1.max(1) as f64,
        map_resets: pipeline.cycle.counts().map_resets,
        localmap: *pipeline.cycle.map.map.stats(),
        stage_times: pipeline.times,
        images_rendered_ahead: frames.iter().map(|f| f.used).sum(),
        images_rendered_again: frames.iter().map(|f| f.wasted).sum(),
        render_ms_mean: if images > 0 {
            render_ms / images as f64
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
    };
    sink.log.finish()?;
    Ok(MissionRun {
        report,
        track: sink.track,
        image_positions,
        obstacle_patches: sink.patches,
        seen_patches: sink.seen.patches(),
        patch_size_m: config.localmap.patch_size_m,
        snapshots: sink.snapshots,
    })
}

/// Where the vehicle will be at the first pose tick at or after `due`, and
/// that tick's time, under the commands `motion` holds now: the mission
/// loop's steps (`(t0, dt, tick)`, the tick it is at) taken on a copy.
fn pose_when_due(
    motion: &MotionModel,
    world: &World,
    config: &Resolved,
    (t0, dt, mut tick): (Utime, Utime, u64),
    due: Utime,
) -> (Utime, Isometry) {
    let mut motion = motion.clone();
    let mut t = t0 + tick as i64 * dt;
    while t < due {
        tick += 1;
        t = t0 + tick as i64 * dt;
        motion.advance_to(t);
    }
    (
        t,
        drape(world, &config.vehicle, motion.state()).world_from_vehicle,
    )
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
