//! The configuration's loading, checks, derivations and messages.

use std::path::Path;

use arcnav_behaviours::{GoalSeekingConfig, Registry};
use arcnav_vehicle::VehicleConfig;

use crate::*;

/// `text` resolved with the built-in behaviours.
fn from_toml(text: &str, origin: &str) -> Result<Resolved, ConfigLoadError> {
    Resolved::from_toml(text, origin, &Registry::builtin())
}

fn parse_error(text: &str) -> String {
    from_toml(text, "test.toml").unwrap_err().to_string()
}

#[test]
fn defaults_round_trip_through_toml() {
    let defaults = Config::default();
    let text = defaults.to_toml();
    assert_eq!(Config::parse(&text, "round-trip").unwrap().to_toml(), text);
}

#[test]
fn the_shipped_default_toml_parses_and_equals_the_defaults() {
    assert_eq!(
        Config::parse(DEFAULT_TOML, "config/default.toml")
            .unwrap()
            .to_toml(),
        Config::default().to_toml()
    );
    from_toml(DEFAULT_TOML, "config/default.toml").expect("the shipped defaults resolve");
}

/// `config/skid_steer.toml` is `VehicleConfig::warthog()` (which tests
/// of turning in place use) and resolves.
#[test]
fn the_skid_steer_preset_is_the_warthog_and_resolves() {
    let text = include_str!("../../config/skid_steer.toml");
    let resolved = from_toml(text, "config/skid_steer.toml").expect("the preset resolves");
    assert_eq!(resolved.vehicle, VehicleConfig::warthog());
    assert!(resolved.arcs.turns_in_place());
}

/// `config/camera_ring.toml` resolves: 000's four cameras, judged together.
#[test]
fn the_camera_ring_preset_resolves_with_four_cameras_judged_together() {
    let text = include_str!("../../config/camera_ring.toml");
    let resolved = from_toml(text, "config/camera_ring.toml").expect("the preset resolves");
    assert_eq!(resolved.sensors.len(), 4);
    assert_eq!(resolved.perception.evaluator, "height_diff");
    assert!(resolved.perception.fuse_within_s > 0.0);
}

#[test]
fn the_shipped_default_toml_documents_every_key() {
    fn keys(prefix: &str, table: &toml::Table, out: &mut Vec<String>) {
        for (k, v) in table {
            let key = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match v {
                toml::Value::Table(t) => keys(&key, t, out),
                _ => out.push(key),
            }
        }
    }
    let shipped: toml::Table = toml::from_str(DEFAULT_TOML).unwrap();
    let defaults: toml::Table = toml::from_str(&Config::default().to_toml()).unwrap();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    keys("", &shipped, &mut a);
    keys("", &defaults, &mut b);
    a.sort();
    b.sort();
    assert_eq!(
        a, b,
        "config/default.toml must hold exactly the configuration's keys"
    );
    // Every key carries a comment right above it or on its line, and no
    // line is longer than 120 characters.
    let lines: Vec<&str> = DEFAULT_TOML.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        assert!(
            line.chars().count() <= 120,
            "line {} of config/default.toml is longer than 120 characters",
            i + 1
        );
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with('[') {
            continue;
        }
        let commented = t.contains('#') || (i > 0 && lines[i - 1].trim().starts_with('#'));
        assert!(
            commented,
            "line {} of config/default.toml has no comment: {t}",
            i + 1
        );
    }
}

#[test]
fn an_unknown_key_is_named_with_its_line() {
    let msg = parse_error("[vehicle]\nwheelbase_m = 3.3\nwheel_base = 3.3\n");
    assert!(
        msg.starts_with(
            "test.toml, line 3, `vehicle.wheel_base`: unknown field `wheel_base`, expected one of"
        ),
        "{msg}"
    );
}

#[test]
fn an_unknown_section_is_named() {
    let msg = parse_error("[vehicel]\nwheelbase_m = 3.3\n");
    assert!(
        msg.starts_with("test.toml, line 1, `vehicel`: unknown field `vehicel`"),
        "{msg}"
    );
}

