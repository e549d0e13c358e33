//! Streaming perception, 002 §7's integrated mode: "process the image one
//! scan line at a time and report obstacles as soon as they are detected".
//!
//! A range image may arrive in [`RangeSlice`]s — blocks of columns from a
//! rotating lidar (an Ouster sends 16 per packet), blocks of rows from a
//! scanning sensor like the ERIM. A [`FrameStream`] assembles the slices of
//! one sensor's frame and, as they arrive, has any [`TerrainEvaluator`]
//! judge the part received so far; of what it reports it passes on the
//! cells whose verdict can no longer change, once each, at once.
//!
//! **When a cell's verdict is final.** An evaluator decides a cell from the
//! returns within its [`Support`] of the cell's centre (horizontally, plus
//! some pixels of image filters). In the sensor frame (where a return's
//! azimuth is its column's azimuth, whatever the pose), a cell at
//! horizontal distance `d` and azimuth `φ` takes returns from the columns
//! within `w = asin(R / d)` of `φ`, `R` its support radius. It is
//! *complete* when every return that could land in that disc has arrived:
//!
//! - blocks of columns, sweeping in azimuth: the disc's columns lie within
//!   the swept angles the evaluated window holds;
//! - blocks of rows, highest beam first (far ground first): a lower beam
//!   of the same column meets a height field no farther than a higher one,
//!   so in each column of the disc every return still to come lies nearer
//!   than the cell (`d − R` beyond the nearest return so far); lowest beam
//!   first, mirrored. Rows in no order: nothing is final before the frame is.
//!   A step evaluates the rows since the last one and the older rows within
//!   reach of its final distances (rows acquired long apart are not judged
//!   together).
//!
//! **Where the vehicle was.** A frame's lines are acquired over its whole
//! period (a 10 Hz lidar's over 100 ms, the ERIM's over 0.5 s). Each
//! evaluation places its returns with the pose at the middle of its lines'
//! acquisition, and each cell it reports is then moved to where the
//! vehicle was when its column (or the row of its nearest return) was
//! acquired: at 10 m/s a 360° frame placed with one pose puts a post up to
//! 0.76 m off, streamed 0.24 m (the near-face bias a standing sensor has).
//!
//! **Each cell once, none lost.** Different steps place the same return
//! with different poses, so their cells differ by up to one cell diagonal
//! `m`. A step reports the cells complete now whose disc grown by `m` was
//! not complete in the previous step; the frame's last evaluation (the
//! whole image) reports the cells whose grown disc was complete in no step.
//! A return whose cell is complete at step k is then reported at the first
//! such k (its cell of step k−1 would otherwise have been complete), or by
//! the last evaluation — never lost; near the boundaries a cell may be
//! reported twice (the local map merges it).
//!
//! **The observed footprint** of a step is built from the returns whose
//! grown disc is complete, so the local map prunes only where this frame's
//! verdicts are in; the last evaluation's is the whole image's. Reports of
//! one frame carry the frame's capture time, so they never prune each other.
//!
//! **Cost.** Columns: a step evaluates the columns swept since the last
//! step plus `2W` before them, `W = asin(R / near_m)`; steps are taken
//! every `W` of sweep at the least, so a frame costs about four whole-image
//! evaluations (the last one included). Cells nearer than `near_m` wait for
//! the frame's last evaluation.

use arcnav_vehicle::{Isometry, Utime};
use nalgebra::{Point3, Vector3};

use crate::config::StreamingConfig;
use crate::evaluator::{
    ImageStats, ObstacleCell, ObstacleReport, PerceptionError, Reasons, Region, Runner, Support,
    TerrainEvaluator,
};
use crate::fov::FovBuilder;
use crate::image::{BeamTable, ImageError, RangeImage};

/// The most pixels a streamed frame may declare (a 128 × 131 072 image):
/// the frame buffer is allocated from the slice's word.
pub const MAX_FRAME_PIXELS: usize = 1 << 24;

/// Which lines of its image a slice carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SliceAxis {
    /// Columns `[first, first + cols)`, every row (a rotating lidar).
    Columns,
    /// Rows `[first, first + rows)`, every column (a scanning sensor).
    Rows,
}

/// A part of one range image, sent as soon as it was acquired.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeSlice {
    /// When the slice's last line was acquired.
    pub utime: Utime,
    /// Capture time of the image it belongs to (the start of the frame).
    pub frame_utime: Utime,
    pub sensor: String,
    /// Sensor → vehicle (the mount).
    pub vehicle_from_sensor: Isometry,
    /// Shape of the whole image.
    pub frame_rows: usize,
    pub frame_cols: usize,
    pub axis: SliceAxis,
    /// The image's index of the slice's first column or row.
    pub first: usize,
    /// The slice's own rows' elevations and columns' azimuths.
    pub beams: BeamTable,
    /// When each line (column or row) was acquired.
    pub line_utimes: Vec<Utime>,
    /// Metres along each beam, row-major `rows × cols` of the slice.
    pub range: Vec<f32>,
}

/// Why a slice cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SliceError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("the slice's image is {rows} × {cols}: empty, or more than {MAX_FRAME_PIXELS} pixels")]
    FrameSize { rows: usize, cols: usize },
    #[error(
        "the slice ({rows} × {cols}, {axis:?} from {first}) does not fit its {frame_rows} × {frame_cols} image"
    )]
    DoesNotFit {
        axis: SliceAxis,
        first: usize,
        rows: usize,
        cols: usize,
        frame_rows: usize,
        frame_cols: usize,
    },
    #[error("the slice has {lines} lines but {times} line times")]
    LineTimes { lines: usize, times: usize },
    #[error("the slice's last line ({utime} µs) is before its frame's start ({frame_utime} µs)")]
    BeforeFrame { utime: Utime, frame_utime: Utime },
    #[error(
        "line {line} was acquired at {at} µs, outside its frame's start ({frame_utime} µs) and the slice's time ({utime} µs)"
    )]
    LineTime {
        line: usize,
        at: Utime,
        frame_utime: Utime,
        utime: Utime,
    },
}

impl RangeSlice {
    /// Lines (columns or rows) the slice carries.
    pub fn lines(&self) -> usize {
        match self.axis {
            SliceAxis::Columns => self.beams.cols(),
            SliceAxis::Rows => self.beams.rows(),
        }
    }

