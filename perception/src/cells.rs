//! The per-image cell classifier of 002 §4 ("early traversability evaluation").
//!
//! Every valid pixel is projected into the gravity-aligned vehicle frame of
//! the capture pose (x forward, y left, z up; the pose's roll and pitch
//! removed) and, if it falls in the evaluated region around the vehicle
//! (`[perception.region]`), binned into a grid of 20 cm cells. Per cell it keeps the point
//! count, min/max z and the sums of a least-squares plane. A cell is
//! untraversable for
//!
//! - (a) **height variation**: its points span more than the tolerated step;
//! - (b) **slope**: its fitted plane is steeper than the vehicle's limit;
//! - (c) **discontinuity**: the heights of a neighbouring cell lie more than
//!   the tolerated step above or below its own;
//!
//! (a) and (b) only with at least 5 points, "to avoid frequent erroneous
//! classification". And, what a cell's own points cannot show:
//!
//! - (d) **drop-off**: it holds the near edge of ground the image did not see,
//!   wider than the vehicle bridges, beyond which the ground drops away (see
//!   `DropOffRule::judge`). Each image column is walked from its highest
//!   beam down, far returns to near ones, while the rows are binned.
//!
//! Untraversable cells are grouped into 8-connected regions. Only cells
//! with data are evaluated; nothing is interpolated; nothing is carried
//! from one image to the next.
//!
//! Work is proportional to the valid pixels: the grid itself is only a map
//! from cell to slot (4 bytes a cell, so it stays in cache); the
//! accumulators of the cells an image touches live densely in touch order,
//! and only those are evaluated and reset. Beam directions are
//! separable (`cos el·(cos az, sin az) , sin el`), so per image only one
//! 3-vector per column and per row is computed.

use arcnav_vehicle::Isometry;
use arcnav_vehicle::frames::{level_frame, wrap_angle};

use crate::config::{GridShape, PerceptionConfig};
use crate::evaluator::{
    ImageStats, InOrder, ObstacleCell, ObstacleReport, PerceptionError, Reasons, Region, Runner,
    TerrainEvaluator,
};
use crate::fov::FovBuilder;
use crate::image::RangeImage;
use crate::shadow::Shadow;

#[derive(Debug, Clone, Copy)]
struct Cell {
    /// Position in the grid (`iy * cols + ix`).
    index: u32,
    count: u32,
    z_min: f32,
    z_max: f32,
    /// Σx, Σy, Σz, Σxx, Σxy, Σyy, Σxz, Σyz with x, y relative to the cell centre.
    sums: [f32; 8],
}

impl Cell {
    fn new(index: u32) -> Self {
        Self {
            index,
            count: 0,
            z_min: f32::INFINITY,
            z_max: f32::NEG_INFINITY,
            sums: [0.0; 8],
        }
    }

    /// What a point (x, y relative to the cell centre) adds to `sums`.
    #[inline(always)]
    fn terms(dx: f32, dy: f32, z: f32) -> [f32; 8] {
        [dx, dy, z, dx * dx, dx * dy, dy * dy, dx * z, dy * z]
    }
}

impl Cell {
    /// Adds the points of `other`, the same cell binned from other columns.
    fn merge(&mut self, other: &Cell) {
        self.count += other.count;
        self.z_min = self.z_min.min(other.z_min);
        self.z_max = self.z_max.max(other.z_max);
        for (sum, term) in self.sums.iter_mut().zip(other.sums) {
            *sum += term;
        }
    }
}

/// Least-squares plane sums over one cell or a window of cells, with x and
/// y relative to the centre of the cell being judged (offsets stay below a
/// metre, so f32 keeps millimetres; the solve runs in f64).
#[derive(Debug, Clone, Copy, Default)]
struct PlaneSums {
    n: f32,
    sx: f32,
    sy: f32,
    sz: f32,
    sxx: f32,
    sxy: f32,
    syy: f32,
    sxz: f32,
    syz: f32,
}

impl PlaneSums {
    /// Adds a cell whose centre lies at (ox, oy) from the judged cell's.
    #[inline]
    fn add(&mut self, cell: &Cell, ox: f32, oy: f32) {
        let n = cell.count as f32;
        let [sx, sy, sz, sxx, sxy, syy, sxz, syz] = cell.sums;
        self.n += n;
        self.sx += sx + n * ox;
        self.sy += sy + n * oy;
        self.sz += sz;
        self.sxx += sxx + 2.0 * ox * sx + n * ox * ox;
        self.syy += syy + 2.0 * oy * sy + n * oy * oy;
        self.sxy += sxy + ox * sy + oy * sx + n * ox * oy;
        self.sxz += sxz + ox * sz;
        self.syz += syz + oy * sz;
    }

    /// Tangent² of the fitted plane's tilt, if the points spread enough in
    /// both horizontal directions to define a plane.
    fn slope_tan2(&self, min_variance: f64) -> Option<f64> {
        let n = f64::from(self.n);
        if n < 3.0 {
            return None;
        }
        let (mx, my, mz) = (
            f64::from(self.sx) / n,
            f64::from(self.sy) / n,
            f64::from(self.sz) / n,
        );
        let cxx = f64::from(self.sxx) / n - mx * mx;
        let cyy = f64::from(self.syy) / n - my * my;
        let cxy = f64::from(self.sxy) / n - mx * my;
        let cxz = f64::from(self.sxz) / n - mx * mz;
        let cyz = f64::from(self.syz) / n - my * mz;
        let det = cxx * cyy - cxy * cxy;
        let trace = cxx + cyy;
        let smallest = 0.5 * (trace - (trace * trace - 4.0 * det).max(0.0).sqrt());
        if smallest <= min_variance || det <= 0.0 {
            return None;
        }
        let a = (cyy * cxz - cxy * cyz) / det;
        let b = (cxx * cyz - cxy * cxz) / det;
        Some(a * a + b * b)
    }
}

/// The trig of the last beam table seen, so a sensor's table is processed once.
#[derive(Debug, Default)]
struct BeamTrig {
    elevation: Vec<f32>,
    azimuth: Vec<f32>,
    cos_el: Vec<f32>,
    sin_el: Vec<f32>,
    cos_az: Vec<f32>,
    sin_az: Vec<f32>,
    /// The rows from the highest beam to the lowest: the order rows are
    /// binned in, so each column is walked from its far returns to its near
    /// ones.
    order: Vec<u32>,
}

