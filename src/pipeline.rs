//! The navigation pipeline as nodes, and the lock-step executor that runs
//! them on simulated or logged time.
//!
//! Nodes are plain structs with `on_<input>` step functions: no threads, no
//! I/O, no clock. The same nodes run under the lock-step [`Pipeline`] (used
//! by `arcnav sim`, `arcnav replay` and the tests, bit-for-bit deterministic)
//! and under the threaded and distributed executors.
//!
//! Lock-step timing: inputs (poses, range images, waypoints) arrive in
//! timestamp order. Internal events — an obstacle report reaching the local
//! map `perception_latency_s` after its image was captured, and the command
//! cycle every `1 / command_rate_hz` from the first pose — run in time order
//! between inputs; an internal event at time t runs after the inputs at t.
//! A cycle takes the newest pose, updates the local map, lets every behaviour
//! vote and the arbiter decide.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use arcnav_arbiter::{Arbiter, BehaviourVotes, Decision, Votes};
use arcnav_behaviours::{Behaviour, Mission, Progress, Registry, VoteContext};
use arcnav_localmap::{LocalMap, MapSnapshot, PoseUpdate};
use arcnav_perception::{
    ImageStats, InOrder, ObstacleReport, RangeImage, Runner, TerrainEvaluator,
};
use arcnav_vehicle::config::{self as check, ConfigError};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{ArcSet, Pose, PoseHistory, SteeringCommand, Utime};
use serde::{Deserialize, Serialize};

use crate::config::Config;

/// Lives in `[pipeline]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineConfig {
    /// Commands per second (one cycle of map update, votes and decision).
    pub command_rate_hz: f64,
    /// Time from image capture until its cells reach the local map in
    /// lock-step runs, s (002 §5 measured ~0.6 s on 1993 hardware).
    pub perception_latency_s: f64,
    /// Poses kept to find the pose at an image's capture time, s.
    pub pose_history_s: f64,
    /// Images waiting for the pose at their capture time; beyond, the
    /// oldest is dropped (counted).
    pub max_waiting_images: usize,
    /// An image is placed only with poses at most this far apart around its
    /// capture time; in a hole of the pose stream it is dropped, s.
    pub max_pose_gap_s: f64,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            command_rate_hz: 10.0,
            perception_latency_s: 0.3,
            pose_history_s: 10.0,
            max_waiting_images: 4,
            max_pose_gap_s: 0.2,
        }
    }
}

impl PipelineConfig {
    /// Keys relative to `[pipeline]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check::in_range("command_rate_hz", self.command_rate_hz, 0.5, 1000.0)?;
        check::in_range("perception_latency_s", self.perception_latency_s, 0.0, 10.0)?;
        check::in_range("pose_history_s", self.pose_history_s, 0.5, 600.0)?;
        check::in_range("max_pose_gap_s", self.max_pose_gap_s, 0.001, 60.0)?;
        if !(1..=1000).contains(&self.max_waiting_images) {
            return Err(ConfigError::new(
                "max_waiting_images",
                format!("is {}, must be 1 to 1000", self.max_waiting_images),
            ));
        }
        Ok(())
    }
}

/// Why an image produced no report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct PerceptionDrops {
    /// No pose around its capture time (too old for the history, or no pose
    /// arrived in time).
    pub no_pose: u64,
    /// The evaluator refused it (malformed image).
    pub invalid: u64,
    /// Older than an image already evaluated from the same sensor.
    pub out_of_order: u64,
}

/// Perception: range images + poses → obstacle reports.
pub struct PerceptionNode {
    evaluator: Box<dyn TerrainEvaluator>,
    runner: Box<dyn Runner + Send>,
    poses: PoseHistory,
    waiting: VecDeque<RangeImage>,
    max_waiting: usize,
    max_gap_us: Utime,
    newest_capture: Vec<(String, Utime)>,
    pub images: u64,
    pub reports: u64,
    pub drops: PerceptionDrops,
    pub totals: ImageStats,
}

impl PerceptionNode {
    pub fn new(config: &Config) -> Result<Self, ConfigError> {
        let rate = config.sim.pose_rate_hz.max(100.0);
        Ok(Self {
            evaluator: config
                .perception
                .build_evaluator()
                .map_err(|e| e.within("perception"))?,
            runner: Box::new(InOrder),
            poses: PoseHistory::with_capacity((config.pipeline.pose_history_s * rate) as usize),
            waiting: VecDeque::new(),
            max_waiting: config.pipeline.max_waiting_images,
            max_gap_us: seconds_to_micros(config.pipeline.max_pose_gap_s),
            newest_capture: Vec::new(),
            images: 0,
            reports: 0,
            drops: PerceptionDrops::default(),
            totals: ImageStats::default(),
        })
    }

