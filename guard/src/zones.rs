//! The stop and slow zones around a command's path, and the speed a hazard
//! on it allows.
//!
//! A vehicle at speed `v` with command latency `L` and braking deceleration
//! `a` stops within
//!
//! ```text
//! d(v) = v·L + v² / (2a)
//! ```
//!
//! so a hazard first touched `s` along the commanded arc (by the body's
//! swept footprint, widened by `side_margin_m`) leaves room for
//!
//! ```text
//! v_allowed(s) = a·(−L + sqrt(L² + 2·(s − margin)/a))     (d(v_allowed) = s − margin)
//! ```
//!
//! The **stop** zone is `s − margin ≤ d(v_now)`: braking now is all that is
//! left. The **slow** zone is the rest of the arc as far as `d(v_max) +
//! margin`: the command's speed is capped to `v_allowed(s)`, so that the
//! stop zone is never entered at speed. One formula, both zones.

use arcnav_vehicle::DrivenPath;
use arcnav_vehicle::arcs::Arc;
use arcnav_vehicle::model::{Footprint, VehicleConfig};
use nalgebra::Point2;

/// What the zones need of the vehicle.
#[derive(Debug, Clone, Copy)]
pub struct Braking {
    pub latency_s: f64,
    pub deceleration_mps2: f64,
    pub max_speed_mps: f64,
    pub margin_m: f64,
}

impl Braking {
    pub fn of(vehicle: &VehicleConfig, margin_m: f64) -> Self {
        Self {
            latency_s: vehicle.command_latency_s,
            deceleration_mps2: vehicle.max_deceleration_mps2,
            max_speed_mps: vehicle.max_speed_mps,
            margin_m,
        }
    }

    /// `d(v)`: the distance to stop from `v`, m.
    pub fn stopping_m(&self, v: f64) -> f64 {
        let v = v.abs();
        v * self.latency_s + v * v / (2.0 * self.deceleration_mps2)
    }

    /// `v_allowed(s)`: the speed that stops `margin_m` short of a hazard
    /// `s` ahead, m/s (0 within the margin).
    pub fn allowed_mps(&self, s: f64) -> f64 {
        let room = s - self.margin_m;
        if room <= 0.0 {
            return 0.0;
        }
        let (l, a) = (self.latency_s, self.deceleration_mps2);
        a * (-l + (l * l + 2.0 * room / a).sqrt())
    }

    /// How far along a path the zones reach: the slow zone's end, m.
    pub fn reach_m(&self) -> f64 {
        self.stopping_m(self.max_speed_mps) + self.margin_m
    }
}

/// Poses along the curvature ramp are tried this far apart, m (a cell
/// is 0.2 m).
const RAMP_STEP_M: f64 = 0.1;

