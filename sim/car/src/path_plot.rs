//! `path.svg`: the car's path drawn at equal scale on its road, the way a test engineer
//! sketches a manoeuvre: the road with its edges, centreline and friction patches, the
//! path of the centre of gravity, tyre marks where a wheel locked, spun or slid, and the
//! car's outline at intervals with its steered front wheels. Self-contained SVG, like
//! the other plots, so every run draws it with nothing installed.

use std::fmt::Write;

use autoplug_road::file::NamedRoad;
use autoplug_road::Road;
use autoplug_vehicle::VehicleParams;

use crate::car::TraceRow;

/// Largest width and height of the drawing area, px.
const MAX_SIDE_PX: f64 = 900.0;
/// Smallest height of the drawing area, px: a long straight path still shows its road.
const MIN_HEIGHT_PX: f64 = 240.0;
/// Smallest width, px: room for the legend under a tall, narrow path.
const MIN_WIDTH_PX: f64 = 720.0;
/// Space around the drawing area for the title and the scale, px.
const MARGIN_PX: f64 = 40.0;
/// Ground around the path, m.
const GROUND_M: f64 = 8.0;
/// How many car outlines the drawing shows at most (besides the last).
const OUTLINES: usize = 12;
/// Friction at or below this is drawn as ice, above it up to [`WET_MU`] as wet.
const ICE_MU: f64 = 0.3;
const WET_MU: f64 = 0.7;

/// The car's dimensions the drawing needs, from its parameters.
struct Body {
    length: f64,
    width: f64,
    /// From the CG to the front of the body, m.
    cg_to_front: f64,
    wheels: [(f64, f64); 4],
    steering_ratio: f64,
}

impl Body {
    fn of(params: &VehicleParams) -> Self {
        let c = &params.chassis;
        Self {
            length: c.body_length_m,
            width: c.body_width_m,
            cg_to_front: c.cg_to_front_axle_m() + c.front_overhang_m,
            wheels: c.wheel_offsets(),
            steering_ratio: params.steering.ratio,
        }
    }
}

/// Maps metres (x east, y north) to pixels (y down) at one scale for both axes.
struct View {
    x0: f64,
    y1: f64,
    scale: f64,
    width: f64,
    height: f64,
}

impl View {
    fn px(&self, x: f64, y: f64) -> (f64, f64) {
        (
            MARGIN_PX + (x - self.x0) * self.scale,
            MARGIN_PX + (self.y1 - y) * self.scale,
        )
    }

    fn contains(&self, x: f64, y: f64, margin_m: f64) -> bool {
        let (px, py) = self.px(x, y);
        let m = margin_m * self.scale;
        (MARGIN_PX - m..=MARGIN_PX + self.width + m).contains(&px)
            && (MARGIN_PX - m..=MARGIN_PX + self.height + m).contains(&py)
    }
}

