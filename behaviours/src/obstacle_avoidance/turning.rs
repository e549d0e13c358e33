//! Turns in place (`[arcs] turn_in_place`, a skid-steer vehicle's arcs of
//! curvature ±∞): the body swept about the turn centre, up to half a turn.
//!
//! A turn meets what the body, grown by half a patch all round and by the
//! margin a manoeuvre keeps (`reverse_margin_m`), would touch as it turns:
//! an obstacle patch, or ground no image has seen (the ground beside and
//! behind a vehicle that looked ahead) not under the body now. The angle it
//! turns clear of both goes out as the arc's forward clearance, in radians
//! (what the arbiter's turn round reads); a turn clear for less than
//! [`MIN_TURN_RAD`] is vetoed; its vote rises from -1 at that angle to +1
//! clear for half a turn.

use arcnav_arbiter::{VetoCause, Votes};
use arcnav_vehicle::{Footprint, TurnInPlace, VehicleConfig};
use nalgebra::Point2;
use std::f64::consts::PI;

use crate::behaviour::VoteContext;

/// How far a turn in place is judged: half a turn, radians.
pub const JUDGED_RAD: f64 = PI;

/// A turn in place clear for less than this is vetoed, radians (15°).
pub const MIN_TURN_RAD: f64 = PI / 12.0;

/// The sweeps of the two turns in place.
#[derive(Debug, Clone)]
pub(super) struct Turning {
    /// Left and right, through [`JUDGED_RAD`].
    turns: [TurnInPlace; 2],
    /// How far from the turn centre the body reaches, m.
    reach: f64,
    /// The body as it stands (its own ground is not unseen ground met).
    body: Footprint,
    /// Spacing of the ground probed for unseen ground, m.
    step: f64,
}

impl Turning {
    pub fn new(vehicle: &VehicleConfig, half_patch: f64, margin_m: f64) -> Self {
        let body = vehicle.footprint();
        let grow = half_patch + margin_m;
        let grown = body.grown(grow, grow, grow);
        let centre = vehicle.turn_centre();
        let reach = grown
            .outline()
            .iter()
            .map(|c| (c - centre).norm())
            .fold(0.0, f64::max);
        let turn = |left| TurnInPlace {
            centre,
            left,
            footprint: grown,
            max_angle: JUDGED_RAD,
        };
        Self {
            turns: [turn(true), turn(false)],
            reach,
            body: body.grown(half_patch, half_patch, half_patch),
            step: half_patch.max(0.05) * 2.0,
        }
    }

    /// The angle each turn (left, right) turns clear, and where it first
    /// meets something (vehicle frame).
    fn clear(&self, ctx: &VoteContext<'_>) -> [(f64, Option<[f32; 2]>); 2] {
        let centre = self.turns[0].centre;
        let mut out = [(JUDGED_RAD, None); 2];
        let mut meet = |p: Point2<f64>| {
            for (turn, best) in self.turns.iter().zip(out.iter_mut()) {
                if let Some(angle) = turn.first_contact(p)
                    && angle < best.0
                {
                    *best = (angle, Some([p.x as f32, p.y as f32]));
                }
            }
        };
        for patch in ctx.map.patches.iter().filter(|p| p.is_obstacle()) {
            let p = Point2::new(f64::from(patch.x), f64::from(patch.y));
            if (p - centre).norm() <= self.reach {
                meet(p);
            }
        }
        let seen = ctx.map.seen_lookup();
        let n = (self.reach / self.step).ceil() as i32;
        for i in -n..=n {
            for j in -n..=n {
                let p = centre + nalgebra::Vector2::new(f64::from(i), f64::from(j)) * self.step;
                if (p - centre).norm() <= self.reach && !self.body.contains(p) && !seen(p.x, p.y) {
                    meet(p);
                }
            }
        }
        out
    }

    /// Votes the turns in place of `ctx.arcs` (the first arc turns right,
    /// the last left).
    pub fn vote(&self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        let [left, right] = self.clear(ctx);
        let last = ctx.arcs.len() - 1;
        for (arc, (clear, at)) in [(0, right), (last, left)] {
            if !ctx.arcs.is_turn_in_place(arc) || arc >= votes.len() {
                continue;
            }
            // Judged here only: what the arcs' sweeps made of it (a path
            // that drives nowhere) is dropped.
            votes.reset(arc);
            votes.set_forward_clearance(arc, clear);
            // Never backed along: it drives nowhere.
            votes.set_reverse_clearance(arc, 0.0);
            if clear < MIN_TURN_RAD {
                votes.veto_for(arc, at.map(VetoCause::Cell));
            } else {
                let share = (clear - MIN_TURN_RAD) / (JUDGED_RAD - MIN_TURN_RAD);
                votes.set(arc, (2.0 * share - 1.0) as f32);
            }
        }
    }
}
