//! Replay speed on one core, in × real time (log span / wall time):
//! a 2 Hz ERIM log of the paper's loop (target ≥ 500×) and a 10 Hz
//! 128×2048 lidar log (target ≥ 20×). The logs are made once by the
//! simulator into target/bench-data. Run with `cargo bench --bench replay`.

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
        "{label:<28} {span:>6.1} s of log ({size:>5.0} MB, {decisions} decisions) in {best:.2} s: {:>6.0}× real time (target ≥ {target}×)",
        span / best
    );
}

fn main() {
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
    measure("ERIM 64×256, 2 Hz", &erim_log, &erim, 500.0);
    measure("lidar 128×2048, 10 Hz", &lidar_log, &lidar, 20.0);
}
