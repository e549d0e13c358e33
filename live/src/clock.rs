//! The wall clock of live executors, given to them as a parameter: the
//! watchdogs, arrival times and deadlines all read it, so a test can drive
//! time ([`ManualClock`]) instead of sleeping.

use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};

use arcnav_bus::transport::wall_clock_utime;

/// Microseconds since the Unix epoch.
pub trait Clock: Send + Sync + std::fmt::Debug {
    fn now_us(&self) -> i64;
}

/// The system's clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct WallClock;

impl Clock for WallClock {
    fn now_us(&self) -> i64 {
        wall_clock_utime()
    }
}

/// A clock that moves only when told (tests); clones share the time.
#[derive(Debug, Clone, Default)]
pub struct ManualClock(Arc<AtomicI64>);

impl ManualClock {
    pub fn starting_at(us: i64) -> Self {
        Self(Arc::new(AtomicI64::new(us)))
    }

    pub fn set(&self, us: i64) {
        self.0.store(us, Ordering::SeqCst);
    }

    pub fn advance(&self, us: i64) {
        self.0.fetch_add(us, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now_us(&self) -> i64 {
        self.0.load(Ordering::SeqCst)
    }
}

/// A clock shared by the threads of an executor.
pub type SharedClock = Arc<dyn Clock>;
