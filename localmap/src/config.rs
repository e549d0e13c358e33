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
    /// The ground between the vehicle's axles is remembered for this much
    /// travel, beyond the window: it bore the vehicle, so it counts as seen
    /// when it comes back into the window (backing out of a dead end the
    /// way the vehicle came in), m; 0: not remembered.
    pub driven_memory_m: f64,
    /// A cell is dropped after this many newer overlapping images of a
    /// sensor that reported it did not report it again (002 §5: 1; 2 by
    /// default: a 10 Hz lidar at 10 m/s looks again 1 m on, where its rows
    /// land elsewhere on a hole's edge, and flags it in one frame of two).
    pub misses_to_drop: u32,
    /// Also let images of one sensor drop cells only other sensors reported.
    pub cross_sensor_pruning: bool,
    /// An image that sees a cell from farther than this many times the
    /// nearest distance an image reported it from counts no miss (0: every
    /// overlapping image counts one, as in 002 §5). A hole shows its far
    /// wall `w·H/R` high to a sensor `H` up at `R`: flagged from 8 m, it is
    /// not there to see from 12, and a vehicle backing away from a ditch
    /// must not erase it.
    pub miss_range_factor: f64,
    /// A suspected drop-off (graded, reason drop-off), and a flagged one
    /// reported from within `drop_off_trust_factor` times this, count a
    /// miss only from an image taken within this distance of them, where
    /// the ray grazing a hole's edge flags it: images from farther,
    /// which flag a ditch's edge in one frame and not in the next, must
    /// not erase them
    /// (0: from any distance; the pipeline sets it from the sensor,
    /// `speed_bound.hole_grazed_m`), m.
    pub hole_range_m: f64,
    /// A drop-off flagged from within this many times `hole_range_m` is
    /// kept like a suspected one (see there); flagged only from farther,
    /// it is missed like any cell: far rows flag rough ground as often as
    /// holes (0: only suspected drop-offs are kept).
    pub drop_off_trust_factor: f64,
    /// Consecutive poses further apart than this (plus what the vehicle's
    /// top speed explains) are a jump, m.
    pub max_pose_jump_m: f64,
    /// What a jump or time running backwards does.
    pub on_pose_jump: JumpPolicy,
    /// Ground within this distance of the vehicle's first pose (and of the
    /// pose after a reset) counts as seen: the vehicle stands there, and no
    /// sensor sees the ground right in front of the bumper, m.
    pub assume_seen_m: f64,
    /// A static occupancy map of the area, merged with perception's cells.
    pub occupancy: OccupancyConfig,
    /// The elevation layer (004 §III).
    pub elevation: crate::elevation::ElevationConfig,
}

/// Lives in `[localmap.occupancy]`: a static 2-D occupancy map (001 §3.4)
/// whose occupied cells are obstacles wherever the window reaches them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OccupancyConfig {
    /// A ROS `map_server` YAML (its PGM beside it, `origin`, `resolution`,
    /// `negate` and `occupied_thresh` as map_server reads them) or a
    /// `.npy` 2-D array; empty: none. A relative path is taken from the
    /// configuration file's directory.
    pub file: String,
    /// `.npy` only: cell size, m.
    pub resolution_m: f64,
    /// `.npy` only: world x, y of the corner of cell [0, 0] and the grid's
    /// yaw (degrees); rows run along +y, columns along +x, as in a ROS
    /// `OccupancyGrid`.
    pub origin: [f64; 3],
    /// `.npy` only: a cell at or above this is occupied (values are
    /// occupancy probabilities 0-1, or percentages 0-100 with -1 unknown
    /// as in a ROS `OccupancyGrid`, told apart by their largest value).
    pub occupied_thresh: f64,
}

impl Default for OccupancyConfig {
    fn default() -> Self {
        Self {
            file: String::new(),
            resolution_m: 0.05,
            origin: [0.0, 0.0, 0.0],
            occupied_thresh: 0.65,
        }
    }
}

impl Default for LocalMapConfig {
    fn default() -> Self {
        Self {
            patch_size_m: 0.4,
            ahead_m: 20.0,
            half_width_m: 10.0,
            behind_m: 20.0,
            driven_memory_m: 100.0,
            misses_to_drop: 2,
            cross_sensor_pruning: false,
            miss_range_factor: 1.25,
            hole_range_m: 0.0,
            drop_off_trust_factor: 2.0,
            max_pose_jump_m: 2.0,
            on_pose_jump: JumpPolicy::Reset,
            assume_seen_m: 8.0,
            occupancy: OccupancyConfig::default(),
            elevation: crate::elevation::ElevationConfig::default(),
        }
    }
}

impl LocalMapConfig {
    /// Keys relative to `[localmap]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("patch_size_m", self.patch_size_m, 0.05, 5.0)?;
        self.elevation
            .validate()
            .map_err(|e| e.within("elevation"))?;
        config::positive("ahead_m", self.ahead_m)?;
        config::positive("half_width_m", self.half_width_m)?;
        config::non_negative("behind_m", self.behind_m)?;
        config::in_range("driven_memory_m", self.driven_memory_m, 0.0, 10_000.0)?;
        config::positive("max_pose_jump_m", self.max_pose_jump_m)?;
        if self.miss_range_factor != 0.0 {
            config::in_range("miss_range_factor", self.miss_range_factor, 1.0, 100.0)?;
        }
        config::in_range("assume_seen_m", self.assume_seen_m, 0.0, 100.0)?;
        config::in_range("hole_range_m", self.hole_range_m, 0.0, 1000.0)?;
        if self.drop_off_trust_factor != 0.0 {
            config::in_range(
                "drop_off_trust_factor",
                self.drop_off_trust_factor,
                1.0,
                100.0,
            )?;
        }
        let o = &self.occupancy;
        config::in_range("occupancy.resolution_m", o.resolution_m, 0.001, 100.0)?;
        config::in_range("occupancy.occupied_thresh", o.occupied_thresh, 0.0, 1.0)?;
        if o.origin.iter().any(|v| !v.is_finite()) {
            return Err(ConfigError::new(
                "occupancy.origin",
                "holds a value that is not finite",
            ));
        }
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
