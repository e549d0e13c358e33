//! `arcnav sweep`: the same mission on many worlds under many settings, as
//! one table.
//!
//! A sweep is a [`Plan`]: worlds × settings, each setting one combination
//! of the values given for each swept configuration key (`--set
//! arbiter.cruise_speed_mps=2.5,4,6`, or a grid file). Every pair is a
//! run, numbered in plan order (world-major); a run's outcome is a [`Row`].
//! Rows are appended to `rows.jsonl` as runs finish, in any order, so an
//! interrupted sweep loses only the runs under way; the tables are written
//! in plan order, so the same plan gives the same tables (every column but
//! `wall_time_s`, the one thing a machine's load changes).
//!
//! On a cluster a plan is split into [`Shard`]s, `--shard K/N` running the
//! runs whose number is K − 1 modulo N (interleaved, so each shard has a
//! share of every world and setting); the shards' directories are then
//! joined into one sweep by [`merge`], which refuses directories of
//! different plans, a shard given twice and shards missing.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arcnav_behaviours::Registry;
use arcnav_sim::World;
use serde::{Deserialize, Serialize};

use crate::mission::MissionReport;
use arcnav_config::{Config, ConfigLoadError, Resolved};

/// Settings a sweep may hold (the product of every key's values).
pub const MAX_SETTINGS: usize = 10_000;

/// Parts a plan may be split into.
pub const MAX_SHARDS: usize = 100_000;

/// The `index`-th (from 1) of `count` parts of a plan: the runs whose
/// number is `index − 1` modulo `count`.
///
/// In `sweep.json` it is its `K/N` text, read back through [`Shard::parse`]
/// (a shard of 0 parts had divided by zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// The whole plan.
    pub const WHOLE: Shard = Shard { index: 1, count: 1 };

    /// `K/N`.
    pub fn parse(text: &str) -> Result<Self, SweepError> {
        let bad = || SweepError::BadShard(text.to_owned());
        let (k, n) = text.trim().split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse::<usize>().map_err(|_| bad())?,
            n.trim().parse::<usize>().map_err(|_| bad())?,
        );
        if index == 0 || index > count || count > MAX_SHARDS {
            return Err(bad());
        }
        Ok(Self { index, count })
    }

    /// Whether run `run` is this shard's.
    pub fn holds(&self, run: usize) -> bool {
        run % self.count == self.index - 1
    }

    /// How many runs of a plan of `runs` this shard holds (counted, not
    /// walked: a plan's size may come from a file).
    pub fn held(&self, runs: usize) -> usize {
        runs.saturating_sub(self.index - 1).div_ceil(self.count)
    }

    /// This shard's runs of a plan of `runs`, in order.
    pub fn runs(&self, runs: usize) -> impl Iterator<Item = usize> + '_ {
        (self.index - 1..runs).step_by(self.count)
    }
}

impl TryFrom<String> for Shard {
    type Error = SweepError;

    fn try_from(text: String) -> Result<Self, SweepError> {
        Self::parse(&text)
    }
}

impl From<Shard> for String {
    fn from(shard: Shard) -> String {
        shard.to_string()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A sweep that cannot be run.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("--set {0:?}: expected KEY=VALUE[,VALUE…], e.g. arbiter.cruise_speed_mps=2.5,4")]
    BadSet(String),
    #[error("`{key}`: no such key in the configuration (`arcnav config` lists them all)")]
    NoKey { key: String },
    #[error("`{key}` = {value}: {reason}")]
    BadValue {
        key: String,
        value: String,
        reason: String,
    },
    #[error("`{key}` is swept over no values: give at least one")]
    NoValues { key: String },
    #[error("`{key}` is swept twice")]
    Twice { key: String },
    #[error("the grid holds {0} settings, more than {MAX_SETTINGS}")]
    TooMany(usize),
    #[error("grid file {}: {reason}", path.display())]
    GridFile { path: PathBuf, reason: String },
    #[error(
        "--shard {0:?}: expected K/N, the K-th of N parts (1 ≤ K ≤ N ≤ {MAX_SHARDS}), e.g. 2/8"
    )]
    BadShard(String),
    #[error("setting {label}: {source}")]
    Invalid {
        label: String,
        source: ConfigLoadError,
    },
}

/// One swept key and its values, in the order given.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    pub key: String,
    pub values: Vec<toml::Value>,
}

/// Parses `KEY=V1,V2,…`. Values are TOML scalars (`4`, `2.5`, `true`,
/// `"slow"`); a bare word is taken as a string where the key holds one.
pub fn parse_set(arg: &str) -> Result<(String, Vec<String>), SweepError> {
    let (key, values) = arg
        .split_once('=')
        .ok_or_else(|| SweepError::BadSet(arg.to_owned()))?;
    let key = key.trim();
    if key.is_empty() {
        return Err(SweepError::BadSet(arg.to_owned()));
    }
    let values: Vec<String> = values
        .split(',')
        .map(str::trim)
        .filter(|v| !v.is_empty())
        .map(str::to_owned)
        .collect();
    if values.is_empty() {
        return Err(SweepError::NoValues {
            key: key.to_owned(),
        });
    }
    Ok((key.to_owned(), values))
}

