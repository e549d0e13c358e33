//! Conversions between the pipeline's types and the LCM wire types
//! (`bus/lcmtypes/*.lcm`). Incoming messages are checked: a message that does
//! not describe a valid value is an error, never a panic.

use arcnav_arbiter::{BehaviourVotes, Reason, StopReason, VetoCause, Vetoer, Votes};
use arcnav_behaviours::{Mission, Waypoint};
use arcnav_bus::lcmtypes::{
    arc_votes_t, decision_t, guard_status_t, local_map_patch_t, local_map_t, obstacle_cell_t,
    obstacle_cells_t, range_image_t, range_slice_t, waypoints_t,
};
use arcnav_localmap::{ElevationGrid, MapSnapshot, Patch, SeenGround};
use arcnav_perception::{
    BeamTable, FovPolygon, HeightSample, ObstacleCell, ObstacleReport, RangeImage, RangeSlice,
    Reasons, Region, Shadow, Shadows, SliceAxis,
};
use arcnav_vehicle::frames::{FrameError, MAX_COORDINATE_M, isometry_from_parts, rotation_to_wxyz};
use arcnav_vehicle::{ArcSet, Isometry, Pose, Utime};
use nalgebra::{Point2, Vector3};

/// A wire message that does not describe a valid value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    #[error("{what}: {source}")]
    Frame {
        what: &'static str,
        source: FrameError,
    },
    #[error("{what}: {reason}")]
    Invalid { what: &'static str, reason: String },
    #[error("{what}: {source}")]
    Time {
        what: &'static str,
        source: arcnav_vehicle::time::ImplausibleTime,
    },
}

/// Each of `times` checked with [`arcnav_vehicle::time::plausible`]: a
/// message's times are on a vehicle's clock before any clock joins them.
fn plausible(what: &'static str, times: &[Utime]) -> Result<(), WireError> {
    for &t in times {
        arcnav_vehicle::time::plausible(t).map_err(|source| WireError::Time { what, source })?;
    }
    Ok(())
}

fn position_and_rotation(iso: &Isometry) -> ([f64; 3], [f64; 4]) {
    let t = iso.translation.vector;
    ([t.x, t.y, t.z], rotation_to_wxyz(&iso.rotation))
}

/// A range image for the wire.
pub fn range_image_to_wire(image: &RangeImage) -> range_image_t {
    let (mount_position, mount_orientation) = position_and_rotation(&image.vehicle_from_sensor);
    range_image_t {
        utime: image.utime,
        sensor: image.sensor.clone(),
        mount_position,
        mount_orientation,
        rows: image.rows() as i32,
        cols: image.cols() as i32,
        elevation: image.beams.elevation.clone(),
        azimuth: image.beams.azimuth.clone(),
        range: image.range.clone(),
    }
}

/// A range image from the wire (sizes were checked by the decoder).
pub fn range_image_from_wire(msg: range_image_t) -> Result<RangeImage, WireError> {
    plausible("range image", &[msg.utime])?;
    let vehicle_from_sensor = isometry_from_parts(msg.mount_position, msg.mount_orientation)
        .map_err(|source| WireError::Frame {
            what: "range image mount",
            source,
        })?;
    let image = RangeImage {
        utime: msg.utime,
        sensor: msg.sensor,
        vehicle_from_sensor,
        beams: BeamTable {
            elevation: msg.elevation,
            azimuth: msg.azimuth,
        },
        range: msg.range,
    };
    image.validate().map_err(|e| WireError::Invalid {
        what: "range image",
        reason: e.to_string(),
    })?;
    Ok(image)
}

/// A range-image slice for the wire.
pub fn range_slice_to_wire(slice: &RangeSlice) -> range_slice_t {
    let (mount_position, mount_orientation) = position_and_rotation(&slice.vehicle_from_sensor);
    range_slice_t {
        utime: slice.utime,
        frame_utime: slice.frame_utime,
        sensor: slice.sensor.clone(),
        mount_position,
        mount_orientation,
        frame_rows: saturate_len(slice.frame_rows),
        frame_cols: saturate_len(slice.frame_cols),
        axis: match slice.axis {
            SliceAxis::Columns => 0,
            SliceAxis::Rows => 1,
        },
        first: saturate_len(slice.first),
        rows: saturate_len(slice.beams.rows()),
        cols: saturate_len(slice.beams.cols()),
        elevation: slice.beams.elevation.clone(),
        azimuth: slice.beams.azimuth.clone(),
        num_lines: saturate_len(slice.line_utimes.len()),
        line_utime: slice.line_utimes.clone(),
        range: slice.range.clone(),
    }
}

fn saturate_len(n: usize) -> i32 {
    i32::try_from(n).unwrap_or(i32::MAX)
}

/// A range-image slice from the wire: sizes were checked by the decoder,
/// the slice's place in its image here (before anything is allocated
/// from the image's declared size).
pub fn range_slice_from_wire(msg: range_slice_t) -> Result<RangeSlice, WireError> {
    plausible("range slice", &[msg.utime, msg.frame_utime])?;
    let invalid = |reason: String| WireError::Invalid {
        what: "range slice",
        reason,
    };
    let vehicle_from_sensor = isometry_from_parts(msg.mount_position, msg.mount_orientation)
        .map_err(|source| WireError::Frame {
            what: "range slice mount",
            source,
        })?;
    let axis = match msg.axis {
        0 => SliceAxis::Columns,
        1 => SliceAxis::Rows,
        other => {
            return Err(invalid(format!(
                "axis {other}: 0 (columns) or 1 (rows) expected"
            )));
        }
    };
    let size = |name: &str, v: i32| {
        usize::try_from(v).map_err(|_| invalid(format!("{name} is {v}, must not be negative")))
    };
    let slice = RangeSlice {
        utime: msg.utime,
        frame_utime: msg.frame_utime,
        sensor: msg.sensor,
        vehicle_from_sensor,
        frame_rows: size("frame_rows", msg.frame_rows)?,
        frame_cols: size("frame_cols", msg.frame_cols)?,
        axis,
        first: size("first", msg.first)?,
        beams: BeamTable {
            elevation: msg.elevation,
            azimuth: msg.azimuth,
        },
        line_utimes: msg.line_utime,
        range: msg.range,
    };
    slice.validate().map_err(|e| invalid(e.to_string()))?;
    Ok(slice)
}

