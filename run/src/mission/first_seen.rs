//! How far ahead each drop hazard was first reported (ground truth): for
//! every hole and ditch of the world the wheels do not bridge, the range
//! from the sensor at which perception first reported it, flagged
//! (untraversable) or suspected (a suspected drop-off, graded), in any
//! image. The figure issue 63 asks of a sensor at speed: "the range at
//! which each ditch was first flagged or suspected" (today's certain
//! range from one image, `R²·δθ/H` for the lidar: see
//! [`crate::speed_bound`]).
//!
//! A report names a hazard when one of its cells, flagged or suspected,
//! has its centre within [`MARGIN_CELLS`] cells of the hazard's ground
//! shape: a hole's near edge is reported on the last ground before it.
//! The range is from the reporting sensor at the image's capture time to
//! the nearest point of the shape.

use std::collections::VecDeque;

use arcnav_perception::{ObstacleReport, SensorModel};
use arcnav_sim::{Feature, FeatureKind, World};
use arcnav_vehicle::Utime;
use arcnav_vehicle::VehicleConfig;
use arcnav_vehicle::time::micros_to_seconds;
use serde::Serialize;

/// A cell this many cells from a hazard's ground shape reports it.
pub const MARGIN_CELLS: f64 = 2.0;
/// Poses kept to place a report's sensor: images are judged within a
/// second or two of their capture.
const POSES_KEPT_US: Utime = 5_000_000;

/// One drop hazard and when it was first reported.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DropFirstSeen {
    /// What it is (`ditch 0.80 m deep`), and where: the middle of its axis.
    pub hazard: String,
    pub at: [f64; 2],
    /// The range from the sensor when first reported, m; absent when no
    /// image reported it.
    pub first_range_m: Option<f64>,
    /// Seconds from the start when that image was captured.
    pub first_at_s: Option<f64>,
    /// Whether the first report suspected it only (graded) rather than
    /// flagged it.
    pub suspected: Option<bool>,
}

#[derive(Debug)]
struct Watched {
    feature: Feature,
    hazard: String,
    /// The shape's box widened by the margin.
    bounds: [f64; 4],
    first: Option<(Utime, f64, bool)>,
}

/// Watches the reports of a mission for the world's drop hazards.
#[derive(Debug)]
pub struct DropWatch {
    watched: Vec<Watched>,
    /// (time, rear-axle x, y, yaw) of the recent ticks.
    poses: VecDeque<(Utime, [f64; 3])>,
    /// Each sensor's id and its mount's horizontal offset (x, y).
    mounts: Vec<(String, [f64; 2])>,
}

impl DropWatch {
    pub fn new(world: &World, vehicle: &VehicleConfig, sensors: &[SensorModel]) -> Self {
        let watched = world
            .features
            .iter()
            .filter(|f| matches!(f.kind, FeatureKind::Hole | FeatureKind::Ditch))
            .filter_map(|f| {
                let hazard = f.hazard(vehicle)?;
                Some(Watched {
                    feature: *f,
                    hazard,
                    bounds: f.bounds(),
                    first: None,
                })
            })
            .collect();
        let mounts = sensors
            .iter()
            .map(|s| {
                let t = s.vehicle_from_sensor.translation.vector;
                (s.id.clone(), [t.x, t.y])
            })
            .collect();
        Self {
            watched,
            poses: VecDeque::new(),
            mounts,
        }
    }

    /// Whether every hazard has been reported (or there is none): nothing
    /// is left to watch for.
    fn all_reported(&self) -> bool {
        self.watched.iter().all(|w| w.first.is_some())
    }

    /// The vehicle's true pose at tick `t`: rear-axle (x, y), yaw.
    pub fn pose(&mut self, t: Utime, pose: [f64; 3]) {
        if self.all_reported() {
            return;
        }
        self.poses.push_back((t, pose));
        while self
            .poses
            .front()
            .is_some_and(|&(old, _)| t - old > POSES_KEPT_US)
        {
            self.poses.pop_front();
        }
    }

    /// Where the sensor that made `report` stood at its capture time, if
    /// a pose of then is kept.
    fn sensor_at(&self, report: &ObstacleReport) -> Option<[f64; 2]> {
        let (_, [x, y, yaw]) = *self.poses.iter().rev().find(|(t, _)| *t <= report.utime)?;
        let [mx, my] = self
            .mounts
            .iter()
            .find(|(id, _)| *id == report.sensor)
            .map_or([0.0, 0.0], |(_, m)| *m);
        let (sin, cos) = yaw.sin_cos();
        Some([x + cos * mx - sin * my, y + sin * mx + cos * my])
    }

    /// Takes in one of perception's reports.
    pub fn report(&mut self, report: &ObstacleReport) {
        if self.all_reported() {
            return;
        }
        let Some(sensor) = self.sensor_at(report) else {
            return;
        };
        let margin = MARGIN_CELLS * report.cell_size_m;
        for watched in self.watched.iter_mut().filter(|w| w.first.is_none()) {
            let [x0, y0, x1, y1] = watched.bounds;
            let mut suspected_only = None;
            for cell in &report.cells {
                let (obstacle, suspected) = (cell.is_obstacle(), cell.is_suspected_drop_off());
                if !(obstacle || suspected)
                    || cell.x < x0 - margin
                    || cell.x > x1 + margin
                    || cell.y < y0 - margin
                    || cell.y > y1 + margin
                    || watched.feature.distance([cell.x, cell.y]) > margin
                {
                    continue;
                }
                if obstacle {
                    suspected_only = Some(false);
                    break;
                }
                suspected_only = Some(true);
            }
            if let Some(suspected) = suspected_only {
                let range = watched.feature.distance(sensor);
                watched.first = Some((report.utime, range, suspected));
            }
        }
    }