/// Reads a grid file: top-level keys naming configuration keys (quoted,
/// `"arbiter.cruise_speed_mps" = [2.5, 4.0]`), each an array of values.
pub fn read_grid(path: &Path) -> Result<Vec<(String, Vec<toml::Value>)>, SweepError> {
    let error = |reason: String| SweepError::GridFile {
        path: path.to_owned(),
        reason,
    };
    let text = arcnav_vehicle::files::read_text(path).map_err(|e| error(e.to_string()))?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| error(e.message().to_owned()))?;
    if table.is_empty() {
        return Err(error(
            "lists no keys; write `\"arbiter.cruise_speed_mps\" = [2.5, 4.0]`".into(),
        ));
    }
    table
        .into_iter()
        .map(|(key, value)| match value {
            toml::Value::Array(values) if values.is_empty() => Err(SweepError::NoValues { key }),
            toml::Value::Array(values) => Ok((key, values)),
            other => Err(error(format!(
                "`{key}` is {}, not an array of values (write `\"{key}\" = [{other}]`)",
                other.type_str()
            ))),
        })
        .collect()
}

/// The value `text` means for a key now holding `current`: TOML, with
/// integers taken as floats where the key is a float and bare words as
/// strings where it is a string.
fn typed(current: &toml::Value, text: &str) -> Result<toml::Value, String> {
    let parsed = toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"));
    match (current, parsed) {
        (toml::Value::String(_), None) => Ok(toml::Value::String(text.to_owned())),
        (_, None) => Err(format!("not a value (expected {})", current.type_str())),
        (current, Some(value)) => coerce(current, value),
    }
}

/// `value` as the type of `current`, where that is lossless.
fn coerce(current: &toml::Value, value: toml::Value) -> Result<toml::Value, String> {
    match (current, value) {
        (toml::Value::Table(_), _) => Err("is a table: sweep one of its keys".into()),
        (toml::Value::Float(_), toml::Value::Integer(i)) => Ok(toml::Value::Float(i as f64)),
        (c, v) if c.same_type(&v) => Ok(v),
        (c, v) => Err(format!(
            "is {}, the key takes {}",
            v.type_str(),
            c.type_str()
        )),
    }
}

/// `base` with `key` (dotted) set to `value`; the key must exist.
fn assign(base: &mut toml::Table, key: &str, value: toml::Value) -> Result<(), SweepError> {
    let no_key = || SweepError::NoKey {
        key: key.to_owned(),
    };
    let mut parts = key.split('.').peekable();
    let mut table = base;
    while let Some(part) = parts.next() {
        if parts.peek().is_none() {
            let slot = table.get_mut(part).ok_or_else(no_key)?;
            *slot = coerce(slot, value.clone()).map_err(|reason| SweepError::BadValue {
                key: key.to_owned(),
                value: value.to_string(),
                reason,
            })?;
            return Ok(());
        }
        table = table
            .get_mut(part)
            .and_then(toml::Value::as_table_mut)
            .ok_or_else(no_key)?;
    }
    Err(no_key())
}

/// The value `key` holds in `table`, if it exists.
fn lookup<'t>(table: &'t toml::Table, key: &str) -> Option<&'t toml::Value> {
    let (path, last) = key.rsplit_once('.').unwrap_or(("", key));
    let mut table = table;
    for part in path.split('.').filter(|p| !p.is_empty()) {
        table = table.get(part)?.as_table()?;
    }
    table.get(last)
}

/// The axis of `key` over `given` values, each typed against the value the
/// key holds in `table` by `value` (and shown as `shown` when it cannot be).
fn axis<T>(
    table: &toml::Table,
    key: &str,
    given: &[T],
    shown: impl Fn(&T) -> String,
    value: impl Fn(&toml::Value, &T) -> Result<toml::Value, String>,
) -> Result<Axis, SweepError> {
    let current = lookup(table, key).ok_or_else(|| SweepError::NoKey {
        key: key.to_owned(),
    })?;
    let values = given
        .iter()
        .map(|g| {
            value(current, g).map_err(|reason| SweepError::BadValue {
                key: key.to_owned(),
                value: shown(g),
                reason,
            })
        })
        .collect::<Result<_, _>>()?;
    Ok(Axis {
        key: key.to_owned(),
        values,
    })
}

/// The axes of `--set` arguments and grid entries, values typed by the
/// keys of `base`.
pub fn axes(
    base: &Config,
    sets: &[(String, Vec<String>)],
    grid: &[(String, Vec<toml::Value>)],
) -> Result<Vec<Axis>, SweepError> {
    let table: toml::Table = toml::from_str(&base.to_toml()).unwrap_or_default();
    let axes = sets
        .iter()
        .map(|(key, texts)| axis(&table, key, texts, String::clone, |c, t| typed(c, t)))
        .chain(grid.iter().map(|(key, values)| {
            axis(&table, key, values, toml::Value::to_string, |c, v| {
                coerce(c, v.clone())
            })
        }))
        .collect::<Result<Vec<_>, _>>()?;
    for (i, axis) in axes.iter().enumerate() {
        if axes[..i].iter().any(|a| a.key == axis.key) {
            return Err(SweepError::Twice {
                key: axis.key.clone(),
            });
        }
    }
    let count = axes
        .iter()
        .try_fold(1usize, |n, a| n.checked_mul(a.values.len()))
        .unwrap_or(usize::MAX);
    if count > MAX_SETTINGS {
        return Err(SweepError::TooMany(count));
    }
    Ok(axes)
}

/// One combination of the axes' values, and the configuration it makes.
#[derive(Debug, Clone)]
pub struct Setting {
    /// The value of each axis, as TOML text.
    pub values: Vec<String>,
    pub config: Resolved,
}

impl Setting {
    /// `key=value, key=value` (`defaults` with no axes).
    pub fn label(&self, axes: &[Axis]) -> String {
        label(axes.iter().map(|a| a.key.as_str()), &self.values)
    }
}

