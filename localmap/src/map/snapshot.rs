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
        let frame = self.seen_frame();
        move |x, y| frame.across(x).seen(y)
    }

    /// The seen ground in the vehicle frame, for lookups line by line
    /// ([`SeenFrame::across`]).
    pub fn seen_frame(&self) -> SeenFrame<'_> {
        let t = self.world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(&self.world_from_vehicle).sin_cos();
        SeenFrame {
            seen: &self.seen,
            x: t.x,
            y: t.y,
            sin,
            cos,
            inverse: 1.0 / self.patch_size_m,
        }
    }

    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }
}

/// A snapshot's seen ground with the pose's trigonometry done once.
#[derive(Debug, Clone, Copy)]
pub struct SeenFrame<'a> {
    seen: &'a SeenGround,
    /// The pose's position in the world, the sine and cosine of its yaw.
    x: f64,
    y: f64,
    sin: f64,
    cos: f64,
    /// 1 / the patch size.
    inverse: f64,
}

impl<'a> SeenFrame<'a> {
    /// The line of vehicle-frame points at `x`: the part of each lookup
    /// that depends on x alone taken once.
    pub fn across(&self, x: f64) -> SeenLine<'a> {
        SeenLine {
            frame: *self,
            x: self.x + self.cos * x,
            y: self.y + self.sin * x,
        }
    }
}

/// The vehicle-frame points of one x ([`SeenFrame::across`]).
#[derive(Debug, Clone, Copy)]
pub struct SeenLine<'a> {
    frame: SeenFrame<'a>,
    /// World x and y of the line's point at vehicle-frame y = 0.
    x: f64,
    y: f64,
}

impl SeenLine<'_> {
    /// Whether the ground at vehicle-frame `y` on this line has been seen
    /// (the world point `t + R·(x, y)`, summed in the order
    /// [`MapSnapshot::seen_lookup`] always has).
    #[inline]
    pub fn seen(&self, y: f64) -> bool {
        let f = &self.frame;
        let (wx, wy) = (self.x - f.sin * y, self.y + f.cos * y);
        f.seen
            .contains(floor_i64(wx * f.inverse), floor_i64(wy * f.inverse))
    }
}
