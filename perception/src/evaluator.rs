//! What every terrain evaluator produces, and the trait they implement.
//!
//! An evaluator turns ONE range image, with the vehicle pose at its capture
//! time, into the untraversable cells of that image (world frame) and the
//! ground footprint the image observed. That is all the local map learns
//! from perception (002 §4–5). The trait assumes nothing about how the cells
//! are found: the paper's per-cell classifier is one implementation; a
//! multi-scale height-difference map (000), a hierarchical PCA (001) or a
//! Kalman elevation map (004, which keeps state across images) fit behind it.

use arcnav_vehicle::{Isometry, Utime};

use crate::fov::FovPolygon;
use crate::image::{ImageError, RangeImage};
use crate::shadow::Shadows;

/// Why a cell is untraversable (a bit set; evaluators may combine reasons).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, PartialOrd, Ord)]
pub struct Reasons(u8);

impl Reasons {
    pub const NONE: Self = Self(0);
    /// The height variation inside the cell is too large (002 §4, criterion a).
    pub const HEIGHT_VARIATION: Self = Self(1);
    /// The plane fitted to the cell is too steep (criterion b).
    pub const SLOPE: Self = Self(2);
    /// The elevation jumps between the cell and a neighbour (criterion c).
    pub const DISCONTINUITY: Self = Self(4);
    /// The near edge of ground the image did not see, wider than the
    /// vehicle bridges, beyond which the ground drops away (a hole, a
    /// trench, a ledge).
    pub const DROP_OFF: Self = Self(8);
    /// The multi-scale height differences of 000 §5.1 add up to an
    /// absolute obstacle (`height_diff`).
    pub const HEIGHT_DIFFERENCE: Self = Self(16);
    /// Not flat even at the smallest region of 001's hierarchical PCA
    /// (`pca`).
    pub const NOT_FLAT: Self = Self(32);
    /// Occupied in the static occupancy map a user gave (001 §3.4); never
    /// set by perception.
    pub const STATIC_MAP: Self = Self(64);
    /// Steeper than the vehicle's slope limit in the local map's fused
    /// elevation layer (a bank's side); never set by perception.
    pub const STEEP: Self = Self(128);
    /// Every reason, with its name, in bit order.
    pub const ALL: [(Self, &'static str); 8] = [
        (Self::HEIGHT_VARIATION, "height variation"),
        (Self::SLOPE, "slope"),
        (Self::DISCONTINUITY, "discontinuity"),
        (Self::DROP_OFF, "drop-off"),
        (Self::HEIGHT_DIFFERENCE, "height difference"),
        (Self::NOT_FLAT, "not flat"),
        (Self::STATIC_MAP, "static map"),
        (Self::STEEP, "steep"),
    ];

    pub const fn bits(self) -> u8 {
        self.0
    }

    pub const fn from_bits(bits: u8) -> Self {
        Self(bits)
    }

    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0 && other.0 != 0
    }

    pub fn insert(&mut self, other: Self) {
        self.0 |= other.0;
    }

    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// Names of the reasons set, e.g. `"height variation+slope"`.
    pub fn names(self) -> String {
        let names: Vec<&str> = Self::ALL
            .iter()
            .filter(|(r, _)| self.contains(*r))
            .map(|(_, n)| *n)
            .collect();
        if names.is_empty() {
            "none".into()
        } else {
            names.join("+")
        }
    }
}

/// One cell perception has an opinion on, world frame: untraversable
/// (`cost` 1, with its reasons) or graded ground (`cost` below 1, no
/// reasons: passable at a price, from evaluators that grade, e.g.
/// `height_diff`'s D̃).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObstacleCell {
    /// Cell centre, world frame, m.
    pub x: f64,
    pub y: f64,
    /// Lowest and highest point seen in the cell, world z, m.
    pub z_min: f32,
    pub z_max: f32,
    pub reasons: Reasons,
    /// Index into [`ObstacleReport::regions`].
    pub region: u32,
    /// In [0, 1]: 1 untraversable, below it how hard the ground is.
    pub cost: f32,
}

impl ObstacleCell {
    /// Whether the vehicle cannot drive here (cost 1).
    pub fn is_obstacle(&self) -> bool {
        self.cost >= 1.0
    }

    /// Whether this is a suspected drop-off (see [`suspected_drop_off`]).
    pub fn is_suspected_drop_off(&self) -> bool {
        suspected_drop_off(self.cost, self.reasons)
    }
}

