//! Live operation: the threaded executor (`arcnav run`) and the distributed
//! nodes (`arcnav node …`) against the lock-step replay of the same log, the
//! safety watchdogs, signals and a flood of range images.
//!
//! Network traffic runs only inside a network namespace each test creates and
//! deletes (see DEVELOPERS.md); the in-process test uses LCM's `memq://`.
//! The tests run one at a time: they feed logs in real time and measure
//! timing, which other tests on the same two cores would disturb.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, mpsc};
use std::time::{Duration, Instant};

use arcnav::Config;
use arcnav::live::clock::ManualClock;
use arcnav::live::threaded::InProcess;
use arcnav::mission::{MissionOptions, SIM_EPOCH_US, run_mission};
use arcnav::replay::{ReplayOptions, replay};
use arcnav_bus::auth::{AuthPolicy, GroupKey, Signer, TRAILER_LEN};
use arcnav_bus::codec::Message as _;
use arcnav_bus::lcmtypes::decision_t;
use arcnav_bus::lcmtypes::{pose_t, steering_command_t};
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::channels;
use arcnav_bus::transport::{Lcm, wall_clock_utime};
use arcnav_perception::SensorPreset;
use arcnav_pipeline::{Decided, Hazard, Why};
use arcnav_sim::World;
use arcnav_testkit::{LcmReference, NetNs, temp_dir};
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{CommandWatchdog, SteeringCommand, Utime};

/// One live test at a time.
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// Seconds of the short course each log holds: long enough to steer round
/// its first bushes (three arcs or more), short enough that the tests'
/// real-time feeds stay a few minutes in all (20 s before 2026-11-28).
const LOG_S: f64 = 12.0;

/// The arbiter's cycles (10 Hz) over a log.
const LOG_CYCLES: usize = LOG_S as usize * 10;

/// The cycles a live run reproducing lock-step must have compared with it
/// over a log: all but the first second's.
const COMPARED_AT_LEAST: usize = LOG_CYCLES - 10;

/// The configuration of the logs and of the live runs compared with them.
fn config(sensor: SensorPreset, reproduce: bool) -> Config {
    let mut c = Config::default();
    c.sensor.preset = sensor;
    c.sim.time_limit_s = LOG_S;
    c.live.reproduce_lockstep = reproduce;
    c.live.status_period_s = 0.0;
    c
}

/// The first `LOG_S` seconds of the short course, made once per test run.
fn sim_log(sensor: SensorPreset) -> PathBuf {
    sim_log_of(&config(sensor, false))
}

/// `config` streaming its images in slices of 16 lines (002 §7's
/// integrated mode), each judged with the poses around it (extrapolating
/// past the newest pose depends on which arrives first: live runs that
/// reproduce lock-step do not).
fn sliced(mut config: Config) -> Config {
    config.sim.slice_lines = 16;
    config.pipeline.slice_pose_extrapolation_s = 0.0;
    config
}

/// The first `LOG_S` seconds of the short course under `config`, made once
/// for this build of the tests (shared by their processes:
/// [`arcnav_testkit::shared_file`]).
fn sim_log_of(config: &Config) -> PathBuf {
    sim_log_on("short_course", config)
}

/// The first `LOG_S` seconds of `world` (an embedded world's name, or a
/// file under tests/worlds) under `config`, made once for this build of
/// the tests.
fn sim_log_on(world: &str, config: &Config) -> PathBuf {
    let key = format!(
        "{}-{:?}-{}-{}",
        world.replace('/', "-"),
        config.sensor.preset,
        config.sim.slice_lines,
        config.sim.time_limit_s
    );
    arcnav_testkit::shared_file(&format!("{key}.lcm"), |path| {
        let world = Arc::new(
            World::embedded(world)
                .unwrap_or_else(|| {
                    World::load(
                        &arcnav_testkit::workspace_root()
                            .join(format!("tests/worlds/{world}.toml")),
                    )
                })
                .unwrap(),
        );
        let options = MissionOptions {
            log: Some(path.to_owned()),
            ..MissionOptions::default()
        };
        run_mission(&config.resolved().unwrap(), world, &options, &mut |_| {}).unwrap();
    })
}

/// The lock-step replay's commands, by cycle time.
fn lockstep(log: &Path, config: &Config) -> BTreeMap<Utime, SteeringCommand> {
    replay(
        log,
        &config.resolved().unwrap(),
        &ReplayOptions::default(),
        &mut |_| {},
    )
    .unwrap()
    .cycles
    .into_iter()
    .map(|((_, t), c)| (t, c.command))
    .collect()
}

/// Publishes the log's inputs (POSE, RANGE_IMAGE*, WAYPOINTS) at `speed` ×
/// real time.
fn feed(log: &Path, speed: f64, mut publish: impl FnMut(&str, &[u8])) {
    let log = LogReader::open(log).unwrap();
    arcnav_bus::log::play(log, speed, channels::is_input, |e| {
        publish(&e.channel, &e.data)
    })
    .unwrap();
}

/// How live commands agree with the lock-step ones over the replayed cycles
/// from `skip_s` after the log's start to `until_s`.
struct Agreement {
    compared: usize,
    agreeing: usize,
    /// The lock-step cycles with no live command.
    missing: Vec<Utime>,
}

impl Agreement {
    fn of(
        live: &BTreeMap<Utime, SteeringCommand>,
        lockstep: &BTreeMap<Utime, SteeringCommand>,
        skip_s: f64,
        until_s: f64,
    ) -> Self {
        let (from, to) = (
            SIM_EPOCH_US + (skip_s * 1e6) as i64,
            SIM_EPOCH_US + (until_s * 1e6) as i64,
        );
        let mut a = Agreement {
            compared: 0,
            agreeing: 0,
            missing: Vec::new(),
        };
        for (t, expected) in lockstep.range(from..to) {
            let Some(got) = live.get(t) else {
                a.missing.push(*t);
                continue;
            };
            a.compared += 1;
            if got.arc_index == expected.arc_index
                && (got.speed_mps - expected.speed_mps).abs() < 1e-6
            {
                a.agreeing += 1;
            }
        }
        a
    }

    fn percent(&self) -> f64 {
        100.0 * self.agreeing as f64 / (self.compared + self.missing.len()).max(1) as f64
    }
}

#[test]
fn the_threaded_executor_gives_the_lockstep_commands() {
    assert_threaded_gives_lockstep(false);
}

#[test]
fn a_busy_polling_perception_thread_gives_the_same_commands() {
    assert_threaded_gives_lockstep(true);
}

/// 020 item 3: a 64-beam lidar's images streamed in 16-column slices,
/// each judged as it arrives: the threaded executor gives lock-step's
/// commands. Fed at real time, as the sensor sends them: at twice real
/// time (2,560 slices a second) perception, at 0.4-0.5 ms a slice, had no
/// time to spare, and with the host's cores shared with other work its
/// reports reached the map after the cycles that lock-step gives them to
/// (4,000 late of 5,000; 6-30 of 200 cycles decided otherwise).
#[test]
fn streamed_slices_give_the_lockstep_commands_in_the_threaded_executor() {
    assert_threaded_gives_lockstep_on(sliced(config(SensorPreset::Lidar64, true)), 1.0);
}

fn assert_threaded_gives_lockstep(perception_busy_poll: bool) {
    let mut config = config(SensorPreset::Erim, true);
    config.live.perception_busy_poll = perception_busy_poll;
    assert_threaded_gives_lockstep_on(config, 2.0);
}

/// `arcnav run`'s executor over memq, fed a sim log at `speed` × real
/// time, gives lock-step replay's commands, its perception thread sleeping
/// between images or polling for them.
fn assert_threaded_gives_lockstep_on(mut config: Config, speed: f64) {
    let _serial = serial();
    // The feed's end is the test's, not the vehicle's: its last poses stay
    // fresh while the run decides the cycles still in its queues.
    config.live.pose_timeout_s = 3.0;
    let mut log_config = config.clone();
    log_config.live.reproduce_lockstep = false;
    let log = sim_log_of(&log_config);
    let expected = lockstep(&log, &config);
    let (tap, taken) = crossbeam_channel::unbounded::<Decided>();
    let run = InProcess::start(&config.resolved().unwrap(), Some(tap)).unwrap();
    // At most twice real time: perception still delivers long before the
    // modelled 0.3 s latency.
    feed(&log, speed, |channel, data| {
        run.publisher().publish(channel, data).unwrap()
    });
    // Stopped once the last cycle is decided on its votes (watchdog stops
    // carry the newest pose's time), or after 3 s.
    let last_cycle = SIM_EPOCH_US + ((LOG_S - 0.1) * 1e6) as Utime;
    let deadline = Instant::now() + Duration::from_secs(3);
    let mut decided: Vec<Decided> = Vec::new();
    while let Ok(d) = taken.recv_deadline(deadline) {
        let done = matches!(d.why, Why::Complete) && d.command.utime >= last_cycle;
        decided.push(d);
        if done {
            break;
        }
    }
    let report = run.stop().unwrap();
    decided.extend(taken.try_iter());
    let live: BTreeMap<Utime, SteeringCommand> = decided
        .iter()
        .filter(|d| matches!(d.why, Why::Complete))
        .map(|d| (d.command.utime, d.command))
        .collect();
    // Until a pose has come and perception has evaluated an image the live
    // arbiter refuses to drive; lock-step replay has no such watchdog. The
    // cycle at the first pose may come before the first image is evaluated
    // (and under load the watchdog may tick before the first pose is
    // taken in); from the next one on the commands must be the same. The
    // guard beside the arbiter, with no image or pose of its own yet,
    // stops those first cycles for the same reason (one CI run of six,
    // 2026-12-07, under load).
    let first = live.keys().next().copied().unwrap();
    let first_s = (first - SIM_EPOCH_US) as f64 * 1e-6;
    assert!(first_s <= 0.11, "first decision on votes at {first_s:.2} s");
    let starting = |why: &Why| match why {
        Why::Watchdog(Hazard::NoImage | Hazard::NoPose) => true,
        Why::Guard(reason) => {
            reason == "no pose yet"
                || (reason.starts_with("no image from ") && reason.ends_with(" yet"))
        }
        _ => false,
    };
    for d in decided.iter().filter(|d| d.command.utime < first) {
        assert!(
            starting(&d.why),
            "before the first decision on votes: {:?}",
            d.why
        );
        assert!(d.command.is_stop(), "{d:?}");
    }
    let a = Agreement::of(&live, &expected, first_s, LOG_S);
    eprintln!("{}", report.table());
    eprintln!(
        "threaded vs lock-step: {} of {} cycles agree ({:.2}%), {} missing",
        a.agreeing,
        a.compared + a.missing.len(),
        a.percent(),
        a.missing.len()
    );
    let missing: Vec<_> = a
        .missing
        .iter()
        .map(|t| {
            let why = decided
                .iter()
                .find(|d| d.command.utime == *t)
                .map(|d| &d.why);
            format!("{:.2} s: {why:?}", (t - SIM_EPOCH_US) as f64 * 1e-6)
        })
        .collect();
    // Same nodes, same timing model: the same commands, cycle for cycle.
    assert!(
        a.compared >= COMPARED_AT_LEAST,
        "only {} cycles compared; not decided: {missing:?}",
        a.compared
    );
    // Reproducing lock-step, no cycle is skipped: every one lock-step
    // decides is decided, and decided the same way.
    assert!(a.missing.is_empty(), "cycles not decided: {missing:?}");
    assert_eq!(a.agreeing, a.compared);
    // The run steered: not a trivially straight log.
    let arcs: std::collections::BTreeSet<_> = live.values().map(|c| c.arc_index).collect();
    assert!(arcs.len() >= 3, "arcs used: {arcs:?}");
    // The final command is a stop.
    let last = decided.last().unwrap();
    assert_eq!(last.why, Why::Final);
    assert!(last.command.is_stop());
    // Figures for every node, the guard's among them: it judged every
    // command and, with no fault, changed none but the startup stop
    // allowed above (no image or pose of its own yet: under load, one CI
    // run of five, 2026-12-07, where this counted it).
    let names: Vec<&str> = report.nodes.iter().map(|n| n.node.as_str()).collect();
    assert_eq!(
        names,
        [
            "io",
            "perception",
            "localmap",
            "behaviours",
            "arbiter",
            "guard"
        ]
    );
    let guard = &report.nodes[5];
    let stopped_at_start = decided
        .iter()
        .any(|d| d.command.utime < first && matches!(d.why, Why::Guard(_)));
    assert!(
        guard.counters.contains(&(
            "guard_interventions".to_owned(),
            u64::from(stopped_at_start)
        )),
        "{}",
        report.table()
    );
    // Nothing dropped but what was captured after the log's last pose
    // (waiting for one when the inputs closed: an image, or less than a
    // streamed frame's slices).
    let perception = &report.nodes[1];
    let counter = |name: &str| {
        perception
            .counters
            .iter()
            .find(|(n, _)| n == name)
            .map_or(0, |(_, v)| *v)
    };
    let waiting = counter("waiting_at_end");
    assert_eq!(perception.dropped, waiting, "{}", report.table());
    assert!(
        waiting <= (counter("slices") / counter("streamed_frames").max(1)).max(1),
        "{}",
        report.table()
    );
}

