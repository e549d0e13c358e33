//! Steering arcs: the finite set of constant-curvature paths the behaviours
//! vote over (002 §6, Figure 9: 39 arcs with radii from -8 m to +8 m).
//!
//! Arcs are indexed by their position in the [`ArcSet`], in increasing
//! curvature: index 0 is the hardest right turn, the middle index is straight
//! ahead, the last is the hardest left turn. Curvature `k = 1/R`, positive
//! turning left. All geometry is in the vehicle frame at the moment of
//! voting: the rear axle at the origin, heading along +x.

use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError};
use crate::model::{Footprint, Kinematics, VehicleConfig};

/// How the arc set is laid out. Lives in `[arcs]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArcSetConfig {
    /// Number of arcs; odd, so that straight ahead is one of them (002 §6: 39).
    pub count: usize,
    /// Radius of the two tightest arcs, m (002 §6: 8 m).
    pub min_radius_m: f64,
    /// Judge each arc along the path the vehicle drives when commanded
    /// onto it ([`crate::DrivenPath`]: the latency, then the steering's
    /// rate) rather than along the arc itself (020 item 2): always, never,
    /// or above [`DrivenPaths::AUTO_ABOVE_MPS`] of cruise.
    pub driven_paths: DrivenPaths,
    /// Add two arcs of curvature -∞ and +∞ at the ends of the set (index 0
    /// and the last): turning in place, right and left, at the vehicle's
    /// `max_yaw_rate_dps` (a skid-steer vehicle's only). Behaviours judge
    /// them like any arc (obstacle avoidance sweeps the body through the
    /// turn); the arbiter turns on them to turn round, where an Ackermann
    /// vehicle makes a K-point turn.
    pub turn_in_place: bool,
}

/// When behaviours judge arcs along the paths the vehicle drives onto them
/// (`[arcs] driven_paths`): `true`, `false`, or `"auto"` (the default):
/// along driven paths when the cruise speed exceeds
/// [`AUTO_ABOVE_MPS`](DrivenPaths::AUTO_ABOVE_MPS), along arcs at the
/// paper's 2–3 m/s. Below it the two differ by under a metre (0.75 m of
/// latency at 3 m/s, the turn a further 2.7 m on to the hardest arc) and
/// 017's turning manoeuvres in lanes narrower than a turning circle were
/// tuned on arcs; above it a turn judged clear on its arc begins metres
/// later than the arc, and judged on arcs the 64-beam lidar hit a ditch at
/// 10 m/s and a boulder at 9 m/s.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DrivenPaths {
    /// Along driven paths above `AUTO_ABOVE_MPS` of cruise, arcs below.
    #[default]
    Auto,
    /// Always along driven paths.
    On,
    /// Always along arcs (002).
    Off,
}

impl DrivenPaths {
    /// Cruise speed above which `auto` judges driven paths, m/s.
    pub const AUTO_ABOVE_MPS: f64 = 3.0;

    /// Whether arcs are judged along driven paths at `cruise_mps`.
    pub fn at(self, cruise_mps: f64) -> bool {
        match self {
            Self::Auto => cruise_mps > Self::AUTO_ABOVE_MPS,
            Self::On => true,
            Self::Off => false,
        }
    }
}

impl Serialize for DrivenPaths {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Auto => serializer.serialize_str("auto"),
            Self::On => serializer.serialize_bool(true),
            Self::Off => serializer.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for DrivenPaths {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = DrivenPaths;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("true, false or \"auto\"")
            }
            fn visit_bool<E: serde::de::Error>(self, on: bool) -> Result<DrivenPaths, E> {
                Ok(if on {
                    DrivenPaths::On
                } else {
                    DrivenPaths::Off
                })
            }
            fn visit_str<E: serde::de::Error>(self, text: &str) -> Result<DrivenPaths, E> {
                match text {
                    "auto" => Ok(DrivenPaths::Auto),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(text), &self)),
                }
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

impl From<bool> for DrivenPaths {
    fn from(on: bool) -> Self {
        if on { Self::On } else { Self::Off }
    }
}

