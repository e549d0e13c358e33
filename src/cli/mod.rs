//! The commands of the `arcnav` tool, one file each; `main.rs` holds the
//! command line they are called from.

mod detect;
mod live;
mod render;
mod replay;
mod sim;
mod sweep;

pub use detect::detect;
pub use live::{live, vehicle};
pub use render::{export, render};
pub use replay::replay;
pub use sim::sim;
pub use sweep::sweep;

/// Set by the first SIGINT or SIGTERM; a second one while shutting down
/// exits at once.
fn interrupt_flag() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
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
fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(len).with_style(
        indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    )
}