/// The watchdogs read the executor's clock: a test moves it instead of
/// waiting for it, and the executor stops the vehicle the moment poses are
/// older than `live.pose_timeout_s` on that clock.
#[test]
fn the_watchdog_stops_on_the_executors_own_clock() {
    let _serial = serial();
    let config = config(SensorPreset::Erim, false);
    let clock = ManualClock::starting_at(1_000_000_000_000);
    let (tap, taken) = crossbeam_channel::unbounded::<Decided>();
    let run = InProcess::start_with(
        &config.resolved().unwrap(),
        Some(tap),
        Some(Arc::new(clock.clone())),
    )
    .unwrap();
    // The first 3 s of the log, the clock following the log's time.
    let mut log = LogReader::open(sim_log(SensorPreset::Erim)).unwrap();
    let mut t0 = None;
    let mut last_pose = 0;
    while let Some(event) = log.next_event().unwrap() {
        let t = event.timestamp;
        let t0 = *t0.get_or_insert(t);
        if t - t0 > 3_000_000 {
            break;
        }
        if event.channel == channels::POSE {
            last_pose = pose_t::decode(&event.data).unwrap().utime;
        }
        if channels::is_input(&event.channel) {
            clock.set(1_000_000_000_000 + (t - t0));
            run.publisher()
                .publish(&event.channel, &event.data)
                .unwrap();
            // Let the executor keep up with a log fed faster than real time.
            std::thread::sleep(Duration::from_micros(500));
        }
    }
    let wait_for = |what: &dyn Fn(&Decided) -> bool| {
        let until = Instant::now() + Duration::from_secs(5);
        while let Ok(d) = taken.recv_deadline(until) {
            if what(&d) {
                return Some(d);
            }
        }
        None
    };
    assert!(
        wait_for(&|d| !d.command.is_stop()).is_some(),
        "the vehicle drove while poses and images were fresh"
    );
    // The last cycle decided (the command rate is 10 Hz): every pose is in,
    // however far a loaded host had let the executor fall behind the feed.
    let period = seconds_to_micros(1.0 / config.pipeline.command_rate_hz);
    assert!(
        wait_for(&|d| !matches!(d.why, Why::Watchdog(_)) && d.command.utime > last_pose - period)
            .is_some(),
        "no decision for the last cycle fed"
    );
    while taken.try_recv().is_ok() {}
    // No more poses: 0.4 s later on the clock, still fresh; 0.6 s, stop.
    clock.advance(400_000);
    std::thread::sleep(Duration::from_millis(50));
    assert!(
        taken
            .try_iter()
            .all(|d| !matches!(d.why, Why::Watchdog(Hazard::PoseStale { .. }))),
        "stopped before the pose timeout"
    );
    clock.advance(200_000);
    let stop = wait_for(&|d| matches!(d.why, Why::Watchdog(Hazard::PoseStale { .. })))
        .expect("a stop for stale poses");
    assert!(stop.command.is_stop());
    let Why::Watchdog(Hazard::PoseStale { age_s }) = stop.why else {
        unreachable!()
    };
    assert!((0.5..0.65).contains(&age_s), "pose age {age_s} s");
    run.stop().unwrap();
}

// ---------------------------------------------------------------------------
// Over UDP multicast, inside a network namespace.

/// An `arcnav` process inside the namespace, its output collected.
struct Proc {
    name: String,
    child: Child,
    stderr: Arc<Mutex<String>>,
    stdout: Arc<Mutex<String>>,
    ready: mpsc::Receiver<()>,
}

impl Proc {
    fn arcnav(ns: &NetNs, name: &str, args: &[&str]) -> Proc {
        let mut child = ns
            .command(env!("CARGO_BIN_EXE_arcnav"))
            .args(args)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (ready_tx, ready) = mpsc::channel();
        let stderr = Arc::new(Mutex::new(String::new()));
        let stdout = Arc::new(Mutex::new(String::new()));
        let pipe = child.stderr.take().unwrap();
        let text = Arc::clone(&stderr);
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                if line.contains("ready: receiving") {
                    let _ = ready_tx.send(());
                }
                let mut text = text.lock().unwrap();
                text.push_str(&line);
                text.push('\n');
            }
        });
        let pipe = child.stdout.take().unwrap();
        let text = Arc::clone(&stdout);
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                let mut text = text.lock().unwrap();
                text.push_str(&line);
                text.push('\n');
            }
        });
        Proc {
            name: name.to_owned(),
            child,
            stderr,
            stdout,
            ready,
        }
    }

    fn wait_ready(&self) {
        if self.ready.recv_timeout(Duration::from_secs(60)).is_err() {
            panic!(
                "{} did not become ready:\n{}",
                self.name,
                self.stderr.lock().unwrap()
            );
        }
    }

    fn signal(&self, signal: &str) {
        let status = Command::new("kill")
            .args([format!("-{signal}"), self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success(), "kill -{signal} {}", self.name);
    }

    /// Waits for the exit; the exit code (None: killed) and stdout.
    fn finish(mut self) -> (Option<i32>, String) {
        let deadline = Instant::now() + Duration::from_secs(20);
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                panic!(
                    "{} did not exit:\n{}",
                    self.name,
                    self.stderr.lock().unwrap()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        // Let the pipe readers drain.
        std::thread::sleep(Duration::from_millis(100));
        let stdout = self.stdout.lock().unwrap().clone();
        if status.code() != Some(0) {
            eprintln!("{} stderr:\n{}", self.name, self.stderr.lock().unwrap());
        }
        (status.code(), stdout)
    }

    /// Resident memory, kB.
    fn rss_kb(&self) -> Option<u64> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).ok()?;
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
    }
}

/// The reference `lcm-logplayer` playing `channels` of `log` at `speed`.
fn logplayer(
    ns: &NetNs,
    reference: &LcmReference,
    log: &Path,
    channels: &str,
    speed: f64,
) -> Child {
    ns.command(reference.tool_path("lcm-logplayer"))
        .args(["-e", channels, "-s", &speed.to_string()])
        .arg(log)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// Steering commands as a vehicle receives them: (arrival, command).
type Received = Vec<(Instant, SteeringCommand)>;

/// Runs `listen` inside `ns` while `body` runs: `body` starts once
/// `listen` says it is ready, and `listen` stops when told, 300 ms after
/// `body` returned (late commands, the final stop, still arrive).
fn listening<T, R: Send>(
    ns: &NetNs,
    listen: impl FnOnce(&AtomicBool, &mpsc::Sender<()>) -> R + Send,
    body: impl FnOnce() -> T,
) -> (T, R) {
    /// Tells the listener to stop however `body` ends (a failed assertion
    /// in it must not leave the test waiting for the listener forever).
    struct StopOnDrop<'a>(&'a AtomicBool);
    impl Drop for StopOnDrop<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    let stop = AtomicBool::new(false);
    let (ready_tx, ready) = mpsc::channel();
    std::thread::scope(|scope| {
        let listener = scope.spawn(|| ns.run(|| listen(&stop, &ready_tx)));
        ready.recv().unwrap();
        let out = {
            let _stop = StopOnDrop(&stop);
            let out = body();
            std::thread::sleep(Duration::from_millis(300));
            out
        };
        (out, listener.join().unwrap())
    })
}

/// Records STEERING_COMMAND inside `ns` while `body` runs.
fn recording<T>(ns: &NetNs, body: impl FnOnce() -> T) -> (T, Received) {
    recording_watched(ns, |_| body())
}

/// The cycle time of the latest steering command heard so far, and of the
/// latest external behaviour's votes (`ARC_VOTES_HEADING_HOLD`).
struct Latest(AtomicI64, AtomicI64);

impl Latest {
    /// Waits (at most `within`) until a command for the cycle at `utime`
    /// or a later one has been heard. A fixed pause after the feed was too
    /// short on a loaded 2-core machine: the last cycles were decided after
    /// the executor had been told to stop.
    fn wait_for_cycle(&self, utime: Utime, within: Duration) {
        wait_until_past(&self.0, utime, within, "decided");
    }

