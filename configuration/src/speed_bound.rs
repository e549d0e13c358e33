//! The speed a configuration allows, by the reasoning of 002 §7: "Sensor
//! acquisition rate and resolution are the two numbers that set hard limits
//! on the speed." The vehicle tolerates discontinuities of
//! `vehicle.tolerated_step_m` (20 cm); a larger one must be seen early
//! enough to stop before it, or to turn away from it on the tightest arc.
//!
//! - **Detection range.** Adjacent beams `δθ` apart are `R·δθ` apart
//!   vertically at range `R`, so a step of height `h` is certain to be hit
//!   by a beam only within `R_res = h / δθ`. Nothing beyond the sensor's
//!   reach or the local map's window ahead reaches the behaviours either:
//!   `R = min(R_res, max_range_m, localmap.ahead_m)` (the window as
//!   `[lookahead]` sets it for the cruise speed). The free distance is
//!   `D = R − (front bumper − sensor)`, the range being the sensor's.
//! - **Reaction time.** A step may become resolvable just after an image
//!   began: `T = 1/rate + pipeline.perception_latency_s +
//!   1/pipeline.command_rate_hz + vehicle.command_latency_s`. With images
//!   streamed in slices (`sim.slice_lines`, 002 §7's integrated mode) the
//!   step is judged once its slice is in: `1/rate` becomes one slice's
//!   acquisition.
//! - **Stopping:** `v·T + v²/(2a) ≤ D`, so `v_stop = a·(√(T² + 2D/a) − T)`
//!   with `a = vehicle.max_deceleration_mps2`.
//! - **Swerving:** moving the body sideways by half its width on the arc of
//!   radius `r = vehicle.min_turning_radius_m` takes `d = √(w·(2r − w))` of
//!   forward travel, after the steering has turned to that arc (`t_s =
//!   (1/r)/vehicle.max_curvature_rate`): `v·(T + t_s) + d ≤ D`, and the turn
//!   itself keeps `v²/r ≤ arbiter.max_lateral_accel_mps2`.
//! - The bound is the faster of the two manoeuvres, at most
//!   `vehicle.max_speed_mps`.
//!
//! A hole is seen differently (016: "no data is not free ground"). Its
//! near edge is flagged a drop-off when a ray that passed it meets the
//! far side more than `δ = δ0 + Δ·R` below the edge
//! (`[perception.drop_off]`, 000 §4.2's gap rule). From a sensor `H` above
//! the ground a ray falls `H/R` per metre at range `R`, so across a hole
//! `w` wide the ray grazing its edge shows `w·H/R` of the far side,
//! whatever the hole's depth: for a hole the wheels do not bridge
//! (`w = max_gap_m`) that is more than `δ` within the `R` that solves
//! `Δ·R² + δ0·R = w·H`, where rows of returns lie closer than `w` on the
//! ground (`R²·δθ/H ≤ w`): `hole_grazed_m`, 8.4 m for the 64-beam lidar
//! 2.4 m up. But no ray need graze the edge (below), and counted as the
//! suspicion is, the hole is certain to be flagged only within
//! `(Δ + δθ)·R² + δ0·R = w·H`: `hole_certain_m`, 6.9 m for that lidar, and
//! `hole_bound_mps` the stop-or-swerve bound over it, 3.2 m/s. (Until
//! 2026-11-29 the report gave the grazing range as certain.) A hole
//! across the whole way cannot be swerved round; the swerve counts for
//! one narrower than the way.
//!
//! From farther, such a hole is at least *suspected*: its near edge is
//! reported as a suspected drop-off when the dip exceeds `noise_m + Δ·R`
//! (`[perception.drop_off] suspect_cost`). No ray need graze the edge:
//! the row that lands first beyond it lands anywhere in the first
//! `s = R²·δθ/H` past it, and a ray that would have met level ground `u`
//! past the edge meets the far wall `(w − u)·H/R` down. So a hole is
//! certain to be suspected only where `(w − s)·H/R ≥ noise_m + Δ·R`:
//!
//! ```text
//! (Δ + δθ)·R² + noise_m·R = w·H
//! ```
//!
//! (the dip and the rows' spacing add up; taking the smaller of the range
//! each allows alone, 15.9 m for the 64-beam lidar, a 3 m ditch across
//! the way was driven into at 10 m/s asked for with 3 of 6 noise seeds,
//! `tests/worlds/short_ditch.toml`). Obstacle avoidance slows for a
//! suspected drop-off, but only from where it is suspected:
//! `suspect_bound_mps`, the speed from which the vehicle stops within
//! `suspect_range_m` (less the setback), is the fastest at which a ditch
//! across the way is learnt of in time to stop: 11.4 m and 5.28 m/s for
//! the 64-beam lidar 2.4 m up (5.49 streamed), 12.0 m and 5.52 m/s for
//! the 128-beam one, 10.3 m and 4.19 m/s for the ERIM.
//! `[lookahead] hole_speed_cap` holds the cruise speed to it.
//!
//! The local map's `hole_range_m` and obstacle avoidance's
//! `hole_seen_within_m` are set from `hole_grazed_m`, what they were tuned
//! with: moved to the certain 6.9 m, the local map remembered holes
//! differently and `short_course` at 10 m/s met a hole while backing
//! beside it with one noise seed of six (2026-11-29).

