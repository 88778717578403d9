//! `kumi demo`: the whole system end to end. Launches a robot (sim bridge in lockstep, an arm
//! node per arm module, the whole-body node; each its own process) on a private ROS domain,
//! sends it targets one after another as a user would (`/<robot>/goal_pose`), and reports
//! each target's final tool error and time, with a top-down plot (SVG) and a CSV of the run.
//! Needs no ROS install and no native library (tract, rapier).

use std::f64::consts::PI;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::nav_msgs::Odometry;
use kumi_msgs::std_msgs::Header;
use kumi_ros::{geometry, qos, topics, RosNode};
use kumi_terms::observation::{target_errors, tool_yaw, Target};
use kumi_terms::termination::tilt;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::launch::{self, Launch, LaunchArgs};
use crate::plot;
use crate::sim::load_model;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// `minimal`, `dragon`, `tricycle`, or a morphology file with a whole-body policy.
    pub morphology: String,
    /// How many targets, one after another.
    #[arg(long, default_value_t = 3)]
    pub targets: usize,
    /// Seed of the targets.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulated seconds per target (default: the policy's training episodes' length).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// The base tilt [rad] past which the robot has tipped over (default: the one the policy
    /// was trained with, from its metadata).
    #[arg(long)]
    pub tilt_limit_rad: Option<f64>,
    /// Where the plot, the CSV and the nodes' log go (default: runs/demo-<robot>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The ROS domain (default: a private one from this process's id, 100-199).
    #[arg(long)]
    pub domain: Option<u16>,
    /// The whole-body policy (default: the shipped one).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// The sim bridge's physics engine: rapier (default) or mujoco (built with `--features
    /// mujoco`).
    #[arg(long)]
    pub engine: Option<String>,
    /// One JSON object on stdout: {robot, targets: [{target: [x, y, z, yaw], position_error_m,
    /// yaw_error_rad, seconds, tipped_over_after_s}], skipped, plot, csv}.
    #[arg(long)]
    pub json: bool,
}

/// Where targets are drawn: within `xy_m` of the robot's base along x and y, height in `z_m`.
struct TargetRange {
    xy_m: f64,
    z_m: [f64; 2],
}

/// The targets of a run, each relative to where the base stands when it is sent ([`place`]):
/// seeded, within the range the policy was trained on (training draws each episode's target
/// around a base that starts near the origin).
fn draw_targets(n: usize, seed: u64, range: &TargetRange) -> Vec<Target> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| Target {
            position_w: Vector3::new(
                rng.random_range(-range.xy_m..range.xy_m),
                rng.random_range(-range.xy_m..range.xy_m),
                rng.random_range(range.z_m[0]..range.z_m[1]),
            ),
            yaw: rng.random_range(-PI..PI),
        })
        .collect()
}

/// A drawn target placed around the base standing at `base_xy` [m]: a target drawn around the
/// start would be out of the trained range (and refused by the whole-body node) once the robot
/// has moved.
fn place(offset: &Target, base_xy: [f64; 2]) -> Target {
    Target {
        position_w: offset.position_w + Vector3::new(base_xy[0], base_xy[1], 0.0),
        yaw: offset.yaw,
    }
}

/// One sample of the run, as the CSV has it.
struct Sample {
    t_s: f64,
    target: usize,
    /// Base x, y [m] and yaw [rad].
    base: [f64; 3],
    /// Base tilt [rad] (`kumi_terms::termination::tilt`).
    tilt_rad: f64,
    tool: Isometry3<f64>,
}

/// A robot that tipped over: during which target, and how long after it was sent [s].
struct TippedOver {
    target: usize,
    after_s: f64,
    tilt_rad: f64,
}

/// What one target came to.
#[derive(serde::Serialize)]
struct Outcome {
    target: [f64; 4],
    position_error_m: f64,
    yaw_error_rad: f64,
    /// Simulated seconds until the tool first came within 0.1 m of the target (`null`: never).
    seconds: Option<f64>,
    /// Simulated seconds until the base tilted past the policy's limit (`null`: it did not).
    tipped_over_after_s: Option<f64>,
}