impl BeamTrig {
    fn update(&mut self, elevation: &[f32], azimuth: &[f32]) {
        if self.elevation != elevation {
            self.elevation.clear();
            self.elevation.extend_from_slice(elevation);
            self.order.clear();
            self.order.extend(0..elevation.len() as u32);
            self.order
                .sort_by(|&a, &b| elevation[b as usize].total_cmp(&elevation[a as usize]));
            self.cos_el.clear();
            self.sin_el.clear();
            for &e in elevation {
                let (s, c) = f64::from(e).sin_cos();
                self.sin_el.push(s as f32);
                self.cos_el.push(c as f32);
            }
        }
        if self.azimuth != azimuth {
            self.azimuth.clear();
            self.azimuth.extend_from_slice(azimuth);
            self.cos_az.clear();
            self.sin_az.clear();
            for &a in azimuth {
                let (s, c) = f64::from(a).sin_cos();
                self.sin_az.push(s as f32);
                self.cos_az.push(c as f32);
            }
        }
    }
}

const EMPTY_SLOT: u32 = u32::MAX;

/// An image's columns are binned in this many parts, which a
/// [`Runner`] may bin at the same time; the parts are merged in a fixed
/// order, so the result is the same however they ran.
const PARTS: usize = 2;

/// Images with fewer pixels are binned in order whatever the runner: a
/// thread hand-off would cost more than it saves.
const PARALLEL_MIN_PIXELS: usize = 1 << 16;

/// The cells binned from a part of an image's columns.
#[derive(Debug)]
struct Bins {
    /// Per grid cell: its slot in `cells`, or `EMPTY_SLOT`.
    slots: Vec<u32>,
    /// The cells this part touched, in first-touch order.
    cells: Vec<Cell>,
    /// Per column of the part: the first and last row with a valid return.
    column_rows: Vec<(u32, u32)>,
    /// No return, out of range, outside the grid, valid.
    counts: [u32; 4],
    /// The row being binned, projected.
    row: ProjectedRow,
    /// The part's columns walked from their far returns to their near ones.
    walk: Walk,
    /// Drop-offs and shadows the walk found.
    found: Found,
}

/// The last two returns of each column of a part, walking the columns
/// from the highest beam down (far to near): horizontal distance from the
/// sensor and height, level frame, one array each (so a row's step is
/// vectorised). `d = ∞`: none yet.
#[derive(Debug, Default)]
struct Walk {
    d: Vec<f32>,
    z: Vec<f32>,
    beyond_d: Vec<f32>,
    beyond_z: Vec<f32>,
    /// Beams of each column that returned nothing since its last return.
    missed: Vec<u8>,
    /// Per pixel of the row: its gap to the column's previous return is
    /// longer than the vehicle bridges and the ground beyond lower, or
    /// beams between them returned nothing.
    long_gap: Vec<u8>,
}

/// This many beams in a row that return nothing between two returns are
/// not dropouts (1 % of pixels each, so three in a row one in a million)
/// but something the sensor does not see, such as glass or water: the
/// ground between is unseen, a shadow, even when the ground beyond is
/// level (000 §6: "this creates a sizable gap through occlusion").
const MISSED_BEAMS: u8 = 3;

impl Walk {
    fn start(&mut self, columns: usize) {
        for (values, start) in [
            (&mut self.d, f32::INFINITY),
            (&mut self.z, 0.0),
            (&mut self.beyond_d, f32::INFINITY),
            (&mut self.beyond_z, 0.0),
        ] {
            values.clear();
            values.resize(columns, start);
        }
        self.missed.clear();
        self.missed.resize(columns, 0);
    }

    /// One row's step: finds the returns whose gap to the column's previous
    /// return is long, has `rule` judge them (rarely any: flat ground's
    /// returns lie closer together than a wheel bridges out to 13 m for
    /// the ERIM), then moves every column that has a return on. A long gap
    /// with a return beyond is a shadow, drop-off or not; so is one across
    /// [`MISSED_BEAMS`] beams that returned nothing, whatever lies beyond.
    #[inline(always)]
    fn step(&mut self, row: &Row, points: &ProjectedRow, found: &mut Found) {
        let n = points.index.len();
        let rule = &row.projection.drop_off;
        let (max_gap, min_depth, depth_per_m) = (rule.max_gap, rule.min_depth, rule.depth_per_m);
        // Gaps that dip less than that are looked at too when suspected
        // drop-offs are reported.
        let shallow_depth = rule.shallow_depth();
        self.long_gap.resize(n, 0);
        let (index, d, z) = (&points.index[..n], &points.d[..n], &points.z[..n]);
        let (wd, wz, bd, bz) = (
            &mut self.d[..n],
            &mut self.z[..n],
            &mut self.beyond_d[..n],
            &mut self.beyond_z[..n],
        );
        let long_gap = &mut self.long_gap[..n];
        let missed = &mut self.missed[..n];
        let (mut any, mut walking) = (false, false);
        for k in 0..n {
            walking |= index[k] <= OUTSIDE_GRID;
            // Only a near edge in the region can be flagged. Far returns lie
            // farther apart than a wheel bridges: only those with ground
            // lower beyond (or none), or with beams lost between, go on.
            let gap = (index[k] < OUTSIDE_GRID) & (wd[k] - d[k] > max_gap);
            let deep = (wd[k] == f32::INFINITY)
                | (z[k] - wz[k] > min_depth + depth_per_m * d[k])
                | (missed[k] >= MISSED_BEAMS);
            let shallow = z[k] - wz[k] > shallow_depth + depth_per_m * d[k];
            // 2: a shadow, drop-off or not; 1: at most a suspected drop-off.
            long_gap[k] = u8::from(gap & deep) * 2 + u8::from(gap & !deep & shallow);
            any |= long_gap[k] != 0;
            // Counted between returns; any return (in the region or not,
            // in range or not) ends the count.
            missed[k] = if index[k] == NO_RETURN {
                missed[k].saturating_add(1)
            } else {
                0
            };
        }
        if any {
            for k in (0..n).filter(|&k| long_gap[k] != 0) {
                let previous = Previous {
                    d: wd[k],
                    z: wz[k],
                    beyond_d: bd[k],
                    beyond_z: bz[k],
                };
                let col = row.first_col + k;
                let edge = (d[k], z[k]);
                if long_gap[k] == 1 {
                    if rule.suspected(row.projection, &previous, edge, row.position, col) {
                        found.suspects.push(index[k]);
                    }
                    continue;
                }
                if rule.judge(row.projection, &previous, edge, row.position, col) {
                    found.drop_offs.push(index[k]);
                }
                if previous.d < f32::INFINITY {
                    found.shadows.push((col as u32, d[k], previous.d));
                }
            }
        }
        // Selected by bit masks: written as `if`, the compiler branches
        // per pixel instead of blending eight at a time.
        let select = |mask: u32, new: f32, old: f32| {
            f32::from_bits((new.to_bits() & mask) | (old.to_bits() & !mask))
        };
        if !walking {
            // A row of sky (or of nothing in range) leaves every column as it was.
            return;
        }
        // Returns in range, in the region or not, walk on; others do not.
        for k in 0..n {
            let mask = 0u32.wrapping_sub(u32::from(index[k] <= OUTSIDE_GRID));
            bd[k] = select(mask, wd[k], bd[k]);
            bz[k] = select(mask, wz[k], bz[k]);
            wd[k] = select(mask, d[k], wd[k]);
            wz[k] = select(mask, z[k], wz[k]);
        }
    }
}

