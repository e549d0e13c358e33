//! Replaying range-image logs against the pipeline.
//!
//! A log's POSE, RANGE_IMAGE* and WAYPOINTS drive the lock-step
//! [`arcnav_pipeline::Pipeline`] in log order, on the messages' own timestamps; OBSTACLE_CELLS,
//! ARC_VOTES_* and STEERING_COMMAND are recomputed (the recorded ones are
//! kept aside for comparison, or, with `recorded_cells`, the recorded cells
//! replace perception). The same log and configuration give the same output
//! byte for byte. Nothing in the input can panic the replay: damaged or
//! foreign input is skipped and counted, and the [`InputProblems`] say what.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use arcnav_arbiter::{BehaviourVotes, Decision};
use arcnav_behaviours::{Mission, Registry};
use arcnav_bus::lcmtypes::steering_command_t;
use arcnav_bus::log::{InTimeOrder, LogReader, LogStats, LogWriteError, ReorderWindow};
use arcnav_bus::messages::{AnyMessage, TypedEvents, channels};
use arcnav_localmap::MapSnapshot;
use arcnav_perception::ObstacleReport;
use arcnav_vehicle::{ArcSet, ConfigError, Pose, SteeringCommand, Utime};
use serde::Serialize;

use crate::config::Config;
use crate::recorder::{Recorder, WriteFailed};
use crate::wire;
use arcnav_pipeline::{Input, Sink};

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
}

/// What could not be used, and why. Any of it but `unknown_channels` and
/// `ignored` means input was lost.
#[derive(Debug, Clone, Default, Serialize)]
pub struct InputProblems {
    pub log: LogSummary,
    /// Messages of types arcnav does not know, per channel (e.g. LCM_SELF_TEST).
    pub unknown_channels: BTreeMap<String, u64>,
    /// Messages with a known fingerprint that do not decode, per channel.
    pub undecodable: BTreeMap<String, u64>,
    /// Poses that are not poses (bad quaternion, non-finite values).
    pub invalid_poses: u64,
    /// Range images that are not images (bad mount, sizes, angles).
    pub invalid_images: u64,
    /// Images with no pose around their capture time.
    pub images_without_pose: u64,
    /// Images older than one already evaluated from the same sensor.
    pub images_out_of_order: u64,
    /// Times the pose jumped or ran backwards and the local map was reset.
    pub map_resets: u64,
    /// Known messages the replay does not consume (e.g. LOCAL_MAP), per channel.
    pub ignored: BTreeMap<String, u64>,
    /// Messages of a known type on a channel that is not arcnav's for that
    /// type (`POSE_GPS_RAW`, `STEERING_COMMAND_TELEOP`), per channel: another
    /// program's, skipped.
    pub foreign: BTreeMap<String, u64>,
    /// Events that came in the file after events logged later, fed in time
    /// order (nothing lost).
    pub reordered: u64,
    /// The largest such lag, s.
    pub max_reorder_lag_s: f64,
    /// Events further out of time order than the reader's window: fed late,
    /// after decisions that should have seen them.
    pub fed_late: u64,
    /// Times the log starts over (a channel goes back in time: logs
    /// concatenated): replayed as consecutive runs.
    pub log_restarts: u64,
    /// Decision cycles not run because the pose clock jumped ahead by more
    /// than a second (a gap in the log, a corrupt time).
    pub skipped_cycles: u64,
    /// Times the pose clock went backwards and the cycle clock restarted.
    pub clock_restarts: u64,
    /// Obstacle reports the local map refused (see the log at -v).
    pub reports_refused: u64,
    /// OBSTACLE_CELLS in a log with no range image, replayed without
    /// `--recorded-cells`: nothing was perceived.
    pub cells_unused: u64,
    /// The log holds no pose: nothing could be placed or decided.
    pub no_poses: bool,
    /// Images still waiting for the pose at their capture time when the log
    /// ended or started over (the pose stream stops before them).
    pub images_unplaced: u64,
}

/// The log reader's counts.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct LogSummary {
    pub events: u64,
    pub skipped_bytes: u64,
    pub corrupt_events: u64,
    pub truncated_tail_bytes: u64,
}

impl From<&LogStats> for LogSummary {
    fn from(s: &LogStats) -> Self {
        Self {
            events: s.events,
            skipped_bytes: s.skipped_bytes,
            corrupt_events: s.corrupt_events,
            truncated_tail_bytes: s.truncated_tail_bytes,
        }
    }
}