impl Default for ArcSetConfig {
    fn default() -> Self {
        Self {
            count: 39,
            min_radius_m: 8.0,
            driven_paths: DrivenPaths::Auto,
            turn_in_place: false,
        }
    }
}

/// Most arcs a set may hold; far beyond any use, small enough to refuse typos.
pub const MAX_ARCS: usize = 100_001;

impl ArcSetConfig {
    /// Checks the arc set on its own; keys are relative to `[arcs]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.count < 3 || self.count.is_multiple_of(2) || self.count > MAX_ARCS {
            return Err(ConfigError::new(
                "count",
                format!(
                    "is {}, must be an odd number between 3 and {MAX_ARCS} so that straight ahead is one of the arcs",
                    self.count
                ),
            ));
        }
        config::positive("min_radius_m", self.min_radius_m)
    }

    /// Checks the arc set against the vehicle: an arc tighter than the
    /// vehicle's minimum turning radius could win and could not be driven.
    pub fn validate_for(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        self.validate()?;
        if self.turn_in_place && vehicle.kinematics != Kinematics::SkidSteer {
            return Err(ConfigError::new(
                "turn_in_place",
                "needs a vehicle that turns in place (vehicle.kinematics = \"skid_steer\")",
            ));
        }
        if self.min_radius_m < vehicle.min_turning_radius_m {
            return Err(ConfigError::new(
                "min_radius_m",
                format!(
                    "is {} m, tighter than the vehicle's minimum turning radius (vehicle.min_turning_radius_m = {} m): the vehicle could not drive the extreme arcs",
                    self.min_radius_m, vehicle.min_turning_radius_m
                ),
            ));
        }
        Ok(())
    }
}

/// The arcs, evenly spaced in curvature between `-1/R` and `+1/R`; with
/// `turn_in_place`, a turn in place (curvature ∓∞) at each end.
#[derive(Debug, Clone, PartialEq)]
pub struct ArcSet {
    curvatures: Vec<f64>,
    max_curvature: f64,
    driven_paths: bool,
    /// Arcs before the first driving one: 1 with turns in place, else 0.
    offset: usize,
}

impl ArcSet {
    /// Builds the set for a vehicle cruising at `cruise_mps` (which
    /// decides `driven_paths = "auto"`); refuses a configuration
    /// `validate()` refuses.
    pub fn for_cruise(config: &ArcSetConfig, cruise_mps: f64) -> Result<Self, ConfigError> {
        let mut set = Self::new(config)?;
        set.driven_paths = config.driven_paths.at(cruise_mps);
        Ok(set)
    }

    /// Builds the set; `driven_paths = "auto"` judges arcs as arcs (the
    /// paper's speeds; [`ArcSet::for_cruise`] decides it for a cruise
    /// speed). Refuses a configuration `validate()` refuses.
    pub fn new(config: &ArcSetConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let max_curvature = 1.0 / config.min_radius_m;
        let n = config.count;
        let half = (n - 1) as f64;
        // Integer numerators make the set exactly symmetric with an exact 0.
        let driving = (0..n).map(|i| max_curvature * (2.0 * i as f64 - half) / half);
        let offset = usize::from(config.turn_in_place);
        let curvatures = std::iter::repeat_n(f64::NEG_INFINITY, offset)
            .chain(driving)
            .chain(std::iter::repeat_n(f64::INFINITY, offset))
            .collect();
        Ok(Self {
            curvatures,
            max_curvature,
            driven_paths: config.driven_paths == DrivenPaths::On,
            offset,
        })
    }

    /// Whether the set holds turns in place (`[arcs] turn_in_place`).
    pub fn turns_in_place(&self) -> bool {
        self.offset > 0
    }

    /// True when the arc at `index` is a turn in place (curvature ±∞).
    pub fn is_turn_in_place(&self, index: usize) -> bool {
        self.curvature(index).is_some_and(f64::is_infinite)
    }

    /// Indices of the arcs the vehicle drives along (all but the turns in
    /// place).
    pub fn driving(&self) -> std::ops::Range<usize> {
        self.offset..self.curvatures.len() - self.offset
    }

