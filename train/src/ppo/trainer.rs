//! The PPO training loop: collect a rollout from parallel environments, then several epochs of
//! minibatch updates with Adam.

use std::time::Instant;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::env::Environment;
use crate::nn::adam::Adam;
use crate::ppo::gae::{gae, GaeInput};
use crate::ppo::loss::{gaussian_log_prob, Loss, LossCoefficients, Samples};
use crate::ppo::network::{ActorCritic, Minibatch, GROUP_NAMES};
use crate::ppo::normalizer::RunningNorm;

/// Every PPO hyperparameter. Defaults follow the paper's Table II where it gives one.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct PpoConfig {
    pub seed: u64,
    /// Environments stepped in parallel.
    pub num_envs: usize,
    /// Steps per environment per rollout.
    pub rollout_steps: usize,
    /// Environment steps to train for, all environments together.
    pub total_steps: u64,
    /// Hidden layer sizes of actor and critic (Table II: 256, 128).
    pub hidden: Vec<usize>,
    /// Adam learning rate (Table II: 1e-3); the starting value when `desired_kl > 0`.
    pub learning_rate: f64,
    /// Target KL divergence per minibatch for an adaptive learning rate
    /// ([`adapt_learning_rate`]); 0 keeps the learning rate fixed.
    pub desired_kl: f64,
    /// Discount (Table II: 0.99).
    pub gamma: f32,
    /// GAE lambda (Table II: 0.95).
    pub lambda: f32,
    /// Clipping range (Table II: 0.2).
    pub clip: f64,
    /// Entropy coefficient (Table II: 0.01).
    pub entropy_coef: f64,
    pub value_coef: f64,
    pub epochs: usize,
    pub minibatches: usize,
    /// Initial log standard deviation of the policy.
    pub initial_log_std: f32,
    /// Fraction of `total_steps` after which the learning rate and the entropy coefficient
    /// fall linearly, reaching `anneal_final` times their values at the end (1: no annealing).
    #[serde(default = "one")]
    pub anneal_after: f64,
    /// What the learning rate and the entropy coefficient are multiplied by at the end.
    #[serde(default = "one")]
    pub anneal_final: f64,
    /// When set, the policy's log standard deviation is capped by a schedule
    /// ([`PpoConfig::log_std_cap`]): `initial_log_std` until `anneal_after`, then falling
    /// linearly to this value at the end. Without it the noise is learnt alone, and under an
    /// adaptive learning rate at its floor it barely moves from `initial_log_std`. Left out
    /// of the serialised config when unset, so configs without it keep their fingerprints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_log_std: Option<f32>,
    /// When set, the weight of the bound loss ([`crate::ppo::loss::LossCoefficients::bound`]),
    /// which keeps the policy's mean within the [-1, 1] the action terms clip to (the form of
    /// rl_games' `bounds_loss_coef`, from 1 rather than its 1.1). Left out of the serialised
    /// config when unset; 0 is refused (leave it out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound_loss_coef: Option<f64>,
    /// When set, the critic learns at this rate (times the schedule's annealing factor, as a
    /// non-adaptive rate is) instead of the actor's: the adaptive rate follows the policy's KL
    /// divergence, which says nothing of how well the values fit, and held at its floor it
    /// left the critic's loss at 15-110 late in Tricycle's training. Left out of the
    /// serialised config when unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critic_learning_rate: Option<f64>,
}

fn one() -> f64 {
    1.0
}

impl PpoConfig {
    /// The annealing factor at `env_steps` (1 before `anneal_after`, `anneal_final` at the end).
    pub fn anneal(&self, env_steps: u64) -> f64 {
        let t = self.anneal_progress(env_steps);
        if t == 0.0 {
            return 1.0;
        }
        1.0 + (self.anneal_final - 1.0) * t
    }

    /// How far the annealed part has gone at `env_steps`: 0 until `anneal_after` (and always,
    /// when `anneal_after` is 1), 1 at `total_steps` and after, linear between.
    fn anneal_progress(&self, env_steps: u64) -> f64 {
        let progress = env_steps as f64 / self.total_steps.max(1) as f64;
        if progress <= self.anneal_after || self.anneal_after >= 1.0 {
            return 0.0;
        }
        ((progress - self.anneal_after) / (1.0 - self.anneal_after)).min(1.0)
    }

