//! The polar table against the exhaustive ray walk.

use std::sync::Arc;

use super::*;
use crate::tiles::TileCache;
use crate::world::World;

/// The table's answer is the walk's (within a rounding of the last
/// cell's dip).
fn assert_same_hit(
    binned: Option<f64>,
    full: Option<f64>,
    ray: (&Point3<f64>, &Vector3<f64>, f64),
) {
    let (origin, d, reach) = ray;
    match (binned, full) {
        (Some(a), Some(b)) => assert!((a - b).abs() < 1e-6, "{origin} {d}: {a} vs {b}"),
        (None, None) => {}
        _ => panic!("{origin} {d} to {reach} m: {binned:?} vs {full:?}"),
    }
}

#[test]
fn the_pseudo_angle_turns_with_the_heading() {
    let turns: Vec<f64> = (0..64)
        .map(|k| {
            let a = f64::from(k) / 64.0 * std::f64::consts::TAU;
            pseudo_angle(a.cos(), a.sin())
        })
        .collect();
    assert!(turns.windows(2).all(|w| w[0] < w[1]), "{turns:?}");
    assert!(turns[0] == 0.0 && turns[63] < 4.0);
}

#[test]
fn the_direction_at_a_pseudo_angle_has_that_pseudo_angle() {
    for k in 0..400 {
        let p = f64::from(k) / 100.0;
        let (x, y) = direction_at(p);
        assert!((x.hypot(y) - 1.0).abs() < 1e-12);
        assert!((pseudo_angle(x, y) - p).abs() < 1e-12, "{p}");
    }
}

#[test]
fn a_wedge_holds_the_headings_it_was_found_from_and_no_more() {
    let at = |degrees: f64| {
        let a = degrees.to_radians();
        Vector3::new(a.cos(), a.sin(), -0.1)
    };
    let holds = |h: Headings, d: Vector3<f64>| h.column(heading_of(d.x, d.y)).is_some();
    // Across +x, where the bins wrap round: the short way, not the
    // rest of the turn.
    let across = Headings::around([at(-1.5), at(1.4), at(0.2)]).unwrap();
    // 2.9° near an axis, where the pseudo-angle turns fastest.
    assert!(across.width < 40, "{across:?}");
    for degrees in [-1.5, -0.7, 0.0, 1.4] {
        assert!(holds(across, at(degrees)), "{degrees}°");
    }
    for degrees in [-3.0, 3.0, 180.0] {
        assert!(!holds(across, at(degrees)), "{degrees}°");
    }
    // One heading: its bin and two either side.
    let one = Headings::around([at(100.0)]).unwrap();
    assert_eq!(one.width, 5);
    // A quarter turn or more, or straight down: none.
    assert!(Headings::around([at(10.0), at(110.0)]).is_none());
    assert!(Headings::around([at(10.0), Vector3::new(0.0, 0.0, -1.0)]).is_none());
    assert!(Headings::around([]).is_none());
}

#[test]
fn a_wedge_raises_only_the_columns_it_holds_round_the_wrap() {
    let wedge = Headings {
        first: HEADINGS - 3,
        width: 6,
    };
    let mut row = [0.0f32; 6];
    // Bins −5..=1 (wrapping): columns 0..=4 (bins 2045-2047, 0, 1).
    wedge.raise(&mut row, -5, 1, 2.0);
    assert_eq!(row, [2.0, 2.0, 2.0, 2.0, 2.0, 0.0]);
    // Bins far from the wedge: nothing.
    wedge.raise(&mut row, 100, 900, 5.0);
    assert_eq!(row, [2.0, 2.0, 2.0, 2.0, 2.0, 0.0]);
    // The whole turn: all.
    wedge.raise(&mut row, 0, HEADINGS as i64 - 1, 3.0);
    assert_eq!(row, [3.0; 6]);
    let mut all = vec![0.0f32; HEADINGS];
    Headings::ALL.raise(&mut all, HEADINGS as i64 - 2, HEADINGS as i64 + 1, 1.0);
    let raised: Vec<usize> = (0..HEADINGS).filter(|&k| all[k] > 0.0).collect();
    assert_eq!(raised, [0, 1, HEADINGS - 2, HEADINGS - 1]);
}

