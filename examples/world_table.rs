//! Runs the mission on procedurally generated worlds and prints a table.
//!
//! ```sh
//! cargo run --release --example world_table               # 20 moderate worlds, seeds 1-20
//! cargo run --release --example world_table -- 40 hard    # 40 hard worlds
//! ```
//!
//! The acceptance target: at least 19 of the 20 moderate worlds completed
//! with zero collisions.

use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav_behaviours::Registry;
use arcnav_sim::{Difficulty, World, generate};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let count: u64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(20);
    let difficulty: Difficulty = args
        .next()
        .map(|a| a.parse().map_err(anyhow::Error::msg))
        .transpose()?
        .unwrap_or(Difficulty::Moderate);
    let config = Config::default();
    let registry = Registry::builtin();
    println!(
        "{count} {difficulty:?} worlds, {} sensor, {:.1} m/s cruise",
        config.sensor.preset_name(),
        config.arbiter.cruise_speed_mps
    );
    println!(
        "seed  outcome     waypoints  distance  time    avg m/s  collisions  closest  features  wall"
    );
    let mut successes = 0;
    for seed in 1..=count {
        let world = Arc::new(World::build(generate(seed, difficulty), "generated", None)?);
        let features = world.features.len();
        let run = run_mission(
            &config,
            &registry,
            world,
            &MissionOptions::default(),
            &mut |_| {},
        )?;
        let r = &run.report;
        successes += usize::from(r.success);
        println!(
            "{seed:>4}  {:<10}  {:>4}/{:<4}  {:>6.0} m  {:>4.0} s  {:>7.2}  {:>10}  {:>5.2} m  {features:>8}  {:>4.1} s{}",
            format!("{:?}", r.outcome).to_lowercase(),
            r.waypoints_reached,
            r.waypoints,
            r.distance_m,
            r.duration_s,
            r.average_speed_mps,
            r.collisions.len(),
            r.closest_approach_m.unwrap_or(f64::NAN),
            r.wall_time_s,
            r.collisions
                .first()
                .map(|c| format!("  ({})", c.cause))
                .unwrap_or_default()
        );
    }
    println!("{successes}/{count} completed with zero collisions");
    Ok(())
}
