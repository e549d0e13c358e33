//! Ground truth: the vehicle's footprint against the world's true hazards —
//! features it cannot drive over (rocks above the tolerated step, trunks,
//! bushes, ditches and holes deeper than the step, banks steeper than its
//! limit), attitude beyond its slope limit, the edge of the mission's
//! operating area (any corner of the footprint beyond it), and the edge of
//! the map. Each
//! contact with a hazard is one collision, however long it lasts.

use std::collections::BTreeSet;

use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::mission::Area;
use arcnav_vehicle::numbers::segments_cross;
use arcnav_vehicle::{Footprint, Utime, VehicleConfig};
use serde::Serialize;

use crate::drape::Stance;
use crate::world::{Feature, World};

/// One collision.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Collision {
    /// Time of first contact, µs.
    pub utime: Utime,
    /// Vehicle origin then, world frame, m.
    pub position: [f64; 2],
    /// What was hit, e.g. "boulder 0.82 m tall" or "slope 27°".
    pub cause: String,
    /// Index of the feature hit, when it is one.
    pub feature: Option<usize>,
}

/// The hazard checker of one run.
#[derive(Debug)]
pub struct Truth {
    vehicle: VehicleConfig,
    footprint: Footprint,
    /// Feature index and why it is a hazard.
    hazards: Vec<Option<String>>,
    in_contact: BTreeSet<usize>,
    tilted: bool,
    off_map: bool,
    /// The operating area, if the mission has one, and whether the
    /// footprint is beyond its edge.
    area: Option<Area>,
    off_area: bool,
    near: Vec<u32>,
    /// Every collision so far.
    pub collisions: Vec<Collision>,
    /// Smallest gap seen between the footprint and a hazard, m.
    pub closest_approach_m: f64,
    /// When and where it was, and to what.
    pub closest_at: Option<NearMiss>,
}

/// The moment of the smallest gap to a hazard.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NearMiss {
    pub utime: Utime,
    /// Vehicle origin then, world frame, m.
    pub position: [f64; 2],
    /// The hazard, e.g. "boulder 0.82 m tall".
    pub hazard: String,
    pub feature: usize,
}

impl Truth {
    pub fn new(world: &World, vehicle: &VehicleConfig, area: Option<&Area>) -> Self {
        Self {
            hazards: world.features.iter().map(|f| f.hazard(vehicle)).collect(),
            vehicle: vehicle.clone(),
            footprint: vehicle.footprint(),
            in_contact: BTreeSet::new(),
            tilted: false,
            off_map: false,
            area: area.cloned(),
            off_area: false,
            near: Vec::new(),
            collisions: Vec::new(),
            closest_approach_m: f64::INFINITY,
            closest_at: None,
        }
    }

