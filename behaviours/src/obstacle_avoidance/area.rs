//! The operating area's edge: where each arc's swept body first leaves the
//! area, forwards along the path its command puts the vehicle on and
//! backing up along the arc. An arc that leaves it is met like a cell (a
//! veto within `min_distance_m`, a vote rising towards 0 beyond), its cause
//! the area's edge, not a cell; backing up is clear only to the edge.

use arcnav_vehicle::mission::Area;
use arcnav_vehicle::{Arc, ArcPose, DrivenPath, Footprint, Pose};
use nalgebra::Point2;

/// Distance between the poses at which the body is checked, m.
const STEP_M: f64 = 0.5;

/// The body's outline points checked against the area, vehicle frame:
/// its corners and the middles of its sides.
fn outline(body: &Footprint) -> Vec<[f64; 2]> {
    body.outline()
        .edges()
        .flat_map(|(a, b)| [[a.x, a.y], [0.5 * (a.x + b.x), 0.5 * (a.y + b.y)]])
        .collect()
}

/// The area and the body it keeps.
#[derive(Debug, Clone)]
pub(super) struct AreaEdge {
    area: Area,
    outline: Vec<[f64; 2]>,
    /// From the rear axle to the farthest point of the body, m.
    radius: f64,
    /// Scratch: a path's poses.
    poses: Vec<(f64, ArcPose)>,
    /// Scratch: how far outside the area each outline point lies where
    /// the vehicle stands.
    standing: Vec<f64>,
}

/// A vehicle-frame pose's point in the world, for a vehicle at `pose`.
struct Placed {
    x: f64,
    y: f64,
    sin: f64,
    cos: f64,
}

impl Placed {
    fn of(pose: &Pose) -> Self {
        let p = pose.position();
        let (sin, cos) = pose.yaw().sin_cos();
        Self {
            x: p.x,
            y: p.y,
            sin,
            cos,
        }
    }
    fn world(&self, q: Point2<f64>) -> [f64; 2] {
        [
            self.x + self.cos * q.x - self.sin * q.y,
            self.y + self.sin * q.x + self.cos * q.y,
        ]
    }
}

impl AreaEdge {
    pub(super) fn new(area: Area, body: &Footprint) -> Self {
        Self {
            area,
            outline: outline(body),
            radius: body.reach(),
            poses: Vec::new(),
            standing: Vec::new(),
        }
    }

    /// Whether no path within `reach` of a vehicle at `pose` can reach the
    /// edge: well inside, every arc is clear of it.
    pub(super) fn far_inside(&self, pose: &Pose, reach: f64) -> bool {
        let p = pose.position();
        let p = [p.x, p.y];
        self.area.contains(p) && self.area.distance_to_edge(p) > reach + self.radius
    }

    /// The first of `poses` (distance along, pose in the vehicle frame)
    /// where a point of the body lies outside the area and deeper than it
    /// lay where the vehicle stands (a body already over the edge may
    /// turn back in): the distance and that point, vehicle frame.
    /// `self.standing` must hold the depths where the vehicle stands
    /// ([`AreaEdge::stand`]).
    fn first_out(&self, placed: &Placed) -> Option<(f64, [f32; 2])> {
        self.poses.iter().skip(1).find_map(|&(s, pose)| {
            self.outline
                .iter()
                .zip(&self.standing)
                .find_map(|(&[x, y], &before)| {
                    let q = pose.transform_point(Point2::new(x, y));
                    (self.depth(placed.world(q)) > before + 1e-6)
                        .then_some((s, [q.x as f32, q.y as f32]))
                })
        })
    }

    /// How far outside the area world point `w` lies (0 inside).
    fn depth(&self, w: [f64; 2]) -> f64 {
        if self.area.contains(w) {
            0.0
        } else {
            self.area.distance_to_edge(w)
        }
    }

