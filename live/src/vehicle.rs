//! `arcnav vehicle`: the vehicle's side of the command interface, as a small
//! bridge a vehicle controller runs beside it.
//!
//! It takes `STEERING_COMMAND` from the bus — through a transport that
//! verifies each command's tag and freshness when `[bus.auth]` is on, so a
//! forged, tampered, replayed or expired command never reaches it — feeds
//! the accepted ones to a [`CommandWatchdog`], and at its own rate hands the
//! controller what to execute: the newest accepted command while it is
//! fresh, a stop when commands stop coming. When it stops (signal,
//! `--duration`), the last thing it hands over is a stop.
//!
//! With the guard on (`[guard] enabled`, the default), it also takes the
//! sensor's images (`RANGE_IMAGE*`, whole or in slices) and `POSE`, and
//! every command it would hand over goes through the guard
//! ([`arcnav_guard::Guard::check`]) on the sensor clock: whatever the
//! pipeline decided, a hazard the returns show on the commanded path, tilt
//! or missing data stops or slows the vehicle. Each verdict is published on
//! `GUARD_STATUS`, said when it changes, and counted.

use std::time::Duration;

use arcnav_bus::messages::AnyMessage;
use arcnav_bus::transport::Lcm;
use arcnav_guard::{Guard, Verdict};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{CommandWatchdog, SteeringCommand};
use serde::Serialize;

pub use super::guarded::Guarded;
use super::guarded::{BridgeGuard, guard_status, say};
use super::io::{Refused, Ticker, auth_status, pump};
use super::threaded::{LiveError, LiveOptions};
use super::{LiveReport, NodeStatus};

/// How the bridge runs.
#[derive(Debug, Clone)]
pub struct BridgeOptions {
    /// The commands to follow: STEERING_COMMAND (the arbiter's), or
    /// STEERING_COMMAND_GUARDED behind `arcnav node guard`.
    pub channel: String,
    /// What to execute is handed over this often, Hz.
    pub rate_hz: f64,
    /// A command received longer ago than this is not executed: stop, s.
    pub timeout_s: f64,
    /// Status lines this often (0: none), s.
    pub status_period_s: f64,
}

/// Why the vehicle executes what it does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Execution {
    /// The newest accepted command, received within the timeout.
    Following,
    /// Stopped: no command accepted yet.
    NoCommandYet,
    /// Stopped: the newest accepted command is older than the timeout.
    Stale,
    /// Stopped: the bridge is shutting down.
    ShuttingDown,
}

/// What the controller is told to execute at one tick.
#[derive(Debug, Clone, Serialize)]
pub struct Executed {
    /// The bridge's clock (µs since the Unix epoch).
    pub wall_us: i64,
    pub state: Execution,
    /// The command's own stamp (the arbiter's cycle time); the tick's time
    /// for stops the bridge makes itself.
    pub command_utime: i64,
    /// 1/m, + left (JSON `null` when turning in place: ±∞).
    pub curvature: f64,
    /// The speed to execute: the command's, held to the guard's verdict.
    pub speed_mps: f64,
    /// The yaw rate to execute, rad/s, + left: speed × curvature on an
    /// arc, the turn's rate in place (a skid-steer vehicle), 0 stopped.
    pub yaw_rate_radps: f64,
    pub arc_index: Option<usize>,
    pub guard: Guarded,
    /// Why the guard slowed or stopped the vehicle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guard_reason: Option<String>,
}

impl Executed {
    fn new(wall_us: i64, state: Execution, command: &SteeringCommand) -> Self {
        Self {
            wall_us,
            state,
            command_utime: command.utime,
            curvature: command.curvature,
            speed_mps: command.speed_mps,
            yaw_rate_radps: command.yaw_rate(),
            arc_index: command.arc_index,
            guard: Guarded::Off,
            guard_reason: None,
        }
    }

    /// `command` as the guard's `verdict` lets it go.
    fn guarded(wall_us: i64, command: &SteeringCommand, verdict: &Verdict) -> Self {
        let applied = verdict.apply(command);
        Self {
            guard: Guarded::from(verdict),
            guard_reason: verdict.reason().map(ToString::to_string),
            ..Self::new(wall_us, Execution::Following, &applied)
        }
    }

    /// The command to execute.
    pub fn command(&self) -> SteeringCommand {
        match self.state {
            Execution::Following => SteeringCommand {
                utime: self.command_utime,
                curvature: self.curvature,
                speed_mps: self.speed_mps,
                arc_index: self.arc_index,
                vote: 0.0,
                turn_rate_radps: if self.curvature.is_infinite() {
                    self.yaw_rate_radps
                } else {
                    0.0
                },
            },
            _ => SteeringCommand::stop(self.command_utime),
        }
    }
}

