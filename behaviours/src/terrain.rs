//! The ground along each arc at the vehicle's scale (004 §IV): attitude,
//! belly clearance and roughness predicted from the local map's elevation
//! layer, for obstacle avoidance to forbid, lower and slow arcs with.
//!
//! For poses every `step_m` along an arc (vehicle frame of the map's pose,
//! then world frame), the four wheel contacts are looked up in the
//! elevation layer: each wheel stands on the highest cell mean under its
//! tyre (the k × k cells nearest the contact point, k = `tyre_patch_m` in
//! cells, at least one: 2 × 2 cells of 0.2 m for the default 0.3 m).
//!
//! - **Inclination (004 §IV-B, at vehicle scale)**: 004 fits a plane to the
//!   footprint's cells and compares its inclination with the robot's limit.
//!   A vehicle on wheels stands on its four contacts, and a rigid body on
//!   four uneven contacts rests on three of them, tipping across a
//!   diagonal: its roll is then one axle's (z_left − z_right)/track and its
//!   pitch one side's (z_rear − z_front)/wheelbase. The prediction takes
//!   the worse axle and the worse side, so it is what the vehicle can reach
//!   on that ground whichever way it settles: on a plane it is the plane's
//!   roll and pitch; a 30 cm rock under one wheel of a 1.82 m track gives
//!   atan(0.3/1.82) = 9.4° of roll.
//! - **Vertical obstacles (004 §IV-A)**: under the body, between the axles
//!   and inside the wheels, every cell's height h above the plane of the
//!   four contacts is compared with the minimum passing height
//!   `V_min = h_minbase + σ` (004 eq. 5; h_minbase = `vehicle.ground_clearance_m`,
//!   σ the cell's standard deviation). h ≥ V_min strikes the chassis;
//!   below it the graded traversability is
//!   `V_trav(h) = (V_min − h) / V_min` (eq. 6), and 1 − V_trav is a cost.
//! - **Twist**: the fourth contact's distance below the plane of the other
//!   three, |z_FL + z_RR − z_FR − z_RL|: how far the suspension articulates,
//!   the roughness the vehicle feels at its scale.
//! - **Bumps**: under each tyre, the range of its cells' heights less what
//!   the contacts' slope explains over them: stones and ruts smaller than
//!   the vehicle, which its wheels ride over one by one.
//!
//! A pose is **forbidden** when its roll or pitch exceeds the configured
//! limit or the chassis strikes; obstacle avoidance treats the first
//! forbidden pose as a collision at that distance. Otherwise its
//! **severity** in [0, 1] is the largest of: attitude within `caution_deg`
//! of the limit (0 at limit − caution, 1 at the limit), the chassis's
//! height h under it rising from `smooth_m` to V_min, the twist rising
//! from `smooth_m` to `max_twist_m` and the bumps from `smooth_m` to
//! `max_bump_m` (below `smooth_m` ground is ordinary:
//! the noise of the measurements, grass, pebbles; without that floor the
//! vehicle slowed on open fields). A pose where fewer than three
//! wheels stand on measured ground ends the arc's judgement: unmeasured
//! ground is obstacle avoidance's unseen ground, not a slope.

use arcnav_localmap::ElevationGrid;
use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::{Arc, DrivenPath, Isometry, VehicleConfig};
use serde::{Deserialize, Serialize};

/// Lives in `[behaviours.obstacle_avoidance.terrain]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TerrainConfig {
    /// Judge the ground's attitude, clearance and roughness at all.
    pub enabled: bool,
    /// Poses along each arc are this far apart, m.
    pub step_m: f64,
    /// Highest predicted roll, degrees (at most `vehicle.max_slope_deg`).
    pub max_roll_deg: f64,
    /// Highest predicted pitch, degrees (at most `vehicle.max_slope_deg`).
    pub max_pitch_deg: f64,
    /// Attitude this close to a limit starts to count against an arc, degrees.
    pub caution_deg: f64,
    /// Side of the square a tyre stands on, m: it stands on the highest
    /// of the layer's cells there.
    pub tyre_patch_m: f64,
    /// Twist at which roughness severity reaches 1, m.
    pub max_twist_m: f64,
    /// Bumps under a tyre at which roughness severity reaches 1, m.
    pub max_bump_m: f64,
    /// Twist, bumps, and heights under the chassis above the wheels'
    /// plane up to this are ordinary ground (noise, grass, small stones):
    /// no severity, m.
    pub smooth_m: f64,
    /// Vote a clear arc loses at severity 1.
    pub penalty: f64,
    /// Speed at severity 1 as a fraction of cruise (the floor while an arc
    /// is acceptable).
    pub min_speed_fraction: f64,
}

