//! The simulated range sensor: perception's sensor model rendering the
//! world's height field, plus range noise and dropouts. Bands of rows are
//! rendered in parallel; noise comes from a generator seeded per image and
//! per row, so an image is the same whatever the thread count.

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use arcnav_perception::{PosedBeams, RangeImage, RangeSlice, RayCast, SensorModel, SliceAxis};
use arcnav_vehicle::{Isometry, Utime};
use nalgebra::{Point3, Vector3};

use crate::polar::{Headings, PolarView};
use crate::rng::Rng;
use crate::tiles::TileView;

/// Images with at least this many rays are cast through a [`PolarView`]
/// (binning the ground costs about as much as casting this many rays).
const POLAR_MIN_RAYS: usize = 16_384;
/// Smaller images with at least this many rays, along a narrow wedge of
/// headings (a rotating lidar's slice), through a [`PolarView::wedge`]:
/// binning a 16-column wedge to 45 m took about 40 µs in a streamed
/// lidar64 mission, walking a ray in the view about 290 ns (`perf`,
/// 2026-11-28), so a wedge pays from about 140 rays.
const WEDGE_MIN_RAYS: usize = 256;

/// Bands of rows an image is cut into (at least; eight a thread with more
/// than four threads). Small, so that a thread that comes to help late
/// (the one that needs a frame rendered ahead) waits little for the last
/// band another thread took; a band of a few rows costs no more to take
/// than a large one.
const BANDS: usize = 32;

/// Renders one image of `view` from `world_from_vehicle` on `threads`
/// threads (this one and `threads - 1` more).
pub fn render(
    sensor: &SensorModel,
    view: &TileView,
    world_from_vehicle: &Isometry,
    utime: Utime,
    noise: (f64, f64),
    seed: (u64, u64),
    threads: usize,
) -> RangeImage {
    if threads <= 1 {
        // Straight into the image: a streamed lidar's slices are rendered
        // so, 128 a frame, and sharing would cost them a tenth more.
        let mut image = sensor.blank_image(utime);
        let beams = sensor.posed_beams(world_from_vehicle);
        let polar = table(sensor, view, world_from_vehicle, beams.origin(), 1);
        let rows = 0..sensor.beams.rows();
        let scene = scene(polar.as_ref(), view);
        render_rows(sensor, &beams, scene, rows, &mut image.range, noise, seed);
        return image;
    }
    let frame = SharedFrame::new(
        Arc::new(sensor.clone()),
        view,
        world_from_vehicle,
        utime,
        noise,
        seed,
        threads,
    );
    std::thread::scope(|scope| {
        for _ in 1..threads.min(frame.bands) {
            scope.spawn(|| frame.help());
        }
        frame.finish().0
    })
}

/// One image being rendered, band of rows by band, by whichever threads
/// help: those started for it ([`render`]), or a thread that started it
/// ahead of time and the one that needs it, which renders what is left
/// when it gets there rather than waiting ([`SharedFrame::finish`]).
///
/// Rows differ in cost (a lidar's upper rows reach far, its lower ones hit
/// the ground near), so helpers take small bands from a counter rather
/// than a share each. Noise comes from a generator seeded per image and
/// per row, so the image is the same whatever the threads and whichever
/// renders which band.
pub struct SharedFrame {
    sensor: Arc<SensorModel>,
    view: TileView,
    /// The ground binned around the sensor, for a frame of many rays.
    polar: Option<PolarView>,
    beams: PosedBeams,
    utime: Utime,
    /// Range noise σ (m) and dropout probability.
    noise: (f64, f64),
    seed: (u64, u64),
    rows_per_band: usize,
    bands: usize,
    /// The next band not yet taken.
    next: AtomicUsize,
    state: Mutex<Bands>,
    /// Signalled when a band is rendered or abandoned.
    changed: Condvar,
    started: Instant,
}

/// What has been rendered of a [`SharedFrame`].
struct Bands {
    ranges: Vec<Option<Vec<f32>>>,
    rendered: usize,
    /// Bands whose thread panicked while rendering them: taken again.
    abandoned: Vec<usize>,
    /// When the last band was rendered.
    last: Option<Instant>,
}

