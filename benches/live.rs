//! End-to-end latency of `arcnav run` (the threaded executor): from a range
//! image's arrival to the publication of the first command decided on a map
//! holding its cells, p50 and p99, for the 2 Hz ERIM and the 10 Hz 128×2048
//! lidar (target: p99 ≤ 5 ms for 128×2048). Logs of the short course are
//! made once by the simulator into target/bench-data and played in real
//! time into the executor over LCM's in-process `memq://` provider, with the
//! default live configuration (new cells trigger a decision at once), the
//! perception thread sleeping between images and evaluating each alone (the
//! default), then polling for them and handing half of each 128×2048 image
//! to a helper thread (`live.perception_busy_poll = true`).
//!
//! `cargo bench --bench live [-- SECONDS]` (default: 30 s of each log).

mod common;

use std::path::Path;

use arcnav::Config;
use arcnav::live::threaded::InProcess;
use arcnav_behaviours::Registry;
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::channels;
use arcnav_perception::SensorPreset;

fn measure(label: &str, log: &Path, config: &Config, speed: f64) {
    let run = InProcess::start(config, Registry::builtin(), None).expect("arcnav run starts");
    let log = LogReader::open(log).expect("log");
    arcnav_bus::log::play(log, speed, channels::is_input, |e| {
        run.publisher()
            .publish(&e.channel, &e.data)
            .expect("memq publish")
    })
    .expect("log plays");
    std::thread::sleep(std::time::Duration::from_millis(300));
    let report = run.stop().expect("runs");
    let a = report.arrival_to_command_ms;
    let perception = &report.nodes[1].busy_ms;
    println!(
        "{label:<24} image arrival → command: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms over {} images \
         (perception p50 {:.2} ms, p99 {:.2} ms){}",
        a.p50,
        a.p99,
        a.max,
        a.count,
        perception.p50,
        perception.p99,
        if label.contains("128") {
            format!(
                " target p99 ≤ 5 ms: {}",
                if a.p99 <= 5.0 { "met" } else { "NOT met" }
            )
        } else {
            String::new()
        }
    );
    if std::env::var_os("ARCNAV_BENCH_TABLE").is_some() {
        print!("{}", report.table());
    }
}

fn main() {
    let seconds: f64 = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(30.0);
    let data = common::data_dir();
    for (label, preset) in [
        ("ERIM", SensorPreset::Erim),
        ("128×2048", SensorPreset::Lidar128),
    ] {
        let mut config = Config::default();
        config.sensor.preset = preset;
        config.sim.time_limit_s = seconds;
        config.live.status_period_s = 0.0;
        let log = data.join(format!("live-{preset:?}-{seconds}s.lcm").to_lowercase());
        common::make_log(&log, "short_course", &config);
        for busy_poll in [false, true] {
            config.live.perception_busy_poll = busy_poll;
            let wait = if busy_poll { "busy poll" } else { "sleeping" };
            measure(&format!("{label} ({wait})"), &log, &config, 1.0);
        }
    }
}
