//! The evaluators of papers 000 (`height_diff`) and 001 (`pca`) on analytic
//! scenes rendered through the sensor model, and the registry that builds
//! every evaluator by name.

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    EvaluatorPlugin, EvaluatorRegistry, HeightDiff, HierarchicalPca, ImageStats, ObstacleReport,
    PerceptionConfig, PerceptionError, RangeImage, Reasons, Runner, SensorModel, TerrainEvaluator,
};
use arcnav_vehicle::frames::isometry_from_xyz_rpy;
use arcnav_vehicle::{Isometry, VehicleConfig};

/// `image` with deterministic range noise of about `sigma` (uniform, the
/// same standard deviation).
fn noisy(mut image: RangeImage, sigma: f32) -> RangeImage {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    for r in image.range.iter_mut().filter(|r| r.is_finite()) {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let u = (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        *r += u * sigma * 12f32.sqrt();
    }
    image
}

fn render(sensor: &SensorModel, height: impl Fn(f64, f64) -> f64 + Sync) -> RangeImage {
    sensor.render(
        1_000_000,
        &Isometry::identity(),
        &HeightFunction::new(height),
    )
}

fn height_diff() -> HeightDiff {
    let p = PerceptionConfig::default();
    HeightDiff::new(p.height_diff.clone(), &p)
}

fn pca() -> HierarchicalPca {
    let p = PerceptionConfig::default();
    HierarchicalPca::new(p.pca.clone(), &p)
}

/// The values of `layer` at cells whose level-frame centre satisfies `inside`.
fn values_where(
    index: impl Fn(f32, f32) -> Option<usize>,
    layer: &[f32],
    inside: impl Fn(f32, f32) -> bool,
) -> Vec<f32> {
    let mut out = Vec::new();
    let mut x = -22.0f32;
    while x < 22.0 {
        let mut y = -12.0f32;
        while y < 12.0 {
            if inside(x, y)
                && let Some(i) = index(x, y)
                && layer[i].is_finite()
            {
                out.push(layer[i]);
            }
            y += 0.1;
        }
        x += 0.1;
    }
    out
}

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

fn evaluate(
    evaluator: &mut dyn TerrainEvaluator,
    image: &RangeImage,
) -> (ObstacleReport, ImageStats) {
    let mut report = ObstacleReport::default();
    let stats = evaluator
        .evaluate(image, &Isometry::identity(), &mut report)
        .unwrap();
    (report, stats)
}

// ---- 000: height differences ----

#[test]
fn a_step_shows_in_d1_and_the_cost_follows_000() {
    // D̃ of a step s: min(.5, 5s) + min(.5, 2.5s) + min(.5, 3.5s); 1 from 9 cm.
    for (step, obstacle, absolute) in [(0.06, false, false), (0.1, true, false), (0.25, true, true)]
    {
        let image = noisy(
            render(
                &SensorModel::lidar64(),
                move |x, _| {
                    if x > 8.05 { step } else { 0.0 }
                },
            ),
            0.01,
        );
        let mut hd = height_diff();
        let (report, _) = evaluate(&mut hd, &image);
        let maps = hd.maps();
        let index = |x, y| maps.index(x, y);
        let at_edge = values_where(index, &maps.differences[0], |x, y| {
            (7.9..8.2).contains(&x) && y.abs() < 3.0
        });
        let away = values_where(index, &maps.differences[0], |x, y| {
            (4.0..7.0).contains(&x) && y.abs() < 3.0
        });
        let edge_max = at_edge.iter().copied().fold(0.0, f32::max);
        assert!(
            (edge_max - step as f32).abs() < 0.04,
            "D_1 at a {step} m step peaks at {edge_max}"
        );
        assert!(mean(&away) < 0.03, "D_1 on flat ground is {}", mean(&away));
        let on_step = report
            .cells
            .iter()
            .filter(|c| c.reasons.contains(Reasons::HEIGHT_DIFFERENCE))
            .filter(|c| (7.7..8.4).contains(&c.x) && c.y.abs() < 3.0)
            .count();
        assert_eq!(
            on_step > 20,
            obstacle,
            "{step} m step: {on_step} height-difference cells on its edge"
        );
        let absolutes = values_where(
            index,
            &maps
                .absolute
                .iter()
                .map(|&a| f32::from(u8::from(a)))
                .collect::<Vec<_>>(),
            |x, y| (7.7..8.4).contains(&x) && y.abs() < 3.0,
        );
        assert_eq!(
            absolutes.iter().sum::<f32>() > 20.0,
            absolute,
            "{step} m step"
        );
        let elsewhere = report
            .cells
            .iter()
            .filter(|c| c.reasons.contains(Reasons::HEIGHT_DIFFERENCE))
            .filter(|c| c.x < 7.5 && c.x > 3.0)
            .count();
        assert_eq!(
            elsewhere, 0,
            "{step} m step: obstacles on the flat before it"
        );
    }
}

#[test]
fn d_d_inflates_absolute_obstacles_by_the_robot_radius_and_never_lowers_the_cost() {
    // 000 §5.1: D_D = max{D̃, local mean}, with absolute obstacles inflated
    // by the robot radius. A 25 cm step at x = 8.05 m is absolute along its
    // edge; the flat ground before it is not.
    let image = noisy(
        render(
            &SensorModel::lidar64(),
            |x, _| if x > 8.05 { 0.25 } else { 0.0 },
        ),
        0.01,
    );
    let mut hd = height_diff();
    evaluate(&mut hd, &image);
    let maps = hd.maps();
    let radius = PerceptionConfig::default().height_diff.robot_radius_m as f32;
    let index = |x, y| maps.index(x, y);
    let band = |from: f32, to: f32| {
        values_where(index, &maps.drivability, move |x, y| {
            (from..to).contains(&x) && y.abs() < 2.0
        })
    };
    // Flat cells within the radius of the edge (less a cell for where the
    // edge's cells lie): inflated to at least 1.
    let inflated = band(8.0 - radius + 0.2, 7.9);
    assert!(inflated.len() > 100, "{} cells", inflated.len());
    let low = inflated.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(low >= 1.0, "D_D within the robot radius of the step: {low}");
    // Beyond the radius and the averaging square, flat ground stays low.
    let beyond = band(8.0 - radius - 1.5, 8.0 - radius - 0.4);
    assert!(beyond.len() > 100, "{} cells", beyond.len());
    let high = beyond.iter().copied().fold(0.0, f32::max);
    assert!(high < 0.5, "D_D on flat ground beyond the radius: {high}");
    // D_D is never below D̃ (inflation also reaches unknown cells).
    for (&d, &cost) in maps.drivability.iter().zip(&maps.cost) {
        assert!(cost.is_nan() || d >= cost, "D_D {d} below D̃ {cost}");
    }
}

#[test]
fn a_step_short_of_an_obstacle_is_reported_as_graded_ground_with_its_cost() {
    // 7 cm: D̃ = 0.35 + 0.175 + 0.245 = 0.77, below 1 and above
    // graded_from (0.75): graded ground of cost D̃, no reasons. 12 cm: cost 1.
    for (step, graded) in [(0.07, true), (0.12, false)] {
        let image = noisy(
            render(
                &SensorModel::lidar64(),
                move |x, _| {
                    if x > 8.05 { step } else { 0.0 }
                },
            ),
            0.005,
        );
        let (report, stats) = evaluate(&mut height_diff(), &image);
        let edge: Vec<_> = report
            .cells
            .iter()
            .filter(|c| (7.7..8.4).contains(&c.x) && c.y.abs() < 3.0)
            .collect();
        assert!(
            edge.len() > 20,
            "{step} m: {} cells on the edge",
            edge.len()
        );
        if graded {
            let costs: Vec<f32> = edge.iter().map(|c| c.cost).collect();
            assert!(
                edge.iter()
                    .all(|c| !c.is_obstacle() && c.reasons.is_empty()),
                "{step} m: {edge:?}"
            );
            let top = costs.iter().copied().fold(0.0, f32::max);
            assert!((0.75..0.95).contains(&top), "{step} m: costs {costs:?}");
            assert!(
                stats.graded as usize >= edge.len() && stats.untraversable == 0,
                "{stats:?}"
            );
            // Their region carries no reason: graded ground is no obstacle.
            let region = report.regions[edge[0].region as usize];
            assert!(region.reasons.is_empty(), "{region:?}");
        } else {
            assert!(
                edge.iter().any(|c| c.is_obstacle() && c.cost == 1.0),
                "{step} m"
            );
        }
        let flat = report
            .cells
            .iter()
            .filter(|c| c.x < 7.0 && c.x > 3.0)
            .count();
        assert_eq!(flat, 0, "{step} m: cells on the flat before it");
    }
}

#[test]
fn a_long_10_degree_incline_shows_in_d6_but_not_in_d1() {
    let slope = 10f64.to_radians().tan();
    let image = noisy(
        render(&SensorModel::lidar64(), move |x, _| {
            slope * (x - 4.0).max(0.0)
        }),
        0.01,
    );
    let mut hd = height_diff();
    let (report, _) = evaluate(&mut hd, &image);
    let maps = hd.maps();
    let on_incline = |x: f32, y: f32| (6.0..12.0).contains(&x) && y.abs() < 4.0;
    let d1 = mean(&values_where(
        |x, y| maps.index(x, y),
        &maps.differences[0],
        on_incline,
    ));
    let d6 = mean(&values_where(
        |x, y| maps.index(x, y),
        &maps.differences[2],
        on_incline,
    ));
    assert!(d1 < 0.05, "D_1 on a 10° incline is {d1}");
    assert!(d6 > 0.08 && d6 > 3.0 * d1, "D_6 {d6} vs D_1 {d1}");
    assert!(
        !report
            .cells
            .iter()
            .any(|c| c.reasons.contains(Reasons::HEIGHT_DIFFERENCE) && c.x < 12.0),
        "a 10° incline is drivable"
    );
}

#[test]
fn two_sensors_overlap_without_an_artificial_obstacle() {
    // Two ERIMs on the roof looking 30° left and right; the right one's
    // mount is off by 12 cm in height from what its images claim.
    let mount = |yaw: f64, z: f64| {
        isometry_from_xyz_rpy([1.5, 0.0, z], 0.0, 18f64.to_radians(), yaw.to_radians())
    };
    let flat = HeightFunction::new(|_, _| 0.0);
    let mut left = SensorModel::erim();
    left.vehicle_from_sensor = mount(30.0, 2.2);
    let mut right = SensorModel::erim();
    right.id = "right".into();
    right.vehicle_from_sensor = mount(-30.0, 2.32);
    let left_image = noisy(left.render(0, &Isometry::identity(), &flat), 0.01);
    let mut right_image = noisy(right.render(0, &Isometry::identity(), &flat), 0.01);
    right_image.vehicle_from_sensor = mount(-30.0, 2.2);
    let mut hd = height_diff();
    let mut stats = ImageStats::default();
    let maps = hd
        .build_maps(
            &[&left_image, &right_image],
            &Isometry::identity(),
            &mut stats,
        )
        .unwrap();
    // The two sensors' heights do disagree where their cells meet...
    let mut disagreements = 0;
    for i in 0..maps.filled.len() - 1 {
        let (a, b) = (maps.filled[i], maps.filled[i + 1]);
        if a.is_finite()
            && b.is_finite()
            && maps.sensor[i] != maps.sensor[i + 1]
            && (a - b).abs() > 0.1
        {
            disagreements += 1;
        }
    }
    assert!(
        disagreements > 50,
        "only {disagreements} cross-sensor steps: the test shows nothing"
    );
    // ...but no difference is taken across them.
    let absolute = maps.absolute.iter().filter(|&&a| a).count();
    let worst = maps
        .cost
        .iter()
        .copied()
        .filter(|c| c.is_finite())
        .fold(0.0, f32::max);
    assert_eq!(
        absolute, 0,
        "absolute obstacles on flat ground (worst D̃ {worst})"
    );
    assert!(worst < 1.0);
}

#[test]
fn a_small_gap_is_filled_and_a_large_one_is_not() {
    let sensor = SensorModel::lidar64();
    let image = render(&sensor, |_, _| 0.0);
    let cols = image.cols();
    // Blank 2° of columns straight ahead (0.28 m wide at 8 m) and 24° to
    // the left (3.4 m).
    let az = &image.beams.azimuth;
    let mut gapped = image.clone();
    for (col, a) in az.iter().enumerate() {
        let a = a.to_degrees();
        if a.abs() < 1.0 || (40.0..64.0).contains(&a) {
            for row in 0..image.rows() {
                gapped.range[row * cols + col] = f32::NAN;
            }
        }
    }
    let mut hd = height_diff();
    let whole = hd
        .build_maps(&[&image], &Isometry::identity(), &mut ImageStats::default())
        .unwrap()
        .height
        .clone();
    let maps = hd
        .build_maps(
            &[&gapped],
            &Isometry::identity(),
            &mut ImageStats::default(),
        )
        .unwrap();
    // Cells the whole image saw and the gapped one did not, in a sector.
    let count = |r0: f32, r1: f32, a0: f32, a1: f32| {
        let (mut unseen, mut filled) = (0, 0);
        for (i, seen) in whole.iter().enumerate() {
            let x = maps.origin[0] + ((i % maps.cols) as f32 + 0.5) * maps.cell;
            let y = maps.origin[1] + ((i / maps.cols) as f32 + 0.5) * maps.cell;
            let (r, a) = (x.hypot(y), y.atan2(x).to_degrees());
            if (r0..r1).contains(&r)
                && (a0..a1).contains(&a)
                && seen.is_finite()
                && maps.height[i].is_nan()
            {
                unseen += 1;
                filled += usize::from(maps.filled[i].is_finite());
            }
        }
        (unseen, filled)
    };
    let (small_unseen, small_filled) = count(5.0, 12.0, -0.5, 0.5);
    assert!(
        small_unseen > 20,
        "the small gap hid only {small_unseen} cells"
    );
    assert!(
        small_filled as f64 >= 0.95 * small_unseen as f64,
        "small gap: {small_filled} of {small_unseen} filled"
    );
    let (large_unseen, large_filled) = count(8.0, 15.0, 49.0, 55.0);
    assert!(
        large_unseen > 100,
        "the large gap hid only {large_unseen} cells"
    );
    assert!(
        (large_filled as f64) < 0.05 * large_unseen as f64,
        "large gap: {large_filled} of {large_unseen} filled"
    );
}

#[test]
fn outliers_are_removed_before_the_height_map() {
    let mut image = render(&SensorModel::lidar64(), |_, _| 0.0);
    let cols = image.cols();
    // Ten isolated returns far short of the ground (a bird, a splash):
    // each would be a 1 m tall spike in the height map.
    let mut spiked = 0;
    for k in 0..10 {
        let i = 50 * cols + 100 + 150 * k;
        if image.range[i].is_finite() {
            image.range[i] *= 0.5;
            spiked += 1;
        }
    }
    let mut hd = height_diff();
    let (report, stats) = evaluate(&mut hd, &image);
    assert_eq!(stats.outliers, spiked);
    assert!(
        report.cells.is_empty(),
        "{} cells from outliers",
        report.cells.len()
    );
}

// ---- 001: hierarchical PCA and roughness ----

#[test]
fn a_flat_tilted_plane_is_never_split_to_10_cm() {
    let slope = 15f64.to_radians().tan();
    let image = noisy(
        render(&SensorModel::lidar64(), move |x, y| {
            slope * (0.6 * x + 0.8 * y)
        }),
        0.01,
    );
    let mut pca = pca();
    let (report, _) = evaluate(&mut pca, &image);
    let maps = pca.maps();
    assert!(maps.regions_judged > 100);
    assert_eq!(
        maps.single_cells_judged, 0,
        "a flat plane was split to single cells"
    );
    assert!(
        report.cells.iter().all(|c| c.reasons == Reasons::DROP_OFF),
        "obstacles on a flat plane"
    );
}

#[test]
fn a_15_cm_box_is_found_at_10_cm_resolution() {
    let image = noisy(
        render(&SensorModel::lidar64(), |x, y| {
            if (6.0..6.5).contains(&x) && (-0.25..0.25).contains(&y) {
                0.15
            } else {
                0.0
            }
        }),
        0.01,
    );
    let mut pca = pca();
    let (report, _) = evaluate(&mut pca, &image);
    let on_box: Vec<_> = report
        .cells
        .iter()
        .filter(|c| c.reasons.contains(Reasons::NOT_FLAT))
        .collect();
    assert!(!on_box.is_empty(), "the box was not found");
    for c in &on_box {
        assert!(
            (5.85..6.65).contains(&c.x) && c.y.abs() < 0.4,
            "a not-flat cell at ({:.2}, {:.2}) away from the box",
            c.x,
            c.y
        );
    }
    assert_eq!(report.cell_size_m, 0.1, "cells of the smallest region");
}

#[test]
fn a_flat_ramp_steeper_than_the_vehicle_climbs_is_an_obstacle() {
    let slope = 35f64.to_radians().tan();
    let image = render(&SensorModel::lidar64(), move |x, _| {
        slope * (x - 8.0).max(0.0)
    });
    let mut pca = pca();
    let (report, _) = evaluate(&mut pca, &image);
    let on_ramp = report
        .cells
        .iter()
        .filter(|c| c.reasons.contains(Reasons::SLOPE) && (8.5..11.0).contains(&c.x))
        .count();
    assert!(on_ramp > 50, "{on_ramp} slope cells on a 35° ramp");
}

#[test]
fn rubble_scores_rougher_than_a_plane_at_the_same_distance() {
    // Rubble: 8 cm bumps every 40 cm, left of the vehicle; flat to the right.
    let image = noisy(
        render(&SensorModel::lidar64(), |x, y| {
            if y > 1.0 {
                0.04 * ((x * 15.7).sin() * (y * 15.7).sin() + 1.0)
            } else {
                0.0
            }
        }),
        0.01,
    );
    let mut pca = pca();
    evaluate(&mut pca, &image);
    let maps = pca.maps();
    let rubble = mean(&values_where(
        |x, y| maps.index(x, y),
        &maps.roughness,
        |x, y| (6.0..10.0).contains(&x) && (2.0..5.0).contains(&y),
    ));
    let plane = mean(&values_where(
        |x, y| maps.index(x, y),
        &maps.roughness,
        |x, y| (6.0..10.0).contains(&x) && (-5.0..-2.0).contains(&y),
    ));
    assert!(
        rubble > 5.0 * plane && rubble > 0.0,
        "rubble {rubble} vs plane {plane}"
    );
}

#[test]
fn rubble_beside_a_track_is_graded_ground_and_the_track_is_not() {
    // Rubble of bumps `amp` high (a 40 cm pattern) left of the vehicle
    // beyond y = 1 m, a smooth track to the right; range noise of 2 cm, as
    // the simulator's.
    let rubble = |amp: f64| {
        move |x: f64, y: f64| {
            if y > 1.0 {
                amp * ((x * 15.7).sin() * (y * 15.7).sin() + 1.0)
            } else {
                0.0
            }
        }
    };
    for sensor in [SensorModel::lidar64(), SensorModel::erim()] {
        let azimuth = &sensor.beams.azimuth;
        let column_spacing =
            f64::from((azimuth[azimuth.len() - 1] - azimuth[0]).abs() / (azimuth.len() - 1) as f32);
        let mut costs = Vec::new();
        for amp in [0.04, 0.08] {
            let image = noisy(render(&sensor, rubble(amp)), 0.02);
            let mut pca = pca();
            let (report, stats) = evaluate(&mut pca, &image);
            // Graded: the rubble's cells, and suspected drop-offs far out on
            // it, where returns lie farther apart than a wheel bridges and
            // a bump's far side dips and rises (their costs add, up to 1).
            let graded: Vec<_> = report.cells.iter().filter(|c| !c.is_obstacle()).collect();
            assert_eq!(stats.graded as usize, graded.len());
            for c in &graded {
                assert!(
                    c.reasons == Reasons::NONE || c.reasons == Reasons::DROP_OFF,
                    "graded ground has no reason but a suspected drop-off: {:?}",
                    c.reasons
                );
                assert!(c.cost > 0.0);
                // A smooth cell is graded only within the scan line's mean
                // filter (9 returns) and the pool of the rubble.
                let spread = 4.5 * column_spacing * c.x.hypot(c.y) + 0.3;
                assert!(
                    c.y > 1.0 - spread,
                    "{}: graded cell on the smooth track at ({:.1}, {:.1})",
                    sensor.id,
                    c.x,
                    c.y
                );
            }
            let on_rubble = |x: f64, y: f64| (6.0..12.0).contains(&x) && (2.0..5.0).contains(&y);
            // The cells judged flat there: only those can be graded.
            let maps = pca.maps();
            let flat: Vec<f32> = maps.flat_region.iter().map(|&s| f32::from(s)).collect();
            let seen = values_where(
                |x, y| maps.index(x, y),
                &flat,
                |x, y| on_rubble(f64::from(x), f64::from(y)),
            )
            .into_iter()
            .filter(|&side| side > 0.0)
            .count();
            assert!(seen > 100, "{}: {seen} rubble cells judged flat", sensor.id);
            let found: Vec<f32> = graded
                .iter()
                .filter(|c| on_rubble(c.x, c.y))
                .map(|c| c.cost)
                .collect();
            assert!(
                found.len() * 100 >= seen * 35,
                "{} with {amp} m bumps: {} of {seen} rubble cells graded",
                sensor.id,
                found.len()
            );
            costs.push(mean(&found));
        }
        assert!(
            costs[1] > costs[0] + 0.1,
            "{}: rougher rubble costs {:.2}, not more than {:.2}",
            sensor.id,
            costs[1],
            costs[0]
        );
    }
}

// ---- the registry ----

#[test]
fn every_built_in_evaluator_is_built_by_name_and_reports_the_same_kind_of_report() {
    let registry = EvaluatorRegistry::builtin();
    assert_eq!(registry.names(), ["cells", "height_diff", "pca"]);
    let image = render(&SensorModel::erim(), |x, y| {
        if (10.0..11.0).contains(&x) && y.abs() < 0.5 {
            0.6
        } else {
            0.0
        }
    });
    for name in registry.names() {
        let config = PerceptionConfig {
            evaluator: name.into(),
            ..Default::default()
        };
        config.validate_for(&VehicleConfig::default()).unwrap();
        let mut evaluator = config.build_evaluator().unwrap();
        assert_eq!(evaluator.name(), name);
        let (report, stats) = evaluate(evaluator.as_mut(), &image);
        assert!(!report.fov.is_empty(), "{name}: no footprint");
        let on_rock = report
            .cells
            .iter()
            .filter(|c| (9.6..11.4).contains(&c.x) && c.y.abs() < 0.9)
            .count();
        assert!(on_rock > 3, "{name}: {on_rock} cells on a 60 cm rock");
        // Every cell is counted: obstacles as untraversable, the rest graded.
        let obstacles = report.cells.iter().filter(|c| c.is_obstacle()).count();
        assert_eq!(stats.untraversable as usize, obstacles, "{name}");
        assert_eq!(
            stats.graded as usize,
            report.cells.len() - obstacles,
            "{name}"
        );
        assert!(
            report
                .cells
                .iter()
                .all(|c| (c.region as usize) < report.regions.len())
        );
    }
}

/// A plug-in: every return higher than `max_height_m` above the vehicle's
/// ground is an obstacle.
struct TooHigh {
    max_height_m: f64,
}

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TooHighConfig {
    max_height_m: f64,
}

impl TerrainEvaluator for TooHigh {
    fn name(&self) -> &'static str {
        "too_high"
    }

    fn evaluate_with(
        &mut self,
        image: &RangeImage,
        _: &Isometry,
        report: &mut ObstacleReport,
        _: &dyn Runner,
    ) -> Result<ImageStats, PerceptionError> {
        report.clear();
        report.cell_size_m = self.max_height_m;
        Ok(ImageStats {
            pixels: image.range.len() as u32,
            ..Default::default()
        })
    }
}

