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
//! the map. Shutdown (signal, `--duration`) closes the channels from the io
//! thread down the pipeline; the arbiter publishes a final stop last.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use arcnav_arbiter::{Arbiter, BehaviourVotes};
use arcnav_behaviours::{Mission, Registry};
use arcnav_bus::lcmtypes::steering_command_t;
use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_bus::transport::{Lcm, Publisher, ReceivedMessage, TransportError, wall_clock_utime};
use arcnav_perception::{ObstacleReport, RangeImage};
use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{Pose, SteeringCommand, Utime};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, select};

use super::stages::{ArbiterStage, Arrived, Cycle, Decided, MapStage, NewestWins, offer};
use super::{LiveReport, NodeStatus, Samples, stages};
use crate::config::Config;
use crate::pipeline::{BehaviourNode, PerceptionNode};
use crate::wire;

/// A live executor that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("invalid configuration: {0}")]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("LCM receive keeps failing: {0}")]
    Receive(TransportError),
    #[error("cannot start the {node} thread: {source}")]
    Spawn {
        node: &'static str,
        source: std::io::Error,
    },
    #[error("the {0} thread panicked (see the message above)")]
    Panicked(&'static str),
    #[error("no behaviour named {name:?} in the configuration (configured: {known})")]
    UnknownBehaviour { name: String, known: String },
}

/// When a live executor stops.
#[derive(Clone, Default)]
pub struct StopWhen {
    /// Set by SIGINT/SIGTERM (or a test).
    pub flag: Arc<AtomicBool>,
    /// After this much wall-clock time.
    pub after: Option<Duration>,
}

impl StopWhen {
    fn deadline(&self) -> Option<Instant> {
        self.after.map(|d| Instant::now() + d)
    }
}

/// How a live executor runs.
#[derive(Clone, Default)]
pub struct LiveOptions {
    pub stop: StopWhen,
    /// Every published command, with why, is also sent here (tests, tools).
    pub command_tap: Option<Sender<Decided>>,
    /// Told once the executor receives (every node built and subscribed).
    pub ready: Option<Sender<()>>,
}

/// Fires every `period` of wall clock (never when the period is zero).
pub(crate) struct Ticker {
    period_us: i64,
    next: i64,
}

impl Ticker {
    pub(crate) fn new(period_s: f64, now: i64) -> Self {
        let period_us = seconds_to_micros(period_s);
        Self {
            period_us,
            next: now + period_us,
        }
    }

    pub(crate) fn due(&mut self, now: i64) -> bool {
        if self.period_us <= 0 || now < self.next {
            return false;
        }
        self.next = now + self.period_us;
        true
    }
}

/// Receives until `stop`: `on` gets each message (or `None` when `tick`
/// passed without one) and the wall-clock time. A receive error is logged;
/// fifty in a row end the loop with that error.
pub(crate) fn pump(
    lcm: &mut Lcm,
    options: &LiveOptions,
    tick: Duration,
    mut on: impl FnMut(Option<ReceivedMessage>, i64),
) -> Result<(), LiveError> {
    let stop = &options.stop;
    let deadline = stop.deadline();
    let mut failures = 0;
    tracing::info!("ready: receiving");
    if let Some(ready) = &options.ready {
        let _ = ready.send(());
    }
    while !stop.flag.load(Ordering::Relaxed) && deadline.is_none_or(|d| Instant::now() < d) {
        match lcm.recv_timeout(tick) {
            Ok(message) => {
                failures = 0;
                on(message, wall_clock_utime());
            }
            Err(e) => {
                failures += 1;
                tracing::warn!(%e, "LCM receive failed");
                if failures >= 50 {
                    return Err(LiveError::Receive(e));
                }
                std::thread::sleep(tick);
                on(None, wall_clock_utime());
            }
        }
    }
    Ok(())
}

