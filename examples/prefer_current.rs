//! A behaviour written outside arcnav, plugged in through configuration:
//! "prefer the current curvature". It votes for arcs close to the curvature
//! the arbiter last commanded, which damps the weaving of a vehicle that
//! follows goal seeking's smooth votes through discrete arcs.
//!
//! Everything a new behaviour needs is in this file:
//!
//! 1. a config struct with its defaults (`[behaviours.prefer_current]`);
//! 2. the behaviour: `Behaviour::vote` fills one vote per arc in [-1, 1];
//! 3. `Plugin`: its name and how it is built from its config;
//! 4. one line, `registry.add::<PreferCurrent>()`, and a weight in `[arbiter.weights]`.
//!
//! ```sh
//! cargo run --release --example prefer_current            # short_course with and without it
//! cargo run --release --example prefer_current -- paper_loop
//! ```

use std::sync::Arc;

use arcnav::Resolved;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav_arbiter::Votes;
use arcnav_behaviours::{Behaviour, Plugin, Registry, Setup, VoteContext};
use arcnav_sim::World;
use arcnav_vehicle::ConfigError;
use arcnav_vehicle::config as check;
use serde::{Deserialize, Serialize};

/// `[behaviours.prefer_current]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PreferCurrentConfig {
    /// How many arcs away from the current curvature the vote has fallen
    /// from +1 to about -0.2 (one standard deviation of a Gaussian).
    pub width_arcs: f64,
}

impl Default for PreferCurrentConfig {
    fn default() -> Self {
        Self { width_arcs: 4.0 }
    }
}

/// Votes for arcs near the last commanded curvature.
pub struct PreferCurrent {
    width_arcs: f64,
}

impl Behaviour for PreferCurrent {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        // No command yet: no opinion (votes stay neutral).
        let Some(current) = ctx.last_command.filter(|c| !c.is_stop()) else {
            return;
        };
        let spacing = ctx.arcs.spacing();
        for (index, &curvature) in ctx.arcs.curvatures().iter().enumerate() {
            let arcs_away = (curvature - current.curvature) / spacing;
            let closeness = (-0.5 * (arcs_away / self.width_arcs).powi(2)).exp();
            votes.set(index, (2.0 * closeness - 1.0) as f32);
        }
    }
}

impl Plugin for PreferCurrent {
    const NAME: &'static str = "prefer_current";
    type Config = PreferCurrentConfig;

    fn validate(config: &Self::Config, _setup: &Setup<'_>) -> Result<(), ConfigError> {
        check::in_range("width_arcs", config.width_arcs, 0.5, 1000.0)
    }

    fn build(config: Self::Config, _setup: &Setup<'_>) -> Self {
        Self {
            width_arcs: config.width_arcs,
        }
    }
}

/// The configuration that turns it on: one table and one weight.
pub const CONFIG: &str = r#"
[behaviours.prefer_current]
width_arcs = 4.0

[arbiter.weights]
obstacle_avoidance = 1.0
goal_seeking = 0.5
prefer_current = 0.25
"#;

/// The built-in behaviours plus this one.
pub fn registry() -> Registry {
    let mut registry = Registry::builtin();
    registry.add::<PreferCurrent>();
    registry
}

fn main() -> anyhow::Result<()> {
    let world_name = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "short_course".into());
    let world = Arc::new(
        World::embedded(&world_name)
            .ok_or_else(|| anyhow::anyhow!("no embedded world {world_name:?}"))??,
    );
    let registry = registry();
    let with = Resolved::from_toml(CONFIG, "prefer_current example", &registry)?;
    for (label, config) in [
        ("without prefer_current", Resolved::default()),
        ("with prefer_current", with),
    ] {
        let run = run_mission(
            &config,
            Arc::clone(&world),
            &MissionOptions::default(),
            &mut |_| {},
        )?;
        let r = &run.report;
        println!(
            "{label:<24} {:?}: {:.0} m in {:.0} s, {} collisions, steering activity {:.5} 1/m per command",
            r.outcome,
            r.distance_m,
            r.duration_s,
            r.collisions.len(),
            r.steering_activity
        );
    }
    Ok(())
}