    /// The largest log standard deviation allowed at `env_steps`, when `final_log_std` is set:
    /// `initial_log_std` until `anneal_after`, `final_log_std` at the end, linear between.
    pub fn log_std_cap(&self, env_steps: u64) -> Option<f32> {
        let last = self.final_log_std?;
        let t = self.anneal_progress(env_steps) as f32;
        Some(self.initial_log_std + (last - self.initial_log_std) * t)
    }

    /// Why this config cannot train, if it cannot.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.num_envs == 0
            || self.rollout_steps == 0
            || self.epochs == 0
            || self.minibatches == 0
        {
            return Err("num_envs, rollout_steps, epochs and minibatches must be positive".into());
        }
        if self.minibatches > self.num_envs * self.rollout_steps {
            return Err(format!(
                "{} minibatches of a {}-sample rollout leave some empty",
                self.minibatches,
                self.num_envs * self.rollout_steps
            ));
        }
        if !(0.0..=1.0).contains(&self.anneal_after)
            || self.anneal_final.is_nan()
            || self.anneal_final <= 0.0
        {
            return Err("anneal_after must lie in [0, 1] and anneal_final be positive".into());
        }
        if let Some(rate) = self.critic_learning_rate {
            if !(rate.is_finite() && rate > 0.0) {
                return Err(format!(
                    "critic_learning_rate ({rate}) must be finite and > 0 (leave it out for the actor's)"
                ));
            }
        }
        if let Some(c) = self.bound_loss_coef {
            if !(c.is_finite() && c > 0.0) {
                return Err(format!(
                    "bound_loss_coef ({c}) must be finite and > 0 (leave it out for none)"
                ));
            }
        }
        if let Some(last) = self.final_log_std {
            if !last.is_finite() || last > self.initial_log_std {
                return Err(format!(
                    "final_log_std ({last}) must be finite and at most initial_log_std ({})",
                    self.initial_log_std
                ));
            }
            if self.anneal_after >= 1.0 {
                return Err(
                    "final_log_std needs anneal_after below 1: the noise falls after it".into(),
                );
            }
        }
        Ok(())
    }
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            num_envs: 16,
            rollout_steps: 256,
            total_steps: 480_000,
            hidden: vec![256, 128],
            learning_rate: 1e-3,
            desired_kl: 0.0,
            gamma: 0.99,
            lambda: 0.95,
            clip: 0.2,
            entropy_coef: 0.01,
            value_coef: 0.5,
            epochs: 5,
            minibatches: 4,
            initial_log_std: -0.5,
            anneal_after: 1.0,
            anneal_final: 1.0,
            final_log_std: None,
            bound_loss_coef: None,
            critic_learning_rate: None,
        }
    }
}

/// What one iteration measured.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct IterationStats {
    pub iteration: usize,
    pub env_steps: u64,
    /// Environment steps per second while collecting.
    pub collect_steps_per_s: f64,
    /// Samples per second through the update (epochs counted once).
    pub update_samples_per_s: f64,
    /// Mean reward per step in this rollout.
    pub mean_step_reward: f64,
    /// Episodes that ended in this rollout.
    pub episodes: usize,
    /// Mean return of the episodes that ended in this rollout (NaN if none).
    pub mean_episode_return: f64,
    /// The environment's own figures ([`Environment::metric_names`]), each the mean over the
    /// rollout of the values its steps reported (NaN if none did).
    pub metrics: Vec<(&'static str, f64)>,
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    pub approx_kl: f64,
    pub clip_fraction: f64,
    /// Mean policy standard deviation.
    pub action_std: f64,
    /// Adam's learning rate at the end of the iteration.
    pub learning_rate: f64,
}

/// Bounds of the adaptive learning rate.
const LEARNING_RATE_RANGE: (f64, f64) = (1e-5, 1e-2);

/// The adaptive learning-rate rule (as in rsl_rl, the trainer behind Isaac Lab): divide by 1.5
/// when the measured KL divergence exceeds twice the target, multiply by 1.5 when it falls
/// below half of it, within [1e-5, 1e-2].
pub fn adapt_learning_rate(learning_rate: f64, kl: f64, desired_kl: f64) -> f64 {
    let (lo, hi) = LEARNING_RATE_RANGE;
    if !kl.is_finite() || desired_kl <= 0.0 {
        learning_rate
    } else if kl > 2.0 * desired_kl {
        (learning_rate / 1.5).max(lo)
    } else if kl < 0.5 * desired_kl {
        (learning_rate * 1.5).min(hi)
    } else {
        learning_rate
    }
}

/// Errors saving or loading a checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Format { path: String, message: String },
}

