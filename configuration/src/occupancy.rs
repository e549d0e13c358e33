//! Reading a static occupancy map (`[localmap.occupancy]`, 001 §3.4): a
//! ROS `map_server` YAML with its PGM image, or a `.npy` 2-D array.
//!
//! map_server's rules: the YAML names the `image` (relative to the YAML),
//! its `resolution` (m per pixel) and `origin` (x, y, yaw of the lower-left
//! pixel's corner); a pixel's occupancy is `p = (255 − v) / 255`, or
//! `v / 255` with `negate: 1`, and the pixel is occupied when
//! `p > occupied_thresh`; `mode: raw` takes `v` as a percentage instead.
//! The image's top row is the map's far (+y) edge. A `.npy` array's row 0
//! is at the origin, as in a ROS `OccupancyGrid`; its resolution, origin
//! and threshold come from the configuration.
//!
//! Map files are regular files read with a bound; nothing is allocated
//! from a size a file states before it is checked against what the file
//! holds, and at most [`MAX_CELLS`] cells.

use std::path::{Path, PathBuf};

use arcnav_localmap::{OccupancyConfig, OccupancyGrid};
use arcnav_vehicle::frames::planar_isometry;

/// The largest map read: 20 000 × 20 000 cells (1 km square at 5 cm).
pub const MAX_CELLS: u64 = 400_000_000;

/// A map that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum OccupancyError {
    #[error("cannot read the occupancy map {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("occupancy map {path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

fn invalid(path: &Path, message: impl Into<String>) -> OccupancyError {
    OccupancyError::Invalid {
        path: path.to_owned(),
        message: message.into(),
    }
}

/// The map `config` names (`None` when it names none), with the image file
/// a `.yaml` names (read too).
pub fn load(
    config: &OccupancyConfig,
) -> Result<Option<(OccupancyGrid, Option<PathBuf>)>, OccupancyError> {
    if config.file.is_empty() {
        return Ok(None);
    }
    let path = Path::new(&config.file);
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("yaml" | "yml") => load_yaml(path).map(|(grid, image)| Some((grid, Some(image)))),
        Some("npy") => load_npy(path, config).map(|grid| Some((grid, None))),
        _ => Err(invalid(
            path,
            "is neither a map_server .yaml nor a .npy array (named by its extension)",
        )),
    }
}

/// The largest map_server YAML read: 1 MiB (they are a few lines).
pub const MAX_YAML_BYTES: u64 = 1 << 20;

/// The most nodes a YAML document may expand to, aliases expanded: a
/// 900-byte document of nested aliases had expanded to 3 GB.
pub const MAX_YAML_NODES: u64 = 10_000;

fn read_error(path: &Path) -> impl FnOnce(std::io::Error) -> OccupancyError + '_ {
    move |source| OccupancyError::Read {
        path: path.to_owned(),
        source,
    }
}

/// The bytes of the map file `path`: a regular file of at most
/// `max_bytes` (a device such as `/dev/zero` had been read until memory
/// ran out). Sizes a file's header states are then checked against what
/// it holds before anything is allocated from them.
fn read_map_file(path: &Path, max_bytes: u64) -> Result<Vec<u8>, OccupancyError> {
    let meta = std::fs::metadata(path).map_err(read_error(path))?;
    if !meta.is_file() {
        return Err(invalid(path, "is not a regular file"));
    }
    arcnav_vehicle::files::read_bounded(path, max_bytes).map_err(read_error(path))
}

/// The deepest a map_server YAML may nest collections: its one level of
/// keys and the `origin` list need two. The parser recurses once a level,
/// and a 4 kB document of nested `- - - …` had overflowed the stack (found
/// by the occupancy_map fuzzer).
pub const MAX_YAML_DEPTH: usize = 32;

