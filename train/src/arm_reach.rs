//! The low-level environment (the paper's section IV-A): one arm module with its base fixed, reaching
//! goals in its base frame. A thin shell: observation, action and reward are the shared pure
//! functions of `kumi-policies` and [`crate::reward`]; physics is any engine of `kumi-worlds`.

use std::sync::Arc;

use kumi_model::{Actuator, ActuatorMode, RobotModel};
use kumi_policies::goal::GoalNoise;
use kumi_policies::goals::GoalDistribution;
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self, Goal, JOINTS, OBSERVATION_DIM};
use kumi_policies::rotation::orientation_error;
use kumi_policies::skill::{ArmSkill, SkillError};
use kumi_worlds::{apply_increments, Engine, RobotState, SimConfig, SimError, SimWorld};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::reward::{reach_terms, ReachTerms, ReachWeights};

/// Episode and task settings. Defaults are the paper's (section IV-A) and kumi's reward weights.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmReachConfig {
    /// The physics engine the arm is simulated in.
    pub engine: Engine,
    /// Control steps per episode (360 at 30 Hz: 12 s).
    pub episode_steps: usize,
    /// Control steps between goal resamples (120 at 30 Hz: 4 s).
    pub goal_period_steps: usize,
    /// Initial joint angles are uniform in [-r, r] [rad].
    pub initial_joint_range: f64,
    pub goals: GoalDistribution,
    pub goal_noise: GoalNoise,
    pub weights: ReachWeights,
}

