//! Replaying range-image logs against the pipeline.
//!
//! A log's POSE, RANGE_IMAGE* and WAYPOINTS drive the lock-step
//! [`arcnav_pipeline::Pipeline`] in log order, on the messages' own timestamps; OBSTACLE_CELLS,
//! ARC_VOTES_* and STEERING_COMMAND are recomputed (the recorded ones are
//! kept aside for comparison, or, with `recorded_cells`, the recorded cells
//! replace perception). The same log and configuration give the same output
//! byte for byte. Nothing in the input can panic the replay: damaged or
//! foreign input is skipped and counted, and the [`InputProblems`] say what
//! (`problems`); [`compare`] sets two runs' decisions side by side.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use arcnav_arbiter::{BehaviourVotes, Decision, Reason};
use arcnav_behaviours::{Mission, Overlay};
use arcnav_bus::log::{EventSource, InTimeOrder, LogReader, LogWriteError, ReorderWindow};
use arcnav_bus::messages::{AnyMessage, TypedEvent, TypedEvents, channels};
use arcnav_localmap::MapSnapshot;
use arcnav_perception::ObstacleReport;
use arcnav_vehicle::{ArcSet, ConfigError, Pose, SteeringCommand, Utime};
use serde::Serialize;

mod compare;
mod problems;

pub use compare::{Comparison, Cycle, Decided, Decisions, Difference, WeightOf, compare};
pub use problems::{InputProblems, LogSummary};

use crate::bag::{Bag, BagError, BagEvents, BagOptions, Format};
use crate::mission::GuardReport;
use crate::mission::guarded::{GuardWatch, Observed};
use crate::recorder::{Recorder, WriteFailed};
use arcnav_config::Resolved;
use arcnav_pipeline::{Input, Pipeline, Sink};
use arcnav_wire as wire;

/// How to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// Start this many seconds after the log's first message (state starts empty there).
    pub from_s: Option<f64>,
    /// Stop this many seconds after the log's first message.
    pub to_s: Option<f64>,
    /// Write the inputs and the recomputed outputs to this log.
    pub out: Option<PathBuf>,
    /// Waypoints to use instead of (or when the log has no) WAYPOINTS.
    pub waypoints: Option<Mission>,
    /// Pace the replay at this many times real time (default: as fast as possible).
    pub speed: Option<f64>,
    /// Feed the log's OBSTACLE_CELLS to the local map instead of recomputing
    /// them from range images.
    pub recorded_cells: bool,
    /// Keep the decision and map of the first cycle at or after this many
    /// seconds (for `arcnav render`), and stop there.
    pub stop_at_s: Option<f64>,
    /// Which topics and frames of a bag to use.
    pub bag: BagOptions,
    /// Without waypoints: one this many metres ahead of the first pose.
    pub goal_ahead_m: Option<f64>,
}

/// Inputs used.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct InputCounts {
    pub poses: u64,
    pub images: u64,
    /// Slices of range images (streamed, `range_slice_t`).
    pub slices: u64,
    pub waypoints: u64,
    pub recorded_cells: u64,
}

/// What a replay produced.
#[derive(Debug, Clone)]
pub struct ReplayResult {
    /// Recomputed decisions by run and time.
    pub cycles: Decisions,
    /// The log's own decisions by run and time (STEERING_COMMAND and
    /// ARC_VOTES_*).
    pub recorded: Decisions,
    /// Why each of them was what it was, by run and time (DECISION; logs
    /// written before it have none).
    pub recorded_reasons: BTreeMap<(u32, Utime), wire::RecordedDecision>,
    /// The vehicle-side guard's verdicts the log holds (GUARD_STATUS), in
    /// log order.
    pub recorded_guard: Vec<wire::RecordedGuard>,
    pub inputs: InputCounts,
    pub problems: InputProblems,
    /// First and last message time of the log, µs.
    pub span: Option<(Utime, Utime)>,
    /// With `stop_at_s`: the first pose's time, from which it counts (on
    /// the messages' clock), µs.
    pub clock_origin: Option<Utime>,
    /// The decision kept for `stop_at_s`.
    pub kept: Option<KeptDecision>,
    pub arcs: ArcSet,
    /// What each external behaviour did (`[behaviours.external.NAME]`):
    /// its counters, and why it ended if it did.
    pub external: Vec<ExternalRun>,
    /// What the guard would have done with the recomputed commands
    /// (`[guard] enabled`); its verdicts are in `--out`'s GUARD_STATUS.
    pub guard: Option<GuardReport>,
    /// Images of different sensors judged together in one height map
    /// (`perception.fuse_within_s`); absent when it is 0.
    pub fused: Option<arcnav_pipeline::FusionCounts>,
}

