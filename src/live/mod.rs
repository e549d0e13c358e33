//! Live operation: the pipeline's nodes driven by messages as they arrive,
//! either all in one process with a thread per node ([`threaded`], `arcnav
//! run`) or each node in its own process talking LCM ([`node`], `arcnav node
//! …`).
//!
//! Both executors run the same nodes as the lock-step [`Pipeline`] and the
//! same live stages ([`stages`]); they differ only in how messages travel.
//! Time: the decision cycle follows the *sensor clock* (the timestamps of
//! the pose stream, so a log played back in real time drives the system
//! exactly as the vehicle would), while the safety watchdogs follow the
//! *wall clock* (a silent sensor stops time on the sensor clock).
//!
//! [`Pipeline`]: crate::pipeline::Pipeline

pub mod node;
pub mod stages;
pub mod threaded;

use std::fmt::Write as _;

use arcnav_vehicle::config::{self as check, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[live]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LiveConfig {
    /// No pose for this long (wall clock): the arbiter commands stop, s.
    pub pose_timeout_s: f64,
    /// No range image evaluated for this long: the arbiter commands stop, s.
    pub image_timeout_s: f64,
    /// The distributed arbiter decides this long after a cycle's first votes
    /// even when an expected behaviour has not voted, s.
    pub decision_deadline_s: f64,
    /// Decide at once when new obstacle cells reach the map, besides the
    /// fixed-rate cycle.
    pub decide_on_new_cells: bool,
    /// Cells wait until capture + `pipeline.perception_latency_s` and
    /// decisions happen only on the cycle, as in `arcnav sim` and `arcnav
    /// replay`: a live run then reproduces the lock-step replay of its inputs
    /// (used by the tests; adds the modelled latency).
    pub reproduce_lockstep: bool,
    /// Each node logs its status this often (0: never), s.
    pub status_period_s: f64,
    /// Messages waiting between two threads before the oldest are dropped
    /// (counted); range images always keep only the newest.
    pub queue_capacity: usize,
    /// The perception thread polls for its next image instead of sleeping
    /// until one comes, and hands half of each large image to a helper
    /// thread. It then keeps one core busy, and picks each image up at once
    /// on a core that is awake and warm: on a virtual machine, or a
    /// processor that saves power when idle, an image evaluated right after
    /// a sleep takes much longer than one after another (2-vCPU VM,
    /// 128×2048 at 10 Hz, image arrival to command: median 2.9-3.2 → 2.0-2.5 ms).
    pub perception_busy_poll: bool,
}

impl Default for LiveConfig {
    fn default() -> Self {
        Self {
            pose_timeout_s: 0.5,
            image_timeout_s: 1.5,
            decision_deadline_s: 0.05,
            decide_on_new_cells: true,
            reproduce_lockstep: false,
            status_period_s: 10.0,
            queue_capacity: 1024,
            perception_busy_poll: false,
        }
    }
}

impl LiveConfig {
    /// Keys relative to `[live]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check::in_range("pose_timeout_s", self.pose_timeout_s, 0.01, 60.0)?;
        check::in_range("image_timeout_s", self.image_timeout_s, 0.01, 600.0)?;
        check::in_range("decision_deadline_s", self.decision_deadline_s, 0.0, 10.0)?;
        check::in_range("status_period_s", self.status_period_s, 0.0, 86_400.0)?;
        if !(8..=1_000_000).contains(&self.queue_capacity) {
            return Err(ConfigError::new(
                "queue_capacity",
                format!("is {}, must be 8 to 1000000", self.queue_capacity),
            ));
        }
        Ok(())
    }
}

/// Count, mean, median, 99th percentile and maximum of a series.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Summary {
    pub count: u64,
    pub mean: f64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Summary {
    fn cell(&self, value: f64) -> String {
        if self.count == 0 {
            "-".to_owned()
        } else {
            format!("{value:.2}")
        }
    }
}

