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
//!
//! A slice of a rotating lidar (16 columns: 2.8° of the turn) needs only
//! the headings its rays run along: [`PolarView::wedge`] bins those alone,
//! from the blocks in the wedge (about 1/100 of a frame's), so a streamed
//! frame is cast through the table too rather than walked ray by ray.

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

/// The heading bin of a direction with horizontal part (x, y).
#[inline]
fn heading_of(x: f64, y: f64) -> usize {
    heading_bin(pseudo_angle(x, y)).clamp(0, HEADINGS as i64 - 1) as usize
}

/// The unit direction at pseudo-angle `p` (the inverse of [`pseudo_angle`]).
fn direction_at(p: f64) -> (f64, f64) {
    let p = p.rem_euclid(4.0);
    let (x, y) = if p < 2.0 {
        (1.0 - p, 1.0 - (1.0 - p).abs())
    } else {
        (p - 3.0, (p - 3.0).abs() - 1.0)
    };
    let norm = (x * x + y * y).sqrt();
    (x / norm, y / norm)
}

/// The heading bins a table holds: `width` of them from `first`, round
/// the turn (all of them for a frame, a wedge for a slice).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Headings {
    first: usize,
    width: usize,
}

impl Headings {
    /// Every heading.
    pub const ALL: Self = Self {
        first: 0,
        width: HEADINGS,
    };

    /// The narrowest wedge holding the headings of `directions`, widened by
    /// two bins each side against rounding; `None` when it spans more than
    /// a quarter turn (a slice of the ERIM's rows spans 128°: it is walked
    /// in the view, as before; wedges wider than that were not measured)
    /// or a direction is (nearly) vertical.
    pub fn around(directions: impl IntoIterator<Item = Vector3<f64>>) -> Option<Self> {
        Self::around_within(directions, HEADINGS / 4)
    }

    /// [`Headings::around`] for a whole image of a sensor that looks
    /// one way (the ERIM's 128°): wedges up to half a turn, binned from
    /// the tiles they meet ([`PolarView::within`]) rather than band by
    /// band.
    pub fn frame_around(directions: impl IntoIterator<Item = Vector3<f64>>) -> Option<Self> {
        Self::around_within(directions, HEADINGS / 2)
    }

    fn around_within(
        directions: impl IntoIterator<Item = Vector3<f64>>,
        widest: usize,
    ) -> Option<Self> {
        const WIDEN: usize = 2;
        let mut bins = Vec::new();
        for d in directions {
            if (d.x * d.x + d.y * d.y).sqrt() < 1e-9 {
                return None;
            }
            bins.push(heading_of(d.x, d.y));
        }
        bins.sort_unstable();
        bins.dedup();
        // The wedge is the turn less the widest gap between neighbours.
        let (&lowest, &highest) = (bins.first()?, bins.last()?);
        let (gap_after, gap) = bins
            .windows(2)
            .map(|w| (w[0], w[1] - w[0]))
            .chain(std::iter::once((highest, lowest + HEADINGS - highest)))
            .max_by_key(|&(_, gap)| gap)?;
        let width = HEADINGS - gap + 1 + 2 * WIDEN;
        (width <= widest).then(|| Self {
            first: (gap_after + gap + HEADINGS - WIDEN) % HEADINGS,
            width,
        })
    }

    /// The table's column of heading bin `heading`, if it holds it.
    #[cfg(test)]
    fn column(self, heading: usize) -> Option<usize> {
        let column = self.offset(heading);
        (column < self.width).then_some(column)
    }

    /// How many bins `heading` is past the first: its column when that is
    /// below `width`.
    #[inline]
    fn offset(self, heading: usize) -> usize {
        heading.wrapping_sub(self.first) & (HEADINGS - 1)
    }

    /// Whether any of heading bins `lo..=hi` (as [`Headings::raise`]
    /// takes them) is one of these.
    #[inline]
    fn meets(self, lo: i64, hi: i64) -> bool {
        let start = (lo - self.first as i64).rem_euclid(HEADINGS as i64) as usize;
        let end = start + (hi - lo).clamp(0, HEADINGS as i64 - 1) as usize;
        start < self.width || end >= HEADINGS
    }

