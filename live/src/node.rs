//! `arcnav node …`: each node in its own process, talking LCM, like the
//! original system spread over workstations.
//!
//! | node | takes | publishes |
//! |---|---|---|
//! | perception | POSE, RANGE_IMAGE* | OBSTACLE_CELLS |
//! | localmap | POSE, OBSTACLE_CELLS | LOCAL_MAP (one per cycle) |
//! | behaviour NAME | LOCAL_MAP, WAYPOINTS, STEERING_COMMAND | ARC_VOTES_NAME |
//! | arbiter | ARC_VOTES_*, POSE, OBSTACLE_CELLS | STEERING_COMMAND, DECISION |
//! | guard | STEERING_COMMAND, POSE, RANGE_IMAGE* | STEERING_COMMAND_GUARDED, GUARD_STATUS |
//!
//! The arbiter decides a cycle when every behaviour with a positive weight
//! has voted for it, or `live.decision_deadline_s` after the first vote;
//! votes older than `arbiter.vote_timeout_s` are not used and a required
//! behaviour's stale votes mean stop. It watches POSE and OBSTACLE_CELLS (one
//! per evaluated image) for its safety watchdog.

use std::time::{Duration, Instant};

use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_bus::transport::Lcm;
use arcnav_pipeline::{ArbiterNode, BehaviourSet};

use super::handoff;
use super::io::{IoRoutes, Refused, Ticker, auth_status, decode, io_loop, publish_command, pump};
use super::threaded::{LiveError, LiveOptions};
use super::workers::{MapStage, perception_node, perception_worker};
use super::{LiveReport, NodeStatus, Samples, arbiter_status};
use arcnav_config::Resolved;
use arcnav_wire as wire;

/// Which node to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NodeKind {
    Perception,
    LocalMap,
    Arbiter,
    /// A behaviour configured under `[behaviours.NAME]`.
    Behaviour(String),
    /// The guard between the arbiter and the vehicle.
    Guard,
}

impl std::fmt::Display for NodeKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NodeKind::Perception => write!(f, "perception"),
            NodeKind::LocalMap => write!(f, "localmap"),
            NodeKind::Arbiter => write!(f, "arbiter"),
            NodeKind::Behaviour(name) => write!(f, "behaviour {name}"),
            NodeKind::Guard => write!(f, "guard"),
        }
    }
}

