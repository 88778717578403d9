//! The whole-body policy's evaluation (the paper's section V, Table VI): over many episodes of
//! the training task, the final tool position and yaw errors, the legs' tool orientation
//! against gravity (Eq. 5), undesired contacts and terminations. Episode `k` is seeded by
//! `(seed, k)`, so results do not depend on how many threads run them.

use std::collections::HashMap;
use std::sync::Arc;

use kumi_model::{RobotModel, Role};
use kumi_terms::action::planar_twist;
use kumi_terms::observation::{tool_yaw, Target};
use kumi_terms::termination::tilt;
use kumi_worlds::{SimWorld, GROUND};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::evaluate::{wilson_interval_95, ErrorStats, EvalError};
use crate::whole_body::{PushConfig, WholeBody, WholeBodyConfig};

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
    /// Of the terminations, those whose physics blew up ([`SimWorld::diverged`]): their final
    /// errors and leg orientation are NaN in the episodes' CSV.
    #[serde(default)]
    pub diverged: usize,
    /// The 95 % Wilson interval of the terminations per 1000 episodes, `[low, high]`
    /// ([`BodyEvaluation::terminations_per_1000_95`]): how far a count of rare falls pins the rate.
    /// Kept for `--json`; the markdown derives it from `terminations` and `rollouts`.
    #[serde(default)]
    pub terminations_per_1000_95: Option<[f64; 2]>,
    /// Standard deviation of the Gaussian noise added to every action [policy units]; 0: the
    /// deterministic policy.
    #[serde(default)]
    pub action_noise: f64,
    /// The pushes the episodes met (`null`: none).
    #[serde(default)]
    pub push: Option<PushConfig>,
    /// Every episode's outcome, in seed order (for plots; not printed).
    #[serde(skip)]
    pub episodes: Vec<Episode>,
    /// The action values' names, for the trace's columns (not printed).
    #[serde(skip)]
    pub action_names: Vec<String>,
}

impl BodyEvaluation {
    /// The 95 % Wilson interval of the termination rate, per 1000 episodes (None without
    /// rollouts).
    pub fn terminations_per_1000_95(terminations: usize, rollouts: usize) -> Option<[f64; 2]> {
        wilson_interval_95(terminations, rollouts).map(|(lo, hi)| [1000.0 * lo, 1000.0 * hi])
    }

