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
//! its channel in the log.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;
use std::sync::Arc;

use arcnav_bus::lcmtypes::{
    arc_votes_t, decision_t, guard_status_t, local_map_t, obstacle_cells_t, pose_t,
    steering_command_t, waypoints_t,
};
use foxglove::schemas::{
    Color, CubePrimitive, FrameTransform, FrameTransforms, LinePrimitive, PackedElementField,
    Point3, Pose, PoseInFrame, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp,
    Vector3, line_primitive, packed_element_field,
};
use foxglove::{Channel, Context, McapWriterHandle, PartialMetadata, RawChannel, Schema};

use super::sink::{
    ExportError, ExportSummary, FusedArcs, PATCH_RGBA, Sink, WAYPOINT_RGBA, arc_polylines,
    cell_rgba, returns_of, vote_rgb,
};
use crate::output::Staged;

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

/// The MCAP file being written, through Foxglove's SDK: the typed channels,
/// made as their topics first appear.
pub struct Foxglove {
    ctx: Arc<Context>,
    writer: McapWriterHandle<BufWriter<std::fs::File>>,
    staged: Staged,
    out: String,
    transforms: Option<Channel<FrameTransforms>>,
    poses: Option<Channel<PoseInFrame>>,
    clouds: BTreeMap<String, Channel<foxglove::schemas::PointCloud>>,
    scenes: BTreeMap<String, Channel<SceneUpdate>>,
    json: BTreeMap<String, Arc<RawChannel>>,
}

impl Foxglove {
    /// Starts an MCAP file for `out`, written beside it and put in its
    /// place by [`finish`](Self::finish) (any file there stays as it was
    /// until then).
    pub fn create(out: &Path) -> Result<Self, ExportError> {
        let write_error = |reason: String| ExportError::Write {
            path: out.display().to_string(),
            reason,
        };
        let (staged, file) = Staged::create(out).map_err(|e| write_error(e.to_string()))?;
        let ctx = Context::new();
        let writer = ctx
            .mcap_writer()
            .create(BufWriter::new(file))
            .map_err(|e| write_error(e.to_string()))?;
        Ok(Self {
            ctx,
            writer,
            staged,
            out: out.display().to_string(),
            transforms: None,
            poses: None,
            clouds: BTreeMap::new(),
            scenes: BTreeMap::new(),
            json: BTreeMap::new(),
        })
    }

    /// Closes the file and puts it in place.
    pub fn finish(self) -> Result<(), ExportError> {
        let write_error = |reason: String| ExportError::Write {
            path: self.out.clone(),
            reason,
        };
        let file = self
            .writer
            .close()
            .map_err(|e| write_error(e.to_string()))?
            .into_inner()
            .map_err(|e| write_error(e.error().to_string()))?;
        self.staged
            .commit(file)
            .map_err(|e| write_error(e.to_string()))
    }

    /// Logs `entity` (stamped `utime`, in `frame`) as the one entity of a
    /// scene update on `topic`.
    fn scene(&mut self, topic: &str, utime: i64, frame: &str, entity: SceneEntity, time: u64) {
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
                PartialMetadata::with_log_time(time),
            );
    }

    /// Logs `json` on `topic` (a JSON channel of `schema`); counted as
    /// written, or as refused when the SDK would not make the channel.
    fn json(
        &mut self,
        topic: &str,
        (schema_name, schema): (&str, &'static str),
        json: serde_json::Value,
        time: u64,
        summary: &mut ExportSummary,
    ) {
        let channel = match self.json.get(topic) {
            Some(channel) => Arc::clone(channel),
            None => match self
                .ctx
                .channel_builder(topic)
                .message_encoding("json")
                .schema(Schema::new(schema_name, "jsonschema", schema.as_bytes()))
                .build_raw()
            {
                Ok(channel) => {
                    self.json.insert(topic.to_owned(), Arc::clone(&channel));
                    channel
                }
                Err(e) => {
                    summary.skip(topic, format!("the MCAP writer refused the topic: {e}"));
                    return;
                }
            },
        };
        channel.log_with_meta(
            json.to_string().as_bytes(),
            PartialMetadata::with_log_time(time),
        );
        summary.wrote(topic);
    }
}

