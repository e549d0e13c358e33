//! Worlds: the embedded ones load and can be driven; bad worlds are refused
//! with a message naming the problem.

use std::path::Path;

use arcnav_sim::world::EMBEDDED;
use arcnav_sim::{FeatureKind, World, WorldError};
use arcnav_vehicle::VehicleConfig;

fn error_of(text: &str) -> String {
    match World::from_toml(text, "w.toml", None) {
        Ok(world) => match world.validate_for(&VehicleConfig::default(), "w.toml") {
            Ok(()) => panic!("the world was accepted"),
            Err(e) => e.to_string(),
        },
        Err(e) => e.to_string(),
    }
}

const BASE: &str = "name = \"w\"\n[terrain]\norigin_m = [-50.0, -50.0]\nsize_m = [100.0, 100.0]\n[start]\nposition_m = [0.0, 0.0]\n";

#[test]
fn every_embedded_world_loads_and_can_be_driven() {
    for (name, description, _) in EMBEDDED {
        let world = World::embedded(name).unwrap().unwrap();
        world.validate_for(&VehicleConfig::default(), name).unwrap();
        assert!(!description.is_empty());
        assert!(!world.waypoints.is_empty());
    }
    assert!(World::embedded("atlantis").is_none());
}

#[test]
fn the_default_world_is_the_papers_loop() {
    let world = World::embedded("paper_loop").unwrap().unwrap();
    assert_eq!(world.waypoints.len(), 10);
    let mut route = vec![world.start.0];
    route.extend(world.waypoints.iter().map(|w| [w.x, w.y]));
    let legs: Vec<f64> = route
        .windows(2)
        .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
        .collect();
    let length: f64 = legs.iter().sum();
    assert!(
        (950.0..1050.0).contains(&length),
        "a 1 km loop: {length:.0} m"
    );
    assert!(
        legs.iter().all(|l| (90.0..110.0).contains(l)),
        "legs of about 100 m: {legs:?}"
    );
    let last = route.last().unwrap();
    assert!(
        (last[0] - route[0][0]).hypot(last[1] - route[0][1]) < 1.0,
        "a loop ends where it starts"
    );
    let count = |kind| world.features.iter().filter(|f| f.kind == kind).count();
    assert!(count(FeatureKind::Boulder) >= 40, "rocks");
    assert!(count(FeatureKind::Ditch) >= 5, "ditches");
    assert!(
        count(FeatureKind::Tree) + count(FeatureKind::Bush) >= 30,
        "trees and bushes"
    );
    assert!(count(FeatureKind::Bank) >= 2, "banks");
    // Hills: the terrain varies by metres over the loop.
    let heights: Vec<f64> = route
        .iter()
        .map(|p| world.terrain_height(p[0], p[1]))
        .collect();
    let span = heights.iter().cloned().fold(f64::MIN, f64::max)
        - heights.iter().cloned().fold(f64::MAX, f64::min);
    assert!(span > 1.5, "hills: {span:.1} m of relief");
}

#[test]
fn a_missing_world_file_is_named() {
    let err = World::load(Path::new("/no/such/world.toml")).unwrap_err();
    assert!(matches!(err, WorldError::Read { .. }));
    assert!(
        err.to_string()
            .starts_with("cannot read world file /no/such/world.toml"),
        "{err}"
    );
}

#[test]
fn a_wrong_key_is_named_with_its_line() {
    let text = format!(
        "{BASE}[[waypoints]]\nposition_m = [10.0, 0.0]\n\n[[boulders]]\nposition_m = [5.0, 5.0]\nradius = 1.0\nheight_m = 1.0\n"
    );
    let err = error_of(&text);
    assert!(
        err.starts_with("w.toml, line 12, `boulders.radius`: unknown field `radius`, expected"),
        "{err}"
    );
}

#[test]
fn a_waypoint_inside_an_obstacle_is_refused() {
    let text = format!(
        "{BASE}[[waypoints]]\nposition_m = [20.0, 0.0]\n[[waypoints]]\nposition_m = [30.0, 10.0]\n[[boulders]]\nposition_m = [30.2, 10.1]\nradius_m = 1.0\nheight_m = 0.8\n"
    );
    let err = error_of(&text);
    assert_eq!(
        err,
        "w.toml: waypoint 2 at (30.0, 10.0) lies inside boulder #0 (boulder 0.80 m tall) at (30.2, 10.1)"
    );
}

