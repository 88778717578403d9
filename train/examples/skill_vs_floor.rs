//! How far a skill is from what the arm can reach: per goal of the paper's box (section IV-A),
//! the skill's final errors set against a Jacobian controller's (the damped least-squares step
//! of `kumi_policies::kinematics::damped_step_rad`, iterated within the joint limits) from the
//! same start, and from the best of 16 random starts; and, of the goals the controller reaches
//! from the same start while the skill ends more than 7 cm away, on how many the skill left a
//! joint at its limit.
//!
//! `cargo run --release -p kumi-train --example skill_vs_floor -- SKILL.onnx [GOALS]`
//! (rapier; MuJoCo with `--features kumi-worlds/mujoco` and `KUMI_ENGINE=mujoco`).
//!
//! In place of `SKILL.onnx`, `step:GAIN` runs a step follower through the same physics: at
//! every control step it commands GAIN times the joint step the skill observes (as increments,
//! clipped to the skill's largest), what a skill that had learnt to follow its step would do.

use std::sync::Arc;

use kumi_model::{assemble, load_morphology, ModuleLibrary};
use kumi_policies::kinematics::{
    damped_step_rad, ToolKinematics, STEP_ORIENTATION_WEIGHT_M_PER_RAD,
};
use kumi_policies::observation::{Goal, JOINTS, OBSERVATION_DIM, TOOL_DIM};
use kumi_policies::rotation::orientation_error;
use kumi_policies::skill::ArmSkill;
use kumi_runtime::{BackendChoice, SkillPolicy};
use kumi_train::arm_reach::{ArmReach, ArmReachConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

type Angles = [f64; JOINTS];
/// Position [m] and orientation [rad] errors.
type Errors = (f64, f64);

/// The Jacobian controller run to rest from `start`.
fn jacobian_controller(
    fk: &ToolKinematics,
    limits: &[(f64, f64); JOINTS],
    goal: &Goal,
    start: Angles,
) -> Errors {
    let tool_pose_b = |q: &Angles| fk.tool_pose_b(q);
    let mut q = start;
    for _ in 0..400 {
        let step = damped_step_rad(&tool_pose_b, limits, &q, goal);
        q = std::array::from_fn(|j| (q[j] + step[j]).clamp(limits[j].0, limits[j].1));
    }
    let pose = fk.tool_pose_b(&q);
    (
        (goal.position_b - pose.translation.vector).norm(),
        orientation_error(&goal.orientation_b, &pose.rotation),
    )
}

/// What acts on the arm: a skill, or a follower of the observed step with its gain.
enum Actor {
    Skill(SkillPolicy),
    StepFollower { gain: f64, skill: ArmSkill },
}

impl Actor {
    fn act(
        &mut self,
        obs: &[f32; OBSERVATION_DIM],
    ) -> Result<[f32; JOINTS], Box<dyn std::error::Error>> {
        Ok(match self {
            Actor::Skill(policy) => policy.act(obs)?,
            Actor::StepFollower { gain, skill } => std::array::from_fn(|j| {
                (*gain * f64::from(obs[TOOL_DIM + j]) / skill.increment_scale[j]) as f32
            }),
        })
    }
}

struct Row {
    skill: Errors,
    local: Errors,
    global: Errors,
    /// The joints within 0.02 rad of a limit where the skill ended the goal.
    at_limit: Vec<usize>,
}

fn report(name: &str, rows: &[&Row]) {
    let mean =
        |f: &dyn Fn(&Row) -> f64| rows.iter().map(|r| f(r)).sum::<f64>() / rows.len().max(1) as f64;
    println!(
        "| {name} | {} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} |",
        rows.len(),
        mean(&|r| r.skill.0),
        mean(&|r| r.skill.1),
        mean(&|r| r.local.0),
        mean(&|r| r.local.1),
        mean(&|r| r.global.0),
        mean(&|r| r.global.1),
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(
        args.get(1)
            .ok_or("usage: skill_vs_floor SKILL.onnx [GOALS]")?,
    );
    let goals: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(300);
    let engine = std::env::var("KUMI_ENGINE")
        .unwrap_or_else(|_| "rapier".into())
        .parse()?;
    let library = ModuleLibrary::shipped();
    let model = Arc::new(assemble(&load_morphology("arm", &library)?, &library));
    let arm = &model.modules[0];
    let fk = ToolKinematics::new(&model, arm)?;
    let limits: Vec<_> = arm.position_joints().map(|a| (a.lower, a.upper)).collect();
    let limits: [(f64, f64); JOINTS] = std::array::from_fn(|j| limits[j]);
    let config = ArmReachConfig {
        engine,
        ..ArmReachConfig::default()
    };
    let mut env = ArmReach::new(model.clone(), config, 7)?;
    let skill = ArmSkill::new(arm, 30.0)?;
    let mut policy = match path.to_str().and_then(|p| p.strip_prefix("step:")) {
        Some(gain) => Actor::StepFollower {
            gain: gain.parse()?,
            skill: skill.clone(),
        },
        None => Actor::Skill(SkillPolicy::load(&path, &skill, BackendChoice::Tract)?),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut rows = Vec::new();
    let mut obs = env.reset();
    let mut start: Angles = std::array::from_fn(|j| env.world().joint_positions()[j]);
    while rows.len() < goals {
        let goal = env.goal();
        let out = env.step(&policy.act(&obs)?);
        obs = out.observation;
        if !out.goal_ended {
            continue;
        }
        let mut global = (f64::INFINITY, f64::INFINITY);
        for _ in 0..16 {
            let s: Angles = std::array::from_fn(|j| rng.random_range(limits[j].0..limits[j].1));
            let e = jacobian_controller(&fk, &limits, &goal, s);
            let cost = |e: Errors| e.0 + STEP_ORIENTATION_WEIGHT_M_PER_RAD * e.1;
            if cost(e) < cost(global) {
                global = e;
            }
        }
        let q = env.world().joint_positions();
        let at_limit = (0..JOINTS)
            .filter(|&j| (q[j] - limits[j].0).min(limits[j].1 - q[j]) < 0.02)
            .collect();
        rows.push(Row {
            skill: (out.position_error, out.orientation_error),
            local: jacobian_controller(&fk, &limits, &goal, start),
            global,
            at_limit,
        });
        if out.truncated {
            obs = env.reset();
        }
        start = std::array::from_fn(|j| env.world().joint_positions()[j]);
    }
    println!(
        "{} on {engine}, {goals} goals of the paper's box",
        path.display()
    );
    println!("\n| goals | n | skill: position [m] / orientation [rad] | Jacobian controller, same start | best of 16 starts |\n|---|---|---|---|---|");
    let all: Vec<&Row> = rows.iter().collect();
    let select =
        |f: &dyn Fn(&Row) -> bool| all.iter().copied().filter(|r| f(r)).collect::<Vec<_>>();
    let reached = |e: Errors| e.0 < 0.01 && e.1 < 0.05;
    report("all", &all);
    report(
        "pose reachable (best start within 1 cm, 0.05 rad)",
        &select(&|r| reached(r.global)),
    );
    report("pose out of reach", &select(&|r| !reached(r.global)));
    report(
        "reached from the same start",
        &select(&|r| reached(r.local)),
    );
    report(
        "not reached from the same start",
        &select(&|r| !reached(r.local)),
    );
    let stuck = select(&|r| reached(r.local) && r.skill.0 > 0.07);
    let mut per_joint = [0; JOINTS];
    for j in stuck.iter().flat_map(|r| &r.at_limit) {
        per_joint[*j] += 1;
    }
    println!(
        "\nthe skill ends more than 7 cm away from {} goals the controller reaches from the same start; on {} of them a joint ends within 0.02 rad of its limit (per joint 1-7: {per_joint:?})",
        stuck.len(),
        stuck.iter().filter(|r| !r.at_limit.is_empty()).count(),
    );
    let mut p: Vec<f64> = rows.iter().map(|r| r.skill.0).collect();
    p.sort_by(f64::total_cmp);
    let at = |q: f64| p[((p.len() - 1) as f64 * q).round() as usize];
    println!(
        "\nskill position error quantiles [m]: p10 {:.3}, p25 {:.3}, median {:.3}, p75 {:.3}, p90 {:.3}",
        at(0.1),
        at(0.25),
        at(0.5),
        at(0.75),
        at(0.9)
    );
    Ok(())
}