use serde::Serialize;

use arcnav_perception::SensorModel;

use crate::file::Config;

/// What a configuration allows, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpeedBound {
    /// The highest speed at which a step taller than the vehicle tolerates
    /// can still be avoided, m/s.
    pub bound_mps: f64,
    /// The stopping and swerving bounds it is the larger of, m/s.
    pub stop_mps: f64,
    pub swerve_mps: f64,
    /// Range at which such a step is certain to be seen, m, and what sets it
    /// (`"resolution"`, `"sensor range"` or `"map window"`).
    pub detection_range_m: f64,
    pub range_limited_by: &'static str,
    /// Image to command effect, s.
    pub reaction_s: f64,
    /// The sensor's vertical angle between adjacent beams, degrees.
    pub beam_spacing_deg: f64,
    /// Range within which a hole the wheels do not bridge is certain to be
    /// flagged, whichever row lands first past its edge
    /// (`(Δ + δθ)·R² + δ0·R = w·H`), and the stop-or-swerve speed over
    /// it, m and m/s (none when `[perception.drop_off]` is off).
    pub hole_certain_m: Option<f64>,
    pub hole_bound_mps: Option<f64>,
    /// Range within which the ray grazing such a hole's edge flags it, on
    /// rows closer than the hole is wide (`Δ·R² + δ0·R = w·H`), m: the best
    /// case, what the local map's `hole_range_m` is set to.
    pub hole_grazed_m: Option<f64>,
    /// How far the front is from such a hole when the grazing ray flags
    /// it, m (`hole_grazed_m` less the sensor's setback from the front):
    /// what obstacle avoidance's `hole_seen_within_m` is set to.
    pub hole_seen_within_m: Option<f64>,
    /// Range within which such a hole is certain to be at least
    /// *suspected*, whichever row lands first past its edge (its dip
    /// exceeds `noise_m + Δ·R`: `(Δ + δθ)·R² + noise_m·R = w·H`), m, and
    /// the speed from which the vehicle stops within it,
    /// m/s: a hole first suspected there is a hole it can still stop
    /// short of (no swerve: a ditch may cross the whole way). Faster, it
    /// may learn of a ditch too late to stop for it, however it slows for
    /// what it suspects. `[lookahead] hole_speed_cap` holds the cruise
    /// speed to it. None when suspected drop-offs are not reported.
    pub suspect_range_m: Option<f64>,
    pub suspect_bound_mps: Option<f64>,
}

/// The bound of `config` with its `sensors`, the map window reaching
/// `window` m ahead (as far as the vehicle looks at its cruise speed):
/// with several sensors, the best of those that look straight ahead (a
/// rear camera does not see what the vehicle drives into).
pub fn speed_bound(
    config: &Config,
    sensors: &[SensorModel],
    window: f64,
) -> Result<SpeedBound, arcnav_vehicle::ConfigError> {
    looking_ahead(sensors)
        .into_iter()
        .map(|sensor| {
            bound_with(
                config,
                sensor,
                window,
                perception_latency_s(config, sensors),
            )
        })
        .max_by(|a, b| a.bound_mps.total_cmp(&b.bound_mps))
        .ok_or_else(|| arcnav_vehicle::ConfigError::new("sensors", "the vehicle has no sensor"))
}

