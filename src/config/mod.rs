//! The whole configuration: one TOML file with a section per crate.
//!
//! Every section is owned by its crate (`serde(default, deny_unknown_fields)`,
//! `Default`, `validate()`); this module composes them, cross-checks values
//! that span sections, and turns TOML and validation failures into messages
//! that name the file, the line and the dotted key. Building the
//! pipeline's nodes from it is in `nodes`.

mod bus;
mod lookahead;
mod nodes;

pub use bus::{BusAuthConfig, BusConfig};
pub use lookahead::{Lookahead, LookaheadConfig};

use std::fmt;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;
use std::sync::Arc;

use arcnav_arbiter::ArbiterConfig;
use arcnav_behaviours::{Prepared, Registry, RegistryError, Setup};
use arcnav_localmap::LocalMapConfig;
use arcnav_perception::{PerceptionConfig, SensorConfig};
use arcnav_pipeline::{LiveConfig, PipelineConfig};
use arcnav_sim::SimConfig;

use arcnav_vehicle::config::toml_location;
use arcnav_vehicle::{ArcSet, ArcSetConfig, ConfigError, VehicleConfig};
use serde::{Deserialize, Serialize};

/// The documented defaults, as shipped in `config/default.toml`.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

/// Every parameter of arcnav.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub vehicle: VehicleConfig,
    pub arcs: ArcSetConfig,
    /// The sensor, when the vehicle has one.
    pub sensor: SensorConfig,
    /// The sensors, when it has several (`[[sensors]]`; then `[sensor]`
    /// keeps its defaults). Each is rendered by the simulator, logged on
    /// its own channel `RANGE_IMAGE_<ID>` and evaluated image by image.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<SensorConfig>,
    pub perception: PerceptionConfig,
    pub localmap: LocalMapConfig,
    pub arbiter: ArbiterConfig,
    /// How far ahead the vehicle looks, from its cruise speed.
    pub lookahead: LookaheadConfig,
    pub pipeline: PipelineConfig,
    pub live: LiveConfig,
    pub bus: BusConfig,
    pub sim: SimConfig,
    /// One table per active behaviour, `[behaviours.NAME]`. The built-in
    /// behaviours are always present (set their weight to 0 to skip them);
    /// a table in a file changes only the keys it names.
    #[serde(deserialize_with = "behaviours_with_defaults")]
    pub behaviours: BTreeMap<String, toml::Table>,
    /// The behaviour tables parsed into their typed configurations and
    /// checked, once, when the configuration was loaded.
    #[serde(skip)]
    prepared: PreparedBehaviours,
    /// The static occupancy map `[localmap.occupancy]` names, read once.
    #[serde(skip)]
    statics: StaticMapCache,
}

/// The static map read for one `[localmap.occupancy]` and patch size.
type StaticEntry = (
    arcnav_localmap::OccupancyConfig,
    f64,
    Option<Arc<arcnav_localmap::StaticMap>>,
);

#[derive(Debug, Clone, Default)]
struct StaticMapCache(Arc<std::sync::Mutex<Option<StaticEntry>>>);

impl PartialEq for StaticMapCache {
    /// A cache of what a file holds: configurations compare by its name.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Behaviour tables parsed and checked by the registry, by name. Building
/// a behaviour uses these when its table is still the one prepared.
#[derive(Debug, Clone, Default)]
struct PreparedBehaviours(Arc<BTreeMap<String, Prepared>>);

impl PartialEq for PreparedBehaviours {
    /// A cache of what the tables say: configurations compare by their tables.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Default for Config {
    fn default() -> Self {
        let mut config = Self {
            vehicle: VehicleConfig::default(),
            arcs: ArcSetConfig::default(),
            sensor: SensorConfig::default(),
            sensors: Vec::new(),
            perception: PerceptionConfig::default(),
            localmap: LocalMapConfig::default(),
            arbiter: ArbiterConfig::default(),
            lookahead: LookaheadConfig::default(),
            pipeline: PipelineConfig::default(),
            live: LiveConfig::default(),
            bus: BusConfig::default(),
            sim: SimConfig::default(),
            behaviours: default_behaviours(),
            prepared: PreparedBehaviours::default(),
            statics: StaticMapCache::default(),
        };
        // The built-in defaults always prepare.
        if let Ok(prepared) = config.prepare_behaviours(&Registry::builtin()) {
            config.prepared = prepared;
        }
        config
    }
}

/// The built-in behaviours with their default tables.
fn default_behaviours() -> BTreeMap<String, toml::Table> {
    let registry = Registry::builtin();
    registry
        .names()
        .into_iter()
        .filter_map(|name| registry.defaults(&name).ok().map(|table| (name, table)))
        .collect()
}

fn behaviours_with_defaults<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<BTreeMap<String, toml::Table>, D::Error> {
    let mut behaviours = default_behaviours();
    let given: BTreeMap<String, toml::Table> = serde::Deserialize::deserialize(deserializer)?;
    for (name, table) in given {
        behaviours.entry(name).or_default().extend(table);
    }
    Ok(behaviours)
}

/// A configuration that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigLoadError {
    #[error("cannot read configuration file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{location}: {message}")]
    Parse { location: Location, message: String },
    #[error("{origin}: invalid configuration: {source}")]
    Invalid { origin: String, source: ConfigError },
}

