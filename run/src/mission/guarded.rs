//! The guard between the pipeline and the simulated vehicle: every command
//! the pipeline sends goes through [`Guard::check`], and every pose tick the
//! last one is checked again (a command that was clear may not be a tick
//! later). A mission with no fault should see the guard do nothing; each
//! intervention is a defect of the pipeline to find, so each is counted
//! and the first ones are listed with where and why.

use std::collections::BTreeMap;
use std::time::Instant;

use arcnav_guard::{Guard, GuardCounts, Verdict};
use arcnav_perception::{RangeImage, RangeSlice, SensorModel};
use arcnav_vehicle::frames::Pose;
use arcnav_vehicle::time::micros_to_seconds;
use arcnav_vehicle::{SteeringCommand, Utime};
use serde::Serialize;

use arcnav_config::Resolved;

/// Interventions listed in the report, at most.
const LISTED: usize = 20;

/// One intervention: the guard stopped or slowed the vehicle.
#[derive(Debug, Clone, Serialize)]
pub struct GuardEvent {
    /// Mission time, s.
    pub t_s: f64,
    /// Where the vehicle was (world frame), m.
    pub x: f64,
    pub y: f64,
    /// "stop" or "slow".
    pub verdict: &'static str,
    pub reason: String,
}

/// An input the guard takes.
pub(crate) enum Observed<'a> {
    Pose(&'a Pose),
    Image(&'a RangeImage),
    Slice(&'a RangeSlice),
}

/// What the guard did in a mission (`report.json`'s `guard`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct GuardReport {
    pub stops: u64,
    pub slows: u64,
    /// Time spent stopped, and slowed, by the guard, s.
    pub stopped_s: f64,
    pub slowed_s: f64,
    /// Interventions by reason.
    pub by_reason: BTreeMap<String, u64>,
    /// The first interventions.
    pub first: Vec<GuardEvent>,
    /// What it took in and held.
    #[serde(flatten)]
    pub counts: GuardCounts,
    /// The guard's own time, mean per image or slice and per check, ms.
    pub observe_ms: f64,
    pub check_ms: f64,
    /// The guard's time in all, s.
    pub time_s: f64,
}

impl GuardReport {
    /// Interventions of either kind.
    pub fn interventions(&self) -> u64 {
        self.stops + self.slows
    }
}

/// The guard and what it has done in this mission.
pub(crate) struct GuardWatch {
    guard: Guard,
    /// The pipeline's last command, and what the vehicle was last sent.
    last: Option<SteeringCommand>,
    sent: Option<SteeringCommand>,
    /// The verdict in force: 0 clear, 1 slow, 2 stop.
    level: u8,
    report: GuardReport,
    observe_s: f64,
    observed: u64,
    check_s: f64,
    checks: u64,
    /// Verdicts to log (GUARD_STATUS): every stop and slow, and the clear
    /// after them.
    said: Vec<arcnav_bus::lcmtypes::guard_status_t>,
}

impl GuardWatch {
    /// The guard of `config`, or none when `[guard] enabled = false`.
    pub(crate) fn new(config: &Resolved, sensors: &[SensorModel]) -> Option<Self> {
        config.guard.enabled.then(|| Self {
            guard: Guard::new(&config.guard, &config.vehicle, sensors),
            last: None,
            sent: None,
            level: 0,
            report: GuardReport::default(),
            observe_s: 0.0,
            observed: 0,
            check_s: 0.0,
            checks: 0,
            said: Vec::new(),
        })
    }

    /// One tick's pose, slices and images, before the pipeline takes them.
    pub(crate) fn observe<'a>(
        &mut self,
        pose: &Pose,
        slices: impl Iterator<Item = &'a RangeSlice>,
        images: impl Iterator<Item = &'a RangeImage>,
    ) {
        self.observe_one(Observed::Pose(pose));
        for slice in slices {
            self.observe_one(Observed::Slice(slice));
        }
        for image in images {
            self.observe_one(Observed::Image(image));
        }
    }

    /// The commands to send the vehicle at `t`: each of the pipeline's new
    /// `commands` as the guard lets it through, or (with none new) the last
    /// one again when the guard's verdict on it has changed.
    pub(crate) fn commands(
        &mut self,
        commands: Vec<SteeringCommand>,
        t: Utime,
        t0: Utime,
        at: [f64; 2],
        dt_s: f64,
    ) -> Vec<SteeringCommand> {
        let start = Instant::now();
        let mut out = Vec::with_capacity(commands.len().max(1));
        let fresh = !commands.is_empty();
        for command in commands {
            let guarded = self.verdict(&command, t, t0, at).apply(&command);
            self.last = Some(command);
            out.push(guarded);
        }
        if !fresh && let Some(last) = self.last {
            let guarded = SteeringCommand {
                utime: t,
                ..self.verdict(&last, t, t0, at).apply(&last)
            };
            let differs = self.sent.is_none_or(|s| {
                s.speed_mps != guarded.speed_mps
                    || s.curvature != guarded.curvature
                    || s.arc_index != guarded.arc_index
            });
            if differs {
                out.push(guarded);
            }
        }
        if let Some(sent) = out.last() {
            self.sent = Some(*sent);
        }
        self.held(dt_s);
        self.check_s += start.elapsed().as_secs_f64();
        self.checks += 1;
        out
    }

    fn verdict(&mut self, command: &SteeringCommand, t: Utime, t0: Utime, at: [f64; 2]) -> Verdict {
        let verdict = self.guard.check(command, t);
        let level = match verdict {
            Verdict::Clear => 0,
            Verdict::Slow { .. } => 1,
            Verdict::Stop { .. } => 2,
        };
        if level > self.level
            && let Some(reason) = verdict.reason()
        {
            let name = if level == 2 { "stop" } else { "slow" };
            if level == 2 {
                self.report.stops += 1;
            } else {
                self.report.slows += 1;
            }
            *self
                .report
                .by_reason
                .entry(reason.name().to_string())
                .or_default() += 1;
            if self.report.first.len() < LISTED {
                self.report.first.push(GuardEvent {
                    t_s: micros_to_seconds(t - t0),
                    x: at[0],
                    y: at[1],
                    verdict: name,
                    reason: reason.to_string(),
                });
            }
        }
        if level > 0 || level != self.level {
            self.said.push(arcnav_wire::guard_status_to_wire(
                t,
                command.utime,
                &verdict,
            ));
        }
        self.level = level;
        verdict
    }

    /// One input, before the pipeline takes it (in a replay, in log order:
    /// the commands before it are judged without it).
    pub(crate) fn observe_one(&mut self, input: Observed<'_>) {
        let start = Instant::now();
        match input {
            Observed::Pose(pose) => self.guard.observe_pose(pose),
            Observed::Image(image) => {
                self.guard.observe_image(image);
                self.observed += 1;
            }
            Observed::Slice(slice) => {
                self.guard.observe_slice(slice);
                self.observed += 1;
            }
        }
        self.observe_s += start.elapsed().as_secs_f64();
    }

    /// The verdict on a replayed `command` at `t` (the vehicle at `at`),
    /// counted as in a mission: what the guard would have done.
    pub(crate) fn judge(
        &mut self,
        command: &SteeringCommand,
        t: Utime,
        t0: Utime,
        at: [f64; 2],
    ) -> Verdict {
        let start = Instant::now();
        // The time since the last command was under the verdict then.
        if let Some(last) = self.last {
            self.held(micros_to_seconds((t - last.utime).max(0)));
        }
        self.last = Some(SteeringCommand {
            utime: t,
            ..*command
        });
        let verdict = self.verdict(command, t, t0, at);
        self.check_s += start.elapsed().as_secs_f64();
        self.checks += 1;
        verdict
    }

    /// `dt_s` passed under the verdict in force: counted as stopped or
    /// slowed time.
    fn held(&mut self, dt_s: f64) {
        match self.level {
            1 => self.report.slowed_s += dt_s,
            2 => self.report.stopped_s += dt_s,
            _ => {}
        }
    }

    /// The verdicts to log since the last call.
    pub(crate) fn said(
        &mut self,
    ) -> impl Iterator<Item = arcnav_bus::lcmtypes::guard_status_t> + '_ {
        self.said.drain(..)
    }

    /// What the guard did, for the report.
    pub(crate) fn report(&self) -> GuardReport {
        let mean = |s: f64, n: u64| if n == 0 { 0.0 } else { s * 1e3 / n as f64 };
        GuardReport {
            counts: self.guard.counts(),
            observe_ms: mean(self.observe_s, self.observed),
            check_ms: mean(self.check_s, self.checks),
            time_s: self.observe_s + self.check_s,
            ..self.report.clone()
        }
    }
}
