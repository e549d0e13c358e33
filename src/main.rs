//! The `arcnav` command-line tool.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context as _;
use arcnav::Config;
use arcnav::live::node::NodeKind;
use arcnav::mission::{LogMode, MissionOptions, MissionProgress, run_mission};
use arcnav_behaviours::Registry;
use arcnav_perception::SensorPreset;
use arcnav_sim::world::EMBEDDED;
use arcnav_sim::{Difficulty, World};
use clap::{ArgAction, Parser, Subcommand, ValueEnum};

/// Reactive cross-country navigation: range images → untraversable cells →
/// local map → arc votes → steering commands.
#[derive(Debug, Parser)]
#[command(name = "arcnav", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// More log output (-v debug, -vv trace).
    #[arg(short, long, action = ArgAction::Count, global = true)]
    verbose: u8,
    /// Less log output (-q warnings only, -qq errors only).
    #[arg(short, long, action = ArgAction::Count, global = true, conflicts_with = "verbose")]
    quiet: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a simulated cross-country mission: the real pipeline (perception,
    /// local map, behaviours, arbiter) drives a simulated vehicle through a
    /// world it has never seen. Writes the LCM log, report.json and map.png
    /// to --out; exit status 0 only when the mission completes without a
    /// collision.
    Sim(SimArgs),
    /// Replay an LCM log (POSE, RANGE_IMAGE, WAYPOINTS) through perception,
    /// local map, behaviours and arbiter in log time; write the recomputed
    /// decisions to --out and compare them with the ones the log recorded.
    /// Exit status: 0 all input used, 3 some input was lost (listed), 1 error.
    Replay(ReplayArgs),
    /// Drive live: every node in this process, a thread each. Takes POSE,
    /// RANGE_IMAGE* and WAYPOINTS from LCM and publishes STEERING_COMMAND at
    /// pipeline.command_rate_hz (and at once on new obstacle cells). Commands
    /// stop when poses, images or obstacle-avoidance votes go stale; Ctrl-C or
    /// SIGTERM publishes a final stop and exits.
    Run(LiveArgs),
    /// Run one node as its own process on LCM, like the original system
    /// spread over workstations: perception (RANGE_IMAGE* → OBSTACLE_CELLS),
    /// localmap (→ LOCAL_MAP), behaviour NAME (LOCAL_MAP → ARC_VOTES_NAME) or
    /// arbiter (ARC_VOTES_* → STEERING_COMMAND).
    Node {
        #[command(subcommand)]
        node: NodeCommand,
    },
    /// Picture of one decision of a log: the local map, the vehicle, the arcs
    /// coloured by fused vote, each behaviour's votes and who vetoed what.
    Render(RenderArgs),
    /// Print the effective configuration (defaults merged with FILE) as TOML,
    /// or validate FILE with --check.
    Config {
        /// A TOML file holding the keys to change; every other key keeps its
        /// default (see config/default.toml).
        file: Option<PathBuf>,
        /// Only validate FILE: exit status 0 when valid, 1 with the reason when not.
        #[arg(long, requires = "file")]
        check: bool,
    },
}