    pub fn len(&self) -> usize {
        self.curvatures.len()
    }

    /// Never true: a valid set holds at least three arcs.
    pub fn is_empty(&self) -> bool {
        self.curvatures.is_empty()
    }

    /// Whether behaviours judge each arc along the path the vehicle drives
    /// onto it (`[arcs] driven_paths`) rather than along the arc.
    pub fn driven_paths(&self) -> bool {
        self.driven_paths
    }

    /// Curvatures in index order, 1/m.
    pub fn curvatures(&self) -> &[f64] {
        &self.curvatures
    }

    /// Curvature of the arc at `index`, or `None` past the end.
    pub fn curvature(&self, index: usize) -> Option<f64> {
        self.curvatures.get(index).copied()
    }

    /// The arc at `index`, or `None` past the end.
    pub fn arc(&self, index: usize) -> Option<Arc> {
        self.curvature(index).map(Arc::new)
    }

    /// All arcs in index order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = Arc> + '_ {
        self.curvatures.iter().map(|&k| Arc::new(k))
    }

    /// Index of the straight arc (the middle one).
    pub fn straight_index(&self) -> usize {
        self.curvatures.len() / 2
    }

    /// The largest |curvature| of the driving arcs, 1/m.
    pub fn max_curvature(&self) -> f64 {
        self.max_curvature
    }

    /// Curvature difference between neighbouring driving arcs, 1/m.
    pub fn spacing(&self) -> f64 {
        2.0 * self.max_curvature / (self.driving().len() - 1) as f64
    }

    /// Index of the driving arc nearest in curvature to `curvature`
    /// (clamped to the driving arcs; a turn in place is never the nearest).
    pub fn nearest_index(&self, curvature: f64) -> usize {
        if !curvature.is_finite() {
            return self.straight_index();
        }
        let position = (curvature + self.max_curvature) / self.spacing();
        (position.round().max(0.0) as usize).min(self.driving().len() - 1) + self.offset
    }
}

/// A pose along an arc, in the vehicle frame of the arc's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcPose {
    pub position: Point2<f64>,
    /// Heading, radians CCW from +x.
    pub heading: f64,
}

impl ArcPose {
    /// The point `p` (given in the frame of this pose) in the arc's start frame.
    pub fn transform_point(&self, p: Point2<f64>) -> Point2<f64> {
        let (sin, cos) = self.heading.sin_cos();
        Point2::new(
            self.position.x + cos * p.x - sin * p.y,
            self.position.y + sin * p.x + cos * p.y,
        )
    }
}

/// A path of constant curvature starting at the origin heading along +x.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arc {
    /// 1/m, positive turning left.
    pub curvature: f64,
}

impl Arc {
    pub fn new(curvature: f64) -> Self {
        Self { curvature }
    }

    /// True for a turn in place (curvature ±∞): [`Arc::pose_at`] and the
    /// sweeps of a driven arc do not apply; see [`TurnInPlace`].
    pub fn is_turn_in_place(&self) -> bool {
        self.curvature.is_infinite()
    }

    /// Turning radius, m, signed like the curvature; `None` when straight
    /// or turning in place.
    pub fn radius(&self) -> Option<f64> {
        (self.curvature != 0.0 && self.curvature.is_finite()).then(|| 1.0 / self.curvature)
    }

    /// Centre of the turning circle; `None` when straight.
    pub fn center(&self) -> Option<Point2<f64>> {
        self.radius().map(|r| Point2::new(0.0, r))
    }

    /// The pose after driving `s` metres along the arc. A turn in place
    /// drives nowhere: its poses are the start (the turn's own poses are
    /// [`TurnInPlace::pose_at`]'s).
    pub fn pose_at(&self, s: f64) -> ArcPose {
        if self.is_turn_in_place() {
            return ArcPose {
                position: Point2::origin(),
                heading: 0.0,
            };
        }
        let theta = self.curvature * s;
        // sin(θ)/k and (1 - cos θ)/k written as s·f(θ), exact as k → 0.
        let (along, across) = if theta.abs() < 1e-6 {
            (s * (1.0 - theta * theta / 6.0), s * (theta / 2.0))
        } else {
            (
                theta.sin() / self.curvature,
                (1.0 - theta.cos()) / self.curvature,
            )
        };
        ArcPose {
            position: Point2::new(along, across),
            heading: theta,
        }
    }

