//! `arcnav sim`: a simulated mission and its summary.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use crate::SimArgs;
use anyhow::Context as _;
use arcnav::mission::{LogMode, MissionOptions, MissionProgress, run_mission};
use arcnav::{Config, Resolved};
use arcnav_behaviours::Registry;
use arcnav_sim::world::EMBEDDED;
use arcnav_sim::{Difficulty, World};

pub fn sim(args: SimArgs) -> anyhow::Result<ExitCode> {
    if args.list {
        println!("embedded worlds (arcnav sim --world NAME):");
        for (name, description, _) in EMBEDDED {
            println!("  {name:<14} {description}");
        }
        println!("or --world FILE.toml, or --seed N [--difficulty easy|moderate|hard]");
        return Ok(ExitCode::SUCCESS);
    }
    let config = configuration(&args)?;
    let world = world_of(&args)?;
    // `[mission] area = "world"`: this world's area, in the config.toml
    // the run writes too.
    let config = config
        .in_world(&world.area(config.mission.area_margin_m))
        .into_owned();
    let name = world.spec.name.clone();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&name));
    // No output may overwrite what the run reads: `--save-world` onto the
    // world file given had rewritten it without its comments, and a run's
    // config.toml passed back as --config was rewritten by the run.
    let files = ["mission.lcm", "report.json", "map.png", "config.toml"].map(|f| out.join(f));
    let [log_path, report_path, map_path, config_path] = &files;
    let written: Vec<&Path> = files
        .iter()
        .map(PathBuf::as_path)
        .chain(args.save_world.as_deref())
        .chain(args.mcap.as_deref())
        .chain(args.bag.as_deref())
        .collect();
    let mut inputs = config.files_read();
    inputs.extend(world.files_read.iter().cloned());
    arcnav::output::check_outputs(&written, &inputs)?;
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create the output directory {}", out.display()))?;
    let snapshot_dir = out.join("snapshots");
    if let Some(every) = args.snapshot_every {
        let period = 1.0 / config.pipeline.command_rate_hz;
        anyhow::ensure!(
            every >= period,
            "--snapshot-every {every}: shorter than one decision cycle ({period} s at pipeline.command_rate_hz)"
        );
        std::fs::create_dir_all(&snapshot_dir)
            .with_context(|| format!("cannot create {}", snapshot_dir.display()))?;
    }
    let options = MissionOptions {
        log: Some(log_path.clone()),
        log_mode: if args.no_images {
            LogMode::NoImages
        } else {
            LogMode::All
        },
        snapshot_every_s: args.snapshot_every,
        snapshot_dir: Some(snapshot_dir),
        beside_others: false,
    };
    let sensors: Vec<&str> = config.sensors.iter().map(|s| s.id.as_str()).collect();
    eprintln!(
        "arcnav sim: {name} ({} waypoints) with the {} sensor{} and the {} evaluator at {:.1} m/s cruise",
        world.waypoints.len(),
        sensors.join(" + "),
        if sensors.len() > 1 { "s" } else { "" },
        config.perception.evaluator,
        config.cruise.asked_mps
    );
    // Faster than holes can be seen: say so before the run, not only in
    // the report.
    speed_notes(&config);
    let bar = super::terminal::progress_bar(
        world.waypoints.len() as u64,
        "{spinner} [{bar:30}] waypoint {pos}/{len} {msg}",
    );
    let world = Arc::new(world);
    let started = std::time::Instant::now();
    let run = run_mission(
        &config,
        Arc::clone(&world),
        &options,
        &mut |p: &MissionProgress| {
            bar.set_position(p.waypoint as u64);
            let wall = started.elapsed().as_secs_f64();
            bar.set_message(format!(
                "· {:.0} s · {:.0} m · {:.1} m/s · {:.0}× real time",
                p.sim_time_s,
                p.distance_m,
                p.speed_mps,
                p.sim_time_s / wall.max(1e-3)
            ));
        },
    )?;
    bar.finish_and_clear();
    arcnav::output::write_file(
        config_path,
        format!("# the configuration of this run: replay with `arcnav replay mission.lcm --config config.toml`\n{}", config.given().to_toml()).as_bytes(),
    )
    .with_context(|| format!("cannot write {}", config_path.display()))?;
    arcnav::output::write_file(
        report_path,
        serde_json::to_string_pretty(&run.report)?.as_bytes(),
    )
    .with_context(|| format!("cannot write {}", report_path.display()))?;
    arcnav::render::mission_picture(map_path, &world, &run)?;
    // Saved after the run, like every other output: a run that fails
    // leaves what it would have replaced as it was.
    if let Some(path) = &args.save_world {
        let text = toml::to_string(&world.spec).context("serialising the world")?;
        arcnav::output::write_file(path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("world saved to {}", path.display());
    }
    print_summary(&run.report, &out, &run.snapshots);
    if let Some(mcap) = &args.mcap {
        super::render::write_export(log_path, mcap, &config, super::render::Export::Mcap)?;
    }
    if let Some(bag) = &args.bag {
        super::render::write_export(log_path, bag, &config, super::render::Export::Bag)?;
    }
    Ok(if run.report.success {
        ExitCode::SUCCESS
    } else if run.report.outcome == arcnav::mission::Outcome::Unreachable {
        ExitCode::from(UNREACHABLE_EXIT)
    } else {
        ExitCode::FAILURE
    })
}

