//! The pipeline's own sections of the configuration: `[pipeline]`, the
//! timing every executor shares, and `[live]`, what live executors add
//! (watchdog timeouts, decision deadline, how cells reach the map).
//!
//! Each node is built from its own crate's section plus these; no
//! simulator setting reaches a node.

use arcnav_vehicle::config::{self as check, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[pipeline]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineConfig {
    /// Commands per second (one cycle of map update, votes and decision).
    pub command_rate_hz: f64,
    /// Time from image capture until its cells reach the local map in
    /// lock-step runs (002 §5 measured ~0.6 s on 1993 hardware): `"auto"`,
    /// the sensors' own (`[sensor] latency_s`, the slowest's), or seconds.
    pub perception_latency_s: Latency,
    /// Poses kept to find the pose at an image's capture time, s.
    pub pose_history_s: f64,
    /// Images waiting for the pose at their capture time; beyond, the
    /// oldest is dropped (counted).
    pub max_waiting_images: usize,
    /// An image is placed only with poses at most this far apart around its
    /// capture time; in a hole of the pose stream it is dropped, s.
    pub max_pose_gap_s: f64,
    /// A range-image slice acquired up to this long after the newest pose
    /// is judged at once, with that pose carried ahead at its velocity and
    /// yaw rate, rather than waiting for the next pose (at 50 Hz, up to
    /// 20 ms); 0: slices wait, as whole images always do, s.
    pub slice_pose_extrapolation_s: f64,
    /// A defect put into the pipeline on purpose, to show that what stands
    /// beside it (the guard) stops the vehicle when the pipeline does not:
    /// see [`Fault`]. Only the lock-step executor (`arcnav sim`, `sweep`,
    /// `replay`) injects it; a live run refuses a configuration with one.
    pub fault: Fault,
    /// The fault begins this long after the first pose, s.
    pub fault_after_s: f64,
}

/// `[pipeline] perception_latency_s`: the sensors' own, or seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Latency {
    /// What the sensors take (`[sensor] latency_s`): the configuration
    /// puts the slowest one's in its place when it is resolved.
    Auto,
    Seconds(f64),
}

impl Latency {
    /// What a configuration that was never resolved against its sensors
    /// assumes for `Auto`: the built-in sensor's (the ERIM's), s.
    pub const UNRESOLVED_AUTO_S: f64 = 0.3;

    /// Seconds ([`Self::UNRESOLVED_AUTO_S`] for `Auto`, not resolved).
    pub fn seconds(self) -> f64 {
        match self {
            Self::Auto => Self::UNRESOLVED_AUTO_S,
            Self::Seconds(s) => s,
        }
    }

    /// The seconds given, or `sensor_s` for `Auto`.
    pub fn or_sensor(self, sensor_s: f64) -> f64 {
        match self {
            Self::Auto => sensor_s,
            Self::Seconds(s) => s,
        }
    }
}

impl Serialize for Latency {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Auto => serializer.serialize_str("auto"),
            Self::Seconds(s) => serializer.serialize_f64(*s),
        }
    }
}

