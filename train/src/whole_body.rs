//! The upper-level environment (the paper's section IV-B), generated from any
//! morphology with one manipulator: the robot stands at a random pose, a target (position and
//! yaw) is drawn around it, and the policy commands the frozen skill of every arm module and
//! the velocity of every wheel module through the action terms of `kumi-terms`. A thin shell:
//! observation, action terms and reward are shared pure functions; physics is any engine.
//!
//! The flat baseline (the paper's section V-C) is the same environment with other terms: every arm
//! joint's position target directly, and every arm module's joint state added to the
//! observation ([`ArmControl::Joints`]); the penalty baseline adds Eqs. 5 and 6 to its reward
//! ([`PenaltyWeights`]).

use std::f64::consts::PI;
use std::ops::Range;
use std::sync::Arc;

use kumi_model::{ActuatorMode, RobotModel, Role};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self as skill_obs, Goal, JOINTS, OBSERVATION_DIM};
use kumi_policies::skill::ArmSkill;
use kumi_runtime::{BackendChoice, SkillPolicy};
use kumi_terms::action::{planar_twist, ActionTerms, GoalBounds, JointBounds, WheelRamp};
use kumi_terms::observation::{self as body_obs, BodyState, ObservationOptions, Target, ToolChain};
use kumi_worlds::{home_joint_positions, Engine, SimConfig, SimWorld, Snapshot};
use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::arm_reach::EnvError;
use crate::body_reward::{
    airborne_penalty, body_terms, contact_penalty, fall_penalty, fallen, leg_orientation_reward,
    rock_penalty, tilt, tilt_penalty, turn_penalty, BodyTerms, BodyWeights, PenaltyWeights,
};
use crate::evaluate_body::{leg_angles, ContactRule};
use crate::noise::{NoiseSource, ObservationNoise};
use crate::randomize::RandomizeConfig;
use crate::replay::{Replay, ReplayConfig};

/// The task's settings per morphology (`[task]` in `train/configs/whole_body/*.toml`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TaskConfig {
    /// Episode length [s] (the paper: 12).
    pub episode_s: f64,
    /// Base tilt [rad] past which the episode ends (Table V: Minimal 0.6, Dragon 1.0,
    /// Tricycle 0.785).
    pub tilt_limit_rad: f64,
    /// Targets: x and y uniform in [-r, r] [m] of the world origin (the paper: 3).
    pub target_xy_m: f64,
    /// Targets: z uniform in this range [m] (per morphology: around the manipulator's reach).
    pub target_z_m: [f64; 2],
    /// The base starts at x and y uniform in [-r, r] [m] (the paper: 0.5), yaw uniform.
    pub initial_xy_m: f64,
}

impl TaskConfig {
    /// What deployment needs to know of these episodes (written into the policy's metadata).
    pub fn trained_task(&self) -> kumi_terms::contract::TrainedTask {
        kumi_terms::contract::TrainedTask {
            tilt_limit_rad: self.tilt_limit_rad,
            target_xy_m: self.target_xy_m,
            target_z_m: self.target_z_m,
            episode_s: self.episode_s,
        }
    }

    fn check(&self) -> Result<(), EnvError> {
        let [lo, hi] = self.target_z_m;
        let ok = self.episode_s > 0.0
            && self.tilt_limit_rad > 0.0
            && self.target_xy_m >= 0.0
            && self.initial_xy_m >= 0.0
            && lo.is_finite()
            && hi >= lo;
        if ok {
            Ok(())
        } else {
            Err(EnvError::Settings(format!("invalid [task]: {self:?}")))
        }
    }
}

/// Random shoves in training (`[push]` in a whole-body config; none when absent): every
/// `interval_s` [s] (uniform in the range) the whole robot's horizontal velocity jumps by x and y
/// each uniform in [-`velocity_m_s`, `velocity_m_s`] [m/s], and it starts to tip about the
/// world's x and y axes through its base at rates each uniform in [-`tip_rad_s`, `tip_rad_s`]
/// [rad/s] ([`SimWorld::push`]). The policy meets the tilts and slides it would rarely meet on
/// its own, and is paid to recover from them (legged_gym's `push_robots`, Isaac Lab's
/// `push_by_setting_velocity` event).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct PushConfig {
    /// Time between pushes [s], uniform in [lo, hi]; the first comes that long after a reset.
    pub interval_s: [f64; 2],
    /// The largest change of each horizontal velocity component [m/s].
    pub velocity_m_s: f64,
    /// The largest change of each horizontal angular velocity component [rad/s].
    pub tip_rad_s: f64,
}

