//! The picture of a sweep: success rate and mean speed per setting.

use std::path::Path;

use super::canvas::{BLACK, Canvas, RenderError, Rgba, WHITE};
use crate::sweep::SettingSummary;

const GRID: Rgba = [225, 225, 225, 255];
const GREY: Rgba = [110, 110, 110, 255];
const SUCCESS: Rgba = [60, 160, 80, 255];
const SPEED: Rgba = [50, 100, 200, 255];

/// Two bar charts over the settings, one above the other: the share of
/// worlds completed without a collision, and the mean of the runs' average
/// speeds. Under each pair of bars, the setting's value of each swept key
/// (`keys`, in the order of the legend).
pub fn sweep_picture(
    path: &Path,
    title: &str,
    keys: &[String],
    summary: &[SettingSummary],
) -> Result<(), RenderError> {
    let n = summary.len().max(1);
    let slot = (680.0 / n as f32).clamp(14.0, 170.0);
    let left = 70.0;
    // Wide enough for the title too (a shard's names its part).
    let title_width = Canvas::new(1, 1, WHITE)?.text(0.0, 0.0, 18.0, BLACK, title);
    let width = (left + slot * n as f32 + 30.0)
        .max(560.0)
        .max(left + title_width + 20.0);
    let label_lines = keys.len().max(1) as f32;
    let panel = 190.0;
    let (top1, top2) = (70.0, 70.0 + panel + 50.0);
    let labels_y = top2 + panel + 22.0;
    let legend_y = labels_y + 16.0 * label_lines + 26.0;
    let height = legend_y + 18.0 * keys.len().max(1) as f32 + 14.0;
    let mut c = Canvas::new(width.ceil() as u32, height.ceil() as u32, WHITE)?;
    c.text(left, 30.0, 18.0, BLACK, title);
    let rates: Vec<f64> = summary.iter().map(|s| s.success_rate).collect();
    let speeds: Vec<f64> = summary.iter().map(|s| s.mean_speed_mps).collect();
    let top_speed = nice_ceiling(speeds.iter().copied().fold(0.0, f64::max));
    let captions: Vec<String> = summary
        .iter()
        .map(|s| format!("{}/{}", s.successes, s.runs))
        .collect();
    bars(
        &mut c,
        Panel {
            left,
            top: top1,
            height: panel,
            slot,
        },
        "completed without collision (%)",
        &rates,
        1.0,
        |v| format!("{:.0}", v * 100.0),
        &captions,
        SUCCESS,
    );
    let captions: Vec<String> = speeds.iter().map(|v| format!("{v:.2}")).collect();
    bars(
        &mut c,
        Panel {
            left,
            top: top2,
            height: panel,
            slot,
        },
        "mean speed (m/s)",
        &speeds,
        top_speed,
        |v| format!("{v:.1}"),
        &captions,
        SPEED,
    );
    // The settings under the bars: one line per swept key.
    for (i, s) in summary.iter().enumerate() {
        let x = left + slot * (i as f32 + 0.15);
        for (line, value) in s.values.iter().enumerate() {
            let fits = ((slot - 4.0) / 6.5).max(1.0) as usize;
            let short: String = value.chars().take(fits).collect();
            c.text(x, labels_y + 16.0 * line as f32, 11.0, BLACK, &short);
        }
        if s.values.is_empty() {
            c.text(x, labels_y, 11.0, BLACK, "defaults");
        }
    }
    c.text(
        left,
        legend_y,
        12.0,
        GREY,
        "under each setting, from the top:",
    );
    for (line, key) in keys.iter().enumerate() {
        c.text(
            left + 12.0,
            legend_y + 18.0 * (line + 1) as f32,
            12.0,
            BLACK,
            key,
        );
    }
    c.save(path)
}

#[derive(Clone, Copy)]
struct Panel {
    left: f32,
    top: f32,
    height: f32,
    slot: f32,
}

/// Bars of `values` over [0, `max`] with four grid lines, each captioned.
#[allow(clippy::too_many_arguments)]
fn bars(
    c: &mut Canvas,
    p: Panel,
    title: &str,
    values: &[f64],
    max: f64,
    tick: impl Fn(f64) -> String,
    captions: &[String],
    color: Rgba,
) {
    let width = p.slot * values.len().max(1) as f32;
    c.text(p.left, p.top - 12.0, 13.0, BLACK, title);
    for k in 0..=4 {
        let v = max * f64::from(k) / 4.0;
        let y = p.top + p.height * (1.0 - k as f32 / 4.0);
        c.fill_rect(p.left, y, width, 1.0, GRID);
        let text = tick(v);
        c.text(
            p.left - 8.0 - 6.5 * text.chars().count() as f32,
            y + 4.0,
            11.0,
            GREY,
            &text,
        );
    }
    let max = max.max(f64::MIN_POSITIVE);
    for (i, (&v, caption)) in values.iter().zip(captions).enumerate() {
        let h = (p.height * (v / max).clamp(0.0, 1.0) as f32).max(1.0);
        let x = p.left + p.slot * i as f32;
        c.fill_rect(
            x + p.slot * 0.15,
            p.top + p.height - h,
            p.slot * 0.7,
            h,
            color,
        );
        if p.slot >= 30.0 {
            // Above the bar, or inside it in white where a full bar leaves no room.
            let (y, ink) = if h > p.height - 14.0 {
                (p.top + p.height - h + 12.0, WHITE)
            } else {
                (p.top + p.height - h - 4.0, BLACK)
            };
            c.text(x + p.slot * 0.15 + 2.0, y, 10.0, ink, caption);
        }
    }
    c.fill_rect(p.left, p.top + p.height, width, 1.5, BLACK);
}

/// The smallest of 1, 2, 4, 8 × 10^k at or above `v` (1 for nothing):
/// quarters of it are round numbers.
fn nice_ceiling(v: f64) -> f64 {
    if !(v > 0.0 && v.is_finite()) {
        return 1.0;
    }
    let magnitude = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 4.0, 8.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .find(|&m| m >= v)
        .unwrap_or(10.0 * magnitude)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_picture_is_wide_enough_for_its_title() {
        let dir = arcnav_testkit::scratch_dir("arcnav-sweep-picture");
        let width = |title: &str| {
            let path = dir.join("sweep.png");
            sweep_picture(&path, title, &["k".into()], &[]).unwrap();
            tiny_skia::Pixmap::load_png(&path).unwrap().width()
        };
        assert_eq!(
            width("arcnav sweep: 4 of 4 runs, 2 worlds × 2 settings"),
            560
        );
        let long = "arcnav sweep: 20 of 1000 runs (shard 13/50), 500 worlds × 2 settings";
        assert!(width(long) > 620, "{}", width(long));
    }
}