impl Default for TerrainConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            step_m: 0.5,
            max_roll_deg: 25.0,
            max_pitch_deg: 25.0,
            caution_deg: 8.0,
            tyre_patch_m: 0.3,
            max_twist_m: 0.4,
            max_bump_m: 0.2,
            smooth_m: 0.05,
            penalty: 0.5,
            min_speed_fraction: 0.4,
        }
    }
}

impl TerrainConfig {
    /// Checks the values (keys relative to the table).
    pub fn validate(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        config::in_range("step_m", self.step_m, 0.1, 5.0)?;
        for (key, value) in [
            ("max_roll_deg", self.max_roll_deg),
            ("max_pitch_deg", self.max_pitch_deg),
        ] {
            config::positive(key, value)?;
            if value > vehicle.max_slope_deg {
                return Err(ConfigError::new(
                    key,
                    format!(
                        "is {value}°, beyond what the vehicle drives (vehicle.max_slope_deg = {}°)",
                        vehicle.max_slope_deg
                    ),
                ));
            }
        }
        config::positive("caution_deg", self.caution_deg)?;
        config::in_range("tyre_patch_m", self.tyre_patch_m, 0.0, 2.0)?;
        config::positive("max_twist_m", self.max_twist_m)?;
        config::non_negative("smooth_m", self.smooth_m)?;
        config::positive("max_bump_m", self.max_bump_m)?;
        if self.smooth_m
            >= self
                .max_twist_m
                .min(self.max_bump_m)
                .min(vehicle.ground_clearance_m)
        {
            return Err(ConfigError::new(
                "smooth_m",
                format!(
                    "is {} m, must be below max_twist_m, max_bump_m and vehicle.ground_clearance_m",
                    self.smooth_m
                ),
            ));
        }
        config::in_range("penalty", self.penalty, 0.0, 2.0)?;
        config::in_range("min_speed_fraction", self.min_speed_fraction, 0.0, 1.0)
    }
}

/// How the vehicle would stand at one pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stance {
    /// Worse axle's roll and worse side's pitch, radians, magnitudes.
    pub roll: f64,
    pub pitch: f64,
    /// |z_FL + z_RR − z_FR − z_RL|, m.
    pub twist: f64,
    /// The largest height range under a tyre beyond what the ground's
    /// slope explains: stones, ruts, m.
    pub bumps: f64,
    /// Highest 1 − V_trav under the body (004 eq. 6) of the heights above
    /// `smooth_m` (lower ones are ordinary ground: 0); ≥ 1: the chassis
    /// strikes.
    pub belly: f64,
    /// Highest h − smooth_m over V_min − smooth_m under the body: the
    /// chassis's share of the severity.
    pub belly_severity: f64,
}

/// A stance as the hot path computes it: roll and pitch as tangents, so
/// that no pose below the caution band pays for an arctangent.
#[derive(Debug, Clone, Copy)]
struct RawStance {
    roll_tan: f64,
    pitch_tan: f64,
    twist: f64,
    bumps: f64,
    belly: f64,
    belly_severity: f64,
}

impl RawStance {
    fn stance(&self) -> Stance {
        Stance {
            roll: self.roll_tan.atan(),
            pitch: self.pitch_tan.atan(),
            twist: self.twist,
            bumps: self.bumps,
            belly: self.belly,
            belly_severity: self.belly_severity,
        }
    }
}

impl From<&Stance> for RawStance {
    fn from(s: &Stance) -> Self {
        Self {
            roll_tan: s.roll.tan(),
            pitch_tan: s.pitch.tan(),
            twist: s.twist,
            bumps: s.bumps,
            belly: s.belly,
            belly_severity: s.belly_severity,
        }
    }
}

