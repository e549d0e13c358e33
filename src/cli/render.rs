//! `arcnav render`: the picture of one decision of a log.

use std::path::{Path, PathBuf};

use std::process::ExitCode;

use crate::{ExportArgs, RenderArgs};
use arcnav::Resolved;
use arcnav_behaviours::Registry;

use super::logged::{config_of_log, files_read};

pub fn render(args: RenderArgs) -> anyhow::Result<ExitCode> {
    use arcnav::replay::{ReplayOptions, replay as run_replay};
    let registry = Registry::builtin();
    let config = config_of_log(&args.log, args.config.as_deref(), &registry, None)?;
    anyhow::ensure!(
        args.at.is_finite() && (0.0..=1e9).contains(&args.at),
        "--at {}: must be a number of seconds from the log's start, 0 or more",
        args.at
    );
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("decision-{:.1}s.png", args.at)));
    arcnav::output::check_outputs(&[&out], &files_read(&args.log, [&config]))?;
    // A log without range images (`arcnav sim --no-images`) perceives
    // nothing: its map would be drawn empty and every arc vetoed. Its
    // recorded cells are what the vehicle drove on.
    let recorded_cells = args.recorded_cells || {
        let cells = cells_of_a_log_without_images(&args.log);
        if cells > 0 {
            eprintln!(
                "note: {} holds no range image (logged with --no-images?): drawn from its {cells} \
                 recorded OBSTACLE_CELLS, as --recorded-cells does",
                args.log.display()
            );
        }
        cells > 0
    };
    let options = ReplayOptions {
        recorded_cells,
        stop_at_s: Some(args.at),
        ..ReplayOptions::default()
    };
    let result = run_replay(&args.log, &config, &options, &mut |_| {})?;
    let origin = result
        .clock_origin
        .or(result.span.map(|s| s.0))
        .unwrap_or(0);
    let log = &result.problems.log;
    anyhow::ensure!(
        log.events > 0,
        "no LCM event could be read from {} ({} bytes skipped as damaged): is it an LCM log?",
        args.log.display(),
        log.skipped_bytes + log.truncated_tail_bytes
    );
    // What the redone decision could not use: said before the picture.
    for line in result.problems.lines() {
        eprintln!("warning: {line}");
    }
    let Some(kept) = &result.kept else {
        anyhow::bail!(
            "no decision at or after {} s: the log spans {:.1} s and yielded {} decisions",
            args.at,
            result.span.map_or(0.0, |(a, b)| (b - a) as f64 * 1e-6),
            result.cycles.len()
        );
    };
    // The guard's verdict on this command (GUARD_STATUS), the gravest
    // first, when the log holds any.
    let guard = result
        .recorded_guard
        .iter()
        .filter(|g| g.command_utime == kept.at)
        .max_by_key(|g| g.verdict)
        .map(ToString::to_string);
    arcnav::render::snapshot_picture(
        &out,
        &config,
        &result.arcs,
        &kept.map,
        Some(&kept.decision),
        kept.at - origin,
        &kept.overlays,
        guard.as_deref(),
    )?;
    println!(
        "decision at {:.2} s drawn to {}",
        (kept.at - origin) as f64 * 1e-6,
        out.display()
    );
    println!("redone        {}", kept.reason);
    // What the run that wrote the log said of the same decision (DECISION;
    // a distributed run's arbiter node publishes it), if it logged it.
    match result
        .recorded_reasons
        .iter()
        .find(|((_, utime), _)| *utime == kept.at)
    {
        Some((_, logged)) => println!("as logged     {}", logged.reason),
        None => println!("as logged     (no DECISION at this time in the log)"),
    }
    match &guard {
        Some(verdict) => println!("guard         {verdict}"),
        None if !result.recorded_guard.is_empty() => println!(
            "guard         no verdict on this command in the log (a simulated run logs only the \
             guard's stops and slows, and the clear after them)"
        ),
        None => {}
    }
    Ok(ExitCode::SUCCESS)
}

/// The OBSTACLE_CELLS events of `log` when it holds no range image (or
/// slice) at all; 0 as soon as one is read, or when the log cannot be read
/// (the replay says why).
fn cells_of_a_log_without_images(log: &Path) -> u64 {
    use arcnav_bus::messages::channels;
    let Ok(reader) = arcnav_bus::log::LogReader::open(log) else {
        return 0;
    };
    let mut cells = 0;
    for event in reader {
        let Ok(event) = event else { return 0 };
        if event.channel.starts_with(channels::RANGE_IMAGE) {
            return 0;
        }
        cells += u64::from(event.channel == channels::OBSTACLE_CELLS);
    }
    cells
}

/// `arcnav export LOG --mcap OUT --bag OUT`.
pub fn export(args: ExportArgs) -> anyhow::Result<ExitCode> {
    let registry = Registry::builtin();
    let config = config_of_log(&args.log, args.config.as_deref(), &registry, None)?;
    let outputs: Vec<&std::path::Path> = args
        .mcap
        .iter()
        .chain(&args.bag)
        .map(|p| p.as_path())
        .collect();
    arcnav::output::check_outputs(&outputs, &files_read(&args.log, [&config]))?;
    if let Some(mcap) = &args.mcap {
        write_export(&args.log, mcap, &config, Export::Mcap)?;
    }
    if let Some(bag) = &args.bag {
        write_export(&args.log, bag, &config, Export::Bag)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What `arcnav export` writes.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Export {
    /// MCAP for Foxglove (`--mcap`).
    Mcap,
    /// A ROS 2 bag (`--bag`).
    Bag,
}

/// Exports `log` to `out` and says what it wrote and skipped.
pub(crate) fn write_export(
    log: &std::path::Path,
    out: &std::path::Path,
    config: &Resolved,
    format: Export,
) -> anyhow::Result<()> {
    let summary = match format {
        Export::Mcap => arcnav::export::export_mcap(log, out, config)?,
        Export::Bag => arcnav::export::export_bag(log, out, config)?,
    };
    let written: u64 = summary.topics.values().sum();
    println!(
        "{}: {written} messages on {} topics from {} events of {}",
        out.display(),
        summary.topics.len(),
        summary.events,
        log.display()
    );
    for (topic, n) in &summary.topics {
        println!("  {topic:<34} {n}");
    }
    for (channel, (n, why)) in &summary.skipped {
        eprintln!("  skipped {n} on {channel}: {why}");
    }
    if summary.damaged_bytes > 0 {
        eprintln!(
            "  skipped {} damaged bytes of the log",
            summary.damaged_bytes
        );
    }
    Ok(())
}
