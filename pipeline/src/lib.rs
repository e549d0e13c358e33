//! # arcnav-pipeline
//!
//! arcnav's navigation pipeline as a library (002 §3-§6): the nodes and the
//! one decision cycle that every executor drives.
//!
//! ```text
//!  range image ─► PerceptionNode ─► obstacle report ─► DecisionCycle ─► Cycle ─► BehaviourSet ─► votes ─► Arbiter / ArbiterNode ─► command
//!  pose ─────────────┴──────────────────────────────────────┘ (local map + cycle clock)
//! ```
//!
//! - [`PerceptionNode`]: range images + poses → obstacle reports, one image
//!   at a time with the pose at its capture time;
//! - [`DecisionCycle`]: the local map (Ganesha) and the cycle clock: cycles
//!   on pose time, report delivery, time going backwards or jumping ahead;
//! - [`BehaviourSet`]: the configured behaviours voting on one cycle;
//! - [`ArbiterNode`]: the DAMN arbiter as live runs use it (per-cycle vote
//!   gathering, deadlines, the safety watchdog);
//! - [`Pipeline`]: the lock-step executor of all of them on one thread.
//!
//! Like the core crates, this crate links no transport, starts no thread and
//! reads no clock: time arrives as an argument. The `arcnav` binary's
//! lock-step (`sim`, `replay`), threaded (`run`) and distributed (`node`)
//! executors only move messages between these nodes; a program of your own
//! can drive them directly (`examples/embed.rs`).

pub mod arbiter;
pub mod behaviours;
pub mod config;
pub mod cycle;
pub mod lockstep;
pub mod perception;
pub mod stats;

pub use arbiter::{ArbiterCounts, ArbiterNode, Decided, Hazard, Why};
pub use behaviours::BehaviourSet;
pub use config::{ExternalConfig, Fault, Latency, LiveConfig, PipelineConfig};
pub use cycle::{Cycle, CycleCounts, DecisionCycle, Delivery, LocalMapNode, MAX_CATCH_UP_US};
pub use lockstep::{
    Commands, Discard, FaultCounts, Input, Pipeline, Sink, StageTime, StageTimes, Stopwatch,
};
pub use perception::{FusionCounts, PerceptionDrops, PerceptionNode, SliceCounts};
pub use stats::{Samples, Summary};
