//! The loops of the perception and local-map threads, shared by `arcnav
//! run` and `arcnav node`: they wait for their inputs, hand them to the
//! pipeline's nodes, and keep the nodes' figures.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use arcnav_perception::ObstacleReport;
use arcnav_pipeline::{Cycle, DecisionCycle, LiveConfig, PerceptionNode};
use arcnav_vehicle::{Pose, Utime};
use crossbeam_channel::{Receiver, select};

use super::clock::{Clock, SharedClock};
use super::handoff::{Arrived, Handoff, SensorInputs};
use super::io::Ticker;
use super::options::LiveError;
use super::{NodeStatus, Samples};
use arcnav_config::Resolved;

/// A helper thread for perception: the perception thread bins and judges
/// half of each large image itself and hands the other half to it.
pub struct PerceptionHelper(rayon::ThreadPool);

impl PerceptionHelper {
    pub fn new() -> Result<Self, LiveError> {
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .thread_name(|_| "perception-helper".into())
            .build()
            .map(Self)
            .map_err(|e| LiveError::Spawn {
                node: "perception-helper",
                source: std::io::Error::other(e),
            })
    }
}

/// The first task on the perception thread, the others on the helper
/// (rayon's pool does it so).
impl arcnav_perception::Runner for PerceptionHelper {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        self.0.run(tasks);
    }
}

/// The perception node of a live run. A perception thread that polls for
/// images (`live.perception_busy_poll`) hands half of each large image to a
/// [`PerceptionHelper`]; one that sleeps evaluates the image alone, because
/// the helper, asleep as well, would start its half only after its own
/// wake-up (~0.7 ms on a 2-vCPU VM) and make the tail longer than the
/// half saves (`cargo bench --bench live`, 128×2048: p99 arrival → command
/// 4.0-5.0 ms alone, 4.4-16.6 ms with the sleeping helper).
pub(crate) fn perception_node(config: &Resolved) -> Result<PerceptionNode, LiveError> {
    let mut node = config.perception_node()?;
    if config.live.perception_busy_poll {
        node.set_runner(Box::new(PerceptionHelper::new()?));
    }
    Ok(node)
}

/// Perception on its own thread's loop: poses, the newest image and every
/// slice in, reports (with the arrival time of what they rest on: their
/// image, or the first of the slices since the last report of the frame)
/// out, until the inputs close. With `live.perception_busy_poll` it polls
/// its inputs instead of sleeping.
pub(crate) fn perception_worker(
    mut node: PerceptionNode,
    poses: Receiver<Pose>,
    sensed: SensorInputs,
    live: &LiveConfig,
    clock: SharedClock,
    mut out: impl FnMut(ObstacleReport, i64),
) -> NodeStatus {
    let wait = if live.perception_busy_poll {
        Wait::Poll
    } else {
        Wait::Block
    };
    let status_period_s = live.status_period_s;
    let mut status = NodeStatus::new("perception");
    let mut busy = Samples::default();
    let mut ticker = Ticker::new(status_period_s, clock.now_us());
    let mut arrivals: VecDeque<(Utime, i64)> = VecDeque::new();
    // Slices no report has covered yet: (frame, last line, arrival).
    let mut slice_arrivals: VecDeque<(Utime, Utime, i64)> = VecDeque::new();
    let mut reports = Vec::new();
    let SensorInputs {
        images,
        slices,
        replaced,
    } = sensed;
    let fill = |status: &mut NodeStatus, node: &PerceptionNode, busy: &Samples| {
        let replaced = replaced.load(Ordering::Relaxed);
        status.handled = node.reports;
        status.busy_ms = busy.summary();
        status.set_overruns(
            replaced,
            "range images replaced by newer ones before evaluation",
        );
        status.queue(node.waiting());
        status.dropped = replaced + node.drops.total();
        status.set("replaced_by_newer", replaced);
        status.set("no_pose", node.drops.no_pose);
        status.set("invalid", node.drops.invalid);
        status.set("out_of_order", node.drops.out_of_order);
        status.set("clock_restart", node.drops.clock_restart);
        status.set("too_many_sensors", node.drops.too_many_sensors);
        status.set("late", node.late);
        status.set("fused_evaluations", node.fused.evaluations);
        status.set("fused_images", node.fused.images);
        let s = node.slices;
        status.dropped += s.invalid + s.stream.out_of_order + s.stream.inconsistent;
        status.set("slices", s.received);
        status.set("slices_invalid", s.invalid);
        status.set(
            "slices_out_of_order",
            s.stream.out_of_order + s.stream.inconsistent,
        );
        status.set("slice_lines_lost", s.stream.lost_lines);
        status.set("streamed_frames", s.stream.frames);
    };
    loop {
        let event = next(&poses, &images, &slices, wait);
        let started = Instant::now();
        match event {
            Next::First(pose) => node.on_pose(&pose, &mut |r| reports.push(r)),
            Next::Second(Arrived { item, wall }) => {
                for pose in poses.try_iter() {
                    node.on_pose(&pose, &mut |r| reports.push(r));
                }
                if arrivals.len() >= 64 {
                    arrivals.pop_front();
                }
                arrivals.push_back((item.utime, wall));
                node.on_image(item, &mut |r| reports.push(r));
            }
            Next::Third(Arrived { item, wall }) => {
                for pose in poses.try_iter() {
                    node.on_pose(&pose, &mut |r| reports.push(r));
                }
                if slice_arrivals.len() >= 4096 {
                    slice_arrivals.pop_front();
                }
                slice_arrivals.push_back((item.frame_utime, item.utime, wall));
                node.on_slice(item, &mut |r| reports.push(r));
            }
            Next::Idle => {}
            Next::Closed => break,
        }
        if !reports.is_empty() {
            busy.add(started.elapsed().as_secs_f64() * 1e3);
        }
        status.set_overruns(
            replaced.load(Ordering::Relaxed),
            "range images replaced by newer ones before evaluation",
        );
        for report in reports.drain(..) {
            // A streamed frame's report covers its slices acquired up to
            // its own acquisition: its arrival is the first of theirs.
            let covered = |&(frame, utime, _): &(Utime, Utime, i64)| {
                frame == report.utime && utime <= report.acquired_utime()
            };
            let first = slice_arrivals
                .iter()
                .filter(|s| covered(s))
                .map(|&(_, _, wall)| wall)
                .min();
            let arrival = if let Some(first) = first {
                slice_arrivals.retain(|s| !covered(s));
                first
            } else if report.acquired_utime() > report.utime {
                // Its slices were covered by an earlier report of the frame.
                clock.now_us()
            } else {
                let arrival = arrivals
                    .iter()
                    .find(|(utime, _)| *utime == report.utime)
                    .map_or_else(|| clock.now_us(), |(_, wall)| *wall);
                arrivals.retain(|(utime, _)| *utime > report.utime);
                arrival
            };
            out(report, arrival);
        }
        if ticker.due(clock.now_us()) {
            fill(&mut status, &node, &busy);
            status.log();
        }
    }
    fill(&mut status, &node, &busy);
    // Images and slices still waiting for a pose after their capture when
    // the inputs closed: that pose never came.
    let left = node.waiting() as u64;
    status.set("waiting_at_end", left);
    status.dropped += left;
    status
}