#[derive(Debug, clap::Args)]
struct SimArgs {
    /// The world: an embedded world's name (see --list) or a world file (TOML,
    /// format in docs/worlds.md). Default: paper_loop, the paper's 1 km loop.
    #[arg(long, conflicts_with = "seed")]
    world: Option<String>,
    /// Generate a world from this seed instead.
    #[arg(long)]
    seed: Option<u64>,
    /// Difficulty of a generated world.
    #[arg(long, value_enum, default_value = "moderate", requires = "seed")]
    difficulty: DifficultyArg,
    /// List the embedded worlds and exit.
    #[arg(long)]
    list: bool,
    /// Configuration file (defaults merged with it; see config/default.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output directory (default: out/<world name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Cruise speed, m/s (sets arbiter.cruise_speed_mps).
    #[arg(long, value_name = "M/S")]
    speed: Option<f64>,
    /// Sensor preset (sets sensor.preset).
    #[arg(long, value_enum)]
    sensor: Option<SensorArg>,
    /// Write a local-map picture every S simulated seconds.
    #[arg(long, value_name = "S")]
    snapshot_every: Option<f64>,
    /// Leave range images out of the log (replay then cannot re-run perception).
    #[arg(long)]
    no_images: bool,
    /// Save the world (e.g. a generated one) as TOML to this file.
    #[arg(long, value_name = "FILE")]
    save_world: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct ReplayArgs {
    /// The LCM event log (written by arcnav sim, lcm-logger or any LCM program
    /// using the arcnav types).
    log: PathBuf,
    /// Configuration file (defaults merged with it).
    #[arg(long, conflicts_with = "compare_config")]
    config: Option<PathBuf>,
    /// Run the log under two configurations and compare them.
    #[arg(long, num_args = 2, value_names = ["A.toml", "B.toml"])]
    compare_config: Option<Vec<PathBuf>>,
    /// Write the inputs and the recomputed outputs to this log.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Start this many seconds into the log (the local map starts empty there).
    #[arg(long, value_name = "S")]
    from: Option<f64>,
    /// Stop this many seconds into the log.
    #[arg(long, value_name = "S")]
    to: Option<f64>,
    /// Replay at this many times real time (default: as fast as possible).
    #[arg(long, value_name = "X")]
    speed: Option<f64>,
    /// Waypoints from this file ([[waypoints]] position_m = [x, y], as in a
    /// world file) instead of the log's WAYPOINTS.
    #[arg(long, value_name = "FILE")]
    waypoints: Option<PathBuf>,
    /// Use the log's OBSTACLE_CELLS instead of recomputing them (logs without images).
    #[arg(long)]
    recorded_cells: bool,
    /// Write the summary, problems and comparison as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// List at most this many differing decisions.
    #[arg(long, default_value_t = 10)]
    show: usize,
}

#[derive(Debug, clap::Args)]
struct RenderArgs {
    /// The LCM event log.
    log: PathBuf,
    /// Seconds into the log: the first decision at or after it is drawn.
    #[arg(long, value_name = "S")]
    at: f64,
    /// The picture (default: decision-<S>s.png).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Configuration file (defaults merged with it).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Use the log's OBSTACLE_CELLS instead of recomputing them.
    #[arg(long)]
    recorded_cells: bool,
}

#[derive(Debug, clap::Args)]
struct LiveArgs {
    /// LCM provider URL.
    #[arg(long, value_name = "URL", env = "LCM_DEFAULT_URL", default_value = arcnav_bus::transport::DEFAULT_URL)]
    lcm: String,
    /// Configuration file (defaults merged with it; see config/default.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print a table of every node's figures (cycle time, queues, drops,
    /// latency) at exit.
    #[arg(long)]
    stats: bool,
    /// Write those figures as JSON to this file at exit.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Stop after this many seconds (default: until Ctrl-C or SIGTERM).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
}

#[derive(Debug, Subcommand)]
enum NodeCommand {
    /// Range images + poses → OBSTACLE_CELLS.
    Perception(LiveArgs),
    /// Poses + obstacle cells → LOCAL_MAP, one per decision cycle.
    Localmap(LiveArgs),
    /// One behaviour (configured under [behaviours.NAME]): LOCAL_MAP → ARC_VOTES_<NAME>.
    Behaviour {
        /// The behaviour, e.g. obstacle_avoidance or goal_seeking.
        name: String,
        #[command(flatten)]
        live: LiveArgs,
    },
    /// ARC_VOTES_* → STEERING_COMMAND, with the safety watchdog.
    Arbiter(LiveArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum DifficultyArg {
    Easy,
    Moderate,
    Hard,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum SensorArg {
    Erim,
    Lidar64,
    Lidar128,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    match run(cli.command) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

fn init_logging(verbose: u8, quiet: u8) {
    let level = match (verbose, quiet) {
        (0, 0) => "info",
        (1, _) => "debug",
        (v, _) if v >= 2 => "trace",
        (_, 1) => "warn",
        _ => "error",
    };
    // RUST_LOG, when set, refines the level per module.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .init();
}

fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Sim(args) => sim(args),
        Command::Replay(args) => replay(args),
        Command::Render(args) => render(args),
        Command::Run(args) => live(None, args),
        Command::Node { node } => match node {
            NodeCommand::Perception(args) => live(Some(NodeKind::Perception), args),
            NodeCommand::Localmap(args) => live(Some(NodeKind::LocalMap), args),
            NodeCommand::Arbiter(args) => live(Some(NodeKind::Arbiter), args),
            NodeCommand::Behaviour { name, live: args } => {
                live(Some(NodeKind::Behaviour(name)), args)
            }
        },
        Command::Config { file, check } => {
            let config = Config::load_or_default(file.as_deref())?;
            if check {
                let file = file.context("--check needs a FILE")?;
                println!("{}: valid", file.display());
            } else {
                match &file {
                    Some(f) => println!(
                        "# effective configuration: defaults merged with {}",
                        f.display()
                    ),
                    None => println!("# effective configuration: the defaults"),
                }
                print!("{}", config.to_toml());
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn sim(args: SimArgs) -> anyhow::Result<ExitCode> {
    if args.list {
        println!("embedded worlds (arcnav sim --world NAME):");
        for (name, description, _) in EMBEDDED {
            println!("  {name:<14} {description}");
        }
        println!("or --world FILE.toml, or --seed N [--difficulty easy|moderate|hard]");
        return Ok(ExitCode::SUCCESS);
    }
    let registry = Registry::builtin();
    let mut config = match &args.config {
        Some(path) => Config::load_with(path, &registry)?,
        None => Config::default(),
    };
    if let Some(speed) = args.speed {
        anyhow::ensure!(
            speed > 0.0 && speed.is_finite(),
            "--speed {speed}: a speed must be positive"
        );
        config.arbiter.cruise_speed_mps = speed;
        config.vehicle.max_speed_mps = config.vehicle.max_speed_mps.max(speed);
    }
    if let Some(sensor) = args.sensor {
        config.sensor.preset = match sensor {
            SensorArg::Erim => SensorPreset::Erim,
            SensorArg::Lidar64 => SensorPreset::Lidar64,
            SensorArg::Lidar128 => SensorPreset::Lidar128,
        };
    }
    if let Some(every) = args.snapshot_every {
        anyhow::ensure!(
            every > 0.0,
            "--snapshot-every {every}: must be positive seconds"
        );
    }
    config
        .validate_with(&registry)
        .context("the configuration with the command-line settings")?;
    let world = match (&args.world, args.seed) {
        (_, Some(seed)) => {
            let difficulty = match args.difficulty {
                DifficultyArg::Easy => Difficulty::Easy,
                DifficultyArg::Moderate => Difficulty::Moderate,
                DifficultyArg::Hard => Difficulty::Hard,
            };
            World::build(
                arcnav_sim::generate(seed, difficulty),
                "generated world",
                None,
            )?
        }
        (Some(name), None) if !Path::new(name).exists() && !name.ends_with(".toml") => {
            match World::embedded(name) {
                Some(world) => world?,
                None => anyhow::bail!(
                    "no embedded world named {name:?} and no file of that name (embedded: {})",
                    EMBEDDED
                        .iter()
                        .map(|(n, _, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        }
        (Some(file), None) => World::load(Path::new(file))?,
        (None, None) => {
            World::embedded("paper_loop").context("the default world is compiled in")??
        }
    };
    if let Some(path) = &args.save_world {
        let text = toml::to_string(&world.spec).context("serialising the world")?;
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
        println!("world saved to {}", path.display());
    }
    let name = world.spec.name.clone();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&name));
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create the output directory {}", out.display()))?;
    let snapshot_dir = out.join("snapshots");
    if args.snapshot_every.is_some() {
        std::fs::create_dir_all(&snapshot_dir)
            .with_context(|| format!("cannot create {}", snapshot_dir.display()))?;
    }
    let options = MissionOptions {
        log: Some(out.join("mission.lcm")),
        log_mode: if args.no_images {
            LogMode::NoImages
        } else {
            LogMode::All
        },
        snapshot_every_s: args.snapshot_every,
        snapshot_dir: Some(snapshot_dir),
    };
    let sensor = config.sensor.model().map_err(|e| e.within("sensor"))?;
    eprintln!(
        "arcnav sim: {name} ({} waypoints) with the {} sensor at {:.1} m/s cruise",
        world.waypoints.len(),
        sensor.id,
        config.arbiter.cruise_speed_mps
    );
    let bar = indicatif::ProgressBar::new(world.waypoints.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} [{bar:30}] waypoint {pos}/{len} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let world = Arc::new(world);
    let run = run_mission(
        &config,
        &registry,
        Arc::clone(&world),
        &options,
        &mut |p: &MissionProgress| {
            bar.set_position(p.waypoint as u64);
            bar.set_message(format!(
                "· {:.0} s · {:.0} m · {:.1} m/s",
                p.sim_time_s, p.distance_m, p.speed_mps
            ));
        },
    )?;
    bar.finish_and_clear();
    let config_path = out.join("config.toml");
    std::fs::write(
        &config_path,
        format!("# the configuration of this run: replay with `arcnav replay mission.lcm --config config.toml`\n{}", config.to_toml()),
    )
    .with_context(|| format!("cannot write {}", config_path.display()))?;
    let report_path = out.join("report.json");
    std::fs::write(&report_path, serde_json::to_string_pretty(&run.report)?)
        .with_context(|| format!("cannot write {}", report_path.display()))?;
    let map_path = out.join("map.png");
    arcnav::render::mission_picture(&map_path, &world, &run)?;
    print_summary(&run.report, &out, &run.snapshots);
    Ok(if run.report.success {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn print_summary(r: &arcnav::mission::MissionReport, out: &Path, snapshots: &[PathBuf]) {
    let outcome = match r.outcome {
        arcnav::mission::Outcome::Completed => "completed",
        arcnav::mission::Outcome::Collision => "FAILED: collision",
        arcnav::mission::Outcome::Timeout => "FAILED: time limit",
        arcnav::mission::Outcome::Stuck => "FAILED: stuck",
    };
    println!("mission       {} on {} with {}", outcome, r.world, r.sensor);
    println!("waypoints     {}/{}", r.waypoints_reached, r.waypoints);
    println!(
        "distance      {:.0} m in {:.0} s: average {:.2} m/s, max {:.2} m/s (cruise {:.2} m/s)",
        r.distance_m, r.duration_s, r.average_speed_mps, r.max_speed_mps, r.cruise_speed_mps
    );
    println!(
        "images        {} processed, {} dropped",
        r.images, r.images_dropped
    );
    println!("collisions    {}", r.collisions.len());
    for c in &r.collisions {
        println!(
            "              {} at ({:.1}, {:.1}) after {:.1} s",
            c.cause,
            c.position[0],
            c.position[1],
            (c.utime - arcnav::mission::SIM_EPOCH_US) as f64 * 1e-6
        );
    }
    if let Some(gap) = r.closest_approach_m {
        println!("closest       {gap:.2} m between the vehicle and a hazard");
    }
    let s = &r.stops;
    println!(
        "stops         {} stop commands in {} episodes (all arcs forbidden {}, no acceptable arc {}, required behaviour stale {})",
        s.stop_commands, s.episodes, s.all_arcs_forbidden, s.no_acceptable_arc, s.required_stale
    );
    let t = &r.stage_times;
    println!(
        "stage time    perception {:.2} ms/image, local map {:.3} ms, behaviours {:.3} ms, arbiter {:.3} ms (mean per call)",
        t.perception.mean_ms(),
        t.localmap.mean_ms(),
        t.behaviours.mean_ms(),
        t.arbiter.mean_ms()
    );
    println!(
        "simulation    {:.0} s simulated in {:.1} s ({:.0}× real time), rendering {:.1} ms/image",
        r.duration_s, r.wall_time_s, r.realtime_factor, r.render_ms_mean
    );
    println!(
        "outputs       {}/mission.lcm, report.json, map.png, config.toml{}",
        out.display(),
        if snapshots.is_empty() {
            String::new()
        } else {
            format!(", {} snapshots in snapshots/", snapshots.len())
        }
    );
}

/// Waypoints from a TOML file with [[waypoints]] entries (a world file works).
fn load_waypoints(path: &Path) -> anyhow::Result<arcnav_behaviours::Mission> {
    #[derive(serde::Deserialize)]
    struct File {
        waypoints: Vec<arcnav_sim::world::WaypointSpec>,
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let file: File = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.message()))
        .with_context(|| "a waypoints file holds [[waypoints]] tables with position_m = [x, y]")?;
    anyhow::ensure!(
        !file.waypoints.is_empty(),
        "{} holds no [[waypoints]]",
        path.display()
    );
    Ok(arcnav_behaviours::Mission {
        version: 1,
        waypoints: file
            .waypoints
            .iter()
            .map(|w| arcnav_behaviours::Waypoint {
                x: w.position_m[0],
                y: w.position_m[1],
                radius_m: w.radius_m,
            })
            .collect(),
    })
}

fn replay(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    use arcnav::replay::{ReplayOptions, compare, replay as run_replay};
    let registry = Registry::builtin();
    let load = |path: &Option<PathBuf>| -> anyhow::Result<Config> {
        Ok(match path {
            Some(p) => Config::load_with(p, &registry)?,
            None => Config::default(),
        })
    };
    if let Some(speed) = args.speed {
        anyhow::ensure!(speed > 0.0, "--speed {speed}: must be positive");
    }
    let options = ReplayOptions {
        from_s: args.from,
        to_s: args.to,
        out: args.out.clone(),
        waypoints: args.waypoints.as_deref().map(load_waypoints).transpose()?,
        speed: args.speed,
        recorded_cells: args.recorded_cells,
        stop_at_s: None,
    };
    let size = std::fs::metadata(&args.log)
        .with_context(|| format!("cannot read the log {}", args.log.display()))?
        .len();
    let bar = indicatif::ProgressBar::new(size);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} replaying [{bar:30}] {bytes}/{total_bytes} ({eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let mut runs = Vec::new();
    let configs: Vec<(String, Config, ReplayOptions)> = match &args.compare_config {
        Some(pair) => {
            let (a, b) = (&pair[0], &pair[1]);
            vec![
                (
                    a.display().to_string(),
                    load(&Some(a.clone()))?,
                    ReplayOptions {
                        out: None,
                        ..options.clone()
                    },
                ),
                (
                    b.display().to_string(),
                    load(&Some(b.clone()))?,
                    options.clone(),
                ),
            ]
        }
        None => vec![("replayed".to_owned(), load(&args.config)?, options.clone())],
    };
    for (label, config, opts) in &configs {
        bar.set_position(0);
        let result = run_replay(&args.log, config, &registry, opts, &mut |p| {
            bar.set_position(p)
        })?;
        runs.push((label.clone(), config.clone(), result));
    }
    bar.finish_and_clear();
    let (_, config, last) = &runs[runs.len() - 1];
    let origin = last.span.map_or(0, |s| s.0);
    let i = &last.inputs;
    println!("log           {}", args.log.display());
    println!(
        "inputs        {} poses, {} range images, {} waypoint lists{}",
        i.poses,
        i.images,
        i.waypoints,
        if args.recorded_cells {
            format!(", {} recorded obstacle reports", i.recorded_cells)
        } else {
            String::new()
        }
    );
    if let Some((a, b)) = last.span {
        println!("span          {:.1} s of log", (b - a) as f64 * 1e-6);
    }
    println!(
        "decisions     {} recomputed{}",
        last.cycles.len(),
        args.out
            .as_ref()
            .map(|o| format!(", written to {}", o.display()))
            .unwrap_or_default()
    );
    let weight_of = |c: &Config| {
        let c = c.clone();
        move |name: &str| c.arbiter.weight(name)
    };
    let mut comparisons = Vec::new();
    if runs.len() == 2 {
        let (wa, wb) = (weight_of(&runs[0].1), weight_of(&runs[1].1));
        comparisons.push(compare(
            (&runs[0].0, &runs[1].0),
            &runs[0].2.cycles,
            &runs[1].2.cycles,
            (&wa, &wb),
            origin,
        ));
    } else if !last.recorded.is_empty() {
        let w = weight_of(config);
        comparisons.push(compare(
            ("recorded", "replayed"),
            &last.recorded,
            &last.cycles,
            (&w, &w),
            origin,
        ));
    } else {
        println!("comparison    the log holds no STEERING_COMMAND to compare with");
    }
    for c in &comparisons {
        println!(
            "comparison    {} vs {}: {} decisions compared, {} agree ({:.2}%)",
            c.a, c.b, c.compared, c.agreeing, c.agreement_percent
        );
        if let Some(d) = &c.first_divergence {
            println!("              first divergence at {:.2} s", d.time_s);
        }
        if let Some(d) = &c.largest_curvature_difference {
            println!(
                "              largest curvature difference {:.4} 1/m at {:.2} s",
                (d.a.curvature - d.b.curvature).abs(),
                d.time_s
            );
        }
        for d in c.differences.iter().take(args.show) {
            let arc = |x: &arcnav::replay::Decided| {
                x.arc.map_or("stop".to_owned(), |a| format!("arc {a}"))
            };
            println!(
                "              {:>8.2} s  {}: {} at {:.2} m/s  {}: {} at {:.2} m/s{}",
                d.time_s,
                c.a,
                arc(&d.a),
                d.a.speed_mps,
                c.b,
                arc(&d.b),
                d.b.speed_mps,
                d.moved_by
                    .as_ref()
                    .map(|b| format!("  (moved by {b})"))
                    .unwrap_or_default()
            );
        }
        if c.differences.len() > args.show {
            println!(
                "              ... {} differences in all (--show N, --json FILE)",
                c.differences.len()
            );
        }
    }
    let problems = &last.problems;
    let lines = problems.lines();
    if lines.is_empty() {
        println!("problems      none: every input was used");
    } else {
        println!("problems      {}", lines[0]);
        for line in &lines[1..] {
            println!("              {line}");
        }
    }
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "log": args.log.display().to_string(),
            "inputs": last.inputs,
            "decisions": last.cycles.len(),
            "problems": problems,
            "input_lost": problems.lost_input(),
            "comparisons": comparisons,
        });
        std::fs::write(path, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(if problems.lost_input() {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    })
}

/// `arcnav run` (no node) or `arcnav node …`.
fn live(node: Option<NodeKind>, args: LiveArgs) -> anyhow::Result<ExitCode> {
    use arcnav::live::threaded::{LiveOptions, StopWhen};
    let registry = Registry::builtin();
    let config = match &args.config {
        Some(p) => Config::load_with(p, &registry)?,
        None => Config::default(),
    };
    let after = match args.duration {
        Some(s) if s > 0.0 && s.is_finite() => Some(std::time::Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration {s}: must be a positive number of seconds"),
        None => None,
    };
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // A second signal while shutting down exits at once.
        signal_hook::flag::register_conditional_shutdown(signal, 1, Arc::clone(&flag))
            .context("cannot install the signal handlers")?;
        signal_hook::flag::register(signal, Arc::clone(&flag))
            .context("cannot install the signal handlers")?;
    }
    let lcm = arcnav_bus::transport::Lcm::new(&args.lcm)
        .with_context(|| format!("cannot open LCM at {}", args.lcm))?;
    let options = LiveOptions {
        stop: StopWhen { flag, after },
        ..LiveOptions::default()
    };
    let what = node
        .as_ref()
        .map_or("every node".to_owned(), |n| format!("node {n}"));
    tracing::info!(
        lcm = %args.lcm,
        rate_hz = config.pipeline.command_rate_hz,
        "starting {what}; Ctrl-C or SIGTERM stops"
    );
    let report = match &node {
        None => arcnav::live::threaded::run(&config, &registry, lcm, &options)?,
        Some(kind) => arcnav::live::node::run_node(kind, &config, &registry, lcm, &options)?,
    };
    tracing::info!(
        commands = report.commands,
        stops = report.stops,
        "{what} stopped after {:.1} s",
        report.wall_s
    );
    if args.stats {
        print!("{}", report.table());
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

fn render(args: RenderArgs) -> anyhow::Result<ExitCode> {
    use arcnav::replay::{ReplayOptions, replay as run_replay};
    let registry = Registry::builtin();
    let config = match &args.config {
        Some(p) => Config::load_with(p, &registry)?,
        None => Config::default(),
    };
    let options = ReplayOptions {
        recorded_cells: args.recorded_cells,
        stop_at_s: Some(args.at),
        ..ReplayOptions::default()
    };
    let result = run_replay(&args.log, &config, &registry, &options, &mut |_| {})?;
    let origin = result.span.map_or(0, |s| s.0);
    let Some((at, decision, map)) = &result.kept else {
        anyhow::bail!(
            "no decision at or after {} s: the log spans {:.1} s and yielded {} decisions",
            args.at,
            result.span.map_or(0.0, |(a, b)| (b - a) as f64 * 1e-6),
            result.cycles.len()
        );
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("decision-{:.1}s.png", args.at)));
    arcnav::render::snapshot_picture(
        &out,
        &config,
        &result.arcs,
        map,
        Some(decision),
        at - origin,
        &[],
    )?;
    println!(
        "decision at {:.2} s drawn to {}",
        (at - origin) as f64 * 1e-6,
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}