/// Roll and pitch limits as tangents: where the caution band starts and
/// where a pose is forbidden.
#[derive(Debug, Clone, Copy)]
struct TanLimits {
    roll_caution: f64,
    roll_max: f64,
    pitch_caution: f64,
    pitch_max: f64,
}

impl TanLimits {
    fn new(c: &TerrainConfig) -> Self {
        // Below zero degrees the band starts at once (any tangent exceeds it).
        let tan = |deg: f64| {
            if deg <= 0.0 {
                f64::NEG_INFINITY
            } else {
                deg.to_radians().tan()
            }
        };
        Self {
            roll_caution: tan(c.max_roll_deg - c.caution_deg),
            roll_max: tan(c.max_roll_deg),
            pitch_caution: tan(c.max_pitch_deg - c.caution_deg),
            pitch_max: tan(c.max_pitch_deg),
        }
    }
}

/// Each tyre's block of cells on a layer of one cell size: k × k cells,
/// centred on the nearest cell corner (k even) or cell (k odd).
#[derive(Debug, Clone, Copy)]
struct Block {
    k: usize,
    /// Added to a contact's cell coordinate to reach the block's first cell.
    shift: f64,
}

impl Block {
    fn new(tyre_patch_m: f64, cell_size_m: f64) -> Self {
        // (0.3 / 0.2 is 1.4999… in binary: nudged, it rounds as written.)
        let k = ((tyre_patch_m / cell_size_m + 1e-9).round() as usize).max(1);
        let half = if k.is_multiple_of(2) { 0.5 } else { 0.0 };
        Self {
            k,
            shift: half - (k / 2) as f64,
        }
    }
}

/// What a stance means for driving there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Judgement {
    /// Beyond a roll or pitch limit, or the chassis strikes.
    Forbidden,
    /// Drivable; severity in [0, 1] (see the module documentation).
    Passable { severity: f64 },
}

/// The verdict on one arc.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArcTerrain {
    /// Distance of the first forbidden pose, and where it is (vehicle frame).
    pub forbidden: Option<(f64, [f32; 2])>,
    /// Highest severity before it (or along the whole arc).
    pub severity: f64,
    /// Highest severity within the speed horizon.
    pub near_severity: f64,
}

/// Offsets (vehicle frame of a pose) of the points looked up.
#[derive(Debug, Clone)]
struct Probes {
    /// Per wheel (FL, FR, RL, RR): its contact point.
    wheels: [[f64; 2]; 4],
    /// Points under the chassis.
    belly: Vec<[f64; 2]>,
    wheelbase: f64,
    track: f64,
    clearance: f64,
}

/// The slopes along and across the vehicle of the mean plane of its four
/// contact heights (FL, FR, RL, RR) on a `wheelbase` × `track` rectangle.
fn contact_slopes([fl, fr, rl, rr]: [f64; 4], wheelbase: f64, track: f64) -> (f64, f64) {
    (
        ((fl + fr) - (rl + rr)) / (2.0 * wheelbase),
        ((fl + rl) - (fr + rr)) / (2.0 * track),
    )
}

/// Predicts stances along arcs.
#[derive(Debug, Clone)]
pub struct TerrainCheck {
    config: TerrainConfig,
    probes: Probes,
    /// Per arc: the poses judged (x, y, cos, sin in the vehicle frame) and
    /// their distances.
    poses: Vec<Vec<(f64, [f64; 4])>>,
    /// Per arc: the poses backing up along it (see
    /// [`TerrainCheck::with_reverse`]).
    reverse_poses: Vec<Vec<(f64, [f64; 4])>>,
    limits: TanLimits,
    /// The chassis is checked every this many poses.
    belly_stride: usize,
    /// How far arcs are judged, m.
    reach_m: f64,
    /// Scratch: per path, the poses [`TerrainCheck::judge_paths`] judges.
    driven: Vec<Vec<(f64, [f64; 4])>>,
    sampled: Vec<(f64, arcnav_vehicle::ArcPose)>,
}

