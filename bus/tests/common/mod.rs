//! Messages shared by the bus tests: the fixed samples (built by the same
//! formulas as `peer/lcm_peer.py`) and seeded random values of every type.

#![allow(dead_code)]

use arcnav_bus::AnyMessage;
use arcnav_bus::lcmtypes::*;

/// The sample messages of `lcm_peer.py`, in the same order, with their type names.
pub fn samples() -> Vec<(&'static str, AnyMessage)> {
    let pose = pose_t {
        utime: 1_700_000_000_123_456,
        position: [1.5, -2.25, 0.125],
        orientation: [0.5, 0.5, 0.5, 0.5],
        velocity: [2.0, 0.5, -0.1],
        yaw_rate: 0.03125,
    };
    let command = steering_command_t {
        utime: 1_700_000_000_600_000,
        curvature: -0.0625,
        speed: 2.5,
        arc_index: 7,
        vote: 0.75,
    };
    let votes = arc_votes_t {
        utime: 1_700_000_000_700_000,
        behaviour: "goal_seeking".into(),
        num_arcs: 39,
        curvature: (0..39)
            .map(|i| (-0.125 + i as f64 * 0.125 / 19.0) as f32)
            .collect(),
        votes: (0..39).map(|i| ((i as f64 - 19.0) / 19.0) as f32).collect(),
        vetoed: (0..39).map(|i| i % 5 == 0).collect(),
        has_speed_vote: true,
        speed_vote: 3.0,
        arc_speed: (0..39).map(|i| i as f32 * 0.25 - 1.0).collect(),
        reverse_clear: (0..39).map(|i| i as f32 * 0.125 - 0.5).collect(),
        forward_clear: (0..39).map(|i| 4.0 - i as f32 * 0.25).collect(),
        veto_cause: (0..39).map(|i| (i % 5 == 0 && i % 2 == 0) as i8).collect(),
        veto_x: (0..39).map(|i| i as f32 * 0.5).collect(),
        veto_y: (0..39).map(|i: i32| (-i) as f32 * 0.25).collect(),
    };
    let decision = decision_t {
        utime: 1_700_000_000_600_000,
        cause: decision_t::ALL_ARCS_VETOED,
        reason:
            "every arc is forbidden (obstacle_avoidance vetoed 39, for the cell at (4.5, -0.5) m)"
                .into(),
        num_vetoers: 2,
        vetoer: vec!["obstacle_avoidance".into(), "h\u{f6}henangst".into()],
        vetoed_arcs: vec![39, 3],
        has_cell: vec![true, false],
        cell_x: vec![4.5, 0.0],
        cell_y: vec![-0.5, 0.0],
    };
    let cells = obstacle_cells_t {
        utime: 1_700_000_000_800_000,
        sensor: "erim-\u{3c0}".into(),
        cell_size: 0.2,
        num_cells: 3,
        cells: (0..3)
            .map(|i| obstacle_cell_t {
                x: 100.0 + i as f64 * 0.2,
                y: -50.5 + i as f64,
                z_min: (i as f64 * 0.1) as f32,
                z_max: (1.0 + i as f64) as f32,
                reasons: [1, 2, 4][i],
                region: (i / 2) as i32,
                cost: 1.0,
            })
            .collect(),
        num_fov: 4,
        fov: vec![[0.0, 0.0], [10.0, -5.0], [20.0, 0.0], [10.0, 5.0]],
        shadow_origin: [-1.5, 2.25],
        num_shadows: 2,
        shadows: vec![[0.25, 0.0625, 6.5, 9.0], [-3.0, 0.001953125, 12.0, 12.5]],
        heights_cell: 0.2,
        num_heights: 2,
        height_cells: vec![[500, -253], [-1, 7]],
        heights: vec![[1.25, 0.0004], [-0.5, 0.015625]],
        acquired_utime: 1_700_000_000_820_000,
    };
    let waypoints = waypoints_t {
        utime: 1_700_000_000_900_000,
        num_waypoints: 3,
        position: vec![[0.0, 0.0], [100.0, 50.0], [200.0, -25.0]],
        radius: vec![5.0, 0.0, 7.5],
    };
    let map = local_map_t {
        utime: 1_700_000_001_000_000,
        position: [10.0, 20.0, 1.0],
        orientation: [1.0, 0.0, 0.0, 0.0],
        patch_size: 0.4,
        num_patches: 2,
        patches: (0..2)
            .map(|i| local_map_patch_t {
                x: 5.0 + i as f32,
                y: -(i as f32),
                world_x: 15.0 + i as f64,
                world_y: 20.0 - i as f64,
                first_seen: 1_700_000_000_000_000 + i,
                last_seen: 1_700_000_000_500_000 + i,
                confirmations: 3 + i as i32,
                reasons: 4,
                z_min: 0.5 - i as f32,
                z_max: 1.25 + i as f32,
                misses: i as i32,
                sensors: 1,
                cost: 1.0,
            })
            .collect(),
        cycle_utime: 1_700_000_001_020_000,
        velocity: [2.5, -0.5, 0.0],
        yaw_rate: 0.125,
        resets: 2,
        seen_origin: [-70, 25],
        seen_side: 9,
        num_seen_words: 2,
        seen: vec![0x0123_4567_89ab_cdef, -5],
        elevation_cell: 0.2,
        elevation_origin: [-120, 40],
        elevation_side: 2,
        num_elevation: 4,
        elevation: vec![
            [1.5, 0.0025],
            [f32::NAN, f32::NAN],
            [-0.25, 0.5],
            [2.0, 0.125],
        ],
    };
    vec![
        ("pose_t", AnyMessage::Pose(pose)),
        (
            "range_image_t",
            AnyMessage::RangeImage(range_image(64, 256, "erim")),
        ),
        ("steering_command_t", AnyMessage::SteeringCommand(command)),
        ("arc_votes_t", AnyMessage::ArcVotes(votes)),
        ("obstacle_cells_t", AnyMessage::ObstacleCells(cells)),
        ("waypoints_t", AnyMessage::Waypoints(waypoints)),
        ("local_map_t", AnyMessage::LocalMap(map)),
        ("range_slice_t", AnyMessage::RangeSlice(range_slice())),
        ("decision_t", AnyMessage::Decision(decision)),
    ]
}