    /// Poses every `step_m` metres from 0 to `length_m` inclusive.
    pub fn sample(&self, length_m: f64, step_m: f64) -> impl Iterator<Item = ArcPose> + '_ {
        let steps = if step_m > 0.0 && length_m > 0.0 {
            (length_m / step_m).ceil() as usize
        } else {
            0
        };
        (0..=steps).map(move |i| self.pose_at((i as f64 * step_m).min(length_m.max(0.0))))
    }

    /// The region the footprint sweeps while driving the first `length_m`
    /// metres of this arc.
    pub fn swept(&self, footprint: Footprint, length_m: f64) -> SweptFootprint {
        SweptFootprint {
            arc: *self,
            footprint,
            length_m,
        }
    }
}

/// The area a footprint covers while it drives along an arc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweptFootprint {
    pub arc: Arc,
    pub footprint: Footprint,
    pub length_m: f64,
}

impl SweptFootprint {
    /// The arc length at which the moving footprint first touches the fixed
    /// point `p` (start frame), or `None` if it does not within `length_m`.
    /// Exact: the point is followed on its circle about the turning centre
    /// and intersected with the footprint's edges.
    pub fn first_contact(&self, p: Point2<f64>) -> Option<f64> {
        let s = self.first_contact_unbounded(p)?;
        (s <= self.length_m).then_some(s)
    }

    /// True when the footprint touches `p` somewhere along the swept length.
    pub fn covers(&self, p: Point2<f64>) -> bool {
        self.first_contact(p).is_some()
    }

    /// Footprint outlines every `step_m` along the arc (for drawing).
    pub fn outlines(&self, step_m: f64) -> Vec<Vec<Point2<f64>>> {
        let outline = self.footprint.outline();
        self.arc
            .sample(self.length_m, step_m)
            .map(|pose| outline.iter().map(|c| pose.transform_point(*c)).collect())
            .collect()
    }

    fn first_contact_unbounded(&self, p: Point2<f64>) -> Option<f64> {
        let f = &self.footprint;
        if f.contains(p) {
            return Some(0.0);
        }
        if self.arc.is_turn_in_place() {
            // It drives nowhere: see [`TurnInPlace::first_contact`].
            return None;
        }
        if !f.is_rectangle() {
            return self.first_contact_with_outline(p);
        }
        let k = self.arc.curvature;
        let Some(center) = self.arc.center() else {
            // Straight: the point slides towards -x in the vehicle frame.
            return (p.y.abs() <= f.half_width && p.x >= f.x_min).then(|| p.x - f.x_max);
        };
        // In the moving frame the point turns about `center` by -k·s.
        let offset: Vector2<f64> = p - center;
        let radius = offset.norm();
        let angle_p = offset.y.atan2(offset.x);
        let mut first: Option<f64> = None;
        let mut consider = |q: Point2<f64>| {
            let angle_q = (q.y - center.y).atan2(q.x - center.x);
            let turn = if k > 0.0 {
                angle_p - angle_q
            } else {
                angle_q - angle_p
            };
            let s = turn.rem_euclid(std::f64::consts::TAU) / k.abs();
            first = Some(first.map_or(s, |best: f64| best.min(s)));
        };
        // Vertical edges x = const, horizontal edges y = const.
        for x in [f.x_min, f.x_max] {
            let dx = x - center.x;
            let h2 = radius * radius - dx * dx;
            if h2 >= 0.0 {
                let h = h2.sqrt();
                for y in [center.y - h, center.y + h] {
                    if y.abs() <= f.half_width {
                        consider(Point2::new(x, y));
                    }
                }
            }
        }
        for y in [-f.half_width, f.half_width] {
            let dy = y - center.y;
            let h2 = radius * radius - dy * dy;
            if h2 >= 0.0 {
                let h = h2.sqrt();
                for x in [center.x - h, center.x + h] {
                    if (f.x_min..=f.x_max).contains(&x) {
                        consider(Point2::new(x, y));
                    }
                }
            }
        }
        first
    }