    /// Checks the slice on its own: shapes, angles, its place in its image.
    pub fn validate(&self) -> Result<(), SliceError> {
        let (rows, cols) = (self.beams.rows(), self.beams.cols());
        self.beams.check(self.range.len())?;
        if self.frame_rows == 0
            || self.frame_cols == 0
            || self
                .frame_rows
                .checked_mul(self.frame_cols)
                .is_none_or(|n| n > MAX_FRAME_PIXELS)
        {
            return Err(SliceError::FrameSize {
                rows: self.frame_rows,
                cols: self.frame_cols,
            });
        }
        let fits = match self.axis {
            SliceAxis::Columns => {
                rows == self.frame_rows
                    && cols > 0
                    && self
                        .first
                        .checked_add(cols)
                        .is_some_and(|end| end <= self.frame_cols)
            }
            SliceAxis::Rows => {
                cols == self.frame_cols
                    && rows > 0
                    && self
                        .first
                        .checked_add(rows)
                        .is_some_and(|end| end <= self.frame_rows)
            }
        };
        if !fits {
            return Err(SliceError::DoesNotFit {
                axis: self.axis,
                first: self.first,
                rows,
                cols,
                frame_rows: self.frame_rows,
                frame_cols: self.frame_cols,
            });
        }
        if self.line_utimes.len() != self.lines() {
            return Err(SliceError::LineTimes {
                lines: self.lines(),
                times: self.line_utimes.len(),
            });
        }
        if self.utime < self.frame_utime {
            return Err(SliceError::BeforeFrame {
                utime: self.utime,
                frame_utime: self.frame_utime,
            });
        }
        if let Some(k) = self
            .line_utimes
            .iter()
            .position(|&t| t < self.frame_utime || t > self.utime)
        {
            return Err(SliceError::LineTime {
                line: self.first + k,
                at: self.line_utimes[k],
                frame_utime: self.frame_utime,
                utime: self.utime,
            });
        }
        Ok(())
    }

    /// The slice as a range image of its own (capture time: the frame's).
    pub fn to_image(&self) -> RangeImage {
        RangeImage {
            utime: self.frame_utime,
            sensor: self.sensor.clone(),
            vehicle_from_sensor: self.vehicle_from_sensor,
            beams: self.beams.clone(),
            range: self.range.clone(),
        }
    }

    /// Cuts `image` into slices of `lines` lines along `axis`, in image
    /// order; line `i` of the image was acquired at `line_utime(i)`.
    pub fn cut(
        image: &RangeImage,
        axis: SliceAxis,
        lines: usize,
        line_utime: impl Fn(usize) -> Utime,
    ) -> Vec<RangeSlice> {
        let (rows, cols) = (image.rows(), image.cols());
        let total = match axis {
            SliceAxis::Columns => cols,
            SliceAxis::Rows => rows,
        };
        let lines = lines.max(1);
        (0..total)
            .step_by(lines)
            .map(|first| {
                let end = (first + lines).min(total);
                let (beams, range) = match axis {
                    SliceAxis::Columns => (
                        BeamTable {
                            elevation: image.beams.elevation.clone(),
                            azimuth: image.beams.azimuth[first..end].to_vec(),
                        },
                        image
                            .range
                            .chunks(cols)
                            .flat_map(|row| &row[first..end])
                            .copied()
                            .collect(),
                    ),
                    SliceAxis::Rows => (
                        BeamTable {
                            elevation: image.beams.elevation[first..end].to_vec(),
                            azimuth: image.beams.azimuth.clone(),
                        },
                        image.range[first * cols..end * cols].to_vec(),
                    ),
                };
                let line_utimes: Vec<Utime> = (first..end).map(&line_utime).collect();
                RangeSlice {
                    utime: line_utimes.last().copied().unwrap_or(image.utime),
                    frame_utime: image.utime,
                    sensor: image.sensor.clone(),
                    vehicle_from_sensor: image.vehicle_from_sensor,
                    frame_rows: rows,
                    frame_cols: cols,
                    axis,
                    first,
                    beams,
                    line_utimes,
                    range,
                }
            })
            .collect()
    }
}

/// What a stream did with its slices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct StreamCounts {
    pub slices: u64,
    /// Frames ended (their last evaluation done).
    pub frames: u64,
    /// Evaluations of part of a frame.
    pub steps: u64,
    /// Lines (columns or rows) received.
    pub received_lines: u64,
    /// Lines (columns or rows) those evaluations took, all told: the work
    /// streaming costs (a frame's own lines once more at its end).
    pub evaluated_lines: u64,
    /// Slices refused: older than the frame being assembled, or a line
    /// already received (a repeated or reordered packet).
    pub out_of_order: u64,
    /// Slices refused: shape, mount or axis unlike their frame's earlier slices.
    pub inconsistent: u64,
    /// Lines that never arrived in frames that ended (no return there).
    pub lost_lines: u64,
    /// Lines of the frame under way when the input ended ([`FrameStream::flush`]).
    pub cut_off_lines: u64,
    /// Frames ended early because a newer frame's slice arrived.
    pub incomplete_frames: u64,
}

/// Height of the returns of a cell that may sit above or below its centre,
/// for the horizontal spread a tilted sensor sees them at, m.
const TILT_HEIGHT_M: f64 = 3.0;

/// The sine of the sensor tilt the sweep window `W` allows for (~11.5°): a
/// more tilted sensor's cells near `near_m` wait for the frame's end (they
/// are still reported, by its last evaluation).
const WINDOW_TILT_SIN: f64 = 0.2;

/// The sine of the sensor tilt a rows window reaches for (~20°: the ERIM
/// looks 18° down): a row farther out is left out of the window.
const ROWS_TILT_SIN: f64 = 0.35;

/// A frame being assembled.
struct Frame {
    utime: Utime,
    axis: SliceAxis,
    sensor: String,
    vehicle_from_sensor: Isometry,
    image: RangeImage,
    received: Vec<bool>,
    /// Lines counted lost so far.
    lost: usize,
    /// Columns: the next column expected.
    next: usize,
    /// Columns: the first received column and the sweep's direction.
    reference: Option<(usize, f32)>,
    sweep: f32,
    /// Columns: angle swept from the reference column, per column (NaN:
    /// none), and whether it only grows.
    swept: Vec<f32>,
    monotone: bool,
    /// Columns: every step's window, (first swept angle, last).
    windows: Vec<(f32, f32)>,
    /// Swept angle evaluated at the last step.
    last_step: f32,
    /// Rows: which way beams arrive (+1: highest first, −1: lowest first,
    /// 0: no order), the rows in the order they came, how many had come at
    /// the last step, and each step's final distances per column.
    order: i8,
    arrived: Vec<usize>,
    rows_at_last_step: usize,
    step_finals: Vec<Vec<[f32; 2]>>,
    /// When each line was acquired (0: not yet).
    line_utimes: Vec<Utime>,
    /// Pose of the last step (the frame's last evaluation uses it).
    pose: Option<Isometry>,
    last_utime: Utime,
    /// Columns: the azimuth between neighbouring columns, once known (0).
    column_step: f64,
}