#[test]
fn a_wrong_type_is_named_with_its_line() {
    let msg = parse_error("# comment\n[arcs]\ncount = \"many\"\n");
    assert_eq!(
        msg,
        "test.toml, line 3, `arcs.count`: invalid type: string \"many\", expected usize"
    );
}

#[test]
fn an_out_of_range_value_is_named() {
    let msg = parse_error("[vehicle]\nwidth_m = -2.0\n");
    assert_eq!(
        msg,
        "test.toml: invalid configuration: `vehicle.width_m`: is -2, must be a finite number > 0"
    );
}

#[test]
fn a_contradictory_value_names_both_keys() {
    let msg = parse_error("[vehicle]\nmin_turning_radius_m = 9.0\n");
    assert!(
        msg.starts_with("test.toml: invalid configuration: `arcs.min_radius_m`: is 8 m, tighter than the vehicle's minimum turning radius (vehicle.min_turning_radius_m = 9 m)"),
        "{msg}"
    );
}

#[test]
fn a_perception_region_smaller_than_the_map_window_is_refused() {
    let msg = parse_error("[localmap]\nahead_m = 30.0\n");
    assert!(
        msg.starts_with("test.toml: invalid configuration: `perception.region.ahead_m`: is 22 m, less than localmap.ahead_m (30 m)"),
        "{msg}"
    );
    let msg = parse_error("[perception.region]\nbehind_m = 5.0\n");
    assert!(
        msg.contains("`perception.region.behind_m`: is 5 m, less than localmap.behind_m (20 m)"),
        "{msg}"
    );
    from_toml(
        "[localmap]\nahead_m = 30.0\n[perception.region]\nahead_m = 32.0\n",
        "test.toml",
    )
    .unwrap();
}

#[test]
fn a_perception_threshold_laxer_than_the_vehicle_is_refused() {
    let msg = parse_error("[vehicle]\ntolerated_step_m = 0.15\n");
    assert!(
        msg.starts_with("test.toml: invalid configuration: `perception.cells.max_height_variation_m`: is 0.2, more than vehicle.tolerated_step_m (0.15)"),
        "{msg}"
    );
}

#[test]
fn an_unknown_sensor_preset_is_named() {
    let msg = parse_error("[sensor]\npreset = \"velodyne\"\n");
    assert!(
        msg.starts_with(
            "test.toml, line 2, `sensor.preset`: unknown variant `velodyne`, expected one of"
        ),
        "{msg}"
    );
}

#[test]
fn an_unknown_behaviour_lists_the_known_ones() {
    let msg = parse_error("[behaviours.wall_follower]\ngain = 2.0\n");
    assert_eq!(
        msg,
        "test.toml: invalid configuration: `behaviours.wall_follower`: unknown behaviour \"wall_follower\" (known: goal_seeking, obstacle_avoidance, route)"
    );
}

#[test]
fn a_bad_behaviour_key_is_named() {
    let msg = parse_error("[behaviours.goal_seeking]\nlookahed_m = 3.0\n");
    assert!(
        msg.starts_with("test.toml: invalid configuration: `behaviours.goal_seeking.lookahed_m`: unknown field `lookahed_m`"),
        "{msg}"
    );
}

#[test]
fn a_behaviour_table_changes_only_its_keys_and_the_others_stay() {
    let config = from_toml("[behaviours.goal_seeking]\nlookahead_m = 14.0\n", "t").unwrap();
    let goal = config
        .behaviour_config::<GoalSeekingConfig>("goal_seeking")
        .unwrap();
    assert_eq!(goal.lookahead_m, 14.0);
    assert_eq!(goal.arrival_radius_m, 5.0);
    assert!(config.behaviour_names().any(|n| n == "obstacle_avoidance"));
}

#[test]
fn a_syntax_error_gives_the_line() {
    let msg = parse_error("[vehicle]\nwidth_m = \n");
    assert!(msg.starts_with("test.toml, line 2"), "{msg}");
}

