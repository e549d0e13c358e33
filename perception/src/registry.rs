//! Terrain evaluators by name, as behaviours are (`perception.evaluator`).
//!
//! ```toml
//! [perception]
//! evaluator = "height_diff"     # cells | height_diff | pca, or a plug-in's name
//!
//! [perception.height_diff]      # the built-ins' tables: every key has a default
//! cell_size_m = 0.1
//!
//! [perception.plugins.my_eval]  # a plug-in's table, parsed into its own Config
//! threshold_m = 0.3
//! ```
//!
//! Every evaluator fills the same [`crate::ObstacleReport`] (untraversable
//! cells with their reasons, the observed footprint and its shadows), so
//! the local map, the behaviours and the arbiter work with any of them
//! unchanged. Adding one: implement [`TerrainEvaluator`] and
//! [`EvaluatorPlugin`], then `registry.add::<MyEvaluator>()`.

use std::collections::BTreeMap;

use arcnav_vehicle::{ConfigError, VehicleConfig};

use crate::config::PerceptionConfig;
use crate::evaluator::TerrainEvaluator;
use crate::plugin::EvaluatorPlugin;

type Validator =
    Box<dyn Fn(&PerceptionConfig, &VehicleConfig) -> Result<(), ConfigError> + Send + Sync>;
type Builder =
    Box<dyn Fn(&PerceptionConfig) -> Result<Box<dyn TerrainEvaluator>, ConfigError> + Send + Sync>;

struct Entry {
    about: &'static str,
    fuses_images: bool,
    validate: Validator,
    build: Builder,
}

/// Terrain evaluators by name.
#[derive(Default)]
pub struct EvaluatorRegistry {
    entries: BTreeMap<&'static str, Entry>,
}

impl std::fmt::Debug for EvaluatorRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EvaluatorRegistry")
            .field("evaluators", &self.names())
            .finish()
    }
}

impl EvaluatorRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// The evaluators arcnav ships: 002's cell classifier, 000's multi-scale
    /// height differences and 001's hierarchical PCA.
    pub fn builtin() -> Self {
        let mut registry = Self::new();
        registry
            .add::<crate::CellClassifier>()
            .add::<crate::HeightDiff>()
            .add::<crate::HierarchicalPca>();
        registry
    }

    /// Registers `P` under `P::NAME` (replacing an evaluator of that name).
    pub fn add<P: EvaluatorPlugin>(&mut self) -> &mut Self {
        self.entries.insert(
            P::NAME,
            Entry {
                about: P::ABOUT,
                fuses_images: P::FUSES_IMAGES,
                validate: Box::new(|perception, vehicle| {
                    let config = P::config(perception)?;
                    P::validate(&config, perception, vehicle)
                }),
                build: Box::new(|perception| {
                    let config = P::config(perception)?;
                    Ok(Box::new(P::build(config, perception)) as Box<dyn TerrainEvaluator>)
                }),
            },
        );
        self
    }

    /// Registered names, sorted.
    pub fn names(&self) -> Vec<&'static str> {
        self.entries.keys().copied().collect()
    }

    /// What evaluator `name` does, if it is registered.
    pub fn about(&self, name: &str) -> Option<&'static str> {
        self.entries.get(name).map(|e| e.about)
    }

    fn entry(&self, name: &str) -> Result<&Entry, ConfigError> {
        self.entries.get(name).ok_or_else(|| {
            ConfigError::new(
                "evaluator",
                format!(
                    "{name:?} is not a known evaluator (known: {})",
                    self.names().join(", ")
                ),
            )
        })
    }

    /// Refuses a name that is not registered, listing the known ones.
    pub fn check_known(&self, name: &str) -> Result<(), ConfigError> {
        self.entry(name).map(|_| ())
    }

    /// Checks that `perception.evaluator` is registered, that every
    /// `[perception.plugins.NAME]` table belongs to a registered evaluator,
    /// and the selected evaluator's table. (The others' tables are only
    /// parsed: their checks against the vehicle apply when selected, so a
    /// changed vehicle need not retune evaluators it does not use.)
    pub fn validate(
        &self,
        perception: &PerceptionConfig,
        vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        self.entry(&perception.evaluator)?;
        if let Some(name) = perception
            .plugins
            .keys()
            .find(|name| !self.entries.contains_key(name.as_str()))
        {
            return Err(ConfigError::new(
                format!("plugins.{name}"),
                format!(
                    "is the table of no known evaluator (known: {})",
                    self.names().join(", ")
                ),
            ));
        }
        let entry = self.entry(&perception.evaluator)?;
        if perception.fuse_within_s > 0.0 && !entry.fuses_images {
            let fusing: Vec<_> = (self.entries.iter())
                .filter(|(_, e)| e.fuses_images)
                .map(|(name, _)| *name)
                .collect();
            return Err(ConfigError::new(
                "fuse_within_s",
                format!(
                    "is {} s, but evaluator {:?} judges each image alone (images are fused into \
                     one height map by: {}); set it to 0 or choose one of those",
                    perception.fuse_within_s,
                    perception.evaluator,
                    if fusing.is_empty() {
                        "none registered".to_owned()
                    } else {
                        fusing.join(", ")
                    }
                ),
            ));
        }
        (entry.validate)(perception, vehicle)
    }

    /// Builds the evaluator `perception.evaluator` names (validate first).
    pub fn build(
        &self,
        perception: &PerceptionConfig,
    ) -> Result<Box<dyn TerrainEvaluator>, ConfigError> {
        (self.entry(&perception.evaluator)?.build)(perception)
    }
}

/// Validating and building, on the configuration's value (defined here,
/// beside the registry they consult, so that the configuration's module
/// imports no evaluator).
impl PerceptionConfig {
    /// Checks the values and that no threshold lets pass terrain the vehicle
    /// cannot drive. Keys are relative to `[perception]`, except those of
    /// the vehicle named in messages.
    pub fn validate_for(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        self.validate_with(&EvaluatorRegistry::builtin(), vehicle)
    }

    /// [`PerceptionConfig::validate_for`], with the evaluators of `registry`
    /// (for programs that add their own).
    pub fn validate_with(
        &self,
        registry: &EvaluatorRegistry,
        vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        registry.check_known(&self.evaluator)?;
        self.validate_shared(vehicle)?;
        registry.validate(self, vehicle)
    }

    /// Builds the configured evaluator (call `validate_for` first).
    pub fn build_evaluator(&self) -> Result<Box<dyn TerrainEvaluator>, ConfigError> {
        EvaluatorRegistry::builtin().build(self)
    }
}
