//! Time per image of each terrain evaluator, on one core, printed:
//!
//! - every evaluator on one 128×2048 lidar image of a rough scene;
//! - `height_diff` on eight 240×320 depth images at once (paper 000's ring
//!   of cameras at QVGA: ~50 ms on an i7-4770K there; target ≤ 5 ms here),
//!   the maps alone (`build_maps`) and with the footprint, shadows and
//!   drop-offs of each image (`evaluate` per image).
//!
//! Run with `cargo bench -p arcnav-perception --bench evaluators`.

use std::time::Instant;

use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    HeightDiff, ImageStats, ObstacleReport, PerceptionConfig, RangeImage, SensorModel,
};
use arcnav_vehicle::Isometry;
use arcnav_vehicle::frames::isometry_from_xyz_rpy;

/// `cargo test --benches` runs this without `--bench`: once, quickly, to
/// check that it still runs; `cargo bench` passes `--bench` for the figures.
fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

/// Median wall time of `f` over rounds of at least `min_s`, ms.
fn time_ms(mut f: impl FnMut()) -> f64 {
    f();
    let mut times = Vec::new();
    let started = Instant::now();
    let rounds = if quick() { 1 } else { 15 };
    while times.len() < rounds
        || (!quick() && started.elapsed().as_secs_f64() < 2.0 && times.len() < 200)
    {
        let t = Instant::now();
        f();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// The rough scene every part renders.
type Scene = HeightFunction<fn(f64, f64) -> f64>;

fn main() {
    // `-- lidar` or `-- ring` runs one part (cargo passes `--bench` too).
    let parts: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let run = |part: &str| parts.is_empty() || parts.iter().any(|p| p == part);
    // Quick mode marches 0.5 m steps: it checks that the parts run.
    let step = if quick() { 0.5 } else { 0.1 };
    let scene: Scene = HeightFunction::with_step(arcnav_perception::scene::rough_ground, step);
    if run("lidar") {
        lidar_image(&scene);
    }
    if run("ring") {
        depth_ring(&scene, None);
        // Real depth cameras are noisy: noise moves returns across cell
        // boundaries (more runs to bin) and makes the median count more.
        depth_ring(&scene, Some(0.02));
    }
}

/// `image` with deterministic range noise of standard deviation `sigma`
/// (uniform), one return in 200 dropped and one in 997 a spike at half
/// its range.
fn noisy(image: &mut RangeImage, sigma: f32, seed: u64) {
    let mut state = 0x2545_f491_4f6c_dd1d_u64 ^ seed;
    for r in image.range.iter_mut().filter(|r| r.is_finite()) {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let u = (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        *r += u * sigma * 12f32.sqrt();
        if state.is_multiple_of(200) {
            *r = f32::NAN;
        } else if state % 997 == 1 {
            *r *= 0.5;
        }
    }
}

fn lidar_image(scene: &Scene) {
    let lidar = SensorModel::lidar128().render(0, &Isometry::identity(), scene);
    println!(
        "one 128×2048 lidar image ({} pixels), one core, median:",
        lidar.range.len()
    );
    for evaluator in ["cells", "height_diff", "pca"] {
        let config = PerceptionConfig {
            evaluator: evaluator.into(),
            ..Default::default()
        };
        let mut e = config.build_evaluator().unwrap_or_else(|e| panic!("{e}"));
        let mut report = ObstacleReport::default();
        let ms = time_ms(|| {
            let _ = std::hint::black_box(e.evaluate(&lidar, &Isometry::identity(), &mut report));
        });
        println!(
            "  {evaluator:<12} {ms:7.2} ms  ({} cells reported, graded included)",
            report.cells.len()
        );
    }
}

fn depth_ring(scene: &Scene, noise: Option<f32>) {
    // Paper 000's ring: eight cameras, 45° apart, on the roof.
    let ring: Vec<RangeImage> = (0..8)
        .map(|k| {
            let mut camera = SensorModel::depth_camera();
            camera.id = format!("camera{k}");
            camera.vehicle_from_sensor = isometry_from_xyz_rpy(
                [0.0, 0.0, 2.2],
                0.0,
                25f64.to_radians(),
                (45.0 * k as f64).to_radians(),
            );
            let mut image = camera.render(0, &Isometry::identity(), scene);
            image.sensor = camera.id;
            if let Some(sigma) = noise {
                noisy(&mut image, sigma, k);
            }
            image
        })
        .collect();
    let pixels: usize = ring.iter().map(|i| i.range.len()).sum();
    let noise = match noise {
        Some(sigma) => format!(
            "{:.0} cm range noise, 0.5 % dropped, 0.1 % spikes",
            sigma * 100.0
        ),
        None => "no noise".into(),
    };
    println!(
        "\neight 240×320 depth images ({pixels} pixels, {noise}), height_diff, one core, median:"
    );
    let config = PerceptionConfig::default();
    let mut hd = HeightDiff::new(config.height_diff.clone(), &config);
    let images: Vec<&RangeImage> = ring.iter().collect();
    let maps_ms = time_ms(|| {
        let mut stats = ImageStats::default();
        let _ = std::hint::black_box(hd.build_maps(&images, &Isometry::identity(), &mut stats));
    });
    println!(
        "  one height map of all eight (build_maps):   {maps_ms:7.2} ms (target <= 5 ms; 000: ~50 ms)"
    );
    // Of which the median outlier filter (§4.1), the part that grows
    // with the pixels' window.
    let mut median = arcnav_perception::median::MedianOutliers::default();
    let mut filtered = Vec::new();
    let median_ms = time_ms(|| {
        for image in &ring {
            let params = hd.median_params(image);
            std::hint::black_box(median.filter(&image.range, image.cols(), &params, &mut filtered));
        }
    });
    let params = hd.median_params(&ring[0]);
    println!(
        "    of which the median outlier filter ({}×{} window): {median_ms:7.2} ms",
        2 * params.half_rows + 1,
        2 * params.half_cols + 1
    );
    let mut report = ObstacleReport::default();
    let each_ms = time_ms(|| {
        for image in &ring {
            let _ = std::hint::black_box(arcnav_perception::TerrainEvaluator::evaluate(
                &mut hd,
                image,
                &Isometry::identity(),
                &mut report,
            ));
        }
    });
    println!("  each image on its own, with footprint, shadows, drop-offs: {each_ms:7.2} ms");
}