#[test]
fn a_missing_file_is_named() {
    let err = Config::load(Path::new("/nonexistent/arcnav.toml")).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("cannot read configuration file /nonexistent/arcnav.toml")
    );
}

#[test]
fn partial_files_keep_the_other_defaults() {
    let config = from_toml("[arcs]\ncount = 41\n", "t").unwrap();
    assert_eq!(config.arcs.len(), 41);
    assert_eq!(config.vehicle, VehicleConfig::default());
}

#[test]
fn a_weight_or_required_name_that_is_no_configured_behaviour_is_refused() {
    let msg = parse_error("[arbiter.weights]\nobstacle_avoidence = 0.0\n");
    assert_eq!(
        msg,
        "test.toml: invalid configuration: `arbiter.weights.obstacle_avoidence`: \
         \"obstacle_avoidence\" is not a configured behaviour (configured: goal_seeking, obstacle_avoidance, route)"
    );
    let msg = parse_error("[arbiter]\nrequired = [\"goal_seekin\"]\n");
    assert!(
        msg.contains("`arbiter.required`: \"goal_seekin\" is not a configured behaviour"),
        "{msg}"
    );
}

#[test]
fn external_behaviours_are_parsed_once_weighted_expected_and_checked() {
    let config = from_toml(
        "[behaviours.external.heading_hold]\ncommand = [\"python3\", \"hh.py\"]\ntimeout_s = 0.5\n\
         [arbiter]\nrequired = [\"heading_hold\"]\n[arbiter.weights]\nheading_hold = 0.5\n",
        "t",
    )
    .unwrap();
    let external = &config.external["heading_hold"];
    assert_eq!(external.command, ["python3", "hh.py"]);
    assert_eq!(external.timeout_s, 0.5);
    assert_eq!(external.start_timeout_s, 10.0);
    // Not a built-in behaviour: the registry never sees its table.
    assert!(!config.behaviour_names().any(|n| n == "external"));
    assert!(
        config
            .expected_behaviours()
            .contains(&"heading_hold".to_owned())
    );
    let unweighted = from_toml(
        "[behaviours.external.heading_hold]\n[arbiter.weights]\nheading_hold = 0.0\n",
        "t",
    )
    .unwrap();
    assert!(
        !unweighted
            .expected_behaviours()
            .contains(&"heading_hold".to_owned())
    );
    for (toml, expect) in [
        (
            "[behaviours.external.\"Heading Hold\"]\n",
            "`behaviours.external.Heading Hold`: \"Heading Hold\" is not a behaviour name",
        ),
        (
            "[behaviours.external.route]\n",
            "\"route\" is also configured under [behaviours.route]",
        ),
        (
            "[behaviours.external]\nx = 3\n",
            "`behaviours.external.x`: must be a table",
        ),
        (
            "[behaviours.external.x]\ncomand = [\"a\"]\n",
            "`behaviours.external.x`: unknown field `comand`",
        ),
        (
            "[behaviours.external.x]\ntimeout_s = 0.0\n",
            "`behaviours.external.x.timeout_s`",
        ),
        (
            "[behaviours.external.x]\ncommand = [\"\"]\n",
            "`behaviours.external.x.command`: starts with an empty program name",
        ),
        (
            "[behaviours.external.x]\n[arbiter]\nrequired = [\"y\"]\n",
            "`arbiter.required`: \"y\" is not a configured behaviour (configured: goal_seeking, \
             obstacle_avoidance, route; external: x)",
        ),
        (
            "[live]\nexternal_behaviours = [\"x\"]\n",
            "unknown field `external_behaviours`",
        ),
    ] {
        let msg = parse_error(toml);
        assert!(msg.contains(expect), "{toml}: {msg}");
    }
}

