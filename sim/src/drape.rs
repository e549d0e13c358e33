//! Puts the planar vehicle state on the ground: height and attitude from the
//! world height under the four wheels (the vehicle origin is on the ground
//! under the middle of the rear axle).

use arcnav_vehicle::frames::isometry_from_xyz_rpy;
use arcnav_vehicle::{Isometry, PlanarState, VehicleConfig};

use crate::world::World;

/// The vehicle standing on the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stance {
    pub world_from_vehicle: Isometry,
    pub roll: f64,
    pub pitch: f64,
    /// Mean height of the four wheel contacts: where the body's middle
    /// rides, world z, m.
    pub centre_z: f64,
}

/// Where `state` puts the vehicle on `world`.
pub fn drape(world: &World, vehicle: &VehicleConfig, state: &PlanarState) -> Stance {
    let (sin, cos) = state.yaw.sin_cos();
    let track = vehicle.track_m;
    let wheel = |along: f64, left: f64| {
        let (x, y) = (
            state.x + cos * along - sin * left,
            state.y + sin * along + cos * left,
        );
        world.height(x, y)
    };
    let (rl, rr) = (wheel(0.0, track / 2.0), wheel(0.0, -track / 2.0));
    let (fl, fr) = (
        wheel(vehicle.wheelbase_m, track / 2.0),
        wheel(vehicle.wheelbase_m, -track / 2.0),
    );
    // Pitch is positive nose down (REP 103: rotation about +y).
    let pitch = ((rl + rr) / 2.0 - (fl + fr) / 2.0).atan2(vehicle.wheelbase_m);
    let roll = ((rl + fl) / 2.0 - (rr + fr) / 2.0).atan2(track);
    let z = (rl + rr) / 2.0;
    Stance {
        world_from_vehicle: isometry_from_xyz_rpy([state.x, state.y, z], roll, pitch, state.yaw),
        roll,
        pitch,
        centre_z: (rl + rr + fl + fr) / 4.0,
    }
}
