//! `arcnav export LOG --mcap OUT`: an LCM log as an MCAP file that Foxglove
//! opens as a scene, written through Foxglove's own SDK (the `foxglove`
//! crate: its MCAP writer and its published protobuf schemas).
//!
//! | LCM channel | MCAP topic | schema |
//! |---|---|---|
//! | POSE | `/pose` (world frame) and `/tf` (world → vehicle) | `foxglove.PoseInFrame`, `foxglove.FrameTransforms` |
//! | RANGE_IMAGE* | `/range_image*`: x, y, z, range per return, vehicle frame | `foxglove.PointCloud` |
//! | OBSTACLE_CELLS | `/obstacle_cells`: a cube per cell, world frame | `foxglove.SceneUpdate` |
//! | LOCAL_MAP | `/local_map`: a cube per patch, world frame | `foxglove.SceneUpdate` |
//! | (no LOCAL_MAP) | `/local_map`, rebuilt each decision cycle from the log's POSE and OBSTACLE_CELLS by the pipeline's own local map, as `arcnav replay --recorded-cells` does | `foxglove.SceneUpdate` |
//! | WAYPOINTS | `/waypoints`: a sphere per waypoint, arrival radius | `foxglove.SceneUpdate` |
//! | ARC_VOTES_NAME | `/arc_votes_name`: votes, vetoes, speed vote | JSON (`arcnav.ArcVotes`) |
//! | STEERING_COMMAND | `/steering_command`: curvature, speed, arc, vote | JSON (`arcnav.SteeringCommand`) |
//! | STEERING_COMMAND | `/arcs`: every arc coloured by the fused vote of that cycle's logged votes, the chosen one wider, vehicle frame | `foxglove.SceneUpdate` |
//!
//! Each message keeps its log time; each topic holds as many messages as
//! its channel in the log. Messages on channels that are not arcnav's, or
//! that do not decode, are counted and skipped.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use arcnav_arbiter::Arbiter;
use arcnav_bus::lcmtypes::{
    arc_votes_t, decision_t, local_map_t, obstacle_cells_t, pose_t, steering_command_t, waypoints_t,
};
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_pipeline::Delivery;
use arcnav_vehicle::{ArcSet, Isometry};
use foxglove::schemas::{
    Color, CubePrimitive, FrameTransform, FrameTransforms, LinePrimitive, PackedElementField,
    Point3, Pose, PoseInFrame, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp,
    Vector3, line_primitive, packed_element_field,
};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use serde::Serialize;

use crate::output::Staged;
use arcnav_config::Resolved;
use arcnav_wire as wire;

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
    fn skip(&mut self, channel: &str, why: impl Into<String>) {
        let entry = self
            .skipped
            .entry(channel.to_owned())
            .or_insert((0, why.into()));
        entry.0 += 1;
    }
}

/// The topic of an LCM channel.
pub fn topic(channel: &str) -> String {
    format!("/{}", channel.to_ascii_lowercase())
}

fn timestamp(utime: i64) -> Timestamp {
    let utime = u64::try_from(utime).unwrap_or(0);
    Timestamp::new_checked(
        u32::try_from(utime / 1_000_000).unwrap_or(u32::MAX),
        u32::try_from((utime % 1_000_000) * 1000).unwrap_or(0),
    )
    .unwrap_or(Timestamp::MAX)
}

fn nanos(utime: i64) -> u64 {
    u64::try_from(utime).unwrap_or(0).saturating_mul(1000)
}

fn rgba(c: [f64; 4]) -> Color {
    Color {
        r: c[0],
        g: c[1],
        b: c[2],
        a: c[3],
    }
}

fn at(x: f64, y: f64, z: f64) -> Option<Pose> {
    Some(Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    })
}

/// A box on the ground cell centred at (x, y), `size` across, from `z_min`
/// to `z_max` (at least 5 cm tall), world frame.
fn cell_cube(x: f64, y: f64, size: f32, z: [f32; 2], color: [f64; 4]) -> CubePrimitive {
    let height = f64::from((z[1] - z[0]).max(0.05));
    CubePrimitive {
        pose: at(x, y, f64::from(z[0]) + height / 2.0),
        size: Some(Vector3 {
            x: f64::from(size),
            y: f64::from(size),
            z: height,
        }),
        color: Some(rgba(color)),
    }
}

