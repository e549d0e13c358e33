//! Procedural worlds from a seed: a loop of waypoints over hills, with
//! rocks, trees, bushes and holes scattered along it, oblique ditches across
//! some legs (one end near the route, so they can be driven around) and
//! steep banks beside others. The result is a [`WorldSpec`], so it can be
//! saved as TOML and edited.

use serde::{Deserialize, Serialize};

use crate::rng::Rng;
use crate::world::{
    BankSpec, DitchSpec, ScatterKind, ScatterSpec, StartSpec, TerrainSpec, WaypointSpec, WorldSpec,
};

/// How much there is to avoid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Difficulty {
    Easy,
    Moderate,
    Hard,
}

impl std::str::FromStr for Difficulty {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "easy" => Ok(Self::Easy),
            "moderate" => Ok(Self::Moderate),
            "hard" => Ok(Self::Hard),
            other => Err(format!(
                "unknown difficulty {other:?} (known: easy, moderate, hard)"
            )),
        }
    }
}

struct Recipe {
    hills: f64,
    boulders: u32,
    trees: u32,
    bushes: u32,
    holes: u32,
    ditches: usize,
    banks: usize,
    spacing: f64,
}

impl Recipe {
    /// How much of each a world of `difficulty` holds.
    fn of(difficulty: Difficulty) -> Self {
        match difficulty {
            Difficulty::Easy => Recipe {
                hills: 1.5,
                boulders: 30,
                trees: 15,
                bushes: 10,
                holes: 5,
                ditches: 1,
                banks: 0,
                spacing: 12.0,
            },
            Difficulty::Moderate => Recipe {
                hills: 2.5,
                boulders: 70,
                trees: 35,
                bushes: 25,
                holes: 12,
                ditches: 3,
                banks: 1,
                spacing: 10.0,
            },
            Difficulty::Hard => Recipe {
                hills: 3.5,
                boulders: 130,
                trees: 60,
                bushes: 45,
                holes: 20,
                ditches: 5,
                banks: 2,
                spacing: 8.0,
            },
        }
    }
}

/// One hard generated world in [`BARRIER_ONE_IN`] has a barrier (issue 62): a
/// 2 m deep, 3 m wide trench running out from inside the loop of
/// waypoints, across one leg, to beyond the map's edge, with one 6 m
/// crossing 25 m outside the loop. The way across is round its inner end
/// or through the crossing, neither in sight from where the leg meets it;
/// outwards the trench runs on to the operating area's edge. Drawn from a
/// stream of its own, so the rest of the world is as without it.
pub const BARRIER_ONE_IN: u64 = 4;

/// The barrier of the world of `seed` (none for most seeds; see
/// [`BARRIER_ONE_IN`]): the trench's two pieces either side of its
/// crossing. The loop has `n` legs starting at angle `phase`, `radius` m
/// round.
fn barrier(seed: u64, n: usize, phase: f64, radius: f64) -> Vec<DitchSpec> {
    let mut rng = Rng::new(seed ^ 0x6261_7272_6965_7273);
    if !rng.next_u64().is_multiple_of(BARRIER_ONE_IN) {
        return Vec::new();
    }
    // Across a leg other than the first (the start is at its beginning).
    let leg = (1 + rng.next_u64() % (n as u64 - 1)) as f64;
    let angle = phase + std::f64::consts::TAU * (leg + 0.5) / n as f64;
    let (c, s) = (angle.cos(), angle.sin());
    let at = |r: f64| [(r * c * 10.0).round() / 10.0, (r * s * 10.0).round() / 10.0];
    let (width, gap) = (3.0, 6.0);
    let crossing = radius + 25.0;
    let piece = |from: f64, to: f64| DitchSpec {
        from_m: at(from),
        to_m: at(to),
        width_m: width,
        depth_m: 2.0,
    };
    vec![
        piece(0.45 * radius, crossing - gap / 2.0 - width / 2.0),
        piece(crossing + gap / 2.0 + width / 2.0, 4.0 * radius + 200.0),
    ]
}