/// What a [`Walk`] finds in a part's columns.
#[derive(Debug, Default)]
struct Found {
    /// Grid indices of the cells at the near edge of a drop-off.
    drop_offs: Vec<u32>,
    /// Grid indices of the cells at the near edge of a suspected drop-off.
    suspects: Vec<u32>,
    /// Shadows: (image column, distance of the edge, of the return beyond),
    /// level frame.
    shadows: Vec<(u32, f32, f32)>,
}

impl Found {
    fn clear(&mut self) {
        self.drop_offs.clear();
        self.suspects.clear();
        self.shadows.clear();
    }
}

/// A column's last two returns (see [`Walk`]).
#[derive(Debug, Clone, Copy)]
struct Previous {
    d: f32,
    z: f32,
    beyond_d: f32,
    beyond_z: f32,
}

/// The drop-off rule (`[perception.drop_off]`) with what it needs of the
/// image being binned.
#[derive(Clone, Copy)]
struct DropOffRule<'a> {
    /// A gap up to this long is bridged (∞: detection off), m.
    max_gap: f32,
    min_depth: f32,
    depth_per_m: f32,
    noise: f32,
    /// tan of the tolerated slope.
    tan_slope: f32,
    /// Suspected drop-offs are reported (`suspect_cost` > 0).
    suspects: bool,
    /// Rows, highest beam first.
    order: &'a [u32],
}

impl DropOffRule<'_> {
    /// The least dip under a near edge (less Δ·d) that may be a suspected
    /// drop-off: the noise (∞ when none are reported).
    fn shallow_depth(&self) -> f32 {
        if self.suspects {
            self.noise
        } else {
            f32::INFINITY
        }
    }

    /// Whether the return (`d`, `z`) of column `col` is the near edge of a
    /// *suspected* drop-off, its gap to the column's previous return
    /// (`previous`, the far side, at `d_f`) being longer than `max_gap` and
    /// dipping under it by `v` = `z − z_f`, less than δ. From a sensor `H`
    /// above the edge at horizontal distance `d`, the ray falls `s = H/d`
    /// per metre, so it ran `v/s` (horizontally) below the edge's height
    /// before it met the far side; between the edge's return and where that
    /// ray would have met level ground (a row's spacing) nothing was seen.
    /// So a hole anywhere from `v/s` to `d_f − d` wide, of a depth the image
    /// cannot tell (000 §4.2: "Larger gaps are problematic because they may
    /// contain dangerous negative obstacles").
    ///
    /// It is suspected when
    /// - `v > noise + Δ·d` (not range noise),
    /// - `(d_f − d) · |cos φ| > max_gap`, `φ` the column's bearing from the
    ///   vehicle's heading: the hole may be wider along the heading than
    ///   the wheels bridge (a slot across the way, seen by a column 50°
    ///   off, is crossed 1.6 times its width along the ray). Asking that
    ///   the ray's run `v/s` alone exceed it, a ditch little wider than
    ///   `max_gap` was suspected only where a row happened to land within
    ///   `w − max_gap` of its edge: straight ahead, where a band of
    ///   columns lands alike, none did, and the ERIM drove into a 0.9 m
    ///   ditch through that gap (2026-11-29); and
    /// - the return beyond the far side lies at least `v/2` above it: the
    ///   ground rises back (a crest falling away does not).
    #[cold]
    #[inline(never)]
    fn suspected(
        &self,
        projection: &Projection,
        previous: &Previous,
        (d, z): (f32, f32),
        position: usize,
        col: usize,
    ) -> bool {
        let v = z - previous.z;
        let fall = (projection.t[2] - z) / d;
        if !(v > self.noise + self.depth_per_m * d && fall > 0.0) {
            return false;
        }
        let [x, y, _] = projection.direction(self.order[position] as usize, col);
        let along_heading = x.abs() / x.hypot(y).max(f32::MIN_POSITIVE);
        (previous.d - d) * along_heading > self.max_gap
            && previous.beyond_d < f32::INFINITY
            && previous.beyond_z - previous.z > 0.5 * v
    }

    /// Whether the return (`d`, `z`) of row `order[position]`, column `col`,
    /// whose column's previous returns (farther, higher beams) are `previous`,
    /// is the near edge of a drop-off. Called only when the gap to the
    /// previous return is longer than `max_gap` (or there is none).
    ///
    /// With the return beyond the gap at (d_f, z_f), the near edge at (d, z)
    /// is a drop-off when the ground beyond lies lower than
    /// δ = δ0 + Δ·d (000 §4.2's gap rule, here in the units a column gives:
    /// ground continuing level from the near edge returns at or above z,
    /// however sparse far returns are), and
    /// - falls away more steeply than the tolerated slope:
    ///   `z - z_f > tan(max_slope)·(d_f - d)`, or
    /// - is the foot of a wall: the next return beyond rises from it more
    ///   steeply than the tolerated slope (a hole's far side).
    ///
    /// The far side of a crest falling away gently, seen beyond its
    /// shadow, is neither. With no return beyond at all, it is a drop-off
    /// when the two beams above would have met level ground within range
    /// (one missing pixel is a dropout; beams that would have met the
    /// ground beyond the range see nothing anyway).
    #[cold]
    #[inline(never)]
    fn judge(
        &self,
        projection: &Projection,
        previous: &Previous,
        (d, z): (f32, f32),
        position: usize,
        col: usize,
    ) -> bool {
        if previous.d == f32::INFINITY {
            return self.nothing_seen_beyond(projection, (d, z), position, col);
        }
        let (gap, depth) = (previous.d - d, z - previous.z);
        if depth <= self.min_depth + self.depth_per_m * d {
            return false;
        }
        if depth > self.tan_slope * gap {
            return true;
        }
        previous.beyond_d < f32::INFINITY
            && previous.beyond_z - previous.z
                > self.tan_slope * (previous.beyond_d - previous.d).max(0.0) + self.noise
    }

    fn nothing_seen_beyond(
        &self,
        projection: &Projection,
        (d, z): (f32, f32),
        position: usize,
        col: usize,
    ) -> bool {
        let (Some(&above), Some(&two_above)) = (
            self.order.get(position.wrapping_sub(1)),
            self.order.get(position.wrapping_sub(2)),
        ) else {
            return false;
        };
        // Where a beam would meet level ground at the near edge's height:
        // (distance along the beam, horizontal distance from the sensor).
        let level_hit = |row: u32| {
            let [x, y, dz] = projection.direction(row as usize, col);
            let t = (z - projection.t[2]) / dz;
            (dz < 0.0 && t > 0.0).then(|| (t, t * x.hypot(y)))
        };
        // Both beams found nothing: the unseen stretch reaches at least
        // to where the higher one would have met level ground.
        match (level_hit(above), level_hit(two_above)) {
            (Some(_), Some((t, horizontal))) => {
                horizontal - d > self.max_gap && t <= projection.max_range
            }
            _ => false,
        }
    }
}

