//! A `sensor_msgs/PointCloud2` as a range image, with the beam angles the
//! cloud itself gives.
//!
//! - An *organized* cloud (height > 1: Ouster's 64 × 1024, say) keeps its
//!   rows and columns. Each row's elevation is the mean elevation of its
//!   returns, each column's azimuth their circular mean; a return whose
//!   direction lies more than half a pixel from its pixel's (a real
//!   sensor's per-beam azimuth offsets) goes to the pixel its direction
//!   falls in, and is counted as moved.
//! - An unorganized cloud with a `ring` field (Velodyne) is binned by ring
//!   (a row per ring, its elevation the ring's mean) and by azimuth into
//!   the configured sensor's columns (`[sensor]`: a 360° lidar's cover the
//!   circle).
//! - Any other cloud is binned on the configured sensor's grid (`[sensor]`
//!   or a `--sensor` preset): nearest row by elevation, nearest column by
//!   azimuth; a return off the grid by more than half a pixel is counted
//!   and left out.
//!
//! A per-point time field (`t`, `time`, `timestamp`, `time_offset`: an
//! integer field in nanoseconds, a float field in seconds; relative to the
//! header's stamp unless it is past 1e8 s, an absolute time) gives each
//! column of the image its time: the latest of its points'. A replay then
//! streams the image as slices of columns acquired at those times.
//!
//! A point with a coordinate that is not finite, or at the origin, is "no
//! return". Two returns in one pixel: the nearer is kept (the other
//! counted). Every size is checked before anything is allocated.

use std::f64::consts::{PI, TAU};

use arcnav_perception::BeamTable;
use arcnav_vehicle::Utime;
use serde::Serialize;

use super::msgs::{PointCloud2, PointField};

/// The most rows a cloud's image may have (rings, or an organized
/// cloud's height).
pub const MAX_ROWS: usize = 1024;

/// What became of a cloud's points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CloudCounts {
    /// Points read.
    pub points: u64,
    /// Of those, no return (not finite, or at the sensor).
    pub no_return: u64,
    /// Returns put in another pixel than the cloud's own (organized).
    pub moved: u64,
    /// Returns behind a nearer one in the same pixel.
    pub hidden: u64,
    /// Returns off the grid they were binned on.
    pub off_grid: u64,
}

impl CloudCounts {
    pub fn add(&mut self, other: &Self) {
        self.points += other.points;
        self.no_return += other.no_return;
        self.moved += other.moved;
        self.hidden += other.hidden;
        self.off_grid += other.off_grid;
    }
}

/// How a cloud was laid out as an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    Organized,
    Rings,
    SensorGrid,
}

/// A cloud that cannot be made an image.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CloudError {
    #[error("no {0} field of 32- or 64-bit floats")]
    NoCoordinate(&'static str),
    #[error(
        "field {name} (type {datatype}, {count} values at offset {offset}) does not fit a point of {point_step} bytes"
    )]
    FieldOutside {
        name: String,
        datatype: u8,
        count: u32,
        offset: u32,
        point_step: u32,
    },
    #[error(
        "{width} × {height} points of {point_step} bytes in rows of {row_step} do not fit its {bytes} bytes of data"
    )]
    Size {
        width: u32,
        height: u32,
        point_step: u32,
        row_step: u32,
        bytes: usize,
    },
    #[error("{points} points, more than the {limit} a range image may hold")]
    TooLarge { points: u64, limit: u64 },
    #[error("{rows} rows (rings), more than {MAX_ROWS}")]
    TooManyRows { rows: u64 },
}

/// A field's place and type in a point.
#[derive(Debug, Clone, Copy)]
struct Field {
    offset: usize,
    datatype: u8,
}

