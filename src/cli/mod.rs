//! The commands of the `arcnav` tool, one file each; `main.rs` holds the
//! command line they are called from.

mod detect;
mod live;
mod logged;
mod render;
mod replay;
mod sim;
mod sweep;
mod terminal;

pub use detect::detect;
pub use live::{live, vehicle};
pub use render::{export, render};
pub use replay::replay;
pub use sim::sim;
pub use sweep::sweep;

/// What the guard did (a mission's, or what it would have done with a
/// replay's commands), as the summaries print it.
pub(crate) fn print_guard(guard: Option<&arcnav::mission::GuardReport>) {
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
