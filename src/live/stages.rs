//! The live stages: the pipeline's nodes wrapped with what live operation
//! adds (the cycle clock on the pose stream, report delivery, the arbiter's
//! completeness and safety watchdog), still without threads, I/O or clock
//! reads. Wall-clock times (µs since the Unix epoch) arrive as arguments.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use arcnav_arbiter::{Arbiter, BehaviourVotes, VoteSizeError};
use arcnav_localmap::{MapSnapshot, PoseUpdate};
use arcnav_perception::ObstacleReport;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{Pose, SteeringCommand, Utime};
use crossbeam_channel::{Receiver, Sender, TrySendError};

use super::{NodeStatus, Samples};
use crate::config::Config;
use crate::pipeline::LocalMapNode;

/// A message with the wall-clock time it arrived, µs.
#[derive(Debug, Clone)]
pub struct Arrived<T> {
    pub item: T,
    pub wall: i64,
}

/// The sending side of a one-place queue that keeps only the newest item:
/// a consumer that falls behind skips to the latest instead of queueing.
pub struct NewestWins<T> {
    sender: Sender<T>,
    stale: Receiver<T>,
    dropped: Arc<AtomicU64>,
}

/// A one-place newest-wins queue and the counter of items it dropped.
pub fn newest_wins<T>() -> (NewestWins<T>, Receiver<T>, Arc<AtomicU64>) {
    let (sender, receiver) = crossbeam_channel::bounded(1);
    let dropped = Arc::new(AtomicU64::new(0));
    (
        NewestWins {
            sender,
            stale: receiver.clone(),
            dropped: Arc::clone(&dropped),
        },
        receiver,
        dropped,
    )
}