impl<'de> Deserialize<'de> for Latency {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Latency;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("\"auto\" or a number of seconds")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Latency, E> {
                if v == "auto" {
                    Ok(Latency::Auto)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Str(v), &self))
                }
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Latency, E> {
                Ok(Latency::Seconds(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Latency, E> {
                Ok(Latency::Seconds(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Latency, E> {
                Ok(Latency::Seconds(v as f64))
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

/// A defect of the pipeline, injected on purpose (`[pipeline] fault`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// The pipeline as it is.
    #[default]
    None,
    /// Perception reports nothing: each image's report says the ground it
    /// observed, with no cell, region, shadow or height in it (a null
    /// evaluator).
    BlindPerception,
    /// The local map drops every cell it is given: perception's reports
    /// (logged whole) reach it with only the ground they observed, which
    /// it then holds as clear.
    ForgetfulMap,
    /// The map stops changing: each cycle from the fault on votes on the
    /// map of the last cycle before it.
    StaleMap,
}

impl Fault {
    /// Its name in the configuration.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::BlindPerception => "blind_perception",
            Self::ForgetfulMap => "forgetful_map",
            Self::StaleMap => "stale_map",
        }
    }
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            command_rate_hz: 10.0,
            perception_latency_s: Latency::Auto,
            pose_history_s: 10.0,
            max_waiting_images: 4,
            max_pose_gap_s: 0.2,
            slice_pose_extrapolation_s: 0.05,
            fault: Fault::None,
            fault_after_s: 0.0,
        }
    }
}

impl PipelineConfig {
    /// Keys relative to `[pipeline]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check::in_range("command_rate_hz", self.command_rate_hz, 0.5, 1000.0)?;
        if let Latency::Seconds(s) = self.perception_latency_s {
            check::in_range("perception_latency_s", s, 0.0, 10.0)?;
        }
        check::in_range("pose_history_s", self.pose_history_s, 0.5, 600.0)?;
        check::in_range("max_pose_gap_s", self.max_pose_gap_s, 0.001, 60.0)?;
        check::in_range(
            "slice_pose_extrapolation_s",
            self.slice_pose_extrapolation_s,
            0.0,
            0.5,
        )?;
        check::in_range("fault_after_s", self.fault_after_s, 0.0, 1e6)?;
        if !(1..=1000).contains(&self.max_waiting_images) {
            return Err(ConfigError::new(
                "max_waiting_images",
                format!("is {}, must be 1 to 1000", self.max_waiting_images),
            ));
        }
        Ok(())
    }
}

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
    /// (used by the tests; adds the modelled latency). Every cycle is then
    /// voted on and decided, in order, and the arbiter waits for a cycle's
    /// votes up to `arbiter.vote_timeout_s`.
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

/// An external behaviour, `[behaviours.external.NAME]`: a program of its
/// own, in any language, that votes like a built-in behaviour. Live, it
/// takes LOCAL_MAP on the bus and answers on `ARC_VOTES_<NAME>` (started by
/// whoever starts the vehicle's processes); `arcnav sim`, `sweep` and
/// `replay` start `command` themselves and talk to it over its standard
/// input and output in lock-step, one cycle at a time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExternalConfig {
    /// The program and its arguments (relative paths from the directory
    /// arcnav runs in). Empty: live only (sim, sweep and replay refuse it).
    pub command: Vec<String>,
    /// Lock-step: how long a cycle waits for the program's votes, s. A
    /// program that misses it is stopped and the mission goes on without
    /// it (counted; a required one stops the vehicle).
    pub timeout_s: f64,
    /// Lock-step: how long the first cycle waits (the program starting:
    /// an interpreter, imports), s.
    pub start_timeout_s: f64,
    /// The local map it is sent carries the elevation layer (004 §III):
    /// some 0.4 MB a cycle with the default layer. Off: its elevation
    /// square is empty.
    pub elevation: bool,
}

impl Default for ExternalConfig {
    fn default() -> Self {
        Self {
            command: Vec::new(),
            timeout_s: 1.0,
            start_timeout_s: 10.0,
            elevation: false,
        }
    }
}

impl ExternalConfig {
    /// Keys relative to its table.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check::in_range("timeout_s", self.timeout_s, 0.001, 60.0)?;
        check::in_range("start_timeout_s", self.start_timeout_s, 0.001, 600.0)?;
        if self
            .command
            .first()
            .is_some_and(|program| program.is_empty())
        {
            return Err(ConfigError::new(
                "command",
                "starts with an empty program name",
            ));
        }
        Ok(())
    }

    /// Whether `name` may name an external behaviour: lower-case letters,
    /// digits and `_` (its votes come on `ARC_VOTES_<NAME in upper case>`).
    pub fn is_plain_name(name: &str) -> bool {
        !name.is_empty()
            && name.len() <= 64
            && name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_bad_settings_are_refused() {
        assert!(PipelineConfig::default().validate().is_ok());
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
        let bad = PipelineConfig {
            command_rate_hz: f64::NAN,
            ..PipelineConfig::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "command_rate_hz");
    }
}
