//! What the grid evaluators (`height_diff`, `pca`) share: the image's points
//! in the gravity-aligned frame of the capture pose, the level-frame grid
//! over `[perception.region]` they are binned into, and the step from
//! "these grid cells are untraversable" to an [`ObstacleReport`]
//! (8-connected regions, world-frame cells).
//!
//! The grid is aligned as the cell classifier's is: cell edges lie on
//! whole multiples of the cell size from the vehicle origin, so a cell of
//! one evaluator and the cell classifier's cell of the same size are the
//! same square of ground.

use arcnav_vehicle::Isometry;
use arcnav_vehicle::config::ConfigError;

use crate::config::{GridShape, RegionConfig};
use crate::evaluator::{
    ImageStats, ObstacleCell, ObstacleReport, Reasons, Region, suspected_drop_off,
};
use crate::image::RangeImage;

/// Refuses a `cell`-sized grid over `region` of more than
/// [`crate::config::MAX_GRID_CELLS`] cells (`key`: the cell size's key):
/// its layers are allocated per evaluator, and cell indices are 32-bit.
pub(crate) fn check_size(key: &str, region: &RegionConfig, cell: f64) -> Result<(), ConfigError> {
    let grid = GridShape::over(region, cell, 0);
    let cells = grid.cols as f64 * grid.rows as f64;
    let max = crate::config::MAX_GRID_CELLS;
    if cells > max as f64 {
        return Err(ConfigError::new(
            key,
            format!(
                "{cell} m cells over the region need a {} x {} grid; at most {max} cells: \
                 use larger cells or a smaller region",
                grid.cols, grid.rows
            ),
        ));
    }
    Ok(())
}

impl GridShape {
    /// The grid over `region` with `cell`-sized cells and `margin` empty
    /// cells along each edge.
    pub(crate) fn over(region: &RegionConfig, cell: f64, margin: usize) -> Self {
        let cells = |metres: f64| (metres / cell).ceil().max(0.0) as usize;
        let (behind, right) = (
            cells(region.behind_m) + margin,
            cells(region.half_width_m) + margin,
        );
        GridShape {
            cols: behind + cells(region.ahead_m) + margin,
            rows: 2 * right,
            corner: [behind as f32, right as f32],
            margin,
        }
    }

    /// The cell holding level-frame (x, y), when it lies at least `margin`
    /// cells inside the grid.
    #[inline]
    pub(crate) fn index(&self, cell: f32, x: f32, y: f32) -> Option<usize> {
        // Cell coordinates from the grid's corner; only those at least
        // `margin` cells in are taken, so they are positive and truncating
        // is flooring (no libm call per point).
        let (fx, fy) = (x / cell + self.corner[0], y / cell + self.corner[1]);
        let m = self.margin as f32;
        if !(fx >= m && fy >= m && fx < (self.cols - self.margin) as f32)
            || fy >= (self.rows - self.margin) as f32
        {
            return None;
        }
        Some(fy as usize * self.cols + fx as usize)
    }

    /// Level-frame centre of cell `index`.
    #[inline]
    pub(crate) fn centre(&self, cell: f32, index: usize) -> [f32; 2] {
        let (ix, iy) = (index % self.cols, index / self.cols);
        [
            (ix as f32 + 0.5 - self.corner[0]) * cell,
            (iy as f32 + 0.5 - self.corner[1]) * cell,
        ]
    }
}

/// The cell of a grid layer (`cols × rows` cells of `cell` from its corner
/// at level-frame `origin`) holding level-frame (x, y): how the evaluators'
/// published maps are looked up.
pub(crate) fn layer_index(
    origin: [f32; 2],
    cell: f32,
    (cols, rows): (usize, usize),
    x: f32,
    y: f32,
) -> Option<usize> {
    let (i, j) = (
        ((x - origin[0]) / cell).floor(),
        ((y - origin[1]) / cell).floor(),
    );
    (i >= 0.0 && j >= 0.0 && (i as usize) < cols && (j as usize) < rows)
        .then(|| j as usize * cols + i as usize)
}

/// One valid return, in the level frame of the capture pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Point {
    pub xyz: [f32; 3],
    pub row: u32,
    pub col: u32,
}

/// What [`Projector::for_each_cell`] projects: the image, its (filtered)
/// ranges, the level frame's sensor pose, the ranges kept, and the grid
/// with its cell size.
type CellArgs<'a> = (
    &'a RangeImage,
    &'a [f32],
    &'a Isometry,
    (f32, f32),
    (&'a GridShape, f32),
);