/// One row of a part, projected: per pixel its cell (or why it has none)
/// and its point relative to the cell's centre.
#[derive(Debug, Default)]
struct ProjectedRow {
    index: Vec<u32>,
    dx: Vec<f32>,
    dy: Vec<f32>,
    z: Vec<f32>,
    /// Horizontal distance from the sensor.
    d: Vec<f32>,
}

/// `ProjectedRow::index` of a pixel that has no cell, by reason (all above
/// any grid index).
const NO_RETURN: u32 = u32::MAX;
const OUT_OF_RANGE: u32 = u32::MAX - 1;
const OUTSIDE_GRID: u32 = u32::MAX - 2;

impl Bins {
    fn new(cells: usize) -> Self {
        Self {
            slots: vec![EMPTY_SLOT; cells],
            cells: Vec::new(),
            column_rows: Vec::new(),
            counts: [0; 4],
            row: ProjectedRow::default(),
            walk: Walk::default(),
            found: Found::default(),
        }
    }

    /// Moves `other`'s cells into these (leaving `other` empty).
    fn absorb(&mut self, other: &mut Bins) {
        for cell in other.cells.drain(..) {
            other.slots[cell.index as usize] = EMPTY_SLOT;
            put(&mut self.slots, &mut self.cells, &cell);
        }
        for (count, more) in self.counts.iter_mut().zip(other.counts) {
            *count += more;
        }
    }
}

/// Bins the projected pixels of one row, in order, continuing `run` (the
/// run reaching into the next row is returned). Neighbouring pixels mostly
/// fall in the same cell: their points gather in the run and reach the bins
/// once per run. A function of its own, with the run in local variables, so
/// that the compiler keeps it in registers (inlined into the projection, it
/// went through memory at every point: 20% slower).
#[inline(never)]
fn gather(row: u32, points: &ProjectedRow, bins: &mut Bins, run: Cell) -> Cell {
    let Cell {
        index: mut index_of_run,
        mut count,
        mut z_min,
        mut z_max,
        mut sums,
    } = run;
    // The run's locals, as a cell (and, assigned to, as its fields).
    macro_rules! run {
        () => {
            Cell {
                index: index_of_run,
                count,
                z_min,
                z_max,
                sums,
            }
        };
    }
    let [mut no_return, mut out_of_range, mut outside_grid, mut valid] = bins.counts;
    let pixels = points
        .index
        .iter()
        .zip(&points.dx)
        .zip(points.dy.iter().zip(&points.z))
        .zip(bins.column_rows.iter_mut());
    for (((&index, &dx), (&dy, &z)), span) in pixels {
        if index >= OUTSIDE_GRID {
            match index {
                NO_RETURN => no_return += 1,
                OUTSIDE_GRID => outside_grid += 1,
                _ => out_of_range += 1,
            }
            continue;
        }
        if index != index_of_run {
            if count > 0 {
                put(&mut bins.slots, &mut bins.cells, &run!());
            }
            run!() = Cell::new(index);
        }
        count += 1;
        z_min = if z < z_min { z } else { z_min };
        z_max = if z > z_max { z } else { z_max };
        for (sum, term) in sums.iter_mut().zip(Cell::terms(dx, dy, z)) {
            *sum += term;
        }
        valid += 1;
        // The column's first and last valid rows (highest beam first) give
        // its far and near return, for the field of view.
        span.0 = if span.0 == u32::MAX { row } else { span.0 };
        span.1 = row;
    }
    bins.counts = [no_return, out_of_range, outside_grid, valid];
    run!()
}

/// The row a [`Walk`] steps through: its place in the walk order, and
/// what the drop-off rule needs.
#[derive(Clone, Copy)]
struct Row<'a> {
    position: usize,
    /// The image column of the part's first column.
    first_col: usize,
    projection: &'a Projection<'a>,
}

/// Adds the points of `cell` to the cell of the same index.
#[inline(always)]
fn put(slots: &mut [u32], cells: &mut Vec<Cell>, cell: &Cell) {
    let slot = &mut slots[cell.index as usize];
    if *slot == EMPTY_SLOT {
        *slot = cells.len() as u32;
        cells.push(*cell);
    } else {
        cells[*slot as usize].merge(cell);
    }
}

