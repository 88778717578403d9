//! Adam (Kingma & Ba 2015) over groups of flat parameter arrays, with PyTorch's and optax's
//! defaults (betas 0.9 and 0.999, epsilon 1e-8 added outside the square root) and no weight
//! decay.

use super::matmul::Real;

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-8;

/// Adam's state: first and second moments per parameter group, and the step count.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Adam<T> {
    pub learning_rate: f64,
    pub step: u64,
    pub first: Vec<Vec<T>>,
    pub second: Vec<Vec<T>>,
}

impl<T: Real> Adam<T> {
    /// One moment array per group of `sizes`.
    pub fn new(learning_rate: f64, sizes: &[usize]) -> Self {
        Self {
            learning_rate,
            step: 0,
            first: sizes.iter().map(|&n| vec![T::zero(); n]).collect(),
            second: sizes.iter().map(|&n| vec![T::zero(); n]).collect(),
        }
    }

    /// One update of every group: `params[g] -= lr m_hat / (sqrt(v_hat) + eps)`.
    pub fn update(&mut self, params: &mut [&mut [T]], grads: &[&[T]]) {
        self.update_with(params, grads, &[]);
    }

    /// As [`Adam::update`], with group `g` at `rates[g]` where given (`Some`) instead of
    /// `learning_rate`.
    pub fn update_with(&mut self, params: &mut [&mut [T]], grads: &[&[T]], rates: &[Option<f64>]) {
        assert_eq!(params.len(), self.first.len(), "parameter groups");
        assert_eq!(grads.len(), self.first.len(), "gradient groups");
        self.step += 1;
        let t = self.step as i32;
        let (b1, b2) = (T::of(BETA1), T::of(BETA2));
        let (c1, c2) = (T::one() - b1, T::one() - b2);
        // Bias corrections folded into the step size, computed in f64.
        let correction = 1.0 - BETA1.powi(t);
        let root_correction = T::of((1.0 - BETA2.powi(t)).sqrt());
        let eps = T::of(EPSILON);
        for g in 0..params.len() {
            let rate = rates.get(g).copied().flatten();
            let step_size = T::of(rate.unwrap_or(self.learning_rate) / correction);
            let (m, v) = (&mut self.first[g], &mut self.second[g]);
            assert_eq!(params[g].len(), m.len(), "group {g} size");
            assert_eq!(grads[g].len(), m.len(), "group {g} gradient size");
            for (((p, &d), m), v) in params[g].iter_mut().zip(grads[g]).zip(m).zip(v) {
                *m = b1 * *m + c1 * d;
                *v = b2 * *v + c2 * d * d;
                *p = *p - step_size * *m / (v.sqrt() / root_correction + eps);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_group_may_step_at_its_own_rate() {
        // Step 1 moves each parameter by its rate (g / |g| = 1): group 0 at the shared 0.1,
        // group 1 at its own 0.5; the moments are the same either way.
        let mut adam = Adam::<f64>::new(0.1, &[1, 1]);
        let (mut a, mut b) = (vec![1.0], vec![1.0]);
        adam.update_with(&mut [&mut a, &mut b], &[&[2.0], &[2.0]], &[None, Some(0.5)]);
        assert!(
            (a[0] - 0.9).abs() < 1e-7 && (b[0] - 0.5).abs() < 1e-7,
            "{a:?} {b:?}"
        );
        assert_eq!(adam.first[0], adam.first[1]);
        let mut same = Adam::<f64>::new(0.1, &[1, 1]);
        let (mut c, mut d) = (vec![1.0], vec![1.0]);
        same.update(&mut [&mut c, &mut d], &[&[2.0], &[2.0]]);
        assert_eq!((c[0], d[0]), (a[0], a[0]), "update is update_with no rates");
    }

    #[test]
    fn first_steps_by_hand() {
        // Step 1: m_hat = g, v_hat = g^2, so each parameter moves by lr * g / (|g| + eps).
        let mut adam = Adam::<f64>::new(0.1, &[2, 1]);
        let (mut a, mut b) = (vec![1.0, -1.0], vec![0.0]);
        adam.update(&mut [&mut a, &mut b], &[&[2.0, -0.5], &[0.0]]);
        assert!((a[0] - (1.0 - 0.1 * 2.0 / (2.0 + 1e-8))).abs() < 1e-12);
        assert!((a[1] - (-1.0 + 0.1 * 0.5 / (0.5 + 1e-8))).abs() < 1e-12);
        assert_eq!(b[0], 0.0);
        // Step 2 with the same gradient: m_hat = g, v_hat = g^2 again.
        adam.update(&mut [&mut a, &mut b], &[&[2.0, -0.5], &[0.0]]);
        assert!((a[0] - (1.0 - 0.2 * 2.0 / (2.0 + 1e-8))).abs() < 1e-12);
        // A gradient that changes sign: m = 0.9*0.19*1 + ... computed directly.
        let mut adam = Adam::<f64>::new(1.0, &[1]);
        let mut p = vec![0.0];
        adam.update(&mut [&mut p], &[&[1.0]]);
        adam.update(&mut [&mut p], &[&[-1.0]]);
        let m = 0.9 * 0.1 - 0.1;
        let v = 0.999 * 0.001 + 0.001;
        let expected =
            -1.0 / (1.0 + 1e-8) - (m / (1.0 - 0.81)) / ((v / (1.0 - 0.998001_f64)).sqrt() + 1e-8);
        assert!((p[0] - expected).abs() < 1e-9, "{} vs {expected}", p[0]);
    }
}