impl SharedFrame {
    /// Prepares the image `sensor` takes of `view` from
    /// `world_from_vehicle` (binning the ground on up to `threads` threads
    /// when the frame has many rays), in bands small enough for `threads`
    /// threads and a late helper to share. No band is rendered yet.
    pub fn new(
        sensor: Arc<SensorModel>,
        view: &TileView,
        world_from_vehicle: &Isometry,
        utime: Utime,
        noise: (f64, f64),
        seed: (u64, u64),
        threads: usize,
    ) -> Self {
        let started = Instant::now();
        let threads = threads.max(1);
        let rows = sensor.beams.rows();
        let rows_per_band = rows.div_ceil(BANDS.max(threads * 8)).max(1);
        let bands = rows.div_ceil(rows_per_band);
        let beams = sensor.posed_beams(world_from_vehicle);
        let polar = table(&sensor, view, world_from_vehicle, beams.origin(), threads);
        Self {
            view: view.clone(),
            polar,
            beams,
            utime,
            noise,
            seed,
            rows_per_band,
            bands,
            next: AtomicUsize::new(0),
            state: Mutex::new(Bands {
                ranges: vec![None; bands],
                rendered: 0,
                abandoned: Vec::new(),
                last: None,
            }),
            changed: Condvar::new(),
            started,
            sensor,
        }
    }

    /// Renders bands until none is left to take.
    pub fn help(&self) {
        while let Some(band) = self.take() {
            self.render_band(band);
        }
    }

    /// The image, once every band is rendered: this thread renders those
    /// not yet taken (and any whose thread panicked) and waits for those
    /// other threads are rendering. With it, the time from
    /// [`SharedFrame::new`] to the last band rendered. Call once: the
    /// bands are moved out.
    pub fn finish(&self) -> (RangeImage, Duration) {
        self.help();
        let mut state = self.lock();
        while state.rendered < self.bands {
            if let Some(band) = state.abandoned.pop() {
                drop(state);
                self.render_band(band);
                state = self.lock();
                continue;
            }
            state = self
                .changed
                .wait(state)
                .unwrap_or_else(PoisonError::into_inner);
        }
        let took = state.last.unwrap_or(self.started) - self.started;
        let mut image = self.sensor.blank_image(self.utime);
        let cols = self.sensor.beams.cols();
        for (band, ranges) in state.ranges.iter_mut().enumerate() {
            let first = band * self.rows_per_band * cols;
            if let Some(ranges) = ranges.take() {
                image.range[first..first + ranges.len()].copy_from_slice(&ranges);
            }
        }
        (image, took)
    }

    /// Leaves the bands no thread has taken unrendered: a frame no one
    /// will finish (helpers stop once their band is done; it must not be
    /// [finished](SharedFrame::finish) after this).
    pub fn cancel(&self) {
        self.next.fetch_max(self.bands, Ordering::Relaxed);
        self.lock().abandoned.clear();
    }

    fn lock(&self) -> MutexGuard<'_, Bands> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A band no thread has taken: the next from the counter, else one
    /// abandoned.
    fn take(&self) -> Option<usize> {
        let band = self.next.fetch_add(1, Ordering::Relaxed);
        if band < self.bands {
            return Some(band);
        }
        self.lock().abandoned.pop()
    }

    fn render_band(&self, band: usize) {
        // Should the casting panic, the band is handed back for another
        // thread to take, not waited for.
        let mut taken = Taken {
            frame: self,
            band: Some(band),
        };
        let (rows, cols) = (self.sensor.beams.rows(), self.sensor.beams.cols());
        let first = band * self.rows_per_band;
        let band_rows = first..(first + self.rows_per_band).min(rows);
        let mut ranges = vec![f32::NAN; band_rows.len() * cols];
        let scene = scene(self.polar.as_ref(), &self.view);
        let (sensor, noise, seed) = (&*self.sensor, self.noise, self.seed);
        render_rows(
            sensor,
            &self.beams,
            scene,
            band_rows,
            &mut ranges,
            noise,
            seed,
        );
        taken.band = None;
        let mut state = self.lock();
        state.ranges[band] = Some(ranges);
        state.rendered += 1;
        state.last = Some(Instant::now());
        drop(state);
        self.changed.notify_all();
    }
}

