//! Perception's configuration (`[perception]`) and the evaluator registry.

use arcnav_vehicle::VehicleConfig;
use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

use std::collections::BTreeMap;

use crate::height_diff::config::HeightDiffConfig;
use crate::pca::config::PcaConfig;

/// Lives in `[perception]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// Which terrain evaluator classifies images, by its name in the
    /// [`crate::EvaluatorRegistry`] (built in: `cells`, `height_diff`, `pca`).
    pub evaluator: String,
    /// Returns closer than this are ignored (the vehicle's own body), m.
    pub min_range_m: f64,
    /// Returns beyond this are ignored, m.
    pub max_range_m: f64,
    /// Most vertices of the field-of-view polygon sent to the local map.
    pub fov_max_vertices: usize,
    /// Images of different sensors captured within this many seconds of
    /// each other are judged together, in one height map (000 §4.1's
    /// eight cameras), by an evaluator that builds one (`height_diff`);
    /// 0: each image on its own. See [`crate::TerrainEvaluator::evaluate_fused`].
    pub fuse_within_s: f64,
    /// The ground evaluated around the vehicle.
    pub region: RegionConfig,
    /// The per-cell classifier of 002 §4.
    pub cells: CellsConfig,
    /// The near edges of unseen ground (holes, trenches, ledges), found
    /// the same way whichever evaluator judges the ground that was seen.
    pub drop_off: DropOffConfig,
    /// Hole evidence accumulated over images, whichever evaluator judges
    /// each (see [`crate::evidence`]).
    pub evidence: EvidenceConfig,
    /// Multi-scale height differences (000 §4–5.1), `evaluator = "height_diff"`.
    pub height_diff: HeightDiffConfig,
    /// Hierarchical PCA and scan-line roughness (001 §3), `evaluator = "pca"`.
    pub pca: PcaConfig,
    /// The height measurements of the local map's elevation layer (004
    /// §III), taken from every image whichever evaluator judges it.
    pub heights: HeightsConfig,
    /// Range images arriving in slices (`range_slice_t`), judged as they
    /// arrive (002 §7's integrated mode).
    pub streaming: StreamingConfig,
    /// Tables of evaluators added to the registry by a program,
    /// `[perception.plugins.NAME]`.
    pub plugins: BTreeMap<String, toml::Table>,
}

/// The largest `fuse_within_s`: an image waits up to that long for the
/// images it is fused with (a ring's cameras are triggered together).
pub const MAX_FUSE_WITHIN_S: f64 = 0.5;

impl Default for PerceptionConfig {
    fn default() -> Self {
        Self {
            evaluator: "cells".into(),
            min_range_m: 0.5,
            max_range_m: 40.0,
            fov_max_vertices: 512,
            fuse_within_s: 0.0,
            region: RegionConfig::default(),
            cells: CellsConfig::default(),
            drop_off: DropOffConfig::default(),
            evidence: EvidenceConfig::default(),
            height_diff: HeightDiffConfig::default(),
            pca: PcaConfig::default(),
            heights: HeightsConfig::default(),
            streaming: StreamingConfig::default(),
            plugins: BTreeMap::new(),
        }
    }
}

/// Lives in `[perception.evidence]`: hole evidence accumulated over
/// images (see [`crate::evidence`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvidenceConfig {
    /// Accumulate returns over images and suspect the holes they show
    /// (reported as `[perception.drop_off]` suspected drop-offs, at
    /// `suspect_cost`).
    pub enabled: bool,
    /// Report the stretches of each image's columns that no return has
    /// verified as shadows (ground not seen: the speed governor slows
    /// before them), when the cruise speed needs it: resolving turns it
    /// off at or below `speed_bound.suspect_bound_mps`, from where one
    /// image suspects a hole in time.
    pub verify: bool,
    /// Within this horizontal distance of the sensor one image is certain
    /// to show a hole the wheels do not bridge (to suspect it at least):
    /// ground there is verified by that image, m (0: resolving sets it
    /// to `speed_bound.suspect_range_m`).
    pub verified_within_m: f64,
    /// World-aligned cell of the layer, m: a gap the wheels do not
    /// bridge must span several.
    pub cell_size_m: f64,
    /// How far the sensor travels, after a ray first passed over a cell,
    /// before the absence of a return there counts, m.
    pub settle_m: f64,
    /// Returns within this horizontal distance of the sensor are kept,
    /// m: beyond the region ahead, so that the ground there has settled
    /// by the time the vehicle nears it.
    pub reach_m: f64,
}