    /// Waits (at most `within`) until the external behaviour has voted on
    /// the cycle at `utime`: under load a Python behaviour lags the
    /// arbiter (which decides without it at the deadline), and its last
    /// votes would reach an executor already told to stop.
    fn wait_for_votes(&self, utime: Utime, within: Duration) {
        wait_until_past(&self.1, utime, within, "voted on by the external behaviour");
    }
}

/// Waits (at most `within`) until `latest` reaches `utime`.
fn wait_until_past(latest: &AtomicI64, utime: Utime, within: Duration, what: &str) {
    let deadline = Instant::now() + within;
    while latest.load(Ordering::Relaxed) < utime {
        assert!(
            Instant::now() < deadline,
            "the cycle at {:.2} s was not {what} within {within:?} of the feed's end",
            (utime - SIM_EPOCH_US) as f64 * 1e-6
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// [`recording`], with what has been heard so far given to `body`.
fn recording_watched<T>(ns: &NetNs, body: impl FnOnce(&Latest) -> T) -> (T, Received) {
    let heard = Latest(AtomicI64::new(i64::MIN), AtomicI64::new(i64::MIN));
    let external = channels::arc_votes("heading_hold");
    let listen = |stop: &AtomicBool, ready: &mpsc::Sender<()>| {
        let mut lcm = Lcm::new("").unwrap();
        lcm.subscribe(channels::STEERING_COMMAND);
        lcm.subscribe(&external);
        ready.send(()).unwrap();
        let mut got = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            if let Some(m) = lcm.recv_timeout(Duration::from_millis(20)).unwrap() {
                if m.channel == external {
                    use arcnav_bus::lcmtypes::arc_votes_t;
                    if let Ok(votes) = arc_votes_t::decode(&m.data) {
                        heard.1.fetch_max(votes.utime, Ordering::Relaxed);
                    }
                    continue;
                }
                let msg = steering_command_t::decode(&m.data).unwrap();
                heard.0.fetch_max(msg.utime, Ordering::Relaxed);
                got.push((Instant::now(), SteeringCommand::from(&msg)));
            }
        }
        got
    };
    listening(ns, listen, || body(&heard))
}

/// The last cycle lock-step replay decides on `log`.
fn last_cycle(log: &Path, config: &Config) -> Utime {
    *lockstep(log, config).keys().next_back().unwrap()
}

/// The commands published at cycle times (heartbeat stops sit between them).
fn by_time(received: &Received) -> BTreeMap<Utime, SteeringCommand> {
    received.iter().map(|(_, c)| (c.utime, *c)).collect()
}

fn write_config(config: &Config, dir: &Path) -> String {
    let path = dir.join("config.toml");
    std::fs::write(&path, config.to_toml()).unwrap();
    path.display().to_string()
}

/// What a network test needs: the reference tools, a namespace of its own,
/// a log to play and a configuration file; one test at a time.
struct Net {
    _serial: MutexGuard<'static, ()>,
    reference: LcmReference,
    ns: NetNs,
    log: PathBuf,
    config: Config,
    file: String,
}

impl Net {
    /// `None` (skipped locally, failed under CI) without root or the tools.
    fn setup(tag: &str, config: Config, log: impl FnOnce(&Config) -> PathBuf) -> Option<Net> {
        let serial = serial();
        let reference = LcmReference::require()?;
        let ns = NetNs::require(tag)?;
        let log = log(&config);
        let file = write_config(&config, &temp_dir(&format!("live-{tag}")));
        Some(Net {
            _serial: serial,
            reference,
            ns,
            log,
            config,
            file,
        })
    }

    /// The ERIM log of the short course under `config`.
    fn erim(tag: &str, config: Config) -> Option<Net> {
        Net::setup(tag, config, |_| sim_log(SensorPreset::Erim))
    }

    /// `arcnav ARGS --config FILE` inside the namespace.
    fn arcnav(&self, name: &str, args: &[&str]) -> Proc {
        let args: Vec<&str> = args
            .iter()
            .copied()
            .chain(["--config", self.file.as_str()])
            .collect();
        Proc::arcnav(&self.ns, name, &args)
    }

    /// The reference `lcm-logger` recording everything on the bus to `path`
    /// (until [`Logger::finish`]).
    fn logger(&self, path: &Path) -> Logger {
        Logger(KillOnDrop(
            self.ns
                .command(self.reference.tool_path("lcm-logger"))
                .args(["-f", "--flush-interval=50"])
                .arg(path)
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        ))
    }

    /// The reference player on the test's log.
    fn play(&self, channels: &str, speed: f64) -> Child {
        logplayer(&self.ns, &self.reference, &self.log, channels, speed)
    }
}

/// A running `lcm-logger`.
struct Logger(KillOnDrop);

impl Logger {
    /// Stops it as Ctrl-C would (its log then ends whole) and waits.
    fn finish(mut self) {
        Command::new("kill")
            .args(["-INT", &self.0.0.id().to_string()])
            .status()
            .unwrap();
        assert!(self.0.0.wait().unwrap().success(), "lcm-logger failed");
    }
}

/// Plays what a guard takes (poses, images and the logged commands) in
/// real time.
fn play_to_the_guard(net: &Net) {
    assert!(
        net.play("POSE|RANGE_IMAGE.*|STEERING_COMMAND", 1.0)
            .wait()
            .unwrap()
            .success()
    );
}

/// Every input of the pipeline, as `lcm-logplayer -e` takes it.
const INPUTS: &str = "POSE|RANGE_IMAGE.*|WAYPOINTS";

/// Checks `received` against the lock-step replay of `log`.
fn assert_reproduces(label: &str, received: &Received, log: &Path, config: &Config) {
    let expected = lockstep(log, config);
    let live = by_time(received);
    // From the first cycle driven on votes (the live arbiter stops until an
    // image has been evaluated; see the threaded test).
    let first = received
        .iter()
        .find(|(_, c)| !c.is_stop())
        .map(|(_, c)| c.utime)
        .unwrap_or_else(|| panic!("{label}: never drove"));
    let first_s = (first - SIM_EPOCH_US) as f64 * 1e-6;
    assert!(first_s <= 0.31, "{label}: first drove at {first_s:.2} s");
    let a = Agreement::of(&live, &expected, first_s, LOG_S);
    eprintln!(
        "{label} vs lock-step: {} of {} cycles agree ({:.2}%), {} missing",
        a.agreeing,
        a.compared + a.missing.len(),
        a.percent(),
        a.missing.len()
    );
    // Reproducing lock-step, every cycle lock-step decides is decided, the
    // same way.
    assert!(
        a.compared >= COMPARED_AT_LEAST,
        "{label}: {} cycles",
        a.compared
    );
    let missing: Vec<String> = a
        .missing
        .iter()
        .map(|t| format!("{:.2} s", (t - SIM_EPOCH_US) as f64 * 1e-6))
        .collect();
    assert!(
        missing.is_empty(),
        "{label}: cycles not decided: {missing:?}"
    );
    // A cycle may differ only where the live safety watchdog stopped the
    // vehicle (poses or images late on a loaded machine: it has no
    // counterpart in lock-step); every decision on votes is lock-step's.
    let (from, to) = (
        SIM_EPOCH_US + (first_s * 1e6) as i64,
        SIM_EPOCH_US + (LOG_S * 1e6) as i64,
    );
    let differing: Vec<String> = expected
        .range(from..to)
        .filter_map(|(t, e)| {
            let got = live.get(t)?;
            let same = got.arc_index == e.arc_index && (got.speed_mps - e.speed_mps).abs() < 1e-6;
            (!same && !got.is_stop()).then(|| {
                format!(
                    "{:.2} s: arc {:?} vs {:?}",
                    (t - SIM_EPOCH_US) as f64 * 1e-6,
                    got.arc_index,
                    e.arc_index
                )
            })
        })
        .collect();
    assert!(
        differing.is_empty(),
        "{label}: decided otherwise: {differing:?}"
    );
    assert!(a.percent() >= 95.0, "{label}: {:.2}% agree", a.percent());
    // The last command is the final stop.
    assert!(
        received.last().unwrap().1.is_stop(),
        "{label}: last command drives"
    );
}

#[test]
fn distributed_nodes_reproduce_the_lockstep_replay_over_udp_multicast() {
    let Some(net) = Net::erim("distributed", config(SensorPreset::Erim, true)) else {
        return;
    };
    assert_distributed_reproduces(&net);
}

/// 020 item 3: `arcnav node perception` takes the ERIM's images in slices
/// of 16 rows (`range_slice_t`), and the distributed nodes still reproduce
/// lock-step replay of the log.
#[test]
fn distributed_nodes_reproduce_the_lockstep_replay_of_streamed_slices() {
    let config = sliced(config(SensorPreset::Erim, true));
    let Some(net) = Net::setup("distributed-slices", config, |config| {
        let mut log_config = config.clone();
        log_config.live.reproduce_lockstep = false;
        sim_log_of(&log_config)
    }) else {
        return;
    };
    // Every decision: one of 199 took the arc next to lock-step's while
    // the behaviour nodes read the map's patch and elevation cell sizes as
    // their `float`s widened (0.4000000059604645 m for 0.4), a hair larger
    // than the map's own.
    assert_distributed_reproduces(&net);
}

/// Runs `nodes` (name, arguments) as processes while the log's inputs
/// play at real time, until the last cycle is decided; what they printed
/// and the commands heard.
fn run_nodes(net: &Net, nodes: &[(&str, &[&str])]) -> (String, Received) {
    let last = last_cycle(&net.log, &net.config);
    recording_watched(&net.ns, |heard| {
        let procs: Vec<Proc> = nodes
            .iter()
            .map(|(name, args)| net.arcnav(name, args))
            .collect();
        procs.iter().for_each(Proc::wait_ready);
        assert!(net.play(INPUTS, 1.0).wait().unwrap().success());
        heard.wait_for_cycle(last, Duration::from_secs(10));
        procs.iter().for_each(|p| p.signal("TERM"));
        let mut printed = String::new();
        for p in procs {
            let (code, out) = p.finish();
            assert_eq!(code, Some(0));
            printed.push_str(&out);
        }
        printed
    })
}

fn assert_distributed_reproduces(net: &Net) {
    let nodes: [(&str, &[&str]); 5] = [
        ("perception", &["node", "perception", "--stats"]),
        ("localmap", &["node", "localmap", "--stats"]),
        (
            "obstacle_avoidance",
            &["node", "behaviour", "obstacle_avoidance", "--stats"],
        ),
        ("route", &["node", "behaviour", "route", "--stats"]),
        ("arbiter", &["node", "arbiter", "--stats"]),
    ];
    let (stats, received) = run_nodes(net, &nodes);
    eprintln!("{stats}");
    assert_reproduces(
        &format!("distributed ({})", net.log.display()),
        &received,
        &net.log,
        &net.config,
    );
    // Every node reported its figures.
    for node in [
        "perception",
        "localmap",
        "behaviour obstacle_avoidance",
        "arbiter",
    ] {
        assert!(stats.contains(node), "no {node} row in:\n{stats}");
    }
}

/// The `DECISION`s of `log`, by the time of their command.
fn decisions(log: &Path) -> BTreeMap<Utime, decision_t> {
    let mut reader = LogReader::open(log).unwrap();
    let mut out = BTreeMap::new();
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel == channels::DECISION {
            let d = decision_t::decode(&event.data).unwrap();
            out.insert(d.utime, d);
        }
    }
    out
}

/// Issue 66: nodes as processes stop before a wall of rocks (a lane too
/// narrow to turn in, closed ahead: tests/worlds/rock_wall.toml), and the
/// run's log, as `lcm-logger` records it, says why as the single-process
/// run's does: each stop's `DECISION` has the same cause, reason and
/// vetoing behaviour with its cell; `arcnav render` of either log names
/// them alike.
#[test]
fn a_distributed_run_says_why_it_stopped_as_one_process_does() {
    let Some(net) = Net::setup("why-stopped", config(SensorPreset::Erim, true), |config| {
        let mut log_config = config.clone();
        log_config.live.reproduce_lockstep = false;
        sim_log_on("rock_wall", &log_config)
    }) else {
        return;
    };
    let single = decisions(&net.log);
    let (first_stop, expected) = single
        .iter()
        .find(|(_, d)| {
            matches!(
                d.cause,
                decision_t::ALL_ARCS_VETOED | decision_t::NO_ACCEPTABLE_ARC
            )
        })
        .expect("the single-process run stops before the wall");
    assert!(
        expected.vetoer.iter().any(|v| v == "obstacle_avoidance")
            && expected.has_cell.iter().any(|&c| c),
        "{}",
        expected.reason
    );
    let recorded = temp_dir("why-stopped").join("distributed.lcm");
    let logger = net.logger(&recorded);
    let nodes: [(&str, &[&str]); 5] = [
        ("perception", &["node", "perception"]),
        ("localmap", &["node", "localmap"]),
        (
            "obstacle_avoidance",
            &["node", "behaviour", "obstacle_avoidance"],
        ),
        ("route", &["node", "behaviour", "route"]),
        ("arbiter", &["node", "arbiter"]),
    ];
    run_nodes(&net, &nodes);
    logger.finish();
    let distributed = decisions(&recorded);
    let got = distributed
        .get(first_stop)
        .unwrap_or_else(|| panic!("no DECISION at the stop's time in {}", recorded.display()));
    eprintln!(
        "stop at {:.1} s: single process says {:?}; distributed says {:?}",
        (first_stop - SIM_EPOCH_US) as f64 * 1e-6,
        expected.reason,
        got.reason
    );
    assert_eq!(got, expected);
    // Every stop the single process made, for a cause, the nodes made for
    // the same one.
    let stops = single
        .iter()
        .filter(|(_, d)| d.cause != decision_t::DRIVE)
        .filter(|(t, _)| distributed.contains_key(t))
        .count();
    let same = single
        .iter()
        .filter(|(t, d)| distributed.get(t).is_some_and(|g| g.cause == d.cause))
        .count();
    assert!(stops >= 5, "{stops} stops compared");
    assert!(
        same * 100 >= distributed.len().min(single.len()) * 95,
        "{same} agree"
    );
    // `arcnav render` of both logs at the stop names them alike.
    let at = format!("{:.2}", (first_stop - SIM_EPOCH_US) as f64 * 1e-6);
    let mut logged = Vec::new();
    for log in [&net.log, &recorded] {
        let picture = recorded.with_extension(format!("{}.png", logged.len()));
        let (code, stdout, stderr) = arcnav_testkit::output_of(
            env!("CARGO_BIN_EXE_arcnav"),
            &[
                "render",
                log.to_str().unwrap(),
                "--at",
                &at,
                "--config",
                &net.file,
                "--out",
                picture.to_str().unwrap(),
            ],
        );
        assert_eq!(code, 0, "{stdout}\n{stderr}");
        let line = stdout
            .lines()
            .find(|l| l.starts_with("as logged"))
            .unwrap_or_else(|| panic!("{stdout}"))
            .to_owned();
        assert!(line.contains(&expected.reason), "{line}\n{stdout}");
        logged.push(line);
    }
    assert_eq!(logged[0], logged[1]);
}

/// The ERIM configuration of a pipeline blind to `box_ahead`'s box:
/// obstacle avoidance and the route out of the vote, goal seeking alone
/// steering at the waypoint behind it.
fn blind_to_the_box() -> Config {
    let mut blind = config(SensorPreset::Erim, false);
    for (name, weight) in [
        ("obstacle_avoidance", 0.0),
        ("route", 0.0),
        ("goal_seeking", 1.0),
    ] {
        blind.arbiter.weights.insert(name.into(), weight);
    }
    blind.arbiter.required.clear();
    blind
}

/// The network for a test of the guard: the log of a pipeline blind to
/// `box_ahead`'s box (its own guard off) driving into it, the logged
/// vehicle's x by pose time, and where it hit the box.
fn box_net(tag: &str) -> Option<(Net, BTreeMap<Utime, f64>, f64)> {
    let mut blind = blind_to_the_box();
    blind.guard.enabled = false;
    let net = Net::setup(tag, config(SensorPreset::Erim, false), |_| {
        sim_log_on("box_ahead", &blind)
    })?;
    let xs = pose_xs(&net.log);
    let hit_x = *xs.values().last()?;
    Some((net, xs, hit_x))
}

/// The JSON lines of a command's standard output (`--print`).
fn json_lines(stdout: &str) -> Vec<serde_json::Value> {
    stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The vehicle's x by pose time in `log`.
fn pose_xs(log: &Path) -> BTreeMap<Utime, f64> {
    let mut xs = BTreeMap::new();
    let mut reader = LogReader::open(log).unwrap();
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel == channels::POSE {
            let pose = pose_t::decode(&event.data).unwrap();
            xs.insert(pose.utime, pose.position[0]);
        }
    }
    xs
}

/// Issue 65: `arcnav vehicle` with the guard (on by default), in a
/// network namespace, is played a log whose commands drive straight at a
/// 1 m box (obstacle avoidance and the route weighted 0, the sim's guard
/// off: the logged vehicle hit it) while its images show the box. The
/// bridge stops the vehicle (executed speed 0) before the box, says why
/// (JSON `guard_reason`, its log, `GUARD_STATUS` on the bus), and counts it.
#[test]
fn the_vehicle_side_guard_stops_commands_that_drive_at_a_box_it_sees() {
    let Some((net, xs, hit_x)) = box_net("vehicle-guard") else {
        return;
    };
    let heard_guard = Arc::new(Mutex::new(Vec::new()));
    let recorded = temp_dir("vehicle-guard").join("bus.lcm");
    let logger = net.logger(&recorded);
    let vehicle = net.arcnav("vehicle", &["vehicle", "--print", "--stats"]);
    vehicle.wait_ready();
    let (_, ()) = listening(
        &net.ns,
        |stop, ready| {
            let mut lcm = Lcm::new("").unwrap();
            lcm.subscribe(channels::GUARD_STATUS);
            ready.send(()).unwrap();
            while !stop.load(Ordering::Relaxed) {
                if let Some(m) = lcm.recv_timeout(Duration::from_millis(20)).unwrap() {
                    let msg = arcnav_bus::lcmtypes::guard_status_t::decode(&m.data).unwrap();
                    heard_guard.lock().unwrap().push(msg);
                }
            }
        },
        || {
            play_to_the_guard(&net);
        },
    );
    vehicle.signal("TERM");
    let stderr = vehicle.stderr.lock().unwrap().clone();
    let (code, stdout) = vehicle.finish();
    assert_eq!(code, Some(0), "{stderr}");
    let ticks = json_lines(&stdout);
    // The first stop for the box, not for data still missing at the start.
    let stop = ticks
        .iter()
        .find(|t| {
            t["guard"] == "stop"
                && t["guard_reason"]
                    .as_str()
                    .is_some_and(|r| r.starts_with("obstacle"))
        })
        .unwrap_or_else(|| panic!("the guard never stopped for the box:\n{stderr}"));
    assert_eq!(stop["speed_mps"], 0.0);
    assert_eq!(stop["state"], "following");
    let at = stop["command_utime"].as_i64().unwrap();
    let x = *xs.range(..=at).next_back().unwrap().1;
    eprintln!(
        "guard stop at x = {x:.1} m (the logged vehicle hit the box at x = {hit_x:.1} m): {}",
        stop["guard_reason"]
    );
    assert!(
        x < hit_x - 1.0,
        "stopped at x = {x:.1} m, the box hit at {hit_x:.1} m"
    );
    // From then on the guard never lets a command through as it is: the
    // vehicle stands, or creeps at the speed from which it stops short of
    // the box by the margin (a slow).
    let wall = stop["wall_us"].as_i64().unwrap();
    let through: Vec<_> = ticks
        .iter()
        .filter(|t| t["wall_us"].as_i64().unwrap() >= wall && t["state"] == "following")
        .filter(|t| t["guard"] == "clear" || (t["guard"] != "slow" && t["speed_mps"] != 0.0))
        .collect();
    assert!(
        through.is_empty(),
        "let through after the stop: {through:?}"
    );
    assert!(stderr.contains("guard: STOP: obstacle"), "{stderr}");
    let heard = heard_guard.lock().unwrap();
    assert!(
        heard
            .iter()
            .any(|g| g.verdict == arcnav_bus::lcmtypes::guard_status_t::STOP
                && g.reason.starts_with("obstacle")),
        "{} GUARD_STATUS heard",
        heard.len()
    );
    assert!(stdout.contains("guard_interventions"), "{stdout}");
    // `arcnav render` of the bus's log at that command says what the guard did.
    logger.finish();
    let first_pose = *xs.keys().next().unwrap();
    let (code, out, err) = arcnav_testkit::output_of(
        env!("CARGO_BIN_EXE_arcnav"),
        &[
            "render",
            recorded.to_str().unwrap(),
            "--at",
            &format!("{:.3}", (at - first_pose) as f64 * 1e-6),
            "--config",
            &net.file,
            "--out",
            recorded.with_extension("png").to_str().unwrap(),
        ],
    );
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("guard         STOP: obstacle"), "{out}");
}

