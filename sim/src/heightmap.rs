//! Height fields read from files: NumPy `.npy` arrays and ESRI ASCII grids
//! (`.asc`), sampled with Catmull-Rom bicubic interpolation so that a coarse
//! DEM gives smooth ground (continuous slopes, no facets).
//!
//! Rows run north to south (row 0 is the northern edge), as in an ESRI grid
//! and in an image; columns west to east. The grid's `origin` is the world
//! position of the centre of its south-west sample.

use crate::numbers::floor;
use std::path::{Path, PathBuf};

/// A height file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("height file {path}: {reason}")]
pub struct HeightmapError {
    pub path: PathBuf,
    pub reason: String,
}

/// A regular grid of heights.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightGrid {
    pub cols: usize,
    pub rows: usize,
    /// Sample spacing, m.
    pub resolution: f64,
    /// World (x, y) of the south-west sample.
    pub origin: [f64; 2],
    /// Row-major, north row first; NaN where the file has no data.
    pub values: Vec<f32>,
}

/// The largest height file read: 1 GiB (a 16 384² grid of doubles is 2 GiB;
/// resample such a DEM before use).
pub const MAX_HEIGHT_FILE_BYTES: u64 = 1 << 30;

impl HeightGrid {
    /// Loads `.npy` or `.asc` by extension; `resolution`/`origin` are
    /// required for `.npy` and override the header of `.asc` when given.
    pub fn load(
        path: &Path,
        resolution: Option<f64>,
        origin: Option<[f64; 2]>,
    ) -> Result<Self, HeightmapError> {
        let bytes =
            arcnav_vehicle::files::read_bounded(path, MAX_HEIGHT_FILE_BYTES).map_err(|e| {
                HeightmapError {
                    path: path.to_owned(),
                    reason: format!("cannot read it: {e}"),
                }
            })?;
        Self::parse(path, bytes, resolution, origin)
    }

    /// Parses the bytes of the height file `path` (named in messages, its
    /// extension telling the format).
    pub fn parse(
        path: &Path,
        bytes: Vec<u8>,
        resolution: Option<f64>,
        origin: Option<[f64; 2]>,
    ) -> Result<Self, HeightmapError> {
        let fail = |reason: String| HeightmapError {
            path: path.to_owned(),
            reason,
        };
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let mut grid = match extension.as_str() {
            "npy" => {
                let (rows, cols, values) = parse_npy(&bytes).map_err(fail)?;
                let resolution = resolution
                    .ok_or_else(|| fail("a .npy height file needs resolution_m".into()))?;
                HeightGrid {
                    cols,
                    rows,
                    resolution,
                    origin: origin.unwrap_or([0.0, 0.0]),
                    values,
                }
            }
            "asc" => {
                let text = String::from_utf8(bytes).map_err(|_| fail("not a text file".into()))?;
                let mut grid = parse_asc(&text).map_err(fail)?;
                if let Some(r) = resolution {
                    grid.resolution = r;
                }
                if let Some(o) = origin {
                    grid.origin = o;
                }
                grid
            }
            other => {
                return Err(fail(format!(
                    "unknown height file type {other:?} (known: npy, asc)"
                )));
            }
        };
        if !(grid.resolution.is_finite() && grid.resolution > 0.0) {
            return Err(fail(format!(
                "resolution {} m is not positive",
                grid.resolution
            )));
        }
        if grid.rows < 2 || grid.cols < 2 {
            return Err(fail(format!(
                "{} × {} samples: at least 2 × 2 are needed",
                grid.rows, grid.cols
            )));
        }
        // Gaps become the lowest valid height (conservative: a hole, not a hill).
        let floor = grid
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f32::INFINITY, f32::min);
        if !floor.is_finite() {
            return Err(fail("holds no valid height".into()));
        }
        for v in &mut grid.values {
            if !v.is_finite() {
                *v = floor;
            }
        }
        // Within the world file's bound on its numbers (scale included,
        // the heights stay finite as f32 cells).
        let max = crate::numbers::MAX_MAGNITUDE;
        if let Some(v) = grid.values.iter().find(|v| f64::from(v.abs()) > max) {
            return Err(fail(format!(
                "holds a height of {v} m: heights lie within ±{max} m"
            )));
        }
        Ok(grid)
    }

    /// World extent: (min x, min y, max x, max y).
    pub fn bounds(&self) -> [f64; 4] {
        [
            self.origin[0],
            self.origin[1],
            self.origin[0] + (self.cols - 1) as f64 * self.resolution,
            self.origin[1] + (self.rows - 1) as f64 * self.resolution,
        ]
    }

    fn sample(&self, col: i64, row_from_south: i64) -> f64 {
        let c = col.clamp(0, self.cols as i64 - 1) as usize;
        let r = row_from_south.clamp(0, self.rows as i64 - 1) as usize;
        f64::from(self.values[(self.rows - 1 - r) * self.cols + c])
    }

    /// Height at world (x, y), bicubic; clamped to the edge outside the grid.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let fx = (x - self.origin[0]) / self.resolution;
        let fy = (y - self.origin[1]) / self.resolution;
        let (cx, cy) = (floor(fx), floor(fy));
        let (tx, ty) = (fx - cx as f64, fy - cy as f64);
        let mut column = [0.0; 4];
        for (k, value) in column.iter_mut().enumerate() {
            let row = cy - 1 + k as i64;
            *value = catmull_rom(
                [
                    self.sample(cx - 1, row),
                    self.sample(cx, row),
                    self.sample(cx + 1, row),
                    self.sample(cx + 2, row),
                ],
                tx,
            );
        }
        catmull_rom(column, ty)
    }
}

