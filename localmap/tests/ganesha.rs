//! The local map (002 §5): latency compensation, the window, consistency
//! pruning, several sensors, out-of-order reports and pose jumps.

use arcnav_localmap::{InsertError, JumpPolicy, JumpReason, LocalMap, LocalMapConfig, PoseUpdate};
use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    FovPolygon, ObstacleCell, ObstacleReport, PerceptionConfig, Reasons, SensorModel, Shadow,
    Shadows,
};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{Pose, PoseHistory, Utime, VehicleConfig};
use nalgebra::Point2;

const SECOND: Utime = 1_000_000;

fn map() -> LocalMap {
    map_with(LocalMapConfig::default())
}

/// A map that drops a cell at the first newer image that misses it (002
/// §5; the default waits for a second).
fn map_as_002() -> LocalMap {
    map_with(LocalMapConfig {
        misses_to_drop: 1,
        ..LocalMapConfig::default()
    })
}

fn map_with(config: LocalMapConfig) -> LocalMap {
    config.validate().unwrap();
    LocalMap::new(&config, &VehicleConfig::default())
}

fn pose_at(utime: Utime, x: f64, y: f64, yaw: f64) -> Pose {
    Pose::at_rest(utime, planar_isometry(x, y, yaw))
}

fn cell(x: f64, y: f64) -> ObstacleCell {
    ObstacleCell {
        x,
        y,
        z_min: 0.0,
        z_max: 0.5,
        reasons: Reasons::HEIGHT_VARIATION,
        region: 0,
        cost: 1.0,
    }
}

fn rectangle(x0: f64, x1: f64, y0: f64, y1: f64) -> FovPolygon {
    FovPolygon::new(vec![
        Point2::new(x0, y0),
        Point2::new(x1, y0),
        Point2::new(x1, y1),
        Point2::new(x0, y1),
    ])
}

fn report(utime: Utime, sensor: &str, cells: &[(f64, f64)], fov: FovPolygon) -> ObstacleReport {
    ObstacleReport {
        utime,
        sensor: sensor.into(),
        cell_size_m: 0.2,
        cells: cells.iter().map(|&(x, y)| cell(x, y)).collect(),
        regions: vec![],
        fov,
        shadows: Default::default(),
        ..ObstacleReport::default()
    }
}

/// Vehicle-frame centres of the snapshot's patches.
fn positions(map: &LocalMap) -> Vec<(f32, f32)> {
    map.snapshot().patches.iter().map(|p| (p.x, p.y)).collect()
}

#[test]
fn a_report_600_ms_late_lands_where_the_obstacle_is() {
    // The vehicle drives north along x = 0 at 2.5 m/s; poses every 20 ms.
    let mut history = PoseHistory::with_capacity(500);
    for k in 0..=100 {
        let t = k * 20_000;
        history
            .push(pose_at(
                t,
                0.0,
                2.5 * t as f64 / SECOND as f64,
                std::f64::consts::FRAC_PI_2,
            ))
            .unwrap();
    }
    // A 0.5 m box at world (0, 12.5); the image is taken at 0.2 s (y = 0.5).
    let capture: Utime = 200_000;
    let capture_pose = history.at(capture).unwrap();
    let scene = HeightFunction::new(|x: f64, y: f64| {
        if x.abs() < 0.5 && (12.0..13.0).contains(&y) {
            0.5
        } else {
            0.0
        }
    });
    let image = SensorModel::erim().render(capture, &capture_pose.world_from_vehicle, &scene);
    let mut evaluator = PerceptionConfig::default().build_evaluator().unwrap();
    let mut obstacles = ObstacleReport::default();
    evaluator
        .evaluate(&image, &capture_pose.world_from_vehicle, &mut obstacles)
        .unwrap();
    assert!(!obstacles.cells.is_empty());
    // The report reaches the map 600 ms later: the vehicle has driven 1.5 m.
    let mut map = map();
    let now = history.at(capture + 600_000).unwrap();
    assert_eq!(map.update(&now), PoseUpdate::Accepted);
    map.insert(&obstacles).unwrap();
    map.update(&now);
    // The box front is 12 m from the capture position: 10.5 m from the vehicle now.
    let ahead: Vec<f32> = positions(&map).iter().map(|p| p.0).collect();
    let nearest = ahead.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(
        (nearest - 10.5).abs() <= 0.45,
        "box front {nearest} m ahead, expected 10.5 m"
    );
    assert!(positions(&map).iter().all(|p| p.1.abs() <= 1.0));
}

