//! What a command that reads a log also reads: the configuration the log
//! was made with, and every file that configuration names.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use arcnav::{Config, Resolved};
use arcnav_behaviours::Registry;
use arcnav_perception::SensorPreset;

/// The configuration to redo a run's decisions with: `--config` if given,
/// else the `config.toml` `arcnav sim` wrote beside the log (said so on
/// stderr), else the defaults; with `sensor` (`--sensor`) as its sensor
/// preset. A run made with another evaluator or other sensors is redone
/// as it was driven.
pub fn config_of_log(
    log: &Path,
    given: Option<&Path>,
    registry: &Registry,
    sensor: Option<SensorPreset>,
) -> anyhow::Result<Resolved> {
    let beside = log.parent().unwrap_or(Path::new(".")).join("config.toml");
    let (mut config, origin) = match given {
        Some(path) => (Config::load(path)?, path.display().to_string()),
        None if beside.is_file() => {
            let config = Config::load(&beside)
                .with_context(|| format!("the run's configuration {}", beside.display()))?;
            eprintln!(
                "using {}, the configuration the run was made with (--config to give another)",
                beside.display()
            );
            (config, beside.display().to_string())
        }
        None => (Config::default(), "the defaults".to_owned()),
    };
    if let Some(preset) = sensor {
        super::settings::set_sensor_preset(&mut config, preset)?;
    }
    config
        .resolve(registry)
        .with_context(|| format!("the configuration {origin}"))
}

/// The files a command reading `log` with `configs` reads, each named by
/// what it is: no output of the command may be one of them.
pub fn files_read<'a>(
    log: &Path,
    configs: impl IntoIterator<Item = &'a Resolved>,
) -> Vec<(&'static str, PathBuf)> {
    let mut files = vec![("the log", log.to_owned())];
    for config in configs {
        files.extend(config.files_read());
    }
    files
}