impl TerrainCheck {
    /// For arcs of `curvatures`, judged `reach_m` along.
    pub fn new(
        config: &TerrainConfig,
        vehicle: &VehicleConfig,
        curvatures: &[f64],
        reach_m: f64,
    ) -> Self {
        let (l, t) = (vehicle.wheelbase_m, vehicle.track_m);
        let wheels = [[l, t / 2.0], [l, -t / 2.0], [0.0, t / 2.0], [0.0, -t / 2.0]];
        // Under the chassis: between the axles, inside the tyres, every
        // 0.4 m (two cells of the default layer).
        let inner = (t / 2.0 - config.tyre_patch_m / 2.0 - 0.25).max(0.0);
        let mut belly = Vec::new();
        let (nx, ny) = (
            ((l - 2.0 * 0.6) / 0.4).floor().max(0.0) as usize,
            (2.0 * inner / 0.4).floor() as usize,
        );
        for i in 0..=nx {
            for j in 0..=ny {
                let x = 0.6 + (l - 1.2) * i as f64 / nx.max(1) as f64;
                let y = if ny == 0 {
                    0.0
                } else {
                    -inner + 2.0 * inner * j as f64 / ny as f64
                };
                belly.push([x, y]);
            }
        }
        let poses = curvatures
            .iter()
            .map(|&k| {
                Arc::new(k)
                    .sample(reach_m, config.step_m)
                    .enumerate()
                    .map(|(i, p)| {
                        let s = (i as f64 * config.step_m).min(reach_m);
                        let (sin, cos) = p.heading.sin_cos();
                        (s, [p.position.x, p.position.y, cos, sin])
                    })
                    .collect()
            })
            .collect();
        Self {
            config: config.clone(),
            probes: Probes {
                wheels,
                belly,
                wheelbase: l,
                track: t,
                clearance: vehicle.ground_clearance_m,
            },
            poses,
            reverse_poses: Vec::new(),
            limits: TanLimits::new(config),
            // The rows under the chassis span l − 1.2 m (2.1 m for the
            // M998): poses at most that far apart let every ground point
            // pass under the span, so within half a row spacing of a row.
            belly_stride: ((l - 1.2) / config.step_m).floor().max(1.0) as usize,
            reach_m,
            driven: Vec::new(),
            sampled: Vec::new(),
        }
    }

    /// Also judges backing up along every arc, `reach_m` back: backing
    /// along curvature k for s metres puts the vehicle at (−sin ks/k,
    /// (1 − cos ks)/k) heading −ks, the forward pose mirrored (x → −x) with
    /// its heading negated; it still faces forwards.
    #[must_use]
    pub fn with_reverse(mut self, curvatures: &[f64], reach_m: f64) -> Self {
        self.reverse_poses = curvatures
            .iter()
            .map(|&k| {
                Arc::new(k)
                    .sample(reach_m, self.config.step_m)
                    .enumerate()
                    .map(|(i, p)| {
                        let s = (i as f64 * self.config.step_m).min(reach_m);
                        let (sin, cos) = p.heading.sin_cos();
                        (s, [-p.position.x, p.position.y, cos, -sin])
                    })
                    .collect()
            })
            .collect();
        self
    }

    pub fn config(&self) -> &TerrainConfig {
        &self.config
    }

    /// How the vehicle stands at the pose `world_from_pose` (x, y, cos, sin
    /// of its yaw in the world), if at least three wheels stand on
    /// measured ground.
    pub fn stance(&self, grid: &ElevationGrid, world_from_pose: [f64; 4]) -> Option<Stance> {
        let block = Block::new(self.config.tyre_patch_m, grid.cell_size_m);
        self.stance_with(grid, block, world_from_pose, true)
            .map(|raw| raw.stance())
    }

    /// [`TerrainCheck::stance`] with tangents; the ground under the
    /// chassis only when `check_belly` (0 otherwise).
    fn stance_with(
        &self,
        grid: &ElevationGrid,
        block: Block,
        world_from_pose: [f64; 4],
        check_belly: bool,
    ) -> Option<RawStance> {
        // The blocks' loops unrolled for the common sizes (the default
        // 0.3 m tyre on 0.2 m cells is 2 × 2): the same sums in the same
        // order.
        match block.k {
            1 => self.stance_of::<1>(grid, block, world_from_pose, check_belly),
            2 => self.stance_of::<2>(grid, block, world_from_pose, check_belly),
            3 => self.stance_of::<3>(grid, block, world_from_pose, check_belly),
            _ => self.stance_of::<0>(grid, block, world_from_pose, check_belly),
        }
    }