/// Red (-1) through yellow (0) to green (+1), as `arcnav render` draws votes.
fn vote_color(v: f32) -> Color {
    let [r, g, b, _] = crate::render::vote_color(v);
    rgba([
        f64::from(r) / 255.0,
        f64::from(g) / 255.0,
        f64::from(b) / 255.0,
        1.0,
    ])
}

/// The typed channels, made as their topics first appear.
struct Topics {
    ctx: Arc<Context>,
    transforms: Option<Channel<FrameTransforms>>,
    poses: Option<Channel<PoseInFrame>>,
    clouds: BTreeMap<String, Channel<foxglove::schemas::PointCloud>>,
    scenes: BTreeMap<String, Channel<SceneUpdate>>,
    json: BTreeMap<String, Arc<RawChannel>>,
}

impl Topics {
    /// Logs the returns of `image` as a point cloud on `topic`.
    fn cloud(&mut self, topic: &str, image: &arcnav_perception::RangeImage, time: PartialMetadata) {
        let ctx = &self.ctx;
        self.clouds
            .entry(topic.to_owned())
            .or_insert_with(|| ctx.channel_builder(topic).build())
            .log_with_meta(&point_cloud(image), time);
    }

    /// Logs `entity` (stamped `utime`, in `frame`) as the one entity of a
    /// scene update on `topic`.
    fn scene(
        &mut self,
        topic: &str,
        utime: i64,
        frame: &str,
        entity: SceneEntity,
        time: PartialMetadata,
    ) {
        let ctx = &self.ctx;
        let entity = SceneEntity {
            timestamp: Some(timestamp(utime)),
            frame_id: frame.into(),
            ..entity
        };
        self.scenes
            .entry(topic.to_owned())
            .or_insert_with(|| ctx.channel_builder(topic).build())
            .log_with_meta(
                &SceneUpdate {
                    deletions: Vec::new(),
                    entities: vec![entity],
                },
                time,
            );
    }

    /// The JSON channel of `topic` (`None` only if the SDK refused it).
    fn json(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema: &'static str,
    ) -> Option<Arc<RawChannel>> {
        if let Some(channel) = self.json.get(topic) {
            return Some(Arc::clone(channel));
        }
        let channel = self
            .ctx
            .channel_builder(topic)
            .message_encoding("json")
            .schema(Schema::new(schema_name, "jsonschema", schema.as_bytes()))
            .build_raw()
            .ok()?;
        self.json.insert(topic.to_owned(), Arc::clone(&channel));
        Some(channel)
    }
}

impl ExportSummary {
    /// The arcnav message an event holds, on arcnav's channel for it; else
    /// none, the event counted as skipped with why.
    fn decoded(&mut self, channel: &str, data: &[u8]) -> Option<AnyMessage> {
        match AnyMessage::decode(data) {
            Ok(Some(m)) if m.on_its_channel(channel) => Some(m),
            Ok(Some(m)) => {
                self.skip(
                    channel,
                    format!("a {} on a channel not arcnav's for it", m.type_name()),
                );
                None
            }
            Ok(None) => {
                self.skip(channel, "not an arcnav message type");
                None
            }
            Err(e) => {
                self.skip(channel, format!("does not decode: {e}"));
                None
            }
        }
    }
}

/// The scenes and transforms of one message each.
impl Topics {
    /// A pose as the vehicle's transform (`/tf`) and as `/pose`.
    fn pose(&mut self, msg: &pose_t, time: PartialMetadata) {
        let [w, x, y, z] = msg.orientation;
        let [px, py, pz] = msg.position;
        let rotation = Some(Quaternion { x, y, z, w });
        let translation = Some(Vector3 {
            x: px,
            y: py,
            z: pz,
        });
        let transforms = self
            .transforms
            .get_or_insert_with(|| self.ctx.channel_builder("/tf").build());
        transforms.log_with_meta(
            &FrameTransforms {
                transforms: vec![FrameTransform {
                    timestamp: Some(timestamp(msg.utime)),
                    parent_frame_id: "world".into(),
                    child_frame_id: "vehicle".into(),
                    translation,
                    rotation,
                }],
            },
            time,
        );
        let poses = self
            .poses
            .get_or_insert_with(|| self.ctx.channel_builder("/pose").build());
        poses.log_with_meta(
            &PoseInFrame {
                timestamp: Some(timestamp(msg.utime)),
                frame_id: "world".into(),
                pose: Some(Pose {
                    position: translation,
                    orientation: rotation,
                }),
            },
            time,
        );
    }

