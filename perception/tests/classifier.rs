//! The 002 §4 classifier on synthetic images rendered from analytic scenes
//! through the sensor model (the same ray-casting path the simulator uses).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    BeamTable, ImageError, ImageStats, InOrder, ObstacleReport, PerceptionConfig, PerceptionError,
    RangeImage, Reasons, Runner, SensorModel, TerrainEvaluator,
};
use arcnav_vehicle::frames::{isometry_from_xyz_rpy, planar_isometry};
use arcnav_vehicle::{Isometry, VehicleConfig};
use nalgebra::Point2;

/// Counts allocations made by the current thread while `COUNTING` is set.
struct CountingAllocator;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.with(|a| a.set(a.get() + 1));
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.with(|a| a.set(a.get() + 1));
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// 002's classifier as the paper has it: criterion (b), per-cell slope,
/// on (off by default since attitude is predicted along the arcs, 018).
fn classifier() -> Box<dyn TerrainEvaluator> {
    let mut config = PerceptionConfig::default();
    config.cells.slope = true;
    config.build_evaluator().unwrap()
}

/// Renders `height` with `sensor` from `pose` and classifies the image.
fn classify(
    height: impl Fn(f64, f64) -> f64 + Sync,
    sensor: &SensorModel,
    pose: &Isometry,
) -> (ObstacleReport, ImageStats) {
    let image = sensor.render(1_000_000, pose, &HeightFunction::new(height));
    let mut report = ObstacleReport::default();
    let stats = classifier().evaluate(&image, pose, &mut report).unwrap();
    (report, stats)
}

fn erim_at_origin(height: impl Fn(f64, f64) -> f64 + Sync) -> (ObstacleReport, ImageStats) {
    classify(height, &SensorModel::erim(), &Isometry::identity())
}

/// Every cell lies in `[x0, x1] × [y0, y1]`; returns how many cells there are.
fn all_within(report: &ObstacleReport, x0: f64, x1: f64, y0: f64, y1: f64) -> usize {
    for c in &report.cells {
        assert!(
            (x0..=x1).contains(&c.x) && (y0..=y1).contains(&c.y),
            "cell at ({:.2}, {:.2}) [{}] lies outside [{x0}, {x1}] × [{y0}, {y1}]",
            c.x,
            c.y,
            c.reasons.names()
        );
    }
    report.cells.len()
}

fn count_with(report: &ObstacleReport, reason: Reasons) -> usize {
    report
        .cells
        .iter()
        .filter(|c| c.reasons.contains(reason))
        .count()
}

fn inside(x: f64, y: f64, x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
    (x0..=x1).contains(&x) && (y0..=y1).contains(&y)
}

#[test]
fn flat_ground_has_no_untraversable_cell() {
    let (report, stats) = erim_at_origin(|_, _| 0.0);
    assert!(report.cells.is_empty(), "{:?}", report.cells.first());
    assert!(
        stats.valid_points > 10_000,
        "the ERIM sees the ground: {stats:?}"
    );
    assert_eq!(stats.untraversable, 0);
    assert_eq!(
        stats.valid_points + stats.no_return + stats.out_of_range + stats.outside_grid,
        stats.pixels,
        "every pixel is accounted for"
    );
}

#[test]
fn a_30_cm_step_is_untraversable_along_its_edge_and_nowhere_else() {
    let (report, _) = erim_at_origin(|x, _| if x >= 10.1 { 0.3 } else { 0.0 });
    let n = all_within(&report, 9.8, 10.4, -25.0, 25.0);
    assert!(
        n >= 20,
        "the step edge is found along its length: {n} cells"
    );
    // A step is an elevation change: the cell the face runs through holds
    // both levels (height variation); whether cells beside it also see a
    // jump (discontinuity) depends on where the face falls within the 20 cm
    // cells (here mid-cell: the face's returns bridge the levels); a few
    // sparse edge cells fit only a steep plane.
    let elevation_change = Reasons::HEIGHT_VARIATION.union(Reasons::DISCONTINUITY);
    let by_change = report
        .cells
        .iter()
        .filter(|c| c.reasons.bits() & elevation_change.bits() != 0)
        .count();
    assert!(
        by_change * 10 >= n * 9,
        "{by_change} of {n} cells see the elevation change"
    );
    assert!(count_with(&report, Reasons::HEIGHT_VARIATION) * 10 >= n * 9);
}