/// What an external behaviour did in a replay.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExternalRun {
    pub name: String,
    pub counters: Vec<(&'static str, u64)>,
    pub fault: Option<String>,
}

/// The first decision at or after `stop_at_s`, with what a picture of it
/// needs.
#[derive(Debug, Clone)]
pub struct KeptDecision {
    pub at: Utime,
    pub decision: Decision,
    /// Why, as DECISION says it.
    pub reason: Reason,
    pub map: MapSnapshot,
    /// What each behaviour's vote rested on (those that show anything).
    pub overlays: Vec<(String, Overlay)>,
}

impl From<WriteFailed> for ReplayError {
    fn from(WriteFailed { path, source }: WriteFailed) -> Self {
        Self::Write { path, source }
    }
}

/// A replay that could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("cannot read the log {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write the log {path}: {source}")]
    Write {
        path: PathBuf,
        source: LogWriteError,
    },
    #[error("cannot create the log {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    External(#[from] crate::external::ExternalError),
    #[error(transparent)]
    Bag(#[from] BagError),
    #[error("--goal-ahead: the bag holds no pose to place the goal from")]
    NoFirstPose,
}

struct ReplaySink<'a> {
    /// The output log, and the first error of the replay.
    out: Recorder<'a, ReplayError>,
    /// How commands go on the wire (`[vehicle] kinematics`).
    kinematics: arcnav_vehicle::Kinematics,
    arcs: ArcSet,
    cycles: Decisions,
    /// The run of the log being replayed (see [`Decisions`]).
    run: u32,
    /// Before `--from`: decisions are not kept.
    warming: bool,
    pending_votes: Vec<BehaviourVotes>,
    keep_at: Option<Utime>,
    kept: Option<KeptDecision>,
    /// The overlays of the cycle about to be decided, when it may be kept.
    overlays: Vec<(String, Overlay)>,
    /// The guard, judging every recomputed command on the log's returns
    /// (`[guard] enabled`), and the first pose's time.
    guard: Option<GuardWatch>,
    first_pose: Option<Utime>,
}

impl Sink for ReplaySink<'_> {
    fn on_obstacles(&mut self, at: Utime, report: &ObstacleReport) {
        self.out.obstacles(at, report);
    }

    fn on_votes(&mut self, at: Utime, votes: &[BehaviourVotes]) {
        self.out.votes(at, votes, &self.arcs);
        self.pending_votes = votes.to_vec();
    }

    fn wants_overlays(&self, at: Utime) -> bool {
        self.kept.is_none() && self.keep_at.is_some_and(|keep| at >= keep)
    }

    fn on_overlays(&mut self, _at: Utime, overlays: Vec<(String, Overlay)>) {
        self.overlays = overlays;
    }

    fn on_command(
        &mut self,
        at: Utime,
        command: &SteeringCommand,
        reason: &Reason,
        decision: Option<&Decision>,
        map: &MapSnapshot,
    ) {
        self.out.command(at, command, self.kinematics, reason);
        if self.warming {
            return;
        }
        if let Some(guard) = &mut self.guard {
            let p = map.world_from_vehicle.translation.vector;
            let t0 = self.first_pose.unwrap_or(at);
            guard.judge(command, at, t0, [p.x, p.y]);
            for status in guard.said() {
                self.out.message(at, channels::GUARD_STATUS, &status);
            }
        }
        self.cycles.insert(
            (self.run, at),
            Cycle {
                command: *command,
                votes: std::mem::take(&mut self.pending_votes),
            },
        );
        if let (Some(keep), None, Some(decision)) = (self.keep_at, &self.kept, decision)
            && at >= keep
        {
            self.kept = Some(KeptDecision {
                at,
                decision: decision.clone(),
                reason: reason.clone(),
                map: map.clone(),
                overlays: std::mem::take(&mut self.overlays),
            });
        }
    }
}

