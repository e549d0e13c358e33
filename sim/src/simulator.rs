//! The simulator stepping itself: every pose tick the vehicle model advances
//! under the commands it has been sent, is draped on the terrain and checked
//! against the true hazards; the pose is measured (with noise and drift if
//! configured) and, at each sensor's rate, a range image (or the slices of
//! one) is ray-cast from the true pose.
//!
//! What it hands out is what a vehicle's sensors would: a [`Step`] holds the
//! measured pose and the images and slices acquired since the last one, in
//! the order a pipeline must take them. Nothing of the ground truth reaches
//! a pipeline through it; the truth is kept for the report ([`Simulator::truth`],
//! [`Simulator::ride`]).

use std::sync::Arc;
use std::time::Instant;

use arcnav_perception::{RangeImage, RangeSlice, SensorModel};
use arcnav_vehicle::frames::isometry_from_xyz_rpy;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{
    Isometry, MotionLimits, MotionModel, PlanarState, Pose, SteeringCommand, Utime, VehicleConfig,
};
use nalgebra::Vector3;

use crate::ahead::{FrameRequest, Frames, view_for};
use crate::drape::drape;
use crate::rng::Rng;
use crate::sensor::{SliceRequest, Slicer};
use crate::tiles::{TileCache, TileView};
use crate::{CollisionPolicy, Ride, SimConfig, Truth, World, WorldError};

/// What the simulator needs besides the world: the vehicle, the simulation
/// settings, the sensors on board and how far perception looks.
#[derive(Debug, Clone, Copy)]
pub struct Setup<'a> {
    pub vehicle: &'a VehicleConfig,
    pub sim: &'a SimConfig,
    pub sensors: &'a [SensorModel],
    /// The farthest range perception evaluates (m): returns beyond it and
    /// `sim.render_margin_m` are never used, so never rendered.
    pub evaluated_range_m: f64,
    /// Whether the simulator has the machine's cores to itself (not one of
    /// several missions side by side): only then are frames rendered ahead,
    /// and only then does `sim.threads = 0` (all cores) render on more
    /// than this thread.
    pub exclusive: bool,
    /// The time of the first tick.
    pub start: Utime,
    /// The mission's operating area, if it has one: leaving it is a
    /// collision in the ground truth.
    pub area: Option<&'a arcnav_vehicle::mission::Area>,
}

/// One pose tick of the simulator.
#[derive(Debug)]
pub enum Stepped {
    /// The vehicle hit a hazard under [`CollisionPolicy::Stop`]: the run
    /// ends at this tick, nothing more is sensed.
    Collided { state: PlanarState },
    /// What the vehicle's sensors saw at this tick.
    Sensed(Step),
}

/// What the sensors acquired at one tick, in the order a pipeline takes it:
/// the slices completed since the last tick, then the pose, then the whole
/// images due now.
#[derive(Debug)]
pub struct Step {
    /// The tick's time.
    pub utime: Utime,
    /// The tick's number (0 at the start).
    pub tick: u64,
    /// The vehicle's true planar state (for the track and the progress).
    pub state: PlanarState,
    /// Slices completed since the last tick: sensor index, the time the
    /// slice was complete, the slice.
    pub slices: Vec<(usize, Utime, RangeSlice)>,
    /// The pose as measured.
    pub pose: Pose,
    /// Whole images due at this tick: sensor index and image.
    pub images: Vec<(usize, RangeImage)>,
}

/// A world, a vehicle in it and its sensors, on simulated time.
pub struct Simulator {
    world: Arc<World>,
    vehicle: VehicleConfig,
    sim: SimConfig,
    /// The sensors as rendered: their range cut to what is evaluated.
    sensors: Vec<Arc<SensorModel>>,
    threads: usize,
    start: Utime,
    dt: Utime,
    tick: u64,
    motion: MotionModel,
    tiles: TileCache,
    truth: Truth,
    ride: Ride,
    pose_rng: Rng,
    drift: [f64; 2],
    /// Each sensor's next image time, and for a sensor sending slices its
    /// slicer and the next slice of the frame under way.
    next_images: Vec<Utime>,
    slicers: Vec<Option<Slicer>>,
    next_slices: Vec<usize>,
    /// Whole frames, each rendered when due or ahead (see `ahead`).
    frames: Vec<Frames>,
    render_ahead: bool,
    previous: PlanarState,
    previous_stance: Option<(Utime, Isometry)>,
    images: u64,
    image_positions: Vec<[f64; 2]>,
    distance_m: f64,
    max_speed_mps: f64,
    render_ms: f64,
    /// Whether this simulator has the cores to itself (see [`Setup`]).
    exclusive: bool,
}

