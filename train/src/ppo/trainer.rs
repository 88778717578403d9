//! The PPO training loop: collect a rollout from parallel environments, then several epochs of
//! minibatch updates with Adam.

use std::time::Instant;

use candle_core::{Device, Result, Tensor, Var};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::env::Environment;
use crate::ppo::gae::{gae, GaeInput};
use crate::ppo::loss::{gaussian_log_prob, ppo_loss, LossCoefficients};
use crate::ppo::network::ActorCritic;
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
    /// Mean return of the episodes that ended in this rollout (NaN if none).
    pub mean_episode_return: f64,
    /// Mean final position [m] and orientation [rad] errors of goals that ended (NaN if none).
    pub final_position_error: f64,
    pub final_orientation_error: f64,
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
}

/// PPO over a set of environments.
pub struct Trainer<E: Environment> {
    pub config: PpoConfig,
    pub net: ActorCritic,
    pub norm: RunningNorm,
    envs: Vec<E>,
    observations: Vec<Vec<f32>>,
    episode_returns: Vec<f64>,
    optimizer: AdamW,
    rng: ChaCha8Rng,
    device: Device,
    pub env_steps: u64,
    pub iteration: usize,
}

fn mean(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        f64::NAN
    } else {
        xs.iter().sum::<f64>() / xs.len() as f64
    }
}

impl<E: Environment> Trainer<E> {
    pub fn new(config: PpoConfig, mut envs: Vec<E>) -> Result<Self> {
        assert!(!envs.is_empty(), "at least one environment");
        let device = Device::Cpu;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let (obs_dim, act_dim) = (envs[0].observation_dim(), envs[0].action_dim());
        let net = ActorCritic::new(
            obs_dim,
            act_dim,
            &config.hidden,
            config.initial_log_std,
            &mut rng,
            &device,
        )?;
        let optimizer = AdamW::new(
            net.vars(),
            // Plain Adam: candle's AdamW decays weights by default.
            ParamsAdamW {
                lr: config.learning_rate,
                weight_decay: 0.0,
                ..Default::default()
            },
        )?;
        let observations = envs.iter_mut().map(|e| e.reset()).collect();
        Ok(Self {
            norm: RunningNorm::new(obs_dim),
            episode_returns: vec![0.0; envs.len()],
            envs,
            observations,
            net,
            optimizer,
            rng,
            device,
            config,
            env_steps: 0,
            iteration: 0,
        })
    }

    fn normalized(&self, rows: &[Vec<f32>]) -> Result<Tensor> {
        let dim = self.norm.mean.len();
        let flat: Vec<f32> = rows.iter().flat_map(|r| self.norm.apply(r)).collect();
        Tensor::from_vec(flat, (rows.len(), dim), &self.device)
    }