impl<T> NewestWins<T> {
    /// Puts `item`, replacing an item still waiting (counted as dropped).
    pub fn put(&self, item: T) {
        let item = match self.sender.try_send(item) {
            Ok(()) | Err(TrySendError::Disconnected(_)) => return,
            Err(TrySendError::Full(item)) => item,
        };
        if self.stale.try_recv().is_ok() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        // Only this sender fills the slot, which was just emptied; should a
        // second producer have raced in, this item is the one dropped.
        if self.sender.try_send(item).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Items replaced before the consumer took them.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// Sends without blocking; a full queue drops the item and counts it.
pub fn offer<T>(sender: &Sender<T>, item: T, dropped: &mut u64) -> bool {
    match sender.try_send(item) {
        Ok(()) => true,
        Err(TrySendError::Full(_)) => {
            *dropped += 1;
            true
        }
        Err(TrySendError::Disconnected(_)) => false,
    }
}

/// One decision cycle's input to the behaviours.
#[derive(Debug, Clone)]
pub struct Cycle {
    /// The cycle's time on the sensor clock; votes carry it.
    pub utime: Utime,
    /// The newest pose at or before `utime`.
    pub pose: Pose,
    pub map: Arc<MapSnapshot>,
    /// Map resets so far: a change tells behaviours to forget their state.
    pub resets: u64,
    /// Capture time and wall-clock arrival of the images whose cells are
    /// new in this map.
    pub images: Vec<(Utime, i64)>,
    /// Run because new cells arrived, not by the fixed-rate clock.
    pub event: bool,
}

struct Delivery {
    at: Utime,
    report: ObstacleReport,
    arrival: i64,
}

/// The local map with the live cycle clock: a cycle every `1 /
/// command_rate_hz` of pose time, exactly as the lock-step pipeline runs
/// them (a cycle at t sees the poses at or before t and the cells delivered
/// at or before t).
pub struct MapStage {
    pub node: LocalMapNode,
    period_us: Utime,
    /// `Some(latency)`: cells wait until capture + latency (lock-step timing).
    hold_us: Option<Utime>,
    decide_on_new_cells: bool,
    next_cycle: Option<Utime>,
    last_cycle: Option<Utime>,
    pose: Option<Pose>,
    deliveries: VecDeque<Delivery>,
    images: Vec<(Utime, i64)>,
    pub resets: u64,
    pub cycles: u64,
    pub event_cycles: u64,
    /// Cycles not run because the pose stream jumped ahead by more than a second.
    pub skipped_cycles: u64,
    /// Reports whose delivery time had passed when they arrived (perception
    /// slower than `pipeline.perception_latency_s` in lock-step timing).
    pub late_reports: u64,
}

/// A gap in the pose stream longer than this is not caught up cycle by cycle.
const MAX_CATCH_UP_US: Utime = 1_000_000;

impl MapStage {
    pub fn new(config: &Config) -> Self {
        let live = &config.live;
        Self {
            node: LocalMapNode::new(config),
            period_us: seconds_to_micros(1.0 / config.pipeline.command_rate_hz),
            hold_us: live
                .reproduce_lockstep
                .then(|| seconds_to_micros(config.pipeline.perception_latency_s)),
            decide_on_new_cells: live.decide_on_new_cells && !live.reproduce_lockstep,
            next_cycle: None,
            last_cycle: None,
            pose: None,
            deliveries: VecDeque::new(),
            images: Vec::new(),
            resets: 0,
            cycles: 0,
            event_cycles: 0,
            skipped_cycles: 0,
            late_reports: 0,
        }
    }

    /// Reports waiting for their delivery time.
    pub fn waiting(&self) -> usize {
        self.deliveries.len()
    }

    /// A pose: runs the cycles it completes (into `out`) and moves the map.
    pub fn on_pose(&mut self, pose: Pose, out: &mut Vec<Cycle>) {
        if self.pose.is_some_and(|p| pose.utime < p.utime) {
            // The sensor clock went backwards (a log restarted): start over.
            tracing::warn!(
                utime = pose.utime,
                "pose time went backwards: cycle clock restarted"
            );
            self.next_cycle = None;
            self.last_cycle = None;
            self.deliveries.clear();
        }
        let mut next = self.next_cycle.unwrap_or(pose.utime);
        if pose.utime - next > MAX_CATCH_UP_US {
            let skip = (pose.utime - next) / self.period_us;
            self.skipped_cycles += skip as u64;
            next += skip * self.period_us;
            tracing::warn!(
                skipped = skip,
                "pose stream jumped ahead: cycles in the gap skipped"
            );
        }
        while next < pose.utime {
            self.cycle(next, false, out);
            next += self.period_us;
        }
        if let PoseUpdate::Reset(reason) = self.node.on_pose(&pose) {
            tracing::warn!(%reason, "local map reset");
            self.resets += 1;
        }
        self.pose = Some(pose);
        if next == pose.utime {
            self.cycle(next, false, out);
            next += self.period_us;
        }
        self.next_cycle = Some(next);
    }

    /// An obstacle report that arrived at wall time `arrival`.
    pub fn on_report(&mut self, report: ObstacleReport, arrival: i64, out: &mut Vec<Cycle>) {
        let now = self.pose.map_or(Utime::MIN, |p| p.utime);
        match self.hold_us {
            Some(latency) => {
                let due = report.utime + latency;
                let at = now.max(due);
                // A cycle after the modelled delivery time ran without it.
                if self.last_cycle.is_some_and(|c| c >= due) {
                    self.late_reports += 1;
                }
                let i = self.deliveries.partition_point(|d| d.at <= at);
                self.deliveries.insert(
                    i,
                    Delivery {
                        at,
                        report,
                        arrival,
                    },
                );
            }
            None => {
                self.images.push((report.utime, arrival));
                self.node.on_obstacles(&report);
                if self.decide_on_new_cells && self.pose.is_some() {
                    let at = self.last_cycle.map_or(now, |c| c.max(now));
                    self.event_cycles += 1;
                    self.cycle(at, true, out);
                }
            }
        }
    }

    fn cycle(&mut self, at: Utime, event: bool, out: &mut Vec<Cycle>) {
        while self.deliveries.front().is_some_and(|d| d.at <= at) {
            if let Some(d) = self.deliveries.pop_front() {
                self.node.on_obstacles(&d.report);
                self.images.push((d.report.utime, d.arrival));
            }
        }
        let Some(pose) = self.pose else { return };
        self.cycles += 1;
        self.last_cycle = Some(at);
        out.push(Cycle {
            utime: at,
            pose,
            map: self.node.snapshot(),
            resets: self.resets,
            images: std::mem::take(&mut self.images),
            event,
        });
    }
}

/// Why the arbiter's watchdog commands stop.
#[derive(Debug, Clone, PartialEq)]
pub enum Hazard {
    NoPose,
    PoseStale {
        age_s: f64,
    },
    NoImage,
    ImagesStale {
        age_s: f64,
    },
    /// Poses and images are fresh but no decision came for this long (the
    /// local map or every behaviour is silent).
    NoDecisions {
        age_s: f64,
    },
}

impl std::fmt::Display for Hazard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Hazard::NoPose => write!(f, "no pose received yet"),
            Hazard::PoseStale { age_s } => write!(f, "last pose {age_s:.2} s ago"),
            Hazard::NoImage => write!(f, "no range image evaluated yet"),
            Hazard::ImagesStale { age_s } => {
                write!(f, "last range image evaluated {age_s:.2} s ago")
            }
            Hazard::NoDecisions { age_s } => {
                write!(f, "no votes to decide on for {age_s:.2} s")
            }
        }
    }
}

