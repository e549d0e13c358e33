//! `[sim]`: the simulated vehicle, sensor and mission rules.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// `threads` at most: every frame starts this many (100 000 aborted the
/// process, out of memory for their stacks).
const MAX_THREADS: usize = 1024;

/// What a collision does to the mission.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CollisionPolicy {
    /// The mission ends, failed.
    Stop,
    /// The vehicle drives on; collisions are counted.
    Continue,
}

/// Lives in `[sim]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Pose messages per second (the INS rate).
    pub pose_rate_hz: f64,
    /// Standard deviation of the range noise, m.
    pub range_noise_m: f64,
    /// Probability that a pixel returns nothing.
    pub dropout_probability: f64,
    /// Standard deviation of the position noise of reported poses, m.
    pub pose_noise_m: f64,
    /// Standard deviation of the heading noise of reported poses, degrees.
    pub heading_noise_deg: f64,
    /// Position drift of reported poses per metre driven (dead reckoning), m/m.
    pub drift_per_m: f64,
    pub on_collision: CollisionPolicy,
    /// The mission fails when it takes longer, s.
    pub time_limit_s: f64,
    /// The mission fails when the vehicle gets no nearer to its waypoint
    /// for this long while staying within `stuck_radius_m` of where it was
    /// when that began, s.
    pub stuck_after_s: f64,
    /// See `stuck_after_s`, m.
    pub stuck_radius_m: f64,
    /// Seed of the sensor and pose noise.
    pub seed: u64,
    /// Threads rendering range images and building terrain tiles (0: all cores).
    pub threads: usize,
    /// Rays are cast only this far beyond `perception.max_range_m` (returns
    /// perception would ignore are not rendered), m.
    pub render_margin_m: f64,
    /// 0: each range image is sent whole at its capture time. N: it is sent
    /// in slices of N lines as the sensor acquires them (002 §7's
    /// integrated mode, `range_slice_t`), each rendered where the vehicle
    /// is then — columns for a sensor spanning 180° or more (a rotating
    /// lidar; an Ouster sends 16 per packet), rows for a scanning one (the
    /// ERIM), highest beam first.
    pub slice_lines: usize,
    /// Render each whole image while the pipeline works on the one before,
    /// when the vehicle's path until it is due is fixed by then (one sensor,
    /// `vehicle.command_latency_s` at least its period). The mission is the
    /// same byte for byte; false renders each image when due, as missions
    /// run side by side (`arcnav sweep`) always do.
    pub render_ahead: bool,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            pose_rate_hz: 50.0,
            range_noise_m: 0.02,
            dropout_probability: 0.01,
            pose_noise_m: 0.0,
            heading_noise_deg: 0.0,
            drift_per_m: 0.0,
            on_collision: CollisionPolicy::Stop,
            time_limit_s: 1800.0,
            stuck_after_s: 90.0,
            stuck_radius_m: 15.0,
            seed: 1,
            threads: 0,
            render_margin_m: 5.0,
            slice_lines: 0,
            render_ahead: true,
        }
    }
}

impl SimConfig {
    /// Keys relative to `[sim]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("pose_rate_hz", self.pose_rate_hz, 1.0, 1000.0)?;
        config::non_negative("range_noise_m", self.range_noise_m)?;
        config::in_range("dropout_probability", self.dropout_probability, 0.0, 1.0)?;
        // Noise beyond these put reported poses kilometres (1e300 m) away:
        // the elevation layer's window overflowed its cell indices.
        config::in_range("pose_noise_m", self.pose_noise_m, 0.0, 100.0)?;
        config::in_range("heading_noise_deg", self.heading_noise_deg, 0.0, 180.0)?;
        config::in_range("drift_per_m", self.drift_per_m, 0.0, 1.0)?;
        config::positive("time_limit_s", self.time_limit_s)?;
        config::positive("stuck_after_s", self.stuck_after_s)?;
        config::positive("stuck_radius_m", self.stuck_radius_m)?;
        config::non_negative("render_margin_m", self.render_margin_m)?;
        if self.threads > MAX_THREADS {
            return Err(ConfigError::new(
                "threads",
                format!(
                    "is {}, must be 0 (all cores) to {MAX_THREADS}",
                    self.threads
                ),
            ));
        }
        Ok(())
    }

    /// Rendering threads to use.
    pub fn thread_count(&self) -> usize {
        if self.threads == 0 {
            std::thread::available_parallelism().map_or(1, |n| n.get())
        } else {
            self.threads
        }
    }
}
