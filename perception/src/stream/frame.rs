//! A frame being assembled from its slices: which lines arrived, which
//! cells they complete, and the sub-images an evaluation takes.

use arcnav_vehicle::{Isometry, Utime};
use nalgebra::{Point3, Vector3};

use super::slice::{RangeSlice, SliceAxis};
use crate::config::StreamingConfig;
use crate::evaluator::{ObstacleCell, Support};
use crate::image::{BeamTable, RangeImage};

/// Height of the returns of a cell that may sit above or below its centre,
/// for the horizontal spread a tilted sensor sees them at, m.
pub(super) const TILT_HEIGHT_M: f64 = 3.0;

/// The sine of the sensor tilt the sweep window `W` allows for (~11.5°): a
/// more tilted sensor's cells near `near_m` wait for the frame's end (they
/// are still reported, by its last evaluation).
pub(super) const WINDOW_TILT_SIN: f64 = 0.2;

/// The sine of the sensor tilt a rows window reaches for (~20°: the ERIM
/// looks 18° down): a row farther out is left out of the window.
pub(super) const ROWS_TILT_SIN: f64 = 0.35;

/// A frame being assembled.
pub(super) struct Frame {
    pub(super) utime: Utime,
    pub(super) axis: SliceAxis,
    pub(super) sensor: String,
    pub(super) vehicle_from_sensor: Isometry,
    pub(super) image: RangeImage,
    pub(super) received: Vec<bool>,
    /// Lines counted lost so far.
    pub(super) lost: usize,
    /// Columns: the next column expected.
    pub(super) next: usize,
    /// Columns: the first received column and the sweep's direction.
    pub(super) reference: Option<(usize, f32)>,
    pub(super) sweep: f32,
    /// Columns: angle swept from the reference column, per column (NaN:
    /// none), and whether it only grows.
    pub(super) swept: Vec<f32>,
    pub(super) monotone: bool,
    /// Columns: every step's window, (first swept angle, last).
    pub(super) windows: Vec<(f32, f32)>,
    /// Swept angle evaluated at the last step.
    pub(super) last_step: f32,
    /// Rows: which way beams arrive (+1: highest first, −1: lowest first,
    /// 0: no order), the rows in the order they came, how many had come at
    /// the last step, and each step's final distances per column.
    pub(super) order: i8,
    pub(super) arrived: Vec<usize>,
    pub(super) rows_at_last_step: usize,
    pub(super) step_finals: Vec<Vec<[f32; 2]>>,
    /// When each line was acquired (0: not yet).
    pub(super) line_utimes: Vec<Utime>,
    /// Pose of the last step (the frame's last evaluation uses it).
    pub(super) pose: Option<Isometry>,
    pub(super) last_utime: Utime,
    /// Columns: the azimuth between neighbouring columns, once known (0).
    pub(super) column_step: f64,
}

/// The vehicle's pose at a time (interpolated between poses, or carried
/// past the newest): `None` when not known.
pub type PoseAt<'a> = &'a dyn Fn(Utime) -> Option<Isometry>;

/// A cell's place in the sensor frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct Place {
    pub(super) d: f64,
    /// Azimuth, sensor frame.
    pub(super) phi: f64,
}

/// The geometry of one evaluation: sensor frame, tilt margins.
pub(super) struct Geometry {
    pub(super) sensor_from_world: Isometry,
    /// Support radius with the tilt margin, m.
    pub(super) radius: f64,
    /// One cell diagonal plus the tilt margin, m.
    pub(super) grow: f64,
    /// The image filters' reach, radians of azimuth.
    pub(super) filter: f64,
}