/// `arcnav node guard` between the arbiter and the vehicle: the same log
/// of commands driving at a box (obstacle avoidance out of the vote), the
/// guard a node of its own, the vehicle (its own guard off) following
/// STEERING_COMMAND_GUARDED: it is stopped before the box.
#[test]
fn the_guard_node_stops_a_vehicle_that_follows_it_short_of_a_box() {
    let Some((net, xs, hit_x)) = box_net("node-guard") else {
        return;
    };
    let mut unguarded = config(SensorPreset::Erim, false);
    unguarded.guard.enabled = false;
    let vehicle_file = write_config(&unguarded, &temp_dir("node-guard-vehicle"));
    let guard = net.arcnav("guard", &["node", "guard", "--stats"]);
    let vehicle = Proc::arcnav(
        &net.ns,
        "vehicle",
        &[
            "vehicle",
            "--print",
            "--commands",
            channels::STEERING_COMMAND_GUARDED,
            "--config",
            &vehicle_file,
        ],
    );
    guard.wait_ready();
    vehicle.wait_ready();
    play_to_the_guard(&net);
    vehicle.signal("TERM");
    guard.signal("TERM");
    let guard_err = guard.stderr.lock().unwrap().clone();
    let (code, guard_out) = guard.finish();
    assert_eq!(code, Some(0), "{guard_err}");
    let vehicle_err = vehicle.stderr.lock().unwrap().clone();
    let (code, stdout) = vehicle.finish();
    assert_eq!(code, Some(0), "{vehicle_err}");
    assert!(guard_err.contains("guard: STOP: obstacle"), "{guard_err}");
    assert!(guard_out.contains("guard_interventions"), "{guard_out}");
    let ticks = json_lines(&stdout);
    // The vehicle followed moving commands, then a stop before the box.
    let moving = ticks
        .iter()
        .position(|t| t["state"] == "following" && t["speed_mps"].as_f64().unwrap() > 0.5)
        .unwrap_or_else(|| panic!("never moved:\n{vehicle_err}\n{guard_err}"));
    let stop = ticks[moving..]
        .iter()
        .find(|t| t["state"] == "following" && t["speed_mps"] == 0.0)
        .unwrap_or_else(|| panic!("never stopped:\n{guard_err}"));
    assert_eq!(stop["guard"], "off", "the vehicle's own guard is off");
    let at = stop["command_utime"].as_i64().unwrap();
    let x = *xs.range(..=at).next_back().unwrap().1;
    eprintln!(
        "stopped by the guard node at x = {x:.1} m (the logged vehicle hit the box at {hit_x:.1} m)"
    );
    assert!(
        x < hit_x - 1.0,
        "stopped at x = {x:.1} m, the box hit at {hit_x:.1} m"
    );
}