#[test]
fn rays_from_the_binned_position_meet_what_the_full_walk_meets() {
    // The paper's loop: hills, rocks, trunks, bushes, ditches, banks.
    let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
    let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
    let mut rng = crate::rng::Rng::stream(11, 3);
    let (mut hits, mut rays) = (0, 0);
    let range = 60.0;
    for &(x, y, dz) in &[
        (0.0, 0.0, 2.4),
        (60.0, 35.0, 0.3),
        (-20.0, 80.0, 3.5),
        (130.0, -40.0, -0.1),
        // On a block's corner and edge: headings all round it.
        (12.8, 25.6, 1.0),
        (4.0, 7.25, 2.0),
    ] {
        let view = cache.view(x, y, range + 1.0);
        // Rays along the axes and the diagonals from off the cell grid
        // (from on it they run along cells' edges, touching two at once).
        for (axes, (x, y)) in [(false, (x, y)), (true, (x + 0.013, y + 0.029))] {
            let origin = Point3::new(x, y, world.height(x, y) + dz);
            let polar = PolarView::new(&view, origin, range, 2);
            for _ in 0..3000 {
                let azimuth = if axes {
                    (rng.unit() * 8.0).floor() * std::f64::consts::FRAC_PI_4
                } else {
                    rng.unit() * std::f64::consts::TAU
                };
                // From steeply down to above the horizon.
                let elevation = (rng.unit() * 55.0 - 45.0).to_radians();
                let d = Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
                let reach = 5.0 + 55.0 * rng.unit();
                let binned = polar.cast(&origin, &d, reach);
                let full = view.cast(&origin, &d, reach);
                assert_same_hit(binned, full, (&origin, &d, reach));
                hits += usize::from(full.is_some());
                rays += 1;
            }
        }
    }
    // Both kinds of answer were asked for.
    assert!(hits > rays / 3 && hits < rays * 9 / 10, "{hits} of {rays}");
}

#[test]
fn rays_from_elsewhere_are_cast_in_the_view() {
    let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
    let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
    let view = cache.view(0.0, 0.0, 41.0);
    let origin = Point3::new(0.0, 0.0, world.height(0.0, 0.0) + 2.0);
    let polar = PolarView::new(&view, origin, 40.0, 1);
    let elsewhere = Point3::new(3.0, -2.0, world.height(3.0, -2.0) + 2.0);
    let d = Vector3::new(1.0, 0.2, -0.3).normalize();
    assert_eq!(
        polar.cast(&elsewhere, &d, 40.0),
        view.cast(&elsewhere, &d, 40.0)
    );
    // Beyond the binned range, too.
    let flat = Vector3::new(0.3, 1.0, -0.02).normalize();
    assert_eq!(
        polar.cast(&origin, &flat, 80.0),
        view.cast(&origin, &flat, 80.0)
    );
}

#[test]
fn rays_of_a_wedge_meet_what_the_full_walk_meets_and_others_are_cast_in_the_view() {
    let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
    let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
    let mut rng = crate::rng::Rng::stream(12, 5);
    let range = 60.0;
    let (mut inside, mut outside, mut hits) = (0, 0, 0);
    // From off the cell grid and from a block's corner; wedges across
    // +x (where the bins wrap) and along the diagonals.
    for &(x, y, dz) in &[(60.013, 35.029, 0.3), (12.8, 25.6, 1.0), (-20.0, 80.0, 3.5)] {
        let view = cache.view(x, y, range + 1.0);
        let origin = Point3::new(x, y, world.height(x, y) + dz);
        for centre in [0.0f64, 45.0, 135.0, 200.0, 315.0] {
            let aim = |degrees: f64, elevation: f64| {
                let (a, e) = (degrees.to_radians(), elevation.to_radians());
                Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
            };
            let headings =
                Headings::around([aim(centre - 3.0, -10.0), aim(centre + 3.0, -10.0)]).unwrap();
            let wedge = PolarView::wedge(&view, origin, range, headings);
            for _ in 0..1500 {
                // Mostly within the wedge, some beyond it either side.
                let d = aim(centre + rng.unit() * 10.0 - 5.0, rng.unit() * 55.0 - 45.0);
                let reach = 5.0 + 55.0 * rng.unit();
                let binned = wedge.cast(&origin, &d, reach);
                let full = view.cast(&origin, &d, reach);
                assert_same_hit(binned, full, (&origin, &d, reach));
                let column = headings.column(heading_of(d.x, d.y));
                *if column.is_some() {
                    &mut inside
                } else {
                    &mut outside
                } += 1;
                hits += usize::from(full.is_some());
            }
        }
    }
    assert!(
        inside > outside && outside > 1000,
        "{inside} in, {outside} out"
    );
    assert!(hits > 1000 && hits < inside + outside - 1000, "{hits} hits");
}

