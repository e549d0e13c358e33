//! The arbiter node of live runs (002 §6, DAMN): votes gathered per
//! cycle, decisions when a cycle is complete or at its deadline, and the
//! safety watchdog on poses, images and decisions.

use std::collections::VecDeque;

use arcnav_arbiter::{Arbiter, BehaviourVotes, Reason, VoteSizeError};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{SteeringCommand, Utime};
use serde::Serialize;

use crate::config::{LiveConfig, PipelineConfig};
use crate::stats::Samples;

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
    /// These behaviours had not voted for the cycle when its deadline
    /// passed, or when a newer cycle was complete (cycles are decided in
    /// order, none is skipped).
    Deadline { missing: Vec<String> },
    /// The watchdog overrode the votes or the pipeline is silent.
    Watchdog(Hazard),
    /// No decision came for one and a half command periods while the
    /// inputs are still fresh (a pose or a decision late, not yet stale):
    /// the last command again, restamped, so that commands keep coming at
    /// the command rate on the wall clock. Once the inputs are stale the
    /// watchdog's stop takes its place.
    Held,
    /// The executor is shutting down.
    Final,
    /// The guard beside the pipeline stopped or slowed the arbiter's
    /// command (why, in words).
    Guard(String),
}

/// A command to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Decided {
    pub command: SteeringCommand,
    pub why: Why,
    /// The arbiter's reason for it (its last decision's, for a command
    /// the watchdog, a hold or the shutdown published instead).
    pub reason: Reason,
}

/// The arbiter node of a live run: the DAMN [`Arbiter`] with what live
/// operation needs around it. Only the expected behaviours' votes are
/// fused, and none stamped ahead of the sensor clock. Votes are gathered
/// per cycle (their `utime`):
/// a cycle is decided when every expected behaviour has voted for it, or at
/// its deadline, and cycles are decided in order, each once. Its watchdog
/// commands stop when poses, evaluated images or decisions stop coming;
/// while that lasts it repeats stop at the command rate. Until the inputs
/// are stale a late decision is covered by the last command, held
/// ([`Why::Held`]): something is published every command period.
///
/// Wall-clock times (µs since the Unix epoch) arrive as arguments: it reads
/// no clock.
pub struct ArbiterNode {
    pub arbiter: Arbiter,
    expected: Vec<String>,
    /// Cycles with votes not yet decided, oldest first.
    pending: VecDeque<PendingCycle>,
    /// The newest cycle decided: votes for older cycles come too late.
    decided: Option<Utime>,
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
    /// The last command decided on votes, to hold while a decision is late.
    last_command: Option<SteeringCommand>,
    /// The last command published was a held one.
    holding: bool,
    hazard: Option<Hazard>,
    /// Images new in the decisions since the last one: capture, arrival
    /// (`None`: known only from OBSTACLE_CELLS, in a distributed system).
    images: Vec<(Utime, Option<i64>)>,
    latency_from_cells: bool,
    /// Cells reach the map this long after capture (lock-step timing), µs.
    hold_us: Utime,
    pub arrival_to_command_ms: Samples,
    pub capture_to_command_ms: Samples,
    counts: ArbiterCounts,
}

/// One cycle's votes from the expected behaviours, in `expected` order.
struct PendingCycle {
    utime: Utime,
    votes: Vec<Option<BehaviourVotes>>,
    /// Wall-clock arrival of its first votes.
    first: i64,
}

/// Cycles waiting for votes at most; beyond, the oldest is decided at once.
const MAX_PENDING_CYCLES: usize = 64;

/// What the arbiter node did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ArbiterCounts {
    pub commands: u64,
    pub stops: u64,
    pub watchdog_stops: u64,
    /// Cycles decided without every expected behaviour's votes.
    pub deadline_decisions: u64,
    /// Votes for a cycle already decided (dropped).
    pub late_votes: u64,
    /// Votes from a behaviour the arbiter does not wait for (not configured,
    /// or weight 0): never fused.
    pub ignored_votes: u64,
    /// Votes stamped more than [`FUTURE_TOLERANCE_US`] after the sensor
    /// clock: refused (they would never go stale).
    pub future_votes: u64,
    /// The last command published again while a decision was late
    /// ([`Why::Held`]).
    pub held: u64,
}

/// How far ahead of the sensor clock (the newest pose, extrapolated on the
/// wall clock) a vote may be stamped, µs.
pub const FUTURE_TOLERANCE_US: Utime = 500_000;

impl ArbiterNode {
    /// `expected`: the behaviours whose votes complete a cycle. `now`: wall
    /// clock. Timing from `[live]` and the pipeline's command rate; with
    /// `live.reproduce_lockstep` a cycle waits for its votes up to
    /// `arbiter.vote_timeout_s` instead of `live.decision_deadline_s`.
    pub fn new(
        arbiter: Arbiter,
        expected: Vec<String>,
        live: &LiveConfig,
        timing: &PipelineConfig,
        now: i64,
    ) -> Self {
        let stall_us = seconds_to_micros(arbiter.config().vote_timeout_s);
        Self {
            arbiter,
            expected,
            pending: VecDeque::new(),
            decided: None,
            deadline_us: if live.reproduce_lockstep {
                stall_us
            } else {
                seconds_to_micros(live.decision_deadline_s)
            },
            pose_timeout_us: seconds_to_micros(live.pose_timeout_s),
            image_timeout_us: seconds_to_micros(live.image_timeout_s),
            stall_us,
            period_us: seconds_to_micros(1.0 / timing.command_rate_hz),
            started: now,
            pose: None,
            last_image: None,
            last_decision: None,
            last_publish: None,
            last_command: None,
            holding: false,
            hazard: None,
            images: Vec::new(),
            latency_from_cells: false,
            hold_us: if live.reproduce_lockstep {
                seconds_to_micros(timing.perception_latency_s.seconds())
            } else {
                0
            },
            arrival_to_command_ms: Samples::default(),
            capture_to_command_ms: Samples::default(),
            counts: ArbiterCounts::default(),
        }
    }

