//! The resolved configuration: the given one checked once, with what
//! follows from it derived once, and the nodes built from it.
//!
//! Resolving is: check every section as given → derive (the cruise speed
//! the hole speed cap allows, the arc set at that speed, how far the
//! vehicle looks ahead, the speed bound and where holes show) → put the
//! derived values in place and check them as keys are checked → freeze.
//! Every node, executor, report and picture is built from the one
//! [`Resolved`] value; nothing after it reads TOML or derives again.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arcnav_arbiter::{Arbiter, ArbiterConfig};
use arcnav_behaviours::{
    Behaviour, ObstacleAvoidanceConfig, Prepared, Registry, RegistryError, Setup,
};
use arcnav_localmap::{LocalMapConfig, StaticMap};
use arcnav_perception::{PerceptionConfig, SensorModel};
use arcnav_pipeline::{
    BehaviourSet, DecisionCycle, Delivery, ExternalConfig, Latency, LiveConfig, LocalMapNode,
    PerceptionNode, Pipeline, PipelineConfig,
};
use arcnav_sim::SimConfig;
use arcnav_vehicle::mission::{Area, AreaSetting, AreaSpec, Mission, WhenUnreachable};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{ArcSet, ConfigError, VehicleConfig};

use crate::bus::BusConfig;
use crate::file::{Config, ConfigLoadError, Origin};
use crate::lookahead::Lookahead;
use crate::speed_bound::{self, SpeedBound};

/// The name of the behaviour whose stopping model sets how far ahead the
/// vehicle looks.
const OBSTACLE_AVOIDANCE: &str = "obstacle_avoidance";

/// The cruise speed: the one asked for and the one driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cruise {
    /// What `arbiter.cruise_speed_mps` asks for, m/s.
    pub asked_mps: f64,
    /// The hole speed cap (`[lookahead] hole_speed_cap`), when it is on and
    /// drop-offs are suspected, m/s.
    pub cap_mps: Option<f64>,
    /// The speed the arbiter drives at when nothing asks for less, and that
    /// everything looking ahead is derived for: the asked speed, held to
    /// the cap, m/s.
    pub mps: f64,
}

impl Cruise {
    /// Whether the cap held the asked speed down.
    pub fn capped(&self) -> bool {
        self.mps < self.asked_mps
    }
}

/// A value set by derivation, for `arcnav config` to say so.
#[derive(Debug, Clone, PartialEq)]
pub struct Derivation {
    /// The dotted key it stands in for.
    pub key: String,
    /// What it was derived from.
    pub from: String,
}

/// The configuration every node is built from: checked once, derived once,
/// frozen. See the module documentation.
#[derive(Debug, Clone)]
pub struct Resolved {
    given: Config,
    pub vehicle: VehicleConfig,
    /// The arcs, `driven_paths = "auto"` decided at the driven cruise speed.
    pub arcs: ArcSet,
    /// The vehicle's sensors (`[[sensors]]`, or `[sensor]`).
    pub sensors: Vec<SensorModel>,
    /// `[perception]`, its region and range as far as the vehicle looks.
    pub perception: PerceptionConfig,
    /// `[localmap]`, its window as far as the vehicle looks and
    /// `hole_range_m` from the sensor unless given.
    pub localmap: LocalMapConfig,
    /// `[arbiter]` as given; it drives at [`Cruise::mps`].
    pub arbiter: ArbiterConfig,
    pub pipeline: PipelineConfig,
    pub live: LiveConfig,
    pub bus: BusConfig,
    pub sim: SimConfig,
    /// `[guard]` as given.
    pub guard: arcnav_guard::GuardConfig,
    /// `[mission]` checked: the operating area asked for, and what to do
    /// with an unreachable waypoint.
    pub mission: Mission,
    /// The simulated world's operating area, once [`Resolved::in_world`]
    /// gave it (what `area = "world"` stands for).
    world_area: Option<Area>,
    pub cruise: Cruise,
    pub lookahead: Lookahead,
    pub speed_bound: SpeedBound,
    behaviours: BTreeMap<String, Prepared>,
    /// `[behaviours.external.NAME]`: behaviours that are programs of their
    /// own (lock-step executors start them; live, they are on the bus).
    pub external: BTreeMap<String, ExternalConfig>,
    statics: Option<Arc<StaticMap>>,
    /// The image a `.yaml` occupancy map names, if any.
    occupancy_image: Option<PathBuf>,
    derived: Vec<Derivation>,
}

