//! The configuration as the user gave it: one TOML file with a section per
//! crate, parsed once into typed sections.
//!
//! Every section is owned by its crate (`serde(default, deny_unknown_fields)`,
//! `Default`, `validate()`); this module composes them, checks each section
//! and the values that span sections, and turns TOML and validation
//! failures into messages that name the file, the line and the dotted key.
//! What follows from these values, and the nodes built from them, is
//! [`Resolved`](crate::Resolved).

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use arcnav_arbiter::ArbiterConfig;
use arcnav_behaviours::Registry;
use arcnav_guard::GuardConfig;
use arcnav_localmap::LocalMapConfig;
use arcnav_perception::{PerceptionConfig, SensorConfig};
use arcnav_pipeline::{ExternalConfig, LiveConfig, PipelineConfig};
use arcnav_sim::SimConfig;

use arcnav_vehicle::config::toml_location;
use arcnav_vehicle::mission::{Mission, MissionConfig};
use arcnav_vehicle::{ArcSetConfig, ConfigError, VehicleConfig};
use serde::{Deserialize, Serialize};

use crate::bus::BusConfig;
use crate::lookahead::section::LookaheadConfig;

/// `[vehicle]`'s keys that only a rectangle's body reads.
const RECTANGLE_KEYS: [&str; 3] = ["length_m", "width_m", "rear_overhang_m"];

/// The table under `[behaviours]` that holds the external behaviours,
/// `[behaviours.external.NAME]` (no built-in behaviour has this name).
pub const EXTERNAL: &str = "external";

/// The documented defaults, as shipped in `config/default.toml`.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

/// Every parameter of arcnav, as given: the defaults with a file's keys
/// (and any command-line settings) over them. Nothing here is derived;
/// [`Config::resolve`] checks it once and derives what follows.
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
    /// The guard beside the pipeline.
    pub guard: GuardConfig,
    /// The operating area and what a mission does when a waypoint cannot
    /// be reached.
    pub mission: MissionConfig,
    /// One table per active behaviour, `[behaviours.NAME]`. The built-in
    /// behaviours are always present (set their weight to 0 to skip them);
    /// a table in a file changes only the keys it names. Programs of their
    /// own are `[behaviours.external.NAME]` ([`ExternalConfig`]).
    #[serde(deserialize_with = "behaviours_with_defaults")]
    pub behaviours: BTreeMap<String, toml::Table>,
    /// Where each key that is not a default came from.
    #[serde(skip)]
    origins: BTreeMap<String, Origin>,
    /// The file this configuration was read from, if any.
    #[serde(skip)]
    source: Option<PathBuf>,
}

/// Where a key's value came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// A configuration file (its name).
    File(String),
    /// A command-line setting (the option that set it).
    CommandLine(String),
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File(file) => write!(f, "from {file}"),
            Self::CommandLine(option) => write!(f, "from {option}"),
        }
    }
}

thread_local! {
    static COUNTS: Cell<LoadCounts> = const { Cell::new(LoadCounts { parses: 0, validations: 0 }) };
}

/// How often this thread has parsed configuration text and validated a
/// configuration: a load parses once and a resolution validates once,
/// however many nodes are built from it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoadCounts {
    pub parses: u64,
    pub validations: u64,
}

/// This thread's [`LoadCounts`] so far.
pub fn load_counts() -> LoadCounts {
    COUNTS.with(Cell::get)
}

pub(crate) fn count(f: impl FnOnce(&mut LoadCounts)) {
    COUNTS.with(|c| {
        let mut counts = c.get();
        f(&mut counts);
        c.set(counts);
    });
}

impl Default for Config {
    fn default() -> Self {
        Self {
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
            guard: GuardConfig::default(),
            mission: MissionConfig::default(),
            behaviours: default_behaviours(),
            origins: BTreeMap::new(),
            source: None,
        }
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
    /// Reads and parses a TOML file; missing keys keep their defaults.
    /// Nothing is checked yet: [`Config::resolve`] does that.
    pub fn load(path: &Path) -> Result<Self, ConfigLoadError> {
        let text =
            arcnav_vehicle::files::read_text(path).map_err(|source| ConfigLoadError::Read {
                path: path.to_owned(),
                source,
            })?;
        let mut config = Self::parse_in(&text, &path.display().to_string(), path.parent())?;
        config.source = Some(path.to_owned());
        Ok(config)
    }

    /// The file this configuration was read from; `None` for the defaults
    /// (and text parsed in memory).
    pub fn source(&self) -> Option<&Path> {
        self.source.as_deref()
    }

    /// The files this configuration reads, each named by what it is: the
    /// file it came from, the occupancy map, the bus key file. (The
    /// occupancy map's image is named inside it: see
    /// `Resolved::files_read`.) No output of a run may be one of them.
    pub fn files_read(&self) -> Vec<(&'static str, PathBuf)> {
        let mut files = Vec::new();
        files.extend(self.source.clone().map(|p| ("the configuration", p)));
        let occupancy = &self.localmap.occupancy.file;
        if !occupancy.is_empty() {
            files.push(("the occupancy map", PathBuf::from(occupancy)));
        }
        if self.bus.auth.enabled() {
            files.push(("the bus key file", self.bus.auth.key_file.clone()));
        }
        files
    }

    /// Loads `path` if given, else the defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<Self, ConfigLoadError> {
        path.map_or_else(|| Ok(Self::default()), Self::load)
    }

