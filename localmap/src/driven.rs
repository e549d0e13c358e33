//! Ground the vehicle has driven over, remembered beyond the window.
//!
//! The map forgets the ground that leaves its window, seen ground with its
//! cells: seen ground whose cells were dropped would read as free when the
//! vehicle comes back to it. The ground between the vehicle's axles is
//! another matter: the vehicle stood on it, so it bore the vehicle, whatever
//! lies around it. Remembering that swath lets the vehicle back out of a
//! dead end the way it came in, further than the window reaches behind the
//! farthest point it reached (a lane too narrow to turn round in): when the
//! swath comes back into the window it counts as seen again.
//!
//! The memory is bounded: the oldest patches are forgotten first, and
//! `driven_memory_m` of travel (at the vehicle's width) is kept.

use arcnav_vehicle::numbers::floor_i64;
use std::collections::{HashSet, VecDeque};

use nalgebra::Point2;

use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::{Footprint, Pose, VehicleConfig};

/// The patches the vehicle's wheelbase has covered, oldest first.
#[derive(Debug, Clone, Default)]
pub(crate) struct DrivenGround {
    /// Where a patch's centre must lie, in the vehicle frame, for its
    /// square to overlap the ground between the axles widened by half a
    /// patch to each side (as the local map clears cells under the vehicle
    /// and obstacle avoidance sweeps the body).
    bearing: Option<Footprint>,
    patch_size_m: f64,
    capacity: usize,
    known: HashSet<(i64, i64)>,
    order: VecDeque<(i64, i64)>,
}

impl DrivenGround {
    /// A memory of about `memory_m` of travel of `vehicle` over patches of
    /// `patch_size_m` (0: none).
    pub fn new(vehicle: &VehicleConfig, patch_size_m: f64, memory_m: f64) -> Self {
        let bearing = vehicle
            .footprint()
            .clipped(0.0, vehicle.wheelbase_m)
            .widened(patch_size_m / 2.0 + patch_size_m * std::f64::consts::FRAC_1_SQRT_2);
        let across = (2.0 * bearing.half_width / patch_size_m).ceil() + 1.0;
        let along = (memory_m / patch_size_m).ceil();
        let capacity = (across * along) as usize;
        Self {
            bearing: (capacity > 0).then_some(bearing),
            patch_size_m,
            capacity,
            known: HashSet::with_capacity(capacity.min(1 << 16)),
            order: VecDeque::with_capacity(capacity.min(1 << 16)),
        }
    }

    /// Adds the patches between the axles at `pose`; returns how many were
    /// new.
    pub fn drive(&mut self, pose: &Pose) -> usize {
        let Some(bearing) = self.bearing else {
            return 0;
        };
        let s = self.patch_size_m;
        let t = pose.world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(&pose.world_from_vehicle).sin_cos();
        let world = |p: Point2<f64>| (t.x + cos * p.x - sin * p.y, t.y + sin * p.x + cos * p.y);
        let corners: Vec<(f64, f64)> = bearing.outline().iter().map(|&p| world(p)).collect();
        let lo = |f: fn(&(f64, f64)) -> f64| {
            floor_i64(corners.iter().map(f).fold(f64::INFINITY, f64::min) / s)
        };
        let hi = |f: fn(&(f64, f64)) -> f64| {
            floor_i64(corners.iter().map(f).fold(f64::NEG_INFINITY, f64::max) / s)
        };
        let (i0, i1, j0, j1) = (lo(|c| c.0), hi(|c| c.0), lo(|c| c.1), hi(|c| c.1));
        let mut added = 0;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let (dx, dy) = ((i as f64 + 0.5) * s - t.x, (j as f64 + 0.5) * s - t.y);
                let centre = Point2::new(cos * dx + sin * dy, -sin * dx + cos * dy);
                if bearing.contains(centre) && self.known.insert((i, j)) {
                    self.order.push_back((i, j));
                    added += 1;
                }
            }
        }
        while self.order.len() > self.capacity {
            if let Some(old) = self.order.pop_front() {
                self.known.remove(&old);
            }
        }
        added
    }

    /// Every remembered patch, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = (i64, i64)> + '_ {
        self.order.iter().copied()
    }

    /// Forgets everything (the map was reset: where the vehicle drove is
    /// no longer known relative to it).
    pub fn clear(&mut self) {
        self.known.clear();
        self.order.clear();
    }
}
