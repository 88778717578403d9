//! The whole-body policy's evaluation (the paper's section V, Table VI): over many episodes of
//! the training task, the final tool position and yaw errors, the legs' tool orientation
//! against gravity (Eq. 5), undesired contacts and terminations. Episode `k` is seeded by
//! `(seed, k)`, so results do not depend on how many threads run them.

use std::collections::HashMap;
use std::sync::Arc;

use kumi_model::{RobotModel, Role};
use kumi_worlds::{SimWorld, GROUND};
use nalgebra::Vector3;
use rayon::prelude::*;

use crate::evaluate::{ErrorStats, EvalError};
use crate::whole_body::{WholeBody, WholeBodyConfig};

/// The result, as `kumi eval whole-body --json` prints it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BodyEvaluation {
    pub robot: String,
    pub engine: String,
    pub rollouts: usize,
    /// Final errors of the episodes that ran their full time (falls excluded).
    pub position_error_m: ErrorStats,
    pub yaw_error_rad: ErrorStats,
    /// Mean over legs of the angle between each leg tool's x axis and gravity at the end
    /// (NaN for a robot without legs).
    pub leg_orientation_rad: ErrorStats,
    /// Control steps per episode with an undesired contact.
    pub contacts_per_episode: ErrorStats,
    /// Episodes that ended by a fall (base tilt past the limit) or diverged physics.
    pub terminations: usize,
    /// Every episode's outcome, in seed order (for plots; not printed).
    #[serde(skip)]
    pub episodes: Vec<Episode>,
}

impl BodyEvaluation {
    /// The result as a markdown table.
    pub fn markdown(&self) -> String {
        let row = ErrorStats::markdown_row;
        format!(
            "| {} ({} rollouts, {}) | mean | std | median | p90 |\n|---|---|---|---|---|\n{}{}{}{}| terminations | {} of {} | | | |\n",
            self.robot,
            self.rollouts,
            self.engine,
            row("final position error [m]", &self.position_error_m),
            row("final yaw error [rad]", &self.yaw_error_rad),
            if self.leg_orientation_rad.mean.is_nan() {
                "| leg tool orientation [rad] | n/a (no legs, or no episode ended standing) | | | |\n"
                    .to_string()
            } else {
                row("leg tool orientation [rad]", &self.leg_orientation_rad)
            },
            row("undesired contacts [steps/episode]", &self.contacts_per_episode),
            self.terminations,
            self.rollouts,
        )
    }
}

/// Which contacts are undesired: an arm module's link against the ground or against a module
/// it is not mounted to. Wheel modules and passive bodies may touch anything.
pub struct ContactRule {
    module_of: HashMap<String, usize>,
    is_arm: Vec<bool>,
    /// Module pairs (by index) that are mounted on each other.
    adjacent: Vec<(usize, usize)>,
}

impl ContactRule {
    pub fn new(model: &RobotModel) -> Self {
        let index: HashMap<&str, usize> = model
            .modules
            .iter()
            .enumerate()
            .map(|(i, m)| (m.name.as_str(), i))
            .collect();
        let mut module_of = HashMap::new();
        for (i, m) in model.modules.iter().enumerate() {
            for link in &m.links {
                module_of.insert(link.clone(), i);
            }
        }
        Self {
            module_of,
            is_arm: model
                .modules
                .iter()
                .map(|m| matches!(m.role, Role::Manipulator | Role::Leg))
                .collect(),
            adjacent: model
                .modules
                .iter()
                .enumerate()
                .filter_map(|(i, m)| {
                    m.parent
                        .as_deref()
                        .and_then(|p| index.get(p))
                        .map(|&p| (p.min(i), p.max(i)))
                })
                .collect(),
        }
    }

    fn undesired(&self, a: &str, b: &str) -> bool {
        let arm_link = |link: &str| self.module_of.get(link).filter(|&&m| self.is_arm[m]);
        let check = |link: &str, other: &str| {
            let Some(&m) = arm_link(link) else {
                return false;
            };
            if other == GROUND {
                return true;
            }
            match self.module_of.get(other) {
                Some(&o) => o != m && !self.adjacent.contains(&(m.min(o), m.max(o))),
                None => false,
            }
        };
        check(a, b) || check(b, a)
    }

    /// Whether the world has an undesired contact now.
    pub fn any(&self, world: &dyn SimWorld) -> bool {
        world.contacts().iter().any(|c| self.undesired(&c.a, &c.b))
    }
}