#[test]
fn a_weights_table_changes_only_the_weights_it_names() {
    let config = from_toml("[arbiter.weights]\ngoal_seeking = 0.8\n", "t").unwrap();
    assert_eq!(config.arbiter.weight("goal_seeking"), 0.8);
    assert_eq!(config.arbiter.weight("obstacle_avoidance"), 1.0);
}

#[test]
fn a_cruise_speed_above_the_vehicles_top_speed_is_refused() {
    let msg = parse_error("[arbiter]\ncruise_speed_mps = 12.0\n");
    assert!(
        msg.contains("`arbiter.cruise_speed_mps`: is 12 m/s, faster than the vehicle's top speed (vehicle.max_speed_mps = 10 m/s)"),
        "{msg}"
    );
}

#[test]
fn behaviours_are_built_from_the_tables_checked_once_and_a_table_changed_in_code_is_checked_too() {
    let config = from_toml("[behaviours.goal_seeking]\nlookahead_m = 14.0\n", "t").unwrap();
    assert_eq!(config.build_behaviours().len(), 3);
    // A table changed in code before resolving is checked as a file's is.
    let mut given = Config::parse("[behaviours.goal_seeking]\nlookahead_m = 14.0\n", "t").unwrap();
    given
        .behaviours
        .get_mut("goal_seeking")
        .unwrap()
        .insert("lookahed_m".into(), toml::Value::Float(3.0));
    let err = given.resolve(&Registry::builtin()).err().unwrap();
    assert_eq!(err.key, "behaviours.goal_seeking.lookahed_m");
}

#[test]
fn an_endless_configuration_file_is_refused_not_read_until_memory_runs_out() {
    let err = Config::load(Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("cannot read configuration file /dev/zero: it is larger than 16 MiB"),
        "{err}"
    );
}

#[test]
fn weights_that_leave_no_behaviour_voting_are_refused() {
    let msg = parse_error("[arbiter.weights]\nobstacle_avoidance = 0.0\nroute = 0.0\n");
    assert!(
        msg.contains("`arbiter.weights`: every configured behaviour has weight 0"),
        "{msg}"
    );
}

#[test]
fn several_sensors_each_with_its_own_id_mount_and_rate() {
    let config = from_toml(
        "[[sensors]]\npreset = \"lidar64\"\n[[sensors]]\npreset = \"depth_camera\"\nid = \"rear\"\n\
         mount_position_m = [-0.6, 0.0, 2.0]\nmount_rpy_deg = [0.0, 25.0, 180.0]\nrate_hz = 10.0\n",
        "test.toml",
    )
    .unwrap();
    let models = &config.sensors;
    assert_eq!(models.len(), 2);
    assert_eq!(models[0], arcnav_perception::SensorModel::lidar64());
    assert_eq!(models[1].id, "rear");
    assert_eq!(models[1].rate_hz, 10.0);
    let yaw = arcnav_vehicle::frames::yaw_of(&models[1].vehicle_from_sensor);
    assert!((yaw.abs() - std::f64::consts::PI).abs() < 1e-9, "{yaw}");
    assert_eq!(
        models[1].beams,
        arcnav_perception::SensorModel::depth_camera().beams
    );
    // Without [[sensors]], [sensor] is the one sensor.
    assert_eq!(Resolved::default().sensors.len(), 1);
}