/// What an image's rays are cast in: the ground binned around the sensor
/// when there is a table, else the view itself.
fn scene<'a>(polar: Option<&'a PolarView>, view: &'a TileView) -> &'a dyn RayCast {
    match polar {
        Some(polar) => polar,
        None => view,
    }
}

/// Renders `rows` of `sensor`'s image into `out` (theirs only), with range
/// noise σ and dropouts `noise`: row `r` draws from stream `r` of the
/// image's `seed`, so a row is the same whichever thread renders it.
fn render_rows(
    sensor: &SensorModel,
    beams: &PosedBeams,
    scene: &dyn RayCast,
    rows: Range<usize>,
    out: &mut [f32],
    (sigma, dropout): (f64, f64),
    seed: (u64, u64),
) {
    let first = rows.start;
    sensor.render_rows_posed(beams, &scene, rows, out);
    for (r, row) in out.chunks_mut(sensor.beams.cols()).enumerate() {
        let mut rng = Rng::stream(
            seed.0,
            seed.1.wrapping_mul(65_536).wrapping_add((first + r) as u64),
        );
        for value in row {
            if dropout > 0.0 && rng.unit() < dropout {
                *value = f32::NAN;
            } else if value.is_finite() && sigma > 0.0 {
                *value = (f64::from(*value) + sigma * rng.ziggurat_normal()).max(0.01) as f32;
            }
        }
    }
}

/// A band being rendered; handed back if its thread unwinds.
struct Taken<'a> {
    frame: &'a SharedFrame,
    band: Option<usize>,
}

impl Drop for Taken<'_> {
    fn drop(&mut self) {
        if let Some(band) = self.band {
            self.frame.lock().abandoned.push(band);
            self.frame.changed.notify_all();
        }
    }
}

/// The binned ground an image of `sensor` is cast through, if any: for a
/// frame of many rays the whole turn, or the headings of one spanning
/// less than half a turn (binned from the tiles they meet); the wedge its
/// rays run along for a smaller one. Headings are found from the rays at
/// its extreme elevations and azimuths (along a row, and along a column, a
/// ray's heading turns one way); a ray outside them is cast in the view.
fn table(
    sensor: &SensorModel,
    view: &TileView,
    world_from_vehicle: &Isometry,
    origin: Point3<f64>,
    threads: usize,
) -> Option<PolarView> {
    let rays = sensor.beams.rows() * sensor.beams.cols();
    if rays < WEDGE_MIN_RAYS {
        return None;
    }
    let extremes = |angles: &[f32]| {
        let (lo, hi) = angles
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &a| {
                (lo.min(a), hi.max(a))
            });
        [f64::from(lo), f64::from(hi)]
    };
    let rotation = (world_from_vehicle * sensor.vehicle_from_sensor).rotation;
    let azimuths = extremes(&sensor.beams.azimuth);
    let corners = extremes(&sensor.beams.elevation)
        .into_iter()
        .flat_map(|el| {
            azimuths.map(|az| {
                rotation * Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
            })
        });
    if rays >= POLAR_MIN_RAYS {
        // A sensor looking one way (the ERIM's 128°) bins the tiles its
        // headings meet; a rotating lidar, the whole turn.
        let headings = if azimuths[1] - azimuths[0] < std::f64::consts::PI {
            Headings::frame_around(corners).unwrap_or(Headings::ALL)
        } else {
            Headings::ALL
        };
        return Some(PolarView::within(
            view,
            origin,
            sensor.max_range_m,
            threads,
            headings,
        ));
    }
    let headings = Headings::around(corners)?;
    Some(PolarView::wedge(view, origin, sensor.max_range_m, headings))
}