impl HeightGrid {
    /// [`HeightGrid::height`] along the row of world `y`: what depends on
    /// y alone taken once, the sixteen samples around a grid cell read
    /// once for every x in it.
    pub fn row(&self, y: f64) -> HeightRow<'_> {
        let fy = (y - self.origin[1]) / self.resolution;
        let cy = floor(fy);
        HeightRow {
            grid: self,
            cy,
            ty: fy - cy as f64,
            cell: None,
        }
    }
}

/// [`HeightGrid::height`] along one row (see [`HeightGrid::row`]).
pub struct HeightRow<'a> {
    grid: &'a HeightGrid,
    cy: i64,
    ty: f64,
    /// The grid column last asked for and its sixteen samples, by row.
    cell: Option<(i64, [[f64; 4]; 4])>,
}

impl HeightRow<'_> {
    /// Height at (x, the row's y): [`HeightGrid::height`]'s value, the
    /// same operations in the same order.
    pub fn at(&mut self, x: f64) -> f64 {
        let grid = self.grid;
        let fx = (x - grid.origin[0]) / grid.resolution;
        let cx = floor(fx);
        let tx = fx - cx as f64;
        let samples = match self.cell {
            Some((at, samples)) if at == cx => samples,
            _ => {
                let samples = std::array::from_fn(|k| {
                    let row = self.cy - 1 + k as i64;
                    [
                        grid.sample(cx - 1, row),
                        grid.sample(cx, row),
                        grid.sample(cx + 1, row),
                        grid.sample(cx + 2, row),
                    ]
                });
                self.cell = Some((cx, samples));
                samples
            }
        };
        catmull_rom(samples.map(|row| catmull_rom(row, tx)), self.ty)
    }
}

fn catmull_rom(p: [f64; 4], t: f64) -> f64 {
    let t2 = t * t;
    0.5 * (2.0 * p[1]
        + (-p[0] + p[2]) * t
        + (2.0 * p[0] - 5.0 * p[1] + 4.0 * p[2] - p[3]) * t2
        + (-p[0] + 3.0 * p[1] - 3.0 * p[2] + p[3]) * t2 * t)
}