impl Default for EvidenceConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            verify: true,
            verified_within_m: 0.0,
            cell_size_m: 0.1,
            settle_m: 3.0,
            reach_m: 30.0,
        }
    }
}

/// The most cells on a side of the hole evidence's ring.
pub(crate) const MAX_EVIDENCE_SIDE: usize = 4096;

impl EvidenceConfig {
    /// Checks the keys (relative to `[perception.evidence]`), with the
    /// drop-off rule's gap it must resolve.
    pub fn validate(&self, drop_off: &DropOffConfig) -> Result<(), ConfigError> {
        config::in_range("cell_size_m", self.cell_size_m, 0.02, 1.0)?;
        config::in_range("settle_m", self.settle_m, 0.0, 100.0)?;
        config::in_range("reach_m", self.reach_m, 1.0, 500.0)?;
        config::in_range("verified_within_m", self.verified_within_m, 0.0, 500.0)?;
        if self.enabled && 3.0 * self.cell_size_m > drop_off.max_gap_m {
            return Err(ConfigError::new(
                "cell_size_m",
                format!(
                    "is {} m; a gap of drop_off.max_gap_m ({} m) must span at least three \
                     cells: use cells of at most {:.3} m",
                    self.cell_size_m,
                    drop_off.max_gap_m,
                    drop_off.max_gap_m / 3.0
                ),
            ));
        }
        if self.enabled && 2.0 * self.reach_m / self.cell_size_m + 8.0 > MAX_EVIDENCE_SIDE as f64 {
            return Err(ConfigError::new(
                "cell_size_m",
                format!(
                    "{} m cells out to reach_m ({} m) need a ring of more than \
                     {MAX_EVIDENCE_SIDE} cells a side: use larger cells or a shorter reach",
                    self.cell_size_m, self.reach_m
                ),
            ));
        }
        Ok(())
    }
}

/// Lives in `[perception.heights]`: the measurements of the elevation layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeightsConfig {
    /// Measure heights at all (false: the elevation layer stays empty and
    /// the `terrain` behaviour judges nothing).
    pub enabled: bool,
    /// World-aligned cell, m (the elevation layer's, see
    /// `[localmap.elevation]`).
    pub cell_size_m: f64,
    /// σ_r: the sensor's range noise, standard deviation, m.
    pub range_noise_m: f64,
    /// σ_θ: the error of the pose's roll and pitch, standard deviation,
    /// degrees.
    pub attitude_noise_deg: f64,
}

impl Default for HeightsConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            cell_size_m: 0.2,
            range_noise_m: 0.02,
            attitude_noise_deg: 0.1,
        }
    }
}

impl HeightsConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::positive("cell_size_m", self.cell_size_m)?;
        if self.cell_size_m < 0.05 {
            return Err(ConfigError::new(
                "cell_size_m",
                format!("is {}, must be at least 0.05 m", self.cell_size_m),
            ));
        }
        config::positive("range_noise_m", self.range_noise_m)?;
        config::non_negative("attitude_noise_deg", self.attitude_noise_deg)
    }

    /// σ_t² of a return at `range_m`.
    pub fn variance(&self, range_m: f32) -> f32 {
        let sigma_theta = self.attitude_noise_deg.to_radians() as f32;
        let r = self.range_noise_m as f32;
        r * r + (range_m * sigma_theta).powi(2)
    }
}