impl PushConfig {
    /// Refuses an interval that is not `0 < lo <= hi < inf` [s] and a velocity or tip rate that
    /// is not finite and `>= 0`, naming the field and its value.
    pub fn check(&self) -> Result<(), EnvError> {
        let [lo, hi] = self.interval_s;
        let bad = |what: String| Err(EnvError::Settings(format!("invalid [push]: {what}")));
        if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
            return bad(format!(
                "interval_s [{lo}, {hi}] must be a finite range [lo, hi] of seconds with 0 < lo <= hi"
            ));
        }
        for (name, value) in [
            ("velocity_m_s", self.velocity_m_s),
            ("tip_rad_s", self.tip_rad_s),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(format!("{name} {value} must be finite and >= 0"));
            }
        }
        Ok(())
    }

    /// Control steps until the next push (at least 1), at `control_hz`.
    pub fn steps_to_next(&self, control_hz: f64, rng: &mut impl Rng) -> usize {
        let interval_s = crate::randomize::draw(self.interval_s, rng);
        ((interval_s * control_hz).round() as usize).max(1)
    }

    /// One push: the base origin's velocity change [m/s] and the robot's angular velocity
    /// change [rad/s], both horizontal and in the world frame, each component uniform.
    pub fn draw(&self, rng: &mut impl Rng) -> (Vector3<f64>, Vector3<f64>) {
        (
            horizontal(self.velocity_m_s, rng),
            horizontal(self.tip_rad_s, rng),
        )
    }
}

/// A horizontal vector whose x and y are each uniform in [-r, r] (zero, drawing nothing, for r 0).
fn horizontal(r: f64, rng: &mut impl Rng) -> Vector3<f64> {
    if r == 0.0 {
        return Vector3::zeros();
    }
    Vector3::new(rng.random_range(-r..=r), rng.random_range(-r..=r), 0.0)
}

/// How the policy drives the arm modules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArmControl {
    /// Through the frozen skill: a goal per arm module within these bounds (the paper's
    /// hierarchical policy).
    Skill(GoalBounds),
    /// Every joint's position target directly (the flat baseline).
    Joints(JointBounds),
}

impl ArmControl {
    /// The action terms for `model`.
    pub fn terms(&self, model: &RobotModel) -> Result<ActionTerms, kumi_terms::TermError> {
        match self {
            ArmControl::Skill(bounds) => ActionTerms::new(model, bounds),
            ArmControl::Joints(bounds) => ActionTerms::flat(model, bounds),
        }
    }
}

/// Everything the environment needs besides the robot and the skill.
#[derive(Debug, Clone, PartialEq)]
pub struct WholeBodyConfig {
    pub engine: Engine,
    pub task: TaskConfig,
    pub weights: BodyWeights,
    /// The penalty baseline's terms (zero: none).
    pub penalty: PenaltyWeights,
    pub arms: ArmControl,
    /// Optional observation slots beyond Table III.
    pub observation: ObservationOptions,
    /// Random shoves (training; none: the task as the paper sets it).
    pub push: Option<PushConfig>,
    /// Episodes replayed from before earlier ones tipped (training; none: fresh starts only).
    pub replay: Option<ReplayConfig>,
    /// Each environment's own physics, drawn from its seed (training; none: the robot's).
    pub randomize: Option<RandomizeConfig>,
    /// What only the critic sees (training; none: the critic reads the policy's observation).
    pub critic: CriticObservation,
    /// Noise on the policy's observation (training; none: exact readings).
    pub observation_noise: ObservationNoise,
}