/// Assembles one sensor's slices and reports the cells they complete.
pub struct FrameStream {
    config: StreamingConfig,
    support: Support,
    region: crate::RegionConfig,
    min_range: f64,
    max_range: f64,
    fov_max_vertices: usize,
    frame: Option<Frame>,
    sub: RangeImage,
    scratch: ObstacleReport,
    fov: FovBuilder,
    /// Rows: the rows of the window being evaluated.
    rows: Vec<usize>,
    /// Evaluate each frame once, whole, when it ends (for evaluators that
    /// fuse images).
    whole_frames: bool,
    pub counts: StreamCounts,
}

/// The vehicle's pose at a time (interpolated between poses, or carried
/// past the newest): `None` when not known.
pub type PoseAt<'a> = &'a dyn Fn(Utime) -> Option<Isometry>;

/// A cell's place in the sensor frame.
#[derive(Debug, Clone, Copy)]
struct Place {
    d: f64,
    /// Azimuth, sensor frame.
    phi: f64,
}

/// The geometry of one evaluation: sensor frame, tilt margins.
struct Geometry {
    sensor_from_world: Isometry,
    /// Support radius with the tilt margin, m.
    radius: f64,
    /// One cell diagonal plus the tilt margin, m.
    grow: f64,
    /// The image filters' reach, radians of azimuth.
    filter: f64,
}

impl Geometry {
    fn new(
        world_from_vehicle: &Isometry,
        vehicle_from_sensor: &Isometry,
        support: Support,
        cell_size: f64,
        column_step: f64,
    ) -> Self {
        let world_from_sensor = world_from_vehicle * vehicle_from_sensor;
        let up = world_from_sensor.rotation * Vector3::z();
        let tilt = up.z.clamp(-1.0, 1.0).acos().sin() * TILT_HEIGHT_M;
        Self {
            sensor_from_world: world_from_sensor.inverse(),
            radius: support.metres + tilt,
            grow: cell_size * std::f64::consts::SQRT_2 + tilt,
            filter: f64::from(support.pixels) * column_step + support.radians,
        }
    }

    fn place(&self, cell: &ObstacleCell) -> Place {
        let z = 0.5 * (f64::from(cell.z_min) + f64::from(cell.z_max));
        let p = self.sensor_from_world * Point3::new(cell.x, cell.y, z);
        Place {
            d: p.x.hypot(p.y),
            phi: p.y.atan2(p.x),
        }
    }

    /// Half the azimuth span of a disc of `radius` at `d` (None: the disc
    /// holds the sensor's axis, every azimuth).
    fn half_span(&self, d: f64, radius: f64) -> Option<f64> {
        (radius < d).then(|| (radius / d).asin() + self.filter)
    }
}

/// Angle from `from` to `to` in the direction `sweep` (±1), in [0, 2π).
fn swept_angle(from: f32, to: f32, sweep: f32) -> f32 {
    (sweep * (to - from)).rem_euclid(std::f32::consts::TAU)
}

impl FrameStream {
    pub fn new(
        config: StreamingConfig,
        support: Support,
        perception: &crate::PerceptionConfig,
    ) -> Self {
        Self {
            config,
            support,
            region: perception.region.clone(),
            min_range: perception.min_range_m,
            max_range: perception.max_range_m,
            fov_max_vertices: perception.fov_max_vertices,
            frame: None,
            sub: RangeImage {
                utime: 0,
                sensor: String::new(),
                vehicle_from_sensor: Isometry::identity(),
                beams: BeamTable {
                    elevation: Vec::new(),
                    azimuth: Vec::new(),
                },
                range: Vec::new(),
            },
            scratch: ObstacleReport::default(),
            fov: FovBuilder::default(),
            rows: Vec::new(),
            whole_frames: false,
            counts: StreamCounts::default(),
        }
    }

    /// Judges each frame once, whole, when its last slice arrives (an
    /// evaluator that fuses images must not see parts of one again and
    /// again); cells then come at the frame's end, as with whole images.
    pub fn set_whole_frames(&mut self, whole: bool) {
        self.whole_frames = whole;
    }

    /// Capture time of the frame being assembled.
    pub fn frame_utime(&self) -> Option<Utime> {
        self.frame.as_ref().map(|f| f.utime)
    }

    /// Takes `slice` and reports every cell it completes to `out`. Each
    /// evaluation places its returns with the pose (from `poses`) at the
    /// middle of the time its lines were acquired over. Stats are those of
    /// the reported cells, plus the whole image's pixel counts when the
    /// slice ends its frame.
    pub fn on_slice(
        &mut self,
        slice: &RangeSlice,
        poses: PoseAt,
        evaluator: &mut dyn TerrainEvaluator,
        runner: &dyn Runner,
        out: &mut dyn FnMut(ObstacleReport),
    ) -> Result<ImageStats, SliceError> {
        slice.validate()?;
        let mut stats = ImageStats::default();
        if let Some(frame) = &self.frame {
            if slice.frame_utime < frame.utime {
                self.counts.out_of_order += 1;
                return Ok(stats);
            }
            if slice.frame_utime > frame.utime {
                self.counts.incomplete_frames += 1;
                stats = self.finish(poses, evaluator, runner, out)?;
            }
        }
        if self.frame.is_none() {
            self.frame = Some(Frame::new(slice));
        }
        let Some(frame) = self.frame.as_mut() else {
            return Ok(stats);
        };
        let same = frame.axis == slice.axis
            && frame.image.rows() == slice.frame_rows
            && frame.image.cols() == slice.frame_cols
            && frame.vehicle_from_sensor == slice.vehicle_from_sensor
            && frame.sensor == slice.sensor;
        if !same {
            self.counts.inconsistent += 1;
            return Ok(stats);
        }
        if !frame.take(slice) {
            self.counts.out_of_order += 1;
            return Ok(stats);
        }
        self.counts.slices += 1;
        self.counts.received_lines += slice.lines() as u64;
        if let Some(pose) = poses(slice.utime) {
            frame.pose = Some(pose);
        }
        frame.last_utime = slice.utime;
        let complete = frame.received.iter().all(|&r| r);
        if !complete {
            let due = !self.whole_frames
                && match frame.axis {
                    SliceAxis::Columns => frame.columns_due(self.support, &self.config),
                    SliceAxis::Rows => frame.order != 0,
                };
            if due {
                stats.accumulate(&self.step(slice.utime, poses, evaluator, runner, out)?);
            }
            return Ok(stats);
        }
        stats.accumulate(&self.finish(poses, evaluator, runner, out)?);
        Ok(stats)
    }

