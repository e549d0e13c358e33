//! The live executors' LCM side: the receive loop, decoding, routing what
//! arrives to the nodes' threads, and publishing commands.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use arcnav_behaviours::Mission;
use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_bus::transport::{Lcm, Publisher, ReceivedMessage};
use arcnav_pipeline::{Decided, LiveConfig, Why};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{ArcSet, Pose};
use crossbeam_channel::Sender;

use super::NodeStatus;
use super::guarded::GuardInput;
use super::handoff::{Arrived, SensorFeed, offer};
use super::options::{LiveError, LiveOptions, ToArbiter};
use arcnav_wire as wire;

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

    /// Whether the next firing is due at `now`. Firings keep to the period
    /// on average however late each is noticed; one noticed more than a
    /// period late starts the count again from `now`.
    pub(crate) fn due(&mut self, now: i64) -> bool {
        if self.period_us <= 0 || now < self.next {
            return false;
        }
        self.next += self.period_us;
        if self.next <= now {
            self.next = now + self.period_us;
        }
        true
    }
}

/// Receives until `stop`: `on` gets each message (or `None` when `tick`
/// passed without one) and the wall-clock time. A receive error is logged;
/// fifty in a row end the loop with that error. With authentication on, a
/// status line of what it accepted and refused every `status_period_s`.
pub(crate) fn pump(
    lcm: &mut Lcm,
    options: &LiveOptions,
    status_period_s: f64,
    tick: Duration,
    mut on: impl FnMut(Option<ReceivedMessage>, i64),
) -> Result<(), LiveError> {
    let stop = &options.stop;
    let clock = options.clock();
    let deadline = stop.deadline();
    let mut failures = 0;
    let mut status = Ticker::new(status_period_s, clock.now_us());
    tracing::info!("ready: receiving");
    if let Some(ready) = &options.ready {
        let _ = ready.send(());
    }
    while !stop.flag.load(Ordering::Relaxed) && deadline.is_none_or(|d| Instant::now() < d) {
        match lcm.recv_timeout(tick) {
            Ok(message) => {
                failures = 0;
                on(message, clock.now_us());
            }
            Err(e) => {
                failures += 1;
                tracing::warn!(%e, "LCM receive failed");
                if failures >= 50 {
                    return Err(LiveError::Receive(e));
                }
                std::thread::sleep(tick);
                on(None, clock.now_us());
            }
        }
        if status.due(clock.now_us())
            && let Some(auth) = lcm.auth_stats()
        {
            tracing::info!(
                accepted = auth.accepted_total(),
                refused = auth.refused_total(),
                "status authentication {}",
                auth.refusal_lines().join("; ")
            );
        }
    }
    Ok(())
}

/// The transport's authentication counts into `status`, and a warning per
/// channel where messages were refused (nothing when authentication is off).
pub(crate) fn auth_status(lcm: &Lcm, status: &mut NodeStatus) {
    if let Some(auth) = lcm.auth_stats() {
        status.set("auth_accepted", auth.accepted_total());
        status.set("auth_refused", auth.refused_total());
        for line in auth.refusal_lines() {
            tracing::warn!(node = %status.node, "authentication: {line}");
        }
    }
}

/// Messages refused because their content is unusable, counted by what
/// they were; the 1st, 2nd, 4th, 8th… of each is warned of, so a flood of
/// bad input cannot flood the log.
#[derive(Debug, Default)]
pub(crate) struct Refused {
    counts: std::collections::BTreeMap<&'static str, u64>,
    /// Warnings logged.
    warned: u64,
}

impl Refused {
    /// Counts one refusal of a `what`.
    pub(crate) fn refuse(
        &mut self,
        what: &'static str,
        channel: &str,
        why: &dyn std::fmt::Display,
    ) {
        let count = self.counts.entry(what).or_default();
        *count += 1;
        if count.is_power_of_two() {
            self.warned += 1;
            tracing::warn!(%channel, count = *count, "{what} refused: {why}");
        }
    }

    pub(crate) fn total(&self) -> u64 {
        self.counts.values().sum()
    }