/// The highest cruise speed at which the vehicle still stops before a
/// hole the wheels do not bridge once it is *suspected*
/// ([`SpeedBound::suspect_bound_mps`], from the sensor alone, whatever the
/// map window), with the best of the `sensors` that look ahead; `None`
/// when drop-offs are not suspected or no sensor is configured. What
/// `[lookahead] hole_speed_cap` holds the cruise speed to.
pub fn hole_speed_cap(config: &Config, sensors: &[SensorModel]) -> Option<f64> {
    looking_ahead(sensors)
        .into_iter()
        .filter_map(|sensor| {
            let latency = perception_latency_s(config, sensors);
            bound_with(config, sensor, f64::INFINITY, latency).suspect_bound_mps
        })
        .max_by(f64::total_cmp)
}

/// The sensors that see what the vehicle drives into: those looking
/// straight ahead, or all when none does.
fn looking_ahead(sensors: &[SensorModel]) -> Vec<&SensorModel> {
    let ahead = |s: &&SensorModel| {
        let yaw = arcnav_vehicle::frames::yaw_of(&s.vehicle_from_sensor);
        s.beams
            .azimuth
            .iter()
            .any(|&az| arcnav_vehicle::frames::wrap_angle(f64::from(az) + yaw).abs() < 0.1)
    };
    if sensors.iter().any(|s| ahead(&s)) {
        sensors.iter().filter(ahead).collect()
    } else {
        sensors.iter().collect()
    }
}

/// From an image's capture to its cells in the map, s: `[pipeline]
/// perception_latency_s`, or for `"auto"` the slowest of the `sensors`'
/// own (what sim and replay then hold cells for).
pub fn perception_latency_s(config: &Config, sensors: &[SensorModel]) -> f64 {
    let slowest = sensors.iter().map(|s| s.latency_s).reduce(f64::max);
    match slowest {
        Some(slowest) => config.pipeline.perception_latency_s.or_sensor(slowest),
        None => config.pipeline.perception_latency_s.seconds(),
    }
}