    /// Obstacle cells as cubes (`/obstacle_cells`): obstacles red, graded
    /// ground purple by cost.
    fn obstacle_cells(&mut self, msg: &obstacle_cells_t, time: PartialMetadata) {
        let cubes = msg
            .cells
            .iter()
            .map(|c| {
                cell_cube(
                    c.x,
                    c.y,
                    msg.cell_size,
                    [c.z_min, c.z_max],
                    // Obstacles red, graded ground purple by cost.
                    if c.cost >= 1.0 {
                        [0.85, 0.15, 0.1, 0.8]
                    } else {
                        [0.5, 0.15, 0.6, 0.2 + 0.6 * f64::from(c.cost)]
                    },
                )
            })
            .collect();
        let entity = SceneEntity {
            id: format!("cells {}", msg.sensor),
            cubes,
            ..SceneEntity::default()
        };
        self.scene("/obstacle_cells", msg.utime, "world", entity, time);
    }

    /// Waypoints as spheres of their radius (`/waypoints`).
    fn waypoints(&mut self, msg: &waypoints_t, time: PartialMetadata) {
        let spheres = msg
            .position
            .iter()
            .zip(&msg.radius)
            .map(|(p, &r)| {
                let d = 2.0 * f64::from(r).max(1.0);
                SpherePrimitive {
                    pose: at(p[0], p[1], 0.0),
                    size: Some(Vector3 { x: d, y: d, z: 0.5 }),
                    color: Some(rgba([0.1, 0.4, 0.9, 0.5])),
                }
            })
            .collect();
        let entity = SceneEntity {
            id: "waypoints".into(),
            spheres,
            ..SceneEntity::default()
        };
        self.scene("/waypoints", msg.utime, "world", entity, time);
    }
    /// An arc-votes message as JSON on `topic`; false when the writer
    /// refused the topic.
    fn votes_json(&mut self, topic: &str, msg: &arc_votes_t, time: PartialMetadata) -> bool {
        let json = serde_json::json!({
            "utime": msg.utime,
            "behaviour": msg.behaviour,
            "curvature": msg.curvature,
            "votes": msg.votes,
            "vetoed": msg.vetoed,
            "speed_vote": msg.has_speed_vote.then_some(msg.speed_vote),
        });
        let Some(channel) = self.json(topic, "arcnav.ArcVotes", VOTES_SCHEMA) else {
            return false;
        };
        channel.log_with_meta(json.to_string().as_bytes(), time);
        true
    }

    /// A steering command as JSON (`/steering_command`); false when the
    /// writer refused the topic.
    fn command_json(&mut self, msg: &steering_command_t, time: PartialMetadata) -> bool {
        let json = serde_json::json!({
            "utime": msg.utime,
            "curvature": msg.curvature,
            "speed_mps": msg.speed,
            "arc_index": msg.arc_index,
            "vote": msg.vote,
        });
        let Some(channel) = self.json(
            "/steering_command",
            "arcnav.SteeringCommand",
            COMMAND_SCHEMA,
        ) else {
            return false;
        };
        channel.log_with_meta(json.to_string().as_bytes(), time);
        true
    }

    /// Why a command is what it is (`/decision`, from `DECISION`).
    fn decision_json(&mut self, msg: &decision_t, time: PartialMetadata) -> bool {
        let vetoers: Vec<serde_json::Value> = (0..msg.vetoer.len())
            .map(|i| {
                serde_json::json!({
                    "behaviour": msg.vetoer[i],
                    "arcs": msg.vetoed_arcs[i],
                    "cell": msg.has_cell[i].then(|| [msg.cell_x[i], msg.cell_y[i]]),
                })
            })
            .collect();
        let json = serde_json::json!({
            "utime": msg.utime,
            "cause": msg.cause,
            "reason": msg.reason,
            "vetoers": vetoers,
        });
        let Some(channel) = self.json("/decision", "arcnav.Decision", DECISION_SCHEMA) else {
            return false;
        };
        channel.log_with_meta(json.to_string().as_bytes(), time);
        true
    }