/// What every part of one image's binning shares: the grid and the
/// projection of the image's beams into the level frame.
#[derive(Clone, Copy)]
struct Projection<'a> {
    ranges: &'a [f32],
    cols: usize,
    cos_el: &'a [f32],
    sin_el: &'a [f32],
    /// Per column: the rotated horizontal beam direction, one array per axis.
    column_terms: &'a [Vec<f32>; 3],
    /// The rotated vertical axis of the sensor.
    r2: [f32; 3],
    t: [f32; 3],
    cell_size: f32,
    /// The grid's corner, negated, in whole cells: a point's cell is
    /// `floor(x / cell) + offset`, so cell edges lie on multiples of the
    /// cell size from the vehicle origin whatever the region's extent.
    offset: [f32; 2],
    /// Cells per grid row.
    stride: usize,
    /// The interior of the grid (the region), in cell units, per axis.
    lo: [f32; 2],
    hi: [f32; 2],
    min_range: f32,
    max_range: f32,
    drop_off: DropOffRule<'a>,
}

impl Projection<'_> {
    /// The unit direction of beam (`row`, `col`) in the level frame.
    fn direction(&self, row: usize, col: usize) -> [f32; 3] {
        let (ce, se) = (self.cos_el[row], self.sin_el[row]);
        std::array::from_fn(|axis| ce * self.column_terms[axis][col] + se * self.r2[axis])
    }

    /// Projects and bins the valid pixels of `columns` into `bins`, with
    /// the AVX2 instruction set where the processor has it (the same
    /// arithmetic, so the same result: Rust never fuses a multiply and an add
    /// on its own).
    fn bin(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.bin_avx2(columns, bins) };
        }
        self.bin_portable(columns, bins);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn bin_avx2(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        self.bin_portable(columns, bins);
    }

    /// Bins row by row, each in two passes: [`Self::project_row`] projects
    /// every pixel on its own (no branch, no dependency between pixels, so
    /// the compiler runs it eight pixels at a time), then [`gather`] puts the
    /// points into the bins in pixel order.
    #[inline(always)]
    fn bin_portable(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        if self.drop_off.max_gap.is_finite() {
            self.bin_rows::<true>(columns, bins);
        } else {
            self.bin_rows::<false>(columns, bins);
        }
    }

    #[inline(always)]
    fn bin_rows<const DROP_OFFS: bool>(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        let mut points = std::mem::take(&mut bins.row);
        bins.column_rows.clear();
        bins.column_rows.resize(columns.len(), (u32::MAX, 0));
        bins.walk.start(columns.len());
        bins.found.clear();
        bins.counts = [0; 4];
        let mut run = Cell::new(u32::MAX);
        let cols = self.cols.max(1);
        for (position, &row) in self.drop_off.order.iter().enumerate() {
            let ranges = &self.ranges[row as usize * cols..][..cols];
            self.project_row::<DROP_OFFS>(
                row as usize,
                &ranges[columns.clone()],
                columns.start,
                &mut points,
            );
            if DROP_OFFS {
                let row = Row {
                    position,
                    first_col: columns.start,
                    projection: self,
                };
                bins.walk.step(&row, &points, &mut bins.found);
            }
            run = gather(row, &points, bins, run);
        }
        if run.count > 0 {
            put(&mut bins.slots, &mut bins.cells, &run);
        }
        bins.row = points;
    }

    /// Projects the pixels `ranges` of `row`, from column `first` on, into
    /// `out` (with each pixel's horizontal distance when `DISTANCE`).
    #[inline(always)]
    fn project_row<const DISTANCE: bool>(
        &self,
        row: usize,
        ranges: &[f32],
        first: usize,
        out: &mut ProjectedRow,
    ) {
        let n = ranges.len();
        for buffer in [&mut out.dx, &mut out.dy, &mut out.z, &mut out.d] {
            buffer.resize(n, 0.0);
        }
        out.index.resize(n, 0);
        let inv_cell = 1.0 / self.cell_size;
        let (t, [ox, oy], stride, cell) = (self.t, self.offset, self.stride, self.cell_size);
        let ([lo_x, lo_y], [hi_x, hi_y]) = (self.lo, self.hi);
        let (last_x, last_y) = (hi_x - 1.0, hi_y - 1.0);
        let (min_range, max_range) = (self.min_range, self.max_range);
        let (ce, se, r2) = (self.cos_el[row], self.sin_el[row], self.r2);
        let v = [se * r2[0], se * r2[1], se * r2[2]];
        let [ux, uy, uz] = self.column_terms;
        let columns = first..first + n;
        let (ux, uy, uz) = (&ux[columns.clone()], &uy[columns.clone()], &uz[columns]);
        let (index, dx, dy, z, d) = (
            &mut out.index[..n],
            &mut out.dx[..n],
            &mut out.dy[..n],
            &mut out.z[..n],
            &mut out.d[..n],
        );
        for k in 0..n {
            let range = ranges[k];
            let x = (ce * ux[k] + v[0]) * range + t[0];
            let y = (ce * uy[k] + v[1]) * range + t[1];
            z[k] = (ce * uz[k] + v[2]) * range + t[2];
            if DISTANCE {
                d[k] = ((x - t[0]) * (x - t[0]) + (y - t[1]) * (y - t[1])).sqrt();
            }
            let fx = x * inv_cell + ox;
            let fy = y * inv_cell + oy;
            // NaN fails every comparison, so these tests keep only valid
            // returns; clamped, the cell is computed for every pixel.
            let in_range = range >= min_range && range <= max_range;
            let in_grid = fx >= lo_x && fx < hi_x && fy >= lo_y && fy < hi_y;
            // SAFETY: clamped to [lo, hi - 1] (max and min return the
            // number when the other operand is NaN), far inside i32.
            let (ix, iy) = unsafe {
                (
                    fx.max(lo_x).min(last_x).to_int_unchecked::<i32>(),
                    fy.max(lo_y).min(last_y).to_int_unchecked::<i32>(),
                )
            };
            let returned = range > 0.0 && range < f32::INFINITY;
            let why = if returned { OUT_OF_RANGE } else { NO_RETURN };
            // Wrapping: exact for a pixel in the grid (the only one whose
            // index is used), and no overflow check to stop the loop
            // vectorising in a checked build (the tests').
            let cell_index = (iy as u32)
                .wrapping_mul(stride as u32)
                .wrapping_add(ix as u32);
            index[k] = if !in_range {
                why
            } else if in_grid {
                cell_index
            } else {
                OUTSIDE_GRID
            };
            dx[k] = x - (ix as f32 + 0.5 - ox) * cell;
            dy[k] = y - (iy as f32 + 0.5 - oy) * cell;
        }
    }
}