impl Sink for Foxglove {
    /// A pose as the vehicle's transform (`/tf`) and as `/pose`.
    fn pose(&mut self, msg: &pose_t, time: u64, summary: &mut ExportSummary) {
        let [w, x, y, z] = msg.orientation;
        let [px, py, pz] = msg.position;
        let rotation = Some(Quaternion { x, y, z, w });
        let translation = Some(Vector3 {
            x: px,
            y: py,
            z: pz,
        });
        let time = PartialMetadata::with_log_time(time);
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
        summary.wrote("/tf");
        summary.wrote("/pose");
    }

    /// The returns of an image as a point cloud on its channel's topic.
    fn image(
        &mut self,
        channel: &str,
        image: &arcnav_perception::RangeImage,
        time: u64,
        summary: &mut ExportSummary,
    ) {
        let topic = topic(channel);
        let ctx = &self.ctx;
        self.clouds
            .entry(topic.clone())
            .or_insert_with(|| ctx.channel_builder(&topic).build())
            .log_with_meta(&point_cloud(image), PartialMetadata::with_log_time(time));
        summary.wrote(&topic);
    }

    /// Obstacle cells as cubes (`/obstacle_cells`): obstacles red, graded
    /// ground purple by cost.
    fn obstacle_cells(&mut self, msg: &obstacle_cells_t, time: u64, summary: &mut ExportSummary) {
        let cubes = msg
            .cells
            .iter()
            .map(|c| {
                cell_cube(
                    c.x,
                    c.y,
                    msg.cell_size,
                    [c.z_min, c.z_max],
                    cell_rgba(c.cost),
                )
            })
            .collect();
        let entity = SceneEntity {
            id: format!("cells {}", msg.sensor),
            cubes,
            ..SceneEntity::default()
        };
        self.scene("/obstacle_cells", msg.utime, "world", entity, time);
        summary.wrote("/obstacle_cells");
    }

    /// The map as a cube per patch (`/local_map`), world frame.
    fn local_map(&mut self, map: &local_map_t, time: u64, summary: &mut ExportSummary) {
        let cubes = map
            .patches
            .iter()
            .map(|p| {
                let z = [p.z_min, p.z_max];
                cell_cube(p.world_x, p.world_y, map.patch_size, z, PATCH_RGBA)
            })
            .collect();
        let entity = SceneEntity {
            id: "local_map".into(),
            cubes,
            ..SceneEntity::default()
        };
        self.scene("/local_map", map.utime, "world", entity, time);
        summary.wrote("/local_map");
    }

    /// Waypoints as spheres of their radius (`/waypoints`).
    fn waypoints(&mut self, msg: &waypoints_t, time: u64, summary: &mut ExportSummary) {
        let spheres = msg
            .position
            .iter()
            .zip(&msg.radius)
            .map(|(p, &r)| {
                let d = 2.0 * f64::from(r).max(1.0);
                SpherePrimitive {
                    pose: at(p[0], p[1], 0.0),
                    size: Some(Vector3 { x: d, y: d, z: 0.5 }),
                    color: Some(rgba(WAYPOINT_RGBA)),
                }
            })
            .collect();
        let entity = SceneEntity {
            id: "waypoints".into(),
            spheres,
            ..SceneEntity::default()
        };
        self.scene("/waypoints", msg.utime, "world", entity, time);
        summary.wrote("/waypoints");
    }

    /// An arc-votes message as JSON on its channel's topic.
    fn votes(&mut self, channel: &str, msg: &arc_votes_t, time: u64, summary: &mut ExportSummary) {
        let json = serde_json::json!({
            "utime": msg.utime,
            "behaviour": msg.behaviour,
            "curvature": msg.curvature,
            "votes": msg.votes,
            "vetoed": msg.vetoed,
            "speed_vote": msg.has_speed_vote.then_some(msg.speed_vote),
        });
        let schema = ("arcnav.ArcVotes", VOTES_SCHEMA);
        self.json(&topic(channel), schema, json, time, summary);
    }

    /// Why a command is what it is (`/decision`, from `DECISION`).
    fn decision(&mut self, msg: &decision_t, time: u64, summary: &mut ExportSummary) {
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
        let schema = ("arcnav.Decision", DECISION_SCHEMA);
        self.json("/decision", schema, json, time, summary);
    }

