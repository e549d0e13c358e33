//! `arcnav run` and `arcnav node …`: live operation on LCM.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use crate::LiveArgs;
use anyhow::Context as _;
use arcnav::Config;
use arcnav::live::node::NodeKind;
use arcnav_behaviours::Registry;

/// `arcnav run` (no node) or `arcnav node …`.
pub fn live(node: Option<NodeKind>, args: LiveArgs) -> anyhow::Result<ExitCode> {
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
    let base = args
        .config
        .as_deref()
        .and_then(std::path::Path::parent)
        .unwrap_or(std::path::Path::new("."));
    let auth = &config.bus.auth;
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