/// The guard inside `arcnav run`: a pipeline blind to the box (obstacle
/// avoidance and the route out of the vote) steers at it; the run's own
/// guard turns its commands into stops before the box, and the DECISION
/// says `guard: obstacle …`.
#[test]
fn arcnav_run_with_its_guard_stops_a_blind_pipeline_short_of_a_box() {
    let blind = blind_to_the_box();
    let Some(net) = Net::setup("run-guard", blind.clone(), |_| {
        let mut unguarded = blind.clone();
        unguarded.guard.enabled = false;
        sim_log_on("box_ahead", &unguarded)
    }) else {
        return;
    };
    let xs = pose_xs(&net.log);
    let hit_x = *xs.values().last().unwrap();
    let recorded = temp_dir("run-guard").join("bus.lcm");
    let logger = net.logger(&recorded);
    let run = net.arcnav("run", &["run", "--stats"]);
    run.wait_ready();
    assert!(net.play(INPUTS, 1.0).wait().unwrap().success());
    run.signal("TERM");
    let stderr = run.stderr.lock().unwrap().clone();
    let (code, stats) = run.finish();
    assert_eq!(code, Some(0), "{stderr}");
    logger.finish();
    let said = decisions(&recorded);
    let (&at, stop) = said
        .iter()
        .find(|(_, d)| d.cause == decision_t::GUARD && d.reason.contains("obstacle"))
        .unwrap_or_else(|| panic!("no DECISION says the guard stopped it:\n{stats}\n{stderr}"));
    let mut speeds = BTreeMap::new();
    let mut reader = LogReader::open(&recorded).unwrap();
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel == channels::STEERING_COMMAND {
            let c = steering_command_t::decode(&event.data).unwrap();
            speeds.insert(c.utime, c.speed);
        }
    }
    assert!(speeds[&at] < 1.0, "{} m/s: {}", speeds[&at], stop.reason);
    let x = *xs.range(..=at).next_back().unwrap().1;
    eprintln!(
        "arcnav run's guard: {} at x = {x:.1} m (the box hit at {hit_x:.1} m)",
        stop.reason
    );
    assert!(
        x < hit_x - 1.0,
        "at x = {x:.1} m, the box hit at {hit_x:.1} m"
    );
    assert!(stats.contains("guard_interventions"), "{stats}");
}

/// Issue 62, live: `arcnav run` fed a drive round a closed ring of trench
/// (the waypoint on the island inside) gives the waypoint up, stands,
/// says on the bus which behaviour asked to stop, and counts it in
/// `--stats`. The simulated run ended `unreachable` 5 s after its route
/// last found no way; live, `unreachable_after_s` is 2 s, so that the
/// same evidence is judged before the drive's inputs end. Played at 4×.
#[test]
fn arcnav_run_gives_up_a_waypoint_no_route_reaches_and_says_who_stopped() {
    // The whole drive (it ends `unreachable` at about 61 s).
    let mut drive = config(SensorPreset::Erim, false);
    drive.sim.time_limit_s = 300.0;
    let mut live = drive.clone();
    live.mission.unreachable_after_s = 2.0;
    let Some(net) = Net::setup("run-unreachable", live, |_| {
        sim_log_on("barriers/ring_trench", &drive)
    }) else {
        return;
    };
    let recorded = temp_dir("run-unreachable").join("bus.lcm");
    let logger = net.logger(&recorded);
    let run = net.arcnav("run", &["run", "--stats"]);
    run.wait_ready();
    assert!(net.play(INPUTS, 4.0).wait().unwrap().success());
    run.signal("TERM");
    let stderr = run.stderr.lock().unwrap().clone();
    let (code, stats) = run.finish();
    assert_eq!(code, Some(0), "{stderr}");
    logger.finish();
    assert!(
        stats.contains("unreachable_waypoints 1") || stats.contains("\"unreachable_waypoints\":1"),
        "{stats}"
    );
    let said = decisions(&recorded);
    let (&at, _) = said
        .iter()
        .find(|(_, d)| d.cause == decision_t::SPEED_LIMITED && d.reason == "route asked to stop")
        .unwrap_or_else(|| panic!("no DECISION says the route asked to stop:\n{stats}\n{stderr}"));
    // From then on it stands.
    let mut reader = LogReader::open(&recorded).unwrap();
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel == channels::STEERING_COMMAND {
            let c = steering_command_t::decode(&event.data).unwrap();
            assert!(
                c.utime < at || c.speed == 0.0,
                "{} m/s at {} after the stop at {at}",
                c.speed,
                c.utime
            );
        }
    }
    assert!(
        stderr.contains("no route to the waypoint"),
        "the route warns: {stderr}"
    );
}

#[test]
fn arcnav_run_reproduces_the_lockstep_replay_over_udp_multicast() {
    let Some(net) = Net::erim("run", config(SensorPreset::Erim, true)) else {
        return;
    };
    let last = last_cycle(&net.log, &net.config);
    let (stats, received) = recording_watched(&net.ns, |heard| {
        let run = net.arcnav("run", &["run", "--stats"]);
        run.wait_ready();
        assert!(net.play(INPUTS, 1.0).wait().unwrap().success());
        heard.wait_for_cycle(last, Duration::from_secs(10));
        run.signal("TERM");
        let (code, out) = run.finish();
        assert_eq!(code, Some(0));
        out
    });
    eprintln!("{stats}");
    assert_reproduces("arcnav run", &received, &net.log, &net.config);
    assert!(stats.contains("image arrival→command"), "{stats}");
}

/// Rewrites `source` with the reference LCM's own log writer (Python), as a
/// logger on the vehicle would have written it: each range image logged
/// 0.1 s after its capture, the events in the order they were logged.
fn rewritten_by_the_reference(reference: &LcmReference, source: &Path, target: &Path) {
    const SCRIPT: &str = r#"
import sys, lcm
events = []
for i, e in enumerate(lcm.EventLog(sys.argv[1], "r")):
    late = 100000 if e.channel.startswith("RANGE_IMAGE") else 0
    events.append((e.timestamp + late, i, e.channel, e.data))
events.sort()
out = lcm.EventLog(sys.argv[2], "w", overwrite=True)
for t, _, channel, data in events:
    out.write_event(t, channel, data)
out.close()
"#;
    let status = reference
        .python()
        .args(["-c", SCRIPT])
        .arg(source)
        .arg(target)
        .status()
        .unwrap();
    assert!(status.success(), "the reference writer failed");
}

/// A log the reference LCM wrote, images 0.1 s behind their capture as a
/// logger sees them, played by `lcm-logplayer` into `arcnav run`: perception
/// evaluates every image as it comes, and the vehicle drives while it plays.
#[test]
fn a_log_written_by_the_reference_lcm_drives_the_vehicle_live() {
    let Some(mut net) = Net::erim("reference-log", config(SensorPreset::Erim, false)) else {
        return;
    };
    let log = temp_dir("live-reference-log").join("reference.lcm");
    rewritten_by_the_reference(&net.reference, &net.log, &log);
    net.log = log;
    let ((played, stats), received) = recording(&net.ns, || {
        let run = net.arcnav("run", &["run", "--stats"]);
        run.wait_ready();
        let started = Instant::now();
        assert!(net.play(INPUTS, 1.0).wait().unwrap().success());
        let played = (started, Instant::now());
        run.signal("TERM");
        let (code, out) = run.finish();
        assert_eq!(code, Some(0));
        (played, out)
    });
    eprintln!("{stats}");
    let driving = received
        .iter()
        .filter(|(at, c)| (played.0..played.1).contains(at) && !c.is_stop())
        .count();
    // LOG_S of log at 10 commands a second: it drove from the first images
    // on (three quarters of the cycles, at least).
    assert!(
        driving >= LOG_CYCLES * 3 / 4,
        "{driving} commands drove while the log played"
    );
    let perception = stats
        .lines()
        .find(|l| l.starts_with("perception"))
        .unwrap_or_else(|| panic!("no perception row in:\n{stats}"));
    assert!(perception.contains("late 0"), "{perception}");
    assert!(perception.contains("replaced_by_newer 0"), "{perception}");
}

