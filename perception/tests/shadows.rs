//! Shadows: ground inside an image's footprint that the image did not see,
//! on images rendered from analytic scenes, from a vehicle standing
//! somewhere in the world and facing some way (so the world frame is tested,
//! not only the vehicle's).

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{ObstacleReport, PerceptionConfig, RangeImage, SensorModel, ShadowIndex};
use arcnav_vehicle::Isometry;
use arcnav_vehicle::frames::planar_isometry;

/// The vehicle stands at (40, -25) facing 120°.
fn pose() -> Isometry {
    planar_isometry(40.0, -25.0, 120f64.to_radians())
}

/// World position of vehicle-frame (`x`, `y`).
fn world(x: f64, y: f64) -> (f64, f64) {
    let p = pose() * nalgebra::Point3::new(x, y, 0.0);
    (p.x, p.y)
}

/// The report of one image of `height` (a function of vehicle-frame x, y).
fn report(sensor: &SensorModel, height: impl Fn(f64, f64) -> f64 + Sync) -> ObstacleReport {
    let inverse = pose().inverse();
    let in_world = move |x: f64, y: f64| {
        let p = inverse * nalgebra::Point3::new(x, y, 0.0);
        height(p.x, p.y)
    };
    evaluate(&sensor.render(0, &pose(), &HeightFunction::new(in_world)))
}

/// The report of `image`, taken from [`pose`].
fn evaluate(image: &RangeImage) -> ObstacleReport {
    let mut report = ObstacleReport::default();
    PerceptionConfig::default()
        .build_evaluator()
        .unwrap()
        .evaluate(image, &pose(), &mut report)
        .unwrap();
    report
}

fn index(report: &ObstacleReport) -> ShadowIndex {
    let mut index = ShadowIndex::default();
    index.build(&report.shadows);
    index
}

/// Fraction of the vehicle-frame points in a shadow.
fn shadowed(index: &ShadowIndex, points: impl IntoIterator<Item = (f64, f64)>) -> f64 {
    let (mut inside, mut all) = (0, 0);
    for (x, y) in points {
        let (wx, wy) = world(x, y);
        inside += usize::from(index.contains(wx, wy));
        all += 1;
    }
    inside as f64 / all as f64
}

/// Points of a rectangle, vehicle frame, every 10 cm.
fn area(x: (f64, f64), y: (f64, f64)) -> Vec<(f64, f64)> {
    let steps = |(a, b): (f64, f64)| {
        let n = ((b - a) / 0.1).round() as usize;
        (0..=n).map(move |k| a + (b - a) * k as f64 / n as f64)
    };
    steps(x)
        .flat_map(|px| steps(y).map(move |py| (px, py)))
        .collect()
}

fn sensors() -> [SensorModel; 2] {
    [SensorModel::erim(), SensorModel::lidar128()]
}

#[test]
fn the_ground_beyond_a_wide_trenchs_near_edge_is_a_shadow() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    // 8 m wide and 2 m deep: from afar its floor is seen beyond a long
    // shadow, and the edge looks like the crest of a gentle slope. The
    // ground just beyond the edge must not count as seen.
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        for near in [12.0, 16.0, 20.0] {
            let trench = move |x: f64, _: f64| {
                if (near..near + 8.0).contains(&x) {
                    -2.0
                } else {
                    0.0
                }
            };
            let report = report(&sensor, trench);
            let index = index(&report);
            let beyond = shadowed(&index, area((near + 0.2, near + 1.5), (-3.0, 3.0)));
            assert!(
                beyond > 0.97,
                "{id}, trench at {near} m: only {:.0} % of the ground just beyond its edge is a shadow",
                beyond * 100.0
            );
            // The shadow begins at the last return before the edge: up to
            // the spacing of two rows of returns in front of it (1.6 m for
            // the ERIM at 20 m).
            let before = shadowed(&index, area((near - 4.0, near - 1.7), (-3.0, 3.0)));
            assert_eq!(before, 0.0, "{id}, trench at {near} m: ground before it");
            // Its far wall and the ground above it are in plain view.
            let after = shadowed(&index, area((near + 8.5, near + 10.0), (-3.0, 3.0)));
            assert_eq!(after, 0.0, "{id}, trench at {near} m: ground beyond it");
        }
    }
}

