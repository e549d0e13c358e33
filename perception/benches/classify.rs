//! Classification throughput of one image of a rough scene, in valid points
//! per second on one core. Target: ≥ 50 million points/s/core (the paper's
//! SparcII did about 80 thousand: 16 384 pixels in ~200 ms).
//! The `_two_threads` variant hands half of the binning and of the cell
//! judging to a helper thread (a one-thread rayon pool, as the live
//! executors do; the result is identical).
//! The `_without_drop_offs` variants turn `[perception.drop_off]` off
//! (the classifier then runs without the column walk, as before drop-offs
//! existed); at the end the cost of drop-off detection is printed as the
//! relative difference (target: within 10 %).
//! Run with `cargo bench -p arcnav-perception`.

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    InOrder, ObstacleReport, PerceptionConfig, RangeImage, Runner, SensorModel,
};
use arcnav_vehicle::Isometry;
use divan::counter::ItemsCount;
use divan::{Bencher, black_box};

/// `cargo test --benches` runs this without `--bench`: once, quickly, to
/// check that it still runs; `cargo bench` passes `--bench` for the figures.
fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

fn main() {
    divan::main();
    drop_off_cost();
}

/// Times `evaluate` with drop-off detection on and off, alternating
/// rounds so both see the same machine load, and prints the difference.
fn drop_off_cost() {
    println!("\ncost of drop-off detection (median of 15 rounds, one core):");
    for sensor in [SensorModel::erim(), SensorModel::lidar128()] {
        let image = scene_image(&sensor);
        let mut evaluators = [true, false].map(|enabled| {
            let mut config = PerceptionConfig::default();
            config.drop_off.enabled = enabled;
            config.build_evaluator().unwrap_or_else(|e| panic!("{e}"))
        });
        let mut report = ObstacleReport::default();
        let iterations = if quick() {
            1
        } else {
            (4_000_000 / image.range.len()).max(5)
        };
        let mut rounds: [Vec<f64>; 2] = Default::default();
        for _ in 0..if quick() { 1 } else { 15 } {
            for (evaluator, times) in evaluators.iter_mut().zip(&mut rounds) {
                let start = std::time::Instant::now();
                for _ in 0..iterations {
                    let _ = black_box(evaluator.evaluate(
                        black_box(&image),
                        &Isometry::identity(),
                        &mut report,
                    ));
                }
                times.push(start.elapsed().as_secs_f64() / iterations as f64);
            }
        }
        let [with, without] = rounds.map(|mut times| {
            times.sort_by(f64::total_cmp);
            times[times.len() / 2]
        });
        println!(
            "  {:>8} {:>4}x{:<4}: {:8.1} µs with, {:8.1} µs without: {:+.1} %",
            sensor.id,
            image.rows(),
            image.cols(),
            with * 1e6,
            without * 1e6,
            100.0 * (with / without - 1.0)
        );
    }
}

/// The rough scene seen by `sensor`, rendered once per sensor (marching
/// every ray through the analytic scene takes seconds; every case reads
/// the same image).
fn scene_image(sensor: &SensorModel) -> RangeImage {
    static IMAGES: std::sync::Mutex<Vec<(String, RangeImage)>> = std::sync::Mutex::new(Vec::new());
    let mut images = IMAGES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((_, image)) = images.iter().find(|(id, _)| *id == sensor.id) {
        return image.clone();
    }
    let image = sensor.render(
        0,
        &Isometry::identity(),
        // Quick mode marches 0.5 m steps: it checks that the cases run.
        &HeightFunction::with_step(
            arcnav_perception::scene::rough_ground,
            if quick() { 0.5 } else { 0.1 },
        ),
    );
    images.push((sensor.id.clone(), image.clone()));
    image
}

fn bench_image(bencher: Bencher, sensor: SensorModel) {
    bench_image_with(bencher, sensor, &InOrder);
}

fn bench_image_with(bencher: Bencher, sensor: SensorModel, runner: &dyn Runner) {
    bench_configured(bencher, sensor, runner, &PerceptionConfig::default());
}

fn bench_configured(
    bencher: Bencher,
    sensor: SensorModel,
    runner: &dyn Runner,
    config: &PerceptionConfig,
) {
    let image = scene_image(&sensor);
    let mut evaluator = config.build_evaluator().unwrap_or_else(|e| panic!("{e}"));
    let mut report = ObstacleReport::default();
    let stats = evaluator
        .evaluate(&image, &Isometry::identity(), &mut report)
        .unwrap_or_else(|e| panic!("{e}"));
    println!(
        "{}: {} pixels, {} valid points, {} cells, {} untraversable in {} regions, {} shadows",
        sensor.id,
        stats.pixels,
        stats.valid_points,
        stats.cells_evaluated,
        stats.untraversable,
        stats.regions,
        report.shadows.sectors.len()
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
    bench_image_with(bencher, SensorModel::lidar128(), &pool);
}

fn without_drop_offs() -> PerceptionConfig {
    let mut config = PerceptionConfig::default();
    config.drop_off.enabled = false;
    config
}

#[divan::bench]
fn erim_64x256_without_drop_offs(bencher: Bencher) {
    bench_configured(bencher, SensorModel::erim(), &InOrder, &without_drop_offs());
}

#[divan::bench]
fn lidar_128x2048_without_drop_offs(bencher: Bencher) {
    bench_configured(
        bencher,
        SensorModel::lidar128(),
        &InOrder,
        &without_drop_offs(),
    );
}
