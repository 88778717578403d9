//! `kumi eval whole-body --trace-plot DIR`: the traced episodes drawn, so that a fall can be
//! looked at rather than read out of the trace CSV. Pure: episodes in, SVG documents out.

use crate::plot::{self, line_plot, top_down, Mark, Path, Series};
use kumi_train::evaluate_body::Episode;

/// Colours of the episodes that stood, in turn.
const STOOD: [&str; 10] = plot::SERIES;
/// The colour of an episode that fell or whose physics blew up.
const FELL: &str = "#000000";
/// The colour of the tilt past which an episode ends.
const LIMIT: &str = plot::GREY;

/// The two drawings of one engine's traced episodes.
pub struct TracePlots {
    /// Top view: each episode's base path [m] in the world frame, its target as a circle with
    /// a heading tick labelled by the episode's number.
    pub paths_svg: String,
    /// The base's tilt [rad] over time [s], with the tilt that ends an episode.
    pub tilt_svg: String,
}

/// Draws the traced episodes among `episodes` (those with a trace; their numbers are their
/// places in `episodes`) of `title` (robot and engine). Time is the control step over
/// `control_hz`. An episode that fell is drawn in black and its legend says after how long; one
/// whose physics blew up says so, and its last state (the blown-up one) is left out.
pub fn trace_plots(
    title: &str,
    episodes: &[Episode],
    control_hz: f64,
    tilt_limit_rad: f64,
) -> TracePlots {
    let (mut paths, mut marks, mut tilts) = (Vec::new(), Vec::new(), Vec::new());
    let mut end_s: f64 = 0.0;
    let traced = episodes
        .iter()
        .enumerate()
        .filter(|(_, e)| !e.trace.is_empty());
    for (n, (k, e)) in traced.enumerate() {
        let (colour, label) = episode_legend(k, e, STOOD[n % STOOD.len()], control_hz);
        let trace = if e.diverged {
            &e.trace[..e.trace.len() - 1]
        } else {
            &e.trace[..]
        };
        end_s = end_s.max(trace.len().saturating_sub(1) as f64 / control_hz);
        paths.push(Path {
            label: label.clone(),
            colour,
            points: trace.iter().map(|s| [s.base[0], s.base[1]]).collect(),
        });
        let target = e.target.position_w;
        marks.push(Mark {
            label: k.to_string(),
            xy: [target.x, target.y],
            yaw: e.target.yaw,
        });
        let tilt = trace.iter().enumerate();
        let tilt = tilt.map(|(i, s)| [i as f64 / control_hz, s.tilt_rad]);
        tilts.push((Series { label, colour }, tilt.collect()));
    }
    let limit = Series {
        label: format!("fall: tilt past {tilt_limit_rad:.3} rad"),
        colour: LIMIT,
    };
    tilts.push((limit, vec![[0.0, tilt_limit_rad], [end_s, tilt_limit_rad]]));
    TracePlots {
        paths_svg: top_down(&format!("{title}: base paths and targets"), &paths, &marks),
        tilt_svg: line_plot(
            &format!("{title}: base tilt"),
            "time [s]",
            "tilt [rad]",
            &tilts,
            None,
        ),
    }
}

/// An episode's colour and legend: `stood` if it ran to its end, else black with when it
/// fell or blew up.
fn episode_legend(
    k: usize,
    e: &Episode,
    stood: &'static str,
    control_hz: f64,
) -> (&'static str, String) {
    let after_s = e.steps as f64 / control_hz;
    if e.diverged {
        (
            FELL,
            format!("episode {k}: physics blew up after {after_s:.1} s"),
        )
    } else if e.terminated {
        (FELL, format!("episode {k}: fell after {after_s:.1} s"))
    } else {
        (stood, format!("episode {k}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_terms::observation::Target;
    use kumi_train::evaluate_body::TraceStep;
    use nalgebra::Vector3;

    fn step(x: f64, tilt_rad: f64) -> TraceStep {
        TraceStep {
            base: [x, 0.5 * x, 0.0],
            tool: [x, 0.0, 1.3, 0.0],
            errors: [1.0, 0.5],
            tilt_rad,
            twist: [0.1, 0.0],
            governor_scale: 1.0,
            ground_links: vec![],
            action: vec![],
        }
    }

    fn episode(terminated: bool, tilts: &[f64]) -> Episode {
        let trace: Vec<_> = tilts
            .iter()
            .enumerate()
            .map(|(i, &t)| step(i as f64, t))
            .collect();
        Episode {
            position: 1.0,
            yaw: 0.5,
            leg: 0.0,
            contacts: 0,
            terminated,
            diverged: false,
            start_position: 2.0,
            closest_position: 0.9,
            steps: trace.len().saturating_sub(1),
            target: Target {
                position_w: Vector3::new(2.0, -1.0, 1.2),
                yaw: 0.3,
            },
            trace,
        }
    }

    #[test]
    fn falls_are_black_with_their_time_and_untraced_episodes_are_left_out() {
        let episodes = [
            episode(false, &[0.0, 0.05, 0.02]),
            episode(false, &[]), // not traced
            episode(true, &[0.0, 0.3, 0.7]),
        ];
        let plots = trace_plots("minimal on mujoco", &episodes, 2.0, 0.6);
        // One target per traced episode.
        assert_eq!(plots.paths_svg.matches("<circle").count(), 2);
        let p = &plots.paths_svg;
        assert!(
            p.contains("minimal on mujoco: base paths and targets"),
            "{p}"
        );
        assert!(p.contains(">episode 0<") && !p.contains("episode 1"), "{p}");
        // The fallen episode: 2 steps at 2 Hz.
        assert!(p.contains(">episode 2: fell after 1.0 s<"), "{p}");
        assert_eq!(
            p.matches(&format!(r#"stroke="{FELL}" stroke-width="2" points"#))
                .count(),
            1
        );
        assert_eq!(p.matches("<polyline").count(), 2, "{p}");
        let t = &plots.tilt_svg;
        assert!(t.contains("fall: tilt past 0.600 rad"), "{t}");
        assert!(t.contains("time [s]") && t.contains("tilt [rad]"), "{t}");
        // Two episodes and the limit; time runs to 1 s (the third state, at 2 Hz).
        assert_eq!(t.matches("<polyline").count(), 3, "{t}");
        assert!(t.contains(">1<") && !t.contains(">1.5<"), "{t}");
    }

    #[test]
    fn a_blown_up_episode_says_so_and_its_last_state_is_not_drawn() {
        let mut blown = episode(true, &[0.0, 0.1, 0.2]);
        blown.diverged = true;
        blown.trace[2].base = [1e12, 1e12, 0.0];
        let plots = trace_plots("tricycle on rapier", &[blown], 30.0, 0.785);
        let p = &plots.paths_svg;
        assert!(
            p.contains(">episode 0: physics blew up after 0.1 s<"),
            "{p}"
        );
        // The frame fits the states before the blow-up (x up to 1 m), not 1e12 m.
        assert!(!p.contains(">1000000000000<") && p.contains(">1<"), "{p}");
    }
}
