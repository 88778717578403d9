//! The PPO loss (Schulman et al. 2017; the paper's Eq. 3): clipped surrogate, value loss and
//! entropy bonus for a diagonal Gaussian policy. Shapes: B = minibatch, A = action dimension.

use candle_core::{Result, Tensor, D};

/// ln(2 pi) / 2.
const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// log N(actions | mean, exp(log_std)), summed over action dimensions.
/// `actions`, `mean`: [B, A]; `log_std`: [A]. Returns [B].
pub fn gaussian_log_prob(actions: &Tensor, mean: &Tensor, log_std: &Tensor) -> Result<Tensor> {
    let z = actions.sub(mean)?.broadcast_div(&log_std.exp()?)?;
    let per_dim = (z.sqr()? * -0.5)?
        .broadcast_sub(log_std)?
        .affine(1.0, -HALF_LN_2PI)?;
    per_dim.sum(D::Minus1)
}

/// Entropy of the Gaussian, summed over action dimensions: sum(log_std) + A (1 + ln 2 pi) / 2.
pub fn gaussian_entropy(log_std: &Tensor) -> Result<Tensor> {
    let a = log_std.dims1()? as f64;
    log_std.sum_all()?.affine(1.0, a * (0.5 + HALF_LN_2PI))
}

/// PPO coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossCoefficients {
    /// Clipping range epsilon.
    pub clip: f64,
    /// Value loss weight c1.
    pub value: f64,
    /// Entropy bonus weight c2.
    pub entropy: f64,
}

/// The loss to minimise and its parts, for logging.
pub struct Loss {
    pub total: Tensor,
    pub policy: f32,
    pub value: f32,
    pub entropy: f32,
    /// Mean of (ratio - 1) - ln(ratio): a low-variance estimate of KL(old || new).
    pub approx_kl: f32,
    /// Fraction of samples whose ratio was clipped.
    pub clip_fraction: f32,
}

