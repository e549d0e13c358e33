//! The elevation layer (004 §III) fed by perception's height measurements:
//! convergence under noise, objects, and scrolling with the vehicle.

use arcnav_localmap::{LocalMap, LocalMapConfig};
use arcnav_perception::scene::HeightFunction;
use arcnav_perception::{
    HeightSampler, ObstacleReport, PerceptionConfig, RangeImage, Reasons, SensorModel,
};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{Pose, Utime, VehicleConfig};

const SECOND: Utime = 1_000_000;

/// A deterministic normal generator (Box–Muller over a 64-bit LCG).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }
}

struct Rig {
    map: LocalMap,
    sampler: HeightSampler,
    sensor: SensorModel,
    noise: Noise,
    sigma_m: f64,
}

impl Rig {
    fn new(sigma_m: f64) -> Self {
        Self::with_sensor(sigma_m, SensorModel::erim())
    }

    fn with_sensor(sigma_m: f64, sensor: SensorModel) -> Self {
        let perception = PerceptionConfig::default();
        Self {
            map: LocalMap::new(&LocalMapConfig::default(), &VehicleConfig::default()),
            sampler: HeightSampler::new(
                &perception.heights,
                &perception.region,
                perception.min_range_m,
                perception.max_range_m,
            ),
            sensor,
            noise: Noise(7),
            sigma_m,
        }
    }

    /// One image of `height` from (x, 0) heading +x, with range noise.
    fn image(&mut self, n: i64, x: f64, height: impl Fn(f64, f64) -> f64 + Sync) {
        let utime = n * SECOND / 2;
        let pose = Pose::at_rest(utime, planar_isometry(x, 0.0, 0.0));
        self.map.update(&pose);
        let mut image: RangeImage = self.sensor.render(
            utime,
            &pose.world_from_vehicle,
            &HeightFunction::new(height),
        );
        for r in image
            .range
            .iter_mut()
            .filter(|r| r.is_finite() && **r > 0.0)
        {
            *r += (self.sigma_m * self.noise.normal()) as f32;
        }
        let mut report = ObstacleReport {
            utime,
            sensor: self.sensor.id.clone(),
            ..ObstacleReport::default()
        };
        self.sampler
            .sample(&image, &pose.world_from_vehicle, &mut report);
        self.map.insert(&report).unwrap();
    }

    fn at(&self, x: f64, y: f64) -> Option<[f32; 2]> {
        self.map.snapshot().elevation.at(x, y)
    }

    /// The centre of a known cell within a metre of (x, y) (one image of
    /// the ERIM leaves far ground between its rows unmeasured).
    fn known_near(&self, x: f64, y: f64) -> (f64, f64) {
        let s = 0.2;
        let (i, j) = ((x / s).floor(), (y / s).floor());
        (0..121)
            .map(|k| {
                let (di, dj) = ((k % 11) as f64 - 5.0, (k / 11) as f64 - 5.0);
                ((i + di + 0.5) * s, (j + dj + 0.5) * s)
            })
            .find(|&(cx, cy)| self.at(cx, cy).is_some())
            .unwrap_or_else(|| panic!("nothing measured within a metre of ({x}, {y})"))
    }
}

#[test]
fn a_noisy_plane_converges_to_its_height_with_a_falling_variance() {
    let mut rig = Rig::new(0.03);
    let plane = |_: f64, _: f64| 0.3;
    rig.image(1, 0.0, plane);
    let probes =
        [(10.1, 0.1), (12.1, -2.1), (15.1, 3.1), (8.1, 1.1)].map(|(x, y)| rig.known_near(x, y));
    let first: Vec<[f32; 2]> = probes.iter().map(|&(x, y)| rig.at(x, y).unwrap()).collect();
    let mut previous = first.clone();
    for n in 2..=20 {
        rig.image(n, 0.0, plane);
        if n <= 4 {
            // Each of the first images narrows every cell it measures.
            for (&(x, y), before) in probes.iter().zip(&mut previous) {
                let now = rig.at(x, y).unwrap();
                assert!(now[1] <= before[1], "({x}, {y}): {now:?} after {before:?}");
                *before = now;
            }
        }
    }
    for (&(x, y), first) in probes.iter().zip(&first) {
        let [mean, variance] = rig.at(x, y).unwrap();
        assert!(
            (mean - 0.3).abs() < 0.02,
            "({x}, {y}): {mean} m after 20 images, the plane is at 0.3 m"
        );
        assert!(
            // The process noise q keeps it near sqrt(q²·σ_t²), about
            // 0.4 σ_t² here: the cell keeps listening.
            variance < first[1] * 0.6,
            "({x}, {y}): variance {variance} after 20 images, {} after one",
            first[1]
        );
    }
    let stats = rig.map.elevation().stats();
    assert!(stats.fused > 10_000, "{stats:?}");
}

#[test]
fn a_half_metre_box_stands_out_of_the_ground() {
    let mut rig = Rig::new(0.02);
    let boxed = |x: f64, y: f64| {
        if (10.0..11.0).contains(&x) && (-0.5..0.5).contains(&y) {
            0.5
        } else {
            0.0
        }
    };
    for n in 1..=4 {
        rig.image(n, 0.0, boxed);
    }
    let top = rig.at(10.5, 0.1).unwrap()[0];
    assert!((top - 0.5).abs() < 0.03, "box top at {top} m");
    let before = rig.at(9.0, 0.1).unwrap()[0];
    assert!(before.abs() < 0.03, "ground before the box at {before} m");
    // Behind the box the sensor does not see the ground: unknown, not 0.
    assert!(rig.at(11.5, 0.1).is_none(), "ground in the box's shadow");
}

