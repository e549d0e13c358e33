//! Typed messages on top of raw bytes: the channel names, decoding by
//! fingerprint (so `RANGE_IMAGE_ERIM` or a foreign channel name carrying a
//! `range_image_t` still decodes), and conversions to the vehicle crate.

use arcnav_vehicle::frames::{FrameError, isometry_from_parts, rotation_to_wxyz};
use arcnav_vehicle::{Isometry, Pose, SteeringCommand};
use nalgebra::Vector3;

use crate::codec::{DecodeError, EncodeError, Message, peek_fingerprint};
use crate::lcmtypes::{
    arc_votes_t, arc_votes_v1_t, decision_t, drive_command_t, guard_status_t, local_map_t,
    obstacle_cells_t, pose_t, range_image_t, range_slice_t, steering_command_t, waypoints_t,
};
use crate::log::{EventSource, LogStats};

/// The channel names arcnav publishes and listens to.
pub mod channels {
    pub const POSE: &str = "POSE";
    /// Range images; with several sensors, `RANGE_IMAGE_<SENSOR>`. Slices
    /// of range images (`range_slice_t`, streamed) use the same channels.
    pub const RANGE_IMAGE: &str = "RANGE_IMAGE";
    pub const WAYPOINTS: &str = "WAYPOINTS";
    pub const OBSTACLE_CELLS: &str = "OBSTACLE_CELLS";
    pub const STEERING_COMMAND: &str = "STEERING_COMMAND";
    pub const LOCAL_MAP: &str = "LOCAL_MAP";
    /// Why each STEERING_COMMAND is what it is (`decision_t`).
    pub const DECISION: &str = "DECISION";
    /// The guard's verdicts (`guard_status_t`).
    pub const GUARD_STATUS: &str = "GUARD_STATUS";
    /// STEERING_COMMAND as `arcnav node guard` lets it through, for a
    /// vehicle that follows it (`arcnav vehicle --commands`).
    pub const STEERING_COMMAND_GUARDED: &str = "STEERING_COMMAND_GUARDED";
    /// Prefix of each behaviour's vote channel.
    pub const ARC_VOTES_PREFIX: &str = "ARC_VOTES_";

    /// `ARC_VOTES_<BEHAVIOUR>`, upper-cased.
    pub fn arc_votes(behaviour: &str) -> String {
        format!("{ARC_VOTES_PREFIX}{}", behaviour.to_ascii_uppercase())
    }

    /// What a navigation system takes in: POSE, RANGE_IMAGE*, WAYPOINTS.
    pub fn is_input(channel: &str) -> bool {
        channel == POSE || channel == WAYPOINTS || channel.starts_with(RANGE_IMAGE)
    }

    /// `RANGE_IMAGE_<SENSOR>`, upper-cased.
    pub fn range_image(sensor: &str) -> String {
        format!("{RANGE_IMAGE}_{}", sensor.to_ascii_uppercase())
    }
}

/// Any top-level arcnav message.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyMessage {
    Pose(pose_t),
    RangeImage(range_image_t),
    RangeSlice(range_slice_t),
    SteeringCommand(steering_command_t),
    /// A skid-steer vehicle's command (with the yaw rate), on
    /// STEERING_COMMAND.
    DriveCommand(drive_command_t),
    ArcVotes(arc_votes_t),
    ObstacleCells(obstacle_cells_t),
    Waypoints(waypoints_t),
    LocalMap(local_map_t),
    Decision(decision_t),
    GuardStatus(guard_status_t),
}

/// Votes of the older type (before veto causes), read as votes whose
/// vetoes give no cause.
impl From<arc_votes_v1_t> for arc_votes_t {
    fn from(v: arc_votes_v1_t) -> Self {
        let n = v.votes.len();
        Self {
            utime: v.utime,
            behaviour: v.behaviour,
            num_arcs: v.num_arcs,
            curvature: v.curvature,
            votes: v.votes,
            vetoed: v.vetoed,
            has_speed_vote: v.has_speed_vote,
            speed_vote: v.speed_vote,
            arc_speed: v.arc_speed,
            reverse_clear: v.reverse_clear,
            forward_clear: v.forward_clear,
            veto_cause: vec![arc_votes_t::NOT_SAID; n],
            veto_x: vec![0.0; n],
            veto_y: vec![0.0; n],
        }
    }
}