    /// Checks the vehicle standing as `stance`; returns the collisions that
    /// start now.
    pub fn check(&mut self, world: &World, utime: Utime, stance: &Stance) -> &[Collision] {
        let before = self.collisions.len();
        let t = stance.world_from_vehicle.translation.vector;
        let (x, y) = (t.x, t.y);
        let yaw = yaw_of(&stance.world_from_vehicle);
        let (roll, pitch) = (stance.roll, stance.pitch);
        let (sin, cos) = yaw.sin_cos();
        let to_vehicle = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - x, p[1] - y);
            [cos * dx + sin * dy, -sin * dx + cos * dy]
        };
        let reach = self.footprint.reach() + 12.0;
        world.features_within([x - reach, y - reach, x + reach, y + reach], &mut self.near);
        let mut touching = BTreeSet::new();
        for &i in &self.near {
            let i = i as usize;
            let Some(why) = &self.hazards[i] else {
                continue;
            };
            let f: &Feature = &world.features[i];
            let gap =
                segment_box_distance(to_vehicle(f.a), to_vehicle(f.b), &self.footprint) - f.radius;
            if gap < self.closest_approach_m {
                self.closest_approach_m = gap.max(0.0);
                self.closest_at = Some(NearMiss {
                    utime,
                    position: [x, y],
                    hazard: why.clone(),
                    feature: i,
                });
            }
            if gap <= 0.0 {
                touching.insert(i);
                if !self.in_contact.contains(&i) {
                    self.collisions.push(Collision {
                        utime,
                        position: [x, y],
                        cause: why.clone(),
                        feature: Some(i),
                    });
                }
            }
        }
        self.in_contact = touching;
        let tilt = roll.abs().max(pitch.abs()).to_degrees();
        let tilted = tilt > self.vehicle.max_slope_deg;
        if tilted && !self.tilted {
            self.collisions.push(Collision {
                utime,
                position: [x, y],
                cause: format!(
                    "slope {tilt:.0}° (limit {:.0}°)",
                    self.vehicle.max_slope_deg
                ),
                feature: None,
            });
        }
        self.tilted = tilted;
        let off_map = !world.contains(x, y);
        if off_map && !self.off_map {
            self.collisions.push(Collision {
                utime,
                position: [x, y],
                cause: "left the map".into(),
                feature: None,
            });
        }
        self.off_map = off_map;
        if let Some(area) = &self.area {
            let off_area =
                self.footprint.outline().iter().any(|c| {
                    !area.contains([x + cos * c.x - sin * c.y, y + sin * c.x + cos * c.y])
                });
            if off_area && !self.off_area && !off_map {
                self.collisions.push(Collision {
                    utime,
                    position: [x, y],
                    cause: "left the operating area".into(),
                    feature: None,
                });
            }
            self.off_area = off_area;
        }
        &self.collisions[before..]
    }
}

/// Distance from the segment a–b to the footprint (0 if they meet), both
/// in the vehicle frame.
fn segment_box_distance(a: [f64; 2], b: [f64; 2], f: &Footprint) -> f64 {
    if !f.is_rectangle() {
        return f.distance_to_segment(a.into(), b.into());
    }
    let inside = |p: [f64; 2]| (f.x_min..=f.x_max).contains(&p[0]) && p[1].abs() <= f.half_width;
    if inside(a) || inside(b) {
        return 0.0;
    }
    let corners = [
        [f.x_min, -f.half_width],
        [f.x_max, -f.half_width],
        [f.x_max, f.half_width],
        [f.x_min, f.half_width],
    ];
    let point_box = |p: [f64; 2]| {
        let dx = (f.x_min - p[0]).max(0.0).max(p[0] - f.x_max);
        let dy = (p[1].abs() - f.half_width).max(0.0);
        dx.hypot(dy)
    };
    let mut best = point_box(a).min(point_box(b));
    for k in 0..4 {
        let (c, d) = (corners[k], corners[(k + 1) % 4]);
        if segments_cross(a, b, c, d) {
            return 0.0;
        }
        best = best.min(crate::world::segment_distance(c, a, b));
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_box_distances() {
        let f = Footprint::rectangle(-1.0, 4.0, 1.0);
        assert_eq!(segment_box_distance([6.0, 0.0], [6.0, 0.0], &f), 2.0);
        assert_eq!(
            segment_box_distance([2.0, 3.0], [2.0, -3.0], &f),
            0.0,
            "crosses the body"
        );
        assert!((segment_box_distance([5.0, 2.0], [5.0, 2.0], &f) - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(segment_box_distance([0.0, 0.0], [0.0, 0.0], &f), 0.0);
    }

    #[test]
    fn a_round_body_clears_what_stands_in_its_bounding_squares_corner() {
        use nalgebra::Point2;
        let round = Footprint::circle(Point2::new(1.5, 0.0), 1.5).unwrap();
        let square = Footprint::rectangle(round.x_min, round.x_max, round.half_width);
        // A post in the square's front left corner, 0.32 m off the circle.
        let post = [2.9, 1.4];
        let gap = segment_box_distance(post, post, &round);
        assert!((gap - (1.4f64.hypot(1.4) - 1.5)).abs() < 0.01, "{gap}");
        assert_eq!(segment_box_distance(post, post, &square), 0.0);
        // A trunk lying across the body's middle touches both.
        assert_eq!(segment_box_distance([1.5, -3.0], [1.5, 3.0], &round), 0.0);
    }
}