    /// Raises to `top` the columns of `row` (one distance bin) that hold
    /// heading bins `lo..=hi` (`lo` may be below 0 and `hi` past the last
    /// bin: the span wraps round the turn).
    #[inline]
    fn raise(self, row: &mut [f32], lo: i64, hi: i64, top: f32) {
        let start = (lo - self.first as i64).rem_euclid(HEADINGS as i64) as usize;
        let end = start + (hi - lo).clamp(0, HEADINGS as i64 - 1) as usize;
        if start < self.width {
            for h in &mut row[start..=end.min(self.width - 1)] {
                *h = h.max(top);
            }
        }
        if end >= HEADINGS {
            for h in &mut row[..=(end - HEADINGS).min(self.width - 1)] {
                *h = h.max(top);
            }
        }
    }
}

/// A [`TileView`] with the highest ground binned around one sensor position:
/// rays from that position are cast through the table, any other ray
/// through the view itself.
#[derive(Debug)]
pub struct PolarView {
    /// The view's tiles (shared with it: a table outlives the view it was
    /// made from when threads other than its maker's cast through it).
    view: TileView,
    origin: Point3<f64>,
    range_m: f64,
    bins: usize,
    /// The headings binned: a row of the tables has `headings.width` columns.
    headings: Headings,
    /// Highest cell per (distance bin, heading bin): `[bin · width + column]`.
    highest: Vec<f32>,
    /// The same over groups of `GROUP` distance bins.
    coarse: Vec<f32>,
    /// Per (distance bin, heading bin): a ray rising faster than this (per
    /// horizontal metre) meets nothing in that bin or any nearer one
    /// (rounded up): where a neighbouring ray's search may start.
    clears: Vec<f32>,
}

impl PolarView {
    /// Bins the ground of `view` within `range_m` of `origin` (horizontally),
    /// on up to `threads` threads.
    pub fn new(view: &TileView, origin: Point3<f64>, range_m: f64, threads: usize) -> Self {
        Self::within(view, origin, range_m, threads, Headings::ALL)
    }

