//! The one decision cycle: the local map (Ganesha, 002 §5) and the clock
//! that turns its inputs into decision cycles. Every executor drives this
//! code; none has a copy of it.
//!
//! - **Pose clock.** A cycle runs every `1 / pipeline.command_rate_hz` of
//!   pose time, from the first pose. A cycle at `t` sees the newest pose at
//!   or before `t` and every report delivered at or before `t`.
//! - **Report delivery.** With [`Delivery::Held`] (lock-step, and live runs
//!   that reproduce it) a report reaches the map at `capture +
//!   perception_latency_s`, or at once when the pose clock has already passed
//!   that time; with [`Delivery::OnArrival`] (live) it reaches the map when
//!   it arrives, and may trigger a decision at once.
//! - **Time going backwards** (a log started over, a vehicle clock reset):
//!   the clock restarts at the new pose, waiting reports are dropped
//!   (counted), and the local map resets itself.
//! - **Time jumping ahead** by more than [`MAX_CATCH_UP_US`]: the cycles in
//!   the gap are skipped (counted), never run one by one; and no cycle runs
//!   past the newest pose, whatever time other inputs (an image, waypoints)
//!   claim.
//!
//! Cycles are handed to the caller in order through `out`; the caller lets
//! the behaviours vote and the arbiter decide, on its own thread or not.

use std::collections::VecDeque;
use std::sync::Arc;

use arcnav_localmap::{LocalMap, LocalMapConfig, MapSnapshot, PoseUpdate};
use arcnav_perception::ObstacleReport;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{Pose, Utime, VehicleConfig};
use serde::Serialize;

use crate::config::PipelineConfig;

/// A gap in the pose stream longer than this is not caught up cycle by
/// cycle, µs.
pub const MAX_CATCH_UP_US: Utime = 1_000_000;

/// The local map: obstacle reports + poses → snapshots.
pub struct LocalMapNode {
    pub map: LocalMap,
}

impl LocalMapNode {
    /// Built from `[localmap]` and the vehicle (a pose that moves faster
    /// than its top speed is a jump, and resets the map).
    pub fn new(config: &LocalMapConfig, vehicle: &VehicleConfig) -> Self {
        Self {
            map: LocalMap::new(config, vehicle),
        }
    }

    pub fn on_pose(&mut self, pose: &Pose) -> PoseUpdate {
        self.map.update(pose)
    }

    pub fn on_obstacles(&mut self, report: &ObstacleReport) {
        if let Err(e) = self.map.insert(report) {
            // Counted in the map's stats; said at the first of each power of
            // two so that a flood does not flood the log.
            let refused = self.map.stats().reports_refused;
            if refused.is_power_of_two() {
                tracing::warn!(%e, refused, "obstacle report refused by the local map");
            } else {
                tracing::debug!(%e, "obstacle report refused by the local map");
            }
        }
    }

    pub fn snapshot(&self) -> Arc<MapSnapshot> {
        self.map.snapshot()
    }
}

/// When obstacle reports reach the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// At capture + this latency, µs, as lock-step runs model perception's
    /// latency (002 §5 measured ~0.6 s).
    Held { latency_us: Utime },
    /// As they arrive; `decide_at_once` runs a cycle for them at once.
    OnArrival { decide_at_once: bool },
}

impl Delivery {
    /// Lock-step timing, from the pipeline's `perception_latency_s`.
    pub fn held(timing: &PipelineConfig) -> Self {
        Delivery::Held {
            latency_us: seconds_to_micros(timing.perception_latency_s.seconds()),
        }
    }
}

/// One decision cycle's input to the behaviours.
#[derive(Debug, Clone)]
pub struct Cycle<T = ()> {
    /// The cycle's time on the sensor clock; votes and the command carry it.
    pub utime: Utime,
    /// The newest pose at or before `utime`.
    pub pose: Pose,
    pub map: Arc<MapSnapshot>,
    /// Map resets so far: a change tells behaviours to forget their state.
    pub resets: u64,
    /// Acquisition time (an image's capture time, a streamed slice's last
    /// line) and tag (a live executor's arrival time) of the reports whose
    /// cells are new in this map.
    pub images: Vec<(Utime, T)>,
    /// Run because new cells arrived, not by the fixed-rate clock.
    pub event: bool,
}

/// What the cycle clock did, for reports and status lines.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CycleCounts {
    /// Cycles run (fixed-rate and event cycles).
    pub cycles: u64,
    /// Cycles run at once because new cells arrived.
    pub event_cycles: u64,
    /// Cycles skipped because the pose stream jumped ahead.
    pub skipped_cycles: u64,
    /// Times the pose clock went backwards and the cycle clock restarted.
    pub restarts: u64,
    /// Reports dropped waiting for delivery when the clock restarted.
    pub dropped_reports: u64,
    /// Reports whose delivery time had passed when they arrived (perception
    /// slower than the modelled latency).
    pub late_reports: u64,
    /// Local-map resets (pose jumps, time going backwards).
    pub map_resets: u64,
}