    /// Every drop hazard, in the world's order, with when it was first
    /// reported (times from `t0`).
    pub fn first_seen(&self, t0: Utime) -> Vec<DropFirstSeen> {
        self.watched
            .iter()
            .map(|w| {
                let f = &w.feature;
                DropFirstSeen {
                    hazard: w.hazard.clone(),
                    at: [(f.a[0] + f.b[0]) / 2.0, (f.a[1] + f.b[1]) / 2.0],
                    first_range_m: w.first.map(|(_, r, _)| r),
                    first_at_s: w.first.map(|(t, _, _)| micros_to_seconds(t - t0)),
                    suspected: w.first.map(|(_, _, s)| s),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use arcnav_perception::{ObstacleCell, Reasons};

    use super::*;

    /// A 1 m deep ditch 0.8 m wide across x = 50 from y = -1.5 to 1.5.
    fn world() -> World {
        let text = "name = \"one_ditch\"\n\
                    [terrain]\norigin_m = [-10.0, -20.0]\nsize_m = [100.0, 40.0]\n\
                    [start]\nposition_m = [0.0, 0.0]\nheading_deg = 0.0\n\
                    [[waypoints]]\nposition_m = [80.0, 0.0]\n\
                    [[ditches]]\nfrom_m = [50.0, -1.5]\nto_m = [50.0, 1.5]\nwidth_m = 0.8\ndepth_m = 1.0\n";
        World::from_toml(text, "one_ditch.toml", None).unwrap()
    }

    fn cell(x: f64, y: f64, reasons: Reasons, cost: f32) -> ObstacleCell {
        ObstacleCell {
            x,
            y,
            z_min: 0.0,
            z_max: 0.0,
            reasons,
            region: 0,
            cost,
        }
    }

    fn report(utime: Utime, sensor: &str, cells: Vec<ObstacleCell>) -> ObstacleReport {
        ObstacleReport {
            utime,
            sensor: sensor.to_owned(),
            cell_size_m: 0.5,
            cells,
            ..ObstacleReport::default()
        }
    }

    #[test]
    fn a_ditch_is_first_seen_from_the_sensor_where_the_image_was_taken() {
        let sensor = SensorModel::lidar64();
        let mount = sensor.vehicle_from_sensor.translation.vector;
        let mut watch = DropWatch::new(
            &world(),
            &VehicleConfig::default(),
            std::slice::from_ref(&sensor),
        );
        for k in 0..=10 {
            watch.pose(k * 100_000, [k as f64, 0.0, 0.0]);
        }
        let flagged = cell(49.3, 0.2, Reasons::DISCONTINUITY, 1.0);
        let suspected = cell(49.4, -0.3, Reasons::DROP_OFF, 0.5);
        let graded = cell(49.5, 0.0, Reasons::NONE, 0.5);
        let far_off = cell(30.0, 0.0, Reasons::DISCONTINUITY, 1.0);
        // Graded ground that is no suspected drop-off, and an obstacle far
        // from the ditch, report nothing of it.
        watch.report(&report(200_000, &sensor.id, vec![graded, far_off]));
        assert_eq!(watch.first_seen(0)[0].first_range_m, None);
        // Suspected from the image of 0.5 s, its sensor 5 m along plus the
        // mount, to the ditch's near edge at 49.6.
        watch.report(&report(500_000, &sensor.id, vec![suspected]));
        // A later image flagging it changes nothing.
        watch.report(&report(900_000, &sensor.id, vec![flagged]));
        let seen = watch.first_seen(0);
        assert_eq!(seen.len(), 1);
        assert_eq!(seen[0].hazard, "ditch 1.00 m deep");
        let range = seen[0].first_range_m.unwrap();
        assert!(
            (range - (49.6 - 5.0 - mount.x)).abs() < 1e-9,
            "{range} m, mount {mount:?}"
        );
        assert_eq!(seen[0].first_at_s, Some(0.5));
        assert_eq!(seen[0].suspected, Some(true));
    }

    #[test]
    fn a_flagged_cell_counts_over_a_suspected_one_of_the_same_image_and_a_bridged_ditch_is_no_hazard()
     {
        let sensor = SensorModel::lidar64();
        let mut watch = DropWatch::new(
            &world(),
            &VehicleConfig::default(),
            std::slice::from_ref(&sensor),
        );
        watch.pose(0, [10.0, 0.0, 0.0]);
        let cells = vec![
            cell(49.4, -0.3, Reasons::DROP_OFF, 0.5),
            cell(50.6, 0.0, Reasons::DISCONTINUITY, 1.0),
        ];
        watch.report(&report(0, &sensor.id, cells));
        assert_eq!(watch.first_seen(0)[0].suspected, Some(false));
        // A ditch no deeper than the step the vehicle drives over.
        let shallow = VehicleConfig {
            tolerated_step_m: 2.0,
            ..VehicleConfig::default()
        };
        assert!(
            DropWatch::new(&world(), &shallow, &[sensor])
                .first_seen(0)
                .is_empty()
        );
    }
}