impl Default for ArmReachConfig {
    fn default() -> Self {
        Self {
            engine: Engine::Rapier,
            episode_steps: 360,
            goal_period_steps: 120,
            initial_joint_range: 0.5,
            goals: GoalDistribution::paper(),
            goal_noise: GoalNoise {
                position_std: 0.005,
                orientation_std: 0.01,
            },
            weights: ReachWeights::default(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Skill(#[from] SkillError),
    #[error("the arm-reach environment needs a fixed-base robot with one 7-joint arm module and a tool frame; `{0}` is not one")]
    NotASingleArm(String),
    #[error("kinematics: {0}")]
    Kinematics(String),
    #[error("goal distribution: {0}")]
    Goals(String),
    /// A setting of the config that is invalid or cannot apply to this robot (the message names
    /// its section).
    #[error("{0}")]
    Settings(String),
    /// The robot cannot carry the task (the message says what it lacks).
    #[error("{0}")]
    Robot(String),
    /// The skill file does not drive this robot's arm modules.
    #[error("the skill: {0}")]
    SkillFile(String),
}

/// The goal distribution as a config file states it (`[goals]` in
/// `train/configs/arm_reach.toml`).
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct GoalConfig {
    /// Probability of a goal from the paper's box; the others are working poses.
    pub paper_box_weight: f64,
    /// Half-width [rad] of the joint-angle spread around each working configuration.
    pub spread_rad: f64,
    /// Morphologies (shipped names or files) whose arm modules' home angles are the working
    /// configurations.
    pub working_configurations: Vec<String>,
    /// Probability that an episode starts at a working configuration, its first goal around
    /// it (see [`GoalDistribution::working_start_weight`]); 0 when absent.
    #[serde(default)]
    pub working_start_weight: f64,
}

impl GoalConfig {
    /// Every arm module of the listed morphologies (seven position joints) as
    /// (`robot/module`, home joint angles [rad]), in file order.
    pub fn working_configurations(&self) -> Result<Vec<(String, [f64; JOINTS])>, EnvError> {
        let library = kumi_model::ModuleLibrary::shipped();
        let mut found = Vec::new();
        for name in &self.working_configurations {
            let morphology = kumi_model::load_morphology(name, &library)
                .map_err(|e| EnvError::Goals(format!("{name}: {e}")))?;
            let model = kumi_model::assemble(&morphology, &library);
            for module in &model.modules {
                if module.position_joints().count() == JOINTS && module.home.len() == JOINTS {
                    let home = std::array::from_fn(|j| module.home[j]);
                    found.push((format!("{}/{}", model.name, module.name), home));
                }
            }
        }
        Ok(found)
    }

    /// The distribution, the working configurations' duplicates removed.
    pub fn resolve(&self) -> Result<GoalDistribution, EnvError> {
        if !(0.0..=1.0).contains(&self.paper_box_weight)
            || !(0.0..=1.0).contains(&self.working_start_weight)
            || self.spread_rad.is_nan()
            || self.spread_rad < 0.0
        {
            return Err(EnvError::Goals(
                "paper_box_weight and working_start_weight must lie in [0, 1] and spread_rad be >= 0".into(),
            ));
        }
        let mut centres: Vec<[f64; JOINTS]> = Vec::new();
        for (_, home) in self.working_configurations()? {
            if !centres.contains(&home) {
                centres.push(home);
            }
        }
        if centres.is_empty() && self.paper_box_weight < 1.0 {
            return Err(EnvError::Goals(
                "working poses asked for, but no arm module found in working_configurations".into(),
            ));
        }
        Ok(GoalDistribution {
            paper_box_weight: self.paper_box_weight,
            centres,
            spread_rad: self.spread_rad,
            working_start_weight: self.working_start_weight,
            ..GoalDistribution::paper()
        })
    }
}

/// What one step produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    pub observation: [f32; OBSERVATION_DIM],
    pub reward: f64,
    pub terms: ReachTerms,
    /// The episode reached its step limit (a time-out: bootstrap the value).
    pub truncated: bool,
    /// The physics blew up ([`SimWorld::diverged`]): the episode ends here, scoring nothing,
    /// its errors NaN and its observation zeros; reset before stepping again.
    pub terminated: bool,
    /// A goal period ended at this step: the errors below are the paper's final errors.
    pub goal_ended: bool,
    /// Tool position error [m] to the (noise-free) goal after this step.
    pub position_error: f64,
    /// Tool orientation error [rad] to the goal after this step.
    pub orientation_error: f64,
}

/// One fixed-base arm reaching goals.
pub struct ArmReach {
    world: Box<dyn SimWorld>,
    module: String,
    ee_link: String,
    base_link: String,
    actuators: Vec<Actuator>,
    /// Forward kinematics and joint limits, for working-pose goals.
    kinematics: ToolKinematics,
    limits: [(f64, f64); JOINTS],
    skill: ArmSkill,
    config: ArmReachConfig,
    rng: ChaCha8Rng,
    goal: Goal,
    observed_goal: Goal,
    targets: Vec<f64>,
    previous_action: [f32; JOINTS],
    step: usize,
}

impl ArmReach {
    /// An environment on `model` (a fixed-base single arm, such as the shipped `arm`), seeded.
    pub fn new(
        model: Arc<RobotModel>,
        config: ArmReachConfig,
        seed: u64,
    ) -> Result<Self, EnvError> {
        let not_arm = || EnvError::NotASingleArm(model.name.clone());
        if !model.fixed_base || model.modules.len() != 1 {
            return Err(not_arm());
        }
        let arm = &model.modules[0];
        let actuators: Vec<Actuator> = arm.position_joints().cloned().collect();
        if actuators.len() != JOINTS
            || arm
                .actuators
                .iter()
                .any(|a| a.mode != ActuatorMode::Position)
        {
            return Err(not_arm());
        }
        let ee_link = arm.ee_link.clone().ok_or_else(not_arm)?;
        let kinematics = ToolKinematics::new(&model, arm).map_err(EnvError::Kinematics)?;
        let limits = std::array::from_fn(|j| (actuators[j].lower, actuators[j].upper));
        let sim = SimConfig::for_model(&model);
        let skill = ArmSkill::new(arm, sim.control_hz)?;
        let world = kumi_worlds::build(config.engine, model.clone(), sim)?;
        let goal = Goal {
            position_b: Default::default(),
            orientation_b: Default::default(),
        };
        let mut env = Self {
            module: arm.name.clone(),
            base_link: arm.root_link.clone(),
            ee_link,
            actuators,
            kinematics,
            limits,
            skill,
            world,
            config,
            rng: ChaCha8Rng::seed_from_u64(seed),
            goal,
            observed_goal: goal,
            targets: vec![0.0; JOINTS],
            previous_action: [0.0; JOINTS],
            step: 0,
        };
        env.reset();
        Ok(env)
    }

    /// Starts an episode: random initial joints, a fresh goal. Returns the first observation.
    pub fn reset(&mut self) -> [f32; OBSERVATION_DIM] {
        let r = self.config.initial_joint_range;
        let start = self.config.goals.start(&mut self.rng, &self.limits);
        let q: Vec<f64> = match start {
            Some((_, q)) => q.to_vec(),
            None => self
                .actuators
                .iter()
                .map(|a| {
                    a.clamp_position(if r > 0.0 {
                        self.rng.random_range(-r..r)
                    } else {
                        0.0
                    })
                })
                .collect(),
        };
        self.world.reset(&RobotState {
            base_pose_w: Isometry3::identity(),
            joint_positions: q.clone(),
        });
        self.targets = q;
        self.previous_action = [0.0; JOINTS];
        self.step = 0;
        self.goal = match start {
            Some((centre, _)) => {
                let kinematics = &self.kinematics;
                self.config
                    .goals
                    .sample_around(&mut self.rng, centre, &self.limits, &|q| {
                        kinematics.tool_pose_b(q)
                    })
            }
            None => self.sample_goal(),
        };
        self.observed_goal = self.config.goal_noise.apply(&self.goal, &mut self.rng);
        self.observation()
    }

    fn sample_goal(&mut self) -> Goal {
        let kinematics = &self.kinematics;
        self.config
            .goals
            .sample(&mut self.rng, &self.limits, &|q| kinematics.tool_pose_b(q))
    }

    /// The tool pose in the arm base frame.
    pub fn tool_pose_b(&self) -> Isometry3<f64> {
        let base = self
            .world
            .link_pose(&self.base_link)
            .expect("the base link exists");
        let tool = self
            .world
            .link_pose(&self.ee_link)
            .expect("the tool link exists");
        base.inverse() * tool
    }

    /// Position [m] and orientation [rad] errors of the tool to the current goal.
    pub fn errors(&self) -> (f64, f64) {
        let tool = self.tool_pose_b();
        (
            (tool.translation.vector - self.goal.position_b).norm(),
            orientation_error(&self.goal.orientation_b, &tool.rotation),
        )
    }

    fn joints(&self) -> ([f64; JOINTS], [f64; JOINTS]) {
        let mut q = [0.0; JOINTS];
        let mut qd = [0.0; JOINTS];
        q.copy_from_slice(&self.world.joint_positions());
        qd.copy_from_slice(&self.world.joint_velocities());
        (q, qd)
    }

    /// The observation the policy sees now (with the noisy goal).
    pub fn observation(&self) -> [f32; OBSERVATION_DIM] {
        let (q, qd) = self.joints();
        observation::build(&q, &qd, &self.observed_goal)
    }

    /// The skill's contract with this arm (joint order, limits, action scale, control rate).
    pub fn skill(&self) -> &ArmSkill {
        &self.skill
    }

    /// The simulated world (read-only), e.g. to rebuild an observation from its state.
    pub fn world(&self) -> &dyn SimWorld {
        self.world.as_ref()
    }

    /// The goal as the policy sees it this step (with this step's noise).
    pub fn observed_goal(&self) -> Goal {
        self.observed_goal
    }

    /// The goal the policy is reaching for (noise-free).
    pub fn goal(&self) -> Goal {
        self.goal
    }

    /// Applies one action (7 values in [-1, 1], clipped), steps the physics one control step.
    pub fn step(&mut self, act: &[f32; JOINTS]) -> StepOutcome {
        if self.world.diverged() {
            return self.diverged_step();
        }
        let increments = self.skill.increments(act);
        let actuators: Vec<&Actuator> = self.actuators.iter().collect();
        self.targets = apply_increments(&self.targets, &increments, &actuators)
            .expect("increments are finite, lengths match");
        self.world
            .set_position_targets(&self.module, &self.targets)
            .expect("targets are finite and the module is an arm");
        self.world.step();
        self.step += 1;
        if self.world.diverged() {
            return self.diverged_step();
        }

        let (position_error, orientation_error) = self.errors();
        let (q, qd) = self.joints();
        let terms = reach_terms(
            position_error,
            orientation_error,
            act,
            &self.previous_action,
            &qd,
            &self.config.weights,
        );
        self.previous_action = *act;

        let goal_ended = self.step.is_multiple_of(self.config.goal_period_steps);
        if goal_ended {
            self.goal = self.sample_goal();
        }
        self.observed_goal = self.config.goal_noise.apply(&self.goal, &mut self.rng);
        StepOutcome {
            observation: observation::build(&q, &qd, &self.observed_goal),
            reward: terms.total(),
            terms,
            truncated: self.step >= self.config.episode_steps,
            terminated: false,
            goal_ended,
            position_error,
            orientation_error,
        }
    }

    /// A step in a world whose physics blew up: its state means nothing, so nothing is scored
    /// from it. Unlike the whole-body task there is no fall penalty: a step's reward here is
    /// mostly positive, so ending early does not pay.
    fn diverged_step(&self) -> StepOutcome {
        StepOutcome {
            observation: [0.0; OBSERVATION_DIM],
            reward: 0.0,
            terms: ReachTerms::default(),
            truncated: self.step >= self.config.episode_steps,
            terminated: true,
            goal_ended: false,
            position_error: f64::NAN,
            orientation_error: f64::NAN,
        }
    }

    /// The simulated world, to set up a test's state (a training or evaluation loop only
    /// steps the environment).
    pub fn world_mut(&mut self) -> &mut dyn SimWorld {
        self.world.as_mut()
    }
}
