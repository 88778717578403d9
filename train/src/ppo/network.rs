//! The actor-critic: MLPs with ELU activations whose parameters kumi initialises from its own
//! seeded generator, a state-independent learned log standard deviation, and the PPO loss's
//! gradient over a minibatch, computed in parallel blocks of rows.
//!
//! **An asymmetric critic.** The actor may read only the leading values of each observation
//! row, the critic all of them ([`ActorCritic::asymmetric`]): the trailing values are what
//! only the critic sees in training (`[critic]` in a whole-body config), and an exported policy
//! never needs them.
//!
//! **Determinism.** A minibatch is cut into blocks of [`BLOCK_ROWS`] rows whatever the number
//! of threads; blocks run in parallel and their gradients are summed in block order, so a
//! seeded run gives the same bits on 1 thread or 16.

use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

pub use crate::nn::mlp::{DenseParameters, Mlp};
use crate::nn::Real;
use crate::ppo::loss::{block_loss, finish, Loss, LossCoefficients, Samples};

/// Rows per block of parallel work (forward passes and gradients).
/// 256 measured faster than 128 on both networks (`kumi bench learn`); a 1024-row minibatch
/// still makes four blocks.
pub const BLOCK_ROWS: usize = 256;

/// Names of the parameter groups (checkpoints), in the order of [`ActorCritic::groups`].
pub const GROUP_NAMES: [&str; 3] = ["actor", "critic", "log_std"];

/// A Gaussian policy (mean from the actor MLP, learned log-std) and a value function. The
/// critic reads whole observation rows, the actor their leading `actor.inputs()` values.
#[derive(Debug, Clone, PartialEq)]
pub struct ActorCritic<T = f32> {
    pub actor: Mlp<T>,
    pub critic: Mlp<T>,
    /// [action_dim]
    pub log_std: Vec<T>,
}

/// A gradient shaped like an [`ActorCritic`]'s parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Gradient<T> {
    pub actor: Vec<T>,
    pub critic: Vec<T>,
    pub log_std: Vec<T>,
}

impl<T: Real> Gradient<T> {
    fn zeros_like(net: &ActorCritic<T>) -> Self {
        Self {
            actor: vec![T::zero(); net.actor.params.len()],
            critic: vec![T::zero(); net.critic.params.len()],
            log_std: vec![T::zero(); net.log_std.len()],
        }
    }

    fn add(&mut self, other: &Self) {
        for (mine, theirs) in [
            (&mut self.actor, &other.actor),
            (&mut self.critic, &other.critic),
            (&mut self.log_std, &other.log_std),
        ] {
            mine.iter_mut().zip(theirs).for_each(|(a, b)| *a += *b);
        }
    }

    /// The groups in [`ActorCritic::groups_mut`]'s order.
    pub fn groups(&self) -> [&[T]; 3] {
        [&self.actor, &self.critic, &self.log_std]
    }
}

/// A minibatch: normalised observations [B, D] and what the rollout recorded for them.
#[derive(Debug, Clone, Copy)]
pub struct Minibatch<'a, T> {
    pub observations: &'a [T],
    pub samples: Samples<'a, T>,
}

/// The leading `keep` values of every `width`-long row of `x`.
pub fn leading_columns<T: Copy>(x: &[T], width: usize, keep: usize) -> Vec<T> {
    assert!(
        keep <= width && x.len().is_multiple_of(width),
        "rows of {width} values, {} in all, {keep} kept",
        x.len()
    );
    x.chunks(width)
        .flat_map(|row| &row[..keep])
        .copied()
        .collect()
}

impl<T: Real> ActorCritic<T> {
    /// Actor and critic both reading `obs_dim` values.
    pub fn new(
        obs_dim: usize,
        action_dim: usize,
        hidden: &[usize],
        initial_log_std: f32,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        Self::asymmetric(obs_dim, obs_dim, action_dim, hidden, initial_log_std, rng)
    }

    /// The critic reading `obs_dim` values, the actor the leading `actor_dim` of them
    /// (`actor_dim <= obs_dim`; equal, this is [`ActorCritic::new`], draw for draw).
    pub fn asymmetric(
        obs_dim: usize,
        actor_dim: usize,
        action_dim: usize,
        hidden: &[usize],
        initial_log_std: f32,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        assert!(
            0 < actor_dim && actor_dim <= obs_dim,
            "the actor reads {actor_dim} of {obs_dim} observation values"
        );
        let sizes = |inputs: usize, out: usize| [&[inputs][..], hidden, &[out]].concat();
        Self {
            actor: Mlp::new(&sizes(actor_dim, action_dim), 0.01, rng),
            critic: Mlp::new(&sizes(obs_dim, 1), 1.0, rng),
            log_std: vec![T::of(f64::from(initial_log_std)); action_dim],
        }
    }

