//! The world file's tables (`docs/worlds.md`): what a world is written
//! as, before it is checked and built into a [`crate::World`].

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::numbers::MAX_MAGNITUDE;

/// The `[terrain]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TerrainSpec {
    /// South-west corner of the world, m.
    pub origin_m: [f64; 2],
    /// Extent east and north, m.
    pub size_m: [f64; 2],
    /// Seed of the procedural terrain.
    pub seed: u64,
    /// Height of the hills (peak to mean), m.
    pub hills_amplitude_m: f64,
    /// Distance between hilltops, m.
    pub hills_wavelength_m: f64,
    /// Height of the small-scale ground roughness, m.
    pub roughness_amplitude_m: f64,
    /// Scale of the roughness, m.
    pub roughness_wavelength_m: f64,
    /// A height file (`.npy` or `.asc`) replacing the procedural hills;
    /// relative paths are relative to the world file. Roughness is added.
    pub heightmap: Option<PathBuf>,
    /// Sample spacing of the height file, m (required for `.npy`).
    pub heightmap_resolution_m: Option<f64>,
    /// World position of the height file's south-west sample, m.
    pub heightmap_origin_m: Option<[f64; 2]>,
    /// Heights in the file are multiplied by this.
    pub heightmap_scale: f64,
}

impl Default for TerrainSpec {
    fn default() -> Self {
        Self {
            origin_m: [-100.0, -100.0],
            size_m: [200.0, 200.0],
            seed: 1,
            hills_amplitude_m: 2.0,
            hills_wavelength_m: 100.0,
            roughness_amplitude_m: 0.03,
            roughness_wavelength_m: 1.5,
            heightmap: None,
            heightmap_resolution_m: None,
            heightmap_origin_m: None,
            heightmap_scale: 1.0,
        }
    }
}

/// The `[start]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartSpec {
    pub position_m: [f64; 2],
    /// Heading, degrees counter-clockwise from east.
    #[serde(default)]
    pub heading_deg: f64,
}

/// A `[[waypoints]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaypointSpec {
    pub position_m: [f64; 2],
    /// Arrival radius, m (default: the goal-seeking behaviour's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
}

impl WaypointSpec {
    /// Why this is no waypoint (a position or radius that is not a finite
    /// number, a radius that is not positive), if it is not.
    pub fn problem(&self) -> Option<String> {
        if !self.position_m.iter().all(|v| v.is_finite()) {
            return Some(format!("position_m {:?} is not finite", self.position_m));
        }
        match self.radius_m {
            Some(r) if !(r.is_finite() && r > 0.0) => {
                Some(format!("radius_m {r} must be a positive number of metres"))
            }
            _ => None,
        }
    }
}

/// The first number of `spec` (its key, dotted, and value) that is not
/// finite or lies beyond [`MAX_MAGNITUDE`].
pub(crate) fn first_out_of_bounds(spec: &WorldSpec) -> Option<(String, f64)> {
    fn walk(value: &toml::Value, key: &str) -> Option<(String, f64)> {
        match value {
            toml::Value::Float(f) if !f.is_finite() || f.abs() > MAX_MAGNITUDE => {
                Some((key.to_owned(), *f))
            }
            toml::Value::Table(t) => t.iter().find_map(|(k, v)| {
                let key = if key.is_empty() {
                    k.clone()
                } else {
                    format!("{key}.{k}")
                };
                walk(v, &key)
            }),
            toml::Value::Array(a) => a
                .iter()
                .enumerate()
                .find_map(|(i, v)| walk(v, &format!("{key}[{i}]"))),
            _ => None,
        }
    }
    walk(&toml::Value::try_from(spec).ok()?, "")
}

/// Terrain wavelengths are at least this, m: `1e-300` made every height
/// NaN (and the vehicle "stuck" with no image placed). The height field's
/// cells are 0.1 m, so anything below 0.2 m is aliased noise already.
pub(crate) const MIN_WAVELENGTH_M: f64 = 0.01;

/// A round feature rising from the ground: boulder, tree trunk or bush.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoundSpec {
    pub position_m: [f64; 2],
    pub radius_m: f64,
    /// Height above the ground, m.
    pub height_m: f64,
}

/// A hole: a round pit with vertical walls.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HoleSpec {
    pub position_m: [f64; 2],
    pub radius_m: f64,
    pub depth_m: f64,
}

/// A ditch: a trench along a segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DitchSpec {
    pub from_m: [f64; 2],
    pub to_m: [f64; 2],
    pub width_m: f64,
    pub depth_m: f64,
}

/// A bank: an embankment along a segment with a flat top and steep sides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BankSpec {
    pub from_m: [f64; 2],
    pub to_m: [f64; 2],
    pub height_m: f64,
    pub top_width_m: f64,
    /// Steepness of its sides, degrees.
    pub slope_deg: f64,
}

/// Rubble: a strip of loose stones along a segment, each below a height:
/// rough ground the vehicle may drive over (when the stones stay under
/// `vehicle.tolerated_step_m`) but feels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RubbleSpec {
    pub from_m: [f64; 2],
    pub to_m: [f64; 2],
    pub width_m: f64,
    /// The tallest stone, m (stones are 50-100 % of it).
    pub height_m: f64,
}

/// Kinds of scattered features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScatterKind {
    Boulder,
    Tree,
    Bush,
    Hole,
}

/// A `[[scatter]]` entry: round features placed at random, reproducibly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScatterSpec {
    pub kind: ScatterKind,
    /// Attempts; placements too close to others are skipped.
    pub count: u32,
    pub seed: u64,
    /// Keep at least this much free ground between features, m.
    pub min_spacing_m: f64,
    /// Radius range, m.
    pub radius_m: [f64; 2],
    /// Height range (depth for holes), m.
    pub height_m: [f64; 2],
    /// Only within this distance of the route (start → waypoints), m.
    pub near_route_m: f64,
    /// Keep this far from waypoints and the start, m.
    #[serde(default = "default_clearance")]
    pub clear_of_waypoints_m: f64,
}

fn default_clearance() -> f64 {
    10.0
}

/// A world file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSpec {
    pub name: String,
    #[serde(default)]
    pub description: String,
    #[serde(default)]
    pub terrain: TerrainSpec,
    pub start: StartSpec,
    #[serde(default)]
    pub waypoints: Vec<WaypointSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub boulders: Vec<RoundSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub trees: Vec<RoundSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bushes: Vec<RoundSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub holes: Vec<HoleSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ditches: Vec<DitchSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub banks: Vec<BankSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rubble: Vec<RubbleSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scatter: Vec<ScatterSpec>,
    /// The operating area of the mission, a polygon `[[x, y], ...]` in
    /// world coordinates (`[mission] area = "world"`); none: the map less
    /// `[mission] area_margin_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area: Option<Vec<[f64; 2]>>,
}