#[test]
fn a_half_metre_box_is_untraversable_where_it_stands() {
    let (x0, x1, y0, y1) = (12.0, 13.0, -0.5, 0.5);
    let (report, stats) = erim_at_origin(|x, y| {
        if inside(x, y, x0, x1, y0, y1) {
            0.5
        } else {
            0.0
        }
    });
    let n = all_within(&report, x0 - 0.3, x1 + 0.3, y0 - 0.3, y1 + 0.3);
    assert!(n >= 5, "{n} cells");
    assert!(
        count_with(&report, Reasons::HEIGHT_VARIATION) > 0,
        "its front face spans 0.5 m"
    );
    assert_eq!(
        report.regions.len(),
        1,
        "one box, one region: {:?}",
        report.regions
    );
    assert_eq!(report.regions[0].cells as usize, n);
    assert_eq!(stats.regions, 1);
}

#[test]
fn a_30_degree_slope_is_untraversable_by_slope() {
    let rise = 30f64.to_radians().tan();
    let (report, _) = erim_at_origin(|x, _| if x >= 8.0 { (x - 8.0) * rise } else { 0.0 });
    all_within(&report, 7.8, 40.0, -40.0, 40.0);
    let on_slope = report
        .cells
        .iter()
        .filter(|c| c.x > 8.3 && c.reasons.contains(Reasons::SLOPE))
        .count();
    assert!(on_slope >= 50, "{on_slope} slope cells on the ramp");
}

#[test]
fn a_20_degree_slope_is_traversable() {
    let rise = 20f64.to_radians().tan();
    let (report, _) = erim_at_origin(|x, _| if x >= 8.0 { (x - 8.0) * rise } else { 0.0 });
    assert!(report.cells.is_empty(), "{:?}", report.cells.first());
}

#[test]
fn a_1_m_wide_ditch_is_untraversable_at_its_edges_and_nowhere_else() {
    let (report, _) = erim_at_origin(|x, _| if (10.0..11.0).contains(&x) { -1.0 } else { 0.0 });
    // Its near edge (a drop-off, the last return before the unseen ditch
    // lies up to a row spacing in front of it) and its far wall.
    let n = all_within(&report, 9.4, 11.3, -25.0, 25.0);
    assert!(n >= 20, "{n} cells");
    // The far wall is seen, from its rim down into the ditch.
    assert!(report.cells.iter().any(|c| c.x > 10.8 && c.z_min < -0.2));
}

#[test]
fn a_10_cm_bump_is_traversable() {
    let (report, _) = erim_at_origin(|x, y| {
        if inside(x, y, 10.0, 11.0, -1.0, 1.0) {
            0.1
        } else {
            0.0
        }
    });
    assert!(report.cells.is_empty(), "{:?}", report.cells.first());
}

/// An image of one vertical column of beams, all landing in the cell around
/// (10.1, 0.1) at heights `z` (a thin pole), seen from a sensor 2 m up.
fn pole_image(heights: &[f64]) -> RangeImage {
    let sensor_height = 2.0;
    let x = 10.1;
    let elevation: Vec<f32> = heights
        .iter()
        .map(|z| ((z - sensor_height) / x).atan() as f32)
        .collect();
    let range: Vec<f32> = heights
        .iter()
        .map(|z| (x * x + (z - sensor_height).powi(2)).sqrt() as f32)
        .collect();
    RangeImage {
        utime: 0,
        sensor: "pole".into(),
        vehicle_from_sensor: isometry_from_xyz_rpy([0.0, 0.1, sensor_height], 0.0, 0.0, 0.0),
        beams: BeamTable {
            elevation,
            azimuth: vec![0.0],
        },
        range,
    }
}

#[test]
fn a_cell_with_4_points_is_never_classified_by_slope_or_height_variation() {
    let mut evaluator = classifier();
    let mut report = ObstacleReport::default();
    let four = pole_image(&[0.0, 0.5, 1.0, 1.5]);
    let stats = evaluator
        .evaluate(&four, &Isometry::identity(), &mut report)
        .unwrap();
    assert_eq!((stats.valid_points, stats.cells_evaluated), (4, 1));
    assert!(
        report.cells.is_empty(),
        "4 points spanning 1.5 m are not enough to judge"
    );
    let five = pole_image(&[0.0, 0.4, 0.8, 1.2, 1.6]);
    evaluator
        .evaluate(&five, &Isometry::identity(), &mut report)
        .unwrap();
    assert_eq!(report.cells.len(), 1);
    assert_eq!(report.cells[0].reasons, Reasons::HEIGHT_VARIATION);
}