impl Resolved {
    /// Checks `given` once and derives what follows from it (the module
    /// documentation says what, in which order).
    pub(crate) fn new(given: Config, registry: &Registry) -> Result<Self, ConfigError> {
        let (sensors, mission) = given.validate_sections()?;
        let (statics, occupancy_image) = static_map(&given)?;
        let cap = if given.lookahead.hole_speed_cap {
            speed_bound::hole_speed_cap(&given, &sensors)
        } else {
            None
        };
        let asked = given.arbiter.cruise_speed_mps;
        let cruise = Cruise {
            asked_mps: asked,
            cap_mps: cap,
            mps: cap.map_or(asked, |cap| asked.min(cap)),
        };
        let arcs = ArcSet::for_cruise(&given.arcs, cruise.mps).map_err(|e| e.within("arcs"))?;
        let mut behaviours = {
            let setup = setup(
                &arcs,
                &given.vehicle,
                &given.localmap,
                statics.as_ref(),
                cruise.mps,
            );
            given
                .behaviour_tables()
                .map(|(name, table)| {
                    registry
                        .prepare(name, table, &setup)
                        .map(|p| (name.clone(), p))
                        .map_err(|e| behaviour_error(name, e))
                })
                .collect::<Result<BTreeMap<_, _>, _>>()?
        };
        let external = given.external_behaviours()?;
        given.arbiter_names_behaviours(&external)?;
        let avoidance = behaviours
            .get(OBSTACLE_AVOIDANCE)
            .and_then(Prepared::config::<ObstacleAvoidanceConfig>)
            .cloned()
            .unwrap_or_default();
        let lookahead = Lookahead::derive(&given, &avoidance, &sensors, &arcs, cruise.mps);
        let speed_bound = speed_bound::speed_bound(&given, &sensors, lookahead.map_ahead_m)?;

        let InPlace {
            localmap,
            perception,
            avoidance: oa,
            mut derived,
        } = in_place(&given, &avoidance, &cruise, &lookahead, &speed_bound);
        let mut pipeline = given.pipeline.clone();
        if pipeline.perception_latency_s == Latency::Auto && !sensors.is_empty() {
            pipeline.perception_latency_s =
                Latency::Seconds(speed_bound::perception_latency_s(&given, &sensors));
            derived.push(Derivation {
                key: "pipeline.perception_latency_s".into(),
                from: "\"auto\": the slowest sensor's latency_s (its acquisition and processing)"
                    .into(),
            });
        }
        // The derived values are checked as the keys they stand in for.
        let as_derived =
            |e: ConfigError| ConfigError::new(e.key, format!("(derived) {}", e.reason));
        perception
            .validate_for(&given.vehicle)
            .map_err(|e| as_derived(e.within("perception")))?;
        localmap
            .validate()
            .map_err(|e| as_derived(e.within("localmap")))?;
        if oa != avoidance
            && let Some(prepared) = behaviours.get_mut(OBSTACLE_AVOIDANCE)
        {
            let setup = setup(
                &arcs,
                &given.vehicle,
                &localmap,
                statics.as_ref(),
                cruise.mps,
            );
            *prepared = prepared
                .with_config(oa, &setup)
                .map_err(|e| as_derived(e.within("behaviours.obstacle_avoidance")))?;
        }
        Ok(Self {
            vehicle: given.vehicle.clone(),
            arcs,
            sensors,
            perception,
            localmap,
            arbiter: given.arbiter.clone(),
            pipeline,
            live: given.live.clone(),
            bus: given.bus.clone(),
            sim: given.sim.clone(),
            guard: given.guard.clone(),
            mission,
            world_area: None,
            cruise,
            lookahead,
            speed_bound,
            behaviours,
            external,
            statics,
            occupancy_image,
            derived,
            given,
        })
    }

    /// Loads, parses and resolves a TOML file (missing keys keep their
    /// defaults); errors name the file.
    pub fn load(path: &Path, registry: &Registry) -> Result<Self, ConfigLoadError> {
        resolved_as(Config::load(path)?, registry, &path.display().to_string())
    }

    /// Loads `path` if given, else resolves the defaults.
    pub fn load_or_default(
        path: Option<&Path>,
        registry: &Registry,
    ) -> Result<Self, ConfigLoadError> {
        match path {
            Some(path) => Self::load(path, registry),
            None => resolved_as(Config::default(), registry, "the defaults"),
        }
    }

    /// Parses and resolves TOML text; `origin` names it in messages.
    pub fn from_toml(
        text: &str,
        origin: &str,
        registry: &Registry,
    ) -> Result<Self, ConfigLoadError> {
        resolved_as(Config::parse(text, origin)?, registry, origin)
    }