impl InputProblems {
    /// True when some input could not be used.
    pub fn lost_input(&self) -> bool {
        self.log.skipped_bytes > 0
            || self.log.corrupt_events > 0
            || self.log.truncated_tail_bytes > 0
            || !self.undecodable.is_empty()
            || self.invalid_poses > 0
            || self.invalid_images > 0
            || self.images_without_pose > 0
            || self.images_out_of_order > 0
            || self.fed_late > 0
            || self.reports_refused > 0
            || self.cells_unused > 0
            || self.no_poses
            || self.images_unplaced > 0
    }

    /// One line per problem, for the summary.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let l = &self.log;
        if l.skipped_bytes > 0 {
            lines.push(format!(
                "{} bytes of damaged log skipped ({} corrupt events)",
                l.skipped_bytes, l.corrupt_events
            ));
        }
        if l.truncated_tail_bytes > 0 {
            lines.push(format!(
                "log ends mid-event: {} bytes of a truncated last event",
                l.truncated_tail_bytes
            ));
        }
        for (channel, n) in &self.undecodable {
            lines.push(format!("{n} undecodable message(s) on {channel}"));
        }
        if self.reordered > 0 {
            lines.push(format!(
                "{} event(s) stood in the file after events logged up to {:.2} s later: fed in time order",
                self.reordered, self.max_reorder_lag_s
            ));
        }
        if self.log_restarts > 0 {
            lines.push(format!(
                "the log starts over {} time(s) (its channels go back in time): replayed as consecutive runs",
                self.log_restarts
            ));
        }
        if self.skipped_cycles > 0 {
            lines.push(format!(
                "{} decision cycle(s) skipped: the pose clock jumped ahead by more than 1 s",
                self.skipped_cycles
            ));
        }
        if self.clock_restarts > 0 {
            lines.push(format!(
                "the pose clock went backwards {} time(s): the decision cycle restarted there",
                self.clock_restarts
            ));
        }
        if self.reports_refused > 0 {
            lines.push(format!(
                "{} obstacle report(s) refused by the local map (-v says why)",
                self.reports_refused
            ));
        }
        if self.log.events == 0 {
            lines.push(format!(
                "no LCM event could be read from the log ({} bytes skipped as damaged): is it an LCM log?",
                self.log.skipped_bytes + self.log.truncated_tail_bytes
            ));
        } else if self.no_poses {
            lines.push("the log holds no POSE: nothing could be placed or decided".into());
        }
        if self.images_unplaced > 0 {
            lines.push(format!(
                "{} image(s) never evaluated: the pose stream ends before their capture time",
                self.images_unplaced
            ));
        }
        if self.cells_unused > 0 {
            lines.push(format!(
                "the log holds {} OBSTACLE_CELLS and no range image: nothing was perceived (replay with --recorded-cells to use them)",
                self.cells_unused
            ));
        }
        if self.fed_late > 0 {
            lines.push(format!(
                "{} event(s) further out of time order than the reader's window: fed late",
                self.fed_late
            ));
        }
        for (what, n) in [
            ("invalid pose(s)", self.invalid_poses),
            ("invalid range image(s)", self.invalid_images),
            (
                "image(s) skipped: no pose around the capture time",
                self.images_without_pose,
            ),
            (
                "image(s) skipped: older than one already evaluated",
                self.images_out_of_order,
            ),
            (
                "local map reset(s): the pose jumped or ran backwards",
                self.map_resets,
            ),
        ] {
            if n > 0 {
                lines.push(format!("{n} {what}"));
            }
        }
        for (channel, n) in &self.unknown_channels {
            lines.push(format!(
                "{n} message(s) of an unknown type on {channel} (skipped)"
            ));
        }
        for (channel, n) in &self.ignored {
            lines.push(format!("{n} message(s) on {channel} not used by replay"));
        }
        for (channel, n) in &self.foreign {
            lines.push(format!(
                "{n} message(s) on {channel}, not an arcnav channel for their type (another program's: skipped)"
            ));
        }
        lines
    }
}

/// Inputs used.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct InputCounts {
    pub poses: u64,
    pub images: u64,
    pub waypoints: u64,
    pub recorded_cells: u64,
}

/// One decision of a replay.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    pub command: SteeringCommand,
    pub votes: Vec<BehaviourVotes>,
}