/// `range_slice(...)` of `lcm_peer.py`: columns 32..48 of a 4-row image.
pub fn range_slice() -> range_slice_t {
    let (rows, cols) = (4usize, 16usize);
    let mut range: Vec<f32> = (0..rows * cols).map(|i| i as f32 * 0.25).collect();
    range[3] = f32::NAN;
    range_slice_t {
        utime: 1_700_000_000_530_000,
        frame_utime: 1_700_000_000_500_000,
        sensor: "lidar64".into(),
        mount_position: [0.5, 0.0, 2.0],
        mount_orientation: [1.0, 0.0, 0.0, 0.0],
        frame_rows: rows as i32,
        frame_cols: 2048,
        axis: 0,
        first: 32,
        rows: rows as i32,
        cols: cols as i32,
        elevation: (0..rows)
            .map(|r| (0.25 - r as f64 * 0.125) as f32)
            .collect(),
        azimuth: (0..cols)
            .map(|c| (3.0 - c as f64 * 0.0625) as f32)
            .collect(),
        num_lines: cols as i32,
        line_utime: (0..cols as i64)
            .map(|c| 1_700_000_000_515_000 + c * 1_000)
            .collect(),
        range,
    }
}

/// `range_image(...)` of `lcm_peer.py`.
pub fn range_image(rows: usize, cols: usize, sensor: &str) -> range_image_t {
    let mut range: Vec<f32> = (0..rows * cols)
        .map(|i| ((i % 997) as f64 * 0.05) as f32)
        .collect();
    range[7] = f32::NAN;
    range_image_t {
        utime: 1_700_000_000_500_000,
        sensor: sensor.into(),
        mount_position: [1.2, 0.0, 2.1],
        mount_orientation: [1.0, 0.0, 0.0, 0.0],
        rows: rows as i32,
        cols: cols as i32,
        elevation: (0..rows)
            .map(|r| (-0.4 + r as f64 * 0.005) as f32)
            .collect(),
        azimuth: (0..cols)
            .map(|c| (-3.0 + c as f64 * 0.003) as f32)
            .collect(),
        range,
    }
}

