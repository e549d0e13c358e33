//! How far ahead the vehicle looks, from how fast it drives (020 item 1).
//!
//! Obstacle avoidance votes each arc a speed at which the vehicle stops
//! within the arc's free distance D (less `stop_margin_m` m), reacting
//! after t = `reaction_s` and braking at a = `braking_fraction` (half) of
//! `vehicle.max_deceleration_mps2`: `v·t + v²/(2a) = D − margin`. An arc
//! clear for `max_distance_m` therefore allows at most the v of
//! D = `max_distance_m`; with the window of 002 §5 (20 m ahead, 18 m of
//! arc) that is 5.9 m/s whatever the sensor sees. So that a clear arc
//! allows the cruise speed v_c, the arcs must be judged
//!
//! ```text
//! D(v_c) = v_c·t + v_c²/(2a) + margin
//! ```
//!
//! along, and the map window and perception's region must hold what lies
//! there. When `D(v_c)` exceeds the configured `max_distance_m`, every
//! distance that looks ahead moves out by the same δ = D(v_c) −
//! `max_distance_m`: `behaviours.obstacle_avoidance.max_distance_m`,
//! `localmap.ahead_m`, `perception.region.ahead_m` and
//! `perception.max_range_m`. δ is bounded so that the window reaches
//! neither beyond `lookahead.max_ahead_m` nor beyond the farthest sensor's
//! range (ground no sensor returns cannot fill it). The configured values
//! are floors: at the default 2.5 m/s nothing changes (D = 5.96 m).
//!
//! The window must also be wide enough for the arcs: on an arc of
//! curvature k the arbiter drives at most v_k = min(v_c, √(a_lat/|k|))
//! (`arbiter.max_lateral_accel_mps2`), so that arc is judged D(v_k) along,
//! where it has moved sideways by (1 − cos(k·D))/|k| (2/|k| past a half
//! turn). `localmap.half_width_m` and `perception.region.half_width_m`
//! move out by what the widest of these, plus half the vehicle's width
//! and 1 m, exceeds the configured half width. (Ground outside the window
//! is ground no image has seen: an arc that leaves it sideways is slowed
//! as if it ran into fog.)
//!
//! Looking farther does not help with holes: the sensor suspects a hole
//! the wheels do not bridge only within `speed_bound.suspect_range_m`
//! (its far wall shows too little from farther), however far the window
//! reaches. With `hole_speed_cap` (on by default) v_c is therefore at
//! most `speed_bound.suspect_bound_mps`, the speed from which the vehicle
//! stops within that range, and everything above follows from v_c as if
//! it had been asked for. `arcnav config` and `arcnav sim` say when the
//! cap holds the configured cruise speed down.

pub(crate) mod section;

pub use section::LookaheadConfig;

use arcnav_behaviours::ObstacleAvoidanceConfig;
use arcnav_perception::SensorModel;
use arcnav_vehicle::ArcSet;

use crate::file::Config;

/// The distances a configuration looks ahead with, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lookahead {
    /// Arc length at which a clear arc allows the cruise speed: D(v_c).
    pub needed_m: f64,
    /// How far every distance that looks ahead moved out (0: as configured).
    pub moved_m: f64,
    pub max_distance_m: f64,
    pub map_ahead_m: f64,
    pub region_ahead_m: f64,
    pub max_range_m: f64,
    /// How far the window moved out to each side (0: as configured).
    pub widened_m: f64,
    pub map_half_width_m: f64,
    pub region_half_width_m: f64,
}