    /// The result as a markdown table.
    pub fn markdown(&self) -> String {
        let row = ErrorStats::markdown_row;
        format!(
            "| {} ({} rollouts, {}) | mean | std | median | p90 |\n|---|---|---|---|---|\n{}{}{}{}| terminations | {} of {}{} | | | |\n",
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
            match self.diverged {
                0 => String::new(),
                n => format!(" ({n} of them physics that blew up)"),
            },
        ) + &match Self::terminations_per_1000_95(self.terminations, self.rollouts) {
            Some([lo, hi]) => format!(
                "\nTerminations: {:.1} per 1000 episodes (95 % Wilson interval {lo:.1}-{hi:.1}).\n",
                1000.0 * self.terminations as f64 / self.rollouts as f64
            ),
            None => String::new(),
        } + &if self.action_noise > 0.0 {
            format!(
                "\nWith Gaussian noise of std {} (policy units) on every action.\n",
                self.action_noise
            )
        } else {
            String::new()
        }
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

/// One control step of a traced episode (world frame).
#[derive(Debug, Clone, PartialEq)]
pub struct TraceStep {
    /// Base position [m] and heading [rad] (of its x axis).
    pub base: [f64; 3],
    /// Tool position [m] and heading [rad].
    pub tool: [f64; 4],
    /// Tool position error [m] and absolute yaw error [rad].
    pub errors: [f64; 2],
    /// Base tilt [rad]: the angle between its z axis and the world's, by the rule a fall is
    /// judged by ([`tilt`]).
    pub tilt_rad: f64,
    /// The base's horizontal speed [m/s] and yaw rate [rad/s] in the world frame: what the
    /// turn governor reads ([`planar_twist`]).
    pub twist: [f64; 2],
    /// The turn governor's scale for this twist
    /// ([`kumi_terms::ActionTerms::governor_scale`]; 1 without a governor), which the next
    /// step's wheel commands get.
    pub governor_scale: f64,
    /// The links that touch the ground, sorted, each once ([`SimWorld::ground_contacts`]; the
    /// wheels of a robot that stands on them: a wheel missing is a wheel off the ground).
    pub ground_links: Vec<String>,
    /// The action that led here, as the policy output it (with any evaluation noise, before
    /// the terms clip it); empty at the episode's start.
    pub action: Vec<f32>,
}

impl TraceStep {
    /// The header of [`TraceStep::csv_row`] for actions of these value names
    /// ([`kumi_terms::ActionTerms::names`]).
    pub fn csv_header(action_names: &[String]) -> String {
        let actions: String = action_names
            .iter()
            .map(|n| format!(",action:{n}"))
            .collect();
        format!("episode,step,base_x_m,base_y_m,base_yaw_rad,tool_x_m,tool_y_m,tool_z_m,tool_yaw_rad,target_x_m,target_y_m,target_z_m,target_yaw_rad,position_error_m,yaw_error_rad,tilt_rad,base_speed_m_s,base_yaw_rate_rad_s,turn_governor_scale,ground_links{actions}")
    }

    fn of(env: &WholeBody, action: &[f32]) -> Self {
        let (base, tool) = (env.world().base_pose(), env.tool_pose_w());
        let (b, t) = (base.translation.vector, tool.translation.vector);
        let (position, yaw) = env.errors();
        let (linear_w, angular_w) = env.world().base_twist_w();
        let (speed_m_s, yaw_rate_rad_s) = planar_twist(&linear_w, &angular_w);
        Self {
            base: [b.x, b.y, tool_yaw(&base.rotation)],
            tool: [t.x, t.y, t.z, tool_yaw(&tool.rotation)],
            errors: [position, yaw],
            tilt_rad: tilt(&base.rotation),
            twist: [speed_m_s, yaw_rate_rad_s],
            governor_scale: env.terms().governor_scale(&linear_w, &angular_w),
            ground_links: env.world().ground_contacts(),
            action: action.to_vec(),
        }
    }

    /// One CSV row: episode `k`, step `step`, to `target`; `width` action columns (empty at
    /// the start).
    pub fn csv_row(&self, k: usize, step: usize, target: &Target, width: usize) -> String {
        let p = target.position_w;
        let mut values = self
            .base
            .iter()
            .chain(&self.tool)
            .chain(&[p.x, p.y, p.z, target.yaw])
            .chain(&self.errors)
            .chain(&[self.tilt_rad])
            .chain(&self.twist)
            .chain(&[self.governor_scale])
            .map(|v| format!("{v:.4}"))
            .collect::<Vec<_>>();
        values.push(self.ground_links.join("|"));
        values.extend((0..width).map(|i| match self.action.get(i) {
            Some(a) => format!("{a:.4}"),
            None => String::new(),
        }));
        format!("{k},{step},{}", values.join(","))
    }
}

/// One episode's outcome.
#[derive(Debug, Clone, PartialEq)]
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
    /// Ended because the physics blew up ([`SimWorld::diverged`]).
    pub diverged: bool,
    /// Tool position error [m] at the start.
    pub start_position: f64,
    /// The smallest tool position error [m] over the episode.
    pub closest_position: f64,
    /// Control steps it ran.
    pub steps: usize,
    /// Its target.
    pub target: Target,
    /// The start and the state after every step (empty unless the episode was traced).
    pub trace: Vec<TraceStep>,
}

impl Episode {
    /// The header of [`Episode::csv_row`].
    pub const CSV_HEADER: &'static str = "episode,start_position_error_m,closest_position_error_m,final_position_error_m,final_yaw_error_rad,leg_orientation_rad,contact_steps,steps,fell,diverged";

    /// One CSV row, `k` the episode's index.
    pub fn csv_row(&self, k: usize) -> String {
        format!(
            "{k},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{}",
            self.start_position,
            self.closest_position,
            self.position,
            self.yaw,
            self.leg,
            self.contacts,
            self.steps,
            u8::from(self.terminated),
            u8::from(self.diverged)
        )
    }
}

/// Which episodes to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Protocol {
    pub rollouts: usize,
    /// Episode `k` is seeded by `(seed, k)`.
    pub seed: u64,
    /// The first `traced` episodes keep every step ([`Episode::trace`]).
    pub traced: usize,
    /// Standard deviation of Gaussian noise added to every action value [policy units] before
    /// the action terms clip and scale it, as training explores; 0 runs the policy's mean.
    /// Drawn from the episode's own stream, so results do not depend on threads either.
    pub action_noise: f64,
}

/// Gaussian noise on the policy's actions, one stream per episode (apart from the stream that
/// draws the episode's start and target).
struct ActionNoise {
    std: f32,
    rng: ChaCha8Rng,
}

impl ActionNoise {
    fn new(std: f64, episode_seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(episode_seed);
        rng.set_stream(1);
        Self {
            std: std as f32,
            rng,
        }
    }

    fn add(&mut self, action: &mut [f32]) {
        if self.std > 0.0 {
            for a in action {
                let z: f32 = StandardNormal.sample(&mut self.rng);
                *a += self.std * z;
            }
        }
    }
}