/// `[perception.streaming]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StreamingConfig {
    /// Blocks of columns: cells nearer than this wait for the frame's last
    /// slice; farther ones are reported as their columns arrive. Smaller
    /// costs more (every step evaluates `2·asin(R / near_m)` of sweep
    /// again), m.
    pub near_m: f64,
}

impl Default for StreamingConfig {
    fn default() -> Self {
        Self { near_m: 8.0 }
    }
}

impl StreamingConfig {
    /// Keys relative to `[perception.streaming]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("near_m", self.near_m, 1.0, 1000.0)
    }
}

/// Lives in `[perception.drop_off]`: where the returns of an image column
/// leave a stretch of ground unseen, the near edge of that stretch is
/// untraversable (reason `drop_off`) when the stretch is wider than the
/// vehicle rolls across and the ground beyond it is a hole's far side, falls
/// away more steeply than the tolerated slope, or is not seen at all. See
/// `cells/projection.rs` for the rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DropOffConfig {
    /// Detect drop-offs at all.
    pub enabled: bool,
    /// An unseen stretch at most this long is bridged, m (default: the
    /// vehicle's [`VehicleConfig::bridgeable_gap_m`], 0.77 m).
    pub max_gap_m: f64,
    /// δ0 of δ = δ0 + Δ·r (000 §4.2): the ground beyond the gap must lie at
    /// least this far below the near edge, m (default: the tolerated step;
    /// a smaller step down is driven).
    pub min_depth_m: f64,
    /// Δ of δ = δ0 + Δ·r: per metre of horizontal distance from the sensor,
    /// for the height error of far returns (beam divergence, pose), m/m.
    pub depth_per_m: f64,
    /// Range noise allowance when deciding that the ground beyond the gap
    /// rises as a wall (a hole's far side), m.
    pub noise_m: f64,
    /// Cost of a *suspected* drop-off (0: none are reported). From afar a
    /// hole shows only `w·H/R` of its far side, less than δ; a near edge
    /// whose gap, longer than `max_gap_m` along the vehicle's heading, dips
    /// at least `noise_m + Δ·r` under it, with the return beyond rising
    /// back at least halfway, may be a hole and is reported as
    /// graded ground of this cost with the reason drop-off. Obstacle
    /// avoidance slows for it to the speed at which a hole there will be
    /// flagged in time.
    pub suspect_cost: f64,
}

impl Default for DropOffConfig {
    fn default() -> Self {
        let vehicle = VehicleConfig::default();
        Self {
            enabled: true,
            max_gap_m: bridgeable_gap_m(&vehicle),
            min_depth_m: vehicle.tolerated_step_m,
            depth_per_m: 0.0025,
            noise_m: 0.05,
            suspect_cost: 0.5,
        }
    }
}

/// Lives in `[perception.region]`: only the ground inside this box around
/// the vehicle (in its gravity-aligned frame: x ahead, y left) is evaluated.
/// The local map drops at once what lies outside its window (002 §5), so
/// the default is that window (0-20 m ahead, ±10 m, 20 m behind) with 2 m
/// to spare.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionConfig {
    /// Ahead of the vehicle origin, m.
    pub ahead_m: f64,
    /// Behind the vehicle origin, m.
    pub behind_m: f64,
    /// To each side, m.
    pub half_width_m: f64,
}

impl Default for RegionConfig {
    fn default() -> Self {
        Self {
            ahead_m: 22.0,
            behind_m: 22.0,
            half_width_m: 12.0,
        }
    }
}

/// The cell classifier's grid: `cols × rows` cells of the level frame, the
/// first cell's corner at `origin`; `margin` cells along each edge stay
/// empty, so every neighbour a binned cell's window reaches exists.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GridShape {
    pub cols: usize,
    pub rows: usize,
    /// The vehicle origin's distance from the first cell's corner, in
    /// whole cells per axis: cell `i` spans `(i - corner) * cell` to
    /// `(i + 1 - corner) * cell`.
    pub corner: [f32; 2],
    pub margin: usize,
}