    /// The configuration as given (defaults, file, command line): what a
    /// run records so that it can be run again. Nodes are built from the
    /// resolved fields, never from this.
    pub fn given(&self) -> &Config {
        &self.given
    }

    /// Every file this configuration reads, each named by what it is
    /// ([`Config::files_read`] and the image a `.yaml` occupancy map
    /// names): a run refuses to write an output onto any of them.
    pub fn files_read(&self) -> Vec<(&'static str, PathBuf)> {
        let mut files = self.given.files_read();
        files.extend(
            self.occupancy_image
                .clone()
                .map(|p| ("the occupancy map's image", p)),
        );
        files
    }

    /// The values derivation set, each with what it was derived from.
    pub fn derivations(&self) -> &[Derivation] {
        &self.derived
    }

    /// Where `key`'s value came from, in words: a file, a command-line
    /// option, a derivation, or the defaults.
    pub fn origin(&self, key: &str) -> String {
        let given = match self.given.origin(key) {
            Some(origin @ (Origin::File(_) | Origin::CommandLine(_))) => origin.to_string(),
            None => "default".into(),
        };
        match self.derived.iter().find(|d| d.key == key) {
            Some(d) => format!("{given}; derived: {}", d.from),
            None => given,
        }
    }

    /// The static occupancy map `[localmap.occupancy]` names, read once.
    pub fn static_map(&self) -> Option<&Arc<StaticMap>> {
        self.statics.as_ref()
    }

    /// The configured behaviours' names, in order.
    pub fn behaviour_names(&self) -> impl Iterator<Item = &str> {
        self.behaviours.keys().map(String::as_str)
    }

    /// Behaviour `name`'s configuration, typed, as it is built (derived
    /// values in place); `None` when it is not configured or not a `C`.
    pub fn behaviour_config<C: 'static>(&self, name: &str) -> Option<&C> {
        self.behaviours.get(name)?.config::<C>()
    }

    /// What behaviours are built with.
    pub fn setup(&self) -> Setup<'_> {
        Setup {
            area: self.area(),
            unreachable: self.mission.unreachable,
            ..setup(
                &self.arcs,
                &self.vehicle,
                &self.localmap,
                self.statics.as_ref(),
                self.cruise.mps,
            )
        }
    }

    /// The operating area the vehicle keeps to: the polygon `[mission]
    /// area` gives, or the simulated world's for `"world"` once
    /// [`Resolved::in_world`] gave it; `None`: anywhere.
    pub fn area(&self) -> Option<&Area> {
        self.mission.area(self.world_area.as_ref())
    }

    /// This configuration in a simulated world whose operating area is
    /// `area` (its map less `[mission] area_margin_m`, or its own
    /// polygon): `area = "world"` becomes that polygon, in the
    /// configuration as given too, so that the `config.toml` a run writes
    /// replays in the same area. Nothing is parsed or checked again.
    /// Borrowed as it is when the area is not the world's (a polygon, or
    /// none).
    #[must_use]
    pub fn in_world(&self, area: &Area) -> std::borrow::Cow<'_, Self> {
        if self.mission.area != AreaSetting::World {
            return std::borrow::Cow::Borrowed(self);
        }
        let mut config = self.clone();
        config.world_area = Some(area.clone());
        config.given.mission.area = AreaSpec::Vertices(area.vertices().to_vec());
        std::borrow::Cow::Owned(config)
    }

    /// Builds the configured behaviour `name` (`None`: not configured).
    pub fn build_behaviour(&self, name: &str) -> Option<Box<dyn Behaviour>> {
        Some(self.behaviours.get(name)?.build(&self.setup()))
    }

    /// Builds every configured behaviour (in name order).
    pub fn build_behaviours(&self) -> Vec<Box<dyn Behaviour>> {
        let setup = self.setup();
        self.behaviours.values().map(|p| p.build(&setup)).collect()
    }

    /// The configured behaviours, voting over the arcs.
    pub fn behaviour_set(&self) -> BehaviourSet {
        BehaviourSet::new(self.build_behaviours(), self.arcs.clone())
    }

    /// The perception node, from `[perception]` (looking as far as the
    /// vehicle does) and `[pipeline]`.
    pub fn perception_node(&self) -> Result<PerceptionNode, ConfigError> {
        PerceptionNode::new(&self.perception, &self.pipeline).map_err(|e| e.within("perception"))
    }

    /// The local map and its cycle clock, from `[localmap]`, the vehicle's
    /// top speed and `[pipeline]`, with reports delivered as `delivery` says.
    pub fn decision_cycle<T>(&self, delivery: Delivery) -> DecisionCycle<T> {
        let mut map = LocalMapNode::new(&self.localmap, &self.vehicle);
        if let Some(statics) = &self.statics {
            map.map.set_static_map(Arc::clone(statics));
        }
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

    /// The DAMN arbiter, from `[arbiter]`, the arcs and the vehicle,
    /// driving at the cruise speed [`Cruise::mps`].
    pub fn arbiter(&self) -> Arbiter {
        Arbiter::new(&self.arbiter, self.arcs.clone(), &self.vehicle).cruising_at(self.cruise.mps)
    }

    /// The lock-step executor with every node of this configuration.
    pub fn lockstep(&self) -> Result<Pipeline, ConfigError> {
        let mut pipeline = Pipeline::new(
            self.perception_node()?,
            self.decision_cycle(Delivery::held(&self.pipeline)),
            self.behaviour_set(),
            self.arbiter(),
        );
        pipeline.inject(
            self.pipeline.fault,
            seconds_to_micros(self.pipeline.fault_after_s),
        );
        Ok(pipeline)
    }

    /// The behaviours whose votes complete a cycle: every configured one
    /// (built in or external) with a positive weight.
    pub fn expected_behaviours(&self) -> Vec<String> {
        self.behaviours
            .keys()
            .chain(self.external.keys())
            .filter(|name| self.arbiter.weight(name) > 0.0)
            .cloned()
            .collect()
    }

    /// The configuration as it is built, as a [`Config`]: the given one
    /// with every derived value in place. It resolves to the same
    /// configuration again.
    pub fn effective(&self) -> Config {
        let mut config = self.given.clone();
        config.localmap = self.localmap.clone();
        config.perception = self.perception.clone();
        config.pipeline = self.pipeline.clone();
        for (name, prepared) in &self.behaviours {
            config
                .behaviours
                .insert(name.clone(), prepared.table().clone());
        }
        config
    }
}

