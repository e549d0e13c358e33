//! The world as a height field for the sensor: square tiles of 0.1 m cells
//! built lazily around the vehicle and cached, and a ray caster over them.
//!
//! Each cell holds the world height at its centre (terrain and features), a
//! flat-topped column: vertical faces stand where a feature rises, which is
//! what a range sensor sees of a rock or a trunk. Rays walk 0.8 m blocks with
//! a 2-D DDA, skipping blocks whose highest cell they pass above, and walk the
//! cells of the blocks they may hit. A whole frame's rays, all from one
//! point, go faster through [`crate::polar::PolarView`].

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender};

use arcnav_perception::RayCast;
use nalgebra::{Point3, Vector3};

use crate::world::World;

/// Cell size, m.
pub const CELL_M: f64 = 0.1;
/// Cells per metre.
const PER_CELL: f64 = 10.0;
/// Cells per block side (blocks carry the max height of their cells).
const BLOCK: usize = 8;
/// Cells per super-block side (8 × 8 blocks).
const SUPER: usize = 64;
/// Cells per tile side.
const TILE: usize = 256;
pub(crate) const BLOCKS: usize = TILE / BLOCK;
/// A cell's tile is its coordinate shifted right by this (`TILE` = 2^8);
/// its place in the tile, the coordinate masked by `TILE_MASK`.
const TILE_SHIFT: i64 = 8;
const TILE_MASK: i64 = TILE as i64 - 1;
const _: () = assert!(TILE == 1 << TILE_SHIFT);
const SUPERS: usize = TILE / SUPER;
pub(crate) const TILE_M: f64 = TILE as f64 * CELL_M;
pub(crate) const BLOCK_M: f64 = BLOCK as f64 * CELL_M;
const SUPER_M: f64 = SUPER as f64 * CELL_M;

pub(crate) use crate::numbers::floor;

/// Cells per side of the squares whose heights lie together in memory (a
/// 64-byte cache line): a ray's walk and its neighbours' stay in few lines.
const PATCH: usize = 4;

/// Where cell (i, j) of a tile is kept: patch by patch, row-major within.
#[inline]
fn cell_index(i: usize, j: usize) -> usize {
    ((j / PATCH) * (TILE / PATCH) + i / PATCH) * PATCH * PATCH + (j % PATCH) * PATCH + i % PATCH
}

/// Where a ray crossing a cell from `t0` (at height `z0`) to `t1` (at
/// `z1`) meets the flat-topped column of height `h`: its face at `t0`, or
/// its top.
#[inline]
fn dip(z0: f64, z1: f64, h: f64, t0: f64, t1: f64) -> Option<f64> {
    if z0 <= h {
        Some(t0)
    } else if z1 <= h {
        Some(t0 + (z0 - h) / (z0 - z1) * (t1 - t0))
    } else {
        None
    }
}

/// One tile of heights.
#[derive(Debug)]
pub struct Tile {
    /// `TILE × TILE` heights, laid out by [`cell_index`].
    heights: Box<[f32; TILE * TILE]>,
    block_max: Vec<f32>,
    super_max: Vec<f32>,
    max: f32,
}

impl Tile {
    fn build(world: &World, tx: i64, ty: i64) -> Self {
        let (x0, y0) = (tx as f64 * TILE_M, ty as f64 * TILE_M);
        let mut heights = Box::new([0.0; TILE * TILE]);
        let mut row = [0.0f64; TILE];
        for j in 0..TILE {
            let y = y0 + (j as f64 + 0.5) * CELL_M;
            let xs = (0..TILE).map(|i| x0 + (i as f64 + 0.5) * CELL_M);
            world.heights_along(y, xs, &mut row);
            for (i, h) in row.iter().enumerate() {
                heights[cell_index(i, j)] = *h as f32;
            }
        }
        let mut block_max = vec![f32::NEG_INFINITY; BLOCKS * BLOCKS];
        let mut super_max = vec![f32::NEG_INFINITY; SUPERS * SUPERS];
        for j in 0..TILE {
            for i in 0..TILE {
                let h = heights[cell_index(i, j)];
                let b = &mut block_max[(j / BLOCK) * BLOCKS + i / BLOCK];
                *b = b.max(h);
                let s = &mut super_max[(j / SUPER) * SUPERS + i / SUPER];
                *s = s.max(h);
            }
        }
        let max = super_max.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        Self {
            heights,
            block_max,
            super_max,
            max,
        }
    }
}

