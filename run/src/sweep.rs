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
        label(axes, &self.values)
    }
}

/// The label of the setting with `values` on `axes`.
fn label(axes: &[Axis], values: &[String]) -> String {
    if axes.is_empty() {
        return "defaults".into();
    }
    axes.iter()
        .zip(values)
        .map(|(a, v)| format!("{}={v}", a.key))
        .collect::<Vec<_>>()
        .join(", ")
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
            let label = label(axes, &values);
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
        let s = run % self.settings.len();
        (
            &self.worlds[run / self.settings.len()],
            s,
            &self.settings[s],
        )
    }

    /// What identifies the plan: worlds, axes, and every setting's whole
    /// configuration (a resumed sweep must be the same sweep).
    pub fn identity(&self) -> PlanIdentity {
        PlanIdentity {
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

/// Written as `sweep.json`: what a resumed sweep is checked against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanIdentity {
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
    /// Runs of consecutive stop commands, and the time stood.
    pub stops: u64,
    pub stopped_s: f64,
    pub recoveries: u64,
    pub backed_m: f64,
    /// The route behaviour's re-plans (0 without it).
    pub replans: u64,
    pub wall_time_s: f64,
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
            stops: 0,
            stopped_s: 0.0,
            recoveries: 0,
            backed_m: 0.0,
            replans: 0,
            wall_time_s: 0.0,
            error: error.to_owned(),
        }
    }

    pub fn new(
        run: usize,
        world: &str,
        setting: usize,
        values: &[String],
        r: &MissionReport,
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
}

/// The summary of each setting that has rows.
pub fn summarise(plan: &Plan, rows: &[Row]) -> Vec<SettingSummary> {
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
                values: plan.settings[s].values.clone(),
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
pub fn table_csv(plan: &Plan, rows: &[Row]) -> String {
    let mut out = String::from("run,world");
    for axis in &plan.axes {
        out.push(',');
        out.push_str(&field(&axis.key));
    }
    out.push_str(
        ",outcome,success,collisions,collision_cause,waypoints_reached,waypoints,distance_m,\
         duration_s,average_speed_mps,closest_approach_m,closest_approach_at_s,speed_bound_mps,\
         stops,stopped_s,recoveries,backed_m,replans,wall_time_s,error\n",
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
            r.stops.to_string(),
            number(r.stopped_s),
            r.recoveries.to_string(),
            number(r.backed_m),
            r.replans.to_string(),
            number(r.wall_time_s),
            field(&r.error),
        ]);
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

/// `summary.csv`: one line per setting.
pub fn summary_csv(plan: &Plan, summary: &[SettingSummary]) -> String {
    let mut out = String::from("setting");
    for axis in &plan.axes {
        out.push(',');
        out.push_str(&field(&axis.key));
    }
    out.push_str(
        ",runs,successes,success_rate,mean_speed_mps,worst_closest_approach_m,collisions,\
         mean_distance_m\n",
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
    /// Keeps the rows that are runs of `plan` (their world and setting
    /// values are the plan's for their run index); the others — a row
    /// edited, or from another sweep's file — are dropped and their runs
    /// done again. How many were dropped.
    pub fn keep_runs_of(&mut self, plan: &Plan) -> usize {
        let before = self.rows.len();
        self.rows.retain(|row| {
            row.run < plan.runs() && {
                let (world, s, setting) = plan.run(row.run);
                row.world == world.label && row.setting == s && row.values == setting.values
            }
        });
        before - self.rows.len()
    }
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
        let mut line = serde_json::to_string(row).map_err(std::io::Error::other)?;
        line.push('\n');
        self.file.write_all(line.as_bytes())?;
        self.file.sync_data()
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
            stops: 0,
            stopped_s: 0.0,
            recoveries: 0,
            backed_m: 0.0,
            replans: 2,
            wall_time_s: 3.0,
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
}