#[test]
fn rays_cast_with_avx2_meet_what_the_portable_cast_meets_bit_for_bit() {
    #[cfg(target_arch = "x86_64")]
    if !std::arch::is_x86_feature_detected!("avx2") {
        arcnav_testkit::missing("AVX2 (the cast compiled for it)");
        return;
    }
    let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
    let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
    let range = 45.0;
    let mut hits = 0;
    // A 64-beam lidar's rows from 2.4 m up, level and on a slope
    // (a tilted sensor's rows are not cones round the vertical).
    for &(x, y, tilt) in &[(0.013, 0.029, 0.0), (60.0, 35.0, 0.2), (12.8, 25.6, -0.15)] {
        let view = cache.view(x, y, range + 1.0);
        let origin = Point3::new(x, y, world.height(x, y) + 2.4);
        let polar = PolarView::new(&view, origin, range, 2);
        for row in 0..64 {
            let elevation = (2.0 - 0.5 * f64::from(row)).to_radians();
            let directions: Vec<Vector3<f64>> = (0..2048)
                .map(|col| {
                    let azimuth = f64::from(col) / 2048.0 * std::f64::consts::TAU;
                    let (a, e) = (azimuth, elevation + tilt * azimuth.cos());
                    Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
                })
                .collect();
            let mut dispatched = vec![0.0f32; directions.len()];
            let mut portable = vec![0.0f32; directions.len()];
            polar.cast_each(&origin, &directions, range, &mut dispatched);
            polar.cast_binned(&origin, &directions, range, &mut portable);
            for (col, (a, b)) in dispatched.iter().zip(&portable).enumerate() {
                assert!(
                    a.to_bits() == b.to_bits(),
                    "from {origin}, row {row}, column {col}: {a} vs {b}"
                );
            }
            hits += portable.iter().filter(|r| r.is_finite()).count();
        }
    }
    // Most rays below the horizon met the ground.
    assert!(hits > 3 * 2048 * 40, "{hits} hits");
}

#[test]
fn a_frame_cast_within_its_headings_is_the_frame_cast_through_every_heading() {
    // An ERIM-like image (±64° of azimuth, 16° up to 34° down) from
    // 2.4 m up, facing four ways (one across +x, where the bins wrap) and
    // tilted on a side slope: the table of its headings alone answers
    // every ray as the table of the whole turn does, bit for bit; a ray
    // outside its headings is cast in the view.
    let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
    let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
    let range = 45.0;
    let (mut hits, mut rays) = (0, 0);
    for &(x, y, yaw, tilt) in &[
        (0.013, 0.029, 0.0f64, 0.0f64),
        (60.0, 35.0, 1.9, 0.2),
        (12.8, 25.6, 3.3, -0.15),
        (-20.0, 80.0, -1.2, 0.1),
    ] {
        let view = cache.view(x, y, range + 1.0);
        let origin = Point3::new(x, y, world.height(x, y) + 2.4);
        let aim = |azimuth: f64, elevation: f64| {
            let (a, e) = (yaw + azimuth, elevation + tilt * azimuth.sin());
            Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
        };
        let (left, right) = (64f64.to_radians(), -64f64.to_radians());
        let (top, bottom) = (16f64.to_radians(), -34f64.to_radians());
        let headings = Headings::frame_around([
            aim(left, top),
            aim(left, bottom),
            aim(right, top),
            aim(right, bottom),
        ])
        .expect("128° is within half a turn");
        let within = PolarView::within(&view, origin, range, 2, headings);
        let every = PolarView::new(&view, origin, range, 2);
        for row in 0..64 {
            let elevation = top + (bottom - top) * f64::from(row) / 63.0;
            let directions: Vec<Vector3<f64>> = (0..256)
                .map(|col| aim(left + (right - left) * f64::from(col) / 255.0, elevation))
                .collect();
            let mut a = vec![0.0f32; directions.len()];
            let mut b = vec![0.0f32; directions.len()];
            within.cast_each(&origin, &directions, range, &mut a);
            every.cast_each(&origin, &directions, range, &mut b);
            for (col, (a, b)) in a.iter().zip(&b).enumerate() {
                assert!(
                    a.to_bits() == b.to_bits(),
                    "from {origin}, row {row}, column {col}: {a} vs {b}"
                );
            }
            hits += b.iter().filter(|r| r.is_finite()).count();
            rays += b.len();
        }
        // Behind the sensor: outside the headings, cast in the view.
        let behind = aim(std::f64::consts::PI, -0.3);
        assert_eq!(
            within.cast(&origin, &behind, range),
            view.cast(&origin, &behind, range)
        );
    }
    assert!(hits > rays / 2 && hits < rays, "{hits} of {rays}");
    // A rotating lidar's turn is no wedge.
    let turn = (0..8).map(|k| {
        let a = f64::from(k) * std::f64::consts::FRAC_PI_4;
        Vector3::new(a.cos(), a.sin(), -0.1)
    });
    assert!(Headings::frame_around(turn).is_none());
}