    /// [`PolarView::new`] along `headings` only: the tiles whose headings
    /// miss them are passed over, and the table is as wide as they are.
    /// A ray along them meets what it meets in a table of every heading;
    /// any other ray is cast in the view.
    pub fn within(
        view: &TileView,
        origin: Point3<f64>,
        range_m: f64,
        threads: usize,
        headings: Headings,
    ) -> Self {
        let range_m = Self::binned_range(range_m);
        let bins = ((range_m / BIN_M).ceil() as usize).max(1);
        let parts = threads.max(1);
        let width = headings.width;
        let table = Table {
            origin,
            range_m,
            bins,
            headings,
        };
        // Each thread bins a share of the tiles into a table of its own;
        // then each takes a share of the headings, merges the tables there
        // (highest wins) and derives the coarse bins and the clearing rises.
        let bin_part = |part: usize| {
            let mut highest = vec![f32::NEG_INFINITY; bins * width];
            let mut corners = Vec::new();
            view.for_each_tile(part, parts, |first, block_max| {
                table.bin_tile(&mut highest, &mut corners, first, block_max);
            });
            highest
        };
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
                        .unwrap_or_else(|_| vec![f32::INFINITY; bins * width])
                })
                .collect();
            (highest, others)
        });
        let groups = bins.div_ceil(GROUP);
        let mut coarse = vec![f32::NEG_INFINITY; groups * width];
        let mut clears = vec![f32::NEG_INFINITY; bins * width];
        let z = origin.z;
        let share = width.div_ceil(parts);
        let others = &others;
        std::thread::scope(|scope| {
            let mut shares = columns(&mut highest, width, parts)
                .into_iter()
                .zip(columns(&mut coarse, width, parts))
                .zip(columns(&mut clears, width, parts))
                .enumerate();
            // The first share on this thread, the others each on one more.
            let here = shares.next();
            for (part, ((mut highest, mut coarse), mut clears)) in shares {
                scope.spawn(move || {
                    derive(
                        &mut highest,
                        (others, width, part * share),
                        &mut coarse,
                        &mut clears,
                        z,
                    );
                });
            }
            if let Some((_, ((mut highest, mut coarse), mut clears))) = here {
                derive(
                    &mut highest,
                    (others, width, 0),
                    &mut coarse,
                    &mut clears,
                    z,
                );
            }
        });
        Self {
            view: view.clone(),
            origin,
            range_m,
            bins,
            headings,
            highest,
            coarse,
            clears,
        }
    }

    /// Bins the ground of `view` within `range_m` of `origin` along
    /// `headings` only (on this thread): a slice's rays from there are cast
    /// through the table, any other ray through the view. The blocks
    /// binned are those in the wedge, found band by band of distance.
    pub fn wedge(view: &TileView, origin: Point3<f64>, range_m: f64, headings: Headings) -> Self {
        let range_m = Self::binned_range(range_m);
        let bins = ((range_m / BIN_M).ceil() as usize).max(1);
        let width = headings.width;
        let table = Table {
            origin,
            range_m,
            bins,
            headings,
        };
        let mut highest = vec![f32::NEG_INFINITY; bins * width];
        table.bin_wedge(view, &mut highest);
        let mut coarse = vec![f32::NEG_INFINITY; bins.div_ceil(GROUP) * width];
        let mut clears = vec![f32::NEG_INFINITY; bins * width];
        derive(
            &mut columns(&mut highest, width, 1)[0],
            (&[], width, 0),
            &mut columns(&mut coarse, width, 1)[0],
            &mut columns(&mut clears, width, 1)[0],
            origin.z,
        );
        Self {
            view: view.clone(),
            origin,
            range_m,
            bins,
            headings,
            highest,
            coarse,
            clears,
        }
    }

    fn binned_range(range_m: f64) -> f64 {
        if range_m.is_finite() {
            range_m.max(0.0)
        } else {
            0.0
        }
    }
}

/// The rows of a `[bin · width + column]` table cut into `parts` ranges of
/// columns: part k's piece of every row.
fn columns(table: &mut [f32], width: usize, parts: usize) -> Vec<Vec<&mut [f32]>> {
    let share = width.div_ceil(parts);
    let mut out: Vec<Vec<&mut [f32]>> = (0..parts).map(|_| Vec::new()).collect();
    for row in table.chunks_exact_mut(width) {
        for (k, piece) in row.chunks_mut(share).enumerate() {
            out[k].push(piece);
        }
    }
    out
}

