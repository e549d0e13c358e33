//! `[behaviours.route]`: the route planner's keys and their checks.

use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

/// Lives in `[behaviours.route]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RouteConfig {
    /// Side of the square of world remembered around the vehicle, m.
    pub size_m: f64,
    /// Side of a memory cell, m (≤ 1 m).
    pub cell_m: f64,
    /// Arcs head for the point of the path this far from the vehicle, m ...
    pub lookahead_m: f64,
    /// ... or this many seconds ahead at the cruise speed, if farther, s
    /// (see [`crate::goal_seeking::lookahead`]).
    pub lookahead_s: f64,
    /// Head for the farthest point of the path in a straight line over
    /// ground no costlier than the path's (`Route::farthest_in_sight`)
    /// when it is at least the lookahead away, rather than for the
    /// path's point the lookahead along.
    pub sight_line: bool,
    /// Cost of crossing ground no image has seen, relative to seen free ground.
    pub unseen_cost: f64,
    /// Extra cost of ground next to an obstacle (half a vehicle width away).
    pub clearance_cost: f64,
    /// Extra cost of the roughest seen ground, relative to smooth ground:
    /// the planner takes a smooth track beside rubble when both lead there.
    pub rough_cost: f64,
    /// Mean |second difference| of the elevation layer's heights in a cell
    /// at which ground starts to count as rough, and at which it is the
    /// roughest, m.
    pub rough_m: [f64; 2],
    /// Cost of crossing a cell with a suspected drop-off in it, relative to
    /// seen free ground: a detour shorter than about this many cells is
    /// taken rather than a crossing (0, the default: as costly as its
    /// graded cost says, like rough ground).
    pub suspect_cost: f64,
    /// When the vehicle starts to back up, ground no image has seen within
    /// this distance of its front (and 60° of its heading) is shut until
    /// seen, m (0: never).
    pub shut_unseen_m: f64,
    /// ... and from there the unseen cells with seen ground on both sides
    /// (a shadow) within this distance of its front, m (at least
    /// `shut_unseen_m`).
    pub shut_along_m: f64,
    /// A waypoint is reached within this distance (unless it has its own), m.
    pub arrival_radius_m: f64,
    /// A waypoint behind the vehicle and within this many arrival radii is passed.
    pub pass_radius_factor: f64,
    /// An obstacle is certain once seen within this distance of the
    /// vehicle; seen only from farther, it is doubtful, m.
    pub confirm_within_m: f64,
    /// Cost of crossing a doubtful obstacle's cell, relative to seen free
    /// ground: a way through ground seen blocked only from afar is looked
    /// at when the way round is longer than about this many cells.
    pub doubtful_cost: f64,
    /// Vertices a cycle's planning may expand at most (it carries on next cycle).
    pub max_expansions: u64,
    /// Near where the vehicle last stood (as before backing up), the path
    /// being followed is kept while the vehicle is on it and it costs at
    /// most this fraction more than the best plan (0: always the best
    /// plan). See `Route::hold_or_switch`.
    pub hold_fraction: f64,
}

impl Default for RouteConfig {
    fn default() -> Self {
        Self {
            size_m: 200.0,
            cell_m: 1.0,
            lookahead_m: 8.0,
            lookahead_s: 0.0,
            sight_line: false,
            unseen_cost: 2.0,
            clearance_cost: 4.0,
            rough_cost: 4.0,
            rough_m: [0.04, 0.15],
            suspect_cost: 0.0,
            shut_unseen_m: 8.0,
            shut_along_m: 25.0,
            arrival_radius_m: 5.0,
            pass_radius_factor: 2.0,
            confirm_within_m: 12.0,
            doubtful_cost: 50.0,
            max_expansions: 200_000,
            hold_fraction: 0.25,
        }
    }
}

impl RouteConfig {
    /// Checks the keys (relative to the table).
    pub(crate) fn validate(&self) -> Result<(), ConfigError> {
        let c = self;
        config::in_range("cell_m", c.cell_m, 0.1, 1.0)?;
        config::in_range("size_m", c.size_m, 10.0, 2000.0)?;
        let cells = (c.size_m / c.cell_m).round();
        if cells > 4000.0 {
            return Err(ConfigError::new(
                "size_m",
                format!(
                    "is {} m: {cells} cells of {} m across, more than 4000 (use larger cells or a smaller area)",
                    c.size_m, c.cell_m
                ),
            ));
        }
        config::positive("lookahead_m", c.lookahead_m)?;
        config::in_range("lookahead_s", c.lookahead_s, 0.0, 10.0)?;
        config::in_range("unseen_cost", c.unseen_cost, 1.0, 100.0)?;
        config::in_range("clearance_cost", c.clearance_cost, 0.0, 100.0)?;
        config::in_range("rough_cost", c.rough_cost, 0.0, 100.0)?;
        config::in_range("suspect_cost", c.suspect_cost, 0.0, 1000.0)?;
        config::in_range("shut_unseen_m", c.shut_unseen_m, 0.0, 100.0)?;
        config::in_range("shut_along_m", c.shut_along_m, 0.0, 200.0)?;
        config::in_range("hold_fraction", c.hold_fraction, 0.0, 10.0)?;
        config::in_range("confirm_within_m", c.confirm_within_m, 0.0, 1000.0)?;
        config::in_range("doubtful_cost", c.doubtful_cost, 1.0, 10_000.0)?;
        if c.suspect_cost > 0.0 && c.suspect_cost < 1.0 {
            // Cheaper than free ground, it would break the planner's
            // heuristic (a cell costs at least 1).
            return Err(ConfigError::new(
                "suspect_cost",
                format!(
                    "is {}, must be 0 (rough ground) or at least 1 (free ground's cost)",
                    c.suspect_cost
                ),
            ));
        }
        let [smooth, rough] = c.rough_m;
        config::non_negative("rough_m", smooth)?;
        if !(rough > smooth && rough.is_finite()) {
            return Err(ConfigError::new(
                "rough_m",
                format!("is [{smooth}, {rough}], the second value must exceed the first"),
            ));
        }
        config::positive("arrival_radius_m", c.arrival_radius_m)?;
        config::non_negative("pass_radius_factor", c.pass_radius_factor)?;
        if c.max_expansions == 0 {
            return Err(ConfigError::new(
                "max_expansions",
                "is 0, must be at least 1",
            ));
        }
        Ok(())
    }
}
