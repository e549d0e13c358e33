//! Pictures: the whole mission on its terrain (like the paper's Figure 3b)
//! and local-map snapshots with the arcs coloured by their fused vote and
//! each behaviour's votes (like Figures 6 and 9).

use std::path::Path;

use arcnav_arbiter::Decision;
use arcnav_behaviours::Overlay;
use arcnav_localmap::MapSnapshot;
use arcnav_perception::{Reasons, suspected_drop_off};
use arcnav_sim::{FeatureKind, World};
use arcnav_vehicle::{ArcSet, Utime};

use crate::mission::report::MissionRun;
use arcnav_config::Resolved;

mod canvas;
pub mod detection;
mod sweep;

pub use canvas::{BLACK, BLUE, Canvas, RED, RenderError, Rgba, WHITE, speed_color, vote_color};
pub use sweep::sweep_picture;

/// Colours of the behaviours' overlays: cells, lines and points each take
/// the next of their own list.
const OVERLAY_CELLS: [Rgba; 3] = [[0, 150, 150, 120], [150, 90, 30, 110], [120, 60, 160, 110]];
const OVERLAY_LINES: [Rgba; 3] = [[0, 140, 50, 230], [200, 120, 0, 230], [150, 0, 150, 230]];
const OVERLAY_POINTS: [Rgba; 3] = [[220, 0, 140, 255], [0, 100, 220, 255], [120, 120, 0, 255]];

/// A snapshot's map panel: its size, pixels per metre and the vehicle
/// frame to pixels. The arcs and the behaviours' overlays are drawn where
/// they fall on it.
struct MapPanel<'a, F: Fn(f32, f32) -> (f32, f32)> {
    size: (f32, f32),
    ppm: f32,
    to_px: &'a F,
}

impl<F: Fn(f32, f32) -> (f32, f32)> MapPanel<'_, F> {
    fn px(&self, [x, y]: [f64; 2]) -> (f32, f32) {
        (self.to_px)(x as f32, y as f32)
    }

    fn on(&self, (u, v): (f32, f32)) -> bool {
        (0.0..=self.size.0).contains(&u) && (0.0..=self.size.1).contains(&v)
    }

    /// The overlays' cells (under the arcs), what falls on the panel.
    /// Returns the legend: each label with its colour.
    fn cells(&self, canvas: &mut Canvas, overlays: &[(String, Overlay)]) -> Vec<(String, Rgba)> {
        let mut legend = Vec::new();
        let cells = overlays.iter().flat_map(|(_, o)| &o.cells);
        for (kind, colour) in cells.zip(OVERLAY_CELLS.iter().cycle()) {
            let (sin, cos) = kind.yaw.sin_cos();
            let h = kind.size_m / 2.0;
            let corners = [(h, h), (h, -h), (-h, -h), (-h, h)];
            let mut drawn = 0;
            for &[cx, cy] in &kind.centres {
                if !self.on(self.px([cx, cy])) {
                    continue;
                }
                let square: Vec<(f32, f32)> = corners
                    .iter()
                    .map(|&(a, b)| self.px([cx + cos * a - sin * b, cy + sin * a + cos * b]))
                    .collect();
                canvas.polygon(&square, Some(*colour), None);
                drawn += 1;
            }
            legend.push((format!("{} ({drawn} on the map)", kind.label), *colour));
        }
        legend
    }

    /// The overlays' lines and points (over the arcs), what falls on the
    /// panel. Returns the legend.
    fn marks(&self, canvas: &mut Canvas, overlays: &[(String, Overlay)]) -> Vec<(String, Rgba)> {
        let mut legend = Vec::new();
        let lines = overlays.iter().flat_map(|(_, o)| &o.lines);
        for (line, colour) in lines.zip(OVERLAY_LINES.iter().cycle()) {
            // Each stretch on the panel on its own.
            let points: Vec<(f32, f32)> = line.points.iter().map(|&p| self.px(p)).collect();
            for stretch in points.split(|&p| !self.on(p)) {
                canvas.polyline(stretch, *colour, 3.0, false);
            }
            let length: f64 = line
                .points
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                .sum();
            legend.push((format!("{} ({length:.0} m)", line.label), *colour));
        }
        let points = overlays.iter().flat_map(|(_, o)| &o.points);
        for (point, colour) in points.zip(OVERLAY_POINTS.iter().cycle()) {
            let (u, v) = self.px(point.at);
            let seen = self.on((u, v));
            if seen {
                canvas.circle(u, v, 0.4 * self.ppm, None, Some((*colour, 3.0)));
            }
            legend.push((
                format!(
                    "{}: ({:.1}, {:.1}) m{}",
                    point.label,
                    point.at[0],
                    point.at[1],
                    if seen { "" } else { ", off the map" }
                ),
                *colour,
            ));
        }
        legend
    }
}

