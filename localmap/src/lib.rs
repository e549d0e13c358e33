//! # arcnav-localmap
//!
//! Ganesha, the local map of 002 §5: it keeps only the untraversable cells
//! near the vehicle — a few items, not a terrain model — placed with the pose
//! at sensing time, dropped when they leave the window around the vehicle or
//! when newer overlapping images do not report them again. The only sensor
//! knowledge it has is each image's observed footprint. Behaviours read
//! immutable vehicle-frame [`MapSnapshot`]s.

pub mod config;
mod driven;
pub mod elevation;
pub mod map;
pub mod raster;
pub mod static_map;

pub use config::{JumpPolicy, LocalMapConfig, OccupancyConfig};
pub use elevation::{ElevationConfig, ElevationGrid, ElevationLayer, ElevationStats};
pub use map::{
    InsertError, InsertOutcome, JumpReason, LocalMap, MAX_SENSORS, MapSnapshot, MapStats, Patch,
    PoseUpdate, SeenFrame, SeenGround, SeenLine,
};
pub use static_map::{OccupancyGrid, StaticMap, StaticMapError};