/// What only the critic sees (`[critic]` in a whole-body config; training only): an asymmetric
/// actor-critic, whose value function reads more of the robot's state than the policy does.
/// The training environment appends these values to the policy's observation, in this order;
/// the actor reads the observation's leading values, and an exported policy carries only
/// those, so nothing here reaches a policy file or the whole-body node.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CriticObservation {
    /// The base's angular velocity [rad/s] in the base frame (3 values).
    #[serde(default)]
    pub base_angular_velocity: bool,
    /// The base origin's height [m] in the world frame (1 value).
    #[serde(default)]
    pub base_height: bool,
    /// Every arm module's joint angles [rad], then their velocities [rad/s] (module by module
    /// in the action terms' order, each in actuator order; the flat baseline observes these
    /// already).
    #[serde(default)]
    pub arm_joint_state: bool,
    /// How many wheel modules have no wheel on the ground
    /// (`SimWorld::wheel_modules_off_ground`, the `airborne` term's rule; 1 value).
    #[serde(default)]
    pub wheel_modules_off_ground: bool,
}

impl CriticObservation {
    /// True when the critic sees only the policy's observation.
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// How many values these add, for a robot with `arm_joints` arm joints in all.
    pub fn size(&self, arm_joints: usize) -> usize {
        3 * usize::from(self.base_angular_velocity)
            + usize::from(self.base_height)
            + 2 * arm_joints * usize::from(self.arm_joint_state)
            + usize::from(self.wheel_modules_off_ground)
    }
}

/// One arm module as its term drives it.
struct ArmIo {
    module: String,
    skill: ArmSkill,
    /// Its tool pose in its base frame from its joints (the skill observes the tool's error).
    kinematics: ToolKinematics,
    /// Its joints in the world's actuator vectors.
    joints: Range<usize>,
}

/// Everything an episode needs to go on from a step: the world, the target, the previous
/// action, the wheels' ramp and the step count.
#[derive(Clone)]
struct Moment {
    world: Snapshot,
    target: Target,
    previous_action: Vec<f32>,
    wheel_ramp: WheelRamp,
    step: usize,
}

/// What one step produced.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyStep {
    pub observation: Vec<f32>,
    pub reward: f64,
    pub terms: BodyTerms,
    /// The base tilted past the limit, or the physics diverged.
    pub terminated: bool,
    pub truncated: bool,
    /// Tool position error [m] and absolute yaw error [rad] to the target after this step.
    pub position_error: f64,
    pub yaw_error: f64,
    /// The episode started from a replayed moment, not a fresh start ([`ReplayConfig`]).
    pub replayed: bool,
}

/// One robot reaching targets with its manipulator, over the frozen skill.
pub struct WholeBody {
    world: Box<dyn SimWorld>,
    terms: ActionTerms,
    arms: Vec<ArmIo>,
    wheel_modules: Vec<String>,
    /// Actuator indices of every wheel joint (wheel modules in order).
    wheel_joints: Vec<usize>,
    tool_link: String,
    tool_chain: ToolChain,
    /// The frozen skill (none for the flat baseline).
    skill: Option<SkillPolicy>,
    /// Undesired contacts, for the penalty baseline.
    contact_rule: ContactRule,
    config: WholeBodyConfig,
    episode_steps: usize,
    rng: ChaCha8Rng,
    /// `[observation_noise]`'s draws (training only: see [`WholeBody::add_observation_noise`]).
    noise: NoiseSource,
    target: Target,
    previous_action: Vec<f32>,
    /// The wheel commands' rate limit (the policy's wheel acceleration).
    wheel_ramp: WheelRamp,
    step: usize,
    /// The step at which the next push comes (none without `[push]`).
    next_push: Option<usize>,
    /// Moments kept to replay (none without `[replay]`).
    replay: Option<Replay<Moment>>,
    /// This episode started from a replayed moment.
    replayed: bool,
}