/// Runs one node on `lcm` until `options.stop`.
pub fn run_node(
    kind: &NodeKind,
    config: &Resolved,
    lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    super::options::refuse_fault(config)?;
    let started = Instant::now();
    let mut report = match kind {
        NodeKind::Perception => perception(config, lcm, options)?,
        NodeKind::LocalMap => localmap(config, lcm, options)?,
        NodeKind::Arbiter => arbiter(config, lcm, options)?,
        NodeKind::Behaviour(name) => behaviour(config, name, lcm, options)?,
        NodeKind::Guard => guard(config, lcm, options)?,
    };
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

fn report(nodes: Vec<NodeStatus>) -> LiveReport {
    LiveReport {
        nodes,
        ..LiveReport::default()
    }
}

fn perception(
    config: &Resolved,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    let node = perception_node(config)?;
    let publisher = lcm.publisher();
    let (feed, sensed) = handoff::sensor_feed(super::threaded::SLICE_QUEUE);
    let (poses_tx, poses) = crossbeam_channel::bounded(config.live.queue_capacity);
    let live = config.live.clone();
    let clock = options.clock();
    let worker = std::thread::Builder::new()
        .name("perception".into())
        .spawn(move || {
            perception_worker(node, poses, sensed, &live, clock, |report, _| {
                if let Err(e) = publisher
                    .publish_message(channels::OBSTACLE_CELLS, &wire::obstacles_to_wire(&report))
                {
                    tracing::error!(%e, "cannot publish obstacle cells");
                }
            })
        })
        .map_err(|source| LiveError::Spawn {
            node: "perception",
            source,
        })?;
    let routes = IoRoutes {
        perception_poses: Some(poses_tx),
        images: Some(feed),
        ..IoRoutes::default()
    };
    routes.subscribe(&mut lcm)?;
    let io = io_loop(&mut lcm, options, &config.live, routes);
    let perception = worker
        .join()
        .map_err(|_| LiveError::Panicked("perception"))?;
    Ok(report(vec![io?, perception]))
}

/// What a node of its own keeps of its work: its status, the messages it
/// refused, how long its work took (against the decision period), and when
/// it last said so.
struct Books {
    status: NodeStatus,
    bad: Refused,
    busy: Samples,
    ticker: Ticker,
    /// One decision cycle, ms (`pipeline.command_rate_hz`).
    period_ms: f64,
}

impl Books {
    fn new(node: &str, config: &Resolved, options: &LiveOptions) -> Self {
        Self {
            status: NodeStatus::new(node),
            bad: Refused::default(),
            busy: Samples::default(),
            ticker: Ticker::new(config.live.status_period_s, options.clock().now_us()),
            period_ms: 1e3 / config.pipeline.command_rate_hz,
        }
    }
}

fn localmap(
    config: &Resolved,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    let mut stage = MapStage::new(config);
    let Books {
        mut status,
        mut bad,
        mut busy,
        mut ticker,
        period_ms,
    } = Books::new("localmap", config, options);
    lcm.subscribe(channels::POSE);
    lcm.subscribe(channels::OBSTACLE_CELLS);
    let publisher = lcm.publisher();
    pump(
        &mut lcm,
        options,
        config.live.status_period_s,
        Duration::from_millis(50),
        |message, now| {
            let started = Instant::now();
            if let Some(message) = message {
                match decode(&message) {
                    Some(AnyMessage::Pose(msg)) => match arcnav_vehicle::Pose::try_from(&msg) {
                        Ok(pose) => stage.on_pose(pose),
                        Err(e) => bad.refuse("pose", &message.channel, &e),
                    },
                    Some(AnyMessage::ObstacleCells(msg)) => match wire::obstacles_from_wire(msg) {
                        Ok(r) => stage.on_report(r, now),
                        Err(e) => bad.refuse("obstacle cells", &message.channel, &e),
                    },
                    _ => status.dropped += 1,
                }
            }
            for cycle in stage.cycles() {
                let msg = wire::map_to_wire(cycle.utime, &cycle.pose, &cycle.map, cycle.resets);
                if let Err(e) = publisher.publish_message(channels::LOCAL_MAP, &msg) {
                    tracing::error!(%e, "cannot publish the local map");
                }
                status.took(&mut busy, started.elapsed().as_secs_f64() * 1e3, period_ms);
            }
            if ticker.due(now) {
                stage.fill(&mut status);
                status.busy_ms = busy.summary();
                status.log();
            }
        },
    )?;
    stage.fill(&mut status);
    status.busy_ms = busy.summary();
    bad.report(&mut status);
    auth_status(&lcm, &mut status);
    Ok(report(vec![status]))
}

fn behaviour(
    config: &Resolved,
    name: &str,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    let arcs = config.arcs.clone();
    let built = config
        .build_behaviour(name)
        .ok_or_else(|| LiveError::UnknownBehaviour {
            name: name.to_owned(),
            known: config
                .behaviour_names()
                .map(str::to_owned)
                .collect::<Vec<_>>()
                .join(", "),
        })?;
    if config.arbiter.weight(name) <= 0.0 {
        tracing::warn!(
            behaviour = name,
            "its weight in [arbiter.weights] is 0: the arbiter will not use its votes"
        );
    }
    let mut node = BehaviourSet::new(vec![built], arcs.clone());
    let Books {
        mut status,
        mut bad,
        mut busy,
        mut ticker,
        period_ms,
    } = Books::new(&format!("behaviour {name}"), config, options);
    let channel = channels::arc_votes(name);
    lcm.subscribe(channels::LOCAL_MAP);
    lcm.subscribe(channels::WAYPOINTS);
    lcm.subscribe(channels::STEERING_COMMAND);
    let publisher = lcm.publisher();
    pump(
        &mut lcm,
        options,
        config.live.status_period_s,
        Duration::from_millis(50),
        |message, now| {
            if let Some(message) = message {
                match decode(&message) {
                    Some(AnyMessage::LocalMap(msg)) => match wire::map_from_wire(&msg) {
                        Ok(cycle) => {
                            let started = Instant::now();
                            let votes = node.on_cycle(
                                cycle.resets,
                                cycle.cycle_utime,
                                &cycle.pose,
                                &cycle.map,
                            );
                            let msg = wire::votes_to_wire(&votes[0], &arcs);
                            if let Err(e) = publisher.publish_message(&channel, &msg) {
                                tracing::error!(%e, "cannot publish the votes");
                            }
                            status.handled += 1;
                            status.set("unreachable_waypoints", node.unreachable() as u64);
                            status.took(
                                &mut busy,
                                started.elapsed().as_secs_f64() * 1e3,
                                period_ms,
                            );
                        }
                        Err(e) => bad.refuse("local map", &message.channel, &e),
                    },
                    Some(AnyMessage::Waypoints(msg)) => match wire::mission_from_wire(&msg) {
                        Ok(mission) => node.on_waypoints(mission),
                        Err(e) => bad.refuse("waypoints", &message.channel, &e),
                    },
                    Some(msg @ (AnyMessage::SteeringCommand(_) | AnyMessage::DriveCommand(_))) => {
                        if let Some(command) = msg.as_command() {
                            node.on_command(&command);
                        }
                    }
                    _ => status.dropped += 1,
                }
            }
            if ticker.due(now) {
                status.busy_ms = busy.summary();
                status.log();
            }
        },
    )?;
    status.busy_ms = busy.summary();
    bad.report(&mut status);
    auth_status(&lcm, &mut status);
    Ok(report(vec![status]))
}

fn arbiter(
    config: &Resolved,
    mut lcm: Lcm,
    options: &LiveOptions,
) -> Result<LiveReport, LiveError> {
    let arcs = config.arcs.clone();
    let kinematics = config.vehicle.kinematics;
    let expected = config.expected_behaviours();
    tracing::info!(
        ?expected,
        "the arbiter decides when these behaviours have voted"
    );
    let mut stage = ArbiterNode::new(
        config.arbiter(),
        expected,
        &config.live,
        &config.pipeline,
        options.clock().now_us(),
    );
    let mut out = Vec::new();
    stage.measure_latency_from_cells();
    let Books {
        mut status,
        mut bad,
        mut busy,
        mut ticker,
        ..
    } = Books::new("arbiter", config, options);
    lcm.subscribe_regex(&format!("{}.*", channels::ARC_VOTES_PREFIX))?;
    lcm.subscribe(channels::POSE);
    lcm.subscribe(channels::OBSTACLE_CELLS);
    let publisher = lcm.publisher();
    let tap = options.command_tap.clone();
    let tick = Duration::from_secs_f64((0.25 / config.pipeline.command_rate_hz).min(0.01));
    let result = pump(
        &mut lcm,
        options,
        config.live.status_period_s,
        tick,
        |message, now| {
            if let Some(message) = message {
                match decode(&message) {
                    Some(AnyMessage::ArcVotes(msg)) => match wire::votes_from_wire(&msg, &arcs) {
                        Ok(votes) => {
                            let started = Instant::now();
                            match stage.on_votes(&votes, &[], now, &mut out) {
                                Ok(()) if !out.is_empty() => {
                                    busy.add(started.elapsed().as_secs_f64() * 1e3);
                                }
                                Ok(()) => {}
                                Err(e) => bad.refuse("votes", &message.channel, &e),
                            }
                        }
                        Err(e) => bad.refuse("votes", &message.channel, &e),
                    },
                    Some(AnyMessage::Pose(msg)) => stage.on_pose(msg.utime, now),
                    Some(AnyMessage::ObstacleCells(msg)) => {
                        stage.on_perceived(msg.utime, now);
                    }
                    _ => status.dropped += 1,
                }
            }
            stage.on_tick(now, &mut out);
            for decided in out.drain(..) {
                publish_command(&publisher, &decided, tap.as_ref(), kinematics);
            }
            if ticker.due(now) {
                arbiter_status(&stage, &mut status);
                status.busy_ms = busy.summary();
                status.log();
            }
        },
    );
    // The final stop goes out whatever ended the loop.
    let last = stage.final_stop(options.clock().now_us());
    publish_command(&publisher, &last, tap.as_ref(), kinematics);
    result?;
    arbiter_status(&stage, &mut status);
    status.busy_ms = busy.summary();
    bad.report(&mut status);
    auth_status(&lcm, &mut status);
    Ok(LiveReport {
        commands: stage.counts().commands,
        stops: stage.counts().stops,
        arrival_to_command_ms: stage.arrival_to_command_ms.summary(),
        capture_to_command_ms: stage.capture_to_command_ms.summary(),
        nodes: vec![status],
        ..LiveReport::default()
    })
}

/// The guard as a node of its own, between the arbiter and the vehicle (as
/// Nav2's collision monitor sits between the controller and the base): it
/// takes the images and the pose, judges every STEERING_COMMAND on the
/// sensor clock and publishes it as it lets it through on
/// STEERING_COMMAND_GUARDED, with its verdict on GUARD_STATUS; an image that
/// changes the verdict on the newest command (received within three
/// command periods) publishes it again at once.
fn guard(config: &Resolved, mut lcm: Lcm, options: &LiveOptions) -> Result<LiveReport, LiveError> {
    use super::guarded::{BridgeGuard, guard_status, say};
    use arcnav_vehicle::SteeringCommand;

    if !config.guard.enabled {
        return Err(LiveError::GuardOff);
    }
    let mut guard = BridgeGuard::new(arcnav_guard::Guard::new(
        &config.guard,
        &config.vehicle,
        &config.sensors,
    ));
    let Books {
        mut status,
        mut bad,
        mut busy,
        mut ticker,
        period_ms,
    } = Books::new("guard", config, options);
    lcm.subscribe(channels::STEERING_COMMAND);
    BridgeGuard::subscribe(&mut lcm)?;
    let publisher = lcm.publisher();
    let fresh_us = (3e6 / config.pipeline.command_rate_hz) as i64;
    let mut newest: Option<(SteeringCommand, i64)> = None;
    let send = |command: &SteeringCommand, at: i64, verdict: &arcnav_guard::Verdict| {
        let sent = verdict.apply(command);
        if let Err(e) = publisher.publish_command(
            channels::STEERING_COMMAND_GUARDED,
            &sent,
            config.vehicle.kinematics,
        ) {
            tracing::error!(%e, "cannot publish the guarded command");
        }
        say(&publisher, at, command.utime, verdict);
    };
    pump(
        &mut lcm,
        options,
        config.live.status_period_s,
        Duration::from_millis(50),
        |message, now| {
            let started = Instant::now();
            if let Some(message) = message {
                if message.channel == channels::STEERING_COMMAND {
                    match AnyMessage::decode_command(&message.data) {
                        Ok(command) => {
                            status.handled += 1;
                            newest = Some((command, now));
                            let (at, verdict) = guard.judge(&command, now);
                            send(&command, at, &verdict);
                        }
                        Err(e) => bad.refuse("steering command", &message.channel, &e),
                    }
                } else {
                    match decode(&message) {
                        Some(m) => guard.on_message(m, now),
                        None => guard.ignored += 1,
                    }
                    // A verdict a new pose or image changes goes out at once.
                    if let Some((command, received)) = newest
                        && now - received <= fresh_us
                    {
                        let before = guard.last();
                        let (at, verdict) = guard.judge(&command, now);
                        if guard.last() != before {
                            send(&command, at, &verdict);
                        }
                    }
                }
                status.took(&mut busy, started.elapsed().as_secs_f64() * 1e3, period_ms);
            }
            if ticker.due(now) {
                guard_status(&guard, &mut status);
                status.busy_ms = busy.summary();
                status.log();
            }
        },
    )?;
    guard_status(&guard, &mut status);
    status.busy_ms = busy.summary();
    bad.report(&mut status);
    auth_status(&lcm, &mut status);
    Ok(report(vec![status]))
}
