//! `arcnav sweep`: missions over worlds × settings on every core, one table.

use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use arcnav::Config;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav::sweep::{
    Finished, Part, Plan, PlanIdentity, Row, RowLog, Shard, SweepWorld, axes, parse_set, read_grid,
    settings, summarise, summary_csv, table_csv,
};
use arcnav_behaviours::Registry;
use arcnav_sim::{Difficulty, World};
use rayon::prelude::*;

use super::sim::named_world;
use crate::{SweepAction, SweepArgs, SweepMergeArgs};

const PLAN_FILE: &str = "sweep.json";

/// The exit status of an interrupted sweep (as for SIGINT).
const INTERRUPTED: u8 = 130;

/// Runs at a time, at most: each is a mission with threads of its own.
/// (`--jobs 100000` for a one-run sweep had started 9 500 threads after
/// 50 s, and did not stop for SIGTERM.)
const MAX_JOBS: usize = 1024;

pub fn sweep(mut args: SweepArgs) -> anyhow::Result<ExitCode> {
    if let Some(SweepAction::Merge(merge_args)) = args.action.take() {
        return merge(merge_args);
    }
    let plan = plan(&args, &Registry::builtin())?;
    let shard = args.shard.unwrap_or(Shard::WHOLE);
    let mut identity = plan.identity();
    if shard != Shard::WHOLE {
        identity.shard = Some(shard);
    }
    let jobs = match args.jobs {
        Some(0) => anyhow::bail!("--jobs 0: at least one run at a time"),
        Some(n) if n > MAX_JOBS => {
            anyhow::bail!("--jobs {n}: at most {MAX_JOBS} runs at a time (each is a mission)")
        }
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, usize::from),
    };
    let out = &args.out;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the output directory {}", out.display()))?;
    let finished = prepare(out, &identity, args.resume)?;
    let done: std::collections::BTreeSet<usize> = finished.rows.iter().map(|r| r.run).collect();
    let pending: Vec<usize> = shard
        .runs(plan.runs())
        .filter(|r| !done.contains(r))
        .collect();
    // A thread a run at most: more would wait for nothing.
    let jobs = jobs.min(pending.len()).max(1);
    eprintln!(
        "arcnav sweep: {} worlds × {} settings = {} runs{}{}, {} at a time; results in {}",
        plan.worlds.len(),
        plan.settings.len(),
        plan.runs(),
        if shard == Shard::WHOLE {
            String::new()
        } else {
            format!(" (shard {shard}: {} of them)", identity.runs_held())
        },
        if done.is_empty() {
            String::new()
        } else {
            format!(" ({} already done)", done.len())
        },
        jobs,
        out.display()
    );
    if finished.unreadable > 0 {
        eprintln!(
            "  {} cut-off line(s) in {} ignored: those runs are done again",
            finished.unreadable,
            RowLog::FILE
        );
    }
    let interrupted = super::terminal::interrupt_flag()?;
    let started = Instant::now();
    let ran = run_pending(&plan, &pending, jobs, out, &interrupted)?;
    let elapsed = started.elapsed().as_secs_f64();
    let mut finished = RowLog::read(out, plan.runs())
        .with_context(|| format!("cannot read {}", out.join(RowLog::FILE).display()))?;
    // Rows prepare set aside as not this plan's were run again and replaced.
    finished.keep_runs_of(&identity);
    let rows = finished.rows;
    write_tables(out, &identity, &rows)?;
    if !ran.is_empty() {
        let busy: f64 = ran.iter().map(|r| r.wall_time_s).sum();
        let cores = elapsed * jobs as f64;
        eprintln!(
            "{} runs in {elapsed:.1} s, {jobs} at a time: the runs took {busy:.1} s, {:.0} % of \
             the {cores:.1} s of {jobs} threads; CPU used {:.1} s ({:.0} % of {jobs} cores)",
            ran.len(),
            100.0 * busy / cores.max(1e-9),
            cpu_seconds(),
            100.0 * cpu_seconds() / cores.max(1e-9)
        );
    }
    print_summary(&identity, &rows);
    if rows.len() < identity.runs_held() {
        eprintln!(
            "interrupted: {} of {} runs done, kept in {}; the same command with --resume carries on",
            rows.len(),
            identity.runs_held(),
            out.display()
        );
        return Ok(ExitCode::from(INTERRUPTED));
    }
    Ok(ExitCode::SUCCESS)
}