/// Decodes votes of either type (`arc_votes_t`, or the older
/// `arc_votes_v1_t` of logs and programs written before veto causes).
pub fn decode_votes(bytes: &[u8]) -> Result<arc_votes_t, DecodeError> {
    match peek_fingerprint(bytes) {
        Some(arc_votes_v1_t::FINGERPRINT) => Ok(arc_votes_v1_t::decode(bytes)?.into()),
        _ => arc_votes_t::decode(bytes),
    }
}

impl AnyMessage {
    /// Decodes `bytes` by their fingerprint; `Ok(None)` for a type arcnav
    /// does not know (e.g. `LCM_SELF_TEST`), to be skipped.
    pub fn decode(bytes: &[u8]) -> Result<Option<Self>, DecodeError> {
        let Some(fingerprint) = peek_fingerprint(bytes) else {
            return Ok(None);
        };
        Ok(Some(match fingerprint {
            pose_t::FINGERPRINT => Self::Pose(pose_t::decode(bytes)?),
            range_image_t::FINGERPRINT => Self::RangeImage(range_image_t::decode(bytes)?),
            range_slice_t::FINGERPRINT => Self::RangeSlice(range_slice_t::decode(bytes)?),
            steering_command_t::FINGERPRINT => {
                Self::SteeringCommand(steering_command_t::decode(bytes)?)
            }
            drive_command_t::FINGERPRINT => Self::DriveCommand(drive_command_t::decode(bytes)?),
            arc_votes_t::FINGERPRINT | arc_votes_v1_t::FINGERPRINT => {
                Self::ArcVotes(decode_votes(bytes)?)
            }
            decision_t::FINGERPRINT => Self::Decision(decision_t::decode(bytes)?),
            guard_status_t::FINGERPRINT => Self::GuardStatus(guard_status_t::decode(bytes)?),
            obstacle_cells_t::FINGERPRINT => Self::ObstacleCells(obstacle_cells_t::decode(bytes)?),
            waypoints_t::FINGERPRINT => Self::Waypoints(waypoints_t::decode(bytes)?),
            local_map_t::FINGERPRINT => Self::LocalMap(local_map_t::decode(bytes)?),
            _ => return Ok(None),
        }))
    }

    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        match self {
            Self::Pose(m) => m.encode(),
            Self::RangeImage(m) => m.encode(),
            Self::RangeSlice(m) => m.encode(),
            Self::SteeringCommand(m) => m.encode(),
            Self::DriveCommand(m) => m.encode(),
            Self::ArcVotes(m) => m.encode(),
            Self::ObstacleCells(m) => m.encode(),
            Self::Waypoints(m) => m.encode(),
            Self::LocalMap(m) => m.encode(),
            Self::Decision(m) => m.encode(),
            Self::GuardStatus(m) => m.encode(),
        }
    }

    /// The message's own timestamp, µs.
    pub fn utime(&self) -> i64 {
        match self {
            Self::Pose(m) => m.utime,
            Self::RangeImage(m) => m.utime,
            Self::RangeSlice(m) => m.utime,
            Self::SteeringCommand(m) => m.utime,
            Self::DriveCommand(m) => m.utime,
            Self::ArcVotes(m) => m.utime,
            Self::ObstacleCells(m) => m.utime,
            Self::Waypoints(m) => m.utime,
            Self::LocalMap(m) => m.utime,
            Self::Decision(m) => m.utime,
            Self::GuardStatus(m) => m.utime,
        }
    }

    /// True when `channel` is where the wire contract puts this message's
    /// type (`POSE`, `RANGE_IMAGE[_<SENSOR>]`, `ARC_VOTES_<NAME>`, ...). A
    /// message of a known type elsewhere (a second pose stream on
    /// `POSE_GPS_RAW`, a teleoperation stream on `STEERING_COMMAND_TELEOP`)
    /// is another program's, not an input of arcnav's.
    pub fn on_its_channel(&self, channel: &str) -> bool {
        use channels::*;
        match self {
            Self::Pose(_) => channel == POSE,
            Self::RangeImage(_) | Self::RangeSlice(_) => {
                channel == RANGE_IMAGE
                    || channel
                        .strip_prefix(RANGE_IMAGE)
                        .and_then(|rest| rest.strip_prefix('_'))
                        .is_some_and(|sensor| !sensor.is_empty())
            }
            Self::SteeringCommand(_) | Self::DriveCommand(_) => channel == STEERING_COMMAND,
            Self::ArcVotes(_) => channel
                .strip_prefix(ARC_VOTES_PREFIX)
                .is_some_and(|name| !name.is_empty()),
            Self::ObstacleCells(_) => channel == OBSTACLE_CELLS,
            Self::Waypoints(_) => channel == WAYPOINTS,
            Self::LocalMap(_) => channel == LOCAL_MAP,
            Self::Decision(_) => channel == DECISION,
            Self::GuardStatus(_) => channel == GUARD_STATUS,
        }
    }

    /// The LCM type name.
    pub fn type_name(&self) -> &'static str {
        match self {
            Self::Pose(_) => pose_t::TYPE_NAME,
            Self::RangeImage(_) => range_image_t::TYPE_NAME,
            Self::RangeSlice(_) => range_slice_t::TYPE_NAME,
            Self::SteeringCommand(_) => steering_command_t::TYPE_NAME,
            Self::DriveCommand(_) => drive_command_t::TYPE_NAME,
            Self::ArcVotes(_) => arc_votes_t::TYPE_NAME,
            Self::ObstacleCells(_) => obstacle_cells_t::TYPE_NAME,
            Self::Waypoints(_) => waypoints_t::TYPE_NAME,
            Self::LocalMap(_) => local_map_t::TYPE_NAME,
            Self::Decision(_) => decision_t::TYPE_NAME,
            Self::GuardStatus(_) => guard_status_t::TYPE_NAME,
        }
    }
}