#[test]
fn flat_ground_seen_from_a_pitched_and_rolled_vehicle_is_still_flat() {
    // A strict classifier: 5° of apparent slope would be flagged.
    let mut config = PerceptionConfig::default();
    config.cells.slope = true;
    config.cells.max_slope_deg = 5.0;
    let mut evaluator = config.build_evaluator().unwrap();
    let pose = isometry_from_xyz_rpy([0.0, 0.0, 0.0], 5f64.to_radians(), 10f64.to_radians(), 0.0);
    let image = SensorModel::erim().render(0, &pose, &HeightFunction::new(|_, _| 0.0));
    let mut report = ObstacleReport::default();
    let stats = evaluator.evaluate(&image, &pose, &mut report).unwrap();
    assert!(stats.valid_points > 5_000);
    assert!(
        report.cells.is_empty(),
        "attitude honoured: {:?}",
        report.cells.first()
    );
    // The same image read as if the vehicle were level shows a slope.
    evaluator
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap();
    assert!(
        count_with(&report, Reasons::SLOPE) > 20,
        "ignoring attitude would tilt the ground"
    );
}

#[test]
fn cells_are_placed_in_the_world_with_the_capture_pose() {
    // The vehicle at (100, 50) heading north; a box 12 m ahead of it.
    let pose = planar_isometry(100.0, 50.0, std::f64::consts::FRAC_PI_2);
    let (report, _) = classify(
        |x, y| {
            if inside(x, y, 99.5, 100.5, 62.0, 63.0) {
                0.5
            } else {
                0.0
            }
        },
        &SensorModel::erim(),
        &pose,
    );
    let n = all_within(&report, 99.2, 100.8, 61.7, 63.3);
    assert!(n >= 5);
    assert!(report.fov.contains(Point2::new(100.0, 60.0)));
    assert!(
        !report.fov.contains(Point2::new(100.0, 40.0)),
        "behind the vehicle is not observed"
    );
}

#[test]
fn a_lidar_sees_all_around_but_not_its_blind_zone() {
    let sensor = SensorModel::lidar64();
    let (report, stats) = classify(
        |x, y| {
            if inside(x, y, -7.0, -6.0, -0.5, 0.5) {
                0.6
            } else {
                0.0
            }
        },
        &sensor,
        &Isometry::identity(),
    );
    let n = all_within(&report, -7.3, -5.7, -0.8, 0.8);
    assert!(
        n >= 3,
        "a box behind the vehicle is found: {n} cells, {stats:?}"
    );
    assert!(report.fov.contains(Point2::new(20.0, 5.0)));
    assert!(report.fov.contains(Point2::new(-7.5, -3.0)));
    assert!(
        !report.fov.contains(Point2::new(1.5, 1.5)),
        "the ground beside the vehicle is hidden by the roof line"
    );
}

/// A box 12 m behind, one 30 m ahead and one 10 m ahead, seen by a 360° lidar.
fn three_boxes(x: f64, y: f64) -> f64 {
    let boxes = [(-25.5, -24.5), (29.5, 30.5), (9.5, 10.5)];
    if boxes
        .iter()
        .any(|&(x0, x1)| inside(x, y, x0, x1, -0.5, 0.5))
    {
        0.6
    } else {
        0.0
    }
}

