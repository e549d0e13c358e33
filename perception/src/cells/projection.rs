//! Projecting an image's returns into grid cells, in parts a runner may
//! bin at the same time, merged in a fixed order; and the drop-offs and
//! shadows found on the way, walking each column from its far returns to
//! its near ones.

use super::cell::{Cell, NO_RETURN, OUT_OF_RANGE, OUTSIDE_GRID, ProjectedRow};

pub(super) const EMPTY_SLOT: u32 = u32::MAX;

/// An image's columns are binned in this many parts, which a
/// [`Runner`] may bin at the same time; the parts are merged in a fixed
/// order, so the result is the same however they ran.
pub(super) const PARTS: usize = 2;

/// Images with fewer pixels are binned in order whatever the runner: a
/// thread hand-off would cost more than it saves.
pub(super) const PARALLEL_MIN_PIXELS: usize = 1 << 16;

/// The cells binned from a part of an image's columns.
#[derive(Debug)]
pub(super) struct Bins {
    /// Per grid cell: its slot in `cells`, or `EMPTY_SLOT`.
    pub(super) slots: Vec<u32>,
    /// The cells this part touched, in first-touch order.
    pub(super) cells: Vec<Cell>,
    /// Per column of the part: the first and last row with a valid return.
    pub(super) column_rows: Vec<(u32, u32)>,
    /// No return, out of range, outside the grid, valid.
    pub(super) counts: [u32; 4],
    /// The row being binned, projected.
    pub(super) row: ProjectedRow,
    /// The part's columns walked from their far returns to their near ones.
    pub(super) walk: Walk,
    /// Drop-offs and shadows the walk found.
    pub(super) found: Found,
}