/// Why a command was published.
#[derive(Debug, Clone, PartialEq)]
pub enum Why {
    /// Every expected behaviour voted for the cycle.
    Complete,
    /// The decision deadline passed; these behaviours had not voted.
    Deadline { missing: Vec<String> },
    /// The watchdog overrode the votes or the pipeline is silent.
    Watchdog(Hazard),
    /// The executor is shutting down.
    Final,
}

/// A command to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Decided {
    pub command: SteeringCommand,
    pub why: Why,
}

/// The arbiter with what live operation needs around it: it decides a cycle
/// when every expected behaviour has voted for it (or at a deadline), and its
/// watchdog commands stop when poses, evaluated images or decisions stop
/// coming; while that lasts it repeats stop at the command rate.
pub struct ArbiterStage {
    pub arbiter: Arbiter,
    expected: Vec<String>,
    voted: Vec<bool>,
    /// Newest vote time since the last decision, and when the first new vote came.
    pending: Option<(Utime, i64)>,
    deadline_us: i64,
    pose_timeout_us: i64,
    image_timeout_us: i64,
    stall_us: i64,
    period_us: i64,
    started: i64,
    /// Newest pose time and its wall-clock arrival.
    pose: Option<(Utime, i64)>,
    last_image: Option<i64>,
    last_decision: Option<i64>,
    last_publish: Option<i64>,
    hazard: Option<Hazard>,
    /// Images new in the decisions since the last one: capture, arrival
    /// (`None`: known only from OBSTACLE_CELLS, in a distributed system).
    images: Vec<(Utime, Option<i64>)>,
    latency_from_cells: bool,
    /// Cells reach the map this long after capture (lock-step timing), µs.
    hold_us: Utime,
    pub arrival_to_command_ms: Samples,
    pub capture_to_command_ms: Samples,
    pub commands: u64,
    pub stops: u64,
    pub watchdog_stops: u64,
    pub deadline_decisions: u64,
}