    /// A pose; images waiting for it are evaluated (reports handed to `out`).
    pub fn on_pose(&mut self, pose: &Pose, out: &mut dyn FnMut(ObstacleReport)) {
        if let Err(e) = self.poses.push(*pose) {
            tracing::debug!(%e, "pose not added to the perception history");
            if matches!(e, arcnav_vehicle::PoseHistoryError::NotIncreasing { .. })
                && pose.utime < self.newest_pose()
            {
                // Time went backwards (a log started over): start over.
                self.poses.clear();
                self.waiting.clear();
                self.newest_capture.clear();
                let _ = self.poses.push(*pose);
            }
        }
        self.drain(out);
    }

    /// Hands independent parts of each evaluation to `runner` (threads of a
    /// live executor); results are the same as without.
    pub fn set_runner(&mut self, runner: Box<dyn Runner + Send>) {
        self.runner = runner;
    }

    /// Images waiting for the pose at their capture time.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    fn newest_pose(&self) -> Utime {
        self.poses.newest().map_or(Utime::MIN, |p| p.utime)
    }

    /// A range image; evaluated as soon as the pose at its capture time is known.
    pub fn on_image(&mut self, image: RangeImage, out: &mut dyn FnMut(ObstacleReport)) {
        self.images += 1;
        self.waiting.push_back(image);
        self.drain(out);
    }

    fn drain(&mut self, out: &mut dyn FnMut(ObstacleReport)) {
        let newest = self.newest_pose();
        while self
            .waiting
            .front()
            .is_some_and(|image| image.utime <= newest)
        {
            if let Some(image) = self.waiting.pop_front() {
                self.evaluate(image, out);
            }
        }
        // Images whose pose never comes (a stopped pose stream) are dropped.
        while self.waiting.len() > self.max_waiting {
            self.waiting.pop_front();
            self.drops.no_pose += 1;
        }
    }

    fn evaluate(&mut self, image: RangeImage, out: &mut dyn FnMut(ObstacleReport)) {
        let pose = match self.poses.at_within(image.utime, self.max_gap_us) {
            Ok(pose) => pose,
            Err(e) => {
                tracing::debug!(%e, image = image.utime, "image dropped: no pose at capture time");
                self.drops.no_pose += 1;
                return;
            }
        };
        match self
            .newest_capture
            .iter_mut()
            .find(|(s, _)| *s == image.sensor)
        {
            Some((_, newest)) if image.utime <= *newest => {
                self.drops.out_of_order += 1;
                return;
            }
            Some((_, newest)) => *newest = image.utime,
            None => self
                .newest_capture
                .push((image.sensor.clone(), image.utime)),
        }
        let mut report = ObstacleReport::default();
        match self.evaluator.evaluate_with(
            &image,
            &pose.world_from_vehicle,
            &mut report,
            &*self.runner,
        ) {
            Ok(stats) => {
                self.totals.accumulate(&stats);
                self.reports += 1;
                out(report);
            }
            Err(e) => {
                tracing::warn!(%e, image = image.utime, "image dropped by perception");
                self.drops.invalid += 1;
            }
        }
    }
}

/// The local map: obstacle reports + poses → snapshots.
pub struct LocalMapNode {
    pub map: LocalMap,
}

impl LocalMapNode {
    pub fn new(config: &Config) -> Self {
        Self {
            map: LocalMap::new(&config.localmap, config.vehicle.max_speed_mps),
        }
    }

    pub fn on_pose(&mut self, pose: &Pose) -> PoseUpdate {
        self.map.update(pose)
    }

    pub fn on_obstacles(&mut self, report: &ObstacleReport) {
        if let Err(e) = self.map.insert(report) {
            tracing::debug!(%e, "obstacle report refused by the local map");
        }
    }

    pub fn snapshot(&self) -> Arc<MapSnapshot> {
        self.map.snapshot()
    }
}

/// The behaviours: snapshot + pose + mission → votes.
pub struct BehaviourNode {
    behaviours: Vec<Box<dyn Behaviour>>,
    votes: Vec<BehaviourVotes>,
    mission: Mission,
    arcs: ArcSet,
    last_command: Option<SteeringCommand>,
}