/// A waypoints file that cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{0} (a waypoints file holds [[waypoints]] tables with position_m = [x, y])")]
pub struct WaypointsError(String);

/// Waypoints from the text of a TOML file with `[[waypoints]]` entries (a
/// world file works).
pub fn parse_waypoints(text: &str) -> Result<Mission, WaypointsError> {
    #[derive(serde::Deserialize)]
    struct File {
        waypoints: Vec<arcnav_sim::world::WaypointSpec>,
    }
    let file: File = toml::from_str(text).map_err(|e| WaypointsError(e.message().to_owned()))?;
    if file.waypoints.is_empty() {
        return Err(WaypointsError("no [[waypoints]]".into()));
    }
    for (i, w) in file.waypoints.iter().enumerate() {
        if let Some(problem) = w.problem() {
            return Err(WaypointsError(format!("waypoint {}: {problem}", i + 1)));
        }
    }
    Ok(Mission {
        version: 1,
        waypoints: file
            .waypoints
            .iter()
            .map(|w| arcnav_behaviours::Waypoint {
                x: w.position_m[0],
                y: w.position_m[1],
                radius_m: w.radius_m,
            })
            .collect(),
    })
}

/// The longest step of log time `--speed` waits out, µs.
const MAX_PACED_STEP_US: Utime = 60_000_000;

/// What a replay takes from its log, besides the decisions it makes.
#[derive(Default)]
struct Fed {
    inputs: InputCounts,
    problems: InputProblems,
    /// The log's own decisions, by their cycle's time.
    recorded: Decisions,
    /// The run of the log being read (see [`Decisions`]).
    run: u32,
    /// Before `--from`: the log's own decisions are not kept.
    warming: bool,
    /// Recorded votes whose command has not been read yet.
    recorded_votes: BTreeMap<Utime, Vec<BehaviourVotes>>,
    /// Recorded obstacle cells (recomputed, unless replayed as they were).
    recorded_cells: u64,
    /// The log's own DECISION messages, by run and time.
    recorded_reasons: BTreeMap<(u32, Utime), wire::RecordedDecision>,
    /// The log's GUARD_STATUS messages, in log order.
    recorded_guard: Vec<wire::RecordedGuard>,
}

/// How a replay takes its events.
struct Taking<'a> {
    /// The log's recorded obstacle cells are fed instead of its range data.
    recorded_cells: bool,
    /// Waypoints were given: the log's own are not fed.
    waypoints_given: bool,
    arcs: &'a ArcSet,
}

/// The guard takes an image or slice at `utime` after the pipeline has
/// decided every cycle before it (what the pipeline does first with one),
/// so that the commands of those cycles are judged without it, as they
/// would be live.
fn guard_takes(
    pipeline: &mut Pipeline,
    sink: &mut ReplaySink<'_>,
    utime: Utime,
    input: Observed<'_>,
) {
    if sink.guard.is_none() {
        return;
    }
    pipeline.run_until(utime - 1, sink);
    if let Some(guard) = &mut sink.guard {
        guard.observe_one(input);
    }
}

