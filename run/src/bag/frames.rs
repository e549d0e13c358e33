//! The tree of coordinate frames a bag's `/tf_static` and `/tf` describe
//! (REP 105: `map → odom → base_link → sensor`), each frame held by its
//! parent and the transform `parent ← child`, the newest given.

use std::collections::HashMap;

use arcnav_vehicle::Isometry;

/// The most frames a tree holds: a bag naming more is damaged or not a
/// vehicle's (each further one is refused and counted).
pub const MAX_FRAMES: usize = 4096;

/// Frames by name: each one's parent and `parent ← child`.
#[derive(Debug, Clone, Default)]
pub struct Frames {
    parents: HashMap<String, (String, Isometry)>,
    /// Transforms refused: past [`MAX_FRAMES`], or a frame its own parent.
    pub refused: u64,
}

impl Frames {
    /// Sets `parent ← child` (the newest wins).
    pub fn set(&mut self, parent: &str, child: &str, parent_from_child: Isometry) {
        if parent == child
            || (self.parents.len() >= MAX_FRAMES && !self.parents.contains_key(child))
        {
            self.refused += 1;
            return;
        }
        self.parents
            .insert(child.to_owned(), (parent.to_owned(), parent_from_child));
    }

    /// The frame at the top of `frame`'s chain and `top ← frame` (the
    /// identity when it has no parent); `None` when the chain loops.
    pub fn to_top(&self, frame: &str) -> Option<(String, Isometry)> {
        let mut at = frame;
        let mut top_from_frame = Isometry::identity();
        for _ in 0..=MAX_FRAMES {
            match self.parents.get(at) {
                Some((parent, parent_from_at)) => {
                    top_from_frame = parent_from_at * top_from_frame;
                    at = parent;
                }
                None => return Some((at.to_owned(), top_from_frame)),
            }
        }
        None
    }

    /// `a ← b`, when both frames hang from the same top.
    pub fn between(&self, a: &str, b: &str) -> Option<Isometry> {
        let (top_a, top_from_a) = self.to_top(a)?;
        let (top_b, top_from_b) = self.to_top(b)?;
        (top_a == top_b).then(|| top_from_a.inverse() * top_from_b)
    }

    /// Whether `frame` lies on the chain from `from` to its top.
    pub fn on_chain(&self, from: &str, frame: &str) -> bool {
        let mut at = from;
        for _ in 0..=MAX_FRAMES {
            if at == frame {
                return true;
            }
            match self.parents.get(at) {
                Some((parent, _)) => at = parent,
                None => return false,
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    #[test]
    fn a_chain_of_frames_composes_and_a_loop_or_a_stranger_gives_none() {
        let mut frames = Frames::default();
        let odom_from_base = isometry_from_xyz_rpy([10.0, 5.0, 0.0], 0.0, 0.0, 1.0);
        let base_from_lidar = isometry_from_xyz_rpy([0.5, 0.0, 2.0], 0.0, 0.1, 0.0);
        frames.set("odom", "base_link", odom_from_base);
        frames.set("base_link", "lidar", base_from_lidar);
        let (top, top_from_lidar) = frames.to_top("lidar").unwrap();
        assert_eq!(top, "odom");
        assert!(
            (top_from_lidar.to_homogeneous() - (odom_from_base * base_from_lidar).to_homogeneous())
                .norm()
                < 1e-12
        );
        let base_from = frames.between("base_link", "lidar").unwrap();
        assert!((base_from.to_homogeneous() - base_from_lidar.to_homogeneous()).norm() < 1e-12);
        assert!(frames.on_chain("lidar", "odom"));
        assert!(!frames.on_chain("base_link", "lidar"));
        assert!(frames.between("base_link", "camera").is_none());
        frames.set("lidar", "odom", Isometry::identity());
        assert!(
            frames.to_top("base_link").is_none(),
            "odom → base_link → lidar → odom"
        );
        frames.set("x", "x", Isometry::identity());
        assert_eq!(frames.refused, 1);
    }
}
