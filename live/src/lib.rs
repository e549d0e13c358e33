//! Live operation: the pipeline's nodes driven by messages as they arrive,
//! either all in one process with a thread per node ([`threaded`], `arcnav
//! run`) or each node in its own process talking LCM ([`node`], `arcnav node
//! …`).
//!
//! Both executors run the nodes of [`arcnav_pipeline`], the same ones and
//! the same decision cycle as the lock-step [`Pipeline`]; they differ only
//! in how messages travel.
//! Time: the decision cycle follows the *sensor clock* (the timestamps of
//! the pose stream, so a log played back in real time drives the system
//! exactly as the vehicle would), while the safety watchdogs follow the
//! *wall clock* (a silent sensor stops time on the sensor clock).
//!
//! [`Pipeline`]: arcnav_pipeline::Pipeline

pub mod clock;
mod guarded;
pub mod handoff;
pub mod io;
pub mod node;
pub mod options;
pub mod threaded;
pub mod vehicle;
mod workers;

use std::fmt::Write as _;

use arcnav_pipeline::ArbiterNode;
pub use arcnav_pipeline::{LiveConfig, Samples, Summary};
use serde::Serialize;

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

/// The arbiter node's figures into `status`.
pub(crate) fn arbiter_status(node: &ArbiterNode, status: &mut NodeStatus) {
    let counts = node.counts();
    status.handled = counts.commands;
    status.set("stops", counts.stops);
    status.set("watchdog_stops", counts.watchdog_stops);
    status.set("held_commands", counts.held);
    status.set("deadline_decisions", counts.deadline_decisions);
    status.set("late_votes", counts.late_votes);
    status.set("ignored_votes", counts.ignored_votes);
    status.set("future_votes", counts.future_votes);
    let stats = node.arbiter.stats();
    status.set("required_stale", stats.stops_required_stale);
    status.set("rejected_votes", stats.rejected_votes);
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
}
