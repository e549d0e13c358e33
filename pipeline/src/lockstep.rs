//! The lock-step executor: every node on one thread, inputs in timestamp
//! order, bit-for-bit deterministic. `arcnav sim`, `arcnav replay`, the
//! tests and a user's own program ([`Pipeline`] in `examples/embed.rs`) use it.
//!
//! Timing: inputs (poses, range images, waypoints, recorded obstacle cells)
//! arrive in timestamp order. Before each input, the [`DecisionCycle`] runs
//! the deliveries and cycles due before its time; an internal event at time
//! t runs after every input at t ([`Pipeline::run_until`] runs those). A
//! cycle lets every behaviour vote on the map snapshot and the arbiter decide.

use std::sync::Arc;
use std::time::Instant;

use arcnav_arbiter::{Arbiter, BehaviourVotes, Decision, Reason};
use arcnav_behaviours::{Mission, Overlay};
use arcnav_localmap::MapSnapshot;
use arcnav_perception::{ObstacleReport, RangeImage, RangeSlice};
use arcnav_vehicle::{ArcSet, Pose, SteeringCommand, Utime};
use serde::Serialize;

use crate::behaviours::BehaviourSet;
use crate::config::Fault;
use crate::cycle::{Cycle, DecisionCycle};
use crate::perception::PerceptionNode;

/// Inputs of the pipeline.
#[derive(Debug, Clone)]
pub enum Input {
    Pose(Pose),
    Image(RangeImage),
    /// A slice of a range image (streamed; 002 §7's integrated mode).
    Slice(RangeSlice),
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
            Input::Slice(s) => s.utime,
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
    /// Whether [`Sink::on_overlays`] should be called for the cycle at
    /// `at`: the behaviours' overlays cost a little, and only pictures use
    /// them.
    fn wants_overlays(&self, _at: Utime) -> bool {
        false
    }
    /// What the behaviours' votes of the cycle at `at` rested on
    /// ([`arcnav_behaviours::Behaviour::overlay`]), before its command.
    fn on_overlays(&mut self, _at: Utime, _overlays: Vec<(String, Overlay)>) {}
    /// The arbiter decided at `at`, for `reason` (with its full
    /// explanation when explaining).
    fn on_command(
        &mut self,
        _at: Utime,
        _command: &SteeringCommand,
        _reason: &Reason,
        _decision: Option<&Decision>,
        _map: &MapSnapshot,
    ) {
    }
}

/// A sink that keeps nothing.
pub struct Discard;

impl Sink for Discard {}

/// A sink that keeps every command (what an embedding program wants).
#[derive(Debug, Default)]
pub struct Commands(pub Vec<SteeringCommand>);

impl Sink for Commands {
    fn on_command(
        &mut self,
        _: Utime,
        command: &SteeringCommand,
        _: &Reason,
        _: Option<&Decision>,
        _: &MapSnapshot,
    ) {
        self.0.push(*command);
    }
}

/// Time spent per stage, for reports (never used to decide anything).
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StageTime {
    pub count: u64,
    pub total_ms: f64,
    pub max_ms: f64,
}

impl StageTime {
    fn add(&mut self, started: Option<Instant>, clock: Option<Stopwatch>) {
        self.add_for(1, started, clock);
    }

