//! The returns that stand above the ground or lie far below it, found from
//! the returns themselves: each column of beams is a profile of the ground
//! along its heading.
//!
//! Taken from the lowest beam up, a column's returns run outward over the
//! ground. Each return `(d, z)` (horizontal distance from the sensor,
//! height in the vehicle's level frame) is judged against every return
//! before it that was judged ground, `(d_k, z_k)` — at first the ground
//! under the sensor:
//!
//! ```text
//! standing  if  z − z_k >  (d − d_k)·tan(max_slope) + step + noise   for some k
//! a hole    if  z_k − z >  (d − d_k)·tan(max_slope) + step + noise   for some k
//! ground    otherwise
//! ```
//!
//! `step` is `vehicle.tolerated_step_m`, `max_slope` is
//! `vehicle.max_slope_deg` and `noise` is `guard.ground_noise_m`: the
//! ground rises and falls no more steeply than the vehicle climbs, give or
//! take a step the wheels take, and whatever rises or falls from it by more
//! is something they cannot. The step is allowed on top of the slope, not
//! beside it: real ground is steeper than `max_slope` over a metre here
//! and there on a hillside the vehicle drives (its attitude follows the
//! ground over its wheelbase), and a slope test alone there sees holes. "For some k", not "from the last
//! ground return": the beams landing on the face of a wall, each a few
//! centimetres above the one before, must not carry the ground up the
//! wall. Only the lowest `z_k − d_k·tan` and the highest `z_k + d_k·tan`
//! decide, so the pass keeps those two. No cells, no evaluator, no map: one
//! pass over the returns.
//!
//! A hole shows this way only where the rays that pass its near edge come
//! down into it more steeply than `max_slope`: a sensor `H` up sees the
//! far wall of a hole whose edge is `R` out at most `w·H/R` down over the
//! hole's width `w`, so within `R < H / tan(max_slope)` (4.7 m from the
//! ERIM 2.2 m up, 5.1 m from a lidar 2.4 m up, at 25°). Farther, what the
//! column shows of a hole is its shadow and its far wall: a stretch of
//! ground the rays pass over without meeting it, longer than the wheels
//! bridge (`max_gap_m`, the `2·sqrt(2·r·step − step²)` of a wheel of
//! radius `r` rolling over a step), and then, within `max_gap_m` of the
//! shadow's far side, a return standing above the ones beyond it (the wall
//! rising out of the hole to its far lip). The shadow is not the gap
//! between two returns: far out the beams land farther apart than the
//! wheels bridge on any ground (1.8 m at 22 m from 2 m up, beams 0.25°
//! apart), and downhill farther still. It is how far short of the return
//! beyond the gap, at `(d_{k+1}, z_{k+1})`, the ray to it would have met the
//! ground going on from the ground return `(d_k, z_k)` before the gap at
//! the column's grade `g` (its rise per m over the last `max_gap_m` of
//! ground, within ±tan(max_slope)); from a sensor at height `z_s`, the ray
//! comes down `t = (z_s − z_{k+1}) / d_{k+1}` per m and meets that ground at
//! `(z_s − z_k + g·d_k) / (t + g)`:
//!
//! ```text
//! hole edge at k  if  d_{k+1} − (z_s − z_k + g·d_k) / (t + g) > max_gap,
//!                     z_{k+1} < z_k + g·(d_{k+1} − d_k) − noise,  t + g > 0,  and some j > k with
//!                     d_j ≤ d_{k+1} + max_gap is standing (all of k+1 … j−1 ground)
//!                     and z_j ≤ z_k + g·(d_j − d_k) + noise
//! ```
//!
//! The last line: a far wall rises out of the hole no higher than the
//! ground at the near edge's level, so a hole is seen only where it is
//! deeper than a step below that level; what stands higher stands on the
//! ground (a tree behind a 7 cm dip 30 m out) and is judged standing. On level ground (`g = 0`) the shadow is `d_{k+1}·(z_k − z_{k+1}) / (z_s −
//! z_{k+1})`, the hole's width `w` for a far wall seen `w·H/R` down. Only a
//! ground return starts a shadow: the gap behind something standing is its
//! own shadow, not a hole's. A crest the ground falls away behind gently
//! leaves a shadow too, but no wall rises beyond it; a dropout leaves a gap
//! with the ground beyond where the grade puts it. Holes whose far wall is
//! out of the beams' reach are
//! perception's to find over several frames.