impl EvaluatorPlugin for TooHigh {
    const NAME: &'static str = "too_high";
    const ABOUT: &'static str = "a test plug-in";
    type Config = TooHighConfig;

    fn validate(
        config: &TooHighConfig,
        _: &PerceptionConfig,
        _: &VehicleConfig,
    ) -> Result<(), arcnav_vehicle::ConfigError> {
        if config.max_height_m <= 0.0 {
            return Err(arcnav_vehicle::ConfigError::new(
                "plugins.too_high.max_height_m",
                "must be positive",
            ));
        }
        Ok(())
    }

    fn build(config: TooHighConfig, _: &PerceptionConfig) -> Self {
        Self {
            max_height_m: config.max_height_m,
        }
    }
}

fn perception(toml_text: &str) -> PerceptionConfig {
    toml::from_str(toml_text).unwrap()
}

#[test]
fn a_plug_in_is_configured_by_its_own_table_and_unknown_names_are_refused() {
    let vehicle = VehicleConfig::default();
    let mut registry = EvaluatorRegistry::builtin();
    registry.add::<TooHigh>();
    let config = perception("evaluator = \"too_high\"\n[plugins.too_high]\nmax_height_m = 0.7\n");
    config.validate_with(&registry, &vehicle).unwrap();
    let mut evaluator = registry.build(&config).unwrap();
    assert_eq!(evaluator.name(), "too_high");
    let (report, _) = evaluate(
        evaluator.as_mut(),
        &render(&SensorModel::erim(), |_, _| 0.0),
    );
    assert_eq!(report.cell_size_m, 0.7, "the plug-in did not get its table");

    let bad = perception("evaluator = \"too_high\"\n[plugins.too_high]\nmax_height_m = -1.0\n");
    let err = bad.validate_with(&registry, &vehicle).unwrap_err();
    assert_eq!(err.key, "plugins.too_high.max_height_m");

    let typo = perception("evaluator = \"too_high\"\n[plugins.too_high]\nmax_hieght_m = 1.0\n");
    let err = typo.validate_with(&registry, &vehicle).unwrap_err();
    assert!(err.to_string().contains("max_hieght_m"), "{err}");

    // Without the plug-in registered, its name and its table are refused.
    let err = config.validate_for(&vehicle).unwrap_err();
    assert_eq!(
        err.to_string(),
        "`evaluator`: \"too_high\" is not a known evaluator (known: cells, height_diff, pca)"
    );
    let stray = perception("[plugins.too_high]\nmax_height_m = 0.7\n");
    let err = stray.validate_for(&vehicle).unwrap_err();
    assert_eq!(err.key, "plugins.too_high");
}