#[test]
fn cells_are_dropped_at_each_window_boundary() {
    let mut map = map_with(LocalMapConfig {
        behind_m: 6.0,
        ..LocalMapConfig::default()
    });
    let origin = pose_at(0, 0.0, 0.0, 0.0);
    map.update(&origin);
    // Heading east: vehicle x = world x. Window: -6 ≤ x ≤ 20, |y| ≤ 10.
    let cells = [
        (19.5, 0.1),
        (20.5, 0.1),
        (-5.5, 0.1),
        (-6.5, 0.1),
        (5.1, 9.5),
        (5.1, 10.5),
        (5.1, -9.5),
        (5.1, -10.5),
    ];
    let outcome = map
        .insert(&report(0, "erim", &cells, FovPolygon::default()))
        .unwrap();
    assert_eq!((outcome.new_patches, outcome.outside_window), (4, 4));
    let mut kept = positions(&map);
    kept.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(kept, [(-5.4, 0.2), (5.0, -9.4), (5.0, 9.4), (19.4, 0.2)]);
    // Driving 1 m forward pushes the cell behind out of the window.
    map.update(&pose_at(SECOND / 2, 1.0, 0.0, 0.0));
    assert_eq!(map.len(), 3);
    // Turning 90° left: the far cell is now 18.4 m to the right and the one
    // at (5.0, -9.4) 9.4 m behind: both gone; (5.0, 9.4) is 9.4 m ahead.
    map.update(&pose_at(SECOND, 1.0, 0.0, std::f64::consts::FRAC_PI_2));
    assert_eq!(positions(&map), [(9.4, -4.0)]);
    assert_eq!(map.stats().dropped_outside_window, 3);
}

