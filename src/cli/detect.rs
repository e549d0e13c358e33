//! `arcnav detect`: paper 000's detection experiment for every evaluator.

use anyhow::Context as _;
use arcnav::Resolved;
use arcnav::detection::{DetectionOptions, run, table};
use arcnav::output::write_file;
use arcnav_perception::{EvaluatorRegistry, SensorPreset};

use crate::DetectArgs;

pub fn detect(args: DetectArgs) -> anyhow::Result<()> {
    let config = Resolved::load_or_default(
        args.config.as_deref(),
        &arcnav_behaviours::Registry::builtin(),
    )?;
    let registry = EvaluatorRegistry::builtin();
    let evaluators = if args.evaluators.is_empty() {
        registry.names().into_iter().map(String::from).collect()
    } else {
        args.evaluators
    };
    for name in &evaluators {
        registry
            .check_known(name)
            .map_err(|e| anyhow::anyhow!("--evaluator {name}: {}", e.reason))?;
    }
    for (flag, values) in [
        ("--heights", &args.heights),
        ("--distances", &args.distances),
    ] {
        anyhow::ensure!(!values.is_empty(), "{flag}: give at least one value");
        if let Some(bad) = values
            .iter()
            .find(|v| !(v.is_finite() && **v > 0.0 && **v <= 500.0))
        {
            anyhow::bail!("{flag} {bad}: values must be positive metres, at most 500");
        }
    }
    anyhow::ensure!(
        (1..=100_000).contains(&args.frames),
        "--frames {}: 1 to 100000",
        args.frames
    );
    let options = DetectionOptions {
        evaluators,
        sensors: if args.sensors.is_empty() {
            vec![SensorPreset::Erim]
        } else {
            args.sensors.into_iter().map(Into::into).collect()
        },
        heights_m: args.heights,
        glass: !args.no_glass,
        distances_m: args.distances,
        frames: args.frames,
        noise_m: config.sim.range_noise_m,
        dropout: config.sim.dropout_probability,
        seed: config.sim.seed,
        ..DetectionOptions::default()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output directory {}", args.out.display()))?;
    let settings = options.evaluators.len()
        * options.sensors.len()
        * (options.heights_m.len() + usize::from(options.glass))
        * options.distances_m.len();
    eprintln!(
        "arcnav detect: {settings} settings × {} frames; results in {}",
        options.frames,
        args.out.display()
    );
    let bar = indicatif::ProgressBar::new(settings as u64).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} settings, {elapsed} ({eta} left)",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let rows = run(&config.perception, &options, &|done, _| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    let text = table(&rows);
    print!("{text}");
    let json = serde_json::to_string_pretty(&rows).context("cannot encode the rows")?;
    for (file, bytes) in [
        ("detection.txt", text.as_bytes()),
        ("detection.json", json.as_bytes()),
    ] {
        let path = args.out.join(file);
        write_file(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
    }
    let picture = args.out.join("detection.png");
    arcnav::render::detection::detection_picture(&picture, &rows)
        .with_context(|| format!("cannot write {}", picture.display()))?;
    eprintln!(
        "wrote detection.txt, detection.json and detection.png to {}",
        args.out.display()
    );
    Ok(())
}