/// For one range of columns (rows of `highest`, `coarse` and `clears` cut
/// to it): merges the other threads' tables (`others`: their tables, rows
/// `width` wide, the range's first column) into `highest`, then fills the
/// coarse bins and the clearing rises.
fn derive(
    highest: &mut [&mut [f32]],
    others: (&[Vec<f32>], usize, usize),
    coarse: &mut [&mut [f32]],
    clears: &mut [&mut [f32]],
    z: f64,
) {
    let (others, width, first) = others;
    for (bin, row) in highest.iter_mut().enumerate() {
        for other in others {
            let theirs = &other[bin * width + first..][..row.len()];
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

/// What a table is binned for: the sensor position, the range, the
/// distance bins and the headings its columns hold.
#[derive(Debug, Clone, Copy)]
struct Table {
    origin: Point3<f64>,
    range_m: f64,
    bins: usize,
    headings: Headings,
}

impl Table {
    /// Raises the bins of `highest` that the blocks of one tile (its
    /// lower-left block `first`, highest cells `block_max`) overlap.
    fn bin_tile(
        &self,
        highest: &mut [f32],
        corners: &mut Vec<f64>,
        first: (i64, i64),
        block_max: &[f32],
    ) {
        let (ox, oy) = (self.origin.x, self.origin.y);
        let side = BLOCKS as f64 * BLOCK_M;
        let nearest = |lo: i64, o: f64| {
            let lo = lo as f64 * BLOCK_M;
            o.clamp(lo, lo + side) - o
        };
        let (nx, ny) = (nearest(first.0, ox), nearest(first.1, oy));
        if (nx * nx + ny * ny).sqrt() - DISTANCE_MARGIN > self.range_m {
            return;
        }
        if self.headings.width < HEADINGS {
            // A tile whose headings miss the table's raises none of its
            // bins (its blocks' headings lie within its own).
            let edge = |k: i64| k as f64 * BLOCK_M;
            let [x0, y0] = [edge(first.0), edge(first.1)];
            let edges = [x0, y0, x0 + side, y0 + side];
            let corners = [(0, 1), (2, 1), (0, 3), (2, 3)]
                .map(|(x, y)| pseudo_angle(edges[x] - ox, edges[y] - oy));
            let (lo, hi) = self.heading_span(edges, corners);
            if !self.headings.meets(lo, hi) {
                return;
            }
        }
        self.bin_blocks(highest, corners, first, (BLOCKS, BLOCKS), |i, j| {
            Some(block_max[j * BLOCKS + i])
        });
    }

    /// Raises the bins of `highest` that the blocks of `view` in the wedge
    /// of `self.headings` overlap. Band by band of `GROUP` distance bins
    /// (`r_a` to `r_b`), the wedge's piece (the headings `e0` to `e1`,
    /// `δ` apart) lies in the hull of `r_a·e0`, `r_a·e1`, `r'·e0` and
    /// `r'·e1` with `r' = r_b / cos(δ/2)` (the chord between the last two
    /// touches the arc of radius `r_b`): the blocks over its bounding box
    /// are binned (a block in two bands twice, to the same effect).
    fn bin_wedge(&self, view: &TileView, highest: &mut [f32]) {
        let (ox, oy) = (self.origin.x, self.origin.y);
        let per_bin = 4.0 / HEADINGS as f64;
        let (first, width) = (self.headings.first, self.headings.width);
        let e0 = direction_at(first as f64 * per_bin - ANGLE_MARGIN);
        let e1 = direction_at((first + width) as f64 * per_bin + ANGLE_MARGIN);
        let cos_half = ((1.0 + e0.0 * e1.0 + e0.1 * e1.1) / 2.0).max(0.0).sqrt();
        let block = |v: f64| floor(v / BLOCK_M);
        let mut corners = Vec::new();
        for band in (0..self.bins).step_by(GROUP) {
            let r_a = (band as f64 * BIN_M - DISTANCE_MARGIN).max(0.0);
            let r_b = ((band + GROUP).min(self.bins) as f64 * BIN_M + DISTANCE_MARGIN) / cos_half;
            let points = [e0, e1].map(|(x, y)| [(r_a * x, r_a * y), (r_b * x, r_b * y)]);
            let (mut lo, mut hi) = (
                (f64::INFINITY, f64::INFINITY),
                (f64::NEG_INFINITY, f64::NEG_INFINITY),
            );
            for &(x, y) in points.iter().flatten() {
                lo = (lo.0.min(x), lo.1.min(y));
                hi = (hi.0.max(x), hi.1.max(y));
            }
            let margin = DISTANCE_MARGIN;
            let (bx0, bx1) = (block(ox + lo.0 - margin), block(ox + hi.0 + margin));
            let (by0, by1) = (block(oy + lo.1 - margin), block(oy + hi.1 + margin));
            let count = ((bx1 - bx0 + 1) as usize, (by1 - by0 + 1) as usize);
            self.bin_blocks(highest, &mut corners, (bx0, by0), count, |i, j| {
                view.block_max(bx0 + i as i64, by0 + j as i64)
                    .map(|top| top as f32)
            });
        }
    }

    /// Raises the bins of `highest` that blocks `first.0 .. first.0 +
    /// count.0` by `first.1 .. first.1 + count.1` (block coordinates)
    /// overlap, `top(i, j)` the highest cell of the block `(i, j)` from the
    /// first (none: not loaded). A block's edges are its coordinates times
    /// `BLOCK_M`, and each corner's pseudo-angle is computed once, from
    /// those very edges, for the four blocks that share it: a corner on
    /// the sensor (which has no heading) is then always seen to hold it.
    #[inline(always)]
    fn bin_blocks(
        &self,
        highest: &mut [f32],
        corners: &mut Vec<f64>,
        first: (i64, i64),
        count: (usize, usize),
        top: impl Fn(usize, usize) -> Option<f32>,
    ) {
        let (ox, oy) = (self.origin.x, self.origin.y);
        let ((bx0, by0), (nx, ny)) = (first, count);
        let edge = |k: i64| k as f64 * BLOCK_M;
        let side = nx + 1;
        corners.clear();
        for cy in by0..=by0 + ny as i64 {
            let y = edge(cy) - oy;
            corners.extend((bx0..=bx0 + nx as i64).map(|cx| pseudo_angle(edge(cx) - ox, y)));
        }
        let at = |i: usize, j: usize| corners[j * side + i];
        for j in 0..ny {
            let by = by0 + j as i64;
            for i in 0..nx {
                let Some(top) = top(i, j) else {
                    continue;
                };
                let bx = bx0 + i as i64;
                self.raise_block(
                    highest,
                    [edge(bx), edge(by), edge(bx + 1), edge(by + 1)],
                    top,
                    [at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)],
                );
            }
        }
    }

    /// The heading bins the square `[x0, y0, x1, y1]` spans (`corners`:
    /// the pseudo-angles of its corners, lower left, lower right, upper
    /// left, upper right): all of them around a square holding the
    /// sensor; else the span of its corners, across +x when it straddles
    /// it (`lo` may be below 0).
    #[inline(always)]
    fn heading_span(&self, [bx0, by0, bx1, by1]: [f64; 4], corners: [f64; 4]) -> (i64, i64) {
        let (ox, oy) = (self.origin.x, self.origin.y);
        let holds = bx0 <= ox && ox <= bx1 && by0 <= oy && oy <= by1;
        if holds {
            return (0, HEADINGS as i64 - 1);
        }
        let wraps = by0 <= oy && oy <= by1 && bx0 > ox;
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for mut p in corners {
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
    }

    /// Raises to `top` the bins of `highest` that the block `[x0, y0, x1,
    /// y1]` overlaps: its span of distances from the sensor and of headings
    /// (`corners`: the pseudo-angles of its four corners, computed from
    /// these very edges: one on the sensor has no heading).
    #[inline(always)]
    fn raise_block(&self, highest: &mut [f32], edges: [f64; 4], top: f32, corners: [f64; 4]) {
        let (ox, oy) = (self.origin.x, self.origin.y);
        let [bx0, by0, bx1, by1] = edges;
        // Distances from the sensor to the block's nearest and farthest point.
        let near_x = ox.clamp(bx0, bx1) - ox;
        let near_y = oy.clamp(by0, by1) - oy;
        let near = (near_x * near_x + near_y * near_y).sqrt() - DISTANCE_MARGIN;
        if near > self.range_m || top == f32::NEG_INFINITY {
            return;
        }
        let far_x = (bx0 - ox).abs().max((bx1 - ox).abs());
        let far_y = (by0 - oy).abs().max((by1 - oy).abs());
        let far = (far_x * far_x + far_y * far_y).sqrt() + DISTANCE_MARGIN;
        let bins = self.bins;
        let first = ((near.max(0.0) / BIN_M) as usize).min(bins - 1);
        let last = ((far / BIN_M) as usize).min(bins - 1);
        let (lo, hi) = self.heading_span(edges, corners);
        let width = self.headings.width;
        for bin in first..=last {
            self.headings
                .raise(&mut highest[bin * width..(bin + 1) * width], lo, hi, top);
        }
    }
}

impl PolarView {
    /// Whether rays from `origin` to `max_range` may be cast through the
    /// table (else they are cast in the view).
    fn binned(&self, origin: &Point3<f64>, max_range: f64) -> bool {
        *origin == self.origin && max_range <= self.range_m
    }

    /// The first distance along `d` (from the table's origin) to a cell the
    /// ray dips to. `hint` is where a neighbouring ray's search started (0:
    /// none); it is set to where this one's started.
    fn cast_from(&self, d: &Vector3<f64>, max_range: f64, hint: &mut usize) -> Option<f64> {
        match Aimed::new(d, self.headings) {
            Some(ray) => self.cast_aimed(&ray, max_range, hint),
            None => self.view.cast(&self.origin, d, max_range),
        }
    }

    /// [`cast_from`](Self::cast_from) for a ray already aimed.
    #[inline(always)]
    fn cast_aimed(&self, ray: &Aimed, max_range: f64, hint: &mut usize) -> Option<f64> {
        let origin = &self.origin;
        let d = &ray.d;
        let column = ray.column;
        let width = self.headings.width;
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
        if rise - RISE_MARGIN > f64::from(self.clears[(self.bins - 1) * width + column]) {
            return None;
        }
        // Start where the neighbour's search did when every bin before is
        // clear for this ray too; else at the sensor.
        let mut bin = match *hint {
            h if h > 0
                && h <= last
                && rise - RISE_MARGIN > f64::from(self.clears[(h - 1) * width + column]) =>
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
                && above + group_drop > f64::from(self.coarse[bin / GROUP * width + column])
            {
                bin += GROUP;
                continue;
            }
            let top = f64::from(self.highest[bin * width + column]);
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
    /// The table's column of its heading.
    column: usize,
}

impl Aimed {
    /// None for a ray (nearly) straight up or down (it has no heading) or
    /// one along a heading outside `headings`: neither is cast through the
    /// table.
    #[inline(always)]
    fn new(d: &Vector3<f64>, headings: Headings) -> Option<Self> {
        let across = (d.x * d.x + d.y * d.y).sqrt();
        let heading = heading_of(d.x, d.y);
        // Both tests at once, without a branch between: a row is aimed
        // in one pass.
        let column = headings.offset(heading);
        ((across >= 1e-9) & (column < headings.width)).then(|| {
            let per_across = 1.0 / across;
            Self {
                d: *d,
                inverse: Vector3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z),
                per_across,
                rise: d.z * per_across,
                column,
            }
        })
    }
}

impl RayCast for PolarView {
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
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.cast_binned_avx2(origin, directions, max_range, out) };
        }
        self.cast_binned(origin, directions, max_range, out);
    }
}

impl PolarView {
    /// [`cast_binned`](Self::cast_binned) compiled for AVX2: the same
    /// operations (no fused multiply-add), so the same ranges, in the
    /// three-operand encodings (fewer register copies) and with wider
    /// lanes for the aiming. About 5 % of a frame (docs/simulator.md).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn cast_binned_avx2(
        &self,
        origin: &Point3<f64>,
        directions: &[Vector3<f64>],
        max_range: f64,
        out: &mut [f32],
    ) {
        self.cast_binned(origin, directions, max_range, out);
    }

    /// Rays from the table's origin cast through the table, a batch at a
    /// time aimed before any is cast.
    #[inline(always)]
    fn cast_binned(
        &self,
        origin: &Point3<f64>,
        directions: &[Vector3<f64>],
        max_range: f64,
        out: &mut [f32],
    ) {
        // Aimed a batch at a time, on the stack.
        let mut aimed = [None; AIM_BATCH];
        let mut hint = 0;
        for (directions, out) in directions.chunks(AIM_BATCH).zip(out.chunks_mut(AIM_BATCH)) {
            for (ray, d) in aimed.iter_mut().zip(directions) {
                *ray = Aimed::new(d, self.headings);
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
mod tests;