impl ArbiterStage {
    /// `expected`: the behaviours whose votes complete a cycle. `now`: wall clock.
    pub fn new(config: &Config, arbiter: Arbiter, expected: Vec<String>, now: i64) -> Self {
        let live = &config.live;
        Self {
            arbiter,
            voted: vec![false; expected.len()],
            expected,
            pending: None,
            deadline_us: seconds_to_micros(live.decision_deadline_s),
            pose_timeout_us: seconds_to_micros(live.pose_timeout_s),
            image_timeout_us: seconds_to_micros(live.image_timeout_s),
            stall_us: seconds_to_micros(config.arbiter.vote_timeout_s),
            period_us: seconds_to_micros(1.0 / config.pipeline.command_rate_hz),
            started: now,
            pose: None,
            last_image: None,
            last_decision: None,
            last_publish: None,
            hazard: None,
            images: Vec::new(),
            latency_from_cells: false,
            hold_us: if live.reproduce_lockstep {
                seconds_to_micros(config.pipeline.perception_latency_s)
            } else {
                0
            },
            arrival_to_command_ms: Samples::default(),
            capture_to_command_ms: Samples::default(),
            commands: 0,
            stops: 0,
            watchdog_stops: 0,
            deadline_decisions: 0,
        }
    }

    /// The behaviours a cycle waits for.
    pub fn expected(&self) -> &[String] {
        &self.expected
    }

    /// A pose was received at `now`.
    pub fn on_pose(&mut self, utime: Utime, now: i64) {
        if self.pose.is_none_or(|(t, _)| utime >= t) {
            self.pose = Some((utime, now));
        }
    }

    /// Latency is measured from the obstacle cells seen by the arbiter
    /// (a distributed arbiter, which never sees the cycles), not from the
    /// images each decision's map holds.
    pub fn measure_latency_from_cells(&mut self) {
        self.latency_from_cells = true;
    }

    /// Perception evaluated the image captured at `capture`.
    pub fn on_perceived(&mut self, capture: Utime, now: i64) {
        self.last_image = Some(now);
        if self.latency_from_cells && self.images.len() < 64 {
            self.images.push((capture, None));
        }
    }

    /// One behaviour's votes, received at `now`, on a map that holds the
    /// cells of `images` (capture, arrival) for the first time; the command
    /// when they complete a cycle.
    pub fn on_votes(
        &mut self,
        votes: &BehaviourVotes,
        images: &[(Utime, i64)],
        now: i64,
    ) -> Result<Option<Decided>, VoteSizeError> {
        self.arbiter.on_votes(votes)?;
        self.images.extend(
            images
                .iter()
                .map(|&(capture, arrival)| (capture, Some(arrival))),
        );
        let newest = self
            .pending
            .map_or(votes.utime, |(t, _)| t.max(votes.utime));
        self.pending = Some((newest, self.pending.map_or(now, |(_, first)| first)));
        if let Some(i) = self.expected.iter().position(|e| *e == votes.behaviour) {
            self.voted[i] = true;
        }
        if self.voted.iter().all(|&v| v) {
            return Ok(Some(self.decide(Why::Complete, now)));
        }
        Ok(None)
    }

    /// Time passes: a decision at the deadline, or a stop while a hazard lasts.
    pub fn on_tick(&mut self, now: i64) -> Option<Decided> {
        if let Some((_, first)) = self.pending
            && now - first >= self.deadline_us
        {
            let missing = self
                .expected
                .iter()
                .zip(&self.voted)
                .filter(|(_, v)| !**v)
                .map(|(name, _)| name.clone())
                .collect();
            self.deadline_decisions += 1;
            return Some(self.decide(Why::Deadline { missing }, now));
        }
        let hazard = self.hazard(now).or_else(|| {
            let since = self.last_decision.unwrap_or(self.started);
            (now - since > self.stall_us).then(|| Hazard::NoDecisions {
                age_s: (now - since) as f64 * 1e-6,
            })
        });
        self.note_hazard(hazard.clone());
        let hazard = hazard?;
        if self
            .last_publish
            .is_some_and(|last| now - last < self.period_us)
        {
            return None;
        }
        self.watchdog_stops += 1;
        Some(self.publish(
            SteeringCommand::stop(self.sensor_time(now)),
            Why::Watchdog(hazard),
            now,
        ))
    }

