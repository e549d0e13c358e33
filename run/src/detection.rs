//! The detection experiment of paper 000 (§6, Fig. 5), redone at this
//! vehicle's scale for every evaluator and sensor preset.
//!
//! 000 placed stones of 1.5 to 7.5 cm and a glass at 1 to 3.5 m from its
//! robot on flat ground, recorded 120 frames of each, and counted the
//! frames showing an obstacle near the object. Here the vehicle stands on
//! flat ground; a block of each height (default 5, 10, 15, 20, 30 cm, 40 cm
//! square) or a "glass" block that returns nothing (40 cm square, 60 cm
//! tall: rays that meet it are lost, and it hides the ground behind it)
//! stands straight ahead at each distance (default 4 to 30 m). Each
//! setting's image is rendered once without noise; each of its frames adds
//! the simulator's range noise and dropouts from its own seed and is
//! evaluated on its own.
//!
//! A frame **detects** the object when the evaluator reports an
//! untraversable cell whose centre lies within `margin_m` (0.3 m) of the
//! object's footprint. A frame has a **false alarm** when it reports one
//! farther than 1 m from the footprint (on flat ground, none is right).
//! Apart from both, a frame **leaves the object unseen** when the centre
//! of its footprint lies in the image's shadows: arcnav keeps ground no
//! image saw apart from free ground (obstacle avoidance slows to stop
//! short of it), which is how a glass that returns nothing shows, where
//! 000 treats every unfilled gap as an obstacle.
//! The figures give, per evaluator, sensor, object and distance, the share
//! of frames that detect and the share with a false alarm.

use std::sync::atomic::{AtomicUsize, Ordering};

use arcnav_perception::{
    ObstacleReport, PerceptionConfig, RangeImage, RayCast, SensorPreset, ShadowIndex,
};
use arcnav_sim::rng::Rng;
use arcnav_vehicle::Isometry;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

/// What the experiment covers.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectionOptions {
    pub evaluators: Vec<String>,
    pub sensors: Vec<SensorPreset>,
    /// Heights of the solid blocks, m.
    pub heights_m: Vec<f64>,
    /// Also a block that returns nothing.
    pub glass: bool,
    /// Distances of the block's near face from the vehicle origin, m.
    pub distances_m: Vec<f64>,
    pub frames: u32,
    /// Side of the blocks' square footprint, m.
    pub width_m: f64,
    /// A reported cell this close to the footprint detects the object, m.
    pub margin_m: f64,
    /// Range noise (σ, m) and dropout probability of each frame.
    pub noise_m: f64,
    pub dropout: f64,
    pub seed: u64,
}

impl Default for DetectionOptions {
    fn default() -> Self {
        Self {
            evaluators: vec!["cells".into(), "height_diff".into(), "pca".into()],
            sensors: vec![SensorPreset::Erim],
            heights_m: vec![0.05, 0.1, 0.15, 0.2, 0.3],
            glass: true,
            distances_m: vec![4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 25.0, 30.0],
            frames: 120,
            width_m: 0.4,
            margin_m: 0.3,
            noise_m: 0.02,
            dropout: 0.01,
            seed: 0,
        }
    }
}

/// One object.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Object {
    /// Height, m.
    pub height_m: f64,
    /// Returns nothing (and hides what is behind it).
    pub glass: bool,
}

/// A glass block is this tall, m.
const GLASS_HEIGHT_M: f64 = 0.6;

impl Object {
    pub fn name(&self) -> String {
        if self.glass {
            format!("glass {:.0} cm", self.height_m * 100.0)
        } else {
            format!("block {:.0} cm", self.height_m * 100.0)
        }
    }
}

/// One row of the result: an evaluator, a sensor, an object, a distance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DetectionRow {
    pub evaluator: String,
    pub sensor: String,
    pub object: String,
    pub height_m: f64,
    pub glass: bool,
    pub distance_m: f64,
    pub frames: u32,
    /// Frames with an untraversable cell on or near the object.
    pub detected: u32,
    pub detection_probability: f64,
    /// Frames whose observed footprint leaves the block's centre unseen
    /// (in a shadow): ground obstacle avoidance never takes for free.
    pub unseen: u32,
    pub unseen_probability: f64,
    /// Frames with an untraversable cell away from it.
    pub false_alarms: u32,
    pub false_alarm_rate: f64,
}

/// Flat ground at z = 0 with one block straight ahead.
struct Scene {
    /// Footprint, vehicle frame: x from `x0` to `x0 + width`, |y| ≤ width/2.
    x0: f64,
    width: f64,
    object: Object,
}

impl Scene {
    /// Where a ray enters the block, by the slab method.
    fn block_entry(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
        let h = self.width / 2.0;
        let lo = [self.x0, -h, 0.0];
        let hi = [self.x0 + self.width, h, self.object.height_m];
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            if d[axis].abs() < 1e-12 {
                if o[axis] < lo[axis] || o[axis] > hi[axis] {
                    return None;
                }
                continue;
            }
            let (a, b) = (
                (lo[axis] - o[axis]) / d[axis],
                (hi[axis] - o[axis]) / d[axis],
            );
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        (near <= far).then_some(near)
    }
}