/// One event of the log within the replay's window: fed to the pipeline
/// (and copied to the output log), kept as a recorded decision, or counted
/// as a problem.
fn take(
    event: TypedEvent,
    how: Taking<'_>,
    pipeline: &mut Pipeline,
    sink: &mut ReplaySink<'_>,
    fed: &mut Fed,
) {
    let t = event.timestamp;
    let channel = event.channel.as_str();
    if !event.message.on_its_channel(channel) {
        *fed.problems.foreign.entry(event.channel).or_default() += 1;
        return;
    }
    match event.message {
        AnyMessage::Pose(msg) => match Pose::try_from(&msg) {
            Ok(pose) => {
                fed.inputs.poses += 1;
                sink.out.message(t, channel, &msg);
                sink.first_pose.get_or_insert(pose.utime);
                // The pose's own cycles are the pipeline's to run (a jump
                // ahead skips some): the guard takes it after them.
                pipeline.input(Input::Pose(pose), sink);
                if let Some(guard) = &mut sink.guard {
                    guard.observe_one(Observed::Pose(&pose));
                }
            }
            Err(e) => {
                tracing::debug!(%e, "invalid pose skipped");
                fed.problems.invalid_poses += 1;
            }
        },
        AnyMessage::RangeImage(msg) if !how.recorded_cells => {
            let encoded = arcnav_bus::Message::encode(&msg).unwrap_or_default();
            match wire::range_image_from_wire(msg) {
                Ok(image) => {
                    fed.inputs.images += 1;
                    sink.out.event(t, channel, &encoded);
                    guard_takes(pipeline, sink, image.utime, Observed::Image(&image));
                    pipeline.input(Input::Image(image), sink);
                }
                Err(e) => {
                    tracing::debug!(%e, "invalid range image skipped");
                    fed.problems.invalid_images += 1;
                }
            }
        }
        AnyMessage::RangeSlice(msg) if !how.recorded_cells => {
            let encoded = arcnav_bus::Message::encode(&msg).unwrap_or_default();
            match wire::range_slice_from_wire(msg) {
                Ok(slice) => {
                    fed.inputs.slices += 1;
                    sink.out.event(t, channel, &encoded);
                    guard_takes(pipeline, sink, slice.utime, Observed::Slice(&slice));
                    pipeline.input(Input::Slice(slice), sink);
                }
                Err(e) => {
                    tracing::debug!(%e, "invalid range slice skipped");
                    fed.problems.invalid_slices += 1;
                }
            }
        }
        AnyMessage::ObstacleCells(msg) if how.recorded_cells => {
            match wire::obstacles_from_wire(msg) {
                Ok(report) => {
                    fed.inputs.recorded_cells += 1;
                    sink.on_obstacles(t, &report);
                    pipeline.input(Input::Obstacles(report), sink);
                }
                Err(_) => *fed.problems.undecodable.entry(event.channel).or_default() += 1,
            }
        }
        AnyMessage::Waypoints(msg) if !how.waypoints_given => match wire::mission_from_wire(&msg) {
            Ok(mission) => {
                fed.inputs.waypoints += 1;
                sink.out.message(t, channel, &msg);
                pipeline.input(Input::Waypoints(mission), sink);
            }
            Err(_) => *fed.problems.undecodable.entry(event.channel).or_default() += 1,
        },
        // Decisions are keyed by their cycle's time (the message's own
        // utime), as the replayed ones are: a logger stamps events when
        // it receives them, later than the cycle.
        AnyMessage::SteeringCommand(_) | AnyMessage::DriveCommand(_) if fed.warming => {}
        AnyMessage::ArcVotes(_) if fed.warming => {}
        AnyMessage::Decision(_) | AnyMessage::GuardStatus(_) if fed.warming => {}
        AnyMessage::GuardStatus(msg) => match wire::guard_status_from_wire(&msg) {
            Ok(status) => fed.recorded_guard.push(status),
            Err(_) => *fed.problems.undecodable.entry(event.channel).or_default() += 1,
        },
        AnyMessage::Decision(msg) => match wire::decision_from_wire(&msg) {
            Ok(decision) => {
                fed.recorded_reasons
                    .insert((fed.run, decision.utime), decision);
            }
            Err(_) => *fed.problems.undecodable.entry(event.channel).or_default() += 1,
        },
        AnyMessage::SteeringCommand(_) | AnyMessage::DriveCommand(_) => {
            let Some(command) = event.message.as_command() else {
                unreachable!("a command message")
            };
            fed.recorded.insert(
                (fed.run, command.utime),
                Cycle {
                    command,
                    votes: fed
                        .recorded_votes
                        .remove(&command.utime)
                        .unwrap_or_default(),
                },
            );
        }
        AnyMessage::ArcVotes(msg) => {
            if let Ok(votes) = wire::votes_from_wire(&msg, how.arcs) {
                fed.recorded_votes
                    .entry(votes.utime)
                    .or_default()
                    .push(votes);
            }
        }
        // Recomputed by the replay: the recorded ones are replaced.
        AnyMessage::ObstacleCells(_) => fed.recorded_cells += 1,
        AnyMessage::RangeImage(_)
        | AnyMessage::RangeSlice(_)
        | AnyMessage::Waypoints(_)
        | AnyMessage::LocalMap(_) => {
            *fed.problems.ignored.entry(event.channel).or_default() += 1;
        }
    }
}

