//! # arcnav
//!
//! Reactive cross-country navigation after Langer, Rosenblatt and Hebert
//! (CMU): early traversability evaluation of each range image, a Ganesha local
//! map of untraversable cells, behaviours voting over steering arcs and a DAMN
//! arbiter fusing the votes into a steering command.
//!
//! This package is the `arcnav` command line. What it runs lives in library
//! crates, re-exported here under the names the command uses:
//! the configuration ([`arcnav_config`]), the offline executors and their
//! pictures ([`arcnav_run`]: [`mission`], [`replay`], [`export`], [`sweep`],
//! [`detection`], [`render`]), the live executors ([`live`], from
//! [`arcnav_live`]) and the wire conversions ([`wire`], from [`arcnav_wire`]).

pub use arcnav_config::{Config, Resolved};
pub use arcnav_live as live;
#[doc(hidden)]
pub use arcnav_run::export;
pub use arcnav_run::{bag, detection, fuzzing, mission, output, render, replay, sweep};
pub use arcnav_wire as wire;

/// Keeps memory the process frees for its next allocations: glibc
/// otherwise maps every block of 128 KiB or more afresh and hands the top
/// of its heap back, so a range image's half megabyte, read, decoded and
/// judged ten times a second, was paid for in fresh zeroed pages (8 % of a
/// lidar replay's CPU). For executables (`arcnav`, the benchmarks), at
/// the start of `main`, before any thread; nothing elsewhere.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's parameters.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}