/// A world generated from `seed`.
pub fn generate(seed: u64, difficulty: Difficulty) -> WorldSpec {
    let recipe = Recipe::of(difficulty);
    let mut rng = Rng::new(seed);
    // A loop of 8 waypoints on a perturbed circle, ~450 m around.
    let n = 8;
    let radius = rng.range(62.0, 78.0);
    let phase = rng.range(0.0, std::f64::consts::TAU);
    let points: Vec<[f64; 2]> = (0..=n)
        .map(|k| {
            let a = phase + std::f64::consts::TAU * k as f64 / n as f64;
            let r = if k == 0 || k == n {
                radius
            } else {
                radius * rng.range(0.85, 1.15)
            };
            [
                (r * a.cos() * 10.0).round() / 10.0,
                (r * a.sin() * 10.0).round() / 10.0,
            ]
        })
        .collect();
    let start = points[0];
    let first = points[1];
    let heading = (first[1] - start[1])
        .atan2(first[0] - start[0])
        .to_degrees();
    let leg = |i: usize, along: f64, across: f64| -> ([f64; 2], [f64; 2], [f64; 2]) {
        let (a, b) = (points[i], points[i + 1]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        let (u, v) = ([dx / len, dy / len], [-dy / len, dx / len]);
        (
            [
                a[0] + dx * along + v[0] * across,
                a[1] + dy * along + v[1] * across,
            ],
            u,
            v,
        )
    };
    let round = |p: [f64; 2]| [(p[0] * 10.0).round() / 10.0, (p[1] * 10.0).round() / 10.0];
    let mut legs: Vec<usize> = (0..n).collect();
    for i in (1..legs.len()).rev() {
        legs.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let ditches = legs[..recipe.ditches]
        .iter()
        .map(|&i| {
            let side = if rng.unit() < 0.5 { 1.0 } else { -1.0 };
            let (centre, u, v) = leg(i, rng.range(0.35, 0.65), -side * rng.range(3.0, 5.0));
            let axis = [
                (u[0] + v[0] * side) / 2f64.sqrt(),
                (u[1] + v[1] * side) / 2f64.sqrt(),
            ];
            let half = rng.range(4.0, 6.5);
            DitchSpec {
                from_m: round([centre[0] - axis[0] * half, centre[1] - axis[1] * half]),
                to_m: round([centre[0] + axis[0] * half, centre[1] + axis[1] * half]),
                width_m: (rng.range(1.0, 1.5) * 10.0).round() / 10.0,
                depth_m: (rng.range(0.6, 1.0) * 10.0).round() / 10.0,
            }
        })
        .collect();
    let mut ditches: Vec<DitchSpec> = ditches;
    let barrier = if difficulty == Difficulty::Hard {
        barrier(seed, n, phase, radius)
    } else {
        Vec::new()
    };
    ditches.extend(barrier.iter().cloned());
    let banks = legs[recipe.ditches..recipe.ditches + recipe.banks]
        .iter()
        .map(|&i| {
            let side = if rng.unit() < 0.5 { 1.0 } else { -1.0 };
            let (centre, u, _) = leg(i, 0.5, side * rng.range(8.0, 10.0));
            let half = rng.range(8.0, 12.0);
            BankSpec {
                from_m: round([centre[0] - u[0] * half, centre[1] - u[1] * half]),
                to_m: round([centre[0] + u[0] * half, centre[1] + u[1] * half]),
                height_m: 1.5,
                top_width_m: 2.0,
                slope_deg: 35.0,
            }
        })
        .collect();
    let scatter =
        |kind: ScatterKind, count: u32, salt: u64, radius_m: [f64; 2], height_m: [f64; 2]| {
            ScatterSpec {
                kind,
                count,
                seed: seed.wrapping_mul(31).wrapping_add(salt),
                min_spacing_m: recipe.spacing,
                radius_m,
                height_m,
                near_route_m: 30.0,
                clear_of_waypoints_m: 10.0,
            }
        };
    let extent = radius * 1.15 + 60.0;
    WorldSpec {
        name: format!("generated-{seed}-{difficulty:?}").to_lowercase(),
        description: format!(
            "procedural world, seed {seed}, {difficulty:?} difficulty{}",
            if barrier.is_empty() {
                ""
            } else {
                ", a trench across the loop"
            }
        )
        .to_lowercase(),
        terrain: TerrainSpec {
            origin_m: [-extent.round(), -extent.round()],
            size_m: [2.0 * extent.round(), 2.0 * extent.round()],
            seed: seed.wrapping_add(1000),
            hills_amplitude_m: recipe.hills,
            hills_wavelength_m: 140.0,
            roughness_amplitude_m: 0.02,
            roughness_wavelength_m: 2.0,
            ..TerrainSpec::default()
        },
        start: StartSpec {
            position_m: start,
            heading_deg: (heading * 10.0).round() / 10.0,
        },
        waypoints: points[1..]
            .iter()
            .map(|&p| WaypointSpec {
                position_m: p,
                radius_m: None,
            })
            .collect(),
        boulders: vec![],
        trees: vec![],
        bushes: vec![],
        holes: vec![],
        ditches,
        banks,
        rubble: vec![],
        area: None,
        scatter: vec![
            scatter(
                ScatterKind::Boulder,
                recipe.boulders,
                1,
                [0.4, 1.0],
                [0.35, 1.0],
            ),
            scatter(ScatterKind::Tree, recipe.trees, 2, [0.15, 0.3], [4.0, 8.0]),
            scatter(ScatterKind::Bush, recipe.bushes, 3, [0.6, 1.2], [0.8, 1.5]),
            scatter(ScatterKind::Hole, recipe.holes, 4, [0.5, 0.9], [0.5, 0.9]),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::World;
    use arcnav_vehicle::VehicleConfig;

    #[test]
    fn generated_worlds_are_reproducible_valid_and_round_trip_through_toml() {
        for seed in 0..5 {
            let spec = generate(seed, Difficulty::Moderate);
            assert_eq!(spec, generate(seed, Difficulty::Moderate));
            let world = World::build(spec.clone(), "generated", None).unwrap();
            world
                .validate_for(&VehicleConfig::default(), "generated")
                .unwrap();
            assert_eq!(world.waypoints.len(), 8);
            assert!(
                world.features.len() > 40,
                "{} features",
                world.features.len()
            );
            let text = toml::to_string(&spec).unwrap();
            let back: WorldSpec = toml::from_str(&text).unwrap();
            assert_eq!(back, spec);
        }
        assert_ne!(generate(1, Difficulty::Hard), generate(2, Difficulty::Hard));
        assert!(
            "medium"
                .parse::<Difficulty>()
                .unwrap_err()
                .contains("easy, moderate, hard")
        );
    }

    /// Issue 62: some hard generated worlds hold a barrier the sweeps meet
    /// — about one in four, each a trench across one leg of the loop, well
    /// clear of every waypoint, the rest of the world as without it; no
    /// easier world has one.
    #[test]
    fn one_generated_world_in_four_has_a_trench_across_its_loop() {
        let with: Vec<u64> = (0..40)
            .filter(|&seed| !barrier(seed, 8, 0.0, 70.0).is_empty())
            .collect();
        assert!((5..=16).contains(&with.len()), "{with:?}");
        for &seed in &with {
            let spec = generate(seed, Difficulty::Hard);
            assert!(spec.description.contains("trench across the loop"));
            let moderate = generate(seed, Difficulty::Moderate);
            assert!(!moderate.description.contains("trench"), "seed {seed}");
            let world = World::build(spec.clone(), "generated", None).unwrap();
            world
                .validate_for(&VehicleConfig::default(), "generated")
                .unwrap();
            let trench = &spec.ditches[spec.ditches.len() - 2..];
            for w in &spec.waypoints {
                for d in trench {
                    let gap = crate::world::segment_distance(w.position_m, d.from_m, d.to_m);
                    assert!(
                        gap > 15.0,
                        "seed {seed}: waypoint {gap:.1} m from the trench"
                    );
                }
            }
        }
    }
}