/// Lives in `[perception.cells]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CellsConfig {
    /// Grid cell size, m (002 §4: 20 cm).
    pub cell_size_m: f64,
    /// Criteria (a) and (b) are evaluated only with at least this many points (002 §4: 5).
    pub min_points: u32,
    /// (a) A cell whose points span more height than this is untraversable, m.
    pub max_height_variation_m: f64,
    /// (b) per cell at all. Off by default: what tilts the vehicle is the
    /// ground under its four wheels, predicted along every arc from the
    /// local map's elevation layer (`behaviours.obstacle_avoidance.terrain`,
    /// 004 §IV); judged per 0.6 m window, noise and small bumps on a 15-25°
    /// hillside push single cells past the limit and they become walls.
    /// Drop-offs still use `max_slope_deg` for ground falling away.
    pub slope: bool,
    /// (b) A cell whose fitted plane is steeper than this is untraversable, degrees.
    pub max_slope_deg: f64,
    /// (c) A height gap larger than this to a neighbouring cell is a discontinuity, m.
    pub max_discontinuity_m: f64,
    /// (b) is evaluated only when the points spread at least this much
    /// (standard deviation) across both horizontal axes, m.
    pub min_plane_spread_m: f64,
    /// (b) fits the plane to the points of this many cells square around the
    /// cell (odd; 1 = the cell alone, as in 002 §4). A single 20 cm cell
    /// straddling a tolerated 10 cm step fits a 27-37° plane; over 3×3 cells
    /// (0.6 m) a true slope keeps its angle and a small step does not.
    pub slope_window_cells: u32,
}

impl Default for CellsConfig {
    fn default() -> Self {
        let vehicle = VehicleConfig::default();
        Self {
            cell_size_m: 0.2,
            min_points: 5,
            max_height_variation_m: vehicle.tolerated_step_m,
            slope: false,
            max_slope_deg: vehicle.max_slope_deg,
            max_discontinuity_m: vehicle.tolerated_step_m,
            min_plane_spread_m: 0.03,
            slope_window_cells: 3,
        }
    }
}

impl PerceptionConfig {
    /// The cell classifier's grid: the region, widened to whole cells
    /// (cell edges lie on multiples of the cell size from the vehicle
    /// origin) and by the margin the slope window needs.
    pub(crate) fn grid(&self) -> GridShape {
        let margin = (self.cells.slope_window_cells / 2).max(1) as usize;
        GridShape::over(&self.region, self.cells.cell_size_m, margin)
    }

