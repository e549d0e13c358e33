//! Simulated worlds: terrain (procedural hills and roughness, or a height
//! file), discrete features (boulders, tree trunks and bushes as vertical
//! obstacles; ditches and holes as negative ones; steep banks), the start
//! pose and the waypoints. Written in TOML (see `docs/worlds.md`), embedded
//! (`World::embedded`), or generated from a seed (`crate::generate`).
//!
//! The world's height at (x, y) is the terrain's plus every feature's
//! contribution, so a rock on a hillside sits on the hill.

use std::path::{Path, PathBuf};

use arcnav_vehicle::VehicleConfig;
use arcnav_vehicle::config::toml_location;
use arcnav_vehicle::mission::Area;
use serde::Serialize;

use crate::heightmap::{HeightGrid, HeightmapError};
use crate::noise::Noise;
use crate::numbers::{MAX_MAGNITUDE, floor};
use crate::rng::Rng;
pub use crate::spec::{
    BankSpec, DitchSpec, HoleSpec, RoundSpec, RubbleSpec, ScatterKind, ScatterSpec, StartSpec,
    TerrainSpec, WaypointSpec, WorldSpec,
};
use crate::spec::{MIN_WAVELENGTH_M, first_out_of_bounds};

/// A world that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldError {
    #[error("cannot read world file {path}: {reason}")]
    Read { path: PathBuf, reason: String },
    #[error("{origin}{}{}: {message}", line.map(|l| format!(", line {l}")).unwrap_or_default(), key.as_ref().map(|k| format!(", `{k}`")).unwrap_or_default())]
    Parse {
        origin: String,
        line: Option<usize>,
        key: Option<String>,
        message: String,
    },
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
    #[error(transparent)]
    Heightmap(#[from] HeightmapError),
}

/// What a feature is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FeatureKind {
    Boulder,
    Tree,
    Bush,
    Hole,
    Ditch,
    Bank,
    Rubble,
}

impl FeatureKind {
    pub fn name(self) -> &'static str {
        match self {
            FeatureKind::Boulder => "boulder",
            FeatureKind::Tree => "tree",
            FeatureKind::Bush => "bush",
            FeatureKind::Hole => "hole",
            FeatureKind::Ditch => "ditch",
            FeatureKind::Bank => "bank",
            FeatureKind::Rubble => "rubble",
        }
    }
}

/// A feature of the built world. Its ground shape is a capsule: the set of
/// points within `radius` of the segment `a`–`b` (a disc when `a == b`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feature {
    pub kind: FeatureKind,
    pub a: [f64; 2],
    pub b: [f64; 2],
    /// Half-width of its ground shape, m.
    pub radius: f64,
    /// Height above ground (negative: depth), m.
    pub height: f64,
    /// Flat-top half-width (banks), m.
    pub top_half_width: f64,
    /// Side slope (banks), degrees.
    pub slope_deg: f64,
}

impl Feature {
    /// Distance from p to the feature's axis (segment).
    pub fn axis_distance(&self, p: [f64; 2]) -> f64 {
        segment_distance(p, self.a, self.b)
    }

    /// Distance from p to the feature's ground shape (0 inside).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        (self.axis_distance(p) - self.radius).max(0.0)
    }

    /// The height it adds at p.
    pub fn height_at(&self, p: [f64; 2]) -> f64 {
        let d = self.axis_distance(p);
        if d > self.radius {
            return 0.0;
        }
        let u = d / self.radius;
        match self.kind {
            FeatureKind::Boulder => self.height * (1.0 - u * u).max(0.0).sqrt(),
            FeatureKind::Tree | FeatureKind::Hole | FeatureKind::Ditch => self.height,
            FeatureKind::Bush => self.height * (1.0 - u.powi(8)).max(0.0).sqrt(),
            FeatureKind::Bank => {
                if d <= self.top_half_width {
                    self.height
                } else {
                    (self.height - (d - self.top_half_width) * self.slope_deg.to_radians().tan())
                        .max(0.0)
                }
            }
            FeatureKind::Rubble => self.height * stone(p),
        }
    }

    /// Whether the vehicle cannot drive over it, and why.
    pub fn hazard(&self, vehicle: &VehicleConfig) -> Option<String> {
        let step = vehicle.tolerated_step_m;
        match self.kind {
            FeatureKind::Tree | FeatureKind::Bush if self.height > step => {
                Some(format!("{} {:.1} m tall", self.kind.name(), self.height))
            }
            FeatureKind::Boulder if self.height > step => {
                Some(format!("boulder {:.2} m tall", self.height))
            }
            FeatureKind::Hole | FeatureKind::Ditch if -self.height > step => {
                Some(format!("{} {:.2} m deep", self.kind.name(), -self.height))
            }
            FeatureKind::Bank if self.slope_deg > vehicle.max_slope_deg && self.height > step => {
                Some(format!("bank sides of {:.0}°", self.slope_deg))
            }
            FeatureKind::Rubble if self.height > step => {
                Some(format!("rubble of stones up to {:.2} m", self.height))
            }
            _ => None,
        }
    }

    /// Bounding box (min x, min y, max x, max y).
    pub fn bounds(&self) -> [f64; 4] {
        [
            self.a[0].min(self.b[0]) - self.radius,
            self.a[1].min(self.b[1]) - self.radius,
            self.a[0].max(self.b[0]) + self.radius,
            self.a[1].max(self.b[1]) + self.radius,
        ]
    }
}

