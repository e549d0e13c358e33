//! The cells under the footprint where the vehicle stands, and which
//! arcs they stop.

use arcnav_vehicle::{Arc, Footprint};
use nalgebra::Point2;

use super::raster::{Raster, Rigid, cells_inside};

/// Cells under the footprint where the vehicle stands (s = 0). The local
/// map clears patches whose centres lie under the body grown by half a
/// patch; rasterised to this behaviour's grid, a patch just beyond that
/// can land in a grid cell inside the footprint, where every arc's sweep
/// meets it at once: all arcs vetoed, forwards and backing, though the
/// patch only touches the body's flank (`short_ditch_09`, a ditch's edge
/// beside the rear overhang after a turn round: stuck for 90 s). Such a
/// cell stops an arc only if driving it takes the footprint deeper over
/// the cell; an arc that slides past it or turns away is free of it.
#[derive(Debug, Clone, Default)]
pub(super) struct UnderStart {
    /// The cells: bitmap word, bit, centre (the raster's frame).
    pub(super) cells: Vec<(usize, u64, Point2<f64>)>,
    /// Scratch: an arc's blocked layer with the cells it leaves cleared.
    pub(super) blocked: Vec<u64>,
}

impl UnderStart {
    /// Finds the cells of `raster` under `footprint` (not those on unseen
    /// ground too: clearing one would clear the unseen ground's block).
    pub(super) fn find(&mut self, raster: &Raster, footprint: &Footprint) {
        self.cells.clear();
        let grid = &raster.grid;
        cells_inside(grid, &footprint.outline(), |row, from, to| {
            for column in from..=to {
                let word = row * grid.words_per_row + column / 64;
                let bit = 1u64 << (column % 64);
                if raster.bitmap[word] & bit != 0 && raster.unseen[word] & bit == 0 {
                    self.cells.push((word, bit, grid.centre(row, column)));
                }
            }
            false
        });
    }

    /// `blocked` as arc `arc` meets it: the cells under the start that
    /// driving the arc does not take `footprint` deeper over cleared;
    /// `None` when there are none (use `blocked` itself).
    pub(super) fn for_arc(
        &mut self,
        blocked: &[u64],
        arc: Arc,
        footprint: &Footprint,
        step: f64,
    ) -> Option<&[u64]> {
        if self.cells.is_empty() {
            return None;
        }
        self.blocked.clear();
        self.blocked.extend_from_slice(blocked);
        for &(word, bit, centre) in &self.cells {
            if !deepens(arc, footprint, centre, step) {
                self.blocked[word] &= !bit;
            }
        }
        Some(&self.blocked)
    }
}

/// Whether driving `arc` takes `footprint` deeper over the point `p` (the
/// arc's start frame, inside the footprint there) within the footprint's
/// own length and width: the point's depth inside the outline, sampled
/// every `step` along the arc, grows.
pub(super) fn deepens(arc: Arc, footprint: &Footprint, p: Point2<f64>, step: f64) -> bool {
    let depth = |q: Point2<f64>| footprint.depth(q);
    let start = depth(p);
    let length = (footprint.x_max - footprint.x_min).hypot(2.0 * footprint.half_width) + step;
    let steps = (length / step).ceil() as usize;
    (1..=steps).any(|i| {
        let q = Rigid::of(&arc.pose_at(i as f64 * step)).invert(p);
        depth(q) > start + 1e-6
    })
}
