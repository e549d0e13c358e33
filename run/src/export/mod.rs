//! `arcnav export LOG --mcap OUT` and `arcnav export LOG --bag OUT`: an
//! LCM log as an MCAP file, for Foxglove with Foxglove's own schemas
//! ([`foxglove`]) or as a ROS 2 bag of standard messages for RViz and
//! every ROS 2 tool ([`ros2`]).
//!
//! Both read the log the same way ([`feed`]): each event decoded and
//! handed to the format's writer ([`Sink`]) with its log time; the local
//! map rebuilt each decision cycle from the log's poses and cells when
//! the log holds none (logs of `arcnav sim` and `arcnav run`), as `arcnav
//! replay --recorded-cells` does; each cycle's logged votes fused by the
//! configuration's arbiter to colour the arcs. Messages on channels that
//! are not arcnav's, that do not decode, or that a format has no message
//! for are counted and skipped, by channel and reason.

pub mod foxglove;
pub mod ros2;
mod sink;

use std::path::Path;

use arcnav_arbiter::Arbiter;
use arcnav_bus::lcmtypes::steering_command_t;
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_config::Resolved;
use arcnav_pipeline::Delivery;
use arcnav_vehicle::ArcSet;
use arcnav_wire as wire;

pub use foxglove::{returns, topic};
pub use sink::{ExportError, ExportSummary, FusedArcs, Sink};

/// Writes `log` as MCAP for Foxglove to `out`; the arc set and the fused
/// votes follow `config`.
pub fn export_mcap(
    log: &Path,
    out: &Path,
    config: &Resolved,
) -> Result<ExportSummary, ExportError> {
    let mut sink = foxglove::Foxglove::create(out)?;
    let summary = feed(log, config, &mut sink)?;
    sink.finish()?;
    Ok(summary)
}

/// Writes `log` as a ROS 2 bag (one MCAP file, CDR messages) to `out`; the
/// vehicle's geometry, the arc set and the fused votes follow `config`.
pub fn export_bag(log: &Path, out: &Path, config: &Resolved) -> Result<ExportSummary, ExportError> {
    let mut sink = ros2::Ros2Bag::create(out, config)?;
    let summary = feed(log, config, &mut sink)?;
    sink.finish()?;
    Ok(summary)
}

