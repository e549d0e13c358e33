//! One Ganesha cycle — insert one image's report (with consistency pruning
//! against its 128-vertex footprint), the loop at a new pose, and a snapshot —
//! with 1 000, 10 000 and 100 000 cells in the map. Target: ≤ 0.15 ms per
//! cycle at 10 000 cells (Ganesha: ~50 ms on a SparcII, 002 §5).
//! Run with `cargo bench -p arcnav-localmap`.
//!
//! To hold 100 000 cells the window is enlarged (80 m × 80 m) and cells are
//! 0.2 m patches; the default window holds ~3 000 patches of 0.4 m.

use std::cell::Cell;

use arcnav_localmap::{LocalMap, LocalMapConfig};
use arcnav_perception::{FovPolygon, ObstacleCell, ObstacleReport, Reasons};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{Pose, VehicleConfig};
use divan::{Bencher, black_box};
use nalgebra::Point2;

fn main() {
    divan::main();
}

fn config() -> LocalMapConfig {
    LocalMapConfig {
        patch_size_m: 0.2,
        misses_to_drop: u32::MAX,
        ahead_m: 60.0,
        behind_m: 20.0,
        half_width_m: 40.0,
        ..LocalMapConfig::default()
    }
}

/// A deterministic spread of `n` distinct cells over the window, none
/// under the vehicle standing at the origin (the map clears the ground
/// under its body, so such a cell would not be kept).
fn cells(n: usize) -> Vec<ObstacleCell> {
    let (columns, rows) = (400usize, 400usize);
    let under_body = |x: f64, y: f64| (-3.0..=5.0).contains(&x) && y.abs() <= 2.5;
    let stride = (columns * rows / (n + n / 50 + 1)).max(1);
    (0..columns * rows)
        .map(|k| (k * stride + (k * 7919) % stride) % (columns * rows))
        .map(|slot| {
            (
                -19.9 + (slot % columns) as f64 * 0.2,
                -39.9 + (slot / columns) as f64 * 0.2,
            )
        })
        .filter(|&(x, y)| !under_body(x, y))
        .take(n)
        .map(|(x, y)| ObstacleCell {
            x,
            y,
            z_min: 0.0,
            z_max: 0.4,
            reasons: Reasons::HEIGHT_VARIATION,
            region: 0,
            cost: 1.0,
        })
        .collect()
}

/// A 128-vertex footprint ahead of the vehicle: an annular sector 3-40 m.
fn footprint() -> FovPolygon {
    let far: Vec<Point2<f64>> = (0..64)
        .map(|k| {
            let a = -1.1 + 2.2 * k as f64 / 63.0;
            Point2::new(40.0 * a.cos(), 40.0 * a.sin())
        })
        .collect();
    let near = far
        .iter()
        .rev()
        .map(|p| Point2::new(p.x * 3.0 / 40.0, p.y * 3.0 / 40.0));
    FovPolygon::new(far.iter().copied().chain(near).collect())
}

#[divan::bench(args = [1_000, 10_000, 100_000])]
fn insert_loop_snapshot(bencher: Bencher, n: usize) {
    let config = config();
    let mut map = LocalMap::new(&config, &VehicleConfig::default());
    map.update(&Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0)));
    let all = cells(n);
    // Fill the map with every cell, then cycle on an image seeing 200 of them.
    let fill = ObstacleReport {
        utime: 1,
        sensor: "erim".into(),
        cell_size_m: 0.2,
        cells: all.clone(),
        regions: vec![],
        fov: FovPolygon::default(),
        shadows: Default::default(),
        ..ObstacleReport::default()
    };
    map.insert(&fill).expect("the fill is valid");
    assert_eq!(map.len(), n, "every cell has its own patch");
    let seen: Vec<ObstacleCell> = all
        .iter()
        .filter(|c| c.x > 3.0)
        .take(200)
        .copied()
        .collect();
    let mut image = ObstacleReport {
        cells: seen,
        fov: FovPolygon::default(),
        ..fill
    };
    image.fov = footprint();
    let time = Cell::new(1_000i64);
    bencher.bench_local(|| {
        let t = time.get() + 1_000;
        time.set(t);
        image.utime = t;
        // Confirm what the image sees; with misses_to_drop > 1 nothing in
        // the footprint is lost across iterations, but every patch is judged.
        let _ = map.insert(black_box(&image));
        let wiggle = if (t / 1_000) % 2 == 0 { 0.01 } else { 0.0 };
        map.update(&Pose::at_rest(t, planar_isometry(wiggle, 0.0, 0.0)));
        map.snapshot().len()
    });
}
