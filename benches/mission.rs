//! Lidar missions × real time (020 item 4: ≥ 20× on this two-core machine;
//! 21.3-21.6× rendered ahead on an AMD host on 2026-11-29 with the cast
//! compiled for AVX2, 18.2-20.0× the hour before; lidar128 16.5×):
//! `arcnav sim --world paper_loop --sensor lidar64 --no-images`
//! in process, each image rendered beside the pipeline (`sim.render_ahead`,
//! the default) and each rendered when due, with where a frame's wall time
//! goes. The two missions are the same byte for byte; only the time differs.
//! A third runs without the guard (`[guard] enabled = false`): what the
//! guard costs the mission's wall time (issue 65's target: under 5 %).
//! `cargo bench --bench mission [-- lidar128]` (about a minute a mission);
//! `… -- dem_loop` drives tests/worlds/dem_loop.toml instead (2 km over a
//! 10 m DEM with slopes to 20° and scattered obstacles, at `--speed 10`:
//! issue 69's real terrain, about three minutes a mission). In quick mode
//! both worlds run for 4 simulated seconds.

use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{LogMode, MissionOptions, run_mission};
use arcnav_perception::SensorPreset;
use arcnav_sim::World;

#[path = "common/mod.rs"]
#[allow(dead_code)]
mod common;

fn main() {
    arcnav::keep_freed_memory();
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let mut preset = SensorPreset::Lidar64;
    let mut dem = false;
    for arg in &args {
        match arg.as_str() {
            "lidar64" => preset = SensorPreset::Lidar64,
            "lidar128" => preset = SensorPreset::Lidar128,
            "dem_loop" => dem = true,
            "paper_loop" => dem = false,
            other => {
                eprintln!(
                    "unknown argument {other:?}: lidar64 (the default) or lidar128, paper_loop (the default) or dem_loop"
                );
                std::process::exit(2);
            }
        }
    }
    if common::quick() {
        drive(preset, false);
        drive(preset, true);
    } else {
        drive(preset, dem);
    }
}

/// The mission of paper_loop at the defaults, or of dem_loop at 10 m/s,
/// rendered ahead and when due, and without the guard.
fn drive(preset: SensorPreset, dem: bool) {
    let world = Arc::new(if dem {
        World::load(&arcnav_testkit::workspace_root().join("tests/worlds/dem_loop.toml"))
            .expect("tests/worlds/dem_loop.toml builds")
    } else {
        World::embedded("paper_loop")
            .expect("embedded")
            .expect("valid")
    });
    let speed = if dem {
        10.0
    } else {
        Config::default().arbiter.cruise_speed_mps
    };
    println!(
        "{}, {preset:?}, default configuration at {speed} m/s, no log, two cores:",
        world.spec.name
    );
    let mut wall = Vec::new();
    for (ahead, guard) in [(true, true), (false, true), (true, false)] {
        let mut config = Config::default();
        config.sensor.preset = preset;
        config.sim.render_ahead = ahead;
        config.guard.enabled = guard;
        config.arbiter.cruise_speed_mps = speed;
        if common::quick() {
            config.sim.time_limit_s = 4.0;
        }
        let options = MissionOptions {
            log_mode: LogMode::NoImages,
            ..MissionOptions::default()
        };
        let run = run_mission(
            &config.resolved().unwrap(),
            Arc::clone(&world),
            &options,
            &mut |_| {},
        )
        .expect("the mission runs");
        let r = &run.report;
        let frame_ms = 1e3 * r.wall_time_s / r.images.max(1) as f64;
        let t = &r.stage_times;
        println!(
            "  rendered {:<8} {:>5.0} s simulated in {:>5.1} s: {:>5.1}× real time (target ≥ 20×), \
             {frame_ms:.1} ms a frame: rendering {:.1} ms ({} of {} images ahead), \
             perception {:.2}, behaviours {:.2}, local map {:.2} (wall clock, ms an image), {:?}",
            match (ahead, guard) {
                (true, true) => "ahead",
                (false, _) => "when due",
                (true, false) => "ahead, no guard",
            },
            r.duration_s,
            r.wall_time_s,
            r.realtime_factor,
            r.render_ms_mean,
            r.images_rendered_ahead,
            r.images,
            t.perception.mean_ms(),
            t.behaviours.total_ms / r.images.max(1) as f64,
            t.localmap.total_ms / r.images.max(1) as f64,
            r.outcome,
        );
        if let Some(g) = &r.guard {
            println!(
                "  guard: {:.2} ms an image, on the pipeline's thread ({:.1} s in all)",
                g.observe_ms, g.time_s
            );
        }
        wall.push(r.wall_time_s);
    }
    println!(
        "  the guard costs the mission {:+.1} % of its wall time (rendered ahead; target < 5 %)",
        100.0 * (wall[0] / wall[2] - 1.0)
    );
}
