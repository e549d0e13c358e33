//! The guard's latency (issue 65): from a lidar64 frame (64 × 1024, 10 Hz)
//! arriving to the verdict on the command, on one core: the ground-profile
//! pass over its returns, the hazard cells updated, and the check of a
//! command against them along the driven path. Target: ≤ 2 ms per frame.
//! The scene is rough ground with boxes, posts and a ditch around the
//! vehicle, so that the frame holds hazards as a forest's or a boulder
//! field's does; the guard has held 5 s of such frames (its memory) when
//! the timing starts. Also the ERIM's 64 × 256 at 2 Hz.
//! Run with `cargo bench -p arcnav-guard`.

use arcnav_guard::{Guard, GuardConfig};
use arcnav_perception::scene::{HeightFunction, rough_ground};
use arcnav_perception::{RangeImage, SensorModel};
use arcnav_vehicle::command::SteeringCommand;
use arcnav_vehicle::frames::{Isometry, Pose};
use arcnav_vehicle::model::VehicleConfig;
use divan::{Bencher, black_box};
use nalgebra::Vector3;

/// `cargo test --benches` runs this without `--bench`: once, quickly.
fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

fn main() {
    divan::main();
}

/// Rough ground, a ring of boxes and posts, and a ditch across ahead.
fn scene(x: f64, y: f64) -> f64 {
    let ground = rough_ground(x, y);
    let (cx, cy) = ((x / 6.0).round() * 6.0, (y / 6.0).round() * 6.0);
    let in_box = (x - cx).abs() < 0.6 && (y - cy).abs() < 0.6 && (cx, cy) != (0.0, 0.0);
    if (14.0..16.0).contains(&x) && y.abs() > 3.0 {
        ground - 1.5
    } else if in_box {
        ground + 0.8
    } else {
        ground
    }
}

fn image(sensor: &SensorModel) -> RangeImage {
    let step = if quick() { 0.5 } else { 0.05 };
    sensor.render(
        0,
        &Isometry::identity(),
        &HeightFunction::with_step(scene, step),
    )
}

fn bench_sensor(bencher: Bencher, sensor: SensorModel) {
    let frame = image(&sensor);
    let period = sensor.period_us();
    let mut guard = Guard::new(
        &GuardConfig::default(),
        &VehicleConfig::default(),
        std::slice::from_ref(&sensor),
    );
    let command = SteeringCommand {
        utime: 0,
        curvature: 0.02,
        speed_mps: 2.0,
        arc_index: Some(20),
        vote: 1.0,
        turn_rate_radps: 0.0,
    };
    let mut t = 0;
    let mut step = move |guard: &mut Guard| {
        t += period;
        let pose = Pose {
            velocity: Vector3::new(2.0, 0.0, 0.0),
            ..Pose::at_rest(t, Isometry::identity())
        };
        guard.observe_pose(&pose);
        guard.observe_image(&RangeImage {
            utime: t,
            ..frame.clone()
        });
        guard.check(
            &SteeringCommand {
                utime: t,
                ..command
            },
            t,
        );
        t
    };
    // Its memory full.
    let frames = (GuardConfig::default().memory_s * 1e6 / period as f64).ceil() as usize;
    for _ in 0..frames {
        step(&mut guard);
    }
    let counts = guard.counts();
    println!(
        "{}: {} returns, {} standing and {} holes a frame; {} cells held",
        sensor.id,
        counts.returns / counts.images,
        counts.standing / counts.images,
        counts.holes / counts.images,
        guard.hazards().count()
    );
    bencher.bench_local(|| black_box(step(&mut guard)));
}

#[divan::bench]
fn lidar64_frame(bencher: Bencher) {
    bench_sensor(bencher, SensorModel::lidar64());
}

#[divan::bench]
fn erim_frame(bencher: Bencher) {
    bench_sensor(bencher, SensorModel::erim());
}
