//! The rendering hook: anything that answers ray queries can be seen by a
//! sensor model. Tests use the analytic scenes of [`crate::scene`]; the
//! simulator implements it for its worlds. One ray-casting path for both.

use nalgebra::{Point3, Vector3};

/// A scene that answers "how far along this ray is the first surface?".
pub trait RayCast: Sync {
    /// Distance from `origin` along the unit vector `direction` (world
    /// frame) to the first surface, if one lies within `max_range`.
    fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>, max_range: f64) -> Option<f64>;

    /// Casts rays from one origin, in order (a sensor's row): `out[k]` is
    /// the distance along `directions[k]`, NaN where nothing lies within
    /// `max_range`. A scene may use what neighbouring rays have in common;
    /// the answers are [`cast`](Self::cast)'s.
    fn cast_each(
        &self,
        origin: &Point3<f64>,
        directions: &[Vector3<f64>],
        max_range: f64,
        out: &mut [f32],
    ) {
        for (d, value) in directions.iter().zip(out) {
            *value = self
                .cast(origin, d, max_range)
                .map_or(f32::NAN, |t| t as f32);
        }
    }
}

impl<T: RayCast + ?Sized> RayCast for &T {
    fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>, max_range: f64) -> Option<f64> {
        (**self).cast(origin, direction, max_range)
    }

    fn cast_each(
        &self,
        origin: &Point3<f64>,
        directions: &[Vector3<f64>],
        max_range: f64,
        out: &mut [f32],
    ) {
        (**self).cast_each(origin, directions, max_range, out);
    }
}
