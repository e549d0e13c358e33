//! A limit on the heavy work tests do at once across the whole suite: one
//! simulation (or replay) per core, whichever test process runs it.
//!
//! cargo-nextest runs one test more than there are cores, and a mission
//! test runs its missions one per core besides: up to six at once on two
//! cores. Six lidar missions at once each took 16 % more CPU than two at a
//! time (`arcnav sim --world short_course --sensor lidar64`: 8.8 against
//! 7.6 s, 2026-12-07: caches and memory bandwidth shared six ways), on a
//! suite whose time is its CPU. A slot is a lock (`flock`) on one of as
//! many files as there are cores in `target/test-shared/cpu-slots/`: held
//! while the work runs, given back when it is dropped (or its process
//! ends, however).

use std::fs::File;
use std::os::fd::AsRawFd;
use std::time::Duration;

/// One core's slot, held until dropped.
#[must_use = "the slot is given back when dropped"]
pub struct CpuSlot {
    _lock: File,
}

/// Waits for a free slot and takes it.
pub fn cpu_slot() -> CpuSlot {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let dir = crate::workspace_root().join("target/test-shared/cpu-slots");
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let files: Vec<File> = (0..cores)
        .map(|k| {
            let path = dir.join(format!("slot-{k}"));
            File::options()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        })
        .collect();
    loop {
        for file in &files {
            // SAFETY: flock on a file descriptor this process holds open.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
                let lock = file.try_clone().expect("a duplicate of an open file");
                return CpuSlot { _lock: lock };
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