/// The label of the setting with `values` for `keys`: `key=value, …`, or
/// `defaults` when nothing is swept.
fn label<'a>(keys: impl IntoIterator<Item = &'a str>, values: &[String]) -> String {
    let label = keys
        .into_iter()
        .zip(values)
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(", ");
    if label.is_empty() {
        "defaults".into()
    } else {
        label
    }
}

/// Every combination of the axes' values (the last axis varying fastest),
/// each validated as a whole configuration.
pub fn settings(
    base: &Config,
    axes: &[Axis],
    registry: &Registry,
) -> Result<Vec<Setting>, SweepError> {
    let table: toml::Table = toml::from_str(&base.to_toml()).unwrap_or_default();
    let mut combos: Vec<Vec<&toml::Value>> = vec![Vec::new()];
    for axis in axes {
        combos = combos
            .into_iter()
            .flat_map(|prefix| {
                axis.values.iter().map(move |v| {
                    let mut c = prefix.clone();
                    c.push(v);
                    c
                })
            })
            .collect();
    }
    combos
        .into_iter()
        .map(|values| {
            let mut config = table.clone();
            for (axis, value) in axes.iter().zip(&values) {
                assign(&mut config, &axis.key, (*value).clone())?;
            }
            let values: Vec<String> = values.iter().map(|v| v.to_string()).collect();
            let label = label(axes.iter().map(|a| a.key.as_str()), &values);
            // Loading validates the whole configuration.
            let text = toml::to_string(&config).unwrap_or_default();
            let config = Resolved::from_toml(&text, &label, registry)
                .map_err(|source| SweepError::Invalid { label, source })?;
            Ok(Setting { values, config })
        })
        .collect()
}

/// A world of the sweep and what to call it in the table.
#[derive(Debug, Clone)]
pub struct SweepWorld {
    pub label: String,
    pub world: Arc<World>,
}

/// Worlds × settings.
#[derive(Debug, Clone)]
pub struct Plan {
    pub worlds: Vec<SweepWorld>,
    pub axes: Vec<Axis>,
    pub settings: Vec<Setting>,
}

impl Plan {
    pub fn runs(&self) -> usize {
        self.worlds.len() * self.settings.len()
    }

    /// Run `run`'s world and setting.
    pub fn run(&self, run: usize) -> (&SweepWorld, usize, &Setting) {
        let (w, s) = place(run, self.settings.len());
        (&self.worlds[w], s, &self.settings[s])
    }

    /// What identifies the plan: worlds, axes, and every setting's whole
    /// configuration (a resumed sweep must be the same sweep).
    pub fn identity(&self) -> PlanIdentity {
        PlanIdentity {
            shard: None,
            worlds: self.worlds.iter().map(|w| w.label.clone()).collect(),
            world_digests: self.worlds.iter().map(|w| world_digest(&w.world)).collect(),
            keys: self.axes.iter().map(|a| a.key.clone()).collect(),
            settings: self.settings.iter().map(|s| s.values.clone()).collect(),
            configs: self
                .settings
                .iter()
                .map(|s| s.config.given().to_toml())
                .collect(),
        }
    }
}

/// Run `run`'s world and setting indices in a plan of `settings` settings
/// per world (runs are numbered world-major).
fn place(run: usize, settings: usize) -> (usize, usize) {
    (run / settings, run % settings)
}

/// The digest [`PlanIdentity::world_digests`] holds, hex.
fn world_digest(world: &World) -> String {
    use sha2::{Digest, Sha256};
    let mut hash = Sha256::new();
    hash.update(toml::to_string(&world.spec).unwrap_or_default().as_bytes());
    for (what, path) in &world.files_read {
        if *what == "the world file" {
            continue;
        }
        hash.update(path.display().to_string().as_bytes());
        match arcnav_vehicle::files::read_bounded(path, 1 << 30) {
            Ok(bytes) => hash.update(&bytes),
            Err(e) => hash.update(e.to_string().as_bytes()),
        }
    }
    hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Written as `sweep.json`: what a resumed sweep is checked against, and
/// all the tables need (world labels, swept keys, setting values).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanIdentity {
    /// The part of the plan a directory holds (`None`: all of it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    pub worlds: Vec<String>,
    /// SHA-256 of each world as built (its spec, scatter expanded) and of
    /// the height file it reads: a world file changed between the runs of
    /// a sweep is another sweep, not one label over two worlds.
    #[serde(default)]
    pub world_digests: Vec<String>,
    pub keys: Vec<String>,
    pub settings: Vec<Vec<String>>,
    pub configs: Vec<String>,
}

impl PlanIdentity {
    pub fn runs(&self) -> usize {
        self.worlds.len() * self.settings.len()
    }

    /// The part of the plan this is (the whole plan when not sharded).
    pub fn shard(&self) -> Shard {
        self.shard.unwrap_or(Shard::WHOLE)
    }

    /// The runs this part holds.
    pub fn runs_held(&self) -> usize {
        self.shard().held(self.runs())
    }

    /// Run `run`'s world label, setting index and setting values.
    pub fn run(&self, run: usize) -> (&str, usize, &[String]) {
        let (w, s) = place(run, self.settings.len());
        (&self.worlds[w], s, &self.settings[s])
    }

    /// `key=value, key=value` of setting `s` (`defaults` with no keys).
    pub fn label(&self, s: usize) -> String {
        label(self.keys.iter().map(String::as_str), &self.settings[s])
    }

    /// Whether `other` is a part of the same plan (or all of it).
    pub fn same_plan(&self, other: &PlanIdentity) -> bool {
        PlanIdentity {
            shard: None,
            ..self.clone()
        } == PlanIdentity {
            shard: None,
            ..other.clone()
        }
    }