#[test]
fn an_evaluator_laxer_than_the_vehicle_is_refused_when_selected() {
    let vehicle = VehicleConfig::default();
    let lax = "[height_diff]\nweights = [4.0, 2.5, 3.5]\n[pca]\nmax_disturbance_m = 0.2\n";
    // Not selected: only parsed (a changed vehicle need not retune them).
    perception(lax).validate_for(&vehicle).unwrap();
    let err = perception(&format!("evaluator = \"height_diff\"\n{lax}"))
        .validate_for(&vehicle)
        .unwrap_err();
    assert_eq!(err.key, "height_diff.weights[0]");
    assert!(err.reason.contains("0.250 m"), "{err}");
    let err = perception(&format!("evaluator = \"pca\"\n{lax}"))
        .validate_for(&vehicle)
        .unwrap_err();
    assert_eq!(err.key, "pca.max_disturbance_m");
    // A key no evaluator has is refused whichever is selected.
    assert!(toml::from_str::<PerceptionConfig>("[pca]\nmax_disturbanse_m = 0.01\n").is_err());
    // Rough ground is passable: a cost of 1 would make it an obstacle.
    for (table, key) in [
        ("rough_max_cost = 1.0", "pca.rough_max_cost"),
        ("rough_from_m = 0.06", "pca.rough_full_m"),
    ] {
        let err = perception(&format!("evaluator = \"pca\"\n[pca]\n{table}\n"))
            .validate_for(&vehicle)
            .unwrap_err();
        assert_eq!(err.key, key, "{table}");
    }
}

