//! A bounded history of poses, queried at any instant inside it.
//!
//! Perception needs the pose at an image's *capture* time, the local map the
//! pose at *sensing* time of a report that arrives ~600 ms late (002 §5).
//! Between two samples the position and velocity are interpolated linearly and
//! the orientation by slerp. Outside the history the answer is a typed error:
//! guessing a pose would place obstacles in the wrong spot.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Translation3};

use crate::frames::Pose;
use crate::time::Utime;

/// Why a pose could not be stored or found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseHistoryError {
    #[error("the pose history is empty")]
    Empty,
    #[error("time {requested} µs is before the oldest pose in the history ({oldest} µs)")]
    BeforeHistory { requested: Utime, oldest: Utime },
    #[error("time {requested} µs is after the newest pose in the history ({newest} µs)")]
    AfterHistory { requested: Utime, newest: Utime },
    #[error(
        "pose at {utime} µs is not newer than the newest pose ({newest} µs): poses must arrive in time order"
    )]
    NotIncreasing { utime: Utime, newest: Utime },
    #[error("pose at {utime} µs has a value that is not finite")]
    NonFinite { utime: Utime },
    #[error(
        "no pose around {requested} µs: the nearest are {before} µs and {after} µs, more than {max_gap} µs apart"
    )]
    Gap {
        requested: Utime,
        before: Utime,
        after: Utime,
        max_gap: Utime,
    },
}

/// The most recent poses, oldest first, strictly increasing in time.
#[derive(Debug, Clone)]
pub struct PoseHistory {
    poses: VecDeque<Pose>,
    capacity: usize,
    /// Poses older than the newest by more than this are dropped (the
    /// newest of them stays, so the span's first instant can be interpolated).
    span: Option<Utime>,
}

impl PoseHistory {
    /// An empty history keeping at most `capacity` poses (at least 2); the
    /// oldest pose is dropped when a new one arrives at capacity.
    pub fn with_capacity(capacity: usize) -> Self {
        let capacity = capacity.max(2);
        Self {
            poses: VecDeque::with_capacity(capacity.min(1024)),
            capacity,
            span: None,
        }
    }

    /// An empty history keeping the poses of the newest `span` µs, whatever
    /// the pose rate, but never more than `capacity` poses (at least 2).
    pub fn spanning(span: Utime, capacity: usize) -> Self {
        Self {
            span: Some(span.max(0)),
            ..Self::with_capacity(capacity)
        }
    }

    /// A history holding `poses`, which must be strictly increasing in time.
    pub fn from_poses(
        capacity: usize,
        poses: impl IntoIterator<Item = Pose>,
    ) -> Result<Self, PoseHistoryError> {
        let mut history = Self::with_capacity(capacity);
        for pose in poses {
            history.push(pose)?;
        }
        Ok(history)
    }

    /// Appends a pose. Refuses one that is not newer than the newest (the
    /// history stays as it was) or that holds a non-finite number.
    pub fn push(&mut self, pose: Pose) -> Result<(), PoseHistoryError> {
        if !pose.is_finite() {
            return Err(PoseHistoryError::NonFinite { utime: pose.utime });
        }
        if let Some(newest) = self.poses.back()
            && pose.utime <= newest.utime
        {
            return Err(PoseHistoryError::NotIncreasing {
                utime: pose.utime,
                newest: newest.utime,
            });
        }
        if self.poses.len() == self.capacity {
            self.poses.pop_front();
        }
        self.poses.push_back(pose);
        if let Some(span) = self.span {
            let oldest_kept = pose.utime.saturating_sub(span);
            while self.poses.get(1).is_some_and(|p| p.utime <= oldest_kept) {
                self.poses.pop_front();
            }
        }
        Ok(())
    }

