//! The simulated range sensor: perception's sensor model rendering the
//! world's height field, plus range noise and dropouts. Rows are rendered in
//! parallel; noise comes from a generator seeded per image and per row, so
//! an image is the same whatever the thread count.

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
    let per_thread = rows.div_ceil(threads.max(1)).max(1);
    let (sigma, dropout) = noise;
    std::thread::scope(|scope| {
        for (chunk_index, chunk) in image.range.chunks_mut(per_thread * cols).enumerate() {
            let first = chunk_index * per_thread;
            scope.spawn(move || {
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
            });
        }
    });
    image
}