    /// [`Self::first_contact_unbounded`] for any outline (`p` outside it):
    /// where the point, followed on its circle about the turning centre
    /// (or along −x, straight), first meets one of the outline's edges.
    fn first_contact_with_outline(&self, p: Point2<f64>) -> Option<f64> {
        let outline = self.footprint.outline();
        let k = self.arc.curvature;
        let mut first: Option<f64> = None;
        let mut consider = |s: f64| first = Some(first.map_or(s, |best: f64| best.min(s)));
        let Some(center) = self.arc.center() else {
            // Straight: the point slides towards −x; it meets an edge
            // where the edge crosses its line at or behind it.
            for (a, b) in outline.edges() {
                let (lo, hi) = (a.y.min(b.y), a.y.max(b.y));
                if p.y < lo || p.y > hi {
                    continue;
                }
                let x = if a.y == b.y {
                    a.x.max(b.x).min(p.x)
                } else {
                    a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x)
                };
                if x <= p.x {
                    consider(p.x - x);
                }
            }
            return first;
        };
        // In the moving frame the point turns about `center` by −k·s.
        turn_to_meet(&outline, center, p, k > 0.0).map(|turn| turn / k.abs())
    }
}

/// The angle the outline turns about `center` (to the left when `left`)
/// before it first meets the fixed point `p` (outside it), in [0, 2π)
/// radians: in the moving frame the point turns the other way about
/// `center`, and its circle's crossings with each edge are the candidates.
fn turn_to_meet(
    outline: &crate::footprint::Outline,
    center: Point2<f64>,
    p: Point2<f64>,
    left: bool,
) -> Option<f64> {
    let offset: Vector2<f64> = p - center;
    let radius2 = offset.norm_squared();
    let angle_p = offset.y.atan2(offset.x);
    let mut first: Option<f64> = None;
    for (a, b) in outline.edges() {
        let (d, f) = (b - a, a - center);
        let (qa, qb, qc) = (
            d.norm_squared(),
            2.0 * f.dot(&d),
            f.norm_squared() - radius2,
        );
        let disc = qb * qb - 4.0 * qa * qc;
        if qa == 0.0 || disc < 0.0 {
            continue;
        }
        let root = disc.sqrt();
        for t in [(-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)] {
            if !(0.0..=1.0).contains(&t) {
                continue;
            }
            let q = a + d * t;
            let angle_q = (q.y - center.y).atan2(q.x - center.x);
            let turn = if left {
                angle_p - angle_q
            } else {
                angle_q - angle_p
            };
            let turn = turn.rem_euclid(std::f64::consts::TAU);
            first = Some(first.map_or(turn, |best: f64| best.min(turn)));
        }
    }
    first
}

/// The body turning in place about `centre` (a skid-steer vehicle's turn,
/// an arc of curvature ±∞), by at most `max_angle` radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnInPlace {
    /// The point turned about, vehicle frame (the middle of the wheelbase).
    pub centre: Point2<f64>,
    /// Turning left (anticlockwise seen from above).
    pub left: bool,
    pub footprint: Footprint,
    /// How far the turn goes, radians.
    pub max_angle: f64,
}

impl TurnInPlace {
    /// The angle, radians, at which the turning body first touches the
    /// fixed point `p` (start frame), or `None` if it does not within
    /// `max_angle`. Exact, like [`SweptFootprint::first_contact`].
    pub fn first_contact(&self, p: Point2<f64>) -> Option<f64> {
        if self.footprint.contains(p) {
            return Some(0.0);
        }
        turn_to_meet(&self.footprint.outline(), self.centre, p, self.left)
            .filter(|&turn| turn <= self.max_angle)
    }

