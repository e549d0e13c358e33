//! `[mission]`: where the vehicle may drive (its operating area) and what
//! a mission does when a waypoint cannot be reached.
//!
//! The operating area is a polygon in world coordinates. The route plans
//! inside it only (its edge is a wall, the ground beyond it is never
//! passable however unseen), and obstacle avoidance vetoes an arc whose
//! swept footprint leaves it. With the area bounding the unseen ground, a
//! waypoint walled off by what the images showed has no route at all, and
//! the mission says so (`unreachable`) instead of searching for ever.

use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError};
use crate::numbers::{crossing_number_inside, segment_distance, segments_cross};

/// A simple polygon in world coordinates (x east, y north, m), convex or
/// not, its vertices in order (either way round; the last joins the first).
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    vertices: Vec<[f64; 2]>,
}

/// At most this many vertices: an operating area is drawn by a person.
pub const MAX_AREA_VERTICES: usize = 10_000;

impl Area {
    /// The polygon through `vertices`: at least three, finite, no two
    /// consecutive alike, no two edges crossing, enclosing some ground.
    pub fn new(vertices: Vec<[f64; 2]>) -> Result<Self, String> {
        let n = vertices.len();
        if n < 3 {
            return Err(format!("has {n} vertices, a polygon needs at least 3"));
        }
        if n > MAX_AREA_VERTICES {
            return Err(format!(
                "has {n} vertices, at most {MAX_AREA_VERTICES} are accepted"
            ));
        }
        if let Some(k) = vertices
            .iter()
            .position(|v| !(v[0].is_finite() && v[1].is_finite()))
        {
            return Err(format!("vertex {k} is not a finite point"));
        }
        for k in 0..n {
            let (a, b) = (vertices[k], vertices[(k + 1) % n]);
            if a == b {
                return Err(format!(
                    "vertices {k} and {} are the same point",
                    (k + 1) % n
                ));
            }
        }
        let area = Self { vertices };
        if let Some((i, j)) = area.crossing_edges() {
            return Err(format!(
                "edges {i} and {j} cross: the vertices must go round the area once"
            ));
        }
        if area.enclosed_m2() < 1.0 {
            return Err("encloses less than 1 m²".into());
        }
        Ok(area)
    }

    /// The rectangle from `min` to `max`.
    pub fn rectangle(min: [f64; 2], max: [f64; 2]) -> Result<Self, String> {
        Self::new(vec![min, [max[0], min[1]], max, [min[0], max[1]]])
    }

    pub fn vertices(&self) -> &[[f64; 2]] {
        &self.vertices
    }

    fn edges(&self) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
        let n = self.vertices.len();
        (0..n).map(move |k| (self.vertices[k], self.vertices[(k + 1) % n]))
    }

    /// The ground it encloses, m² (the shoelace formula).
    pub fn enclosed_m2(&self) -> f64 {
        0.5 * self
            .edges()
            .map(|(a, b)| a[0] * b[1] - b[0] * a[1])
            .sum::<f64>()
            .abs()
    }

    /// The smallest and largest x and y of its vertices.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        self.vertices.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), v| {
                (
                    [lo[0].min(v[0]), lo[1].min(v[1])],
                    [hi[0].max(v[0]), hi[1].max(v[1])],
                )
            },
        )
    }

    /// Whether world point `p` lies inside (crossing number: a ray from
    /// `p` along +x crosses the edges an odd number of times).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        crossing_number_inside(self.edges(), p)
    }

    /// Distance from `p` to the nearest point of the area's edge, m.
    pub fn distance_to_edge(&self, p: [f64; 2]) -> f64 {
        self.edges()
            .map(|(a, b)| segment_distance(p, a, b))
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether `p` lies inside and at least `margin` from the edge.
    pub fn holds(&self, p: [f64; 2], margin: f64) -> bool {
        self.contains(p) && (margin <= 0.0 || self.distance_to_edge(p) >= margin)
    }

    /// Two edges that cross (not neighbours sharing their vertex), if any.
    fn crossing_edges(&self) -> Option<(usize, usize)> {
        let n = self.vertices.len();
        // Quadratic, but bounded by `MAX_AREA_VERTICES` and checked once,
        // when the configuration is read.
        for i in 0..n {
            let (a, b) = (self.vertices[i], self.vertices[(i + 1) % n]);
            for j in i + 1..n {
                if j == i + 1 || (i == 0 && j == n - 1) {
                    continue;
                }
                let (c, d) = (self.vertices[j], self.vertices[(j + 1) % n]);
                if segments_cross(a, b, c, d) {
                    return Some((i, j));
                }
            }
        }
        None
    }
}

