//! Line plots as SVG, like the report's figures: a time axis, one or two value axes, a
//! legend. Self-contained so every run can draw its figures with nothing installed.

use std::fmt::Write;

use crate::decimal;

/// Which value axis a series is drawn against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// The left axis.
    Left,
    /// The right axis.
    Right,
}

/// One line.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// (x, y) points in x order.
    pub points: Vec<(f64, f64)>,
    /// Axis it belongs to.
    pub axis: Axis,
    /// Draw as steps (for gears and on/off signals) instead of straight segments.
    pub steps: bool,
}

/// A figure.
#[derive(Clone, Debug)]
pub struct Plot {
    /// Title.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the left axis.
    pub left_label: String,
    /// Label of the right axis (used when a series is on it).
    pub right_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

const WIDTH: f64 = 900.0;
const HEIGHT: f64 = 420.0;
const MARGIN_LEFT: f64 = 70.0;
const MARGIN_RIGHT: f64 = 70.0;
const MARGIN_TOP: f64 = 40.0;
const MARGIN_BOTTOM: f64 = 55.0;
const COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// Round tick spacing: 1, 2 or 5 times a power of ten, giving about `target` ticks.
fn tick_step(span: f64, target: f64) -> f64 {
    let raw = (span / target).max(1e-12);
    let magnitude = 10f64.powf(raw.log10().floor());
    let norm = raw / magnitude;
    let nice = if norm < 1.5 {
        1.0
    } else if norm < 3.5 {
        2.0
    } else if norm < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// Axis range rounded out to ticks; a flat series gets a range around its value.
fn axis_range(values: impl Iterator<Item = f64>) -> (f64, f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0, 0.2);
    }
    if hi - lo < 1e-9 {
        lo -= 1.0;
        hi += 1.0;
    }
    let step = tick_step(hi - lo, 6.0);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn number(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    format!("{v:.decimals$}")
}

impl Plot {
    /// The figure as an SVG document.
    pub fn to_svg(&self) -> String {
        let plot_w = WIDTH - MARGIN_LEFT - MARGIN_RIGHT;
        let plot_h = HEIGHT - MARGIN_TOP - MARGIN_BOTTOM;
        let all_x = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        let (x0, x1, x_step) = axis_range(all_x);
        let on = |axis| {
            self.series
                .iter()
                .filter(move |s| s.axis == axis)
                .flat_map(|s| s.points.iter().map(|p| p.1))
        };
        let left = axis_range(on(Axis::Left));
        let has_right = self.series.iter().any(|s| s.axis == Axis::Right);
        let right = axis_range(on(Axis::Right));
        let sx = |x: f64| MARGIN_LEFT + (x - x0) / (x1 - x0) * plot_w;
        let sy = |y: f64, (lo, hi, _): (f64, f64, f64)| MARGIN_TOP + (hi - y) / (hi - lo) * plot_h;

        let mut svg = String::new();
        let _ = write!(
            svg,
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{}" y="22" text-anchor="middle" font-size="15" font-weight="bold">{}</text>
"##,
            WIDTH / 2.0,
            escape(&self.title)
        );
        // Grid and ticks.
        let mut x = x0;
        while x <= x1 + x_step * 1e-6 {
            let px = sx(x);
            let _ = writeln!(
                svg,
                r##"<line x1="{px:.1}" y1="{MARGIN_TOP}" x2="{px:.1}" y2="{:.1}" stroke="#e0e0e0"/><text x="{px:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                MARGIN_TOP + plot_h,
                MARGIN_TOP + plot_h + 16.0,
                number(x, x_step)
            );
            x += x_step;
        }
        let mut y = left.0;
        while y <= left.1 + left.2 * 1e-6 {
            let py = sy(y, left);
            let _ = writeln!(
                svg,
                r##"<line x1="{MARGIN_LEFT}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#e0e0e0"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                MARGIN_LEFT + plot_w,
                MARGIN_LEFT - 6.0,
                py + 4.0,
                number(y, left.2)
            );
            y += left.2;
        }
        if has_right {
            let mut y = right.0;
            while y <= right.1 + right.2 * 1e-6 {
                let py = sy(y, right);
                let _ = writeln!(
                    svg,
                    r##"<text x="{:.1}" y="{:.1}">{}</text>"##,
                    MARGIN_LEFT + plot_w + 6.0,
                    py + 4.0,
                    number(y, right.2)
                );
                y += right.2;
            }
        }
        let _ = writeln!(
            svg,
            r##"<rect x="{MARGIN_LEFT}" y="{MARGIN_TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#444"/>
<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>
<text transform="translate(18 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"##,
            MARGIN_LEFT + plot_w / 2.0,
            HEIGHT - 12.0,
            escape(&self.x_label),
            MARGIN_TOP + plot_h / 2.0,
            escape(&self.left_label)
        );
        if has_right {
            let _ = writeln!(
                svg,
                r##"<text transform="translate({:.1} {:.1}) rotate(90)" text-anchor="middle">{}</text>"##,
                WIDTH - 18.0,
                MARGIN_TOP + plot_h / 2.0,
                escape(&self.right_label)
            );
        }
        // Lines.
        for (i, series) in self.series.iter().enumerate() {
            let range = if series.axis == Axis::Left {
                left
            } else {
                right
            };
            // The path is most of a plot's text: its numbers go through
            // `decimal::push_fixed` (what `{:.1}` writes, faster).
            let mut path = Vec::new();
            let mut point = |command: &[u8], px: f64, py: f64| {
                path.extend_from_slice(command);
                decimal::push_fixed(&mut path, px, 1);
                path.push(b' ');
                decimal::push_fixed(&mut path, py, 1);
            };
            let mut previous: Option<(f64, f64)> = None;
            for &(x, y) in series
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
            {
                let (px, py) = (sx(x), sy(y, range));
                match previous {
                    None => point(b"M", px, py),
                    Some((_, prev_py)) if series.steps => {
                        point(b" L", px, prev_py);
                        point(b" L", px, py);
                    }
                    Some(_) => point(b" L", px, py),
                }
                previous = Some((px, py));
            }
            // Only ASCII digits, signs, points, spaces and letters went in.
            let path = String::from_utf8_lossy(&path);
            let colour = COLOURS[i % COLOURS.len()];
            let _ = writeln!(
                svg,
                r##"<path d="{path}" fill="none" stroke="{colour}" stroke-width="1.5"/>"##
            );
            let ly = MARGIN_TOP + 14.0 + 16.0 * i as f64;
            let lx = MARGIN_LEFT + 10.0;
            let suffix = if has_right && series.axis == Axis::Right {
                " (right)"
            } else {
                ""
            };
            let _ = writeln!(
                svg,
                r##"<line x1="{lx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="3"/><text x="{:.1}" y="{ly:.1}">{}{suffix}</text>"##,
                ly - 4.0,
                lx + 18.0,
                ly - 4.0,
                lx + 24.0,
                escape(&series.name)
            );
        }
        svg.push_str("</svg>\n");
        svg
    }
}
