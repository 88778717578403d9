//! The PPO loss (Schulman et al. 2017; the paper's Eq. 3) for a diagonal Gaussian policy with a
//! state-independent log standard deviation, and its gradient with respect to the policy mean,
//! the value estimates and the log standard deviation. Pure functions over row-major slices:
//! B rows (samples), A action dimensions.
//!
//! total = -mean(min(r A, clip(r, 1 - eps, 1 + eps) A)) + c1 mean((V - R)^2) - c2 H
//!         + cb mean(sum_j excess(mu_j)^2),
//! r = exp(log pi(a|s) - log pi_old(a|s)), excess(mu) = how far the mean lies past
//! [-MEAN_BOUND, MEAN_BOUND] (the form of rl_games' `bounds_loss_coef`, from +-1 rather than its
//! soft bound of 1.1; 0 unless cb > 0).

use crate::nn::Real;

/// ln(2 pi) / 2.
const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// log N(action | mean, exp(log_std)) of each row, summed over action dimensions.
/// `actions`, `mean`: [B, A]; `log_std`: [A]. Returns [B].
pub fn gaussian_log_prob<T: Real>(actions: &[T], mean: &[T], log_std: &[T]) -> Vec<T> {
    let a = log_std.len();
    assert_eq!(
        actions.len(),
        mean.len(),
        "actions and means differ in shape"
    );
    let half_ln_2pi = T::of(HALF_LN_2PI);
    let half = T::of(0.5);
    let inv_std: Vec<T> = log_std.iter().map(|l| (-*l).exp()).collect();
    actions
        .chunks_exact(a)
        .zip(mean.chunks_exact(a))
        .map(|(x, mu)| {
            (0..a)
                .map(|j| {
                    let z = (x[j] - mu[j]) * inv_std[j];
                    -half * z * z - log_std[j] - half_ln_2pi
                })
                .sum()
        })
        .collect()
}

/// Entropy of the Gaussian, summed over action dimensions: sum(log_std) + A (1 + ln 2 pi) / 2.
pub fn gaussian_entropy<T: Real>(log_std: &[T]) -> T {
    log_std.iter().copied().sum::<T>() + T::of(log_std.len() as f64 * (0.5 + HALF_LN_2PI))
}

/// Where the bound loss starts: every action term clips its values to [-1, 1], so a mean past
/// it commands no more than 1 does, and nothing but noise tells the policy where it lies.
pub const MEAN_BOUND: f64 = 1.0;

/// PPO coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossCoefficients {
    /// Clipping range epsilon.
    pub clip: f64,
    /// Value loss weight c1.
    pub value: f64,
    /// Entropy bonus weight c2.
    pub entropy: f64,
    /// Bound loss weight cb (0: none): keeps the policy's mean within [-MEAN_BOUND,
    /// MEAN_BOUND].
    pub bound: f64,
}

/// How far `mean` lies past [-MEAN_BOUND, MEAN_BOUND] (signed; 0 within; NaN for NaN).
pub fn excess(mean: f64) -> f64 {
    if mean.is_nan() {
        return f64::NAN;
    }
    (mean - MEAN_BOUND).max(0.0) + (mean + MEAN_BOUND).min(0.0)
}

/// The loss and its parts (means over the minibatch), for logging.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Loss {
    pub total: f64,
    pub policy: f64,
    pub value: f64,
    pub entropy: f64,
    /// Mean over samples of the squared excess of the policy's mean, summed over action
    /// dimensions (0 when the bound loss is off).
    pub bound: f64,
    /// Mean of (ratio - 1) - ln(ratio): a low-variance estimate of KL(old || new).
    pub approx_kl: f64,
    /// Fraction of samples whose ratio was outside the clipping range.
    pub clip_fraction: f64,
}