enum Next<A, B, C> {
    First(A),
    Second(B),
    Third(C),
    /// Nothing for 100 ms.
    Idle,
    /// An input closed: the executor is shutting down.
    Closed,
}

/// How a thread waits for its next message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Wait {
    /// Sleeps until one comes.
    Block,
    /// Polls, yielding the core to any other runnable thread between polls
    /// but never sleeping: the core stays awake.
    Poll,
}

/// The next message of any of the receivers.
fn next<A, B, C>(
    first: &Receiver<A>,
    second: &Receiver<B>,
    third: &Receiver<C>,
    wait: Wait,
) -> Next<A, B, C> {
    const IDLE: Duration = Duration::from_millis(100);
    if wait == Wait::Block {
        return select! {
            recv(first) -> m => m.map_or(Next::Closed, Next::First),
            recv(second) -> m => m.map_or(Next::Closed, Next::Second),
            recv(third) -> m => m.map_or(Next::Closed, Next::Third),
            default(IDLE) => Next::Idle,
        };
    }
    let since = Instant::now();
    loop {
        select! {
            recv(first) -> m => return m.map_or(Next::Closed, Next::First),
            recv(second) -> m => return m.map_or(Next::Closed, Next::Second),
            recv(third) -> m => return m.map_or(Next::Closed, Next::Third),
            default => {}
        }
        if since.elapsed() >= IDLE {
            return Next::Idle;
        }
        std::thread::yield_now();
    }
}

/// The local map of a live run: the pipeline's [`DecisionCycle`], its
/// reports tagged with their image's wall-clock arrival. A pose's own cycle
/// runs at once: at the map no other input shares a pose's time.
pub(crate) struct MapStage {
    pub cycle: DecisionCycle<i64>,
    out: Vec<Cycle<i64>>,
}

impl MapStage {
    pub fn new(config: &Resolved) -> Self {
        Self {
            cycle: config.decision_cycle(config.live_delivery()),
            out: Vec::new(),
        }
    }

    pub fn on_pose(&mut self, pose: Pose) {
        self.cycle.on_pose(pose, &mut self.out);
        self.cycle.advance(pose.utime, true, &mut self.out);
    }

    /// A report whose image arrived at wall-clock time `arrival`.
    pub fn on_report(&mut self, report: ObstacleReport, arrival: i64) {
        self.cycle.on_report(report, arrival, &mut self.out);
    }