/// Runs the bridge on `lcm` until `options.stop`; `execute` gets what to
/// execute at every tick, and a stop last. With `guard`, every command goes
/// through it (see the module documentation).
pub fn run_bridge(
    mut lcm: Lcm,
    options: &LiveOptions,
    bridge: &BridgeOptions,
    guard: Option<Guard>,
    mut execute: impl FnMut(&Executed),
) -> Result<LiveReport, LiveError> {
    let started = std::time::Instant::now();
    let clock = options.clock();
    let mut watchdog = CommandWatchdog::new(seconds_to_micros(bridge.timeout_s));
    let mut status = NodeStatus::new("vehicle");
    let mut bad = Refused::default();
    let (mut following, mut stopped) = (0u64, 0u64);
    let mut tick = Ticker::new(1.0 / bridge.rate_hz, clock.now_us());
    let mut report = Ticker::new(bridge.status_period_s, clock.now_us());
    lcm.subscribe(&bridge.channel);
    let mut guard = guard.map(BridgeGuard::new);
    if guard.is_some() {
        BridgeGuard::subscribe(&mut lcm)?;
    }
    let publisher = lcm.publisher();
    let wait = Duration::from_secs_f64((0.25 / bridge.rate_hz).min(0.005));
    pump(
        &mut lcm,
        options,
        bridge.status_period_s,
        wait,
        |message, now| {
            if let Some(message) = message {
                if message.channel != bridge.channel {
                    if let Some(guard) = &mut guard {
                        match AnyMessage::decode(&message.data) {
                            Ok(Some(m)) if m.on_its_channel(&message.channel) => {
                                guard.on_message(m, now)
                            }
                            _ => guard.ignored += 1,
                        }
                    }
                } else {
                    match AnyMessage::decode_command(&message.data) {
                        Ok(command) => {
                            status.handled += 1;
                            watchdog.on_command(now, command);
                        }
                        Err(e) => bad.refuse("steering command", &message.channel, &e),
                    }
                }
            }
            if tick.due(now) {
                let state = if watchdog.is_following(now) {
                    Execution::Following
                } else if watchdog.has_received() {
                    Execution::Stale
                } else {
                    Execution::NoCommandYet
                };
                match state {
                    Execution::Following => following += 1,
                    _ => stopped += 1,
                }
                let command = watchdog.command_at(now);
                match (&mut guard, state) {
                    (Some(guard), Execution::Following) => {
                        let (at, verdict) = guard.judge(&command, now);
                        say(&publisher, at, command.utime, &verdict);
                        execute(&Executed::guarded(now, &command, &verdict));
                    }
                    _ => execute(&Executed::new(now, state, &command)),
                }
            }
            if report.due(now) {
                status.dropped = bad.total();
                status.set("watchdog_trips", watchdog.trips);
                if let Some(guard) = &guard {
                    guard_status(guard, &mut status);
                }
                status.log();
            }
        },
    )?;
    let now = clock.now_us();
    execute(&Executed::new(
        now,
        Execution::ShuttingDown,
        &SteeringCommand::stop(now),
    ));
    bad.report(&mut status);
    status.set("ticks_following", following);
    status.set("ticks_stopped", stopped + 1);
    status.set("watchdog_trips", watchdog.trips);
    if let Some(guard) = &guard {
        guard_status(guard, &mut status);
    }
    status.set("own_datagrams_ignored", lcm.stats().own);
    auth_status(&lcm, &mut status);
    Ok(LiveReport {
        wall_s: started.elapsed().as_secs_f64(),
        commands: status.handled,
        nodes: vec![status],
        ..LiveReport::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::threaded::StopWhen;
    use arcnav_bus::lcmtypes::steering_command_t;
    use arcnav_bus::messages::channels;

    /// Stops before the first command, the command while it is fresh, stops
    /// once it is stale, and a stop last: in that order, and only that.
    #[test]
    fn the_bridge_follows_a_fresh_command_and_stops_when_it_goes_stale() {
        let lcm = Lcm::new("memq://").unwrap();
        let publisher = lcm.publisher();
        let options = LiveOptions {
            stop: StopWhen {
                after: Some(Duration::from_millis(600)),
                ..StopWhen::default()
            },
            ..LiveOptions::default()
        };
        let bridge = BridgeOptions {
            channel: channels::STEERING_COMMAND.into(),
            rate_hz: 100.0,
            timeout_s: 0.1,
            status_period_s: 0.0,
        };
        let sender = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(150));
            let command = SteeringCommand {
                utime: 42,
                curvature: 0.05,
                speed_mps: 2.0,
                arc_index: Some(25),
                vote: 0.8,
                turn_rate_radps: 0.0,
            };
            publisher
                .publish_message(
                    channels::STEERING_COMMAND,
                    &steering_command_t::from(&command),
                )
                .unwrap();
            publisher
                .publish(channels::STEERING_COMMAND, b"not a command")
                .unwrap();
        });
        let mut ticks = Vec::new();
        let report = run_bridge(lcm, &options, &bridge, None, |e| ticks.push(e.clone())).unwrap();
        sender.join().unwrap();
        let states: Vec<Execution> = ticks.iter().map(|t| t.state).collect();
        let mut runs = states.clone();
        runs.dedup();
        assert_eq!(
            runs,
            [
                Execution::NoCommandYet,
                Execution::Following,
                Execution::Stale,
                Execution::ShuttingDown
            ],
            "{states:?}"
        );
        for tick in &ticks {
            let command = tick.command();
            match tick.state {
                Execution::Following => {
                    assert_eq!((command.utime, command.speed_mps), (42, 2.0));
                }
                _ => assert!(command.is_stop()),
            }
        }
        let status = &report.nodes[0];
        assert_eq!((status.handled, status.dropped), (1, 1), "{status:?}");
        assert!(status.counters.contains(&("watchdog_trips".to_owned(), 1)));
    }
}