/// Tiles built on demand and kept while near the vehicle.
#[derive(Debug)]
pub struct TileCache {
    world: Arc<World>,
    tiles: HashMap<(i64, i64), (Arc<Tile>, u64)>,
    capacity: usize,
    clock: u64,
    threads: usize,
    /// The thread building tiles asked for ahead ([`TileCache::prefetch`]),
    /// once asked.
    ahead: Option<Ahead>,
}

/// A thread building tiles before a view needs them: the keys it was
/// sent and has not handed back yet.
#[derive(Debug)]
struct Ahead {
    jobs: Sender<(i64, i64)>,
    built: Receiver<((i64, i64), Tile)>,
    pending: HashSet<(i64, i64)>,
}

/// The tiles around one sensor position, read-only: what rays are cast in.
#[derive(Debug, Clone)]
pub struct TileView {
    tx0: i64,
    ty0: i64,
    width: usize,
    tiles: Vec<Option<Arc<Tile>>>,
    /// Highest cell of every tile in view: a rising ray above it hits nothing.
    max: f64,
}

impl TileCache {
    /// A cache of up to `capacity` tiles (25.6 m each), built with up to
    /// `threads` threads.
    pub fn new(world: Arc<World>, capacity: usize, threads: usize) -> Self {
        Self {
            world,
            tiles: HashMap::new(),
            capacity: capacity.max(16),
            clock: 0,
            threads: threads.max(1),
            ahead: None,
        }
    }

    /// Starts building, on a thread of its own, the tiles a view of
    /// `radius` about (x, y) would need that are neither here nor asked for
    /// already: a later [`TileCache::view`] takes them (waiting for those
    /// still being built) rather than building them itself. A tile is a
    /// pure function of the world, so views are the same either way.
    pub fn prefetch(&mut self, x: f64, y: f64, radius: f64) {
        if self.ahead.is_none() {
            self.ahead = self.start_ahead();
        }
        let Some(ahead) = &mut self.ahead else {
            return;
        };
        for key in keys_around(x, y, radius) {
            if self.tiles.contains_key(&key) || ahead.pending.contains(&key) {
                continue;
            }
            if ahead.jobs.send(key).is_err() {
                // The thread is gone: views build their own tiles.
                self.ahead = None;
                return;
            }
            ahead.pending.insert(key);
        }
    }

    fn start_ahead(&self) -> Option<Ahead> {
        let (jobs, queue) = std::sync::mpsc::channel::<(i64, i64)>();
        let (hand, built) = std::sync::mpsc::channel();
        let world = Arc::clone(&self.world);
        std::thread::Builder::new()
            .name("tiles-ahead".into())
            .spawn(move || {
                for (tx, ty) in queue {
                    if hand.send(((tx, ty), Tile::build(&world, tx, ty))).is_err() {
                        return;
                    }
                }
            })
            .ok()?;
        Some(Ahead {
            jobs,
            built,
            pending: HashSet::new(),
        })
    }

    /// Takes in the tiles built ahead so far, and waits for those of
    /// `needed` still being built.
    fn take_ahead(&mut self, needed: &[(i64, i64)]) {
        let Some(ahead) = &mut self.ahead else {
            return;
        };
        loop {
            let waiting = needed.iter().any(|key| ahead.pending.contains(key));
            let next = if waiting {
                ahead.built.recv().ok()
            } else {
                ahead.built.try_recv().ok()
            };
            match next {
                Some((key, tile)) => {
                    ahead.pending.remove(&key);
                    self.tiles.insert(key, (Arc::new(tile), self.clock));
                }
                None if waiting => {
                    // The thread is gone (it panicked): build here.
                    self.ahead = None;
                    return;
                }
                None => return,
            }
        }
    }

    pub fn world(&self) -> &Arc<World> {
        &self.world
    }

