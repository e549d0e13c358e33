//! `arcnav replay`: a log through the pipeline, compared with what it recorded.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use crate::ReplayArgs;
use anyhow::Context as _;
use arcnav::Resolved;
use arcnav_behaviours::Registry;

use super::logged::{config_of_log, files_read};

pub fn replay(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    use arcnav::replay::{ReplayOptions, compare, replay as run_replay};
    let registry = Registry::builtin();
    check_pace_and_window(&args)?;
    // A log `arcnav sim` wrote is replayed with the configuration beside it
    // unless told otherwise: replayed with the defaults, a run made with
    // another evaluator or sensor had agreed on 0.07 % of its decisions.
    let configs: Vec<(String, Resolved)> = match &args.compare_config {
        Some(pair) => pair
            .iter()
            .map(|c| Ok((c.display().to_string(), Resolved::load(c, &registry)?)))
            .collect::<anyhow::Result<_>>()?,
        None => vec![(
            "replayed".to_owned(),
            config_of_log(
                &args.log,
                args.config.as_deref(),
                &registry,
                args.sensor.map(Into::into),
            )?,
        )],
    };
    let mut inputs = files_read(&args.log, configs.iter().map(|(_, c)| c));
    inputs.extend(args.waypoints.clone().map(|w| ("the waypoints file", w)));
    let outputs: Vec<&std::path::Path> = args
        .out
        .iter()
        .chain(&args.json)
        .map(PathBuf::as_path)
        .collect();
    arcnav::output::check_outputs(&outputs, &inputs)?;
    let options = ReplayOptions {
        from_s: args.from,
        to_s: args.to,
        out: args.out.clone(),
        waypoints: args.waypoints.as_deref().map(load_waypoints).transpose()?,
        speed: args.speed,
        recorded_cells: args.recorded_cells,
        stop_at_s: None,
        bag: arcnav::bag::BagOptions {
            cloud: args.cloud.clone(),
            pose: args.pose.clone(),
            vehicle_frame: args.vehicle_frame.clone(),
            slice_lines: args.slice_lines,
        },
        goal_ahead_m: args.goal_ahead,
    };
    let size = std::fs::metadata(&args.log)
        .with_context(|| format!("cannot read the log {}", args.log.display()))?
        .len();
    let bar = super::terminal::progress_bar(
        size,
        "{spinner} replaying [{bar:30}] {bytes}/{total_bytes} ({eta})",
    );
    let mut runs = Vec::new();
    let n = configs.len();
    for (i, (label, config)) in configs.into_iter().enumerate() {
        // Of two configurations compared, the second's replay is the one
        // `--out` records.
        let opts = ReplayOptions {
            out: if i + 1 == n {
                options.out.clone()
            } else {
                None
            },
            ..options.clone()
        };
        bar.set_position(0);
        let result = run_replay(&args.log, &config, &opts, &mut |p| bar.set_position(p))?;
        runs.push((label, config, result));
    }
    bar.finish_and_clear();
    let (_, config, last) = &runs[runs.len() - 1];
    let origin = last.span.map_or(0, |s| s.0);
    let i = &last.inputs;
    println!("log           {}", args.log.display());
    let configurations: Vec<String> = runs
        .iter()
        .map(|(_, c, _)| match c.given().source() {
            Some(path) => path.display().to_string(),
            None => "the defaults".to_owned(),
        })
        .collect();
    println!("configuration {}", configurations.join(" vs "));
    if let Some(bag) = &last.problems.bag {
        print_bag(bag);
    }
    println!(
        "inputs        {} poses, {} range images{}, {} waypoint lists{}",
        i.poses,
        i.images,
        if i.slices > 0 {
            format!(", {} range slices", i.slices)
        } else {
            String::new()
        },
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
    for run in &last.external {
        let counts: Vec<String> = run
            .counters
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        println!("{:<13} {}", run.name, counts.join(", "));
        if let Some(why) = &run.fault {
            println!("{:<13} ENDED: {why}", run.name);
        }
    }
    super::terminal::print_guard(last.guard.as_ref());
    if let Some(f) = &last.fused {
        super::terminal::print_fused(f);
    }
    let weight_of = |c: &Resolved| {
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
        if last.problems.outside_window > 0 || last.problems.before_window > 0 {
            // `--from` past the end: the log may well hold commands.
            println!("comparison    no STEERING_COMMAND between --from and --to to compare with");
        } else {
            println!("comparison    the log holds no STEERING_COMMAND to compare with");
        }
    }
    for c in &comparisons {
        print_comparison(c, args.show);
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
            "configurations": configurations,
            "inputs": last.inputs,
            "decisions": last.cycles.len(),
            "problems": problems,
            "input_lost": problems.lost_input(),
            "comparisons": comparisons,
            "guard": last.guard,
            "fused": last.fused,
        });
        arcnav::output::write_file(path, serde_json::to_string_pretty(&json)?.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(if problems.lost_input() {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    })
}

/// A bag's topics and what the replay made of them.
fn print_bag(bag: &arcnav::bag::BagSummary) {
    println!(
        "bag           {}: {} topic(s)",
        bag.format,
        bag.topics.len()
    );
    for t in &bag.topics {
        let what = match (t.used_as, &t.skipped_because) {
            (Some(used), Some(why)) => format!("chosen as the {used}, but not read: {why}"),
            (Some(used), None) => format!("used: {used}"),
            (None, Some(why)) => format!("skipped: {why}"),
            (None, None) => "skipped".to_owned(),
        };
        println!(
            "              {} ({}, {} messages): {what}",
            t.topic, t.type_name, t.messages
        );
    }
    let clouds: Vec<String> = bag.clouds.iter().map(|(l, n)| format!("{n} {l}")).collect();
    println!(
        "clouds        {} from {}: {} points, {} no return, {} moved to the pixel they fall in, \
         {} behind a nearer one, {} off the grid",
        if clouds.is_empty() {
            "none".to_owned()
        } else {
            clouds.join(", ")
        },
        bag.cloud_topic,
        bag.points.points,
        bag.points.no_return,
        bag.points.moved,
        bag.points.hidden,
        bag.points.off_grid
    );
    if let Some((field, lines)) = &bag.streamed {
        println!(
            "              streamed as {} slices of {lines} columns, each at its points' times (field {field})",
            bag.slices
        );
    }
    println!(
        "poses         {} from {}, vehicle frame {}",
        bag.poses, bag.poses_from, bag.vehicle_frame
    );
    println!("mount         from {}", bag.mount_from);
}

/// `--speed`, `--from` and `--to` make sense.
fn check_pace_and_window(args: &ReplayArgs) -> anyhow::Result<()> {
    if let Some(speed) = args.speed {
        anyhow::ensure!(
            speed.is_finite() && (1e-3..=1e6).contains(&speed),
            "--speed {speed}: must be 0.001 to 1000000 (times real time)"
        );
    }
    for (flag, value) in [("--from", args.from), ("--to", args.to)] {
        if let Some(s) = value {
            anyhow::ensure!(
                s.is_finite() && s >= 0.0,
                "{flag} {s}: must be a number of seconds from the log's start, 0 or more"
            );
        }
    }
    if let (Some(from), Some(to)) = (args.from, args.to) {
        anyhow::ensure!(from < to, "--from {from} --to {to}: the range is empty");
    }
    Ok(())
}

/// One comparison's lines: how many decisions agree, the first
/// divergence, the largest curvature difference, and up to `show` of the
/// differences.
fn print_comparison(c: &arcnav::replay::Comparison, show: usize) {
    let Some(percent) = c.agreement_percent else {
        println!(
            "comparison    {} vs {}: nothing to compare: no decision of one is at the time of a decision of the other",
            c.a, c.b
        );
        return;
    };
    println!(
        "comparison    {} vs {}: {} decisions compared, {} agree ({percent:.2}%)",
        c.a, c.b, c.compared, c.agreeing
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
    let mut movers: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    for d in &c.differences {
        *movers
            .entry(
                d.moved_by
                    .as_deref()
                    .unwrap_or("none (a stop, or votes alike)"),
            )
            .or_default() += 1;
    }
    if !movers.is_empty() {
        let mut movers: Vec<_> = movers.into_iter().collect();
        movers.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
        let movers: Vec<String> = movers.iter().map(|(b, n)| format!("{b} {n}")).collect();
        println!("              differences moved by: {}", movers.join(", "));
    }
    for d in c.differences.iter().take(show) {
        let arc =
            |x: &arcnav::replay::Decided| x.arc.map_or("stop".to_owned(), |a| format!("arc {a}"));
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
    if c.differences.len() > show {
        println!(
            "              ... {} differences in all (--show N, --json FILE)",
            c.differences.len()
        );
    }
}

/// Waypoints from a TOML file with [[waypoints]] entries (a world file works).
fn load_waypoints(path: &Path) -> anyhow::Result<arcnav_behaviours::Mission> {
    let text = arcnav_vehicle::files::read_text(path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    arcnav::replay::parse_waypoints(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}
