//! The next whole frame, rendered while the pipeline works on this one.
//!
//! A command acts `vehicle.command_latency_s` after it is decided. When a
//! frame has been rendered, the commands that will move the vehicle until
//! the next frame are therefore already decided, as long as the latency is
//! at least the frame period: where the vehicle will be when the next frame
//! is due is known. The mission starts that frame on the other cores while
//! perception, the local map, the behaviours and the arbiter work on this
//! one on the mission's thread, which renders what is left of it when it
//! gets there: a lidar mission's two halves overlap and both cores stay
//! busy.
//!
//! A frame rendered ahead is used only when what it was rendered from (the
//! time, the vehicle's pose bit for bit, the noise stream) is what the
//! mission renders from when the frame is due. The renderer is a function
//! of those alone, so the mission is the one that renders each frame when
//! due, byte for byte. Otherwise the frame is thrown away and rendered then.

use std::sync::Arc;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Instant;

use crate::sensor::SharedFrame;
use crate::tiles::{TileCache, TileView};
use arcnav_perception::{RangeImage, SensorModel};
use arcnav_vehicle::{Isometry, Utime};

/// What a whole frame is rendered from.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FrameRequest {
    pub utime: Utime,
    pub world_from_vehicle: Isometry,
    /// The frame's noise stream (the mission's image count).
    pub stream: u64,
}

/// One sensor's whole frames, each either rendered when due or taken from
/// the one rendered ahead.
pub(crate) struct Frames {
    sensor: Arc<SensorModel>,
    /// Range noise σ (m) and dropout probability.
    noise: (f64, f64),
    seed: u64,
    threads: usize,
    /// The thread rendering ahead (started with the first frame rendered
    /// ahead), and what it is rendering.
    worker: Option<Worker>,
    ahead: Option<FrameRequest>,
    /// Frames taken from those rendered ahead, and those thrown away.
    pub used: u64,
    pub wasted: u64,
}

/// A thread that starts rendering each frame it is sent: it bins the
/// ground, hands the frame over and renders bands of it until none is left
/// to take. It lives as long as the mission: a thread started for each
/// frame waits a millisecond or two before a core takes it up, which is
/// most of what overlapping saves.
struct Worker {
    jobs: mpsc::Sender<(FrameRequest, TileView)>,
    started: mpsc::Receiver<Arc<SharedFrame>>,
    thread: JoinHandle<()>,
}

impl Frames {
    pub(crate) fn new(
        sensor: Arc<SensorModel>,
        noise: (f64, f64),
        seed: u64,
        threads: usize,
    ) -> Self {
        Self {
            sensor,
            noise,
            seed,
            threads,
            worker: None,
            ahead: None,
            used: 0,
            wasted: 0,
        }
    }

    /// The frame `request` asks for, and the milliseconds spent rendering
    /// it (on whichever thread did).
    pub(crate) fn render(
        &mut self,
        tiles: &mut TileCache,
        request: &FrameRequest,
    ) -> (RangeImage, f64) {
        // The mission's thread renders what the worker has not yet taken
        // of the frame: while the pipeline worked, the worker rendered on
        // the other core; now the two cores finish it together. (A worker
        // rendering on as many threads as there are cores took half a core
        // from the pipeline while it worked, then left that core idle
        // while the pipeline finished alone.)
        match self.take_ahead() {
            Some((ahead, Some(frame))) if ahead == *request => {
                self.used += 1;
                let (image, took) = frame.finish();
                return (image, took.as_secs_f64() * 1e3);
            }
            Some((_, frame)) => self.throw_away(frame),
            None => {}
        }
        let view = view_for(&self.sensor, tiles, &request.world_from_vehicle);
        render_timed(
            &self.sensor,
            &view,
            request,
            self.noise,
            self.seed,
            self.threads,
        )
    }

    /// Starts rendering the frame `request` asks for on other threads.
    pub(crate) fn render_ahead(&mut self, tiles: &mut TileCache, request: FrameRequest) {
        // One not taken is thrown away.
        if let Some((_, frame)) = self.take_ahead() {
            self.throw_away(frame);
        }
        if self.worker.is_none() {
            self.worker = self.start_worker();
        }
        let view = view_for(&self.sensor, tiles, &request.world_from_vehicle);
        // Without the worker the frame is rendered when due, as without this.
        if let Some(worker) = &self.worker {
            if worker.jobs.send((request.clone(), view)).is_ok() {
                self.ahead = Some(request);
            } else {
                self.worker = None;
            }
        }
    }

    /// The frame being rendered ahead, if one is: what it was rendered
    /// from, and the frame (none from a worker that panicked), once the
    /// worker has binned its ground and handed it over.
    fn take_ahead(&mut self) -> Option<(FrameRequest, Option<Arc<SharedFrame>>)> {
        let ahead = self.ahead.take()?;
        let frame = self.worker.as_ref().and_then(|w| w.started.recv().ok());
        if frame.is_none() {
            self.worker = None;
        }
        Some((ahead, frame))
    }

    /// A frame rendered ahead that is not the one asked for: counted, and
    /// its bands not yet taken left unrendered.
    fn throw_away(&mut self, frame: Option<Arc<SharedFrame>>) {
        if let Some(frame) = frame {
            frame.cancel();
        }
        self.wasted += 1;
    }