/// Whether ground of `cost` with `reasons` is a suspected drop-off: graded
/// (cost below 1) with the reason drop-off, a hole's edge seen from too far
/// to show its depth (see `[perception.drop_off] suspect_cost`). The one
/// definition behind cells, the local map's patches and the pictures.
pub fn suspected_drop_off(cost: f32, reasons: Reasons) -> bool {
    cost < 1.0 && reasons.contains(Reasons::DROP_OFF)
}

/// A connected group of untraversable cells of one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Number of cells.
    pub cells: u32,
    /// Union of the cells' reasons.
    pub reasons: Reasons,
}

/// Everything perception reports about one image.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObstacleReport {
    /// Capture time of the image (the start of the frame; every report of
    /// a streamed frame carries it).
    pub utime: Utime,
    /// When the last return the report rests on was acquired: the end of
    /// the slice for a streamed frame (see [`crate::stream`]); for a whole
    /// image, its capture time (0 = `utime`).
    pub acquired: Utime,
    pub sensor: String,
    pub cell_size_m: f64,
    pub cells: Vec<ObstacleCell>,
    pub regions: Vec<Region>,
    /// The ground the image actually observed, world frame.
    pub fov: FovPolygon,
    /// The parts of `fov` the image did not see: beyond edges, out of
    /// sight (empty when the evaluator does not tell).
    pub shadows: Shadows,
    /// Height measurements for the local map's elevation layer (004 §III),
    /// one per world-aligned cell the image hit; filled after the
    /// evaluator by the perception node (see [`crate::HeightSampler`]).
    pub heights: Vec<HeightSample>,
    /// The side of the world-aligned cells `heights` index, m.
    pub heights_cell_m: f64,
}

impl ObstacleReport {
    /// Empties the report, keeping its allocations.
    pub fn clear(&mut self) {
        self.utime = 0;
        self.acquired = 0;
        self.sensor.clear();
        self.cells.clear();
        self.regions.clear();
        self.fov.vertices.clear();
        self.shadows.clear();
        self.heights.clear();
    }
}

/// Counts of one evaluation. Evaluators never read a clock; executors time them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImageStats {
    pub pixels: u32,
    /// Returns projected and binned.
    pub valid_points: u32,
    /// Pixels without a return (0, negative, NaN, infinite).
    pub no_return: u32,
    /// Returns closer than `min_range_m` or beyond `max_range_m`.
    pub out_of_range: u32,
    /// Returns outside the evaluated region (`[perception.region]`).
    pub outside_grid: u32,
    /// Cells holding at least one point.
    pub cells_evaluated: u32,
    /// Cells reported as graded ground (cost below 1).
    pub graded: u32,
    /// Of those, suspected drop-offs (reason drop-off).
    pub suspected: u32,
    /// Cells classified untraversable.
    pub untraversable: u32,
    /// Untraversable cells per reason, in [`Reasons::ALL`] order (a cell
    /// with two reasons counts in both).
    pub by_reason: [u32; Reasons::ALL.len()],
    pub regions: u32,
    /// Returns removed as outliers before evaluation (by evaluators that
    /// filter the image, e.g. 000's median filter).
    pub outliers: u32,
}

impl ImageStats {
    /// Adds `other`'s counts to these (saturating: a long mission's totals
    /// of a 128×2048 lidar at 10 Hz pass 2³² pixels in 27 minutes).
    pub fn accumulate(&mut self, other: &ImageStats) {
        let add = |a: &mut u32, b: u32| *a = a.saturating_add(b);
        add(&mut self.pixels, other.pixels);
        add(&mut self.valid_points, other.valid_points);
        add(&mut self.no_return, other.no_return);
        add(&mut self.out_of_range, other.out_of_range);
        add(&mut self.outside_grid, other.outside_grid);
        add(&mut self.cells_evaluated, other.cells_evaluated);
        add(&mut self.untraversable, other.untraversable);
        add(&mut self.graded, other.graded);
        add(&mut self.suspected, other.suspected);
        for (a, b) in self.by_reason.iter_mut().zip(other.by_reason) {
            add(a, b);
        }
        add(&mut self.regions, other.regions);
        add(&mut self.outliers, other.outliers);
    }
}

/// Why an image could not be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PerceptionError {
    #[error(transparent)]
    Image(#[from] ImageError),
}

/// Runs the independent pieces of one evaluation, possibly at the same time.
/// Perception never starts threads: an executor that has threads to spare
/// passes a runner that uses them. Results never depend on the runner.
pub trait Runner: Sync {
    /// Runs every task once; returns when all are done.
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]);
}

/// Runs the tasks one after the other, on the calling thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct InOrder;