/// A series of measurements; percentiles over the newest [`Samples::KEPT`].
#[derive(Debug, Clone, Default)]
pub struct Samples {
    kept: Vec<f64>,
    next: usize,
    count: u64,
    sum: f64,
    max: f64,
}

impl Samples {
    pub const KEPT: usize = 1 << 16;

    pub fn add(&mut self, value: f64) {
        if self.kept.len() < Self::KEPT {
            self.kept.push(value);
        } else {
            self.kept[self.next] = value;
            self.next = (self.next + 1) % Self::KEPT;
        }
        self.count += 1;
        self.sum += value;
        self.max = if self.count == 1 {
            value
        } else {
            self.max.max(value)
        };
    }

    pub fn summary(&self) -> Summary {
        if self.count == 0 {
            return Summary::default();
        }
        let mut sorted = self.kept.clone();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Summary {
            count: self.count,
            mean: self.sum / self.count as f64,
            p50: at(0.5),
            p99: at(0.99),
            max: self.max,
        }
    }
}

/// What a node reports about itself (periodically through `tracing`, and in
/// the `--stats` table at exit).
#[derive(Debug, Clone, Default, Serialize)]
pub struct NodeStatus {
    pub node: String,
    /// What the node did: images evaluated, cycles run, vote sets cast,
    /// commands published, messages received.
    pub handled: u64,
    /// Time spent per handled item, ms.
    pub busy_ms: Summary,
    /// Items that took longer than their period (the node cannot keep up).
    pub overruns: u64,
    /// Items waiting for the node now, and at most.
    pub queue_depth: usize,
    pub queue_max: usize,
    /// Messages dropped (replaced by newer ones, undecodable, unplaceable).
    pub dropped: u64,
    /// Node-specific counters.
    pub counters: Vec<(String, u64)>,
}

impl NodeStatus {
    pub fn new(node: &str) -> Self {
        Self {
            node: node.to_owned(),
            ..Self::default()
        }
    }

    pub fn set(&mut self, counter: &str, value: u64) {
        match self.counters.iter_mut().find(|(name, _)| name == counter) {
            Some((_, v)) => *v = value,
            None => self.counters.push((counter.to_owned(), value)),
        }
    }

    /// One item took `ms` of its `period_ms` budget; longer is an overrun,
    /// logged the 1st, 2nd, 4th, 8th… time (the node cannot keep up).
    pub fn took(&mut self, busy: &mut Samples, ms: f64, period_ms: f64) {
        busy.add(ms);
        if ms > period_ms {
            self.set_overruns(
                self.overruns + 1,
                &format!("took {ms:.1} ms of a {period_ms:.0} ms period"),
            );
        }
    }

    /// Sets the overrun count, logging when it reaches a power of two.
    pub fn set_overruns(&mut self, overruns: u64, what: &str) {
        if overruns > self.overruns && overruns.is_power_of_two() {
            tracing::warn!(node = %self.node, overruns, "cannot keep up: {what}");
        }
        self.overruns = overruns;
    }

    pub fn queue(&mut self, depth: usize) {
        self.queue_depth = depth;
        self.queue_max = self.queue_max.max(depth);
    }

    /// One status line through `tracing`.
    pub fn log(&self) {
        let counters: Vec<String> = self
            .counters
            .iter()
            .map(|(name, value)| format!("{name}={value}"))
            .collect();
        tracing::info!(
            node = %self.node,
            handled = self.handled,
            busy_mean_ms = format_args!("{:.3}", self.busy_ms.mean),
            busy_p99_ms = format_args!("{:.3}", self.busy_ms.p99),
            overruns = self.overruns,
            queue = self.queue_depth,
            queue_max = self.queue_max,
            dropped = self.dropped,
            "status {}",
            counters.join(" ")
        );
    }
}