/// Evaluates a whole-body policy over the protocol's episodes. `make_policy` builds one policy
/// per worker thread; a policy maps an observation to an action (or fails with a message).
pub fn evaluate_body<P, F>(
    model: Arc<RobotModel>,
    config: WholeBodyConfig,
    skill_onnx: &[u8],
    protocol: Protocol,
    make_policy: F,
) -> Result<BodyEvaluation, EvalError>
where
    F: Fn() -> Result<P, String> + Sync,
    P: FnMut(&[f32]) -> Result<Vec<f32>, String>,
{
    let Protocol {
        rollouts,
        seed,
        traced,
        action_noise,
    } = protocol;
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
                let episode_seed = seed.wrapping_mul(1_000_003).wrapping_add(k as u64);
                env.reseed(episode_seed);
                let mut noise = ActionNoise::new(action_noise, episode_seed);
                let mut obs = env.reset();
                let start_position = env.errors().0;
                let (mut contacts, mut closest, mut steps) = (0, start_position, 0);
                let mut trace = Vec::new();
                if k < traced {
                    trace.push(TraceStep::of(env, &[]));
                }
                loop {
                    let mut action = policy(&obs).map_err(EvalError::Policy)?;
                    noise.add(&mut action);
                    let out = env.step(&action);
                    if k < traced {
                        trace.push(TraceStep::of(env, &action));
                    }
                    // A world that blew up has no contacts or legs worth counting.
                    let diverged = env.world().diverged();
                    contacts += usize::from(!diverged && rule.any(env.world()));
                    closest = closest.min(out.position_error);
                    steps += 1;
                    if out.terminated || out.truncated {
                        return Ok(Episode {
                            position: out.position_error,
                            yaw: out.yaw_error,
                            leg: if diverged {
                                f64::NAN
                            } else {
                                leg_orientation(&model, env.world())
                            },
                            contacts,
                            terminated: out.terminated,
                            diverged,
                            start_position,
                            closest_position: closest,
                            steps,
                            target: env.target(),
                            trace,
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
    let terminations = episodes.len() - finished.len();
    Ok(BodyEvaluation {
        robot: model.name.clone(),
        engine: config.engine.to_string(),
        rollouts,
        position_error_m: stats(&|e| e.position, false),
        yaw_error_rad: stats(&|e| e.yaw, false),
        leg_orientation_rad: stats(&|e| e.leg, false),
        contacts_per_episode: stats(&|e| e.contacts as f64, true),
        terminations,
        diverged: episodes.iter().filter(|e| e.diverged).count(),
        terminations_per_1000_95: BodyEvaluation::terminations_per_1000_95(terminations, rollouts),
        action_noise,
        push: config.push,
        episodes,
        action_names: config
            .arms
            .terms(&model)
            .map_or_else(|_| Vec::new(), |terms| terms.names()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_markdown_and_json_say_how_many_terminations_blew_up() {
        let stats = ErrorStats::of(&[0.1, 0.3]);
        let e = BodyEvaluation {
            robot: "tricycle".into(),
            engine: "rapier".into(),
            rollouts: 300,
            position_error_m: stats,
            yaw_error_rad: stats,
            leg_orientation_rad: stats,
            contacts_per_episode: stats,
            terminations: 67,
            diverged: 0,
            terminations_per_1000_95: BodyEvaluation::terminations_per_1000_95(67, 300),
            action_noise: 0.0,
            push: None,
            episodes: Vec::new(),
            action_names: Vec::new(),
        };
        assert!(e
            .markdown()
            .contains("| terminations | 67 of 300 | | | |\n"));
        let blown = BodyEvaluation { diverged: 1, ..e };
        assert!(blown
            .markdown()
            .contains("| terminations | 67 of 300 (1 of them physics that blew up) | | | |\n"));
        let v = serde_json::to_value(&blown).unwrap();
        assert_eq!(
            (v["terminations"].as_u64(), v["diverged"].as_u64()),
            (Some(67), Some(1))
        );
        // 67 of 300: 179.9-273.8 per 1000 (Wilson, by hand in `evaluate.rs`'s test).
        assert!(blown.markdown().contains(
            "\nTerminations: 223.3 per 1000 episodes (95 % Wilson interval 179.9-273.8).\n"
        ));
        let interval = &v["terminations_per_1000_95"];
        assert!(
            (interval[0].as_f64().unwrap() - 179.871).abs() < 1e-3,
            "{interval}"
        );
        assert!(
            (interval[1].as_f64().unwrap() - 273.791).abs() < 1e-3,
            "{interval}"
        );
    }
}
