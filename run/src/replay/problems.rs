//! What a replay could not use, and why: counted, and said line by line.

use std::collections::BTreeMap;

use arcnav_bus::log::LogStats;

use crate::bag::BagSummary;
use serde::Serialize;

/// What could not be used, and why. Any of it but `unknown_channels` and
/// `ignored` means input was lost.
#[derive(Debug, Clone, Default, Serialize)]
pub struct InputProblems {
    pub log: LogSummary,
    /// Messages of types arcnav does not know, per channel (e.g. LCM_SELF_TEST).
    pub unknown_channels: BTreeMap<String, u64>,
    /// Messages with a known fingerprint that do not decode, per channel.
    pub undecodable: BTreeMap<String, u64>,
    /// Poses that are not poses (bad quaternion, non-finite values).
    pub invalid_poses: u64,
    /// Range images that are not images (bad mount, sizes, angles).
    pub invalid_images: u64,
    /// Range-image slices that are not slices (bad mount, sizes, place in
    /// their image), or that perception refused.
    pub invalid_slices: u64,
    /// Slices repeated, out of order, older than their sensor's frame, or
    /// unlike their frame's earlier slices.
    pub slices_out_of_order: u64,
    /// Lines (columns or rows) of streamed frames that never arrived.
    pub lost_slice_lines: u64,
    /// Images (and slices) with no pose around their capture time.
    pub images_without_pose: u64,
    /// Images older than one already evaluated from the same sensor.
    pub images_out_of_order: u64,
    /// Times the pose jumped or ran backwards and the local map was reset.
    pub map_resets: u64,
    /// Known messages the replay does not consume (e.g. LOCAL_MAP), per channel.
    pub ignored: BTreeMap<String, u64>,
    /// Messages of a known type on a channel that is not arcnav's for that
    /// type (`POSE_GPS_RAW`, `STEERING_COMMAND_TELEOP`), per channel: another
    /// program's, skipped.
    pub foreign: BTreeMap<String, u64>,
    /// Events that came in the file after events logged later, fed in time
    /// order (nothing lost).
    pub reordered: u64,
    /// The largest such lag, s.
    pub max_reorder_lag_s: f64,
    /// Events further out of time order than the reader's window: fed late,
    /// after decisions that should have seen them.
    pub fed_late: u64,
    /// Times the log starts over (a channel goes back in time: logs
    /// concatenated): replayed as consecutive runs.
    pub log_restarts: u64,
    /// Decision cycles not run because the pose clock jumped ahead by more
    /// than a second (a gap in the log, a corrupt time).
    pub skipped_cycles: u64,
    /// Times the pose clock went backwards and the cycle clock restarted.
    pub clock_restarts: u64,
    /// Obstacle reports the local map refused (see the log at -v).
    pub reports_refused: u64,
    /// OBSTACLE_CELLS in a log with no range image, replayed without
    /// `--recorded-cells`: nothing was perceived.
    pub cells_unused: u64,
    /// The log holds no pose (within `--from`/`--to` when given): nothing
    /// could be placed or decided.
    pub no_poses: bool,
    /// Events after `--to`, as asked: not replayed.
    pub outside_window: u64,
    /// Events before `--from`: replayed to bring the pipeline to its state
    /// at `--from`, their decisions not kept.
    pub before_window: u64,
    /// `--from` (and `--to`) hold no decision: the log ends before `--from`.
    pub window_empty: bool,
    /// Images still waiting for the pose at their capture time when the log
    /// ended or started over (the pose stream stops before them).
    pub images_unplaced: u64,
    /// A bag's topics, what was used of them, and what could not be.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bag: Option<BagSummary>,
}

/// The log reader's counts.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct LogSummary {
    pub events: u64,
    pub skipped_bytes: u64,
    pub corrupt_events: u64,
    pub truncated_tail_bytes: u64,
}

impl From<&LogStats> for LogSummary {
    fn from(s: &LogStats) -> Self {
        Self {
            events: s.events,
            skipped_bytes: s.skipped_bytes,
            corrupt_events: s.corrupt_events,
            truncated_tail_bytes: s.truncated_tail_bytes,
        }
    }
}

impl InputProblems {
    /// True when some input could not be used.
    pub fn lost_input(&self) -> bool {
        self.log.skipped_bytes > 0
            || self.log.corrupt_events > 0
            || self.log.truncated_tail_bytes > 0
            || !self.undecodable.is_empty()
            || self.invalid_poses > 0
            || self.invalid_images > 0
            || self.invalid_slices > 0
            || self.slices_out_of_order > 0
            || self.lost_slice_lines > 0
            || self.images_without_pose > 0
            || self.images_out_of_order > 0
            || self.fed_late > 0
            || self.reports_refused > 0
            || self.cells_unused > 0
            || self.no_poses
            || self.window_empty
            || self.images_unplaced > 0
            || self.bag.as_ref().is_some_and(BagSummary::lost_input)
    }