    /// The guard's verdicts (`/guard_status`, from `GUARD_STATUS`).
    fn guard_json(
        &mut self,
        msg: &arcnav_bus::lcmtypes::guard_status_t,
        time: PartialMetadata,
    ) -> bool {
        let json = serde_json::json!({
            "utime": msg.utime,
            "command_utime": msg.command_utime,
            "verdict": msg.verdict,
            "reason": msg.reason,
            "speed_cap_mps": msg.speed_cap,
        });
        let Some(channel) = self.json("/guard_status", "arcnav.GuardStatus", GUARD_SCHEMA) else {
            return false;
        };
        channel.log_with_meta(json.to_string().as_bytes(), time);
        true
    }

    /// The arcs by their fused vote, the commanded one marked (`/arcs`).
    fn arcs(
        &mut self,
        arcs: &ArcSet,
        fused: &[f32],
        msg: &steering_command_t,
        time: PartialMetadata,
    ) {
        let chosen = usize::try_from(msg.arc_index).ok();
        let entity = SceneEntity {
            id: "arcs".into(),
            lines: arc_lines(arcs, fused, chosen),
            ..SceneEntity::default()
        };
        self.scene("/arcs", msg.utime, "vehicle", entity, time);
    }
}

const VOTES_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"behaviour":{"type":"string"},"curvature":{"type":"array","items":{"type":"number"}},"votes":{"type":"array","items":{"type":"number"}},"vetoed":{"type":"array","items":{"type":"boolean"}},"speed_vote":{"type":["number","null"]}}}"#;
const COMMAND_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"curvature":{"type":"number"},"speed_mps":{"type":"number"},"arc_index":{"type":"integer"},"vote":{"type":"number"}}}"#;

const GUARD_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"command_utime":{"type":"integer"},"verdict":{"type":"integer"},"reason":{"type":"string"},"speed_cap_mps":{"type":"number"}}}"#;

const DECISION_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"cause":{"type":"integer"},"reason":{"type":"string"},"vetoers":{"type":"array","items":{"type":"object","properties":{"behaviour":{"type":"string"},"arcs":{"type":"integer"},"cell":{"type":["array","null"],"items":{"type":"number"}}}}}}}"#;

