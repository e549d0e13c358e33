//! Test support shared by arcnav's crates (a dev-dependency only).
//!
//! - [`LcmReference`]: the reference LCM implementation (PyPI `lcm`, pinned
//!   in `scripts/test-tools`, installed into `target/lcm-venv`) as a test
//!   peer: its Python bindings and its `lcm-gen`, `lcm-logger`,
//!   `lcm-logplayer` binaries.
//! - [`NetNs`]: a network namespace a test creates and deletes, with `lo` up
//!   and `224.0.0.0/4` routed to it. Live traffic in tests runs only there,
//!   never on the host's network.
//!
//! - [`alloc::Largest`]: an allocator that remembers the largest allocation,
//!   for tests that input never allocates from an unchecked size.
//! - [`cpu_slot`]: one core's share of the suite's heavy work (missions,
//!   replays), across every test process; [`output_of`] takes one.
//!
//! A missing tool skips a test with a loud message locally; under `CI=true`
//! it fails the test with the reason instead.

pub mod alloc;
mod slots;

pub use slots::{CpuSlot, cpu_slot};

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The pinned version of the reference implementation.
pub const LCM_VERSION: &str = "1.5.3";

/// Runs `program` with `args` to its end, holding a [`cpu_slot`]: its
/// exit code (-1 when a signal ended it) and what it printed on standard
/// output and standard error. A test crate passes its binary
/// (`env!("CARGO_BIN_EXE_arcnav")`, which only the test crate can read).
pub fn output_of(program: impl AsRef<std::ffi::OsStr>, args: &[&str]) -> (i32, String, String) {
    let program = program.as_ref();
    let _slot = cpu_slot();
    let out = Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", program.display()));
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// True under CI (`CI=true`), where nothing may be skipped.
pub fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Skips (locally) or fails (under CI) because `what` is missing.
#[track_caller]
pub fn missing(what: &str) {
    if under_ci() {
        panic!("{what}; under CI=true this test may not be skipped (run scripts/test-tools)");
    }
    eprintln!("SKIPPED: {what} (run scripts/test-tools to install it)");
}

/// The reference LCM implementation in a virtual environment.
#[derive(Debug, Clone)]
pub struct LcmReference {
    python: PathBuf,
    bin: PathBuf,
}

impl LcmReference {
    /// The venv named by `ARCNAV_LCM_VENV`, else `target/lcm-venv`, if it
    /// holds a working `lcm` package.
    pub fn find() -> Result<Self, String> {
        let venv = std::env::var_os("ARCNAV_LCM_VENV")
            .map(PathBuf::from)
            .unwrap_or_else(|| workspace_root().join("target/lcm-venv"));
        let python = venv.join("bin/python");
        if !python.exists() {
            return Err(format!(
                "the reference LCM (PyPI lcm=={LCM_VERSION}) is not installed at {}",
                venv.display()
            ));
        }
        let out = Command::new(&python)
            .args(["-c", "import lcm, os; print(os.path.dirname(lcm.__file__))"])
            .output()
            .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
        if !out.status.success() {
            return Err(format!(
                "{} cannot import lcm: {}",
                python.display(),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let package = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
        let bin = package
            .parent()
            .map(|site| site.join("bin"))
            .ok_or("unexpected lcm package location")?;
        if !bin.join("lcm-gen").exists() {
            return Err(format!("lcm-gen not found in {}", bin.display()));
        }
        Ok(Self { python, bin })
    }

    /// [`LcmReference::find`], or skip/fail through [`missing`].
    #[track_caller]
    pub fn require() -> Option<Self> {
        match Self::find() {
            Ok(reference) => Some(reference),
            Err(why) => {
                missing(&why);
                None
            }
        }
    }

    /// The venv's Python interpreter.
    pub fn python(&self) -> Command {
        let mut command = Command::new(&self.python);
        command.env("PYTHONUNBUFFERED", "1");
        command
    }

    pub fn python_path(&self) -> &Path {
        &self.python
    }

    /// Path of a reference binary (`lcm-gen`, `lcm-logger`, `lcm-logplayer`, ...).
    /// These are the real binaries, not the venv wrappers, so signals reach them.
    pub fn tool_path(&self, name: &str) -> PathBuf {
        self.bin.join(name)
    }

    /// The reference LCM and arcnav's types (`bus/lcmtypes`) generated for
    /// Python by its `lcm-gen`, once per test process: the directory to
    /// put on `PYTHONPATH` (`from arcnav import pose_t`). `None` (or a
    /// failure under CI) as [`require`](Self::require).
    #[track_caller]
    pub fn with_arcnav_types() -> Option<&'static (Self, PathBuf)> {
        static TYPES: std::sync::OnceLock<Option<(LcmReference, PathBuf)>> =
            std::sync::OnceLock::new();
        TYPES
            .get_or_init(|| {
                let reference = Self::require()?;
                let files: Vec<PathBuf> = std::fs::read_dir(workspace_root().join("bus/lcmtypes"))
                    .expect("read bus/lcmtypes")
                    .map(|e| e.expect("a bus/lcmtypes entry").path())
                    .collect();
                let types = reference.generate_python(&files, &temp_dir("arcnav-python-types"));
                Some((reference, types))
            })
            .as_ref()
    }

    /// Runs `lcm-gen -p` on `lcm_files` into `out_dir`; returns `out_dir`.
    pub fn generate_python(&self, lcm_files: &[PathBuf], out_dir: &Path) -> PathBuf {
        std::fs::create_dir_all(out_dir).expect("create the lcm-gen output directory");
        let status = Command::new(self.tool_path("lcm-gen"))
            .arg("-p")
            .arg("--ppath")
            .arg(out_dir)
            .args(lcm_files)
            .status()
            .expect("run lcm-gen");
        assert!(status.success(), "lcm-gen -p failed on {lcm_files:?}");
        out_dir.to_path_buf()
    }
}

/// A fresh directory under `target/test-tmp` for one test, named
/// `TAG-PID-N`. What a test process writes there (logs shared by its tests,
/// up to 190 MB each) stays until the process has ended and another calls
/// this: the first call in a process removes the directories of processes
/// that are no longer running (7 GB had piled up over a few days' runs).
pub fn temp_dir(tag: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    static SWEPT: std::sync::Once = std::sync::Once::new();
    let root = workspace_root().join("target/test-tmp");
    SWEPT.call_once(|| remove_dirs_of_ended_processes(&root));
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = root.join(format!("{tag}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a test directory");
    dir
}

/// A file that the test processes of one test executable share: made once
/// by `make` (given the path to write it at) for this build of the
/// executable, then used by every process of the run and of later runs
/// until the executable is rebuilt. nextest runs each test in a process of
/// its own, so a log made "once" per process (`OnceLock`) was made again
/// for each test. Processes that want it at the same time wait for the
/// one making it (a lock on a file beside it); what `make` leaves half
/// written (it panicked) is never used. Under
/// `target/test-shared/EXE-BUILD/`; the directories of the executable's
/// earlier builds are removed when a new one is made.
pub fn shared_file(name: &str, make: impl FnOnce(&Path)) -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let stem = exe
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("test")
        .to_owned();
    let built = std::fs::metadata(&exe)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    let root = workspace_root().join("target/test-shared");
    let dir = root.join(format!("{stem}-{built}"));
    std::fs::create_dir_all(&dir).expect("create the shared test directory");
    let lock = std::fs::File::create(dir.join(format!("{name}.lock"))).expect("create a lock file");
    lock.lock().expect("lock the shared test file");
    let path = dir.join(name);
    if !path.exists() {
        if let Ok(entries) = std::fs::read_dir(&root) {
            for entry in entries.flatten() {
                let other = entry.file_name();
                let other = other.to_string_lossy();
                if other.starts_with(&format!("{stem}-")) && entry.path() != dir {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
            }
        }
        let partial = dir.join(format!("{name}.partial-{}", std::process::id()));
        make(&partial);
        std::fs::rename(&partial, &path).expect("put the shared test file in place");
    }
    path
}

/// Removes each `TAG-PID-N` directory in `root` whose process is not
/// running (no `/proc/PID`). Where there is no `/proc`, removes nothing.
fn remove_dirs_of_ended_processes(root: &Path) {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(root) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(|name| {
            let mut parts = name.rsplitn(3, '-');
            let (_n, pid, _tag) = (parts.next()?, parts.next()?, parts.next()?);
            pid.parse::<u32>().ok()
        }) else {
            continue;
        };
        if !proc.join(pid.to_string()).exists() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// A fresh directory under the system's temporary directory for what one
/// test writes (logs of a whole mission run to tens of MB). It is removed
/// when the test passes; when the test fails it is kept, and its path
/// printed, so what the run wrote can be looked at.
#[derive(Debug)]
pub struct ScratchDir(Option<tempfile::TempDir>);

/// A [`ScratchDir`] whose name starts with `prefix`.
pub fn scratch_dir(prefix: &str) -> ScratchDir {
    let dir = tempfile::Builder::new()
        .prefix(&format!("{prefix}-"))
        .tempdir()
        .expect("create a test directory");
    ScratchDir(Some(dir))
}

impl std::ops::Deref for ScratchDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        self.0.as_ref().map_or(Path::new(""), |dir| dir.path())
    }
}

impl AsRef<Path> for ScratchDir {
    fn as_ref(&self) -> &Path {
        self
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        if std::thread::panicking()
            && let Some(dir) = self.0.take()
        {
            eprintln!(
                "kept {} for a look at what the failed test wrote",
                dir.keep().display()
            );
        }
    }
}

/// A network namespace owned by one test; deleted on drop.
#[derive(Debug)]
pub struct NetNs {
    name: String,
}

const NETNS_PREFIX: &str = "arcnav-test-";

impl NetNs {
    /// Creates a namespace with `lo` up and multicast routed to `lo`.
    /// Needs root and `ip` (iproute2).
    pub fn create(tag: &str) -> Result<Self, String> {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            return Err("network-namespace tests need root (ip netns add)".into());
        }
        remove_stale_namespaces();
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!("{NETNS_PREFIX}{}-{n}-{tag}", std::process::id());
        let name: String = name.chars().take(60).collect();
        ip(&["netns", "add", &name])?;
        let ns = Self { name };
        ip(&["-n", &ns.name, "link", "set", "lo", "up"])?;
        ip(&["-n", &ns.name, "route", "add", "224.0.0.0/4", "dev", "lo"])?;
        Ok(ns)
    }

    /// [`NetNs::create`], or skip/fail through [`missing`].
    #[track_caller]
    pub fn require(tag: &str) -> Option<Self> {
        match Self::create(tag) {
            Ok(ns) => Some(ns),
            Err(why) => {
                missing(&why);
                None
            }
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// A command that runs `program` inside the namespace.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut command = Command::new("ip");
        command.args(["netns", "exec", &self.name]).arg(program);
        command
    }

    /// Runs `f` on a thread that has entered the namespace: sockets it
    /// creates live there (and keep living there when used elsewhere).
    pub fn run<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        let path = format!("/run/netns/{}", self.name);
        std::thread::scope(|scope| {
            scope
                .spawn(move || {
                    let file =
                        std::fs::File::open(&path).unwrap_or_else(|e| panic!("open {path}: {e}"));
                    use std::os::fd::AsRawFd;
                    // SAFETY: setns on a valid namespace fd only changes this
                    // thread's network namespace.
                    let rc = unsafe { libc::setns(file.as_raw_fd(), libc::CLONE_NEWNET) };
                    assert_eq!(
                        rc,
                        0,
                        "setns into {path}: {}",
                        std::io::Error::last_os_error()
                    );
                    f()
                })
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
        })
    }
}

impl Drop for NetNs {
    fn drop(&mut self) {
        if let Err(e) = ip(&["netns", "del", &self.name]) {
            eprintln!(
                "warning: could not delete network namespace {}: {e}",
                self.name
            );
        }
    }
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run `ip` (install iproute2): {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Deletes namespaces left by test processes that no longer exist.
fn remove_stale_namespaces() {
    let Ok(entries) = std::fs::read_dir("/run/netns") else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(NETNS_PREFIX) else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = ip(&["netns", "del", &name]);
        }
    }
}

#[cfg(test)]
mod scratch_tests {
    use super::*;

    #[test]
    fn a_scratch_dir_goes_when_the_test_passes_and_stays_when_it_fails() {
        let passed = scratch_dir("arcnav-testkit-pass");
        std::fs::write(passed.join("log"), b"x").unwrap();
        let path = passed.to_path_buf();
        drop(passed);
        assert!(!path.exists());

        let (send, receive) = std::sync::mpsc::channel();
        let failed = std::thread::spawn(move || {
            let dir = scratch_dir("arcnav-testkit-fail");
            std::fs::write(dir.join("log"), b"x").unwrap();
            send.send(dir.to_path_buf()).unwrap();
            panic!("a failing test");
        });
        assert!(failed.join().is_err());
        let kept = receive.recv().unwrap();
        assert!(kept.join("log").exists(), "{kept:?} kept");
        std::fs::remove_dir_all(kept).unwrap();
    }

    #[test]
    fn directories_of_ended_processes_are_removed_and_running_ones_kept() {
        let root = scratch_dir("arcnav-testkit-sweep");
        // A process that has ended: a child that has been waited for.
        let mut child = Command::new("true").spawn().unwrap();
        let ended = child.id();
        child.wait().unwrap();
        let running = std::process::id();
        let names = [
            format!("live-log-{ended}-3"),
            format!("live-log-{running}-0"),
            "not-a-pid-dir".to_owned(),
        ];
        for name in &names {
            std::fs::create_dir_all(root.join(name)).unwrap();
        }
        remove_dirs_of_ended_processes(&root);
        assert!(!root.join(&names[0]).exists(), "ended: {}", names[0]);
        assert!(root.join(&names[1]).exists(), "running: {}", names[1]);
        assert!(root.join(&names[2]).exists(), "not TAG-PID-N");
    }
}