impl Simulator {
    /// The vehicle at the world's start, at `setup.start`; an error when the
    /// world does not suit the vehicle.
    pub fn new(world: Arc<World>, setup: Setup<'_>) -> Result<Self, WorldError> {
        world.validate_for(setup.vehicle, &world.spec.name)?;
        let sim = setup.sim.clone();
        let evaluated = setup.evaluated_range_m + sim.render_margin_m;
        let sensors: Vec<Arc<SensorModel>> = setup
            .sensors
            .iter()
            .map(|sensor| {
                let mut rendered = sensor.clone();
                rendered.max_range_m = sensor.max_range_m.min(evaluated);
                Arc::new(rendered)
            })
            .collect();
        // Beside other missions (a sweep's jobs, one a core) a mission
        // renders and builds tiles on its own thread unless told
        // otherwise: a frame split among threads the other missions also
        // want waits for the one descheduled last.
        let threads = if setup.exclusive || sim.threads != 0 {
            sim.thread_count()
        } else {
            1
        };
        let (start, heading) = world.start;
        let motion = MotionModel::new(
            MotionLimits::from_vehicle(setup.vehicle),
            PlanarState {
                x: start[0],
                y: start[1],
                yaw: heading,
                ..PlanarState::default()
            },
            setup.start,
        );
        let slicers = sensors
            .iter()
            .map(|sensor| (sim.slice_lines > 0).then(|| Slicer::new(sensor, sim.slice_lines)))
            .collect();
        let noise = (sim.range_noise_m, sim.dropout_probability);
        let frames = sensors
            .iter()
            .map(|sensor| Frames::new(Arc::clone(sensor), noise, sim.seed, threads))
            .collect();
        let render_ahead = sim.render_ahead
            && setup.exclusive
            && sensors.len() == 1
            && sim.slice_lines == 0
            && seconds_to_micros(setup.vehicle.command_latency_s) >= sensors[0].period_us();
        Ok(Self {
            tiles: TileCache::new(Arc::clone(&world), 128, threads),
            truth: Truth::new(&world, setup.vehicle, setup.area),
            ride: Ride::new(setup.start, setup.vehicle.max_slope_deg),
            pose_rng: Rng::stream(sim.seed, 0x0b5e_55ed),
            drift: [0.0; 2],
            next_images: vec![setup.start; sensors.len()],
            next_slices: vec![0; sensors.len()],
            slicers,
            frames,
            render_ahead,
            exclusive: setup.exclusive,
            previous: *motion.state(),
            previous_stance: None,
            motion,
            images: 0,
            image_positions: Vec::new(),
            distance_m: 0.0,
            max_speed_mps: 0.0,
            render_ms: 0.0,
            dt: seconds_to_micros(1.0 / sim.pose_rate_hz),
            start: setup.start,
            tick: 0,
            vehicle: setup.vehicle.clone(),
            sensors,
            threads,
            world,
            sim,
        })
    }

    /// The time of the next tick.
    pub fn time(&self) -> Utime {
        self.start + self.tick as i64 * self.dt
    }

    /// A steering command sent to the vehicle; it acts after the vehicle's
    /// command latency.
    pub fn command(&mut self, command: SteeringCommand) {
        self.motion.command(command);
    }