/// The number of nodes `text` holds with every alias expanded (saturating),
/// read event by event (no recursion) so that neither an alias bomb nor a
/// deep nesting reaches the loader: deeper than [`MAX_YAML_DEPTH`] is an
/// error.
fn expanded_nodes(text: &str) -> Result<u64, String> {
    use yaml_rust2::parser::{Event, Parser};
    let mut total: u64 = 0;
    // Expanded size of each anchor, by anchor id.
    let mut anchors = std::collections::BTreeMap::<usize, u64>::new();
    // Open collections: anchor id and the total when opened.
    let mut open: Vec<(usize, u64)> = Vec::new();
    let mut parser = Parser::new_from_str(text);
    loop {
        let (event, mark) = parser.next_token().map_err(|e| e.to_string())?;
        match event {
            Event::StreamEnd => return Ok(total),
            Event::Scalar(_, _, anchor, _) => {
                total = total.saturating_add(1);
                if anchor > 0 {
                    anchors.insert(anchor, 1);
                }
            }
            Event::SequenceStart(anchor, _) | Event::MappingStart(anchor, _) => {
                total = total.saturating_add(1);
                open.push((anchor, total));
                if open.len() > MAX_YAML_DEPTH {
                    return Err(format!(
                        "nests collections more than {MAX_YAML_DEPTH} deep (line {}): \
                         a map_server map is a few keys",
                        mark.line()
                    ));
                }
            }
            Event::SequenceEnd | Event::MappingEnd => {
                if let Some((anchor, from)) = open.pop()
                    && anchor > 0
                {
                    anchors.insert(anchor, total - from + 1);
                }
            }
            Event::Alias(anchor) => {
                let size = anchors.get(&anchor).copied().unwrap_or(1);
                total = total.saturating_add(size);
            }
            _ => {}
        }
    }
}

fn load_yaml(path: &Path) -> Result<(OccupancyGrid, PathBuf), OccupancyError> {
    let text = read_map_file(path, MAX_YAML_BYTES)?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_owned();
    let mut image_path = PathBuf::new();
    let grid = parse_yaml(path, &text, |image| {
        image_path = dir.join(image);
        read_map_file(&image_path, 2 * MAX_CELLS + 4096)
    })?;
    Ok((grid, image_path))
}

/// A map_server YAML (`text`, named `path` in messages) and the image it
/// names, whose bytes `image_bytes` gives.
pub fn parse_yaml(
    path: &Path,
    text: &[u8],
    image_bytes: impl FnOnce(&str) -> Result<Vec<u8>, OccupancyError>,
) -> Result<OccupancyGrid, OccupancyError> {
    use yaml_rust2::{Yaml, YamlLoader};
    let text = std::str::from_utf8(text).map_err(|_| invalid(path, "is not UTF-8 text"))?;
    let nodes = expanded_nodes(text).map_err(|e| invalid(path, e))?;
    if nodes > MAX_YAML_NODES {
        return Err(invalid(
            path,
            format!(
                "expands to {nodes} YAML nodes (its aliases expanded), more than \
                 {MAX_YAML_NODES}: a map_server map is a few keys"
            ),
        ));
    }
    let docs = YamlLoader::load_from_str(text).map_err(|e| invalid(path, e.to_string()))?;
    let doc = docs
        .first()
        .ok_or_else(|| invalid(path, "holds no YAML document"))?;
    let number = |key: &str| -> Result<Option<f64>, OccupancyError> {
        match &doc[key] {
            Yaml::BadValue => Ok(None),
            Yaml::Real(_) => doc[key]
                .as_f64()
                .map(Some)
                .ok_or_else(|| invalid(path, format!("`{key}` is not a number"))),
            Yaml::Integer(i) => Ok(Some(*i as f64)),
            _ => Err(invalid(path, format!("`{key}` is not a number"))),
        }
    };
    let image = doc["image"]
        .as_str()
        .ok_or_else(|| invalid(path, "has no `image` (the PGM file)"))?;
    let resolution =
        number("resolution")?.ok_or_else(|| invalid(path, "has no `resolution` (m per pixel)"))?;
    if !(resolution.is_finite() && resolution > 0.0) {
        return Err(invalid(
            path,
            format!("`resolution` {resolution} must be positive"),
        ));
    }
    let origin: Vec<f64> = doc["origin"]
        .as_vec()
        .ok_or_else(|| invalid(path, "has no `origin` [x, y, yaw]"))?
        .iter()
        .map(|v| v.as_f64().or_else(|| v.as_i64().map(|i| i as f64)))
        .collect::<Option<Vec<f64>>>()
        .filter(|o| o.len() == 3 && o.iter().all(|v| v.is_finite()))
        .ok_or_else(|| invalid(path, "`origin` must be three numbers [x, y, yaw]"))?;
    let negate = number("negate")?.unwrap_or(0.0) != 0.0;
    let occupied_thresh = number("occupied_thresh")?.unwrap_or(0.65);
    if !(0.0..=1.0).contains(&occupied_thresh) {
        return Err(invalid(path, "`occupied_thresh` must be 0 to 1"));
    }
    let raw = doc["mode"].as_str() == Some("raw");
    let image_name = Path::new(image);
    let pixels = parse_pgm(image_name, &image_bytes(image)?)?;
    let (cols, rows) = (pixels.width() as usize, pixels.height() as usize);
    let mut occupied = vec![false; cols * rows];
    for (x, y, v) in pixels.enumerate_pixels() {
        let v = f64::from(v.0[0]);
        let is = if raw {
            (100.0 * occupied_thresh..=100.0).contains(&v)
        } else {
            let p = if negate {
                v / 255.0
            } else {
                (255.0 - v) / 255.0
            };
            p > occupied_thresh
        };
        // The image's top row is the map's far edge.
        let row = rows - 1 - y as usize;
        occupied[row * cols + x as usize] = is;
    }
    let grid = OccupancyGrid {
        resolution_m: resolution,
        origin: planar_isometry(origin[0], origin[1], origin[2]),
        cols,
        rows,
        occupied,
    };
    Ok(grid)
}

