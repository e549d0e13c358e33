//! External behaviours in lock-step: a program of its own (any language)
//! that `arcnav sim`, `sweep` and `replay` start and talk to over its
//! standard input and output, one decision cycle at a time.
//!
//! Each cycle the program is sent, as [frames](frames) of the messages it
//! would take from the bus live: `WAYPOINTS` when the mission changed,
//! `STEERING_COMMAND` when a new command was sent, the cycle's `POSE`, and
//! last `LOCAL_MAP` (the cycle's time in `cycle_utime`). It answers with its
//! `arc_votes_t` on `ARC_VOTES_<NAME>`, stamped with that time; the cycle
//! waits for it at most `timeout_s` (`start_timeout_s` the first time).
//! Votes of an earlier cycle (an answer that came late) are skipped; other
//! channels are ignored; both counted.
//!
//! A program that exits, hangs past the timeout or writes something that is
//! not a frame is stopped and named, with the last lines of its standard
//! error, and the run goes on without it: it abstains (its votes age out at
//! the arbiter as a silent behaviour's do live; a required one then stops
//! the vehicle). Votes that are not valid (undecodable, over other arcs,
//! from the future, under another name) are refused and counted, and that
//! cycle runs without them. With a program that is itself deterministic the
//! run is: nothing here depends on the wall clock but the timeouts.

pub mod frames;

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use arcnav_arbiter::Votes;
use arcnav_behaviours::{Behaviour, VoteContext};
use arcnav_bus::lcmtypes::pose_t;
use arcnav_bus::messages::AnyMessage;
use arcnav_bus::messages::channels;
use arcnav_bus::{EncodeError, Message};
use arcnav_config::Resolved;
use arcnav_pipeline::{ExternalConfig, Pipeline};
use arcnav_vehicle::{ArcSet, Utime};
use arcnav_wire as wire;

use frames::{Frame, FrameError};

/// Lines of a program's standard error kept to explain its end.
const STDERR_LINES: usize = 12;
/// A line of standard error longer than this is cut, bytes.
const STDERR_LINE_MAX: u64 = 4096;
/// Frames read ahead of the cycle that waits for them.
const READ_AHEAD: usize = 16;
/// How long a program is given to end after its input closes.
const END_GRACE: Duration = Duration::from_secs(2);

/// The environment variable that tells a program it is run in lock-step
/// (value `stdio`): `examples/python/arcnav_behaviour.py` reads it.
pub const TRANSPORT_ENV: &str = "ARCNAV_TRANSPORT";
/// ... and the one that gives it its behaviour name.
pub const NAME_ENV: &str = "ARCNAV_BEHAVIOUR";

/// ... and the one that gives it the arc set's curvatures, 1/m, in index
/// order, comma-separated (each as Rust prints an `f64`: it reads back exactly).
pub const ARCS_ENV: &str = "ARCNAV_ARC_CURVATURES";

fn curvatures(arcs: &ArcSet) -> String {
    let text: Vec<String> = arcs.curvatures().iter().map(f64::to_string).collect();
    text.join(",")
}

/// An external behaviour that could not be started.
#[derive(Debug, thiserror::Error)]
pub enum ExternalError {
    #[error(
        "behaviours.external.{name} has no `command`: arcnav sim, sweep and replay start an \
         external behaviour themselves (give the program and its arguments, \
         command = [\"python3\", \"my_behaviour.py\"])"
    )]
    NoCommand { name: String },
    #[error("cannot start behaviours.external.{name} ({command}): {source}")]
    Spawn {
        name: String,
        command: String,
        source: std::io::Error,
    },
}

/// Starts every `[behaviours.external.NAME]` of `config` and adds it to
/// the pipeline's behaviours (after the built-in ones, in name order).
pub fn attach(config: &Resolved, pipeline: &mut Pipeline) -> Result<(), ExternalError> {
    for (name, external) in &config.external {
        let behaviour =
            ExternalBehaviour::start(name, external, &config.arcs, config.vehicle.kinematics)?;
        pipeline.behaviours.push(Box::new(behaviour));
    }
    Ok(())
}

/// What the reader thread hands the cycle.
enum FromProgram {
    Frame(Frame),
    Garbage(FrameError),
}