/// Bytes of one value of a `PointField` datatype (1 INT8 ... 8 FLOAT64).
fn datatype_size(datatype: u8) -> Option<usize> {
    match datatype {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

impl Field {
    fn find(
        fields: &[PointField],
        name: &str,
        point_step: u32,
    ) -> Result<Option<Self>, CloudError> {
        let Some(f) = fields.iter().find(|f| f.name == name) else {
            return Ok(None);
        };
        let outside = || CloudError::FieldOutside {
            name: f.name.clone(),
            datatype: f.datatype,
            count: f.count,
            offset: f.offset,
            point_step,
        };
        let size = datatype_size(f.datatype).ok_or_else(outside)?;
        let end = (f.offset as usize).checked_add(size).ok_or_else(outside)?;
        if end > point_step as usize {
            return Err(outside());
        }
        Ok(Some(Self {
            offset: f.offset as usize,
            datatype: f.datatype,
        }))
    }

    /// The value in `point` (whose length the field fits, checked in
    /// [`find`](Self::find)), as f64.
    fn read(self, point: &[u8], big_endian: bool) -> f64 {
        let size = datatype_size(self.datatype).unwrap_or(1);
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(&point[self.offset..self.offset + size]);
        if big_endian {
            b[..size].reverse();
        }
        let [b0, b1, b2, b3, ..] = b;
        match self.datatype {
            1 => f64::from(b0 as i8),
            2 => f64::from(b0),
            3 => f64::from(i16::from_le_bytes([b0, b1])),
            4 => f64::from(u16::from_le_bytes([b0, b1])),
            5 => f64::from(i32::from_le_bytes([b0, b1, b2, b3])),
            6 => f64::from(u32::from_le_bytes([b0, b1, b2, b3])),
            7 => f64::from(f32::from_le_bytes([b0, b1, b2, b3])),
            _ => f64::from_le_bytes(b),
        }
    }
}

/// One return: its range and direction, and the ring it came from.
#[derive(Debug, Clone, Copy)]
struct Return {
    range: f64,
    elevation: f64,
    azimuth: f64,
    /// The organized cloud's pixel, or the ring (row) and no column.
    row: usize,
    col: Option<usize>,
    /// When it was taken (µs), from a per-point time field.
    time: Option<Utime>,
}

/// The cloud as an image: its beam table and ranges (row-major), and what
/// became of its points.
#[derive(Debug, Clone)]
pub struct CloudImage {
    pub beams: BeamTable,
    pub range: Vec<f32>,
    pub layout: Layout,
    pub counts: CloudCounts,
    /// From a per-point time field: its name, and each column's time (µs;
    /// a column none of whose points has one takes its neighbour's).
    pub line_utimes: Option<(String, Vec<Utime>)>,
}

/// The names a per-point time field goes by.
const TIME_FIELDS: [&str; 4] = ["t", "time", "timestamp", "time_offset"];

/// The name of `fields`' per-point time field (32- or 64-bit, integer
/// or float), if it has one.
pub fn time_field(fields: &[PointField]) -> Option<&'static str> {
    TIME_FIELDS.into_iter().find(|name| {
        fields
            .iter()
            .any(|f| f.name == *name && (5..=8).contains(&f.datatype))
    })
}

/// Past this many seconds a point's time is absolute (since the epoch),
/// not an offset from the header's stamp.
const ABSOLUTE_S: f64 = 1e8;

/// `cloud` as a range image. `grid` is the configured sensor's beam table
/// (the columns of a ring cloud, the whole grid of any other unorganized
/// one; the spacing of an organized one's rows where none returned);
/// `max_pixels` bounds the image.
pub fn to_image(
    cloud: &PointCloud2<'_>,
    grid: &BeamTable,
    max_pixels: u64,
) -> Result<CloudImage, CloudError> {
    let step = cloud.point_step;
    let coordinate = |name: &'static str| -> Result<Field, CloudError> {
        Field::find(&cloud.fields, name, step)?
            .filter(|f| matches!(f.datatype, 7 | 8))
            .ok_or(CloudError::NoCoordinate(name))
    };
    let (fx, fy, fz) = (coordinate("x")?, coordinate("y")?, coordinate("z")?);
    let ring = Field::find(&cloud.fields, "ring", step)?.filter(|f| f.datatype <= 6);
    let time = match time_field(&cloud.fields) {
        // One that does not fit the point is no time: the cloud is then
        // one image at its stamp.
        Some(name) => Field::find(&cloud.fields, name, step)
            .ok()
            .flatten()
            .map(|f| (name, f)),
        None => None,
    };
    let stamp = cloud.header.stamp.utime();
    // A point's time, µs, if it has one that is a time.
    let time_of = |point: &[u8]| -> Option<Utime> {
        let (_, f) = time?;
        let v = f.read(point, cloud.is_bigendian);
        let seconds = if f.datatype <= 6 { v * 1e-9 } else { v };
        let at = if seconds.abs() > ABSOLUTE_S {
            seconds * 1e6
        } else {
            stamp as f64 + seconds * 1e6
        };
        (at.is_finite() && at.abs() < 9.0e15).then(|| at.round() as Utime)
    };
    let (width, height) = (u64::from(cloud.width), u64::from(cloud.height));
    let points = width * height;
    if points > max_pixels {
        return Err(CloudError::TooLarge {
            points,
            limit: max_pixels,
        });
    }
    let size_error = || CloudError::Size {
        width: cloud.width,
        height: cloud.height,
        point_step: step,
        row_step: cloud.row_step,
        bytes: cloud.data.len(),
    };
    let row_bytes = u64::from(cloud.row_step);
    if u64::from(step) * width > row_bytes
        || (height > 0
            && row_bytes * (height - 1) + u64::from(step) * width > cloud.data.len() as u64)
        || (step == 0 && points > 0)
    {
        return Err(size_error());
    }
    let layout = if height > 1 {
        Layout::Organized
    } else if ring.is_some() {
        Layout::Rings
    } else {
        Layout::SensorGrid
    };
    let mut counts = CloudCounts {
        points,
        ..CloudCounts::default()
    };
    // Every return, read once; an organized cloud's columns' times.
    let mut returns = Vec::with_capacity(points as usize);
    let mut column_times: Vec<Option<Utime>> = match (layout, time) {
        (Layout::Organized, Some(_)) => vec![None; width as usize],
        _ => Vec::new(),
    };
    let mut max_ring = 0usize;
    for r in 0..height as usize {
        for c in 0..width as usize {
            let at = r * cloud.row_step as usize + c * step as usize;
            let point = &cloud.data[at..at + step as usize];
            let (x, y, z) = (
                fx.read(point, cloud.is_bigendian),
                fy.read(point, cloud.is_bigendian),
                fz.read(point, cloud.is_bigendian),
            );
            let at_time = time_of(point);
            if let (Some(t), Some(slot)) = (at_time, column_times.get_mut(c)) {
                *slot = Some(slot.map_or(t, |s: Utime| s.max(t)));
            }
            let range = (x * x + y * y + z * z).sqrt();
            if !range.is_finite() || range < 1e-6 {
                counts.no_return += 1;
                continue;
            }
            let (row, col) = match layout {
                Layout::Organized => (r, Some(c)),
                Layout::Rings => {
                    let ring = ring.map_or(0.0, |f| f.read(point, cloud.is_bigendian));
                    if !(0.0..MAX_ROWS as f64).contains(&ring) {
                        return Err(CloudError::TooManyRows {
                            rows: ring.max(0.0) as u64 + 1,
                        });
                    }
                    max_ring = max_ring.max(ring as usize);
                    (ring as usize, None)
                }
                Layout::SensorGrid => (0, None),
            };
            returns.push(Return {
                range,
                elevation: z.atan2(x.hypot(y)),
                azimuth: y.atan2(x),
                row,
                col,
                time: at_time,
            });
        }
    }
    let beams = match layout {
        Layout::Organized => {
            if height as usize > MAX_ROWS {
                return Err(CloudError::TooManyRows { rows: height });
            }
            organized_table(&returns, height as usize, width as usize, grid)
        }
        Layout::Rings => BeamTable {
            elevation: row_means(&returns, max_ring + 1, grid),
            azimuth: grid.azimuth.clone(),
        },
        Layout::SensorGrid => grid.clone(),
    };
    let (rows, cols) = (beams.rows(), beams.cols());
    if (rows * cols) as u64 > max_pixels {
        return Err(CloudError::TooLarge {
            points: (rows * cols) as u64,
            limit: max_pixels,
        });
    }
    let mut range = vec![f32::NAN; rows * cols];
    let by_elevation = Nearest::new(&beams.elevation, false);
    let by_azimuth = Nearest::new(&beams.azimuth, true);
    for ret in &returns {
        let own = match (layout, ret.col) {
            (Layout::Organized, Some(c)) => {
                let (el, az) = (
                    f64::from(beams.elevation[ret.row]),
                    f64::from(beams.azimuth[c]),
                );
                let near = (ret.elevation - el).abs() <= by_elevation.half_step(ret.row)
                    && angle_between(ret.azimuth, az) <= by_azimuth.half_step(c);
                near.then_some((ret.row, c))
            }
            _ => None,
        };
        let pixel = match (own, layout) {
            (Some(pixel), _) => Some(pixel),
            (None, Layout::Rings) => by_azimuth.find(ret.azimuth).map(|c| (ret.row, c)),
            (None, _) => by_elevation
                .find(ret.elevation)
                .zip(by_azimuth.find(ret.azimuth)),
        };
        let Some((r, c)) = pixel else {
            counts.off_grid += 1;
            continue;
        };
        if layout != Layout::Organized
            && let Some(t) = ret.time
        {
            if column_times.is_empty() {
                column_times = vec![None; cols];
            }
            column_times[c] = Some(column_times[c].map_or(t, |s: Utime| s.max(t)));
        }
        if own.is_none() && layout == Layout::Organized {
            counts.moved += 1;
        }
        let slot = &mut range[r * cols + c];
        if slot.is_nan() {
            *slot = ret.range as f32;
        } else {
            counts.hidden += 1;
            *slot = slot.min(ret.range as f32);
        }
    }
    let line_utimes = time
        .filter(|_| column_times.iter().any(Option::is_some))
        .map(|(name, _)| (name.to_owned(), fill_times(&column_times, cols, stamp)));
    Ok(CloudImage {
        beams,
        range,
        layout,
        counts,
        line_utimes,
    })
}

