//! A top-down plot of a run as SVG, drawn here (no plotting crate): paths as polylines,
//! targets as circles with a heading tick, axes in metres with a grid, a legend. Pure.

use std::fmt::Write;

/// One path to draw: a label for the legend, a colour, points [m] in the plane.
pub struct Path {
    pub label: String,
    pub colour: &'static str,
    pub points: Vec<[f64; 2]>,
}

/// A target: position [m] in the plane and heading [rad].
pub struct Mark {
    pub label: String,
    pub xy: [f64; 2],
    pub yaw: f64,
}

/// The colours of a figure's series, in turn: matplotlib's tab10 without its red, which marks
/// targets, and its grey ([`GREY`]), then two of tab20b's blues.
pub const SERIES: [&str; 10] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22", "#17becf",
    "#393b79", "#6b6ecf",
];
/// The colour of a target (a [`Mark`]).
pub const TARGET: &str = "#d62728";
/// The colour of what stands behind the series: a limit, the base under a tool's path.
pub const GREY: &str = "#7f7f7f";

const SIZE_PX: f64 = 640.0;
const MARGIN_PX: f64 = 48.0;

/// The SVG document: `title` on top, the paths and marks in a square frame scaled to fit them
/// all (with 0.5 m around), x to the right and y up.
pub fn top_down(title: &str, paths: &[Path], marks: &[Mark]) -> String {
    let all = paths
        .iter()
        .flat_map(|p| p.points.iter().copied())
        .chain(marks.iter().map(|m| m.xy))
        .filter(|p| p.iter().all(|v| v.is_finite()));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all {
        for i in 0..2 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    if !lo[0].is_finite() {
        (lo, hi) = ([-1.0; 2], [1.0; 2]);
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1.0;
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let origin = [centre[0] - span / 2.0, centre[1] - span / 2.0];
    let scale = (SIZE_PX - 2.0 * MARGIN_PX) / span;
    let px = |p: [f64; 2]| {
        (
            MARGIN_PX + (p[0] - origin[0]) * scale,
            SIZE_PX - MARGIN_PX - (p[1] - origin[1]) * scale,
        )
    };
    let mut svg = svg_open(SIZE_PX, SIZE_PX, title);
    // Grid every metre (every 0.5 m for small spans).
    let step = if span > 4.0 { 1.0 } else { 0.5 };
    let mut g = (origin[0] / step).ceil() * step;
    while g <= origin[0] + span {
        let (x, _) = px([g, origin[1]]);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{MARGIN_PX}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{g}</text>"##,
            SIZE_PX - MARGIN_PX,
            SIZE_PX - MARGIN_PX + 16.0
        );
        g += step;
    }
    let mut g = (origin[1] / step).ceil() * step;
    while g <= origin[1] + span {
        let (_, y) = px([origin[0], g]);
        let _ = writeln!(
            svg,
            r##"<line x1="{MARGIN_PX}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{g}</text>"##,
            SIZE_PX - MARGIN_PX,
            MARGIN_PX - 6.0,
            y + 4.0
        );
        g += step;
    }
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="{}" text-anchor="middle">x [m]</text><text x="14" y="{}" transform="rotate(-90 14 {})" text-anchor="middle">y [m]</text>"#,
        SIZE_PX / 2.0,
        SIZE_PX - 8.0,
        SIZE_PX / 2.0,
        SIZE_PX / 2.0
    );
    for path in paths {
        let points: Vec<String> = path
            .points
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|&p| {
                let (x, y) = px(p);
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let _ = writeln!(
            svg,
            r#"<polyline fill="none" stroke="{}" stroke-width="2" points="{}"/>"#,
            path.colour,
            points.join(" ")
        );
    }
    for mark in marks {
        let (x, y) = px(mark.xy);
        let tip = px([
            mark.xy[0] + 0.3 * mark.yaw.cos(),
            mark.xy[1] + 0.3 * mark.yaw.sin(),
        ]);
        let _ = writeln!(
            svg,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="6" fill="none" stroke="{TARGET}" stroke-width="2"/><line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{:.1}" stroke="{TARGET}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"##,
            tip.0,
            tip.1,
            x + 8.0,
            y - 8.0,
            escape(&mark.label)
        );
    }
    for (i, path) in paths.iter().enumerate() {
        let y = MARGIN_PX + 14.0 + 16.0 * i as f64;
        let _ = writeln!(
            svg,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="3"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            MARGIN_PX + 8.0,
            y - 4.0,
            MARGIN_PX + 28.0,
            y - 4.0,
            path.colour,
            MARGIN_PX + 34.0,
            y,
            escape(&path.label)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// One box of a box plot: quartiles, whiskers at the 5th and 95th percentiles, the mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxStats {
    pub p5: f64,
    pub q1: f64,
    pub median: f64,
    pub q3: f64,
    pub p95: f64,
    pub mean: f64,
}

impl BoxStats {
    /// The statistics of `values` (non-finite ones dropped); none when nothing is left.
    pub fn of(values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        // Linear interpolation between closest ranks.
        let q = |p: f64| {
            let at = p * (v.len() - 1) as f64;
            let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
            v[lo] + (v[hi] - v[lo]) * (at - lo as f64)
        };
        Some(Self {
            p5: q(0.05),
            q1: q(0.25),
            median: q(0.5),
            q3: q(0.75),
            p95: q(0.95),
            mean: v.iter().sum::<f64>() / v.len() as f64,
        })
    }
}

/// A group of boxes side by side under one label (a morphology), each box a series (a
/// policy) with its legend colour; a missing box leaves its slot empty.
pub struct BoxGroup {
    pub label: String,
    pub boxes: Vec<Option<BoxStats>>,
}

/// A series of a chart: its legend label and colour.
pub struct Series {
    pub label: String,
    pub colour: &'static str,
}

const CHART_W_PX: f64 = 720.0;
const CHART_H_PX: f64 = 420.0;

/// A chart's frame: title, axes, y grid and labels, legend. Returns the SVG opened (close it
/// with `</svg>`) and the function from a y value to its pixel row.
fn chart_frame(
    title: &str,
    x_label: &str,
    y_label: &str,
    y_max: f64,
    series: &[Series],
) -> (String, impl Fn(f64) -> f64) {
    let (top, bottom) = (40.0, CHART_H_PX - 48.0);
    let y_max = if y_max.is_finite() && y_max > 0.0 {
        y_max
    } else {
        1.0
    };
    let y_px = move |v: f64| bottom - (v.clamp(0.0, y_max) / y_max) * (bottom - top);
    let mut svg = svg_open(CHART_W_PX, CHART_H_PX, title);
    let step = nice_step(y_max / 5.0);
    let mut g = 0.0;
    while g <= y_max + 1e-12 {
        let y = y_px(g);
        let _ = writeln!(
            svg,
            r##"<line x1="{MARGIN_PX}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            CHART_W_PX - 16.0,
            MARGIN_PX - 6.0,
            y + 4.0,
            format_tick(g)
        );
        g += step;
    }
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text><text x="14" y="{}" transform="rotate(-90 14 {})" text-anchor="middle">{}</text>"#,
        CHART_W_PX / 2.0,
        CHART_H_PX - 8.0,
        escape(x_label),
        CHART_H_PX / 2.0,
        CHART_H_PX / 2.0,
        escape(y_label)
    );
    for (i, s) in series.iter().enumerate() {
        let x = CHART_W_PX - 180.0;
        let y = top + 6.0 + 16.0 * i as f64;
        let _ = writeln!(
            svg,
            r#"<rect x="{x:.1}" y="{:.1}" width="14" height="10" fill="{}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            y - 9.0,
            s.colour,
            x + 20.0,
            y,
            escape(&s.label)
        );
    }
    (svg, y_px)
}

/// A round grid step near `raw` (1, 2 or 5 times a power of ten).
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(raw.log10().floor());
    let m = raw / power;
    power
        * if m <= 1.0 {
            1.0
        } else if m <= 2.0 {
            2.0
        } else if m <= 5.0 {
            5.0
        } else {
            10.0
        }
}

fn format_tick(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-3) {
        format!("{v:.0e}")
    } else {
        format!("{}", (v * 1e6).round() / 1e6)
    }
}