/// A PGM image's bytes (`path` names it in messages): its header's size
/// is checked against the bytes before the pixels are allocated.
fn parse_pgm(path: &Path, bytes: &[u8]) -> Result<image::GrayImage, OccupancyError> {
    use image::ImageDecoder as _;
    let unreadable =
        |e: image::ImageError| invalid(path, format!("is not a readable PGM image: {e}"));
    let mut decoder =
        image::codecs::pnm::PnmDecoder::new(std::io::Cursor::new(bytes)).map_err(unreadable)?;
    let (width, height) = decoder.dimensions();
    let pixels = u64::from(width) * u64::from(height);
    if pixels > MAX_CELLS {
        return Err(invalid(path, "holds more than 400 million pixels"));
    }
    if decoder.total_bytes() > bytes.len() as u64 {
        return Err(invalid(
            path,
            format!(
                "its header says {width} × {height} pixels, more than its {} bytes hold",
                bytes.len()
            ),
        ));
    }
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(2 * MAX_CELLS);
    decoder.set_limits(limits).map_err(unreadable)?;
    let decoded = image::DynamicImage::from_decoder(decoder).map_err(unreadable)?;
    Ok(decoded.to_luma8())
}

fn load_npy(path: &Path, config: &OccupancyConfig) -> Result<OccupancyGrid, OccupancyError> {
    // Eight bytes a value at most, and the header.
    let bytes = read_map_file(path, 8 * MAX_CELLS + (1 << 16))?;
    parse_npy(path, &bytes, config)
}