/// `cols` columns' times, each that has none taking the last known before
/// it (the first known, before any; `stamp` when none is known).
fn fill_times(known: &[Option<Utime>], cols: usize, stamp: Utime) -> Vec<Utime> {
    let first = known.iter().flatten().next().copied().unwrap_or(stamp);
    let mut last = first;
    (0..cols)
        .map(|c| {
            if let Some(Some(t)) = known.get(c) {
                last = *t;
            }
            last
        })
        .collect()
}

/// The absolute difference of two angles, radians, in [0, π].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    d.min(TAU - d)
}

/// Each row's mean elevation over its returns; a row with none is filled
/// in from its neighbours (or from the configured grid's spacing).
fn row_means(returns: &[Return], rows: usize, grid: &BeamTable) -> Vec<f32> {
    let mut sums = vec![(0.0f64, 0u32); rows];
    for ret in returns {
        if let Some(s) = sums.get_mut(ret.row) {
            s.0 += ret.elevation;
            s.1 += 1;
        }
    }
    let spacing = grid_spacing(&grid.elevation);
    fill(
        sums.iter().map(|&(s, n)| (n > 0).then(|| s / f64::from(n))),
        -spacing,
    )
}

/// The table of an organized cloud: rows' mean elevations, columns'
/// circular mean azimuths, gaps filled in.
fn organized_table(returns: &[Return], rows: usize, cols: usize, grid: &BeamTable) -> BeamTable {
    let mut columns = vec![(0.0f64, 0.0f64, 0u32); cols];
    for ret in returns {
        if let Some(c) = ret.col.and_then(|c| columns.get_mut(c)) {
            c.0 += ret.azimuth.sin();
            c.1 += ret.azimuth.cos();
            c.2 += 1;
        }
    }
    let spacing = -TAU / cols.max(1) as f64;
    let azimuth = fill_angles(
        columns.iter().map(|&(s, c, n)| (n > 0).then(|| s.atan2(c))),
        spacing,
    );
    BeamTable {
        elevation: row_means(returns, rows, grid),
        azimuth,
    }
}