/// The whole mission: shaded terrain, hazards, the obstacle cells the local
/// map held, the path coloured by speed, image positions, waypoints and
/// collisions.
pub fn mission_picture(path: &Path, world: &World, run: &MissionRun) -> Result<(), RenderError> {
    let mut xs: Vec<f64> = world
        .waypoints
        .iter()
        .map(|w| w.x)
        .chain(run.track.iter().map(|p| p.x))
        .collect();
    let mut ys: Vec<f64> = world
        .waypoints
        .iter()
        .map(|w| w.y)
        .chain(run.track.iter().map(|p| p.y))
        .collect();
    xs.push(world.start.0[0]);
    ys.push(world.start.0[1]);
    let margin = 25.0;
    let min_x = xs.iter().cloned().fold(f64::INFINITY, f64::min) - margin;
    let max_x = xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + margin;
    let min_y = ys.iter().cloned().fold(f64::INFINITY, f64::min) - margin;
    let max_y = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + margin;
    let scale = (1600.0 / (max_x - min_x).max(max_y - min_y)).clamp(1.0, 8.0);
    let header = 70.0;
    let (w, h) = (
        ((max_x - min_x) * scale) as u32,
        ((max_y - min_y) * scale) as u32 + header as u32,
    );
    let mut canvas = Canvas::new(w, h, WHITE)?;
    let to_px = |x: f64, y: f64| {
        (
            ((x - min_x) * scale) as f32,
            (header + (max_y - y) * scale) as f32,
        )
    };

    // Terrain: elevation tint with hill shading; features over it.
    shade_terrain(&mut canvas, world, header as usize, (min_x, max_y), scale);
    draw_features(&mut canvas, world, &to_px, scale);
    // The ground the images observed, lighter.
    let s = run.patch_size_m;
    let side = (s * scale) as f32;
    for &(i, j) in &run.seen_patches {
        let (x, y) = to_px(i as f64 * s, (j + 1) as f64 * s);
        canvas.fill_rect(x, y, side, side, SEEN);
    }
    // What the local map held: the paper's "obstacle regions shown as black
    // dots", drop-offs in their own colour.
    for (&(i, j), &(reasons, cost)) in &run.obstacle_patches {
        let (x, y) = to_px(i as f64 * s, (j + 1) as f64 * s);
        canvas.fill_rect(x, y, side, side, patch_color(reasons, cost, 200));
    }
    // The path, coloured by speed.
    let top = run.track.iter().map(|p| p.speed_mps).fold(0.5, f64::max);
    for pair in run.track.windows(2) {
        let (a, b) = (to_px(pair[0].x, pair[0].y), to_px(pair[1].x, pair[1].y));
        canvas.polyline(&[a, b], speed_color(pair[1].speed_mps, top), 3.0, false);
    }
    for p in &run.image_positions {
        let (x, y) = to_px(p[0], p[1]);
        canvas.circle(x, y, 1.6, Some(WHITE), Some((BLACK, 0.5)));
    }
    // Where the speed governor held the speed: a ring beside the path.
    for p in run.track.iter().filter(|p| p.governed) {
        let (x, y) = to_px(p.x, p.y);
        canvas.circle(x, y, 4.0, None, Some((GOVERNED, 1.5)));
    }
    // Waypoints and the start.
    let (sx, sy) = to_px(world.start.0[0], world.start.0[1]);
    canvas.circle(sx, sy, 7.0, None, Some((BLACK, 2.5)));
    canvas.label(sx + 9.0, sy - 6.0, 14.0, BLACK, "start");
    for (k, wp) in world.waypoints.iter().enumerate() {
        let (x, y) = to_px(wp.x, wp.y);
        let r = (wp.radius_m.unwrap_or(5.0) * scale) as f32;
        let reached = k < run.report.waypoints_reached;
        canvas.circle(
            x,
            y,
            r.max(5.0),
            None,
            Some((if reached { BLUE } else { RED }, 2.5)),
        );
        canvas.label(
            x + r.max(5.0) + 3.0,
            y + 5.0,
            15.0,
            BLACK,
            &format!("{}", k + 1),
        );
    }
    // The operating area's edge, dashed; the ring of impassable cells that
    // closed off each waypoint no route reached, magenta, and where the
    // vehicle was when the route gave it up.
    if let Some(area) = &run.report.area {
        let mut outline: Vec<(f32, f32)> = area.iter().map(|p| to_px(p[0], p[1])).collect();
        outline.extend(outline.first().copied());
        canvas.polyline(&outline, AREA_EDGE, 2.5, true);
    }
    for n in &run.no_routes {
        let side = ((n.cell_m * scale) as f32).max(2.0);
        for p in &n.ring {
            let (x, y) = to_px(p[0], p[1]);
            canvas.fill_rect(x - side / 2.0, y - side / 2.0, side, side, NO_ROUTE);
        }
        let (x, y) = to_px(n.vehicle_at[0], n.vehicle_at[1]);
        canvas.label(
            x + 9.0,
            y - 8.0,
            13.0,
            NO_ROUTE,
            &format!(
                "no route to waypoint {}{}",
                n.waypoint + 1,
                if n.skipped { ": skipped" } else { "" }
            ),
        );
    }
    // Where the vehicle turned in place: a circular arrow the way it
    // turned, and how far.
    for turn in &run.turns_in_place {
        let (x, y) = to_px(turn.x, turn.y);
        let r = 11.0f32;
        let sweep = (turn.turned_deg.abs().min(330.0) as f32)
            .to_radians()
            .max(0.5);
        let side = if turn.turned_deg >= 0.0 { 1.0f32 } else { -1.0 };
        // Screen y points down: a left (anticlockwise) turn runs to -y.
        let at = |a: f32| (x + r * a.cos(), y - side * r * a.sin());
        let arc: Vec<(f32, f32)> = (0..=24).map(|k| at(sweep * k as f32 / 24.0)).collect();
        canvas.polyline(&arc, TURN_IN_PLACE, 2.5, false);
        let (hx, hy) = at(sweep);
        let (bx, by) = at(sweep - 0.45);
        let (dx, dy) = (hx - bx, hy - by);
        canvas.polyline(
            &[
                (bx - 0.6 * dy, by + 0.6 * dx),
                (hx, hy),
                (bx + 0.6 * dy, by - 0.6 * dx),
            ],
            TURN_IN_PLACE,
            2.5,
            false,
        );
        canvas.label(
            x + r + 4.0,
            y + 4.0,
            12.0,
            TURN_IN_PLACE,
            &format!("turned {:.0}° in place", turn.turned_deg.abs()),
        );
    }
    for c in &run.report.collisions {
        let (x, y) = to_px(c.position[0], c.position[1]);
        canvas.polyline(&[(x - 8.0, y - 8.0), (x + 8.0, y + 8.0)], RED, 3.0, false);
        canvas.polyline(&[(x - 8.0, y + 8.0), (x + 8.0, y - 8.0)], RED, 3.0, false);
        canvas.label(x + 10.0, y, 13.0, RED, &c.cause);
    }
    // Where the guard stopped (red) or slowed (orange) the vehicle, each a
    // defect of the pipeline to find: a square, and the time of the first
    // at each place.
    if let Some(guard) = &run.report.guard {
        let mut labelled: Vec<(f64, f64)> = Vec::new();
        for e in &guard.first {
            let (x, y) = to_px(e.x, e.y);
            let colour = if e.verdict == "stop" {
                RED
            } else {
                [230, 140, 0, 255]
            };
            canvas.polygon(
                &[
                    (x - 6.0, y - 6.0),
                    (x + 6.0, y - 6.0),
                    (x + 6.0, y + 6.0),
                    (x - 6.0, y + 6.0),
                ],
                None,
                Some((colour, 2.5)),
            );
            if labelled
                .iter()
                .all(|&(lx, ly)| (lx - e.x).hypot(ly - e.y) > 10.0)
            {
                labelled.push((e.x, e.y));
                canvas.label(
                    x + 9.0,
                    y + 12.0,
                    12.0,
                    colour,
                    &format!("guard {} at {:.0} s", e.verdict, e.t_s),
                );
            }
        }
    }
    // Header: what happened, and the speed scale.
    let r = &run.report;
    canvas.fill_rect(0.0, 0.0, w as f32, header as f32, WHITE);
    canvas.text(
        10.0,
        24.0,
        19.0,
        BLACK,
        &format!(
            "{} — {} — {:.0} m in {:.0} s, {:.2} m/s average, {} images, {} collision(s){}",
            r.world,
            if r.success { "completed" } else { "FAILED" },
            r.distance_m,
            r.duration_s,
            r.average_speed_mps,
            r.images,
            r.collisions.len(),
            match &r.guard {
                Some(g) if g.interventions() > 0 => format!(
                    ", guard: {} stops (red squares), {} slows (orange)",
                    g.stops, g.slows
                ),
                _ => String::new(),
            }
        ),
    );
    canvas.text(10.0, 50.0, 14.0, BLACK, "path speed:");
    for k in 0..120 {
        let v = top * k as f64 / 119.0;
        canvas.fill_rect(95.0 + k as f32 * 2.0, 38.0, 2.0, 14.0, speed_color(v, top));
    }
    canvas.text(340.0, 50.0, 14.0, BLACK, &format!("0 – {top:.1} m/s"));
    canvas.text(
        470.0,
        50.0,
        14.0,
        BLACK,
        &format!("black: cells in the local map · orange: drop-offs (pale: suspected) · purple: graded ground · light: ground seen · white: images · violet rings: speed held by the governor (ground not verified) · circles: waypoints ({} reached) · dashed: operating area · magenta: no way through · grey: no map · {:.2} m/px", r.waypoints_reached, 1.0 / scale),
    );
    canvas.save(path)
}

