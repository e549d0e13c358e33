//! The `arcnav` command-line tool.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use arcnav::Resolved;
use arcnav::live::node::NodeKind;
use clap::{ArgAction, Parser, Subcommand, ValueEnum};

mod cli;

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
    /// Run a simulated mission on a world it has never seen.
    ///
    /// Run a simulated cross-country mission: the real pipeline (perception,
    /// local map, behaviours, arbiter) drives a simulated vehicle through a
    /// world it has never seen. Writes the LCM log, report.json and map.png
    /// to --out; exit status 0 only when the mission completes without a
    /// collision, 4 when it ends at a waypoint no route reaches inside the
    /// operating area (`[mission] on_unreachable`, docs/route.md), 1 for
    /// any other failure.
    Sim(SimArgs),
    /// Run missions over many worlds and settings, on every core.
    ///
    /// Run missions on many worlds under many settings, on every core: each
    /// world (--world, --seeds) with each combination of the values given to
    /// --set (or in --grid). Writes table.csv/json (one row per run),
    /// summary.csv/json (one per setting) and sweep.png to --out, keeping
    /// each run's row as it finishes: an interrupted sweep carries on with
    /// --resume. Exit status 0 when every run was done (whatever its outcome),
    /// 130 when interrupted. On a cluster, each task runs one --shard K/N and
    /// `arcnav sweep merge` joins them.
    #[command(args_conflicts_with_subcommands = true)]
    Sweep(SweepArgs),
    /// Replay a log through the pipeline and compare the decisions.
    ///
    /// Replay an LCM log (POSE, RANGE_IMAGE, WAYPOINTS) through perception,
    /// local map, behaviours and arbiter in log time; write the recomputed
    /// decisions to --out and compare them with the ones the log recorded.
    ///
    /// A ROS 1 bag (.bag) or a ROS 2 bag (its .mcap file) replays the same way: its
    /// sensor_msgs/PointCloud2 topic becomes range images (an organized
    /// cloud keeps its rows and columns; a cloud with a `ring` field is
    /// binned by ring and azimuth; any other on the configured sensor's
    /// grid), its nav_msgs/Odometry, geometry_msgs/PoseStamped or
    /// PoseWithCovarianceStamped (or /tf) the vehicle's pose, /tf_static the
    /// sensor's mount. Topics are found when there is one of each kind
    /// (--cloud, --pose, --vehicle-frame otherwise); waypoints from
    /// --waypoints or --goal-ahead.
    ///
    /// Exit status: 0 all input used, 3 some input was lost (listed), 1 error.
    Replay(ReplayArgs),
    /// Drive live: every node in this process, on LCM.
    ///
    /// Drive live: every node in this process, a thread each. Takes POSE,
    /// RANGE_IMAGE* and WAYPOINTS from LCM and publishes STEERING_COMMAND at
    /// pipeline.command_rate_hz (and at once on new obstacle cells). Commands
    /// stop when poses, images or obstacle-avoidance votes go stale; Ctrl-C or
    /// SIGTERM publishes a final stop and exits.
    Run(LiveArgs),
    /// Run one node as its own process on LCM.
    ///
    /// Run one node as its own process on LCM, like the original system
    /// spread over workstations: perception (RANGE_IMAGE* → OBSTACLE_CELLS),
    /// localmap (→ LOCAL_MAP), behaviour NAME (LOCAL_MAP → ARC_VOTES_NAME) or
    /// arbiter (ARC_VOTES_* → STEERING_COMMAND).
    Node {
        #[command(subcommand)]
        node: NodeCommand,
    },
    /// The vehicle's side: verified commands in, what to execute out.
    ///
    /// The vehicle's side of the command interface, for a controller to run
    /// beside it: takes STEERING_COMMAND from the bus (only commands with a
    /// valid, fresh tag when [bus.auth] is on; forged, tampered, replayed and
    /// expired ones are refused and counted) and, at --rate, hands over what
    /// to execute: the newest command while it is fresh, a stop when
    /// commands stop arriving within --timeout, and a stop when it exits.
    /// Out as JSON lines (--print) and/or as plain STEERING_COMMAND on the
    /// controller's own LCM link (--forward).
    Vehicle(VehicleArgs),
    /// Draw one decision of a log: map, arcs by vote, who vetoed what.
    ///
    /// Picture of one decision of a log: the local map, the vehicle, the arcs
    /// coloured by fused vote, each behaviour's votes and what they rested on
    /// (the route's planned path, the point it steered for, the ground it
    /// remembers as obstacles or shut), and who vetoed what.
    Render(RenderArgs),
    /// Write an LCM log as MCAP for Foxglove, or as a ROS 2 bag.
    ///
    /// --mcap: the format Foxglove opens, with Foxglove's schemas: range
    /// images as point clouds in the vehicle frame, obstacle cells, local map
    /// and waypoints as 3-D scenes, the pose and world → vehicle transforms,
    /// the arcs coloured by fused vote, each behaviour's votes and the command
    /// as plottable series.
    ///
    /// --bag: a ROS 2 bag (one .mcap file) of standard messages only, for
    /// RViz (`ros2 bag play`) and every ROS 2 tool: organized PointCloud2s in
    /// each sensor's frame, nav_msgs/Odometry on /odom, odom → base_link on
    /// /tf, the mounts on /tf_static, the commands as
    /// ackermann_msgs/AckermannDriveStamped on /cmd, cells, map, waypoints and
    /// arcs as visualization_msgs/MarkerArray. `arcnav replay` reads it back
    /// to the log's decisions. Every message keeps its log time.
    Export(ExportArgs),
    /// Run paper 000's detection experiment per evaluator and sensor.
    ///
    /// The detection experiment of paper 000 (§6, Fig. 5) at this vehicle's
    /// scale: blocks of several heights and a glass block that returns
    /// nothing, straight ahead on flat ground at several distances, many
    /// noisy frames each; per evaluator and sensor, the share of frames
    /// that report the block untraversable and the share with a false
    /// alarm. Writes detection.txt, detection.json and detection.png to --out
    Detect(DetectArgs),
    /// List the terrain evaluators perception.evaluator can name.
    ///
    /// List the terrain evaluators `perception.evaluator` can name (the
    /// papers they come from; configure each in [perception.NAME])
    Evaluators,
    /// Print the resolved configuration, or check a file.
    ///
    /// Print the resolved configuration (defaults, FILE over them, and what
    /// follows from both) as TOML, each key marked with where its value came
    /// from; or validate FILE with --check.
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
    /// Terrain evaluator (sets perception.evaluator): cells (002, the
    /// default), height_diff (000) or pca (001); `arcnav evaluators`
    /// describes them.
    #[arg(long, value_name = "NAME")]
    evaluator: Option<String>,
    /// Write a local-map picture every S simulated seconds.
    #[arg(long, value_name = "S")]
    snapshot_every: Option<f64>,
    /// Leave range images out of the log (replay and render then cannot re-run
    /// perception: give them --recorded-cells to use the logged cells).
    #[arg(long)]
    no_images: bool,
    /// Save the world (e.g. a generated one) as TOML to this file.
    #[arg(long, value_name = "FILE")]
    save_world: Option<PathBuf>,
    /// Also write the run as MCAP for Foxglove to this file (as arcnav export --mcap).
    #[arg(long, value_name = "FILE")]
    mcap: Option<PathBuf>,
    /// Also write the run as a ROS 2 bag (.mcap) to this file (as arcnav export --bag).
    #[arg(long, value_name = "FILE")]
    bag: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("outputs").required(true).multiple(true).args(["mcap", "bag"])))]