/// Per-image beam trigonometry and the projection of valid returns.
#[derive(Debug, Default)]
pub(crate) struct Projector {
    cos_el: Vec<f32>,
    sin_el: Vec<f32>,
    /// Per column: the rotated horizontal beam direction, x, y and z.
    cos_az: Vec<f32>,
    sin_az: Vec<f32>,
    up: Vec<f32>,
    /// [`Projector::for_each_cell`]'s row: each return's cell (`u32::MAX`:
    /// none) and level-frame z.
    row_cells: Vec<u32>,
    row_z: Vec<f32>,
    /// A row's runs (cell, highest, lowest), for the AVX2 hand-over.
    runs: Vec<(u32, f32, f32)>,
    /// [`Projector::for_each_row`]'s row.
    row_points: RowPoints,
}

/// What [`Projector::project_row`] needs of an image beyond its rows: the
/// sensor's position in the level frame, and the sensor's vertical there.
pub(crate) struct RowStart {
    translation: [f32; 3],
    vertical: [f32; 3],
}

/// One row of an image projected into the level frame, by column.
#[derive(Debug, Default)]
pub(crate) struct RowPoints {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    /// A return within the ranges kept.
    pub used: Vec<bool>,
}

impl RowPoints {
    fn resize(&mut self, cols: usize) {
        self.x.resize(cols, 0.0);
        self.y.resize(cols, 0.0);
        self.z.resize(cols, 0.0);
        self.used.resize(cols, false);
    }
}

/// The level frame of `world_from_vehicle` and where `image`'s sensor
/// stands in it.
pub(crate) fn level_frames(
    image: &RangeImage,
    world_from_vehicle: &Isometry,
) -> (Isometry, Isometry) {
    let world_from_level = arcnav_vehicle::frames::level_frame(world_from_vehicle);
    let level_from_sensor =
        world_from_level.inverse() * world_from_vehicle * image.vehicle_from_sensor;
    (world_from_level, level_from_sensor)
}