    /// How `self` differs from `other`, in words.
    pub fn difference(&self, other: &PlanIdentity) -> String {
        let (a, b) = (self, other);
        if a.worlds != b.worlds {
            format!("worlds {:?}, not {:?}", a.worlds, b.worlds)
        } else if a.world_digests != b.world_digests {
            let changed: Vec<&str> = a
                .worlds
                .iter()
                .enumerate()
                .filter(|(i, _)| a.world_digests.get(*i) != b.world_digests.get(*i))
                .map(|(_, w)| w.as_str())
                .collect();
            format!("the worlds {changed:?} changed since it started")
        } else if a.keys != b.keys || a.settings != b.settings {
            format!("settings of {:?}, not {:?}", a.keys, b.keys)
        } else if a.configs != b.configs {
            "the same settings over another base configuration".into()
        } else {
            format!("shard {}, not {}", a.shard(), b.shard())
        }
    }
}

/// One run's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Its place in the plan.
    pub run: usize,
    pub world: String,
    /// The setting's index, and its values per swept key.
    pub setting: usize,
    pub values: Vec<String>,
    pub outcome: String,
    pub success: bool,
    pub collisions: usize,
    /// What the first collision hit.
    pub collision_cause: String,
    pub waypoints_reached: usize,
    pub waypoints: usize,
    pub distance_m: f64,
    pub duration_s: f64,
    pub average_speed_mps: f64,
    pub closest_approach_m: Option<f64>,
    /// When it was, s from the start (`arcnav render` draws that moment of
    /// the run's log).
    #[serde(default)]
    pub closest_approach_at_s: Option<f64>,
    /// The speed the configuration allows (002 §7), m/s.
    #[serde(default)]
    pub speed_bound_mps: f64,
    /// The nearest of the ranges at which the world's holes and ditches
    /// were first flagged or suspected (`drops_first_seen`), m; none when
    /// no drop hazard was reported.
    #[serde(default)]
    pub drops_first_seen_min_m: Option<f64>,
    /// Near edges the hole evidence over images suspected, summed over
    /// the images (report.json `evidence_suspected`).
    #[serde(default)]
    pub evidence_suspected: u64,
    /// Runs of consecutive stop commands, and the time stood.
    pub stops: u64,
    pub stopped_s: f64,
    pub recoveries: u64,
    pub backed_m: f64,
    /// The route behaviour's re-plans (0 without it).
    pub replans: u64,
    pub wall_time_s: f64,
    /// The guard's stops and slows (0 with no fault; its time is in each
    /// run's report.json: a table is reproducible, wall time aside).
    #[serde(default)]
    pub guard_stops: u64,
    #[serde(default)]
    pub guard_slows: u64,
    /// Cycles the external behaviours (`[behaviours.external.NAME]`) voted
    /// on, summed over them.
    #[serde(default)]
    pub external_votes: u64,
    /// Behaviours that could no longer vote, `NAME: why`, `; `-separated
    /// (an external program that exited, hung or wrote garbage).
    #[serde(default)]
    pub behaviour_faults: String,
    /// Why the run could not be done (outcome `error`); empty otherwise.
    #[serde(default)]
    pub error: String,
}

impl Row {
    /// A run that could not be done.
    pub fn failed(run: usize, world: &str, setting: usize, values: &[String], error: &str) -> Self {
        Self {
            run,
            world: world.to_owned(),
            setting,
            values: values.to_vec(),
            outcome: "error".into(),
            success: false,
            collisions: 0,
            collision_cause: String::new(),
            waypoints_reached: 0,
            waypoints: 0,
            distance_m: 0.0,
            duration_s: 0.0,
            average_speed_mps: 0.0,
            closest_approach_m: None,
            closest_approach_at_s: None,
            speed_bound_mps: 0.0,
            drops_first_seen_min_m: None,
            evidence_suspected: 0,
            stops: 0,
            stopped_s: 0.0,
            recoveries: 0,
            backed_m: 0.0,
            replans: 0,
            wall_time_s: 0.0,
            guard_stops: 0,
            guard_slows: 0,
            external_votes: 0,
            behaviour_faults: String::new(),
            error: error.to_owned(),
        }
    }

    pub fn new(
        run: usize,
        world: &str,
        setting: usize,
        values: &[String],
        r: &MissionReport,
        external: &[String],
    ) -> Self {
        Self {
            run,
            world: world.to_owned(),
            setting,
            values: values.to_vec(),
            outcome: serde_json::to_value(r.outcome)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default(),
            success: r.success,
            collisions: r.collisions.len(),
            collision_cause: r
                .collisions
                .first()
                .map(|c| c.cause.clone())
                .unwrap_or_default(),
            waypoints_reached: r.waypoints_reached,
            waypoints: r.waypoints,
            distance_m: r.distance_m,
            duration_s: r.duration_s,
            average_speed_mps: r.average_speed_mps,
            closest_approach_m: r.closest_approach_m,
            closest_approach_at_s: r.closest_approach.as_ref().map(|m| m.at_s),
            speed_bound_mps: r.speed_bound.bound_mps,
            drops_first_seen_min_m: r
                .drops_first_seen
                .iter()
                .filter_map(|d| d.first_range_m)
                .min_by(f64::total_cmp),
            evidence_suspected: r.evidence_suspected,
            stops: r.stops.episodes,
            stopped_s: r.stops.stopped_s.values().sum(),
            recoveries: r.recovery.recoveries,
            backed_m: r.recovery.backed_m,
            replans: r
                .behaviour_counters
                .values()
                .filter_map(|c| c.get("replans"))
                .sum(),
            wall_time_s: r.wall_time_s,
            guard_stops: r.guard.as_ref().map_or(0, |g| g.stops),
            guard_slows: r.guard.as_ref().map_or(0, |g| g.slows),
            external_votes: r
                .behaviour_counters
                .iter()
                .filter(|(name, _)| external.iter().any(|e| e == *name))
                .filter_map(|(_, c)| c.get("voted"))
                .sum(),
            behaviour_faults: r
                .behaviour_faults
                .iter()
                .map(|(name, why)| format!("{name}: {why}"))
                .collect::<Vec<_>>()
                .join("; "),
            error: String::new(),
        }
    }
}

