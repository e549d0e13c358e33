//! Building behaviours by name from their TOML tables.
//!
//! ```toml
//! [behaviours.goal_seeking]
//! lookahead_m = 12.0          # other keys keep their defaults
//! ```
//!
//! Each behaviour's table is deserialised into its own config type (unknown
//! keys and wrong types are refused, naming the key), validated, and passed
//! to its constructor. Adding a behaviour: implement [`Plugin`] and call
//! `registry.add::<MyBehaviour>()`.

use std::collections::BTreeMap;

use arcnav_vehicle::ConfigError;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::behaviour::{Behaviour, Setup};

/// A behaviour the registry can build from configuration.
pub trait Plugin: Behaviour + Sized + 'static {
    /// Its name in the configuration (`[behaviours.NAME]`).
    const NAME: &'static str;
    /// Its configuration, with the documented defaults in `Default`.
    type Config: Serialize + DeserializeOwned + Default + Clone + Send + Sync + 'static;

    /// Checks the configuration (keys relative to its table).
    fn validate(_config: &Self::Config, _setup: &Setup<'_>) -> Result<(), ConfigError> {
        Ok(())
    }

    /// Builds the behaviour from its (validated) configuration.
    fn build(config: Self::Config, setup: &Setup<'_>) -> Self;
}

/// A behaviour that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegistryError {
    #[error("unknown behaviour {name:?} (known: {})", known.join(", "))]
    Unknown { name: String, known: Vec<String> },
    #[error(transparent)]
    Config(#[from] ConfigError),
}

type Preparer =
    Box<dyn Fn(&toml::Table, &Setup<'_>) -> Result<Prepared, ConfigError> + Send + Sync>;

struct Entry {
    prepare: Preparer,
    defaults: toml::Table,
}

/// A behaviour's table, parsed into its typed configuration and validated
/// (once): what building the behaviour needs, and the table with every
/// default filled in.
#[derive(Clone)]
pub struct Prepared {
    table: toml::Table,
    build: Constructor,
}

/// Builds a behaviour from a configuration checked once.
type Constructor = std::sync::Arc<dyn Fn(&Setup<'_>) -> Box<dyn Behaviour> + Send + Sync>;

impl Prepared {
    /// The table with every default filled in.
    pub fn table(&self) -> &toml::Table {
        &self.table
    }

    /// Builds the behaviour (its configuration was checked when prepared).
    pub fn build(&self, setup: &Setup<'_>) -> Box<dyn Behaviour> {
        (self.build)(setup)
    }
}

impl std::fmt::Debug for Prepared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prepared")
            .field("table", &self.table)
            .finish_non_exhaustive()
    }
}

/// Behaviours by name.
#[derive(Default)]
pub struct Registry {
    entries: BTreeMap<&'static str, Entry>,
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registry")
            .field("behaviours", &self.names())
            .finish()
    }
}

/// Deserialises a behaviour's table; errors name the key where toml does.
fn parse<C: DeserializeOwned>(table: &toml::Table) -> Result<C, ConfigError> {
    toml::Value::Table(table.clone())
        .try_into::<C>()
        .map_err(|e| {
            let message = e.message().to_owned();
            let key = message
                .strip_prefix("unknown field `")
                .and_then(|rest| rest.split('`').next())
                .map(str::to_owned)
                .or_else(|| {
                    // "invalid type: ..., expected ... for key `x`" style messages.
                    message
                        .rsplit_once("key `")
                        .and_then(|(_, k)| k.split('`').next())
                        .map(str::to_owned)
                })
                .unwrap_or_default();
            ConfigError::new(key, message)
        })
}

fn table_of<C: Serialize>(config: &C) -> toml::Table {
    toml::Table::try_from(config).unwrap_or_default()
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// The behaviours arcnav ships: obstacle avoidance, goal seeking and
    /// the route planner.
    pub fn builtin() -> Self {
        let mut registry = Self::new();
        registry
            .add::<crate::ObstacleAvoidance>()
            .add::<crate::GoalSeeking>()
            .add::<crate::Route>();
        registry
    }

    /// Registers `P` under `P::NAME` (replacing a behaviour of that name).
    pub fn add<P: Plugin>(&mut self) -> &mut Self {
        let prepare: Preparer = Box::new(|table, setup| {
            let config: P::Config = parse(table)?;
            P::validate(&config, setup)?;
            Ok(Prepared {
                table: table_of(&config),
                build: std::sync::Arc::new(move |setup| {
                    Box::new(P::build(config.clone(), setup)) as Box<dyn Behaviour>
                }),
            })
        });
        self.entries.insert(
            P::NAME,
            Entry {
                prepare,
                defaults: table_of(&P::Config::default()),
            },
        );
        self
    }

    /// Registered names, sorted.
    pub fn names(&self) -> Vec<String> {
        self.entries.keys().map(|k| k.to_string()).collect()
    }

    fn entry(&self, name: &str) -> Result<&Entry, RegistryError> {
        self.entries
            .get(name)
            .ok_or_else(|| RegistryError::Unknown {
                name: name.to_owned(),
                known: self.names(),
            })
    }

    /// Parses and checks behaviour `name`'s table, once: the result builds
    /// the behaviour as often as needed. Config errors carry keys relative
    /// to the table.
    pub fn prepare(
        &self,
        name: &str,
        table: &toml::Table,
        setup: &Setup<'_>,
    ) -> Result<Prepared, RegistryError> {
        Ok((self.entry(name)?.prepare)(table, setup)?)
    }

    /// Builds behaviour `name` from its table (prepares it, then builds).
    pub fn build(
        &self,
        name: &str,
        table: &toml::Table,
        setup: &Setup<'_>,
    ) -> Result<Box<dyn Behaviour>, RegistryError> {
        Ok(self.prepare(name, table, setup)?.build(setup))
    }

    /// The default table of behaviour `name`.
    pub fn defaults(&self, name: &str) -> Result<toml::Table, RegistryError> {
        Ok(self.entry(name)?.defaults.clone())
    }
}