/// The drawing of `trace` on `track` (or on open ground without one) as an SVG document.
pub fn path_svg(trace: &[TraceRow], track: Option<&NamedRoad>, params: &VehicleParams) -> String {
    let body = Body::of(params);
    let points: Vec<(f64, f64)> = trace
        .iter()
        .map(|r| (r.x_m, r.y_m))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let view = view_of(&points, track.map(|t| &t.road));
    let mut svg = String::with_capacity(64 * 1024);
    let total_w = view.width + 2.0 * MARGIN_PX;
    let total_h = view.height + 2.0 * MARGIN_PX;
    let _ = write!(
        svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{total_w:.0}" height="{total_h:.0}" viewBox="0 0 {total_w:.0} {total_h:.0}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="#ffffff"/>
<rect x="{MARGIN_PX}" y="{MARGIN_PX}" width="{:.1}" height="{:.1}" fill="{}"/>
"##,
        view.width,
        view.height,
        if track.is_some() {
            "#cfe0b8"
        } else {
            "#f2f2f2"
        },
    );
    let _ = writeln!(
        svg,
        r##"<svg x="{MARGIN_PX}" y="{MARGIN_PX}" width="{:.1}" height="{:.1}" viewBox="{MARGIN_PX} {MARGIN_PX} {:.1} {:.1}">"##,
        view.width, view.height, view.width, view.height
    );
    if let Some(track) = track {
        draw_road(&mut svg, &track.road, &view);
    }
    draw_tyre_marks(&mut svg, trace, &body, &view);
    draw_path(&mut svg, &points, &view);
    draw_outlines(&mut svg, trace, &body, &view);
    svg.push_str("</svg>\n");
    let title = match track {
        Some(t) => format!("Path on the {} (equal scale)", t.name),
        None => "Path on open ground (equal scale)".to_string(),
    };
    let _ = writeln!(
        svg,
        r##"<text x="{:.1}" y="24" text-anchor="middle" font-size="15" font-weight="bold">{}</text>"##,
        total_w / 2.0,
        escape(&title)
    );
    draw_scale(&mut svg, &view, total_h);
    let _ = writeln!(
        svg,
        r##"<text x="{:.1}" y="{:.1}" text-anchor="end" fill="#444">path of the CG (blue), tyre marks (black), the car every {} (grey, last in red); x east, y north</text>"##,
        total_w - MARGIN_PX,
        total_h - 14.0,
        outline_spacing_text(trace)
    );
    svg.push_str("</svg>\n");
    svg
}

/// The area to draw: the path with ground around it, and a closed track whole; the
/// same scale on both axes, at most [`MAX_SIDE_PX`] either way.
fn view_of(points: &[(f64, f64)], road: Option<&Road>) -> View {
    let mut lo = (f64::INFINITY, f64::INFINITY);
    let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut include = |x: f64, y: f64| {
        lo = (lo.0.min(x), lo.1.min(y));
        hi = (hi.0.max(x), hi.1.max(y));
    };
    for &(x, y) in points {
        include(x, y);
    }
    if let Some(road) = road.filter(|r| r.is_closed()) {
        let mut s = 0.0;
        while s <= road.length_m() {
            let p = road.pose_at(s);
            include(p.x_m, p.y_m);
            s += 5.0;
        }
    }
    if !lo.0.is_finite() {
        lo = (0.0, 0.0);
        hi = (0.0, 0.0);
    }
    let margin = GROUND_M + road.map_or(0.0, |r| r.width_m() / 2.0);
    let (mut x0, mut x1) = (lo.0 - margin, hi.0 + margin);
    let (mut y0, mut y1) = (lo.1 - margin, hi.1 + margin);
    let scale = (MAX_SIDE_PX / (x1 - x0)).min(MAX_SIDE_PX / (y1 - y0));
    // A flat drawing keeps a readable height: more ground above and below.
    let min_span_y = MIN_HEIGHT_PX / scale;
    if y1 - y0 < min_span_y {
        let grow = (min_span_y - (y1 - y0)) / 2.0;
        y0 -= grow;
        y1 += grow;
    }
    let min_span_x = MIN_WIDTH_PX / scale;
    if x1 - x0 < min_span_x {
        let grow = (min_span_x - (x1 - x0)) / 2.0;
        x0 -= grow;
        x1 += grow;
    }
    View {
        x0,
        y1,
        scale,
        width: (x1 - x0) * scale,
        height: (y1 - y0) * scale,
    }
}