    fn start_worker(&self) -> Option<Worker> {
        let (jobs, queue) = mpsc::channel::<(FrameRequest, TileView)>();
        let (handed, started) = mpsc::channel();
        // The mission's thread holds a core while the pipeline works: the
        // worker renders on the others (with helpers on a machine of more
        // than two), and the mission's thread helps once it is free.
        let (sensor, noise, seed, helpers) = (
            Arc::clone(&self.sensor),
            self.noise,
            self.seed,
            self.threads.saturating_sub(1).max(1),
        );
        let thread = std::thread::Builder::new()
            .name("render-ahead".into())
            .spawn(move || {
                while let Ok((request, view)) = queue.recv() {
                    let frame = Arc::new(SharedFrame::new(
                        Arc::clone(&sensor),
                        &view,
                        &request.world_from_vehicle,
                        request.utime,
                        noise,
                        (seed, request.stream),
                        helpers,
                    ));
                    if handed.send(Arc::clone(&frame)).is_err() {
                        break;
                    }
                    std::thread::scope(|scope| {
                        for _ in 1..helpers {
                            scope.spawn(|| frame.help());
                        }
                        frame.help();
                    });
                }
            })
            .ok()?;
        Some(Worker {
            jobs,
            started,
            thread,
        })
    }
}

impl Drop for Frames {
    /// The worker is told there is no more and waited for, not left running.
    fn drop(&mut self) {
        if let Some(Worker {
            jobs,
            started,
            thread,
        }) = self.worker.take()
        {
            drop((jobs, started));
            let _ = thread.join();
        }
    }
}

/// Asks for the tiles `sensor` will see a tile's side further on along
/// the vehicle's heading from `world_from_vehicle` to be built ahead
/// ([`TileCache::prefetch`]).
pub(crate) fn prefetch_for(
    sensor: &SensorModel,
    tiles: &mut TileCache,
    world_from_vehicle: &Isometry,
) {
    let at = sensor_position(sensor, world_from_vehicle);
    let heading = world_from_vehicle * nalgebra::Vector3::x();
    let along = heading.xy().try_normalize(1e-9).unwrap_or_default() * crate::tiles::TILE_M;
    tiles.prefetch(at.x + along.x, at.y + along.y, view_radius(sensor));
}

/// Where `sensor` is in the world with the vehicle at `world_from_vehicle`.
fn sensor_position(sensor: &SensorModel, world_from_vehicle: &Isometry) -> nalgebra::Vector3<f64> {
    (world_from_vehicle * sensor.vehicle_from_sensor)
        .translation
        .vector
}

/// How far about the sensor its view's tiles reach: its range and a
/// metre more.
fn view_radius(sensor: &SensorModel) -> f64 {
    sensor.max_range_m + 1.0
}

/// The tiles `sensor` on the vehicle at `world_from_vehicle` sees.
pub(crate) fn view_for(
    sensor: &SensorModel,
    tiles: &mut TileCache,
    world_from_vehicle: &Isometry,
) -> TileView {
    let at = sensor_position(sensor, world_from_vehicle);
    tiles.view(at.x, at.y, view_radius(sensor))
}

fn render_timed(
    sensor: &SensorModel,
    view: &TileView,
    request: &FrameRequest,
    noise: (f64, f64),
    seed: u64,
    threads: usize,
) -> (RangeImage, f64) {
    let started = Instant::now();
    let image = crate::sensor::render(
        sensor,
        view,
        &request.world_from_vehicle,
        request.utime,
        noise,
        (seed, request.stream),
        threads,
    );
    (image, started.elapsed().as_secs_f64() * 1e3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::World;
    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    fn request(x: f64, stream: u64) -> FrameRequest {
        FrameRequest {
            utime: 1_000_000 + stream as Utime,
            world_from_vehicle: isometry_from_xyz_rpy([x, 0.0, 0.0], 0.0, 0.0, 0.3),
            stream,
        }
    }

    /// A frame rendered ahead from what the mission then asks for is the
    /// one rendered when due; one rendered from anything else (another
    /// pose, another noise stream) is thrown away, counted, and the frame
    /// rendered as asked. A frame left rendering when the mission ends is
    /// waited for.
    #[test]
    fn a_frame_rendered_ahead_is_used_only_when_asked_for_exactly() {
        let world = Arc::new(World::embedded("short_course").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 64, 2);
        let mut sensor = SensorModel::erim();
        sensor.max_range_m = 20.0;
        let noise = (0.02, 0.01);
        let mut frames = Frames::new(Arc::new(sensor.clone()), noise, 7, 2);
        let when_due = |request: &FrameRequest, tiles: &mut TileCache| {
            let view = view_for(&sensor, tiles, &request.world_from_vehicle);
            render_timed(&sensor, &view, request, noise, 7, 1).0
        };
        let same = |a: &RangeImage, b: &RangeImage| {
            a.utime == b.utime
                && a.range.len() == b.range.len()
                && a.range
                    .iter()
                    .zip(&b.range)
                    .all(|(x, y)| x.to_bits() == y.to_bits())
        };

        frames.render_ahead(&mut tiles, request(10.0, 1));
        let (image, _) = frames.render(&mut tiles, &request(10.0, 1));
        assert!(same(&image, &when_due(&request(10.0, 1), &mut tiles)));
        assert_eq!((frames.used, frames.wasted), (1, 0));

        for asked in [request(10.5, 2), request(10.0, 3)] {
            frames.render_ahead(&mut tiles, request(10.0, 2));
            let (image, _) = frames.render(&mut tiles, &asked);
            assert!(same(&image, &when_due(&asked, &mut tiles)));
        }
        assert_eq!((frames.used, frames.wasted), (1, 2));

        // Asked for ahead twice before it was due: the first is thrown away.
        frames.render_ahead(&mut tiles, request(11.0, 4));
        frames.render_ahead(&mut tiles, request(12.0, 5));
        let (image, _) = frames.render(&mut tiles, &request(12.0, 5));
        assert!(same(&image, &when_due(&request(12.0, 5), &mut tiles)));
        assert_eq!((frames.used, frames.wasted), (2, 3));

        frames.render_ahead(&mut tiles, request(13.0, 6));
        drop(frames);
    }
}