/// Decodes a received message; `None` (logged at debug, to be counted as
/// dropped) when it is not an arcnav message or is malformed.
pub(crate) fn decode(message: &ReceivedMessage) -> Option<AnyMessage> {
    match AnyMessage::decode(&message.data) {
        Ok(Some(m)) => Some(m),
        Ok(None) => {
            tracing::debug!(channel = %message.channel, "message of an unknown type dropped");
            None
        }
        Err(e) => {
            tracing::debug!(channel = %message.channel, %e, "undecodable message dropped");
            None
        }
    }
}

/// Publishes a decided command on STEERING_COMMAND (and to the tap).
pub(crate) fn publish_command(
    publisher: &Publisher,
    decided: &Decided,
    tap: Option<&Sender<Decided>>,
) {
    if let stages::Why::Deadline { missing } = &decided.why {
        tracing::debug!(?missing, "decided at the deadline without every behaviour");
    }
    if let Err(e) = publisher.publish_message(
        channels::STEERING_COMMAND,
        &steering_command_t::from(&decided.command),
    ) {
        tracing::error!(%e, "cannot publish the steering command");
    }
    if let Some(tap) = tap {
        let _ = tap.try_send(decided.clone());
    }
}

/// The behaviours a cycle's votes must come from: every configured one with
/// a positive weight.
pub(crate) fn expected_behaviours(config: &Config) -> Vec<String> {
    config
        .behaviours
        .keys()
        .filter(|name| config.arbiter.weight(name) > 0.0)
        .cloned()
        .collect()
}

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

impl arcnav_perception::Runner for PerceptionHelper {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        self.0.in_place_scope(|scope| {
            let (first, rest) = tasks.split_at_mut(1);
            for task in rest {
                scope.spawn(move |_| task());
            }
            first.iter_mut().for_each(|task| task());
        });
    }
}

/// The perception node of a live run. A perception thread that polls for
/// images (`live.perception_busy_poll`) hands half of each large image to a
/// [`PerceptionHelper`]; one that sleeps evaluates the image alone, because
/// the helper, asleep as well, would start its half only after its own
/// wake-up (~0.7 ms on a 2-vCPU VM) and make the tail longer than the
/// half saves (`cargo bench --bench live`, 128×2048: p99 arrival → command
/// 4.0-5.0 ms alone, 4.4-16.6 ms with the sleeping helper).
pub(crate) fn perception_node(config: &Config) -> Result<PerceptionNode, LiveError> {
    let mut node = PerceptionNode::new(config)?;
    if config.live.perception_busy_poll {
        node.set_runner(Box::new(PerceptionHelper::new()?));
    }
    Ok(node)
}

/// Perception on its own thread's loop: poses and the newest image in,
/// reports (with their image's arrival time) out, until the inputs close.
/// With `live.perception_busy_poll` it polls its inputs instead of sleeping.
pub(crate) fn perception_worker(
    mut node: PerceptionNode,
    poses: Receiver<Pose>,
    images: Receiver<Arrived<RangeImage>>,
    replaced: Arc<AtomicU64>,
    live: &super::LiveConfig,
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
    let mut ticker = Ticker::new(status_period_s, wall_clock_utime());
    let mut arrivals: VecDeque<(Utime, i64)> = VecDeque::new();
    let mut reports = Vec::new();
    let fill = |status: &mut NodeStatus, node: &PerceptionNode, busy: &Samples| {
        let replaced = replaced.load(Ordering::Relaxed);
        status.handled = node.reports;
        status.busy_ms = busy.summary();
        status.set_overruns(
            replaced,
            "range images replaced by newer ones before evaluation",
        );
        status.queue(node.waiting());
        status.dropped =
            replaced + node.drops.no_pose + node.drops.invalid + node.drops.out_of_order;
        status.set("replaced_by_newer", replaced);
        status.set("no_pose", node.drops.no_pose);
        status.set("invalid", node.drops.invalid);
        status.set("out_of_order", node.drops.out_of_order);
    };
    loop {
        let event = next(&poses, &images, wait);
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
            let arrival = arrivals
                .iter()
                .find(|(utime, _)| *utime == report.utime)
                .map_or_else(wall_clock_utime, |(_, wall)| *wall);
            arrivals.retain(|(utime, _)| *utime > report.utime);
            out(report, arrival);
        }
        if ticker.due(wall_clock_utime()) {
            fill(&mut status, &node, &busy);
            status.log();
        }
    }
    fill(&mut status, &node, &busy);
    status
}