impl WholeBody {
    /// An environment for `model` (one manipulator, arm and wheel modules), its arms driven by
    /// the skill in `skill_onnx` (the file's bytes; checked against every arm module; unused
    /// by the flat baseline), seeded.
    pub fn new(
        model: Arc<RobotModel>,
        config: WholeBodyConfig,
        skill_onnx: &[u8],
        seed: u64,
    ) -> Result<Self, EnvError> {
        config.task.check()?;
        if let Some(push) = &config.push {
            push.check()?;
        }
        if let Some(replay) = &config.replay {
            replay
                .check(config.task.tilt_limit_rad)
                .map_err(EnvError::Settings)?;
        }
        let manipulators: Vec<_> = model.modules_with_role(Role::Manipulator).collect();
        let [manipulator] = manipulators.as_slice() else {
            return Err(EnvError::Robot(format!(
                "the whole-body task needs exactly one manipulator; `{}` has {}",
                model.name,
                manipulators.len()
            )));
        };
        let tool_link = manipulator
            .ee_link
            .clone()
            .ok_or_else(|| EnvError::NotASingleArm(manipulator.name.clone()))?;
        let terms = config
            .arms
            .terms(&model)
            .map_err(|e| EnvError::Settings(format!("action terms: {e}")))?;
        let mut sim = SimConfig::for_model(&model);
        if let Some(randomize) = &config.randomize {
            randomize.check().map_err(EnvError::Settings)?;
            sim = randomize.apply(sim, seed);
        }
        let world = kumi_worlds::build(config.engine, model.clone(), sim)?;
        let mut arms = Vec::new();
        let arm_modules = terms.arms().map(|t| &t.module);
        for name in arm_modules.chain(terms.joint_terms().map(|t| &t.module)) {
            let module = model.module(name).expect("terms come from the model");
            arms.push(ArmIo {
                module: name.clone(),
                skill: ArmSkill::new(module, sim.control_hz)?,
                kinematics: ToolKinematics::new(&model, module).map_err(EnvError::Kinematics)?,
                joints: world.module_range(name)?,
            });
        }
        let skill = if terms.uses_skill() {
            Some(load_skill(skill_onnx, &arms)?)
        } else {
            None
        };
        let wheel_modules: Vec<String> = terms.wheels().map(|w| w.module.clone()).collect();
        let wheel_joints = world
            .servos()
            .actuators()
            .iter()
            .enumerate()
            .filter(|(_, a)| a.mode == ActuatorMode::Velocity)
            .map(|(i, _)| i)
            .collect();
        let episode_steps = (config.task.episode_s * sim.control_hz).round() as usize;
        let replay = config.replay;
        let mut env = Self {
            previous_action: vec![0.0; terms.size()],
            wheel_ramp: WheelRamp::new(&terms, sim.control_hz),
            world,
            terms,
            arms,
            wheel_modules,
            wheel_joints,
            tool_link,
            tool_chain: ToolChain::new(&model).map_err(EnvError::Robot)?,
            skill,
            contact_rule: ContactRule::new(&model),
            config,
            episode_steps,
            rng: ChaCha8Rng::seed_from_u64(seed),
            noise: NoiseSource::silent(), // set below, from the slots of the built environment
            target: Target {
                position_w: Vector3::zeros(),
                yaw: 0.0,
            },
            step: 0,
            next_push: None,
            replay: replay.map(|r| Replay::new(r, sim.control_hz)),
            replayed: false,
        };
        let noise_std = env
            .config
            .observation_noise
            .per_value(&env.slots())
            .map_err(EnvError::Settings)?;
        env.noise = NoiseSource::new(noise_std, seed);
        env.reset();
        Ok(env)
    }

    /// Whether episodes may start from replayed moments (`[replay]`).
    pub fn replays(&self) -> bool {
        self.replay.is_some()
    }

    /// The action terms (their size is the action's).
    pub fn terms(&self) -> &ActionTerms {
        &self.terms
    }

    /// The policy's observation slots, in order.
    pub fn slots(&self) -> Vec<body_obs::ObservationSlot> {
        let options = self.config.observation;
        let arm_joints = self.arms.iter().map(|a| a.joints.len()).sum();
        let wheels = self.wheel_joints.len();
        let slots = body_obs::slots(wheels, arm_joints, self.terms.size(), options);
        body_obs::with_arm_state(slots, self.flat_joints())
    }

    pub fn observation_dim(&self) -> usize {
        body_obs::size(&self.slots())
    }

    /// Adds `[observation_noise]` to the policy's observation at the start of `obs` (training
    /// only; nothing without the section). Values past the policy's observation are untouched.
    pub fn add_observation_noise(&mut self, obs: &mut [f32]) {
        self.noise.apply(obs);
    }

