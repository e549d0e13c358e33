//! The way the vehicle came, and following it back.
//!
//! The arbiter reads no pose. What it knows of the vehicle's motion is what
//! its own commands make of it through the vehicle's motion model (command
//! latency, steering rate, acceleration limits): a dead-reckoned path in a
//! frame of its own. [`Trail`] keeps the last stretch of that path as points
//! every [`STEP_M`], each with the direction it was driven in, and leads the
//! vehicle back along it, newest first: each run of one direction is driven
//! the other way (what was driven forwards is backed over, a backing leg is
//! crept forwards) up to the point where the run began, steering by pure
//! pursuit of a point [`LOOKAHEAD_M`] back along it (the curvature of the
//! circle through the rear axle, tangent to the heading, that reaches it:
//! k = 2·y / (x² + y²) in the vehicle frame, backing or not). Pursuit
//! corrects what a replay of the recorded curvatures would accumulate (a
//! curvature taken a latency late, a leg a few centimetres long).

use std::collections::VecDeque;

use arcnav_vehicle::PlanarState;

/// Points are kept this far apart along the path, m.
pub const STEP_M: f64 = 0.25;

/// Pursuit aims this far back along the path, m.
pub const LOOKAHEAD_M: f64 = 2.0;

/// A point counts as reached within this distance, m.
const REACHED_M: f64 = 0.3;

/// A point of the path: the rear axle's position and heading, and whether
/// the vehicle was backing up when it got there.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Point {
    x: f64,
    y: f64,
    yaw: f64,
    reverse: bool,
    /// Path length from the point before, m.
    step_m: f64,
}

/// Where following the trail back leads next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pursuit {
    /// The curvature that reaches the point pursued, 1/m.
    pub curvature: f64,
    /// True when the way back is driven backing up.
    pub reverse: bool,
    /// Path length to where this run began (where the direction changes
    /// again), m.
    pub run_m: f64,
}

/// The last `max_m` of the vehicle's dead-reckoned path.
#[derive(Debug, Clone, Default)]
pub struct Trail {
    max_m: f64,
    points: VecDeque<Point>,
    /// Path length held, m.
    length_m: f64,
    /// The odometer at the newest point, m.
    odometer_at_last: f64,
    /// The direction driven since the newest point (`None`: not moved).
    moving_reverse: Option<bool>,
}

impl Trail {
    /// A trail holding at most `max_m` of path.
    pub fn new(max_m: f64) -> Self {
        Self {
            max_m,
            ..Self::default()
        }
    }

    /// Path length held, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Records the motion from `before` (odometer `odometer_before`) to
    /// `after` (odometer `odometer_after`, signed: it runs backwards when
    /// backing up).
    pub fn record(
        &mut self,
        before: &PlanarState,
        odometer_before: f64,
        after: &PlanarState,
        odometer_after: f64,
    ) {
        let moved = odometer_after - odometer_before;
        if moved == 0.0 || !moved.is_finite() {
            return;
        }
        let reverse = moved < 0.0;
        if self.points.is_empty() {
            self.push(before, reverse, 0.0);
            self.odometer_at_last = odometer_before;
        }
        // Where the direction changed, the vehicle stood: that is a point
        // of its own (a cusp), the end of one run and the start of the next.
        if self.moving_reverse.is_some_and(|was| was != reverse)
            && (odometer_before - self.odometer_at_last).abs() > 1e-3
        {
            let step = (odometer_before - self.odometer_at_last).abs();
            self.push(before, !reverse, step);
            self.odometer_at_last = odometer_before;
        }
        self.moving_reverse = Some(reverse);
        let step = (odometer_after - self.odometer_at_last).abs();
        if step >= STEP_M {
            self.push(after, reverse, step);
            self.odometer_at_last = odometer_after;
        }
    }

    fn push(&mut self, state: &PlanarState, reverse: bool, step_m: f64) {
        self.points.push_back(Point {
            x: state.x,
            y: state.y,
            yaw: state.yaw,
            reverse,
            step_m,
        });
        self.length_m += step_m;
        while self.length_m > self.max_m && self.points.len() > 1 {
            self.points.pop_front();
            if let Some(first) = self.points.front_mut() {
                self.length_m -= first.step_m;
                first.step_m = 0.0;
            }
        }
    }

    /// The way back from `state`: drops the points already reached and
    /// the runs already driven back, then aims at the point `LOOKAHEAD_M`
    /// back along the newest run. `None` when nothing is left to follow.
    pub fn pursue(&mut self, state: &PlanarState) -> Option<Pursuit> {
        loop {
            let run = self.newest_run()?;
            let back_reverse = !run.reverse;
            // The path back: the run's points newest first, then the point
            // it began from.
            let path: Vec<Point> = self
                .points
                .iter()
                .rev()
                .take(run.len + 1)
                .copied()
                .collect();
            let ahead = path
                .iter()
                .position(|p| !reached(state, p, back_reverse))
                .unwrap_or(path.len());
            if ahead == path.len() {
                // Driven back to where the run began: the next run (the
                // other way) starts from that point, kept.
                for _ in 0..run.len {
                    self.pop_newest();
                }
                continue;
            }
            // The points passed are off the trail.
            for _ in 0..ahead {
                self.pop_newest();
            }
            let rest = &path[ahead..];
            let target = rest
                .iter()
                .find(|p| distance(state, p) >= LOOKAHEAD_M)
                .or(rest.last())?;
            let (dx, dy) = (target.x - state.x, target.y - state.y);
            let (sin, cos) = state.yaw.sin_cos();
            let (x, y) = (cos * dx + sin * dy, -sin * dx + cos * dy);
            let d2 = x * x + y * y;
            let curvature = if d2 > 1e-9 { 2.0 * y / d2 } else { 0.0 };
            let run_m =
                distance(state, &rest[0]) + rest.iter().skip(1).map(|p| p.step_m).sum::<f64>();
            return Some(Pursuit {
                curvature,
                reverse: back_reverse,
                run_m,
            });
        }
    }