use arcnav_perception::BeamTable;
use arcnav_vehicle::frames::Isometry;
use nalgebra::{Point3, Vector3};

/// What a hazardous return is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum HazardKind {
    /// It stands above the ground profile.
    Standing,
    /// It lies far below it (a ditch, a drop).
    Hole,
}

impl HazardKind {
    /// The name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Standing => "obstacle",
            Self::Hole => "hole",
        }
    }
}

/// One hazardous return, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hazard {
    pub position: Point3<f64>,
    pub kind: HazardKind,
    /// How far above (standing) or below (hole) the ground profile, m.
    pub height_m: f64,
}

/// The ground-profile test's thresholds.
#[derive(Debug, Clone, Copy)]
pub struct Profile {
    /// `vehicle.tolerated_step_m`.
    pub step_m: f64,
    /// tan(`vehicle.max_slope_deg`).
    pub max_rise_per_m: f64,
    /// Returns farther than this from the vehicle are not reported, m.
    pub range_m: f64,
    /// `guard.ground_noise_m`.
    pub noise_m: f64,
    /// The longest gap the wheels bridge, m (see the module documentation).
    pub max_gap_m: f64,
    /// The guard's cells, m: columns are walked only as densely as these
    /// can tell apart at `range_m` (see [`Profile::column_stride`]).
    pub cell_m: f64,
}

impl Profile {
    /// Every how many columns of a sensor whose columns are `spacing_rad`
    /// apart are walked: as many as keep the walked columns no farther
    /// apart than a cell at `range_m` (`cell_m / (range_m·spacing)`,
    /// rounded down, at least 1). Every cell within range is then crossed
    /// by a walked column in every row; denser columns add returns to cells
    /// that hold some already, at a cost per return (a 2048-column lidar:
    /// 9 cm apart at 30 m, every second column; a 256-column ERIM, every
    /// one).
    pub fn column_stride(&self, spacing_rad: f64) -> usize {
        let walked = self.cell_m / (self.range_m * spacing_rad.abs());
        if walked.is_finite() && walked >= 1.0 {
            walked.floor().min(64.0) as usize
        } else {
            1
        }
    }

    /// The gap a wheel of `wheel_radius_m` rolls over without dropping more
    /// than `step_m`: `2·sqrt(2·r·step − step²)`, m.
    pub fn bridged_gap_m(wheel_radius_m: f64, step_m: f64) -> f64 {
        let step = step_m.min(wheel_radius_m);
        2.0 * (2.0 * wheel_radius_m * step - step * step).max(0.0).sqrt()
    }
}

/// A block of returns: `rows × cols` ranges (row-major), the beams of its
/// rows and columns, and where its sensor was.
pub struct Returns<'a> {
    pub beams: &'a BeamTable,
    pub range: &'a [f32],
    pub vehicle_from_sensor: &'a Isometry,
    /// The vehicle when the returns were taken.
    pub world_from_vehicle: &'a Isometry,
}

/// How many returns a block had, and how many were hazardous.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Found {
    pub returns: u64,
    pub standing: u64,
    pub holes: u64,
}

/// What a column's walk holds between its returns.
#[derive(Debug, Clone, Copy)]
struct Column {
    /// (z_k − d_k·tan, z_k) at the lowest, (z_k + d_k·tan, z_k) at the
    /// highest.
    low: (f64, f64),
    high: (f64, f64),
    /// The last return (d, z, point) if it was ground, and a hole's near
    /// edge waiting for its far wall (the point, its d, the grade there,
    /// the shadow's far side d).
    last: Option<(f64, f64, Point3<f64>)>,
    edge: Option<(Point3<f64>, f64, f64, f64)>,
    /// The ground's grade (rise per m, within ±tan(max_slope)) over the
    /// last `max_gap_m` or more of ground, and the return it ends at (d, z).
    grade: f64,
    anchor: (f64, f64),
}

impl Column {
    /// Before its first return: the ground under the sensor at `z`.
    fn new(z: f64) -> Self {
        Self {
            low: (z, z),
            high: (z, z),
            last: None,
            edge: None,
            grade: 0.0,
            anchor: (0.0, z),
        }
    }
}