    /// How many values only the critic sees ([`CriticObservation`]).
    pub fn critic_extras_dim(&self) -> usize {
        let arm_joints = self.arms.iter().map(|a| a.joints.len()).sum();
        self.config.critic.size(arm_joints)
    }

    /// The values only the critic sees now, in [`CriticObservation`]'s order.
    pub fn critic_extras(&self) -> Vec<f32> {
        let c = self.config.critic;
        if c.is_none() {
            return Vec::new();
        }
        let mut extras = Vec::with_capacity(self.critic_extras_dim());
        let base = self.world.base_pose();
        if c.base_angular_velocity {
            let angular_b = base.rotation.inverse() * self.world.base_twist_w().1;
            extras.extend(angular_b.iter().map(|v| *v as f32));
        }
        if c.base_height {
            extras.push(base.translation.z as f32);
        }
        if c.arm_joint_state {
            let (q, qd) = (self.world.joint_positions(), self.world.joint_velocities());
            body_obs::push_arm_state(&mut extras, &self.arm_values(&q), &self.arm_values(&qd));
        }
        if c.wheel_modules_off_ground {
            extras.push(self.world.wheel_modules_off_ground() as f32);
        }
        extras
    }

    /// Arm joints whose state the flat baseline observes (0 over the skill).
    fn flat_joints(&self) -> usize {
        if self.skill.is_some() {
            0
        } else {
            self.arms.iter().map(|a| a.joints.len()).sum()
        }
    }

    /// The arm modules' joint angles or velocities, module by module.
    fn arm_values(&self, all: &[f64]) -> Vec<f64> {
        self.arms
            .iter()
            .flat_map(|a| all[a.joints.clone()].iter().copied())
            .collect()
    }

    /// The simulated world (read-only).
    pub fn world(&self) -> &dyn SimWorld {
        self.world.as_ref()
    }

    /// The simulated world, to place the robot (evaluation, tests).
    pub fn world_mut(&mut self) -> &mut dyn SimWorld {
        self.world.as_mut()
    }

    pub fn target(&self) -> Target {
        self.target
    }

    /// Sets the target (evaluation, demos); the next observation sees it.
    pub fn set_target(&mut self, target: Target) {
        self.target = target;
    }

