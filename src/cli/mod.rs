//! The commands of the `arcnav` tool, one file each; `main.rs` holds the
//! command line they are called from.

mod detect;
mod live;
mod logged;
mod render;
mod replay;
mod sim;
mod sweep;
mod terminal;

pub use detect::detect;
pub use live::{live, vehicle};
pub use render::{export, render};
pub use replay::replay;
pub use sim::sim;
pub use sweep::sweep;

/// `--sensor`: the configuration's sensor preset, said to come from the
/// command line; refused when the configuration lists `[[sensors]]`.
fn set_sensor_preset(
    config: &mut arcnav::Config,
    preset: arcnav_perception::SensorPreset,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        config.sensors.is_empty(),
        "--sensor: the configuration lists its sensors in [[sensors]]; change them there"
    );
    config.sensor.preset = preset;
    config.set_by("sensor.preset", "--sensor");
    Ok(())
}
