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
    ImageStats, ObstacleReport, PerceptionError, Reasons, Region, Runner, Support, TerrainEvaluator,
};
use crate::fov::FovBuilder;
use crate::image::{BeamTable, RangeImage};

mod frame;
mod slice;

pub use frame::PoseAt;
use frame::{Frame, Geometry, Place, ROWS_TILT_SIN, TILT_HEIGHT_M};
pub use slice::{MAX_FRAME_PIXELS, RangeSlice, SliceAxis, SliceError};

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

/// Assembles one sensor's slices and reports the cells they complete.
pub struct FrameStream {
    config: StreamingConfig,
    support: Support,
    region: crate::RegionConfig,
    min_range: f64,
    max_range: f64,
    fov_max_vertices: usize,
    frame: Option<Frame>,
    /// The capture time of the last frame ended: a slice of it or of an
    /// older frame is late (a repeated packet), never a new frame.
    ended: Option<Utime>,
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
            ended: None,
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
        // A repeat of a frame's last slice had opened a phantom frame of
        // that time, never completed: every line "lost".
        if self.frame.is_none() && self.ended.is_some_and(|t| slice.frame_utime <= t) {
            self.counts.out_of_order += 1;
            return Ok(stats);
        }
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
        self.ended = Some(frame.utime);
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