/// The mission picture's terrain below `header` pixel rows: an elevation
/// tint with hill shading, `scale` pixels a metre from world (`min_x`,
/// `max_y`) at the top left.
/// The part of segment a-b inside the box (lo, hi), if any
/// (Liang-Barsky).
fn clip_segment(
    a: [f32; 2],
    b: [f32; 2],
    (lo, hi): ([f32; 2], [f32; 2]),
) -> Option<([f32; 2], [f32; 2])> {
    let d = [b[0] - a[0], b[1] - a[1]];
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for axis in 0..2 {
        for (p, q) in [
            (-d[axis], a[axis] - lo[axis]),
            (d[axis], hi[axis] - a[axis]),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
    }
    let at = |t: f32| [a[0] + t * d[0], a[1] + t * d[1]];
    (t0 <= t1).then(|| (at(t0), at(t1)))
}

/// Beyond the map: no ground.
const NO_GROUND: [u8; 3] = [205, 205, 205];
/// The operating area's edge.
const AREA_EDGE: Rgba = [40, 40, 160, 255];
/// The cells that closed a waypoint off.
const NO_ROUTE: Rgba = [200, 0, 160, 255];
/// Where the speed governor held the speed.
const GOVERNED: Rgba = [120, 60, 220, 200];
/// Turns in place on the map.
const TURN_IN_PLACE: Rgba = [120, 40, 200, 255];

fn shade_terrain(
    canvas: &mut Canvas,
    world: &World,
    header: usize,
    (min_x, max_y): (f64, f64),
    scale: f64,
) {
    let (gw, gh) = (
        canvas.pixmap.width() as usize,
        (canvas.pixmap.height() as usize).saturating_sub(header),
    );
    let step = 1.0 / scale;
    let mut heights = vec![0.0; gw * gh];
    for (r, row) in heights.chunks_exact_mut(gw.max(1)).enumerate() {
        let xs = (0..gw).map(|c| min_x + (c as f64 + 0.5) * step);
        world.terrain_heights_along(max_y - (r as f64 + 0.5) * step, xs, row);
    }
    // The tint spans the heights on the map only.
    let (lo, hi) = heights
        .iter()
        .enumerate()
        .filter(|&(k, _)| {
            let (c, r) = (k % gw, k / gw);
            world.contains(
                min_x + (c as f64 + 0.5) * step,
                max_y - (r as f64 + 0.5) * step,
            )
        })
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, &v)| {
            (a.min(v), b.max(v))
        });
    let pixels = canvas.pixmap.pixels_mut();
    for r in 0..gh {
        for c in 0..gw {
            let at = |cc: usize, rr: usize| heights[rr.min(gh - 1) * gw + cc.min(gw - 1)];
            let dzdx = (at(c + 1, r) - at(c.saturating_sub(1), r)) / (2.0 * step);
            let dzdy = (at(c, r.saturating_sub(1)) - at(c, r + 1)) / (2.0 * step);
            let shade = ((-dzdx * 0.6 + dzdy * 0.6 + 1.0)
                / (dzdx * dzdx + dzdy * dzdy + 1.0).sqrt())
            .clamp(0.3, 1.3)
                / 1.3;
            let t = (heights[r * gw + c] - lo) / (hi - lo).max(0.1);
            let base = [150.0 + 60.0 * t, 175.0 + 30.0 * t, 120.0 + 50.0 * t];
            let (x, y) = (
                min_x + (c as f64 + 0.5) * step,
                max_y - (r as f64 + 0.5) * step,
            );
            // Beyond the map there is no ground: a flat grey.
            let rgb = if world.contains(x, y) {
                base.map(|v| (v * (0.55 + 0.45 * shade)).clamp(0.0, 255.0) as u8)
            } else {
                NO_GROUND
            };
            if let Some(p) = tiny_skia::PremultipliedColorU8::from_rgba(rgb[0], rgb[1], rgb[2], 255)
            {
                pixels[(r + header) * gw + c] = p;
            }
        }
    }
}

