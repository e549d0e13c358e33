//! The whole configuration: one TOML file with a section per crate.
//!
//! Every section is owned by its crate (`serde(default, deny_unknown_fields)`,
//! `Default`, `validate()`); this module composes them, cross-checks values
//! that span sections, and turns TOML and validation failures into messages
//! that name the file, the line and the dotted key.

use std::fmt;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;
use std::sync::Arc;

use arcnav_arbiter::{Arbiter, ArbiterConfig};
use arcnav_behaviours::{Behaviour, Prepared, Registry, RegistryError, Setup};
use arcnav_localmap::LocalMapConfig;
use arcnav_perception::{PerceptionConfig, SensorConfig};
use arcnav_pipeline::{
    BehaviourSet, DecisionCycle, Delivery, LiveConfig, LocalMapNode, PerceptionNode, Pipeline,
    PipelineConfig,
};
use arcnav_sim::SimConfig;

use arcnav_vehicle::config::toml_location;
use arcnav_vehicle::{ArcSet, ArcSetConfig, ConfigError, VehicleConfig};
use serde::{Deserialize, Serialize};

/// The documented defaults, as shipped in `config/default.toml`.
pub const DEFAULT_TOML: &str = include_str!("../config/default.toml");

/// Every parameter of arcnav.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub vehicle: VehicleConfig,
    pub arcs: ArcSetConfig,
    pub sensor: SensorConfig,
    pub perception: PerceptionConfig,
    pub localmap: LocalMapConfig,
    pub arbiter: ArbiterConfig,
    pub pipeline: PipelineConfig,
    pub live: LiveConfig,
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
            perception: PerceptionConfig::default(),
            localmap: LocalMapConfig::default(),
            arbiter: ArbiterConfig::default(),
            pipeline: PipelineConfig::default(),
            live: LiveConfig::default(),
            sim: SimConfig::default(),
            behaviours: default_behaviours(),
            prepared: PreparedBehaviours::default(),
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
        let text = std::fs::read_to_string(path).map_err(|source| ConfigLoadError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string())
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
        let text = std::fs::read_to_string(path).map_err(|source| ConfigLoadError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_with(&text, &path.display().to_string(), registry)
    }

    /// The arc set this configuration describes.
    pub fn arc_set(&self) -> Result<ArcSet, ConfigError> {
        ArcSet::new(&self.arcs).map_err(|e| e.within("arcs"))
    }

    fn setup<'a>(&'a self, arcs: &'a ArcSet) -> Setup<'a> {
        Setup {
            arcs,
            vehicle: &self.vehicle,
            patch_size_m: self.localmap.patch_size_m,
        }
    }

    /// Parses and checks every behaviour table with `registry`; checks that
    /// `[arbiter.weights]` and `arbiter.required` name configured behaviours.
    fn prepare_behaviours(&self, registry: &Registry) -> Result<PreparedBehaviours, ConfigError> {
        let arcs = self.arc_set()?;
        let setup = self.setup(&arcs);
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

    /// Every name the arbiter's section gives must be a configured behaviour.
    fn arbiter_names_behaviours(&self) -> Result<(), ConfigError> {
        let known = || {
            self.behaviours
                .keys()
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
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
            .find(|name| !self.behaviours.contains_key(*name))
        {
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
        Ok(())
    }

    /// Builds the configured behaviour `name` (`None`: not configured), from
    /// its table as prepared at load; a table changed since is prepared now.
    pub fn build_behaviour(
        &self,
        registry: &Registry,
        arcs: &ArcSet,
        name: &str,
    ) -> Option<Result<Box<dyn Behaviour>, ConfigError>> {
        let table = self.behaviours.get(name)?;
        let setup = self.setup(arcs);
        Some(match self.prepared.0.get(name) {
            Some(p) if p.table() == table => Ok(p.build(&setup)),
            _ => registry
                .prepare(name, table, &setup)
                .map(|p| p.build(&setup))
                .map_err(|e| behaviour_error(name, e)),
        })
    }

    /// Builds every configured behaviour (in name order).
    pub fn build_behaviours(
        &self,
        registry: &Registry,
        arcs: &ArcSet,
    ) -> Result<Vec<Box<dyn Behaviour>>, ConfigError> {
        self.behaviours
            .keys()
            .filter_map(|name| self.build_behaviour(registry, arcs, name))
            .collect()
    }

    /// The configured behaviours, voting over the configured arcs.
    pub fn behaviour_set(&self, registry: &Registry) -> Result<BehaviourSet, ConfigError> {
        let arcs = self.arc_set()?;
        Ok(BehaviourSet::new(
            self.build_behaviours(registry, &arcs)?,
            arcs,
        ))
    }

    /// The perception node, from `[perception]` and `[pipeline]`.
    pub fn perception_node(&self) -> Result<PerceptionNode, ConfigError> {
        PerceptionNode::new(&self.perception, &self.pipeline).map_err(|e| e.within("perception"))
    }

    /// The local map and its cycle clock, from `[localmap]`, the vehicle's
    /// top speed and `[pipeline]`, with reports delivered as `delivery` says.
    pub fn decision_cycle<T>(&self, delivery: Delivery) -> DecisionCycle<T> {
        let map = LocalMapNode::new(&self.localmap, self.vehicle.max_speed_mps);
        DecisionCycle::new(map, &self.pipeline, delivery)
    }

    /// How a live run delivers reports to the map (`[live]`).
    pub fn live_delivery(&self) -> Delivery {
        if self.live.reproduce_lockstep {
            Delivery::held(&self.pipeline)
        } else {
            Delivery::OnArrival {
                decide_at_once: self.live.decide_on_new_cells,
            }
        }
    }

    /// The DAMN arbiter, from `[arbiter]`, `[arcs]` and the vehicle.
    pub fn arbiter(&self) -> Result<Arbiter, ConfigError> {
        Ok(Arbiter::new(&self.arbiter, self.arc_set()?, &self.vehicle))
    }

    /// The lock-step executor with every node of this configuration.
    pub fn lockstep(&self, registry: &Registry) -> Result<Pipeline, ConfigError> {
        Ok(Pipeline::new(
            self.perception_node()?,
            self.decision_cycle(Delivery::held(&self.pipeline)),
            self.behaviour_set(registry)?,
            self.arbiter()?,
        ))
    }

    /// The behaviours whose votes complete a cycle: every configured one
    /// with a positive weight.
    pub fn expected_behaviours(&self) -> Vec<String> {
        self.behaviours
            .keys()
            .filter(|name| self.arbiter.weight(name) > 0.0)
            .cloned()
            .collect()
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

    fn validate_sections(&self) -> Result<(), ConfigError> {
        self.vehicle.validate().map_err(|e| e.within("vehicle"))?;
        self.arcs
            .validate_for(&self.vehicle)
            .map_err(|e| e.within("arcs"))?;
        self.sensor.validate().map_err(|e| e.within("sensor"))?;
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
        self.pipeline.validate().map_err(|e| e.within("pipeline"))?;
        self.live.validate().map_err(|e| e.within("live"))?;
        self.sim.validate().map_err(|e| e.within("sim"))?;
        Ok(())
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
mod tests {
    use super::*;

    fn parse_error(text: &str) -> String {
        Config::from_toml(text, "test.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn defaults_round_trip_through_toml() {
        let defaults = Config::default();
        let text = defaults.to_toml();
        assert_eq!(Config::from_toml(&text, "round-trip").unwrap(), defaults);
    }

    #[test]
    fn the_shipped_default_toml_parses_and_equals_the_defaults() {
        assert_eq!(
            Config::from_toml(DEFAULT_TOML, "config/default.toml").unwrap(),
            Config::default()
        );
    }

    #[test]
    fn the_shipped_default_toml_documents_every_key() {
        fn keys(prefix: &str, table: &toml::Table, out: &mut Vec<String>) {
            for (k, v) in table {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                match v {
                    toml::Value::Table(t) => keys(&key, t, out),
                    _ => out.push(key),
                }
            }
        }
        let shipped: toml::Table = toml::from_str(DEFAULT_TOML).unwrap();
        let defaults: toml::Table = toml::from_str(&Config::default().to_toml()).unwrap();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        keys("", &shipped, &mut a);
        keys("", &defaults, &mut b);
        a.sort();
        b.sort();
        assert_eq!(
            a, b,
            "config/default.toml must hold exactly the configuration's keys"
        );
        // Every key carries a comment right above it or on its line.
        let lines: Vec<&str> = DEFAULT_TOML.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with('[') {
                continue;
            }
            let commented = t.contains('#') || (i > 0 && lines[i - 1].trim().starts_with('#'));
            assert!(
                commented,
                "line {} of config/default.toml has no comment: {t}",
                i + 1
            );
        }
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line() {
        let msg = parse_error("[vehicle]\nwheelbase_m = 3.3\nwheel_base = 3.3\n");
        assert!(
            msg.starts_with("test.toml, line 3, `vehicle.wheel_base`: unknown field `wheel_base`, expected one of"),
            "{msg}"
        );
    }

    #[test]
    fn an_unknown_section_is_named() {
        let msg = parse_error("[vehicel]\nwheelbase_m = 3.3\n");
        assert!(
            msg.starts_with("test.toml, line 1, `vehicel`: unknown field `vehicel`"),
            "{msg}"
        );
    }

    #[test]
    fn a_wrong_type_is_named_with_its_line() {
        let msg = parse_error("# comment\n[arcs]\ncount = \"many\"\n");
        assert_eq!(
            msg,
            "test.toml, line 3, `arcs.count`: invalid type: string \"many\", expected usize"
        );
    }

    #[test]
    fn an_out_of_range_value_is_named() {
        let msg = parse_error("[vehicle]\nwidth_m = -2.0\n");
        assert_eq!(
            msg,
            "test.toml: invalid configuration: `vehicle.width_m`: is -2, must be a finite number > 0"
        );
    }

    #[test]
    fn a_contradictory_value_names_both_keys() {
        let msg = parse_error("[vehicle]\nmin_turning_radius_m = 9.0\n");
        assert!(
            msg.starts_with("test.toml: invalid configuration: `arcs.min_radius_m`: is 8 m, tighter than the vehicle's minimum turning radius (vehicle.min_turning_radius_m = 9 m)"),
            "{msg}"
        );
    }

    #[test]
    fn a_perception_region_smaller_than_the_map_window_is_refused() {
        let msg = parse_error("[localmap]\nahead_m = 30.0\n");
        assert!(
            msg.starts_with("test.toml: invalid configuration: `perception.region.ahead_m`: is 22 m, less than localmap.ahead_m (30 m)"),
            "{msg}"
        );
        let msg = parse_error("[perception.region]\nbehind_m = 5.0\n");
        assert!(
            msg.contains("`perception.region.behind_m`: is 5 m, less than localmap.behind_m (6 m)"),
            "{msg}"
        );
        Config::from_toml(
            "[localmap]\nahead_m = 30.0\n[perception.region]\nahead_m = 32.0\n",
            "test.toml",
        )
        .unwrap();
    }

    #[test]
    fn a_perception_threshold_laxer_than_the_vehicle_is_refused() {
        let msg = parse_error("[vehicle]\ntolerated_step_m = 0.15\n");
        assert!(
            msg.starts_with("test.toml: invalid configuration: `perception.cells.max_height_variation_m`: is 0.2, more than vehicle.tolerated_step_m (0.15)"),
            "{msg}"
        );
    }

    #[test]
    fn an_unknown_sensor_preset_is_named() {
        let msg = parse_error("[sensor]\npreset = \"velodyne\"\n");
        assert!(
            msg.starts_with(
                "test.toml, line 2, `sensor.preset`: unknown variant `velodyne`, expected one of"
            ),
            "{msg}"
        );
    }

    #[test]
    fn an_unknown_behaviour_lists_the_known_ones() {
        let msg = parse_error("[behaviours.wall_follower]\ngain = 2.0\n");
        assert_eq!(
            msg,
            "test.toml: invalid configuration: `behaviours.wall_follower`: unknown behaviour \"wall_follower\" (known: goal_seeking, obstacle_avoidance)"
        );
    }

    #[test]
    fn a_bad_behaviour_key_is_named() {
        let msg = parse_error("[behaviours.goal_seeking]\nlookahed_m = 3.0\n");
        assert!(
            msg.starts_with("test.toml: invalid configuration: `behaviours.goal_seeking.lookahed_m`: unknown field `lookahed_m`"),
            "{msg}"
        );
    }

    #[test]
    fn a_behaviour_table_changes_only_its_keys_and_the_others_stay() {
        let config =
            Config::from_toml("[behaviours.goal_seeking]\nlookahead_m = 14.0\n", "t").unwrap();
        let goal = &config.behaviours["goal_seeking"];
        assert_eq!(goal["lookahead_m"].as_float(), Some(14.0));
        assert_eq!(goal["arrival_radius_m"].as_float(), Some(5.0));
        assert!(config.behaviours.contains_key("obstacle_avoidance"));
    }

    #[test]
    fn a_syntax_error_gives_the_line() {
        let msg = parse_error("[vehicle]\nwidth_m = \n");
        assert!(msg.starts_with("test.toml, line 2"), "{msg}");
    }

    #[test]
    fn a_missing_file_is_named() {
        let err = Config::load(Path::new("/nonexistent/arcnav.toml")).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("cannot read configuration file /nonexistent/arcnav.toml")
        );
    }

    #[test]
    fn partial_files_keep_the_other_defaults() {
        let config = Config::from_toml("[arcs]\ncount = 41\n", "t").unwrap();
        assert_eq!(config.arcs.count, 41);
        assert_eq!(config.vehicle, VehicleConfig::default());
    }

    #[test]
    fn a_weight_or_required_name_that_is_no_configured_behaviour_is_refused() {
        let msg = parse_error("[arbiter.weights]\nobstacle_avoidence = 0.0\n");
        assert_eq!(
            msg,
            "test.toml: invalid configuration: `arbiter.weights.obstacle_avoidence`: \
             \"obstacle_avoidence\" is not a configured behaviour (configured: goal_seeking, obstacle_avoidance)"
        );
        let msg = parse_error("[arbiter]\nrequired = [\"goal_seekin\"]\n");
        assert!(
            msg.contains("`arbiter.required`: \"goal_seekin\" is not a configured behaviour"),
            "{msg}"
        );
    }

    #[test]
    fn a_weights_table_changes_only_the_weights_it_names() {
        let config = Config::from_toml("[arbiter.weights]\ngoal_seeking = 0.8\n", "t").unwrap();
        assert_eq!(config.arbiter.weight("goal_seeking"), 0.8);
        assert_eq!(config.arbiter.weight("obstacle_avoidance"), 1.0);
    }

    #[test]
    fn a_cruise_speed_above_the_vehicles_top_speed_is_refused() {
        let msg = parse_error("[arbiter]\ncruise_speed_mps = 12.0\n");
        assert!(
            msg.contains("`arbiter.cruise_speed_mps`: is 12 m/s, faster than the vehicle's top speed (vehicle.max_speed_mps = 10 m/s)"),
            "{msg}"
        );
    }

    #[test]
    fn behaviours_are_built_from_the_tables_checked_at_load_and_follow_later_edits() {
        let mut config =
            Config::from_toml("[behaviours.goal_seeking]\nlookahead_m = 14.0\n", "t").unwrap();
        let registry = Registry::builtin();
        let arcs = config.arc_set().unwrap();
        assert_eq!(config.build_behaviours(&registry, &arcs).unwrap().len(), 2);
        // A table changed in code is checked when built.
        config
            .behaviours
            .get_mut("goal_seeking")
            .unwrap()
            .insert("lookahed_m".into(), toml::Value::Float(3.0));
        let err = config.build_behaviours(&registry, &arcs).err().unwrap();
        assert_eq!(err.key, "behaviours.goal_seeking.lookahed_m");
    }
}