    /// The next tick: the vehicle moves, is checked against the hazards,
    /// and its sensors acquire what is due.
    pub fn step(&mut self) -> Stepped {
        let t = self.time();
        let state = self.motion.advance_to(t);
        let stepped = (state.x - self.previous.x).hypot(state.y - self.previous.y);
        self.distance_m += stepped;
        self.previous = state;
        self.max_speed_mps = self.max_speed_mps.max(state.speed_mps);
        let stance = drape(&self.world, &self.vehicle, &state);
        self.ride.observe(t, &stance);
        let collided = !self.truth.check(&self.world, t, &stance).is_empty();
        if collided && self.sim.on_collision == CollisionPolicy::Stop {
            return Stepped::Collided { state };
        }
        let pose = self.measure(t, stepped, &state, &stance);
        let slices = self.slices_until(t, &state, &stance.world_from_vehicle);
        self.previous_stance = Some((t, stance.world_from_vehicle));
        let images = self.images_at(t, &state, &stance.world_from_vehicle);
        let step = Step {
            utime: t,
            tick: self.tick,
            state,
            slices,
            pose,
            images,
        };
        self.tick += 1;
        Stepped::Sensed(step)
    }

    /// The pose the vehicle's navigation reports: the true one with noise
    /// and drift if configured.
    fn measure(
        &mut self,
        t: Utime,
        stepped: f64,
        state: &PlanarState,
        stance: &crate::drape::Stance,
    ) -> Pose {
        let sim = &self.sim;
        let rng = &mut self.pose_rng;
        if sim.drift_per_m > 0.0 {
            self.drift[0] += stepped * sim.drift_per_m * rng.normal();
            self.drift[1] += stepped * sim.drift_per_m * rng.normal();
        }
        let (noise_x, noise_y, noise_yaw) = if sim.pose_noise_m > 0.0 || sim.heading_noise_deg > 0.0
        {
            (
                sim.pose_noise_m * rng.normal(),
                sim.pose_noise_m * rng.normal(),
                sim.heading_noise_deg.to_radians() * rng.normal(),
            )
        } else {
            (0.0, 0.0, 0.0)
        };
        let true_position = stance.world_from_vehicle.translation.vector;
        Pose {
            utime: t,
            world_from_vehicle: isometry_from_xyz_rpy(
                [
                    true_position.x + self.drift[0] + noise_x,
                    true_position.y + self.drift[1] + noise_y,
                    true_position.z,
                ],
                stance.roll,
                stance.pitch,
                state.yaw + noise_yaw,
            ),
            velocity: Vector3::new(
                state.speed_mps * state.yaw.cos(),
                state.speed_mps * state.yaw.sin(),
                0.0,
            ),
            // On an arc, or turning in place.
            yaw_rate: state.speed_mps * state.curvature + self.motion.turn_rate(),
        }
    }

    /// Slices acquired since the last tick, which come before this tick's
    /// pose (they wait in perception for the pose after them). Each is
    /// rendered where the vehicle was at its middle line; those of one tick
    /// side by side.
    fn slices_until(
        &mut self,
        t: Utime,
        state: &PlanarState,
        now: &Isometry,
    ) -> Vec<(usize, Utime, RangeSlice)> {
        let mut out = Vec::new();
        for (i, slicer) in self.slicers.iter().enumerate() {
            let Some(slicer) = slicer else { continue };
            let mut due: Vec<(usize, Utime, Utime, Isometry, u64)> = Vec::new();
            loop {
                let frame = self.next_images[i];
                let k = self.next_slices[i];
                let (done, middle) = slicer.times(frame, k);
                if done > t {
                    break;
                }
                let at = match self.previous_stance {
                    Some((before, ref from)) if t > before => {
                        let f = ((middle - before) as f64 / (t - before) as f64).clamp(0.0, 1.0);
                        from.lerp_slerp(now, f)
                    }
                    _ => *now,
                };
                let stream = self.images.wrapping_mul(65_536).wrapping_add(k as u64);
                due.push((k, frame, done, at, stream));
                self.next_slices[i] = k + 1;
                if self.next_slices[i] == slicer.len() {
                    self.next_slices[i] = 0;
                    self.next_images[i] += self.sensors[i].period_us();
                    self.images += 1;
                    self.image_positions.push([state.x, state.y]);
                }
            }
            if due.is_empty() {
                continue;
            }
            let started = Instant::now();
            let views: Vec<TileView> = due
                .iter()
                .map(|(_, _, _, at, _)| view_for(&self.sensors[i], &mut self.tiles, at))
                .collect();
            let requests: Vec<SliceRequest<'_>> = due
                .iter()
                .zip(&views)
                .map(|(&(k, frame, _, at, stream), view)| SliceRequest {
                    k,
                    frame,
                    view,
                    world_from_vehicle: at,
                    stream,
                })
                .collect();
            let noise = (self.sim.range_noise_m, self.sim.dropout_probability);
            let slices = slicer.render_all(&requests, noise, self.sim.seed, self.threads);
            self.render_ms += started.elapsed().as_secs_f64() * 1e3;
            out.extend(
                due.iter()
                    .zip(slices)
                    .map(|((_, _, done, _, _), slice)| (i, *done, slice)),
            );
        }
        out
    }