fn parse_npy(bytes: &[u8]) -> Result<(usize, usize, Vec<f32>), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a NumPy .npy file (bad magic)".into());
    }
    let major = bytes[6];
    let (header_len, header_start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated header".into());
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header = bytes
        .get(header_start..header_start + header_len)
        .ok_or("truncated header")?;
    let header = std::str::from_utf8(header).map_err(|_| "header is not text")?;
    let field = |name: &str| -> Option<&str> {
        let at = header.find(&format!("'{name}'"))?;
        let rest = &header[at + name.len() + 2..];
        Some(rest.trim_start().trim_start_matches(':').trim_start())
    };
    let descr = field("descr").ok_or("header has no 'descr'")?;
    let descr = descr
        .trim_start_matches('\'')
        .split('\'')
        .next()
        .unwrap_or("");
    if field("fortran_order").is_some_and(|v| v.starts_with("True")) {
        return Err(
            "Fortran-ordered arrays are not supported; save with np.ascontiguousarray".into(),
        );
    }
    let shape = field("shape").ok_or("header has no 'shape'")?;
    let shape = shape.trim_start_matches('(');
    let shape = &shape[..shape.find(')').ok_or("malformed shape")?];
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| format!("malformed shape dimension {s:?}"))
        })
        .collect::<Result<_, _>>()?;
    let [rows, cols] = dims[..] else {
        return Err(format!(
            "array has shape {dims:?}; a 2-D (rows, cols) array is needed"
        ));
    };
    let data = &bytes[header_start + header_len..];
    let count = rows.checked_mul(cols).ok_or("shape too large")?;
    let decode = |size: usize, convert: &dyn Fn(&[u8]) -> f32| -> Result<Vec<f32>, String> {
        let needed = count.checked_mul(size).ok_or("shape too large")?;
        if data.len() < needed {
            return Err(format!(
                "holds {} data bytes, the shape needs {needed}",
                data.len()
            ));
        }
        Ok(data[..needed].chunks_exact(size).map(convert).collect())
    };
    let le = |c: &[u8], n: usize| -> [u8; 8] {
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(&c[..n]);
        b
    };
    let be = |c: &[u8], n: usize| -> [u8; 8] {
        let mut b = [0u8; 8];
        for (i, byte) in c[..n].iter().rev().enumerate() {
            b[i] = *byte;
        }
        b
    };
    let values = match descr {
        "<f4" | "=f4" => decode(4, &|c| f32::from_le_bytes(c.try_into().unwrap_or([0; 4])))?,
        ">f4" => decode(4, &|c| f32::from_be_bytes(c.try_into().unwrap_or([0; 4])))?,
        "<f8" | "=f8" => decode(8, &|c| f64::from_le_bytes(le(c, 8)) as f32)?,
        ">f8" => decode(8, &|c| f64::from_le_bytes(be(c, 8)) as f32)?,
        "<i2" | "=i2" => decode(2, &|c| f32::from(i16::from_le_bytes([c[0], c[1]])))?,
        "<u2" | "=u2" => decode(2, &|c| f32::from(u16::from_le_bytes([c[0], c[1]])))?,
        "<i4" | "=i4" => decode(4, &|c| {
            i32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f32
        })?,
        "<i8" | "=i8" => decode(8, &|c| i64::from_le_bytes(le(c, 8)) as f32)?,
        other => {
            return Err(format!(
                "unsupported element type {other:?} (use float32, float64, int16, uint16, int32 or int64)"
            ));
        }
    };
    Ok((rows, cols, values))
}

