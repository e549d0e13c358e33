//! The commands of the `arcnav` tool, one file each; `main.rs` holds the
//! command line they are called from.

mod detect;
mod live;
mod logged;
mod render;
mod replay;
mod settings;
mod sim;
mod sweep;
mod terminal;

pub use detect::detect;
pub use live::{live, vehicle};
pub use render::{export, render};
pub use replay::replay;
pub use sim::sim;
pub use sweep::sweep;