/// Issue 63 item 4: the perception latency sim and replay assume is the
/// sensor's own unless given (the slowest sensor's with several), and the
/// speed governor reasons with the reaction time it makes.
#[test]
fn the_perception_latency_is_each_sensors_own_unless_given() {
    use arcnav_pipeline::Latency;
    let latency = |text: &str| from_toml(text, "test.toml").unwrap();
    let erim = latency("");
    assert_eq!(erim.pipeline.perception_latency_s, Latency::Seconds(0.3));
    let lidar = latency("[sensor]\npreset = \"lidar64\"\n");
    assert_eq!(lidar.pipeline.perception_latency_s, Latency::Seconds(0.15));
    // 0.1 s to the next frame, 0.15 s to the map, 0.1 s to the next
    // command, 0.25 s to the wheels.
    assert!((lidar.speed_bound.reaction_s - 0.6).abs() < 1e-9);
    let governor = lidar
        .behaviour_config::<arcnav_behaviours::ObstacleAvoidanceConfig>("obstacle_avoidance")
        .unwrap()
        .governor_reaction_s;
    assert_eq!(governor, lidar.speed_bound.reaction_s);
    assert!(
        lidar
            .derivations()
            .iter()
            .any(|d| d.key == "pipeline.perception_latency_s"),
        "{:?}",
        lidar.derivations()
    );
    let both = latency(
        "[[sensors]]\npreset = \"lidar64\"\n[[sensors]]\npreset = \"depth_camera\"\n\
         latency_s = 0.4\n",
    );
    assert_eq!(both.pipeline.perception_latency_s, Latency::Seconds(0.4));
    // The bound reacts as the cells are held: the lidar's frame with the
    // slowest sensor's latency, 0.1 + 0.4 + 0.1 + 0.25 s.
    assert!(
        (both.speed_bound.reaction_s - 0.85).abs() < 1e-9,
        "{:?}",
        both.speed_bound
    );
    let given =
        latency("[sensor]\npreset = \"lidar64\"\n[pipeline]\nperception_latency_s = 0.05\n");
    assert_eq!(given.pipeline.perception_latency_s, Latency::Seconds(0.05));
    assert!((given.speed_bound.reaction_s - 0.5).abs() < 1e-9);
    // The effective configuration holds the number and resolves to itself.
    let effective = lidar.effective();
    assert_eq!(
        effective.pipeline.perception_latency_s,
        Latency::Seconds(0.15)
    );
    let msg = parse_error("[pipeline]\nperception_latency_s = \"soon\"\n");
    assert!(msg.contains("\"auto\" or a number of seconds"), "{msg}");
    let msg = parse_error("[sensor]\nlatency_s = -1.0\n");
    assert!(msg.contains("`sensor.latency_s`"), "{msg}");
}

#[test]
fn two_sensors_with_one_id_or_sensor_and_sensors_together_are_refused() {
    let msg = parse_error("[[sensors]]\npreset = \"lidar64\"\n[[sensors]]\npreset = \"lidar64\"\n");
    assert!(
        msg.contains("`sensors[1].id`: \"lidar64\" is also the id of sensors[0]"),
        "{msg}"
    );
    let msg = parse_error("[sensor]\npreset = \"lidar64\"\n[[sensors]]\npreset = \"erim\"\n");
    assert!(
        msg.contains("`sensor`: is set as well as [[sensors]]"),
        "{msg}"
    );
    let msg = parse_error("[[sensors]]\npreset = \"erim\"\nid = \"front camera\"\n");
    assert!(msg.contains("`sensors[0].id`"), "{msg}");
    let msg = parse_error("[[sensors]]\npreset = \"erim\"\nrate_hz = 0.0\n");
    assert!(msg.contains("`sensors[0].rate_hz`"), "{msg}");
}

#[test]
fn more_sensors_than_the_local_map_tracks_are_refused() {
    let sensors = |n: usize| -> String {
        (0..n)
            .map(|i| format!("[[sensors]]\npreset = \"erim\"\nid = \"s{i}\"\n"))
            .collect()
    };
    assert!(from_toml(&sensors(32), "32.toml").is_ok());
    let msg = parse_error(&sensors(33));
    assert!(
        msg.contains("`sensors`: lists 33 sensors; the local map tracks at most 32"),
        "{msg}"
    );
}

#[test]
fn driven_paths_reach_the_behaviours_steering_response() {
    let config = from_toml("[arcs]\ndriven_paths = true\n", "test.toml").unwrap();
    assert!(config.arcs.driven_paths());
    let response = config.setup().steering_response();
    assert_eq!(
        response,
        arcnav_vehicle::SteeringResponse::of(&config.vehicle)
    );
    let defaults = Resolved::default();
    let response = defaults.setup().steering_response();
    assert_eq!(response, arcnav_vehicle::SteeringResponse::immediate());
}

