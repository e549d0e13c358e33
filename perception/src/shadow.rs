//! Ground inside an image's footprint that the image did not see.
//!
//! The footprint ([`crate::fov`]) runs, per column, from the nearest return
//! to the farthest, which is what pruning needs: an old cell in it that the
//! image does not report again is gone (002 §5). It is not what the ground
//! *seen* is. Beyond an edge the ground may fall away out of sight: a crest,
//! the top of a rock, the near edge of a trench. The next return of the
//! column then lies farther on and lower, and the stretch between is a
//! shadow. Seen from afar, a trench's floor and a hillside falling at 10°
//! look alike there; what lies in the shadow is unknown, not free.
//!
//! Each shadow is an annular sector around the sensor: one column's
//! direction, its angular width, and the stretch from the edge to the next
//! return. [`ShadowIndex`] answers "is this point in a shadow" for a whole
//! report at the cost of an `atan2` and a few comparisons.

use arcnav_vehicle::frames::wrap_angle;
use nalgebra::Point2;

/// One column's shadow, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shadow {
    /// Direction of the column from [`Shadows::origin`], rad, counter-clockwise from +x.
    pub azimuth: f32,
    /// Half the column's angular width, rad.
    pub half_width: f32,
    /// Horizontal distance from the origin of the edge, m.
    pub near: f32,
    /// ... and of the next return beyond it, m.
    pub far: f32,
}

impl Shadow {
    /// The widest a shadow may be: a column wider than this is no column of
    /// a range image (the ERIM's are 0.5°, a 2048-column lidar's 0.18°), rad.
    pub const MAX_HALF_WIDTH: f32 = 0.1;

    /// Whether the fields can describe a column's shadow (finite, ordered,
    /// not wider than [`Self::MAX_HALF_WIDTH`]).
    pub fn is_valid(&self) -> bool {
        self.azimuth.is_finite()
            && (0.0..=Self::MAX_HALF_WIDTH).contains(&self.half_width)
            && self.near >= 0.0
            && self.far >= self.near
            && self.far.is_finite()
    }
}

/// The shadows of one image.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Shadows {
    /// The sensor's ground position at capture, world frame.
    pub origin: Point2<f64>,
    pub sectors: Vec<Shadow>,
}

impl Shadows {
    pub fn clear(&mut self) {
        self.origin = Point2::origin();
        self.sectors.clear();
    }

    pub fn is_empty(&self) -> bool {
        self.sectors.is_empty()
    }

    /// Adds `other`'s sectors, seen from `other.origin`, to these: taking
    /// its origin when these hold none yet, or else each sector redrawn
    /// from this origin (the sensor moved a little between the slices of
    /// one frame): the direction of its middle, the distances of its two
    /// ends, widened by the angle the stretch between them subtends.
    pub fn append(&mut self, other: &Shadows) {
        if self.sectors.is_empty() {
            self.origin = other.origin;
        }
        let (from, to) = (other.origin, self.origin);
        if from == to {
            self.sectors.extend_from_slice(&other.sectors);
            return;
        }
        self.sectors.extend(other.sectors.iter().map(|s| {
            let (sin, cos) = f64::from(s.azimuth).sin_cos();
            let end = |d: f32| {
                let d = f64::from(d);
                let (x, y) = (from.x + d * cos - to.x, from.y + d * sin - to.y);
                (y.atan2(x), x.hypot(y))
            };
            let ((a, near), (b, far)) = (end(s.near), end(s.far));
            let (mid, spread) = (a + 0.5 * wrap_angle(b - a), 0.5 * wrap_angle(b - a).abs());
            // The column's width at its middle, seen from here.
            let middle = 0.5 * f64::from(s.near + s.far);
            let scale = middle / (0.5 * (near + far)).max(1e-3);
            Shadow {
                azimuth: wrap_angle(mid) as f32,
                half_width: ((f64::from(s.half_width) * scale + spread) as f32)
                    .min(Shadow::MAX_HALF_WIDTH),
                near: near.min(far) as f32,
                far: near.max(far) as f32,
            }
        }));
    }
}

/// Bins of direction, each listing the shadows that reach into it.
const BINS: usize = 1024;

/// [`Shadows`] indexed by direction, to test many points. Keep one and
/// [`ShadowIndex::build`] it per report: it allocates only to grow.
#[derive(Debug, Clone, Default)]
pub struct ShadowIndex {
    origin: [f64; 2],
    sectors: Vec<Shadow>,
    /// Bin `b`'s shadows are `entries[starts[b]..starts[b + 1]]`.
    starts: Vec<u32>,
    entries: Vec<u32>,
}

fn bin_of(azimuth: f32) -> isize {
    let turns = azimuth as f64 / std::f64::consts::TAU;
    ((turns - turns.floor()) * BINS as f64) as isize
}