/// The mean step between a table's neighbours (its sign too), radians; a
/// degree when it has fewer than two.
fn grid_spacing(table: &[f32]) -> f64 {
    match (table.first(), table.last()) {
        (Some(&a), Some(&b)) if table.len() > 1 => {
            (f64::from(b) - f64::from(a)) / (table.len() - 1) as f64
        }
        _ => 1f64.to_radians(),
    }
    .abs()
}

/// Values with gaps filled: between two known ones linearly, before the
/// first and after the last by `step` a place; all `step` apart from 0
/// when none is known.
fn fill(values: impl Iterator<Item = Option<f64>>, step: f64) -> Vec<f32> {
    let known: Vec<Option<f64>> = values.collect();
    let at: Vec<(usize, f64)> = known
        .iter()
        .enumerate()
        .filter_map(|(i, v)| v.map(|v| (i, v)))
        .collect();
    (0..known.len())
        .map(|i| {
            let before = at.iter().rev().find(|(j, _)| *j <= i);
            let after = at.iter().find(|(j, _)| *j >= i);
            let v = match (before, after) {
                (Some(&(j, a)), Some(&(k, b))) if k > j => {
                    a + (b - a) * (i - j) as f64 / (k - j) as f64
                }
                (Some(&(j, a)), _) => a + step * (i - j) as f64,
                (None, Some(&(k, b))) => b - step * (k - i) as f64,
                (None, None) => step * i as f64,
            };
            v as f32
        })
        .collect()
}