    /// Restarts the episodes' random stream (evaluation seeds each episode). The training
    /// noise's stream goes on: evaluation has none.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
    }

    /// Starts an episode: the robot at home, standing at a random pose; a random target. With
    /// `[replay]`, sometimes a moment kept from before an earlier episode tipped instead.
    pub fn reset(&mut self) -> Vec<f32> {
        let replayed = match &self.replay {
            Some(replay) => replay.draw_start(&mut self.rng),
            None => None,
        };
        self.replayed = replayed.is_some();
        match replayed {
            Some(moment) => self.resume(moment),
            None => self.fresh_start(),
        }
        if self.replay.is_some() {
            let first = self.moment();
            if let Some(replay) = self.replay.as_mut() {
                replay.start_episode(first, self.replayed);
            }
        }
        self.next_push = self.push_after(self.step);
        self.observation()
    }

    /// The robot at home, standing at a random pose; a random target.
    fn fresh_start(&mut self) {
        let t = self.config.task;
        let r = t.initial_xy_m;
        let (x, y) = (self.uniform(-r, r), self.uniform(-r, r));
        let yaw = self.uniform(-PI, PI);
        let state = self
            .world
            .standing_state(x, y, yaw, home_joint_positions(self.world.model()));
        self.world.reset(&state);
        let r = t.target_xy_m;
        self.target = Target {
            position_w: Vector3::new(
                self.uniform(-r, r),
                self.uniform(-r, r),
                self.uniform(t.target_z_m[0], t.target_z_m[1]),
            ),
            yaw: self.uniform(-PI, PI),
        };
        self.previous_action.iter_mut().for_each(|a| *a = 0.0);
        self.wheel_ramp.stop();
        self.step = 0;
    }

    /// The episode as it is now, to go on from later.
    fn moment(&self) -> Moment {
        Moment {
            world: self.world.snapshot(),
            target: self.target,
            previous_action: self.previous_action.clone(),
            wheel_ramp: self.wheel_ramp.clone(),
            step: self.step,
        }
    }

    /// Goes on from a kept moment.
    fn resume(&mut self, moment: Moment) {
        self.world
            .restore(&moment.world)
            .expect("moments are taken from this world");
        self.target = moment.target;
        self.previous_action = moment.previous_action;
        self.wheel_ramp = moment.wheel_ramp;
        self.step = moment.step;
    }

    /// The step of the next push after `step` (none without `[push]`).
    fn push_after(&mut self, step: usize) -> Option<usize> {
        let push = self.config.push?;
        // Saturating: an interval past any episode's end (a push that never comes) is allowed.
        let control_hz = self.world.config().control_hz;
        Some(step.saturating_add(push.steps_to_next(control_hz, &mut self.rng)))
    }

    /// Pushes the robot if this step is due one, and schedules the next.
    fn push_if_due(&mut self) {
        let Some(push) = self.config.push else {
            return;
        };
        if self.next_push == Some(self.step) {
            let (delta_v_w, delta_w_w) = push.draw(&mut self.rng);
            self.world.push(&delta_v_w, &delta_w_w);
            self.next_push = self.push_after(self.step);
        }
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        if hi > lo {
            self.rng.random_range(lo..hi)
        } else {
            lo
        }
    }

    /// The manipulator's tool pose in the world.
    pub fn tool_pose_w(&self) -> Isometry3<f64> {
        self.world
            .link_pose(&self.tool_link)
            .expect("the tool link exists")
    }

    /// Tool position error [m] and absolute yaw error [rad] to the target now.
    pub fn errors(&self) -> (f64, f64) {
        body_obs::target_errors(&self.tool_pose_w(), &self.target)
    }

    /// The manipulator's tool pose as the policy observes it: forward kinematics of the
    /// joint angles from the base pose ([`ToolChain`]), as the whole-body node computes it.
    pub fn observed_tool_pose_w(&self) -> Isometry3<f64> {
        let q = self.world.joint_positions();
        let names = self.world.actuator_names();
        self.tool_chain
            .tool_pose_w(&self.world.base_pose(), names.into_iter().zip(q))
    }

    /// The observation the policy sees now.
    pub fn observation(&self) -> Vec<f32> {
        let velocities = self.world.joint_velocities();
        let wheels: Vec<f64> = self.wheel_joints.iter().map(|&i| velocities[i]).collect();
        let (linear_w, angular_w) = self.world.base_twist_w();
        let positions = self.world.joint_positions();
        let arm_angles = if self.config.observation.arm_joint_angles {
            self.arm_values(&positions)
        } else {
            Vec::new()
        };
        let state = BodyState {
            base_pose_w: self.world.base_pose(),
            base_linear_velocity_w: linear_w,
            base_angular_velocity_w: angular_w,
            tool_pose_w: self.observed_tool_pose_w(),
            target: self.target,
            wheel_velocities: &wheels,
            arm_joint_angles: &arm_angles,
            previous_action: &self.previous_action,
        };
        let mut obs = body_obs::build(&state, self.config.observation);
        if self.skill.is_none() {
            let positions = self.arm_values(&positions);
            body_obs::push_arm_state(&mut obs, &positions, &self.arm_values(&velocities));
        }
        obs
    }

    /// Each arm module's skill observation for its goal, as the arm-reach environment and the
    /// arm node build it: its own joints, the goal in its own base frame.
    pub fn skill_observations(&self, goals: &[Goal]) -> Vec<[f32; OBSERVATION_DIM]> {
        let (q, qd) = (self.world.joint_positions(), self.world.joint_velocities());
        let targets = self.world.commands();
        self.arms
            .iter()
            .zip(goals)
            .map(|(arm, goal)| {
                let at = |v: &[f64]| -> [f64; JOINTS] {
                    std::array::from_fn(|j| v[arm.joints.start + j])
                };
                let fk = |q: &[f64; JOINTS]| arm.kinematics.tool_pose_b(q);
                let limits = arm.kinematics.limits_rad();
                skill_obs::build(&at(&q), &at(&qd), &at(&targets), goal, &fk, limits)
            })
            .collect()
    }

    /// Applies one action through the terms, steps the physics one control step.
    pub fn step(&mut self, action: &[f32]) -> BodyStep {
        let commands = self
            .terms
            .commands(action)
            .expect("the trainer sends actions of the terms' size");
        let observations = self
            .skill
            .is_some()
            .then(|| self.skill_observations(&commands.goals));
        if let (Some(skill), Some(observations)) = (self.skill.as_mut(), observations) {
            let skill_actions = skill
                .act_batch(&observations)
                .expect("the skill was checked at load");
            for (arm, a) in self.arms.iter().zip(&skill_actions) {
                self.world
                    .apply_increments(&arm.module, &arm.skill.increments(a))
                    .expect("increments are finite and sized for the module");
            }
        } else {
            for (arm, targets) in self.arms.iter().zip(&commands.joint_targets) {
                self.world
                    .set_position_targets(&arm.module, targets)
                    .expect("targets are finite and sized for the module");
            }
        }
        let mut wheel_commands = commands.wheel_velocities;
        let (v_w, w_w) = self.world.base_twist_w();
        self.terms.govern(&mut wheel_commands, &v_w, &w_w);
        let wheel_velocities = self.wheel_ramp.follow(&wheel_commands);
        for (module, v) in self.wheel_modules.iter().zip(&wheel_velocities) {
            self.world
                .set_wheel_velocity(module, *v)
                .expect("a wheel module");
        }
        self.push_if_due();
        self.world.step();
        self.step += 1;
        if self.world.diverged() {
            return self.diverged_step(action);
        }

        let (position_error, yaw_error) = self.errors();
        let arm_velocities = self.arm_values(&self.world.joint_velocities());
        let mut terms = body_terms(
            position_error,
            yaw_error,
            &arm_velocities,
            action,
            &self.previous_action,
            &self.config.weights,
        );
        self.add_penalties(&mut terms);
        self.previous_action.copy_from_slice(action);
        let fell = fallen(
            &self.world.base_pose().rotation,
            self.config.task.tilt_limit_rad,
        );
        terms.fall = fall_penalty(self.config.weights.fall, fell);
        if self.config.weights.tilt != 0.0 {
            terms.tilt = tilt_penalty(
                self.config.weights.tilt,
                tilt(&self.world.base_pose().rotation),
            );
        }
        if self.config.weights.turn != 0.0 {
            let (v_w, w_w) = self.world.base_twist_w();
            let (speed_xy_m_s, yaw_rate_rad_s) = planar_twist(&v_w, &w_w);
            terms.turn = turn_penalty(self.config.weights.turn, speed_xy_m_s, yaw_rate_rad_s);
        }
        if self.config.weights.rock != 0.0 {
            let (_, w_w) = self.world.base_twist_w();
            let w_b = self.world.base_pose().rotation.inverse() * w_w;
            terms.rock = rock_penalty(self.config.weights.rock, &w_b);
        }
        if self.config.weights.airborne != 0.0 {
            terms.airborne = airborne_penalty(
                self.config.weights.airborne,
                self.world.wheel_modules_off_ground(),
            );
        }
        let terminated = fell;
        if self.replay.is_some() {
            let (moment, tilt_rad) = (self.moment(), tilt(&self.world.base_pose().rotation));
            if let Some(replay) = self.replay.as_mut() {
                replay.record(moment, tilt_rad);
            }
        }
        BodyStep {
            observation: self.observation(),
            reward: terms.total(),
            terms,
            terminated,
            truncated: self.step >= self.episode_steps,
            position_error,
            yaw_error,
            replayed: self.replayed,
        }
    }
}