/// Worlds and settings, every one loaded and validated before any run.
fn plan(args: &SweepArgs, registry: &Registry) -> anyhow::Result<Plan> {
    let base = Config::load_or_default(args.config.as_deref())?;
    let sets = args
        .sets
        .iter()
        .map(|s| parse_set(s))
        .collect::<Result<Vec<_>, _>>()?;
    let grid = match &args.grid {
        Some(path) => read_grid(path)?,
        None => Vec::new(),
    };
    let axes = axes(&base, &sets, &grid)?;
    let settings = settings(&base, &axes, registry)?;
    let mut worlds = Vec::new();
    for name in &args.worlds {
        let world = named_world(name).with_context(|| format!("--world {name}"))?;
        worlds.push(SweepWorld {
            label: name.clone(),
            world: Arc::new(world),
        });
    }
    if let Some(range) = &args.seeds {
        let difficulty: Difficulty = args.difficulty.into();
        for seed in parse_seeds(range)? {
            let label = format!("seed {seed} ({difficulty:?})").to_lowercase();
            let world = World::build(arcnav_sim::generate(seed, difficulty), &label, None)?;
            worlds.push(SweepWorld {
                label,
                world: Arc::new(world),
            });
        }
    }
    anyhow::ensure!(
        !worlds.is_empty(),
        "no worlds: give --world NAME|FILE (repeatable) and/or --seeds A..B"
    );
    for (i, w) in worlds.iter().enumerate() {
        anyhow::ensure!(
            !worlds[..i].iter().any(|o| o.label == w.label),
            "world {} is given twice",
            w.label
        );
        for s in &settings {
            w.world
                .validate_for(&s.config.vehicle, &w.label)
                .with_context(|| format!("setting {}", s.label(&axes)))?;
        }
    }
    Ok(Plan {
        worlds,
        axes,
        settings,
    })
}

/// `A..B`: seeds A up to B, B excluded.
fn parse_seeds(range: &str) -> anyhow::Result<std::ops::Range<u64>> {
    let bad = || anyhow::anyhow!("--seeds {range:?}: expected A..B, e.g. 0..50 (B excluded)");
    let (a, b) = range.split_once("..").ok_or_else(bad)?;
    let (a, b): (u64, u64) = (
        a.trim().parse().map_err(|_| bad())?,
        b.trim().parse().map_err(|_| bad())?,
    );
    anyhow::ensure!(a < b, "--seeds {range}: no seeds (B must be above A)");
    anyhow::ensure!(b - a <= 100_000, "--seeds {range}: more than 100000 worlds");
    Ok(a..b)
}