impl Projector {
    /// Projects every return of `ranges` (an image of `image`'s beam
    /// table, possibly filtered) with a range in `[min_range, max_range]`
    /// into the level frame, appending to `out`, and counts what it skips.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn project(
        &mut self,
        image: &RangeImage,
        ranges: &[f32],
        level_from_sensor: &Isometry,
        min_range: f32,
        max_range: f32,
        out: &mut Vec<Point>,
        stats: &mut ImageStats,
    ) {
        self.for_each_row(
            image,
            ranges,
            level_from_sensor,
            (min_range, max_range),
            stats,
            |row, points| {
                for (col, &used) in points.used.iter().enumerate() {
                    if used {
                        out.push(Point {
                            xyz: [points.x[col], points.y[col], points.z[col]],
                            row: row as u32,
                            col: col as u32,
                        });
                    }
                }
            },
        );
    }

    /// Every return of `image` projected into the level frame, a row at a
    /// time: `each_row(row, points)` gets every column's point, with
    /// whether it is a return in range (`points.used`; the others'
    /// coordinates are meaningless). Beam directions are separable, so per
    /// image one rotated 3-vector per column and the elevation's cosine and
    /// sine per row are computed: a point costs six multiplications, with
    /// no branch (it vectorises, for a caller whose own work on a row does
    /// too). A caller whose work on a row is to run with AVX2 loops over
    /// the rows itself ([`Projector::prepare`], [`Projector::project_row`]):
    /// a closure's body may be left out of line, without the features.
    pub(crate) fn for_each_row(
        &mut self,
        image: &RangeImage,
        ranges: &[f32],
        level_from_sensor: &Isometry,
        kept: (f32, f32),
        stats: &mut ImageStats,
        mut each_row: impl FnMut(usize, &RowPoints),
    ) {
        let start = self.prepare(image, level_from_sensor);
        let cols = image.cols();
        let mut points = std::mem::take(&mut self.row_points);
        for row in 0..self.cos_el.len() {
            let line = &ranges[row * cols..(row + 1) * cols];
            self.project_row(&start, row, line, kept, &mut points, stats);
            each_row(row, &points);
        }
        self.row_points = points;
    }

    /// Row `row` of the image [`Projector::prepare`] readied, its ranges
    /// `line`, projected into `points` (see [`Projector::for_each_row`]),
    /// counting the returns it skips in `stats`.
    #[inline(always)]
    pub(crate) fn project_row(
        &self,
        start: &RowStart,
        row: usize,
        line: &[f32],
        kept: (f32, f32),
        points: &mut RowPoints,
        stats: &mut ImageStats,
    ) {
        self.project_columns(start, row, (line, 0), kept, points, stats);
    }

    /// Columns `first..first + ranges.len()` of row `row`, their ranges
    /// `ranges`, projected into `points` (its column 0 the image's
    /// `first`), as [`Projector::project_row`] projects a whole row.
    #[inline(always)]
    pub(crate) fn project_columns(
        &self,
        &RowStart {
            translation: t,
            vertical,
        }: &RowStart,
        row: usize,
        (line, first): (&[f32], usize),
        kept: (f32, f32),
        points: &mut RowPoints,
        stats: &mut ImageStats,
    ) {
        let (ce, se) = (self.cos_el[row], self.sin_el[row]);
        let v = [se * vertical[0], se * vertical[1], se * vertical[2]];
        points.resize(line.len());
        let (mut no_return, mut out_of_range) = (0u32, 0u32);
        let beams = self.cos_az[first..]
            .iter()
            .zip(&self.sin_az[first..])
            .zip(&self.up[first..]);
        let RowPoints { x, y, z, used } = points;
        for (((((&range, ((&ca, &sa), &up)), x), y), z), used) in line
            .iter()
            .zip(beams)
            .zip(x.iter_mut())
            .zip(y.iter_mut())
            .zip(z.iter_mut())
            .zip(used.iter_mut())
        {
            let (returned, in_range, point) = beam_point(range, kept, ce, (ca, sa, up), v, t);
            no_return += u32::from(!returned);
            out_of_range += u32::from(returned && !in_range);
            [*x, *y, *z] = point;
            *used = returned && in_range;
        }
        stats.no_return += no_return;
        stats.out_of_range += out_of_range;
    }

    /// [`Projector::for_each_row`] binned into `grid` of `cell`-sized cells,
    /// keeping each cell's highest and lowest level-frame z: `each` gets
    /// the cell (as [`GridShape::index`] finds it, the same arithmetic)
    /// with the highest and lowest z of a run of neighbouring returns in
    /// range that fall inside it, every return in exactly one run. A row
    /// at a time, in two passes: every column's point and cell first, with
    /// no branch (it vectorises: the divisions by the cell size are most of
    /// a point's cost), then the hand-over of each run of columns in one
    /// cell (near the sensor a cell holds many returns of a row: one
    /// scattered update per run instead of per return).
    /// With AVX2 where the processor has it (as [`crate::cells`] bins):
    /// the same arithmetic (no fused multiply-add), so the same cells.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn for_each_cell(
        &mut self,
        image: &RangeImage,
        ranges: &[f32],
        level_from_sensor: &Isometry,
        ranges_kept: (f32, f32),
        grid: (&GridShape, f32),
        stats: &mut ImageStats,
        each: impl FnMut(usize, f32, f32),
    ) {
        let args = (image, ranges, level_from_sensor, ranges_kept, grid);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.for_each_cell_avx2(args, stats, each) };
        }
        self.for_each_cell_portable::<false>(args, stats, each);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn for_each_cell_avx2(
        &mut self,
        args: CellArgs<'_>,
        stats: &mut ImageStats,
        each: impl FnMut(usize, f32, f32),
    ) {
        self.for_each_cell_portable::<true>(args, stats, each);
    }

    /// `AVX2`: whether the caller is compiled for AVX2 (and so may hand
    /// runs over with [`hand_over_runs_avx2`]).
    #[inline(always)]
    fn for_each_cell_portable<const AVX2: bool>(
        &mut self,
        (image, ranges, level_from_sensor, (min_range, max_range), (grid, cell)): CellArgs<'_>,
        stats: &mut ImageStats,
        mut each: impl FnMut(usize, f32, f32),
    ) {
        let RowStart {
            translation: [tx, ty, tz],
            vertical,
        } = self.prepare(image, level_from_sensor);
        let cols = image.cols();
        let m = grid.margin as f32;
        let (x_end, y_end) = (
            (grid.cols - grid.margin) as f32,
            (grid.rows - grid.margin) as f32,
        );
        let [cx, cy] = grid.corner;
        let width = grid.cols as i32;
        let (mut no_return, mut out_of_range) = (0u32, 0u32);
        let (row_cells, row_z) = (&mut self.row_cells, &mut self.row_z);
        row_cells.resize(cols, u32::MAX);
        row_z.resize(cols, 0.0);
        for (row, (&ce, &se)) in self.cos_el.iter().zip(&self.sin_el).enumerate() {
            let line = &ranges[row * cols..(row + 1) * cols];
            let (vx, vy, vz) = (se * vertical[0], se * vertical[1], se * vertical[2]);
            let beams = self.cos_az.iter().zip(&self.sin_az).zip(&self.up);
            for (((&range, ((&ca, &sa), &up)), index), z) in line
                .iter()
                .zip(beams)
                .zip(row_cells.iter_mut())
                .zip(row_z.iter_mut())
            {
                let (returned, in_range, [x, y, point_z]) = beam_point(
                    range,
                    (min_range, max_range),
                    ce,
                    (ca, sa, up),
                    [vx, vy, vz],
                    [tx, ty, tz],
                );
                no_return += u32::from(!returned);
                out_of_range += u32::from(returned && !in_range);
                *z = point_z;
                let (fx, fy) = (x / cell + cx, y / cell + cy);
                let used = returned && in_range && fx >= m && fy >= m && fx < x_end && fy < y_end;
                // Truncating the cell coordinates of a point outside is
                // avoided by selecting 0 first; inside they are whole
                // numbers of cells below 2^24, so the unchecked conversion
                // is exact (and, unlike `as`, vectorises).
                let (fx, fy) = if used { (fx, fy) } else { (0.0, 0.0) };
                // SAFETY: fx and fy are 0 or within [margin, cols) and
                // [margin, rows): finite and representable as i32.
                let (ix, iy) =
                    unsafe { (fx.to_int_unchecked::<i32>(), fy.to_int_unchecked::<i32>()) };
                let cell_index = (iy * width + ix) as u32;
                *index = if used { cell_index } else { u32::MAX };
            }
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // SAFETY: AVX2 is set only where the processor has AVX2.
                unsafe { hand_over_runs_avx2(row_cells, row_z, &mut self.runs, &mut each) };
                continue;
            }
            hand_over_runs(row_cells, row_z, 0, None, &mut each);
        }
        stats.no_return += no_return;
        stats.out_of_range += out_of_range;
    }

    /// Readies [`Projector::project_row`] for `image` seen from
    /// Per column of the image [`Projector::prepare`] readied, the x
    /// (forward) part of its beams' horizontal direction in the level
    /// frame.
    pub(crate) fn forward(&self) -> &[f32] {
        &self.cos_az
    }

    /// `level_from_sensor`: per row the elevation's cosine and sine, per
    /// column the rotated horizontal direction; the sensor's position and
    /// the rotated vertical.
    pub(crate) fn prepare(&mut self, image: &RangeImage, level_from_sensor: &Isometry) -> RowStart {
        let beams = &image.beams;
        let m = level_from_sensor.rotation.to_rotation_matrix();
        let m = m.matrix();
        let r = |i: usize, j: usize| m[(i, j)] as f32;
        // Per row: cos and sin of the elevation. Per column: the rotated
        // horizontal direction R·(cos az, sin az, 0), one array per axis.
        self.cos_el.clear();
        self.sin_el.clear();
        for &el in &beams.elevation {
            let (s, c) = el.sin_cos();
            self.sin_el.push(s);
            self.cos_el.push(c);
        }
        self.cos_az.clear();
        self.sin_az.clear();
        self.up.clear();
        for &az in &beams.azimuth {
            let (sa, ca) = az.sin_cos();
            self.cos_az.push(r(0, 0) * ca + r(0, 1) * sa);
            self.sin_az.push(r(1, 0) * ca + r(1, 1) * sa);
            self.up.push(r(2, 0) * ca + r(2, 1) * sa);
        }
        let vertical = [r(0, 2), r(1, 2), r(2, 2)];
        let t = level_from_sensor.translation.vector;
        RowStart {
            translation: [t.x as f32, t.y as f32, t.z as f32],
            vertical,
        }
    }
}

