//! The output log that `arcnav sim` and `arcnav replay` write the pipeline's
//! messages to, and the first error their run meets.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use arcnav_arbiter::{BehaviourVotes, Reason};
use arcnav_bus::log::{LogWriteError, LogWriter};
use arcnav_bus::messages::{AnyMessage, channels};
use arcnav_perception::ObstacleReport;
use arcnav_vehicle::{ArcSet, Kinematics, SteeringCommand, Utime};

use crate::output::Staged;
use arcnav_wire as wire;

/// A write to the output log failed.
#[derive(Debug)]
pub(crate) struct WriteFailed {
    pub path: PathBuf,
    pub source: LogWriteError,
}

/// An optional output log and the first error of the run (of any kind `E`
/// can hold): once an error is kept, nothing more is written.
pub(crate) struct Recorder<'a, E> {
    out: Option<(&'a Path, LogWriter<BufWriter<File>>, Staged)>,
    pub error: Option<E>,
    /// Nothing is written while set (a replay's warm-up before `--from`).
    pub paused: bool,
}

impl<'a, E: From<WriteFailed>> Recorder<'a, E> {
    /// Starts the log at `path`, if there is one: written beside it and
    /// put in its place by [`Recorder::finish`], so a run that fails or is
    /// interrupted leaves any old file at `path` as it was.
    pub fn create(path: Option<&'a Path>) -> Result<Self, (PathBuf, std::io::Error)> {
        let out = match path {
            Some(path) => {
                let (staged, file) = Staged::create(path).map_err(|e| (path.to_owned(), e))?;
                Some((path, LogWriter::new(BufWriter::new(file)), staged))
            }
            None => None,
        };
        Ok(Self {
            out,
            error: None,
            paused: false,
        })
    }

    /// Completes the log: flushed, synced and renamed into place, unless an
    /// error was kept (returned; the partial log is removed).
    pub fn finish(&mut self) -> Result<(), E> {
        if let Some(e) = self.error.take() {
            self.out = None;
            return Err(e);
        }
        let Some((path, writer, staged)) = self.out.take() else {
            return Ok(());
        };
        let failed = |source: std::io::Error| {
            E::from(WriteFailed {
                path: path.to_path_buf(),
                source: LogWriteError::Io(source),
            })
        };
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| failed(e.into_error()))?;
        staged.commit(file).map_err(failed)
    }

    /// Writes `message` on `channel` at `at`.
    pub fn message<M: arcnav_bus::Message>(&mut self, at: Utime, channel: &str, message: &M) {
        self.write(|writer| writer.write_message(at, channel, message).map(drop));
    }

    /// Writes an already encoded message.
    pub fn event(&mut self, at: Utime, channel: &str, data: &[u8]) {
        self.write(|writer| writer.write_event(at, channel, data).map(drop));
    }

    /// Writes perception's report on OBSTACLE_CELLS.
    pub fn obstacles(&mut self, at: Utime, report: &ObstacleReport) {
        self.message(
            at,
            channels::OBSTACLE_CELLS,
            &wire::obstacles_to_wire(report),
        );
    }

    /// Writes the command (STEERING_COMMAND, in the type `kinematics`
    /// calls for) and why (DECISION).
    pub fn command(
        &mut self,
        at: Utime,
        command: &SteeringCommand,
        kinematics: Kinematics,
        reason: &Reason,
    ) {
        let message = AnyMessage::command(command, kinematics);
        self.write(|writer| {
            let data = message.encode()?;
            writer
                .write_event(at, channels::STEERING_COMMAND, &data)
                .map(drop)
        });
        self.message(
            at,
            channels::DECISION,
            &wire::decision_to_wire(command.utime, wire::Said::Arbiter(reason)),
        );
    }

    /// Writes each behaviour's votes on its ARC_VOTES_<NAME> channel.
    pub fn votes(&mut self, at: Utime, votes: &[BehaviourVotes], arcs: &ArcSet) {
        for v in votes {
            let message = wire::votes_to_wire(v, arcs);
            self.message(at, &channels::arc_votes(&v.behaviour), &message);
        }
    }

    fn write(
        &mut self,
        write: impl FnOnce(&mut LogWriter<BufWriter<File>>) -> Result<(), LogWriteError>,
    ) {
        if self.paused {
            return;
        }
        if let Some((path, writer, _)) = &mut self.out
            && self.error.is_none()
            && let Err(source) = write(writer)
        {
            self.error = Some(E::from(WriteFailed {
                path: path.to_path_buf(),
                source,
            }));
        }
    }
}