/// Where in a TOML document an error is.
#[derive(Debug, Clone, PartialEq)]
pub struct Location {
    pub origin: String,
    /// 1-based line, when TOML gave a position.
    pub line: Option<usize>,
    /// Dotted key written on that line, when there is one.
    pub key: Option<String>,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.origin)?;
        if let Some(line) = self.line {
            write!(f, ", line {line}")?;
        }
        if let Some(key) = &self.key {
            write!(f, ", `{key}`")?;
        }
        Ok(())
    }
}

impl Config {
    /// Reads, parses and validates a TOML file; missing keys keep their defaults.
    pub fn load(path: &Path) -> Result<Self, ConfigLoadError> {
        let text =
            arcnav_vehicle::files::read_text(path).map_err(|source| ConfigLoadError::Read {
                path: path.to_owned(),
                source,
            })?;
        Self::from_toml_in(
            &text,
            &path.display().to_string(),
            &Registry::builtin(),
            path.parent(),
        )
    }

    /// Loads `path` if given, else the defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<Self, ConfigLoadError> {
        path.map_or_else(|| Ok(Self::default()), Self::load)
    }

    /// Parses and validates TOML text; `origin` names it in messages.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, ConfigLoadError> {
        Self::from_toml_with(text, origin, &Registry::builtin())
    }

    /// Like [`Config::from_toml`], with behaviours from `registry` (for
    /// programs that add their own).
    pub fn from_toml_with(
        text: &str,
        origin: &str,
        registry: &Registry,
    ) -> Result<Self, ConfigLoadError> {
        Self::from_toml_in(text, origin, registry, None)
    }

    /// Parses and validates; relative file names in the text are taken
    /// from `base` (the configuration file's directory), if given.
    fn from_toml_in(
        text: &str,
        origin: &str,
        registry: &Registry,
        base: Option<&Path>,
    ) -> Result<Self, ConfigLoadError> {
        let mut config: Self = toml::from_str(text).map_err(|err| {
            let (line, key) = err
                .span()
                .map(|span| toml_location(text, span.start))
                .unwrap_or((None, None));
            ConfigLoadError::Parse {
                location: Location {
                    origin: origin.to_owned(),
                    line,
                    key,
                },
                message: err.message().to_owned(),
            }
        })?;
        let file = &mut config.localmap.occupancy.file;
        if let Some(base) = base
            && !file.is_empty()
            && Path::new(file.as_str()).is_relative()
        {
            *file = base.join(&*file).display().to_string();
        }
        config
            .validate_sections()
            .and_then(|()| config.prepare_behaviours(registry))
            .map(|prepared| {
                for (name, p) in prepared.0.iter() {
                    config.behaviours.insert(name.clone(), p.table().clone());
                }
                config.prepared = prepared;
            })
            .map_err(|source| ConfigLoadError::Invalid {
                origin: origin.to_owned(),
                source,
            })?;
        Ok(config)
    }

    /// Reads, parses and validates a file with behaviours from `registry`.
    pub fn load_with(path: &Path, registry: &Registry) -> Result<Self, ConfigLoadError> {
        let text =
            arcnav_vehicle::files::read_text(path).map_err(|source| ConfigLoadError::Read {
                path: path.to_owned(),
                source,
            })?;
        Self::from_toml_in(&text, &path.display().to_string(), registry, path.parent())
    }

    /// The arc set this configuration describes (`driven_paths = "auto"`
    /// decided at its cruise speed).
    pub fn arc_set(&self) -> Result<ArcSet, ConfigError> {
        ArcSet::for_cruise(&self.arcs, self.arbiter.cruise_speed_mps).map_err(|e| e.within("arcs"))
    }

    fn setup<'a>(
        &'a self,
        arcs: &'a ArcSet,
        statics: Option<&'a Arc<arcnav_localmap::StaticMap>>,
    ) -> Setup<'a> {
        Setup {
            arcs,
            vehicle: &self.vehicle,
            localmap: &self.localmap,
            statics,
            cruise_mps: self.arbiter.cruise_speed_mps,
        }
    }

    /// Parses and checks every behaviour table with `registry`; checks that
    /// `[arbiter.weights]` and `arbiter.required` name configured behaviours.
    fn prepare_behaviours(&self, registry: &Registry) -> Result<PreparedBehaviours, ConfigError> {
        let arcs = self.arc_set()?;
        let statics = self.static_map()?;
        let setup = self.setup(&arcs, statics.as_ref());
        let prepared = self
            .behaviours
            .iter()
            .map(|(name, table)| {
                registry
                    .prepare(name, table, &setup)
                    .map(|p| (name.clone(), p))
                    .map_err(|e| behaviour_error(name, e))
            })
            .collect::<Result<BTreeMap<_, _>, _>>()?;
        self.arbiter_names_behaviours()?;
        Ok(PreparedBehaviours(Arc::new(prepared)))
    }

    /// Every name the arbiter's section gives must be a configured behaviour
    /// (weights may also name `live.external_behaviours`; `required` may
    /// not: `arcnav sim` and `arcnav replay` run without them).
    fn arbiter_names_behaviours(&self) -> Result<(), ConfigError> {
        let known = || {
            let mut known = self
                .behaviours
                .keys()
                .cloned()
                .collect::<Vec<_>>()
                .join(", ");
            if !self.live.external_behaviours.is_empty() {
                known.push_str(&format!(
                    "; external: {}",
                    self.live.external_behaviours.join(", ")
                ));
            }
            known
        };
        let unknown = |key: String, name: &str| {
            ConfigError::new(
                key,
                format!(
                    "{name:?} is not a configured behaviour (configured: {})",
                    known()
                ),
            )
        };
        if let Some(name) = self.arbiter.weights.keys().find(|name| {
            !self.behaviours.contains_key(*name) && !self.live.external_behaviours.contains(name)
        }) {
            return Err(unknown(format!("arbiter.weights.{name}"), name));
        }
        if let Some(name) = self
            .arbiter
            .required
            .iter()
            .find(|name| !self.behaviours.contains_key(*name))
        {
            return Err(unknown("arbiter.required".into(), name));
        }
        if self
            .behaviours
            .keys()
            .all(|name| self.arbiter.weight(name) <= 0.0)
        {
            return Err(ConfigError::new(
                "arbiter.weights",
                "every configured behaviour has weight 0: nothing would vote and the vehicle would never move",
            ));
        }
        Ok(())
    }

    /// Checks every section and the values that relate sections, with the
    /// built-in behaviours.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_with(&Registry::builtin())
    }

    /// Checks every section with behaviours from `registry` (a configuration
    /// built in code; one loaded from TOML was checked when loaded).
    pub fn validate_with(&self, registry: &Registry) -> Result<(), ConfigError> {
        self.validate_sections()?;
        self.prepare_behaviours(registry).map(|_| ())
    }

    /// The vehicle's sensors: each of `[[sensors]]`, or `[sensor]`. Keys
    /// in errors are absolute (`sensors[1].id`).
    pub fn sensor_models(&self) -> Result<Vec<arcnav_perception::SensorModel>, ConfigError> {
        if self.sensors.is_empty() {
            return Ok(vec![self.sensor.model().map_err(|e| e.within("sensor"))?]);
        }
        if self.sensor != SensorConfig::default() {
            return Err(ConfigError::new(
                "sensor",
                "is set as well as [[sensors]]: give the vehicle's sensors in one place \
                 (move [sensor] into [[sensors]])",
            ));
        }
        let mut models: Vec<arcnav_perception::SensorModel> = Vec::new();
        for (i, sensor) in self.sensors.iter().enumerate() {
            let model = sensor
                .model()
                .map_err(|e| e.within(&format!("sensors[{i}]")))?;
            if let Some(j) = models.iter().position(|m| m.id == model.id) {
                return Err(ConfigError::new(
                    format!("sensors[{i}].id"),
                    format!(
                        "{:?} is also the id of sensors[{j}]: each sensor needs its own (it names \
                         its channel RANGE_IMAGE_<ID> and its cells in the local map)",
                        model.id
                    ),
                ));
            }
            models.push(model);
        }
        Ok(models)
    }

    fn validate_sections(&self) -> Result<(), ConfigError> {
        self.vehicle.validate().map_err(|e| e.within("vehicle"))?;
        self.arcs
            .validate_for(&self.vehicle)
            .map_err(|e| e.within("arcs"))?;
        self.sensor.validate().map_err(|e| e.within("sensor"))?;
        self.sensor_models()?;
        self.perception
            .validate_for(&self.vehicle)
            .map_err(|e| e.within("perception"))?;
        self.localmap.validate().map_err(|e| e.within("localmap"))?;
        self.region_covers_the_map_window()?;
        self.arbiter.validate().map_err(|e| e.within("arbiter"))?;
        if self.arbiter.cruise_speed_mps > self.vehicle.max_speed_mps {
            return Err(ConfigError::new(
                "arbiter.cruise_speed_mps",
                format!(
                    "is {} m/s, faster than the vehicle's top speed (vehicle.max_speed_mps = {} m/s)",
                    self.arbiter.cruise_speed_mps, self.vehicle.max_speed_mps
                ),
            ));
        }
        self.lookahead
            .validate()
            .map_err(|e| e.within("lookahead"))?;
        self.pipeline.validate().map_err(|e| e.within("pipeline"))?;
        self.live.validate().map_err(|e| e.within("live"))?;
        if let Some(name) = self
            .live
            .external_behaviours
            .iter()
            .find(|name| self.behaviours.contains_key(*name))
        {
            return Err(ConfigError::new(
                "live.external_behaviours",
                format!(
                    "{name:?} is also configured under [behaviours.{name}]: one behaviour, one \
                     process (remove one of them)"
                ),
            ));
        }
        self.bus.validate().map_err(|e| e.within("bus"))?;
        self.sim.validate().map_err(|e| e.within("sim"))?;
        self.static_map()?;
        Ok(())
    }

    /// The static occupancy map `[localmap.occupancy]` names, gathered onto
    /// the local map's patches (read once per file and patch size).
    pub fn static_map(&self) -> Result<Option<Arc<arcnav_localmap::StaticMap>>, ConfigError> {
        let occupancy = &self.localmap.occupancy;
        let patch = self.localmap.patch_size_m;
        let mut cache = self
            .statics
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((c, p, map)) = cache.as_ref()
            && c == occupancy
            && *p == patch
        {
            return Ok(map.clone());
        }
        let map = crate::occupancy::load(occupancy)
            .map_err(|e| ConfigError::new("localmap.occupancy.file", e.to_string()))?
            .map(|grid| Arc::new(arcnav_localmap::StaticMap::from_grid(&grid, patch)));
        if let Some(m) = &map {
            tracing::info!(
                file = %occupancy.file,
                patches = m.len(),
                "static occupancy map merged into the local map"
            );
        }
        *cache = Some((occupancy.clone(), patch, map.clone()));
        Ok(map)
    }

    /// Perception must evaluate all the ground the local map keeps.
    fn region_covers_the_map_window(&self) -> Result<(), ConfigError> {
        let (region, map) = (&self.perception.region, &self.localmap);
        [
            ("ahead_m", region.ahead_m, map.ahead_m),
            ("behind_m", region.behind_m, map.behind_m),
            ("half_width_m", region.half_width_m, map.half_width_m),
        ]
        .into_iter()
        .find(|&(_, evaluated, kept)| evaluated < kept)
        .map_or(Ok(()), |(key, evaluated, kept)| {
            Err(ConfigError::new(
                format!("perception.region.{key}"),
                format!(
                    "is {evaluated} m, less than localmap.{key} ({kept} m): \
                     obstacles there would never reach the map"
                ),
            ))
        })
    }

    /// The configuration as TOML.
    pub fn to_toml(&self) -> String {
        // Plain structs of numbers, strings and tables always serialise.
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"))
    }
}

fn behaviour_error(name: &str, error: RegistryError) -> ConfigError {
    match error {
        RegistryError::Config(e) if e.key.is_empty() => {
            ConfigError::new(format!("behaviours.{name}"), e.reason)
        }
        RegistryError::Config(e) => e.within(&format!("behaviours.{name}")),
        unknown @ RegistryError::Unknown { .. } => {
            ConfigError::new(format!("behaviours.{name}"), unknown.to_string())
        }
    }
}

#[cfg(test)]
mod tests;