/// The problems the pipeline and the log reader counted, added to those
/// the replay met.
fn tally<S: EventSource>(
    fed: &mut Fed,
    pipeline: &Pipeline,
    events: &TypedEvents<InTimeOrder<S>>,
    recorded_cells: bool,
) {
    let Fed {
        inputs,
        problems,
        recorded_cells: cells,
        ..
    } = fed;
    let drops = pipeline.perception.drops;
    problems.images_without_pose = drops.no_pose;
    problems.images_out_of_order = drops.out_of_order;
    // Past the sensors the local map tracks: refused like an invalid image
    // (said on stderr with the sensor's name).
    problems.invalid_images += drops.invalid + drops.too_many_sensors;
    let slices = pipeline.perception.slices;
    problems.invalid_slices += slices.invalid;
    problems.slices_out_of_order = slices.stream.out_of_order + slices.stream.inconsistent;
    problems.lost_slice_lines = slices.stream.lost_lines;
    let counts = pipeline.cycle.counts();
    problems.map_resets = counts.map_resets;
    problems.skipped_cycles = counts.skipped_cycles;
    problems.clock_restarts = counts.restarts;
    problems.reports_refused = pipeline.cycle.map.map.stats().reports_refused;
    problems.log = events.log_stats().into();
    problems.no_poses = inputs.poses == 0;
    problems.images_unplaced =
        pipeline.perception.waiting() as u64 + pipeline.perception.drops.clock_restart;
    let order = *events.source().order();
    problems.reordered = order.reordered;
    problems.max_reorder_lag_s = order.max_lag_us as f64 * 1e-6;
    problems.fed_late = order.beyond_window;
    problems.log_restarts = order.restarts;
    if inputs.images == 0 && inputs.slices == 0 && !recorded_cells {
        problems.cells_unused = *cells;
    }
    // On a channel the replay takes its input from (POSE, RANGE_IMAGE*,
    // WAYPOINTS) a message of no arcnav type is damaged input (a POSE
    // whose fingerprint was damaged had been skipped as "unknown"): lost.
    for (channel, n) in &events.stats().unknown {
        let lost = arcnav_bus::messages::channels::is_input(channel);
        let counts = if lost {
            &mut problems.undecodable
        } else {
            &mut problems.unknown_channels
        };
        *counts.entry(channel.clone()).or_default() += n;
    }
    for (channel, n) in &events.stats().undecodable {
        *problems.undecodable.entry(channel.clone()).or_default() += n;
    }
}

/// With `stop_at_s`, how far past the kept decision the log is read for
/// what was said of it (DECISION, GUARD_STATUS), µs of message time.
const RECORDED_AFTER_US: Utime = 1_000_000;

/// Replays the log at `path`: an LCM log, or a ROS 2 bag (MCAP).
pub fn replay(
    path: &Path,
    config: &Resolved,
    options: &ReplayOptions,
    progress: &mut dyn FnMut(u64),
) -> Result<ReplayResult, ReplayError> {
    let read = |source| ReplayError::Read {
        path: path.to_owned(),
        source,
    };
    if crate::bag::format_of(path).map_err(read)? != Format::Other {
        return replay_bag(path, config, options, progress);
    }
    let reader = LogReader::open(path).map_err(read)?;
    let events = TypedEvents::new(InTimeOrder::new(reader, ReorderWindow::default()));
    replay_events(path, events, config, options, progress, |_| None)
}