/// An obstacle report for the wire.
pub fn obstacles_to_wire(report: &ObstacleReport) -> obstacle_cells_t {
    obstacle_cells_t {
        utime: report.utime,
        sensor: report.sensor.clone(),
        cell_size: report.cell_size_m as f32,
        num_cells: report.cells.len() as i32,
        cells: report
            .cells
            .iter()
            .map(|c| obstacle_cell_t {
                x: c.x,
                y: c.y,
                z_min: c.z_min,
                z_max: c.z_max,
                reasons: c.reasons.bits() as i8,
                region: c.region as i32,
                cost: c.cost,
            })
            .collect(),
        num_fov: report.fov.vertices.len() as i32,
        fov: report.fov.vertices.iter().map(|v| [v.x, v.y]).collect(),
        shadow_origin: [report.shadows.origin.x, report.shadows.origin.y],
        num_shadows: report.shadows.sectors.len() as i32,
        shadows: report
            .shadows
            .sectors
            .iter()
            .map(|s| [s.azimuth, s.half_width, s.near, s.far])
            .collect(),
        heights_cell: report.heights_cell_m as f32,
        num_heights: report.heights.len() as i32,
        // Cells of at least 5 cm within the 1e8 m the local map accepts fit
        // an i32; one that does not saturates and lands outside the map.
        height_cells: report
            .heights
            .iter()
            .map(|h| [saturate(h.i), saturate(h.j)])
            .collect(),
        heights: report.heights.iter().map(|h| [h.z, h.variance]).collect(),
        acquired_utime: report.acquired_utime(),
    }
}

fn saturate(i: i64) -> i32 {
    i32::try_from(i).unwrap_or(if i < 0 { i32::MIN } else { i32::MAX })
}

/// An obstacle report from the wire; regions are rebuilt from the cells.
pub fn obstacles_from_wire(msg: obstacle_cells_t) -> Result<ObstacleReport, WireError> {
    plausible("obstacle cells", &[msg.utime, msg.acquired_utime])?;
    let invalid = |reason: String| WireError::Invalid {
        what: "obstacle cells",
        reason,
    };
    let mut regions: Vec<Region> = Vec::new();
    let mut cells = Vec::with_capacity(msg.cells.len());
    for c in &msg.cells {
        if !(c.x.is_finite() && c.y.is_finite()) {
            return Err(invalid(format!(
                "cell at ({}, {}) is not a finite position",
                c.x, c.y
            )));
        }
        let region = u32::try_from(c.region)
            .map_err(|_| invalid(format!("region {} is negative", c.region)))?;
        if region as usize >= 1 << 20 {
            return Err(invalid(format!("region {region} is implausibly large")));
        }
        if !(c.cost.is_finite() && c.cost > 0.0 && c.cost <= 1.0) {
            return Err(invalid(format!(
                "cell at ({}, {}) has cost {}: a cell's cost lies in (0, 1]",
                c.x, c.y, c.cost
            )));
        }
        let reasons = Reasons::from_bits(c.reasons as u8);
        if regions.len() <= region as usize {
            regions.resize(
                region as usize + 1,
                Region {
                    cells: 0,
                    reasons: Reasons::NONE,
                },
            );
        }
        regions[region as usize].cells += 1;
        regions[region as usize].reasons.insert(reasons);
        cells.push(ObstacleCell {
            x: c.x,
            y: c.y,
            z_min: c.z_min,
            z_max: c.z_max,
            reasons,
            region,
            cost: c.cost,
        });
    }
    if msg.fov.iter().flatten().any(|v| !v.is_finite()) {
        return Err(invalid(
            "field-of-view polygon has a vertex that is not finite".into(),
        ));
    }
    if !msg.shadow_origin.iter().all(|v| v.is_finite()) {
        return Err(invalid("shadow origin is not finite".into()));
    }
    let mut sectors = Vec::with_capacity(msg.shadows.len());
    for &[azimuth, half_width, near, far] in &msg.shadows {
        let shadow = Shadow {
            azimuth,
            half_width,
            near,
            far,
        };
        if !shadow.is_valid() {
            return Err(invalid(format!(
                "shadow [{azimuth}, {half_width}, {near}, {far}] is not a column's: direction and distances must be finite, half width 0 to {} rad, 0 <= near <= far",
                Shadow::MAX_HALF_WIDTH
            )));
        }
        sectors.push(shadow);
    }
    let heights_cell_m = f64::from(msg.heights_cell);
    let cell_ok = heights_cell_m.is_finite() && heights_cell_m >= 0.01;
    if !(msg.heights.is_empty() || cell_ok) {
        return Err(invalid(format!(
            "height measurements in cells of {heights_cell_m} m: at least 0.01 m is needed"
        )));
    }
    let mut heights = Vec::with_capacity(msg.heights.len());
    for (&[i, j], &[z, variance]) in msg.height_cells.iter().zip(&msg.heights) {
        if !(z.is_finite() && variance.is_finite() && variance > 0.0) {
            return Err(invalid(format!(
                "height measurement {z} m with variance {variance} m² in cell ({i}, {j}): both must be finite, the variance > 0"
            )));
        }
        heights.push(HeightSample {
            i: i64::from(i),
            j: i64::from(j),
            z,
            variance,
        });
    }
    if msg.acquired_utime < msg.utime {
        return Err(invalid(format!(
            "cells acquired at {} µs, before their image's capture at {} µs",
            msg.acquired_utime, msg.utime
        )));
    }
    Ok(ObstacleReport {
        utime: msg.utime,
        acquired: msg.acquired_utime,
        sensor: msg.sensor,
        cell_size_m: f64::from(msg.cell_size),
        cells,
        regions,
        fov: FovPolygon::new(msg.fov.iter().map(|v| Point2::new(v[0], v[1])).collect()),
        shadows: Shadows {
            origin: Point2::new(msg.shadow_origin[0], msg.shadow_origin[1]),
            sectors,
        },
        heights,
        heights_cell_m,
    })
}