/// The world's features, dark where the vehicle cannot drive over them.
fn draw_features(
    canvas: &mut Canvas,
    world: &World,
    to_px: &impl Fn(f64, f64) -> (f32, f32),
    scale: f64,
) {
    let vehicle = arcnav_vehicle::VehicleConfig::default();
    for f in &world.features {
        let hazard = f.hazard(&vehicle).is_some();
        let c: Rgba = match (f.kind, hazard) {
            (FeatureKind::Boulder, true) => [95, 95, 95, 255],
            (FeatureKind::Tree, _) => [20, 90, 30, 255],
            (FeatureKind::Bush, _) => [60, 140, 50, 255],
            (FeatureKind::Hole | FeatureKind::Ditch, true) => [40, 60, 120, 255],
            (FeatureKind::Bank, _) => [140, 100, 60, 255],
            (FeatureKind::Rubble, _) => [150, 130, 110, 255],
            _ => [170, 170, 160, 255],
        };
        let (ax, ay) = to_px(f.a[0], f.a[1]);
        let (bx, by) = to_px(f.b[0], f.b[1]);
        let r = (f.radius * scale) as f32;
        if f.a == f.b {
            canvas.circle(ax, ay, r.max(1.5), Some(c), None);
        } else {
            canvas.polyline(&[(ax, ay), (bx, by)], c, (2.0 * r).max(2.0), false);
        }
    }
}