impl WholeBody {
    /// A step after which the physics had blown up ([`SimWorld::diverged`]): its state means
    /// nothing, so nothing is scored from it (a rapier world that blew up once gave a training
    /// batch rewards summing to -3.6e20 through the joint-speed penalty). It ends the episode
    /// as a fall does, earning the fall penalty alone; its errors are NaN, and its observation
    /// zeros (the trainer resets before reading one).
    fn diverged_step(&mut self, action: &[f32]) -> BodyStep {
        self.previous_action.copy_from_slice(action);
        let terms = BodyTerms {
            fall: fall_penalty(self.config.weights.fall, true),
            ..BodyTerms::default()
        };
        BodyStep {
            observation: vec![0.0; self.observation_dim()],
            reward: terms.total(),
            terms,
            terminated: true,
            truncated: self.step >= self.episode_steps,
            position_error: f64::NAN,
            yaw_error: f64::NAN,
            replayed: self.replayed,
        }
    }

    /// The penalty baseline's terms (Eqs. 5 and 6), when their weights are set.
    fn add_penalties(&self, terms: &mut BodyTerms) {
        let p = self.config.penalty;
        if p.w_ori != 0.0 {
            let angles = leg_angles(self.world.model(), self.world.as_ref());
            terms.leg_orientation = leg_orientation_reward(p.w_ori, &angles);
        }
        if p.w_c != 0.0 {
            terms.contact = contact_penalty(p.w_c, self.contact_rule.any(self.world.as_ref()));
        }
    }
}

