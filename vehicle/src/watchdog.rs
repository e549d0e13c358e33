//! The vehicle side of the command interface: a watchdog that turns a silent
//! or stale command stream into a stop. A vehicle controller feeds it every
//! command it receives and asks it, at its own rate, what to execute.

use crate::command::SteeringCommand;
use crate::time::Utime;

/// Executes the newest command while it is fresh, stop otherwise.
#[derive(Debug, Clone)]
pub struct CommandWatchdog {
    timeout_us: Utime,
    latest: Option<(Utime, SteeringCommand)>,
    /// Times the watchdog stopped the vehicle because commands stopped coming.
    pub trips: u64,
    tripped: bool,
}

impl CommandWatchdog {
    /// Commands older than `timeout_us` (by receive time) are not executed.
    pub fn new(timeout_us: Utime) -> Self {
        Self {
            timeout_us,
            latest: None,
            trips: 0,
            tripped: false,
        }
    }

    /// A command received at `now`.
    pub fn on_command(&mut self, now: Utime, command: SteeringCommand) {
        self.latest = Some((now, command));
    }

    /// Whether, at `now`, the newest command is fresh enough to execute.
    pub fn is_following(&self, now: Utime) -> bool {
        self.latest
            .is_some_and(|(received, _)| now - received <= self.timeout_us)
    }

    /// Whether any command has been received.
    pub fn has_received(&self) -> bool {
        self.latest.is_some()
    }

    /// What to execute at `now`.
    pub fn command_at(&mut self, now: Utime) -> SteeringCommand {
        match self.latest {
            Some((received, command)) if now - received <= self.timeout_us => {
                self.tripped = false;
                command
            }
            _ => {
                if !self.tripped && self.latest.is_some() {
                    self.trips += 1;
                }
                self.tripped = self.latest.is_some();
                SteeringCommand::stop(now)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive(utime: Utime) -> SteeringCommand {
        SteeringCommand {
            utime,
            curvature: 0.05,
            speed_mps: 2.0,
            arc_index: Some(25),
            vote: 0.8,
            turn_rate_radps: 0.0,
        }
    }

    #[test]
    fn a_fresh_command_is_executed_and_a_silent_stream_stops_the_vehicle() {
        let mut w = CommandWatchdog::new(500_000);
        assert!(w.command_at(0).is_stop(), "nothing received yet: stop");
        assert!(!w.has_received() && !w.is_following(0));
        w.on_command(1_000_000, drive(1_000_000));
        assert_eq!(w.command_at(1_400_000).speed_mps, 2.0);
        assert!(w.is_following(1_400_000));
        assert!(w.command_at(1_600_000).is_stop(), "0.6 s of silence");
        assert!(w.has_received() && !w.is_following(1_600_000));
        assert!(w.command_at(1_700_000).is_stop());
        assert_eq!(w.trips, 1, "one trip per silence");
        w.on_command(2_000_000, drive(2_000_000));
        assert!(!w.command_at(2_100_000).is_stop());
        assert!(w.command_at(3_000_000).is_stop());
        assert_eq!(w.trips, 2);
    }
}
