//! Writing output files without losing anything: an output is never one of
//! the run's inputs (same file, also through links), and it is written to a
//! temporary file beside it and renamed into place only when complete, so an
//! interrupted or failed run leaves the old file as it was.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

/// An output that would overwrite an input, or another output.
#[derive(Debug, thiserror::Error)]
pub enum OverwritesInput {
    #[error(
        "refusing to write {output}: it is {what} {input}, which this run reads; choose another file"
    )]
    Input {
        output: PathBuf,
        what: String,
        input: PathBuf,
    },
    #[error(
        "refusing to write {output}: the run writes {other} already, the same file; choose another file"
    )]
    Twice { output: PathBuf, other: PathBuf },
}

/// True when `a` and `b` name the same existing file (through links too).
pub fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Refuses `output` when it is one of `inputs` (each named by what it is,
/// e.g. "the log"), or another of the run's `outputs`.
pub fn check_outputs<P: AsRef<Path>>(
    outputs: &[&Path],
    inputs: &[(&str, P)],
) -> Result<(), OverwritesInput> {
    for (i, &output) in outputs.iter().enumerate() {
        for (what, input) in inputs {
            let input = input.as_ref();
            if same_file(output, input) {
                return Err(OverwritesInput::Input {
                    output: output.to_owned(),
                    what: (*what).to_owned(),
                    input: input.to_owned(),
                });
            }
        }
        if let Some(other) = outputs[..i]
            .iter()
            .find(|o| **o == output || same_file(o, output))
        {
            return Err(OverwritesInput::Twice {
                output: output.to_owned(),
                other: other.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// A file being written. A regular file (or a new one) is written to a
/// temporary file beside it, renamed onto it by [`Staged::commit`]; dropped
/// uncommitted, the temporary is removed and the old file stays. A symlink
/// is followed: the file it names is the one written, the link stays. A
/// FIFO, a device or a socket is written to directly and never replaced.
#[derive(Debug)]
pub struct Staged {
    /// `(temporary, target)` when written beside the target; `None` when
    /// written in place.
    rename: Option<(PathBuf, PathBuf)>,
}

/// What an output path names now.
enum Target {
    /// A regular file, or nothing yet: staged beside it.
    Regular(PathBuf),
    /// A FIFO, a character or block device, a socket: written in place.
    Special(PathBuf),
}

/// Follows `path` through any symlinks to what it names; refuses a
/// directory and a link that names nothing.
fn target_of(path: &Path) -> io::Result<Target> {
    use std::os::unix::fs::FileTypeExt;
    let refuse = |why: String| io::Error::new(io::ErrorKind::InvalidInput, why);
    let link = std::fs::symlink_metadata(path);
    let resolved = match &link {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path).map_err(|e| {
            refuse(format!(
                "{} is a symbolic link to nothing that can be written ({e}); remove it or name another file",
                path.display()
            ))
        })?,
        _ => path.to_owned(),
    };
    match std::fs::metadata(&resolved) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Target::Regular(resolved)),
        Err(e) => Err(e),
        Ok(m) if m.is_file() => Ok(Target::Regular(resolved)),
        Ok(m) if m.is_dir() => Err(refuse(format!(
            "{} is a directory; name a file",
            path.display()
        ))),
        Ok(m) => {
            let t = m.file_type();
            if t.is_fifo() || t.is_char_device() || t.is_block_device() || t.is_socket() {
                Ok(Target::Special(resolved))
            } else {
                Err(refuse(format!("{} is not a file", path.display())))
            }
        }
    }
}

impl Staged {
    /// Opens what `target` is written through (see [`Staged`]).
    pub fn create(target: &Path) -> io::Result<(Self, File)> {
        match target_of(target)? {
            Target::Special(path) => {
                let file = std::fs::OpenOptions::new().write(true).open(path)?;
                Ok((Self { rename: None }, file))
            }
            Target::Regular(target) => {
                let name = target.file_name().ok_or_else(|| {
                    io::Error::new(io::ErrorKind::InvalidInput, "not a file name")
                })?;
                let mut temp_name = std::ffi::OsString::from(".");
                temp_name.push(name);
                temp_name.push(format!(".{}.partial", std::process::id()));
                let temp = target.with_file_name(temp_name);
                let file = File::create(&temp)?;
                Ok((
                    Self {
                        rename: Some((temp, target)),
                    },
                    file,
                ))
            }
        }
    }

    /// The file is complete: synced and put in the target's place (written
    /// in place, nothing is left to do but flushing it).
    pub fn commit(mut self, file: File) -> io::Result<()> {
        match self.rename.take() {
            Some((temp, target)) => {
                let synced = file.sync_all().and_then(|()| {
                    drop(file);
                    std::fs::rename(&temp, &target)
                });
                if synced.is_err() {
                    let _ = std::fs::remove_file(&temp);
                }
                synced
            }
            None => Ok(()),
        }
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if let Some((temp, _)) = &self.rename {
            let _ = std::fs::remove_file(temp);
        }
    }
}

/// Writes `bytes` to `path` through a [`Staged`] file.
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write as _;
    let (staged, mut file) = Staged::create(path)?;
    file.write_all(bytes)?;
    staged.commit(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> arcnav_testkit::ScratchDir {
        arcnav_testkit::scratch_dir(&format!("arcnav-output-{tag}"))
    }

    #[test]
    fn an_output_that_is_an_input_is_refused_also_through_a_link() {
        let d = dir("links");
        let log = d.join("in.lcm");
        std::fs::write(&log, b"log").unwrap();
        let link = d.join("link.lcm");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&log, &link).unwrap();
        let err = check_outputs(&[&link], &[("the log", &log)]).unwrap_err();
        assert!(err.to_string().contains("it is the log"), "{err}");
        assert!(check_outputs(&[&d.join("out.lcm")], &[("the log", &log)]).is_ok());
        // Two outputs on one file.
        let out = d.join("out.json");
        let err = check_outputs::<&Path>(&[&out, &out], &[]).unwrap_err();
        assert!(
            err.to_string().contains("the run writes") && !err.to_string().contains("reads"),
            "{err}"
        );
    }

    #[test]
    fn a_staged_file_replaces_the_old_one_only_when_committed() {
        let d = dir("staged");
        let path = d.join("kept.json");
        std::fs::write(&path, b"old").unwrap();
        {
            let (_staged, _file) = Staged::create(&path).unwrap();
            // Dropped: as if the run failed half way.
        }
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(
            std::fs::read_dir(&d).unwrap().count(),
            1,
            "no temporary left"
        );
        write_file(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
    }

    #[test]
    fn a_link_is_followed_and_kept_and_the_file_it_names_is_written() {
        let d = dir("follow");
        let real = d.join("real.json");
        std::fs::write(&real, b"old").unwrap();
        let link = d.join("link.json");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_file(&link, b"new").unwrap();
        let meta = std::fs::symlink_metadata(&link).unwrap();
        assert!(meta.file_type().is_symlink(), "the link was replaced");
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        // A link to nothing is refused, not replaced by a file.
        let dangling = d.join("dangling.json");
        let _ = std::fs::remove_file(&dangling);
        std::os::unix::fs::symlink(d.join("missing/none.json"), &dangling).unwrap();
        let err = write_file(&dangling, b"x").unwrap_err();
        assert!(err.to_string().contains("symbolic link"), "{err}");
        assert!(
            std::fs::symlink_metadata(&dangling)
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }

    #[test]
    fn a_directory_is_refused_and_a_fifo_is_written_in_place() {
        use std::os::unix::fs::FileTypeExt;
        let d = dir("special");
        let err = write_file(&d, b"x").unwrap_err();
        assert!(err.to_string().contains("is a directory"), "{err}");
        let fifo = d.join("pipe");
        let _ = std::fs::remove_file(&fifo);
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo (coreutils) runs");
        assert!(made.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_file(&fifo, b"through the pipe").unwrap();
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
        assert!(kind.is_fifo(), "the FIFO was replaced by {kind:?}");
        let left = std::fs::read_dir(&d).unwrap().count();
        assert_eq!(left, 1, "a temporary was left beside the FIFO");
    }
}
