//! What the benchmarks share: simulator logs made once into
//! target/bench-data.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav_sim::World;

/// Whether this is a quick run: `cargo test --benches` (as `scripts/test`
/// does) runs a custom-harness benchmark without `--bench`, to check that
/// it builds and runs, on shorter inputs and once; `cargo bench` passes
/// `--bench` and gets the figures.
pub fn quick() -> bool {
    !std::env::args().any(|a| a == "--bench")
}

/// `target/bench-data`, created.
pub fn data_dir() -> PathBuf {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/bench-data");
    std::fs::create_dir_all(&data).expect("create target/bench-data");
    data
}

/// The log of a simulated mission on `world` (an embedded world's name,
/// or a world file's path from the workspace, ending in `.toml`) under
/// `config`, made unless `path` exists.
pub fn make_log(path: &Path, world: &str, config: &Config) {
    if path.exists() {
        return;
    }
    eprintln!("making {} (once)...", path.display());
    let world = Arc::new(if world.ends_with(".toml") {
        World::load(&arcnav_testkit::workspace_root().join(world)).expect("the world loads")
    } else {
        World::embedded(world).expect("embedded").expect("valid")
    });
    let options = MissionOptions {
        log: Some(path.to_owned()),
        ..MissionOptions::default()
    };
    run_mission(&config.resolved().unwrap(), world, &options, &mut |_| {})
        .expect("the mission runs");
}
