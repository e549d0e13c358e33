//! The commands of the `arcnav` tool, one file each; `main.rs` holds the
//! command line they are called from.

mod live;
mod render;
mod replay;
mod sim;
mod sweep;

pub use live::{live, vehicle};
pub use render::{export, render};
pub use replay::replay;
pub use sim::sim;
pub use sweep::sweep;