    /// Tiles built so far (cached or evicted).
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// Makes sure every tile within `radius` of (x, y) exists and returns
    /// them as a view.
    pub fn view(&mut self, x: f64, y: f64, radius: f64) -> TileView {
        self.clock += 1;
        let (tx0, ty0, tx1, ty1) = tile_span(x, y, radius);
        let mut missing: Vec<(i64, i64)> = keys_around(x, y, radius)
            .filter(|key| !self.tiles.contains_key(key))
            .collect();
        if self.ahead.is_some() {
            self.take_ahead(&missing);
            missing.retain(|key| !self.tiles.contains_key(key));
        }
        // Build missing tiles in parallel: each is a pure function of the world.
        let world = &self.world;
        let built: Vec<((i64, i64), Tile)> = if missing.len() > 1 && self.threads > 1 {
            let chunk = missing.len().div_ceil(self.threads);
            std::thread::scope(|scope| {
                let handles: Vec<_> = missing
                    .chunks(chunk)
                    .map(|keys| {
                        scope.spawn(move || {
                            keys.iter()
                                .map(|&(tx, ty)| ((tx, ty), Tile::build(world, tx, ty)))
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .flat_map(|h| h.join().unwrap_or_default())
                    .collect()
            })
        } else {
            missing
                .iter()
                .map(|&(tx, ty)| ((tx, ty), Tile::build(world, tx, ty)))
                .collect()
        };
        for (key, tile) in built {
            self.tiles.insert(key, (Arc::new(tile), self.clock));
        }
        let width = (tx1 - tx0 + 1) as usize;
        let mut tiles = Vec::with_capacity(width * (ty1 - ty0 + 1) as usize);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let entry = self.tiles.get_mut(&(tx, ty));
                tiles.push(entry.map(|(tile, used)| {
                    *used = self.clock;
                    Arc::clone(tile)
                }));
            }
        }
        // Evict the least recently used beyond capacity (never this view's).
        while self.tiles.len() > self.capacity {
            let Some(oldest) = self
                .tiles
                .iter()
                .filter(|(_, (_, used))| *used < self.clock)
                .min_by_key(|(key, (_, used))| (*used, **key))
                .map(|(key, _)| *key)
            else {
                break;
            };
            self.tiles.remove(&oldest);
        }
        let max = tiles
            .iter()
            .flatten()
            .map(|t| f64::from(t.max))
            .fold(f64::NEG_INFINITY, f64::max);
        TileView {
            tx0,
            ty0,
            width,
            tiles,
            max,
        }
    }
}

/// The first and last tile, along x and along y, of a view of `radius`
/// about (x, y).
fn tile_span(x: f64, y: f64, radius: f64) -> (i64, i64, i64, i64) {
    let index = |v: f64| floor(v / TILE_M);
    (
        index(x - radius),
        index(y - radius),
        index(x + radius),
        index(y + radius),
    )
}

/// The keys of the tiles a view of `radius` about (x, y) holds, row by row.
fn keys_around(x: f64, y: f64, radius: f64) -> impl Iterator<Item = (i64, i64)> {
    let (tx0, ty0, tx1, ty1) = tile_span(x, y, radius);
    (ty0..=ty1).flat_map(move |ty| (tx0..=tx1).map(move |tx| (tx, ty)))
}

impl TileView {
    fn tile(&self, tx: i64, ty: i64) -> Option<&Tile> {
        let (dx, dy) = (tx - self.tx0, ty - self.ty0);
        if dx < 0 || dy < 0 || dx as usize >= self.width {
            return None;
        }
        self.tiles
            .get(dy as usize * self.width + dx as usize)?
            .as_deref()
    }

    /// Max height of the block at block coordinates (bx, by), if loaded.
    pub(crate) fn block_max(&self, bx: i64, by: i64) -> Option<f64> {
        let per_tile = BLOCKS as i64;
        let tile = self.tile(bx.div_euclid(per_tile), by.div_euclid(per_tile))?;
        let (i, j) = (
            bx.rem_euclid(per_tile) as usize,
            by.rem_euclid(per_tile) as usize,
        );
        Some(f64::from(tile.block_max[j * BLOCKS + i]))
    }

    /// Height of the cell at cell coordinates (cx, cy), if loaded.
    pub fn cell_height(&self, cx: i64, cy: i64) -> Option<f64> {
        let per_tile = TILE as i64;
        let tile = self.tile(cx.div_euclid(per_tile), cy.div_euclid(per_tile))?;
        let (i, j) = (
            cx.rem_euclid(per_tile) as usize,
            cy.rem_euclid(per_tile) as usize,
        );
        Some(f64::from(tile.heights[cell_index(i, j)]))
    }

    /// Calls `visit((bx, by), block_max)` for every `parts`-th loaded tile,
    /// from the `part`-th: its lower-left block (in block coordinates, as
    /// [`TileView::block_max`] takes them) and the height of the highest
    /// cell of each of its blocks (`BLOCKS` rows of `BLOCKS`, each
    /// `BLOCK_M` square).
    pub(crate) fn for_each_tile(
        &self,
        part: usize,
        parts: usize,
        mut visit: impl FnMut((i64, i64), &[f32]),
    ) {
        for (k, tile) in self
            .tiles
            .iter()
            .enumerate()
            .skip(part)
            .step_by(parts.max(1))
        {
            let Some(tile) = tile else { continue };
            let tx = self.tx0 + (k % self.width) as i64;
            let ty = self.ty0 + (k / self.width) as i64;
            let per_tile = BLOCKS as i64;
            visit((tx * per_tile, ty * per_tile), &tile.block_max);
        }
    }

    /// The first cell along the ray between `t0` and `t1` that the ray dips
    /// to (at or below its top), walked cell by cell: where it meets its
    /// face or its top. The cells `walk` visits, with the tile found once
    /// and again only where the walk leaves it (the hot loop of a frame
    /// cast through [`crate::polar::PolarView`]).
    #[inline(always)]
    pub(crate) fn cast_cells(
        &self,
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        inverse: &Vector3<f64>,
        t0: f64,
        t1: f64,
    ) -> Option<f64> {
        // Written for few instructions a cell (the walk is most of a
        // frame): the ray's reciprocals given, tiles and cells found by
        // shifts and masks.
        let mut dda = Dda::with_inverse(origin, d, inverse, t0);
        let tile_of = |cx: i64, cy: i64| {
            let key = (cx >> TILE_SHIFT, cy >> TILE_SHIFT);
            (key, self.tile(key.0, key.1).map(|t| &*t.heights))
        };
        let (mut key, mut heights) = tile_of(dda.cx, dda.cy);
        let mut t_in = t0;
        loop {
            let t_out = least(dda.exit(), t1);
            let (cx, cy) = (dda.cx, dda.cy);
            if (cx >> TILE_SHIFT, cy >> TILE_SHIFT) != key {
                (key, heights) = tile_of(cx, cy);
            }
            if let Some(heights) = heights {
                let (i, j) = ((cx & TILE_MASK) as usize, (cy & TILE_MASK) as usize);
                let h = f64::from(heights[cell_index(i, j) & (TILE * TILE - 1)]);
                let hit = dip(
                    origin.z + d.z * t_in,
                    origin.z + d.z * t_out,
                    h,
                    t_in,
                    t_out,
                );
                if hit.is_some() {
                    return hit;
                }
            }
            if t_out >= t1 {
                return None;
            }
            t_in = dda.step();
        }
    }

    /// Walks the cells of size `size` along the ray from `t0` to `t1`,
    /// calling `visit(cx, cy, t_in, t_out)`; stops when it returns Some.
    fn walk<T>(
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        t0: f64,
        t1: f64,
        size: f64,
        mut visit: impl FnMut(i64, i64, f64, f64) -> Option<T>,
    ) -> Option<T> {
        let mut dda = Dda::new(origin, d, t0, size);
        let mut t_in = t0;
        loop {
            let t_out = least(dda.exit(), t1);
            if let Some(hit) = visit(dda.cx, dda.cy, t_in, t_out) {
                return Some(hit);
            }
            if t_out >= t1 {
                return None;
            }
            t_in = dda.step();
        }
    }
}

/// The smaller of two distances: a plain comparison (`f64::min` also
/// handles NaN, in five instructions; a ray's distances are never NaN).
#[inline(always)]
fn least(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// A 2-D DDA over square cells (Amanatides & Woo, 1987): the cell a ray
/// is in, and the distances along it at which it crosses the next column
/// and row boundary.
struct Dda {
    cx: i64,
    cy: i64,
    sx: i64,
    sy: i64,
    tx: f64,
    ty: f64,
    dx: f64,
    dy: f64,
}

impl Dda {
    /// Cells of `size`, the ray from `origin` along `d` entered at `t0`.
    #[inline(always)]
    fn new(origin: &Point3<f64>, d: &Vector3<f64>, t0: f64, size: f64) -> Self {
        let start = origin + d * t0;
        let cell = (floor(start.x / size), floor(start.y / size));
        Self::from_cell(cell, origin, d, size, |x, axis| x / d[axis])
    }

    /// Cells of [`CELL_M`], with the ray's reciprocals given (no division).
    #[inline(always)]
    fn with_inverse(
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        inverse: &Vector3<f64>,
        t0: f64,
    ) -> Self {
        let start = origin + d * t0;
        let cell = (floor(start.x * PER_CELL), floor(start.y * PER_CELL));
        Self::from_cell(cell, origin, d, CELL_M, |x, axis| x * inverse[axis])
    }

    /// The ray in cell `(cx, cy)` of `size`; `along(x, axis)` is how far
    /// along the ray it moves `x` metres along that axis (divided by, or
    /// multiplied by the reciprocal of, its direction there).
    #[inline(always)]
    fn from_cell(
        (cx, cy): (i64, i64),
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        size: f64,
        along: impl Fn(f64, usize) -> f64,
    ) -> Self {
        let (sx, sy) = (sign(d.x), sign(d.y));
        let axis = |c: i64, s: i64, axis: usize| {
            if d[axis].abs() < 1e-12 {
                (f64::INFINITY, f64::INFINITY)
            } else {
                (
                    along(boundary(c, s) * size - origin[axis], axis),
                    along(size, axis).abs(),
                )
            }
        };
        let ((tx, dx), (ty, dy)) = (axis(cx, sx, 0), axis(cy, sy, 1));
        Self {
            cx,
            cy,
            sx,
            sy,
            tx,
            ty,
            dx,
            dy,
        }
    }

    /// Where the ray leaves the current cell.
    #[inline(always)]
    fn exit(&self) -> f64 {
        least(self.tx, self.ty)
    }

    /// On to the next cell; returns where the ray enters it.
    #[inline(always)]
    fn step(&mut self) -> f64 {
        if self.tx < self.ty {
            let t = self.tx;
            self.cx += self.sx;
            self.tx += self.dx;
            t
        } else {
            let t = self.ty;
            self.cy += self.sy;
            self.ty += self.dy;
            t
        }
    }
}

/// The step along an axis a ray moves along with direction `dir`.
#[inline(always)]
fn sign(dir: f64) -> i64 {
    if dir > 0.0 { 1 } else { -1 }
}

/// The index of the boundary a ray in cell `c` stepping `s` crosses next.
#[inline(always)]
fn boundary(c: i64, s: i64) -> f64 {
    (if s > 0 { c + 1 } else { c }) as f64
}

impl RayCast for TileView {
    fn cast(&self, origin: &Point3<f64>, d: &Vector3<f64>, max_range: f64) -> Option<f64> {
        let z_at = |t: f64| origin.z + d.z * t;
        // A ray rising from above everything in view hits nothing.
        if d.z >= 0.0 && origin.z > self.max {
            return None;
        }
        // The ray's lowest point over [t0, t1].
        let lowest = |t0: f64, t1: f64| z_at(if d.z < 0.0 { t1 } else { t0 });
        TileView::walk(origin, d, 0.0, max_range, SUPER_M, |sx, sy, s0, s1| {
            // A super-block lies inside one tile: find it once.
            let per_tile = SUPERS as i64;
            let (tx, ty) = (sx.div_euclid(per_tile), sy.div_euclid(per_tile));
            let tile = self.tile(tx, ty)?;
            let (i, j) = (
                sx.rem_euclid(per_tile) as usize,
                sy.rem_euclid(per_tile) as usize,
            );
            if lowest(s0, s1) > f64::from(tile.super_max[j * SUPERS + i]) {
                return None;
            }
            let (cell_x0, cell_y0) = (tx * TILE as i64, ty * TILE as i64);
            let local = |cx: i64, cy: i64| {
                let (i, j) = (cx - cell_x0, cy - cell_y0);
                (i >= 0 && j >= 0 && i < TILE as i64 && j < TILE as i64)
                    .then_some((i as usize, j as usize))
            };
            TileView::walk(origin, d, s0, s1, BLOCK_M, |bx, by, t0, t1| {
                let top = match local(bx * BLOCK as i64, by * BLOCK as i64) {
                    Some((i, j)) => f64::from(tile.block_max[(j / BLOCK) * BLOCKS + i / BLOCK]),
                    None => self.block_max(bx, by)?,
                };
                if lowest(t0, t1) > top {
                    return None;
                }
                TileView::walk(origin, d, t0, t1, CELL_M, |cx, cy, c0, c1| {
                    let h = match local(cx, cy) {
                        Some((i, j)) => f64::from(tile.heights[cell_index(i, j)]),
                        None => self.cell_height(cx, cy)?,
                    };
                    dip(z_at(c0), z_at(c1), h, c0, c1)
                })
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::World;

    /// Views of tiles built ahead on their own thread are the views of
    /// tiles built when needed: the same heights everywhere, the same
    /// highest cell; and the tiles asked for ahead are the ones built.
    #[test]
    fn tiles_built_ahead_make_the_views_tiles_built_when_needed_make() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut ahead = TileCache::new(Arc::clone(&world), 64, 1);
        let mut when_needed = TileCache::new(Arc::clone(&world), 64, 1);
        let places: Vec<(f64, f64)> = (0..8)
            .map(|k| (-60.0 + 17.0 * f64::from(k), 5.0 * f64::from(k)))
            .collect();
        for &(x, y) in &places {
            ahead.prefetch(x + TILE_M, y, 46.0);
            let (a, b) = (ahead.view(x, y, 46.0), when_needed.view(x, y, 46.0));
            assert_eq!(a.max.to_bits(), b.max.to_bits());
            for cy in (floor((y - 46.0) * PER_CELL)..floor((y + 46.0) * PER_CELL)).step_by(7) {
                for cx in (floor((x - 46.0) * PER_CELL)..floor((x + 46.0) * PER_CELL)).step_by(5) {
                    assert_eq!(
                        a.cell_height(cx, cy).map(f64::to_bits),
                        b.cell_height(cx, cy).map(f64::to_bits),
                        "cell ({cx}, {cy}) seen from ({x}, {y})"
                    );
                }
            }
        }
        // Everything asked for ahead was taken in by the last view, or is
        // still on its way: none was built twice.
        let pending = ahead.ahead.as_ref().map_or(0, |a| a.pending.len());
        assert!(
            ahead.len() + pending > when_needed.len(),
            "{} + {pending} against {}",
            ahead.len(),
            when_needed.len()
        );
        let asked: HashSet<(i64, i64)> = places
            .iter()
            .flat_map(|&(x, y)| keys_around(x + TILE_M, y, 46.0).chain(keys_around(x, y, 46.0)))
            .collect();
        assert_eq!(ahead.len() + pending, asked.len());
    }

    fn flat_world_with_wall() -> Arc<World> {
        let text = r#"
name = "t"
[terrain]
origin_m = [-50.0, -50.0]
size_m = [100.0, 100.0]
hills_amplitude_m = 0.0
roughness_amplitude_m = 0.0
[start]
position_m = [0.0, 0.0]
[[waypoints]]
position_m = [20.0, 0.0]
[[trees]]
position_m = [10.05, 0.05]
radius_m = 0.5
height_m = 3.0
"#;
        Arc::new(World::from_toml(text, "test", None).unwrap())
    }

    #[test]
    fn rays_hit_flat_ground_and_vertical_faces_where_they_are() {
        let mut cache = TileCache::new(flat_world_with_wall(), 32, 2);
        let view = cache.view(0.0, 0.0, 30.0);
        let origin = Point3::new(0.0, 0.0, 2.0);
        // Down 45°: ground at 2 m ahead, 2.83 m along the ray.
        let d = Vector3::new(1.0, 0.0, -1.0).normalize();
        assert!((view.cast(&origin, &d, 40.0).unwrap() - 8f64.sqrt()).abs() < 1e-9);
        // Horizontal at 2 m: the trunk's face at x = 9.55 (cells of 0.1 m).
        let d = Vector3::new(1.0, 0.0, 0.0);
        let hit = view.cast(&origin, &d, 40.0).unwrap();
        assert!((hit - 9.55).abs() <= 0.1, "{hit}");
        // Up: nothing.
        assert_eq!(
            view.cast(&origin, &Vector3::new(1.0, 0.0, 0.2).normalize(), 40.0),
            None
        );
        // Ground 200 m away along +y (no tree there), beyond the range: nothing.
        assert_eq!(
            view.cast(&origin, &Vector3::new(0.0, 1.0, -0.01).normalize(), 40.0),
            None
        );
    }

    /// The plain answer: every cell along the ray, in order, the first one
    /// the ray dips to (a 2-D DDA at 0.1 m; Amanatides & Woo, 1987).
    fn cell_by_cell(view: &TileView, o: &Point3<f64>, d: &Vector3<f64>, range: f64) -> Option<f64> {
        let (mut cx, mut cy) = (floor(o.x / CELL_M), floor(o.y / CELL_M));
        let axis = |p: f64, dir: f64, c: i64| {
            if dir.abs() < 1e-15 {
                return (0, f64::INFINITY, f64::INFINITY);
            }
            let step = if dir > 0.0 { 1 } else { -1 };
            let edge = (if dir > 0.0 { c + 1 } else { c }) as f64 * CELL_M;
            (step, (edge - p) / dir, CELL_M / dir.abs())
        };
        let (sx, mut tx, dx) = axis(o.x, d.x, cx);
        let (sy, mut ty, dy) = axis(o.y, d.y, cy);
        let mut t = 0.0;
        while t < range {
            let end = tx.min(ty).min(range);
            if let Some(h) = view.cell_height(cx, cy) {
                let (z0, z1) = (o.z + d.z * t, o.z + d.z * end);
                if z0 <= h {
                    return Some(t);
                }
                if z1 <= h {
                    return Some(t + (z0 - h) / (z0 - z1) * (end - t));
                }
            }
            if tx < ty {
                (t, cx, tx) = (tx, cx + sx, tx + dx);
            } else {
                (t, cy, ty) = (ty, cy + sy, ty + dy);
            }
        }
        None
    }

    #[test]
    fn the_block_walk_finds_the_first_cell_a_ray_dips_to() {
        // The paper's loop: hills, rocks, trunks, bushes, ditches, banks.
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut cache = TileCache::new(Arc::clone(&world), 64, 2);
        let mut rng = crate::rng::Rng::stream(7, 1);
        let (mut hits, mut rays) = (0, 0);
        for &(x, y) in &[(0.0, 0.0), (60.0, 35.0), (-20.0, 80.0), (130.0, -40.0)] {
            let view = cache.view(x, y, 61.0);
            for _ in 0..4000 {
                // Heights from at the ground (rays start inside a cell's
                // column) to well above the trees; down steeply to above
                // the horizon; every azimuth, axis-aligned ones included.
                let z = world.height(x, y) + 3.0 * rng.unit() - 0.2;
                let origin = Point3::new(x + rng.unit() - 0.5, y + rng.unit() - 0.5, z);
                let azimuth = match rays % 5 {
                    0 => (rng.unit() * 4.0).floor() * std::f64::consts::FRAC_PI_2,
                    _ => rng.unit() * std::f64::consts::TAU,
                };
                let elevation = (rng.unit() * 55.0 - 45.0).to_radians();
                let d = Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
                let range = 10.0 + 50.0 * rng.unit();
                let (fast, plain) = (
                    view.cast(&origin, &d, range),
                    cell_by_cell(&view, &origin, &d, range),
                );
                match (fast, plain) {
                    (Some(a), Some(b)) => assert!((a - b).abs() < 1e-6, "{origin} {d}: {a} vs {b}"),
                    (None, None) => {}
                    _ => panic!("{origin} {d} to {range} m: {fast:?} vs {plain:?}"),
                }
                hits += usize::from(plain.is_some());
                rays += 1;
            }
        }
        // Both kinds of answer were asked for.
        assert!(hits > rays / 3 && hits < rays * 9 / 10, "{hits} of {rays}");
    }

    #[test]
    fn diagonal_and_negative_directions_work() {
        let mut cache = TileCache::new(flat_world_with_wall(), 32, 1);
        let view = cache.view(0.0, 0.0, 30.0);
        let origin = Point3::new(3.0, 3.0, 1.0);
        for (dx, dy) in [(-1.0, -1.0), (-1.0, 0.5), (0.3, -1.0), (0.0, 1.0)] {
            let d = Vector3::new(dx, dy, -0.5).normalize();
            let t = view.cast(&origin, &d, 40.0).unwrap();
            assert!(
                (origin.z + d.z * t).abs() < 1e-9,
                "lands on the ground at z = 0"
            );
        }
    }

    #[test]
    fn the_cache_is_bounded_and_keeps_what_is_in_view() {
        let mut cache = TileCache::new(flat_world_with_wall(), 16, 2);
        for k in 0..10 {
            let view = cache.view(k as f64 * 30.0 - 40.0, 0.0, 20.0);
            assert!(
                view.cell_height(((k as f64 * 30.0 - 40.0) / CELL_M) as i64, 0)
                    .is_some()
            );
        }
        assert!(cache.len() <= 16);
    }
}
