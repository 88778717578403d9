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
use kumi_worlds::{apply_increments, Engine, Load, RobotState, SimConfig, SimError, SimWorld};
use nalgebra::{Isometry3, Vector3};
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
    /// A force on the tool during some goals (none by default: the paper's task).
    pub load: ToolLoad,
    /// What the policy observes beyond Table I's values (none: format 1, the shipped skill's).
    pub observation: SkillObservation,
    /// How the policy's action is formed (the network's output alone by default).
    pub action: SkillAction,
}

impl ArmReachConfig {
    /// How many leading values of the observation the policy is trained on.
    pub fn observation_dim(&self) -> usize {
        self.observation
            .observation_dim()
            .expect("checked when the environment is built")
    }
}

/// What the skill observes (`[observation]` of the training config). Each choice reads a
/// prefix of the one layout ([`kumi_policies::observation`]), so the tool's error comes with
/// the targets' lead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct SkillObservation {
    /// How far each joint's position target leads its angle, after Table I's values (format
    /// `kumi-skill/arm-reach/2`); without it, Table I's 21 values (format 1).
    #[serde(default)]
    pub targets_lead: bool,
    /// The goal's position less the tool's, and the rotation from the tool's orientation to the
    /// goal's, after the lead (format `kumi-skill/arm-reach/3`; needs `targets_lead`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub tool_error: bool,
    /// The damped least-squares joint step toward the goal, after the tool's error (format
    /// `kumi-skill/arm-reach/4`; needs `tool_error`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub joint_step: bool,
}

impl SkillObservation {
    /// Table I's observation (the section left out).
    pub fn is_table_i(&self) -> bool {
        !self.targets_lead && !self.tool_error && !self.joint_step
    }

    /// How many leading observation values this choice reads, or why it is not a layout.
    pub fn observation_dim(&self) -> Result<usize, EnvError> {
        match (self.targets_lead, self.tool_error, self.joint_step) {
            (false, false, false) => Ok(observation::BASE_DIM),
            (true, false, false) => Ok(observation::LEAD_DIM),
            (true, true, false) => Ok(observation::TOOL_DIM),
            (true, true, true) => Ok(OBSERVATION_DIM),
            _ => Err(EnvError::Observation(
                "`joint_step = true` needs `tool_error = true`, and `tool_error = true` needs `targets_lead = true`: each skill format reads a prefix of one layout, in that order".into(),
            )),
        }
    }
}

/// How the skill's action is formed (`[action]` of the training config).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct SkillAction {
    /// The action is the network's output plus this gain times the observed joint step over
    /// the largest increment ([`step_prior`]): the network learns a residual on a step
    /// follower. 0: the network's output alone. Needs `joint_step`. The exported policy
    /// carries the term in its graph, so the skill's contract and whoever runs it are as for
    /// any skill of its format.
    #[serde(default)]
    pub step_prior_gain: f64,
}

impl SkillAction {
    /// The network's output alone (the section left out).
    pub fn is_plain(&self) -> bool {
        self.step_prior_gain == 0.0
    }
}

/// The step follower's part of the action as a matrix [[`OBSERVATION_DIM`]][[`JOINTS`]]
/// (row-major): `gain` over each joint's largest increment, from each joint's observed step
/// (`step1..step7`) to its action. The training environment adds observation times matrix to
/// the network's output; the exported policy's graph does the same.
pub fn step_prior(gain: f64, skill: &ArmSkill) -> Vec<f32> {
    let mut matrix = vec![0.0_f32; OBSERVATION_DIM * JOINTS];
    for j in 0..JOINTS {
        matrix[(observation::TOOL_DIM + j) * JOINTS + j] = (gain / skill.increment_scale[j]) as f32;
    }
    matrix
}

/// `action` plus `observation` times `prior` ([`step_prior`]), value by value in f32.
pub fn with_prior(
    action: &[f32; JOINTS],
    observation: &[f32; OBSERVATION_DIM],
    prior: &[f32],
) -> [f32; JOINTS] {
    std::array::from_fn(|j| {
        let follower: f32 = (0..OBSERVATION_DIM)
            .map(|i| observation[i] * prior[i * JOINTS + j])
            .sum();
        action[j] + follower
    })
}

