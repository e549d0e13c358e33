//! Reading input files with a bound on their size: a path that names a
//! device (`/dev/zero`), a pipe or a file far larger than expected fails
//! with a clear error instead of reading until memory runs out.

use std::io::{self, Read};
use std::path::Path;

/// Text files arcnav reads (configurations, worlds, waypoints): 16 MiB.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Reads the file at `path`, refusing one larger than `max_bytes`.
pub fn read_bounded(path: &Path, max_bytes: u64) -> io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let hint = file.metadata().map_or(0, |m| m.len()).min(max_bytes);
    let mut bytes = Vec::with_capacity(usize::try_from(hint).unwrap_or(0));
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "it is larger than {} MiB, the most this file may be",
                max_bytes >> 20
            ),
        ));
    }
    Ok(bytes)
}

/// Reads a UTF-8 text file of at most [`MAX_TEXT_BYTES`].
pub fn read_text(path: &Path) -> io::Result<String> {
    String::from_utf8(read_bounded(path, MAX_TEXT_BYTES)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "it is not UTF-8 text"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_file_is_refused_not_read_until_memory_runs_out() {
        let err = read_bounded(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(err.to_string().contains("larger than 1 MiB"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.toml");
        std::fs::write(&path, b"[vehicle]\n").unwrap();
        assert_eq!(read_text(&path).unwrap(), "[vehicle]\n");
        std::fs::write(&path, [0xff, 0xfe]).unwrap();
        assert!(
            read_text(&path)
                .unwrap_err()
                .to_string()
                .contains("not UTF-8")
        );
    }
}
