//! Drop-off detection (`[perception.drop_off]`) on images rendered from
//! analytic scenes: trenches show up as the near edge of ground the image
//! did not see; gentle ground that hides part of itself does not.

use std::f64::consts::PI;

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{ObstacleReport, PerceptionConfig, Reasons, SensorModel};
use arcnav_vehicle::Isometry;

/// The drop-off cells (definite ones) of one image of `height` taken from the origin.
fn drop_offs(
    sensor: &SensorModel,
    height: impl Fn(f64, f64) -> f64 + Sync,
    config: &PerceptionConfig,
) -> Vec<(f64, f64)> {
    let image = sensor.render(0, &Isometry::identity(), &HeightFunction::new(height));
    classify(&image, config)
}

fn classify(image: &arcnav_perception::RangeImage, config: &PerceptionConfig) -> Vec<(f64, f64)> {
    let mut report = ObstacleReport::default();
    let stats = config
        .build_evaluator()
        .unwrap()
        .evaluate(image, &Isometry::identity(), &mut report)
        .unwrap();
    let cells: Vec<(f64, f64)> = report
        .cells
        .iter()
        .filter(|c| c.is_obstacle() && c.reasons.contains(Reasons::DROP_OFF))
        .map(|c| (c.x, c.y))
        .collect();
    assert_eq!(
        stats.by_reason[3] as usize,
        cells.len(),
        "counted per reason"
    );
    cells
}

fn sensors() -> [SensorModel; 2] {
    [SensorModel::erim(), SensorModel::lidar128()]
}

/// A trench 3 m wide and 2 m deep across the path, its near edge at `near`.
fn trench(near: f64) -> impl Fn(f64, f64) -> f64 + Sync {
    move |x, _| {
        if (near..near + 3.0).contains(&x) {
            -2.0
        } else {
            0.0
        }
    }
}

#[test]
fn the_near_edge_of_a_trench_across_the_path_is_a_drop_off_at_10_and_20_m() {
    let config = PerceptionConfig::default();
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        for near in [10.0, 20.0] {
            let cells = drop_offs(&sensor, trench(near), &config);
            // The near edge: within the spacing of two rows of returns in
            // front of the trench (1.6 m for the ERIM at 20 m), never in it
            // or beyond it.
            for &(x, y) in &cells {
                assert!(
                    (near - 1.6..near).contains(&x),
                    "{id}, trench at {near} m: drop-off at ({x:.2}, {y:.2}) is not at the near edge"
                );
            }
            // Across the 6 m in front of the vehicle (30 cells of 20 cm),
            // nearly every cell of the edge is found.
            let mut ahead: Vec<i64> = cells
                .iter()
                .filter(|(_, y)| y.abs() < 3.0)
                .map(|(_, y)| (y / 0.2).floor() as i64)
                .collect();
            ahead.sort_unstable();
            ahead.dedup();
            assert!(
                ahead.len() >= 27,
                "{id}, trench at {near} m: only {} of the 30 cells of the edge ahead are drop-offs",
                ahead.len()
            );
        }
    }
}

#[test]
fn a_narrow_ditch_is_found_and_a_bridgeable_one_is_not() {
    let config = PerceptionConfig::default();
    let ditch = |near: f64, width: f64, depth: f64| {
        move |x: f64, _: f64| {
            if (near..near + width).contains(&x) {
                -depth
            } else {
                0.0
            }
        }
    };
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        let cells = drop_offs(&sensor, ditch(10.0, 1.5, 1.0), &config);
        let ahead = cells.iter().filter(|(_, y)| y.abs() < 3.0).count();
        assert!(
            ahead >= 20,
            "{id}: 1.5 m × 1 m ditch at 10 m: {ahead} cells"
        );
        // A 0.5 m slot: the wheels roll across it (0.77 m bridged).
        let cells = drop_offs(&sensor, ditch(10.0, 0.5, 1.0), &config);
        assert!(
            cells.is_empty(),
            "{id}: a 0.5 m slot is bridged, yet {} drop-offs",
            cells.len()
        );
    }
}

