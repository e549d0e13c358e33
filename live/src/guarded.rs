//! The guard inside `arcnav run`: a thread of its own takes the poses and
//! the sensor's images (copies, from the io thread) and every command the
//! arbiter decides goes through it before it is published. What it lets
//! through is published on STEERING_COMMAND; when it stops or slows one,
//! the DECISION says `guard: …` and GUARD_STATUS says why. The guard as
//! the vehicle bridge and `arcnav node guard` hold it is here too
//! ([`BridgeGuard`]).

use std::sync::{Arc, Mutex, PoisonError};

use arcnav_bus::messages::AnyMessage;
use arcnav_bus::messages::channels;
use arcnav_bus::transport::Publisher;
use arcnav_guard::{Guard, Verdict};
use arcnav_perception::{RangeImage, RangeSlice};
use arcnav_pipeline::Decided;
use arcnav_vehicle::{Pose, SteeringCommand};
use arcnav_wire as wire;
use crossbeam_channel::Receiver;
use serde::Serialize;

use super::NodeStatus;

/// What the io thread hands the guard.
pub(crate) enum GuardInput {
    /// A pose, and when it arrived (the bridge's clock).
    Pose(Pose, i64),
    Image(RangeImage),
    Slice(RangeSlice),
}

/// The guard shared by its thread (which feeds it) and the arbiter's
/// (which asks it).
#[derive(Clone)]
pub(crate) struct RunGuard(Arc<Mutex<BridgeGuard>>);

impl RunGuard {
    pub(crate) fn new(guard: Guard) -> Self {
        Self(Arc::new(Mutex::new(BridgeGuard::new(guard))))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BridgeGuard> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The guard's thread: takes every input until the io thread ends.
    pub(crate) fn run(&self, inputs: &Receiver<GuardInput>) -> NodeStatus {
        let mut status = NodeStatus::new("guard");
        for input in inputs {
            status.handled += 1;
            let mut guard = self.lock();
            match input {
                GuardInput::Pose(pose, now) => guard.observe_pose(&pose, now),
                GuardInput::Image(image) => guard.guard.observe_image(&image),
                GuardInput::Slice(slice) => guard.guard.observe_slice(&slice),
            }
        }
        guard_status(&self.lock(), &mut status);
        status
    }

    /// `decided` as the guard lets it through at `now`: published as it
    /// is when clear; its speed capped, or stopped, with the DECISION
    /// saying so, otherwise. GUARD_STATUS says the verdict either way.
    pub(crate) fn judge(&self, decided: &Decided, now: i64, publisher: &Publisher) -> Decided {
        let (at, verdict) = self.lock().judge(&decided.command, now);
        say(publisher, at, decided.command.utime, &verdict);
        let mut out = decided.clone();
        if let Some(reason) = verdict.reason() {
            out.command = verdict.apply(&decided.command);
            out.why = arcnav_pipeline::Why::Guard(reason.to_string());
        }
        out
    }
}

/// The guard's verdict on what is executed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Guarded {
    /// No guard (`[guard] enabled = false`), or no command to judge.
    Off,
    Clear,
    /// The speed is capped.
    Slow,
    /// The vehicle stops.
    Stop,
}

impl From<&Verdict> for Guarded {
    fn from(verdict: &Verdict) -> Self {
        match verdict {
            Verdict::Clear => Self::Clear,
            Verdict::Slow { .. } => Self::Slow,
            Verdict::Stop { .. } => Self::Stop,
        }
    }
}

/// The guard in the bridge: the guard, the newest pose's sensor time and
/// when it arrived (the sensor clock runs on from it), what it did.
pub(crate) struct BridgeGuard {
    pub(crate) guard: Guard,
    pose_at: Option<(i64, i64)>,
    last: Guarded,
    stops: u64,
    slows: u64,
    interventions: u64,
    pub(crate) ignored: u64,
}