/// An event of a log, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct TypedEvent {
    pub event_number: i64,
    /// When the event was logged, µs.
    pub timestamp: i64,
    pub channel: String,
    pub message: AnyMessage,
}

/// What typed reading skipped, on top of the log's own [`LogStats`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TypedStats {
    /// Events whose type arcnav does not know (e.g. `LCM_SELF_TEST`), per channel.
    pub unknown: std::collections::BTreeMap<String, u64>,
    /// Events with a known fingerprint that failed to decode, per channel.
    pub undecodable: std::collections::BTreeMap<String, u64>,
}

/// The arcnav messages of a log, in log order; unknown types are skipped and
/// counted, as are messages that do not decode (with a warning).
pub struct TypedEvents<S> {
    log: S,
    stats: TypedStats,
}

impl<S: EventSource> TypedEvents<S> {
    pub fn new(log: S) -> Self {
        Self {
            log,
            stats: TypedStats::default(),
        }
    }

    pub fn stats(&self) -> &TypedStats {
        &self.stats
    }

    /// Where the events come from.
    pub fn source(&self) -> &S {
        &self.log
    }

    pub fn log_stats(&self) -> &LogStats {
        self.log.stats()
    }

    /// Bytes of the log consumed so far.
    pub fn position(&self) -> u64 {
        self.log.position()
    }
}

impl<S: EventSource> Iterator for TypedEvents<S> {
    type Item = std::io::Result<TypedEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let event = match self.log.next_event() {
                Ok(Some(event)) => event,
                Ok(None) => return None,
                Err(e) => return Some(Err(e)),
            };
            match AnyMessage::decode(&event.data) {
                Ok(Some(message)) => {
                    return Some(Ok(TypedEvent {
                        event_number: event.event_number,
                        timestamp: event.timestamp,
                        channel: event.channel,
                        message,
                    }));
                }
                Ok(None) => *self.stats.unknown.entry(event.channel).or_default() += 1,
                Err(err) => {
                    tracing::warn!(channel = %event.channel, event = event.event_number, %err, "undecodable message skipped");
                    *self.stats.undecodable.entry(event.channel).or_default() += 1;
                }
            }
        }
    }
}

impl From<&Pose> for pose_t {
    fn from(pose: &Pose) -> Self {
        let t = pose.world_from_vehicle.translation.vector;
        Self {
            utime: pose.utime,
            position: [t.x, t.y, t.z],
            orientation: rotation_to_wxyz(&pose.world_from_vehicle.rotation),
            velocity: [pose.velocity.x, pose.velocity.y, pose.velocity.z],
            yaw_rate: pose.yaw_rate,
        }
    }
}

