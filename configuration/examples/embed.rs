//! arcnav inside your own program: poses and range images from your own
//! code go into the pipeline, steering commands come back. No LCM, no
//! threads, no simulator: the pipeline is a library
//! ([`arcnav_pipeline::Pipeline`]), and you call it.
//!
//! Here "your code" is a vehicle driving on a flat field to a goal 30 m
//! ahead, past a 1 m box 15 m ahead just left of its line: the poses come from integrating the commands,
//! the range images from an analytic scene. Replace both with your vehicle's
//! pose estimate and your sensor driver.
//!
//! It depends on arcnav's library crates only (`arcnav-config` and the
//! crates of the pipeline), not on the `arcnav` program:
//!
//! ```sh
//! cargo run --release -p arcnav-config --example embed               # the default configuration
//! cargo run --release -p arcnav-config --example embed -- my.toml    # yours
//! ```

use anyhow::Context as _;
use arcnav_behaviours::{Mission, Registry, Waypoint};
use arcnav_config::Resolved;
use arcnav_perception::scene::HeightFunction;
use arcnav_pipeline::{Commands, Input};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{Pose, SteeringCommand};
use nalgebra::Vector3;

fn main() -> anyhow::Result<()> {
    // 1. The configuration: a file of yours, or the defaults.
    //    Loading parses it, checks it and derives what follows from it, once.
    let path = std::env::args().nth(1);
    let config = Resolved::load_or_default(
        path.as_deref().map(std::path::Path::new),
        &Registry::builtin(),
    )?;
    let arrival = drive(&config)?;
    println!(
        "reached the goal after {:.1} s at ({:.1}, {:.1}); came no closer than {:.1} m to the box's centre",
        arrival.time_s, arrival.x, arrival.y, arrival.closest_to_box_m
    );
    Ok(())
}

/// Where and when the vehicle reached the goal.
pub struct Arrival {
    pub time_s: f64,
    pub x: f64,
    pub y: f64,
    pub closest_to_box_m: f64,
}

/// Drives to the goal with the pipeline `config` describes.
pub fn drive(config: &Resolved) -> anyhow::Result<Arrival> {
    let mut pipeline = config.lockstep()?;
    let sensor = config
        .sensors
        .first()
        .context("the configuration has no sensor")?
        .clone();

    // 2. Your world: flat ground, a 1 m box, the goal at 30 m.
    let field = HeightFunction::new(|x: f64, y: f64| {
        if (15.0..16.0).contains(&x) && (0.5..2.5).contains(&y) {
            1.0
        } else {
            0.0
        }
    });
    let goal = Waypoint {
        x: 30.0,
        y: 0.0,
        radius_m: Some(2.0),
    };
    let mut commands = Commands::default();
    pipeline.input(
        Input::Waypoints(Mission {
            version: 0,
            waypoints: vec![goal],
        }),
        &mut commands,
    );

    // 3. Your loop: a pose every 20 ms, an image every half second; the
    //    command in force steers your vehicle.
    let (mut x, mut y, mut yaw) = (0.0f64, 0.0f64, 0.0f64);
    let mut command = SteeringCommand::stop(0);
    let mut closest_to_box = f64::INFINITY;
    for step in 0..3_000i64 {
        let utime = step * 20_000;
        let pose = Pose {
            utime,
            world_from_vehicle: planar_isometry(x, y, yaw),
            velocity: Vector3::new(
                command.speed_mps * yaw.cos(),
                command.speed_mps * yaw.sin(),
                0.0,
            ),
            yaw_rate: command.speed_mps * command.curvature,
        };
        pipeline.input(Input::Pose(pose), &mut commands);
        if step % 25 == 0 {
            let image = sensor.render(utime, &pose.world_from_vehicle, &field);
            pipeline.input(Input::Image(image), &mut commands);
        }
        pipeline.run_until(utime, &mut commands);
        if let Some(newest) = commands.0.pop() {
            command = newest;
        }
        commands.0.clear();
        // Your vehicle follows the command for 20 ms.
        let ds = command.speed_mps * 0.02;
        yaw += ds * command.curvature;
        x += ds * yaw.cos();
        y += ds * yaw.sin();
        closest_to_box = closest_to_box.min((x - 15.5).hypot(y - 1.5));
        if pipeline.behaviours.progress().is_some_and(|p| p.complete) {
            return Ok(Arrival {
                time_s: utime as f64 * 1e-6,
                x,
                y,
                closest_to_box_m: closest_to_box,
            });
        }
    }
    anyhow::bail!("the goal was not reached in 60 s: the vehicle is at ({x:.1}, {y:.1})")
}