    /// Checks the keys every evaluator shares (the evaluator's own are
    /// checked by the registry, see [`PerceptionConfig::validate_for`]) and
    /// that no threshold lets pass terrain the vehicle cannot drive. Keys
    /// are relative to `[perception]`, except those of the vehicle named in
    /// messages.
    pub(crate) fn validate_shared(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        config::non_negative("min_range_m", self.min_range_m)?;
        config::positive("max_range_m", self.max_range_m)?;
        if self.min_range_m >= self.max_range_m {
            return Err(ConfigError::new(
                "min_range_m",
                format!(
                    "is {} m, must be below max_range_m ({} m)",
                    self.min_range_m, self.max_range_m
                ),
            ));
        }
        if !(6..=100_000).contains(&self.fov_max_vertices) {
            return Err(ConfigError::new(
                "fov_max_vertices",
                format!("is {}, must be 6 to 100000", self.fov_max_vertices),
            ));
        }
        config::non_negative("fuse_within_s", self.fuse_within_s)?;
        if self.fuse_within_s > MAX_FUSE_WITHIN_S {
            return Err(ConfigError::new(
                "fuse_within_s",
                format!(
                    "is {} s; images are fused within at most {MAX_FUSE_WITHIN_S} s (each waits \
                     that long on the pose clock for the others)",
                    self.fuse_within_s
                ),
            ));
        }
        let r = &self.region;
        config::positive("region.ahead_m", r.ahead_m)?;
        config::non_negative("region.behind_m", r.behind_m)?;
        config::positive("region.half_width_m", r.half_width_m)?;
        for (key, value) in [
            ("max_range_m", self.max_range_m),
            ("region.ahead_m", r.ahead_m),
            ("region.behind_m", r.behind_m),
            ("region.half_width_m", r.half_width_m),
        ] {
            if value > 500.0 {
                return Err(ConfigError::new(
                    key,
                    format!("is {value} m; at most 500 m is evaluated"),
                ));
            }
        }
        self.heights.validate().map_err(|e| e.within("heights"))?;
        self.streaming
            .validate()
            .map_err(|e| e.within("streaming"))?;
        // The sampler's world-aligned grid covers the region at any heading:
        // up to twice the region's area (a square region at 45°).
        let diagonal = (r.ahead_m + r.behind_m).hypot(2.0 * r.half_width_m);
        let side = diagonal / self.heights.cell_size_m + 2.0;
        if side * side > 2.0 * MAX_GRID_CELLS as f64 {
            return Err(ConfigError::new(
                "heights.cell_size_m",
                format!(
                    "{} m cells over the region need up to {:.0} cells; at most \
                     {}: use larger cells or a smaller region",
                    self.heights.cell_size_m,
                    side * side,
                    2 * MAX_GRID_CELLS
                ),
            ));
        }
        let c = &self.cells;
        config::in_range("cells.cell_size_m", c.cell_size_m, 0.02, 2.0)?;
        // Before the grid, which the window widens.
        if c.slope_window_cells.is_multiple_of(2) || c.slope_window_cells > 9 {
            return Err(ConfigError::new(
                "cells.slope_window_cells",
                format!("is {}, must be 1, 3, 5, 7 or 9", c.slope_window_cells),
            ));
        }
        // The classifier's grid holds 4 bytes a cell in each of its two parts.
        let grid = self.grid();
        let cells = grid.cols as f64 * grid.rows as f64;
        if cells > MAX_GRID_CELLS as f64 {
            return Err(ConfigError::new(
                "cells.cell_size_m",
                format!(
                    "{} m cells over the region need a {} x {} grid ({:.0} MiB); \
                     at most {MAX_GRID_CELLS} cells: use larger cells or a smaller region",
                    c.cell_size_m,
                    grid.cols,
                    grid.rows,
                    cells * 8.0 / f64::from(1 << 20)
                ),
            ));
        }
        if !(1..=1_000_000).contains(&c.min_points) {
            return Err(ConfigError::new(
                "cells.min_points",
                format!("is {}, must be 1 to 1000000", c.min_points),
            ));
        }
        config::positive("cells.max_height_variation_m", c.max_height_variation_m)?;
        config::in_range("cells.max_slope_deg", c.max_slope_deg, 0.1, 89.0)?;
        config::positive("cells.max_discontinuity_m", c.max_discontinuity_m)?;
        config::non_negative("cells.min_plane_spread_m", c.min_plane_spread_m)?;
        let d = &self.drop_off;
        config::positive("drop_off.max_gap_m", d.max_gap_m)?;
        config::positive("drop_off.min_depth_m", d.min_depth_m)?;
        config::in_range("drop_off.depth_per_m", d.depth_per_m, 0.0, 0.1)?;
        config::in_range("drop_off.noise_m", d.noise_m, 0.0, 1.0)?;
        config::in_range("drop_off.suspect_cost", d.suspect_cost, 0.0, 0.99)?;
        self.evidence
            .validate(d)
            .map_err(|e| e.within("evidence"))?;
        let too_lax = |key: &str, value: f64, vehicle_key: &str, limit: f64| {
            (value > limit).then(|| {
                ConfigError::new(
                    key,
                    format!(
                        "is {value}, more than vehicle.{vehicle_key} ({limit}): perception would pass terrain the vehicle cannot drive"
                    ),
                )
            })
        };
        let checks = [
            too_lax(
                "cells.max_height_variation_m",
                c.max_height_variation_m,
                "tolerated_step_m",
                vehicle.tolerated_step_m,
            ),
            too_lax(
                "cells.max_discontinuity_m",
                c.max_discontinuity_m,
                "tolerated_step_m",
                vehicle.tolerated_step_m,
            ),
            too_lax(
                "cells.max_slope_deg",
                c.max_slope_deg,
                "max_slope_deg",
                vehicle.max_slope_deg,
            ),
            too_lax(
                "drop_off.max_gap_m",
                d.max_gap_m,
                "wheel_radius_m and tolerated_step_m allow",
                bridgeable_gap_m(vehicle),
            ),
            too_lax(
                "drop_off.min_depth_m",
                d.min_depth_m,
                "tolerated_step_m",
                vehicle.tolerated_step_m,
            ),
        ];
        checks.into_iter().flatten().next().map_or(Ok(()), Err)
    }
}

