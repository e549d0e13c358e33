//! Backing up: the backward sweeps over a mirrored raster, and each arc's
//! clearance behind the vehicle.

use arcnav_arbiter::Votes;
use arcnav_vehicle::{Arc, Footprint};

use super::raster::{Entry, Raster, first_in};
use super::under_start::UnderStart;
use crate::behaviour::VoteContext;
use crate::terrain::{ArcTerrain, TerrainCheck};

/// The backward sweeps: one band per arc over a mirrored raster.
#[derive(Debug, Clone)]
pub(super) struct Reverse {
    pub(super) raster: Raster,
    /// Per arc: the body's band, and the band grown by the margin.
    pub(super) bands: Vec<[Vec<Entry>; 2]>,
    /// Scratch: cells and unseen ground together.
    pub(super) blocked: Vec<u64>,
    /// Per arc: the terrain's verdict backing up along it.
    pub(super) verdicts: Vec<ArcTerrain>,
    /// The mirrored body the bands sweep.
    pub(super) footprint: Footprint,
    /// Cells under it where the vehicle stands.
    pub(super) under_start: UnderStart,
}

impl Reverse {
    /// Each arc's clearance backing up: cells, unseen ground and ground the
    /// vehicle cannot stand on (its attitude or chassis) stop it.
    pub(super) fn vote(
        &mut self,
        terrain: &mut TerrainCheck,
        reach: f64,
        ctx: &VoteContext<'_>,
        votes: &mut Votes,
    ) {
        let reverse = self;
        terrain.judge_reverse_arcs(
            &ctx.map.elevation,
            &ctx.map.world_from_vehicle,
            &mut reverse.verdicts,
        );
        reverse.raster.rasterise(ctx);
        reverse.raster.rasterise_unseen(ctx);
        for ((blocked, cell), unseen) in reverse
            .blocked
            .iter_mut()
            .zip(&reverse.raster.bitmap)
            .zip(&reverse.raster.unseen)
        {
            *blocked = cell | unseen;
        }
        reverse
            .under_start
            .find(&reverse.raster, &reverse.footprint);
        let step = reverse.raster.grid.resolution;
        for (arc, [body, margin]) in reverse.bands.iter().enumerate().take(votes.len()) {
            // The body may not meet a cell or unseen ground; the margin
            // beside it may not close on a cell. Cells already inside the
            // margin where the vehicle stands (s = 0: a trunk beside the
            // flank) are left to the body's band; cells inside the body's
            // band there, to the arc's direction ([`UnderStart`]; mirrored,
            // the backward sweep is the forward arc's).
            let curvature = ctx.arcs.curvature(arc).unwrap_or(0.0);
            let blocked = reverse
                .under_start
                .for_arc(
                    &reverse.blocked,
                    Arc::new(curvature),
                    &reverse.footprint,
                    step,
                )
                .unwrap_or(&reverse.blocked);
            let body_hit = first_in(blocked, body, reach as f32).map(|hit| hit.s);
            let moving = margin.partition_point(|e| e.s <= 0.0);
            let margin_hit =
                first_in(&reverse.raster.bitmap, &margin[moving..], reach as f32).map(|hit| hit.s);
            let ground = reverse.verdicts[arc].forbidden.map(|(s, _)| s);
            let clear = body_hit
                .into_iter()
                .chain(margin_hit)
                .map(f64::from)
                .chain(ground)
                .fold(reach, f64::min);
            votes.set_reverse_clearance(arc, clear);
        }
    }
}
