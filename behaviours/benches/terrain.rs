//! Attitude prediction along the arcs (018): the 39 arcs' poses every
//! 0.5 m up to 18 m judged on an elevation layer of rolling ground tilted
//! by 12° with 5 cm bumps (no arc ends early at a forbidden pose), one core: wheel
//! contacts, roll, pitch, twist and chassis clearance per pose. Prints the
//! median, the mean and the 99th percentile over 2 000 calls from varying poses.
//! Target: ≤ 0.2 ms for 39 arcs.
//! Run with `cargo bench -p arcnav-behaviours --bench terrain`.

use std::time::Instant;

use arcnav_behaviours::{ArcTerrain, TerrainCheck, TerrainConfig};
use arcnav_localmap::ElevationGrid;
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{ArcSet, ArcSetConfig, VehicleConfig};

fn main() {
    let arcs = ArcSet::new(&ArcSetConfig::default()).expect("default arcs");
    let check = TerrainCheck::new(
        &TerrainConfig::default(),
        &VehicleConfig::default(),
        arcs.curvatures(),
        18.0,
    );
    let (cell, side) = (0.2, 227u32);
    let origin = (-113i64, -113i64);
    let tilt = 12f64.to_radians().tan();
    let mut cells = Vec::new();
    for j in 0..i64::from(side) {
        for i in 0..i64::from(side) {
            let (x, y) = (
                (origin.0 + i) as f64 * cell + 0.1,
                (origin.1 + j) as f64 * cell + 0.1,
            );
            let rolling =
                0.35 * (0.21 * x).sin() * (0.17 * y).cos() + 0.05 * (1.3 * x + 0.7 * y).sin();
            cells.push([(rolling + tilt * y) as f32, 4e-4]);
        }
    }
    let grid = ElevationGrid {
        cell_size_m: cell,
        origin,
        side,
        cells,
    };
    let mut verdicts = vec![ArcTerrain::default(); arcs.len()];
    let mut times = Vec::new();
    let mut forbidden = 0;
    for n in 0..2_200 {
        let pose = planar_isometry(
            (n % 7) as f64 * 0.3,
            (n % 5) as f64 * 0.2,
            (n % 11) as f64 * 0.05,
        );
        let start = Instant::now();
        check.judge_arcs(&grid, &pose, 6.0, &mut verdicts);
        let elapsed = start.elapsed().as_secs_f64() * 1e3;
        if n >= 200 {
            times.push(elapsed);
        }
        forbidden += verdicts.iter().filter(|v| v.forbidden.is_some()).count();
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!(
        "attitude along {} arcs ({} poses each): {:.3} ms median, {:.3} ms mean, {:.3} ms p99 (target <= 0.2 ms); {} forbidden arcs seen",
        arcs.len(),
        (18.0f64 / check.config().step_m) as usize + 1,
        times[times.len() / 2],
        mean,
        times[times.len() * 99 / 100],
        forbidden
    );
}