#[test]
fn only_the_region_around_the_vehicle_is_evaluated() {
    let sensor = SensorModel::lidar64();
    let pose = Isometry::identity();
    let image = sensor.render(1_000_000, &pose, &HeightFunction::new(three_boxes));
    let evaluate = |config: &PerceptionConfig| {
        config.validate_for(&VehicleConfig::default()).unwrap();
        let mut report = ObstacleReport::default();
        let stats = config
            .build_evaluator()
            .unwrap()
            .evaluate(&image, &pose, &mut report)
            .unwrap();
        (report, stats)
    };
    let near = PerceptionConfig::default();
    let (r, wide) = (&near.region, &mut PerceptionConfig::default());
    assert_eq!((r.ahead_m, r.behind_m, r.half_width_m), (22.0, 22.0, 12.0));
    wide.region.ahead_m = 35.0;
    wide.region.behind_m = 30.0;
    let (cropped, cropped_stats) = evaluate(&near);
    let (whole, whole_stats) = evaluate(wide);

    let count = |report: &ObstacleReport, x0: f64, x1: f64| {
        report
            .cells
            .iter()
            .filter(|c| (x0..=x1).contains(&c.x) && c.y.abs() <= 0.8)
            .count()
    };
    for (x0, x1) in [(-25.8, -24.2), (29.2, 30.8)] {
        assert_eq!(count(&cropped, x0, x1), 0, "box at {x0} m lies outside");
        assert!(count(&whole, x0, x1) >= 2, "box at {x0} m: {whole_stats:?}");
    }
    assert!(count(&cropped, 9.2, 10.8) >= 3, "{cropped_stats:?}");
    assert!(
        cropped
            .cells
            .iter()
            .all(|c| (-22.0..=22.0).contains(&c.x) && c.y.abs() <= 12.0),
        "every cell lies in the region"
    );
    // Outside the region, returns are counted, not evaluated; inside it
    // (a cell away from its edge) the cells are the same.
    assert!(cropped_stats.outside_grid > whole_stats.outside_grid);
    assert!(cropped_stats.valid_points < whole_stats.valid_points);
    assert_eq!(
        cropped_stats.valid_points
            + cropped_stats.no_return
            + cropped_stats.out_of_range
            + cropped_stats.outside_grid,
        cropped_stats.pixels
    );
    let interior = |report: &ObstacleReport| {
        report
            .cells
            .iter()
            .filter(|c| (-21.6..=21.6).contains(&c.x) && c.y.abs() <= 11.6)
            .map(|c| (c.x.to_bits(), c.y.to_bits(), c.reasons))
            .collect::<Vec<_>>()
    };
    let (mut a, mut b) = (interior(&cropped), interior(&whole));
    a.sort_by_key(|c| (c.0, c.1));
    b.sort_by_key(|c| (c.0, c.1));
    assert!(!a.is_empty());
    assert_eq!(a, b);
}

#[test]
fn non_uniform_beam_tables_work() {
    // Rows denser towards the horizon, as many lidars have.
    let mut sensor = SensorModel::erim();
    sensor.beams.elevation = (0..64)
        .map(|r| (0.28 - 0.55 * (r as f64 / 63.0).powf(1.6)) as f32)
        .collect();
    let (flat, _) = classify(|_, _| 0.0, &sensor, &Isometry::identity());
    assert!(flat.cells.is_empty());
    let (boxed, _) = classify(
        |x, y| {
            if inside(x, y, 12.0, 13.0, -0.5, 0.5) {
                0.5
            } else {
                0.0
            }
        },
        &sensor,
        &Isometry::identity(),
    );
    assert!(all_within(&boxed, 11.7, 13.3, -0.8, 0.8) >= 3);
}

#[test]
fn invalid_returns_are_skipped_and_counted() {
    let mut image =
        SensorModel::erim().render(0, &Isometry::identity(), &HeightFunction::new(|_, _| 0.0));
    let n = image.range.len();
    image.range[n - 1] = f32::NAN;
    image.range[n - 2] = f32::INFINITY;
    image.range[n - 3] = -4.0;
    image.range[n - 4] = 0.0;
    image.range[n - 5] = 1000.0;
    let mut report = ObstacleReport::default();
    let stats = classifier()
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap();
    assert!(report.cells.is_empty());
    assert!(stats.no_return >= 4);
    assert!(stats.out_of_range >= 1);
    assert_eq!(
        stats.valid_points + stats.no_return + stats.out_of_range + stats.outside_grid,
        stats.pixels
    );
}