/// [`replay`] of a bag: its clouds and poses as the events of a log.
fn replay_bag(
    path: &Path,
    config: &Resolved,
    options: &ReplayOptions,
    progress: &mut dyn FnMut(u64),
) -> Result<ReplayResult, ReplayError> {
    let bag = Bag::open(path)?;
    let sensor = config.sensors.first().ok_or_else(|| {
        BagError::Choice("the configuration has no sensor to make the clouds images of".into())
    })?;
    let plan = bag.plan(&options.bag, sensor)?;
    let mut options = options.clone();
    if let (Some(ahead), None) = (options.goal_ahead_m, &options.waypoints) {
        let first = plan.first_pose(&bag)?.ok_or(ReplayError::NoFirstPose)?;
        options.waypoints = Some(goal_ahead(&first, ahead));
    }
    let events = TypedEvents::new(InTimeOrder::new(
        bag.events(&plan)?,
        ReorderWindow::default(),
    ));
    let summary = |events: &TypedEvents<InTimeOrder<BagEvents<'_>>>| {
        Some(events.source().source().summary().clone())
    };
    replay_events(path, events, config, &options, progress, summary)
}

/// One waypoint `ahead` metres along the heading of `pose`.
pub fn goal_ahead(pose: &arcnav_vehicle::Pose, ahead: f64) -> Mission {
    let p = pose.world_from_vehicle * nalgebra::Point3::new(ahead, 0.0, 0.0);
    Mission {
        version: 1,
        waypoints: vec![arcnav_behaviours::Waypoint {
            x: p.x,
            y: p.y,
            radius_m: None,
        }],
    }
}