    /// One line per problem, for the summary.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let l = &self.log;
        if l.skipped_bytes > 0 {
            lines.push(format!(
                "{} bytes of damaged log skipped ({} corrupt events)",
                l.skipped_bytes, l.corrupt_events
            ));
        }
        if l.truncated_tail_bytes > 0 {
            lines.push(format!(
                "log ends mid-event: {} bytes of a truncated last event",
                l.truncated_tail_bytes
            ));
        }
        for (channel, n) in &self.undecodable {
            lines.push(format!("{n} undecodable message(s) on {channel}"));
        }
        if self.reordered > 0 {
            lines.push(format!(
                "{} event(s) stood in the file after events logged up to {:.2} s later: fed in time order",
                self.reordered, self.max_reorder_lag_s
            ));
        }
        if self.log_restarts > 0 {
            lines.push(format!(
                "the log starts over {} time(s) (its channels go back in time): replayed as consecutive runs",
                self.log_restarts
            ));
        }
        if self.clock_restarts > 0 {
            lines.push(format!(
                "the pose clock went backwards {} time(s): the decision cycle restarted there",
                self.clock_restarts
            ));
        }
        if let Some(bag) = &self.bag {
            for (why, n) in &bag.refused {
                lines.push(format!("{n} message(s) of {why}"));
            }
            if let Some(damage) = &bag.damaged {
                lines.push(format!(
                    "the bag is damaged: {damage}; it was read up to there"
                ));
            }
        }
        if self.log.events == 0 && self.bag.is_some() {
            lines.push("no message of the bag could be used: nothing was replayed".into());
        } else if self.log.events == 0 {
            lines.push(format!(
                "no LCM event could be read from the log ({} bytes skipped as damaged): is it an LCM log?",
                self.log.skipped_bytes + self.log.truncated_tail_bytes
            ));
        } else if self.no_poses && self.outside_window > 0 {
            lines.push(format!(
                "no POSE between --from and --to ({} event(s) of the log lie outside them): \
                 nothing could be placed or decided",
                self.outside_window
            ));
        } else if self.no_poses {
            lines.push("the log holds no POSE: nothing could be placed or decided".into());
        } else if self.window_empty {
            lines.push(format!(
                "no decision between --from and --to: all {} event(s) of the log lie before \
                 --from (past its end?)",
                self.before_window
            ));
        }
        if self.cells_unused > 0 {
            lines.push(format!(
                "the log holds {} OBSTACLE_CELLS and no range image: nothing was perceived (--recorded-cells uses them)",
                self.cells_unused
            ));
        }
        for (what, n) in [
            ("invalid pose(s)", self.invalid_poses),
            ("invalid range image(s)", self.invalid_images),
            ("invalid range-image slice(s)", self.invalid_slices),
            (
                "range-image slice(s) skipped: repeated, out of order or unlike their frame",
                self.slices_out_of_order,
            ),
            (
                "line(s) of streamed range images never arrived (no return there)",
                self.lost_slice_lines,
            ),
            (
                "image(s) skipped: no pose around the capture time",
                self.images_without_pose,
            ),
            (
                "image(s) skipped: older than one already evaluated",
                self.images_out_of_order,
            ),
            (
                "local map reset(s): the pose jumped or ran backwards",
                self.map_resets,
            ),
            (
                "decision cycle(s) skipped: the pose clock jumped ahead by more than 1 s",
                self.skipped_cycles,
            ),
            (
                "obstacle report(s) refused by the local map (-v says why)",
                self.reports_refused,
            ),
            (
                "image(s) never evaluated: the pose stream ends before their capture time",
                self.images_unplaced,
            ),
            (
                "event(s) further out of time order than the reader's window: fed late",
                self.fed_late,
            ),
        ] {
            if n > 0 {
                lines.push(format!("{n} {what}"));
            }
        }
        for (channel, n) in &self.unknown_channels {
            lines.push(format!(
                "{n} message(s) of an unknown type on {channel} (skipped)"
            ));
        }
        for (channel, n) in &self.ignored {
            lines.push(format!("{n} message(s) on {channel} not used by replay"));
        }
        for (channel, n) in &self.foreign {
            lines.push(format!(
                "{n} message(s) on {channel}, not an arcnav channel for their type (another program's: skipped)"
            ));
        }
        lines
    }
}