/// The 002 §4 classifier. Build it with [`PerceptionConfig::build_evaluator`]
/// or [`CellClassifier::new`].
pub struct CellClassifier {
    cell_size: f32,
    /// Half the slope window, cells.
    slope_radius: usize,
    min_points: u32,
    max_height_variation: f32,
    max_slope_tan2: f64,
    max_discontinuity: f32,
    min_plane_variance: f64,
    min_range: f32,
    max_range: f32,
    fov_max_vertices: usize,
    /// `[perception.drop_off]`, without a beam order: each image's binning
    /// uses it with the order of its rows.
    drop_off: DropOffRule<'static>,
    /// Grid indices of this image's drop-off cells (the parts' merged).
    drop_offs: Vec<u32>,
    /// Grid indices of this image's suspected drop-off cells (the parts'
    /// merged), and the cost they are reported at.
    suspects: Vec<u32>,
    suspect_cost: f32,
    /// This image's shadows (the parts' merged): (column, edge, beyond).
    shadows: Vec<(u32, f32, f32)>,
    /// The sensor's position in the level frame, this image.
    sensor_xy: [f32; 2],
    /// The grid over the region, in the level frame. Points are binned only
    /// `grid.margin` cells away from its edge, so every neighbour a window
    /// reaches exists.
    grid: GridShape,
    /// Index offsets of the slope window's cells, with their (dx, dy) in metres.
    window: Vec<(isize, f32, f32)>,
    /// Index offsets of a cell's eight neighbours.
    neighbours: [isize; 8],
    /// The parts' bins; the first holds the whole image once merged.
    bins: [Bins; PARTS],
    /// Per touched cell (same slot as in `bins[0]`): its reasons and its region.
    labels: Vec<(Reasons, u32)>,
    queue: Vec<u32>,
    trig: BeamTrig,
    column_terms: [Vec<f32>; 3],
    fov: FovBuilder,
}

impl CellClassifier {
    /// A classifier with a grid covering `max_range_m` around the sensor.
    pub fn new(config: &PerceptionConfig) -> Self {
        let c = &config.cells;
        let cell_size = c.cell_size_m as f32;
        let grid = config.grid();
        let radius = (c.slope_window_cells / 2) as isize;
        let s = grid.cols as isize;
        let window = (-radius..=radius)
            .flat_map(|dy| {
                (-radius..=radius)
                    .map(move |dx| (dy * s + dx, dx as f32 * cell_size, dy as f32 * cell_size))
            })
            .collect();
        Self {
            slope_radius: radius as usize,
            cell_size,
            min_points: c.min_points,
            max_height_variation: c.max_height_variation_m as f32,
            max_slope_tan2: if c.slope {
                c.max_slope_deg.to_radians().tan().powi(2)
            } else {
                f64::INFINITY
            },
            max_discontinuity: c.max_discontinuity_m as f32,
            min_plane_variance: c.min_plane_spread_m * c.min_plane_spread_m,
            min_range: config.min_range_m as f32,
            max_range: config.max_range_m as f32,
            fov_max_vertices: config.fov_max_vertices,
            drop_off: {
                let d = &config.drop_off;
                DropOffRule {
                    max_gap: if d.enabled {
                        d.max_gap_m
                    } else {
                        f64::INFINITY
                    } as f32,
                    min_depth: d.min_depth_m as f32,
                    depth_per_m: d.depth_per_m as f32,
                    noise: d.noise_m as f32,
                    tan_slope: c.max_slope_deg.to_radians().tan() as f32,
                    suspects: d.suspect_cost > 0.0,
                    order: &[],
                }
            },
            drop_offs: Vec::new(),
            suspects: Vec::new(),
            suspect_cost: config.drop_off.suspect_cost as f32,
            shadows: Vec::new(),
            sensor_xy: [0.0; 2],
            grid,
            window,
            neighbours: [-s - 1, -s, -s + 1, -1, 1, s - 1, s, s + 1],
            bins: std::array::from_fn(|_| Bins::new(grid.cols * grid.rows)),
            labels: Vec::new(),
            queue: Vec::new(),
            trig: BeamTrig::default(),
            column_terms: Default::default(),
            fov: FovBuilder::default(),
        }
    }

    /// Projects and bins every valid pixel, the parts through `runner`.
    fn bin(
        &mut self,
        image: &RangeImage,
        level_from_sensor: &Isometry,
        runner: &dyn Runner,
        stats: &mut ImageStats,
    ) {
        self.trig
            .update(&image.beams.elevation, &image.beams.azimuth);
        let rotation = level_from_sensor.rotation.to_rotation_matrix();
        let m = rotation.matrix();
        let column = |i: usize| [m[(0, i)] as f32, m[(1, i)] as f32, m[(2, i)] as f32];
        let (r0, r1, r2) = (column(0), column(1), column(2));
        let t = level_from_sensor.translation.vector;
        let t = [t.x as f32, t.y as f32, t.z as f32];
        let cols = image.cols();
        for (axis, terms) in self.column_terms.iter_mut().enumerate() {
            terms.clear();
            terms.extend(
                self.trig
                    .cos_az
                    .iter()
                    .zip(&self.trig.sin_az)
                    .map(|(&ca, &sa)| ca * r0[axis] + sa * r1[axis]),
            );
        }
        let projection = Projection {
            ranges: &image.range,
            cols,
            cos_el: &self.trig.cos_el,
            sin_el: &self.trig.sin_el,
            column_terms: &self.column_terms,
            r2,
            t,
            cell_size: self.cell_size,
            offset: self.grid.corner,
            stride: self.grid.cols,
            lo: [self.grid.margin as f32; 2],
            hi: [
                (self.grid.cols - self.grid.margin) as f32,
                (self.grid.rows - self.grid.margin) as f32,
            ],
            min_range: self.min_range.max(f32::MIN_POSITIVE),
            max_range: self.max_range,
            drop_off: DropOffRule {
                order: &self.trig.order,
                ..self.drop_off
            },
        };
        let parts: [std::ops::Range<usize>; PARTS] =
            std::array::from_fn(|k| cols * k / PARTS..cols * (k + 1) / PARTS);
        let [first, second] = &mut self.bins;
        let (left, right) = (parts[0].clone(), parts[1].clone());
        let mut tasks: [&mut (dyn FnMut() + Send); PARTS] =
            [&mut || projection.bin(left.clone(), first), &mut || {
                projection.bin(right.clone(), second)
            }];
        runner.run(&mut tasks);
        // Far and near return of each column, for the field of view.
        self.fov.start(cols, [t[0], t[1]]);
        for (bins, columns) in self.bins.iter().zip(&parts) {
            for (i, &(top, bottom)) in bins.column_rows.iter().enumerate() {
                if top == u32::MAX {
                    continue;
                }
                let col = columns.start + i;
                let u = self.column_terms.each_ref().map(|terms| terms[col]);
                for row in [top, bottom] {
                    let row = row as usize;
                    let (ce, se) = (self.trig.cos_el[row], self.trig.sin_el[row]);
                    let range = image.range[row * cols + col];
                    let x = (ce * u[0] + se * r2[0]) * range + t[0];
                    let y = (ce * u[1] + se * r2[1]) * range + t[1];
                    self.fov.add(col, x, y);
                }
            }
        }
        self.drop_offs.clear();
        self.suspects.clear();
        self.shadows.clear();
        for bins in &self.bins {
            self.drop_offs.extend_from_slice(&bins.found.drop_offs);
            self.suspects.extend_from_slice(&bins.found.suspects);
            self.shadows.extend_from_slice(&bins.found.shadows);
        }
        self.sensor_xy = [t[0], t[1]];
        let (first, rest) = self.bins.split_at_mut(1);
        for other in rest {
            first[0].absorb(other);
        }
        let [no_return, out_of_range, outside_grid, valid] = first[0].counts;
        stats.no_return += no_return;
        stats.out_of_range += out_of_range;
        stats.outside_grid += outside_grid;
        stats.valid_points += valid;
    }

