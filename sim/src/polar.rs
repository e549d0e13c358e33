//! The highest ground around one sensor position, binned by heading and
//! horizontal distance: what lets most of a frame's rays skip straight to
//! the few metres where they may meet the ground.
//!
//! Every ray leaves the sensor at `o`, so over the ground it runs straight
//! out along its heading φ, and at horizontal distance `r` it is at height
//! `z(r) = o_z + s·r` (`s` its rise per horizontal metre, the same for a
//! tilted sensor). Over a bin of headings and distances `[r_j, r_{j+1}]`
//! whose highest cell is `h_j`, the ray meets nothing if
//!
//! ```text
//! min(z(r_j), z(r_{j+1})) > h_j
//! ```
//!
//! and where it may, only where `z(r) ≤ h_j`: so a ray is walked cell by
//! cell only over the stretch of the first bins it may dip into, from where
//! it comes down to their highest cell. The answer is the one the full walk
//! gives (`TileView`'s caster): the table only says where nothing can be.
//!
//! Bins are built each frame from the 0.8 m blocks' highest cells: every
//! block raises the bins its square overlaps (its span of headings and of
//! distances from the sensor). Headings are binned by a pseudo-angle
//! (monotone in the angle, no trigonometry), so bins are wedges of slightly
//! unequal widths.

use arcnav_perception::RayCast;
use nalgebra::{Point3, Vector3};

use crate::tiles::{BLOCK_M, BLOCKS, TileView, floor};

/// Heading bins over the full turn.
const HEADINGS: usize = 2048;
/// Distance bins are this wide, m.
const BIN_M: f64 = 0.8;
/// Distance bins per coarse bin (the first pass over a ray's bins).
const GROUP: usize = 8;
/// Rays aimed together before they are cast.
const AIM_BATCH: usize = 64;
/// Widening of every bound, against rounding: pseudo-angle, metres.
const ANGLE_MARGIN: f64 = 1e-7;
const DISTANCE_MARGIN: f64 = 1e-6;
const HEIGHT_MARGIN: f64 = 1e-9;
const RISE_MARGIN: f64 = 1e-9;

/// A monotone stand-in for the heading of (x, y), in [0, 4): 0 along +x,
/// 1 along +y, 2 along −x, 3 along −y ("diamond angle").
fn pseudo_angle(x: f64, y: f64) -> f64 {
    let p = x / (x.abs() + y.abs());
    if y >= 0.0 { 1.0 - p } else { 3.0 + p }
}

fn heading_bin(p: f64) -> i64 {
    floor(p * HEADINGS as f64 / 4.0)
}

/// A [`TileView`] with the highest ground binned around one sensor position:
/// rays from that position are cast through the table, any other ray
/// through the view itself.
#[derive(Debug)]
pub struct PolarView<'a> {
    view: &'a TileView,
    origin: Point3<f64>,
    range_m: f64,
    bins: usize,
    /// Highest cell per (distance bin, heading bin): `[bin · HEADINGS + heading]`.
    highest: Vec<f32>,
    /// The same over groups of `GROUP` distance bins.
    coarse: Vec<f32>,
    /// Per (distance bin, heading bin): a ray rising faster than this (per
    /// horizontal metre) meets nothing in that bin or any nearer one
    /// (rounded up): where a neighbouring ray's search may start.
    clears: Vec<f32>,
}