/// `[mission] area` as written: `"world"`, `"none"`, or the vertices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum AreaSpec {
    Named(String),
    Vertices(Vec<[f64; 2]>),
}

/// The operating area a configuration asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum AreaSetting {
    /// The simulated world's (`arcnav sim`, `sweep`): its map less
    /// `area_margin_m`, or the polygon its file gives. A live run has no
    /// world: it drives with no area unless given one.
    World,
    /// No area: the route may plan anywhere its memory reaches.
    None,
    /// This polygon.
    Polygon(Area),
}

/// What a mission does with a waypoint no route reaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnUnreachable {
    /// End the mission (`unreachable`); live, the vehicle stands.
    #[default]
    Stop,
    /// Give the waypoint up and go on to the next.
    Skip,
}

/// `[mission]` as given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MissionConfig {
    /// `"world"` (the simulated world's; none live), `"none"`, or a
    /// polygon `[[x, y], ...]` in world coordinates, m.
    pub area: AreaSpec,
    /// The world's area, when its file gives no polygon: its map less
    /// this on every side, m.
    pub area_margin_m: f64,
    /// A waypoint is unreachable once the route has found no way to it,
    /// searching all of the area it knows, for this long without a break, s.
    pub unreachable_after_s: f64,
    pub on_unreachable: OnUnreachable,
}

impl Default for MissionConfig {
    fn default() -> Self {
        Self {
            area: AreaSpec::Named("world".into()),
            area_margin_m: 5.0,
            unreachable_after_s: 5.0,
            on_unreachable: OnUnreachable::Stop,
        }
    }
}

/// When a waypoint counts as unreachable and what follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WhenUnreachable {
    /// No way found, searching all the area known, this long, s.
    pub after_s: f64,
    pub then: OnUnreachable,
}

impl Default for WhenUnreachable {
    fn default() -> Self {
        let c = MissionConfig::default();
        Self {
            after_s: c.unreachable_after_s,
            then: c.on_unreachable,
        }
    }
}

/// `[mission]` checked: the area as a polygon or a choice.
#[derive(Debug, Clone, PartialEq)]
pub struct Mission {
    pub area: AreaSetting,
    pub area_margin_m: f64,
    pub unreachable: WhenUnreachable,
}

impl Default for Mission {
    fn default() -> Self {
        MissionConfig::default()
            .checked()
            .expect("the default [mission] is valid")
    }
}

impl MissionConfig {
    /// The keys checked (errors relative to `[mission]`), the area as a
    /// polygon.
    pub fn checked(&self) -> Result<Mission, ConfigError> {
        let area = match &self.area {
            AreaSpec::Named(name) if name == "world" => AreaSetting::World,
            AreaSpec::Named(name) if name == "none" => AreaSetting::None,
            AreaSpec::Named(name) => {
                return Err(ConfigError::new(
                    "area",
                    format!(
                        "is \"{name}\": give \"world\", \"none\" or the polygon's vertices [[x, y], ...] in world coordinates, m"
                    ),
                ));
            }
            AreaSpec::Vertices(vertices) => AreaSetting::Polygon(
                Area::new(vertices.clone()).map_err(|e| ConfigError::new("area", e))?,
            ),
        };
        config::in_range("area_margin_m", self.area_margin_m, 0.0, 1000.0)?;
        config::in_range("unreachable_after_s", self.unreachable_after_s, 0.0, 3600.0)?;
        Ok(Mission {
            area,
            area_margin_m: self.area_margin_m,
            unreachable: WhenUnreachable {
                after_s: self.unreachable_after_s,
                then: self.on_unreachable,
            },
        })
    }
}