    /// The slot of the cell `offset` grid indices away from `cell`, if it
    /// holds points. Binned cells keep a margin from the edge, so every
    /// offset of the window stays inside the grid.
    #[inline]
    fn neighbour(&self, cell: &Cell, offset: isize) -> Option<usize> {
        let slot = *self.bins[0]
            .slots
            .get((cell.index as isize + offset) as usize)?;
        (slot != EMPTY_SLOT).then_some(slot as usize)
    }

    /// Plane sums of the slope window around `cell`.
    fn window_sums(&self, cell: &Cell) -> PlaneSums {
        let mut sums = PlaneSums::default();
        for &(offset, ox, oy) in &self.window {
            if let Some(slot) = self.neighbour(cell, offset) {
                sums.add(&self.bins[0].cells[slot], ox, oy);
            }
        }
        sums
    }

    /// Applies criteria (a), (b), (c) to every touched cell.
    fn classify(&mut self, runner: &dyn Runner, stats: &mut ImageStats) {
        self.labels.clear();
        let cells = self.bins[0].cells.len();
        self.labels.resize(cells, (Reasons::NONE, u32::MAX));
        // Each cell is judged on its own (a jump between two cells marks
        // both, as each sees it): the halves may run at once.
        let mut labels = std::mem::take(&mut self.labels);
        let half = cells / 2;
        let (low, high) = labels.split_at_mut(half);
        let this = &*self;
        runner.run(&mut [&mut || this.judge(0, low), &mut || this.judge(half, high)]);
        self.labels = labels;
        for &index in &self.drop_offs {
            let slot = self.bins[0].slots[index as usize];
            self.labels[slot as usize].0.insert(Reasons::DROP_OFF);
        }
        for &(reasons, _) in &self.labels {
            stats.cells_evaluated += 1;
            if !reasons.is_empty() {
                stats.untraversable += 1;
                for (count, (reason, _)) in stats.by_reason.iter_mut().zip(Reasons::ALL) {
                    *count += u32::from(reasons.contains(reason));
                }
            }
        }
    }

