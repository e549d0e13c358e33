//! The embedding example (examples/embed.rs): a program of its own drives
//! the pipeline as a library and reaches its goal past an obstacle.

#[path = "../examples/embed.rs"]
#[allow(dead_code)]
mod embed;

#[test]
fn a_program_of_its_own_drives_the_pipeline_to_its_goal_around_the_box() {
    // Heavy: one core's share of the suite's work (arcnav_testkit::cpu_slot).
    let _slot = arcnav_testkit::cpu_slot();
    let arrival = embed::drive(&arcnav_config::Resolved::default()).unwrap();
    assert!((arrival.x - 30.0).hypot(arrival.y) <= 2.0);
    // The box's half-diagonal is 1.1 m, the vehicle's half-width about 1 m.
    assert!(
        arrival.closest_to_box_m > 2.5,
        "came within {:.1} m of the box's centre",
        arrival.closest_to_box_m
    );
}