    /// The stop published when the executor shuts down.
    pub fn final_stop(&mut self, now: i64) -> Decided {
        self.publish(
            SteeringCommand::stop(self.sensor_time(now)),
            Why::Final,
            now,
        )
    }

    /// The sensor clock extrapolated from the newest pose (wall clock before any).
    fn sensor_time(&self, now: i64) -> Utime {
        self.pose.map_or(now, |(utime, at)| utime + (now - at))
    }

    fn hazard(&self, now: i64) -> Option<Hazard> {
        let age = |since: i64| (now - since) as f64 * 1e-6;
        match self.pose {
            None => return Some(Hazard::NoPose),
            Some((_, at)) if now - at > self.pose_timeout_us => {
                return Some(Hazard::PoseStale { age_s: age(at) });
            }
            Some(_) => {}
        }
        match self.last_image {
            None => Some(Hazard::NoImage),
            Some(at) if now - at > self.image_timeout_us => {
                Some(Hazard::ImagesStale { age_s: age(at) })
            }
            Some(_) => None,
        }
    }

    fn note_hazard(&mut self, hazard: Option<Hazard>) {
        let same_kind = |a: &Option<Hazard>, b: &Option<Hazard>| match (a, b) {
            (Some(a), Some(b)) => std::mem::discriminant(a) == std::mem::discriminant(b),
            (None, None) => true,
            _ => false,
        };
        if !same_kind(&self.hazard, &hazard) {
            match &hazard {
                Some(h) => tracing::warn!(hazard = %h, "commanding stop"),
                None => tracing::info!("inputs fresh again: deciding on votes"),
            }
        }
        self.hazard = hazard;
    }

    fn decide(&mut self, why: Why, now: i64) -> Decided {
        let (cycle, _) = self.pending.take().unwrap_or((self.sensor_time(now), now));
        self.voted.fill(false);
        self.last_decision = Some(now);
        let hazard = self.hazard(now);
        self.note_hazard(hazard.clone());
        let (command, why) = match hazard {
            Some(h) => {
                self.watchdog_stops += 1;
                (SteeringCommand::stop(cycle), Why::Watchdog(h))
            }
            None => (self.arbiter.decide(cycle), why),
        };
        if !matches!(why, Why::Watchdog(_)) {
            // Capture times map onto the wall clock through the newest pose.
            let offset = self.pose.map(|(utime, at)| at - utime);
            // Cells known only from OBSTACLE_CELLS are in the map once held
            // long enough; the others came with the cycle.
            let hold = self.hold_us;
            let (now_in, later): (Vec<_>, Vec<_>) = self
                .images
                .drain(..)
                .partition(|(capture, arrival)| arrival.is_some() || capture + hold <= cycle);
            self.images = later;
            for (capture, arrival) in now_in {
                if let Some(arrival) = arrival {
                    self.arrival_to_command_ms
                        .add((now - arrival) as f64 * 1e-3);
                }
                if let Some(offset) = offset {
                    self.capture_to_command_ms
                        .add((now - (capture + offset)) as f64 * 1e-3);
                }
            }
        }
        self.publish(command, why, now)
    }

    fn publish(&mut self, command: SteeringCommand, why: Why, now: i64) -> Decided {
        self.last_publish = Some(now);
        self.commands += 1;
        if command.is_stop() {
            self.stops += 1;
        }
        Decided { command, why }
    }