/// The bound of `config` with `sensor` alone, the map window reaching
/// `window` m ahead, its cells in the map `latency` s after capture.
fn bound_with(config: &Config, sensor: &SensorModel, window: f64, latency: f64) -> SpeedBound {
    let v = &config.vehicle;
    let elevations = &sensor.beams.elevation;
    let span = elevations
        .iter()
        .fold(f64::NEG_INFINITY, |m, &e| m.max(f64::from(e)))
        - elevations
            .iter()
            .fold(f64::INFINITY, |m, &e| m.min(f64::from(e)));
    let spacing = span / (elevations.len().max(2) - 1) as f64;
    let resolved = if spacing > 0.0 {
        v.tolerated_step_m / spacing
    } else {
        f64::INFINITY
    };
    let (range, limited_by) = [
        (resolved, "resolution"),
        (sensor.max_range_m, "sensor range"),
        (window, "map window"),
    ]
    .into_iter()
    .fold(
        (f64::INFINITY, ""),
        |best, c| if c.0 < best.0 { c } else { best },
    );
    let front = v.footprint().x_max;
    let sensor_x = sensor.vehicle_from_sensor.translation.vector.x;
    let free_within = |range: f64| (range - (front - sensor_x).max(0.0)).max(0.0);
    let acquisition = if config.sim.slice_lines > 0 {
        let slicer = arcnav_sim::sensor::Slicer::new(sensor, config.sim.slice_lines);
        (slicer.times(0, 0).0 as f64 * 1e-6).min(1.0 / sensor.rate_hz)
    } else {
        1.0 / sensor.rate_hz
    };
    let reaction =
        acquisition + latency + 1.0 / config.pipeline.command_rate_hz + v.command_latency_s;
    let a = v.max_deceleration_mps2;
    let r = v.min_turning_radius_m;
    let w = v.footprint().half_width.min(r);
    let sideways = (w * (2.0 * r - w)).sqrt();
    let steer = (1.0 / r) / v.max_curvature_rate;
    // Stopping and swerving within `free` metres.
    let stopping = |free: f64| a * ((reaction * reaction + 2.0 * free / a).sqrt() - reaction);
    let manoeuvres = |free: f64| {
        let swerve = ((free - sideways) / (reaction + steer))
            .max(0.0)
            .min((config.arbiter.max_lateral_accel_mps2 * r).sqrt());
        (stopping(free), swerve)
    };
    let (stop, swerve) = manoeuvres(free_within(range));
    let drop_off = &config.perception.drop_off;
    let height = sensor.vehicle_from_sensor.translation.vector.z;
    // Within what range a hole `max_gap_m` wide shows a dip of at least
    // `step + per_m·R` beyond its near edge: to the ray grazing the edge
    // (`w·H/R`), on rows of returns closer than `w` on the ground; and to
    // whichever row lands first past the edge, up to a row's spacing `s`
    // in (`(w − s)·H/R`): `(Δ + δθ)·R² + step·R = w·H` (module doc).
    let (gap, per_m) = (drop_off.max_gap_m, drop_off.depth_per_m);
    let solve = |quadratic: f64, step: f64| {
        if quadratic > 0.0 {
            (-step + (step * step + 4.0 * quadratic * gap * height).sqrt()) / (2.0 * quadratic)
        } else {
            gap * height / step
        }
    };
    let rows = if spacing > 0.0 {
        (gap * height / spacing).sqrt()
    } else {
        f64::INFINITY
    };
    let reach = |range: f64| range.min(sensor.max_range_m).min(window);
    let grazed_within = |step: f64| reach(solve(per_m, step).min(rows));
    let certain_within = |step: f64| reach(solve(per_m + spacing, step));
    let holes = drop_off.enabled && height > 0.0;
    let hole_grazed = holes.then(|| grazed_within(drop_off.min_depth_m));
    let hole_range = holes.then(|| certain_within(drop_off.min_depth_m));
    let hole_bound = hole_range.map(|range| {
        let (stop, swerve) = manoeuvres(free_within(range));
        stop.max(swerve).min(v.max_speed_mps)
    });
    let suspect_range =
        (holes && drop_off.suspect_cost > 0.0).then(|| certain_within(drop_off.noise_m));
    SpeedBound {
        bound_mps: stop.max(swerve).min(v.max_speed_mps),
        stop_mps: stop,
        swerve_mps: swerve,
        detection_range_m: range,
        range_limited_by: limited_by,
        reaction_s: reaction,
        beam_spacing_deg: spacing.to_degrees(),
        hole_certain_m: hole_range,
        hole_bound_mps: hole_bound,
        hole_grazed_m: hole_grazed,
        hole_seen_within_m: hole_grazed.map(free_within),
        suspect_range_m: suspect_range,
        suspect_bound_mps: suspect_range
            .map(|range| stopping(free_within(range)).min(v.max_speed_mps)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_perception::SensorPreset;

    /// The speed bound `config` resolves to.
    fn resolved_bound(config: &Config) -> SpeedBound {
        config
            .clone()
            .resolve(&arcnav_behaviours::Registry::builtin())
            .unwrap()
            .speed_bound
    }

    #[test]
    fn the_papers_erim_allows_its_2_to_3_m_s_and_the_map_window_caps_it() {
        let config = Config::default();
        let b = resolved_bound(&config);
        // 0.5° beams resolve 20 cm out to 22.9 m; the 20 m window is shorter.
        assert!((b.beam_spacing_deg - 0.508).abs() < 0.01, "{b:?}");
        assert_eq!(b.range_limited_by, "map window");
        assert_eq!(b.detection_range_m, 20.0);
        assert!((b.reaction_s - 1.15).abs() < 1e-9, "{b:?}");
        // 002 drove 2-3 m/s with room to spare; far less than 10 m/s.
        assert!((4.0..9.0).contains(&b.bound_mps), "{b:?}");
        assert!(b.stop_mps > b.swerve_mps, "braking is the better way out");
        // A window that reaches the resolution limit raises the bound; the
        // resolution then limits it.
        let mut wider = config.clone();
        wider.localmap.ahead_m = 40.0;
        wider.perception.region.ahead_m = 42.0;
        let w = resolved_bound(&wider);
        assert_eq!(w.range_limited_by, "resolution");
        assert!(w.bound_mps > b.bound_mps, "{w:?} vs {b:?}");
    }

    #[test]
    fn a_faster_sensor_and_a_tolerant_vehicle_allow_more_a_slow_one_less() {
        let base = resolved_bound(&Config::default()).bound_mps;
        let mut lidar = Config::default();
        lidar.sensor.preset = SensorPreset::Lidar64;
        let lidar = resolved_bound(&lidar);
        // 0.1 s a frame instead of 0.5 s, and its own latency (a rotation
        // and processing, 0.15 s) instead of the ERIM's 0.3 s: 0.1 + 0.15 +
        // 0.1 + 0.25.
        assert!((lidar.reaction_s - 0.6).abs() < 1e-9, "10 Hz: {lidar:?}");
        assert!(lidar.bound_mps > base, "{} vs {base}", lidar.bound_mps);
        let mut slow = Config::default();
        slow.pipeline.perception_latency_s = arcnav_pipeline::Latency::Seconds(2.0);
        assert!(resolved_bound(&slow).bound_mps < base);
        let mut brakes = Config::default();
        brakes.vehicle.max_deceleration_mps2 = 6.0;
        assert!(resolved_bound(&brakes).bound_mps > base);
    }

    /// 016's holes: the 64-beam lidar 2.4 m up shows a 0.77 m hole's far
    /// side 0.2 m + 0.0025·R down to the ray grazing its edge only within
    /// 8.4 m (`Δ·R² + δ0·R = w·H`), and to whichever row lands first past
    /// it only within 6.9 m (`(Δ + δθ)·R² + δ0·R = w·H`), well inside the
    /// 27 m at which it resolves a 20 cm step, so holes hold the speed far
    /// lower; mounted higher it sees them farther; with drop-off detection
    /// off there is no such bound.
    #[test]
    fn holes_are_seen_nearer_than_steps_and_a_higher_mount_sees_them_farther() {
        let mut lidar = Config::default();
        lidar.sensor.preset = SensorPreset::Lidar64;
        lidar.arbiter.cruise_speed_mps = 10.0;
        // The window as far as 10 m/s needs (held to the suspect bound, it
        // would reach 25 m).
        lidar.lookahead.hole_speed_cap = false;
        let b = resolved_bound(&lidar);
        let d = &lidar.perception.drop_off;
        let grazed = b.hole_grazed_m.unwrap();
        let shown = d.max_gap_m * 2.4 / grazed;
        assert!(
            (shown - (d.min_depth_m + d.depth_per_m * grazed)).abs() < 1e-9,
            "{b:?}"
        );
        assert!((8.0..9.0).contains(&grazed), "{b:?}");
        let range = b.hole_certain_m.unwrap();
        let spacing = range * range * b.beam_spacing_deg.to_radians() / 2.4;
        let shown = (d.max_gap_m - spacing) * 2.4 / range;
        assert!(
            (shown - (d.min_depth_m + d.depth_per_m * range)).abs() < 1e-9,
            "{b:?}"
        );
        assert!((6.5..7.5).contains(&range), "{b:?}");
        assert!(b.detection_range_m > 25.0, "{b:?}");
        let hole = b.hole_bound_mps.unwrap();
        assert!(hole < 0.5 * b.bound_mps, "{b:?}");
        let mut higher = lidar.clone();
        higher.sensor.mount_position_m = Some([1.2, 0.0, 3.6]);
        let h = resolved_bound(&higher);
        // Half as high again: the grazing ray's range 1.44 times, the
        // certain one 1.37 (the rows' spacing grows with R² as the dip).
        assert!(h.hole_grazed_m.unwrap() > 1.4 * grazed, "{h:?}");
        assert!(h.hole_certain_m.unwrap() > 1.3 * range, "{h:?}");
        assert!(h.hole_bound_mps.unwrap() > hole);
        let mut off = lidar.clone();
        off.perception.drop_off.enabled = false;
        let o = resolved_bound(&off);
        assert_eq!(
            (o.hole_certain_m, o.hole_bound_mps, o.hole_grazed_m),
            (None, None, None)
        );
        assert_eq!(o.bound_mps, b.bound_mps);
    }

    #[test]
    fn streamed_slices_take_a_slice_not_a_frame_of_acquisition() {
        let mut whole = Config::default();
        whole.sensor.preset = SensorPreset::Lidar64;
        let mut sliced = whole.clone();
        sliced.sim.slice_lines = 16;
        let (w, s) = (resolved_bound(&whole), resolved_bound(&sliced));
        // 16 of 2048 columns at 10 Hz: 0.78 ms instead of 100 ms.
        assert!(
            (w.reaction_s - s.reaction_s - (0.1 - 0.00078125)).abs() < 1e-6,
            "{w:?} {s:?}"
        );
        assert!(s.bound_mps > w.bound_mps);
        // The ERIM in blocks of 4 of its 64 rows: 31 ms instead of 500 ms.
        let mut erim = Config::default();
        erim.sim.slice_lines = 4;
        let e = resolved_bound(&erim);
        assert!(
            (resolved_bound(&Config::default()).reaction_s - e.reaction_s - 0.46875).abs() < 1e-6
        );
    }

    /// A hole is suspected farther than it is flagged (its dip need only
    /// exceed the noise, not the step the wheels tolerate), but only where
    /// the row landing first past its edge, up to a row's spacing
    /// `R²·δθ/H` in, still shows `noise_m + Δ·R` of its far wall: for the
    /// 64-beam lidar 2.4 m up, rows 0.42° apart, within 11.4 m, nearer
    /// than either the dip (19 m) or the spacing (15.9 m) allows alone.
    /// The suspect bound is the speed that stops within that range, less
    /// the sensor's setback from the front.
    #[test]
    fn holes_are_suspected_farther_than_flagged_and_the_rows_set_how_far() {
        let mut lidar = Config::default();
        lidar.sensor.preset = SensorPreset::Lidar64;
        lidar.arbiter.cruise_speed_mps = 10.0;
        let b = resolved_bound(&lidar);
        let (range, bound) = (b.suspect_range_m.unwrap(), b.suspect_bound_mps.unwrap());
        let d = &lidar.perception.drop_off;
        let spacing = range * range * b.beam_spacing_deg.to_radians() / 2.4;
        let shown = (d.max_gap_m - spacing) * 2.4 / range;
        assert!(
            (shown - (d.noise_m + d.depth_per_m * range)).abs() < 1e-9,
            "{b:?}"
        );
        assert!((11.0..12.0).contains(&range), "{b:?}");
        let rows = (d.max_gap_m * 2.4 / b.beam_spacing_deg.to_radians()).sqrt();
        assert!(range < rows && d.max_gap_m * 2.4 / range > d.noise_m + d.depth_per_m * range);
        assert!(range > b.hole_certain_m.unwrap() && bound > b.hole_bound_mps.unwrap());
        let setback = b.hole_grazed_m.unwrap() - b.hole_seen_within_m.unwrap();
        let (t, a) = (b.reaction_s, lidar.vehicle.max_deceleration_mps2);
        let stopped_in = bound * t + bound * bound / (2.0 * a);
        assert!((stopped_in - (range - setback)).abs() < 1e-9, "{b:?}");
        // Suspected drop-offs not reported: no such bound.
        let mut off = lidar.clone();
        off.perception.drop_off.suspect_cost = 0.0;
        let o = resolved_bound(&off);
        assert_eq!((o.suspect_range_m, o.suspect_bound_mps), (None, None));
        assert_eq!(o.hole_certain_m, b.hole_certain_m);
    }
}