/// A sensor that sends each image in slices as it acquires it (002 §7's
/// integrated mode): blocks of columns for a sensor whose columns span
/// 180° or more (a rotating lidar), else blocks of rows, highest beam
/// first (a scanning sensor like the ERIM). Line `i` of `n` of a frame
/// starting at `t` is acquired at `t + period·(i + 1)/n`; each slice is
/// rendered with the vehicle where it was at the slice's middle line.
#[derive(Debug, Clone)]
pub struct Slicer {
    axis: SliceAxis,
    /// Each slice's sensor (its rows or columns only) and its first line.
    parts: Vec<(SensorModel, usize)>,
    lines: usize,
    frame_rows: usize,
    frame_cols: usize,
    period_us: Utime,
}

impl Slicer {
    /// `lines` lines per slice (at least 1).
    pub fn new(sensor: &SensorModel, lines: usize) -> Self {
        let (rows, cols) = (sensor.beams.rows(), sensor.beams.cols());
        let az = &sensor.beams.azimuth;
        let span = match (az.first(), az.last()) {
            (Some(a), Some(b)) => f64::from((a - b).abs()) * cols as f64 / (cols.max(2) - 1) as f64,
            _ => 0.0,
        };
        let axis = if span >= std::f64::consts::PI {
            SliceAxis::Columns
        } else {
            SliceAxis::Rows
        };
        let total = match axis {
            SliceAxis::Columns => cols,
            SliceAxis::Rows => rows,
        };
        let lines = lines.clamp(1, total.max(1));
        let parts = (0..total)
            .step_by(lines)
            .map(|first| {
                let end = (first + lines).min(total);
                let mut part = sensor.clone();
                match axis {
                    SliceAxis::Columns => part.beams.azimuth = az[first..end].to_vec(),
                    SliceAxis::Rows => {
                        part.beams.elevation = sensor.beams.elevation[first..end].to_vec();
                    }
                }
                (part, first)
            })
            .collect();
        Self {
            axis,
            parts,
            lines: total,
            frame_rows: rows,
            frame_cols: cols,
            period_us: sensor.period_us(),
        }
    }

    pub fn axis(&self) -> SliceAxis {
        self.axis
    }

    /// Slices per frame.
    pub fn len(&self) -> usize {
        self.parts.len()
    }

    pub fn is_empty(&self) -> bool {
        self.parts.is_empty()
    }

    /// When line `line` of the frame starting at `frame` was acquired.
    pub fn line_utime(&self, frame: Utime, line: usize) -> Utime {
        frame + self.period_us * (line as Utime + 1) / self.lines.max(1) as Utime
    }

    /// When slice `k` of the frame starting at `frame` is complete, and
    /// when its middle line was acquired (the pose it is rendered at).
    pub fn times(&self, frame: Utime, k: usize) -> (Utime, Utime) {
        let (part, first) = &self.parts[k.min(self.parts.len() - 1)];
        let n = match self.axis {
            SliceAxis::Columns => part.beams.cols(),
            SliceAxis::Rows => part.beams.rows(),
        };
        (
            self.line_utime(frame, first + n - 1),
            self.line_utime(frame, first + n / 2),
        )
    }

    /// Renders slice `k` of the frame starting at `frame`, the vehicle at
    /// `world_from_vehicle`.
    pub fn render(
        &self,
        k: usize,
        frame: Utime,
        view: &TileView,
        world_from_vehicle: &Isometry,
        noise: (f64, f64),
        seed: (u64, u64),
    ) -> RangeSlice {
        let (part, first) = &self.parts[k.min(self.parts.len() - 1)];
        let image = render(part, view, world_from_vehicle, frame, noise, seed, 1);
        let n = match self.axis {
            SliceAxis::Columns => part.beams.cols(),
            SliceAxis::Rows => part.beams.rows(),
        };
        let line_utimes: Vec<Utime> = (*first..first + n)
            .map(|line| self.line_utime(frame, line))
            .collect();
        RangeSlice {
            utime: *line_utimes.last().unwrap_or(&frame),
            frame_utime: frame,
            sensor: image.sensor,
            vehicle_from_sensor: image.vehicle_from_sensor,
            frame_rows: self.frame_rows,
            frame_cols: self.frame_cols,
            axis: self.axis,
            first: *first,
            beams: image.beams,
            line_utimes,
            range: image.range,
        }
    }