    /// A call that did the work of `n` (images judged together): counted
    /// as `n`, each taking its share.
    fn add_for(&mut self, n: usize, started: Option<Instant>, clock: Option<Stopwatch>) {
        let (Some(started), Some(clock)) = (started, clock) else {
            return;
        };
        let n = n.max(1);
        let ms = clock().duration_since(started).as_secs_f64() * 1e3;
        self.count += n as u64;
        self.total_ms += ms;
        self.max_ms = self.max_ms.max(ms / n as f64);
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

/// The clock stage times are measured with (`Instant::now`), given by the
/// caller: the pipeline reads no clock of its own.
pub type Stopwatch = fn() -> Instant;

/// The lock-step executor.
pub struct Pipeline {
    pub perception: PerceptionNode,
    pub cycle: DecisionCycle,
    pub behaviours: BehaviourSet,
    pub arbiter: Arbiter,
    cycles: Vec<Cycle>,
    reports: Vec<ObstacleReport>,
    stopwatch: Option<Stopwatch>,
    pub times: StageTimes,
    pub commands: u64,
    fault: Injected,
}

/// A fault injected on purpose ([`Pipeline::inject`]) and what it did.
#[derive(Debug, Clone, Default)]
struct Injected {
    fault: Fault,
    /// It begins this long after the first pose, µs.
    after: Utime,
    /// When it begins (set by the first pose).
    from: Option<Utime>,
    /// The last cycle's map before it began ([`Fault::StaleMap`]).
    last_map: Option<Arc<MapSnapshot>>,
    counts: FaultCounts,
}

/// Takes every cell, region, shadow and height out of `report`, leaving the
/// ground it observed; returns how many cells it held.
fn strip(report: &mut ObstacleReport) -> u64 {
    let cells = report.cells.len() as u64;
    report.cells.clear();
    report.regions.clear();
    report.shadows.clear();
    report.heights.clear();
    cells
}

impl Injected {
    fn active(&self, t: Utime) -> bool {
        self.fault != Fault::None && self.from.is_some_and(|from| t >= from)
    }

    /// The map the cycle votes on, as the fault leaves it.
    fn corrupt(&mut self, cycle: &mut Cycle) {
        if !self.active(cycle.utime) {
            if self.fault == Fault::StaleMap {
                self.last_map = Some(Arc::clone(&cycle.map));
            }
            return;
        }
        if self.fault == Fault::StaleMap {
            let frozen = self.last_map.get_or_insert_with(|| Arc::clone(&cycle.map));
            cycle.map = Arc::clone(frozen);
            self.counts.cycles_stale += 1;
        }
    }
}

/// What an injected fault did (`report.json`'s `fault`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultCounts {
    /// Perception's untraversable and graded cells thrown away.
    pub cells_dropped: u64,
    /// Cycles that voted on a stale map.
    pub cycles_stale: u64,
}

impl Pipeline {
    /// The nodes, each built from its own configuration section.
    pub fn new(
        perception: PerceptionNode,
        cycle: DecisionCycle,
        behaviours: BehaviourSet,
        arbiter: Arbiter,
    ) -> Self {
        Self {
            perception,
            cycle,
            behaviours,
            arbiter,
            cycles: Vec::new(),
            reports: Vec::new(),
            stopwatch: None,
            times: StageTimes::default(),
            commands: 0,
            fault: Injected::default(),
        }
    }

    /// Makes the pipeline faulty on purpose from `after` µs past the first
    /// pose (`[pipeline] fault`): to test what stands beside it.
    pub fn inject(&mut self, fault: Fault, after: Utime) {
        self.fault = Injected {
            fault,
            after,
            ..Injected::default()
        };
    }

    /// The fault injected, and what it did so far.
    pub fn fault(&self) -> (Fault, FaultCounts) {
        (self.fault.fault, self.fault.counts)
    }

    /// Keeps an explanation of every decision (for pictures and replays).
    pub fn set_explain(&mut self, explain: bool) {
        self.arbiter.set_explain(explain);
    }

    /// Measures the time of each stage with `clock` (see [`StageTimes`]).
    pub fn time_stages(&mut self, clock: Stopwatch) {
        self.stopwatch = Some(clock);
    }

    pub fn arcs(&self) -> &ArcSet {
        self.arbiter.arcs()
    }

    /// The newest pose received.
    pub fn pose(&self) -> Option<&Pose> {
        self.cycle.pose()
    }

    fn started(&self) -> Option<Instant> {
        self.stopwatch.map(|clock| clock())
    }