/// The road's stations within the view (and a little beyond), in order: ranges of
/// stations every `step` m.
fn visible_stations(road: &Road, view: &View, step: f64) -> Vec<Vec<f64>> {
    let margin = road.width_m();
    let mut runs: Vec<Vec<f64>> = Vec::new();
    let mut current: Vec<f64> = Vec::new();
    let mut s: f64 = 0.0;
    let end = road.length_m();
    loop {
        let p = road.pose_at(s.min(end));
        if view.contains(p.x_m, p.y_m, margin) {
            current.push(s.min(end));
        } else if !current.is_empty() {
            runs.push(std::mem::take(&mut current));
        }
        if s >= end {
            break;
        }
        s += step;
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs
}

/// The line `lateral` m left of the centreline along `stations`, as SVG points.
fn offset_line(road: &Road, stations: &[f64], lateral: f64, view: &View) -> String {
    let mut text = String::with_capacity(stations.len() * 16);
    for &s in stations {
        let p = road.pose_at(s);
        let (sin, cos) = p.heading_rad.sin_cos();
        let (px, py) = view.px(p.x_m - lateral * sin, p.y_m + lateral * cos);
        let _ = write!(text, "{px:.1},{py:.1} ");
    }
    text
}

fn draw_road(svg: &mut String, road: &Road, view: &View) {
    // Fine enough that a 60 m bend looks round at this scale.
    let step = (3.0 / view.scale).clamp(0.5, 5.0);
    let half = road.width_m() / 2.0;
    let runs = visible_stations(road, view, step);
    for stations in &runs {
        let left = offset_line(road, stations, half, view);
        let reversed: Vec<f64> = stations.iter().rev().copied().collect();
        let right = offset_line(road, &reversed, -half, view);
        let _ = writeln!(
            svg,
            r##"<polygon points="{left}{right}" fill="#9b9b9b" stroke="none"/>"##
        );
    }
    for patch in road.patches() {
        let (from, to) = (patch.from_m, patch.to_m);
        let span: Vec<f64> = if from <= to {
            stations_between(from, to, step)
        } else {
            let mut first = stations_between(from, road.length_m(), step);
            first.extend(stations_between(0.0, to, step));
            first
        };
        let left = offset_line(road, &span, patch.left_m, view);
        let reversed: Vec<f64> = span.iter().rev().copied().collect();
        let right = offset_line(road, &reversed, patch.right_m, view);
        let colour = if patch.mu <= ICE_MU {
            "#bfe4f5"
        } else if patch.mu <= WET_MU {
            "#5f7f99"
        } else {
            "#7d7d7d"
        };
        let _ = writeln!(
            svg,
            r##"<polygon points="{left}{right}" fill="{colour}" opacity="0.9"><title>{} (μ {:.2})</title></polygon>"##,
            escape(&patch.name),
            patch.mu
        );
        let mid = road.pose_at(if from <= to {
            (from + to) / 2.0
        } else {
            road.wrap((from + to + road.length_m()) / 2.0)
        });
        let lateral = (patch.left_m + patch.right_m) / 2.0;
        let (sin, cos) = mid.heading_rad.sin_cos();
        let (px, mut py) = view.px(mid.x_m - lateral * sin, mid.y_m + lateral * cos);
        // Drawn on the patch where the road is wide on the page; where it is a few pixels
        // (a whole lap) the path and the marks would cover the label: above the road there.
        let half_width_px = road.width_m() / 2.0 * view.scale;
        if half_width_px < 15.0 {
            py -= half_width_px + 4.0;
        }
        if view.contains(mid.x_m, mid.y_m, 0.0) {
            // A white halo keeps it legible over the grass or the asphalt.
            let _ = writeln!(
                svg,
                r##"<text x="{px:.1}" y="{py:.1}" text-anchor="middle" font-size="11" fill="#1d3b53" stroke="#ffffff" stroke-width="3" stroke-opacity="0.85" paint-order="stroke">{} μ {:.2}</text>"##,
                escape(&patch.name),
                patch.mu
            );
        }
    }
    for stations in &runs {
        for lateral in [half, -half] {
            let line = offset_line(road, stations, lateral, view);
            let _ = writeln!(
                svg,
                r##"<polyline points="{line}" fill="none" stroke="#ffffff" stroke-width="1.5"/>"##
            );
        }
        let centre = offset_line(road, stations, 0.0, view);
        let _ = writeln!(
            svg,
            r##"<polyline points="{centre}" fill="none" stroke="#ffffff" stroke-width="1" stroke-dasharray="8 8"/>"##
        );
    }
}

fn stations_between(from: f64, to: f64, step: f64) -> Vec<f64> {
    let mut stations = Vec::new();
    let mut s = from;
    while s < to {
        stations.push(s);
        s += step;
    }
    stations.push(to);
    stations
}

/// Where each wheel is, and whether it marks the road, at one trace row.
fn wheel_marks(row: &TraceRow, body: &Body) -> [((f64, f64), bool); 4] {
    let (sin, cos) = row.heading_rad.sin_cos();
    std::array::from_fn(|i| {
        let (x, y) = body.wheels[i];
        let at = (row.x_m + x * cos - y * sin, row.y_m + x * sin + y * cos);
        (at, row.marks[i])
    })
}

fn draw_tyre_marks(svg: &mut String, trace: &[TraceRow], body: &Body, view: &View) {
    let width = (0.22 * view.scale).max(1.0);
    for wheel in 0..4 {
        let mut run = String::new();
        let flush = |run: &mut String, svg: &mut String| {
            if run.matches(' ').count() >= 2 {
                let _ = writeln!(
                    svg,
                    r##"<polyline points="{run}" fill="none" stroke="#1a1a1a" stroke-opacity="0.75" stroke-width="{width:.1}" stroke-linecap="round"/>"##
                );
            }
            run.clear();
        };
        for row in trace {
            let ((x, y), marks) = wheel_marks(row, body)[wheel];
            if marks && x.is_finite() && y.is_finite() {
                let (px, py) = view.px(x, y);
                let _ = write!(run, "{px:.1},{py:.1} ");
            } else {
                flush(&mut run, svg);
            }
        }
        flush(&mut run, svg);
    }
}

fn draw_path(svg: &mut String, points: &[(f64, f64)], view: &View) {
    // Farther than this between two rows (10 ms apart) is the simulator's hand (the car
    // put back at its start), not a drive: the path breaks there.
    const JUMP_M: f64 = 5.0;
    let mut line = String::with_capacity(points.len() * 8);
    let mut last: Option<(f64, f64)> = None;
    let mut previous: Option<(f64, f64)> = None;
    let flush = |line: &mut String, svg: &mut String| {
        if !line.is_empty() {
            let _ = writeln!(
                svg,
                r##"<polyline points="{line}" fill="none" stroke="#1f5fbf" stroke-width="1.5"/>"##
            );
            line.clear();
        }
    };
    for &(x, y) in points {
        if previous.is_some_and(|(px, py)| (x - px).hypot(y - py) > JUMP_M) {
            flush(&mut line, svg);
            last = None;
        }
        previous = Some((x, y));
        let p = view.px(x, y);
        // Points closer than half a pixel add nothing but bytes.
        if last.is_some_and(|l: (f64, f64)| (l.0 - p.0).hypot(l.1 - p.1) < 0.5) {
            continue;
        }
        let _ = write!(line, "{:.1},{:.1} ", p.0, p.1);
        last = Some(p);
    }
    flush(&mut line, svg);
}

/// The rows the car's outline is drawn at: evenly in distance while it moves, at most
/// [`OUTLINES`], and the last.
fn outline_rows(trace: &[TraceRow]) -> Vec<usize> {
    let Some(last) = trace.len().checked_sub(1) else {
        return Vec::new();
    };
    let total = trace[last].distance_m - trace[0].distance_m;
    let mut rows = Vec::new();
    if total > 1.0 {
        let spacing = total / OUTLINES as f64;
        let mut next = trace[0].distance_m;
        for (i, row) in trace.iter().enumerate() {
            if row.distance_m >= next {
                rows.push(i);
                next += spacing;
            }
        }
    } else {
        rows.push(0);
    }
    if rows.last() != Some(&last) {
        rows.push(last);
    }
    rows
}

fn outline_spacing_text(trace: &[TraceRow]) -> String {
    let total = trace
        .last()
        .zip(trace.first())
        .map_or(0.0, |(l, f)| l.distance_m - f.distance_m);
    if total > 1.0 {
        format!("{:.0} m", total / OUTLINES as f64)
    } else {
        "moment (it stood)".to_string()
    }
}

fn draw_outlines(svg: &mut String, trace: &[TraceRow], body: &Body, view: &View) {
    let rows = outline_rows(trace);
    for (k, &i) in rows.iter().enumerate() {
        let row = &trace[i];
        if !(row.x_m.is_finite() && row.y_m.is_finite() && row.heading_rad.is_finite()) {
            continue;
        }
        let last = k + 1 == rows.len();
        let (sin, cos) = row.heading_rad.sin_cos();
        let corner = |ax: f64, ay: f64| {
            view.px(row.x_m + ax * cos - ay * sin, row.y_m + ax * sin + ay * cos)
        };
        let (front, rear) = (body.cg_to_front, body.cg_to_front - body.length);
        let half = body.width / 2.0;
        let shape = [
            corner(front, half),
            corner(front, -half),
            corner(rear, -half),
            corner(rear, half),
        ];
        let points: String = shape
            .iter()
            .map(|(x, y)| format!("{x:.1},{y:.1} "))
            .collect();
        let (stroke, fill) = if last {
            ("#c0392b", "#c0392b")
        } else {
            ("#555555", "#ffffff")
        };
        let _ = writeln!(
            svg,
            r##"<polygon points="{points}" fill="{fill}" fill-opacity="0.35" stroke="{stroke}" stroke-width="1"><title>t = {:.2} s, {:.1} km/h, heading {:.1}°</title></polygon>"##,
            row.t_s,
            row.speed_kmh,
            row.heading_rad.to_degrees()
        );
        // The wheels, the front ones turned by the road-wheel angle.
        let steer = (row.steering_deg / body.steering_ratio).to_radians();
        for (w, &(wx, wy)) in body.wheels.iter().enumerate() {
            let angle = if w < 2 { steer } else { 0.0 };
            let (s, c) = angle.sin_cos();
            let (half_len, half_w) = (0.31, 0.11);
            let wheel: String = [
                (half_len, half_w),
                (half_len, -half_w),
                (-half_len, -half_w),
                (-half_len, half_w),
            ]
            .iter()
            .map(|&(lx, ly)| {
                let (x, y) = corner(wx + lx * c - ly * s, wy + lx * s + ly * c);
                format!("{x:.1},{y:.1} ")
            })
            .collect();
            let _ = writeln!(
                svg,
                r##"<polygon points="{wheel}" fill="{stroke}" stroke="none"/>"##
            );
        }
        if k == 0 || last {
            let (px, py) = corner(front + 1.5, 0.0);
            let _ = writeln!(
                svg,
                r##"<text x="{px:.1}" y="{py:.1}" font-size="11" fill="{stroke}">{:.1} s</text>"##,
                row.t_s
            );
        }
    }
}

/// A scale bar of a round length, bottom left.
fn draw_scale(svg: &mut String, view: &View, total_h: f64) {
    let target_m = 120.0 / view.scale;
    let magnitude = 10f64.powf(target_m.log10().floor());
    let length_m = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|k| k * magnitude)
        .rfind(|&m| m <= target_m)
        .unwrap_or(magnitude);
    let (x, y) = (MARGIN_PX, total_h - 16.0);
    let px = length_m * view.scale;
    let _ = writeln!(
        svg,
        r##"<path d="M{x:.1},{:.1} v6 h{px:.1} v-6" fill="none" stroke="#222" stroke-width="1.5"/>
<text x="{:.1}" y="{:.1}">{} m</text>"##,
        y - 6.0,
        x + px + 6.0,
        y,
        length_m
    );
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