/// total = -mean(min(r A, clip(r, 1 - eps, 1 + eps) A)) + c1 mean((V - R)^2) - c2 H
/// with r = exp(log pi(a|s) - log pi_old(a|s)). `new_log_prob`, `old_log_prob`, `advantages`,
/// `values`, `returns`: [B]; `log_std`: [A].
pub fn ppo_loss(
    new_log_prob: &Tensor,
    old_log_prob: &Tensor,
    advantages: &Tensor,
    values: &Tensor,
    returns: &Tensor,
    log_std: &Tensor,
    c: &LossCoefficients,
) -> Result<Loss> {
    let log_ratio = new_log_prob.sub(old_log_prob)?;
    let ratio = log_ratio.exp()?;
    let unclipped = ratio.mul(advantages)?;
    let clipped = ratio.clamp(1.0 - c.clip, 1.0 + c.clip)?.mul(advantages)?;
    let policy = unclipped.minimum(&clipped)?.mean_all()?.neg()?;
    let value = values.sub(returns)?.sqr()?.mean_all()?;
    let entropy = gaussian_entropy(log_std)?;
    let total = policy
        .add(&(value.clone() * c.value)?)?
        .sub(&(entropy.clone() * c.entropy)?)?;

    let approx_kl = ratio
        .affine(1.0, -1.0)?
        .sub(&log_ratio)?
        .mean_all()?
        .to_scalar::<f32>()?;
    let outside = ratio
        .affine(1.0, -1.0)?
        .abs()?
        .gt(c.clip)?
        .to_dtype(candle_core::DType::F32)?;
    Ok(Loss {
        policy: policy.to_scalar()?,
        value: value.to_scalar()?,
        entropy: entropy.to_scalar()?,
        approx_kl,
        clip_fraction: outside.mean_all()?.to_scalar()?,
        total,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    fn t(v: &[f32]) -> Tensor {
        Tensor::new(v, &Device::Cpu).unwrap()
    }

    #[test]
    fn log_prob_and_entropy_by_hand() {
        // One dimension, mean 0, log_std 0 (std 1): log N(1) = -0.5 - ln(2 pi)/2.
        let lp = gaussian_log_prob(
            &Tensor::new(&[[1.0_f32]], &Device::Cpu).unwrap(),
            &Tensor::new(&[[0.0_f32]], &Device::Cpu).unwrap(),
            &t(&[0.0]),
        )
        .unwrap();
        assert!((lp.to_vec1::<f32>().unwrap()[0] as f64 - (-0.5 - HALF_LN_2PI)).abs() < 1e-6);
        // Two dimensions with std e^0.5: entropy = 1.0 + 2 (0.5 + ln(2 pi)/2).
        let h = gaussian_entropy(&t(&[0.5, 0.5]))
            .unwrap()
            .to_scalar::<f32>()
            .unwrap() as f64;
        assert!((h - (1.0 + 2.0 * (0.5 + HALF_LN_2PI))).abs() < 1e-5);
    }

    #[test]
    fn clipped_surrogate_on_a_hand_built_batch() {
        // Two samples, eps = 0.2:
        //  1. ratio e^0.5 = 1.6487, A = +1: min(1.6487, 1.2) = 1.2 (clipped)
        //  2. ratio e^-0.1 = 0.9048, A = -2: min(-1.8097, -1.8097) = -1.8097 (inside the range)
        // policy loss = -(1.2 - 1.8097) / 2 = 0.30484
        // value loss = ((1 - 0)^2 + (2 - 4)^2) / 2 = 2.5; log_std = [0]: entropy = 1.41894
        let c = LossCoefficients {
            clip: 0.2,
            value: 0.5,
            entropy: 0.01,
        };
        let loss = ppo_loss(
            &t(&[0.5, -0.1]),
            &t(&[0.0, 0.0]),
            &t(&[1.0, -2.0]),
            &t(&[1.0, 2.0]),
            &t(&[0.0, 4.0]),
            &t(&[0.0]),
            &c,
        )
        .unwrap();
        let policy = -(1.2 - 2.0 * (-0.1_f64).exp()) / 2.0;
        assert!(
            (loss.policy as f64 - policy).abs() < 1e-5,
            "{}",
            loss.policy
        );
        assert!((loss.value - 2.5).abs() < 1e-6);
        assert!((loss.entropy as f64 - (0.5 + HALF_LN_2PI)).abs() < 1e-5);
        let total = policy + 0.5 * 2.5 - 0.01 * (0.5 + HALF_LN_2PI);
        assert!((loss.total.to_scalar::<f32>().unwrap() as f64 - total).abs() < 1e-5);
        assert_eq!(loss.clip_fraction, 0.5);
        // KL estimate: mean((r - 1) - ln r) = ((e^0.5 - 1.5) + (e^-0.1 - 0.9)) / 2
        let kl = ((0.5_f64.exp() - 1.5) + ((-0.1_f64).exp() - 0.9)) / 2.0;
        assert!((loss.approx_kl as f64 - kl).abs() < 1e-5);
    }

    #[test]
    fn gradients_flow_to_the_policy() {
        use candle_core::Var;
        let mean = Var::new(&[[0.0_f32]], &Device::Cpu).unwrap();
        let log_std = Var::new(&[0.0_f32], &Device::Cpu).unwrap();
        let lp = gaussian_log_prob(
            &Tensor::new(&[[1.0_f32]], &Device::Cpu).unwrap(),
            mean.as_tensor(),
            log_std.as_tensor(),
        )
        .unwrap();
        let c = LossCoefficients {
            clip: 0.2,
            value: 0.5,
            entropy: 0.0,
        };
        let loss = ppo_loss(
            &lp,
            &lp.detach(),
            &t(&[1.0]),
            &t(&[0.0]),
            &t(&[0.0]),
            log_std.as_tensor(),
            &c,
        )
        .unwrap();
        let grads = loss.total.backward().unwrap();
        // d(-ratio * A)/d mean at ratio 1 = -(a - mu)/sigma^2 = -1: moving the mean toward the
        // rewarded action lowers the loss.
        let g = grads.get(&mean).unwrap().to_vec2::<f32>().unwrap()[0][0];
        assert!((g + 1.0).abs() < 1e-5, "{g}");
    }
}