    /// Into `status` at exit: the `refused` counter, and added to `dropped`
    /// (which counts what did not decode as it came).
    pub(crate) fn report(&self, status: &mut NodeStatus) {
        status.dropped += self.total();
        status.set("refused", self.total());
    }
}

/// Decodes a received message; `None` (logged at debug, to be counted as
/// dropped) when it is not an arcnav message or is malformed.
pub(crate) fn decode(message: &ReceivedMessage) -> Option<AnyMessage> {
    match AnyMessage::decode(&message.data) {
        Ok(Some(m)) if m.on_its_channel(&message.channel) => Some(m),
        Ok(Some(m)) => {
            tracing::debug!(channel = %message.channel, kind = m.type_name(), "message on a channel not arcnav's for its type dropped");
            None
        }
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
    kinematics: arcnav_vehicle::Kinematics,
) {
    if let Why::Deadline { missing } = &decided.why {
        tracing::debug!(?missing, "decided at the deadline without every behaviour");
    }
    if let Err(e) =
        publisher.publish_command(channels::STEERING_COMMAND, &decided.command, kinematics)
    {
        tracing::error!(%e, "cannot publish the steering command");
    }
    let hazard;
    let said = match &decided.why {
        Why::Watchdog(h) => {
            hazard = h.to_string();
            wire::Said::StaleInput(&hazard)
        }
        Why::Held => wire::Said::Held,
        Why::Final => wire::Said::Final,
        Why::Guard(why) => wire::Said::Guard(why),
        Why::Complete | Why::Deadline { .. } => wire::Said::Arbiter(&decided.reason),
    };
    let decision = wire::decision_to_wire(decided.command.utime, said);
    if let Err(e) = publisher.publish_message(channels::DECISION, &decision) {
        tracing::error!(%e, "cannot publish the decision");
    }
    if let Some(tap) = tap {
        let _ = tap.try_send(decided.clone());
    }
}

/// Where the io loop sends what it receives (`None`: not subscribed).
#[derive(Default)]
pub(crate) struct IoRoutes {
    pub perception_poses: Option<Sender<Pose>>,
    pub map_poses: Option<Sender<Pose>>,
    /// Range images and their slices.
    pub images: Option<SensorFeed>,
    pub waypoints: Option<Sender<Mission>>,
    pub(crate) arbiter: Option<Sender<ToArbiter>>,
    /// Behaviours in processes of their own, whose votes go to `arbiter`.
    pub external: Option<External>,
    /// The guard's thread: poses and copies of the images.
    pub(crate) guard: Option<Sender<super::guarded::GuardInput>>,
}

/// Behaviours that vote from other processes, and the arc set their votes
/// must match.
pub struct External {
    pub names: Vec<String>,
    pub arcs: ArcSet,
}

impl IoRoutes {
    /// Subscribes `lcm` to the channels these routes take.
    pub(crate) fn subscribe(&self, lcm: &mut Lcm) -> Result<(), LiveError> {
        let guard = self.guard.is_some();
        if self.perception_poses.is_some()
            || self.map_poses.is_some()
            || self.arbiter.is_some()
            || guard
        {
            lcm.subscribe(channels::POSE);
        }
        if self.images.is_some() || guard {
            lcm.subscribe_regex(&format!("{}.*", channels::RANGE_IMAGE))?;
        }
        if self.waypoints.is_some() {
            lcm.subscribe(channels::WAYPOINTS);
        }
        for name in self.external.iter().flat_map(|e| &e.names) {
            lcm.subscribe(&channels::arc_votes(name));
        }
        Ok(())
    }
}

/// The io thread: LCM in, routed to the nodes; returns when told to stop.
pub(crate) fn io_loop(
    lcm: &mut Lcm,
    options: &LiveOptions,
    live: &LiveConfig,
    routes: IoRoutes,
) -> Result<NodeStatus, LiveError> {
    let mut status = NodeStatus::new("io");
    let mut ticker = Ticker::new(live.status_period_s, options.clock().now_us());
    let (mut poses, mut images, mut slices, mut queue_full) = (0u64, 0u64, 0u64, 0u64);
    let (mut bad, mut undecodable, mut external_votes) = (Refused::default(), 0u64, 0u64);
    let result = pump(
        lcm,
        options,
        live.status_period_s,
        Duration::from_millis(20),
        |message, now| {
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
                                offer(arbiter, ToArbiter::Pose(pose.utime, now), &mut queue_full);
                            }
                            if let Some(guard) = &routes.guard {
                                offer(guard, GuardInput::Pose(pose, now), &mut queue_full);
                            }
                        }
                        Err(e) => bad.refuse("pose", &message.channel, &e),
                    },
                    Some(AnyMessage::RangeImage(msg)) => match wire::range_image_from_wire(msg) {
                        Ok(image) => {
                            images += 1;
                            if let Some(guard) = &routes.guard {
                                offer(guard, GuardInput::Image(image.clone()), &mut queue_full);
                            }
                            if let Some(feed) = &routes.images {
                                feed.images.put(Arrived {
                                    item: image,
                                    wall: now,
                                });
                            }
                        }
                        Err(e) => bad.refuse("range image", &message.channel, &e),
                    },
                    Some(AnyMessage::RangeSlice(msg)) => match wire::range_slice_from_wire(msg) {
                        Ok(slice) => {
                            slices += 1;
                            if let Some(guard) = &routes.guard {
                                offer(guard, GuardInput::Slice(slice.clone()), &mut queue_full);
                            }
                            if let Some(feed) = &routes.images {
                                let slice = Arrived {
                                    item: slice,
                                    wall: now,
                                };
                                offer(&feed.slices, slice, &mut queue_full);
                            }
                        }
                        Err(e) => bad.refuse("range slice", &message.channel, &e),
                    },
                    Some(AnyMessage::Waypoints(msg)) => match wire::mission_from_wire(&msg) {
                        Ok(mission) => {
                            if let Some(route) = &routes.waypoints {
                                offer(route, mission, &mut queue_full);
                            }
                        }
                        Err(e) => bad.refuse("waypoints", &message.channel, &e),
                    },
                    Some(AnyMessage::ArcVotes(msg)) => match (&routes.external, &routes.arbiter) {
                        (Some(external), Some(arbiter))
                            if channels::arc_votes(&msg.behaviour) == message.channel
                                && external.names.contains(&msg.behaviour) =>
                        {
                            match wire::votes_from_wire(&msg, &external.arcs) {
                                Ok(votes) => {
                                    external_votes += 1;
                                    let votes = ToArbiter::Votes {
                                        votes: vec![votes],
                                        images: Vec::new(),
                                    };
                                    offer(arbiter, votes, &mut queue_full);
                                }
                                Err(e) => bad.refuse("votes", &message.channel, &e),
                            }
                        }
                        _ => bad.refuse(
                            "votes",
                            &message.channel,
                            &format_args!(
                                "from {:?}, not an external behaviour's on its own channel",
                                msg.behaviour
                            ),
                        ),
                    },
                    _ => undecodable += 1,
                };
            }
            if ticker.due(now) {
                status.dropped = bad.total() + undecodable + queue_full;
                status.log();
            }
        },
    );
    let transport = lcm.stats();
    let refused = bad.total() + undecodable;
    status.dropped = refused + queue_full;
    let depth = [&routes.perception_poses, &routes.map_poses]
        .into_iter()
        .flatten()
        .map(Sender::len)
        .max();
    status.queue(depth.unwrap_or(0));
    status.set("poses", poses);
    status.set("images", images);
    status.set("slices", slices);
    status.set("refused", refused);
    if routes.external.is_some() {
        status.set("external_votes", external_votes);
    }
    status.set("queue_full", queue_full);
    status.set("incomplete_messages", transport.reassembly.incomplete);
    status.set("malformed_datagrams", transport.reassembly.malformed);
    auth_status(lcm, &mut status);
    result.map(|()| status)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_of_refusals_is_counted_whole_and_warned_of_ten_times_in_a_thousand() {
        let mut refused = Refused::default();
        for _ in 0..1000 {
            refused.refuse("pose", "POSE", &"not finite");
        }
        assert_eq!(refused.warned, 10, "1, 2, 4, … 512");
        refused.refuse("votes", "ARC_VOTES_X", &"12 arcs");
        assert_eq!(refused.warned, 11, "each kind's first");
        assert_eq!(refused.total(), 1001);
    }
}