/// Resolving, on the file's value (defined here, beside what it builds, so
/// that the file's module does not import the resolved one).
impl Config {
    /// Checks this configuration once and derives what follows from it:
    /// the configuration every node is built from.
    pub fn resolve(self, registry: &Registry) -> Result<Resolved, ConfigError> {
        Resolved::new(self, registry)
    }

    /// [`Config::resolve`] with the built-in behaviours, leaving this
    /// configuration as it is (for one changed in code).
    pub fn resolved(&self) -> Result<Resolved, ConfigError> {
        self.clone().resolve(&Registry::builtin())
    }
}

impl Default for Resolved {
    /// The built-in defaults with the built-in behaviours, resolved. They
    /// always resolve (a test holds that `config/default.toml` does).
    fn default() -> Self {
        Config::default()
            .resolve(&Registry::builtin())
            .expect("the built-in defaults resolve")
    }
}

/// The sections as they are built: the given local map, perception and
/// obstacle avoidance with the derived values in place, and what derived
/// each.
struct InPlace {
    localmap: LocalMapConfig,
    perception: PerceptionConfig,
    avoidance: ObstacleAvoidanceConfig,
    derived: Vec<Derivation>,
}

/// Puts what `cruise`, `lookahead` and the speed `bound` derive in place of
/// the given values (the module documentation says which).
fn in_place(
    given: &Config,
    avoidance: &ObstacleAvoidanceConfig,
    cruise: &Cruise,
    lookahead: &Lookahead,
    bound: &SpeedBound,
) -> InPlace {
    let mut derived = Vec::new();
    let mut derive = |key: &str, from: String| {
        derived.push(Derivation {
            key: key.to_owned(),
            from,
        })
    };
    if cruise.capped() {
        derive(
            "arbiter.cruise_speed_mps",
            format!(
                "driven at {:.2} m/s: lookahead.hole_speed_cap holds it to the speed from \
                 which the vehicle stops within {:.1} m, where a hole the wheels do not \
                 bridge is first suspected",
                cruise.mps,
                bound.suspect_range_m.unwrap_or_default()
            ),
        );
    }
    let mut localmap = given.localmap.clone();
    let mut perception = given.perception.clone();
    let mut oa = avoidance.clone();
    if localmap.hole_range_m == 0.0
        && let Some(range) = bound.hole_grazed_m
    {
        localmap.hole_range_m = range;
        derive(
            "localmap.hole_range_m",
            "given as 0: where the sensor's ray grazing a hole's edge flags it \
             (speed bound's hole_grazed_m)"
                .into(),
        );
    }
    if perception.evidence.verify
        && let Some(bound) = bound.suspect_bound_mps
        && cruise.mps <= bound
    {
        perception.evidence.verify = false;
        derive(
            "perception.evidence.verify",
            format!(
                "at {:.2} m/s one image suspects a hole in time (speed bound's \
                 suspect_bound_mps {bound:.2}): no ground need be verified over images",
                cruise.mps
            ),
        );
    }
    if perception.evidence.verified_within_m == 0.0
        && let Some(range) = bound.suspect_range_m
    {
        perception.evidence.verified_within_m = range;
        derive(
            "perception.evidence.verified_within_m",
            "given as 0: where one image is certain to suspect a hole the wheels do not \
             bridge (speed bound's suspect_range_m)"
                .into(),
        );
    }
    if oa.governor_reaction_s == 0.0 {
        oa.governor_reaction_s = bound.reaction_s;
        derive(
            "behaviours.obstacle_avoidance.governor_reaction_s",
            "given as 0: from image to effect (speed bound's reaction_s: acquisition, \
             perception latency, command period, actuation)"
                .into(),
        );
    }
    if oa.hole_seen_within_m == 0.0
        && let Some(within) = bound.hole_seen_within_m
    {
        oa.hole_seen_within_m = within;
        derive(
            "behaviours.obstacle_avoidance.hole_seen_within_m",
            "given as 0: hole_grazed_m less the sensor's setback from the front".into(),
        );
    }
    if lookahead.moved_m > 0.0 {
        let why = format!(
            "{:.1} m farther than given: at {:.2} m/s a clear arc allows cruise {:.1} m along \
             (lookahead.from_speed)",
            lookahead.moved_m, cruise.mps, lookahead.needed_m
        );
        localmap.ahead_m = lookahead.map_ahead_m;
        perception.region.ahead_m = lookahead.region_ahead_m;
        perception.max_range_m = lookahead.max_range_m;
        oa.max_distance_m = lookahead.max_distance_m;
        for key in [
            "localmap.ahead_m",
            "perception.region.ahead_m",
            "perception.max_range_m",
            "behaviours.obstacle_avoidance.max_distance_m",
        ] {
            derive(key, why.clone());
        }
        if lookahead.widened_m > 0.0 {
            let why = format!(
                "{:.1} m wider than given: the widest arc's reach at the speed it is driven",
                lookahead.widened_m
            );
            localmap.half_width_m = lookahead.map_half_width_m;
            perception.region.half_width_m = lookahead.region_half_width_m;
            for key in ["localmap.half_width_m", "perception.region.half_width_m"] {
                derive(key, why.clone());
            }
        }
    }
    InPlace {
        localmap,
        perception,
        avoidance: oa,
        derived,
    }
}