#[derive(serde::Serialize)]
struct Report {
    robot: String,
    targets: Vec<Outcome>,
    /// Targets not sent because the robot had tipped over.
    skipped: usize,
    plot: String,
    csv: String,
}

fn target_msg(target: &Target, frame: &str) -> PoseStamped {
    let pose = Isometry3::from_parts(
        target.position_w.into(),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), target.yaw),
    );
    PoseStamped {
        header: Header {
            stamp: Default::default(),
            frame_id: frame.to_string(),
        },
        pose: geometry::pose(&pose),
    }
}

pub fn run(args: DemoArgs) -> Result<()> {
    if args.targets == 0 || args.seconds.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        bail!("--targets and --seconds must be positive");
    }
    let model = load_model(&args.morphology)?;
    let robot = model.name.clone();
    let launch_args = LaunchArgs {
        morphology: args.morphology.clone(),
        robot: Some(robot.clone()),
        lockstep: true,
        engine: args.engine.clone(),
        without: Vec::new(),
        no_whole_body: false,
        policy: args.policy.clone(),
        tilt_limit_rad: args.tilt_limit_rad,
        skill: None,
        backend: Some("tract".into()),
        hardware: None,
        profile: None,
    };
    let policy = launch::check_policy(&model, &launch_args, None)?;
    let (range, tilt_limit_rad, seconds) = match crate::whole_body::trained_task(&policy, &robot)? {
        Some((task, from)) => {
            eprintln!(
                "demo: targets within {} m of the base at heights {}-{} m, {} s each, tipped over past {} rad ({from})",
                task.target_xy_m, task.target_z_m[0], task.target_z_m[1], task.episode_s, task.tilt_limit_rad
            );
            (
                TargetRange {
                    xy_m: task.target_xy_m,
                    z_m: task.target_z_m,
                },
                Some(task.tilt_limit_rad),
                task.episode_s,
            )
        }
        None => {
            eprintln!(
                "demo: {} carries no training task (exported by an older kumi) and kumi ships no config for `{robot}`: targets within 3 m at heights 0.9-1.5 m, 12 s each, and no tilt limit unless --tilt-limit-rad gives one",
                policy.display()
            );
            (
                TargetRange {
                    xy_m: 3.0,
                    z_m: [0.9, 1.5],
                },
                None,
                12.0,
            )
        }
    };
    let tilt_limit_rad = args.tilt_limit_rad.or(tilt_limit_rad);
    let seconds = args.seconds.unwrap_or(seconds);
    let targets = draw_targets(args.targets, args.seed, &range);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("runs/demo-{robot}")));
    crate::output::ensure_dir(&out)?;
    let domain = args
        .domain
        .unwrap_or(100 + (std::process::id() % 100) as u16);
    let nodes = launch::plan(&model, &launch_args)?;
    eprintln!(
        "demo: `{robot}` on ROS domain {domain} (watch with ROS_DOMAIN_ID={domain} ros2 topic echo /{robot}/tool_pose); nodes log to {}",
        out.join("nodes.log").display()
    );
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    let mut launched = Launch::start(&nodes, Some(domain), Some(&out.join("nodes.log")))?;
    let result = drive(
        &model,
        &robot,
        domain,
        &targets,
        seconds,
        tilt_limit_rad,
        &shutdown,
        &mut launched,
    );
    launched.stop(Duration::from_secs(5));
    let (placed, samples, tipped) = result?;
    report(
        &robot,
        &placed,
        targets.len(),
        &samples,
        tipped.as_ref(),
        &out,
        args.json,
    )
}