/// A behaviour's votes for the wire.
pub fn votes_to_wire(votes: &BehaviourVotes, arcs: &ArcSet) -> arc_votes_t {
    let n = votes.votes.len();
    let causes = votes.votes.causes();
    arc_votes_t {
        utime: votes.utime,
        behaviour: votes.behaviour.clone(),
        num_arcs: n as i32,
        curvature: arcs.curvatures().iter().map(|&k| k as f32).collect(),
        votes: votes.votes.values().to_vec(),
        vetoed: votes.votes.vetoed().to_vec(),
        has_speed_vote: votes.votes.speed_mps().is_some(),
        speed_vote: votes.votes.speed_mps().unwrap_or(0.0),
        arc_speed: votes
            .votes
            .arc_speeds()
            .iter()
            .map(|&s| if s.is_finite() { s } else { -1.0 })
            .collect(),
        reverse_clear: votes.votes.reverse_clearances().to_vec(),
        forward_clear: votes.votes.forward_clearances().to_vec(),
        veto_cause: causes
            .iter()
            .map(|c| match c {
                Some(VetoCause::Cell(_)) => arc_votes_t::CELL,
                Some(VetoCause::AreaEdge(_)) => arc_votes_t::AREA,
                None => arc_votes_t::NOT_SAID,
            })
            .collect(),
        veto_x: causes
            .iter()
            .map(|c| c.map_or(0.0, |c| c.at()[0]))
            .collect(),
        veto_y: causes
            .iter()
            .map(|c| c.map_or(0.0, |c| c.at()[1]))
            .collect(),
    }
}

/// What `DECISION` says of a command besides the arbiter's reason.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Said<'a> {
    /// The arbiter decided it, for this reason.
    Arbiter(&'a Reason),
    /// The watchdog stopped: an input is stale (the hazard in words).
    StaleInput(&'a str),
    /// The last command again: this cycle's decision is late.
    Held,
    /// The executor is shutting down.
    Final,
    /// The guard stopped or slowed the pipeline's command (why, in words).
    Guard(&'a str),
}

/// Why the command at `utime` is what it is, for the wire.
pub fn decision_to_wire(utime: Utime, said: Said<'_>) -> decision_t {
    let (cause, reason, vetoers): (i8, String, &[Vetoer]) = match said {
        Said::Arbiter(reason) => {
            let cause = match reason {
                Reason::Drive => decision_t::DRIVE,
                Reason::Manoeuvre { .. } => decision_t::MANOEUVRE,
                Reason::SpeedLimited { .. } => decision_t::SPEED_LIMITED,
                Reason::Stop { stop, .. } => match stop {
                    StopReason::AllArcsForbidden { .. } => decision_t::ALL_ARCS_VETOED,
                    StopReason::NoAcceptableArc { .. } => decision_t::NO_ACCEPTABLE_ARC,
                    StopReason::NoVotes => decision_t::NO_VOTES,
                    StopReason::RequiredStale { .. } => decision_t::REQUIRED_STALE,
                    StopReason::Stuck { .. } => decision_t::STUCK,
                },
            };
            let vetoers = match reason {
                Reason::Stop { vetoers, .. } => vetoers.as_slice(),
                _ => &[],
            };
            (cause, reason.to_string(), vetoers)
        }
        Said::StaleInput(hazard) => (decision_t::STALE_INPUT, format!("watchdog: {hazard}"), &[]),
        Said::Held => (
            decision_t::HELD,
            "the last command again: this cycle's decision is late".into(),
            &[],
        ),
        Said::Final => (decision_t::FINAL, "shutting down".into(), &[]),
        Said::Guard(why) => (decision_t::GUARD, format!("guard: {why}"), &[]),
    };
    decision_t {
        utime,
        cause,
        reason,
        num_vetoers: vetoers.len() as i32,
        vetoer: vetoers.iter().map(|v| v.behaviour.clone()).collect(),
        vetoed_arcs: vetoers
            .iter()
            .map(|v| i32::try_from(v.arcs).unwrap_or(i32::MAX))
            .collect(),
        // Only a cell has a place here (the area's edge is said in the
        // reason's words).
        has_cell: vetoers.iter().map(|v| cell_of(v).is_some()).collect(),
        cell_x: vetoers
            .iter()
            .map(|v| cell_of(v).map_or(0.0, |c| c[0]))
            .collect(),
        cell_y: vetoers
            .iter()
            .map(|v| cell_of(v).map_or(0.0, |c| c[1]))
            .collect(),
    }
}

/// The cell behind a vetoer's veto, when a cell is.
fn cell_of(v: &Vetoer) -> Option<[f32; 2]> {
    match v.cause {
        Some(VetoCause::Cell(at)) => Some(at),
        _ => None,
    }
}

/// A recorded `DECISION`: why the command at `utime` was what it was.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedDecision {
    pub utime: Utime,
    /// `decision_t`'s cause code (a newer writer's unknown code is kept).
    pub cause: i8,
    pub reason: String,
    pub vetoers: Vec<Vetoer>,
}

impl RecordedDecision {
    /// Whether its cause is one of the pipeline's stops (a guard's
    /// verdict may be a stop or a slow: see the command).
    pub fn is_stop(&self) -> bool {
        (decision_t::SPEED_LIMITED..=decision_t::FINAL).contains(&self.cause)
            && self.cause != decision_t::HELD
    }
}

/// A `DECISION` from the wire.
pub fn decision_from_wire(msg: &decision_t) -> Result<RecordedDecision, WireError> {
    plausible("decision", &[msg.utime])?;
    let vetoers = (0..msg.vetoer.len())
        .map(|i| Vetoer {
            behaviour: msg.vetoer[i].clone(),
            arcs: usize::try_from(msg.vetoed_arcs[i]).unwrap_or(0),
            cause: (msg.has_cell[i] && msg.cell_x[i].is_finite() && msg.cell_y[i].is_finite())
                .then(|| VetoCause::Cell([msg.cell_x[i], msg.cell_y[i]])),
        })
        .collect();
    Ok(RecordedDecision {
        utime: msg.utime,
        cause: msg.cause,
        reason: msg.reason.clone(),
        vetoers,
    })
}

/// The guard's verdict at `utime` (sensor clock) on the command stamped
/// `command_utime`, for the wire.
pub fn guard_status_to_wire(
    utime: Utime,
    command_utime: Utime,
    verdict: &arcnav_guard::Verdict,
) -> guard_status_t {
    use arcnav_guard::Verdict;
    let (code, cap) = match verdict {
        Verdict::Clear => (guard_status_t::CLEAR, 0.0),
        Verdict::Slow { cap_mps, .. } => (guard_status_t::SLOW, *cap_mps),
        Verdict::Stop { .. } => (guard_status_t::STOP, 0.0),
    };
    guard_status_t {
        utime,
        command_utime,
        verdict: code,
        reason: verdict
            .reason()
            .map(ToString::to_string)
            .unwrap_or_default(),
        speed_cap: cap,
    }
}

/// A recorded `GUARD_STATUS`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedGuard {
    pub utime: Utime,
    pub command_utime: Utime,
    /// `guard_status_t::CLEAR`, `SLOW` or `STOP`.
    pub verdict: i8,
    pub reason: String,
    pub speed_cap_mps: f64,
}

