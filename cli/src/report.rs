//! `kumi report`: reports computed from the shipped configs and models.
//!
//! `goal-bounds`: where the upper level may send each arm module's goals (its home tool pose
//! plus the bounds of the whole-body config's `[action]`), against where the frozen skill was
//! trained to reach (the `[goals]` of its training config: the paper's box and the working
//! poses). A goal far from every training goal asks the skill for what it never learnt.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use kumi_model::{assemble, load_morphology, ModuleLibrary};
use kumi_policies::goal::GoalRange;
use kumi_policies::goals::GoalDistribution;
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{Goal, JOINTS};
use kumi_terms::action::ActionTerms;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

#[derive(Subcommand)]
pub enum ReportCommand {
    /// Each arm module's goal bounds against the skill's training goals.
    GoalBounds(GoalBoundsArgs),
    /// The paper's comparison: every shipped hierarchical, flat and penalty policy evaluated
    /// side by side, with box plots, Table VI and learning curves (writes reports/compare).
    Compare(crate::compare::CompareArgs),
}

#[derive(Args)]
pub struct GoalBoundsArgs {
    /// Robots to report: shipped names or morphology files; their whole-body configs give the
    /// bounds.
    #[arg(long, value_delimiter = ',', default_value = "minimal,dragon,tricycle")]
    pub morphologies: Vec<String>,
    /// The whole-body config giving the bounds (default: each robot's shipped one), for one
    /// robot only: a robot that is not shipped needs its own.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The skill's training config, whose `[goals]` are the training goals (default: shipped).
    #[arg(long)]
    pub skill_config: Option<PathBuf>,
    /// Goals drawn per module from its bounds, and training goals drawn to compare with.
    #[arg(long, default_value_t = 2000)]
    pub samples: usize,
    /// Write the markdown report here as well.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of markdown.
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: ReportCommand) -> Result<()> {
    match command {
        ReportCommand::GoalBounds(args) => goal_bounds(args),
        ReportCommand::Compare(args) => crate::compare::run(args),
    }
}

/// Distances [m] and angles [rad] from a module's goals to the nearest training goal.
#[derive(Debug, Clone, serde::Serialize)]
struct Coverage {
    robot: String,
    module: String,
    role: String,
    home_position_m: [f64; 3],
    position_bound_m: f64,
    rotation_bound_rad: f64,
    /// Whether the skill's working poses include this module's home (else only other centres).
    own_working_poses: bool,
    in_paper_box: f64,
    nearest_m: Quantiles,
    nearest_angle_rad: Quantiles,
    /// The same for training goals held out: the spacing of the training goals themselves.
    training_nearest_m: Quantiles,
    training_nearest_angle_rad: Quantiles,
}

#[derive(Debug, Clone, serde::Serialize)]
struct Quantiles {
    median: f64,
    p90: f64,
    max: f64,
}

fn quantiles(mut v: Vec<f64>) -> Quantiles {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Quantiles {
        median: at(0.5),
        p90: at(0.9),
        max: at(1.0),
    }
}

fn inside(range: &GoalRange, p: &Vector3<f64>) -> bool {
    (0..3).all(|i| p[i] >= range.position_min[i] && p[i] <= range.position_max[i])
}

/// The training goal nearest to `goal`, by position plus 0.1 m per radian of orientation:
/// (distance [m], angle [rad]) to it.
fn nearest(goal: &Goal, training: &[Goal]) -> (f64, f64) {
    training
        .iter()
        .map(|t| {
            let d = (t.position_b - goal.position_b).norm();
            let a = t.orientation_b.angle_to(&goal.orientation_b);
            (d + 0.1 * a, d, a)
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, d, a)| (d, a))
        .unwrap_or((f64::INFINITY, f64::INFINITY))
}