/// One beam's return in the level frame: whether it returned, whether it
/// lies within the ranges `kept`, and its point, from the row's elevation
/// cosine `ce`, the column's rotated horizontal direction `(ca, sa, up)`,
/// the row's share of the rotated vertical `v` and the sensor's position
/// `t`. Every projection here does this arithmetic, so a return is the
/// same point whichever projects it.
#[inline(always)]
fn beam_point(
    range: f32,
    kept: (f32, f32),
    ce: f32,
    (ca, sa, up): (f32, f32, f32),
    v: [f32; 3],
    t: [f32; 3],
) -> (bool, bool, [f32; 3]) {
    let returned = range.is_finite() && range > 0.0;
    let in_range = range >= kept.0 && range <= kept.1;
    let point = [
        (ce * ca + v[0]) * range + t[0],
        (ce * sa + v[1]) * range + t[1],
        (ce * up + v[2]) * range + t[2],
    ];
    (returned, in_range, point)
}

/// Hands `each` every run of neighbouring returns of a row in one cell:
/// the cell, the run's highest and lowest z (finite). Starts at column
/// `from`, continuing `open`: the run (cell, highest, lowest) that the
/// columns before `from` left unfinished, if any. Cells `u32::MAX` (no
/// return in the grid) form no run.
#[inline(always)]
fn hand_over_runs(
    cells: &[u32],
    z: &[f32],
    from: usize,
    open: Option<(u32, f32, f32)>,
    each: &mut impl FnMut(usize, f32, f32),
) {
    let (mut run, mut highest, mut lowest) = open.unwrap_or((u32::MAX, f32::NAN, f32::NAN));
    for (&index, &z) in cells[from..].iter().zip(&z[from..]) {
        if index == run {
            // z is finite: plain comparisons.
            highest = if z > highest { z } else { highest };
            lowest = if z < lowest { z } else { lowest };
            continue;
        }
        if run != u32::MAX {
            each(run as usize, highest, lowest);
        }
        (run, highest, lowest) = (index, z, z);
    }
    if run != u32::MAX {
        each(run as usize, highest, lowest);
    }
}

