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
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{SIZE_PX}" height="{SIZE_PX}" viewBox="0 0 {SIZE_PX} {SIZE_PX}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="20" text-anchor="middle" font-size="14">{}</text>"#,
        SIZE_PX / 2.0,
        escape(title)
    );
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
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="6" fill="none" stroke="#d62728" stroke-width="2"/><line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{:.1}" stroke="#d62728" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"##,
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
}
