//! What every export shares: its errors, its summary, and the writer of one
//! format ([`Sink`]) that the export's reading of the log feeds.

use std::collections::BTreeMap;

use arcnav_bus::lcmtypes::{
    arc_votes_t, decision_t, guard_status_t, local_map_t, obstacle_cells_t, pose_t,
    steering_command_t, waypoints_t,
};
use arcnav_perception::RangeImage;
use arcnav_vehicle::ArcSet;
use serde::Serialize;

/// An export that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("cannot write {path}: {reason}")]
    Write { path: String, reason: String },
    #[error(
        "no LCM event could be read from {path} ({damaged_bytes} bytes skipped as damaged): is it an LCM log?"
    )]
    Empty { path: String, damaged_bytes: u64 },
    #[error("invalid configuration: {0}")]
    Config(#[from] arcnav_vehicle::ConfigError),
}

/// What an export wrote and skipped.
#[derive(Debug, Default, Clone, Serialize)]
pub struct ExportSummary {
    pub events: u64,
    /// Messages written per topic.
    pub topics: BTreeMap<String, u64>,
    /// Events skipped, per channel, with why.
    pub skipped: BTreeMap<String, (u64, String)>,
    /// Bytes of the log that were not LCM events.
    pub damaged_bytes: u64,
}

impl ExportSummary {
    /// Counts an event of `channel` skipped (the first reason given stays).
    pub fn skip(&mut self, channel: &str, why: impl Into<String>) {
        let entry = self
            .skipped
            .entry(channel.to_owned())
            .or_insert((0, why.into()));
        entry.0 += 1;
    }

    /// Counts a message written on `topic`.
    pub fn wrote(&mut self, topic: &str) {
        *self.topics.entry(topic.to_owned()).or_default() += 1;
    }
}

/// The arcs of a command's cycle: the arc set and the fused votes of the
/// cycle's logged votes (empty when none were logged), for drawing.
pub struct FusedArcs<'a> {
    pub arcs: &'a ArcSet,
    pub fused: &'a [f32],
}

/// One export format: each message of the log, decoded, handed to the
/// writer of that format with the event's log time (ns). Each method
/// counts in `summary` what it wrote, or why it skipped the message.
pub trait Sink {
    fn pose(&mut self, msg: &pose_t, time: u64, summary: &mut ExportSummary);
    /// A range image (a slice: the image of its columns) from `channel`.
    fn image(&mut self, channel: &str, image: &RangeImage, time: u64, summary: &mut ExportSummary);
    fn obstacle_cells(&mut self, msg: &obstacle_cells_t, time: u64, summary: &mut ExportSummary);
    /// The local map, logged or rebuilt from the log's poses and cells.
    fn local_map(&mut self, msg: &local_map_t, time: u64, summary: &mut ExportSummary);
    fn waypoints(&mut self, msg: &waypoints_t, time: u64, summary: &mut ExportSummary);
    fn votes(&mut self, channel: &str, msg: &arc_votes_t, time: u64, summary: &mut ExportSummary);
    fn decision(&mut self, msg: &decision_t, time: u64, summary: &mut ExportSummary);
    fn guard(&mut self, msg: &guard_status_t, time: u64, summary: &mut ExportSummary);
    /// A command, and its cycle's arcs when its arc is one of the arc set's.
    fn command(
        &mut self,
        msg: &steering_command_t,
        arcs: Option<FusedArcs<'_>>,
        time: u64,
        summary: &mut ExportSummary,
    );
}

/// Nanoseconds of a log's µs time (0 before the epoch).
pub fn nanos(utime: i64) -> u64 {
    u64::try_from(utime).unwrap_or(0).saturating_mul(1000)
}

/// Each arc as a polyline of 25 points over its first 12 m from the
/// vehicle's origin (vehicle frame, 0.3 m up).
pub fn arc_polylines(arcs: &ArcSet) -> Vec<Vec<[f64; 3]>> {
    const LENGTH_M: f64 = 12.0;
    arcs.curvatures()
        .iter()
        .map(|&k| {
            (0..=24)
                .map(|s| {
                    let s = LENGTH_M * f64::from(s) / 24.0;
                    let (x, y) = if k.abs() < 1e-9 {
                        (s, 0.0)
                    } else {
                        ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
                    };
                    [x, y, 0.3]
                })
                .collect()
        })
        .collect()
}

/// Red (-1) through yellow (0) to green (+1), as `arcnav render` draws
/// votes, in [0, 1] per channel.
pub fn vote_rgb(v: f32) -> [f64; 3] {
    let [r, g, b, _] = crate::render::vote_color(v);
    [r, g, b].map(|c| f64::from(c) / 255.0)
}

/// An obstacle cell's colour (RGBA in [0, 1]): obstacles red, graded
/// ground purple by cost.
pub fn cell_rgba(cost: f32) -> [f64; 4] {
    if cost >= 1.0 {
        [0.85, 0.15, 0.1, 0.8]
    } else {
        [0.5, 0.15, 0.6, 0.2 + 0.6 * f64::from(cost)]
    }
}

/// A local-map patch's colour (RGBA in [0, 1]).
pub const PATCH_RGBA: [f64; 4] = [0.55, 0.2, 0.65, 0.6];
/// A waypoint's colour (RGBA in [0, 1]).
pub const WAYPOINT_RGBA: [f64; 4] = [0.1, 0.4, 0.9, 0.5];

/// The returns of an image: (row, column, range, point in the sensor
/// frame) of each finite, positive range whose beam has a direction.
pub fn returns_of(image: &RangeImage) -> impl Iterator<Item = (usize, usize, f32, [f64; 3])> + '_ {
    let cols = image.cols();
    image.range.iter().enumerate().filter_map(move |(i, &r)| {
        if !(r.is_finite() && r > 0.0) {
            return None;
        }
        let (row, col) = (i / cols, i % cols);
        let d = image.beams.direction(row, col)?;
        let r64 = f64::from(r);
        Some((row, col, r, [d[0] * r64, d[1] * r64, d[2] * r64]))
    })
}