impl RayCast for Scene {
    fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>, max_range: f64) -> Option<f64> {
        let ground = (d.z < 0.0).then(|| -o.z / d.z).filter(|&t| t <= max_range);
        match self.block_entry(o, d).filter(|&t| t <= max_range) {
            Some(t) if ground.is_none_or(|g| t <= g) => (!self.object.glass).then_some(t),
            _ => ground,
        }
    }
}

/// Adds frame `frame`'s noise and dropouts to `clean`, into `out`.
fn noisy_frame(clean: &RangeImage, options: &DetectionOptions, frame: u64, out: &mut RangeImage) {
    out.clone_from(clean);
    let cols = clean.cols().max(1);
    for (row, ranges) in out.range.chunks_mut(cols).enumerate() {
        let mut rng = Rng::stream(options.seed, frame.wrapping_mul(65_536) + row as u64);
        for r in ranges {
            if options.dropout > 0.0 && rng.unit() < options.dropout {
                *r = f32::NAN;
            } else if r.is_finite() && options.noise_m > 0.0 {
                *r = (f64::from(*r) + options.noise_m * rng.normal()).max(0.01) as f32;
            }
        }
    }
}

/// How far (x, y) lies outside the footprint, m (0 inside).
fn outside(scene: &Scene, x: f64, y: f64) -> f64 {
    let dx = (scene.x0 - x).max(x - scene.x0 - scene.width).max(0.0);
    let dy = (y.abs() - scene.width / 2.0).max(0.0);
    dx.hypot(dy)
}