impl<'a> PolarView<'a> {
    /// Bins the ground of `view` within `range_m` of `origin` (horizontally),
    /// on up to `threads` threads.
    pub fn new(view: &'a TileView, origin: Point3<f64>, range_m: f64, threads: usize) -> Self {
        let range_m = if range_m.is_finite() {
            range_m.max(0.0)
        } else {
            0.0
        };
        let bins = ((range_m / BIN_M).ceil() as usize).max(1);
        let parts = threads.max(1);
        // Each thread bins a share of the tiles into a table of its own;
        // then each takes a share of the headings, merges the tables there
        // (highest wins) and derives the coarse bins and the clearing rises.
        let bin_part = |part: usize| {
            let mut highest = vec![f32::NEG_INFINITY; bins * HEADINGS];
            view.for_each_tile(part, parts, |x0, y0, block_max| {
                bin_tile(&mut highest, bins, &origin, range_m, (x0, y0), block_max);
            });
            highest
        };
        let groups = bins.div_ceil(GROUP);
        let mut coarse = vec![f32::NEG_INFINITY; groups * HEADINGS];
        let mut clears = vec![f32::NEG_INFINITY; bins * HEADINGS];
        let z = origin.z;
        let (mut highest, others) = std::thread::scope(|scope| {
            let others: Vec<_> = (1..parts)
                .map(|part| scope.spawn(move || bin_part(part)))
                .collect();
            let highest = bin_part(0);
            // A thread that panicked binned nothing: its share of the
            // ground is treated as everywhere high (cast in the view).
            let others: Vec<Vec<f32>> = others
                .into_iter()
                .map(|other| {
                    other
                        .join()
                        .unwrap_or_else(|_| vec![f32::INFINITY; bins * HEADINGS])
                })
                .collect();
            (highest, others)
        });
        let width = HEADINGS.div_ceil(parts);
        let others = &others;
        std::thread::scope(|scope| {
            let mut shares = columns(&mut highest, parts)
                .into_iter()
                .zip(columns(&mut coarse, parts))
                .zip(columns(&mut clears, parts))
                .enumerate();
            // The first share on this thread, the others each on one more.
            let here = shares.next();
            for (part, ((mut highest, mut coarse), mut clears)) in shares {
                scope.spawn(move || {
                    derive(
                        &mut highest,
                        others,
                        part * width,
                        &mut coarse,
                        &mut clears,
                        z,
                    );
                });
            }
            if let Some((_, ((mut highest, mut coarse), mut clears))) = here {
                derive(&mut highest, others, 0, &mut coarse, &mut clears, z);
            }
        });
        Self {
            view,
            origin,
            range_m,
            bins,
            highest,
            coarse,
            clears,
        }
    }
}

/// The rows of a `[bin · HEADINGS + heading]` table cut into `parts`
/// ranges of headings: part k's piece of every row.
fn columns(table: &mut [f32], parts: usize) -> Vec<Vec<&mut [f32]>> {
    let width = HEADINGS.div_ceil(parts);
    let mut out: Vec<Vec<&mut [f32]>> = (0..parts).map(|_| Vec::new()).collect();
    for row in table.chunks_exact_mut(HEADINGS) {
        for (k, piece) in row.chunks_mut(width).enumerate() {
            out[k].push(piece);
        }
    }
    out
}

/// For one range of headings (starting at `first`; rows of `highest`,
/// `coarse` and `clears` cut to it): merges the other threads' tables into
/// `highest`, then fills the coarse bins and the clearing rises.
fn derive(
    highest: &mut [&mut [f32]],
    others: &[Vec<f32>],
    first: usize,
    coarse: &mut [&mut [f32]],
    clears: &mut [&mut [f32]],
    z: f64,
) {
    for (bin, row) in highest.iter_mut().enumerate() {
        for other in others {
            let theirs = &other[bin * HEADINGS + first..][..row.len()];
            for (h, o) in row.iter_mut().zip(theirs) {
                *h = h.max(*o);
            }
        }
    }
    for (bin, row) in highest.iter().enumerate() {
        for (g, h) in coarse[bin / GROUP].iter_mut().zip(row.iter()) {
            *g = g.max(*h);
        }
    }
    // A ray rising s per metre clears bin j (from r_j to r_{j+1}) with
    // highest cell h iff min(z + s·r_j, z + s·r_{j+1}) > h: iff
    // s > (h − z)/r_j when h ≥ z (the near edge binds), iff
    // s > (h − z)/r_{j+1} when h < z (the far edge binds). Worked out in
    // f64 (z may be hundreds of metres, h within a millimetre of it), kept
    // in f32 raised by far more than the rounding: a bound only too high
    // starts fewer searches late, never one too late.
    let mut running = vec![f32::NEG_INFINITY; highest.first().map_or(0, |r| r.len())];
    for (bin, (row, out)) in highest.iter().zip(clears.iter_mut()).enumerate() {
        let near = bin as f64 * BIN_M;
        let far = near + BIN_M;
        for ((&top, run), out) in row.iter().zip(&mut running).zip(out.iter_mut()) {
            let above = f64::from(top) - z;
            let bound = if above >= 0.0 {
                if bin == 0 {
                    f32::INFINITY
                } else {
                    (above / near) as f32
                }
            } else {
                (above / far) as f32
            };
            *run = run.max(bound + bound.abs() * 1e-5 + 1e-9);
            *out = *run;
        }
    }
}

