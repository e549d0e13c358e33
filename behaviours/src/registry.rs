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

use std::any::Any;
use std::collections::BTreeMap;
use std::sync::Arc;

use arcnav_vehicle::ConfigError;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::behaviour::{Behaviour, Plugin, Setup};

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
/// (once): what building the behaviour needs, the typed configuration, and
/// the table with every default filled in.
#[derive(Clone)]
pub struct Prepared {
    table: toml::Table,
    config: Arc<dyn Any + Send + Sync>,
    build: Constructor,
    remake: Remaker,
}

/// Builds a behaviour from a configuration checked once.
type Constructor = Arc<dyn Fn(&Setup<'_>) -> Box<dyn Behaviour> + Send + Sync>;

/// Checks another configuration of the same behaviour and prepares it.
type Remaker = Arc<
    dyn Fn(&(dyn Any + Send + Sync), &Setup<'_>) -> Result<Prepared, ConfigError> + Send + Sync,
>;

impl Prepared {
    /// `config` of behaviour `P`, checked against `setup`.
    fn of<P: Plugin>(config: P::Config, setup: &Setup<'_>) -> Result<Self, ConfigError> {
        P::validate(&config, setup)?;
        let typed = Arc::new(config);
        let built = Arc::clone(&typed);
        Ok(Self {
            table: table_of(&*typed),
            config: typed,
            build: Arc::new(move |setup| {
                Box::new(P::build((*built).clone(), setup)) as Box<dyn Behaviour>
            }),
            remake: Arc::new(|config, setup| match config.downcast_ref::<P::Config>() {
                Some(config) => Self::of::<P>(config.clone(), setup),
                None => Err(ConfigError::new(
                    "",
                    format!("is not the configuration of behaviour {:?}", P::NAME),
                )),
            }),
        })
    }

    /// The table with every default filled in.
    pub fn table(&self) -> &toml::Table {
        &self.table
    }

    /// The typed configuration, when it is a `C`.
    pub fn config<C: 'static>(&self) -> Option<&C> {
        self.config.downcast_ref::<C>()
    }

    /// The same behaviour with `config` in place of its own (a
    /// configuration with derived values set), checked against `setup`
    /// as a table is. Refused when `config` is not this behaviour's type.
    pub fn with_config<C: Send + Sync + 'static>(
        &self,
        config: C,
        setup: &Setup<'_>,
    ) -> Result<Self, ConfigError> {
        (self.remake)(&config, setup)
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
        let prepare: Preparer = Box::new(|table, setup| Prepared::of::<P>(parse(table)?, setup));
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