/// `driven_paths = "auto"` (the default) judges arcs as arcs at the paper's
/// 2-3 m/s and along driven paths above 3 m/s; `true` and `false` hold at
/// every speed; anything else is refused naming the key and what it takes.
#[test]
fn driven_paths_auto_follows_the_cruise_speed() {
    let at = |driven: &str, cruise: f64| {
        let text =
            format!("[arcs]\ndriven_paths = {driven}\n[arbiter]\ncruise_speed_mps = {cruise}\n");
        from_toml(&text, "test.toml").unwrap().arcs.driven_paths()
    };
    assert!(!at("\"auto\"", 2.5));
    assert!(!at("\"auto\"", 3.0));
    assert!(at("\"auto\"", 3.5));
    assert!(at("\"auto\"", 10.0));
    assert!(at("true", 2.5));
    assert!(!at("false", 10.0));
    let cruise = |v: f64| {
        let text = format!("[arbiter]\ncruise_speed_mps = {v}\n");
        from_toml(&text, "test.toml").unwrap().arcs.driven_paths()
    };
    assert!(!cruise(2.5) && cruise(4.5), "the default is auto");
    let error = from_toml("[arcs]\ndriven_paths = \"sometimes\"\n", "test.toml")
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("driven_paths") && error.contains("auto"),
        "{error}"
    );
    // The effective configuration prints what was set, and reads back.
    let effective = Resolved::default().effective().to_toml();
    assert!(effective.contains("driven_paths = \"auto\""), "{effective}");
    let on = from_toml("[arcs]\ndriven_paths = true\n", "test.toml").unwrap();
    assert!(on.effective().to_toml().contains("driven_paths = true"));
}

/// A load parses its text once and checks it once; building nodes from
/// the result, however many and however often, parses and checks nothing
/// again.
#[test]
fn a_configuration_is_parsed_and_validated_once_however_many_nodes_are_built() {
    let before = load_counts();
    let resolved = from_toml(
        "[arbiter]\ncruise_speed_mps = 8.0\n[sensor]\npreset = \"lidar64\"\n",
        "test.toml",
    )
    .unwrap();
    for _ in 0..3 {
        resolved.lockstep().unwrap();
    }
    resolved.perception_node().unwrap();
    let _ = resolved.arbiter();
    let _ = resolved.behaviour_set();
    let _ = resolved.decision_cycle::<()>(arcnav_pipeline::Delivery::held(&resolved.pipeline));
    let after = load_counts();
    assert_eq!(after.parses - before.parses, 1, "{before:?} -> {after:?}");
    assert_eq!(
        after.validations - before.validations,
        1,
        "{before:?} -> {after:?}"
    );
    // Resolving a configuration built in code parses nothing.
    Config::default().resolved().unwrap();
    let code = load_counts();
    assert_eq!(
        (code.parses, code.validations),
        (after.parses, after.validations + 1)
    );
}

