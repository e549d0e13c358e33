//! # arcnav-run
//!
//! The offline executors of arcnav, each a library function over the
//! pipeline of [`arcnav_pipeline`] built from one [`arcnav_config::Resolved`]
//! configuration:
//!
//! - [`mission::run_mission`]: a simulated mission on a world of
//!   [`arcnav_sim`], closing the loop through the simulator;
//! - [`replay::replay`]: a recorded log (arcnav's LCM log, or a ROS 2 bag
//!   through [`bag`]) played against the pipeline, its decisions written
//!   to a new log and compared with the recorded ones;
//! - [`export::export_mcap`], [`export::export_bag`]: a log written as MCAP
//!   for Foxglove, or as a ROS 2 bag of standard messages;
//! - [`sweep`]: many missions over worlds and speeds, one row each;
//! - [`external`]: behaviours that are programs of their own, started and
//!   voting in lock-step with the executors above;
//! - [`detection`]: the detection-rate experiment of the range sensors;
//! - [`render`]: the pictures of each (map.png, sweep and detection figures).

pub mod bag;
pub mod detection;
#[doc(hidden)]
pub mod export;
pub mod external;
pub mod fuzzing;
pub mod mission;
pub mod output;
mod recorder;
pub mod render;
pub mod replay;
pub mod sweep;