    /// Feeds one input (after running the internal events before it).
    pub fn input(&mut self, input: Input, sink: &mut dyn Sink) {
        let now = input.utime();
        let started = self.started();
        match input {
            Input::Pose(pose) => {
                if self.fault.from.is_none() {
                    self.fault.from = Some(pose.utime + self.fault.after);
                }
                // Runs the events before the pose, then moves the map.
                self.cycle.on_pose(pose, &mut self.cycles);
                self.times.localmap.add(started, self.stopwatch);
                self.run_cycles(sink);
                let started = self.started();
                self.perception
                    .on_pose(&pose, &mut |r| self.reports.push(r));
                self.perceived(now, started, sink);
            }
            Input::Image(image) => {
                self.advance(now, false, sink);
                let started = self.started();
                self.perception
                    .on_image(image, &mut |r| self.reports.push(r));
                self.perceived(now, started, sink);
            }
            Input::Slice(slice) => {
                self.advance(now, false, sink);
                let started = self.started();
                self.perception
                    .on_slice(slice, &mut |r| self.reports.push(r));
                self.perceived(now, started, sink);
            }
            Input::Waypoints(mission) => {
                self.advance(now, false, sink);
                self.behaviours.on_waypoints(mission);
            }
            Input::Obstacles(report) => {
                self.advance(now, false, sink);
                self.cycle.on_report(report, (), &mut self.cycles);
            }
        }
    }

    /// Hands the reports perception just made to the sink and the map.
    fn perceived(&mut self, now: Utime, started: Option<Instant>, sink: &mut dyn Sink) {
        if self.reports.is_empty() {
            return;
        }
        // Images judged together (`fuse_within_s`) come out of one call:
        // each is counted, so that the mean stays a mean per image.
        self.times
            .perception
            .add_for(self.reports.len(), started, self.stopwatch);
        // A blind perception's reports are empty as they leave it; a
        // forgetful map's lose their cells as they reach it.
        let fault = self.fault.active(now).then_some(self.fault.fault);
        if fault == Some(Fault::BlindPerception) {
            for report in &mut self.reports {
                self.fault.counts.cells_dropped += strip(report);
            }
        }
        for mut report in self.reports.drain(..) {
            sink.on_obstacles(now, &report);
            if fault == Some(Fault::ForgetfulMap) {
                self.fault.counts.cells_dropped += strip(&mut report);
            }
            self.cycle.on_report(report, (), &mut self.cycles);
        }
    }

    /// Ends the frames being streamed (the end of the inputs): their cells
    /// not yet reported reach the map.
    pub fn flush(&mut self, sink: &mut dyn Sink) {
        let now = self.pose().map_or(0, |p| p.utime);
        let started = self.started();
        self.perception.flush(&mut |r| self.reports.push(r));
        self.perceived(now, started, sink);
    }

    /// Runs every internal event at or before `until`.
    pub fn run_until(&mut self, until: Utime, sink: &mut dyn Sink) {
        self.advance(until, true, sink);
    }

    fn advance(&mut self, until: Utime, inclusive: bool, sink: &mut dyn Sink) {
        let started = self.started();
        self.cycle.advance(until, inclusive, &mut self.cycles);
        self.times.localmap.add(started, self.stopwatch);
        self.run_cycles(sink);
    }

    /// Every behaviour votes on each cycle, the arbiter decides.
    fn run_cycles(&mut self, sink: &mut dyn Sink) {
        let mut cycles = std::mem::take(&mut self.cycles);
        let stopwatch = self.stopwatch;
        let started = || stopwatch.map(|clock| clock());
        for mut cycle in cycles.drain(..) {
            self.fault.corrupt(&mut cycle);
            let begun = started();
            let votes =
                self.behaviours
                    .on_cycle(cycle.resets, cycle.utime, &cycle.pose, &cycle.map);
            self.times.behaviours.add(begun, stopwatch);
            sink.on_votes(cycle.utime, votes);
            let begun = started();
            for v in votes {
                if let Err(e) = self.arbiter.on_votes(v) {
                    tracing::warn!(%e, "votes refused by the arbiter");
                }
            }
            let command = self.arbiter.decide(cycle.utime);
            self.times.arbiter.add(begun, stopwatch);
            if sink.wants_overlays(cycle.utime) {
                sink.on_overlays(cycle.utime, self.behaviours.overlays(&cycle.pose));
            }
            self.behaviours.on_command(&command);
            self.commands += 1;
            sink.on_command(
                cycle.utime,
                &command,
                self.arbiter.reason(),
                self.arbiter.decision(),
                &cycle.map,
            );
        }
        self.cycles = cycles;
    }
}
