//! The trait that lets the [`crate::EvaluatorRegistry`] build a terrain
//! evaluator by name from its configuration table.

use arcnav_vehicle::{ConfigError, VehicleConfig};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::config::PerceptionConfig;
use crate::evaluator::TerrainEvaluator;

/// A terrain evaluator the registry can build from configuration.
pub trait EvaluatorPlugin: TerrainEvaluator + Sized + 'static {
    /// Its name in `perception.evaluator`.
    const NAME: &'static str;
    /// One line for `--help` and error messages: what it does, whose it is.
    const ABOUT: &'static str;
    /// Its configuration, with the documented defaults in `Default`.
    type Config: Serialize + DeserializeOwned + Default + Clone;
    /// Whether it judges images of several sensors together, in one
    /// height map, when `perception.fuse_within_s` asks it to (it then
    /// overrides [`TerrainEvaluator::evaluate_fused`]).
    const FUSES_IMAGES: bool = false;

    /// Its table, typed: `[perception.plugins.NAME]` (the built-ins read
    /// their own `[perception.NAME]`). Errors name keys relative to
    /// `[perception]`.
    fn config(perception: &PerceptionConfig) -> Result<Self::Config, ConfigError> {
        let key = format!("plugins.{}", Self::NAME);
        match perception.plugins.get(Self::NAME) {
            None => Ok(Self::Config::default()),
            Some(table) => toml::Value::Table(table.clone())
                .try_into()
                .map_err(|e: toml::de::Error| ConfigError::new(key, e.message().to_owned())),
        }
    }

    /// Checks the configuration against the vehicle (keys relative to
    /// `[perception]`).
    fn validate(
        _config: &Self::Config,
        _perception: &PerceptionConfig,
        _vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        Ok(())
    }

    /// Builds the evaluator from its (validated) configuration.
    fn build(config: Self::Config, perception: &PerceptionConfig) -> Self;
}