impl Runner for InOrder {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        for task in tasks {
            task();
        }
    }
}

/// A thread pool runs the first task on the calling thread and the others
/// on its threads, and returns when all are done.
impl Runner for rayon::ThreadPool {
    fn run(&self, tasks: &mut [&mut (dyn FnMut() + Send)]) {
        self.in_place_scope(|scope| {
            let (first, rest) = tasks.split_at_mut(1);
            for task in rest {
                scope.spawn(move |_| task());
            }
            first.iter_mut().for_each(|task| task());
        });
    }
}

/// A per-image terrain evaluator.
pub trait TerrainEvaluator: Send {
    /// Short name, as in the configuration.
    fn name(&self) -> &'static str;

    /// Evaluates `image`, taken with the vehicle at `world_from_vehicle` (the
    /// pose at capture time), into `report` (cleared first), handing
    /// independent pieces of the work to `runner` (which may run them at
    /// the same time; an evaluator that does not split its work ignores
    /// it). The result does not depend on the runner. Allocates nothing
    /// once warmed up to the image size.
    fn evaluate_with(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
        runner: &dyn Runner,
    ) -> Result<ImageStats, PerceptionError>;

    /// [`TerrainEvaluator::evaluate_with`], every piece of the work done
    /// here, in order ([`InOrder`]).
    fn evaluate(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
    ) -> Result<ImageStats, PerceptionError> {
        self.evaluate_with(image, world_from_vehicle, report, &InOrder)
    }

    /// Evaluates images of several sensors captured close together
    /// (`perception.fuse_within_s`), each with the vehicle pose at its own
    /// capture, into one report per image (`reports[k]` for `images[k]`,
    /// which must be as many); returns each image's counts, or why it was
    /// refused (the others are evaluated all the same). An evaluator that
    /// builds a height map puts them all into one (000 §4.1's eight
    /// cameras) and reports each cell with the image its height came from,
    /// so that the local map keeps and prunes every sensor's cells as
    /// before. The default judges each image on its own.
    fn evaluate_fused(
        &mut self,
        images: &[(&RangeImage, &Isometry)],
        reports: &mut [ObstacleReport],
        runner: &dyn Runner,
    ) -> Vec<Result<ImageStats, PerceptionError>> {
        evaluate_each(self, images, reports, runner)
    }

    /// Forgets anything carried between images (for evaluators that fuse).
    fn reset(&mut self) {}

    /// How far from a cell's centre the returns that decide its verdict
    /// may lie. Streaming perception ([`crate::stream`]) reports a cell
    /// once every return within it has arrived, so an evaluator must not
    /// understate it; the default is generous (3 m, 8 pixels).
    fn support(&self) -> Support {
        Support {
            metres: 3.0,
            pixels: 8,
            radians: 0.0,
        }
    }

    /// Whether this evaluator judges each image on its own (002 §4's early
    /// traversability evaluation). One that fuses images (a Kalman
    /// elevation map) must say false: a streamed frame is evaluated in
    /// overlapping parts, which it would fuse again and again.
    fn judges_each_image_alone(&self) -> bool {
        true
    }
}

/// Each of `images` judged on its own by `evaluator` (what
/// [`TerrainEvaluator::evaluate_fused`] does unless an evaluator fuses).
pub fn evaluate_each<E: TerrainEvaluator + ?Sized>(
    evaluator: &mut E,
    images: &[(&RangeImage, &Isometry)],
    reports: &mut [ObstacleReport],
    runner: &dyn Runner,
) -> Vec<Result<ImageStats, PerceptionError>> {
    (images.iter().zip(reports))
        .map(|((image, pose), report)| evaluator.evaluate_with(image, pose, report, runner))
        .collect()
}

/// Time of the last return a report rests on.
impl ObstacleReport {
    pub fn acquired_utime(&self) -> Utime {
        if self.acquired == 0 {
            self.utime
        } else {
            self.acquired
        }
    }
}

/// How far from a cell's centre the returns that decide its verdict may
/// lie: within `metres` horizontally, and beyond that the reach of an
/// image-space filter (000's median, 001's scan-line roughness), `pixels`
/// plus `radians` of beam angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Support {
    pub metres: f64,
    pub pixels: u32,
    pub radians: f64,
}

/// One height measurement: the highest return of one image in one
/// world-aligned cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeightSample {
    /// World cell index: the cell spans [i·s, (i+1)·s) × [j·s, (j+1)·s).
    pub i: i64,
    pub j: i64,
    /// h_t, world z, m.
    pub z: f32,
    /// σ_t², m².
    pub variance: f32,
}