impl BehaviourNode {
    pub fn new(behaviours: Vec<Box<dyn Behaviour>>, arcs: ArcSet) -> Self {
        let votes = behaviours
            .iter()
            .map(|b| BehaviourVotes {
                behaviour: b.name().to_owned(),
                utime: 0,
                votes: Votes::new(arcs.len()),
            })
            .collect();
        Self {
            behaviours,
            votes,
            mission: Mission::default(),
            arcs,
            last_command: None,
        }
    }

    pub fn on_waypoints(&mut self, mission: Mission) {
        self.mission = mission;
    }

    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// Every behaviour votes.
    pub fn on_cycle(&mut self, now: Utime, pose: &Pose, map: &MapSnapshot) -> &[BehaviourVotes] {
        let ctx = VoteContext {
            utime: now,
            pose,
            map,
            mission: &self.mission,
            arcs: &self.arcs,
            last_command: self.last_command.as_ref(),
        };
        for (behaviour, out) in self.behaviours.iter_mut().zip(self.votes.iter_mut()) {
            out.votes.clear();
            out.utime = now;
            behaviour.vote(&ctx, &mut out.votes);
        }
        &self.votes
    }

    /// The command the arbiter sent.
    pub fn on_command(&mut self, command: &SteeringCommand) {
        for behaviour in &mut self.behaviours {
            behaviour.debrief(command);
        }
        self.last_command = Some(*command);
    }

    /// Forgets state carried between cycles (map reset, new mission).
    pub fn reset(&mut self) {
        for behaviour in &mut self.behaviours {
            behaviour.reset();
        }
    }

    /// The mission progress of the behaviour that follows waypoints.
    pub fn progress(&self) -> Option<Progress> {
        self.behaviours.iter().find_map(|b| b.progress())
    }
}

/// Inputs of the pipeline.
#[derive(Debug, Clone)]
pub enum Input {
    Pose(Pose),
    Image(RangeImage),
    Waypoints(Mission),
    /// Obstacle cells perceived elsewhere (a recorded log's OBSTACLE_CELLS,
    /// or a distributed perception node): straight to the local map.
    Obstacles(ObstacleReport),
}

impl Input {
    pub fn utime(&self) -> Utime {
        match self {
            Input::Pose(p) => p.utime,
            Input::Image(i) => i.utime,
            Input::Waypoints(m) => m.version,
            Input::Obstacles(r) => r.utime,
        }
    }
}

/// Where the pipeline's outputs go.
pub trait Sink {
    /// Perception evaluated an image at `at`.
    fn on_obstacles(&mut self, _at: Utime, _report: &ObstacleReport) {}
    /// The behaviours voted at `at`.
    fn on_votes(&mut self, _at: Utime, _votes: &[BehaviourVotes]) {}
    /// The arbiter decided at `at` (with its explanation when explaining).
    fn on_command(
        &mut self,
        _at: Utime,
        _command: &SteeringCommand,
        _decision: Option<&Decision>,
        _map: &MapSnapshot,
    ) {
    }
}

/// A sink that keeps nothing.
pub struct Discard;

impl Sink for Discard {}

/// Time spent per stage, for reports (never used to decide anything).
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StageTime {
    pub count: u64,
    pub total_ms: f64,
    pub max_ms: f64,
}

impl StageTime {
    fn add(&mut self, started: Instant) {
        let ms = started.elapsed().as_secs_f64() * 1e3;
        self.count += 1;
        self.total_ms += ms;
        self.max_ms = self.max_ms.max(ms);
    }

    pub fn mean_ms(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.total_ms / self.count as f64
        }
    }
}

/// Time per pipeline stage.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StageTimes {
    pub perception: StageTime,
    pub localmap: StageTime,
    pub behaviours: StageTime,
    pub arbiter: StageTime,
}

/// The lock-step executor.
pub struct Pipeline {
    pub perception: PerceptionNode,
    pub localmap: LocalMapNode,
    pub behaviours: BehaviourNode,
    pub arbiter: Arbiter,
    period_us: Utime,
    latency_us: Utime,
    next_cycle: Option<Utime>,
    deliveries: VecDeque<(Utime, ObstacleReport)>,
    pose: Option<Pose>,
    pub times: StageTimes,
    pub map_resets: u64,
    pub commands: u64,
}