/// Where the path the vehicle drives first meets a hazard: the distance
/// along it at which the swept footprint first touches one of `points`,
/// and which point that is (its place in `points`), if any within
/// `reach_m`. `points` are in the vehicle's level frame (x forward).
/// Forwards the path is [`DrivenPath`]: the command's arc reached through
/// the vehicle's latency and steering rate, as the behaviours judge it
/// (along the ramp the footprint is tried every 0.1 m, along the arc the
/// contact is exact). `reverse` drives the arc backwards (at the speeds
/// the vehicle backs, at once).
pub fn nearest_contact(
    footprint: Footprint,
    path: &DrivenPath,
    reverse: bool,
    reach_m: f64,
    points: impl Iterator<Item = Point2<f64>>,
) -> Option<(f64, usize)> {
    // Backing along an arc is driving the same arc forwards in the frame
    // mirrored front to back: the body mirrored too.
    let (footprint, mirror, path) = if reverse {
        let arc = DrivenPath::arc(path.curvature_at(path.settled_at()));
        (footprint.mirrored(), -1.0, arc)
    } else {
        (footprint, 1.0, *path)
    };
    let settled = path.settled_at().min(reach_m);
    let from = path.pose_at(settled);
    let (sin, cos) = from.heading.sin_cos();
    let arc = Arc::new(path.curvature_at(settled)).swept(footprint, reach_m - settled);
    let ramp: Vec<(f64, Point2<f64>, f64, f64)> = if settled > 0.0 {
        path.sample(settled, RAMP_STEP_M)
            .into_iter()
            .map(|(s, pose)| {
                let (sin, cos) = pose.heading.sin_cos();
                (s, pose.position, sin, cos)
            })
            .collect()
    } else {
        Vec::new()
    };
    let bound = reach_m + footprint.x_max.max(-footprint.x_min) + footprint.half_width;
    let mut nearest: Option<(f64, usize)> = None;
    for (k, p) in points.enumerate() {
        let p = Point2::new(p.x * mirror, p.y);
        if p.coords.norm() > bound {
            continue;
        }
        let on_ramp = ramp.iter().find_map(|&(s, at, sin, cos)| {
            let d = p - at;
            let local = Point2::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y);
            footprint.contains(local).then_some(s)
        });
        let s = on_ramp.or_else(|| {
            let d = p - from.position;
            let local = Point2::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y);
            arc.first_contact(local).map(|s| settled + s)
        });
        if let Some(s) = s
            && nearest.is_none_or(|(best, _)| s < best)
        {
            nearest = Some((s, k));
        }
    }
    nearest
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use arcnav_vehicle::{Steering, SteeringResponse};

    fn braking() -> Braking {
        Braking {
            latency_s: 0.25,
            deceleration_mps2: 3.0,
            max_speed_mps: 10.0,
            margin_m: 1.0,
        }
    }

    #[test]
    fn the_allowed_speed_stops_exactly_the_margin_short() {
        let b = braking();
        for s in [1.5, 4.0, 10.0, 25.0] {
            let v = b.allowed_mps(s);
            assert_relative_eq!(b.stopping_m(v), s - b.margin_m, epsilon = 1e-9);
        }
        assert_eq!(b.allowed_mps(0.5), 0.0);
        // 10 m/s stops in 2.5 + 16.7 m.
        assert_relative_eq!(b.reach_m(), 2.5 + 100.0 / 6.0 + 1.0, epsilon = 1e-9);
    }

    #[test]
    fn only_points_on_the_path_count_and_reversing_looks_behind() {
        let body = Footprint::rectangle(-0.6, 4.0, 1.1);
        let ahead = [Point2::new(10.2, 0.3), Point2::new(10.0, 0.3)];
        let straight = DrivenPath::arc(0.0);
        // Straight on: the front (4 m) reaches 10 m after 6.
        let (s, k) = nearest_contact(body, &straight, false, 20.0, ahead.into_iter()).unwrap();
        assert_relative_eq!(s, 6.0, epsilon = 1e-6);
        assert_eq!(k, 1);
        // Not within the reach.
        assert!(nearest_contact(body, &straight, false, 5.0, ahead.into_iter()).is_none());
        // Turning hard left passes well away.
        let left = DrivenPath::arc(1.0 / 8.0);
        assert!(nearest_contact(body, &left, false, 20.0, ahead.into_iter()).is_none());
        // Backing up does not meet what is ahead, and meets what is behind.
        assert!(nearest_contact(body, &straight, true, 20.0, ahead.into_iter()).is_none());
        let behind = ahead.iter().map(|p| Point2::new(-p.x, p.y));
        let (s, _) = nearest_contact(body, &straight, true, 20.0, behind).unwrap();
        // The rear (0.6 m) reaches 10 m after 9.4.
        assert_relative_eq!(s, 9.4, epsilon = 1e-6);
    }

    #[test]
    fn at_speed_the_path_is_the_arc_reached_through_latency_and_steering_rate() {
        let vehicle = VehicleConfig::default();
        let body = vehicle.footprint();
        // Driving straight at 8 m/s, commanded hard left: 0.25 s latency
        // (2 m) straight on, then the curvature ramps at 0.15/s, 0.019/m.
        let steering = Steering {
            speed_mps: 8.0,
            curvature: 0.0,
            commanded_curvature: 0.0,
        };
        let k = vehicle.max_curvature();
        let path = DrivenPath::new(&steering, &SteeringResponse::of(&vehicle), k);
        assert!(path.settled_at() > 5.0, "{}", path.settled_at());
        // A point 8 m ahead, 1.3 m left, that the arc taken at once would
        // pass left of (its inner side), is met by the path driven.
        let point = [Point2::new(8.0, 1.3)];
        assert!(
            nearest_contact(body, &DrivenPath::arc(k), false, 20.0, point.into_iter()).is_none()
        );
        let (s, _) = nearest_contact(body, &path, false, 20.0, point.into_iter()).unwrap();
        assert!((3.0..6.0).contains(&s), "{s}");
    }
}