/// A box plot as SVG: per group (x axis) one box per series, whiskers at the 5th and 95th
/// percentiles, a line at the median and a dot at the mean; the y axis from 0 to the largest
/// whisker.
pub fn box_plot(title: &str, y_label: &str, series: &[Series], groups: &[BoxGroup]) -> String {
    let y_max = groups
        .iter()
        .flat_map(|g| g.boxes.iter().flatten())
        .map(|b| b.p95.max(b.mean))
        .fold(0.0, f64::max)
        * 1.1;
    let (mut svg, y_px) = chart_frame(title, "", y_label, y_max, series);
    let width = (CHART_W_PX - MARGIN_PX - 200.0) / groups.len().max(1) as f64;
    let slot = width / (series.len().max(1) as f64 + 1.0);
    for (gi, group) in groups.iter().enumerate() {
        let left = MARGIN_PX + gi as f64 * width;
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            left + width / 2.0,
            CHART_H_PX - 30.0,
            escape(&group.label)
        );
        for (si, b) in group.boxes.iter().enumerate() {
            let Some(b) = b else { continue };
            let colour = series.get(si).map_or("#333", |s| s.colour);
            let cx = left + slot * (si as f64 + 1.0);
            let half = slot * 0.35;
            let _ = writeln!(
                svg,
                r##"<line x1="{cx:.1}" y1="{:.1}" x2="{cx:.1}" y2="{:.1}" stroke="#333"/><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{colour}" fill-opacity="0.6" stroke="#333"/><line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#000" stroke-width="2"/><circle cx="{cx:.1}" cy="{:.1}" r="3" fill="#000"/>"##,
                y_px(b.p5),
                y_px(b.p95),
                cx - half,
                y_px(b.q3),
                2.0 * half,
                (y_px(b.q1) - y_px(b.q3)).max(1.0),
                cx - half,
                y_px(b.median),
                cx + half,
                y_px(b.median),
                y_px(b.mean),
            );
        }
    }
    svg.push_str("</svg>\n");
    svg
}