/// Training progress saved beside the parameters.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct Progress {
    iteration: usize,
    env_steps: u64,
    normalizer: RunningNorm,
    /// Adam's learning rate (it adapts when `desired_kl > 0`).
    learning_rate: f64,
    /// Adam's step count (for its bias correction).
    #[serde(default)]
    adam_step: u64,
}

/// A config that cannot train.
#[derive(Debug, thiserror::Error)]
#[error("invalid PPO config: {0}")]
pub struct ConfigError(pub String);

/// The update half of PPO: the networks, Adam and the minibatch shuffling. Independent of
/// any environment (`kumi bench learn` times it on synthetic batches).
pub struct Learner {
    pub config: PpoConfig,
    pub net: ActorCritic,
    pub optimizer: Adam<f32>,
    rng: ChaCha8Rng,
}

/// PPO over a set of environments.
pub struct Trainer<E: Environment> {
    pub learner: Learner,
    pub norm: RunningNorm,
    envs: Vec<E>,
    observations: Vec<Vec<f32>>,
    episode_returns: Vec<f64>,
    /// Action noise.
    rng: ChaCha8Rng,
    pub env_steps: u64,
    pub iteration: usize,
}

/// What one rollout recorded, row `t * num_envs + i` for step `t` of environment `i`.
struct Rollout {
    /// Raw observations and the observations after each step.
    observations: Vec<Vec<f32>>,
    /// The observations as the policy saw them (normalised), [rows, D].
    normalized: Vec<f32>,
    next_observations: Vec<Vec<f32>>,
    /// [rows, A]
    actions: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    ended: Vec<bool>,
    episode_returns: Vec<f64>,
    /// Per metric name: sum and count.
    metrics: std::collections::HashMap<&'static str, (f64, usize)>,
    seconds: f64,
}

/// A rollout made ready for the update.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch {
    /// Normalised observations [rows, D].
    pub observations: Vec<f32>,
    /// [rows, A]
    pub actions: Vec<f32>,
    /// Log-probabilities of the actions under the policy that took them, [rows].
    pub old_log_prob: Vec<f32>,
    /// Normalised advantages, [rows].
    pub advantages: Vec<f32>,
    /// Value targets, [rows].
    pub returns: Vec<f32>,
}

fn mean(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        f64::NAN
    } else {
        xs.iter().sum::<f64>() / xs.len() as f64
    }
}

/// (x - mean) / std over the batch (std floored at 1e-8).
fn standardize(xs: &[f32]) -> Vec<f32> {
    let n = xs.len() as f32;
    let m = xs.iter().sum::<f32>() / n;
    let std = (xs.iter().map(|a| (a - m).powi(2)).sum::<f32>() / n)
        .sqrt()
        .max(1e-8);
    xs.iter().map(|a| (a - m) / std).collect()
}

/// Copies the rows `indices` of a [rows, width] array.
fn gather(xs: &[f32], width: usize, indices: &[u32]) -> Vec<f32> {
    indices
        .iter()
        .flat_map(|&i| &xs[i as usize * width..(i as usize + 1) * width])
        .copied()
        .collect()
}

impl Learner {
    /// Lowers the policy's log standard deviations to the schedule's cap at `env_steps`
    /// ([`PpoConfig::log_std_cap`]; nothing without a schedule).
    fn cap_log_std(&mut self, env_steps: u64) {
        if let Some(cap) = self.config.log_std_cap(env_steps) {
            self.net.log_std.iter_mut().for_each(|l| *l = l.min(cap));
        }
    }

    /// Fresh networks for `obs_dim` observations and `act_dim` actions, initialised from the
    /// seed; the minibatch shuffling draws from its own stream of the same seed.
    pub fn new(
        config: PpoConfig,
        obs_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
    ) -> std::result::Result<Self, ConfigError> {
        Self::asymmetric(config, obs_dim, obs_dim, act_dim, rng)
    }

    /// As [`Learner::new`], the actor reading the leading `actor_dim` of the `obs_dim`
    /// observation values the critic reads ([`ActorCritic::asymmetric`]).
    pub fn asymmetric(
        config: PpoConfig,
        obs_dim: usize,
        actor_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
    ) -> std::result::Result<Self, ConfigError> {
        config.check().map_err(ConfigError)?;
        if actor_dim == 0 || actor_dim > obs_dim {
            return Err(ConfigError(format!(
                "the actor reads {actor_dim} of {obs_dim} observation values"
            )));
        }
        let net = ActorCritic::asymmetric(
            obs_dim,
            actor_dim,
            act_dim,
            &config.hidden,
            config.initial_log_std,
            rng,
        );
        let mut shuffle = ChaCha8Rng::seed_from_u64(config.seed);
        shuffle.set_stream(1);
        Ok(Self {
            optimizer: Adam::new(config.learning_rate, &net.group_sizes()),
            net,
            rng: shuffle,
            config,
        })
    }