    /// [`TerrainCheck::stance_with`] for blocks of `K` × `K` cells (0: of
    /// `block.k`).
    #[inline(always)]
    fn stance_of<const K: usize>(
        &self,
        grid: &ElevationGrid,
        block: Block,
        world_from_pose: [f64; 4],
        check_belly: bool,
    ) -> Option<RawStance> {
        let [tx, ty, cos, sin] = world_from_pose;
        // The pose in the grid's cell coordinates: a point (px, py) of the
        // pose's frame lies in cell (u, v) = (u0 + cu·px - su·py,
        // v0 + su·px + cu·py), floored. Checked non-negative first, so
        // truncating is flooring: no libm call per lookup.
        let inverse = 1.0 / grid.cell_size_m;
        let (u0, v0) = (
            tx * inverse - grid.origin.0 as f64,
            ty * inverse - grid.origin.1 as f64,
        );
        let (cu, su) = (cos * inverse, sin * inverse);
        let side = grid.side as usize;
        let limit = grid.side as f64;
        let at = |p: &[f64; 2]| -> Option<[f32; 2]> {
            let (u, v) = (u0 + cu * p[0] - su * p[1], v0 + su * p[0] + cu * p[1]);
            if !(u >= 0.0 && v >= 0.0 && u < limit && v < limit) {
                return None;
            }
            let cell = grid.cells[v as usize * side + u as usize];
            cell[0].is_finite().then_some(cell)
        };
        // Each tyre: the k × k cells around the cell corner (k even) or
        // the cell (k odd) nearest its contact point, read as one block.
        let k = if K == 0 { block.k } else { K };
        // First pass: each tyre's block, its first cell's grid position and
        // the mean of its known cells.
        let mut blocks: [Option<(usize, usize, [f64; 2])>; 4] = [None; 4];
        let mut z = [f64::NAN; 4];
        for (wheel, p) in self.probes.wheels.iter().enumerate() {
            let (fu, fv) = (u0 + cu * p[0] - su * p[1], v0 + su * p[0] + cu * p[1]);
            let (u, v) = (fu + block.shift, fv + block.shift);
            if !(u >= 0.0 && v >= 0.0 && u + (k as f64) < limit && v + (k as f64) < limit) {
                continue;
            }
            let (u, v) = (u as usize, v as usize);
            let (mut sum, mut count) = (0.0f32, 0u32);
            for r in 0..k {
                let row = &grid.cells[(v + r) * side + u..][..k];
                for cell in row.iter().filter(|c| c[0].is_finite()) {
                    sum += cell[0];
                    count += 1;
                }
            }
            if count > 0 {
                z[wheel] = f64::from(sum) / f64::from(count);
                // The contact point's offset from the block's first cell
                // centre, in cells.
                blocks[wheel] = Some((u, v, [fu - u as f64 - 0.5, fv - v as f64 - 0.5]));
            }
        }
        // One wheel on unmeasured ground stands where the plane of the
        // other three puts it.
        let mut unknown = (0..4).filter(|&w| z[w].is_nan());
        match (unknown.next(), unknown.next()) {
            (None, _) => {}
            (Some(w), None) => {
                let [fl, fr, rl, rr] = z;
                z[w] = match w {
                    0 => fr + rl - rr,
                    1 => fl + rr - rl,
                    2 => fl + rr - fr,
                    _ => fr + rl - fl,
                };
            }
            (Some(_), Some(_)) => return None,
        }
        // Second pass: the ground's gradient from the block means; each
        // tyre stands on the highest cell of its block once the gradient
        // is taken out (on a plane exactly the plane's height at the
        // contact, with a rock the rock's top), and its bumps are the
        // range of those detrended heights.
        let (l, t) = (self.probes.wheelbase, self.probes.track);
        let (along, across) = contact_slopes(z, l, t);
        let cell_m = grid.cell_size_m;
        let (gu, gv) = (
            (cos * along - sin * across) * cell_m,
            (sin * along + cos * across) * cell_m,
        );
        let mut bumps: f64 = 0.0;
        for (wheel, block) in blocks.iter().enumerate() {
            let Some((u, v, [du, dv])) = *block else {
                continue;
            };
            let (mut top, mut low) = (f64::NAN, f64::NAN);
            // Height at the contact point if the ground were the plane
            // through a cell: its height + gu·du + gv·dv − gu·c − gv·r.
            let mut row_offset = gu * du + gv * dv;
            for r in 0..k {
                let row = &grid.cells[(v + r) * side + u..][..k];
                let mut offset = row_offset;
                for cell in row {
                    let h = f64::from(cell[0]) + offset;
                    // NaN (unknown) never wins a max or a min.
                    top = top.max(h);
                    low = low.min(h);
                    offset -= gu;
                }
                row_offset -= gv;
            }
            z[wheel] = top;
            bumps = bumps.max(top - low);
        }
        let [fl, fr, rl, rr] = z;
        let roll_tan = (fl - fr).abs().max((rl - rr).abs()) / t;
        let pitch_tan = (fl - rl).abs().max((fr - rr).abs()) / l;
        let twist = (fl + rr - fr - rl).abs();
        // The mean plane of the four contacts, in the pose's frame.
        let mean = (fl + fr + rl + rr) / 4.0;
        let (slope_x, slope_y) = contact_slopes(z, l, t);
        let mut belly: f64 = 0.0;
        let mut belly_severity: f64 = 0.0;
        let smooth = self.config.smooth_m;
        let probes: &[[f64; 2]] = if check_belly { &self.probes.belly } else { &[] };
        for p in probes {
            let Some([height, variance]) = at(p) else {
                continue;
            };
            let ground = mean + slope_x * (p[0] - l / 2.0) + slope_y * p[1];
            let h = f64::from(height) - ground;
            if h <= smooth {
                // Ordinary ground: no cost, and nothing to compute.
                continue;
            }
            // 004 eqs. 5 and 6.
            let v_min = self.probes.clearance + f64::from(variance).sqrt();
            belly = belly.max(if h >= v_min {
                1.0
            } else {
                (h / v_min).max(0.0)
            });
            belly_severity = belly_severity.max(((h - smooth) / (v_min - smooth)).clamp(0.0, 1.0));
        }
        Some(RawStance {
            roll_tan,
            pitch_tan,
            twist,
            bumps,
            belly,
            belly_severity,
        })
    }