#[test]
fn a_start_pose_off_the_map_is_refused() {
    let text = "name = \"w\"\n[terrain]\norigin_m = [-50.0, -50.0]\nsize_m = [100.0, 100.0]\n[start]\nposition_m = [80.0, 0.0]\n[[waypoints]]\nposition_m = [10.0, 0.0]\n";
    assert_eq!(
        error_of(text),
        "w.toml: the start pose [80.0, 0.0] is off the map [-50, 50] × [-50, 50]"
    );
}

#[test]
fn a_start_on_an_obstacle_and_a_world_without_waypoints_are_refused() {
    let text = format!(
        "{BASE}[[waypoints]]\nposition_m = [20.0, 0.0]\n[[ditches]]\nfrom_m = [1.0, -5.0]\nto_m = [1.0, 5.0]\nwidth_m = 1.0\ndepth_m = 0.8\n"
    );
    assert!(
        error_of(&text).contains("the start pose at (0.0, 0.0) is within 4.6 m of ditch #0"),
        "{}",
        error_of(&text)
    );
    assert_eq!(error_of(BASE), "w.toml: the world has no [[waypoints]]");
}

#[test]
fn height_files_are_read_and_resampled() {
    let dir = arcnav_testkit::scratch_dir("arcnav-worlds");
    let asc = "ncols 4\nnrows 4\nxllcorner -60\nyllcorner -60\ncellsize 40\n0 0 0 0\n0 4 4 0\n0 4 4 0\n0 0 0 0\n";
    std::fs::write(dir.join("dem.asc"), asc).unwrap();
    let text = "name = \"dem\"\n[terrain]\norigin_m = [-50.0, -50.0]\nsize_m = [100.0, 100.0]\nheightmap = \"dem.asc\"\nroughness_amplitude_m = 0.0\n[start]\nposition_m = [-45.0, -45.0]\n[[waypoints]]\nposition_m = [0.0, 0.0]\n";
    std::fs::write(dir.join("w.toml"), text).unwrap();
    let world = World::load(&dir.join("w.toml")).unwrap();
    assert!(
        (world.height(0.0, 0.0) - 4.0).abs() < 0.6,
        "the hill in the middle: {}",
        world.height(0.0, 0.0)
    );
    // Smooth: no jump between neighbouring points.
    let steps: Vec<f64> = (0..100)
        .map(|i| world.height(-40.0 + i as f64 * 0.8, 0.0))
        .collect();
    assert!(steps.windows(2).all(|w| (w[1] - w[0]).abs() < 0.2));
    std::fs::write(dir.join("bad.toml"), text.replace("dem.asc", "missing.npy")).unwrap();
    let err = World::load(&dir.join("bad.toml")).unwrap_err().to_string();
    assert!(
        err.contains("missing.npy") && err.contains("cannot read it"),
        "{err}"
    );
}

#[test]
fn numbers_that_are_not_finite_are_refused_naming_their_key() {
    let wp = "[[waypoints]]\nposition_m = [30.0, 0.0]\n";
    for (extra, key) in [
        ("heading_deg = nan\n", "start.heading_deg"),
        (
            "[[trees]]\nposition_m = [10.0, 10.0]\nradius_m = inf\nheight_m = 3.0\n",
            "trees[0].radius_m",
        ),
        (
            "[[waypoints]]\nposition_m = [20.0, 0.0]\nradius_m = -2.0\n",
            "radius_m -2 must be a positive",
        ),
    ] {
        let text = if extra.starts_with("heading") {
            format!("{BASE}{extra}{wp}")
        } else {
            format!("{BASE}{wp}{extra}")
        };
        let err = error_of(&text);
        assert!(err.contains(key), "{extra}: {err}");
    }
    let err = error_of(&format!(
        "{}{wp}",
        BASE.replace("[start]", "hills_amplitude_m = nan\n[start]")
    ));
    assert!(
        err.contains("terrain.hills_amplitude_m is not a finite number"),
        "{err}"
    );
}

