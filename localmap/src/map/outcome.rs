//! What the map reports of its work: an insertion's outcome and errors, a
//! pose update's, and the running counts.

use arcnav_vehicle::Utime;

/// Sensors are tracked in a 32-bit set.
pub const MAX_SENSORS: usize = 32;

/// The farthest a footprint vertex may be from the world origin, m: no
/// local frame on Earth reaches further (a larger value is damage).
pub const MAX_COORDINATE_M: f64 = 1e8;

/// What a pose update did.
#[derive(Debug, Clone, PartialEq)]
pub enum PoseUpdate {
    Accepted,
    /// The map was cleared; reports captured before the new pose are refused.
    Reset(JumpReason),
    /// The pose was ignored.
    Rejected(JumpReason),
}

/// Why a pose was not taken as it came.
#[derive(Debug, Clone, PartialEq)]
pub enum JumpReason {
    TimeBackwards { from: Utime, to: Utime },
    Jump { distance_m: f64, allowed_m: f64 },
}

impl std::fmt::Display for JumpReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            JumpReason::TimeBackwards { from, to } => {
                write!(f, "time went backwards from {from} µs to {to} µs")
            }
            JumpReason::Jump {
                distance_m,
                allowed_m,
            } => write!(
                f,
                "the pose jumped {distance_m:.2} m where at most {allowed_m:.2} m is plausible"
            ),
        }
    }
}

/// A report the map did not take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InsertError {
    #[error("report captured at {utime} µs predates the map reset at {reset} µs")]
    BeforeReset { utime: Utime, reset: Utime },
    #[error("sensor {sensor:?} would be the {}th; the map tracks at most {MAX_SENSORS}", MAX_SENSORS + 1)]
    TooManySensors { sensor: String },
    #[error("report holds a cell at ({x}, {y}), which is not a finite position")]
    BadCell { x: f64, y: f64 },
    #[error(
        "report's field-of-view footprint has a vertex at ({x}, {y}), not a place within {MAX_COORDINATE_M} m of the origin"
    )]
    BadFootprint { x: f64, y: f64 },
}

/// What one insertion did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InsertOutcome {
    pub new_patches: u32,
    pub confirmed_patches: u32,
    /// Cells outside the window at insertion (not stored).
    pub outside_window: u32,
    /// Patches dropped because this image did not report them again.
    pub pruned: u32,
}

/// Counters over the map's life.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct MapStats {
    pub reports: u64,
    pub reports_refused: u64,
    pub new_patches: u64,
    pub confirmations: u64,
    pub pruned_inconsistent: u64,
    pub dropped_outside_window: u64,
    pub resets: u64,
    pub rejected_poses: u64,
    /// Patches removed because the vehicle's body stands on them.
    pub cleared_under_vehicle: u64,
    /// Perception cells on patches the static map already holds (not
    /// stored twice, 001 eq. 6).
    pub already_in_static_map: u64,
    /// Static-map patches that entered the window.
    pub static_patches_added: u64,
    /// Times an image's footprint covered a patch it did not report, from
    /// farther than `miss_range_factor` times the nearest distance the
    /// patch was reported from: no miss.
    pub seen_from_afar: u64,
    /// Reports whose sensor position (`shadows.origin`) was not plausible:
    /// their misses count whatever the distance.
    pub reports_without_viewpoint: u64,
}
