//! Every fuzz target over its committed corpus (`fuzz/corpus/<target>/`,
//! seeds and whatever libFuzzer found worth keeping), as plain tests on
//! stable: a regression on an input the fuzzers met fails here, no fuzzer
//! needed. Each input must also finish within a bound (no hangs).

use std::time::{Duration, Instant};

use arcnav::fuzzing::TARGETS;

#[test]
fn every_fuzz_target_handles_its_whole_corpus() {
    let root = arcnav_testkit::workspace_root().join("fuzz/corpus");
    for (name, target) in TARGETS {
        let dir = root.join(name);
        let mut inputs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.unwrap().path())
            .collect();
        inputs.sort();
        assert!(!inputs.is_empty(), "{name}: an empty corpus");
        for input in inputs {
            let bytes = std::fs::read(&input).unwrap();
            let started = Instant::now();
            target(&bytes);
            assert!(
                started.elapsed() < Duration::from_secs(5),
                "{}: took {:?}",
                input.display(),
                started.elapsed()
            );
        }
    }
}