#[test]
fn numbers_that_would_make_the_heights_infinite_or_nan_are_refused_naming_their_key() {
    // Each had built a world whose heights were NaN or infinite: the
    // mission ran, placed no image and reported the vehicle stuck.
    let wp = "[[waypoints]]\nposition_m = [30.0, 0.0]\n";
    for (terrain, expect) in [
        (
            "hills_wavelength_m = 1e-300\n",
            "terrain.hills_wavelength_m is 1e-300: terrain wavelengths are at least 0.01 m",
        ),
        (
            "roughness_wavelength_m = 0.0\n",
            "terrain.roughness_wavelength_m is 0.0: terrain wavelengths are at least 0.01 m",
        ),
        (
            "hills_amplitude_m = 1e300\n",
            "terrain.hills_amplitude_m is 1e300: numbers in a world lie within ±100000",
        ),
    ] {
        let text = format!(
            "{}{wp}",
            BASE.replace("[start]", &format!("{terrain}[start]"))
        );
        let err = error_of(&text);
        assert!(err.contains(expect), "{terrain}: {err}");
    }
    let err = error_of(&format!(
        "{BASE}{wp}[[boulders]]\nposition_m = [10.0, 0.0]\nradius_m = 1.0\nheight_m = -2e5\n"
    ));
    assert!(
        err.contains("boulders[0].height_m is -200000.0: numbers in a world lie within ±100000"),
        "{err}"
    );
    // The same from a height file.
    let dir = arcnav_testkit::scratch_dir("arcnav-worlds-huge");
    let asc = "ncols 2\nnrows 2\nxllcorner -50\nyllcorner -50\ncellsize 100\n0 0\n0 1e30\n";
    std::fs::write(dir.join("dem.asc"), asc).unwrap();
    let text = "name = \"dem\"\n[terrain]\norigin_m = [-50.0, -50.0]\nsize_m = [100.0, 100.0]\nheightmap = \"dem.asc\"\n[start]\nposition_m = [-45.0, -45.0]\n[[waypoints]]\nposition_m = [0.0, 0.0]\n";
    std::fs::write(dir.join("w.toml"), text).unwrap();
    let err = World::load(&dir.join("w.toml")).unwrap_err().to_string();
    assert!(err.contains("heights lie within ±100000 m"), "{err}");
}

#[test]
fn a_height_file_covering_a_sliver_of_the_world_is_refused() {
    let dir = arcnav_testkit::scratch_dir("arcnav-worlds-sliver");
    // 150 nm across for a 100 m world: the resolution is in the wrong unit.
    let asc = "ncols 4\nnrows 4\nxllcorner 0\nyllcorner 0\ncellsize 0.00000005\n0 0 0 0\n0 4 4 0\n0 4 4 0\n0 0 0 0\n";
    std::fs::write(dir.join("dem.asc"), asc).unwrap();
    let text = "name = \"dem\"\n[terrain]\norigin_m = [-50.0, -50.0]\nsize_m = [100.0, 100.0]\nheightmap = \"dem.asc\"\n[start]\nposition_m = [-45.0, -45.0]\n[[waypoints]]\nposition_m = [0.0, 0.0]\n";
    std::fs::write(dir.join("w.toml"), text).unwrap();
    let err = World::load(&dir.join("w.toml")).unwrap_err().to_string();
    assert!(
        err.contains("less than half of the 100 m × 100 m world"),
        "{err}"
    );
}

/// A tile's heights, taken row by row (`World::heights_along`), are the
/// world's heights point by point, bit for bit, and so are the terrain's
/// without its features (`World::terrain_heights_along`, what map.png is
/// shaded from): every embedded world, a generated hard one and the DEM
/// loop.
#[test]
fn heights_along_a_row_are_the_heights_point_by_point() {
    let mut worlds: Vec<World> = EMBEDDED
        .iter()
        .map(|(name, _, _)| World::embedded(name).unwrap().unwrap())
        .collect();
    worlds.push(
        World::build(
            arcnav_sim::generate(3, arcnav_sim::Difficulty::Hard),
            "generated",
            None,
        )
        .unwrap(),
    );
    let dem = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/worlds/dem_loop.toml");
    worlds.push(World::load(&dem).unwrap());
    for world in &worlds {
        let [x0, y0, x1, y1] = world.bounds;
        for k in 0..25 {
            let y = y0 + (y1 - y0) * (k as f64 + 0.37) / 25.0;
            let xs: Vec<f64> = (0..400)
                .map(|i| x0 + (x1 - x0) * (i as f64 + 0.5) / 400.0)
                .collect();
            let mut row = vec![0.0; xs.len()];
            world.heights_along(y, xs.iter().copied(), &mut row);
            let mut terrain = vec![0.0; xs.len()];
            world.terrain_heights_along(y, xs.iter().copied(), &mut terrain);
            for ((x, h), t) in xs.iter().zip(&row).zip(&terrain) {
                assert_eq!(
                    h.to_bits(),
                    world.height(*x, y).to_bits(),
                    "{} at ({x}, {y})",
                    world.spec.name
                );
                assert_eq!(
                    t.to_bits(),
                    world.terrain_height(*x, y).to_bits(),
                    "{}'s terrain at ({x}, {y})",
                    world.spec.name
                );
            }
        }
    }
}