/// Replays `events` (read from `path`); `bag` gives a bag's summary at
/// the end.
fn replay_events<S: EventSource>(
    path: &Path,
    mut events: TypedEvents<InTimeOrder<S>>,
    config: &Resolved,
    options: &ReplayOptions,
    progress: &mut dyn FnMut(u64),
    bag: impl Fn(&TypedEvents<InTimeOrder<S>>) -> Option<crate::bag::BagSummary>,
) -> Result<ReplayResult, ReplayError> {
    let mut pipeline = config.lockstep()?;
    crate::external::attach(config, &mut pipeline)?;
    pipeline.set_explain(options.stop_at_s.is_some());
    let arcs = pipeline.arcs().clone();
    let out = Recorder::create(options.out.as_deref())
        .map_err(|(path, source)| ReplayError::Create { path, source })?;
    let mut sink = ReplaySink {
        out,
        kinematics: config.vehicle.kinematics,
        arcs: arcs.clone(),
        cycles: Decisions::new(),
        run: 0,
        warming: false,
        pending_votes: Vec::new(),
        keep_at: None,
        kept: None,
        overlays: Vec::new(),
        guard: GuardWatch::new(config, &config.sensors),
        first_pose: None,
    };
    let mut fed = Fed::default();
    let mut span: Option<(Utime, Utime)> = None;
    let mut waypoints_given = false;
    let mut past_to = false;
    if let Some(mission) = &options.waypoints {
        pipeline.input(Input::Waypoints(mission.clone()), &mut sink);
        waypoints_given = true;
        fed.inputs.waypoints += 1;
    }
    let (wall_start, mut first_time) = (Instant::now(), None::<Utime>);
    let mut last_progress = 0;
    let mut paced: Option<(Utime, Utime)> = None;
    let mut clock_origin: Option<Utime> = None;
    while let Some(event) = events.next() {
        let event = event.map_err(|source| ReplayError::Read {
            path: path.to_owned(),
            source,
        })?;
        let t = event.timestamp;
        // Each time the log starts over, a new run of it (logs concatenated).
        let run = u32::try_from(events.source().order().restarts).unwrap_or(u32::MAX);
        if run != fed.run {
            // The last run's cycles due by its newest pose are its own.
            if let Some(newest) = pipeline.pose().map(|p| p.utime) {
                pipeline.run_until(newest, &mut sink);
            }
            fed.recorded_votes.clear();
        }
        (sink.run, fed.run) = (run, run);
        let origin = *first_time.get_or_insert(t);
        // The pace's origin, shifted past jumps, and the newest time paced.
        let paced = paced.get_or_insert((t, t));
        span = Some(span.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
        let since = (t - origin) as f64 * 1e-6;
        // Before --from the log brings the pipeline to its state at --from
        // (the map, the progress along the waypoints, each behaviour's
        // memory); its decisions are not kept nor written. Skipped, the
        // vehicle had steered back to the first waypoint, behind it.
        let warming = options.from_s.is_some_and(|from| since < from);
        fed.problems.before_window += u64::from(warming);
        (sink.warming, fed.warming, sink.out.paused) = (warming, warming, warming);
        if options.to_s.is_some_and(|to| since > to) {
            // Past the end: one event alone may be a damaged time (a flipped
            // bit); two in a row end the replay.
            fed.problems.outside_window += 1;
            if past_to {
                break;
            }
            past_to = true;
            continue;
        }
        past_to = false;
        if options.stop_at_s.is_some()
            && let Some(kept) = &sink.kept
        {
            // What the run said of the kept decision comes after it: the
            // vehicle's guard judges a command for as long as it holds it.
            // Read on, feeding nothing, while the messages are of the
            // decision's next second.
            if event.message.utime() > kept.at + RECORDED_AFTER_US {
                break;
            }
            match event.message {
                AnyMessage::Decision(_) | AnyMessage::GuardStatus(_) => {}
                _ => continue,
            }
        }
        if let Some(speed) = options.speed.filter(|_| !warming) {
            // Log time jumping ahead by more than a minute (a gap, a corrupt
            // time) is not waited out: the pace carries on from there.
            let step = t - paced.1;
            if step > MAX_PACED_STEP_US {
                tracing::warn!(
                    jump_s = step as f64 * 1e-6,
                    "the log's time jumps ahead: not waited for"
                );
                paced.0 += step;
            }
            paced.1 = paced.1.max(t);
            let due = Duration::try_from_secs_f64((t - paced.0) as f64 * 1e-6 / speed);
            if let Some(wait) = due.ok().and_then(|d| d.checked_sub(wall_start.elapsed())) {
                std::thread::sleep(wait);
            }
        }
        let position = events.position();
        if position - last_progress > 1 << 20 {
            last_progress = position;
            progress(position);
        }
        take(
            event,
            Taking {
                recorded_cells: options.recorded_cells,
                waypoints_given,
                arcs: &arcs,
            },
            &mut pipeline,
            &mut sink,
            &mut fed,
        );
        // `stop_at_s` counts from the first pose, on the pipeline's clock
        // (the messages' own times: a log recorded with lcm-logger stamps
        // its events with the wall clock of the recording instead).
        if let (Some(at), None, Some(pose)) = (options.stop_at_s, sink.keep_at, pipeline.pose()) {
            clock_origin = Some(pose.utime);
            sink.keep_at = Some(pose.utime.saturating_add((at * 1e6) as Utime));
        }
        if let Some(e) = sink.out.error.take() {
            return Err(e);
        }
    }
    // The cycles due by the newest pose (of the last run, when the log
    // starts over; never those an absurd pose time would claim).
    // A frame whose last slices the log does not hold ends here.
    pipeline.flush(&mut sink);
    if let Some(newest) = pipeline.pose().map(|p| p.utime) {
        pipeline.run_until(newest, &mut sink);
    }
    sink.out.paused = false;
    sink.out.finish()?;
    tally(&mut fed, &pipeline, &events, options.recorded_cells);
    fed.problems.bag = bag(&events);
    fed.problems.window_empty = fed.problems.before_window > 0 && sink.cycles.is_empty();
    Ok(ReplayResult {
        cycles: sink.cycles,
        recorded: fed.recorded,
        recorded_reasons: fed.recorded_reasons,
        recorded_guard: fed.recorded_guard,
        clock_origin,
        inputs: fed.inputs,
        problems: fed.problems,
        span,
        kept: sink.kept,
        arcs,
        external: external_runs(config, &pipeline),
        guard: sink.guard.as_ref().map(GuardWatch::report),
        fused: pipeline.perception.fusion(),
    })
}

/// The external behaviours' counters and faults, in name order.
fn external_runs(config: &Resolved, pipeline: &arcnav_pipeline::Pipeline) -> Vec<ExternalRun> {
    let counters = pipeline.behaviours.counters();
    let faults = pipeline.behaviours.faults();
    config
        .external
        .keys()
        .map(|name| ExternalRun {
            name: name.clone(),
            counters: counters
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, c)| c.clone())
                .unwrap_or_default(),
            fault: faults
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, why)| (*why).to_owned()),
        })
        .collect()
}