/// [`fill`] for angles: unwrapped first so that a gap across ±π fills
/// the short way, wrapped back to (-π, π] after.
fn fill_angles(values: impl Iterator<Item = Option<f64>>, step: f64) -> Vec<f32> {
    let mut previous: Option<f64> = None;
    let unwrapped = values.map(|v| {
        v.map(|a| {
            let a = match previous {
                Some(p) => p + (a - p + PI).rem_euclid(TAU) - PI,
                None => a,
            };
            previous = Some(a);
            a
        })
    });
    fill(unwrapped, step)
        .into_iter()
        .map(|a| {
            let a = f64::from(a);
            (a - TAU * ((a + PI) / TAU).floor()) as f32
        })
        .collect()
}

/// The entry of a table of angles nearest an angle, within half the
/// spacing of its neighbours.
struct Nearest {
    /// (angle, index), sorted by angle.
    sorted: Vec<(f64, usize)>,
    /// Half the distance to each entry's nearer neighbour in the table.
    half: Vec<f64>,
    wraps: bool,
}

impl Nearest {
    fn new(table: &[f32], wraps: bool) -> Self {
        let mut sorted: Vec<(f64, usize)> = table
            .iter()
            .enumerate()
            .map(|(i, &a)| (f64::from(a), i))
            .collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let n = table.len();
        let gap = |i: usize, j: usize| -> f64 {
            let d = (f64::from(table[i]) - f64::from(table[j])).abs();
            if wraps { d.min(TAU - d) } else { d }
        };
        let half = (0..n)
            .map(|i| {
                let neighbours = [i.checked_sub(1), (i + 1 < n).then_some(i + 1)];
                let nearest = neighbours
                    .iter()
                    .flatten()
                    .map(|&j| gap(i, j))
                    .fold(f64::INFINITY, f64::min);
                if nearest.is_finite() {
                    0.5 * nearest
                } else {
                    0.5f64.to_radians()
                }
            })
            .collect();
        Self {
            sorted,
            half,
            wraps,
        }
    }

    fn half_step(&self, index: usize) -> f64 {
        self.half.get(index).copied().unwrap_or(0.0)
    }

