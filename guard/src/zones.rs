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

/// Where the commanded path first meets enough hazards: the arc length to
/// the `min_points`-th nearest hazard the swept footprint touches, and
/// which point that is (its place in `points`), if any within `reach_m`.
/// `points` are in the vehicle's level frame (x forward); `reverse` drives
/// the arc backwards.
pub fn nearest_contact(
    footprint: Footprint,
    curvature: f64,
    reverse: bool,
    reach_m: f64,
    min_points: usize,
    points: impl Iterator<Item = Point2<f64>>,
) -> Option<(f64, usize)> {
    // Backing along an arc is driving the same arc forwards in the frame
    // mirrored front to back: the body mirrored too.
    let (footprint, mirror) = if reverse {
        (
            Footprint {
                x_min: -footprint.x_max,
                x_max: -footprint.x_min,
                half_width: footprint.half_width,
            },
            -1.0,
        )
    } else {
        (footprint, 1.0)
    };
    let swept = Arc::new(curvature).swept(footprint, reach_m);
    let bound = reach_m + footprint.x_max.max(-footprint.x_min) + footprint.half_width;
    let mut contacts: Vec<(f64, usize)> = points
        .map(|p| Point2::new(p.x * mirror, p.y))
        .enumerate()
        .filter(|(_, p)| p.coords.norm() <= bound)
        .filter_map(|(k, p)| Some((swept.first_contact(p)?, k)))
        .collect();
    if contacts.len() < min_points {
        return None;
    }
    let k = min_points - 1;
    contacts.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
    Some(contacts[k])
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

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
        let body = Footprint {
            x_min: -0.6,
            x_max: 4.0,
            half_width: 1.1,
        };
        let ahead: Vec<Point2<f64>> = (0..3)
            .map(|k| Point2::new(10.0 + k as f64 * 0.1, 0.3))
            .collect();
        // Straight on: the front (4 m) reaches 10 m after 6.
        let (s, k) = nearest_contact(body, 0.0, false, 20.0, 3, ahead.iter().copied()).unwrap();
        assert_relative_eq!(s, 6.2, epsilon = 1e-6);
        assert_eq!(k, 2);
        // Two points are not enough for three.
        assert!(nearest_contact(body, 0.0, false, 20.0, 3, ahead[..2].iter().copied()).is_none());
        // Turning hard left passes right of them... or well away.
        assert!(nearest_contact(body, 1.0 / 8.0, false, 20.0, 3, ahead.iter().copied()).is_none());
        // Backing up does not meet what is ahead, and meets what is behind.
        assert!(nearest_contact(body, 0.0, true, 20.0, 3, ahead.iter().copied()).is_none());
        let behind = ahead.iter().map(|p| Point2::new(-p.x, p.y));
        let (s, _) = nearest_contact(body, 0.0, true, 20.0, 3, behind).unwrap();
        // The rear (0.6 m) reaches 10 m after 9.4.
        assert_relative_eq!(s, 9.6, epsilon = 1e-6);
    }
}