    /// The newest run: how many of the newest points were all driven one
    /// way, and which. The point before them is where it began (the oldest
    /// point begins the first run).
    fn newest_run(&self) -> Option<Run> {
        let newest = self.points.back()?;
        let len = self
            .points
            .iter()
            .rev()
            .take_while(|p| p.reverse == newest.reverse)
            .count()
            .min(self.points.len() - 1);
        (len > 0).then_some(Run {
            reverse: newest.reverse,
            len,
        })
    }

    /// Gives up the rest of the newest run: the next run (the other way)
    /// is followed from here. False when no run is left.
    pub fn skip_run(&mut self) -> bool {
        let Some(run) = self.newest_run() else {
            return false;
        };
        for _ in 0..run.len {
            self.pop_newest();
        }
        true
    }

    fn pop_newest(&mut self) {
        if let Some(p) = self.points.pop_back() {
            self.length_m -= p.step_m;
        }
    }

    /// Carries on recording from the odometer reading `odometer` (after
    /// following the trail back, which records nothing).
    pub fn resume_from(&mut self, odometer: f64) {
        self.odometer_at_last = odometer;
        self.moving_reverse = None;
    }
}

/// The newest run of one direction.
#[derive(Debug, Clone, Copy)]
struct Run {
    reverse: bool,
    len: usize,
}

fn distance(state: &PlanarState, p: &Point) -> f64 {
    (p.x - state.x).hypot(p.y - state.y)
}

/// True when `p` is within reach of the rear axle, or no longer ahead of
/// it in the direction of travel.
fn reached(state: &PlanarState, p: &Point, reverse: bool) -> bool {
    let along = (p.x - state.x) * state.yaw.cos() + (p.y - state.y) * state.yaw.sin();
    let ahead = if reverse { -along } else { along };
    distance(state, p) < REACHED_M || ahead <= 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64, yaw: f64) -> PlanarState {
        PlanarState {
            x,
            y,
            yaw,
            ..PlanarState::default()
        }
    }

    /// Records a straight drive along the heading `yaw` from `from` (its
    /// odometer `odometer`) over `metres` (negative: backing), in steps of
    /// 5 cm; the new state and odometer.
    fn straight(
        trail: &mut Trail,
        from: PlanarState,
        odometer: f64,
        metres: f64,
    ) -> (PlanarState, f64) {
        let (mut state, mut odo) = (from, odometer);
        let steps = (metres.abs() / 0.05).round() as usize;
        for _ in 0..steps {
            let d = 0.05f64.copysign(metres);
            let next = at(
                state.x + d * state.yaw.cos(),
                state.y + d * state.yaw.sin(),
                state.yaw,
            );
            trail.record(&state, odo, &next, odo + d);
            (state, odo) = (next, odo + d);
        }
        (state, odo)
    }

    #[test]
    fn each_run_is_followed_back_the_other_way_newest_first() {
        let mut trail = Trail::new(50.0);
        let (state, odo) = straight(&mut trail, at(0.0, 0.0, 0.0), 0.0, 10.0);
        let (state, _) = straight(&mut trail, state, odo, -3.0);
        assert!(
            (trail.length_m() - 13.0).abs() < 0.3,
            "{}",
            trail.length_m()
        );
        // At x = 7 after backing 3 m: the backing run is undone forwards,
        // 3 m to the cusp at x = 10.
        let undo = trail.pursue(&state).unwrap();
        assert!(!undo.reverse && undo.curvature.abs() < 1e-9, "{undo:?}");
        assert!((undo.run_m - 3.0).abs() < 0.3, "{undo:?}");
        // At the cusp, the forward run is backed over, 10 m.
        let back = trail.pursue(&at(10.0, 0.0, 0.0)).unwrap();
        assert!(back.reverse, "{back:?}");
        assert!((back.run_m - 10.0).abs() < 0.3, "{back:?}");
        // 0.3 m to the right of the line, pursuit steers back onto it:
        // backing along k > 0 moves the vehicle to the left, (1 − cos ks)/k.
        let off = trail.pursue(&at(6.0, -0.3, 0.0)).unwrap();
        assert!(off.reverse && off.curvature > 0.05, "{off:?}");
        // At the start, nothing is left.
        assert!(trail.pursue(&at(0.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn the_trail_keeps_only_its_newest_stretch() {
        let mut trail = Trail::new(5.0);
        straight(&mut trail, at(0.0, 0.0, 0.0), 0.0, 20.0);
        assert!(trail.length_m() <= 5.0 && trail.length_m() > 4.5);
        // Followed back from its end, it ends 5 m short of the start.
        let mut state = at(20.0, 0.0, 0.0);
        while let Some(p) = trail.pursue(&state) {
            assert!(p.reverse);
            state.x -= 0.1;
        }
        assert!((state.x - 15.0).abs() < 0.5, "{state:?}");
    }
}