    /// Each parameter group's own learning rate (in [`ActorCritic::groups`]' order), where it
    /// has one: the critic's, when `critic_learning_rate` is set.
    fn group_rates(&self, anneal: f64) -> [Option<f64>; 3] {
        [
            None,
            self.config.critic_learning_rate.map(|r| r * anneal),
            None,
        ]
    }

    /// Epochs of shuffled minibatch steps; returns the mean loss parts.
    pub fn update(&mut self, data: &Batch, env_steps: u64) -> Loss {
        let (d, a) = (self.net.critic.inputs(), self.net.log_std.len());
        let total = data.returns.len();
        let anneal = self.config.anneal(env_steps);
        let coefficients = LossCoefficients {
            clip: self.config.clip,
            value: self.config.value_coef,
            entropy: self.config.entropy_coef * anneal,
            bound: self.config.bound_loss_coef.unwrap_or(0.0),
        };
        if self.config.desired_kl <= 0.0 {
            self.optimizer.learning_rate = self.config.learning_rate * anneal;
        }
        let rates = self.group_rates(anneal);
        let minibatch = total.div_ceil(self.config.minibatches);
        let mut indices: Vec<u32> = (0..total as u32).collect();
        let (mut sum, mut count) = (Loss::default(), 0.0);
        for _ in 0..self.config.epochs {
            indices.shuffle(&mut self.rng);
            for chunk in indices.chunks(minibatch) {
                let (observations, actions) = (
                    gather(&data.observations, d, chunk),
                    gather(&data.actions, a, chunk),
                );
                let (old_log_prob, advantages, returns) = (
                    gather(&data.old_log_prob, 1, chunk),
                    gather(&data.advantages, 1, chunk),
                    gather(&data.returns, 1, chunk),
                );
                let batch = Minibatch {
                    observations: &observations,
                    samples: Samples {
                        actions: &actions,
                        old_log_prob: &old_log_prob,
                        advantages: &advantages,
                        returns: &returns,
                    },
                };
                let (loss, gradient) = self.net.loss_and_gradient(&batch, &coefficients);
                self.optimizer
                    .update_with(&mut self.net.groups_mut(), &gradient.groups(), &rates);
                if self.config.desired_kl > 0.0 {
                    self.optimizer.learning_rate = adapt_learning_rate(
                        self.optimizer.learning_rate,
                        loss.approx_kl,
                        self.config.desired_kl,
                    );
                }
                sum.total += loss.total;
                sum.policy += loss.policy;
                sum.value += loss.value;
                sum.entropy += loss.entropy;
                sum.bound += loss.bound;
                sum.approx_kl += loss.approx_kl;
                sum.clip_fraction += loss.clip_fraction;
                count += 1.0;
            }
        }
        self.cap_log_std(env_steps);
        Loss {
            total: sum.total / count,
            policy: sum.policy / count,
            value: sum.value / count,
            entropy: sum.entropy / count,
            bound: sum.bound / count,
            approx_kl: sum.approx_kl / count,
            clip_fraction: sum.clip_fraction / count,
        }
    }
}