/// One block of a minibatch: what the rollout recorded for its rows.
#[derive(Debug, Clone, Copy)]
pub struct Samples<'a, T> {
    /// [B, A]
    pub actions: &'a [T],
    /// [B]
    pub old_log_prob: &'a [T],
    /// [B] (normalised)
    pub advantages: &'a [T],
    /// [B]
    pub returns: &'a [T],
}

/// The sample terms of the loss over some rows of a minibatch of `minibatch` rows, and their
/// gradient. Sums of the per-sample means' terms, so that blocks add up to the minibatch.
#[derive(Debug, Clone)]
pub struct BlockLoss<T> {
    /// Sums over the block of policy, value, bound, approx-KL and clipped terms, each divided
    /// by the minibatch size.
    pub policy: f64,
    pub value: f64,
    pub bound: f64,
    pub approx_kl: f64,
    pub clip_fraction: f64,
    /// d total / d mean, [B, A].
    pub d_mean: Vec<T>,
    /// d total / d value, [B].
    pub d_value: Vec<T>,
    /// d total / d log_std from these samples (the entropy term is added once per minibatch by
    /// [`finish`]), [A].
    pub d_log_std: Vec<T>,
}

/// The policy and value terms of the loss for a block of rows and their gradients. `mean`
/// [B, A] and `values` [B] are the networks' outputs for the block's observations.
pub fn block_loss<T: Real>(
    samples: &Samples<T>,
    mean: &[T],
    values: &[T],
    log_std: &[T],
    c: &LossCoefficients,
    minibatch: usize,
) -> BlockLoss<T> {
    let a = log_std.len();
    let rows = samples.old_log_prob.len();
    let scale = 1.0 / minibatch as f64;
    let inv_std: Vec<T> = log_std.iter().map(|l| (-*l).exp()).collect();
    let log_prob = gaussian_log_prob(samples.actions, mean, log_std);
    let mut out = BlockLoss {
        policy: 0.0,
        value: 0.0,
        bound: 0.0,
        approx_kl: 0.0,
        clip_fraction: 0.0,
        d_mean: vec![T::zero(); rows * a],
        d_value: vec![T::zero(); rows],
        d_log_std: vec![T::zero(); a],
    };
    let (lo, hi) = (T::of(1.0 - c.clip), T::of(1.0 + c.clip));
    for i in 0..rows {
        let log_ratio = log_prob[i] - samples.old_log_prob[i];
        let ratio = log_ratio.exp();
        let adv = samples.advantages[i];
        let unclipped = ratio * adv;
        let clipped = ratio.max(lo).min(hi) * adv;
        out.policy -= unclipped.min(clipped).to_f64().unwrap_or(f64::NAN) * scale;
        out.approx_kl += ((ratio - T::one()) - log_ratio)
            .to_f64()
            .unwrap_or(f64::NAN)
            * scale;
        if ratio < lo || ratio > hi {
            out.clip_fraction += scale;
        }
        // The minimum follows the unclipped term unless clipping made it smaller; the clipped
        // term is flat outside the range, so its derivative only matters where both agree.
        let d_log_prob = if unclipped <= clipped {
            -adv * ratio * T::of(scale)
        } else {
            T::zero()
        };
        // d log_prob / d mean_j = z_j / std_j; d log_prob / d log_std_j = z_j^2 - 1.
        for j in 0..a {
            let z = (samples.actions[i * a + j] - mean[i * a + j]) * inv_std[j];
            out.d_mean[i * a + j] = d_log_prob * z * inv_std[j];
            out.d_log_std[j] += d_log_prob * (z * z - T::one());
        }
        let error = values[i] - samples.returns[i];
        out.value += (error * error).to_f64().unwrap_or(f64::NAN) * scale;
        out.d_value[i] = T::of(2.0 * c.value * scale) * error;
        if c.bound > 0.0 {
            for j in 0..a {
                let e = excess(mean[i * a + j].to_f64().unwrap_or(f64::NAN));
                out.bound += e * e * scale;
                out.d_mean[i * a + j] += T::of(2.0 * c.bound * e * scale);
            }
        }
    }
    out
}