/// What a replay produced.
#[derive(Debug, Clone)]
pub struct ReplayResult {
    /// Recomputed decisions by time.
    pub cycles: BTreeMap<Utime, Cycle>,
    /// The log's own decisions by time (STEERING_COMMAND and ARC_VOTES_*).
    pub recorded: BTreeMap<Utime, Cycle>,
    pub inputs: InputCounts,
    pub problems: InputProblems,
    /// First and last message time of the log, µs.
    pub span: Option<(Utime, Utime)>,
    /// The decision and map kept for `stop_at_s`.
    pub kept: Option<(Utime, Decision, MapSnapshot)>,
    pub arcs: ArcSet,
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
}

struct ReplaySink<'a> {
    /// The output log, and the first error of the replay.
    out: Recorder<'a, ReplayError>,
    arcs: ArcSet,
    cycles: BTreeMap<Utime, Cycle>,
    pending_votes: Vec<BehaviourVotes>,
    keep_at: Option<Utime>,
    kept: Option<(Utime, Decision, MapSnapshot)>,
}

impl Sink for ReplaySink<'_> {
    fn on_obstacles(&mut self, at: Utime, report: &ObstacleReport) {
        self.out.obstacles(at, report);
    }

    fn on_votes(&mut self, at: Utime, votes: &[BehaviourVotes]) {
        self.out.votes(at, votes, &self.arcs);
        self.pending_votes = votes.to_vec();
    }

    fn on_command(
        &mut self,
        at: Utime,
        command: &SteeringCommand,
        decision: Option<&Decision>,
        map: &MapSnapshot,
    ) {
        self.out.message(
            at,
            channels::STEERING_COMMAND,
            &steering_command_t::from(command),
        );
        self.cycles.insert(
            at,
            Cycle {
                command: *command,
                votes: std::mem::take(&mut self.pending_votes),
            },
        );
        if let (Some(keep), None, Some(decision)) = (self.keep_at, &self.kept, decision)
            && at >= keep
        {
            self.kept = Some((at, decision.clone(), map.clone()));
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

/// Replays the log at `path`.
pub fn replay(
    path: &Path,
    config: &Config,
    registry: &Registry,
    options: &ReplayOptions,
    progress: &mut dyn FnMut(u64),
) -> Result<ReplayResult, ReplayError> {
    let reader = LogReader::open(path).map_err(|source| ReplayError::Read {
        path: path.to_owned(),
        source,
    })?;
    let mut events = TypedEvents::new(InTimeOrder::new(reader, ReorderWindow::default()));
    let mut pipeline = config.lockstep(registry)?;
    pipeline.set_explain(options.stop_at_s.is_some());
    let arcs = pipeline.arcs().clone();
    let out = Recorder::create(options.out.as_deref())
        .map_err(|(path, source)| ReplayError::Create { path, source })?;
    let mut sink = ReplaySink {
        out,
        arcs: arcs.clone(),
        cycles: BTreeMap::new(),
        pending_votes: Vec::new(),
        keep_at: None,
        kept: None,
    };
    let mut recorded: BTreeMap<Utime, Cycle> = BTreeMap::new();
    let mut recorded_votes: BTreeMap<Utime, Vec<BehaviourVotes>> = BTreeMap::new();
    let (mut inputs, mut problems) = (InputCounts::default(), InputProblems::default());
    let mut span: Option<(Utime, Utime)> = None;
    let mut waypoints_given = false;
    let mut recorded_cells = 0u64;
    let mut skipped_mission = None;
    let mut past_to = false;
    if let Some(mission) = &options.waypoints {
        pipeline.input(Input::Waypoints(mission.clone()), &mut sink);
        waypoints_given = true;
        inputs.waypoints += 1;
    }
    let (wall_start, mut first_time) = (Instant::now(), None::<Utime>);
    let mut last_progress = 0;
    let mut paced: Option<(Utime, Utime)> = None;
    while let Some(event) = events.next() {
        let event = event.map_err(|source| ReplayError::Read {
            path: path.to_owned(),
            source,
        })?;
        let t = event.timestamp;
        let origin = *first_time.get_or_insert(t);
        // The pace's origin, shifted past jumps, and the newest time paced.
        let paced = paced.get_or_insert((t, t));
        span = Some(span.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
        let since = (t - origin) as f64 * 1e-6;
        if options.from_s.is_some_and(|from| since < from) {
            // The mission in force at --from still holds there: the newest
            // waypoints before it are fed when the replay starts.
            if let AnyMessage::Waypoints(msg) = &event.message
                && !waypoints_given
                && event.message.on_its_channel(&event.channel)
            {
                skipped_mission = Some((t, event.channel.clone(), msg.clone()));
            }
            continue;
        }
        if let Some((at, channel, msg)) = skipped_mission.take() {
            match wire::mission_from_wire(&msg) {
                Ok(mission) => {
                    inputs.waypoints += 1;
                    sink.out.message(at, &channel, &msg);
                    pipeline.input(Input::Waypoints(mission), &mut sink);
                }
                Err(_) => *problems.undecodable.entry(channel).or_default() += 1,
            }
        }
        if options.to_s.is_some_and(|to| since > to) {
            // Past the end: one event alone may be a damaged time (a flipped
            // bit); two in a row end the replay.
            if past_to {
                break;
            }
            past_to = true;
            continue;
        }
        past_to = false;
        if let Some(at) = options.stop_at_s {
            sink.keep_at = Some(origin.saturating_add((at * 1e6) as Utime));
            if sink.kept.is_some() {
                break;
            }
        }
        if let Some(speed) = options.speed {
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
        let channel = event.channel.as_str();
        if !event.message.on_its_channel(channel) {
            *problems.foreign.entry(event.channel).or_default() += 1;
            continue;
        }
        match event.message {
            AnyMessage::Pose(msg) => match Pose::try_from(&msg) {
                Ok(pose) => {
                    inputs.poses += 1;
                    sink.out.message(t, channel, &msg);
                    pipeline.input(Input::Pose(pose), &mut sink);
                }
                Err(e) => {
                    tracing::debug!(%e, "invalid pose skipped");
                    problems.invalid_poses += 1;
                }
            },
            AnyMessage::RangeImage(msg) if !options.recorded_cells => {
                let encoded = arcnav_bus::Message::encode(&msg).unwrap_or_default();
                match wire::range_image_from_wire(msg) {
                    Ok(image) => {
                        inputs.images += 1;
                        sink.out.event(t, channel, &encoded);
                        pipeline.input(Input::Image(image), &mut sink);
                    }
                    Err(e) => {
                        tracing::debug!(%e, "invalid range image skipped");
                        problems.invalid_images += 1;
                    }
                }
            }
            AnyMessage::ObstacleCells(msg) if options.recorded_cells => {
                match wire::obstacles_from_wire(msg) {
                    Ok(report) => {
                        inputs.recorded_cells += 1;
                        sink.on_obstacles(t, &report);
                        pipeline.input(Input::Obstacles(report), &mut sink);
                    }
                    Err(_) => *problems.undecodable.entry(event.channel).or_default() += 1,
                }
            }
            AnyMessage::Waypoints(msg) if !waypoints_given => match wire::mission_from_wire(&msg) {
                Ok(mission) => {
                    inputs.waypoints += 1;
                    sink.out.message(t, channel, &msg);
                    pipeline.input(Input::Waypoints(mission), &mut sink);
                }
                Err(_) => *problems.undecodable.entry(event.channel).or_default() += 1,
            },
            // Decisions are keyed by their cycle's time (the message's own
            // utime), as the replayed ones are: a logger stamps events when
            // it receives them, later than the cycle.
            AnyMessage::SteeringCommand(msg) => {
                recorded.insert(
                    msg.utime,
                    Cycle {
                        command: SteeringCommand::from(&msg),
                        votes: recorded_votes.remove(&msg.utime).unwrap_or_default(),
                    },
                );
            }
            AnyMessage::ArcVotes(msg) => {
                if let Ok(votes) = wire::votes_from_wire(&msg, &arcs) {
                    recorded_votes.entry(votes.utime).or_default().push(votes);
                }
            }
            // Recomputed by the replay: the recorded ones are replaced.
            AnyMessage::ObstacleCells(_) => recorded_cells += 1,
            AnyMessage::RangeImage(_) | AnyMessage::Waypoints(_) | AnyMessage::LocalMap(_) => {
                *problems.ignored.entry(event.channel).or_default() += 1;
            }
        }
        if let Some(e) = sink.out.error.take() {
            return Err(e);
        }
    }
    // The cycles due by the newest pose (of the last run, when the log
    // starts over; never those an absurd pose time would claim).
    if let Some(newest) = pipeline.pose().map(|p| p.utime) {
        pipeline.run_until(newest, &mut sink);
    }
    sink.out.finish()?;
    let drops = pipeline.perception.drops;
    problems.images_without_pose = drops.no_pose;
    problems.images_out_of_order = drops.out_of_order;
    problems.invalid_images += drops.invalid;
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
    if inputs.images == 0 && !options.recorded_cells {
        problems.cells_unused = recorded_cells;
    }
    problems.unknown_channels = events.stats().unknown.clone();
    for (channel, n) in &events.stats().undecodable {
        *problems.undecodable.entry(channel.clone()).or_default() += n;
    }
    Ok(ReplayResult {
        cycles: sink.cycles,
        recorded,
        inputs,
        problems,
        span,
        kept: sink.kept,
        arcs,
    })
}

/// A behaviour's weight by name, for attributing changes.
pub type WeightOf<'a> = &'a dyn Fn(&str) -> f64;

/// A decision that differs between two runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Difference {
    /// Seconds from the log's start.
    pub time_s: f64,
    pub utime: Utime,
    pub a: Decided,
    pub b: Decided,
    /// The behaviour whose (weighted) votes moved the choice from a's arc to b's most.
    pub moved_by: Option<String>,
}

/// One side of a difference.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Decided {
    pub arc: Option<usize>,
    pub curvature: f64,
    pub speed_mps: f64,
}

impl From<&SteeringCommand> for Decided {
    fn from(c: &SteeringCommand) -> Self {
        Self {
            arc: c.arc_index,
            curvature: c.curvature,
            speed_mps: c.speed_mps,
        }
    }
}

/// How two runs of a log compare.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    pub a: String,
    pub b: String,
    /// Decisions at the same times in both runs.
    pub compared: usize,
    pub agreeing: usize,
    /// `None` when no decision could be compared: never "100 %" of nothing.
    pub agreement_percent: Option<f64>,
    pub largest_curvature_difference: Option<Difference>,
    pub first_divergence: Option<Difference>,
    pub differences: Vec<Difference>,
}

/// Compares decisions of `a` and `b` at the times both made one.
/// `weights_a`/`weights_b` give each behaviour's weight, to attribute changes.
pub fn compare(
    labels: (&str, &str),
    a: &BTreeMap<Utime, Cycle>,
    b: &BTreeMap<Utime, Cycle>,
    weights: (WeightOf<'_>, WeightOf<'_>),
    origin: Utime,
) -> Comparison {
    let mut differences = Vec::new();
    let mut compared = 0;
    for (t, ca) in a {
        let Some(cb) = b.get(t) else { continue };
        compared += 1;
        let same = ca.command.arc_index == cb.command.arc_index
            && (ca.command.speed_mps - cb.command.speed_mps).abs() < 1e-6
            && (ca.command.curvature - cb.command.curvature).abs() < 1e-9;
        if same {
            continue;
        }
        differences.push(Difference {
            time_s: (*t - origin) as f64 * 1e-6,
            utime: *t,
            a: Decided::from(&ca.command),
            b: Decided::from(&cb.command),
            moved_by: attribute(ca, cb, weights),
        });
    }
    let largest = differences
        .iter()
        .max_by(|x, y| {
            (x.a.curvature - x.b.curvature)
                .abs()
                .total_cmp(&(y.a.curvature - y.b.curvature).abs())
        })
        .cloned();
    Comparison {
        a: labels.0.to_owned(),
        b: labels.1.to_owned(),
        compared,
        agreeing: compared - differences.len(),
        agreement_percent: (compared > 0)
            .then(|| 100.0 * (compared - differences.len()) as f64 / compared as f64),
        largest_curvature_difference: largest,
        first_divergence: differences.first().cloned(),
        differences,
    }
}

/// Which behaviour's weighted votes moved the choice from a's arc to b's
/// most: for each behaviour, how much more it favours b's arc over a's in
/// run b than in run a.
fn attribute(a: &Cycle, b: &Cycle, weights: (WeightOf<'_>, WeightOf<'_>)) -> Option<String> {
    let (arc_a, arc_b) = (a.command.arc_index?, b.command.arc_index?);
    let preference = |cycle: &Cycle, name: &str, weight: f64| -> f64 {
        cycle
            .votes
            .iter()
            .find(|v| v.behaviour == name)
            .map_or(0.0, |v| {
                weight
                    * f64::from(
                        v.votes.vote(arc_b).unwrap_or(0.0) - v.votes.vote(arc_a).unwrap_or(0.0),
                    )
            })
    };
    let mut names: Vec<&str> = a
        .votes
        .iter()
        .chain(&b.votes)
        .map(|v| v.behaviour.as_str())
        .collect();
    names.sort_unstable();
    names.dedup();
    names
        .into_iter()
        .map(|name| {
            (
                name,
                preference(b, name, (weights.1)(name)) - preference(a, name, (weights.0)(name)),
            )
        })
        .filter(|(_, shift)| *shift > 1e-9)
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(name, _)| name.to_owned())
}