#[test]
fn a_grid_too_fine_for_the_region_is_refused_before_anything_is_allocated() {
    // 2 cm cells over 150 m × 200 m: 7.5·10⁷ cells, each layer 300 MB;
    // refused with the key to change, whichever grid evaluator is selected
    // (over the largest region allowed, 1000 m square, they would pass a
    // 32-bit cell index).
    let vehicle = VehicleConfig::default();
    let region = "[region]\nahead_m = 100.0\nbehind_m = 50.0\nhalf_width_m = 100.0\n";
    for name in ["height_diff", "pca"] {
        let text = format!("evaluator = \"{name}\"\n[{name}]\ncell_size_m = 0.02\n{region}");
        let err = perception(&text).validate_for(&vehicle).unwrap_err();
        assert_eq!(err.key, format!("{name}.cell_size_m"), "{err}");
        assert!(err.reason.contains("use larger cells"), "{err}");
        // At their defaults over that region they are fine.
        let text = format!("evaluator = \"{name}\"\n{region}");
        perception(&text).validate_for(&vehicle).unwrap();
    }
}

/// The 15 cm blocks (12 cm square) at 3, 6 and 9 m on the seams at 0° and
/// 45° of a ring of four depth cameras 45° apart (000's), 2.2 m up, tilted
/// 25° down; with the cameras either side of each block's seam.
#[allow(clippy::type_complexity)]
fn blocks_in_a_ring_s_seams() -> (
    HeightFunction<impl Fn(f64, f64) -> f64 + Sync>,
    Vec<(f64, f64, [usize; 2])>,
    Vec<SensorModel>,
) {
    let blocks: Vec<(f64, f64, [usize; 2])> = [0.0f64, 45.0]
        .iter()
        .enumerate()
        .flat_map(|(seam, &angle)| {
            [3.0, 6.0, 9.0].map(move |r: f64| {
                let a = angle.to_radians();
                (r * a.cos(), r * a.sin(), [seam + 1, seam + 2])
            })
        })
        .collect();
    let placed: Vec<(f64, f64)> = blocks.iter().map(|&(x, y, _)| (x, y)).collect();
    let scene = HeightFunction::new(move |x: f64, y: f64| {
        if placed
            .iter()
            .any(|&(bx, by)| (x - bx).abs() < 0.06 && (y - by).abs() < 0.06)
        {
            0.15
        } else {
            0.0
        }
    });
    let ring = [-67.5f64, -22.5, 22.5, 67.5]
        .iter()
        .enumerate()
        .map(|(k, yaw)| {
            let mut camera = SensorModel::depth_camera();
            camera.id = format!("camera{k}");
            camera.vehicle_from_sensor =
                isometry_from_xyz_rpy([0.0, 0.0, 2.2], 0.0, 25f64.to_radians(), yaw.to_radians());
            camera
        })
        .collect();
    (scene, blocks, ring)
}