/// [`hand_over_runs`] eight returns at a time: within each eight, a
/// segmented scan (three steps of 1, 2 and 4 lanes, each lane combining
/// with the one that far back while both lie in one run) gives every lane
/// the highest and lowest of its run so far; the leading lanes that
/// continue the eight before take its last lane's too; the lanes that end
/// a run are kept in `runs` (every lane written, the count advanced by the
/// ends: a fixed number of steps) and handed over at the row's end, in
/// order. The same runs, values and order as
/// [`hand_over_runs`] (max and min are exact), without its dependency from
/// one return to the next.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn hand_over_runs_avx2(
    cells: &[u32],
    z: &[f32],
    runs: &mut Vec<(u32, f32, f32)>,
    each: &mut impl FnMut(usize, f32, f32),
) {
    use std::arch::x86_64::*;
    let n = cells.len().min(z.len());
    // Blocks of eight with a ninth column after them (whether the eighth
    // ends its run); the rest goes to the scalar hand-over.
    let blocks = n.saturating_sub(1) / 8;
    if blocks == 0 {
        return hand_over_runs(cells, z, 0, None, each);
    }
    let (mut carry_high, mut carry_low) = (f32::NEG_INFINITY, f32::INFINITY);
    let mut ended_last = true;
    let (mut highs, mut lows) = ([0f32; 8], [0f32; 8]);
    runs.resize(8 * blocks + 8, (0, 0.0, 0.0));
    let mut kept = 0;
    // SAFETY (whole block): every load reads lanes c - 1 ..= c + 8 with
    // 8 <= c + 8 < n for c >= 8, and lanes 0 ..= 8 < n for c = 0.
    unsafe {
        let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let from = |d: i32| _mm256_cmpgt_epi32(lane, _mm256_set1_epi32(d - 1));
        let back = |d: i32| {
            _mm256_max_epi32(
                _mm256_sub_epi32(lane, _mm256_set1_epi32(d)),
                _mm256_setzero_si256(),
            )
        };
        let (from1, from2, from4) = (from(1), from(2), from(4));
        let (back1, back2, back4) = (back(1), back(2), back(4));
        for c in (0..blocks).map(|b| 8 * b) {
            let here = _mm256_loadu_si256(cells.as_ptr().add(c).cast());
            let next = _mm256_loadu_si256(cells.as_ptr().add(c + 1).cast());
            // Lane i continues lane i - 1's run (lane 0: the block before's
            // last, with a neutral carry at the row's start).
            let before = if c == 0 {
                _mm256_permutevar8x32_epi32(here, back1)
            } else {
                _mm256_loadu_si256(cells.as_ptr().add(c - 1).cast())
            };
            let same1 = _mm256_cmpeq_epi32(here, before);
            let (mut high, mut low) = (
                _mm256_loadu_ps(z.as_ptr().add(c)),
                _mm256_loadu_ps(z.as_ptr().add(c)),
            );
            // Runs within the block: lane i combines with lane i - d where
            // lanes i - d ..= i share a run.
            let mut joined = same1;
            for (back_d, from_d) in [(back1, from1), (back2, from2), (back4, from4)] {
                let take = _mm256_castsi256_ps(_mm256_and_si256(joined, from_d));
                let (h, l) = (
                    _mm256_permutevar8x32_ps(high, back_d),
                    _mm256_permutevar8x32_ps(low, back_d),
                );
                high = _mm256_blendv_ps(high, _mm256_max_ps(high, h), take);
                low = _mm256_blendv_ps(low, _mm256_min_ps(low, l), take);
                joined = _mm256_and_si256(joined, _mm256_permutevar8x32_epi32(joined, back_d));
            }
            // The leading lanes of the run the block before left open.
            let continuing =
                (!(_mm256_movemask_ps(_mm256_castsi256_ps(same1)) as u32)).trailing_zeros();
            let lead = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                _mm256_set1_epi32(continuing as i32),
                lane,
            ));
            high = _mm256_blendv_ps(high, _mm256_max_ps(high, _mm256_set1_ps(carry_high)), lead);
            low = _mm256_blendv_ps(low, _mm256_min_ps(low, _mm256_set1_ps(carry_low)), lead);
            // Lanes that end a run in the grid.
            let ends = _mm256_andnot_si256(
                _mm256_or_si256(
                    _mm256_cmpeq_epi32(here, next),
                    _mm256_cmpeq_epi32(here, _mm256_set1_epi32(-1)),
                ),
                _mm256_set1_epi32(-1),
            );
            let bits = _mm256_movemask_ps(_mm256_castsi256_ps(ends)) as u32;
            _mm256_storeu_ps(highs.as_mut_ptr(), high);
            _mm256_storeu_ps(lows.as_mut_ptr(), low);
            // Every lane is written, the ends kept: a fixed count of steps
            // (how many of eight end a run is a coin toss on noisy ground).
            for i in 0..8 {
                runs[kept] = (cells[c + i], highs[i], lows[i]);
                kept += ((bits >> i) & 1) as usize;
            }
            (carry_high, carry_low) = (highs[7], lows[7]);
            ended_last = cells[c + 7] != cells[c + 8];
        }
    }
    for &(cell, high, low) in &runs[..kept] {
        each(cell as usize, high, low);
    }
    let from = 8 * blocks;
    let open = (!ended_last).then(|| (cells[from - 1], carry_high, carry_low));
    hand_over_runs(cells, z, from, open, each);
}