/// Adds the entropy term, once per minibatch: returns the loss's parts and adds
/// `d(-c2 H)/d log_std = -c2` to `d_log_std`.
#[allow(clippy::too_many_arguments)]
pub fn finish<T: Real>(
    policy: f64,
    value: f64,
    bound: f64,
    approx_kl: f64,
    clip_fraction: f64,
    log_std: &[T],
    d_log_std: &mut [T],
    c: &LossCoefficients,
) -> Loss {
    let entropy = gaussian_entropy(log_std).to_f64().unwrap_or(f64::NAN);
    d_log_std
        .iter_mut()
        .for_each(|d| *d = *d - T::of(c.entropy));
    Loss {
        total: policy + c.value * value - c.entropy * entropy + c.bound * bound,
        policy,
        value,
        entropy,
        bound,
        approx_kl,
        clip_fraction,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_prob_and_entropy_by_hand() {
        // One dimension, mean 0, log_std 0 (std 1): log N(1) = -0.5 - ln(2 pi)/2.
        let lp = gaussian_log_prob(&[1.0_f64], &[0.0], &[0.0]);
        assert!((lp[0] - (-0.5 - HALF_LN_2PI)).abs() < 1e-15);
        // Two dimensions with std e^0.5: entropy = 1.0 + 2 (0.5 + ln(2 pi)/2).
        let h = gaussian_entropy(&[0.5_f64, 0.5]);
        assert!((h - (1.0 + 2.0 * (0.5 + HALF_LN_2PI))).abs() < 1e-15);
    }

    fn two_samples(c: &LossCoefficients) -> (BlockLoss<f64>, Loss) {
        // Two samples, one action dimension with mean 0 and log_std 0, so that the log-prob is
        // -a^2/2 - ln(2 pi)/2; the old log-probs are chosen for log-ratios 0.5 and -0.1.
        let actions = [1.0, 0.5];
        let lp = gaussian_log_prob(&actions, &[0.0, 0.0], &[0.0]);
        let old = [lp[0] - 0.5, lp[1] + 0.1];
        let samples = Samples {
            actions: &actions,
            old_log_prob: &old,
            advantages: &[1.0, -2.0],
            returns: &[0.0, 4.0],
        };
        let mut block = block_loss(&samples, &[0.0, 0.0], &[1.0, 2.0], &[0.0], c, 2);
        let mut d = block.d_log_std.clone();
        let loss = finish(
            block.policy,
            block.value,
            block.bound,
            block.approx_kl,
            block.clip_fraction,
            &[0.0],
            &mut d,
            c,
        );
        block.d_log_std = d;
        (block, loss)
    }

    #[test]
    fn clipped_surrogate_on_a_hand_built_batch() {
        //  1. ratio e^0.5 = 1.6487, A = +1: min(1.6487, 1.2) = 1.2 (clipped)
        //  2. ratio e^-0.1 = 0.9048, A = -2: min(-1.8097, -1.8097) = -1.8097 (inside the range)
        // policy loss = -(1.2 - 1.8097) / 2 = 0.30484
        // value loss = ((1 - 0)^2 + (2 - 4)^2) / 2 = 2.5; log_std = [0]: entropy = 1.41894
        let c = LossCoefficients {
            clip: 0.2,
            value: 0.5,
            entropy: 0.01,
            bound: 0.0,
        };
        let (block, loss) = two_samples(&c);
        let policy = -(1.2 - 2.0 * (-0.1_f64).exp()) / 2.0;
        assert!((loss.policy - policy).abs() < 1e-12, "{}", loss.policy);
        assert!((loss.value - 2.5).abs() < 1e-12);
        assert!((loss.entropy - (0.5 + HALF_LN_2PI)).abs() < 1e-12);
        let total = policy + 0.5 * 2.5 - 0.01 * (0.5 + HALF_LN_2PI);
        assert!((loss.total - total).abs() < 1e-12);
        assert_eq!(loss.clip_fraction, 0.5);
        // KL estimate: mean((r - 1) - ln r) = ((e^0.5 - 1.5) + (e^-0.1 - 0.9)) / 2
        let kl = ((0.5_f64.exp() - 1.5) + ((-0.1_f64).exp() - 0.9)) / 2.0;
        assert!((loss.approx_kl - kl).abs() < 1e-12);
        // Gradients: sample 1 is clipped (none); sample 2: d/d lp = -A r / 2 = e^-0.1,
        // d lp / d mean = a = 0.5, d lp / d log_std = a^2 - 1 = -0.75.
        let g = (-0.1_f64).exp();
        assert_eq!(block.d_mean[0], 0.0);
        assert!((block.d_mean[1] - g * 0.5).abs() < 1e-12);
        assert!((block.d_log_std[0] - (g * -0.75 - 0.01)).abs() < 1e-12);
        // d(c1 mean (V - R)^2)/dV = c1 (V - R) = [0.5, -1.0]
        assert!((block.d_value[0] - 0.5).abs() < 1e-12 && (block.d_value[1] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_gradient_moves_the_mean_toward_a_rewarded_action() {
        // At ratio 1 with A = 1: d(-r A)/d mean = -(a - mu)/sigma^2 = -1 for a = 1.
        let lp = gaussian_log_prob(&[1.0_f64], &[0.0], &[0.0]);
        let c = LossCoefficients {
            clip: 0.2,
            value: 0.5,
            entropy: 0.0,
            bound: 0.0,
        };
        let samples = Samples {
            actions: &[1.0],
            old_log_prob: &lp,
            advantages: &[1.0],
            returns: &[0.0],
        };
        let block = block_loss(&samples, &[0.0], &[0.0], &[0.0], &c, 1);
        assert!((block.d_mean[0] + 1.0).abs() < 1e-12, "{}", block.d_mean[0]);
    }

    #[test]
    fn the_bound_loss_pulls_means_back_inside_the_clip_range_by_hand() {
        // One sample, three dimensions with means 1.5, -3 and 0.3; no advantage, so only the
        // bound term moves the means. Excess 0.5, -2 and 0: bound = 0.25 + 4 = 4.25,
        // d/d mean = 2 cb excess = [0.1, -0.4, 0] at cb = 0.1 (the mean falls toward 1, rises
        // toward -1).
        let mean = [1.5_f64, -3.0, 0.3];
        let lp = gaussian_log_prob(&mean, &mean, &[0.0, 0.0, 0.0]);
        let samples = Samples {
            actions: &mean,
            old_log_prob: &lp,
            advantages: &[0.0],
            returns: &[0.0],
        };
        let c = LossCoefficients {
            clip: 0.2,
            value: 0.5,
            entropy: 0.0,
            bound: 0.1,
        };
        let block = block_loss(&samples, &mean, &[0.0], &[0.0, 0.0, 0.0], &c, 1);
        assert!((block.bound - 4.25).abs() < 1e-12);
        let want = [0.1, -0.4, 0.0];
        for (d, w) in block.d_mean.iter().zip(want) {
            assert!((d - w).abs() < 1e-12, "{:?}", block.d_mean);
        }
        let mut d = block.d_log_std.clone();
        let loss = finish(0.0, 0.0, block.bound, 0.0, 0.0, &[0.0; 3], &mut d, &c);
        assert!((loss.total - 0.425).abs() < 1e-12);
        // Off, it adds nothing at all.
        let off = LossCoefficients { bound: 0.0, ..c };
        let block = block_loss(&samples, &mean, &[0.0], &[0.0, 0.0, 0.0], &off, 1);
        assert_eq!(block.bound, 0.0);
        assert!(block.d_mean.iter().all(|d| *d == 0.0));
    }
}