/// The cells of `report` untraversable within 0.6 m of (x, y).
fn cells_near(report: &ObstacleReport, x: f64, y: f64) -> usize {
    (report.cells.iter())
        .filter(|c| c.cost >= 1.0 && (c.x - x).hypot(c.y - y) < 0.6)
        .count()
}

/// 000 (§III) builds one height map from all of a robot's depth cameras
/// and takes differences within each camera's cells only. Judged one
/// image at a time, an obstacle standing in the seam between two cameras
/// of a ring is reported by each of them, from its own half of the
/// obstacle and the ground before it, so one camera's report never drops
/// what its neighbour saw there (issue 68 asked for fusion on the premise
/// that it does). Judged together (`fuse_within_s`), in one map, each
/// block is reported as well: by the cameras that gave its cells their
/// heights, each cell once.
#[test]
fn an_obstacle_in_the_seam_of_a_ring_is_reported_judged_alone_and_fused() {
    let (scene, blocks, ring) = blocks_in_a_ring_s_seams();
    let images: Vec<RangeImage> = (ring.iter())
        .map(|camera| camera.render(0, &Isometry::identity(), &scene))
        .collect();
    let alone: Vec<ObstacleReport> = (images.iter())
        .map(|image| evaluate(&mut height_diff(), image).0)
        .collect();
    let pose = Isometry::identity();
    let placed: Vec<(&RangeImage, &Isometry)> = images.iter().map(|i| (i, &pose)).collect();
    let mut fused = vec![ObstacleReport::default(); images.len()];
    let results = height_diff().evaluate_fused(&placed, &mut fused, &arcnav_perception::InOrder);
    for result in &results {
        result.as_ref().unwrap();
    }
    for &(x, y, cameras) in &blocks {
        for k in cameras {
            let cells = cells_near(&alone[k], x, y);
            assert!(
                cells >= 5,
                "camera {k} alone reports {cells} cells of the block at ({x:.1}, {y:.1})"
            );
        }
        let cells: usize = fused.iter().map(|r| cells_near(r, x, y)).sum();
        assert!(
            cells >= 5,
            "fused, the ring reports {cells} cells of the block at ({x:.1}, {y:.1})"
        );
    }
    // Fused, no cell is reported by two cameras: each cell has one height,
    // from one camera.
    let mut seen = std::collections::HashSet::new();
    for report in &fused {
        for c in &report.cells {
            let key = ((c.x * 100.0).round() as i64, (c.y * 100.0).round() as i64);
            assert!(
                seen.insert(key),
                "cell ({:.2}, {:.2}) reported twice",
                c.x,
                c.y
            );
        }
    }
    // Each image's own counts: every return is the image's own.
    for (result, image) in results.iter().zip(&images) {
        assert_eq!(result.as_ref().unwrap().pixels as usize, image.range.len());
    }
}