/// Every node of a lock-step build drives at one cruise speed, looks as
/// far as one lookahead says and votes over one arc set: at 10 m/s with
/// the 64-beam lidar (the window moved out 25 m), and held to the hole
/// speed cap.
#[test]
fn every_node_of_a_lockstep_build_gets_the_same_cruise_lookahead_and_arcs() {
    let capped = from_toml(
        "[arbiter]\ncruise_speed_mps = 10.0\n[sensor]\npreset = \"lidar64\"\n\
         [lookahead]\nhole_speed_cap = true\n",
        "test.toml",
    )
    .unwrap();
    assert!(
        capped.cruise.capped() && capped.cruise.mps < 6.0,
        "{:?}",
        capped.cruise
    );
    let pipeline = capped.lockstep().unwrap();
    assert_eq!(pipeline.arbiter.cruise_mps(), capped.cruise.mps);
    assert_eq!(capped.setup().cruise_mps, capped.cruise.mps);
    let resolved = from_toml(
        "[arbiter]\ncruise_speed_mps = 10.0\n[sensor]\npreset = \"lidar64\"\n\
         [lookahead]\nhole_speed_cap = false\n",
        "test.toml",
    )
    .unwrap();
    let cruise = resolved.cruise;
    assert!(!cruise.capped() && cruise.mps == 10.0, "{cruise:?}");
    let look = resolved.lookahead;
    assert!(look.moved_m > 0.0, "{look:?}");
    let pipeline = resolved.lockstep().unwrap();
    // The arbiter drives at the capped speed over the resolved arcs...
    assert_eq!(pipeline.arbiter.cruise_mps(), cruise.mps);
    assert_eq!(pipeline.arbiter.arcs(), &resolved.arcs);
    // ... the behaviours vote over the same arcs, built with the same speed
    // and the map window that lookahead set ...
    assert_eq!(pipeline.behaviours.arcs(), &resolved.arcs);
    let setup = resolved.setup();
    assert_eq!(setup.cruise_mps, cruise.mps);
    assert_eq!(setup.arcs, &resolved.arcs);
    assert_eq!(setup.localmap.ahead_m, look.map_ahead_m);
    let avoidance = resolved
        .behaviour_config::<arcnav_behaviours::ObstacleAvoidanceConfig>("obstacle_avoidance")
        .unwrap();
    assert_eq!(avoidance.max_distance_m, look.max_distance_m);
    // ... the local map keeps that window and perception evaluates it.
    let map = pipeline.cycle.map.map.config();
    assert_eq!(
        (map.ahead_m, map.half_width_m),
        (look.map_ahead_m, look.map_half_width_m)
    );
    let perception = pipeline.perception.config();
    assert_eq!(perception.region.ahead_m, look.region_ahead_m);
    assert_eq!(perception.max_range_m, look.max_range_m);
    // The arc set decides driven paths at the speed driven (above 3 m/s).
    assert!(resolved.arcs.driven_paths());
}

/// `arcnav config` says of each key whether it is a default, came from the
/// file or the command line, or was derived, and from what.
#[test]
fn each_key_says_where_its_value_came_from() {
    let mut given = Config::parse(
        "[sensor]\npreset = \"lidar64\"\n[lookahead]\nhole_speed_cap = true\n",
        "my.toml",
    )
    .unwrap();
    given.arbiter.cruise_speed_mps = 10.0;
    given.set_by("arbiter.cruise_speed_mps", "--speed");
    let resolved = given.resolve(&Registry::builtin()).unwrap();
    assert_eq!(resolved.origin("sensor.preset"), "from my.toml");
    assert_eq!(resolved.origin("vehicle.width_m"), "default");
    assert!(
        resolved
            .origin("arbiter.cruise_speed_mps")
            .starts_with("from --speed; derived: driven at 5.6"),
        "{}",
        resolved.origin("arbiter.cruise_speed_mps")
    );
    assert!(
        resolved
            .origin("localmap.hole_range_m")
            .starts_with("default; derived: given as 0")
    );
    let text = resolved.to_toml_with_origins();
    assert!(
        text.contains("preset = \"lidar64\"  # from my.toml"),
        "{text}"
    );
    assert!(
        text.contains("width_m = 2.0  # default") || text.contains("# default"),
        "{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("hole_seen_within_m = ") && l.contains("# default; derived: ")),
        "{text}"
    );
    // What it prints reads back to the same configuration.
    let again = Resolved::from_toml(&text, "printed", &Registry::builtin()).unwrap();
    assert_eq!(again.effective().to_toml(), resolved.effective().to_toml());
    // Without the cap, the asked speed is the one driven and says so.
    let mut uncapped = Config::default();
    uncapped.arbiter.cruise_speed_mps = 3.0;
    uncapped.set_by("arbiter.cruise_speed_mps", "--speed");
    let uncapped = uncapped.resolved().unwrap();
    assert_eq!(uncapped.origin("arbiter.cruise_speed_mps"), "from --speed");
}
