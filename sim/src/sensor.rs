//! The simulated range sensor: perception's sensor model rendering the
//! world's height field, plus range noise and dropouts. Bands of rows are
//! rendered in parallel; noise comes from a generator seeded per image and
//! per row, so an image is the same whatever the thread count.

use std::sync::Mutex;

use arcnav_perception::{RangeImage, SensorModel};
use arcnav_vehicle::{Isometry, Utime};

use crate::rng::Rng;
use crate::tiles::TileView;

/// Renders one image of `view` from `world_from_vehicle`.
pub fn render(
    sensor: &SensorModel,
    view: &TileView,
    world_from_vehicle: &Isometry,
    utime: Utime,
    noise: (f64, f64),
    seed: (u64, u64),
    threads: usize,
) -> RangeImage {
    let mut image = sensor.blank_image(utime);
    let (rows, cols) = (sensor.beams.rows(), sensor.beams.cols());
    // Rows differ in cost (a lidar's upper rows reach far, its lower ones
    // hit the ground near), so threads take small bands from a queue
    // rather than one half each.
    let threads = threads.max(1);
    let per_band = rows.div_ceil(threads * 8).max(1);
    let (sigma, dropout) = noise;
    let bands = Mutex::new(image.range.chunks_mut(per_band * cols).enumerate());
    // The lock is held only to take a band.
    let next_band = || bands.lock().ok().and_then(|mut queue| queue.next());
    let work = || {
        while let Some((band, chunk)) = next_band() {
            let first = band * per_band;
            let rows_here = chunk.len() / cols;
            sensor.render_rows(world_from_vehicle, view, first..first + rows_here, chunk);
            for (r, row) in chunk.chunks_mut(cols).enumerate() {
                let mut rng = Rng::stream(
                    seed.0,
                    seed.1.wrapping_mul(65_536).wrapping_add((first + r) as u64),
                );
                for value in row {
                    if dropout > 0.0 && rng.unit() < dropout {
                        *value = f32::NAN;
                    } else if value.is_finite() && sigma > 0.0 {
                        *value = (f64::from(*value) + sigma * rng.normal()).max(0.01) as f32;
                    }
                }
            }
        }
    };
    std::thread::scope(|scope| {
        for _ in 1..threads.min(rows) {
            scope.spawn(work);
        }
        work();
    });
    image
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    use super::*;
    use crate::World;
    use crate::tiles::TileCache;

    #[test]
    fn an_image_is_the_same_whatever_the_thread_count() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 64, 2);
        let sensor = SensorModel::erim();
        let pose = isometry_from_xyz_rpy([0.0, 0.0, world.height(0.0, 0.0)], 0.05, -0.1, 0.3);
        let view = tiles.view(0.0, 0.0, sensor.max_range_m + 3.0);
        let image = |threads| render(&sensor, &view, &pose, 7, (0.02, 0.01), (3, 9), threads);
        let one = image(1);
        let returns = one.range.iter().filter(|r| r.is_finite()).count();
        assert!(returns > one.range.len() / 2, "{returns} returns");
        for threads in [2, 3, 64] {
            let other = image(threads);
            // NaN ≠ NaN: compare the bits.
            let bits = |i: &RangeImage| i.range.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&one), bits(&other), "{threads} threads");
        }
    }
}
