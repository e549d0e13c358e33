//! What the commands share at the terminal: Ctrl-C, progress bars, the
//! guard's lines of a summary.

/// Set by the first SIGINT or SIGTERM; a second one while shutting down
/// exits at once.
pub(super) fn interrupt_flag() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use anyhow::Context as _;
    use std::sync::Arc;
    let flag = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 1, Arc::clone(&flag))
            .context("cannot install the signal handlers")?;
        signal_hook::flag::register(signal, Arc::clone(&flag))
            .context("cannot install the signal handlers")?;
    }
    Ok(flag)
}

/// A progress bar of `len` steps drawn with `template` (indicatif's
/// syntax), `=>` filling its bar.
pub(super) fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(len).with_style(
        indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    )
}

/// What the guard did (a mission's, or what it would have done with a
/// replay's commands), as the summaries print it.
pub(super) fn print_guard(guard: Option<&arcnav::mission::GuardReport>) {
    match guard {
        Some(g) => {
            println!(
                "guard         {} stops, {} slows (stopped {:.1} s, slowed {:.1} s); {} hazardous returns ({} standing, {} holes) from {} images and {} slices, {:.2} ms each",
                g.stops,
                g.slows,
                g.stopped_s,
                g.slowed_s,
                g.counts.standing + g.counts.holes,
                g.counts.standing,
                g.counts.holes,
                g.counts.images,
                g.counts.slices,
                g.observe_ms
            );
            if g.counts.unknown_sensor
                + g.counts.before_pose
                + g.counts.malformed
                + g.counts.forgotten
                > 0
            {
                println!(
                    "              not tested: {} of an unknown sensor, {} before any pose, {} malformed; {} returns forgotten (guard.max_cells held)",
                    g.counts.unknown_sensor,
                    g.counts.before_pose,
                    g.counts.malformed,
                    g.counts.forgotten
                );
            }
            if let Some(e) = g.first.first() {
                println!(
                    "              first: {} at {:.1} s at ({:.1}, {:.1}): {}",
                    e.verdict, e.t_s, e.x, e.y, e.reason
                );
            }
        }
        None => println!("guard         off ([guard] enabled = false)"),
    }
}

/// The summary's line for images judged together (`perception.fuse_within_s`).
pub(super) fn print_fused(f: &arcnav_pipeline::FusionCounts) {
    println!(
        "fused         {} images judged together in {} height maps ({:.1} per evaluation, \
         perception.fuse_within_s)",
        f.images,
        f.evaluations,
        f.images_per_evaluation()
    );
}
