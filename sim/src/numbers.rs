//! Numbers the simulator's modules share: the bound on a world's numbers
//! and a fast floor for the ray walks and the noise lattice.

/// Every number of a world file (metres, degrees, a height file's scale)
/// lies within this of 0: heights are kept as `f32` cells, and `1e300`
/// turned them infinite.
pub(crate) const MAX_MAGNITUDE: f64 = 100_000.0;

/// `x.floor() as i64` without the library call `floor` is on x86-64's
/// baseline (no SSE4.1): a few percent of a frame.
pub(crate) use arcnav_vehicle::numbers::floor_i64 as floor;
