//! The low-level skill's evaluation (the paper's protocol, section IV-A): the tool's position
//! and orientation errors at the end of each 4 s goal, over many goals.
//!
//! Episodes are the training environment's own (random initial joints, three goals of 4 s,
//! goal noise as in training); every goal end is one rollout, so later goals start wherever the
//! arm was left. Episode `k` is seeded by `(seed, k)`, so results do not depend on how many
//! threads run them.
//!
//! Beside the errors it measures how calmly the skill reaches and holds each goal
//! ([`kumi_policies::settle`]): hold smoothness over the last second of each goal and the
//! settle time.

use std::sync::Arc;

use kumi_model::RobotModel;
use kumi_policies::observation::{JOINTS, OBSERVATION_DIM};
use kumi_policies::settle::{settle_steps, HoldCounts, HOLD_WINDOW_S};
use kumi_policies::skill::{values_past_limit, ACTION_LIMIT};
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::arm_reach::{ArmReach, ArmReachConfig, EnvError};

/// Summary of one error over all rollouts.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorStats {
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
    pub median: f64,
    /// 90th percentile (nearest rank).
    pub p90: f64,
}

impl ErrorStats {
    /// One markdown table row: `| name | mean | std | median | p90 |`.
    pub fn markdown_row(name: &str, s: &ErrorStats) -> String {
        format!(
            "| {name} | {:.4} | {:.4} | {:.4} | {:.4} |\n",
            s.mean, s.std, s.median, s.p90
        )
    }

    /// The summary of no values: NaN everywhere.
    pub fn empty() -> Self {
        Self::of(&[])
    }

    /// The summary of `values` (NaN everywhere if empty).
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self {
                mean: f64::NAN,
                std: f64::NAN,
                median: f64::NAN,
                p90: f64::NAN,
            };
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = if sorted.len() % 2 == 1 {
            sorted[sorted.len() / 2]
        } else {
            0.5 * (sorted[sorted.len() / 2 - 1] + sorted[sorted.len() / 2])
        };
        // Nearest rank: the smallest value with at least 90 % of the values at or below it.
        let rank = ((0.9 * n).ceil() as usize).clamp(1, sorted.len());
        Self {
            mean,
            std,
            median,
            p90: sorted[rank - 1],
        }
    }
}

/// The 95 % Wilson score interval of a rate from `count` events in `trials` independent
/// trials, as fractions `(low, high)` (None without trials). Unlike the normal approximation it
/// stays inside [0, 1] and is not empty at a count of 0, which is where rare events such as falls
/// sit: 0 of 1000 gives (0, 0.0038). Wilson, "Probable inference, the law of succession, and
/// statistical inference", JASA 22 (1927).
pub fn wilson_interval_95(count: usize, trials: usize) -> Option<(f64, f64)> {
    if trials == 0 || count > trials {
        return None;
    }
    const Z: f64 = 1.959_963_984_540_054; // the standard normal's 97.5 % quantile
    let (n, p) = (trials as f64, count as f64 / trials as f64);
    let z2 = Z * Z;
    let denominator = 1.0 + z2 / n;
    let center = (p + z2 / (2.0 * n)) / denominator;
    let half = Z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / denominator;
    Some(((center - half).max(0.0), (center + half).min(1.0)))
}