/// A `pose_t` whose values are not a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    #[error("pose at {utime} µs: {source}")]
    Frame { utime: i64, source: FrameError },
    #[error("pose at {utime} µs has a velocity or yaw rate that is not finite")]
    NonFinite { utime: i64 },
    #[error("pose: {0}")]
    Time(#[from] arcnav_vehicle::time::ImplausibleTime),
}

impl TryFrom<&pose_t> for Pose {
    type Error = PoseError;

    fn try_from(msg: &pose_t) -> Result<Self, PoseError> {
        arcnav_vehicle::time::plausible(msg.utime)?;
        let world_from_vehicle: Isometry = isometry_from_parts(msg.position, msg.orientation)
            .map_err(|source| PoseError::Frame {
                utime: msg.utime,
                source,
            })?;
        if !msg.velocity.iter().all(|v| v.is_finite()) || !msg.yaw_rate.is_finite() {
            return Err(PoseError::NonFinite { utime: msg.utime });
        }
        Ok(Pose {
            utime: msg.utime,
            world_from_vehicle,
            velocity: Vector3::from(msg.velocity),
            yaw_rate: msg.yaw_rate,
        })
    }
}

impl From<&SteeringCommand> for steering_command_t {
    fn from(command: &SteeringCommand) -> Self {
        Self {
            utime: command.utime,
            curvature: command.curvature,
            speed: command.speed_mps,
            arc_index: command
                .arc_index
                .and_then(|i| i32::try_from(i).ok())
                .unwrap_or(-1),
            vote: command.vote,
        }
    }
}

impl From<&steering_command_t> for SteeringCommand {
    /// Values a vehicle must not act on (non-finite speed or curvature)
    /// become a stop. A negative speed backs the vehicle up along the arc.
    fn from(msg: &steering_command_t) -> Self {
        let sane = msg.curvature.is_finite() && msg.speed.is_finite();
        if !sane {
            return SteeringCommand::stop(msg.utime);
        }
        SteeringCommand {
            utime: msg.utime,
            curvature: msg.curvature,
            speed_mps: msg.speed,
            arc_index: usize::try_from(msg.arc_index).ok(),
            vote: msg.vote,
            turn_rate_radps: 0.0,
        }
    }
}

impl From<&SteeringCommand> for drive_command_t {
    fn from(command: &SteeringCommand) -> Self {
        let plain = steering_command_t::from(command);
        Self {
            utime: plain.utime,
            curvature: plain.curvature,
            speed: plain.speed,
            yaw_rate: command.yaw_rate(),
            arc_index: plain.arc_index,
            vote: plain.vote,
        }
    }
}

impl From<&drive_command_t> for SteeringCommand {
    /// A turn in place (infinite curvature, speed 0, a finite yaw rate and
    /// an arc) is one; otherwise as [`steering_command_t`]: values a
    /// vehicle must not act on become a stop.
    fn from(msg: &drive_command_t) -> Self {
        let turning = msg.curvature.is_infinite()
            && msg.speed == 0.0
            && msg.yaw_rate.is_finite()
            && msg.yaw_rate != 0.0
            && msg.curvature.signum() == msg.yaw_rate.signum();
        match usize::try_from(msg.arc_index) {
            Ok(arc) if turning => {
                SteeringCommand::turn_in_place(msg.utime, msg.yaw_rate, arc, msg.vote)
            }
            _ => SteeringCommand::from(&steering_command_t {
                utime: msg.utime,
                curvature: msg.curvature,
                speed: msg.speed,
                arc_index: msg.arc_index,
                vote: msg.vote,
            }),
        }
    }
}

impl AnyMessage {
    /// The arbiter's command as `kinematics` puts it on STEERING_COMMAND:
    /// `steering_command_t` for an Ackermann vehicle, `drive_command_t`
    /// (with the yaw rate) for one that turns in place.
    pub fn command(command: &SteeringCommand, kinematics: arcnav_vehicle::Kinematics) -> Self {
        match kinematics {
            arcnav_vehicle::Kinematics::Ackermann => Self::SteeringCommand(command.into()),
            arcnav_vehicle::Kinematics::SkidSteer => Self::DriveCommand(command.into()),
        }
    }

    /// Decodes a STEERING_COMMAND message of either type into the command.
    pub fn decode_command(bytes: &[u8]) -> Result<SteeringCommand, DecodeError> {
        match peek_fingerprint(bytes) {
            Some(drive_command_t::FINGERPRINT) => Ok((&drive_command_t::decode(bytes)?).into()),
            _ => Ok((&steering_command_t::decode(bytes)?).into()),
        }
    }