#[test]
fn malformed_images_are_typed_errors_and_empty_images_empty_output() {
    let mut evaluator = classifier();
    let mut report = ObstacleReport::default();
    let mut image = SensorModel::erim().blank_image(0);
    image.range.pop();
    assert_eq!(
        evaluator.evaluate(&image, &Isometry::identity(), &mut report),
        Err(PerceptionError::Image(ImageError::ShapeMismatch {
            rows: 64,
            cols: 256,
            values: 64 * 256 - 1
        }))
    );
    let mut image = SensorModel::erim().blank_image(0);
    image.beams.azimuth[3] = f32::NAN;
    assert!(matches!(
        evaluator.evaluate(&image, &Isometry::identity(), &mut report),
        Err(PerceptionError::Image(ImageError::BadBeamAngle {
            table: "azimuth",
            index: 3
        }))
    ));
    let empty = RangeImage {
        utime: 5,
        sensor: "none".into(),
        vehicle_from_sensor: Isometry::identity(),
        beams: BeamTable {
            elevation: vec![],
            azimuth: vec![],
        },
        range: vec![],
    };
    let stats = evaluator
        .evaluate(&empty, &Isometry::identity(), &mut report)
        .unwrap();
    assert_eq!(stats, ImageStats::default());
    assert!(report.cells.is_empty() && report.fov.is_empty());
    assert_eq!(report.utime, 5);
    // An image of nothing but NaN.
    let blank = SensorModel::erim().blank_image(7);
    let stats = evaluator
        .evaluate(&blank, &Isometry::identity(), &mut report)
        .unwrap();
    assert_eq!(stats.no_return, stats.pixels);
    assert!(report.fov.is_empty());
}

#[test]
fn no_allocation_per_image_after_warm_up() {
    let sensor = SensorModel::erim();
    let scene = HeightFunction::new(|x, y| {
        if inside(x, y, 12.0, 13.0, -0.5, 0.5) {
            0.5
        } else {
            0.0
        }
    });
    let image = sensor.render(0, &Isometry::identity(), &scene);
    // Every evaluator, the other papers' too.
    for name in ["cells", "height_diff", "pca"] {
        let config = PerceptionConfig {
            evaluator: name.into(),
            ..Default::default()
        };
        let mut evaluator = config.build_evaluator().unwrap();
        let mut report = ObstacleReport::default();
        evaluator
            .evaluate(&image, &Isometry::identity(), &mut report)
            .unwrap();
        ALLOCATIONS.with(|a| a.set(0));
        COUNTING.with(|c| c.set(true));
        let result = evaluator.evaluate(&image, &Isometry::identity(), &mut report);
        COUNTING.with(|c| c.set(false));
        assert!(result.is_ok() && !report.cells.is_empty(), "{name}");
        assert_eq!(
            ALLOCATIONS.with(Cell::get),
            0,
            "{name}: the second image allocated"
        );
    }
}

#[test]
fn the_same_image_gives_the_same_report() {
    let (a, sa) = erim_at_origin(|x, y| {
        if inside(x, y, 12.0, 13.0, -0.5, 0.5) {
            0.5
        } else {
            0.0
        }
    });
    let (b, sb) = erim_at_origin(|x, y| {
        if inside(x, y, 12.0, 13.0, -0.5, 0.5) {
            0.5
        } else {
            0.0
        }
    });
    assert_eq!(a, b);
    assert_eq!(sa, sb);
}

#[test]
fn thresholds_follow_the_vehicle() {
    // A vehicle that tolerates only 10 cm steps must see the 15 cm bump.
    let vehicle = VehicleConfig {
        tolerated_step_m: 0.1,
        ..Default::default()
    };
    let mut config = PerceptionConfig::default();
    config.cells.max_height_variation_m = vehicle.tolerated_step_m;
    config.cells.max_discontinuity_m = vehicle.tolerated_step_m;
    config.drop_off.min_depth_m = vehicle.tolerated_step_m;
    config.drop_off.max_gap_m = 0.58;
    config.validate_for(&vehicle).unwrap();
    let mut evaluator = config.build_evaluator().unwrap();
    let scene = HeightFunction::new(|x, y| {
        if inside(x, y, 10.0, 11.0, -1.0, 1.0) {
            0.15
        } else {
            0.0
        }
    });
    let image = SensorModel::erim().render(0, &Isometry::identity(), &scene);
    let mut report = ObstacleReport::default();
    evaluator
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap();
    assert!(all_within(&report, 9.7, 11.3, -1.3, 1.3) > 0);
    let (default_report, _) = classify(
        |x, y| {
            if inside(x, y, 10.0, 11.0, -1.0, 1.0) {
                0.15
            } else {
                0.0
            }
        },
        &SensorModel::erim(),
        &Isometry::identity(),
    );
    assert!(
        default_report.cells.is_empty(),
        "the HMMWV drives over 15 cm"
    );
}

/// Runs the tasks on threads of their own, the last one started first.
struct Reversed;

impl Runner for Reversed {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        std::thread::scope(|scope| {
            for task in tasks.iter_mut().rev() {
                scope.spawn(task);
            }
        });
    }
}

