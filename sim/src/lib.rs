//! # arcnav-sim
//!
//! The simulator that closes the loop when nobody has a HMMWV at hand:
//!
//! - [`world`]: worlds in TOML (terrain from noise or a `.npy`/`.asc` file,
//!   boulders, trees, bushes, ditches, holes, banks, waypoints, start), three
//!   embedded ones and [`generate`](mod@generate)d ones;
//! - [`tiles`]: the world as 0.1 m height tiles and a ray caster implementing
//!   perception's [`arcnav_perception::RayCast`] — the one rendering path,
//!   and [`polar`], the same answers faster for a frame's rays from one point;
//! - [`sensor`]: range images with noise and dropouts;
//! - [`drape`]: the vehicle standing on the ground;
//! - [`truth`]: collisions of the footprint with the true hazards;
//! - [`simulator`]: all of it stepping itself, one pose tick at a time: the
//!   motion, the measured pose, the sensors' timing, slices and frames
//!   (rendered ahead where the vehicle's path is already decided).

mod ahead;
pub mod config;
pub mod drape;
pub mod generate;
pub mod heightmap;
pub mod noise;
mod numbers;
pub mod polar;
pub mod ride;
pub mod rng;
pub mod sensor;
pub mod simulator;
pub mod spec;
pub mod tiles;
pub mod truth;
pub mod world;

pub use config::{CollisionPolicy, SimConfig};
pub use generate::{Difficulty, generate};
pub use ride::{Ride, RideReport};
pub use simulator::{Simulator, Step, Stepped};
pub use truth::{Collision, NearMiss, Truth};
pub use world::{Feature, FeatureKind, World, WorldError, WorldSpec};
