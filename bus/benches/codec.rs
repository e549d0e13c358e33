//! Encode and decode throughput of a 128×2048 range image (1 MiB of ranges).
//! Target: decode ≥ 2 GB/s (1 MiB in ≤ 0.5 ms). Run with `cargo bench -p arcnav-bus`.

use arcnav_bus::Message;
use arcnav_bus::lcmtypes::range_image_t;
use divan::counter::BytesCount;
use divan::{Bencher, black_box};

fn main() {
    divan::main();
}

fn lidar_image() -> range_image_t {
    let (rows, cols) = (128usize, 2048usize);
    range_image_t {
        utime: 1_700_000_000_000_000,
        sensor: "lidar128".into(),
        mount_position: [1.2, 0.0, 2.1],
        mount_orientation: [1.0, 0.0, 0.0, 0.0],
        rows: rows as i32,
        cols: cols as i32,
        elevation: (0..rows).map(|r| -0.4 + r as f32 * 0.005).collect(),
        azimuth: (0..cols)
            .map(|c| -std::f32::consts::PI + c as f32 * 0.003)
            .collect(),
        range: (0..rows * cols).map(|i| (i % 997) as f32 * 0.05).collect(),
    }
}

#[divan::bench]
fn encode_128x2048(bencher: Bencher) {
    let image = lidar_image();
    let mut out = Vec::new();
    let len = image.encode().map(|b| b.len()).unwrap_or(0);
    bencher
        .counter(BytesCount::new(len))
        .bench_local(|| black_box(&image).encode_into(&mut out).map(|()| out.len()));
}

#[divan::bench]
fn decode_128x2048(bencher: Bencher) {
    let bytes = lidar_image().encode().unwrap_or_default();
    bencher
        .counter(BytesCount::new(bytes.len()))
        .bench_local(|| range_image_t::decode(black_box(&bytes)).map(|m| m.range.len()));
}