/// Checks `out` against the plan: a fresh directory gets the plan, a
/// resumed one must hold the same plan; the finished rows.
fn prepare(out: &Path, identity: &PlanIdentity, resume: bool) -> anyhow::Result<Finished> {
    let plan_path = out.join(PLAN_FILE);
    let earlier: Option<PlanIdentity> = match std::fs::read_to_string(&plan_path) {
        Ok(text) => Some(
            serde_json::from_str(&text)
                .with_context(|| format!("{} is not a sweep plan", plan_path.display()))?,
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", plan_path.display())),
    };
    match (resume, &earlier) {
        (true, Some(earlier)) if earlier != identity => anyhow::bail!(
            "--resume: {} holds another sweep ({}); resume it with the command that started it, \
             or give another --out",
            out.display(),
            earlier.difference(identity)
        ),
        (true, None) => anyhow::bail!(
            "--resume: {} holds no sweep to carry on (no {PLAN_FILE})",
            out.display()
        ),
        _ => {}
    }
    let finished = if earlier.is_some() {
        let mut rows = RowLog::read(out, identity.runs())
            .with_context(|| format!("cannot read {}", out.join(RowLog::FILE).display()))?;
        let foreign = rows.keep_runs_of(identity);
        if foreign > 0 {
            eprintln!(
                "note: {foreign} rows of {} are not runs of this plan (their world or values \
                 differ from the plan's for their run): not resumed, those runs are done again",
                out.join(RowLog::FILE).display()
            );
        }
        rows
    } else if out.join(RowLog::FILE).exists() {
        anyhow::bail!(
            "{} holds a {} but no {PLAN_FILE}: not a sweep this version can carry on; give \
             another --out",
            out.display(),
            RowLog::FILE
        )
    } else {
        Finished::default()
    };
    match resume {
        false if !finished.rows.is_empty() => anyhow::bail!(
            "{} already holds {} finished runs of a sweep: --resume carries it on, or give \
             another --out (nothing was overwritten)",
            out.display(),
            finished.rows.len()
        ),
        _ => {}
    }
    write_in(
        out,
        PLAN_FILE,
        serde_json::to_string_pretty(identity)?.as_bytes(),
    )?;
    Ok(finished)
}

/// Runs `pending` on `jobs` threads, appending each row to the rows file
/// as it finishes; stops starting runs when `interrupted`, and then returns
/// without waiting for the runs under way. The rows of this call.
fn run_pending(
    plan: &Plan,
    pending: &[usize],
    jobs: usize,
    out: &Path,
    interrupted: &AtomicBool,
) -> anyhow::Result<Vec<Row>> {
    let mut log = RowLog::append(out)
        .with_context(|| format!("cannot write {}", out.join(RowLog::FILE).display()))?;
    let bar = super::terminal::progress_bar(
        plan.runs() as u64,
        "{spinner} [{bar:30}] {pos}/{len} runs · {elapsed} · {eta} left · {msg}",
    );
    bar.set_position((plan.runs() - pending.len()) as u64);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .thread_name(|i| format!("sweep-{i}"))
        .build()
        .context("cannot start the sweep's threads")?;
    let (tx, rx) = crossbeam_channel::unbounded::<Row>();
    let plan_ref = plan.clone();
    let work: Vec<usize> = pending.to_vec();
    // Detached: an interrupted sweep leaves the runs under way behind.
    let stop = Arc::new(AtomicBool::new(false));
    let stop_workers = Arc::clone(&stop);
    std::thread::spawn(move || {
        pool.install(|| {
            work.par_iter().with_max_len(1).for_each(|&run| {
                if stop_workers.load(Ordering::Relaxed) {
                    return;
                }
                let _ = tx.send(one_run(&plan_ref, run, jobs > 1));
            });
        });
    });
    let mut ran = Vec::new();
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    while ran.len() < pending.len() {
        if interrupted.load(Ordering::Relaxed) {
            stop.store(true, Ordering::Relaxed);
            break;
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(row) => {
                log.push(&row).with_context(|| {
                    format!("cannot write {}", out.join(RowLog::FILE).display())
                })?;
                let line = format!(
                    "{} · {}: {}{}",
                    row.world,
                    plan.settings[row.setting].label(&plan.axes),
                    row.outcome,
                    if row.success {
                        format!(", {:.2} m/s", row.average_speed_mps)
                    } else {
                        String::new()
                    }
                );
                bar.inc(1);
                if terminal {
                    bar.set_message(line);
                } else {
                    eprintln!("[{}/{}] {line}", bar.position(), plan.runs());
                }
                ran.push(row);
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => break,
        }
    }
    bar.finish_and_clear();
    Ok(ran)
}

/// One mission; a run that cannot start is a row with outcome `error`.
/// Run `run` of `plan`; `beside_others` when other runs go at the same time.
fn one_run(plan: &Plan, run: usize, beside_others: bool) -> Row {
    let (world, s, setting) = plan.run(run);
    match run_mission(
        &setting.config,
        Arc::clone(&world.world),
        &MissionOptions {
            beside_others,
            ..MissionOptions::default()
        },
        &mut |_| {},
    ) {
        Ok(done) => {
            let external: Vec<String> = setting.config.external.keys().cloned().collect();
            Row::new(
                run,
                &world.label,
                s,
                &setting.values,
                &done.report,
                &external,
            )
        }
        Err(e) => Row::failed(run, &world.label, s, &setting.values, &e.to_string()),
    }
}

/// Writes `bytes` whole as the file `name` of the sweep directory `out`.
fn write_in(out: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let path = out.join(name);
    arcnav::output::write_file(&path, bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}

fn write_tables(out: &Path, plan: &PlanIdentity, rows: &[Row]) -> anyhow::Result<()> {
    let write = |name: &str, bytes: &[u8]| write_in(out, name, bytes);
    let summary = summarise(plan, rows);
    write("table.csv", table_csv(plan, rows).as_bytes())?;
    write("table.json", serde_json::to_string_pretty(rows)?.as_bytes())?;
    write("summary.csv", summary_csv(plan, &summary).as_bytes())?;
    write(
        "summary.json",
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    let title = format!(
        "arcnav sweep: {} of {}{}, {} × {}",
        rows.len(),
        count(plan.runs(), "run"),
        plan.shard
            .map(|s| format!(" (shard {s})"))
            .unwrap_or_default(),
        count(plan.worlds.len(), "world"),
        count(plan.settings.len(), "setting")
    );
    arcnav::render::sweep_picture(&out.join("sweep.png"), &title, &plan.keys, &summary)?;
    Ok(())
}

fn print_summary(plan: &PlanIdentity, rows: &[Row]) {
    let summary = summarise(plan, rows);
    let labels: Vec<String> = summary.iter().map(|s| plan.label(s.setting)).collect();
    let w = labels
        .iter()
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0)
        .max(7);
    println!(
        "{:<w$}  {:>9} {:>9} {:>16} {:>10}",
        "setting", "completed", "mean m/s", "closest approach", "collisions"
    );
    for (s, label) in summary.iter().zip(labels) {
        println!(
            "{label:<w$}  {:>9} {:>9.2} {:>16} {:>10}",
            format!("{}/{}", s.successes, s.runs),
            s.mean_speed_mps,
            s.worst_closest_approach_m
                .map_or("-".into(), |m| format!("{m:.2} m")),
            s.collisions
        );
    }
}

/// CPU time this process has used (user + system), s.
fn cpu_seconds() -> f64 {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage fills the rusage it is given, a valid pointer to
    // zeroed memory of the right type, and reports failure by its result.
    let ok = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) } == 0;
    if !ok {
        return f64::NAN;
    }
    // SAFETY: zero-initialised and, getrusage having succeeded, filled.
    let usage = unsafe { usage.assume_init() };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

/// `arcnav sweep merge DIR… --out OUT`: the shards' directories joined into
/// one sweep directory, as an unsharded sweep of the same plan writes it.
fn merge(args: SweepMergeArgs) -> anyhow::Result<ExitCode> {
    let out = &args.out;
    for dir in &args.dirs {
        anyhow::ensure!(
            !same_dir(out, dir),
            "--out {}: it is one of the shards given; give a new directory",
            out.display()
        );
    }
    let mut parts = Vec::with_capacity(args.dirs.len());
    for dir in &args.dirs {
        let plan_path = dir.join(PLAN_FILE);
        let text = std::fs::read_to_string(&plan_path).with_context(|| {
            format!(
                "{} holds no sweep (cannot read its {PLAN_FILE})",
                dir.display()
            )
        })?;
        let plan: PlanIdentity = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a sweep plan", plan_path.display()))?;
        let finished = RowLog::read(dir, plan.runs())
            .with_context(|| format!("cannot read {}", dir.join(RowLog::FILE).display()))?;
        if finished.unreadable > 0 {
            eprintln!(
                "  {}: {} cut-off line(s) of {} ignored",
                dir.display(),
                finished.unreadable,
                RowLog::FILE
            );
        }
        parts.push(Part {
            name: dir.display().to_string(),
            plan,
            finished,
        });
    }
    let shards = parts.len();
    let (plan, rows, foreign) = arcnav::sweep::merge(parts)?;
    if foreign > 0 {
        eprintln!(
            "note: {foreign} rows were not runs of their shard's plan (edited, or another \
             shard's) and are left out"
        );
    }
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the output directory {}", out.display()))?;
    for existing in [PLAN_FILE, RowLog::FILE] {
        anyhow::ensure!(
            !out.join(existing).exists(),
            "{} already holds a sweep ({existing}): give another --out (nothing was overwritten)",
            out.display()
        );
    }
    RowLog::write(out, &rows)
        .with_context(|| format!("cannot write {}", out.join(RowLog::FILE).display()))?;
    write_tables(out, &plan, &rows)?;
    // The plan last: a directory with it is a whole sweep.
    write_in(
        out,
        PLAN_FILE,
        serde_json::to_string_pretty(&plan)?.as_bytes(),
    )?;
    eprintln!(
        "arcnav sweep merge: {} runs from {shards} director{} into {}",
        rows.len(),
        if shards == 1 { "y" } else { "ies" },
        out.display()
    );
    print_summary(&plan, &rows);
    Ok(ExitCode::SUCCESS)
}

/// Whether `a` and `b` name the same directory.
fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