/// A `.npy` array's bytes (`path` names it in messages), placed as
/// `config` says: its shape is checked against the bytes before the
/// values are allocated.
pub fn parse_npy(
    path: &Path,
    bytes: &[u8],
    config: &OccupancyConfig,
) -> Result<OccupancyGrid, OccupancyError> {
    use npyz::{DType, TypeChar};
    // The header's length field, checked before npyz allocates it (a
    // version-3 header may state 4 GB; the fuzzer found one of 660 MB).
    let (header_at, header_len) = match bytes {
        [0x93, b'N', b'U', b'M', b'P', b'Y', 1, _, a, b, ..] => {
            (10, u64::from(u16::from_le_bytes([*a, *b])))
        }
        [0x93, b'N', b'U', b'M', b'P', b'Y', 2 | 3, _, a, b, c, d, ..] => {
            (12, u64::from(u32::from_le_bytes([*a, *b, *c, *d])))
        }
        _ => (0, 0),
    };
    if header_len > bytes.len() as u64 {
        return Err(invalid(
            path,
            format!(
                "is not a .npy array: its header says {header_len} bytes, more than its {} bytes hold",
                bytes.len()
            ),
        ));
    }
    // The header is a flat dict holding a tuple: deeper nesting is no .npy
    // (npyz's parser takes exponential time over nested braces; the
    // fuzzer found 30 of them taking seconds).
    let header = bytes
        .get(header_at..)
        .and_then(|rest| rest.get(..usize::try_from(header_len).ok()?))
        .unwrap_or_default();
    let mut depth = 0usize;
    for &c in header {
        match c {
            b'{' | b'(' | b'[' => depth += 1,
            b'}' | b')' | b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
        if depth > 2 {
            return Err(invalid(
                path,
                "is not a .npy array: its header nests deeper than a dict holding a tuple",
            ));
        }
    }
    if !shape_fits(header) {
        return Err(invalid(
            path,
            "is not a .npy array: its shape is not decimal sizes whose product a 64-bit count holds",
        ));
    }
    let npy = npyz::NpyFile::new(bytes)
        .map_err(|e| invalid(path, format!("is not a .npy array: {e}")))?;
    let shape = npy.shape().to_vec();
    let [rows, cols] = shape[..] else {
        return Err(invalid(
            path,
            format!(
                "is a {}-D array; an occupancy map is 2-D (rows, columns)",
                shape.len()
            ),
        ));
    };
    if rows.saturating_mul(cols) > MAX_CELLS || rows == 0 || cols == 0 {
        return Err(invalid(
            path,
            format!("is {rows} × {cols}: at least one cell, at most 400 million"),
        ));
    }
    let fortran = npy.order() == npyz::Order::Fortran;
    let DType::Plain(ty) = npy.dtype() else {
        return Err(invalid(path, "holds records, not numbers"));
    };
    // The values the shape states must be in the file: a header alone had
    // been allocated for (8 bytes a value of 400 million).
    let held = bytes.len() as u64 / ty.size_field().max(1);
    if rows.saturating_mul(cols) > held {
        return Err(invalid(
            path,
            format!(
                "its header says {rows} × {cols} values, more than its {} bytes hold",
                bytes.len()
            ),
        ));
    }
    let values: Vec<f64> = match (ty.type_char(), ty.size_field()) {
        (TypeChar::Bool, 1) => to_f64(npy.into_vec::<bool>(), path, |v| f64::from(u8::from(v)))?,
        (TypeChar::Uint, 1) => to_f64(npy.into_vec::<u8>(), path, f64::from)?,
        (TypeChar::Int, 1) => to_f64(npy.into_vec::<i8>(), path, f64::from)?,
        (TypeChar::Int, 2) => to_f64(npy.into_vec::<i16>(), path, f64::from)?,
        (TypeChar::Int, 4) => to_f64(npy.into_vec::<i32>(), path, f64::from)?,
        (TypeChar::Int, 8) => to_f64(npy.into_vec::<i64>(), path, |v| v as f64)?,
        (TypeChar::Float, 4) => to_f64(npy.into_vec::<f32>(), path, f64::from)?,
        (TypeChar::Float, 8) => to_f64(npy.into_vec::<f64>(), path, |v| v)?,
        (c, size) => {
            return Err(invalid(
                path,
                format!("holds {c:?} of {size} bytes; use bool, integers or floats"),
            ));
        }
    };
    let (rows, cols) = (rows as usize, cols as usize);
    if values.len() != rows * cols {
        return Err(invalid(path, "holds fewer values than its shape says"));
    }
    let largest = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let threshold = if largest > 1.0 {
        100.0 * config.occupied_thresh
    } else {
        config.occupied_thresh
    };
    let occupied = (0..rows * cols)
        .map(|k| {
            let (row, col) = (k / cols, k % cols);
            let v = if fortran {
                values[col * rows + row]
            } else {
                values[k]
            };
            v >= threshold
        })
        .collect();
    let [x, y, yaw] = config.origin;
    Ok(OccupancyGrid {
        resolution_m: config.resolution_m,
        origin: planar_isometry(x, y, yaw.to_radians()),
        cols,
        rows,
        occupied,
    })
}

/// Whether the `shape` tuple of a .npy header is decimal sizes (as numpy
/// writes them) whose product fits in a u64: npyz multiplies them
/// unchecked (the fuzzer found a shape whose product overflowed, a panic
/// with overflow checks on). A header without a shape is left to npyz.
fn shape_fits(header: &[u8]) -> bool {
    let text = String::from_utf8_lossy(header);
    let Some(tuple) = text
        .find("'shape'")
        .or_else(|| text.find("\"shape\""))
        .map(|at| &text[at..])
        .and_then(|rest| {
            let open = rest.find('(')? + 1;
            let close = open + rest[open..].find(')')?;
            Some(&rest[open..close])
        })
    else {
        return true;
    };
    if !tuple
        .chars()
        .all(|c| c.is_ascii_digit() || c == ',' || c == ' ')
    {
        return false;
    }
    let mut product: u64 = 1;
    for size in tuple.split([',', ' ']).filter(|p| !p.is_empty()) {
        let Some(p) = size
            .parse::<u64>()
            .ok()
            .and_then(|v| product.checked_mul(v.max(1)))
        else {
            return false;
        };
        product = p;
    }
    true
}

fn to_f64<T>(
    values: std::io::Result<Vec<T>>,
    path: &Path,
    convert: impl Fn(T) -> f64,
) -> Result<Vec<f64>, OccupancyError> {
    values
        .map(|v| v.into_iter().map(convert).collect())
        .map_err(|e| invalid(path, format!("cannot be read: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use npyz::WriterBuilder as _;

    fn dir(tag: &str) -> arcnav_testkit::ScratchDir {
        arcnav_testkit::scratch_dir(&format!("arcnav-occ-{tag}"))
    }

    fn config(file: &Path) -> OccupancyConfig {
        OccupancyConfig {
            file: file.to_str().unwrap().into(),
            ..OccupancyConfig::default()
        }
    }

    #[test]
    fn a_map_server_yaml_and_pgm_are_read_with_its_rules() {
        let d = dir("yaml");
        // 3 wide, 2 tall; top row: black (occupied), grey (0.5), white.
        let mut pgm = b"P5\n3 2\n255\n".to_vec();
        pgm.extend_from_slice(&[0, 128, 255, 255, 255, 0]);
        std::fs::write(d.join("map.pgm"), &pgm).unwrap();
        std::fs::write(
            d.join("map.yaml"),
            "image: map.pgm\nresolution: 0.5\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        )
        .unwrap();
        let grid = load(&config(&d.join("map.yaml"))).unwrap().unwrap().0;
        assert_eq!((grid.cols, grid.rows, grid.resolution_m), (3, 2, 0.5));
        // Row 0 is the image's bottom row: white, white, black.
        assert_eq!(grid.occupied, [false, false, true, true, false, false]);
        assert_eq!(grid.origin.translation.vector.x, -1.0);
        // negate: 1 turns it over.
        std::fs::write(
            d.join("neg.yaml"),
            "image: map.pgm\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 1\n",
        )
        .unwrap();
        let grid = load(&config(&d.join("neg.yaml"))).unwrap().unwrap().0;
        assert_eq!(grid.occupied, [true, true, false, false, false, true]);
    }

    #[test]
    fn a_npy_array_is_read_with_the_configured_origin() {
        let d = dir("npy");
        let path = d.join("map.npy");
        // 2 rows × 3 columns of percentages, -1 unknown.
        let mut out = Vec::new();
        {
            let mut writer = npyz::WriteOptions::new()
                .default_dtype()
                .shape(&[2, 3])
                .writer(&mut out)
                .begin_nd()
                .unwrap();
            writer.extend([0i8, 100, -1, 70, 50, 0]).unwrap();
            writer.finish().unwrap();
        }
        std::fs::write(&path, &out).unwrap();
        let c = OccupancyConfig {
            resolution_m: 0.2,
            origin: [5.0, 0.0, 90.0],
            ..config(&path)
        };
        let grid = load(&c).unwrap().unwrap().0;
        assert_eq!((grid.cols, grid.rows), (3, 2));
        assert_eq!(grid.occupied, [false, true, false, true, false, false]);
        let yaw = arcnav_vehicle::frames::yaw_of(&grid.origin);
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn bad_maps_are_refused_naming_the_file_and_the_problem() {
        let d = dir("bad");
        let case = |name: &str, bytes: &[u8]| {
            let p = d.join(name);
            std::fs::write(&p, bytes).unwrap();
            load(&config(&p)).unwrap_err().to_string()
        };
        assert!(case("a.txt", b"").contains("neither a map_server .yaml nor a .npy"));
        let e = case("noimage.yaml", b"resolution: 0.1\norigin: [0, 0, 0]\n");
        assert!(e.contains("has no `image`"), "{e}");
        let e = case(
            "missing.yaml",
            b"image: nowhere.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n",
        );
        assert!(
            e.contains("cannot read the occupancy map") && e.contains("nowhere.pgm"),
            "{e}"
        );
        std::fs::write(d.join("huge.pgm"), b"P5\n100000 100000\n255\n\0").unwrap();
        let e = case(
            "huge.yaml",
            b"image: huge.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n",
        );
        assert!(e.contains("huge.pgm"), "{e}");
        let e = case(
            "origin.yaml",
            b"image: huge.pgm\nresolution: 0.1\norigin: [0, 0]\n",
        );
        assert!(e.contains("`origin` must be three numbers"), "{e}");
        let e = case("bad.npy", b"\x93NUMPY garbage");
        assert!(
            e.contains("bad.npy") && e.contains("not a .npy array"),
            "{e}"
        );
        let e = load(&config(&d.join("absent.npy")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read the occupancy map"), "{e}");
    }

    #[test]
    fn devices_and_alias_bombs_are_refused_without_reading_them_whole() {
        let d = dir("unbounded");
        // `image: /dev/zero` had been read until memory ran out; a `.npy`
        // naming a device the same.
        let yaml = d.join("zero.yaml");
        std::fs::write(
            &yaml,
            "image: /dev/zero\nresolution: 0.1\norigin: [0, 0, 0]\n",
        )
        .unwrap();
        let e = load(&config(&yaml)).unwrap_err().to_string();
        assert!(e.contains("/dev/zero: is not a regular file"), "{e}");
        let npy = d.join("zero.npy");
        let _ = std::fs::remove_file(&npy);
        std::os::unix::fs::symlink("/dev/zero", &npy).unwrap();
        let e = load(&config(&npy)).unwrap_err().to_string();
        assert!(e.contains("is not a regular file"), "{e}");
        // Headers that state more than the file holds: refused before the
        // pixels or values are allocated (a 400-million-value header alone
        // had been allocated for).
        let e = parse_pgm(Path::new("big.pgm"), b"P5\n20000 20000\n255\n\0\0").unwrap_err();
        assert!(e.to_string().contains("more than its 21 bytes hold"), "{e}");
        let mut header = b"\x93NUMPY\x01\x00".to_vec();
        let dict = b"{'descr': '<f8', 'fortran_order': False, 'shape': (20000, 20000), }";
        let mut text = dict.to_vec();
        while !(10 + text.len() + 1).is_multiple_of(64) {
            text.push(b' ');
        }
        text.push(b'\n');
        header.extend_from_slice(&(text.len() as u16).to_le_bytes());
        header.extend_from_slice(&text);
        header.extend_from_slice(&[0; 64]);
        let e = parse_npy(Path::new("big.npy"), &header, &OccupancyConfig::default()).unwrap_err();
        assert!(
            e.to_string().contains("20000 × 20000 values, more than"),
            "{e}"
        );
        // Braces nested 30 deep in the header (npyz's parser took seconds).
        let mut nested = b"\x93NUMPY\x01\x00".to_vec();
        let dict = format!("{{'descr': '|b1', 'shape': {}(2, 2), }}", "{".repeat(30));
        nested.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        nested.extend_from_slice(dict.as_bytes());
        let e = parse_npy(Path::new("deep.npy"), &nested, &OccupancyConfig::default()).unwrap_err();
        assert!(e.to_string().contains("nests deeper"), "{e}");
        // A shape whose product overflows (npyz multiplied it unchecked: a
        // panic the fuzzer found), and one not in decimal.
        for shape in ["(4294967296, 4294967296)", "(0x10, 2)"] {
            let mut header = b"\x93NUMPY\x01\x00".to_vec();
            let dict = format!("{{'descr': '|b1', 'fortran_order': False, 'shape': {shape}, }}");
            header.extend_from_slice(&(dict.len() as u16).to_le_bytes());
            header.extend_from_slice(dict.as_bytes());
            let e =
                parse_npy(Path::new("wide.npy"), &header, &OccupancyConfig::default()).unwrap_err();
            assert!(
                e.to_string().contains("its shape is not decimal sizes"),
                "{shape}: {e}"
            );
        }
        // A `)` before the `(` (shape_fits itself had panicked on it).
        let mut header = b"\x93NUMPY\x01\x00".to_vec();
        let dict = "{'descr': '<i4', 'fortran_order': False, 'shape': 1, 1)( }";
        header.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        header.extend_from_slice(dict.as_bytes());
        assert!(parse_npy(Path::new("odd.npy"), &header, &OccupancyConfig::default()).is_err());
        // A version-3 header stating 4 GB of itself (the fuzzer found one).
        let mut v3 = b"\x93NUMPY\x03\x00".to_vec();
        v3.extend_from_slice(&u32::MAX.to_le_bytes());
        v3.extend_from_slice(b"{'descr': '<f8'");
        let e = parse_npy(Path::new("v3.npy"), &v3, &OccupancyConfig::default()).unwrap_err();
        assert!(
            e.to_string().contains("its header says 4294967295 bytes"),
            "{e}"
        );
        // A YAML of /dev/zero itself, and one of nested aliases (900 bytes
        // had expanded to 3 GB).
        let endless = d.join("endless.yaml");
        let _ = std::fs::remove_file(&endless);
        std::os::unix::fs::symlink("/dev/zero", &endless).unwrap();
        let e = load(&config(&endless)).unwrap_err().to_string();
        assert!(e.contains("is not a regular file"), "{e}");
        let mut bomb = String::from("a: &a [x, x, x, x, x, x, x, x, x, x]\n");
        let names = ["a", "b", "c", "d", "e", "f", "g", "h", "i"];
        for pair in names.windows(2) {
            let refs = vec![format!("*{}", pair[0]); 10].join(", ");
            bomb.push_str(&format!("{0}: &{0} [{refs}]\n", pair[1]));
        }
        bomb.push_str("image: map.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n");
        assert!(bomb.len() < 1000);
        let bombed = d.join("bomb.yaml");
        std::fs::write(&bombed, &bomb).unwrap();
        let e = load(&config(&bombed)).unwrap_err().to_string();
        assert!(e.contains("YAML nodes (its aliases expanded)"), "{e}");
        // A few aliases are fine.
        assert!(expanded_nodes("a: &a [1, 2]\nb: *a\n").unwrap() < 20);
        // Collections nested thousands deep, in block and in flow style:
        // refused before the recursive loader (4 kB of `- - - …` had
        // overflowed the stack; the occupancy_map fuzzer found it).
        // (yaml-rust2's scanner itself stops flow nesting at 255.)
        for (deep, says) in [
            ("- ".repeat(2000), "nests collections more than 32 deep"),
            (
                "a:\n".to_owned() + &"- ".repeat(40),
                "nests collections more than 32 deep",
            ),
            ("[".repeat(2000), "recursion limit exceeded"),
        ] {
            let e = parse_yaml(Path::new("deep.yaml"), deep.as_bytes(), |_| Ok(Vec::new()))
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{e}");
        }
    }
}
