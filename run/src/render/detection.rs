//! The picture of the detection experiment (paper 000's Fig. 5b as
//! curves): one panel per evaluator and sensor, detection probability
//! against distance, a line per object.

use std::path::Path;

use super::canvas::{BLACK, Canvas, RenderError, Rgba, WHITE};
use crate::detection::DetectionRow;

const GRID: Rgba = [225, 225, 225, 255];
const GREY: Rgba = [110, 110, 110, 255];
const UNSEEN: Rgba = [90, 90, 90, 255];
/// One colour per object, light to dark with height; the glass last.
const LINES: [Rgba; 8] = [
    [160, 200, 235, 255],
    [90, 160, 220, 255],
    [40, 110, 200, 255],
    [20, 60, 160, 255],
    [10, 20, 90, 255],
    [120, 120, 40, 255],
    [200, 120, 30, 255],
    [200, 40, 160, 255],
];

/// Panels in rows of evaluators and columns of sensors.
pub fn detection_picture(path: &Path, rows: &[DetectionRow]) -> Result<(), RenderError> {
    let mut evaluators: Vec<&str> = Vec::new();
    let mut sensors: Vec<&str> = Vec::new();
    let mut objects: Vec<&str> = Vec::new();
    for r in rows {
        for (list, v) in [
            (&mut evaluators, r.evaluator.as_str()),
            (&mut sensors, r.sensor.as_str()),
            (&mut objects, r.object.as_str()),
        ] {
            if !list.contains(&v) {
                list.push(v);
            }
        }
    }
    let max_distance = rows.iter().map(|r| r.distance_m).fold(1.0, f64::max).ceil();
    let (pw, ph) = (300.0f32, 170.0f32);
    let (left, top, gap_x, gap_y) = (60.0f32, 60.0f32, 40.0f32, 60.0f32);
    let width = (left + sensors.len().max(1) as f32 * (pw + gap_x) + 150.0).max(720.0);
    let height = top + evaluators.len().max(1) as f32 * (ph + gap_y) + 10.0;
    let mut c = Canvas::new(width.ceil() as u32, height.ceil() as u32, WHITE)?;
    c.text(
        left,
        26.0,
        17.0,
        BLACK,
        "detection probability by distance (paper 000, Fig. 5, at vehicle scale)",
    );
    for (e, evaluator) in evaluators.iter().enumerate() {
        for (s, sensor) in sensors.iter().enumerate() {
            let x0 = left + s as f32 * (pw + gap_x);
            let y0 = top + e as f32 * (ph + gap_y);
            let frames: u32 = rows
                .iter()
                .filter(|r| r.evaluator == *evaluator && r.sensor == *sensor)
                .map(|r| r.frames)
                .sum();
            let alarms: u32 = rows
                .iter()
                .filter(|r| r.evaluator == *evaluator && r.sensor == *sensor)
                .map(|r| r.false_alarms)
                .sum();
            c.text(
                x0,
                y0 - 8.0,
                13.0,
                BLACK,
                &format!(
                    "{evaluator}, {sensor} (false alarms {:.1} %)",
                    100.0 * f64::from(alarms) / f64::from(frames.max(1))
                ),
            );
            for k in 0..=4 {
                let y = y0 + ph * (1.0 - k as f32 / 4.0);
                c.fill_rect(x0, y, pw, 1.0, GRID);
                c.text(
                    x0 - 30.0,
                    y + 4.0,
                    10.0,
                    GREY,
                    &format!("{:.2}", k as f32 / 4.0),
                );
            }
            let ticks = (max_distance / 5.0).ceil() as usize;
            for k in 0..=ticks {
                let d = 5.0 * k as f64;
                let x = x0 + pw * (d / max_distance) as f32;
                if d <= max_distance {
                    c.fill_rect(x, y0, 1.0, ph, GRID);
                    c.text(x - 6.0, y0 + ph + 14.0, 10.0, GREY, &format!("{d:.0}"));
                }
            }
            c.text(x0 + pw - 60.0, y0 + ph + 28.0, 10.0, GREY, "distance, m");
            // A series: the panel's rows `keep` picks, `value` against
            // distance, in order of distance.
            let series = |keep: &dyn Fn(&DetectionRow) -> bool, value: fn(&DetectionRow) -> f64| {
                let mut points: Vec<&DetectionRow> = rows
                    .iter()
                    .filter(|r| r.evaluator == *evaluator && r.sensor == *sensor && keep(r))
                    .collect();
                points.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
                points
                    .iter()
                    .map(|r| {
                        (
                            x0 + pw * (r.distance_m / max_distance) as f32,
                            y0 + ph * (1.0 - value(r) as f32),
                        )
                    })
                    .collect::<Vec<(f32, f32)>>()
            };
            for (o, object) in objects.iter().enumerate() {
                let line = series(&|r| r.object == *object, |r| r.detection_probability);
                let colour = LINES[o % LINES.len()];
                c.polyline(&line, colour, 2.0, object.starts_with("glass"));
                for &(x, y) in &line {
                    c.fill_rect(x - 2.0, y - 2.0, 4.0, 4.0, colour);
                }
            }
            // The glass left unseen (in the image's shadows), dotted.
            let line = series(&|r| r.glass, |r| r.unseen_probability);
            c.polyline(&line, UNSEEN, 1.5, true);
            c.fill_rect(x0, y0 + ph, pw, 1.5, BLACK);
            c.fill_rect(x0, y0, 1.5, ph, BLACK);
        }
    }
    let lx = left + sensors.len().max(1) as f32 * (pw + gap_x);
    for (o, object) in objects.iter().enumerate() {
        let y = top + 10.0 + 18.0 * o as f32;
        let colour = LINES[o % LINES.len()];
        c.fill_rect(lx, y - 4.0, 18.0, 3.0, colour);
        c.text(lx + 24.0, y, 11.0, BLACK, object);
    }
    if rows.iter().any(|r| r.glass) {
        let y = top + 10.0 + 18.0 * objects.len() as f32;
        c.polyline(&[(lx, y - 3.0), (lx + 18.0, y - 3.0)], UNSEEN, 1.5, true);
        c.text(lx + 24.0, y, 11.0, BLACK, "glass left unseen");
    }
    c.save(path)
}