/// Images fused from different capture poses are each placed with their
/// own: a ring whose cameras fired while the vehicle drove 0.8 m and
/// turned 6° puts the blocks where they stand in the world, as each image
/// judged alone does.
#[test]
fn images_fused_from_different_poses_are_each_placed_with_their_own() {
    let (scene, blocks, ring) = blocks_in_a_ring_s_seams();
    let poses: Vec<Isometry> = (0..ring.len())
        .map(|k| {
            let t = k as f64 / 3.0;
            isometry_from_xyz_rpy(
                [-0.8 + 0.8 * t, 0.1 * t, 0.0],
                0.0,
                0.0,
                (6.0 * t).to_radians(),
            )
        })
        .collect();
    let images: Vec<RangeImage> = (ring.iter().zip(&poses))
        .enumerate()
        .map(|(k, (camera, pose))| camera.render(k as i64 * 10_000, pose, &scene))
        .collect();
    let placed: Vec<(&RangeImage, &Isometry)> = images.iter().zip(&poses).collect();
    let mut fused = vec![ObstacleReport::default(); images.len()];
    for result in height_diff().evaluate_fused(&placed, &mut fused, &arcnav_perception::InOrder) {
        result.unwrap();
    }
    for &(x, y, _) in &blocks {
        let cells: usize = fused.iter().map(|r| cells_near(r, x, y)).sum();
        assert!(cells >= 5, "{cells} cells of the block at ({x:.1}, {y:.1})");
    }
    // Nothing where no block stands (a misplaced image would step at the
    // seams or double a block elsewhere).
    for report in &fused {
        for c in report.cells.iter().filter(|c| c.cost >= 1.0) {
            let near = blocks
                .iter()
                .any(|&(x, y, _)| (c.x - x).hypot(c.y - y) < 0.6);
            assert!(
                near,
                "an obstacle at ({:.2}, {:.2}), where none stands",
                c.x, c.y
            );
        }
    }
}

/// `fuse_within_s` asks for one height map: refused with an evaluator that
/// judges each image alone, naming the ones that fuse.
#[test]
fn fusion_is_refused_with_an_evaluator_that_judges_each_image_alone() {
    let vehicle = VehicleConfig::default();
    for name in ["cells", "pca"] {
        let err = perception(&format!("evaluator = \"{name}\"\nfuse_within_s = 0.05\n"))
            .validate_for(&vehicle)
            .unwrap_err();
        assert_eq!(err.key, "fuse_within_s", "{err}");
        assert!(err.reason.contains("height_diff"), "{err}");
    }
    perception("evaluator = \"height_diff\"\nfuse_within_s = 0.05\n")
        .validate_for(&vehicle)
        .unwrap();
    for bad in ["-0.1", "0.6", "nan"] {
        let err = perception(&format!(
            "evaluator = \"height_diff\"\nfuse_within_s = {bad}\n"
        ))
        .validate_for(&vehicle)
        .unwrap_err();
        assert_eq!(err.key, "fuse_within_s", "{err}");
    }
}
