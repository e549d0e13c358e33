//! Settings the command line gives that more than one command shares.

/// `--sensor`: the configuration's sensor preset, said to come from the
/// command line; refused when the configuration lists `[[sensors]]`.
pub fn set_sensor_preset(
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