/// What a program did, for reports (`behaviour_counters`) and `--stats`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExternalCounts {
    /// Cycles it voted on (votes taken).
    pub voted: u64,
    /// Cycles that ran without its votes (refused, timed out, or after it
    /// ended).
    pub abstained: u64,
    /// Votes refused: not an `arc_votes_t`.
    pub undecodable: u64,
    /// Votes refused: over other arcs, under another name, or not valid.
    pub invalid: u64,
    /// Votes refused: stamped later than the cycle.
    pub from_the_future: u64,
    /// Votes of an earlier cycle, arriving after it had run without them.
    pub late: u64,
    /// Messages on channels other than its votes', ignored.
    pub other_channels: u64,
    /// Cycles it did not answer within the timeout (it is then stopped).
    pub timeouts: u64,
    /// 1 once it ended (exited, hung, wrote garbage), else 0.
    pub ended: u64,
}

/// A behaviour that is a program (see the module documentation).
pub struct ExternalBehaviour {
    name: String,
    channel: String,
    config: ExternalConfig,
    arcs: ArcSet,
    child: Option<Child>,
    to_program: Option<Sender<Vec<u8>>>,
    from_program: Receiver<FromProgram>,
    stderr: Arc<Mutex<VecDeque<String>>>,
    answered_once: bool,
    mission_sent: Option<Utime>,
    command_sent: Option<Utime>,
    resets: u64,
    abstained: bool,
    fault: Option<String>,
    counts: ExternalCounts,
    buf: Vec<u8>,
    /// How commands go on the wire (`[vehicle] kinematics`).
    kinematics: arcnav_vehicle::Kinematics,
}