/// Ground observed by some image (mission picture: a light veil).
const SEEN: [u8; 4] = [255, 255, 255, 90];
/// Ground no image observed (snapshot picture).
const UNSEEN: [u8; 4] = [200, 200, 205, 255];

/// A map patch's colour: drop-offs orange, other obstacles black,
/// suspected drop-offs (graded, reason drop-off) pale orange, other graded
/// ground (cost below 1) purple, the more opaque the costlier.
fn patch_color(reasons: Reasons, cost: f32, alpha: u8) -> [u8; 4] {
    if suspected_drop_off(cost, reasons) {
        [250, 190, 110, alpha]
    } else if cost < 1.0 {
        [
            130,
            40,
            150,
            (f32::from(alpha) * cost.clamp(0.2, 1.0)) as u8,
        ]
    } else if reasons.contains(Reasons::DROP_OFF) {
        [235, 120, 20, alpha]
    } else {
        [20, 20, 20, alpha]
    }
}

/// One decision: the local map in the vehicle frame with the arcs coloured by
/// fused vote (chosen arc in blue, forbidden arcs dashed), and each
/// behaviour's votes and the fused votes as bars, hardest left turn first.
#[allow(clippy::too_many_arguments)]
pub fn snapshot_picture(
    path: &Path,
    config: &Resolved,
    arcs: &ArcSet,
    map: &MapSnapshot,
    decision: Option<&Decision>,
    elapsed_us: Utime,
    overlays: &[(String, Overlay)],
    guard: Option<&str>,
) -> Result<(), RenderError> {
    let ppm = 20.0f32;
    // The picture reaches 2 m past the map window as the nodes use it
    // (farther at speed: `arcnav_config::Lookahead`).
    let (ahead, side, behind) = (
        config.localmap.ahead_m as f32,
        config.localmap.half_width_m as f32,
        config.localmap.behind_m as f32,
    );
    let (x_behind, x_ahead, half) = (8.0f32, (ahead + 2.0).max(22.0), (side + 3.0).max(13.0));
    let map_h = ((x_behind + x_ahead) * ppm) as u32;
    let map_w = (2.0 * half * ppm) as u32;
    let panel = 520u32;
    let mut canvas = Canvas::new(map_w + panel, map_h.max(640), [245, 245, 240, 255])?;
    // Vehicle frame (x forward up, y left to the left) to pixels.
    let to_px = |x: f32, y: f32| ((half - y) * ppm, (x_ahead - x) * ppm);
    canvas.fill_rect(0.0, 0.0, map_w as f32, map_h as f32, WHITE);
    let window = [
        to_px(ahead, side),
        to_px(ahead, -side),
        to_px(-behind, -side),
        to_px(-behind, side),
    ];
    canvas.polygon(&window, None, Some(([150, 150, 150, 255], 1.0)));
    for m in (-5..=20).step_by(5) {
        let (_, y) = to_px(m as f32, 0.0);
        canvas.text(3.0, y + 4.0, 11.0, [120, 120, 120, 255], &format!("{m} m"));
    }
    // Ground no image has seen, shaded: a grid of the patch size in the
    // vehicle frame, each cell judged at its centre.
    let s = map.patch_size_m as f32;
    let seen = map.seen_lookup();
    let cells = |from: f32, to: f32| (from / s).floor() as i32..(to / s).ceil() as i32;
    for gx in cells(-x_behind, x_ahead) {
        for gy in cells(-half, half) {
            let (cx, cy) = ((gx as f32 + 0.5) * s, (gy as f32 + 0.5) * s);
            if !seen(f64::from(cx), f64::from(cy)) {
                let (x, y) = to_px(cx + s / 2.0, cy + s / 2.0);
                canvas.fill_rect(x, y, s * ppm, s * ppm, UNSEEN);
            }
        }
    }
    // Map patches, drop-offs in their own colour.
    // (Only those on the map panel: the window reaches further behind.)
    for p in map
        .patches
        .iter()
        .filter(|p| p.x > -x_behind && p.y.abs() < half)
    {
        let (x, y) = to_px(p.x + s / 2.0, p.y + s / 2.0);
        canvas.fill_rect(x, y, s * ppm, s * ppm, patch_color(p.reasons, p.cost, 255));
    }
    // The operating area's edge, in the vehicle frame of the decision.
    if let Some(area) = config.area() {
        let t = map.world_from_vehicle.translation.vector;
        let (sin, cos) = arcnav_vehicle::frames::yaw_of(&map.world_from_vehicle).sin_cos();
        let local: Vec<[f32; 2]> = area
            .vertices()
            .iter()
            .map(|&[x, y]| {
                let (dx, dy) = (x - t.x, y - t.y);
                [(cos * dx + sin * dy) as f32, (-sin * dx + cos * dy) as f32]
            })
            .collect();
        let panel = ([-x_behind, -half], [x_ahead, half]);
        for (k, &a) in local.iter().enumerate() {
            let b = local[(k + 1) % local.len()];
            if let Some((a, b)) = clip_segment(a, b, panel) {
                canvas.polyline(
                    &[to_px(a[0], a[1]), to_px(b[0], b[1])],
                    AREA_EDGE,
                    2.5,
                    true,
                );
            }
        }
    }
    // What the behaviours' votes rested on: cells under the arcs, lines
    // and points over them.
    let map_panel = MapPanel {
        size: (map_w as f32, map_h as f32),
        ppm,
        to_px: &to_px,
    };
    let cell_legend = map_panel.cells(&mut canvas, overlays);
    // Arcs: fused vote colours, chosen arc blue.
    let chosen = decision.and_then(|d| d.command.arc_index);
    // As far as obstacle avoidance judges them.
    let reach = config.lookahead.max_distance_m;
    // An arc is drawn until it leaves the map (at speed, tight arcs judged
    // 40 m along circle the vehicle and would run over the panel).
    let arc_pixels = |arc: &arcnav_vehicle::Arc| -> Vec<(f32, f32)> {
        arc.sample(reach, 0.5)
            .map(|p| to_px(p.position.x as f32, p.position.y as f32))
            .take_while(|&p| map_panel.on(p))
            .collect()
    };
    for (i, arc) in arcs.iter().enumerate() {
        let (vote, vetoed) = decision
            .map(|d| {
                (
                    d.fused.get(i).copied().unwrap_or(0.0),
                    d.vetoes.get(i).is_some_and(|v| !v.is_empty()),
                )
            })
            .unwrap_or((0.0, false));
        let points = arc_pixels(&arc);
        if Some(i) == chosen {
            continue;
        }
        canvas.polyline(&points, vote_color(vote), 2.0, vetoed);
    }
    if let Some(i) = chosen
        && let Some(arc) = arcs.arc(i)
    {
        let points = arc_pixels(&arc);
        canvas.polyline(&points, BLUE, 4.0, false);
    }
    let mut legend = cell_legend;
    legend.extend(map_panel.marks(&mut canvas, overlays));
    // The map's key, over whatever lies under it.
    canvas.fill_rect(
        0.0,
        map_h as f32 - 22.0,
        map_w as f32,
        22.0,
        [255, 255, 255, 210],
    );
    canvas.text(
        6.0,
        map_h as f32 - 8.0,
        12.0,
        [60, 60, 60, 255],
        "grey: ground not seen · black: cells · orange: drop-offs (pale: suspected) · purple: graded ground (by cost) · dashed: operating area",
    );
    let f = config.vehicle.footprint();
    let body: Vec<_> = f
        .outline()
        .iter()
        .map(|p| to_px(p.x as f32, p.y as f32))
        .collect();
    canvas.polygon(&body, Some([70, 110, 200, 180]), Some((BLACK, 1.5)));

    // Vote bars, the key and the decision, right of the map.
    vote_panel(
        &mut canvas,
        map_w as f32 + 20.0,
        panel as f32,
        arcs,
        decision,
        elapsed_us,
        &legend,
        guard,
    );
    canvas.save(path)
}