/// Per setting: how it did over the worlds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SettingSummary {
    pub setting: usize,
    pub values: Vec<String>,
    pub runs: usize,
    pub successes: usize,
    /// successes / runs.
    pub success_rate: f64,
    /// Mean of the runs' average speeds, m/s.
    pub mean_speed_mps: f64,
    /// The smallest closest approach of any run, m.
    pub worst_closest_approach_m: Option<f64>,
    pub collisions: usize,
    pub mean_distance_m: f64,
    /// The guard's stops and slows in all (0 with no fault in the
    /// pipeline).
    pub guard_interventions: u64,
}

/// The summary of each setting that has rows.
pub fn summarise(plan: &PlanIdentity, rows: &[Row]) -> Vec<SettingSummary> {
    (0..plan.settings.len())
        .filter_map(|s| {
            let of: Vec<&Row> = rows.iter().filter(|r| r.setting == s).collect();
            if of.is_empty() {
                return None;
            }
            let n = of.len() as f64;
            let successes = of.iter().filter(|r| r.success).count();
            Some(SettingSummary {
                setting: s,
                values: plan.settings[s].clone(),
                runs: of.len(),
                successes,
                success_rate: successes as f64 / n,
                mean_speed_mps: of.iter().map(|r| r.average_speed_mps).sum::<f64>() / n,
                worst_closest_approach_m: of
                    .iter()
                    .filter_map(|r| r.closest_approach_m)
                    .min_by(f64::total_cmp),
                collisions: of.iter().map(|r| r.collisions).sum(),
                mean_distance_m: of.iter().map(|r| r.distance_m).sum::<f64>() / n,
                guard_interventions: of.iter().map(|r| r.guard_stops + r.guard_slows).sum(),
            })
        })
        .collect()
}

/// A CSV field: quoted when it holds a comma, quote or line break.
fn field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

fn number(v: f64) -> String {
    // -0.000 reads as a sign error.
    let v = if v.abs() < 5e-4 { 0.0 } else { v };
    format!("{v:.3}")
}

fn optional(v: Option<f64>) -> String {
    v.map(number).unwrap_or_default()
}

