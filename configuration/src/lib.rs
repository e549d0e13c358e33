//! # arcnav's configuration
//!
//! One TOML file with a section per crate ([`Config`], as the user gave it)
//! is parsed once into typed sections, checked once, and what follows from
//! it is derived once — the cruise speed the hole speed cap allows, the arc
//! set at that speed, how far the vehicle looks ahead ([`Lookahead`]), the
//! speed it can stop or swerve from ([`SpeedBound`]), where holes show —
//! into the frozen [`Resolved`] configuration from which every node,
//! executor, report and picture is built.
//!
//! ```no_run
//! use arcnav_behaviours::Registry;
//! use arcnav_config::Config;
//!
//! let resolved = Config::load(std::path::Path::new("my.toml"))?
//!     .resolve(&Registry::builtin())?;
//! let mut pipeline = resolved.lockstep()?;
//! # let _ = &mut pipeline;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod bus;
mod file;
mod lookahead;
pub mod occupancy;
mod print;
mod resolved;
pub mod speed_bound;

pub use bus::{BusAuthConfig, BusConfig};
pub use file::{
    Config, ConfigLoadError, DEFAULT_TOML, EXTERNAL, LoadCounts, Location, Origin, load_counts,
};
pub use lookahead::{Lookahead, LookaheadConfig};
pub use resolved::{Cruise, Derivation, Resolved};
pub use speed_bound::SpeedBound;

#[cfg(test)]
mod tests;
