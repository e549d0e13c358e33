//! `arcnav run` and `arcnav node …`: live operation on LCM.

use std::process::ExitCode;

use crate::{LiveArgs, VehicleArgs};
use anyhow::Context as _;
use arcnav::Resolved;
use arcnav::live::LiveReport;
use arcnav::live::node::NodeKind;
use arcnav::live::threaded::StopWhen;
use arcnav_behaviours::Registry;
use arcnav_bus::transport::Lcm;

/// `arcnav run` (no node) or `arcnav node …`.
pub fn live(node: Option<NodeKind>, args: LiveArgs) -> anyhow::Result<ExitCode> {
    use arcnav::live::threaded::LiveOptions;
    let registry = Registry::builtin();
    let Started { config, lcm, stop } = start(&args, &registry)?;
    let options = LiveOptions {
        stop,
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
        None => arcnav::live::threaded::run(&config, lcm, &options)?,
        Some(kind) => arcnav::live::node::run_node(kind, &config, lcm, &options)?,
    };
    tracing::info!(
        commands = report.commands,
        stops = report.stops,
        "{what} stopped after {:.1} s",
        report.wall_s
    );
    finish(&args, &report)
}

/// `--stats` and `--json`.
fn finish(args: &LiveArgs, report: &LiveReport) -> anyhow::Result<ExitCode> {
    if args.stats {
        print!("{}", report.table());
    }
    if let Some(path) = &args.json {
        arcnav::output::write_file(path, serde_json::to_string_pretty(report)?.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What every live command starts from.
struct Started {
    config: Resolved,
    /// Authenticating when `[bus.auth]` names a key.
    lcm: Lcm,
    stop: StopWhen,
}

/// Loads the configuration, installs the signal handlers, reads the key
/// and opens LCM; warns when multicast leaves the host unauthenticated.
fn start(args: &LiveArgs, registry: &Registry) -> anyhow::Result<Started> {
    let config = Resolved::load_or_default(args.config.as_deref(), registry)?;
    let after = match args.duration {
        Some(s) if s > 0.0 && s.is_finite() => Some(std::time::Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration {s}: must be a positive number of seconds"),
        None => None,
    };
    let flag = super::terminal::interrupt_flag()?;
    let base = args
        .config
        .as_deref()
        .and_then(std::path::Path::parent)
        .unwrap_or(std::path::Path::new("."));
    let auth = &config.bus.auth;
    // The figures written at exit must not replace what the run reads.
    if let Some(json) = &args.json {
        arcnav::output::check_outputs(&[json], &config.files_read())?;
    }
    let policy = auth.policy(base).with_context(|| {
        format!(
            "authentication is configured ([bus.auth] key_file = {:?}) but its key cannot be used",
            auth.key_file
        )
    })?;
    if let Ok(arcnav_bus::transport::url::LcmUrl::Udpm(url)) = args.lcm.parse()
        && url.ttl > 0
    {
        if policy.is_none() {
            tracing::warn!(
                lcm = %args.lcm,
                "multicast leaves this host (ttl={}) and authentication is off: any machine on \
                 the network can publish STEERING_COMMAND, ARC_VOTES_*, WAYPOINTS or POSE and be \
                 believed (votes from behaviours that are not configured are ignored); set \
                 [bus.auth] key_file to sign and verify them",
                url.ttl
            );
        } else {
            tracing::info!(
                lcm = %args.lcm,
                channels = ?auth.channels,
                "multicast leaves this host (ttl={}); messages on the authenticated channels \
                 without a valid, fresh tag are refused, other channels are open",
                url.ttl
            );
        }
    }
    let mut lcm = arcnav_bus::transport::Lcm::new(&args.lcm)
        .with_context(|| format!("cannot open LCM at {}", args.lcm))?;
    if let Some(policy) = policy {
        tracing::info!(key = %auth.key_path(base).display(), channels = ?auth.channels, "authentication on");
        lcm = lcm.authenticate(policy);
    }
    Ok(Started {
        config,
        lcm,
        stop: StopWhen { flag, after },
    })
}

/// `arcnav vehicle`: verified commands in, what to execute out.
pub fn vehicle(args: VehicleArgs) -> anyhow::Result<ExitCode> {
    use arcnav::live::threaded::LiveOptions;
    use arcnav::live::vehicle::{BridgeOptions, run_bridge};
    use arcnav_bus::messages::channels;
    use std::io::Write as _;

    let live = &args.live;
    if !(args.rate > 0.0 && args.rate <= 1000.0) {
        anyhow::bail!("--rate {}: must be in (0, 1000] Hz", args.rate);
    }
    // The vehicle keeps executing its last command this long when commands
    // stop: a watchdog, bounded as [live] pose_timeout_s is (1e300 had
    // been taken, and the vehicle would never have stopped).
    const MAX_TIMEOUT_S: f64 = 60.0;
    if let Some(timeout_s) = args.timeout
        && !(timeout_s > 0.0 && timeout_s <= MAX_TIMEOUT_S)
    {
        anyhow::bail!(
            "--timeout {timeout_s}: must be more than 0 and at most {MAX_TIMEOUT_S} s (the \
             vehicle executes its last command this long when commands stop)"
        );
    }
    let registry = Registry::builtin();
    let Started { config, lcm, stop } = start(live, &registry)?;
    let timeout_s = args
        .timeout
        .unwrap_or(3.0 / config.pipeline.command_rate_hz);
    // A stop reaches the controller up to one hand-over period after the
    // watchdog trips: at most half the timeout late (at 0.5 Hz it had come
    // 2 s after a 0.3 s timeout).
    let min_rate = 2.0 / timeout_s;
    anyhow::ensure!(
        args.rate >= min_rate,
        "--rate {}: a stop would reach the controller up to {:.3} s after the {timeout_s} s \
         watchdog timeout; hand over at least {min_rate:.1} Hz (twice per timeout)",
        args.rate,
        1.0 / args.rate
    );
    if lcm.auth_stats().is_none() {
        tracing::warn!(
            lcm = %live.lcm,
            "authentication is off: this vehicle follows any STEERING_COMMAND published on the \
             bus; set [bus.auth] key_file to follow only commands signed with the group key"
        );
    } else if !lcm.authenticates(&args.commands) {
        anyhow::bail!(
            "[bus.auth] channels {:?} do not include {}: the vehicle would follow unsigned \
             commands; add \"{}\"",
            config.bus.auth.channels,
            args.commands,
            args.commands
        );
    }
    anyhow::ensure!(
        args.commands == channels::STEERING_COMMAND
            || args.commands == channels::STEERING_COMMAND_GUARDED,
        "--commands {}: the vehicle follows {} (the arbiter's) or {} (behind arcnav node guard)",
        args.commands,
        channels::STEERING_COMMAND,
        channels::STEERING_COMMAND_GUARDED
    );
    let mut lcm = lcm;
    let forward = match &args.forward {
        Some(url) => {
            let parsed: arcnav_bus::transport::url::LcmUrl = url.parse()?;
            // Compared by what the buses are (group and port), not by how
            // the URLs are spelt: `udpm://` is the default bus too.
            if parsed.same_bus(lcm.url()) {
                anyhow::bail!(
                    "--forward {url} is the bus the commands come from ({}): give the controller \
                     a link of its own (e.g. udpm://239.255.76.68:7669?ttl=0)",
                    live.lcm
                );
            }
            anyhow::ensure!(
                parsed != arcnav_bus::transport::url::LcmUrl::Memq,
                "--forward {url}: an in-process queue no controller hears; give the controller's \
                 bus (e.g. udpm://239.255.76.68:7669?ttl=0)"
            );
            let to =
                Lcm::new(url).with_context(|| format!("cannot open LCM at --forward {url}"))?;
            let publisher = to.publisher();
            // Whatever route brings the forwards back, they are not commands.
            lcm.ignore_from(&publisher);
            Some(publisher)
        }
        None => None,
    };
    let options = LiveOptions {
        stop,
        ..LiveOptions::default()
    };
    let bridge = BridgeOptions {
        channel: args.commands.clone(),
        rate_hz: args.rate,
        timeout_s,
        status_period_s: config.live.status_period_s,
    };
    tracing::info!(
        lcm = %live.lcm,
        rate_hz = args.rate,
        timeout_s,
        forward = args.forward.as_deref().unwrap_or("-"),
        guard = config.guard.enabled,
        "vehicle bridge: executing verified commands, stop when none arrive within the timeout \
         or the guard sees a hazard on the commanded path; Ctrl-C or SIGTERM stops"
    );
    let mut stdout = std::io::stdout().lock();
    let mut forward_failed = false;
    // The guard, independent of the pipeline: the sensor's images and the
    // pose in, every command judged before it is handed over.
    let guard = config
        .guard
        .enabled
        .then(|| arcnav_guard::Guard::new(&config.guard, &config.vehicle, &config.sensors));
    if guard.is_none() {
        tracing::warn!(
            "[guard] enabled = false: commands are handed over as the pipeline made them"
        );
    }
    let report = run_bridge(lcm, &options, &bridge, guard, |executed| {
        if args.print {
            match serde_json::to_string(executed) {
                Ok(line) => {
                    let _ = writeln!(stdout, "{line}");
                }
                Err(e) => tracing::error!(%e, "cannot write the command as JSON"),
            }
        }
        if let Some(publisher) = &forward
            && let Err(e) = publisher.publish_command(
                channels::STEERING_COMMAND,
                &executed.command(),
                config.vehicle.kinematics,
            )
            && !forward_failed
        {
            forward_failed = true;
            tracing::error!(%e, "cannot forward the command to the controller");
        }
    })?;
    drop(stdout);
    tracing::info!(
        commands = report.commands,
        "vehicle bridge stopped after {:.1} s",
        report.wall_s
    );
    finish(live, &report)
}