    /// Renders the slices `requests` ask for, side by side on up to
    /// `threads` threads: each as [`Slicer::render`] makes it, in the
    /// requests' order.
    pub fn render_all(
        &self,
        requests: &[SliceRequest<'_>],
        noise: (f64, f64),
        seed: u64,
        threads: usize,
    ) -> Vec<RangeSlice> {
        let one = |r: &SliceRequest<'_>| {
            self.render(
                r.k,
                r.frame,
                r.view,
                &r.world_from_vehicle,
                noise,
                (seed, r.stream),
            )
        };
        let threads = threads.clamp(1, requests.len().max(1));
        if threads == 1 {
            return requests.iter().map(one).collect();
        }
        // Slices differ in cost (the ground ahead, the sky), so threads
        // take them one at a time.
        let next = AtomicUsize::new(0);
        let work = || {
            let mut done = Vec::new();
            loop {
                let index = next.fetch_add(1, Ordering::Relaxed);
                let Some(request) = requests.get(index) else {
                    return done;
                };
                done.push((index, one(request)));
            }
        };
        let mut slots: Vec<Option<RangeSlice>> = requests.iter().map(|_| None).collect();
        std::thread::scope(|scope| {
            let others: Vec<_> = (1..threads).map(|_| scope.spawn(work)).collect();
            let mine = work();
            // A thread that panicked left its slices empty.
            let theirs = others
                .into_iter()
                .flat_map(|o| o.join().unwrap_or_default());
            for (index, slice) in mine.into_iter().chain(theirs) {
                slots[index] = Some(slice);
            }
        });
        // The slices of a thread that panicked are rendered here.
        slots
            .into_iter()
            .zip(requests)
            .map(|(slice, request)| slice.unwrap_or_else(|| one(request)))
            .collect()
    }
}