/// Reads every event of `log` into `sink`. A log with no event is an
/// error (the caller then writes nothing).
pub fn feed(
    log: &Path,
    config: &Resolved,
    sink: &mut impl Sink,
) -> Result<ExportSummary, ExportError> {
    let arcs = config.arcs.clone();
    let mut arbiter: Arbiter = config.arbiter();
    let mut reader = LogReader::open(log).map_err(read_error(log))?;
    // Logs of `arcnav sim` and `arcnav run` hold no LOCAL_MAP: rebuild it.
    let mut rebuilt = if has_channel(log, channels::LOCAL_MAP)? {
        None
    } else {
        Some((
            config.decision_cycle::<()>(Delivery::held(&config.pipeline)),
            Vec::new(),
        ))
    };
    let mut summary = ExportSummary::default();
    loop {
        let event = match reader.next_event() {
            Ok(Some(event)) => event,
            Ok(None) => break,
            Err(source) => return Err(read_error(log)(source)),
        };
        summary.events += 1;
        let time = sink::nanos(event.timestamp);
        let Some(message) = decoded(&mut summary, &event.channel, &event.data) else {
            continue;
        };
        let summary = &mut summary;
        match message {
            AnyMessage::Pose(msg) => {
                if let (Some((cycle, out)), Ok(pose)) =
                    (&mut rebuilt, arcnav_vehicle::Pose::try_from(&msg))
                {
                    cycle.on_pose(pose, out);
                    cycle.advance(pose.utime, true, out);
                }
                sink.pose(&msg, time, summary);
            }
            AnyMessage::RangeImage(msg) => match wire::range_image_from_wire(msg) {
                Ok(image) => sink.image(&event.channel, &image, time, summary),
                Err(e) => summary.skip(&event.channel, format!("range image refused: {e}")),
            },
            // Each slice is a cloud of its own, on its sensor's topic.
            AnyMessage::RangeSlice(msg) => match wire::range_slice_from_wire(msg) {
                Ok(slice) => sink.image(&event.channel, &slice.to_image(), time, summary),
                Err(e) => summary.skip(&event.channel, format!("range slice refused: {e}")),
            },
            AnyMessage::ObstacleCells(msg) => {
                if let Some((cycle, out)) = &mut rebuilt
                    && let Ok(report) = wire::obstacles_from_wire(msg.clone())
                {
                    cycle.on_report(report, (), out);
                }
                sink.obstacle_cells(&msg, time, summary);
            }
            AnyMessage::LocalMap(msg) => sink.local_map(&msg, time, summary),
            AnyMessage::Waypoints(msg) => sink.waypoints(&msg, time, summary),
            AnyMessage::ArcVotes(msg) => {
                match wire::votes_from_wire(&msg, &arcs) {
                    Ok(votes) => {
                        let _ = arbiter.on_votes(&votes);
                    }
                    // Written as they are, not fused into the arcs.
                    Err(e) => summary.skip(
                        &format!("{} (fused)", event.channel),
                        format!(
                            "not fused into /arcs: {e} (give the log's configuration with --config)"
                        ),
                    ),
                }
                sink.votes(&event.channel, &msg, time, summary);
            }
            AnyMessage::Decision(msg) => sink.decision(&msg, time, summary),
            AnyMessage::GuardStatus(msg) => sink.guard(&msg, time, summary),
            command @ (AnyMessage::SteeringCommand(_) | AnyMessage::DriveCommand(_)) => {
                // A skid-steer vehicle's drive_command_t is drawn as the
                // steering_command_t it extends (a turn in place with its
                // infinite curvature).
                let Some(command) = command.as_command() else {
                    unreachable!("a command message")
                };
                let msg = arcnav_bus::lcmtypes::steering_command_t::from(&command);
                arbiter.decide(msg.utime);
                // A command whose arc is not this arc set's was decided over
                // another: drawn here, its index would mark the wrong arc.
                let fused = arbiter.decision().map(|d| d.fused.as_slice());
                let drawn = commanded_arc_is_in(&arcs, &msg).then(|| FusedArcs {
                    arcs: &arcs,
                    fused: fused.unwrap_or_default(),
                });
                if drawn.is_none() {
                    summary.skip(
                        "STEERING_COMMAND (/arcs)",
                        format!(
                            "its arc_index names an arc of another curvature among this \
                             configuration's {} arcs: the log was made with another arc set \
                             (give its configuration with --config)",
                            arcs.len()
                        ),
                    );
                }
                sink.command(&msg, drawn, time, summary);
            }
        }
        if let Some((_, out)) = &mut rebuilt {
            for cycle in out.drain(..) {
                let msg = wire::map_to_wire(cycle.utime, &cycle.pose, &cycle.map, cycle.resets);
                sink.local_map(&msg, sink::nanos(cycle.utime), summary);
            }
        }
    }
    let stats = reader.stats();
    summary.damaged_bytes = stats.skipped_bytes + stats.truncated_tail_bytes;
    // Nothing read is a failure: the caller writes nothing, and any old
    // file at its output stays as it was.
    if summary.events == 0 {
        return Err(ExportError::Empty {
            path: log.display().to_string(),
            damaged_bytes: summary.damaged_bytes,
        });
    }
    Ok(summary)
}

/// The arcnav message an event holds, on arcnav's channel for it; else
/// none, the event counted as skipped with why.
fn decoded(summary: &mut ExportSummary, channel: &str, data: &[u8]) -> Option<AnyMessage> {
    match AnyMessage::decode(data) {
        Ok(Some(m)) if m.on_its_channel(channel) => Some(m),
        Ok(Some(m)) => {
            summary.skip(
                channel,
                format!("a {} on a channel not arcnav's for it", m.type_name()),
            );
            None
        }
        Ok(None) => {
            summary.skip(channel, "not an arcnav message type");
            None
        }
        Err(e) => {
            summary.skip(channel, format!("does not decode: {e}"));
            None
        }
    }
}

/// Whether `msg`'s arc index names an arc of `arcs` with its curvature (a
/// stop, index -1, is in every set).
fn commanded_arc_is_in(arcs: &ArcSet, msg: &steering_command_t) -> bool {
    let Ok(index) = usize::try_from(msg.arc_index) else {
        return true;
    };
    arcs.curvatures().get(index).is_some_and(|&k| {
        // A turn in place's ±∞ is equal, not near.
        k == msg.curvature || (k - msg.curvature).abs() <= 1e-9_f64.max(1e-6 * k.abs())
    })
}

/// The error of reading `log`.
fn read_error(log: &Path) -> impl Fn(std::io::Error) -> ExportError + '_ {
    move |source| ExportError::Read {
        path: log.display().to_string(),
        source,
    }
}

/// Whether `log` holds any message on `channel`.
fn has_channel(log: &Path, channel: &str) -> Result<bool, ExportError> {
    let mut reader = LogReader::open(log).map_err(read_error(log))?;
    while let Some(event) = reader.next_event().map_err(read_error(log))? {
        if event.channel == channel {
            return Ok(true);
        }
    }
    Ok(false)
}
