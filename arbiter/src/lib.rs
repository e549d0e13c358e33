//! # arcnav-arbiter
//!
//! Rosenblatt's DAMN command arbitration as used in 002 §6: behaviours vote
//! in [-1, 1] over the arc set, the arbiter owns the weights and decides. It
//! knows votes, not behaviours.

pub mod arbiter;
pub mod config;
pub mod recovery;
pub mod trail;
pub mod votes;

pub use arbiter::{
    Arbiter, ArbiterStats, Decision, InputExplanation, Reason, StopReason, StopTime, Vetoer,
    VoteSizeError,
};
pub use config::ArbiterConfig;
pub use recovery::{RecoveryConfig, RecoveryStats};
pub use votes::{BehaviourVotes, SpeedCause, VetoCause, Votes};