    /// Whether `stance` is forbidden, and its severity otherwise.
    pub fn judge(&self, stance: &Stance) -> Judgement {
        self.judge_raw(&RawStance::from(stance))
    }

    /// [`TerrainCheck::judge`] on tangents: an arctangent only within the
    /// caution band.
    fn judge_raw(&self, stance: &RawStance) -> Judgement {
        let (c, limits) = (&self.config, &self.limits);
        if stance.roll_tan > limits.roll_max
            || stance.pitch_tan > limits.pitch_max
            || stance.belly >= 1.0
        {
            return Judgement::Forbidden;
        }
        // 0 at limit − caution, 1 at the limit, in degrees.
        let near = |tan: f64, caution_tan: f64, limit: f64| {
            if tan <= caution_tan {
                return 0.0;
            }
            ((tan.atan().to_degrees() - (limit - c.caution_deg)) / c.caution_deg).clamp(0.0, 1.0)
        };
        Judgement::Passable {
            severity: near(stance.roll_tan, limits.roll_caution, c.max_roll_deg)
                .max(near(
                    stance.pitch_tan,
                    limits.pitch_caution,
                    c.max_pitch_deg,
                ))
                .max(stance.belly_severity)
                .max(((stance.twist - c.smooth_m) / (c.max_twist_m - c.smooth_m)).clamp(0.0, 1.0))
                .max(((stance.bumps - c.smooth_m) / (c.max_bump_m - c.smooth_m)).clamp(0.0, 1.0)),
        }
    }