/// The vehicle's bridgeable gap, rounded up to the centimetre
/// `config/default.toml` writes it with.
fn bridgeable_gap_m(vehicle: &VehicleConfig) -> f64 {
    (vehicle.bridgeable_gap_m() * 100.0).ceil() / 100.0
}

/// The most cells the classifier's grid may have (256 MiB of slots).
pub(crate) const MAX_GRID_CELLS: u64 = 1 << 25;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_derive_from_the_vehicle_and_are_valid() {
        let p = PerceptionConfig::default();
        assert_eq!(p.cells.cell_size_m, 0.2);
        assert_eq!(p.cells.min_points, 5);
        assert_eq!(p.cells.max_discontinuity_m, 0.2);
        p.validate_for(&VehicleConfig::default()).unwrap();
        assert_eq!(p.build_evaluator().unwrap().name(), "cells");
    }

    #[test]
    fn a_threshold_laxer_than_the_vehicle_is_refused() {
        let vehicle = VehicleConfig {
            tolerated_step_m: 0.15,
            ..Default::default()
        };
        let err = PerceptionConfig::default()
            .validate_for(&vehicle)
            .unwrap_err();
        assert_eq!(err.key, "cells.max_height_variation_m");
        assert!(
            err.reason.contains("vehicle.tolerated_step_m (0.15)"),
            "{err}"
        );
    }

    #[test]
    fn a_grid_too_large_for_memory_is_refused() {
        let mut p = PerceptionConfig {
            max_range_m: 500.0,
            region: RegionConfig {
                ahead_m: 500.0,
                behind_m: 500.0,
                half_width_m: 500.0,
            },
            ..Default::default()
        };
        p.validate_for(&VehicleConfig::default()).unwrap();
        p.cells.cell_size_m = 0.02;
        let err = p.validate_for(&VehicleConfig::default()).unwrap_err();
        assert_eq!(err.key, "cells.cell_size_m");
        assert!(
            err.reason.contains("need a 50002 x 50002 grid (19075 MiB)"),
            "{err}"
        );
    }

    #[test]
    fn counts_out_of_range_are_refused_by_their_own_key() {
        // A huge slope window had been reported as a grid too large for
        // `cells.cell_size_m`, which the user had not touched.
        let mut p = PerceptionConfig::default();
        p.cells.slope_window_cells = u32::MAX;
        let err = p.validate_for(&VehicleConfig::default()).unwrap_err();
        assert_eq!(err.key, "cells.slope_window_cells");
        let mut p = PerceptionConfig::default();
        p.cells.min_points = u32::MAX;
        let err = p.validate_for(&VehicleConfig::default()).unwrap_err();
        assert_eq!(err.key, "cells.min_points");
        assert!(err.reason.contains("must be 1 to 1000000"), "{err}");
    }

    #[test]
    fn an_unknown_evaluator_lists_the_known_ones() {
        let p = PerceptionConfig {
            evaluator: "magic".into(),
            ..Default::default()
        };
        let err = p.validate_for(&VehicleConfig::default()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "`evaluator`: \"magic\" is not a known evaluator (known: cells, height_diff, pca)"
        );
    }
}