impl Profile {
    /// Walks each column of `returns` and pushes its hazardous returns onto
    /// `out`. Ranges that are not finite and positive are no return.
    pub fn hazards(&self, returns: &Returns<'_>, out: &mut Vec<Hazard>) -> Found {
        let beams = returns.beams;
        let (rows, cols) = (beams.rows(), beams.cols());
        let mut found = Found::default();
        if rows * cols != returns.range.len() {
            return found;
        }
        let level = arcnav_vehicle::frames::level_frame(returns.world_from_vehicle);
        let level_from_vehicle = level.inverse() * returns.world_from_vehicle;
        let level_from_sensor = level_from_vehicle * returns.vehicle_from_sensor;
        let sensor = level_from_sensor.translation.vector;
        // The ground under the sensor: where the vertical through it meets
        // the vehicle frame's ground plane (z = 0, the wheels' contact).
        // Not the plane's point under the mount: on a side slope the
        // vehicle's roll sets that aside from the sensor, uphill, and a
        // column running downhill would start too high.
        let origin = level_from_vehicle.translation.vector;
        let normal = level_from_vehicle.rotation * Vector3::z();
        let under_z = origin.z
            - (normal.x * (sensor.x - origin.x) + normal.y * (sensor.y - origin.y))
                / normal.z.max(f64::EPSILON);
        // Lowest beam first.
        let mut order: Vec<usize> = (0..rows).collect();
        order.sort_by(|&a, &b| beams.elevation[a].total_cmp(&beams.elevation[b]));
        let order: Vec<(usize, f64, f64)> = order
            .into_iter()
            .map(|row| {
                let (sin, cos) = f64::from(beams.elevation[row]).sin_cos();
                (row, sin, cos)
            })
            .collect();
        let rotation = level_from_sensor.rotation.to_rotation_matrix();
        // A beam's direction in the level frame is cos(el)·R·(cos az, sin
        // az, 0) + sin(el)·R·z: the column's part once per frame, the
        // row's two numbers per return.
        let up = rotation * Vector3::z();
        let (to_world, shift) = (
            level.rotation.to_rotation_matrix(),
            level.translation.vector,
        );
        let world = |p: Point3<f64>| to_world * p + shift;
        let range2 = self.range_m * self.range_m;
        let slope = self.max_rise_per_m;
        // Each column walked from its lowest beam up, all columns a row at
        // a time (the rows are contiguous in memory).
        let spacing = if cols > 1 {
            f64::from(beams.azimuth[cols - 1] - beams.azimuth[0]) / (cols - 1) as f64
        } else {
            0.0
        };
        let stride = self.column_stride(spacing);
        let azimuths: Vec<Vector3<f64>> = beams
            .azimuth
            .iter()
            .step_by(stride)
            .map(|&az| {
                let (sin, cos) = f64::from(az).sin_cos();
                rotation * Vector3::new(cos, sin, 0.0)
            })
            .collect();
        let mut state = vec![Column::new(under_z); azimuths.len()];
        // A row's returns in the level frame first, in a loop of plain
        // arithmetic the compiler vectorises (x, y, z, the horizontal
        // distance; NaN where there is no return), then each column's walk.
        let mut points = vec![[0.0f64; 4]; azimuths.len()];
        for &(row, sin_el, cos_el) in &order {
            let ranges = returns.range[row * cols..(row + 1) * cols]
                .iter()
                .step_by(stride);
            let up = up * sin_el;
            for ((&r, across_dir), point) in ranges.zip(&azimuths).zip(&mut points) {
                let r = f64::from(r);
                let valid = r.is_finite() && r > 0.0;
                let r = if valid { r } else { 0.0 };
                let x = sensor.x + (across_dir.x * cos_el + up.x) * r;
                let y = sensor.y + (across_dir.y * cos_el + up.y) * r;
                let z = sensor.z + (across_dir.z * cos_el + up.z) * r;
                let (dx, dy) = (x - sensor.x, y - sensor.y);
                let across = (dx * dx + dy * dy).sqrt();
                *point = [x, y, z, if valid { across } else { f64::NAN }];
            }
            for (&[x, y, z, across], column) in points.iter().zip(&mut state) {
                if across.is_nan() {
                    continue;
                }
                found.returns += 1;
                let p = Vector3::new(x, y, z);
                let (low, high) = (column.low, column.high);
                let above = p.z - (low.0 + across * slope + self.noise_m);
                let below = (high.0 - across * slope - self.noise_m) - p.z;
                let kind = if above > self.step_m {
                    HazardKind::Standing
                } else if below > self.step_m {
                    HazardKind::Hole
                } else {
                    // The shadow: how far short of this return the ray
                    // would have met the ground going on at its grade from
                    // the last (with descent = (H − z)/across + grade, the
                    // shadow is across − (H − z_k + grade·d_k)/descent;
                    // multiplied out by across·descent > 0, no division).
                    let grade = column.grade.min(0.0);
                    let after_gap = column.last.filter(|&(d, z, _)| {
                        let drop = z + grade * (across - d) - p.z;
                        let descent_across = sensor.z - p.z + grade * across;
                        drop > self.noise_m
                            && descent_across > f64::EPSILON * across
                            && (across - self.max_gap_m) * descent_across
                                > (sensor.z - z + grade * d) * across
                    });
                    if p.z - across * slope < low.0 {
                        column.low = (p.z - across * slope, p.z);
                    }
                    if p.z + across * slope > high.0 {
                        column.high = (p.z + across * slope, p.z);
                    }
                    column.last = Some((across, p.z, Point3::from(p)));
                    let (d0, z0) = column.anchor;
                    if across - d0 >= self.max_gap_m {
                        column.grade = ((p.z - z0) / (across - d0)).clamp(-slope, slope);
                        column.anchor = (across, p.z);
                    }
                    if let Some((d, _, near)) = after_gap {
                        column.edge = Some((near, d, grade, across));
                    } else if column
                        .edge
                        .is_some_and(|(.., far)| across > far + self.max_gap_m)
                    {
                        column.edge = None;
                    }
                    continue;
                };
                // A return far below the ground: the vehicle meets the
                // hole at its near edge, the last ground return before it
                // (held as a hole too, once per edge), not where the ray
                // met the floor or the far wall.
                if kind == HazardKind::Hole
                    && let Some((_, z, near)) = column.last
                    && near.x * near.x + near.y * near.y <= range2
                {
                    found.holes += 1;
                    out.push(Hazard {
                        position: world(near),
                        kind: HazardKind::Hole,
                        height_m: z - p.z,
                    });
                }
                // A gap after a hazard is its shadow, not a hole's.
                column.last = None;
                // The far wall rises out of the hole no higher than the
                // ground at the near edge's level: what stands above that
                // stands on the ground, and is judged standing.
                if kind == HazardKind::Standing
                    && let Some((near, d, grade, _)) = column.edge.take()
                    && p.z <= near.z + grade * (across - d) + self.noise_m
                    && near.x * near.x + near.y * near.y <= range2
                {
                    found.holes += 1;
                    out.push(Hazard {
                        position: world(near),
                        kind: HazardKind::Hole,
                        height_m: near.z - low.1,
                    });
                }
                if p.x * p.x + p.y * p.y > range2 {
                    continue;
                }
                let height_m = match kind {
                    HazardKind::Standing => {
                        found.standing += 1;
                        p.z - low.1
                    }
                    HazardKind::Hole => {
                        found.holes += 1;
                        high.1 - p.z
                    }
                };
                out.push(Hazard {
                    position: world(Point3::from(p)),
                    kind,
                    height_m,
                });
            }
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    /// One column looking straight ahead from 2 m up, beams from -40° to
    /// 0° every 0.25°, over ground given as height(x).
    fn column(height: impl Fn(f64) -> f64, obstacle: Option<(f64, f64)>) -> Vec<Hazard> {
        let rows = 161;
        let beams = BeamTable {
            elevation: (0..rows)
                .map(|k| (-(k as f32) / 4.0).to_radians())
                .collect(),
            azimuth: vec![0.0],
        };
        let mount = isometry_from_xyz_rpy([1.0, 0.0, 2.0], 0.0, 0.0, 0.0);
        // Range to the first crossing, marched finely.
        let range: Vec<f32> = beams
            .elevation
            .iter()
            .map(|&el| {
                let (s, c) = f64::from(el).sin_cos();
                let mut t = 0.0;
                while t < 60.0 {
                    t += 0.005;
                    let (x, z) = (1.0 + c * t, 2.0 + s * t);
                    let top = match obstacle {
                        Some((at, h)) if (at..at + 0.5).contains(&x) => height(x) + h,
                        _ => height(x),
                    };
                    if z <= top {
                        return t as f32;
                    }
                }
                f32::NAN
            })
            .collect();
        let world = isometry_from_xyz_rpy([0.0, 0.0, 0.0], 0.0, 0.0, 0.0);
        judge(&beams, &range, &mount, &world).1
    }

    /// The hazards a vehicle with 0.4 m wheels, a 0.2 m step and a 25°
    /// slope limit finds in `range`.
    fn judge(
        beams: &BeamTable,
        range: &[f32],
        mount: &Isometry,
        world: &Isometry,
    ) -> (Found, Vec<Hazard>) {
        let profile = Profile {
            step_m: 0.2,
            max_rise_per_m: 25f64.to_radians().tan(),
            range_m: 30.0,
            noise_m: 0.05,
            max_gap_m: Profile::bridged_gap_m(0.4, 0.2),
            cell_m: 0.2,
        };
        let mut out = Vec::new();
        let found = profile.hazards(
            &Returns {
                beams,
                range,
                vehicle_from_sensor: mount,
                world_from_vehicle: world,
            },
            &mut out,
        );
        (found, out)
    }

    #[test]
    fn level_ground_and_a_slope_the_vehicle_climbs_are_ground() {
        assert!(column(|_| 0.0, None).is_empty());
        // 20° up from 6 m on: steep, but climbable.
        let slope = |x: f64| (x - 6.0).max(0.0) * 20f64.to_radians().tan();
        assert!(column(slope, None).is_empty());
    }

    #[test]
    fn a_box_standing_on_the_ground_is_standing() {
        let found = column(|_| 0.0, Some((8.0, 0.6)));
        assert!(!found.is_empty());
        for h in &found {
            assert_eq!(h.kind, HazardKind::Standing);
            assert!((8.0..8.6).contains(&h.position.x), "{h:?}");
            assert!(h.height_m > 0.2, "{h:?}");
        }
        // A step the wheels take is not.
        assert!(column(|_| 0.0, Some((8.0, 0.15))).is_empty());
    }

    /// Columns are walked as densely as the cells tell apart at range: a
    /// 2048-column lidar every second column (9 cm apart at 30 m), the
    /// 256-column ERIM every one, never none.
    #[test]
    fn columns_are_walked_as_densely_as_cells_at_range_tell_apart() {
        let profile = Profile {
            step_m: 0.2,
            max_rise_per_m: 0.47,
            range_m: 30.0,
            noise_m: 0.05,
            max_gap_m: 0.7,
            cell_m: 0.2,
        };
        use arcnav_perception::SensorModel;
        let stride = |sensor: SensorModel| {
            let az = &sensor.beams.azimuth;
            let spacing = f64::from(az[az.len() - 1] - az[0]) / (az.len() - 1) as f64;
            profile.column_stride(spacing)
        };
        assert_eq!(stride(SensorModel::lidar64()), 2);
        assert_eq!(stride(SensorModel::lidar128()), 2);
        assert_eq!(stride(SensorModel::erim()), 1);
        assert_eq!(profile.column_stride(0.0), 1);
        assert_eq!(profile.column_stride(f64::NAN), 1);
    }

    #[test]
    fn the_far_floor_of_a_ditch_is_a_hole() {
        // 1.5 m deep from 4 to 6 m: its edge 3 m from the sensor, within
        // H / tan(max_slope) = 4.3 m.
        let ditch = |x: f64| if (4.0..6.0).contains(&x) { -1.5 } else { 0.0 };
        let found = column(ditch, None);
        assert!(
            found.iter().any(|h| h.kind == HazardKind::Hole),
            "{found:?}"
        );
        // The near edge is a hole: the last ground return before the floor
        // (where a wheel would drop), within a return's spacing of it.
        assert!(
            found
                .iter()
                .any(|h| h.kind == HazardKind::Hole && (3.5..4.0).contains(&h.position.x)),
            "{found:?}"
        );
        // Every hazard is at the edge, in the ditch or just beyond: its far
        // wall rises steeply from the floor seen (a wall too, standing), and
        // so does the ground beyond until it is as far from the floor as
        // its depth allows at max_slope.
        for h in &found {
            assert!((3.5..6.0 + 1.5 / 0.46).contains(&h.position.x), "{h:?}");
        }
    }

    #[test]
    fn a_far_ditch_is_a_hole_at_its_near_edge_from_its_shadow_and_far_wall() {
        // 10 m out the far wall is seen too little below the edge to tell
        // it from a dip; its top rising to the far lip, beyond the ditch's
        // shadow, makes the edge a hole.
        let far = |x: f64| if (11.0..13.0).contains(&x) { -1.5 } else { 0.0 };
        let found = column(far, None);
        let holes: Vec<_> = found
            .iter()
            .filter(|h| h.kind == HazardKind::Hole)
            .collect();
        assert_eq!(holes.len(), 1, "{found:?}");
        assert!((10.5..=11.0).contains(&holes[0].position.x), "{holes:?}");
        // Narrower than the wheels bridge: no hole.
        let narrow = |x: f64| if (11.0..11.5).contains(&x) { -1.5 } else { 0.0 };
        assert!(
            column(narrow, None)
                .iter()
                .all(|h| h.kind != HazardKind::Hole)
        );
        // A crest the ground falls away behind at 15° leaves a shadow but
        // no wall: no hole, nothing standing.
        let crest = |x: f64| {
            let rise = 10f64.to_radians().tan();
            if x < 8.0 {
                x * rise
            } else {
                8.0 * rise - (x - 8.0) * 15f64.to_radians().tan()
            }
        };
        assert!(column(crest, None).is_empty(), "{:?}", column(crest, None));
    }

    #[test]
    fn far_beams_spaced_wider_than_the_wheels_bridge_and_a_downhill_are_no_hole() {
        // 22 m out the beams land 1.8 m apart on level ground: a box there
        // behind a 6 cm dip leaves no shadow longer than the dip explains.
        let dip = |x: f64| {
            if (20.0..22.0).contains(&x) {
                -0.06
            } else {
                0.0
            }
        };
        let found = column(dip, Some((22.0, 0.6)));
        assert!(found.iter().any(|h| h.kind == HazardKind::Standing));
        assert!(
            found.iter().all(|h| h.kind != HazardKind::Hole),
            "{found:?}"
        );
        // Nor does ground going down at 12° to a box: its grade explains
        // the rays landing far apart.
        let down = |x: f64| -(x - 8.0).max(0.0) * 12f64.to_radians().tan();
        let found = column(down, Some((15.0, 0.6)));
        assert!(found.iter().any(|h| h.kind == HazardKind::Standing));
        assert!(
            found.iter().all(|h| h.kind != HazardKind::Hole),
            "{found:?}"
        );
    }

    #[test]
    fn a_side_slope_the_vehicle_stands_rolled_on_is_ground_all_round() {
        // Rolled 24° on a plane falling to its right, the sensor 2 m up
        // stands 0.8 m downhill of the ground under its mount: the columns
        // running downhill start from the ground under the sensor.
        let roll = 24f64.to_radians();
        let world = isometry_from_xyz_rpy([0.0, 0.0, 0.0], roll, 0.0, 0.0);
        let normal = world.rotation * Vector3::z();
        let ground = |x: f64, y: f64| -(normal.x * x + normal.y * y) / normal.z;
        let mount = isometry_from_xyz_rpy([1.0, 0.0, 2.0], 0.0, 0.0, 0.0);
        let beams = BeamTable {
            elevation: (0..121).map(|k| (-(k as f32) / 4.0).to_radians()).collect(),
            azimuth: (0..36).map(|k| (k as f32 * 10.0).to_radians()).collect(),
        };
        let sensor = world * mount;
        let mut range = Vec::new();
        for &el in &beams.elevation {
            for &az in &beams.azimuth {
                let (se, ce) = f64::from(el).sin_cos();
                let (sa, ca) = f64::from(az).sin_cos();
                let dir = sensor.rotation * Vector3::new(ce * ca, ce * sa, se);
                let o = sensor.translation.vector;
                let hit = (1..12_000)
                    .map(|k| f64::from(k) * 0.005)
                    .find(|t| o.z + dir.z * t <= ground(o.x + dir.x * t, o.y + dir.y * t));
                range.push(hit.map_or(f32::NAN, |t| t as f32));
            }
        }
        let (found, out) = judge(&beams, &range, &mount, &world);
        assert!(found.returns > 2000, "{found:?}");
        assert!(out.is_empty(), "{found:?}: {:?}", &out[..out.len().min(3)]);
    }
}