/// Raises the bins of `highest` that the blocks of one tile (lower-left
/// corner `corner`, highest cells `block_max`) overlap, as seen from `origin`.
fn bin_tile(
    highest: &mut [f32],
    bins: usize,
    origin: &Point3<f64>,
    range_m: f64,
    corner: (f64, f64),
    block_max: &[f32],
) {
    let (ox, oy) = (origin.x, origin.y);
    let (x0, y0) = corner;
    let side = BLOCKS as f64 * BLOCK_M;
    let nearest = |lo: f64, o: f64| o.clamp(lo, lo + side) - o;
    let (nx, ny) = (nearest(x0, ox), nearest(y0, oy));
    if (nx * nx + ny * ny).sqrt() - DISTANCE_MARGIN > range_m {
        return;
    }
    // The pseudo-angle of every block corner, computed once for the four
    // blocks that share it.
    const SIDE: usize = BLOCKS + 1;
    let mut corners = [0.0f64; SIDE * SIDE];
    for j in 0..SIDE {
        let y = y0 + j as f64 * BLOCK_M - oy;
        for i in 0..SIDE {
            corners[j * SIDE + i] = pseudo_angle(x0 + i as f64 * BLOCK_M - ox, y);
        }
    }
    for j in 0..BLOCKS {
        let (by0, by1) = (y0 + j as f64 * BLOCK_M, y0 + (j + 1) as f64 * BLOCK_M);
        for i in 0..BLOCKS {
            let top = block_max[j * BLOCKS + i];
            let (bx0, bx1) = (x0 + i as f64 * BLOCK_M, x0 + (i + 1) as f64 * BLOCK_M);
            // Distances from the sensor to the block's nearest and farthest point.
            let near_x = ox.clamp(bx0, bx1) - ox;
            let near_y = oy.clamp(by0, by1) - oy;
            let near = (near_x * near_x + near_y * near_y).sqrt() - DISTANCE_MARGIN;
            if near > range_m || top == f32::NEG_INFINITY {
                continue;
            }
            let far_x = (bx0 - ox).abs().max((bx1 - ox).abs());
            let far_y = (by0 - oy).abs().max((by1 - oy).abs());
            let far = (far_x * far_x + far_y * far_y).sqrt() + DISTANCE_MARGIN;
            let first = ((near.max(0.0) / BIN_M) as usize).min(bins - 1);
            let last = ((far / BIN_M) as usize).min(bins - 1);
            // Headings: all of them around a block holding the sensor; else
            // the span of its corners, across +x when it straddles it.
            let holds = bx0 <= ox && ox <= bx1 && by0 <= oy && oy <= by1;
            let (lo, hi) = if holds {
                (0, HEADINGS as i64 - 1)
            } else {
                let wraps = by0 <= oy && oy <= by1 && bx0 > ox;
                let mut lo = f64::INFINITY;
                let mut hi = f64::NEG_INFINITY;
                for k in [
                    j * SIDE + i,
                    j * SIDE + i + 1,
                    (j + 1) * SIDE + i,
                    (j + 1) * SIDE + i + 1,
                ] {
                    let mut p = corners[k];
                    if wraps && p > 2.0 {
                        p -= 4.0;
                    }
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                (
                    heading_bin(lo - ANGLE_MARGIN),
                    heading_bin(hi + ANGLE_MARGIN),
                )
            };
            for bin in first..=last {
                let row = &mut highest[bin * HEADINGS..(bin + 1) * HEADINGS];
                if lo >= 0 && hi < HEADINGS as i64 {
                    for h in &mut row[lo as usize..=hi as usize] {
                        *h = h.max(top);
                    }
                } else {
                    for k in lo..=hi.min(lo + HEADINGS as i64 - 1) {
                        let h = &mut row[k.rem_euclid(HEADINGS as i64) as usize];
                        *h = h.max(top);
                    }
                }
            }
        }
    }
}

impl PolarView<'_> {
    /// Whether rays from `origin` to `max_range` may be cast through the
    /// table (else they are cast in the view).
    fn binned(&self, origin: &Point3<f64>, max_range: f64) -> bool {
        *origin == self.origin && max_range <= self.range_m
    }

    /// The first distance along `d` (from the table's origin) to a cell the
    /// ray dips to. `hint` is where a neighbouring ray's search started (0:
    /// none); it is set to where this one's started.
    fn cast_from(&self, d: &Vector3<f64>, max_range: f64, hint: &mut usize) -> Option<f64> {
        match Aimed::new(d) {
            Some(ray) => self.cast_aimed(&ray, max_range, hint),
            None => self.view.cast(&self.origin, d, max_range),
        }
    }

    /// [`cast_from`](Self::cast_from) for a ray already aimed.
    fn cast_aimed(&self, ray: &Aimed, max_range: f64, hint: &mut usize) -> Option<f64> {
        let origin = &self.origin;
        let d = &ray.d;
        let heading = ray.heading;
        let rise = ray.rise;
        // The ray's lowest height over a bin (a group of bins) starting at
        // `near`: at its near edge when it rises, at its far edge when it
        // falls.
        let base = origin.z - HEIGHT_MARGIN;
        let (bin_drop, group_drop) = if rise < 0.0 {
            (rise * BIN_M, rise * (GROUP as f64 * BIN_M))
        } else {
            (0.0, 0.0)
        };
        // One bin more than the range reaches into: the bound is
        // multiplied out, not divided, and must not fall short by a rounding.
        let last = ((max_range / ray.per_across * (1.0 / BIN_M)) as usize + 1).min(self.bins - 1);
        // A ray rising faster than every bin of its heading needs clears
        // them all (most rays above the horizon).
        if rise - RISE_MARGIN > f64::from(self.clears[(self.bins - 1) * HEADINGS + heading]) {
            return None;
        }
        // Start where the neighbour's search did when every bin before is
        // clear for this ray too; else at the sensor.
        let mut bin = match *hint {
            h if h > 0
                && h <= last
                && rise - RISE_MARGIN > f64::from(self.clears[(h - 1) * HEADINGS + heading]) =>
            {
                h
            }
            _ => 0,
        };
        let mut first = None;
        while bin <= last {
            // Bins number a few hundred: u32 converts in one instruction.
            let near = f64::from(bin as u32) * BIN_M;
            let above = base + rise * near;
            if bin % GROUP == 0
                && above + group_drop > f64::from(self.coarse[bin / GROUP * HEADINGS + heading])
            {
                bin += GROUP;
                continue;
            }
            let top = f64::from(self.highest[bin * HEADINGS + heading]);
            bin += 1;
            if above + bin_drop > top {
                continue;
            }
            first.get_or_insert(bin - 1);
            let mut t0 = near * ray.per_across;
            let mut t1 = ((near + BIN_M) * ray.per_across).min(max_range);
            // Only where the ray is down at the bin's highest cell.
            if d.z < 0.0 {
                t0 = t0.max((top - origin.z) * ray.inverse.z - HEIGHT_MARGIN);
            } else if d.z > 0.0 {
                t1 = t1.min((top - origin.z) * ray.inverse.z + HEIGHT_MARGIN);
            }
            if t0 > t1 {
                continue;
            }
            if let Some(t) = self.view.cast_cells(origin, d, &ray.inverse, t0, t1) {
                *hint = first.unwrap_or(0);
                return Some(t);
            }
        }
        *hint = first.unwrap_or(0);
        None
    }
}

