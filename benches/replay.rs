//! Replay speed on one core, in × real time (log span / wall time), of
//! logs the simulator makes once into target/bench-data:
//!
//! - a 2 Hz ERIM log of the paper's loop at the defaults (issue 69: ≥ 200×;
//!   596× when replay was first built, before the terrain check, the
//!   driven paths and the route's memory);
//! - 30 s of a 10 Hz 64×2048 lidar log of `tests/worlds/dem_loop.toml` at
//!   `--speed 10` (2 km over a 10 m DEM with slopes to 20°: issue 69,
//!   ≥ 25×);
//! - 20 s of a 10 Hz 128×2048 lidar log of `short_course` (≥ 20×).
//!
//! Run with `cargo bench --bench replay`.

mod common;

use std::path::Path;
use std::time::Instant;

use arcnav::Config;
use arcnav::replay::{ReplayOptions, replay};
use arcnav_perception::SensorPreset;

fn measure(label: &str, log: &Path, config: &Config, target: f64) {
    let mut best = f64::INFINITY;
    let mut span = 0.0;
    let mut decisions = 0;
    for _ in 0..if common::quick() { 1 } else { 3 } {
        let started = Instant::now();
        let result = replay(
            log,
            &config.resolved().unwrap(),
            &ReplayOptions::default(),
            &mut |_| {},
        )
        .expect("replays");
        best = best.min(started.elapsed().as_secs_f64());
        span = result.span.map_or(0.0, |(a, b)| (b - a) as f64 * 1e-6);
        decisions = result.cycles.len();
    }
    let size = std::fs::metadata(log).map_or(0, |m| m.len()) as f64 / 1e6;
    println!(
        "{label:<30} {span:>6.1} s of log ({size:>5.0} MB, {decisions} decisions) in {best:.2} s: {:>6.0}× real time (target ≥ {target}×)",
        span / best
    );
}

fn main() {
    arcnav::keep_freed_memory();
    let data = common::data_dir();
    let quick = common::quick();
    let mut erim = Config::default();
    let erim_log = if quick {
        erim.sim.time_limit_s = 20.0;
        data.join("paper_loop-erim-20s.lcm")
    } else {
        data.join("paper_loop-erim.lcm")
    };
    common::make_log(&erim_log, "paper_loop", &erim);
    let mut lidar = Config::default();
    lidar.sensor.preset = SensorPreset::Lidar128;
    lidar.sim.time_limit_s = if quick { 2.0 } else { 20.0 };
    let lidar_log = data.join(format!(
        "short_course-lidar128-{}s.lcm",
        lidar.sim.time_limit_s
    ));
    common::make_log(&lidar_log, "short_course", &lidar);
    let mut dem = Config::default();
    dem.sensor.preset = SensorPreset::Lidar64;
    dem.arbiter.cruise_speed_mps = 10.0;
    dem.sim.time_limit_s = if quick { 2.0 } else { 30.0 };
    let dem_log = data.join(format!(
        "dem_loop-lidar64-speed10-{}s.lcm",
        dem.sim.time_limit_s
    ));
    common::make_log(&dem_log, "tests/worlds/dem_loop.toml", &dem);
    measure("ERIM 64×256, 2 Hz", &erim_log, &erim, 200.0);
    measure("lidar 64×2048 dem_loop, 10 Hz", &dem_log, &dem, 25.0);
    measure("lidar 128×2048, 10 Hz", &lidar_log, &lidar, 20.0);
}