impl BridgeGuard {
    pub(crate) fn new(guard: Guard) -> Self {
        Self {
            guard,
            pose_at: None,
            last: Guarded::Off,
            stops: 0,
            slows: 0,
            interventions: 0,
            ignored: 0,
        }
    }

    /// The verdict last said.
    pub(crate) fn last(&self) -> Guarded {
        self.last
    }

    /// Subscribes `lcm` to what the guard takes: POSE and RANGE_IMAGE*.
    pub(crate) fn subscribe(
        lcm: &mut arcnav_bus::transport::Lcm,
    ) -> Result<(), super::options::LiveError> {
        lcm.subscribe(channels::POSE);
        lcm.subscribe_regex(&format!("{}.*", channels::RANGE_IMAGE))?;
        Ok(())
    }

    /// A pose that arrived at `now` (the bridge's clock).
    pub(crate) fn observe_pose(&mut self, pose: &Pose, now: i64) {
        self.guard.observe_pose(pose);
        if self.pose_at.is_none_or(|(t, _)| pose.utime >= t) {
            self.pose_at = Some((pose.utime, now));
        }
    }

    pub(crate) fn on_message(&mut self, message: AnyMessage, now: i64) {
        match message {
            AnyMessage::Pose(msg) => match Pose::try_from(&msg) {
                Ok(pose) => self.observe_pose(&pose, now),
                Err(_) => self.ignored += 1,
            },
            AnyMessage::RangeImage(msg) => match wire::range_image_from_wire(msg) {
                Ok(image) => self.guard.observe_image(&image),
                Err(_) => self.ignored += 1,
            },
            AnyMessage::RangeSlice(msg) => match wire::range_slice_from_wire(msg) {
                Ok(slice) => self.guard.observe_slice(&slice),
                Err(_) => self.ignored += 1,
            },
            _ => self.ignored += 1,
        }
    }

    /// `now` (the bridge's clock) on the sensor clock.
    fn sensor_time(&self, now: i64) -> i64 {
        self.pose_at.map_or(now, |(utime, at)| utime + (now - at))
    }

    /// The verdict on `command` at `now`, said when it changes.
    pub(crate) fn judge(&mut self, command: &SteeringCommand, now: i64) -> (i64, Verdict) {
        let at = self.sensor_time(now);
        let verdict = self.guard.check(command, at);
        let state = Guarded::from(&verdict);
        match state {
            Guarded::Stop => self.stops += 1,
            Guarded::Slow => self.slows += 1,
            _ => {}
        }
        if state != self.last {
            match &verdict {
                Verdict::Clear => tracing::info!("guard: clear"),
                Verdict::Slow { cap_mps, reason } => {
                    self.interventions += 1;
                    tracing::warn!("guard: SLOW to {cap_mps:.2} m/s: {reason}");
                }
                Verdict::Stop { reason, .. } => {
                    self.interventions += 1;
                    tracing::warn!("guard: STOP: {reason}");
                }
            }
            self.last = state;
        }
        (at, verdict)
    }
}

/// The guard's verdict at `at` (sensor clock) on the command stamped
/// `command_utime`, on GUARD_STATUS.
pub(crate) fn say(publisher: &Publisher, at: i64, command_utime: i64, verdict: &Verdict) {
    let said = wire::guard_status_to_wire(at, command_utime, verdict);
    if let Err(e) = publisher.publish_message(channels::GUARD_STATUS, &said) {
        tracing::debug!(%e, "cannot publish the guard's status");
    }
}

/// The guard's counts on the status lines and in `--stats`.
pub(crate) fn guard_status(guard: &BridgeGuard, status: &mut NodeStatus) {
    let counts = guard.guard.counts();
    status.set("guard_interventions", guard.interventions);
    status.set("guard_stop_ticks", guard.stops);
    status.set("guard_slow_ticks", guard.slows);
    status.set("guard_images", counts.images + counts.slices);
    status.set("guard_messages_unused", guard.ignored);
}
