//! `arcnav run`: every node in one process, a thread per node, crossbeam
//! channels between them.
//!
//! ```text
//!  LCM ─► io ─┬─ poses ──────────────► perception ─ reports ─► localmap ─ cycle ─► behaviours
//!             ├─ newest range image ──►    │                    ▲  (newest)            │
//!             ├─ poses ──────────────────────────────────────────┘                     │ votes
//!             └─ poses ─► arbiter ◄── evaluated ─────┘                                 │
//!                           ▲ └──────────────── commands (debrief) ───────────────────►│
//!                           └──────────────────────────────────────────────────────────┘
//!                           └─► STEERING_COMMAND
//! ```
//!
//! Range images travel through a one-place newest-wins queue: perception
//! that falls behind skips to the newest image (the skipped ones are
//! counted). The map snapshot travels as an `Arc`: behaviours never wait for
//! the map, and one that falls behind skips to the newest cycle (counted) —
//! except with `live.reproduce_lockstep`, where every cycle is voted on, in
//! order, each after the previous cycle's command was debriefed, exactly as
//! in lock-step. Shutdown (signal, `--duration`) closes the channels from the
//! io thread down the pipeline; the arbiter publishes a final stop last.
//!
//! Every thread drives a node of [`arcnav_pipeline`]; the decision cycle
//! itself is the pipeline's [`arcnav_pipeline::DecisionCycle`].

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use arcnav_behaviours::Mission;
use arcnav_bus::transport::{Lcm, Publisher};
use arcnav_perception::ObstacleReport;
use arcnav_pipeline::{ArbiterNode, BehaviourSet, Cycle, Decided};
use arcnav_vehicle::{Pose, SteeringCommand, Utime};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, select};

use super::clock::{Clock, SharedClock};
use super::guarded::{GuardInput, RunGuard};
use super::handoff::{self, Arrived, Handoff};
use super::io::{External, IoRoutes, Ticker, io_loop, publish_command};
pub(crate) use super::options::ToArbiter;
pub use super::options::{LiveError, LiveOptions, StopWhen};
use super::workers::{MapStage, map_worker, perception_node, perception_worker};
use super::{LiveReport, NodeStatus, Samples, arbiter_status};
use arcnav_config::Resolved;
use arcnav_wire as wire;

/// Range-image slices that may wait for perception: 16 frames of a
/// 2048-column lidar in 16-column slices. Beyond, slices are dropped
/// (counted by the io node as a full queue; their lines count as lost).
pub(crate) const SLICE_QUEUE: usize = 2048;
use arcnav_bus::messages::channels;

fn spawn<T: Send + 'static>(
    node: &'static str,
    body: impl FnOnce() -> T + Send + 'static,
) -> Result<(&'static str, JoinHandle<T>), LiveError> {
    std::thread::Builder::new()
        .name(node.to_owned())
        .spawn(body)
        .map(|handle| (node, handle))
        .map_err(|source| LiveError::Spawn { node, source })
}