/// A small deterministic generator (SplitMix64).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// Any f64 but NaN (NaN payloads need not survive other languages).
    pub fn f64(&mut self) -> f64 {
        match self.below(6) {
            0 => 0.0,
            1 => -0.0,
            2 => [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::MIN_POSITIVE,
                f64::MAX,
            ][self.below(4)],
            _ => {
                let v = f64::from_bits(self.next_u64());
                if v.is_nan() { 1.0 / 3.0 } else { v }
            }
        }
    }

    /// Any f32 but a non-canonical NaN.
    pub fn f32(&mut self) -> f32 {
        match self.below(6) {
            0 => f32::NAN,
            1 => -0.0,
            2 => [f32::INFINITY, f32::MIN_POSITIVE, f32::MAX, 1e-40][self.below(4)],
            _ => {
                let v = f32::from_bits(self.next_u64() as u32);
                if v.is_nan() { 0.1 } else { v }
            }
        }
    }

    pub fn string(&mut self) -> String {
        let alphabet = [
            'a',
            'Z',
            '_',
            '0',
            ' ',
            '\u{e9}',
            '\u{3c0}',
            '\u{1f697}',
            '\n',
        ];
        (0..self.below(20))
            .map(|_| alphabet[self.below(alphabet.len())])
            .collect()
    }

    pub fn len(&mut self) -> usize {
        if self.below(4) == 0 {
            0
        } else {
            self.below(40)
        }
    }
}

