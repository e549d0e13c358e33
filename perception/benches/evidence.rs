//! Time per image of the hole evidence layer (`[perception.evidence]`,
//! issue 63's target: a 64-beam lidar frame into it in ≤ 1 ms on one
//! core), printed with its memory: the 64-beam lidar 2.4 m up driving at
//! 8 m/s over rough ground towards a 0.8 m ditch across the way, one frame
//! every 0.8 m, and the range at which the layer first suspected the
//! ditch.
//!
//! Run with `cargo bench -p arcnav-perception --bench evidence`.

use std::time::Instant;

use arcnav_perception::scene::{HeightFunction, rough_ground};
use arcnav_perception::{HoleEvidence, ObstacleReport, PerceptionConfig, SensorModel};
use arcnav_vehicle::frames::isometry_from_xyz_rpy;

/// `cargo test --benches` runs this without `--bench`: once, quickly, to
/// check that it still runs; `cargo bench` passes `--bench` for the figures.
fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

/// The ditch: 0.8 m wide, 1 m deep, its near edge this far out.
const DITCH_AT_M: f64 = 60.0;

fn main() {
    let step = if quick() { 0.5 } else { 0.05 };
    let scene = HeightFunction::with_step(
        |x: f64, y: f64| {
            if (DITCH_AT_M..DITCH_AT_M + 0.8).contains(&x) {
                -1.0
            } else {
                rough_ground(x, y)
            }
        },
        step,
    );
    let lidar = SensorModel::lidar64();
    let config = PerceptionConfig::default();
    let frames = if quick() { 2 } else { 60 };
    let sensor_x = lidar.vehicle_from_sensor.translation.vector.x;
    // 8 m/s at 10 Hz, the last frame 8 m short of the ditch.
    let frames: Vec<_> = (0..frames)
        .map(|k| {
            let x = DITCH_AT_M - 8.0 - sensor_x - 0.8 * (frames - 1 - k) as f64;
            let pose = isometry_from_xyz_rpy([x, 0.3, rough_ground(x, 0.3)], 0.0, 0.0, 0.0);
            (x, pose, lidar.render(k as i64 * 100_000, &pose, &scene))
        })
        .collect();
    // The drive again and again (one figure per frame: the fastest of the
    // repeats), so that a busy machine's pauses do not count.
    let repeats = if quick() { 1 } else { 10 };
    let mut times = vec![f64::INFINITY; frames.len()];
    let mut first = None;
    for _ in 0..repeats {
        let mut evidence = HoleEvidence::new(&config);
        for ((x, pose, image), time) in frames.iter().zip(&mut times) {
            let mut report = ObstacleReport::default();
            let t = Instant::now();
            let found = evidence.observe(image, pose, &mut report);
            *time = time.min(t.elapsed().as_secs_f64() * 1e3);
            let at_ditch = report
                .cells
                .iter()
                .any(|c| (c.x - DITCH_AT_M).abs() < 0.4 && c.y.abs() < 5.0);
            if first.is_none() && at_ditch {
                first = Some(DITCH_AT_M - x - sensor_x);
            }
            std::hint::black_box(found);
        }
    }
    let memory = HoleEvidence::new(&config).memory_bytes();
    // The first frames fill an empty layer; the rest are the steady state.
    let mut steady = times[times.len() / 3..].to_vec();
    steady.sort_by(f64::total_cmp);
    println!(
        "hole evidence, one 64×2048 lidar64 frame a step, one core, {} frames:",
        frames.len()
    );
    println!(
        "  median {:.3} ms, slowest {:.3} ms (target <= 1 ms); ring {:.1} MiB",
        steady[steady.len() / 2],
        steady[steady.len() - 1],
        memory as f64 / f64::from(1 << 20)
    );
    match first {
        Some(range) => println!("  the 0.8 m ditch first suspected {range:.1} m from the sensor"),
        None => println!("  the 0.8 m ditch was not suspected (down to 8 m from it)"),
    }
}