/// The angle [rad] between each leg tool's x axis and gravity (Eq. 5's theta_i), per leg.
pub fn leg_angles(model: &RobotModel, world: &dyn SimWorld) -> Vec<f64> {
    model
        .modules_with_role(Role::Leg)
        .filter_map(|m| m.ee_link.as_deref())
        .filter_map(|link| world.link_pose(link).ok())
        .map(|pose| {
            let x = pose.rotation * Vector3::x();
            x.dot(&-Vector3::z()).clamp(-1.0, 1.0).acos()
        })
        .collect()
}

/// The mean angle [rad] between each leg tool's x axis and gravity (Eq. 5), NaN without legs.
pub fn leg_orientation(model: &RobotModel, world: &dyn SimWorld) -> f64 {
    let angles = leg_angles(model, world);
    if angles.is_empty() {
        f64::NAN
    } else {
        angles.iter().sum::<f64>() / angles.len() as f64
    }
}

/// One episode's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Episode {
    /// Final tool position error [m].
    pub position: f64,
    /// Final absolute yaw error [rad].
    pub yaw: f64,
    /// Final mean leg tool angle to gravity [rad] (NaN without legs).
    pub leg: f64,
    /// Control steps with an undesired contact.
    pub contacts: usize,
    /// Ended by a fall or diverged physics.
    pub terminated: bool,
    /// Tool position error [m] at the start.
    pub start_position: f64,
    /// The smallest tool position error [m] over the episode.
    pub closest_position: f64,
    /// Control steps it ran.
    pub steps: usize,
}

impl Episode {
    /// The header of [`Episode::csv_row`].
    pub const CSV_HEADER: &'static str = "episode,start_position_error_m,closest_position_error_m,final_position_error_m,final_yaw_error_rad,leg_orientation_rad,contact_steps,steps,fell";

    /// One CSV row, `k` the episode's index.
    pub fn csv_row(&self, k: usize) -> String {
        format!(
            "{k},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{}",
            self.start_position,
            self.closest_position,
            self.position,
            self.yaw,
            self.leg,
            self.contacts,
            self.steps,
            u8::from(self.terminated)
        )
    }
}

/// Evaluates a whole-body policy over `rollouts` episodes. `make_policy` builds one policy
/// per worker thread; a policy maps an observation to an action (or fails with a message).
pub fn evaluate_body<P, F>(
    model: Arc<RobotModel>,
    config: WholeBodyConfig,
    skill_onnx: &[u8],
    rollouts: usize,
    seed: u64,
    make_policy: F,
) -> Result<BodyEvaluation, EvalError>
where
    F: Fn() -> Result<P, String> + Sync,
    P: FnMut(&[f32]) -> Result<Vec<f32>, String>,
{
    let rule = ContactRule::new(&model);
    let episodes: Vec<Episode> = (0..rollouts)
        .into_par_iter()
        .map_init(
            || -> Result<_, EvalError> {
                let policy = make_policy().map_err(EvalError::Policy)?;
                let env = WholeBody::new(model.clone(), config.clone(), skill_onnx, seed)?;
                Ok((policy, env))
            },
            |state, k| {
                let (policy, env) = state
                    .as_mut()
                    .map_err(|e| EvalError::Policy(e.to_string()))?;
                env.reseed(seed.wrapping_mul(1_000_003).wrapping_add(k as u64));
                let mut obs = env.reset();
                let start_position = env.errors().0;
                let (mut contacts, mut closest, mut steps) = (0, start_position, 0);
                loop {
                    let action = policy(&obs).map_err(EvalError::Policy)?;
                    let out = env.step(&action);
                    contacts += usize::from(rule.any(env.world()));
                    closest = closest.min(out.position_error);
                    steps += 1;
                    if out.terminated || out.truncated {
                        return Ok(Episode {
                            position: out.position_error,
                            yaw: out.yaw_error,
                            leg: leg_orientation(&model, env.world()),
                            contacts,
                            terminated: out.terminated,
                            start_position,
                            closest_position: closest,
                            steps,
                        });
                    }
                    obs = out.observation;
                }
            },
        )
        .collect::<Result<_, EvalError>>()?;
    let finished: Vec<&Episode> = episodes.iter().filter(|e| !e.terminated).collect();
    let stats = |f: &dyn Fn(&Episode) -> f64, all: bool| {
        let values: Vec<f64> = if all {
            episodes.iter().map(f).collect()
        } else {
            finished.iter().map(|e| f(e)).collect()
        };
        ErrorStats::of(&values)
    };
    Ok(BodyEvaluation {
        robot: model.name.clone(),
        engine: config.engine.to_string(),
        rollouts,
        position_error_m: stats(&|e| e.position, false),
        yaw_error_rad: stats(&|e| e.yaw, false),
        leg_orientation_rad: stats(&|e| e.leg, false),
        contacts_per_episode: stats(&|e| e.contacts as f64, true),
        terminations: episodes.len() - finished.len(),
        episodes,
    })
}