fn parse_asc(text: &str) -> Result<HeightGrid, String> {
    let mut header = std::collections::HashMap::new();
    let mut lines = text.lines().filter(|l| !l.trim().is_empty()).peekable();
    while let Some(line) = lines.peek() {
        let mut parts = line.split_whitespace();
        let (Some(key), Some(value)) = (parts.next(), parts.next()) else {
            break;
        };
        let key = key.to_ascii_lowercase();
        if key.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
            let value: f64 = value
                .parse()
                .map_err(|_| format!("header {key} = {value:?} is not a number"))?;
            header.insert(key, value);
            lines.next();
        } else {
            break;
        }
    }
    let get = |k: &str| {
        header
            .get(k)
            .copied()
            .ok_or_else(|| format!("header has no {k}"))
    };
    let cols = get("ncols")? as usize;
    let rows = get("nrows")? as usize;
    let cell = get("cellsize")?;
    let nodata = header.get("nodata_value").copied();
    // Corner or centre registration.
    let (x0, y0) = match (header.get("xllcenter"), header.get("yllcenter")) {
        (Some(&x), Some(&y)) => (x, y),
        _ => (
            get("xllcorner")? + cell / 2.0,
            get("yllcorner")? + cell / 2.0,
        ),
    };
    // Sized by what the text can hold (a value and a separator at least),
    // not by what the header claims.
    let mut values = Vec::with_capacity(rows.saturating_mul(cols).min(text.len() / 2 + 1));
    for token in lines.flat_map(str::split_whitespace) {
        let v: f64 = token
            .parse()
            .map_err(|_| format!("value {token:?} is not a number"))?;
        values.push(if nodata == Some(v) {
            f32::NAN
        } else {
            v as f32
        });
    }
    if rows.checked_mul(cols) != Some(values.len()) {
        return Err(format!(
            "holds {} values, ncols × nrows is {cols} × {rows}",
            values.len()
        ));
    }
    Ok(HeightGrid {
        cols,
        rows,
        resolution: cell,
        origin: [x0, y0],
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, shape: (usize, usize), data: &[u8]) -> Vec<u8> {
        let mut header = format!(
            "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}), }}",
            shape.0, shape.1
        );
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn a_row_of_heights_is_the_grid_height_bit_for_bit() {
        // 7 × 9 samples of 10 m, rough, read along rows inside, across
        // cell edges and beyond the edge (clamped), in both directions.
        let (rows, cols) = (7usize, 9usize);
        let values = (0..rows * cols)
            .map(|i| ((i * 7919) % 113) as f32 * 0.37 - 20.0)
            .collect();
        let grid = HeightGrid {
            cols,
            rows,
            resolution: 10.0,
            origin: [-40.0, 15.0],
            values,
        };
        let mut compared = 0;
        for y in [-3.0, 15.0, 21.37, 44.999, 75.0, 80.1, 200.0] {
            let mut row = grid.row(y);
            let xs = (-300..=1300).map(|i| -50.0 + f64::from(i) * 0.1);
            for x in xs.clone().chain(xs.rev()) {
                assert_eq!(
                    row.at(x).to_bits(),
                    grid.height(x, y).to_bits(),
                    "({x}, {y})"
                );
                compared += 1;
            }
        }
        assert_eq!(compared, 7 * 2 * 1601);
    }

    #[test]
    fn npy_float32_rows_run_north_to_south() {
        // 2 × 3, north row [0, 1, 2], south row [10, 11, 12].
        let data: Vec<u8> = [0.0f32, 1.0, 2.0, 10.0, 11.0, 12.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let (rows, cols, values) = parse_npy(&npy("<f4", (2, 3), &data)).unwrap();
        assert_eq!((rows, cols), (2, 3));
        let grid = HeightGrid {
            cols,
            rows,
            resolution: 1.0,
            origin: [100.0, 200.0],
            values,
        };
        assert!(
            (grid.height(100.0, 200.0) - 10.0).abs() < 1e-9,
            "south-west sample"
        );
        assert!(
            (grid.height(102.0, 201.0) - 2.0).abs() < 1e-9,
            "north-east sample"
        );
        assert_eq!(grid.bounds(), [100.0, 200.0, 102.0, 201.0]);
    }

    #[test]
    fn npy_float64_and_bad_files() {
        let data: Vec<u8> = [1.0f64, 2.0, 3.0, 4.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let (_, _, values) = parse_npy(&npy("<f8", (2, 2), &data)).unwrap();
        assert_eq!(values, [1.0, 2.0, 3.0, 4.0]);
        assert!(parse_npy(b"not numpy").unwrap_err().contains("magic"));
        assert!(
            parse_npy(&npy("<f4", (2, 2), &[0; 4]))
                .unwrap_err()
                .contains("data bytes")
        );
        assert!(
            parse_npy(&npy("<c16", (1, 1), &[0; 16]))
                .unwrap_err()
                .contains("unsupported element type")
        );
    }

    #[test]
    fn asc_grids_with_nodata() {
        let text = "ncols 3\nnrows 2\nxllcorner 0.0\nyllcorner 0.0\ncellsize 2.0\nNODATA_value -9999\n1 2 3\n4 -9999 6\n";
        let grid = parse_asc(text).unwrap();
        assert_eq!(
            (grid.cols, grid.rows, grid.resolution, grid.origin),
            (3, 2, 2.0, [1.0, 1.0])
        );
        assert!(grid.values[4].is_nan());
        assert!(
            parse_asc("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n")
                .unwrap_err()
                .contains("holds 3 values")
        );
    }

    #[test]
    fn bicubic_reproduces_a_plane_and_is_smooth() {
        let (rows, cols) = (6, 6);
        let values: Vec<f32> = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (c as f32) * 0.5 + ((rows - 1 - r) as f32) * 0.25))
            .collect();
        let grid = HeightGrid {
            cols,
            rows,
            resolution: 1.0,
            origin: [0.0, 0.0],
            values,
        };
        for (x, y) in [(1.3, 2.7), (2.5, 2.5), (3.9, 1.1)] {
            assert!((grid.height(x, y) - (0.5 * x + 0.25 * y)).abs() < 1e-9);
        }
    }
}