/// A ray from the table's origin, aimed: its heading bin, its rise per
/// horizontal metre and the reciprocals its search and walk multiply by.
/// A row's rays are aimed in one pass before any is cast, so their
/// divisions and square roots overlap rather than each ray waiting on its
/// own.
#[derive(Debug, Clone, Copy)]
struct Aimed {
    d: Vector3<f64>,
    /// 1 / d per axis (infinite along an axis it does not move on).
    inverse: Vector3<f64>,
    /// Along the ray per horizontal metre.
    per_across: f64,
    rise: f64,
    heading: usize,
}

impl Aimed {
    /// None for a ray (nearly) straight up or down: it has no heading.
    fn new(d: &Vector3<f64>) -> Option<Self> {
        let across = (d.x * d.x + d.y * d.y).sqrt();
        (across >= 1e-9).then(|| {
            let per_across = 1.0 / across;
            Self {
                d: *d,
                inverse: Vector3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z),
                per_across,
                rise: d.z * per_across,
                heading: heading_bin(pseudo_angle(d.x, d.y)).clamp(0, HEADINGS as i64 - 1) as usize,
            }
        })
    }
}

impl RayCast for PolarView<'_> {
    fn cast(&self, origin: &Point3<f64>, d: &Vector3<f64>, max_range: f64) -> Option<f64> {
        if !self.binned(origin, max_range) {
            return self.view.cast(origin, d, max_range);
        }
        self.cast_from(d, max_range, &mut 0)
    }

    fn cast_each(
        &self,
        origin: &Point3<f64>,
        directions: &[Vector3<f64>],
        max_range: f64,
        out: &mut [f32],
    ) {
        if !self.binned(origin, max_range) {
            return self.view.cast_each(origin, directions, max_range, out);
        }
        // Aimed a batch at a time, on the stack.
        let mut aimed = [None; AIM_BATCH];
        let mut hint = 0;
        for (directions, out) in directions.chunks(AIM_BATCH).zip(out.chunks_mut(AIM_BATCH)) {
            for (ray, d) in aimed.iter_mut().zip(directions) {
                *ray = Aimed::new(d);
            }
            for ((ray, d), value) in aimed.iter().zip(directions).zip(out) {
                let hit = match ray {
                    Some(ray) => self.cast_aimed(ray, max_range, &mut hint),
                    None => self.view.cast(origin, d, max_range),
                };
                *value = hit.map_or(f32::NAN, |t| t as f32);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::tiles::TileCache;
    use crate::world::World;

    #[test]
    fn the_pseudo_angle_turns_with_the_heading() {
        let turns: Vec<f64> = (0..64)
            .map(|k| {
                let a = f64::from(k) / 64.0 * std::f64::consts::TAU;
                pseudo_angle(a.cos(), a.sin())
            })
            .collect();
        assert!(turns.windows(2).all(|w| w[0] < w[1]), "{turns:?}");
        assert!(turns[0] == 0.0 && turns[63] < 4.0);
    }

    #[test]
    fn rays_from_the_binned_position_meet_what_the_full_walk_meets() {
        // The paper's loop: hills, rocks, trunks, bushes, ditches, banks.
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
        let mut rng = crate::rng::Rng::stream(11, 3);
        let (mut hits, mut rays) = (0, 0);
        let range = 60.0;
        for &(x, y, dz) in &[
            (0.0, 0.0, 2.4),
            (60.0, 35.0, 0.3),
            (-20.0, 80.0, 3.5),
            (130.0, -40.0, -0.1),
            // On a block's corner and edge: headings all round it.
            (12.8, 25.6, 1.0),
            (4.0, 7.25, 2.0),
        ] {
            let view = cache.view(x, y, range + 1.0);
            // Rays along the axes and the diagonals from off the cell grid
            // (from on it they run along cells' edges, touching two at once).
            for (axes, (x, y)) in [(false, (x, y)), (true, (x + 0.013, y + 0.029))] {
                let origin = Point3::new(x, y, world.height(x, y) + dz);
                let polar = PolarView::new(&view, origin, range, 2);
                for _ in 0..3000 {
                    let azimuth = if axes {
                        (rng.unit() * 8.0).floor() * std::f64::consts::FRAC_PI_4
                    } else {
                        rng.unit() * std::f64::consts::TAU
                    };
                    // From steeply down to above the horizon.
                    let elevation = (rng.unit() * 55.0 - 45.0).to_radians();
                    let d = Vector3::new(
                        elevation.cos() * azimuth.cos(),
                        elevation.cos() * azimuth.sin(),
                        elevation.sin(),
                    );
                    let reach = 5.0 + 55.0 * rng.unit();
                    let binned = polar.cast(&origin, &d, reach);
                    let full = view.cast(&origin, &d, reach);
                    match (binned, full) {
                        (Some(a), Some(b)) => {
                            assert!((a - b).abs() < 1e-6, "{origin} {d}: {a} vs {b}");
                        }
                        (None, None) => {}
                        _ => panic!("{origin} {d} to {reach} m: {binned:?} vs {full:?}"),
                    }
                    hits += usize::from(full.is_some());
                    rays += 1;
                }
            }
        }
        // Both kinds of answer were asked for.
        assert!(hits > rays / 3 && hits < rays * 9 / 10, "{hits} of {rays}");
    }

    #[test]
    fn rays_from_elsewhere_are_cast_in_the_view() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
        let view = cache.view(0.0, 0.0, 41.0);
        let origin = Point3::new(0.0, 0.0, world.height(0.0, 0.0) + 2.0);
        let polar = PolarView::new(&view, origin, 40.0, 1);
        let elsewhere = Point3::new(3.0, -2.0, world.height(3.0, -2.0) + 2.0);
        let d = Vector3::new(1.0, 0.2, -0.3).normalize();
        assert_eq!(
            polar.cast(&elsewhere, &d, 40.0),
            view.cast(&elsewhere, &d, 40.0)
        );
        // Beyond the binned range, too.
        let flat = Vector3::new(0.3, 1.0, -0.02).normalize();
        assert_eq!(
            polar.cast(&origin, &flat, 80.0),
            view.cast(&origin, &flat, 80.0)
        );
    }
}