enum Next<A, B> {
    First(A),
    Second(B),
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

/// The next message of either receiver.
fn next<A, B>(first: &Receiver<A>, second: &Receiver<B>, wait: Wait) -> Next<A, B> {
    const IDLE: Duration = Duration::from_millis(100);
    if wait == Wait::Block {
        return select! {
            recv(first) -> m => m.map_or(Next::Closed, Next::First),
            recv(second) -> m => m.map_or(Next::Closed, Next::Second),
            default(IDLE) => Next::Idle,
        };
    }
    let since = Instant::now();
    loop {
        select! {
            recv(first) -> m => return m.map_or(Next::Closed, Next::First),
            recv(second) -> m => return m.map_or(Next::Closed, Next::Second),
            default => {}
        }
        if since.elapsed() >= IDLE {
            return Next::Idle;
        }
        std::thread::yield_now();
    }
}

pub(crate) enum ToArbiter {
    Pose(Utime, i64),
    Perceived(Utime, i64),
    Votes {
        votes: Vec<BehaviourVotes>,
        images: Vec<(Utime, i64)>,
    },
}

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
    config: &Config,
    registry: &Registry,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    config.validate_with(registry)?;
    let started = Instant::now();
    let live = config.live.clone();
    let arcs = config.arc_set()?;
    let perception = perception_node(config)?;
    let mut map = MapStage::new(config);
    let mut behaviours =
        BehaviourNode::new(config.build_behaviours(registry, &arcs)?, arcs.clone());
    let arbiter = Arbiter::new(&config.arbiter, arcs, &config.vehicle);
    let mut arbiter = ArbiterStage::new(
        config,
        arbiter,
        expected_behaviours(config),
        wall_clock_utime(),
    );
    let period_s = 1.0 / config.pipeline.command_rate_hz;
    let capacity = live.queue_capacity;

    let publisher = lcm.publisher();

    let (image_slot, images, replaced) = stages::newest_wins::<Arrived<RangeImage>>();
    let (perception_poses_tx, perception_poses) = crossbeam_channel::bounded::<Pose>(capacity);
    let (map_poses_tx, map_poses) = crossbeam_channel::bounded::<Pose>(capacity);
    let (reports_tx, reports) = crossbeam_channel::bounded::<Arrived<ObstacleReport>>(capacity);
    let (cycle_slot, cycles, _) = stages::newest_wins::<Cycle>();
    let (waypoints_tx, waypoints) = crossbeam_channel::bounded::<Mission>(16);
    let (commands_tx, commands) = crossbeam_channel::bounded::<SteeringCommand>(capacity);
    let (arbiter_tx, arbiter_rx) = crossbeam_channel::bounded::<ToArbiter>(capacity);

