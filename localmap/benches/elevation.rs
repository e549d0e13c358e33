//! The elevation layer's cost per image (018): one 128×2048 lidar image of
//! rough ground (`arcnav_perception::scene::rough_ground`) turned into height
//! measurements (projection, binning into world cells) and fused into the
//! layer (004 eqs. 3–4), one core. Prints the mean and the worst over the
//! 4 images taken along a 10 m drive, each measured and fused 24 times
//! (after a round of warming up), and the layer's memory. Target: ≤ 2 ms
//! per image. Run with `cargo bench -p arcnav-localmap --bench elevation`.
//! The images are rendered first, a thread each, by marching each beam in
//! 10 cm steps (as the perception benches render theirs), about 20 s of
//! CPU an image: 50 images marched in 5 cm steps had taken over 20 minutes
//! on a slow host.

use std::time::Instant;

use arcnav_localmap::{LocalMap, LocalMapConfig};
use arcnav_perception::scene::{HeightFunction, rough_ground};
use arcnav_perception::{HeightSampler, ObstacleReport, PerceptionConfig, SensorModel};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{Pose, VehicleConfig};

/// Images along the drive, 2.5 m apart.
const IMAGES: i64 = 4;

/// `cargo test --benches` runs this without `--bench`: once, quickly, to
/// check that it still runs; `cargo bench` passes `--bench` for the figures.
fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

fn main() {
    let sensor = SensorModel::lidar128();
    let perception = PerceptionConfig::default();
    let mut sampler = HeightSampler::new(
        &perception.heights,
        &perception.region,
        perception.min_range_m,
        perception.max_range_m,
    );
    let mut map = LocalMap::new(&LocalMapConfig::default(), &VehicleConfig::default());
    // Quick mode marches 0.5 m steps: it checks that the bench runs.
    let scene = HeightFunction::with_step(rough_ground, if quick() { 0.5 } else { 0.1 });
    let started = Instant::now();
    let images: Vec<_> = std::thread::scope(|scope| {
        let renders: Vec<_> = (0..if quick() { 1 } else { IMAGES })
            .map(|n| {
                let (sensor, scene) = (&sensor, &scene);
                scope.spawn(move || {
                    let pose =
                        Pose::at_rest(n * 250_000, planar_isometry(n as f64 * 2.5, 0.0, 0.1));
                    let image = sensor.render(pose.utime, &pose.world_from_vehicle, scene);
                    (pose, image)
                })
            })
            .collect();
        renders.into_iter().map(|r| r.join().unwrap()).collect()
    });
    println!(
        "rendered {} images in {:.1} s",
        images.len(),
        started.elapsed().as_secs_f64()
    );
    let mut report = ObstacleReport::default();
    let (mut sample_times, mut fuse_times) = (Vec::new(), Vec::new());
    for round in 0..if quick() { 2 } else { 25 } {
        for (pose, image) in &images {
            map.update(pose);
            report.clear();
            report.utime = pose.utime;
            report.sensor.push_str("lidar128");
            let start = Instant::now();
            sampler.sample(image, &pose.world_from_vehicle, &mut report);
            let sampled = Instant::now();
            map.insert(&report).expect("a valid report");
            let fused = Instant::now();
            if round > 0 {
                sample_times.push((sampled - start).as_secs_f64() * 1e3);
                fuse_times.push((fused - sampled).as_secs_f64() * 1e3);
            }
        }
        // The next round fuses the same images into an empty map.
        map = LocalMap::new(&LocalMapConfig::default(), &VehicleConfig::default());
    }
    let total: Vec<f64> = sample_times
        .iter()
        .zip(&fuse_times)
        .map(|(a, b)| a + b)
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let worst = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    println!(
        "elevation layer, 128x2048 lidar image ({} measurements): measure {:.2} ms + fuse {:.2} ms = {:.2} ms mean, {:.2} ms worst (target <= 2 ms)",
        report.heights.len(),
        mean(&sample_times),
        mean(&fuse_times),
        mean(&total),
        worst(&total)
    );
    let layer = map.elevation();
    println!(
        "layer: {} x {} cells of {} m, {:.1} MB",
        layer.side(),
        layer.side(),
        layer.config().cell_size_m,
        layer.memory_bytes() as f64 / 1e6
    );
}