/// The evaluation's result, as `kumi eval arm --json` prints it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Evaluation {
    /// The physics engine the rollouts ran in.
    pub engine: String,
    /// The goal distribution: "paper" (the paper's box) or "working" (working poses).
    #[serde(default)]
    pub goals: String,
    pub rollouts: usize,
    pub position_error_m: ErrorStats,
    pub orientation_error_rad: ErrorStats,
    /// The share (0-1) of the policy's action values, over every control step of every
    /// episode, that lie past the +-[`ACTION_LIMIT`] the skill clips them to
    /// ([`values_past_limit`]): near 1 the skill acts as a relay.
    #[serde(default)]
    pub action_values_past_limit: f64,
    /// Episodes cut short because their physics blew up ([`kumi_worlds::SimWorld::diverged`]):
    /// the goals they did not finish are not among the rollouts.
    #[serde(default)]
    pub diverged_episodes: usize,
    /// Over the last [`HOLD_WINDOW_S`] of every goal: the mean absolute increment per joint per
    /// step, as a share (0-1) of the largest increment ([`HoldCounts::mean_increment_share`]).
    #[serde(default)]
    pub hold_increment_share: f64,
    /// Over the same windows: the share (0-1) of steps at which a joint's increment reversed
    /// sign with a magnitude above 20 % of the largest ([`HoldCounts::reversal_share`]).
    #[serde(default)]
    pub hold_reversal_share: f64,
    /// Seconds from each goal's start until the tool stays within 2 cm and 0.1 rad of where it
    /// ends ([`settle_steps`]).
    #[serde(default = "ErrorStats::empty")]
    pub settle_time_s: ErrorStats,
    /// The standard deviations of the noise drawn afresh at every step on the goal the skill
    /// observes: position [m] and orientation [rad].
    #[serde(default)]
    pub goal_noise: GoalNoiseStd,
}

/// The goal noise of an evaluation, as its JSON reports it.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct GoalNoiseStd {
    pub position_m: f64,
    pub orientation_rad: f64,
}

impl Evaluation {
    /// The result as a markdown table.
    pub fn markdown(&self) -> String {
        let row = ErrorStats::markdown_row;
        format!(
            "| final error ({} rollouts, {} goals, {}) | mean | std | median | p90 |\n|---|---|---|---|---|\n{}{}{}\naction values past the +-{ACTION_LIMIT} they are clipped to: {:.1} %\nhold, last {HOLD_WINDOW_S} s of each goal: mean increment {:.1} % of the largest; sign reversals above 20 % of it at {:.1} % of the steps\ngoal noise: {} m, {} rad (standard deviations, drawn afresh every step)\n{}",
            self.rollouts,
            self.goals,
            self.engine,
            row("position [m]", &self.position_error_m),
            row("orientation [rad]", &self.orientation_error_rad),
            row("settle time [s] (within 2 cm, 0.1 rad of the end)", &self.settle_time_s),
            100.0 * self.action_values_past_limit,
            100.0 * self.hold_increment_share,
            100.0 * self.hold_reversal_share,
            self.goal_noise.position_m,
            self.goal_noise.orientation_rad,
            match self.diverged_episodes {
                0 => String::new(),
                n => format!("episodes cut short by physics that blew up: {n}\n"),
            },
        )
    }
}

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error("the policy failed: {0}")]
    Policy(String),
}

/// Evaluates a policy over `rollouts` goals. `make_policy` builds one policy instance per
/// worker thread; a policy maps an observation to an action (or fails with a message).
pub fn evaluate<P, F>(
    model: Arc<RobotModel>,
    config: ArmReachConfig,
    rollouts: usize,
    seed: u64,
    make_policy: F,
) -> Result<Evaluation, EvalError>
where
    F: Fn() -> Result<P, String> + Sync,
    P: FnMut(&[f32; OBSERVATION_DIM]) -> Result<[f32; JOINTS], String>,
{
    let goals_per_episode = (config.episode_steps / config.goal_period_steps).max(1);
    let episodes = rollouts.div_ceil(goals_per_episode);
    let per_episode: Vec<EpisodeOutcome> = (0..episodes)
        .into_par_iter()
        .map_init(
            || make_policy().map_err(EvalError::Policy),
            |policy, k| {
                let policy = policy
                    .as_mut()
                    .map_err(|e| EvalError::Policy(e.to_string()))?;
                let episode_seed = seed.wrapping_mul(1_000_003).wrapping_add(k as u64);
                let mut env = ArmReach::new(model.clone(), config.clone(), episode_seed)?;
                let obs = env.reset();
                run_episode(&mut env, obs, config.episode_steps, policy)
            },
        )
        .collect::<Result<_, EvalError>>()?;
    let values: usize = per_episode.iter().map(|e| e.action_values).sum();
    let past_limit: usize = per_episode.iter().map(|e| e.action_values_past_limit).sum();
    let diverged_episodes = per_episode.iter().filter(|e| e.diverged).count();
    let goals: Vec<GoalOutcome> = per_episode
        .into_iter()
        .flat_map(|e| e.goals)
        .take(rollouts)
        .collect();
    let p: Vec<f64> = goals.iter().map(|g| g.position_error).collect();
    let o: Vec<f64> = goals.iter().map(|g| g.orientation_error).collect();
    let settle: Vec<f64> = goals.iter().map(|g| g.settle_time_s).collect();
    let hold = goals
        .iter()
        .fold(HoldCounts::default(), |sum, g| sum + g.hold);
    Ok(Evaluation {
        engine: config.engine.to_string(),
        goals: if config.goals.centres.is_empty() || config.goals.paper_box_weight >= 1.0 {
            "paper".into()
        } else if config.goals.paper_box_weight <= 0.0 {
            "working".into()
        } else {
            "mixed".into()
        },
        rollouts: goals.len(),
        position_error_m: ErrorStats::of(&p),
        orientation_error_rad: ErrorStats::of(&o),
        action_values_past_limit: past_limit as f64 / values.max(1) as f64,
        diverged_episodes,
        hold_increment_share: hold.mean_increment_share(),
        hold_reversal_share: hold.reversal_share(),
        settle_time_s: ErrorStats::of(&settle),
        goal_noise: GoalNoiseStd {
            position_m: config.goal_noise.position_std,
            orientation_rad: config.goal_noise.orientation_std,
        },
    })
}