    /// One iteration: a rollout, then the update. Returns its statistics.
    pub fn iterate(&mut self) -> Result<IterationStats> {
        let n = self.envs.len();
        let steps = self.config.rollout_steps;
        let act_dim = self.envs[0].action_dim();
        let log_std: Vec<f32> = self.net.log_std.as_tensor().to_vec1()?;

        let (mut obs_rows, mut next_rows) =
            (Vec::with_capacity(n * steps), Vec::with_capacity(n * steps));
        let mut actions = Vec::with_capacity(n * steps * act_dim);
        let (mut rewards, mut terminated, mut ended) = (Vec::new(), Vec::new(), Vec::new());
        let (mut returns_done, mut position_errors, mut orientation_errors) =
            (Vec::new(), Vec::new(), Vec::new());
        let collect_start = Instant::now();
        for _ in 0..steps {
            let obs = self.normalized(&self.observations)?;
            let mean: Vec<Vec<f32>> = self.net.actor.forward(&obs)?.to_vec2()?;
            let step_actions: Vec<Vec<f32>> = mean
                .iter()
                .map(|m| {
                    m.iter()
                        .zip(&log_std)
                        .map(|(mu, ls)| {
                            let z: f64 = StandardNormal.sample(&mut self.rng);
                            mu + ls.exp() * z as f32
                        })
                        .collect()
                })
                .collect();
            let transitions: Vec<_> = self
                .envs
                .par_iter_mut()
                .zip(&step_actions)
                .map(|(env, a)| env.step(a))
                .collect();
            for (i, tr) in transitions.into_iter().enumerate() {
                obs_rows.push(self.observations[i].clone());
                next_rows.push(tr.observation.clone());
                actions.extend_from_slice(&step_actions[i]);
                rewards.push(tr.reward as f32);
                terminated.push(tr.terminated);
                ended.push(tr.terminated || tr.truncated);
                self.episode_returns[i] += tr.reward;
                if let Some((p, o)) = tr.goal_errors {
                    position_errors.push(p);
                    orientation_errors.push(o);
                }
                if tr.terminated || tr.truncated {
                    returns_done.push(std::mem::take(&mut self.episode_returns[i]));
                    self.observations[i] = self.envs[i].reset();
                } else {
                    self.observations[i] = tr.observation;
                }
            }
        }
        let collect_s = collect_start.elapsed().as_secs_f64();
        self.env_steps += (n * steps) as u64;

        // Values and old log-probabilities under the statistics the actions were taken with.
        let obs = self.normalized(&obs_rows)?;
        let next_obs = self.normalized(&next_rows)?;
        let total = n * steps;
        let actions = Tensor::from_vec(actions, (total, act_dim), &self.device)?;
        let values: Vec<f32> = self.net.value(&obs)?.to_vec1()?;
        let next_values: Vec<f32> = self.net.value(&next_obs)?.to_vec1()?;
        let old_log_prob = gaussian_log_prob(
            &actions,
            &self.net.actor.forward(&obs)?,
            self.net.log_std.as_tensor(),
        )?
        .detach();
        let (advantages, returns) = gae(
            &GaeInput {
                rewards: &rewards,
                values: &values,
                next_values: &next_values,
                terminated: &terminated,
                ended: &ended,
            },
            n,
            self.config.gamma,
            self.config.lambda,
        );
        let adv_mean = advantages.iter().sum::<f32>() / total as f32;
        let adv_std = (advantages
            .iter()
            .map(|a| (a - adv_mean).powi(2))
            .sum::<f32>()
            / total as f32)
            .sqrt()
            .max(1e-8);
        let advantages = Tensor::from_vec(
            advantages
                .iter()
                .map(|a| (a - adv_mean) / adv_std)
                .collect::<Vec<_>>(),
            total,
            &self.device,
        )?;
        let returns = Tensor::from_vec(returns, total, &self.device)?;

        let update_start = Instant::now();
        let coefficients = LossCoefficients {
            clip: self.config.clip,
            value: self.config.value_coef,
            entropy: self.config.entropy_coef,
        };
        let minibatch = total / self.config.minibatches.max(1);
        let mut indices: Vec<u32> = (0..total as u32).collect();
        let (mut sums, mut count) = ([0.0_f64; 5], 0.0);
        for _ in 0..self.config.epochs {
            indices.shuffle(&mut self.rng);
            for chunk in indices.chunks(minibatch.max(1)) {
                let idx = Tensor::new(chunk, &self.device)?;
                let mb_obs = obs.index_select(&idx, 0)?;
                let new_log_prob = gaussian_log_prob(
                    &actions.index_select(&idx, 0)?,
                    &self.net.actor.forward(&mb_obs)?,
                    self.net.log_std.as_tensor(),
                )?;
                let loss = ppo_loss(
                    &new_log_prob,
                    &old_log_prob.index_select(&idx, 0)?,
                    &advantages.index_select(&idx, 0)?,
                    &self.net.value(&mb_obs)?,
                    &returns.index_select(&idx, 0)?,
                    self.net.log_std.as_tensor(),
                    &coefficients,
                )?;
                self.optimizer.backward_step(&loss.total)?;
                if self.config.desired_kl > 0.0 {
                    let lr = adapt_learning_rate(
                        self.optimizer.learning_rate(),
                        f64::from(loss.approx_kl),
                        self.config.desired_kl,
                    );
                    self.optimizer.set_learning_rate(lr);
                }
                for (s, v) in sums.iter_mut().zip([
                    loss.policy,
                    loss.value,
                    loss.entropy,
                    loss.approx_kl,
                    loss.clip_fraction,
                ]) {
                    *s += f64::from(v);
                }
                count += 1.0;
            }
        }
        let update_s = update_start.elapsed().as_secs_f64();
        // Statistics for the next rollout include this one's observations.
        let rows: Vec<&[f32]> = obs_rows.iter().map(|r| r.as_slice()).collect();
        self.norm.update(&rows);
        self.iteration += 1;

        let std: Vec<f32> = self.net.log_std.as_tensor().exp()?.to_vec1()?;
        Ok(IterationStats {
            iteration: self.iteration,
            env_steps: self.env_steps,
            collect_steps_per_s: total as f64 / collect_s,
            update_samples_per_s: total as f64 / update_s,
            mean_step_reward: rewards.iter().map(|r| f64::from(*r)).sum::<f64>() / total as f64,
            mean_episode_return: mean(&returns_done),
            final_position_error: mean(&position_errors),
            final_orientation_error: mean(&orientation_errors),
            policy_loss: sums[0] / count,
            value_loss: sums[1] / count,
            entropy: sums[2] / count,
            approx_kl: sums[3] / count,
            clip_fraction: sums[4] / count,
            action_std: std.iter().map(|s| f64::from(*s)).sum::<f64>() / std.len() as f64,
            learning_rate: self.optimizer.learning_rate(),
        })
    }

