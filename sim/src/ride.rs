//! What the ground did to the vehicle (ground truth for `report.json`):
//! the peak roll and pitch it stood at, and the vertical acceleration of
//! its body.
//!
//! The body's height is the mean of the four wheel contacts; its vertical
//! acceleration is the second difference of that height over
//! [`RIDE_STEP_S`] (tyres and suspension smooth what is quicker: without
//! the step a 10 cm stone at 50 Hz would read as 250 m/s²).

use arcnav_vehicle::Utime;
use arcnav_vehicle::time::micros_to_seconds;
use serde::Serialize;

use crate::drape::Stance;

/// The spacing of the height samples the vertical acceleration is taken
/// from, s.
pub const RIDE_STEP_S: f64 = 0.1;

/// Peaks of the ride, for the mission report.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RideReport {
    /// The vehicle's slope limit (`vehicle.max_slope_deg`), degrees.
    pub slope_limit_deg: f64,
    /// Largest |roll| the vehicle stood at, degrees, and when (s from the
    /// start) and where.
    pub peak_roll_deg: f64,
    pub peak_roll_at_s: f64,
    pub peak_roll_position: [f64; 2],
    /// Largest |pitch|, degrees, when and where.
    pub peak_pitch_deg: f64,
    pub peak_pitch_at_s: f64,
    pub peak_pitch_position: [f64; 2],
    /// Largest |vertical acceleration| of the body, m/s², when and where.
    pub peak_vertical_accel_mps2: f64,
    pub peak_vertical_accel_at_s: f64,
    pub peak_vertical_accel_position: [f64; 2],
    /// Root mean square of the vertical acceleration over the mission, m/s².
    pub rms_vertical_accel_mps2: f64,
}

/// Follows the vehicle's stance through a mission.
#[derive(Debug, Clone, Default)]
pub struct Ride {
    start: Utime,
    report: RideReport,
    /// The last two body heights sampled RIDE_STEP_S apart, and the time
    /// of the newer.
    heights: Option<(f64, Option<f64>, Utime)>,
    sum_squares: f64,
    samples: u64,
}

impl Ride {
    /// A ride starting at `start` of a vehicle that tips beyond
    /// `slope_limit_deg`.
    pub fn new(start: Utime, slope_limit_deg: f64) -> Self {
        Self {
            start,
            report: RideReport {
                slope_limit_deg,
                ..RideReport::default()
            },
            ..Self::default()
        }
    }

    /// The vehicle standing as `stance` at `utime`.
    pub fn observe(&mut self, utime: Utime, stance: &Stance) {
        let at = micros_to_seconds(utime - self.start);
        let t = stance.world_from_vehicle.translation.vector;
        let position = [t.x, t.y];
        let r = &mut self.report;
        let (roll, pitch) = (
            stance.roll.abs().to_degrees(),
            stance.pitch.abs().to_degrees(),
        );
        if roll > r.peak_roll_deg {
            (r.peak_roll_deg, r.peak_roll_at_s, r.peak_roll_position) = (roll, at, position);
        }
        if pitch > r.peak_pitch_deg {
            (r.peak_pitch_deg, r.peak_pitch_at_s, r.peak_pitch_position) = (pitch, at, position);
        }
        let step = arcnav_vehicle::time::seconds_to_micros(RIDE_STEP_S);
        match self.heights {
            None => self.heights = Some((stance.centre_z, None, utime)),
            Some((newest, older, when)) if utime - when >= step => {
                if let Some(oldest) = older {
                    let accel =
                        (stance.centre_z - 2.0 * newest + oldest) / (RIDE_STEP_S * RIDE_STEP_S);
                    self.sum_squares += accel * accel;
                    self.samples += 1;
                    if accel.abs() > r.peak_vertical_accel_mps2 {
                        r.peak_vertical_accel_mps2 = accel.abs();
                        r.peak_vertical_accel_at_s = at;
                        r.peak_vertical_accel_position = position;
                    }
                }
                self.heights = Some((stance.centre_z, Some(newest), utime));
            }
            Some(_) => {}
        }
    }

    pub fn report(&self) -> RideReport {
        RideReport {
            rms_vertical_accel_mps2: if self.samples > 0 {
                (self.sum_squares / self.samples as f64).sqrt()
            } else {
                0.0
            },
            ..self.report
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::planar_isometry;

    fn stance(x: f64, z: f64, roll: f64) -> Stance {
        Stance {
            world_from_vehicle: planar_isometry(x, 0.0, 0.0),
            roll,
            pitch: 0.0,
            centre_z: z,
        }
    }

    #[test]
    fn a_bump_of_known_curvature_gives_its_acceleration_and_the_peaks_their_place() {
        // z = 0.5·a·t² with a = 2 m/s² for 1 s, sampled at 50 Hz.
        let mut ride = Ride::new(0, 25.0);
        for tick in 0..=50 {
            let t = f64::from(tick) * 0.02;
            let roll = if tick == 20 { -0.3 } else { 0.1 };
            ride.observe((t * 1e6) as Utime, &stance(t, t * t, roll));
        }
        let r = ride.report();
        assert!((r.peak_vertical_accel_mps2 - 2.0).abs() < 1e-6, "{r:?}");
        assert!((r.rms_vertical_accel_mps2 - 2.0).abs() < 1e-6, "{r:?}");
        assert!((r.peak_roll_deg - 0.3f64.to_degrees()).abs() < 1e-9);
        assert!(
            (r.peak_roll_at_s - 0.4).abs() < 1e-9 && (r.peak_roll_position[0] - 0.4).abs() < 1e-9
        );
    }
}