impl Bins {
    pub(super) fn new(cells: usize) -> Self {
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
    pub(super) fn absorb(&mut self, other: &mut Bins) {
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
pub(super) fn gather(row: u32, points: &ProjectedRow, bins: &mut Bins, run: Cell) -> Cell {
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

/// Adds the points of `cell` to the cell of the same index.
#[inline(always)]
pub(super) fn put(slots: &mut [u32], cells: &mut Vec<Cell>, cell: &Cell) {
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
pub(super) struct Projection<'a> {
    pub(super) ranges: &'a [f32],
    pub(super) cols: usize,
    pub(super) cos_el: &'a [f32],
    pub(super) sin_el: &'a [f32],
    /// Per column: the rotated horizontal beam direction, one array per axis.
    pub(super) column_terms: &'a [Vec<f32>; 3],
    /// The rotated vertical axis of the sensor.
    pub(super) r2: [f32; 3],
    pub(super) t: [f32; 3],
    pub(super) cell_size: f32,
    /// The grid's corner, negated, in whole cells: a point's cell is
    /// `floor(x / cell) + offset`, so cell edges lie on multiples of the
    /// cell size from the vehicle origin whatever the region's extent.
    pub(super) offset: [f32; 2],
    /// Cells per grid row.
    pub(super) stride: usize,
    /// The interior of the grid (the region), in cell units, per axis.
    pub(super) lo: [f32; 2],
    pub(super) hi: [f32; 2],
    pub(super) min_range: f32,
    pub(super) max_range: f32,
    pub(super) drop_off: DropOffRule<'a>,
}

impl Projection<'_> {
    /// The unit direction of beam (`row`, `col`) in the level frame.
    pub(super) fn direction(&self, row: usize, col: usize) -> [f32; 3] {
        let (ce, se) = (self.cos_el[row], self.sin_el[row]);
        std::array::from_fn(|axis| ce * self.column_terms[axis][col] + se * self.r2[axis])
    }

    /// Projects and bins the valid pixels of `columns` into `bins`, with
    /// the AVX2 instruction set where the processor has it (the same
    /// arithmetic, so the same result: Rust never fuses a multiply and an add
    /// on its own).
    pub(super) fn bin(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.bin_avx2(columns, bins) };
        }
        self.bin_portable(columns, bins);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) fn bin_avx2(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        self.bin_portable(columns, bins);
    }

    /// Bins row by row, each in two passes: [`Self::project_row`] projects
    /// every pixel on its own (no branch, no dependency between pixels, so
    /// the compiler runs it eight pixels at a time), then [`gather`] puts the
    /// points into the bins in pixel order.
    #[inline(always)]
    pub(super) fn bin_portable(&self, columns: std::ops::Range<usize>, bins: &mut Bins) {
        if self.drop_off.max_gap.is_finite() {
            self.bin_rows::<true>(columns, bins);
        } else {
            self.bin_rows::<false>(columns, bins);
        }
    }

    #[inline(always)]
    pub(super) fn bin_rows<const DROP_OFFS: bool>(
        &self,
        columns: std::ops::Range<usize>,
        bins: &mut Bins,
    ) {
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
    pub(super) fn project_row<const DISTANCE: bool>(
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

/// The row a [`Walk`] steps through: its place in the walk order, and
/// what the drop-off rule needs.
#[derive(Clone, Copy)]
pub(super) struct Row<'a> {
    pub(super) position: usize,
    /// The image column of the part's first column.
    pub(super) first_col: usize,
    pub(super) projection: &'a Projection<'a>,
}

/// The last two returns of each column of a part, walking the columns
/// from the highest beam down (far to near): horizontal distance from the
/// sensor and height, level frame, one array each (so a row's step is
/// vectorised). `d = ∞`: none yet.
#[derive(Debug, Default)]
pub(super) struct Walk {
    pub(super) d: Vec<f32>,
    pub(super) z: Vec<f32>,
    pub(super) beyond_d: Vec<f32>,
    pub(super) beyond_z: Vec<f32>,
    /// Beams of each column that returned nothing since its last return.
    pub(super) missed: Vec<u8>,
    /// Per pixel of the row: its gap to the column's previous return is
    /// longer than the vehicle bridges and the ground beyond lower, or
    /// beams between them returned nothing.
    pub(super) long_gap: Vec<u8>,
}

/// This many beams in a row that return nothing between two returns are
/// not dropouts (1 % of pixels each, so three in a row one in a million)
/// but something the sensor does not see, such as glass or water: the
/// ground between is unseen, a shadow, even when the ground beyond is
/// level (000 §6: "this creates a sizable gap through occlusion").
pub(super) const MISSED_BEAMS: u8 = 3;

impl Walk {
    pub(super) fn start(&mut self, columns: usize) {
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
    pub(super) fn step(&mut self, row: &Row, points: &ProjectedRow, found: &mut Found) {
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
pub(super) struct Found {
    /// Grid indices of the cells at the near edge of a drop-off.
    pub(super) drop_offs: Vec<u32>,
    /// Grid indices of the cells at the near edge of a suspected drop-off.
    pub(super) suspects: Vec<u32>,
    /// Shadows: (image column, distance of the edge, of the return beyond),
    /// level frame.
    pub(super) shadows: Vec<(u32, f32, f32)>,
}

impl Found {
    pub(super) fn clear(&mut self) {
        self.drop_offs.clear();
        self.suspects.clear();
        self.shadows.clear();
    }
}

/// A column's last two returns (see [`Walk`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Previous {
    pub(super) d: f32,
    pub(super) z: f32,
    pub(super) beyond_d: f32,
    pub(super) beyond_z: f32,
}

/// The drop-off rule (`[perception.drop_off]`) with what it needs of the
/// image being binned.
#[derive(Clone, Copy)]
pub(super) struct DropOffRule<'a> {
    /// A gap up to this long is bridged (∞: detection off), m.
    pub(super) max_gap: f32,
    pub(super) min_depth: f32,
    pub(super) depth_per_m: f32,
    pub(super) noise: f32,
    /// tan of the tolerated slope.
    pub(super) tan_slope: f32,
    /// Suspected drop-offs are reported (`suspect_cost` > 0).
    pub(super) suspects: bool,
    /// Rows, highest beam first.
    pub(super) order: &'a [u32],
}

impl DropOffRule<'_> {
    /// The least dip under a near edge (less Δ·d) that may be a suspected
    /// drop-off: the noise (∞ when none are reported).
    pub(super) fn shallow_depth(&self) -> f32 {
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
    pub(super) fn suspected(
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
    pub(super) fn judge(
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

    pub(super) fn nothing_seen_beyond(
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