/// An untraversable grid cell, before it becomes an [`ObstacleCell`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Marked {
    pub index: u32,
    pub reasons: Reasons,
    /// 1: untraversable; below: graded ground (no reasons), see
    /// [`ObstacleCell::cost`].
    pub cost: f32,
    /// Level-frame heights of the cell, m.
    pub z_min: f32,
    pub z_max: f32,
}

impl Marked {
    /// Whether the cell is untraversable (cost 1) rather than graded.
    fn is_obstacle(&self) -> bool {
        self.cost >= 1.0
    }
}

/// Groups marked cells into 8-connected regions and writes them to
/// `report` in the world frame. `labels` is scratch of the grid's size
/// (every entry `u32::MAX`), left that way.
#[allow(clippy::too_many_arguments)]
pub(crate) fn emit(
    marked: &mut [Marked],
    grid: &GridShape,
    cell: f32,
    labels: &mut Vec<u32>,
    queue: &mut Vec<usize>,
    world_from_level: &Isometry,
    report: &mut ObstacleReport,
    stats: &mut ImageStats,
) {
    const UNLABELLED: u32 = u32::MAX;
    const MARKED: u32 = u32::MAX - 1;
    labels.resize(grid.cols * grid.rows, UNLABELLED);
    // The same cell may be marked twice (two reasons): merge.
    marked.sort_unstable_by_key(|m| m.index);
    let mut merged = 0;
    for k in 0..marked.len() {
        if merged > 0 && marked[merged - 1].index == marked[k].index {
            let m = marked[k];
            let last = &mut marked[merged - 1];
            // The reasons of the costlier mark: a suspected drop-off adds
            // none to an untraversable cell.
            if m.cost > last.cost {
                last.reasons = m.reasons;
            } else if m.cost == last.cost {
                last.reasons.insert(m.reasons);
            }
            last.cost = last.cost.max(m.cost);
            last.z_min = last.z_min.min(m.z_min);
            last.z_max = last.z_max.max(m.z_max);
        } else {
            marked[merged] = marked[k];
            merged += 1;
        }
    }
    let marked = &marked[..merged];
    for m in marked.iter().filter(|m| m.is_obstacle()) {
        labels[m.index as usize] = MARKED;
    }
    let s = grid.cols as isize;
    let neighbours = [-s - 1, -s, -s + 1, -1, 1, s - 1, s, s + 1];
    queue.clear();
    let regions = &mut report.regions;
    regions.clear();
    for m in marked.iter().filter(|m| m.is_obstacle()) {
        if labels[m.index as usize] != MARKED {
            continue;
        }
        let region = regions.len() as u32;
        regions.push(Region {
            cells: 0,
            reasons: Reasons::NONE,
        });
        labels[m.index as usize] = region;
        queue.push(m.index as usize);
        while let Some(i) = queue.pop() {
            regions[region as usize].cells += 1;
            for offset in neighbours {
                let n = i as isize + offset;
                if let Some(label) = usize::try_from(n).ok().and_then(|n| labels.get_mut(n))
                    && *label == MARKED
                {
                    *label = region;
                    queue.push(n as usize);
                }
            }
        }
    }
    // Graded ground (cost below 1) is no obstacle: one region of its own,
    // after the untraversable ones, with no reasons.
    let graded_region = regions.len() as u32;
    if marked.iter().any(|m| !m.is_obstacle()) {
        regions.push(Region {
            cells: 0,
            reasons: Reasons::NONE,
        });
    }
    let (sin, cos) = arcnav_vehicle::frames::yaw_of(world_from_level).sin_cos();
    let origin = world_from_level.translation.vector;
    for m in marked {
        let region = if m.is_obstacle() {
            let region = labels[m.index as usize];
            labels[m.index as usize] = UNLABELLED;
            region
        } else {
            regions[graded_region as usize].cells += 1;
            graded_region
        };
        regions[region as usize].reasons.insert(m.reasons);
        let [cx, cy] = grid.centre(cell, m.index as usize).map(f64::from);
        report.cells.push(ObstacleCell {
            x: origin.x + cos * cx - sin * cy,
            y: origin.y + sin * cx + cos * cy,
            z_min: m.z_min + origin.z as f32,
            z_max: m.z_max + origin.z as f32,
            reasons: m.reasons,
            region,
            cost: m.cost.min(1.0),
        });
        if !m.is_obstacle() {
            stats.graded += 1;
            stats.suspected += u32::from(suspected_drop_off(m.cost, m.reasons));
            continue;
        }
        stats.untraversable += 1;
        for (count, (reason, _)) in stats.by_reason.iter_mut().zip(Reasons::ALL) {
            *count += u32::from(m.reasons.contains(reason));
        }
    }
    stats.regions = report.regions.len() as u32;
}