    /// Parses TOML text; `origin` names it in messages.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigLoadError> {
        Self::parse_in(text, origin, None)
    }

    /// Parses; relative file names in the text are taken from `base` (the
    /// configuration file's directory), if given.
    fn parse_in(text: &str, origin: &str, base: Option<&Path>) -> Result<Self, ConfigLoadError> {
        count(|c| c.parses += 1);
        let error = |err: toml::de::Error| {
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
        };
        // Parsed once: the document's keys say where each value came from
        // (for `arcnav config`), then the same document is deserialised.
        let document = toml::de::DeTable::parse(text).map_err(error)?;
        let mut keys = Vec::new();
        leaf_keys("", document.get_ref(), &mut keys);
        let mut config =
            Self::deserialize(toml::de::Deserializer::from(document)).map_err(error)?;
        config.origins = keys
            .into_iter()
            .map(|key| (key, Origin::File(origin.to_owned())))
            .collect();
        let file = &mut config.localmap.occupancy.file;
        if let Some(base) = base
            && !file.is_empty()
            && Path::new(file.as_str()).is_relative()
        {
            *file = base.join(&*file).display().to_string();
        }
        // The key file too, so that every file the configuration names is
        // where it is read from (`BusAuth::key_path` of a relative name
        // still joins the base a live run gives).
        let key = &mut config.bus.auth.key_file;
        if let Some(base) = base
            && !key.as_os_str().is_empty()
            && key.is_relative()
        {
            *key = base.join(&*key);
        }
        Ok(config)
    }

    /// Records that `key` (dotted) was set by the command-line `option`.
    pub fn set_by(&mut self, key: &str, option: &str) {
        self.origins
            .insert(key.to_owned(), Origin::CommandLine(option.to_owned()));
    }

    /// Where `key` (dotted, as `config/default.toml` spells it) came from:
    /// `None` for a default.
    pub fn origin(&self, key: &str) -> Option<&Origin> {
        self.origins.get(key)
    }

    /// The built-in (and registered) behaviours' tables: `[behaviours.NAME]`
    /// but `[behaviours.external]`.
    pub(crate) fn behaviour_tables(&self) -> impl Iterator<Item = (&String, &toml::Table)> {
        self.behaviours.iter().filter(|(name, _)| *name != EXTERNAL)
    }

    /// `[behaviours.external.NAME]`, each parsed and checked (keys in
    /// errors are absolute).
    pub(crate) fn external_behaviours(
        &self,
    ) -> Result<BTreeMap<String, ExternalConfig>, ConfigError> {
        let Some(tables) = self.behaviours.get(EXTERNAL) else {
            return Ok(BTreeMap::new());
        };
        let mut externals = BTreeMap::new();
        for (name, table) in tables {
            let key = format!("behaviours.{EXTERNAL}.{name}");
            if !ExternalConfig::is_plain_name(name) {
                return Err(ConfigError::new(
                    key,
                    format!(
                        "{name:?} is not a behaviour name: lower-case letters, digits and _ \
                         (its votes come on ARC_VOTES_<NAME in upper case>)"
                    ),
                ));
            }
            if self.behaviours.contains_key(name) {
                return Err(ConfigError::new(
                    key,
                    format!(
                        "{name:?} is also configured under [behaviours.{name}]: one behaviour, \
                         one name (rename the external one)"
                    ),
                ));
            }
            let toml::Value::Table(table) = table else {
                return Err(ConfigError::new(
                    key,
                    "must be a table (`[behaviours.external.NAME]` with `command = [...]`)",
                ));
            };
            let external: ExternalConfig = table
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| ConfigError::new(key.clone(), e.message()))?;
            external.validate().map_err(|e| e.within(&key))?;
            externals.insert(name.clone(), external);
        }
        Ok(externals)
    }

    /// Every name the arbiter's section gives must be a configured
    /// behaviour, built in or external.
    pub(crate) fn arbiter_names_behaviours(
        &self,
        externals: &BTreeMap<String, ExternalConfig>,
    ) -> Result<(), ConfigError> {
        let names = || {
            self.behaviour_tables()
                .map(|(name, _)| name)
                .chain(externals.keys())
        };
        let known = || {
            let mut known = self
                .behaviour_tables()
                .map(|(name, _)| name.as_str())
                .collect::<Vec<_>>()
                .join(", ");
            if !externals.is_empty() {
                let external: Vec<&str> = externals.keys().map(String::as_str).collect();
                known.push_str(&format!("; external: {}", external.join(", ")));
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
        if let Some(name) = self
            .arbiter
            .weights
            .keys()
            .find(|name| !names().any(|n| n == *name))
        {
            return Err(unknown(format!("arbiter.weights.{name}"), name));
        }
        if let Some(name) = self
            .arbiter
            .required
            .iter()
            .find(|name| !names().any(|n| n == *name))
        {
            return Err(unknown("arbiter.required".into(), name));
        }
        if names().all(|name| self.arbiter.weight(name) <= 0.0) {
            return Err(ConfigError::new(
                "arbiter.weights",
                "every configured behaviour has weight 0: nothing would vote and the vehicle would never move",
            ));
        }
        Ok(())
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
        let max = arcnav_localmap::MAX_SENSORS;
        if self.sensors.len() > max {
            // Past the limit every report had been refused while the run
            // said "completed, 0 dropped".
            return Err(ConfigError::new(
                "sensors",
                format!(
                    "lists {} sensors; the local map tracks at most {max} (one bit each in its \
                     cells' sensor set)",
                    self.sensors.len()
                ),
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

    /// `vehicle.length_m`, `width_m` and `rear_overhang_m` are a
    /// rectangle's: given with another footprint, they would say a body
    /// that the outline does not.
    fn rectangle_keys_only_with_a_rectangle(&self) -> Result<(), ConfigError> {
        let shape = self.vehicle.footprint;
        if shape == arcnav_vehicle::model::FootprintShape::Rectangle {
            return Ok(());
        }
        for key in RECTANGLE_KEYS {
            if self.origin(&format!("vehicle.{key}")).is_some() {
                return Err(ConfigError::new(
                    format!("vehicle.{key}"),
                    format!(
                        "is a rectangle's, and footprint is \"{}\": the outline gives the body's length and width; leave {key} out",
                        shape.name()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Checks every section and the values that relate sections (the
    /// behaviours' tables are checked as they are parsed, when resolved);
    /// the vehicle's sensors, which the check builds.
    pub(crate) fn validate_sections(
        &self,
    ) -> Result<(Vec<arcnav_perception::SensorModel>, Mission), ConfigError> {
        count(|c| c.validations += 1);
        self.vehicle.validate().map_err(|e| e.within("vehicle"))?;
        self.rectangle_keys_only_with_a_rectangle()?;
        self.arcs
            .validate_for(&self.vehicle)
            .map_err(|e| e.within("arcs"))?;
        self.sensor.validate().map_err(|e| e.within("sensor"))?;
        let sensors = self.sensor_models()?;
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
        self.guard.validate().map_err(|e| e.within("guard"))?;
        self.bus.validate().map_err(|e| e.within("bus"))?;
        self.sim.validate().map_err(|e| e.within("sim"))?;
        let mission = self.mission.checked().map_err(|e| e.within("mission"))?;
        Ok((sensors, mission))
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

    /// The configuration as given, as TOML.
    pub fn to_toml(&self) -> String {
        // Plain structs of numbers, strings and tables always serialise.
        let text =
            toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"));
        if self.vehicle.footprint == arcnav_vehicle::model::FootprintShape::Rectangle {
            return text;
        }
        // A circle's or a polygon's body has no rectangle's keys (given,
        // they are refused): what is written reads back.
        let Ok(mut document) = text.parse::<toml_edit::DocumentMut>() else {
            return text;
        };
        if let Some(vehicle) = document
            .get_mut("vehicle")
            .and_then(toml_edit::Item::as_table_mut)
        {
            for key in RECTANGLE_KEYS {
                vehicle.remove(key);
            }
            // A polygon's vertices one line, `[[x, y], ...]`, as written.
            if let Some(vertices) = vehicle
                .get_mut("vertices_m")
                .and_then(toml_edit::Item::as_array_mut)
            {
                for vertex in vertices.iter_mut() {
                    if let Some(pair) = vertex.as_array_mut() {
                        pair.fmt();
                    }
                }
                vertices.fmt();
            }
        }
        document.to_string()
    }
}

/// The dotted keys of every value in `table` that is not itself a table
/// (an array of tables, `[[sensors]]`, is one key).
fn leaf_keys(prefix: &str, table: &toml::de::DeTable<'_>, out: &mut Vec<String>) {
    for (k, v) in table {
        let key = if prefix.is_empty() {
            k.get_ref().to_string()
        } else {
            format!("{prefix}.{}", k.get_ref())
        };
        match v.get_ref() {
            toml::de::DeValue::Table(t) => leaf_keys(&key, t, out),
            _ => out.push(key),
        }
    }
}
