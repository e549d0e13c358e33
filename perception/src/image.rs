//! Range images as perception sees them.

use arcnav_vehicle::{Isometry, Utime};

/// Elevation per row and azimuth per column, radians, in the sensor frame
/// (elevation + up, azimuth + left, counter-clockwise from +x). The beam of
/// pixel (r, c) points along
/// `(cos el[r] cos az[c], cos el[r] sin az[c], sin el[r])`.
/// Any table works, uniform or not.
#[derive(Debug, Clone, PartialEq)]
pub struct BeamTable {
    pub elevation: Vec<f32>,
    pub azimuth: Vec<f32>,
}

impl BeamTable {
    /// `rows` elevations from `top` down to `bottom` and `cols` azimuths from
    /// `left` to `right` (all radians), evenly spaced, pixel centres.
    pub fn uniform(rows: usize, cols: usize, top: f64, bottom: f64, left: f64, right: f64) -> Self {
        let centres = |n: usize, from: f64, to: f64| -> Vec<f32> {
            let step = (to - from) / n as f64;
            (0..n)
                .map(|i| (from + (i as f64 + 0.5) * step) as f32)
                .collect()
        };
        Self {
            elevation: centres(rows, top, bottom),
            azimuth: centres(cols, left, right),
        }
    }

    pub fn rows(&self) -> usize {
        self.elevation.len()
    }

    /// Checks that the table has `values` pixels and finite angles.
    pub fn check(&self, values: usize) -> Result<(), ImageError> {
        let (rows, cols) = (self.rows(), self.cols());
        if rows.checked_mul(cols) != Some(values) {
            return Err(ImageError::ShapeMismatch { rows, cols, values });
        }
        for (table, angles) in [("elevation", &self.elevation), ("azimuth", &self.azimuth)] {
            if let Some(index) = angles.iter().position(|v| !v.is_finite()) {
                return Err(ImageError::BadBeamAngle { table, index });
            }
        }
        Ok(())
    }

    pub fn cols(&self) -> usize {
        self.azimuth.len()
    }

    /// Unit beam direction of pixel (r, c) in the sensor frame.
    pub fn direction(&self, row: usize, col: usize) -> Option<[f64; 3]> {
        let el = f64::from(*self.elevation.get(row)?);
        let az = f64::from(*self.azimuth.get(col)?);
        Some([el.cos() * az.cos(), el.cos() * az.sin(), el.sin()])
    }
}

/// One range image.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeImage {
    /// Capture time (start of the frame).
    pub utime: Utime,
    /// Sensor id.
    pub sensor: String,
    /// Sensor → vehicle (the mount).
    pub vehicle_from_sensor: Isometry,
    pub beams: BeamTable,
    /// Metres along each beam, row-major `rows × cols`; 0, negative, NaN or
    /// infinite = no return.
    pub range: Vec<f32>,
}

impl RangeImage {
    pub fn rows(&self) -> usize {
        self.beams.rows()
    }

    pub fn cols(&self) -> usize {
        self.beams.cols()
    }

    /// Checks that the table and the data agree.
    pub fn validate(&self) -> Result<(), ImageError> {
        self.beams.check(self.range.len())
    }
}

/// A range image that cannot be evaluated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageError {
    #[error("range image holds {values} values but its beam table is {rows} rows × {cols} columns")]
    ShapeMismatch {
        rows: usize,
        cols: usize,
        values: usize,
    },
    #[error("beam {table} angle {index} is not a finite number")]
    BadBeamAngle { table: &'static str, index: usize },
}