    /// Judges every arc on `grid` from the pose `world_from_vehicle`,
    /// writing one verdict per arc; `horizon_m` bounds `near_severity`.
    pub fn judge_arcs(
        &self,
        grid: &ElevationGrid,
        world_from_vehicle: &Isometry,
        horizon_m: f64,
        out: &mut [ArcTerrain],
    ) {
        self.judge_poses(&self.poses, grid, world_from_vehicle, horizon_m, true, out);
    }

    /// [`TerrainCheck::judge_arcs`] along the paths the vehicle drives
    /// when commanded onto each arc ([`DrivenPath`]: latency and steering
    /// rate first), one verdict per path.
    pub fn judge_paths(
        &mut self,
        grid: &ElevationGrid,
        world_from_vehicle: &Isometry,
        horizon_m: f64,
        paths: &[DrivenPath],
        out: &mut [ArcTerrain],
    ) {
        self.driven.resize_with(paths.len(), Vec::new);
        for (path, poses) in paths.iter().zip(&mut self.driven) {
            path.sample_into(self.reach_m, self.config.step_m, &mut self.sampled);
            poses.clear();
            poses.extend(self.sampled.iter().map(|(s, p)| {
                let (sin, cos) = p.heading.sin_cos();
                (*s, [p.position.x, p.position.y, cos, sin])
            }));
        }
        let driven = std::mem::take(&mut self.driven);
        self.judge_poses(&driven, grid, world_from_vehicle, horizon_m, true, out);
        self.driven = driven;
    }

    /// [`TerrainCheck::judge_arcs`] backing up along every arc (none unless
    /// built [`TerrainCheck::with_reverse`]). The stance the vehicle has
    /// now forbids nothing: backing is how it gets off ground it should
    /// not stand on.
    pub fn judge_reverse_arcs(
        &self,
        grid: &ElevationGrid,
        world_from_vehicle: &Isometry,
        out: &mut [ArcTerrain],
    ) {
        self.judge_poses(
            &self.reverse_poses,
            grid,
            world_from_vehicle,
            0.0,
            false,
            out,
        );
    }

    /// Judges the poses of every arc of `arcs` (the first is the
    /// vehicle's own; it may forbid an arc only when `own_stance_forbids`).
    fn judge_poses(
        &self,
        arcs: &[Vec<(f64, [f64; 4])>],
        grid: &ElevationGrid,
        world_from_vehicle: &Isometry,
        horizon_m: f64,
        own_stance_forbids: bool,
        out: &mut [ArcTerrain],
    ) {
        out.fill(ArcTerrain::default());
        if !self.config.enabled || grid.is_empty() {
            return;
        }
        let t = world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(world_from_vehicle).sin_cos();
        let block = Block::new(self.config.tyre_patch_m, grid.cell_size_m);
        // Every arc's first pose is the vehicle's own (`Arc::sample` starts
        // at 0): judged once for all of them.
        let here = self.stance_with(grid, block, [t.x, t.y, cos, sin], true);
        for (verdict, poses) in out.iter_mut().zip(arcs) {
            for (index, &(s, [x, y, c, si])) in poses.iter().enumerate() {
                let pose = [
                    t.x + cos * x - sin * y,
                    t.y + sin * x + cos * y,
                    cos * c - sin * si,
                    sin * c + cos * si,
                ];
                // Ground under the chassis every `belly_stride` poses: each
                // point still passes under one of its rows once.
                let belly = index.is_multiple_of(self.belly_stride) || index + 1 == poses.len();
                let stance = if index == 0 {
                    here
                } else {
                    self.stance_with(grid, block, pose, belly)
                };
                let Some(stance) = stance else {
                    break;
                };
                match self.judge_raw(&stance) {
                    Judgement::Forbidden if index == 0 && !own_stance_forbids => {}
                    Judgement::Forbidden => {
                        let centre = [
                            (x + c * self.probes.wheelbase / 2.0) as f32,
                            (y + si * self.probes.wheelbase / 2.0) as f32,
                        ];
                        verdict.forbidden = Some((s, centre));
                        break;
                    }
                    Judgement::Passable { severity } => {
                        verdict.severity = verdict.severity.max(severity);
                        if s <= horizon_m {
                            verdict.near_severity = verdict.near_severity.max(severity);
                        }
                    }
                }
            }
        }
    }
}