#[test]
fn flat_ground_rolling_hills_and_a_gentle_crest_have_no_drop_off() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    let config = PerceptionConfig::default();
    // Hills of 10 m wavelength and 1 m amplitude (2 m crest to trough)
    // beyond 3 m, starting level under the vehicle.
    let hills = |x: f64, y: f64| {
        if x > 3.0 {
            (2.0 * PI * (x - 3.0) / 10.0).sin() * (0.2 * y).cos()
        } else {
            0.0
        }
    };
    // Level to 10 m, then falling away at 10°: the sensors see the slope
    // beyond the crest from here (the ERIM's beam there is 12° down).
    let crest = |x: f64, _: f64| {
        if x > 10.0 {
            -(x - 10.0) * 10f64.to_radians().tan()
        } else {
            0.0
        }
    };
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        assert_eq!(drop_offs(&sensor, |_, _| 0.0, &config), [], "{id}: flat");
        assert_eq!(drop_offs(&sensor, hills, &config), [], "{id}: hills");
        assert_eq!(drop_offs(&sensor, crest, &config), [], "{id}: crest");
    }
}

#[test]
fn a_crest_whose_far_side_hides_from_the_sensor_is_a_drop_off_until_seen() {
    // The same 10° fall beginning at 15 m: the beams there are shallower
    // than 10° (the ERIM's 8.3°) and never meet the far side. Unseen ground
    // beyond an edge is a drop-off; 5 m closer the slope is seen and the
    // edge is not one any more (the local map then drops it).
    let config = PerceptionConfig::default();
    let crest = |start: f64| {
        move |x: f64, _: f64| {
            if x > start {
                -(x - start) * 10f64.to_radians().tan()
            } else {
                0.0
            }
        }
    };
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        let far = drop_offs(&sensor, crest(15.0), &config);
        assert!(
            far.iter().filter(|(_, y)| y.abs() < 3.0).count() >= 25,
            "{id}: the hidden far side at 15 m is a drop-off"
        );
        assert!(far.iter().all(|&(x, _)| (13.4..15.0).contains(&x)));
    }
}

#[test]
fn dropouts_and_the_shadow_behind_a_rock_are_not_drop_offs() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    let config = PerceptionConfig::default();
    for sensor in sensors() {
        let id = sensor.to_custom().id;
        let mut image = sensor.render(0, &Isometry::identity(), &HeightFunction::new(|_, _| 0.0));
        // Every 7th pixel lost, and runs of two lost pixels down every
        // 5th column: a data gap, not a hole.
        let cols = image.cols();
        for (i, range) in image.range.iter_mut().enumerate() {
            let (row, col) = (i / cols, i % cols);
            if i % 7 == 0 || (col % 5 == 0 && row % 6 < 2) {
                *range = 0.0;
            }
        }
        assert_eq!(classify(&image, &config), [], "{id}: dropouts");
        // A 0.6 m rock casts a shadow 2-4 m long on level ground behind it.
        let rock = |x: f64, y: f64| {
            if (x - 10.0).hypot(y) < 0.5 { 0.6 } else { 0.0 }
        };
        assert_eq!(drop_offs(&sensor, rock, &config), [], "{id}: rock");
    }
}

#[test]
fn detection_follows_the_configuration() {
    let mut config = PerceptionConfig::default();
    let sensor = SensorModel::erim();
    config.drop_off.enabled = false;
    assert_eq!(drop_offs(&sensor, trench(10.0), &config), []);
    // A vehicle that bridges 5 m crosses the trench ahead (the unseen
    // stretch runs from the last return before it to the foot of its far
    // wall); far to the side, beams cross it obliquely over more than 5 m.
    config.drop_off.enabled = true;
    config.drop_off.max_gap_m = 5.0;
    let wide = drop_offs(&sensor, trench(10.0), &config);
    assert!(wide.iter().all(|(_, y)| y.abs() > 8.0), "{wide:?}");
}