impl Geometry {
    pub(super) fn new(
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

    pub(super) fn place(&self, cell: &ObstacleCell) -> Place {
        let z = 0.5 * (f64::from(cell.z_min) + f64::from(cell.z_max));
        let p = self.sensor_from_world * Point3::new(cell.x, cell.y, z);
        Place {
            d: p.x.hypot(p.y),
            phi: p.y.atan2(p.x),
        }
    }

    /// Half the azimuth span of a disc of `radius` at `d` (None: the disc
    /// holds the sensor's axis, every azimuth).
    pub(super) fn half_span(&self, d: f64, radius: f64) -> Option<f64> {
        (radius < d).then(|| (radius / d).asin() + self.filter)
    }
}

/// Angle from `from` to `to` in the direction `sweep` (±1), in [0, 2π).
pub(super) fn swept_angle(from: f32, to: f32, sweep: f32) -> f32 {
    (sweep * (to - from)).rem_euclid(std::f32::consts::TAU)
}

impl Frame {
    pub(super) fn new(slice: &RangeSlice) -> Self {
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
    pub(super) fn take(&mut self, slice: &RangeSlice) -> bool {
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

    pub(super) fn received_elevations(&self) -> (f32, f32) {
        self.received
            .iter()
            .zip(&self.image.beams.elevation)
            .filter(|(r, _)| **r)
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (_, &e)| {
                (a.min(e), b.max(e))
            })
    }

    pub(super) fn note_sweep(&mut self, c: usize, az: f32) {
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
    pub(super) fn geometry(&self, pose: &Isometry, support: Support, cell_size: f64) -> Geometry {
        Geometry::new(
            pose,
            &self.vehicle_from_sensor,
            support,
            cell_size,
            self.column_step(),
        )
    }

    /// Azimuth between neighbouring columns, radians (0.1 while unknown).
    pub(super) fn column_step(&self) -> f64 {
        if self.column_step > 0.0 {
            return self.column_step;
        }
        let step = smallest_step(&self.image.beams.azimuth);
        if step > 0.0 { step } else { 0.1 }
    }

    /// Elevation between neighbouring received rows, radians.
    pub(super) fn row_step(&self) -> f64 {
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
    pub(super) fn half_window(&self, support: Support, config: &StreamingConfig) -> f32 {
        let radius = (support.metres + TILT_HEIGHT_M * WINDOW_TILT_SIN).min(config.near_m * 0.99);
        ((radius / config.near_m).asin()
            + f64::from(support.pixels) * self.column_step()
            + support.radians) as f32
    }

    /// Columns: a step is due once `W` of sweep came in since the last.
    pub(super) fn columns_due(&self, support: Support, config: &StreamingConfig) -> bool {
        if !self.monotone || self.sweep == 0.0 || self.next == 0 {
            return false;
        }
        let top = self.swept[self.next - 1];
        top.is_finite() && top - self.last_step >= self.half_window(support, config)
    }

    /// Whether the disc of `radius` at `place` is complete now.
    pub(super) fn complete_now(&self, geometry: &Geometry, place: Place, radius: f64) -> bool {
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
    pub(super) fn ever_complete(&self, geometry: &Geometry, place: Place, radius: f64) -> bool {
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
    pub(super) fn span(
        &self,
        geometry: &Geometry,
        place: Place,
        radius: f64,
    ) -> Option<(f32, f32)> {
        let (_, az0) = self.reference?;
        let w = geometry.half_span(place.d, radius)? as f32;
        let a = swept_angle(az0, place.phi as f32, self.sweep);
        (a - w >= 0.0 && a + w < std::f32::consts::TAU).then_some((a - w, a + w))
    }

    pub(super) fn in_window(
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
    pub(super) fn complete_in(
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
    pub(super) fn rows_window(&mut self, filter: usize, reach: f32, rows: &mut Vec<usize>) {
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
    pub(super) fn deskewed(
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
    pub(super) fn nearest_column(&self, phi: f64) -> Option<usize> {
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
    pub(super) fn middle_pose(
        &self,
        lines: impl Iterator<Item = usize>,
        poses: PoseAt,
    ) -> Option<Isometry> {
        let (first, last) = self.span_of(lines)?;
        poses(first + (last - first) / 2)
    }

    /// Acquisition times of the given lines: the earliest and the latest.
    pub(super) fn span_of(&self, lines: impl Iterator<Item = usize>) -> Option<(Utime, Utime)> {
        lines
            .filter_map(|l| self.line_utimes.get(l).copied().filter(|&t| t != 0))
            .fold(None, |span, t| match span {
                None => Some((t, t)),
                Some((a, b)) => Some((a.min(t), b.max(t))),
            })
    }

    pub(super) fn copy_columns(&self, columns: std::ops::Range<usize>, sub: &mut RangeImage) {
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

    pub(super) fn copy_rows(&self, rows: &[usize], sub: &mut RangeImage) {
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
    pub(super) fn fill_missing_beams(&mut self) {
        fill_nan(&mut self.image.beams.elevation);
        fill_nan(&mut self.image.beams.azimuth);
    }
}

/// The smallest gap between neighbouring angles (0 when none), at most 0.1.
pub(super) fn smallest_step(angles: &[f32]) -> f64 {
    let step = angles
        .windows(2)
        .map(|w| f64::from((w[1] - w[0]).abs()))
        .filter(|s| s.is_finite() && *s > 0.0)
        .fold(f64::INFINITY, f64::min);
    if step.is_finite() { step.min(0.1) } else { 0.0 }
}

/// Replaces each NaN by the nearest finite value before it (or after it,
/// at the start); all NaN becomes zeros.
pub(super) fn fill_nan(values: &mut [f32]) {
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