    /// Where the vehicle's origin is, and its heading, after turning by
    /// `angle` radians (start frame).
    pub fn pose_at(&self, angle: f64) -> ArcPose {
        let heading = if self.left { angle } else { -angle };
        let (sin, cos) = heading.sin_cos();
        let (cx, cy) = (self.centre.x, self.centre.y);
        ArcPose {
            position: Point2::new(cx - cos * cx + sin * cy, cy - sin * cx - cos * cy),
            heading,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    fn default_set() -> ArcSet {
        ArcSet::new(&ArcSetConfig::default()).unwrap()
    }

    #[test]
    fn the_default_set_has_39_arcs_from_minus_to_plus_8_metres() {
        let arcs = default_set();
        assert_eq!(arcs.len(), 39);
        assert_relative_eq!(
            arcs.arc(0).unwrap().radius().unwrap(),
            -8.0,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            arcs.arc(38).unwrap().radius().unwrap(),
            8.0,
            epsilon = 1e-12
        );
        assert!(arcs.curvature(39).is_none());
    }

    #[test]
    fn curvatures_are_evenly_spaced_and_symmetric_about_straight() {
        let arcs = default_set();
        let k = arcs.curvatures();
        for pair in k.windows(2) {
            assert_relative_eq!(pair[1] - pair[0], arcs.spacing(), epsilon = 1e-12);
        }
        for i in 0..k.len() {
            assert_eq!(
                k[i],
                -k[k.len() - 1 - i],
                "arc {i} mirrors its opposite exactly"
            );
        }
        assert_eq!(arcs.straight_index(), 19);
        assert_eq!(k[19], 0.0);
        assert!(arcs.arc(19).unwrap().radius().is_none());
    }

    #[test]
    fn nearest_index_speaks_curvature() {
        let arcs = default_set();
        assert_eq!(arcs.nearest_index(0.0), 19);
        assert_eq!(arcs.nearest_index(0.125), 38);
        assert_eq!(arcs.nearest_index(-1.0), 0);
        assert_eq!(
            arcs.nearest_index(arcs.curvature(25).unwrap() + 0.1 * arcs.spacing()),
            25
        );
        assert_eq!(arcs.nearest_index(f64::NAN), 19);
    }

    #[test]
    fn arcs_tighter_than_the_vehicle_can_turn_are_refused() {
        let vehicle = VehicleConfig::default();
        let err = ArcSetConfig {
            min_radius_m: 7.0,
            ..Default::default()
        }
        .validate_for(&vehicle)
        .unwrap_err();
        assert_eq!(err.key, "min_radius_m");
        assert!(err.reason.contains("minimum turning radius"), "{err}");
        ArcSetConfig::default().validate_for(&vehicle).unwrap();
    }

    #[test]
    fn an_even_count_is_refused_because_straight_would_be_missing() {
        let err = ArcSet::new(&ArcSetConfig {
            count: 40,
            ..Default::default()
        })
        .unwrap_err();
        assert_eq!(err.key, "count");
    }

    #[test]
    fn sampled_points_lie_on_the_circle_of_radius_one_over_k() {
        for arc in default_set().iter() {
            let Some(center) = arc.center() else { continue };
            let r = arc.radius().unwrap().abs();
            for pose in arc.sample(20.0, 0.5) {
                assert_relative_eq!((pose.position - center).norm(), r, epsilon = 1e-9);
            }
        }
        // A quarter circle of radius 8 to the left ends at (8, 8) heading north.
        let end = Arc::new(0.125).pose_at(8.0 * FRAC_PI_2);
        assert_relative_eq!(end.position, Point2::new(8.0, 8.0), epsilon = 1e-12);
        assert_relative_eq!(end.heading, FRAC_PI_2, epsilon = 1e-12);
    }

    #[test]
    fn nearly_straight_arcs_are_continuous_with_straight() {
        let a = Arc::new(1e-9).pose_at(10.0);
        let b = Arc::new(0.0).pose_at(10.0);
        assert_relative_eq!(a.position, b.position, epsilon = 1e-7);
    }

    #[test]
    fn swept_footprint_covers_the_vehicle_width_along_the_arc() {
        let footprint = VehicleConfig::default().footprint();
        for arc in default_set().iter() {
            let swept = arc.swept(footprint, 15.0);
            for pose in arc.sample(15.0, 0.75) {
                for lateral in [-1.09, -0.5, 0.0, 0.5, 1.09] {
                    let p = pose.transform_point(Point2::new(0.0, lateral));
                    let s = swept.first_contact(p).expect("rear-axle line is covered");
                    let along = pose.heading / arc.curvature;
                    let along = if along.is_finite() {
                        along
                    } else {
                        pose.position.x
                    };
                    assert!(
                        s <= along + 1e-9,
                        "covered no later than when the axle passes"
                    );
                }
            }
        }
    }

    #[test]
    fn swept_footprint_leaves_the_inside_of_the_turn_free() {
        let footprint = VehicleConfig::default().footprint();
        let arc = Arc::new(0.125);
        let swept = arc.swept(footprint, 15.0);
        // Inside the turn the body never comes closer to the centre than R - w/2.
        let pose = arc.pose_at(10.0);
        let inside = pose.transform_point(Point2::new(0.0, footprint.half_width + 0.05));
        assert!(!swept.covers(inside));
        let straight = Arc::new(0.0).swept(footprint, 15.0);
        assert!(!straight.covers(Point2::new(8.0, 1.15)));
        assert!(straight.covers(Point2::new(8.0, 1.05)));
        // A point behind the vehicle is never reached driving forwards.
        assert!(!straight.covers(Point2::new(-3.0, 0.0)));
    }

    #[test]
    fn straight_first_contact_is_the_gap_to_the_front_bumper() {
        let footprint = VehicleConfig::default().footprint();
        let swept = Arc::new(0.0).swept(footprint, 20.0);
        assert_relative_eq!(swept.first_contact(Point2::new(9.0, 0.3)).unwrap(), 5.0);
        assert_eq!(swept.first_contact(Point2::new(1.0, 0.3)), Some(0.0));
        assert_eq!(
            swept.first_contact(Point2::new(30.0, 0.0)),
            None,
            "beyond the swept length"
        );
    }

    fn brute_force_first_contact(swept: &SweptFootprint, p: Point2<f64>, step: f64) -> Option<f64> {
        let steps = (swept.length_m / step) as usize;
        (0..=steps).map(|i| i as f64 * step).find(|&s| {
            let pose = swept.arc.pose_at(s);
            let (sin, cos) = pose.heading.sin_cos();
            let d = p - pose.position;
            let local = Point2::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y);
            swept.footprint.contains(local)
        })
    }

    /// The bodies the contact is checked for: the HMMWV's rectangle, an
    /// L-shaped polygon (its front right corner cut away) and a circle.
    fn bodies() -> [Footprint; 3] {
        let p = Point2::new;
        [
            VehicleConfig::default().footprint(),
            Footprint::polygon(&[
                p(-0.6, -1.1),
                p(2.0, -1.1),
                p(2.0, 0.0),
                p(4.0, 0.0),
                p(4.0, 1.1),
                p(-0.6, 1.1),
            ])
            .unwrap(),
            Footprint::circle(p(0.4, 0.0), 1.2).unwrap(),
        ]
    }

    proptest! {
        #[test]
        fn exact_first_contact_agrees_with_dense_sampling(
            body in 0usize..3, k in -0.125f64..0.125, x in -3.0f64..20.0, y in -12.0f64..12.0
        ) {
            let footprint = bodies()[body];
            let swept = Arc::new(k).swept(footprint, 20.0);
            let p = Point2::new(x, y);
            let step = 0.002;
            match (swept.first_contact(p), brute_force_first_contact(&swept, p, step)) {
                (Some(a), Some(b)) => prop_assert!((a - b).abs() <= 2.0 * step, "exact {a} vs sampled {b}"),
                (None, None) => {}
                // A grazing contact may fall between samples: a footprint 1 cm
                // larger all round must then be seen touching.
                (Some(_), None) => {
                    let grown = footprint.grown(0.01, 0.01, 0.01);
                    prop_assert!(brute_force_first_contact(&swept.arc.swept(grown, 20.0 + 0.01), p, step).is_some());
                }
                (None, Some(b)) => prop_assert!(false, "sampling found contact at {b}, exact found none"),
            }
        }
    }

    #[test]
    fn straight_ahead_the_notch_of_an_l_lets_a_point_in_farther() {
        let ell = bodies()[1];
        let swept = Arc::new(0.0).swept(ell, 20.0);
        // In line with the notch (right of the centre line), the point
        // meets the body's front at x = 2, not 4.
        let s = swept.first_contact(Point2::new(10.0, -0.5)).unwrap();
        assert!((s - 8.0).abs() < 1e-12, "{s}");
        let s = swept.first_contact(Point2::new(10.0, 0.5)).unwrap();
        assert!((s - 6.0).abs() < 1e-12, "{s}");
    }

    #[test]
    fn turns_in_place_end_the_set_and_are_never_the_nearest_driving_arc() {
        let arcs = ArcSet::new(&ArcSetConfig {
            turn_in_place: true,
            ..ArcSetConfig::default()
        })
        .unwrap();
        assert_eq!(arcs.len(), 41);
        assert_eq!(arcs.curvature(0), Some(f64::NEG_INFINITY));
        assert_eq!(arcs.curvature(40), Some(f64::INFINITY));
        assert!(arcs.is_turn_in_place(0) && arcs.is_turn_in_place(40) && !arcs.is_turn_in_place(1));
        assert_eq!(arcs.driving(), 1..40);
        assert_eq!(arcs.curvature(arcs.straight_index()), Some(0.0));
        assert_eq!(arcs.nearest_index(1.0), 39);
        assert_eq!(arcs.nearest_index(-1.0), 1);
        assert_eq!(arcs.curvature(1), Some(-1.0 / 8.0));
        let plain = ArcSet::new(&ArcSetConfig::default()).unwrap();
        assert_eq!(arcs.spacing(), plain.spacing());
        let err = ArcSetConfig {
            turn_in_place: true,
            ..ArcSetConfig::default()
        }
        .validate_for(&VehicleConfig::default())
        .unwrap_err();
        assert_eq!(err.key, "turn_in_place");
    }

    #[test]
    fn a_body_turning_in_place_meets_what_stands_beside_its_corners() {
        // A 1.6 m × 1.2 m body over a 1 m wheelbase, origin on the rear
        // axle 0.3 m from the back: it turns about (0.5, 0).
        let body = Footprint::rectangle(-0.3, 1.3, 0.6);
        let turn = |left| TurnInPlace {
            centre: Point2::new(0.5, 0.0),
            left,
            footprint: body,
            max_angle: std::f64::consts::PI,
        };
        // A point 1.0 m from the centre, straight ahead of it: the corners
        // (1.0 m from the centre at 0.8 m, 0.6 m) reach it; turning left,
        // the front-right corner swings into it.
        let ahead = Point2::new(0.5 + 0.95, 0.0);
        let left = turn(true).first_contact(ahead).unwrap();
        let right = turn(false).first_contact(ahead).unwrap();
        assert!((left - right).abs() < 1e-9, "symmetric: {left} {right}");
        // Checked against a dense walk of the turn.
        let dense = (0..=18000)
            .map(|i| i as f64 * std::f64::consts::PI / 18000.0)
            .find(|&a| {
                let pose = turn(true).pose_at(a);
                // The point in the turned body's frame.
                let (sin, cos) = pose.heading.sin_cos();
                let d = ahead - pose.position;
                body.contains(Point2::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y))
            })
            .unwrap();
        assert!((left - dense).abs() < 2e-4, "{left} vs {dense}");
        // Beyond the corners' reach nothing is met; inside the body, at once.
        assert_eq!(turn(true).first_contact(Point2::new(0.5 + 1.01, 0.0)), None);
        assert_eq!(turn(true).first_contact(Point2::new(0.5, 0.1)), Some(0.0));
        // The turn centre stays put as the origin swings round it.
        let pose = turn(true).pose_at(1.0);
        let centre = pose.transform_point(Point2::new(0.5, 0.0));
        assert!((centre - Point2::new(0.5, 0.0)).norm() < 1e-12);
        assert_eq!(turn(false).pose_at(1.0).heading, -1.0);
    }
}