/// Sends the targets one by one, each placed around where the base stands then, and records
/// the run; returns the targets as sent. A robot that tilts past `tilt_limit_rad` has tipped
/// over (the whole-body node stops driving it): the remaining targets are not sent.
#[allow(clippy::too_many_arguments)]
fn drive(
    model: &kumi_model::RobotModel,
    robot: &str,
    domain: u16,
    targets: &[Target],
    seconds: f64,
    tilt_limit_rad: Option<f64>,
    shutdown: &AtomicBool,
    launched: &mut Launch,
) -> Result<(Vec<Target>, Vec<Sample>, Option<TippedOver>)> {
    let mut node = RosNode::new(&format!("/{robot}"), "demo", domain)?;
    let publisher =
        node.publisher::<PoseStamped>(&topics::robot_goal_pose(robot), qos::default())?;
    let tool =
        node.strict_subscription::<PoseStamped>(&topics::tool_pose(robot), qos::default())?;
    let odom = node.strict_subscription::<Odometry>(&topics::odom(robot), qos::default())?;
    // Every node up: the whole-body node's and each arm node's outputs are discovered.
    let mut outputs = vec![topics::tool_pose(robot)];
    for m in model.modules.iter().filter(|m| m.ee_link.is_some()) {
        outputs.push(topics::joint_increments(robot, &m.name));
    }
    let deadline = Instant::now() + Duration::from_secs(120);
    while outputs.iter().any(|t| node.remote_publishers(t) == 0) {
        if let Some((name, status)) = launched.exited() {
            bail!("node `{name}` exited ({status}) during start-up; see the nodes' log");
        }
        if Instant::now() > deadline || shutdown.load(Ordering::Relaxed) {
            bail!("the nodes did not come up within 120 s; see the nodes' log");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    let frame = topics::odom_frame(robot);
    let mut samples = Vec::new();
    let mut base = [0.0; 3];
    // The base's latest tilt [rad], and the largest since the last sample: a brief tip the
    // node caught counts.
    let (mut tilt_now, mut tilt_rad) = (0.0_f64, 0.0_f64);
    let mut t_end = 0.0_f64;
    let mut tipped = None;
    let mut last_sample_at = Instant::now();
    let mut placed = Vec::new();
    for (i, offset) in targets.iter().enumerate() {
        let t_start = t_end;
        let mut sent_at = None::<Instant>;
        let mut moved = false;
        read_odometry(&odom, &mut base, &mut tilt_now, &mut tilt_rad);
        let target = &place(offset, [base[0], base[1]]);
        placed.push(*target);
        loop {
            if shutdown.load(Ordering::Relaxed) {
                bail!("interrupted");
            }
            if let Some((name, status)) = launched.exited() {
                bail!("node `{name}` exited ({status}); see the nodes' log");
            }
            // Sent until the robot answers (a target sent before the whole-body node's
            // subscription is matched would be lost); repeating it changes nothing.
            if !moved && sent_at.is_none_or(|s| s.elapsed() > Duration::from_millis(500)) {
                let _ = publisher.publish(target_msg(target, &frame));
                sent_at = Some(Instant::now());
            }
            read_odometry(&odom, &mut base, &mut tilt_now, &mut tilt_rad);
            let mut done = false;
            while let Some(msg) = tool.take() {
                let Ok((m, _)) = msg else { continue };
                let Ok(pose) = geometry::isometry(&m.pose) else {
                    continue;
                };
                let t = m.header.stamp.seconds();
                if t <= t_start {
                    continue;
                }
                moved = true;
                t_end = t_end.max(t);
                samples.push(Sample {
                    t_s: t,
                    target: i,
                    base,
                    tilt_rad,
                    tool: pose,
                });
                last_sample_at = Instant::now();
                done |= t >= t_start + seconds;
                if tipped.is_none() && tilt_limit_rad.is_some_and(|limit| tilt_rad > limit) {
                    tipped = Some(TippedOver {
                        target: i,
                        after_s: t - t_start,
                        tilt_rad,
                    });
                    done = true;
                }
                tilt_rad = tilt_now;
            }
            if last_sample_at.elapsed() > Duration::from_secs(60) {
                bail!("no tool pose from the whole-body node for 60 s (target {}); see the nodes' log", i + 1);
            }
            if done {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let last = samples.last().expect("samples of this target");
        let (p, y) = target_errors(&last.tool, target);
        eprintln!(
            "target {}: ({:.2}, {:.2}, {:.2}) m, yaw {:.2} rad -> tool {p:.3} m and {y:.2} rad away after {:.1} s",
            i + 1,
            target.position_w.x,
            target.position_w.y,
            target.position_w.z,
            target.yaw,
            last.t_s - t_start
        );
        if let Some(t) = &tipped {
            eprintln!(
                "target {}: the robot tipped over after {:.1} s (tilt {:.3} rad, past the policy's {:.3}); the whole-body node stopped driving it, and {} more target(s) are not sent",
                i + 1,
                t.after_s,
                t.tilt_rad,
                tilt_limit_rad.unwrap_or(f64::NAN),
                targets.len() - i - 1
            );
            break;
        }
    }
    Ok((placed, samples, tipped))
}

/// Takes the odometry waiting: the base's x, y and yaw, its tilt now and the largest since the
/// last sample.
fn read_odometry(
    odom: &kumi_ros::StrictSubscription<Odometry>,
    base: &mut [f64; 3],
    tilt_now: &mut f64,
    tilt_rad: &mut f64,
) {
    while let Some(msg) = odom.take() {
        if let Ok((m, _)) = msg {
            let p = m.pose.pose.position;
            let rotation = geometry::isometry(&m.pose.pose)
                .ok()
                .map(|iso| iso.rotation);
            *base = [p.x, p.y, rotation.map_or(0.0, |r| tool_yaw(&r))];
            *tilt_now = rotation.map_or(0.0, |r| tilt(&r));
            *tilt_rad = tilt_rad.max(*tilt_now);
        }
    }
}

/// Writes the CSV and the plot; prints the table (or the JSON object).
fn report(
    robot: &str,
    targets: &[Target],
    drawn: usize,
    samples: &[Sample],
    tipped: Option<&TippedOver>,
    out: &std::path::Path,
    json: bool,
) -> Result<()> {
    let csv_path = out.join("run.csv");
    let mut csv = String::from(
        "t_s,target,target_x_m,target_y_m,target_z_m,target_yaw_rad,base_x_m,base_y_m,base_yaw_rad,base_tilt_rad,tool_x_m,tool_y_m,tool_z_m,tool_yaw_rad,position_error_m,yaw_error_rad\n",
    );
    let mut outcomes = Vec::new();
    for (i, target) in targets.iter().enumerate() {
        let mine: Vec<&Sample> = samples.iter().filter(|s| s.target == i).collect();
        let start = mine.first().map_or(0.0, |s| s.t_s);
        let mut reached = None;
        for s in &mine {
            let (p, y) = target_errors(&s.tool, target);
            if p < 0.1 && reached.is_none() {
                reached = Some(s.t_s - start);
            }
            let t = s.tool.translation.vector;
            csv.push_str(&format!(
                "{:.4},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}\n",
                s.t_s,
                i + 1,
                target.position_w.x,
                target.position_w.y,
                target.position_w.z,
                target.yaw,
                s.base[0],
                s.base[1],
                s.base[2],
                s.tilt_rad,
                t.x,
                t.y,
                t.z,
                tool_yaw(&s.tool.rotation),
                p,
                y
            ));
        }
        let (p, y) = mine
            .last()
            .map_or((f64::NAN, f64::NAN), |s| target_errors(&s.tool, target));
        outcomes.push(Outcome {
            target: [
                target.position_w.x,
                target.position_w.y,
                target.position_w.z,
                target.yaw,
            ],
            position_error_m: p,
            yaw_error_rad: y,
            seconds: reached,
            tipped_over_after_s: tipped.filter(|t| t.target == i).map(|t| t.after_s),
        });
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    let svg_path = out.join("run.svg");
    let svg = plot::top_down(
        &format!("kumi demo: {robot}, top view"),
        &[
            plot::Path {
                label: "base".into(),
                colour: plot::GREY,
                points: samples.iter().map(|s| [s.base[0], s.base[1]]).collect(),
            },
            plot::Path {
                label: "tool".into(),
                colour: plot::SERIES[0],
                points: samples
                    .iter()
                    .map(|s| [s.tool.translation.x, s.tool.translation.y])
                    .collect(),
            },
        ],
        &targets
            .iter()
            .enumerate()
            .map(|(i, t)| plot::Mark {
                label: format!("{}", i + 1),
                xy: [t.position_w.x, t.position_w.y],
                yaw: t.yaw,
            })
            .collect::<Vec<_>>(),
    );
    std::fs::write(&svg_path, svg).with_context(|| format!("writing {}", svg_path.display()))?;
    let report = Report {
        robot: robot.to_string(),
        targets: outcomes,
        skipped: drawn - targets.len(),
        plot: svg_path.display().to_string(),
        csv: csv_path.display().to_string(),
    };
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("| target | x, y, z [m] | yaw [rad] | final position error [m] | final yaw error [rad] | within 0.1 m after [s] | tipped over after [s] |");
        println!("|---|---|---|---|---|---|---|");
        for (i, o) in report.targets.iter().enumerate() {
            println!(
                "| {} | {:.2}, {:.2}, {:.2} | {:.2} | {:.3} | {:.2} | {} | {} |",
                i + 1,
                o.target[0],
                o.target[1],
                o.target[2],
                o.target[3],
                o.position_error_m,
                o.yaw_error_rad,
                o.seconds.map_or("never".into(), |s| format!("{s:.1}")),
                o.tipped_over_after_s
                    .map_or("-".into(), |s| format!("{s:.1}"))
            );
        }
        if report.skipped > 0 {
            println!(
                "{} target(s) not sent: the robot had tipped over",
                report.skipped
            );
        }
        println!("plot: {}\ncsv: {}", report.plot, report.csv);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_are_seeded_and_inside_the_trained_range() {
        let range = TargetRange {
            xy_m: 3.0,
            z_m: [0.9, 1.5],
        };
        let a = draw_targets(20, 4, &range);
        assert_eq!(a.len(), 20);
        assert!(a.iter().all(|t| t.position_w.x.abs() <= 3.0
            && t.position_w.y.abs() <= 3.0
            && (0.9..1.5).contains(&t.position_w.z)
            && t.yaw.abs() <= PI));
        let b = draw_targets(20, 4, &range);
        assert_eq!(a[7].position_w, b[7].position_w);
        assert_ne!(draw_targets(1, 5, &range)[0].position_w, a[0].position_w);
    }

    #[test]
    fn each_target_is_placed_around_where_the_base_stands() {
        let offset = Target {
            position_w: Vector3::new(2.5, -3.0, 1.2),
            yaw: 0.4,
        };
        let t = place(&offset, [4.0, 1.0]);
        assert_eq!(t.position_w, Vector3::new(6.5, -2.0, 1.2));
        assert_eq!(t.yaw, 0.4);
        // However far the robot has gone, the target is as far from it as training's are
        // from a base starting at the origin: within the whole-body node's 4.5 m.
        let range = TargetRange {
            xy_m: 3.0,
            z_m: [0.9, 1.5],
        };
        for offset in draw_targets(200, 11, &range) {
            let t = place(&offset, [-7.0, 5.0]);
            let d = (t.position_w.x + 7.0).hypot(t.position_w.y - 5.0);
            assert!(d <= 3.0 * 2f64.sqrt() && d < 4.5, "{d}");
        }
    }
}