    /// The values of observation rows [rows, D] the actor reads (all of them, borrowed, when it
    /// reads everything the critic does).
    fn actor_view<'a>(&self, observations: &'a [T]) -> std::borrow::Cow<'a, [T]> {
        let (d, k) = (self.critic.inputs(), self.actor.inputs());
        if k == d {
            std::borrow::Cow::Borrowed(observations)
        } else {
            std::borrow::Cow::Owned(leading_columns(observations, d, k))
        }
    }

    /// Sizes of the parameter groups (actor, critic, log-std), for the optimiser.
    pub fn group_sizes(&self) -> [usize; 3] {
        [
            self.actor.params.len(),
            self.critic.params.len(),
            self.log_std.len(),
        ]
    }

    /// The parameter groups, named [`GROUP_NAMES`], in the order of [`Gradient::groups`].
    pub fn groups(&self) -> [&[T]; 3] {
        [&self.actor.params, &self.critic.params, &self.log_std]
    }

    /// The parameter groups, mutably, in the order of [`Gradient::groups`].
    pub fn groups_mut(&mut self) -> [&mut [T]; 3] {
        [
            &mut self.actor.params,
            &mut self.critic.params,
            &mut self.log_std,
        ]
    }

    /// The policy means [rows, A] of normalised observations [rows, D] (the actor reads the
    /// leading values of each row).
    pub fn mean(&self, observations: &[T]) -> Vec<T> {
        forward_rows(&self.actor, &self.actor_view(observations))
    }

    /// Value estimates [rows] of normalised observations [rows, D].
    pub fn value(&self, observations: &[T]) -> Vec<T> {
        forward_rows(&self.critic, observations)
    }

    /// The PPO loss over a minibatch and its gradient with respect to every parameter.
    pub fn loss_and_gradient(
        &self,
        batch: &Minibatch<T>,
        c: &LossCoefficients,
    ) -> (Loss, Gradient<T>) {
        let (d, a) = (self.critic.inputs(), self.log_std.len());
        let rows = batch.samples.old_log_prob.len();
        assert_eq!(
            batch.observations.len(),
            rows * d,
            "observations are not [B, D]"
        );
        let starts: Vec<usize> = (0..rows).step_by(BLOCK_ROWS).collect();
        let blocks: Vec<_> = starts
            .par_iter()
            .map(|&start| {
                let end = (start + BLOCK_ROWS).min(rows);
                let r = end - start;
                let s = &batch.samples;
                let obs = &batch.observations[start * d..end * d];
                let actor = self.actor.forward_trace(&self.actor_view(obs), r);
                let critic = self.critic.forward_trace(obs, r);
                let samples = Samples {
                    actions: &s.actions[start * a..end * a],
                    old_log_prob: &s.old_log_prob[start..end],
                    advantages: &s.advantages[start..end],
                    returns: &s.returns[start..end],
                };
                let block = block_loss(
                    &samples,
                    actor.output(),
                    critic.output(),
                    &self.log_std,
                    c,
                    rows,
                );
                let mut g = Gradient::zeros_like(self);
                self.actor.backward(&actor, &block.d_mean, &mut g.actor);
                self.critic.backward(&critic, &block.d_value, &mut g.critic);
                g.log_std = block.d_log_std;
                let parts = [
                    block.policy,
                    block.value,
                    block.bound,
                    block.approx_kl,
                    block.clip_fraction,
                ];
                (g, parts)
            })
            .collect();
        // Summed in block order: the same bits on any number of threads.
        let mut gradient = Gradient::zeros_like(self);
        let mut parts = [0.0; 5];
        for (g, p) in &blocks {
            gradient.add(g);
            parts.iter_mut().zip(p).for_each(|(s, x)| *s += x);
        }
        let [policy, value, bound, kl, clipped] = parts;
        let loss = finish(
            policy,
            value,
            bound,
            kl,
            clipped,
            &self.log_std,
            &mut gradient.log_std,
            c,
        );
        (loss, gradient)
    }
}

/// A network's outputs for many rows, blocks of [`BLOCK_ROWS`] in parallel.
pub fn forward_rows<T: Real>(net: &Mlp<T>, x: &[T]) -> Vec<T> {
    let d = net.inputs();
    x.par_chunks(BLOCK_ROWS * d)
        .flat_map_iter(|block| net.forward(block, block.len() / d))
        .collect()
}