/// Writes `log` as MCAP to `out`; the arc set and the fused votes follow
/// `config`.
pub fn export_mcap(
    log: &Path,
    out: &Path,
    config: &Resolved,
) -> Result<ExportSummary, ExportError> {
    let arcs = config.arcs.clone();
    let mut arbiter: Arbiter = config.arbiter();
    let mut reader = LogReader::open(log).map_err(read_error(log))?;
    let write_error = |reason: String| ExportError::Write {
        path: out.display().to_string(),
        reason,
    };
    // Written whole or not at all: beside `out`, renamed onto it at the end.
    let (staged, file) = Staged::create(out).map_err(|e| write_error(e.to_string()))?;
    let ctx = Context::new();
    let writer = ctx
        .mcap_writer()
        .create(std::io::BufWriter::new(file))
        .map_err(|e| write_error(e.to_string()))?;
    let mut topics = Topics {
        ctx: Arc::clone(&ctx),
        transforms: None,
        poses: None,
        clouds: BTreeMap::new(),
        scenes: BTreeMap::new(),
        json: BTreeMap::new(),
    };
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
    // Messages the MCAP writer would not take a channel for.
    let mut refused_topics = 0u64;
    loop {
        let event = match reader.next_event() {
            Ok(Some(event)) => event,
            Ok(None) => break,
            Err(source) => return Err(read_error(log)(source)),
        };
        summary.events += 1;
        let time = PartialMetadata::with_log_time(nanos(event.timestamp));
        let Some(message) = summary.decoded(&event.channel, &event.data) else {
            continue;
        };
        let mut wrote = |topic: &str| *summary.topics.entry(topic.to_owned()).or_default() += 1;
        // Said in the summary once the message is handled.
        let mut not_drawn: Option<(String, String)> = None;
        match message {
            AnyMessage::Pose(msg) => {
                if let (Some((cycle, out)), Ok(pose)) =
                    (&mut rebuilt, arcnav_vehicle::Pose::try_from(&msg))
                {
                    cycle.on_pose(pose, out);
                    cycle.advance(pose.utime, true, out);
                }
                topics.pose(&msg, time);
                wrote("/tf");
                wrote("/pose");
            }
            AnyMessage::RangeImage(msg) => {
                let topic = topic(&event.channel);
                match wire::range_image_from_wire(msg) {
                    Ok(image) => {
                        topics.cloud(&topic, &image, time);
                        wrote(&topic);
                    }
                    Err(e) => summary.skip(&event.channel, format!("range image refused: {e}")),
                }
            }
            // Each slice is a cloud of its own, on its sensor's topic.
            AnyMessage::RangeSlice(msg) => {
                let topic = topic(&event.channel);
                match wire::range_slice_from_wire(msg) {
                    Ok(slice) => {
                        topics.cloud(&topic, &slice.to_image(), time);
                        wrote(&topic);
                    }
                    Err(e) => summary.skip(&event.channel, format!("range slice refused: {e}")),
                }
            }
            AnyMessage::ObstacleCells(msg) => {
                if let Some((cycle, out)) = &mut rebuilt
                    && let Ok(report) = wire::obstacles_from_wire(msg.clone())
                {
                    cycle.on_report(report, (), out);
                }
                topics.obstacle_cells(&msg, time);
                wrote("/obstacle_cells");
            }
            AnyMessage::LocalMap(msg) => {
                local_map_scene(&mut topics, &msg, time);
                wrote("/local_map");
            }
            AnyMessage::Waypoints(msg) => {
                topics.waypoints(&msg, time);
                wrote("/waypoints");
            }
            AnyMessage::ArcVotes(msg) => {
                let topic = topic(&event.channel);
                match wire::votes_from_wire(&msg, &arcs) {
                    Ok(votes) => {
                        let _ = arbiter.on_votes(&votes);
                    }
                    // Written to their topic, not fused into `/arcs`.
                    Err(e) => {
                        not_drawn = Some((
                            format!("{} (fused)", event.channel),
                            format!(
                                "not fused into /arcs: {e} (give the log's configuration with --config)"
                            ),
                        ));
                    }
                }
                match topics.votes_json(&topic, &msg, time) {
                    true => wrote(&topic),
                    false => refused_topics += 1,
                }
            }
            AnyMessage::Decision(msg) => match topics.decision_json(&msg, time) {
                true => wrote("/decision"),
                false => refused_topics += 1,
            },
            AnyMessage::GuardStatus(msg) => match topics.guard_json(&msg, time) {
                true => wrote("/guard_status"),
                false => refused_topics += 1,
            },
            AnyMessage::SteeringCommand(msg) => {
                match topics.command_json(&msg, time) {
                    true => wrote("/steering_command"),
                    false => refused_topics += 1,
                }
                arbiter.decide(msg.utime);
                // A command whose arc is not this arc set's was decided over
                // another: drawn here, its index would mark the wrong arc.
                if commanded_arc_is_in(&arcs, &msg) {
                    let fused = arbiter.decision().map(|d| d.fused.as_slice());
                    topics.arcs(&arcs, fused.unwrap_or_default(), &msg, time);
                    wrote("/arcs");
                } else {
                    not_drawn = Some((
                        "STEERING_COMMAND (/arcs)".to_owned(),
                        format!(
                            "its arc_index names an arc of another curvature among this \
                             configuration's {} arcs: the log was made with another arc set \
                             (give its configuration with --config)",
                            arcs.len()
                        ),
                    ));
                }
            }
        }
        if let Some((channel, why)) = not_drawn {
            summary.skip(&channel, why);
        }
        if let Some((_, out)) = &mut rebuilt {
            for cycle in out.drain(..) {
                let msg = wire::map_to_wire(cycle.utime, &cycle.pose, &cycle.map, cycle.resets);
                let time = PartialMetadata::with_log_time(nanos(cycle.utime));
                local_map_scene(&mut topics, &msg, time);
                *summary.topics.entry("/local_map".into()).or_default() += 1;
            }
        }
    }
    if refused_topics > 0 {
        summary.skipped.insert(
            "(any)".into(),
            (refused_topics, "the MCAP writer refused their topic".into()),
        );
    }
    let stats = reader.stats();
    summary.damaged_bytes = stats.skipped_bytes + stats.truncated_tail_bytes;
    // Nothing read is a failure: the staged file is dropped, and any old
    // file at `out` stays as it was.
    if summary.events == 0 {
        return Err(ExportError::Empty {
            path: log.display().to_string(),
            damaged_bytes: summary.damaged_bytes,
        });
    }
    let file = writer
        .close()
        .map_err(|e| write_error(e.to_string()))?
        .into_inner()
        .map_err(|e| write_error(e.error().to_string()))?;
    staged
        .commit(file)
        .map_err(|e| write_error(e.to_string()))?;
    Ok(summary)
}