    /// The command a STEERING_COMMAND message carries, of either type.
    pub fn as_command(&self) -> Option<SteeringCommand> {
        match self {
            Self::SteeringCommand(m) => Some(m.into()),
            Self::DriveCommand(m) => Some(m.into()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    #[test]
    fn a_skid_steer_vehicles_commands_carry_the_yaw_rate_and_decode_either_type() {
        use arcnav_vehicle::Kinematics;
        let turn = SteeringCommand::turn_in_place(7, -0.8, 0, 0.4);
        let AnyMessage::DriveCommand(msg) = AnyMessage::command(&turn, Kinematics::SkidSteer)
        else {
            panic!("a skid-steer vehicle's command is a drive_command_t")
        };
        assert_eq!(
            (msg.curvature, msg.speed, msg.yaw_rate),
            (f64::NEG_INFINITY, 0.0, -0.8)
        );
        let bytes = msg.encode().unwrap();
        assert_eq!(AnyMessage::decode_command(&bytes).unwrap(), turn);
        let arc = SteeringCommand {
            utime: 8,
            curvature: 0.1,
            speed_mps: 2.0,
            arc_index: Some(30),
            vote: 0.5,
            turn_rate_radps: 0.0,
        };
        let AnyMessage::DriveCommand(msg) = AnyMessage::command(&arc, Kinematics::SkidSteer) else {
            panic!()
        };
        assert!((msg.yaw_rate - 0.2).abs() < 1e-12);
        assert_eq!(
            AnyMessage::decode_command(&msg.encode().unwrap()).unwrap(),
            arc
        );
        // An Ackermann vehicle's stay steering_command_t, and decode alike.
        let plain = AnyMessage::command(&arc, Kinematics::Ackermann);
        assert!(matches!(plain, AnyMessage::SteeringCommand(_)));
        assert_eq!(
            AnyMessage::decode_command(&plain.encode().unwrap()).unwrap(),
            arc
        );
        // A turn whose signs disagree, or with no rate, is a stop.
        let odd = drive_command_t {
            yaw_rate: 0.8,
            ..msg_of(&turn)
        };
        assert!(SteeringCommand::from(&odd).is_stop());
        let still = drive_command_t {
            yaw_rate: 0.0,
            ..msg_of(&turn)
        };
        assert!(SteeringCommand::from(&still).is_stop());
    }

    fn msg_of(command: &SteeringCommand) -> drive_command_t {
        command.into()
    }

    #[test]
    fn channel_names_follow_the_wire_contract() {
        assert_eq!(
            channels::arc_votes("obstacle_avoidance"),
            "ARC_VOTES_OBSTACLE_AVOIDANCE"
        );
        assert_eq!(channels::range_image("erim"), "RANGE_IMAGE_ERIM");
    }

    #[test]
    fn poses_convert_both_ways() {
        let pose = Pose {
            utime: 42,
            world_from_vehicle: isometry_from_xyz_rpy([1.0, 2.0, 3.0], 0.1, 0.2, 0.3),
            velocity: Vector3::new(1.0, -1.0, 0.0),
            yaw_rate: 0.05,
        };
        let msg = pose_t::from(&pose);
        let back = Pose::try_from(&msg).unwrap();
        assert!(
            (back.world_from_vehicle.translation.vector
                - pose.world_from_vehicle.translation.vector)
                .norm()
                < 1e-12
        );
        assert!(
            back.world_from_vehicle
                .rotation
                .angle_to(&pose.world_from_vehicle.rotation)
                < 1e-12
        );
        let bad = pose_t {
            orientation: [0.0; 4],
            ..msg
        };
        assert!(Pose::try_from(&bad).is_err());
        // Finite, but 10^19 m out: it had aborted replay (the local map's
        // cell indices overflowed); now an invalid pose, counted.
        let far = pose_t {
            position: [1e19, 2.0, 3.0],
            ..msg
        };
        assert!(Pose::try_from(&far).is_err());
        // A time no clock gives: one such pose had restarted the cycle clock
        // near i64::MIN and hung the pipeline catching up 10^10 cycles.
        for utime in [i64::MIN, -1, i64::MAX, (1 << 53) + 1] {
            let err = Pose::try_from(&pose_t { utime, ..msg }).unwrap_err();
            assert!(matches!(err, PoseError::Time(_)), "{utime}: {err}");
        }
    }

    #[test]
    fn a_stop_is_arc_index_minus_one_and_bad_commands_become_stops() {
        let stop = steering_command_t::from(&SteeringCommand::stop(5));
        assert_eq!((stop.arc_index, stop.speed), (-1, 0.0));
        let weird = steering_command_t {
            utime: 1,
            curvature: 0.1,
            speed: f64::NAN,
            arc_index: 3,
            vote: 0.5,
        };
        assert!(SteeringCommand::from(&weird).is_stop());
        let back_up = steering_command_t {
            speed: -1.0,
            ..weird
        };
        let command = SteeringCommand::from(&back_up);
        assert!(command.is_reverse(), "{command:?}");
        assert_eq!((command.speed_mps, command.curvature), (-1.0, 0.1));
    }

    #[test]
    fn typed_reading_skips_self_tests_and_counts_bad_messages() {
        let mut writer = crate::log::LogWriter::new(Vec::new());
        writer
            .write_event(1, "LCM_SELF_TEST", b"lcm self test")
            .unwrap();
        writer.write_message(2, "POSE", &pose_t::default()).unwrap();
        let mut broken = pose_t::default().encode().unwrap();
        broken.truncate(30);
        writer.write_event(3, "POSE", &broken).unwrap();
        writer
            .write_message(4, "STEERING_COMMAND", &steering_command_t::default())
            .unwrap();
        let bytes = writer.into_inner();
        let mut typed = TypedEvents::new(crate::log::LogReader::new(bytes.as_slice()));
        let events: Vec<TypedEvent> = typed.by_ref().map(Result::unwrap).collect();
        let channels: Vec<&str> = events.iter().map(|e| e.channel.as_str()).collect();
        assert_eq!(channels, ["POSE", "STEERING_COMMAND"]);
        assert_eq!(events[1].event_number, 3);
        assert_eq!(typed.stats().unknown["LCM_SELF_TEST"], 1);
        assert_eq!(typed.stats().undecodable["POSE"], 1);
    }

    #[test]
    fn votes_written_before_veto_causes_still_decode_as_votes_without_causes() {
        // arc_votes_t's fingerprint until 2026-12 (pinned: logs and
        // programs of that time carry it).
        assert_eq!(arc_votes_v1_t::FINGERPRINT, 0x883c_d606_e2fa_1e13);
        assert_ne!(arc_votes_t::FINGERPRINT, arc_votes_v1_t::FINGERPRINT);
        let old = arc_votes_v1_t {
            utime: 7,
            behaviour: "heading_hold".into(),
            num_arcs: 3,
            curvature: vec![-0.1, 0.0, 0.1],
            votes: vec![0.5, 1.0, -1.0],
            vetoed: vec![false, false, true],
            has_speed_vote: false,
            speed_vote: 0.0,
            arc_speed: vec![-1.0; 3],
            reverse_clear: vec![-1.0; 3],
            forward_clear: vec![-1.0; 3],
        };
        let bytes = old.encode().unwrap();
        let Some(AnyMessage::ArcVotes(new)) = AnyMessage::decode(&bytes).unwrap() else {
            panic!("old votes not decoded as votes");
        };
        assert_eq!(new.votes, old.votes);
        assert_eq!(new.vetoed, old.vetoed);
        assert_eq!(new.veto_cause, vec![arc_votes_t::NOT_SAID; 3]);
        assert_eq!(decode_votes(&bytes).unwrap(), new);
        // And the new ones decode as themselves.
        let again = new.encode().unwrap();
        assert_eq!(decode_votes(&again).unwrap(), new);
    }

    #[test]
    fn unknown_fingerprints_are_skipped_and_known_ones_decode() {
        assert_eq!(AnyMessage::decode(b"LCM self test").unwrap(), None);
        assert_eq!(AnyMessage::decode(b"short").unwrap(), None);
        let bytes = pose_t::default().encode().unwrap();
        let decoded = AnyMessage::decode(&bytes).unwrap().unwrap();
        assert_eq!(decoded.type_name(), "arcnav.pose_t");
        assert!(
            AnyMessage::decode(&bytes[..20]).is_err(),
            "a truncated pose is an error"
        );
    }
}