    /// The index whose angle is nearest `angle`, if within its half step.
    fn find(&self, angle: f64) -> Option<usize> {
        let at = self.sorted.partition_point(|&(a, _)| a < angle);
        let mut candidates = [
            at.checked_sub(1),
            (at < self.sorted.len()).then_some(at),
            None,
            None,
        ];
        if self.wraps && !self.sorted.is_empty() {
            candidates[2] = Some(0);
            candidates[3] = Some(self.sorted.len() - 1);
        }
        let distance = |a: f64| {
            if self.wraps {
                angle_between(angle, a)
            } else {
                (angle - a).abs()
            }
        };
        candidates
            .iter()
            .flatten()
            .map(|&k| self.sorted[k])
            .min_by(|a, b| distance(a.0).total_cmp(&distance(b.0)))
            .filter(|&(a, i)| distance(a) <= self.half_step(i) * (1.0 + 1e-9))
            .map(|(_, i)| i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bag::msgs::Header;
    use crate::bag::msgs::Time;

    /// Fields x, y and z, float32, from offset 0.
    fn xyz_fields() -> Vec<PointField> {
        ["x", "y", "z"]
            .iter()
            .enumerate()
            .map(|(i, name)| PointField {
                name: name.to_string(),
                offset: 4 * i as u32,
                datatype: 7,
                count: 1,
            })
            .collect()
    }

    /// A cloud of `(x, y, z)` float32 points (and a ring, u16, when given),
    /// `width × height`.
    fn cloud(
        points: &[([f32; 3], Option<u16>)],
        width: u32,
        height: u32,
    ) -> (Vec<PointField>, Vec<u8>) {
        let mut fields = xyz_fields();
        if points.iter().any(|p| p.1.is_some()) {
            fields.push(PointField {
                name: "ring".into(),
                offset: 12,
                datatype: 4,
                count: 1,
            });
        }
        let mut data = Vec::new();
        for (p, ring) in points {
            for v in p {
                data.extend_from_slice(&v.to_le_bytes());
            }
            data.extend_from_slice(&ring.unwrap_or(0).to_le_bytes());
            data.extend_from_slice(&[0, 0]);
        }
        assert_eq!(data.len(), (width * height * 16) as usize);
        (fields, data)
    }

    fn message<'a>(
        fields: Vec<PointField>,
        data: &'a [u8],
        width: u32,
        height: u32,
    ) -> PointCloud2<'a> {
        PointCloud2 {
            header: Header {
                stamp: Time { sec: 1, nanosec: 0 },
                frame_id: "lidar".into(),
            },
            height,
            width,
            fields,
            is_bigendian: false,
            point_step: 16,
            row_step: 16 * width,
            data: std::borrow::Cow::Borrowed(data),
            is_dense: false,
        }
    }

    fn point(range: f64, el_deg: f64, az_deg: f64) -> [f32; 3] {
        let (el, az) = (el_deg.to_radians(), az_deg.to_radians());
        [
            (range * el.cos() * az.cos()) as f32,
            (range * el.cos() * az.sin()) as f32,
            (range * el.sin()) as f32,
        ]
    }

    /// A 2 × 4 organized cloud (x, y, z float32, then a time field of
    /// `datatype` named `name`, 8 bytes wide) whose column `c` was taken at
    /// `times[c]` (in the field's unit); one column returns nothing.
    fn timed(name: &str, datatype: u8, times: [f64; 4]) -> (Vec<PointField>, Vec<u8>) {
        let mut fields = xyz_fields();
        fields.push(PointField {
            name: name.into(),
            offset: 12,
            datatype,
            count: 1,
        });
        let mut data = Vec::new();
        for el in [1.0, -1.0] {
            for (c, az) in [30.0, 10.0, -10.0, -30.0].into_iter().enumerate() {
                let p = if c == 2 {
                    [f32::NAN; 3]
                } else {
                    point(10.0, el, az)
                };
                for v in p {
                    data.extend_from_slice(&v.to_le_bytes());
                }
                let t = times[c];
                let mut field = [0u8; 8];
                match datatype {
                    6 => field[..4].copy_from_slice(&(t as u32).to_le_bytes()),
                    7 => field[..4].copy_from_slice(&(t as f32).to_le_bytes()),
                    _ => field.copy_from_slice(&t.to_le_bytes()),
                }
                data.extend_from_slice(&field);
            }
        }
        (fields, data)
    }