/// On a multicast URL whose traffic leaves the host, `arcnav run` says what
/// is open; with ttl=0 it says nothing of the kind.
#[test]
fn multicast_beyond_the_host_is_warned_about() {
    let _serial = serial();
    let Some(ns) = NetNs::require("ttl-warning") else {
        return;
    };
    for (url, warned) in [
        ("udpm://239.255.76.67:7667?ttl=1", true),
        ("udpm://239.255.76.67:7667?ttl=0", false),
    ] {
        let run = Proc::arcnav(&ns, "run", &["run", "--lcm", url, "--duration", "0.3"]);
        run.wait_ready();
        let stderr = Arc::clone(&run.stderr);
        let (code, _) = run.finish();
        assert_eq!(code, Some(0));
        let stderr = stderr.lock().unwrap();
        assert_eq!(
            stderr.contains("multicast leaves this host"),
            warned,
            "{url}:\n{stderr}"
        );
    }
}

/// When the first command after `after` that is a stop arrived, and whether
/// every command from then on (until `until`) is a stop.
fn stop_after(received: &Received, after: Instant, until: Instant) -> Option<(Duration, bool)> {
    let (at, _) = received.iter().find(|(t, c)| *t >= after && c.is_stop())?;
    let all = received
        .iter()
        .filter(|(t, _)| t >= at && *t <= until)
        .all(|(_, c)| c.is_stop());
    Some((at.duration_since(after), all))
}

#[test]
fn killing_obstacle_avoidance_makes_the_arbiter_stop_within_its_timeout() {
    let Some(net) = Net::erim("kill-oa", config(SensorPreset::Erim, false)) else {
        return;
    };
    let timeout = net.config.arbiter.vote_timeout_s;
    let ((killed, end), received) = recording(&net.ns, || {
        let procs = vec![
            net.arcnav("perception", &["node", "perception"]),
            net.arcnav("localmap", &["node", "localmap"]),
            net.arcnav("route", &["node", "behaviour", "route"]),
            net.arcnav("arbiter", &["node", "arbiter"]),
        ];
        let oa = net.arcnav(
            "obstacle_avoidance",
            &["node", "behaviour", "obstacle_avoidance"],
        );
        procs.iter().chain([&oa]).for_each(Proc::wait_ready);
        let mut feeder = net.play(INPUTS, 1.0);
        std::thread::sleep(Duration::from_secs(4));
        oa.signal("KILL");
        let killed = Instant::now();
        std::thread::sleep(Duration::from_secs_f64(timeout + 2.0));
        let end = Instant::now();
        let _ = feeder.kill();
        let _ = feeder.wait();
        let _ = oa.finish();
        for p in procs {
            p.signal("TERM");
            assert_eq!(p.finish().0, Some(0));
        }
        (killed, end)
    });
    let drove = received
        .iter()
        .filter(|(t, _)| *t < killed)
        .any(|(_, c)| !c.is_stop());
    assert!(drove, "the vehicle never drove before the kill");
    let (delay, held) = stop_after(&received, killed, end).expect("no stop after the kill");
    eprintln!(
        "obstacle avoidance killed: stop after {:.0} ms (vote timeout {:.0} ms)",
        delay.as_secs_f64() * 1e3,
        timeout * 1e3
    );
    // Its last votes are at most one cycle old at the kill; the arbiter
    // stops once they are older than the timeout.
    assert!(
        delay.as_secs_f64() <= timeout + 0.3,
        "stopped {:.2} s after the kill",
        delay.as_secs_f64()
    );
    assert!(
        delay.as_secs_f64() >= timeout - 0.25,
        "stopped before the timeout"
    );
    assert!(held, "drove again without obstacle avoidance");
}

#[test]
fn a_silent_pose_stream_stops_the_vehicle_and_sigterm_publishes_a_final_stop() {
    let Some(net) = Net::erim("poses", config(SensorPreset::Erim, false)) else {
        return;
    };
    let timeout = net.config.live.pose_timeout_s;
    let ((silenced, terminated, end), received) = recording(&net.ns, || {
        let run = net.arcnav("run", &["run"]);
        run.wait_ready();
        // Poses and images from two players: only the poses stop.
        let mut images = net.play("RANGE_IMAGE.*|WAYPOINTS", 1.0);
        let mut poses = net.play("POSE", 1.0);
        std::thread::sleep(Duration::from_secs(4));
        let _ = poses.kill();
        let silenced = Instant::now();
        let _ = poses.wait();
        std::thread::sleep(Duration::from_secs(2));
        let _ = images.kill();
        let _ = images.wait();
        let terminated = Instant::now();
        run.signal("TERM");
        let (code, _) = run.finish();
        assert_eq!(code, Some(0), "arcnav run exits 0 on SIGTERM");
        (silenced, terminated, Instant::now())
    });
    let (delay, held) = stop_after(&received, silenced, terminated).expect("no stop");
    eprintln!(
        "poses silenced: stop after {:.0} ms (pose timeout {:.0} ms)",
        delay.as_secs_f64() * 1e3,
        timeout * 1e3
    );
    assert!(delay.as_secs_f64() <= timeout + 0.25, "{delay:?}");
    assert!(held);
    // Stop is repeated at the command rate while the poses are silent.
    let repeated = received
        .iter()
        .filter(|(t, _)| *t > silenced + delay && *t <= silenced + delay + Duration::from_secs(1))
        .count();
    assert!(repeated >= 8, "{repeated} stops in the second after");
    // SIGTERM: a final stop, after which nothing comes.
    let last = received.iter().rfind(|(t, _)| *t >= terminated);
    let (at, command) = last.expect("no final stop after SIGTERM");
    assert!(command.is_stop());
    assert!(*at <= end);
}

#[test]
fn when_arcnav_dies_the_vehicle_watchdog_stops_the_vehicle() {
    let Some(net) = Net::erim("sigkill", config(SensorPreset::Erim, false)) else {
        return;
    };
    let (killed, received) = recording(&net.ns, || {
        let run = net.arcnav("run", &["run"]);
        run.wait_ready();
        let mut feeder = net.play(INPUTS, 1.0);
        std::thread::sleep(Duration::from_secs(3));
        // No chance to publish a final stop.
        run.signal("KILL");
        let killed = Instant::now();
        let _ = run.finish();
        let _ = feeder.kill();
        let _ = feeder.wait();
        killed
    });
    let last = received.last().expect("no commands");
    assert!(
        !last.1.is_stop(),
        "SIGKILL should leave a driving command last"
    );
    // The vehicle side: commands by receive time into its watchdog.
    let start = received[0].0;
    let us = |t: Instant| t.duration_since(start).as_micros() as i64;
    let mut watchdog = CommandWatchdog::new(300_000);
    for (t, command) in &received {
        watchdog.on_command(us(*t), *command);
    }
    assert!(!watchdog.command_at(us(last.0) + 50_000).is_stop());
    assert!(watchdog.command_at(us(killed) + 400_000).is_stop());
    assert_eq!(watchdog.trips, 1);
}