/// The configuration of `--config` (or the defaults) with the command
/// line's settings, resolved.
fn configuration(args: &SimArgs) -> anyhow::Result<Resolved> {
    let registry = Registry::builtin();
    let mut config = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    if let Some(speed) = args.speed {
        anyhow::ensure!(
            speed > 0.0 && speed.is_finite(),
            "--speed {speed}: a speed must be positive"
        );
        config.arbiter.cruise_speed_mps = speed;
        config.set_by("arbiter.cruise_speed_mps", "--speed");
        if config.vehicle.max_speed_mps < speed {
            config.vehicle.max_speed_mps = speed;
            config.set_by("vehicle.max_speed_mps", "--speed");
        }
    }
    if let Some(sensor) = args.sensor {
        super::settings::set_sensor_preset(&mut config, sensor.into())?;
    }
    if let Some(evaluator) = &args.evaluator {
        config.perception.evaluator.clone_from(evaluator);
        config.set_by("perception.evaluator", "--evaluator");
    }
    if let Some(every) = args.snapshot_every {
        anyhow::ensure!(
            every.is_finite() && every > 0.0,
            "--snapshot-every {every}: must be a positive number of seconds"
        );
    }
    config
        .resolve(&registry)
        .context("the configuration with the command-line settings")
}

/// The world `--world` names or `--seed` generates (the paper's loop by
/// default).
fn world_of(args: &SimArgs) -> anyhow::Result<World> {
    Ok(match (&args.world, args.seed) {
        (_, Some(seed)) => {
            let difficulty: Difficulty = args.difficulty.into();
            World::build(
                arcnav_sim::generate(seed, difficulty),
                "generated world",
                None,
            )?
        }
        (Some(name), None) => named_world(name)?,
        (None, None) => {
            World::embedded("paper_loop").context("the default world is compiled in")??
        }
    })
}