impl std::fmt::Display for RecordedGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.verdict {
            guard_status_t::STOP => write!(f, "STOP: {}", self.reason),
            guard_status_t::SLOW => {
                write!(f, "SLOW to {:.2} m/s: {}", self.speed_cap_mps, self.reason)
            }
            _ => write!(f, "clear"),
        }
    }
}

/// A `GUARD_STATUS` from the wire.
pub fn guard_status_from_wire(msg: &guard_status_t) -> Result<RecordedGuard, WireError> {
    plausible("guard status", &[msg.utime, msg.command_utime])?;
    let invalid = |reason: String| WireError::Invalid {
        what: "guard status",
        reason,
    };
    if !(guard_status_t::CLEAR..=guard_status_t::STOP).contains(&msg.verdict) {
        return Err(invalid(format!(
            "verdict {} is none of 0, 1, 2",
            msg.verdict
        )));
    }
    if !(msg.speed_cap.is_finite() && msg.speed_cap >= 0.0) {
        return Err(invalid(format!("speed cap {} m/s", msg.speed_cap)));
    }
    Ok(RecordedGuard {
        utime: msg.utime,
        command_utime: msg.command_utime,
        verdict: msg.verdict,
        reason: msg.reason.clone(),
        speed_cap_mps: msg.speed_cap,
    })
}

/// A behaviour's votes from the wire; they must be over `arcs`.
pub fn votes_from_wire(msg: &arc_votes_t, arcs: &ArcSet) -> Result<BehaviourVotes, WireError> {
    plausible("arc votes", &[msg.utime])?;
    let invalid = |reason: String| WireError::Invalid {
        what: "arc votes",
        reason,
    };
    if msg.votes.len() != arcs.len() {
        return Err(invalid(format!(
            "{} voted over {} arcs, this arc set has {}",
            msg.behaviour,
            msg.votes.len(),
            arcs.len()
        )));
    }
    let tolerance = (arcs.spacing() / 4.0) as f32;
    if let Some(i) = (0..arcs.len())
        .find(|&i| (msg.curvature[i] - arcs.curvatures()[i] as f32).abs() > tolerance)
    {
        return Err(invalid(format!(
            "{}'s arc {i} has curvature {}, this arc set's is {:.5}",
            msg.behaviour,
            msg.curvature[i],
            arcs.curvatures()[i]
        )));
    }
    let mut votes = Votes::new(arcs.len());
    for (i, (&v, &vetoed)) in msg.votes.iter().zip(&msg.vetoed).enumerate() {
        if vetoed {
            // A cell's position, when given and finite (another cause, or
            // none, is a veto without one).
            let at = |v: &[f32]| v.get(i).copied().unwrap_or(f32::NAN);
            let cell = [at(&msg.veto_x), at(&msg.veto_y)];
            let cause = match msg.veto_cause.get(i) {
                _ if !cell.iter().all(|c| c.is_finite()) => None,
                Some(&arc_votes_t::CELL) => Some(VetoCause::Cell(cell)),
                Some(&arc_votes_t::AREA) => Some(VetoCause::AreaEdge(cell)),
                _ => None,
            };
            votes.veto_for(i, cause);
        } else {
            votes.set(i, v);
        }
    }
    if msg.has_speed_vote {
        votes.vote_speed(msg.speed_vote);
    }
    for (i, &speed) in msg.arc_speed.iter().enumerate() {
        // Negative: no limit; NaN is no number of m/s: 0.
        if speed >= 0.0 || speed.is_nan() {
            votes.limit_arc_speed(i, f64::from(speed));
        }
    }
    // Negative: no opinion; NaN is no number of metres: 0.
    let given = |metres: &f32| *metres >= 0.0 || metres.is_nan();
    for (i, &metres) in msg.reverse_clear.iter().enumerate() {
        if given(&metres) {
            votes.set_reverse_clearance(i, f64::from(metres));
        }
    }
    for (i, &metres) in msg.forward_clear.iter().enumerate() {
        if given(&metres) {
            votes.set_forward_clearance(i, f64::from(metres));
        }
    }
    Ok(BehaviourVotes {
        behaviour: msg.behaviour.clone(),
        utime: msg.utime,
        votes,
    })
}

/// A mission for the wire.
pub fn mission_to_wire(mission: &Mission) -> waypoints_t {
    waypoints_t {
        utime: mission.version,
        num_waypoints: mission.waypoints.len() as i32,
        position: mission.waypoints.iter().map(|w| [w.x, w.y]).collect(),
        radius: mission
            .waypoints
            .iter()
            .map(|w| w.radius_m.unwrap_or(0.0) as f32)
            .collect(),
    }
}

/// A mission from the wire.
pub fn mission_from_wire(msg: &waypoints_t) -> Result<Mission, WireError> {
    let waypoints = msg
        .position
        .iter()
        .zip(&msg.radius)
        .map(|(p, &r)| {
            // Also false for a NaN or infinite coordinate.
            let near = p.iter().all(|v| v.abs() <= MAX_COORDINATE_M);
            if near && r.is_finite() {
                Ok(Waypoint {
                    x: p[0],
                    y: p[1],
                    radius_m: (r > 0.0).then_some(f64::from(r)),
                })
            } else {
                Err(WireError::Invalid {
                    what: "waypoints",
                    reason: format!(
                        "waypoint ({}, {}) radius {r} is not finite or lies farther than \
                         {MAX_COORDINATE_M} m from the origin",
                        p[0], p[1]
                    ),
                })
            }
        })
        .collect::<Result<_, _>>()?;
    Ok(Mission {
        version: msg.utime,
        waypoints,
    })
}