    /// Forgets every pose (after a pose jump, for instance).
    pub fn clear(&mut self) {
        self.poses.clear();
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    pub fn oldest(&self) -> Option<&Pose> {
        self.poses.front()
    }

    pub fn newest(&self) -> Option<&Pose> {
        self.poses.back()
    }

    /// True when `utime` lies within `[oldest, newest]`.
    pub fn covers(&self, utime: Utime) -> bool {
        matches!((self.oldest(), self.newest()), (Some(o), Some(n)) if (o.utime..=n.utime).contains(&utime))
    }

    /// The pose at `utime`, interpolated between the two samples around it
    /// only if they are at most `max_gap` apart (a hole in the pose stream is
    /// not papered over).
    pub fn at_within(&self, utime: Utime, max_gap: Utime) -> Result<Pose, PoseHistoryError> {
        let pose = self.at(utime)?;
        let after_index = self.poses.partition_point(|p| p.utime < utime);
        if let (Some(after), Some(before)) = (
            self.poses.get(after_index),
            after_index.checked_sub(1).and_then(|i| self.poses.get(i)),
        ) && after.utime != utime
            && after.utime.saturating_sub(before.utime) > max_gap
        {
            return Err(PoseHistoryError::Gap {
                requested: utime,
                before: before.utime,
                after: after.utime,
                max_gap,
            });
        }
        Ok(pose)
    }

    /// The pose at `utime`, interpolated between the two samples around it.
    pub fn at(&self, utime: Utime) -> Result<Pose, PoseHistoryError> {
        let (Some(oldest), Some(newest)) = (self.poses.front(), self.poses.back()) else {
            return Err(PoseHistoryError::Empty);
        };
        if utime < oldest.utime {
            return Err(PoseHistoryError::BeforeHistory {
                requested: utime,
                oldest: oldest.utime,
            });
        }
        if utime > newest.utime {
            return Err(PoseHistoryError::AfterHistory {
                requested: utime,
                newest: newest.utime,
            });
        }
        // First sample at or after `utime`; it exists because utime <= newest.
        let after_index = self.poses.partition_point(|p| p.utime < utime);
        let after = &self.poses[after_index];
        if after.utime == utime || after_index == 0 {
            return Ok(*after);
        }
        let before = &self.poses[after_index - 1];
        let t = crate::time::seconds_between(before.utime, utime)
            / crate::time::seconds_between(before.utime, after.utime);
        Ok(interpolate(before, after, t, utime))
    }
}

/// The pose a fraction `t` in [0, 1] of the way from `a` to `b`.
fn interpolate(a: &Pose, b: &Pose, t: f64, utime: Utime) -> Pose {
    let translation = a
        .world_from_vehicle
        .translation
        .vector
        .lerp(&b.world_from_vehicle.translation.vector, t);
    let (ra, rb) = (a.world_from_vehicle.rotation, b.world_from_vehicle.rotation);
    // Slerp is ambiguous only for rotations 180° apart, which two consecutive
    // poses never are; then take the nearer sample rather than panic.
    let rotation = ra
        .try_slerp(&rb, t, 1e-9)
        .unwrap_or(if t < 0.5 { ra } else { rb });
    Pose {
        utime,
        world_from_vehicle: Isometry3::from_parts(Translation3::from(translation), rotation),
        velocity: a.velocity.lerp(&b.velocity, t),
        yaw_rate: a.yaw_rate + (b.yaw_rate - a.yaw_rate) * t,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::{isometry_from_xyz_rpy, planar_isometry, yaw_of};
    use approx::assert_relative_eq;
    use nalgebra::Vector3;
    use std::f64::consts::FRAC_PI_2;

    fn pose(utime: Utime, x: f64, y: f64, yaw: f64) -> Pose {
        Pose::at_rest(utime, planar_isometry(x, y, yaw))
    }

    #[test]
    fn position_is_interpolated_linearly_between_samples() {
        let history =
            PoseHistory::from_poses(10, [pose(0, 0.0, 0.0, 0.0), pose(1_000_000, 2.0, 4.0, 0.0)])
                .unwrap();
        let p = history.at(250_000).unwrap();
        assert_eq!(p.utime, 250_000);
        assert_relative_eq!(p.position().x, 0.5, epsilon = 1e-12);
        assert_relative_eq!(p.position().y, 1.0, epsilon = 1e-12);
    }

    #[test]
    fn orientation_is_slerped_midway_between_two_yaws() {
        let history =
            PoseHistory::from_poses(10, [pose(0, 0.0, 0.0, 0.0), pose(100, 0.0, 0.0, FRAC_PI_2)])
                .unwrap();
        let mid = history.at(50).unwrap();
        assert_relative_eq!(
            yaw_of(&mid.world_from_vehicle),
            FRAC_PI_2 / 2.0,
            epsilon = 1e-12
        );
        // And a pitched pose: half the pitch midway.
        let history = PoseHistory::from_poses(
            10,
            [
                Pose::at_rest(0, isometry_from_xyz_rpy([0.0; 3], 0.0, 0.0, 0.0)),
                Pose::at_rest(10, isometry_from_xyz_rpy([0.0; 3], 0.0, 0.4, 0.0)),
            ],
        )
        .unwrap();
        let (_, pitch, _) = history
            .at(5)
            .unwrap()
            .world_from_vehicle
            .rotation
            .euler_angles();
        assert_relative_eq!(pitch, 0.2, epsilon = 1e-12);
    }

    #[test]
    fn exact_sample_times_return_the_sample() {
        let mut a = pose(10, 1.0, 2.0, 0.3);
        a.velocity = Vector3::new(1.0, 0.0, 0.0);
        let history = PoseHistory::from_poses(10, [a, pose(20, 3.0, 2.0, 0.3)]).unwrap();
        assert_eq!(history.at(10).unwrap(), a);
        assert_eq!(history.at(20).unwrap().position().x, 3.0);
    }

    #[test]
    fn times_outside_the_history_are_errors() {
        let history =
            PoseHistory::from_poses(10, [pose(100, 0.0, 0.0, 0.0), pose(200, 1.0, 0.0, 0.0)])
                .unwrap();
        assert_eq!(
            history.at(99),
            Err(PoseHistoryError::BeforeHistory {
                requested: 99,
                oldest: 100
            })
        );
        assert_eq!(
            history.at(201),
            Err(PoseHistoryError::AfterHistory {
                requested: 201,
                newest: 200
            })
        );
        assert_eq!(
            PoseHistory::with_capacity(4).at(0),
            Err(PoseHistoryError::Empty)
        );
    }

    #[test]
    fn unsorted_input_is_refused_and_leaves_the_history_intact() {
        let err = PoseHistory::from_poses(10, [pose(200, 0.0, 0.0, 0.0), pose(100, 1.0, 0.0, 0.0)])
            .unwrap_err();
        assert_eq!(
            err,
            PoseHistoryError::NotIncreasing {
                utime: 100,
                newest: 200
            }
        );

        let mut history = PoseHistory::with_capacity(10);
        history.push(pose(100, 0.0, 0.0, 0.0)).unwrap();
        assert!(
            history.push(pose(100, 5.0, 0.0, 0.0)).is_err(),
            "duplicate time refused"
        );
        assert_eq!(history.len(), 1);
        assert_eq!(history.newest().unwrap().position().x, 0.0);
    }

    #[test]
    fn non_finite_poses_are_refused() {
        let mut history = PoseHistory::with_capacity(4);
        let mut bad = pose(1, 0.0, 0.0, 0.0);
        bad.yaw_rate = f64::NAN;
        assert_eq!(
            history.push(bad),
            Err(PoseHistoryError::NonFinite { utime: 1 })
        );
        assert!(history.is_empty());
    }

    #[test]
    fn a_hole_in_the_pose_stream_is_not_interpolated_across() {
        let history = PoseHistory::from_poses(
            10,
            [
                pose(0, 0.0, 0.0, 0.0),
                pose(100, 1.0, 0.0, 0.0),
                pose(3_000, 9.0, 0.0, 0.0),
            ],
        )
        .unwrap();
        assert!(history.at_within(50, 200).is_ok());
        assert!(history.at_within(3_000, 200).is_ok(), "exactly on a sample");
        assert_eq!(
            history.at_within(1_000, 200),
            Err(PoseHistoryError::Gap {
                requested: 1_000,
                before: 100,
                after: 3_000,
                max_gap: 200
            })
        );
    }

    #[test]
    fn capacity_bounds_the_history_by_dropping_the_oldest() {
        let mut history = PoseHistory::with_capacity(3);
        for t in 0..5 {
            history.push(pose(t, t as f64, 0.0, 0.0)).unwrap();
        }
        assert_eq!(history.len(), 3);
        assert_eq!(history.oldest().unwrap().utime, 2);
        assert!(history.at(1).is_err());
        assert!(history.covers(3) && !history.covers(5));
    }

    #[test]
    fn a_spanning_history_keeps_its_seconds_whatever_the_pose_rate() {
        // 10 s at 50 Hz and at 400 Hz: both keep the newest 10 s, and the
        // pose just before the span so its first instant interpolates.
        for rate_hz in [50, 400] {
            let dt = 1_000_000 / rate_hz;
            let mut history = PoseHistory::spanning(10_000_000, 100_000);
            for k in 0..(30 * rate_hz) {
                history.push(pose(k * dt, k as f64, 0.0, 0.0)).unwrap();
            }
            let newest = history.newest().unwrap().utime;
            assert!(history.at(newest - 10_000_000).is_ok(), "{rate_hz} Hz");
            assert!(history.oldest().unwrap().utime > newest - 10_000_000 - dt);
            assert_eq!(history.len() as i64, 10 * rate_hz + 1);
        }
        // The count bound still holds.
        let mut history = PoseHistory::spanning(10_000_000, 5);
        for t in 0..20 {
            history.push(pose(t, 0.0, 0.0, 0.0)).unwrap();
        }
        assert_eq!(history.len(), 5);
    }
}