    /// Fills `self.standing` for a vehicle placed at `placed`.
    fn stand(&mut self, placed: &Placed) {
        let mut standing = std::mem::take(&mut self.standing);
        standing.clear();
        standing.extend(
            self.outline
                .iter()
                .map(|&[x, y]| self.depth(placed.world(Point2::new(x, y)))),
        );
        self.standing = standing;
    }

    /// Per path (forwards, within `reach`): where the body first leaves the
    /// area, into `exits`.
    pub(super) fn forward(
        &mut self,
        pose: &Pose,
        paths: &[DrivenPath],
        reach: f64,
        exits: &mut [Option<(f64, [f32; 2])>],
    ) {
        exits.fill(None);
        if self.far_inside(pose, reach) {
            return;
        }
        let placed = Placed::of(pose);
        self.stand(&placed);
        for (path, exit) in paths.iter().zip(exits.iter_mut()) {
            path.sample_into(reach, STEP_M, &mut self.poses);
            *exit = self.first_out(&placed);
        }
    }

    /// How far the vehicle at `pose` may back up along curvature `k`
    /// within `reach` before its body leaves the area (None: all of it).
    /// Asked only when it is not [far inside](AreaEdge::far_inside).
    pub(super) fn backing(&mut self, pose: &Pose, k: f64, reach: f64) -> Option<f64> {
        let arc = Arc::new(k);
        let steps = (reach / STEP_M).ceil() as usize;
        self.poses.clear();
        self.poses.extend((0..=steps).map(|i| {
            let s = (i as f64 * STEP_M).min(reach);
            (s, arc.pose_at(-s))
        }));
        let placed = Placed::of(pose);
        self.stand(&placed);
        self.first_out(&placed).map(|(s, _)| s - STEP_M)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::VehicleConfig;
    use arcnav_vehicle::frames::planar_isometry;

    fn edge_ahead(at_x: f64) -> AreaEdge {
        let area = Area::rectangle([-100.0, -100.0], [at_x, 100.0]).unwrap();
        AreaEdge::new(area, &VehicleConfig::default().footprint())
    }

    #[test]
    fn the_straight_path_leaves_the_area_where_the_front_reaches_its_edge() {
        let body = VehicleConfig::default().footprint();
        let mut edge = edge_ahead(12.0);
        let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
        let paths = [DrivenPath::arc(0.0), DrivenPath::arc(0.05)];
        let mut exits = [None; 2];
        edge.forward(&pose, &paths, 18.0, &mut exits);
        let (s, at) = exits[0].expect("straight on reaches the edge");
        let expected = 12.0 - body.x_max;
        assert!(
            (s - expected).abs() <= STEP_M,
            "left at {s}, the front at {expected}"
        );
        assert!((f64::from(at[0]) - 12.0).abs() <= STEP_M);
        let (bent, _) = exits[1].expect("a gentle turn reaches it too");
        assert!(bent >= s, "no sooner than straight on");
        // Turned away from the edge, backing up never meets it.
        assert!(!edge.far_inside(&pose, 8.0));
        assert_eq!(edge.backing(&pose, 0.0, 8.0), None);
        // Far inside, nothing is computed and nothing leaves.
        let mut far = edge_ahead(90.0);
        far.forward(&pose, &paths, 18.0, &mut exits);
        assert_eq!(exits, [None, None]);
    }

    #[test]
    fn backing_up_stops_short_of_the_edge_behind() {
        let body = VehicleConfig::default().footprint();
        let area = Area::rectangle([-6.0, -100.0], [100.0, 100.0]).unwrap();
        let mut edge = AreaEdge::new(area, &body);
        let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
        // The rear bumper reaches the edge after this much backing up.
        let room = body.x_min + 6.0;
        let clear = edge.backing(&pose, 0.0, 8.0).expect("the edge is behind");
        assert!(
            clear <= room && clear >= room - 2.0 * STEP_M,
            "{clear} for {room}"
        );
    }
}