/// A local-map snapshot as one decision cycle sees it (channel LOCAL_MAP).
#[derive(Debug, Clone, PartialEq)]
pub struct MapMessage {
    /// The decision cycle the snapshot is for; votes on it carry this time.
    pub cycle_utime: Utime,
    /// The pose the snapshot is expressed in (its time is `map.utime`).
    pub pose: Pose,
    pub map: MapSnapshot,
    /// Map resets so far.
    pub resets: u64,
}

/// A cycle's map for the wire.
pub fn map_to_wire(cycle_utime: Utime, pose: &Pose, map: &MapSnapshot, resets: u64) -> local_map_t {
    let (position, orientation) = position_and_rotation(&map.world_from_vehicle);
    let s = map.patch_size_m;
    local_map_t {
        utime: map.utime,
        position,
        orientation,
        patch_size: s as f32,
        num_patches: map.patches.len() as i32,
        patches: map
            .patches
            .iter()
            .map(|p| local_map_patch_t {
                x: p.x,
                y: p.y,
                world_x: (p.i as f64 + 0.5) * s,
                world_y: (p.j as f64 + 0.5) * s,
                first_seen: p.first_seen,
                last_seen: p.last_seen,
                confirmations: p.confirmations as i32,
                reasons: p.reasons.bits() as i8,
                z_min: p.z_min,
                z_max: p.z_max,
                misses: p.misses as i32,
                sensors: p.sensors as i32,
                cost: p.cost,
            })
            .collect(),
        cycle_utime,
        velocity: [pose.velocity.x, pose.velocity.y, pose.velocity.z],
        yaw_rate: pose.yaw_rate,
        resets: i32::try_from(resets).unwrap_or(i32::MAX),
        seen_origin: [map.seen.i0, map.seen.j0],
        seen_side: map.seen.side as i32,
        num_seen_words: map.seen.words.len() as i32,
        seen: map.seen.words.iter().map(|&w| w as i64).collect(),
        elevation_cell: map.elevation.cell_size_m as f32,
        elevation_origin: [map.elevation.origin.0, map.elevation.origin.1],
        elevation_side: map.elevation.side as i32,
        num_elevation: map.elevation.cells.len() as i32,
        elevation: map.elevation.cells.clone(),
    }
}

/// Empties a map message's elevation square (for receivers that do not
/// use it: the rest of the message is a tenth of its size).
pub fn drop_elevation(msg: &mut local_map_t) {
    msg.elevation_side = 0;
    msg.num_elevation = 0;
    msg.elevation.clear();
}

/// A cycle's map from the wire. Patch indices come back from the world
/// centres (exact doubles), not from the `float` patch size.
pub fn map_from_wire(msg: &local_map_t) -> Result<MapMessage, WireError> {
    plausible("local map", &[msg.utime, msg.cycle_utime])?;
    let invalid = |reason: String| WireError::Invalid {
        what: "local map",
        reason,
    };
    let world_from_vehicle =
        isometry_from_parts(msg.position, msg.orientation).map_err(|source| WireError::Frame {
            what: "local map pose",
            source,
        })?;
    let size = decimal_of(msg.patch_size);
    if !(size.is_finite() && size > 0.0) {
        return Err(invalid(format!("patch size {size} is not positive")));
    }
    if !(msg.velocity.iter().all(|v| v.is_finite()) && msg.yaw_rate.is_finite()) {
        return Err(invalid("velocity or yaw rate is not finite".into()));
    }
    let mut patches = Vec::with_capacity(msg.patches.len());
    for p in &msg.patches {
        let (i, j) = (p.world_x / size, p.world_y / size);
        if !(i.is_finite() && j.is_finite() && i.abs() < 1e15 && j.abs() < 1e15) {
            return Err(invalid(format!(
                "patch at ({}, {}) is not a finite position",
                p.world_x, p.world_y
            )));
        }
        let counts = [p.confirmations, p.misses, p.sensors];
        if counts[..2].iter().any(|&c| c < 0) {
            return Err(invalid(format!(
                "patch at ({}, {}) has a negative count",
                p.world_x, p.world_y
            )));
        }
        let mut patch = Patch::at(i.floor() as i64, j.floor() as i64);
        patch.x = p.x;
        patch.y = p.y;
        patch.first_seen = p.first_seen;
        patch.last_seen = p.last_seen;
        patch.confirmations = counts[0] as u32;
        patch.misses = counts[1] as u32;
        patch.sensors = counts[2] as u32;
        patch.reasons = Reasons::from_bits(p.reasons as u8);
        patch.z_min = p.z_min;
        patch.z_max = p.z_max;
        if !(p.cost.is_finite() && p.cost > 0.0 && p.cost <= 1.0) {
            return Err(invalid(format!(
                "patch at ({}, {}) has cost {}: a patch's cost lies in (0, 1]",
                p.world_x, p.world_y, p.cost
            )));
        }
        patch.cost = p.cost;
        patches.push(patch);
    }
    let side = u32::try_from(msg.seen_side)
        .ok()
        .filter(|&side| SeenGround::words_for(side) == msg.seen.len())
        .ok_or_else(|| {
            invalid(format!(
                "seen ground of side {} needs {} words, the message holds {}",
                msg.seen_side,
                SeenGround::words_for(msg.seen_side.max(0) as u32),
                msg.seen.len()
            ))
        })?;
    let seen = SeenGround {
        i0: msg.seen_origin[0],
        j0: msg.seen_origin[1],
        side,
        words: msg.seen.iter().map(|&w| w as u64).collect(),
    };
    let elevation = elevation_from_wire(msg).map_err(invalid)?;
    Ok(MapMessage {
        cycle_utime: msg.cycle_utime,
        pose: Pose {
            utime: msg.utime,
            world_from_vehicle,
            velocity: Vector3::from(msg.velocity),
            yaw_rate: msg.yaw_rate,
        },
        map: MapSnapshot {
            utime: msg.utime,
            world_from_vehicle,
            patch_size_m: size,
            patches,
            seen,
            elevation: std::sync::Arc::new(elevation),
        },
        resets: u64::try_from(msg.resets).unwrap_or(0),
    })
}