/// The suspected drop-offs (graded, reason drop-off) of one image of
/// `height` taken from the origin, with their cost.
fn suspected(
    sensor: &SensorModel,
    height: impl Fn(f64, f64) -> f64 + Sync,
    config: &PerceptionConfig,
) -> Vec<(f64, f64, f32)> {
    let image = sensor.render(0, &Isometry::identity(), &HeightFunction::new(height));
    let mut report = ObstacleReport::default();
    let stats = config
        .build_evaluator()
        .unwrap()
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap();
    let cells: Vec<(f64, f64, f32)> = report
        .cells
        .iter()
        .filter(|c| !c.is_obstacle())
        .map(|c| {
            assert_eq!(c.reasons, Reasons::DROP_OFF);
            (c.x, c.y, c.cost)
        })
        .collect();
    assert_eq!(stats.graded as usize, cells.len(), "counted as graded");
    cells
}

#[test]
fn a_ditch_too_far_to_show_its_depth_is_a_suspected_drop_off_and_a_near_slot_is_not() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    // From 16-20 m a ray dips 0.15-0.3 m into a 1.5 m ditch before it
    // meets the far side, less than δ (0.24-0.25 m): no definite drop-off
    // there, but a dip wider than the wheels bridge, whose far side rises.
    let config = PerceptionConfig::default();
    let ditch = |near: f64, width: f64| {
        move |x: f64, _: f64| {
            if (near..near + width).contains(&x) {
                -1.0
            } else {
                0.0
            }
        }
    };
    for sensor in [
        SensorModel::erim(),
        SensorModel::lidar64(),
        SensorModel::lidar128(),
    ] {
        let id = sensor.to_custom().id;
        for near in [16.0, 20.0] {
            let cells = suspected(&sensor, ditch(near, 1.5), &config);
            for &(x, y, cost) in &cells {
                assert!(
                    (near - 1.6..near).contains(&x),
                    "{id}, ditch at {near} m: suspected drop-off at ({x:.2}, {y:.2}) is not at the near edge"
                );
                assert_eq!(f64::from(cost), config.drop_off.suspect_cost, "{id}");
            }
            let mut ahead: Vec<i64> = cells
                .iter()
                .filter(|(_, y, _)| y.abs() < 3.0)
                .map(|(_, y, _)| (y / 0.2).floor() as i64)
                .collect();
            ahead.sort_unstable();
            ahead.dedup();
            assert!(
                ahead.len() >= 8,
                "{id}, ditch at {near} m: only {} of the 30 cells of the edge ahead are suspected",
                ahead.len()
            );
        }
        // A 0.5 m slot is bridged: never flagged. From near, where the
        // rows lie closer than `max_gap − w` (0.27 m), not suspected
        // either (6 m ahead; off to the side the same slot is farther
        // off). From farther one image cannot tell it from a ditch (the
        // ground between the edge's return and where the next ray would
        // have met it is not seen): it may be suspected, which only slows
        // the vehicle; asking more of a suspicion let the ERIM drive into
        // a 0.9 m ditch whose edge straight ahead no row showed enough of.
        for near in [12.0, 16.0] {
            assert_eq!(
                drop_offs(&sensor, ditch(near, 0.5), &config),
                [],
                "{id}: slot at {near} m"
            );
        }
        let near_slot: Vec<_> = suspected(&sensor, ditch(6.0, 0.5), &config)
            .into_iter()
            .filter(|(_, y, _)| y.abs() < 3.0)
            .collect();
        assert_eq!(near_slot, [], "{id}: slot 6 m ahead");
        assert_eq!(suspected(&sensor, |_, _| 0.0, &config), [], "{id}: flat");
        // Off: nothing suspected.
        let mut off = config.clone();
        off.drop_off.suspect_cost = 0.0;
        assert_eq!(suspected(&sensor, ditch(16.0, 1.5), &off), [], "{id}: off");
    }
}