/// `config` resolved, its errors naming `origin`.
fn resolved_as(
    config: Config,
    registry: &Registry,
    origin: &str,
) -> Result<Resolved, ConfigLoadError> {
    config
        .resolve(registry)
        .map_err(|source| ConfigLoadError::Invalid {
            origin: origin.to_owned(),
            source,
        })
}

/// What behaviours are prepared and built with.
fn setup<'a>(
    arcs: &'a ArcSet,
    vehicle: &'a VehicleConfig,
    localmap: &'a LocalMapConfig,
    statics: Option<&'a Arc<StaticMap>>,
    cruise_mps: f64,
) -> Setup<'a> {
    Setup {
        arcs,
        vehicle,
        localmap,
        statics,
        cruise_mps,
        area: None,
        unreachable: WhenUnreachable::default(),
    }
}

/// The static occupancy map `[localmap.occupancy]` names, gathered onto the
/// local map's patches.
/// Also the image file a `.yaml` map names.
fn static_map(config: &Config) -> Result<StaticMapRead, ConfigError> {
    let occupancy = &config.localmap.occupancy;
    let Some((grid, image)) = crate::occupancy::load(occupancy)
        .map_err(|e| ConfigError::new("localmap.occupancy.file", e.to_string()))?
    else {
        return Ok((None, None));
    };
    let map = StaticMap::from_grid(&grid, config.localmap.patch_size_m).map_err(|e| {
        ConfigError::new(
            "localmap.occupancy.file",
            format!("occupancy map {}: {e}", occupancy.file),
        )
    })?;
    let map = Some(Arc::new(map));
    if let Some(m) = &map {
        tracing::info!(
            file = %occupancy.file,
            patches = m.len(),
            "static occupancy map merged into the local map"
        );
    }
    Ok((map, image))
}

/// The static map [`static_map`] reads and the image file it names.
type StaticMapRead = (Option<Arc<StaticMap>>, Option<PathBuf>);

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