#[test]
fn the_layer_scrolls_with_the_vehicle_and_keeps_what_stays_in_the_window() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    let mut rig = Rig::new(0.02);
    let ground = |x: f64, _: f64| 0.3 * (x / 7.0).sin();
    rig.image(1, 0.0, ground);
    let (x, y) = rig.known_near(15.1, 0.1);
    let seen_early = rig.at(x, y).unwrap()[0];
    assert!(
        (f64::from(seen_early) - ground(x, y)).abs() < 0.03,
        "{seen_early}"
    );
    // Drive 10 m without images: the cell is now 5 m ahead and still known.
    for step in 1..=10 {
        rig.map.update(&Pose::at_rest(
            SECOND / 2 + step * SECOND / 10,
            planar_isometry(f64::from(step as i32), 0.0, 0.0),
        ));
    }
    assert_eq!(rig.at(x, y).unwrap()[0], seen_early);
    // Drive on 100 m at 3 m/s with images: ground 30 m behind is forgotten, the
    // ground ahead is known, and the layer's square is centred on the
    // vehicle.
    for n in 4..=70 {
        rig.image(n, 10.0 + (n - 3) as f64 * 1.5, ground);
    }
    let snapshot = rig.map.snapshot();
    let grid = &snapshot.elevation;
    assert_eq!(rig.map.stats().resets, 0);
    assert!(grid.at(x, y).is_none(), "ground 95 m behind is kept");
    let (x, y) = rig.known_near(125.6, 0.1);
    let here = rig.at(x, y).unwrap()[0];
    assert!(
        (f64::from(here) - ground(x, y)).abs() < 0.03,
        "{here} at {x}"
    );
    let centre = (
        grid.origin.0 + i64::from(grid.side / 2),
        grid.origin.1 + i64::from(grid.side / 2),
    );
    assert_eq!(centre, (552, 0), "square centred on the vehicle at 110.5 m");
}

/// A bank's 35° side, as `cul_de_sac`'s banks have: rising from 3 m to the
/// left of the vehicle's line to a 1.5 m top at 5.1 m.
fn bank(_: f64, y: f64) -> f64 {
    ((y - 3.0) * 35f64.to_radians().tan()).clamp(0.0, 1.5)
}

/// The steep patches of `rig`'s snapshot: vehicle-frame centres.
fn steep(rig: &Rig) -> Vec<(f32, f32)> {
    rig.map
        .snapshot()
        .patches
        .iter()
        .filter(|p| p.reasons.contains(Reasons::STEEP))
        .inspect(|p| assert!(p.is_obstacle(), "{p:?}"))
        .map(|p| (p.x, p.y))
        .collect()
}

#[test]
fn a_bank_side_steeper_than_the_vehicle_drives_is_an_obstacle_along_its_whole_run() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    // Perception's cells mark a 35° side only in places (within a 20 cm
    // cell it rises 14 cm, below every threshold); the fused layer sees it
    // all.
    let mut rig = Rig::with_sensor(0.02, SensorModel::lidar64());
    for n in 1..=4 {
        rig.image(n, 0.0, bank);
    }
    let found = steep(&rig);
    // On the side (3-5.1 m), give or take a patch and the central
    // differences' reach.
    assert!(
        found.iter().all(|&(_, y)| (2.4..=5.7).contains(&y)),
        "{found:?}"
    );
    // Along its run ahead of the vehicle, every metre from 5 to 15 m.
    for x in 5..=15 {
        let x = x as f32;
        assert!(
            found.iter().any(|&(px, _)| (px - x).abs() <= 0.6),
            "no steep patch near x = {x} m: {found:?}"
        );
    }
    // A 20° hillside, as driven on `hillside`: nothing, though noise
    // lifts single cells past the limit.
    let mut rig = Rig::with_sensor(0.02, SensorModel::lidar64());
    let hillside = |_: f64, y: f64| y * 20f64.to_radians().tan();
    for n in 1..=4 {
        rig.image(n, 0.0, hillside);
    }
    assert_eq!(steep(&rig), vec![], "a 20° hillside is no obstacle");
    // Off (steep_deg = 90), the bank is only what perception found.
    let mut config = LocalMapConfig::default();
    config.elevation.steep_deg = 90.0;
    config.validate().unwrap();
    let mut rig = Rig::with_sensor(0.02, SensorModel::lidar64());
    rig.map = LocalMap::new(&config, &VehicleConfig::default());
    for n in 1..=4 {
        rig.image(n, 0.0, bank);
    }
    assert!(steep(&rig).is_empty());
}

#[test]
fn steep_ground_under_the_vehicle_is_not_an_obstacle() {
    // The vehicle stands across the foot of the side (its left flank at
    // 1.1 m): the steep patches start beyond its body.
    let mut rig = Rig::with_sensor(0.02, SensorModel::lidar64());
    let near = |x: f64, y: f64| bank(x, y + 2.0);
    for n in 1..=4 {
        rig.image(n, 0.0, near);
    }
    let found = steep(&rig);
    assert!(!found.is_empty());
    let body = VehicleConfig::default().footprint().widened(0.2);
    assert!(
        found
            .iter()
            .all(|&(x, y)| !body.contains(nalgebra::Point2::new(f64::from(x), f64::from(y)))),
        "{found:?}"
    );
}