/// `table.csv`: one line per row, the swept keys as columns.
pub fn table_csv(plan: &PlanIdentity, rows: &[Row]) -> String {
    let mut out = String::from("run,world");
    for key in &plan.keys {
        out.push(',');
        out.push_str(&field(key));
    }
    out.push_str(
        ",outcome,success,collisions,collision_cause,waypoints_reached,waypoints,distance_m,\
         duration_s,average_speed_mps,closest_approach_m,closest_approach_at_s,speed_bound_mps,\
         drops_first_seen_min_m,evidence_suspected,stops,stopped_s,recoveries,backed_m,replans,wall_time_s,guard_stops,guard_slows,\
         external_votes,behaviour_faults,error\n",
    );
    for r in rows {
        let mut line = vec![r.run.to_string(), field(&r.world)];
        line.extend(r.values.iter().map(|v| field(v)));
        line.extend([
            r.outcome.clone(),
            r.success.to_string(),
            r.collisions.to_string(),
            field(&r.collision_cause),
            r.waypoints_reached.to_string(),
            r.waypoints.to_string(),
            number(r.distance_m),
            number(r.duration_s),
            number(r.average_speed_mps),
            optional(r.closest_approach_m),
            optional(r.closest_approach_at_s),
            number(r.speed_bound_mps),
            optional(r.drops_first_seen_min_m),
            r.evidence_suspected.to_string(),
            r.stops.to_string(),
            number(r.stopped_s),
            r.recoveries.to_string(),
            number(r.backed_m),
            r.replans.to_string(),
            number(r.wall_time_s),
            r.guard_stops.to_string(),
            r.guard_slows.to_string(),
            r.external_votes.to_string(),
            field(&r.behaviour_faults),
            field(&r.error),
        ]);
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

/// `summary.csv`: one line per setting.
pub fn summary_csv(plan: &PlanIdentity, summary: &[SettingSummary]) -> String {
    let mut out = String::from("setting");
    for key in &plan.keys {
        out.push(',');
        out.push_str(&field(key));
    }
    out.push_str(
        ",runs,successes,success_rate,mean_speed_mps,worst_closest_approach_m,collisions,\
         mean_distance_m,guard_interventions\n",
    );
    for s in summary {
        let mut line = vec![s.setting.to_string()];
        line.extend(s.values.iter().map(|v| field(v)));
        line.extend([
            s.runs.to_string(),
            s.successes.to_string(),
            number(s.success_rate),
            number(s.mean_speed_mps),
            optional(s.worst_closest_approach_m),
            s.collisions.to_string(),
            number(s.mean_distance_m),
            s.guard_interventions.to_string(),
        ]);
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

/// The rows file of a sweep directory, appended to as runs finish.
pub struct RowLog {
    file: std::fs::File,
}

/// What `rows.jsonl` held.
#[derive(Debug, Default)]
pub struct Finished {
    pub rows: Vec<Row>,
    /// Lines that are not a whole row (a run cut off while its row was
    /// being written), ignored: the run is done again.
    pub unreadable: usize,
}

impl Finished {
    /// Keeps the rows that are runs of `plan`'s part (their world and
    /// setting values are the plan's for their run index, and the run is
    /// the shard's); the others — a row edited, or from another sweep's or
    /// shard's file — are dropped and their runs done again. How many were
    /// dropped.
    pub fn keep_runs_of(&mut self, plan: &PlanIdentity) -> usize {
        let before = self.rows.len();
        let shard = plan.shard();
        self.rows.retain(|row| {
            row.run < plan.runs() && shard.holds(row.run) && {
                let (world, s, values) = plan.run(row.run);
                row.world == world && row.setting == s && row.values == values
            }
        });
        before - self.rows.len()
    }
}

/// One directory given to [`merge`]: its name (for messages), its plan
/// and what its rows file held.
#[derive(Debug)]
pub struct Part {
    pub name: String,
    pub plan: PlanIdentity,
    pub finished: Finished,
}

/// Parts that do not make one whole sweep.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("nothing to merge: give the directories of a sweep's shards")]
    Nothing,
    #[error("{part} holds another sweep than {first}: {difference}")]
    OtherPlan {
        part: String,
        first: String,
        difference: String,
    },
    #[error("{part} is shard {shard}, {first} is of a plan in {count} shards")]
    OtherSplit {
        part: String,
        shard: Shard,
        first: String,
        count: usize,
    },
    #[error("shard {shard} is given twice: {a} and {b}")]
    Twice { shard: Shard, a: String, b: String },
    #[error("not a whole sweep: {0}")]
    Incomplete(String),
}

/// The whole sweep that `parts` make: its plan (not sharded) and every
/// run's row in plan order, and how many rows of the parts were not theirs
/// (another sweep's or shard's, or edited) and left out. Refuses parts of
/// different plans or splits, a shard given twice, and a shard missing or
/// missing runs.
pub fn merge(parts: Vec<Part>) -> Result<(PlanIdentity, Vec<Row>, usize), MergeError> {
    let first = parts.first().ok_or(MergeError::Nothing)?;
    let count = first.plan.shard().count;
    let mut by_shard: BTreeMap<usize, &str> = BTreeMap::new();
    for part in &parts {
        if !part.plan.same_plan(&first.plan) {
            return Err(MergeError::OtherPlan {
                part: part.name.clone(),
                first: first.name.clone(),
                difference: part.plan.difference(&first.plan),
            });
        }
        let shard = part.plan.shard();
        if shard.count != count {
            return Err(MergeError::OtherSplit {
                part: part.name.clone(),
                shard,
                first: first.name.clone(),
                count,
            });
        }
        if let Some(a) = by_shard.insert(shard.index, &part.name) {
            return Err(MergeError::Twice {
                shard,
                a: a.to_owned(),
                b: part.name.clone(),
            });
        }
    }
    let mut problems = Vec::new();
    let absent: Vec<String> = (1..=count)
        .filter(|k| !by_shard.contains_key(k))
        .map(|index| Shard { index, count }.to_string())
        .collect();
    if !absent.is_empty() {
        problems.push(format!("no directory holds shard {}", absent.join(", ")));
    }
    let mut plan = first.plan.clone();
    plan.shard = None;
    let mut rows = Vec::new();
    let mut foreign = 0;
    for mut part in parts {
        foreign += part.finished.keep_runs_of(&part.plan);
        let held = part.plan.runs_held();
        if part.finished.rows.len() < held {
            problems.push(format!(
                "{} (shard {}) has {} of its {held} runs: carry it on with its command and \
                 --resume",
                part.name,
                part.plan.shard(),
                part.finished.rows.len()
            ));
        }
        rows.append(&mut part.finished.rows);
    }
    if !problems.is_empty() {
        return Err(MergeError::Incomplete(problems.join("; ")));
    }
    rows.sort_by_key(|r| r.run);
    Ok((plan, rows, foreign))
}

impl RowLog {
    pub const FILE: &'static str = "rows.jsonl";

    /// Opens `dir`'s rows file for appending (after a line cut off by an
    /// interruption, on a line of its own).
    pub fn append(dir: &Path) -> std::io::Result<Self> {
        let path = dir.join(Self::FILE);
        let cut_off = std::fs::read(&path)
            .map(|bytes| bytes.last().is_some_and(|&b| b != b'\n'))
            .unwrap_or(false);
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        if cut_off {
            file.write_all(b"\n")?;
        }
        Ok(Self { file })
    }

    /// Appends `row` as one line, on disk before it returns.
    pub fn push(&mut self, row: &Row) -> std::io::Result<()> {
        self.file.write_all(Self::line(row)?.as_bytes())?;
        self.file.sync_data()
    }

    /// Writes `dir`'s rows file whole, holding `rows` (a merged sweep's).
    pub fn write(dir: &Path, rows: &[Row]) -> std::io::Result<()> {
        let mut text = String::new();
        for row in rows {
            text.push_str(&Self::line(row)?);
        }
        crate::output::write_file(&dir.join(Self::FILE), text.as_bytes())
    }

    /// `row` as a line of the rows file.
    fn line(row: &Row) -> std::io::Result<String> {
        let mut line = serde_json::to_string(row).map_err(std::io::Error::other)?;
        line.push('\n');
        Ok(line)
    }

    /// The rows already in `dir` (none when there is no rows file), each
    /// run once, in plan order; runs outside a plan of `runs` are refused.
    pub fn read(dir: &Path, runs: usize) -> std::io::Result<Finished> {
        let path = dir.join(Self::FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Finished::default()),
            Err(e) => return Err(e),
        };
        let mut finished = Finished::default();
        let mut by_run = BTreeMap::new();
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            match serde_json::from_str::<Row>(line) {
                Ok(row) if row.run < runs => {
                    by_run.insert(row.run, row);
                }
                Ok(row) => {
                    return Err(std::io::Error::other(format!(
                        "{} holds run {} of a sweep of {runs} runs",
                        path.display(),
                        row.run
                    )));
                }
                Err(_) => finished.unreadable += 1,
            }
        }
        finished.rows = by_run.into_values().collect();
        Ok(finished)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> Config {
        Config::default()
    }

    fn sets(args: &[&str]) -> Vec<(String, Vec<String>)> {
        args.iter().map(|a| parse_set(a).unwrap()).collect()
    }

    #[test]
    fn values_take_the_type_of_the_key_they_set() {
        let axes = axes(
            &base(),
            &sets(&[
                "arbiter.cruise_speed_mps=2,3.5",
                "behaviours.obstacle_avoidance.unseen_ground=slow,\"obstacle\"",
                "behaviours.obstacle_avoidance.speed_vote=false",
            ]),
            &[],
        )
        .unwrap();
        assert_eq!(
            axes[0].values,
            [toml::Value::Float(2.0), toml::Value::Float(3.5)]
        );
        assert_eq!(
            axes[1].values,
            [
                toml::Value::String("slow".into()),
                toml::Value::String("obstacle".into())
            ]
        );
        assert_eq!(axes[2].values, [toml::Value::Boolean(false)]);
        let settings = settings(&base(), &axes, &Registry::builtin()).unwrap();
        assert_eq!(settings.len(), 4, "2 × 2 × 1");
        assert_eq!(settings[3].config.arbiter.cruise_speed_mps, 3.5);
        assert_eq!(
            settings[3].label(&axes),
            "arbiter.cruise_speed_mps=3.5, behaviours.obstacle_avoidance.unseen_ground=\"obstacle\", \
             behaviours.obstacle_avoidance.speed_vote=false"
        );
    }

    #[test]
    fn unknown_keys_wrong_types_empty_and_invalid_values_are_refused_by_name() {
        let refused = |args: &[&str]| {
            let sets: Result<Vec<_>, _> = args.iter().map(|a| parse_set(a)).collect();
            sets.and_then(|s| axes(&base(), &s, &[]))
                .and_then(|a| settings(&base(), &a, &Registry::builtin()).map(|_| ()))
                .unwrap_err()
                .to_string()
        };
        let message = refused(&["arbiter.cruise_speed=3"]);
        assert!(
            message.contains("`arbiter.cruise_speed`: no such key"),
            "{message}"
        );
        let message = refused(&["behaviours.nope.x=1"]);
        assert!(
            message.contains("`behaviours.nope.x`: no such key"),
            "{message}"
        );
        let message = refused(&["arbiter.cruise_speed_mps=fast"]);
        assert!(
            message.contains("`arbiter.cruise_speed_mps` = fast") && message.contains("float"),
            "{message}"
        );
        let message = refused(&["behaviours.obstacle_avoidance.speed_vote=1"]);
        assert!(message.contains("the key takes boolean"), "{message}");
        let message = refused(&["arbiter.cruise_speed_mps="]);
        assert!(message.contains("swept over no values"), "{message}");
        let message = refused(&["arbiter"]);
        assert!(message.contains("expected KEY=VALUE"), "{message}");
        let message = refused(&["arbiter=1"]);
        assert!(message.contains("is a table"), "{message}");
        let message = refused(&["arbiter.cruise_speed_mps=-1"]);
        assert!(
            message.contains("arbiter.cruise_speed_mps=-1") && message.contains("cruise_speed_mps"),
            "{message}"
        );
        let message = refused(&["arcs.count=3", "arcs.count=5"]);
        assert!(message.contains("swept twice"), "{message}");
    }

    #[test]
    fn a_cut_off_row_is_counted_and_its_run_done_again() {
        let dir = arcnav_testkit::scratch_dir("arcnav-rows");
        let row = Row {
            run: 1,
            world: "w".into(),
            setting: 1,
            values: vec!["2".into()],
            outcome: "completed".into(),
            success: true,
            collisions: 0,
            collision_cause: String::new(),
            waypoints_reached: 3,
            waypoints: 3,
            distance_m: 100.0,
            duration_s: 40.0,
            average_speed_mps: 2.5,
            closest_approach_m: Some(1.5),
            closest_approach_at_s: Some(12.0),
            speed_bound_mps: 7.4,
            drops_first_seen_min_m: Some(14.2),
            evidence_suspected: 3,
            stops: 0,
            stopped_s: 0.0,
            recoveries: 0,
            backed_m: 0.0,
            replans: 2,
            wall_time_s: 3.0,
            guard_stops: 0,
            guard_slows: 0,
            external_votes: 0,
            behaviour_faults: String::new(),
            error: String::new(),
        };
        let mut log = RowLog::append(&dir).unwrap();
        log.push(&row).unwrap();
        log.push(&Row {
            run: 0,
            ..row.clone()
        })
        .unwrap();
        std::fs::OpenOptions::new()
            .append(true)
            .open(dir.join(RowLog::FILE))
            .unwrap()
            .write_all(b"{\"run\": 2, \"wor")
            .unwrap();
        let finished = RowLog::read(&dir, 4).unwrap();
        assert_eq!(finished.unreadable, 1);
        // Carried on: the next row is whole, on a line of its own.
        RowLog::append(&dir)
            .unwrap()
            .push(&Row {
                run: 3,
                ..row.clone()
            })
            .unwrap();
        let finished = RowLog::read(&dir, 4).unwrap();
        assert_eq!(finished.unreadable, 1);
        let runs: Vec<usize> = finished.rows.iter().map(|r| r.run).collect();
        assert_eq!(runs, [0, 1, 3], "in plan order");
        assert!(
            RowLog::read(&dir, 1).is_err(),
            "run 1 is not in a plan of 1"
        );
    }

    /// Two worlds × three settings, as `sweep.json` holds it.
    fn identity(shard: Option<Shard>) -> PlanIdentity {
        PlanIdentity {
            shard,
            worlds: vec!["a".into(), "b".into()],
            world_digests: vec!["1".into(), "2".into()],
            keys: vec!["arbiter.cruise_speed_mps".into()],
            settings: vec![vec!["2.5".into()], vec!["4.0".into()], vec!["6.0".into()]],
            configs: vec![String::new(); 3],
        }
    }

    /// Shard `k` of `n` of [`identity`] with a row for each of its runs.
    fn part(k: usize, n: usize) -> Part {
        let plan = identity((n > 1).then_some(Shard { index: k, count: n }));
        let rows = plan
            .shard()
            .runs(plan.runs())
            .map(|r| {
                let (world, s, values) = plan.run(r);
                Row::failed(r, world, s, values, "")
            })
            .collect();
        Part {
            name: format!("shard{k}"),
            plan,
            finished: Finished {
                rows,
                unreadable: 0,
            },
        }
    }

    #[test]
    fn shards_split_a_plan_into_parts_that_hold_every_run_once() {
        for bad in ["", "1", "0/3", "4/3", "a/3", "1/0", "-1/3", "1/100001"] {
            assert!(Shard::parse(bad).is_err(), "{bad:?}");
        }
        assert_eq!(Shard::parse(" 2/3 ").unwrap(), Shard { index: 2, count: 3 });
        for count in [1, 2, 3, 6, 7] {
            let mut seen = vec![0; 6];
            for index in 1..=count {
                let shard = Shard { index, count };
                for r in shard.runs(6) {
                    assert!(shard.holds(r));
                    seen[r] += 1;
                }
                assert_eq!(
                    shard.runs(6).count(),
                    (0..6).filter(|&r| shard.holds(r)).count()
                );
                assert_eq!(shard.held(6), shard.runs(6).count());
                assert_eq!(shard.held(0), 0);
            }
            assert_eq!(seen, [1; 6], "{count} shards");
        }
        // In sweep.json a shard is its K/N text, read back through parse.
        let text = serde_json::to_string(&identity(Some(Shard { index: 2, count: 3 }))).unwrap();
        assert!(text.contains("\"shard\":\"2/3\""), "{text}");
        let read: PlanIdentity = serde_json::from_str(&text).unwrap();
        assert_eq!(read.shard(), Shard { index: 2, count: 3 });
        for bad in ["0/0", "4/3", "1/x"] {
            let edited = text.replace("\"2/3\"", &format!("\"{bad}\""));
            let e = serde_json::from_str::<PlanIdentity>(&edited).unwrap_err();
            assert!(e.to_string().contains("expected K/N"), "{bad}: {e}");
        }
        // An old sweep.json (no shard) reads as the whole plan.
        let text = serde_json::to_string(&identity(None)).unwrap();
        assert!(!text.contains("shard"));
        let read: PlanIdentity = serde_json::from_str(&text).unwrap();
        assert_eq!(read.shard(), Shard::WHOLE);
        assert_eq!(read.runs_held(), 6);
    }

    #[test]
    fn merging_joins_the_shards_of_one_plan_and_refuses_anything_else() {
        let (plan, rows, foreign) = merge((1..=4).rev().map(|k| part(k, 4)).collect()).unwrap();
        assert_eq!(plan, identity(None));
        assert_eq!(
            rows.iter().map(|r| r.run).collect::<Vec<_>>(),
            [0, 1, 2, 3, 4, 5]
        );
        assert_eq!(foreign, 0);
        // A whole sweep merges with itself alone.
        assert_eq!(merge(vec![part(1, 1)]).unwrap().1.len(), 6);

        let said = |parts: Vec<Part>| merge(parts).unwrap_err().to_string();
        assert!(said(Vec::new()).contains("nothing to merge"));
        let mut other = part(2, 2);
        other.plan.world_digests[1] = "changed".into();
        let e = said(vec![part(1, 2), other]);
        assert!(
            e.contains("shard2 holds another sweep than shard1: the worlds [\"b\"] changed"),
            "{e}"
        );
        let e = said(vec![part(1, 2), part(2, 3)]);
        assert!(
            e.contains("shard2 is shard 2/3, shard1 is of a plan in 2 shards"),
            "{e}"
        );
        let e = said(vec![part(1, 2), part(1, 2)]);
        assert!(e.contains("shard 1/2 is given twice"), "{e}");
        let e = said(vec![part(1, 3), part(3, 3)]);
        assert!(e.contains("no directory holds shard 2/3"), "{e}");
        let mut cut = part(2, 2);
        cut.finished.rows.pop();
        let e = said(vec![part(1, 2), cut]);
        assert!(e.contains("shard2 (shard 2/2) has 2 of its 3 runs"), "{e}");
        // A row of another shard in a shard's file is not taken for it.
        let mut mixed = part(1, 2);
        let stray = part(2, 2).finished.rows[0].clone();
        mixed.finished.rows.push(stray);
        let (_, rows, foreign) = merge(vec![mixed, part(2, 2)]).unwrap();
        assert_eq!((rows.len(), foreign), (6, 1));
    }
}
