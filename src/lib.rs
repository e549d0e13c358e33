//! # arcnav
//!
//! Reactive cross-country navigation after Langer, Rosenblatt and Hebert
//! (CMU): early traversability evaluation of each range image, a Ganesha local
//! map of untraversable cells, behaviours voting over steering arcs and a DAMN
//! arbiter fusing the votes into a steering command.
//!
//! This package is the `arcnav` command line. What it runs lives in library
//! crates, re-exported here under the names the command uses:
//! the configuration ([`arcnav_config`]), the offline executors and their
//! pictures ([`arcnav_run`]: [`mission`], [`replay`], [`export`], [`sweep`],
//! [`detection`], [`render`]), the live executors ([`live`], from
//! [`arcnav_live`]) and the wire conversions ([`wire`], from [`arcnav_wire`]).

pub use arcnav_config::{Config, Resolved};
pub use arcnav_live as live;
#[doc(hidden)]
pub use arcnav_run::export;
pub use arcnav_run::{bag, detection, fuzzing, mission, output, render, replay, sweep};
pub use arcnav_wire as wire;