/// Rubble's stones at p, as a fraction of the tallest: domes 0.4 m across
/// on a jittered 0.5 m lattice, each 50-100 % tall (a hash of its lattice
/// cell, so the same everywhere it is asked).
fn stone(p: [f64; 2]) -> f64 {
    const SPACING: f64 = 0.5;
    const RADIUS: f64 = 0.2;
    let hash = |i: i64, j: i64, salt: u64| {
        let mut h = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (j as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ salt;
        h ^= h >> 31;
        h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 29;
        (h >> 11) as f64 / (1u64 << 53) as f64
    };
    let (ci, cj) = (floor(p[0] / SPACING), floor(p[1] / SPACING));
    let mut best: f64 = 0.0;
    for i in ci - 1..=ci + 1 {
        for j in cj - 1..=cj + 1 {
            let centre = [
                (i as f64 + 0.25 + 0.5 * hash(i, j, 1)) * SPACING,
                (j as f64 + 0.25 + 0.5 * hash(i, j, 2)) * SPACING,
            ];
            let d = (p[0] - centre[0]).hypot(p[1] - centre[1]) / RADIUS;
            if d < 1.0 {
                best = best.max((0.5 + 0.5 * hash(i, j, 3)) * (1.0 - d * d).sqrt());
            }
        }
    }
    best
}

pub use arcnav_vehicle::numbers::segment_distance;

#[derive(Debug, Clone)]
enum Base {
    Procedural {
        noise: Box<Noise>,
        amplitude: f64,
        wavelength: f64,
    },
    File {
        grid: HeightGrid,
        scale: f64,
    },
}

/// Features bucketed on a coarse grid for fast lookup by position.
#[derive(Debug, Clone)]
struct FeatureIndex {
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    buckets: Vec<Vec<u32>>,
}

impl FeatureIndex {
    const CELL_M: f64 = 8.0;

    fn new(bounds: [f64; 4], features: &[Feature]) -> Self {
        let cell = Self::CELL_M;
        let cols = (((bounds[2] - bounds[0]) / cell).ceil() as usize).max(1);
        let rows = (((bounds[3] - bounds[1]) / cell).ceil() as usize).max(1);
        let mut index = Self {
            origin: [bounds[0], bounds[1]],
            cell,
            cols,
            rows,
            buckets: vec![Vec::new(); cols * rows],
        };
        for (i, f) in features.iter().enumerate() {
            let b = f.bounds();
            let (c0, r0) = index.clamp_cell(b[0], b[1]);
            let (c1, r1) = index.clamp_cell(b[2], b[3]);
            for r in r0..=r1 {
                for c in c0..=c1 {
                    index.buckets[r * cols + c].push(i as u32);
                }
            }
        }
        index
    }

    fn clamp_cell(&self, x: f64, y: f64) -> (usize, usize) {
        let c = ((x - self.origin[0]) / self.cell)
            .floor()
            .clamp(0.0, (self.cols - 1) as f64) as usize;
        let r = ((y - self.origin[1]) / self.cell)
            .floor()
            .clamp(0.0, (self.rows - 1) as f64) as usize;
        (c, r)
    }

    /// Features whose bounds may contain p (p inside the indexed area).
    fn at(&self, x: f64, y: f64) -> &[u32] {
        let (c, r) = self.clamp_cell(x, y);
        &self.buckets[r * self.cols + c]
    }

    /// Features whose bounds may meet the box (deduplicated into `out`).
    fn within(&self, bounds: [f64; 4], out: &mut Vec<u32>) {
        out.clear();
        let (c0, r0) = self.clamp_cell(bounds[0], bounds[1]);
        let (c1, r1) = self.clamp_cell(bounds[2], bounds[3]);
        for r in r0..=r1 {
            for c in c0..=c1 {
                out.extend_from_slice(&self.buckets[r * self.cols + c]);
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}

/// A waypoint of the built world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldWaypoint {
    pub x: f64,
    pub y: f64,
    pub radius_m: Option<f64>,
}

/// A built world.
#[derive(Debug, Clone)]
pub struct World {
    pub spec: WorldSpec,
    base: Base,
    roughness: Noise,
    roughness_amplitude: f64,
    roughness_wavelength: f64,
    pub features: Vec<Feature>,
    index: FeatureIndex,
    /// (min x, min y, max x, max y), m.
    pub bounds: [f64; 4],
    /// Start position and heading (radians).
    pub start: ([f64; 2], f64),
    pub waypoints: Vec<WorldWaypoint>,
    /// The files this world was read from (the world file, its height
    /// file), each named by what it is: no output of a run may be one.
    pub files_read: Vec<(&'static str, PathBuf)>,
}

/// The worlds compiled into arcnav: name, description, TOML.
pub const EMBEDDED: [(&str, &str, &str); 4] = [
    (
        "paper_loop",
        "the paper's mission (002 §3): a 1 km loop through hills, rocks, trees, bushes, ditches and banks, 10 waypoints ~100 m apart",
        include_str!("../worlds/paper_loop.toml"),
    ),
    (
        "short_course",
        "a 150 m course with a boulder field, a ditch and a bank: a quick end-to-end run",
        include_str!("../worlds/short_course.toml"),
    ),
    (
        "open_field",
        "gentle open ground and three waypoints, no obstacles: a smoke test",
        include_str!("../worlds/open_field.toml"),
    ),
    (
        "drop_offs",
        "trenches, a pit and oblique ditches: negative obstacles seen as missing ground",
        include_str!("../worlds/drop_offs.toml"),
    ),
];

impl World {
    /// An embedded world by name (see [`EMBEDDED`]).
    pub fn embedded(name: &str) -> Option<Result<World, WorldError>> {
        EMBEDDED
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|(n, _, text)| World::from_toml(text, &format!("embedded world {n}"), None))
    }

    /// Reads a world file; height files are found relative to it.
    pub fn load(path: &Path) -> Result<World, WorldError> {
        let text = arcnav_vehicle::files::read_text(path).map_err(|e| WorldError::Read {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
        let mut world = World::from_toml(&text, &path.display().to_string(), path.parent())?;
        world
            .files_read
            .insert(0, ("the world file", path.to_owned()));
        Ok(world)
    }

    /// Parses and builds a world; `origin` names it in messages.
    pub fn from_toml(
        text: &str,
        origin: &str,
        base_dir: Option<&Path>,
    ) -> Result<World, WorldError> {
        let spec: WorldSpec = toml::from_str(text).map_err(|err| {
            let (line, key) = err
                .span()
                .map(|s| toml_location(text, s.start))
                .unwrap_or((None, None));
            WorldError::Parse {
                origin: origin.to_owned(),
                line,
                key,
                message: err.message().to_owned(),
            }
        })?;
        World::build(spec, origin, base_dir)
    }

    /// Builds a world from its spec (scatter expanded, height file loaded).
    pub fn build(
        spec: WorldSpec,
        origin: &str,
        base_dir: Option<&Path>,
    ) -> Result<World, WorldError> {
        let invalid = |message: String| WorldError::Invalid {
            origin: origin.to_owned(),
            message,
        };
        if let Some((key, value)) = first_out_of_bounds(&spec) {
            return Err(invalid(if value.is_finite() {
                format!("{key} is {value:?}: numbers in a world lie within ±{MAX_MAGNITUDE}")
            } else {
                format!("{key} is not a finite number")
            }));
        }
        let t = &spec.terrain;
        if !(t.size_m[0] > 0.0
            && t.size_m[1] > 0.0
            && t.size_m[0].is_finite()
            && t.size_m[1].is_finite())
        {
            return Err(invalid(format!(
                "terrain.size_m {:?} must be two positive sizes",
                t.size_m
            )));
        }
        if t.size_m[0] * t.size_m[1] > 25e6 {
            return Err(invalid(format!(
                "terrain.size_m {:?}: at most 25 km² are supported",
                t.size_m
            )));
        }
        for (key, wavelength) in [
            ("hills_wavelength_m", t.hills_wavelength_m),
            ("roughness_wavelength_m", t.roughness_wavelength_m),
        ] {
            if wavelength < MIN_WAVELENGTH_M {
                return Err(invalid(format!(
                    "terrain.{key} is {wavelength:?}: terrain wavelengths are at least \
                     {MIN_WAVELENGTH_M} m (the height field's cells are 0.1 m)"
                )));
            }
        }
        let bounds = [
            t.origin_m[0],
            t.origin_m[1],
            t.origin_m[0] + t.size_m[0],
            t.origin_m[1] + t.size_m[1],
        ];
        let mut files_read = Vec::new();
        let base = match &t.heightmap {
            Some(file) => {
                let path = match base_dir {
                    Some(dir) if file.is_relative() => dir.join(file),
                    _ => file.clone(),
                };
                let grid = HeightGrid::load(&path, t.heightmap_resolution_m, t.heightmap_origin_m)?;
                let g = grid.bounds();
                let overlap = |lo: f64, hi: f64, a: f64, b: f64| (hi.min(b) - lo.max(a)).max(0.0);
                let covered = overlap(g[0], g[2], bounds[0], bounds[2])
                    * overlap(g[1], g[3], bounds[1], bounds[3]);
                if covered < 0.5 * t.size_m[0] * t.size_m[1] {
                    return Err(invalid(format!(
                        "the height file {} covers {:.3} m × {:.3} m from ({}, {}), less than half of the {} m × {} m world: is heightmap_resolution_m (or its origin) right?",
                        path.display(),
                        g[2] - g[0],
                        g[3] - g[1],
                        g[0],
                        g[1],
                        t.size_m[0],
                        t.size_m[1]
                    )));
                }
                files_read.push(("the world's height file", path));
                Base::File {
                    grid,
                    scale: t.heightmap_scale,
                }
            }
            None => Base::Procedural {
                noise: Box::new(Noise::new(t.seed)),
                amplitude: t.hills_amplitude_m,
                wavelength: t.hills_wavelength_m,
            },
        };
        if spec.waypoints.is_empty() {
            return Err(invalid("the world has no [[waypoints]]".into()));
        }
        let inside = |p: [f64; 2]| {
            (bounds[0]..=bounds[2]).contains(&p[0]) && (bounds[1]..=bounds[3]).contains(&p[1])
        };
        if !inside(spec.start.position_m) {
            return Err(invalid(format!(
                "the start pose {:?} is off the map [{}, {}] × [{}, {}]",
                spec.start.position_m, bounds[0], bounds[2], bounds[1], bounds[3]
            )));
        }
        for (i, w) in spec.waypoints.iter().enumerate() {
            if let Some(problem) = w.problem() {
                return Err(invalid(format!("waypoint {}: {problem}", i + 1)));
            }
            if !inside(w.position_m) {
                return Err(invalid(format!(
                    "waypoint {} at {:?} is off the map",
                    i + 1,
                    w.position_m
                )));
            }
        }
        let mut features = spec_features(&spec, &invalid)?;
        let waypoints: Vec<WorldWaypoint> = spec
            .waypoints
            .iter()
            .map(|w| WorldWaypoint {
                x: w.position_m[0],
                y: w.position_m[1],
                radius_m: w.radius_m,
            })
            .collect();
        let route: Vec<[f64; 2]> = std::iter::once(spec.start.position_m)
            .chain(spec.waypoints.iter().map(|w| w.position_m))
            .collect();
        for scatter in &spec.scatter {
            scatter_features(scatter, &route, bounds, &mut features).map_err(invalid)?;
        }
        if let Some(vertices) = &spec.area {
            let area = Area::new(vertices.clone()).map_err(|e| invalid(format!("area {e}")))?;
            let (lo, hi) = area.bounds();
            if lo[0] < bounds[0] || lo[1] < bounds[1] || hi[0] > bounds[2] || hi[1] > bounds[3] {
                return Err(invalid(format!(
                    "area reaches ({:.1}, {:.1}) to ({:.1}, {:.1}), beyond the map ({:.1}, {:.1}) to ({:.1}, {:.1})",
                    lo[0], lo[1], hi[0], hi[1], bounds[0], bounds[1], bounds[2], bounds[3]
                )));
            }
        }
        let index = FeatureIndex::new(bounds, &features);
        Ok(World {
            roughness: Noise::new(t.seed.wrapping_add(7919)),
            roughness_amplitude: t.roughness_amplitude_m,
            roughness_wavelength: t.roughness_wavelength_m,
            start: (spec.start.position_m, spec.start.heading_deg.to_radians()),
            spec,
            base,
            features,
            index,
            bounds,
            waypoints,
            files_read,
        })
    }

    /// Checks that the mission can be driven by `vehicle`: no waypoint inside
    /// a hazard, the start clear of hazards.
    pub fn validate_for(&self, vehicle: &VehicleConfig, origin: &str) -> Result<(), WorldError> {
        let invalid = |message: String| WorldError::Invalid {
            origin: origin.to_owned(),
            message,
        };
        for (i, w) in self.waypoints.iter().enumerate() {
            if let Some((j, f, why)) = self.hazard_at([w.x, w.y], 0.0, vehicle) {
                return Err(invalid(format!(
                    "waypoint {} at ({:.1}, {:.1}) lies inside {} #{} ({why}) at ({:.1}, {:.1})",
                    i + 1,
                    w.x,
                    w.y,
                    f.kind.name(),
                    j,
                    f.a[0],
                    f.a[1]
                )));
            }
        }
        let body = vehicle.footprint();
        let reach = (body.x_max - body.x_min).max(2.0 * body.half_width);
        if let Some((j, f, why)) = self.hazard_at(self.start.0, reach, vehicle) {
            return Err(invalid(format!(
                "the start pose at ({:.1}, {:.1}) is within {reach} m of {} #{} ({why})",
                self.start.0[0],
                self.start.0[1],
                f.kind.name(),
                j
            )));
        }
        Ok(())
    }

    /// The first hazardous feature within `margin` of p.
    fn hazard_at(
        &self,
        p: [f64; 2],
        margin: f64,
        vehicle: &VehicleConfig,
    ) -> Option<(usize, &Feature, String)> {
        let mut near = Vec::new();
        self.index.within(
            [p[0] - margin, p[1] - margin, p[0] + margin, p[1] + margin],
            &mut near,
        );
        near.iter().find_map(|&i| {
            let f = &self.features[i as usize];
            (f.distance(p) <= margin)
                .then(|| f.hazard(vehicle))
                .flatten()
                .map(|why| (i as usize, f, why))
        })
    }

    /// Ground height without features, m.
    pub fn terrain_height(&self, x: f64, y: f64) -> f64 {
        let hills = match &self.base {
            Base::Procedural {
                noise,
                amplitude,
                wavelength,
            } => amplitude * noise.fbm(x / wavelength, y / wavelength, 3),
            Base::File { grid, scale } => scale * grid.height(x, y),
        };
        hills
            + self.roughness_amplitude
                * self.roughness.fbm(
                    x / self.roughness_wavelength,
                    y / self.roughness_wavelength,
                    2,
                )
    }

    /// [`height`](Self::height) at each of `xs` on the row at `y`, into
    /// `out`: the same values bit for bit, the terrain's noise worked out
    /// along the row (see [`Noise::row`]). A tile's cells are built so.
    pub fn heights_along(&self, y: f64, xs: impl Iterator<Item = f64>, out: &mut [f64]) {
        self.along(y, xs, out, true);
    }

    /// [`terrain_height`](Self::terrain_height) at each of `xs` on the row
    /// at `y`, into `out`, as [`heights_along`](Self::heights_along) gives
    /// [`height`](Self::height): the same values bit for bit.
    pub fn terrain_heights_along(&self, y: f64, xs: impl Iterator<Item = f64>, out: &mut [f64]) {
        self.along(y, xs, out, false);
    }

    /// The heights along a row, the features' with `features`.
    fn along(&self, y: f64, xs: impl Iterator<Item = f64>, out: &mut [f64], features: bool) {
        // The terrain's row: its hills' noise, or its height file's.
        enum BaseRow<'a> {
            Hills(crate::noise::FbmRow<'a>, f64, f64),
            File(crate::heightmap::HeightRow<'a>, f64),
        }
        let mut base = match &self.base {
            Base::Procedural {
                noise,
                wavelength,
                amplitude,
            } => BaseRow::Hills(noise.fbm_row(y / wavelength, 3), *amplitude, *wavelength),
            Base::File { grid, scale } => BaseRow::File(grid.row(y), *scale),
        };
        let mut roughness = self.roughness.fbm_row(y / self.roughness_wavelength, 2);
        for (x, out) in xs.zip(out) {
            let base = match &mut base {
                BaseRow::Hills(row, amplitude, wavelength) => *amplitude * row.at(x / *wavelength),
                BaseRow::File(row, scale) => *scale * row.at(x),
            };
            let mut h =
                base + self.roughness_amplitude * roughness.at(x / self.roughness_wavelength);
            if features {
                for &i in self.index.at(x, y) {
                    h += self.features[i as usize].height_at([x, y]);
                }
            }
            *out = h;
        }
    }

    /// Height of the world at (x, y): terrain plus features, m.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let mut h = self.terrain_height(x, y);
        for &i in self.index.at(x, y) {
            h += self.features[i as usize].height_at([x, y]);
        }
        h
    }

    /// Indices of the features whose bounds may meet the box.
    pub fn features_within(&self, bounds: [f64; 4], out: &mut Vec<u32>) {
        self.index.within(bounds, out);
    }

    /// The mission's operating area in this world: the polygon its file
    /// gives, else its map less `margin_m` on every side (a map too small
    /// for that margin keeps a tenth of its size instead).
    pub fn area(&self, margin_m: f64) -> Area {
        if let Some(area) = self.spec.area.clone().and_then(|v| Area::new(v).ok()) {
            return area;
        }
        let [x0, y0, x1, y1] = self.bounds;
        let margin = margin_m.min(0.45 * (x1 - x0).min(y1 - y0));
        Area::rectangle([x0 + margin, y0 + margin], [x1 - margin, y1 - margin])
            .expect("a world's map is a rectangle of positive size")
    }

    /// True when (x, y) is inside the world's bounds.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.bounds[0]..=self.bounds[2]).contains(&x)
            && (self.bounds[1]..=self.bounds[3]).contains(&y)
    }
}

/// The features a world's spec lists (boulders, trees, bushes, holes,
/// ditches, rubble, banks; its scatter is expanded later), each checked.
fn spec_features(
    spec: &WorldSpec,
    invalid: &dyn Fn(String) -> WorldError,
) -> Result<Vec<Feature>, WorldError> {
    let mut features = Vec::new();
    let round = |kind: FeatureKind, r: &RoundSpec, sign: f64| -> Result<Feature, WorldError> {
        if !(r.radius_m > 0.0 && r.height_m > 0.0) {
            return Err(invalid(format!(
                "{} at {:?}: radius_m and height_m must be positive",
                kind.name(),
                r.position_m
            )));
        }
        Ok(Feature {
            kind,
            a: r.position_m,
            b: r.position_m,
            radius: r.radius_m,
            height: sign * r.height_m,
            top_half_width: 0.0,
            slope_deg: 90.0,
        })
    };
    for r in &spec.boulders {
        features.push(round(FeatureKind::Boulder, r, 1.0)?);
    }
    for r in &spec.trees {
        features.push(round(FeatureKind::Tree, r, 1.0)?);
    }
    for r in &spec.bushes {
        features.push(round(FeatureKind::Bush, r, 1.0)?);
    }
    for h in &spec.holes {
        let r = RoundSpec {
            position_m: h.position_m,
            radius_m: h.radius_m,
            height_m: h.depth_m,
        };
        features.push(round(FeatureKind::Hole, &r, -1.0)?);
    }
    for d in &spec.ditches {
        if !(d.width_m > 0.0 && d.depth_m > 0.0) {
            return Err(invalid(format!(
                "ditch from {:?}: width_m and depth_m must be positive",
                d.from_m
            )));
        }
        features.push(Feature {
            kind: FeatureKind::Ditch,
            a: d.from_m,
            b: d.to_m,
            radius: d.width_m / 2.0,
            height: -d.depth_m,
            top_half_width: 0.0,
            slope_deg: 90.0,
        });
    }
    for r in &spec.rubble {
        if !(r.width_m > 0.0 && r.height_m > 0.0) {
            return Err(invalid(format!(
                "rubble from {:?}: width_m and height_m must be positive",
                r.from_m
            )));
        }
        features.push(Feature {
            kind: FeatureKind::Rubble,
            a: r.from_m,
            b: r.to_m,
            radius: r.width_m / 2.0,
            height: r.height_m,
            top_half_width: 0.0,
            slope_deg: 90.0,
        });
    }
    for b in &spec.banks {
        if !(b.height_m > 0.0 && b.top_width_m >= 0.0 && b.slope_deg > 0.0 && b.slope_deg < 90.0) {
            return Err(invalid(format!(
                "bank from {:?}: height_m > 0, top_width_m >= 0 and 0 < slope_deg < 90 are required",
                b.from_m
            )));
        }
        let run = b.height_m / b.slope_deg.to_radians().tan();
        features.push(Feature {
            kind: FeatureKind::Bank,
            a: b.from_m,
            b: b.to_m,
            radius: b.top_width_m / 2.0 + run,
            height: b.height_m,
            top_half_width: b.top_width_m / 2.0,
            slope_deg: b.slope_deg,
        });
    }
    Ok(features)
}

/// Places one scatter entry's features (Poisson-disc style rejection).
fn scatter_features(
    scatter: &ScatterSpec,
    route: &[[f64; 2]],
    bounds: [f64; 4],
    features: &mut Vec<Feature>,
) -> Result<(), String> {
    let (r0, r1) = (scatter.radius_m[0], scatter.radius_m[1]);
    let (h0, h1) = (scatter.height_m[0], scatter.height_m[1]);
    if !(r0 > 0.0 && r1 >= r0 && h0 > 0.0 && h1 >= h0) {
        return Err(format!(
            "scatter of {:?}: radius_m and height_m must be [min, max] ranges of positive values",
            scatter.kind
        ));
    }
    if scatter.count > 100_000 {
        return Err(format!(
            "scatter of {:?}: count {} exceeds 100000",
            scatter.kind, scatter.count
        ));
    }
    let route_distance = |p: [f64; 2]| -> f64 {
        route
            .windows(2)
            .map(|w| segment_distance(p, w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
            .min(
                route
                    .first()
                    .map_or(f64::INFINITY, |s| (p[0] - s[0]).hypot(p[1] - s[1])),
            )
    };
    let (kind, sign) = match scatter.kind {
        ScatterKind::Boulder => (FeatureKind::Boulder, 1.0),
        ScatterKind::Tree => (FeatureKind::Tree, 1.0),
        ScatterKind::Bush => (FeatureKind::Bush, 1.0),
        ScatterKind::Hole => (FeatureKind::Hole, -1.0),
    };
    let mut rng = Rng::new(scatter.seed);
    let reach = scatter.near_route_m;
    let area = [
        bounds[0].max(route.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min) - reach),
        bounds[1].max(route.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min) - reach),
        bounds[2].min(route.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max) + reach),
        bounds[3].min(route.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max) + reach),
    ];
    for _ in 0..scatter.count {
        let p = [rng.range(area[0], area[2]), rng.range(area[1], area[3])];
        let radius = rng.range(r0, r1);
        let height = rng.range(h0, h1);
        if route_distance(p) > reach {
            continue;
        }
        let clear_of_route_points = route
            .iter()
            .all(|w| (p[0] - w[0]).hypot(p[1] - w[1]) > scatter.clear_of_waypoints_m + radius);
        let spaced = features
            .iter()
            .all(|f| f.distance(p) > radius + scatter.min_spacing_m);
        if clear_of_route_points && spaced {
            features.push(Feature {
                kind,
                a: p,
                b: p,
                radius,
                height: sign * height,
                top_half_width: 0.0,
                slope_deg: 90.0,
            });
        }
    }
    Ok(())
}
