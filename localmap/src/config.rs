//! `[localmap]`: the window, the patches, pruning and pose-jump handling.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// What to do when the pose jumps or time runs backwards.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JumpPolicy {
    /// Forget every cell (their positions relative to the vehicle are no
    /// longer known) and continue from the new pose.
    Reset,
    /// Ignore the pose and keep the map as it is.
    Reject,
}

/// Lives in `[localmap]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalMapConfig {
    /// Side of a map patch, m (002 §3: 40 cm).
    pub patch_size_m: f64,
    /// The window reaches this far ahead of the vehicle origin, m (002 §5: 20 m).
    pub ahead_m: f64,
    /// ... and this far to each side, m (002 §5: 10 m).
    pub half_width_m: f64,
    /// ... and this far behind the origin, m (the paper's window starts at
    /// 0). Cells beside the vehicle in a tight turn are kept, and so is the
    /// ground the vehicle may have to back up over: ground that left the
    /// window is forgotten (cells and seen ground alike), so backing up
    /// goes at most this far, less the rear overhang, behind the farthest
    /// point reached.
    pub behind_m: f64,
    /// A cell is dropped after this many newer overlapping images of a
    /// sensor that reported it did not report it again (002 §5: 1).
    pub misses_to_drop: u32,
    /// Also let images of one sensor drop cells only other sensors reported.
    pub cross_sensor_pruning: bool,
    /// Consecutive poses further apart than this (plus what the vehicle's
    /// top speed explains) are a jump, m.
    pub max_pose_jump_m: f64,
    /// What a jump or time running backwards does.
    pub on_pose_jump: JumpPolicy,
    /// Ground within this distance of the vehicle's first pose (and of the
    /// pose after a reset) counts as seen: the vehicle stands there, and no
    /// sensor sees the ground right in front of the bumper, m.
    pub assume_seen_m: f64,
}

impl Default for LocalMapConfig {
    fn default() -> Self {
        Self {
            patch_size_m: 0.4,
            ahead_m: 20.0,
            half_width_m: 10.0,
            behind_m: 20.0,
            misses_to_drop: 1,
            cross_sensor_pruning: false,
            max_pose_jump_m: 2.0,
            on_pose_jump: JumpPolicy::Reset,
            assume_seen_m: 8.0,
        }
    }
}

impl LocalMapConfig {
    /// Keys relative to `[localmap]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("patch_size_m", self.patch_size_m, 0.05, 5.0)?;
        config::positive("ahead_m", self.ahead_m)?;
        config::positive("half_width_m", self.half_width_m)?;
        config::non_negative("behind_m", self.behind_m)?;
        config::positive("max_pose_jump_m", self.max_pose_jump_m)?;
        config::in_range("assume_seen_m", self.assume_seen_m, 0.0, 100.0)?;
        if self.misses_to_drop == 0 {
            return Err(ConfigError::new(
                "misses_to_drop",
                "is 0, must be at least 1",
            ));
        }
        let radius = self.radius_m();
        let cells = 2.0 * radius / self.patch_size_m;
        if cells > 8192.0 {
            return Err(ConfigError::new(
                "patch_size_m",
                format!(
                    "is {} m: the window needs {cells:.0} patches across, more than 8192 (use larger patches or a smaller window)",
                    self.patch_size_m
                ),
            ));
        }
        Ok(())
    }

    /// The farthest the window reaches from the vehicle origin, whatever
    /// the heading, m.
    pub fn radius_m(&self) -> f64 {
        self.ahead_m.max(self.behind_m).hypot(self.half_width_m)
    }

    /// True when a vehicle-frame position lies inside the window.
    pub fn in_window(&self, x: f64, y: f64) -> bool {
        (-self.behind_m..=self.ahead_m).contains(&x) && y.abs() <= self.half_width_m
    }
}