fn join<T>((node, handle): (&'static str, JoinHandle<T>)) -> Result<T, LiveError> {
    handle.join().map_err(|_| LiveError::Panicked(node))
}

/// Runs every node in this process on `lcm` until `options.stop`.
pub fn run(
    config: &Resolved,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    super::options::refuse_fault(config)?;
    let started = Instant::now();
    let clock = options.clock();
    let live = config.live.clone();
    let perception = perception_node(config)?;
    let map = MapStage::new(config);
    let behaviours = config.behaviour_set();
    let arcs = config.arcs.clone();
    let arbiter = ArbiterNode::new(
        config.arbiter(),
        config.expected_behaviours(),
        &live,
        &config.pipeline,
        clock.now_us(),
    );
    let period_s = 1.0 / config.pipeline.command_rate_hz;
    let capacity = live.queue_capacity;

    let publisher = lcm.publisher();

    let (feed, sensed) = handoff::sensor_feed(SLICE_QUEUE);
    let (perception_poses_tx, perception_poses) = crossbeam_channel::bounded::<Pose>(capacity);
    let (map_poses_tx, map_poses) = crossbeam_channel::bounded::<Pose>(capacity);
    let (reports_tx, reports) = crossbeam_channel::bounded::<Arrived<ObstacleReport>>(capacity);
    let (cycle_handoff, cycles, _) = Handoff::new(live.reproduce_lockstep, capacity);
    let (waypoints_tx, waypoints) = crossbeam_channel::bounded::<Mission>(16);
    let (commands_tx, commands) = crossbeam_channel::bounded::<SteeringCommand>(capacity);
    let (arbiter_tx, arbiter_rx) = crossbeam_channel::bounded::<ToArbiter>(capacity);

    let perception_thread = {
        let arbiter_tx = arbiter_tx.clone();
        let live = live.clone();
        let clock = clock.clone();
        spawn("perception", move || {
            let now = clock.clone();
            perception_worker(
                perception,
                perception_poses,
                sensed,
                &live,
                clock,
                |report, arrival| {
                    let _ = arbiter_tx.try_send(ToArbiter::Perceived(report.utime, now.now_us()));
                    // Reports are never dropped: perception waits for the map.
                    let _ = reports_tx.send(Arrived {
                        item: report,
                        wall: arrival,
                    });
                },
            )
        })?
    };

    let map_thread = {
        let period = live.status_period_s;
        let clock = clock.clone();
        spawn("localmap", move || {
            map_worker(
                map,
                map_poses,
                reports,
                cycle_handoff,
                &*clock,
                period,
                period_s,
            )
        })?
    };

    let behaviours_thread = {
        let voter = Voter {
            behaviours,
            commands,
            waypoints,
            // Reproducing lock-step: each vote after the previous command.
            debrief_wait: live
                .reproduce_lockstep
                .then(|| Duration::from_secs_f64(config.arbiter.vote_timeout_s)),
            awaiting: None,
            map_out: (!config.external.is_empty()).then(|| lcm.publisher()),
            map_elevation: config.external.values().any(|e| e.elevation),
        };
        let arbiter_tx = arbiter_tx.clone();
        let period = live.status_period_s;
        let clock = clock.clone();
        spawn("behaviours", move || {
            voter.run(cycles, &arbiter_tx, &*clock, period, period_s)
        })?
    };

    // The guard, on a thread of its own fed by the io thread: every
    // command the arbiter decides goes through it.
    let guard = config.guard.enabled.then(|| {
        RunGuard::new(arcnav_guard::Guard::new(
            &config.guard,
            &config.vehicle,
            &config.sensors,
        ))
    });
    let (guard_tx, guard_rx) = crossbeam_channel::bounded::<GuardInput>(capacity);
    let guard_thread = match &guard {
        Some(guard) => {
            let guard = guard.clone();
            Some(spawn("guard", move || guard.run(&guard_rx))?)
        }
        None => None,
    };

    let arbiter_thread = {
        let kinematics = config.vehicle.kinematics;
        let tap = options.command_tap.clone();
        let period = live.status_period_s;
        let tick = Duration::from_secs_f64((period_s / 4.0).min(0.01));
        let clock = clock.clone();
        let guard = guard.clone();
        spawn("arbiter", move || {
            let now = clock.clone();
            arbiter_worker(arbiter, arbiter_rx, &*clock, tick, period, |decided| {
                let guarded;
                let decided = match &guard {
                    Some(guard) => {
                        guarded = guard.judge(decided, now.now_us(), &publisher);
                        &guarded
                    }
                    None => decided,
                };
                publish_command(&publisher, decided, tap.as_ref(), kinematics);
                let _ = commands_tx.try_send(decided.command);
            })
        })?
    };

    let external = (!config.external.is_empty()).then(|| External {
        names: config.external.keys().cloned().collect(),
        arcs: arcs.clone(),
    });
    let routes = IoRoutes {
        perception_poses: Some(perception_poses_tx),
        map_poses: Some(map_poses_tx),
        images: Some(feed),
        waypoints: Some(waypoints_tx),
        arbiter: Some(arbiter_tx),
        external,
        guard: guard.is_some().then_some(guard_tx),
    };
    routes.subscribe(&mut lcm)?;
    let io_status = io_loop(&mut lcm, options, &live, routes);
    tracing::info!("shutting down: final stop follows");
    let perception_status = join(perception_thread)?;
    let map_status = join(map_thread)?;
    let behaviours_status = join(behaviours_thread)?;
    let (arbiter_status, arbiter) = join(arbiter_thread)?;
    let guard_status = guard_thread.map(join).transpose()?;
    let io_status = io_status?;
    let counts = arbiter.counts();
    Ok(LiveReport {
        wall_s: started.elapsed().as_secs_f64(),
        commands: counts.commands,
        stops: counts.stops,
        arrival_to_command_ms: arbiter.arrival_to_command_ms.summary(),
        capture_to_command_ms: arbiter.capture_to_command_ms.summary(),
        nodes: [
            io_status,
            perception_status,
            map_status,
            behaviours_status,
            arbiter_status,
        ]
        .into_iter()
        .chain(guard_status)
        .collect(),
    })
}

/// The behaviours' thread: each cycle voted on, the commands debriefed.
struct Voter {
    behaviours: BehaviourSet,
    commands: Receiver<SteeringCommand>,
    waypoints: Receiver<Mission>,
    /// `Some`: before voting, wait this long at most for the command of the
    /// cycle voted on last (`awaiting`).
    debrief_wait: Option<Duration>,
    awaiting: Option<Utime>,
    /// Publishes each cycle's LOCAL_MAP for behaviours in other processes.
    map_out: Option<Publisher>,
    /// ... with the elevation layer (an external behaviour asks for it:
    /// `[behaviours.external.NAME] elevation`).
    map_elevation: bool,
}

impl Voter {
    fn run(
        mut self,
        cycles: Receiver<Cycle<i64>>,
        arbiter: &Sender<ToArbiter>,
        clock: &dyn Clock,
        status_period_s: f64,
        period_s: f64,
    ) -> NodeStatus {
        let mut status = NodeStatus::new("behaviours");
        let mut busy = Samples::default();
        let mut ticker = Ticker::new(status_period_s, clock.now_us());
        loop {
            select! {
                recv(cycles) -> cycle => {
                    let Ok(cycle) = cycle else { break };
                    self.catch_up();
                    let started = Instant::now();
                    let votes = self
                        .behaviours
                        .on_cycle(cycle.resets, cycle.utime, &cycle.pose, &cycle.map)
                        .to_vec();
                    status.took(&mut busy, started.elapsed().as_secs_f64() * 1e3, period_s * 1e3);
                    status.handled += 1;
                    // The route gave a waypoint up (it says why as it does,
                    // and votes to stand or goes on: `[mission] on_unreachable`).
                    status.set("unreachable_waypoints", self.behaviours.unreachable() as u64);
                    if self.debrief_wait.is_some() {
                        self.awaiting = Some(cycle.utime);
                    }
                    let _ = arbiter.send(ToArbiter::Votes { votes, images: cycle.images });
                    if let Some(out) = &self.map_out {
                        let mut msg = wire::map_to_wire(cycle.utime, &cycle.pose, &cycle.map, cycle.resets);
                        if !self.map_elevation {
                            wire::drop_elevation(&mut msg);
                        }
                        if let Err(e) = out.publish_message(channels::LOCAL_MAP, &msg) {
                            tracing::error!(%e, "cannot publish the local map");
                        }
                    }
                },
                recv(self.commands) -> command => {
                    if let Ok(command) = command {
                        self.debrief(&command);
                    }
                },
                recv(self.waypoints) -> mission => {
                    if let Ok(mission) = mission {
                        self.behaviours.on_waypoints(mission);
                    }
                },
                default(Duration::from_millis(100)) => {}
            }
            if ticker.due(clock.now_us()) {
                status.busy_ms = busy.summary();
                status.log();
            }
        }
        status.busy_ms = busy.summary();
        status
    }

    /// Takes the commands and waypoints that came, waiting first for the
    /// command of the cycle voted on last when reproducing lock-step.
    fn catch_up(&mut self) {
        if let Some(wait) = self.debrief_wait {
            let until = Instant::now() + wait;
            while self.awaiting.is_some() {
                let Ok(command) = self.commands.recv_deadline(until) else {
                    break;
                };
                self.debrief(&command);
            }
            self.awaiting = None;
        }
        while let Ok(command) = self.commands.try_recv() {
            self.debrief(&command);
        }
        for mission in self.waypoints.try_iter() {
            self.behaviours.on_waypoints(mission);
        }
    }

    /// Tells the behaviours the command that was sent; the cycle voted on
    /// last is debriefed once a command as new as it has come (whether it
    /// came while waiting for the next cycle or before).
    fn debrief(&mut self, command: &SteeringCommand) {
        self.behaviours.on_command(command);
        if self.awaiting.is_some_and(|cycle| command.utime >= cycle) {
            self.awaiting = None;
        }
    }
}

/// The arbiter's thread: votes, poses and evaluated images in, commands out
/// (to `publish`), a final stop when the inputs close.
fn arbiter_worker(
    mut arbiter: ArbiterNode,
    inputs: Receiver<ToArbiter>,
    clock: &dyn Clock,
    tick: Duration,
    status_period_s: f64,
    mut publish: impl FnMut(&Decided),
) -> (NodeStatus, ArbiterNode) {
    let mut status = NodeStatus::new("arbiter");
    let mut busy = Samples::default();
    let mut ticker = Ticker::new(status_period_s, clock.now_us());
    let mut out = Vec::new();
    loop {
        let now;
        match inputs.recv_timeout(tick) {
            Ok(message) => {
                now = clock.now_us();
                take(&mut arbiter, message, now, &mut out, &mut busy);
                // What else is queued too, before the watchdog judges the
                // inputs' age: behind a backlog, a newer pose may be waiting
                // behind the one just taken. Only what is queued now, so
                // that inputs coming faster than they are taken still let
                // it tick.
                let queued = inputs.len();
                for message in inputs.try_iter().take(queued) {
                    take(&mut arbiter, message, clock.now_us(), &mut out, &mut busy);
                }
            }
            Err(RecvTimeoutError::Timeout) => now = clock.now_us(),
            Err(RecvTimeoutError::Disconnected) => break,
        }
        arbiter.on_tick(clock.now_us(), &mut out);
        out.drain(..).for_each(|d| publish(&d));
        if ticker.due(now) {
            arbiter_status(&arbiter, &mut status);
            status.busy_ms = busy.summary();
            status.log();
        }
    }
    let last = arbiter.final_stop(clock.now_us());
    publish(&last);
    arbiter_status(&arbiter, &mut status);
    status.busy_ms = busy.summary();
    (status, arbiter)
}

/// One input of the arbiter's thread, taken at `now` (the executor's clock).
fn take(
    arbiter: &mut ArbiterNode,
    message: ToArbiter,
    now: i64,
    out: &mut Vec<Decided>,
    busy: &mut Samples,
) {
    match message {
        ToArbiter::Pose(utime, wall) => arbiter.on_pose(utime, wall),
        ToArbiter::Perceived(utime, wall) => arbiter.on_perceived(utime, wall),
        ToArbiter::Votes { votes, images } => {
            let started = Instant::now();
            let before = out.len();
            for (i, v) in votes.iter().enumerate() {
                let images = if i == 0 { &images[..] } else { &[] };
                if let Err(e) = arbiter.on_votes(v, images, now, out) {
                    tracing::warn!(%e, "votes refused by the arbiter");
                }
            }
            if out.len() > before {
                busy.add(started.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
}

/// `arcnav run` on an in-process LCM (`memq://`) that the caller feeds
/// through [`InProcess::publisher`]: for tests, benchmarks and tools.
pub struct InProcess {
    publisher: Publisher,
    stop: Arc<AtomicBool>,
    handle: JoinHandle<Result<LiveReport, LiveError>>,
}

impl InProcess {
    /// Starts the executor; returns once it receives. Every command is also
    /// sent to `tap` when given.
    pub fn start(config: &Resolved, tap: Option<Sender<Decided>>) -> Result<Self, LiveError> {
        Self::start_with(config, tap, None)
    }

    /// Like [`InProcess::start`], on `clock` (`None`: the wall clock).
    pub fn start_with(
        config: &Resolved,
        tap: Option<Sender<Decided>>,
        clock: Option<SharedClock>,
    ) -> Result<Self, LiveError> {
        let lcm = Lcm::new("memq://")?;
        let publisher = lcm.publisher();
        let (ready, is_ready) = crossbeam_channel::bounded(1);
        let options = LiveOptions {
            command_tap: tap,
            ready: Some(ready),
            clock,
            ..LiveOptions::default()
        };
        let stop = Arc::clone(&options.stop.flag);
        let config = config.clone();
        let handle = std::thread::Builder::new()
            .name("arcnav-run".into())
            .spawn(move || run(&config, lcm, &options))
            .map_err(|source| LiveError::Spawn {
                node: "arcnav-run",
                source,
            })?;
        if is_ready.recv().is_err() {
            // The executor ended before receiving: its error says why.
            return Err(handle
                .join()
                .map_err(|_| LiveError::Panicked("arcnav-run"))?
                .err()
                .unwrap_or(LiveError::Panicked("arcnav-run")));
        }
        Ok(Self {
            publisher,
            stop,
            handle,
        })
    }

    /// Publishes into the executor.
    pub fn publisher(&self) -> &Publisher {
        &self.publisher
    }

    /// Stops the executor (final stop included) and returns its figures.
    pub fn stop(self) -> Result<LiveReport, LiveError> {
        self.stop.store(true, Ordering::Relaxed);
        self.handle
            .join()
            .map_err(|_| LiveError::Panicked("arcnav-run"))?
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reproducing lock-step, the behaviours wait before each vote for the
    /// command of the cycle voted on last. A command taken between cycles
    /// (in the select loop) debriefs that cycle, so the next one does not
    /// wait for it again: it used to wait the whole vote timeout (1 s) for
    /// a command it already had, and the run fell further behind its feed
    /// each time until the watchdog stopped it for stale images.
    #[test]
    fn a_command_taken_between_cycles_is_not_waited_for_again() {
        let (commands_tx, commands) = crossbeam_channel::bounded(4);
        let (_waypoints_tx, waypoints) = crossbeam_channel::bounded(1);
        let mut voter = Voter {
            behaviours: Resolved::default().behaviour_set(),
            commands,
            waypoints,
            debrief_wait: Some(Duration::from_secs(1)),
            awaiting: Some(5),
            map_out: None,
            map_elevation: false,
        };
        voter.debrief(&SteeringCommand::stop(4));
        assert_eq!(voter.awaiting, Some(5), "an older command debriefs nothing");
        voter.debrief(&SteeringCommand::stop(5));
        assert_eq!(voter.awaiting, None, "the awaited cycle's command came");
        // Nothing awaited: the next cycle takes what came and votes.
        commands_tx.send(SteeringCommand::stop(6)).unwrap();
        voter.catch_up();
        assert!(voter.commands.is_empty());
        assert_eq!(voter.behaviours.last_command().map(|c| c.utime), Some(6));
    }

    /// Behind a backlog the arbiter takes every queued input before its
    /// watchdog judges their age: a pose 0.7 s old on the executor's clock
    /// (`live.pose_timeout_s` 0.5 s) queued in front of one 0.1 s old is no
    /// reason to stop. It used to tick after each input, and stopped for
    /// the stale pose while the fresh one waited behind it.
    #[test]
    fn a_fresh_pose_queued_behind_a_stale_one_stops_nothing() {
        use arcnav_pipeline::{Hazard, Why};

        use crate::clock::ManualClock;

        let config = Resolved::default();
        let start = 1_000_000_000_000;
        let clock = ManualClock::starting_at(start);
        let arbiter = ArbiterNode::new(
            config.arbiter(),
            config.expected_behaviours(),
            &config.live,
            &config.pipeline,
            start,
        );
        let (inputs, queue) = crossbeam_channel::unbounded();
        inputs.send(ToArbiter::Pose(5_000_000, start)).unwrap();
        inputs
            .send(ToArbiter::Pose(5_600_000, start + 600_000))
            .unwrap();
        drop(inputs);
        clock.set(start + 700_000);
        let mut published = Vec::new();
        arbiter_worker(arbiter, queue, &clock, Duration::from_millis(1), 0.0, |d| {
            published.push(d.why.clone())
        });
        assert!(
            !published
                .iter()
                .any(|why| matches!(why, Why::Watchdog(Hazard::PoseStale { .. }))),
            "{published:?}"
        );
        // What it did judge: fresh poses, and no image yet.
        assert!(
            published
                .iter()
                .any(|why| matches!(why, Why::Watchdog(Hazard::NoImage))),
            "{published:?}"
        );
    }
}
