//! # arcnav-vehicle
//!
//! The bottom layer of arcnav: time ([`Utime`], microseconds), poses and frame
//! conventions (REP 103; the vehicle origin is on the ground under the middle
//! of the rear axle), a [`PoseHistory`] answering "where was the vehicle when
//! this image was taken", the [`VehicleConfig`] model, the [`ArcSet`] the
//! behaviours vote over, [`SteeringCommand`] and a kinematic [`MotionModel`].
//!
//! Like every core crate it reads no clock, starts no thread and links no
//! middleware.

pub mod arcs;
pub mod command;
pub mod config;
pub mod drive;
pub mod files;
pub mod footprint;
pub mod frames;
pub mod mission;
pub mod model;
pub mod motion;
pub mod numbers;
pub mod pose_history;
pub mod time;
pub mod watchdog;

pub use arcs::{Arc, ArcPose, ArcSet, ArcSetConfig, DrivenPaths, SweptFootprint, TurnInPlace};
pub use command::SteeringCommand;
pub use config::ConfigError;
pub use drive::{DrivenPath, Steering, SteeringResponse};
pub use frames::{Isometry, Pose};
pub use model::{Footprint, Kinematics, VehicleConfig};
pub use motion::{MotionLimits, MotionModel, PlanarState};
pub use pose_history::{PoseHistory, PoseHistoryError};
pub use time::Utime;
pub use watchdog::CommandWatchdog;