    /// The input ended (a log's end): the frame under way is judged with
    /// the lines it has ([`FrameStream::finish`]); those it lacks are
    /// counted as cut off, not lost.
    pub fn flush(
        &mut self,
        poses: PoseAt,
        evaluator: &mut dyn TerrainEvaluator,
        runner: &dyn Runner,
        out: &mut dyn FnMut(ObstacleReport),
    ) -> Result<ImageStats, SliceError> {
        self.end(true, poses, evaluator, runner, out)
    }

    /// Ends the frame being assembled: the whole image (lines that never
    /// came hold no return, counted lost) is evaluated and the cells no
    /// step completed are reported. Nothing when no frame is under way.
    pub fn finish(
        &mut self,
        poses: PoseAt,
        evaluator: &mut dyn TerrainEvaluator,
        runner: &dyn Runner,
        out: &mut dyn FnMut(ObstacleReport),
    ) -> Result<ImageStats, SliceError> {
        self.end(false, poses, evaluator, runner, out)
    }

    fn end(
        &mut self,
        input_ended: bool,
        poses: PoseAt,
        evaluator: &mut dyn TerrainEvaluator,
        runner: &dyn Runner,
        out: &mut dyn FnMut(ObstacleReport),
    ) -> Result<ImageStats, SliceError> {
        if let Some(frame) = &self.frame {
            let missing = frame.received.iter().filter(|&&r| !r).count() as u64;
            self.counts.frames += 1;
            self.counts.lost_lines += frame.lost as u64;
            if input_ended {
                self.counts.cut_off_lines += missing;
            } else {
                self.counts.lost_lines += missing;
            }
        }
        let Some(mut frame) = self.frame.take() else {
            return Ok(ImageStats::default());
        };
        let Some(newest) = frame.pose else {
            return Ok(ImageStats::default());
        };
        let lines = frame.line_utimes.len();
        let pose = frame.middle_pose(0..lines, poses).unwrap_or(newest);
        frame.fill_missing_beams();
        let mut report = std::mem::take(&mut self.scratch);
        let evaluated = evaluator.evaluate_with(&frame.image, &pose, &mut report, runner);
        let mut stats = match evaluated {
            Ok(stats) => stats,
            Err(PerceptionError::Image(e)) => {
                self.scratch = report;
                return Err(e.into());
            }
        };
        let geometry = frame.geometry(&pose, self.support, report.cell_size_m);
        let received: Vec<usize> = match frame.axis {
            SliceAxis::Rows => (0..frame.image.rows())
                .filter(|&r| frame.received[r])
                .collect(),
            SliceAxis::Columns => Vec::new(),
        };
        let mut kept = report.clone();
        kept.cells.clear();
        kept.acquired = frame.last_utime;
        for cell in &report.cells {
            let place = geometry.place(cell);
            if !frame.ever_complete(&geometry, place, geometry.radius + geometry.grow) {
                kept.cells
                    .push(frame.deskewed(cell, place, &pose, poses, &received));
            }
        }
        renumber_regions(&report.regions, &mut kept);
        count_cells(&kept, &mut stats);
        self.scratch = report;
        out(kept);
        Ok(stats)
    }

    /// Evaluates the part of the frame received so far (a window of it,
    /// for columns) and reports the cells that became complete.
    fn step(
        &mut self,
        utime: Utime,
        poses: PoseAt,
        evaluator: &mut dyn TerrainEvaluator,
        runner: &dyn Runner,
        out: &mut dyn FnMut(ObstacleReport),
    ) -> Result<ImageStats, SliceError> {
        let Some(frame) = self.frame.as_mut() else {
            return Ok(ImageStats::default());
        };
        let Some(newest) = frame.pose else {
            return Ok(ImageStats::default());
        };
        self.counts.steps += 1;
        let window = match frame.axis {
            SliceAxis::Columns => {
                let w = frame.half_window(self.support, &self.config);
                let lo_angle = frame.last_step - 2.0 * w;
                // The last received column at or before that angle.
                let reference = frame.reference.map_or(0, |(c, _)| c);
                let lo = (reference..frame.next)
                    .take_while(|&c| frame.swept[c].is_nan() || frame.swept[c] <= lo_angle)
                    .last()
                    .unwrap_or(reference);
                frame.copy_columns(lo..frame.next, &mut self.sub);
                self.counts.evaluated_lines += (frame.next - lo) as u64;
                Some(lo)
            }
            SliceAxis::Rows => {
                let filter = self.support.pixels as usize
                    + (self.support.radians / frame.row_step()).ceil() as usize;
                // The cells this step completes rest on returns within two
                // support radii and a cell (and the tilt) of the last
                // step's final distances.
                let tilt = TILT_HEIGHT_M * ROWS_TILT_SIN;
                let reach = (2.0 * (self.support.metres + tilt) + 0.5) as f32;
                let mut rows = std::mem::take(&mut self.rows);
                frame.rows_window(filter, reach, &mut rows);
                frame.copy_rows(&rows, &mut self.sub);
                self.counts.evaluated_lines += rows.len() as u64;
                self.rows = rows;
                None
            }
        };
        let pose = match window {
            Some(lo) => frame.middle_pose(lo..frame.next, poses),
            None => frame.middle_pose(self.rows.iter().copied(), poses),
        }
        .unwrap_or(newest);
        let mut report = std::mem::take(&mut self.scratch);
        let evaluated = evaluator.evaluate_with(&self.sub, &pose, &mut report, runner);
        if let Err(PerceptionError::Image(e)) = evaluated {
            self.scratch = report;
            return Err(e.into());
        }
        let frame = self.frame.as_mut().expect("checked above");
        let geometry = frame.geometry(&pose, self.support, report.cell_size_m);
        let previous_window = frame.windows.last().copied();
        if let Some(lo) = window {
            let top = frame.swept[frame.next - 1];
            frame.windows.push((frame.swept[lo], top));
            frame.last_step = top;
        }
        let mut kept = ObstacleReport {
            utime: frame.utime,
            acquired: utime,
            sensor: frame.sensor.clone(),
            cell_size_m: report.cell_size_m,
            shadows: report.shadows.clone(),
            ..ObstacleReport::default()
        };
        for cell in &report.cells {
            let place = geometry.place(cell);
            let now = frame.complete_now(&geometry, place, geometry.radius);
            let before = match frame.axis {
                SliceAxis::Columns => previous_window.is_some_and(|w| {
                    frame.in_window(&geometry, place, geometry.radius + geometry.grow, w)
                }),
                SliceAxis::Rows => frame
                    .step_finals
                    .len()
                    .checked_sub(2)
                    .and_then(|i| frame.step_finals.get(i))
                    .is_some_and(|finals| {
                        frame.complete_in(finals, &geometry, place, geometry.radius + geometry.grow)
                    }),
            };
            if now && !before {
                kept.cells
                    .push(frame.deskewed(cell, place, &pose, poses, &self.rows));
            }
        }
        renumber_regions(&report.regions, &mut kept);
        let mut stats = ImageStats::default();
        count_cells(&kept, &mut stats);
        self.footprint(&pose, &geometry, window, &mut kept);
        self.scratch = report;
        out(kept);
        Ok(stats)
    }