    let perception_thread = {
        let arbiter_tx = arbiter_tx.clone();
        let live = live.clone();
        spawn("perception", move || {
            perception_worker(
                perception,
                perception_poses,
                images,
                replaced,
                &live,
                |report, arrival| {
                    let _ =
                        arbiter_tx.try_send(ToArbiter::Perceived(report.utime, wall_clock_utime()));
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
        spawn("localmap", move || {
            map_worker(&mut map, map_poses, reports, cycle_slot, period, period_s)
        })?
    };

    let behaviours_thread = {
        let arbiter_tx = arbiter_tx.clone();
        let period = live.status_period_s;
        spawn("behaviours", move || {
            let mut status = NodeStatus::new("behaviours");
            let mut busy = Samples::default();
            let mut ticker = Ticker::new(period, wall_clock_utime());
            let mut resets = 0;
            loop {
                select! {
                    recv(cycles) -> cycle => {
                        let Ok(cycle) = cycle else { break };
                        for command in commands.try_iter() {
                            behaviours.on_command(&command);
                        }
                        for mission in waypoints.try_iter() {
                            behaviours.on_waypoints(mission);
                        }
                        let started = Instant::now();
                        if cycle.resets != resets {
                            resets = cycle.resets;
                            behaviours.reset();
                        }
                        let votes = behaviours.on_cycle(cycle.utime, &cycle.pose, &cycle.map).to_vec();
                        status.took(&mut busy, started.elapsed().as_secs_f64() * 1e3, period_s * 1e3);
                        status.handled += 1;
                        let _ = arbiter_tx.send(ToArbiter::Votes { votes, images: cycle.images });
                    },
                    recv(commands) -> command => {
                        if let Ok(command) = command {
                            behaviours.on_command(&command);
                        }
                    },
                    recv(waypoints) -> mission => {
                        if let Ok(mission) = mission {
                            behaviours.on_waypoints(mission);
                        }
                    },
                    default(Duration::from_millis(100)) => {}
                }
                if ticker.due(wall_clock_utime()) {
                    status.busy_ms = busy.summary();
                    status.log();
                }
            }
            status.busy_ms = busy.summary();
            status
        })?
    };

    let arbiter_thread = {
        let tap = options.command_tap.clone();
        let period = live.status_period_s;
        let tick = Duration::from_secs_f64((period_s / 4.0).min(0.01));
        spawn("arbiter", move || {
            let mut status = NodeStatus::new("arbiter");
            let mut busy = Samples::default();
            let mut ticker = Ticker::new(period, wall_clock_utime());
            let publish = |decided: &Decided| {
                publish_command(&publisher, decided, tap.as_ref());
                let _ = commands_tx.try_send(decided.command);
            };
            loop {
                let message = arbiter_rx.recv_timeout(tick);
                let now = wall_clock_utime();
                match message {
                    Ok(ToArbiter::Pose(utime, wall)) => arbiter.on_pose(utime, wall),
                    Ok(ToArbiter::Perceived(utime, wall)) => arbiter.on_perceived(utime, wall),
                    Ok(ToArbiter::Votes { votes, images }) => {
                        let started = Instant::now();
                        let mut decided = None;
                        for (i, v) in votes.iter().enumerate() {
                            let images = if i == 0 { &images[..] } else { &[] };
                            match arbiter.on_votes(v, images, now) {
                                Ok(Some(d)) => decided = Some(d),
                                Ok(None) => {}
                                Err(e) => tracing::warn!(%e, "votes refused by the arbiter"),
                            }
                        }
                        if let Some(d) = decided {
                            publish(&d);
                            busy.add(started.elapsed().as_secs_f64() * 1e3);
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => break,
                }
                if let Some(d) = arbiter.on_tick(wall_clock_utime()) {
                    publish(&d);
                }
                if ticker.due(now) {
                    arbiter.status(&mut status);
                    status.busy_ms = busy.summary();
                    status.log();
                }
            }
            let last = arbiter.final_stop(wall_clock_utime());
            publish(&last);
            arbiter.status(&mut status);
            status.busy_ms = busy.summary();
            (
                status,
                arbiter.arrival_to_command_ms.summary(),
                arbiter.capture_to_command_ms.summary(),
                arbiter.commands,
                arbiter.stops,
            )
        })?
    };

    let routes = IoRoutes {
        perception_poses: Some(perception_poses_tx),
        map_poses: Some(map_poses_tx),
        images: Some(image_slot),
        waypoints: Some(waypoints_tx),
        arbiter: Some(arbiter_tx),
    };
    routes.subscribe(&mut lcm)?;
    let io_status = io_loop(&mut lcm, options, &live, routes);
    tracing::info!("shutting down: final stop follows");
    let perception_status = join(perception_thread)?;
    let map_status = join(map_thread)?;
    let behaviours_status = join(behaviours_thread)?;
    let (arbiter_status, arrival, capture, commands, stops) = join(arbiter_thread)?;
    let io_status = io_status?;
    Ok(LiveReport {
        wall_s: started.elapsed().as_secs_f64(),
        commands,
        stops,
        arrival_to_command_ms: arrival,
        capture_to_command_ms: capture,
        nodes: vec![
            io_status,
            perception_status,
            map_status,
            behaviours_status,
            arbiter_status,
        ],
    })
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
    pub fn start(
        config: &Config,
        registry: Registry,
        tap: Option<Sender<Decided>>,
    ) -> Result<Self, LiveError> {
        let lcm = Lcm::new("memq://")?;
        let publisher = lcm.publisher();
        let (ready, is_ready) = crossbeam_channel::bounded(1);
        let options = LiveOptions {
            command_tap: tap,
            ready: Some(ready),
            ..LiveOptions::default()
        };
        let stop = Arc::clone(&options.stop.flag);
        let config = config.clone();
        let handle = std::thread::Builder::new()
            .name("arcnav-run".into())
            .spawn(move || run(&config, &registry, lcm, &options))
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

/// The local map's thread: poses and reports in, cycles out.
fn map_worker(
    map: &mut MapStage,
    poses: Receiver<Pose>,
    reports: Receiver<Arrived<ObstacleReport>>,
    cycles: NewestWins<Cycle>,
    status_period_s: f64,
    period_s: f64,
) -> NodeStatus {
    let mut status = NodeStatus::new("localmap");
    let mut busy = Samples::default();
    let mut ticker = Ticker::new(status_period_s, wall_clock_utime());
    let mut out = Vec::new();
    let fill =
        |status: &mut NodeStatus, map: &MapStage, busy: &Samples, cycles: &NewestWins<Cycle>| {
            status.handled = map.cycles;
            status.busy_ms = busy.summary();
            status.queue(map.waiting());
            status.dropped = cycles.dropped();
            status.set("event_cycles", map.event_cycles);
            status.set("late_reports", map.late_reports);
            status.set("skipped_cycles", map.skipped_cycles);
            status.set("resets", map.resets);
            status.set("patches", map.node.map.len() as u64);
        };
    loop {
        let event = next(&poses, &reports, Wait::Block);
        let started = Instant::now();
        match event {
            Next::First(pose) => map.on_pose(pose, &mut out),
            Next::Second(Arrived { item, wall }) => map.on_report(item, wall, &mut out),
            Next::Idle => {}
            Next::Closed => break,
        }
        if !out.is_empty() {
            status.took(
                &mut busy,
                started.elapsed().as_secs_f64() * 1e3,
                period_s * 1e3,
            );
        }
        for cycle in out.drain(..) {
            cycles.put(cycle);
        }
        if ticker.due(wall_clock_utime()) {
            fill(&mut status, map, &busy, &cycles);
            status.log();
        }
    }
    fill(&mut status, map, &busy, &cycles);
    status
}

/// Where the io loop sends what it receives (`None`: not subscribed).
#[derive(Default)]
pub(crate) struct IoRoutes {
    pub perception_poses: Option<Sender<Pose>>,
    pub map_poses: Option<Sender<Pose>>,
    pub images: Option<NewestWins<Arrived<RangeImage>>>,
    pub waypoints: Option<Sender<Mission>>,
    pub(crate) arbiter: Option<Sender<ToArbiter>>,
}

impl IoRoutes {
    /// Subscribes `lcm` to the channels these routes take.
    pub(crate) fn subscribe(&self, lcm: &mut Lcm) -> Result<(), LiveError> {
        if self.perception_poses.is_some() || self.map_poses.is_some() || self.arbiter.is_some() {
            lcm.subscribe(channels::POSE);
        }
        if self.images.is_some() {
            lcm.subscribe_regex(&format!("{}.*", channels::RANGE_IMAGE))?;
        }
        if self.waypoints.is_some() {
            lcm.subscribe(channels::WAYPOINTS);
        }
        Ok(())
    }
}

/// The io thread: LCM in, routed to the nodes; returns when told to stop.
pub(crate) fn io_loop(
    lcm: &mut Lcm,
    options: &LiveOptions,
    live: &super::LiveConfig,
    routes: IoRoutes,
) -> Result<NodeStatus, LiveError> {
    let mut status = NodeStatus::new("io");
    let mut ticker = Ticker::new(live.status_period_s, wall_clock_utime());
    let (mut poses, mut images, mut queue_full) = (0u64, 0u64, 0u64);
    let mut refused = 0u64;
    let result = pump(lcm, options, Duration::from_millis(20), |message, now| {
        if let Some(message) = message {
            status.handled += 1;
            match decode(&message) {
                Some(AnyMessage::Pose(msg)) => match Pose::try_from(&msg) {
                    Ok(pose) => {
                        poses += 1;
                        for route in [&routes.perception_poses, &routes.map_poses]
                            .into_iter()
                            .flatten()
                        {
                            offer(route, pose, &mut queue_full);
                        }
                        if let Some(arbiter) = &routes.arbiter {
                            offer(
                                arbiter,
                                ToArbiter::Pose(pose.utime, message.recv_utime),
                                &mut queue_full,
                            );
                        }
                    }
                    Err(e) => {
                        tracing::warn!(%e, "pose refused");
                        refused += 1;
                    }
                },
                Some(AnyMessage::RangeImage(msg)) => match wire::range_image_from_wire(msg) {
                    Ok(image) => {
                        images += 1;
                        if let Some(slot) = &routes.images {
                            slot.put(Arrived {
                                item: image,
                                wall: message.recv_utime,
                            });
                        }
                    }
                    Err(e) => {
                        tracing::warn!(%e, channel = %message.channel, "range image refused");
                        refused += 1;
                    }
                },
                Some(AnyMessage::Waypoints(msg)) => match wire::mission_from_wire(&msg) {
                    Ok(mission) => {
                        if let Some(route) = &routes.waypoints {
                            offer(route, mission, &mut queue_full);
                        }
                    }
                    Err(e) => {
                        tracing::warn!(%e, "waypoints refused");
                        refused += 1;
                    }
                },
                _ => refused += 1,
            };
        }
        if ticker.due(now) {
            status.dropped = refused + queue_full;
            status.log();
        }
    });
    let transport = lcm.stats();
    status.dropped = refused + queue_full;
    let depth = [&routes.perception_poses, &routes.map_poses]
        .into_iter()
        .flatten()
        .map(Sender::len)
        .max();
    status.queue(depth.unwrap_or(0));
    status.set("poses", poses);
    status.set("images", images);
    status.set("refused", refused);
    status.set("queue_full", queue_full);
    status.set("incomplete_messages", transport.reassembly.incomplete);
    status.set("malformed_datagrams", transport.reassembly.malformed);
    result.map(|()| status)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn next_brings_either_input_then_idle_then_closed_sleeping_or_polling() {
        for wait in [Wait::Block, Wait::Poll] {
            let (poses_tx, poses) = crossbeam_channel::bounded::<u8>(4);
            let (images_tx, images) = crossbeam_channel::bounded::<&str>(4);
            let late = std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(20));
                images_tx.send("image").unwrap();
                images_tx
            });
            assert!(
                matches!(next(&poses, &images, wait), Next::Second("image")),
                "{wait:?}"
            );
            poses_tx.send(7).unwrap();
            assert!(matches!(next(&poses, &images, wait), Next::First(7)));
            let images_tx = late.join().unwrap();
            // Nothing for 100 ms: idle, so the status still gets logged.
            let since = Instant::now();
            assert!(matches!(next(&poses, &images, wait), Next::Idle));
            assert!(since.elapsed() >= Duration::from_millis(100), "{wait:?}");
            // An input closed: the executor is shutting down.
            drop(images_tx);
            assert!(matches!(next(&poses, &images, wait), Next::Closed));
        }
    }
}