struct Waiting<T> {
    at: Utime,
    report: ObstacleReport,
    tag: T,
}

/// The local map with the cycle clock (see the module documentation).
/// `T` tags each report (a live executor's arrival time; `()` in lock-step).
pub struct DecisionCycle<T = ()> {
    pub map: LocalMapNode,
    period_us: Utime,
    delivery: Delivery,
    next_cycle: Option<Utime>,
    last_cycle: Option<Utime>,
    pose: Option<Pose>,
    waiting: VecDeque<Waiting<T>>,
    images: Vec<(Utime, T)>,
    counts: CycleCounts,
}

impl<T> DecisionCycle<T> {
    /// A cycle every `1 / timing.command_rate_hz` of pose time.
    pub fn new(map: LocalMapNode, timing: &PipelineConfig, delivery: Delivery) -> Self {
        Self {
            map,
            period_us: seconds_to_micros(1.0 / timing.command_rate_hz).max(1),
            delivery,
            next_cycle: None,
            last_cycle: None,
            pose: None,
            waiting: VecDeque::new(),
            images: Vec::new(),
            counts: CycleCounts::default(),
        }
    }

    /// The newest pose received.
    pub fn pose(&self) -> Option<&Pose> {
        self.pose.as_ref()
    }

    /// Reports waiting for their delivery time.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    pub fn counts(&self) -> CycleCounts {
        self.counts
    }

    /// A pose: runs the cycles before it (into `out`), then moves the map.
    /// The cycle at exactly the pose's time runs at the next
    /// [`advance`](Self::advance) past it, after every other input at that
    /// time (a live stage with no other inputs calls `advance(t, true)` at once).
    pub fn on_pose(&mut self, pose: Pose, out: &mut Vec<Cycle<T>>) {
        if self.pose.is_some_and(|p| pose.utime < p.utime) {
            tracing::warn!(
                utime = pose.utime,
                "pose time went backwards: cycle clock restarted"
            );
            self.counts.restarts += 1;
            self.counts.dropped_reports += self.waiting.len() as u64;
            self.waiting.clear();
            self.next_cycle = None;
            self.last_cycle = None;
        }
        if let Some(next) = self.next_cycle {
            // Exact, whatever the two times: a saturated gap had left the
            // clock 10¹⁰ cycles behind the pose, caught up one by one.
            let gap = i128::from(pose.utime) - i128::from(next);
            if gap > i128::from(MAX_CATCH_UP_US) {
                // Cycles in the gap would all decide on the stale pose
                // before it. Reports due in it still reach the map.
                let skip = gap / i128::from(self.period_us);
                let resumed = i128::from(next) + skip * i128::from(self.period_us);
                // `resumed` lies in (pose − period, pose]: it is an i64.
                self.next_cycle = Some(Utime::try_from(resumed).unwrap_or(pose.utime));
                let skip = u64::try_from(skip).unwrap_or(u64::MAX);
                self.counts.skipped_cycles = self.counts.skipped_cycles.saturating_add(skip);
                tracing::warn!(
                    skipped = skip,
                    gap_s = gap as f64 * 1e-6,
                    "pose stream jumped ahead: cycles in the gap skipped"
                );
            }
        }
        // The cycles before this pose, on the pose before it.
        self.run_due(pose.utime, false, pose.utime, out);
        if let PoseUpdate::Reset(reason) = self.map.on_pose(&pose) {
            tracing::warn!(%reason, "local map reset");
            self.counts.map_resets += 1;
        }
        self.pose = Some(pose);
        if self.next_cycle.is_none() {
            self.next_cycle = Some(pose.utime);
        }
    }

    /// An obstacle report, tagged `tag`.
    pub fn on_report(&mut self, report: ObstacleReport, tag: T, out: &mut Vec<Cycle<T>>) {
        let now = self.pose.map_or(Utime::MIN, |p| p.utime);
        match self.delivery {
            Delivery::Held { latency_us } => {
                let due = report.acquired_utime().saturating_add(latency_us);
                // A cycle after the modelled delivery time ran without it.
                if self.last_cycle.is_some_and(|c| c >= due) {
                    self.counts.late_reports += 1;
                }
                let at = now.max(due);
                let i = self.waiting.partition_point(|w| w.at <= at);
                self.waiting.insert(i, Waiting { at, report, tag });
            }
            Delivery::OnArrival { decide_at_once } => {
                self.map.on_obstacles(&report);
                self.images.push((report.acquired_utime(), tag));
                if decide_at_once && self.pose.is_some() {
                    let at = self.last_cycle.map_or(now, |c| c.max(now));
                    self.counts.event_cycles += 1;
                    self.run_cycle(at, true, out);
                }
            }
        }
    }

    /// Runs, in time order, every delivery and cycle due before `until` (at
    /// or before with `inclusive`); cycles only up to the newest pose (the
    /// pose clock: another input claiming a later time runs none).
    pub fn advance(&mut self, until: Utime, inclusive: bool, out: &mut Vec<Cycle<T>>) {
        let newest = self.pose.map_or(Utime::MIN, |p| p.utime);
        self.run_due(until, inclusive, newest, out);
    }

    fn run_due(
        &mut self,
        until: Utime,
        inclusive: bool,
        cycles_until: Utime,
        out: &mut Vec<Cycle<T>>,
    ) {
        let due = |t: Utime| if inclusive { t <= until } else { t < until };
        loop {
            let delivery = self.waiting.front().map(|w| w.at).filter(|&t| due(t));
            let cycle = self
                .next_cycle
                .filter(|&t| due(t) && t <= cycles_until && t < Utime::MAX);
            match (delivery, cycle) {
                (Some(d), c) if c.is_none_or(|c| d <= c) => self.deliver_first(),
                (_, Some(c)) => {
                    self.run_cycle(c, false, out);
                    self.next_cycle = Some(c.saturating_add(self.period_us));
                }
                _ => return,
            }
        }
    }

    fn deliver_first(&mut self) {
        if let Some(w) = self.waiting.pop_front() {
            self.map.on_obstacles(&w.report);
            self.images.push((w.report.acquired_utime(), w.tag));
        }
    }

    fn run_cycle(&mut self, at: Utime, event: bool, out: &mut Vec<Cycle<T>>) {
        let Some(pose) = self.pose else { return };
        self.counts.cycles += 1;
        self.last_cycle = Some(at);
        out.push(Cycle {
            utime: at,
            pose,
            map: self.map.snapshot(),
            resets: self.counts.map_resets,
            images: std::mem::take(&mut self.images),
            event,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
            ..ObstacleReport::default()
        }
    }

    fn cycle(delivery: Delivery) -> DecisionCycle<i64> {
        let timing = PipelineConfig::default();
        let map = LocalMapNode::new(&LocalMapConfig::default(), &VehicleConfig::default());
        DecisionCycle::new(map, &timing, delivery)
    }

    fn held() -> DecisionCycle<i64> {
        cycle(Delivery::held(&PipelineConfig::default()))
    }

    /// A pose, then the cycle at its own time (a stage with no other inputs).
    fn live_pose(c: &mut DecisionCycle<i64>, p: Pose, out: &mut Vec<Cycle<i64>>) {
        c.on_pose(p, out);
        c.advance(p.utime, true, out);
    }

    #[test]
    fn cycles_follow_the_pose_clock() {
        let mut c = held();
        let mut out = Vec::new();
        // Poses every 20 ms from t = 1 s: cycles at 1.0, 1.1, 1.2 s.
        for k in 0..=10 {
            live_pose(
                &mut c,
                pose(1_000_000 + k * 20_000, k as f64 * 0.04),
                &mut out,
            );
        }
        let times: Vec<Utime> = out.iter().map(|c| c.utime).collect();
        assert_eq!(times, vec![1_000_000, 1_100_000, 1_200_000]);
        // A cycle at t sees the pose at t.
        assert_eq!(out[1].pose.utime, 1_100_000);
        // Poses that skip a cycle time: the cycle uses the pose before it.
        let mut out = Vec::new();
        live_pose(&mut c, pose(1_230_000, 0.5), &mut out);
        live_pose(&mut c, pose(1_310_000, 0.6), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].utime, out[0].pose.utime), (1_300_000, 1_230_000));
    }

    #[test]
    fn a_cycle_at_a_poses_time_waits_for_the_other_inputs_at_that_time() {
        let mut c = held();
        let mut out = Vec::new();
        c.on_pose(pose(0, 0.0), &mut out);
        assert!(out.is_empty(), "the cycle at 0 runs after every input at 0");
        c.advance(0, false, &mut out);
        assert!(out.is_empty());
        c.advance(0, true, &mut out);
        assert_eq!(out.len(), 1);
    }

    #[test]
    fn held_reports_reach_the_map_at_capture_plus_latency() {
        let mut c = held();
        let mut out = Vec::new();
        live_pose(&mut c, pose(0, 0.0), &mut out);
        c.on_report(report(0), 77, &mut out);
        assert_eq!(c.waiting(), 1);
        out.clear();
        // Latency 0.3 s: not delivered to the cycles at 0.1 and 0.2 s...
        for k in 1..15 {
            live_pose(&mut c, pose(k * 20_000, 0.0), &mut out);
        }
        assert!(out.iter().all(|c| c.images.is_empty()));
        // ... but to the cycle at 0.3 s.
        live_pose(&mut c, pose(320_000, 0.0), &mut out);
        let at_300 = out.iter().find(|c| c.utime == 300_000).unwrap();
        assert_eq!(at_300.images, vec![(0, 77)]);
        assert_eq!(c.waiting(), 0);
        assert_eq!(c.counts().late_reports, 0);
        // A report whose delivery time has passed is counted late, and
        // reaches the next cycle.
        c.on_report(report(0), 78, &mut out);
        assert_eq!(c.counts().late_reports, 1);
        out.clear();
        live_pose(&mut c, pose(400_000, 0.0), &mut out);
        assert_eq!(out[0].images, vec![(0, 78)]);
    }

    #[test]
    fn new_cells_trigger_a_decision_at_once_when_asked() {
        let mut c = cycle(Delivery::OnArrival {
            decide_at_once: true,
        });
        let mut out = Vec::new();
        live_pose(&mut c, pose(0, 0.0), &mut out);
        live_pose(&mut c, pose(20_000, 0.0), &mut out);
        out.clear();
        c.on_report(report(10_000), 5, &mut out);
        assert_eq!(out.len(), 1);
        assert!(out[0].event);
        assert_eq!(out[0].utime, 20_000);
        assert_eq!(out[0].images, vec![(10_000, 5)]);
        // Without events, the cells wait for the next cycle.
        let mut c = cycle(Delivery::OnArrival {
            decide_at_once: false,
        });
        let mut out = Vec::new();
        live_pose(&mut c, pose(0, 0.0), &mut out);
        out.clear();
        c.on_report(report(0), 6, &mut out);
        assert!(out.is_empty());
        live_pose(&mut c, pose(100_000, 0.0), &mut out);
        assert_eq!(out[0].images, vec![(0, 6)]);
    }

    #[test]
    fn a_pose_stream_jump_is_not_caught_up_cycle_by_cycle() {
        let mut c = held();
        let mut out = Vec::new();
        live_pose(&mut c, pose(0, 0.0), &mut out);
        live_pose(&mut c, pose(60_000_000, 0.0), &mut out);
        assert!(out.len() <= 12, "{} cycles", out.len());
        assert!(c.counts().skipped_cycles > 500);
        // Time going backwards restarts the clock.
        out.clear();
        live_pose(&mut c, pose(5_000, 0.0), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].utime, 5_000);
        assert_eq!(c.counts().restarts, 1);
    }

    #[test]
    fn a_pose_at_the_far_end_of_time_is_caught_up_in_a_bounded_number_of_cycles() {
        // The wire refuses such times (`arcnav_vehicle::time::plausible`);
        // the clock stays bounded without that check too.
        for first in [Utime::MIN, Utime::MIN + 1, -1_000_000_000_000] {
            let mut c = held();
            let mut out = Vec::new();
            live_pose(&mut c, pose(1_700_000_000_000_000, 0.0), &mut out);
            live_pose(&mut c, pose(first, 0.0), &mut out);
            out.clear();
            live_pose(&mut c, pose(1_700_000_000_100_000, 0.0), &mut out);
            assert!(out.len() <= 12, "{first}: {} cycles", out.len());
            assert!(
                out.iter()
                    .all(|o| o.utime > 1_700_000_000_000_000 - 100_000)
            );
            assert!(c.counts().skipped_cycles > 1_000_000, "{first}");
        }
    }

    #[test]
    fn an_absurd_time_runs_no_cycles_and_the_clock_recovers() {
        let mut c = held();
        let mut out = Vec::new();
        live_pose(&mut c, pose(0, 0.0), &mut out);
        // Another input claims the end of time: no cycle past the newest pose.
        c.advance(Utime::MAX, true, &mut out);
        assert_eq!(out.len(), 1);
        // A pose at the end of time: skipped, never run one by one, no overflow.
        live_pose(&mut c, pose(Utime::MAX, 0.0), &mut out);
        assert!(out.len() <= 3, "{} cycles", out.len());
        // Back to normal time: the clock restarts there.
        out.clear();
        live_pose(&mut c, pose(2_000_000, 0.0), &mut out);
        assert_eq!(out.iter().map(|c| c.utime).collect::<Vec<_>>(), [2_000_000]);
    }

    #[test]
    fn time_going_backwards_drops_waiting_reports_and_counts_them() {
        let mut c = held();
        let mut out = Vec::new();
        live_pose(&mut c, pose(10_000_000, 0.0), &mut out);
        c.on_report(report(10_000_000), 1, &mut out);
        live_pose(&mut c, pose(0, 0.0), &mut out);
        assert_eq!(c.waiting(), 0);
        assert_eq!(c.counts().dropped_reports, 1);
    }
}