/// What one goal gave, at its end.
#[derive(Debug, Clone, Copy)]
pub struct GoalOutcome {
    /// Tool position error [m] to the goal.
    pub position_error: f64,
    /// Tool orientation error [rad] to the goal.
    pub orientation_error: f64,
    /// Hold smoothness over the goal's last [`HOLD_WINDOW_S`].
    pub hold: HoldCounts,
    /// From the goal's start until the tool stayed near where it ended [s] ([`settle_steps`]).
    pub settle_time_s: f64,
}

/// What one evaluation episode gave.
#[derive(Debug, Default)]
pub struct EpisodeOutcome {
    /// Each finished goal, in order.
    pub goals: Vec<GoalOutcome>,
    /// The policy's action values past the +-[`ACTION_LIMIT`] they are clipped to.
    pub action_values_past_limit: usize,
    /// Every action value the policy gave.
    pub action_values: usize,
    /// Cut short because its physics blew up.
    pub diverged: bool,
}

/// Runs `env` from `obs` (its reset's) for up to `steps` control steps under `policy`, or until
/// its physics blows up.
pub fn run_episode<P>(
    env: &mut ArmReach,
    mut obs: [f32; OBSERVATION_DIM],
    steps: usize,
    policy: &mut P,
) -> Result<EpisodeOutcome, EvalError>
where
    P: FnMut(&[f32; OBSERVATION_DIM]) -> Result<[f32; JOINTS], String>,
{
    let control_hz = env.skill().control_hz;
    let hold_steps = ((HOLD_WINDOW_S * control_hz).round() as usize).max(2);
    let mut outcome = EpisodeOutcome::default();
    let mut actions: Vec<[f32; JOINTS]> = Vec::new();
    let mut poses: Vec<(Vector3<f64>, UnitQuaternion<f64>)> = Vec::new();
    for _ in 0..steps {
        let action = policy(&obs).map_err(EvalError::Policy)?;
        outcome.action_values_past_limit += values_past_limit(&action);
        outcome.action_values += JOINTS;
        let out = env.step(&action);
        if out.terminated {
            outcome.diverged = true;
            break;
        }
        let tool = env.tool_pose_b();
        actions.push(action);
        poses.push((tool.translation.vector, tool.rotation));
        if out.goal_ended {
            outcome.goals.push(GoalOutcome {
                position_error: out.position_error,
                orientation_error: out.orientation_error,
                hold: HoldCounts::of(&actions[actions.len().saturating_sub(hold_steps)..]),
                settle_time_s: settle_steps(&poses) as f64 / control_hz,
            });
            actions.clear();
            poses.clear();
        }
        obs = out.observation;
    }
    Ok(outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_intervals_by_hand() {
        // z^2 / (n + z^2) = 3.841459 / 1003.841459 at a count of 0.
        let (lo, hi) = wilson_interval_95(0, 1000).unwrap();
        assert!(
            lo.abs() < 1e-12 && (hi - 0.003_826_758).abs() < 1e-8,
            "{lo} {hi}"
        );
        let (lo, hi) = wilson_interval_95(50, 5000).unwrap();
        assert!((lo - 0.007_593_773).abs() < 1e-8, "{lo}");
        assert!((hi - 0.013_158_575).abs() < 1e-8, "{hi}");
        let (lo, hi) = wilson_interval_95(67, 300).unwrap();
        assert!((lo - 0.179_871_358).abs() < 1e-8 && (hi - 0.273_791_086).abs() < 1e-8);
        // Every trial an event: n / (n + z^2) = 5 / 8.841459 up to 1, clamped there.
        let (lo, hi) = wilson_interval_95(5, 5).unwrap();
        assert!((lo - 0.565_517_5).abs() < 1e-6 && hi == 1.0, "{lo} {hi}");
        assert_eq!(wilson_interval_95(0, 0), None);
        assert_eq!(wilson_interval_95(3, 2), None);
    }

    #[test]
    fn stats_by_hand() {
        let s = ErrorStats::of(&[4.0, 1.0, 3.0, 2.0]);
        assert_eq!(s.mean, 2.5);
        assert!((s.std - 1.25_f64.sqrt()).abs() < 1e-12); // mean squared deviation 1.25
        assert_eq!(s.median, 2.5);
        assert_eq!(s.p90, 4.0); // rank ceil(3.6) = 4
        let ten: Vec<f64> = (1..=10).map(f64::from).collect();
        let s = ErrorStats::of(&ten);
        assert_eq!((s.median, s.p90), (5.5, 9.0)); // rank ceil(9.0) = 9
        assert_eq!(ErrorStats::of(&[7.0]).p90, 7.0);
        assert!(ErrorStats::of(&[]).mean.is_nan());
    }

    #[test]
    fn json_has_the_documented_shape() {
        let e = Evaluation {
            engine: "rapier".into(),
            goals: "paper".into(),
            rollouts: 2,
            position_error_m: ErrorStats::of(&[0.1, 0.3]),
            orientation_error_rad: ErrorStats::of(&[0.5, 0.5]),
            action_values_past_limit: 0.25,
            diverged_episodes: 0,
            hold_increment_share: 0.5,
            hold_reversal_share: 0.125,
            settle_time_s: ErrorStats::of(&[1.0, 2.0]),
            goal_noise: GoalNoiseStd {
                position_m: 0.005,
                orientation_rad: 0.0,
            },
        };
        let v: serde_json::Value = serde_json::to_value(&e).unwrap();
        assert_eq!(v["goal_noise"]["position_m"], 0.005);
        assert_eq!(v["goal_noise"]["orientation_rad"], 0.0);
        assert!(e.markdown().contains("goal noise: 0.005 m, 0 rad"));
        assert_eq!(v["rollouts"], 2);
        assert_eq!(v["engine"], "rapier");
        for key in ["mean", "std", "median", "p90"] {
            assert!(v["position_error_m"][key].is_number(), "{key}");
            assert!(v["orientation_error_rad"][key].is_number(), "{key}");
        }
        assert!(e.markdown().contains("| position [m] | 0.2000 | 0.1000 |"));
        assert_eq!(v["action_values_past_limit"], 0.25);
        assert!(e.markdown().contains("clipped to: 25.0 %"));
        assert_eq!(v["hold_increment_share"], 0.5);
        assert_eq!(v["hold_reversal_share"], 0.125);
        assert_eq!(v["settle_time_s"]["mean"], 1.5);
        assert!(e.markdown().contains(
            "mean increment 50.0 % of the largest; sign reversals above 20 % of it at 12.5 %"
        ));
        assert!(e
            .markdown()
            .contains("| settle time [s] (within 2 cm, 0.1 rad of the end) | 1.5000 |"));
        assert!(!e.markdown().contains("blew up"));
        let cut = Evaluation {
            diverged_episodes: 2,
            ..e
        };
        assert!(cut
            .markdown()
            .ends_with("episodes cut short by physics that blew up: 2\n"));
        assert_eq!(serde_json::to_value(&cut).unwrap()["diverged_episodes"], 2);
    }
}