#[test]
fn level_ground_and_dropouts_cast_no_shadow_and_a_rock_casts_its_own() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        assert!(
            report(&sensor, |_, _| 0.0).shadows.is_empty(),
            "{id}: level ground"
        );
        let mut image = sensor.render(0, &pose(), &HeightFunction::new(|x: f64, _: f64| 0.0 * x));
        let cols = image.cols();
        // Single lost beams and pairs of them down a column (never three
        // in a row: that is something unseen, below).
        for (i, range) in image.range.iter_mut().enumerate() {
            let (row, col) = (i / cols, i % cols);
            if (i % 7 == 0 && row % 3 != 2) || (col % 5 == 0 && row % 6 < 2) {
                *range = 0.0;
            }
        }
        let dropouts = evaluate(&image);
        assert!(dropouts.shadows.is_empty(), "{id}: dropouts");
        // A 0.6 m rock of 1 m across, 10 m ahead: the ground right behind
        // it is hidden, the ground beside it and in front of it is not.
        let rock = |x: f64, y: f64| {
            if (x - 10.0).hypot(y) < 0.5 { 0.6 } else { 0.0 }
        };
        let index = index(&report(&sensor, rock));
        let behind = shadowed(&index, area((10.6, 11.5), (-0.2, 0.2)));
        assert!(behind > 0.9, "{id}: behind the rock {behind}");
        let beside = area((9.0, 13.0), (1.5, 3.0))
            .into_iter()
            .chain(area((5.0, 9.0), (-2.0, 2.0)));
        assert_eq!(shadowed(&index, beside), 0.0, "{id}: beside the rock");
    }
}

#[test]
fn glass_that_returns_nothing_casts_a_shadow_but_is_no_drop_off() {
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        // A pane 60 cm tall and 2 m wide, 10 m ahead: every beam meeting
        // it is lost, and it hides the level ground behind it.
        let mut image = sensor.render(0, &pose(), &HeightFunction::new(|_: f64, _: f64| 0.0));
        let origin = (pose() * image.vehicle_from_sensor).translation.vector;
        let towards = pose() * nalgebra::Point3::new(10.0, 0.0, 0.0);
        let cols = image.cols();
        let mut lost = 0;
        for (i, range) in image.range.iter_mut().enumerate() {
            let (row, col) = (i / cols, i % cols);
            let Some([dx, dy, dz]) = image.beams.direction(row, col) else {
                continue;
            };
            // The beam in the world, and where it crosses the pane's plane
            // (10 m ahead of the vehicle, facing it).
            let world =
                (pose() * image.vehicle_from_sensor).rotation * nalgebra::Vector3::new(dx, dy, dz);
            let ahead = nalgebra::Vector3::new(
                towards.x - pose().translation.vector.x,
                towards.y - pose().translation.vector.y,
                0.0,
            )
            .normalize();
            let along = world.dot(&ahead);
            if along <= 0.0 {
                continue;
            }
            let to_plane = (towards.coords - origin).dot(&ahead);
            let t = to_plane / along;
            let hit = origin + world * t;
            let side = (hit - towards.coords).dot(&nalgebra::Vector3::new(-ahead.y, ahead.x, 0.0));
            if t > 0.0 && f64::from(*range) > t && hit.z < 0.6 && side.abs() < 1.0 {
                *range = f32::NAN;
                lost += 1;
            }
        }
        assert!(lost > 10, "{id}: the pane took only {lost} beams");
        let report = evaluate(&image);
        let index = index(&report);
        let behind = shadowed(&index, area((10.2, 11.0), (-0.5, 0.5)));
        assert!(
            behind > 0.9,
            "{id}: only {:.0} % behind the pane unseen",
            behind * 100.0
        );
        let beside = area((9.0, 13.0), (2.0, 3.0));
        assert_eq!(shadowed(&index, beside), 0.0, "{id}: beside the pane");
        assert!(
            report.cells.is_empty(),
            "{id}: level ground beyond a pane is no drop-off"
        );
    }
}
