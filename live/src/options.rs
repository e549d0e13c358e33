//! How a live executor runs and stops, what stops it, and what its
//! threads hand the arbiter: shared by the threaded executor, its io loop
//! and its workers.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use arcnav_arbiter::BehaviourVotes;
use arcnav_bus::transport::TransportError;
use arcnav_pipeline::Decided;
use arcnav_vehicle::Utime;
use arcnav_vehicle::config::ConfigError;
use crossbeam_channel::Sender;

use super::clock::{SharedClock, WallClock};

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
    #[error(
        "the configuration injects a fault into the pipeline ([pipeline] fault = {0:?}): that is for the simulator and replay, never a vehicle; remove it"
    )]
    FaultInjected(&'static str),
    #[error(
        "[guard] enabled = false: the guard node has nothing to do; enable it, or do not run it"
    )]
    GuardOff,
}

/// A live executor refuses a configuration that injects a fault.
pub(crate) fn refuse_fault(config: &arcnav_config::Resolved) -> Result<(), LiveError> {
    match config.pipeline.fault {
        arcnav_pipeline::Fault::None => Ok(()),
        fault => Err(LiveError::FaultInjected(fault.name())),
    }
}

/// When a live executor stops.
#[derive(Clone, Default)]
pub struct StopWhen {
    /// Set by SIGINT/SIGTERM (or a test).
    pub flag: Arc<AtomicBool>,
    /// After this much wall-clock time.
    pub after: Option<Duration>,
}

impl LiveOptions {
    /// The executor's clock.
    pub fn clock(&self) -> SharedClock {
        self.clock.clone().unwrap_or_else(|| Arc::new(WallClock))
    }
}

impl StopWhen {
    pub(crate) fn deadline(&self) -> Option<Instant> {
        self.after.map(|d| Instant::now() + d)
    }
}

/// How a live executor runs.
#[derive(Clone, Default)]
pub struct LiveOptions {
    /// The clock every watchdog, deadline and arrival time reads (default:
    /// the wall clock).
    pub clock: Option<SharedClock>,
    pub stop: StopWhen,
    /// Every published command, with why, is also sent here (tests, tools).
    pub command_tap: Option<Sender<Decided>>,
    /// Told once the executor receives (every node built and subscribed).
    pub ready: Option<Sender<()>>,
}

/// What the arbiter thread receives.
pub(crate) enum ToArbiter {
    Pose(Utime, i64),
    Perceived(Utime, i64),
    Votes {
        votes: Vec<BehaviourVotes>,
        images: Vec<(Utime, i64)>,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fault is for the simulator and replay: every live executor
    /// refuses it by name before it starts a thread.
    #[test]
    fn a_live_run_refuses_a_configuration_that_injects_a_fault() {
        let mut config = arcnav_config::Config::default();
        assert!(refuse_fault(&config.resolved().unwrap()).is_ok());
        config.pipeline.fault = arcnav_pipeline::Fault::StaleMap;
        let e = refuse_fault(&config.resolved().unwrap()).unwrap_err();
        assert!(matches!(e, LiveError::FaultInjected("stale_map")), "{e}");
        assert!(e.to_string().contains("[pipeline] fault"), "{e}");
    }
}