    /// The guard's verdicts (`/guard_status`, from `GUARD_STATUS`).
    fn guard(&mut self, msg: &guard_status_t, time: u64, summary: &mut ExportSummary) {
        let json = serde_json::json!({
            "utime": msg.utime,
            "command_utime": msg.command_utime,
            "verdict": msg.verdict,
            "reason": msg.reason,
            "speed_cap_mps": msg.speed_cap,
        });
        let schema = ("arcnav.GuardStatus", GUARD_SCHEMA);
        self.json("/guard_status", schema, json, time, summary);
    }

    /// A command as JSON (`/steering_command`), and the arcs by their
    /// fused vote, the commanded one marked (`/arcs`).
    fn command(
        &mut self,
        msg: &steering_command_t,
        arcs: Option<FusedArcs<'_>>,
        time: u64,
        summary: &mut ExportSummary,
    ) {
        let json = serde_json::json!({
            "utime": msg.utime,
            "curvature": msg.curvature,
            "speed_mps": msg.speed,
            "arc_index": msg.arc_index,
            "vote": msg.vote,
        });
        let schema = ("arcnav.SteeringCommand", COMMAND_SCHEMA);
        self.json("/steering_command", schema, json, time, summary);
        if let Some(FusedArcs { arcs, fused }) = arcs {
            let chosen = usize::try_from(msg.arc_index).ok();
            let entity = SceneEntity {
                id: "arcs".into(),
                lines: arc_lines(arcs, fused, chosen),
                ..SceneEntity::default()
            };
            self.scene("/arcs", msg.utime, "vehicle", entity, time);
            summary.wrote("/arcs");
        }
    }
}

const VOTES_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"behaviour":{"type":"string"},"curvature":{"type":"array","items":{"type":"number"}},"votes":{"type":"array","items":{"type":"number"}},"vetoed":{"type":"array","items":{"type":"boolean"}},"speed_vote":{"type":["number","null"]}}}"#;
const COMMAND_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"curvature":{"type":"number"},"speed_mps":{"type":"number"},"arc_index":{"type":"integer"},"vote":{"type":"number"}}}"#;

const GUARD_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"command_utime":{"type":"integer"},"verdict":{"type":"integer"},"reason":{"type":"string"},"speed_cap_mps":{"type":"number"}}}"#;

const DECISION_SCHEMA: &str = r#"{"type":"object","properties":{"utime":{"type":"integer"},"cause":{"type":"integer"},"reason":{"type":"string"},"vetoers":{"type":"array","items":{"type":"object","properties":{"behaviour":{"type":"string"},"arcs":{"type":"integer"},"cell":{"type":["array","null"],"items":{"type":"number"}}}}}}}"#;

/// Each arc as a 12 m polyline from the vehicle origin, coloured by its
/// fused vote (grey when there is none), the chosen one wider.
fn arc_lines(
    arcs: &arcnav_vehicle::ArcSet,
    fused: &[f32],
    chosen: Option<usize>,
) -> Vec<LinePrimitive> {
    arc_polylines(arcs)
        .into_iter()
        .enumerate()
        .map(|(i, line)| {
            let color = fused.get(i).map_or(rgba([0.6, 0.6, 0.6, 0.6]), |&v| {
                let [r, g, b] = vote_rgb(v);
                rgba([r, g, b, 1.0])
            });
            LinePrimitive {
                r#type: line_primitive::Type::LineStrip as i32,
                pose: at(0.0, 0.0, 0.0),
                thickness: if Some(i) == chosen { 0.12 } else { 0.04 },
                scale_invariant: false,
                points: line
                    .into_iter()
                    .map(|[x, y, z]| Point3 { x, y, z })
                    .collect(),
                color: Some(color),
                ..LinePrimitive::default()
            }
        })
        .collect()
}

/// The returns of an image as x, y, z (vehicle frame) and range, float32.
fn point_cloud(image: &arcnav_perception::RangeImage) -> foxglove::schemas::PointCloud {
    let mount = &image.vehicle_from_sensor;
    let mut data = Vec::with_capacity(image.range.len() * 16);
    for (_, _, r, [x, y, z]) in returns_of(image) {
        let p = mount * nalgebra::Point3::new(x, y, z);
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
    returns_of(image).count()
}