/// The panel right of a snapshot's map, from `x0`, `panel` wide: each
/// behaviour's votes and the fused ones as bars, the map's key, the
/// command, the guard's verdict on it and who vetoed what.
#[allow(clippy::too_many_arguments)]
fn vote_panel(
    canvas: &mut Canvas,
    x0: f32,
    panel: f32,
    arcs: &ArcSet,
    decision: Option<&Decision>,
    elapsed_us: Utime,
    legend: &[(String, Rgba)],
    guard: Option<&str>,
) {
    let chosen = decision.and_then(|d| d.command.arc_index);
    let bar_w = ((panel - 40.0) / arcs.len() as f32).max(1.0);
    let mut rows: Vec<(String, Vec<f32>, Vec<bool>)> = Vec::new();
    if let Some(d) = decision {
        for input in &d.inputs {
            if let Some(v) = &input.votes {
                rows.push((
                    format!(
                        "{} (weight {}{})",
                        input.behaviour,
                        input.weight,
                        if input.used { "" } else { ", not used" }
                    ),
                    v.values().to_vec(),
                    v.vetoed().to_vec(),
                ));
            }
        }
        let vetoed = d.vetoes.iter().map(|v| !v.is_empty()).collect();
        rows.push(("fused".to_owned(), d.fused.clone(), vetoed));
    }
    let row_h = 110.0;
    let mut y = 30.0;
    canvas.text(
        x0,
        y - 8.0,
        15.0,
        BLACK,
        &format!("t = {:.1} s", elapsed_us as f64 * 1e-6),
    );
    y += 10.0;
    for (name, values, vetoed) in &rows {
        canvas.text(x0, y + 12.0, 13.0, BLACK, name);
        let mid = y + 20.0 + (row_h - 40.0) / 2.0;
        let amp = (row_h - 40.0) / 2.0;
        canvas.polyline(
            &[(x0, mid), (x0 + bar_w * values.len() as f32, mid)],
            [150, 150, 150, 255],
            1.0,
            false,
        );
        for (k, (&v, &veto)) in values.iter().zip(vetoed).enumerate().rev() {
            // Hardest left turn (last index) first.
            let col = (values.len() - 1 - k) as f32;
            let c = if veto {
                [120, 0, 0, 255]
            } else {
                vote_color(v)
            };
            let (top, height) = if v >= 0.0 {
                (mid - v * amp, v * amp)
            } else {
                (mid, -v * amp)
            };
            canvas.fill_rect(x0 + col * bar_w + 0.5, top, bar_w - 1.0, height, c);
            if Some(k) == chosen && name == "fused" {
                canvas.fill_rect(x0 + col * bar_w, mid + amp + 2.0, bar_w, 4.0, BLUE);
            }
        }
        y += row_h;
    }
    canvas.text(
        x0,
        y,
        11.0,
        [90, 90, 90, 255],
        "bars: hard left ... straight ... hard right; dark red: vetoed",
    );
    y += 20.0;
    for (label, colour) in legend {
        canvas.fill_rect(x0, y - 9.0, 14.0, 10.0, *colour);
        canvas.text(x0 + 20.0, y, 12.0, BLACK, label);
        y += 16.0;
    }
    y += 4.0;
    if let Some(d) = decision {
        let c = &d.command;
        let radius = if c.curvature.abs() < 1e-9 {
            "straight".to_owned()
        } else {
            format!("{:.1} m", 1.0 / c.curvature)
        };
        let line = match &d.stop {
            Some(reason) => format!("STOP: {reason}"),
            None if c.is_turn_in_place() => format!(
                "manoeuvre: turning {} in place at {:.0}°/s",
                if c.turn_rate_radps > 0.0 {
                    "left"
                } else {
                    "right"
                },
                c.turn_rate_radps.abs().to_degrees()
            ),
            None if d.is_manoeuvre() => format!(
                "manoeuvre: curvature {:+.4} 1/m (radius {radius}), {:.2} m/s",
                c.curvature, c.speed_mps
            ),
            None => format!(
                "arc {} of {}: curvature {:+.4} 1/m (radius {radius}), {:.2} m/s, fused vote {:.2}",
                c.arc_index.map_or(0, |i| i),
                arcs.len(),
                c.curvature,
                c.speed_mps,
                c.vote
            ),
        };
        canvas.text(
            x0,
            y,
            13.0,
            if d.stop.is_some() { RED } else { BLACK },
            &line,
        );
        y += 20.0;
        // The guard's verdict on this command, when the log says it.
        if let Some(verdict) = guard {
            let colour = if verdict.starts_with("STOP") {
                RED
            } else if verdict.starts_with("SLOW") {
                [200, 110, 0, 255]
            } else {
                BLACK
            };
            canvas.text(x0, y, 13.0, colour, &format!("guard: {verdict}"));
            y += 20.0;
        }
        let mut listed = 0;
        for (arc, vetoes) in d.vetoes.iter().enumerate() {
            for (who, cause) in vetoes {
                if listed < 6 {
                    let at = cause.map_or("cause not said".to_owned(), |c| c.to_string());
                    canvas.text(
                        x0,
                        y,
                        11.0,
                        [120, 0, 0, 255],
                        &format!("arc {arc} vetoed by {who}: {at}"),
                    );
                    y += 15.0;
                }
                listed += 1;
            }
        }
        if listed > 6 {
            canvas.text(
                x0,
                y,
                11.0,
                [120, 0, 0, 255],
                &format!("... {} vetoes in all", listed),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_behaviours::{OverlayCells, OverlayLine, OverlayPoint};

    /// A behaviour's overlay is drawn on the snapshot where it lies in the
    /// vehicle frame: its line in the line colour over everything, its
    /// cells tinted; what lies off the map is left out.
    #[test]
    fn a_snapshot_draws_the_behaviours_overlays_where_they_lie() {
        let config = Resolved::default();
        let arcs = config.arcs.clone();
        let map = MapSnapshot {
            patch_size_m: 0.5,
            ..MapSnapshot::default()
        };
        let overlay = Overlay {
            // Across the map 6 m behind the vehicle, and on far off it.
            lines: vec![OverlayLine {
                label: "a path".to_owned(),
                points: vec![[-6.0, 8.0], [-6.0, -8.0], [-6.0, -400.0]],
            }],
            cells: vec![OverlayCells {
                label: "some ground".to_owned(),
                size_m: 1.0,
                yaw: 0.0,
                centres: vec![[-3.0, 6.0], [500.0, 0.0]],
            }],
            points: vec![OverlayPoint {
                label: "a point".to_owned(),
                at: [-3.0, -6.0],
            }],
        };
        let dir = arcnav_testkit::temp_dir("render-overlay");
        let picture = |overlays: &[(String, Overlay)], name: &str| {
            let path = dir.join(name);
            snapshot_picture(&path, &config, &arcs, &map, None, 0, overlays, None).unwrap();
            tiny_skia::Pixmap::load_png(&path).unwrap()
        };
        let with = picture(&[("b".to_owned(), overlay)], "with.png");
        let without = picture(&[], "without.png");
        // The map panel's vehicle frame, as snapshot_picture lays it out.
        let x_ahead = (config.localmap.ahead_m as f32 + 2.0).max(22.0);
        let half = (config.localmap.half_width_m as f32 + 3.0).max(13.0);
        let pixel = |image: &tiny_skia::Pixmap, x: f32, y: f32| {
            let (u, v) = (((half - y) * 20.0) as u32, ((x_ahead - x) * 20.0) as u32);
            let p = image.pixel(u, v).unwrap();
            [p.red(), p.green(), p.blue()]
        };
        // Within the blending of a colour not quite opaque.
        let near = |p: [u8; 3], c: Rgba| (0..3).all(|k| p[k].abs_diff(c[k]) <= 30);
        let line = OVERLAY_LINES[0];
        assert!(
            near(pixel(&with, -6.0, 3.0), line),
            "{:?}",
            pixel(&with, -6.0, 3.0)
        );
        assert!(!near(pixel(&without, -6.0, 3.0), line));
        // Teal over the map: green and blue above red, unlike without.
        let [r, g, b] = pixel(&with, -3.0, 6.0);
        assert!(g > r + 40 && b > r + 40, "{r} {g} {b}");
        assert_ne!(pixel(&without, -3.0, 6.0), [r, g, b]);
        // The point's ring, 0.4 m round it.
        let ring = OVERLAY_POINTS[0];
        assert!(
            near(pixel(&with, -3.0, -6.4), ring),
            "{:?}",
            pixel(&with, -3.0, -6.4)
        );
        assert!(!near(pixel(&without, -3.0, -6.4), ring));
    }
}