impl Lookahead {
    /// How far `config` looks ahead driving at `cruise_mps` (see the module
    /// documentation), with obstacle avoidance's stopping model `oa`, the
    /// vehicle's `sensors` and its `arcs`.
    pub fn derive(
        config: &Config,
        oa: &ObstacleAvoidanceConfig,
        sensors: &[SensorModel],
        arcs: &ArcSet,
        cruise_mps: f64,
    ) -> Self {
        let cruise = cruise_mps;
        let a = oa.braking_fraction * config.vehicle.max_deceleration_mps2;
        let judged = |v: f64| v * oa.reaction_s + v * v / (2.0 * a) + oa.stop_margin_m;
        let needed = judged(cruise);
        let (map, region) = (config.localmap.ahead_m, config.perception.region.ahead_m);
        let reach = if sensors.is_empty() {
            map
        } else {
            sensors.iter().map(|m| m.max_range_m).fold(0.0, f64::max)
        };
        let room = (config.lookahead.max_ahead_m.min(reach) - map).max(0.0);
        let moved = if config.lookahead.from_speed {
            (needed - oa.max_distance_m).clamp(0.0, room)
        } else {
            0.0
        };
        // The widest sideways reach of an arc within the length it is
        // judged at the speed it can be driven.
        let max_distance = oa.max_distance_m + moved;
        let sideways = arcs
            .curvatures()
            .iter()
            .map(|&k| {
                let k = k.abs();
                if k < 1e-9 {
                    return 0.0;
                }
                let v = cruise.min((config.arbiter.max_lateral_accel_mps2 / k).sqrt());
                let along = judged(v).min(max_distance);
                if k * along >= std::f64::consts::PI {
                    2.0 / k
                } else {
                    (1.0 - (k * along).cos()) / k
                }
            })
            .fold(0.0, f64::max);
        let half = config.localmap.half_width_m;
        let widened = if moved > 0.0 {
            (sideways + config.vehicle.footprint().half_width + 1.0 - half).max(0.0)
        } else {
            0.0
        };
        Self {
            needed_m: needed,
            moved_m: moved,
            max_distance_m: max_distance,
            map_ahead_m: map + moved,
            region_ahead_m: region + moved,
            max_range_m: config.perception.max_range_m + moved,
            widened_m: widened,
            map_half_width_m: half + widened,
            region_half_width_m: config.perception.region.half_width_m + widened,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use arcnav_perception::SensorPreset;

    use crate::Resolved;

    fn at(speed: f64, sensor: SensorPreset) -> Config {
        let mut config = Config::default();
        config.arbiter.cruise_speed_mps = speed;
        config.vehicle.max_speed_mps = config.vehicle.max_speed_mps.max(speed);
        config.sensor.preset = sensor;
        config.lookahead.from_speed = true;
        config
    }

    fn resolved(config: &Config) -> Resolved {
        config.resolved().unwrap()
    }

    fn avoidance(resolved: &Resolved) -> &ObstacleAvoidanceConfig {
        resolved
            .behaviour_config::<ObstacleAvoidanceConfig>("obstacle_avoidance")
            .unwrap()
    }

    /// Resolving the effective configuration of `resolved` again changes
    /// nothing: the derived values are fixed points.
    fn assert_stable(resolved: &Resolved) {
        let effective = resolved.effective();
        let again = effective.resolved().unwrap();
        assert_eq!(again.effective().to_toml(), effective.to_toml());
        assert_eq!(again.cruise, resolved.cruise);
    }

    /// `config` with where holes show and the pipeline's timing
    /// configured, as resolving would otherwise set them from the sensor.
    fn holes_configured(mut config: Config) -> Config {
        config.localmap.hole_range_m = 7.0;
        config.pipeline.perception_latency_s = arcnav_pipeline::Latency::Seconds(0.3);
        config.perception.evidence.verify = false;
        config.perception.evidence.verified_within_m = 11.0;
        let avoidance = config.behaviours.get_mut("obstacle_avoidance").unwrap();
        avoidance.insert("hole_seen_within_m".into(), toml::Value::Float(5.0));
        avoidance.insert("governor_reaction_s".into(), toml::Value::Float(1.0));
        config
    }

    #[test]
    fn where_holes_show_comes_from_the_sensor_unless_configured() {
        for sensor in [SensorPreset::Erim, SensorPreset::Lidar64] {
            let config = at(2.5, sensor);
            let resolved = resolved(&config);
            let bound = &resolved.speed_bound;
            assert_eq!(Some(resolved.localmap.hole_range_m), bound.hole_grazed_m);
            assert_eq!(
                Some(avoidance(&resolved).hole_seen_within_m),
                bound.hole_seen_within_m
            );
            // The front is the sensor's setback nearer.
            assert!(bound.hole_seen_within_m < bound.hole_grazed_m, "{bound:?}");
            let configured = self::resolved(&holes_configured(config));
            assert_eq!(configured.localmap.hole_range_m, 7.0);
            assert_eq!(avoidance(&configured).hole_seen_within_m, 5.0);
            assert!(
                configured.derivations().is_empty(),
                "{:?}",
                configured.derivations()
            );
            assert_stable(&resolved);
        }
    }

    #[test]
    fn the_default_speed_looks_as_far_as_configured() {
        let config = holes_configured(at(2.5, SensorPreset::Erim));
        let resolved = resolved(&config);
        let look = resolved.lookahead;
        // 2.5·0.75 + 2.5²/(2·1.5) + 2 = 5.96 m: well inside 18 m.
        assert!((look.needed_m - 5.958).abs() < 1e-3, "{look:?}");
        assert_eq!(look.moved_m, 0.0);
        assert_eq!(resolved.effective().to_toml(), config.to_toml());
    }

    /// `config` driving at its cruise speed whatever holes it may meet.
    fn uncapped(mut config: Config) -> Config {
        config.lookahead.hole_speed_cap = false;
        config
    }

    #[test]
    fn a_faster_vehicle_looks_farther_so_that_a_clear_arc_allows_cruise() {
        let resolved = resolved(&uncapped(at(10.0, SensorPreset::Lidar64)));
        let look = resolved.lookahead;
        // 10·0.75 + 100/3 + 2 = 42.83 m of arc; everything moves out by 24.83 m.
        assert!((look.needed_m - 42.833).abs() < 1e-3, "{look:?}");
        assert!((look.max_distance_m - look.needed_m).abs() < 1e-9);
        assert!((look.map_ahead_m - 44.833).abs() < 1e-3);
        assert!((look.region_ahead_m - 46.833).abs() < 1e-3);
        assert!((look.max_range_m - 64.833).abs() < 1e-3);
        // Arcs of |k| ~ 1/50 run at 8.7 m/s, judged 33.5 m along, where
        // they are 10.8 m to the side: the window widens to ~12.9 m.
        assert!((12.0..14.0).contains(&look.map_half_width_m), "{look:?}");
        assert_eq!(look.region_half_width_m, look.map_half_width_m + 2.0);
        assert_eq!(resolved.localmap.ahead_m, look.map_ahead_m);
        assert_eq!(resolved.perception.region.ahead_m, look.region_ahead_m);
        assert_eq!(avoidance(&resolved).max_distance_m, look.max_distance_m);
        // A clear arc's stopping-distance speed is the cruise speed.
        let (t, a) = (0.75f64, 1.5f64);
        let room = look.max_distance_m - 2.0;
        let v = -a * t + ((a * t).powi(2) + 2.0 * a * room).sqrt();
        assert!((v - 10.0).abs() < 1e-9, "{v}");
        assert_stable(&resolved);
        // 6 m/s needs 4.5 + 12 + 2 = 18.5 m: a little farther than configured.
        let look = self::resolved(&uncapped(at(6.0, SensorPreset::Lidar64))).lookahead;
        assert!((look.moved_m - 0.5).abs() < 1e-9, "{look:?}");
        // Counting on all of the braking (braking_fraction = 1): 10·0.75 +
        // 100/6 + 2 = 26.17 m.
        let mut full = uncapped(at(10.0, SensorPreset::Lidar64));
        full.behaviours
            .get_mut("obstacle_avoidance")
            .unwrap()
            .insert("braking_fraction".into(), toml::Value::Float(1.0));
        let look = self::resolved(&full).lookahead;
        assert!((look.needed_m - 26.167).abs() < 1e-3, "{look:?}");
    }

    #[test]
    fn the_window_stops_at_the_sensor_and_the_bound_or_when_switched_off() {
        // The ERIM returns nothing beyond 40 m: the window stops there.
        let look = resolved(&uncapped(at(10.0, SensorPreset::Erim))).lookahead;
        assert_eq!(look.map_ahead_m, 40.0, "{look:?}");
        let mut config = uncapped(at(10.0, SensorPreset::Lidar64));
        config.lookahead.max_ahead_m = 30.0;
        assert_eq!(resolved(&config).lookahead.map_ahead_m, 30.0);
        config.lookahead.from_speed = false;
        assert_eq!(resolved(&config).lookahead.moved_m, 0.0);
        let config = holes_configured(config);
        assert_eq!(resolved(&config).effective().to_toml(), config.to_toml());
    }

    /// However far the window reaches, a hole the wheels do not bridge is
    /// suspected only within `suspect_range_m`: the cruise speed is held
    /// to the speed from which the vehicle stops within it, and everything
    /// that looks ahead follows from that speed, the arbiter's too.
    #[test]
    fn the_cruise_speed_is_held_to_stopping_where_a_hole_is_first_suspected() {
        // Off by default (the speed governor slows where ground is not
        // verified); a user may still ask for it.
        let mut config = at(10.0, SensorPreset::Lidar64);
        assert!(!resolved(&config).cruise.capped());
        config.lookahead.hole_speed_cap = true;
        let capped = resolved(&config);
        let cap = capped.speed_bound.suspect_bound_mps.unwrap();
        assert!((5.0..6.0).contains(&cap), "{:?}", capped.speed_bound);
        assert_eq!(capped.cruise.cap_mps, Some(cap));
        assert!(
            capped.cruise.capped() && capped.cruise.mps == cap,
            "{:?}",
            capped.cruise
        );
        assert_eq!(capped.cruise.asked_mps, 10.0);
        assert_eq!(
            capped.arbiter.cruise_speed_mps, 10.0,
            "the key keeps what was asked"
        );
        // Everything looks as far as the held speed needs: D(v_c) with
        // 0.75 s and 1.5 m/s² of the default obstacle avoidance, 2 m of
        // margin.
        let look = capped.lookahead;
        let needed = cap * 0.75 + cap * cap / 3.0 + 2.0;
        assert!((look.needed_m - needed).abs() < 1e-9, "{look:?}");
        let mut asked = uncapped(config.clone());
        asked.arbiter.cruise_speed_mps = cap;
        assert_eq!(resolved(&asked).lookahead.map_ahead_m, look.map_ahead_m);
        assert_stable(&capped);
        assert_eq!(capped.arbiter().cruise_mps(), cap);
        // Slower than the cap, switched off, or with no drop-off suspected:
        // the cruise speed is the configured one.
        let slow = resolved(&at(2.5, SensorPreset::Lidar64)).cruise;
        assert!(!slow.capped() && slow.mps == 2.5, "{slow:?}");
        let off = resolved(&uncapped(config.clone()));
        assert_eq!(off.cruise.mps, 10.0);
        assert_eq!(off.arbiter().cruise_mps(), 10.0);
        let mut unsuspected = config.clone();
        unsuspected.perception.drop_off.suspect_cost = 0.0;
        assert_eq!(resolved(&unsuspected).cruise.mps, 10.0);
        // The ERIM sees holes nearer and reacts later: a lower cap (4.19
        // m/s, so 020's 4.5 m/s is held to it).
        let mut erim = at(10.0, SensorPreset::Erim);
        erim.lookahead.hole_speed_cap = true;
        let erim = resolved(&erim).cruise;
        assert!(erim.capped() && (4.0..cap).contains(&erim.mps), "{erim:?}");
    }
}