/// A random message of type `kind` (0..9, the order of [`samples`]).
pub fn random_message(rng: &mut Rng, kind: usize) -> (&'static str, AnyMessage) {
    let utime = rng.next_u64() as i64;
    match kind % 9 {
        0 => (
            "pose_t",
            AnyMessage::Pose(pose_t {
                utime,
                position: [rng.f64(), rng.f64(), rng.f64()],
                orientation: [rng.f64(), rng.f64(), rng.f64(), rng.f64()],
                velocity: [rng.f64(), rng.f64(), rng.f64()],
                yaw_rate: rng.f64(),
            }),
        ),
        1 => {
            let (rows, cols) = (rng.len(), rng.len());
            (
                "range_image_t",
                AnyMessage::RangeImage(range_image_t {
                    utime,
                    sensor: rng.string(),
                    mount_position: [rng.f64(), rng.f64(), rng.f64()],
                    mount_orientation: [rng.f64(), rng.f64(), rng.f64(), rng.f64()],
                    rows: rows as i32,
                    cols: cols as i32,
                    elevation: (0..rows).map(|_| rng.f32()).collect(),
                    azimuth: (0..cols).map(|_| rng.f32()).collect(),
                    range: (0..rows * cols).map(|_| rng.f32()).collect(),
                }),
            )
        }
        2 => (
            "steering_command_t",
            AnyMessage::SteeringCommand(steering_command_t {
                utime,
                curvature: rng.f64(),
                speed: rng.f64(),
                arc_index: rng.next_u64() as i32,
                vote: rng.f32(),
            }),
        ),
        3 => {
            let n = rng.len();
            (
                "arc_votes_t",
                AnyMessage::ArcVotes(arc_votes_t {
                    utime,
                    behaviour: rng.string(),
                    num_arcs: n as i32,
                    curvature: (0..n).map(|_| rng.f32()).collect(),
                    votes: (0..n).map(|_| rng.f32()).collect(),
                    vetoed: (0..n).map(|_| rng.below(2) == 1).collect(),
                    has_speed_vote: rng.below(2) == 1,
                    speed_vote: rng.f64(),
                    arc_speed: (0..n).map(|_| rng.f32()).collect(),
                    reverse_clear: (0..n).map(|_| rng.f32()).collect(),
                    forward_clear: (0..n).map(|_| rng.f32()).collect(),
                    veto_cause: (0..n).map(|_| rng.next_u64() as i8).collect(),
                    veto_x: (0..n).map(|_| rng.f32()).collect(),
                    veto_y: (0..n).map(|_| rng.f32()).collect(),
                }),
            )
        }
        4 => {
            let (n, f, s, h) = (rng.len(), rng.len(), rng.len(), rng.len());
            (
                "obstacle_cells_t",
                AnyMessage::ObstacleCells(obstacle_cells_t {
                    utime,
                    sensor: rng.string(),
                    cell_size: rng.f32(),
                    num_cells: n as i32,
                    cells: (0..n)
                        .map(|_| obstacle_cell_t {
                            x: rng.f64(),
                            y: rng.f64(),
                            z_min: rng.f32(),
                            z_max: rng.f32(),
                            reasons: rng.next_u64() as i8,
                            region: rng.next_u64() as i32,
                            cost: 1.0,
                        })
                        .collect(),
                    num_fov: f as i32,
                    fov: (0..f).map(|_| [rng.f64(), rng.f64()]).collect(),
                    shadow_origin: [rng.f64(), rng.f64()],
                    num_shadows: s as i32,
                    shadows: (0..s).map(|_| std::array::from_fn(|_| rng.f32())).collect(),
                    heights_cell: rng.f32(),
                    num_heights: h as i32,
                    height_cells: (0..h)
                        .map(|_| [rng.next_u64() as i32, rng.next_u64() as i32])
                        .collect(),
                    heights: (0..h).map(|_| [rng.f32(), rng.f32()]).collect(),
                    acquired_utime: rng.next_u64() as i64,
                }),
            )
        }
        5 => {
            let n = rng.len();
            (
                "waypoints_t",
                AnyMessage::Waypoints(waypoints_t {
                    utime,
                    num_waypoints: n as i32,
                    position: (0..n).map(|_| [rng.f64(), rng.f64()]).collect(),
                    radius: (0..n).map(|_| rng.f32()).collect(),
                }),
            )
        }
        8 => {
            let n = rng.len();
            (
                "decision_t",
                AnyMessage::Decision(decision_t {
                    utime,
                    cause: rng.next_u64() as i8,
                    reason: rng.string(),
                    num_vetoers: n as i32,
                    vetoer: (0..n).map(|_| rng.string()).collect(),
                    vetoed_arcs: (0..n).map(|_| rng.next_u64() as i32).collect(),
                    has_cell: (0..n).map(|_| rng.below(2) == 1).collect(),
                    cell_x: (0..n).map(|_| rng.f32()).collect(),
                    cell_y: (0..n).map(|_| rng.f32()).collect(),
                }),
            )
        }
        7 => {
            let (rows, cols, lines) = (rng.len(), rng.len(), rng.len());
            (
                "range_slice_t",
                AnyMessage::RangeSlice(range_slice_t {
                    utime,
                    frame_utime: rng.next_u64() as i64,
                    sensor: rng.string(),
                    mount_position: [rng.f64(), rng.f64(), rng.f64()],
                    mount_orientation: [rng.f64(), rng.f64(), rng.f64(), rng.f64()],
                    frame_rows: rng.next_u64() as i32,
                    frame_cols: rng.next_u64() as i32,
                    axis: rng.next_u64() as i8,
                    first: rng.next_u64() as i32,
                    rows: rows as i32,
                    cols: cols as i32,
                    elevation: (0..rows).map(|_| rng.f32()).collect(),
                    azimuth: (0..cols).map(|_| rng.f32()).collect(),
                    num_lines: lines as i32,
                    line_utime: (0..lines).map(|_| rng.next_u64() as i64).collect(),
                    range: (0..rows * cols).map(|_| rng.f32()).collect(),
                }),
            )
        }
        _ => {
            let n = rng.len();
            (
                "local_map_t",
                AnyMessage::LocalMap(local_map_t {
                    utime,
                    position: [rng.f64(), rng.f64(), rng.f64()],
                    orientation: [rng.f64(), rng.f64(), rng.f64(), rng.f64()],
                    patch_size: rng.f32(),
                    num_patches: n as i32,
                    patches: (0..n)
                        .map(|_| local_map_patch_t {
                            x: rng.f32(),
                            y: rng.f32(),
                            world_x: rng.f64(),
                            world_y: rng.f64(),
                            first_seen: rng.next_u64() as i64,
                            last_seen: rng.next_u64() as i64,
                            confirmations: rng.next_u64() as i32,
                            reasons: rng.next_u64() as i8,
                            z_min: rng.f32(),
                            z_max: rng.f32(),
                            misses: rng.next_u64() as i32,
                            sensors: rng.next_u64() as i32,
                            cost: 1.0,
                        })
                        .collect(),
                    cycle_utime: rng.next_u64() as i64,
                    velocity: [rng.f64(), rng.f64(), rng.f64()],
                    yaw_rate: rng.f64(),
                    resets: rng.next_u64() as i32,
                    seen_origin: [rng.next_u64() as i64, rng.next_u64() as i64],
                    seen_side: rng.next_u64() as i32,
                    num_seen_words: n as i32,
                    seen: (0..n).map(|_| rng.next_u64() as i64).collect(),
                    elevation_cell: rng.f32(),
                    elevation_origin: [rng.next_u64() as i64, rng.next_u64() as i64],
                    elevation_side: rng.next_u64() as i32,
                    num_elevation: n as i32,
                    elevation: (0..n).map(|_| [rng.f32(), rng.f32()]).collect(),
                }),
            )
        }
    }
}
