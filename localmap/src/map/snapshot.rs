//! An immutable view of the map in the vehicle frame, cheap to share:
//! what the behaviours read.

use arcnav_vehicle::numbers::floor_i64;
use std::sync::Arc;

use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::{Isometry, Utime};

use super::patch::Patch;
use super::seen::SeenGround;
use crate::elevation::ElevationGrid;

/// An immutable view of the map in the vehicle frame, cheap to share.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MapSnapshot {
    /// Time of the pose the snapshot is expressed in.
    pub utime: Utime,
    /// That pose.
    pub world_from_vehicle: Isometry,
    pub patch_size_m: f64,
    pub patches: Vec<Patch>,
    /// The ground observed around the vehicle (the window's square).
    pub seen: SeenGround,
    /// The elevation layer around the vehicle (004 §III), world-aligned
    /// (shared between snapshots while the layer does not change).
    pub elevation: Arc<ElevationGrid>,
}

impl MapSnapshot {
    /// Whether the ground at vehicle-frame (`x`, `y`) has been seen.
    pub fn is_seen(&self, x: f64, y: f64) -> bool {
        self.seen_lookup()(x, y)
    }

    /// [`MapSnapshot::is_seen`] with the pose's trigonometry done once, for
    /// many lookups.
    pub fn seen_lookup(&self) -> impl Fn(f64, f64) -> bool + '_ {
        let t = self.world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(&self.world_from_vehicle).sin_cos();
        let inverse = 1.0 / self.patch_size_m;
        move |x, y| {
            let (wx, wy) = (t.x + cos * x - sin * y, t.y + sin * x + cos * y);
            self.seen
                .contains(floor_i64(wx * inverse), floor_i64(wy * inverse))
        }
    }

    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }
}