    /// The stage's figures.
    pub fn status(&self, status: &mut NodeStatus) {
        status.handled = self.commands;
        status.set("stops", self.stops);
        status.set("watchdog_stops", self.watchdog_stops);
        status.set("deadline_decisions", self.deadline_decisions);
        let stats = self.arbiter.stats();
        status.set("required_stale", stats.stops_required_stale);
        status.set("rejected_votes", stats.rejected_votes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_arbiter::Votes;
    use arcnav_perception::FovPolygon;
    use nalgebra::Vector3;

    fn pose(utime: Utime, x: f64) -> Pose {
        Pose {
            utime,
            world_from_vehicle: arcnav_vehicle::frames::isometry_from_xyz_rpy(
                [x, 0.0, 0.0],
                0.0,
                0.0,
                0.0,
            ),
            velocity: Vector3::new(2.0, 0.0, 0.0),
            yaw_rate: 0.0,
        }
    }

    fn report(utime: Utime) -> ObstacleReport {
        ObstacleReport {
            utime,
            sensor: "erim".into(),
            cell_size_m: 0.2,
            cells: Vec::new(),
            regions: Vec::new(),
            fov: FovPolygon::new(Vec::new()),
        }
    }

    fn config(reproduce: bool, events: bool) -> Config {
        let mut c = Config::default();
        c.live.reproduce_lockstep = reproduce;
        c.live.decide_on_new_cells = events;
        c
    }

    #[test]
    fn cycles_follow_the_pose_clock_like_the_lockstep_pipeline() {
        let mut stage = MapStage::new(&config(true, false));
        let mut out = Vec::new();
        // Poses every 20 ms from t = 1 s: cycles at 1.0, 1.1, 1.2 s.
        for k in 0..=10 {
            stage.on_pose(pose(1_000_000 + k * 20_000, k as f64 * 0.04), &mut out);
        }
        let times: Vec<Utime> = out.iter().map(|c| c.utime).collect();
        assert_eq!(times, vec![1_000_000, 1_100_000, 1_200_000]);
        // A cycle at t sees the pose at t.
        assert_eq!(out[1].pose.utime, 1_100_000);
        // Poses that skip a cycle time: the cycle uses the pose before it.
        let mut out = Vec::new();
        stage.on_pose(pose(1_230_000, 0.5), &mut out);
        stage.on_pose(pose(1_310_000, 0.6), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].utime, out[0].pose.utime), (1_300_000, 1_230_000));
    }

    #[test]
    fn held_reports_reach_the_map_at_capture_plus_latency() {
        let mut stage = MapStage::new(&config(true, false));
        let mut out = Vec::new();
        stage.on_pose(pose(0, 0.0), &mut out);
        stage.on_report(report(0), 77, &mut out);
        assert_eq!(stage.waiting(), 1);
        out.clear();
        // Latency 0.3 s: not delivered to the cycles at 0.1 and 0.2 s...
        for k in 1..15 {
            stage.on_pose(pose(k * 20_000, 0.0), &mut out);
        }
        assert!(out.iter().all(|c| c.images.is_empty()));
        // ... but to the cycle at 0.3 s.
        stage.on_pose(pose(320_000, 0.0), &mut out);
        let at_300 = out.iter().find(|c| c.utime == 300_000).unwrap();
        assert_eq!(at_300.images, vec![(0, 77)]);
        assert_eq!(stage.waiting(), 0);
        assert_eq!(stage.late_reports, 0);
        // A report whose delivery time has passed is counted late.
        stage.on_report(report(0), 78, &mut out);
        assert_eq!(stage.late_reports, 1);
    }

    #[test]
    fn new_cells_trigger_a_decision_at_once_when_asked() {
        let mut stage = MapStage::new(&config(false, true));
        let mut out = Vec::new();
        stage.on_pose(pose(0, 0.0), &mut out);
        stage.on_pose(pose(20_000, 0.0), &mut out);
        out.clear();
        stage.on_report(report(10_000), 5, &mut out);
        assert_eq!(out.len(), 1);
        assert!(out[0].event);
        assert_eq!(out[0].utime, 20_000);
        assert_eq!(out[0].images, vec![(10_000, 5)]);
        // Without events, the cells wait for the next cycle.
        let mut stage = MapStage::new(&config(false, false));
        let mut out = Vec::new();
        stage.on_pose(pose(0, 0.0), &mut out);
        out.clear();
        stage.on_report(report(0), 6, &mut out);
        assert!(out.is_empty());
        stage.on_pose(pose(100_000, 0.0), &mut out);
        assert_eq!(out[0].images, vec![(0, 6)]);
    }