impl ShadowIndex {
    /// Indexes `shadows` (those that are not [`Shadow::is_valid`] are left out).
    pub fn build(&mut self, shadows: &Shadows) {
        self.origin = [shadows.origin.x, shadows.origin.y];
        self.sectors.clear();
        self.sectors
            .extend(shadows.sectors.iter().filter(|s| s.is_valid()));
        // Each sector spans at most a few bins: count, then place.
        let spans = |s: &Shadow| {
            let first = bin_of(s.azimuth - s.half_width);
            let width = (f64::from(2.0 * s.half_width) / std::f64::consts::TAU * BINS as f64).ceil()
                as isize;
            (first..=first + width + 1).map(|b| b.rem_euclid(BINS as isize) as usize)
        };
        self.starts.clear();
        self.starts.resize(BINS + 1, 0);
        for s in &self.sectors {
            for b in spans(s) {
                self.starts[b + 1] += 1;
            }
        }
        for b in 0..BINS {
            self.starts[b + 1] += self.starts[b];
        }
        self.entries.clear();
        self.entries.resize(self.starts[BINS] as usize, 0);
        let mut next = self.starts.clone();
        for (k, s) in self.sectors.iter().enumerate() {
            for b in spans(s) {
                self.entries[next[b] as usize] = k as u32;
                next[b] += 1;
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        self.sectors.is_empty()
    }

    /// Whether world point (`x`, `y`) lies in one of the shadows.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        if self.sectors.is_empty() {
            return false;
        }
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let (azimuth, distance) = (dy.atan2(dx) as f32, dx.hypot(dy) as f32);
        let b = bin_of(azimuth) as usize % BINS;
        let (start, end) = (self.starts[b] as usize, self.starts[b + 1] as usize);
        self.entries[start..end].iter().any(|&k| {
            let s = &self.sectors[k as usize];
            let off = wrap_angle(f64::from(azimuth - s.azimuth));
            off.abs() <= f64::from(s.half_width) && (s.near..=s.far).contains(&distance)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn index(origin: (f64, f64), sectors: Vec<Shadow>) -> ShadowIndex {
        let mut index = ShadowIndex::default();
        index.build(&Shadows {
            origin: Point2::new(origin.0, origin.1),
            sectors,
        });
        index
    }

    #[test]
    fn a_sector_holds_the_points_between_its_edges_and_its_distances() {
        let shadow = Shadow {
            azimuth: 0.5,
            half_width: 0.05,
            near: 10.0,
            far: 14.0,
        };
        let index = index((100.0, -20.0), vec![shadow]);
        let at = |angle: f64, distance: f64| {
            index.contains(
                100.0 + distance * angle.cos(),
                -20.0 + distance * angle.sin(),
            )
        };
        assert!(at(0.5, 12.0));
        assert!(at(0.46, 10.1) && at(0.54, 13.9));
        assert!(
            !at(0.5, 9.9) && !at(0.5, 14.1),
            "before the edge, beyond the return"
        );
        assert!(!at(0.56, 12.0) && !at(0.44, 12.0), "beside the column");
    }

    #[test]
    fn sectors_across_the_half_turn_are_found_on_both_sides() {
        // Straight behind (±π), where atan2 jumps.
        let index = index(
            (0.0, 0.0),
            vec![Shadow {
                azimuth: std::f32::consts::PI - 0.01,
                half_width: 0.03,
                near: 5.0,
                far: 8.0,
            }],
        );
        for angle in [3.13f64, std::f64::consts::PI, -3.13] {
            assert!(
                index.contains(6.0 * angle.cos(), 6.0 * angle.sin()),
                "{angle}"
            );
        }
        assert!(!index.contains(6.0, 0.0));
    }

    #[test]
    fn sectors_appended_from_elsewhere_cover_the_same_ground() {
        let seen_from = |origin: (f64, f64), sectors| Shadows {
            origin: Point2::new(origin.0, origin.1),
            sectors,
        };
        let column = Shadow {
            azimuth: 0.3,
            half_width: 0.004,
            near: 18.0,
            far: 19.5,
        };
        let mut shadows = Shadows::default();
        shadows.append(&seen_from((2.0, 1.0), vec![column]));
        assert_eq!(shadows, seen_from((2.0, 1.0), vec![column]), "taken whole");
        // From 0.8 m on and a little aside (the next slice's sensor): the
        // same stretch of ground, seen from the first origin.
        shadows.append(&seen_from((2.8, 1.1), vec![column]));
        assert_eq!(shadows.sectors.len(), 2);
        let mut index = ShadowIndex::default();
        index.build(&seen_from((2.0, 1.0), vec![shadows.sectors[1]]));
        let at = |d: f64, angle: f64| (2.8 + d * angle.cos(), 1.1 + d * angle.sin());
        for d in [18.1, 18.75, 19.4] {
            let (x, y) = at(d, 0.3);
            assert!(index.contains(x, y), "{d} m along the column");
        }
        for (d, angle) in [(17.8, 0.3), (19.8, 0.3), (18.75, 0.31)] {
            let (x, y) = at(d, angle);
            assert!(!index.contains(x, y), "{d} m at {angle} rad");
        }
    }

    #[test]
    fn invalid_sectors_are_left_out() {
        let bad = [
            (f32::NAN, 0.01, 1.0, 2.0),
            (0.0, 3.0, 1.0, 2.0),
            (0.0, 0.01, 2.0, 1.0),
            (0.0, 0.01, 1.0, f32::INFINITY),
            (0.0, -0.01, 1.0, 2.0),
        ];
        let sectors = bad
            .iter()
            .map(|&(azimuth, half_width, near, far)| Shadow {
                azimuth,
                half_width,
                near,
                far,
            })
            .collect::<Vec<_>>();
        assert!(sectors.iter().all(|s| !s.is_valid()));
        let index = index((0.0, 0.0), sectors);
        assert!(index.is_empty());
        assert!(!index.contains(1.5, 0.0));
    }
}