    #[test]
    fn a_per_point_time_field_gives_each_column_its_time() {
        let with_step = |fields, data: &[u8]| {
            let mut m = message(fields, data, 4, 2);
            m.point_step = 20;
            m.row_step = 80;
            to_image(&m, &BeamTable::uniform(2, 4, 0.1, -0.1, 1.0, -1.0), 1 << 20).unwrap()
        };
        // The stamp is 1 s; Ouster's `t`: ns after it. The column without
        // a return still has its points' time.
        let (fields, data) = timed("t", 6, [0.0, 25e6, 50e6, 75e6]);
        let image = with_step(fields, &data);
        let (name, times) = image.line_utimes.unwrap();
        assert_eq!(name, "t");
        assert_eq!(times, [1_000_000, 1_025_000, 1_050_000, 1_075_000]);
        // Velodyne's `time`: float32 s after the stamp.
        let (fields, data) = timed("time", 7, [0.0, 0.025, 0.05, 0.075]);
        let (_, times) = with_step(fields, &data).line_utimes.unwrap();
        assert_eq!(times, [1_000_000, 1_025_000, 1_050_000, 1_075_000]);
        // Hesai's `timestamp`: float64 s since the epoch.
        let (fields, data) = timed(
            "timestamp",
            8,
            [1.7e9, 1.7e9 + 0.025, 1.7e9 + 0.05, 1.7e9 + 0.075],
        );
        let (_, times) = with_step(fields, &data).line_utimes.unwrap();
        assert_eq!(
            times,
            [
                1_700_000_000_000_000,
                1_700_000_000_025_000,
                1_700_000_000_050_000,
                1_700_000_000_075_000
            ]
        );
        // No such field: no times.
        let (fields, data) = timed("intensity", 7, [0.0; 4]);
        assert!(with_step(fields, &data).line_utimes.is_none());
    }

    #[test]
    fn an_organized_cloud_keeps_its_rows_and_columns_and_takes_its_angles_from_its_points() {
        // 3 rows × 4 columns, one point missing (NaN), one at the origin.
        let (els, azs) = ([2.0, 0.0, -2.0], [30.0, 10.0, -10.0, -30.0]);
        let mut points = Vec::new();
        for (r, el) in els.iter().enumerate() {
            for (c, az) in azs.iter().enumerate() {
                let p = match (r, c) {
                    (1, 1) => [f32::NAN; 3],
                    (2, 3) => [0.0; 3],
                    _ => point(10.0 + r as f64 + c as f64, *el, *az),
                };
                points.push((p, None));
            }
        }
        let (fields, data) = cloud(&points, 4, 3);
        let grid = BeamTable::uniform(8, 16, 0.2, -0.2, 3.0, -3.0);
        let image = to_image(&message(fields, &data, 4, 3), &grid, 1 << 20).unwrap();
        assert_eq!(image.layout, Layout::Organized);
        assert_eq!((image.beams.rows(), image.beams.cols()), (3, 4));
        for (got, want) in image.beams.elevation.iter().zip(els) {
            assert!(
                (f64::from(*got) - f64::to_radians(want)).abs() < 1e-6,
                "{got} {want}"
            );
        }
        for (got, want) in image.beams.azimuth.iter().zip(azs) {
            assert!(
                (f64::from(*got) - f64::to_radians(want)).abs() < 1e-6,
                "{got} {want}"
            );
        }
        assert!((image.range[0] - 10.0).abs() < 1e-5);
        assert!((image.range[2 * 4 + 2] - 14.0).abs() < 1e-5);
        assert!(image.range[4 + 1].is_nan() && image.range[2 * 4 + 3].is_nan());
        assert_eq!(image.counts.no_return, 2);
        assert_eq!((image.counts.moved, image.counts.hidden), (0, 0));
    }

    #[test]
    fn a_return_off_its_column_by_more_than_half_a_pixel_is_moved_to_the_one_it_falls_in() {
        // Two rows × 8 columns 10° apart; row 1 is staggered by 6° (a real
        // sensor's beam offset).
        let mut points = Vec::new();
        for r in 0..2 {
            for c in 0..8 {
                let az = 35.0 - 10.0 * c as f64 - if r == 1 { 6.0 } else { 0.0 };
                points.push((point(5.0 + c as f64, 1.0 - 2.0 * r as f64, az), None));
            }
        }
        let (fields, data) = cloud(&points, 8, 2);
        let grid = BeamTable::uniform(2, 8, 0.1, -0.1, 1.0, -1.0);
        let image = to_image(&message(fields, &data, 8, 2), &grid, 1 << 20).unwrap();
        // The columns' azimuths are the mean of both rows (3° off each):
        // within half a pixel, so every return stays.
        assert_eq!(image.counts.moved, 0, "{:?}", image.beams.azimuth);
        // Staggered by two columns, row 1's returns move.
        let mut points = Vec::new();
        for r in 0..2 {
            for c in 0..8 {
                let az = 35.0 - 10.0 * c as f64 - if r == 1 { 20.0 } else { 0.0 };
                points.push((point(5.0 + c as f64, 1.0 - 2.0 * r as f64, az), None));
            }
        }
        let (fields, data) = cloud(&points, 8, 2);
        let image = to_image(&message(fields, &data, 8, 2), &grid, 1 << 20).unwrap();
        assert!(image.counts.moved >= 8, "{:?}", image.counts);
        assert_eq!(image.counts.points, 16);
    }

