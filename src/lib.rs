//! # arcnav
//!
//! Reactive cross-country navigation after Langer, Rosenblatt and Hebert
//! (CMU): early traversability evaluation of each range image, a Ganesha local
//! map of untraversable cells, behaviours voting over steering arcs and a DAMN
//! arbiter fusing the votes into a steering command.
//!
//! This crate holds what sits on top of the pipeline library
//! ([`arcnav_pipeline`]) and the configuration ([`arcnav_config`]): the mission runner,
//! replay, recording, pictures and the live executors' I/O used by the
//! `arcnav` binary.

pub mod detection;
#[doc(hidden)]
pub mod export;
pub mod fuzzing;
pub mod live;
pub mod mission;
pub mod output;
mod recorder;
pub mod render;
pub mod replay;
pub mod sweep;
pub mod wire;

pub use arcnav_config::{Config, Resolved};