/// What every grid evaluator reports besides its own judgement, found by
/// the cell classifier with its criteria (a)-(c) switched off: the
/// observed footprint, its shadows and the drop-offs (the near edges of
/// ground the image did not see, which no judgement of the ground that
/// was seen can find).
pub(crate) struct SeenGround {
    classifier: crate::CellClassifier,
    report: ObstacleReport,
}

impl SeenGround {
    /// Over `config`'s region and drop-off rule, with `cell`-sized cells.
    pub(crate) fn new(config: &crate::PerceptionConfig, cell: f64) -> Self {
        let mut config = config.clone();
        let c = &mut config.cells;
        c.cell_size_m = cell;
        c.max_height_variation_m = f64::INFINITY;
        c.max_discontinuity_m = f64::INFINITY;
        c.max_slope_deg = 90.0;
        c.slope_window_cells = 1;
        Self {
            classifier: crate::CellClassifier::new(&config),
            report: ObstacleReport::default(),
        }
    }

    /// Evaluates `image` into `report` (cleared first): footprint, shadows,
    /// the pixel counts in `stats`, and the drop-off cells left for
    /// [`SeenGround::drop_offs`].
    pub(crate) fn evaluate(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        runner: &dyn crate::Runner,
        report: &mut ObstacleReport,
    ) -> Result<ImageStats, crate::PerceptionError> {
        use crate::TerrainEvaluator;
        let stats =
            self.classifier
                .evaluate_with(image, world_from_vehicle, &mut self.report, runner)?;
        report.clear();
        report.utime = self.report.utime;
        report.sensor.push_str(&self.report.sensor);
        report.cell_size_m = self.report.cell_size_m;
        // Field by field: a derived `clone_from` would allocate anew.
        report.fov.vertices.clone_from(&self.report.fov.vertices);
        report.shadows.origin = self.report.shadows.origin;
        report
            .shadows
            .sectors
            .clone_from(&self.report.shadows.sectors);
        // What the grid evaluator counts again when it writes its cells
        // (the drop-offs, suspected ones graded, among them): zero here,
        // or they were counted twice.
        Ok(ImageStats {
            cells_evaluated: 0,
            untraversable: 0,
            graded: 0,
            suspected: 0,
            by_reason: [0; Reasons::ALL.len()],
            regions: 0,
            ..stats
        })
    }

    /// The drop-off cells of the last image (suspected ones graded), marked on `grid` (the same
    /// cell size, so the same squares of ground); `world_from_level` is the
    /// level frame of its capture pose.
    pub(crate) fn drop_offs(
        &self,
        grid: &GridShape,
        cell: f32,
        world_from_level: &Isometry,
        marked: &mut Vec<Marked>,
    ) {
        let level_from_world = world_from_level.inverse();
        let z0 = world_from_level.translation.vector.z as f32;
        for c in &self.report.cells {
            let p = level_from_world * nalgebra::Point3::new(c.x, c.y, 0.0);
            if let Some(index) = grid.index(cell, p.x as f32, p.y as f32) {
                marked.push(Marked {
                    index: index as u32,
                    reasons: Reasons::DROP_OFF,
                    // 1, or a suspected drop-off's cost.
                    cost: c.cost,
                    z_min: c.z_min - z0,
                    z_max: c.z_max - z0,
                });
            }
        }
    }
}