impl ExternalBehaviour {
    /// Starts `config.command` as behaviour `name`, voting over `arcs`,
    /// for a vehicle of `kinematics` (which sets the type of the commands
    /// it is sent, as on the bus).
    pub fn start(
        name: &str,
        config: &ExternalConfig,
        arcs: &ArcSet,
        kinematics: arcnav_vehicle::Kinematics,
    ) -> Result<Self, ExternalError> {
        let Some((program, args)) = config.command.split_first() else {
            return Err(ExternalError::NoCommand { name: name.into() });
        };
        let mut child = Command::new(program)
            .args(args)
            .env(TRANSPORT_ENV, "stdio")
            .env(NAME_ENV, name)
            .env(ARCS_ENV, curvatures(arcs))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| ExternalError::Spawn {
                name: name.into(),
                command: config.command.join(" "),
                source,
            })?;
        // Spawned with all three piped: each is there, once.
        let (stdin, stdout, stderr) = (
            child.stdin.take().expect("piped stdin"),
            child.stdout.take().expect("piped stdout"),
            child.stderr.take().expect("piped stderr"),
        );
        let (to_program, writes) = mpsc::channel();
        let (reads, from_program) = mpsc::sync_channel(READ_AHEAD);
        let tail = Arc::new(Mutex::new(VecDeque::new()));
        spawn_writer(name, stdin, writes);
        spawn_reader(name, stdout, reads);
        spawn_stderr(name, stderr, Arc::clone(&tail));
        tracing::info!(behaviour = name, command = %config.command.join(" "), "external behaviour started");
        Ok(Self {
            name: name.into(),
            channel: channels::arc_votes(name),
            config: config.clone(),
            arcs: arcs.clone(),
            kinematics,
            child: Some(child),
            to_program: Some(to_program),
            from_program,
            stderr: tail,
            answered_once: false,
            mission_sent: None,
            command_sent: None,
            resets: 0,
            abstained: false,
            fault: None,
            counts: ExternalCounts::default(),
            buf: Vec::new(),
        })
    }

    pub fn counts(&self) -> ExternalCounts {
        self.counts
    }

    /// The cycle's messages, framed: what changed, the pose, the map last.
    fn cycle_frames(&mut self, ctx: &VoteContext<'_>) -> Result<Vec<u8>, String> {
        let mut out = std::mem::take(&mut self.buf);
        out.clear();
        let mut put = |channel: &str, payload: Result<Vec<u8>, EncodeError>| {
            let payload = payload.map_err(|e| format!("{channel}: {e}"))?;
            frames::encode(channel, &payload, &mut out);
            Ok::<(), String>(())
        };
        if self.mission_sent != Some(ctx.mission.version) {
            put(
                channels::WAYPOINTS,
                wire::mission_to_wire(ctx.mission).encode(),
            )?;
            self.mission_sent = Some(ctx.mission.version);
        }
        if let Some(command) = ctx.last_command
            && self.command_sent != Some(command.utime)
        {
            // The type the bus carries for this vehicle.
            put(
                channels::STEERING_COMMAND,
                AnyMessage::command(command, self.kinematics).encode(),
            )?;
            self.command_sent = Some(command.utime);
        }
        put(channels::POSE, pose_t::from(ctx.pose).encode())?;
        let mut map = wire::map_to_wire(ctx.utime, ctx.pose, ctx.map, self.resets);
        if !self.config.elevation {
            wire::drop_elevation(&mut map);
        }
        put(channels::LOCAL_MAP, map.encode())?;
        Ok(out)
    }

    /// Waits for the answer to the cycle at `utime`: its votes, if valid.
    fn answer(&mut self, utime: Utime) -> Option<Votes> {
        let timeout = if self.answered_once {
            self.config.timeout_s
        } else {
            self.config.start_timeout_s
        };
        let deadline = Instant::now() + Duration::from_secs_f64(timeout);
        loop {
            let wait = deadline.saturating_duration_since(Instant::now());
            let frame = match self.from_program.recv_timeout(wait) {
                Ok(FromProgram::Frame(frame)) => frame,
                Ok(FromProgram::Garbage(e)) => {
                    self.end(
                        format!(
                            "wrote something that is not a framed message on its standard \
                             output ({e}; print to standard error instead)"
                        ),
                        Duration::ZERO,
                    );
                    return None;
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.counts.timeouts += 1;
                    self.end(format!("gave no votes within {timeout} s"), Duration::ZERO);
                    return None;
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.end("closed its standard output".into(), END_GRACE);
                    return None;
                }
            };
            if frame.channel != self.channel {
                self.counts.other_channels += 1;
                continue;
            }
            self.answered_once = true;
            let msg = match arcnav_bus::messages::decode_votes(&frame.payload) {
                Ok(msg) => msg,
                Err(e) => {
                    self.counts.undecodable += 1;
                    self.refused(format_args!("undecodable votes ({e})"));
                    return None;
                }
            };
            if msg.utime < utime {
                self.counts.late += 1;
                continue;
            }
            if msg.utime > utime {
                self.counts.from_the_future += 1;
                self.refused(format_args!(
                    "votes stamped {} µs after the cycle they answer",
                    msg.utime - utime
                ));
                return None;
            }
            if msg.behaviour != self.name {
                self.counts.invalid += 1;
                self.refused(format_args!(
                    "votes named {:?} on {}",
                    msg.behaviour, self.channel
                ));
                return None;
            }
            return match wire::votes_from_wire(&msg, &self.arcs) {
                Ok(votes) => Some(votes.votes),
                Err(e) => {
                    self.counts.invalid += 1;
                    self.refused(format_args!("{e}"));
                    None
                }
            };
        }
    }

    /// Said at the first refusal of a run and at each power of two after.
    fn refused(&self, why: std::fmt::Arguments<'_>) {
        let refused = self.counts.undecodable + self.counts.invalid + self.counts.from_the_future;
        if refused.is_power_of_two() {
            tracing::warn!(behaviour = %self.name, refused, "votes refused: {why}");
        }
    }

    /// The program is done for: stopped, and why said once. A program
    /// that closed its output is given `grace` to exit on its own (its
    /// status then says how it ended).
    fn end(&mut self, why: String, grace: Duration) {
        self.to_program = None;
        let status = self.child.take().map(|mut child| {
            let until = Instant::now() + grace;
            let status = loop {
                match child.try_wait() {
                    Ok(Some(status)) => break Some(status),
                    Ok(None) if Instant::now() < until => {
                        std::thread::sleep(Duration::from_millis(5))
                    }
                    _ => {
                        let _ = child.kill();
                        break None;
                    }
                }
            };
            let _ = child.wait();
            status
        });
        // Its last words arrive on their own thread: give them a moment.
        std::thread::sleep(Duration::from_millis(50));
        let tail: Vec<String> = self
            .stderr
            .lock()
            .map(|t| t.iter().cloned().collect())
            .unwrap_or_default();
        let mut message = format!("external behaviour {} {why}", self.name);
        match status {
            Some(Some(status)) => message.push_str(&format!("; it exited ({status})")),
            Some(None) => message.push_str("; it was stopped"),
            None => {}
        }
        if !tail.is_empty() {
            message.push_str(&format!("; its standard error ended: {}", tail.join(" | ")));
        }
        tracing::warn!("{message}; the run goes on without it");
        self.counts.ended = 1;
        self.fault = Some(message);
    }
}