/// An experiment that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum DetectionError {
    #[error("perception configuration: {0}")]
    Config(#[from] arcnav_vehicle::ConfigError),
    #[error("evaluating a frame: {0}")]
    Perception(#[from] arcnav_perception::PerceptionError),
}

/// Runs the experiment with `perception` (its evaluator replaced by each
/// of `options.evaluators`), on every core; `progress(done, total)` after
/// each setting. Rows come in the order evaluator, sensor, object,
/// distance.
pub fn run(
    perception: &PerceptionConfig,
    options: &DetectionOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<DetectionRow>, DetectionError> {
    let mut objects: Vec<Object> = options
        .heights_m
        .iter()
        .map(|&height_m| Object {
            height_m,
            glass: false,
        })
        .collect();
    if options.glass {
        objects.push(Object {
            height_m: GLASS_HEIGHT_M,
            glass: true,
        });
    }
    let mut cases = Vec::new();
    for evaluator in &options.evaluators {
        let mut config = perception.clone();
        config.evaluator.clone_from(evaluator);
        // Checked and built once up front, so a bad name fails at once.
        config.build_evaluator()?;
        for &sensor in &options.sensors {
            for &object in &objects {
                for &distance in &options.distances_m {
                    cases.push((config.clone(), sensor, object, distance));
                }
            }
        }
    }
    let done = AtomicUsize::new(0);
    let total = cases.len();
    cases
        .par_iter()
        .map(|(config, preset, object, distance)| {
            let sensor = arcnav_perception::SensorConfig {
                preset: *preset,
                ..Default::default()
            }
            .model()?;
            let scene = Scene {
                x0: *distance,
                width: options.width_m,
                object: *object,
            };
            let clean = sensor.render(0, &Isometry::identity(), &scene);
            let mut evaluator = config.build_evaluator()?;
            let (mut frame, mut report) = (clean.clone(), ObstacleReport::default());
            let mut shadows = ShadowIndex::default();
            let (mut detected, mut unseen, mut false_alarms) = (0, 0, 0);
            let centre = (distance + options.width_m / 2.0, 0.0);
            for k in 0..options.frames {
                noisy_frame(&clean, options, u64::from(k), &mut frame);
                evaluator.evaluate(&frame, &Isometry::identity(), &mut report)?;
                // Obstacles only: graded ground is driven over.
                let distances = report
                    .cells
                    .iter()
                    .filter(|c| c.is_obstacle())
                    .map(|c| outside(&scene, c.x, c.y));
                let (mut near, mut away) = (false, false);
                for d in distances {
                    near |= d <= options.margin_m;
                    away |= d > 1.0;
                }
                detected += u32::from(near);
                false_alarms += u32::from(away);
                shadows.build(&report.shadows);
                unseen += u32::from(shadows.contains(centre.0, centre.1));
            }
            let n = options.frames.max(1);
            let row = DetectionRow {
                evaluator: config.evaluator.clone(),
                sensor: sensor.id.clone(),
                object: object.name(),
                height_m: object.height_m,
                glass: object.glass,
                distance_m: *distance,
                frames: options.frames,
                detected,
                detection_probability: f64::from(detected) / f64::from(n),
                unseen,
                unseen_probability: f64::from(unseen) / f64::from(n),
                false_alarms,
                false_alarm_rate: f64::from(false_alarms) / f64::from(n),
            };
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
            Ok(row)
        })
        .collect()
}

/// The rows as text: per evaluator and sensor, a table of detection
/// probability with the objects down and the distances across, and the
/// false-alarm rate over all of its frames.
pub fn table(rows: &[DetectionRow]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let mut groups: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        if !groups.contains(&(&r.evaluator, &r.sensor)) {
            groups.push((&r.evaluator, &r.sensor));
        }
    }
    for (evaluator, sensor) in groups {
        let group: Vec<&DetectionRow> = rows
            .iter()
            .filter(|r| r.evaluator == evaluator && r.sensor == sensor)
            .collect();
        let mut distances: Vec<f64> = Vec::new();
        let mut objects: Vec<&str> = Vec::new();
        for r in &group {
            if !distances.contains(&r.distance_m) {
                distances.push(r.distance_m);
            }
            if !objects.contains(&r.object.as_str()) {
                objects.push(&r.object);
            }
        }
        let frames: u32 = group.iter().map(|r| r.frames).sum();
        let alarms: u32 = group.iter().map(|r| r.false_alarms).sum();
        let _ = writeln!(
            out,
            "evaluator {evaluator}, sensor {sensor}: detection probability by distance (m); \
             false alarms in {alarms} of {frames} frames ({:.1} %)",
            100.0 * f64::from(alarms) / f64::from(frames.max(1))
        );
        let _ = write!(out, "{:<14}", "object");
        for d in &distances {
            let _ = write!(out, "{d:>6}");
        }
        out.push('\n');
        for object in objects {
            let _ = write!(out, "{object:<14}");
            for d in &distances {
                match group
                    .iter()
                    .find(|r| r.object == object && r.distance_m == *d)
                {
                    Some(r) => {
                        let _ = write!(out, "{:>6.2}", r.detection_probability);
                    }
                    None => out.push_str("      "),
                }
            }
            out.push('\n');
        }
        let glass: Vec<&&DetectionRow> = group.iter().filter(|r| r.glass).collect();
        if !glass.is_empty() {
            let _ = write!(out, "{:<14}", "(glass unseen)");
            for d in &distances {
                match glass.iter().find(|r| r.distance_m == *d) {
                    Some(r) => {
                        let _ = write!(out, "{:>6.2}", r.unseen_probability);
                    }
                    None => out.push_str("      "),
                }
            }
            out.push('\n');
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    pub(super) use arcnav_perception::SensorModel;

    fn options() -> DetectionOptions {
        DetectionOptions {
            evaluators: vec!["cells".into(), "height_diff".into()],
            heights_m: vec![0.05, 0.4],
            distances_m: vec![8.0, 39.0],
            frames: 6,
            ..Default::default()
        }
    }

    #[test]
    fn a_tall_block_near_by_is_detected_a_low_one_and_one_out_of_reach_are_not() {
        let rows = run(&PerceptionConfig::default(), &options(), &|_, _| {}).unwrap();
        assert_eq!(rows.len(), 2 * 3 * 2);
        for r in &rows {
            let near = r.distance_m < 30.0;
            // Beyond the ERIM's reach and the evaluated region nothing
            // shows; a glass is never an obstacle cell but its ground is
            // left unseen; a 5 cm block is driven over.
            let (detected, unseen) = match (r.glass, r.height_m) {
                (true, _) => (0.0, f64::from(u8::from(near))),
                (false, h) if h < 0.1 => (0.0, 0.0),
                _ => (f64::from(u8::from(near)), 0.0),
            };
            let what = format!(
                "{} {} {} at {} m",
                r.evaluator, r.sensor, r.object, r.distance_m
            );
            assert_eq!(r.detection_probability, detected, "{what}");
            assert_eq!(r.unseen_probability, unseen, "{what}");
            assert_eq!(r.false_alarms, 0, "{r:?}");
        }
        let text = table(&rows);
        assert!(
            text.contains("evaluator height_diff, sensor erim"),
            "{text}"
        );
        assert!(text.contains("glass 60 cm"), "{text}");
    }

    #[test]
    fn glass_returns_nothing_and_hides_the_ground_behind_it() {
        let sensor = SensorModel::erim();
        let glass = Scene {
            x0: 8.0,
            width: 0.4,
            object: Object {
                height_m: GLASS_HEIGHT_M,
                glass: true,
            },
        };
        let solid = Scene {
            object: Object {
                glass: false,
                ..glass.object
            },
            ..glass
        };
        let flat = Scene {
            object: Object {
                height_m: 0.0,
                glass: false,
            },
            ..solid
        };
        let count = |scene: &Scene| {
            sensor
                .render(0, &Isometry::identity(), scene)
                .range
                .iter()
                .filter(|r| r.is_finite())
                .count()
        };
        let (g, s, f) = (count(&glass), count(&solid), count(&flat));
        assert!(g < f && s == f, "glass {g}, solid {s}, flat {f}");
    }
}
