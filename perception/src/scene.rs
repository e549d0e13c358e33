//! Analytic scenes for tests, examples and benchmarks: terrain given as a
//! height function `z = h(x, y)` of the world position, which may jump
//! (steps, boxes, ditches). Rays are marched in small steps and the first
//! crossing is refined by bisection, so vertical faces are found where they
//! are, to well under a millimetre.

use nalgebra::{Point3, Vector3};

use crate::raycast::RayCast;

/// Terrain whose height at (x, y) is `height(x, y)`.
pub struct HeightFunction<F> {
    height: F,
    step_m: f64,
}

impl<F: Fn(f64, f64) -> f64 + Sync> HeightFunction<F> {
    /// Marches rays in 5 cm steps: features thinner than that may be missed.
    pub fn new(height: F) -> Self {
        Self {
            height,
            step_m: 0.05,
        }
    }

    /// Marches in `step_m` steps.
    pub fn with_step(height: F, step_m: f64) -> Self {
        Self { height, step_m }
    }

    fn below(&self, p: &Point3<f64>) -> bool {
        p.z <= (self.height)(p.x, p.y)
    }
}

impl<F: Fn(f64, f64) -> f64 + Sync> RayCast for HeightFunction<F> {
    fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>, max_range: f64) -> Option<f64> {
        if self.below(origin) {
            return None;
        }
        let mut previous = 0.0;
        let mut t = self.step_m;
        while previous < max_range {
            let t_clamped = t.min(max_range);
            if self.below(&(origin + direction * t_clamped)) {
                let (mut lo, mut hi) = (previous, t_clamped);
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if self.below(&(origin + direction * mid)) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                return Some(hi);
            }
            previous = t_clamped;
            t += self.step_m;
        }
        None
    }
}

/// Rolling ground with ridges, scattered 40-80 cm rocks every 6 m or so
/// and a 1.2 m wide, 0.8 m deep ditch 25 m away on either side: the scene
/// the benchmarks time evaluators on.
pub fn rough_ground(x: f64, y: f64) -> f64 {
    let ground = 0.35 * (0.21 * x).sin() * (0.17 * y).cos() + 0.06 * (1.3 * x + 0.7 * y).sin();
    let (cx, cy) = ((x / 6.0).round() * 6.0, (y / 6.0).round() * 6.0);
    let hash = ((cx * 12.9898 + cy * 78.233).sin() * 43_758.545)
        .fract()
        .abs();
    let rock = if hash > 0.6 && (x - cx).hypot(y - cy) < 0.8 {
        0.4 + 0.4 * hash
    } else {
        0.0
    };
    let ditch = if (25.0..26.2).contains(&x.abs()) {
        -0.8
    } else {
        0.0
    };
    ground + rock + ditch
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn a_ray_down_onto_flat_ground_hits_at_the_height() {
        let ground = HeightFunction::new(|_, _| 0.0);
        let d = ground.cast(
            &Point3::new(0.0, 0.0, 2.0),
            &Vector3::new(0.0, 0.0, -1.0),
            10.0,
        );
        assert_relative_eq!(d.unwrap(), 2.0, epsilon = 1e-9);
        assert_eq!(
            ground.cast(
                &Point3::new(0.0, 0.0, 2.0),
                &Vector3::new(1.0, 0.0, 0.0),
                10.0
            ),
            None
        );
    }

    #[test]
    fn a_vertical_face_is_found_where_it_is() {
        let wall = HeightFunction::new(|x, _| if x >= 5.0 { 1.0 } else { 0.0 });
        let d = wall.cast(
            &Point3::new(0.0, 0.0, 0.5),
            &Vector3::new(1.0, 0.0, 0.0),
            10.0,
        );
        assert_relative_eq!(d.unwrap(), 5.0, epsilon = 1e-9);
    }
}