    /// The deterministic action (the mean) for a raw observation.
    pub fn act(&self, observation: &[f32]) -> Result<Vec<f32>> {
        let obs = self.normalized(&[observation.to_vec()])?;
        Ok(self.net.actor.forward(&obs)?.to_vec2::<f32>()?.remove(0))
    }

    /// All trainable variables.
    pub fn vars(&self) -> Vec<Var> {
        self.net.vars()
    }

    /// Saves the parameters (`params.safetensors`), the observation statistics and the
    /// counters (`progress.json`) into `dir`.
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
        let tensors: std::collections::HashMap<String, Tensor> = self
            .net
            .named_vars()
            .into_iter()
            .map(|(n, v)| (n, v.as_tensor().clone()))
            .collect();
        candle_core::safetensors::save(&tensors, &params).map_err(|e| CheckpointError::Format {
            path: params.display().to_string(),
            message: e.to_string(),
        })?;
        let progress = dir.join("progress.json");
        let json = serde_json::to_string_pretty(&Progress {
            iteration: self.iteration,
            env_steps: self.env_steps,
            normalizer: self.norm.clone(),
            learning_rate: self.optimizer.learning_rate(),
        })
        .map_err(|e| CheckpointError::Format {
            path: progress.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&progress, json).map_err(io(&progress))
    }

    /// Restores what [`Self::save_checkpoint`] wrote. The networks must have the same shapes.
    /// Adam's moment estimates are not saved (candle cannot serialise them): a resumed run
    /// restarts them.
    pub fn load_checkpoint(
        &mut self,
        dir: &std::path::Path,
    ) -> std::result::Result<(), CheckpointError> {
        let params = dir.join("params.safetensors");
        let format = |path: &std::path::Path, message: String| CheckpointError::Format {
            path: path.display().to_string(),
            message,
        };
        let tensors = candle_core::safetensors::load(&params, &self.device)
            .map_err(|e| format(&params, e.to_string()))?;
        for (name, var) in self.net.named_vars() {
            let t = tensors
                .get(&name)
                .ok_or_else(|| format(&params, format!("no tensor `{name}`")))?;
            if t.dims() != var.as_tensor().dims() {
                return Err(format(
                    &params,
                    format!(
                        "`{name}` has shape {:?}, the network {:?}",
                        t.dims(),
                        var.as_tensor().dims()
                    ),
                ));
            }
            var.set(t).map_err(|e| format(&params, e.to_string()))?;
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
        self.optimizer.set_learning_rate(progress.learning_rate);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::adapt_learning_rate;

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