#[test]
fn the_result_does_not_depend_on_how_the_parts_ran() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    // Rolling ground with boxes every 6 m, seen all around by the 128×2048
    // lidar (large enough to be split) from a tilted vehicle.
    let sensor = SensorModel::lidar128();
    let rough = |x: f64, y: f64| {
        let (cx, cy) = ((x / 6.0).round() * 6.0, (y / 6.0).round() * 6.0);
        let rock = if (x - cx).abs() < 0.6 && (y - cy).abs() < 0.6 {
            0.5
        } else {
            0.0
        };
        0.2 * (0.3 * x).sin() * (0.2 * y).cos() + rock
    };
    let pose = isometry_from_xyz_rpy([3.0, -2.0, 0.2], 0.02, -0.03, 0.7);
    let image = sensor.render(7, &pose, &HeightFunction::with_step(rough, 0.1));
    let mut evaluator = classifier();
    let (mut in_order, mut threaded) = (ObstacleReport::default(), ObstacleReport::default());
    let a = evaluator
        .evaluate_with(&image, &pose, &mut in_order, &InOrder)
        .unwrap();
    let b = evaluator
        .evaluate_with(&image, &pose, &mut threaded, &Reversed)
        .unwrap();
    assert!(a.untraversable > 10 && a.regions > 5, "{a:?}");
    assert_eq!(a, b);
    assert_eq!(in_order, threaded);
    // And the same again in order (nothing left over from the parts).
    let mut again = ObstacleReport::default();
    assert_eq!(evaluator.evaluate(&image, &pose, &mut again).unwrap(), a);
    assert_eq!(again, in_order);
}

/// An image whose returns land on two flat patches side by side: the cell
/// [10.0, 10.2) × [0, 0.2) at height 0 and the cell [10.2, 10.4) beside it
/// at `step`, five returns in each (two columns), none on a face between
/// them; seen from 2 m up.
fn two_level_image(step: f64) -> RangeImage {
    let sensor_height = 2.0;
    let targets: Vec<(f64, f64)> = [10.23, 10.27, 10.31, 10.35, 10.39]
        .iter()
        .map(|&x| (x, step))
        .chain(
            [10.03, 10.07, 10.11, 10.15, 10.19]
                .iter()
                .map(|&x| (x, 0.0)),
        )
        .collect();
    let elevation = targets
        .iter()
        .map(|(x, z)| ((z - sensor_height) / x).atan() as f32)
        .collect();
    let azimuth = vec![0.004, 0.008];
    let range = targets
        .iter()
        .flat_map(|(x, z)| {
            let r = (x * x + (z - sensor_height).powi(2)).sqrt() as f32;
            [r, r]
        })
        .collect();
    RangeImage {
        utime: 0,
        sensor: "two levels".into(),
        vehicle_from_sensor: isometry_from_xyz_rpy([0.0, 0.0, sensor_height], 0.0, 0.0, 0.0),
        beams: BeamTable { elevation, azimuth },
        range,
    }
}

/// 002 §4 (c): a jump in height between neighbouring cells taller than the
/// vehicle tolerates is untraversable even where each cell is flat (no face
/// was seen between them); a jump it tolerates is not.
#[test]
fn a_jump_between_flat_neighbouring_cells_is_a_discontinuity() {
    let mut evaluator = classifier();
    let mut report = ObstacleReport::default();
    evaluator
        .evaluate(&two_level_image(0.35), &Isometry::identity(), &mut report)
        .unwrap();
    assert_eq!(report.cells.len(), 2, "{:?}", report.cells);
    for cell in &report.cells {
        assert_eq!(
            cell.reasons,
            Reasons::DISCONTINUITY,
            "cell at ({:.2}, {:.2}): {}",
            cell.x,
            cell.y,
            cell.reasons.names()
        );
    }
    let xs: Vec<f64> = report
        .cells
        .iter()
        .map(|c| (c.x * 10.0).round() / 10.0)
        .collect();
    assert!(
        xs.contains(&10.1) && xs.contains(&10.3),
        "both sides: {xs:?}"
    );
    // 15 cm: below the 20 cm the vehicle drives over.
    evaluator
        .evaluate(&two_level_image(0.15), &Isometry::identity(), &mut report)
        .unwrap();
    assert!(report.cells.is_empty(), "{:?}", report.cells);
}