fn goal_bounds(args: GoalBoundsArgs) -> Result<()> {
    anyhow::ensure!(args.samples > 0, "--samples must be positive");
    anyhow::ensure!(
        args.config.is_none() || args.morphologies.len() == 1,
        "--config gives one robot's bounds: name one robot with --morphologies"
    );
    if let Some(out) = &args.out {
        crate::output::check_file(out, "--out")?;
    }
    let library = ModuleLibrary::shipped();
    let goals = crate::train::read_config(args.skill_config.as_deref())?.goals;
    let distribution: GoalDistribution = goals.resolve().map_err(anyhow::Error::msg)?;
    let arm = assemble(&load_morphology("arm", &library)?, &library);
    let fk = ToolKinematics::new(&arm, &arm.modules[0]).map_err(anyhow::Error::msg)?;
    let limits: [(f64, f64); JOINTS] = std::array::from_fn(|j| {
        let a = arm.modules[0].actuators[j].clone();
        (a.lower, a.upper)
    });
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let tool = |q: &[f64; JOINTS]| fk.tool_pose_b(q);
    let paper = distribution.paper_box;
    let reference = args.samples * 10;
    let mut rows = Vec::new();
    for morphology in &args.morphologies {
        let model = assemble(&load_morphology(morphology, &library)?, &library);
        let robot = &model.name;
        let config = crate::train::body_config_for(
            &model,
            args.config.as_deref(),
            crate::train::Variant::Hierarchical,
            false,
        )?
        .config;
        let terms = ActionTerms::new(&model, &config.goal_bounds()?)
            .with_context(|| format!("the action terms of {robot}"))?;
        for term in terms.arms() {
            let home: Vec<f64> = model
                .module(&term.module)
                .map(|m| m.home.clone())
                .unwrap_or_default();
            let centre = distribution.centres.iter().position(|c| c[..] == home[..]);
            // What the skill met around this module: the paper's box, and the working poses
            // around this module's home (all centres when it has none of its own).
            let draw = |rng: &mut ChaCha8Rng| match centre {
                Some(c) if rng.random::<f64>() >= distribution.paper_box_weight => {
                    distribution.sample_around(rng, c, &limits, &tool)
                }
                Some(_) => distribution.paper_box.sample(rng),
                None => distribution.sample(rng, &limits, &tool),
            };
            let training: Vec<Goal> = (0..reference).map(|_| draw(&mut rng)).collect();
            let held_out: Vec<Goal> = (0..args.samples).map(|_| draw(&mut rng)).collect();
            let goals: Vec<Goal> = (0..args.samples)
                .map(|_| {
                    let action: Vec<f32> = (0..term.width())
                        .map(|_| rng.random_range(-1.0f32..=1.0))
                        .collect();
                    term.goal(&action)
                })
                .collect();
            let distances = |goals: &[Goal]| -> (Vec<f64>, Vec<f64>) {
                goals.par_iter().map(|g| nearest(g, &training)).unzip()
            };
            let (d, a) = distances(&goals);
            let (d_ref, a_ref) = distances(&held_out);
            let n = goals.len() as f64;
            let home = term.home_tool_b.translation.vector;
            rows.push(Coverage {
                robot: robot.clone(),
                module: term.module.clone(),
                role: term.role.as_str().to_string(),
                own_working_poses: centre.is_some(),
                home_position_m: [home.x, home.y, home.z],
                position_bound_m: term.position_scale_m,
                rotation_bound_rad: term.rotation_scale_rad,
                in_paper_box: goals
                    .iter()
                    .filter(|g| inside(&paper, &g.position_b))
                    .count() as f64
                    / n,
                nearest_m: quantiles(d),
                nearest_angle_rad: quantiles(a),
                training_nearest_m: quantiles(d_ref),
                training_nearest_angle_rad: quantiles(a_ref),
            });
        }
    }
    let source = args.skill_config.as_ref().map_or_else(
        || "train/configs/arm_reach.toml".to_string(),
        |p| p.display().to_string(),
    );
    let markdown = markdown(&rows, &goals, &source, args.samples);
    if let Some(out) = &args.out {
        std::fs::write(out, &markdown).with_context(|| format!("writing {}", out.display()))?;
        eprintln!("report in {}", out.display());
    }
    if args.json {
        println!("{}", serde_json::json!({ "modules": rows }));
    } else {
        print!("{markdown}");
    }
    Ok(())
}

fn markdown(
    rows: &[Coverage],
    goals: &kumi_train::arm_reach::GoalConfig,
    source: &str,
    samples: usize,
) -> String {
    let mut out = format!(
        "# Goal bounds against the skill's training goals\n\n\
         Generated by `kumi report goal-bounds` (here with `--samples {samples}`).\n\n\
         For each arm module of each robot: its home tool pose (module base frame), the bounds \
         of the whole-body config's `[action]` around it (position along each axis, rotation), \
         and how far {samples} goals drawn uniformly within those bounds lie from the nearest \
         of {} training goals of the skill around that module: the paper's box with weight {}, \
         otherwise working poses within +-{} rad of the module's home angles (the `[goals]` of \
         `{source}`, whose working configurations are the arm modules of {}). Nearest is by position plus 0.1 m per radian of orientation. The same figures \
         for {samples} training goals held out give the spacing of the training goals \
         themselves: a module whose goals lie as close as those is inside what the skill \
         learnt.\n\n\
         | robot | module | role | home tool position [m] | bounds [m, rad] | in the paper's box | nearest training goal [m] median / p90 / max | held-out training goals [m] median / p90 / max | angle to it [rad] median / p90 (held out) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        10 * samples,
        goals.paper_box_weight,
        goals.spread_rad,
        goals.working_configurations.join(", ")
    );
    for r in rows {
        let q = |q: &Quantiles| format!("{:.3} / {:.3} / {:.3}", q.median, q.p90, q.max);
        out += &format!(
            "| {} | {}{} | {} | ({:.3}, {:.3}, {:.3}) | +-{:.2}, +-{:.2} | {:.0} % | {} | {} | {:.2} / {:.2} ({:.2} / {:.2}) |\n",
            r.robot,
            r.module,
            if r.own_working_poses { "" } else { " (no working poses of its own)" },
            r.role,
            r.home_position_m[0],
            r.home_position_m[1],
            r.home_position_m[2],
            r.position_bound_m,
            r.rotation_bound_rad,
            100.0 * r.in_paper_box,
            q(&r.nearest_m),
            q(&r.training_nearest_m),
            r.nearest_angle_rad.median,
            r.nearest_angle_rad.p90,
            r.training_nearest_angle_rad.median,
            r.training_nearest_angle_rad.p90,
        );
    }
    out
}