#[test]
fn a_flood_of_large_range_images_keeps_memory_bounded_and_counts_drops() {
    // 128×2048 images (1 MiB each) at ten times their 10 Hz rate, four
    // times over, then at a hundred times: more than perception can take.
    let mut short = config(SensorPreset::Lidar128, false);
    short.sim.time_limit_s = 3.0;
    let Some(net) = Net::setup("flood", short, flood_log) else {
        return;
    };
    let published = LogReader::open(&net.log)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .channel
                .starts_with(channels::RANGE_IMAGE)
        })
        .count() as u64;
    let json = temp_dir("live-flood-report").join("run.json");
    let run = net.arcnav("run", &["run", "--json", json.to_str().unwrap()]);
    run.wait_ready();
    std::thread::sleep(Duration::from_millis(300));
    let baseline = run.rss_kb().unwrap();
    let mut peak = baseline;
    const ROUNDS: u64 = 5;
    for round in 0..ROUNDS {
        let speed = if round + 1 < ROUNDS { 10.0 } else { 100.0 };
        let mut player = net.play("POSE|RANGE_IMAGE.*", speed);
        while player.try_wait().unwrap().is_none() {
            peak = peak.max(run.rss_kb().unwrap_or(0));
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    std::thread::sleep(Duration::from_millis(500));
    peak = peak.max(run.rss_kb().unwrap_or(0));
    run.signal("TERM");
    assert_eq!(run.finish().0, Some(0));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let node = |name: &str| {
        report["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["node"] == name)
            .unwrap()
            .clone()
    };
    let counter = |node: &serde_json::Value, name: &str| {
        node["counters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c[0] == name)
            .map_or(0, |c| c[1].as_u64().unwrap())
    };
    let (io, perception) = (node("io"), node("perception"));
    let received = counter(&io, "images");
    let incomplete = counter(&io, "incomplete_messages");
    let evaluated = perception["handled"].as_u64().unwrap();
    let replaced = counter(&perception, "replaced_by_newer");
    let unplaced = counter(&perception, "no_pose")
        + counter(&perception, "invalid")
        + counter(&perception, "out_of_order");
    // Waiting for a pose when the log started over, or when the run ended
    // (1 of 88 in a CI run, 2026-12-07: left out, the sum fell one short).
    let abandoned = counter(&perception, "clock_restart")
        + counter(&perception, "too_many_sensors")
        + counter(&perception, "waiting_at_end");
    let flooded_mib = ROUNDS * published;
    eprintln!(
        "flood: {} images ({} MiB) published, {received} received ({incomplete} incomplete), \
         {evaluated} evaluated, {replaced} replaced by newer, {unplaced} unplaceable, \
         {abandoned} left waiting for a pose; RSS {baseline} kB before, peak {peak} kB",
        ROUNDS * published,
        flooded_mib
    );
    // Every received image is evaluated or counted; none is lost silently.
    assert_eq!(evaluated + replaced + unplaced + abandoned, received);
    assert!(
        abandoned <= ROUNDS,
        "{abandoned} abandoned in {ROUNDS} rounds"
    );
    // Perception fell behind in the last round and skipped to the newest.
    assert!(replaced > 0, "no image replaced by a newer one");
    // Each round starts the log over: the executor follows, placing every
    // image but the first of a round (no pose before it yet), and goes on
    // evaluating after the first round. How many it evaluates is the
    // host's speed (about half on an idle two-core host, 47 of 154 in a CI
    // run beside a simulation, 2026-11-28), so no share is asserted.
    assert!(
        unplaced <= ROUNDS,
        "{unplaced} unplaceable in {ROUNDS} rounds"
    );
    assert!(
        evaluated > published,
        "{evaluated} of {received} evaluated, {published} a round"
    );
    // What did not arrive whole is counted by the transport (or never left
    // the kernel: at most the socket buffer's worth per round).
    assert!(received + incomplete <= ROUNDS * published);
    // Bounded: far less than what was pushed through.
    let grown_mib = (peak.saturating_sub(baseline)) / 1024;
    assert!(
        grown_mib < 64 && grown_mib < flooded_mib / 4,
        "RSS grew by {grown_mib} MiB during a {flooded_mib} MiB flood"
    );
}

/// A lidar128 log of `config.sim.time_limit_s` seconds.
fn flood_log(config: &Config) -> PathBuf {
    static LOG: OnceLock<PathBuf> = OnceLock::new();
    LOG.get_or_init(|| {
        let path = temp_dir("live-flood-log").join("lidar128.lcm");
        let world = Arc::new(World::embedded("short_course").unwrap().unwrap());
        let options = MissionOptions {
            log: Some(path.clone()),
            ..MissionOptions::default()
        };
        run_mission(&config.resolved().unwrap(), world, &options, &mut |_| {}).unwrap();
        path
    })
    .clone()
}

// ---------------------------------------------------------------------------
// An attacker on an authenticated bus.

/// A group key file, readable by its owner only.
fn key_file(dir: &Path, fill: u8) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join("group.key");
    let hex: String = (0..32).map(|i| format!("{:02x}", fill ^ i)).collect();
    std::fs::write(&path, hex).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    path
}

/// What the attacker sent, by kind.
type Sent = BTreeMap<&'static str, u64>;

/// An attacker inside the namespace until `stop`. It has no key but can
/// read and write the bus, and holds a second, unconfigured behaviour's
/// process that does have the group key (`insider`). Every 50 ms it sends
/// forged commands (unsigned and signed with another key: full left at
/// 7.5 m/s) and obstacle-avoidance votes vetoing every arc (unsigned and
/// with another key), the same vetoes from the key holder as
/// ARC_VOTES_INTRUDER, and as obstacle avoidance stamped 10 s ahead; every
/// authentic command and vote it sees it replays at once and 1.5 s later,
/// and sends each command again with its speed changed and its tag kept.
fn attack(stop: &AtomicBool, insider: AuthPolicy) -> Sent {
    use arcnav_bus::lcmtypes::arc_votes_t;
    use std::collections::{HashSet, VecDeque};
    const OA: &str = "ARC_VOTES_OBSTACLE_AVOIDANCE";
    let mut lcm = Lcm::new("").unwrap();
    lcm.subscribe(channels::STEERING_COMMAND);
    lcm.subscribe(OA);
    let bus = lcm.publisher();
    let mut outsider = Signer::new(GroupKey::new(&[0x66; 32]).unwrap());
    let mut insider = insider.signer();
    // What it sent itself, never taken for authentic.
    let mut own: HashSet<Vec<u8>> = HashSet::new();
    let mut sent = Sent::new();
    let mut send =
        |own: &mut HashSet<Vec<u8>>, kind: &'static str, channel: &str, data: Vec<u8>| {
            bus.publish(channel, &data).unwrap();
            own.insert(data);
            *sent.entry(kind).or_default() += 1;
        };
    let now_us = || u64::try_from(wall_clock_utime()).unwrap();
    let strip = |data: &[u8]| data[..data.len() - TRAILER_LEN].to_vec();
    let mut later: VecDeque<(Instant, String, Vec<u8>)> = VecDeque::new();
    let mut latest_votes: Option<arc_votes_t> = None;
    let mut next = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if let Some(m) = lcm.recv_timeout(Duration::from_millis(5)).unwrap()
            && m.data.len() > TRAILER_LEN
            && !own.contains(&m.data)
        {
            send(&mut own, "replayed at once", &m.channel, m.data.clone());
            later.push_back((
                Instant::now() + Duration::from_millis(1500),
                m.channel.clone(),
                m.data.clone(),
            ));
            if m.channel == OA {
                latest_votes = arc_votes_t::decode(&strip(&m.data)).ok();
            } else {
                // The speed (after fingerprint, utime and curvature) at
                // 7.5 m/s, the tag kept.
                let mut tampered = m.data.clone();
                tampered[24..32].copy_from_slice(&7.5f64.to_be_bytes());
                send(&mut own, "tampered", &m.channel, tampered);
            }
        }
        while later
            .front()
            .is_some_and(|(at, _, _)| *at <= Instant::now())
        {
            let (_, channel, data) = later.pop_front().unwrap();
            send(&mut own, "replayed late", &channel, data);
        }
        if Instant::now() < next {
            continue;
        }
        next += Duration::from_millis(50);
        let forged = steering_command_t {
            utime: 0,
            curvature: 0.125,
            speed: 7.5,
            arc_index: 38,
            vote: 1.0,
        }
        .encode()
        .unwrap();
        send(
            &mut own,
            "unsigned",
            channels::STEERING_COMMAND,
            forged.clone(),
        );
        let signed = outsider.sign(channels::STEERING_COMMAND, &forged, now_us());
        send(&mut own, "another key", channels::STEERING_COMMAND, signed);
        let Some(votes) = &latest_votes else {
            continue;
        };
        let mut veto = votes.clone();
        veto.votes.iter_mut().for_each(|v| *v = -1.0);
        veto.vetoed.iter_mut().for_each(|v| *v = true);
        let vetoes = veto.encode().unwrap();
        send(&mut own, "unsigned", OA, vetoes.clone());
        send(
            &mut own,
            "another key",
            OA,
            outsider.sign(OA, &vetoes, now_us()),
        );
        let mut intruder = veto.clone();
        intruder.behaviour = "intruder".into();
        let intruder = intruder.encode().unwrap();
        let signed = insider.sign("ARC_VOTES_INTRUDER", &intruder, now_us());
        send(&mut own, "unconfigured", "ARC_VOTES_INTRUDER", signed);
        let mut ahead = veto;
        ahead.utime += 10_000_000;
        let signed = insider.sign(OA, &ahead.encode().unwrap(), now_us());
        send(&mut own, "from the future", OA, signed);
    }
    sent
}

/// Commands as the vehicle's own verifier sees them: the authentic ones
/// (arrival, command), how many it refused, and every message as received
/// (tags and all) written to `log`.
struct Heard {
    authentic: Received,
    refused: u64,
}

fn hear<T>(ns: &NetNs, policy: &AuthPolicy, log: &Path, body: impl FnOnce() -> T) -> (T, Heard) {
    let listen = |stop: &AtomicBool, ready: &mpsc::Sender<()>| {
        let mut lcm = Lcm::new("").unwrap();
        lcm.subscribe(channels::STEERING_COMMAND);
        let mut writer = arcnav_bus::log::LogWriter::create(log).unwrap();
        let mut verifier = policy.verifier();
        let mut heard = Heard {
            authentic: Vec::new(),
            refused: 0,
        };
        ready.send(()).unwrap();
        while !stop.load(Ordering::Relaxed) {
            let Some(m) = lcm.recv_timeout(Duration::from_millis(20)).unwrap() else {
                continue;
            };
            writer
                .write_event(m.recv_utime, &m.channel, &m.data)
                .unwrap();
            let now = u64::try_from(m.recv_utime).unwrap();
            match verifier.verify(&m.channel, &m.data, now) {
                Ok(message) => {
                    let msg = steering_command_t::decode(message).unwrap();
                    heard
                        .authentic
                        .push((Instant::now(), SteeringCommand::from(&msg)));
                }
                Err(_) => heard.refused += 1,
            }
        }
        heard
    };
    listening(ns, listen, body)
}

/// The per-reason refusals a process warned of for `channel` at exit
/// ("CHANNEL: N refused (unauthenticated a, bad tag b, …), M accepted").
fn refusals(stderr: &str, channel: &str) -> BTreeMap<String, u64> {
    let prefix = format!("authentication: {channel}: ");
    let Some(line) = stderr
        .lines()
        .find_map(|l| l.split_once(&prefix).map(|(_, r)| r))
    else {
        return BTreeMap::new();
    };
    let reasons = line
        .split_once('(')
        .and_then(|(_, r)| r.split_once(')'))
        .map_or("", |(r, _)| r);
    reasons
        .split(", ")
        .filter_map(|r| {
            let (name, n) = r.rsplit_once(' ')?;
            Some((name.to_owned(), n.parse().ok()?))
        })
        .collect()
}