    /// The behaviours a cycle waits for.
    pub fn expected(&self) -> &[String] {
        &self.expected
    }

    pub fn counts(&self) -> ArbiterCounts {
        self.counts
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
    /// cells of `images` (capture, arrival) for the first time. The commands
    /// they let the arbiter decide go to `out`: their cycle's when it is
    /// complete, after those of older cycles still waiting.
    pub fn on_votes(
        &mut self,
        votes: &BehaviourVotes,
        images: &[(Utime, i64)],
        now: i64,
        out: &mut Vec<Decided>,
    ) -> Result<(), VoteSizeError> {
        // The images belong to the cycle, whichever behaviour's votes
        // carry them (the first of a cycle may be one the arbiter ignores).
        self.images.extend(
            images
                .iter()
                .map(|&(capture, arrival)| (capture, Some(arrival))),
        );
        let Some(slot) = self.expected.iter().position(|e| *e == votes.behaviour) else {
            // Not a configured behaviour with a weight: a stray publisher.
            self.counts.ignored_votes += 1;
            return Ok(());
        };
        if votes.votes.len() != self.arbiter.arcs().len() {
            return self.arbiter.on_votes(votes);
        }
        if votes.utime > self.sensor_time(now).saturating_add(FUTURE_TOLERANCE_US) {
            self.counts.future_votes += 1;
            return Ok(());
        }
        if self.decided.is_some_and(|d| votes.utime < d) {
            self.counts.late_votes += 1;
            return Ok(());
        }
        let i = self.pending.partition_point(|p| p.utime < votes.utime);
        if self.pending.get(i).is_none_or(|p| p.utime != votes.utime) {
            self.pending.insert(
                i,
                PendingCycle {
                    utime: votes.utime,
                    votes: vec![None; self.expected.len()],
                    first: now,
                },
            );
        }
        self.pending[i].votes[slot] = Some(votes.clone());
        if self.pending[i].votes.iter().all(Option::is_some) {
            for _ in 0..=i {
                self.decide_oldest(now, out);
            }
        } else if self.pending.len() > MAX_PENDING_CYCLES {
            self.decide_oldest(now, out);
        }
        Ok(())
    }

    /// Time passes: decisions at their deadline, or a stop while a hazard lasts.
    pub fn on_tick(&mut self, now: i64, out: &mut Vec<Decided>) {
        let before = out.len();
        while self
            .pending
            .front()
            .is_some_and(|p| now - p.first >= self.deadline_us)
        {
            self.decide_oldest(now, out);
        }
        if out.len() > before {
            return;
        }
        let hazard = self.hazard(now).or_else(|| {
            let since = self.last_decision.unwrap_or(self.started);
            (now - since > self.stall_us).then(|| Hazard::NoDecisions {
                age_s: (now - since) as f64 * 1e-6,
            })
        });
        self.note_hazard(hazard.clone());
        let Some(hazard) = hazard else {
            // Inputs fresh, but no command for one and a half periods (a
            // decision late), then every period while none comes.
            let wait = if self.holding {
                self.period_us
            } else {
                self.period_us + self.period_us / 2
            };
            let late = self.last_publish.is_some_and(|last| now - last >= wait);
            if late && let Some(last) = self.last_command {
                self.counts.held += 1;
                let held = SteeringCommand {
                    utime: self.sensor_time(now),
                    ..last
                };
                out.push(self.publish(held, Why::Held, now));
                self.holding = true;
            }
            return;
        };
        if self
            .last_publish
            .is_some_and(|last| now - last < self.period_us)
        {
            return;
        }
        self.counts.watchdog_stops += 1;
        let stop = SteeringCommand::stop(self.sensor_time(now));
        out.push(self.publish(stop, Why::Watchdog(hazard), now));
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

    /// Decides the oldest waiting cycle with the votes it has.
    fn decide_oldest(&mut self, now: i64, out: &mut Vec<Decided>) {
        let Some(cycle) = self.pending.pop_front() else {
            return;
        };
        let missing: Vec<String> = self
            .expected
            .iter()
            .zip(&cycle.votes)
            .filter(|(_, v)| v.is_none())
            .map(|(name, _)| name.clone())
            .collect();
        for votes in cycle.votes.iter().flatten() {
            // Sizes were checked on arrival.
            let _ = self.arbiter.on_votes(votes);
        }
        let why = if missing.is_empty() {
            Why::Complete
        } else {
            self.counts.deadline_decisions += 1;
            Why::Deadline { missing }
        };
        self.decided = Some(cycle.utime);
        out.push(self.decide(cycle.utime, why, now));
    }

    fn decide(&mut self, cycle: Utime, why: Why, now: i64) -> Decided {
        self.last_decision = Some(now);
        let hazard = self.hazard(now);
        self.note_hazard(hazard.clone());
        let (command, why) = match hazard {
            Some(h) => {
                self.counts.watchdog_stops += 1;
                (SteeringCommand::stop(cycle), Why::Watchdog(h))
            }
            None => {
                let command = self.arbiter.decide(cycle);
                self.last_command = Some(command);
                (command, why)
            }
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
        self.holding = false;
        if matches!(why, Why::Watchdog(_) | Why::Final) {
            // After a stop only a new decision moves the vehicle again.
            self.last_command = None;
        }
        self.counts.commands += 1;
        if command.is_stop() {
            self.counts.stops += 1;
        }
        Decided {
            command,
            why,
            reason: self.arbiter.reason().clone(),
        }
    }
}

#[cfg(test)]
mod tests;