    /// The step's footprint: the returns of the evaluated part whose disc,
    /// grown by a cell, is complete.
    fn footprint(
        &mut self,
        pose: &Isometry,
        geometry: &Geometry,
        lo: Option<usize>,
        report: &mut ObstacleReport,
    ) {
        let Some(frame) = self.frame.as_ref() else {
            return;
        };
        let world_from_sensor = pose * frame.vehicle_from_sensor;
        let sensor_at = world_from_sensor.translation.vector;
        let (yaw_sin, yaw_cos) = {
            let forward = pose.rotation * Vector3::x();
            forward.y.atan2(forward.x).sin_cos()
        };
        let vehicle_at = pose.translation.vector;
        let region = &self.region;
        let sub = &self.sub;
        let cols = sub.cols();
        let grown = geometry.radius + geometry.grow;
        // Per column, the nearest horizontal distance at which a return's
        // grown disc is complete (columns: from the column's swept angle
        // and the window; rows: found per return below).
        let near: Vec<f64> = match (frame.axis, lo, frame.windows.last()) {
            (SliceAxis::Columns, Some(lo), Some(&(bottom, top))) => (0..cols)
                .map(|col| {
                    let a = frame.swept[lo + col];
                    let room = f64::from((a - bottom).min(top - a)) - geometry.filter;
                    if room.is_nan() || room <= 0.0 {
                        f64::INFINITY
                    } else if room >= std::f64::consts::FRAC_PI_2 {
                        grown
                    } else {
                        grown / room.sin()
                    }
                })
                .collect(),
            (SliceAxis::Columns, ..) => vec![f64::INFINITY; cols],
            (SliceAxis::Rows, ..) => vec![f64::NAN; cols],
        };
        let trig = |angles: &[f32]| -> Vec<(f64, f64)> {
            angles.iter().map(|&a| f64::from(a).sin_cos()).collect()
        };
        let (rows_trig, cols_trig) = (trig(&sub.beams.elevation), trig(&sub.beams.azimuth));
        self.fov
            .start(cols, [sensor_at.x as f32, sensor_at.y as f32]);
        for (row, ranges) in sub.range.chunks(cols.max(1)).enumerate() {
            let (sin_el, cos_el) = rows_trig[row];
            for (col, &r) in ranges.iter().enumerate() {
                let r = f64::from(r);
                if !(r.is_finite() && r >= self.min_range && r <= self.max_range) {
                    continue;
                }
                let d = r * cos_el;
                let complete = if near[col].is_nan() {
                    let place = Place {
                        d,
                        phi: f64::from(sub.beams.azimuth[col]),
                    };
                    frame.complete_now(geometry, place, grown)
                } else {
                    d >= near[col] && grown < d
                };
                if !complete {
                    continue;
                }
                let (sin_az, cos_az) = cols_trig[col];
                let p = world_from_sensor * Point3::new(d * cos_az, d * sin_az, r * sin_el);
                let (dx, dy) = (p.x - vehicle_at.x, p.y - vehicle_at.y);
                let ahead = yaw_cos * dx + yaw_sin * dy;
                let left = -yaw_sin * dx + yaw_cos * dy;
                if ahead > region.ahead_m
                    || ahead < -region.behind_m
                    || left.abs() > region.half_width_m
                {
                    continue;
                }
                self.fov.add(col, p.x as f32, p.y as f32);
            }
        }
        self.fov.finish(
            &Isometry::identity(),
            self.fov_max_vertices,
            &mut report.fov,
        );
    }
}

/// Keeps the regions `report`'s cells name, renumbered, with their counts.
fn renumber_regions(regions: &[Region], report: &mut ObstacleReport) {
    report.regions.clear();
    let mut map: Vec<(u32, u32)> = Vec::new();
    for cell in &mut report.cells {
        let Some(region) = regions.get(cell.region as usize) else {
            continue;
        };
        let index = match map.iter().find(|(old, _)| *old == cell.region) {
            Some(&(_, new)) => new,
            None => {
                let new = report.regions.len() as u32;
                map.push((cell.region, new));
                report.regions.push(Region {
                    cells: 0,
                    reasons: region.reasons,
                });
                new
            }
        };
        report.regions[index as usize].cells += 1;
        cell.region = index;
    }
}

/// The cell counts of `report`'s cells into `stats`.
fn count_cells(report: &ObstacleReport, stats: &mut ImageStats) {
    stats.untraversable = 0;
    stats.graded = 0;
    stats.suspected = 0;
    stats.by_reason = [0; Reasons::ALL.len()];
    for cell in &report.cells {
        if cell.is_obstacle() {
            stats.untraversable += 1;
            for (i, (reason, _)) in Reasons::ALL.iter().enumerate() {
                if cell.reasons.contains(*reason) {
                    stats.by_reason[i] += 1;
                }
            }
        } else {
            stats.graded += 1;
            stats.suspected += u32::from(cell.is_suspected_drop_off());
        }
    }
    stats.regions = report.regions.len() as u32;
}

impl Frame {
    fn new(slice: &RangeSlice) -> Self {
        let (rows, cols) = (slice.frame_rows, slice.frame_cols);
        let lines = match slice.axis {
            SliceAxis::Columns => cols,
            SliceAxis::Rows => rows,
        };
        Self {
            utime: slice.frame_utime,
            axis: slice.axis,
            sensor: slice.sensor.clone(),
            vehicle_from_sensor: slice.vehicle_from_sensor,
            image: RangeImage {
                utime: slice.frame_utime,
                sensor: slice.sensor.clone(),
                vehicle_from_sensor: slice.vehicle_from_sensor,
                beams: BeamTable {
                    elevation: vec![f32::NAN; rows],
                    azimuth: vec![f32::NAN; cols],
                },
                range: vec![f32::NAN; rows * cols],
            },
            received: vec![false; lines],
            lost: 0,
            next: 0,
            reference: None,
            sweep: 0.0,
            swept: vec![f32::NAN; cols],
            monotone: true,
            windows: Vec::new(),
            last_step: 0.0,
            order: 0,
            arrived: Vec::new(),
            rows_at_last_step: 0,
            step_finals: Vec::new(),
            line_utimes: vec![0; lines],
            pose: None,
            last_utime: slice.utime,
            column_step: 0.0,
        }
    }

