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
pub fn check_outputs(outputs: &[&Path], inputs: &[(&str, &Path)]) -> Result<(), OverwritesInput> {
    for (i, &output) in outputs.iter().enumerate() {
        for &(what, input) in inputs {
            if same_file(output, input) {
                return Err(OverwritesInput::Input {
                    output: output.to_owned(),
                    what: what.to_owned(),
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

/// A file being written: a temporary file beside `target`, renamed onto it
/// by [`Staged::commit`]; dropped uncommitted, it is removed.
#[derive(Debug)]
pub struct Staged {
    target: PathBuf,
    temp: PathBuf,
    committed: bool,
}

impl Staged {
    /// Creates the temporary file for `target`.
    pub fn create(target: &Path) -> io::Result<(Self, File)> {
        let name = target
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "not a file name"))?;
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".{}.partial", std::process::id()));
        let temp = target.with_file_name(temp_name);
        let file = File::create(&temp)?;
        Ok((
            Self {
                target: target.to_owned(),
                temp,
                committed: false,
            },
            file,
        ))
    }

    /// The file is complete: it takes the target's place.
    pub fn commit(mut self) -> io::Result<()> {
        std::fs::rename(&self.temp, &self.target)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// Writes `bytes` to `path` through a [`Staged`] file.
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write as _;
    let (staged, mut file) = Staged::create(path)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    staged.commit()
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
        let err = check_outputs(&[&out, &out], &[]).unwrap_err();
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
}
