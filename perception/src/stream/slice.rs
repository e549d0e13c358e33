//! `range_slice_t` as perception takes it: a part of a range image (some
//! columns of a spinning lidar, some rows of a scanning one), checked
//! before it is used.

use arcnav_vehicle::{Isometry, Utime};

use crate::image::{BeamTable, ImageError, RangeImage};

/// The most pixels a streamed frame may declare: 2²¹ (a 128 × 16 384
/// image, eight times the densest spinning lidar's 128 × 2048). The frame
/// buffer is allocated, and each frame evaluated whole, from the slice's
/// word: at 2²⁴, 68 kB of slices declaring 64 × 262 144 frames had taken
/// replay to 2.9 GB.
pub const MAX_FRAME_PIXELS: usize = 1 << 21;

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