/// The report of a grid evaluator: what [`SeenGround`] finds (footprint,
/// shadows, drop-offs) and the cells the evaluator marks on its grid,
/// grouped into regions and written in the world frame.
pub(crate) struct GridReport {
    seen: SeenGround,
    grid: GridShape,
    cell: f32,
    cell_size_m: f64,
    /// The evaluator's untraversable cells of this image.
    pub marked: Vec<Marked>,
    labels: Vec<u32>,
    queue: Vec<usize>,
}

impl GridReport {
    /// Over `perception`'s region, with `cell_size_m` cells.
    pub(crate) fn new(perception: &crate::PerceptionConfig, cell_size_m: f64) -> Self {
        Self {
            seen: SeenGround::new(perception, cell_size_m),
            grid: GridShape::over(&perception.region, cell_size_m, 1),
            cell: cell_size_m as f32,
            cell_size_m,
            marked: Vec::new(),
            labels: Vec::new(),
            queue: Vec::new(),
        }
    }

    /// The grid the evaluator marks cells of.
    pub(crate) fn grid(&self) -> GridShape {
        self.grid
    }

    /// Starts `image`'s report (cleared): footprint, shadows, pixel counts.
    pub(crate) fn start(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        runner: &dyn crate::Runner,
        report: &mut ObstacleReport,
    ) -> Result<ImageStats, crate::PerceptionError> {
        let stats = self
            .seen
            .evaluate(image, world_from_vehicle, runner, report)?;
        report.cell_size_m = self.cell_size_m;
        self.marked.clear();
        Ok(stats)
    }

    /// Adds the drop-offs to the marked cells and writes them all, in
    /// regions, to `report`.
    pub(crate) fn finish(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
        stats: &mut ImageStats,
    ) {
        let (world_from_level, _) = level_frames(image, world_from_vehicle);
        self.seen
            .drop_offs(&self.grid, self.cell, &world_from_level, &mut self.marked);
        emit(
            &mut self.marked,
            &self.grid,
            self.cell,
            &mut self.labels,
            &mut self.queue,
            &world_from_level,
            report,
            stats,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every run [`hand_over_runs`] hands over for a row.
    fn runs(cells: &[u32], z: &[f32], avx2: bool) -> Vec<(usize, u32, u32)> {
        let mut out = Vec::new();
        let mut each = |i: usize, high: f32, low: f32| out.push((i, high.to_bits(), low.to_bits()));
        if avx2 {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: called only where the processor has AVX2.
            unsafe {
                hand_over_runs_avx2(cells, z, &mut Vec::new(), &mut each)
            };
        } else {
            hand_over_runs(cells, z, 0, None, &mut each);
        }
        out
    }

    #[test]
    fn runs_of_a_row_are_its_neighbouring_returns_in_one_cell() {
        // Cells 5, 5, off the grid (NaN z), 7, 5: three runs, the off-grid
        // return in none.
        let cells = [5, 5, u32::MAX, 7, 5];
        let z = [0.5, 0.25, f32::NAN, 1.0, 2.0];
        assert_eq!(
            runs(&cells, &z, false),
            [
                (5, 0.5f32.to_bits(), 0.25f32.to_bits()),
                (7, 1.0f32.to_bits(), 1.0f32.to_bits()),
                (5, 2.0f32.to_bits(), 2.0f32.to_bits()),
            ]
        );
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_scalar_hand_over_the_same_runs() {
        if !crate::avx2_to_test("the AVX2 hand-over") {
            return;
        }
        // Rows of every length up to 70 with runs of 1 to 20 returns
        // (across block boundaries), off-grid returns with NaN heights, and
        // a cell met again after another.
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = |m: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % m
        };
        let mut tested_long = false;
        for round in 0..400 {
            let n = round % 71;
            let (mut cells, mut z) = (Vec::new(), Vec::new());
            while cells.len() < n {
                let length = 1 + next(if round % 2 == 0 { 4 } else { 20 }) as usize;
                let cell = match next(5) {
                    0 => u32::MAX,
                    1 => 3,
                    _ => next(1000) as u32,
                };
                for _ in 0..length.min(n - cells.len()) {
                    cells.push(cell);
                    z.push(if cell == u32::MAX {
                        f32::NAN
                    } else {
                        next(2000) as f32 * 0.01 - 10.0
                    });
                }
                tested_long |= length > 9;
            }
            assert_eq!(runs(&cells, &z, true), runs(&cells, &z, false), "{cells:?}");
        }
        assert!(tested_long);
    }
}