/// The skill, loaded once for the environment (tract: no native library needed in training)
/// and checked against every arm module it will drive.
fn load_skill(bytes: &[u8], arms: &[ArmIo]) -> Result<SkillPolicy, EnvError> {
    let first = arms
        .first()
        .ok_or_else(|| EnvError::Robot("no arm module for the skill to drive".into()))?;
    let skill =
        SkillPolicy::from_bytes(bytes.to_vec(), "skill", &first.skill, BackendChoice::Tract)
            .map_err(|e| EnvError::SkillFile(e.to_string()))?;
    for arm in &arms[1..] {
        arm.skill
            .check(skill.metadata())
            .map_err(|e| EnvError::SkillFile(format!("module `{}`: {e}", arm.module)))?;
    }
    Ok(skill)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PUSH: PushConfig = PushConfig {
        interval_s: [2.0, 4.0],
        velocity_m_s: 0.5,
        tip_rad_s: 0.3,
    };

    #[test]
    fn pushes_come_within_their_interval_and_bounds() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut shortest, mut longest) = (usize::MAX, 0);
        for _ in 0..2000 {
            let steps = PUSH.steps_to_next(30.0, &mut rng);
            (shortest, longest) = (shortest.min(steps), longest.max(steps));
            let (dv, dw) = PUSH.draw(&mut rng);
            assert_eq!((dv.z, dw.z), (0.0, 0.0), "pushes are horizontal");
            assert!(dv.x.abs() <= 0.5 && dv.y.abs() <= 0.5, "{dv:?}");
            assert!(dw.x.abs() <= 0.3 && dw.y.abs() <= 0.3, "{dw:?}");
        }
        // 2-4 s at 30 Hz, both ends reached over 2000 draws.
        assert_eq!((shortest, longest), (60, 120));
    }

    #[test]
    fn a_push_comes_at_least_one_step_on_and_a_zero_push_is_none() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let soon = PushConfig {
            interval_s: [0.001, 0.001],
            velocity_m_s: 0.0,
            tip_rad_s: 0.0,
        };
        assert_eq!(soon.steps_to_next(30.0, &mut rng), 1);
        assert_eq!(soon.draw(&mut rng), (Vector3::zeros(), Vector3::zeros()));
    }

    #[test]
    fn bad_push_settings_are_refused() {
        for (interval_s, velocity_m_s, tip_rad_s, named) in [
            ([0.0, 1.0], 0.5, 0.1, "interval_s [0, 1]"),
            ([2.0, 1.0], 0.5, 0.1, "interval_s [2, 1]"),
            ([1.0, f64::INFINITY], 0.5, 0.1, "interval_s [1, inf]"),
            ([1.0, 2.0], -0.1, 0.1, "velocity_m_s -0.1"),
            ([1.0, 2.0], f64::NAN, 0.1, "velocity_m_s NaN"),
            ([1.0, 2.0], 0.5, -0.1, "tip_rad_s -0.1"),
            ([1.0, 2.0], 0.5, f64::INFINITY, "tip_rad_s inf"),
        ] {
            let push = PushConfig {
                interval_s,
                velocity_m_s,
                tip_rad_s,
            };
            let error = push.check().unwrap_err().to_string();
            assert!(error.starts_with("invalid [push]: "), "{error}");
            assert!(error.contains(named), "{error} should name {named}");
        }
        PUSH.check().unwrap();
    }
}
