//! One map patch: what was judged of a square of ground, by which
//! sensor, when.

use arcnav_perception::{Reasons, suspected_drop_off};
use arcnav_vehicle::Utime;

/// One map patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// World patch index: the patch spans [i·s, (i+1)·s) × [j·s, (j+1)·s).
    pub i: i64,
    pub j: i64,
    /// Centre in the vehicle frame of the last update, m.
    pub x: f32,
    pub y: f32,
    /// Capture time of the first and of the latest image reporting it.
    pub first_seen: Utime,
    pub last_seen: Utime,
    /// Images that reported it.
    pub confirmations: u32,
    /// Newer overlapping images that did not report it since its last confirmation.
    pub misses: u32,
    pub reasons: Reasons,
    /// Set of sensor indices (see [`LocalMap::sensor_name`]) that reported it.
    pub sensors: u32,
    /// Lowest and highest point of its cells, world z, m.
    pub z_min: f32,
    pub z_max: f32,
    /// Highest cost of its cells: 1 untraversable, below 1 graded ground
    /// (see `arcnav_perception::ObstacleCell::cost`).
    pub cost: f32,
    /// Nearest horizontal distance from which an image reported it, m
    /// (infinite: not known; any overlapping image may miss it).
    pub nearest_m: f32,
    /// Last report that touched it.
    pub(super) stamp: u64,
}

impl Patch {
    /// Whether the vehicle cannot drive here (cost 1); graded ground
    /// otherwise.
    pub fn is_obstacle(&self) -> bool {
        self.cost >= 1.0
    }

    /// Whether this is a suspected drop-off (see
    /// [`arcnav_perception::suspected_drop_off`]).
    pub fn is_suspected_drop_off(&self) -> bool {
        suspected_drop_off(self.cost, self.reasons)
    }

    /// An empty patch at world index (`i`, `j`), to fill in field by field
    /// (a map snapshot rebuilt from a message, a test).
    pub fn at(i: i64, j: i64) -> Self {
        Self {
            i,
            j,
            x: 0.0,
            y: 0.0,
            first_seen: 0,
            last_seen: 0,
            confirmations: 0,
            misses: 0,
            reasons: Reasons::NONE,
            sensors: 0,
            z_min: 0.0,
            z_max: 0.0,
            cost: 1.0,
            nearest_m: f32::INFINITY,
            stamp: 0,
        }
    }
}