/// A load on the tool during some goals (`[load]` of the training config): what the rest of a
/// robot puts on an arm module that carries it (a leg under the base, an arm holding a wheel
/// module), which a fixed arm reaching in free space never feels. A goal may come with a
/// constant force, with a spring holding the tool where it stands when the goal starts (as the
/// ground holds a leg's tip: the skill cannot reach its goal and must not wind its targets up
/// trying), or with both.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ToolLoad {
    /// Probability that a goal comes with a constant force.
    pub share: f64,
    /// Largest force [N]: the magnitude is uniform in [0, max_force_n], the direction uniform.
    pub max_force_n: f64,
    /// Probability that a goal comes with the tool held where it stands; 0 when absent.
    #[serde(default)]
    pub anchored_share: f64,
    /// The holding spring's stiffness range [N/m], drawn uniformly.
    #[serde(default)]
    pub stiffness_n_m: [f64; 2],
    /// When set, an anchored goal is the tool's pose where it is held, moved by up to this much
    /// [m] in a random direction (a module asked to hold about where it stands); when absent, an
    /// anchored goal is drawn as any other, mostly out of the held tool's reach.
    #[serde(default)]
    pub anchored_goal_offset_m: Option<f64>,
}

impl ToolLoad {
    /// Whether no goal is ever loaded (the section left out).
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// Refuses shares outside [0, 1], a negative or non-finite force, or a stiffness range
    /// that is not 0 <= low <= high (finite) while anchored goals are asked for.
    pub fn validate(&self) -> Result<(), EnvError> {
        let share = |p: f64| (0.0..=1.0).contains(&p);
        let [low, high] = self.stiffness_n_m;
        let offset = self.anchored_goal_offset_m.unwrap_or(0.0);
        let stiffness = self.anchored_share == 0.0
            || (low.is_finite()
                && high.is_finite()
                && 0.0 <= low
                && low <= high
                && offset.is_finite()
                && offset >= 0.0);
        if !(share(self.share)
            && share(self.anchored_share)
            && self.max_force_n.is_finite()
            && self.max_force_n >= 0.0
            && stiffness)
        {
            return Err(EnvError::Settings(format!(
                "[load]: share and anchored_share must lie in [0, 1], max_force_n be a force >= 0 N, stiffness_n_m a range [low, high] with 0 <= low <= high N/m and anchored_goal_offset_m >= 0 m; got {self:?}"
            )));
        }
        Ok(())
    }

    /// The load for the next goal, the tool's frame at `tool_w` [m] (world frame). Draws
    /// nothing for a kind of load no goal gets, so a config without loads keeps its random
    /// stream.
    pub fn draw(&self, rng: &mut impl Rng, tool_w: &Vector3<f64>) -> Load {
        // (An anchored load is the one with a spring: `Load::stiffness_n_m` > 0.)
        let mut load = Load::NONE;
        if self.share > 0.0 && rng.random_bool(self.share) {
            load.force_w = uniform_direction(rng) * rng.random_range(0.0..=self.max_force_n);
        }
        if self.anchored_share > 0.0 && rng.random_bool(self.anchored_share) {
            let [low, high] = self.stiffness_n_m;
            load.anchor_w = *tool_w;
            load.stiffness_n_m = rng.random_range(low..=high).max(f64::MIN_POSITIVE);
        }
        load
    }

    /// The goal of an anchored goal period near the tool's pose `tool_b`, when
    /// `anchored_goal_offset_m` is set: that pose moved by up to the offset in a random
    /// direction.
    pub fn anchored_goal(&self, rng: &mut impl Rng, tool_b: &Isometry3<f64>) -> Option<Goal> {
        let radius = self.anchored_goal_offset_m?;
        let offset = uniform_direction(rng) * rng.random_range(0.0..=radius);
        Some(Goal {
            position_b: tool_b.translation.vector + offset,
            orientation_b: tool_b.rotation,
        })
    }
}

/// A direction drawn uniformly on the unit sphere (a normal draw per axis, normalised).
fn uniform_direction(rng: &mut impl Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::from_fn(|_, _| {
            let (u1, u2): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        });
        if v.norm() > 1e-9 {
            return v.normalize();
        }
    }
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
            load: ToolLoad::default(),
            observation: SkillObservation::default(),
            action: SkillAction::default(),
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
    #[error("[observation]: {0}")]
    Observation(String),
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
    /// The step follower's matrix when `[action]` asks for one ([`step_prior`]).
    prior: Option<Vec<f32>>,
    /// The observation the next action answers (the last one returned).
    last_observation: [f32; OBSERVATION_DIM],
    step: usize,
}

