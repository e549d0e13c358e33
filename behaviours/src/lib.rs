//! # arcnav-behaviours
//!
//! Behaviours vote over the arc set; the arbiter decides (002 §6).
//!
//! - [`Behaviour`]: one hot method, [`Behaviour::vote`], filling a
//!   caller-owned [`arcnav_arbiter::Votes`] from a [`VoteContext`] (map
//!   snapshot, pose, mission, arcs); lifecycle hooks with default bodies;
//! - [`Registry`]: builds behaviours by name from their TOML tables; plug in
//!   your own with [`Plugin`] and `registry.add::<Mine>()`;
//! - [`ObstacleAvoidance`] and [`GoalSeeking`], the paper's two behaviours;
//! - [`Route`], a D* Lite route planner voting for the arcs along its path.

pub mod behaviour;
pub mod goal_seeking;
pub mod obstacle_avoidance;
pub mod registry;
pub mod route;
pub mod terrain;

pub use behaviour::{
    Behaviour, Mission, NoRoute, Overlay, OverlayCells, OverlayLine, OverlayPoint, Plugin,
    Progress, Setup, VoteContext, Waypoint,
};
pub use goal_seeking::{GoalSeeking, GoalSeekingConfig};
pub use obstacle_avoidance::{ObstacleAvoidance, ObstacleAvoidanceConfig, UnseenGround};
pub use registry::{Prepared, Registry, RegistryError};
pub use route::{Route, RouteConfig, RouteStats};
pub use terrain::{ArcTerrain, Judgement, Stance, TerrainCheck, TerrainConfig};