/// Says before the run when the cruise is held below what was asked, and
/// when it is faster than a hole is certain to be seen in time.
fn speed_notes(config: &Resolved) {
    let bound = &config.speed_bound;
    let cruise = config.cruise.mps;
    if config.cruise.capped()
        && let Some(range) = bound.suspect_range_m
    {
        eprintln!(
            "note: cruise held to {cruise:.1} m/s: a hole the wheels do not bridge is first \
             suspected within {range:.1} m, and from faster the vehicle could not stop short of \
             it ([lookahead] hole_speed_cap = false to drive where the ground has no holes at \
             {:.1} m/s)",
            config.cruise.asked_mps
        );
    }
    // The vehicle slows for what it suspects: with suspicion on, a
    // hole is learnt of in time up to the suspect bound; without, only
    // up to the bound of where it is flagged for certain.
    let in_time = (bound.suspect_range_m.zip(bound.suspect_bound_mps))
        .map(|(range, speed)| (range, speed, "suspects"))
        .or(bound
            .hole_certain_m
            .zip(bound.hole_bound_mps)
            .map(|(range, speed)| (range, speed, "flags")));
    if let Some((range, speed, how)) = in_time
        && cruise > speed + 1e-6
    {
        let governed = config.perception.evidence.verify;
        eprintln!(
            "note: {cruise:.1} m/s is faster than {speed:.2} m/s, at which one image is certain \
             to show a hole the wheels do not bridge in time: the sensor {how} one for certain \
             only within {range:.1} m (report.json speed_bound; a higher mount sees farther){}",
            if governed {
                "; the speed governor slows wherever the ground ahead is not verified over \
                 images (report.json verified_distance_m)"
            } else {
                ""
            }
        );
    }
}

/// The exit status of a mission that ended at a waypoint no route reaches
/// (a collision or any other failure is 1).
pub(crate) const UNREACHABLE_EXIT: u8 = 4;