/// A line chart as SVG: each series' points (x, y), x from 0 to the largest x, y from 0 to
/// the largest y (or `y_max` when given); non-finite points are skipped.
pub fn line_plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(Series, Vec<[f64; 2]>)],
    y_max: Option<f64>,
) -> String {
    let finite = || {
        series
            .iter()
            .flat_map(|(_, p)| p.iter())
            .filter(|p| p[0].is_finite() && p[1].is_finite())
    };
    let x_max = finite().map(|p| p[0]).fold(0.0, f64::max).max(1e-9);
    let y_max = y_max.unwrap_or_else(|| finite().map(|p| p[1]).fold(0.0, f64::max) * 1.05);
    let legend: Vec<Series> = series
        .iter()
        .map(|(s, _)| Series {
            label: s.label.clone(),
            colour: s.colour,
        })
        .collect();
    let (mut svg, y_px) = chart_frame(title, x_label, y_label, y_max, &legend);
    let x_px = |x: f64| MARGIN_PX + x / x_max * (CHART_W_PX - MARGIN_PX - 200.0);
    let step = nice_step(x_max / 5.0);
    let mut g = 0.0;
    while g <= x_max + 1e-9 {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            x_px(g),
            CHART_H_PX - 30.0,
            format_tick(g)
        );
        g += step;
    }
    for (s, points) in series {
        let points: Vec<String> = points
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .map(|p| format!("{:.1},{:.1}", x_px(p[0]), y_px(p[1])))
            .collect();
        let _ = writeln!(
            svg,
            r#"<polyline fill="none" stroke="{}" stroke-width="2" points="{}"/>"#,
            s.colour,
            points.join(" ")
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// An SVG document opened: `width` x `height` px on white, `title` centred on top (close it
/// with `</svg>`).
fn svg_open(width: f64, height: f64, title: &str) -> String {
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="20" text-anchor="middle" font-size="14">{}</text>"#,
        width / 2.0,
        escape(title)
    );
    svg
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_and_targets_land_inside_the_frame() {
        let svg = top_down(
            "a <run>",
            &[Path {
                label: "tool".into(),
                colour: "#1f77b4",
                points: vec![[0.0, 0.0], [1.0, 2.0], [f64::NAN, 0.0]],
            }],
            &[Mark {
                label: "1".into(),
                xy: [3.0, -1.0],
                yaw: 0.5,
            }],
        );
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("a &lt;run&gt;"));
        let polyline = svg.lines().find(|l| l.starts_with("<polyline")).unwrap();
        let numbers: Vec<f64> = polyline
            .split(['"', ' ', ','])
            .filter_map(|t| t.parse().ok())
            .collect();
        assert_eq!(
            numbers.len(),
            5,
            "2 points (the NaN one dropped) and the width: {polyline}"
        );
        assert!(numbers.iter().all(|&v| (0.0..=SIZE_PX).contains(&v)));
        assert!(svg.contains("<circle"));
    }

    #[test]
    fn box_statistics_by_hand() {
        // 0..=100: quartiles at 25 and 75, whiskers at 5 and 95, mean 50; NaN dropped.
        let mut v: Vec<f64> = (0..=100).map(f64::from).collect();
        v.push(f64::NAN);
        let b = BoxStats::of(&v).unwrap();
        assert_eq!(
            (b.p5, b.q1, b.median, b.q3, b.p95, b.mean),
            (5.0, 25.0, 50.0, 75.0, 95.0, 50.0)
        );
        assert_eq!(BoxStats::of(&[f64::NAN]), None);
        // Interpolated between ranks: [1, 2] has its median at 1.5.
        assert_eq!(BoxStats::of(&[2.0, 1.0]).unwrap().median, 1.5);
    }

    #[test]
    fn charts_draw_every_box_and_line_inside_the_frame() {
        let series = || {
            vec![
                Series {
                    label: "hierarchical".into(),
                    colour: "#1f77b4",
                },
                Series {
                    label: "flat".into(),
                    colour: "#ff7f0e",
                },
            ]
        };
        let stats = BoxStats::of(&[0.1, 0.2, 0.3, 0.4]);
        let svg = box_plot(
            "errors",
            "position error [m]",
            &series(),
            &[
                BoxGroup {
                    label: "minimal".into(),
                    boxes: vec![stats, stats],
                },
                BoxGroup {
                    label: "tricycle".into(),
                    boxes: vec![None, stats],
                },
            ],
        );
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert_eq!(
            svg.matches("fill-opacity").count(),
            3,
            "one box per present series"
        );
        assert!(svg.contains(">tricycle<") && svg.contains(">flat<"));
        let lines = line_plot(
            "learning",
            "env steps",
            "reward",
            &[
                (
                    series().remove(0),
                    vec![[0.0, 0.1], [1e6, 0.5], [2e6, f64::NAN]],
                ),
                (series().remove(1), vec![[0.0, 0.0], [5e5, 0.9]]),
            ],
            None,
        );
        assert_eq!(lines.matches("<polyline").count(), 2);
        for line in lines.lines().filter(|l| l.starts_with("<polyline")) {
            let numbers: Vec<f64> = line
                .split(['"', ' ', ','])
                .filter_map(|t| t.parse().ok())
                .collect();
            assert!(
                numbers.iter().all(|&v| (0.0..=CHART_W_PX).contains(&v)),
                "{line}"
            );
        }
    }
}
