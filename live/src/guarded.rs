//! The guard inside `arcnav run`: a thread of its own takes the poses and
//! the sensor's images (copies, from the io thread) and every command the
//! arbiter decides goes through it before it is published. What it lets
//! through is published on STEERING_COMMAND; when it stops or slows one,
//! the DECISION says `guard: …` and GUARD_STATUS says why.

use std::sync::{Arc, Mutex, PoisonError};

use arcnav_bus::messages::channels;
use arcnav_bus::transport::Publisher;
use arcnav_guard::Guard;
use arcnav_perception::{RangeImage, RangeSlice};
use arcnav_pipeline::Decided;
use arcnav_vehicle::Pose;
use arcnav_wire as wire;
use crossbeam_channel::Receiver;

use super::NodeStatus;
use super::vehicle::{BridgeGuard, guard_status};

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
        let said = wire::guard_status_to_wire(at, decided.command.utime, &verdict);
        if let Err(e) = publisher.publish_message(channels::GUARD_STATUS, &said) {
            tracing::debug!(%e, "cannot publish the guard's status");
        }
        let mut out = decided.clone();
        if let Some(reason) = verdict.reason() {
            out.command = verdict.apply(&decided.command);
            out.why = arcnav_pipeline::Why::Guard(reason.to_string());
        }
        out
    }
}