    /// The cycles run since the last call.
    pub fn cycles(&mut self) -> std::vec::Drain<'_, Cycle<i64>> {
        self.out.drain(..)
    }

    /// The map's figures into `status`.
    pub fn fill(&self, status: &mut NodeStatus) {
        let counts = self.cycle.counts();
        status.handled = counts.cycles;
        status.queue(self.cycle.waiting());
        status.set("event_cycles", counts.event_cycles);
        status.set("late_reports", counts.late_reports);
        status.set("skipped_cycles", counts.skipped_cycles);
        status.set("clock_restarts", counts.restarts);
        status.set("resets", counts.map_resets);
        status.set("patches", self.cycle.map.map.len() as u64);
        // Reports the map refused (off the map, sensors past its limit,
        // cells out of range): had been logged at DEBUG only.
        status.set(
            "reports_refused",
            self.cycle.map.map.stats().reports_refused,
        );
    }
}

/// The local map's thread: poses and reports in, cycles out.
pub(crate) fn map_worker(
    mut map: MapStage,
    poses: Receiver<Pose>,
    reports: Receiver<Arrived<ObstacleReport>>,
    cycles: Handoff<Cycle<i64>>,
    clock: &dyn Clock,
    status_period_s: f64,
    period_s: f64,
) -> NodeStatus {
    let mut status = NodeStatus::new("localmap");
    let mut busy = Samples::default();
    let mut ticker = Ticker::new(status_period_s, clock.now_us());
    let fill = |status: &mut NodeStatus, map: &MapStage, busy: &Samples, cycles: &Handoff<_>| {
        map.fill(status);
        status.busy_ms = busy.summary();
        status.dropped = cycles.dropped();
    };
    loop {
        let event = next(
            &poses,
            &reports,
            &crossbeam_channel::never::<()>(),
            Wait::Block,
        );
        let started = Instant::now();
        match event {
            Next::First(pose) => map.on_pose(pose),
            Next::Second(Arrived { item, wall }) => map.on_report(item, wall),
            Next::Third(()) | Next::Idle => {}
            Next::Closed => break,
        }
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let mut ran = false;
        for cycle in map.cycles() {
            ran = true;
            if !cycles.put(cycle) {
                break;
            }
        }
        if ran {
            status.took(&mut busy, ms, period_s * 1e3);
        }
        if ticker.due(clock.now_us()) {
            fill(&mut status, &map, &busy, &cycles);
            status.log();
        }
    }
    fill(&mut status, &map, &busy, &cycles);
    status
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reports the map refuses are counted where a user sees them (the
    /// live node had shown "refused 0", the refusals at DEBUG only).
    #[test]
    fn the_map_stage_counts_the_reports_its_map_refuses() {
        let config = Resolved::default();
        let mut stage = MapStage::new(&config);
        stage.on_pose(Pose::at_rest(
            1_000_000,
            arcnav_vehicle::frames::planar_isometry(0.0, 0.0, 0.0),
        ));
        for i in 0..34 {
            let report = ObstacleReport {
                utime: 1_000_000,
                sensor: format!("s{i}"),
                cell_size_m: 0.2,
                ..ObstacleReport::default()
            };
            stage.on_report(report, 0);
        }
        let mut status = NodeStatus::new("localmap");
        stage.fill(&mut status);
        let refused = status.counters.iter().find(|(k, _)| k == "reports_refused");
        assert_eq!(refused.map(|(_, v)| *v), Some(2), "{:?}", status.counters);
    }

    #[test]
    fn next_brings_any_input_then_idle_then_closed_sleeping_or_polling() {
        for wait in [Wait::Block, Wait::Poll] {
            let (poses_tx, poses) = crossbeam_channel::bounded::<u8>(4);
            let (images_tx, images) = crossbeam_channel::bounded::<&str>(4);
            let (slices_tx, slices) = crossbeam_channel::bounded::<u16>(4);
            slices_tx.send(3).unwrap();
            assert!(matches!(
                next(&poses, &images, &slices, wait),
                Next::Third(3)
            ));
            let late = std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(20));
                images_tx.send("image").unwrap();
                images_tx
            });
            assert!(
                matches!(next(&poses, &images, &slices, wait), Next::Second("image")),
                "{wait:?}"
            );
            poses_tx.send(7).unwrap();
            assert!(matches!(
                next(&poses, &images, &slices, wait),
                Next::First(7)
            ));
            let images_tx = late.join().unwrap();
            // Nothing for 100 ms: idle, so the status still gets logged.
            let since = Instant::now();
            assert!(matches!(next(&poses, &images, &slices, wait), Next::Idle));
            assert!(since.elapsed() >= Duration::from_millis(100), "{wait:?}");
            // An input closed: the executor is shutting down.
            drop(images_tx);
            assert!(matches!(next(&poses, &images, &slices, wait), Next::Closed));
        }
    }
}