#[test]
fn a_phantom_cell_disappears_after_one_overlapping_image_that_does_not_see_it() {
    let mut map = map_as_002();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(
        100,
        "erim",
        &[(10.0, 0.0)],
        rectangle(4.0, 25.0, -8.0, 8.0),
    ))
    .unwrap();
    assert_eq!(map.len(), 1);
    let outcome = map
        .insert(&report(
            600_000,
            "erim",
            &[],
            rectangle(4.0, 25.0, -8.0, 8.0),
        ))
        .unwrap();
    assert_eq!(outcome.pruned, 1);
    assert!(map.is_empty());
    // By default it takes a second image that misses it.
    let mut map = map_with(LocalMapConfig::default());
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let fov = rectangle(4.0, 25.0, -8.0, 8.0);
    map.insert(&report(100, "lidar64", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    map.insert(&report(100_000, "lidar64", &[], fov.clone()))
        .unwrap();
    assert_eq!(map.len(), 1);
    map.insert(&report(200_000, "lidar64", &[], fov)).unwrap();
    assert!(map.is_empty());
}

/// A report whose sensor stood at (`x`, `y`) when it looked.
fn seen_from(mut report: ObstacleReport, x: f64, y: f64) -> ObstacleReport {
    report.shadows.origin = Point2::new(x, y);
    report
}

#[test]
fn an_image_from_farther_than_a_cell_was_reported_from_does_not_drop_it() {
    // A cell at (x, 0) reported by a sensor standing 8 m short of it; then
    // `image(t, from)`: an image of the same ground from (from, 0) (or from
    // nowhere it says plausibly) that does not report it.
    let start = |config: LocalMapConfig, x: f64| {
        let mut map = map_with(config);
        map.update(&pose_at(0, x - 10.0, 0.0, 0.0));
        let fov = rectangle(x - 30.0, x + 30.0, -10.0, 10.0);
        map.insert(&seen_from(
            report(100, "lidar64", &[(x, 0.0)], fov.clone()),
            x - 8.0,
            0.0,
        ))
        .unwrap();
        (map, fov)
    };
    let image = |t, fov: &FovPolygon, from: Option<f64>| {
        let image = report(t, "lidar64", &[], fov.clone());
        match from {
            Some(x) => seen_from(image, x, 0.0),
            None => image,
        }
    };
    let as_002 = LocalMapConfig {
        misses_to_drop: 1,
        ..LocalMapConfig::default()
    };
    // A ditch's edge flagged 8 m ahead (its far wall shows only from near);
    // the vehicle backs away and looks again from 12 m: that image could
    // not have flagged it, so it is no evidence against it.
    let (mut map, fov) = start(as_002.clone(), 10.0);
    let outcome = map.insert(&image(600_000, &fov, Some(-2.0))).unwrap();
    assert_eq!((outcome.pruned, map.len()), (0, 1));
    assert_eq!(map.stats().seen_from_afar, 1);
    // From 9.5 m (within 1.25 times 8 m) it is missed and dropped.
    let outcome = map.insert(&image(1_200_000, &fov, Some(0.5))).unwrap();
    assert_eq!((outcome.pruned, map.len()), (1, 0));

    // A report that does not say plausibly where its sensor stood (0, 0,
    // far from its footprint) prunes as 002 §5 does, and is counted.
    let (mut map, fov) = start(as_002.clone(), 510.0);
    let outcome = map.insert(&image(600_000, &fov, None)).unwrap();
    assert_eq!(outcome.pruned, 1);
    assert_eq!(map.stats().reports_without_viewpoint, 1);

    // With the rule off (0), every overlapping image counts a miss.
    let (mut map, fov) = start(
        LocalMapConfig {
            miss_range_factor: 0.0,
            ..as_002
        },
        10.0,
    );
    let outcome = map.insert(&image(600_000, &fov, Some(-2.0))).unwrap();
    assert_eq!(outcome.pruned, 1);
}

#[test]
fn a_drop_off_is_missed_only_by_images_from_where_a_hole_would_show() {
    // A cell at x = 40; a hole there is flagged for certain within 8 m
    // (`hole_range_m`). Each case: the cell's reasons and cost, the
    // distance it was reported from, `drop_off_trust_factor`, then the
    // distances of later images that do not report it and how many
    // patches are left after each.
    let config = LocalMapConfig {
        hole_range_m: 8.0,
        misses_to_drop: 1,
        ahead_m: 40.0,
        ..LocalMapConfig::default()
    };
    type Case = (
        &'static str,
        Reasons,
        f32,
        f64,
        f64,
        &'static [(f64, usize)],
    );
    let cases: [Case; 5] = [
        // The rows of a far image land elsewhere on a hole's edge each
        // frame: a suspicion stays until an image from within 8 m.
        (
            "suspected from 18 m",
            Reasons::DROP_OFF,
            0.5,
            18.0,
            2.0,
            &[(15.0, 1), (10.0, 1), (7.0, 0)],
        ),
        // Flagged from 9.5 m, within twice the hole range
        // (`drop_off_trust_factor`), it stays the same way (a vehicle
        // turning round 10 m before a ditch lost its flagged cells to
        // images from 9-12 m that did not flag them, and the route sent it
        // across).
        (
            "flagged from 9.5 m",
            Reasons::DROP_OFF,
            1.0,
            9.5,
            2.0,
            &[(11.5, 1), (9.0, 1), (7.5, 0)],
        ),
        // Flagged from farther, it is missed like any cell: far rows flag
        // rough ground as often as holes (the ERIM at 10 m/s, its
        // perception region 30 m deep).
        (
            "flagged from 18 m",
            Reasons::DROP_OFF,
            1.0,
            18.0,
            2.0,
            &[(15.0, 0)],
        ),
        // With the factor 0, only suspicions are kept so.
        (
            "flagged from 9.5 m, factor 0",
            Reasons::DROP_OFF,
            1.0,
            9.5,
            0.0,
            &[(11.5, 0)],
        ),
        (
            "a rock from 10 m",
            Reasons::HEIGHT_VARIATION,
            1.0,
            10.0,
            2.0,
            &[(9.0, 0)],
        ),
    ];
    let fov = rectangle(10.0, 60.0, -10.0, 10.0);
    let empty = |t, from: f64| seen_from(report(t, "lidar64", &[], fov.clone()), 40.0 - from, 0.0);
    for (name, reasons, cost, reported_from, trust, looks) in cases {
        let mut map = map_with(LocalMapConfig {
            drop_off_trust_factor: trust,
            ..config.clone()
        });
        map.update(&pose_at(0, 21.0, 0.0, 0.0));
        let mut first = empty(100, reported_from);
        first.cells.push(ObstacleCell {
            reasons,
            cost,
            ..cell(40.0, 0.0)
        });
        map.insert(&first).unwrap();
        assert_eq!(map.len(), 1, "{name}");
        for (k, &(from, left)) in looks.iter().enumerate() {
            map.insert(&empty(200_000 * (k as i64 + 1), from)).unwrap();
            assert_eq!(map.len(), left, "{name}, then not reported from {from} m");
        }
    }
}

#[test]
fn a_cell_reported_again_is_kept_and_confirmed() {
    let mut map = map();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let fov = rectangle(4.0, 25.0, -8.0, 8.0);
    map.insert(&report(100, "erim", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    map.insert(&report(600_000, "erim", &[(10.05, 0.05), (10.1, 0.1)], fov))
        .unwrap();
    let patches = &map.snapshot().patches;
    assert_eq!(patches.len(), 1);
    assert_eq!(
        patches[0].confirmations, 2,
        "one confirmation per image, not per cell"
    );
    assert_eq!(
        (patches[0].first_seen, patches[0].last_seen),
        (100, 600_000)
    );
}

/// Graded ground (cells of cost below 1) makes patches that carry their
/// cost and are no obstacles; an untraversable cell in the same patch makes
/// it one, and it stays one.
#[test]
fn a_patch_carries_the_highest_cost_of_its_cells() {
    let mut map = map();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let fov = rectangle(4.0, 25.0, -8.0, 8.0);
    let graded = |utime, cost: f32| {
        let mut r = report(utime, "erim", &[(10.0, 0.0)], fov.clone());
        r.cells[0].cost = cost;
        r.cells[0].reasons = Reasons::NONE;
        r
    };
    map.insert(&graded(100, 0.8)).unwrap();
    let patch = map.snapshot().patches[0];
    assert_eq!(patch.cost, 0.8);
    assert!(!patch.is_obstacle());
    map.insert(&graded(200, 0.9)).unwrap();
    assert_eq!(map.snapshot().patches[0].cost, 0.9);
    map.insert(&report(300, "erim", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    map.insert(&graded(400, 0.8)).unwrap();
    let patch = map.snapshot().patches[0];
    assert!(patch.is_obstacle() && patch.reasons.contains(Reasons::HEIGHT_VARIATION));
}

#[test]
fn a_cell_outside_the_newer_images_footprint_survives() {
    let mut map = map_as_002();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(
        100,
        "erim",
        &[(10.0, 0.0), (3.0, 6.0)],
        rectangle(2.0, 25.0, -8.0, 8.0),
    ))
    .unwrap();
    // The newer image sees only x > 8 and |y| < 4.
    let outcome = map
        .insert(&report(
            600_000,
            "erim",
            &[],
            rectangle(8.0, 25.0, -4.0, 4.0),
        ))
        .unwrap();
    assert_eq!(outcome.pruned, 1);
    assert_eq!(positions(&map), [(3.0, 6.2)]);
}

#[test]
fn misses_to_drop_sets_how_many_images_must_disagree() {
    let mut map = map_with(LocalMapConfig {
        misses_to_drop: 2,
        ..Default::default()
    });
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let fov = rectangle(4.0, 25.0, -8.0, 8.0);
    map.insert(&report(100, "erim", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    map.insert(&report(200, "erim", &[], fov.clone())).unwrap();
    assert_eq!(map.len(), 1);
    assert_eq!(map.patches()[0].misses, 1);
    map.insert(&report(300, "erim", &[], fov)).unwrap();
    assert!(map.is_empty());
}

#[test]
fn two_sensors_with_different_footprints() {
    let mut map = map_as_002();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let erim_fov = rectangle(4.0, 25.0, -8.0, 8.0);
    let side_fov = rectangle(-5.0, 12.0, -10.0, 2.0);
    map.insert(&report(
        100,
        "erim",
        &[(10.0, 0.0), (15.0, 0.0)],
        erim_fov.clone(),
    ))
    .unwrap();
    map.insert(&report(150, "side", &[(0.0, -8.0)], side_fov.clone()))
        .unwrap();
    assert_eq!(map.len(), 3);
    // The side sensor covers (10, 0) but never reported it: it does not prune
    // the ERIM's cell; its own cell, seen again by the ERIM's footprint, stays.
    map.insert(&report(300, "side", &[(0.0, -8.0)], side_fov.clone()))
        .unwrap();
    map.insert(&report(
        400,
        "erim",
        &[(10.0, 0.0), (15.0, 0.0)],
        erim_fov.clone(),
    ))
    .unwrap();
    assert_eq!(map.len(), 3);
    // The ERIM stops seeing (15, 0): dropped. (10, 0) still reported: kept.
    map.insert(&report(500, "erim", &[(10.0, 0.0)], erim_fov.clone()))
        .unwrap();
    assert_eq!(map.len(), 2);
    let sensors: Vec<u32> = map.patches().iter().map(|p| p.sensors).collect();
    assert!(
        sensors.contains(&0b10),
        "the side sensor's cell is tagged with its sensor"
    );
    assert_eq!(map.sensor_name(1), Some("side"));
    // With cross-sensor pruning any overlapping image may retract any cell.
    let mut shared = map_with(LocalMapConfig {
        cross_sensor_pruning: true,
        misses_to_drop: 1,
        ..Default::default()
    });
    shared.update(&pose_at(0, 0.0, 0.0, 0.0));
    shared
        .insert(&report(100, "erim", &[(10.0, 0.0)], erim_fov))
        .unwrap();
    shared.insert(&report(200, "side", &[], side_fov)).unwrap();
    assert!(shared.is_empty());
}

#[test]
fn an_out_of_order_report_never_prunes_what_a_newer_image_confirmed() {
    let mut map = map_as_002();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let fov = rectangle(4.0, 25.0, -8.0, 8.0);
    map.insert(&report(500_000, "erim", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    // An image captured earlier arrives late and did not see the cell.
    let outcome = map
        .insert(&report(400_000, "erim", &[(12.0, 1.0)], fov.clone()))
        .unwrap();
    assert_eq!(outcome.pruned, 0);
    assert_eq!(map.len(), 2);
    let late = map.patches().iter().find(|p| p.x > 11.0).unwrap();
    assert_eq!((late.first_seen, late.last_seen), (400_000, 400_000));
    // A newer image without (12, 1) prunes it; one older than it cannot.
    map.insert(&report(450_000, "erim", &[(10.0, 0.0)], fov.clone()))
        .unwrap();
    assert_eq!(map.len(), 1, "450 ms is newer than the 400 ms sighting");
    map.insert(&report(300_000, "erim", &[], fov)).unwrap();
    assert_eq!(map.len(), 1, "300 ms is older than the 500 ms confirmation");
}

#[test]
fn a_pose_jump_resets_the_map_and_refuses_reports_from_before() {
    let mut map = map();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(0, "erim", &[(10.0, 0.0)], FovPolygon::default()))
        .unwrap();
    map.update(&pose_at(100_000, 0.25, 0.0, 0.0));
    assert_eq!(map.len(), 1, "0.25 m in 0.1 s is plausible");
    let jump = map.update(&pose_at(200_000, 40.0, 0.0, 0.0));
    assert!(
        matches!(jump, PoseUpdate::Reset(JumpReason::Jump { .. })),
        "{jump:?}"
    );
    assert!(map.is_empty());
    assert_eq!(
        map.insert(&report(
            150_000,
            "erim",
            &[(45.0, 0.0)],
            FovPolygon::default()
        )),
        Err(InsertError::BeforeReset {
            utime: 150_000,
            reset: 200_000
        })
    );
    map.insert(&report(
        250_000,
        "erim",
        &[(45.0, 0.0)],
        FovPolygon::default(),
    ))
    .unwrap();
    assert_eq!(map.len(), 1);
    // Time running backwards resets too.
    let back = map.update(&pose_at(100_000, 40.0, 0.0, 0.0));
    assert_eq!(
        back,
        PoseUpdate::Reset(JumpReason::TimeBackwards {
            from: 200_000,
            to: 100_000
        })
    );
    assert!(map.is_empty());
    assert_eq!(map.stats().resets, 2);
}

#[test]
fn with_the_reject_policy_a_jumping_pose_is_ignored() {
    let mut map = map_with(LocalMapConfig {
        on_pose_jump: JumpPolicy::Reject,
        ..Default::default()
    });
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(0, "erim", &[(10.0, 0.0)], FovPolygon::default()))
        .unwrap();
    let update = map.update(&pose_at(100_000, 30.0, 0.0, 0.0));
    assert!(matches!(
        update,
        PoseUpdate::Rejected(JumpReason::Jump { .. })
    ));
    assert_eq!(map.len(), 1);
    assert_eq!(map.pose().unwrap().utime, 0);
    assert_eq!(map.stats().rejected_poses, 1);
}

#[test]
fn snapshots_are_immutable_and_shared_across_threads() {
    let mut map = map();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(
        0,
        "erim",
        &[(10.0, 0.0), (12.0, 0.0)],
        FovPolygon::default(),
    ))
    .unwrap();
    let snapshot = map.snapshot();
    let reader = {
        let snapshot = std::sync::Arc::clone(&snapshot);
        std::thread::spawn(move || snapshot.patches.iter().map(|p| p.x).sum::<f32>())
    };
    // The map moves on while the behaviour thread reads.
    map.update(&pose_at(SECOND, 5.0, 0.0, 0.0));
    map.insert(&report(
        SECOND,
        "erim",
        &[(20.0, 0.0)],
        FovPolygon::default(),
    ))
    .unwrap();
    assert_eq!(reader.join().unwrap(), 10.2 + 12.2);
    assert_eq!(snapshot.len(), 2);
    assert_eq!(map.snapshot().len(), 3);
}

#[test]
fn bad_reports_are_refused_with_a_reason() {
    let mut map = map();
    let bad = report(0, "erim", &[(f64::NAN, 0.0)], FovPolygon::default());
    assert!(matches!(map.insert(&bad), Err(InsertError::BadCell { .. })));
    for i in 0..32 {
        map.insert(&report(0, &format!("s{i}"), &[], FovPolygon::default()))
            .unwrap();
    }
    assert!(matches!(
        map.insert(&report(0, "one-too-many", &[], FovPolygon::default())),
        Err(InsertError::TooManySensors { .. })
    ));
    assert_eq!(map.stats().reports_refused, 2);
}

#[test]
fn a_footprint_reaching_around_the_earth_still_prunes_and_an_absurd_one_is_refused_and_counted() {
    let mut map = map_as_002();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(
        100,
        "erim",
        &[(10.0, 0.0)],
        rectangle(4.0, 25.0, -8.0, 8.0),
    ))
    .unwrap();
    // 4·10^7 m across (took 2.4 GB before footprints were clipped to the
    // rows the map holds): prunes the phantom like any footprint over it.
    let outcome = map
        .insert(&report(
            200_000,
            "erim",
            &[],
            rectangle(-2e7, 2e7, -2e7, 2e7),
        ))
        .unwrap();
    assert_eq!(outcome.pruned, 1);
    // A vertex at 10^15 m is damage, not a place: refused, counted.
    let refused = map.stats().reports_refused;
    let err = map
        .insert(&report(
            400_000,
            "erim",
            &[],
            rectangle(4.0, 1e15, -8.0, 8.0),
        ))
        .unwrap_err();
    assert!(matches!(err, InsertError::BadFootprint { .. }), "{err}");
    assert_eq!(map.stats().reports_refused, refused + 1);
    let err = map
        .insert(&report(
            500_000,
            "erim",
            &[],
            rectangle(4.0, f64::NAN, -8.0, 8.0),
        ))
        .unwrap_err();
    assert!(matches!(err, InsertError::BadFootprint { .. }), "{err}");
}

#[test]
fn the_map_knows_which_ground_has_been_seen() {
    // What images saw (the driven ground is the next test's).
    let mut map = map_with(LocalMapConfig {
        assume_seen_m: 3.0,
        driven_memory_m: 0.0,
        ..LocalMapConfig::default()
    });
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    let snapshot = map.snapshot();
    // Around the first pose the vehicle stands on ground it knows.
    assert!(snapshot.is_seen(0.0, 0.0) && snapshot.is_seen(2.5, 0.0));
    assert!(!snapshot.is_seen(5.0, 0.0) && !snapshot.is_seen(0.0, -5.0));
    // An image that observed 5-15 m ahead, ±4 m.
    map.insert(&report(
        SECOND,
        "erim",
        &[],
        rectangle(5.0, 15.0, -4.0, 4.0),
    ))
    .unwrap();
    let snapshot = map.snapshot();
    for (x, y, seen) in [
        (5.3, 0.0, true),
        (14.7, 3.7, true),
        (10.0, -3.7, true),
        (15.5, 0.0, false),
        (10.0, 4.5, false),
        (4.0, 0.0, false),
    ] {
        assert_eq!(snapshot.is_seen(x, y), seen, "({x}, {y})");
    }
    // Patches of 0.4 m whose centre lies within 3 m of the origin.
    let disc = (-8..8)
        .flat_map(|i| (-8..8).map(move |j| (i, j)))
        .filter(|&(i, j)| (0.4 * (f64::from(i) + 0.5)).hypot(0.4 * (f64::from(j) + 0.5)) <= 3.0)
        .count() as u32;
    assert_eq!(
        snapshot.seen.count(),
        25 * 20 + disc,
        "footprint + start disc"
    );
    // The window moves on 40 m: everything seen is behind it; as the
    // ring reuses those slots for new ground, none of it reads as seen.
    for (k, x) in [10.0, 20.0, 30.0, 40.0].into_iter().enumerate() {
        let update = map.update(&pose_at((2 + k as i64) * SECOND, x, 0.0, 0.0));
        assert_eq!(update, PoseUpdate::Accepted);
    }
    let snapshot = map.snapshot();
    assert_eq!(snapshot.seen.count(), 0);
    assert!(!snapshot.is_seen(0.0, 0.0) && !snapshot.is_seen(-30.0, 0.0));
    // A reset forgets what was seen, except around the new pose.
    map.update(&pose_at(6 * SECOND, 500.0, 0.0, 0.0));
    let snapshot = map.snapshot();
    assert_eq!(snapshot.seen.count(), disc, "start disc only");
    assert!(snapshot.is_seen(0.0, 0.0));
}

#[test]
fn ground_that_left_the_window_is_forgotten_with_its_cells() {
    // Backing up over ground whose cells were dropped must not find it
    // seen and free: the bank's end the vehicle drove past is still there.
    let mut map = map_with(LocalMapConfig {
        behind_m: 6.0,
        assume_seen_m: 0.0,
        ..LocalMapConfig::default()
    });
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    map.insert(&report(
        SECOND / 10,
        "erim",
        &[(8.0, 3.0)],
        rectangle(2.0, 18.0, -6.0, 6.0),
    ))
    .unwrap();
    assert!(map.snapshot().is_seen(5.0, 0.0));
    // 16 m on, the cell (8 m behind) and the ground around it have left
    // the window; 2 m behind is still held.
    map.update(&pose_at(SECOND, 8.0, 0.0, 0.0));
    map.update(&pose_at(2 * SECOND, 16.0, 0.0, 0.0));
    let snapshot = map.snapshot();
    assert!(snapshot.patches.is_empty());
    assert!(!snapshot.is_seen(-8.0, 3.0) && !snapshot.is_seen(-11.0, 0.0));
    assert!(snapshot.is_seen(-2.0, 0.0) && snapshot.is_seen(1.5, -5.5));
    // Backing 10 m: the ground around the dropped cell stays unseen.
    map.update(&pose_at(3 * SECOND, 11.0, 0.0, 0.0));
    map.update(&pose_at(4 * SECOND, 6.0, 0.0, 0.0));
    let snapshot = map.snapshot();
    assert!(!snapshot.is_seen(2.0, 3.0), "the dropped cell's ground");
    assert!(!snapshot.is_seen(-2.0, 0.0) && snapshot.is_seen(5.0, 0.0));
}

#[test]
fn the_ground_the_vehicle_drove_over_is_seen_again_when_it_backs_onto_it() {
    // A lane driven 30 m in, with a window 6 m behind: backing out the way
    // it came, the swath between the axles it drove over bore it, so it
    // counts as seen though the window forgot it; beside the swath, and
    // with no memory of it, the forgotten ground stays unseen.
    let drive_and_back = |memory_m: f64| {
        let mut map = map_with(LocalMapConfig {
            behind_m: 6.0,
            assume_seen_m: 0.0,
            driven_memory_m: memory_m,
            ..LocalMapConfig::default()
        });
        let mut t = 0;
        for step in (0..=300).chain((100..300).rev()) {
            t += SECOND / 20;
            map.update(&pose_at(t, f64::from(step) * 0.1, 0.0, 0.0));
        }
        // Back at x = 10 m, 20 m behind the farthest point reached.
        map.snapshot()
    };
    let remembered = drive_and_back(100.0);
    for x in [-5.5, -3.0, -0.5, 1.0, 3.0] {
        for y in [-1.3, -1.0, 0.0, 1.0, 1.3] {
            assert!(remembered.is_seen(x, y), "driven ({x}, {y})");
        }
    }
    assert!(!remembered.is_seen(-3.0, 2.5) && !remembered.is_seen(-3.0, -2.5));
    // The swath beyond the window behind is not in the map at all.
    assert!(!remembered.is_seen(-8.0, 0.0));
    let forgotten = drive_and_back(0.0);
    assert!(!forgotten.is_seen(-3.0, 0.0) && !forgotten.is_seen(-5.5, 0.0));
    // A short memory keeps the newest travel only: the lane behind was
    // driven over 40 m of travel ago; where the vehicle stands, just now.
    let short = drive_and_back(10.0);
    assert!(short.is_seen(1.0, 0.0));
    assert!(!short.is_seen(-3.0, 0.0) && !short.is_seen(-5.5, 0.0));
}

#[test]
fn a_reset_forgets_the_driven_ground() {
    let mut map = map_with(LocalMapConfig {
        behind_m: 6.0,
        assume_seen_m: 0.0,
        ..LocalMapConfig::default()
    });
    let mut t = 0;
    for step in 0..=200 {
        t += SECOND / 20;
        map.update(&pose_at(t, f64::from(step) * 0.1, 0.0, 0.0));
    }
    map.reset(t);
    map.update(&pose_at(t + SECOND / 20, 5.0, 0.0, 0.0));
    assert!(!map.snapshot().is_seen(-3.0, 0.0));
}

#[test]
fn ground_in_a_shadow_is_not_seen_and_an_old_cell_there_is_still_pruned() {
    let mut map = map_with(LocalMapConfig {
        assume_seen_m: 0.0,
        misses_to_drop: 1,
        ..LocalMapConfig::default()
    });
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    // A cell 12 m ahead, seen by an image that observed only the ground
    // around it; then an image that observed 5-15 m ahead but whose columns
    // straight ahead (±0.1 rad) lost sight of the ground from 10 to 13 m
    // (beyond an edge).
    map.insert(&report(
        SECOND / 2,
        "erim",
        &[(12.0, 0.0)],
        rectangle(11.6, 12.4, -0.4, 0.4),
    ))
    .unwrap();
    let mut image = report(SECOND, "erim", &[], rectangle(5.0, 15.0, -4.0, 4.0));
    image.shadows = Shadows {
        origin: Point2::new(0.0, 0.0),
        sectors: (-10..=10)
            .map(|k| Shadow {
                azimuth: k as f32 * 0.01,
                half_width: 0.0051,
                near: 10.0,
                far: 13.0,
            })
            .collect(),
    };
    let outcome = map.insert(&image).unwrap();
    let snapshot = map.snapshot();
    for (x, y, seen) in [
        (9.7, 0.0, true),
        (10.5, 0.0, false),
        (12.5, 0.9, false),
        (12.5, -0.9, false),
        (12.5, 2.0, true),
        (13.5, 0.0, true),
    ] {
        assert_eq!(snapshot.is_seen(x, y), seen, "({x}, {y})");
    }
    // Pruning keeps 002 §5's footprint: the cell, not reported again, goes.
    assert_eq!(outcome.pruned, 1);
    assert!(snapshot.patches.is_empty());
}

#[test]
fn cells_under_the_vehicle_are_cleared_and_counted() {
    // Body: 0.6 m behind the rear axle to 4.0 m ahead, 1.1 m each side.
    let mut map = map();
    map.update(&pose_at(0, 0.0, 0.0, 0.0));
    // A cell 2 m ahead (a slope cell the vehicle will drive onto), one
    // beside the body and one ahead of its bumper; the image saw none of
    // the ground below so nothing prunes them.
    let cells = [(6.1, 0.1), (6.1, 1.9), (10.1, 0.1)];
    map.insert(&report(0, "erim", &cells, rectangle(30.0, 40.0, -5.0, 5.0)))
        .unwrap();
    assert_eq!(map.len(), 3);
    // The vehicle drives 4 m forward: the first cell is now under its
    // bonnet (2.1 m ahead of the rear axle), the second 0.8 m beside its
    // flank, the third beyond its bumper.
    map.update(&pose_at(SECOND, 4.0, 0.0, 0.0));
    let kept = positions(&map);
    assert_eq!(kept.len(), 2, "{kept:?}");
    assert!(
        kept.iter().all(|&(x, y)| y.abs() > 1.1 || x > 4.0),
        "{kept:?}"
    );
    assert_eq!(map.stats().cleared_under_vehicle, 1);
    // A late report placing a cell under the body is cleared at once too
    // (it was captured before the vehicle drove there).
    map.insert(&report(
        SECOND / 2,
        "erim",
        &[(5.0, -0.5)],
        rectangle(30.0, 40.0, -5.0, 5.0),
    ))
    .unwrap();
    assert_eq!(map.len(), 2);
    assert_eq!(map.stats().cleared_under_vehicle, 2);
    // Turning on the spot sweeps the body over the flank cell.
    map.update(&pose_at(2 * SECOND, 4.0, 0.0, 0.5));
    assert_eq!(map.len(), 1, "{:?}", positions(&map));
    assert_eq!(map.stats().cleared_under_vehicle, 3);
}

/// A wall 0.4 m thick from (10, -2) to (10.4, 2), as a 10 cm occupancy grid.
fn wall() -> std::sync::Arc<arcnav_localmap::StaticMap> {
    let grid = arcnav_localmap::OccupancyGrid {
        resolution_m: 0.1,
        origin: planar_isometry(10.0, -2.0, 0.0),
        cols: 4,
        rows: 40,
        occupied: vec![true; 160],
    };
    std::sync::Arc::new(arcnav_localmap::StaticMap::from_grid(&grid, 0.4).unwrap())
}

#[test]
fn a_static_map_joins_the_window_is_never_pruned_and_is_not_stored_twice() {
    let mut map = map_as_002();
    map.set_static_map(wall());
    assert!(map.is_empty(), "no pose yet: nothing is placed");
    // 15 m back, facing +x: the wall is beyond the 20 m window... at 25 m.
    map.update(&pose_at(0, -15.0, 0.0, 0.0));
    assert!(map.is_empty(), "the wall 25 m ahead is outside the window");
    map.update(&pose_at(SECOND, 0.0, 0.0, 0.0));
    let statics = map
        .snapshot()
        .patches
        .iter()
        .filter(|p| p.reasons.contains(Reasons::STATIC_MAP))
        .count();
    assert_eq!(statics, 10, "a 4 m wall is ten 0.4 m patches");
    assert_eq!(map.stats().static_patches_added, 10);
    // An image that sees the wall's ground and reports nothing there does
    // not prune it; its cells on the wall are not stored again, those
    // elsewhere are.
    let outcome = map
        .insert(&report(
            SECOND,
            "erim",
            &[(10.1, 0.1), (10.3, -1.5), (6.0, 3.0)],
            rectangle(2.0, 18.0, -8.0, 8.0),
        ))
        .unwrap();
    assert_eq!(outcome.new_patches, 1);
    assert_eq!(map.stats().already_in_static_map, 2);
    map.insert(&report(
        SECOND + 1,
        "erim",
        &[],
        rectangle(2.0, 18.0, -8.0, 8.0),
    ))
    .unwrap();
    let patches = map.snapshot().patches.clone();
    assert_eq!(
        patches.len(),
        10,
        "the perception cell was pruned, the wall not"
    );
    assert!(patches.iter().all(|p| p.reasons == Reasons::STATIC_MAP));
    // Driving past, the wall leaves the window and comes back with it.
    map.update(&pose_at(2 * SECOND, 12.0, 30.0, 0.0));
    assert!(map.is_empty());
    map.update(&pose_at(3 * SECOND, 12.0, 12.0, 0.0));
    assert!(map.is_empty(), "behind and beside beyond the window");
    map.update(&pose_at(4 * SECOND, 0.0, 5.0, 0.0));
    assert_eq!(map.len(), 10);
}