/// One slice for [`Slicer::render_all`]: slice `k` of the frame starting at
/// `frame`, cast in `view` from the vehicle at `world_from_vehicle`, with
/// noise stream `stream`.
#[derive(Debug, Clone)]
pub struct SliceRequest<'a> {
    pub k: usize,
    pub frame: Utime,
    pub view: &'a TileView,
    pub world_from_vehicle: Isometry,
    pub stream: u64,
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arcnav_vehicle::frames::isometry_from_xyz_rpy;
    use nalgebra::Point3;

    use super::*;
    use crate::World;
    use crate::tiles::TileCache;

    #[test]
    fn an_image_is_the_same_whatever_the_thread_count() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 64, 2);
        let sensor = SensorModel::erim();
        let pose = isometry_from_xyz_rpy([0.0, 0.0, world.height(0.0, 0.0)], 0.05, -0.1, 0.3);
        let view = tiles.view(0.0, 0.0, sensor.max_range_m + 3.0);
        let image = |threads| render(&sensor, &view, &pose, 7, (0.02, 0.01), (3, 9), threads);
        let one = image(1);
        let returns = one.range.iter().filter(|r| r.is_finite()).count();
        assert!(returns > one.range.len() / 2, "{returns} returns");
        for threads in [2, 3, 64] {
            let other = image(threads);
            // NaN ≠ NaN: compare the bits.
            let bits = |i: &RangeImage| i.range.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&one), bits(&other), "{threads} threads");
        }
    }

    /// A frame started on one thread and finished on another (which takes
    /// what is left, and waits for what the first is rendering) is the
    /// frame rendered at once; a band whose thread gave up on it (it
    /// panicked) is rendered by the thread that finishes.
    #[test]
    fn a_shared_frame_is_the_frame_whoever_renders_its_bands() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 64, 2);
        let sensor = Arc::new(SensorModel::lidar64());
        let pose = isometry_from_xyz_rpy([5.0, 2.0, world.height(5.0, 2.0)], 0.04, -0.02, 0.7);
        let view = tiles.view(5.0, 2.0, sensor.max_range_m + 1.0);
        let (noise, seed) = ((0.02, 0.01), (4, 11));
        let bits = |i: &RangeImage| i.range.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        let at_once = render(&sensor, &view, &pose, 9, noise, seed, 1);
        let shared = || SharedFrame::new(Arc::clone(&sensor), &view, &pose, 9, noise, seed, 1);
        // Another thread helps from the start; this one finishes.
        let frame = shared();
        let (image, _) = std::thread::scope(|scope| {
            scope.spawn(|| frame.help());
            frame.finish()
        });
        assert_eq!(bits(&image), bits(&at_once));
        // A band taken and given up, and one taken by no one yet.
        let frame = shared();
        let taken = frame.take().expect("a band");
        drop(Taken {
            frame: &frame,
            band: Some(taken),
        });
        assert_eq!(frame.lock().abandoned, [taken]);
        let (image, took) = frame.finish();
        assert_eq!(bits(&image), bits(&at_once));
        assert!(took > Duration::ZERO);
        // A frame thrown away: a band taken before renders, the rest not.
        let frame = shared();
        let taken = frame.take().expect("a band");
        frame.cancel();
        frame.help();
        frame.render_band(taken);
        assert_eq!(frame.lock().rendered, 1);
        let returns = image.range.iter().filter(|r| r.is_finite()).count();
        assert!(returns > image.range.len() / 2, "{returns} returns");
    }

    /// Slices rendered side by side are those rendered one by one, in the
    /// order asked for, whatever the thread count.
    #[test]
    fn slices_rendered_side_by_side_are_the_slices_rendered_in_turn() {
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 64, 2);
        let slicer = Slicer::new(&SensorModel::lidar64(), 16);
        let poses: Vec<Isometry> = (0..25)
            .map(|n| {
                let x = 0.4 * f64::from(n);
                isometry_from_xyz_rpy([x, 1.0, world.height(x, 1.0)], 0.02, -0.03, 0.1)
            })
            .collect();
        let views: Vec<TileView> = poses
            .iter()
            .map(|pose| tiles.view(pose.translation.x, pose.translation.y, 60.0))
            .collect();
        // A frame's last slices and the next frame's first, as one step
        // hands them over.
        let requests: Vec<SliceRequest<'_>> = (0..25)
            .map(|n| {
                let (k, frame) = ((120 + n) % 128, if n < 8 { 1_000 } else { 101_000 });
                SliceRequest {
                    k,
                    frame,
                    view: &views[n],
                    world_from_vehicle: poses[n],
                    stream: (n as u64) * 65_536 + k as u64,
                }
            })
            .collect();
        let noise = (0.02, 0.01);
        let in_turn = slicer.render_all(&requests, noise, 5, 1);
        assert_eq!(in_turn.len(), 25);
        for (r, slice) in requests.iter().zip(&in_turn) {
            assert_eq!((slice.first, slice.frame_utime), (r.k * 16, r.frame));
        }
        let bits = |s: &RangeSlice| s.range.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        let returns: usize = in_turn
            .iter()
            .map(|s| s.range.iter().filter(|r| r.is_finite()).count())
            .sum();
        assert!(returns > 25 * 64 * 16 / 4, "{returns} returns");
        for threads in [2, 3, 64] {
            let side_by_side = slicer.render_all(&requests, noise, 5, threads);
            assert_eq!(side_by_side.len(), in_turn.len());
            for (n, (a, b)) in in_turn.iter().zip(&side_by_side).enumerate() {
                assert_eq!(bits(a), bits(b), "slice {n}, {threads} threads");
                assert_eq!(a.line_utimes, b.line_utimes);
            }
        }
    }

    /// Vehicle poses on `paper_loop` (x, y, roll, pitch, yaw), level and
    /// tilted, from its start to its far side.
    const POSES: [(f64, f64, f64, f64, f64); 3] = [
        (0.0, 0.0, 0.0, 0.0, 0.3),
        (60.0, 35.0, 0.2, -0.1, 2.0),
        (-52.0, 162.0, -0.05, 0.15, -1.2),
    ];

    /// How many of `sensor`'s ranges from `pose` differ (bit for bit)
    /// between `binned` and the `view` itself, and how many returned.
    fn differences(
        sensor: &SensorModel,
        pose: &Isometry,
        binned: &PolarView,
        view: &TileView,
    ) -> (usize, usize) {
        let cells = sensor.beams.rows() * sensor.beams.cols();
        let (mut through, mut walked) = (vec![0f32; cells], vec![0f32; cells]);
        sensor.render_rows(pose, binned, 0..sensor.beams.rows(), &mut through);
        sensor.render_rows(pose, view, 0..sensor.beams.rows(), &mut walked);
        let differ = through
            .iter()
            .zip(&walked)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        (differ, walked.iter().filter(|r| r.is_finite()).count())
    }

    #[test]
    fn a_frame_cast_through_the_binned_ground_is_the_frame_cast_in_the_view() {
        // Bit for bit: the table only says where a ray meets nothing.
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 128, 2);
        let sensor = SensorModel::lidar64();
        let cells = sensor.beams.rows() * sensor.beams.cols();
        for (x, y, roll, pitch, yaw) in POSES {
            let pose = isometry_from_xyz_rpy([x, y, world.height(x, y)], roll, pitch, yaw);
            let p = (pose * sensor.vehicle_from_sensor).translation.vector;
            let view = tiles.view(p.x, p.y, sensor.max_range_m + 1.0);
            let polar = PolarView::new(&view, Point3::from(p), sensor.max_range_m, 2);
            let (differ, returns) = differences(&sensor, &pose, &polar, &view);
            assert!(returns > cells / 2, "{returns} returns");
            assert_eq!(differ, 0, "at ({x}, {y})");
        }
    }

    #[test]
    fn slices_cast_through_their_wedge_are_the_slices_cast_in_the_view() {
        // A streamed lidar frame (16 columns a slice) all round, level and
        // tilted: bit for bit, and every slice through a wedge of the table.
        let world = Arc::new(World::embedded("paper_loop").unwrap().unwrap());
        let mut tiles = TileCache::new(Arc::clone(&world), 128, 2);
        for sensor in [SensorModel::lidar64(), SensorModel::lidar128()] {
            let slicer = Slicer::new(&sensor, 16);
            for (x, y, roll, pitch, yaw) in POSES {
                let pose = isometry_from_xyz_rpy([x, y, world.height(x, y)], roll, pitch, yaw);
                let p = (pose * sensor.vehicle_from_sensor).translation.vector;
                let view = tiles.view(p.x, p.y, sensor.max_range_m + 1.0);
                let (mut differ, mut returns, mut rays) = (0, 0, 0);
                for (part, _) in &slicer.parts {
                    let origin = Point3::from(p);
                    let wedge = table(part, &view, &pose, origin, 1)
                        .expect("a lidar slice is cast through a wedge");
                    let (these, returned) = differences(part, &pose, &wedge, &view);
                    differ += these;
                    returns += returned;
                    rays += part.beams.rows() * part.beams.cols();
                }
                assert!(returns > rays / 3, "{returns} returns of {rays}");
                assert_eq!(differ, 0, "{} at ({x}, {y})", sensor.id);
            }
        }
        // A slice of the ERIM's rows spans 128° of headings: cast in the view.
        let erim = SensorModel::erim();
        let rows = &Slicer::new(&erim, 16).parts[0].0;
        let view = tiles.view(0.0, 0.0, erim.max_range_m + 1.0);
        let origin = Point3::new(0.0, 0.0, 2.0);
        assert!(table(rows, &view, &Isometry::identity(), origin, 1).is_none());
    }
}