impl Behaviour for ExternalBehaviour {
    fn name(&self) -> &str {
        &self.name
    }

    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        self.abstained = true;
        if self.fault.is_none() {
            match self.cycle_frames(ctx) {
                Ok(bytes) => {
                    let sent = self
                        .to_program
                        .as_ref()
                        .is_some_and(|to| to.send(bytes).is_ok());
                    if !sent {
                        self.end("closed its standard input".into(), END_GRACE);
                    } else if let Some(cast) = self.answer(ctx.utime) {
                        votes.copy_from(&cast);
                        self.abstained = false;
                    }
                }
                Err(e) => tracing::warn!(behaviour = %self.name, "cannot encode its input: {e}"),
            }
        }
        if self.abstained {
            self.counts.abstained += 1;
        } else {
            self.counts.voted += 1;
        }
    }

    fn abstained(&self) -> bool {
        self.abstained
    }

    fn fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }

    fn reset(&mut self) {
        self.resets += 1;
    }

    fn counters(&self) -> Vec<(&'static str, u64)> {
        let c = self.counts;
        vec![
            ("voted", c.voted),
            ("abstained", c.abstained),
            ("refused_undecodable", c.undecodable),
            ("refused_invalid", c.invalid),
            ("refused_from_the_future", c.from_the_future),
            ("late", c.late),
            ("other_channels", c.other_channels),
            ("timeouts", c.timeouts),
            ("ended", c.ended),
        ]
    }
}

impl Drop for ExternalBehaviour {
    /// Its input closes (the helper ends then); a program still running
    /// after [`END_GRACE`] is killed.
    fn drop(&mut self) {
        self.to_program = None;
        if let Some(mut child) = self.child.take() {
            let until = Instant::now() + END_GRACE;
            while Instant::now() < until {
                if let Ok(Some(_)) = child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn spawn_writer(name: &str, mut stdin: ChildStdin, writes: Receiver<Vec<u8>>) {
    let thread = format!("ext-in-{name}");
    let spawned = std::thread::Builder::new().name(thread).spawn(move || {
        use std::io::Write;
        for bytes in writes {
            if stdin
                .write_all(&bytes)
                .and_then(|()| stdin.flush())
                .is_err()
            {
                // The program closed its input: the next send finds the
                // channel closed, and the cycle says so.
                return;
            }
        }
    });
    if let Err(e) = spawned {
        tracing::warn!(behaviour = name, "cannot start its writer thread: {e}");
    }
}

fn spawn_reader(name: &str, stdout: impl Read + Send + 'static, reads: SyncSender<FromProgram>) {
    let thread = format!("ext-out-{name}");
    let spawned = std::thread::Builder::new().name(thread).spawn(move || {
        let mut stdout = BufReader::new(stdout);
        loop {
            let next = match frames::read(&mut stdout) {
                Ok(Some(frame)) => FromProgram::Frame(frame),
                Ok(None) => return,
                Err(e) => FromProgram::Garbage(e),
            };
            let garbage = matches!(next, FromProgram::Garbage(_));
            if reads.send(next).is_err() || garbage {
                return;
            }
        }
    });
    if let Err(e) = spawned {
        tracing::warn!(behaviour = name, "cannot start its reader thread: {e}");
    }
}

/// Its standard error, line by line, to the log (at info) and the tail
/// kept to explain its end.
fn spawn_stderr(
    name: &str,
    stderr: impl Read + Send + 'static,
    tail: Arc<Mutex<VecDeque<String>>>,
) {
    let behaviour = name.to_owned();
    let thread = format!("ext-err-{name}");
    let spawned = std::thread::Builder::new().name(thread).spawn(move || {
        let mut stderr = BufReader::new(stderr);
        let mut line = Vec::new();
        loop {
            line.clear();
            match (&mut stderr)
                .take(STDERR_LINE_MAX)
                .read_until(b'\n', &mut line)
            {
                Ok(0) | Err(_) => return,
                Ok(_) => {}
            }
            let text = String::from_utf8_lossy(&line).trim_end().to_owned();
            tracing::info!(behaviour = %behaviour, "{text}");
            if let Ok(mut tail) = tail.lock() {
                if tail.len() == STDERR_LINES {
                    tail.pop_front();
                }
                tail.push_back(text);
            }
        }
    });
    if let Err(e) = spawned {
        tracing::warn!(
            behaviour = name,
            "cannot start its standard-error thread: {e}"
        );
    }
}