/// The figures of a live run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LiveReport {
    /// Wall-clock duration of the run, s.
    pub wall_s: f64,
    /// Steering commands published, and how many of them were stops.
    pub commands: u64,
    pub stops: u64,
    /// Image arrival → publication of the first command decided after its
    /// cells reached the map, ms (measured where one process sees both).
    pub arrival_to_command_ms: Summary,
    /// Image capture → that command, ms, with the capture time mapped onto
    /// the wall clock through the pose stream (what a distributed arbiter can
    /// measure).
    pub capture_to_command_ms: Summary,
    pub nodes: Vec<NodeStatus>,
}

impl LiveReport {
    /// The `--stats` table.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let w = self
            .nodes
            .iter()
            .map(|n| n.node.chars().count())
            .chain([22])
            .max()
            .unwrap_or(22);
        let _ = writeln!(
            out,
            "{:<w$} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}  other",
            "node", "handled", "mean ms", "p99 ms", "max ms", "overruns", "queue≤", "dropped"
        );
        for n in &self.nodes {
            let other: Vec<String> = n
                .counters
                .iter()
                .map(|(name, value)| format!("{name} {value}"))
                .collect();
            let _ = writeln!(
                out,
                "{:<w$} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}  {}",
                n.node,
                n.handled,
                n.busy_ms.cell(n.busy_ms.mean),
                n.busy_ms.cell(n.busy_ms.p99),
                n.busy_ms.cell(n.busy_ms.max),
                n.overruns,
                n.queue_max,
                n.dropped,
                other.join(", ")
            );
        }
        if self.commands == 0 {
            return out;
        }
        let latency = |label: &str, s: &Summary| {
            format!(
                "{label:<w$} p50 {} ms, p99 {} ms, max {} ms over {} commands\n",
                s.cell(s.p50),
                s.cell(s.p99),
                s.cell(s.max),
                s.count
            )
        };
        out.push_str(&latency(
            "image arrival→command",
            &self.arrival_to_command_ms,
        ));
        out.push_str(&latency(
            "image capture→command",
            &self.capture_to_command_ms,
        ));
        let _ = writeln!(
            out,
            "{:<w$} {} published ({} stops) in {:.1} s",
            "commands", self.commands, self.stops, self.wall_s
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_give_percentiles_of_the_newest_samples() {
        let mut s = Samples::default();
        assert_eq!(s.summary().count, 0);
        for v in 1..=100 {
            s.add(f64::from(v));
        }
        let sum = s.summary();
        assert_eq!(sum.count, 100);
        assert_eq!(sum.max, 100.0);
        assert!((sum.mean - 50.5).abs() < 1e-12);
        assert!((sum.p50 - 50.0).abs() <= 1.0);
        assert!((sum.p99 - 99.0).abs() <= 1.0);
        // Beyond KEPT, old samples leave the percentiles but not the count.
        for _ in 0..Samples::KEPT {
            s.add(1000.0);
        }
        let sum = s.summary();
        assert_eq!(sum.p50, 1000.0);
        assert_eq!(sum.count, 100 + Samples::KEPT as u64);
    }

    #[test]
    fn the_stats_table_names_every_node_and_latency() {
        let mut perception = NodeStatus::new("perception");
        perception.handled = 12;
        perception.set("no_pose", 1);
        perception.set("no_pose", 2);
        let report = LiveReport {
            nodes: vec![perception],
            commands: 40,
            stops: 3,
            ..LiveReport::default()
        };
        let table = report.table();
        assert!(table.contains("perception"), "{table}");
        assert!(table.contains("no_pose 2"), "{table}");
        assert!(table.contains("40 published (3 stops)"), "{table}");
        assert!(table.contains("image arrival→command"), "{table}");
    }

    #[test]
    fn bad_live_settings_are_refused() {
        assert!(LiveConfig::default().validate().is_ok());
        let bad = LiveConfig {
            pose_timeout_s: 0.0,
            ..LiveConfig::default()
        };
        assert!(bad.validate().is_err());
        let bad = LiveConfig {
            queue_capacity: 1,
            ..LiveConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