impl Mission {
    /// The polygon the vehicle keeps to: the one given, or for `world`
    /// the world's (`world`, when there is one).
    pub fn area<'a>(&'a self, world: Option<&'a Area>) -> Option<&'a Area> {
        match &self.area {
            AreaSetting::Polygon(area) => Some(area),
            AreaSetting::World => world,
            AreaSetting::None => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ell() -> Area {
        // An L: the square 0..20 less its upper right quarter.
        Area::new(vec![
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 10.0],
            [10.0, 10.0],
            [10.0, 20.0],
            [0.0, 20.0],
        ])
        .unwrap()
    }

    #[test]
    fn a_point_is_inside_a_concave_polygon_only_where_it_encloses_ground() {
        let l = ell();
        assert!(l.contains([5.0, 5.0]));
        assert!(l.contains([15.0, 5.0]));
        assert!(l.contains([5.0, 15.0]));
        assert!(!l.contains([15.0, 15.0]), "the missing quarter");
        assert!(!l.contains([-1.0, 5.0]));
        assert_eq!(l.enclosed_m2(), 300.0);
        assert!((l.distance_to_edge([12.0, 12.0]) - 2.0).abs() < 1e-12);
        assert!(l.holds([5.0, 5.0], 4.0));
        assert!(!l.holds([5.0, 5.0], 6.0));
        assert_eq!(l.bounds(), ([0.0, 0.0], [20.0, 20.0]));
    }

    #[test]
    fn bad_polygons_are_refused_with_the_reason() {
        let two = Area::new(vec![[0.0, 0.0], [1.0, 1.0]]).unwrap_err();
        assert!(two.contains("at least 3"), "{two}");
        let bow = Area::new(vec![[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]]).unwrap_err();
        assert!(bow.contains("cross"), "{bow}");
        let flat = Area::new(vec![[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]).unwrap_err();
        assert!(flat.contains("less than 1 m²"), "{flat}");
        let nan = Area::new(vec![[0.0, 0.0], [f64::NAN, 0.0], [1.0, 1.0]]).unwrap_err();
        assert!(nan.contains("vertex 1"), "{nan}");
        let repeated = Area::new(vec![[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]]).unwrap_err();
        assert!(repeated.contains("same point"), "{repeated}");
    }

    #[test]
    fn the_area_key_takes_world_none_or_vertices_and_nothing_else() {
        let parse = |text: &str| -> Result<Mission, ConfigError> {
            toml::from_str::<MissionConfig>(text).unwrap().checked()
        };
        assert_eq!(parse("").unwrap().area, AreaSetting::World);
        assert_eq!(parse("area = \"none\"").unwrap().area, AreaSetting::None);
        let square = parse("area = [[0, 0], [10, 0], [10, 10], [0, 10]]").unwrap();
        assert!(matches!(square.area, AreaSetting::Polygon(ref a) if a.enclosed_m2() == 100.0));
        let wrong = parse("area = \"everywhere\"").unwrap_err();
        assert_eq!(wrong.key, "area");
        assert!(wrong.reason.contains("\"world\""), "{wrong}");
        let skip = parse("on_unreachable = \"skip\"").unwrap();
        assert_eq!(skip.unreachable.then, OnUnreachable::Skip);
        assert!(toml::from_str::<MissionConfig>("on_unreachable = \"wait\"").is_err());
    }
}