    /// Copies the slice in; false when one of its lines was already here,
    /// or (columns) it comes before the next column expected.
    fn take(&mut self, slice: &RangeSlice) -> bool {
        let lines = slice.first..slice.first + slice.lines();
        if self.received[lines.clone()].iter().any(|&r| r) {
            return false;
        }
        let cols = self.image.cols();
        if self.axis == SliceAxis::Columns && slice.first < self.next {
            return false;
        }
        self.line_utimes[lines.clone()].copy_from_slice(&slice.line_utimes);
        match self.axis {
            SliceAxis::Columns => {
                // Columns skipped are lost: they hold no return.
                self.lost += slice.first - self.next;
                for c in self.next..slice.first {
                    self.received[c] = true;
                }
                let n = slice.beams.cols();
                self.image
                    .beams
                    .elevation
                    .clone_from(&slice.beams.elevation);
                for (k, &az) in slice.beams.azimuth.iter().enumerate() {
                    let c = slice.first + k;
                    self.image.beams.azimuth[c] = az;
                    self.received[c] = true;
                    self.note_sweep(c, az);
                }
                for (row, values) in slice.range.chunks(n).enumerate() {
                    self.image.range[row * cols + slice.first..][..n].copy_from_slice(values);
                }
                self.next = slice.first + n;
                if self.column_step == 0.0 {
                    self.column_step = smallest_step(&slice.beams.azimuth);
                }
            }
            SliceAxis::Rows => {
                let (lo, hi) = self.received_elevations();
                let (slo, shi) = slice
                    .beams
                    .elevation
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &e| {
                        (a.min(e), b.max(e))
                    });
                let order = if lo > hi {
                    // The first slice: highest beam first when its rows
                    // descend (image order), else lowest first.
                    let first = slice.beams.elevation.first().copied().unwrap_or(0.0);
                    let last = slice.beams.elevation.last().copied().unwrap_or(0.0);
                    if first >= last { 1 } else { -1 }
                } else if shi < lo {
                    1
                } else if slo > hi {
                    -1
                } else {
                    0
                };
                if self.order == 0 && lo <= hi {
                    // Once without order, the frame stays so.
                } else if lo > hi || self.order == order {
                    self.order = order;
                } else {
                    self.order = 0;
                }
                self.image.beams.azimuth.clone_from(&slice.beams.azimuth);
                if self.column_step == 0.0 {
                    self.column_step = smallest_step(&slice.beams.azimuth);
                }
                for (k, &el) in slice.beams.elevation.iter().enumerate() {
                    self.image.beams.elevation[slice.first + k] = el;
                    self.received[slice.first + k] = true;
                    self.arrived.push(slice.first + k);
                }
                self.image.range[slice.first * cols..][..slice.range.len()]
                    .copy_from_slice(&slice.range);
            }
        }
        true
    }

    fn received_elevations(&self) -> (f32, f32) {
        self.received
            .iter()
            .zip(&self.image.beams.elevation)
            .filter(|(r, _)| **r)
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (_, &e)| {
                (a.min(e), b.max(e))
            })
    }

    fn note_sweep(&mut self, c: usize, az: f32) {
        let Some((reference, az0)) = self.reference else {
            self.reference = Some((c, az));
            self.swept[c] = 0.0;
            return;
        };
        if self.sweep == 0.0 {
            // The second column sets the direction (the nearer way round).
            let ccw = swept_angle(az0, az, 1.0);
            self.sweep = if ccw <= std::f32::consts::PI {
                1.0
            } else {
                -1.0
            };
        }
        let a = swept_angle(az0, az, self.sweep);
        let previous = self.swept[..c]
            .iter()
            .rev()
            .find(|v| v.is_finite())
            .copied()
            .unwrap_or(0.0);
        if c != reference && (a.is_nan() || a <= previous) {
            self.monotone = false;
        }
        self.swept[c] = a;
    }

    /// The geometry of an evaluation with the vehicle at `pose`.
    fn geometry(&self, pose: &Isometry, support: Support, cell_size: f64) -> Geometry {
        Geometry::new(
            pose,
            &self.vehicle_from_sensor,
            support,
            cell_size,
            self.column_step(),
        )
    }

    /// Azimuth between neighbouring columns, radians (0.1 while unknown).
    fn column_step(&self) -> f64 {
        if self.column_step > 0.0 {
            return self.column_step;
        }
        let step = smallest_step(&self.image.beams.azimuth);
        if step > 0.0 { step } else { 0.1 }
    }

    /// Elevation between neighbouring received rows, radians.
    fn row_step(&self) -> f64 {
        let mut elevations: Vec<f32> = self
            .received
            .iter()
            .zip(&self.image.beams.elevation)
            .filter(|(r, e)| **r && e.is_finite())
            .map(|(_, e)| *e)
            .collect();
        elevations.sort_by(f32::total_cmp);
        elevations
            .windows(2)
            .map(|w| f64::from(w[1] - w[0]))
            .filter(|s| *s > 0.0)
            .fold(f64::INFINITY, f64::min)
            .clamp(1e-4, 0.1)
    }

    /// `W`: half the azimuth span of a support disc at `near_m`.
    fn half_window(&self, support: Support, config: &StreamingConfig) -> f32 {
        let radius = (support.metres + TILT_HEIGHT_M * WINDOW_TILT_SIN).min(config.near_m * 0.99);
        ((radius / config.near_m).asin()
            + f64::from(support.pixels) * self.column_step()
            + support.radians) as f32
    }

    /// Columns: a step is due once `W` of sweep came in since the last.
    fn columns_due(&self, support: Support, config: &StreamingConfig) -> bool {
        if !self.monotone || self.sweep == 0.0 || self.next == 0 {
            return false;
        }
        let top = self.swept[self.next - 1];
        top.is_finite() && top - self.last_step >= self.half_window(support, config)
    }

    /// Whether the disc of `radius` at `place` is complete now.
    fn complete_now(&self, geometry: &Geometry, place: Place, radius: f64) -> bool {
        match self.axis {
            SliceAxis::Columns => self
                .windows
                .last()
                .is_some_and(|&w| self.in_window(geometry, place, radius, w)),
            SliceAxis::Rows => self
                .step_finals
                .last()
                .is_some_and(|finals| self.complete_in(finals, geometry, place, radius)),
        }
    }

    /// Whether the disc was complete at any step of the frame.
    fn ever_complete(&self, geometry: &Geometry, place: Place, radius: f64) -> bool {
        match self.axis {
            SliceAxis::Columns => {
                let Some(span) = self.span(geometry, place, radius) else {
                    return false;
                };
                // Windows end ever later: the first that reaches the
                // disc's end starts earliest among those that do.
                let first = self.windows.partition_point(|&(_, top)| top < span.1);
                self.windows
                    .get(first)
                    .is_some_and(|&(bottom, _)| bottom <= span.0)
            }
            SliceAxis::Rows => self
                .step_finals
                .iter()
                .any(|finals| self.complete_in(finals, geometry, place, radius)),
        }
    }

    /// Columns: the disc's swept span (None: it holds the axis, or
    /// crosses the reference column).
    fn span(&self, geometry: &Geometry, place: Place, radius: f64) -> Option<(f32, f32)> {
        let (_, az0) = self.reference?;
        let w = geometry.half_span(place.d, radius)? as f32;
        let a = swept_angle(az0, place.phi as f32, self.sweep);
        (a - w >= 0.0 && a + w < std::f32::consts::TAU).then_some((a - w, a + w))
    }

    fn in_window(
        &self,
        geometry: &Geometry,
        place: Place,
        radius: f64,
        window: (f32, f32),
    ) -> bool {
        self.span(geometry, place, radius)
            .is_some_and(|(lo, hi)| lo >= window.0 && hi <= window.1)
    }

    /// Rows: whether every column within the disc's azimuth span has its
    /// returns final over the disc's distances.
    fn complete_in(
        &self,
        finals: &[[f32; 2]],
        geometry: &Geometry,
        place: Place,
        radius: f64,
    ) -> bool {
        if self.order == 0 {
            return false;
        }
        let Some(w) = geometry.half_span(place.d, radius) else {
            return false;
        };
        let (near, far) = ((place.d - radius) as f32, (place.d + radius) as f32);
        self.image
            .beams
            .azimuth
            .iter()
            .zip(finals)
            .filter(|(az, _)| {
                let off = (f64::from(**az) - place.phi + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                off.abs() <= w
            })
            .all(|(_, f)| f[0] <= near && far <= f[1])
    }

    /// Rows: the window of rows this step evaluates, in image order, and
    /// each column's distances whose returns the window holds in full.
    ///
    /// Beams still to come lie below (highest first) or above (lowest
    /// first) every beam received; in a height field a lower beam of a
    /// column meets the ground no farther than a higher one, so returns to
    /// come lie nearer (farther) than the newest rows' (the `filter` rows
    /// received last and the two returns nearest the rows to come are not
    /// relied on: image filters, the drop-off rule's look beyond). The
    /// window holds the rows since the last step and the older ones whose
    /// returns the cells this step may complete rest on (within `reach` of
    /// the last step's final distances); older rows, left out, bound the
    /// final distances on the other side. Rows acquired long apart are not
    /// judged together with one pose: a window spans little time.
    fn rows_window(&mut self, filter: usize, reach: f32, rows: &mut Vec<usize>) {
        let cols = self.image.cols();
        let far_first = self.order > 0;
        let distance = |frame: &Self, r: usize, c: usize| {
            let range = frame.image.range[r * cols + c];
            (range.is_finite() && range > 0.0).then(|| range * frame.image.beams.elevation[r].cos())
        };
        // Newest first.
        let arrived: Vec<usize> = self.arrived.iter().rev().copied().collect();
        let new = self.arrived.len() - self.rows_at_last_step;
        let previous = self.step_finals.last().cloned();
        // Older rows go in while some column's return lies within reach of
        // where the last step's final distances ended.
        let mut take = new.min(arrived.len());
        let bounded = previous.as_ref().is_some_and(|previous| {
            previous.iter().any(|f| {
                if far_first {
                    f[0].is_finite()
                } else {
                    f[1].is_finite()
                }
            })
        });
        if let (Some(previous), true) = (&previous, bounded) {
            let mut beyond = 0;
            while take < arrived.len() && beyond <= filter + 2 {
                let r = arrived[take];
                let within = (0..cols).any(|c| {
                    let bound = if far_first {
                        previous[c][0]
                    } else {
                        previous[c][1]
                    };
                    bound.is_finite()
                        && distance(self, r, c).is_some_and(|d| {
                            if far_first {
                                d <= bound + reach
                            } else {
                                d >= bound - reach
                            }
                        })
                });
                if !within {
                    beyond += 1;
                }
                take += 1;
            }
        } else {
            take = arrived.len();
        }
        let window = &arrived[..take];
        let all = take == arrived.len();
        let mut finals = vec![[f32::INFINITY, f32::NEG_INFINITY]; cols];
        for (c, f) in finals.iter_mut().enumerate() {
            // The side of the rows to come.
            let (mut returns, mut frontier) = (
                0,
                if far_first {
                    f32::NEG_INFINITY
                } else {
                    f32::INFINITY
                },
            );
            for (k, &r) in window.iter().enumerate() {
                if let Some(d) = distance(self, r, c) {
                    frontier = if far_first {
                        frontier.max(d)
                    } else {
                        frontier.min(d)
                    };
                    returns += 1;
                }
                if k + 1 > filter && returns >= 2 {
                    break;
                }
            }
            if returns < 2 {
                continue;
            }
            // The side of the rows left out.
            let mut bound = if far_first {
                f32::INFINITY
            } else {
                f32::NEG_INFINITY
            };
            if !all {
                let (mut seen, mut rows_seen) = (0, 0);
                for &r in window.iter().rev() {
                    if let Some(d) = distance(self, r, c) {
                        bound = if far_first {
                            bound.min(d)
                        } else {
                            bound.max(d)
                        };
                        seen += 1;
                    }
                    rows_seen += 1;
                    if rows_seen > filter && seen >= 2 {
                        break;
                    }
                }
                if seen < 2 {
                    continue;
                }
            }
            *f = if far_first {
                [frontier, bound]
            } else {
                [bound, frontier]
            };
        }
        self.step_finals.push(finals);
        self.rows_at_last_step = self.arrived.len();
        rows.clear();
        rows.extend_from_slice(window);
        rows.sort_unstable();
    }

    /// `cell`, judged with the vehicle at `pose`, moved to where the
    /// vehicle was when its returns were acquired (a frame's lines are
    /// acquired over its whole period, the ERIM's over half a second):
    /// the line of its column (columns), or of the return nearest it in
    /// its column among `rows` (rows).
    fn deskewed(
        &self,
        cell: &ObstacleCell,
        place: Place,
        pose: &Isometry,
        poses: PoseAt,
        rows: &[usize],
    ) -> ObstacleCell {
        let column = |phi: f64| self.nearest_column(phi);
        let Some(c) = column(place.phi) else {
            return *cell;
        };
        let line = match self.axis {
            SliceAxis::Columns => Some(c),
            SliceAxis::Rows => {
                let cols = self.image.cols();
                rows.iter()
                    .filter_map(|&r| {
                        let range = self.image.range[r * cols + c];
                        (range.is_finite() && range > 0.0).then(|| {
                            let d = f64::from(range * self.image.beams.elevation[r].cos());
                            ((d - place.d).abs(), r)
                        })
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map(|(_, r)| r)
            }
        };
        let Some(acquired) = line
            .and_then(|l| self.line_utimes.get(l).copied())
            .filter(|&t| t != 0)
            .and_then(poses)
        else {
            return *cell;
        };
        let moved = acquired * pose.inverse();
        let z = 0.5 * (f64::from(cell.z_min) + f64::from(cell.z_max));
        let p = moved * Point3::new(cell.x, cell.y, z);
        let dz = (p.z - z) as f32;
        ObstacleCell {
            x: p.x,
            y: p.y,
            z_min: cell.z_min + dz,
            z_max: cell.z_max + dz,
            ..*cell
        }
    }

    /// The received column whose azimuth is nearest `phi` (found near
    /// where evenly spaced columns would put it: only a line's time rests
    /// on it).
    fn nearest_column(&self, phi: f64) -> Option<usize> {
        let az = &self.image.beams.azimuth;
        let cols = az.len();
        let (first, last) = (f64::from(*az.first()?), f64::from(*az.last()?));
        let off = |a: f64| {
            ((a - phi + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI)
                .abs()
        };
        let guess = match (self.axis, self.reference) {
            // Columns still to come have no azimuth yet: count from the
            // first one along the sweep.
            (SliceAxis::Columns, Some((reference, az0))) if self.sweep != 0.0 => {
                let a = f64::from(swept_angle(az0, phi as f32, self.sweep));
                let step = self.column_step();
                if step > 0.0 {
                    (reference + (a / step).round() as usize).min(cols - 1)
                } else {
                    reference
                }
            }
            _ => {
                let step = if cols > 1 && first.is_finite() && last.is_finite() {
                    (last - first) / (cols - 1) as f64
                } else {
                    0.0
                };
                if step != 0.0 {
                    let turns =
                        ((phi - first) / step).rem_euclid(std::f64::consts::TAU / step.abs());
                    (turns.round() as usize).min(cols - 1)
                } else {
                    0
                }
            }
        };
        let usable =
            |c: &usize| az[*c].is_finite() && (self.axis == SliceAxis::Rows || self.received[*c]);
        (guess.saturating_sub(8)..(guess + 9).min(cols))
            .filter(usable)
            .min_by(|&a, &b| off(f64::from(az[a])).total_cmp(&off(f64::from(az[b]))))
    }

    /// The pose at the middle of the time `lines` were acquired over.
    fn middle_pose(&self, lines: impl Iterator<Item = usize>, poses: PoseAt) -> Option<Isometry> {
        let (first, last) = self.span_of(lines)?;
        poses(first + (last - first) / 2)
    }

    /// Acquisition times of the given lines: the earliest and the latest.
    fn span_of(&self, lines: impl Iterator<Item = usize>) -> Option<(Utime, Utime)> {
        lines
            .filter_map(|l| self.line_utimes.get(l).copied().filter(|&t| t != 0))
            .fold(None, |span, t| match span {
                None => Some((t, t)),
                Some((a, b)) => Some((a.min(t), b.max(t))),
            })
    }

    fn copy_columns(&self, columns: std::ops::Range<usize>, sub: &mut RangeImage) {
        let cols = self.image.cols();
        sub.utime = self.utime;
        sub.sensor.clone_from(&self.sensor);
        sub.vehicle_from_sensor = self.vehicle_from_sensor;
        sub.beams.elevation.clone_from(&self.image.beams.elevation);
        sub.beams.azimuth.clear();
        sub.beams
            .azimuth
            .extend(columns.clone().map(|c| self.image.beams.azimuth[c]));
        sub.range.clear();
        for row in self.image.range.chunks(cols) {
            sub.range.extend_from_slice(&row[columns.clone()]);
        }
        // Columns lost before the window's first: no angle; borrow the
        // nearest known one (they hold no return anyway).
        fill_nan(&mut sub.beams.azimuth);
        fill_nan(&mut sub.beams.elevation);
    }

    fn copy_rows(&self, rows: &[usize], sub: &mut RangeImage) {
        let cols = self.image.cols();
        sub.utime = self.utime;
        sub.sensor.clone_from(&self.sensor);
        sub.vehicle_from_sensor = self.vehicle_from_sensor;
        sub.beams.azimuth.clone_from(&self.image.beams.azimuth);
        sub.beams.elevation.clear();
        sub.range.clear();
        for &r in rows {
            sub.beams.elevation.push(self.image.beams.elevation[r]);
            sub.range
                .extend_from_slice(&self.image.range[r * cols..(r + 1) * cols]);
        }
    }

    /// Lines that never came have no angle: each takes its neighbour's
    /// (they hold no return).
    fn fill_missing_beams(&mut self) {
        fill_nan(&mut self.image.beams.elevation);
        fill_nan(&mut self.image.beams.azimuth);
    }
}

/// The smallest gap between neighbouring angles (0 when none), at most 0.1.
fn smallest_step(angles: &[f32]) -> f64 {
    let step = angles
        .windows(2)
        .map(|w| f64::from((w[1] - w[0]).abs()))
        .filter(|s| s.is_finite() && *s > 0.0)
        .fold(f64::INFINITY, f64::min);
    if step.is_finite() { step.min(0.1) } else { 0.0 }
}

/// Replaces each NaN by the nearest finite value before it (or after it,
/// at the start); all NaN becomes zeros.
fn fill_nan(values: &mut [f32]) {
    let first = values
        .iter()
        .copied()
        .find(|v| v.is_finite())
        .unwrap_or(0.0);
    let mut last = first;
    for v in values {
        if v.is_finite() {
            last = *v;
        } else {
            *v = last;
        }
    }
}