/// A counter of a node in a `--json` report.
fn counter(json: &Path, name: &str) -> u64 {
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    report["nodes"][0]["counters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c[0] == name)
        .and_then(|c| c[1].as_u64())
        .unwrap_or_else(|| panic!("no counter {name} in {}", json.display()))
}

/// With `[bus.auth]` on, an attacker on the bus — forged commands, forged
/// all-veto votes, replays, tampering, an unconfigured behaviour holding the
/// key, votes from the future — changes nothing: the arbiter's commands are
/// lock-step's, cycle for cycle, as in the run without it; the vehicle
/// bridge executes only those; every refusal is counted by reason; and the
/// Python verifier, reading the commands as the vehicle received them,
/// accepts exactly the authentic ones.
#[test]
fn an_attacker_on_an_authenticated_bus_changes_no_command() {
    let dir = temp_dir("live-attack");
    let mut config = config(SensorPreset::Erim, true);
    config.bus.auth.key_file = key_file(&dir, 0x3c);
    let policy = config.bus.auth.policy(&dir).unwrap().unwrap();
    let Some(net) = Net::erim("attack", config) else {
        return;
    };
    let (arbiter_json, vehicle_json) = (dir.join("arbiter.json"), dir.join("vehicle.json"));
    let nodes: [(&str, Vec<&str>); 6] = [
        ("perception", vec!["node", "perception"]),
        ("localmap", vec!["node", "localmap"]),
        (
            "obstacle_avoidance",
            vec!["node", "behaviour", "obstacle_avoidance"],
        ),
        ("route", vec!["node", "behaviour", "route"]),
        (
            "arbiter",
            vec!["node", "arbiter", "--json", arbiter_json.to_str().unwrap()],
        ),
        (
            "vehicle",
            vec![
                "vehicle",
                "--print",
                "--rate",
                "100",
                "--json",
                vehicle_json.to_str().unwrap(),
            ],
        ),
    ];
    let heard_log = dir.join("heard.lcm");
    let ((sent, stderr, executed), heard) = hear(&net.ns, &policy, &heard_log, || {
        let procs: Vec<Proc> = nodes
            .iter()
            .map(|(name, args)| net.arcnav(name, args))
            .collect();
        procs.iter().for_each(Proc::wait_ready);
        let stop = AtomicBool::new(false);
        let sent = std::thread::scope(|scope| {
            let attacker = scope.spawn(|| net.ns.run(|| attack(&stop, policy.clone())));
            // The log's inputs, WAYPOINTS signed with the group key.
            net.ns.run(|| {
                let lcm = Lcm::new("").unwrap().authenticate(policy.clone());
                feed(&net.log, 1.0, |channel, data| {
                    lcm.publish(channel, data).unwrap()
                });
            });
            std::thread::sleep(Duration::from_millis(300));
            stop.store(true, Ordering::Relaxed);
            attacker.join().unwrap()
        });
        procs.iter().for_each(|p| p.signal("TERM"));
        let mut stderr = BTreeMap::new();
        let mut executed = String::new();
        for p in procs {
            let (name, text) = (p.name.clone(), Arc::clone(&p.stderr));
            let (code, out) = p.finish();
            assert_eq!(code, Some(0), "{name}");
            stderr.insert(name.clone(), text.lock().unwrap().clone());
            if name == "vehicle" {
                executed = out;
            }
        }
        (sent, stderr, executed)
    });
    eprintln!("attacker sent: {sent:?}");
    for kind in [
        "unsigned",
        "another key",
        "replayed at once",
        "replayed late",
        "tampered",
        "unconfigured",
        "from the future",
    ] {
        assert!(
            sent.get(kind).copied().unwrap_or(0) >= 20,
            "attacker sent {sent:?}"
        );
    }

    // The mission's commands are lock-step's, as without the attacker.
    assert_reproduces("under attack", &heard.authentic, &net.log, &net.config);

    // The vehicle executed only authentic commands, and drove. A watchdog
    // stop published the instant a pose arrives carries that pose's time,
    // which a cycle decided later carries too: a time can have two.
    let mut authentic: BTreeMap<Utime, Vec<SteeringCommand>> = BTreeMap::new();
    for (_, command) in &heard.authentic {
        authentic.entry(command.utime).or_default().push(*command);
    }
    let ticks = json_lines(&executed);
    let mut states: BTreeMap<String, usize> = BTreeMap::new();
    for tick in &ticks {
        *states.entry(tick["state"].to_string()).or_default() += 1;
        if tick["state"] != "following" {
            assert_eq!(tick["speed_mps"], 0.0, "{tick}");
            continue;
        }
        let utime = tick["command_utime"].as_i64().unwrap();
        let sent = authentic
            .get(&utime)
            .unwrap_or_else(|| panic!("the vehicle followed a command arcnav never sent: {tick}"));
        // JSON keeps 17 digits; serde_json reads them back to within an ulp.
        let same = |key: &str, value: f64| (tick[key].as_f64().unwrap() - value).abs() < 1e-12;
        assert!(
            sent.iter().any(|sent| same("speed_mps", sent.speed_mps)
                && same("curvature", sent.curvature)
                && tick["arc_index"].as_u64().map(|a| a as usize) == sent.arc_index),
            "{tick} vs {sent:?}"
        );
    }
    eprintln!("vehicle ticks: {states:?}");
    // It drove through the LOG_S of log: measured on the ticks' wall clock,
    // not by their count. A bridge descheduled for more than a period (two
    // cores, six nodes, an attacker and the test suite) restarts its count,
    // and fewer ticks are no sign of a command refused.
    let wall = |tick: &serde_json::Value| tick["wall_us"].as_i64().unwrap();
    let followed: Vec<&serde_json::Value> = ticks
        .iter()
        .filter(|tick| tick["state"] == "following")
        .collect();
    let (first, last) = (followed.first().unwrap(), followed.last().unwrap());
    let span_s = (wall(last) - wall(first)) as f64 * 1e-6;
    assert!(
        span_s >= 0.75 * LOG_S,
        "the vehicle followed commands for {span_s:.1} s of the {LOG_S} s log"
    );
    // And the attacker made it stop in none of that time: every tick within
    // it but a few (a late authentic command on a loaded machine) followed.
    let within = ticks
        .iter()
        .filter(|tick| (wall(first)..=wall(last)).contains(&wall(tick)))
        .count();
    assert!(
        followed.len() as f64 >= 0.95 * within as f64,
        "the vehicle followed at {} of the {within} ticks from its first command to its last: {states:?}",
        followed.len()
    );
    assert_eq!(ticks.last().unwrap()["state"], "shutting_down");

    // Refused, each for what it is, where it arrived.
    let reasons = ["unauthenticated", "bad tag", "replayed", "expired"];
    for (process, channel) in [
        ("vehicle", "STEERING_COMMAND"),
        ("arbiter", "ARC_VOTES_OBSTACLE_AVOIDANCE"),
        ("obstacle_avoidance", "STEERING_COMMAND"),
    ] {
        let counted = refusals(&stderr[process], channel);
        eprintln!("{process} refused on {channel}: {counted:?}");
        for reason in reasons {
            assert!(
                counted.get(reason).copied().unwrap_or(0) >= 10,
                "{process} on {channel}: {counted:?}\n{}",
                stderr[process]
            );
        }
    }
    let (refused, ignored, future) = (
        counter(&vehicle_json, "auth_refused"),
        counter(&arbiter_json, "ignored_votes"),
        counter(&arbiter_json, "future_votes"),
    );
    eprintln!("refused {refused}, ignored {ignored}, future {future}");
    assert!(refused >= LOG_CYCLES as u64, "{refused} refused");
    // The key holder that is not configured, and the votes from the future.
    assert!(ignored >= LOG_CYCLES as u64 / 2, "{ignored} ignored");
    assert!(future >= LOG_CYCLES as u64 / 2, "{future} from the future");

    // The Python verifier, on the commands as received, tags and all.
    let key = net.config.bus.auth.key_path(&dir);
    let python = net
        .reference
        .python()
        .arg(arcnav_testkit::workspace_root().join("examples/verify_command.py"))
        .arg(&key)
        .arg(&heard_log)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&python.stdout);
    let summary = text.lines().last().unwrap_or_default();
    assert_eq!(
        summary,
        format!(
            "{} accepted, {} refused",
            heard.authentic.len(),
            heard.refused
        ),
        "{}",
        String::from_utf8_lossy(&python.stderr)
    );
    assert_eq!(python.status.code(), Some(1), "some were refused: exit 1");
    for reason in reasons {
        assert!(
            text.contains(&format!("refused: {reason}")),
            "python verifier: no {reason}"
        );
    }
}

// ---------------------------------------------------------------------------
// A behaviour in Python.

/// A child process that does not outlive a failed test.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The mean heading of the log's poses, rad.
fn mean_heading(log: &Path) -> f64 {
    use arcnav_bus::lcmtypes::pose_t;
    let mut reader = LogReader::open(log).unwrap();
    let (mut s, mut c) = (0.0, 0.0);
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel == channels::POSE {
            let pose = pose_t::decode(&event.data).unwrap();
            let yaw = arcnav_vehicle::Pose::try_from(&pose).unwrap().yaw();
            s += yaw.sin();
            c += yaw.cos();
        }
    }
    s.atan2(c)
}

/// `examples/python/heading_hold.py`, run with the reference `lcm` package
/// beside `arcnav run` and named in `[behaviours.external]`: it gets the
/// local map each cycle, its votes reach the arbiter, and with its weight
/// they pull the decisions towards its heading (60° left of the course);
/// every other behaviour's votes are as in the lock-step replay without it.
#[test]
fn a_behaviour_in_python_beside_arcnav_run_steers_by_its_weight() {
    let mut config = config(SensorPreset::Erim, true);
    // Live only (no command): the test starts it beside arcnav run.
    config.behaviours.insert(
        arcnav_config::EXTERNAL.into(),
        toml::Table::from_iter([("heading_hold".to_owned(), toml::Table::new().into())]),
    );
    config.arbiter.weights.insert("heading_hold".into(), 1.0);
    let Some(net) = Net::erim("python", config) else {
        return;
    };
    let types = net.reference.generate_python(
        &std::fs::read_dir(arcnav_testkit::workspace_root().join("bus/lcmtypes"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect::<Vec<_>>(),
        &temp_dir("python-types"),
    );
    let heading = mean_heading(&net.log) + 60f64.to_radians();
    let json = temp_dir("python-run").join("run.json");
    let builtin_only = {
        let mut c = net.config.clone();
        c.behaviours.remove(arcnav_config::EXTERNAL);
        c.arbiter.weights.remove("heading_hold");
        c
    };
    let last = last_cycle(&net.log, &builtin_only);
    let (python_stderr, received) = recording_watched(&net.ns, |heard| {
        let mut python = KillOnDrop(
            net.ns
                .command(net.reference.python_path())
                .arg(arcnav_testkit::workspace_root().join("examples/python/heading_hold.py"))
                .args(["--heading-deg", &heading.to_degrees().to_string()])
                .env("PYTHONPATH", &types)
                .env("PYTHONUNBUFFERED", "1")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let mut lines = BufReader::new(python.0.stderr.take().unwrap()).lines();
        let first = lines.next().unwrap().unwrap();
        assert!(first.contains("holding heading"), "{first}");
        let run = net.arcnav("run", &["run", "--json", json.to_str().unwrap()]);
        run.wait_ready();
        assert!(net.play(INPUTS, 1.0).wait().unwrap().success());
        heard.wait_for_cycle(last, Duration::from_secs(10));
        heard.wait_for_votes(last, Duration::from_secs(10));
        run.signal("TERM");
        let (code, _) = run.finish();
        assert_eq!(code, Some(0));
        Command::new("kill")
            .args(["-TERM", &python.0.id().to_string()])
            .status()
            .unwrap();
        let stderr: Vec<String> = lines.map_while(Result::ok).collect();
        let status = python.0.wait().unwrap();
        assert!(
            status.success(),
            "heading_hold: {status}\n{}",
            stderr.join("\n")
        );
        stderr.join("\n")
    });
    eprintln!("heading_hold: {python_stderr}");
    // It voted on every cycle, and the arbiter took its votes.
    assert!(
        counter(&json, "external_votes") >= COMPARED_AT_LEAST as u64,
        "{}",
        std::fs::read_to_string(&json).unwrap()
    );
    let voted: u64 = python_stderr
        .rsplit("voted on ")
        .next()
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(voted >= COMPARED_AT_LEAST as u64, "{python_stderr}");

    // Against lock-step without it: decisions moved, and to the left.
    let without = lockstep(&net.log, &builtin_only);
    let with = by_time(&received);
    let (mut compared, mut moved, mut shift) = (0, 0, 0.0);
    for (t, base) in &without {
        let Some(got) = with.get(t) else { continue };
        if got.is_stop() || base.is_stop() {
            continue;
        }
        compared += 1;
        if got.arc_index != base.arc_index {
            moved += 1;
        }
        shift += got.curvature - base.curvature;
    }
    let mean_shift = shift / f64::from(compared.max(1));
    eprintln!(
        "with heading_hold at weight 1: {moved} of {compared} driving decisions moved, mean curvature shift {mean_shift:+.4} 1/m"
    );
    assert!(
        compared as usize >= LOG_CYCLES * 3 / 4,
        "{compared} decisions compared"
    );
    assert!(moved * 5 >= compared, "only {moved} of {compared} moved");
    assert!(
        mean_shift > 0.005,
        "not towards the left: {mean_shift:+.4} 1/m"
    );
}