/// The `double` a `float` size on the wire was written from: the
/// shortest decimal that reads back as that `float` (0.4 for a patch of
/// 0.4 m, not 0.4000000059604645). Sizes come from configuration, in a few
/// decimals; with the widened `float` instead, a node across the bus cut
/// the ground into cells a hair larger than the map's own, and near a
/// cell's edge decided a near tie otherwise than the same pipeline in one
/// process.
fn decimal_of(x: f32) -> f64 {
    if x.is_finite() {
        x.to_string().parse().unwrap_or(f64::from(x))
    } else {
        f64::from(x)
    }
}

/// The elevation square of a local-map message.
fn elevation_from_wire(msg: &local_map_t) -> Result<ElevationGrid, String> {
    let side = u32::try_from(msg.elevation_side)
        .ok()
        .filter(|&side| side as usize * side as usize == msg.elevation.len())
        .ok_or_else(|| {
            format!(
                "elevation square of side {} needs its square of cells, the message holds {}",
                msg.elevation_side,
                msg.elevation.len()
            )
        })?;
    let cell = decimal_of(msg.elevation_cell);
    if side > 0 && !(cell.is_finite() && cell >= 0.01) {
        return Err(format!(
            "elevation cells of {cell} m: at least 0.01 m is needed"
        ));
    }
    if msg.elevation_origin.iter().any(|o| o.abs() > 1 << 40) {
        return Err(format!(
            "elevation origin {:?} is not a place on Earth",
            msg.elevation_origin
        ));
    }
    Ok(ElevationGrid {
        cell_size_m: cell,
        origin: (msg.elevation_origin[0], msg.elevation_origin[1]),
        side,
        cells: msg.elevation.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_perception::SensorModel;
    use arcnav_vehicle::ArcSetConfig;

    #[test]
    fn range_images_round_trip() {
        let mut image = SensorModel::erim().blank_image(42);
        image.range[7] = 12.5;
        let back = range_image_from_wire(range_image_to_wire(&image)).unwrap();
        assert_eq!(back.range[7], 12.5);
        assert_eq!(back.beams, image.beams);
        assert!(
            (back.vehicle_from_sensor.translation.vector
                - image.vehicle_from_sensor.translation.vector)
                .norm()
                < 1e-12
        );
        let mut bad = range_image_to_wire(&image);
        bad.mount_orientation = [0.0; 4];
        assert!(range_image_from_wire(bad).is_err());
    }

    #[test]
    fn range_slices_round_trip_and_bad_ones_are_refused_with_a_reason() {
        let mut image = SensorModel::lidar64().blank_image(1_000);
        image.range[70] = 3.25;
        let slices = RangeSlice::cut(&image, SliceAxis::Columns, 16, |c| 1_000 + c as Utime);
        for slice in &slices[..3] {
            let back = range_slice_from_wire(range_slice_to_wire(slice)).unwrap();
            assert_eq!(back.range.len(), slice.range.len());
            assert_eq!(back.line_utimes, slice.line_utimes);
            assert_eq!(
                (back.first, back.axis, back.utime),
                (slice.first, slice.axis, slice.utime)
            );
            assert_eq!(back.beams, slice.beams);
        }
        assert_eq!(
            range_slice_from_wire(range_slice_to_wire(&slices[4]))
                .unwrap()
                .range[6],
            3.25
        );
        let refused = |edit: &dyn Fn(&mut range_slice_t)| {
            let mut msg = range_slice_to_wire(&slices[1]);
            edit(&mut msg);
            range_slice_from_wire(msg).unwrap_err().to_string()
        };
        assert!(refused(&|m| m.axis = 2).contains("axis 2"));
        assert!(refused(&|m| m.first = -1).contains("first is -1"));
        assert!(refused(&|m| m.first = 2040).contains("does not fit"));
        assert!(refused(&|m| m.frame_rows = i32::MAX).contains("more than"));
        assert!(refused(&|m| m.frame_cols = 0).contains("empty"));
        assert!(refused(&|m| m.mount_orientation = [0.0; 4]).contains("mount"));
        assert!(refused(&|m| m.utime = m.frame_utime - 1).contains("before its frame"));
        assert!(refused(&|m| m.line_utime[3] = i64::MAX).contains("outside its frame"));
        for t in [i64::MIN, -5, i64::MAX] {
            assert!(refused(&|m| m.frame_utime = t).contains("not on a vehicle's clock"));
            assert!(refused(&|m| m.utime = t).contains("not on a vehicle's clock"));
        }
        assert!(
            refused(&|m| {
                m.line_utime.pop();
                m.num_lines -= 1;
            })
            .contains("line times")
        );
    }

    #[test]
    fn obstacle_reports_round_trip_with_their_regions() {
        let report = ObstacleReport {
            utime: 5,
            acquired: 7,
            sensor: "erim".into(),
            cell_size_m: 0.2,
            cells: vec![
                ObstacleCell {
                    x: 1.0,
                    y: 2.0,
                    z_min: 0.0,
                    z_max: 0.5,
                    reasons: Reasons::SLOPE,
                    region: 0,
                    cost: 1.0,
                },
                ObstacleCell {
                    x: 1.2,
                    y: 2.0,
                    z_min: 0.0,
                    z_max: 0.6,
                    reasons: Reasons::HEIGHT_VARIATION,
                    region: 0,
                    cost: 1.0,
                },
                ObstacleCell {
                    x: 9.0,
                    y: 2.0,
                    z_min: 0.0,
                    z_max: 0.6,
                    reasons: Reasons::DISCONTINUITY,
                    region: 1,
                    cost: 1.0,
                },
            ],
            regions: vec![
                Region {
                    cells: 2,
                    reasons: Reasons::SLOPE.union(Reasons::HEIGHT_VARIATION),
                },
                Region {
                    cells: 1,
                    reasons: Reasons::DISCONTINUITY,
                },
            ],
            fov: FovPolygon::new(vec![
                Point2::new(0.0, 0.0),
                Point2::new(10.0, 0.0),
                Point2::new(5.0, 5.0),
            ]),
            shadows: Shadows {
                origin: Point2::new(-1.0, 0.5),
                sectors: vec![Shadow {
                    azimuth: 0.25,
                    half_width: 0.003,
                    near: 6.5,
                    far: 9.0,
                }],
            },
            heights: vec![HeightSample {
                i: -12,
                j: 400,
                z: 1.5,
                variance: 0.0009,
            }],
            heights_cell_m: 0.25,
        };
        let mut report = report;
        report.cells[2].cost = 0.8;
        let back = obstacles_from_wire(obstacles_to_wire(&report)).unwrap();
        assert_eq!(back.cells, report.cells);
        let mut bad = obstacles_to_wire(&report);
        bad.cells[1].cost = 1.5;
        let error = obstacles_from_wire(bad).unwrap_err().to_string();
        assert!(error.contains("cost"), "{error}");
        assert_eq!(back.heights, report.heights);
        assert_eq!(back.heights_cell_m, 0.25);
        let mut bad = obstacles_to_wire(&report);
        bad.heights[0][1] = -1.0;
        let error = obstacles_from_wire(bad).unwrap_err().to_string();
        assert!(error.contains("variance"), "{error}");
        assert_eq!(back.regions, report.regions);
        assert_eq!(back.fov, report.fov);
        assert_eq!(back.shadows, report.shadows);
        let mut bad = obstacles_to_wire(&report);
        bad.cells[0].region = -1;
        assert!(obstacles_from_wire(bad).is_err());
        // A shadow wider than a column, or with its ends swapped, is refused.
        for shadow in [[0.25, 1.5, 6.5, 9.0], [0.25, 0.003, 9.0, 6.5]] {
            let mut bad = obstacles_to_wire(&report);
            bad.shadows[0] = shadow;
            let error = obstacles_from_wire(bad).unwrap_err().to_string();
            assert!(error.contains("shadow"), "{error}");
        }
        let mut bad = obstacles_to_wire(&report);
        bad.shadow_origin[1] = f64::NAN;
        assert!(obstacles_from_wire(bad).is_err());
    }

    #[test]
    fn votes_round_trip_and_must_match_the_arc_set() {
        let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
        let mut votes = Votes::new(39);
        votes.set(3, 0.5);
        votes.veto(19, Some([1.0, 2.0]));
        votes.vote_speed(1.5);
        votes.limit_arc_speed(4, 2.25);
        votes.limit_arc_speed(5, 0.0);
        votes.set_reverse_clearance(6, 3.5);
        votes.set_reverse_clearance(7, 0.0);
        votes.set_forward_clearance(9, 2.75);
        let bv = BehaviourVotes {
            behaviour: "obstacle_avoidance".into(),
            utime: 9,
            votes,
        };
        votes_are_vetoed_with_their_causes(&bv, &arcs);
        let back = votes_from_wire(&votes_to_wire(&bv, &arcs), &arcs).unwrap();
        assert_eq!(back.votes.values(), bv.votes.values());
        assert_eq!(back.votes.vetoed(), bv.votes.vetoed());
        assert_eq!(
            back.votes.causes(),
            bv.votes.causes(),
            "veto causes survive"
        );
        assert_eq!(back.votes.speed_mps(), Some(1.5));
        assert_eq!(back.votes.arc_speeds(), bv.votes.arc_speeds());
        assert_eq!(back.votes.arc_speed(5), Some(0.0));
        assert_eq!(
            (
                back.votes.reverse_clearance(6),
                back.votes.reverse_clearance(7),
                back.votes.reverse_clearance(8)
            ),
            (Some(3.5), Some(0.0), None),
            "backing-up clearances: given, zero, no opinion"
        );
        assert_eq!(
            (
                back.votes.forward_clearance(9),
                back.votes.forward_clearance(10)
            ),
            (Some(2.75), None),
            "creeping clearances: given, no opinion"
        );
        let other = ArcSet::new(&ArcSetConfig {
            count: 39,
            min_radius_m: 10.0,
            ..Default::default()
        })
        .unwrap();
        let err = votes_from_wire(&votes_to_wire(&bv, &other), &arcs).unwrap_err();
        assert!(err.to_string().contains("arc 0 has curvature"), "{err}");
    }

    /// A veto's cell crosses the wire; one without a cause, or a cell that
    /// is not a number, arrives as a veto without cause.
    fn votes_are_vetoed_with_their_causes(bv: &BehaviourVotes, arcs: &ArcSet) {
        let mut msg = votes_to_wire(bv, arcs);
        assert_eq!(msg.veto_cause[19], arc_votes_t::CELL);
        assert_eq!((msg.veto_x[19], msg.veto_y[19]), (1.0, 2.0));
        msg.vetoed[20] = true;
        msg.vetoed[21] = true;
        msg.veto_cause[21] = arc_votes_t::CELL;
        msg.veto_x[21] = f32::NAN;
        msg.vetoed[22] = true;
        msg.veto_cause[22] = 77;
        msg.vetoed[23] = true;
        msg.veto_cause[23] = arc_votes_t::AREA;
        (msg.veto_x[23], msg.veto_y[23]) = (6.0, -1.5);
        let back = votes_from_wire(&msg, arcs).unwrap();
        assert_eq!(back.votes.causes()[19], Some(VetoCause::Cell([1.0, 2.0])));
        assert_eq!(
            back.votes.causes()[23],
            Some(VetoCause::AreaEdge([6.0, -1.5])),
            "the area's edge is a cause of its own"
        );
        assert_eq!(votes_to_wire(&back, arcs).veto_cause[23], arc_votes_t::AREA);
        for i in 20..=22 {
            assert!(back.votes.is_vetoed(i));
            assert_eq!(back.votes.causes()[i], None, "arc {i}");
        }
    }

    #[test]
    fn a_decision_says_why_on_the_wire_and_back() {
        let vetoes = vec![
            Vetoer {
                behaviour: "obstacle_avoidance".into(),
                arcs: 39,
                cause: Some(VetoCause::Cell([4.5, -0.5])),
            },
            Vetoer {
                behaviour: "terrain".into(),
                arcs: 2,
                cause: None,
            },
        ];
        let stop = Reason::Stop {
            stop: StopReason::AllArcsForbidden {
                vetoes: vetoes.clone(),
            },
            vetoers: vetoes.clone(),
        };
        let msg = decision_to_wire(1_700_000_000_000_000, Said::Arbiter(&stop));
        assert_eq!(msg.cause, decision_t::ALL_ARCS_VETOED);
        let back = decision_from_wire(&msg).unwrap();
        assert!(back.is_stop());
        assert_eq!(back.reason, stop.to_string());
        assert!(
            back.reason
                .contains("obstacle_avoidance vetoed 39, for the cell at (4.5, -0.5) m"),
            "{}",
            back.reason
        );
        assert_eq!(back.vetoers, vetoes);
        for (said, cause) in [
            (Said::Arbiter(&Reason::Drive), decision_t::DRIVE),
            (
                Said::Arbiter(&Reason::Manoeuvre {
                    backing: true,
                    standing: false,
                    in_place: false,
                }),
                decision_t::MANOEUVRE,
            ),
            (
                Said::StaleInput("last pose 0.80 s ago"),
                decision_t::STALE_INPUT,
            ),
            (Said::Held, decision_t::HELD),
            (Said::Final, decision_t::FINAL),
            (
                Said::Guard("a standing return 3.1 m ahead"),
                decision_t::GUARD,
            ),
        ] {
            let msg = decision_to_wire(1_700_000_000_000_000, said);
            assert_eq!(msg.cause, cause);
            assert_eq!(msg.num_vetoers, 0);
            let back = decision_from_wire(&msg).unwrap();
            assert_eq!(back.is_stop(), !matches!(cause, 0 | 1 | 9 | 11), "{said:?}");
        }
        let mut late = decision_to_wire(1, Said::Held);
        late.utime = -5;
        assert!(decision_from_wire(&late).is_err(), "an implausible time");
    }

    #[test]
    fn missions_round_trip() {
        let mission = Mission {
            version: 3,
            waypoints: vec![
                Waypoint {
                    x: 1.0,
                    y: 2.0,
                    radius_m: Some(4.0),
                },
                Waypoint {
                    x: 5.0,
                    y: 6.0,
                    radius_m: None,
                },
            ],
        };
        assert_eq!(
            mission_from_wire(&mission_to_wire(&mission)).unwrap(),
            mission
        );
    }

    #[test]
    fn a_float_size_reads_back_as_the_decimal_it_was_written_from() {
        for size in [0.4, 0.2, 0.1, 0.25, 1.0, 0.35, 12.8] {
            assert_eq!(decimal_of(size as f32), size);
        }
        // A `float` no short decimal wrote reads back as itself.
        let third = 1.0f32 / 3.0;
        assert_eq!(decimal_of(third) as f32, third);
        assert!(decimal_of(f32::NAN).is_nan());
        assert_eq!(decimal_of(f32::INFINITY), f64::INFINITY);
    }

    #[test]
    fn map_cycles_round_trip() {
        let pose = Pose {
            utime: 1_000,
            world_from_vehicle: arcnav_vehicle::frames::isometry_from_xyz_rpy(
                [100.0, -40.0, 2.0],
                0.01,
                -0.02,
                1.2,
            ),
            velocity: Vector3::new(2.0, 1.0, 0.0),
            yaw_rate: 0.1,
        };
        let mut far = Patch::at(-251, 99);
        far.x = 12.5;
        far.y = -3.0;
        far.first_seen = 500;
        far.last_seen = 900;
        far.confirmations = 3;
        far.misses = 1;
        far.sensors = 0b101;
        far.reasons = Reasons::SLOPE;
        far.z_min = -0.25;
        far.z_max = 0.75;
        far.cost = 0.625;
        let map = MapSnapshot {
            utime: pose.utime,
            world_from_vehicle: pose.world_from_vehicle,
            patch_size_m: 0.4,
            patches: vec![far, Patch::at(0, -1), Patch::at(123_456, -7)],
            seen: {
                let mut seen = SeenGround::new(-30, 40, 57);
                seen.insert(-30, 40);
                seen.insert(26, 96);
                seen.insert(0, 77);
                seen
            },
            elevation: std::sync::Arc::new(ElevationGrid {
                cell_size_m: 0.25,
                origin: (-5, 9),
                side: 2,
                cells: vec![[1.0, 0.01], [f32::NAN; 2], [2.5, 0.5], [-1.0, 0.25]],
            }),
        };
        let back = map_from_wire(&map_to_wire(1_020, &pose, &map, 2)).unwrap();
        assert_eq!(back.cycle_utime, 1_020);
        assert_eq!(back.resets, 2);
        assert_eq!(back.pose.utime, 1_000);
        assert!((back.pose.velocity - pose.velocity).norm() < 1e-12);
        assert!(
            (back.pose.world_from_vehicle.translation.vector
                - pose.world_from_vehicle.translation.vector)
                .norm()
                < 1e-9
        );
        assert_eq!(back.map.patches, map.patches);
        assert_eq!(back.map.seen, map.seen);
        // The sizes are the map's own, not their `float`s widened.
        assert_eq!(back.map.patch_size_m, 0.4);
        assert_eq!(back.map.elevation.cell_size_m, 0.25);
        assert_eq!(back.map.elevation.at(-1.1, 2.3), Some([1.0, 0.01]));
        assert_eq!(back.map.elevation.at(-0.9, 2.3), None);
        assert_eq!(back.map.elevation.at(-0.9, 2.6), Some([-1.0, 0.25]));
        let mut bad = map_to_wire(1_020, &pose, &map, 2);
        bad.elevation_side = 3;
        assert!(map_from_wire(&bad).is_err());
        assert!(back.map.seen.contains(26, 96) && !back.map.seen.contains(26, 95));
        let mut bad = map_to_wire(1_020, &pose, &map, 2);
        bad.seen_side = 58;
        assert!(
            map_from_wire(&bad).is_err(),
            "seen words do not match its side"
        );
        let mut bad = map_to_wire(1_020, &pose, &map, 2);
        bad.patches[0].world_x = f64::NAN;
        assert!(map_from_wire(&bad).is_err());
        let mut bad = map_to_wire(1_020, &pose, &map, 2);
        bad.patch_size = 0.0;
        assert!(map_from_wire(&bad).is_err());
        let mut bad = map_to_wire(1_020, &pose, &map, 2);
        bad.patches[1].confirmations = -1;
        assert!(map_from_wire(&bad).is_err());
    }
}
