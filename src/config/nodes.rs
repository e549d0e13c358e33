//! Building the pipeline's nodes from the configuration: each node from
//! its own section, the behaviours from the tables checked at load.

use arcnav_arbiter::Arbiter;
use arcnav_behaviours::{Behaviour, Registry};
use arcnav_pipeline::{
    BehaviourSet, DecisionCycle, Delivery, LocalMapNode, PerceptionNode, Pipeline,
};
use arcnav_vehicle::{ArcSet, ConfigError};

use super::{Config, behaviour_error};

impl Config {
    /// Builds the configured behaviour `name` (`None`: not configured), from
    /// its table as prepared at load; a table changed since is prepared now.
    pub fn build_behaviour(
        &self,
        registry: &Registry,
        arcs: &ArcSet,
        name: &str,
    ) -> Option<Result<Box<dyn Behaviour>, ConfigError>> {
        let this = self.effective();
        let table = this.behaviours.get(name)?;
        // Read (and its errors reported) when the configuration was checked.
        let statics = this.static_map().ok().flatten();
        let setup = this.setup(arcs, statics.as_ref());
        Some(match this.prepared.0.get(name) {
            Some(p) if p.table() == table => Ok(p.build(&setup)),
            _ => registry
                .prepare(name, table, &setup)
                .map(|p| p.build(&setup))
                .map_err(|e| behaviour_error(name, e)),
        })
    }

    /// Builds every configured behaviour (in name order).
    pub fn build_behaviours(
        &self,
        registry: &Registry,
        arcs: &ArcSet,
    ) -> Result<Vec<Box<dyn Behaviour>>, ConfigError> {
        self.behaviours
            .keys()
            .filter_map(|name| self.build_behaviour(registry, arcs, name))
            .collect()
    }

    /// The configured behaviours, voting over the configured arcs.
    pub fn behaviour_set(&self, registry: &Registry) -> Result<BehaviourSet, ConfigError> {
        let arcs = self.arc_set()?;
        Ok(BehaviourSet::new(
            self.build_behaviours(registry, &arcs)?,
            arcs,
        ))
    }

    /// The perception node, from `[perception]` (looking as far as
    /// [`Config::lookahead`] says) and `[pipeline]`.
    pub fn perception_node(&self) -> Result<PerceptionNode, ConfigError> {
        let this = self.effective();
        PerceptionNode::new(&this.perception, &this.pipeline).map_err(|e| e.within("perception"))
    }

    /// The local map and its cycle clock, from `[localmap]`, the vehicle's
    /// top speed and `[pipeline]`, with reports delivered as `delivery` says.
    pub fn decision_cycle<T>(&self, delivery: Delivery) -> DecisionCycle<T> {
        let this = self.effective();
        let mut map = LocalMapNode::new(&this.localmap, &this.vehicle);
        // Read (and its errors reported) when the configuration was checked.
        match self.static_map() {
            Ok(Some(statics)) => map.map.set_static_map(statics),
            Ok(None) => {}
            Err(e) => tracing::error!(%e, "no static occupancy map"),
        }
        DecisionCycle::new(map, &self.pipeline, delivery)
    }

    /// How a live run delivers reports to the map (`[live]`).
    pub fn live_delivery(&self) -> Delivery {
        if self.live.reproduce_lockstep {
            Delivery::held(&self.pipeline)
        } else {
            Delivery::OnArrival {
                decide_at_once: self.live.decide_on_new_cells,
            }
        }
    }

    /// The DAMN arbiter, from `[arbiter]` (its cruise speed as
    /// [`Config::lookahead`] holds it), `[arcs]` and the vehicle.
    pub fn arbiter(&self) -> Result<Arbiter, ConfigError> {
        let this = self.effective();
        Ok(Arbiter::new(&this.arbiter, self.arc_set()?, &self.vehicle))
    }

    /// The lock-step executor with every node of this configuration.
    pub fn lockstep(&self, registry: &Registry) -> Result<Pipeline, ConfigError> {
        Ok(Pipeline::new(
            self.perception_node()?,
            self.decision_cycle(Delivery::held(&self.pipeline)),
            self.behaviour_set(registry)?,
            self.arbiter()?,
        ))
    }

    /// The behaviours whose votes complete a cycle: every configured one
    /// with a positive weight.
    pub fn expected_behaviours(&self) -> Vec<String> {
        self.behaviours
            .keys()
            .chain(&self.live.external_behaviours)
            .filter(|name| self.arbiter.weight(name) > 0.0)
            .cloned()
            .collect()
    }
}
