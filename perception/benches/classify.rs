//! Classification throughput of one image of a rough scene, in valid points
//! per second on one core. Target: ≥ 50 million points/s/core (the paper's
//! SparcII did about 80 thousand: 16 384 pixels in ~200 ms).
//! The `_two_threads` variant hands half of the binning and of the cell
//! judging to a helper thread (a one-thread rayon pool, as the live
//! executors do; the result is identical).
//! Run with `cargo bench -p arcnav-perception`.

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    InOrder, ObstacleReport, PerceptionConfig, RangeImage, Runner, SensorModel,
};
use arcnav_vehicle::Isometry;
use divan::counter::ItemsCount;
use divan::{Bencher, black_box};

fn main() {
    divan::main();
}

/// Rolling ground with ridges, scattered 40-80 cm rocks and a ditch.
fn rough(x: f64, y: f64) -> f64 {
    let ground = 0.35 * (0.21 * x).sin() * (0.17 * y).cos() + 0.06 * (1.3 * x + 0.7 * y).sin();
    let (cx, cy) = ((x / 6.0).round() * 6.0, (y / 6.0).round() * 6.0);
    let hash = ((cx * 12.9898 + cy * 78.233).sin() * 43_758.545)
        .fract()
        .abs();
    let rock = if hash > 0.6 && (x - cx).hypot(y - cy) < 0.8 {
        0.4 + 0.4 * hash
    } else {
        0.0
    };
    let ditch = if (25.0..26.2).contains(&x.abs()) {
        -0.8
    } else {
        0.0
    };
    ground + rock + ditch
}

fn scene_image(sensor: &SensorModel) -> RangeImage {
    sensor.render(
        0,
        &Isometry::identity(),
        &HeightFunction::with_step(rough, 0.1),
    )
}

/// Runs the first task here and the others on a helper pool.
struct Helpers(rayon::ThreadPool);

impl Runner for Helpers {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        self.0.in_place_scope(|scope| {
            let (first, rest) = tasks.split_at_mut(1);
            for task in rest {
                scope.spawn(move |_| task());
            }
            first.iter_mut().for_each(|task| task());
        });
    }
}

fn bench_image(bencher: Bencher, sensor: SensorModel) {
    bench_image_with(bencher, sensor, &InOrder);
}

fn bench_image_with(bencher: Bencher, sensor: SensorModel, runner: &dyn Runner) {
    let image = scene_image(&sensor);
    let mut evaluator = PerceptionConfig::default()
        .build_evaluator()
        .unwrap_or_else(|e| panic!("{e}"));
    let mut report = ObstacleReport::default();
    let stats = evaluator
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap_or_else(|e| panic!("{e}"));
    println!(
        "{}: {} pixels, {} valid points, {} cells, {} untraversable in {} regions",
        sensor.id,
        stats.pixels,
        stats.valid_points,
        stats.cells_evaluated,
        stats.untraversable,
        stats.regions
    );
    bencher
        .counter(ItemsCount::new(stats.valid_points))
        .bench_local(|| {
            evaluator
                .evaluate_with(
                    black_box(&image),
                    &Isometry::identity(),
                    &mut report,
                    runner,
                )
                .map(|s| s.untraversable)
        });
}

#[divan::bench]
fn erim_64x256(bencher: Bencher) {
    bench_image(bencher, SensorModel::erim());
}

#[divan::bench]
fn lidar_128x2048(bencher: Bencher) {
    bench_image(bencher, SensorModel::lidar128());
}

#[divan::bench]
fn lidar_128x2048_two_threads(bencher: Bencher) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap_or_else(|e| panic!("{e}"));
    bench_image_with(bencher, SensorModel::lidar128(), &Helpers(pool));
}