impl ArmReach {
    /// An environment on `model` (a fixed-base single arm, such as the shipped `arm`), seeded.
    pub fn new(
        model: Arc<RobotModel>,
        config: ArmReachConfig,
        seed: u64,
    ) -> Result<Self, EnvError> {
        config.load.validate()?;
        let observation_dim = config.observation.observation_dim()?;
        let gain = config.action.step_prior_gain;
        if !(gain.is_finite() && gain >= 0.0) {
            return Err(EnvError::Observation(format!(
                "`step_prior_gain` must be finite and >= 0, not {gain}"
            )));
        }
        if gain > 0.0 && observation_dim != OBSERVATION_DIM {
            return Err(EnvError::Observation(
                "`step_prior_gain` needs the joint step in the observation (`joint_step = true`)"
                    .into(),
            ));
        }
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
        let prior = (gain > 0.0).then(|| step_prior(gain, &skill));
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
            prior,
            last_observation: [0.0; OBSERVATION_DIM],
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
            joint_positions: q,
        });
        // The targets start at the measured angles, as the arm node's do (rapier's f32 state
        // can differ from the drawn angles in the last bits).
        self.targets = self.world.joint_positions();
        self.world
            .set_position_targets(&self.module, &self.targets)
            .expect("measured angles are finite and within the joint ranges");
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
        self.load_tool();
        self.observed_goal = self.config.goal_noise.apply(&self.goal, &mut self.rng);
        self.last_observation = self.observation();
        self.last_observation
    }

    /// Draws the tool's load for the goal that starts now and puts it on; an anchored goal
    /// period may get its goal where the tool is held ([`ToolLoad::anchored_goal`]).
    fn load_tool(&mut self) {
        let tool_w = self
            .world
            .link_pose(&self.ee_link)
            .expect("the tool link exists")
            .translation
            .vector;
        let load = self.config.load.draw(&mut self.rng, &tool_w);
        self.world
            .set_link_load(&self.ee_link, &load)
            .expect("the tool link exists and the load is valid");
        if load.stiffness_n_m > 0.0 {
            let tool_b = self.tool_pose_b();
            if let Some(goal) = self.config.load.anchored_goal(&mut self.rng, &tool_b) {
                self.goal = goal;
            }
        }
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
        let fk = |q: &[f64; JOINTS]| self.kinematics.tool_pose_b(q);
        let limits = self.kinematics.limits_rad();
        observation::build(&q, &qd, &self.targets(), &self.observed_goal, &fk, limits)
    }

    /// The joints' position targets [rad], which the skill's increments move.
    pub fn targets(&self) -> [f64; JOINTS] {
        std::array::from_fn(|j| self.targets[j])
    }

    /// The skill's contract with this arm (joint order, limits, action scale, control rate).
    pub fn skill(&self) -> &ArmSkill {
        &self.skill
    }

    /// The task's settings.
    pub fn config(&self) -> &ArmReachConfig {
        &self.config
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

    /// Applies one action (7 values in [-1, 1], clipped; with a step prior, the network's
    /// output, to which the follower's part is added first), steps the physics one control step.
    pub fn step(&mut self, network: &[f32; JOINTS]) -> StepOutcome {
        if self.world.diverged() {
            return self.diverged_step();
        }
        let act = &match &self.prior {
            Some(prior) => with_prior(network, &self.last_observation, prior),
            None => *network,
        };
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
        let targets = self.targets();
        let lead: [f64; JOINTS] = std::array::from_fn(|j| targets[j] - q[j]);
        let terms = reach_terms(
            position_error,
            orientation_error,
            act,
            &self.previous_action,
            &qd,
            &lead,
            &self.config.weights,
        );
        self.previous_action = *act;

        let goal_ended = self.step.is_multiple_of(self.config.goal_period_steps);
        if goal_ended {
            self.goal = self.sample_goal();
            self.load_tool();
        }
        self.observed_goal = self.config.goal_noise.apply(&self.goal, &mut self.rng);
        self.last_observation = observation::build(
            &q,
            &qd,
            &targets,
            &self.observed_goal,
            &|q| self.kinematics.tool_pose_b(q),
            self.kinematics.limits_rad(),
        );
        StepOutcome {
            observation: self.last_observation,
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