/// Whether `msg`'s arc index names an arc of `arcs` with its curvature (a
/// stop, index -1, is in every set).
fn commanded_arc_is_in(arcs: &ArcSet, msg: &steering_command_t) -> bool {
    let Ok(index) = usize::try_from(msg.arc_index) else {
        return true;
    };
    arcs.curvatures()
        .get(index)
        .is_some_and(|&k| (k - msg.curvature).abs() <= 1e-9_f64.max(1e-6 * k.abs()))
}

/// The error of reading `log`.
fn read_error(log: &Path) -> impl Fn(std::io::Error) -> ExportError + '_ {
    move |source| ExportError::Read {
        path: log.display().to_string(),
        source,
    }
}

/// Logs `map` on `/local_map`: a cube per patch, world frame.
fn local_map_scene(topics: &mut Topics, map: &local_map_t, time: PartialMetadata) {
    let cubes = map
        .patches
        .iter()
        .map(|p| {
            let z = [p.z_min, p.z_max];
            cell_cube(
                p.world_x,
                p.world_y,
                map.patch_size,
                z,
                [0.55, 0.2, 0.65, 0.6],
            )
        })
        .collect();
    let entity = SceneEntity {
        id: "local_map".into(),
        cubes,
        ..SceneEntity::default()
    };
    topics.scene("/local_map", map.utime, "world", entity, time);
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

/// Each arc as a 12 m polyline from the vehicle origin, coloured by its
/// fused vote (grey when there is none), the chosen one wider.
fn arc_lines(arcs: &ArcSet, fused: &[f32], chosen: Option<usize>) -> Vec<LinePrimitive> {
    const LENGTH_M: f64 = 12.0;
    arcs.curvatures()
        .iter()
        .enumerate()
        .map(|(i, &k)| {
            let points = (0..=24)
                .map(|s| {
                    let s = LENGTH_M * f64::from(s) / 24.0;
                    let (x, y) = if k.abs() < 1e-9 {
                        (s, 0.0)
                    } else {
                        ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
                    };
                    Point3 { x, y, z: 0.3 }
                })
                .collect();
            let color = fused
                .get(i)
                .map_or(rgba([0.6, 0.6, 0.6, 0.6]), |&v| vote_color(v));
            LinePrimitive {
                r#type: line_primitive::Type::LineStrip as i32,
                pose: at(0.0, 0.0, 0.0),
                thickness: if Some(i) == chosen { 0.12 } else { 0.04 },
                scale_invariant: false,
                points,
                color: Some(color),
                ..LinePrimitive::default()
            }
        })
        .collect()
}

/// The returns of an image as x, y, z (vehicle frame) and range, float32.
fn point_cloud(image: &arcnav_perception::RangeImage) -> foxglove::schemas::PointCloud {
    let mount: &Isometry = &image.vehicle_from_sensor;
    let cols = image.cols();
    let mut data = Vec::with_capacity(image.range.len() * 16);
    for (i, &r) in image.range.iter().enumerate() {
        if !(r.is_finite() && r > 0.0) {
            continue;
        }
        let Some(d) = image.beams.direction(i / cols, i % cols) else {
            continue;
        };
        let r64 = f64::from(r);
        let p = mount * nalgebra::Point3::new(d[0] * r64, d[1] * r64, d[2] * r64);
        for v in [p.x as f32, p.y as f32, p.z as f32, r] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    let field = |name: &str, offset: u32| PackedElementField {
        name: name.into(),
        offset,
        r#type: packed_element_field::NumericType::Float32 as i32,
    };
    foxglove::schemas::PointCloud {
        timestamp: Some(timestamp(image.utime)),
        frame_id: "vehicle".into(),
        pose: at(0.0, 0.0, 0.0),
        point_stride: 16,
        fields: vec![
            field("x", 0),
            field("y", 4),
            field("z", 8),
            field("range", 12),
        ],
        data: data.into(),
    }
}

/// How many returns an image holds (the points of its cloud).
pub fn returns(image: &arcnav_perception::RangeImage) -> usize {
    image
        .range
        .iter()
        .enumerate()
        .filter(|(i, r)| {
            r.is_finite()
                && **r > 0.0
                && image
                    .beams
                    .direction(i / image.cols(), i % image.cols())
                    .is_some()
        })
        .count()
}