fn print_summary(r: &arcnav::mission::MissionReport, out: &Path, snapshots: &[PathBuf]) {
    let outcome = match r.outcome {
        arcnav::mission::Outcome::Completed => "completed",
        arcnav::mission::Outcome::Collision => "FAILED: collision",
        arcnav::mission::Outcome::Timeout => "FAILED: time limit",
        arcnav::mission::Outcome::Stuck => "FAILED: stuck",
        arcnav::mission::Outcome::BehaviourFailed => "FAILED: a required behaviour ended",
        arcnav::mission::Outcome::Unreachable => "ENDED: a waypoint no route reaches",
    };
    println!("mission       {} on {} with {}", outcome, r.world, r.sensor);
    println!(
        "waypoints     {}/{}{}",
        r.waypoints_reached,
        r.waypoints,
        if r.waypoints_skipped > 0 {
            format!(", {} skipped as unreachable", r.waypoints_skipped)
        } else {
            String::new()
        }
    );
    for n in &r.unreachable {
        println!(
            "unreachable   waypoint {} at ({:.1}, {:.1}): no way round {} impassable cells, {:.0} of the {:.0} m² of the area in the planner's memory seen; no way since {:.0} s, given up at {:.0} s with the vehicle at ({:.1}, {:.1}){}",
            n.waypoint,
            n.position[0],
            n.position[1],
            n.ring_cells,
            n.known_m2,
            n.area_m2,
            n.no_way_since_s,
            n.given_up_at_s,
            n.vehicle_at[0],
            n.vehicle_at[1],
            if n.skipped { "; skipped" } else { "" }
        );
    }
    println!(
        "distance      {:.0} m in {:.0} s: average {:.2} m/s, max {:.2} m/s (cruise {:.2} m/s{})",
        r.distance_m,
        r.duration_s,
        r.average_speed_mps,
        r.max_speed_mps,
        r.cruise_mps,
        if r.cruise_mps < r.cruise_asked_mps {
            format!(
                ", held from {:.2} by [lookahead] hole_speed_cap",
                r.cruise_asked_mps
            )
        } else {
            String::new()
        }
    );
    print_speed_bound(r);
    println!(
        "images        {} processed, {} dropped",
        r.images, r.images_dropped
    );
    if let Some(f) = &r.fused {
        super::terminal::print_fused(f);
    }
    if let Some(s) = &r.slices {
        let c = &s.stream;
        println!(
            "streamed      {} slices judged as they came: {} evaluations of parts of frames over \
             {:.1}× the lines received, then each frame whole at its end; {} lines lost",
            s.received,
            c.steps,
            c.evaluated_lines as f64 / c.received_lines.max(1) as f64,
            c.lost_lines
        );
    }
    let cells: Vec<String> = r
        .untraversable_cells
        .iter()
        .map(|(reason, n)| format!("{reason} {n}"))
        .collect();
    println!(
        "cells         untraversable: {}; graded {} (suspected drop-offs {})",
        cells.join(", "),
        r.graded_cells,
        r.suspected_drop_offs
    );
    let m = &r.localmap;
    println!(
        "local map     {} patches, {} confirmations; dropped: {} missed by a newer image, {} under \
         the vehicle; {} misses not counted (seen from farther than reported from)",
        m.new_patches,
        m.confirmations,
        m.pruned_inconsistent,
        m.cleared_under_vehicle,
        m.seen_from_afar
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
        match &r.closest_approach {
            Some(m) => println!(
                "closest       {gap:.2} m between the vehicle and a hazard ({}) at {:.1} s, at ({:.1}, {:.1}): \
                 `arcnav render {}/mission.lcm --at {:.1}` draws that decision",
                m.hazard,
                m.at_s,
                m.position[0],
                m.position[1],
                out.display(),
                (m.at_s - 0.5).max(0.0)
            ),
            None => println!("closest       {gap:.2} m between the vehicle and a hazard"),
        }
    }
    print_drops_first_seen(r);
    print_ride_stops_and_recoveries(r);
    for (behaviour, counters) in &r.behaviour_counters {
        let counts: Vec<String> = counters.iter().map(|(k, v)| format!("{k} {v}")).collect();
        println!("{:<13} {}", behaviour, counts.join(", "));
    }
    for (behaviour, why) in &r.behaviour_faults {
        println!("{behaviour:<13} ENDED: {why}");
    }
    let t = &r.stage_times;
    println!(
        "stage time    perception {:.2} ms/image, local map {:.3} ms, behaviours {:.3} ms, arbiter {:.3} ms (mean per call{})",
        t.perception.mean_ms(),
        t.localmap.mean_ms(),
        t.behaviours.mean_ms(),
        t.arbiter.mean_ms(),
        if r.images_rendered_ahead > 0 {
            ", wall clock, sharing the cores with the rendering"
        } else {
            ""
        }
    );
    let ahead = if r.images_rendered_ahead > 0 {
        format!(
            " ({} of {} rendered ahead, beside the pipeline; {} rendered twice)",
            r.images_rendered_ahead, r.images, r.images_rendered_again
        )
    } else {
        String::new()
    };
    println!(
        "simulation    {:.0} s simulated in {:.1} s ({:.0}× real time), rendering {:.1} ms/image{ahead}",
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

/// The summary's lines on the speed bound (002 §7) and what set the speed.
fn print_speed_bound(r: &arcnav::mission::MissionReport) {
    let b = &r.speed_bound;
    println!(
        "speed bound   {:.2} m/s (002 §7): a {:.1} m reach set by the {}, {:.2} s from image to \
         effect; the average is {:.0} % of it",
        b.bound_mps,
        b.detection_range_m,
        b.range_limited_by,
        b.reaction_s,
        100.0 * r.speed_fraction_of_bound
    );
    if let (Some(range), Some(bound)) = (b.hole_certain_m, b.hole_bound_mps) {
        println!(
            "              holes the wheels do not bridge are flagged for certain within {range:.1} m: {bound:.2} m/s \
             (the average is {:.0} % of it)",
            100.0 * r.average_speed_mps / bound.max(1e-9)
        );
    }
    if let (Some(range), Some(bound)) = (b.suspect_range_m, b.suspect_bound_mps) {
        println!(
            "              ... and first suspected within {range:.1} m: stopping short of one from \
             there allows {bound:.2} m/s"
        );
    }
    if !r.speed_limited_by_s.is_empty() {
        println!("speed set by  {}", seconds_list(&r.speed_limited_by_s));
    }
    if let Some(v) = r.verified_distance_m {
        println!(
            "verified      the ground along the arc driven: {:.1} m at least, {:.1} m median",
            v.min, v.median
        );
    }
}

/// The summary's lines on the ride, the stops and the recoveries.
fn print_ride_stops_and_recoveries(r: &arcnav::mission::MissionReport) {
    let ride = &r.ride;
    println!(
        "ride          peak roll {:.1}° at {:.1} s, peak pitch {:.1}° at {:.1} s (limit {:.0}°); vertical acceleration {:.1} m/s² peak at {:.1} s, {:.2} m/s² rms",
        ride.peak_roll_deg,
        ride.peak_roll_at_s,
        ride.peak_pitch_deg,
        ride.peak_pitch_at_s,
        ride.slope_limit_deg,
        ride.peak_vertical_accel_mps2,
        ride.peak_vertical_accel_at_s,
        ride.rms_vertical_accel_mps2
    );
    let s = &r.stops;
    println!(
        "stops         {} stop commands in {} episodes (all arcs forbidden {}, no acceptable arc {}, required behaviour stale {}, stuck {})",
        s.stop_commands,
        s.episodes,
        s.all_arcs_forbidden,
        s.no_acceptable_arc,
        s.required_stale,
        s.stuck
    );
    if !s.stopped_s.is_empty() {
        println!("stopped       {}", seconds_list(&s.stopped_s));
    }
    if let Some(f) = &r.fault {
        println!(
            "fault         {} from {:.1} s, injected on purpose ([pipeline] fault): {} cells perception found thrown away, {} cycles voted on a stale map",
            f.fault, f.after_s, f.counts.cells_dropped, f.counts.cycles_stale
        );
    }
    super::terminal::print_guard(r.guard.as_ref());
    let rec = &r.recovery;
    println!(
        "recoveries    {} (backed {:.1} m; {} turns round in {} legs, {:.0}° turned, {} turned the other way; {} retraces over {:.1} m; blocked with no way back {} decisions, out of recoveries {})",
        rec.recoveries,
        rec.backed_m,
        rec.turns,
        rec.turn_legs,
        rec.turned_deg,
        rec.turns_reversed,
        rec.retraces,
        rec.retraced_m,
        rec.no_way_back,
        rec.exhausted
    );
}

/// An embedded world by name, or a world file.
pub(crate) fn named_world(name: &str) -> anyhow::Result<World> {
    if Path::new(name).exists() || name.ends_with(".toml") {
        return Ok(World::load(Path::new(name))?);
    }
    match World::embedded(name) {
        Some(world) => Ok(world?),
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

/// "why 1.2 s, other 3.4 s".
fn seconds_list(seconds: &std::collections::BTreeMap<&'static str, f64>) -> String {
    seconds
        .iter()
        .map(|(why, s)| format!("{why} {s:.1} s"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// How far ahead the world's holes and ditches were first reported.
fn print_drops_first_seen(r: &arcnav::mission::MissionReport) {
    let all = &r.drops_first_seen;
    if all.is_empty() {
        return;
    }
    let mut ranges: Vec<f64> = all.iter().filter_map(|d| d.first_range_m).collect();
    ranges.sort_by(f64::total_cmp);
    let never = all.len() - ranges.len();
    let never = if never > 0 {
        format!("; {never} never reported")
    } else {
        String::new()
    };
    let what = match all.len() {
        1 => "1 hole or ditch".to_owned(),
        n => format!("{n} holes and ditches"),
    };
    match (ranges.first(), ranges.last()) {
        (Some(near), Some(far)) if near == far => println!(
            "drop hazards  {what} the wheels do not bridge: first flagged or suspected {near:.1} m \
             from the sensor{never}"
        ),
        (Some(near), Some(far)) => println!(
            "drop hazards  {what} the wheels do not bridge: first flagged or suspected {near:.1} to \
             {far:.1} m from the sensor, median {:.1} m{never}",
            ranges[ranges.len() / 2]
        ),
        _ => println!("drop hazards  {what} the wheels do not bridge: none reported"),
    }
}