impl<E: Environment> Trainer<E> {
    pub fn new(config: PpoConfig, mut envs: Vec<E>) -> std::result::Result<Self, ConfigError> {
        if envs.is_empty() {
            return Err(ConfigError("no environments".into()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let (obs_dim, act_dim) = (envs[0].observation_dim(), envs[0].action_dim());
        let actor_dim = envs[0].actor_observation_dim();
        let learner = Learner::asymmetric(config, obs_dim, actor_dim, act_dim, &mut rng)?;
        let observations = envs.iter_mut().map(|e| e.reset()).collect();
        Ok(Self {
            norm: RunningNorm::new(obs_dim),
            episode_returns: vec![0.0; envs.len()],
            envs,
            observations,
            learner,
            rng,
            env_steps: 0,
            iteration: 0,
        })
    }

    pub fn config(&self) -> &PpoConfig {
        &self.learner.config
    }

    pub fn net(&self) -> &ActorCritic {
        &self.learner.net
    }

    /// Normalised observations, [rows, D].
    fn normalized(&self, rows: &[Vec<f32>]) -> Vec<f32> {
        rows.iter().flat_map(|r| self.norm.apply(r)).collect()
    }

    /// Steps every environment `rollout_steps` times with actions sampled from the policy.
    fn collect(&mut self) -> Rollout {
        let (n, steps) = (self.envs.len(), self.learner.config.rollout_steps);
        let std: Vec<f32> = self.learner.net.log_std.iter().map(|l| l.exp()).collect();
        let mut r = Rollout {
            observations: Vec::with_capacity(n * steps),
            normalized: Vec::new(),
            next_observations: Vec::with_capacity(n * steps),
            actions: Vec::with_capacity(n * steps * std.len()),
            rewards: Vec::with_capacity(n * steps),
            terminated: Vec::with_capacity(n * steps),
            ended: Vec::with_capacity(n * steps),
            episode_returns: Vec::new(),
            metrics: Default::default(),
            seconds: 0.0,
        };
        let start = Instant::now();
        for _ in 0..steps {
            let normalized = self.normalized(&self.observations);
            let mut actions = self.learner.net.mean(&normalized);
            r.normalized.extend_from_slice(&normalized);
            for (k, a) in actions.iter_mut().enumerate() {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                *a += std[k % std.len()] * z as f32;
            }
            let transitions: Vec<_> = self
                .envs
                .par_iter_mut()
                .zip(actions.par_chunks(std.len()))
                .map(|(env, a)| env.step(a))
                .collect();
            r.actions.extend_from_slice(&actions);
            for (i, tr) in transitions.into_iter().enumerate() {
                r.rewards.push(tr.reward as f32);
                r.terminated.push(tr.terminated);
                r.ended.push(tr.terminated || tr.truncated);
                self.episode_returns[i] += tr.reward;
                for (name, value) in &tr.metrics {
                    let entry = r.metrics.entry(name).or_default();
                    entry.0 += value;
                    entry.1 += 1;
                }
                let next = if tr.terminated || tr.truncated {
                    r.episode_returns
                        .push(std::mem::take(&mut self.episode_returns[i]));
                    self.envs[i].reset()
                } else {
                    tr.observation.clone()
                };
                r.next_observations.push(tr.observation);
                r.observations
                    .push(std::mem::replace(&mut self.observations[i], next));
            }
        }
        r.seconds = start.elapsed().as_secs_f64();
        r
    }

    /// Values, old log-probabilities (under the statistics the actions were taken with), GAE.
    /// Moves the normalised observations and the actions out of the rollout.
    fn prepare(&self, rollout: &mut Rollout) -> Batch {
        let observations = std::mem::take(&mut rollout.normalized);
        let actions = std::mem::take(&mut rollout.actions);
        let values = self.learner.net.value(&observations);
        let next_values = self
            .learner
            .net
            .value(&self.normalized(&rollout.next_observations));
        let old_log_prob = gaussian_log_prob(
            &actions,
            &self.learner.net.mean(&observations),
            &self.learner.net.log_std,
        );
        let (advantages, returns) = gae(
            &GaeInput {
                rewards: &rollout.rewards,
                values: &values,
                next_values: &next_values,
                terminated: &rollout.terminated,
                ended: &rollout.ended,
            },
            self.envs.len(),
            self.learner.config.gamma,
            self.learner.config.lambda,
        );
        Batch {
            observations,
            actions,
            old_log_prob,
            advantages: standardize(&advantages),
            returns,
        }
    }

    /// One iteration: a rollout, then the update. Returns its statistics.
    pub fn iterate(&mut self) -> IterationStats {
        let mut rollout = self.collect();
        let total = rollout.rewards.len();
        self.env_steps += total as u64;
        let data = self.prepare(&mut rollout);
        let update_start = Instant::now();
        let loss = self.learner.update(&data, self.env_steps);
        let update_s = update_start.elapsed().as_secs_f64();
        // Statistics for the next rollout include this one's observations.
        let rows: Vec<&[f32]> = rollout.observations.iter().map(|r| r.as_slice()).collect();
        self.norm.update(&rows);
        self.iteration += 1;
        let std = self.learner.net.log_std.iter().map(|l| f64::from(l.exp()));
        IterationStats {
            iteration: self.iteration,
            env_steps: self.env_steps,
            collect_steps_per_s: total as f64 / rollout.seconds,
            update_samples_per_s: total as f64 / update_s,
            mean_step_reward: rollout.rewards.iter().map(|r| f64::from(*r)).sum::<f64>()
                / total as f64,
            episodes: rollout.episode_returns.len(),
            mean_episode_return: mean(&rollout.episode_returns),
            metrics: self.envs[0]
                .metric_names()
                .iter()
                .map(|name| {
                    let (sum, n) = rollout.metrics.get(name).copied().unwrap_or_default();
                    (*name, if n == 0 { f64::NAN } else { sum / n as f64 })
                })
                .collect(),
            policy_loss: loss.policy,
            value_loss: loss.value,
            entropy: loss.entropy,
            approx_kl: loss.approx_kl,
            clip_fraction: loss.clip_fraction,
            action_std: std.sum::<f64>() / self.learner.net.log_std.len() as f64,
            learning_rate: self.learner.optimizer.learning_rate,
        }
    }

    /// One rollout without an update (what `kumi bench learn` times): environment steps per
    /// second, policy inference and action sampling included.
    pub fn collect_rate(&mut self) -> f64 {
        let rollout = self.collect();
        rollout.rewards.len() as f64 / rollout.seconds
    }

    /// The deterministic action (the mean) for a raw observation (the environment's whole
    /// observation, what only the critic sees included).
    pub fn act(&self, observation: &[f32]) -> Vec<f32> {
        self.learner.net.mean(&self.norm.apply(observation))
    }

    /// The observation normaliser of what the actor reads (the leading values): what an
    /// exported policy carries.
    pub fn actor_norm(&self) -> RunningNorm {
        let k = self.learner.net.actor.inputs();
        RunningNorm {
            mean: self.norm.mean[..k].to_vec(),
            var: self.norm.var[..k].to_vec(),
            count: self.norm.count,
        }
    }

    /// Saves the parameters and Adam's moments (`params.safetensors`), the observation
    /// statistics and the counters (`progress.json`) into `dir`.
    pub fn save_checkpoint(
        &self,
        dir: &std::path::Path,
    ) -> std::result::Result<(), CheckpointError> {
        let io = |path: &std::path::Path| {
            let path = path.display().to_string();
            move |source| CheckpointError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let params = dir.join("params.safetensors");
        checkpoint::save(&params, &self.named_arrays()).map_err(|message| {
            CheckpointError::Format {
                path: params.display().to_string(),
                message,
            }
        })?;
        let progress = dir.join("progress.json");
        let json = serde_json::to_string_pretty(&Progress {
            iteration: self.iteration,
            env_steps: self.env_steps,
            normalizer: self.norm.clone(),
            learning_rate: self.learner.optimizer.learning_rate,
            adam_step: self.learner.optimizer.step,
        })
        .map_err(|e| CheckpointError::Format {
            path: progress.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&progress, json).map_err(io(&progress))
    }

    /// Every saved array with its stable name: `actor`, `critic`, `log_std` and Adam's moments
    /// (`adam.m.<group>`, `adam.v.<group>`).
    fn named_arrays(&self) -> Vec<(String, &[f32])> {
        let (net, adam) = (&self.learner.net, &self.learner.optimizer);
        let mut v = Vec::new();
        for (g, (name, params)) in GROUP_NAMES.iter().zip(net.groups()).enumerate() {
            v.push((name.to_string(), params));
            v.push((format!("adam.m.{name}"), adam.first[g].as_slice()));
            v.push((format!("adam.v.{name}"), adam.second[g].as_slice()));
        }
        v
    }

    /// Restores what [`Self::save_checkpoint`] wrote. The networks must have the same shapes.
    pub fn load_checkpoint(
        &mut self,
        dir: &std::path::Path,
    ) -> std::result::Result<(), CheckpointError> {
        let params = dir.join("params.safetensors");
        let format = |path: &std::path::Path, message: String| CheckpointError::Format {
            path: path.display().to_string(),
            message,
        };
        let mut arrays = checkpoint::load(&params).map_err(|m| format(&params, m))?;
        let mut take = |name: &str, into: &mut [f32]| {
            let found = arrays
                .remove(name)
                .ok_or_else(|| format(&params, format!("no array `{name}`")))?;
            if found.len() != into.len() {
                return Err(format(
                    &params,
                    format!(
                        "`{name}` has {} values, the network {}{}",
                        found.len(),
                        into.len(),
                        if name.contains("critic") {
                            " (a critic that sees other values: resume with the [critic] \
                             section the checkpoint was trained with)"
                        } else {
                            ""
                        }
                    ),
                ));
            }
            into.copy_from_slice(&found);
            Ok(())
        };
        let (net, adam) = (&mut self.learner.net, &mut self.learner.optimizer);
        for (g, (name, params)) in GROUP_NAMES.iter().zip(net.groups_mut()).enumerate() {
            take(name, params)?;
            take(&format!("adam.m.{name}"), &mut adam.first[g])?;
            take(&format!("adam.v.{name}"), &mut adam.second[g])?;
        }
        let progress_path = dir.join("progress.json");
        let text =
            std::fs::read_to_string(&progress_path).map_err(|source| CheckpointError::Io {
                path: progress_path.display().to_string(),
                source,
            })?;
        let progress: Progress =
            serde_json::from_str(&text).map_err(|e| format(&progress_path, e.to_string()))?;
        if progress.normalizer.mean.len() != self.norm.mean.len() {
            return Err(format(
                &progress_path,
                "observation size differs from this environment's".into(),
            ));
        }
        self.iteration = progress.iteration;
        self.env_steps = progress.env_steps;
        self.norm = progress.normalizer;
        self.learner.optimizer.learning_rate = progress.learning_rate;
        self.learner.optimizer.step = progress.adam_step;
        // The noise cap is not applied here: a resumed run's first rollout runs at the
        // checkpoint's noise, and the cap holds from its first update. Applying it here would
        // change what tricycle_settle.toml's documented second stage reproduces.
        Ok(())
    }
}

/// Named `f32` arrays in a safetensors file (one-dimensional tensors).
mod checkpoint {
    use std::collections::HashMap;

    use safetensors::{tensor::TensorView, Dtype, SafeTensors};

    pub fn save(path: &std::path::Path, arrays: &[(String, &[f32])]) -> Result<(), String> {
        let bytes: Vec<(String, Vec<u8>, usize)> = arrays
            .iter()
            .map(|(name, a)| {
                let b = a.iter().flat_map(|x| x.to_le_bytes()).collect();
                (name.clone(), b, a.len())
            })
            .collect();
        let views = bytes
            .iter()
            .map(|(name, b, n)| {
                TensorView::new(Dtype::F32, vec![*n], b)
                    .map(|v| (name.clone(), v))
                    .map_err(|e| e.to_string())
            })
            .collect::<Result<Vec<_>, _>>()?;
        safetensors::serialize_to_file(views, None, path).map_err(|e| e.to_string())
    }

    pub fn load(path: &std::path::Path) -> Result<HashMap<String, Vec<f32>>, String> {
        let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
        let file = SafeTensors::deserialize(&bytes).map_err(|e| e.to_string())?;
        file.tensors()
            .into_iter()
            .map(|(name, view)| {
                if view.dtype() != Dtype::F32 {
                    return Err(format!("`{name}` is {:?}, not F32", view.dtype()));
                }
                let values = view
                    .data()
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect();
                Ok((name, values))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::{adapt_learning_rate, gather, standardize, PpoConfig};

    #[test]
    fn annealing_by_hand() {
        let c = PpoConfig {
            total_steps: 1000,
            anneal_after: 0.6,
            anneal_final: 0.1,
            ..PpoConfig::default()
        };
        assert_eq!(c.anneal(0), 1.0);
        assert_eq!(c.anneal(600), 1.0);
        // Halfway through the annealed part: 1 + (0.1 - 1) * 0.5 = 0.55.
        assert!((c.anneal(800) - 0.55).abs() < 1e-12);
        assert!((c.anneal(1000) - 0.1).abs() < 1e-12);
        assert!((c.anneal(5000) - 0.1).abs() < 1e-12, "held at the end");
        // Off by default.
        assert_eq!(PpoConfig::default().anneal(479_999), 1.0);
    }

    #[test]
    fn the_noise_cap_by_hand() {
        let c = PpoConfig {
            total_steps: 1000,
            initial_log_std: -0.5,
            anneal_after: 0.6,
            final_log_std: Some(-1.5),
            ..PpoConfig::default()
        };
        assert_eq!(c.log_std_cap(0), Some(-0.5));
        assert_eq!(c.log_std_cap(600), Some(-0.5));
        // Halfway through the annealed part: -0.5 + (-1.5 + 0.5) * 0.5 = -1.0.
        assert!((c.log_std_cap(800).unwrap() + 1.0).abs() < 1e-6);
        assert_eq!(c.log_std_cap(1000), Some(-1.5));
        assert_eq!(c.log_std_cap(9000), Some(-1.5), "held at the end");
        // Off by default: the noise is learnt alone.
        assert_eq!(PpoConfig::default().log_std_cap(1000), None);
    }

    #[test]
    fn an_unset_noise_schedule_leaves_the_config_fingerprint_alone() {
        // Exported policies record a fingerprint of their config's values: configs written
        // before `final_log_std` existed must serialise as they did.
        let text = serde_json::to_string(&PpoConfig::default()).unwrap();
        assert!(!text.contains("final_log_std"), "{text}");
        let set = PpoConfig {
            final_log_std: Some(-1.9),
            anneal_after: 0.75,
            ..PpoConfig::default()
        };
        assert!(serde_json::to_string(&set)
            .unwrap()
            .contains("\"final_log_std\":-1.9"));
        // Nor does an unset bound loss, or an unset critic rate.
        assert!(!text.contains("bound_loss_coef"), "{text}");
        assert!(!text.contains("critic_learning_rate"), "{text}");
    }

    #[test]
    fn configs_that_cannot_train_are_refused() {
        assert!(PpoConfig::default().check().is_ok());
        for bad in [
            PpoConfig {
                num_envs: 0,
                ..PpoConfig::default()
            },
            PpoConfig {
                minibatches: 5000,
                ..PpoConfig::default()
            },
            PpoConfig {
                anneal_final: 0.0,
                ..PpoConfig::default()
            },
            PpoConfig {
                anneal_after: 1.5,
                ..PpoConfig::default()
            },
            PpoConfig {
                final_log_std: Some(0.0), // above initial_log_std (-0.5): noise would grow
                anneal_after: 0.5,
                ..PpoConfig::default()
            },
            PpoConfig {
                final_log_std: Some(f32::NAN),
                anneal_after: 0.5,
                ..PpoConfig::default()
            },
            PpoConfig {
                final_log_std: Some(-1.0), // never reached: nothing anneals
                anneal_after: 1.0,
                ..PpoConfig::default()
            },
            PpoConfig {
                bound_loss_coef: Some(-0.01),
                ..PpoConfig::default()
            },
            PpoConfig {
                bound_loss_coef: Some(f64::NAN),
                ..PpoConfig::default()
            },
            PpoConfig {
                bound_loss_coef: Some(0.0), // as unset, but a different fingerprint
                ..PpoConfig::default()
            },
            PpoConfig {
                critic_learning_rate: Some(0.0),
                ..PpoConfig::default()
            },
            PpoConfig {
                critic_learning_rate: Some(f64::INFINITY),
                ..PpoConfig::default()
            },
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn rows_are_gathered_and_advantages_standardised() {
        let xs = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(gather(&xs, 2, &[2, 0]), vec![5.0, 6.0, 1.0, 2.0]);
        let z = standardize(&[1.0, 3.0]);
        assert_eq!(z, vec![-1.0, 1.0]);
    }

    #[test]
    fn the_critic_keeps_its_own_rate_annealed_and_the_rest_the_shared_one() {
        let c = PpoConfig {
            total_steps: 1000,
            anneal_after: 0.6,
            anneal_final: 0.1,
            critic_learning_rate: Some(3e-4),
            ..PpoConfig::default()
        };
        let mut rng = rand::SeedableRng::seed_from_u64(0);
        let learner = super::Learner::new(c.clone(), 4, 2, &mut rng).unwrap();
        let rates = learner.group_rates(c.anneal(800));
        assert_eq!(rates[0], None, "the actor at the shared rate");
        assert!((rates[1].unwrap() - 3e-4 * 0.55).abs() < 1e-15);
        assert_eq!(rates[2], None, "the noise at the shared rate");
        let shared = super::Learner::new(PpoConfig::default(), 4, 2, &mut rng).unwrap();
        assert_eq!(shared.group_rates(1.0), [None; 3]);
    }

    #[test]
    fn learning_rate_adapts_to_the_kl_divergence() {
        // Too large a step: divide by 1.5; too small: multiply; in the band: keep.
        assert!((adapt_learning_rate(1e-3, 0.03, 0.01) - 1e-3 / 1.5).abs() < 1e-15);
        assert!((adapt_learning_rate(1e-3, 0.004, 0.01) - 1.5e-3).abs() < 1e-15);
        assert_eq!(adapt_learning_rate(1e-3, 0.01, 0.01), 1e-3);
        // Bounded, and off when no target is set or the KL is not a number.
        assert_eq!(adapt_learning_rate(1e-5, 1.0, 0.01), 1e-5);
        assert_eq!(adapt_learning_rate(1e-2, 0.0, 0.01), 1e-2);
        assert_eq!(adapt_learning_rate(1e-3, 1.0, 0.0), 1e-3);
        assert_eq!(adapt_learning_rate(1e-3, f64::NAN, 0.01), 1e-3);
    }
}