    #[test]
    fn a_pose_stream_jump_is_not_caught_up_cycle_by_cycle() {
        let mut stage = MapStage::new(&config(false, false));
        let mut out = Vec::new();
        stage.on_pose(pose(0, 0.0), &mut out);
        stage.on_pose(pose(60_000_000, 0.0), &mut out);
        assert!(out.len() <= 12, "{} cycles", out.len());
        assert!(stage.skipped_cycles > 500);
        // Time going backwards restarts the clock.
        out.clear();
        stage.on_pose(pose(5_000, 0.0), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].utime, 5_000);
    }

    fn votes(name: &str, utime: Utime, arcs: usize) -> BehaviourVotes {
        let mut v = Votes::new(arcs);
        for i in 0..arcs {
            v.set(i, 0.5);
        }
        BehaviourVotes {
            behaviour: name.into(),
            utime,
            votes: v,
        }
    }

    fn arbiter_stage(now: i64) -> (ArbiterStage, usize) {
        let config = Config::default();
        let arcs = config.arc_set().unwrap();
        let n = arcs.len();
        let arbiter = Arbiter::new(&config.arbiter, arcs, &config.vehicle);
        let expected = vec!["goal_seeking".into(), "obstacle_avoidance".into()];
        (ArbiterStage::new(&config, arbiter, expected, now), n)
    }

    #[test]
    fn the_arbiter_decides_when_every_expected_behaviour_voted() {
        let t0 = 1_000_000_000;
        let (mut stage, n) = arbiter_stage(t0);
        stage.on_pose(5_000_000, t0);
        stage.on_perceived(4_900_000, t0 - 2_000);
        let first = stage
            .on_votes(&votes("goal_seeking", 5_000_000, n), &[], t0 + 100)
            .unwrap();
        assert!(first.is_none());
        let decided = stage
            .on_votes(
                &votes("obstacle_avoidance", 5_000_000, n),
                &[(4_900_000, t0 - 2_000)],
                t0 + 200,
            )
            .unwrap()
            .unwrap();
        assert_eq!(decided.why, Why::Complete);
        assert_eq!(decided.command.utime, 5_000_000);
        assert!(decided.command.speed_mps > 0.0);
        let latency = stage.arrival_to_command_ms.summary();
        assert_eq!(latency.count, 1);
        assert!((latency.max - 2.2).abs() < 1e-9);
        // Capture 100 ms before the pose that arrived at t0: 100.2 ms.
        assert!((stage.capture_to_command_ms.summary().max - 100.2).abs() < 1e-9);
    }

    #[test]
    fn a_missing_behaviour_is_waited_for_until_the_deadline() {
        let t0 = 1_000_000_000;
        let (mut stage, n) = arbiter_stage(t0);
        stage.on_pose(5_000_000, t0);
        stage.on_perceived(5_000_000, t0);
        assert!(
            stage
                .on_votes(&votes("obstacle_avoidance", 5_000_000, n), &[], t0)
                .unwrap()
                .is_none()
        );
        assert!(stage.on_tick(t0 + 10_000).is_none());
        let decided = stage.on_tick(t0 + 50_000).unwrap();
        assert_eq!(
            decided.why,
            Why::Deadline {
                missing: vec!["goal_seeking".into()]
            }
        );
        assert!(decided.command.speed_mps > 0.0);
        assert_eq!(stage.deadline_decisions, 1);
    }

    #[test]
    fn the_watchdog_stops_on_stale_poses_images_or_silence() {
        let t0 = 1_000_000_000;
        let (mut stage, n) = arbiter_stage(t0);
        // Nothing yet: stop, repeated at the command rate, not more often.
        let first = stage.on_tick(t0).unwrap();
        assert_eq!(first.why, Why::Watchdog(Hazard::NoPose));
        assert!(first.command.is_stop());
        assert!(stage.on_tick(t0 + 50_000).is_none());
        assert!(stage.on_tick(t0 + 100_000).is_some());
        // Fresh inputs and votes: driving.
        let t1 = t0 + 200_000;
        stage.on_pose(9_000_000, t1);
        stage.on_perceived(9_000_000, t1);
        for name in ["goal_seeking", "obstacle_avoidance"] {
            stage.on_votes(&votes(name, 9_000_000, n), &[], t1).unwrap();
        }
        assert!(stage.on_tick(t1 + 100_000).is_none());
        // Poses stop: the next decision is a stop, and so is every tick.
        let t2 = t1 + 600_000;
        for name in ["goal_seeking", "obstacle_avoidance"] {
            if let Some(d) = stage.on_votes(&votes(name, 9_100_000, n), &[], t2).unwrap() {
                assert!(matches!(d.why, Why::Watchdog(Hazard::PoseStale { .. })));
                assert!(d.command.is_stop());
                // Stop at the sensor time of the cycle.
                assert_eq!(d.command.utime, 9_100_000);
            }
        }
        let tick = stage.on_tick(t2 + 100_000).unwrap();
        assert!(matches!(tick.why, Why::Watchdog(Hazard::PoseStale { .. })));
        // Extrapolated sensor clock.
        assert_eq!(tick.command.utime, 9_000_000 + 700_000);
        // Poses back but images stale.
        let t3 = t2 + 1_000_000;
        stage.on_pose(10_000_000, t3);
        let tick = stage.on_tick(t3).unwrap();
        assert!(matches!(
            tick.why,
            Why::Watchdog(Hazard::ImagesStale { .. })
        ));
        // Everything fresh but nobody votes: stop once vote_timeout_s passes.
        let t4 = t3 + 1_100_000;
        stage.on_pose(11_000_000, t4);
        stage.on_perceived(11_000_000, t4);
        let tick = stage.on_tick(t4).unwrap();
        assert!(matches!(
            tick.why,
            Why::Watchdog(Hazard::NoDecisions { .. })
        ));
        assert!(stage.watchdog_stops >= 4);
        let last = stage.final_stop(t4 + 1);
        assert_eq!(last.why, Why::Final);
        assert!(last.command.is_stop());
    }

    #[test]
    fn newest_wins_keeps_the_newest_and_counts_what_it_replaced() {
        let (slot, receiver, dropped) = newest_wins();
        slot.put(1);
        slot.put(2);
        slot.put(3);
        assert_eq!(receiver.try_recv(), Ok(3));
        assert_eq!(dropped.load(Ordering::Relaxed), 2);
        assert_eq!(slot.dropped(), 2);
        slot.put(4);
        assert_eq!(receiver.try_recv(), Ok(4));
        assert!(receiver.try_recv().is_err());
        // Dropping the producer ends the consumer's loop.
        drop(slot);
        assert!(receiver.recv().is_err());
    }

    #[test]
    fn a_slow_consumer_never_holds_more_than_one_item() {
        let (slot, receiver, dropped) = newest_wins::<Vec<u8>>();
        let consumer = std::thread::spawn(move || {
            let mut seen = Vec::new();
            while let Ok(item) = receiver.recv() {
                seen.push(item[0]);
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            seen
        });
        for i in 0..=200u8 {
            slot.put(vec![i; 1 << 16]);
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
        let dropped_count = dropped.load(Ordering::Relaxed);
        drop(slot);
        let seen = consumer.join().unwrap();
        // Everything is either seen or counted, the newest is never lost,
        // and what was seen is in order.
        assert_eq!(seen.len() as u64 + dropped_count, 201);
        assert_eq!(seen.last(), Some(&200));
        assert!(seen.windows(2).all(|w| w[0] < w[1]));
        assert!(dropped_count > 0, "a 2 ms consumer fed every 0.1 ms drops");
    }
}