    #[test]
    fn a_ring_cloud_is_binned_by_ring_and_azimuth_and_the_nearer_of_two_returns_kept() {
        let points = [
            (point(10.0, 5.0, 0.2), Some(0)),
            (point(8.0, 5.0, 0.3), Some(0)),
            (point(12.0, -5.0, 90.0), Some(2)),
        ];
        let (fields, data) = cloud(&points, 3, 1);
        let grid = BeamTable::uniform(4, 360, 0.2, -0.2, PI, -PI);
        let image = to_image(&message(fields, &data, 3, 1), &grid, 1 << 20).unwrap();
        assert_eq!(image.layout, Layout::Rings);
        assert_eq!((image.beams.rows(), image.beams.cols()), (3, 360));
        assert!((f64::from(image.beams.elevation[2]) + 5f64.to_radians()).abs() < 1e-6);
        // Ring 1 has no return: between its neighbours.
        assert!(f64::from(image.beams.elevation[1]).abs() < 1e-6);
        assert_eq!(image.counts.hidden, 1);
        let kept: Vec<f32> = image
            .range
            .iter()
            .copied()
            .filter(|r| !r.is_nan())
            .collect();
        assert_eq!(kept.len(), 2);
        assert!(kept.iter().any(|r| (r - 8.0).abs() < 1e-5));
    }

    #[test]
    fn any_other_cloud_is_binned_on_the_sensor_grid_and_what_is_off_it_counted() {
        let points = [
            (point(10.0, 0.0, 0.0), None),
            (point(10.0, 40.0, 0.0), None),
        ];
        let (fields, data) = cloud(&points, 2, 1);
        let grid = BeamTable::uniform(16, 64, 0.2, -0.2, 0.5, -0.5);
        let image = to_image(&message(fields, &data, 2, 1), &grid, 1 << 20).unwrap();
        assert_eq!(image.layout, Layout::SensorGrid);
        assert_eq!(image.beams, grid);
        assert_eq!(image.counts.off_grid, 1);
        assert_eq!(image.range.iter().filter(|r| !r.is_nan()).count(), 1);
    }

    #[test]
    fn clouds_whose_sizes_do_not_add_up_are_refused_before_anything_is_allocated() {
        let points = [(point(10.0, 0.0, 0.0), None)];
        let (fields, data) = cloud(&points, 1, 1);
        let grid = BeamTable::uniform(2, 2, 0.2, -0.2, 0.5, -0.5);
        let mut big = message(fields.clone(), &data, 1, 1);
        big.width = u32::MAX;
        big.height = u32::MAX;
        assert!(matches!(
            to_image(&big, &grid, 1 << 20),
            Err(CloudError::TooLarge { .. })
        ));
        let mut short = message(fields.clone(), &data, 1, 1);
        short.width = 2;
        short.row_step = 32;
        assert!(matches!(
            to_image(&short, &grid, 1 << 20),
            Err(CloudError::Size { .. })
        ));
        let mut outside = message(fields.clone(), &data, 1, 1);
        outside.fields[2].offset = 14;
        assert!(matches!(
            to_image(&outside, &grid, 1 << 20),
            Err(CloudError::FieldOutside { .. })
        ));
        let mut no_z = message(fields, &data, 1, 1);
        no_z.fields.remove(2);
        assert_eq!(
            to_image(&no_z, &grid, 1 << 20).unwrap_err(),
            CloudError::NoCoordinate("z")
        );
    }
}