struct ExportArgs {
    /// The LCM event log (arcnav sim's mission.lcm, lcm-logger's, arcnav replay --out's).
    log: PathBuf,
    /// Write an MCAP file for Foxglove (Foxglove's own schemas: scenes,
    /// point clouds, transforms; votes, decisions and the guard as JSON).
    #[arg(long, value_name = "FILE")]
    mcap: Option<PathBuf>,
    /// Write a ROS 2 bag (one .mcap file, CDR) of standard messages for
    /// RViz, `ros2 bag play` and Foxglove: PointCloud2, Odometry, /tf,
    /// /tf_static, AckermannDriveStamped, MarkerArray. `arcnav replay`
    /// reads it back.
    #[arg(long, value_name = "FILE")]
    bag: Option<PathBuf>,
    /// Configuration (arc set and arbiter weights for the fused votes drawn
    /// on /arcs; default: the defaults).
    #[arg(long)]
    config: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct SweepArgs {
    /// A world: an embedded world's name (arcnav sim --list) or a world file;
    /// repeatable.
    #[arg(long = "world", value_name = "NAME|FILE")]
    worlds: Vec<String>,
    /// Generated worlds from seeds A up to B (B excluded), e.g. 0..50.
    #[arg(long, value_name = "A..B")]
    seeds: Option<String>,
    /// Difficulty of the generated worlds.
    #[arg(long, value_enum, default_value = "moderate", requires = "seeds")]
    difficulty: DifficultyArg,
    /// A configuration key and the values to run it at, e.g.
    /// arbiter.cruise_speed_mps=2.5,4,6; repeatable: every combination runs.
    #[arg(long = "set", value_name = "KEY=V1,V2,…")]
    sets: Vec<String>,
    /// A TOML file of keys to sweep, each with its values:
    /// "arbiter.cruise_speed_mps" = [2.5, 4.0, 6.0].
    #[arg(long, value_name = "FILE")]
    grid: Option<PathBuf>,
    /// Base configuration (defaults merged with it) the settings change.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "out/sweep")]
    out: PathBuf,
    /// Carry on an interrupted sweep in --out (the same worlds and settings).
    #[arg(long)]
    resume: bool,
    /// Runs at a time, 1 to 1024 (default: one per core; never more than there are runs).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Run only the K-th of N parts of the plan (runs K-1, K-1+N, …), e.g. one
    /// task of a cluster's array job; `arcnav sweep merge` joins the parts.
    #[arg(long, value_name = "K/N", value_parser = arcnav::sweep::Shard::parse)]
    shard: Option<arcnav::sweep::Shard>,
    #[command(subcommand)]
    action: Option<SweepAction>,
}

#[derive(Debug, Subcommand)]
enum SweepAction {
    /// Join the directories of a sweep's shards into one sweep.
    ///
    /// Join the output directories of `arcnav sweep --shard K/N` runs (all N of
    /// them, each complete) into one sweep directory: sweep.json, rows.jsonl,
    /// the tables and sweep.png, as one unsharded sweep writes them. Refuses
    /// directories of different plans (worlds, settings, base configuration),
    /// a shard given twice and a shard missing or incomplete.
    Merge(SweepMergeArgs),
}

#[derive(Debug, clap::Args)]
struct SweepMergeArgs {
    /// The shards' output directories.
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Directory of the merged sweep (new, or one holding no sweep).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
struct DetectArgs {
    /// Terrain evaluator to test; repeatable (default: every built-in one).
    #[arg(long = "evaluator", value_name = "NAME")]
    evaluators: Vec<String>,
    /// Sensor preset; repeatable (default: erim).
    #[arg(long = "sensor", value_enum)]
    sensors: Vec<SensorArg>,
    /// Heights of the solid blocks, m, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.05,0.1,0.15,0.2,0.3")]
    heights: Vec<f64>,
    /// Leave out the glass block.
    #[arg(long)]
    no_glass: bool,
    /// Distances of the blocks' near face from the vehicle, m, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "4,6,8,10,12,15,20,25,30")]
    distances: Vec<f64>,
    /// Noisy frames per block and distance (000: 120).
    #[arg(long, default_value_t = 120)]
    frames: u32,
    /// Configuration file (its [perception] and [sim] noise are used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "out/detect")]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
struct ReplayArgs {
    /// The LCM event log (written by arcnav sim, lcm-logger or any LCM program
    /// using the arcnav types), a ROS 1 .bag, or a ROS 2 bag's .mcap file.
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
    /// Keep and write the decisions from this many seconds into the log on
    /// (the log before it is replayed to bring the map, the waypoint
    /// progress and the behaviours to their state there).
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
    /// A bag's point-cloud topic (sensor_msgs/PointCloud2), when it has
    /// several.
    #[arg(long, value_name = "TOPIC")]
    cloud: Option<String>,
    /// A bag's pose topic (nav_msgs/Odometry, geometry_msgs/PoseStamped or
    /// PoseWithCovarianceStamped), or /tf for the chain of frames to the
    /// vehicle's, when it has several.
    #[arg(long, value_name = "TOPIC")]
    pose: Option<String>,
    /// The vehicle's frame in a bag (default: the odometry's child frame,
    /// else base_link).
    #[arg(long, value_name = "FRAME")]
    vehicle_frame: Option<String>,
    /// Columns per slice of a bag's clouds that carry per-point times (a
    /// field t, time, timestamp or time_offset): each cloud is streamed to
    /// perception as slices of columns at their times, as a lidar's packets
    /// arrive; 0 makes each cloud one image at its stamp.
    #[arg(long, value_name = "N", default_value_t = arcnav::bag::SLICE_LINES)]
    slice_lines: usize,
    /// With no waypoints: one this many metres ahead of the first pose.
    #[arg(long, value_name = "M", conflicts_with = "waypoints")]
    goal_ahead: Option<f64>,
    /// Sensor preset (sets sensor.preset): a bag's unorganized clouds are
    /// binned on its grid.
    #[arg(long, value_enum, conflicts_with = "compare_config")]
    sensor: Option<SensorArg>,
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
    /// Use the log's OBSTACLE_CELLS instead of recomputing them (what a log
    /// without range images, `arcnav sim --no-images`, is drawn from anyway).
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

#[derive(Debug, clap::Args)]
struct VehicleArgs {
    #[command(flatten)]
    live: LiveArgs,
    /// Hand over what to execute this often, Hz, at most 1000 and at least
    /// twice per --timeout (a stop is then at most half a timeout late).
    #[arg(long, value_name = "HZ", default_value_t = 50.0)]
    rate: f64,
    /// Stop when the newest accepted command was received longer ago than
    /// this, s, at most 60 (default: three command periods, 3 /
    /// pipeline.command_rate_hz).
    #[arg(long, value_name = "S")]
    timeout: Option<f64>,
    /// Print what to execute on stdout, one JSON line per tick: wall_us,
    /// state (following, no_command_yet, stale, shutting_down),
    /// command_utime, curvature, speed_mps, arc_index, guard (off, clear,
    /// slow, stop) and guard_reason. With [guard] enabled (the default) the
    /// bridge also takes POSE and RANGE_IMAGE* and stops or slows the
    /// vehicle on hazards along the commanded path, tilt or missing data,
    /// publishing each verdict on GUARD_STATUS.
    #[arg(long)]
    print: bool,
    /// Republish what to execute, unsigned, as STEERING_COMMAND on this LCM
    /// URL: the controller's own link, e.g. udpm://239.255.76.68:7669?ttl=0.
    #[arg(long, value_name = "URL")]
    forward: Option<String>,
    /// The commands to follow: STEERING_COMMAND (the arbiter's), or
    /// STEERING_COMMAND_GUARDED when `arcnav node guard` runs between the
    /// arbiter and the vehicle.
    #[arg(long, value_name = "CHANNEL", default_value = "STEERING_COMMAND")]
    commands: String,
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
    /// The guard on its own: STEERING_COMMAND, POSE, RANGE_IMAGE* →
    /// STEERING_COMMAND_GUARDED, GUARD_STATUS.
    ///
    /// The guard as a node of its own between the arbiter and the vehicle
    /// (as Nav2's collision monitor sits between the controller and the
    /// base): every command is judged on the raw returns, tilt and the
    /// age of the data, and republished as it is let through on
    /// STEERING_COMMAND_GUARDED (run `arcnav vehicle --commands
    /// STEERING_COMMAND_GUARDED`), with its verdict on GUARD_STATUS.
    Guard(LiveArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum DifficultyArg {
    Easy,
    Moderate,
    Hard,
}

impl From<DifficultyArg> for arcnav_sim::Difficulty {
    fn from(d: DifficultyArg) -> Self {
        match d {
            DifficultyArg::Easy => Self::Easy,
            DifficultyArg::Moderate => Self::Moderate,
            DifficultyArg::Hard => Self::Hard,
        }
    }
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum SensorArg {
    Erim,
    Lidar64,
    Lidar128,
    #[value(name = "depth_camera")]
    DepthCamera,
}

impl From<SensorArg> for arcnav_perception::SensorPreset {
    fn from(s: SensorArg) -> Self {
        match s {
            SensorArg::Erim => Self::Erim,
            SensorArg::Lidar64 => Self::Lidar64,
            SensorArg::Lidar128 => Self::Lidar128,
            SensorArg::DepthCamera => Self::DepthCamera,
        }
    }
}

fn main() -> ExitCode {
    arcnav::keep_freed_memory();
    let cli = Cli::parse();
    // A sweep's many missions would bury its progress in their log lines:
    // warnings only, unless asked.
    let quiet = match cli.command {
        Command::Sweep(_) if cli.verbose == 0 => cli.quiet.max(1),
        _ => cli.quiet,
    };
    init_logging(cli.verbose, quiet);
    if matches!(cli.command, Command::Config { .. } | Command::Evaluators) {
        end_quietly_when_the_reader_leaves();
    }
    match run(cli.command) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {}", message(&err));
            ExitCode::FAILURE
        }
    }
}

/// For commands that only print (no socket, no file half written): a
/// reader that leaves early (`arcnav config | head`) ends the process
/// quietly, as it does any Unix filter, instead of the panic Rust's
/// ignored SIGPIPE turns a failed `println!` into. Commands that serve or
/// write files keep SIGPIPE ignored, so a closed connection is an error
/// they handle.
fn end_quietly_when_the_reader_leaves() {
    // SAFETY: called once, before any thread is started; SIG_DFL is a
    // valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The error and its causes, each said once: a cause that an error's own
/// message already ends with is not repeated.
fn message(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let cause = cause.to_string();
        if text.ends_with(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
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
        Command::Sim(args) => cli::sim(args),
        Command::Sweep(args) => cli::sweep(args),
        Command::Detect(args) => cli::detect(args).map(|()| ExitCode::SUCCESS),
        Command::Evaluators => {
            let registry = arcnav_perception::EvaluatorRegistry::builtin();
            for name in registry.names() {
                println!("{name:<12} {}", registry.about(name).unwrap_or_default());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Replay(args) => cli::replay(args),
        Command::Render(args) => cli::render(args),
        Command::Export(args) => cli::export(args),
        Command::Run(args) => cli::live(None, args),
        Command::Vehicle(args) => cli::vehicle(args),
        Command::Node { node } => match node {
            NodeCommand::Perception(args) => cli::live(Some(NodeKind::Perception), args),
            NodeCommand::Localmap(args) => cli::live(Some(NodeKind::LocalMap), args),
            NodeCommand::Arbiter(args) => cli::live(Some(NodeKind::Arbiter), args),
            NodeCommand::Guard(args) => cli::live(Some(NodeKind::Guard), args),
            NodeCommand::Behaviour { name, live: args } => {
                cli::live(Some(NodeKind::Behaviour(name)), args)
            }
        },
        Command::Config { file, check } => {
            let config = Resolved::load_or_default(
                file.as_deref(),
                &arcnav_behaviours::Registry::builtin(),
            )?;
            if check {
                let file = file.context("--check needs a FILE")?;
                // What `run` would refuse at start is not valid either: the
                // key file is read and checked as the live commands do.
                let base = file.parent().unwrap_or(std::path::Path::new("."));
                let auth = &config.bus.auth;
                auth.policy(base).with_context(|| {
                    format!("`bus.auth.key_file` ({})", auth.key_file.display())
                })?;
                println!("{}: valid", file.display());
            } else {
                match &file {
                    Some(f) => println!(
                        "# the resolved configuration: the defaults, {} over them, and what \
                         follows from both; each key says where its value came from",
                        f.display()
                    ),
                    None => println!(
                        "# the resolved configuration: the defaults and what follows from them; \
                         each key says where its value came from"
                    ),
                }
                let cruise = &config.cruise;
                println!(
                    "# cruise: {:.2} m/s asked (arbiter.cruise_speed_mps), {:.2} m/s driven{}",
                    cruise.asked_mps,
                    cruise.mps,
                    cruise.cap_mps.map_or(String::new(), |cap| format!(
                        " (lookahead.hole_speed_cap allows {cap:.2} m/s)"
                    ))
                );
                print!("{}", config.to_toml_with_origins());
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