    /// The whole images due at `t`; and the next frame of a sensor that
    /// renders ahead started on the other cores, where the commands sent so
    /// far put the vehicle when it is due.
    fn images_at(
        &mut self,
        t: Utime,
        state: &PlanarState,
        now: &Isometry,
    ) -> Vec<(usize, RangeImage)> {
        let mut out = Vec::new();
        for i in 0..self.sensors.len() {
            if self.slicers[i].is_some() || t < self.next_images[i] {
                continue;
            }
            let request = FrameRequest {
                utime: t,
                world_from_vehicle: *now,
                stream: self.images,
            };
            let (image, ms) = self.frames[i].render(&mut self.tiles, &request);
            self.render_ms += ms;
            if self.exclusive {
                // The tiles the vehicle drives towards are built while the
                // pipeline works, on a core of their own.
                crate::ahead::prefetch_for(&self.sensors[i], &mut self.tiles, now);
            }
            self.next_images[i] += self.sensors[i].period_us();
            if self.render_ahead {
                let (utime, world_from_vehicle) = self.pose_when_due(self.next_images[i]);
                let request = FrameRequest {
                    utime,
                    world_from_vehicle,
                    stream: self.images + 1,
                };
                self.frames[i].render_ahead(&mut self.tiles, request);
            }
            out.push((i, image));
            self.images += 1;
            self.image_positions.push([state.x, state.y]);
        }
        out
    }

    /// Where the vehicle will be at the first tick at or after `due`, and
    /// that tick's time, under the commands sent so far: the ticks taken on
    /// a copy of the motion model.
    fn pose_when_due(&self, due: Utime) -> (Utime, Isometry) {
        let mut motion = self.motion.clone();
        let mut tick = self.tick;
        let mut t = self.start + tick as i64 * self.dt;
        while t < due {
            tick += 1;
            t = self.start + tick as i64 * self.dt;
            motion.advance_to(t);
        }
        (
            t,
            drape(&self.world, &self.vehicle, motion.state()).world_from_vehicle,
        )
    }

    /// The world simulated.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The collisions and the closest approach to a hazard so far.
    pub fn truth(&self) -> &Truth {
        &self.truth
    }

    /// How the ride has been: slopes, roll, pitch.
    pub fn ride(&self) -> &Ride {
        &self.ride
    }

    /// The distance driven (m) and the highest speed (m/s) so far.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    pub fn max_speed_mps(&self) -> f64 {
        self.max_speed_mps
    }

    /// The images acquired so far (a sliced frame counts once complete), and
    /// where the vehicle was at each.
    pub fn images(&self) -> u64 {
        self.images
    }

    pub fn image_positions(&self) -> &[[f64; 2]] {
        &self.image_positions
    }

    /// Milliseconds spent rendering (on whichever thread did).
    pub fn render_ms(&self) -> f64 {
        self.render_ms
    }

    /// Whole frames taken from those rendered ahead, and those thrown away.
    pub fn frames_rendered_ahead(&self) -> (u64, u64) {
        self.frames.iter().fold((0, 0), |(used, wasted), f| {
            (used + f.used, wasted + f.wasted)
        })
    }
}