    /// Applies (a), (b), (c) to the cells from slot `first` on, one per label
    /// (with AVX2 where the processor has it, as in [`Projection::bin`]).
    fn judge(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.judge_avx2(first, labels) };
        }
        self.judge_portable(first, labels);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn judge_avx2(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        self.judge_portable(first, labels);
    }

    #[inline(always)]
    fn judge_portable(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        let cells = &self.bins[0].cells[first..];
        for (cell, label) in cells.iter().zip(labels) {
            let jump = self.neighbours.iter().any(|&offset| {
                self.neighbour(cell, offset).is_some_and(|n| {
                    let neighbour = &self.bins[0].cells[n];
                    let gap = (neighbour.z_min - cell.z_max).max(cell.z_min - neighbour.z_max);
                    gap > self.max_discontinuity
                })
            });
            if jump {
                label.0.insert(Reasons::DISCONTINUITY);
            }
            if cell.count < self.min_points {
                continue;
            }
            if cell.z_max - cell.z_min > self.max_height_variation {
                label.0.insert(Reasons::HEIGHT_VARIATION);
            }
            if self
                .window_sums(cell)
                .slope_tan2(self.min_plane_variance)
                .is_some_and(|tan2| tan2 > self.max_slope_tan2)
            {
                label.0.insert(Reasons::SLOPE);
            }
        }
    }

    /// Groups untraversable cells into 8-connected regions and writes them,
    /// in the world frame, into `report`.
    fn emit(
        &mut self,
        world_from_level: &Isometry,
        report: &mut ObstacleReport,
        stats: &mut ImageStats,
    ) {
        for seed in 0..self.bins[0].cells.len() {
            if self.labels[seed].0.is_empty() || self.labels[seed].1 != u32::MAX {
                continue;
            }
            let region = report.regions.len() as u32;
            let mut summary = Region {
                cells: 0,
                reasons: Reasons::NONE,
            };
            self.queue.clear();
            self.queue.push(seed as u32);
            self.labels[seed].1 = region;
            while let Some(slot) = self.queue.pop() {
                let cell = self.bins[0].cells[slot as usize];
                summary.cells += 1;
                summary.reasons.insert(self.labels[slot as usize].0);
                for offset in self.neighbours {
                    let Some(n) = self.neighbour(&cell, offset) else {
                        continue;
                    };
                    let label = &mut self.labels[n];
                    if !label.0.is_empty() && label.1 == u32::MAX {
                        label.1 = region;
                        self.queue.push(n as u32);
                    }
                }
            }
            report.regions.push(summary);
        }
        let (sin, cos) = arcnav_vehicle::frames::yaw_of(world_from_level).sin_cos();
        let origin = world_from_level.translation.vector;
        let [ox, oy] = self.grid.corner;
        let (cols, size) = (self.grid.cols, self.cell_size);
        let world = |cell: &Cell, reasons, region, cost| {
            let (ix, iy) = (cell.index as usize % cols, cell.index as usize / cols);
            let cx = f64::from((ix as f32 + 0.5 - ox) * size);
            let cy = f64::from((iy as f32 + 0.5 - oy) * size);
            ObstacleCell {
                x: origin.x + cos * cx - sin * cy,
                y: origin.y + sin * cx + cos * cy,
                z_min: cell.z_min + origin.z as f32,
                z_max: cell.z_max + origin.z as f32,
                reasons,
                region,
                cost,
            }
        };
        for (cell, &(reasons, region)) in self.bins[0].cells.iter().zip(&self.labels) {
            if !reasons.is_empty() {
                report.cells.push(world(cell, reasons, region, 1.0));
            }
        }
        // Suspected drop-offs on cells judged traversable: graded ground
        // with the reason drop-off, in one region of their own.
        self.suspects.sort_unstable();
        self.suspects.dedup();
        let region = report.regions.len() as u32;
        let mut graded = 0;
        for &index in &self.suspects {
            let slot = self.bins[0].slots[index as usize] as usize;
            if self.labels[slot].0.is_empty() {
                let cell = &self.bins[0].cells[slot];
                report
                    .cells
                    .push(world(cell, Reasons::DROP_OFF, region, self.suspect_cost));
                graded += 1;
            }
        }
        if graded > 0 {
            report.regions.push(Region {
                cells: graded,
                reasons: Reasons::NONE,
            });
        }
        stats.graded += graded;
        stats.suspected += graded;
        stats.regions = report.regions.len() as u32;
    }

    /// Writes the image's shadows, in the world frame, into `report`. A
    /// column's sector reaches halfway to the farther of its neighbours'
    /// directions (in the level frame, where a tilted sensor's columns
    /// spread wider than in its own).
    fn emit_shadows(&self, world_from_level: &Isometry, report: &mut ObstacleReport) {
        let [ux, uy, _] = &self.column_terms;
        let cols = ux.len();
        // The angle between the horizontal directions of two columns, as
        // its sine (columns are well under 0.1 rad apart): no trigonometry.
        let between = |a: usize, b: usize| {
            let cross = ux[a] * uy[b] - uy[a] * ux[b];
            cross.abs() / (ux[a].hypot(uy[a]) * ux[b].hypot(uy[b]))
        };
        let yaw = arcnav_vehicle::frames::yaw_of(world_from_level);
        let origin = world_from_level
            * nalgebra::Point3::new(
                f64::from(self.sensor_xy[0]),
                f64::from(self.sensor_xy[1]),
                0.0,
            );
        report.shadows.origin = nalgebra::Point2::new(origin.x, origin.y);
        for &(col, near, far) in &self.shadows {
            let col = col as usize;
            let spacing = [col.checked_sub(1), (col + 1 < cols).then_some(col + 1)]
                .into_iter()
                .flatten()
                .map(|n| between(col, n))
                .fold(0.0f32, f32::max);
            report.shadows.sectors.push(Shadow {
                azimuth: wrap_angle(f64::from(uy[col].atan2(ux[col])) + yaw) as f32,
                // A hair wider, so neighbouring columns' sectors overlap
                // rather than leave a rounding gap between them.
                half_width: (0.51 * spacing).min(Shadow::MAX_HALF_WIDTH),
                near,
                far,
            });
        }
    }

    fn reset_touched(&mut self) {
        let bins = &mut self.bins[0];
        for cell in &bins.cells {
            bins.slots[cell.index as usize] = EMPTY_SLOT;
        }
        bins.cells.clear();
    }
}

impl crate::plugin::EvaluatorPlugin for CellClassifier {
    const NAME: &'static str = "cells";
    const ABOUT: &'static str =
        "per-cell height variation, slope and discontinuity (002, Langer, Rosenblatt & Hebert)";
    type Config = crate::config::CellsConfig;

    /// `[perception.cells]`, checked with the rest of `[perception]`.
    fn config(perception: &PerceptionConfig) -> Result<Self::Config, arcnav_vehicle::ConfigError> {
        Ok(perception.cells.clone())
    }

    fn build(_: Self::Config, perception: &PerceptionConfig) -> Self {
        Self::new(perception)
    }
}

impl TerrainEvaluator for CellClassifier {
    fn name(&self) -> &'static str {
        "cells"
    }

    /// A cell's own returns, its slope window's and its neighbours' (the
    /// discontinuity), each a cell diagonal from its centre at most. The
    /// drop-off rule looks along the cell's own columns only.
    fn support(&self) -> crate::Support {
        let cells = (self.slope_radius + 2) as f64;
        crate::Support {
            metres: cells * f64::from(self.cell_size) * std::f64::consts::SQRT_2,
            pixels: 1,
            radians: 0.0,
        }
    }

    fn evaluate(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
    ) -> Result<ImageStats, PerceptionError> {
        self.evaluate_with(image, world_from_vehicle, report, &InOrder)
    }

    fn evaluate_with(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
        runner: &dyn Runner,
    ) -> Result<ImageStats, PerceptionError> {
        report.clear();
        image.validate()?;
        report.utime = image.utime;
        report.sensor.push_str(&image.sensor);
        report.cell_size_m = f64::from(self.cell_size);
        let mut stats = ImageStats {
            pixels: image.range.len() as u32,
            ..ImageStats::default()
        };
        if image.range.is_empty() {
            return Ok(stats);
        }
        let world_from_level = level_frame(world_from_vehicle);
        let level_from_sensor =
            world_from_level.inverse() * world_from_vehicle * image.vehicle_from_sensor;
        let runner: &dyn Runner = if image.range.len() >= PARALLEL_MIN_PIXELS {
            runner
        } else {
            &InOrder
        };
        self.bin(image, &level_from_sensor, runner, &mut stats);
        self.classify(runner, &mut stats);
        self.emit(&world_from_level, report, &mut stats);
        self.fov
            .finish(&world_from_level, self.fov_max_vertices, &mut report.fov);
        self.emit_shadows(&world_from_level, report);
        self.reset_touched();
        Ok(stats)
    }
}