impl Pipeline {
    /// Builds every node from `config`, behaviours from `registry`.
    pub fn new(config: &Config, registry: &Registry) -> Result<Self, ConfigError> {
        let arcs = config.arc_set()?;
        let behaviours = config.build_behaviours(registry, &arcs)?;
        Ok(Self {
            perception: PerceptionNode::new(config)?,
            localmap: LocalMapNode::new(config),
            behaviours: BehaviourNode::new(behaviours, arcs.clone()),
            arbiter: Arbiter::new(&config.arbiter, arcs, &config.vehicle),
            period_us: seconds_to_micros(1.0 / config.pipeline.command_rate_hz),
            latency_us: seconds_to_micros(config.pipeline.perception_latency_s),
            next_cycle: None,
            deliveries: VecDeque::new(),
            pose: None,
            times: StageTimes::default(),
            map_resets: 0,
            commands: 0,
        })
    }

    /// Keeps an explanation of every decision (for pictures and replays).
    pub fn set_explain(&mut self, explain: bool) {
        self.arbiter.set_explain(explain);
    }

    pub fn arcs(&self) -> &ArcSet {
        self.arbiter.arcs()
    }

    /// The newest pose received.
    pub fn pose(&self) -> Option<&Pose> {
        self.pose.as_ref()
    }

    /// Feeds one input (after running the internal events before it).
    pub fn input(&mut self, input: Input, sink: &mut dyn Sink) {
        let now = input.utime();
        self.run_events(now, false, sink);
        match input {
            Input::Pose(pose) => {
                let started = Instant::now();
                let mut reports = Vec::new();
                self.perception.on_pose(&pose, &mut |r| reports.push(r));
                if !reports.is_empty() {
                    self.times.perception.add(started);
                }
                for report in reports {
                    self.schedule(now, report, sink);
                }
                let started = Instant::now();
                if let PoseUpdate::Reset(reason) = self.localmap.on_pose(&pose) {
                    tracing::warn!(%reason, "local map reset");
                    self.map_resets += 1;
                    self.behaviours.reset();
                }
                self.times.localmap.add(started);
                if self.next_cycle.is_none() {
                    self.next_cycle = Some(pose.utime);
                }
                self.pose = Some(pose);
            }
            Input::Image(image) => {
                let started = Instant::now();
                let mut reports = Vec::new();
                self.perception.on_image(image, &mut |r| reports.push(r));
                if !reports.is_empty() {
                    self.times.perception.add(started);
                }
                for report in reports {
                    self.schedule(now, report, sink);
                }
            }
            Input::Waypoints(mission) => {
                self.behaviours.on_waypoints(mission);
            }
            Input::Obstacles(report) => {
                let at = report.utime + self.latency_us;
                self.deliveries.push_back((at, report));
                self.deliveries.make_contiguous().sort_by_key(|(t, _)| *t);
            }
        }
    }

    fn schedule(&mut self, now: Utime, report: ObstacleReport, sink: &mut dyn Sink) {
        sink.on_obstacles(now, &report);
        let at = now.max(report.utime + self.latency_us);
        self.deliveries.push_back((at, report));
    }

    /// Runs every internal event at or before `until`.
    pub fn run_until(&mut self, until: Utime, sink: &mut dyn Sink) {
        self.run_events(until, true, sink);
    }

    fn run_events(&mut self, until: Utime, inclusive: bool, sink: &mut dyn Sink) {
        let due = |t: Utime| if inclusive { t <= until } else { t < until };
        loop {
            let delivery = self.deliveries.front().map(|(t, _)| *t).filter(|&t| due(t));
            let cycle = self.next_cycle.filter(|&t| due(t));
            match (delivery, cycle) {
                (Some(d), c) if c.is_none_or(|c| d <= c) => {
                    if let Some((_, report)) = self.deliveries.pop_front() {
                        let started = Instant::now();
                        self.localmap.on_obstacles(&report);
                        self.times.localmap.add(started);
                    }
                }
                (_, Some(c)) => {
                    self.cycle(c, sink);
                    self.next_cycle = Some(c + self.period_us);
                }
                _ => return,
            }
        }
    }

    fn cycle(&mut self, now: Utime, sink: &mut dyn Sink) {
        let Some(pose) = self.pose else { return };
        let started = Instant::now();
        let map = self.localmap.snapshot();
        self.times.localmap.add(started);
        let started = Instant::now();
        let votes = self.behaviours.on_cycle(now, &pose, &map);
        self.times.behaviours.add(started);
        sink.on_votes(now, votes);
        let started = Instant::now();
        for v in votes {
            if let Err(e) = self.arbiter.on_votes(v) {
                tracing::warn!(%e, "votes refused by the arbiter");
            }
        }
        let command = self.arbiter.decide(now);
        self.times.arbiter.add(started);
        self.behaviours.on_command(&command);
        self.commands += 1;
        sink.on_command(now, &command, self.arbiter.decision(), &map);
    }
}
